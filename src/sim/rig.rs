//! The virtual rig of the paper's section 2.3: two telecentric cameras in the
//! X-Z plane at +-theta from vertical and a projector looking straight down
//! with vertical fringes and a shallow depth of field.
//!
//! Geometry (world millimetres, X right, Y up the image, Z up towards the
//! cameras, origin at the field centre on the stage): the left camera sits on
//! the left and looks right-down, `d_L = (sin t, 0, -cos t)`, with its image
//! `u` axis along `(cos t, 0, sin t) / pitch` and `v` along `-Y / pitch`, so
//! `d = r1 x r2 / |r1 x r2|` as in [`AffineCamera::viewing_direction`]. The
//! right camera is its mirror image, `d_R = (-sin t, 0, -cos t)`, then rolled
//! about its axis, scaled and offset a little so rectification has work to do.
//!
//! The rig is independent of the scene: anything that is a heightfield (a
//! fringe scene, a calibration target in a pose) is imaged through the same
//! [`Rig`], and its cameras *are* the true calibration.

use serde::{Deserialize, Serialize};

use crate::engine::camera_model::{AffineCamera, Distortion, StereoCalibration};

/// Pixel pitch of the paper's cameras on the object: 3.45 um / 0.296x.
pub const PAPER_PIXEL_PITCH_MM: f64 = 0.00345 / 0.296;
/// The paper's sensor: 2048 x 1536 px.
pub const PAPER_WIDTH_PX: usize = 2048;
pub const PAPER_HEIGHT_PX: usize = 1536;
/// Field of view of the paper's cameras on the stage (about 23.9 x 17.9 mm);
/// the simulated field keeps this size at any resolution.
pub const FIELD_WIDTH_MM: f64 = PAPER_WIDTH_PX as f64 * PAPER_PIXEL_PITCH_MM;
pub const FIELD_HEIGHT_MM: f64 = PAPER_HEIGHT_PX as f64 * PAPER_PIXEL_PITCH_MM;

/// Projector settings (defaults: the paper's 912-px-wide fringe patterns).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProjectorConfig {
    /// Projector pixels across the pattern; the sparsest default period equals it.
    pub columns: usize,
    /// Width covered by the pattern on the stage, as a multiple of the field width.
    pub coverage: f64,
    /// Blur of the pattern at the focus, in projector pixels (Gaussian sigma).
    pub blur_sigma0_px: f64,
    /// Growth of the blur away from focus: `sigma = sigma0 + k |Z - focus|`.
    pub blur_px_per_mm: f64,
    /// Height of best focus; `None`: the scene's own focus height.
    pub focus_z_mm: Option<f64>,
    /// Fringe modulation of the pattern in focus (1: black fringes are black).
    pub modulation: f64,
}

impl Default for ProjectorConfig {
    fn default() -> Self {
        Self {
            columns: 912,
            coverage: 1.25,
            blur_sigma0_px: 1.6,
            blur_px_per_mm: 1.6,
            focus_z_mm: None,
            modulation: 0.95,
        }
    }
}

/// Camera placement (defaults: the paper's 15 degree rig with a right camera
/// rolled 2 degrees, 2 % larger magnification and offset by a few tenths of a millimetre).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigConfig {
    /// Angle of each camera from vertical.
    pub theta_deg: f64,
    /// Roll of the right camera about its viewing axis.
    pub right_roll_deg: f64,
    /// Magnification of the right camera relative to the left.
    pub right_scale: f64,
    /// Point of the stage (X, Y) seen by the right image centre; the left
    /// image centre sees the origin.
    pub right_offset_mm: [f64; 2],
    /// Radial distortion `k1` of both lenses (`Distortion::for_image` convention); 0: none.
    pub distortion_k1: f64,
    pub projector: ProjectorConfig,
}

impl Default for RigConfig {
    fn default() -> Self {
        Self {
            theta_deg: 15.0,
            right_roll_deg: 2.0,
            right_scale: 1.02,
            right_offset_mm: [0.35, -0.25],
            distortion_k1: 0.0,
            projector: ProjectorConfig::default(),
        }
    }
}

/// The projector: orthographic along -Z with vertical fringes; projector
/// column `x_p = center_column_px + X / pitch_mm` grows with X.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Projector {
    pub columns: usize,
    /// Stage millimetres per projector pixel.
    pub pitch_mm: f64,
    /// Projector column that lands on X = 0.
    pub center_column_px: f64,
    pub blur_sigma0_px: f64,
    pub blur_px_per_mm: f64,
    pub focus_z_mm: f64,
    pub modulation: f64,
}

impl Projector {
    /// Projector column `x_p` lighting a stage point at `x_mm`.
    #[inline]
    pub fn column_px(&self, x_mm: f64) -> f64 {
        self.center_column_px + x_mm / self.pitch_mm
    }

    /// Gaussian blur of the pattern at height `z_mm`, in projector pixels:
    /// `sigma(Z) = sigma0 + k |Z - focus|`.
    #[inline]
    pub fn blur_sigma_px(&self, z_mm: f64) -> f64 {
        self.blur_sigma0_px + self.blur_px_per_mm * (z_mm - self.focus_z_mm).abs()
    }

    /// Contrast kept by a sinusoid of period `period_px` under the blur at
    /// `z_mm`: the Fourier transform of the Gaussian, `exp(-2 pi^2 sigma^2 / p^2)`.
    /// Dense fringes lose contrast first (the paper's Fig. 2).
    #[inline]
    pub fn contrast(&self, z_mm: f64, period_px: f64) -> f64 {
        let sigma = self.blur_sigma_px(z_mm);
        (-2.0 * std::f64::consts::PI.powi(2) * sigma * sigma / (period_px * period_px)).exp()
    }
}

/// A camera ray: the stage points `(X, Y) = origin + slope Z` that one ideal
/// pixel sees, `slope = (d_x / d_z, d_y / d_z)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin_mm: [f64; 2],
    pub slope: [f64; 2],
}

impl Ray {
    #[inline]
    pub fn at(&self, z_mm: f64) -> [f64; 3] {
        [self.origin_mm[0] + self.slope[0] * z_mm, self.origin_mm[1] + self.slope[1] * z_mm, z_mm]
    }
}

/// Which of the two cameras.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CameraId {
    Left,
    Right,
}

impl CameraId {
    pub const BOTH: [CameraId; 2] = [CameraId::Left, CameraId::Right];

    pub fn name(self) -> &'static str {
        match self {
            CameraId::Left => "left",
            CameraId::Right => "right",
        }
    }

    pub fn other(self) -> CameraId {
        match self {
            CameraId::Left => CameraId::Right,
            CameraId::Right => CameraId::Left,
        }
    }
}

/// The assembled rig for one image size.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Rig {
    pub width: usize,
    pub height: usize,
    /// Left-camera pixel pitch on the stage (the right one is `/ right_scale`).
    pub pitch_mm: f64,
    pub theta_deg: f64,
    pub left: AffineCamera,
    pub right: AffineCamera,
    pub projector: Projector,
}

impl Rig {
    /// Builds the rig for `width` x `height` images; the field of view keeps
    /// the paper's size, so the resolution sets the pixel pitch. `focus_z_mm`
    /// is used where the projector configuration leaves the focus open.
    /// The caller validates the configuration (see `SimConfig::validate`).
    pub fn new(config: &RigConfig, width: usize, height: usize, focus_z_mm: f64) -> Self {
        let pitch = (FIELD_WIDTH_MM / width as f64).max(FIELD_HEIGHT_MM / height as f64);
        let (s, c) = config.theta_deg.to_radians().sin_cos();
        let center = [(width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0];
        let distortion = (config.distortion_k1 != 0.0)
            .then(|| Distortion { k1: config.distortion_k1, ..Distortion::for_image(width, height) });
        let left = AffineCamera {
            width,
            height,
            p: [[c / pitch, 0.0, s / pitch, center[0]], [0.0, -1.0 / pitch, 0.0, center[1]]],
            distortion,
        };
        // Mirror of the left camera, then (u, v) -> k R(roll) (u, v) + t with t
        // chosen so the image centre sees the offset point on the stage.
        let r1 = [c / pitch, 0.0, -s / pitch];
        let r2 = [0.0, -1.0 / pitch, 0.0];
        let (rs, rc) = config.right_roll_deg.to_radians().sin_cos();
        let k = config.right_scale;
        let row1: [f64; 3] = std::array::from_fn(|i| k * (rc * r1[i] - rs * r2[i]));
        let row2: [f64; 3] = std::array::from_fn(|i| k * (rs * r1[i] + rc * r2[i]));
        let o = [config.right_offset_mm[0], config.right_offset_mm[1], 0.0];
        let dot = |r: [f64; 3]| r[0] * o[0] + r[1] * o[1] + r[2] * o[2];
        let right = AffineCamera {
            width,
            height,
            p: [[row1[0], row1[1], row1[2], center[0] - dot(row1)], [row2[0], row2[1], row2[2], center[1] - dot(row2)]],
            distortion,
        };
        let pc = &config.projector;
        let projector = Projector {
            columns: pc.columns,
            pitch_mm: pc.coverage * FIELD_WIDTH_MM / pc.columns as f64,
            center_column_px: (pc.columns as f64 - 1.0) / 2.0,
            blur_sigma0_px: pc.blur_sigma0_px,
            blur_px_per_mm: pc.blur_px_per_mm,
            focus_z_mm: pc.focus_z_mm.unwrap_or(focus_z_mm),
            modulation: pc.modulation,
        };
        Self { width, height, pitch_mm: pitch, theta_deg: config.theta_deg, left, right, projector }
    }

    pub fn camera(&self, id: CameraId) -> &AffineCamera {
        match id {
            CameraId::Left => &self.left,
            CameraId::Right => &self.right,
        }
    }

    /// The true calibration of the rig, in the calibration contract's units.
    pub fn calibration(&self) -> StereoCalibration {
        StereoCalibration {
            unit: crate::engine::length_unit::LengthUnit::Mm,
            left: self.left.clone(),
            right: self.right.clone(),
            rms_reprojection_px: None,
            // The simulator's calibration is its truth: known, exactly.
            scale_uncertainty: Some(crate::engine::camera_model::ScaleUncertainty {
                height_relative: Some(0.0),
                lateral_relative: Some(0.0),
            }),
        }
    }

    /// Unit vector from the stage towards camera `id` (`-d`).
    pub fn to_camera(&self, id: CameraId) -> [f64; 3] {
        let d = self.camera(id).viewing_direction();
        [-d[0], -d[1], -d[2]]
    }

    /// The ray of an *ideal* (undistorted) pixel of camera `id`: solves the
    /// 2x2 system `M_xy (X, Y)^T = p - t - m_z Z` for `(X, Y)` as a function of Z.
    pub fn ray(&self, id: CameraId, ideal_px: [f64; 2]) -> Ray {
        let p = &self.camera(id).p;
        let (a, b, cc, d) = (p[0][0], p[0][1], p[1][0], p[1][1]);
        let det = a * d - b * cc;
        let inv = [[d / det, -b / det], [-cc / det, a / det]];
        let rhs = [ideal_px[0] - p[0][3], ideal_px[1] - p[1][3]];
        let mz = [p[0][2], p[1][2]];
        Ray {
            origin_mm: [inv[0][0] * rhs[0] + inv[0][1] * rhs[1], inv[1][0] * rhs[0] + inv[1][1] * rhs[1]],
            slope: [-(inv[0][0] * mz[0] + inv[0][1] * mz[1]), -(inv[1][0] * mz[0] + inv[1][1] * mz[1])],
        }
    }

    /// The ray through the centre of observed pixel `(u, v)` (distortion removed).
    pub fn pixel_ray(&self, id: CameraId, observed_px: [f64; 2]) -> Ray {
        self.ray(id, self.camera(id).ideal_from_observed(observed_px))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::camera_model::dot;

    fn rig() -> Rig {
        Rig::new(&RigConfig::default(), 256, 192, 0.0)
    }

    #[test]
    fn cameras_look_as_specified() {
        let r = rig();
        let t = 15f64.to_radians();
        let dl = r.left.viewing_direction();
        let dr = r.right.viewing_direction();
        for (got, want) in [(dl, [t.sin(), 0.0, -t.cos()]), (dr, [-t.sin(), 0.0, -t.cos()])] {
            assert!((0..3).all(|i| (got[i] - want[i]).abs() < 1e-12), "{got:?} vs {want:?}");
        }
        assert!((r.calibration().stereo_angle_deg() - 30.0).abs() < 1e-9);
        assert!(r.calibration().validate().is_ok());
        // Image centres see the field centre (left) and the offset point (right).
        let c = [127.5, 95.5];
        let pl = r.left.project([0.0, 0.0, 0.0]);
        let pr = r.right.project([0.35, -0.25, 0.0]);
        assert!((pl[0] - c[0]).abs() < 1e-12 && (pl[1] - c[1]).abs() < 1e-12);
        assert!((pr[0] - c[0]).abs() < 1e-12 && (pr[1] - c[1]).abs() < 1e-12);
        // The right camera is 2 % larger.
        assert!((r.right.pixels_per_unit() / r.left.pixels_per_unit() - 1.02).abs() < 1e-12);
    }

    #[test]
    fn rays_project_to_their_pixels() {
        let r = rig();
        for id in CameraId::BOTH {
            let d = r.camera(id).viewing_direction();
            let ray = r.ray(id, [37.25, 150.5]);
            for z in [-2.0, 0.0, 1.5] {
                let p = r.camera(id).project(ray.at(z));
                assert!((p[0] - 37.25).abs() < 1e-9 && (p[1] - 150.5).abs() < 1e-9, "{p:?}");
            }
            // The slope is the viewing direction's.
            let s = [d[0] / d[2], d[1] / d[2]];
            assert!((ray.slope[0] - s[0]).abs() < 1e-12 && (ray.slope[1] - s[1]).abs() < 1e-12);
        }
        let to_left = r.to_camera(CameraId::Left);
        assert!(dot(to_left, [0.0, 0.0, 1.0]) > 0.9);
    }

    #[test]
    fn contrast_follows_gaussian_blur() {
        let r = rig();
        let p = &r.projector;
        assert!((p.column_px(0.0) - 455.5).abs() < 1e-12);
        let sigma = p.blur_sigma_px(1.0);
        assert!((sigma - (p.blur_sigma0_px + p.blur_px_per_mm * 1.0)).abs() < 1e-12 && p.blur_px_per_mm > 0.0);
        let expected = (-2.0 * std::f64::consts::PI.powi(2) * sigma * sigma / 144.0).exp();
        assert!((p.contrast(1.0, 12.0) - expected).abs() < 1e-15);
        assert!(p.contrast(1.0, 12.0) < p.contrast(1.0, 24.0) && p.contrast(1.0, 24.0) < p.contrast(1.0, 912.0));
    }
}
