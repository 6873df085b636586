//! The calibration window: open a calibration set, detect the
//! target and solve the rig on worker threads, inspect each pose (both
//! cameras' images with the numbered detections and their magnified
//! residual vectors, a per-pose RMS chart, the report's warnings), leave
//! poses out and re-solve, choose the distortion model, save the
//! calibration and use it for the open fringe set.
//!
//! State and jobs live here; drawing is in `draw.rs`; the work itself (no
//! GUI types) in `work.rs`. Every job is polled once per frame; a failure
//! is shown in the window and logged, never a panic, and the previous
//! result stays.

mod draw;
pub mod work;

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use eframe::egui;

use super::jobs::{Job, JobOutcome};
use super::log::LogBook;
use crate::engine::calibration::model::DistortionModel;
use crate::engine::fringe::Measurement;

pub use work::{DetectedSet, DisplayImage, Solved};

/// A file dialog returning this fast was never shown (no portal, no zenity).
const DIALOG_NEVER_SHOWN: Duration = Duration::from_millis(400);

/// Default magnification of the residual vectors drawn over the images.
pub const DEFAULT_MAGNIFICATION: f32 = 200.0;

/// What the operator wants done with a native dialog's answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DialogPurpose {
    OpenSet,
    SaveCalibration,
}

/// The calibration window's state, runtime only (nothing here is persisted).
pub struct CalibrationView {
    /// Whether the window is shown.
    pub open: bool,
    /// The calibration-set path field.
    pub set_path: String,
    /// Where "Save" writes the calibration.
    pub save_path: String,
    pub distortion: DistortionModel,
    /// Residual vectors are drawn this many times their length.
    pub magnification: f32,
    /// Set index of the pose shown.
    pub selected_pose: usize,
    /// One camera's image (0 left, 1 right) or both.
    pub shown_camera: Option<usize>,
    /// Show the part of the images around the target.
    pub zoom_to_target: bool,
    /// Set on a new set; the first solution then picks the magnification.
    auto_magnification: bool,
    /// Set poses the operator left out of the solution.
    excluded: BTreeSet<usize>,
    set: Option<Arc<DetectedSet>>,
    solved: Option<Solved>,
    detect_job: Option<Job<DetectedSet>>,
    solve_job: Option<Job<Solved>>,
    save_job: Option<Job<PathBuf>>,
    apply_job: Option<Job<Measurement>>,
    dialog: Option<(DialogPurpose, Instant, Job<Option<PathBuf>>)>,
    /// The last failure, shown until the next success.
    error: Option<String>,
    /// The last success worth saying (saved, applied).
    notice: Option<String>,
    textures: HashMap<(usize, usize), egui::TextureHandle>,
    solves_finished: u64,
    last_saved: Option<PathBuf>,
}

impl Default for CalibrationView {
    fn default() -> Self {
        Self {
            open: false,
            set_path: String::new(),
            save_path: String::new(),
            distortion: DistortionModel::K1,
            magnification: DEFAULT_MAGNIFICATION,
            selected_pose: 0,
            shown_camera: None,
            zoom_to_target: true,
            auto_magnification: true,
            excluded: BTreeSet::new(),
            set: None,
            solved: None,
            detect_job: None,
            solve_job: None,
            save_job: None,
            apply_job: None,
            dialog: None,
            error: None,
            notice: None,
            textures: HashMap::new(),
            solves_finished: 0,
            last_saved: None,
        }
    }
}

fn repaint_handle(ctx: &egui::Context) -> impl Fn() + Send + 'static {
    let ctx = ctx.clone();
    move || ctx.request_repaint()
}

impl CalibrationView {
    // ---- read access (the app, tests) ----

    /// The loaded set with its detections.
    pub fn set(&self) -> Option<&DetectedSet> {
        self.set.as_deref()
    }

    /// The latest solution.
    pub fn solved(&self) -> Option<&Solved> {
        self.solved.as_ref()
    }

    /// Solutions finished so far (tests wait for the next one).
    pub fn solves_finished(&self) -> u64 {
        self.solves_finished
    }

    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    pub fn last_saved(&self) -> Option<&Path> {
        self.last_saved.as_deref()
    }

    pub fn excluded(&self) -> &BTreeSet<usize> {
        &self.excluded
    }

    /// True while a detection, solution, save, apply or dialog runs.
    pub fn is_busy(&self) -> bool {
        self.detect_job.is_some()
            || self.solve_job.is_some()
            || self.save_job.is_some()
            || self.apply_job.is_some()
            || self.dialog.is_some()
    }

    /// Whether the solution on screen is for other poses or another model than chosen.
    pub fn is_stale(&self) -> bool {
        self.solved.as_ref().is_some_and(|s| s.excluded != self.excluded || s.distortion != self.distortion)
    }

    // ---- actions ----

    /// Opens the calibration set at `path`: detection, then a solution, on workers.
    pub fn load(&mut self, ctx: &egui::Context, path: PathBuf, log: &mut LogBook) {
        if let Some(job) = self.detect_job.take() {
            job.cancel();
        }
        if let Some(job) = self.solve_job.take() {
            job.cancel();
        }
        log.info(format!("Calibration: reading {}", path.display()));
        self.set_path = path.display().to_string();
        self.error = None;
        self.notice = None;
        let label = format!("detecting the target in {}", path.display());
        self.detect_job = Some(Job::spawn(label, repaint_handle(ctx), move |control| work::detect(&path, control)));
    }

    /// Solves again with the current poses and model (the latest request wins).
    fn start_solve(&mut self, ctx: &egui::Context) {
        let Some(set) = self.set.clone() else {
            return;
        };
        if let Some(job) = self.solve_job.take() {
            job.cancel();
        }
        let excluded = self.excluded.clone();
        let distortion = self.distortion;
        self.solve_job = Some(Job::spawn("solving the rig", repaint_handle(ctx), move |control| {
            work::solve_set(&set, &excluded, distortion, control)
        }));
    }

    /// Leaves set pose `index` out of the solution (or takes it back) and re-solves.
    pub fn set_pose_used(&mut self, ctx: &egui::Context, index: usize, used: bool) {
        let changed = if used { self.excluded.remove(&index) } else { self.excluded.insert(index) };
        if changed {
            self.start_solve(ctx);
        }
    }

    fn set_distortion(&mut self, ctx: &egui::Context, model: DistortionModel) {
        if self.distortion != model {
            self.distortion = model;
            self.start_solve(ctx);
        }
    }

    /// Writes the solved calibration to `path` (atomically, never over the set's files).
    pub fn save_to(&mut self, ctx: &egui::Context, path: PathBuf) {
        let (Some(solved), Some(set)) = (&self.solved, &self.set) else {
            self.error = Some("Nothing to save yet: open a calibration set and let it solve.".into());
            return;
        };
        if self.is_stale() {
            self.error = Some(
                "The solution on screen is for another choice of poses or distortion model; wait for the new one."
                    .into(),
            );
            return;
        }
        let calibration = solved.calibration.clone();
        let inputs = set.inputs();
        self.save_path = path.display().to_string();
        self.save_job = Some(Job::spawn("saving the calibration", repaint_handle(ctx), move |_| {
            work::save(&path, &calibration, &inputs)
        }));
    }

    /// Gives the open fringe set the solved calibration (on a worker: it copies the samples).
    fn apply_to(&mut self, ctx: &egui::Context, measurement: Arc<Measurement>) {
        let Some(solved) = &self.solved else {
            return;
        };
        let calibration = solved.calibration.clone();
        self.apply_job = Some(Job::spawn("applying the calibration", repaint_handle(ctx), move |control| {
            work::with_calibration(&measurement, calibration, control)
        }));
    }

    fn open_dialog(&mut self, ctx: &egui::Context, purpose: DialogPurpose) {
        if self.dialog.is_some() {
            return;
        }
        let start_dir = self.set.as_ref().and_then(|s| s.path.parent().map(Path::to_path_buf));
        let job = Job::spawn("file dialog", repaint_handle(ctx), move |_| {
            let mut dialog = rfd::FileDialog::new().add_filter("JSON", &["json"]).add_filter("All files", &["*"]);
            if let Some(dir) = start_dir {
                dialog = dialog.set_directory(dir);
            }
            Ok(match purpose {
                DialogPurpose::OpenSet => dialog.set_title("Open a Sheen calibration set").pick_file(),
                DialogPurpose::SaveCalibration => {
                    dialog.set_title("Save the calibration").set_file_name("calibration.json").save_file()
                }
            })
        });
        self.dialog = Some((purpose, Instant::now(), job));
    }

    // ---- jobs ----

    /// Collects finished jobs; returns a measurement that now carries the
    /// new calibration, for the app to install and re-run.
    fn poll(&mut self, ctx: &egui::Context, log: &mut LogBook) -> Option<Measurement> {
        if let Some(outcome) = self.detect_job.as_ref().and_then(Job::poll) {
            self.detect_job = None;
            match outcome {
                JobOutcome::Done(set) => {
                    let usable = set.detected.len();
                    log.info(format!(
                        "Calibration: the target was found in {usable} of {} poses of {}.",
                        set.set.poses.len(),
                        set.path.display()
                    ));
                    let dir = set.path.parent().map(Path::to_path_buf).unwrap_or_default();
                    self.save_path = dir.join("calibration.json").display().to_string();
                    self.textures.clear();
                    self.excluded.clear();
                    self.solved = None;
                    self.auto_magnification = true;
                    self.selected_pose = set.detected.first().map_or(0, |p| p.source.index);
                    self.set = Some(Arc::new(set));
                    self.start_solve(ctx);
                }
                other => self.fail(log, "Could not read the calibration set", other),
            }
        }
        if let Some(outcome) = self.solve_job.as_ref().and_then(Job::poll) {
            self.solve_job = None;
            match outcome {
                JobOutcome::Done(solved) => {
                    let [l, r] = solved.report.rms_per_camera();
                    log.info(format!(
                        "Calibration solved from {} poses ({} distortion): RMS {l:.4} / {r:.4} px left / right.",
                        solved.report.poses.len(),
                        solved.distortion
                    ));
                    // Only what is new: re-solving repeats the set's warnings (skipped poses).
                    let before: &[crate::engine::warning::Warning] =
                        self.solved.as_ref().map_or(&[], |s| &s.report.warnings);
                    for w in solved.report.warnings.iter().filter(|w| !before.contains(w)) {
                        log.warning(format!("Calibration: {w}"));
                    }
                    self.error = None;
                    if self.auto_magnification {
                        self.auto_magnification = false;
                        if let Some(set) = &self.set {
                            self.magnification = work::residual_magnification(set, &solved.report);
                        }
                    }
                    self.solved = Some(solved);
                    self.solves_finished += 1;
                }
                other => self.fail(log, "The calibration could not be solved", other),
            }
        }
        if let Some(outcome) = self.save_job.as_ref().and_then(Job::poll) {
            self.save_job = None;
            match outcome {
                JobOutcome::Done(path) => {
                    let text = format!("Calibration saved to {}.", path.display());
                    log.info(text.clone());
                    self.notice = Some(text);
                    self.error = None;
                    self.last_saved = Some(path);
                }
                other => self.fail(log, "The calibration was not saved", other),
            }
        }
        if let Some((purpose, started, job)) = &self.dialog
            && let Some(outcome) = job.poll()
        {
            let (purpose, quick) = (*purpose, started.elapsed() < DIALOG_NEVER_SHOWN);
            self.dialog = None;
            match outcome {
                JobOutcome::Done(Some(path)) => match purpose {
                    DialogPurpose::OpenSet => self.load(ctx, path, log),
                    DialogPurpose::SaveCalibration => self.save_to(ctx, path),
                },
                JobOutcome::Done(None) if !quick => {}
                _ => {
                    self.error = Some(
                        "No file dialog could be shown on this system (it needs xdg-desktop-portal or zenity); type \
                         the path into the field instead."
                            .into(),
                    )
                }
            }
        }
        if let Some(outcome) = self.apply_job.as_ref().and_then(Job::poll) {
            self.apply_job = None;
            match outcome {
                JobOutcome::Done(m) => {
                    self.notice = Some(format!("The new calibration is used for {}; it is measured again.", m.label));
                    self.error = None;
                    return Some(m);
                }
                other => self.fail(log, "The calibration could not be used for the fringe set", other),
            }
        }
        None
    }

    fn fail<T>(&mut self, log: &mut LogBook, what: &str, outcome: JobOutcome<T>) {
        let text = match outcome {
            JobOutcome::Done(_) | JobOutcome::Cancelled => return,
            JobOutcome::Failed(e) => format!("{what}: {}", crate::error_text::error_chain(&e)),
            JobOutcome::Panicked(e) => format!("{what}: the worker crashed ({e}); please report this with the set."),
        };
        log.error(text.clone());
        self.error = Some(text);
        self.notice = None;
    }

    /// Draws the window (when open) and collects finished jobs. `fringe` is
    /// the open fringe set; a returned measurement is that set with the new
    /// calibration, for the app to install and measure again.
    pub fn show(
        &mut self,
        ctx: &egui::Context,
        fringe: Option<&Arc<Measurement>>,
        log: &mut LogBook,
    ) -> Option<Measurement> {
        let applied = self.poll(ctx, log);
        if self.is_busy() {
            ctx.request_repaint_after(Duration::from_millis(100));
        }
        if !self.open {
            return applied;
        }
        let mut open = true;
        let mut actions = Vec::new();
        egui::Window::new("Calibration")
            .id(egui::Id::unique("calibration window"))
            .open(&mut open)
            .default_pos([16.0, 30.0])
            .default_size([1360.0, 790.0])
            .min_size([720.0, 420.0])
            .resizable(true)
            .collapsible(false)
            .show(ctx, |ui| draw::window(ui, self, fringe.map(|m| m.as_ref()), &mut actions));
        self.open = open;
        for action in actions {
            match action {
                draw::Action::Load(path) => self.load(ctx, path, log),
                draw::Action::OpenDialog => self.open_dialog(ctx, DialogPurpose::OpenSet),
                draw::Action::SaveDialog => self.open_dialog(ctx, DialogPurpose::SaveCalibration),
                draw::Action::Save(path) => self.save_to(ctx, path),
                draw::Action::UsePose(index, used) => self.set_pose_used(ctx, index, used),
                draw::Action::Distortion(model) => self.set_distortion(ctx, model),
                draw::Action::Apply => {
                    if let Some(m) = fringe {
                        self.apply_to(ctx, Arc::clone(m));
                    }
                }
                draw::Action::Cancel => {
                    if let Some(job) = self.detect_job.take() {
                        job.cancel();
                    }
                    if let Some(job) = self.solve_job.take() {
                        job.cancel();
                    }
                    log.info("Calibration: detection or solution cancelled.");
                }
            }
        }
        applied
    }
}
