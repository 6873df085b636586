//! Scheduling of engine runs: debounced automatic re-runs where the latest
//! parameters win, and the second-method runs of the comparison view. Both run
//! `pipeline::run` on a [`Job`] thread; the UI only polls.

use std::sync::Arc;

use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::engine::pipeline::{self, EngineError, Method, Params, Reconstruction};

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
    Ok(EngineOutput { reconstruction: Arc::new(rec), derived: Arc::new(derived), measurement_id: measurement.id })
}

/// The main engine run: at most one at a time, restarted when parameters change.
#[derive(Default)]
pub struct EngineRunner {
    job: Option<Job<EngineOutput>>,
    /// UI time (seconds) at which a scheduled run starts.
    due_at_s: Option<f64>,
    /// Runs started so far (tests count re-runs with it).
    runs_started: u64,
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
            run_engine(&measurement, &params, previous.as_deref(), control)
        }));
    }

    /// Cancels the running job and any scheduled run; true if something was stopped.
    pub fn cancel(&mut self) -> bool {
        let scheduled = self.due_at_s.take().is_some();
        match self.job.take() {
            Some(job) => {
                job.cancel();
                true
            }
            None => scheduled,
        }
    }

    /// The outcome of the running job once it ended.
    pub fn poll(&mut self) -> Option<JobOutcome<EngineOutput>> {
        let outcome = self.job.as_ref()?.poll()?;
        self.job = None;
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
