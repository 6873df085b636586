//! Scheduling of engine runs: debounced automatic re-runs where the latest
//! parameters win, and the second-method runs of the comparison view. Both run
//! `pipeline::run` on a [`Job`] thread; the UI only polls.

use std::sync::Arc;

use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::engine::pipeline::{self, EngineError, Method, Params, Reconstruction};
use crate::platform::resident_bytes;

use super::jobs::{Job, JobError, JobOutcome};
use super::run_data::{CompareKey, CompareOutput, ComparePane, Derived, ResultSet};

/// Quiet time after the last parameter change before a run starts, in seconds:
/// long enough that dragging a slider does not start a run per frame, short
/// enough to feel immediate.
pub const DEBOUNCE_S: f64 = 0.15;

/// What one engine run hands back.
pub struct EngineOutput {
    pub reconstruction: Arc<Reconstruction>,
    pub derived: Arc<Derived>,
    pub measurement_id: u64,
    /// How much the process's resident memory grew during the run.
    pub resident_growth_bytes: Option<usize>,
}

/// Runs the whole method and derives the per-pixel view data, on the worker.
pub fn run_engine(
    measurement: &Measurement,
    params: &Params,
    previous: Option<&Reconstruction>,
    control: &RunControl,
) -> Result<EngineOutput, JobError> {
    let rec = pipeline::run(measurement, params, previous, control).map_err(|e| match e {
        EngineError::Cancelled(_) => JobError::Cancelled,
        e => JobError::Failed(e.into()),
    })?;
    control.begin_stage("preparing views");
    let derived = Derived::compute(&rec);
    Ok(EngineOutput {
        reconstruction: Arc::new(rec),
        derived: Arc::new(derived),
        measurement_id: measurement.id,
        resident_growth_bytes: None,
    })
}

/// The main engine run: at most one at a time, restarted when parameters change.
#[derive(Default)]
pub struct EngineRunner {
    job: Option<Job<EngineOutput>>,
    /// UI time (seconds) at which a scheduled run starts.
    due_at_s: Option<f64>,
    /// Runs started so far (tests count re-runs with it).
    runs_started: u64,
    /// The measurement the last warm-up was for.
    warmed_measurement: Option<u64>,
    /// Faulting in pages for the next run ([`warm_pages`]).
    warm: Option<Job<()>>,
    /// Warm-ups started so far.
    warmups_started: u64,
}

/// Blocks the warm-up touches and frees: a full-size map's size, the size
/// the engine's buffers come in.
const WARM_BLOCK_BYTES: usize = 12 << 20;

/// Touches `bytes` of fresh memory and frees it. The app keeps the pages it
/// frees (`cli::keep_freed_pages_between_runs`), so the next run's buffers
/// land on pages already faulted in. Without it the first re-run after
/// loading faulted in a whole result's worth of fresh pages while the first
/// result stayed on screen: 1.7 s from Run to result with a software
/// renderer at full size, against 0.8 s for later runs (docs/benchmarks-history.md).
///
/// It never takes more than half the memory the system can still give, and
/// stops where memory cannot be had: it is a head start, not a need.
fn warm_pages(bytes: usize, control: &RunControl) -> Result<(), JobError> {
    let available = crate::io::manifest::available_memory_bytes().map_or(usize::MAX, |a| (a / 2) as usize);
    let bytes = bytes.min(available);
    let mut blocks: Vec<Vec<u8>> = Vec::new();
    let mut warmed = 0;
    while warmed < bytes {
        if control.is_cancelled() {
            return Err(JobError::Cancelled);
        }
        // Written, not asked for zeroed: a zeroed request may be served
        // with pages never touched.
        let mut block: Vec<u8> = Vec::new();
        if block.try_reserve_exact(WARM_BLOCK_BYTES).is_err() {
            break;
        }
        block.resize(WARM_BLOCK_BYTES, 1);
        blocks.push(std::hint::black_box(block));
        warmed += WARM_BLOCK_BYTES;
    }
    drop(blocks);
    Ok(())
}

impl EngineRunner {
    /// A parameter changed: run `DEBOUNCE_S` after the last such call. The
    /// running job, computing for stale parameters, is cancelled at once.
    pub fn schedule(&mut self, now_s: f64) {
        self.due_at_s = Some(now_s + DEBOUNCE_S);
        if let Some(job) = &self.job {
            job.cancel();
        }
    }

    /// Seconds until the scheduled run, if one is scheduled (0 when due).
    pub fn due_in_s(&self, now_s: f64) -> Option<f64> {
        self.due_at_s.map(|t| (t - now_s).max(0.0))
    }

    pub fn is_due(&self, now_s: f64) -> bool {
        self.due_at_s.is_some_and(|t| now_s >= t)
    }

    /// Starts a run now, replacing (and cancelling) any running one.
    pub fn start(
        &mut self,
        measurement: Arc<Measurement>,
        params: Params,
        previous: Option<&ResultSet>,
        repaint: impl Fn() + Send + 'static,
    ) {
        self.cancel();
        self.due_at_s = None;
        self.runs_started += 1;
        // Phases are reused only from a result of the same measurement; the
        // engine checks the id as well.
        let previous = previous.map(|r| Arc::clone(&r.reconstruction));
        let label = format!("{} run", params.method);
        self.job = Some(Job::spawn(label, repaint, move |control| {
            let before = resident_bytes();
            let mut output = run_engine(&measurement, &params, previous.as_deref(), control)?;
            output.resident_growth_bytes = before.zip(resident_bytes()).map(|(b, a)| a.saturating_sub(b));
            Ok(output)
        }));
    }

    /// Cancels the running job and any scheduled run; true if something was stopped.
    pub fn cancel(&mut self) -> bool {
        if let Some(warm) = self.warm.take() {
            warm.cancel();
        }
        let scheduled = self.due_at_s.take().is_some();
        match self.job.take() {
            Some(job) => {
                job.cancel();
                true
            }
            None => scheduled,
        }
    }

    /// The outcome of the running job once it ended. After a measurement's
    /// first result, the memory the next run will need is faulted in in the
    /// background ([`warm_pages`]), since that result stays in memory (on
    /// screen) while the next one is made.
    pub fn poll(&mut self) -> Option<JobOutcome<EngineOutput>> {
        let outcome = self.job.as_ref()?.poll()?;
        self.job = None;
        if let JobOutcome::Done(output) = &outcome
            && let Some(growth) = output.resident_growth_bytes
            && self.warmed_measurement != Some(output.measurement_id)
        {
            self.warmed_measurement = Some(output.measurement_id);
            self.warmups_started += 1;
            self.warm = Some(Job::spawn(
                "preparing memory for the next run",
                || {},
                move |control| warm_pages(growth, control),
            ));
        }
        Some(outcome)
    }

    pub fn is_running(&self) -> bool {
        self.job.is_some()
    }

    pub fn progress(&self) -> Option<(String, f32)> {
        self.job.as_ref().map(Job::progress)
    }

    pub fn runs_started(&self) -> u64 {
        self.runs_started
    }

    /// Memory warm-ups started so far, and whether the last one is still on
    /// (not stopped by a new run).
    pub fn warmups(&self) -> (u64, bool) {
        (self.warmups_started, self.warm.is_some())
    }
}

/// The comparison view's runs: the two chosen methods with the main result's
/// other parameters, reusing the main result where a method equals its own.
#[derive(Default)]
pub struct CompareRunner {
    job: Option<(CompareKey, Job<CompareOutput>)>,
    pub output: Option<CompareOutput>,
}

impl CompareRunner {
    /// Makes sure results for `methods` on `main` exist or are being computed.
    pub fn request(
        &mut self,
        measurement: &Arc<Measurement>,
        main: &ResultSet,
        methods: [Method; 2],
        repaint: impl Fn() + Send + 'static,
    ) {
        let key = CompareKey { generation: main.generation, methods };
        if self.output.as_ref().is_some_and(|o| o.key == key) || self.job.as_ref().is_some_and(|(k, _)| *k == key) {
            return;
        }
        if let Some((_, job)) = self.job.take() {
            job.cancel();
        }
        let measurement = Arc::clone(measurement);
        let main_rec = Arc::clone(&main.reconstruction);
        let main_derived = Arc::clone(&main.derived);
        let label = format!("comparison {} vs {}", methods[0], methods[1]);
        let job = Job::spawn(label, repaint, move |control| {
            let mut panes = Vec::with_capacity(2);
            for method in methods {
                if method == main_rec.params.method {
                    panes.push(ComparePane {
                        method,
                        reconstruction: Arc::clone(&main_rec),
                        derived: Arc::clone(&main_derived),
                    });
                    continue;
                }
                let params = Params { method, ..main_rec.params.clone() };
                let out = run_engine(&measurement, &params, Some(&main_rec), control)?;
                panes.push(ComparePane { method, reconstruction: out.reconstruction, derived: out.derived });
            }
            let [a, b]: [ComparePane; 2] =
                panes.try_into().map_err(|_| JobError::Failed(anyhow::anyhow!("comparison produced no pair")))?;
            Ok(CompareOutput { key, panes: [a, b] })
        });
        self.job = Some((key, job));
    }

    /// Collects a finished comparison; returns the failure if it failed.
    pub fn poll(&mut self) -> Option<anyhow::Result<()>> {
        let (_, job) = self.job.as_ref()?;
        let outcome = job.poll()?;
        self.job = None;
        match outcome {
            JobOutcome::Done(output) => {
                self.output = Some(output);
                Some(Ok(()))
            }
            JobOutcome::Cancelled => None,
            JobOutcome::Failed(e) => Some(Err(e.context("the comparison run failed"))),
            JobOutcome::Panicked(e) => Some(Err(anyhow::anyhow!("the comparison run panicked: {e}"))),
        }
    }

    pub fn is_running(&self) -> bool {
        self.job.is_some()
    }

    pub fn progress(&self) -> Option<(String, f32)> {
        self.job.as_ref().map(|(_, j)| j.progress())
    }

    /// Forgets everything (a new measurement was loaded).
    pub fn reset(&mut self) {
        if let Some((_, job)) = self.job.take() {
            job.cancel();
        }
        self.output = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Samples, next_measurement_id};
    use std::time::Duration;

    /// One camera, two sets; `samples` overrides the stacks' sample count.
    fn measurement(samples: Option<usize>) -> Measurement {
        let (w, h, n) = (32, 4, 4);
        let sets = vec![FringeSetInfo::uniform(64.0, n), FringeSetInfo::uniform(8.0, n)];
        let stacks = sets
            .iter()
            .map(|set| {
                let planes = set
                    .phase_shifts_rad
                    .iter()
                    .map(|d| {
                        (0..w * h)
                            .map(|p| {
                                let phi = std::f64::consts::TAU * ((p % w) as f64 + 3.0) / set.period_px;
                                (120.0 + 80.0 * (phi + d).cos()).round() as u8
                            })
                            .collect()
                    })
                    .collect();
                let mut stack = FringeStack::from_planes_u8(w, h, planes);
                if let Some(len) = samples {
                    stack.samples = Samples::U8(vec![100; len]);
                }
                stack
            })
            .collect();
        Measurement {
            bit_depth: 8,
            saturation_level: 255,
            sets,
            cameras: vec![CameraFringes { name: "left".into(), width: w, height: h, stacks }],
            calibration: None,
            label: "runner test".into(),
            projector: None,
            id: next_measurement_id(),
        }
    }

    fn finish(runner: &mut EngineRunner) -> JobOutcome<EngineOutput> {
        for _ in 0..2000 {
            if let Some(outcome) = runner.poll() {
                return outcome;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("the engine run did not end");
    }

    /// After a measurement's first result the runner faults in, in the
    /// background, the memory that run added (that result stays while the
    /// next is made); later results of the same measurement start no
    /// warm-up, a new measurement's first does, and a new run stops one.
    #[test]
    fn the_first_result_of_a_measurement_warms_the_next_runs_memory() {
        let (a, b) = (Arc::new(measurement(None)), Arc::new(measurement(None)));
        let mut runner = EngineRunner::default();
        runner.start(Arc::clone(&a), Params::default(), None, || {});
        let JobOutcome::Done(first) = finish(&mut runner) else { panic!("first run failed") };
        if cfg!(target_os = "linux") {
            assert!(first.resident_growth_bytes.is_some(), "Linux reports the resident memory");
            assert_eq!(runner.warmups().0, 1, "the first result starts a warm-up");
        }
        let started = runner.warmups().0;
        runner.start(Arc::clone(&a), Params::default(), None, || {});
        assert!(!runner.warmups().1, "a new run stops the warm-up");
        let JobOutcome::Done(_) = finish(&mut runner) else { panic!("second run failed") };
        assert_eq!(runner.warmups().0, started, "a measurement is warmed for once");
        runner.start(Arc::clone(&b), Params::default(), None, || {});
        let JobOutcome::Done(_) = finish(&mut runner) else { panic!("third run failed") };
        assert_eq!(runner.warmups().0, 2 * started, "another measurement is warmed for");
    }

    #[test]
    fn a_warm_up_ends_and_stops_at_once_when_cancelled() {
        assert!(warm_pages(2 * WARM_BLOCK_BYTES + 1, &RunControl::new()).is_ok());
        let cancelled = RunControl::new();
        cancelled.cancel();
        let started = std::time::Instant::now();
        assert!(matches!(warm_pages(64 << 30, &cancelled), Err(JobError::Cancelled)));
        assert!(started.elapsed() < Duration::from_secs(5), "64 GiB were not touched");
    }

    #[test]
    fn a_run_derives_completeness_and_reuses_phases_when_only_sets_change() {
        let m = Arc::new(measurement(None));
        let mut runner = EngineRunner::default();
        runner.start(Arc::clone(&m), Params::default(), None, || {});
        let JobOutcome::Done(first) = finish(&mut runner) else { panic!("first run failed") };
        assert_eq!(first.derived.completeness.len(), 1);
        assert!(first.derived.completeness[0] > 0.99, "{:?}", first.derived.completeness);
        let previous = ResultSet { reconstruction: first.reconstruction, derived: first.derived, generation: 1 };
        let params = Params { enabled_sets: vec![true, false], ..Params::default() };
        runner.start(Arc::clone(&m), params, Some(&previous), || {});
        let JobOutcome::Done(second) = finish(&mut runner) else { panic!("second run failed") };
        assert!(Arc::ptr_eq(&second.reconstruction.cameras[0].sets[1], &previous.reconstruction.cameras[0].sets[1]));
        assert_eq!(runner.runs_started(), 2);
    }

    #[test]
    fn an_engine_panic_becomes_an_outcome() {
        // Stacks shorter than their shape pass the engine's shape check and
        // make its kernel index past the end: the worker must report, not die.
        let m = Arc::new(measurement(Some(10)));
        let mut runner = EngineRunner::default();
        runner.start(m, Params::default(), None, || {});
        assert!(matches!(finish(&mut runner), JobOutcome::Panicked(_)));
        assert!(!runner.is_running());
    }

    #[test]
    fn scheduling_waits_for_the_debounce_and_cancel_clears_it() {
        let mut runner = EngineRunner::default();
        runner.schedule(10.0);
        runner.schedule(10.1);
        assert!(!runner.is_due(10.2));
        assert!(runner.is_due(10.1 + DEBOUNCE_S));
        assert!(runner.cancel(), "a scheduled run counts as something to cancel");
        assert_eq!(runner.due_in_s(11.0), None);
    }
}
