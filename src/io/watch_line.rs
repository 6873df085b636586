//! One line of `sheen watch --json`: a part, how it went and its values.
//!
//! The watch writes it and the app's Line view reads it through this one
//! type, so the two cannot drift: each value carries its kind (the view
//! leaves the alignment rows out by kind, not by name) and the verdicts are
//! the records' own types. The keys are those scripts already read
//! (`part`, `folder`, `verdict` or `skipped`, `measurements`).

use serde::{Deserialize, Serialize};

use crate::analysis::measurement_table::{MeasurementKind, PartVerdict, Verdict};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WatchLine {
    /// The part's ID (the recipe's pattern on the folder name, or the name).
    pub part: String,
    /// The part's folder in the inbox, which names its results folder.
    pub folder: String,
    #[serde(flatten)]
    pub outcome: WatchOutcome,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum WatchOutcome {
    /// The watch decided not to measure the part.
    Skipped {
        skipped: SkipReason,
    },
    Measured(MeasuredPart),
}

/// Why a part was not measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SkipReason {
    /// Its inputs' content hash is on record under the recipe.
    #[serde(rename = "already recorded")]
    AlreadyRecorded,
}

/// A part the watch measured (or tried to: an error part has a verdict too).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeasuredPart {
    pub verdict: PartVerdict,
    /// Why: the failed rows, "no toleranced measurement", or the error.
    pub reason: Option<String>,
    /// Seconds from taking the part to its record.
    pub seconds: f64,
    /// Whether the record was kept.
    pub recorded: bool,
    /// Why it was not, when it was not.
    pub record_error: Option<String>,
    /// The rule the toleranced values were judged by (`iso-14253-1`, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decision_rule: Option<String>,
    pub measurements: Vec<WatchValue>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WatchValue {
    pub name: String,
    pub kind: MeasurementKind,
    pub value: Option<f64>,
    pub unit: String,
    pub verdict: Option<Verdict>,
    pub lower_limit: Option<f64>,
    pub upper_limit: Option<f64>,
    /// The value's expanded uncertainty U (k = 2), where stated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expanded_uncertainty: Option<f64>,
}

impl WatchLine {
    /// The measured part; `None` for a skipped one.
    pub fn measured(&self) -> Option<&MeasuredPart> {
        match &self.outcome {
            WatchOutcome::Measured(m) => Some(m),
            WatchOutcome::Skipped { .. } => None,
        }
    }

    /// The part's verdict; `None` for a skipped part.
    pub fn verdict(&self) -> Option<PartVerdict> {
        self.measured().map(|m| m.verdict)
    }

    /// One line of JSON, as the watch prints it.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }

    pub fn from_json(line: &str) -> Result<WatchLine, serde_json::Error> {
        serde_json::from_str(line)
    }
}

impl MeasuredPart {
    /// The values a line follows: toleranced, and not where the part was found.
    pub fn toleranced(&self) -> impl Iterator<Item = &WatchValue> {
        self.measurements.iter().filter(|m| m.verdict.is_some() && m.kind != MeasurementKind::Alignment)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measured() -> WatchLine {
        WatchLine {
            part: "SN-17".into(),
            folder: "part SN-17".into(),
            outcome: WatchOutcome::Measured(MeasuredPart {
                verdict: PartVerdict::Fail,
                reason: Some("out of tolerance: 'step 200'".into()),
                seconds: 1.234,
                recorded: true,
                record_error: None,
                decision_rule: Some("iso-14253-1".into()),
                measurements: vec![
                    WatchValue {
                        name: "alignment score".into(),
                        kind: MeasurementKind::Alignment,
                        value: Some(0.98),
                        unit: "".into(),
                        verdict: Some(Verdict::Pass),
                        lower_limit: Some(0.9),
                        upper_limit: None,
                        expanded_uncertainty: None,
                    },
                    WatchValue {
                        name: "step 200".into(),
                        kind: MeasurementKind::StepHeight,
                        value: Some(203.5),
                        unit: "um".into(),
                        verdict: Some(Verdict::Fail),
                        lower_limit: Some(199.0),
                        upper_limit: Some(201.0),
                        expanded_uncertainty: Some(0.12),
                    },
                    WatchValue {
                        name: "Sa".into(),
                        kind: MeasurementKind::Texture,
                        value: None,
                        unit: "um".into(),
                        verdict: None,
                        lower_limit: None,
                        upper_limit: None,
                        expanded_uncertainty: None,
                    },
                ],
            }),
        }
    }

    /// What the watch writes, the Line view reads back whole, skipped parts
    /// included; and the keys scripts read stay where they were.
    #[test]
    fn a_line_round_trips_through_the_readers_type() {
        for line in [
            measured(),
            WatchLine {
                part: "p".into(),
                folder: "p".into(),
                outcome: WatchOutcome::Skipped { skipped: SkipReason::AlreadyRecorded },
            },
        ] {
            let text = line.to_json();
            assert!(!text.contains('\n'), "one line: {text}");
            assert_eq!(WatchLine::from_json(&text).expect("parses"), line, "{text}");
        }
        let v: serde_json::Value = serde_json::from_str(&measured().to_json()).expect("json");
        assert_eq!(v["verdict"], "fail");
        assert_eq!(v["measurements"][1]["kind"], "step_height");
        assert_eq!(v["measurements"][1]["verdict"], "fail");
        let skipped: serde_json::Value = serde_json::from_str(
            &WatchLine {
                part: "p".into(),
                folder: "p".into(),
                outcome: WatchOutcome::Skipped { skipped: SkipReason::AlreadyRecorded },
            }
            .to_json(),
        )
        .expect("json");
        assert_eq!(skipped["skipped"], "already recorded");
        assert!(skipped.get("verdict").is_none());
    }

    /// The alignment rows are left out by their kind, whatever their name.
    #[test]
    fn the_followed_values_are_toleranced_and_not_alignment() {
        let line = measured();
        let names: Vec<&str> = line.measured().expect("measured").toleranced().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["step 200"]);
    }

    #[test]
    fn a_line_with_an_unknown_verdict_is_refused() {
        let text = measured().to_json().replace("\"verdict\":\"fail\",\"reason\"", "\"verdict\":\"maybe\",\"reason\"");
        assert!(WatchLine::from_json(&text).is_err(), "{text}");
    }
}
