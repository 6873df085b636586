//! The real app driven through egui_kittest (no display needed): it loads a
//! small synthetic stereo measurement, waits for the engine on its worker,
//! and checks that what the operator does reaches the engine and the screen.

#[path = "gui/synthetic.rs"]
mod synthetic;

#[path = "gui/cloud.rs"]
mod cloud;

#[path = "gui/calibration.rs"]
mod calibration;
#[path = "gui/gauge.rs"]
mod gauge;
#[path = "gui/import.rs"]
mod import;
#[path = "gui/inspect.rs"]
mod inspect;
#[path = "gui/line.rs"]
mod line;
#[path = "gui/projector.rs"]
mod projector;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use eframe::egui::{self, Vec2};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use sheen::app::commands::PixelRef;
use sheen::app::loading::DemoFn;
use sheen::app::run_data::DataSource;
use sheen::app::views::ViewKind;
use sheen::app::widgets::map_view;
use sheen::app::{AppOptions, SheenApp, Startup};
use sheen::engine::fusion::SOURCE_NONE;
use sheen::engine::pipeline::Method;

const WINDOW: Vec2 = Vec2::new(1280.0, 800.0);

fn options(demo: DemoFn) -> AppOptions {
    AppOptions { startup: Startup::Demo, demo_size: [160, 120], demo, restore_state: false }
}

/// Presses and releases the primary button at `pos` (no frame between).
fn press_release(h: &mut Harness<'_, SheenApp>, pos: egui::Pos2) {
    for pressed in [true, false] {
        h.event(egui::Event::PointerButton {
            pos,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: egui::Modifiers::NONE,
        });
    }
}

/// A primary click at `pos` (move, press, release), then a few frames.
fn click_at(h: &mut Harness<'_, SheenApp>, pos: egui::Pos2) {
    h.event(egui::Event::PointerMoved(pos));
    press_release(h, pos);
    h.run_steps(3);
}

/// The pointer moved to `pos` and a wheel turn of `dy` points there (no frames run).
fn wheel_at(h: &mut Harness<'_, SheenApp>, pos: egui::Pos2, dy: f32) {
    h.event(egui::Event::PointerMoved(pos));
    h.event(egui::Event::MouseWheel {
        unit: egui::MouseWheelUnit::Point,
        delta: egui::vec2(0.0, dy),
        modifiers: egui::Modifiers::NONE,
        phase: egui::TouchPhase::Move,
        source: egui::MouseWheelSource::Wheel,
    });
}

fn harness(demo: DemoFn) -> Harness<'static, SheenApp> {
    Harness::builder().with_size(WINDOW).with_max_steps(64).build_eframe(move |cc| SheenApp::new(cc, options(demo)))
}

/// Steps the app until `done` holds, sleeping between frames so worker threads
/// progress; panics after about 20 seconds.
fn step_until(h: &mut Harness<'_, SheenApp>, what: &str, done: impl Fn(&SheenApp) -> bool) {
    for _ in 0..2000 {
        h.step();
        if done(h.state()) {
            // A few more frames so the UI shows what just arrived.
            h.run_steps(3);
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let log: Vec<String> = h.state().log().entries().iter().map(|e| format!("{:?}: {}", e.level, e.text)).collect();
    panic!("timed out waiting for {what}; the app's log:\n{}", log.join("\n"));
}

/// True if some node's label contains `text` (labels may repeat, e.g. a title and a map name).
fn shows(h: &Harness<'_, SheenApp>, text: &str) -> bool {
    h.query_all_by_label_contains(text).next().is_some()
}

fn generation(app: &SheenApp) -> u64 {
    app.result().map_or(0, |r| r.generation)
}

/// Waits for a result newer than `after` with nothing running or scheduled.
fn wait_for_result(h: &mut Harness<'_, SheenApp>, after: u64) -> u64 {
    step_until(h, "an engine result", |app| generation(app) > after && !app.is_busy());
    generation(h.state())
}

/// The app started on the fringe set at `manifest`, its first result in.
fn opened(manifest: PathBuf) -> Harness<'static, SheenApp> {
    let startup = Startup::Manifest(manifest);
    let mut h = Harness::builder()
        .with_size(WINDOW)
        .with_max_steps(64)
        .build_eframe(move |cc| SheenApp::new(cc, AppOptions { startup, ..options(synthetic::demo) }));
    wait_for_result(&mut h, 0);
    h
}

fn started() -> Harness<'static, SheenApp> {
    let mut h = harness(synthetic::demo);
    wait_for_result(&mut h, 0);
    h
}

#[test]
fn the_demo_opens_says_it_is_simulated_and_is_measured() {
    let mut h = started();
    let app = h.state();
    let session = app.session().expect("a session");
    assert!(session.source.is_simulated());
    let result = app.result().expect("a result");
    assert_eq!(result.reconstruction.params.method, Method::Hdr);
    assert!(result.reconstruction.stereo.is_some(), "{:?}", result.reconstruction.stereo_skipped);
    assert!(result.reconstruction.point_count() > 10_000, "{} points", result.reconstruction.point_count());
    assert!(shows(&h, "SIMULATED DATA"), "the simulated-data mark must be on screen");
    // Heights of a plane z = 0.05 x + 0.03 y over +-0.8 mm lie within +-70 um.
    let height = result.derived.height.as_ref().expect("height grid");
    let finite: Vec<f32> = height.iter().copied().filter(|z| z.is_finite()).collect();
    assert!(finite.iter().all(|z| z.abs() < 70.0), "heights in um");
    h.step();
}

#[test]
fn changing_the_threshold_reruns_the_engine_and_updates_the_statistics() {
    let mut h = started();
    let g0 = generation(h.state());
    let runs0 = h.state().engine_runs_started();
    let before = h.state().result().expect("result").reconstruction.cameras[0].sets[0].stats;
    h.get_by_label("Statistics").click();
    h.run_steps(2);
    assert!(shows(&h, "threshold 255 dn"));

    h.get_by_label("Saturation threshold (exact)").set_value_accesskit(200.0);
    let g1 = wait_for_result(&mut h, g0);
    let app = h.state();
    assert!(app.engine_runs_started() > runs0, "the change must start a run");
    let rec = &app.result().expect("result").reconstruction;
    assert_eq!(rec.saturation_threshold, 200);
    assert_eq!(rec.params.saturation_threshold, Some(200));
    let after = rec.cameras[0].sets[0].stats;
    assert!(
        after.partially_saturated > before.partially_saturated,
        "a lower threshold saturates more pixels: {} -> {}",
        before.partially_saturated,
        after.partially_saturated
    );
    assert!(g1 > g0);
    assert!(shows(&h, "threshold 200 dn"), "the statistics panel must show the new run");
    assert!(!shows(&h, "threshold 255 dn"));
}

#[test]
fn disabling_a_set_changes_the_fusion_and_reuses_the_phases() {
    let mut h = started();
    let g0 = generation(h.state());
    let before = h.state().result().expect("result").clone();
    let cam0 = &before.reconstruction.cameras[0];
    // With all sets, the blown-out disc is filled from set 1 (the densest usable there).
    assert_eq!(cam0.enabled, vec![0, 1, 2]);
    let from_set_1 = cam0.fused.source_counts[1];
    assert!(from_set_1 > 200, "set 1 fills the disc: {from_set_1} px");

    h.get_by_label("set 1").click();
    wait_for_result(&mut h, g0);
    let after = h.state().result().expect("result").clone();
    let cam0_after = &after.reconstruction.cameras[0];
    assert_eq!(cam0_after.enabled, vec![0, 2]);
    assert!(!cam0_after.fused.source_set.contains(&1), "set 1 must no longer supply pixels");
    assert!(cam0_after.fused.source_counts[0] > cam0.fused.source_counts[0], "set 0 takes over the disc");
    for (a, b) in cam0.sets.iter().zip(&cam0_after.sets) {
        assert!(Arc::ptr_eq(a, b), "toggling a set must reuse the per-set phases");
    }
}

#[test]
fn switching_the_method_changes_completeness() {
    let mut h = started();
    let g0 = generation(h.state());
    let hdr = h.state().result().expect("result").derived.completeness[0];
    h.get_by_role_and_label(egui::Role::ComboBox, "Method").click();
    h.run_steps(2);
    h.get_by_label("masked").click();
    wait_for_result(&mut h, g0);
    let result = h.state().result().expect("result");
    assert_eq!(result.reconstruction.params.method, Method::Masked);
    let masked = result.derived.completeness[0];
    assert!(hdr > 0.95, "hdr recovers nearly everything: {hdr}");
    assert!(masked < hdr - 0.05, "masked leaves the shiny disc out: {masked} vs {hdr}");
}

/// Issue 18: the order check and the stereo continuity rule are chosen in
/// the Parameters panel and reach the engine, which reruns with them.
#[test]
fn the_order_check_and_stereo_continuity_are_chosen_in_the_panel() {
    use sheen::engine::stereo_match::StereoContinuity;
    use sheen::engine::unwrap::OrderCheck;
    // The Statistics line the operator reads: the rule, and how many orders
    // were confirmed, left undecided or contradicted, from this very run.
    fn order_line(app: &SheenApp) -> String {
        let rec = &app.result().expect("result").reconstruction;
        let u = &rec.cameras[0].unwrapped;
        let pixels = rec.cameras[0].width * rec.cameras[0].height;
        let total = |v: &[usize]| v.iter().sum::<usize>();
        let pct = |v: &[usize]| sheen::app::views::percent(total(v), pixels);
        format!(
            "Fringe orders ({}): confirmed by neighbours {} · by patch {} · undecided {} · contradicted {}",
            u.check,
            pct(&u.confirmed_by_neighbours),
            pct(&u.confirmed_by_patch),
            pct(&u.undecided),
            pct(&u.contradicted)
        )
    }
    let mut h = started();
    let g0 = generation(h.state());
    assert_eq!(h.state().result().expect("result").reconstruction.params.order_check, OrderCheck::Evidence);
    h.get_by_label("Statistics").click();
    h.run_steps(2);
    let evidence_line = order_line(h.state());
    assert!(evidence_line.starts_with("Fringe orders (evidence)") && shows(&h, &evidence_line), "{evidence_line}");
    h.get_by_role_and_label(egui::Role::ComboBox, "Fringe orders").click();
    h.run_steps(2);
    h.get_by_label("strict").click();
    let g1 = wait_for_result(&mut h, g0);
    assert_eq!(h.state().result().expect("result").reconstruction.params.order_check, OrderCheck::Strict);
    h.run_steps(2);
    let strict_line = order_line(h.state());
    assert!(strict_line.starts_with("Fringe orders (strict)") && shows(&h, &strict_line), "{strict_line}");
    assert!(!shows(&h, "Fringe orders (evidence)"), "the statistics follow the new run");
    h.get_by_role_and_label(egui::Role::ComboBox, "Stereo continuity").click();
    h.run_steps(2);
    h.get_by_label("plain").click();
    wait_for_result(&mut h, g1);
    let params = &h.state().result().expect("result").reconstruction.params;
    assert_eq!(params.stereo_continuity, StereoContinuity::Plain);
    assert_eq!(params.order_check, OrderCheck::Strict, "the first choice stays");
}

#[test]
fn the_sources_view_marks_orders_confirmed_by_neighbours_and_can_stop() {
    let mut h = started();
    h.get_by_label("Sources").click();
    h.run_steps(2);
    assert!(h.state().state.views.sources.mark_confirmed, "marked by default");
    assert!(shows(&h, "confirmed by neighbours: "), "the legend gives the share of neighbour-confirmed pixels");
    assert!(shows(&h, "confirmed by patch: "));
    h.get_by_label("Mark confirmed orders").click();
    h.run_steps(2);
    assert!(!h.state().state.views.sources.mark_confirmed);
    assert!(!shows(&h, "confirmed by neighbours: "), "no legend entry for a tint that is not drawn");
}

/// Screen position of pixel (u, v) of the map labelled `label`.
fn pixel_position(h: &Harness<'_, SheenApp>, label: &str, size: [usize; 2], pixel: [usize; 2]) -> egui::Pos2 {
    let rect = h.get_by_label(label).rect();
    let image = map_view::image_rect(rect, size, &map_view::ViewTransform::default());
    map_view::pixel_center(image, size, pixel)
}

#[test]
fn clicking_a_pixel_plots_its_samples() {
    let mut h = started();
    h.get_by_label("Sources").click();
    h.run_steps(2);
    // A pixel in the middle of the shiny disc, in the left camera.
    let cam = synthetic::left_camera();
    let (u, v) = (105, 50);
    assert!(synthetic::on_disc(synthetic::surface_point(&cam, u as f64, v as f64)));
    let label = "left · fusion source per pixel map";
    let pos = pixel_position(&h, label, [synthetic::WIDTH, synthetic::HEIGHT], [u, v]);
    click_at(&mut h, pos);
    let app = h.state();
    assert_eq!(app.selection(), Some(PixelRef { camera: 0, u, v }));
    let report = app.pixel_report().expect("report");
    let m = &app.session().expect("session").measurement;
    for (s, set) in report.sets.iter().enumerate() {
        assert_eq!(set.samples_dn, m.cameras[0].stacks[s].pixel_samples(v * synthetic::WIDTH + u));
        assert_eq!(set.shifts_rad.len(), synthetic::SHIFTS);
    }
    // The dense set is blown out; the middle set keeps >= 3 samples and supplies the phase.
    assert_eq!(report.sets[2].saturated_count(), synthetic::SHIFTS);
    assert!(report.sets[1].saturated_count() < synthetic::SHIFTS - 2);
    let fit = report.sets[1].fit.expect("fit of set 1");
    assert!((fit.modulation - 100.0).abs() < 5.0, "B = {}", fit.modulation);
    assert_eq!(report.source, Some(1));
    assert!(report.verdict.contains("filled in by HDR fusion"), "{}", report.verdict);
    assert!(shows(&h, "set 2 · 20 px: 12 samples, 12 saturated"));
    assert!(shows(&h, "over-saturated: 0 unsaturated sample(s), 3 needed"));
}

#[test]
fn a_bad_manifest_shows_a_banner_and_keeps_the_previous_result() {
    let mut h = started();
    let g0 = generation(h.state());
    let id0 = h.state().session().expect("session").measurement.id;
    let bad = PathBuf::from("/nonexistent/folder/manifest.json");
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Manifest path").focus();
    h.run_steps(1);
    h.get_by_label("Manifest path").type_text(&bad.display().to_string());
    h.run_steps(1);
    h.get_by_label("Open path").click();
    step_until(&mut h, "the error banner", |app| app.banner().is_some() && !app.is_busy());
    let app = h.state();
    let banner = app.banner().expect("banner");
    assert!(banner.is_error);
    assert!(banner.text.contains("/nonexistent/folder/manifest.json"), "{}", banner.text);
    assert_eq!(app.session().expect("session").measurement.id, id0, "the previous measurement stays");
    assert_eq!(generation(app), g0, "the previous result stays");
    assert!(app.log().entries().iter().any(|e| e.text.contains("/nonexistent/folder/manifest.json")));
    assert!(shows(&h, "Could not open /nonexistent/folder/manifest.json"));
    h.get_by_label("Dismiss").click();
    h.run_steps(2);
    assert!(h.state().banner().is_none());
}

#[test]
fn disabling_every_set_is_an_error_in_the_ui_not_a_crash() {
    let mut h = started();
    let g0 = generation(h.state());
    // Without automatic re-runs, so no intermediate selection is run on the way.
    h.get_by_label("Re-run on every change").click();
    h.run_steps(1);
    for s in 0..3 {
        h.get_by_label(&format!("set {s}")).click();
        h.run_steps(1);
    }
    assert!(shows(&h, "Enable at least one set."));
    assert!(shows(&h, "The result is for other parameters: press Run."));
    assert_eq!(h.state().engine_runs_started(), 1, "no run without auto-run");
    h.get_by_label("Run").click();
    step_until(&mut h, "the engine error", |app| app.banner().is_some() && !app.is_busy());
    let banner = h.state().banner().expect("banner").text.clone();
    assert!(banner.contains("no fringe set is enabled"), "{banner}");
    assert_eq!(generation(h.state()), g0, "the previous result stays");
}

#[test]
fn textures_are_built_once_per_result_not_per_frame() {
    let mut h = started();
    h.get_by_label("Fused phase").click();
    h.run_steps(3);
    let builds = h.state().texture_builds();
    h.run_steps(20);
    assert_eq!(h.state().texture_builds(), builds, "no rebuild without a change");
    // Hovering and zooming change nothing the image depends on either.
    let rect = h.get_by_label("left · in radians of the 20 px period map").rect();
    wheel_at(&mut h, rect.center(), 120.0);
    h.run_steps(5);
    assert_eq!(h.state().texture_builds(), builds);
    // Switching the colour map is a new image.
    h.get_by_role_and_label(egui::Role::ComboBox, "Colour map").click();
    h.run_steps(2);
    assert_eq!(h.state().state.views.fused.colormap, sheen::app::palette::Colormap::Turbo);
    h.get_by_label("viridis").click();
    h.run_steps(2);
    assert_eq!(h.state().state.views.fused.colormap, sheen::app::palette::Colormap::Viridis);
    assert_eq!(h.state().texture_builds(), builds + 1);
    h.run_steps(5);
    assert_eq!(h.state().texture_builds(), builds + 1);
}

#[test]
fn zoom_and_pan_are_shared_by_the_maps_of_a_camera_and_hover_reads_values() {
    // Short frames, so two clicks (one event per frame) can make a double-click.
    let mut h = Harness::builder()
        .with_size(WINDOW)
        .with_max_steps(64)
        .with_step_dt(0.05)
        .build_eframe(|cc| SheenApp::new(cc, options(synthetic::demo)));
    wait_for_result(&mut h, 0);
    h.get_by_label("Fused phase").click();
    h.run_steps(2);
    let label = "left · in radians of the 20 px period map";
    let rect = h.get_by_label(label).rect();
    wheel_at(&mut h, rect.center(), 200.0);
    h.run_steps(10);
    let zoomed = h.state().view_transform(0);
    assert!(zoomed.zoom > 1.2, "the wheel zooms: {zoomed:?}");
    assert_eq!(h.state().view_transform(1), map_view::ViewTransform::default(), "the right camera is separate");
    // Another view of the same camera shows the same region.
    h.get_by_label("Wrapped phase").click();
    h.run_steps(2);
    assert_eq!(h.state().view_transform(0), zoomed);
    // Hovering a pixel reads its coordinates and value under the map.
    let rect = h.get_by_label("left · set 0 · 500 px map").rect();
    let size = [synthetic::WIDTH, synthetic::HEIGHT];
    let pos = map_view::pixel_center(map_view::image_rect(rect, size, &zoomed), size, [80, 60]);
    h.event(egui::Event::PointerMoved(pos));
    h.run_steps(2);
    let phase = h.state().result().expect("result").reconstruction.cameras[0].sets[0].wrapped_phase_rad[60 * 160 + 80];
    assert!(shows(&h, &format!("u 80, v 60: φ = {phase:.4} rad")), "phase {phase}");
    // Double-click fits the image again, for every map of the camera (after a
    // pause, so the tab click above does not turn it into a triple click).
    h.run_steps(10);
    for _ in 0..2 {
        press_release(&mut h, pos);
    }
    h.run_steps(3);
    assert_eq!(h.state().view_transform(0), map_view::ViewTransform::default());
}

#[test]
fn the_comparison_runs_the_second_method_on_the_worker() {
    let mut h = started();
    h.get_by_label("Compare").click();
    step_until(&mut h, "the comparison", |app| app.compare_output().is_some() && !app.is_busy());
    let app = h.state();
    let output = app.compare_output().expect("comparison");
    assert_eq!(output.panes[0].method, Method::Standard);
    assert_eq!(output.panes[1].method, Method::Hdr);
    assert!(
        Arc::ptr_eq(&output.panes[1].reconstruction, &app.result().expect("result").reconstruction),
        "the side equal to the main method reuses the main result"
    );
    let standard = &output.panes[0].reconstruction.cameras[0].fused;
    assert!(standard.valid_count() > 0);
    // With a calibrated rig the comparison shows heights (the paper's Fig. 5)...
    assert!(shows(&h, "hdr · height · points at"));
    assert!(shows(&h, "standard · height · points at"));
    // ...and the fused phase on request, with each method's completeness.
    h.get_by_label("Phase maps").click();
    h.run_steps(2);
    let hdr = percent_label(app_completeness(&h, 1));
    let standard = percent_label(app_completeness(&h, 0));
    assert!(shows(&h, &format!("hdr · fused phase · complete {hdr}")), "{hdr}");
    assert!(shows(&h, &format!("standard · fused phase · complete {standard}")), "{standard}");
}

/// Steps the app until `text` is on screen, sleeping between frames so a
/// worker thread (which runs below the UI thread's priority) gets its turn.
fn step_until_shown(h: &mut Harness<'_, SheenApp>, text: &str) {
    for _ in 0..2000 {
        h.step();
        if shows(h, text) {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("timed out waiting for {text:?} on screen");
}

/// Share of valid fused-phase pixels of the left camera on one comparison side.
fn app_completeness(h: &Harness<'_, SheenApp>, side: usize) -> f64 {
    let fused = &h.state().compare_output().expect("comparison").panes[side].reconstruction.cameras[0].fused;
    fused.valid_count() as f64 / (synthetic::WIDTH * synthetic::HEIGHT) as f64
}

fn percent_label(share: f64) -> String {
    format!("{:.1} %", 100.0 * share)
}

#[test]
fn keyboard_steps_through_sets_and_shifts() {
    let mut h = started();
    assert_eq!(h.state().state.views.cursor.set, 0);
    h.key_press(egui::Key::CloseBracket);
    h.run_steps(2);
    assert_eq!(h.state().state.views.cursor.set, 1);
    h.key_press(egui::Key::PageUp);
    h.run_steps(2);
    assert_eq!(h.state().state.views.cursor.set, 0);
    h.key_press(egui::Key::ArrowRight);
    h.run_steps(2);
    assert_eq!(h.state().state.views.cursor.shift, 1);
    h.key_press(egui::Key::ArrowLeft);
    h.key_press(egui::Key::ArrowLeft);
    h.run_steps(2);
    assert_eq!(h.state().state.views.cursor.shift, synthetic::SHIFTS - 1, "shifts wrap around");
}

#[test]
fn a_load_can_be_cancelled_while_the_ui_keeps_running() {
    let mut h = harness(synthetic::endless_demo);
    step_until_shown(&mut h, "waiting to be cancelled");
    assert!(h.state().is_busy());
    h.key_press(egui::Key::Escape);
    step_until(&mut h, "the cancelled load", |app| !app.is_busy());
    let app = h.state();
    assert!(app.session().is_none());
    assert!(app.banner().is_none(), "cancelling is not an error");
    assert!(app.log().entries().iter().any(|e| e.text.contains("cancelled")));
}

/// Issue 19: while a job runs, the window redraws only as often as its
/// progress moves, never every frame: with a software renderer a
/// continuously animated progress bar took the cores the engine needed.
#[test]
fn a_running_job_asks_for_no_repaint_every_frame() {
    let mut h = harness(synthetic::endless_demo);
    step_until_shown(&mut h, "waiting to be cancelled");
    h.run_steps(3);
    assert!(h.state().is_busy(), "the load is still running");
    assert!(!h.ctx.requested_repaint_last_pass(), "a running job must not repaint every frame");
    h.key_press(egui::Key::Escape);
    step_until(&mut h, "the cancelled load", |app| !app.is_busy());
}

#[test]
fn every_view_draws_without_panicking() {
    let mut h = started();
    for layout in ["left", "Side by side"] {
        // The camera picker is on the per-camera views (not on Inspect).
        h.get_by_label("Raw").click();
        h.run_steps(2);
        h.get_by_label(layout).click();
        for kind in ViewKind::ALL {
            h.get_by_label(kind.title()).click();
            h.run_steps(2);
            // Every control a view adds must be reachable by name (screen readers, tests).
            h.check_accessibility();
        }
    }
    h.get_by_label("Statistics").click();
    h.run_steps(2);
    h.check_accessibility();
    let app = h.state();
    let m = &app.session().expect("session").measurement;
    assert_eq!(m.cameras.len(), 2);
    let invalid =
        app.result().expect("result").reconstruction.cameras[0].fused.source_set.iter().filter(|&&s| s == SOURCE_NONE);
    assert!(invalid.count() < synthetic::WIDTH * synthetic::HEIGHT / 20);
}

/// A file dropped onto the window (what winit hands egui).
#[derive(Debug)]
struct Dropped(PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &std::path::Path {
        &self.0
    }

    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

#[test]
fn a_manifest_given_at_start_is_loaded_measured_and_remembered() {
    let dir = tempfile::tempdir().expect("tempdir");
    let written = synthetic::measurement();
    let path = synthetic::write_manifest(dir.path(), &written);
    let h = opened(path.clone());
    let app = h.state();
    let session = app.session().expect("session");
    assert_eq!(session.source, DataSource::File(path.clone()));
    assert_eq!(session.measurement.sets.len(), 3);
    assert_eq!(session.measurement.cameras[1].stacks[2].samples, written.cameras[1].stacks[2].samples);
    assert!(session.measurement.calibration.is_some());
    assert_eq!(app.state.recent_files.first(), Some(&path));
    assert!(app.result().expect("result").reconstruction.point_count() > 10_000);
    assert!(!shows(&h, "SIMULATED DATA"), "a measurement must not be marked simulated");
    assert!(shows(&h, &path.display().to_string()));
}

#[test]
fn dropping_a_manifest_opens_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = synthetic::write_manifest(dir.path(), &synthetic::measurement());
    let mut h = started();
    let id0 = h.state().session().expect("session").measurement.id;
    let g0 = generation(h.state());
    h.input_mut().dropped_files.push(Arc::new(Dropped(path.clone())));
    step_until(&mut h, "the dropped manifest", |app| {
        app.session().is_some_and(|s| s.measurement.id != id0) && generation(app) > g0 && !app.is_busy()
    });
    let session = h.state().session().expect("session");
    assert_eq!(session.source, DataSource::File(path));
}

#[test]
fn the_built_in_demo_is_the_simulated_watch_plate() {
    let mut h = harness(sheen::app::loading::simulated_watch_plate);
    wait_for_result(&mut h, 0);
    let app = h.state();
    let session = app.session().expect("session");
    assert!(session.source.is_simulated());
    assert_eq!(session.measurement.cameras.len(), 2);
    assert_eq!(session.measurement.cameras[0].width, 160);
    let rec = &app.result().expect("result").reconstruction;
    assert!(rec.stereo.is_some(), "{:?}", rec.stereo_skipped);
    assert!(rec.point_count() > 0, "{:?}", rec.warnings);
    assert!(shows(&h, "SIMULATED DATA · simulated watch plate, 160x120 px"));
}

#[test]
fn inconsistent_data_is_refused_with_a_message_and_the_app_keeps_running() {
    let mut h = harness(synthetic::truncated_demo);
    step_until(&mut h, "the refusal", |app| app.banner().is_some() && !app.is_busy());
    let app = h.state();
    let banner = app.banner().expect("banner");
    assert!(banner.is_error);
    assert!(
        banner.text.contains("camera 'left' set 0 holds 10 samples") && banner.text.contains("expected 230400"),
        "{}",
        banner.text
    );
    assert!(app.session().is_none());
    // Still alive: the operator can switch to the good demo.
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Open the simulated demo").click();
    h.run_steps(2);
    assert!(h.state().is_busy(), "the demo is loading");
}

#[test]
fn the_theme_follows_the_view_menu() {
    let mut h = started();
    assert!((h.ctx.theme() == egui::Theme::Dark));
    h.get_by_label("View").click();
    h.run_steps(2);
    h.get_by_label("Light").click();
    h.run_steps(3);
    assert_eq!(h.state().state.theme, sheen::app::state::Theme::Light);
    assert!(!(h.ctx.theme() == egui::Theme::Dark), "the light theme must be applied");
}

#[test]
fn main_window_snapshot() {
    let mut h = Harness::builder()
        .with_size(WINDOW)
        .with_max_steps(64)
        .wgpu()
        .build_eframe(|cc| SheenApp::new(cc, options(synthetic::demo)));
    wait_for_result(&mut h, 0);
    h.state_mut().state.layout.show_log = false;
    h.get_by_label("Sources").click();
    h.run_steps(2);
    h.state_mut().push_command(sheen::app::commands::Command::SelectPixel(PixelRef { camera: 0, u: 105, v: 50 }));
    h.run_steps(4);
    h.snapshot("main_window");
}

#[test]
fn the_height_uncertainty_limit_reruns_and_leaves_out_uncertain_points() {
    let mut h = started();
    let g0 = generation(h.state());
    let cloud = |h: &Harness<'_, SheenApp>| {
        h.state().result().expect("result").reconstruction.stereo.as_ref().expect("3D").cloud.clone()
    };
    let before = cloud(&h);
    let mut sigma_um: Vec<f32> = before.sigma_z.iter().map(|s| s * 1e3).collect();
    sigma_um.sort_by(f32::total_cmp);
    // A limit at the median leaves out about half of the points.
    let median_um = sigma_um[sigma_um.len() / 2];
    assert!(median_um > 0.01, "the synthetic demo's points have a measurable uncertainty: {median_um} µm");

    h.get_by_label("Maximum height uncertainty (exact)").set_value_accesskit(f64::from(median_um));
    wait_for_result(&mut h, g0);
    let after = cloud(&h);
    let kept = sigma_um.iter().filter(|&&s| s <= median_um).count();
    assert!(
        after.len() < before.len() && after.len().abs_diff(kept) <= 1,
        "{} -> {} points, {kept} expected",
        before.len(),
        after.len()
    );
    assert!(after.sigma_z.iter().all(|s| s * 1e3 <= median_um * 1.0001), "every kept point is within the limit");

    // Unticking keeps every point again.
    let g1 = generation(h.state());
    h.get_by_label("Maximum height uncertainty").click();
    wait_for_result(&mut h, g1);
    assert_eq!(h.state().result().expect("result").reconstruction.params.max_sigma_z_um, None);
    assert!(cloud(&h).len() >= before.len());
}
