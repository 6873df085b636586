//! The profile plot rendered into an image for export (what the egui_plot on
//! screen shows: every profile, raw points, cursors, axes in mm and µm),
//! drawn with the io colour-bar font so it needs no font file or GPU.

use image::{Rgba, RgbaImage};

use crate::app::widgets::legend::{format_tick, nice_ticks};
use crate::io::colormap::{draw_text, text_width_px};

/// One profile as plotted: (distance mm, z um) with NaN for gaps.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotSeries {
    pub name: String,
    pub color: [u8; 3],
    pub points: Vec<[f64; 2]>,
    /// Raw map nodes near the line, drawn as dots.
    pub raw: Vec<[f64; 2]>,
}

const WHITE: [u8; 4] = [255, 255, 255, 255];
const INK: [u8; 4] = [20, 20, 20, 255];
const GRID: [u8; 4] = [225, 225, 225, 255];
const CURSOR: [u8; 4] = [220, 40, 40, 255];

fn put(img: &mut RgbaImage, x: i64, y: i64, c: [u8; 4]) {
    if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, Rgba(c));
    }
}

fn dot(img: &mut RgbaImage, x: f64, y: f64, r: i64, c: [u8; 4]) {
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    for dy in -r..=r {
        for dx in -r..=r {
            if dx * dx + dy * dy <= r * r {
                put(img, cx + dx, cy + dy, c);
            }
        }
    }
}

/// A line `width` pixels wide, by stepping along it every half pixel.
fn segment(img: &mut RgbaImage, a: [f64; 2], b: [f64; 2], width: i64, c: [u8; 4]) {
    let n = ((b[0] - a[0]).abs().max((b[1] - a[1]).abs()) * 2.0).ceil().max(1.0) as usize;
    if n > 100_000 {
        return;
    }
    for i in 0..=n {
        let t = i as f64 / n as f64;
        dot(img, a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), width / 2, c);
    }
}

fn text_right(img: &mut RgbaImage, x_right: i64, y_mid: i64, text: &str, scale: u32) {
    let w = i64::from(text_width_px(text, scale));
    draw_text(img, x_right - w, y_mid - i64::from(7 * scale / 2), text, scale, INK);
}

fn text_centre(img: &mut RgbaImage, x_mid: i64, y_top: i64, text: &str, scale: u32) {
    let w = i64::from(text_width_px(text, scale));
    draw_text(img, x_mid - w / 2, y_top, text, scale, INK);
}

/// Renders the plot at `size` pixels.
pub fn render_profile_plot(series: &[PlotSeries], cursors: [Option<f64>; 2], title: &str, size: [u32; 2]) -> RgbaImage {
    let [w, h] = size;
    let mut img = RgbaImage::from_pixel(w, h, Rgba(WHITE));
    let scale = 2;
    let glyph = i64::from(7 * scale);
    let finite = |p: &&[f64; 2]| p[0].is_finite() && p[1].is_finite();
    let all: Vec<[f64; 2]> =
        series.iter().flat_map(|s| s.points.iter().chain(&s.raw)).filter(finite).copied().collect();
    let (mut x0, mut x1, mut y0, mut y1) =
        all.iter().fold((f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY), |(a, b, c, d), p| {
            (a.min(p[0]), b.max(p[0]), c.min(p[1]), d.max(p[1]))
        });
    if !(x0.is_finite() && x1 > x0) {
        (x0, x1) = (0.0, 1.0);
    }
    if !(y0.is_finite() && y1 > y0) {
        let mid = if y0.is_finite() { y0 } else { 0.0 };
        (y0, y1) = (mid - 1.0, mid + 1.0);
    }
    let pad = (y1 - y0) * 0.05;
    (y0, y1) = (y0 - pad, y1 + pad);

    let (left, right, top, bottom) = (110i64, i64::from(w) - 30, 60i64, i64::from(h) - 70);
    let to_px = |p: [f64; 2]| {
        [
            left as f64 + (p[0] - x0) / (x1 - x0) * (right - left) as f64,
            bottom as f64 - (p[1] - y0) / (y1 - y0) * (bottom - top) as f64,
        ]
    };
    // Grid, ticks and labels.
    let xt = nice_ticks(x0, x1, 8);
    for &t in &xt {
        let x = to_px([t, y0])[0];
        segment(&mut img, [x, top as f64], [x, bottom as f64], 1, GRID);
        segment(&mut img, [x, bottom as f64], [x, bottom as f64 + 6.0], 2, INK);
        text_centre(&mut img, x.round() as i64, bottom + 10, &format_tick(t, &xt), scale);
    }
    let yt = nice_ticks(y0, y1, 8);
    for &t in &yt {
        let y = to_px([x0, t])[1];
        segment(&mut img, [left as f64, y], [right as f64, y], 1, GRID);
        segment(&mut img, [left as f64 - 6.0, y], [left as f64, y], 2, INK);
        text_right(&mut img, left - 10, y.round() as i64, &format_tick(t, &yt), scale);
    }
    let frame = [[left, top], [right, top], [right, bottom], [left, bottom], [left, top]];
    for pair in frame.windows(2) {
        let p = |q: [i64; 2]| [q[0] as f64, q[1] as f64];
        segment(&mut img, p(pair[0]), p(pair[1]), 2, INK);
    }
    text_centre(&mut img, (left + right) / 2, bottom + 16 + glyph + 6, "distance mm", scale);
    draw_text(&mut img, 8, top - glyph - 12, "z um", scale, INK);
    draw_text(&mut img, left, 10, title, scale, INK);

    // Data: raw dots under the lines; lines broken at gaps.
    for s in series {
        let c = [s.color[0], s.color[1], s.color[2], 255];
        let faint = [
            ((u16::from(s.color[0]) + 2 * 255) / 3) as u8,
            ((u16::from(s.color[1]) + 2 * 255) / 3) as u8,
            ((u16::from(s.color[2]) + 2 * 255) / 3) as u8,
            255,
        ];
        for p in s.raw.iter().filter(finite) {
            let q = to_px(*p);
            dot(&mut img, q[0], q[1], 1, faint);
        }
        for pair in s.points.windows(2) {
            if pair.iter().all(|p| p[0].is_finite() && p[1].is_finite()) {
                segment(&mut img, to_px(pair[0]), to_px(pair[1]), 3, c);
            }
        }
    }
    for (i, cursor) in cursors.iter().enumerate() {
        if let Some(d) = cursor.filter(|d| d.is_finite() && *d >= x0 && *d <= x1) {
            let x = to_px([d, y0])[0];
            segment(&mut img, [x, top as f64], [x, bottom as f64], 2, CURSOR);
            draw_text(&mut img, x.round() as i64 + 4, top + 4, if i == 0 { "A" } else { "B" }, scale, CURSOR);
        }
    }
    // Legend, top right inside the frame.
    let mut y = top + 10;
    for s in series {
        let c = [s.color[0], s.color[1], s.color[2], 255];
        let tw = i64::from(text_width_px(&s.name, scale));
        let x = right - 16 - tw - 30;
        segment(&mut img, [x as f64, (y + glyph / 2) as f64], [(x + 22) as f64, (y + glyph / 2) as f64], 3, c);
        draw_text(&mut img, x + 30, y, &s.name, scale, INK);
        y += glyph + 8;
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plot_draws_each_profile_in_its_colour() {
        let series = vec![
            PlotSeries {
                name: "A-A".into(),
                color: [255, 0, 0],
                points: (0..100).map(|i| [f64::from(i) * 0.01, if i == 50 { f64::NAN } else { 5.0 }]).collect(),
                raw: Vec::new(),
            },
            PlotSeries {
                name: "B-B".into(),
                color: [0, 0, 255],
                points: vec![[0.0, -5.0], [0.99, 15.0]],
                raw: vec![[0.5, 3.0]],
            },
        ];
        let img = render_profile_plot(&series, [Some(0.25), None], "test", [800, 500]);
        let count = |c: [u8; 3]| img.pixels().filter(|p| p.0[..3] == c).count();
        assert!(count([255, 0, 0]) > 500, "the red profile is drawn");
        assert!(count([0, 0, 255]) > 500, "the blue profile is drawn");
        assert!(count([220, 40, 40]) > 100, "the cursor is drawn");
        // Nothing to plot still gives an image with axes.
        let empty = render_profile_plot(&[], [None, None], "", [400, 300]);
        assert!(empty.pixels().any(|p| p.0 == INK));
    }
}
