//! Colours of the views: the colour maps as egui colour tables, plus the few
//! fixed colours with a meaning (saturated, invalid, categorical sources).
//!
//! The maps themselves are `crate::io::colormap`'s lookup tables (shared with
//! the PNG exports so a map looks the same on screen and on disk); this file
//! only converts them to `Color32` once and maps values onto them.

use std::sync::OnceLock;

use eframe::egui::Color32;

pub use crate::io::colormap::Colormap;
use crate::io::colormap::ValueRange;

/// Entries per colour table.
pub const LUT_SIZE: usize = 256;

/// The maps an operator can pick for magnitudes (the cyclic one is for wrapped
/// phase only, the discrete ones for their own views).
pub const MAGNITUDE_MAPS: [Colormap; 3] = [Colormap::Viridis, Colormap::Turbo, Colormap::Gray];

/// The 256-colour table of a continuous map, converted once from io's table.
pub fn lut(map: Colormap) -> &'static [Color32; LUT_SIZE] {
    static TABLES: OnceLock<[[Color32; LUT_SIZE]; 4]> = OnceLock::new();
    let continuous = [Colormap::Viridis, Colormap::Turbo, Colormap::Twilight, Colormap::Gray];
    let tables = TABLES.get_or_init(|| {
        continuous.map(|map| {
            std::array::from_fn(|i| {
                // Entry i is value i / 255 of the unit range, as in io's tables.
                let t = i as f32 / (LUT_SIZE - 1) as f32;
                let [r, g, b, a] = map.rgba(t, ValueRange::new(0.0, 1.0));
                Color32::from_rgba_unmultiplied(r, g, b, a)
            })
        })
    });
    let index = continuous.iter().position(|m| *m == map).unwrap_or(0);
    &tables[index]
}

fn color(rgba: [u8; 4]) -> Color32 {
    Color32::from_rgba_unmultiplied(rgba[0], rgba[1], rgba[2], rgba[3])
}

/// Pixels without a value (NaN, not computed): a neutral dark grey that no
/// colour map uses at its ends.
pub const INVALID: Color32 = Color32::from_rgb(48, 48, 52);
/// Saturated samples in the raw view: a magenta no grey level can be mistaken for.
pub const SATURATED: Color32 = Color32::from_rgb(255, 0, 200);
/// Valid / invalid in mask views.
pub const MASK_TRUE: Color32 = Color32::from_rgb(235, 235, 235);
pub const MASK_FALSE: Color32 = Color32::from_rgb(20, 20, 24);
/// Warning text (simulated data, stale results) on a dark background; see [`warning_text`].
pub const WARNING: Color32 = Color32::from_rgb(255, 170, 40);
/// Error text on a dark background; see [`error_text`].
pub const ERROR: Color32 = Color32::from_rgb(235, 80, 70);

/// Warning colour readable on the current theme (amber is too pale on white).
pub fn warning_text(visuals: &eframe::egui::Visuals) -> Color32 {
    if visuals.dark_mode { WARNING } else { Color32::from_rgb(165, 85, 0) }
}

/// Error colour readable on the current theme.
pub fn error_text(visuals: &eframe::egui::Visuals) -> Color32 {
    if visuals.dark_mode { ERROR } else { Color32::from_rgb(185, 25, 25) }
}

/// Colour of `value` on `lut` over `[lo, hi]`; NaN gives [`INVALID`].
#[inline]
pub fn map_value(lut: &[Color32; LUT_SIZE], value: f32, lo: f32, hi: f32) -> Color32 {
    if !value.is_finite() {
        return INVALID;
    }
    let span = hi - lo;
    let t = if span > 0.0 { (value - lo) / span } else { 0.5 };
    lut[(t.clamp(0.0, 1.0) * (LUT_SIZE - 1) as f32).round() as usize]
}

/// Discrete colour of a saturation count `0..=n` (Alg. 1's `sat_map`), from
/// io's scale: dark for none, yellow to orange while at least 3 samples stay
/// usable, red to purple once fewer do (over-saturated).
pub fn count_color(count: u8, n: u8) -> Color32 {
    color(Colormap::SaturationCount.rgba(f32::from(count), ValueRange::new(0.0, f32::from(n))))
}

/// Categorical colour of a fusion source: manifest set index, or
/// `SOURCE_NONE` / `SOURCE_ORDER_FAILED` (io's palette, shared with the PNG exports).
pub fn source_color(source: i8) -> Color32 {
    color(Colormap::SourceSet.rgba(f32::from(source), ValueRange::new(0.0, 1.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_and_out_of_range_values() {
        let lut = lut(Colormap::Viridis);
        assert_eq!(map_value(lut, f32::NAN, 0.0, 1.0), INVALID);
        assert_eq!(map_value(lut, -5.0, 0.0, 1.0), lut[0]);
        assert_eq!(map_value(lut, 5.0, 0.0, 1.0), lut[LUT_SIZE - 1]);
        assert_eq!(map_value(lut, 0.5, 0.0, 1.0), lut[128]);
    }

    #[test]
    fn the_cyclic_map_closes_on_itself() {
        let lut = lut(Colormap::Twilight);
        let (a, b) = (lut[0], lut[LUT_SIZE - 1]);
        let d = (i32::from(a.r()) - i32::from(b.r())).abs()
            + (i32::from(a.g()) - i32::from(b.g())).abs()
            + (i32::from(a.b()) - i32::from(b.b())).abs();
        assert!(d <= 12, "ends of the cyclic map differ: {a:?} vs {b:?}");
    }

    #[test]
    fn counts_and_sources_are_distinguishable() {
        let colors: Vec<Color32> = (0..=12).map(|c| count_color(c, 12)).collect();
        for w in colors.windows(2) {
            assert_ne!(w[0], w[1]);
        }
        let sources: Vec<Color32> = (-2..8).map(source_color).collect();
        for (i, a) in sources.iter().enumerate() {
            for b in &sources[i + 1..] {
                assert_ne!(a, b);
            }
        }
    }
}
