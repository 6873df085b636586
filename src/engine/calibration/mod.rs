//! Calibration of the telecentric stereo rig from images of a planar target
//! in several tilted poses (after Hu et al. 2019 and Chen et al.
//! 2014 for telecentric stereo).
//!
//! Pipeline: [`detect::detect_target`] finds and orders the target's points
//! in each image ([`detect_pose`] skips a pose that is not complete in both
//! cameras, naming the image); [`closed_form::closed_form`] computes both
//! affine cameras and all poses from the per-image affine maps;
//! [`refine::refine`] refines everything jointly (Levenberg-Marquardt, robust
//! to a few bad detections); [`solve`] assembles the calibration, names the
//! cameras (the left camera looks to the right: this resolves the mirror
//! through the target plane) and writes the [`report::CalibrationReport`].
//!
//! Architecture invariant: pure computation over in-memory images; reading a
//! calibration set from disk is `io::calibration_set`.

pub mod camera_projector;
pub mod closed_form;
pub mod detect;
pub mod detect_checkerboard;
pub mod detect_circles;
pub mod gray_image;
pub mod grid;
pub mod model;
pub mod refine;
pub mod report;
pub mod scale;
pub mod target;

use rayon::prelude::*;

use self::closed_form::{ClosedFormError, closed_form};
use self::detect::{DetectionError, DetectionParams, TargetDetection, detect_target};
use self::gray_image::GrayImage;
use self::model::{DistortionModel, RigModel};
use self::refine::{Observation, RefineError, RefineOptions, Refined, refine};
use self::report::{
    CalibrationReport, CameraReport, PointResidual, PoseCameraReport, PoseReport, RectificationReport,
    SkippedPoseReport, rms_and_max,
};
use self::target::{Target, TargetError};
use super::camera_model::{CalibrationError, StereoCalibration, dot};
use super::control::{Cancelled, RunControl};
use super::rectify::rectify;
use super::warning::{Warning, WarningKind};

/// Calibration needs at least this many usable poses.
pub const MIN_POSES: usize = 3;
/// Fewer usable poses than this earn a warning.
pub const RECOMMENDED_POSES: usize = 4;
/// Poses whose normals span less than this angle earn a warning.
pub const MIN_TILT_SPREAD_DEG: f64 = 10.0;
/// How many of the largest residuals the report lists.
pub const WORST_POINTS: usize = 10;

pub const CAMERA_NAMES: [&str; 2] = ["left", "right"];

/// The ordered points of one usable pose in both cameras.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseObservations {
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
}

/// Where a pose comes from, for messages and the report.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PoseSource {
    /// Index in the calibration set.
    pub index: usize,
    pub name: String,
    /// How the images are named to the user (relative paths).
    pub left_image: String,
    pub right_image: String,
}

/// A pose whose target was found completely in both cameras.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseDetections {
    pub source: PoseSource,
    /// Width and height of the left and right images.
    pub image_size_px: [[usize; 2]; 2],
    pub left: TargetDetection,
    pub right: TargetDetection,
}

/// A pose left out, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct SkippedPose {
    pub source: PoseSource,
    /// Names the image(s) and what was wrong with each.
    pub reason: String,
    /// The detection failure of each camera that failed (0 left, 1 right).
    pub errors: Vec<(usize, DetectionError)>,
}

/// Settings of a calibration run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationOptions {
    pub distortion: DistortionModel,
    pub detection: DetectionParams,
    pub outlier_threshold_sigma: f64,
    pub min_outlier_threshold_px: f64,
    pub max_iterations: usize,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        let refine = RefineOptions::default();
        Self {
            distortion: DistortionModel::K1,
            detection: DetectionParams::default(),
            outlier_threshold_sigma: refine.outlier_threshold_sigma,
            min_outlier_threshold_px: refine.min_outlier_threshold_px,
            max_iterations: refine.max_iterations,
        }
    }
}

/// Why no calibration came out.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CalibrateError {
    #[error(transparent)]
    Target(#[from] TargetError),
    #[error(
        "only {usable} pose(s) have the complete target in both cameras; at least {required} are needed{}",
        describe_skipped(.skipped)
    )]
    TooFewPoses { usable: usize, required: usize, skipped: Vec<String> },
    #[error(
        "{pose}: the {camera} image is {found_w}x{found_h} px, but the {camera} images of the other poses are \
         {expected_w}x{expected_h} px; all poses of a camera must come from the same sensor setting"
    )]
    ImageSize {
        pose: String,
        camera: &'static str,
        found_w: usize,
        found_h: usize,
        expected_w: usize,
        expected_h: usize,
    },
    #[error("{pose}: {camera} detection has {found} points, the target has {expected}")]
    PointCount { pose: String, camera: &'static str, found: usize, expected: usize },
    #[error(transparent)]
    ClosedForm(#[from] ClosedFormError),
    #[error(transparent)]
    Refine(RefineError),
    #[error("the fitted calibration is unusable: {0}")]
    Invalid(#[from] CalibrationError),
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

impl From<RefineError> for CalibrateError {
    fn from(e: RefineError) -> Self {
        match e {
            RefineError::Cancelled(c) => CalibrateError::Cancelled(c),
            other => CalibrateError::Refine(other),
        }
    }
}

fn describe_skipped(skipped: &[String]) -> String {
    if skipped.is_empty() { String::new() } else { format!(". Skipped: {}", skipped.join("; ")) }
}

/// What detection made of one pose. Not an error either way: a skipped pose
/// is reported and the others are used.
#[derive(Clone, Debug, PartialEq)]
pub enum PoseOutcome {
    Detected(PoseDetections),
    Skipped(SkippedPose),
}

/// Detects the target in both images of a pose; a pose whose target is not
/// complete in both is skipped with the reason, naming the image(s).
pub fn detect_pose(
    source: PoseSource,
    left: &GrayImage,
    right: &GrayImage,
    target: &Target,
    params: &DetectionParams,
) -> PoseOutcome {
    let (l, r) = rayon::join(|| detect_target(left, target, params), || detect_target(right, target, params));
    match (l, r) {
        (Ok(left_detection), Ok(right_detection)) => PoseOutcome::Detected(PoseDetections {
            image_size_px: [[left.width, left.height], [right.width, right.height]],
            source,
            left: left_detection,
            right: right_detection,
        }),
        (l, r) => {
            let errors: Vec<(usize, DetectionError)> =
                [l.err(), r.err()].into_iter().enumerate().filter_map(|(c, e)| e.map(|e| (c, e))).collect();
            let reason = errors
                .iter()
                .map(|(c, e)| format!("{}: {e}", if *c == 0 { &source.left_image } else { &source.right_image }))
                .collect::<Vec<_>>()
                .join("; ");
            PoseOutcome::Skipped(SkippedPose { reason, errors, source })
        }
    }
}

/// Detection over many poses (in parallel) followed by [`solve`]: the whole
/// calibration for images already in memory.
pub fn calibrate_images(
    target: &Target,
    poses: &[(PoseSource, GrayImage, GrayImage)],
    options: &CalibrationOptions,
    control: &RunControl,
) -> Result<(StereoCalibration, CalibrationReport), CalibrateError> {
    target.validate()?;
    control.begin_stage("target detection");
    let results: Vec<PoseOutcome> =
        poses.par_iter().map(|(source, l, r)| detect_pose(source.clone(), l, r, target, &options.detection)).collect();
    control.check()?;
    let mut found = Vec::new();
    let mut skipped = Vec::new();
    for result in results {
        match result {
            PoseOutcome::Detected(p) => found.push(p),
            PoseOutcome::Skipped(s) => skipped.push(s),
        }
    }
    solve(target, &found, &skipped, options, control)
}

/// Calibrates the rig from the detections of the usable poses (in set order;
/// the first is the world frame) and reports on it, including the poses that
/// were skipped.
pub fn solve(
    target: &Target,
    poses: &[PoseDetections],
    skipped: &[SkippedPose],
    options: &CalibrationOptions,
    control: &RunControl,
) -> Result<(StereoCalibration, CalibrationReport), CalibrateError> {
    target.validate()?;
    let skipped_text: Vec<String> =
        skipped.iter().map(|s| format!("{} skipped: {}", s.source.name, s.reason)).collect();
    if poses.len() < MIN_POSES {
        return Err(CalibrateError::TooFewPoses { usable: poses.len(), required: MIN_POSES, skipped: skipped_text });
    }
    let sizes = check_detections(target, poses)?;
    let expected = target.point_count();
    control.begin_stage("closed-form start");
    let observations: Vec<PoseObservations> = poses
        .iter()
        .map(|p| PoseObservations { left_px: p.left.points_px.clone(), right_px: p.right.points_px.clone() })
        .collect();
    let start = closed_form(target, &observations, sizes)?;
    control.check()?;
    control.begin_stage("bundle adjustment");
    let mut obs = Vec::with_capacity(2 * expected * poses.len());
    for (k, pose) in observations.iter().enumerate() {
        for (c, points) in [&pose.left_px, &pose.right_px].into_iter().enumerate() {
            for (point, &observed_px) in points.iter().enumerate() {
                obs.push(Observation { pose: k, camera: c, point, observed_px });
            }
        }
    }
    let names: Vec<String> = poses.iter().map(|p| p.source.name.clone()).collect();
    let refine_options = RefineOptions {
        distortion: options.distortion,
        outlier_threshold_sigma: options.outlier_threshold_sigma,
        min_outlier_threshold_px: options.min_outlier_threshold_px,
        max_iterations: options.max_iterations,
    };
    let refined = refine(&start, target, &obs, &names, &refine_options, control)?;
    let model = &refined.model;

    let cameras = camera_reports(model, &obs, &refined);
    let pose_reports = pose_reports(poses, model, &refined, expected);
    let worst = worst_points(target, poses, &obs, &refined);

    let (rms_all, _, _) =
        rms_and_max(refined.residuals_px.iter().zip(&refined.inlier).filter(|(_, k)| **k).map(|(r, _)| *r));
    let outliers = refined.inlier.iter().filter(|k| !**k).count();
    let (tilt_from_pose0_deg, tilt_spread_deg) = tilt_statistics(model);

    let calibration = StereoCalibration {
        unit: crate::engine::length_unit::LengthUnit::Mm,
        left: model.cameras[0].clone(),
        right: model.cameras[1].clone(),
        rms_reprojection_px: Some([cameras[0].rms_reprojection_px, cameras[1].rms_reprojection_px]),
        scale_uncertainty: Some(scale::scale_uncertainty(
            [&model.cameras[0], &model.cameras[1]],
            &refined.camera_covariance,
        )),
    };
    calibration.validate()?;

    let mut warnings =
        solution_warnings(&skipped_text, poses.len(), tilt_from_pose0_deg, tilt_spread_deg, obs.len(), &refined);
    let rectification = match rectify(&calibration) {
        Ok(r) => Some(RectificationReport::new(&r)),
        Err(e) => {
            warnings.push(Warning::new(WarningKind::NoRectification, format!("no rectification: {e}")));
            None
        }
    };
    let report = CalibrationReport {
        target: *target,
        distortion_model: options.distortion,
        stereo_angle_deg: calibration.stereo_angle_deg(),
        cameras,
        poses: pose_reports,
        skipped_poses: skipped
            .iter()
            .map(|s| SkippedPoseReport { index: s.source.index, name: s.source.name.clone(), reason: s.reason.clone() })
            .collect(),
        worst_points: worst,
        parameters: refined.parameters.clone(),
        rms_reprojection_px: rms_all,
        robust_sigma_px: refined.robust_sigma_px,
        outlier_threshold_px: refined.outlier_threshold_px,
        outliers,
        iterations: refined.iterations,
        tilt_from_pose0_deg,
        tilt_spread_deg,
        rectification,
        warnings,
    };
    Ok((calibration, report))
}

/// Every pose has images of the first pose's sizes and every target point
/// detected in both cameras; returns the image sizes.
fn check_detections(target: &Target, poses: &[PoseDetections]) -> Result<[[usize; 2]; 2], CalibrateError> {
    let sizes = poses[0].image_size_px;
    let expected = target.point_count();
    for pose in poses {
        for c in 0..2 {
            let [w, h] = pose.image_size_px[c];
            if [w, h] != sizes[c] {
                return Err(CalibrateError::ImageSize {
                    pose: pose.source.name.clone(),
                    camera: CAMERA_NAMES[c],
                    found_w: w,
                    found_h: h,
                    expected_w: sizes[c][0],
                    expected_h: sizes[c][1],
                });
            }
        }
        for (c, det) in [&pose.left, &pose.right].into_iter().enumerate() {
            if det.points_px.len() != expected {
                return Err(CalibrateError::PointCount {
                    pose: pose.source.name.clone(),
                    camera: CAMERA_NAMES[c],
                    found: det.points_px.len(),
                    expected,
                });
            }
        }
    }
    Ok(sizes)
}

/// Per camera: reprojection RMS and maximum over the inliers, outliers counted.
fn camera_reports(model: &RigModel, obs: &[Observation], refined: &Refined) -> Vec<CameraReport> {
    let mut cameras: Vec<CameraReport> =
        CAMERA_NAMES.iter().zip(&model.cameras).map(|(n, c)| CameraReport::summary(n, c)).collect();
    for (c, report) in cameras.iter_mut().enumerate() {
        let sel = |keep: bool| {
            obs.iter()
                .zip(&refined.residuals_px)
                .zip(&refined.inlier)
                .filter(move |((o, _), k)| o.camera == c && **k == keep)
        };
        let (rms, max, n) = rms_and_max(sel(true).map(|((_, r), _)| *r));
        report.points = n;
        report.rms_reprojection_px = rms;
        report.max_reprojection_px = max;
        report.outliers = sel(false).count();
    }
    cameras
}

/// Per pose and camera: the fitted pose, detections, residuals and outliers.
fn pose_reports(poses: &[PoseDetections], model: &RigModel, refined: &Refined, expected: usize) -> Vec<PoseReport> {
    let per_pose = 2 * expected;
    let mut pose_reports = Vec::with_capacity(poses.len());
    for (k, pose) in poses.iter().enumerate() {
        let fitted = &model.poses[k];
        let mut views = Vec::with_capacity(2);
        for (c, det) in [&pose.left, &pose.right].into_iter().enumerate() {
            let range = k * per_pose + c * expected..k * per_pose + (c + 1) * expected;
            let residuals: Vec<[f64; 2]> = refined.residuals_px[range.clone()].to_vec();
            let outlier: Vec<bool> = refined.inlier[range].iter().map(|k| !k).collect();
            let (rms, max, n) = rms_and_max(residuals.iter().zip(&outlier).filter(|(_, o)| !**o).map(|(r, _)| *r));
            views.push(PoseCameraReport {
                camera: CAMERA_NAMES[c].to_owned(),
                image: if c == 0 { pose.source.left_image.clone() } else { pose.source.right_image.clone() },
                points: n,
                outliers: expected - n,
                rms_reprojection_px: rms,
                max_reprojection_px: max,
                feature_size_px: det.feature_size_px,
                detections_px: det.points_px.clone(),
                residuals_px: residuals,
                outlier,
            });
        }
        pose_reports.push(PoseReport {
            index: pose.source.index,
            name: pose.source.name.clone(),
            rotation_deg: fitted.rotation_vector_rad().map(f64::to_degrees),
            translation_mm: fitted.translation_mm,
            tilt_deg: fitted.tilt_deg(),
            cameras: views,
        });
    }
    pose_reports
}

/// The [`WORST_POINTS`] largest residuals, outliers included, for finding a
/// bad detection in its image.
fn worst_points(
    target: &Target,
    poses: &[PoseDetections],
    obs: &[Observation],
    refined: &Refined,
) -> Vec<PointResidual> {
    let mut worst: Vec<PointResidual> = obs
        .iter()
        .zip(&refined.residuals_px)
        .zip(&refined.inlier)
        .map(|((o, r), keep)| {
            let source = &poses[o.pose].source;
            let (row, col) = target.row_col(o.point);
            PointResidual {
                pose: source.name.clone(),
                pose_index: source.index,
                camera: CAMERA_NAMES[o.camera].to_owned(),
                image: if o.camera == 0 { source.left_image.clone() } else { source.right_image.clone() },
                row,
                col,
                detected_px: o.observed_px,
                residual_px: *r,
                error_px: r[0].hypot(r[1]),
                outlier: !keep,
            }
        })
        .collect();
    worst.sort_by(|a, b| b.error_px.total_cmp(&a.error_px));
    worst.truncate(WORST_POINTS);
    worst
}

/// The smallest and largest tilt of a pose against pose 0, and the largest
/// angle between any two poses' target normals: too little spread leaves
/// the cameras' depth axes poorly determined.
fn tilt_statistics(model: &RigModel) -> ([f64; 2], f64) {
    let tilts: Vec<f64> = model.poses[1..].iter().map(|p| p.tilt_deg()).collect();
    let tilt_from_pose0_deg =
        [tilts.iter().copied().fold(f64::INFINITY, f64::min), tilts.iter().copied().fold(0.0, f64::max)];
    let mut tilt_spread_deg = 0.0f64;
    for a in &model.poses {
        for b in &model.poses {
            tilt_spread_deg = tilt_spread_deg.max(dot(a.normal(), b.normal()).clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    (tilt_from_pose0_deg, tilt_spread_deg)
}

/// What makes a solution less trustworthy than its residuals say.
fn solution_warnings(
    skipped_text: &[String],
    usable_poses: usize,
    tilt_from_pose0_deg: [f64; 2],
    tilt_spread_deg: f64,
    detections: usize,
    refined: &Refined,
) -> Vec<Warning> {
    let outliers = refined.inlier.iter().filter(|k| !**k).count();
    let mut warnings: Vec<Warning> =
        skipped_text.iter().map(|s| Warning::new(WarningKind::PoseSkipped, s.clone())).collect();
    if usable_poses < RECOMMENDED_POSES {
        warnings.push(Warning::new(
            WarningKind::FewPoses,
            format!(
                "only {} poses are usable; {RECOMMENDED_POSES} or more, tilted in different directions, determine the \
             cameras reliably",
                usable_poses
            ),
        ));
    }
    if tilt_spread_deg < MIN_TILT_SPREAD_DEG {
        warnings.push(Warning::new(WarningKind::SmallTiltSpread, format!(
            "the poses tilt at most {tilt_spread_deg:.1} deg against each other (tilt from pose 0: {:.1} to {:.1} deg): \
             the cameras' depth axes are poorly determined; tilt the target by 10 to 30 deg in different directions",
            tilt_from_pose0_deg[0], tilt_from_pose0_deg[1]
        )));
    }
    if outliers > 0 {
        warnings.push(Warning::new(WarningKind::DetectionOutliers, format!(
            "{outliers} of {} detections were set aside as outliers (farther than {:.3} px from their reprojection); \
             see worst_points",
            detections,
            refined.outlier_threshold_px
        )));
    }
    warnings
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::calibration::model::{Pose, RigModel};
    use crate::engine::calibration::target::TargetKind;
    use crate::engine::camera_model::AffineCamera;

    fn camera(theta_deg: f64, p14: f64) -> AffineCamera {
        let (s, c) = theta_deg.to_radians().sin_cos();
        AffineCamera {
            width: 400,
            height: 300,
            p: [[30.0 * c, 0.0, 30.0 * s, p14], [0.0, -30.0, 0.0, 60.0]],
            distortion: None,
        }
    }

    /// Exact detections of `poses` (rotation vectors, translations) by a 15 degree rig.
    fn detections(target: &Target, poses: &[([f64; 3], [f64; 3])]) -> Vec<PoseDetections> {
        let model = RigModel {
            cameras: [camera(15.0, 60.0), camera(-15.0, 70.0)],
            poses: poses.iter().map(|&(r, t)| Pose::from_rotation_vector(r, t)).collect(),
        };
        let points = target.points_mm();
        (0..poses.len())
            .map(|k| {
                let det = |c: usize| TargetDetection {
                    points_px: points.iter().map(|&x| model.project(c, k, x)).collect(),
                    feature_size_px: 10.0,
                    candidates: points.len(),
                };
                PoseDetections {
                    source: PoseSource {
                        index: k,
                        name: format!("pose {k}"),
                        left_image: format!("l{k}.png"),
                        right_image: format!("r{k}.png"),
                    },
                    image_size_px: [[400, 300], [400, 300]],
                    left: det(0),
                    right: det(1),
                }
            })
            .collect()
    }

    fn target() -> Target {
        Target { kind: TargetKind::Circles, rows: 6, cols: 8, pitch_mm: 1.0, dark_on_light: true }
    }

    #[test]
    fn few_and_little_tilted_poses_are_warned_about() {
        let t = target();
        let poses = [([0.0; 3], [0.0; 3]), ([0.06, 0.0, 0.0], [0.1, 0.0, 0.0]), ([0.0, 0.07, 0.1], [0.0, 0.2, 0.1])];
        let skipped = SkippedPose {
            source: PoseSource {
                index: 3,
                name: "pose 3".into(),
                left_image: "l3.png".into(),
                right_image: "r3.png".into(),
            },
            reason: "l3.png: the image is flat".into(),
            errors: vec![(0, DetectionError::NoContrast)],
        };
        let (calibration, report) =
            solve(&t, &detections(&t, &poses), &[skipped], &CalibrationOptions::default(), &RunControl::new())
                .expect("solved");
        let of =
            |kind| report.warnings.iter().filter(|w| w.kind == kind).map(|w| w.message.as_str()).collect::<Vec<_>>();
        let skipped = of(WarningKind::PoseSkipped);
        assert!(skipped.len() == 1 && skipped[0].contains("pose 3 skipped: l3.png"), "{skipped:?}");
        assert_eq!(of(WarningKind::FewPoses).len(), 1);
        let tilt = of(WarningKind::SmallTiltSpread);
        assert!(tilt.len() == 1 && tilt[0].contains("tilt from pose 0: 3.4 to 4.0 deg"), "{tilt:?}");
        assert_eq!(report.skipped_poses.len(), 1);
        // Exact detections are reprojected exactly, and the names hold.
        assert!(report.rms_reprojection_px < 1e-6, "{}", report.rms_reprojection_px);
        assert!(calibration.left.viewing_direction()[0] > calibration.right.viewing_direction()[0]);
        assert!((calibration.stereo_angle_deg() - 30.0).abs() < 1e-6);
    }

    #[test]
    fn too_few_poses_and_cancellation_are_errors() {
        let t = target();
        let poses = [([0.0; 3], [0.0; 3]), ([0.3, 0.0, 0.0], [0.1, 0.0, 0.0])];
        let e =
            solve(&t, &detections(&t, &poses), &[], &CalibrationOptions::default(), &RunControl::new()).unwrap_err();
        assert!(matches!(e, CalibrateError::TooFewPoses { usable: 2, required: 3, .. }), "{e}");
        let poses = [([0.0; 3], [0.0; 3]), ([0.3, 0.0, 0.0], [0.1, 0.0, 0.0]), ([0.0, 0.3, 0.0], [0.0; 3])];
        let control = RunControl::new();
        control.cancel();
        let e = solve(&t, &detections(&t, &poses), &[], &CalibrationOptions::default(), &control).unwrap_err();
        assert!(matches!(e, CalibrateError::Cancelled(_)), "{e}");
    }

    #[test]
    fn a_bad_detection_is_flagged_in_the_report() {
        let t = target();
        let poses = [
            ([0.0; 3], [0.0; 3]),
            ([0.3, 0.0, 0.0], [0.1, 0.0, 0.0]),
            ([0.0, 0.3, 0.1], [0.0, 0.2, 0.1]),
            ([-0.2, 0.2, 0.0], [0.0; 3]),
        ];
        let mut dets = detections(&t, &poses);
        dets[2].right.points_px[17][1] += 1.5;
        let options = CalibrationOptions { distortion: DistortionModel::None, ..CalibrationOptions::default() };
        let (_, report) = solve(&t, &dets, &[], &options, &RunControl::new()).expect("solved");
        assert_eq!(report.outliers, 1);
        let worst = &report.worst_points[0];
        assert_eq!((worst.pose_index, worst.camera.as_str(), worst.row, worst.col), (2, "right", 2, 1));
        assert!(worst.outlier && (worst.error_px - 1.5).abs() < 1e-6, "{worst:?}");
        assert!(report.poses[2].cameras[1].outlier[17]);
        assert_eq!(report.poses[2].cameras[1].points, 47);
        let outliers: Vec<&str> = report
            .warnings
            .iter()
            .filter(|w| w.kind == WarningKind::DetectionOutliers)
            .map(|w| w.message.as_str())
            .collect();
        assert!(outliers.len() == 1 && outliers[0].starts_with("1 of 384 detections"), "{outliers:?}");
    }
}
