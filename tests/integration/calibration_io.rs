//! Calibration sets on disk: a simulated set written, read back and
//! calibrated from its files; bad sets give one clear error naming the file.

use std::path::{Path, PathBuf};

use sheen::engine::calibration::target::TargetKind;
use sheen::engine::calibration::{CalibrationOptions, model::DistortionModel};
use sheen::engine::control::RunControl;
use sheen::io::calibration::read_calibration;
use sheen::io::calibration_set::{
    SimulatedCalibrationSet, calibrate_from_set, write_calibration_report, write_simulated_calibration_set,
};
use sheen::sim::target::{CalibrationTargetConfig, render_calibration_set};

use crate::calibration_solve::{rig_cameras, worst_reprojection_px};

/// Writes a simulated 8-pose dot-grid set (noise 1 DN, k1 = 1e-3) into `dir`.
fn write_set(dir: &Path, kind: TargetKind) -> PathBuf {
    let cameras = rig_cameras(1e-3);
    let mut config = CalibrationTargetConfig::for_field(kind, &cameras[0]);
    config.look.noise_sigma_dn = 1.0;
    let set = render_calibration_set(&cameras, &config).expect("simulated");
    let sim = SimulatedCalibrationSet {
        target: config.target,
        images: &set.images,
        full_scale_dn: config.look.full_scale_dn,
        calibration_world: &set.truth.calibration_world,
        calibration_pose0: &set.truth.calibration_pose0,
        poses_world: &set.truth.poses_world,
        points_px: &set.truth.points_px,
        settings: serde_json::to_value(config).expect("settings"),
    };
    write_simulated_calibration_set(dir, &sim).expect("written").set
}

fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json");
    edit(&mut v);
    std::fs::write(path, serde_json::to_vec_pretty(&v).expect("json")).expect("write");
}

fn error_of(path: &Path) -> String {
    match calibrate_from_set(path, &CalibrationOptions::default(), &RunControl::new()) {
        Ok(_) => panic!("{} calibrated", path.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_written_set_calibrates_from_its_files_like_the_truth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set_path = write_set(dir.path(), TargetKind::Circles);
    let options = CalibrationOptions { distortion: DistortionModel::Radial, ..CalibrationOptions::default() };
    let (calib, report) = calibrate_from_set(&set_path, &options, &RunControl::new()).expect("calibrated");
    let (truth, _) = read_calibration(&dir.path().join("truth/calibration.json")).expect("truth");
    let worst = worst_reprojection_px(&truth, &calib);
    assert!(worst < 0.02, "worst {worst} px");
    // The report has every pose's detections and residuals, k2 fitted, and a rectification.
    let report_path = dir.path().join("report.json");
    write_calibration_report(&report_path, &report).expect("report");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&report_path).expect("read")).expect("json");
    assert_eq!(v["poses"].as_array().map(Vec::len), Some(8));
    assert_eq!(v["poses"][3]["cameras"][1]["image"], "right/pose03.png");
    assert_eq!(v["poses"][3]["cameras"][1]["residuals_px"].as_array().map(Vec::len), Some(99));
    assert!(v["rectification"]["rows"].as_u64().is_some_and(|r| r > 100), "{}", v["rectification"]);
    assert!(v["parameters"].as_array().is_some_and(|p| p.iter().any(|q| q["name"] == "left.k2")));
    assert!(v["cameras"][0]["rms_reprojection_px"].as_f64().is_some_and(|r| r > 0.0 && r < 0.05));
    assert_eq!(v["worst_points"].as_array().map(Vec::len), Some(10));
}

#[test]
fn an_unknown_target_kind_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set_path = write_set(dir.path(), TargetKind::Circles);
    edit_json(&set_path, |v| v["target"]["kind"] = "rings".into());
    let e = error_of(&set_path);
    assert!(e.contains(&set_path.display().to_string()) && e.contains("'rings' is unknown"), "{e}");
}

#[test]
fn a_grid_that_does_not_match_the_images_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set_path = write_set(dir.path(), TargetKind::Circles);
    edit_json(&set_path, |v| v["target"]["cols"] = 12.into());
    let e = error_of(&set_path);
    assert!(e.contains(&set_path.display().to_string()), "{e}");
    assert!(e.contains("declared as 9 x 12 dots, but the images show 9 x 11"), "{e}");
}

#[test]
fn a_missing_image_of_one_camera_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set_path = write_set(dir.path(), TargetKind::Circles);
    std::fs::remove_file(dir.path().join("right/pose05.png")).expect("removed");
    let e = error_of(&set_path);
    assert!(e.contains(&set_path.display().to_string()) && e.contains("right/pose05.png"), "{e}");
    assert!(e.contains("pose 5: the right image"), "{e}");
}

#[test]
fn fewer_than_three_usable_poses_is_an_error_listing_why() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set_path = write_set(dir.path(), TargetKind::Circles);
    // Blank the left images of poses 2 to 7: only poses 0 and 1 remain.
    let blank = image::GrayImage::from_pixel(640, 480, image::Luma([200u8]));
    for k in 2..8 {
        blank.save(dir.path().join(format!("left/pose{k:02}.png"))).expect("saved");
    }
    let e = error_of(&set_path);
    assert!(e.contains(&set_path.display().to_string()), "{e}");
    assert!(e.contains("only 2 pose(s)") && e.contains("at least 3"), "{e}");
    assert!(e.contains("pose 7 skipped: left/pose07.png:"), "{e}");
}

#[test]
fn a_checkerboard_set_calibrates_too() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set_path = write_set(dir.path(), TargetKind::Checkerboard);
    let (calib, report) =
        calibrate_from_set(&set_path, &CalibrationOptions::default(), &RunControl::new()).expect("calibrated");
    let (truth, _) = read_calibration(&dir.path().join("truth/calibration.json")).expect("truth");
    let worst = worst_reprojection_px(&truth, &calib);
    assert!(worst < 0.02, "worst {worst} px; warnings {:?}", report.warnings);
}

/// The calibration file has one writer (the model serialises itself, io
/// writes the value): what `sheen calibrate` writes for a solved rig, what the
/// simulator writes as its truth and beside a fringe set, and the camera
/// blocks of the calibration report and of the simulator's rig are the same
/// JSON for the same model, and the reader accepts every file.
#[test]
fn calibrate_simulate_and_report_write_the_same_calibration_json() {
    use sheen::io::calibration::{calibration_to_value, write_calibration};
    let dir = tempfile::tempdir().expect("tempdir");
    let bytes = |p: &Path| std::fs::read(p).expect("read");
    let json = |p: &Path| -> serde_json::Value { serde_json::from_slice(&bytes(p)).expect("json") };
    let camera_keys = ["width", "height", "P", "distortion"];

    // Calibration: the solved model as `sheen calibrate` writes it, and the report.
    let set_path = write_set(dir.path(), TargetKind::Circles);
    let options = CalibrationOptions { distortion: DistortionModel::Radial, ..CalibrationOptions::default() };
    let (calib, report) = calibrate_from_set(&set_path, &options, &RunControl::new()).expect("calibrated");
    let solved = dir.path().join("solved.json");
    write_calibration(&solved, &calib).expect("write");
    let (back, warnings) = read_calibration(&solved).expect("the reader accepts the calibrated file");
    assert_eq!(back, calib);
    assert!(warnings.is_empty(), "{warnings:?}");
    let file = json(&solved);
    assert!(file["cameras"]["left"]["distortion"]["k1"].as_f64().is_some_and(|k1| k1 != 0.0), "{file}");
    let report_path = dir.path().join("report.json");
    write_calibration_report(&report_path, &report).expect("report");
    let report_json = json(&report_path);
    for (k, name) in ["left", "right"].iter().enumerate() {
        for key in camera_keys {
            assert_eq!(report_json["cameras"][k][key], file["cameras"][name][key], "report {name}.{key}");
        }
    }

    // The simulator's truth, written beside the set, is the same file as the
    // library writes for the model it holds.
    let truth_path = dir.path().join("truth/calibration.json");
    let (truth, _) = read_calibration(&truth_path).expect("the reader accepts the truth");
    let rewritten = dir.path().join("truth_rewritten.json");
    write_calibration(&rewritten, &truth).expect("write");
    assert_eq!(bytes(&truth_path), bytes(&rewritten), "the truth file is the library's file");

    // A fringe set from a rig with distortion: calibration.json beside it,
    // and the rig's own cameras in truth.json, are the one shape.
    let mut config = sheen::sim::SimConfig::new(sheen::sim::SceneKind::Flat, 64, 48);
    config.rig.distortion_k1 = 1e-3;
    let sim = sheen::sim::simulate(&config, &RunControl::new()).expect("simulate");
    let rig_calibration = sim.measurement.calibration.clone().expect("calibration");
    let manifest = sheen::io::dataset::write_measurement(&dir.path().join("set"), &sim.measurement).expect("set");
    let beside = manifest.parent().expect("folder").join(sheen::io::dataset::CALIBRATION_FILE);
    let (read, _) = read_calibration(&beside).expect("the reader accepts the set's calibration");
    assert_eq!(read, rig_calibration);
    let again = dir.path().join("rig_again.json");
    write_calibration(&again, &rig_calibration).expect("write");
    assert_eq!(bytes(&beside), bytes(&again));
    let rig = serde_json::to_value(&sim.truth.rig).expect("rig");
    let value = calibration_to_value(&rig_calibration);
    for name in ["left", "right"] {
        assert!(rig[name]["distortion"]["k1"].as_f64().is_some_and(|k1| k1 == 1e-3), "{}", rig[name]);
        for key in camera_keys {
            assert_eq!(rig[name][key], value["cameras"][name][key], "rig {name}.{key}");
        }
    }
}
