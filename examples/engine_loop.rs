//! The engine on one manifest's images, run again and again in one process:
//! the warm engine of the app, on any data set, for a profiler (`perf record`)
//! or a quick A/B of two builds. Prints each run's stage times on stderr and
//! the minimum and median on stdout.
//!
//! `cargo run --release --example engine_loop -- SET/fringe-set.json [RUNS] [THRESHOLD_DN]`
//! (`SHEEN_SIMD=avx2` or `baseline` keeps the kernels below AVX-512).

use sheen::engine::control::RunControl;
use sheen::engine::pipeline::{self, Params};
use sheen::engine::simd;

/// The app's allocator: with glibc's, the buffers over its largest mmap
/// threshold (the cloud's coordinates) were faulted in afresh on every run,
/// about 11,000 page faults a run that the app does not have.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> anyhow::Result<()> {
    // As the app does: each run reuses the pages of the one before.
    sheen::cli::keep_memory_as_the_app_does();
    // `SHEEN_SIMD=avx2` (or `baseline`) compares the kernels' copies in one binary.
    simd::limit_from_env().map_err(anyhow::Error::msg)?;
    eprintln!("kernels: {:?}", simd::level());
    let mut args = std::env::args().skip(1);
    let manifest = args.next().ok_or_else(|| anyhow::anyhow!("usage: engine_loop MANIFEST [RUNS] [THRESHOLD_DN]"))?;
    let runs: usize = args.next().map_or(Ok(20), |s| s.parse())?;
    // A saturation threshold other than the set's default, as an operator types one.
    let threshold: Option<u16> = args.next().map(|s| s.parse()).transpose()?;
    let control = RunControl::new();
    let m = sheen::io::manifest::load_measurement(std::path::Path::new(&manifest), &control)?.measurement;
    let params = Params { saturation_threshold: threshold, ..Params::default() };
    let mut seconds = Vec::with_capacity(runs);
    let mut previous = None;
    for _ in 0..runs.max(1) {
        let start = std::time::Instant::now();
        let rec = pipeline::run(&m, &params, None, &control)?;
        seconds.push(start.elapsed().as_secs_f64());
        let stages: Vec<String> = rec.timings.iter().map(|(s, t)| format!("{s} {t:.3}")).collect();
        eprintln!("{:.3} s: {}", start.elapsed().as_secs_f64(), stages.join(", "));
        // Dropped after the next run, as the app replaces a shown result.
        previous = Some(rec);
    }
    drop(previous);
    seconds.sort_by(f64::total_cmp);
    println!("min {:.3} s, median {:.3} s over {} runs", seconds[0], seconds[seconds.len() / 2], seconds.len());
    Ok(())
}
