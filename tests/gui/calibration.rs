//! The calibration window in the real app: it opens from the menu bar, reads
//! a simulated calibration set and solves it on workers, shows each pose's
//! RMS, re-solves without a pose the operator unticks, saves a calibration
//! that reads back, and gives the open fringe set the new calibration.

use std::path::{Path, PathBuf};
use std::time::Duration;

use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use sheen::app::{AppOptions, SheenApp, Startup};
use sheen::engine::calibration::model::DistortionModel;
use sheen::engine::calibration::target::TargetKind;
use sheen::io::calibration_set::{SimulatedCalibrationSet, write_simulated_calibration_set};
use sheen::sim::target::{CalibrationTargetConfig, render_calibration_set};
use sheen::sim::{Rig, RigConfig};

use super::{WINDOW, shows, started, wait_for_result};

/// Writes a simulated dot-grid set through the simulator's rig at `size`
/// (8 poses, 1 DN of noise, radial distortion `k1`); returns the set's path.
fn write_set(dir: &Path, size: [usize; 2], k1: f64) -> PathBuf {
    let rig = Rig::new(&RigConfig { distortion_k1: k1, ..RigConfig::default() }, size[0], size[1], 0.0);
    let cameras = [rig.left, rig.right];
    let mut config = CalibrationTargetConfig::for_field(TargetKind::Circles, &cameras[0]);
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
        settings: serde_json::Value::Null,
    };
    write_simulated_calibration_set(dir, &sim).expect("written").set
}

/// Steps until `done`, for up to a minute (detection and solving run on workers).
fn wait(h: &mut Harness<'_, SheenApp>, what: &str, done: impl Fn(&SheenApp) -> bool) {
    for _ in 0..6000 {
        h.step();
        if done(h.state()) {
            h.run_steps(3);
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let c = h.state().calibration_view();
    panic!("timed out waiting for {what}; calibration error: {:?}", c.error());
}

/// Opens the calibration window and types `set` into its path field.
fn type_set_path(h: &mut Harness<'_, SheenApp>, set: &Path) {
    h.get_by_label("Calibration").click();
    h.run_steps(3);
    assert!(shows(h, "No calibration set"));
    h.get_by_label("Calibration set path").focus();
    h.run_steps(1);
    h.get_by_label("Calibration set path").type_text(&set.display().to_string());
    h.run_steps(1);
}

fn open_set(h: &mut Harness<'_, SheenApp>, set: &Path) {
    type_set_path(h, set);
    h.get_by_label("Load").click();
    wait(h, "the first solution", |app| {
        let c = app.calibration_view();
        c.solves_finished() >= 1 && !c.is_busy()
    });
}

#[test]
fn the_calibration_window_solves_removes_a_pose_and_saves() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = write_set(dir.path(), [640, 480], 1e-3);
    let mut h = started();
    open_set(&mut h, &set);

    let c = h.state().calibration_view();
    assert!(c.error().is_none(), "{:?}", c.error());
    let report = &c.solved().expect("solved").report;
    assert_eq!(report.poses.len(), 8);
    let [l, r] = report.rms_per_camera();
    assert!(l > 0.0 && l < 0.05 && r > 0.0 && r < 0.05, "rms {l} {r}");
    // The table shows each pose's RMS, the chart and both images of the selected pose.
    let pose3_left = report.poses[3].cameras[0].rms_reprojection_px;
    assert!(shows(&h, &format!("{pose3_left:.4}")), "pose 3's left RMS {pose3_left:.4} must be on screen");
    assert!(shows(&h, "RMS per pose chart"));
    assert!(shows(&h, "pose 0 · left image") && shows(&h, "pose 0 · right image"));
    // Every control of the window is reachable by name (screen readers, tests).
    h.check_accessibility();
    // Another pose's images on request.
    h.get_by_label("pose 5").click();
    h.run_steps(3);
    assert!(shows(&h, "pose 5 · right image"));
    // A click on an image shows that camera alone; another click both again.
    h.get_by_label("pose 5 · right image").click();
    h.run_steps(3);
    assert!(shows(&h, "pose 5 · right image") && !shows(&h, "pose 5 · left image"));
    h.get_by_label("pose 5 · right image").click();
    h.run_steps(3);
    assert!(shows(&h, "pose 5 · left image"));

    // Untick pose 3: solved again from 7 poses, without it.
    h.get_by_label("use pose 3").click();
    wait(&mut h, "the second solution", |app| {
        let c = app.calibration_view();
        c.solves_finished() >= 2 && !c.is_busy()
    });
    let c = h.state().calibration_view();
    assert!(c.excluded().contains(&3));
    let solved = c.solved().expect("solved");
    assert_eq!(solved.report.poses.len(), 7);
    assert!(solved.report.poses.iter().all(|p| p.index != 3));
    assert!(shows(&h, "7 of 8 (0 skipped, 1 left out)"));
    let calibration = solved.calibration.clone();

    // The synthetic fringe set is 160 x 120 px: the calibration cannot be used for it.
    assert!(shows(&h, "The calibration is for 640x480 px images"));

    // Save to the suggested path beside the set; it reads back as solved.
    h.get_by_label("Save").click();
    wait(&mut h, "the saved file", |app| app.calibration_view().last_saved().is_some());
    let saved = h.state().calibration_view().last_saved().expect("saved").to_path_buf();
    assert_eq!(saved, dir.path().join("calibration.json"));
    let (back, _) = sheen::io::calibration::read_calibration(&saved).expect("reads back");
    // JSON keeps every digit; parsing may differ in the last bit.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(1.0);
    for (b, c) in [(&back.left, &calibration.left), (&back.right, &calibration.right)] {
        assert!(b.p.iter().flatten().zip(c.p.iter().flatten()).all(|(x, y)| close(*x, *y)), "{:?} vs {:?}", b.p, c.p);
        let (kb, kc) = (b.distortion.expect("distortion").k1, c.distortion.expect("distortion").k1);
        assert!(close(kb, kc) && (kb - 1e-3).abs() < 1e-4, "k1 {kb} vs {kc}");
    }
    assert!(shows(&h, "Calibration saved to"));

    // Another distortion model solves again; without the lens term the residuals grow.
    h.get_by_role_and_label(egui::Role::ComboBox, "Distortion model").click();
    h.run_steps(2);
    h.get_by_label("none").click();
    wait(&mut h, "the solution without distortion", |app| {
        let c = app.calibration_view();
        c.solves_finished() >= 3 && !c.is_busy()
    });
    let solved = h.state().calibration_view().solved().expect("solved");
    assert_eq!(solved.distortion, DistortionModel::None);
    assert!(solved.calibration.left.distortion.is_none_or(|d| d.k1 == 0.0));
    assert!(solved.report.rms_reprojection_px > 3.0 * l, "{} vs {l}", solved.report.rms_reprojection_px);
    assert_eq!(solved.report.poses.len(), 7, "pose 3 stays left out");
}

#[test]
fn a_bad_set_is_shown_as_an_error_not_a_crash() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = dir.path().join("calibration_set.json");
    std::fs::write(&set, r#"{"sheen_calibration_set": 1, "target": {"kind": "rings", "rows": 9, "cols": 11, "pitch_mm": 0.5}, "poses": []}"#)
        .expect("write");
    let mut h = started();
    type_set_path(&mut h, &set);
    h.get_by_label("Load").click();
    wait(&mut h, "the error", |app| app.calibration_view().error().is_some() && !app.calibration_view().is_busy());
    let e = h.state().calibration_view().error().expect("error").to_owned();
    assert!(e.contains(&set.display().to_string()) && e.contains("'rings' is unknown"), "{e}");
    assert!(shows(&h, "'rings' is unknown"));
    assert!(h.state().calibration_view().set().is_none());
}

#[test]
fn a_calibration_from_the_window_is_used_for_the_open_fringe_set() {
    // The simulator's watch plate and a target set through the same rig and size.
    let size = [320, 240];
    let dir = tempfile::tempdir().expect("tempdir");
    let set = write_set(dir.path(), size, 0.0);
    let options = AppOptions {
        startup: Startup::Demo,
        demo_size: size,
        demo: sheen::app::loading::simulated_watch_plate,
        restore_state: false,
    };
    let mut h =
        Harness::builder().with_size(WINDOW).with_max_steps(64).build_eframe(move |cc| SheenApp::new(cc, options));
    let g0 = wait_for_result(&mut h, 0);
    let id = h.state().session().expect("session").measurement.id;
    open_set(&mut h, &set);
    let calibration = h.state().calibration_view().solved().expect("solved").calibration.clone();
    h.get_by_label("Use for the open fringe set").click();
    let g1 = wait_for_result_after_apply(&mut h, g0);
    let app = h.state();
    let session = app.session().expect("session");
    assert_eq!(session.measurement.id, id, "the same fringe set, measured again");
    assert_eq!(session.measurement.calibration.as_ref(), Some(&calibration));
    let rec = &app.result().expect("result").reconstruction;
    assert!(g1 > g0);
    assert!(rec.stereo.is_some(), "{:?}", rec.stereo_skipped);
    assert!(rec.point_count() > 1000, "{} points", rec.point_count());
}

fn wait_for_result_after_apply(h: &mut Harness<'_, SheenApp>, after: u64) -> u64 {
    wait(h, "the result with the new calibration", |app| {
        app.result().is_some_and(|r| r.generation > after) && !app.is_busy() && !app.calibration_view().is_busy()
    });
    h.state().result().map_or(0, |r| r.generation)
}

/// Cancel stops a detection on its worker: no error, nothing half-loaded,
/// and the window works on afterwards.
#[test]
fn cancel_stops_a_detection_and_the_window_works_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = write_set(dir.path(), [640, 480], 1e-3);
    let mut h = started();
    type_set_path(&mut h, &set);

    // Cancel the detection the moment it shows.
    h.get_by_label("Load").click();
    h.run_steps(2);
    assert!(h.state().calibration_view().is_busy(), "detection must be running");
    assert!(shows(&h, "Detecting"));
    h.get_by_label("Cancel detection").click();
    wait(&mut h, "the cancelled detection", |app| !app.calibration_view().is_busy());
    let c = h.state().calibration_view();
    assert!(c.error().is_none(), "cancelling is not an error: {:?}", c.error());
    assert!(c.set().is_none() && c.solved().is_none() && c.solves_finished() == 0);
    assert!(h.state().log().entries().iter().any(|e| e.text.contains("cancelled")));
    assert!(!shows(&h, "Detecting"));

    // Loading again after the cancel works. (A re-solve is too quick to
    // cancel reliably from a test; it shares the job and the action.)
    h.get_by_label("Load").click();
    wait(&mut h, "the first solution", |app| {
        let c = app.calibration_view();
        c.solves_finished() >= 1 && !c.is_busy()
    });
    let c = h.state().calibration_view();
    assert!(c.error().is_none(), "{:?}", c.error());
    assert_eq!(c.solved().expect("solved").report.poses.len(), 8);
}
