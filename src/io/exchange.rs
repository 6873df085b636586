//! What Sheen hands a plant's quality system about one part, whatever the
//! format: the part's identity (part number, serial, time, station,
//! operator, gauge), its verdict and every measured value with its limits,
//! verdict, rule and uncertainty. The AQDEF ([`super::aqdef`]) and QIF
//! ([`super::qif`]) writers read only this, so the CLI, the watch, the
//! history and the app export the same part the same way.

use std::path::Path;

use chrono::{DateTime, Utc};
use sha2::Digest as _;

use crate::analysis::measurement_record::MeasurementRecord;
use crate::analysis::measurement_table::PartVerdict;

use super::IoError;

/// One part as the exchange formats describe it.
#[derive(Clone, Debug, PartialEq)]
pub struct ExchangePart {
    /// The part's serial (Sheen's part ID).
    pub part_id: String,
    /// The part number: the recipe's or the spec's name.
    pub part_number: String,
    pub description: Option<String>,
    /// The operation (production step) where the recipe names one.
    pub operation: Option<String>,
    pub time_utc: DateTime<Utc>,
    pub station: Option<String>,
    pub operator: Option<String>,
    /// The measuring system: Sheen, its version and the rig's calibration.
    pub gauge: String,
    pub verdict: PartVerdict,
    /// Why the part failed or could not be measured.
    pub reason: Option<String>,
    /// Every measured value; for a part that could not be measured, the
    /// values its recipe measures, each without a value
    /// ([`ExchangePart::not_measured_like`]), so the part is in the file.
    pub measurements: Vec<MeasurementRecord>,
}

impl ExchangePart {
    /// The gauge's description: Sheen's version and, where known, the
    /// calibration the part was measured with.
    pub fn gauge_name(sheen_version: &str, calibration: Option<&str>) -> String {
        match calibration {
            Some(c) => format!("Sheen {sheen_version} / {c}"),
            None => format!("Sheen {sheen_version}"),
        }
    }

    /// Gives a part that was not measured the characteristics of a measured
    /// part of its recipe, each without a value or verdict, so an exchange
    /// file shows the part as invalid values instead of leaving it out.
    pub fn not_measured_like(&mut self, template: &[MeasurementRecord]) {
        if !self.measurements.is_empty() {
            return;
        }
        self.measurements = template
            .iter()
            .map(|m| MeasurementRecord {
                value: None,
                verdict: None,
                uncertainty: None,
                note: self.reason.clone(),
                ..m.clone()
            })
            .collect();
    }

    /// A stable identity of this part's result (for QIF's QPIds): the same
    /// part, time and values give the same identity.
    pub fn digest(&self) -> [u8; 32] {
        let mut hasher = sha2::Sha256::new();
        for text in [self.part_id.as_str(), self.part_number.as_str(), &self.time_utc.to_rfc3339()] {
            hasher.update(text.as_bytes());
            hasher.update([0u8]);
        }
        for m in &self.measurements {
            hasher.update(m.name.as_bytes());
            hasher.update(m.value.unwrap_or(f64::NAN).to_le_bytes());
        }
        hasher.finalize().into()
    }
}

/// One characteristic's description for people: the row's name and, for
/// a texture parameter, the parameter.
pub fn characteristic_description(m: &MeasurementRecord) -> String {
    match &m.parameter {
        Some(p) if !m.name.ends_with(p.as_str()) => format!("{} {p}", m.name),
        _ => m.name.clone(),
    }
}

/// Writes an exchange file as one atomic replacement (a temporary file
/// renamed over the name), so a collector polling the folder never reads
/// half a file; a folder that cannot be written is an error naming it.
pub fn write_exchange_file(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    use std::io::Write as _;
    super::atomic::write_atomic(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part() -> ExchangePart {
        ExchangePart {
            part_id: "p1".into(),
            part_number: "gasket".into(),
            description: None,
            operation: None,
            time_utc: DateTime::from_timestamp(1_800_000_000, 0).unwrap(),
            station: None,
            operator: None,
            gauge: ExchangePart::gauge_name("1.0", None),
            verdict: PartVerdict::Error,
            reason: Some("image 3 is truncated".into()),
            measurements: Vec::new(),
        }
    }

    #[test]
    fn a_part_not_measured_takes_its_recipe_characteristics_without_values() {
        let mut template = MeasurementRecord::bare("step", "step_height", 12.0, "um");
        template.upper_limit = Some(13.0);
        template.lower_limit = Some(11.0);
        let mut p = part();
        p.not_measured_like(std::slice::from_ref(&template));
        assert_eq!(p.measurements.len(), 1);
        let m = &p.measurements[0];
        assert_eq!((m.value, m.verdict, m.upper_limit, m.lower_limit), (None, None, Some(13.0), Some(11.0)));
        assert_eq!(m.note.as_deref(), Some("image 3 is truncated"));
        // A measured part keeps its own values.
        let mut measured = part();
        measured.measurements = vec![MeasurementRecord::bare("step", "step_height", 12.5, "um")];
        measured.not_measured_like(&[template]);
        assert_eq!(measured.measurements[0].value, Some(12.5));
    }

    #[test]
    fn the_digest_follows_the_part_and_its_values() {
        let a = part();
        let mut b = part();
        assert_eq!(a.digest(), b.digest());
        b.measurements.push(MeasurementRecord::bare("step", "step_height", 12.0, "um"));
        assert_ne!(a.digest(), b.digest());
    }
}
