//! The map views of the central area, one file per view. Each view struct
//! owns its (persisted) settings and turns the session data into *panes*: a
//! map per camera (or per method) with its colour legend and a per-pixel
//! probe for the hover read-out. This module draws the panes: textures via
//! the cache, zoom/pan synchronised per camera, hover, click-to-select.
//!
//! Views never import each other; they share only the helpers here and the
//! widgets. A new view is one more file, one more [`ViewKind`] and one more
//! field in [`ViewsState`]. The 3D point cloud fits the same way:
//! its settings (camera, colouring, point size) go in its view struct, its GPU
//! buffers in a runtime resource next to the texture cache (never in the
//! persisted state), and it draws through a [`PaneContent`] variant of its own
//! that hands the pane's `Ui` to an `egui_wgpu` paint callback.

mod cloud;
mod compare;
mod fused;
mod height;
pub mod history;
pub mod inspect;
pub mod line;
mod modulation;
mod projector;
mod raw;
mod saturation;
mod sources;
mod uncertainty;
mod unwrapped;
mod valid;
mod wrapped;

use std::cell::RefCell;
use std::collections::HashMap;
use std::hash::Hash;

use eframe::egui::{self, Color32, ColorImage, vec2};

use crate::engine::fringe::Measurement;
use crate::engine::pipeline::{CameraPhase, Params};

use super::commands::{Command, PixelRef};
use super::palette::{self, LUT_SIZE};
use super::run_data::{CompareOutput, ResultSet};
use super::state::CameraLayout;
use super::textures::{TextureCache, key_of};
use super::widgets::legend::{self, Legend};
use super::widgets::map_view::{self, ViewTransform};

pub use cloud::{CloudRuntime, CloudView, ColorBy, OrbitCamera, PointInfo, Projection, ViewPreset};
pub use compare::CompareView;
pub use fused::FusedView;
pub use height::HeightView;
pub use history::{HistoryRuntime, HistoryView};
pub use inspect::{InspectRuntime, InspectView};
pub use line::{LineRuntime, LineView};
pub use modulation::ModulationView;
pub use projector::ProjectorView;
pub use raw::RawView;
pub use saturation::SaturationView;
pub use sources::SourcesView;
pub use uncertainty::UncertaintyView;
pub use unwrapped::UnwrappedView;
pub use valid::ValidView;
pub use wrapped::WrappedView;

/// The views, in tab order (the method's order: raw data to 3D).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum ViewKind {
    #[default]
    Raw,
    Saturation,
    Wrapped,
    Modulation,
    Uncertainty,
    Unwrapped,
    Fused,
    Sources,
    Valid,
    /// A camera–projector rig's absolute projector coordinates.
    Projector,
    Height,
    Cloud,
    Compare,
    /// Quality control on the height map.
    Inspect,
    /// The inspection records over time.
    History,
    /// The production line: a watched inbox, part after part.
    Line,
}

impl ViewKind {
    pub const ALL: [ViewKind; 16] = [
        ViewKind::Raw,
        ViewKind::Saturation,
        ViewKind::Wrapped,
        ViewKind::Modulation,
        ViewKind::Uncertainty,
        ViewKind::Unwrapped,
        ViewKind::Fused,
        ViewKind::Sources,
        ViewKind::Valid,
        ViewKind::Projector,
        ViewKind::Height,
        ViewKind::Cloud,
        ViewKind::Compare,
        ViewKind::Inspect,
        ViewKind::History,
        ViewKind::Line,
    ];

    pub fn title(self) -> &'static str {
        match self {
            ViewKind::Raw => "Raw",
            ViewKind::Saturation => "Saturation",
            ViewKind::Wrapped => "Wrapped phase",
            ViewKind::Modulation => "Modulation",
            ViewKind::Uncertainty => "Uncertainty",
            ViewKind::Unwrapped => "Unwrapped",
            ViewKind::Fused => "Fused phase",
            ViewKind::Sources => "Sources",
            ViewKind::Valid => "Valid",
            ViewKind::Projector => "Projector",
            ViewKind::Height => "Height",
            ViewKind::Cloud => "3D",
            ViewKind::Compare => "Compare",
            ViewKind::Inspect => "Inspect",
            ViewKind::History => "History",
            ViewKind::Line => "Line",
        }
    }

    pub fn tooltip(self) -> &'static str {
        match self {
            ViewKind::Raw => "The fringe images as recorded; saturated samples in magenta.",
            ViewKind::Saturation => {
                "Saturated samples per pixel (Alg. 1) and the pixels left with fewer than 3 usable."
            }
            ViewKind::Wrapped => "Wrapped phase of one fringe set (Alg. 2), on a cyclic colour map.",
            ViewKind::Modulation => "Fitted fringe modulation B per pixel: low values mean noisy phase.",
            ViewKind::Uncertainty => "Standard deviation of the wrapped phase predicted from noise and fit.",
            ViewKind::Unwrapped => "Absolute phase of one set after hierarchical unwrapping (Alg. 3).",
            ViewKind::Fused => "Final absolute phase after HDR fusion, in radians of the densest period.",
            ViewKind::Sources => "Which fringe set supplied each pixel's phase, and where none could.",
            ViewKind::Valid => "Pixels with a valid final phase.",
            ViewKind::Projector => {
                "A camera–projector rig: the absolute projector column or row each pixel sees, its Gray code, and \
                 why refused pixels have none."
            }
            ViewKind::Height => "Height Z of the 3D points, drawn at their left-camera pixel.",
            ViewKind::Cloud => "The 3D point cloud: orbit, pan, zoom, colour by height or quality, click a point.",
            ViewKind::Compare => "Two methods side by side with their completeness (the paper's Fig. 5).",
            ViewKind::Inspect => {
                "Quality control: height map, regions, section profiles, levelling, flatness, step height, \
                 coplanarity, exports."
            }
            ViewKind::History => {
                "The recorded parts of a recipe over time: trend with tolerance and control limits, histogram with \
                 Cp/Cpk, the parts table; click a point to open that part."
            }
            ViewKind::Line => {
                "The production line: watch an inbox with a recipe; each part's verdict, height map with the regions \
                 where the part was found, the last 50 parts and the trends."
            }
        }
    }
}

/// The set and shift the per-set views show (keyboard: [ ] and arrows).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SetCursor {
    pub set: usize,
    pub shift: usize,
}

impl SetCursor {
    /// The cursor clamped to the sets and shifts of `m`.
    pub fn clamped(self, m: &Measurement) -> Self {
        let set = self.set.min(m.sets.len().saturating_sub(1));
        let shifts = m.sets.get(set).map_or(1, |s| s.shifts());
        Self { set, shift: self.shift.min(shifts.saturating_sub(1)) }
    }

    pub fn step_set(&mut self, m: &Measurement, delta: i32) {
        let n = m.sets.len().max(1) as i64;
        self.set = (self.set as i64 + i64::from(delta)).rem_euclid(n) as usize;
        *self = self.clamped(m);
    }

    pub fn step_shift(&mut self, m: &Measurement, delta: i32) {
        let c = self.clamped(m);
        let n = m.sets.get(c.set).map_or(1, |s| s.shifts()).max(1) as i64;
        self.shift = (c.shift as i64 + i64::from(delta)).rem_euclid(n) as usize;
    }
}

/// Every view's settings, persisted.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ViewsState {
    pub active: ViewKind,
    pub cameras: CameraLayout,
    pub cursor: SetCursor,
    pub raw: RawView,
    pub saturation: SaturationView,
    pub wrapped: WrappedView,
    pub modulation: ModulationView,
    pub uncertainty: UncertaintyView,
    pub unwrapped: UnwrappedView,
    pub fused: FusedView,
    pub sources: SourcesView,
    pub valid: ValidView,
    pub projector: ProjectorView,
    pub height: HeightView,
    pub cloud: CloudView,
    pub compare: CompareView,
    pub inspect: InspectView,
    pub history: HistoryView,
    pub line: LineView,
}

/// What the views read: all borrowed from the session for one frame.
pub struct ViewCx<'a> {
    pub measurement: &'a Measurement,
    pub measurement_generation: u64,
    pub result: Option<&'a ResultSet>,
    pub compare: Option<&'a CompareOutput>,
    pub compare_busy: bool,
    /// The parameters being edited (the result may still be for older ones).
    pub params: &'a Params,
    pub cursor: SetCursor,
    /// The cameras the panes show (from the camera layout).
    pub shown: Vec<usize>,
    /// Automatic colour ranges already computed, by [`ViewCx::memo_range`] key.
    pub ranges: &'a RefCell<HashMap<u64, Option<(f32, f32)>>>,
}

/// Why a view has no phase result of a camera to draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NoPhase {
    #[error("No result yet: the engine is running or has not run.")]
    NoResult,
    #[error("The result has no camera {0}.")]
    NoCamera(usize),
}

impl From<NoPhase> for String {
    fn from(why: NoPhase) -> String {
        why.to_string()
    }
}

impl<'a> ViewCx<'a> {
    /// The phase result of `camera`, or why a pane shows a message instead.
    pub fn camera_phase(&self, camera: usize) -> Result<&'a CameraPhase, NoPhase> {
        let result = self.result.ok_or(NoPhase::NoResult)?;
        result.reconstruction.cameras.get(camera).ok_or(NoPhase::NoCamera(camera))
    }

    pub fn camera_name(&self, camera: usize) -> &'a str {
        self.measurement.cameras.get(camera).map_or("?", |c| c.name.as_str())
    }

    pub fn camera_size(&self, camera: usize) -> [usize; 2] {
        self.measurement.cameras.get(camera).map_or([1, 1], |c| [c.width, c.height])
    }

    pub fn period_px(&self, set: usize) -> f64 {
        self.measurement.sets.get(set).map_or(f64::NAN, |s| s.period_px)
    }

    pub fn generation(&self) -> u64 {
        self.result.map_or(0, |r| r.generation)
    }

    /// An automatic colour range, computed once per result, set and camera
    /// layout (`key` names the quantity) instead of once per frame.
    pub fn memo_range(&self, key: impl Hash, compute: impl FnOnce() -> Option<(f32, f32)>) -> Option<(f32, f32)> {
        let k = key_of(&(key, self.generation(), self.measurement_generation, self.cursor.set, &self.shown));
        if let Some(range) = self.ranges.borrow().get(&k) {
            return *range;
        }
        let range = compute();
        let mut memo = self.ranges.borrow_mut();
        if memo.len() > 256 {
            memo.clear();
        }
        memo.insert(k, range);
        range
    }

    /// One robust range over the maps of all shown cameras, so side-by-side
    /// panes share their colour scale (memoized under `key`).
    pub fn shown_range(
        &self,
        key: &str,
        quantiles: (f64, f64),
        map_of: impl Fn(usize) -> Option<&'a [f32]>,
    ) -> Option<(f32, f32)> {
        self.memo_range((key, quantiles.0.to_bits(), quantiles.1.to_bits()), || {
            joint_range(self.shown.iter().filter_map(|&c| map_of(c)), quantiles)
        })
    }
}

/// The robust range over several maps (the union of each one's quantile range).
pub fn joint_range<'m>(maps: impl Iterator<Item = &'m [f32]>, (lo_q, hi_q): (f64, f64)) -> Option<(f32, f32)> {
    let ranges: Vec<(f32, f32)> = maps.filter_map(|m| robust_range(m, lo_q, hi_q)).collect();
    let lo = ranges.iter().map(|r| r.0).fold(f32::INFINITY, f32::min);
    let hi = ranges.iter().map(|r| r.1).fold(f32::NEG_INFINITY, f32::max);
    (lo.is_finite() && hi >= lo).then_some((lo, hi))
}

/// A map ready to draw.
pub struct MapSpec<'a> {
    pub size: [usize; 2],
    /// Hash of everything the image depends on: a new key rebuilds the texture.
    pub key: u64,
    pub paint: Box<dyn FnOnce() -> ColorImage + 'a>,
    /// Text for the value at a linear pixel index, for the hover read-out.
    pub probe: Box<dyn Fn(usize) -> String + 'a>,
    pub legend: Legend,
    /// A line under the map (e.g. completeness).
    pub footer: Option<String>,
}

/// A pane that draws itself, with the runtime resources.
pub type PaneDraw<'a> = Box<dyn FnOnce(&mut egui::Ui, &mut ViewRuntime<'_>) + 'a>;

pub enum PaneContent<'a> {
    Map(MapSpec<'a>),
    /// Drawn by the view itself into the pane (the 3D cloud, through wgpu).
    Custom(PaneDraw<'a>),
    /// Why there is nothing to show.
    Message(String),
}

pub struct Pane<'a> {
    pub camera: usize,
    pub title: String,
    pub content: PaneContent<'a>,
}

impl<'a> Pane<'a> {
    pub fn message(camera: usize, title: impl Into<String>, text: impl Into<String>) -> Self {
        Self { camera, title: title.into(), content: PaneContent::Message(text.into()) }
    }

    pub fn map(camera: usize, title: impl Into<String>, spec: MapSpec<'a>) -> Self {
        Self { camera, title: title.into(), content: PaneContent::Map(spec) }
    }
}

/// What every view does.
pub trait View {
    /// Whether the set picker applies.
    fn uses_set(&self) -> bool {
        false
    }

    /// Whether the shift picker applies.
    fn uses_shift(&self) -> bool {
        false
    }

    /// The view's own controls, above the maps.
    fn controls(&mut self, _ui: &mut egui::Ui, _cx: &ViewCx<'_>) {}

    /// The panes to draw for `cameras`.
    fn panes<'a>(&self, cx: &ViewCx<'a>, cameras: &[usize], commands: &mut Vec<Command>) -> Vec<Pane<'a>>;
}

impl ViewsState {
    fn view_mut(&mut self, kind: ViewKind) -> &mut dyn View {
        match kind {
            ViewKind::Raw => &mut self.raw,
            ViewKind::Saturation => &mut self.saturation,
            ViewKind::Wrapped => &mut self.wrapped,
            ViewKind::Modulation => &mut self.modulation,
            ViewKind::Uncertainty => &mut self.uncertainty,
            ViewKind::Unwrapped => &mut self.unwrapped,
            ViewKind::Fused => &mut self.fused,
            ViewKind::Sources => &mut self.sources,
            ViewKind::Valid => &mut self.valid,
            ViewKind::Projector => &mut self.projector,
            ViewKind::Height => &mut self.height,
            ViewKind::Cloud => &mut self.cloud,
            ViewKind::Compare => &mut self.compare,
            ViewKind::Inspect => &mut self.inspect,
            ViewKind::History => &mut self.history,
            ViewKind::Line => &mut self.line,
        }
    }
}

/// Runtime resources the views draw with (not persisted).
pub struct ViewRuntime<'r> {
    pub textures: &'r mut TextureCache,
    /// Zoom and pan per camera, shared by all maps of that camera.
    pub transforms: &'r mut HashMap<usize, ViewTransform>,
    pub selection: Option<PixelRef>,
    pub commands: &'r mut Vec<Command>,
    /// The 3D view's GPU resources, camera and picking state.
    pub cloud: &'r mut CloudRuntime,
    /// The Inspect view's inspection, computations and file jobs.
    pub inspect: &'r mut InspectRuntime,
    /// The History view's records.
    pub history: &'r mut HistoryRuntime,
    /// The Line view's running watch.
    pub line: &'r mut LineRuntime,
}

/// Draws the view tabs, the active view's controls and its panes.
pub fn show(ui: &mut egui::Ui, views: &mut ViewsState, cx: &ViewCx<'_>, rt: ViewRuntime<'_>) {
    ui.horizontal_wrapped(|ui| {
        for kind in ViewKind::ALL {
            ui.selectable_value(&mut views.active, kind, kind.title()).on_hover_text(kind.tooltip());
        }
    });
    ui.separator();
    if views.active == ViewKind::Line {
        line::show(ui, &mut views.line, &views.inspect.record, rt.line);
        return;
    }
    if views.active == ViewKind::History {
        let written = rt.inspect.records_written();
        history::show(ui, &mut views.history, &views.inspect.record, written, rt.history, rt.commands);
        return;
    }
    if views.inspect.record.always && views.active != ViewKind::Inspect {
        // "Always record" measures each new result even while another view is shown.
        let ctx = ui.ctx().clone();
        rt.inspect.update(cx, views.inspect.fill_holes, move || ctx.request_repaint());
    }
    if views.active == ViewKind::Inspect {
        // The height map is the left camera's cloud: no camera or set pickers.
        inspect::show(ui, &mut views.inspect, cx, rt);
        return;
    }
    let cameras_available = cx.measurement.cameras.len();
    let mut cursor = cx.cursor.clamped(cx.measurement);
    ui.horizontal_wrapped(|ui| {
        if cameras_available > 1 {
            let first = cx.camera_name(0).to_owned();
            let second = cx.camera_name(1).to_owned();
            ui.label("Camera:");
            ui.selectable_value(&mut views.cameras, CameraLayout::Main, first)
                .on_hover_text("Show the main (left) camera.");
            ui.selectable_value(&mut views.cameras, CameraLayout::Second, second)
                .on_hover_text("Show the second (right) camera.");
            ui.selectable_value(&mut views.cameras, CameraLayout::SideBySide, "Side by side")
                .on_hover_text("Show both cameras next to each other.");
            ui.separator();
        }
        let active = views.active;
        let view = views.view_mut(active);
        if view.uses_set() {
            set_picker(ui, cx.measurement, &mut cursor);
        }
        if view.uses_shift() {
            shift_picker(ui, cx.measurement, &mut cursor);
        }
    });
    if cursor != cx.cursor.clamped(cx.measurement) {
        views.cursor = cursor;
    }
    let cameras = views.cameras.cameras(cameras_available);
    let cx = ViewCx {
        measurement: cx.measurement,
        measurement_generation: cx.measurement_generation,
        result: cx.result,
        compare: cx.compare,
        compare_busy: cx.compare_busy,
        params: cx.params,
        cursor: views.cursor.clamped(cx.measurement),
        shown: cameras.clone(),
        ranges: cx.ranges,
    };
    let active = views.active;
    let view = views.view_mut(active);
    ui.horizontal_wrapped(|ui| view.controls(ui, &cx));
    ui.add_space(4.0);
    let panes = view.panes(&cx, &cameras, rt.commands);
    draw_panes(ui, active, panes, rt);
}

fn set_picker(ui: &mut egui::Ui, m: &Measurement, cursor: &mut SetCursor) {
    ui.label("Set:");
    let current = m.sets.get(cursor.set).map_or_else(String::new, |s| set_label(cursor.set, s.period_px));
    egui::ComboBox::from_id_salt("set picker")
        .selected_text(current)
        .show_ui(ui, |ui| {
            for (i, s) in m.sets.iter().enumerate() {
                ui.selectable_value(&mut cursor.set, i, set_label(i, s.period_px));
            }
        })
        .response
        .on_hover_text("Fringe set to show (PageUp/PageDown or [ and ] step through the sets).")
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, "Set"));
}

fn shift_picker(ui: &mut egui::Ui, m: &Measurement, cursor: &mut SetCursor) {
    let shifts = m.sets.get(cursor.set).map_or(1, |s| s.shifts());
    ui.label("Shift:");
    let mut shown = cursor.shift + 1;
    let response = ui
        .add(egui::DragValue::new(&mut shown).range(1..=shifts).suffix(format!(" / {shifts}")))
        .on_hover_text("Phase-shifted image to show (Left/Right arrows step through the shifts).");
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Shift"));
    cursor.shift = shown.saturating_sub(1);
    if let Some(set) = m.sets.get(cursor.set)
        && let Some(delta) = set.phase_shifts_rad.get(cursor.shift)
    {
        ui.weak(format!("δ = {delta:.3} rad"));
    }
}

/// "set 2 · 24 px".
pub fn set_label(set: usize, period_px: f64) -> String {
    format!("set {set} · {} px", format_period(period_px))
}

pub fn format_period(period_px: f64) -> String {
    if period_px.fract() == 0.0 { format!("{period_px:.0}") } else { format!("{period_px:.2}") }
}

const PANE_TITLE_H: f32 = 18.0;
const PANE_FOOTER_H: f32 = 18.0;

fn draw_panes(ui: &mut egui::Ui, kind: ViewKind, panes: Vec<Pane<'_>>, rt: ViewRuntime<'_>) {
    let ViewRuntime { textures, transforms, selection, commands, cloud, inspect, history, line } = rt;
    if panes.is_empty() {
        ui.label("Nothing to show.");
        return;
    }
    let n = panes.len();
    let avail = ui.available_size();
    let spacing = ui.spacing().item_spacing.x;
    let col_w = ((avail.x - spacing * (n as f32 - 1.0)) / n as f32).max(60.0);
    let col_h = avail.y.max(80.0);
    ui.horizontal_top(|ui| {
        for (index, pane) in panes.into_iter().enumerate() {
            ui.allocate_ui_with_layout(vec2(col_w, col_h), egui::Layout::top_down(egui::Align::Min), |ui| {
                ui.set_width(col_w);
                ui.add_sized(
                    [col_w, PANE_TITLE_H],
                    egui::Label::new(egui::RichText::new(&pane.title).strong()).truncate(),
                );
                match pane.content {
                    PaneContent::Message(text) => {
                        ui.add_space(12.0);
                        ui.label(text);
                    }
                    PaneContent::Custom(draw) => {
                        let (textures, transforms, commands, cloud, inspect, history) = (
                            &mut *textures,
                            &mut *transforms,
                            &mut *commands,
                            &mut *cloud,
                            &mut *inspect,
                            &mut *history,
                        );
                        draw(
                            ui,
                            &mut ViewRuntime {
                                textures,
                                transforms,
                                selection,
                                commands,
                                cloud,
                                inspect,
                                history,
                                line,
                            },
                        );
                    }
                    PaneContent::Map(spec) if spec.size[0] == 0 || spec.size[1] == 0 => {
                        ui.add_space(12.0);
                        ui.label(format!("The image is empty ({}x{} px).", spec.size[0], spec.size[1]));
                    }
                    PaneContent::Map(spec) => {
                        let footer_lines = if spec.footer.is_some() { 2.0 } else { 1.0 };
                        let legend_w = legend::width(ui, &spec.legend);
                        let map_w = (col_w - legend_w - spacing).max(40.0);
                        let map_h = (col_h - PANE_TITLE_H - PANE_FOOTER_H * footer_lines - 12.0).max(40.0);
                        let slot = egui::Id::unique(("map", kind, index, pane.camera));
                        let texture = textures.get(ui.ctx(), slot, spec.key, spec.paint);
                        let transform = transforms.entry(pane.camera).or_default();
                        let marker = selection.filter(|s| s.camera == pane.camera).map(|s| [s.u, s.v]);
                        let label = format!("{} map", pane.title);
                        let response = ui
                            .horizontal_top(|ui| {
                                let r = map_view::show(
                                    ui,
                                    &label,
                                    &texture,
                                    spec.size,
                                    transform,
                                    marker,
                                    vec2(map_w, map_h),
                                );
                                legend::show(ui, &spec.legend, vec2(legend_w, map_h));
                                r
                            })
                            .inner;
                        let hover_text = match response.hovered {
                            Some([u, v]) => format!("u {u}, v {v}: {}", (spec.probe)(v * spec.size[0] + u)),
                            None => "Hover for values · click to inspect · wheel zooms · drag pans".to_owned(),
                        };
                        ui.add_sized(
                            [col_w, PANE_FOOTER_H],
                            egui::Label::new(egui::RichText::new(hover_text).monospace()).truncate(),
                        );
                        if let Some(footer) = spec.footer {
                            ui.add_sized([col_w, PANE_FOOTER_H], egui::Label::new(footer).truncate());
                        }
                        if let Some([u, v]) = response.clicked {
                            commands.push(Command::SelectPixel(PixelRef { camera: pane.camera, u, v }));
                        }
                    }
                }
            });
        }
    });
}

/// Colour-maps `values` (row-major, `size`) on `lut` over `[lo, hi]`, in
/// parallel: it runs on the UI thread when a map changes, and a full-size
/// map is 3 million pixels.
pub fn paint_continuous(values: &[f32], size: [usize; 2], lut: &[Color32; LUT_SIZE], lo: f32, hi: f32) -> ColorImage {
    use rayon::prelude::*;
    let pixels = values.par_iter().map(|&v| palette::map_value(lut, v, lo, hi)).collect();
    ColorImage::new(size, pixels)
}

/// The `lo_q` and `hi_q` quantiles of the finite values, from a subsample of
/// at most ~20 000 values so it is cheap enough to call every frame.
pub fn robust_range(values: &[f32], lo_q: f64, hi_q: f64) -> Option<(f32, f32)> {
    let step = (values.len() / 20_000).max(1);
    let mut v: Vec<f32> = values.iter().step_by(step).copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_unstable_by(f32::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize];
    let (lo, hi) = (at(lo_q), at(hi_q));
    Some(if hi > lo { (lo, hi) } else { (lo - 0.5, lo + 0.5) })
}

/// A value range that follows the data (robust 1-99 % range) or is set by hand.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RangeSetting {
    pub auto: bool,
    pub lo: f32,
    pub hi: f32,
}

impl Default for RangeSetting {
    fn default() -> Self {
        Self { auto: true, lo: 0.0, hi: 1.0 }
    }
}

impl RangeSetting {
    /// The range to use, given the data's automatic range.
    pub fn resolve(&self, auto_range: Option<(f32, f32)>) -> (f32, f32) {
        if self.auto {
            auto_range.unwrap_or((0.0, 1.0))
        } else if self.hi > self.lo {
            (self.lo, self.hi)
        } else {
            (self.lo, self.lo + 1.0)
        }
    }

    /// Auto checkbox and min/max fields; switching auto off starts from the data range.
    pub fn ui(&mut self, ui: &mut egui::Ui, unit: &str, auto_range: Option<(f32, f32)>) {
        ui.checkbox(&mut self.auto, "Auto range")
            .on_hover_text("Follow the data (robust percentiles); untick to set the range by hand.");
        // While automatic, the fields show the range in use, so unticking starts from it.
        if self.auto
            && let Some((lo, hi)) = auto_range
        {
            self.lo = lo;
            self.hi = hi;
        }
        ui.add_enabled_ui(!self.auto, |ui| {
            let speed = ((self.hi - self.lo).abs() / 200.0).max(1e-4);
            let lo = ui
                .add(egui::DragValue::new(&mut self.lo).speed(speed).prefix("min ").suffix(format!(" {unit}")))
                .on_hover_text("Value at the bottom of the colour bar.");
            lo.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Range minimum"));
            let hi = ui
                .add(egui::DragValue::new(&mut self.hi).speed(speed).prefix("max ").suffix(format!(" {unit}")))
                .on_hover_text("Value at the top of the colour bar.");
            hi.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Range maximum"));
        });
    }

    /// Bits for hashing into a texture key.
    pub fn key(&self, auto_range: Option<(f32, f32)>) -> [u32; 2] {
        let (lo, hi) = self.resolve(auto_range);
        [lo.to_bits(), hi.to_bits()]
    }
}

/// A colour-map picker for magnitude views.
pub fn colormap_picker(ui: &mut egui::Ui, id: &str, map: &mut palette::Colormap) {
    egui::ComboBox::from_id_salt(id)
        .selected_text(map.name())
        .show_ui(ui, |ui| {
            for m in palette::MAGNITUDE_MAPS {
                ui.selectable_value(map, m, m.name());
            }
        })
        .response
        .on_hover_text("Colour map: viridis is perceptually uniform, turbo shows small differences, gray prints well.")
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, "Colour map"));
}

/// `100 * part / whole` with one decimal, "–" for an empty whole.
pub fn percent(part: usize, whole: usize) -> String {
    if whole == 0 { "–".into() } else { format!("{:.1} %", 100.0 * part as f64 / whole as f64) }
}

/// A value with a sensible number of significant digits and its unit; "no value" for NaN.
pub fn format_value(v: f32, unit: &str) -> String {
    if !v.is_finite() {
        return "no value".into();
    }
    let a = v.abs();
    let text = if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.3e}")
    } else if a >= 100.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.4}")
    } else {
        format!("{v:.5}")
    };
    if unit.is_empty() { text } else { format!("{text} {unit}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_range_ignores_nan_and_outliers() {
        let mut v: Vec<f32> = (0..1000).map(|i| i as f32).collect();
        v[3] = f32::NAN;
        v[10] = 1e9;
        let (lo, hi) = robust_range(&v, 0.01, 0.99).expect("range");
        assert!((lo - 10.0).abs() <= 2.0, "{lo}");
        assert!((hi - 989.0).abs() <= 2.0, "{hi}");
        assert_eq!(robust_range(&[f32::NAN; 4], 0.0, 1.0), None);
        assert_eq!(robust_range(&[2.0; 4], 0.0, 1.0), Some((1.5, 2.5)));
    }

    #[test]
    fn a_manual_range_is_never_empty() {
        let r = RangeSetting { auto: false, lo: 3.0, hi: 3.0 };
        assert_eq!(r.resolve(Some((0.0, 1.0))), (3.0, 4.0));
        let r = RangeSetting { auto: true, ..r };
        assert_eq!(r.resolve(Some((0.0, 1.0))), (0.0, 1.0));
    }

    #[test]
    fn values_are_formatted_with_units() {
        assert_eq!(format_value(f32::NAN, "rad"), "no value");
        assert_eq!(format_value(2.5, "rad"), "2.5000 rad");
        assert_eq!(format_value(1234.56, "µm"), "1234.6 µm");
        assert_eq!(format_value(0.012345, ""), "0.01235");
        assert_eq!(percent(1, 3), "33.3 %");
        assert_eq!(percent(1, 0), "–");
    }
}
