//! What the SQLite and PostgreSQL stores share about rows: the values a part
//! and a measurement are inserted with, named and in the order of the
//! column lists in [`super::schema`], and reading a selected row by column name.
//! A column added to the schema is added here once, for both drivers, and
//! no column is read by its number.

use std::borrow::Cow;

use super::query::StoredPart;
use super::{MeasurementRecord, PartRecord, PartVerdict, time};
use crate::analysis::measurement_table::{DecisionRule, Verdict};

/// A value bound to an `INSERT` parameter, typed as its column is
/// (`INTEGER` is 32 bits in PostgreSQL, `BIGINT` 64).
#[derive(Clone, Debug, PartialEq)]
pub(super) enum SqlValue<'a> {
    Text(Option<Cow<'a, str>>),
    Integer(i32),
    BigInt(i64),
    Double(Option<f64>),
}

/// A part's `parts` columns with their values, in [`super::schema::PART_COLUMNS`]
/// order (the `$n` of [`super::schema::insert_part`]).
pub(super) fn part_values(r: &PartRecord) -> [(&'static str, SqlValue<'_>); 16] {
    [
        ("part_id", text(&r.part_id)),
        ("recipe", text(&r.recipe)),
        ("time_utc", SqlValue::Text(Some(Cow::Owned(time::stored(r.time_utc))))),
        ("station", optional_text(&r.station)),
        ("operator", optional_text(&r.operator)),
        ("input_path", text(&r.input_path)),
        ("input_hash", optional_text(&r.input_hash)),
        ("sheen_version", text(&r.sheen_version)),
        ("engine_parameters", optional_text(&r.engine_parameters)),
        ("verdict", text(r.verdict.name())),
        ("reason", optional_text(&r.reason)),
        ("height_map_path", optional_text(&r.height_map_path)),
        ("height_map_hash", optional_text(&r.height_map_hash)),
        ("inspection", optional_text(&r.inspection)),
        ("decision_rule", SqlValue::Text(r.decision_rule.map(|d| Cow::Owned(d.name())))),
        ("exports", SqlValue::Text((!r.exports.is_empty()).then(|| Cow::Owned(r.exports.join("\n"))))),
    ]
}

/// A measurement's `measurements` columns with their values: the part's
/// row id, then [`super::schema::MEASUREMENT_COLUMNS`] in order.
pub(super) fn measurement_values(
    part: i64,
    position: usize,
    m: &MeasurementRecord,
) -> [(&'static str, SqlValue<'_>); 20] {
    use SqlValue::Double;
    [
        ("part", SqlValue::BigInt(part)),
        ("position", SqlValue::Integer(i32::try_from(position).unwrap_or(i32::MAX))),
        ("name", text(&m.name)),
        ("kind", text(&m.kind)),
        ("parameter", optional_text(&m.parameter)),
        ("value", Double(m.value)),
        ("unit", text(&m.unit)),
        ("nominal", Double(m.nominal)),
        ("lower_limit", Double(m.lower_limit)),
        ("upper_limit", Double(m.upper_limit)),
        ("verdict", SqlValue::Text(m.verdict.map(|v| Cow::Borrowed(v.name())))),
        ("note", optional_text(&m.note)),
        ("uncertainty", Double(m.uncertainty.as_ref().map(|u| u.u))),
        ("expanded_uncertainty", Double(m.uncertainty.as_ref().map(|u| u.expanded))),
        ("coverage_factor", Double(m.uncertainty.as_ref().map(|u| u.k))),
        ("uncertainty_method", SqlValue::Text(m.uncertainty.as_ref().map(|u| Cow::Borrowed(u.method.name())))),
        // The whole statement (budget, trials, noise floor) as JSON; the
        // columns before it are for queries.
        (
            "uncertainty_budget",
            SqlValue::Text(m.uncertainty.as_ref().and_then(|u| serde_json::to_string(u).ok()).map(Cow::Owned)),
        ),
        ("decision_rule", SqlValue::Text(m.decision_rule.map(|d| Cow::Owned(d.name())))),
        ("acceptance_lower", Double(m.acceptance_lower)),
        ("acceptance_upper", Double(m.acceptance_upper)),
    ]
}

fn text(value: &str) -> SqlValue<'_> {
    SqlValue::Text(Some(Cow::Borrowed(value)))
}

fn optional_text(value: &Option<String>) -> SqlValue<'_> {
    SqlValue::Text(value.as_deref().map(Cow::Borrowed))
}

impl SqlValue<'_> {
    /// The value as SQLite's driver binds it.
    pub(super) fn sqlite(&self) -> &dyn rusqlite::ToSql {
        match self {
            SqlValue::Text(v) => v,
            SqlValue::Integer(v) => v,
            SqlValue::BigInt(v) => v,
            SqlValue::Double(v) => v,
        }
    }

    /// The value as PostgreSQL's driver binds it (its own type checks apply).
    pub(super) fn postgres(&self) -> &(dyn postgres::types::ToSql + Sync) {
        match self {
            SqlValue::Text(v) => v,
            SqlValue::Integer(v) => v,
            SqlValue::BigInt(v) => v,
            SqlValue::Double(v) => v,
        }
    }
}

/// A row a store selected, read by column name.
pub(super) trait StoreRow {
    type Error;
    fn text(&self, column: &str) -> Result<String, Self::Error>;
    fn optional_text(&self, column: &str) -> Result<Option<String>, Self::Error>;
    fn big_int(&self, column: &str) -> Result<i64, Self::Error>;
    fn optional_double(&self, column: &str) -> Result<Option<f64>, Self::Error>;
}

/// Both drivers read a column by name into any of its Rust types with one
/// method (`get`, `try_get`); the trait names the four types records use.
macro_rules! impl_store_row {
    ($row:ty, $error:ty, $get:ident) => {
        impl StoreRow for $row {
            type Error = $error;
            fn text(&self, column: &str) -> Result<String, Self::Error> {
                self.$get(column)
            }
            fn optional_text(&self, column: &str) -> Result<Option<String>, Self::Error> {
                self.$get(column)
            }
            fn big_int(&self, column: &str) -> Result<i64, Self::Error> {
                self.$get(column)
            }
            fn optional_double(&self, column: &str) -> Result<Option<f64>, Self::Error> {
                self.$get(column)
            }
        }
    };
}

impl_store_row!(rusqlite::Row<'_>, rusqlite::Error, get);
impl_store_row!(postgres::Row, postgres::Error, try_get);

/// Why a selected row is not a record: the driver could not read a column,
/// or a value is one the schema does not allow.
pub(super) enum RowError<E> {
    Driver(E),
    Corrupt(String),
}

impl<E> From<E> for RowError<E> {
    fn from(e: E) -> Self {
        RowError::Driver(e)
    }
}

/// The `decision_rule` column of a part or measurement row.
fn decision_rule<R: StoreRow>(row: &R) -> Result<Option<DecisionRule>, RowError<R::Error>> {
    match row.optional_text("decision_rule")? {
        None => Ok(None),
        Some(text) => DecisionRule::parse(&text).map(Some).map_err(RowError::Corrupt),
    }
}

/// A row of [`super::schema::select_parts`]; its measurements are attached later.
pub(super) fn stored_part<R: StoreRow>(row: &R) -> Result<StoredPart, RowError<R::Error>> {
    let verdict = row.text("verdict")?;
    let verdict = PartVerdict::from_name(&verdict).ok_or_else(|| {
        RowError::Corrupt(format!("part verdict '{verdict}' is not pass, fail, inconclusive or error"))
    })?;
    let decision_rule = decision_rule(row)?;
    let time = row.text("time_utc")?;
    let time_utc = time::parse_stored(&time)
        .ok_or_else(|| RowError::Corrupt(format!("part time '{time}' is not an RFC 3339 time")))?;
    Ok(StoredPart {
        row_id: row.big_int("id")?,
        record: PartRecord {
            part_id: row.text("part_id")?,
            recipe: row.text("recipe")?,
            time_utc,
            station: row.optional_text("station")?,
            operator: row.optional_text("operator")?,
            input_path: row.text("input_path")?,
            input_hash: row.optional_text("input_hash")?,
            sheen_version: row.text("sheen_version")?,
            engine_parameters: row.optional_text("engine_parameters")?,
            verdict,
            reason: row.optional_text("reason")?,
            height_map_path: row.optional_text("height_map_path")?,
            height_map_hash: row.optional_text("height_map_hash")?,
            inspection: row.optional_text("inspection")?,
            decision_rule,
            exports: row.optional_text("exports")?.map_or_else(Vec::new, |e| e.lines().map(Into::into).collect()),
            measurements: Vec::new(),
        },
    })
}

/// A row of [`super::schema::select_measurements`] with its part's row id.
pub(super) fn stored_measurement<R: StoreRow>(row: &R) -> Result<(i64, MeasurementRecord), RowError<R::Error>> {
    let verdict = match row.optional_text("verdict")? {
        None => None,
        Some(text) => Some(Verdict::from_name(&text).ok_or_else(|| {
            RowError::Corrupt(format!("measurement verdict '{text}' is not pass, fail or inconclusive"))
        })?),
    };
    let uncertainty = match row.optional_text("uncertainty_budget")? {
        None => None,
        Some(json) => Some(serde_json::from_str(&json).map_err(|e| {
            RowError::Corrupt(format!("measurement uncertainty '{json}' is not an uncertainty statement: {e}"))
        })?),
    };
    let measurement = MeasurementRecord {
        name: row.text("name")?,
        kind: row.text("kind")?,
        parameter: row.optional_text("parameter")?,
        value: row.optional_double("value")?,
        unit: row.text("unit")?,
        nominal: row.optional_double("nominal")?,
        lower_limit: row.optional_double("lower_limit")?,
        upper_limit: row.optional_double("upper_limit")?,
        verdict,
        note: row.optional_text("note")?,
        uncertainty,
        decision_rule: decision_rule(row)?,
        acceptance_lower: row.optional_double("acceptance_lower")?,
        acceptance_upper: row.optional_double("acceptance_upper")?,
    };
    Ok((row.big_int("part")?, measurement))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::schema;

    /// The values bind to the `$n` of the shared `INSERT`s only if they come
    /// in the order of the schema's column lists.
    #[test]
    fn values_come_in_the_order_of_the_schemas_columns() {
        let record = PartRecord::bare("p", "r", time::now_utc());
        let names: Vec<&str> = part_values(&record).iter().map(|(name, _)| *name).collect();
        assert_eq!(names.join(", "), schema::PART_COLUMNS);
        let placeholders = (1..=16).map(|i| format!("${i}")).collect::<Vec<_>>().join(", ");
        assert!(schema::insert_part().contains(&format!("({}) VALUES ({placeholders})", schema::PART_COLUMNS)));
        let m = MeasurementRecord::bare("n", "k", 1.0, "um");
        let names: Vec<&str> = measurement_values(7, 3, &m).iter().map(|(name, _)| *name).collect();
        let expected = format!("part, {}", schema::MEASUREMENT_COLUMNS);
        assert_eq!(names.join(", "), expected);
        let placeholders = (1..=20).map(|i| format!("${i}")).collect::<Vec<_>>().join(", ");
        assert!(schema::insert_measurement().contains(&format!("({expected}) VALUES ({placeholders})")));
        assert_eq!(
            measurement_values(7, 3, &m)[..2],
            [("part", SqlValue::BigInt(7)), ("position", SqlValue::Integer(3))]
        );
        // The time is stored as the fixed-width text that sorts as time.
        let t = part_values(&record)[2].1.clone();
        assert_eq!(t, SqlValue::Text(Some(Cow::Owned(time::stored(record.time_utc)))));
    }
}
