//! The Inspect view: the quality-control workplace. The current
//! result's point cloud as a height map in micrometres (axes in mm), drawing
//! tools for regions and sections, the profile plot with two cursors,
//! levelling, flatness, step height and coplanarity in a measurement table
//! with tolerances, exports and sessions.
//!
//! Layout of this view:
//! - `inspect/state.rs`: the inspection being edited ([`InspectDoc`]), tools, cursors; no GUI types;
//! - `inspect/compute.rs`: rasterizing and analysing on worker threads, memoised by key;
//! - `inspect/files.rs`, `inspect/plot_png.rs`: exports and sessions written (no GUI types);
//! - `inspect/follow.rs`: following a recipe (no GUI types);
//! - `inspect/record.rs`: what a record and a report hold (no GUI types);
//! - the runtime's rooms, each an `impl InspectRuntime` over its own jobs:
//!   `inspect/exporting.rs` (exports built from the screen and written),
//!   `inspect/opening.rs` (sessions, recipes and height maps read in, every
//!   file job collected), `inspect/recording.rs` (the record job);
//! - `inspect/map.rs`, `inspect/plot.rs`, `inspect/panel.rs`: drawing.
//!
//! Invariant: nothing heavy runs per frame. The height map is computed once
//! per result, the analysis once per change of the inspection (keyed by a
//! hash of its JSON), the texture once per analysis and colour setting; a
//! frame only draws.

mod compute;
mod exporting;
pub mod files;
mod follow;
pub mod map;
mod opening;
mod panel;
pub mod plot;
pub mod plot_png;
pub mod record;
mod recording;
pub mod state;
mod texture;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use eframe::egui;

use crate::analysis::error::AnalysisError;
use crate::analysis::height_map::{DisplayFillParams, HeightMap, Rasterized};
use crate::analysis::inspection::InspectionReport;
use crate::analysis::profile::Profile;
use crate::analysis::session::Session;
use crate::app::commands::Command;
use crate::app::jobs::Job;
use crate::app::palette::Colormap;
use crate::app::textures::key_of;
use crate::app::widgets::map_view::ViewTransform;

/// Why the inspection on screen cannot be exported or recorded now.
#[derive(Debug, thiserror::Error)]
pub enum Unavailable<'a> {
    #[error("the inspection is still being measured")]
    StillMeasuring,
    #[error("the height map is not ready yet")]
    HeightMapNotReady,
    #[error("the inspection cannot run: {0}")]
    InspectionCannotRun(&'a AnalysisError),
    #[error("there is no result")]
    NoResult,
    #[error("the report needs the part's details")]
    NoPartDetails,
    #[error("sessions are saved from the File menu")]
    SessionFromFileMenu,
    #[error("a height map opened from a file has no point cloud")]
    NoCloudOfMap,
    #[error(
        "a height map opened from a file is inspected and exported, not recorded: record the measurement it \
         came from"
    )]
    OpenedMapNotRecorded,
    #[error("the part was not found on the followed recipe's reference: nothing was measured")]
    PartNotFound,
}

use super::{Pane, RangeSetting, View, ViewCx, ViewRuntime};

pub use compute::{Analysis, MapShows};
pub use files::{Export, ExportKind, Payload};
pub use opening::{is_height_map_file, is_session_file};
pub use panel::FOLLOW_RECIPE_TIP;
pub use record::{PartFacts, RecordSettings};
pub use state::{InspectDoc, RegionRole, Tool, ViewExtras};

/// The Inspect view's persisted display settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct InspectView {
    pub colormap: Colormap,
    pub range: RangeSetting,
    /// Fill small holes for display only (marked on the map, never measured).
    pub fill_holes: bool,
    /// Where records go and who measures.
    pub record: RecordSettings,
    /// A float TIFF height map's pixel size (mm; 0 = not given: such a
    /// TIFF is refused) and height unit, which the file does not carry.
    pub tiff_pixel_mm: f64,
    pub tiff_z_unit: crate::engine::length_unit::LengthUnit,
}

impl Default for InspectView {
    fn default() -> Self {
        Self {
            colormap: Colormap::Turbo,
            range: RangeSetting::default(),
            fill_holes: false,
            record: RecordSettings::default(),
            tiff_pixel_mm: 0.0,
            tiff_z_unit: crate::engine::length_unit::LengthUnit::Um,
        }
    }
}

impl InspectView {
    /// How a TIFF height map opened in the app is scaled.
    pub fn tiff_scale(&self) -> crate::io::height_map_file::TiffMapScale {
        crate::io::height_map_file::TiffMapScale {
            pixel_mm: (self.tiff_pixel_mm > 0.0).then_some(self.tiff_pixel_mm),
            z_unit: self.tiff_z_unit,
        }
    }
}

impl View for InspectView {
    /// Drawn by [`show`] (it needs the runtime for its controls too).
    fn panes<'a>(&self, _cx: &ViewCx<'a>, _cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        Vec::new()
    }
}

/// Which item of the inspection is selected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Selection {
    Region(usize),
    Profile(usize),
}

/// A message for the operator: shown in the view and passed to the app's log.
#[derive(Clone, Debug, PartialEq)]
pub struct Notice {
    pub text: String,
    pub is_error: bool,
}

/// What a finished export or session job produced.
enum FileOutcome {
    Written { kind: ExportKind, paths: Vec<PathBuf> },
    Cancelled,
    Opened(PathBuf, Box<Session>),
    HeightMap(Box<OpenedMap>),
    Recipe(PathBuf, Box<crate::io::recipe_file::LoadedRecipe>),
}

/// Another instrument's height map (or one Sheen wrote) opened for
/// inspection on its own: the Inspect view measures it in place of the
/// measurement's map; the other views, which need fringe images, keep the
/// measurement.
pub struct OpenedMap {
    pub path: PathBuf,
    pub format: crate::io::height_map_file::HeightMapFormat,
    /// Who wrote it, where the file says.
    pub writer: Option<String>,
    pub raster: Arc<Rasterized>,
    /// What reading adjusted (resampling, an unchecked checksum).
    pub warnings: Vec<crate::engine::warning::Warning>,
    /// Distinguishes two openings of the same file (it may have changed).
    generation: u64,
}

/// The Inspect view's runtime: the inspection, tools, memoised computations
/// and file jobs (never persisted; sessions save the inspection).
pub struct InspectRuntime {
    pub doc: InspectDoc,
    pub tool: Tool,
    drawing: Option<state::Drawing>,
    pub selection: Option<Selection>,
    /// Plot cursors A and B (distance along the profile, mm).
    pub cursors: [Option<f64>; 2],
    transform: ViewTransform,
    measurement_generation: u64,
    raster: compute::Latest<Arc<Rasterized>>,
    analysis: compute::Latest<Analysis>,
    file_job: Option<(String, Job<anyhow::Result<FileOutcome>>)>,
    /// The last message, shown under the toolbar.
    pub status: Option<Notice>,
    notices: Vec<Notice>,
    opened: Option<(PathBuf, Box<Session>)>,
    saved_session: Option<PathBuf>,
    /// Ask for file names with native dialogs (tests turn this off: files
    /// then go to `export_folder` under their default names).
    pub use_dialogs: bool,
    pub export_folder: String,
    editing: Option<(panel::NameRef, String)>,
    /// Raster parameters being edited, applied with a button (each change re-rasterizes).
    raster_edit: Option<crate::analysis::height_map::RasterParams>,
    /// The Record form's part ID and recipe (empty = the defaults shown as hints).
    pub part_id: String,
    pub recipe: String,
    record_job: Option<Job<anyhow::Result<String>>>,
    /// The result (generation, measurement generation) last recorded by
    /// "always record", so each result is recorded once.
    auto_recorded: Option<(u64, u64)>,
    /// A part opened from History for review: "always record" leaves it
    /// alone, since looking at a past part again is not measuring a new one.
    pub reviewing: Option<ReviewedPart>,
    /// Records written since the last call, for the History view to reload.
    records_written: u64,
    /// A height map opened from a file, inspected in place of the measurement's.
    opened_map: Option<OpenedMap>,
    opened_maps: u64,
    /// What the map shows: the heights, a texture measurement's surface, or
    /// (a recipe followed) the difference to the reference.
    pub map_shows: MapShows,
    /// The inspection the operator stopped measuring: not started again until
    /// it changes (or Measure is pressed).
    cancelled_key: Option<u64>,
    /// A recipe the inspection follows: each map is registered to its
    /// reference and the recipe's inspection moved onto the part.
    followed: Option<Arc<follow::FollowedRecipe>>,
    /// The loaded measurement's calibration's stated scale uncertainty
    /// (none for an opened map), for the rows' budgets.
    scale_uncertainty: Option<crate::analysis::uncertainty::ScaleUncertainty>,
    followed_recipes: u64,
    /// The part found (or not) on the current map.
    placing: compute::Latest<Arc<crate::analysis::recipe::PlacedInspection>>,
    /// The placement last put into the inspection, so the operator's edits
    /// stand until the next part.
    placed_key: Option<u64>,
}

impl Default for InspectRuntime {
    fn default() -> Self {
        Self {
            doc: InspectDoc::default(),
            tool: Tool::Pan,
            drawing: None,
            selection: None,
            cursors: [None, None],
            transform: ViewTransform::default(),
            measurement_generation: 0,
            raster: compute::Latest::default(),
            analysis: compute::Latest::interruptible(),
            file_job: None,
            status: None,
            notices: Vec::new(),
            opened: None,
            saved_session: None,
            use_dialogs: true,
            export_folder: String::new(),
            editing: None,
            raster_edit: None,
            part_id: String::new(),
            recipe: String::new(),
            record_job: None,
            auto_recorded: None,
            reviewing: None,
            records_written: 0,
            opened_map: None,
            opened_maps: 0,
            cancelled_key: None,
            map_shows: MapShows::Heights,
            followed: None,
            scale_uncertainty: None,
            followed_recipes: 0,
            placing: compute::Latest::default(),
            placed_key: None,
        }
    }
}

/// The recorded part under review: its input, the last measurement loaded
/// before it was opened, and the measurement that shows it once known.
#[derive(Clone, Debug, PartialEq)]
pub struct ReviewedPart {
    pub manifest: PathBuf,
    pub opened_after_measurement: u64,
    pub measurement: Option<u64>,
}

impl ReviewedPart {
    pub fn new(manifest: PathBuf, opened_after_measurement: u64) -> Self {
        Self { manifest, opened_after_measurement, measurement: None }
    }

    /// Whether the result of `source`, loaded as measurement
    /// `measurement_generation`, is the part under review (or the
    /// measurement before it, still on screen while it loads). False once
    /// any other measurement was loaded, the same input opened again
    /// included: that is measuring the part anew.
    pub fn holds(&mut self, source: &crate::app::run_data::DataSource, measurement_generation: u64) -> bool {
        if let Some(reviewed) = self.measurement {
            return reviewed == measurement_generation;
        }
        let same_input = match source {
            crate::app::run_data::DataSource::File(path) => {
                path == &self.manifest
                    || path.canonicalize().ok().is_some_and(|p| Some(p) == self.manifest.canonicalize().ok())
            }
            _ => false,
        };
        if same_input {
            self.measurement = Some(measurement_generation);
            return true;
        }
        measurement_generation <= self.opened_after_measurement
    }
}

impl InspectRuntime {
    /// The height map as rasterized from the result (before levelling).
    pub fn height_map(&self) -> Option<&HeightMap> {
        self.raster.value().map(|r| &r.map)
    }

    /// How the height map was made (points, triangles, cuts at discontinuities).
    pub fn raster_stats(&self) -> Option<crate::analysis::height_map::RasterStats> {
        self.raster.value().map(|r| r.stats)
    }

    /// Why there is no height map, when rasterizing failed.
    pub fn height_map_error(&self) -> Option<&anyhow::Error> {
        match self.raster.result() {
            Some(Err(e)) => Some(e),
            _ => None,
        }
    }

    /// The latest analysis (levelled map, report, display data).
    pub fn analysis(&self) -> Option<&Analysis> {
        self.analysis.value()
    }

    /// The measurements and profiles of the latest analysis.
    pub fn report(&self) -> Option<&InspectionReport> {
        self.analysis.value().and_then(|a| a.report.as_ref().ok())
    }

    pub fn profiles(&self) -> &[Profile] {
        self.report().map_or(&[], |r| r.profiles.as_slice())
    }

    /// True while the height map or the analysis is being computed or is out
    /// of date, or a file is being written.
    pub fn is_busy(&self) -> bool {
        self.raster.is_running()
            || self.analysis.is_running()
            || self.file_job.is_some()
            || (self.raster.value().is_some() && !self.analysis.is_current() && self.cancelled_key.is_none())
    }

    /// True when the analysis on screen is for the inspection as it is now.
    pub fn is_current(&self) -> bool {
        self.raster.is_current() && self.analysis.is_current()
    }

    /// Replaces the inspection (a session was opened).
    pub fn load_doc(&mut self, doc: InspectDoc, cursors: [Option<f64>; 2]) {
        self.doc = doc;
        self.cursors = cursors;
        self.selection = None;
        self.drawing = None;
        self.editing = None;
        self.raster_edit = None;
    }

    /// Messages for the app's log since the last call.
    pub fn take_notices(&mut self) -> Vec<Notice> {
        std::mem::take(&mut self.notices)
    }

    /// The session file just written, for the recent-files list.
    pub fn take_saved_session(&mut self) -> Option<PathBuf> {
        self.saved_session.take()
    }

    /// A session the operator opened (its file and content), for the app to apply.
    pub fn take_opened_session(&mut self) -> Option<(PathBuf, Session)> {
        self.opened.take().map(|(p, s)| (p, *s))
    }

    fn notify(&mut self, text: String, is_error: bool) {
        let notice = Notice { text, is_error };
        self.status = Some(notice.clone());
        self.notices.push(notice);
    }

    /// Brings the memoised computations up to date with the result and the
    /// inspection: starts what is missing, collects what finished.
    pub fn update(&mut self, cx: &ViewCx<'_>, fill: bool, repaint: impl Fn() + Clone + Send + 'static) {
        if cx.measurement_generation != self.measurement_generation {
            self.measurement_generation = cx.measurement_generation;
            self.raster.clear();
            self.analysis.clear();
            self.transform = ViewTransform::default();
            // A newly loaded measurement is what the operator wants to see now.
            self.opened_map = None;
        }
        self.raster.poll();
        self.analysis.poll();
        self.placing.poll();
        if let Some(opened) = &self.opened_map {
            self.scale_uncertainty = None;
            let (map_key, raster) = (key_of(&("opened map", opened.generation)), Arc::clone(&opened.raster));
            return self.follow_then_analyse(map_key, raster, fill, repaint);
        }
        let Some(result) = cx.result else { return };
        self.scale_uncertainty = cx.measurement.calibration.as_ref().and_then(|c| c.scale_uncertainty);
        let params = compute::raster_params(&self.doc.raster, cx.measurement.calibration.as_ref());
        let raster_key = key_of(&(result.generation, cx.measurement_generation, serde_json::to_string(&params).ok()));
        let rec = Arc::clone(&result.reconstruction);
        self.raster.request(raster_key, "rasterizing the height map", repaint.clone(), move |control| {
            compute::rasterize(&rec, &params, control).map(Arc::new)
        });
        if !self.raster.is_current() {
            return;
        }
        let Some(raster) = self.raster.value() else { return };
        let raster = Arc::clone(raster);
        self.follow_then_analyse(raster_key, raster, fill, repaint);
    }

    /// With a recipe followed, finds the part on the map first and measures
    /// the recipe's inspection where the part lies; a part not found is not
    /// measured (the map is shown, the reason under the toolbar).
    fn follow_then_analyse(
        &mut self,
        map_key: u64,
        raster: Arc<Rasterized>,
        fill: bool,
        repaint: impl Fn() + Clone + Send + 'static,
    ) {
        let Some(followed) = self.followed.clone() else {
            return self.request_analysis(map_key, raster, None, fill, repaint);
        };
        let key = key_of(&(map_key, followed.generation));
        let (recipe, map) = (Arc::clone(&followed), Arc::clone(&raster));
        self.placing
            .request(key, "finding the part", repaint.clone(), move |_| Ok(Arc::new(recipe.place_on(&map.map)?)));
        if !self.placing.is_current() {
            return;
        }
        let fresh = self.placed_key != Some(key);
        self.placed_key = Some(key);
        let placed = match self.placing.result() {
            Some(Ok(placed)) => Arc::clone(placed),
            Some(Err(e)) => {
                if fresh {
                    let text = format!("Recipe '{}': {}", followed.name(), crate::error_text::error_chain(e));
                    // Nothing is measured where the part may not be.
                    self.load_doc(InspectDoc::default(), [None, None]);
                    self.notify(text, true);
                }
                return self.request_analysis(map_key, raster, None, fill, repaint);
            }
            None => return,
        };
        if fresh {
            self.load_doc(InspectDoc::from_spec(&placed.spec, None), [None, None]);
            let p = placed.alignment.placement;
            self.notify(
                format!(
                    "Recipe '{}': part found (match score {:.4}), rotated {:.3}° and shifted {:.4}, {:.4} mm from the \
                     reference; its regions and sections moved with it.",
                    followed.name(),
                    placed.alignment.score,
                    p.rotation_deg,
                    p.shift_mm[0],
                    p.shift_mm[1]
                ),
                false,
            );
        }
        let following = Some(follow::Following {
            key,
            placed,
            reference: Arc::clone(&followed.reference),
            show_difference: self.map_shows == MapShows::DifferenceToReference,
        });
        self.request_analysis(map_key, raster, following, fill, repaint);
    }

    /// Measures the inspection on `raster` (`map_key` names the map) unless
    /// the operator cancelled this very inspection.
    fn request_analysis(
        &mut self,
        map_key: u64,
        raster: Arc<Rasterized>,
        following: Option<follow::Following>,
        fill: bool,
        repaint: impl Fn() + Send + 'static,
    ) {
        let spec = self.doc.spec();
        let fill_params = fill.then(DisplayFillParams::default);
        let surface = match &self.map_shows {
            MapShows::Surface(name) => Some(name.clone()),
            _ => None,
        };
        let placement = following.as_ref().map(|f| f.key);
        let calibration = self.scale_uncertainty;
        let analysis_key = key_of(&(
            map_key,
            spec.to_json(),
            fill,
            &self.map_shows,
            placement,
            serde_json::to_string(&calibration).ok(),
        ));
        if self.cancelled_key.is_some_and(|k| k != analysis_key) {
            self.cancelled_key = None;
        }
        if self.cancelled_key.is_none() {
            self.analysis.request(analysis_key, "measuring", repaint, move |control| {
                let analysis =
                    compute::analyse(&raster.map, &spec, calibration, fill_params, surface.as_deref(), control);
                Ok(match &following {
                    Some(f) => f.apply(analysis, &raster.map),
                    None => analysis,
                })
            });
        }
    }

    /// Stops measuring the inspection on screen (a texture of a full-size
    /// map takes seconds); the last finished results stay shown.
    pub fn cancel_measuring(&mut self) {
        if let Some(key) = self.analysis.cancel() {
            self.cancelled_key = Some(key);
            self.notify(
                "Measuring cancelled: the table shows the last finished inspection. Change the inspection or press \
                 Measure to run it."
                    .into(),
                false,
            );
        }
    }

    /// Whether the operator cancelled the inspection on screen.
    pub fn measuring_cancelled(&self) -> bool {
        self.cancelled_key.is_some()
    }

    /// Measures the cancelled inspection after all.
    pub fn measure_again(&mut self) {
        self.cancelled_key = None;
    }

    /// The map the inspection on screen measures (levelled when levelling
    /// is on), once measured.
    pub fn measured_map(&self) -> Option<Arc<HeightMap>> {
        self.analysis.value().map(|a| Arc::clone(&a.map))
    }

    /// The session of this inspection for `manifest` (empty = the simulated demo).
    pub fn session(&self, manifest: &Path, params: crate::engine::pipeline::Params) -> Session {
        let mut session = Session::new(manifest, params);
        session.inspection = self.doc.spec();
        let mut view = serde_json::Map::new();
        view.insert(state::VIEW_KEY.into(), serde_json::to_value(self.doc.extras(self.cursors)).unwrap_or_default());
        session.view = serde_json::Value::Object(view);
        session
    }
}

/// "the simulated demo" for an empty manifest path.
pub fn describe_manifest(manifest: &Path) -> String {
    if manifest.as_os_str().is_empty() { "the simulated demo".into() } else { manifest.display().to_string() }
}

/// The GUI extras of a session's view state, if it has them.
pub fn extras_of(session: &Session) -> Option<ViewExtras> {
    session.view.get(state::VIEW_KEY).and_then(|v| serde_json::from_value(v.clone()).ok())
}

/// Draws the Inspect view: toolbar, map, plot and the side panel.
pub fn show(ui: &mut egui::Ui, settings: &mut InspectView, cx: &ViewCx<'_>, rt: ViewRuntime<'_>) {
    let ViewRuntime { textures, commands, inspect, .. } = rt;
    let ctx = ui.ctx().clone();
    let repaint = move || ctx.request_repaint();
    inspect.update(cx, settings.fill_holes, repaint.clone());
    inspect.poll_files();

    if let Some(opened) = &inspect.opened_map {
        let mut close = false;
        ui.horizontal_wrapped(|ui| {
            close = ui.button("Close map").on_hover_text("Back to the measurement's own height map.").clicked();
            ui.label(egui::RichText::new(format!("Height map {}", opened.path.display())).strong());
            ui.weak(format!(
                "({}{}) · Inspect only: the other views show the measurement",
                opened.format.name(),
                opened.writer.as_ref().map_or_else(String::new, |w| format!(", {w}"))
            ));
        });
        if close {
            inspect.close_opened_map();
            ui.ctx().request_repaint();
            return;
        }
    } else {
        let Some(result) = cx.result else {
            ui.label("No result yet: the engine is running or has not run.");
            return;
        };
        if result.reconstruction.stereo.is_none() {
            let why = result.reconstruction.stereo_skipped.as_deref().unwrap_or("no stereo result");
            ui.label(format!("No 3D points, so no height map: {why}."));
            return;
        }
    }

    panel::toolbar(ui, settings, inspect);
    if let Some(status) = &inspect.status {
        let color = if status.is_error {
            crate::app::palette::error_text(ui.visuals())
        } else {
            ui.visuals().weak_text_color()
        };
        ui.label(egui::RichText::new(&status.text).color(color));
    }
    let avail = ui.available_size();
    let panel_w = 370.0_f32.min(avail.x * 0.45);
    let left_w = (avail.x - panel_w - ui.spacing().item_spacing.x).max(200.0);
    ui.horizontal_top(|ui| {
        ui.allocate_ui_with_layout(egui::vec2(left_w, avail.y), egui::Layout::top_down(egui::Align::Min), |ui| {
            ui.set_width(left_w);
            let map_h = (avail.y * 0.56).max(160.0);
            map::show(ui, settings, inspect, textures, egui::vec2(left_w, map_h));
            plot::show(ui, inspect, (avail.y - map_h - 12.0).max(120.0));
        });
        ui.allocate_ui_with_layout(egui::vec2(panel_w, avail.y), egui::Layout::top_down(egui::Align::Min), |ui| {
            ui.set_width(panel_w);
            egui::ScrollArea::vertical().id_salt("inspect panel").show(ui, |ui| {
                panel::show(ui, inspect, &mut settings.record, commands);
            });
        });
    });
}
