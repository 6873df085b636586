//! The records schema, one for SQLite and PostgreSQL, and its migrations.
//!
//! The version lives in `sheen_records_schema` (one row). Opening a store
//! applies the migrations from its version up to [`SCHEMA_VERSION`] in one
//! transaction; a store at a higher version was written by a newer Sheen
//! and is refused, since an older Sheen cannot know what its columns mean.
//!
//! The DDL is shared; only the row id differs (SQLite's rowid alias, a
//! PostgreSQL identity column). Types are written so both read them alike:
//! `TEXT`, `BIGINT`, `INTEGER`, `DOUBLE PRECISION` (SQLite's REAL). Times
//! are `TEXT` in one fixed-width RFC 3339 UTC form ([`super::time`]), so
//! comparing them as text compares instants in either store.

/// The schema version this Sheen writes and reads.
pub const SCHEMA_VERSION: i64 = 1;

/// The table holding the version.
pub const VERSION_TABLE: &str = "sheen_records_schema";

/// Placeholder in the DDL for the store's auto-numbered primary key.
pub const ROW_ID: &str = "{row_id}";

/// Per version, the statements that bring the previous version to it.
pub const MIGRATIONS: &[&[&str]] = &[
    // 1: parts and their measurements.
    &[
        "CREATE TABLE parts (
            id {row_id},
            part_id TEXT NOT NULL,
            recipe TEXT NOT NULL,
            time_utc TEXT NOT NULL,
            station TEXT,
            operator TEXT,
            input_path TEXT NOT NULL,
            input_hash TEXT,
            sheen_version TEXT NOT NULL,
            engine_parameters TEXT,
            verdict TEXT NOT NULL CHECK (verdict IN ('pass', 'fail', 'error')),
            reason TEXT,
            height_map_path TEXT,
            height_map_hash TEXT,
            inspection TEXT
        )",
        "CREATE INDEX parts_recipe_time ON parts (recipe, time_utc)",
        "CREATE INDEX parts_time ON parts (time_utc)",
        "CREATE INDEX parts_part_id ON parts (part_id)",
        "CREATE TABLE measurements (
            part BIGINT NOT NULL REFERENCES parts (id),
            position INTEGER NOT NULL,
            name TEXT NOT NULL,
            kind TEXT NOT NULL,
            parameter TEXT,
            value DOUBLE PRECISION,
            unit TEXT NOT NULL,
            nominal DOUBLE PRECISION,
            lower_limit DOUBLE PRECISION,
            upper_limit DOUBLE PRECISION,
            verdict TEXT CHECK (verdict IN ('pass', 'fail')),
            note TEXT,
            PRIMARY KEY (part, position)
        )",
    ],
];

/// The statements of migration `to` (1-based) with the store's row id.
pub fn migration(to: i64, row_id: &str) -> Vec<String> {
    let index = usize::try_from(to - 1).unwrap_or(usize::MAX);
    MIGRATIONS.get(index).map_or_else(Vec::new, |m| m.iter().map(|s| s.replace(ROW_ID, row_id)).collect())
}

/// Columns of `parts` in the order the stores insert and select them.
pub const PART_COLUMNS: &str = "part_id, recipe, time_utc, station, operator, input_path, input_hash, \
     sheen_version, engine_parameters, verdict, reason, height_map_path, height_map_hash, inspection";

/// Columns of `measurements` after `part`, in insert and select order.
pub const MEASUREMENT_COLUMNS: &str =
    "position, name, kind, parameter, value, unit, nominal, lower_limit, upper_limit, verdict, note";

/// One part, returning its row id; `$n` placeholders, which SQLite also
/// reads (numbered in order of appearance, so they bind as PostgreSQL's do).
pub fn insert_part() -> String {
    format!("INSERT INTO parts ({PART_COLUMNS}) VALUES ({}) RETURNING id", placeholders(PART_COLUMNS, 0))
}

/// One measurement of a part.
pub fn insert_measurement() -> String {
    format!("INSERT INTO measurements (part, {MEASUREMENT_COLUMNS}) VALUES ({})", placeholders(MEASUREMENT_COLUMNS, 1))
}

/// `$1, $2, ...`: one per column of a list, and `extra` more.
fn placeholders(columns: &str, extra: usize) -> String {
    let n = columns.split(',').count() + extra;
    (1..=n).map(|i| format!("${i}")).collect::<Vec<_>>().join(", ")
}

/// The filter of `sheen history`: recipe, time from (inclusive) and to
/// (exclusive), station. `CAST(.. AS TEXT)` types an absent filter for
/// PostgreSQL and is plain SQL for SQLite.
pub const PART_FILTER: &str = "(CAST($1 AS TEXT) IS NULL OR recipe = $1) \
     AND (CAST($2 AS TEXT) IS NULL OR time_utc >= $2) \
     AND (CAST($3 AS TEXT) IS NULL OR time_utc < $3) \
     AND (CAST($4 AS TEXT) IS NULL OR station = $4)";

/// The selected parts, oldest first.
pub fn select_parts() -> String {
    format!("SELECT id, {PART_COLUMNS} FROM parts WHERE {PART_FILTER} ORDER BY time_utc, id")
}

/// The measurements of the selected parts.
pub fn select_measurements() -> String {
    format!(
        "SELECT part, {MEASUREMENT_COLUMNS} FROM measurements \
         WHERE part IN (SELECT id FROM parts WHERE {PART_FILTER}) ORDER BY part, position"
    )
}

/// The input hashes recorded under one recipe (parameter 1).
pub const SELECT_INPUT_HASHES: &str =
    "SELECT DISTINCT input_hash FROM parts WHERE recipe = $1 AND input_hash IS NOT NULL";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_version_has_a_migration() {
        assert_eq!(MIGRATIONS.len() as i64, SCHEMA_VERSION);
        let v1 = migration(1, "INTEGER PRIMARY KEY AUTOINCREMENT");
        assert!(v1[0].contains("id INTEGER PRIMARY KEY AUTOINCREMENT,"));
        assert!(v1.iter().all(|s| !s.contains(ROW_ID)));
        assert!(migration(SCHEMA_VERSION + 1, "x").is_empty());
    }
}
