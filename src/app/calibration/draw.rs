//! Drawing of the calibration window: the set and model bar, the pose table
//! with the use checkboxes, the per-pose RMS chart, the warnings, saving,
//! and the selected pose's two images with numbered detections and
//! magnified residual vectors. Drawing only pushes [`Action`]s.

use std::path::PathBuf;

use eframe::egui::{self, Color32, Pos2, RichText, Stroke, Vec2};
use egui_plot::{Bar, BarChart, Legend, Plot};

use super::work::{DisplayImage, numbered};
use super::{CalibrationView, DEFAULT_MAGNIFICATION};
use crate::app::palette;
use crate::app::widgets::busy_line;
use crate::engine::calibration::CAMERA_NAMES;
use crate::engine::calibration::model::DistortionModel;
use crate::engine::calibration::report::PoseReport;
use crate::engine::fringe::Measurement;

/// What the operator asked for this frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    Load(PathBuf),
    OpenDialog,
    SaveDialog,
    Save(PathBuf),
    /// Use (true) or leave out (false) a set pose.
    UsePose(usize, bool),
    Distortion(DistortionModel),
    /// Use the solved calibration for the open fringe set.
    Apply,
    Cancel,
}

/// Height of the per-pose RMS chart.
const CHART_HEIGHT: f32 = 150.0;
const LEFT_COLOUR: Color32 = Color32::from_rgb(80, 160, 255);
const RIGHT_COLOUR: Color32 = Color32::from_rgb(255, 150, 60);
const INLIER_COLOUR: Color32 = Color32::from_rgb(70, 230, 110);
const OUTLIER_COLOUR: Color32 = Color32::from_rgb(255, 70, 70);
const RESIDUAL_COLOUR: Color32 = Color32::from_rgb(255, 225, 40);

fn distortion_tooltip(model: DistortionModel) -> &'static str {
    match model {
        DistortionModel::None => "Affine cameras alone, no lens distortion.",
        DistortionModel::K1 => "One radial term k1 (the usual choice for telecentric lenses).",
        DistortionModel::Radial => "Radial terms k1 and k2.",
        DistortionModel::Full => "k1, k2 and the decentering terms p1, p2.",
    }
}

pub fn window(ui: &mut egui::Ui, view: &mut CalibrationView, fringe: Option<&Measurement>, actions: &mut Vec<Action>) {
    toolbar(ui, view, actions);
    status(ui, view, actions);
    ui.separator();
    if view.set.is_none() {
        ui.add_space(20.0);
        ui.vertical_centered(|ui| {
            ui.heading("No calibration set");
            ui.label(
                "Type the path of a calibration set (calibration_set.json beside its target images) above and \
                 press Load, or Browse for it.",
            );
            ui.weak("A simulated one: sheen simulate --scene calibration-target --out DIR");
        });
        return;
    }
    let height = ui.available_height();
    ui.horizontal_top(|ui| {
        ui.allocate_ui_with_layout(Vec2::new(420.0, height), egui::Layout::top_down(egui::Align::Min), |ui| {
            ui.set_width(420.0);
            egui::ScrollArea::vertical().id_salt("calibration side").auto_shrink([false, false]).show(ui, |ui| {
                side(ui, view, fringe, actions);
            });
        });
        ui.separator();
        ui.vertical(|ui| pose_view(ui, view));
    });
}

fn toolbar(ui: &mut egui::Ui, view: &mut CalibrationView, actions: &mut Vec<Action>) {
    ui.horizontal_wrapped(|ui| {
        ui.label("Calibration set");
        let edit = ui.add(
            egui::TextEdit::singleline(&mut view.set_path)
                .hint_text("/path/to/calibration_set.json")
                .desired_width(360.0),
        );
        edit.widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Calibration set path"));
        let enter = edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
        let path = view.set_path.trim().to_owned();
        if (ui.button("Load").on_hover_text("Detect the target in every pose and solve.").clicked() || enter)
            && !path.is_empty()
        {
            actions.push(Action::Load(PathBuf::from(path)));
        }
        if ui.button("Browse…").on_hover_text("Choose the calibration set in a file dialog.").clicked() {
            actions.push(Action::OpenDialog);
        }
        ui.separator();
        ui.label("Distortion");
        let mut model = view.distortion;
        egui::ComboBox::from_id_salt("calibration distortion")
            .selected_text(model.name())
            .show_ui(ui, |ui| {
                for m in DistortionModel::ALL {
                    ui.selectable_value(&mut model, m, m.name()).on_hover_text(distortion_tooltip(m));
                }
            })
            .response
            .on_hover_text("Lens distortion terms to fit; the rig is solved again on a change.")
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, "Distortion model"));
        if model != view.distortion {
            actions.push(Action::Distortion(model));
        }
        ui.separator();
        ui.add(
            egui::Slider::new(&mut view.magnification, 1.0..=20000.0)
                .logarithmic(true)
                .max_decimals(0)
                .text("× residuals"),
        )
        .on_hover_text(format!(
            "Residual vectors (detected minus reprojected) are drawn this many times their length (set for each new \
             set so that a typical residual is a quarter of the point spacing; {DEFAULT_MAGNIFICATION} before that)."
        ));
    });
}

fn status(ui: &mut egui::Ui, view: &CalibrationView, actions: &mut Vec<Action>) {
    let running =
        view.detect_job.as_ref().map(|j| j.progress()).or_else(|| view.solve_job.as_ref().map(|j| j.progress()));
    if let Some((stage, fraction)) = running {
        ui.horizontal(|ui| {
            let detecting = view.detect_job.is_some();
            ui.label(if detecting { "Detecting" } else { "Solving" });
            ui.add(egui::ProgressBar::new(fraction).text(stage).desired_width(260.0));
            // Named for what it stops: the Parameters panel has an engine Cancel too.
            let cancel = if detecting { "Cancel detection" } else { "Cancel solution" };
            if ui.button(cancel).on_hover_text("Stop; the previous solution stays.").clicked() {
                actions.push(Action::Cancel);
            }
        });
    }
    if view.save_job.is_some() || view.apply_job.is_some() {
        busy_line(ui, if view.save_job.is_some() { "Saving…" } else { "Applying the calibration…" });
    }
    if let Some(e) = &view.error {
        ui.label(RichText::new(e).color(palette::error_text(ui.visuals())));
    }
    if let Some(n) = &view.notice {
        ui.label(n);
    }
}

fn side(ui: &mut egui::Ui, view: &mut CalibrationView, fringe: Option<&Measurement>, actions: &mut Vec<Action>) {
    let Some(set) = view.set.clone() else {
        return;
    };
    let t = &set.set.target;
    ui.label(RichText::new(set.path.display().to_string()).strong());
    ui.label(format!(
        "{} x {} {} at {} mm pitch · {} poses",
        t.rows,
        t.cols,
        t.kind.point_noun(),
        t.pitch_mm,
        set.set.poses.len()
    ));
    ui.add_space(4.0);
    summary(ui, view);
    ui.add_space(6.0);
    save_ui(ui, view, fringe, actions);
    ui.add_space(6.0);
    pose_table(ui, view, actions);
    if let Some(solved) = &view.solved
        && !solved.report.warnings.is_empty()
    {
        ui.add_space(6.0);
        ui.label(RichText::new("Warnings").strong());
        for w in &solved.report.warnings {
            ui.label(RichText::new(&w.message).color(palette::warning_text(ui.visuals())));
        }
    }
    if let Some(solved) = &view.solved {
        egui::CollapsingHeader::new("Parameters and their standard deviations").id_salt("calibration parameters").show(
            ui,
            |ui| {
                egui::Grid::new("calibration parameter grid").striped(true).num_columns(3).show(ui, |ui| {
                    for p in solved.report.parameters.iter().filter(|p| !p.name.starts_with("pose")) {
                        ui.monospace(&p.name);
                        ui.monospace(format!("{:.6e}", p.value));
                        ui.monospace(format!("± {:.2e}", p.std));
                        ui.end_row();
                    }
                });
            },
        );
    }
}

fn summary(ui: &mut egui::Ui, view: &CalibrationView) {
    let Some(solved) = &view.solved else {
        ui.weak("Not solved yet.");
        return;
    };
    if view.is_stale() {
        ui.label(
            RichText::new("Solving again for the new choice; the figures below are for the previous one.")
                .color(palette::warning_text(ui.visuals())),
        );
    }
    let r = &solved.report;
    let [l, rr] = r.rms_per_camera();
    egui::Grid::new("calibration summary").num_columns(2).show(ui, |ui| {
        ui.label("Poses used");
        let set = view.set.as_deref();
        let skipped = set.map_or(0, |s| s.skipped.len());
        ui.label(format!(
            "{} of {} ({} skipped, {} left out) · world frame: {}",
            r.poses.len(),
            set.map_or(0, |s| s.set.poses.len()),
            skipped,
            solved.excluded.len(),
            r.poses.first().map_or("-", |p| p.name.as_str())
        ));
        ui.end_row();
        ui.label("RMS left / right");
        ui.label(RichText::new(format!("{l:.4} / {rr:.4} px")).strong());
        ui.end_row();
        ui.label("Outliers");
        ui.label(format!("{} (threshold {:.3} px)", r.outliers, r.outlier_threshold_px));
        ui.end_row();
        ui.label("Stereo angle");
        ui.label(format!("{:.2}°", r.stereo_angle_deg));
        ui.end_row();
        ui.label("Tilt spread");
        ui.label(format!("{:.1}°", r.tilt_spread_deg));
        ui.end_row();
        if solved.distortion != DistortionModel::None {
            let k1 = |c: usize| r.cameras.get(c).and_then(|c| c.model.distortion).map_or(0.0, |d| d.k1);
            ui.label("k1 left / right");
            ui.label(format!("{:.3e} / {:.3e}", k1(0), k1(1)));
            ui.end_row();
        }
        ui.label("Scale left / right");
        let ppm = |c: usize| r.cameras.get(c).map_or(0.0, |c| c.pixels_per_mm);
        ui.label(format!("{:.2} / {:.2} px/mm", ppm(0), ppm(1)));
        ui.end_row();
    });
}

/// The report of set pose `index` in the current solution, if it was used.
fn pose_report(view: &CalibrationView, index: usize) -> Option<&PoseReport> {
    view.solved.as_ref()?.report.poses.iter().find(|p| p.index == index)
}

fn pose_table(ui: &mut egui::Ui, view: &mut CalibrationView, actions: &mut Vec<Action>) {
    let Some(set) = view.set.clone() else {
        return;
    };
    ui.label(RichText::new("Poses").strong())
        .on_hover_text("Untick a pose to leave it out; the rig is solved again. Click a name to show its images.");
    egui::Grid::new("calibration poses").striped(true).num_columns(7).spacing([10.0, 2.0]).show(ui, |ui| {
        for h in ["use", "pose", "left pts", "right pts", "left RMS", "right RMS", "tilt"] {
            ui.label(RichText::new(h).small().strong());
        }
        ui.end_row();
        for (k, _) in set.set.poses.iter().enumerate() {
            let name = format!("pose {k}");
            if let Some(skipped) = set.skipped(k) {
                ui.add_enabled(false, egui::Checkbox::without_text(&mut false)).widget_info(|| {
                    egui::WidgetInfo::selected(egui::Role::CheckBox, false, false, format!("use {name}"))
                });
                if ui.selectable_label(view.selected_pose == k, &name).clicked() {
                    view.selected_pose = k;
                }
                ui.label(RichText::new("skipped").color(palette::warning_text(ui.visuals())))
                    .on_hover_text(&skipped.reason);
                for _ in 0..4 {
                    ui.label("");
                }
                ui.end_row();
                continue;
            }
            let mut used = !view.excluded.contains(&k);
            let was = used;
            ui.checkbox(&mut used, "")
                .on_hover_text("Use this pose in the solution")
                .widget_info(|| egui::WidgetInfo::selected(egui::Role::CheckBox, true, used, format!("use {name}")));
            if used != was {
                actions.push(Action::UsePose(k, used));
            }
            if ui.selectable_label(view.selected_pose == k, &name).clicked() {
                view.selected_pose = k;
            }
            let det = set.detection(k);
            let found =
                |c: usize| det.map_or(0, |d| if c == 0 { d.left.points_px.len() } else { d.right.points_px.len() });
            let report = pose_report(view, k);
            for c in 0..2 {
                let outliers = report.and_then(|r| r.cameras.get(c)).map_or(0, |v| v.outliers);
                let text = if outliers > 0 { format!("{} ({outliers} out)", found(c)) } else { found(c).to_string() };
                ui.label(text);
            }
            for c in 0..2 {
                match report.and_then(|r| r.cameras.get(c)) {
                    Some(v) => ui.monospace(format!("{:.4}", v.rms_reprojection_px)),
                    None => ui.weak("-"),
                };
            }
            match report {
                Some(r) => ui.label(format!("{:.1}°", r.tilt_deg)),
                None => ui.weak("left out"),
            };
            ui.end_row();
        }
    });
}

fn rms_chart(ui: &mut egui::Ui, view: &CalibrationView) {
    let Some(solved) = &view.solved else {
        return;
    };
    let bars = |c: usize, offset: f64| -> Vec<Bar> {
        solved
            .report
            .poses
            .iter()
            .filter_map(|p| {
                let v = p.cameras.get(c)?;
                Some(Bar::new(p.index as f64 + offset, v.rms_reprojection_px).width(0.38).name(&p.name))
            })
            .collect()
    };
    let n = view.set.as_ref().map_or(1, |s| s.set.poses.len());
    ui.label(RichText::new("RMS reprojection error per pose (px)").strong());
    Plot::new("calibration rms chart")
        .height((ui.available_height() - 24.0).max(CHART_HEIGHT))
        .allow_scroll(false)
        .allow_zoom(false)
        .allow_drag(false)
        .include_x(-0.5)
        .include_x(n as f64 - 0.5)
        .include_y(0.0)
        .x_axis_label("pose")
        .legend(Legend::default())
        .show(ui, |plot| {
            plot.bar_chart(BarChart::new(CAMERA_NAMES[0], bars(0, -0.2)).color(LEFT_COLOUR));
            plot.bar_chart(BarChart::new(CAMERA_NAMES[1], bars(1, 0.2)).color(RIGHT_COLOUR));
        })
        .response
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "RMS per pose chart"));
}

fn save_ui(ui: &mut egui::Ui, view: &mut CalibrationView, fringe: Option<&Measurement>, actions: &mut Vec<Action>) {
    let ready = view.solved.is_some() && !view.is_stale();
    ui.horizontal(|ui| {
        if ui
            .add_enabled(ready, egui::Button::new("Save calibration…"))
            .on_hover_text("Write calibration.json (atomically) where you choose.")
            .clicked()
        {
            actions.push(Action::SaveDialog);
        }
    });
    ui.horizontal(|ui| {
        let edit = ui.add(egui::TextEdit::singleline(&mut view.save_path).desired_width(300.0));
        edit.widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Calibration output path"));
        let path = view.save_path.trim().to_owned();
        if ui.add_enabled(ready && !path.is_empty(), egui::Button::new("Save")).clicked() {
            actions.push(Action::Save(PathBuf::from(path)));
        }
    });
    let (can_apply, why) = match (fringe, &view.solved) {
        (None, _) => (false, "No fringe set is open.".to_string()),
        (_, None) => (false, "Nothing solved yet.".to_string()),
        (Some(m), Some(s)) => {
            let c = &s.calibration;
            if m.cameras.len() < 2 {
                (false, format!("{} has one camera; stereo needs two.", m.label))
            } else if m.cameras[0].width != c.left.width || m.cameras[0].height != c.left.height {
                (
                    false,
                    format!(
                        "The calibration is for {}x{} px images; {} has {}x{} px.",
                        c.left.width, c.left.height, m.label, m.cameras[0].width, m.cameras[0].height
                    ),
                )
            } else {
                (ready, format!("Measure {} again with this calibration.", m.label))
            }
        }
    };
    let button = ui.add_enabled(can_apply, egui::Button::new("Use for the open fringe set"));
    let button = if can_apply { button.on_hover_text(&why) } else { button.on_disabled_hover_text(&why) };
    if button.clicked() {
        actions.push(Action::Apply);
    }
    if !can_apply {
        ui.weak(why);
    }
}

fn pose_view(ui: &mut egui::Ui, view: &mut CalibrationView) {
    let Some(set) = view.set.clone() else {
        return;
    };
    let n = set.set.poses.len();
    if n == 0 {
        return;
    }
    let k = view.selected_pose.min(n - 1);
    ui.horizontal(|ui| {
        if ui.add_enabled(k > 0, egui::Button::new("Previous")).clicked() {
            view.selected_pose = k - 1;
        }
        if ui.add_enabled(k + 1 < n, egui::Button::new("Next")).clicked() {
            view.selected_pose = k + 1;
        }
        let mut title = format!("pose {k}");
        if let Some(r) = pose_report(view, k) {
            title.push_str(&format!(
                " · tilt {:.1}° against pose {}",
                r.tilt_deg,
                view.solved.as_ref().and_then(|s| s.report.poses.first()).map_or(0, |p| p.index)
            ));
        } else if set.skipped(k).is_some() {
            title.push_str(" · skipped");
        } else if view.excluded.contains(&k) {
            title.push_str(" · left out of the solution");
        }
        ui.label(RichText::new(title).strong());
    });
    if let Some(s) = set.skipped(k) {
        ui.label(RichText::new(&s.reason).color(palette::warning_text(ui.visuals())));
    }
    ui.horizontal(|ui| {
        ui.label("Show");
        for (value, text) in [(None, "both cameras"), (Some(0), "left"), (Some(1), "right")] {
            ui.selectable_value(&mut view.shown_camera, value, text);
        }
        ui.separator();
        ui.checkbox(&mut view.zoom_to_target, "Zoom to the target").on_hover_text(
            "Show the part of each image around the detected points, larger. Click an image to show that camera alone.",
        );
    });
    let k = view.selected_pose.min(n - 1);
    let cameras: Vec<usize> = match view.shown_camera {
        Some(c) => vec![c],
        None => vec![0, 1],
    };
    // The part of each image shown, in pixel-edge coordinates.
    let crops: Vec<egui::Rect> = cameras
        .iter()
        .map(|&c| {
            let img = &set.images[k][c];
            let full = egui::Rect::from_min_size(Pos2::ZERO, Vec2::new(img.width as f32, img.height as f32));
            let det = set.detection(k).map(|d| if c == 0 { &d.left } else { &d.right });
            match det.filter(|_| view.zoom_to_target) {
                Some(d) => target_crop(&d.points_px, d.feature_size_px, full),
                None => full,
            }
        })
        .collect();
    // Side by side or stacked, whichever shows the images larger; the RMS chart below.
    let chart_height = if view.solved.is_some() { CHART_HEIGHT + 30.0 } else { 0.0 };
    let avail = ui.available_size() - Vec2::new(8.0, 4.0 + chart_height);
    let caption = 22.0;
    let (cw, ch) = crops.iter().fold((1f32, 1f32), |(w, h), r| (w.max(r.width()), h.max(r.height())));
    let m = cameras.len() as f32;
    let side_scale = ((avail.x - 8.0 * (m - 1.0)) / m / cw).min((avail.y - caption) / ch);
    let stacked_scale = (avail.x / cw).min((avail.y - m * caption - 8.0 * (m - 1.0)) / m / ch);
    let side_by_side = side_scale >= stacked_scale;
    let scale = side_scale.max(stacked_scale).max(0.05);
    let draw = |ui: &mut egui::Ui, view: &mut CalibrationView, c: usize, crop: egui::Rect| {
        let img = &set.images[k][c];
        ui.vertical(|ui| {
            let det = set.detection(k).map(|d| if c == 0 { &d.left } else { &d.right });
            let report = pose_report(view, k).and_then(|r| r.cameras.get(c)).cloned();
            let mut caption = format!("{} · {}", CAMERA_NAMES[c], set.set.poses[k].image(c));
            if let Some(r) = &report {
                caption
                    .push_str(&format!(" · RMS {:.4} px · max {:.4} px", r.rms_reprojection_px, r.max_reprojection_px));
            }
            ui.label(caption);
            let texture = view
                .textures
                .entry((k, c))
                .or_insert_with(|| {
                    ui.ctx().load_texture(
                        format!("calibration pose {k} camera {c}"),
                        egui::ColorImage::from_gray([img.width, img.height], &img.gray),
                        egui::TextureOptions::LINEAR,
                    )
                })
                .id();
            let overlay = Overlay {
                points_px: det.map(|d| d.points_px.as_slice()),
                residuals_px: report.as_ref().map(|r| r.residuals_px.as_slice()),
                outlier: report.as_ref().map(|r| r.outlier.as_slice()),
                cols: set.set.target.cols,
                feature_px: det.map_or(6.0, |d| d.feature_size_px),
                magnification: view.magnification,
            };
            let label = format!("pose {k} · {} image", CAMERA_NAMES[c]);
            if pose_image(ui, texture, img, crop, crop.size() * scale, &overlay, label) {
                // A click shows this camera alone, larger; another click both again.
                view.shown_camera = if view.shown_camera.is_some() { None } else { Some(c) };
            }
        });
    };
    if side_by_side {
        ui.horizontal_top(|ui| {
            for (&c, &crop) in cameras.iter().zip(&crops) {
                draw(ui, view, c, crop);
            }
        });
    } else {
        for (&c, &crop) in cameras.iter().zip(&crops) {
            draw(ui, view, c, crop);
        }
    }
    ui.add_space(4.0);
    rms_chart(ui, view);
}

/// The detected points' bounding box with a margin of a few features,
/// within the image (`full`).
fn target_crop(points_px: &[[f64; 2]], feature_px: f64, full: egui::Rect) -> egui::Rect {
    if points_px.is_empty() {
        return full;
    }
    let (mut lo, mut hi) = (Pos2::new(f32::MAX, f32::MAX), Pos2::new(f32::MIN, f32::MIN));
    for p in points_px {
        let q = Pos2::new(p[0] as f32 + 0.5, p[1] as f32 + 0.5);
        lo = lo.min(q);
        hi = hi.max(q);
    }
    let margin = (2.0 * feature_px as f32).max(0.04 * (hi - lo).length()).max(8.0);
    egui::Rect::from_min_max(lo, hi).expand(margin).intersect(full)
}

/// What is drawn over one image.
struct Overlay<'a> {
    points_px: Option<&'a [[f64; 2]]>,
    residuals_px: Option<&'a [[f64; 2]]>,
    outlier: Option<&'a [bool]>,
    cols: usize,
    feature_px: f64,
    magnification: f32,
}

/// Draws the part `crop` (pixel-edge coordinates) of `img` at `size` with the overlay.
fn pose_image(
    ui: &mut egui::Ui,
    texture: egui::TextureId,
    img: &DisplayImage,
    crop: egui::Rect,
    size: Vec2,
    overlay: &Overlay<'_>,
    label: String,
) -> bool {
    let (rect, response) = ui.allocate_exact_size(size, egui::Sense::click());
    let clicked = response.clicked();
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, &label));
    let painter = ui.painter_at(rect);
    let (w, h) = (img.width.max(1) as f32, img.height.max(1) as f32);
    let uv =
        egui::Rect::from_min_max(Pos2::new(crop.min.x / w, crop.min.y / h), Pos2::new(crop.max.x / w, crop.max.y / h));
    painter.image(texture, rect, uv, Color32::WHITE);
    let scale = size.x / crop.width().max(1.0);
    // Pixel (u, v) is the centre of the image's pixel u, v, which spans u - 0.5 to u + 0.5.
    let to_screen = |p: [f64; 2]| {
        rect.min + Vec2::new((p[0] as f32 + 0.5 - crop.min.x) * scale, (p[1] as f32 + 0.5 - crop.min.y) * scale)
    };
    let Some(points) = overlay.points_px else {
        return clicked;
    };
    let cols = overlay.cols.max(1);
    let spacing = if points.len() > 1 {
        let (a, b) = (to_screen(points[0]), to_screen(points[1]));
        a.distance(b)
    } else {
        30.0
    };
    let radius = ((overlay.feature_px as f32) * 0.5 * scale).clamp(2.5, 14.0);
    let font = egui::FontId::proportional(if spacing > 40.0 { 12.0 } else { 10.0 });
    for (n, &p) in points.iter().enumerate() {
        let at = to_screen(p);
        let outlier = overlay.outlier.and_then(|o| o.get(n)).copied().unwrap_or(false);
        let colour = if outlier { OUTLIER_COLOUR } else { INLIER_COLOUR };
        painter.circle_stroke(at, radius, Stroke::new(if n == 0 { 2.5 } else { 1.2 }, colour));
        if let Some(r) = overlay.residuals_px.and_then(|r| r.get(n)) {
            let v = Vec2::new(r[0] as f32, r[1] as f32) * overlay.magnification * scale;
            if v.length() > 0.5 {
                painter.arrow(at, v, Stroke::new(1.6, RESIDUAL_COLOUR));
            }
        }
        let (row, col) = (n / cols, n % cols);
        if numbered(row, col, spacing) {
            let pos = at + Vec2::new(radius + 1.0, -radius - 1.0);
            let text = n.to_string();
            painter.text(pos + Vec2::new(1.0, 1.0), egui::Align2::LEFT_BOTTOM, &text, font.clone(), Color32::BLACK);
            painter.text(pos, egui::Align2::LEFT_BOTTOM, &text, font.clone(), Color32::WHITE);
        }
    }
    // Hover: the nearest point's number, position and residual.
    if let Some(hover) = response.hover_pos() {
        let nearest = points
            .iter()
            .enumerate()
            .map(|(n, &p)| (n, to_screen(p).distance(hover)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .filter(|(_, d)| *d < spacing.max(12.0) * 0.6);
        if let Some((n, _)) = nearest {
            let p = points[n];
            let mut text =
                format!("point {n} (row {}, column {})\ndetected at ({:.3}, {:.3}) px", n / cols, n % cols, p[0], p[1]);
            if let Some(r) = overlay.residuals_px.and_then(|r| r.get(n)) {
                text.push_str(&format!("\nresidual ({:+.4}, {:+.4}) px, |e| = {:.4} px", r[0], r[1], r[0].hypot(r[1])));
            }
            if overlay.outlier.and_then(|o| o.get(n)).copied().unwrap_or(false) {
                text.push_str("\nset aside as an outlier");
            }
            response.on_hover_text_at_pointer(text);
        }
    }
    clicked
}
