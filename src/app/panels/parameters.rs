//! The parameters panel: the paper's knobs (saturation threshold, minimum
//! modulation, method, the fringe sets taking part), the run controls with
//! the engine's progress, and the result's warnings. Any change asks for a
//! debounced re-run; the panel never runs anything itself.

use eframe::egui::{self, RichText};

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::run_data::ResultSet;
use crate::app::state::max_dn;
use crate::app::views::format_period;
use crate::engine::fringe::Measurement;
use crate::engine::pipeline::{Method, Params};
use crate::engine::stereo_match::StereoContinuity;
use crate::engine::unwrap::OrderCheck;

/// What the engine is doing, for the progress display.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EngineStatus {
    pub running: bool,
    /// A run is scheduled (debounce) but not started.
    pub scheduled: bool,
    pub stage: String,
    pub fraction: f32,
    /// The shown result was computed for other parameters than the current ones.
    pub stale: bool,
}

pub fn method_tooltip(method: Method) -> &'static str {
    match method {
        Method::Hdr => {
            "The paper's scheme: generalized phase shifting on unsaturated samples, and sparser sets fill in where the densest is over-saturated."
        }
        Method::Standard => {
            "The traditional N-step formula on all samples, saturated or not (ripples where saturated)."
        }
        Method::Masked => "The N-step formula, dropping every pixel with a saturated sample (holes where saturated).",
        Method::Generalized => "Generalized phase shifting on unsaturated samples, densest set only (no fusion).",
    }
}

/// Draws the panel; pushes [`Command::ParamsChanged`] when a parameter changed.
pub fn show(
    ui: &mut egui::Ui,
    params: &mut Params,
    auto_run: &mut bool,
    measurement: Option<&Measurement>,
    result: Option<&ResultSet>,
    status: &EngineStatus,
    commands: &mut Vec<Command>,
) {
    let before = params.clone();
    ui.heading("Parameters");
    ui.add_space(4.0);

    choice_ui(ui, "Method", &mut params.method, &Method::ALL, Method::name, method_tooltip);
    ui.add_space(6.0);

    if let Some(m) = measurement {
        threshold_ui(ui, params, m);
        ui.add_space(6.0);
        modulation_ui(ui, params, m);
        ui.add_space(6.0);
        uncertainty_ui(ui, params);
        ui.add_space(6.0);
        orders_ui(ui, params);
        ui.add_space(8.0);
        sets_ui(ui, params, m);
    } else {
        ui.weak("Load a measurement to set its parameters.");
    }

    if *params != before {
        commands.push(Command::ParamsChanged);
    }

    ui.add_space(8.0);
    ui.separator();
    ui.checkbox(auto_run, "Re-run on every change")
        .on_hover_text("Run the engine automatically 150 ms after the last parameter change.");
    ui.horizontal(|ui| {
        if ui
            .add_enabled(measurement.is_some(), egui::Button::new("Run"))
            .on_hover_text("Run the engine now with these parameters (F5 or Ctrl+R).")
            .clicked()
        {
            commands.push(Command::Run);
        }
        if ui
            .add_enabled(status.running || status.scheduled, egui::Button::new("Cancel"))
            .on_hover_text("Stop the running engine; the last result stays (Esc).")
            .clicked()
        {
            commands.push(Command::Cancel);
        }
    });
    if status.running {
        ui.add(egui::ProgressBar::new(status.fraction).text(status.stage.clone()));
    } else if status.scheduled {
        ui.weak("Run starting…");
    } else if status.stale {
        ui.colored_label(palette::warning_text(ui.visuals()), "The result is for other parameters: press Run.");
    } else if let Some(r) = result {
        ui.weak(format!("Result #{} is up to date ({} method).", r.generation, r.reconstruction.params.method));
    }

    if let Some(r) = result
        && !r.reconstruction.warnings.is_empty()
    {
        ui.add_space(8.0);
        ui.label(RichText::new(format!("Warnings ({})", r.reconstruction.warnings.len())).strong());
        egui::ScrollArea::vertical().id_salt("warnings").max_height(220.0).show(ui, |ui| {
            for w in &r.reconstruction.warnings {
                ui.colored_label(palette::warning_text(ui.visuals()), format!("• {w}"));
                ui.add_space(2.0);
            }
        });
    }
}

pub fn order_check_tooltip(check: OrderCheck) -> &'static str {
    match check {
        OrderCheck::Evidence => {
            "Orders unambiguous on the pixel's own samples, and ambiguous ones that its neighbours on the same surface or its patch's mean residual confirm (the default)."
        }
        OrderCheck::Strict => {
            "Only orders unambiguous on the pixel's own samples (the rule of Sheen 0.1): fewer pixels on dim faces."
        }
        OrderCheck::Off => {
            "The rounded order without a plausibility test, as the paper: complete, but wrong orders get through on dim faces."
        }
    }
}

fn continuity_tooltip(c: StereoContinuity) -> &'static str {
    match c {
        StereoContinuity::Strict => "Never match or interpolate across a step, hole or occlusion (the default).",
        StereoContinuity::Plain => "Plain matching along the row: the nearest monotone bracket (Eq. 7), as the paper.",
    }
}

/// How fringe orders are accepted and how strictly stereo keeps to continuous surfaces.
fn orders_ui(ui: &mut egui::Ui, params: &mut Params) {
    choice_ui(ui, "Fringe orders", &mut params.order_check, &OrderCheck::ALL, OrderCheck::name, order_check_tooltip);
    ui.add_enabled(
        params.order_check == OrderCheck::Evidence,
        egui::Checkbox::new(&mut params.own_orders_only, "Own-pixel orders only"),
    )
    .on_hover_text("Leave out pixels whose orders needed their neighbours' or their patch's evidence.");
    ui.add_space(4.0);
    choice_ui(
        ui,
        "Stereo continuity",
        &mut params.stereo_continuity,
        &StereoContinuity::ALL,
        StereoContinuity::name,
        continuity_tooltip,
    );
}

/// A labelled combo box over the values of a parameter, each with its
/// tooltip; the label also names the box for screen readers and tests.
fn choice_ui<T: Copy + PartialEq>(
    ui: &mut egui::Ui,
    label: &str,
    value: &mut T,
    all: &[T],
    name: fn(T) -> &'static str,
    tooltip: fn(T) -> &'static str,
) {
    ui.label(label);
    egui::ComboBox::from_id_salt(label)
        .selected_text(name(*value))
        .width(ui.available_width() - 8.0)
        .show_ui(ui, |ui| {
            for &v in all {
                ui.selectable_value(value, v, name(v)).on_hover_text(tooltip(v));
            }
        })
        .response
        .on_hover_text(tooltip(*value))
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, label));
}

fn threshold_ui(ui: &mut egui::Ui, params: &mut Params, m: &Measurement) {
    let top = max_dn(m.bit_depth);
    let mut threshold = params.threshold_for(m);
    let tip =
        "Samples at or above this grey level count as saturated (Alg. 1); default: the camera's saturation level.";
    ui.label(format!("Saturation threshold ({}-bit, 1..{top} dn)", m.bit_depth)).on_hover_text(tip);
    let slider = ui
        .add(egui::Slider::new(&mut threshold, 1..=top).show_value(false).clamping(egui::SliderClamping::Always))
        .on_hover_text(tip);
    slider.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Slider, true, "Saturation threshold"));
    let mut changed = slider.changed();
    ui.horizontal(|ui| {
        let exact = ui.add(egui::DragValue::new(&mut threshold).range(1..=top).suffix(" dn")).on_hover_text(tip);
        exact.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Saturation threshold (exact)"));
        changed |= exact.changed();
        if ui
            .add_enabled(params.saturation_threshold.is_some(), egui::Button::new("Default"))
            .on_hover_text(format!("Back to the saturation level of the data, {} dn.", m.saturation_level))
            .clicked()
        {
            params.saturation_threshold = None;
        }
    });
    if changed {
        params.saturation_threshold = Some(threshold);
    }
}

fn modulation_ui(ui: &mut egui::Ui, params: &mut Params, m: &Measurement) {
    let top = f32::from(max_dn(m.bit_depth)) / 4.0;
    let tip =
        "Pixels whose fitted fringe modulation B is below this many grey levels are invalid (too dark or blurred).";
    ui.label("Minimum modulation").on_hover_text(tip);
    ui.add(
        egui::Slider::new(&mut params.min_modulation_dn, 0.0..=top)
            .logarithmic(true)
            .show_value(false)
            .clamping(egui::SliderClamping::Always),
    )
    .on_hover_text(tip)
    .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Slider, true, "Minimum modulation"));
    let exact = ui
        .add(egui::DragValue::new(&mut params.min_modulation_dn).range(0.0..=top).speed(0.1).suffix(" dn"))
        .on_hover_text(tip);
    exact.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Minimum modulation (exact)"));
}

/// The height-uncertainty limit of the 3D points: pixels that only a sparse
/// set could fill carry their period's larger phase noise into the height, and
/// a flatness peak-to-valley is only as good as its worst point.
fn uncertainty_ui(ui: &mut egui::Ui, params: &mut Params) {
    let tip = "3D points whose height uncertainty (propagated from the phase noise of both cameras) exceeds this many \
               micrometres are left out; untick to keep every point.";
    let mut limited = params.max_sigma_z_um.is_some();
    let mut limit_um = params.max_sigma_z_um.unwrap_or(crate::engine::pipeline::DEFAULT_MAX_SIGMA_Z_UM);
    ui.horizontal(|ui| {
        ui.checkbox(&mut limited, "Maximum height uncertainty").on_hover_text(tip);
    });
    ui.add_enabled_ui(limited, |ui| {
        ui.add(
            egui::Slider::new(&mut limit_um, 0.01..=1000.0)
                .logarithmic(true)
                .show_value(false)
                .clamping(egui::SliderClamping::Always),
        )
        .on_hover_text(tip)
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Slider, true, "Height uncertainty limit"));
        let exact = ui
            .add(egui::DragValue::new(&mut limit_um).range(0.01..=1000.0).speed(0.1).suffix(" µm"))
            .on_hover_text(tip);
        exact.widget_info(|| {
            egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Maximum height uncertainty (exact)")
        });
    });
    params.max_sigma_z_um = limited.then_some(limit_um);
}

fn sets_ui(ui: &mut egui::Ui, params: &mut Params, m: &Measurement) {
    if params.enabled_sets.len() != m.sets.len() {
        params.enabled_sets = vec![true; m.sets.len()];
    }
    ui.label(RichText::new("Fringe sets (sparsest first)").strong()).on_hover_text(
        "Untick a set to see what unwrapping and fusion do without it; the first enabled set must cover the field with one fringe.",
    );
    egui::Grid::new("sets").num_columns(3).striped(true).show(ui, |ui| {
        ui.weak("use");
        ui.weak("period");
        ui.weak("shifts");
        ui.end_row();
        for (s, set) in m.sets.iter().enumerate() {
            let label = format!("set {s}");
            ui.checkbox(&mut params.enabled_sets[s], &label).on_hover_text(format!(
                "Let set {s} (period {} px, {} shifts) take part in unwrapping and fusion.",
                format_period(set.period_px),
                set.shifts()
            ));
            ui.label(format!("{} px", format_period(set.period_px)));
            ui.label(format!("{}", set.shifts()));
            ui.end_row();
        }
    });
    if params.enabled_sets.iter().all(|e| !e) {
        ui.colored_label(palette::error_text(ui.visuals()), "Enable at least one set.");
    }
}
