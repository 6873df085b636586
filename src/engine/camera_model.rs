//! Telecentric (affine) camera model of the rig and its validation.
//!
//! Each camera maps a world point to its ideal pixel by `(u, v)^T = P (X, Y,
//! Z, 1)^T` (u = column, v = row, (0, 0) the centre of the top-left pixel); an
//! optional Brown-Conrady distortion then maps the ideal pixel to the observed
//! one. With the 2x3 part `M = [r1; r2]` the viewing direction is the null
//! vector of `M`, `d = r1 x r2 / |r1 x r2|` (image right x image down, from the
//! camera towards the scene).

use serde::{Deserialize, Serialize};

use super::length_unit::LengthUnit;

/// Lens distortion from the ideal to the observed pixel:
/// `x = (u - cx)/s`, `r2 = x^2 + y^2`,
/// `x_d = x (1 + k1 r2 + k2 r2^2) + 2 p1 x y + p2 (r2 + 2 x^2)`,
/// `y_d = y (1 + k1 r2 + k2 r2^2) + p1 (r2 + 2 y^2) + 2 p2 x y`,
/// `u_d = cx + s x_d`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Distortion {
    #[serde(rename = "center")]
    pub center_px: [f64; 2],
    pub scale_px: f64,
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
}

impl Distortion {
    /// The convention calibration writes: centre of the image, half its larger side.
    pub fn for_image(width: usize, height: usize) -> Self {
        Self {
            center_px: [(width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0],
            scale_px: width.max(height) as f64 / 2.0,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
        }
    }

    pub fn is_identity(&self) -> bool {
        self.k1 == 0.0 && self.k2 == 0.0 && self.p1 == 0.0 && self.p2 == 0.0
    }

    /// Ideal pixel -> observed pixel.
    #[inline]
    pub fn distort(&self, ideal: [f64; 2]) -> [f64; 2] {
        let s = self.scale_px;
        let x = (ideal[0] - self.center_px[0]) / s;
        let y = (ideal[1] - self.center_px[1]) / s;
        let r2 = x * x + y * y;
        let radial = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
        let xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
        [self.center_px[0] + s * xd, self.center_px[1] + s * yd]
    }

    /// Observed pixel -> ideal pixel, by Newton iteration on `distort` (the
    /// simulator renders through it; reconstruction never needs it).
    pub fn undistort(&self, observed: [f64; 2]) -> [f64; 2] {
        let mut p = observed;
        for _ in 0..30 {
            let d = self.distort(p);
            let r = [d[0] - observed[0], d[1] - observed[1]];
            if r[0].abs() < 1e-12 && r[1].abs() < 1e-12 {
                break;
            }
            // Numerical Jacobian: the map is smooth and close to identity.
            let h = 1e-6;
            let dx = self.distort([p[0] + h, p[1]]);
            let dy = self.distort([p[0], p[1] + h]);
            let j = [[(dx[0] - d[0]) / h, (dy[0] - d[0]) / h], [(dx[1] - d[1]) / h, (dy[1] - d[1]) / h]];
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if det.abs() < 1e-12 {
                break;
            }
            p[0] -= (j[1][1] * r[0] - j[0][1] * r[1]) / det;
            p[1] -= (-j[1][0] * r[0] + j[0][0] * r[1]) / det;
        }
        p
    }
}

/// One telecentric camera. It serialises itself in the calibration file's
/// shape (`width`, `height`, `P`, `distortion` when there is one), the one
/// writer of that shape: the calibration file, the simulator's rig and the
/// calibration report all write cameras through it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AffineCamera {
    pub width: usize,
    pub height: usize,
    /// `(u, v)^T = P (X, Y, Z, 1)^T`.
    #[serde(rename = "P")]
    pub p: [[f64; 4]; 2],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distortion: Option<Distortion>,
}

impl AffineCamera {
    /// Ideal (undistorted) pixel of a world point.
    #[inline]
    pub fn project(&self, x: [f64; 3]) -> [f64; 2] {
        let p = &self.p;
        [
            p[0][0] * x[0] + p[0][1] * x[1] + p[0][2] * x[2] + p[0][3],
            p[1][0] * x[0] + p[1][1] * x[1] + p[1][2] * x[2] + p[1][3],
        ]
    }

    /// Observed pixel of a world point (distortion applied).
    pub fn project_observed(&self, x: [f64; 3]) -> [f64; 2] {
        let ideal = self.project(x);
        match &self.distortion {
            Some(d) => d.distort(ideal),
            None => ideal,
        }
    }

    /// The lens distortion where it moves pixels: `None` without one or
    /// for the identity.
    #[inline]
    pub fn active_distortion(&self) -> Option<&Distortion> {
        self.distortion.as_ref().filter(|d| !d.is_identity())
    }

    /// Observed pixel of an ideal pixel.
    #[inline]
    pub fn observed_from_ideal(&self, ideal: [f64; 2]) -> [f64; 2] {
        self.active_distortion().map_or(ideal, |d| d.distort(ideal))
    }

    /// Ideal pixel of an observed pixel.
    pub fn ideal_from_observed(&self, observed: [f64; 2]) -> [f64; 2] {
        self.active_distortion().map_or(observed, |d| d.undistort(observed))
    }

    /// The rows `r1`, `r2` of the 2x3 part.
    pub fn rows(&self) -> ([f64; 3], [f64; 3]) {
        let p = &self.p;
        ([p[0][0], p[0][1], p[0][2]], [p[1][0], p[1][1], p[1][2]])
    }

    /// Unit viewing direction `r1 x r2 / |r1 x r2|`.
    pub fn viewing_direction(&self) -> [f64; 3] {
        let (r1, r2) = self.rows();
        normalize(cross(r1, r2))
    }

    /// Mean magnification in pixels per calibration unit.
    pub fn pixels_per_unit(&self) -> f64 {
        let (r1, r2) = self.rows();
        (norm(cross(r1, r2))).sqrt()
    }
}

/// The calibrated two-camera rig; the left camera is the main camera.
#[derive(Clone, Debug, PartialEq)]
pub struct StereoCalibration {
    /// Length unit of world coordinates (Sheen's rigs: mm).
    pub unit: LengthUnit,
    pub left: AffineCamera,
    pub right: AffineCamera,
    /// Reprojection RMS per camera, written by calibration.
    pub rms_reprojection_px: Option<[f64; 2]>,
    /// The scales' stated uncertainty (`"uncertainty"` in the file).
    pub scale_uncertainty: Option<ScaleUncertainty>,
}

/// What a calibration states of its own accuracy: the relative standard
/// uncertainties of the height (Z) and lateral (X-Y) scales it gives, as
/// the calibration file's `"uncertainty"` (a stated value, from a
/// calibration certificate or a step-gauge check). Every measured height
/// carries it in its budget (`analysis::uncertainty`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleUncertainty {
    /// u(Z scale) / Z scale.
    #[serde(default, rename = "height_scale_relative", skip_serializing_if = "Option::is_none")]
    pub height_relative: Option<f64>,
    /// u(X-Y scale) / X-Y scale.
    #[serde(default, rename = "lateral_scale_relative", skip_serializing_if = "Option::is_none")]
    pub lateral_relative: Option<f64>,
}

impl ScaleUncertainty {
    /// Whether the height scale's uncertainty is stated.
    pub fn is_known(&self) -> bool {
        self.height_relative.is_some()
    }

    /// The relative uncertainty of a slope (rise over run): both scales.
    pub fn slope_relative(&self) -> f64 {
        let h = self.height_relative.unwrap_or(0.0);
        let l = self.lateral_relative.unwrap_or(0.0);
        h.hypot(l)
    }
}

/// The calibration file: `{"model": "affine", "unit", "cameras": {"left",
/// "right"}}`, each camera with its reprojection RMS when calibration
/// measured one. `io::calibration` writes this value atomically and reads it.
impl Serialize for StereoCalibration {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        #[derive(Serialize)]
        struct Camera<'a> {
            #[serde(flatten)]
            camera: &'a AffineCamera,
            #[serde(skip_serializing_if = "Option::is_none")]
            rms_reprojection_px: Option<f64>,
        }
        #[derive(Serialize)]
        struct Cameras<'a> {
            left: Camera<'a>,
            right: Camera<'a>,
        }
        #[derive(Serialize)]
        struct File<'a> {
            model: &'static str,
            unit: LengthUnit,
            cameras: Cameras<'a>,
            #[serde(skip_serializing_if = "Option::is_none")]
            uncertainty: Option<ScaleUncertainty>,
        }
        let rms = self.rms_reprojection_px;
        File {
            model: "affine",
            unit: self.unit,
            cameras: Cameras {
                left: Camera { camera: &self.left, rms_reprojection_px: rms.map(|r| r[0]) },
                right: Camera { camera: &self.right, rms_reprojection_px: rms.map(|r| r[1]) },
            },
            uncertainty: self.scale_uncertainty,
        }
        .serialize(serializer)
    }
}

/// Why a calibration cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    #[error("camera '{camera}': P contains a non-finite number")]
    NonFinite { camera: &'static str },
    #[error("camera '{camera}': P has rank below 2 (its two rows are parallel or zero), so it cannot image a scene")]
    RankDeficient { camera: &'static str },
    #[error(
        "the cameras' viewing directions are parallel (angle {angle_deg:.4} deg): there is no stereo baseline; \
         check that left and right are two different cameras"
    )]
    ParallelViews { angle_deg: f64 },
    #[error("camera '{camera}': image size {width}x{height} px is empty")]
    EmptyImage { camera: &'static str, width: usize, height: usize },
    #[error("camera '{camera}': distortion has a non-finite or non-positive scale")]
    BadDistortion { camera: &'static str },
}

/// Viewing directions closer than this cannot triangulate meaningfully.
pub const MIN_STEREO_ANGLE_DEG: f64 = 0.5;

impl StereoCalibration {
    pub fn validate(&self) -> Result<(), CalibrationError> {
        for (name, cam) in [("left", &self.left), ("right", &self.right)] {
            if cam.p.iter().flatten().any(|v| !v.is_finite()) {
                return Err(CalibrationError::NonFinite { camera: name });
            }
            if cam.width == 0 || cam.height == 0 {
                return Err(CalibrationError::EmptyImage { camera: name, width: cam.width, height: cam.height });
            }
            let (r1, r2) = cam.rows();
            let c = norm(cross(r1, r2));
            if !(c > 1e-12 * (norm(r1) * norm(r2)).max(1e-300)) {
                return Err(CalibrationError::RankDeficient { camera: name });
            }
            if let Some(d) = &cam.distortion {
                let finite =
                    [d.center_px[0], d.center_px[1], d.scale_px, d.k1, d.k2, d.p1, d.p2].iter().all(|v| v.is_finite());
                if !finite || d.scale_px <= 0.0 {
                    return Err(CalibrationError::BadDistortion { camera: name });
                }
            }
        }
        let angle_deg = self.stereo_angle_deg();
        if angle_deg < MIN_STEREO_ANGLE_DEG {
            return Err(CalibrationError::ParallelViews { angle_deg });
        }
        Ok(())
    }

    /// Angle between the two viewing directions.
    pub fn stereo_angle_deg(&self) -> f64 {
        let dl = self.left.viewing_direction();
        let dr = self.right.viewing_direction();
        dot(dl, dr).clamp(-1.0, 1.0).acos().to_degrees()
    }
}

#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[inline]
pub fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    [a[0] / n, a[1] / n, a[2] / n]
}
