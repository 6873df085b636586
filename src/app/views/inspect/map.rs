//! The height map of the Inspect view: colour-mapped heights (north up, axes
//! in mm, colour bar in µm), zoom and pan, the drawing tools, and the regions
//! and sections drawn over it.

use eframe::egui::{self, Color32, Pos2, Rect, Sense, Stroke, Vec2, pos2, vec2};

use crate::analysis::region::Region;
use crate::app::palette::{self, LUT_SIZE};
use crate::app::textures::{TextureCache, key_of};
use crate::app::widgets::legend::{self, Legend, format_tick, nice_ticks};
use crate::app::widgets::map_view::{ViewTransform, image_rect};

use super::state::{self, Drawing, Drawn, Tool};
use super::{Analysis, InspectRuntime, InspectView, Selection};

/// Nodes filled for display are drawn with every other pixel lightened, a
/// pattern no colour map produces.
pub const FILLED_MARK: Color32 = Color32::from_rgb(200, 200, 200);

const AXIS_LEFT: f32 = 46.0;
const AXIS_BOTTOM: f32 = 16.0;
const READOUT_H: f32 = 18.0;

/// Mapping between map millimetres and the screen.
#[derive(Clone, Copy, Debug)]
pub struct MapFrame {
    pub image: Rect,
    pub size: [usize; 2],
    pub origin_mm: [f64; 2],
    pub pitch_mm: f64,
}

impl MapFrame {
    pub fn new(rect: Rect, map: &crate::analysis::height_map::HeightMap, t: &ViewTransform) -> Self {
        let size = [map.width, map.height];
        Self {
            image: image_rect(rect, size, t),
            size,
            origin_mm: [map.origin_x_mm, map.origin_y_mm],
            pitch_mm: map.pitch_mm,
        }
    }

    fn texel_scale(&self) -> Vec2 {
        self.image.size() / vec2(self.size[0].max(1) as f32, self.size[1].max(1) as f32)
    }

    /// Screen position of map point `(x, y)` mm (node centres on texel centres; Y up).
    pub fn to_screen(&self, p: [f64; 2]) -> Pos2 {
        let col = (p[0] - self.origin_mm[0]) / self.pitch_mm;
        let row = (p[1] - self.origin_mm[1]) / self.pitch_mm;
        let v = (self.size[1] as f64 - 1.0) - row;
        let s = self.texel_scale();
        pos2(self.image.min.x + (col as f32 + 0.5) * s.x, self.image.min.y + (v as f32 + 0.5) * s.y)
    }

    pub fn to_mm(&self, p: Pos2) -> [f64; 2] {
        let s = self.texel_scale();
        let col = f64::from((p.x - self.image.min.x) / s.x - 0.5);
        let v = f64::from((p.y - self.image.min.y) / s.y - 0.5);
        let row = (self.size[1] as f64 - 1.0) - v;
        [self.origin_mm[0] + col * self.pitch_mm, self.origin_mm[1] + row * self.pitch_mm]
    }

    pub fn px_per_mm(&self) -> f32 {
        self.texel_scale().x / self.pitch_mm as f32
    }
}

/// Zooms by `factor` keeping the image point under `pointer` fixed.
fn zoom_about(t: &mut ViewTransform, rect: Rect, size: [usize; 2], pointer: Pos2, factor: f32) {
    let fit = |r: Rect| (r.width() / size[0].max(1) as f32).min(r.height() / size[1].max(1) as f32).max(1e-6);
    let old_scale = fit(rect) * t.zoom;
    let new_zoom = (t.zoom * factor).clamp(0.5, 256.0);
    let new_scale = fit(rect) * new_zoom;
    let center = t.center_px.unwrap_or(vec2(size[0] as f32 / 2.0, size[1] as f32 / 2.0));
    let offset = pointer - rect.center();
    let under = center + offset / old_scale;
    t.center_px = Some(under - offset / new_scale);
    t.zoom = new_zoom;
}

fn pan(t: &mut ViewTransform, rect: Rect, size: [usize; 2], delta: Vec2) {
    let fit = (rect.width() / size[0].max(1) as f32).min(rect.height() / size[1].max(1) as f32).max(1e-6);
    let center = t.center_px.unwrap_or(vec2(size[0] as f32 / 2.0, size[1] as f32 / 2.0));
    t.center_px = Some(center - delta / (fit * t.zoom));
}

pub fn color32(c: [u8; 3]) -> Color32 {
    Color32::from_rgb(c[0], c[1], c[2])
}

/// The display heights as a north-up image; filled nodes patterned.
fn paint(a: &Analysis, lut: &[Color32; LUT_SIZE], lo: f32, hi: f32) -> egui::ColorImage {
    let (w, h) = (a.map.width, a.map.height);
    let mut pixels = Vec::with_capacity(w * h);
    for v in 0..h {
        let row = h - 1 - v;
        for col in 0..w {
            let i = row * w + col;
            let c = palette::map_value(lut, a.display_um[i], lo, hi);
            let filled = a.filled.as_ref().is_some_and(|f| f[i]);
            pixels.push(if filled && (col + v) % 2 == 0 { c.lerp_to_gamma(Color32::WHITE, 0.55) } else { c });
        }
    }
    egui::ColorImage::new([w, h], pixels)
}

/// The map with its axes, legend and read-out in `size`.
pub fn show(
    ui: &mut egui::Ui,
    settings: &mut InspectView,
    rt: &mut InspectRuntime,
    textures: &mut TextureCache,
    size: Vec2,
) {
    let Some(analysis) = rt.analysis.value() else {
        let (rect, _) = ui.allocate_exact_size(size, Sense::hover());
        let text = match rt.raster.result() {
            Some(Err(e)) => format!("No height map: {e}"),
            _ => "Rasterizing the point cloud into a height map…".to_owned(),
        };
        ui.painter().text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            text,
            egui::FontId::proportional(14.0),
            ui.visuals().text_color(),
        );
        return;
    };
    let lut = palette::lut(settings.colormap);
    let (lo, hi) = settings.range.resolve(analysis.range_um);
    let mut legend =
        Legend::bar(lut, f64::from(lo), f64::from(hi), "µm").with_entry(palette::INVALID, "hole (no data)");
    if analysis.filled.is_some() {
        legend = legend.with_entry(FILLED_MARK, "filled for display");
    }
    let legend_w = legend::width(ui, &legend);
    let map_w = (size.x - legend_w - AXIS_LEFT - 8.0).max(60.0);
    let map_h = (size.y - AXIS_BOTTOM - READOUT_H - 6.0).max(60.0);
    // Keyed by the analysis on screen (not the one being computed), so the
    // texture follows the data it shows.
    let key = key_of(&(rt.analysis.value_key(), settings.colormap, lo.to_bits(), hi.to_bits()));
    let texture = textures.get(ui.ctx(), egui::Id::unique("inspect height map"), key, || paint(analysis, lut, lo, hi));
    let map_size = [analysis.map.width, analysis.map.height];

    let (outer, _) = ui.allocate_exact_size(vec2(size.x, map_h + AXIS_BOTTOM), Sense::hover());
    let rect = Rect::from_min_size(outer.min + vec2(AXIS_LEFT, 0.0), vec2(map_w, map_h));
    let legend_rect = Rect::from_min_size(pos2(rect.right() + 8.0, rect.top()), vec2(legend_w, map_h));
    let response = ui.interact(rect, egui::Id::unique("inspect map area"), Sense::click_and_drag());
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "Height map"));

    // Zoom and pan.
    if response.hovered() {
        let (scroll, pinch) = ui.input(|i| (i.smooth_scroll_delta.y, i.zoom_delta()));
        let factor = (scroll * 0.0025).exp() * pinch;
        if (factor - 1.0).abs() > 1e-4
            && let Some(p) = response.hover_pos()
        {
            zoom_about(&mut rt.transform, rect, map_size, p, factor);
        }
    }
    let pans = (rt.tool == Tool::Pan && response.dragged_by(egui::PointerButton::Primary))
        || response.dragged_by(egui::PointerButton::Secondary)
        || response.dragged_by(egui::PointerButton::Middle);
    if pans {
        pan(&mut rt.transform, rect, map_size, response.drag_delta());
    }
    let map = std::sync::Arc::clone(&analysis.map);
    let frame = MapFrame::new(rect, &map, &rt.transform);
    let min_mm = 2.0 * map.pitch_mm;
    handle_tools(ui, &response, &frame, rt, min_mm);

    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, ui.visuals().extreme_bg_color);
    painter.image(texture.id(), frame.image, Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)), Color32::WHITE);
    draw_overlays(&painter, &frame, rt, &map);
    draw_axes(ui, rect, &frame);
    let mut legend_ui = ui.new_child(egui::UiBuilder::new().max_rect(legend_rect));
    legend::show(&mut legend_ui, &legend, legend_rect.size());

    let Some(analysis) = rt.analysis.value() else { return };
    let readout = match response.hover_pos() {
        Some(p) => {
            let [x, y] = frame.to_mm(p);
            let z = map.z_at(x, y);
            let (col, row) = map.grid_position(x, y);
            let (c, r) = (col.round(), row.round());
            let display = if c >= 0.0 && r >= 0.0 && (c as usize) < map.width && (r as usize) < map.height {
                let i = r as usize * map.width + c as usize;
                analysis.filled.as_ref().filter(|f| f[i]).map(|_| analysis.display_um[i])
            } else {
                None
            };
            let zt = if z.is_finite() {
                format!("z {:.3} µm", z * 1000.0)
            } else if let Some(d) = display {
                format!("hole (filled for display: {d:.3} µm, not measured)")
            } else {
                "hole (no data)".to_owned()
            };
            format!("x {x:.4} mm · y {y:.4} mm · {zt}")
        }
        None if rt.tool == Tool::Pan => rt.tool.tooltip().to_owned(),
        None => format!("{} Wheel zooms, right-drag pans.", rt.tool.tooltip()),
    };
    let level = match &analysis.levelling {
        Some(fit) => format!("levelled to {} (tilt {:.4}°)", fit.region, fit.plane.tilt_deg()),
        None => "not levelled".to_owned(),
    };
    ui.add_sized(
        [size.x, READOUT_H],
        egui::Label::new(egui::RichText::new(format!("{readout}   |   {level}")).monospace()).truncate(),
    );
}

fn handle_tools(ui: &egui::Ui, response: &egui::Response, frame: &MapFrame, rt: &mut InspectRuntime, min_mm: f64) {
    let pointer_mm = response.interact_pointer_pos().or(response.hover_pos()).map(|p| frame.to_mm(p));
    match rt.tool {
        Tool::Pan => {
            if response.double_clicked() {
                rt.transform = ViewTransform::default();
            } else if response.clicked()
                && let Some(p) = response.interact_pointer_pos()
            {
                rt.selection = hit(frame, rt, p);
            }
        }
        Tool::Rectangle | Tool::Circle | Tool::Line => {
            if response.drag_started_by(egui::PointerButton::Primary) {
                let origin = ui.input(|i| i.pointer.press_origin()).map(|p| frame.to_mm(p));
                if let Some(start) = origin.or(pointer_mm) {
                    rt.drawing = Some(Drawing::Drag { tool: rt.tool, start_mm: start, end_mm: start });
                }
            }
            if response.dragged_by(egui::PointerButton::Primary)
                && let (Some(Drawing::Drag { end_mm, .. }), Some(p)) = (rt.drawing.as_mut(), pointer_mm)
            {
                *end_mm = p;
            }
            if response.drag_stopped_by(egui::PointerButton::Primary)
                && let Some(Drawing::Drag { tool, start_mm, end_mm }) = rt.drawing.take()
            {
                let end = pointer_mm.unwrap_or(end_mm);
                match state::finish_drag(tool, start_mm, end, min_mm) {
                    Some(Drawn::Region(r)) => {
                        let i = rt.doc.add_region(r);
                        rt.selection = Some(Selection::Region(i));
                    }
                    Some(Drawn::Profile(line)) => {
                        let i = rt.doc.add_profile(line);
                        rt.selection = Some(Selection::Profile(i));
                    }
                    None => {}
                }
            }
        }
        Tool::Polygon => {
            let close = |rt: &mut InspectRuntime| {
                if let Some(Drawing::Polygon { vertices_mm }) = rt.drawing.take()
                    && let Some(region) = state::finish_polygon(&vertices_mm)
                {
                    let i = rt.doc.add_region(region);
                    rt.selection = Some(Selection::Region(i));
                }
            };
            if response.double_clicked() {
                close(rt);
            } else if response.clicked()
                && let Some(p) = response.interact_pointer_pos()
            {
                let mm = frame.to_mm(p);
                let near_first = match &rt.drawing {
                    Some(Drawing::Polygon { vertices_mm }) if vertices_mm.len() >= 3 => {
                        frame.to_screen(vertices_mm[0]).distance(p) < 8.0
                    }
                    _ => false,
                };
                if near_first {
                    close(rt);
                } else if let Some(Drawing::Polygon { vertices_mm }) = rt.drawing.as_mut() {
                    vertices_mm.push(mm);
                } else {
                    rt.drawing = Some(Drawing::Polygon { vertices_mm: vec![mm] });
                }
            }
            if rt.drawing.is_some() && !ui.ctx().egui_wants_keyboard_input() {
                if ui.input(|i| i.key_pressed(egui::Key::Enter)) {
                    close(rt);
                } else if ui.input(|i| i.key_pressed(egui::Key::Escape)) {
                    rt.drawing = None;
                }
            }
        }
        Tool::Horizontal | Tool::Vertical => {
            if response.clicked()
                && let Some(p) = response.interact_pointer_pos()
                && let Some(line) = state::click_profile(rt.tool, frame.to_mm(p))
            {
                let i = rt.doc.add_profile(line);
                rt.selection = Some(Selection::Profile(i));
            }
        }
    }
}

/// The region or profile under a screen position (profiles first: they are thin).
fn hit(frame: &MapFrame, rt: &InspectRuntime, p: Pos2) -> Option<Selection> {
    let map_extent = rt.analysis.value().map(|a| a.map.extent_mm());
    if let Some(extent) = map_extent {
        for (i, item) in rt.doc.profiles.iter().enumerate().rev() {
            let (a, b) = line_ends(&item.spec.line, extent);
            if distance_to_segment(p, frame.to_screen(a), frame.to_screen(b)) < 6.0 {
                return Some(Selection::Profile(i));
            }
        }
    }
    let [x, y] = frame.to_mm(p);
    rt.doc.regions.iter().rposition(|r| r.region.contains(x, y)).map(Selection::Region)
}

fn line_ends(line: &crate::analysis::profile::ProfileLine, extent: ([f64; 2], [f64; 2])) -> ([f64; 2], [f64; 2]) {
    use crate::analysis::profile::ProfileLine;
    let ([x0, y0], [x1, y1]) = extent;
    match *line {
        ProfileLine::Segment { start_mm, end_mm } => (start_mm, end_mm),
        ProfileLine::Horizontal { through_mm: [_, y] } => ([x0, y], [x1, y]),
        ProfileLine::Vertical { through_mm: [x, _] } => ([x, y0], [x, y1]),
    }
}

fn distance_to_segment(p: Pos2, a: Pos2, b: Pos2) -> f32 {
    let ab = b - a;
    let t = if ab.length_sq() > 0.0 { ((p - a).dot(ab) / ab.length_sq()).clamp(0.0, 1.0) } else { 0.0 };
    p.distance(a + ab * t)
}

fn outlined_line(painter: &egui::Painter, a: Pos2, b: Pos2, color: Color32, width: f32) {
    painter.line_segment([a, b], Stroke::new(width + 2.0, Color32::from_black_alpha(200)));
    painter.line_segment([a, b], Stroke::new(width, color));
}

fn label(painter: &egui::Painter, at: Pos2, text: &str, color: Color32) {
    let font = egui::FontId::proportional(12.0);
    let galley = painter.layout_no_wrap(text.to_owned(), font, color);
    let r = Rect::from_min_size(at + vec2(4.0, -galley.size().y - 2.0), galley.size()).expand(2.0);
    painter.rect_filled(r, 2.0, Color32::from_black_alpha(170));
    painter.galley(r.min + vec2(2.0, 2.0), galley, color);
}

fn region_outline(frame: &MapFrame, region: &Region) -> Vec<Pos2> {
    match region {
        Region::Rectangle { x_mm, y_mm } => {
            [[x_mm[0], y_mm[0]], [x_mm[1], y_mm[0]], [x_mm[1], y_mm[1]], [x_mm[0], y_mm[1]]]
                .map(|p| frame.to_screen(p))
                .to_vec()
        }
        Region::Polygon { vertices_mm } => vertices_mm.iter().map(|&p| frame.to_screen(p)).collect(),
        Region::Circle { centre_mm, radius_mm } => (0..72)
            .map(|k| {
                let a = f64::from(k) / 72.0 * std::f64::consts::TAU;
                frame.to_screen([centre_mm[0] + radius_mm * a.cos(), centre_mm[1] + radius_mm * a.sin()])
            })
            .collect(),
    }
}

fn draw_overlays(
    painter: &egui::Painter,
    frame: &MapFrame,
    rt: &InspectRuntime,
    map: &crate::analysis::height_map::HeightMap,
) {
    for (i, item) in rt.doc.regions.iter().enumerate() {
        let color = color32(item.color);
        let selected = rt.selection == Some(Selection::Region(i));
        let outline = region_outline(frame, &item.region.region);
        let width = if selected { 3.0 } else { 1.5 };
        let mut closed = outline.clone();
        if let Some(first) = outline.first() {
            closed.push(*first);
        }
        painter.add(egui::Shape::line(closed.clone(), Stroke::new(width + 2.0, Color32::from_black_alpha(200))));
        painter.add(egui::Shape::line(closed, Stroke::new(width, color)));
        let top_left = outline.iter().fold(pos2(f32::INFINITY, f32::INFINITY), |a, p| pos2(a.x.min(p.x), a.y.min(p.y)));
        let role =
            if item.role == state::RegionRole::None { String::new() } else { format!(" · {}", item.role.name()) };
        label(painter, top_left, &format!("{}{role}", item.region.name), color);
    }
    let extent = map.extent_mm();
    for (i, item) in rt.doc.profiles.iter().enumerate() {
        let color = color32(item.color);
        let (a, b) = line_ends(&item.spec.line, extent);
        let (sa, sb) = (frame.to_screen(a), frame.to_screen(b));
        let selected = rt.selection == Some(Selection::Profile(i));
        if item.spec.width_mm > 0.0 && sa.distance(sb) > 0.0 {
            let n = (sb - sa).normalized().rot90() * (item.spec.width_mm as f32 / 2.0 * frame.px_per_mm());
            for s in [-1.0, 1.0] {
                painter.line_segment([sa + n * s, sb + n * s], Stroke::new(1.0, color.gamma_multiply(0.8)));
            }
        }
        outlined_line(painter, sa, sb, color, if selected { 3.0 } else { 2.0 });
        painter.circle_filled(sa, 3.5, color);
        label(painter, sa, &item.spec.name, color);
    }
    let draw_color = Color32::from_rgb(255, 255, 0);
    match &rt.drawing {
        Some(Drawing::Drag { tool, start_mm, end_mm }) => match state::finish_drag(*tool, *start_mm, *end_mm, 0.0) {
            Some(Drawn::Region(r)) => {
                let mut pts = region_outline(frame, &r);
                if let Some(f) = pts.first().copied() {
                    pts.push(f);
                }
                painter.add(egui::Shape::dashed_line(&pts, Stroke::new(2.0, draw_color), 6.0, 4.0));
            }
            Some(Drawn::Profile(_)) => {
                outlined_line(painter, frame.to_screen(*start_mm), frame.to_screen(*end_mm), draw_color, 2.0)
            }
            None => {}
        },
        Some(Drawing::Polygon { vertices_mm }) => {
            let pts: Vec<Pos2> = vertices_mm.iter().map(|&p| frame.to_screen(p)).collect();
            painter.add(egui::Shape::line(pts.clone(), Stroke::new(2.0, draw_color)));
            for p in pts {
                painter.circle_filled(p, 3.0, draw_color);
            }
        }
        None => {}
    }
}

/// X ticks under the map and Y ticks left of it, in mm.
fn draw_axes(ui: &egui::Ui, rect: Rect, frame: &MapFrame) {
    let painter = ui.painter();
    let color = ui.visuals().text_color();
    let font = egui::FontId::proportional(10.5);
    let [x_lo, y_hi] = frame.to_mm(rect.left_top());
    let [x_hi, y_lo] = frame.to_mm(rect.right_bottom());
    let n_x = ((rect.width() / 80.0) as usize).clamp(2, 10);
    let xt = nice_ticks(x_lo, x_hi, n_x);
    for &t in &xt {
        let x = frame.to_screen([t, 0.0]).x;
        painter.line_segment([pos2(x, rect.bottom()), pos2(x, rect.bottom() + 4.0)], Stroke::new(1.0, color));
        painter.text(pos2(x, rect.bottom() + 4.0), egui::Align2::CENTER_TOP, format_tick(t, &xt), font.clone(), color);
    }
    painter.text(rect.left_bottom() + vec2(2.0 - AXIS_LEFT, 4.0), egui::Align2::LEFT_TOP, "mm", font.clone(), color);
    let n_y = ((rect.height() / 50.0) as usize).clamp(2, 10);
    let yt = nice_ticks(y_lo, y_hi, n_y);
    for &t in &yt {
        let y = frame.to_screen([0.0, t]).y;
        painter.line_segment([pos2(rect.left() - 4.0, y), pos2(rect.left(), y)], Stroke::new(1.0, color));
        painter.text(pos2(rect.left() - 6.0, y), egui::Align2::RIGHT_CENTER, format_tick(t, &yt), font.clone(), color);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::testing::node_map;

    #[test]
    fn screen_and_map_coordinates_agree_and_y_points_up() {
        let map = node_map(50, 40, [1.0, -2.0], 0.01, |_, _| Some(0.0));
        let rect = Rect::from_min_size(pos2(10.0, 20.0), vec2(500.0, 400.0));
        let frame = MapFrame::new(rect, &map, &ViewTransform::default());
        for p in [[1.0, -2.0], [1.49, -1.61], [1.2, -1.8]] {
            let back = frame.to_mm(frame.to_screen(p));
            assert!((back[0] - p[0]).abs() < 1e-6 && (back[1] - p[1]).abs() < 1e-6, "{p:?} -> {back:?}");
        }
        // The first node (smallest Y) is at the bottom left.
        let first = frame.to_screen([1.0, -2.0]);
        assert!(first.x < rect.center().x && first.y > rect.center().y);
        assert!((frame.px_per_mm() - 1000.0).abs() < 1e-2);
    }
}
