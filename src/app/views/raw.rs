//! Raw fringe images: one phase-shifted image of one set per camera, in grey
//! levels, with the samples at or above the saturation threshold in a
//! warning colour, so the operator sees where the paper's problem starts.

use eframe::egui::{self, ColorImage};
use rayon::prelude::*;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;

use super::{MapSpec, Pane, View, ViewCx, format_period};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RawView {
    /// Paint saturated samples in the warning colour.
    pub mark_saturated: bool,
}

impl Default for RawView {
    fn default() -> Self {
        Self { mark_saturated: true }
    }
}

impl View for RawView {
    fn uses_set(&self) -> bool {
        true
    }

    fn uses_shift(&self) -> bool {
        true
    }

    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        let threshold = cx.params.threshold_for(cx.measurement);
        ui.checkbox(&mut self.mark_saturated, format!("Mark saturated (≥ {threshold} dn)"))
            .on_hover_text("Paint samples at or above the saturation threshold in magenta.");
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let m = cx.measurement;
        let (set, shift) = (cx.cursor.set, cx.cursor.shift);
        let threshold = cx.params.threshold_for(m);
        let level = m.saturation_level.max(1);
        let mark = self.mark_saturated;
        cameras
            .iter()
            .map(|&camera| {
                let title = format!(
                    "{} · set {set} · {} px · shift {}/{}",
                    cx.camera_name(camera),
                    format_period(cx.period_px(set)),
                    shift + 1,
                    m.sets.get(set).map_or(0, |s| s.shifts())
                );
                let Some(stack) = m.cameras.get(camera).and_then(|c| c.stacks.get(set)) else {
                    return Pane::message(camera, title, "This camera has no images for this set.");
                };
                if shift >= stack.shifts {
                    return Pane::message(camera, title, "This set has fewer shifts.");
                }
                let size = [stack.width, stack.height];
                let key = key_of(&("raw", cx.measurement_generation, camera, set, shift, threshold, mark));
                let paint = Box::new(move || {
                    let gray = palette::lut(Colormap::Gray);
                    let scale = 255.0 / f32::from(level);
                    let pixels = (0..stack.pixel_count())
                        .into_par_iter()
                        .map(|p| {
                            let s = stack.sample(shift, p);
                            if mark && s >= threshold {
                                palette::SATURATED
                            } else {
                                gray[((f32::from(s) * scale).round() as usize).min(255)]
                            }
                        })
                        .collect();
                    ColorImage::new(size, pixels)
                });
                let probe = Box::new(move |p: usize| {
                    let s = stack.sample(shift, p);
                    if s >= threshold {
                        format!("I = {s} dn (saturated, ≥ {threshold} dn)")
                    } else {
                        format!("I = {s} dn")
                    }
                });
                let mut legend = Legend::bar(palette::lut(Colormap::Gray), 0.0, f64::from(level), "dn");
                if mark {
                    legend = legend.with_entry(palette::SATURATED, format!("≥ {threshold} dn"));
                }
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer: None })
            })
            .collect()
    }
}
