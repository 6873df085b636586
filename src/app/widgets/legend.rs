//! Colour bars with ticks and units, and class legends (swatch + label with
//! the class's share), drawn beside every colour-mapped view.

use eframe::egui::{self, Color32, Rect, Stroke, StrokeKind, Vec2, pos2, vec2};

use crate::app::palette::LUT_SIZE;

/// A continuous colour scale.
#[derive(Clone)]
pub struct ColorBar {
    pub lut: &'static [Color32; LUT_SIZE],
    pub lo: f64,
    pub hi: f64,
    /// Unit of the values, e.g. "rad", "dn", "µm".
    pub unit: String,
}

/// One class of a categorical or discrete map.
#[derive(Clone, Debug, PartialEq)]
pub struct LegendEntry {
    pub color: Color32,
    pub label: String,
}

/// What explains a map's colours.
#[derive(Clone, Default)]
pub struct Legend {
    pub bar: Option<ColorBar>,
    pub entries: Vec<LegendEntry>,
}

impl Legend {
    pub fn bar(lut: &'static [Color32; LUT_SIZE], lo: f64, hi: f64, unit: &str) -> Self {
        Self { bar: Some(ColorBar { lut, lo, hi, unit: unit.to_owned() }), entries: Vec::new() }
    }

    pub fn classes(entries: Vec<LegendEntry>) -> Self {
        Self { bar: None, entries }
    }

    pub fn with_entry(mut self, color: Color32, label: impl Into<String>) -> Self {
        self.entries.push(LegendEntry { color, label: label.into() });
        self
    }
}

/// Width the legend needs next to a map.
pub fn width(ui: &egui::Ui, legend: &Legend) -> f32 {
    let font = egui::FontId::proportional(11.0);
    let text_w = |t: &str| ui.fonts_mut(|f| f.layout_no_wrap(t.to_owned(), font.clone(), Color32::WHITE).size().x);
    let mut w: f32 = 0.0;
    if let Some(bar) = &legend.bar {
        let ticks = nice_ticks(bar.lo, bar.hi, 6);
        let widest = ticks.iter().map(|&t| text_w(&format_tick(t, &ticks))).fold(0.0, f32::max);
        w = w.max(BAR_W + 6.0 + widest).max(text_w(&bar.unit));
    }
    for e in &legend.entries {
        w = w.max(SWATCH + 6.0 + text_w(&e.label));
    }
    (w + 6.0).min(240.0)
}

const BAR_W: f32 = 14.0;
const SWATCH: f32 = 11.0;

/// Draws the legend into a `width x height` area.
pub fn show(ui: &mut egui::Ui, legend: &Legend, size: Vec2) {
    let (rect, response) = ui.allocate_exact_size(size, egui::Sense::hover());
    // Painted text is invisible to screen readers: the legend's node carries it.
    let spoken: Vec<&str> =
        legend.bar.iter().map(|b| b.unit.as_str()).chain(legend.entries.iter().map(|e| e.label.as_str())).collect();
    response
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Label, true, format!("legend: {}", spoken.join("; "))));
    let painter = ui.painter_at(rect);
    let text_color = ui.visuals().text_color();
    let font = egui::FontId::proportional(11.0);
    let line_h = 15.0;
    let entries_h = legend.entries.len() as f32 * line_h;
    let mut y = rect.top();
    if let Some(bar) = &legend.bar {
        painter.text(pos2(rect.left(), y), egui::Align2::LEFT_TOP, &bar.unit, font.clone(), text_color);
        y += line_h;
        let bottom = (rect.bottom() - entries_h - if entries_h > 0.0 { 8.0 } else { 6.0 }).max(y + 20.0);
        let bar_rect = Rect::from_min_max(pos2(rect.left(), y + 4.0), pos2(rect.left() + BAR_W, bottom));
        // Top = high values, as on every height colour bar.
        let stripes = 64;
        for i in 0..stripes {
            let t0 = i as f32 / stripes as f32;
            let t1 = (i + 1) as f32 / stripes as f32;
            let lut_index = (((1.0 - (t0 + t1) / 2.0) * (LUT_SIZE - 1) as f32).round() as usize).min(LUT_SIZE - 1);
            let r = Rect::from_min_max(
                pos2(bar_rect.left(), bar_rect.top() + t0 * bar_rect.height()),
                pos2(bar_rect.right(), bar_rect.top() + t1 * bar_rect.height() + 0.5),
            );
            painter.rect_filled(r, 0.0, bar.lut[lut_index]);
        }
        painter.rect_stroke(bar_rect, 0.0, Stroke::new(1.0, ui.visuals().weak_text_color()), StrokeKind::Outside);
        let ticks = nice_ticks(bar.lo, bar.hi, ((bar_rect.height() / 28.0) as usize).clamp(2, 8));
        let span = bar.hi - bar.lo;
        for &t in &ticks {
            let f = if span > 0.0 { ((t - bar.lo) / span) as f32 } else { 0.5 };
            let ty = bar_rect.bottom() - f * bar_rect.height();
            painter.line_segment([pos2(bar_rect.right(), ty), pos2(bar_rect.right() + 4.0, ty)], (1.0, text_color));
            painter.text(
                pos2(bar_rect.right() + 6.0, ty),
                egui::Align2::LEFT_CENTER,
                format_tick(t, &ticks),
                font.clone(),
                text_color,
            );
        }
        y = bar_rect.bottom() + 8.0;
    }
    for e in &legend.entries {
        let sw = Rect::from_min_size(pos2(rect.left(), y + 2.0), vec2(SWATCH, SWATCH));
        painter.rect_filled(sw, 2.0, e.color);
        painter.rect_stroke(sw, 2.0, Stroke::new(1.0, ui.visuals().weak_text_color()), StrokeKind::Outside);
        painter.text(pos2(sw.right() + 6.0, y), egui::Align2::LEFT_TOP, &e.label, font.clone(), text_color);
        y += line_h;
    }
}

/// Round tick values covering `[lo, hi]` (1, 2, 5 times a power of ten apart),
/// at most about `max_count` of them, all inside the range.
pub fn nice_ticks(lo: f64, hi: f64, max_count: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    if hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / max_count.max(2) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// A tick label with just enough decimals to tell neighbouring ticks apart.
pub fn format_tick(value: f64, ticks: &[f64]) -> String {
    let step = if ticks.len() >= 2 { (ticks[1] - ticks[0]).abs() } else { value.abs().max(1.0) };
    let decimals = if step >= 1.0 { 0 } else { (-step.log10()).ceil().clamp(0.0, 9.0) as usize };
    let v = if value.abs() < step * 1e-9 { 0.0 } else { value };
    format!("{v:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_inside() {
        assert_eq!(nice_ticks(0.0, 6.5, 6), vec![0.0, 2.0, 4.0, 6.0]);
        let t = nice_ticks(-12.5, 37.0, 5);
        assert_eq!(t, vec![-10.0, 0.0, 10.0, 20.0, 30.0]);
        let t = nice_ticks(0.0012, 0.0049, 4);
        assert!(t.iter().all(|&v| (0.0012..=0.0049).contains(&v)));
        assert!(t.len() >= 2);
        assert_eq!(nice_ticks(3.0, 3.0, 5), vec![3.0]);
        assert!(nice_ticks(f64::NAN, 1.0, 5).is_empty());
    }

    #[test]
    fn labels_have_the_decimals_the_step_needs() {
        let t = nice_ticks(0.0, 0.05, 5);
        let labels: Vec<String> = t.iter().map(|&v| format_tick(v, &t)).collect();
        assert_eq!(labels, vec!["0.00", "0.01", "0.02", "0.03", "0.04", "0.05"]);
        let t = nice_ticks(100.0, 900.0, 4);
        assert_eq!(format_tick(t[0], &t), "200");
    }
}
