//! [`SheenApp`]: the eframe application. Each frame it collects finished jobs,
//! starts due engine runs, handles dropped files and shortcuts, draws the
//! panels and views, then runs the [`Command`]s they pushed.
//!
//! Invariant: the UI thread only polls. Loading, simulation, the engine, the
//! comparison and the file dialog all run on job threads; a failure of any of
//! them becomes a banner and a log entry, and leaves the data on screen as it
//! was.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// How often a running job's progress is redrawn.
pub const PROGRESS_REPAINT: Duration = Duration::from_millis(200);
/// The same where the window is drawn on the CPU (Mesa's llvmpipe on VMs
/// and remote desktops): a frame there costs two renderer threads about
/// 70 ms each at 1600x1000, so five frames a second took a core from the
/// engine. At this pace a full-size re-run showed its result after a median
/// 0.98 s instead of 1.15 s (docs/benchmarks-history.md, "The window paced by the app").
pub const PROGRESS_REPAINT_ON_CPU: Duration = Duration::from_millis(750);

use eframe::egui;

use super::calibration::CalibrationView;
use super::commands::{Command, PixelRef};
use super::import_dialog::ImportDialog;
use super::jobs::JobOutcome;
use super::loading::{DemoFn, DialogOutcome, LoadRequest, LoadedData, Loader, simulated_watch_plate};
use super::log::LogBook;
use super::panels::parameters::EngineStatus;
use super::panels::status::Banner;
use super::panels::top_bar::OpenPathBox;
use super::panels::{inspector, log as log_panel, parameters, statistics, status, top_bar};
use super::pixel_report::{self, PixelReport};
use super::run_data::{CompareOutput, ResultSet, Session};
use super::runner::{CompareRunner, EngineRunner};
use super::state::{AppState, SideTab, fit_params_to};
use super::textures::TextureCache;
use super::views::{self, ViewCx, ViewRuntime};
use super::widgets::map_view::ViewTransform;

mod inspect_glue;

/// What to open at start-up.
#[derive(Clone, Debug, PartialEq)]
pub enum Startup {
    /// The simulated demo (no manifest given).
    Demo,
    Manifest(PathBuf),
}

/// How the app is started (the binary uses the defaults; tests shrink the demo).
#[derive(Clone)]
pub struct AppOptions {
    pub startup: Startup,
    /// Size of the simulated demo in camera pixels.
    pub demo_size: [usize; 2],
    /// Builds the demo; the simulator's watch plate by default.
    pub demo: DemoFn,
    /// Read the state remembered from the last session (off in tests, so they
    /// do not depend on the machine).
    pub restore_state: bool,
}

impl Default for AppOptions {
    fn default() -> Self {
        Self { startup: Startup::Demo, demo_size: [640, 480], demo: simulated_watch_plate, restore_state: true }
    }
}

pub struct SheenApp {
    /// Persisted state (parameters, theme, recent files, layout, view settings).
    pub state: AppState,
    demo: DemoFn,
    demo_size: [usize; 2],
    ctx: egui::Context,
    session: Option<Session>,
    result_counter: u64,
    measurement_counter: u64,
    loader: Loader,
    engine: EngineRunner,
    compare: CompareRunner,
    textures: TextureCache,
    cloud: views::CloudRuntime,
    inspect: views::InspectRuntime,
    history: views::HistoryRuntime,
    line: views::LineRuntime,
    transforms: HashMap<usize, ViewTransform>,
    selection: Option<PixelRef>,
    log: LogBook,
    banner: Option<Banner>,
    open_path: OpenPathBox,
    commands: Vec<Command>,
    /// The Import dialog.
    import: ImportDialog,
    /// Automatic colour ranges of the views (see `ViewCx::memo_range`).
    ranges: RefCell<HashMap<u64, Option<(f32, f32)>>>,
    calibration: CalibrationView,
    /// The graphics adapter wgpu draws with (`None` without a wgpu renderer).
    renderer: Option<eframe::wgpu::AdapterInfo>,
}

impl SheenApp {
    pub fn new(cc: &eframe::CreationContext<'_>, options: AppOptions) -> Self {
        let state = if options.restore_state {
            cc.storage.and_then(|s| eframe::get_value::<AppState>(s, eframe::APP_KEY)).unwrap_or_default()
        } else {
            AppState::default()
        };
        cc.egui_ctx.set_theme(state.theme.preference());
        let mut app = Self {
            state,
            demo: options.demo,
            demo_size: options.demo_size,
            ctx: cc.egui_ctx.clone(),
            session: None,
            result_counter: 0,
            measurement_counter: 0,
            loader: Loader::default(),
            engine: EngineRunner::default(),
            compare: CompareRunner::default(),
            textures: TextureCache::default(),
            cloud: views::CloudRuntime::new(cc.wgpu_render_state.clone()),
            inspect: views::InspectRuntime::default(),
            history: views::HistoryRuntime::default(),
            line: views::LineRuntime::default(),
            transforms: HashMap::new(),
            selection: None,
            log: LogBook::default(),
            banner: None,
            open_path: OpenPathBox::default(),
            commands: Vec::new(),
            import: ImportDialog::default(),
            ranges: RefCell::default(),
            calibration: CalibrationView::default(),
            renderer: cc.wgpu_render_state.as_ref().map(|r| r.adapter.get_info()),
        };
        if let Some(adapter) = app.renderer.as_ref().filter(|a| a.device_type == eframe::wgpu::DeviceType::Cpu) {
            // See `jobs`: a CPU renderer needs the cores the engine uses.
            super::jobs::set_jobs_below_ui_thread(false);
            app.log.info(format!(
                "Drawing on the CPU ({}): the engine shares the cores with the window at equal priority",
                adapter.name
            ));
        }
        match options.startup {
            Startup::Demo => app.commands.push(Command::OpenDemo),
            Startup::Manifest(path) => app.commands.push(Command::Open(path)),
        }
        app.run_commands();
        app
    }

    // ---- read access (panels, tests) ----

    pub fn session(&self) -> Option<&Session> {
        self.session.as_ref()
    }

    pub fn result(&self) -> Option<&ResultSet> {
        self.session.as_ref()?.result.as_ref()
    }

    pub fn compare_output(&self) -> Option<&CompareOutput> {
        self.compare.output.as_ref()
    }

    pub fn banner(&self) -> Option<&Banner> {
        self.banner.as_ref()
    }

    pub fn log(&self) -> &LogBook {
        &self.log
    }

    pub fn selection(&self) -> Option<PixelRef> {
        self.selection
    }

    /// Zoom and pan shared by every map of `camera`.
    pub fn view_transform(&self, camera: usize) -> ViewTransform {
        self.transforms.get(&camera).copied().unwrap_or_default()
    }

    /// True while anything runs or is scheduled (load, dialog, engine, comparison).
    pub fn is_busy(&self) -> bool {
        let now = self.ctx.input(|i| i.time);
        self.loader.is_loading()
            || self.loader.dialog_open()
            || self.engine.is_running()
            || self.engine.due_in_s(now).is_some()
            || self.compare.is_running()
    }

    /// The graphics adapter the window is drawn with, if wgpu draws it.
    pub fn renderer(&self) -> Option<&eframe::wgpu::AdapterInfo> {
        self.renderer.as_ref()
    }

    /// How often the progress of a running job is redrawn: less often where
    /// drawing takes the engine's cores.
    pub fn progress_repaint(&self) -> Duration {
        match &self.renderer {
            Some(adapter) if adapter.device_type == eframe::wgpu::DeviceType::Cpu => PROGRESS_REPAINT_ON_CPU,
            _ => PROGRESS_REPAINT,
        }
    }

    pub fn engine_runs_started(&self) -> u64 {
        self.engine.runs_started()
    }

    /// The 3D view's runtime side (camera, uploads, hovered point).
    pub fn cloud_view(&self) -> &views::CloudRuntime {
        &self.cloud
    }

    /// The calibration window's state (set, detections, solution).
    pub fn calibration_view(&self) -> &CalibrationView {
        &self.calibration
    }

    /// The Import dialog (tests drive its form; the folder picker cannot be clicked there).
    pub fn import_dialog(&self) -> &ImportDialog {
        &self.import
    }

    pub fn import_dialog_mut(&mut self) -> &mut ImportDialog {
        &mut self.import
    }

    /// Texture images built so far (they are rebuilt only when their data changed).
    pub fn texture_builds(&self) -> u64 {
        self.textures.builds()
    }

    /// The inspector's report of the selected pixel.
    pub fn pixel_report(&self) -> Option<PixelReport> {
        let session = self.session.as_ref()?;
        let m = &session.measurement;
        let result = session.result.as_ref().map(|r| (r.reconstruction.as_ref(), r.derived.as_ref()));
        pixel_report::build(m, self.selection?, self.state.params.threshold_for(m), result)
    }

    /// Queues a command, run at the end of the next frame (what drag and drop,
    /// the command line and tests use).
    pub fn push_command(&mut self, command: Command) {
        self.commands.push(command);
        self.ctx.request_repaint();
    }

    fn repaint_handle(&self) -> impl Fn() + Send + 'static {
        let ctx = self.ctx.clone();
        move || ctx.request_repaint()
    }

    fn show_error(&mut self, text: String) {
        self.log.error(text.clone());
        self.banner = Some(Banner { text, is_error: true });
    }

    fn show_notice(&mut self, text: String) {
        self.log.warning(text.clone());
        self.banner = Some(Banner { text, is_error: false });
    }

    // ---- jobs ----

    fn poll_jobs(&mut self) {
        if let Some((request, outcome)) = self.loader.poll() {
            match outcome {
                JobOutcome::Done(data) => self.install(data),
                JobOutcome::Failed(e) => self.show_error(format!(
                    "Could not open {}: {}. The data on screen is unchanged.",
                    request.describe(),
                    crate::error_text::error_chain(&e)
                )),
                JobOutcome::Cancelled => self.log.info(format!("Loading {} cancelled.", request.describe())),
                JobOutcome::Panicked(e) => self.show_error(format!(
                    "Loading {} crashed ({e}); the data on screen is unchanged. Please report this with the file.",
                    request.describe()
                )),
            }
        }
        if let Some(outcome) = self.loader.poll_dialog() {
            match outcome {
                DialogOutcome::Picked(path) => self.commands.push(Command::Open(path)),
                DialogOutcome::Dismissed => self.log.info("No file chosen."),
                DialogOutcome::Unavailable => self.show_notice(
                    "No file dialog could be shown on this system (it needs xdg-desktop-portal or zenity). Drop a \
                     manifest onto the window, type its path under File > Open path, or start `sheen MANIFEST`."
                        .into(),
                ),
            }
        }
        if let Some(outcome) = self.engine.poll() {
            match outcome {
                JobOutcome::Done(out) => {
                    let current = self.session.as_ref().is_some_and(|s| s.measurement.id == out.measurement_id);
                    if current {
                        self.install_result(out.reconstruction, out.derived);
                    }
                }
                JobOutcome::Failed(e) => self.show_error(format!(
                    "The engine run failed: {}. The previous result is kept.",
                    crate::error_text::error_chain(&e)
                )),
                JobOutcome::Cancelled => {}
                JobOutcome::Panicked(e) => self.show_error(format!(
                    "The engine crashed ({e}). The previous result is kept; please report this with the log."
                )),
            }
        }
        if let Some(Err(e)) = self.compare.poll() {
            self.show_error(crate::error_text::error_chain(&e));
        }
        self.poll_inspect();
    }

    fn install(&mut self, data: LoadedData) {
        let LoadedData { measurement, source, warnings } = data;
        for note in fit_params_to(&mut self.state.params, &measurement) {
            self.log.info(note);
        }
        for w in warnings {
            self.log.warning(format!("{}: {w}", source.describe()));
        }
        if let super::run_data::DataSource::File(path) = &source {
            self.state.remember_file(path);
        }
        let m = &measurement;
        let (w, h) = m.cameras.first().map_or((0, 0), |c| (c.width, c.height));
        self.log.info(format!(
            "Loaded {}: {} camera(s), {} set(s), {w}x{h} px, {}-bit, {}.",
            source.describe(),
            m.cameras.len(),
            m.sets.len(),
            m.bit_depth,
            match &m.projector {
                Some(p) if p.calibration.is_some() => "a calibrated camera–projector rig",
                Some(_) => "a camera–projector rig without calibration (projector coordinates only)",
                None if m.calibration.is_some() => "calibrated",
                None => "no calibration (phase maps only)",
            }
        ));
        if source.is_simulated() {
            self.log.info("This is simulated demo data, not a measurement.");
        }
        self.measurement_counter += 1;
        self.session = Some(Session {
            measurement: Arc::new(measurement),
            source,
            measurement_generation: self.measurement_counter,
            result: None,
        });
        self.compare.reset();
        self.selection = None;
        self.transforms.clear();
        self.banner = None;
        self.start_run();
    }

    fn install_result(
        &mut self,
        reconstruction: Arc<crate::engine::pipeline::Reconstruction>,
        derived: Arc<super::run_data::Derived>,
    ) {
        let Some(session) = self.session.as_mut() else {
            return;
        };
        let old_warnings: Vec<crate::engine::warning::Warning> =
            session.result.as_ref().map(|r| r.reconstruction.warnings.clone()).unwrap_or_default();
        for w in reconstruction.warnings.iter().filter(|w| !old_warnings.contains(w)) {
            self.log.warning(w.message.clone());
        }
        self.result_counter += 1;
        let total = reconstruction.total_seconds();
        self.log.info(format!(
            "Result #{} ({} method): {} valid, {} points, {total:.2} s.",
            self.result_counter,
            reconstruction.params.method,
            derived.completeness.iter().map(|c| format!("{:.1} %", c * 100.0)).collect::<Vec<_>>().join(" / "),
            reconstruction.point_count()
        ));
        let replaced = session.result.replace(ResultSet { reconstruction, derived, generation: self.result_counter });
        // A full-size result is about 0.75 GB in hundreds of buffers; freeing
        // it took 5 ms, the UI thread's longest frame (docs/benchmarks-history.md).
        if let Some(old) = replaced {
            std::thread::Builder::new().name("sheen: free result".into()).spawn(move || drop(old)).ok();
        }
    }

    fn start_run(&mut self) {
        let repaint = self.repaint_handle();
        let Some(session) = self.session.as_ref() else {
            return;
        };
        self.engine.start(
            Arc::clone(&session.measurement),
            self.state.params.clone(),
            session.result.as_ref(),
            repaint,
        );
    }

    fn engine_status(&self) -> EngineStatus {
        let now = self.ctx.input(|i| i.time);
        let (stage, fraction) = self.engine.progress().unwrap_or_default();
        EngineStatus {
            running: self.engine.is_running(),
            scheduled: self.engine.due_in_s(now).is_some(),
            stage,
            fraction,
            stale: self.result().is_some_and(|r| r.reconstruction.params != self.state.params),
        }
    }

    // ---- input ----

    fn handle_input(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| i.raw.dropped_files.iter().map(|f| f.path().to_path_buf()).collect());
        if let Some(path) = dropped.into_iter().next() {
            self.commands.push(Command::Open(path));
        }
        use egui::{Key, KeyboardShortcut, Modifiers};
        let shortcut = |m: Modifiers, k: Key| ctx.input_mut(|i| i.consume_shortcut(&KeyboardShortcut::new(m, k)));
        if shortcut(Modifiers::COMMAND, Key::O) {
            self.commands.push(Command::OpenDialog);
        }
        if shortcut(Modifiers::NONE, Key::F5) || shortcut(Modifiers::COMMAND, Key::R) {
            self.commands.push(Command::Run);
        }
        if shortcut(Modifiers::NONE, Key::Escape) {
            self.commands.push(Command::Cancel);
            self.commands.push(Command::CancelLoad);
        }
        // Plain keys only when no text field or slider wants them.
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        if shortcut(Modifiers::NONE, Key::PageUp) || shortcut(Modifiers::NONE, Key::OpenBracket) {
            self.commands.push(Command::StepSet(-1));
        }
        if shortcut(Modifiers::NONE, Key::PageDown) || shortcut(Modifiers::NONE, Key::CloseBracket) {
            self.commands.push(Command::StepSet(1));
        }
        if shortcut(Modifiers::NONE, Key::ArrowLeft) {
            self.commands.push(Command::StepShift(-1));
        }
        if shortcut(Modifiers::NONE, Key::ArrowRight) {
            self.commands.push(Command::StepShift(1));
        }
    }

    // ---- commands ----

    fn run_commands(&mut self) {
        let commands = std::mem::take(&mut self.commands);
        for command in commands {
            self.run_command(command);
        }
        // Commands may queue more (a picked file queues an Open).
        if !self.commands.is_empty() {
            self.ctx.request_repaint();
        }
    }

    fn run_command(&mut self, command: Command) {
        let now = self.ctx.input(|i| i.time);
        match command {
            Command::OpenDialog => {
                let start_dir = self.state.recent_files.first().and_then(|p| p.parent()).map(|p| p.to_path_buf());
                let repaint = self.repaint_handle();
                self.loader.open_dialog(start_dir, repaint);
            }
            // A folder (given at start, dropped, typed) is a set of images to import.
            Command::Open(path) if path.is_dir() => {
                self.log.info(format!("{} is a folder: import its images", path.display()));
                self.import.open_with_folder(&path);
            }
            Command::Open(path) if views::inspect::is_height_map_file(&path) => {
                let repaint = self.repaint_handle();
                self.log.info(format!("Opening the height map {} in the Inspect view", path.display()));
                let tiff = self.state.views.inspect.tiff_scale();
                self.inspect.start_open_height_map(path, tiff, repaint);
                self.state.views.active = views::ViewKind::Inspect;
            }
            Command::Open(path) if views::inspect::is_session_file(&path) => {
                let repaint = self.repaint_handle();
                self.inspect.start_open_session(Some(path), repaint);
            }
            Command::Open(path) => {
                let repaint = self.repaint_handle();
                self.log.info(format!("Opening {}", path.display()));
                self.loader.start(LoadRequest::Manifest(path), self.demo, repaint);
            }
            Command::OpenImport => self.import.open = true,
            Command::OpenDemo => {
                let repaint = self.repaint_handle();
                let [width, height] = self.demo_size;
                self.loader.start(LoadRequest::Demo { width, height }, self.demo, repaint);
            }
            Command::CancelLoad => {
                if let Some((what, _, _)) = self.loader.progress()
                    && self.loader.cancel()
                {
                    self.log.info(format!("Loading {what} cancelled; the data on screen is unchanged."));
                }
            }
            Command::ForgetRecent(path) => self.state.forget_file(&path),
            Command::ParamsChanged => {
                if self.state.auto_run && self.session.is_some() {
                    self.engine.schedule(now);
                }
            }
            Command::Run => self.start_run(),
            Command::Cancel => {
                if self.engine.cancel() {
                    self.log.info("Engine run cancelled; the previous result stays.");
                }
            }
            Command::Compare(methods) => {
                let repaint = self.repaint_handle();
                if let Some(session) = &self.session
                    && let Some(result) = &session.result
                {
                    self.compare.request(&session.measurement, result, methods, repaint);
                }
            }
            Command::SelectPixel(pixel) => {
                self.selection = Some(pixel);
                self.state.layout.side_tab = SideTab::Inspector;
                self.state.layout.show_side_panel = true;
            }
            Command::ClearSelection => self.selection = None,
            Command::SectionsThrough { x_mm, y_mm } => {
                use crate::analysis::profile::ProfileLine;
                self.inspect.doc.add_profile(ProfileLine::Horizontal { through_mm: [x_mm, y_mm] });
                let i = self.inspect.doc.add_profile(ProfileLine::Vertical { through_mm: [x_mm, y_mm] });
                self.inspect.selection = Some(views::inspect::Selection::Profile(i));
                self.state.views.active = views::ViewKind::Inspect;
                self.log.info(format!("Sections through X {x_mm:.4} mm, Y {y_mm:.4} mm in the Inspect view"));
            }
            Command::StepSet(delta) => {
                if let Some(s) = &self.session {
                    self.state.views.cursor.step_set(&s.measurement, delta);
                }
            }
            Command::StepShift(delta) => {
                if let Some(s) = &self.session {
                    self.state.views.cursor.step_shift(&s.measurement, delta);
                }
            }
            Command::ResetZoom(camera) => {
                self.transforms.insert(camera, ViewTransform::default());
            }
            Command::DismissBanner => self.banner = None,
            Command::ClearLog => self.log.clear(),
            Command::OpenCalibration => self.calibration.open = true,
            Command::InspectExport(kind) => self.inspect_export(kind),
            Command::SaveSession(path) => self.save_session(path),
            Command::SaveRecipe(path) => self.save_recipe(path),
            Command::InspectRecord => self.inspect_record(),
            Command::OpenRecord(part) => self.open_record(*part),
            Command::OpenSession(path) => {
                let repaint = self.repaint_handle();
                self.inspect.start_open_session(path, repaint);
            }
            Command::FollowRecipe(path) => {
                let repaint = self.repaint_handle();
                self.inspect.start_follow_recipe(path, repaint);
                self.state.views.active = views::ViewKind::Inspect;
            }
        }
    }

    // ---- drawing ----

    fn summary(&self) -> String {
        let Some(session) = &self.session else {
            return if self.loader.is_loading() { String::new() } else { "No measurement loaded.".into() };
        };
        let m = &session.measurement;
        let Some(r) = &session.result else {
            return format!("{} set(s) · no result yet", m.sets.len());
        };
        let rec = &r.reconstruction;
        let valid =
            r.derived.completeness.iter().map(|c| format!("{:.1} %", c * 100.0)).collect::<Vec<_>>().join(" / ");
        let enabled = rec.params.enabled_sets.iter().filter(|e| **e).count();
        let mut text = format!("{} · {enabled} of {} sets · valid {valid}", rec.params.method, m.sets.len());
        if rec.cloud().is_some() {
            text.push_str(&format!(" · {} points", rec.point_count()));
        }
        if !rec.warnings.is_empty() {
            text.push_str(&format!(" · {} warning(s)", rec.warnings.len()));
        }
        text
    }

    fn draw(&mut self, ui: &mut egui::Ui) {
        let source = self.session.as_ref().map(|s| s.source.clone());
        egui::Panel::top("menu").show(ui, |ui| {
            top_bar::show(ui, &mut self.state, source.as_ref(), &mut self.open_path, &mut self.commands);
        });
        if let Some(b) = self.banner.clone() {
            egui::Panel::top("banner").show(ui, |ui| status::banner(ui, &b, &mut self.commands));
        }
        let engine_status = self.engine_status();
        let load = self.loader.progress();
        let compare = self.compare.progress();
        let summary = self.summary();
        egui::Panel::bottom("status").show(ui, |ui| {
            status::status_bar(ui, load.as_ref(), &engine_status, compare.as_ref(), &summary, &mut self.commands);
        });
        if self.state.layout.show_log {
            egui::Panel::bottom("log").resizable(true).default_size(130.0).show(ui, |ui| {
                log_panel::show(ui, &self.log, &mut self.state.layout.log_filter, &mut self.commands);
            });
        }
        let measurement = self.session.as_ref().map(|s| Arc::clone(&s.measurement));
        let result = self.result().cloned();
        egui::Panel::left("parameters").resizable(true).default_size(250.0).show(ui, |ui| {
            egui::ScrollArea::vertical().id_salt("parameters scroll").show(ui, |ui| {
                parameters::show(
                    ui,
                    &mut self.state.params,
                    &mut self.state.auto_run,
                    measurement.as_deref(),
                    result.as_ref(),
                    &engine_status,
                    &mut self.commands,
                );
            });
        });
        if self.state.layout.show_side_panel {
            let report = self.pixel_report();
            egui::Panel::right("side").resizable(true).default_size(330.0).show(ui, |ui| {
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut self.state.layout.side_tab, SideTab::Inspector, "Inspector")
                        .on_hover_text("The selected pixel's samples and fit.");
                    ui.selectable_value(&mut self.state.layout.side_tab, SideTab::Statistics, "Statistics")
                        .on_hover_text("Figures of the current result.");
                });
                ui.separator();
                match self.state.layout.side_tab {
                    SideTab::Inspector => inspector::show(ui, report.as_ref(), &mut self.commands),
                    SideTab::Statistics => statistics::show(ui, measurement.as_deref(), result.as_ref()),
                }
            });
        }
        egui::CentralPanel::default().show(ui, |ui| self.draw_views(ui));
        self.draw_calibration(ui.ctx());
        self.import.show(ui.ctx(), &mut self.commands);
        self.draw_drop_hint(ui.ctx());
    }

    /// The calibration window (polled every frame, drawn when open); a
    /// calibration it hands over replaces the open fringe set's.
    fn draw_calibration(&mut self, ctx: &egui::Context) {
        let fringe = self.session.as_ref().map(|s| Arc::clone(&s.measurement));
        let Some(m) = self.calibration.show(ctx, fringe.as_ref(), &mut self.log) else {
            return;
        };
        let Some(session) = self.session.as_mut() else {
            return;
        };
        if session.measurement.id != m.id {
            self.log.warning("Another fringe set was opened meanwhile; the calibration was not applied to it.");
            return;
        }
        self.log.info(format!("{} is measured again with the calibration from the calibration window.", m.label));
        // Same id: the phases are reused and only the stereo stage runs again.
        self.measurement_counter += 1;
        session.measurement = Arc::new(m);
        session.measurement_generation = self.measurement_counter;
        self.compare.reset();
        self.start_run();
    }

    fn draw_views(&mut self, ui: &mut egui::Ui) {
        // A height map opened with no measurement loaded: the Inspect view
        // alone (the other views need fringe images).
        let map_alone = self.session.is_none() && self.inspect.opened_map().is_some();
        if self.session.is_none() && !map_alone {
            ui.vertical_centered(|ui| {
                ui.add_space(ui.available_height() / 3.0);
                if let Some((what, stage, fraction)) = self.loader.progress() {
                    ui.heading(format!("Loading {what}"));
                    ui.add(egui::ProgressBar::new(fraction).text(stage).desired_width(320.0));
                } else {
                    ui.heading("No measurement");
                    ui.label(
                        "Open a manifest (Ctrl+O), drop one here, or open the simulated demo from the File menu. A \
                         height map (.x3p, .sdf, .tif) opens in the Inspect view.",
                    );
                }
            });
            return;
        }
        let no_measurement;
        let (measurement, measurement_generation, result) = match &self.session {
            Some(s) => (&*s.measurement, s.measurement_generation, s.result.as_ref()),
            None => {
                no_measurement = crate::engine::fringe::Measurement {
                    bit_depth: 8,
                    saturation_level: 255,
                    sets: Vec::new(),
                    cameras: Vec::new(),
                    calibration: None,
                    label: String::new(),
                    projector: None,
                    id: 0,
                };
                (&no_measurement, self.measurement_counter, None)
            }
        };
        let cx = ViewCx {
            measurement,
            measurement_generation,
            result,
            compare: self.compare.output.as_ref(),
            compare_busy: self.compare.is_running(),
            params: &self.state.params,
            cursor: self.state.views.cursor,
            shown: Vec::new(),
            ranges: &self.ranges,
        };
        let rt = ViewRuntime {
            textures: &mut self.textures,
            transforms: &mut self.transforms,
            selection: self.selection,
            commands: &mut self.commands,
            cloud: &mut self.cloud,
            inspect: &mut self.inspect,
            history: &mut self.history,
            line: &mut self.line,
        };
        if map_alone {
            return views::inspect::show(ui, &mut self.state.views.inspect, &cx, rt);
        }
        views::show(ui, &mut self.state.views, &cx, rt);
        // The 3D view draws an older cloud only while it packs a newer one.
        let drawing_a_cloud = self.state.views.active == views::ViewKind::Cloud
            && result.is_some_and(|r| r.reconstruction.stereo.is_some());
        if !drawing_a_cloud {
            self.cloud.forget_other_results(result.map(|r| r.generation));
        }
    }

    fn draw_drop_hint(&self, ctx: &egui::Context) {
        let hovering = ctx.input(|i| !i.raw.hovered_files.is_empty());
        if !hovering {
            return;
        }
        let screen = ctx.content_rect();
        let painter = ctx.layer_painter(egui::LayerId::new(egui::Order::Foreground, egui::Id::unique("drop hint")));
        painter.rect_filled(screen, 0.0, egui::Color32::from_black_alpha(180));
        painter.text(
            screen.center(),
            egui::Align2::CENTER_CENTER,
            "Drop a manifest (.json) or a height map (.x3p, .sdf, .tif) to open it, or a folder of images to import it",
            egui::FontId::proportional(24.0),
            egui::Color32::WHITE,
        );
    }

    fn schedule_repaint(&self) {
        let now = self.ctx.input(|i| i.time);
        if self.loader.is_loading() || self.engine.is_running() || self.compare.is_running() {
            // The progress shown moves a few times a second; job ends wake
            // the UI by themselves. An animated bar would repaint every frame
            // instead, and with a software renderer take the cores the engine
            // needs (a 0.4 s run took 3.7 to 5 s under llvmpipe).
            self.ctx.request_repaint_after(self.progress_repaint());
        }
        if let Some(due) = self.engine.due_in_s(now) {
            self.ctx.request_repaint_after(Duration::from_secs_f64(due));
        }
    }
}

impl eframe::App for SheenApp {
    fn logic(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        self.poll_jobs();
        let now = ctx.input(|i| i.time);
        if self.engine.is_due(now) {
            self.start_run();
        }
        self.handle_input(ctx);
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        // The persisted state is the one source of the theme (egui's own memory
        // is restored too and could disagree).
        let theme = self.state.theme.preference();
        if ui.ctx().options(|o| o.theme_preference) != theme {
            ui.ctx().set_theme(theme);
        }
        self.draw(ui);
        self.run_commands();
        self.textures.end_frame();
        self.schedule_repaint();
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, eframe::APP_KEY, &self.state);
    }
}
