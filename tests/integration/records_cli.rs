//! Issue 21 through the binary: `sheen analyze --record` on a small
//! simulated flat (about 30 ms a part), `sheen history` with its CSV, filters
//! and `stats`, a process killed inside its record's transaction, four
//! stations recording at once, and a PostgreSQL server that is down. Each
//! runs on SQLite and, with `SHEEN_TEST_POSTGRES_URL`, on PostgreSQL.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use super::records::{TestDb, on_each_store, record};
use sheen::records::hash::sha256_file;
use sheen::records::{HistoryFilter, PartVerdict, Store};

pub(crate) fn sheen(args: &[&str]) -> Output {
    sheen_env(args, &[])
}

fn sheen_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sheen"));
    c.args(args).env_remove("PGPASSWORD").env_remove(sheen::records::ABORT_AFTER_ROWS_ENV);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("run the sheen binary")
}

pub(crate) fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

pub(crate) fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A small simulated flat part in `dir/<part>/`, and the recipe `plate-B`
/// (a peak-to-valley and an RMS flatness, upper limits `pv`, `rms` um).
pub(crate) struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    pub(crate) fn new(pv: f64, rms: f64) -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let spec = serde_json::json!({
            "sheen_inspection": 1,
            "regions": [{ "name": "base", "region": { "shape": "rectangle", "x_mm": [-1, 1], "y_mm": [-1, 1] } }],
            "measurements": [
                { "name": "flatness base", "measure": { "kind": "flatness", "region": "base" },
                  "tolerance": { "lower": 0, "upper": pv } },
                { "name": "rms base", "measure": { "kind": "flatness", "region": "base", "statistic": "rms" },
                  "tolerance": { "lower": 0, "upper": rms } }
            ]
        });
        std::fs::write(dir.path().join("plate-B.json"), spec.to_string()).expect("spec");
        Self { dir }
    }

    pub(crate) fn path(&self) -> &Path {
        self.dir.path()
    }

    fn spec(&self) -> PathBuf {
        self.path().join("plate-B.json")
    }

    /// Simulates part `name` once; returns its manifest.
    pub(crate) fn part(&self, name: &str) -> PathBuf {
        let out = self.path().join(name);
        if !out.exists() {
            let o = sheen(&["simulate", "--scene", "flat", "--out", s(&out), "--width", "64", "--height", "48", "-q"]);
            assert!(o.status.success(), "simulate: {}", stderr(&o));
        }
        out.join("fringe-set.json")
    }

    /// `sheen analyze MANIFEST --spec plate-B.json --out OUT -q --record --db DB` plus `extra`.
    pub(crate) fn record(&self, db: &TestDb, part: &str, extra: &[&str], env: &[(&str, &str)]) -> Output {
        let manifest = self.part(part);
        let out = self.path().join(format!("qc-{part}"));
        let spec = self.spec();
        let dbarg = db.arg();
        let mut args = vec!["analyze", s(&manifest), "--spec", s(&spec), "--out", s(&out), "-q", "--record"];
        args.extend(["--db", &dbarg]);
        args.extend(extra);
        sheen_env(&args, env)
    }
}

pub(crate) fn history(db: &TestDb, extra: &[&str]) -> Output {
    let dbarg = db.arg();
    let mut args = vec!["history", "--db", &dbarg];
    args.extend(extra);
    sheen(&args)
}

pub(crate) fn stored(db: &TestDb) -> Vec<sheen::records::StoredPart> {
    Store::open(&db.location()).expect("open").parts(&HistoryFilter::default()).expect("read")
}

#[test]
fn analyze_record_keeps_the_part_with_hashes_and_its_height_map() {
    let fx = Fixture::new(15.0, 5.0);
    on_each_store("analyze_record_keeps_the_part_with_hashes_and_its_height_map", |db| {
        let maps = fx.path().join(format!("maps-{}", db.kind()));
        let o =
            fx.record(db, "part-0042", &["--station", "line 2", "--operator", "ana", "--records-dir", s(&maps)], &[]);
        assert_eq!(o.status.code(), Some(0), "{}: {}", db.kind(), stderr(&o));
        let parts = stored(db);
        assert_eq!(parts.len(), 1);
        let r = &parts[0].record;
        assert_eq!((r.part_id.as_str(), r.recipe.as_str()), ("part-0042", "plate-B"), "folder name and spec stem");
        assert_eq!((r.station.as_deref(), r.operator.as_deref()), (Some("line 2"), Some("ana")));
        assert_eq!((r.verdict, r.sheen_version.as_str()), (PartVerdict::Pass, env!("CARGO_PKG_VERSION")));
        assert!(r.engine_parameters.as_deref().is_some_and(|p| p.contains("\"method\"")), "{:?}", r.engine_parameters);
        let names: Vec<&str> = r.measurements.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["flatness base", "rms base"]);
        // A `<=` flatness has an upper limit only.
        assert_eq!((r.measurements[0].lower_limit, r.measurements[0].upper_limit), (None, Some(15.0)));
        // The input hash is the sha256sum listing of the manifest and every
        // file it names, hashed.
        let folder = fx.path().join("part-0042");
        let manifest = sheen::io::manifest::read_manifest(&folder.join("fringe-set.json")).expect("manifest");
        let mut listing = String::new();
        for p in manifest.input_paths(&folder.join("fringe-set.json")) {
            let name = p.strip_prefix(&folder).expect("inside the folder").display().to_string();
            listing.push_str(&format!("{}  {name}\n", sha256_file(&p).expect("hash")));
        }
        assert!(listing.lines().count() > 10, "manifest, calibration and images: {listing}");
        assert_eq!(r.input_hash.as_deref(), Some(sheen::records::hash::sha256_bytes(listing.as_bytes()).as_str()));
        // The height map is an X3P with the stored hash.
        let x3p = PathBuf::from(r.height_map_path.as_deref().expect("height map path"));
        assert!(x3p.starts_with(&maps) || x3p.starts_with(maps.canonicalize().expect("maps")), "{}", x3p.display());
        assert_eq!(r.height_map_hash.as_deref(), Some(sha256_file(&x3p).expect("x3p").as_str()));
        let file = sheen::io::x3p::read_x3p(std::fs::File::open(&x3p).expect("open x3p")).expect("X3P");
        assert!(file.map.valid_count() > 0);
        // It is the part's own height_map.x3p, kept as written rather than
        // encoded a second time.
        let written = fx.path().join("qc-part-0042").join("height_map.x3p");
        assert_eq!(std::fs::read(&x3p).expect("kept"), std::fs::read(&written).expect("written"), "{}", db.kind());
        // On one file system it is that file under a second name, not a copy;
        // measuring the part again into the same folder replaces the results'
        // file with a new one and leaves the record's as it was hashed.
        #[cfg(unix)]
        let inode = |p: &Path| std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(p).expect("metadata"));
        #[cfg(unix)]
        assert_eq!(inode(&x3p), inode(&written), "{}: one file, two names", db.kind());
        let o = fx.record(db, "part-0042", &["--records-dir", s(&maps)], &[]);
        assert_eq!(o.status.code(), Some(0), "{}: {}", db.kind(), stderr(&o));
        #[cfg(unix)]
        assert_ne!(inode(&x3p), inode(&written), "{}: the results' file was replaced, not rewritten", db.kind());
        assert_eq!(r.height_map_hash.as_deref(), Some(sha256_file(&x3p).expect("x3p").as_str()), "{}", db.kind());
        let again = &stored(db)[1].record;
        assert_ne!(again.height_map_path, r.height_map_path, "{}: each record its own name", db.kind());
        // The same part with a stricter spec: a record; a failing tolerance exits 2.
        let strict = Fixture::new(0.0001, 5.0);
        let manifest = fx.part("part-0042");
        let out = fx.path().join("qc-strict");
        let o = sheen(&[
            "analyze",
            s(&manifest),
            "--spec",
            s(&strict.spec()),
            "--out",
            s(&out),
            "-q",
            "--record",
            "--db",
            &db.arg(),
            "--records-dir",
            s(&maps),
        ]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        let parts = stored(db);
        assert_eq!(parts.len(), 3);
        assert_eq!(parts[2].record.part_id, "part-0042");
        assert_eq!(parts[2].record.verdict, PartVerdict::Fail);
        assert!(parts[2].record.reason.as_deref().is_some_and(|r| r.contains("flatness base")));
    });
}

#[test]
fn sqlite_height_maps_go_beside_the_database_by_relative_path() {
    let fx = Fixture::new(15.0, 5.0);
    let db = TestDb::sqlite();
    let o = fx.record(&db, "p1", &["--part", "x'); DROP TABLE parts;--"], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r = &stored(&db)[0].record;
    assert_eq!(r.part_id, "x'); DROP TABLE parts;--", "stored verbatim");
    let rel = r.height_map_path.as_deref().expect("path");
    assert!(rel.starts_with("records/") && rel.ends_with(".x3p"), "{rel}");
    let TestDb::Sqlite { path, .. } = &db else { unreachable!() };
    let x3p = path.parent().expect("folder").join(rel);
    assert_eq!(r.height_map_hash.as_deref(), Some(sha256_file(&x3p).expect("x3p").as_str()));
    let list = history(&db, &[]);
    assert!(stdout(&list).contains("x'); DROP TABLE parts;--"), "{}", stdout(&list));
}

#[test]
fn an_input_that_cannot_be_measured_is_recorded_as_an_error() {
    let fx = Fixture::new(15.0, 5.0);
    on_each_store("an_input_that_cannot_be_measured_is_recorded_as_an_error", |db| {
        assert!(fx.record(db, "good", &[], &[]).status.success());
        let manifest = fx.part(&format!("broken-{}", db.kind()));
        let folder = manifest.parent().expect("folder");
        let image = std::fs::read_dir(folder.join("left")).expect("images").flatten().next().expect("an image").path();
        std::fs::remove_file(&image).expect("remove an image");
        let o = fx.record(db, &format!("broken-{}", db.kind()), &[], &[]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        let parts = stored(db);
        assert_eq!(parts.len(), 2);
        let r = &parts[1].record;
        assert_eq!(r.verdict, PartVerdict::Error);
        assert!(r.measurements.is_empty() && r.height_map_path.is_none() && r.input_hash.is_none());
        let reason = r.reason.clone().expect("reason");
        assert!(reason.contains(&image.file_name().expect("name").to_string_lossy().into_owned()), "{reason}");
        // In the CSV: one row, measurement columns empty, the reason as its verdict.
        let csv = fx.path().join(format!("history-{}.csv", db.kind()));
        let o = history(db, &["--csv", s(&csv)]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = std::fs::read_to_string(&csv).expect("csv");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], sheen::cli::HISTORY_COLUMNS);
        assert_eq!(lines.len(), 1 + 2 + 1, "two rows for the good part, one for the error: {text}");
        let error_row = lines[3];
        assert!(error_row.starts_with(&format!("broken-{},", db.kind())), "{error_row}");
        assert!(error_row.contains(",plate-B,error,,,,"), "{error_row}");
        assert!(error_row.contains("left"), "the reason names the image: {error_row}");
        let good = lines[1];
        assert!(
            good.starts_with("good,") && good.contains(",plate-B,pass,flatness base,") && good.ends_with(",um,pass")
        );
    });
}

#[test]
fn a_record_not_kept_exits_1_even_when_a_tolerance_failed_and_files_stay() {
    let fx = Fixture::new(0.0001, 5.0);
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("blocker"), "a file where the database folder should be").expect("write");
    let db = dir.path().join("blocker").join("records.sqlite");
    let manifest = fx.part("p1");
    let out = fx.path().join("qc");
    let o =
        sheen(&["analyze", s(&manifest), "--spec", s(&fx.spec()), "--out", s(&out), "-q", "--record", "--db", s(&db)]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.starts_with("record not kept: ") && err.contains("blocker"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(out.join("measurements.json").exists() && out.join("height_map.x3p").exists());

    // A store from a newer Sheen: refused the same way, nothing written to it.
    let newer = TestDb::sqlite();
    assert!(fx.record(&newer, "p1", &[], &[]).status.code() == Some(2));
    newer.execute("UPDATE sheen_records_schema SET version = 7");
    let o = fx.record(&newer, "p1", &[], &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("record not kept: ") && stderr(&o).contains("schema version 7"), "{}", stderr(&o));
    assert_eq!(newer.count("SELECT count(*) FROM parts"), 1);
    let TestDb::Sqlite { path, .. } = &newer else { unreachable!() };
    let maps: Vec<_> = std::fs::read_dir(path.parent().expect("folder").join("records")).expect("records").collect();
    assert_eq!(maps.len(), 1, "the map of a record not kept is removed again");

    // Record options need --record.
    let o = sheen(&["analyze", s(&manifest), "--out", s(&out), "--db", s(&db)]);
    assert_eq!(o.status.code(), Some(1));
    // Inline options alone give no recipe name.
    let o = sheen(&["analyze", s(&manifest), "--out", s(&out), "-q", "--record", "--db", s(&db)]);
    assert!(o.status.code() == Some(1) && stderr(&o).contains("--recipe"), "{}", stderr(&o));
}

#[test]
fn a_process_killed_inside_its_transaction_leaves_no_half_record() {
    let fx = Fixture::new(15.0, 5.0);
    on_each_store("a_process_killed_inside_its_transaction_leaves_no_half_record", |db| {
        for p in ["a", "b"] {
            assert!(fx.record(db, p, &[], &[]).status.success());
        }
        let o = fx.record(db, "c", &[], &[(sheen::records::ABORT_AFTER_ROWS_ENV, "1")]);
        assert!(!o.status.success(), "the hook must kill the process");
        assert!(stderr(&o).contains("aborting inside the record's transaction"), "{}", stderr(&o));
        assert_eq!(db.count("SELECT count(*) FROM parts"), 2, "{}: no half part", db.kind());
        assert_eq!(db.count("SELECT count(*) FROM measurements"), 4, "{}: no orphan row", db.kind());
        let parts = stored(db);
        assert!(parts.iter().all(|p| p.record.measurements.len() == 2));
        // The store is not left locked: the next part records.
        assert!(fx.record(db, "c", &[], &[]).status.success());
        assert_eq!(db.count("SELECT count(*) FROM parts"), 3);
    });
}

#[test]
fn a_connection_lost_inside_the_transaction_keeps_no_half_record_and_says_so() {
    let Some(db) = TestDb::postgres("a_connection_lost_inside_the_transaction") else { return };
    let fx = Fixture::new(15.0, 5.0);
    let maps = fx.path().join("maps");
    let in_maps = || std::fs::read_dir(&maps).map_or(0, |d| d.count());
    for p in ["a", "b"] {
        assert!(fx.record(&db, p, &["--records-dir", s(&maps)], &[]).status.success());
    }
    assert_eq!(in_maps(), 2);
    let env = [(sheen::records::DROP_CONNECTION_AFTER_ROWS_ENV, "1")];
    let o = fx.record(&db, "c", &["--records-dir", s(&maps)], &env);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.starts_with("record not kept: ") && err.lines().count() == 1, "{err}");
    assert_eq!(db.count("SELECT count(*) FROM parts"), 2, "no half part");
    assert_eq!(db.count("SELECT count(*) FROM measurements"), 4, "no orphan row");
    assert_eq!(in_maps(), 2, "the height map of a record not kept is removed");
    assert!(fx.path().join("qc-c").join("measurements.json").exists(), "the results stay on disk");
    assert!(fx.record(&db, "c", &["--records-dir", s(&maps)], &[]).status.success());
    assert_eq!(db.count("SELECT count(*) FROM parts"), 3);
}

/// A disk that refuses to grow any file past 4 KiB (the process's file size
/// limit, with SIGXFSZ ignored so a write fails as on a full disk instead of
/// killing the process): the record is not kept, the command says so and
/// exits 1, the parts before it stay whole, and nothing half-written remains.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn a_disk_that_refuses_writes_keeps_no_record_and_says_so() {
    use std::os::unix::process::CommandExt as _;
    let fx = Fixture::new(15.0, 5.0);
    let db = TestDb::sqlite();
    for p in ["a", "b"] {
        assert!(fx.record(&db, p, &[], &[]).status.success());
    }
    let maps = db.location().height_map_dir(None).expect("records folder");
    let kept_maps = std::fs::read_dir(&maps).expect("records folder").count();
    let broken = fx.part("broken");
    let image = std::fs::read_dir(broken.parent().expect("folder").join("left"))
        .expect("images")
        .flatten()
        .next()
        .expect("an image")
        .path();
    std::fs::remove_file(&image).expect("remove an image");
    // A part that cannot be measured: no height map and small result files,
    // so the database's own write is the one that meets the full disk.
    let part = "broken";
    let manifest = fx.part(part);
    let out = fx.path().join(format!("qc-full-{part}"));
    std::fs::create_dir_all(&out).expect("out");
    let (spec, dbarg) = (fx.spec(), db.arg());
    let mut c = Command::new(env!("CARGO_BIN_EXE_sheen"));
    c.args(["analyze", s(&manifest), "--spec", s(&spec), "--out", s(&out), "-q", "--record", "--db", &dbarg]);
    c.env_remove(sheen::records::ABORT_AFTER_ROWS_ENV);
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        c.pre_exec(|| {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit { rlim_cur: 4096, rlim_max: 4096 };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let o = c.output().expect("run sheen");
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{part}: {err}");
    assert!(err.contains("record not kept: "), "{part}: {err}");
    assert_eq!(db.count("SELECT count(*) FROM parts"), 2, "{part}: the parts before it stay, no half part");
    assert_eq!(db.count("SELECT count(*) FROM measurements"), 4, "{part}: no orphan row");
    assert_eq!(std::fs::read_dir(&maps).expect("records folder").count(), kept_maps, "{part}: no stray map");
    // With room again the store takes the next part.
    assert!(fx.record(&db, "c", &[], &[]).status.success());
    assert_eq!(db.count("SELECT count(*) FROM parts"), 3);
}

#[test]
fn four_stations_recording_at_once_lose_and_double_nothing() {
    let fx = Fixture::new(15.0, 5.0);
    fx.part("shared");
    on_each_store("four_stations_recording_at_once_lose_and_double_nothing", |db| {
        let started = std::time::Instant::now();
        std::thread::scope(|scope| {
            for station in 0..4 {
                let fx = &fx;
                scope.spawn(move || {
                    for n in 0..50 {
                        let part = format!("s{station}-{n:02}");
                        let st = format!("station {station}");
                        let o = fx.record(db, "shared", &["--part", &part, "--station", &st], &[]);
                        assert!(o.status.success(), "{part}: {}", stderr(&o));
                    }
                });
            }
        });
        eprintln!("{}: 200 records from 4 stations in {:.1} s", db.kind(), started.elapsed().as_secs_f64());
        let parts = stored(db);
        assert_eq!(parts.len(), 200, "{}", db.kind());
        let mut ids: Vec<&str> = parts.iter().map(|p| p.record.part_id.as_str()).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), 200, "{}: every part exactly once", db.kind());
        assert_eq!(db.count("SELECT count(*) FROM measurements"), 400);
        let maps: std::collections::HashSet<_> = parts.iter().map(|p| p.record.height_map_path.clone()).collect();
        assert_eq!(maps.len(), 200, "one height map file per record");
    });
}

#[test]
fn history_filters_by_local_dates_offsets_station_and_measurement() {
    on_each_store("history_filters_by_local_dates_offsets_station_and_measurement", |db| {
        let mut store = Store::open(&db.location()).expect("open");
        for (i, t) in ["2026-03-01T09:30:00.000000Z", "2026-03-01T10:30:00.000000Z", "2026-03-02T10:00:00.000000Z"]
            .iter()
            .enumerate()
        {
            let mut r = record(&format!("p{i}"), "R", t, &[Some(1.0 + i as f64), Some(0.5)]);
            r.station = Some(if i == 2 { "s2" } else { "s1" }.into());
            store.insert(&r).expect("insert");
        }
        drop(store);
        let scratch = tempfile::tempdir().expect("temp dir");
        let csv = scratch.path().join("history.csv");
        let csv_rows = |extra: &[&str], tz: &str| -> Vec<String> {
            let dbarg = db.arg();
            let mut args = vec!["history", "--db", &dbarg, "--csv", s(&csv)];
            args.extend(extra);
            let o = sheen_env(&args, &[("TZ", tz)]);
            assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
            let text = std::fs::read_to_string(&csv).expect("csv");
            text.lines().skip(1).map(str::to_string).collect()
        };
        let parts_listed = |extra: &[&str], tz: &str| -> Vec<String> {
            let mut ids: Vec<String> =
                csv_rows(extra, tz).iter().map(|l| l.split(',').next().unwrap_or("").to_string()).collect();
            ids.dedup();
            ids
        };
        // 12:00 local in UTC+2 (POSIX "UTC-2") is 10:00Z.
        assert_eq!(parts_listed(&["--since", "2026-03-01T12:00"], "UTC-2"), ["p1", "p2"]);
        assert_eq!(parts_listed(&["--since", "2026-03-01T12:00"], "UTC0"), ["p2"]);
        // An offset wins over the local zone.
        assert_eq!(parts_listed(&["--since", "2026-03-01T12:00+02:00"], "UTC0"), ["p1", "p2"]);
        // A date as --until includes that whole local day.
        assert_eq!(parts_listed(&["--until", "2026-03-01"], "UTC0"), ["p0", "p1"]);
        assert_eq!(parts_listed(&["--station", "s2"], "UTC0"), ["p2"]);
        let o = sheen(&["history", "--db", &db.arg(), "--since", "1 March"]);
        assert!(o.status.code() == Some(1) && stderr(&o).contains("--since") && stderr(&o).contains("ISO 8601"));
        // --measurement keeps only that measurement's rows.
        let rows = csv_rows(&["--measurement", "flatness 1"], "UTC0");
        assert_eq!(rows.len(), 3, "{rows:?}");
        assert!(rows.iter().all(|l| l.contains(",flatness 1,0.5,um,pass")), "{rows:?}");
        assert_eq!(csv_rows(&[], "UTC0").len(), 6);
    });
}

#[test]
fn history_stats_gives_capability_control_limits_and_run_rules() {
    on_each_store("history_stats_gives_capability_control_limits_and_run_rules", |db| {
        let mut store = Store::open(&db.location()).expect("open");
        // 10, 12, 11, 13, 12 (hand-computed in records::spc), then a drift.
        let values = [10.0, 12.0, 11.0, 13.0, 12.0];
        for (i, v) in values.iter().enumerate() {
            let mut r = record(&format!("p{i}"), "R", &format!("2026-03-01T1{i}:00:00.000000Z"), &[Some(*v)]);
            r.measurements[0].lower_limit = Some(8.0);
            r.measurements[0].upper_limit = Some(16.0);
            if i == 3 {
                r.verdict = PartVerdict::Inconclusive;
            }
            store.insert(&r).expect("insert");
        }
        let o = sheen(&["history", "--db", &db.arg(), "stats", "--recipe", "R"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = stdout(&o);
        for want in [
            "parts: 5  pass 4  fail 0  inconclusive 1  error 0; decision rule: iso-14253-1",
            "R / flatness 0 (um), limits: 8 .. 16",
            "n 5  mean 11.6000  sigma 1.1402  min 10.0000  max 13.0000",
            "within sigma 1.3298",
            "Cp 1.0027  Cpk 0.9024",
            "centre 11.6000  UCL 15.5894  LCL 7.6106; moving range UCL 4.9005",
            "run rules: none broken",
        ] {
            assert!(text.contains(want), "missing '{want}' in:\n{text}");
        }
        // Later parts far off: beyond 3 sigma against the first parts' limits.
        for (i, v) in [30.0, 31.0].iter().enumerate() {
            let r = record(&format!("q{i}"), "R", &format!("2026-03-02T1{i}:00:00.000000Z"), &[Some(*v)]);
            store.insert(&r).expect("insert");
        }
        // An upper-only limit now (the latest record's): CPU, no Cp.
        let o = sheen(&["history", "stats", "--db", &db.arg()]);
        let text = stdout(&o);
        assert!(text.contains("note: the limits changed") && text.contains("limits: upper 15 only"), "{text}");
        assert!(text.contains("CPU ") && !text.contains("Cp "), "{text}");
        assert!(text.contains("q0  30.0000  beyond 3 sigma") && text.contains("q1  31.0000  beyond 3 sigma"), "{text}");
    });
}

#[test]
fn a_postgres_server_that_is_down_gives_one_line_without_the_password() {
    let url = "postgres://sheen:hunter2secret@127.0.0.1:1/qc";
    let o = sheen(&["history", "--db", url]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("postgres://sheen@127.0.0.1:1/qc") && !err.contains("hunter2"), "{err}");
    let fx = Fixture::new(15.0, 5.0);
    let manifest = fx.part("p1");
    let out = fx.path().join("qc");
    let maps = fx.path().join("maps");
    let spec = fx.spec();
    let args = [
        "analyze",
        s(&manifest),
        "--spec",
        s(&spec),
        "--out",
        s(&out),
        "-q",
        "--record",
        "--db",
        url,
        "--records-dir",
        s(&maps),
    ];
    let o = sheen(&args);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.starts_with("record not kept: ") && err.lines().count() == 1, "{err}");
    assert!(err.contains("postgres://sheen@127.0.0.1:1/qc") && !err.contains("hunter2"), "{err}");
    assert!(out.join("measurements.json").exists());

    // Passwords the client still reads whole although they are not
    // percent-encoded: a '/', a '?' or an '@' in them.
    for url in [
        "postgres://sheen:hunter/2secret@127.0.0.1:1/qc",
        "postgres://sheen:hunter?2secret@127.0.0.1:1/qc",
        "postgres://sheen:hunter@2secret@127.0.0.1:1/qc",
    ] {
        let o = sheen(&["history", "--db", url]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{url}: {err}");
        assert!(!err.contains("hunter") && !err.contains("2secret"), "{url} leaked: {err}");
        assert!(err.contains("postgres://sheen@"), "{url}: {err}");
    }
}

#[test]
fn a_mistyped_or_foreign_database_url_is_refused_and_makes_no_stray_file() {
    let fx = Fixture::new(15.0, 5.0);
    let manifest = fx.part("p1");
    let spec = fx.spec();
    let work = tempfile::tempdir().expect("temp dir");
    for url in ["mysql://x@y/z", "postgres:/u@host/db", "postgresql:u@host/db"] {
        let out = work.path().join("qc");
        let run = |args: &[&str]| {
            Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).current_dir(work.path()).output().expect("run sheen")
        };
        let o = run(&["analyze", s(&manifest), "--spec", s(&spec), "--out", s(&out), "-q", "--record", "--db", url]);
        assert_eq!(o.status.code(), Some(1), "{url}: {}", stderr(&o));
        assert!(stderr(&o).contains("postgres://user@host/database"), "{url}: {}", stderr(&o));
        let o = run(&["history", "--db", url]);
        assert_eq!(o.status.code(), Some(1), "{url}: {}", stderr(&o));
        let left: Vec<_> = std::fs::read_dir(work.path()).expect("list").flatten().map(|e| e.file_name()).collect();
        assert!(left.iter().all(|n| n != "mysql:" && n != "postgres:" && n != "postgresql:"), "{url}: {left:?}");
    }
}

#[test]
fn postgres_password_from_pgpassword_or_pgpass() {
    let Some(db) = TestDb::postgres("postgres_password_from_pgpassword_or_pgpass") else { return };
    let url = db.arg();
    let config: postgres::Config = url.parse().expect("URL");
    let Some(password) = config.get_password().map(|p| String::from_utf8_lossy(p).into_owned()) else {
        eprintln!("skipping: the test server's URL has no password to move elsewhere");
        return;
    };
    let bare = sheen::records::location::redact_url(&url);
    // Without any password (a server that trusts loopback still lets it in).
    let o = sheen_env(&["history", "--db", &bare], &[("PGPASSFILE", "/nonexistent")]);
    assert!(!stderr(&o).contains(&password) && !stdout(&o).contains(&password));
    // PGPASSWORD.
    let o = sheen_env(&["history", "--db", &bare], &[("PGPASSWORD", &password), ("PGPASSFILE", "/nonexistent")]);
    assert!(o.status.success(), "PGPASSWORD: {}", stderr(&o));
    // A password file (PGPASSFILE, 0600).
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("pgpass");
    let host = match config.get_hosts().first() {
        Some(postgres::config::Host::Tcp(h)) => h.clone(),
        _ => "localhost".into(),
    };
    let port = config.get_ports().first().copied().unwrap_or(5432);
    let escaped = password.replace('\\', "\\\\").replace(':', "\\:");
    std::fs::write(&file, format!("# test\n{host}:{port}:*:{}:{escaped}\n", config.get_user().unwrap_or("")))
        .expect("write");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    }
    let o = sheen_env(&["history", "--db", &bare], &[("PGPASSFILE", s(&file))]);
    assert!(o.status.success(), ".pgpass: {}", stderr(&o));
}

/// Whether poppler's tools are here; CI installs them and demands the
/// report tests (`SHEEN_REQUIRE_POPPLER_TESTS=1`), a bare machine skips.
fn poppler_available() -> bool {
    let found =
        Command::new("pdftoppm").arg("-v").output().is_ok() && Command::new("pdftotext").arg("-v").output().is_ok();
    if !found {
        assert!(
            std::env::var("SHEEN_REQUIRE_POPPLER_TESTS").is_err(),
            "SHEEN_REQUIRE_POPPLER_TESTS is set but pdftoppm/pdftotext are missing (apt-get install poppler-utils)"
        );
        eprintln!("skipping: pdftoppm/pdftotext not installed (poppler-utils)");
    }
    found
}

/// The PDF as a reader sees it: its text (pdftotext, layout kept) and the
/// fraction of page 1's pixels that are not white (pdftoppm at 40 dpi).
fn read_pdf(pdf: &Path) -> (String, f64) {
    let o = Command::new("pdftotext").args(["-layout", s(pdf), "-"]).output().expect("pdftotext");
    assert!(o.status.success(), "pdftotext: {}", stderr(&o));
    let text = stdout(&o);
    let prefix = pdf.with_extension("page");
    let o = Command::new("pdftoppm").args(["-r", "40", "-png", "-f", "1", "-l", "1", s(pdf), s(&prefix)]).output();
    let o = o.expect("pdftoppm");
    assert!(o.status.success(), "pdftoppm: {}", stderr(&o));
    let folder = pdf.parent().expect("folder");
    let stem = prefix.file_name().expect("name").to_string_lossy().into_owned();
    let png = std::fs::read_dir(folder)
        .expect("folder")
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name().is_some_and(|n| n.to_string_lossy().starts_with(&stem))
                && p.extension().is_some_and(|e| e == "png")
        })
        .expect("pdftoppm wrote page 1");
    let page = image::open(&png).expect("page png").to_rgb8();
    // A4 at 40 dpi is 331 x 468 px.
    assert!(
        (page.width() as i32 - 331).abs() <= 2 && (page.height() as i32 - 468).abs() <= 2,
        "{:?}",
        page.dimensions()
    );
    let inked = page.pixels().filter(|p| p.0.iter().any(|&c| c < 200)).count();
    (text, inked as f64 / (page.width() * page.height()) as f64)
}

#[test]
fn analyze_reports_hold_the_verdict_and_every_measurement_as_a_reader_sees_them() {
    if !poppler_available() {
        return;
    }
    // The PV limit fails, the RMS one passes: a FAIL report.
    let fx = Fixture::new(0.0001, 5.0);
    let manifest = fx.part("part-7");
    let out = fx.path().join("qc-7");
    let (pdf, html) = (fx.path().join("part-7.pdf"), fx.path().join("part-7.html"));
    let o = sheen(&[
        "analyze",
        s(&manifest),
        "--spec",
        s(&fx.spec()),
        "--out",
        s(&out),
        "-q",
        "--hsection",
        "mid=0",
        "--part",
        "P-7 <b>&",
        "--station",
        "line 2",
        "--operator",
        "ana",
        "--report-pdf",
        s(&pdf),
        "--report-html",
        s(&html),
    ]);
    assert_eq!(o.status.code(), Some(2), "the PV tolerance fails: {}", stderr(&o));
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("measurements.json")).expect("json")).expect("json");
    let rows = table["measurements"].as_array().expect("rows");
    assert_eq!(rows.len(), 2);

    let (text, inked) = read_pdf(&pdf);
    assert!(inked > 0.03, "page 1 is nearly blank: {:.3} of its pixels inked", inked);
    for needle in ["FAIL", "P-7 <b>&", "plate-B", "line 2", "ana", "flatness base", "rms base", "mid"] {
        assert!(text.contains(needle), "the PDF's text lacks '{needle}':\n{text}");
    }
    // Every measured value as the table prints it (4 decimals), and the
    // input's hash, which must be the manifest-and-images hash.
    // Every value with its expanded uncertainty, and the rule the verdicts
    // were taken by, on the PDF and the page alike.
    let page = std::fs::read_to_string(&html).expect("html");
    for row in rows {
        let v = row["value"].as_f64().expect("value");
        let u = row["uncertainty"]["U"].as_f64().expect("every row states U");
        assert!(text.contains(&format!("{v:.4} ± {u:.4}")), "value {v:.4} ± {u:.4} missing:\n{text}");
        assert!(page.contains(&format!("{v:.4} ± {u:.4}")), "value {v:.4} ± {u:.4} missing from the page");
    }
    assert!(text.replace('\n', " ").contains("decision rule iso-14253-1"), "{text}");
    assert!(page.contains("Verdicts by decision rule iso-14253-1"), "the page names the rule");
    let manifest_data = sheen::io::manifest::read_manifest(&manifest).expect("manifest");
    let hash = sheen::records::hash::manifest_hash(&manifest, &manifest_data).expect("hash");
    assert!(text.replace(['\n', ' '], "").contains(&hash), "the input hash {hash} is missing:\n{text}");

    assert!(page.contains("FAIL") && page.contains("P-7 &lt;b&gt;&amp;") && !page.contains("<b>&"), "escaped part id");
    assert!(page.contains("data:image/png;base64,") && page.contains("<svg"), "map and profile inline");
    assert!(!page.contains("src=\"http") && !page.contains("<script"), "self-contained");

    // A part that cannot be measured still gets its report: ERROR and why.
    let broken = fx.part("part-8");
    let folder = broken.parent().expect("folder");
    let image = std::fs::read_dir(folder.join("left")).expect("images").flatten().next().expect("an image").path();
    std::fs::write(&image, b"not a TIFF").expect("corrupt an image");
    let pdf8 = fx.path().join("part-8.pdf");
    let o = sheen(&[
        "analyze",
        s(&broken),
        "--spec",
        s(&fx.spec()),
        "--out",
        s(&fx.path().join("qc-8")),
        "-q",
        "--report-pdf",
        s(&pdf8),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let (text, _) = read_pdf(&pdf8);
    let name = image.file_name().expect("name").to_string_lossy().into_owned();
    assert!(text.contains("ERROR") && text.contains(&name), "the error report names the image:\n{text}");
}
