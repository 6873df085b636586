//! Background jobs: a closure on its own thread with a [`RunControl`] for
//! progress and cancellation, polled by the UI thread once per frame.
//!
//! The UI thread never blocks on a job: it only calls [`Job::poll`], which is a
//! `try_recv`. The closure runs under `catch_unwind`, so a panic in the engine
//! or a decoder becomes [`JobOutcome::Panicked`] with its message instead of
//! taking the application down.
//!
//! Jobs run below the UI thread's scheduling priority, on a thread pool of
//! their own (the GUI keeps its frame rate while the engine runs).
//! The engine spreads over every core with rayon; at equal priority the UI
//! thread then waits its turn behind it and frames stretch. Below it, a frame
//! runs as soon as it is due and the engine gets every cycle the UI leaves,
//! which with a GPU drawing is nearly all of them. Where the renderer itself
//! runs on the CPU (Mesa's llvmpipe: VMs, remote desktops) drawing a frame
//! takes the cores for tens of milliseconds, and priority would hand them to
//! the progress bar: a full-size run took 1.7 s instead of 0.6 s on the
//! development VM. The app then keeps jobs at normal priority
//! ([`set_jobs_below_ui_thread`]).

use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Instant;

use crate::engine::control::RunControl;
use crate::platform::set_this_threads_niceness;
pub use crate::platform::this_threads_niceness;

/// How a job ended.
#[derive(Debug)]
pub enum JobOutcome<T> {
    Done(T),
    /// The work returned an error, causes included (show it with `{:#}`).
    Failed(anyhow::Error),
    /// The owner cancelled the job before it finished.
    Cancelled,
    /// The work panicked; the text is the panic message.
    Panicked(String),
}

/// What a job closure returns: its value, or why it stopped.
pub enum JobError {
    Cancelled,
    Failed(anyhow::Error),
}

impl From<anyhow::Error> for JobError {
    fn from(e: anyhow::Error) -> Self {
        JobError::Failed(e)
    }
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
        let below_ui = jobs_below_ui_thread();
        let job_niceness =
            if below_ui { this_threads_niceness().map(|nice| (nice + BACKGROUND_NICE_STEPS).min(19)) } else { None };
        let spawned = std::thread::Builder::new().name(format!("sheen job: {label}")).spawn(move || {
            if let Some(nice) = job_niceness {
                set_this_threads_niceness(nice);
            }
            let pool = if below_ui { background_pool() } else { None };
            let run = || match pool {
                Some(pool) => pool.install(|| work(&worker_control)),
                None => work(&worker_control),
            };
            let outcome = match std::panic::catch_unwind(AssertUnwindSafe(run)) {
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
            let _ = failure_sender
                .send(JobOutcome::Failed(anyhow::Error::new(e).context("could not start a worker thread")));
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

static JOBS_BELOW_UI_THREAD: AtomicBool = AtomicBool::new(true);

/// Whether jobs started from now on run below the UI thread's priority (the
/// default). The app turns it off when its renderer runs on the CPU.
pub fn set_jobs_below_ui_thread(below: bool) {
    JOBS_BELOW_UI_THREAD.store(below, Ordering::Relaxed);
}

pub fn jobs_below_ui_thread() -> bool {
    JOBS_BELOW_UI_THREAD.load(Ordering::Relaxed)
}

/// How many nice steps below the thread that starts them jobs and their
/// workers run. Linux's scheduler weighs nice 0 against nice 10 about 9 to 1,
/// so a runnable UI thread gets its frame done almost at once, while with the
/// UI idle the workers still have every core.
pub const BACKGROUND_NICE_STEPS: i32 = 10;

/// The rayon pool the jobs' parallel work runs on: as many workers as the
/// global pool, at the priority of the job thread that first asks for it
/// (background). The global pool stays at normal priority for the UI
/// thread's own parallel work (picking in the 3D view). `None` if the pool
/// could not be built; jobs then use the global pool.
fn background_pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    POOL.get_or_init(|| {
        let niceness = this_threads_niceness();
        rayon::ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .thread_name(|i| format!("sheen worker {i}"))
            .start_handler(move |_| {
                if let Some(nice) = niceness {
                    set_this_threads_niceness(nice);
                }
            })
            .build()
            .ok()
    })
    .as_ref()
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

    /// The engine must not take the UI thread's turn: a job, and the rayon
    /// workers its parallel loops run on, sit below the thread that started it.
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn jobs_and_their_parallel_work_run_below_the_ui_thread() {
        use rayon::prelude::*;
        let ui_nice = this_threads_niceness().expect("read the test thread's niceness");
        let job = Job::spawn(
            "niceness",
            || {},
            |_| {
                let job_nice = this_threads_niceness();
                let worker_nice: Vec<(Option<i32>, Option<usize>)> = (0..64)
                    .into_par_iter()
                    .map(|_| {
                        std::thread::sleep(Duration::from_millis(1));
                        (this_threads_niceness(), rayon::current_thread_index())
                    })
                    .collect();
                Ok((job_nice, worker_nice))
            },
        );
        let expected = (ui_nice + BACKGROUND_NICE_STEPS).min(19);
        match wait(&job) {
            JobOutcome::Done((job_nice, worker_nice)) => {
                assert_eq!(job_nice, Some(expected), "the thread running the job");
                for (nice, index) in worker_nice {
                    // Items the job thread ran itself have no worker index.
                    assert_eq!(nice, Some(expected), "a rayon worker (index {index:?})");
                }
            }
            other => panic!("expected the niceness values, got {other:?}"),
        }
        assert_eq!(this_threads_niceness(), Some(ui_nice), "the UI thread keeps its priority");
    }

    #[test]
    fn errors_keep_their_causes() {
        let job: Job<()> = Job::spawn(
            "fail",
            || {},
            |_| Err(anyhow::Error::new(std::io::Error::other("disk full")).context("writing cloud.ply").into()),
        );
        match wait(&job) {
            JobOutcome::Failed(e) => {
                assert_eq!(format!("{e:#}"), "writing cloud.ply: disk full");
                assert!(e.root_cause().downcast_ref::<std::io::Error>().is_some(), "the cause keeps its type");
            }
            other => panic!("expected a failure, got {other:?}"),
        }
    }
}
