//! Saturation of one set (Alg. 1): the number of saturated samples per pixel
//! on a discrete scale 0..N, or the over-saturation mask of the pixels left
//! with fewer than 3 usable samples (the paper's Fig. 2(e)-(f)), where no
//! phase can be computed from this set.

use rayon::prelude::*;
use std::cell::RefCell;

use eframe::egui::{self, ColorImage};

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::textures::key_of;
use crate::app::widgets::legend::{Legend, LegendEntry};

use super::{MapSpec, Pane, View, ViewCx, format_period, percent};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum SaturationMode {
    /// Saturated samples per pixel, 0..N.
    #[default]
    Count,
    /// Pixels with fewer than 3 unsaturated samples.
    OverSaturated,
}

/// (result generation, camera, set).
type HistogramKey = (u64, usize, usize);

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SaturationView {
    pub mode: SaturationMode,
    /// Histogram of the counts per (result generation, camera, set): the
    /// legend needs it every frame, the data changes only with a new result.
    #[serde(skip)]
    histograms: RefCell<Vec<(HistogramKey, Vec<usize>)>>,
}

impl SaturationView {
    fn histogram(&self, key: HistogramKey, counts: &[u8], n: usize) -> Vec<usize> {
        let mut memo = self.histograms.borrow_mut();
        if let Some((_, h)) = memo.iter().find(|(k, _)| *k == key) {
            return h.clone();
        }
        let mut h = vec![0usize; n + 1];
        for &c in counts {
            h[usize::from(c).min(n)] += 1;
        }
        memo.retain(|(k, _)| k.0 == key.0);
        memo.push((key, h.clone()));
        h
    }
}

impl View for SaturationView {
    fn uses_set(&self) -> bool {
        true
    }

    fn controls(&mut self, ui: &mut egui::Ui, _cx: &ViewCx<'_>) {
        ui.selectable_value(&mut self.mode, SaturationMode::Count, "Saturated samples per pixel")
            .on_hover_text("How many of the N samples of each pixel reach the threshold (0..N).");
        ui.selectable_value(&mut self.mode, SaturationMode::OverSaturated, "Over-saturated (< 3 usable)")
            .on_hover_text("Pixels with fewer than 3 unsaturated samples: no phase can be fitted from this set.");
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let set = cx.cursor.set;
        let mode = self.mode;
        let generation = cx.generation();
        cameras
            .iter()
            .map(|&camera| {
                let title = format!("{} · set {set} · {} px", cx.camera_name(camera), format_period(cx.period_px(set)));
                let wp = match cx.camera_phase(camera) {
                    Ok(cp) => match cp.sets.get(set) {
                        Some(wp) => wp.as_ref(),
                        None => return Pane::message(camera, title, "The result has no such set."),
                    },
                    Err(message) => return Pane::message(camera, title, message),
                };
                let n = wp.shifts;
                let n_u8 = u8::try_from(n).unwrap_or(u8::MAX);
                let size = [wp.width, wp.height];
                let threshold = cx.result.map_or(0, |r| r.reconstruction.saturation_threshold);
                let key = key_of(&("saturation", generation, camera, set, mode));
                let counts = &wp.saturation_count;
                let probe = Box::new(move |p: usize| {
                    let c = counts[p];
                    let usable = n.saturating_sub(usize::from(c));
                    if usable < 3 {
                        format!("{c} of {n} samples saturated: over-saturated ({usable} usable, 3 needed)")
                    } else {
                        format!("{c} of {n} samples saturated ({usable} usable)")
                    }
                });
                let pixels = wp.stats.pixels;
                let (paint, legend): (Box<dyn FnOnce() -> ColorImage + 'a>, Legend) = match mode {
                    SaturationMode::Count => {
                        let hist = self.histogram((generation, camera, set), counts, n);
                        let entries = (0..=n)
                            .map(|c| LegendEntry {
                                color: palette::count_color(c as u8, n_u8),
                                label: format!("{c}: {}", percent(hist[c], pixels)),
                            })
                            .collect();
                        let paint = Box::new(move || {
                            ColorImage::new(size, counts.par_iter().map(|&c| palette::count_color(c, n_u8)).collect())
                        });
                        (paint, Legend::classes(entries))
                    }
                    SaturationMode::OverSaturated => {
                        let over = wp.stats.over_saturated;
                        let paint = Box::new(move || {
                            let px = counts
                                .par_iter()
                                .map(|&c| {
                                    if n.saturating_sub(usize::from(c)) < 3 {
                                        palette::MASK_TRUE
                                    } else {
                                        palette::MASK_FALSE
                                    }
                                })
                                .collect();
                            ColorImage::new(size, px)
                        });
                        let legend = Legend::classes(vec![
                            LegendEntry {
                                color: palette::MASK_TRUE,
                                label: format!("< 3 usable: {}", percent(over, pixels)),
                            },
                            LegendEntry {
                                color: palette::MASK_FALSE,
                                label: format!("≥ 3 usable: {}", percent(pixels - over, pixels)),
                            },
                        ]);
                        (paint, legend)
                    }
                };
                let footer = Some(format!(
                    "threshold {threshold} dn · partially saturated {} · over-saturated {}",
                    percent(wp.stats.partially_saturated, pixels),
                    percent(wp.stats.over_saturated, pixels)
                ));
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}
