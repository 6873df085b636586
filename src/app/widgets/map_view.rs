//! The zoomable, pannable image of one camera map: mouse wheel zooms about the
//! cursor, dragging pans, double-click fits; hovering reports the pixel under
//! the cursor and clicking selects it.
//!
//! The zoom and pan live in a [`ViewTransform`] the caller owns per camera,
//! so every map of the same camera shows the same region (synchronised views).

use eframe::egui::{self, Color32, Pos2, Rect, Sense, Stroke, Vec2, pos2, vec2};

/// Zoom and pan of a camera's maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewTransform {
    /// Magnification relative to "fit the whole image" (1 = fit).
    pub zoom: f32,
    /// Image position (pixels, continuous) at the centre of the view; `None`
    /// = the image centre.
    pub center_px: Option<Vec2>,
}

impl Default for ViewTransform {
    fn default() -> Self {
        Self { zoom: 1.0, center_px: None }
    }
}

/// Zoom limits relative to fit.
const MIN_ZOOM: f32 = 0.5;
const MAX_ZOOM: f32 = 256.0;
/// Zoom factor per scrolled point.
const WHEEL_ZOOM_PER_POINT: f32 = 0.0025;

/// Where an image of `size` pixels lands on screen inside `rect`.
pub fn image_rect(rect: Rect, size: [usize; 2], t: &ViewTransform) -> Rect {
    let (w, h) = (size[0].max(1) as f32, size[1].max(1) as f32);
    let scale = fit_scale(rect, size) * t.zoom;
    let center = t.center_px.unwrap_or(vec2(w / 2.0, h / 2.0));
    Rect::from_min_size(rect.center() - center * scale, vec2(w, h) * scale)
}

/// Screen points per image pixel at zoom 1.
fn fit_scale(rect: Rect, size: [usize; 2]) -> f32 {
    let (w, h) = (size[0].max(1) as f32, size[1].max(1) as f32);
    (rect.width() / w).min(rect.height() / h).max(1e-6)
}

/// The image pixel `(u, v)` under a screen position, if inside the image.
pub fn pixel_at(image_rect: Rect, size: [usize; 2], pos: Pos2) -> Option<[usize; 2]> {
    let rel = (pos - image_rect.min) / image_rect.size();
    let (u, v) = ((rel.x * size[0] as f32).floor(), (rel.y * size[1] as f32).floor());
    (u >= 0.0 && v >= 0.0 && u < size[0] as f32 && v < size[1] as f32).then_some([u as usize, v as usize])
}

/// Screen position of the centre of pixel `(u, v)`.
pub fn pixel_center(image_rect: Rect, size: [usize; 2], [u, v]: [usize; 2]) -> Pos2 {
    let s = image_rect.size() / vec2(size[0].max(1) as f32, size[1].max(1) as f32);
    image_rect.min + vec2((u as f32 + 0.5) * s.x, (v as f32 + 0.5) * s.y)
}

pub struct MapResponse {
    /// The whole widget area.
    pub rect: Rect,
    pub hovered: Option<[usize; 2]>,
    pub clicked: Option<[usize; 2]>,
}

/// Draws `texture` (an image of `size` pixels) into the next `desired` area.
/// `label` names the map for screen readers and tests; `marker` is a
/// selected pixel to draw a crosshair at.
pub fn show(
    ui: &mut egui::Ui,
    label: &str,
    texture: &egui::TextureHandle,
    size: [usize; 2],
    transform: &mut ViewTransform,
    marker: Option<[usize; 2]>,
    desired: Vec2,
) -> MapResponse {
    let (rect, response) = ui.allocate_exact_size(desired, Sense::click_and_drag());
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, label));

    if response.double_clicked() {
        *transform = ViewTransform::default();
    }
    if response.hovered() {
        let (scroll, pinch) = ui.input(|i| (i.smooth_scroll_delta.y, i.zoom_delta()));
        let factor = (scroll * WHEEL_ZOOM_PER_POINT).exp() * pinch;
        if (factor - 1.0).abs() > 1e-4
            && let Some(pointer) = response.hover_pos()
        {
            zoom_about(transform, rect, size, pointer, factor);
        }
    }
    if response.dragged() {
        let delta = response.drag_delta();
        if delta != Vec2::ZERO {
            let scale = fit_scale(rect, size) * transform.zoom;
            let center = transform.center_px.unwrap_or(vec2(size[0] as f32 / 2.0, size[1] as f32 / 2.0));
            transform.center_px = Some(center - delta / scale);
        }
    }

    let img = image_rect(rect, size, transform);
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, ui.visuals().extreme_bg_color);
    painter.image(texture.id(), img, Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)), Color32::WHITE);

    let hovered = response.hover_pos().and_then(|p| pixel_at(img, size, p));
    let clicked =
        if response.clicked() { response.interact_pointer_pos().and_then(|p| pixel_at(img, size, p)) } else { None };

    if let Some(pixel) = marker {
        let c = pixel_center(img, size, pixel);
        let half_px = (img.width() / size[0].max(1) as f32 / 2.0).max(3.0);
        let outer = Stroke::new(3.0, Color32::BLACK);
        let inner = Stroke::new(1.5, Color32::from_rgb(0, 230, 255));
        for stroke in [outer, inner] {
            painter.circle_stroke(c, half_px + 4.0, stroke);
            painter.line_segment([c - vec2(half_px + 10.0, 0.0), c - vec2(half_px + 4.0, 0.0)], stroke);
            painter.line_segment([c + vec2(half_px + 4.0, 0.0), c + vec2(half_px + 10.0, 0.0)], stroke);
            painter.line_segment([c - vec2(0.0, half_px + 10.0), c - vec2(0.0, half_px + 4.0)], stroke);
            painter.line_segment([c + vec2(0.0, half_px + 4.0), c + vec2(0.0, half_px + 10.0)], stroke);
        }
    }
    if transform.zoom != 1.0 {
        painter.text(
            rect.right_bottom() - vec2(4.0, 4.0),
            egui::Align2::RIGHT_BOTTOM,
            format!("{:.1}x", transform.zoom),
            egui::FontId::proportional(11.0),
            ui.visuals().weak_text_color(),
        );
    }
    MapResponse { rect, hovered, clicked }
}

/// Zooms by `factor` keeping the image point under `pointer` fixed.
fn zoom_about(t: &mut ViewTransform, rect: Rect, size: [usize; 2], pointer: Pos2, factor: f32) {
    let old_scale = fit_scale(rect, size) * t.zoom;
    let new_zoom = (t.zoom * factor).clamp(MIN_ZOOM, MAX_ZOOM);
    let new_scale = fit_scale(rect, size) * new_zoom;
    let center = t.center_px.unwrap_or(vec2(size[0] as f32 / 2.0, size[1] as f32 / 2.0));
    let offset = pointer - rect.center();
    let under_pointer = center + offset / old_scale;
    t.center_px = Some(under_pointer - offset / new_scale);
    t.zoom = new_zoom;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect() -> Rect {
        Rect::from_min_size(pos2(10.0, 20.0), vec2(400.0, 300.0))
    }

    #[test]
    fn fit_centres_the_image_and_maps_pixels_both_ways() {
        let size = [160, 120];
        let img = image_rect(rect(), size, &ViewTransform::default());
        assert!((img.center() - rect().center()).length() < 1e-4);
        assert!((img.width() - 400.0).abs() < 1e-3 && (img.height() - 300.0).abs() < 1e-3);
        for pixel in [[0, 0], [159, 119], [37, 81]] {
            assert_eq!(pixel_at(img, size, pixel_center(img, size, pixel)), Some(pixel));
        }
        assert_eq!(pixel_at(img, size, pos2(5.0, 25.0)), None);
    }

    #[test]
    fn zooming_keeps_the_pixel_under_the_pointer() {
        let size = [160, 120];
        let mut t = ViewTransform::default();
        let pointer = pos2(100.0, 90.0);
        let before = pixel_at(image_rect(rect(), size, &t), size, pointer);
        zoom_about(&mut t, rect(), size, pointer, 4.0);
        assert_eq!(t.zoom, 4.0);
        let img = image_rect(rect(), size, &t);
        assert_eq!(pixel_at(img, size, pointer), before);
        assert!((img.width() - 1600.0).abs() < 1e-2);
    }

    #[test]
    fn zoom_is_clamped() {
        let mut t = ViewTransform::default();
        zoom_about(&mut t, rect(), [10, 10], rect().center(), 1e9);
        assert_eq!(t.zoom, MAX_ZOOM);
        zoom_about(&mut t, rect(), [10, 10], rect().center(), 1e-12);
        assert_eq!(t.zoom, MIN_ZOOM);
    }
}
