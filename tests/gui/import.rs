//! Issue 13 in the app: a one-camera manifest without calibration opens with
//! every per-camera view populated and the 3D views saying what they need;
//! the Import dialog turns a folder of images into a manifest and opens it.

use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT as _, Queryable as _};
use sheen::app::SheenApp;
use sheen::app::views::ViewKind;
use sheen::engine::shift_estimate::{PhaseDirection, Verdict};

use super::{harness, opened, shows, step_until, synthetic, wait_for_result};

/// The synthetic measurement with its left camera only and no calibration.
fn one_camera() -> sheen::engine::fringe::Measurement {
    let mut m = synthetic::measurement();
    m.cameras.truncate(1);
    m.calibration = None;
    m
}

/// Labels of the map images on screen ("left · set 0 · 500 px map").
fn map_labels(h: &Harness<'_, SheenApp>) -> Vec<String> {
    h.query_all_by_label_contains(" map")
        .filter_map(|n| n.accesskit_node().label())
        .filter(|l| l.ends_with(" map") && l.contains(" · "))
        .collect()
}

#[test]
fn a_one_camera_manifest_opens_with_every_per_camera_view() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = synthetic::write_manifest(dir.path(), &one_camera());
    let mut h = opened(path);
    let app = h.state();
    assert!(app.banner().is_none(), "{:?}", app.banner().map(|b| &b.text));
    let m = &app.session().expect("session").measurement;
    assert_eq!(m.cameras.len(), 1);
    assert!(m.calibration.is_none());
    let rec = &app.result().expect("result").reconstruction;
    assert!(rec.stereo.is_none());
    assert!(rec.cameras[0].fused.valid_count() > synthetic::WIDTH * synthetic::HEIGHT * 9 / 10);
    for kind in [
        ViewKind::Raw,
        ViewKind::Saturation,
        ViewKind::Wrapped,
        ViewKind::Modulation,
        ViewKind::Uncertainty,
        ViewKind::Unwrapped,
        ViewKind::Fused,
        ViewKind::Sources,
        ViewKind::Valid,
    ] {
        h.get_by_label(kind.title()).click();
        h.run_steps(3);
        let maps = map_labels(&h);
        assert!(maps.iter().any(|l| l.starts_with("left ·")), "{kind:?} shows no map of the camera: {maps:?}");
        assert!(!shows(&h, "No result yet"), "{kind:?}");
    }
    for kind in [ViewKind::Height, ViewKind::Cloud] {
        h.get_by_label(kind.title()).click();
        h.run_steps(3);
        assert!(shows(&h, "3D needs a second camera and a calibration"), "{kind:?} must say what it needs");
        assert!(map_labels(&h).is_empty(), "{kind:?} draws no map");
    }
    // The comparison falls back to phase maps without 3D.
    h.get_by_label(ViewKind::Compare.title()).click();
    step_until(&mut h, "the comparison", |app| app.compare_output().is_some() && !app.is_busy());
    h.run_steps(3);
    assert!(map_labels(&h).iter().any(|l| l.contains("fused phase")), "{:?}", map_labels(&h));
    // The inspector works on the one camera.
    h.state_mut().push_command(sheen::app::commands::Command::SelectPixel(sheen::app::commands::PixelRef {
        camera: 0,
        u: 40,
        v: 30,
    }));
    h.run_steps(3);
    let report = h.state().pixel_report().expect("pixel report");
    assert_eq!(report.sets.len(), 3);
    assert!(report.sets.iter().all(|s| s.fit.is_some()));
}

/// The synthetic stereo measurement as a vendor would write it: one folder,
/// `cam{L,R}_{1..36}.png`, plus Gray-code images to skip.
fn vendor_folder(dir: &std::path::Path) -> std::path::PathBuf {
    use sheen::engine::fringe::Samples;
    let m = synthetic::measurement();
    let folder = dir.join("rig export");
    std::fs::create_dir_all(&folder).expect("mkdir");
    for (cam, key) in m.cameras.iter().zip(["L", "R"]) {
        let mut index = 1;
        for stack in &cam.stacks {
            let Samples::U8(samples) = &stack.samples else { panic!("8-bit") };
            let n = stack.width * stack.height;
            for k in 0..stack.shifts {
                let img = image::GrayImage::from_raw(
                    stack.width as u32,
                    stack.height as u32,
                    samples[k * n..(k + 1) * n].to_vec(),
                )
                .expect("plane");
                img.save(folder.join(format!("cam{key}_{index}.png"))).expect("png");
                index += 1;
            }
        }
        image::GrayImage::new(cam.width as u32, cam.height as u32)
            .save(folder.join(format!("gray_{key}_0.png")))
            .expect("png");
    }
    folder
}

#[test]
fn the_import_dialog_writes_a_manifest_and_opens_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let folder = vendor_folder(dir.path());
    let mut h = harness(synthetic::demo);
    wait_for_result(&mut h, 0);
    let id0 = h.state().session().expect("session").measurement.id;
    // Reachable from the File menu.
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Import a folder of images…").click();
    h.run_steps(2);
    assert!(h.state().import_dialog().open);
    // A new window takes a sizing frame before it is shown.
    h.run_steps(3);
    assert!(h.query_by_label("Import folder").is_some(), "the dialog's form is on screen");
    // The folder picker cannot be clicked in a test: set what it would.
    {
        let dialog = h.state_mut().import_dialog_mut();
        dialog.open_with_folder(&folder);
        dialog.form.pattern = "cam{camera}_{index}.png".into();
        dialog.form.cameras = "left=L,right=R".into();
    }
    // Periods missing: the dialog says so.
    step_until(&mut h, "the scan", |app| !app.import_dialog().is_busy());
    let error = h.state().import_dialog().scan_error().expect("an error").to_string();
    assert!(error.contains("--periods"), "{error}");
    assert!(shows(&h, "no fringe periods"));
    // Typed through the form like the operator does.
    h.get_by_label("Import periods").focus();
    h.run_steps(1);
    h.get_by_label("Import periods").type_text("500,100,20");
    h.get_by_label("Import shifts").focus();
    h.run_steps(1);
    h.get_by_label("Import shifts").type_text("12");
    h.run_steps(1);
    step_until(&mut h, "the scan and the shift check", |app| {
        let d = app.import_dialog();
        !d.is_busy() && d.shift_check().is_some()
    });
    let dialog = h.state().import_dialog();
    let error = dialog.scan_error();
    let a = dialog.assignment().unwrap_or_else(|| panic!("an assignment: {error:?}"));
    assert_eq!(a.cameras, ["left", "right"]);
    assert_eq!(a.sets[1].files["right"][0], "camR_13.png");
    assert_eq!(a.ignored.len(), 2, "the Gray-code images are left out: {:?}", a.ignored);
    assert_eq!(dialog.thumbnail_count(), 6, "a thumbnail per camera and set");
    let checks = dialog.shift_check().expect("check").as_ref().expect("check ran");
    assert!(checks.iter().flat_map(|c| &c.sets).all(|s| s.verdict == Verdict::Agrees), "{checks:?}");
    assert!(shows(&h, "camL_13.png"), "the table lists the files");

    h.get_by_label("Write manifest and open").click();
    step_until(&mut h, "the imported measurement", |app| {
        app.session().is_some_and(|s| s.measurement.id != id0) && app.result().is_some() && !app.is_busy()
    });
    let app = h.state();
    assert!(!app.import_dialog().open, "the dialog closes once the manifest is open");
    let manifest = folder.join("fringe-set.json");
    assert!(manifest.is_file());
    let session = app.session().expect("session");
    assert_eq!(session.source, sheen::app::run_data::DataSource::File(manifest.clone()));
    assert_eq!(session.measurement.cameras[1].stacks[2].samples, synthetic::measurement().cameras[1].stacks[2].samples);
    let listed = sheen::io::manifest::read_manifest(&manifest).expect("manifest");
    assert_eq!(listed.sets[0].images["left"][11], "camL_12.png");
}

/// The app with its Import dialog filled in for [`vendor_folder`] (written
/// into `dir`, returned beside it), with `shifts` per set.
fn import_dialog_on_vendor_folder(
    dir: &std::path::Path,
    shifts: &str,
) -> (Harness<'static, SheenApp>, std::path::PathBuf) {
    let folder = vendor_folder(dir);
    let mut h = harness(synthetic::demo);
    wait_for_result(&mut h, 0);
    let d = h.state_mut().import_dialog_mut();
    d.open_with_folder(&folder);
    d.form.pattern = "cam{camera}_{index}.png".into();
    d.form.cameras = "left=L,right=R".into();
    d.form.periods = "500,100,20".into();
    d.form.shifts = shifts.into();
    (h, folder)
}

/// A shift direction reversed in every set only mirrors the phase, so the
/// images alone agree with it; told where the phase grows, the check flags it.
#[test]
fn the_phase_direction_lets_the_shift_check_catch_an_all_reversed_convention() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mut h, _) = import_dialog_on_vendor_folder(dir.path(), "12");
    // The images are recorded +2 pi k / N; the operator claims the reverse.
    h.state_mut().import_dialog_mut().form.reversed = true;
    let checked = |app: &SheenApp| {
        let d = app.import_dialog();
        !d.is_busy() && d.shift_check().is_some()
    };
    let verdicts = |h: &Harness<'_, SheenApp>| -> Vec<Verdict> {
        let check = h.state().import_dialog().shift_check().expect("check").as_ref().expect("check ran");
        check.iter().flat_map(|c| c.sets.iter().map(|s| s.verdict.clone())).collect()
    };
    step_until(&mut h, "the scan and the shift check", checked);
    let v = verdicts(&h);
    assert_eq!(v.len(), 6);
    assert!(v.iter().all(|v| *v == Verdict::Agrees), "without a direction nothing tells: {v:?}");

    // The operator says the phase grows to the right, through the dialog.
    h.run_steps(3);
    h.get_by_role_and_label(egui::Role::ComboBox, "Phase grows").click();
    h.run_steps(2);
    h.get_by_label("to the right").click();
    h.run_steps(2);
    assert_eq!(h.state().import_dialog().form.phase_grows, Some(PhaseDirection::Right));
    step_until(&mut h, "the check with the direction", checked);
    let v = verdicts(&h);
    assert!(v.iter().all(|v| v.is_problem()), "every set is reversed: {v:?}");
    assert!(shows(&h, "disagree with the manifest"));

    // The right convention with the same direction passes.
    h.state_mut().import_dialog_mut().form.reversed = false;
    h.run_steps(2);
    step_until(&mut h, "the check of the plain convention", checked);
    let v = verdicts(&h);
    assert!(v.iter().all(|v| *v == Verdict::Agrees), "{v:?}");
}

#[test]
fn import_dialog_errors_stay_in_the_dialog() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mut h, folder) = import_dialog_on_vendor_folder(dir.path(), "10");
    step_until(&mut h, "the scan", |app| !app.import_dialog().is_busy());
    let error = h.state().import_dialog().scan_error().expect("an error").to_string();
    assert!(error.contains("camera 'left' has 36 images but the sets need 30 (10+10+10)"), "{error}");
    assert!(h.state().banner().is_none(), "dialog errors are not banners");
    assert!(!folder.join("fringe-set.json").exists());
}

#[test]
fn opening_a_folder_opens_the_import_dialog_on_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let folder = vendor_folder(dir.path());
    let mut h = harness(synthetic::demo);
    wait_for_result(&mut h, 0);
    let id0 = h.state().session().expect("session").measurement.id;
    h.state_mut().push_command(sheen::app::commands::Command::Open(folder.clone()));
    h.run_steps(3);
    let app = h.state();
    assert!(app.import_dialog().open);
    assert_eq!(app.import_dialog().form.folder, folder.display().to_string());
    assert!(app.banner().is_none(), "a folder is not a broken manifest");
    assert_eq!(app.session().expect("session").measurement.id, id0, "the measurement on screen stays");
}
