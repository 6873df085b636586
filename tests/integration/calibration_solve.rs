//! Calibration end to end on simulated target sets: the calibrated cameras
//! reproject the measurement volume like the true ones, in the pose-0 frame.

use sheen::engine::calibration::target::TargetKind;
use sheen::engine::calibration::{CalibrationOptions, PoseSource, calibrate_images};
use sheen::engine::camera_model::{AffineCamera, Distortion, StereoCalibration};
use sheen::engine::control::RunControl;
use sheen::sim::target::{CalibrationTargetConfig, CalibrationTargetSet, render_calibration_set};

use crate::util::telecentric_camera;

const W: usize = 640;
const H: usize = 480;

pub fn rig_cameras(k1: f64) -> [AffineCamera; 2] {
    let d = (k1 != 0.0).then(|| Distortion { k1, ..Distortion::for_image(W, H) });
    let mut left = telecentric_camera(15.0, 0.0, 26.7, W, H, [0.0, 0.0]);
    let mut right = telecentric_camera(-15.0, 2.0, 26.7 * 1.02, W, H, [9.0, -6.0]);
    left.distortion = d;
    right.distortion = d;
    [left, right]
}

/// The world point (pose-0 frame) seen by the left camera's observed pixel at height z.
fn volume_point(cam: &AffineCamera, observed: [f64; 2], z: f64) -> [f64; 3] {
    let ideal = cam.ideal_from_observed(observed);
    let p = &cam.p;
    let r = [ideal[0] - p[0][3] - p[0][2] * z, ideal[1] - p[1][3] - p[1][2] * z];
    let det = p[0][0] * p[1][1] - p[0][1] * p[1][0];
    [(p[1][1] * r[0] - p[0][1] * r[1]) / det, (-p[1][0] * r[0] + p[0][0] * r[1]) / det, z]
}

/// Largest difference, over the left camera's field at heights -1..1 mm and
/// both cameras, between the observed pixels of `truth` and `fitted`.
pub fn worst_reprojection_px(truth: &StereoCalibration, fitted: &StereoCalibration) -> f64 {
    let mut worst = 0.0f64;
    for a in 0..=8 {
        for b in 0..=6 {
            let observed = [(W - 1) as f64 * a as f64 / 8.0, (H - 1) as f64 * b as f64 / 6.0];
            for z in [-1.0, 0.0, 1.0] {
                let x = volume_point(&truth.left, observed, z);
                for (t, f) in [(&truth.left, &fitted.left), (&truth.right, &fitted.right)] {
                    let (pt, pf) = (t.project_observed(x), f.project_observed(x));
                    worst = worst.max((pt[0] - pf[0]).hypot(pt[1] - pf[1]));
                }
            }
        }
    }
    worst
}

pub fn sources(
    set: &CalibrationTargetSet,
) -> Vec<(PoseSource, sheen::engine::calibration::image::GrayImage, sheen::engine::calibration::image::GrayImage)> {
    set.images
        .iter()
        .enumerate()
        .map(|(k, [l, r])| {
            let source = PoseSource {
                index: k,
                name: format!("pose {k}"),
                left_image: format!("left/pose{k:02}.png"),
                right_image: format!("right/pose{k:02}.png"),
            };
            (source, l.clone(), r.clone())
        })
        .collect()
}

#[test]
fn noisy_dots_in_eight_poses_calibrate_the_volume_to_two_hundredths_of_a_pixel() {
    let cameras = rig_cameras(1e-3);
    let mut config = CalibrationTargetConfig::for_field(TargetKind::Circles, &cameras[0]);
    config.look.noise_sigma_dn = 1.5;
    let set = render_calibration_set(&cameras, &config).expect("simulated");
    let (calib, report) =
        calibrate_images(&config.target, &sources(&set), &CalibrationOptions::default(), &RunControl::new())
            .expect("calibrated");
    let worst = worst_reprojection_px(&set.truth.calibration_pose0, &calib);
    eprintln!(
        "worst {worst} rms {:?} warnings {:?} tilt {:?} pitch {}",
        calib.rms_reprojection_px, report.warnings, report.tilt_from_pose0_deg, config.target.pitch_mm
    );
    assert!(worst < 0.02, "worst reprojection difference {worst} px");
    assert_eq!(report.poses.len(), 8);
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    let k1 = calib.left.distortion.map(|d| d.k1).unwrap_or(0.0);
    assert!((k1 - 1e-3).abs() < 5e-5, "k1 {k1}");
}
