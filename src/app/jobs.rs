//! Background jobs: a closure on its own thread with a [`RunControl`] for
//! progress and cancellation, polled by the UI thread once per frame.
//!
//! The UI thread never blocks on a job: it only calls [`Job::poll`], which is a
//! `try_recv`. The closure runs under `catch_unwind`, so a panic in the engine
//! or a decoder becomes [`JobOutcome::Panicked`] with its message instead of
//! taking the application down.

use std::panic::AssertUnwindSafe;
use std::sync::mpsc;
use std::time::Instant;

use crate::engine::control::RunControl;

/// How a job ended.
#[derive(Debug)]
pub enum JobOutcome<T> {
    Done(T),
    /// The work returned an error; the text is its full `{:#}` chain.
    Failed(String),
    /// The owner cancelled the job before it finished.
    Cancelled,
    /// The work panicked; the text is the panic message.
    Panicked(String),
}

/// What a job closure returns: its value, or why it stopped.
pub enum JobError {
    Cancelled,
    Failed(String),
}

impl From<crate::engine::control::Cancelled> for JobError {
    fn from(_: crate::engine::control::Cancelled) -> Self {
        JobError::Cancelled
    }
}

/// One running (or finished, not yet polled) background job.
pub struct Job<T> {
    /// What the job does, for the status line ("loading /x/manifest.json").
    pub label: String,
    control: RunControl,
    receiver: mpsc::Receiver<JobOutcome<T>>,
    started: Instant,
}

impl<T: Send + 'static> Job<T> {
    /// Starts `work` on a new thread. `repaint` is called when the job ends so
    /// the UI wakes up to collect the result (eframe sleeps otherwise).
    pub fn spawn(
        label: impl Into<String>,
        repaint: impl Fn() + Send + 'static,
        work: impl FnOnce(&RunControl) -> Result<T, JobError> + Send + 'static,
    ) -> Self {
        let label = label.into();
        let control = RunControl::new();
        let (sender, receiver) = mpsc::channel();
        let worker_control = control.clone();
        let failure_sender = sender.clone();
        let spawned = std::thread::Builder::new().name(format!("sheen job: {label}")).spawn(move || {
            let outcome = match std::panic::catch_unwind(AssertUnwindSafe(|| work(&worker_control))) {
                Ok(Ok(value)) => JobOutcome::Done(value),
                Ok(Err(JobError::Cancelled)) => JobOutcome::Cancelled,
                Ok(Err(JobError::Failed(message))) => JobOutcome::Failed(message),
                Err(payload) => JobOutcome::Panicked(panic_message(payload.as_ref())),
            };
            // The receiver is gone when the owner dropped the job: nothing to report to.
            let _ = sender.send(outcome);
            repaint();
        });
        if let Err(e) = spawned {
            let _ = failure_sender.send(JobOutcome::Failed(format!("could not start a worker thread: {e}")));
        }
        Self { label, control, receiver, started: Instant::now() }
    }
}

impl<T> Job<T> {
    /// The outcome, once the job has ended; `None` while it runs.
    pub fn poll(&self) -> Option<JobOutcome<T>> {
        match self.receiver.try_recv() {
            Ok(outcome) => Some(outcome),
            Err(mpsc::TryRecvError::Empty) => None,
            // The thread ended without sending: only possible if sending itself
            // failed, which `catch_unwind` leaves no room for; report it anyway.
            Err(mpsc::TryRecvError::Disconnected) => {
                Some(JobOutcome::Panicked("the worker thread ended without a result".into()))
            }
        }
    }

    /// Asks the job to stop; it ends with [`JobOutcome::Cancelled`] within milliseconds.
    pub fn cancel(&self) {
        self.control.cancel();
    }

    pub fn is_cancelled(&self) -> bool {
        self.control.is_cancelled()
    }

    /// Current stage name and its completed fraction in [0, 1].
    pub fn progress(&self) -> (String, f32) {
        self.control.progress()
    }

    pub fn elapsed_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }
}

/// The text of a panic payload (`&str` or `String`; anything else is named as such).
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn wait<T>(job: &Job<T>) -> JobOutcome<T> {
        for _ in 0..500 {
            if let Some(outcome) = job.poll() {
                return outcome;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("job did not finish within a second");
    }

    #[test]
    fn a_job_returns_its_value() {
        let job = Job::spawn("sum", || {}, |_| Ok(2 + 3));
        assert!(matches!(wait(&job), JobOutcome::Done(5)));
    }

    #[test]
    fn a_panic_becomes_an_outcome_with_its_message() {
        let job: Job<()> = Job::spawn("boom", || {}, |_| panic!("index 7 out of range"));
        match wait(&job) {
            JobOutcome::Panicked(message) => assert_eq!(message, "index 7 out of range"),
            other => panic!("expected a panic outcome, got {other:?}"),
        }
    }

    #[test]
    fn cancelling_stops_a_job_that_polls_its_control() {
        let job: Job<()> = Job::spawn(
            "spin",
            || {},
            |control| loop {
                control.check()?;
                std::thread::sleep(Duration::from_millis(1));
            },
        );
        assert!(job.poll().is_none(), "the job must still be running");
        job.cancel();
        assert!(matches!(wait(&job), JobOutcome::Cancelled));
    }

    #[test]
    fn errors_keep_their_text() {
        let job: Job<()> = Job::spawn("fail", || {}, |_| Err(JobError::Failed("disk full".into())));
        match wait(&job) {
            JobOutcome::Failed(message) => assert_eq!(message, "disk full"),
            other => panic!("expected a failure, got {other:?}"),
        }
    }
}
