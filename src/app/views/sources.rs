//! The fusion source map (Alg. 3): which fringe set supplied each pixel's
//! phase, pixels no set could recover, and pixels refused because two sets'
//! fringe orders disagreed; the legend gives each class's share. Pixels
//! whose orders needed more than their own samples (confirmed by
//! their neighbours, or by their patch against the sparser set) are marked
//! in a lighter or darker tint of their set's colour.

use eframe::egui::{self, Color32, ColorImage};

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::textures::key_of;
use crate::app::widgets::legend::{Legend, LegendEntry};
use crate::engine::fusion::{SOURCE_NONE, SOURCE_ORDER_FAILED};
use crate::engine::unwrap::{EVIDENCE_NEIGHBOURS, EVIDENCE_PATCH};

use super::{MapSpec, Pane, View, ViewCx, format_period, percent};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SourcesView {
    /// Tint the pixels whose fringe orders were confirmed by evidence beyond
    /// their own samples.
    pub mark_confirmed: bool,
}

impl Default for SourcesView {
    fn default() -> Self {
        Self { mark_confirmed: true }
    }
}

/// The colour of a pixel of the source map: its set's colour, lighter where
/// neighbours confirmed its orders and darker where its patch did.
pub fn source_pixel_color(source: i8, order_evidence: u8, mark_confirmed: bool) -> Color32 {
    let base = palette::source_color(source);
    if !mark_confirmed || source < 0 {
        return base;
    }
    match order_evidence {
        EVIDENCE_NEIGHBOURS => base.lerp_to_gamma(Color32::WHITE, 0.55),
        EVIDENCE_PATCH => base.lerp_to_gamma(Color32::BLACK, 0.5),
        _ => base,
    }
}

impl View for SourcesView {
    fn controls(&mut self, ui: &mut egui::Ui, _cx: &ViewCx<'_>) {
        ui.checkbox(&mut self.mark_confirmed, "Mark confirmed orders").on_hover_text(
            "Tint the pixels whose fringe orders were ambiguous on their own samples and were confirmed by their \
             neighbours on the same surface (lighter) or by their patch against the sparser set (darker).",
        );
    }

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
                let mark = self.mark_confirmed;
                let key = key_of(&("sources", cx.generation(), camera, mark));
                let paint = Box::new(move || {
                    let colors = fused
                        .source_set
                        .iter()
                        .zip(&fused.order_evidence)
                        .map(|(&s, &e)| source_pixel_color(s, e, mark))
                        .collect();
                    ColorImage::new(size, colors)
                });
                let probe = Box::new(move |p: usize| match fused.source_set[p] {
                    SOURCE_NONE => "no set could recover this pixel".to_owned(),
                    SOURCE_ORDER_FAILED => "refused: two sets' fringe orders disagree".to_owned(),
                    s => {
                        let period = m.sets.get(s as usize).map_or(f64::NAN, |set| set.period_px);
                        let how = match fused.order_evidence[p] {
                            EVIDENCE_NEIGHBOURS => " · order confirmed by its neighbours",
                            EVIDENCE_PATCH => " · order confirmed by its patch",
                            _ => "",
                        };
                        format!("phase from set {s} · {} px{how}", format_period(period))
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
                if mark {
                    let tint = |evidence| source_pixel_color(cp.enabled.last().map_or(0, |&s| s as i8), evidence, true);
                    entries.push(LegendEntry {
                        color: tint(EVIDENCE_NEIGHBOURS),
                        label: format!("confirmed by neighbours: {}", percent(fused.confirmed_counts[0], pixels)),
                    });
                    entries.push(LegendEntry {
                        color: tint(EVIDENCE_PATCH),
                        label: format!("confirmed by patch: {}", percent(fused.confirmed_counts[1], pixels)),
                    });
                }
                let footer = Some(format!("valid {}", percent(fused.valid_count(), pixels)));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend: Legend::classes(entries), footer })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confirmed_orders_are_tinted_only_when_asked_and_only_on_valid_pixels() {
        let base = palette::source_color(2);
        assert_eq!(source_pixel_color(2, 0, true), base);
        let lighter = source_pixel_color(2, EVIDENCE_NEIGHBOURS, true);
        let darker = source_pixel_color(2, EVIDENCE_PATCH, true);
        let luma = |c: Color32| u32::from(c.r()) + u32::from(c.g()) + u32::from(c.b());
        assert!(luma(lighter) > luma(base) && luma(darker) < luma(base));
        assert_eq!(source_pixel_color(2, EVIDENCE_NEIGHBOURS, false), base);
        assert_eq!(source_pixel_color(SOURCE_NONE, EVIDENCE_NEIGHBOURS, true), palette::source_color(SOURCE_NONE));
    }
}
