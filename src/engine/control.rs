//! Progress reporting and cancellation for long engine runs.
//!
//! The GUI runs the engine on a worker thread and must be able to replace a run
//! mid-way (latest parameters win); the engine polls [`RunControl`] between row
//! blocks so a cancel takes effect within milliseconds and leaves no partial
//! result behind (the caller gets [`Cancelled`] instead of data).

use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// The run was cancelled by its owner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("cancelled")]
pub struct Cancelled;

/// Shared between the thread that runs the engine and the one that watches it.
#[derive(Clone, Default)]
pub struct RunControl {
    inner: Arc<ControlInner>,
}

#[derive(Default)]
struct ControlInner {
    cancelled: AtomicBool,
    /// Fraction of the current stage done, as `f32` bits.
    fraction_bits: AtomicU32,
    stage: Mutex<String>,
}

impl RunControl {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn cancel(&self) {
        self.inner.cancelled.store(true, Ordering::Relaxed);
    }

    pub fn is_cancelled(&self) -> bool {
        self.inner.cancelled.load(Ordering::Relaxed)
    }

    /// `Err(Cancelled)` once [`cancel`](Self::cancel) was called.
    pub fn check(&self) -> Result<(), Cancelled> {
        if self.is_cancelled() { Err(Cancelled) } else { Ok(()) }
    }

    /// Starts a named stage at 0 %.
    pub fn begin_stage(&self, name: &str) {
        if let Ok(mut stage) = self.inner.stage.lock() {
            stage.clear();
            stage.push_str(name);
        }
        self.set_fraction(0.0);
    }

    pub fn set_fraction(&self, fraction: f32) {
        self.inner.fraction_bits.store(fraction.clamp(0.0, 1.0).to_bits(), Ordering::Relaxed);
    }

    /// Current stage name and its completed fraction in [0, 1].
    pub fn progress(&self) -> (String, f32) {
        let stage = self.inner.stage.lock().map(|s| s.clone()).unwrap_or_default();
        (stage, f32::from_bits(self.inner.fraction_bits.load(Ordering::Relaxed)))
    }
}

/// A no-op control for callers that neither cancel nor watch.
pub fn unobserved() -> RunControl {
    RunControl::new()
}
