//! A session: everything needed to reopen the same state in the GUI or rerun
//! it from the CLI — the manifest, the engine parameters and the analysis
//! setup (regions, profiles, measurements with tolerances, levelling), as
//! versioned JSON (`"sheen_session": 1`). Serde types only: io reads and
//! writes the file and resolves the manifest path relative to it.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::inspection::{InspectionSpec, check_version};
use crate::engine::pipeline::Params;

/// Format version written and read.
pub const SESSION_VERSION: u64 = 1;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Session {
    /// Format version, [`SESSION_VERSION`].
    pub sheen_session: u64,
    /// The measurement's manifest, as the caller stored it.
    pub manifest: PathBuf,
    /// Engine parameters of the run (method, thresholds, enabled sets).
    pub params: Params,
    /// Height-map parameters, levelling, regions, profiles, measurements.
    pub inspection: InspectionSpec,
    /// Front-end state the analysis does not interpret (the GUI keeps profile
    /// colours and view settings here); absent when null.
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub view: serde_json::Value,
}

impl Session {
    pub fn new(manifest: impl Into<PathBuf>, params: Params) -> Self {
        Self {
            sheen_session: SESSION_VERSION,
            manifest: manifest.into(),
            params,
            inspection: InspectionSpec::default(),
            view: serde_json::Value::Null,
        }
    }

    /// Parses a session, checking its version first and its analysis setup after.
    pub fn from_json(text: &str) -> Result<Self, AnalysisError> {
        const WHAT: &str = "session";
        check_version(text, WHAT, "sheen_session", SESSION_VERSION)?;
        let session: Self = serde_json::from_str(text).map_err(|source| AnalysisError::Json { what: WHAT, source })?;
        session.inspection.validate()?;
        Ok(session)
    }

    /// Pretty JSON, the form [`Session::from_json`] reads.
    pub fn to_json(&self) -> String {
        // Plain structs, strings, numbers and a JSON value always serialize.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::inspection::{Measure, MeasurementSpec};
    use crate::analysis::measurement_table::Tolerance;
    use crate::analysis::profile::{ProfileLine, ProfileSpec};
    use crate::analysis::region::{NamedRegion, Region};
    use crate::engine::pipeline::Method;

    fn session() -> Session {
        let mut s = Session::new(
            "../lot 7/manifest.json",
            Params { method: Method::Generalized, enabled_sets: vec![true, false, true], ..Params::default() },
        );
        s.inspection.height_map.pitch_mm = Some(0.0117);
        s.inspection.level_to = vec!["base".into()];
        s.inspection.regions = vec![
            NamedRegion::new("base", Region::Rectangle { x_mm: [0.0, 1.0], y_mm: [0.0, 1.0] }),
            NamedRegion::new("land", Region::Polygon { vertices_mm: vec![[2.0, 0.0], [3.0, 0.0], [2.5, 1.0]] }),
        ];
        s.inspection.profiles = vec![ProfileSpec {
            name: "B-B".into(),
            line: ProfileLine::Vertical { through_mm: [2.5, 0.0] },
            step_mm: Some(0.005),
            width_mm: 0.1,
            raw_samples: true,
        }];
        s.inspection.measurements = vec![MeasurementSpec {
            name: "land height".into(),
            measure: Measure::StepHeight { reference: vec!["base".into()], measured: vec!["land".into()] },
            nominal: Some(50.0),
            tolerance: Some(Tolerance::symmetric(1.0)),
        }];
        s.view = serde_json::json!({ "profile_colours": { "B-B": "#ff8800" } });
        s
    }

    #[test]
    fn a_session_reopens_identically() {
        let s = session();
        let text = s.to_json();
        assert!(text.contains("\"sheen_session\": 1"), "{text}");
        assert_eq!(Session::from_json(&text).unwrap(), s);
        // Without front-end state the field is left out and reads back as null.
        let bare = Session { view: serde_json::Value::Null, ..s };
        assert!(!bare.to_json().contains("\"view\""));
        assert_eq!(Session::from_json(&bare.to_json()).unwrap(), bare);
    }

    #[test]
    fn foreign_or_future_sessions_are_refused_with_a_reason() {
        let text = session().to_json();
        let newer = text.replace("\"sheen_session\": 1", "\"sheen_session\": 3");
        let e = Session::from_json(&newer).unwrap_err().to_string();
        assert!(e.contains("version 3") && e.contains("reads version 1"), "{e}");
        let e = Session::from_json("{\"manifest\": \"m.json\"}").unwrap_err().to_string();
        assert!(e.contains("'sheen_session'"), "{e}");
        let broken = text.replace("\"measured\": [\n", "\"measured\": [\n \"nowhere\",\n");
        let e = Session::from_json(&broken).unwrap_err().to_string();
        assert!(e.contains("nowhere"), "{e}");
    }
}
