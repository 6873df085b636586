//! Method comparison (the paper's Fig. 5): the same map for two methods side
//! by side, e.g. standard (ripples where saturated) against hdr (complete),
//! with each one's completeness. The second method runs on the worker like
//! every engine run; this view only asks for it.

use eframe::egui;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::run_data::ComparePane;
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;
use crate::engine::pipeline::Method;

use super::{MapSpec, Pane, View, ViewCx, format_value, joint_range, paint_continuous, percent};

/// What the two panes show.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum CompareShow {
    /// The fused phase (always available).
    Phase,
    /// Heights of the 3D points, as in the paper's Fig. 5; falls back to the
    /// phase when the measurement has no calibrated stereo pair.
    #[default]
    Height,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct CompareView {
    pub methods: [Method; 2],
    pub show: CompareShow,
}

impl Default for CompareView {
    fn default() -> Self {
        Self { methods: [Method::Standard, Method::Hdr], show: CompareShow::Height }
    }
}

/// The camera compared: the main one (the cloud is organized on it too).
const CAMERA: usize = 0;

impl View for CompareView {
    fn controls(&mut self, ui: &mut egui::Ui, _cx: &ViewCx<'_>) {
        for (i, side) in ["Left", "Right"].into_iter().enumerate() {
            egui::ComboBox::from_id_salt(("compare method", i))
                .selected_text(format!("{side}: {}", self.methods[i]))
                .show_ui(ui, |ui| {
                    for m in Method::ALL {
                        ui.selectable_value(&mut self.methods[i], m, m.name());
                    }
                })
                .response
                .on_hover_text("Method of this side; all other parameters are those of the current run.")
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, format!("{side} method")));
        }
        ui.selectable_value(&mut self.show, CompareShow::Phase, "Phase maps")
            .on_hover_text("Compare the final phase maps.");
        ui.selectable_value(&mut self.show, CompareShow::Height, "Height maps").on_hover_text(
            "Compare the heights of the 3D points (without a calibrated stereo pair, the phase is shown).",
        );
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, _cameras: &[usize], commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let Some(main) = cx.result else {
            return vec![Pane::message(CAMERA, "Comparison", "No result yet: the engine is running or has not run.")];
        };
        let current = cx.compare.filter(|c| c.key.generation == main.generation && c.key.methods == self.methods);
        let Some(output) = current else {
            commands.push(Command::Compare(self.methods));
            let text =
                if cx.compare_busy { "Computing both methods on the worker…" } else { "Starting the comparison…" };
            return vec![Pane::message(CAMERA, "Comparison", text)];
        };
        // One shared range so equal colours mean equal values on both sides.
        let has_3d = output.panes.iter().all(|p| p.derived.height.is_some());
        let show = if has_3d { self.show } else { CompareShow::Phase };
        let quantiles = (0.01, 0.99);
        let range = cx
            .memo_range(("compare", self.methods, show), || match show {
                CompareShow::Phase => joint_range(
                    output
                        .panes
                        .iter()
                        .filter_map(|p| Some(p.reconstruction.cameras.get(CAMERA)?.fused.fused_phase_rad.as_slice())),
                    quantiles,
                ),
                CompareShow::Height => {
                    joint_range(output.panes.iter().filter_map(|p| p.derived.height.as_deref()), quantiles)
                }
            })
            .unwrap_or((0.0, 1.0));
        output.panes.iter().enumerate().map(|(side, pane)| Self::pane(cx, show, side, pane, range)).collect()
    }
}

impl CompareView {
    fn pane<'a>(cx: &ViewCx<'a>, show: CompareShow, side: usize, pane: &'a ComparePane, range: (f32, f32)) -> Pane<'a> {
        let (lo, hi) = range;
        let camera = CAMERA;
        let Some(cp) = pane.reconstruction.cameras.get(camera) else {
            return Pane::message(camera, pane.method.name(), "The result has no camera.");
        };
        let pixels = cp.width * cp.height;
        let map = Colormap::Turbo;
        let completeness = percent(cp.fused.valid_count(), pixels);
        match show {
            CompareShow::Phase => {
                let phase = &cp.fused.fused_phase_rad;
                let size = [cp.width, cp.height];
                let key = key_of(&("compare phase", cx.generation(), pane.method, side, lo.to_bits(), hi.to_bits()));
                let title = format!("{} · fused phase · complete {completeness}", pane.method);
                let spec = MapSpec {
                    size,
                    key,
                    paint: Box::new(move || paint_continuous(phase, size, palette::lut(map), lo, hi)),
                    probe: Box::new(move |p: usize| format!("Φ = {}", format_value(phase[p], "rad"))),
                    legend: Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), "rad")
                        .with_entry(palette::INVALID, "no phase"),
                    footer: Some(format!("{}: valid phase at {completeness} of the pixels", pane.method)),
                };
                Pane::map(camera, title, spec)
            }
            CompareShow::Height => {
                let (Some(stereo), Some(height)) = (pane.reconstruction.stereo.as_ref(), pane.derived.height.as_ref())
                else {
                    let why = pane.reconstruction.stereo_skipped.as_deref().unwrap_or("no stereo result");
                    return Pane::message(camera, pane.method.name(), format!("No 3D points: {why}."));
                };
                let unit = pane.derived.height_unit.as_str();
                let size = [stereo.cloud.grid_width, stereo.cloud.grid_height];
                let points = percent(stereo.cloud.len(), size[0] * size[1]);
                let key = key_of(&("compare height", cx.generation(), pane.method, side, lo.to_bits(), hi.to_bits()));
                let title = format!("{} · height · points at {points} of the pixels", pane.method);
                let spec = MapSpec {
                    size,
                    key,
                    paint: Box::new(move || paint_continuous(height, size, palette::lut(map), lo, hi)),
                    probe: Box::new(move |p: usize| format!("Z = {}", format_value(height[p], unit))),
                    legend: Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), unit)
                        .with_entry(palette::INVALID, "no point"),
                    footer: Some(format!(
                        "{}: {} points · valid phase at {completeness}",
                        pane.method,
                        stereo.cloud.len()
                    )),
                };
                Pane::map(camera, title, spec)
            }
        }
    }
}
