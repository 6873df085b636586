//! Calibration of the simulated camera–projector rig (issue 52, item 3):
//! a dot grid in eight poses under every frame the rig projects, each pose
//! decoded and its target points carried into the projector by local
//! homographies, then Zhang's start and one bundle adjustment. The result
//! is compared with the rig the simulator rendered, and a sphere measured
//! with it against the sphere's truth. Figures are printed for
//! BENCHMARKS.md (`cargo test --release --test integration
//! camera_projector_calibration -- --nocapture`).

use sheen::engine::calibration::camera_projector::{
    RigCalibrationOptions, RigPoseObservation, observe_measurement, rotation_angle_deg, solve_rig,
};
use sheen::engine::calibration::target::TargetKind;
use sheen::engine::camera_projector::{projector_maps, rig_point_cloud};
use sheen::engine::control::RunControl;
use sheen::engine::pinhole::{CameraProjectorCalibration, PinholeDevice};
use sheen::engine::pipeline::Params;
use sheen::sim::SceneKind;
use sheen::sim::camera_projector::{
    PinholeRigConfig, calibration_poses, rig_calibration, rig_calibration_target, simulate_calibration_pose,
    simulate_camera_projector,
};
use sheen::sim::target::TargetLook;

/// Depth errors of a sphere measured through `calibration` against its
/// truth: RMS, mean (a depth offset) and the number of points.
fn sphere_depth_error_mm(config: &PinholeRigConfig, calibration: &CameraProjectorCalibration) -> (f64, f64, usize) {
    let control = RunControl::new();
    let mut sim = simulate_camera_projector(config, &control).expect("renders");
    if let Some(p) = sim.measurement.projector.as_mut() {
        p.calibration = Some(calibration.clone());
    }
    let m = &sim.measurement;
    let maps = projector_maps(m, &Params::default().phase_params(m), &control).expect("decodes");
    let cloud = rig_point_cloud(m, &maps).expect("a calibrated cloud");
    let w = sim.truth.width;
    let errors: Vec<f64> = cloud
        .xyz
        .iter()
        .zip(&cloud.pixel_uv)
        .map(|(p, uv)| p[2] - sim.truth.point_camera_mm[uv[1] as usize * w + uv[0] as usize][2])
        .collect();
    let n = errors.len().max(1) as f64;
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    (rms, errors.iter().sum::<f64>() / n, errors.len())
}

#[test]
fn a_simulated_rig_is_recovered_from_eight_poses_of_a_dot_grid() {
    recovers_the_rig(TargetKind::Circles);
}

#[test]
fn a_simulated_rig_is_recovered_from_eight_poses_of_a_checkerboard() {
    recovers_the_rig(TargetKind::Checkerboard);
}

fn recovers_the_rig(kind: TargetKind) {
    let control = RunControl::new();
    let config = PinholeRigConfig { distortion_k1: -0.05, ..PinholeRigConfig::new(SceneKind::Flat) };
    let truth = rig_calibration(&config);
    let target = rig_calibration_target(kind);
    let look = TargetLook::default();
    let options = RigCalibrationOptions::default();
    let mut observations: Vec<RigPoseObservation> = Vec::new();
    let mut worst_projector_point_px = 0.0f64;
    for (k, pose) in calibration_poses(&target, 8, 30.0).iter().enumerate() {
        let sim = simulate_calibration_pose(&config, &target, &look, pose, k, &control).expect("renders");
        let obs = observe_measurement(&format!("pose{k}"), &sim.measurement, &target, &options, &control)
            .unwrap_or_else(|e| panic!("pose {k}: {e}"));
        assert_eq!(obs.camera_px.len(), target.point_count());
        let decoded = obs.projector_px.iter().flatten().count();
        assert_eq!(decoded, target.point_count(), "pose {k}: every dot lies in the projector's light");
        for (found, true_px) in obs.projector_px.iter().zip(&sim.projector_points_px) {
            if let Some(f) = found {
                worst_projector_point_px = worst_projector_point_px.max((f[0] - true_px[0]).hypot(f[1] - true_px[1]));
            }
        }
        observations.push(obs);
    }
    let sizes = [[config.camera_width, config.camera_height], [config.projector_width, config.projector_height]];
    let (fitted, report) = solve_rig(&target, &observations, sizes, &[], &options, &control).expect("calibrates");

    let rotation_error_deg = rotation_angle_deg(&fitted.r, &truth.r);
    let translation_error_mm = (0..3).map(|i| (fitted.t[i] - truth.t[i]).powi(2)).sum::<f64>().sqrt();
    let [camera_rms, projector_rms] = report.rms_per_device();
    println!(
        "camera–projector calibration, 8 poses (30 deg) of a 9 x 11 {kind} (1.5 mm), 1 DN noise, camera k1 -0.05: \
         reprojection RMS camera {camera_rms:.4} px, projector {projector_rms:.4} px; projector points from local \
         homographies within {worst_projector_point_px:.3} px of the truth"
    );
    for (name, f, t) in [("camera", &fitted.camera, &truth.camera), ("projector", &fitted.projector, &truth.projector)]
    {
        println!(
            "  {name}: fx {:.2} (true {:.2}, {:+.3} %), fy {:.2}, cx {:.2} (true {:.2}), cy {:.2} (true {:.2}), k1 {:.4} \
             (true {:.4}), k2 {:.4}",
            f.fx,
            t.fx,
            100.0 * (f.fx / t.fx - 1.0),
            f.fy,
            f.cx,
            t.cx,
            f.cy,
            t.cy,
            f.distortion[0],
            t.distortion[0],
            f.distortion[1]
        );
    }
    println!(
        "  R off by {rotation_error_deg:.4} deg, t off by {translation_error_mm:.4} mm (baseline {:.2} mm, stated σ(t) \
         {:?} mm)",
        report.baseline_mm, report.sigma_translation_mm
    );
    assert!(camera_rms < 0.1 && projector_rms < 0.2, "reprojection RMS {camera_rms} / {projector_rms} px");
    for (f, t) in [(&fitted.camera, &truth.camera), (&fitted.projector, &truth.projector)] {
        assert!((f.fx / t.fx - 1.0).abs() < 0.005 && (f.fy / t.fy - 1.0).abs() < 0.005, "{f:?} vs {t:?}");
        assert!((f.cx - t.cx).abs() < 0.03 * t.cx && (f.cy - t.cy).abs() < 0.03 * t.cy, "{f:?} vs {t:?}");
    }
    // The distortion as it acts: the shift it gives the image's corner.
    let corner_shift_px = |d: &PinholeDevice| {
        let (x, y) = (-d.cx / d.fx, -d.cy / d.fy);
        let (xd, yd) = d.distort(x, y);
        [d.fx * (xd - x), d.fy * (yd - y)]
    };
    for (f, t) in [(&fitted.camera, &truth.camera), (&fitted.projector, &truth.projector)] {
        let (a, b) = (corner_shift_px(f), corner_shift_px(t));
        println!("  distortion at the corner: {a:.3?} px (true {b:.3?} px)");
        assert!((a[0] - b[0]).hypot(a[1] - b[1]) < 0.05, "corner shift {a:?} vs {b:?} px");
    }
    assert!(rotation_error_deg < 0.1, "R off by {rotation_error_deg} deg");
    assert!(translation_error_mm < 0.01 * report.baseline_mm, "t off by {translation_error_mm} mm");
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);

    // What matters: a part measured with the fitted calibration.
    let sphere = PinholeRigConfig { scene: SceneKind::Sphere, ..config.clone() };
    let (with_truth_mm, _, points) = sphere_depth_error_mm(&sphere, &truth);
    let (with_fit_mm, offset_mm, fitted_points) = sphere_depth_error_mm(&sphere, &fitted);
    println!(
        "  sphere measured with the fitted calibration: depth RMS {with_fit_mm:.4} mm (mean {offset_mm:+.4} mm) over \
         {fitted_points} points (with the true calibration {with_truth_mm:.4} mm over {points})"
    );
    assert!(fitted_points * 100 >= points * 99, "{fitted_points} of {points} points");
    // The shape is measured as well as with the true rig; what is left is a
    // depth offset (a scale of the whole rig). A dot's centroid is not the
    // image of its centre under perspective (Heikkilä 2000), which biases a
    // dot grid's scale by about 1e-4 here; a checkerboard's corners are not
    // biased.
    let shape_mm = (with_fit_mm.powi(2) - offset_mm.powi(2)).max(0.0).sqrt();
    assert!(shape_mm < 1.5 * with_truth_mm + 0.002, "shape {shape_mm} mm against {with_truth_mm} mm");
    let offset_limit_mm = if kind == TargetKind::Circles { 0.03 } else { 0.01 };
    assert!(offset_mm.abs() < offset_limit_mm, "depth offset {offset_mm} mm");
}

fn sheen(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn text(p: &std::path::Path) -> &str {
    p.to_str().expect("utf8 path")
}

/// As an operator runs it: `sheen simulate --rig camera-projector --scene
/// calibration-target` writes a set of fringe sets, `sheen calibrate`
/// finds the rig the truth holds, its report lists every pose, and a set
/// with a pose missing or not of this rig fails with one line naming it.
#[test]
fn a_camera_projector_set_calibrates_from_the_command_line_and_bad_sets_are_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = dir.path();
    let out = sheen(&[
        "simulate",
        "--rig",
        "camera-projector",
        "--scene",
        "calibration-target",
        "--target",
        "checkerboard",
        "--poses",
        "6",
        "--width",
        "640",
        "--height",
        "480",
        "--distortion=-0.05",
        "--out",
        text(root),
        "-q",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let set = root.join("calibration_set.json");
    let (fit, report) = (root.join("fit.json"), root.join("report.json"));
    let out = sheen(&["calibrate", text(&set), "--out", text(&fit), "--report", text(&report)]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{err}");
    assert!(err.contains("camera–projector calibration written to"), "{err}");
    let (fitted, _) = sheen::io::pinhole_calibration::read_camera_projector_calibration(&fit).expect("reads");
    let (truth, _) =
        sheen::io::pinhole_calibration::read_camera_projector_calibration(&root.join("truth/calibration.json"))
            .expect("the truth reads");
    for (f, t) in [(&fitted.camera, &truth.camera), (&fitted.projector, &truth.projector)] {
        assert!((f.fx / t.fx - 1.0).abs() < 0.005, "{f:?} vs {t:?}");
    }
    assert!(rotation_angle_deg(&fitted.r, &truth.r) < 0.1);
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).expect("report")).expect("json");
    assert_eq!(report["poses"].as_array().map(Vec::len), Some(6));
    assert_eq!(report["devices"][1]["device"], "projector");
    assert!(report["devices"][1]["rms_reprojection_px"].as_f64().is_some_and(|r| r < 0.2), "{report}");

    // A pose whose fringe set is gone; a pose that is a stereo set's image.
    let broken = root.join("broken_set.json");
    let value: serde_json::Value = serde_json::from_slice(&std::fs::read(&set).expect("set")).expect("json");
    let mut missing = value.clone();
    missing["poses"][2]["fringe_set"] = "pose09/fringe-set.json".into();
    std::fs::write(&broken, missing.to_string()).expect("write");
    let out = sheen(&["calibrate", text(&broken), "--out", text(&root.join("x.json"))]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success());
    assert!(err.contains("broken_set.json") && err.contains("pose 2") && err.contains("pose09"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let mut wrong = value;
    wrong["poses"][1] = serde_json::json!({"left": "a.png", "right": "b.png"});
    std::fs::write(&broken, wrong.to_string()).expect("write");
    let out = sheen(&["calibrate", text(&broken), "--out", text(&root.join("x.json"))]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success());
    assert!(err.contains("pose 1 lacks 'fringe_set'"), "{err}");
    assert!(!root.join("x.json").exists(), "nothing written on a failure");
}
