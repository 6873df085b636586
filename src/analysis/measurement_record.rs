//! One measured value as it leaves an inspection: its limits as limits
//! (not a nominal and deviations), its verdict, uncertainty and rule, so the
//! records, the history and the exchange formats (AQDEF, QIF) need no
//! inspection to judge or describe it.

use super::measurement_table::{DecisionRule, MeasurementRow, Verdict};
use super::uncertainty::Uncertainty;

/// One measurement row of a part, with its limits as limits (not as a
/// nominal and deviations), so the history needs no inspection to judge it.
#[derive(Clone, Debug, PartialEq)]
pub struct MeasurementRecord {
    pub name: String,
    /// [`MeasurementKind::name`].
    pub kind: String,
    pub parameter: Option<String>,
    /// `None` when the value could not be measured (`note` says why).
    pub value: Option<f64>,
    pub unit: String,
    pub nominal: Option<f64>,
    /// `None` where the measurement has no such limit: a `<=` limit of a
    /// quantity that cannot be negative (flatness, Sa) has only an upper one.
    pub lower_limit: Option<f64>,
    pub upper_limit: Option<f64>,
    pub verdict: Option<Verdict>,
    pub note: Option<String>,
    /// The value's uncertainty (schema 2; `None` on older records).
    pub uncertainty: Option<Uncertainty>,
    /// The rule `verdict` was taken by (`None`: a record older than schema
    /// 2, judged by simple acceptance, or no tolerance).
    pub decision_rule: Option<DecisionRule>,
    /// The acceptance zone the rule left of the limits.
    pub acceptance_lower: Option<f64>,
    pub acceptance_upper: Option<f64>,
}

#[cfg(test)]
impl MeasurementRecord {
    /// A value without limits, nominal or note.
    pub(crate) fn bare(name: &str, kind: &str, value: f64, unit: &str) -> Self {
        Self { value: Some(value), ..Self::unmeasured(name, kind, unit) }
    }
}

impl MeasurementRecord {
    /// A measurement without a value, limits, verdict or note: what a part
    /// that could not be measured shows of it.
    pub fn unmeasured(name: &str, kind: &str, unit: &str) -> Self {
        MeasurementRecord {
            name: name.into(),
            kind: kind.into(),
            parameter: None,
            value: None,
            unit: unit.into(),
            nominal: None,
            lower_limit: None,
            upper_limit: None,
            verdict: None,
            note: None,
            uncertainty: None,
            decision_rule: None,
            acceptance_lower: None,
            acceptance_upper: None,
        }
    }

    /// The record of one table row.
    pub fn from_row(row: &MeasurementRow) -> Self {
        let (lower, upper) = row.limits().map_or((None, None), |(l, h)| (Some(l), Some(h)));
        // No lower limit where the decision guards none (`<=X` on a flatness).
        let lower = lower.filter(|_| row.lower_limit_applies());
        Self {
            name: row.name.clone(),
            kind: row.kind.name().to_string(),
            parameter: row.parameter.clone(),
            value: row.value.filter(|v| v.is_finite()),
            unit: row.unit.clone(),
            nominal: row.nominal,
            lower_limit: lower,
            upper_limit: upper,
            verdict: row.verdict(),
            note: row.note.clone(),
            uncertainty: row.uncertainty.clone(),
            decision_rule: row.applied_rule(),
            acceptance_lower: row.acceptance_limits().and_then(|(lo, _)| lo),
            acceptance_upper: row.acceptance_limits().map(|(_, hi)| hi),
        }
    }
}
