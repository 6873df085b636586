//! One recipe's measurement over the selected records, in time order, with
//! its statistics: what `sheen history stats` prints and the app's History
//! view draws, computed once here so the two always agree.

use super::spc::{self, BASELINE_PARTS, Capability, ControlLimits, Summary, Violation};
use super::{StoredPart, time};
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

/// Every (recipe, measurement) of `parts` (oldest first), in order of first
/// appearance. `whole_range_baseline`: the control limits come from all the
/// values (a date range the user chose), else from a recipe's first
/// [`BASELINE_PARTS`].
pub fn trends(parts: &[StoredPart], whole_range_baseline: bool) -> Vec<Trend> {
    let mut out: Vec<Trend> = Vec::new();
    for (index, p) in parts.iter().enumerate() {
        let time_s = time::parse_stored(&p.record.time_utc).map_or(f64::NAN, |t| t.timestamp_micros() as f64 * 1e-6);
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
        let baseline = if whole_range_baseline { values.len() } else { values.len().min(BASELINE_PARTS) };
        t.control = spc::individuals_limits(&values[..baseline]);
        if let Some(limits) = &t.control {
            t.violations = spc::run_rule_violations(&values, limits);
        }
    }
    out
}
