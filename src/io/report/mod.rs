//! A report per inspected part: one self-contained page for the
//! customer or the lab file, as HTML ([`html`]) or as an A4 PDF with its font
//! embedded ([`pdf`]).
//!
//! Both are drawn from the same [`PartReport`]: the part and recipe, when,
//! where and by whom, the verdict, the height map with the regions and
//! sections drawn on it, the profile plots, the measurement table with its
//! limits and verdicts, the engine parameters and the input's hash. The
//! height-map picture is rendered once here ([`render_inspection_map`]) so the
//! two formats show the same thing.

pub mod html;
pub mod pdf;
pub mod study;

use image::RgbaImage;

use crate::analysis::height_map::{HeightMap, rows_north_up, z_um};
use crate::analysis::measurement_table::{MeasurementRow, MeasurementTable, PartVerdict, Verdict};
use crate::analysis::profile::Profile;
use crate::analysis::region::{NamedRegion, Region};
use crate::io::colormap::{Colormap, ValueRange, draw_text};

/// The word a verdict is printed as, in large type.
pub fn headline(verdict: PartVerdict) -> &'static str {
    match verdict {
        PartVerdict::Pass => "PASS",
        PartVerdict::Fail => "FAIL",
        PartVerdict::Error => "ERROR",
        PartVerdict::Inconclusive => "INCONCLUSIVE",
    }
}

/// Background of the verdict box: green, red, amber, ochre.
pub fn verdict_rgb(verdict: PartVerdict) -> [u8; 3] {
    match verdict {
        PartVerdict::Pass => [22, 128, 60],
        PartVerdict::Fail => [190, 30, 45],
        PartVerdict::Error => [200, 120, 0],
        PartVerdict::Inconclusive => [150, 120, 10],
    }
}

/// Everything one report shows.
#[derive(Clone, Debug)]
pub struct PartReport<'a> {
    pub part_id: String,
    pub recipe: String,
    pub time_utc: chrono::DateTime<chrono::Utc>,
    pub station: Option<String>,
    pub operator: Option<String>,
    /// The verdict as the records keep it, and why: the failed rows, "no
    /// toleranced measurement", or what kept the part from being measured.
    pub verdict: PartVerdict,
    pub reason: Option<String>,
    pub map: Option<&'a HeightMap>,
    pub regions: &'a [NamedRegion],
    pub profiles: &'a [Profile],
    pub table: &'a MeasurementTable,
    /// Engine parameters as `name = value` lines.
    pub engine_parameters: Vec<(String, String)>,
    pub input_path: String,
    /// Content hash of the manifest and every image it names, when computed.
    pub input_hash: Option<String>,
    pub sheen_version: String,
}

impl PartReport<'_> {
    /// The lines under the title, in the order both formats print them.
    pub fn identity_lines(&self) -> Vec<(&'static str, String)> {
        let mut lines = vec![
            ("Part", self.part_id.clone()),
            ("Recipe", self.recipe.clone()),
            // The records' form of a time (RFC 3339 with microseconds).
            ("Time (UTC)", self.time_utc.to_rfc3339_opts(chrono::SecondsFormat::Micros, true)),
        ];
        lines.push(("Station", self.station.clone().unwrap_or_else(|| "-".into())));
        lines.push(("Operator", self.operator.clone().unwrap_or_else(|| "-".into())));
        lines.push(("Input", self.input_path.clone()));
        lines.push(("Input hash", self.input_hash.clone().unwrap_or_else(|| "-".into())));
        lines.push(("Sheen", self.sheen_version.clone()));
        lines
    }
}

/// Engine parameters (their JSON, as records keep them) as `name = value`
/// lines: nested objects flattened to dotted names, lists and scalars as
/// compact JSON, so the report lists every setting the run used.
pub fn parameter_lines(json: &str) -> Vec<(String, String)> {
    fn walk(prefix: &str, value: &serde_json::Value, out: &mut Vec<(String, String)>) {
        match value {
            serde_json::Value::Object(map) => {
                for (key, v) in map {
                    let name = if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") };
                    walk(&name, v, out);
                }
            }
            serde_json::Value::String(text) => out.push((prefix.to_string(), text.clone())),
            other => out.push((prefix.to_string(), other.to_string())),
        }
    }
    let mut out = Vec::new();
    match serde_json::from_str::<serde_json::Value>(json) {
        Ok(value) => walk("", &value, &mut out),
        Err(_) => out.push(("parameters".into(), json.to_string())),
    }
    out
}

/// One measurement row as the report's table prints it: name (with the
/// texture parameter), value, unit, limits, verdict.
pub fn row_cells(row: &MeasurementRow) -> [String; 5] {
    let name = match &row.parameter {
        Some(p) => format!("{} {p}", row.name),
        None => row.name.clone(),
    };
    let value = match (row.value.filter(|v| v.is_finite()), &row.uncertainty) {
        (None, _) => "not measured".to_string(),
        (Some(v), Some(u)) => format!("{} ± {}", format_value(v), format_value(u.expanded)),
        (Some(v), None) => format_value(v),
    };
    let limits = match (row.limits(), row.nominal) {
        (Some((lo, hi)), Some(n)) => format!("{} ({} .. {})", format_value(n), format_value(lo), format_value(hi)),
        (Some((lo, hi)), None) => format!("{} .. {}", format_value(lo), format_value(hi)),
        (None, _) => String::new(),
    };
    let verdict = row.verdict().map_or("", Verdict::name).to_uppercase();
    [name, value, row.unit.clone(), limits, verdict]
}

/// What noise alone gives for an extreme (PV, Sz, Rz) on the row's nodes,
/// printed beside its value: a value near it is noise.
pub fn noise_floor_text(row: &MeasurementRow) -> Option<String> {
    let floor = row.uncertainty.as_ref()?.noise_floor.filter(|f| f.is_finite())?;
    row.value.filter(|v| v.is_finite())?;
    Some(format!("noise floor {}", format_value(floor)))
}

/// The line under a report's table: what the ± means and how the verdicts
/// were taken (the rules of the toleranced rows, and how many are
/// inconclusive).
pub fn decision_note(table: &MeasurementTable) -> String {
    let rules = table.rule_names();
    let open = table.rows.iter().filter(|r| r.verdict() == Some(Verdict::Inconclusive)).count();
    let mut note = "Values ± expanded uncertainty U (k = 2, about 95 %).".to_string();
    if table.rows.iter().any(|r| r.uncertainty.as_ref().is_some_and(|u| u.noise_floor.is_some())) {
        note.push_str(" A noise floor is what noise alone gives for a peak-to-valley on the same nodes.");
    }
    if !rules.is_empty() {
        note.push_str(&format!(
            " Verdicts by decision rule {}{}.",
            rules.join(", "),
            if open > 0 { format!("; {open} inconclusive (within U of a limit)") } else { String::new() }
        ));
    }
    note
}

/// Four significant decimals for micrometre-scale values, fewer for large ones.
fn format_value(v: f64) -> String {
    if v.abs() >= 1000.0 { format!("{v:.1}") } else { format!("{v:.4}") }
}

/// Colours of the regions and sections drawn on the map, in turn.
const OVERLAY_RGB: [[u8; 3]; 6] =
    [[255, 255, 255], [255, 80, 80], [80, 200, 255], [255, 200, 40], [200, 120, 255], [120, 255, 120]];

/// The height-map picture of the report: heights in Viridis over their
/// 0.5-99.5 % range, north up as the camera sees the part, scaled by whole
/// pixels to at most `max_side_px`, with each region's outline and each
/// section's line in a colour of its own and labelled by name. Returns the
/// picture and the height range (um) its colours span.
pub fn render_inspection_map(
    map: &HeightMap,
    regions: &[NamedRegion],
    profiles: &[Profile],
    max_side_px: u32,
) -> (RgbaImage, ValueRange) {
    let z = z_um(map);
    let range = ValueRange::quantiles(&z, 0.005, 0.995).unwrap_or(ValueRange::new(0.0, 1.0));
    let north_up = rows_north_up(&z, map.width);
    let longest = map.width.max(map.height).max(1) as u32;
    // Whole-pixel scales keep every node a crisp square; large maps shrink.
    let (scale_up, scale_down) = if longest <= max_side_px {
        ((max_side_px / longest).clamp(1, 8), 1)
    } else {
        (1, longest.div_ceil(max_side_px))
    };
    let (w, h) =
        ((map.width as u32 * scale_up).div_ceil(scale_down), (map.height as u32 * scale_up).div_ceil(scale_down));
    let mut img = RgbaImage::new(w.max(1), h.max(1));
    for (x, y, px) in img.enumerate_pixels_mut() {
        let col = ((x * scale_down) / scale_up) as usize;
        let row = ((y * scale_down) / scale_up) as usize;
        let value = north_up.get(row * map.width + col).copied().unwrap_or(f32::NAN);
        let rgba = Colormap::Viridis.rgba(value, range);
        // Holes print as light grey, not as transparency a printer shows white.
        px.0 = if rgba[3] == 0 { [215, 215, 215, 255] } else { rgba };
    }
    // Map (x_mm, y_mm) to picture pixels: rows run north up.
    let px_per_node = scale_up as f64 / scale_down as f64;
    let to_px = |x_mm: f64, y_mm: f64| -> (f64, f64) {
        let (gx, gy) = map.grid_position(x_mm, y_mm);
        ((gx + 0.5) * px_per_node, (map.height as f64 - 0.5 - gy) * px_per_node)
    };
    let mut colour = 0usize;
    for named in regions {
        let rgb = OVERLAY_RGB[colour % OVERLAY_RGB.len()];
        colour += 1;
        let outline: Vec<(f64, f64)> = region_outline_mm(&named.region).into_iter().map(|(x, y)| to_px(x, y)).collect();
        for pair in outline.windows(2) {
            draw_line(&mut img, pair[0], pair[1], rgb);
        }
        if let (Some(first), Some(last)) = (outline.first(), outline.last()) {
            draw_line(&mut img, *last, *first, rgb);
        }
        let (lx, ly) = outline.iter().fold((f64::INFINITY, f64::INFINITY), |a, p| (a.0.min(p.0), a.1.min(p.1)));
        label(&mut img, lx + 3.0, ly + 3.0, &named.name, rgb);
    }
    for profile in profiles {
        let rgb = OVERLAY_RGB[colour % OVERLAY_RGB.len()];
        colour += 1;
        let (a, b) = (to_px(profile.start_mm[0], profile.start_mm[1]), to_px(profile.end_mm[0], profile.end_mm[1]));
        draw_line(&mut img, a, b, rgb);
        label(&mut img, a.0 + 3.0, a.1 + 3.0, &profile.name, rgb);
    }
    (img, range)
}

/// Outline vertices in mm (closed implicitly); circles as 96-gons.
fn region_outline_mm(region: &Region) -> Vec<(f64, f64)> {
    match region {
        Region::Rectangle { x_mm, y_mm } => {
            let (x0, x1) = (x_mm[0].min(x_mm[1]), x_mm[0].max(x_mm[1]));
            let (y0, y1) = (y_mm[0].min(y_mm[1]), y_mm[0].max(y_mm[1]));
            vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        }
        Region::Polygon { vertices_mm } => vertices_mm.iter().map(|v| (v[0], v[1])).collect(),
        Region::Circle { centre_mm, radius_mm } => (0..96)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 96.0;
                (centre_mm[0] + radius_mm * a.cos(), centre_mm[1] + radius_mm * a.sin())
            })
            .collect(),
    }
}

/// A 2-pixel line with a dark edge, so it shows on any colour of the map.
fn draw_line(img: &mut RgbaImage, a: (f64, f64), b: (f64, f64), rgb: [u8; 3]) {
    let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).clamp(1, 1 << 16);
    let (w, h) = (img.width() as i64, img.height() as i64);
    for (offset, colour) in [(1i64, [0u8, 0, 0]), (0, rgb)] {
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (x, y) = ((a.0 + t * (b.0 - a.0)).round() as i64, (a.1 + t * (b.1 - a.1)).round() as i64);
            for dy in -offset..=offset + 1 {
                for dx in -offset..=offset + 1 {
                    let (px, py) = (x + dx, y + dy);
                    if (0..w).contains(&px) && (0..h).contains(&py) {
                        img.put_pixel(px as u32, py as u32, image::Rgba([colour[0], colour[1], colour[2], 255]));
                    }
                }
            }
        }
    }
}

fn label(img: &mut RgbaImage, x: f64, y: f64, text: &str, rgb: [u8; 3]) {
    let (x, y) = (x.max(0.0) as i64, y.max(0.0) as i64);
    for (dx, dy) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
        draw_text(img, x + dx, y + dy, text, 2, [0, 0, 0, 255]);
    }
    draw_text(img, x, y, text, 2, [rgb[0], rgb[1], rgb[2], 255]);
}

/// A profile's stations as polylines in (distance mm, height um): a hole
/// (NaN) ends one and the next valid station starts another.
pub fn profile_polylines(profile: &Profile) -> Vec<Vec<(f64, f64)>> {
    let mut lines = Vec::new();
    let mut current = Vec::new();
    for s in &profile.samples {
        if s.z_um.is_finite() {
            current.push((s.distance_mm, s.z_um));
        } else if !current.is_empty() {
            lines.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        lines.push(current);
    }
    lines
}

/// Height range (um) of a profile's valid stations, widened to at least 1 um.
pub fn profile_z_range(profile: &Profile) -> Option<(f64, f64)> {
    let (lo, hi) = profile
        .samples
        .iter()
        .filter(|s| s.z_um.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, s| (a.0.min(s.z_um), a.1.max(s.z_um)));
    if !(lo <= hi) {
        return None;
    }
    let mid = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo)).max(0.5) * 1.05;
    Some((mid - half, mid + half))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_map() -> HeightMap {
        HeightMap::new(40, 30, 0.0, 0.0, 0.1, vec![0.001; 1200]).expect("map")
    }

    #[test]
    fn regions_and_sections_are_drawn_where_they_lie() {
        let map = flat_map();
        // A rectangle over the left half, x 0.5..1.5 mm, y 0.5..2.5 mm.
        let regions = [NamedRegion::new("base", Region::Rectangle { x_mm: [0.5, 1.5], y_mm: [0.5, 2.5] })];
        let (img, _) = render_inspection_map(&map, &regions, &[], 400);
        let scale = (img.width() / 40) as f64;
        assert_eq!((img.width(), img.height()), (320, 240), "small maps scale up by whole pixels, at most 8");
        // The rectangle's left edge at x = 0.5 mm is column 5 (+0.5 node).
        let x = ((5.0 + 0.5) * scale) as u32;
        let y_mid = ((30.0 - 0.5 - 15.0) * scale) as u32;
        assert_eq!(img.get_pixel(x, y_mid).0, [255, 255, 255, 255], "outline on the region's edge");
        // Far inside the region the map's own colour, not an outline.
        let inside = img.get_pixel(((10.0 + 0.5) * scale) as u32, y_mid).0;
        assert_ne!(inside, [255, 255, 255, 255]);
        assert_ne!(inside, [0, 0, 0, 255]);
    }

    #[test]
    fn a_profile_breaks_into_polylines_at_holes() {
        use crate::analysis::profile::{Interpolation, ProfileSample};
        let sample = |d: f64, z: f64| ProfileSample { distance_mm: d, x_mm: d, y_mm: 0.0, z_um: z, n: 1 };
        let profile = Profile {
            name: "p".into(),
            start_mm: [0.0, 0.0],
            end_mm: [0.4, 0.0],
            length_mm: 0.4,
            step_mm: 0.1,
            width_mm: 0.0,
            lines_across: 1,
            interpolation: Interpolation::Bilinear,
            samples: vec![
                sample(0.0, 1.0),
                sample(0.1, 2.0),
                sample(0.2, f64::NAN),
                sample(0.3, 3.0),
                sample(0.4, 4.0),
            ],
            raw: Vec::new(),
        };
        let lines = profile_polylines(&profile);
        assert_eq!(lines, vec![vec![(0.0, 1.0), (0.1, 2.0)], vec![(0.3, 3.0), (0.4, 4.0)]]);
        let (lo, hi) = profile_z_range(&profile).expect("range");
        assert!(lo < 1.0 && hi > 4.0);
    }
}
