//! Fitted fringe modulation `B` per pixel (grey levels): where it is low the
//! phase is noisy or rejected by the minimum-modulation parameter.

use eframe::egui;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;

use super::{
    MapSpec, Pane, RangeSetting, View, ViewCx, colormap_picker, format_period, format_value, paint_continuous, percent,
};

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ModulationView {
    pub colormap: Colormap,
    pub range: RangeSetting,
}

impl ModulationView {
    fn auto_range(cx: &ViewCx<'_>) -> Option<(f32, f32)> {
        let set = cx.cursor.set;
        cx.shown_range("modulation", (0.0, 0.99), |c| Some(&cx.camera_phase(c).ok()?.sets.get(set)?.modulation_dn))
            .map(|(_, hi)| (0.0, hi))
    }
}

impl View for ModulationView {
    fn uses_set(&self) -> bool {
        true
    }

    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        colormap_picker(ui, "modulation colormap", &mut self.colormap);
        self.range.ui(ui, "dn", Self::auto_range(cx));
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let set = cx.cursor.set;
        let min_modulation =
            cx.result.map_or(cx.params.min_modulation_dn, |r| r.reconstruction.params.min_modulation_dn);
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
                let values = &wp.modulation_dn;
                let map = self.colormap;
                let key = key_of(&("modulation", cx.generation(), camera, set, map, self.range.key(auto)));
                let paint = Box::new(move || paint_continuous(values, size, palette::lut(map), lo, hi));
                let probe = Box::new(move |p: usize| {
                    let b = values[p];
                    if b < min_modulation {
                        format!("B = {} (below the minimum {min_modulation} dn)", format_value(b, "dn"))
                    } else {
                        format!("B = {}", format_value(b, "dn"))
                    }
                });
                let legend = Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), "dn");
                let footer = Some(format!(
                    "below {min_modulation} dn: {} · noise σ {:.2} dn{}",
                    percent(wp.stats.low_modulation, wp.stats.pixels),
                    wp.noise.sigma_dn,
                    if wp.noise.measured { "" } else { " (assumed)" }
                ));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}
