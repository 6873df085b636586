//! Colour maps for Sheen's maps, shared by written PNGs and the GUI: lookup
//! tables of perceptual maps (viridis, turbo), a cyclic map for wrapped phase
//! (twilight: `0` and `2 pi` get the same colour, so phase wraps show no false
//! edge), a discrete map for saturation counts (Alg. 1's `sat_map`) and a
//! categorical palette for the fused source-set map (Alg. 3), plus rendering
//! to `image::RgbaImage` and PNG files with a labelled colour bar.
//!
//! No GUI types here: colours are plain `[u8; 4]` sRGB + alpha. Invalid
//! values (NaN) are fully transparent, so a view can show its own background
//! (the app a checkerboard, a PNG viewer its page) instead of a colour that
//! could be mistaken for data.

mod font;
mod tables;

use std::f32::consts::TAU;
use std::path::Path;

use image::{ImageEncoder, Rgba, RgbaImage};
use rayon::prelude::*;

pub use font::{draw_text, text_width_px};

use super::atomic::write_atomic;
use super::error::IoError;

/// Colour of a pixel without a value (NaN): transparent.
pub const INVALID_RGBA: [u8; 4] = [0, 0, 0, 0];
/// Source map: no set could supply the pixel (`engine::fusion::SOURCE_NONE`).
pub const SOURCE_NONE_RGBA: [u8; 4] = [64, 64, 64, 255];
/// Source map: rejected by the fringe-order check (`engine::fusion::SOURCE_ORDER_FAILED`);
/// an alarm colour that no set colour resembles.
pub const SOURCE_ORDER_FAILED_RGBA: [u8; 4] = [255, 0, 255, 255];
/// Saturation counts: no saturated sample.
pub const SATURATION_NONE_RGBA: [u8; 4] = [28, 28, 36, 255];

/// Set colours of the source map, by manifest set index (Okabe-Ito's
/// colour-blind-safe palette first, then Tableau's); repeats after 12 sets.
const SET_PALETTE: [[u8; 3]; 12] = [
    [0, 114, 178],
    [230, 159, 0],
    [0, 158, 115],
    [86, 180, 233],
    [240, 228, 66],
    [213, 94, 0],
    [204, 121, 167],
    [140, 86, 75],
    [188, 189, 34],
    [23, 190, 207],
    [148, 103, 189],
    [127, 127, 127],
];

/// The colour maps Sheen offers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Colormap {
    /// Sequential, perceptually uniform: modulation, uncertainty, intensity.
    #[default]
    Viridis,
    /// High-contrast rainbow with even lightness steps: unwrapped phase, height.
    Turbo,
    /// Cyclic: wrapped phase; a range of one period maps once around the circle.
    Twilight,
    /// Linear grey levels: raw fringe images and texture.
    Gray,
    /// Discrete counts `0..=N` with `N = range.max` (the set's shift count):
    /// 0 dark, counts leaving >= 3 usable samples yellow to orange, counts
    /// leaving fewer than 3 (over-saturated, Alg. 1's `ind`) red to purple.
    SaturationCount,
    /// Categorical: manifest set index `0..`, with distinct colours for
    /// "no set" (-1) and "fringe order failed" (-2); `range` is not used.
    SourceSet,
}

impl Colormap {
    pub const ALL: [Colormap; 6] = [
        Colormap::Viridis,
        Colormap::Turbo,
        Colormap::Twilight,
        Colormap::Gray,
        Colormap::SaturationCount,
        Colormap::SourceSet,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::Turbo => "turbo",
            Colormap::Twilight => "twilight (cyclic)",
            Colormap::Gray => "gray",
            Colormap::SaturationCount => "saturation counts",
            Colormap::SourceSet => "source sets",
        }
    }

    /// Whether values are categories (drawn as blocks in the colour bar).
    pub fn is_discrete(self) -> bool {
        matches!(self, Colormap::SaturationCount | Colormap::SourceSet)
    }

    /// The 256-entry table of a continuous map (`None` for gray and the
    /// discrete maps), for a GUI that wants to upload it as a texture.
    pub fn table(self) -> Option<&'static [[u8; 3]; 256]> {
        match self {
            Colormap::Viridis => Some(&tables::VIRIDIS),
            Colormap::Turbo => Some(&tables::TURBO),
            Colormap::Twilight => Some(&tables::TWILIGHT),
            _ => None,
        }
    }

    /// Colour of `value` when `range` spans the map; NaN is [`INVALID_RGBA`].
    /// Continuous maps clamp values outside the range, except the cyclic
    /// one, which wraps them (a phase of `2 pi + x` looks like `x`).
    pub fn rgba(self, value: f32, range: ValueRange) -> [u8; 4] {
        if value.is_nan() {
            return INVALID_RGBA;
        }
        match self {
            Colormap::Viridis | Colormap::Turbo | Colormap::Gray => {
                let t = range.fraction(value).clamp(0.0, 1.0);
                let i = (t * 255.0).round() as usize;
                match self.table() {
                    Some(table) => opaque(table[i]),
                    None => [i as u8, i as u8, i as u8, 255],
                }
            }
            Colormap::Twilight => {
                let t = range.fraction(value).rem_euclid(1.0);
                let i = ((t * 256.0) as usize).min(255);
                opaque(tables::TWILIGHT[i])
            }
            Colormap::SaturationCount => saturation_rgba(value, range.max),
            Colormap::SourceSet => source_rgba(value),
        }
    }
}

fn opaque(rgb: [u8; 3]) -> [u8; 4] {
    [rgb[0], rgb[1], rgb[2], 255]
}

fn lerp_rgb(a: [u8; 3], b: [u8; 3], t: f32) -> [u8; 4] {
    let m = |x: u8, y: u8| (f32::from(x) + (f32::from(y) - f32::from(x)) * t).round() as u8;
    [m(a[0], b[0]), m(a[1], b[1]), m(a[2], b[2]), 255]
}

/// At most this many categories are drawn (the engine allows 32 shifts, 16 sets).
const MAX_CATEGORIES: i32 = 64;

fn saturation_rgba(value: f32, shifts: f32) -> [u8; 4] {
    let n = if shifts.is_finite() { (shifts.round() as i32).clamp(0, MAX_CATEGORIES) } else { 0 };
    let c = (value.round() as i32).clamp(0, n);
    if c == 0 {
        return SATURATION_NONE_RGBA;
    }
    // Fewer than 3 unsaturated samples from this count on (Alg. 1: sat > N - 3).
    let over_from = (n - 2).max(1);
    if c < over_from {
        let t = if over_from > 2 { (c - 1) as f32 / (over_from - 2) as f32 } else { 0.0 };
        lerp_rgb([250, 224, 90], [235, 120, 20], t)
    } else {
        let t = if n > over_from { (c - over_from) as f32 / (n - over_from) as f32 } else { 0.0 };
        lerp_rgb([215, 25, 28], [120, 0, 100], t)
    }
}

fn source_rgba(value: f32) -> [u8; 4] {
    let v = value.round() as i32;
    match v {
        -2 => SOURCE_ORDER_FAILED_RGBA,
        v if v < 0 => SOURCE_NONE_RGBA,
        v => set_rgba(v as usize),
    }
}

/// Colour of manifest set `set` in the source map (and in plots by set).
pub fn set_rgba(set: usize) -> [u8; 4] {
    opaque(SET_PALETTE[set % SET_PALETTE.len()])
}

/// The values a colour map spans: `min` maps to the first colour, `max` to the last.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ValueRange {
    pub min: f32,
    pub max: f32,
}

impl ValueRange {
    /// One period of wrapped phase, `[0, 2 pi)`.
    pub const PHASE_RAD: ValueRange = ValueRange { min: 0.0, max: TAU };

    pub fn new(min: f32, max: f32) -> Self {
        Self { min, max }
    }

    /// Position of `value` in the range (0 at `min`, 1 at `max`); 0.5 for an
    /// empty or invalid range, so a constant map shows the middle colour.
    pub fn fraction(&self, value: f32) -> f32 {
        let span = self.max - self.min;
        if span > 0.0 && span.is_finite() { (value - self.min) / span } else { 0.5 }
    }

    /// Smallest and largest finite value, `None` when there is none.
    pub fn of_finite(map: &[f32]) -> Option<Self> {
        let (lo, hi) = map
            .par_iter()
            .filter(|v| v.is_finite())
            .fold(|| (f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)))
            .reduce(|| (f32::INFINITY, f32::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
        (lo <= hi).then_some(Self { min: lo, max: hi })
    }

    /// The `lo` and `hi` quantiles (fractions in [0, 1]) of the finite values,
    /// from a subsample of at most ~100 000 pixels: a display range that a few
    /// outliers cannot stretch. `None` when there is no finite value.
    pub fn quantiles(map: &[f32], lo: f64, hi: f64) -> Option<Self> {
        let step = (map.len() / 100_000).max(1);
        let mut v: Vec<f32> = map.iter().step_by(step).copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_unstable_by(f32::total_cmp);
        let at = |q: f64| v[((q.clamp(0.0, 1.0) * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        Some(Self { min: at(lo.min(hi)), max: at(hi.max(lo)) })
    }
}

/// Renders a row-major `width` x `height` map with `colormap` over `range`.
/// Pixels beyond the end of a short `map` render as invalid.
pub fn render_map_png(map: &[f32], width: usize, height: usize, colormap: Colormap, range: ValueRange) -> RgbaImage {
    let mut img = RgbaImage::new(width as u32, height as u32);
    if width == 0 {
        return img;
    }
    let raw: &mut [u8] = &mut img;
    raw.par_chunks_mut(width * 4).enumerate().for_each(|(row, out)| {
        for (col, px) in out.chunks_exact_mut(4).enumerate() {
            let value = map.get(row * width + col).copied().unwrap_or(f32::NAN);
            px.copy_from_slice(&colormap.rgba(value, range));
        }
    });
    img
}

/// What the colour bar beside a written map says.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColorBar {
    /// Unit of the values, drawn above the bar ("rad", "DN", "um"); may be empty.
    pub unit: String,
    /// Names of discrete values (e.g. source set 0 -> "912 px"); values not
    /// listed get a default label (the number, "none", "failed").
    pub categories: Vec<(i32, String)>,
}

impl ColorBar {
    pub fn unit(unit: &str) -> Self {
        Self { unit: unit.to_string(), categories: Vec::new() }
    }

    fn label_for(&self, value: i32, default: String) -> String {
        self.categories.iter().find(|(v, _)| *v == value).map_or(default, |(_, l)| l.clone())
    }
}

const PANEL_RGBA: [u8; 4] = [255, 255, 255, 255];
const INK_RGBA: [u8; 4] = [20, 20, 20, 255];

/// One entry of the colour bar's legend.
enum BarEntry {
    /// A tick at fraction `t` of the continuous bar (0 = bottom).
    Tick { t: f32, label: String },
    /// A block of one colour (discrete maps), listed top to bottom.
    Block { rgba: [u8; 4], label: String },
}

fn bar_entries(colormap: Colormap, range: ValueRange, bar: &ColorBar) -> Vec<BarEntry> {
    match colormap {
        Colormap::SaturationCount => {
            let n = if range.max.is_finite() { (range.max.round() as i32).clamp(0, MAX_CATEGORIES) } else { 0 };
            (0..=n)
                .rev()
                .map(|c| BarEntry::Block {
                    rgba: saturation_rgba(c as f32, n as f32),
                    label: bar.label_for(c, c.to_string()),
                })
                .collect()
        }
        Colormap::SourceSet => {
            let k = if range.max.is_finite() { (range.max.round() as i32).clamp(0, MAX_CATEGORIES) } else { 0 };
            (-2..=k)
                .rev()
                .map(|v| {
                    let default = match v {
                        -2 => "failed".to_string(),
                        -1 => "none".to_string(),
                        v => format!("set {v}"),
                    };
                    BarEntry::Block { rgba: source_rgba(v as f32), label: bar.label_for(v, default) }
                })
                .collect()
        }
        _ => {
            let (lo, hi) = (f64::from(range.min), f64::from(range.max));
            nice_ticks(lo, hi, 6)
                .into_iter()
                .map(|(value, label)| BarEntry::Tick { t: range.fraction(value as f32), label })
                .collect()
        }
    }
}

/// Round tick values (1, 2 or 5 times a power of ten apart) inside
/// `[lo, hi]`, about `target` of them, with labels of just enough decimals.
fn nice_ticks(lo: f64, hi: f64, target: usize) -> Vec<(f64, String)> {
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    let span = hi - lo;
    if span <= 0.0 {
        return vec![(lo, format_tick(lo, 0.0))];
    }
    let raw = span / target.max(1) as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    // The candidate nearest to the raw step on a log scale.
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * magnitude)
        .min_by(|a, b| (a / raw).ln().abs().total_cmp(&(b / raw).ln().abs()))
        .unwrap_or(magnitude);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|i| i as f64 * step).map(|v| (v, format_tick(v, step))).collect()
}

fn format_tick(value: f64, step: f64) -> String {
    let value = if value.abs() < step * 1e-9 { 0.0 } else { value };
    if value != 0.0 && (value.abs() >= 1e6 || (step > 0.0 && step < 1e-4)) {
        return format!("{value:.2e}");
    }
    if step <= 0.0 {
        // A lone value (constant map): its shortest exact form.
        return format!("{}", value as f32);
    }
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    format!("{value:.decimals$}")
}

/// The map rendered as [`render_map_png`] with a colour bar panel to its
/// right: the bar (or blocks for discrete maps), tick labels and the unit.
/// The font scales with the map height so labels stay readable on
/// full-resolution maps.
pub fn render_with_color_bar(
    map: &[f32],
    width: usize,
    height: usize,
    colormap: Colormap,
    range: ValueRange,
    bar: &ColorBar,
) -> RgbaImage {
    let map_img = render_map_png(map, width, height, colormap, range);
    let scale = (height as u32 / 200).clamp(1, 8);
    let glyph_h = font::GLYPH_HEIGHT * scale;
    let margin = 4 * scale;
    let bar_w = 12 * scale;
    let tick_len = 3 * scale;
    let entries = bar_entries(colormap, range, bar);
    let label_w = entries
        .iter()
        .map(|e| match e {
            BarEntry::Tick { label, .. } | BarEntry::Block { label, .. } => text_width_px(label, scale),
        })
        .max()
        .unwrap_or(0);
    let unit_h = if bar.unit.is_empty() { 0 } else { glyph_h + 2 * margin };
    let blocks = entries.iter().filter(|e| matches!(e, BarEntry::Block { .. })).count() as u32;
    // Discrete blocks need room for a label each; a continuous bar some length.
    let bar_min_h = if blocks > 0 { blocks * (glyph_h + 2 * scale) } else { 8 * glyph_h };
    let canvas_h = (height as u32).max(unit_h + bar_min_h + 2 * margin + glyph_h);
    let panel_w =
        (2 * margin + bar_w + tick_len + 2 * scale + label_w).max(2 * margin + text_width_px(&bar.unit, scale));
    let mut img = RgbaImage::from_pixel(width as u32 + panel_w, canvas_h, Rgba(PANEL_RGBA));
    image::imageops::replace(&mut img, &map_img, 0, 0);
    if canvas_h > height as u32 {
        // Below a short map: transparent like invalid pixels, not panel white.
        for y in height as u32..canvas_h {
            for x in 0..width as u32 {
                img.put_pixel(x, y, Rgba(INVALID_RGBA));
            }
        }
    }

    let x0 = width as u32 + margin;
    if !bar.unit.is_empty() {
        draw_text(&mut img, i64::from(x0), i64::from(margin), &bar.unit, scale, INK_RGBA);
    }
    let top = margin + unit_h + glyph_h / 2;
    let bottom = canvas_h - margin - glyph_h / 2; // exclusive
    let bar_h = bottom.saturating_sub(top).max(1);
    let label_x = i64::from(x0 + bar_w + tick_len + 2 * scale);
    if blocks > 0 {
        // Label every k-th block when blocks are lower than the font.
        let block_h = bar_h as f32 / blocks as f32;
        let every = ((glyph_h + scale) as f32 / block_h).ceil().max(1.0) as usize;
        for (i, entry) in entries.iter().enumerate() {
            let BarEntry::Block { rgba, label } = entry else { continue };
            let y_a = top + (i as f32 * block_h).round() as u32;
            let y_b = top + ((i + 1) as f32 * block_h).round() as u32;
            fill_rect(&mut img, x0, y_a, bar_w, y_b.saturating_sub(y_a), *rgba);
            if i % every == 0 {
                let yc = (y_a + y_b) / 2;
                fill_rect(&mut img, x0 + bar_w, yc, tick_len, scale, INK_RGBA);
                draw_text(&mut img, label_x, i64::from(yc) - i64::from(glyph_h / 2), label, scale, INK_RGBA);
            }
        }
    } else {
        for y in top..bottom {
            let t = if bar_h > 1 { (bottom - 1 - y) as f32 / (bar_h - 1) as f32 } else { 0.5 };
            let value = range.min + t * (range.max - range.min);
            fill_rect(&mut img, x0, y, bar_w, 1, colormap.rgba(value, range));
        }
        for entry in &entries {
            let BarEntry::Tick { t, label } = entry else { continue };
            let y = bottom - 1 - (t.clamp(0.0, 1.0) * (bar_h - 1) as f32).round() as u32;
            fill_rect(&mut img, x0 + bar_w, y.saturating_sub(scale / 2), tick_len, scale, INK_RGBA);
            draw_text(&mut img, label_x, i64::from(y) - i64::from(glyph_h / 2), label, scale, INK_RGBA);
        }
    }
    frame_rect(&mut img, x0, top, bar_w, bar_h, INK_RGBA);
    img
}

fn fill_rect(img: &mut RgbaImage, x: u32, y: u32, w: u32, h: u32, rgba: [u8; 4]) {
    for yy in y..(y + h).min(img.height()) {
        for xx in x..(x + w).min(img.width()) {
            img.put_pixel(xx, yy, Rgba(rgba));
        }
    }
}

fn frame_rect(img: &mut RgbaImage, x: u32, y: u32, w: u32, h: u32, rgba: [u8; 4]) {
    fill_rect(img, x.saturating_sub(1), y.saturating_sub(1), w + 2, 1, rgba);
    fill_rect(img, x.saturating_sub(1), y + h, w + 2, 1, rgba);
    fill_rect(img, x.saturating_sub(1), y, 1, h, rgba);
    fill_rect(img, x + w, y, 1, h, rgba);
}

/// Half the width of a colour range symmetric about zero that holds
/// `percent` % of the finite values' magnitudes (for differences, where
/// zero must be the middle colour and a few outliers must not flatten the
/// rest); `None` without finite values.
pub fn symmetric_half_range(values: &[f32], percent: usize) -> Option<f32> {
    let mut magnitudes: Vec<f32> = values.iter().filter(|v| v.is_finite()).map(|v| v.abs()).collect();
    if magnitudes.is_empty() {
        return None;
    }
    let k = (magnitudes.len() * percent / 100).min(magnitudes.len() - 1);
    let (_, half, _) = magnitudes.select_nth_unstable_by(k, f32::total_cmp);
    Some(*half)
}

/// Writes `img` as an 8-bit RGBA PNG, atomically.
pub fn write_png(path: &Path, img: &RgbaImage) -> Result<(), IoError> {
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgba8)
            .map_err(std::io::Error::other)
    })
}

/// Renders a map with its colour bar ([`render_with_color_bar`]) and writes it as PNG.
pub fn write_map_png(
    path: &Path,
    map: &[f32],
    width: usize,
    height: usize,
    colormap: Colormap,
    range: ValueRange,
    bar: &ColorBar,
) -> Result<(), IoError> {
    write_png(path, &render_with_color_bar(map, width, height, colormap, range, bar))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luminance(c: [u8; 4]) -> f64 {
        let lin = |v: u8| {
            let v = f64::from(v) / 255.0;
            if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
        };
        0.2126 * lin(c[0]) + 0.7152 * lin(c[1]) + 0.0722 * lin(c[2])
    }

    #[test]
    fn viridis_matches_reference_anchors_and_brightens_monotonically() {
        let r = ValueRange::new(0.0, 1.0);
        // Published end points of viridis: #440154 and #fde725.
        assert_eq!(Colormap::Viridis.rgba(0.0, r), [0x44, 0x01, 0x54, 255]);
        assert_eq!(Colormap::Viridis.rgba(1.0, r), [0xfd, 0xe7, 0x25, 255]);
        // Luminance rises along the map (within 8-bit rounding between neighbours).
        let l: Vec<f64> = (0..256).map(|i| luminance(Colormap::Viridis.rgba(i as f32 / 255.0, r))).collect();
        for i in 1..256 {
            assert!(l[i] > l[i - 1] - 1e-3, "viridis luminance drops at {i}");
        }
        for i in 8..256 {
            assert!(l[i] > l[i - 8], "viridis luminance not increasing at {i}");
        }
        // Clamped outside the range.
        assert_eq!(Colormap::Viridis.rgba(-5.0, r), Colormap::Viridis.rgba(0.0, r));
        assert_eq!(Colormap::Viridis.rgba(7.0, r), Colormap::Viridis.rgba(1.0, r));
    }

    #[test]
    fn turbo_runs_from_dark_blue_through_green_to_dark_red() {
        let r = ValueRange::new(0.0, 1.0);
        let lo = Colormap::Turbo.rgba(0.0, r);
        let mid = Colormap::Turbo.rgba(0.5, r);
        let hi = Colormap::Turbo.rgba(1.0, r);
        assert!(lo[2] > lo[0] && lo[2] > lo[1], "{lo:?}");
        assert!(mid[1] > mid[0] && mid[1] > mid[2], "{mid:?}");
        assert!(hi[0] > hi[1] && hi[0] > hi[2], "{hi:?}");
    }

    #[test]
    fn twilight_is_cyclic_over_one_phase_period() {
        let r = ValueRange::PHASE_RAD;
        let a = Colormap::Twilight.rgba(0.0, r);
        let b = Colormap::Twilight.rgba(TAU - 1e-6, r);
        let diff: i32 = (0..3).map(|i| (i32::from(a[i]) - i32::from(b[i])).abs()).sum();
        assert!(diff <= 6, "ends differ: {a:?} vs {b:?}");
        assert_eq!(Colormap::Twilight.rgba(TAU + 1.0, r), Colormap::Twilight.rgba(1.0, r));
        // Neighbouring table entries differ little everywhere (no hidden seam).
        for i in 0..256 {
            let (p, q) = (tables::TWILIGHT[i], tables::TWILIGHT[(i + 1) % 256]);
            let d: i32 = (0..3).map(|k| (i32::from(p[k]) - i32::from(q[k])).abs()).sum();
            assert!(d <= 12, "jump of {d} after entry {i}");
        }
        // Dark in the middle of the period, light at its ends.
        assert!(luminance(Colormap::Twilight.rgba(TAU / 2.0, r)) < 0.1);
        assert!(luminance(a) > 0.6);
    }

    #[test]
    fn nan_is_transparent_for_every_map() {
        for cm in Colormap::ALL {
            assert_eq!(cm.rgba(f32::NAN, ValueRange::new(0.0, 12.0)), INVALID_RGBA, "{cm:?}");
        }
    }

    #[test]
    fn saturation_counts_are_distinct_and_mark_over_saturation() {
        let n = 12.0;
        let colours: Vec<[u8; 4]> =
            (0..=12).map(|c| Colormap::SaturationCount.rgba(c as f32, ValueRange::new(0.0, n))).collect();
        for i in 0..colours.len() {
            for j in i + 1..colours.len() {
                assert_ne!(colours[i], colours[j], "counts {i} and {j} share a colour");
            }
        }
        assert_eq!(colours[0], SATURATION_NONE_RGBA);
        // Counts 1..=9 leave >= 3 samples (yellow/orange: red dominant, green high);
        // 10..=12 leave fewer (red/purple: green low).
        for (c, col) in colours.iter().enumerate().skip(1) {
            assert_eq!(col[1] < 60, c > 9, "count {c}: {col:?}");
        }
    }

    #[test]
    fn source_sets_have_distinct_colours_and_special_values() {
        let r = ValueRange::new(0.0, 3.0);
        let mut seen: Vec<[u8; 4]> = Vec::new();
        for v in [-2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0] {
            let c = Colormap::SourceSet.rgba(v, r);
            assert!(!seen.contains(&c), "value {v} repeats a colour");
            seen.push(c);
        }
        assert_eq!(Colormap::SourceSet.rgba(-1.0, r), SOURCE_NONE_RGBA);
        assert_eq!(Colormap::SourceSet.rgba(-2.0, r), SOURCE_ORDER_FAILED_RGBA);
        assert_eq!(Colormap::SourceSet.rgba(2.0, r), set_rgba(2));
    }

    #[test]
    fn render_maps_each_pixel_in_row_major_order() {
        let map = [0.0, 1.0, f32::NAN, 0.5, 2.0, -1.0];
        let img = render_map_png(&map, 3, 2, Colormap::Gray, ValueRange::new(0.0, 1.0));
        assert_eq!((img.width(), img.height()), (3, 2));
        assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0, 255]);
        assert_eq!(img.get_pixel(1, 0).0, [255, 255, 255, 255]);
        assert_eq!(img.get_pixel(2, 0).0, INVALID_RGBA);
        assert_eq!(img.get_pixel(0, 1).0, [128, 128, 128, 255]);
        assert_eq!(img.get_pixel(1, 1).0, [255, 255, 255, 255]);
        assert_eq!(img.get_pixel(2, 1).0, [0, 0, 0, 255]);
        // A short map renders its missing pixels as invalid instead of panicking.
        let img = render_map_png(&map[..4], 3, 2, Colormap::Gray, ValueRange::new(0.0, 1.0));
        assert_eq!(img.get_pixel(2, 1).0, INVALID_RGBA);
    }

    #[test]
    fn constant_map_uses_the_middle_colour() {
        let r = ValueRange::of_finite(&[3.0, 3.0, f32::NAN]).unwrap();
        assert_eq!(r, ValueRange::new(3.0, 3.0));
        assert_eq!(Colormap::Viridis.rgba(3.0, r), Colormap::Viridis.rgba(0.5, ValueRange::new(0.0, 1.0)));
        assert!(ValueRange::of_finite(&[f32::NAN, f32::INFINITY]).is_none());
    }

    #[test]
    fn quantiles_ignore_outliers_and_nan() {
        let mut map: Vec<f32> = (0..1000).map(|i| i as f32).collect();
        map.push(1e9);
        map.push(f32::NAN);
        let r = ValueRange::quantiles(&map, 0.01, 0.99).unwrap();
        assert!((r.min - 10.0).abs() <= 1.0 && (r.max - 990.0).abs() <= 1.0, "{r:?}");
    }

    #[test]
    fn nice_ticks_are_round_and_inside() {
        let t = nice_ticks(0.0, std::f64::consts::TAU, 6);
        let labels: Vec<&str> = t.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["0", "1", "2", "3", "4", "5", "6"]);
        let t = nice_ticks(-0.037, 0.052, 6);
        let labels: Vec<&str> = t.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["-0.02", "0.00", "0.02", "0.04"]);
        let t = nice_ticks(100.0, 4000.0, 6);
        let labels: Vec<&str> = t.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["500", "1000", "1500", "2000", "2500", "3000", "3500", "4000"]);
        assert_eq!(nice_ticks(5.0, 5.0, 6), vec![(5.0, "5".to_string())]);
        assert!(nice_ticks(f64::NAN, 1.0, 6).is_empty());
    }

    #[test]
    fn colour_bar_panel_has_gradient_ticks_and_unit() {
        let (w, h) = (64usize, 300usize);
        let map: Vec<f32> = (0..w * h).map(|i| (i / w) as f32 / h as f32).collect();
        let range = ValueRange::new(0.0, 1.0);
        let img = render_with_color_bar(&map, w, h, Colormap::Viridis, range, &ColorBar::unit("um"));
        assert_eq!(img.height(), h as u32);
        assert!(img.width() > w as u32 + 20);
        // The map part is unchanged.
        let plain = render_map_png(&map, w, h, Colormap::Viridis, range);
        for (x, y) in [(0, 0), (10, 150), (63, 299)] {
            assert_eq!(img.get_pixel(x, y), plain.get_pixel(x, y));
        }
        // The bar holds the colour map's end colours near its top and bottom.
        let scale = 1;
        let x_bar = w as u32 + 4 * scale + 6;
        let column: Vec<[u8; 4]> = (0..h as u32).map(|y| img.get_pixel(x_bar, y).0).collect();
        assert!(column.contains(&Colormap::Viridis.rgba(1.0, range)));
        assert!(column.contains(&Colormap::Viridis.rgba(0.0, range)));
        // Labels and unit put dark ink on the white panel.
        let ink = img.pixels().filter(|p| p.0 == INK_RGBA).count();
        assert!(ink > 100, "only {ink} ink pixels");
    }

    #[test]
    fn discrete_bar_grows_canvas_to_fit_labels() {
        let map = vec![0.0f32; 10 * 10];
        let bar = ColorBar { unit: String::new(), categories: vec![(0, "912 px".into())] };
        let img = render_with_color_bar(&map, 10, 10, Colormap::SourceSet, ValueRange::new(0.0, 3.0), &bar);
        // 6 blocks of at least one glyph height each.
        assert!(img.height() >= 6 * 7);
        // The area below the 10-pixel map is transparent.
        assert_eq!(img.get_pixel(0, img.height() - 1).0, INVALID_RGBA);
        // Every block colour appears.
        for v in -2..=3 {
            let c = Colormap::SourceSet.rgba(v as f32, ValueRange::new(0.0, 3.0));
            assert!(img.pixels().any(|p| p.0 == c), "block {v} missing");
        }
    }

    #[test]
    fn written_png_reads_back_identically() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.png");
        let map: Vec<f32> = (0..40 * 30).map(|i| (i % 40) as f32).collect();
        write_map_png(&path, &map, 40, 30, Colormap::Turbo, ValueRange::new(0.0, 39.0), &ColorBar::unit("rad"))
            .unwrap();
        let back = image::open(&path).unwrap().to_rgba8();
        let want =
            render_with_color_bar(&map, 40, 30, Colormap::Turbo, ValueRange::new(0.0, 39.0), &ColorBar::unit("rad"));
        assert_eq!(back, want);
    }
}
