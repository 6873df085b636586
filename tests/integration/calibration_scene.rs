//! Issue 12's last acceptance test: a fringe scene reconstructed with the
//! rig calibrated from simulated targets matches its truth as well (within
//! 10 % RMS) as with the true calibration.

use sheen::engine::calibration::model::Pose;
use sheen::engine::calibration::target::TargetKind;
use sheen::engine::calibration::{CalibrationOptions, calibrate_images};
use sheen::engine::camera_model::StereoCalibration;
use sheen::engine::control::RunControl;
use sheen::engine::pipeline::{Params, run};
use sheen::sim::target::{CalibrationTargetConfig, render_calibration_set};
use sheen::sim::{Rig, RigConfig, SceneKind, SimConfig, Simulation, simulate};

use crate::calibration_solve::sources;

/// RMS height error (um) of the scene's cloud measured with `calib`, whose
/// world frame is `frame` in the simulator's world, and the point count.
fn height_rms_um(sim: &Simulation, calib: &StereoCalibration, frame: &Pose) -> (f64, usize) {
    let mut m = sim.measurement.clone();
    m.calibration = Some(calib.clone());
    let rec = run(&m, &Params::default(), None, &RunControl::new()).expect("reconstructed");
    let cloud = &rec.stereo.as_ref().expect("stereo").cloud;
    let mut sum2 = 0.0;
    let mut n = 0usize;
    for p in &cloud.xyz {
        let w = frame.apply(*p);
        let dz = w[2] - sim.truth.scene.height_mm(w[0], w[1]);
        if dz.is_finite() {
            sum2 += dz * dz;
            n += 1;
        }
    }
    ((sum2 / n.max(1) as f64).sqrt() * 1e3, n)
}

#[test]
fn a_scene_measured_with_the_calibrated_rig_matches_its_truth_like_the_true_rig() {
    let (w, h) = (512, 384);
    let rig_config = RigConfig { distortion_k1: 1e-3, ..RigConfig::default() };
    let rig = Rig::new(&rig_config, w, h, 0.0);
    let cameras = [rig.left.clone(), rig.right.clone()];
    let mut target_config = CalibrationTargetConfig::for_field(TargetKind::Circles, &cameras[0]);
    target_config.look.noise_sigma_dn = 1.0;
    let targets = render_calibration_set(&cameras, &target_config).expect("targets");
    let (calib, _) =
        calibrate_images(&target_config.target, &sources(&targets), &CalibrationOptions::default(), &RunControl::new())
            .expect("calibrated");

    // Smooth scenes, so the RMS measures the method rather than the few
    // points at depth discontinuities; 8-bit images with 1 DN of read noise.
    for kind in [SceneKind::Flat, SceneKind::Sphere] {
        let scene = SimConfig { noise_sigma_dn: 1.0, rig: rig_config.clone(), ..SimConfig::new(kind, w, h) };
        let sim = simulate(&scene, &RunControl::new()).expect("simulated");
        let (truth_rms, truth_points) = height_rms_um(&sim, &targets.truth.calibration_world, &Pose::IDENTITY);
        let (calib_rms, calib_points) = height_rms_um(&sim, &calib, &targets.truth.poses_world[0]);
        assert!(calib_rms <= 1.1 * truth_rms, "{kind}: calibrated {calib_rms} um vs true {truth_rms} um");
        assert!(truth_rms < 3.0, "{kind}: true calibration {truth_rms} um");
        assert!(calib_points as f64 > 0.99 * truth_points as f64, "{kind}: {calib_points} vs {truth_points} points");
    }
}
