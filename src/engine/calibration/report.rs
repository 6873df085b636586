//! What a calibration run reports: per pose and camera the detections, their
//! residual vectors and RMS, the worst points, parameter standard deviations,
//! the rectification the stereo stage will use, and warnings.
//!
//! Rich enough for the calibration view (pose images with numbered
//! detections, magnified residual vectors, a per-pose RMS chart) and
//! serialisable as the report JSON of `sheen calibrate`.

use serde::Serialize;

use super::model::DistortionModel;
use super::refine::ParameterStd;
use super::target::Target;
use crate::engine::camera_model::AffineCamera;
use crate::engine::rectify::{RectMap, Rectification};

/// The whole report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CalibrationReport {
    pub target: Target,
    pub distortion_model: DistortionModel,
    pub cameras: Vec<CameraReport>,
    /// The poses used, in calibration-set order; the first is the world frame.
    pub poses: Vec<PoseReport>,
    pub skipped_poses: Vec<SkippedPoseReport>,
    /// The largest residuals over all poses and cameras (outliers included), largest first.
    pub worst_points: Vec<PointResidual>,
    pub parameters: Vec<ParameterStd>,
    /// RMS reprojection error over all used detections, `sqrt(mean(du^2 + dv^2))`.
    pub rms_reprojection_px: f64,
    /// Per-coordinate standard deviation of the detections from the median residual.
    pub robust_sigma_px: f64,
    /// Detections farther than this from their reprojection were set aside.
    pub outlier_threshold_px: f64,
    pub outliers: usize,
    pub iterations: usize,
    /// Smallest and largest tilt of a pose against pose 0.
    pub tilt_from_pose0_deg: [f64; 2],
    /// Largest angle between the target normals of any two poses.
    pub tilt_spread_deg: f64,
    pub stereo_angle_deg: f64,
    /// `None` when the cameras share no field of view (see the warnings).
    pub rectification: Option<RectificationReport>,
    /// Each with its `kind` and `message`; the set file's own come first.
    pub warnings: Vec<crate::engine::warning::Warning>,
}

/// One camera's result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CameraReport {
    pub camera: String,
    /// The fitted camera, written as in the calibration file.
    #[serde(flatten)]
    pub model: AffineCamera,
    /// `r1 x r2` normalised: from the camera towards the target.
    pub viewing_direction: [f64; 3],
    pub pixels_per_mm: f64,
    pub points: usize,
    pub outliers: usize,
    pub rms_reprojection_px: f64,
    pub max_reprojection_px: f64,
}

/// One used pose.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PoseReport {
    /// Index in the calibration set (skipped poses count).
    pub index: usize,
    pub name: String,
    /// Rotation vector (axis times angle) from the target frame to the world frame.
    pub rotation_deg: [f64; 3],
    pub translation_mm: [f64; 3],
    /// Angle between this pose's target plane and pose 0's.
    pub tilt_deg: f64,
    /// Left, then right.
    pub cameras: Vec<PoseCameraReport>,
}

/// One camera's view of one pose.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PoseCameraReport {
    pub camera: String,
    pub image: String,
    pub points: usize,
    pub outliers: usize,
    /// Over the points used.
    pub rms_reprojection_px: f64,
    pub max_reprojection_px: f64,
    /// Dot diameter or corner spacing in pixels.
    pub feature_size_px: f64,
    /// Detected pixel of each grid point, row-major (`i * cols + j`).
    pub detections_px: Vec<[f64; 2]>,
    /// Detected minus reprojected pixel, per grid point.
    pub residuals_px: Vec<[f64; 2]>,
    /// Per grid point: set aside as an outlier.
    pub outlier: Vec<bool>,
}

/// A pose that could not be used, and why (naming the image).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SkippedPoseReport {
    pub index: usize,
    pub name: String,
    pub reason: String,
}

/// One detection and its residual.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PointResidual {
    pub pose: String,
    pub pose_index: usize,
    pub camera: String,
    pub image: String,
    pub row: usize,
    pub col: usize,
    pub detected_px: [f64; 2],
    pub residual_px: [f64; 2],
    pub error_px: f64,
    pub outlier: bool,
}

/// The rectified geometry the stereo stage would use with this calibration.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RectificationReport {
    pub rows: usize,
    pub left: RectMapReport,
    pub right: RectMapReport,
    /// Whether the left map is an integer shift (left pixels kept exactly).
    pub left_is_integer_shift: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RectMapReport {
    pub width: usize,
    /// `(c, r)^T = to_rect (u, v, 1)^T` from ideal camera pixels.
    pub to_rect: [[f64; 3]; 2],
}

impl RectificationReport {
    pub fn new(rect: &Rectification) -> Self {
        let map = |m: &RectMap| RectMapReport { width: m.width, to_rect: m.to_rect };
        Self {
            rows: rect.rows,
            left: map(&rect.left),
            right: map(&rect.right),
            left_is_integer_shift: rect.left.is_integer_shift(),
        }
    }
}

impl CameraReport {
    pub(crate) fn summary(name: &str, cam: &AffineCamera) -> Self {
        Self {
            camera: name.to_owned(),
            model: cam.clone(),
            viewing_direction: cam.viewing_direction(),
            pixels_per_mm: cam.pixels_per_unit(),
            points: 0,
            outliers: 0,
            rms_reprojection_px: 0.0,
            max_reprojection_px: 0.0,
        }
    }
}

impl CalibrationReport {
    /// RMS reprojection error of the left and right camera.
    pub fn rms_per_camera(&self) -> [f64; 2] {
        [0, 1].map(|c| self.cameras.get(c).map_or(0.0, |r| r.rms_reprojection_px))
    }
}

/// `sqrt(mean(|r|^2))` and `max |r|` over the selected residuals.
pub(crate) fn rms_and_max(residuals: impl Iterator<Item = [f64; 2]>) -> (f64, f64, usize) {
    let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
    for r in residuals {
        let e2 = r[0] * r[0] + r[1] * r[1];
        sum += e2;
        max = max.max(e2.sqrt());
        n += 1;
    }
    ((sum / n.max(1) as f64).sqrt(), max, n)
}
