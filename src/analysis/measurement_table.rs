//! The table of results an inspection produces: one row per measured value,
//! with its unit and, when a tolerance is given, a pass/fail verdict.
//!
//! A tolerance is a pair of deviations from the nominal value (`lower` is
//! usually negative); without a nominal the deviations are the limits
//! themselves, which suits one-sided quantities such as flatness
//! (`upper = 5 um`, `lower = 0`). A value that could not be measured fails
//! any tolerance: a production line must not pass a part it did not measure.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;

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
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Fail => "fail",
        }
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
}

impl PartVerdict {
    pub fn name(self) -> &'static str {
        match self {
            PartVerdict::Pass => "pass",
            PartVerdict::Fail => "fail",
            PartVerdict::Error => "error",
        }
    }

    /// The verdict of a measured part and why: failed rows named, or "no
    /// toleranced measurement" for a part measured without limits (a pass:
    /// nothing it was asked to meet failed).
    pub fn of_table(table: &MeasurementTable) -> (Self, Option<String>) {
        match table.overall_verdict() {
            Some(Verdict::Fail) => {
                let failed: Vec<String> = table
                    .rows
                    .iter()
                    .filter(|r| r.verdict() == Some(Verdict::Fail))
                    .map(|r| format!("'{}'", r.name))
                    .collect();
                (PartVerdict::Fail, Some(format!("out of tolerance: {}", failed.join(", "))))
            }
            Some(Verdict::Pass) => (PartVerdict::Pass, None),
            None => (PartVerdict::Pass, Some("no toleranced measurement".into())),
        }
    }

    pub fn from_name(text: &str) -> Option<Self> {
        match text {
            "pass" => Some(PartVerdict::Pass),
            "fail" => Some(PartVerdict::Fail),
            "error" => Some(PartVerdict::Error),
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

    /// Lowest and highest accepted value, when toleranced.
    pub fn limits(&self) -> Option<(f64, f64)> {
        let t = self.tolerance?;
        let nominal = self.nominal.unwrap_or(0.0);
        Some((nominal + t.lower, nominal + t.upper))
    }

    /// Pass/fail against the limits (inclusive); `None` without a tolerance.
    pub fn verdict(&self) -> Option<Verdict> {
        let (lo, hi) = self.limits()?;
        match self.value {
            Some(v) if v >= lo && v <= hi => Some(Verdict::Pass),
            _ => Some(Verdict::Fail),
        }
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

    /// Fail if any toleranced row fails, pass if all toleranced rows pass,
    /// `None` when nothing is toleranced.
    pub fn overall_verdict(&self) -> Option<Verdict> {
        let verdicts: Vec<Verdict> = self.rows.iter().filter_map(MeasurementRow::verdict).collect();
        if verdicts.is_empty() {
            None
        } else if verdicts.contains(&Verdict::Fail) {
            Some(Verdict::Fail)
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
