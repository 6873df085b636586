//! What `sheen history` asks of a store, and what it gets back.

use super::PartRecord;

/// Which records to read. Times are [`super::time`]'s stored form: `since`
/// inclusive, `until` exclusive.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HistoryFilter {
    pub recipe: Option<String>,
    pub since_utc: Option<String>,
    pub until_utc: Option<String>,
    pub station: Option<String>,
}

impl HistoryFilter {
    /// The filter's four parameters, in [`super::schema::PART_FILTER`]'s order.
    pub(super) fn parameters(&self) -> [Option<&str>; 4] {
        [self.recipe.as_deref(), self.since_utc.as_deref(), self.until_utc.as_deref(), self.station.as_deref()]
    }
}

/// A record read back, with the row id the store gave it.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredPart {
    pub row_id: i64,
    pub record: PartRecord,
}

/// Attaches measurement rows `(part row id, position, row)` (ordered by part
/// and position) to their parts.
pub(super) fn attach_measurements(parts: &mut [StoredPart], rows: Vec<(i64, super::MeasurementRecord)>) {
    let mut by_id: std::collections::HashMap<i64, usize> = std::collections::HashMap::new();
    for (i, p) in parts.iter().enumerate() {
        by_id.insert(p.row_id, i);
    }
    for (part, row) in rows {
        if let Some(&i) = by_id.get(&part) {
            parts[i].record.measurements.push(row);
        }
    }
}
