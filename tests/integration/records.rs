//! Issue 21's store through the library, against SQLite and (when
//! `SHEEN_TEST_POSTGRES_URL` names a server) PostgreSQL: the schema and its
//! version check, records read back as written (a part ID that is SQL kept
//! verbatim), append-only re-measurement, the history filters. Also the
//! helpers `records_cli` shares: a throw-away database of either kind.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use sheen::analysis::measurement_table::{DecisionRule, Verdict};
use sheen::analysis::uncertainty::{Contribution, Uncertainty, UncertaintyMethod};
use sheen::records::{DbLocation, HistoryFilter, MeasurementRecord, PartRecord, PartVerdict, Store};

/// The server URL for the PostgreSQL tests.
pub const POSTGRES_URL_ENV: &str = "SHEEN_TEST_POSTGRES_URL";
/// Set to 1 (CI does) and a missing URL fails the tests instead of skipping them.
pub const REQUIRE_POSTGRES_ENV: &str = "SHEEN_REQUIRE_POSTGRES_TESTS";

/// A throw-away records database: a SQLite file in a temporary folder, or a
/// schema of its own on the test server (dropped afterwards), so tests
/// running at once never see each other's records.
pub enum TestDb {
    Sqlite { _dir: tempfile::TempDir, path: PathBuf },
    Postgres { server: String, schema: String, url: String },
}

impl TestDb {
    pub fn sqlite() -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("lab").join("records.sqlite");
        TestDb::Sqlite { _dir: dir, path }
    }

    /// A fresh schema on the test server; `None` (with a message) when no
    /// server is configured, a panic when one is required.
    pub fn postgres(test: &str) -> Option<Self> {
        let Ok(server) = std::env::var(POSTGRES_URL_ENV) else {
            if std::env::var(REQUIRE_POSTGRES_ENV).is_ok_and(|v| v == "1") {
                panic!("{test}: {REQUIRE_POSTGRES_ENV}=1 but {POSTGRES_URL_ENV} is not set");
            }
            eprintln!("skipping the PostgreSQL half of {test}: set {POSTGRES_URL_ENV}=postgres://user:pw@host:port/db");
            return None;
        };
        static N: AtomicU64 = AtomicU64::new(0);
        let schema = format!("sheen_test_{}_{}", std::process::id(), N.fetch_add(1, Ordering::Relaxed));
        let mut client = postgres::Client::connect(&server, postgres::NoTls)
            .unwrap_or_else(|e| panic!("{test}: cannot reach the test server: {e}"));
        client.batch_execute(&format!("CREATE SCHEMA {schema}")).expect("create a test schema");
        let sep = if server.contains('?') { '&' } else { '?' };
        let url = format!("{server}{sep}options=-c%20search_path%3D{schema}");
        Some(TestDb::Postgres { server, schema, url })
    }

    /// The `--db` value.
    pub fn arg(&self) -> String {
        match self {
            TestDb::Sqlite { path, .. } => path.display().to_string(),
            TestDb::Postgres { url, .. } => url.clone(),
        }
    }

    pub fn location(&self) -> DbLocation {
        DbLocation::parse(&self.arg()).expect("a test store location")
    }

    pub fn kind(&self) -> &'static str {
        match self {
            TestDb::Sqlite { .. } => "SQLite",
            TestDb::Postgres { .. } => "PostgreSQL",
        }
    }

    /// Runs SQL on the store directly, behind Sheen's back.
    pub fn execute(&self, sql: &str) {
        match self {
            TestDb::Sqlite { path, .. } => {
                rusqlite::Connection::open(path).expect("open").execute_batch(sql).expect("SQL");
            }
            TestDb::Postgres { url, .. } => {
                let mut c = postgres::Client::connect(url, postgres::NoTls).expect("connect");
                c.batch_execute(sql).expect("SQL");
            }
        }
    }

    /// A single number from SQL.
    pub fn count(&self, sql: &str) -> i64 {
        match self {
            TestDb::Sqlite { path, .. } => {
                rusqlite::Connection::open(path).expect("open").query_row(sql, [], |r| r.get(0)).expect("SQL")
            }
            TestDb::Postgres { url, .. } => {
                let mut c = postgres::Client::connect(url, postgres::NoTls).expect("connect");
                c.query_one(&format!("SELECT ({sql})::BIGINT"), &[]).expect("SQL").get(0)
            }
        }
    }
}

impl Drop for TestDb {
    fn drop(&mut self) {
        if let TestDb::Postgres { server, schema, .. } = self
            && let Ok(mut c) = postgres::Client::connect(server, postgres::NoTls)
        {
            let _ = c.batch_execute(&format!("DROP SCHEMA {schema} CASCADE"));
        }
    }
}

/// Runs `check` on a SQLite database and, when a server is configured, on
/// a PostgreSQL one.
pub fn on_each_store(test: &str, check: impl Fn(&TestDb)) {
    check(&TestDb::sqlite());
    if let Some(db) = TestDb::postgres(test) {
        check(&db);
    }
}

/// A time in the stored form.
pub fn utc(text: &str) -> chrono::DateTime<chrono::Utc> {
    sheen::records::time::parse_stored(text).expect("an RFC 3339 time")
}

pub fn record(part: &str, recipe: &str, time_utc: &str, values: &[Option<f64>]) -> PartRecord {
    PartRecord {
        part_id: part.into(),
        recipe: recipe.into(),
        time_utc: utc(time_utc),
        station: Some("line 2".into()),
        operator: None,
        input_path: "/data/lot 7/part/fringe-set.json".into(),
        input_hash: Some("ab".repeat(32)),
        sheen_version: "0.1.0".into(),
        engine_parameters: Some(r#"{"method":"hdr"}"#.into()),
        inspection: Some(r#"{"sheen_inspection":1,"regions":[]}"#.into()),
        verdict: PartVerdict::Pass,
        reason: None,
        height_map_path: None,
        height_map_hash: None,
        decision_rule: Some(DecisionRule::Iso14253),
        exports: vec!["/out/lot 7/part.dfq".into(), "/out/lot 7/part.qif".into()],
        measurements: values
            .iter()
            .enumerate()
            .map(|(i, &value)| MeasurementRecord {
                name: format!("flatness {i}"),
                kind: "flatness_peak_to_valley".into(),
                parameter: None,
                value,
                unit: "um".into(),
                nominal: None,
                lower_limit: None,
                upper_limit: Some(15.0),
                verdict: Some(if value.is_some() { Verdict::Pass } else { Verdict::Fail }),
                note: value.is_none().then(|| "no valid node".to_string()),
                // Schema 2: the statement of uncertainty reads back whole.
                uncertainty: value.map(|v| {
                    Uncertainty::from_budget(
                        UncertaintyMethod::MonteCarlo,
                        vec![
                            Contribution::new("height noise, by Monte Carlo", 0.25),
                            Contribution::new("calibration", v * 1e-4),
                        ],
                    )
                    .with_trials(50)
                    .with_noise_floor(1.5)
                }),
                decision_rule: Some(DecisionRule::Iso14253),
                acceptance_lower: None,
                acceptance_upper: value.map(|_| 14.5),
            })
            .collect(),
    }
}

#[test]
fn schema_is_created_versioned_and_a_newer_one_refused() {
    on_each_store("schema_is_created_versioned_and_a_newer_one_refused", |db| {
        let mut store = Store::open(&db.location()).unwrap_or_else(|e| panic!("{}: {e}", db.kind()));
        assert_eq!(store.schema_version().expect("version"), sheen::records::schema::SCHEMA_VERSION);
        drop(store);
        // Opening again migrates nothing and keeps one version row.
        Store::open(&db.location()).expect("reopen");
        assert_eq!(db.count("SELECT count(*) FROM sheen_records_schema"), 1);
        db.execute("UPDATE sheen_records_schema SET version = 99");
        let e = Store::open(&db.location()).err().expect("a newer schema must be refused").to_string();
        assert!(e.contains("schema version 99") && e.contains("newer than this Sheen"), "{}: {e}", db.kind());
        assert!(!e.contains('\n'));
    });
}

/// A store written by a Sheen of schema 1 (verdicts pass, fail and error
/// only, no uncertainty) opens migrated: its records read back unchanged,
/// without uncertainty or rule, and an inconclusive part can be kept.
#[test]
fn a_schema_1_store_is_migrated_and_keeps_its_records() {
    use sheen::records::schema::{Dialect, migration};
    on_each_store("a_schema_1_store_is_migrated_and_keeps_its_records", |db| {
        let dialect = if db.kind() == "SQLite" { Dialect::Sqlite } else { Dialect::Postgres };
        if let TestDb::Sqlite { path, .. } = db {
            std::fs::create_dir_all(path.parent().expect("folder")).expect("create the folder");
        }
        let mut v1 = vec!["CREATE TABLE sheen_records_schema (version INTEGER NOT NULL)".to_string()];
        v1.extend(migration(1, dialect));
        v1.push("INSERT INTO sheen_records_schema (version) VALUES (1)".into());
        v1.push(
            "INSERT INTO parts (part_id, recipe, time_utc, input_path, sheen_version, verdict, reason) VALUES \
             ('old-1', 'plate', '2026-11-30T08:00:00.000000Z', '/in', '0.0.9', 'fail', 'out of tolerance')"
                .into(),
        );
        v1.push(
            "INSERT INTO measurements (part, position, name, kind, value, unit, upper_limit, verdict) \
             SELECT id, 0, 'flat', 'flatness_peak_to_valley', 16.5, 'um', 15.0, 'fail' FROM parts"
                .into(),
        );
        db.execute(&v1.join(";\n"));
        let mut store = Store::open(&db.location()).unwrap_or_else(|e| panic!("{}: {e}", db.kind()));
        assert_eq!(store.schema_version().expect("version"), sheen::records::schema::SCHEMA_VERSION);
        let parts = store.parts(&HistoryFilter::default()).expect("read");
        assert_eq!(parts.len(), 1, "{}", db.kind());
        let old = &parts[0].record;
        assert_eq!((old.part_id.as_str(), old.verdict, old.decision_rule), ("old-1", PartVerdict::Fail, None));
        let m = &old.measurements[0];
        assert_eq!((m.value, m.upper_limit, m.verdict), (Some(16.5), Some(15.0), Some(Verdict::Fail)));
        assert!(m.uncertainty.is_none() && m.decision_rule.is_none(), "{}: {m:?}", db.kind());
        let mut open = record("new-1", "plate", "2026-12-07T08:00:00.000000Z", &[Some(14.8)]);
        open.verdict = PartVerdict::Inconclusive;
        open.measurements[0].verdict = Some(Verdict::Inconclusive);
        let id = store.insert(&open).unwrap_or_else(|e| panic!("{}: {e}", db.kind()));
        let parts = store.parts(&HistoryFilter::default()).expect("read");
        assert_eq!(parts[1].record, open, "{}", db.kind());
        assert!(id > parts[0].row_id, "{}: row ids continue after the migration", db.kind());
    });
}

#[test]
fn records_read_back_as_written_and_remeasuring_appends() {
    on_each_store("records_read_back_as_written_and_remeasuring_appends", |db| {
        let mut store = Store::open(&db.location()).expect("open");
        let evil = "x'); DROP TABLE parts;--";
        let mut first = record(evil, "plate-B", "2026-12-01T08:00:00.000000Z", &[Some(3.25), None]);
        first.operator = Some("Robert'); DELETE FROM measurements;--".into());
        first.measurements[1].lower_limit = Some(-1.5);
        let mut again = record(evil, "plate-B", "2026-12-01T09:00:00.000000Z", &[Some(3.5)]);
        again.verdict = PartVerdict::Fail;
        again.reason = Some("out of tolerance: 'flatness 0'".into());
        let a = store.insert(&first).expect("insert");
        let b = store.insert(&again).expect("insert again");
        assert!(b > a);
        let parts = store.parts(&HistoryFilter::default()).expect("read");
        assert_eq!(parts.len(), 2, "{}: a part measured again is a second record", db.kind());
        assert_eq!(parts[0].record, first);
        assert_eq!(parts[1].record, again);
        assert_eq!((parts[0].row_id, parts[1].row_id), (a, b));
        assert_eq!(db.count("SELECT count(*) FROM measurements"), 3);
    });
}

/// A time changed behind Sheen's back into no time is refused by name as a
/// corrupt store, never read as a record (it would sort and chart as
/// nothing).
#[test]
fn a_stored_time_that_is_no_time_is_refused_as_corrupt() {
    on_each_store("a_stored_time_that_is_no_time_is_refused_as_corrupt", |db| {
        let mut store = Store::open(&db.location()).expect("open");
        store.insert(&record("p1", "A", "2026-12-01T08:00:00.000000Z", &[Some(1.0)])).expect("insert");
        db.execute("UPDATE parts SET time_utc = 'yesterday'");
        let e = store.parts(&HistoryFilter::default()).expect_err("a time that is no time");
        assert!(matches!(e, sheen::records::RecordsError::Corrupt { .. }), "{}: {e:?}", db.kind());
        assert!(e.to_string().contains("'yesterday'"), "{}: {e}", db.kind());
        db.execute("UPDATE parts SET time_utc = '2026-12-01T08:00:00.000000Z'");
        let parts = store.parts(&HistoryFilter::default()).expect("read");
        assert_eq!(parts[0].record.time_utc, utc("2026-12-01T08:00:00.000000Z"));
    });
}

#[test]
fn history_filters_select_recipe_station_and_time() {
    on_each_store("history_filters_select_recipe_station_and_time", |db| {
        let mut store = Store::open(&db.location()).expect("open");
        for (i, (recipe, station)) in [("A", "s1"), ("B", "s1"), ("A", "s2"), ("A", "s1")].iter().enumerate() {
            let mut r = record(&format!("p{i}"), recipe, &format!("2026-12-0{}T10:00:00.000000Z", i + 1), &[Some(1.0)]);
            r.station = Some(station.to_string());
            store.insert(&r).expect("insert");
        }
        let ids = |store: &mut Store, f: HistoryFilter| -> Vec<String> {
            store.parts(&f).expect("read").into_iter().map(|p| p.record.part_id).collect()
        };
        assert_eq!(
            ids(&mut store, HistoryFilter { recipe: Some("A".into()), ..Default::default() }),
            ["p0", "p2", "p3"]
        );
        let f = HistoryFilter { recipe: Some("A".into()), station: Some("s1".into()), ..Default::default() };
        assert_eq!(ids(&mut store, f), ["p0", "p3"]);
        let f = HistoryFilter {
            since_utc: Some(utc("2026-12-02T10:00:00.000000Z")),
            until_utc: Some(utc("2026-12-04T10:00:00.000000Z")),
            ..Default::default()
        };
        assert_eq!(ids(&mut store, f), ["p1", "p2"], "since inclusive, until exclusive");
        let f = HistoryFilter { recipe: Some("A' OR '1'='1".into()), ..Default::default() };
        assert!(ids(&mut store, f).is_empty(), "a filter value is data, not SQL");
    });
}

#[test]
fn a_file_that_is_not_a_database_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("notes.sqlite");
    std::fs::write(&path, "these are my notes, not a database, and long enough to have a header").expect("write");
    let e = Store::open(&DbLocation::Sqlite(path.clone())).err().expect("refused").to_string();
    assert!(e.contains("notes.sqlite") && e.contains("not a"), "{e}");
    assert_eq!(
        std::fs::read_to_string(&path).expect("read"),
        "these are my notes, not a database, and long enough to have a header"
    );
}
