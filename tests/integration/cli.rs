//! The `sheen` binary as a production line uses it: exit codes, one-line
//! errors naming the file, and the files it writes.

use std::path::Path;
use std::process::{Command, Output};

use sheen::io::dataset::write_measurement;

use crate::util::measurement;

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A one-camera 12-bit fringe set without calibration on disk.
fn one_camera_set(dir: &Path) -> std::path::PathBuf {
    let (w, h) = (96, 32);
    let m = measurement(
        w,
        h,
        4095,
        &[912.0, 144.0, 24.0, 12.0],
        6,
        |i| 60.0 + 7.5 * (i % w) as f64,
        |_, i| {
            if (i % w) > w / 2 { (3900.0, 600.0) } else { (2000.0, 1200.0) }
        },
    );
    write_measurement(dir, &m).expect("write the fringe set")
}

#[test]
fn phase_writes_the_map_contract_for_one_camera() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let maps = dir.path().join("maps");
    let report = dir.path().join("report.json");
    let out = sheen(&[
        "phase",
        manifest.to_str().expect("utf8"),
        "--maps",
        maps.to_str().expect("utf8"),
        "--report",
        report.to_str().expect("utf8"),
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    for name in [
        "left_fused_phase.tif",
        "left_source.tif",
        "left_saturation_12.tif",
        "left_wrapped_912.tif",
        "left_modulation_24.tif",
    ] {
        assert!(maps.join(name).is_file(), "missing {name}");
        assert!(maps.join(name.replace(".tif", ".png")).is_file(), "missing preview of {name}");
    }
    let fused = sheen::io::maps::read_f32_tiff(&maps.join("left_fused_phase.tif")).expect("read back");
    assert_eq!((fused.width, fused.height), (96, 32));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).expect("report")).expect("json");
    assert_eq!(json["cameras"][0]["camera"], "left");
    // The right half saturates some samples at every period: the report counts them.
    assert!(json["cameras"][0]["sets"][3]["saturated_pixels"].as_u64().expect("count") > 0);
    assert!(json["cameras"][0]["valid_percent"].as_f64().expect("percent") > 90.0);
}

#[test]
fn reconstruct_refuses_one_camera_with_one_clear_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let cloud = dir.path().join("cloud.ply");
    let out = sheen(&["reconstruct", manifest.to_str().expect("utf8"), "--out", cloud.to_str().expect("utf8")]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert_eq!(err.lines().filter(|l| l.starts_with("error:")).count(), 1, "{err}");
    assert!(err.contains("two cameras and a calibration") && err.contains("sheen phase"), "{err}");
    assert!(!cloud.exists(), "no cloud is written");
}

#[test]
fn missing_manifest_is_named_in_the_error() {
    let out = sheen(&["phase", "/nonexistent/fringe-set.json", "--maps", "/tmp/x"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("/nonexistent/fringe-set.json"), "{}", stderr(&out));
}

#[test]
fn outputs_never_overwrite_inputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let before = std::fs::read(&manifest).expect("manifest");
    let out = sheen(&["phase", manifest.to_str().expect("utf8"), "--report", manifest.to_str().expect("utf8")]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("input"), "{}", stderr(&out));
    assert_eq!(std::fs::read(&manifest).expect("manifest"), before, "the manifest is untouched");
}

#[test]
fn bad_parameters_are_refused_before_running() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let m = manifest.to_str().expect("utf8");
    let out = sheen(&["phase", m, "--report", "/tmp/r.json", "--sat-threshold", "0"]);
    assert!(stderr(&out).contains("outside 1..=65535"), "{}", stderr(&out));
    let out = sheen(&["phase", m, "--report", "/tmp/r.json", "--disable-set", "7"]);
    assert!(stderr(&out).contains("has 4 sets"), "{}", stderr(&out));
    let out = sheen(&["phase", m, "--report", "/tmp/r.json", "--method", "magic"]);
    assert!(!out.status.success() && stderr(&out).contains("magic"), "{}", stderr(&out));
}

#[test]
fn usage_errors_exit_1_on_every_subcommand_never_2() {
    // 2 is `sheen analyze`'s "a toleranced measurement failed"; a mistyped
    // command line must not be counted as a failed part.
    for sub in ["reconstruct", "phase", "simulate", "analyze", "calibrate", "import", "check"] {
        let o = sheen(&[sub, "--no-such-option"]);
        assert_eq!(o.status.code(), Some(1), "{sub}: {}", stderr(&o));
        assert!(stderr(&o).contains("--no-such-option"), "{sub}: clap's message names the option: {}", stderr(&o));
        let help = sheen(&[sub, "--help"]);
        assert_eq!(help.status.code(), Some(0), "{sub} --help");
        assert!(!help.stdout.is_empty(), "{sub} --help prints to stdout");
    }
}
