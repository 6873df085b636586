//! The part report as one self-contained HTML page: the height map inlined
//! as a PNG data URI, the profiles as inline SVG, no external files, fonts or
//! scripts, so it can be mailed or archived as it is and printed to A4.

use std::io::Write;

use base64::Engine as _;

use super::{
    PartReport, PartVerdict, headline, profile_polylines, profile_z_range, render_inspection_map, row_cells,
    verdict_rgb,
};

/// Escapes text for HTML element content and attribute values.
pub(crate) fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// Writes the report page.
pub fn write_html(w: &mut impl Write, report: &PartReport) -> std::io::Result<()> {
    let verdict_rgb = verdict_rgb(report.verdict);
    writeln!(w, "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">")?;
    writeln!(w, "<title>{} {}: {}</title>", escape(&report.recipe), escape(&report.part_id), headline(report.verdict))?;
    writeln!(
        w,
        "<style>@page {{ size: A4; margin: 14mm; }} body {{ font-family: sans-serif; font-size: 10pt; color: #111; max-width: 182mm; margin: auto; }} \
         h1 {{ font-size: 16pt; margin: 0 0 4pt 0; }} h2 {{ font-size: 12pt; margin: 12pt 0 4pt 0; }} \
         .verdict {{ display: inline-block; color: white; font-size: 32pt; font-weight: bold; padding: 4pt 16pt; border-radius: 4pt; background: rgb({},{},{}); }} \
         table {{ border-collapse: collapse; width: 100%; }} td, th {{ text-align: left; padding: 1pt 6pt; border-bottom: 1px solid #ddd; vertical-align: top; }} \
         td.num {{ text-align: right; font-variant-numeric: tabular-nums; }} tr.fail td {{ color: #b01020; font-weight: bold; }} \
         .meta td:first-child {{ color: #555; width: 28mm; }} img {{ max-width: 100%; image-rendering: pixelated; }} .small {{ font-size: 8pt; color: #444; }}</style>",
        verdict_rgb[0], verdict_rgb[1], verdict_rgb[2]
    )?;
    writeln!(w, "</head><body>")?;
    writeln!(w, "<h1>Sheen inspection report</h1>")?;
    writeln!(w, "<p><span class=\"verdict\">{}</span></p>", headline(report.verdict))?;
    match (report.verdict, &report.reason) {
        (PartVerdict::Error, reason) => {
            writeln!(w, "<p><b>Not measured:</b> {}</p>", escape(reason.as_deref().unwrap_or("no reason recorded")))?;
        }
        (_, Some(reason)) => writeln!(w, "<p>{}</p>", escape(reason))?,
        (_, None) => {}
    }
    writeln!(w, "<table class=\"meta\">")?;
    for (key, value) in report.identity_lines() {
        writeln!(w, "<tr><td>{key}</td><td>{}</td></tr>", escape(&value))?;
    }
    writeln!(w, "</table>")?;

    if let Some(map) = report.map {
        let (img, range) = render_inspection_map(map, report.regions, report.profiles, 720);
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        let data = base64::engine::general_purpose::STANDARD.encode(&png);
        writeln!(w, "<h2>Height map</h2>")?;
        writeln!(
            w,
            "<img alt=\"height map with the inspection's regions and sections\" src=\"data:image/png;base64,{data}\">"
        )?;
        writeln!(
            w,
            "<p class=\"small\">{} x {} nodes at {:.4} mm pitch, north up; colours (Viridis) from {:.3} um to {:.3} um; holes grey.</p>",
            map.width, map.height, map.pitch_mm, range.min, range.max
        )?;
    }

    if !report.profiles.is_empty() {
        writeln!(w, "<h2>Profiles</h2>")?;
        for profile in report.profiles {
            write_profile_svg(w, profile)?;
        }
    }

    writeln!(w, "<h2>Measurements</h2>")?;
    if report.table.rows.is_empty() {
        writeln!(w, "<p>No measurements.</p>")?;
    } else {
        writeln!(
            w,
            "<table><tr><th>measurement</th><th>value</th><th>unit</th><th>nominal (limits)</th><th>verdict</th></tr>"
        )?;
        for row in &report.table.rows {
            let [name, mut value, unit, limits, verdict] = row_cells(row);
            if let Some(floor) = super::noise_floor_text(row) {
                value = format!("{value} ({floor})");
            }
            let failed = row.verdict() == Some(crate::analysis::measurement_table::Verdict::Fail);
            let class = if failed { " class=\"fail\"" } else { "" };
            writeln!(
                w,
                "<tr{class}><td>{}</td><td class=\"num\">{}</td><td>{}</td><td class=\"num\">{}</td><td>{}</td></tr>",
                escape(&name),
                escape(&value),
                escape(&unit),
                escape(&limits),
                verdict
            )?;
        }
        writeln!(w, "</table>")?;
        writeln!(w, "<p class=\"small\">{}</p>", escape(&super::decision_note(report.table)))?;
    }

    if !report.engine_parameters.is_empty() {
        writeln!(w, "<h2>Engine parameters</h2><table class=\"meta small\">")?;
        for (key, value) in &report.engine_parameters {
            writeln!(w, "<tr><td>{}</td><td>{}</td></tr>", escape(key), escape(value))?;
        }
        writeln!(w, "</table>")?;
    }
    writeln!(w, "</body></html>")
}

/// A profile as an SVG plot: height (um) against distance (mm), with its
/// range on the axes.
fn write_profile_svg(w: &mut impl Write, profile: &crate::analysis::profile::Profile) -> std::io::Result<()> {
    let (width, height, left, bottom) = (680.0, 160.0, 60.0, 24.0);
    let (plot_w, plot_h) = (width - left - 10.0, height - bottom - 10.0);
    writeln!(
        w,
        "<p><b>{}</b> <span class=\"small\">length {:.3} mm, step {:.4} mm, width {:.3} mm</span></p>",
        escape(&profile.name),
        profile.length_mm,
        profile.step_mm,
        profile.width_mm
    )?;
    let Some((z_lo, z_hi)) = profile_z_range(profile) else {
        return writeln!(w, "<p class=\"small\">No valid station.</p>");
    };
    let length = profile.length_mm.max(1e-12);
    let x = |d: f64| left + d / length * plot_w;
    let y = |z: f64| 10.0 + (z_hi - z) / (z_hi - z_lo) * plot_h;
    writeln!(
        w,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" role=\"img\" aria-label=\"profile {}\">",
        escape(&profile.name)
    )?;
    writeln!(w, "<rect x=\"{left}\" y=\"10\" width=\"{plot_w}\" height=\"{plot_h}\" fill=\"none\" stroke=\"#888\"/>")?;
    for line in profile_polylines(profile) {
        let points: Vec<String> = line.iter().map(|&(d, z)| format!("{:.2},{:.2}", x(d), y(z))).collect();
        writeln!(
            w,
            "<polyline fill=\"none\" stroke=\"#1f5fbf\" stroke-width=\"1.2\" points=\"{}\"/>",
            points.join(" ")
        )?;
    }
    let font = "font-size=\"10\" font-family=\"sans-serif\"";
    writeln!(w, "<text x=\"{}\" y=\"16\" {font} text-anchor=\"end\">{z_hi:.3}</text>", left - 4.0)?;
    writeln!(w, "<text x=\"{}\" y=\"{}\" {font} text-anchor=\"end\">{z_lo:.3}</text>", left - 4.0, 10.0 + plot_h)?;
    writeln!(w, "<text x=\"4\" y=\"{}\" {font}>um</text>", 10.0 + plot_h / 2.0)?;
    writeln!(w, "<text x=\"{left}\" y=\"{}\" {font}>0</text>", height - 8.0)?;
    writeln!(
        w,
        "<text x=\"{}\" y=\"{}\" {font} text-anchor=\"end\">{:.3} mm</text>",
        left + plot_w,
        height - 8.0,
        profile.length_mm
    )?;
    writeln!(w, "</svg>")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::measurement_table::{MeasurementKind, MeasurementRow, MeasurementTable, Tolerance};

    #[test]
    fn the_page_escapes_what_users_type_and_marks_failures() {
        let mut table = MeasurementTable::default();
        table.push(
            MeasurementRow::new("step <a>", MeasurementKind::StepHeight, Some(12.5), "um")
                .with_tolerance(Some(10.0), Some(Tolerance::symmetric(1.0))),
        );
        let report = PartReport {
            part_id: "x'); DROP TABLE parts;--".into(),
            recipe: "plate & co".into(),
            time_utc: chrono::DateTime::parse_from_rfc3339("2026-12-03T18:00:00Z").expect("time").to_utc(),
            station: None,
            operator: Some("<script>".into()),
            verdict: PartVerdict::of_table(&table).0,
            reason: PartVerdict::of_table(&table).1,
            map: None,
            regions: &[],
            profiles: &[],
            table: &table,
            engine_parameters: vec![("method".into(), "hdr".into())],
            input_path: "in.json".into(),
            input_hash: Some("sha256:00".into()),
            sheen_version: "0.1.0".into(),
        };
        let mut out = Vec::new();
        write_html(&mut out, &report).expect("write");
        let page = String::from_utf8(out).expect("utf-8");
        assert!(page.contains("<span class=\"verdict\">FAIL</span>"));
        assert!(page.contains("x&#39;); DROP TABLE parts;--"));
        assert!(page.contains("plate &amp; co"));
        assert!(!page.contains("<script>"), "user text is never markup");
        assert!(page.contains("<tr class=\"fail\"><td>step &lt;a&gt;</td><td class=\"num\">12.5000</td>"));
    }
}
