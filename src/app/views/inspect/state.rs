//! The inspection the Inspect view edits, without GUI types: named regions
//! with a role and a colour, section profiles with a colour, the measurements
//! with their tolerances, levelling. It converts to and from the analysis
//! module's [`InspectionSpec`] (what `sheen analyze` and session files hold),
//! so the GUI, the CLI and a production line run the same inspection.
//!
//! Invariants kept by every edit: region, profile and measurement names are
//! unique and non-empty; every region a measurement names exists (renaming a
//! region renames its uses, deleting one drops the measurements that can no
//! longer be made).

use serde::{Deserialize, Serialize};

use crate::analysis::height_map::RasterParams;
use crate::analysis::inspection::{FlatnessStatistic, INSPECTION_VERSION, InspectionSpec, Measure, MeasurementSpec};
use crate::analysis::measurement_table::{DecisionRule, Tolerance};
use crate::analysis::profile::{Profile, ProfileLine, ProfileSpec};
use crate::analysis::region::{NamedRegion, Region};
use crate::analysis::texture::filter::FormRemoval;

/// What a region is for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionRole {
    /// No role: a region to measure flatness or tilt of.
    #[default]
    None,
    /// The datum: levelling fits its plane to these, step heights are measured from them.
    Reference,
    /// Step heights are measured on these, against the references.
    Measured,
    /// A land of a coplanarity check.
    Land,
}

impl RegionRole {
    pub const ALL: [RegionRole; 4] = [RegionRole::None, RegionRole::Reference, RegionRole::Measured, RegionRole::Land];

    pub fn name(self) -> &'static str {
        match self {
            RegionRole::None => "—",
            RegionRole::Reference => "reference",
            RegionRole::Measured => "measured",
            RegionRole::Land => "land",
        }
    }

    pub fn tooltip(self) -> &'static str {
        match self {
            RegionRole::None => "No role: measure its flatness or tilt.",
            RegionRole::Reference => "Datum: levelling and step heights use the plane fitted to all reference regions.",
            RegionRole::Measured => "Step heights are measured on this region against the reference regions.",
            RegionRole::Land => "A land of the coplanarity check (all lands against their common plane).",
        }
    }
}

/// Colours given to new regions and profiles in turn (distinct on the height
/// colour maps and on both themes).
pub const ITEM_COLORS: [[u8; 3]; 8] = [
    [255, 90, 90],
    [80, 200, 255],
    [255, 200, 40],
    [190, 110, 255],
    [90, 230, 120],
    [255, 140, 200],
    [255, 255, 255],
    [255, 150, 60],
];

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegionItem {
    pub region: NamedRegion,
    pub role: RegionRole,
    pub color: [u8; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileItem {
    pub spec: ProfileSpec,
    pub color: [u8; 3],
}

/// The whole inspection being edited.
#[derive(Clone, Debug, PartialEq)]
pub struct InspectDoc {
    pub regions: Vec<RegionItem>,
    pub profiles: Vec<ProfileItem>,
    pub measurements: Vec<MeasurementSpec>,
    /// Level the map (display and profiles) to the plane of the reference regions.
    pub level: bool,
    /// Also extract the map nodes near each profile line, to plot beside it.
    pub show_raw: bool,
    /// Plot the R and W profiles of the profiles with a texture measurement
    /// instead of the measured heights.
    pub show_r_and_w: bool,
    pub raster: RasterParams,
    /// How toleranced rows are judged against their uncertainty.
    pub decision_rule: DecisionRule,
    /// Monte Carlo trials of the non-linear rows (`None` = the default).
    pub monte_carlo_trials: Option<usize>,
    /// Averaging width and step given to new profiles (mm; step `None` = the map pitch).
    pub default_width_mm: f64,
    pub default_step_mm: Option<f64>,
    next_color: usize,
}

impl Default for InspectDoc {
    fn default() -> Self {
        Self {
            regions: Vec::new(),
            profiles: Vec::new(),
            measurements: Vec::new(),
            level: true,
            show_raw: false,
            show_r_and_w: false,
            raster: RasterParams::default(),
            decision_rule: DecisionRule::default(),
            monte_carlo_trials: None,
            default_width_mm: 0.0,
            default_step_mm: None,
            next_color: 0,
        }
    }
}

/// The GUI-only part of a session (`Session::view`): colours and roles.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ViewExtras {
    pub regions: Vec<RegionExtra>,
    pub profiles: Vec<ProfileExtra>,
    pub show_raw: bool,
    pub level: Option<bool>,
    /// Plot cursors (profile distance, mm).
    pub cursors: [Option<f64>; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegionExtra {
    pub name: String,
    pub role: RegionRole,
    pub color: [u8; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileExtra {
    pub name: String,
    pub color: [u8; 3],
}

/// Key of the GUI's part in `Session::view`.
pub const VIEW_KEY: &str = "inspect";

impl InspectDoc {
    fn take_color(&mut self) -> [u8; 3] {
        let c = ITEM_COLORS[self.next_color % ITEM_COLORS.len()];
        self.next_color += 1;
        c
    }

    fn unique_name(taken: impl Fn(&str) -> bool, candidates: impl Iterator<Item = String>) -> String {
        for c in candidates {
            if !taken(&c) {
                return c;
            }
        }
        // Candidates are unbounded in practice; this is the type system's fallback.
        String::from("unnamed")
    }

    pub fn region_index(&self, name: &str) -> Option<usize> {
        self.regions.iter().position(|r| r.region.name == name)
    }

    /// Adds a region named `R1`, `R2`, ... and returns its index.
    pub fn add_region(&mut self, region: Region) -> usize {
        let name = Self::unique_name(|n| self.region_index(n).is_some(), (1..).map(|i| format!("R{i}")));
        let color = self.take_color();
        self.regions.push(RegionItem { region: NamedRegion::new(name, region), role: RegionRole::None, color });
        self.regions.len() - 1
    }

    /// Adds a profile named `A-A`, `B-B`, ... (section names as on drawings).
    pub fn add_profile(&mut self, line: ProfileLine) -> usize {
        let taken = |n: &str| self.profiles.iter().any(|p| p.spec.name == n);
        let letters = ('A'..='Z').map(|c| format!("{c}-{c}"));
        let numbered = (1..).map(|i| format!("P{i}"));
        let name = Self::unique_name(taken, letters.chain(numbered));
        let color = self.take_color();
        let spec = ProfileSpec {
            name,
            line,
            step_mm: self.default_step_mm,
            width_mm: self.default_width_mm,
            raw_samples: self.show_raw,
        };
        self.profiles.push(ProfileItem { spec, color });
        self.profiles.len() - 1
    }

    /// Renames region `index`, and every measurement's use of it.
    pub fn rename_region(&mut self, index: usize, new_name: &str) -> Result<(), EditError> {
        let new_name = new_name.trim();
        let old = self.regions.get(index).ok_or(EditError::NoSuch(Item::Region))?.region.name.clone();
        if new_name == old {
            return Ok(());
        }
        if new_name.is_empty() {
            return Err(EditError::EmptyName(Item::Region));
        }
        if self.region_index(new_name).is_some() {
            return Err(EditError::NameTaken(Item::Region, new_name.to_string()));
        }
        for m in &mut self.measurements {
            for name in measure_regions_mut(&mut m.measure) {
                if *name == old {
                    *name = new_name.to_string();
                }
            }
        }
        self.regions[index].region.name = new_name.to_string();
        Ok(())
    }

    pub fn rename_profile(&mut self, index: usize, new_name: &str) -> Result<(), EditError> {
        let new_name = new_name.trim();
        if self.profiles.get(index).is_none() {
            return Err(EditError::NoSuch(Item::Profile));
        }
        if new_name.is_empty() {
            return Err(EditError::EmptyName(Item::Profile));
        }
        if self.profiles.iter().enumerate().any(|(i, p)| i != index && p.spec.name == new_name) {
            return Err(EditError::NameTaken(Item::Profile, new_name.to_string()));
        }
        self.profiles[index].spec.name = new_name.to_string();
        Ok(())
    }

    pub fn rename_measurement(&mut self, index: usize, new_name: &str) -> Result<(), EditError> {
        let new_name = new_name.trim();
        if self.measurements.get(index).is_none() {
            return Err(EditError::NoSuch(Item::Measurement));
        }
        if new_name.is_empty() {
            return Err(EditError::EmptyName(Item::Measurement));
        }
        if self.measurements.iter().enumerate().any(|(i, m)| i != index && m.name == new_name) {
            return Err(EditError::NameTaken(Item::Measurement, new_name.to_string()));
        }
        self.measurements[index].name = new_name.to_string();
        Ok(())
    }

    /// Deletes region `index`, removes it from the measurements, and drops
    /// the measurements that are left without what they need. Returns the
    /// names of the dropped measurements.
    pub fn delete_region(&mut self, index: usize) -> Vec<String> {
        if index >= self.regions.len() {
            return Vec::new();
        }
        let name = self.regions.remove(index).region.name;
        let mut dropped = Vec::new();
        self.measurements.retain_mut(|m| {
            let keep = match &mut m.measure {
                Measure::StepHeight { reference, measured } => {
                    reference.retain(|n| *n != name);
                    measured.retain(|n| *n != name);
                    !reference.is_empty() && !measured.is_empty()
                }
                Measure::Flatness { region, .. } => *region != name,
                Measure::Texture { region, .. } => *region != name,
                Measure::ProfileTexture { .. } => true,
                Measure::Coplanarity { lands } => {
                    lands.retain(|n| *n != name);
                    lands.len() >= 2
                }
                Measure::Tilt { regions } => {
                    regions.retain(|n| *n != name);
                    !regions.is_empty()
                }
            };
            if !keep {
                dropped.push(m.name.clone());
            }
            keep
        });
        dropped
    }

    pub fn delete_profile(&mut self, index: usize) {
        if index < self.profiles.len() {
            self.profiles.remove(index);
        }
    }

    pub fn delete_measurement(&mut self, index: usize) {
        if index < self.measurements.len() {
            self.measurements.remove(index);
        }
    }

    fn names_with_role(&self, role: RegionRole) -> Vec<String> {
        self.regions.iter().filter(|r| r.role == role).map(|r| r.region.name.clone()).collect()
    }

    fn unique_measurement_name(&self, base: &str) -> String {
        let taken = |n: &str| self.measurements.iter().any(|m| m.name == n);
        let candidates = std::iter::once(base.to_string()).chain((2..).map(|i| format!("{base} {i}")));
        Self::unique_name(taken, candidates)
    }

    fn push_measurement(&mut self, base: &str, measure: Measure) -> usize {
        let name = self.unique_measurement_name(base);
        self.measurements.push(MeasurementSpec { name, measure, nominal: None, tolerance: None });
        self.measurements.len() - 1
    }

    /// Step height of the measured regions (as one set) over the reference regions.
    pub fn add_step_height(&mut self) -> Result<usize, EditError> {
        let reference = self.names_with_role(RegionRole::Reference);
        let measured = self.names_with_role(RegionRole::Measured);
        if reference.is_empty() || measured.is_empty() {
            return Err(EditError::NeedsReferenceAndMeasured { what: "a step height needs" });
        }
        let base = if measured.len() == 1 { format!("step {}", measured[0]) } else { "step height".to_string() };
        Ok(self.push_measurement(&base, Measure::StepHeight { reference, measured }))
    }

    /// One step height per measured region, each over all reference regions.
    pub fn add_step_heights_each(&mut self) -> Result<Vec<usize>, EditError> {
        let reference = self.names_with_role(RegionRole::Reference);
        let measured = self.names_with_role(RegionRole::Measured);
        if reference.is_empty() || measured.is_empty() {
            return Err(EditError::NeedsReferenceAndMeasured { what: "step heights need" });
        }
        Ok(measured
            .into_iter()
            .map(|m| {
                let base = format!("step {m}");
                self.push_measurement(&base, Measure::StepHeight { reference: reference.clone(), measured: vec![m] })
            })
            .collect())
    }

    /// Flatness of region `index`: peak-to-valley and RMS rows.
    pub fn add_flatness(&mut self, index: usize) -> Result<[usize; 2], EditError> {
        let name = self.regions.get(index).ok_or(EditError::NoSuch(Item::Region))?.region.name.clone();
        let pv = self.push_measurement(
            &format!("flatness PV {name}"),
            Measure::Flatness { region: name.clone(), statistic: FlatnessStatistic::PeakToValley, ls_mm: None },
        );
        let rms = self.push_measurement(
            &format!("flatness RMS {name}"),
            Measure::Flatness { region: name, statistic: FlatnessStatistic::Rms, ls_mm: None },
        );
        Ok([pv, rms])
    }

    /// The ISO 25178-2 areal parameters of a region after a least-squares
    /// plane (F-operator), without S- or L-filter until the operator sets one.
    pub fn add_texture(&mut self, index: usize) -> Result<usize, EditError> {
        let name = self.regions.get(index).ok_or(EditError::NoSuch(Item::Region))?.region.name.clone();
        Ok(self.push_measurement(
            &format!("texture {name}"),
            Measure::Texture {
                region: name,
                form: FormRemoval::Plane,
                ls_mm: None,
                lc_mm: None,
                smr_c_um: None,
                smc_mr_percent: None,
                limits: Default::default(),
            },
        ))
    }

    /// The ISO 21920-2 parameters of a profile (R, W and P), with the
    /// standard's default cut-offs until the operator sets them.
    pub fn add_roughness(&mut self, index: usize) -> Result<usize, EditError> {
        let name = self.profiles.get(index).ok_or(EditError::NoSuch(Item::Profile))?.spec.name.clone();
        Ok(self.push_measurement(
            &format!("roughness {name}"),
            Measure::ProfileTexture {
                profile: name,
                ls_mm: None,
                lc_mm: None,
                c_um: None,
                periodic: false,
                limits: Default::default(),
            },
        ))
    }

    pub fn add_tilt(&mut self, index: usize) -> Result<usize, EditError> {
        let name = self.regions.get(index).ok_or(EditError::NoSuch(Item::Region))?.region.name.clone();
        Ok(self.push_measurement(&format!("tilt {name}"), Measure::Tilt { regions: vec![name] }))
    }

    /// Coplanarity of all lands.
    pub fn add_coplanarity(&mut self) -> Result<usize, EditError> {
        let lands = self.names_with_role(RegionRole::Land);
        if lands.len() < 2 {
            return Err(EditError::NeedsTwoLands { found: lands.len() });
        }
        Ok(self.push_measurement("coplanarity", Measure::Coplanarity { lands }))
    }

    /// The inspection as the analysis runs it.
    pub fn spec(&self) -> InspectionSpec {
        InspectionSpec {
            sheen_inspection: INSPECTION_VERSION,
            height_map: self.raster.clone(),
            level_to: if self.level { self.names_with_role(RegionRole::Reference) } else { Vec::new() },
            regions: self.regions.iter().map(|r| r.region.clone()).collect(),
            profiles: self
                .profiles
                .iter()
                .map(|p| ProfileSpec { raw_samples: self.show_raw, ..p.spec.clone() })
                .collect(),
            measurements: self.measurements.clone(),
            decision_rule: self.decision_rule,
            monte_carlo_trials: self.monte_carlo_trials,
        }
    }

    /// Colours, roles and toggles, for `Session::view`.
    pub fn extras(&self, cursors: [Option<f64>; 2]) -> ViewExtras {
        ViewExtras {
            regions: self
                .regions
                .iter()
                .map(|r| RegionExtra { name: r.region.name.clone(), role: r.role, color: r.color })
                .collect(),
            profiles: self
                .profiles
                .iter()
                .map(|p| ProfileExtra { name: p.spec.name.clone(), color: p.color })
                .collect(),
            show_raw: self.show_raw,
            level: Some(self.level),
            cursors,
        }
    }

    /// Rebuilds the document from a spec (a session or a CLI inspection file)
    /// and the GUI's extras when present. Without extras, roles are inferred:
    /// levelling regions are references, step-height regions are references
    /// and measured, coplanarity regions are lands.
    pub fn from_spec(spec: &InspectionSpec, extras: Option<&ViewExtras>) -> Self {
        let mut doc = InspectDoc { raster: spec.height_map.clone(), ..InspectDoc::default() };
        let inferred = |name: &str| {
            let uses = |f: &dyn Fn(&Measure) -> bool| spec.measurements.iter().any(|m| f(&m.measure));
            let n = name.to_string();
            if spec.level_to.contains(&n)
                || uses(&|m| matches!(m, Measure::StepHeight { reference, .. } if reference.contains(&n)))
            {
                RegionRole::Reference
            } else if uses(&|m| matches!(m, Measure::StepHeight { measured, .. } if measured.contains(&n))) {
                RegionRole::Measured
            } else if uses(&|m| matches!(m, Measure::Coplanarity { lands } if lands.contains(&n))) {
                RegionRole::Land
            } else {
                RegionRole::None
            }
        };
        for r in &spec.regions {
            let extra = extras.and_then(|e| e.regions.iter().find(|x| x.name == r.name));
            let color = extra.map_or_else(|| doc.take_color(), |x| x.color);
            let role = extra.map_or_else(|| inferred(&r.name), |x| x.role);
            doc.regions.push(RegionItem { region: r.clone(), role, color });
        }
        for p in &spec.profiles {
            let extra = extras.and_then(|e| e.profiles.iter().find(|x| x.name == p.name));
            let color = extra.map_or_else(|| doc.take_color(), |x| x.color);
            doc.profiles.push(ProfileItem { spec: ProfileSpec { raw_samples: false, ..p.clone() }, color });
        }
        doc.next_color = doc.regions.len() + doc.profiles.len();
        doc.measurements = spec.measurements.clone();
        doc.decision_rule = spec.decision_rule;
        doc.monte_carlo_trials = spec.monte_carlo_trials;
        doc.show_raw = extras.map_or_else(|| spec.profiles.iter().any(|p| p.raw_samples), |e| e.show_raw);
        doc.level = extras.and_then(|e| e.level).unwrap_or(!spec.level_to.is_empty());
        doc
    }
}

/// The region names a measurement uses, for renaming.
fn measure_regions_mut(m: &mut Measure) -> Vec<&mut String> {
    match m {
        Measure::StepHeight { reference, measured } => reference.iter_mut().chain(measured.iter_mut()).collect(),
        Measure::Flatness { region, .. } | Measure::Texture { region, .. } => vec![region],
        Measure::Coplanarity { lands } => lands.iter_mut().collect(),
        Measure::Tilt { regions } => regions.iter_mut().collect(),
        Measure::ProfileTexture { .. } => Vec::new(),
    }
}

/// The accepted range of a measurement, `(min, max)` in the row's unit.
pub fn limits(m: &MeasurementSpec) -> Option<(f64, f64)> {
    let t = m.tolerance?;
    let nominal = m.nominal.unwrap_or(0.0);
    Some((nominal + t.lower, nominal + t.upper))
}

/// Sets the accepted range from its limits, keeping a nominal value if there is one.
pub fn set_limits(m: &mut MeasurementSpec, limits: Option<(f64, f64)>) {
    match limits {
        None => m.tolerance = None,
        Some((min, max)) => {
            let (min, max) = (min.min(max), min.max(max));
            let nominal = m.nominal.unwrap_or(0.0);
            m.tolerance = Some(Tolerance { lower: min - nominal, upper: max - nominal });
        }
    }
}

/// A short description of what a measurement measures, for the list.
pub fn describe_measure(m: &Measure) -> String {
    match m {
        Measure::StepHeight { reference, measured } => {
            format!("step height of {} over {}", measured.join(" + "), reference.join(" + "))
        }
        Measure::Flatness { region, statistic, .. } => match statistic {
            FlatnessStatistic::PeakToValley => format!("flatness (peak to valley) of {region}"),
            FlatnessStatistic::Rms => format!("flatness (RMS) of {region}"),
        },
        Measure::Coplanarity { lands } => format!("coplanarity of {}", lands.join(", ")),
        Measure::Tilt { regions } => format!("tilt of {}", regions.join(" + ")),
        Measure::Texture { region, .. } => format!("surface texture of {region}"),
        Measure::ProfileTexture { profile, .. } => format!("roughness of profile {profile}"),
    }
}

/// The tools of the map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Tool {
    /// Drag pans, wheel zooms; click selects a region or profile.
    #[default]
    Pan,
    Rectangle,
    Polygon,
    Circle,
    /// A section between two points (drag).
    Line,
    /// A horizontal section through the clicked point.
    Horizontal,
    /// A vertical section through the clicked point.
    Vertical,
}

impl Tool {
    pub const ALL: [Tool; 7] =
        [Tool::Pan, Tool::Rectangle, Tool::Polygon, Tool::Circle, Tool::Line, Tool::Horizontal, Tool::Vertical];

    pub fn name(self) -> &'static str {
        match self {
            Tool::Pan => "Pan",
            Tool::Rectangle => "Rectangle",
            Tool::Polygon => "Polygon",
            Tool::Circle => "Circle",
            Tool::Line => "Line section",
            Tool::Horizontal => "Horizontal section",
            Tool::Vertical => "Vertical section",
        }
    }

    pub fn tooltip(self) -> &'static str {
        match self {
            Tool::Pan => "Drag to pan, wheel to zoom, double-click to fit.",
            Tool::Rectangle => "Drag a rectangle region.",
            Tool::Polygon => {
                "Click the vertices; double-click, Enter or a click on the first vertex closes it; Esc cancels."
            }
            Tool::Circle => "Drag from the centre to the rim.",
            Tool::Line => "Drag a section line from its start to its end.",
            Tool::Horizontal => "Click a point: a section along X through it.",
            Tool::Vertical => "Click a point: a section along Y through it.",
        }
    }
}

/// A shape being drawn, in mm.
#[derive(Clone, Debug, PartialEq)]
pub enum Drawing {
    Drag { tool: Tool, start_mm: [f64; 2], end_mm: [f64; 2] },
    Polygon { vertices_mm: Vec<[f64; 2]> },
}

/// What a finished drag or click makes.
#[derive(Clone, Debug, PartialEq)]
pub enum Drawn {
    Region(Region),
    Profile(ProfileLine),
}

/// A drawn coordinate rounded to 0.1 um: far below the instrument's
/// resolution, and sessions stay readable.
pub fn snap_mm(p: [f64; 2]) -> [f64; 2] {
    p.map(|v| (v * 1e4).round() / 1e4)
}

/// Turns a finished drag into a region or profile; `None` when it is too
/// small to be meant (under `min_mm`, e.g. two map pitches).
pub fn finish_drag(tool: Tool, start: [f64; 2], end: [f64; 2], min_mm: f64) -> Option<Drawn> {
    let (start, end) = (snap_mm(start), snap_mm(end));
    let (dx, dy) = (end[0] - start[0], end[1] - start[1]);
    match tool {
        Tool::Rectangle if dx.abs() >= min_mm && dy.abs() >= min_mm => Some(Drawn::Region(Region::Rectangle {
            x_mm: [start[0].min(end[0]), start[0].max(end[0])],
            y_mm: [start[1].min(end[1]), start[1].max(end[1])],
        })),
        Tool::Circle if dx.hypot(dy) >= min_mm => {
            Some(Drawn::Region(Region::Circle { centre_mm: start, radius_mm: dx.hypot(dy) }))
        }
        Tool::Line if dx.hypot(dy) >= min_mm => {
            Some(Drawn::Profile(ProfileLine::Segment { start_mm: start, end_mm: end }))
        }
        _ => None,
    }
}

/// What a click makes with a point tool.
pub fn click_profile(tool: Tool, at: [f64; 2]) -> Option<ProfileLine> {
    let at = snap_mm(at);
    match tool {
        Tool::Horizontal => Some(ProfileLine::Horizontal { through_mm: at }),
        Tool::Vertical => Some(ProfileLine::Vertical { through_mm: at }),
        _ => None,
    }
}

/// A closed polygon from clicked vertices, if it has an area.
pub fn finish_polygon(vertices: &[[f64; 2]]) -> Option<Region> {
    let region = Region::Polygon { vertices_mm: vertices.iter().map(|&v| snap_mm(v)).collect() };
    (vertices.len() >= 3 && region.area_mm2() > 0.0).then_some(region)
}

/// Height of `profile` at `distance_mm`, linear between stations; NaN in a
/// gap (no data at either neighbouring station) or off the line.
pub fn profile_z_at(profile: &Profile, distance_mm: f64) -> f64 {
    let s = &profile.samples;
    if s.is_empty() || !distance_mm.is_finite() {
        return f64::NAN;
    }
    let i = s.partition_point(|p| p.distance_mm <= distance_mm);
    if i == 0 {
        return if (s[0].distance_mm - distance_mm).abs() < 1e-12 { s[0].z_um } else { f64::NAN };
    }
    if i == s.len() {
        let last = s[s.len() - 1];
        return if (last.distance_mm - distance_mm).abs() < 1e-9 { last.z_um } else { f64::NAN };
    }
    let (a, b) = (s[i - 1], s[i]);
    let t = (distance_mm - a.distance_mm) / (b.distance_mm - a.distance_mm);
    a.z_um + t * (b.z_um - a.z_um)
}

/// Two cursors on a profile: where they read and what lies between.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CursorReadout {
    pub a: [f64; 2],
    pub b: [f64; 2],
    pub dx_mm: f64,
    pub dz_um: f64,
    /// dz / dx in um per mm (= mrad for small angles).
    pub slope_um_per_mm: f64,
    pub angle_deg: f64,
}

pub fn cursor_readout(profile: &Profile, a_mm: f64, b_mm: f64) -> CursorReadout {
    let (za, zb) = (profile_z_at(profile, a_mm), profile_z_at(profile, b_mm));
    let dx_mm = b_mm - a_mm;
    let dz_um = zb - za;
    let slope = if dx_mm != 0.0 { dz_um / dx_mm } else { f64::NAN };
    CursorReadout {
        a: [a_mm, za],
        b: [b_mm, zb],
        dx_mm,
        dz_um,
        slope_um_per_mm: slope,
        angle_deg: (slope * 1e-3).atan().to_degrees(),
    }
}

/// What an item of the inspection is, in an edit's error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Item {
    Region,
    Profile,
    Measurement,
}

impl std::fmt::Display for Item {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Item::Region => "region",
            Item::Profile => "profile",
            Item::Measurement => "measurement",
        })
    }
}

/// Why an edit of the inspection was refused; the operator reads the message.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EditError {
    #[error("no such {0}")]
    NoSuch(Item),
    #[error("a {0} needs a name")]
    EmptyName(Item),
    #[error("there is already a {0} named '{1}'")]
    NameTaken(Item, String),
    #[error("{what} at least one region with the role 'reference' and one with the role 'measured'")]
    NeedsReferenceAndMeasured { what: &'static str },
    #[error("coplanarity needs at least two regions with the role 'land' ({found} now)")]
    NeedsTwoLands { found: usize },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::profile::{Interpolation, ProfileSample};

    fn doc_with_regions() -> InspectDoc {
        let mut d = InspectDoc::default();
        for x in 0..4 {
            let x = f64::from(x);
            d.add_region(Region::Rectangle { x_mm: [x, x + 0.5], y_mm: [0.0, 1.0] });
        }
        d.regions[0].role = RegionRole::Reference;
        d.regions[1].role = RegionRole::Measured;
        d.regions[2].role = RegionRole::Land;
        d.regions[3].role = RegionRole::Land;
        d
    }

    #[test]
    fn new_items_get_unique_names_and_colours() {
        let mut d = doc_with_regions();
        assert_eq!(d.regions.iter().map(|r| r.region.name.as_str()).collect::<Vec<_>>(), ["R1", "R2", "R3", "R4"]);
        assert_ne!(d.regions[0].color, d.regions[1].color);
        d.delete_region(1);
        let again = d.add_region(Region::Circle { centre_mm: [0.0, 0.0], radius_mm: 1.0 });
        assert_eq!(d.regions[again].region.name, "R2");
        let a = d.add_profile(ProfileLine::Horizontal { through_mm: [0.0, 0.5] });
        let b = d.add_profile(ProfileLine::Vertical { through_mm: [0.5, 0.0] });
        assert_eq!((d.profiles[a].spec.name.as_str(), d.profiles[b].spec.name.as_str()), ("A-A", "B-B"));
        assert!(d.spec().validate().is_ok());
    }

    #[test]
    fn measurements_follow_roles_renames_and_deletions() {
        let mut d = doc_with_regions();
        let step = d.add_step_height().unwrap();
        let [pv, _] = d.add_flatness(0).unwrap();
        let cop = d.add_coplanarity().unwrap();
        assert_eq!(d.measurements[cop].name, "coplanarity");
        assert_eq!(d.measurements[step].name, "step R2");
        assert_eq!(
            d.measurements[step].measure,
            Measure::StepHeight { reference: vec!["R1".into()], measured: vec!["R2".into()] }
        );
        assert_eq!(d.measurements[pv].name, "flatness PV R1");
        assert_eq!(d.spec().level_to, vec!["R1".to_string()]);

        d.rename_region(0, "base").unwrap();
        assert_eq!(d.spec().level_to, vec!["base".to_string()]);
        assert!(
            matches!(&d.measurements[step].measure, Measure::StepHeight { reference, .. } if reference == &["base"])
        );
        assert!(
            matches!(d.rename_region(1, "base"), Err(EditError::NameTaken(_, n)) if n == "base"),
            "duplicate names are refused"
        );
        assert!(matches!(d.rename_region(1, "  "), Err(EditError::EmptyName(_))));
        assert!(d.spec().validate().is_ok());

        // Deleting a land leaves one: the coplanarity cannot be made any more.
        let dropped = d.delete_region(3);
        assert_eq!(dropped, vec!["coplanarity".to_string()]);
        assert!(d.measurements.iter().all(|m| !matches!(m.measure, Measure::Coplanarity { .. })));
        // Deleting the reference drops the step and the flatness rows.
        d.delete_region(0);
        assert!(d.measurements.is_empty(), "{:?}", d.measurements);
        assert!(d.spec().validate().is_ok());
        assert!(matches!(d.add_step_height(), Err(EditError::NeedsReferenceAndMeasured { .. })), "no reference left");
    }

    #[test]
    fn a_document_survives_the_session_form() {
        let mut d = doc_with_regions();
        d.add_step_height().unwrap();
        d.add_coplanarity().unwrap();
        let p = d.add_profile(ProfileLine::Segment { start_mm: [0.0, 0.0], end_mm: [3.0, 1.0] });
        d.profiles[p].spec.width_mm = 0.05;
        d.profiles[p].spec.step_mm = Some(0.01);
        set_limits(&mut d.measurements[0], Some((19.5, 20.5)));
        d.show_raw = true;
        d.regions[2].color = [1, 2, 3];
        let spec = InspectionSpec::from_json(&d.spec().to_json()).unwrap();
        let extras: ViewExtras = serde_json::from_value(serde_json::to_value(d.extras([None, None])).unwrap()).unwrap();
        let back = InspectDoc::from_spec(&spec, Some(&extras));
        assert_eq!(back.regions, d.regions);
        assert_eq!(back.profiles, d.profiles);
        assert_eq!(back.measurements, d.measurements);
        assert_eq!((back.level, back.show_raw), (d.level, d.show_raw));
        assert_eq!(limits(&back.measurements[0]), Some((19.5, 20.5)));
        // A CLI spec without GUI extras: roles come from the measurements.
        let inferred = InspectDoc::from_spec(&spec, None);
        let roles: Vec<RegionRole> = inferred.regions.iter().map(|r| r.role).collect();
        assert_eq!(roles, [RegionRole::Reference, RegionRole::Measured, RegionRole::Land, RegionRole::Land]);
    }

    #[test]
    fn limits_keep_the_nominal() {
        let mut m = MeasurementSpec {
            name: "s".into(),
            measure: Measure::Tilt { regions: vec!["a".into()] },
            nominal: Some(20.0),
            tolerance: None,
        };
        set_limits(&mut m, Some((20.5, 19.0)));
        assert_eq!(m.tolerance, Some(Tolerance { lower: -1.0, upper: 0.5 }));
        assert_eq!(limits(&m), Some((19.0, 20.5)));
        set_limits(&mut m, None);
        assert_eq!(limits(&m), None);
    }

    #[test]
    fn drags_and_clicks_make_shapes() {
        let r = finish_drag(Tool::Rectangle, [2.0, 1.0], [1.0, 3.0], 0.01);
        assert_eq!(r, Some(Drawn::Region(Region::Rectangle { x_mm: [1.0, 2.0], y_mm: [1.0, 3.0] })));
        assert_eq!(finish_drag(Tool::Rectangle, [2.0, 1.0], [2.001, 3.0], 0.01), None, "a line is no rectangle");
        let c = finish_drag(Tool::Circle, [0.0, 0.0], [3.0, 4.0], 0.01);
        assert_eq!(c, Some(Drawn::Region(Region::Circle { centre_mm: [0.0, 0.0], radius_mm: 5.0 })));
        assert!(matches!(finish_drag(Tool::Line, [0.0, 0.0], [1.0, 0.0], 0.01), Some(Drawn::Profile(_))));
        assert_eq!(finish_drag(Tool::Pan, [0.0, 0.0], [1.0, 0.0], 0.01), None);
        assert_eq!(click_profile(Tool::Vertical, [1.0, 2.0]), Some(ProfileLine::Vertical { through_mm: [1.0, 2.0] }));
        assert!(finish_polygon(&[[0.0, 0.0], [1.0, 0.0]]).is_none());
        assert!(finish_polygon(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]).is_none(), "collinear");
        assert!(finish_polygon(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]).is_some());
    }

    #[test]
    fn cursors_read_distance_height_difference_and_slope() {
        let samples = (0..=10)
            .map(|i| {
                let d = f64::from(i) * 0.1;
                let z = if i == 5 { f64::NAN } else { 20.0 * d };
                ProfileSample { distance_mm: d, x_mm: d, y_mm: 0.0, z_um: z, n: u32::from(i != 5) }
            })
            .collect();
        let profile = Profile {
            name: "A-A".into(),
            start_mm: [0.0, 0.0],
            end_mm: [1.0, 0.0],
            length_mm: 1.0,
            step_mm: 0.1,
            width_mm: 0.0,
            lines_across: 1,
            interpolation: Interpolation::Bilinear,
            samples,
            raw: Vec::new(),
        };
        let r = cursor_readout(&profile, 0.15, 0.85);
        assert!((r.dx_mm - 0.7).abs() < 1e-12);
        assert!((r.dz_um - 14.0).abs() < 1e-9, "{r:?}");
        assert!((r.slope_um_per_mm - 20.0).abs() < 1e-9);
        assert!((r.angle_deg - 0.02f64.atan().to_degrees()).abs() < 1e-12);
        assert!(profile_z_at(&profile, 0.45).is_nan(), "a gap is not bridged");
        assert!(profile_z_at(&profile, 1.5).is_nan(), "off the line");
        assert!((profile_z_at(&profile, 1.0) - 20.0).abs() < 1e-9);
    }
}
