//! Where the app keeps inspection records and who measures: set in the
//! Inspect view's Record form, read by the History view too, so it lives
//! beside the views rather than in one of them.

use crate::records::DbLocation;
use crate::records::location::LocationError;

/// The record settings of the Inspect view, persisted with its display
/// settings: where records go, who and where measures, and whether every
/// new result is recorded without asking.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RecordSettings {
    /// A SQLite file or a `postgres://` URL; empty = the default SQLite file.
    pub db: String,
    pub station: String,
    pub operator: String,
    /// Record each new result once its inspection is measured.
    pub always: bool,
}

impl RecordSettings {
    /// The store the settings name.
    pub fn location(&self) -> Result<DbLocation, LocationError> {
        let typed = self.db.trim();
        DbLocation::from_option((!typed.is_empty()).then_some(typed))
    }
}
