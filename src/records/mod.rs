//! Inspection records: every inspected part kept in a database, so
//! a lab can ask how a recipe's measurements drift, not only whether today's
//! part passed.
//!
//! One versioned schema ([`schema`]) for two stores: SQLite (a file, the
//! default, one station) and PostgreSQL (a server several stations share).
//! Records are append-only: a part measured again gets a new row under the
//! same part ID, and nothing is ever updated in place. One record is one
//! transaction, so a killed process, a full disk or a lost connection leaves
//! either the whole record or none of it. Every statement is parameterised:
//! a part ID is data, never SQL.
//!
//! Pure storage: no GUI, no engine runs. The command line (`sheen analyze
//! --record`, `sheen history`) and the app build a [`PartRecord`] from an
//! inspection and hand it here.

pub mod hash;
pub mod keep;
pub mod location;
mod postgres_store;
pub mod query;
mod row;
pub mod schema;
pub mod spc;
mod sqlite_store;
pub mod time;
pub mod tls;
pub mod trend;

use crate::analysis::measurement_table::{DecisionRule, MeasurementTable};

pub use location::DbLocation;
pub use query::{HistoryFilter, StoredPart};

/// Test hook: the number of measurement rows after which the recording
/// process aborts inside its transaction (a crash at the worst moment, made
/// deterministic so a test can check no half record survives).
pub const ABORT_AFTER_ROWS_ENV: &str = "SHEEN_TEST_RECORD_ABORT_AFTER_ROWS";

/// Test hook: the number of measurement rows after which a PostgreSQL
/// server ends the recording connection (the store asks the server to
/// terminate its own backend, so the loss is the server's, not a mock).
pub const DROP_CONNECTION_AFTER_ROWS_ENV: &str = "SHEEN_TEST_RECORD_DROP_CONNECTION_AFTER_ROWS";

pub use crate::analysis::measurement_record::MeasurementRecord;
pub use crate::analysis::measurement_table::PartVerdict;

/// One inspected part: who, what, when, from which input, and the result.
#[derive(Clone, Debug, PartialEq)]
pub struct PartRecord {
    pub part_id: String,
    /// The inspection's name (its spec or session file stem by default).
    pub recipe: String,
    /// When the part was measured, to the microsecond; stored as fixed-width
    /// RFC 3339 text ([`time::stored`]), so text order is time order in both
    /// stores.
    pub time_utc: chrono::DateTime<chrono::Utc>,
    pub station: Option<String>,
    pub operator: Option<String>,
    pub input_path: String,
    /// SHA-256 of the input ([`hash`]); `None` when it could not be read.
    pub input_hash: Option<String>,
    pub sheen_version: String,
    /// The engine parameters as JSON text; `None` for a PLY input.
    pub engine_parameters: Option<String>,
    pub verdict: PartVerdict,
    /// Why the part failed or could not be measured.
    pub reason: Option<String>,
    /// The height map's X3P (relative to the SQLite file's folder, or
    /// absolute for PostgreSQL) and its SHA-256.
    pub height_map_path: Option<String>,
    pub height_map_hash: Option<String>,
    /// The inspection (regions, profiles, measurements) as JSON, so a
    /// record can be opened again with what was measured on it.
    pub inspection: Option<String>,
    /// The rule the part's toleranced rows were judged by (schema 2; `None`
    /// on older records and parts without a tolerance).
    pub decision_rule: Option<DecisionRule>,
    /// The exchange files (AQDEF, QIF) written for the part, one path each
    /// (schema 3; empty on older records).
    pub exports: Vec<String>,
    pub measurements: Vec<MeasurementRecord>,
}

impl PartRecord {
    /// The part's report under this record's header (part, recipe, time,
    /// station, operator, verdict and reason, input, engine parameters), so
    /// the app, `sheen analyze` and the watch print a part as they record it.
    pub fn report<'a>(
        &self,
        map: Option<&'a crate::analysis::height_map::HeightMap>,
        regions: &'a [crate::analysis::region::NamedRegion],
        profiles: &'a [crate::analysis::profile::Profile],
        table: &'a MeasurementTable,
    ) -> crate::io::report::PartReport<'a> {
        crate::io::report::PartReport {
            part_id: self.part_id.clone(),
            recipe: self.recipe.clone(),
            time_utc: self.time_utc,
            station: self.station.clone(),
            operator: self.operator.clone(),
            verdict: self.verdict,
            reason: self.reason.clone(),
            map,
            regions,
            profiles,
            table,
            engine_parameters: self
                .engine_parameters
                .as_deref()
                .map_or_else(Vec::new, crate::io::report::parameter_lines),
            input_path: self.input_path.clone(),
            input_hash: self.input_hash.clone(),
            sheen_version: self.sheen_version.clone(),
        }
    }
}

#[cfg(test)]
impl PartRecord {
    /// A passing record with nothing optional and no measurements, for a
    /// test to change what it is about.
    pub(crate) fn bare(part_id: &str, recipe: &str, time_utc: chrono::DateTime<chrono::Utc>) -> Self {
        PartRecord {
            part_id: part_id.into(),
            recipe: recipe.into(),
            time_utc,
            station: None,
            operator: None,
            input_path: "/in".into(),
            input_hash: None,
            sheen_version: "0".into(),
            engine_parameters: None,
            verdict: PartVerdict::Pass,
            reason: None,
            height_map_path: None,
            height_map_hash: None,
            inspection: None,
            decision_rule: None,
            exports: Vec::new(),
            measurements: Vec::new(),
        }
    }
}

impl PartRecord {
    /// The part as the exchange formats (AQDEF, QIF) describe it; the gauge
    /// names Sheen's version and, where known, the rig's calibration.
    pub fn exchange(&self, calibration: Option<&str>) -> crate::io::exchange::ExchangePart {
        crate::io::exchange::ExchangePart {
            part_id: self.part_id.clone(),
            part_number: self.recipe.clone(),
            description: None,
            operation: None,
            time_utc: self.time_utc,
            station: self.station.clone(),
            operator: self.operator.clone(),
            gauge: crate::io::exchange::ExchangePart::gauge_name(&self.sheen_version, calibration),
            verdict: self.verdict,
            reason: self.reason.clone(),
            measurements: self.measurements.clone(),
        }
    }
}

/// Why a record could not be kept or read. Every message names the store
/// (a PostgreSQL URL without its password) and fits one line.
#[derive(Debug, thiserror::Error)]
pub enum RecordsError {
    #[error("cannot open the records database {location}: {reason}")]
    Open { location: String, reason: String },
    #[error(
        "the records database {location} has schema version {found}, newer than this Sheen ({sheen}) knows \
         (up to {known}); use a newer Sheen with it"
    )]
    NewerSchema { location: String, found: i64, known: i64, sheen: &'static str },
    #[error("records database {location}: {reason}")]
    Store { location: String, reason: String },
    /// A stored row this Sheen cannot read back (edited by hand, or written
    /// by a faulty version): the store works, its content does not.
    #[error("records database {location} holds a record Sheen cannot read: {reason}")]
    Corrupt { location: String, reason: String },
}

/// An open records store.
pub enum Store {
    Sqlite(sqlite_store::SqliteStore),
    Postgres(postgres_store::PostgresStore),
}

impl Store {
    /// Opens (creating if needed) the store and brings its schema to this
    /// Sheen's version; a newer schema is refused.
    pub fn open(location: &DbLocation) -> Result<Self, RecordsError> {
        match location {
            DbLocation::Sqlite(path) => Ok(Store::Sqlite(sqlite_store::SqliteStore::open(path)?)),
            DbLocation::Postgres(url) => Ok(Store::Postgres(postgres_store::PostgresStore::open(url)?)),
        }
    }

    /// Writes one record in one transaction; returns its row id.
    pub fn insert(&mut self, record: &PartRecord) -> Result<i64, RecordsError> {
        match self {
            Store::Sqlite(s) => s.insert(record),
            Store::Postgres(s) => s.insert(record),
        }
    }

    /// The records the filter selects, oldest first, with their measurements.
    pub fn parts(&mut self, filter: &HistoryFilter) -> Result<Vec<StoredPart>, RecordsError> {
        match self {
            Store::Sqlite(s) => s.parts(filter),
            Store::Postgres(s) => s.parts(filter),
        }
    }

    /// The input hashes on record under `recipe`, and nothing else of its
    /// history: what the watch needs at its start to skip parts measured
    /// before.
    pub fn input_hashes(&mut self, recipe: &str) -> Result<std::collections::HashSet<String>, RecordsError> {
        match self {
            Store::Sqlite(s) => s.input_hashes(recipe),
            Store::Postgres(s) => s.input_hashes(recipe),
        }
    }

    /// The schema version the store is at.
    pub fn schema_version(&mut self) -> Result<i64, RecordsError> {
        match self {
            Store::Sqlite(s) => s.schema_version(),
            Store::Postgres(s) => s.schema_version(),
        }
    }
}

/// A test hook's row count, read once per record.
fn hook_rows(variable: &str) -> Option<usize> {
    std::env::var(variable).ok()?.trim().parse().ok()
}

fn abort_after_rows() -> Option<usize> {
    hook_rows(ABORT_AFTER_ROWS_ENV)
}

/// Called after each measurement row inside the transaction: under the test
/// hook, dies the way a killed process does (no unwinding, no rollback, no
/// destructor), so the store's own recovery is what is tested.
fn after_row_written(rows_written: usize, abort_after: Option<usize>) {
    if abort_after == Some(rows_written) {
        eprintln!("sheen: {ABORT_AFTER_ROWS_ENV}={rows_written}: aborting inside the record's transaction");
        std::process::abort();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::measurement_table::{MeasurementKind, MeasurementRow, Tolerance, Verdict};

    #[test]
    fn upper_only_limits_of_nonnegative_quantities_have_no_lower_limit() {
        let flat = MeasurementRow::new("flatness base", MeasurementKind::FlatnessPeakToValley, Some(3.0), "um")
            .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 5.0 }));
        let r = MeasurementRecord::from_row(&flat);
        assert_eq!((r.lower_limit, r.upper_limit, r.verdict), (None, Some(5.0), Some(Verdict::Pass)));
        // A step height's 0..5 without nominal is a real two-sided interval.
        let step = MeasurementRow::new("step", MeasurementKind::StepHeight, Some(3.0), "um")
            .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 5.0 }));
        assert_eq!(MeasurementRecord::from_row(&step).lower_limit, Some(0.0));
        // Ssk can be negative: its 0 is a limit; Sa cannot.
        let tex = |p: &str| {
            MeasurementRow::new(format!("seal {p}"), MeasurementKind::Texture, Some(0.2), "1")
                .with_parameter(p)
                .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 0.5 }))
        };
        assert_eq!(MeasurementRecord::from_row(&tex("Ssk")).lower_limit, Some(0.0));
        assert_eq!(MeasurementRecord::from_row(&tex("Sa")).lower_limit, None);
        // With a nominal the limits are nominal + deviations, both kept.
        let nom = MeasurementRow::new("step", MeasurementKind::StepHeight, Some(20.1), "um")
            .with_tolerance(Some(20.0), Some(Tolerance::symmetric(0.5)));
        let r = MeasurementRecord::from_row(&nom);
        assert_eq!((r.nominal, r.lower_limit, r.upper_limit), (Some(20.0), Some(19.5), Some(20.5)));
        // An unmeasured value is stored as none, never NaN.
        let none = MeasurementRow::new("x", MeasurementKind::FlatnessRms, Some(f64::NAN), "um");
        assert_eq!(MeasurementRecord::from_row(&none).value, None);
    }

    #[test]
    fn a_failing_store_and_an_unreadable_record_read_differently() {
        let store = RecordsError::Store { location: "r.sqlite".into(), reason: "disk I/O error".into() };
        let corrupt = RecordsError::Corrupt { location: "r.sqlite".into(), reason: "part verdict 'maybe'".into() };
        assert_eq!(store.to_string(), "records database r.sqlite: disk I/O error");
        assert_eq!(
            corrupt.to_string(),
            "records database r.sqlite holds a record Sheen cannot read: part verdict 'maybe'"
        );
    }

    #[test]
    fn verdict_names_round_trip() {
        for v in [PartVerdict::Pass, PartVerdict::Fail, PartVerdict::Error] {
            assert_eq!(PartVerdict::from_name(v.name()), Some(v));
        }
        assert_eq!(PartVerdict::from_name("PASS"), None);
    }
}
