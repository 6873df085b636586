//! The Inspect view in the real app, on a synthetic stereo measurement of a
//! tilted plane with a 20 um step (edge along X, so neither camera sees a
//! wall): regions and a section drawn with the mouse, roles and measurements
//! set in the panel, the measurement table checked against the truth,
//! exports read back, and a session saved and reopened.

use std::path::Path;
use std::time::Duration;

use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use sheen::analysis::inspection::Measure;
use sheen::analysis::region::Region;
use sheen::app::SheenApp;
use sheen::app::commands::Command;
use sheen::app::loading::DemoData;
use sheen::app::views::inspect::map::MapFrame;
use sheen::app::views::inspect::{InspectDoc, MapShows, RegionRole};
use sheen::app::widgets::map_view::ViewTransform;
use sheen::engine::camera_model::{AffineCamera, StereoCalibration};
use sheen::engine::control::RunControl;
use sheen::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Measurement, next_measurement_id};

use super::{WINDOW, options, shows, step_until, wait_for_result};

// The synthetic rig of the other GUI tests, with a projector of its own.
use super::synthetic::{HEIGHT, PITCH_MM, THETA_DEG, WIDTH, camera};
const PROJECTOR_PITCH_MM: f64 = 0.004;
/// The plane z = a x + b y (mm), and the step added where y > 0.
const SLOPE: [f64; 2] = [0.02, 0.01];
pub const STEP_UM: f64 = 20.0;

/// The true surface height (mm) at (x, y).
pub fn surface_z(x: f64, y: f64) -> f64 {
    SLOPE[0] * x + SLOPE[1] * y + if y > 0.0 { STEP_UM * 1e-3 } else { 0.0 }
}

/// The surface point seen at pixel (u, v): the camera's second row fixes y,
/// then the first row is linear in x on that row's plane.
fn surface_point(cam: &AffineCamera, u: f64, v: f64) -> [f64; 3] {
    let p = &cam.p;
    let y = (v - p[1][3]) / p[1][1];
    let offset = surface_z(0.0, y);
    let x = (u - p[0][3] - p[0][2] * offset) / (p[0][0] + p[0][2] * SLOPE[0]);
    [x, y, SLOPE[0] * x + offset]
}

fn render(cam: &AffineCamera, sets: &[FringeSetInfo]) -> Vec<FringeStack> {
    sets.iter()
        .map(|set| {
            let planes = set
                .phase_shifts_rad
                .iter()
                .map(|delta| {
                    (0..WIDTH * HEIGHT)
                        .map(|i| {
                            let x = surface_point(cam, (i % WIDTH) as f64, (i / WIDTH) as f64);
                            let phase = std::f64::consts::TAU * (x[0] + 1.0) / PROJECTOR_PITCH_MM / set.period_px;
                            (128.0 + 90.0 * (phase + delta).cos()).round().clamp(0.0, 255.0) as u8
                        })
                        .collect()
                })
                .collect();
            FringeStack::from_planes_u8(WIDTH, HEIGHT, planes)
        })
        .collect()
}

pub fn stepped_demo(_width: usize, _height: usize, control: &RunControl) -> anyhow::Result<DemoData> {
    control.check()?;
    let sets: Vec<FringeSetInfo> = [500.0, 100.0, 20.0].iter().map(|&p| FringeSetInfo::uniform(p, 12)).collect();
    let (left, right) = (camera(1.0), camera(-1.0));
    let cameras = vec![
        CameraFringes { name: "left".into(), width: WIDTH, height: HEIGHT, stacks: render(&left, &sets) },
        CameraFringes { name: "right".into(), width: WIDTH, height: HEIGHT, stacks: render(&right, &sets) },
    ];
    let measurement = Measurement {
        bit_depth: 8,
        saturation_level: 255,
        sets,
        cameras,
        calibration: Some(StereoCalibration {
            unit: sheen::engine::length_unit::LengthUnit::Mm,
            left,
            right,
            rms_reprojection_px: None,
            scale_uncertainty: None,
        }),
        label: "synthetic 20 um step".into(),
        projector: None,
        id: next_measurement_id(),
    };
    Ok(DemoData { measurement, description: "synthetic tilted plane with a 20 um step, 160x120 px".into() })
}

/// The app on the stepped plane, in the Inspect view with its height map ready.
fn inspecting() -> Harness<'static, SheenApp> {
    let mut h = Harness::builder()
        .with_size(WINDOW)
        .with_max_steps(64)
        .with_step_dt(0.05)
        .build_eframe(|cc| SheenApp::new(cc, options(stepped_demo)));
    wait_for_result(&mut h, 0);
    h.state_mut().state.layout.show_side_panel = false;
    h.state_mut().state.layout.show_log = false;
    // Let the layout settle before clicking a tab by position.
    h.run_steps(2);
    h.get_by_label("Inspect").click();
    settle(&mut h);
    assert_eq!(h.state().state.views.active, sheen::app::views::ViewKind::Inspect);
    h
}

/// Steps until the Inspect view's analysis is up to date and nothing runs.
fn settle(h: &mut Harness<'_, SheenApp>) {
    // Events queued by the caller reach the UI in the next frames; the
    // recomputation they cause is requested only then.
    h.run_steps(2);
    let rt = h.state().inspect();
    let what = format!(
        "the inspection (height map error: {:?}; analysis: {}; current: {}; busy: {})",
        rt.height_map_error(),
        rt.analysis().is_some(),
        rt.is_current(),
        rt.is_busy()
    );
    step_until(h, &what, |app| {
        app.inspect().analysis().is_some() && app.inspect().is_current() && !app.inspect().is_busy() && !app.is_busy()
    });
}

/// Screen position of map point (x, y) mm on the Inspect map as drawn.
fn map_pos(h: &Harness<'_, SheenApp>, p: [f64; 2]) -> egui::Pos2 {
    let rect = h.get_by_label("Height map").rect();
    let map = &h.state().inspect().analysis().expect("analysis").map;
    MapFrame::new(rect, map, &ViewTransform::default()).to_screen(p)
}

fn press(h: &mut Harness<'_, SheenApp>, pos: egui::Pos2, pressed: bool) {
    h.event(egui::Event::PointerButton {
        pos,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers: egui::Modifiers::NONE,
    });
}

/// A mouse drag from `a` to `b` in small moves, as a hand would.
fn drag(h: &mut Harness<'_, SheenApp>, a: egui::Pos2, b: egui::Pos2) {
    h.event(egui::Event::PointerMoved(a));
    h.run_steps(1);
    press(h, a, true);
    h.run_steps(1);
    for k in 1..=8 {
        h.event(egui::Event::PointerMoved(a + (b - a) * (k as f32 / 8.0)));
        h.run_steps(1);
    }
    press(h, b, false);
    h.run_steps(2);
}

fn click(h: &mut Harness<'_, SheenApp>, pos: egui::Pos2) {
    h.event(egui::Event::PointerMoved(pos));
    h.run_steps(1);
    press(h, pos, true);
    press(h, pos, false);
    h.run_steps(2);
}

/// Clicks a panel control by its label, scrolling it into view first.
fn press_named(h: &mut Harness<'_, SheenApp>, label: &str) {
    h.get_by_label(label).scroll_to_me();
    h.run_steps(5);
    h.get_by_label(label).click_accesskit();
    h.run_steps(2);
}

fn row_value(h: &Harness<'_, SheenApp>, name: &str) -> f64 {
    let report = h.state().inspect().report().expect("report");
    let row = report.table.rows.iter().find(|r| r.name == name);
    row.and_then(|r| r.value).unwrap_or_else(|| panic!("no value for '{name}': {:?}", report.table.rows))
}

fn rect_of(region: &Region) -> ([f64; 2], [f64; 2]) {
    match region {
        Region::Rectangle { x_mm, y_mm } => (*x_mm, *y_mm),
        other => panic!("expected a rectangle, got {other:?}"),
    }
}

#[test]
fn regions_and_a_section_drawn_on_the_map_measure_the_step() {
    let mut h = inspecting();
    let map = h.state().inspect().height_map().expect("height map").clone();
    assert!((map.pitch_mm - PITCH_MM * THETA_DEG.to_radians().cos()).abs() < 2e-3, "pitch {}", map.pitch_mm);

    // Two rectangles: the base below the step, the land above it.
    h.get_by_label("Rectangle").click();
    h.run_steps(2);
    let (a, b) = (map_pos(&h, [-0.4, -0.45]), map_pos(&h, [0.4, -0.1]));
    drag(&mut h, a, b);
    let (a, b) = (map_pos(&h, [-0.4, 0.1]), map_pos(&h, [0.4, 0.45]));
    drag(&mut h, a, b);
    let doc = &h.state().inspect().doc;
    assert_eq!(doc.regions.len(), 2, "{:?}", doc.regions);
    let (x, y) = rect_of(&doc.regions[0].region.region);
    assert!((x[0] + 0.4).abs() < 0.02 && (x[1] - 0.4).abs() < 0.02 && (y[0] + 0.45).abs() < 0.02, "{x:?} {y:?}");
    assert_eq!(doc.regions[1].region.name, "R2");

    // Roles through the panel's combo boxes.
    for (name, role) in [("R1", "reference"), ("R2", "measured")] {
        press_named(&mut h, &format!("Role of {name}"));
        h.get_by_label(role).click();
        h.run_steps(2);
    }
    let roles: Vec<RegionRole> = h.state().inspect().doc.regions.iter().map(|r| r.role).collect();
    assert_eq!(roles, [RegionRole::Reference, RegionRole::Measured]);
    press_named(&mut h, "Step height");
    h.get_all_by_label("Flatness").next().expect("a flatness button").scroll_to_me();
    h.run_steps(2);
    h.get_all_by_label("Flatness").next().expect("a flatness button").click();
    h.run_steps(1);

    // A vertical section through the middle, across the step.
    h.get_by_label("Vertical section").click();
    h.run_steps(2);
    let p = map_pos(&h, [0.0, 0.0]);
    click(&mut h, p);
    settle(&mut h);

    let app = h.state();
    assert_eq!(app.inspect().doc.profiles.len(), 1);
    let step = row_value(&h, "step R2");
    assert!((step - STEP_UM).abs() < 0.5, "step height {step} um, truth {STEP_UM} um");
    let pv = row_value(&h, "flatness PV R1");
    let rms = row_value(&h, "flatness RMS R1");
    assert!(pv < 2.0 && rms < 0.5 && rms <= pv, "PV {pv} um, RMS {rms} um on a plane");
    let u_step = {
        let report = h.state().inspect().report().expect("report");
        let row = report.table.rows.iter().find(|r| r.name == "step R2").expect("step row");
        row.uncertainty.as_ref().expect("the step states its uncertainty").expanded
    };
    assert!(u_step > 0.0 && u_step < 0.5, "U {u_step} um");
    assert!(
        shows(&h, "step R2") && shows(&h, &format!("{step:.3} ± {u_step:.3} µm")),
        "the table shows the step with its U"
    );

    // Levelled to the base: the section reads 0 below the step and 20 um above.
    let a = app.inspect().analysis().expect("analysis");
    assert!(a.levelling.is_some(), "{:?}", a.warnings);
    let profile = &app.inspect().profiles()[0];
    let z_at = |y: f64| {
        let s =
            profile.samples.iter().min_by(|p, q| (p.y_mm - y).abs().total_cmp(&(q.y_mm - y).abs())).expect("sample");
        s.z_um
    };
    assert!(z_at(-0.3).abs() < 0.5, "base {} um", z_at(-0.3));
    assert!((z_at(0.3) - STEP_UM).abs() < 0.5, "land {} um", z_at(0.3));
    assert!(shows(&h, "Profile plot"));

    // A tolerance on the step makes the verdict; a tight wrong one fails.
    let tol = &mut h.state_mut().inspect_mut().doc.measurements[0];
    assert!(matches!(tol.measure, Measure::StepHeight { .. }));
    sheen::app::views::inspect::state::set_limits(tol, Some((19.5, 20.5)));
    settle(&mut h);
    assert!(shows(&h, "PASS"));
    let tol = &mut h.state_mut().inspect_mut().doc.measurements[0];
    sheen::app::views::inspect::state::set_limits(tol, Some((25.0, 26.0)));
    settle(&mut h);
    assert!(shows(&h, "FAIL") && shows(&h, "Overall: FAIL"));

    // An upper limit within U above the value: ISO 14253-1 (the default)
    // proves neither; simple acceptance, chosen in the panel, passes it.
    let tol = &mut h.state_mut().inspect_mut().doc.measurements[0];
    sheen::app::views::inspect::state::set_limits(tol, Some((step - 1.0, step + u_step / 2.0)));
    settle(&mut h);
    assert!(shows(&h, "INCONCLUSIVE") && shows(&h, "Overall: INCONCLUSIVE"));
    press_named(&mut h, "Decision rule");
    press_named(&mut h, "Simple acceptance");
    settle(&mut h);
    assert_eq!(h.state().inspect().doc.decision_rule, sheen::analysis::measurement_table::DecisionRule::Simple);
    assert!(shows(&h, "Overall: PASS"), "the rule's change measured again");
}

fn export_to(h: &mut Harness<'_, SheenApp>, dir: &Path, button: &str) {
    let rt = h.state_mut().inspect_mut();
    rt.use_dialogs = false;
    rt.export_folder = dir.display().to_string();
    h.run_steps(1);
    press_named(h, button);
    assert!(
        h.state().inspect().file_job_running() || h.state().inspect().status.is_some(),
        "{button} started; banner {:?}",
        h.state().banner().map(|b| b.text.clone())
    );
    step_until(h, "the export", |app| !app.inspect().file_job_running());
    let status = h.state().inspect().status.clone().expect("a status line");
    assert!(!status.is_error, "{}", status.text);
}

#[test]
fn exports_write_files_that_read_back() {
    let mut h = inspecting();
    let dir = tempfile::tempdir().expect("tempdir");
    {
        let doc = &mut h.state_mut().inspect_mut().doc;
        let r = doc.add_region(Region::Rectangle { x_mm: [-0.4, 0.4], y_mm: [-0.45, -0.1] });
        doc.regions[r].role = RegionRole::Reference;
        let m = doc.add_region(Region::Circle { centre_mm: [0.0, 0.3], radius_mm: 0.12 });
        doc.regions[m].role = RegionRole::Measured;
        doc.add_step_height().expect("step");
        doc.add_profile(sheen::analysis::profile::ProfileLine::Vertical { through_mm: [0.1, 0.0] });
        // Two lands on the base, one plane: coplanar within the noise.
        for x in [-0.6, 0.5] {
            let l = doc.add_region(Region::Rectangle { x_mm: [x, x + 0.15], y_mm: [-0.5, -0.2] });
            doc.regions[l].role = RegionRole::Land;
        }
    }
    settle(&mut h);
    press_named(&mut h, "Coplanarity");
    settle(&mut h);
    let coplanarity = row_value(&h, "coplanarity");
    assert!(coplanarity < 1.0, "lands on one plane: coplanarity {coplanarity} um");

    export_to(&mut h, dir.path(), "Measurements CSV");
    let csv = std::fs::read_to_string(dir.path().join("measurements.csv")).expect("csv");
    let line = csv.lines().find(|l| l.starts_with("step R2,step_height,")).expect("the step row");
    let value: f64 = line.split(',').nth(2).expect("value").parse().expect("number");
    assert!((value - STEP_UM).abs() < 0.5, "{line}");

    export_to(&mut h, dir.path(), "Height map X3P");
    let file = std::fs::File::open(dir.path().join("height_map.x3p")).expect("x3p");
    let back = sheen::io::x3p::read_x3p(file).expect("read x3p");
    let shown = std::sync::Arc::clone(&h.state().inspect().analysis().expect("analysis").map);
    assert_eq!((back.map.width, back.map.height), (shown.width, shown.height));
    assert!((back.map.pitch_mm - shown.pitch_mm).abs() < 1e-12);
    let same = back.map.z.iter().zip(&shown.z).all(|(a, b)| (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-9);
    assert!(same, "the X3P holds the levelled map as shown");

    export_to(&mut h, dir.path(), "Profiles CSV");
    let text = std::fs::read_to_string(dir.path().join("profiles.csv")).expect("profile csv");
    assert!(text.contains("# name: A-A") && text.contains("distance_mm,x_mm,y_mm,z_um,n"), "{text}");

    export_to(&mut h, dir.path(), "Height map TIFF");
    let tif = sheen::io::maps::read_f32_tiff(&dir.path().join("height_map.tif")).expect("tiff");
    assert_eq!((tif.width, tif.height), (shown.width, shown.height));

    for (button, file) in [("Height map PNG", "height_map.png"), ("Profile plot PNG", "profiles.png")] {
        export_to(&mut h, dir.path(), button);
        let img = image::open(dir.path().join(file)).expect("png").to_rgba8();
        assert!(img.width() > 100 && img.height() > 100, "{file}");
    }
    export_to(&mut h, dir.path(), "Point cloud PLY");
    let ply = sheen::io::ply::read_ply(&dir.path().join("cloud.ply")).expect("ply");
    let points = h.state().result().expect("result").reconstruction.point_count();
    assert_eq!(ply.xyz.len(), points);

    // A folder that does not exist: an error on screen, no crash, no file.
    let rt = h.state_mut().inspect_mut();
    rt.export_folder = "/nonexistent/sheen/exports".into();
    press_named(&mut h, "Measurements CSV");
    step_until(&mut h, "the failed export", |app| !app.inspect().file_job_running() && app.banner().is_some());
    let banner = h.state().banner().expect("banner").text.clone();
    assert!(banner.contains("/nonexistent/sheen/exports/measurements.csv"), "{banner}");
    assert!(h.state().inspect().status.as_ref().is_some_and(|s| s.is_error));
}

#[test]
fn a_saved_session_reopens_regions_profiles_and_measurements() {
    let mut h = inspecting();
    let dir = tempfile::tempdir().expect("tempdir");
    {
        let rt = h.state_mut().inspect_mut();
        let doc = &mut rt.doc;
        let r = doc.add_region(Region::Rectangle { x_mm: [-0.4, 0.4], y_mm: [-0.45, -0.1] });
        doc.regions[r].role = RegionRole::Reference;
        let m = doc.add_region(Region::Polygon { vertices_mm: vec![[-0.3, 0.1], [0.3, 0.1], [0.0, 0.45]] });
        doc.regions[m].role = RegionRole::Measured;
        doc.rename_region(m, "land").expect("rename");
        doc.add_step_height().expect("step");
        let p = doc.add_profile(sheen::analysis::profile::ProfileLine::Vertical { through_mm: [0.0, 0.0] });
        doc.profiles[p].spec.width_mm = 0.05;
        rt.cursors = [Some(0.1), Some(0.8)];
    }
    h.state_mut().state.views.inspect.colormap = sheen::app::palette::Colormap::Gray;
    settle(&mut h);
    let before = h.state().inspect().doc.clone();
    let step_before = row_value(&h, "step land");
    let path = dir.path().join("part.sheen-session.json");
    h.state_mut().push_command(Command::SaveSession(Some(path.clone())));
    step_until(&mut h, "the session file", |app| !app.inspect().file_job_running() && path.exists());

    // Forget everything, then reopen.
    h.state_mut().inspect_mut().load_doc(InspectDoc::default(), [None, None]);
    h.state_mut().state.views.inspect.colormap = sheen::app::palette::Colormap::Viridis;
    settle(&mut h);
    assert!(h.state().inspect().doc.regions.is_empty());
    let g0 = h.state().result().map_or(0, |r| r.generation);
    h.state_mut().push_command(Command::OpenSession(Some(path.clone())));
    step_until(&mut h, "the reopened session", |app| {
        app.inspect().doc.regions.len() == 2 && app.result().is_some_and(|r| r.generation > g0) && !app.is_busy()
    });
    settle(&mut h);
    std::thread::sleep(Duration::from_millis(10));
    let rt = h.state().inspect();
    assert_eq!(rt.doc.regions, before.regions);
    assert_eq!(rt.doc.profiles, before.profiles);
    assert_eq!(rt.doc.measurements, before.measurements);
    assert_eq!(rt.cursors, [Some(0.1), Some(0.8)]);
    assert_eq!(h.state().state.views.inspect.colormap, sheen::app::palette::Colormap::Gray, "display settings too");
    let step_after = row_value(&h, "step land");
    assert!((step_after - step_before).abs() < 1e-9, "{step_before} -> {step_after}");
    assert!(shows(&h, "step land"));
    assert_eq!(h.state().state.recent_files.first(), Some(&path), "the session is a recent file");

    // Opening it as a file (recent files, drag and drop) reads it as a session, not a manifest.
    h.state_mut().inspect_mut().load_doc(InspectDoc::default(), [None, None]);
    h.state_mut().push_command(Command::Open(path.clone()));
    step_until(&mut h, "the session opened as a file", |app| app.inspect().doc.regions.len() == 2 && !app.is_busy());
    assert!(h.state().banner().is_none(), "{:?}", h.state().banner().map(|b| b.text.clone()));

    // A damaged session is refused with its name and the inspection stays.
    std::fs::write(dir.path().join("bad.json"), "{\"sheen_session\": 9}").expect("write");
    h.state_mut().push_command(Command::OpenSession(Some(dir.path().join("bad.json"))));
    step_until(&mut h, "the refusal", |app| app.banner().is_some() && !app.inspect().file_job_running());
    let banner = h.state().banner().expect("banner").text.clone();
    assert!(banner.contains("bad.json") && banner.contains("version 9"), "{banner}");
    assert_eq!(h.state().inspect().doc.regions.len(), 2);
}

#[test]
fn the_averaging_width_and_step_are_edited_in_the_panel() {
    let mut h = inspecting();
    h.state_mut()
        .inspect_mut()
        .doc
        .add_profile(sheen::analysis::profile::ProfileLine::Vertical { through_mm: [0.1, 0.0] });
    settle(&mut h);
    h.get_by_label("Width of A-A").scroll_to_me();
    h.run_steps(3);
    h.get_by_label("Width of A-A").set_value_accesskit(0.05);
    h.run_steps(2);
    assert_eq!(h.state().inspect().doc.profiles[0].spec.width_mm, 0.05, "the panel edits the document");
    settle(&mut h);
    let p = &h.state().inspect().profiles()[0];
    assert!((p.width_mm - 0.05).abs() < 1e-9, "width {}", p.width_mm);
    assert!(p.lines_across > 1, "{} lines averaged", p.lines_across);
    assert!(shows(&h, "averaging width 0.0500 mm"));
}

#[test]
fn polygon_and_circle_tools_and_plot_cursors_work_with_the_mouse() {
    let mut h = inspecting();
    // A polygon below the step: three clicks, then a click on the first vertex closes it.
    h.get_by_label("Polygon").click();
    h.run_steps(2);
    let vertices = [[-0.4, -0.45], [0.4, -0.45], [0.0, -0.1]];
    for v in vertices.iter().chain(std::iter::once(&vertices[0])) {
        let p = map_pos(&h, *v);
        click(&mut h, p);
        // Apart in time, so no two clicks make a double-click.
        h.run_steps(10);
    }
    let doc = &h.state().inspect().doc;
    assert_eq!(doc.regions.len(), 1, "{:?}", doc.regions);
    let Region::Polygon { vertices_mm } = &doc.regions[0].region.region else {
        panic!("expected a polygon, got {:?}", doc.regions[0].region.region)
    };
    assert_eq!(vertices_mm.len(), 3);
    for (got, want) in vertices_mm.iter().zip(&vertices) {
        assert!((got[0] - want[0]).abs() < 0.02 && (got[1] - want[1]).abs() < 0.02, "{got:?} vs {want:?}");
    }
    // A circle above it: drag from the centre to the rim.
    h.get_by_label("Circle").click();
    h.run_steps(2);
    let (c, rim) = (map_pos(&h, [0.0, 0.3]), map_pos(&h, [0.12, 0.3]));
    drag(&mut h, c, rim);
    let doc = &h.state().inspect().doc;
    let Region::Circle { centre_mm, radius_mm } = &doc.regions[1].region.region else {
        panic!("expected a circle, got {:?}", doc.regions[1].region.region)
    };
    assert!(centre_mm[0].abs() < 0.02 && (centre_mm[1] - 0.3).abs() < 0.02 && (radius_mm - 0.12).abs() < 0.02);
    {
        let doc = &mut h.state_mut().inspect_mut().doc;
        doc.regions[0].role = RegionRole::Reference;
    }
    // A vertical section across the step.
    h.get_by_label("Vertical section").click();
    h.run_steps(2);
    let p = map_pos(&h, [0.05, 0.0]);
    click(&mut h, p);
    settle(&mut h);

    // Two clicks on the plot place cursors A and B, one on each side of the step.
    let rect = h.get_by_label("Profile plot").rect();
    for fx in [0.15, 0.85] {
        h.run_steps(10);
        click(&mut h, egui::pos2(rect.left() + fx * rect.width(), rect.center().y));
    }
    let rt = h.state().inspect();
    let [Some(a), Some(b)] = rt.cursors else { panic!("cursors {:?}", rt.cursors) };
    assert!(b > a);
    let profile = &rt.profiles()[0];
    let reading = sheen::app::views::inspect::state::cursor_readout(profile, a, b);
    assert!((reading.dz_um - STEP_UM).abs() < 1.0, "dz {} um across the step", reading.dz_um);
    assert!(shows(&h, &format!("dz {:.3} µm", reading.dz_um)), "the read-out is on screen");
}

/// The inspection the record and report tests measure: a reference base, a
/// measured land, their step with a tolerance, and one section.
fn step_inspection(h: &mut Harness<'_, SheenApp>) {
    let doc = &mut h.state_mut().inspect_mut().doc;
    let r = doc.add_region(Region::Rectangle { x_mm: [-0.4, 0.4], y_mm: [-0.45, -0.1] });
    doc.regions[r].role = RegionRole::Reference;
    let m = doc.add_region(Region::Circle { centre_mm: [0.0, 0.3], radius_mm: 0.12 });
    doc.regions[m].role = RegionRole::Measured;
    doc.add_step_height().expect("step");
    sheen::app::views::inspect::state::set_limits(&mut doc.measurements[0], Some((19.5, 20.5)));
    doc.add_profile(sheen::analysis::profile::ProfileLine::Vertical { through_mm: [0.1, 0.0] });
    settle(h);
}

/// Issue 21 in the app: Record keeps the part on screen (its measurements,
/// verdict, inspection and height map) in the database the form names, and
/// the History view lists it, reloading when another is recorded.
#[test]
fn the_record_button_keeps_the_part_and_history_lists_it() {
    let mut h = inspecting();
    step_inspection(&mut h);
    let dir = tempfile::tempdir().expect("tempdir");
    let db = dir.path().join("lab").join("records.sqlite");
    h.state_mut().state.views.inspect.record.db = db.display().to_string();
    h.state_mut().state.views.inspect.record.station = "line 3".into();
    h.state_mut().inspect_mut().part_id = "P-0007".into();
    h.state_mut().inspect_mut().recipe = "plate B".into();
    h.run_steps(1);
    // Before the first record the history is empty, which is not an error.
    h.get_by_label("History").click();
    step_until(&mut h, "the empty history", |app| app.history().no_database().is_some());
    h.run_steps(2);
    assert!(h.state().history().error().is_none());
    assert!(shows(&h, "No parts recorded yet"));
    assert!(!db.exists(), "looking at the history creates no database");
    h.get_by_label("Inspect").click();
    settle(&mut h);
    press_named(&mut h, "Record");
    step_until(&mut h, "the record", |app| !app.inspect().record_job_running());
    let status = h.state().inspect().status.clone().expect("a status line");
    assert!(!status.is_error && status.text.contains("P-0007"), "{}", status.text);

    let location = sheen::records::DbLocation::Sqlite(db.clone());
    let read = || {
        sheen::records::Store::open(&location)
            .expect("open")
            .parts(&sheen::records::HistoryFilter::default())
            .expect("read")
    };
    let parts = read();
    assert_eq!(parts.len(), 1);
    let r = &parts[0].record;
    assert_eq!((r.part_id.as_str(), r.recipe.as_str(), r.station.as_deref()), ("P-0007", "plate B", Some("line 3")));
    assert_eq!(r.verdict, sheen::records::PartVerdict::Pass, "{:?}", r.measurements);
    let step = &r.measurements[0];
    let shown = row_value(&h, &step.name);
    assert_eq!(step.value, Some(shown), "the value on screen is the value kept");
    assert_eq!((step.lower_limit, step.upper_limit), (Some(19.5), Some(20.5)));
    let spec = sheen::analysis::inspection::InspectionSpec::from_json(r.inspection.as_deref().expect("inspection"))
        .expect("the recorded inspection reads back");
    assert_eq!(spec.regions.len(), 2);
    let map = db.parent().expect("folder").join(r.height_map_path.as_deref().expect("height map"));
    assert_eq!(sheen::records::hash::sha256_file(&map).ok(), r.height_map_hash, "X3P beside the database");

    h.get_by_label("History").click();
    step_until(&mut h, "the history", |app| app.history().parts().is_some_and(|p| p.len() == 1));
    h.run_steps(3);
    assert!(shows(&h, "P-0007") && shows(&h, "Trend chart") && shows(&h, "Histogram"));
    assert!(h.state().history().error().is_none());
    // The view's filters: another station, or a range after today, select
    // nothing; the part's own station and today select it again.
    let count = |h: &Harness<'_, SheenApp>| h.state().history().parts().map(<[_]>::len);
    h.state_mut().state.views.history.station = "line 9".into();
    step_until(&mut h, "the station filter", |app| app.history().parts().is_some_and(<[_]>::is_empty));
    h.run_steps(2);
    assert!(shows(&h, "No records in"), "an empty selection says so");
    h.state_mut().state.views.history.station = "line 3".into();
    step_until(&mut h, "the part's station", |app| app.history().parts().is_some_and(|p| p.len() == 1));
    let tomorrow = (chrono::Local::now() + chrono::Duration::days(1)).format("%Y-%m-%d").to_string();
    h.state_mut().state.views.history.since = tomorrow;
    step_until(&mut h, "a range after today", |app| app.history().parts().is_some_and(<[_]>::is_empty));
    h.state_mut().state.views.history.since = chrono::Local::now().format("%Y-%m-%d").to_string();
    step_until(&mut h, "today", |app| app.history().parts().is_some_and(|p| p.len() == 1));
    assert_eq!(count(&h), Some(1));
    h.state_mut().state.views.history.since.clear();

    // A second record of the same part: appended, and the view reloads.
    h.get_by_label("Inspect").click();
    settle(&mut h);
    press_named(&mut h, "Record");
    step_until(&mut h, "the second record", |app| !app.inspect().record_job_running());
    h.get_by_label("History").click();
    step_until(&mut h, "the history to reload", |app| app.history().parts().is_some_and(|p| p.len() == 2));
    assert_eq!(read().len(), 2, "append-only: a part measured again is a new record");
}

/// Export > Report PDF: a PDF of the part on screen with the verdict and the
/// table (read back with poppler where it is installed).
#[test]
fn the_report_export_writes_a_pdf_with_the_verdict_and_the_table() {
    let mut h = inspecting();
    step_inspection(&mut h);
    h.state_mut().inspect_mut().part_id = "P-0008".into();
    let dir = tempfile::tempdir().expect("tempdir");
    export_to(&mut h, dir.path(), "Report PDF");
    let pdf = dir.path().join("report.pdf");
    let bytes = std::fs::read(&pdf).expect("report.pdf");
    assert!(bytes.starts_with(b"%PDF-") && bytes.len() > 10_000, "{} bytes", bytes.len());
    export_to(&mut h, dir.path(), "Report HTML");
    let html = std::fs::read_to_string(dir.path().join("report.html")).expect("report.html");
    assert!(html.contains("P-0008") && html.contains("PASS") && html.contains("data:image/png;base64,"));
    let Ok(o) = std::process::Command::new("pdftotext").args([pdf.to_str().expect("utf-8"), "-"]).output() else {
        eprintln!("pdftotext not installed: the PDF's text is not read back");
        return;
    };
    let text = String::from_utf8_lossy(&o.stdout);
    let name = h.state().inspect().report().expect("report").table.rows[0].name.clone();
    assert!(text.contains("PASS") && text.contains("P-0008") && text.contains(&name), "{text}");
}

/// Export > AQDEF and QIF: the part on screen as the plant's quality system
/// takes it, with the part ID from Record and the table's values.
#[test]
fn the_exchange_exports_write_the_part_for_the_quality_system() {
    let mut h = inspecting();
    step_inspection(&mut h);
    h.state_mut().inspect_mut().part_id = "P-0009".into();
    let dir = tempfile::tempdir().expect("tempdir");
    export_to(&mut h, dir.path(), "AQDEF (.dfq)");
    export_to(&mut h, dir.path(), "QIF results");
    let table = h.state().inspect().report().expect("report").table.clone();
    let dfq = std::fs::read(dir.path().join("part.dfq")).expect("part.dfq");
    let dfq: String = dfq.iter().map(|&b| b as char).collect();
    assert!(dfq.starts_with(&format!("K0100 {}\r\n", table.rows.len())), "{dfq}");
    assert!(dfq.contains("K0014/1 P-0009\r\n"), "{dfq}");
    let first = table.rows[0].value.expect("a value");
    let written: f64 =
        dfq.lines().find_map(|l| l.strip_prefix("K0001/1 ")).expect("a value line").trim().parse().expect("a number");
    assert!((written - first).abs() < 1e-6, "{written} vs {first}");
    let qif = std::fs::read_to_string(dir.path().join("part.qif")).expect("part.qif");
    assert!(qif.contains("<SerialNumber>P-0009</SerialNumber>") && qif.contains("versionQIF=\"3.0.0\""));
    let schema = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/qif-3.0/QIFApplications/QIFDocument.xsd");
    if let Ok(o) = std::process::Command::new("xmllint")
        .args(["--noout", "--nonet", "--schema"])
        .arg(schema)
        .arg(dir.path().join("part.qif"))
        .output()
    {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
}

/// History > Open part: the recorded part comes back with its measurement,
/// parameters and inspection. The record is made by `sheen analyze
/// --record` on a simulated flat written to disk, as a line would.
#[test]
fn opening_a_recorded_part_loads_its_measurement_and_inspection() {
    let dir = tempfile::tempdir().expect("tempdir");
    let sheen_bin = env!("CARGO_BIN_EXE_sheen");
    let part = dir.path().join("part-42");
    let run = |args: &[&str]| {
        let o = std::process::Command::new(sheen_bin).args(args).output().expect("run sheen");
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    };
    let s = |p: &Path| p.display().to_string();
    run(&["simulate", "--scene", "flat", "--out", &s(&part), "--width", "64", "--height", "48", "-q"]);
    let manifest = part.join("fringe-set.json");
    let db = dir.path().join("records.sqlite");
    run(&[
        "analyze",
        &s(&manifest),
        "--out",
        &s(&dir.path().join("qc")),
        "-q",
        "--record",
        "--db",
        &s(&db),
        "--recipe",
        "flat plate",
        "--region",
        "base=rect:-1,-1,1,1",
        "--flatness",
        "base<=15",
        "--min-modulation",
        "6",
    ]);

    let mut h = inspecting();
    h.state_mut().state.views.inspect.record.db = db.display().to_string();
    // "Always record" on: the simulated demo on screen is not a part and is
    // not recorded; the real part opened below is, once.
    h.state_mut().state.views.inspect.record.always = true;
    h.get_by_label("History").click();
    step_until(&mut h, "the history", |app| app.history().parts().is_some_and(|p| p.len() == 1));
    h.run_steps(3);
    // Select the part's row (its time), then Open part.
    let row_id = h.state().history().parts().expect("parts")[0].row_id;
    h.query_all_by_label_contains(&format!("{}", chrono::Local::now().format("%Y-%m-%d")))
        .next()
        .expect("the row")
        .click_accesskit();
    h.run_steps(2);
    assert_eq!(h.state().history().selected, Some(row_id));
    h.get_by_label("Open part").click();
    h.run_steps(2);
    step_until(&mut h, "the recorded part", |app| {
        app.session().is_some_and(|s| {
            s.source == sheen::app::run_data::DataSource::File(manifest.clone())
                || s.source.describe().contains("part-42")
        }) && app.result().is_some()
            && !app.is_busy()
    });
    let app = h.state();
    assert_eq!(app.state.params.min_modulation_dn, 6.0, "the recorded engine parameters");
    assert_eq!(app.state.views.active, sheen::app::views::ViewKind::Inspect);
    let doc = &app.inspect().doc;
    assert_eq!(doc.regions.len(), 1, "the recorded inspection");
    assert_eq!(doc.regions[0].region.name, "base");
    assert_eq!((app.inspect().part_id.as_str(), app.inspect().recipe.as_str()), ("part-42", "flat plate"));

    let location = sheen::records::DbLocation::Sqlite(db.clone());
    let count = || {
        sheen::records::Store::open(&location)
            .expect("open")
            .parts(&sheen::records::HistoryFilter::default())
            .expect("read")
            .len()
    };
    // Reviewing a recorded part measures nothing new: "Always record" leaves it alone.
    h.run_steps(20);
    step_until(&mut h, "nothing to record", |app| !app.inspect().record_job_running() && !app.is_busy());
    assert_eq!(count(), 1, "opening a part from History must not record it again");
    assert!(h.state().inspect().reviewing.is_some());

    // A click on the part's point in the trend chart selects and opens it too.
    h.get_by_label("History").click();
    h.run_steps(3);
    h.state_mut().history_mut().selected = None;
    h.run_steps(2);
    let before = super::generation(h.state());
    let points = h.state().history().drawn_points().to_vec();
    assert_eq!(points.iter().map(|(id, _)| *id).collect::<Vec<_>>(), vec![row_id], "one point per recorded part");
    super::click_at(&mut h, points[0].1);
    assert_eq!(h.state().history().selected, Some(row_id), "the clicked point's part is selected");
    step_until(&mut h, "the reopened part", |app| super::generation(app) > before && !app.is_busy());
    assert_eq!(h.state().state.views.active, sheen::app::views::ViewKind::Inspect, "opened in Inspect");
    h.run_steps(10);
    assert_eq!(count(), 1, "a part reopened from the chart is not recorded again either");

    // Opening the same input again is measuring the part anew: recorded once.
    h.state_mut().push_command(sheen::app::commands::Command::Open(manifest.clone()));
    step_until(&mut h, "the automatic record", |app| !app.inspect().record_job_running() && count() == 2);
    h.run_steps(20);
    step_until(&mut h, "nothing more to record", |app| !app.inspect().record_job_running() && !app.is_busy());
    let parts = sheen::records::Store::open(&location)
        .expect("open")
        .parts(&sheen::records::HistoryFilter::default())
        .expect("read");
    assert_eq!(parts.len(), 2, "one automatic record per new result, none for the demo or the review");
    assert!(h.state().inspect().reviewing.is_none());
    let auto = &parts[1].record;
    assert_eq!((auto.part_id.as_str(), auto.recipe.as_str()), ("part-42", "flat plate"));
    assert_eq!(auto.input_hash, parts[0].record.input_hash, "the same images as the CLI's record");
    assert_eq!(auto.measurements.len(), 1);
}

/// Issue 20 in the app: Texture on a region and Roughness on a profile add
/// their ISO parameters to the table; a form removal turns a tilted plane's
/// slope into nothing, and a limit on one parameter gives its row a verdict.
#[test]
fn texture_and_roughness_buttons_measure_the_iso_parameters() {
    use sheen::analysis::inspection::{Measure, ParameterLimit};
    use sheen::analysis::texture::filter::FormRemoval;
    use sheen::analysis::texture::measure::ArealParameter;
    let mut h = inspecting();
    {
        let doc = &mut h.state_mut().inspect_mut().doc;
        // The base below the step: a tilted plane (slope 0.02 in x).
        doc.add_region(Region::Rectangle { x_mm: [-0.5, 0.5], y_mm: [-0.45, -0.1] });
        doc.add_profile(sheen::analysis::profile::ProfileLine::Horizontal { through_mm: [0.0, -0.3] });
    }
    settle(&mut h);
    press_named(&mut h, "Texture");
    press_named(&mut h, "Roughness");
    settle(&mut h);
    let names: Vec<String> =
        h.state().inspect().report().expect("report").table.rows.iter().map(|r| r.name.clone()).collect();
    for want in
        ["texture R1 Sa", "texture R1 Sq", "texture R1 Sdr", "texture R1 Vmc", "roughness A-A Ra", "roughness A-A Wt"]
    {
        assert!(names.iter().any(|n| n == want), "{want} missing from {names:?}");
    }
    // Plane removed: what is left of a plane is the rendering's rounding.
    let sq_plane = row_value(&h, "texture R1 Sq");
    assert!(sq_plane < 0.5, "Sq after plane removal {sq_plane} um");
    // Without form removal the 0.02 slope over 1 mm is all texture.
    let set_form = |h: &mut Harness<'_, SheenApp>, f: FormRemoval| {
        let m =
            h.state_mut().inspect_mut().doc.measurements.iter_mut().find(|m| m.name == "texture R1").expect("texture");
        if let Measure::Texture { form, .. } = &mut m.measure {
            *form = f;
        }
    };
    set_form(&mut h, FormRemoval::None);
    settle(&mut h);
    let sq_raw = row_value(&h, "texture R1 Sq");
    // z = 0.02 x over x in [-0.5, 0.5] mm: Sq = 0.02 * 1 mm / sqrt(12) = 5.77 um.
    assert!((sq_raw - 5.77).abs() < 0.3, "Sq without form removal {sq_raw} um");
    set_form(&mut h, FormRemoval::Plane);
    // A limit on Sa: its row gets a verdict, the others none.
    {
        let m =
            h.state_mut().inspect_mut().doc.measurements.iter_mut().find(|m| m.name == "texture R1").expect("texture");
        if let Measure::Texture { limits, .. } = &mut m.measure {
            limits.insert(
                ArealParameter::Sa,
                ParameterLimit {
                    nominal: None,
                    tolerance: sheen::analysis::measurement_table::Tolerance { lower: 0.0, upper: 1e-6 },
                },
            );
        }
    }
    settle(&mut h);
    let report = h.state().inspect().report().expect("report");
    let verdict = |n: &str| report.table.rows.iter().find(|r| r.name == n).and_then(|r| r.verdict());
    assert_eq!(verdict("texture R1 Sa"), Some(sheen::analysis::measurement_table::Verdict::Fail));
    assert_eq!(verdict("texture R1 Sq"), None);
    assert!(shows(&h, "Overall: FAIL"));
}

/// Another instrument's height map opened in the app (File > Open path):
/// an X3P of a 25 um step on a plane is measured in the Inspect view in
/// place of the measurement's map, Record is refused for it, a float TIFF
/// needs its pixel size first, and Close map returns to the measurement.
#[test]
fn a_height_map_file_opens_in_the_inspect_view_and_is_measured() {
    use sheen::analysis::height_map::HeightMap;
    use sheen::io::x3p::{X3pDataType, X3pMetadata, write_x3p};
    let mut h = inspecting();
    let measured_width = h.state().inspect().analysis().expect("analysis").map.width;
    let dir = tempfile::tempdir().expect("tempdir");
    // 200 x 100 nodes at 10 um: heights 0 for x < 1 mm, 25 um beyond, on a
    // 1e-3 tilt along y that levelling to the low side removes.
    let (w, hh, pitch) = (200usize, 100usize, 0.01);
    let z_mm: Vec<f32> = (0..w * hh)
        .map(|i| {
            let (c, r) = (i % w, i / w);
            (if c >= 100 { 0.025 } else { 0.0 } + 1e-3 * r as f64 * pitch) as f32
        })
        .collect();
    let map = HeightMap::new(w, hh, 0.0, 0.0, pitch, z_mm.clone()).expect("map");
    let x3p = dir.path().join("confocal step.x3p");
    let file = std::fs::File::create(&x3p).expect("create");
    write_x3p(file, &map, &X3pMetadata::sheen("2026-12-05T00:00:00Z"), X3pDataType::Float64).expect("x3p");

    h.state_mut().push_command(Command::Open(x3p.clone()));
    step_until(&mut h, "the height map to open", |app| app.inspect().opened_map().is_some());
    settle(&mut h);
    assert_eq!(h.state().state.views.active, sheen::app::views::ViewKind::Inspect);
    let opened = h.state().inspect().opened_map().expect("opened");
    assert_eq!((opened.path.as_path(), opened.format.name()), (x3p.as_path(), "X3P"));
    let shown = &h.state().inspect().analysis().expect("analysis").map;
    assert_eq!((shown.width, shown.height), (w, hh), "the file's map is inspected, not the measurement's");
    assert!(h.query_by_label("Close map").is_some());

    let doc = &mut h.state_mut().inspect_mut().doc;
    let r = doc.add_region(Region::Rectangle { x_mm: [0.1, 0.8], y_mm: [0.1, 0.9] });
    doc.regions[r].role = RegionRole::Reference;
    let m = doc.add_region(Region::Rectangle { x_mm: [1.2, 1.9], y_mm: [0.1, 0.9] });
    doc.regions[m].role = RegionRole::Measured;
    doc.add_step_height().expect("step");
    settle(&mut h);
    let step = row_value(&h, &h.state().inspect().doc.measurements[0].name.clone());
    assert!((step - 25.0).abs() < 0.01, "step {step} um");
    let refused = h.state().inspect().can_record().expect_err("no record of a file's map").to_string();
    assert!(refused.contains("not recorded"), "{refused}");

    // A float TIFF of the same heights (um, north up) needs its pixel size.
    let tif = dir.path().join("map.tif");
    let north_up: Vec<f32> = (0..hh).rev().flat_map(|r| z_mm[r * w..(r + 1) * w].iter().map(|z| z * 1000.0)).collect();
    sheen::io::maps::write_f32_tiff(&tif, w, hh, &north_up, sheen::io::maps::TiffCompression::None).expect("tiff");
    h.state_mut().push_command(Command::Open(tif.clone()));
    step_until(&mut h, "the TIFF to be refused", |app| {
        app.inspect().status.as_ref().is_some_and(|s| s.is_error && s.text.contains("pixel size"))
    });
    assert_eq!(h.state().inspect().opened_map().map(|o| o.path.clone()), Some(x3p.clone()), "the X3P stays");
    h.state_mut().state.views.inspect.tiff_pixel_mm = pitch;
    h.state_mut().push_command(Command::Open(tif.clone()));
    step_until(&mut h, "the TIFF to open", |app| app.inspect().opened_map().is_some_and(|o| o.path == tif));
    settle(&mut h);
    let step = row_value(&h, &h.state().inspect().doc.measurements[0].name.clone());
    assert!((step - 25.0).abs() < 0.01, "TIFF step {step} um");

    h.get_by_label("Close map").click();
    settle(&mut h);
    assert!(h.state().inspect().opened_map().is_none());
    assert_eq!(
        h.state().inspect().analysis().expect("analysis").map.width,
        measured_width,
        "the measurement's map again"
    );
}

/// A texture measurement on a profile puts its R and W profiles in the
/// profile plot: "R and W" switches the plot to them, and what is drawn is
/// the evaluation itself (form + W + R gives the measured profile back at
/// every evaluated sample; Ra in the table is the mean |R| drawn).
#[test]
fn the_profile_plot_draws_the_r_and_w_profiles_of_a_texture_measurement() {
    use sheen::app::views::inspect::plot::texture_lines;
    let mut h = inspecting();
    step_inspection(&mut h);
    let doc = &mut h.state_mut().inspect_mut().doc;
    let m = doc.add_roughness(0).expect("roughness");
    if let Measure::ProfileTexture { lc_mm, .. } = &mut doc.measurements[m].measure {
        *lc_mm = Some(0.08);
    }
    let name = doc.measurements[m].name.clone();
    settle(&mut h);
    assert!(!h.state().inspect().doc.show_r_and_w);
    let report = h.state().inspect().report().expect("report").clone();
    let t = report.profile_textures.first().expect("the texture's curves");
    let profile = report.profiles.iter().find(|p| p.name == t.profile).expect("profile");
    let c = &t.curves;
    for i in c.evaluated.clone().filter(|&i| profile.samples[i].n > 0) {
        let back = c.form_um[i] + c.waviness_um[i] + c.roughness_um[i];
        assert!((back - profile.samples[i].z_um).abs() < 1e-6, "sample {i}: {back} vs {}", profile.samples[i].z_um);
    }
    let doc = &h.state().inspect().doc;
    let heights = texture_lines(doc, &report.profile_textures, false);
    assert!(heights.len() == 1 && heights[0].name.contains("mean line") && heights[0].dashed, "{heights:?}");

    h.get_by_label("R and W").click();
    h.run_steps(2);
    assert!(h.state().inspect().doc.show_r_and_w, "the checkbox switches the plot");
    let drawn = texture_lines(&h.state().inspect().doc, &report.profile_textures, true);
    let r = drawn.iter().find(|l| l.name == format!("{} R", t.profile)).expect("an R line");
    assert!(drawn.iter().any(|l| l.name == format!("{} W", t.profile) && l.dashed));
    let finite: Vec<f64> = r.points.iter().map(|p| p[1]).filter(|z| z.is_finite()).collect();
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    let ra = finite.iter().map(|z| (z - mean).abs()).sum::<f64>() / finite.len() as f64;
    let table_ra = row_value(&h, &format!("{name} Ra"));
    assert!((ra - table_ra).abs() <= 1e-6 * table_ra.max(1e-3), "Ra drawn {ra} vs table {table_ra}");
}

/// The texture of a full-size map takes seconds: Cancel stops it (the
/// table keeps the last finished inspection and nothing runs on), the
/// inspection is not measured again by itself, and Measure runs it.
#[test]
fn measuring_a_large_texture_can_be_cancelled_and_run_again() {
    use sheen::analysis::height_map::HeightMap;
    use sheen::analysis::texture::filter::FormRemoval;
    use sheen::io::x3p::{X3pDataType, X3pMetadata, write_x3p};
    let mut h = inspecting();
    let dir = tempfile::tempdir().expect("tempdir");
    let (w, hh, pitch) = (2048usize, 1536usize, 0.0117);
    let z_mm: Vec<f32> = (0..w * hh)
        .map(|i| {
            let (x, y) = ((i % w) as f64 * pitch, (i / w) as f64 * pitch);
            (1e-4 * (x * 40.0).sin() * (y * 25.0).cos()) as f32
        })
        .collect();
    let map = HeightMap::new(w, hh, 0.0, 0.0, pitch, z_mm).expect("map");
    let x3p = dir.path().join("plate.x3p");
    write_x3p(
        std::fs::File::create(&x3p).expect("create"),
        &map,
        &X3pMetadata::sheen("2026-12-05T00:00:00Z"),
        X3pDataType::Float32,
    )
    .expect("x3p");
    h.state_mut().push_command(Command::Open(x3p));
    step_until(&mut h, "the map to open", |app| app.inspect().opened_map().is_some());
    settle(&mut h);
    let doc = &mut h.state_mut().inspect_mut().doc;
    doc.measurements.push(sheen::analysis::inspection::MeasurementSpec {
        name: "plate".into(),
        measure: Measure::Texture {
            region: sheen::analysis::inspection::WHOLE_MAP.into(),
            form: FormRemoval::Plane,
            ls_mm: Some(0.025),
            lc_mm: Some(0.8),
            smr_c_um: None,
            smc_mr_percent: None,
            limits: Default::default(),
        },
        nominal: None,
        tolerance: None,
    });
    h.run_steps(2);
    assert!(h.state().inspect().is_busy(), "the texture is being measured");
    h.get_by_label("Cancel measuring").click();
    h.run_steps(2);
    let rt = h.state().inspect();
    assert!(rt.measuring_cancelled() && !rt.is_current(), "cancelled, and the table is the older inspection's");
    step_until(&mut h, "the cancelled job to stop", |app| !app.inspect().is_busy());
    h.run_steps(3);
    assert!(!h.state().inspect().is_busy() && !h.state().inspect().is_current(), "not measured again by itself");
    h.get_by_label("Measure").click();
    settle(&mut h);
    let sq = row_value(&h, "plate Sq");
    assert!(sq > 0.0 && sq.is_finite(), "Sq {sq}");

    // The map can show the S-L surface the parameters describe: its RMS is Sq.
    h.get_by_label("Map shows").click();
    h.run_steps(2);
    h.get_by_label("surface of plate").click();
    settle(&mut h);
    let a = h.state().inspect().analysis().expect("analysis");
    assert_eq!(a.shown, MapShows::Surface("plate".into()));
    let shown: Vec<f64> = a.display_um.iter().filter(|z| z.is_finite()).map(|&z| f64::from(z)).collect();
    let rms = (shown.iter().map(|z| z * z).sum::<f64>() / shown.len() as f64).sqrt();
    assert!((rms - sq).abs() < 1e-3 * sq, "the surface shown has RMS {rms} um, Sq is {sq} um");
}

/// Save as recipe writes the session and the measured map; the recipe then
/// measures that map on the command line as the app did: found in place
/// (score 1, no rotation, no shift) and the step height the table shows.
#[test]
fn save_as_recipe_writes_a_recipe_the_command_line_measures_alike() {
    let mut h = inspecting();
    step_inspection(&mut h);
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("plate.sheen-recipe.json");
    let step_in_app = row_value(&h, "step R2");
    h.state_mut().push_command(Command::SaveRecipe(Some(path.clone())));
    step_until(&mut h, "the recipe file", |app| !app.inspect().file_job_running() && path.exists());
    let recipe = sheen::analysis::recipe::Recipe::from_json(&std::fs::read_to_string(&path).expect("read"))
        .expect("the recipe reads back");
    assert_eq!(recipe.name, "plate");
    assert_eq!(recipe.session.inspection.regions.len(), 2);
    assert!(recipe.session.inspection.height_map.pitch_mm.is_some(), "the pitch is fixed");
    let map = dir.path().join(&recipe.reference_map);
    assert!(map.exists(), "{}", map.display());

    let out = dir.path().join("out");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(["analyze", map.to_str().expect("utf8"), "--recipe", path.to_str().expect("utf8"), "--out"])
        .arg(&out)
        .arg("-q")
        .output()
        .expect("run sheen");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("measurements.json")).expect("read")).expect("json");
    let value = |name: &str| {
        json["measurements"]
            .as_array()
            .expect("rows")
            .iter()
            .find(|r| r["name"] == name)
            .and_then(|r| r["value"].as_f64())
    };
    assert!(value("alignment score").expect("score") > 0.999);
    assert!(value("alignment rotation").expect("rotation").abs() < 0.01);
    assert!(value("alignment shift X").expect("x").abs() < 1e-3 && value("alignment shift Y").expect("y").abs() < 1e-3);
    let step = value("step R2").expect("the step");
    assert!((step - step_in_app).abs() < 0.05, "{step} um on the command line, {step_in_app} um in the app");
}

/// A part with a block 25 um high and a round boss 10 um high, in the
/// reference part's millimetres; `at(x, y)` maps a node of the map drawn to
/// that reference point.
fn block_part_map(at: impl Fn(f64, f64) -> [f64; 2]) -> sheen::analysis::height_map::HeightMap {
    let (w, hh, pitch) = (400usize, 300usize, 0.01);
    let z_mm: Vec<f32> = (0..w * hh)
        .map(|i| {
            let [x, y] = at((i % w) as f64 * pitch, (i / w) as f64 * pitch);
            // Walls 30 um wide, as optics and rasterization leave them.
            let inside = |d: f64| (d / 0.03 + 0.5).clamp(0.0, 1.0);
            let block = inside(x - 2.2) * inside(3.2 - x) * inside(y - 0.8) * inside(2.0 - y);
            let boss = inside(0.35 - (x - 1.0).hypot(y - 2.2));
            (0.025 * block + 0.010 * boss) as f32
        })
        .collect();
    sheen::analysis::height_map::HeightMap::new(w, hh, 0.0, 0.0, pitch, z_mm).expect("map")
}

fn write_x3p_file(path: &Path, map: &sheen::analysis::height_map::HeightMap) {
    use sheen::io::x3p::{X3pDataType, X3pMetadata, write_x3p};
    std::fs::create_dir_all(path.parent().expect("folder")).expect("folder");
    let file = std::fs::File::create(path).expect("create");
    write_x3p(file, map, &X3pMetadata::sheen("2026-12-05T00:00:00Z"), X3pDataType::Float64).expect("x3p");
}

/// Inspect follows a line's recipe as `sheen analyze --recipe` does: the
/// part, turned 3° and shifted on the stage, is found on the recipe's
/// reference, the recipe's regions move with it (rectangles become
/// polygons), the step is the reference part's, the alignment leads the
/// table, and the map can show the part less its reference, near zero where
/// it matches. Another part is "part not found" and nothing is measured.
#[test]
fn following_a_recipe_moves_its_regions_with_the_part_and_shows_the_difference() {
    let mut h = inspecting();
    let dir = tempfile::tempdir().expect("tempdir");
    write_x3p_file(&dir.path().join("plate.reference/height_map.x3p"), &block_part_map(|x, y| [x, y]));
    let mut doc = InspectDoc::default();
    let r = doc.add_region(Region::Rectangle { x_mm: [0.3, 1.6], y_mm: [0.3, 1.2] });
    doc.regions[r].role = RegionRole::Reference;
    let m = doc.add_region(Region::Rectangle { x_mm: [2.4, 3.0], y_mm: [1.0, 1.8] });
    doc.regions[m].role = RegionRole::Measured;
    doc.add_step_height().expect("step");
    let mut session =
        sheen::analysis::session::Session::new("plate/fringe-set.json", sheen::engine::pipeline::Params::default());
    session.inspection = doc.spec();
    let recipe = sheen::analysis::recipe::Recipe::new("plate", session, "plate.reference/height_map.x3p");
    let recipe_path = dir.path().join("plate.sheen-recipe.json");
    std::fs::write(&recipe_path, recipe.to_json()).expect("write the recipe");

    // The part: reference point p lies at R(3°) p + (0.15, -0.1) mm.
    let (s, c) = 3f64.to_radians().sin_cos();
    let moved = block_part_map(|x, y| {
        let (dx, dy) = (x - 0.15, y + 0.1);
        [c * dx + s * dy, -s * dx + c * dy]
    });
    let part = dir.path().join("part.x3p");
    write_x3p_file(&part, &moved);
    h.state_mut().push_command(Command::Open(part.clone()));
    step_until(&mut h, "the part's map to open", |app| app.inspect().opened_map().is_some());
    h.state_mut().push_command(Command::FollowRecipe(Some(recipe_path.clone())));
    step_until(&mut h, "the recipe", |app| app.inspect().followed_recipe().is_some());
    step_until(&mut h, "the part to be found", |app| {
        app.inspect().report().is_some_and(|r| r.table.rows.first().is_some_and(|row| row.name == "alignment score"))
    });
    settle(&mut h);
    assert!(h.query_by_label("Stop following").is_some());
    assert!(row_value(&h, "alignment score") > 0.99);
    let rotation = row_value(&h, "alignment rotation");
    assert!((rotation - 3.0).abs() < 0.1, "rotation {rotation}°");
    let shift = [row_value(&h, "alignment shift X"), row_value(&h, "alignment shift Y")];
    assert!((shift[0] - 0.15).abs() < 0.01 && (shift[1] + 0.1).abs() < 0.01, "shift {shift:?} mm");
    let rt = h.state().inspect();
    assert!(rt.doc.regions.iter().all(|r| matches!(r.region.region, Region::Polygon { .. })), "{:?}", rt.doc.regions);
    let step = row_value(&h, &rt.doc.measurements[0].name.clone());
    assert!((step - 25.0).abs() < 0.1, "step {step} um on the moved part");
    assert_eq!(rt.recipe, "plate", "parts are recorded under the recipe's name");

    h.state_mut().inspect_mut().map_shows = MapShows::DifferenceToReference;
    settle(&mut h);
    let analysis = h.state().inspect().analysis().expect("analysis");
    assert_eq!(analysis.shown, MapShows::DifferenceToReference);
    let mut d: Vec<f32> = analysis.display_um.iter().filter(|v| v.is_finite()).map(|v| v.abs()).collect();
    d.sort_by(f32::total_cmp);
    assert!(d.len() > 100_000, "{} nodes compared", d.len());
    // The difference is exactly zero away from the edges, which the node
    // grid resamples.
    assert!(
        d[d.len() / 2] < 0.01 && d[d.len() * 9 / 10] < 0.5,
        "median {} um, q90 {} um",
        d[d.len() / 2],
        d[d.len() * 9 / 10]
    );

    // Another part: not found, and nothing measured in its place.
    let other = dir.path().join("other.x3p");
    write_x3p_file(&other, &block_part_map(|x, y| [4.0 - y * 1.3, x * 0.7]));
    h.state_mut().push_command(Command::Open(other.clone()));
    step_until(&mut h, "the other part to be refused", |app| {
        app.inspect().status.as_ref().is_some_and(|s| s.is_error && s.text.contains("part not found"))
    });
    settle(&mut h);
    let rt = h.state().inspect();
    assert!(rt.doc.measurements.is_empty() && rt.doc.regions.is_empty(), "{:?}", rt.doc.regions);
    assert!(rt.report().is_some_and(|r| r.table.rows.is_empty()));

    // The measurement on screen is another part too: it is not found, and
    // a part not found is not recorded as if it had been measured.
    h.state_mut().inspect_mut().status = None;
    h.get_by_label("Close map").click();
    step_until(&mut h, "the measurement to be refused", |app| {
        app.inspect().opened_map().is_none()
            && app.inspect().status.as_ref().is_some_and(|s| s.is_error && s.text.contains("part not found"))
    });
    settle(&mut h);
    let refused = h.state().inspect().can_record().expect_err("not recorded").to_string();
    assert!(refused.contains("not found"), "{refused}");
    h.get_by_label("Stop following").click();
    settle(&mut h);
    assert!(h.state().inspect().followed_recipe().is_none() && h.state().inspect().can_record().is_ok());
}
