//! The part report as an A4 PDF, drawn with krilla (see ARCHITECTURE.md for
//! why): text in DejaVu Sans Condensed, embedded and subset so the page looks
//! the same on every reader and printer, and extractable (`pdftotext` finds
//! the verdict and every measurement); the height map as an image, the
//! profiles as vector plots.
//!
//! The layout is computed first as a list of drawing operations per page and
//! only then painted, so a long measurement table simply continues on the
//! next page.

use krilla::Document;
use krilla::color::rgb;
use krilla::geom::{PathBuilder, Point, Size, Transform};
use krilla::image::Image;
use krilla::metadata::Metadata;
use krilla::num::NormalizedF32;
use krilla::page::PageSettings;
use krilla::paint::{Fill, FillRule, Stroke};
use krilla::surface::Surface;
use krilla::text::{Font, TextDirection};

use super::{
    PartReport, PartVerdict, profile_polylines, profile_z_range, render_inspection_map, row_cells, verdict_rgb,
};

/// The embedded font (Bitstream Vera licence, assets/fonts/DejaVu-LICENSE.txt).
static FONT_TTF: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSansCondensed.ttf");

/// A4 in points.
const PAGE_W: f32 = 595.28;
const PAGE_H: f32 = 841.89;
const MARGIN: f32 = 42.0;
const CONTENT_W: f32 = PAGE_W - 2.0 * MARGIN;

enum Op {
    Text { x: f32, y: f32, size: f32, text: String, rgb: [u8; 3] },
    Rect { x: f32, y: f32, w: f32, h: f32, rgb: [u8; 3] },
    Frame { x: f32, y: f32, w: f32, h: f32, rgb: [u8; 3] },
    Polyline { points: Vec<(f32, f32)>, width: f32, rgb: [u8; 3] },
    Image { x: f32, y: f32, w: f32, h: f32, index: usize },
}

/// Lays pages out top to bottom, starting a new page when the next block
/// does not fit.
struct Layout {
    pages: Vec<Vec<Op>>,
    y: f32,
    images: Vec<Image>,
}

impl Layout {
    fn new() -> Self {
        Self { pages: vec![Vec::new()], y: MARGIN, images: Vec::new() }
    }

    fn ensure(&mut self, height: f32) {
        if self.y + height > PAGE_H - MARGIN {
            self.pages.push(Vec::new());
            self.y = MARGIN;
        }
    }

    fn push(&mut self, op: Op) {
        self.pages.last_mut().expect("a page").push(op);
    }

    fn text(&mut self, x: f32, size: f32, text: impl Into<String>, rgb: [u8; 3]) {
        let y = self.y + size;
        self.push(Op::Text { x, y, size, text: text.into(), rgb });
    }

    fn line(&mut self, size: f32, text: impl Into<String>) {
        self.ensure(size * 1.4);
        self.text(MARGIN, size, text, [17, 17, 17]);
        self.y += size * 1.4;
    }

    fn image(&mut self, image: Image, w: f32, h: f32) {
        self.images.push(image);
        let index = self.images.len() - 1;
        self.push(Op::Image { x: MARGIN, y: self.y, w, h, index });
    }

    fn heading(&mut self, text: &str) {
        self.ensure(40.0);
        self.y += 8.0;
        self.line(12.0, text);
        self.y += 2.0;
    }
}

/// Cuts text to at most `chars` characters, marking the cut.
fn fit(text: &str, chars: usize) -> String {
    if text.chars().count() <= chars {
        text.to_string()
    } else {
        let mut cut: String = text.chars().take(chars.saturating_sub(1)).collect();
        cut.push('…');
        cut
    }
}

/// The report as PDF bytes.
pub fn pdf_bytes(report: &PartReport) -> Result<Vec<u8>, String> {
    let font = Font::new(FONT_TTF.into(), 0).ok_or("the embedded font cannot be read")?;
    let mut layout = Layout::new();
    let dark = [17, 17, 17];
    let grey = [90, 90, 90];

    layout.line(16.0, "Sheen inspection report");
    layout.y += 4.0;
    // The verdict in large type on its colour.
    let headline = super::headline(report.verdict);
    let box_w = 30.0 + 24.0 * headline.chars().count() as f32;
    layout.push(Op::Rect { x: MARGIN, y: layout.y, w: box_w, h: 46.0, rgb: verdict_rgb(report.verdict) });
    layout.push(Op::Text {
        x: MARGIN + 14.0,
        y: layout.y + 36.0,
        size: 34.0,
        text: headline.into(),
        rgb: [255, 255, 255],
    });
    layout.y += 54.0;
    let reason = match (report.verdict, &report.reason) {
        (PartVerdict::Error, reason) => {
            Some(format!("Not measured: {}", reason.as_deref().unwrap_or("no reason recorded")))
        }
        (_, reason) => reason.clone(),
    };
    for chunk in reason.iter().flat_map(|r| wrap(r, 100)) {
        layout.line(10.0, chunk);
    }
    for (key, value) in report.identity_lines() {
        layout.ensure(14.0);
        layout.text(MARGIN, 9.5, key, grey);
        layout.text(MARGIN + 70.0, 9.5, fit(&value, 95), dark);
        layout.y += 13.0;
    }

    if let Some(map) = report.map {
        let (img, range) = render_inspection_map(map, report.regions, report.profiles, 900);
        let (iw, ih) = (img.width() as f32, img.height() as f32);
        let scale = (CONTENT_W / iw).min(300.0 / ih);
        let (w, h) = (iw * scale, ih * scale);
        layout.heading("Height map");
        layout.ensure(h + 16.0);
        let image = Image::from_rgba8(img.into_raw(), iw as u32, ih as u32);
        layout.image(image, w, h);
        layout.y += h + 4.0;
        layout.line(
            8.0,
            format!(
                "{} x {} nodes at {:.4} mm pitch, north up; colours (Viridis) from {:.3} um to {:.3} um; holes grey.",
                map.width, map.height, map.pitch_mm, range.min, range.max
            ),
        );
    }

    if !report.profiles.is_empty() {
        layout.heading("Profiles");
        for profile in report.profiles {
            profile_plot(&mut layout, profile);
        }
    }

    layout.heading("Measurements");
    let columns = [MARGIN, MARGIN + 175.0, MARGIN + 280.0, MARGIN + 305.0, MARGIN + 450.0];
    if report.table.rows.is_empty() {
        layout.line(10.0, "No measurements.");
    } else {
        let header = ["measurement", "value", "unit", "nominal (limits)", "verdict"];
        layout.ensure(14.0);
        for (x, h) in columns.iter().zip(header) {
            layout.text(*x, 9.0, h, grey);
        }
        layout.y += 13.0;
        for row in &report.table.rows {
            let cells = row_cells(row);
            let failed = row.verdict() == Some(crate::analysis::measurement_table::Verdict::Fail);
            let rgb = if failed { [176, 16, 32] } else { dark };
            layout.ensure(13.0);
            let widths = [35, 21, 5, 30, 12];
            for ((x, cell), chars) in columns.iter().zip(&cells).zip(widths) {
                layout.text(*x, 9.0, fit(cell, chars), rgb);
            }
            layout.y += 12.5;
            // An extreme's noise floor, under its value.
            if let Some(floor) = super::noise_floor_text(row) {
                layout.ensure(10.0);
                layout.text(columns[1], 7.5, fit(&floor, 30), grey);
                layout.y += 9.5;
            }
        }
        for line in wrap(&super::decision_note(report.table), 125) {
            layout.ensure(12.0);
            layout.text(MARGIN, 8.0, line, grey);
            layout.y += 11.0;
        }
    }

    if !report.engine_parameters.is_empty() {
        layout.heading("Engine parameters");
        for (key, value) in &report.engine_parameters {
            layout.ensure(11.0);
            layout.text(MARGIN, 8.0, fit(key, 40), grey);
            layout.text(MARGIN + 150.0, 8.0, fit(value, 80), dark);
            layout.y += 10.5;
        }
    }

    let metadata = Metadata::new()
        .title(format!("{} {}: {}", report.recipe, report.part_id, super::headline(report.verdict)))
        .creator(format!("Sheen {}", report.sheen_version));
    let footer = format!("{} · {}", report.recipe, report.part_id);
    document_bytes(layout, &font, metadata, &footer)
}

/// Paints the laid-out pages into a PDF, each with `footer` and its page
/// number at the foot.
fn document_bytes(layout: Layout, font: &Font, metadata: Metadata, footer: &str) -> Result<Vec<u8>, String> {
    let pages = layout.pages.len();
    let mut document = Document::new();
    document.set_metadata(metadata);
    let Layout { pages: page_ops, images, .. } = layout;
    for (number, ops) in page_ops.into_iter().enumerate() {
        let settings = PageSettings::from_wh(PAGE_W, PAGE_H).ok_or("A4 is a valid page size")?;
        let mut page = document.start_page_with(settings);
        let mut surface = page.surface();
        for op in ops {
            paint(&mut surface, font, op, &images);
        }
        let footer = format!("{footer} · page {} of {pages}", number + 1);
        draw_text(&mut surface, font, MARGIN, PAGE_H - 24.0, 7.5, &fit(&footer, 120), [90, 90, 90]);
        surface.finish();
        page.finish();
    }
    document.finish().map_err(|e| format!("the PDF cannot be written: {e:?}"))
}

/// A gauge study as an A4 PDF: the verdict on its colour, where the values
/// came from, the figures as the command line prints them, and every value.
pub fn study_pdf_bytes(page: &super::study::StudyPage<'_>) -> Result<Vec<u8>, String> {
    let font = Font::new(FONT_TTF.into(), 0).ok_or("the embedded font cannot be read")?;
    let mut layout = Layout::new();
    let (dark, grey) = ([17, 17, 17], [90, 90, 90]);
    layout.line(16.0, page.title);
    layout.y += 4.0;
    let rgb = if page.good { [22, 128, 60] } else { [190, 30, 45] };
    let headline = fit(&page.headline, 60);
    let box_w = (24.0 + 9.5 * headline.chars().count() as f32).min(CONTENT_W);
    layout.push(Op::Rect { x: MARGIN, y: layout.y, w: box_w, h: 28.0, rgb });
    layout.push(Op::Text { x: MARGIN + 10.0, y: layout.y + 20.0, size: 16.0, text: headline, rgb: [255, 255, 255] });
    layout.y += 36.0;
    for chunk in wrap(&format!("Data: {}", page.source), 100) {
        layout.line(9.0, chunk);
    }
    layout.heading("Figures");
    for text in page.figures.lines() {
        layout.line(8.5, fit(text, 110));
    }
    layout.heading(&format!("Data ({} values)", page.data.len()));
    let columns = [(MARGIN, "#"), (MARGIN + 40.0, "part"), (MARGIN + 220.0, "operator"), (MARGIN + 360.0, "value")];
    let row = |layout: &mut Layout, cells: [String; 4], rgb: [u8; 3]| {
        layout.ensure(12.0);
        for ((x, _), text) in columns.iter().zip(cells) {
            layout.text(*x, 8.5, fit(&text, 34), rgb);
        }
        layout.y += 12.0;
    };
    row(&mut layout, columns.map(|(_, h)| h.to_string()), grey);
    for (i, o) in page.data.iter().enumerate() {
        row(&mut layout, [(i + 1).to_string(), o.part.clone(), o.operator.clone(), format!("{}", o.value)], dark);
    }
    let metadata = Metadata::new()
        .title(format!("{}: {}", page.title, page.headline))
        .creator(format!("Sheen {}", env!("CARGO_PKG_VERSION")));
    document_bytes(layout, &font, metadata, page.title)
}

/// Splits text into lines of at most `chars` characters at spaces.
fn wrap(text: &str, chars: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut current = String::new();
    for word in text.split(' ') {
        // A path longer than a line is cut, not run off the page.
        let mut word = word.to_string();
        while word.chars().count() > chars {
            if !current.is_empty() {
                lines.push(std::mem::take(&mut current));
            }
            let head: String = word.chars().take(chars).collect();
            word = word.chars().skip(chars).collect();
            lines.push(head);
        }
        let word = word.as_str();
        if !current.is_empty() && current.chars().count() + 1 + word.chars().count() > chars {
            lines.push(std::mem::take(&mut current));
        }
        if !current.is_empty() {
            current.push(' ');
        }
        current.push_str(word);
    }
    if !current.is_empty() {
        lines.push(current);
    }
    lines
}

/// A profile's plot: height (um) against distance (mm), with its range.
fn profile_plot(layout: &mut Layout, profile: &crate::analysis::profile::Profile) {
    let (plot_h, left) = (100.0, 48.0);
    layout.ensure(plot_h + 40.0);
    layout.line(
        9.0,
        format!(
            "{}: length {:.3} mm, step {:.4} mm, width {:.3} mm",
            fit(&profile.name, 40),
            profile.length_mm,
            profile.step_mm,
            profile.width_mm
        ),
    );
    let (x0, y0, w) = (MARGIN + left, layout.y, CONTENT_W - left);
    layout.push(Op::Frame { x: x0, y: y0, w, h: plot_h, rgb: [136, 136, 136] });
    if let Some((z_lo, z_hi)) = profile_z_range(profile) {
        let length = profile.length_mm.max(1e-12);
        for line in profile_polylines(profile) {
            let points = line
                .iter()
                .map(|&(d, z)| (x0 + (d / length) as f32 * w, y0 + ((z_hi - z) / (z_hi - z_lo)) as f32 * plot_h))
                .collect();
            layout.push(Op::Polyline { points, width: 1.4, rgb: [31, 95, 191] });
        }
        let grey = [70, 70, 70];
        layout.push(Op::Text { x: MARGIN, y: y0 + 8.0, size: 7.5, text: format!("{z_hi:.3} um"), rgb: grey });
        layout.push(Op::Text { x: MARGIN, y: y0 + plot_h, size: 7.5, text: format!("{z_lo:.3} um"), rgb: grey });
        layout.push(Op::Text { x: x0, y: y0 + plot_h + 10.0, size: 7.5, text: "0 mm".into(), rgb: grey });
        layout.push(Op::Text {
            x: x0 + w - 50.0,
            y: y0 + plot_h + 10.0,
            size: 7.5,
            text: format!("{:.3} mm", profile.length_mm),
            rgb: grey,
        });
    } else {
        layout.push(Op::Text {
            x: x0 + 8.0,
            y: y0 + 20.0,
            size: 9.0,
            text: "no valid station".into(),
            rgb: [90, 90, 90],
        });
    }
    layout.y += plot_h + 16.0;
}

fn fill(rgb: [u8; 3]) -> Fill {
    Fill { paint: rgb::Color::new(rgb[0], rgb[1], rgb[2]).into(), opacity: NormalizedF32::ONE, rule: FillRule::NonZero }
}

fn draw_text(surface: &mut Surface, font: &Font, x: f32, y: f32, size: f32, text: &str, rgb: [u8; 3]) {
    surface.set_fill(Some(fill(rgb)));
    surface.set_stroke(None);
    surface.draw_text(Point::from_xy(x, y), font.clone(), size, text, false, TextDirection::Auto);
}

fn paint(surface: &mut Surface, font: &Font, op: Op, images: &[Image]) {
    match op {
        Op::Text { x, y, size, text, rgb } => draw_text(surface, font, x, y, size, &text, rgb),
        Op::Rect { x, y, w, h, rgb } | Op::Frame { x, y, w, h, rgb } => {
            let filled = matches!(op, Op::Rect { .. });
            let mut pb = PathBuilder::new();
            pb.move_to(x, y);
            pb.line_to(x + w, y);
            pb.line_to(x + w, y + h);
            pb.line_to(x, y + h);
            pb.close();
            let Some(path) = pb.finish() else { return };
            if filled {
                surface.set_stroke(None);
                surface.set_fill(Some(fill(rgb)));
            } else {
                surface.set_fill(None);
                surface.set_stroke(Some(stroke(rgb, 0.6)));
            }
            surface.draw_path(&path);
        }
        Op::Polyline { points, width, rgb } => {
            let mut pb = PathBuilder::new();
            for (i, &(x, y)) in points.iter().enumerate() {
                if i == 0 { pb.move_to(x, y) } else { pb.line_to(x, y) }
            }
            // A single station is a dot: a zero-length segment with a round cap.
            if points.len() == 1 {
                pb.line_to(points[0].0 + 0.01, points[0].1);
            }
            let Some(path) = pb.finish() else { return };
            surface.set_fill(None);
            surface.set_stroke(Some(stroke(rgb, width)));
            surface.draw_path(&path);
        }
        Op::Image { x, y, w, h, index } => {
            let Some(image) = images.get(index).cloned() else { return };
            let Some(size) = Size::from_wh(w, h) else { return };
            surface.push_transform(&Transform::from_translate(x, y));
            surface.draw_image(image, size);
            surface.pop();
        }
    }
}

fn stroke(rgb: [u8; 3], width: f32) -> Stroke {
    Stroke { paint: rgb::Color::new(rgb[0], rgb[1], rgb[2]).into(), width, ..Stroke::default() }
}
