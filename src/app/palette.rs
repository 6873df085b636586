//! Colours of the views: the colour maps as egui colour tables, plus the few
//! fixed colours with a meaning (saturated, invalid, categorical sources).
//!
//! The maps themselves are `crate::io::colormap`'s lookup tables (shared with
//! the PNG exports so a map looks the same on screen and on disk); this file
//! only converts them to `Color32` once and maps values onto them.

use std::sync::OnceLock;

use eframe::egui::Color32;

/// Entries per colour table.
pub const LUT_SIZE: usize = 256;

/// A continuous colour map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Colormap {
    /// Perceptually uniform, colour-blind safe: the default for magnitudes.
    #[default]
    Viridis,
    /// High-contrast rainbow for small height differences.
    Turbo,
    /// Starts and ends on the same colour: for wrapped phase.
    Cyclic,
    Gray,
}

impl Colormap {
    /// The maps an operator can pick for magnitudes (cyclic is for phase only).
    pub const MAGNITUDE: [Colormap; 3] = [Colormap::Viridis, Colormap::Turbo, Colormap::Gray];

    pub fn name(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::Turbo => "turbo",
            Colormap::Cyclic => "cyclic",
            Colormap::Gray => "gray",
        }
    }

    pub fn lut(self) -> &'static [Color32; LUT_SIZE] {
        static TABLES: OnceLock<[[Color32; LUT_SIZE]; 4]> = OnceLock::new();
        let tables = TABLES.get_or_init(|| {
            [Colormap::Viridis, Colormap::Turbo, Colormap::Cyclic, Colormap::Gray].map(|map| {
                std::array::from_fn(|i| {
                    let [r, g, b, a] = rgba(map, i as f32 / (LUT_SIZE - 1) as f32);
                    Color32::from_rgba_unmultiplied(r, g, b, a)
                })
            })
        });
        &tables[self as usize]
    }
}

/// The colour of `t` in [0, 1] on a map.
// INTERIM until the io branch's colour maps are merged: piecewise-linear stops.
fn rgba(map: Colormap, t: f32) -> [u8; 4] {
    const VIRIDIS: [[u8; 3]; 9] = [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ];
    const TURBO: [[u8; 3]; 9] = [
        [48, 18, 59],
        [70, 107, 227],
        [40, 187, 236],
        [50, 242, 152],
        [164, 252, 60],
        [237, 208, 58],
        [251, 128, 34],
        [210, 48, 5],
        [122, 4, 3],
    ];
    const CYCLIC: [[u8; 3]; 9] = [
        [226, 217, 226],
        [158, 187, 201],
        [94, 128, 185],
        [84, 63, 156],
        [47, 20, 55],
        [128, 36, 79],
        [185, 93, 75],
        [211, 165, 146],
        [226, 217, 226],
    ];
    let stops: &[[u8; 3]] = match map {
        Colormap::Viridis => &VIRIDIS,
        Colormap::Turbo => &TURBO,
        Colormap::Cyclic => &CYCLIC,
        Colormap::Gray => &[[0, 0, 0], [255, 255, 255]],
    };
    let x = t.clamp(0.0, 1.0) * (stops.len() - 1) as f32;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f32;
    let c = |k: usize| (f32::from(stops[i][k]) * (1.0 - f) + f32::from(stops[i + 1][k]) * f).round() as u8;
    [c(0), c(1), c(2), 255]
}

/// Pixels without a value (NaN, not computed): a neutral dark grey that no
/// colour map uses at its ends.
pub const INVALID: Color32 = Color32::from_rgb(48, 48, 52);
/// Saturated samples in the raw view: a magenta no grey level can be mistaken for.
pub const SATURATED: Color32 = Color32::from_rgb(255, 0, 200);
/// Valid / invalid in mask views.
pub const MASK_TRUE: Color32 = Color32::from_rgb(235, 235, 235);
pub const MASK_FALSE: Color32 = Color32::from_rgb(20, 20, 24);
/// Warning text (simulated data, stale results).
pub const WARNING: Color32 = Color32::from_rgb(255, 170, 40);
pub const ERROR: Color32 = Color32::from_rgb(235, 80, 70);

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

/// Discrete colour of a saturation count `0..=n` (Alg. 1's `sat_map`): 0 is
/// black, then the counts step through viridis so neighbouring counts differ.
pub fn count_color(count: u8, n: u8) -> Color32 {
    if count == 0 {
        return Color32::BLACK;
    }
    let lut = Colormap::Viridis.lut();
    let t = f32::from(count) / f32::from(n.max(1));
    lut[((0.15 + 0.85 * t).clamp(0.0, 1.0) * (LUT_SIZE - 1) as f32).round() as usize]
}

/// Categorical colour of a fusion source: manifest set index, or
/// `SOURCE_NONE` / `SOURCE_ORDER_FAILED`.
pub fn source_color(source: i8) -> Color32 {
    use crate::engine::fusion::{SOURCE_NONE, SOURCE_ORDER_FAILED};
    // Tableau-like palette: distinct hues, none of them grey or red.
    const SETS: [Color32; 10] = [
        Color32::from_rgb(78, 121, 167),
        Color32::from_rgb(242, 142, 43),
        Color32::from_rgb(89, 161, 79),
        Color32::from_rgb(176, 122, 161),
        Color32::from_rgb(237, 201, 72),
        Color32::from_rgb(118, 183, 178),
        Color32::from_rgb(255, 157, 167),
        Color32::from_rgb(156, 117, 95),
        Color32::from_rgb(186, 176, 172),
        Color32::from_rgb(140, 86, 75),
    ];
    match source {
        SOURCE_NONE => INVALID,
        SOURCE_ORDER_FAILED => Color32::from_rgb(225, 40, 40),
        s if s >= 0 => SETS[s as usize % SETS.len()],
        _ => INVALID,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_and_out_of_range_values() {
        let lut = Colormap::Viridis.lut();
        assert_eq!(map_value(lut, f32::NAN, 0.0, 1.0), INVALID);
        assert_eq!(map_value(lut, -5.0, 0.0, 1.0), lut[0]);
        assert_eq!(map_value(lut, 5.0, 0.0, 1.0), lut[LUT_SIZE - 1]);
        assert_eq!(map_value(lut, 0.5, 0.0, 1.0), lut[128]);
    }

    #[test]
    fn the_cyclic_map_closes_on_itself() {
        let lut = Colormap::Cyclic.lut();
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
