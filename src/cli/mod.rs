//! The command-line front end: clap subcommands over the engine, io and sim.
//! With no subcommand the binary opens the app. Every failure prints one line
//! (`error: ...` with its causes, `{:#}`) and exits non-zero.

pub mod analyze;
mod calibrate;
mod camera_projector;
mod check;
mod gauge;
mod history;
mod import;
mod memory;
mod progress;
mod recipe;
mod reconstruct;
mod simulate;
mod watch;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub use analyze::AnalyzeArgs;
pub use calibrate::CalibrateArgs;
pub use check::CheckArgs;
pub use history::{HISTORY_COLUMNS, HistoryArgs};
pub use import::ImportArgs;
pub use memory::{keep_freed_memory_for_reuse, keep_freed_pages_between_runs, keep_memory_as_the_app_does};
pub use recipe::RecipeArgs;
pub use reconstruct::{PhaseArgs, ReconstructArgs, RunArgs};
pub use simulate::SimulateArgs;
pub use watch::WatchArgs;

/// Microscopic 3D measurement of shiny surfaces (saturation-aware
/// multi-frequency phase shifting, dual telecentric stereo).
#[derive(Debug, Parser)]
#[command(name = "sheen", version, args_conflicts_with_subcommands = true)]
pub struct Cli {
    /// A fringe-set manifest to open in the app (no subcommand), or a folder
    /// of images to import there. Without it the app opens its built-in
    /// simulated demo.
    pub manifest: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Reconstruct a point cloud from a fringe set: phases, unwrapping,
    /// fusion, stereo matching, triangulation.
    Reconstruct(ReconstructArgs),
    /// Run only the per-camera stages (works with one camera and no calibration).
    Phase(PhaseArgs),
    /// Render a scene through the virtual rig as a fringe set with its truth.
    Simulate(SimulateArgs),
    /// Quality control: height map, levelling, step heights, flatness,
    /// coplanarity and section profiles from a manifest or a PLY cloud, with
    /// tolerances (exit code 2 when one fails).
    #[command(after_help = analyze::HELP)]
    Analyze(Box<AnalyzeArgs>),
    /// Calibrate the stereo rig from a calibration set (target images in
    /// several poses): writes calibration.json and, on request, a report.
    Calibrate(CalibrateArgs),
    /// Write a manifest for a folder of another rig's images (patterns,
    /// natural sort, skips, shift conventions), checking it first.
    Import(ImportArgs),
    /// Estimate the recorded phase shifts from the images and compare them
    /// with the manifest's (non-zero exit on a clear mismatch).
    Check(CheckArgs),
    /// The inspection records (`sheen analyze --record`): parts and values as
    /// a table or CSV; `history stats` for capability, control limits and
    /// run rules per measurement.
    History(HistoryArgs),
    /// Gauge studies: a Type-1 study (Cg, Cgk) or a Gage R&R (AIAG MSA:
    /// ANOVA or average and range) from a CSV or a recipe's records.
    Gauge(gauge::GaugeArgs),
    /// A part type's recipe from a reference part: its inspection, engine
    /// parameters and height map, which later parts are registered to so the
    /// regions follow them (`sheen analyze --recipe`, `sheen watch`).
    Recipe(RecipeArgs),
    /// The production line: inspect every part dropped into an inbox folder
    /// with a recipe, record and report it, one line per part.
    Watch(WatchArgs),
}

/// When the process started (the first thing `main` does), so a run
/// report's `process_s` counts from there and not from the command's own
/// start: parsing, allocator set-up and the like are the line's time too.
static PROCESS_STARTED: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();

/// The process's start as [`main`] noted it (now, for a library caller).
pub(crate) fn process_started() -> std::time::Instant {
    *PROCESS_STARTED.get_or_init(std::time::Instant::now)
}

/// Parses the command line and runs it; the binary's whole `main`.
pub fn main() -> ExitCode {
    process_started();
    keep_freed_memory_for_reuse();
    // clap exits 2 on a usage error, which `sheen analyze` uses for "a
    // toleranced measurement failed": a mistyped command must not read as a
    // failed part, so usage errors exit 1 like every other error.
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { ExitCode::FAILURE } else { ExitCode::SUCCESS };
        }
    };
    if let Err(e) = crate::engine::simd::limit_from_env() {
        eprintln!("sheen: {e}");
        return ExitCode::FAILURE;
    }
    let result = match cli.command {
        Some(Command::Reconstruct(args)) => reconstruct::reconstruct(&args),
        Some(Command::Phase(args)) => reconstruct::phase(&args),
        Some(Command::Simulate(args)) => simulate::run(&args),
        Some(Command::Analyze(args)) => match analyze::run(&args) {
            Ok(code) => return code,
            Err(e) => Err(e),
        },
        Some(Command::Calibrate(args)) => calibrate::run(&args),
        Some(Command::Import(args)) => import::run(&args),
        Some(Command::Check(args)) => match check::run(&args) {
            Ok(code) => return code,
            Err(e) => Err(e),
        },
        Some(Command::History(args)) => history::run(&args),
        Some(Command::Gauge(args)) => gauge::run(&args),
        Some(Command::Recipe(args)) => recipe::run(&args),
        Some(Command::Watch(args)) => {
            memory::keep_freed_pages_between_runs();
            watch::run(&args)
        }
        None => {
            memory::keep_freed_pages_between_runs();
            crate::app::run(cli.manifest)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", crate::error_text::error_chain(&e));
            ExitCode::FAILURE
        }
    }
}
