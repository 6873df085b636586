//! What `sheen history` asks of a store, and what it gets back.

use super::PartRecord;

/// Which records to read: `since` inclusive, `until` exclusive.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HistoryFilter {
    pub recipe: Option<String>,
    pub since_utc: Option<chrono::DateTime<chrono::Utc>>,
    pub until_utc: Option<chrono::DateTime<chrono::Utc>>,
    pub station: Option<String>,
}

impl HistoryFilter {
    /// The filter's four parameters, in [`super::schema::PART_FILTER`]'s
    /// order, times in the stored form they are compared with as text.
    pub(super) fn parameters(&self) -> [Option<String>; 4] {
        let time = |t: &Option<chrono::DateTime<chrono::Utc>>| t.map(super::time::stored);
        [self.recipe.clone(), time(&self.since_utc), time(&self.until_utc), self.station.clone()]
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
