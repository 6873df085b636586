//! The fusion source map (Alg. 3): which fringe set supplied each pixel's
//! phase, pixels no set could recover, and pixels refused because two sets'
//! fringe orders disagreed; the legend gives each class's share.

use eframe::egui::ColorImage;

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::textures::key_of;
use crate::app::widgets::legend::{Legend, LegendEntry};
use crate::engine::fusion::{SOURCE_NONE, SOURCE_ORDER_FAILED};

use super::{MapSpec, Pane, View, ViewCx, format_period, percent};

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SourcesView {}

impl View for SourcesView {
    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let m = cx.measurement;
        cameras
            .iter()
            .map(|&camera| {
                let title = format!("{} · fusion source per pixel", cx.camera_name(camera));
                let cp = match cx.camera_phase(camera) {
                    Ok(cp) => cp,
                    Err(message) => return Pane::message(camera, title, message),
                };
                let size = [cp.width, cp.height];
                let pixels = cp.width * cp.height;
                let fused = &cp.fused;
                let key = key_of(&("sources", cx.generation(), camera));
                let paint = Box::new(move || {
                    ColorImage::new(size, fused.source_set.iter().map(|&s| palette::source_color(s)).collect())
                });
                let probe = Box::new(move |p: usize| match fused.source_set[p] {
                    SOURCE_NONE => "no set could recover this pixel".to_owned(),
                    SOURCE_ORDER_FAILED => "refused: two sets' fringe orders disagree".to_owned(),
                    s => {
                        let period = m.sets.get(s as usize).map_or(f64::NAN, |set| set.period_px);
                        format!("phase from set {s} · {} px", format_period(period))
                    }
                });
                let mut entries: Vec<LegendEntry> = cp
                    .enabled
                    .iter()
                    .zip(&fused.source_counts)
                    .map(|(&set, &count)| LegendEntry {
                        color: palette::source_color(set as i8),
                        label: format!(
                            "set {set} · {} px: {}",
                            format_period(cx.period_px(set)),
                            percent(count, pixels)
                        ),
                    })
                    .collect();
                entries.push(LegendEntry {
                    color: palette::source_color(SOURCE_NONE),
                    label: format!("none: {}", percent(fused.none_count, pixels)),
                });
                entries.push(LegendEntry {
                    color: palette::source_color(SOURCE_ORDER_FAILED),
                    label: format!("order failed: {}", percent(fused.order_failed_count, pixels)),
                });
                let footer = Some(format!("valid {}", percent(fused.valid_count(), pixels)));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend: Legend::classes(entries), footer })
            })
            .collect()
    }
}
