//! Calibration end to end on simulated target sets: the calibrated cameras
//! reproject the measurement volume like the true ones, in the pose-0 frame.

use sheen::engine::calibration::model::DistortionModel;
use sheen::engine::calibration::target::TargetKind;
use sheen::engine::calibration::{CalibrationOptions, PoseSource, calibrate_images};
use sheen::engine::camera_model::{AffineCamera, StereoCalibration};
use sheen::engine::control::RunControl;
use sheen::sim::target::{
    CalibrationTargetConfig, CalibrationTargetSet, render_calibration_set, simulate_calibration_target,
};
use sheen::sim::{Rig, RigConfig, SceneKind, SimConfig};

const W: usize = 640;
const H: usize = 480;

/// The simulator's rig (the paper's 15 degree cameras, the right one rolled,
/// scaled and offset) at 640 x 480 px with radial distortion `k1`.
pub fn rig_cameras(k1: f64) -> [AffineCamera; 2] {
    let rig = Rig::new(&RigConfig { distortion_k1: k1, ..RigConfig::default() }, W, H, 0.0);
    [rig.left, rig.right]
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
) -> Vec<(
    PoseSource,
    sheen::engine::calibration::gray_image::GrayImage,
    sheen::engine::calibration::gray_image::GrayImage,
)> {
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

#[test]
fn twelve_bit_checkerboards_through_the_simulators_rig_calibrate_it() {
    // The same rig as a fringe simulation: image size, bits, noise, distortion.
    let mut config = SimConfig::new(SceneKind::Flat, W, H);
    config.bits = 12;
    config.noise_sigma_dn = 8.0;
    config.rig.distortion_k1 = -2e-3;
    let set = simulate_calibration_target(&config, TargetKind::Checkerboard).expect("simulated");
    assert!(set.images[0][0].pixels_dn.iter().any(|&v| v > 255.0 * 8.0));
    let (calib, report) =
        calibrate_images(&set.config.target, &sources(&set), &CalibrationOptions::default(), &RunControl::new())
            .expect("calibrated");
    let worst = worst_reprojection_px(&set.truth.calibration_pose0, &calib);
    assert!(worst < 0.02, "worst {worst} px; {:?}", report.warnings);
    let d = calib.right.distortion.expect("distortion");
    assert!((d.k1 + 2e-3).abs() < 5e-5 && d.k2 == 0.0 && d.p1 == 0.0, "{d:?}");
}

#[test]
fn the_full_distortion_model_finds_no_decentering_where_there_is_none() {
    let cameras = rig_cameras(1e-3);
    let mut config = CalibrationTargetConfig::for_field(TargetKind::Circles, &cameras[0]);
    config.look.noise_sigma_dn = 1.0;
    config.seed = 5;
    let set = render_calibration_set(&cameras, &config).expect("simulated");
    let options = CalibrationOptions { distortion: DistortionModel::Full, ..CalibrationOptions::default() };
    let (calib, report) =
        calibrate_images(&config.target, &sources(&set), &options, &RunControl::new()).expect("calibrated");
    let worst = worst_reprojection_px(&set.truth.calibration_pose0, &calib);
    assert!(worst < 0.02, "worst {worst} px");
    for cam in [&calib.left, &calib.right] {
        let d = cam.distortion.expect("distortion");
        assert!((d.k1 - 1e-3).abs() < 1e-4 && d.k2.abs() < 2e-4 && d.p1.abs() < 2e-5 && d.p2.abs() < 2e-5, "{d:?}");
    }
    // Each term's standard deviation is reported, and is consistent with its error.
    let p1 = report.parameters.iter().find(|p| p.name == "left.p1").expect("p1 reported");
    assert!(p1.std > 0.0 && p1.value.abs() < 5.0 * p1.std + 1e-6, "{p1:?}");
}

/// The height and lateral scale errors a fitted rig makes, relative: a
/// world displacement as the fitted cameras reconstruct what the true
/// ones saw (distortion aside).
fn scale_errors(truth: &StereoCalibration, fitted: &StereoCalibration) -> [f64; 2] {
    use nalgebra::{Matrix4x3, Vector3};
    let a = |c: [&AffineCamera; 2]| Matrix4x3::from_fn(|r, k| c[r / 2].p[r % 2][k]);
    let (t, f) = (a([&truth.left, &truth.right]), a([&fitted.left, &fitted.right]));
    let m = (f.transpose() * f).try_inverse().expect("invertible") * f.transpose() * t;
    let length = |v: Vector3<f64>| (m * v).norm();
    [length(Vector3::z()) - 1.0, 0.5 * (length(Vector3::x()) + length(Vector3::y())) - 1.0]
}

/// `sheen calibrate` states the scales' uncertainty from its own fit, and
/// the statement holds: over calibrations of the same rig with different
/// noise, the scale errors spread as widely as the stated u, not five
/// times more or less.
#[test]
fn the_stated_scale_uncertainty_matches_the_spread_of_repeated_calibrations() {
    let cameras = rig_cameras(0.0);
    let (mut heights, mut laterals, mut stated) = (Vec::new(), Vec::new(), Vec::new());
    for seed in 0..8u64 {
        let mut config = CalibrationTargetConfig::for_field(TargetKind::Circles, &cameras[0]);
        config.look.noise_sigma_dn = 6.0;
        config.seed = 100 + seed;
        let set = render_calibration_set(&cameras, &config).expect("simulated");
        let (calib, _) =
            calibrate_images(&config.target, &sources(&set), &CalibrationOptions::default(), &RunControl::new())
                .expect("calibrated");
        let [h, l] = scale_errors(&set.truth.calibration_pose0, &calib);
        heights.push(h);
        laterals.push(l);
        let u = calib.scale_uncertainty.expect("a calibration states its scales' uncertainty");
        stated.push([u.height_relative.expect("height"), u.lateral_relative.expect("lateral")]);
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let mean_stated = |i: usize| stated.iter().map(|s| s[i]).sum::<f64>() / stated.len() as f64;
    let (h, l) = (rms(&heights), rms(&laterals));
    eprintln!("height: errors rms {h:.2e}, stated {:.2e}; lateral: {l:.2e}, {:.2e}", mean_stated(0), mean_stated(1));
    assert!(mean_stated(0) > 0.0 && mean_stated(1) > 0.0);
    for (seen, said) in [(h, mean_stated(0)), (l, mean_stated(1))] {
        assert!(seen < 2.5 * said && seen > said / 2.5, "errors rms {seen:.2e} against stated u {said:.2e}");
    }
}
