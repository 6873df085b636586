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

/// The schema version this Sheen writes and reads. 2 added each
/// measurement's uncertainty and decision rule, and the verdict
/// `inconclusive` (ISO 14253-1); 3 the exchange files written for a part
/// (AQDEF, QIF).
pub const SCHEMA_VERSION: i64 = 3;

/// Version 3 from version 2: which exchange files were written for a part.
const MIGRATION_3: [&str; 1] = ["ALTER TABLE parts ADD COLUMN exports TEXT"];

/// The two stores' SQL, where it differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    Sqlite,
    Postgres,
}

impl Dialect {
    /// The auto-numbered primary key.
    pub fn row_id(self) -> &'static str {
        match self {
            Dialect::Sqlite => "INTEGER PRIMARY KEY AUTOINCREMENT",
            Dialect::Postgres => "BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
        }
    }
}

/// Version 2's new columns, as `ALTER TABLE .. ADD COLUMN` takes them.
const PART_COLUMNS_V2: [&str; 1] = ["decision_rule TEXT"];
const MEASUREMENT_COLUMNS_V2: [&str; 8] = [
    "uncertainty DOUBLE PRECISION",
    "expanded_uncertainty DOUBLE PRECISION",
    "coverage_factor DOUBLE PRECISION",
    "uncertainty_method TEXT",
    "uncertainty_budget TEXT",
    "decision_rule TEXT",
    "acceptance_lower DOUBLE PRECISION",
    "acceptance_upper DOUBLE PRECISION",
];

/// The verdicts' CHECK constraints of version 1 and of version 2.
const PART_VERDICTS: [&str; 2] =
    ["CHECK (verdict IN ('pass', 'fail', 'error'))", "CHECK (verdict IN ('pass', 'fail', 'error', 'inconclusive'))"];
const MEASUREMENT_VERDICTS: [&str; 2] =
    ["CHECK (verdict IN ('pass', 'fail'))", "CHECK (verdict IN ('pass', 'fail', 'inconclusive'))"];

/// Version 1's `parts` and `measurements` columns, copied by the SQLite rebuild.
const PART_COLUMNS_V1: &str = "id, part_id, recipe, time_utc, station, operator, input_path, input_hash, \
     sheen_version, engine_parameters, verdict, reason, height_map_path, height_map_hash, inspection";
const MEASUREMENT_COLUMNS_V1: &str =
    "part, position, name, kind, parameter, value, unit, nominal, lower_limit, upper_limit, verdict, note";

/// Version 2 from version 1: the verdicts admit `inconclusive`, and the
/// new columns are added. PostgreSQL changes the CHECK constraints in
/// place; SQLite cannot, so it rebuilds both tables from version 1's DDL
/// with the wider CHECK (its documented procedure: new tables, copy, drop
/// the old, rename), in the migration's transaction, children dropped before
/// their parents so the foreign keys hold throughout. The new columns are
/// added alike in both.
fn migration_2(dialect: Dialect) -> Vec<String> {
    let v1 = MIGRATIONS[0];
    let (parts_ddl, part_indexes, measurements_ddl) = (v1[0], &v1[1..4], v1[4]);
    let mut out: Vec<String> = match dialect {
        Dialect::Postgres => vec![
            "ALTER TABLE parts DROP CONSTRAINT parts_verdict_check".into(),
            format!("ALTER TABLE parts ADD CONSTRAINT parts_verdict_check {}", PART_VERDICTS[1]),
            "ALTER TABLE measurements DROP CONSTRAINT measurements_verdict_check".into(),
            format!("ALTER TABLE measurements ADD CONSTRAINT measurements_verdict_check {}", MEASUREMENT_VERDICTS[1]),
        ],
        Dialect::Sqlite => {
            let mut rebuild = vec![
                parts_ddl
                    .replacen("CREATE TABLE parts (", "CREATE TABLE parts_v2 (", 1)
                    .replacen(PART_VERDICTS[0], PART_VERDICTS[1], 1)
                    .replace(ROW_ID, dialect.row_id()),
                format!("INSERT INTO parts_v2 ({PART_COLUMNS_V1}) SELECT {PART_COLUMNS_V1} FROM parts"),
                measurements_ddl
                    .replacen("CREATE TABLE measurements (", "CREATE TABLE measurements_v2 (", 1)
                    .replacen("REFERENCES parts (id)", "REFERENCES parts_v2 (id)", 1)
                    .replacen(MEASUREMENT_VERDICTS[0], MEASUREMENT_VERDICTS[1], 1),
                format!(
                    "INSERT INTO measurements_v2 ({MEASUREMENT_COLUMNS_V1}) SELECT {MEASUREMENT_COLUMNS_V1} FROM measurements"
                ),
                "DROP TABLE measurements".into(),
                "DROP TABLE parts".into(),
                "ALTER TABLE parts_v2 RENAME TO parts".into(),
                "ALTER TABLE measurements_v2 RENAME TO measurements".into(),
            ];
            rebuild.extend(part_indexes.iter().map(|s| s.to_string()));
            rebuild
        }
    };
    out.extend(PART_COLUMNS_V2.iter().map(|c| format!("ALTER TABLE parts ADD COLUMN {c}")));
    out.extend(MEASUREMENT_COLUMNS_V2.iter().map(|c| format!("ALTER TABLE measurements ADD COLUMN {c}")));
    out
}

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

/// The statements of migration `to` (1-based) in the store's dialect.
pub fn migration(to: i64, dialect: Dialect) -> Vec<String> {
    if to == 2 {
        return migration_2(dialect);
    }
    if to == 3 {
        return MIGRATION_3.iter().map(|s| s.to_string()).collect();
    }
    let index = usize::try_from(to - 1).unwrap_or(usize::MAX);
    MIGRATIONS.get(index).map_or_else(Vec::new, |m| m.iter().map(|s| s.replace(ROW_ID, dialect.row_id())).collect())
}

/// Columns of `parts` in the order the stores insert and select them.
pub const PART_COLUMNS: &str = "part_id, recipe, time_utc, station, operator, input_path, input_hash, \
     sheen_version, engine_parameters, verdict, reason, height_map_path, height_map_hash, inspection, decision_rule, exports";

/// Columns of `measurements` after `part`, in insert and select order.
pub const MEASUREMENT_COLUMNS: &str = "position, name, kind, parameter, value, unit, nominal, lower_limit, upper_limit, \
     verdict, note, uncertainty, expanded_uncertainty, coverage_factor, uncertainty_method, uncertainty_budget, \
     decision_rule, acceptance_lower, acceptance_upper";

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
        assert_eq!(MIGRATIONS.len() as i64 + 2, SCHEMA_VERSION, "versions 2 and 3 are built per dialect");
        assert!(migration(3, Dialect::Postgres)[0].contains("exports") && PART_COLUMNS.ends_with("exports"));
        let v1 = migration(1, Dialect::Sqlite);
        assert!(v1[0].contains("id INTEGER PRIMARY KEY AUTOINCREMENT,"));
        assert!(v1.iter().all(|s| !s.contains(ROW_ID)));
        for dialect in [Dialect::Sqlite, Dialect::Postgres] {
            let v2 = migration(2, dialect).join(";\n");
            for column in MEASUREMENT_COLUMNS_V2.iter().map(|c| c.split(' ').next().unwrap_or_default()) {
                assert!(v2.contains(column) && MEASUREMENT_COLUMNS.contains(column), "{column}");
            }
            assert!(v2.contains("'inconclusive'"));
            // Each rebuilt table's CHECK was widened, not left as version 1's.
            assert!(!v2.contains(PART_VERDICTS[0]) && !v2.contains(MEASUREMENT_VERDICTS[0]), "{v2}");
        }
        assert!(migration(SCHEMA_VERSION + 1, Dialect::Sqlite).is_empty());
    }
}
