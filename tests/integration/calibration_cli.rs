//! `sheen simulate --scene calibration-target` and `sheen calibrate` as an
//! operator runs them: a simulated set calibrates the rig to within 0.02 px
//! of the true cameras over the measurement volume, the report has every
//! pose, and bad sets fail with one line naming the file.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use sheen::io::calibration::read_calibration;

use crate::calibration_solve::worst_reprojection_px;

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn text(p: &Path) -> &str {
    p.to_str().expect("utf8 path")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A simulated 640 x 480 set through the simulator's rig: 8 poses, k1 = 1e-3,
/// 1 DN of read noise, written by the `simulate` command.
fn simulate_set(dir: &Path, target: &str) -> PathBuf {
    let out = sheen(&[
        "simulate",
        "--scene",
        "calibration-target",
        "--target",
        target,
        "--poses",
        "8",
        "--width",
        "640",
        "--height",
        "480",
        "--distortion",
        "1e-3",
        "--noise",
        "1",
        "--out",
        text(dir),
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    dir.join("calibration_set.json")
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

#[test]
fn a_simulated_target_set_calibrates_the_rig_from_the_command_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = simulate_set(dir.path(), "circles");
    // The truth says where the pose-0 target frame lies in the simulator's world.
    let truth = json(&dir.path().join("truth/target_truth.json"));
    assert!(truth["pose0_in_world"]["rotation"].is_array(), "{}", truth["pose0_in_world"]);
    assert_eq!(truth["poses_in_world"].as_array().map(Vec::len), Some(8));
    assert_eq!(truth["settings"]["target"]["poses"], 8);
    assert_eq!(json(&set)["target"]["kind"], "circles");

    let calibration = dir.path().join("out/calibration.json");
    std::fs::create_dir_all(calibration.parent().expect("parent")).expect("mkdir");
    let report = dir.path().join("out/report.json");
    let out = sheen(&["calibrate", text(&set), "--out", text(&calibration), "--report", text(&report)]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    // Progress (the later stages may pass between two polls), the per-pose table and the summary line.
    assert!(err.contains("target detection"), "{err}");
    for k in 0..8 {
        assert!(err.lines().any(|l| l.starts_with(&format!("pose {k} ")) && l.contains("99")), "pose {k}: {err}");
    }
    assert!(err.contains("calibration written to"), "{err}");
    assert!(!err.contains("warning:"), "{err}");

    let (fitted, _) = read_calibration(&calibration).expect("calibration reads back");
    let (truth, _) = read_calibration(&dir.path().join("truth/calibration.json")).expect("truth");
    let worst = worst_reprojection_px(&truth, &fitted);
    assert!(worst < 0.02, "worst reprojection difference {worst} px");
    let k1 = fitted.left.distortion.map_or(0.0, |d| d.k1);
    assert!((k1 - 1e-3).abs() < 5e-5, "k1 {k1}");
    assert!(fitted.rms_reprojection_px.is_some_and(|r| r[0] > 0.0 && r[0] < 0.05));
    // The fit states its scales' uncertainty, in the file and on stderr, so
    // the measurements made with it carry the calibration in their budgets.
    let u = fitted.scale_uncertainty.expect("the calibration's scale uncertainty");
    assert!(u.height_relative.is_some_and(|h| h > 0.0 && h < 1e-2), "{u:?}");
    assert!(u.lateral_relative.is_some_and(|l| l > 0.0 && l < 1e-2), "{u:?}");
    assert!(json(&calibration)["uncertainty"]["height_scale_relative"].is_f64());
    assert!(err.contains("scale uncertainty from the fit"), "{err}");

    let r = json(&report);
    let poses = r["poses"].as_array().expect("poses");
    assert_eq!(poses.len(), 8);
    for (k, pose) in poses.iter().enumerate() {
        assert_eq!(pose["index"], k);
        for (c, camera) in ["left", "right"].iter().enumerate() {
            let view = &pose["cameras"][c];
            assert_eq!(view["camera"], *camera);
            assert_eq!(view["points"].as_u64().unwrap_or(0) + view["outliers"].as_u64().unwrap_or(0), 99);
            assert!(view["rms_reprojection_px"].as_f64().is_some_and(|v| v > 0.0 && v < 0.1), "{view}");
        }
    }
    assert_eq!(r["distortion_model"], "k1");
}

#[test]
fn the_distortion_option_chooses_the_fitted_terms() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = simulate_set(dir.path(), "checkerboard");
    // A pose without the target in one camera is skipped, named in the table and the warnings.
    image::GrayImage::from_pixel(640, 480, image::Luma([90u8]))
        .save(dir.path().join("right/pose04.png"))
        .expect("saved");
    let calibration = dir.path().join("none.json");
    let out = sheen(&["calibrate", text(&set), "--out", text(&calibration), "--distortion", "none"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.lines().any(|l| l.starts_with("pose 4 ") && l.contains("skipped")), "{err}");
    assert!(err.lines().any(|l| l.starts_with("warning: pose 4 skipped: right/pose04.png")), "{err}");
    assert!(err.contains("(7 of 8 poses, distortion none"), "{err}");
    let (fitted, _) = read_calibration(&calibration).expect("reads back");
    assert!(fitted.left.distortion.is_none_or(|d| d.k1 == 0.0 && d.k2 == 0.0), "{:?}", fitted.left.distortion);
    // Without the lens term the 1e-3 barrel shows in the residuals (about
    // 0.004 px with k1 fitted, 0.02 px without).
    assert!(fitted.rms_reprojection_px.is_some_and(|r| r[0] > 0.015), "{:?}", fitted.rms_reprojection_px);

    let out = sheen(&["calibrate", text(&set), "--out", text(&calibration), "--distortion", "fisheye"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("fisheye"), "{}", stderr(&out));
}

/// Asserts a failed run with exactly one `error:` line containing every one of `needles`.
fn assert_one_line_error(out: &Output, needles: &[&str]) {
    assert!(!out.status.success(), "the command must fail");
    let err = stderr(out);
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    for n in needles {
        assert!(errors[0].contains(n), "'{n}' missing in: {}", errors[0]);
    }
}

fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v = json(path);
    edit(&mut v);
    std::fs::write(path, serde_json::to_vec_pretty(&v).expect("json")).expect("write");
}

#[test]
fn bad_calibration_sets_fail_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = simulate_set(dir.path(), "circles");
    let out_file = dir.path().join("calibration.json");
    let calibrate = || sheen(&["calibrate", text(&set), "--out", text(&out_file), "-q"]);
    let set_name = set.display().to_string();

    // Unknown target kind.
    let original = std::fs::read(&set).expect("read");
    edit_json(&set, |v| v["target"]["kind"] = "rings".into());
    assert_one_line_error(&calibrate(), &[&set_name, "'rings' is unknown"]);
    std::fs::write(&set, &original).expect("restore");

    // One camera's image missing.
    let missing = dir.path().join("right/pose05.png");
    let kept = std::fs::read(&missing).expect("read");
    std::fs::remove_file(&missing).expect("remove");
    assert_one_line_error(&calibrate(), &[&set_name, "right/pose05.png", "pose 5: the right image"]);
    std::fs::write(&missing, kept).expect("restore");

    // Fewer than 3 usable poses: the left images of poses 2 to 7 show no target.
    let blank = image::GrayImage::from_pixel(640, 480, image::Luma([200u8]));
    for k in 2..8 {
        blank.save(dir.path().join(format!("left/pose{k:02}.png"))).expect("saved");
    }
    assert_one_line_error(&calibrate(), &[&set_name, "only 2 pose(s)", "at least 3", "left/pose07.png"]);
    assert!(!out_file.exists(), "nothing is written when calibration fails");

    // The output may not overwrite an input.
    let out = sheen(&["calibrate", text(&set), "--out", text(&dir.path().join("left/pose00.png")), "-q"]);
    assert_one_line_error(&out, &["refusing to write", "pose00.png"]);

    // A set file that does not exist.
    let nowhere = dir.path().join("nowhere/calibration_set.json");
    let out = sheen(&["calibrate", text(&nowhere), "--out", text(&out_file), "-q"]);
    assert_one_line_error(&out, &[&nowhere.display().to_string()]);
}

#[test]
fn simulate_names_an_unknown_scene_and_a_bad_pose_count() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = sheen(&["simulate", "--scene", "calibration-plate", "--out", text(dir.path())]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("calibration-target"), "{}", stderr(&out));
    let out = sheen(&[
        "simulate",
        "--scene",
        "calibration-target",
        "--poses",
        "2",
        "--width",
        "320",
        "--height",
        "240",
        "--out",
        text(dir.path()),
        "-q",
    ]);
    assert_one_line_error(&out, &["2 poses", "at least 3"]);
}

#[test]
fn few_and_little_tilted_poses_are_warned_about_on_the_command_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = sheen(&[
        "simulate",
        "--scene",
        "calibration-target",
        "--poses",
        "3",
        "--tilt",
        "4",
        "--width",
        "640",
        "--height",
        "480",
        "--out",
        text(dir.path()),
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let calibration = dir.path().join("calibration.json");
    let out = sheen(&["calibrate", text(&dir.path().join("calibration_set.json")), "--out", text(&calibration)]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.lines().any(|l| l.starts_with("warning: only 3 poses are usable")), "{err}");
    assert!(err.lines().any(|l| l.starts_with("warning: the poses tilt at most")), "{err}");
    assert!(calibration.is_file());
}

#[test]
fn the_distortion_of_simulate_applies_to_fringe_scenes_too() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = sheen(&[
        "simulate",
        "--scene",
        "flat",
        "--width",
        "64",
        "--height",
        "48",
        "--periods",
        "912,144,24",
        "--shifts",
        "4",
        "--distortion",
        "2e-3",
        "--out",
        text(dir.path()),
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let truth = json(&dir.path().join("truth/truth.json"));
    for camera in ["left", "right"] {
        let k1 = truth["calibration"]["cameras"][camera]["distortion"]["k1"].as_f64();
        assert_eq!(k1, Some(2e-3), "{camera}: {}", truth["calibration"]);
    }
}
