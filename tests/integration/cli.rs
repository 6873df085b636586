//! The `sheen` binary as a production line uses it: exit codes, one-line
//! errors naming the file, and the files it writes.

use std::path::Path;
use std::process::{Command, Output};

use sheen::io::dataset::write_measurement;

use crate::util::measurement;

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A one-camera 12-bit fringe set without calibration on disk.
fn one_camera_set(dir: &Path) -> std::path::PathBuf {
    let (w, h) = (96, 32);
    let m = measurement(
        w,
        h,
        4095,
        &[912.0, 144.0, 24.0, 12.0],
        6,
        |i| 60.0 + 7.5 * (i % w) as f64,
        |_, i| {
            if (i % w) > w / 2 { (3900.0, 600.0) } else { (2000.0, 1200.0) }
        },
    );
    write_measurement(dir, &m).expect("write the fringe set")
}

#[test]
fn phase_writes_the_map_contract_for_one_camera() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let maps = dir.path().join("maps");
    let report = dir.path().join("report.json");
    let out = sheen(&[
        "phase",
        manifest.to_str().expect("utf8"),
        "--maps",
        maps.to_str().expect("utf8"),
        "--report",
        report.to_str().expect("utf8"),
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    for name in [
        "left_fused_phase.tif",
        "left_source.tif",
        "left_saturation_12.tif",
        "left_wrapped_912.tif",
        "left_modulation_24.tif",
        "left_order_evidence.tif",
    ] {
        assert!(maps.join(name).is_file(), "missing {name}");
        assert!(maps.join(name.replace(".tif", ".png")).is_file(), "missing preview of {name}");
    }
    let fused = sheen::io::maps::read_f32_tiff(&maps.join("left_fused_phase.tif")).expect("read back");
    assert_eq!((fused.width, fused.height), (96, 32));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).expect("report")).expect("json");
    assert_eq!(json["cameras"][0]["camera"], "left");
    // The right half saturates some samples at every period: the report counts them.
    assert!(json["cameras"][0]["sets"][3]["saturated_pixels"].as_u64().expect("count") > 0);
    assert!(json["cameras"][0]["valid_percent"].as_f64().expect("percent") > 90.0);
}

#[test]
fn reconstruct_refuses_one_camera_with_one_clear_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let cloud = dir.path().join("cloud.ply");
    let out = sheen(&["reconstruct", manifest.to_str().expect("utf8"), "--out", cloud.to_str().expect("utf8")]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert_eq!(err.lines().filter(|l| l.starts_with("error:")).count(), 1, "{err}");
    assert!(err.contains("two cameras and a calibration") && err.contains("sheen phase"), "{err}");
    assert!(!cloud.exists(), "no cloud is written");
}

#[test]
fn missing_manifest_is_named_in_the_error() {
    let out = sheen(&["phase", "/nonexistent/fringe-set.json", "--maps", "/tmp/x"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("/nonexistent/fringe-set.json"), "{}", stderr(&out));
}

#[test]
fn outputs_never_overwrite_inputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let before = std::fs::read(&manifest).expect("manifest");
    let out = sheen(&["phase", manifest.to_str().expect("utf8"), "--report", manifest.to_str().expect("utf8")]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("input"), "{}", stderr(&out));
    assert_eq!(std::fs::read(&manifest).expect("manifest"), before, "the manifest is untouched");
}

#[test]
fn bad_parameters_are_refused_before_running() {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = one_camera_set(dir.path());
    let m = manifest.to_str().expect("utf8");
    let out = sheen(&["phase", m, "--report", "/tmp/r.json", "--sat-threshold", "0"]);
    assert!(stderr(&out).contains("outside 1..=65535"), "{}", stderr(&out));
    let out = sheen(&["phase", m, "--report", "/tmp/r.json", "--disable-set", "7"]);
    assert!(stderr(&out).contains("has 4 sets"), "{}", stderr(&out));
    let out = sheen(&["phase", m, "--report", "/tmp/r.json", "--method", "magic"]);
    assert!(!out.status.success() && stderr(&out).contains("magic"), "{}", stderr(&out));
}

#[test]
fn usage_errors_exit_1_on_every_subcommand_never_2() {
    // 2 is `sheen analyze`'s "a toleranced measurement failed"; a mistyped
    // command line must not be counted as a failed part.
    for sub in ["reconstruct", "phase", "simulate", "analyze", "calibrate", "import", "check", "recipe", "watch"] {
        let o = sheen(&[sub, "--no-such-option"]);
        assert_eq!(o.status.code(), Some(1), "{sub}: {}", stderr(&o));
        assert!(stderr(&o).contains("--no-such-option"), "{sub}: clap's message names the option: {}", stderr(&o));
        let help = sheen(&[sub, "--help"]);
        assert_eq!(help.status.code(), Some(0), "{sub} --help");
        assert!(!help.stdout.is_empty(), "{sub} --help prints to stdout");
    }
}

/// Every exit code the README documents, for every subcommand, on small
/// simulated inputs: 0 success, 1 bad input or usage (an unknown option, a
/// missing value), 2 a failed tolerance in `analyze`, 3 a disagreement in
/// `check`. A script tells a failed part from a mistyped command by these.
#[test]
fn every_documented_exit_code_of_every_subcommand() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |name: &str| dir.path().join(name).to_str().expect("utf8").to_string();
    let (set, target) = (p("set"), p("target"));
    let manifest = format!("{set}/fringe-set.json");
    let missing = p("no-such-file.json");
    let sim = ["--width", "320", "--height", "240", "-q"];
    let simulate_set: Vec<&str> =
        ["simulate", "--scene", "step-gauge", "--shifts", "4", "--out", set.as_str()].into_iter().chain(sim).collect();
    let simulate_target: Vec<&str> =
        ["simulate", "--scene", "calibration-target", "--poses", "5", "--out", target.as_str()]
            .into_iter()
            .chain(sim)
            .collect();
    let import = |out: &str, extra: &[&'static str]| -> Vec<String> {
        let mut a: Vec<String> = ["import", set.as_str(), "--out", out, "--pattern", "{camera}/p{period}_{shift}.png"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        a.extend(["--cameras", "left=left,right=right", "-q"].iter().chain(extra).map(|s| s.to_string()));
        a
    };
    // A manifest whose shifts run the wrong way: written without the check.
    let reversed = p("reversed.json");
    let region = ["--region", "middle=rect:-2,-2,2,2"];

    let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<String>>();
    let cases: Vec<(&str, Vec<String>, i32)> = vec![
        ("simulate: a fringe set", own(&simulate_set), 0),
        ("simulate: a calibration set", own(&simulate_target), 0),
        (
            "simulate: an image of width 0",
            own(&["simulate", "--scene", "flat", "--width", "0", "--out", &p("x"), "-q"]),
            1,
        ),
        ("phase", own(&["phase", &manifest, "--report", &p("phase.json"), "-q"]), 0),
        ("phase: no manifest", own(&["phase", &missing, "--report", &p("phase2.json"), "-q"]), 1),
        ("reconstruct", own(&["reconstruct", &manifest, "--out", &p("cloud.ply"), "-q"]), 0),
        ("reconstruct: no manifest", own(&["reconstruct", &missing, "--out", &p("cloud2.ply"), "-q"]), 1),
        ("analyze: nothing toleranced", own(&["analyze", &manifest, "--out", &p("qc0"), "-q"]), 0),
        (
            "analyze: a tolerance met",
            own(&[&["analyze", &manifest, "--out", &p("qc1"), "-q"][..], &region, &["--flatness", "middle<=100000"]]
                .concat()),
            0,
        ),
        (
            "analyze: a tolerance failed",
            own(&[&["analyze", &manifest, "--out", &p("qc2"), "-q"][..], &region, &["--flatness", "middle<=0.001"]]
                .concat()),
            2,
        ),
        (
            "analyze: a region outside the map",
            own(&[
                "analyze",
                &manifest,
                "--out",
                &p("qc3"),
                "-q",
                "--region",
                "far=rect:100,100,101,101",
                "--flatness",
                "far<=1",
            ]),
            1,
        ),
        ("analyze: no input", own(&["analyze", &missing, "--out", &p("qc4"), "-q"]), 1),
        (
            "calibrate",
            own(&["calibrate", &format!("{target}/calibration_set.json"), "--out", &p("calibration.json"), "-q"]),
            0,
        ),
        ("calibrate: no set", own(&["calibrate", &missing, "--out", &p("calibration2.json"), "-q"]), 1),
        ("import", import(&p("imported.json"), &[]), 0),
        ("import: written unchecked, shifts reversed", import(&reversed, &["--shift-sign", "-1", "--no-check"]), 0),
        ("import: no folder", own(&["import", &p("no-such-folder"), "--out", &p("i.json"), "-q"]), 1),
        ("check: agrees", own(&["check", &manifest, "-q", "--phase-grows", "right"]), 0),
        ("check: disagrees", own(&["check", &reversed, "-q", "--phase-grows", "right"]), 3),
        ("check: no manifest", own(&["check", &missing, "-q"]), 1),
        // Usage errors: a missing value, on every subcommand (an unknown
        // option is `usage_errors_exit_1_on_every_subcommand_never_2`).
        ("reconstruct: --out without a value", own(&["reconstruct", &manifest, "--out"]), 1),
        ("phase: --maps without a value", own(&["phase", &manifest, "--maps"]), 1),
        ("simulate: --scene without a value", own(&["simulate", "--out", &p("y"), "--scene"]), 1),
        ("analyze: --pitch-mm without a value", own(&["analyze", &manifest, "--out", &p("qc5"), "--pitch-mm"]), 1),
        ("calibrate: --out without a value", own(&["calibrate", &missing, "--out"]), 1),
        ("import: --pattern without a value", own(&["import", &set, "--pattern"]), 1),
        ("check: --phase-grows without a value", own(&["check", &manifest, "--phase-grows"]), 1),
        ("check: --phase-grows with a wrong value", own(&["check", &manifest, "--phase-grows", "sideways"]), 1),
        (
            "analyze: recorded",
            own(&["analyze", &manifest, "--out", &p("qc6"), "-q", "--record", "--db", &p("r.sqlite"), "--recipe", "x"]),
            0,
        ),
        ("history: parts recorded", own(&["history", "--db", &p("r.sqlite")]), 0),
        ("history: stats", own(&["history", "stats", "--db", &p("r.sqlite")]), 0),
        ("history: no database there", own(&["history", "--db", &p("none.sqlite")]), 1),
        ("history: a date that is none", own(&["history", "--db", &p("r.sqlite"), "--since", "2026-13-45"]), 1),
        ("history: --since without a value", own(&["history", "--db", &p("r.sqlite"), "--since"]), 1),
        ("history: another database's URL", own(&["history", "--db", "mysql://u@host/qc"]), 1),
        (
            "recipe: made",
            own(&["recipe", &manifest, "--spec", &p("spec.json"), "--out", &p("g.sheen-recipe.json"), "-q"]),
            0,
        ),
        ("recipe: no spec or session", own(&["recipe", &manifest, "--out", &p("h.sheen-recipe.json")]), 1),
        (
            "recipe: a missing reference",
            own(&["recipe", &missing, "--spec", &p("spec.json"), "--out", &p("i.json")]),
            1,
        ),
        (
            "watch: an empty inbox once",
            own(&["watch", &p("inbox"), "--recipe", &p("g.sheen-recipe.json"), "--db", &p("w.sqlite"), "--once"]),
            0,
        ),
        ("watch: a missing recipe", own(&["watch", &p("inbox"), "--recipe", &missing, "--once"]), 1),
        ("--version", own(&["--version"]), 0),
    ];
    std::fs::create_dir_all(p("inbox")).expect("an inbox");
    std::fs::write(p("spec.json"), r#"{"sheen_inspection": 1}"#).expect("a spec");
    let mut seen = std::collections::BTreeMap::<(String, i32), usize>::new();
    for (what, args, expected) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = sheen(&args);
        assert_eq!(o.status.code(), Some(*expected), "{what}: sheen {}\n{}", args.join(" "), stderr(&o));
        let sub = what.split(':').next().unwrap_or(what).to_string();
        *seen.entry((sub, *expected)).or_default() += 1;
    }
    // Every subcommand met its success and its error code, and the two
    // special codes were met where they belong.
    for sub in
        ["simulate", "phase", "reconstruct", "analyze", "calibrate", "import", "check", "history", "recipe", "watch"]
    {
        for code in [0, 1] {
            assert!(seen.contains_key(&(sub.to_string(), code)), "{sub} never exited {code}");
        }
    }
    assert!(seen.contains_key(&("analyze".to_string(), 2)) && seen.contains_key(&("check".to_string(), 3)));
}

/// Issue 19: the same simulated set written as uncompressed TIFF and as PNG
/// gives the same cloud bit for bit, and the run report says where a
/// one-shot run's time went (load, compute, write, adding up to the total).
#[test]
fn tiff_and_png_sets_give_the_same_cloud_and_the_report_times_the_process() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut clouds = Vec::new();
    for format in ["tiff", "png"] {
        let set = dir.path().join(format);
        let o = sheen(&[
            "simulate",
            "--scene",
            "step-gauge",
            "--width",
            "128",
            "--height",
            "96",
            "--noise",
            "1",
            "--image-format",
            format,
            "--out",
            set.to_str().expect("path"),
            "-q",
        ]);
        assert!(o.status.success(), "simulate {format}: {}", stderr(&o));
        let extension = if format == "tiff" { "tif" } else { "png" };
        assert!(set.join("left").join(format!("p0012_00.{extension}")).exists(), "{format} images written");
        let (ply, report) = (dir.path().join(format!("{format}.ply")), dir.path().join(format!("{format}.json")));
        let started = std::time::Instant::now();
        let o = sheen(&[
            "reconstruct",
            set.join("fringe-set.json").to_str().expect("path"),
            "--out",
            ply.to_str().expect("path"),
            "--report",
            report.to_str().expect("path"),
            "-q",
        ]);
        let wall_s = started.elapsed().as_secs_f64();
        assert!(o.status.success(), "reconstruct {format}: {}", stderr(&o));
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).expect("report")).expect("json");
        let p = &r["process_s"];
        let [load, compute, write, total] =
            ["load", "compute", "write", "total"].map(|k| p[k].as_f64().unwrap_or_else(|| panic!("process_s.{k}")));
        assert!(load > 0.0 && compute > 0.0 && write > 0.0, "{p}");
        // The process's own clock lies within the wall time the caller saw,
        // and each engine stage ran inside "compute" (not their sum: "stereo
        // total" holds the three stereo stages again).
        assert!(total <= wall_s && load + compute + write <= total + 1e-9, "{p} in {wall_s} s");
        let longest = r["timings_s"]
            .as_array()
            .expect("timings")
            .iter()
            .filter_map(|t| t["seconds"].as_f64())
            .fold(0.0, f64::max);
        assert!(longest > 0.0 && longest <= compute + 1e-3, "longest stage {longest} s, compute {compute} s");
        // The header names the source manifest, which differs; the vertices must not.
        let bytes = std::fs::read(&ply).expect("ply");
        let body = bytes.windows(11).position(|w| w == b"end_header\n").expect("header end") + 11;
        clouds.push(bytes[body..].to_vec());
    }
    assert!(clouds[0].len() > 1000 * 52, "a cloud of some size");
    assert!(clouds[0] == clouds[1], "TIFF and PNG input give the same vertices");
}

/// `SHEEN_SIMD` keeps the kernels on narrower instructions for a whole
/// process and changes no byte of the cloud; a value naming no instruction
/// set is refused before anything runs.
#[test]
fn sheen_simd_limits_the_kernels_without_changing_the_cloud() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = dir.path().join("set");
    let o = sheen(&[
        "simulate",
        "--scene",
        "watch-plate",
        "--width",
        "131",
        "--height",
        "67",
        "--noise",
        "1",
        "--out",
        set.to_str().expect("path"),
        "-q",
    ]);
    assert!(o.status.success(), "simulate: {}", stderr(&o));
    let manifest = set.join("fringe-set.json");
    let mut clouds = Vec::new();
    for limit in [None, Some("avx2"), Some("baseline")] {
        let ply = dir.path().join(format!("{}.ply", limit.unwrap_or("widest")));
        let report = dir.path().join(format!("{}.json", limit.unwrap_or("widest")));
        let mut command = Command::new(env!("CARGO_BIN_EXE_sheen"));
        command.args(["reconstruct", manifest.to_str().expect("path"), "--out", ply.to_str().expect("path"), "-q"]);
        command.args(["--report", report.to_str().expect("path")]);
        match limit {
            Some(l) => command.env("SHEEN_SIMD", l),
            None => command.env_remove("SHEEN_SIMD"),
        };
        let o = command.output().expect("run sheen");
        assert!(o.status.success(), "SHEEN_SIMD={limit:?}: {}", stderr(&o));
        clouds.push(std::fs::read(&ply).expect("ply"));
        // The report names the instruction set the run used: the limit's,
        // or the widest the CPU has.
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).expect("report")).expect("json");
        let kernels = r["kernels"].as_str().expect("kernels");
        let widest = sheen::engine::simd::supported();
        let expected = limit.map_or(widest, |l| sheen::engine::simd::parse_limit(l).expect("a level").min(widest));
        assert_eq!(kernels, expected.name(), "SHEEN_SIMD={limit:?}");
    }
    assert!(clouds[0].len() > 1000 * 52, "a cloud of some size");
    assert!(clouds[1] == clouds[0] && clouds[2] == clouds[0], "the same bytes on every instruction set");
    let o = Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(["reconstruct", manifest.to_str().expect("path"), "--out", "x.ply", "-q"])
        .env("SHEEN_SIMD", "sse4")
        .current_dir(dir.path())
        .output()
        .expect("run sheen");
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("SHEEN_SIMD=sse4: expected avx512, avx2 or baseline"), "{}", stderr(&o));
    assert!(!dir.path().join("x.ply").exists(), "nothing written");
}

/// `sheen analyze` takes the engine's order and stereo rules as `sheen
/// reconstruct` does, so rules can be compared on a manifest as inspected:
/// the rules reach the engine (the record keeps them) and change the cloud.
#[test]
fn analyze_takes_the_order_and_stereo_rules() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |name: &str| dir.path().join(name).to_str().expect("utf8").to_string();
    let set = p("set");
    let o = sheen(&["simulate", "--scene", "step-gauge", "--out", &set, "--width", "256", "--height", "192", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let manifest = format!("{set}/fringe-set.json");
    let db = p("records.sqlite");
    let run = |out: &str, extra: &[&str]| -> serde_json::Value {
        let mut args = vec!["analyze", manifest.as_str(), "--out", out, "-q", "--record", "--db", &db, "--recipe", "x"];
        args.extend(extra);
        let o = sheen(&args);
        assert_eq!(o.status.code(), Some(0), "{extra:?}: {}", stderr(&o));
        let text = std::fs::read_to_string(Path::new(out).join("measurements.json")).expect("measurements.json");
        serde_json::from_str(&text).expect("JSON")
    };
    let default = run(&p("default"), &[]);
    let strict = run(&p("strict"), &["--order-check", "strict", "--own-orders-only", "--stereo-continuity", "plain"]);
    let location = sheen::records::DbLocation::Sqlite(db.clone().into());
    let parts = sheen::records::Store::open(&location)
        .expect("open")
        .parts(&sheen::records::HistoryFilter::default())
        .expect("read");
    let params = |i: usize| -> serde_json::Value {
        serde_json::from_str(parts[i].record.engine_parameters.as_deref().expect("parameters")).expect("JSON")
    };
    let (a, b) = (params(0), params(1));
    assert_eq!(
        (&a["order_check"], &a["own_orders_only"], &a["stereo_continuity"]),
        (&"evidence".into(), &false.into(), &"strict".into())
    );
    assert_eq!(
        (&b["order_check"], &b["own_orders_only"], &b["stereo_continuity"]),
        (&"strict".into(), &true.into(), &"plain".into())
    );
    let points = |j: &serde_json::Value| j["rasterization"]["points"].as_u64().expect("points");
    // Plain continuity matches across what strict refuses: another cloud.
    assert_ne!(points(&strict), points(&default), "the rules must reach the engine");
    let o = sheen(&["analyze", &manifest, "--out", &p("bad"), "-q", "--order-check", "loose"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--order-check"), "{}", stderr(&o));
}

/// Issue 50, item 4: a tolerance typed with its unit is read in it. The
/// simulated watch plate's base is flat to some micrometres: `<=1mm`
/// and `<=100um` pass, a bare `<=1` (um, as always) fails, a unit a height
/// does not take is refused with one line.
#[test]
fn flatness_tolerances_are_read_in_the_unit_typed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = dir.path().join("wp");
    let o = sheen(&["simulate", "--scene", "watch-plate", "--out", set.to_str().expect("utf8"), "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let manifest = set.join("fringe-set.json");
    let analyze = |limit: &str| {
        let out = dir.path().join("qc");
        sheen(&[
            "analyze",
            manifest.to_str().expect("utf8"),
            "--out",
            out.to_str().expect("utf8"),
            "-q",
            "--region",
            "base=rect:-11,-8.5,11,-7.5",
            "--level",
            "base",
            "--flatness",
            &format!("base<={limit}"),
        ])
    };
    for (limit, code) in [("1mm", 0), ("100um", 0), ("100 µm", 0), ("1", 2), ("0.001mm", 2)] {
        let o = analyze(limit);
        assert_eq!(o.status.code(), Some(code), "<={limit}: {}", stderr(&o));
    }
    let o = analyze("5m");
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.trim().lines().count() == 1 && err.contains("'5m' has a unit this limit does not take"), "{err}");
}

/// Issue 50, item 3, end to end: `sheen analyze` exits 0 for a pass, 2 for
/// a fail and its own code 4 (not 1) for an inconclusive part, whose limit
/// lies within U of the value (ISO 14253-1, the default rule).
#[test]
fn analyze_exits_4_for_an_inconclusive_part_between_pass_and_fail() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = dir.path().join("wp");
    let o = sheen(&[
        "simulate",
        "--scene",
        "watch-plate",
        "--width",
        "512",
        "--height",
        "384",
        "--out",
        set.to_str().expect("utf8"),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let manifest = set.join("fringe-set.json");
    let out = dir.path().join("qc");
    let analyze = |limit_um: f64| {
        sheen(&[
            "analyze",
            manifest.to_str().expect("utf8"),
            "--out",
            out.to_str().expect("utf8"),
            "-q",
            "--region",
            "base=rect:-11,-8.5,11,-7.5",
            "--level",
            "base",
            "--flatness",
            &format!("base<={limit_um}um"),
        ])
    };
    let row = || -> serde_json::Value {
        let text = std::fs::read_to_string(out.join("measurements.json")).expect("measurements.json");
        let json: serde_json::Value = serde_json::from_str(&text).expect("json");
        json["measurements"]
            .as_array()
            .expect("rows")
            .iter()
            .find(|r| r["verdict"].is_string())
            .expect("the toleranced flatness")
            .clone()
    };
    assert_eq!(analyze(1000.0).status.code(), Some(0));
    let first = row();
    let (value, expanded) = (first["value"].as_f64().expect("value"), first["uncertainty"]["U"].as_f64().expect("U"));
    assert!(expanded > 0.0, "{first}");
    // The limit just above the value: inside the limit, not inside it less U.
    let o = analyze(value + 0.25 * expanded);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    assert_eq!(row()["verdict"], "inconclusive");
    assert_eq!(analyze(value + 2.0 * expanded).status.code(), Some(0));
    assert_eq!(analyze(value - 2.0 * expanded).status.code(), Some(2));
    assert_eq!(row()["verdict"], "fail");
}
