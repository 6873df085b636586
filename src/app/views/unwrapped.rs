//! Absolute phase of one set after hierarchical unwrapping (Alg. 3, first
//! loop), in radians of that set's own period; blank where its fringe order
//! was not found or failed the order check.

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
pub struct UnwrappedView {
    pub colormap: Colormap,
    pub range: RangeSetting,
}

impl Default for UnwrappedView {
    fn default() -> Self {
        Self { colormap: Colormap::Turbo, range: RangeSetting::default() }
    }
}

impl UnwrappedView {
    fn auto_range(cx: &ViewCx<'_>) -> Option<(f32, f32)> {
        let set = cx.cursor.set;
        cx.shown_range("unwrapped", (0.0, 1.0), |c| cx.camera_phase(c).ok()?.unwrapped_phase(set))
    }
}

impl View for UnwrappedView {
    fn uses_set(&self) -> bool {
        true
    }

    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        colormap_picker(ui, "unwrapped colormap", &mut self.colormap);
        self.range.ui(ui, "rad", Self::auto_range(cx));
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let set = cx.cursor.set;
        cameras
            .iter()
            .map(|&camera| {
                let title = format!("{} · set {set} · {} px", cx.camera_name(camera), format_period(cx.period_px(set)));
                let cp = match cx.camera_phase(camera) {
                    Ok(cp) => cp,
                    Err(message) => return Pane::message(camera, title, message),
                };
                let Some(k) = cp.enabled.iter().position(|&s| s == set) else {
                    return Pane::message(
                        camera,
                        title,
                        "This set is disabled: it takes no part in unwrapping or fusion. Enable it in the parameters.",
                    );
                };
                let phase = &cp.unwrapped.unwrapped_phase_rad[k];
                let auto = Self::auto_range(cx);
                let (lo, hi) = self.range.resolve(auto);
                let size = [cp.width, cp.height];
                let map = self.colormap;
                let flags = &cp.unwrapped.order_flags;
                let key = key_of(&("unwrapped", cx.generation(), camera, set, map, self.range.key(auto)));
                let paint = Box::new(move || paint_continuous(phase, size, palette::lut(map), lo, hi));
                let probe = Box::new(move |p: usize| {
                    if flags[p] & (1 << k) != 0 {
                        "Φ: fringe order failed its check".to_owned()
                    } else {
                        format!("Φ = {}", format_value(phase[p], "rad"))
                    }
                });
                let legend = Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), "rad")
                    .with_entry(palette::INVALID, "not unwrapped");
                let pixels = cp.width * cp.height;
                let footer = Some(format!(
                    "unwrapped {} · order check failed {}",
                    percent(cp.unwrapped.unwrapped_count[k], pixels),
                    percent(cp.unwrapped.order_failures[k], pixels)
                ));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}
