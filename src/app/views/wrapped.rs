//! Wrapped phase of one set (Alg. 2) on a cyclic colour map, so 0 and 2 pi
//! look alike and fringes read as smooth bands.

use std::f64::consts::TAU;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;

use super::{MapSpec, Pane, View, ViewCx, format_period, format_value, paint_continuous, percent};

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct WrappedView {}

impl View for WrappedView {
    fn uses_set(&self) -> bool {
        true
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
                let size = [wp.width, wp.height];
                let phase = &wp.wrapped_phase_rad;
                let key = key_of(&("wrapped", cx.generation(), camera, set));
                let paint =
                    Box::new(move || paint_continuous(phase, size, palette::lut(Colormap::Twilight), 0.0, TAU as f32));
                let probe = Box::new(move |p: usize| format!("φ = {}", format_value(phase[p], "rad")));
                let legend = Legend::bar(palette::lut(Colormap::Twilight), 0.0, TAU, "rad")
                    .with_entry(palette::INVALID, "no phase");
                let footer = Some(format!("valid {}", percent(wp.stats.valid, wp.stats.pixels)));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}
