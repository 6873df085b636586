//! A camera–projector rig's absolute projector coordinates (issue 52): per
//! camera the projector column (x) or row (y) each pixel sees, the Gray
//! code it decoded to, or why each refused pixel has none (the shadow mask
//! among the reasons); hovering a pixel explains it.

use eframe::egui::{self, Color32, ColorImage};
use rayon::prelude::*;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::textures::key_of;
use crate::app::widgets::legend::{Legend, LegendEntry};
use crate::engine::fringe::FringeStack;
use crate::engine::gray_code::GrayRefusal;
use crate::engine::projector_coordinate::CoordinateRefusal;

use super::{MapSpec, Pane, View, ViewCx, paint_continuous, percent};

/// Which projector axis is shown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Axis {
    #[default]
    X,
    Y,
}

/// What of the axis is shown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Layer {
    /// The absolute projector coordinate.
    #[default]
    Coordinate,
    /// The decoded Gray code cell.
    GrayCode,
    /// Why each pixel was refused, by reason.
    Refusals,
    /// One bit plane of the code as recorded: its pattern frame minus its
    /// inverse (bright where the bit is 1, dark where 0, grey where the
    /// two are too close to decide).
    GrayBit,
}

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ProjectorView {
    pub axis: Axis,
    pub layer: Layer,
    /// The bit plane [`Layer::GrayBit`] shows, most significant first.
    pub bit_plane: usize,
}

/// The colour of each refusal class, and of a measured pixel.
const CLASSES: [(Color32, &str); 6] = [
    (palette::MASK_TRUE, "measured"),
    (palette::MASK_FALSE, "shadow"),
    (Color32::from_rgb(230, 159, 0), "Gray code undecided"),
    (Color32::from_rgb(86, 180, 233), "no phase"),
    (Color32::from_rgb(213, 94, 0), "sets disagree"),
    (Color32::from_rgb(204, 121, 167), "outside the cell"),
];

fn class(refusal: Option<CoordinateRefusal>) -> usize {
    match refusal {
        None => 0,
        Some(CoordinateRefusal::Code(GrayRefusal::Shadow)) => 1,
        Some(CoordinateRefusal::Code(_)) => 2,
        Some(CoordinateRefusal::NoPhase) => 3,
        Some(CoordinateRefusal::SetsDisagree) => 4,
        Some(CoordinateRefusal::OutsideCell) => 5,
    }
}

impl View for ProjectorView {
    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        ui.label("Projector axis");
        ui.selectable_value(&mut self.axis, Axis::X, "x (columns)");
        ui.selectable_value(&mut self.axis, Axis::Y, "y (rows)");
        ui.separator();
        ui.selectable_value(&mut self.layer, Layer::Coordinate, "Coordinate");
        ui.selectable_value(&mut self.layer, Layer::GrayCode, "Gray code");
        ui.selectable_value(&mut self.layer, Layer::GrayBit, "Gray bits");
        ui.selectable_value(&mut self.layer, Layer::Refusals, "Refused pixels");
        let planes = bit_planes(cx, self.axis);
        if self.layer == Layer::GrayBit && planes > 0 {
            self.bit_plane = self.bit_plane.min(planes - 1);
            ui.add(egui::DragValue::new(&mut self.bit_plane).range(0..=planes - 1).prefix("bit plane "))
                .on_hover_text("0 is the most significant bit (the coarsest stripes).");
        }
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let axis_name = if self.axis == Axis::X { "x" } else { "y" };
        cameras
            .iter()
            .map(|&camera| {
                let title = format!("{} · projector {axis_name}", cx.camera_name(camera));
                let Some(result) = cx.result else {
                    return Pane::message(camera, title, "No result yet.");
                };
                let maps = match &result.reconstruction.projector {
                    None => {
                        return Pane::message(
                            camera,
                            title,
                            "Projector coordinates need a camera–projector rig with a Gray code (the manifest's \
                             \"rig\", \"projector\" and \"gray_code\"; `sheen import --projector --gray-code`).",
                        );
                    }
                    Some(Err(e)) => return Pane::message(camera, title, format!("No projector coordinates: {e}")),
                    Some(Ok(maps)) => maps,
                };
                let Some(cam) = maps.get(camera) else {
                    return Pane::message(camera, title, "No such camera in the result.");
                };
                let (coordinate, code) =
                    if self.axis == Axis::X { (&cam.x, &cam.code_x) } else { (&cam.y, &cam.code_y) };
                let (Some(coordinate), Some(code)) = (coordinate, code) else {
                    return Pane::message(
                        camera,
                        title,
                        format!("The capture has no projector {axis_name}: no row code or no sets along y."),
                    );
                };
                let size = [coordinate.width, coordinate.height];
                let (lit, measured) = coordinate.lit_and_measured();
                let footer = Some(format!(
                    "{} of the lit pixels measured ({measured} of {lit}) · {} lit",
                    percent(measured, lit),
                    percent(lit, coordinate.refusal.len())
                ));
                let values = &coordinate.coordinate_px;
                let refusal = &coordinate.refusal;
                let cells = &code.cells;
                // Hovering explains the pixel: its coordinate and cell, or why it has none.
                let probe = Box::new(move |p: usize| coordinate.explain_pixel(code, axis_name, p));
                let key = key_of(&("projector", cx.generation(), camera, self.axis, self.layer));
                let (paint, legend): (Box<dyn FnOnce() -> ColorImage + 'a>, Legend) = match self.layer {
                    Layer::Coordinate => {
                        // Ranges once per result, not on every frame the view is drawn.
                        let (lo, hi) = cx
                            .memo_range(("projector coordinate", camera, self.axis), || Some(finite_range(values)))
                            .unwrap_or((0.0, 1.0));
                        let lut = palette::lut(Colormap::Turbo);
                        (
                            Box::new(move || paint_continuous(values, size, lut, lo, hi)),
                            Legend::bar(lut, f64::from(lo), f64::from(hi), "projector px"),
                        )
                    }
                    Layer::GrayCode => {
                        let (lo, hi) = cx
                            .memo_range(("projector cells", camera, self.axis), || {
                                let (lo, hi) =
                                    cells.iter().flatten().fold((u32::MAX, 0), |(lo, hi), &c| (lo.min(c), hi.max(c)));
                                (lo < hi).then_some((lo as f32, hi as f32))
                            })
                            .unwrap_or((0.0, 1.0));
                        let lut = palette::lut(Colormap::Turbo);
                        (
                            Box::new(move || {
                                let as_f32: Vec<f32> =
                                    cells.par_iter().map(|c| c.map_or(f32::NAN, |c| c as f32)).collect();
                                paint_continuous(&as_f32, size, lut, lo, hi)
                            }),
                            Legend::bar(lut, f64::from(lo), f64::from(hi), "cell"),
                        )
                    }
                    Layer::GrayBit => {
                        let Some(stack) = code_frames(cx, camera, self.axis) else {
                            return Pane::message(camera, title, "The capture has no Gray code frames for this axis.");
                        };
                        let plane = self.bit_plane.min((stack.shifts / 2).saturating_sub(1));
                        let difference = move |p: usize| {
                            f32::from(stack.sample(2 * plane, p)) - f32::from(stack.sample(2 * plane + 1, p))
                        };
                        // Scaled to the bulk of the pixels (a specular glint would grey out the rest).
                        let reach = cx
                            .memo_range(("projector bit plane", camera, self.axis, plane), || {
                                let values: Vec<f32> =
                                    (0..stack.pixel_count()).into_par_iter().map(difference).collect();
                                let (lo, hi) = super::robust_range(&values, 0.01, 0.99)?;
                                let reach = lo.abs().max(hi.abs()).max(1.0);
                                Some((-reach, reach))
                            })
                            .map_or(1.0, |r| r.1);
                        let lut = palette::lut(Colormap::Gray);
                        let key = key_of(&("projector bit", cx.generation(), camera, self.axis, plane));
                        let probe = Box::new(move |p: usize| {
                            let (pattern, inverse) = (stack.sample(2 * plane, p), stack.sample(2 * plane + 1, p));
                            format!("bit plane {plane}: pattern {pattern} − inverse {inverse} dn")
                        });
                        let footer = Some(format!(
                            "bit plane {plane} of {} (most significant first): pattern minus inverse",
                            stack.shifts / 2
                        ));
                        let paint: Box<dyn FnOnce() -> ColorImage + 'a> = Box::new(move || {
                            let values: Vec<f32> = (0..stack.pixel_count()).into_par_iter().map(difference).collect();
                            paint_continuous(&values, size, lut, -reach, reach)
                        });
                        let legend = Legend::bar(lut, f64::from(-reach), f64::from(reach), "dn");
                        return Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer });
                    }
                    Layer::Refusals => {
                        let mut counts = [0usize; CLASSES.len()];
                        refusal.iter().for_each(|r| counts[class(*r)] += 1);
                        let total = refusal.len();
                        let entries = CLASSES
                            .iter()
                            .zip(counts)
                            .map(|((color, label), n)| LegendEntry {
                                color: *color,
                                label: format!("{label}: {}", percent(n, total)),
                            })
                            .collect();
                        (
                            Box::new(move || {
                                ColorImage::new(size, refusal.par_iter().map(|r| CLASSES[class(*r)].0).collect())
                            }),
                            Legend::classes(entries),
                        )
                    }
                };
                Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })
            })
            .collect()
    }
}

/// The code frames of an axis for a camera: pattern then inverse per plane.
fn code_frames<'a>(cx: &ViewCx<'a>, camera: usize, axis: Axis) -> Option<&'a FringeStack> {
    let frames = cx.measurement.projector.as_ref()?.cameras.get(camera)?;
    if axis == Axis::X { frames.gray_columns.as_ref() } else { frames.gray_rows.as_ref() }
}

/// Bit planes of an axis's code in the first camera (0 without a code).
fn bit_planes(cx: &ViewCx<'_>, axis: Axis) -> usize {
    code_frames(cx, 0, axis).map_or(0, |stack| stack.shifts / 2)
}

fn finite_range(values: &[f32]) -> (f32, f32) {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo < hi { (lo, hi) } else { (0.0, 1.0) }
}
