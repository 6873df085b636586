//! A batch inspection: named regions, section lines, measurements with
//! tolerances and optional levelling, written as JSON once and run over every
//! height map of a production lot, so the line runs the same inspection the
//! operator set up in the GUI (`sheen analyze` calls [`run_inspection`]).
//!
//! Format (`"sheen_inspection": 1`; unknown fields are refused so a typo in a
//! tolerance cannot pass silently):
//! ```json
//! {
//!   "sheen_inspection": 1,
//!   "height_map": { "pitch_mm": 0.0117 },
//!   "level_to": ["base"],
//!   "regions": [
//!     { "name": "base", "region": { "shape": "rectangle", "x_mm": [0, 2], "y_mm": [0, 1] } },
//!     { "name": "land", "region": { "shape": "circle", "centre_mm": [3, 0.5], "radius_mm": 0.4 } }
//!   ],
//!   "profiles": [
//!     { "name": "A-A", "line": { "kind": "horizontal", "through_mm": [0, 0.5] }, "width_mm": 0.05 }
//!   ],
//!   "measurements": [
//!     { "name": "land height", "measure": { "kind": "step_height", "reference": ["base"], "measured": ["land"] },
//!       "nominal": 20.0, "tolerance": { "lower": -0.5, "upper": 0.5 } }
//!   ]
//! }
//! ```
//! Texture items: `{"kind": "texture", "region": "face" | "all",
//! "form": "plane", "ls_mm": 0.0025, "lc_mm": 0.8, "limits": {"Sa": {"tolerance":
//! {"lower": 0, "upper": 0.4}}}}` gives one row per ISO 25178-2 parameter,
//! `{"kind": "profile_texture", "profile": "A-A", ...}` one per ISO 21920-2
//! parameter, and a flatness may carry `"ls_mm"` (ISO 12781-2 S-filter); all
//! new fields are optional, so version-1 files written before still load.
//! `"decision_rule"` (`"iso-14253-1"`, the default, `"simple"` or
//! `"guard-band:F"`) says how toleranced rows are judged against their
//! uncertainty, `"monte_carlo_trials"` (default 50, 0 = none) how many
//! trials the rows that are not linear in the data get.
//!
//! Step heights, flatness and coplanarity are defined on fitted planes and do
//! not depend on how the part lies, so they are computed on the map as
//! measured; levelling gives the profiles (heights above the reference plane)
//! and the reference for tilts. A measurement that cannot be made on a given
//! part (its region fell on a hole) becomes a row without a value that fails
//! its tolerance; only a spec that contradicts itself, or a levelling
//! reference without data, is an error.

use crate::engine::control::RunControl;
use crate::engine::warning::{Warning, WarningKind};
use std::borrow::Cow;
use std::collections::{BTreeMap, HashSet};

use serde::{Deserialize, Serialize};

use super::coplanarity::coplanarity;
use super::error::AnalysisError;
use super::height_map::{HeightMap, RasterParams};
use super::measurement_table::{DecisionRule, MeasurementKind, MeasurementRow, MeasurementTable, Tolerance};
use super::plane_fit::{PlaneFit, fit_plane, level};
use super::profile::{Profile, ProfileSpec, extract_profile};
use super::region::{NamedRegion, label, node_window, region_mask};
use super::step_height::step_height_pooled;
use super::texture::areal::MaterialRatioPoints;
use super::texture::filter::FormRemoval;
use super::texture::measure::{
    ArealParameter, HeightNoise, MIN_KERNEL_COVERAGE, TextureSettings, crop, filtered_flatness, measure_texture,
    noise_note, s_filter_note, scale_limited_surface,
};
use super::texture::profile_params::{ProfileParameter, ProfileSettings, SFilter, profile_parameters};
use super::uncertainty::{
    DEFAULT_TRIALS, NodeNoise, PlaneNoises, ScaleUncertainty, Uncertainty, region_variogram, seed_of,
};

mod budget;
use budget::Budgets;

/// Format version written and read.
pub const INSPECTION_VERSION: u64 = 1;

/// The region name a texture measurement gives for the whole map (unless
/// the spec defines a region of that name, which then wins).
pub const WHOLE_MAP: &str = "all";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InspectionSpec {
    /// Format version, [`INSPECTION_VERSION`].
    pub sheen_inspection: u64,
    /// How the cloud becomes a height map (pitch, discontinuity limits).
    #[serde(default)]
    pub height_map: RasterParams,
    /// Regions whose common plane the map is levelled to before anything is
    /// measured; empty = measure the map as it is.
    #[serde(default)]
    pub level_to: Vec<String>,
    #[serde(default)]
    pub regions: Vec<NamedRegion>,
    #[serde(default)]
    pub profiles: Vec<ProfileSpec>,
    #[serde(default)]
    pub measurements: Vec<MeasurementSpec>,
    /// How toleranced rows are judged against their uncertainty.
    #[serde(default)]
    pub decision_rule: DecisionRule,
    /// Monte Carlo trials of the rows not linear in the data (flatness,
    /// coplanarity, texture and profile parameters); `None` =
    /// [`DEFAULT_TRIALS`], 0 = none (those rows state no uncertainty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub monte_carlo_trials: Option<usize>,
}

impl Default for InspectionSpec {
    fn default() -> Self {
        Self {
            sheen_inspection: INSPECTION_VERSION,
            height_map: RasterParams::default(),
            level_to: Vec::new(),
            regions: Vec::new(),
            profiles: Vec::new(),
            measurements: Vec::new(),
            decision_rule: DecisionRule::default(),
            monte_carlo_trials: None,
        }
    }
}

/// One measurement: what to measure, and what it should be.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementSpec {
    pub name: String,
    pub measure: Measure,
    /// Nominal value in the row's unit (um for heights, deg for tilts).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<Tolerance>,
}

/// The measurement types, on regions named in the spec.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Measure {
    /// Height of `measured` over `reference` (each a union of regions), um.
    StepHeight { reference: Vec<String>, measured: Vec<String> },
    /// Flatness of one region, um; with `ls_mm`, of its S-filtered surface
    /// (ISO 12781-2: Gaussian S-filter at λs before the reference plane).
    Flatness {
        region: String,
        #[serde(default)]
        statistic: FlatnessStatistic,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ls_mm: Option<f64>,
    },
    /// Coplanarity of the lands, um; one extra row per land (its largest |deviation|).
    Coplanarity { lands: Vec<String> },
    /// Tilt of the plane fitted to the regions, deg: against the levelling
    /// reference plane when the spec levels, else against X-Y.
    Tilt { regions: Vec<String> },
    /// Areal texture parameters (ISO 25178-2) of a region or of the whole
    /// map ([`WHOLE_MAP`]) after the F-operator `form`, the S-filter at
    /// `ls_mm` and the L-filter at `lc_mm` (ISO 16610-61 Gaussian); one row
    /// per parameter, named "NAME Sq". Measured on the levelled map when the
    /// spec levels (it matters only with `form: none`).
    Texture {
        region: String,
        #[serde(default = "default_form")]
        form: FormRemoval,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ls_mm: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        lc_mm: Option<f64>,
        /// Height c of Smr(c), um above the mean plane [default 0].
        #[serde(default, skip_serializing_if = "Option::is_none")]
        smr_c_um: Option<f64>,
        /// Material ratio of Smc(mr), % [default 10].
        #[serde(default, skip_serializing_if = "Option::is_none")]
        smc_mr_percent: Option<f64>,
        /// Limits per parameter, in the parameter's unit.
        #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
        limits: BTreeMap<ArealParameter, ParameterLimit>,
    },
    /// ISO 21920-2 parameters of the R, W and P profiles of a section
    /// profile of the spec (on the levelled map when the spec levels): the
    /// least-squares line removed, S-filter at `ls_mm`, L-filter at `lc_mm`
    /// (both from the measured Ra by ISO 21920-3 when not given); one row
    /// per parameter, named "NAME Ra".
    ProfileTexture {
        profile: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ls_mm: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        lc_mm: Option<f64>,
        /// Height c of Rmr(c), um above the mean line [default 0].
        #[serde(default, skip_serializing_if = "Option::is_none")]
        c_um: Option<f64>,
        /// A periodic profile: λc, when not given, from RSm (ISO 21920-3's
        /// table for periodic profiles) instead of Ra.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        periodic: bool,
        #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
        limits: BTreeMap<ProfileParameter, ParameterLimit>,
    },
}

fn default_form() -> FormRemoval {
    FormRemoval::Plane
}

/// What one texture parameter should be: as a measurement's `nominal` and
/// `tolerance` (without a nominal the tolerance gives the limits).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterLimit {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal: Option<f64>,
    pub tolerance: Tolerance,
}

/// Why a pair of nesting indices cannot be used, if it cannot: each a
/// positive length and λs below λc (ISO 25178-3 §3.1).
pub fn check_cutoffs(ls_mm: Option<f64>, lc_mm: Option<f64>) -> Result<(), String> {
    for (what, v) in [("ls (λs)", ls_mm), ("lc (λc)", lc_mm)] {
        if let Some(v) = v
            && !(v.is_finite() && v > 0.0)
        {
            return Err(format!("the cut-off {what} {v} mm is not a positive length in mm"));
        }
    }
    if let (Some(ls), Some(lc)) = (ls_mm, lc_mm)
        && !(ls < lc)
    {
        return Err(format!("the S-filter cut-off ls {ls} mm must be shorter than the L-filter cut-off lc {lc} mm"));
    }
    Ok(())
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlatnessStatistic {
    #[default]
    PeakToValley,
    Rms,
}

/// Checks the JSON names a supported version before the body is decoded, so
/// a file from a newer Sheen gets a version message, not a field error.
pub(crate) fn check_version(
    text: &str,
    what: &'static str,
    field: &'static str,
    supported: u64,
) -> Result<(), AnalysisError> {
    let value: serde_json::Value = serde_json::from_str(text).map_err(|source| AnalysisError::Json { what, source })?;
    let found =
        value.get(field).and_then(serde_json::Value::as_u64).ok_or(AnalysisError::MissingVersion { what, field })?;
    if found != supported {
        return Err(AnalysisError::UnsupportedVersion { what, found, supported });
    }
    Ok(())
}

impl InspectionSpec {
    /// Parses and validates a spec.
    pub fn from_json(text: &str) -> Result<Self, AnalysisError> {
        const WHAT: &str = "inspection spec";
        check_version(text, WHAT, "sheen_inspection", INSPECTION_VERSION)?;
        let spec: Self = serde_json::from_str(text).map_err(|source| AnalysisError::Json { what: WHAT, source })?;
        spec.validate()?;
        Ok(spec)
    }

    /// Pretty JSON, the form [`InspectionSpec::from_json`] reads.
    pub fn to_json(&self) -> String {
        // A tree of plain structs, strings and numbers always serializes.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    fn region(&self, name: &str, used_by: &str) -> Result<&NamedRegion, AnalysisError> {
        self.regions.iter().find(|r| r.name == name).ok_or_else(|| AnalysisError::UnknownRegion {
            name: name.to_string(),
            used_by: used_by.to_string(),
            defined: if self.regions.is_empty() {
                "none".into()
            } else {
                self.regions.iter().map(|r| format!("'{}'", r.name)).collect::<Vec<_>>().join(", ")
            },
        })
    }

    fn regions_named(&self, names: &[String], used_by: &str) -> Result<Vec<NamedRegion>, AnalysisError> {
        names.iter().map(|n| self.region(n, used_by).cloned()).collect()
    }

    /// Checks names are unique, references resolve, shapes and tolerances are sane.
    pub fn validate(&self) -> Result<(), AnalysisError> {
        fn unique<'a>(kind: &'static str, names: impl Iterator<Item = &'a str>) -> Result<(), AnalysisError> {
            let mut seen = HashSet::new();
            for n in names {
                if !seen.insert(n) {
                    return Err(AnalysisError::DuplicateName { kind, name: n.to_string() });
                }
            }
            Ok(())
        }
        unique("region", self.regions.iter().map(|r| r.name.as_str()))?;
        unique("profile", self.profiles.iter().map(|p| p.name.as_str()))?;
        unique("measurement", self.measurements.iter().map(|m| m.name.as_str()))?;
        for r in &self.regions {
            r.validate()?;
        }
        for p in &self.profiles {
            p.validate()?;
        }
        self.regions_named(&self.level_to, "levelling (level_to)")?;
        for m in &self.measurements {
            let bad =
                |reason: &str| Err(AnalysisError::InvalidMeasurement { name: m.name.clone(), reason: reason.into() });
            if m.name.trim().is_empty() {
                return bad("the name is empty; give every measurement a name");
            }
            if let Some(t) = &m.tolerance {
                t.validate(&m.name)?;
            }
            if m.nominal.is_some_and(|v| !v.is_finite()) {
                return bad("the nominal value is not finite");
            }
            let used_by = format!("measurement '{}'", m.name);
            match &m.measure {
                Measure::StepHeight { reference, measured } => {
                    if reference.is_empty() || measured.is_empty() {
                        return bad("a step height needs at least one reference and one measured region");
                    }
                    self.regions_named(reference, &used_by)?;
                    self.regions_named(measured, &used_by)?;
                }
                Measure::Flatness { region, ls_mm, .. } => {
                    self.region(region, &used_by)?;
                    check_cutoffs(*ls_mm, None).or_else(|e| bad(&e))?;
                }
                Measure::Texture { region, form, ls_mm, lc_mm, smr_c_um, smc_mr_percent, limits } => {
                    if region != WHOLE_MAP {
                        self.region(region, &used_by)?;
                    }
                    if let FormRemoval::Polynomial(n) = form
                        && !(1..=10).contains(n)
                    {
                        return bad(&format!("form polynomial order {n} is outside 1..=10"));
                    }
                    check_cutoffs(*ls_mm, *lc_mm).or_else(|e| bad(&e))?;
                    if smr_c_um.is_some_and(|c| !c.is_finite()) {
                        return bad("the height c of Smr(c) is not finite");
                    }
                    if smc_mr_percent.is_some_and(|m| !(0.0..=100.0).contains(&m)) {
                        return bad("the material ratio mr of Smc(mr) is outside 0..100 %");
                    }
                    for (p, limit) in limits {
                        limit.tolerance.validate(&format!("{} {}", m.name, p.name()))?;
                        if limit.nominal.is_some_and(|v| !v.is_finite()) {
                            return bad(&format!("the nominal value of {} is not finite", p.name()));
                        }
                    }
                }
                Measure::ProfileTexture { profile, ls_mm, lc_mm, c_um, limits, .. } => {
                    if !self.profiles.iter().any(|p| &p.name == profile) {
                        return bad(&format!(
                            "profile '{profile}' is not defined; defined profiles: {}",
                            if self.profiles.is_empty() {
                                "none".to_string()
                            } else {
                                self.profiles.iter().map(|p| format!("'{}'", p.name)).collect::<Vec<_>>().join(", ")
                            }
                        ));
                    }
                    check_cutoffs(*ls_mm, *lc_mm).or_else(|e| bad(&e))?;
                    if c_um.is_some_and(|c| !c.is_finite()) {
                        return bad("the height c of Rmr(c) is not finite");
                    }
                    for (p, limit) in limits {
                        limit.tolerance.validate(&format!("{} {}", m.name, p.name()))?;
                        if limit.nominal.is_some_and(|v| !v.is_finite()) {
                            return bad(&format!("the nominal value of {} is not finite", p.name()));
                        }
                    }
                }
                Measure::Coplanarity { lands } => {
                    if lands.len() < 2 {
                        return bad("coplanarity needs at least two lands");
                    }
                    self.regions_named(lands, &used_by)?;
                }
                Measure::Tilt { regions } => {
                    if regions.is_empty() {
                        return bad("a tilt needs at least one region");
                    }
                    self.regions_named(regions, &used_by)?;
                }
            }
        }
        Ok(())
    }
}

/// What an inspection produced.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InspectionReport {
    /// The levelling plane, when the spec levels.
    pub levelling: Option<PlaneFit>,
    pub table: MeasurementTable,
    /// Profiles on the (levelled) map, in spec order.
    pub profiles: Vec<Profile>,
    pub warnings: Vec<Warning>,
    /// The R and W profiles of each profile texture measurement evaluated,
    /// for plotting (the table holds their parameters).
    #[serde(skip)]
    pub profile_textures: Vec<ProfileTextureCurves>,
}

/// The profiles one profile texture measurement evaluated.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileTextureCurves {
    /// The measurement's name (its rows are "NAME Ra", ...).
    pub measurement: String,
    pub profile: String,
    /// Distance along the profile of each sample (mm).
    pub distance_mm: Vec<f64>,
    pub lc_mm: f64,
    pub curves: crate::analysis::texture::profile_params::ProfileCurves,
}

fn plane_note(fit: &PlaneFit) -> String {
    format!(
        "'{}': {} samples of {} nodes, residual RMS {:.4} um",
        fit.region, fit.samples, fit.nodes_inside, fit.rms_um
    )
}

/// PV, RMS and a note of the region's S-filtered flatness (ISO 12781-2).
fn s_filtered_flatness(
    map: &HeightMap,
    region: &NamedRegion,
    fit: &PlaneFit,
    ls_mm: f64,
) -> Result<(f64, f64, String), AnalysisError> {
    let mask = region_mask(map, std::slice::from_ref(region));
    let too_few = AnalysisError::TooFewSamples { region: region.name.clone(), found: 0, needed: 3 };
    let c = crop(map, &mask).ok_or(too_few)?;
    let f = filtered_flatness(&c, ls_mm, fit.plane.cos_tilt(), &region.name)?;
    let edge = if f.edge_kept {
        format!(
            "every node lies within λs/4 of the region's edge or a hole ({:.1} % on a partial kernel), so PV and RMS \
             rest on edge values",
            f.filter.incomplete_percent()
        )
    } else {
        format!(
            "PV and RMS over {} nodes; {} edge node(s) within about λs/4 of the region's edge or a hole (kernel under \
             {:.0} % on data) left out",
            f.nodes,
            f.edge_nodes,
            100.0 * MIN_KERNEL_COVERAGE
        )
    };
    let mut note = format!("S-filter λs {ls_mm} mm (Gaussian, ISO 12781-2), {edge}; unfiltered {}", plane_note(fit));
    if let Some(n) = s_filter_note("map pitch", map.pitch_mm, Some(ls_mm)) {
        note = format!("near the resolution limit: {n}; {note}");
    }
    Ok((f.peak_to_valley_um, f.rms_um, note))
}

/// The node noise the Monte Carlo of texture and profile rows draws: the
/// smaller of the cloud's height noise and the median of the plane regions'
/// measured noise; the correlation the plane regions measured (a textured
/// region's own residual is its texture, not noise).
#[derive(Clone, Copy, Debug)]
struct TextureNoise {
    /// σ (um) and where it came from.
    sigma_um: Option<(f64, &'static str)>,
    correlation_factor: Option<f64>,
}

/// The variograms of an inspection's plane regions (levelling, steps,
/// flatness, lands, tilts), each set of regions once, by its label.
fn plane_noises(map: &HeightMap, spec: &InspectionSpec) -> PlaneNoises {
    let mut planes: Vec<Vec<String>> = vec![spec.level_to.clone()];
    for m in &spec.measurements {
        match &m.measure {
            Measure::StepHeight { reference, measured } => planes.extend([reference.clone(), measured.clone()]),
            Measure::Flatness { region, .. } => planes.push(vec![region.clone()]),
            Measure::Coplanarity { lands } => planes.extend(lands.iter().map(|l| vec![l.clone()])),
            Measure::Tilt { regions } => planes.push(regions.clone()),
            Measure::Texture { .. } | Measure::ProfileTexture { .. } => {}
        }
    }
    planes.retain(|names| !names.is_empty());
    planes.sort();
    planes.dedup();
    PlaneNoises::new(
        planes
            .iter()
            .filter_map(|names| {
                let regions = spec.regions_named(names, "noise").ok()?;
                let fit = fit_plane(map, &regions).ok()?;
                Some((label(&regions), region_variogram(map, &regions, &fit.plane)?))
            })
            .collect(),
    )
}

impl TextureNoise {
    fn of(spec: &InspectionSpec, cloud: Option<&HeightNoise>, planes: &PlaneNoises) -> Self {
        let textured = spec
            .measurements
            .iter()
            .any(|m| matches!(m.measure, Measure::Texture { .. } | Measure::ProfileTexture { .. }));
        if !textured {
            return Self { sigma_um: None, correlation_factor: None };
        }
        let mut sigmas: Vec<f64> = planes.by_label.iter().map(|(_, v)| v.sigma_um).collect();
        sigmas.sort_by(f64::total_cmp);
        // Both are upper bounds of the nodes' noise: the cloud's σz is a
        // point's, and the resampling interpolates points into nodes (on the
        // simulator's full-size step gauge 1.71 um against 0.76 um measured);
        // a plane region's measured noise keeps whatever of its form is not
        // a plane (a sine under a "plane" reads as noise). The smaller is the
        // tighter bound.
        let sigma_um = match (cloud, sigmas.get(sigmas.len() / 2).copied()) {
            (Some(n), Some(s)) if s < n.sigma_um => Some((s, "the plane regions' measured node noise")),
            (Some(n), _) => Some((n.sigma_um, "the cloud's height noise")),
            (None, s) => s.map(|s| (s, "the plane regions' measured node noise")),
        };
        Self { sigma_um, correlation_factor: planes.pooled_factor }
    }

    /// The noise and its description, `fallback_um` standing in for an
    /// unknown σ (the texture's own estimate from its second differences).
    fn resolve(&self, fallback_um: Option<f64>) -> Option<(NodeNoise, String)> {
        let (sigma, from) = self.sigma_um.or(fallback_um.map(|s| (s, "the surface's second differences")))?;
        let (factor, correlation) = match self.correlation_factor {
            Some(f) => (f, format!("{f:.1} nodes per independent one, measured on the plane regions")),
            None => (1.0, "nodes taken as independent: no plane region to measure the correlation on".into()),
        };
        Some((
            NodeNoise { sigma_um: sigma, correlation_factor: factor },
            format!("height noise (σ {sigma:.3} um per node from {from}; {correlation})"),
        ))
    }
}

/// The parts of an inspection the texture and profile rows of one
/// measurement share.
struct TextureRows<'a> {
    spec: &'a InspectionSpec,
    m: &'a MeasurementSpec,
    budgets: &'a Budgets<'a>,
    noise: &'a TextureNoise,
}

/// Monte Carlo trials of a texture on `nodes` nodes: fewer on a large
/// region (each trial filters and measures it all), at least 10.
fn texture_trials(trials: usize, nodes: usize) -> usize {
    const NODE_TRIALS: usize = 1 << 20;
    if trials == 0 { 0 } else { trials.min((NODE_TRIALS / nodes.max(1)).max(10)) }
}

impl TextureRows<'_> {
    /// One row per areal parameter of a texture measurement; a region without
    /// data gives rows without values (failing their limits), not an error.
    #[allow(clippy::too_many_arguments)]
    fn texture(
        &self,
        table: &mut MeasurementTable,
        map: &HeightMap,
        region: &str,
        settings: &TextureSettings,
        limits: &BTreeMap<ArealParameter, ParameterLimit>,
        noise: Option<&HeightNoise>,
        control: &RunControl,
    ) -> Result<(), AnalysisError> {
        let (spec, m) = (self.spec, self.m);
        let (mask, label) = match spec.regions.iter().find(|r| r.name == region) {
            Some(r) => (region_mask(map, std::slice::from_ref(r)), r.name.clone()),
            None if region == WHOLE_MAP => (vec![true; map.z.len()], "the whole map".to_string()),
            // validate() has refused an undefined region; this is its error.
            None => return spec.region(region, &format!("measurement '{}'", m.name)).map(|_| ()),
        };
        let result = crop(map, &mask)
            .ok_or(AnalysisError::TooFewSamples { region: label.clone(), found: 0, needed: 2 })
            .and_then(|c| measure_texture(&c, settings, noise, &label, control));
        if let Err(AnalysisError::Cancelled(c)) = result {
            return Err(c.into());
        }
        let uncertainties = match &result {
            Ok(r) => self.texture_uncertainties(map, region, &mask, settings, noise, r, control),
            Err(_) => vec![None; ArealParameter::ALL.len()],
        };
        for (p, u) in ArealParameter::ALL.into_iter().zip(uncertainties) {
            let limit = limits.get(&p);
            let name = format!("{} {}", m.name, p.name());
            let row = |value: Option<f64>| {
                MeasurementRow::new(name.clone(), MeasurementKind::Texture, value, p.unit())
                    .with_parameter(p.name())
                    .with_tolerance(limit.and_then(|l| l.nominal), limit.map(|l| l.tolerance))
                    .with_decision_rule(spec.decision_rule)
                    .with_uncertainty(u.clone())
            };
            table.push(match &result {
                Ok(r) => {
                    let near = if r.resolution_notes.is_empty() {
                        String::new()
                    } else {
                        format!("near the resolution limit: {}; ", r.resolution_notes.join("; "))
                    };
                    let at = match p {
                    ArealParameter::Smr => format!("c = {} um above the mean plane; ", settings.points.smr_c_um),
                    ArealParameter::Smc => format!("mr = {} %; ", settings.points.smc_mr_percent),
                    ArealParameter::Vmp | ArealParameter::Vmc | ArealParameter::Vvc | ArealParameter::Vvv => {
                        "p = 10 %, q = 80 %; um = um3/um2; ".to_string()
                    }
                    ArealParameter::Sal => "s = 0.2; ".to_string(),
                    ArealParameter::Str if r.spatial.is_some_and(|s| s.str_is_upper_bound) => {
                        "s = 0.2; an upper bound: the autocorrelation did not decay to s within half the surface in \
                         some direction (a lay); "
                            .to_string()
                    }
                    ArealParameter::Str => "s = 0.2; ".to_string(),
                    ArealParameter::Std => "direction of the lay from the X axis towards Y; ".to_string(),
                    _ => String::new(),
                };
                    let v = p.value(r);
                    row(v.is_finite().then_some(v)).with_note(format!("{near}{at}{} of {label}", r.description))
                }
                Err(e) => row(None).with_note(e.to_string()),
            });
        }
        Ok(())
    }

    /// Each areal parameter's uncertainty by Monte Carlo on the region.
    #[allow(clippy::too_many_arguments)]
    fn texture_uncertainties(
        &self,
        map: &HeightMap,
        region: &str,
        mask: &[bool],
        settings: &TextureSettings,
        noise: Option<&HeightNoise>,
        measured: &super::texture::measure::TextureResult,
        control: &RunControl,
    ) -> Vec<Option<Uncertainty>> {
        let none = vec![None; ArealParameter::ALL.len()];
        let Some(c) = crop(map, mask) else { return none };
        let Some(noise_and_source) = self.noise.resolve(super::texture::measure::height_noise_from_map_um(&c)) else {
            return none;
        };
        let window = [c.origin[0], c.origin[0] + c.width - 1, c.origin[1], c.origin[1] + c.height - 1];
        let nodes = mask.iter().filter(|m| **m).count();
        let values: Vec<(f64, &str)> = ArealParameter::ALL.iter().map(|p| (p.value(measured), p.unit())).collect();
        let region_def = self.spec.regions.iter().find(|r| r.name == region).cloned();
        let trials = texture_trials(self.budgets.trials, nodes);
        let extremes: Vec<bool> = ArealParameter::ALL.iter().map(|p| p.is_extreme()).collect();
        let crop_of = |w: &HeightMap| {
            let mask = match &region_def {
                Some(r) => region_mask(w, std::slice::from_ref(r)),
                None => vec![true; w.z.len()],
            };
            crop(w, &mask)
        };
        let measure = |w: &HeightMap| {
            let r = measure_texture(&crop_of(w)?, settings, noise, region, control).ok()?;
            Some(ArealParameter::ALL.iter().map(|p| p.value(&r)).collect())
        };
        // The noise floor needs the filtered surface's extremes only, not
        // the spatial parameters (an FFT each).
        let extremes_only = |w: &HeightMap| {
            let c = crop_of(w)?;
            let surface = scale_limited_surface(&c, settings, region).ok()?;
            let p =
                super::texture::areal::areal_parameters(&surface.z_um, c.width, c.height, c.pitch_mm, settings.points)?;
            Some(
                ArealParameter::ALL
                    .iter()
                    .map(|q| if q.is_extreme() { q.value_of(&p, None) } else { f64::NAN })
                    .collect(),
            )
        };
        let seed = seed_of(&self.m.name);
        self.budgets.parameters(window, &noise_and_source, trials, seed, &values, measure, (&extremes, extremes_only))
    }

    /// One row per profile parameter (R, then W, then P) of a section profile;
    /// a profile that cannot be evaluated gives rows without values.
    #[allow(clippy::too_many_arguments)]
    fn profile(
        &self,
        table: &mut MeasurementTable,
        map: &HeightMap,
        profile: &str,
        settings: &ProfileSettings,
        limits: &BTreeMap<ProfileParameter, ParameterLimit>,
        noise: Option<&HeightNoise>,
        curves: &mut Vec<ProfileTextureCurves>,
    ) {
        let (spec, m) = (self.spec, self.m);
        let profile_spec = spec.profiles.iter().find(|p| p.name == profile);
        let mut result = spec
            .profiles
            .iter()
            .find(|p| p.name == profile)
            .ok_or_else(|| format!("profile '{profile}' is not defined"))
            .and_then(|p| extract_profile(map, p).map_err(|e| e.to_string()))
            .and_then(|p| {
                let z: Vec<f64> = p.samples.iter().map(|s| if s.n > 0 { s.z_um } else { f64::NAN }).collect();
                let distance_mm: Vec<f64> = p.samples.iter().map(|s| s.distance_mm).collect();
                profile_parameters(&z, p.step_mm, settings)
                    .map(|r| (r, p.step_mm, distance_mm))
                    .map_err(|e| e.to_string())
            });
        // The rows below read the parameters only: the curves move to the plot.
        if let Ok((r, _, distance_mm)) = &mut result {
            curves.push(ProfileTextureCurves {
                measurement: m.name.clone(),
                profile: profile.to_string(),
                distance_mm: std::mem::take(distance_mm),
                lc_mm: r.lc_mm,
                curves: std::mem::take(&mut r.curves),
            });
        }
        let note = result.as_ref().map(|(r, step_mm, _)| {
            let notes: Vec<String> =
                [s_filter_note("profile step", *step_mm, r.ls_mm), noise_note("Rq", r.roughness.q_um, noise)]
                    .into_iter()
                    .flatten()
                    .collect();
            let near = if notes.is_empty() {
                String::new()
            } else {
                format!("near the resolution limit: {}; ", notes.join("; "))
            };
            format!(
                "{near}λc {} mm{}, λs {}; evaluation length {:.3} mm in {} section(s) (λc run-in and run-out left \
             out), {} samples; F-operator least-squares line; profile '{profile}'",
                r.lc_mm,
                match (r.lc_from_table, r.periodic) {
                    (true, true) => " (from RSm, periodic profile, ISO 21920-3)",
                    (true, false) => " (from Ra, ISO 21920-3)",
                    (false, _) => "",
                },
                r.ls_mm.map_or("none".to_string(), |ls| format!("{ls} mm")),
                r.evaluation_length_mm,
                r.sections,
                r.samples
            )
        });
        let parameters = ProfileParameter::all();
        let uncertainties = match (&result, profile_spec) {
            (Ok((r, _, _)), Some(ps)) => self.profile_uncertainties(map, ps, settings, r),
            _ => vec![None; parameters.len()],
        };
        for (p, u) in parameters.into_iter().zip(uncertainties) {
            let limit = limits.get(&p);
            let row = MeasurementRow::new(
                format!("{} {}", m.name, p.name()),
                MeasurementKind::ProfileTexture,
                None,
                p.unit(),
            )
            .with_parameter(p.name())
            .with_tolerance(limit.and_then(|l| l.nominal), limit.map(|l| l.tolerance))
            .with_decision_rule(spec.decision_rule)
            .with_uncertainty(u);
            table.push(match (&result, &note) {
                (Ok((r, _, _)), Ok(note)) => {
                    let v = p.value(r);
                    let extra = match p.measure {
                        super::texture::profile_params::ProfileMeasure::Mr => {
                            format!("c = {} um above the mean line; ", settings.c_um)
                        }
                        super::texture::profile_params::ProfileMeasure::Dc => "Rdc(20 %, 80 %); ".to_string(),
                        _ => String::new(),
                    };
                    MeasurementRow { value: v.is_finite().then_some(v), ..row }.with_note(format!("{extra}{note}"))
                }
                (Err(e), _) => row.with_note(e.clone()),
                (_, Err(e)) => row.with_note((*e).clone()),
            });
        }
    }

    /// Each profile parameter's uncertainty by Monte Carlo on the map around
    /// the section line.
    fn profile_uncertainties(
        &self,
        map: &HeightMap,
        profile: &ProfileSpec,
        settings: &ProfileSettings,
        measured: &super::texture::profile_params::ProfileParameters,
    ) -> Vec<Option<Uncertainty>> {
        let parameters = ProfileParameter::all();
        let none = vec![None; parameters.len()];
        let (a, b) = profile.end_points(map);
        let half = profile.width_mm / 2.0 + 2.0 * map.pitch_mm;
        let lo = [a[0].min(b[0]) - half, a[1].min(b[1]) - half];
        let hi = [a[0].max(b[0]) + half, a[1].max(b[1]) + half];
        let Some((c0, c1, r0, r1)) = node_window(map, lo, hi) else { return none };
        let Some(noise_and_source) = self.noise.resolve(None) else { return none };
        let values: Vec<(f64, &str)> = parameters.iter().map(|p| (p.value(measured), p.unit())).collect();
        let extremes: Vec<bool> = parameters.iter().map(|p| p.is_extreme()).collect();
        let measure = |w: &HeightMap| {
            let p = extract_profile(w, profile).ok()?;
            let z: Vec<f64> = p.samples.iter().map(|s| if s.n > 0 { s.z_um } else { f64::NAN }).collect();
            let r = profile_parameters(&z, p.step_mm, settings).ok()?;
            Some(parameters.iter().map(|q| q.value(&r)).collect())
        };
        let seed = seed_of(&self.m.name);
        let window = [c0, c1, r0, r1];
        self.budgets.parameters(
            window,
            &noise_and_source,
            self.budgets.trials,
            seed,
            &values,
            measure,
            (&extremes, measure),
        )
    }
}

/// The warnings the uncertainties raise: a tolerance no measurement can
/// prove conformity to, and a calibration that states no scale uncertainty.
fn uncertainty_warnings(table: &MeasurementTable, context: &MeasurementContext, warnings: &mut Vec<Warning>) {
    for row in table.rows.iter().filter(|r| r.tolerance_below_uncertainty()) {
        let (lo, hi) = row.limits().unwrap_or_default();
        let u = row.expanded_uncertainty();
        warnings.push(Warning::new(
            WarningKind::ToleranceBelowUncertainty,
            format!(
                "'{}': the tolerance {lo:.4} .. {hi:.4} {unit} is no wider than 2U = {:.4} {unit}: no measurement \
                 can prove conformity (ISO 14253-1); reduce the uncertainty or widen the tolerance",
                row.name,
                2.0 * u,
                unit = row.unit
            ),
        ));
    }
    let stated = table.rows.iter().any(|r| r.uncertainty.is_some());
    if stated && !context.calibration.is_some_and(|c| c.is_known()) {
        warnings.push(Warning::new(
            WarningKind::CalibrationUncertaintyUnknown,
            "the calibration states no scale uncertainty: the budgets take it as 0 (state it in the calibration \
             file's \"uncertainty\", or calibrate with Sheen)",
        ));
    }
}

impl Measure {
    /// A texture measurement's region and filter settings.
    pub fn texture_settings(&self) -> Option<(&str, TextureSettings)> {
        let Measure::Texture { region, form, ls_mm, lc_mm, smr_c_um, smc_mr_percent, .. } = self else {
            return None;
        };
        let settings = TextureSettings {
            form: *form,
            ls_mm: *ls_mm,
            lc_mm: *lc_mm,
            points: MaterialRatioPoints {
                smr_c_um: smr_c_um.unwrap_or(0.0),
                smc_mr_percent: smc_mr_percent.unwrap_or(10.0),
            },
        };
        Some((region.as_str(), settings))
    }
}

/// The scale-limited surface (µm) a texture measurement of `spec` evaluates,
/// placed on `map`'s grid (NaN outside its region), to be shown in place of
/// the heights: what the parameters describe is then what the operator sees.
pub fn texture_surface_on_map(
    map: &HeightMap,
    spec: &InspectionSpec,
    measurement: &str,
) -> Result<Vec<f32>, AnalysisError> {
    let m = spec.measurements.iter().find(|m| m.name == measurement);
    let Some((region, settings)) = m.and_then(|m| m.measure.texture_settings()) else {
        return Err(AnalysisError::InvalidMeasurement {
            name: measurement.to_string(),
            reason: "is no texture measurement of this inspection".into(),
        });
    };
    let mask = match spec.regions.iter().find(|r| r.name == region) {
        Some(r) => region_mask(map, std::slice::from_ref(r)),
        None if region == WHOLE_MAP => vec![true; map.z.len()],
        None => return spec.region(region, &format!("measurement '{measurement}'")).map(|_| Vec::new()),
    };
    let c = crop(map, &mask).ok_or(AnalysisError::TooFewSamples { region: region.to_string(), found: 0, needed: 2 })?;
    let surface = scale_limited_surface(&c, &settings, region)?;
    let mut out = vec![f32::NAN; map.z.len()];
    for (k, v) in surface.z_um.iter().enumerate() {
        let (c0, r0) = (c.origin[0] + k % c.width, c.origin[1] + k / c.width);
        out[r0 * map.width + c0] = *v as f32;
    }
    Ok(out)
}

/// What an inspection's uncertainties draw on besides the map.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeasurementContext<'a> {
    /// The cloud's height noise: texture rows are judged against it, and it
    /// is the node noise of their Monte Carlo.
    pub noise: Option<&'a HeightNoise>,
    /// The calibration's scale uncertainty; `None` where the input carries
    /// no calibration or it states none (the budgets then take it as 0 and
    /// a warning says so).
    pub calibration: Option<ScaleUncertainty>,
}

/// Runs `spec` on `map`: levels (if asked), measures, extracts profiles.
/// Texture values are compared with a height noise estimated from the map
/// ([`run_inspection_with_noise`] takes a measured one).
pub fn run_inspection(map: &HeightMap, spec: &InspectionSpec) -> Result<InspectionReport, AnalysisError> {
    run_inspection_with_noise(map, spec, None)
}

/// [`run_inspection`] with the measured height noise of the data (the
/// cloud's height uncertainty), which texture rows are judged against.
pub fn run_inspection_with_noise(
    map: &HeightMap,
    spec: &InspectionSpec,
    noise: Option<&HeightNoise>,
) -> Result<InspectionReport, AnalysisError> {
    run_inspection_controlled(map, spec, &MeasurementContext { noise, calibration: None }, &RunControl::new())
}

/// [`run_inspection_with_noise`] that stops with [`AnalysisError::Cancelled`]
/// between measurements and between the stages of a texture (filters,
/// parameters, spatial parameters) once `control` is cancelled: an
/// inspection of a full-size map takes seconds, and an edit or the operator
/// may make it obsolete.
pub fn run_inspection_controlled(
    map: &HeightMap,
    spec: &InspectionSpec,
    context: &MeasurementContext,
    control: &RunControl,
) -> Result<InspectionReport, AnalysisError> {
    spec.validate()?;
    let noise = context.noise;
    let mut warnings = Vec::new();
    let level_regions = spec.regions_named(&spec.level_to, "levelling (level_to)")?;
    let (levelled, levelling) = if spec.level_to.is_empty() {
        (Cow::Borrowed(map), None)
    } else {
        let l = level(map, &level_regions)?;
        (Cow::Owned(l.map), Some(l.reference))
    };
    let planes = plane_noises(map, spec);
    let budgets = Budgets {
        map,
        calibration: context.calibration.unwrap_or_default(),
        trials: spec.monte_carlo_trials.unwrap_or(DEFAULT_TRIALS),
        planes: Some(&planes),
    };
    let texture_noise = TextureNoise::of(spec, noise, &planes);
    let mut table = MeasurementTable::default();
    let mut profile_textures = Vec::new();
    for m in &spec.measurements {
        control.check()?;
        let row = |kind: MeasurementKind, value: Option<f64>, unit: &str| {
            MeasurementRow::new(m.name.clone(), kind, value, unit)
                .with_tolerance(m.nominal, m.tolerance)
                .with_decision_rule(spec.decision_rule)
        };
        let seed = seed_of(&m.name);
        let used_by = format!("measurement '{}'", m.name);
        match &m.measure {
            Measure::StepHeight { reference, measured } => {
                let (r, s) = (spec.regions_named(reference, &used_by)?, spec.regions_named(measured, &used_by)?);
                table.push(match step_height_pooled(map, &r, &s, budgets.planes) {
                    Ok(h) => row(MeasurementKind::StepHeight, Some(h.height_um), "um")
                        .with_note(format!(
                            "reference {}; measured {}; planes at {:.4} deg",
                            plane_note(&h.reference),
                            plane_note(&h.measured),
                            h.planes_angle_deg
                        ))
                        .with_uncertainty(Some(budgets.step(&h, &label(&r), &label(&s)))),
                    Err(e) => row(MeasurementKind::StepHeight, None, "um").with_note(e.to_string()),
                });
            }
            Measure::Flatness { region, statistic, ls_mm } => {
                let r = spec.region(region, &used_by)?;
                let kind = match statistic {
                    FlatnessStatistic::PeakToValley => MeasurementKind::FlatnessPeakToValley,
                    FlatnessStatistic::Rms => MeasurementKind::FlatnessRms,
                };
                let flatness_of = |m: &HeightMap, f: &PlaneFit| match ls_mm {
                    None => Ok((f.peak_to_valley_um(), f.rms_um, plane_note(f))),
                    Some(ls) => s_filtered_flatness(m, r, f, *ls),
                };
                let measured = fit_plane(map, std::slice::from_ref(r))
                    .and_then(|f| flatness_of(map, &f).map(|(pv, rms, note)| (f, pv, rms, note)));
                table.push(match measured {
                    Ok((fit, pv, rms, note)) => {
                        let k = match statistic {
                            FlatnessStatistic::PeakToValley => 0,
                            FlatnessStatistic::Rms => 1,
                        };
                        let u = match ls_mm {
                            None => budgets.flatness_unfiltered(r, &fit, seed),
                            Some(_) => budgets.flatness(r, &fit, [pv, rms], seed, |m| {
                                let f = fit_plane(m, std::slice::from_ref(r)).ok()?;
                                flatness_of(m, &f).ok().map(|(pv, rms, _)| (pv, rms))
                            }),
                        };
                        let note = match u.as_ref().and_then(|u| u[k].noise_floor) {
                            Some(floor) => format!("noise alone would give {floor:.4} um on these nodes; {note}"),
                            None => note,
                        };
                        let [pv_u, rms_u] = u.map_or([None, None], |[a, b]| [Some(a), Some(b)]);
                        row(kind, Some([pv, rms][k]), "um").with_note(note).with_uncertainty([pv_u, rms_u][k].clone())
                    }
                    Err(e) => row(kind, None, "um").with_note(e.to_string()),
                });
            }
            Measure::Texture { region, limits, .. } => {
                let Some((_, settings)) = m.measure.texture_settings() else { unreachable!("a texture") };
                let rows = TextureRows { spec, m, budgets: &budgets, noise: &texture_noise };
                rows.texture(&mut table, &levelled, region, &settings, limits, noise, control)?;
            }
            Measure::ProfileTexture { profile, ls_mm, lc_mm, c_um, periodic, limits } => {
                let settings = ProfileSettings {
                    s_filter: SFilter::from_spec(*ls_mm),
                    lc_mm: *lc_mm,
                    periodic: *periodic,
                    c_um: c_um.unwrap_or(0.0),
                };
                let rows = TextureRows { spec, m, budgets: &budgets, noise: &texture_noise };
                rows.profile(&mut table, &levelled, profile, &settings, limits, noise, &mut profile_textures);
            }
            Measure::Coplanarity { lands } => {
                let l = spec.regions_named(lands, &used_by)?;
                match coplanarity(map, &l) {
                    Ok(c) => {
                        let values: Vec<f64> = std::iter::once(c.coplanarity_um)
                            .chain(c.lands.iter().map(|l| l.max_abs_deviation_um()))
                            .collect();
                        let mut u = budgets.coplanarity(&l, &values, seed).map(Vec::into_iter);
                        let mut next_u = || u.as_mut().and_then(Iterator::next);
                        table.push(
                            row(MeasurementKind::Coplanarity, Some(c.coplanarity_um), "um")
                                .with_note(format!("common plane {}", plane_note(&c.common)))
                                .with_uncertainty(next_u()),
                        );
                        for land in &c.lands {
                            table.push(
                                MeasurementRow::new(
                                    format!("{} / {}", m.name, land.fit.region),
                                    MeasurementKind::LandDeviation,
                                    Some(land.max_abs_deviation_um()),
                                    "um",
                                )
                                .with_note(format!(
                                    "deviation {:.4} .. {:.4} um, {:.4} um at the land's centroid; {}",
                                    land.min_deviation_um,
                                    land.max_deviation_um,
                                    land.mean_deviation_um,
                                    plane_note(&land.fit)
                                ))
                                .with_uncertainty(next_u()),
                            );
                        }
                    }
                    Err(e) => table.push(row(MeasurementKind::Coplanarity, None, "um").with_note(e.to_string())),
                }
            }
            Measure::Tilt { regions } => {
                let r = spec.regions_named(regions, &used_by)?;
                table.push(match fit_plane(map, &r) {
                    Ok(f) => {
                        let tilt = match &levelling {
                            Some(reference) => f.plane.angle_to_deg(&reference.plane),
                            None => f.plane.tilt_deg(),
                        };
                        let reference = levelling.as_ref().map(|reference| (level_regions.as_slice(), reference));
                        row(MeasurementKind::PlaneTilt, Some(tilt), "deg")
                            .with_note(plane_note(&f))
                            .with_uncertainty(budgets.tilt(&r, &f, reference))
                    }
                    Err(e) => row(MeasurementKind::PlaneTilt, None, "deg").with_note(e.to_string()),
                });
            }
        }
    }
    let mut profiles = Vec::with_capacity(spec.profiles.len());
    for p in &spec.profiles {
        match extract_profile(&levelled, p) {
            Ok(profile) => {
                if profile.samples.iter().all(|s| s.n == 0) {
                    warnings.push(Warning::new(
                        WarningKind::ProfileOffSurface,
                        format!("profile '{}' runs outside the measured surface: it has no data", p.name),
                    ));
                }
                profiles.push(profile);
            }
            Err(e) => warnings.push(Warning::new(WarningKind::NotMeasured, e.to_string())),
        }
    }
    uncertainty_warnings(&table, context, &mut warnings);
    for row in &table.rows {
        if row.value.is_none() {
            warnings.push(Warning::new(
                WarningKind::NotMeasured,
                format!("'{}' was not measured: {}", row.name, row.note.as_deref().unwrap_or("")),
            ));
        }
    }
    Ok(InspectionReport { levelling, table, profiles, warnings, profile_textures })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::measurement_table::Verdict;
    use crate::analysis::testing::node_map;

    /// The texture's Monte Carlo draws the tighter of two upper bounds of
    /// the nodes' noise: the cloud's per-point σ and the plane regions'
    /// measured node noise.
    #[test]
    fn texture_noise_is_the_smaller_of_the_clouds_and_the_measured() {
        // 1 um of white noise on a flat plate (heights in mm).
        let map = node_map(120, 80, [0.0, 0.0], 0.01, |x, y| {
            let k = ((x * 1000.0).round() as u64).wrapping_mul(2654435761)
                ^ ((y * 1000.0).round() as u64).wrapping_mul(40503);
            let u1 = ((k >> 11) % 100_000) as f64 / 100_000.0 + 5e-6;
            let u2 = ((k.wrapping_mul(6364136223846793005) >> 13) % 100_000) as f64 / 100_000.0;
            Some(1e-3 * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos())
        });
        let spec = InspectionSpec::from_json(
            r#"{"sheen_inspection": 1,
                "regions": [{ "name": "plate", "region": { "shape": "rectangle", "x_mm": [0.05, 1.1], "y_mm": [0.05, 0.75] } }],
                "measurements": [
                  { "name": "flat", "measure": { "kind": "flatness", "region": "plate" } },
                  { "name": "tex", "measure": { "kind": "texture", "region": "plate" } }]}"#,
        )
        .expect("spec");
        let cloud = |sigma_um: f64| HeightNoise { sigma_um, source: "test".into() };
        let planes = plane_noises(&map, &spec);
        let measured = TextureNoise::of(&spec, None, &planes).sigma_um.expect("measured").0;
        assert!((measured - 1.0).abs() < 0.15, "the plane region measures the nodes' 1 um: {measured}");
        let (s, from) = TextureNoise::of(&spec, Some(&cloud(1.7)), &planes).sigma_um.expect("sigma");
        assert_eq!((s, from), (measured, "the plane regions' measured node noise"), "a per-point σ above the nodes'");
        let (s, from) = TextureNoise::of(&spec, Some(&cloud(0.5)), &planes).sigma_um.expect("sigma");
        assert_eq!((s, from), (0.5, "the cloud's height noise"), "a plane region that is not flat reads high");
    }

    /// A plate tilted 0.5 deg with a 20 um boss (circle) and a hole in the base.
    fn plate() -> HeightMap {
        let t = 0.5f64.to_radians().tan();
        node_map(300, 100, [0.0, 0.0], 0.01, move |x, y| {
            if (x - 0.5).hypot(y - 0.5) < 0.1 {
                return None;
            }
            let base = t * x + 0.1;
            let boss = if (x - 2.2).hypot(y - 0.5) < 0.3 { 0.020 / t.atan().cos() } else { 0.0 };
            Some(base + boss)
        })
    }

    const SPEC: &str = r#"{
        "sheen_inspection": 1,
        "level_to": ["base"],
        "regions": [
            { "name": "base", "region": { "shape": "rectangle", "x_mm": [0.05, 1.5], "y_mm": [0.05, 0.95] } },
            { "name": "boss", "region": { "shape": "circle", "centre_mm": [2.2, 0.5], "radius_mm": 0.25 } },
            { "name": "in the hole", "region": { "shape": "circle", "centre_mm": [0.5, 0.5], "radius_mm": 0.05 } }
        ],
        "profiles": [
            { "name": "A-A", "line": { "kind": "horizontal", "through_mm": [0, 0.5] }, "width_mm": 0.02 }
        ],
        "measurements": [
            { "name": "boss height", "measure": { "kind": "step_height", "reference": ["base"], "measured": ["boss"] },
              "nominal": 20.0, "tolerance": { "lower": -0.5, "upper": 0.5 } },
            { "name": "base flatness", "measure": { "kind": "flatness", "region": "base" },
              "tolerance": { "lower": 0, "upper": 1.0 } },
            { "name": "hole flatness", "measure": { "kind": "flatness", "region": "in the hole", "statistic": "rms" },
              "tolerance": { "lower": 0, "upper": 1.0 } },
            { "name": "lands", "measure": { "kind": "coplanarity", "lands": ["base", "boss"] } },
            { "name": "base tilt", "measure": { "kind": "tilt", "regions": ["base"] } }
        ]
    }"#;

    #[test]
    fn the_spec_runs_to_a_table_and_profiles() {
        let spec = InspectionSpec::from_json(SPEC).unwrap();
        let report = run_inspection(&plate(), &spec).unwrap();
        let lev = report.levelling.as_ref().unwrap();
        assert!((lev.plane.tilt_deg() - 0.5).abs() < 1e-6);
        let rows = &report.table.rows;
        let get = |name: &str| rows.iter().find(|r| r.name == name).unwrap();
        let boss = get("boss height");
        assert!((boss.value.unwrap() - 20.0).abs() < 1e-3, "{boss:?}");
        assert_eq!(boss.verdict(), Some(Verdict::Pass));
        assert!(get("base flatness").value.unwrap() < 1e-3);
        // Against the levelling reference the base has no tilt.
        assert!(get("base tilt").value.unwrap() < 1e-4);
        // The region inside the hole has no data: a failed row, not an error.
        let hole = get("hole flatness");
        assert!(hole.value.is_none() && hole.verdict() == Some(Verdict::Fail));
        assert!(hole.note.as_deref().unwrap().contains("in the hole"));
        assert_eq!(report.table.overall_verdict(), Some(Verdict::Fail));
        // Coplanarity as the function computes it on the unlevelled map, plus one row per land.
        let regions = |names: [&str; 2]| names.map(|n| spec.regions.iter().find(|r| r.name == n).unwrap().clone());
        let direct = coplanarity(&plate(), &regions(["base", "boss"])).unwrap();
        assert_eq!(get("lands").value, Some(direct.coplanarity_um));
        assert_eq!(get("lands / boss").value, Some(direct.lands[1].max_abs_deviation_um()));
        assert!(get("lands / boss").kind == MeasurementKind::LandDeviation);
        // The hole's row, and the calibration that states no scale uncertainty.
        let kinds: Vec<WarningKind> = report.warnings.iter().map(|w| w.kind).collect();
        assert_eq!(kinds, [WarningKind::CalibrationUncertaintyUnknown, WarningKind::NotMeasured]);
        // The profile runs along the levelled map: base at 0, boss at 20 um.
        let p = &report.profiles[0];
        let at = |x: f64| p.samples.iter().min_by(|a, b| (a.x_mm - x).abs().total_cmp(&(b.x_mm - x).abs())).unwrap();
        assert!(at(1.0).z_um.abs() < 1e-3 && (at(2.2).z_um - 20.0).abs() < 1e-3);
        assert!(at(0.5).z_um.is_nan());
    }

    #[test]
    fn specs_round_trip_and_bad_specs_say_what_is_wrong() {
        let spec = InspectionSpec::from_json(SPEC).unwrap();
        assert_eq!(InspectionSpec::from_json(&spec.to_json()).unwrap(), spec);
        let cases = [
            (SPEC.replace("\"sheen_inspection\": 1", "\"sheen_inspection\": 2"), "format version 2"),
            (SPEC.replace("\"sheen_inspection\": 1,", ""), "'sheen_inspection'"),
            (SPEC.replace("\"measured\": [\"boss\"]", "\"measured\": [\"bos\"]"), "region 'bos', which is not defined"),
            (SPEC.replace("\"upper\": 0.5", "\"uper\": 0.5"), "uper"),
            (SPEC.replace("\"lower\": -0.5", "\"lower\": 0.7"), "is not an interval"),
            (SPEC.replace("\"name\": \"boss\"", "\"name\": \"base\""), "two regions are named 'base'"),
            (SPEC.replace("\"lands\": [\"base\", \"boss\"]", "\"lands\": [\"base\"]"), "at least two lands"),
            ("[1, 2".to_string(), "not valid JSON"),
        ];
        for (text, expected) in cases {
            let e = InspectionSpec::from_json(&text).unwrap_err().to_string();
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
    }

    /// A sine of 0.4 um amplitude along X, 0.1 mm period, on a 0.5 deg tilt.
    fn sine_plate() -> HeightMap {
        let t = 0.5f64.to_radians().tan();
        node_map(1200, 40, [0.0, 0.0], 0.0025, move |x, _| {
            Some(0.2 + t * x + 0.0004 * (2.0 * std::f64::consts::PI * x / 0.1).sin())
        })
    }

    const TEXTURE_SPEC: &str = r#"{
        "sheen_inspection": 1,
        "regions": [ { "name": "face", "region": { "shape": "rectangle", "x_mm": [0.0, 3.0], "y_mm": [0.0, 0.1] } } ],
        "measurements": [
            { "name": "seal", "measure": { "kind": "texture", "region": "face", "ls_mm": 0.008, "lc_mm": 0.5,
              "limits": { "Sa": { "tolerance": { "lower": 0, "upper": 0.2 } },
                          "Sq": { "nominal": 0.2828, "tolerance": { "lower": -0.01, "upper": 0.01 } } } } },
            { "name": "whole", "measure": { "kind": "texture", "region": "all", "form": { "polynomial": 2 } } }
        ]
    }"#;

    #[test]
    fn texture_measurements_give_one_row_per_parameter_with_units_and_limits() {
        let spec = InspectionSpec::from_json(TEXTURE_SPEC).unwrap();
        assert_eq!(InspectionSpec::from_json(&spec.to_json()).unwrap(), spec);
        let report = run_inspection(&sine_plate(), &spec).unwrap();
        let rows = &report.table.rows;
        let get = |name: &str| rows.iter().find(|r| r.name == name).unwrap_or_else(|| panic!("{name}: {rows:?}"));
        assert_eq!(rows.len(), 2 * ArealParameter::ALL.len());
        let sq = get("seal Sq");
        assert_eq!((sq.kind, sq.parameter.as_deref(), sq.unit.as_str()), (MeasurementKind::Texture, Some("Sq"), "um"));
        // S-L surface of a sine at λc/5: the L-filter keeps it all, the S-filter
        // at λs = 0.008 mm keeps exp(-π (α 0.08)²) = 99.55 %; Sq = 0.4/√2 um.
        let kept = (-std::f64::consts::PI * (0.4697 * 0.08f64).powi(2)).exp();
        let want = 0.4 / 2f64.sqrt() * kept;
        assert!((sq.value.unwrap() - want).abs() < 0.01 * want, "{sq:?}");
        assert_eq!(sq.verdict(), Some(Verdict::Pass));
        // Sa = 2A/π = 0.2546 um against an upper limit of 0.2 um: fails.
        let sa = get("seal Sa");
        assert!((sa.value.unwrap() - 0.8 / std::f64::consts::PI * kept).abs() < 0.01 * 0.25, "{sa:?}");
        assert_eq!(sa.verdict(), Some(Verdict::Fail));
        assert_eq!(get("seal Sdr").unit, "%");
        assert_eq!(get("seal Ssk").unit, "1");
        assert_eq!(get("seal Sku").verdict(), None);
        assert!(
            get("seal Sq").note.as_deref().unwrap().contains("S-L surface; F-operator plane; λs 0.008 mm; λc 0.5 mm")
        );
        assert!(get("seal Smr").note.as_deref().unwrap().contains("c = 0 um"));
        // The whole map, form order 2, no S-filter: flagged near the resolution limit.
        let whole = get("whole Sq");
        assert!((whole.value.unwrap() - 0.4 / 2f64.sqrt()).abs() < 0.01 * 0.28, "{whole:?}");
        assert!(whole.note.as_deref().unwrap().starts_with("near the resolution limit: no S-filter"), "{whole:?}");
        assert_eq!(report.table.overall_verdict(), Some(Verdict::Fail));
    }

    #[test]
    fn bad_texture_specs_say_what_is_wrong() {
        for (from, to, expected) in [
            ("\"ls_mm\": 0.008", "\"ls_mm\": 0.9", "must be shorter than the L-filter cut-off"),
            ("\"lc_mm\": 0.5", "\"lc_mm\": -1", "not a positive length"),
            ("\"Sa\":", "\"Sx\":", "unknown variant `Sx`"),
            ("\"region\": \"face\"", "\"region\": \"fcae\"", "region 'fcae', which is not defined"),
            ("{ \"polynomial\": 2 }", "{ \"polynomial\": 0 }", "order 0"),
        ] {
            let text = TEXTURE_SPEC.replace(from, to);
            assert_ne!(text, TEXTURE_SPEC, "{from}");
            let e = InspectionSpec::from_json(&text).unwrap_err().to_string();
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
        // A spec of this version without the new fields still loads.
        let old = SPEC.replace(
            "\"kind\": \"flatness\", \"region\": \"base\"",
            "\"kind\": \"flatness\", \"region\": \"base\", \"ls_mm\": 0.05",
        );
        let spec = InspectionSpec::from_json(&old).unwrap();
        assert!(spec.measurements.iter().any(|m| matches!(m.measure, Measure::Flatness { ls_mm: Some(_), .. })));
        // Specs without the new fields write none of them.
        let json = InspectionSpec::from_json(SPEC).unwrap().to_json();
        assert!(!json.contains("ls_mm") && !json.contains("limits"), "{json}");
    }

    #[test]
    fn an_s_filter_lowers_the_flatness_of_a_rippled_plate_and_keeps_its_form() {
        // A plate with a 0.2 um ripple at 2.5 pitches (noise-like) and a 1 um
        // bow over its length: unfiltered PV sees both, the S-filtered PV only the bow.
        let map = node_map(400, 100, [0.0, 0.0], 0.0025, |x, y| {
            let ripple =
                if ((x / 0.0025).round() as i64 + (y / 0.0025).round() as i64) % 2 == 0 { 1e-4 } else { -1e-4 };
            Some(0.1 + 0.001 * ((x - 0.5) / 0.5).powi(2) + ripple)
        });
        let mut spec = InspectionSpec::from_json(SPEC).unwrap();
        spec.level_to.clear();
        spec.regions = vec![NamedRegion::new(
            "base",
            crate::analysis::region::Region::Rectangle { x_mm: [0.0, 1.0], y_mm: [0.0, 0.25] },
        )];
        let flat = |ls_mm| MeasurementSpec {
            name: format!("flat {ls_mm:?}"),
            measure: Measure::Flatness { region: "base".into(), statistic: FlatnessStatistic::PeakToValley, ls_mm },
            nominal: None,
            tolerance: None,
        };
        spec.measurements = vec![flat(None), flat(Some(0.025))];
        let report = run_inspection(&map, &spec).unwrap();
        let (raw, filtered) = (&report.table.rows[0], &report.table.rows[1]);
        assert!(raw.value.unwrap() > 0.8 + 0.15, "{raw:?}");
        // The bow's PV about its best plane: 1 um (ends to middle, x² on [-1, 1]).
        assert!((filtered.value.unwrap() - 1.0).abs() < 0.05, "{filtered:?}");
        assert!(filtered.note.as_deref().unwrap().contains("S-filter λs 0.025 mm"), "{filtered:?}");
    }

    #[test]
    fn profile_texture_specs_load_and_name_bad_parameters_and_profiles() {
        let item = r#"{ "name": "A-A", "measure": { "kind": "profile_texture", "profile": "A-A", "lc_mm": 0.25,
                        "limits": { "Ra": { "tolerance": { "lower": 0, "upper": 0.4 } } } } }"#;
        let text = SPEC.replace(
            "{ \"name\": \"base tilt\", \"measure\": { \"kind\": \"tilt\", \"regions\": [\"base\"] } }",
            &format!(
                "{{ \"name\": \"base tilt\", \"measure\": {{ \"kind\": \"tilt\", \"regions\": [\"base\"] }} }}, {item}"
            ),
        );
        assert_ne!(text, SPEC);
        let spec = InspectionSpec::from_json(&text).unwrap();
        assert_eq!(InspectionSpec::from_json(&spec.to_json()).unwrap(), spec);
        let report = run_inspection(&plate(), &spec).unwrap();
        let ra = report.table.rows.iter().find(|r| r.name == "A-A Ra").unwrap();
        assert_eq!(
            (ra.kind, ra.parameter.as_deref(), ra.unit.as_str()),
            (MeasurementKind::ProfileTexture, Some("Ra"), "um")
        );
        for (from, to, expected) in [
            ("\"Ra\":", "\"Rx\":", "unknown profile parameter 'Rx'"),
            ("\"profile\": \"A-A\"", "\"profile\": \"B\"", "profile 'B' is not defined; defined profiles: 'A-A'"),
        ] {
            let e = InspectionSpec::from_json(&text.replace(from, to)).unwrap_err().to_string();
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
    }
}
