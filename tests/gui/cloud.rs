//! The 3D view in the real app: drawn through wgpu (lavapipe will do), a
//! click on a point selects its pixel in the inspector, gestures move the
//! camera, the cloud is uploaded once per result; without a wgpu renderer the
//! view says why instead of crashing.

use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use sheen::app::SheenApp;
use sheen::app::commands::PixelRef;
use sheen::app::views::{ColorBy, ViewPreset};

use super::{WINDOW, click_at, options, shows, started, step_until, synthetic, wait_for_result, wheel_at};

/// The app on the synthetic demo with eframe's wgpu render state, as the binary runs it.
fn started_with_wgpu() -> Harness<'static, SheenApp> {
    let mut h = Harness::builder()
        .with_size(WINDOW)
        .with_max_steps(64)
        .with_step_dt(0.05)
        .wgpu()
        .build_eframe(|cc| SheenApp::new(cc, options(synthetic::demo)));
    wait_for_result(&mut h, 0);
    h.get_by_label("3D").click();
    wait_for_cloud(&mut h);
    h
}

/// Steps until the 3D view has packed and uploaded the newest cloud (a worker
/// does that; the view shows the previous one, or a spinner, meanwhile).
fn wait_for_cloud(h: &mut Harness<'static, SheenApp>) {
    let uploads = h.state().cloud_view().uploads();
    step_until(h, "the cloud on the GPU", |app| !app.cloud_view().is_packing() && app.cloud_view().uploads() > uploads);
}

/// Jobs yield to the UI thread only where drawing leaves the cores to the
/// engine: with a GPU they run below it, with a CPU renderer (lavapipe, as
/// in CI) at the same priority, and the log says why.
#[test]
fn job_priority_follows_where_the_window_is_drawn() {
    let h = started_with_wgpu();
    let adapter = h.state().renderer().expect("a wgpu renderer").clone();
    let on_cpu = adapter.device_type == eframe::wgpu::DeviceType::Cpu;
    assert_eq!(sheen::app::jobs::jobs_below_ui_thread(), !on_cpu, "{adapter:?}");
    let logged = h.state().log().entries().iter().any(|e| e.text.starts_with("Drawing on the CPU"));
    assert_eq!(logged, on_cpu, "{adapter:?}");
    // Progress is redrawn less often where each frame takes the engine's cores.
    let pace = if on_cpu { sheen::app::PROGRESS_REPAINT_ON_CPU } else { sheen::app::PROGRESS_REPAINT };
    assert_eq!(h.state().progress_repaint(), pace, "{adapter:?}");
    assert!(sheen::app::PROGRESS_REPAINT_ON_CPU > sheen::app::PROGRESS_REPAINT);
}

/// Index in the cloud of the point measured at left pixel (u, v).
fn point_of_pixel(h: &Harness<'_, SheenApp>, u: usize, v: usize) -> usize {
    let derived = &h.state().result().expect("result").derived;
    let index = derived.point_index.as_ref().expect("point index")[v * synthetic::WIDTH + u];
    assert_ne!(index, u32::MAX, "pixel ({u}, {v}) has a point");
    index as usize
}

#[test]
fn clicking_a_point_selects_its_pixel_in_the_inspector() {
    let mut h = started_with_wgpu();
    let (u, v) = (105, 50);
    let index = point_of_pixel(&h, u, v);
    let pos = h.state().cloud_view().screen_position(index).expect("the point is drawn");
    let canvas = h.get_by_label("3D point cloud").rect();
    assert!(canvas.contains(pos), "the home view shows the whole cloud: {pos:?} in {canvas:?}");

    // Hovering reads the point's values.
    h.event(egui::Event::PointerMoved(pos));
    h.run_steps(2);
    let hovered = h.state().cloud_view().hovered().expect("a hovered point").clone();
    assert_eq!(hovered.index, index);
    assert_eq!(hovered.pixel, Some([u, v]));
    let xyz = h.state().result().expect("result").reconstruction.stereo.as_ref().expect("stereo").cloud.xyz[index];
    assert!(shows(
        &h,
        &format!("X {:.4} mm · Y {:.4} mm · Z {:.2} µm · pixel u {u}, v {v}", xyz[0], xyz[1], xyz[2] * 1e3)
    ));

    // Clicking selects the pixel: the inspector and the 2D views follow.
    click_at(&mut h, pos);
    let app = h.state();
    assert_eq!(app.selection(), Some(PixelRef { camera: 0, u, v }));
    let report = app.pixel_report().expect("the inspector's report");
    assert_eq!(report.source, Some(1), "the disc pixel's phase came from set 1");
    assert!(shows(&h, &format!("left camera · u {u}, v {v}")), "the inspector shows the pixel");
    assert!(shows(&h, "Selected: X "), "the view shows the selected point");

    // Nothing is picked away from the cloud.
    click_at(&mut h, canvas.left_top() + egui::vec2(3.0, 3.0));
    assert_eq!(h.state().selection(), Some(PixelRef { camera: 0, u, v }), "a click on empty space keeps the selection");
}

#[test]
fn the_cloud_is_drawn_through_egui_wgpu_and_uploaded_once_per_result() {
    let mut h = started_with_wgpu();
    assert_eq!(h.state().cloud_view().uploads(), 1);
    // The paint callback draws in kittest's pass (no depth attachment).
    let image = h.render().expect("render");
    let canvas = h.get_by_label("3D point cloud").rect();
    let background = image.get_pixel(canvas.left() as u32 + 2, canvas.top() as u32 + 2).0;
    let (mut cloud, mut total) = (0, 0);
    for y in canvas.top() as u32..canvas.bottom() as u32 {
        for x in canvas.left() as u32..canvas.right() as u32 {
            total += 1;
            cloud += usize::from(image.get_pixel(x, y).0 != background);
        }
    }
    assert!(cloud * 5 > total, "the cloud covers a fifth of the view: {cloud} of {total} px");

    // Frames, hovering and camera moves reuse the upload.
    wheel_at(&mut h, canvas.center(), 120.0);
    h.run_steps(10);
    assert_eq!(h.state().cloud_view().uploads(), 1);
    // Another colour mode is another upload, once.
    h.get_by_role_and_label(egui::Role::ComboBox, "Colour by").click();
    h.run_steps(2);
    h.get_by_label("source set").click();
    // A worker packs the new colours; the frame that starts it shows a
    // spinner, not the old colours read through the new colour map.
    for _ in 0..3 {
        h.step();
        if h.state().cloud_view().is_packing() {
            break;
        }
    }
    assert!(h.state().cloud_view().is_packing(), "the packing runs on a worker");
    assert!(shows(&h, "points for the 3D view"), "a spinner while the new colours are packed");
    wait_for_cloud(&mut h);
    assert_eq!(h.state().state.views.cloud.color_by, ColorBy::SourceSet);
    assert_eq!(h.state().cloud_view().uploads(), 2);
    h.run_steps(5);
    assert_eq!(h.state().cloud_view().uploads(), 2);
}

#[test]
fn mouse_and_keys_move_the_camera() {
    let mut h = started_with_wgpu();
    let home = h.state().cloud_view().camera().expect("camera");
    let canvas = h.get_by_label("3D point cloud").rect();
    let c = canvas.center();

    // Wheel zooms towards the cursor.
    wheel_at(&mut h, c, 200.0);
    h.run_steps(10);
    let zoomed = h.state().cloud_view().camera().expect("camera");
    assert!(zoomed.distance < home.distance * 0.8, "{} vs {}", zoomed.distance, home.distance);

    // A drag with `button` from the centre by `to`, in five moves.
    let drag = |h: &mut Harness<'_, SheenApp>, button, to: egui::Vec2| {
        h.event(egui::Event::PointerButton { pos: c, button, pressed: true, modifiers: egui::Modifiers::NONE });
        for step in 1..=5 {
            h.event(egui::Event::PointerMoved(c + to * (step as f32 / 5.0)));
            h.run_steps(1);
        }
        h.event(egui::Event::PointerButton { pos: c + to, button, pressed: false, modifiers: egui::Modifiers::NONE });
        h.run_steps(2);
    };

    // A left drag orbits about the target.
    drag(&mut h, egui::PointerButton::Primary, egui::vec2(50.0, 0.0));
    let orbited = h.state().cloud_view().camera().expect("camera");
    assert!((orbited.yaw_rad - zoomed.yaw_rad).abs() > 0.1, "the drag turned the view");
    assert_eq!(orbited.target, zoomed.target);
    assert_eq!(orbited.distance, zoomed.distance);

    // A right drag pans: the target moves, the distance stays.
    let before_pan = h.state().cloud_view().camera().expect("camera");
    drag(&mut h, egui::PointerButton::Secondary, egui::vec2(30.0, 40.0));
    let panned = h.state().cloud_view().camera().expect("camera");
    assert!((panned.target - before_pan.target).norm() > 1e-3, "the target moved");
    assert_eq!(panned.distance, before_pan.distance);
    assert_eq!((panned.yaw_rad, panned.pitch_rad), (before_pan.yaw_rad, before_pan.pitch_rad));

    // A stronger Z exaggeration stretches the scene about the cloud's centre, and the target with it.
    h.get_by_role_and_label(egui::Role::Slider, "Z exaggeration").set_value_accesskit(10.0);
    h.run_steps(2);
    assert_eq!(h.state().state.views.cloud.z_exaggeration, 10.0);
    let stretched = h.state().cloud_view().camera().expect("camera");
    assert!(panned.target.z.abs() > 1e-4, "the pan moved the target off the centre's height: {}", panned.target.z);
    assert!((stretched.target.z - 10.0 * panned.target.z).abs() <= 1e-9 * panned.target.z.abs());
    assert_eq!((stretched.target.x, stretched.target.y), (panned.target.x, panned.target.y));

    // With the view focused (it was dragged), arrows orbit and R resets.
    let before = orbited.pitch_rad;
    h.key_press(egui::Key::ArrowDown);
    h.run_steps(2);
    let tilted = h.state().cloud_view().camera().expect("camera");
    assert!(tilted.pitch_rad > before, "the down arrow tilts: {} -> {}", before, tilted.pitch_rad);
    assert_eq!(h.state().state.views.cursor.shift, 0, "the arrows went to the 3D view, not the shift cursor");
    h.key_press(egui::Key::Minus);
    h.run_steps(2);
    assert!(h.state().cloud_view().camera().expect("camera").distance > tilted.distance);
    h.key_press(egui::Key::R);
    h.run_steps(2);
    let reset = h.state().cloud_view().camera().expect("camera");
    assert_eq!((reset.yaw_rad, reset.pitch_rad), ViewPreset::Oblique.angles_rad());
    assert!((reset.target - home.target).norm() < 1e-6, "R frames the cloud about its centre again");
    assert!(reset.distance >= home.distance, "the stretched cloud needs at least as much room");

    // Presets.
    h.get_by_label("Top").click();
    h.run_steps(2);
    let top = h.state().cloud_view().camera().expect("camera");
    assert_eq!((top.yaw_rad, top.pitch_rad), ViewPreset::Top.angles_rad());
}

#[test]
fn without_a_wgpu_renderer_the_view_says_why() {
    let mut h = started();
    h.get_by_label("3D").click();
    h.run_steps(3);
    assert!(shows(&h, "The 3D view needs the wgpu renderer"), "a message instead of a crash");
    assert_eq!(h.state().cloud_view().uploads(), 0);
    h.check_accessibility();
}

#[test]
fn a_picked_point_opens_sections_through_it_in_the_inspect_view() {
    use sheen::analysis::profile::ProfileLine;
    let mut h = started_with_wgpu();
    let (u, v) = (105, 50);
    let index = point_of_pixel(&h, u, v);
    let pos = h.state().cloud_view().screen_position(index).expect("the point is drawn");
    click_at(&mut h, pos);
    let xyz = h.state().result().expect("result").reconstruction.stereo.as_ref().expect("stereo").cloud.xyz[index];
    assert!(h.state().inspect().doc.profiles.is_empty());

    h.get_by_label("Sections here").click();
    h.run_steps(4);
    let lines: Vec<ProfileLine> = h.state().inspect().doc.profiles.iter().map(|p| p.spec.line.clone()).collect();
    assert_eq!(
        lines,
        vec![
            ProfileLine::Horizontal { through_mm: [xyz[0], xyz[1]] },
            ProfileLine::Vertical { through_mm: [xyz[0], xyz[1]] }
        ],
        "a horizontal and a vertical section through the picked point (calibration in mm)"
    );
    assert!(shows(&h, "Profiles (2)"), "the Inspect view is shown with both profiles");
}

/// The 3D view keeps the result its cloud came from only while it is shown:
/// hidden, it lets go of older results so they do not stay in memory (about
/// 0.75 GB each at full size) until the view is opened again.
#[test]
fn a_hidden_3d_view_lets_go_of_older_results() {
    let mut h = started_with_wgpu();
    let first = h.state().result().expect("result");
    let (g1, old) = (first.generation, std::sync::Arc::downgrade(&first.reconstruction));
    h.get_by_label("Height").click();
    h.run_steps(2);
    h.state_mut().push_command(sheen::app::commands::Command::Run);
    let g2 = wait_for_result(&mut h, g1);
    assert!(!h.state().cloud_view().holds_a_result(), "the hidden view holds no result");
    step_until(&mut h, "the first result to be freed", |_| old.upgrade().is_none());
    // Shown again, it packs the newest result.
    h.get_by_label("3D").click();
    wait_for_cloud(&mut h);
    assert!(h.state().cloud_view().holds_a_result());
    assert_eq!(h.state().result().expect("result").generation, g2);
}
