//! One measurement per process (issue 19): spawns the release `sheen` binary
//! on fringe sets written to disk, as a production line or a script runs it,
//! and reports the wall time from spawn to exit (min and median over the
//! repeats) with the run report's breakdown: load, the per-camera stages,
//! stereo, and writing.
//!
//! `cargo bench --bench one_shot` runs the paper's full workload (2 cameras x
//! 4 sets x 12 shifts of 2048x1536, the simulator's watch plate) as 8-bit
//! uncompressed TIFF, 16-bit TIFF and 8-bit PNG; `SHEEN_BENCH_SIZE=quick`
//! uses 512x384. `SHEEN_BENCH_REPEATS` sets the repeats (default 5). The sets
//! are written once under `target/one-shot-bench/` and reused.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use sheen::engine::control::RunControl;
use sheen::io::dataset::{ImageFileFormat, write_measurement_as};
use sheen::sim::{SceneKind, SimConfig, simulate};

struct Input {
    name: &'static str,
    bits: u32,
    format: ImageFileFormat,
    cameras: usize,
}

const INPUTS: [Input; 4] = [
    Input { name: "tiff-8bit", bits: 8, format: ImageFileFormat::Tiff, cameras: 2 },
    Input { name: "tiff-16bit", bits: 16, format: ImageFileFormat::Tiff, cameras: 2 },
    Input { name: "png-8bit", bits: 8, format: ImageFileFormat::Png, cameras: 2 },
    Input { name: "tiff-8bit-one-camera", bits: 8, format: ImageFileFormat::Tiff, cameras: 1 },
];

/// Writes the watch plate as `input` once; returns its manifest.
fn fringe_set(root: &Path, input: &Input, width: usize, height: usize) -> PathBuf {
    let dir = root.join(format!("{}-{width}x{height}", input.name));
    let manifest = dir.join(sheen::io::dataset::MANIFEST_FILE);
    if manifest.exists() {
        return manifest;
    }
    let mut config = SimConfig::new(SceneKind::WatchPlate, width, height);
    config.bits = input.bits;
    config.noise_sigma_dn = if input.bits > 8 { 256.0 } else { 1.0 };
    config.cameras = input.cameras;
    let sim = simulate(&config, &RunControl::new()).expect("simulate the watch plate");
    let partial = dir.with_extension("partial");
    let _ = std::fs::remove_dir_all(&partial);
    write_measurement_as(&partial, &sim.measurement, input.format).expect("write the fringe set");
    std::fs::rename(&partial, &dir).expect("move the fringe set into place");
    manifest
}

struct Run {
    wall_s: f64,
    report: serde_json::Value,
}

fn run_once(args: &[&str], report: &Path) -> Run {
    let start = Instant::now();
    let status = Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).status().expect("spawn sheen");
    let wall_s = start.elapsed().as_secs_f64();
    assert!(status.success(), "sheen {args:?} failed: {status}");
    let report = serde_json::from_slice(&std::fs::read(report).expect("read the report")).expect("parse the report");
    Run { wall_s, report }
}

/// Seconds of the report's stages whose names start with `prefix`.
fn stage_s(report: &serde_json::Value, prefix: &str) -> f64 {
    report["timings_s"]
        .as_array()
        .map(|stages| {
            stages
                .iter()
                .filter(|t| t["stage"].as_str().is_some_and(|s| s.starts_with(prefix) && s != "stereo total"))
                .filter_map(|t| t["seconds"].as_f64())
                .sum()
        })
        .unwrap_or(0.0)
}

fn summarise(label: &str, runs: &[Run]) {
    let mut walls: Vec<f64> = runs.iter().map(|r| r.wall_s).collect();
    walls.sort_by(f64::total_cmp);
    let median = walls[walls.len() / 2];
    // The breakdown of the median run.
    let run = runs.iter().find(|r| r.wall_s == median).expect("median run");
    let p = &run.report["process_s"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    println!(
        "{label:<36} min {:.3} s  median {median:.3} s | load {:.3}  left {:.3}  right {:.3}  stereo {:.3}  write {:.3}  (in process {:.3})",
        walls[0],
        f(&p["load"]),
        stage_s(&run.report, "phase left") + stage_s(&run.report, "unwrap+fuse left"),
        stage_s(&run.report, "phase right") + stage_s(&run.report, "unwrap+fuse right"),
        stage_s(&run.report, "stereo"),
        f(&p["write"]),
        f(&p["total"]),
    );
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument is not supported.
    let (width, height) = match std::env::var("SHEEN_BENCH_SIZE").as_deref() {
        Ok("quick") => (512, 384),
        _ => (2048, 1536),
    };
    let repeats: usize = std::env::var("SHEEN_BENCH_REPEATS").ok().and_then(|r| r.parse().ok()).unwrap_or(5).max(1);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/one-shot-bench");
    std::fs::create_dir_all(&root).expect("create the bench folder");
    let out = root.join("out");
    std::fs::create_dir_all(&out).expect("create the output folder");
    let report = out.join("report.json");
    let ply = out.join("cloud.ply");
    println!("one-shot processes, watch plate {width}x{height}, 2 cameras x 4 sets x 12 shifts, {repeats} runs each");
    for input in &INPUTS {
        let manifest = fringe_set(&root, input, width, height);
        let m = manifest.to_str().expect("UTF-8 path");
        if input.cameras == 1 {
            let args = ["phase", m, "--report", report.to_str().expect("path"), "-q"];
            let runs: Vec<Run> = (0..repeats).map(|_| run_once(&args, &report)).collect();
            summarise(&format!("phase {} --report", input.name), &runs);
            continue;
        }
        let args =
            ["reconstruct", m, "--out", ply.to_str().expect("path"), "--report", report.to_str().expect("path"), "-q"];
        let runs: Vec<Run> = (0..repeats).map(|_| run_once(&args, &report)).collect();
        summarise(&format!("reconstruct {} -> binary PLY", input.name), &runs);
        if input.name == "tiff-8bit" {
            analyze_runs(m, &out, repeats);
        }
    }
}

/// `sheen analyze` as a line runs it: the engine, the height map, one region's
/// flatness, one section profile, and the X3P/TIFF/PNG maps and tables.
/// Wall time only (analyze writes no run report).
fn analyze_runs(manifest: &str, out: &Path, repeats: usize) {
    let qc = out.join("qc");
    let qc = qc.to_str().expect("path");
    let args =
        ["analyze", manifest, "--out", qc, "-q", "--region", "r=circle:0,0,1", "--flatness", "r", "--hsection", "0"];
    let mut walls: Vec<f64> = (0..repeats)
        .map(|_| {
            let start = Instant::now();
            let status = Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).status().expect("spawn sheen");
            assert!(status.success(), "sheen {args:?} failed: {status}");
            start.elapsed().as_secs_f64()
        })
        .collect();
    walls.sort_by(f64::total_cmp);
    println!(
        "{:<36} min {:.3} s  median {:.3} s",
        "analyze tiff-8bit (flatness, section)",
        walls[0],
        walls[walls.len() / 2]
    );
}
