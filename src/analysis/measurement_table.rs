//! The table of results an inspection produces: one row per measured value,
//! with its unit, its uncertainty and, when a tolerance is given, a verdict
//! by a stated decision rule (ISO 14253-1 by default: conformity is proven
//! only inside the tolerance shrunk by the expanded uncertainty U).
//!
//! A tolerance is a pair of deviations from the nominal value (`lower` is
//! usually negative); without a nominal the deviations are the limits
//! themselves, which suits one-sided quantities such as flatness
//! (`upper = 5 um`, `lower = 0`). A value that could not be measured fails
//! any tolerance: a production line must not pass a part it did not measure.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::uncertainty::Uncertainty;

/// What a row measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeasurementKind {
    StepHeight,
    FlatnessPeakToValley,
    FlatnessRms,
    Coplanarity,
    /// One land's largest |deviation| from the common plane of a coplanarity.
    LandDeviation,
    /// Tilt of a fitted plane against the X-Y plane.
    PlaneTilt,
    /// One ISO 25178-2 areal parameter of a region (the row's `parameter`).
    Texture,
    /// One ISO 21920-2 parameter of a section profile.
    ProfileTexture,
    /// Where a recipe found the part: match score, rotation, shift.
    Alignment,
}

impl MeasurementKind {
    pub fn name(self) -> &'static str {
        match self {
            MeasurementKind::StepHeight => "step_height",
            MeasurementKind::FlatnessPeakToValley => "flatness_peak_to_valley",
            MeasurementKind::FlatnessRms => "flatness_rms",
            MeasurementKind::Coplanarity => "coplanarity",
            MeasurementKind::LandDeviation => "land_deviation",
            MeasurementKind::PlaneTilt => "plane_tilt",
            MeasurementKind::Texture => "texture",
            MeasurementKind::ProfileTexture => "profile_texture",
            MeasurementKind::Alignment => "alignment",
        }
    }

    pub const ALL: [MeasurementKind; 9] = [
        MeasurementKind::StepHeight,
        MeasurementKind::FlatnessPeakToValley,
        MeasurementKind::FlatnessRms,
        MeasurementKind::Coplanarity,
        MeasurementKind::LandDeviation,
        MeasurementKind::PlaneTilt,
        MeasurementKind::Texture,
        MeasurementKind::ProfileTexture,
        MeasurementKind::Alignment,
    ];

    /// The kind [`name`](Self::name) spells (as the records keep it).
    pub fn from_name(text: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == text)
    }
}

/// Allowed deviations from the nominal value (or limits when there is none).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerance {
    pub lower: f64,
    pub upper: f64,
}

impl Tolerance {
    /// Symmetric `nominal ± half_width`.
    pub fn symmetric(half_width: f64) -> Self {
        Self { lower: -half_width.abs(), upper: half_width.abs() }
    }

    /// Checks the interval (finite, `lower <= upper`); `name` is the measurement's.
    pub fn validate(&self, name: &str) -> Result<(), AnalysisError> {
        if self.lower.is_finite() && self.upper.is_finite() && self.lower <= self.upper {
            Ok(())
        } else {
            Err(AnalysisError::InvalidTolerance { name: name.to_string(), lower: self.lower, upper: self.upper })
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Pass,
    Fail,
    /// The value lies within U of a limit: by ISO 14253-1 neither
    /// conformity nor non-conformity is proven.
    Inconclusive,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Fail => "fail",
            Verdict::Inconclusive => "inconclusive",
        }
    }

    pub fn from_name(text: &str) -> Option<Self> {
        [Verdict::Pass, Verdict::Fail, Verdict::Inconclusive].into_iter().find(|v| v.name() == text)
    }
}

/// How a toleranced value and its expanded uncertainty U become a verdict.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum DecisionRule {
    /// ISO 14253-1:2017: pass when LSL + U <= y <= USL - U, fail when
    /// y < LSL - U or y > USL + U, otherwise inconclusive.
    #[default]
    Iso14253,
    /// ILAC-G8:2019 simple acceptance: within the limits passes, U ignored.
    Simple,
    /// ILAC-G8:2019 guarded acceptance (ISO/TR 14253-6): the limits shrunk
    /// by `fraction` x U; within them passes, anything else fails.
    GuardBand { fraction: f64 },
}

impl DecisionRule {
    pub const HELP: &'static str = "iso-14253-1 (default), simple, or guard-band:F (limits shrunk by F x U)";

    pub fn name(&self) -> String {
        match self {
            DecisionRule::Iso14253 => "iso-14253-1".into(),
            DecisionRule::Simple => "simple".into(),
            DecisionRule::GuardBand { fraction } => format!("guard-band:{fraction}"),
        }
    }

    pub fn parse(text: &str) -> Result<Self, String> {
        let t = text.trim();
        match t {
            "iso-14253-1" | "iso14253-1" | "iso" => Ok(DecisionRule::Iso14253),
            "simple" => Ok(DecisionRule::Simple),
            _ => match t.strip_prefix("guard-band:").map(str::parse::<f64>) {
                Some(Ok(fraction)) if fraction.is_finite() && fraction >= 0.0 => {
                    Ok(DecisionRule::GuardBand { fraction })
                }
                Some(_) => Err(format!(
                    "decision rule '{text}': the guard band is a fraction of U, a number >= 0 (guard-band:0.5)"
                )),
                None => Err(format!("decision rule '{text}' is unknown; expected {}", Self::HELP)),
            },
        }
    }

    /// How far inside a limit the acceptance zone starts, for U.
    pub fn guard(&self, expanded_u: f64) -> f64 {
        match self {
            DecisionRule::Iso14253 => expanded_u,
            DecisionRule::Simple => 0.0,
            DecisionRule::GuardBand { fraction } => fraction * expanded_u,
        }
    }

    /// The verdict of a measured `value` against the limits (`lower` absent
    /// for a one-sided tolerance) with expanded uncertainty `expanded_u`.
    pub fn decide(&self, value: f64, lower: Option<f64>, upper: f64, expanded_u: f64) -> Verdict {
        let g = self.guard(expanded_u);
        let inside = |margin: f64| lower.is_none_or(|lo| value >= lo + margin) && value <= upper - margin;
        if inside(g) {
            Verdict::Pass
        } else if matches!(self, DecisionRule::Iso14253) && inside(-expanded_u) {
            Verdict::Inconclusive
        } else {
            Verdict::Fail
        }
    }
}

impl TryFrom<String> for DecisionRule {
    type Error = String;
    fn try_from(text: String) -> Result<Self, String> {
        Self::parse(&text)
    }
}

impl From<DecisionRule> for String {
    fn from(rule: DecisionRule) -> String {
        rule.name()
    }
}

impl std::fmt::Display for DecisionRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

impl std::str::FromStr for DecisionRule {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        Self::parse(text)
    }
}

/// A part's overall verdict: the one type the records, the reports, the
/// watch's line and the app share, so a part reads the same everywhere. A
/// part measured without a toleranced row is a pass (nothing it was asked
/// to meet failed) whose reason says "no toleranced measurement".
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PartVerdict {
    Pass,
    Fail,
    /// The part could not be measured (bad input, no 3D result); the record's
    /// reason says why.
    Error,
    /// No row failed, but at least one lies within its uncertainty of a
    /// limit (ISO 14253-1): neither accepted nor rejected.
    Inconclusive,
}

impl PartVerdict {
    pub fn name(self) -> &'static str {
        match self {
            PartVerdict::Pass => "pass",
            PartVerdict::Fail => "fail",
            PartVerdict::Error => "error",
            PartVerdict::Inconclusive => "inconclusive",
        }
    }

    /// The verdict of a measured part and why: failed rows named, or "no
    /// toleranced measurement" for a part measured without limits (a pass:
    /// nothing it was asked to meet failed).
    pub fn of_table(table: &MeasurementTable) -> (Self, Option<String>) {
        match table.overall_verdict() {
            Some(Verdict::Fail) => {
                (PartVerdict::Fail, Some(format!("out of tolerance: {}", table.rows_judged(Verdict::Fail))))
            }
            Some(Verdict::Inconclusive) => (
                PartVerdict::Inconclusive,
                Some(format!("within the uncertainty of a limit: {}", table.rows_judged(Verdict::Inconclusive))),
            ),
            Some(Verdict::Pass) => (PartVerdict::Pass, None),
            None => (PartVerdict::Pass, Some("no toleranced measurement".into())),
        }
    }

    pub fn from_name(text: &str) -> Option<Self> {
        match text {
            "pass" => Some(PartVerdict::Pass),
            "fail" => Some(PartVerdict::Fail),
            "error" => Some(PartVerdict::Error),
            "inconclusive" => Some(PartVerdict::Inconclusive),
            _ => None,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeasurementRow {
    pub name: String,
    pub kind: MeasurementKind,
    /// The texture parameter of a texture row ("Sq", "Ra"); absent on other kinds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameter: Option<String>,
    /// `None` when the value could not be measured (`note` says why).
    pub value: Option<f64>,
    /// "um" for heights, "deg" for angles, "%" for ratios, "1" for shape parameters, "mm" for lengths.
    pub unit: String,
    pub nominal: Option<f64>,
    pub tolerance: Option<Tolerance>,
    /// Context: sample counts, residuals, why a value is missing.
    pub note: Option<String>,
    /// The value's uncertainty, in `unit`; `None` where none is stated
    /// (alignment rows, rows kept by a store older than schema 2, Monte
    /// Carlo turned off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<Uncertainty>,
    /// The rule the verdict is taken by; `None` on rows that state none
    /// (records older than schema 2), which were judged by simple acceptance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decision_rule: Option<DecisionRule>,
}

impl MeasurementRow {
    pub fn new(name: impl Into<String>, kind: MeasurementKind, value: Option<f64>, unit: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            kind,
            parameter: None,
            value,
            unit: unit.into(),
            nominal: None,
            tolerance: None,
            note: None,
            uncertainty: None,
            decision_rule: None,
        }
    }

    pub fn with_parameter(mut self, parameter: impl Into<String>) -> Self {
        self.parameter = Some(parameter.into());
        self
    }

    pub fn with_tolerance(mut self, nominal: Option<f64>, tolerance: Option<Tolerance>) -> Self {
        self.nominal = nominal;
        self.tolerance = tolerance;
        self
    }

    pub fn with_note(mut self, note: impl Into<String>) -> Self {
        self.note = Some(note.into());
        self
    }

    pub fn with_uncertainty(mut self, uncertainty: Option<Uncertainty>) -> Self {
        self.uncertainty = uncertainty;
        self
    }

    pub fn with_decision_rule(mut self, rule: DecisionRule) -> Self {
        self.decision_rule = Some(rule);
        self
    }

    /// Lowest and highest value within tolerance, when toleranced.
    pub fn limits(&self) -> Option<(f64, f64)> {
        let t = self.tolerance?;
        let nominal = self.nominal.unwrap_or(0.0);
        Some((nominal + t.lower, nominal + t.upper))
    }

    /// Whether the value can never be below zero (peak-to-valley and RMS
    /// deviations, tilt angles, most texture parameters).
    pub fn cannot_be_negative(&self) -> bool {
        use super::texture::measure::ArealParameter;
        use super::texture::profile_params::ProfileParameter;
        let parameter = self.parameter.as_deref();
        match self.kind {
            MeasurementKind::StepHeight | MeasurementKind::Alignment => false,
            MeasurementKind::FlatnessPeakToValley
            | MeasurementKind::FlatnessRms
            | MeasurementKind::Coplanarity
            | MeasurementKind::LandDeviation
            | MeasurementKind::PlaneTilt => true,
            MeasurementKind::Texture => {
                parameter.and_then(ArealParameter::from_name).is_some_and(|p| !p.can_be_negative())
            }
            MeasurementKind::ProfileTexture => {
                parameter.and_then(ProfileParameter::from_name).is_some_and(|p| !p.can_be_negative())
            }
        }
    }

    /// Whether the tolerance has a lower specification limit. `<=X` becomes
    /// the tolerance 0..X without a nominal; for a quantity that cannot be
    /// negative the 0 is where the quantity ends, not a limit: a decision
    /// rule does not guard it and the records keep no lower limit (a
    /// flatness would otherwise get a Cp against a limit nobody set).
    pub fn lower_limit_applies(&self) -> bool {
        !(self.nominal.is_none() && self.tolerance.is_some_and(|t| t.lower == 0.0) && self.cannot_be_negative())
    }

    /// The rule this row is judged by (simple acceptance where it states none).
    pub fn rule(&self) -> DecisionRule {
        self.decision_rule.unwrap_or(DecisionRule::Simple)
    }

    /// The rule the row's verdict was taken by; `None` without a tolerance.
    pub fn applied_rule(&self) -> Option<DecisionRule> {
        self.limits().map(|_| self.rule())
    }

    /// The expanded uncertainty a decision uses: 0 where none is stated.
    pub fn expanded_uncertainty(&self) -> f64 {
        self.uncertainty.as_ref().map_or(0.0, |u| u.expanded)
    }

    /// The acceptance zone the rule leaves of the limits (lower absent when
    /// one-sided): the limits shrunk by the rule's guard band.
    pub fn acceptance_limits(&self) -> Option<(Option<f64>, f64)> {
        let (lo, hi) = self.limits()?;
        let g = self.rule().guard(self.expanded_uncertainty());
        Some((self.lower_limit_applies().then_some(lo + g), hi - g))
    }

    /// The verdict by the row's rule (limits inclusive); `None` without a
    /// tolerance. A value that could not be measured fails.
    pub fn verdict(&self) -> Option<Verdict> {
        let (lo, hi) = self.limits()?;
        Some(match self.value.filter(|v| v.is_finite()) {
            Some(v) => self.rule().decide(v, self.lower_limit_applies().then_some(lo), hi, self.expanded_uncertainty()),
            None => Verdict::Fail,
        })
    }

    /// Whether 2U reaches the tolerance's width: no value can then be shown
    /// to conform (ISO 14253-1), whatever the rule.
    pub fn tolerance_below_uncertainty(&self) -> bool {
        let (Some((lo, hi)), Some(u)) = (self.limits(), self.uncertainty.as_ref()) else { return false };
        2.0 * u.expanded >= hi - lo
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeasurementTable {
    pub rows: Vec<MeasurementRow>,
}

impl MeasurementTable {
    pub fn push(&mut self, row: MeasurementRow) {
        self.rows.push(row);
    }

    /// The rule the toleranced rows are judged by (the first one's: an
    /// inspection gives all its rows the spec's); `None` without tolerances.
    pub fn decision_rule(&self) -> Option<DecisionRule> {
        self.rows.iter().find_map(MeasurementRow::applied_rule)
    }

    /// The names of the rules the toleranced rows were judged by, once each.
    pub fn rule_names(&self) -> Vec<String> {
        let names: std::collections::BTreeSet<String> =
            self.rows.iter().filter_map(MeasurementRow::applied_rule).map(|r| r.name()).collect();
        names.into_iter().collect()
    }

    /// The names of the rows with verdict `v`, quoted, for a part's reason.
    fn rows_judged(&self, v: Verdict) -> String {
        let names: Vec<String> =
            self.rows.iter().filter(|r| r.verdict() == Some(v)).map(|r| format!("'{}'", r.name)).collect();
        names.join(", ")
    }

    /// Fail if any toleranced row fails, else inconclusive if any is, else
    /// pass; `None` when nothing is toleranced.
    pub fn overall_verdict(&self) -> Option<Verdict> {
        let verdicts: Vec<Verdict> = self.rows.iter().filter_map(MeasurementRow::verdict).collect();
        if verdicts.is_empty() {
            None
        } else if verdicts.contains(&Verdict::Fail) {
            Some(Verdict::Fail)
        } else if verdicts.contains(&Verdict::Inconclusive) {
            Some(Verdict::Inconclusive)
        } else {
            Some(Verdict::Pass)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_follow_nominal_and_limits() {
        let step = |v: Option<f64>| {
            MeasurementRow::new("step", MeasurementKind::StepHeight, v, "um")
                .with_tolerance(Some(20.0), Some(Tolerance::symmetric(0.5)))
        };
        assert_eq!(step(Some(20.4)).verdict(), Some(Verdict::Pass));
        assert_eq!(step(Some(20.5)).verdict(), Some(Verdict::Pass), "limits are inclusive");
        assert_eq!(step(Some(19.4)).verdict(), Some(Verdict::Fail));
        assert_eq!(step(None).verdict(), Some(Verdict::Fail), "unmeasured never passes");
        // One-sided: flatness at most 3 um, no nominal.
        let flat = MeasurementRow::new("flat", MeasurementKind::FlatnessPeakToValley, Some(3.2), "um")
            .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 3.0 }));
        assert_eq!(flat.limits(), Some((0.0, 3.0)));
        assert_eq!(flat.verdict(), Some(Verdict::Fail));
        let free = MeasurementRow::new("tilt", MeasurementKind::PlaneTilt, Some(1.0), "deg");
        assert_eq!(free.verdict(), None);

        let mut table = MeasurementTable::default();
        table.push(free);
        assert_eq!(table.overall_verdict(), None);
        table.push(step(Some(20.1)));
        assert_eq!(table.overall_verdict(), Some(Verdict::Pass));
        table.push(flat);
        assert_eq!(table.overall_verdict(), Some(Verdict::Fail));
    }

    fn with_u(row: MeasurementRow, expanded: f64, rule: DecisionRule) -> MeasurementRow {
        use crate::analysis::uncertainty::{Contribution, UncertaintyMethod};
        let u =
            Uncertainty::from_budget(UncertaintyMethod::Propagation, vec![Contribution::new("noise", expanded / 2.0)]);
        row.with_uncertainty(Some(u)).with_decision_rule(rule)
    }

    #[test]
    fn iso_14253_1_decides_at_each_zone_edge() {
        // 20 ± 1 with U = 0.25: pass in [19.25, 20.75], fail outside
        // [18.75, 21.25], inconclusive between; every edge inclusive.
        let step = |v: f64| {
            with_u(
                MeasurementRow::new("step", MeasurementKind::StepHeight, Some(v), "um")
                    .with_tolerance(Some(20.0), Some(Tolerance::symmetric(1.0))),
                0.25,
                DecisionRule::Iso14253,
            )
        };
        for (v, expected) in [
            (20.0, Verdict::Pass),
            (19.25, Verdict::Pass),
            (20.75, Verdict::Pass),
            (19.2499, Verdict::Inconclusive),
            (20.7501, Verdict::Inconclusive),
            (19.0, Verdict::Inconclusive),
            (21.0, Verdict::Inconclusive),
            (18.75, Verdict::Inconclusive),
            (21.25, Verdict::Inconclusive),
            (18.7499, Verdict::Fail),
            (21.2501, Verdict::Fail),
        ] {
            assert_eq!(step(v).verdict(), Some(expected), "value {v}");
        }
        assert_eq!(step(20.0).acceptance_limits(), Some((Some(19.25), 20.75)));
        // One-sided flatness <= 3: the lower end 0 is not guarded, so a
        // near-zero flatness passes.
        let flat = |v: f64| {
            with_u(
                MeasurementRow::new("flat", MeasurementKind::FlatnessPeakToValley, Some(v), "um")
                    .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 3.0 })),
                0.5,
                DecisionRule::Iso14253,
            )
        };
        assert_eq!(flat(0.1).verdict(), Some(Verdict::Pass));
        assert_eq!(flat(2.5).verdict(), Some(Verdict::Pass));
        assert_eq!(flat(2.6).verdict(), Some(Verdict::Inconclusive));
        assert_eq!(flat(3.5).verdict(), Some(Verdict::Inconclusive));
        assert_eq!(flat(3.6).verdict(), Some(Verdict::Fail));
        assert_eq!(flat(1.0).acceptance_limits(), Some((None, 2.5)));
        // A step's lower limit 0 without a nominal is a real limit (steps can be negative).
        let step_min = with_u(
            MeasurementRow::new("s", MeasurementKind::StepHeight, Some(0.1), "um")
                .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 3.0 })),
            0.5,
            DecisionRule::Iso14253,
        );
        assert_eq!(step_min.verdict(), Some(Verdict::Inconclusive));
    }

    #[test]
    fn simple_and_guard_band_rules_never_leave_a_verdict_open() {
        let row = |v: f64, rule| {
            with_u(
                MeasurementRow::new("step", MeasurementKind::StepHeight, Some(v), "um")
                    .with_tolerance(Some(20.0), Some(Tolerance::symmetric(1.0))),
                0.4,
                rule,
            )
        };
        assert_eq!(row(20.99, DecisionRule::Simple).verdict(), Some(Verdict::Pass));
        assert_eq!(row(21.0, DecisionRule::Simple).verdict(), Some(Verdict::Pass));
        assert_eq!(row(21.01, DecisionRule::Simple).verdict(), Some(Verdict::Fail));
        // Guard band of half U: limits shrunk by 0.2.
        let half = DecisionRule::GuardBand { fraction: 0.5 };
        assert_eq!(row(20.8, half).verdict(), Some(Verdict::Pass));
        assert_eq!(row(19.2, half).verdict(), Some(Verdict::Pass));
        assert_eq!(row(20.81, half).verdict(), Some(Verdict::Fail));
        assert_eq!(row(19.19, half).verdict(), Some(Verdict::Fail));
        assert_eq!(row(20.0, half).acceptance_limits(), Some((Some(19.2), 20.8)));
        // Rules read back from their names; bad names say what is expected.
        for rule in [DecisionRule::Iso14253, DecisionRule::Simple, half] {
            assert_eq!(DecisionRule::parse(&rule.name()), Ok(rule));
            let json = serde_json::to_string(&rule).unwrap();
            assert_eq!(serde_json::from_str::<DecisionRule>(&json).unwrap(), rule);
        }
        assert!(DecisionRule::parse("lenient").unwrap_err().contains("iso-14253-1 (default), simple"));
        assert!(DecisionRule::parse("guard-band:-1").unwrap_err().contains("a number >= 0"));
    }

    #[test]
    fn a_part_is_inconclusive_only_when_nothing_failed() {
        let row = |name: &str, v: f64| {
            with_u(
                MeasurementRow::new(name, MeasurementKind::StepHeight, Some(v), "um")
                    .with_tolerance(Some(20.0), Some(Tolerance::symmetric(1.0))),
                0.4,
                DecisionRule::Iso14253,
            )
        };
        let mut table = MeasurementTable::default();
        table.push(row("a", 20.0));
        assert_eq!(PartVerdict::of_table(&table).0, PartVerdict::Pass);
        table.push(row("b", 20.9));
        let (verdict, reason) = PartVerdict::of_table(&table);
        assert_eq!(verdict, PartVerdict::Inconclusive);
        assert_eq!(reason.as_deref(), Some("within the uncertainty of a limit: 'b'"));
        table.push(row("c", 22.0));
        assert_eq!(PartVerdict::of_table(&table).0, PartVerdict::Fail);
        assert_eq!(PartVerdict::from_name("inconclusive"), Some(PartVerdict::Inconclusive));
        // 2U at least the width: flagged.
        assert!(!row("d", 20.0).tolerance_below_uncertainty());
        assert!(with_u(row("e", 20.0), 1.0, DecisionRule::Iso14253).tolerance_below_uncertainty());
        let wide_u = with_u(row("e", 20.0), 1.2, DecisionRule::Iso14253);
        assert!(wide_u.tolerance_below_uncertainty());
        assert_eq!(wide_u.verdict(), Some(Verdict::Inconclusive), "no value can pass");
    }

    #[test]
    fn tolerances_must_be_intervals() {
        for (lower, upper) in [(1.0, -1.0), (f64::NAN, 1.0), (0.0, f64::INFINITY)] {
            match (Tolerance { lower, upper }).validate("step A") {
                Err(AnalysisError::InvalidTolerance { name, lower: l, upper: u }) => {
                    assert_eq!(name, "step A");
                    assert!(l.to_bits() == lower.to_bits() && u.to_bits() == upper.to_bits());
                }
                other => panic!("{lower}..{upper}: {other:?}"),
            }
        }
        assert!(Tolerance::symmetric(-2.0).validate("x").is_ok());
    }
}
