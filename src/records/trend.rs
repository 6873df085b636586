//! One recipe's measurement over the selected records, in time order, with
//! its statistics: what `sheen history stats` prints and the app's History
//! view draws, computed once here so the two always agree.

use super::StoredPart;
use super::spc::{self, BASELINE_PARTS, Capability, ControlLimits, Summary, Violation};
use crate::analysis::measurement_table::Verdict;

/// One record of the measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct TrendPoint {
    /// Index of the part in the records the trend was made from.
    pub part: usize,
    /// Seconds since the Unix epoch (for a time axis).
    pub time_s: f64,
    /// `None` when the value could not be measured.
    pub value: Option<f64>,
    pub verdict: Option<Verdict>,
}

/// A recipe's measurement across records, and its statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct Trend {
    pub recipe: String,
    pub name: String,
    pub unit: String,
    pub points: Vec<TrendPoint>,
    /// The latest record's limits; `limits_changed` when older ones differ.
    pub lower: Option<f64>,
    pub upper: Option<f64>,
    pub limits_changed: bool,
    /// Of the measured values.
    pub summary: Option<Summary>,
    /// Mean moving range / d2.
    pub within_sigma: Option<f64>,
    pub capability: Capability,
    /// Individuals chart limits from the baseline.
    pub control: Option<ControlLimits>,
    /// Run-rule violations; `index` counts measured values (see [`Trend::measured`]).
    pub violations: Vec<Violation>,
}

impl Trend {
    /// The points that have a value, in order: what [`Violation::index`] counts.
    pub fn measured(&self) -> Vec<&TrendPoint> {
        self.points.iter().filter(|p| p.value.is_some()).collect()
    }

    /// Whether the measured point `i` (a [`Trend::measured`] index) breaks a rule.
    pub fn violates(&self, i: usize) -> bool {
        self.violations.iter().any(|v| v.index == i)
    }
}

/// Where the control limits of a trend come from.
#[derive(Clone, Copy, Debug)]
pub enum Baseline<'a> {
    /// All the selected values: a date range the user chose is the baseline.
    Selection,
    /// The first [`BASELINE_PARTS`] measured values of the recipe's whole
    /// history (every station, oldest first), so a filter by station is
    /// judged against the limits the process was characterised with, not
    /// against limits of its own making.
    RecipeStart(&'a [StoredPart]),
}

/// Every (recipe, measurement) of `parts` (oldest first), in order of first
/// appearance, with control limits from `baseline`.
pub fn trends(parts: &[StoredPart], baseline: Baseline<'_>) -> Vec<Trend> {
    let mut out: Vec<Trend> = Vec::new();
    for (index, p) in parts.iter().enumerate() {
        let time_s = p.record.time_utc.timestamp_micros() as f64 * 1e-6;
        for m in &p.record.measurements {
            let i = match out.iter().position(|t| t.recipe == p.record.recipe && t.name == m.name) {
                Some(i) => i,
                None => {
                    out.push(Trend {
                        recipe: p.record.recipe.clone(),
                        name: m.name.clone(),
                        unit: m.unit.clone(),
                        points: Vec::new(),
                        lower: m.lower_limit,
                        upper: m.upper_limit,
                        limits_changed: false,
                        summary: None,
                        within_sigma: None,
                        capability: Capability::default(),
                        control: None,
                        violations: Vec::new(),
                    });
                    out.len() - 1
                }
            };
            let t = &mut out[i];
            if (t.lower, t.upper) != (m.lower_limit, m.upper_limit) {
                t.limits_changed = true;
            }
            (t.lower, t.upper) = (m.lower_limit, m.upper_limit);
            t.points.push(TrendPoint { part: index, time_s, value: m.value, verdict: m.verdict });
        }
    }
    for t in &mut out {
        let values: Vec<f64> = t.points.iter().filter_map(|p| p.value).collect();
        t.summary = spc::summary(&values);
        t.within_sigma = spc::sigma_within(&values);
        if let Some(s) = &t.summary {
            t.capability = spc::capability(s.mean, t.within_sigma, t.lower, t.upper);
        }
        t.control = match baseline {
            Baseline::Selection => spc::individuals_limits(&values),
            Baseline::RecipeStart(history) => {
                let first: Vec<f64> = history
                    .iter()
                    .filter(|p| p.record.recipe == t.recipe)
                    .flat_map(|p| p.record.measurements.iter().filter(|m| m.name == t.name).filter_map(|m| m.value))
                    .take(BASELINE_PARTS)
                    .collect();
                spc::individuals_limits(&first)
            }
        };
        if let Some(limits) = &t.control {
            t.violations = spc::run_rule_violations(&values, limits);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::{MeasurementRecord, PartRecord};

    fn part(row_id: i64, station: &str, value: f64) -> StoredPart {
        let m = MeasurementRecord::bare("step", "step_height", value, "um");
        let time = crate::records::time::parse_stored(&format!("2026-12-01T10:00:{:02}.000000Z", row_id % 60));
        let record = PartRecord {
            station: Some(station.into()),
            measurements: vec![m],
            ..PartRecord::bare(&format!("p{row_id}"), "plate-B", time.unwrap())
        };
        StoredPart { row_id, record }
    }

    #[test]
    fn a_station_filter_keeps_the_recipe_baseline_and_a_date_range_is_its_own() {
        // Station A measures 10, 12, 10, 12, ... and B 20, 22, ...: the
        // recipe's first 25 values alternate A, B (mean moving range 10, so
        // sigma 10 / 1.128 = 8.865 and centre ~16), while B's own values
        // would give centre 21 and sigma 2 / 1.128.
        let all: Vec<StoredPart> = (0..40)
            .map(|i| {
                let wobble = if (i / 2) % 2 == 0 { 0.0 } else { 2.0 };
                if i % 2 == 0 { part(i, "A", 10.0 + wobble) } else { part(i, "B", 20.0 + wobble) }
            })
            .collect();
        let only_b: Vec<StoredPart> =
            all.iter().filter(|p| p.record.station.as_deref() == Some("B")).cloned().collect();
        let recipe = trends(&only_b, Baseline::RecipeStart(&all));
        let own = trends(&only_b, Baseline::Selection);
        let (recipe, own) = (recipe[0].control.unwrap(), own[0].control.unwrap());
        assert_eq!(recipe.baseline_n, 25);
        let first25: Vec<f64> = all[..25].iter().map(|p| p.record.measurements[0].value.unwrap()).collect();
        let centre = first25.iter().sum::<f64>() / 25.0;
        assert!((recipe.centre - centre).abs() < 1e-12, "{} vs {centre}", recipe.centre);
        assert_eq!(own.baseline_n, 20);
        assert!((own.centre - 21.0).abs() < 1e-12);
        // Station B alone sits 5 um above the recipe's centre line.
        assert!(recipe.centre < 16.5 && own.sigma < 2.0 && recipe.sigma > 8.0, "{recipe:?} {own:?}");
    }
}
