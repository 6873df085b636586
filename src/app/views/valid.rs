//! The valid mask: pixels with a final absolute phase (white) and without.

use eframe::egui::ColorImage;
use rayon::prelude::*;

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::textures::key_of;
use crate::app::widgets::legend::{Legend, LegendEntry};

use super::{MapSpec, Pane, View, ViewCx, percent};

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ValidView {}

impl View for ValidView {
    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        cameras
            .iter()
            .map(|&camera| {
                let title = format!("{} · valid final phase", cx.camera_name(camera));
                let cp = match cx.camera_phase(camera) {
                    Ok(cp) => cp,
                    Err(message) => return Pane::message(camera, title, message),
                };
                let size = [cp.width, cp.height];
                let pixels = cp.width * cp.height;
                let phase = &cp.fused.fused_phase_rad;
                let key = key_of(&("valid", cx.generation(), camera));
                let paint = Box::new(move || {
                    let px =
                        phase.par_iter().map(|p| if p.is_nan() { palette::MASK_FALSE } else { palette::MASK_TRUE });
                    ColorImage::new(size, px.collect())
                });
                let probe =
                    Box::new(move |p: usize| if phase[p].is_nan() { "invalid".to_owned() } else { "valid".to_owned() });
                let valid = cp.fused.valid_count();
                let legend = Legend::classes(vec![
                    LegendEntry { color: palette::MASK_TRUE, label: format!("valid: {}", percent(valid, pixels)) },
                    LegendEntry {
                        color: palette::MASK_FALSE,
                        label: format!("invalid: {}", percent(pixels - valid, pixels)),
                    },
                ]);
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer: None })
            })
            .collect()
    }
}
