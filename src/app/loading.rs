//! Getting a measurement into the app without blocking the UI: manifests are
//! decoded by `io::manifest::load_measurement` on a job thread (parallel
//! decode, progress, cancel), the demo is simulated on one, and the native
//! file dialog runs on one too (it is modal and would freeze the window).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;

use super::jobs::{Job, JobError, JobOutcome};
use super::run_data::DataSource;

/// A measurement ready to be shown.
pub struct LoadedData {
    pub measurement: Measurement,
    pub source: DataSource,
    /// Non-fatal findings of the loader (unknown keys, colour images, ...).
    pub warnings: Vec<crate::engine::warning::Warning>,
}

/// A simulated measurement and how to describe it on screen.
pub struct DemoData {
    pub measurement: Measurement,
    /// e.g. "simulated watch plate, 320x240 px".
    pub description: String,
}

/// Builds the built-in demo of a given size (in camera pixels).
pub type DemoFn = fn(width: usize, height: usize, control: &RunControl) -> anyhow::Result<DemoData>;

/// The built-in demo: the simulator's watch plate.
pub fn simulated_watch_plate(width: usize, height: usize, control: &RunControl) -> anyhow::Result<DemoData> {
    control.begin_stage("simulating the demo watch plate");
    let simulation = crate::sim::demo(width, height);
    control.check()?;
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
        Err(e) => Err(JobError::Failed(e.into())),
    }
}

/// Checks that a measurement is internally consistent before the app shows it:
/// the views and the inspector read samples by shape, so a stack holding fewer
/// samples than its shape says (a faulty importer, a truncated buffer) must be
/// refused here with a message instead of panicking the UI later.
pub fn check_measurement(m: &Measurement) -> anyhow::Result<()> {
    if m.cameras.is_empty() {
        anyhow::bail!("the measurement has no camera");
    }
    if m.sets.is_empty() {
        anyhow::bail!("the measurement has no fringe set");
    }
    for (s, set) in m.sets.iter().enumerate() {
        if !(set.period_px.is_finite() && set.period_px > 0.0) {
            anyhow::bail!("set {s} has period {} px; expected a positive number", set.period_px);
        }
        if set.phase_shifts_rad.iter().any(|d| !d.is_finite()) {
            anyhow::bail!("set {s} (period {} px) has a non-finite phase shift", set.period_px);
        }
    }
    for cam in &m.cameras {
        if cam.width == 0 || cam.height == 0 {
            anyhow::bail!("camera '{}' images are {}x{} px: empty", cam.name, cam.width, cam.height);
        }
        if cam.stacks.len() != m.sets.len() {
            anyhow::bail!(
                "camera '{}' has {} image stacks for {} fringe sets",
                cam.name,
                cam.stacks.len(),
                m.sets.len()
            );
        }
        for (s, (stack, set)) in cam.stacks.iter().zip(&m.sets).enumerate() {
            let expected = cam.width * cam.height * set.shifts();
            if stack.width != cam.width
                || stack.height != cam.height
                || stack.shifts != set.shifts()
                || stack.samples.len() != expected
            {
                anyhow::bail!(
                    "camera '{}' set {s} holds {} samples as {}x{} px x {} images; expected {expected} \
                     ({}x{} px x {} shifts)",
                    cam.name,
                    stack.samples.len(),
                    stack.width,
                    stack.height,
                    stack.shifts,
                    cam.width,
                    cam.height,
                    set.shifts()
                );
            }
        }
    }
    Ok(())
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

fn load(request: LoadRequest, demo: DemoFn, control: &RunControl) -> Result<LoadedData, JobError> {
    match request {
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
        let job = Job::spawn(label, repaint, move |control| {
            let data = load(work_request, demo, control)?;
            check_measurement(&data.measurement)?;
            Ok(data)
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
                .set_title("Open a Sheen fringe-set manifest or a height map")
                .add_filter("Sheen manifest", &["json"])
                .add_filter("Height map (Inspect only)", &["x3p", "sdf", "tif", "tiff"])
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Samples, next_measurement_id};

    fn measurement() -> Measurement {
        let sets = vec![FringeSetInfo::uniform(64.0, 4), FringeSetInfo::uniform(8.0, 4)];
        let stack = || FringeStack::from_planes_u8(8, 2, vec![vec![10; 16]; 4]);
        Measurement {
            bit_depth: 8,
            saturation_level: 255,
            sets,
            cameras: vec![CameraFringes { name: "left".into(), width: 8, height: 2, stacks: vec![stack(), stack()] }],
            calibration: None,
            label: "check".into(),
            projector: None,
            id: next_measurement_id(),
        }
    }

    #[test]
    fn a_consistent_measurement_passes() {
        check_measurement(&measurement()).expect("a consistent measurement");
    }

    #[test]
    fn inconsistent_measurements_are_refused_with_what_is_wrong() {
        let mut m = measurement();
        m.cameras[0].stacks[1].samples = Samples::U8(vec![0; 63]);
        let e = check_measurement(&m).expect_err("short stack").to_string();
        assert!(e.contains("camera 'left' set 1 holds 63 samples") && e.contains("expected 64"), "{e}");

        let mut m = measurement();
        m.cameras[0].stacks.pop();
        assert!(
            check_measurement(&m).expect_err("missing stack").to_string().contains("1 image stacks for 2 fringe sets")
        );

        let mut m = measurement();
        m.sets[0].phase_shifts_rad[2] = f64::NAN;
        assert!(check_measurement(&m).expect_err("nan shift").to_string().contains("non-finite phase shift"));

        let mut m = measurement();
        m.cameras.clear();
        assert!(check_measurement(&m).expect_err("no camera").to_string().contains("no camera"));
    }
}
