//! The SQLite store: one file, WAL journal, writers queued by a busy
//! timeout, every record one `BEGIN IMMEDIATE` transaction.
//!
//! WAL lets `sheen history` read while a station writes, and a commit is one
//! append to the log. `BEGIN IMMEDIATE` takes the write lock when the
//! transaction starts, so two writers never both read and then both try to
//! upgrade (the deadlock SQLite answers with `SQLITE_BUSY` at once, whatever
//! the timeout); the busy timeout makes the second writer wait its turn.

use std::path::{Path, PathBuf};
use std::time::Duration;

use rusqlite::{Connection, OpenFlags, OptionalExtension, TransactionBehavior, params, params_from_iter};

use super::query::{HistoryFilter, StoredPart, attach_measurements};
use super::row::{self, RowError};
use super::schema::{self, SCHEMA_VERSION, VERSION_TABLE};
use super::{PartRecord, RecordsError, after_row_written};

/// How long a writer waits for another's transaction before giving up. A
/// record takes milliseconds; a minute covers a slow disk and many stations.
const BUSY_TIMEOUT: Duration = Duration::from_secs(60);

pub struct SqliteStore {
    conn: Connection,
    path: PathBuf,
}

impl SqliteStore {
    pub fn open(path: &Path) -> Result<Self, RecordsError> {
        let location = path.display().to_string();
        let open_err = |reason: String| RecordsError::Open { location: location.clone(), reason };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| open_err(format!("cannot create {}: {e}", dir.display())))?;
        }
        let flags = OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_CREATE | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let conn = Connection::open_with_flags(path, flags).map_err(|e| open_err(e.to_string()))?;
        conn.busy_timeout(BUSY_TIMEOUT).map_err(|e| open_err(e.to_string()))?;
        // Switching to WAL needs a moment of exclusive access; a store other
        // processes are opening at the same time can answer busy even with
        // the timeout set, so retry for as long as the timeout allows.
        let started = std::time::Instant::now();
        loop {
            match conn.query_row("PRAGMA journal_mode = WAL", [], |r| r.get::<_, String>(0)) {
                Ok(_) => break,
                Err(e) if is_busy(&e) && started.elapsed() < BUSY_TIMEOUT => {
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => return Err(open_err(describe(&e))),
            }
        }
        conn.pragma_update(None, "foreign_keys", true).map_err(|e| open_err(e.to_string()))?;
        let mut store = Self { conn, path: path.to_path_buf() };
        store.migrate()?;
        Ok(store)
    }

    fn location(&self) -> String {
        self.path.display().to_string()
    }

    fn store_err(&self, e: &rusqlite::Error) -> RecordsError {
        RecordsError::Store { location: self.location(), reason: describe(e) }
    }

    fn read_version(conn: &Connection) -> rusqlite::Result<i64> {
        let exists: bool = conn.query_row(
            "SELECT count(*) > 0 FROM sqlite_master WHERE type = 'table' AND name = ?1",
            [VERSION_TABLE],
            |r| r.get(0),
        )?;
        if !exists {
            return Ok(0);
        }
        let v: Option<i64> = conn
            .query_row(&format!("SELECT max(version) FROM {VERSION_TABLE}"), [], |r| r.get(0))
            .optional()?
            .flatten();
        Ok(v.unwrap_or(0))
    }

    pub fn schema_version(&mut self) -> Result<i64, RecordsError> {
        Self::read_version(&self.conn).map_err(|e| self.store_err(&e))
    }

    fn newer(&self, found: i64) -> RecordsError {
        newer_schema(self.location(), found)
    }

    /// Brings the schema to [`SCHEMA_VERSION`]; the common case (already
    /// there) only reads.
    fn migrate(&mut self) -> Result<(), RecordsError> {
        let location = self.location();
        let open_err = |e: &rusqlite::Error| RecordsError::Open { location: location.clone(), reason: describe(e) };
        let found = Self::read_version(&self.conn).map_err(|e| open_err(&e))?;
        if found > SCHEMA_VERSION {
            return Err(self.newer(found));
        }
        if found == SCHEMA_VERSION {
            return Ok(());
        }
        let tx = self.conn.transaction_with_behavior(TransactionBehavior::Immediate).map_err(|e| open_err(&e))?;
        // Another process may have migrated while this one waited.
        let found = Self::read_version(&tx).map_err(|e| open_err(&e))?;
        if found > SCHEMA_VERSION {
            return Err(newer_schema(location.clone(), found));
        }
        let apply = || -> rusqlite::Result<()> {
            tx.execute(&format!("CREATE TABLE IF NOT EXISTS {VERSION_TABLE} (version INTEGER NOT NULL)"), [])?;
            for to in found + 1..=SCHEMA_VERSION {
                for statement in schema::migration(to, schema::Dialect::Sqlite) {
                    tx.execute(&statement, [])?;
                }
            }
            tx.execute(&format!("DELETE FROM {VERSION_TABLE}"), [])?;
            tx.execute(&format!("INSERT INTO {VERSION_TABLE} (version) VALUES (?1)"), [SCHEMA_VERSION])?;
            Ok(())
        };
        apply().map_err(|e| open_err(&e))?;
        tx.commit().map_err(|e| open_err(&e))
    }

    pub fn insert(&mut self, record: &PartRecord) -> Result<i64, RecordsError> {
        let abort_after = super::abort_after_rows();
        let location = self.location();
        let err = |e: rusqlite::Error| RecordsError::Store { location: location.clone(), reason: describe(&e) };
        let tx = self.conn.transaction_with_behavior(TransactionBehavior::Immediate).map_err(err)?;
        let values = row::part_values(record);
        let id: i64 = tx
            .query_row(&schema::insert_part(), params_from_iter(values.iter().map(|(_, v)| v.sqlite())), |r| r.get(0))
            .map_err(err)?;
        let insert = schema::insert_measurement();
        for (position, m) in record.measurements.iter().enumerate() {
            let values = row::measurement_values(id, position, m);
            tx.execute(&insert, params_from_iter(values.iter().map(|(_, v)| v.sqlite()))).map_err(err)?;
            after_row_written(position + 1, abort_after);
        }
        tx.commit().map_err(err)?;
        Ok(id)
    }

    pub fn input_hashes(&mut self, recipe: &str) -> Result<std::collections::HashSet<String>, RecordsError> {
        let err = |e: rusqlite::Error| self.store_err(&e);
        let mut stmt = self.conn.prepare(schema::SELECT_INPUT_HASHES).map_err(err)?;
        let hashes = stmt
            .query_map([recipe], |r| r.get::<_, String>(0))
            .map_err(err)?
            .collect::<rusqlite::Result<_>>()
            .map_err(err)?;
        Ok(hashes)
    }

    pub fn parts(&mut self, filter: &HistoryFilter) -> Result<Vec<StoredPart>, RecordsError> {
        let location = self.location();
        let err = |e: rusqlite::Error| RecordsError::Store { location: location.clone(), reason: describe(&e) };
        let row_err = |e: RowError<rusqlite::Error>| match e {
            RowError::Driver(e) => err(e),
            RowError::Corrupt(reason) => RecordsError::Corrupt { location: location.clone(), reason },
        };
        // One read transaction, so parts and measurements are one snapshot
        // even while another station commits.
        let tx = self.conn.transaction_with_behavior(TransactionBehavior::Deferred).map_err(err)?;
        let f = filter.parameters();
        let mut parts = Vec::new();
        {
            let mut stmt = tx.prepare(&schema::select_parts()).map_err(err)?;
            let mut rows = stmt.query(params![f[0], f[1], f[2], f[3]]).map_err(err)?;
            while let Some(r) = rows.next().map_err(err)? {
                parts.push(row::stored_part(r).map_err(row_err)?);
            }
        }
        let mut measurements = Vec::new();
        {
            let mut stmt = tx.prepare(&schema::select_measurements()).map_err(err)?;
            let mut rows = stmt.query(params![f[0], f[1], f[2], f[3]]).map_err(err)?;
            while let Some(r) = rows.next().map_err(err)? {
                measurements.push(row::stored_measurement(r).map_err(row_err)?);
            }
        }
        tx.finish().map_err(err)?;
        attach_measurements(&mut parts, measurements);
        Ok(parts)
    }
}

/// A store at `found` was written by a newer Sheen.
pub(super) fn newer_schema(location: String, found: i64) -> RecordsError {
    RecordsError::NewerSchema { location, found, known: SCHEMA_VERSION, sheen: env!("CARGO_PKG_VERSION") }
}

fn is_busy(e: &rusqlite::Error) -> bool {
    matches!(e.sqlite_error_code(), Some(rusqlite::ErrorCode::DatabaseBusy | rusqlite::ErrorCode::DatabaseLocked))
}

/// SQLite's message, with the hint a user needs for the usual causes.
fn describe(e: &rusqlite::Error) -> String {
    match e.sqlite_error_code() {
        Some(rusqlite::ErrorCode::NotADatabase) => format!("{e} (the file is not a Sheen records database)"),
        Some(rusqlite::ErrorCode::DiskFull) => format!("{e} (the disk is full)"),
        Some(rusqlite::ErrorCode::ReadOnly) => format!("{e} (no write access)"),
        _ => e.to_string(),
    }
}
