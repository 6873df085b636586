//! Getting a measurement into the app without blocking the UI: manifests are
//! decoded by `io::manifest::load_measurement` on a job thread (parallel
//! decode, progress, cancel), the demo is simulated on one, and the native
//! file dialog runs on one too (it is modal and would freeze the window).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;

use super::jobs::{Job, JobError, JobOutcome};
use super::session::DataSource;

/// A measurement ready to be shown.
pub struct LoadedData {
    pub measurement: Measurement,
    pub source: DataSource,
    /// Non-fatal findings of the loader (unknown keys, colour images, ...).
    pub warnings: Vec<String>,
}

/// A simulated measurement and how to describe it on screen.
pub struct DemoData {
    pub measurement: Measurement,
    /// e.g. "simulated watch plate, 320x240 px".
    pub description: String,
}

/// Builds the built-in demo of a given size (in camera pixels).
pub type DemoFn = fn(width: usize, height: usize, control: &RunControl) -> Result<DemoData, String>;

/// The built-in demo: the simulator's watch plate.
pub fn simulated_watch_plate(width: usize, height: usize, control: &RunControl) -> Result<DemoData, String> {
    control.begin_stage("simulating the demo watch plate");
    let simulation = crate::sim::demo(width, height);
    control.check().map_err(|e| e.to_string())?;
    let (w, h) = simulation.measurement.cameras.first().map_or((width, height), |c| (c.width, c.height));
    Ok(DemoData { measurement: simulation.measurement, description: format!("simulated watch plate, {w}x{h} px") })
}

/// Reads a manifest and decodes its images (in parallel, cancellable).
pub fn load_manifest(path: &Path, control: &RunControl) -> Result<LoadedData, JobError> {
    match crate::io::manifest::load_measurement(path, control) {
        Ok(loaded) => Ok(LoadedData {
            measurement: loaded.measurement,
            source: DataSource::File(path.to_path_buf()),
            warnings: loaded.warnings,
        }),
        Err(_) if control.is_cancelled() => Err(JobError::Cancelled),
        Err(e) => Err(JobError::Failed(e.to_string())),
    }
}

/// What the loader was asked to load.
#[derive(Clone, Debug, PartialEq)]
pub enum LoadRequest {
    Manifest(PathBuf),
    Demo { width: usize, height: usize },
}

impl LoadRequest {
    pub fn describe(&self) -> String {
        match self {
            LoadRequest::Manifest(path) => path.display().to_string(),
            LoadRequest::Demo { width, height } => format!("the simulated demo ({width}x{height} px)"),
        }
    }
}

/// A native file dialog returning this fast was never shown: rfd returns
/// `None` at once when neither an XDG portal nor zenity is available.
const DIALOG_NEVER_SHOWN: Duration = Duration::from_millis(400);

/// What came of the file dialog.
pub enum DialogOutcome {
    Picked(PathBuf),
    /// The operator closed the dialog.
    Dismissed,
    /// No dialog could be shown on this system.
    Unavailable,
}

#[derive(Default)]
pub struct Loader {
    job: Option<(LoadRequest, Job<LoadedData>)>,
    dialog: Option<(Instant, Job<Option<PathBuf>>)>,
}

impl Loader {
    /// Starts loading, cancelling a load in progress (the latest request wins).
    pub fn start(&mut self, request: LoadRequest, demo: DemoFn, repaint: impl Fn() + Send + 'static) {
        self.cancel();
        let label = format!("loading {}", request.describe());
        let work_request = request.clone();
        let job = Job::spawn(label, repaint, move |control| match work_request {
            LoadRequest::Manifest(path) => load_manifest(&path, control),
            LoadRequest::Demo { width, height } => {
                let demo = demo(width, height, control)
                    .map_err(|e| if control.is_cancelled() { JobError::Cancelled } else { JobError::Failed(e) })?;
                control.check()?;
                Ok(LoadedData {
                    measurement: demo.measurement,
                    source: DataSource::Simulated { description: demo.description },
                    warnings: Vec::new(),
                })
            }
        });
        self.job = Some((request, job));
    }

    pub fn cancel(&mut self) -> bool {
        match self.job.take() {
            Some((_, job)) => {
                job.cancel();
                true
            }
            None => false,
        }
    }

    /// The finished load with its request.
    pub fn poll(&mut self) -> Option<(LoadRequest, JobOutcome<LoadedData>)> {
        let outcome = self.job.as_ref()?.1.poll()?;
        self.job.take().map(|(request, _)| (request, outcome))
    }

    pub fn is_loading(&self) -> bool {
        self.job.is_some()
    }

    /// What is being loaded, its stage and fraction.
    pub fn progress(&self) -> Option<(String, String, f32)> {
        self.job.as_ref().map(|(request, job)| {
            let (stage, fraction) = job.progress();
            (request.describe(), stage, fraction)
        })
    }

    /// Opens the native file dialog on its own thread.
    pub fn open_dialog(&mut self, start_dir: Option<PathBuf>, repaint: impl Fn() + Send + 'static) {
        if self.dialog.is_some() {
            return;
        }
        let job = Job::spawn("file dialog", repaint, move |_| {
            let mut dialog = rfd::FileDialog::new()
                .set_title("Open a Sheen fringe-set manifest")
                .add_filter("Sheen manifest", &["json"])
                .add_filter("All files", &["*"]);
            if let Some(dir) = start_dir {
                dialog = dialog.set_directory(dir);
            }
            Ok(dialog.pick_file())
        });
        self.dialog = Some((Instant::now(), job));
    }

    pub fn dialog_open(&self) -> bool {
        self.dialog.is_some()
    }

    pub fn poll_dialog(&mut self) -> Option<DialogOutcome> {
        let (started, job) = self.dialog.as_ref()?;
        let outcome = job.poll()?;
        let quick = started.elapsed() < DIALOG_NEVER_SHOWN;
        self.dialog = None;
        Some(match outcome {
            JobOutcome::Done(Some(path)) => DialogOutcome::Picked(path),
            JobOutcome::Done(None) if quick => DialogOutcome::Unavailable,
            JobOutcome::Done(None) | JobOutcome::Cancelled => DialogOutcome::Dismissed,
            JobOutcome::Failed(_) | JobOutcome::Panicked(_) => DialogOutcome::Unavailable,
        })
    }
}
