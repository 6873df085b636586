//! Progress on stderr for long runs: each stage is announced when it starts,
//! polled from the engine's [`RunControl`] by a watcher thread.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::engine::control::RunControl;

pub struct ProgressPrinter {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl ProgressPrinter {
    /// Starts printing stage names of `control` to stderr unless `quiet`.
    pub fn start(control: &RunControl, quiet: bool) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        if quiet {
            return Self { stop, handle: None };
        }
        let (control, flag) = (control.clone(), Arc::clone(&stop));
        let handle = std::thread::spawn(move || {
            let start = Instant::now();
            let mut last = String::new();
            while !flag.load(Ordering::Relaxed) {
                let (stage, _) = control.progress();
                if !stage.is_empty() && stage != last {
                    eprintln!("sheen: {:>6.2} s  {stage}", start.elapsed().as_secs_f64());
                    last = stage;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        });
        Self { stop, handle: Some(handle) }
    }
}

impl Drop for ProgressPrinter {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}
