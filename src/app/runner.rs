//! Scheduling of engine runs: debounced automatic re-runs where the latest
//! parameters win, and the second-method runs of the comparison view. Both run
//! `pipeline::run` on a [`Job`] thread; the UI only polls.

use std::sync::Arc;

use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::engine::pipeline::{self, EngineError, Method, Params, Reconstruction};

use super::jobs::{Job, JobError, JobOutcome};
use super::session::{CompareKey, CompareOutput, ComparePane, Derived, ResultSet};

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
        e => JobError::Failed(e.to_string()),
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
                panes.try_into().map_err(|_| JobError::Failed("comparison produced no pair".into()))?;
            Ok(CompareOutput { key, panes: [a, b] })
        });
        self.job = Some((key, job));
    }

    /// Collects a finished comparison; returns the failure text if it failed.
    pub fn poll(&mut self) -> Option<Result<(), String>> {
        let (_, job) = self.job.as_ref()?;
        let outcome = job.poll()?;
        self.job = None;
        match outcome {
            JobOutcome::Done(output) => {
                self.output = Some(output);
                Some(Ok(()))
            }
            JobOutcome::Cancelled => None,
            JobOutcome::Failed(e) => Some(Err(format!("the comparison run failed: {e}"))),
            JobOutcome::Panicked(e) => Some(Err(format!("the comparison run panicked: {e}"))),
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
