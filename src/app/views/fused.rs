//! The final absolute phase after HDR fusion (Alg. 3), in radians of the
//! densest enabled period: what stereo matching uses.

use eframe::egui;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;

use super::{
    MapSpec, Pane, RangeSetting, View, ViewCx, colormap_picker, format_period, format_value, paint_continuous, percent,
};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct FusedView {
    pub colormap: Colormap,
    pub range: RangeSetting,
}

impl Default for FusedView {
    fn default() -> Self {
        Self { colormap: Colormap::Turbo, range: RangeSetting::default() }
    }
}

impl FusedView {
    fn auto_range(cx: &ViewCx<'_>) -> Option<(f32, f32)> {
        cx.shown_range("fused", (0.0, 1.0), |c| Some(&cx.camera_phase(c).ok()?.fused.fused_phase_rad))
    }
}

impl View for FusedView {
    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        colormap_picker(ui, "fused colormap", &mut self.colormap);
        self.range.ui(ui, "rad", Self::auto_range(cx));
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let m = cx.measurement;
        cameras
            .iter()
            .map(|&camera| {
                let cp = match cx.camera_phase(camera) {
                    Ok(cp) => cp,
                    Err(message) => return Pane::message(camera, cx.camera_name(camera), message),
                };
                let densest = cp.enabled.last().map_or(f64::NAN, |&s| cx.period_px(s));
                let title =
                    format!("{} · in radians of the {} px period", cx.camera_name(camera), format_period(densest));
                let auto = Self::auto_range(cx);
                let (lo, hi) = self.range.resolve(auto);
                let size = [cp.width, cp.height];
                let map = self.colormap;
                let fused = &cp.fused;
                let key = key_of(&("fused", cx.generation(), camera, map, self.range.key(auto)));
                let paint = Box::new(move || paint_continuous(&fused.fused_phase_rad, size, palette::lut(map), lo, hi));
                let probe = Box::new(move |p: usize| {
                    let phase = fused.fused_phase_rad[p];
                    let source = fused.source_set[p];
                    if phase.is_finite() && source >= 0 {
                        let period = m.sets.get(source as usize).map_or(f64::NAN, |s| s.period_px);
                        format!(
                            "Φ = {} (σ {}, from set {source} · {} px)",
                            format_value(phase, "rad"),
                            format_value(fused.fused_sigma_rad[p], "rad"),
                            format_period(period)
                        )
                    } else {
                        "no valid phase".to_owned()
                    }
                });
                let legend = Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), "rad")
                    .with_entry(palette::INVALID, "no phase");
                let footer = Some(format!("valid {}", percent(fused.valid_count(), cp.width * cp.height)));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}
