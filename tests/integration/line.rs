//! The production line: a recipe that finds the part wherever it lies on
//! the stage, and `sheen watch` inspecting every part dropped into an inbox.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The line's parts: small, many of them.
const LINE_SIZE: [&str; 2] = ["256", "192"];
/// The acceptance's parts: large enough that a step height repeats to well
/// under 0.2 um between captures (at 384 x 288 two captures of the unmoved
/// part already differ by up to 0.4 um: the noise, not the placement).
const ACCEPTANCE_SIZE: [&str; 2] = ["1024", "768"];

/// A step gauge (or another scene) rendered at `place` = "DX,DY,DEG".
fn simulate(out: &Path, scene: &str, seed: u64, place: &str, [width, height]: [&str; 2]) {
    let o = sheen(&[
        "simulate",
        "--scene",
        scene,
        "--out",
        out.to_str().expect("utf8"),
        "-q",
        "--width",
        width,
        "--height",
        height,
        "--noise",
        "0.5",
        "--seed",
        &seed.to_string(),
        "--place",
        place,
    ]);
    assert!(o.status.success(), "simulate: {}", text(&o.stderr));
}

/// Regions on the 200 um and 50 um bars away from their edges, a section,
/// step heights, a plane fit (RMS flatness) and an areal texture.
const SPEC: &str = include_str!("../line-spec.json");

/// A recipe made from an unmoved step gauge in `dir`.
fn make_recipe(dir: &Path, size: [&str; 2]) -> PathBuf {
    make_recipe_with(dir, size, &[])
}

/// The same with more `sheen recipe` options.
fn make_recipe_with(dir: &Path, size: [&str; 2], extra: &[&str]) -> PathBuf {
    simulate(&dir.join("reference"), "step-gauge", 1, "0,0,0", size);
    let spec = dir.join("spec.json");
    std::fs::write(&spec, SPEC).expect("spec");
    let recipe = dir.join("gauge.sheen-recipe.json");
    let reference = dir.join("reference/fringe-set.json");
    let mut args = vec!["recipe", reference.to_str().expect("utf8"), "--spec", spec.to_str().expect("utf8")];
    args.extend(["--out", recipe.to_str().expect("utf8"), "-q"]);
    args.extend(extra);
    let o = sheen(&args);
    assert!(o.status.success(), "recipe: {}", text(&o.stderr));
    recipe
}

/// `sheen watch` started in the background with `args`.
fn start_watch(args: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the watch")
}

/// The first part a running watch reports; then SIGTERM, which must end it cleanly.
fn first_part_then_stop(mut child: std::process::Child) -> serde_json::Value {
    let line = BufReader::new(child.stdout.take().expect("stdout")).lines().next().expect("a line").expect("read");
    Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill");
    assert_eq!(child.wait().expect("wait").code(), Some(0));
    serde_json::from_str(&line).expect("json")
}

/// `measurements.json`'s rows: name -> (value, unit).
fn rows(out: &Path) -> HashMap<String, (f64, String)> {
    measurements(out)
        .iter()
        .filter_map(|r| {
            Some((r["name"].as_str()?.to_string(), (r["value"].as_f64()?, r["unit"].as_str()?.to_string())))
        })
        .collect()
}

/// `measurements.json`'s rows as written.
fn measurements(out: &Path) -> Vec<serde_json::Value> {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("measurements.json")).expect("read")).expect("json");
    json["measurements"].as_array().expect("rows").clone()
}

fn analyze(input: &Path, recipe: &Path, out: &Path) -> Output {
    sheen(&[
        "analyze",
        input.join("fringe-set.json").to_str().expect("utf8"),
        "--recipe",
        recipe.to_str().expect("utf8"),
        "--out",
        out.to_str().expect("utf8"),
        "-q",
    ])
}

/// The acceptance: the same scene moved by up to 2 mm and turned by up to
/// 5 degrees in the stage plane gives every step height and plane fit, and
/// the texture's height parameters (Sa, Sq), within 1 % or 0.2 um of the
/// unmoved part; the placement is found to 0.05 degree and 0.1 mm; another
/// scene is refused as "part not found". (The texture's extreme values, Sp,
/// Sv, Sz, are the noise's peaks on this flat bar and differ between any
/// two captures, moved or not: they are not compared.)
#[test]
fn a_moved_part_measures_as_the_unmoved_one_and_another_part_is_not_found() {
    let dir = tempfile::tempdir().expect("tempdir");
    let recipe = make_recipe(dir.path(), ACCEPTANCE_SIZE);
    simulate(&dir.path().join("still"), "step-gauge", 2, "0,0,0", ACCEPTANCE_SIZE);
    let still_out = dir.path().join("still-out");
    let o = analyze(&dir.path().join("still"), &recipe, &still_out);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let still = rows(&still_out);
    for (k, place) in ["2,-1.5,5", "-2,2,-5", "1.2,0.4,-2.5"].iter().enumerate() {
        let part = dir.path().join(format!("moved-{k}"));
        simulate(&part, "step-gauge", 3 + k as u64, place, ACCEPTANCE_SIZE);
        let out = dir.path().join(format!("moved-{k}-out"));
        let o = analyze(&part, &recipe, &out);
        assert!(o.status.success(), "{place}: {}", text(&o.stderr));
        let moved = rows(&out);
        let truth: Vec<f64> = place.split(',').map(|v| v.parse().expect("number")).collect();
        assert!((moved["alignment rotation"].0 - truth[2]).abs() < 0.05, "{place}: {:?}", moved["alignment rotation"]);
        for (axis, t) in [("X", truth[0]), ("Y", truth[1])] {
            let found = moved[&format!("alignment shift {axis}")].0;
            assert!((found - t).abs() < 0.1, "{place}: shift {axis} {found} against {t}");
        }
        assert!(moved["alignment score"].0 > 0.99, "{place}: score {}", moved["alignment score"].0);
        let mut compared = 0;
        for (name, &(value, ref unit)) in &still {
            let texture_height = name == "top Sa" || name == "top Sq";
            if !(texture_height || ["step 200", "step 50", "top rms"].contains(&name.as_str())) {
                continue;
            }
            assert_eq!(unit, "um", "{name}");
            let other = moved[name].0;
            let allowed = (0.01 * value.abs()).max(0.2);
            assert!((other - value).abs() <= allowed, "{place}: {name} {other} um against {value} um unmoved");
            compared += 1;
        }
        assert_eq!(compared, 5, "every compared measurement was there");
        // The part less its aligned reference is the two captures' noise.
        let tif =
            tiff::decoder::Decoder::new(std::fs::File::open(out.join("difference_to_reference.tif")).expect("tif"))
                .expect("decoder")
                .read_image()
                .expect("read");
        let tiff::decoder::DecodingResult::F32(values) = tif else { panic!("float32 TIFF") };
        let mut abs: Vec<f32> = values.iter().filter(|v| v.is_finite()).map(|v| v.abs()).collect();
        abs.sort_by(f32::total_cmp);
        let median_um = abs[abs.len() / 2];
        assert!(median_um < 1.0, "{place}: median |difference to the reference| {median_um} um");
    }

    simulate(&dir.path().join("other"), "watch-plate", 1, "0,0,0", ACCEPTANCE_SIZE);
    let o = analyze(&dir.path().join("other"), &recipe, &dir.path().join("other-out"));
    assert_eq!(o.status.code(), Some(1), "another part type is not measured");
    assert!(text(&o.stderr).contains("part not found: match score"), "{}", text(&o.stderr));
    assert!(!dir.path().join("other-out/measurements.json").exists(), "nothing measured in the wrong place");
}

/// A line writes a part's map pictures only when the part fails (the watch's
/// default; the X3P, the measurements and the profiles always): a passing
/// part's folder holds no TIFF or PNG, not even an earlier run's, and its
/// measurements.json names none; a part outside a tolerance gets them all.
#[test]
fn map_pictures_are_written_for_failed_parts_only_when_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let recipe = make_recipe(dir.path(), LINE_SIZE);
    let part = dir.path().join("part");
    simulate(&part, "step-gauge", 5, "0.5,-0.3,1.5", LINE_SIZE);
    let out = dir.path().join("out");
    let pictures = ["height_map.tif", "height_map.png", "difference_to_reference.tif", "difference_to_reference.png"];
    let run = |extra: &[&str]| {
        let manifest = part.join("fringe-set.json");
        let mut args = vec!["analyze", manifest.to_str().expect("utf8"), "--recipe", recipe.to_str().expect("utf8")];
        args.extend(["--out", out.to_str().expect("utf8"), "-q"]);
        args.extend(extra);
        let o = sheen(&args);
        assert!(o.status.success() || o.status.code() == Some(2), "{extra:?}: {}", text(&o.stderr));
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("measurements.json")).expect("json")).expect("json");
        (json["overall_verdict"].as_str().map(String::from), json["height_map_files"].clone())
    };
    let present = |names: &[&str]| names.iter().filter(|n| out.join(n).is_file()).count();

    // `sheen analyze` writes them by default.
    let (verdict, files) = run(&[]);
    assert_eq!(verdict.as_deref(), Some("pass"));
    assert_eq!((present(&pictures), files["png"].as_str()), (4, Some("height_map.png")));

    // A passing part with --map-images failed: none, and the earlier run's are gone.
    let (verdict, files) = run(&["--map-images", "failed"]);
    assert_eq!(verdict.as_deref(), Some("pass"));
    assert_eq!(present(&pictures), 0, "no pictures of a passing part");
    assert!(files["png"].is_null() && files["tif"].is_null(), "{files}");
    assert_eq!(present(&["height_map.x3p", "measurements.csv", "profile_A.csv"]), 3);

    // Outside a tolerance: all four.
    let (verdict, files) = run(&["--map-images", "failed", "--step", "tight=ref200:top200=100±1"]);
    assert_eq!(verdict.as_deref(), Some("fail"));
    assert_eq!((present(&pictures), files["tif"].as_str()), (4, Some("height_map.tif")));

    // The watch's default is `failed`: a passing part keeps its X3P only.
    let inbox = dir.path().join("inbox");
    std::fs::create_dir_all(&inbox).expect("inbox");
    simulate(&inbox.join("part-01"), "step-gauge", 6, "-0.4,0.2,-1", LINE_SIZE);
    let o = watch_once(&inbox, &recipe, dir.path());
    assert!(text(&o.stdout).contains("\"pass\""), "{}", text(&o.stdout));
    let folder = dir.path().join("results/part-01");
    assert!(folder.join("height_map.x3p").is_file());
    assert!(pictures.iter().all(|n| !folder.join(n).exists()), "the watch wrote a passing part's pictures");
}

/// The watch measures the next part while the one before is recorded; a
/// part whose content is the same as one still in hand waits for that one's
/// record and is skipped, never inspected twice.
#[test]
fn a_copy_of_a_part_in_hand_is_skipped_not_inspected_twice() {
    let dir = tempfile::tempdir().expect("tempdir");
    let recipe = make_recipe(dir.path(), LINE_SIZE);
    let inbox = dir.path().join("inbox");
    simulate(&inbox.join("part-a"), "step-gauge", 8, "0.3,0.1,2", LINE_SIZE);
    let copy = sheen_copy_dir(&inbox.join("part-a"), &inbox.join("part-b"));
    assert!(copy > 0);
    simulate(&inbox.join("part-c"), "step-gauge", 9, "-0.3,0.2,-2", LINE_SIZE);
    let o = watch_once(&inbox, &recipe, dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let lines: Vec<serde_json::Value> =
        text(&o.stdout).lines().map(|l| serde_json::from_str(l).expect("json")).collect();
    let summary: Vec<(String, String)> = lines
        .iter()
        .map(|v| {
            let what = v["verdict"].as_str().or(v["skipped"].as_str()).unwrap_or("?");
            (v["folder"].as_str().unwrap_or("?").to_string(), what.to_string())
        })
        .collect();
    let expected = [("part-a", "pass"), ("part-b", "already recorded"), ("part-c", "pass")];
    assert_eq!(summary, expected.map(|(a, b)| (a.to_string(), b.to_string())).to_vec(), "{}", text(&o.stdout));
}

/// `--report-pdf` on the watch gives every part `DIR/PART/report.pdf`: a
/// PDF a reader opens, with that part's name and verdict in it; without the
/// flag there is none.
#[test]
fn the_watch_writes_each_parts_pdf_report_when_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let recipe = make_recipe(dir.path(), LINE_SIZE);
    let inbox = dir.path().join("inbox");
    for (name, seed, place) in [("part-01", 11, "0.2,-0.1,1"), ("part-02", 12, "-0.2,0.1,-1")] {
        simulate(&inbox.join(name), "step-gauge", seed, place, LINE_SIZE);
    }
    let o = watch_once_with(&inbox, &recipe, dir.path(), &["--report-pdf"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    for part in ["part-01", "part-02"] {
        let pdf = dir.path().join("results").join(part).join("report.pdf");
        let bytes = std::fs::read(&pdf).unwrap_or_else(|e| panic!("{}: {e}", pdf.display()));
        assert!(bytes.starts_with(b"%PDF-"), "{part}: not a PDF");
        let o = Command::new("pdftotext").args(["-layout", pdf.to_str().expect("utf8"), "-"]).output();
        let o = o.expect("pdftotext (poppler-utils)");
        assert!(o.status.success(), "pdftotext: {}", text(&o.stderr));
        let reader_text = text(&o.stdout);
        assert!(reader_text.contains(part) && reader_text.contains("PASS"), "{part}:\n{reader_text}");
    }

    let plain = dir.path().join("plain");
    simulate(&plain.join("inbox/part-03"), "step-gauge", 13, "0.1,0.1,0", LINE_SIZE);
    let o = watch_once(&plain.join("inbox"), &recipe, &plain);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(plain.join("results/part-03/height_map.x3p").is_file());
    assert!(!plain.join("results/part-03/report.pdf").exists(), "a report without --report-pdf");
}

/// `sheen watch --once` over `inbox`, its records and results in `work`.
fn watch_once(inbox: &Path, recipe: &Path, work: &Path) -> Output {
    watch_once_with(inbox, recipe, work, &[])
}

/// [`watch_once`] with more options.
fn watch_once_with(inbox: &Path, recipe: &Path, work: &Path, extra: &[&str]) -> Output {
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let (inbox_s, recipe_s, db, results) = (p(inbox), p(recipe), p(&work.join("r.sqlite")), p(&work.join("results")));
    let mut args = watch_args(&inbox_s, &recipe_s, &db, &results);
    args.push("--once");
    args.extend(extra);
    sheen(&args)
}

/// Copies a folder tree; returns the number of files copied.
fn sheen_copy_dir(from: &Path, to: &Path) -> usize {
    std::fs::create_dir_all(to).expect("create");
    let mut n = 0;
    for entry in std::fs::read_dir(from).expect("read").filter_map(Result::ok) {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            n += sheen_copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
            n += 1;
        }
    }
    n
}

/// The parts of a 20-part run, in arrival order: 17 good step gauges at
/// different places, a part missing an image, one with a truncated image
/// and one of another type.
fn fill_inbox(inbox: &Path) -> Vec<String> {
    let mut names = Vec::new();
    for i in 0..20u64 {
        let name = format!("part-{i:02}");
        let folder = inbox.join(&name);
        let scene = if i == 13 { "watch-plate" } else { "step-gauge" };
        let place = format!("{:.2},{:.2},{:.1}", 0.1 * (i as f64 - 10.0), 0.05 * i as f64, (i % 7) as f64 - 3.0);
        simulate(&folder, scene, 100 + i, &place, LINE_SIZE);
        if i == 5 {
            std::fs::remove_file(folder.join("left/p0144_02.png")).expect("remove an image");
        }
        if i == 9 {
            let image = folder.join("right/p0024_05.png");
            let bytes = std::fs::read(&image).expect("read");
            std::fs::write(&image, &bytes[..bytes.len() / 3]).expect("truncate");
        }
        names.push(name);
    }
    names
}

fn watch_args<'a>(inbox: &'a str, recipe: &'a str, db: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "watch",
        inbox,
        "--recipe",
        recipe,
        "--db",
        db,
        "--out",
        out,
        "--json",
        "--settle-ms",
        "100",
        "--poll-ms",
        "20",
    ]
}

/// A 20-part run with three bad parts records 17 measured parts and 3
/// errors in arrival order and keeps going; stopped by SIGTERM midway and
/// started again, it inspects no part twice.
#[test]
fn watch_records_every_part_once_in_arrival_order_through_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let recipe = make_recipe(dir.path(), LINE_SIZE);
    let inbox = dir.path().join("inbox");
    let names = fill_inbox(&inbox);
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let (inbox_s, recipe_s, db, out) =
        (p(&inbox), p(&recipe), p(&dir.path().join("records.sqlite")), p(&dir.path().join("results")));

    // First run: stopped by SIGTERM after six parts.
    let mut child = Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(watch_args(&inbox_s, &recipe_s, &db, &out))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the watch");
    let mut first: Vec<serde_json::Value> = Vec::new();
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    while first.len() < 6 {
        let line = lines.next().expect("a line per part").expect("read");
        first.push(serde_json::from_str(&line).expect("one JSON object per line"));
    }
    let kill = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill");
    assert!(kill.success());
    // The parts in hand, if any, are finished and printed before the exit.
    for line in lines {
        first.push(serde_json::from_str(&line.expect("read")).expect("json"));
    }
    let status = child.wait().expect("wait");
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().expect("stderr"), &mut stderr).expect("stderr");
    assert_eq!(status.code(), Some(0), "a clean exit on SIGTERM: {stderr}");
    assert!(stderr.contains("stopping on request"), "{stderr}");
    assert!(first.len() < 20, "stopped midway ({} parts)", first.len());

    // Second run picks up the rest and skips the recorded ones.
    let mut args = watch_args(&inbox_s, &recipe_s, &db, &out);
    args.push("--once");
    let o = sheen(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let second: Vec<serde_json::Value> =
        text(&o.stdout).lines().map(|l| serde_json::from_str(l).expect("json")).collect();
    assert_eq!(second.iter().filter(|v| v["skipped"].is_string()).count(), first.len());

    // Every part inspected exactly once, in arrival order.
    let inspected: Vec<&serde_json::Value> =
        first.iter().chain(second.iter().filter(|v| !v["skipped"].is_string())).collect();
    let order: Vec<&str> = inspected.iter().map(|v| v["part"].as_str().expect("part")).collect();
    assert_eq!(order, names.iter().map(String::as_str).collect::<Vec<_>>(), "arrival order, each once");
    for v in &inspected {
        let part = v["part"].as_str().expect("part");
        let bad = ["part-05", "part-09", "part-13"].contains(&part);
        assert_eq!(v["verdict"].as_str(), Some(if bad { "error" } else { "pass" }), "{part}: {v}");
        assert_eq!(v["recorded"].as_bool(), Some(true), "{part}");
    }
    let reason = |part: &str| {
        inspected.iter().find(|v| v["part"] == part).and_then(|v| v["reason"].as_str()).unwrap_or("").to_string()
    };
    assert!(reason("part-05").contains("p0144_02.png"), "{}", reason("part-05"));
    assert!(reason("part-09").contains("p0024_05.png"), "{}", reason("part-09"));
    assert!(reason("part-13").contains("part not found"), "{}", reason("part-13"));

    // The records agree: 20 parts, 17 measured and 3 errors, none twice.
    let location = sheen::records::DbLocation::Sqlite(dir.path().join("records.sqlite"));
    let mut store = sheen::records::Store::open(&location).expect("open the records");
    let parts = store.parts(&sheen::records::query::HistoryFilter::default()).expect("read the records");
    let recorded: Vec<&str> = parts.iter().map(|p| p.record.part_id.as_str()).collect();
    assert_eq!(recorded, names.iter().map(String::as_str).collect::<Vec<_>>(), "each part once, in arrival order");
    let errors = parts.iter().filter(|p| p.record.verdict == sheen::records::PartVerdict::Error).count();
    assert_eq!((parts.len() - errors, errors), (17, 3));
}

/// A recipe or records database that cannot be opened stops the watch at
/// once with one line naming it, exit 1, before any part is touched.
#[test]
fn watch_stops_at_once_on_a_bad_recipe_or_database() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path().join("inbox");
    std::fs::create_dir_all(&inbox).expect("inbox");
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let missing = p(&dir.path().join("no-such.sheen-recipe.json"));
    let o = sheen(&["watch", &p(&inbox), "--recipe", &missing, "--once"]);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("no-such.sheen-recipe.json"), "{err}");

    let recipe = make_recipe(dir.path(), LINE_SIZE);
    let o = sheen(&["watch", &p(&inbox), "--recipe", &p(&recipe), "--db", "mysql://x@y/z", "--once"]);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("mysql"), "{err}");
}

/// A rig that drops folders of images without a manifest: the recipe keeps
/// `sheen import`'s options and the calibration; the watch waits until the
/// images have settled, writes the manifest with the calibration beside it
/// and inspects the part; a restart does not inspect it again.
#[test]
fn watch_imports_folders_of_images_with_the_recipes_pattern() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let calibration = p(&d.join("reference/calibration.json"));
    let options = ["--import-option=--pattern", "--import-option={camera}/p{period}_{shift:02}.png", "--calibration"];
    let recipe = make_recipe_with(d, LINE_SIZE, &[options[0], options[1], options[2], &calibration]);
    // Images only: no manifest, no calibration.
    let inbox = d.join("inbox");
    let part = inbox.join("part-01");
    simulate(&part, "step-gauge", 7, "1,-0.5,2", LINE_SIZE);
    for f in ["fringe-set.json", "calibration.json"] {
        std::fs::remove_file(part.join(f)).expect("remove");
    }
    std::fs::remove_dir_all(part.join("truth")).expect("remove the truth");

    let db = p(&d.join("records.sqlite"));
    let out = p(&d.join("results"));
    let v = first_part_then_stop(start_watch(&watch_args(&p(&inbox), &p(&recipe), &db, &out)));
    assert_eq!((v["part"].as_str(), v["verdict"].as_str()), (Some("part-01"), Some("pass")), "{v}");
    assert!(part.join("fringe-set.json").is_file() && part.join("calibration.json").is_file());

    let (inbox_s, recipe_s) = (p(&inbox), p(&recipe));
    let mut args = watch_args(&inbox_s, &recipe_s, &db, &out);
    args.push("--once");
    let o = sheen(&args);
    assert!(text(&o.stdout).contains("\"skipped\""), "{}", text(&o.stdout));
}

/// A recipe with a sentinel: a part is taken only once its sentinel file
/// arrives, however long its images have sat still; with --archive the part's
/// folder moves out of the inbox once recorded.
#[test]
fn watch_waits_for_the_sentinel_and_archives_the_part() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let recipe = make_recipe_with(d, LINE_SIZE, &["--sentinel", "done.txt"]);
    let inbox = d.join("inbox");
    let part = inbox.join("part-01");
    simulate(&part, "step-gauge", 3, "0.5,0.5,1", LINE_SIZE);
    let (inbox_s, recipe_s, db, out, archive) =
        (p(&inbox), p(&recipe), p(&d.join("records.sqlite")), p(&d.join("results")), p(&d.join("archive")));
    let mut args = watch_args(&inbox_s, &recipe_s, &db, &out);
    args.extend(["--archive", &archive]);
    let child = start_watch(&args);
    // Settled many times over, but no sentinel: nothing is taken.
    std::thread::sleep(std::time::Duration::from_millis(800));
    assert!(part.is_dir() && !d.join("results/part-01").exists(), "taken before its sentinel");
    std::fs::write(part.join("done.txt"), "").expect("sentinel");
    let v = first_part_then_stop(child);
    assert_eq!((v["part"].as_str(), v["verdict"].as_str()), (Some("part-01"), Some("pass")), "{v}");
    assert!(!part.exists(), "the part left the inbox");
    assert!(d.join("archive/part-01/fringe-set.json").is_file(), "and is in the archive");
}

/// A part whose manifest arrives before its images is not taken while they
/// are missing (the manifest is parsed once and its files looked at every
/// poll), and is taken, whole, once they are there.
#[test]
fn watch_takes_a_part_whose_images_arrive_after_its_manifest_once_they_are_all_there() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let recipe = make_recipe_with(d, LINE_SIZE, &[]);
    let staged = d.join("staged");
    simulate(&staged, "step-gauge", 4, "0.3,-0.2,2", LINE_SIZE);
    let part = d.join("inbox/part-01");
    std::fs::create_dir_all(&part).expect("inbox");
    for file in ["fringe-set.json", "calibration.json"] {
        std::fs::copy(staged.join(file), part.join(file)).expect("copy the manifest");
    }
    let (inbox_s, recipe_s, db, out) =
        (p(&d.join("inbox")), p(&recipe), p(&d.join("records.sqlite")), p(&d.join("results")));
    let child = start_watch(&watch_args(&inbox_s, &recipe_s, &db, &out));
    std::thread::sleep(std::time::Duration::from_millis(800));
    assert!(!d.join("results/part-01").exists(), "taken with its images missing");
    for camera in ["left", "right"] {
        std::fs::rename(staged.join(camera), part.join(camera)).expect("the images arrive");
    }
    let v = first_part_then_stop(child);
    assert_eq!((v["part"].as_str(), v["verdict"].as_str()), (Some("part-01"), Some("pass")), "{v}");
}

/// A recipe's part-ID pattern takes the ID from the folder's name (the
/// first group of the regular expression): the watch prints and records
/// that ID and writes the results under the folder's own name, which its
/// JSON line gives for the Line view. A pattern that does not compile is
/// refused before the reference is measured, naming the option.
#[test]
fn a_recipes_part_id_pattern_names_the_part_from_its_folder() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let o = sheen(&[
        "recipe",
        "no-such/fringe-set.json",
        "--spec",
        "no-such/spec.json",
        "--out",
        &p(&d.join("x.sheen-recipe.json")),
        "--part-id-pattern",
        "SN(",
    ]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--part-id-pattern") && err.contains("SN("), "{err}");

    let recipe = make_recipe_with(d, LINE_SIZE, &["--part-id-pattern", r"SN(\d+)"]);
    let folder = "20261205-1200_SN4711";
    simulate(&d.join("inbox").join(folder), "step-gauge", 5, "0.2,0.1,1", LINE_SIZE);
    let (inbox_s, recipe_s, db, out) =
        (p(&d.join("inbox")), p(&recipe), p(&d.join("records.sqlite")), p(&d.join("results")));
    let mut args = watch_args(&inbox_s, &recipe_s, &db, &out);
    args.push("--once");
    let o = sheen(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let line = text(&o.stdout).lines().next().map(str::to_string).expect("a part");
    let v: serde_json::Value = serde_json::from_str(&line).expect("json");
    assert_eq!(
        (v["part"].as_str(), v["folder"].as_str(), v["verdict"].as_str()),
        (Some("4711"), Some(folder), Some("pass")),
        "{v}"
    );
    assert!(d.join("results").join(folder).join("measurements.json").is_file(), "results under the folder's name");
    let o = sheen(&["history", "--db", &db]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let listed = text(&o.stdout);
    assert!(listed.contains("4711") && !listed.contains(folder), "recorded as 4711: {listed}");
}

/// A folder dropped again under a name already taken and archived is a new
/// part: measured when its content is new, skipped with a line saying so
/// when the same content is on record (the watch used to remember every
/// folder name it took and never look at such a folder). The watch is
/// stopped as the Line view stops it, by closing its standard input.
#[test]
fn a_folder_name_seen_again_after_archiving_is_a_new_part() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let recipe = make_recipe(d, LINE_SIZE);
    let inbox = d.join("inbox");
    std::fs::create_dir_all(&inbox).expect("inbox");
    for (seed, place) in [(21, "0.2,0.1,1"), (22, "-0.3,0.2,-2")] {
        simulate(&d.join(format!("staged-{seed}")), "step-gauge", seed, place, LINE_SIZE);
    }
    let (inbox_s, recipe_s, db, out, archive) =
        (p(&inbox), p(&recipe), p(&d.join("records.sqlite")), p(&d.join("results")), p(&d.join("archive")));
    let mut args = watch_args(&inbox_s, &recipe_s, &db, &out);
    args.extend(["--archive", &archive, "--stop-on-stdin-close"]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(&args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the watch");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    // Each line read as JSON and through the type the app's Line view reads.
    let mut next_line = || -> serde_json::Value {
        let text = lines.next().expect("a line per part").expect("read");
        let typed = sheen::io::watch_line::WatchLine::from_json(&text).expect("the Line view's type reads it");
        assert_eq!(typed.folder, "part-01", "{text}");
        serde_json::from_str(&text).expect("json")
    };
    let part = inbox.join("part-01");
    let wait_archived = |n: usize| {
        for _ in 0..500 {
            if std::fs::read_dir(d.join("archive")).map(|e| e.count()).unwrap_or(0) == n && !part.exists() {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        panic!("part-01 was not archived");
    };
    // The first part, then a different part under the same name.
    sheen_copy_dir(&d.join("staged-21"), &d.join("drop"));
    std::fs::rename(d.join("drop"), &part).expect("drop part-01");
    let v = next_line();
    assert_eq!((v["folder"].as_str(), v["verdict"].as_str()), (Some("part-01"), Some("pass")), "{v}");
    wait_archived(1);
    sheen_copy_dir(&d.join("staged-22"), &d.join("drop"));
    std::fs::rename(d.join("drop"), &part).expect("drop part-01 again");
    let v = next_line();
    assert_eq!((v["folder"].as_str(), v["verdict"].as_str()), (Some("part-01"), Some("pass")), "measured: {v}");
    wait_archived(2);
    // The first part's content once more: on record, so skipped, and said so.
    sheen_copy_dir(&d.join("staged-21"), &d.join("drop"));
    std::fs::rename(d.join("drop"), &part).expect("drop part-01 a third time");
    let v = next_line();
    assert_eq!((v["folder"].as_str(), v["skipped"].as_str()), (Some("part-01"), Some("already recorded")), "{v}");
    drop(child.stdin.take());
    let status = child.wait().expect("wait");
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().expect("stderr"), &mut err).expect("stderr");
    assert!(status.success(), "the watch stops cleanly when its input closes: {err}");
    assert_eq!(err.matches("arrived again").count(), 2, "each reuse of the name is logged: {err}");
    assert!(err.contains("3 parts inspected") || err.contains("skipped as already recorded"), "{err}");
}

/// A recipe's import options are checked when the recipe is made and when
/// the watch starts: a bad one is one clear line and exit 1 there, not an
/// error on every part.
#[test]
fn a_bad_import_option_is_refused_when_the_recipe_is_made_and_when_the_watch_starts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    simulate(&d.join("reference"), "step-gauge", 1, "0,0,0", LINE_SIZE);
    let spec = d.join("spec.json");
    std::fs::write(&spec, SPEC).expect("spec");
    let recipe = d.join("bad.sheen-recipe.json");
    let (reference, spec_s, recipe_s) = (p(&d.join("reference/fringe-set.json")), p(&spec), p(&recipe));
    let o = sheen(&[
        "recipe",
        &reference,
        "--spec",
        &spec_s,
        "--out",
        &recipe_s,
        "-q",
        "--import-option=--periods",
        "--import-option=912,abc",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--import-option") && err.contains("abc"), "{err}");
    assert!(!recipe.exists(), "no recipe is written");

    // A recipe edited by hand after it was made: the watch refuses it at start.
    let good = make_recipe(d, LINE_SIZE);
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&good).expect("recipe")).expect("recipe json");
    json.as_object_mut().expect("object").insert("import".into(), serde_json::json!(["--shifts", "12,x"]));
    std::fs::write(&recipe, serde_json::to_string_pretty(&json).expect("json")).expect("write");
    let inbox = d.join("inbox");
    std::fs::create_dir_all(&inbox).expect("inbox");
    let o = sheen(&["watch", &p(&inbox), "--recipe", &recipe_s, "--db", &p(&d.join("r.sqlite")), "--once"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("import options") && err.contains("12,x") || err.contains("'x'"), "{err}");
}

#[test]
fn the_watch_writes_each_parts_exchange_files_and_a_part_in_error_as_invalid_values() {
    let dir = tempfile::tempdir().expect("tempdir");
    let recipe =
        make_recipe_with(dir.path(), LINE_SIZE, &["--description", "Gauge block, 2 steps", "--operation", "OP 40"]);
    let inbox = dir.path().join("inbox");
    simulate(&inbox.join("part-01"), "step-gauge", 21, "0.1,0.1,0", LINE_SIZE);
    let broken = inbox.join("part-02");
    simulate(&broken, "step-gauge", 22, "-0.1,0.0,1", LINE_SIZE);
    let image = broken.join("right/p0024_05.png");
    let bytes = std::fs::read(&image).expect("read");
    std::fs::write(&image, &bytes[..bytes.len() / 3]).expect("truncate");
    let (dfq_dir, qif_dir) = (dir.path().join("spc/dfq"), dir.path().join("spc/qif"));
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let o = watch_once_with(&inbox, &recipe, dir.path(), &["--dfq-dir", &p(&dfq_dir), "--qif-dir", &p(&qif_dir)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let files = |d: &Path, ext: &str| -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(d)
            .expect("exchange folder")
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == ext))
            .collect();
        v.sort();
        v
    };
    let (dfqs, qifs) = (files(&dfq_dir, "dfq"), files(&qif_dir, "qif"));
    assert_eq!((dfqs.len(), qifs.len()), (2, 2), "one file of each per part: {dfqs:?} {qifs:?}");
    assert!(dfqs[0].file_name().expect("name").to_string_lossy().starts_with("part-01_"));
    let good = String::from_utf8_lossy(&std::fs::read(&dfqs[0]).expect("dfq")).into_owned();
    let error = String::from_utf8_lossy(&std::fs::read(&dfqs[1]).expect("dfq")).into_owned();
    let count = |t: &str, key: &str| t.lines().filter(|l| l.starts_with(key)).count();
    assert!(count(&good, "K2001/") > 0);
    assert!(good.contains("K1002/1 Gauge block, 2 steps\r\n") && good.contains("K1086/1 OP 40\r\n"), "{good}");
    assert_eq!(count(&error, "K2001/"), count(&good, "K2001/"), "the part in error has its recipe's characteristics");
    assert!(error.lines().filter(|l| l.starts_with("K0002/")).all(|l| l.ends_with(" 255")), "{error}");
    let qif = std::fs::read_to_string(&qifs[1]).expect("qif");
    assert!(qif.contains("<InspectionStatusEnum>SYSERROR</InspectionStatusEnum>"));
    for q in &qifs {
        if let Ok(o) = Command::new("xmllint")
            .args(["--noout", "--nonet", "--schema"])
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/qif-3.0/QIFApplications/QIFDocument.xsd"))
            .arg(q)
            .output()
        {
            assert!(o.status.success(), "{}: {}", q.display(), text(&o.stderr));
        }
    }
    // The records note the files.
    let db = sheen::records::DbLocation::Sqlite(dir.path().join("r.sqlite"));
    let parts = sheen::records::Store::open(&db).expect("open").parts(&Default::default()).expect("read");
    assert!(
        parts.iter().all(|p| p.record.exports.len() == 2),
        "{:?}",
        parts.iter().map(|p| &p.record.exports).collect::<Vec<_>>()
    );
}

/// A spec's decision rule travels into the recipe made from it and decides
/// every part measured with that recipe; `--decision-rule` still overrides
/// it for one run.
#[test]
fn a_recipes_decision_rule_decides_its_parts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    simulate(&d.join("reference"), "step-gauge", 1, "0,0,0", LINE_SIZE);
    let spec = d.join("spec.json");
    let guarded = SPEC.replacen(
        "{\"sheen_inspection\": 1,",
        "{\"sheen_inspection\": 1, \"decision_rule\": \"guard-band:0.5\",",
        1,
    );
    assert_ne!(guarded, SPEC);
    std::fs::write(&spec, guarded).expect("spec");
    let recipe = d.join("gauge.sheen-recipe.json");
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let o =
        sheen(&["recipe", &p(&d.join("reference/fringe-set.json")), "--spec", &p(&spec), "--out", &p(&recipe), "-q"]);
    assert!(o.status.success(), "recipe: {}", text(&o.stderr));
    assert!(std::fs::read_to_string(&recipe).expect("recipe").contains("guard-band:0.5"), "the recipe keeps the rule");
    simulate(&d.join("part"), "step-gauge", 7, "0.3,-0.2,2", LINE_SIZE);
    let rule_of_step = |out: &Path| -> serde_json::Value {
        measurements(out).iter().find(|r| r["name"] == "step 200").expect("the toleranced step")["decision_rule"]
            .clone()
    };
    let o = analyze(&d.join("part"), &recipe, &d.join("qc"));
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(rule_of_step(&d.join("qc")), "guard-band:0.5");
    let mut args = vec!["analyze".to_string(), p(&d.join("part/fringe-set.json")), "--recipe".into(), p(&recipe)];
    args.extend(["--out".into(), p(&d.join("qc-simple")), "-q".into(), "--decision-rule".into(), "simple".into()]);
    let o = sheen(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(rule_of_step(&d.join("qc-simple")), "simple");
}
