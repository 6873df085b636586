//! The measured object as an exact heightfield `z = h(x, y)` (world millimetres:
//! X right, Y up the image, Z up towards the cameras).
//!
//! A scene is a list of *features* painted in order, like layers: each covers
//! its footprint with its surface, and the last feature covering a point sets
//! the height there. Where two features meet, the height jumps and the ray
//! caster meets a vertical wall, which is what real lands, pockets and bores
//! have. Heights and gradients are analytic, so truth points and shading
//! normals are exact, and the whole scene is plain data that serialises into
//! the truth file.

use serde::{Deserialize, Serialize};

use super::material::Material;

/// The scenes the simulator knows, named after what operators measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// Nickel-plated watch plate: lands at a few heights, pockets, a bore in a
    /// raised boss; brushed so that saturation varies across it.
    WatchPlate,
    /// Two steel gaskets: one flat, one bent by load with a circular indentation
    /// (the paper's Fig. 7).
    Gaskets,
    /// Circuit board: shiny tin pads and white silkscreen on green solder mask.
    Pcb,
    /// A threaded steel rod lying on the stage.
    ScrewThread,
    /// Metrology artefact: a plane, slightly tilted so levelling has work.
    Flat,
    /// Metrology artefact: blocks of known height (10, 50, 200, 500 um) on a base.
    StepGauge,
    /// Metrology artefact: a sphere cap of known radius and centre.
    Sphere,
    /// A bright part on a dark background, beside matte faces so dim that
    /// they carry 4-12 DN of modulation under a dark exposure (see
    /// [`SimConfig::camera_projector`](super::SimConfig::camera_projector)):
    /// where order decisions are hard.
    DimPart,
}

impl SceneKind {
    pub const ALL: [SceneKind; 8] = [
        SceneKind::WatchPlate,
        SceneKind::Gaskets,
        SceneKind::Pcb,
        SceneKind::ScrewThread,
        SceneKind::Flat,
        SceneKind::StepGauge,
        SceneKind::Sphere,
        SceneKind::DimPart,
    ];

    /// The scenes made of shiny metal, which saturate the camera.
    pub const SHINY: [SceneKind; 4] =
        [SceneKind::WatchPlate, SceneKind::Gaskets, SceneKind::Pcb, SceneKind::ScrewThread];

    pub fn name(self) -> &'static str {
        match self {
            SceneKind::WatchPlate => "watch-plate",
            SceneKind::Gaskets => "gaskets",
            SceneKind::Pcb => "pcb",
            SceneKind::ScrewThread => "screw-thread",
            SceneKind::Flat => "flat",
            SceneKind::StepGauge => "step-gauge",
            SceneKind::Sphere => "sphere",
            SceneKind::DimPart => "dim-part",
        }
    }

    pub fn is_shiny(self) -> bool {
        Self::SHINY.contains(&self)
    }
}

impl std::fmt::Display for SceneKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SceneKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SceneKind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<&str> = SceneKind::ALL.iter().map(|k| k.name()).collect();
            format!("unknown scene '{s}': expected one of {}", names.join(", "))
        })
    }
}

/// Where a feature covers the stage (its outline seen from above).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case")]
pub enum Footprint {
    /// The whole stage.
    All,
    /// An axis-aligned rectangle with rounded corners (`corner_radius_mm` 0: sharp).
    Rect {
        center_mm: [f64; 2],
        half_size_mm: [f64; 2],
        corner_radius_mm: f64,
    },
    Disc {
        center_mm: [f64; 2],
        radius_mm: f64,
    },
    Annulus {
        center_mm: [f64; 2],
        inner_radius_mm: f64,
        outer_radius_mm: f64,
    },
}

impl Footprint {
    #[inline]
    pub fn contains(&self, x: f64, y: f64) -> bool {
        match self {
            Footprint::All => true,
            Footprint::Rect { center_mm, half_size_mm, corner_radius_mm } => {
                let r = corner_radius_mm.min(half_size_mm[0]).min(half_size_mm[1]).max(0.0);
                let qx = (x - center_mm[0]).abs() - (half_size_mm[0] - r);
                let qy = (y - center_mm[1]).abs() - (half_size_mm[1] - r);
                if qx <= 0.0 || qy <= 0.0 { qx <= r && qy <= r } else { qx * qx + qy * qy <= r * r }
            }
            Footprint::Disc { center_mm, radius_mm } => {
                let (dx, dy) = (x - center_mm[0], y - center_mm[1]);
                dx * dx + dy * dy <= radius_mm * radius_mm
            }
            Footprint::Annulus { center_mm, inner_radius_mm, outer_radius_mm } => {
                let (dx, dy) = (x - center_mm[0], y - center_mm[1]);
                let r2 = dx * dx + dy * dy;
                r2 >= inner_radius_mm * inner_radius_mm && r2 <= outer_radius_mm * outer_radius_mm
            }
        }
    }

    /// Bounding box `[x_min, x_max, y_min, y_max]`, or `None` for the whole stage.
    pub fn bounds_mm(&self) -> Option<[f64; 4]> {
        match self {
            Footprint::All => None,
            Footprint::Rect { center_mm: c, half_size_mm: h, .. } => {
                Some([c[0] - h[0], c[0] + h[0], c[1] - h[1], c[1] + h[1]])
            }
            Footprint::Disc { center_mm: c, radius_mm: r }
            | Footprint::Annulus { center_mm: c, outer_radius_mm: r, .. } => {
                Some([c[0] - r, c[0] + r, c[1] - r, c[1] + r])
            }
        }
    }
}

/// A circular groove pressed into a surface: depth `depth_mm` at radius
/// `radius_mm` from `center_mm`, Gaussian across with standard deviation `width_mm`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RingDent {
    pub center_mm: [f64; 2],
    pub radius_mm: f64,
    pub width_mm: f64,
    pub depth_mm: f64,
}

/// The shape of a feature's top surface over its footprint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "surface", rename_all = "snake_case")]
pub enum Surface {
    /// `z = z0 + slope_x x + slope_y y`.
    Plane { z0_mm: f64, slope_x: f64, slope_y: f64 },
    /// Upper half of a sphere: `z = cz + sqrt(R^2 - (x - cx)^2 - (y - cy)^2)`;
    /// outside its outline the feature does not cover the point.
    SphereCap { center_mm: [f64; 3], radius_mm: f64 },
    /// A plate bent by load, lower in the middle and higher at both ends:
    /// `z = z0 + curvature/2 (x - xc)^2 - dent(x, y)`.
    Bent { z0_mm: f64, center_x_mm: f64, curvature_per_mm: f64, dent: Option<RingDent> },
    /// A plain rod along X: `z = zc + sqrt(R^2 - (y - yc)^2)`; beside it the
    /// feature does not cover the point.
    Cylinder { axis_y_mm: f64, axis_z_mm: f64, radius_mm: f64 },
    /// A threaded rod along X: the radius follows a truncated 60 degree thread
    /// profile (crest flat P/8, root flat P/4) along the helix coordinate
    /// `s = x - x0 - P asin((y - yc)/R) / (2 pi)`, and `z = zc + sqrt(r(s)^2 - (y - yc)^2)`;
    /// beside the rod the feature does not cover the point.
    Thread { axis_y_mm: f64, axis_z_mm: f64, major_radius_mm: f64, pitch_mm: f64, start_x_mm: f64 },
}

/// Height and gradient of the surface at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub z_mm: f64,
    pub dz_dx: f64,
    pub dz_dy: f64,
}

impl Surface {
    /// Height and gradient at `(x, y)`, or `None` where this surface leaves the
    /// point to the features below (beside a sphere or a rod).
    #[inline]
    pub fn eval(&self, x: f64, y: f64) -> Option<SurfacePoint> {
        match *self {
            Surface::Plane { z0_mm, slope_x, slope_y } => {
                Some(SurfacePoint { z_mm: z0_mm + slope_x * x + slope_y * y, dz_dx: slope_x, dz_dy: slope_y })
            }
            Surface::SphereCap { center_mm: c, radius_mm } => {
                let (dx, dy) = (x - c[0], y - c[1]);
                let q = radius_mm * radius_mm - dx * dx - dy * dy;
                if q <= 0.0 {
                    return None;
                }
                let s = q.sqrt();
                Some(SurfacePoint { z_mm: c[2] + s, dz_dx: -dx / s, dz_dy: -dy / s })
            }
            Surface::Bent { z0_mm, center_x_mm, curvature_per_mm, ref dent } => {
                let dx = x - center_x_mm;
                let mut p = SurfacePoint {
                    z_mm: z0_mm + 0.5 * curvature_per_mm * dx * dx,
                    dz_dx: curvature_per_mm * dx,
                    dz_dy: 0.0,
                };
                if let Some(d) = dent {
                    let (ex, ey) = (x - d.center_mm[0], y - d.center_mm[1]);
                    let r = ex.hypot(ey);
                    let t = (r - d.radius_mm) / d.width_mm;
                    let g = d.depth_mm * (-0.5 * t * t).exp();
                    p.z_mm -= g;
                    if r > 0.0 {
                        // d/dr of -g is g t / width; chain rule through r(x, y).
                        let dr = g * t / d.width_mm;
                        p.dz_dx += dr * ex / r;
                        p.dz_dy += dr * ey / r;
                    }
                }
                Some(p)
            }
            Surface::Cylinder { axis_y_mm, axis_z_mm, radius_mm } => {
                let dy = y - axis_y_mm;
                let q = radius_mm * radius_mm - dy * dy;
                if q <= 0.0 {
                    return None;
                }
                let w = q.sqrt();
                Some(SurfacePoint { z_mm: axis_z_mm + w, dz_dx: 0.0, dz_dy: -dy / w })
            }
            Surface::Thread { axis_y_mm, axis_z_mm, major_radius_mm, pitch_mm, start_x_mm } => {
                let dy = y - axis_y_mm;
                if dy.abs() >= major_radius_mm {
                    return None;
                }
                let root = (major_radius_mm * major_radius_mm - dy * dy).sqrt();
                let turns = (dy / major_radius_mm).asin() / std::f64::consts::TAU;
                let s = x - start_x_mm - pitch_mm * turns;
                let (r, dr_ds) = thread_radius(s, major_radius_mm, pitch_mm);
                let q = r * r - dy * dy;
                if q <= 0.0 {
                    return None;
                }
                let w = q.sqrt();
                // ds/dy = -P / (2 pi) * 1 / sqrt(R^2 - dy^2).
                let ds_dy = -pitch_mm / std::f64::consts::TAU / root;
                Some(SurfacePoint { z_mm: axis_z_mm + w, dz_dx: r * dr_ds / w, dz_dy: (r * dr_ds * ds_dy - dy) / w })
            }
        }
    }
}

/// Truncated ISO-like 60 degree thread: radius and its derivative along the
/// axis at helix coordinate `s`. Crest flat P/8 at the major radius, root flat
/// P/4, flanks of axial width 5P/16 each, so the depth is 5P/16 / tan 30 deg.
fn thread_radius(s: f64, major_radius_mm: f64, pitch_mm: f64) -> (f64, f64) {
    let p = pitch_mm;
    let depth = thread_depth_mm(p);
    let slope = depth / (5.0 * p / 16.0);
    let t = s.rem_euclid(p);
    let (crest, flank) = (p / 8.0, 5.0 * p / 16.0);
    if t < crest {
        (major_radius_mm, 0.0)
    } else if t < crest + flank {
        (major_radius_mm - slope * (t - crest), -slope)
    } else if t < crest + flank + p / 4.0 {
        (major_radius_mm - depth, 0.0)
    } else {
        (major_radius_mm - depth + slope * (t - crest - flank - p / 4.0), slope)
    }
}

/// Depth of the thread profile of [`Surface::Thread`] for pitch `pitch_mm`.
pub fn thread_depth_mm(pitch_mm: f64) -> f64 {
    5.0 * pitch_mm / 16.0 / (30f64).to_radians().tan()
}

/// One painted layer of a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Feature {
    pub name: String,
    pub footprint: Footprint,
    pub surface: Surface,
    /// Index into [`Scene::materials`].
    pub material: usize,
}

/// An axis-aligned region of the stage, e.g. where a land's top is measured
/// (kept clear of its walls).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Region {
    pub x_min_mm: f64,
    pub x_max_mm: f64,
    pub y_min_mm: f64,
    pub y_max_mm: f64,
}

impl Region {
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.x_min_mm && x <= self.x_max_mm && y >= self.y_min_mm && y <= self.y_max_mm
    }
}

/// A named quantity of a scene that accuracy tests and QC tools compare against.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Landmark {
    /// A plane `z = z0 + slope_x x + slope_y y`, measurable over `region`.
    Plane {
        name: String,
        z0_mm: f64,
        slope_x: f64,
        slope_y: f64,
        region: Region,
    },
    /// A step of `height_mm` between two level regions (measured minus reference).
    Step {
        name: String,
        reference: Region,
        measured: Region,
        height_mm: f64,
    },
    /// A level land at `height_mm`, measurable over `region`.
    Land {
        name: String,
        region: Region,
        height_mm: f64,
    },
    Sphere {
        name: String,
        center_mm: [f64; 3],
        radius_mm: f64,
    },
    /// A cylindrical bore with its floor at `floor_mm`.
    Bore {
        name: String,
        center_mm: [f64; 2],
        radius_mm: f64,
        floor_mm: f64,
    },
    /// A straight section line from `from_mm` to `to_mm` (the paper's Fig. 7 d-g).
    Section {
        name: String,
        from_mm: [f64; 2],
        to_mm: [f64; 2],
    },
    /// A thread of known pitch and radii.
    Thread {
        name: String,
        pitch_mm: f64,
        major_radius_mm: f64,
        minor_radius_mm: f64,
        axis_y_mm: f64,
        axis_z_mm: f64,
    },
}

impl Landmark {
    pub fn name(&self) -> &str {
        match self {
            Landmark::Plane { name, .. }
            | Landmark::Step { name, .. }
            | Landmark::Land { name, .. }
            | Landmark::Sphere { name, .. }
            | Landmark::Bore { name, .. }
            | Landmark::Section { name, .. }
            | Landmark::Thread { name, .. } => name,
        }
    }
}

/// What lies at one point of the stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StagePoint {
    pub surface: SurfacePoint,
    /// Index of the covering feature in [`Scene::features`].
    pub feature: usize,
}

/// Buckets of the stage listing, per cell, the features whose footprint may
/// cover it, so a height lookup tests a handful of features instead of all.
#[derive(Clone, Debug, Default, PartialEq)]
struct FeatureIndex {
    x0_mm: f64,
    y0_mm: f64,
    cell_mm: f64,
    cols: usize,
    rows: usize,
    /// Per cell, feature indices in painting order.
    cells: Vec<Vec<u16>>,
}

impl FeatureIndex {
    const CELL_MM: f64 = 0.5;

    fn new(features: &[Feature], extent: Region) -> Self {
        let cell = Self::CELL_MM;
        let cols = ((extent.x_max_mm - extent.x_min_mm) / cell).ceil().max(1.0) as usize;
        let rows = ((extent.y_max_mm - extent.y_min_mm) / cell).ceil().max(1.0) as usize;
        let mut cells = vec![Vec::new(); cols * rows];
        for (i, f) in features.iter().enumerate() {
            let i = i as u16;
            match f.footprint.bounds_mm() {
                None => cells.iter_mut().for_each(|c| c.push(i)),
                Some([x0, x1, y0, y1]) => {
                    let c0 = ((x0 - extent.x_min_mm) / cell).floor().max(0.0) as usize;
                    let c1 = (((x1 - extent.x_min_mm) / cell).floor().max(0.0) as usize).min(cols - 1);
                    let r0 = ((y0 - extent.y_min_mm) / cell).floor().max(0.0) as usize;
                    let r1 = (((y1 - extent.y_min_mm) / cell).floor().max(0.0) as usize).min(rows - 1);
                    for r in r0..=r1 {
                        for c in c0..=c1 {
                            cells[r * cols + c].push(i);
                        }
                    }
                }
            }
        }
        Self { x0_mm: extent.x_min_mm, y0_mm: extent.y_min_mm, cell_mm: cell, cols, rows, cells }
    }

    /// Feature indices that may cover `(x, y)`, in painting order; `None`
    /// when the index does not cover the point (or was never built).
    #[inline]
    fn candidates(&self, x: f64, y: f64) -> Option<&[u16]> {
        let c = ((x - self.x0_mm) / self.cell_mm).floor();
        let r = ((y - self.y0_mm) / self.cell_mm).floor();
        if c >= 0.0 && r >= 0.0 && (c as usize) < self.cols && (r as usize) < self.rows {
            Some(&self.cells[r as usize * self.cols + c as usize])
        } else {
            None
        }
    }
}

/// A complete object on the stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    pub kind: SceneKind,
    /// What it is, in words (for reports and the demo banner).
    pub description: String,
    pub materials: Vec<Material>,
    /// Painting order: the first must cover the whole stage.
    pub features: Vec<Feature>,
    pub landmarks: Vec<Landmark>,
    /// Where the projector is focused by default (operators focus on the part).
    pub focus_z_mm: f64,
    /// Camera exposure for this part: DN at full scale per unit of reflected
    /// projector white (tuned so the shiny parts saturate as in the paper).
    pub exposure: f64,
    /// Stage area the scene is defined over; rays leaving it miss.
    pub extent: Region,
    /// Where the part lies: its features are defined in its own frame and
    /// seen at `R(rotation) p + shift` on the stage.
    #[serde(default)]
    pub placement: super::PartPlacement,
    #[serde(skip)]
    index: FeatureIndex,
}

impl Scene {
    /// Assembles a scene; the first feature must cover the whole stage so
    /// every point inside `extent` has a height.
    pub fn new(
        kind: SceneKind,
        description: &str,
        materials: Vec<Material>,
        features: Vec<Feature>,
        landmarks: Vec<Landmark>,
        focus_z_mm: f64,
        exposure: f64,
    ) -> Self {
        debug_assert!(matches!(features.first().map(|f| &f.footprint), Some(Footprint::All)));
        debug_assert!(features.iter().all(|f| f.material < materials.len()));
        let extent = Region { x_min_mm: -16.0, x_max_mm: 16.0, y_min_mm: -12.0, y_max_mm: 12.0 };
        let index = FeatureIndex::new(&features, extent);
        Self {
            kind,
            description: description.to_owned(),
            materials,
            features,
            landmarks,
            focus_z_mm,
            exposure,
            extent,
            placement: super::PartPlacement::default(),
            index,
        }
    }

    /// The top surface at `(x, y)` and the feature it belongs to; `None`
    /// outside the scene's extent.
    #[inline]
    pub fn stage_point(&self, x: f64, y: f64) -> Option<StagePoint> {
        if !self.extent.contains(x, y) {
            return None;
        }
        let p = self.placement;
        if p != super::PartPlacement::default() {
            // The part's own frame: p = R^-1 (q - t); its gradient turns back with it.
            let (s, c) = p.rotation_deg.to_radians().sin_cos();
            let (dx, dy) = (x - p.shift_mm[0], y - p.shift_mm[1]);
            let point = self.part_point(c * dx + s * dy, -s * dx + c * dy)?;
            let (gx, gy) = (point.surface.dz_dx, point.surface.dz_dy);
            return Some(StagePoint {
                surface: SurfacePoint { dz_dx: c * gx - s * gy, dz_dy: s * gx + c * gy, ..point.surface },
                ..point
            });
        }
        self.part_point(x, y)
    }

    /// The top surface at `(x, y)` of the part's own frame.
    #[inline]
    fn part_point(&self, x: f64, y: f64) -> Option<StagePoint> {
        let top = |i: usize| {
            let f = &self.features[i];
            if f.footprint.contains(x, y) {
                f.surface.eval(x, y).map(|surface| StagePoint { surface, feature: i })
            } else {
                None
            }
        };
        match self.index.candidates(x, y) {
            Some(candidates) => candidates.iter().rev().find_map(|&i| top(usize::from(i))),
            None => (0..self.features.len()).rev().find_map(top),
        }
    }

    /// `h(x, y)` in millimetres; NaN outside the scene's extent.
    #[inline]
    pub fn height_mm(&self, x: f64, y: f64) -> f64 {
        self.stage_point(x, y).map_or(f64::NAN, |p| p.surface.z_mm)
    }

    pub fn material_of(&self, feature: usize) -> &Material {
        &self.materials[self.features[feature].material]
    }

    /// Restores the lookup index after deserialisation.
    pub fn reindex(&mut self) {
        self.index = FeatureIndex::new(&self.features, self.extent);
    }

    pub fn landmark(&self, name: &str) -> Option<&Landmark> {
        self.landmarks.iter().find(|l| l.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_gradients_match_finite_differences() {
        let surfaces = [
            Surface::Plane { z0_mm: 0.1, slope_x: 0.002, slope_y: -0.003 },
            Surface::SphereCap { center_mm: [0.5, -0.3, -2.0], radius_mm: 4.0 },
            Surface::Bent {
                z0_mm: 0.4,
                center_x_mm: 0.3,
                curvature_per_mm: 0.002,
                dent: Some(RingDent { center_mm: [0.0, 0.0], radius_mm: 1.0, width_mm: 0.2, depth_mm: 0.03 }),
            },
            Surface::Cylinder { axis_y_mm: 0.2, axis_z_mm: 0.0, radius_mm: 2.5 },
            Surface::Thread { axis_y_mm: 0.2, axis_z_mm: 0.0, major_radius_mm: 2.5, pitch_mm: 0.8, start_x_mm: 0.1 },
        ];
        let e = 1e-6;
        let mut checked = 0;
        for surface in &surfaces {
            for k in 0..400 {
                let (x, y) = (-2.0 + 0.0101 * k as f64, -1.5 + 0.0077 * k as f64);
                let (Some(p), Some(px0), Some(px1), Some(py0), Some(py1)) = (
                    surface.eval(x, y),
                    surface.eval(x - e, y),
                    surface.eval(x + e, y),
                    surface.eval(x, y - e),
                    surface.eval(x, y + e),
                ) else {
                    continue;
                };
                let (gx, gy) = ((px1.z_mm - px0.z_mm) / (2.0 * e), (py1.z_mm - py0.z_mm) / (2.0 * e));
                // Skip the thread profile's kinks, where the one-sided slopes differ.
                let (lx, rx) = ((p.z_mm - px0.z_mm) / e, (px1.z_mm - p.z_mm) / e);
                if (lx - rx).abs() > 1e-3 * (1.0 + lx.abs()) {
                    continue;
                }
                let tol = 1e-5 * (1.0 + gx.abs() + gy.abs());
                assert!(
                    (p.dz_dx - gx).abs() < tol && (p.dz_dy - gy).abs() < tol,
                    "{surface:?} at ({x}, {y}): {p:?} vs ({gx}, {gy})"
                );
                checked += 1;
            }
        }
        assert!(checked > 1500, "{checked}");
    }

    #[test]
    fn rounded_rectangle_and_annulus_footprints() {
        let r = Footprint::Rect { center_mm: [1.0, 2.0], half_size_mm: [3.0, 1.0], corner_radius_mm: 0.5 };
        assert!(r.contains(1.0, 2.0) && r.contains(3.9, 2.0) && r.contains(1.0, 2.99));
        assert!(!r.contains(4.1, 2.0) && !r.contains(1.0, 3.01));
        // The corner is cut: the square corner is outside, the arc's inside is in.
        assert!(!r.contains(3.98, 2.98));
        assert!(r.contains(3.5 + 0.3, 2.5 + 0.3));
        assert_eq!(r.bounds_mm(), Some([-2.0, 4.0, 1.0, 3.0]));
        let a = Footprint::Annulus { center_mm: [0.0, 0.0], inner_radius_mm: 1.0, outer_radius_mm: 2.0 };
        assert!(!a.contains(0.5, 0.0) && a.contains(1.5, 0.0) && !a.contains(2.1, 0.0));
    }

    #[test]
    fn later_features_cover_earlier_ones_and_rods_leave_the_stage_beside_them() {
        let scene = crate::sim::scenes::build(SceneKind::ScrewThread);
        // Beside the rod the stage shows; on the rod's top line the thread.
        let stage = scene.stage_point(0.0, 5.0).unwrap();
        assert_eq!(scene.features[stage.feature].name, "stage");
        let top = scene.stage_point(0.0, 0.0).unwrap();
        assert_eq!(scene.features[top.feature].name, "thread");
        assert!(scene.height_mm(0.0, 0.0) > scene.height_mm(0.0, 5.0) + 2.0);
        assert!(scene.height_mm(100.0, 0.0).is_nan());
    }
}
