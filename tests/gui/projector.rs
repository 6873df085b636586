//! Issue 52 in the app: a camera–projector capture with a Gray code opens,
//! and the Projector view shows each camera pixel's absolute projector
//! column and row, its Gray code, and the refused pixels by reason.

use std::path::{Path, PathBuf};

use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT as _, Queryable as _};
use sheen::app::SheenApp;
use sheen::app::commands::{Command, PixelRef};
use sheen::app::views::ViewKind;
use sheen::engine::control::RunControl;
use sheen::sim::SceneKind;
use sheen::sim::camera_projector::{PinholeRigConfig, PinholeTruth, simulate_camera_projector};

use super::{opened, shows};

/// The simulator's camera–projector rig over the step gauge (its blocks
/// shadow the stage beside them), 96 x 72 px, no read noise; returns the
/// written manifest and the truth.
fn write_capture(dir: &Path) -> (PathBuf, PinholeTruth) {
    let config = PinholeRigConfig {
        camera_width: 96,
        camera_height: 72,
        noise_sigma_dn: 0.0,
        ..PinholeRigConfig::new(SceneKind::StepGauge)
    };
    let sim = simulate_camera_projector(&config, &RunControl::new()).expect("simulate");
    let manifest = sheen::io::dataset::write_measurement(dir, &sim.measurement).expect("write the capture");
    (manifest, sim.truth)
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
    let (manifest, truth) = write_capture(dir.path());
    let mut h = opened(manifest);
    let app = h.state();
    assert!(app.banner().is_none(), "{:?}", app.banner().map(|b| &b.text));
    let rec = &app.result().expect("result").reconstruction;
    let maps = rec.projector.as_ref().expect("a camera–projector result").as_ref().expect("coordinates");
    let x = maps[0].x.as_ref().expect("projector x");
    // Every lit pixel measured, to a small fraction of a projector pixel.
    let (lit, measured) = x.lit_and_measured();
    assert_eq!(lit, truth.lit_count());
    assert!(measured as f64 > 0.98 * lit as f64, "{measured} of {lit}");
    for (i, v) in x.coordinate_px.iter().enumerate().filter(|(_, v)| !v.is_nan()) {
        let t = truth.projector_px[i][0];
        assert!((f64::from(*v) - t).abs() < 0.2, "pixel {i}: {v} for {t}");
    }
    h.get_by_label(ViewKind::Projector.title()).click();
    h.run_steps(3);
    assert!(map_labels(&h).iter().any(|l| l.starts_with("camera · projector x")), "{:?}", map_labels(&h));
    assert!(shows(&h, "of the lit pixels measured"));
    h.get_by_label("Refused pixels").click();
    h.run_steps(3);
    assert!(shows(&h, "shadow: "), "the legend counts the shadow");
    h.get_by_label("y (rows)").click();
    h.get_by_label("Gray code").click();
    h.run_steps(3);
    assert!(map_labels(&h).iter().any(|l| l.starts_with("camera · projector y")), "{:?}", map_labels(&h));
    // The code's bit planes as recorded: pattern minus inverse.
    h.get_by_label("Gray bits").click();
    h.run_steps(3);
    assert!(shows(&h, "bit plane 0 of 5 (most significant first)"), "the Gray bits layer's footer");
    // Clicking a pixel: the inspector gives its projector x and y, or why not.
    let select = |h: &mut Harness<'_, SheenApp>, i: usize| {
        let pixel = PixelRef { camera: 0, u: i % 96, v: i / 96 };
        h.state_mut().push_command(Command::SelectPixel(pixel));
        h.run_steps(3);
        h.state().pixel_report().expect("a pixel report").projector
    };
    let lit = (0..96 * 72).find(|&i| truth.is_lit(i)).expect("a lit pixel");
    let lines = select(&mut h, lit);
    assert!(
        lines.len() == 2 && lines[0].starts_with("projector x: x_p = ") && lines[1].contains("y_p = "),
        "{lines:?}"
    );
    assert!(shows(&h, &lines[0]), "the inspector shows {}", lines[0]);
    let shadow = (0..96 * 72).find(|&i| !truth.is_lit(i)).expect("a pixel in the shadow");
    let lines = select(&mut h, shadow);
    assert!(lines[0].contains("refused: in the projector's shadow"), "{lines:?}");
    h.check_accessibility();
}

/// The camera–projector rig's 3D in the app (issue 52, item 4): the
/// calibrated capture's cloud is the run's cloud, on the surface the
/// simulator rendered (seen from the camera: Z is minus the depth), and
/// the Height and 3D views show it instead of "no 3D points".
#[test]
fn a_calibrated_camera_projector_capture_has_its_cloud_in_the_height_and_3d_views() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (manifest, truth) = write_capture(dir.path());
    let mut h = opened(manifest);
    let app = h.state();
    let rec = &app.result().expect("result").reconstruction;
    let cloud = rec.cloud().expect("the rig's cloud");
    assert!(cloud.len() as f64 > 0.95 * truth.lit_count() as f64, "{} of {}", cloud.len(), truth.lit_count());
    let worst_mm = cloud
        .xyz
        .iter()
        .zip(&cloud.pixel_uv)
        .map(|(p, uv)| (p[2] + truth.point_camera_mm[uv[1] as usize * 96 + uv[0] as usize][2]).abs())
        .fold(0.0f64, f64::max);
    assert!(worst_mm < 0.05, "a point {worst_mm} mm off the rendered surface");
    // The status line counts the rig's points and the pixels with a projector x.
    let x = rec.projector.as_ref().expect("coordinates").as_ref().expect("decoded")[0].x.as_ref().expect("x");
    let measured = x.coordinate_px.iter().filter(|v| !v.is_nan()).count();
    let valid = format!("valid {:.1} % · {} points", 100.0 * measured as f64 / (96.0 * 72.0), cloud.len());
    assert!(shows(&h, &valid), "the status line says {valid}");
    h.get_by_label(ViewKind::Height.title()).click();
    h.run_steps(3);
    assert!(shows(&h, "from the projector coordinates, Z towards the camera"), "the Height view's footer");
    h.get_by_label(ViewKind::Cloud.title()).click();
    h.run_steps(3);
    assert!(!shows(&h, "No 3D points"), "the 3D view has the rig's points");
}
