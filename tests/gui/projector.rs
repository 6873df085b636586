//! Issue 52 in the app: a camera–projector capture with a Gray code opens,
//! and the Projector view shows each camera pixel's absolute projector
//! column and row, its Gray code, and the refused pixels by reason.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT as _, Queryable as _};
use sheen::app::views::ViewKind;
use sheen::app::{AppOptions, SheenApp, Startup};
use sheen::engine::gray_code::{bit_planes, pattern_is_bright};

use super::{WINDOW, options, shows, synthetic, wait_for_result};

const CAMERA: (usize, usize) = (64, 48);
const PROJECTOR: (usize, usize) = (256, 192);
const CELL_PX: usize = 16;
const PERIODS: [f64; 2] = [16.0, 24.0];

/// The projector point a camera pixel sees (a tilted plane); the left
/// eighth of the image is in the projector's shadow.
fn seen(c: usize, r: usize) -> Option<(f64, f64)> {
    (c >= 8).then_some((4.0 + 3.6 * c as f64 + 0.1 * r as f64, 6.0 + 3.5 * r as f64 + 0.05 * c as f64))
}

/// Writes the capture's 32 frames and its manifest; returns the manifest.
fn write_capture(dir: &Path) -> PathBuf {
    let mut frames: Vec<Box<dyn Fn(f64, f64) -> f64>> = Vec::new();
    for axis in 0..2 {
        for period in PERIODS {
            for k in 0..3 {
                let shift = TAU / 3.0 * (k as f64 - 1.0);
                frames.push(Box::new(move |x, y| {
                    let p = if axis == 0 { x } else { y };
                    100.0 + 60.0 * (TAU * p / period + shift).cos()
                }));
            }
        }
    }
    for (axis, extent) in [(0usize, PROJECTOR.0), (1, PROJECTOR.1)] {
        let planes = bit_planes(extent.div_ceil(CELL_PX));
        for plane in 0..planes {
            for inverse in [false, true] {
                frames.push(Box::new(move |x, y| {
                    let cell = ((if axis == 0 { x } else { y }) / CELL_PX as f64).floor() as u32;
                    if pattern_is_bright(cell, planes, plane) != inverse { 180.0 } else { 30.0 }
                }));
            }
        }
    }
    frames.push(Box::new(|_, _| 200.0));
    frames.push(Box::new(|_, _| 20.0));
    let names: Vec<String> = (0..frames.len()).map(|i| format!("pat{i:02}.png")).collect();
    for (frame, name) in frames.iter().zip(&names) {
        let pixels: Vec<u8> = (0..CAMERA.0 * CAMERA.1)
            .map(|i| seen(i % CAMERA.0, i / CAMERA.0).map_or(20.0, |(x, y)| frame(x, y)).round() as u8)
            .collect();
        image::GrayImage::from_raw(CAMERA.0 as u32, CAMERA.1 as u32, pixels)
            .expect("frame size")
            .save(dir.join(name))
            .expect("write a frame");
    }
    let list = |from: usize, n: usize| serde_json::json!({"camera": names[from..from + n]});
    let shifts = [-TAU / 3.0, 0.0, TAU / 3.0];
    let set = |period: f64, axis: &str, from: usize| serde_json::json!({"period": period, "shifts": 3, "axis": axis, "phase_shifts_rad": shifts, "images": list(from, 3)});
    let manifest = serde_json::json!({"sheen_fringe_set": 1, "bit_depth": 8, "rig": "camera-projector",
        "projector": {"width": PROJECTOR.0, "height": PROJECTOR.1},
        "sets": [set(24.0, "x", 3), set(16.0, "x", 0), set(24.0, "y", 9), set(16.0, "y", 6)],
        "gray_code": {"layout": "opencv", "cell_px": CELL_PX, "columns": list(12, 8), "rows": list(20, 8),
                      "white": {"camera": names[28]}, "black": {"camera": names[29]}}});
    let path = dir.join("fringe-set.json");
    std::fs::write(&path, manifest.to_string()).expect("write the manifest");
    path
}

fn map_labels(h: &Harness<'_, SheenApp>) -> Vec<String> {
    h.query_all_by_label_contains(" map")
        .filter_map(|n| n.accesskit_node().label())
        .filter(|l| l.ends_with(" map") && l.contains(" · "))
        .collect()
}

#[test]
fn the_projector_view_shows_a_camera_projector_rigs_coordinates_code_and_refusals() {
    let dir = tempfile::tempdir().expect("tempdir");
    let startup = Startup::Manifest(write_capture(dir.path()));
    let mut h = Harness::builder()
        .with_size(WINDOW)
        .with_max_steps(64)
        .build_eframe(move |cc| SheenApp::new(cc, AppOptions { startup, ..options(synthetic::demo) }));
    wait_for_result(&mut h, 0);
    let app = h.state();
    assert!(app.banner().is_none(), "{:?}", app.banner().map(|b| &b.text));
    let rec = &app.result().expect("result").reconstruction;
    let maps = rec.projector.as_ref().expect("a camera–projector result").as_ref().expect("coordinates");
    let x = maps[0].x.as_ref().expect("projector x");
    // Every lit pixel off the cell edges measured, to a small fraction of a pixel.
    let (lit, measured) = x.lit_and_measured();
    assert_eq!(lit, (CAMERA.0 - 8) * CAMERA.1);
    assert!(measured as f64 > 0.95 * lit as f64, "{measured} of {lit}");
    for (i, v) in x.coordinate_px.iter().enumerate().filter(|(_, v)| !v.is_nan()) {
        let truth = seen(i % CAMERA.0, i / CAMERA.0).expect("lit").0;
        assert!((f64::from(*v) - truth).abs() < 0.05, "pixel {i}: {v} for {truth}");
    }
    h.get_by_label(ViewKind::Projector.title()).click();
    h.run_steps(3);
    assert!(map_labels(&h).iter().any(|l| l.starts_with("camera · projector x")), "{:?}", map_labels(&h));
    assert!(shows(&h, "of the lit pixels measured"));
    h.get_by_label("Refused pixels").click();
    h.run_steps(3);
    assert!(shows(&h, "shadow: 12.5 %"), "the legend counts the shadow");
    h.get_by_label("y (rows)").click();
    h.get_by_label("Gray code").click();
    h.run_steps(3);
    assert!(map_labels(&h).iter().any(|l| l.starts_with("camera · projector y")), "{:?}", map_labels(&h));
    h.check_accessibility();
}
