//! The Inspect view's inspection records and reports: what the
//! Record button keeps and what Export > Report prints, built from what is on
//! screen. No GUI types: the view gathers a [`PartFacts`], a job thread
//! hashes the input and writes (the hash reads every image, which must not
//! stall a frame).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::analysis::height_map::HeightMap;
use crate::analysis::measurement_table::MeasurementTable;
use crate::analysis::profile::Profile;
use crate::analysis::region::NamedRegion;
pub use crate::app::record_settings::RecordSettings;
use crate::io::report;
use crate::records::keep::{RecordMap, absolute, default_part_id, input_hash, keep};
use crate::records::{self, DbLocation, MeasurementRecord, PartRecord, PartVerdict};
use anyhow::Context as _;

fn non_empty(text: &str) -> Option<String> {
    let t = text.trim();
    (!t.is_empty()).then(|| t.to_string())
}

/// Who, what and where of the part on screen, gathered on the UI thread.
#[derive(Clone, Debug)]
pub struct PartFacts {
    pub part_id: String,
    pub recipe: String,
    pub station: Option<String>,
    pub operator: Option<String>,
    /// The measurement's manifest; `None` for the simulated demo.
    pub manifest: Option<PathBuf>,
    /// What the data is when there is no manifest ("the simulated demo").
    pub source: String,
    pub engine_parameters: Option<String>,
    pub inspection: Option<String>,
    pub time_utc: chrono::DateTime<chrono::Utc>,
}

impl PartFacts {
    pub fn new(
        part_id: &str,
        recipe: &str,
        settings: &RecordSettings,
        manifest: Option<PathBuf>,
        source: String,
        engine_parameters: Option<String>,
        inspection: Option<String>,
    ) -> Self {
        let part_id = non_empty(part_id).unwrap_or_else(|| default_part_for(manifest.as_deref()));
        Self {
            part_id,
            recipe: non_empty(recipe).unwrap_or_else(|| "session".into()),
            station: non_empty(&settings.station),
            operator: non_empty(&settings.operator),
            manifest,
            source,
            engine_parameters,
            inspection,
            time_utc: records::time::now_utc(),
        }
    }

    fn input_path(&self) -> String {
        self.manifest.as_deref().map_or_else(|| self.source.clone(), |m| absolute(m).display().to_string())
    }

    /// The manifest with every file it names; `None` for the demo or when a
    /// file can no longer be read.
    fn input_hash(&self) -> Option<String> {
        let manifest = self.manifest.as_deref()?;
        let m = crate::io::manifest::read_manifest(manifest).ok()?;
        input_hash(manifest, Some(&m))
    }

    /// The part as it is recorded, and as its report is headed.
    fn record(&self, table: &MeasurementTable) -> PartRecord {
        let (verdict, reason) = PartVerdict::of_table(table);
        PartRecord {
            part_id: self.part_id.clone(),
            recipe: self.recipe.clone(),
            time_utc: self.time_utc,
            station: self.station.clone(),
            operator: self.operator.clone(),
            input_path: self.input_path(),
            input_hash: self.input_hash(),
            sheen_version: env!("CARGO_PKG_VERSION").to_string(),
            engine_parameters: self.engine_parameters.clone(),
            verdict,
            reason,
            height_map_path: None,
            height_map_hash: None,
            inspection: self.inspection.clone(),
            decision_rule: table.decision_rule(),
            exports: Vec::new(),
            measurements: table.rows.iter().map(MeasurementRecord::from_row).collect(),
        }
    }
}

/// The part ID the Record form proposes: the manifest's folder name (a
/// folder per part), else "demo".
pub fn default_part_for(manifest: Option<&Path>) -> String {
    manifest.map_or_else(|| "demo".into(), |m| default_part_id(m, true))
}

/// What one Record press keeps.
pub struct RecordRequest {
    pub facts: PartFacts,
    pub table: MeasurementTable,
    /// The height map as measured (not levelled), stored as X3P.
    pub map: Arc<HeightMap>,
    pub location: DbLocation,
}

/// Writes the record (worker side); returns the line the operator reads.
pub fn write_record(request: &RecordRequest) -> anyhow::Result<String> {
    let mut record = request.facts.record(&request.table);
    let dir = request.location.height_map_dir(None)?;
    let row_id = keep(&request.location, &dir, &mut record, Some(RecordMap::Map(&request.map)))
        .context("the record was not kept")?;
    Ok(format!(
        "Part '{}' ({}, {}) recorded in {} (record {row_id}).",
        record.part_id,
        record.recipe,
        record.verdict.name(),
        request.location.display()
    ))
}

/// What Export > Report prints.
pub struct ReportPayload {
    pub facts: PartFacts,
    pub map: Arc<HeightMap>,
    pub regions: Vec<NamedRegion>,
    pub profiles: Vec<Profile>,
    pub table: MeasurementTable,
}

/// What an AQDEF or QIF export of the part on screen holds.
pub struct ExchangePayload {
    pub facts: PartFacts,
    pub table: MeasurementTable,
}

/// Writes the part as a Q-DAS AQDEF file (`dfq`) or a QIF 3.0 Results
/// document to `path` (worker side), from the record it would be kept as.
pub fn write_exchange(payload: &ExchangePayload, path: &Path, dfq: bool) -> anyhow::Result<()> {
    let part = payload.facts.record(&payload.table).exchange(None);
    if dfq {
        Ok(crate::io::aqdef::write_dfq(path, std::slice::from_ref(&part))?)
    } else {
        Ok(crate::io::qif::write_qif(path, &part, env!("CARGO_PKG_VERSION"))?)
    }
}

/// Writes the report as PDF (`pdf`) or HTML to `path` (worker side).
pub fn write_report(payload: &ReportPayload, path: &Path, pdf: bool) -> anyhow::Result<()> {
    // The time is the one the facts were gathered at, as a record of the
    // part would have it; the input is hashed as the record's would be.
    let record = payload.facts.record(&payload.table);
    let report = record.report(Some(&payload.map), &payload.regions, &payload.profiles, &payload.table);
    if pdf {
        let bytes = report::pdf::pdf_bytes(&report).map_err(anyhow::Error::msg).context("the PDF report")?;
        Ok(crate::io::atomic::write_atomic(path, |w| std::io::Write::write_all(w, &bytes))?)
    } else {
        Ok(crate::io::atomic::write_atomic(path, |w| report::html::write_html(w, &report))?)
    }
}
