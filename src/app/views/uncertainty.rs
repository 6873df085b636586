//! Predicted standard deviation of the wrapped phase per pixel: the noise the
//! unwrapping's order check and the period-ratio warning reason about.

use eframe::egui;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;

use super::{
    MapSpec, Pane, RangeSetting, View, ViewCx, colormap_picker, format_period, format_value, paint_continuous,
};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct UncertaintyView {
    pub colormap: Colormap,
    pub range: RangeSetting,
}

impl Default for UncertaintyView {
    fn default() -> Self {
        Self { colormap: Colormap::Turbo, range: RangeSetting::default() }
    }
}

impl UncertaintyView {
    fn auto_range(cx: &ViewCx<'_>) -> Option<(f32, f32)> {
        let set = cx.cursor.set;
        cx.shown_range("uncertainty", (0.0, 0.99), |c| Some(&cx.camera_phase(c).ok()?.sets.get(set)?.phase_sigma_rad))
            .map(|(_, hi)| (0.0, hi))
    }
}

impl View for UncertaintyView {
    fn uses_set(&self) -> bool {
        true
    }

    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        colormap_picker(ui, "uncertainty colormap", &mut self.colormap);
        self.range.ui(ui, "rad", Self::auto_range(cx));
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let set = cx.cursor.set;
        cameras
            .iter()
            .map(|&camera| {
                let title = format!("{} · set {set} · {} px", cx.camera_name(camera), format_period(cx.period_px(set)));
                let wp = match cx.camera_phase(camera).map(|cp| cp.sets.get(set)) {
                    Ok(Some(wp)) => wp.as_ref(),
                    Ok(None) => return Pane::message(camera, title, "The result has no such set."),
                    Err(message) => return Pane::message(camera, title, message),
                };
                let auto = Self::auto_range(cx);
                let (lo, hi) = self.range.resolve(auto);
                let size = [wp.width, wp.height];
                let values = &wp.phase_sigma_rad;
                let map = self.colormap;
                let key = key_of(&("uncertainty", cx.generation(), camera, set, map, self.range.key(auto)));
                let paint = Box::new(move || paint_continuous(values, size, palette::lut(map), lo, hi));
                let probe = Box::new(move |p: usize| format!("σφ = {}", format_value(values[p], "rad")));
                let legend = Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), "rad")
                    .with_entry(palette::INVALID, "no phase");
                let median = crate::engine::pipeline::median_finite(values);
                let footer = Some(format!(
                    "median σφ {} · camera noise σ {:.2} dn",
                    median.map_or_else(|| "–".to_owned(), |m| format_value(m as f32, "rad")),
                    wp.noise.sigma_dn
                ));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}
