//! The production line's throughput: `sheen watch` fed at the rig's pace.
//! Distinct parts (a step gauge at a different place and with its own noise
//! each, rendered once as 8-bit uncompressed TIFF under
//! `target/line-bench/`) are moved into the inbox one every 1.2 s while the
//! release binary watches it with a recipe made from an unmoved part; the
//! bench reports each part's time as the watch prints it (min, median,
//! max), the throughput (the interval between results, and how long after
//! its arrival the last part's result came against the first's: a growing
//! lag is a backlog), and the watch's peak memory after every part (it must
//! not grow with the parts).
//!
//! `cargo bench --bench line` runs 20 parts at the paper's 2048x1536 (about
//! 6 GB of images on disk) and 100 at 1024x768; `SHEEN_BENCH_SIZE=quick`
//! runs 20 parts at 1024x768 only, `SHEEN_BENCH_SIZE=full` the 20 at
//! 2048x1536 only. `SHEEN_BENCH_PACE_MS` sets the pace
//! (default 1200), `SHEEN_BENCH_PARTS` the number of parts.
//! `SHEEN_BENCH_COPY=ahead` copies every part aside before the clock starts
//! and only moves them in at the pace: the watch's own capacity, without
//! the copying's share of the two cores (by default each part is copied
//! while the line runs, as a rig's writes over the network would be).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use sheen::engine::control::RunControl;
use sheen::io::dataset::{ImageFileFormat, write_measurement_as};
use sheen::sim::{PartPlacement, SceneKind, SimConfig, simulate};

/// The same inspection as the line tests: two step heights, a plane fit and a texture.
const SPEC: &str = include_str!("../tests/line-spec.json");

/// Renders part `index` (0 = the unmoved reference) once; returns its folder.
fn part(root: &Path, index: usize, width: usize, height: usize) -> PathBuf {
    let dir = root.join(format!("part-{index:03}"));
    if dir.join(sheen::io::dataset::MANIFEST_FILE).exists() {
        return dir;
    }
    let mut config = SimConfig::new(SceneKind::StepGauge, width, height);
    config.noise_sigma_dn = 1.0;
    config.seed = index as u64 + 1;
    if index > 0 {
        let k = index as f64;
        config.part_placement = PartPlacement {
            rotation_deg: (k * 1.7) % 10.0 - 5.0,
            shift_mm: [(k * 0.37) % 4.0 - 2.0, (k * 0.61) % 4.0 - 2.0],
        };
    }
    let sim = simulate(&config, &RunControl::new()).expect("simulate the step gauge");
    let partial = dir.with_extension("partial");
    let _ = std::fs::remove_dir_all(&partial);
    write_measurement_as(&partial, &sim.measurement, ImageFileFormat::Tiff).expect("write the part");
    std::fs::rename(&partial, &dir).expect("move the part into place");
    dir
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("create");
    for entry in std::fs::read_dir(from).expect("read").filter_map(Result::ok) {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

/// Peak resident memory of a process so far (kB), from /proc.
fn peak_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status.lines().find(|l| l.starts_with("VmHWM:"))?.split_whitespace().nth(1)?.parse().ok()
}

fn run(width: usize, height: usize, parts: usize, pace: Duration) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("target/line-bench/{width}x{height}"));
    std::fs::create_dir_all(&root).expect("create the bench folder");
    let reference = part(&root, 0, width, height);
    let rendered: Vec<PathBuf> = (1..=parts).map(|i| part(&root, i, width, height)).collect();
    let work = root.join("run");
    let _ = std::fs::remove_dir_all(&work);
    let (inbox, staging) = (work.join("inbox"), work.join("staging"));
    std::fs::create_dir_all(&inbox).expect("inbox");
    std::fs::create_dir_all(&staging).expect("staging");
    std::fs::write(work.join("spec.json"), SPEC).expect("spec");
    let recipe = work.join("gauge.sheen-recipe.json");
    let s = |p: &Path| p.to_str().expect("UTF-8 path").to_string();
    let status = Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(["recipe", &s(&reference.join("fringe-set.json")), "--spec", &s(&work.join("spec.json"))])
        .args(["--out", &s(&recipe), "-q"])
        .status()
        .expect("spawn sheen recipe");
    assert!(status.success(), "sheen recipe failed");

    let mut watch = Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(["watch", &s(&inbox), "--recipe", &s(&recipe), "--db", &s(&work.join("records.sqlite"))])
        .args(["--out", &s(&work.join("results")), "--json", "--settle-ms", "200", "--poll-ms", "20"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn sheen watch");
    let pid = watch.id();
    let lines = BufReader::new(watch.stdout.take().expect("stdout")).lines();
    let copy_ahead = std::env::var("SHEEN_BENCH_COPY").is_ok_and(|v| v == "ahead");
    if copy_ahead {
        for from in &rendered {
            copy_dir(from, &staging.join(from.file_name().expect("name")));
        }
    }
    // The rig: one part every `pace`, each moved in whole (copied aside first).
    let start = Instant::now();
    let feeder = std::thread::spawn(move || {
        let mut arrivals = Vec::new();
        for (i, from) in rendered.iter().enumerate() {
            let name = from.file_name().expect("name").to_owned();
            if !copy_ahead {
                copy_dir(from, &staging.join(&name));
            }
            let due = pace * i as u32;
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
            std::fs::rename(staging.join(&name), inbox.join(&name)).expect("drop the part");
            arrivals.push(start.elapsed().as_secs_f64());
        }
        arrivals
    });
    let mut seconds = Vec::new();
    let mut results = Vec::new();
    let mut peaks = Vec::new();
    let mut verdicts = std::collections::BTreeMap::<String, usize>::new();
    for line in lines.take(parts) {
        let v: serde_json::Value = serde_json::from_str(&line.expect("read")).expect("JSON line");
        results.push(start.elapsed().as_secs_f64());
        seconds.push(v["seconds"].as_f64().unwrap_or(f64::NAN));
        *verdicts.entry(v["verdict"].as_str().unwrap_or("?").to_string()).or_default() += 1;
        peaks.push(peak_kb(pid).unwrap_or(0));
    }
    assert_eq!(results.len(), parts, "the watch printed fewer lines than parts");
    let arrivals = feeder.join().expect("feeder");
    let span_s = start.elapsed().as_secs_f64();
    // Keeping the pace means results come out as fast as parts arrive: the
    // interval between the first and the last result per part, and the
    // last part's result no later after its arrival than one part's time
    // (a backlog shows as a lag that grows with the parts).
    let interval_s = (results[parts - 1] - results[0]) / (parts - 1).max(1) as f64;
    let lag_s: Vec<f64> = results.iter().zip(&arrivals).map(|(r, a)| r - a).collect();
    // The copying shares the cores and the disk: when it falls behind, the
    // parts arrive slower than the pace and the interval between results
    // shows the rig's pace, not the watch's.
    let arrival_interval_s = (arrivals[parts - 1] - arrivals[0]) / (parts - 1).max(1) as f64;
    let _ = Command::new("kill").args(["-TERM", &pid.to_string()]).status();
    let _ = watch.wait();
    let mut sorted = seconds.clone();
    sorted.sort_by(f64::total_cmp);
    let mb = |kb: u64| kb as f64 / 1024.0;
    println!(
        "{width}x{height}: {parts} parts at {:.1} s{} | per part min {:.2} s, median {:.2} s, max {:.2} s | \
         {:.2} s per part between the first and the last result (parts arrived every {:.2} s) | last result \
         {:.2} s after its part arrived (first {:.2} s) | {:.2} s per part from the first arrival to the last result | peak memory after the \
         first part {:.0} MB, after the last {:.0} MB | verdicts {verdicts:?}",
        pace.as_secs_f64(),
        if copy_ahead { " (copied ahead)" } else { "" },
        sorted[0],
        sorted[sorted.len() / 2],
        sorted[sorted.len() - 1],
        interval_s,
        arrival_interval_s,
        lag_s[parts - 1],
        lag_s[0],
        span_s / parts as f64,
        mb(peaks[0]),
        mb(*peaks.last().unwrap_or(&0)),
    );
    // Whether the peak settles or keeps growing with the parts.
    let every: Vec<String> = peaks.iter().map(|kb| format!("{:.0}", mb(*kb))).collect();
    println!("{width}x{height}: peak memory after each part (MB): {}", every.join(" "));
}

fn main() {
    let pace =
        Duration::from_millis(std::env::var("SHEEN_BENCH_PACE_MS").ok().and_then(|v| v.parse().ok()).unwrap_or(1200));
    // More parts show whether memory settles over a longer run.
    let parts =
        |default: usize| std::env::var("SHEEN_BENCH_PARTS").ok().and_then(|v| v.parse().ok()).unwrap_or(default);
    match std::env::var("SHEEN_BENCH_SIZE").as_deref() {
        Ok("quick") => run(1024, 768, parts(20), pace),
        Ok("full") => run(2048, 1536, parts(20), pace),
        _ => {
            run(2048, 1536, parts(20), pace);
            run(1024, 768, parts(100), pace);
        }
    }
}
