//! Ground truth of a simulation: what each camera pixel really sees, the
//! scene's height function and a sampled height grid, and the rig.
//!
//! Every map is row-major over its camera's image. Truth is exact: a surface
//! point is on its pixel's ray (it projects back onto the pixel centre through
//! the true calibration) and on the surface to 1e-12 mm.

use std::f64::consts::TAU;

use serde::Serialize;

use super::rig::{CameraId, Rig};
use super::scene_model::Scene;

/// Per pixel of one camera.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CameraTruth {
    pub camera: CameraId,
    pub width: usize,
    pub height: usize,
    /// First surface point on the pixel's ray (world mm); NaN where the ray misses.
    pub point_mm: Vec<[f64; 3]>,
    /// The point lies on a vertical wall (a step's side): it gets no projector light.
    pub on_wall: Vec<bool>,
    /// The point is also seen by the other camera (inside its image, not occluded).
    pub visible_in_other: Vec<bool>,
    /// Projector column `x_p` lighting the point; the true phase of a set of
    /// period `p` is `2 pi x_p / p`. NaN where the ray misses.
    pub projector_column_px: Vec<f64>,
    /// Mean intensity `A` (grey levels) before clipping.
    pub offset_dn: Vec<f32>,
    /// Fringe amplitude `B` (grey levels) in focus, before the defocus contrast and clipping.
    pub amplitude_dn: Vec<f32>,
}

impl CameraTruth {
    /// True absolute phase of a set of period `period_px` at `pixel`.
    pub fn phase_rad(&self, pixel: usize, period_px: f64) -> f64 {
        TAU * self.projector_column_px[pixel] / period_px
    }

    /// Pixels whose ray hits the scene.
    pub fn hit_count(&self) -> usize {
        self.point_mm.iter().filter(|p| !p[0].is_nan()).count()
    }
}

/// Heights of the scene sampled on a regular grid over the field: column `i`,
/// row `j` at `(x0 + i pitch, y0 - j pitch)` (rows run down the image, like Y
/// falling), NaN outside the scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeightGrid {
    /// `(x0, y0)`: the stage point of column 0, row 0.
    pub origin_mm: [f64; 2],
    pub pitch_mm: f64,
    pub cols: usize,
    pub rows: usize,
    pub z_mm: Vec<f64>,
}

impl HeightGrid {
    /// Samples `scene` over the rig's field at the left camera's pitch.
    pub fn sample(scene: &Scene, rig: &Rig) -> Self {
        use rayon::prelude::*;
        let (cols, rows, pitch) = (rig.width, rig.height, rig.pitch_mm);
        let origin = [-(cols as f64 - 1.0) / 2.0 * pitch, (rows as f64 - 1.0) / 2.0 * pitch];
        let z_mm = (0..rows * cols)
            .into_par_iter()
            .map(|i| scene.height_mm(origin[0] + (i % cols) as f64 * pitch, origin[1] - (i / cols) as f64 * pitch))
            .collect();
        Self { origin_mm: origin, pitch_mm: pitch, cols, rows, z_mm }
    }

    /// Stage position of a grid node.
    pub fn position_mm(&self, col: usize, row: usize) -> [f64; 2] {
        [self.origin_mm[0] + col as f64 * self.pitch_mm, self.origin_mm[1] - row as f64 * self.pitch_mm]
    }
}

/// Everything known about a simulated measurement.
#[derive(Clone, Debug, Serialize)]
pub struct Truth {
    /// The object: its height function `h(x, y)` ([`Scene::height_mm`]), materials and landmarks.
    pub scene: Scene,
    pub rig: Rig,
    pub left: CameraTruth,
    pub right: CameraTruth,
    pub height_grid: HeightGrid,
}

impl Truth {
    pub fn camera(&self, id: CameraId) -> &CameraTruth {
        match id {
            CameraId::Left => &self.left,
            CameraId::Right => &self.right,
        }
    }
}
