//! `sheen analyze --record`: the run's result kept as an inspection record
//!. The part's files are written first, as without --record; the
//! record is then one transaction. A record that cannot be kept says so
//! ("record not kept: ...") and exits 1 whatever the tolerances said, since
//! a line must not believe a part is on file when it is not; the files stay.
//! A part whose input was read but could not be measured is recorded with
//! the verdict `error` and its reason.

use std::io::Write as _;
use std::process::ExitCode;

use anyhow::{Context as _, bail};

use std::sync::Arc;

use super::{Analysis, AnalyzeArgs, EXIT_TOLERANCE_FAILED, RunTrace, analyze_traced};
use crate::analysis::measurement_table::MeasurementTable;
use crate::io;
use crate::io::recipe_file::{LoadedRecipe, read_recipe};
use crate::io::report;
use crate::records::keep::{RecordMap, absolute, default_part_id, input_hash, keep};
use crate::records::{self, DbLocation, MeasurementRecord, PartRecord, PartVerdict};

pub(super) fn run_documented(args: &AnalyzeArgs) -> anyhow::Result<ExitCode> {
    inspect_and_record(args, &RecordOptions::default()).map(|inspected| inspected.code)
}

/// How `sheen watch` records parts beyond what `analyze --record` does.
#[derive(Default)]
pub struct RecordOptions<'a> {
    /// Every input that was read is a part: an unreadable manifest or a
    /// truncated image is recorded as the part's error, not the command's.
    pub every_input_is_a_part: bool,
    /// The input's hash, when the caller has computed it already.
    pub input_hash: Option<String>,
    /// The recipe `--recipe` names, when the caller has read it already.
    pub recipe: Option<Arc<LoadedRecipe>>,
    /// Called right before the record is kept: the watch measures the next
    /// part while one is written, and keeps records in arrival order.
    pub before_keep: Option<&'a (dyn Fn() + Sync)>,
    /// The record's time when the caller took the part [default: now]: the
    /// watch's parts are recorded in the order they were taken.
    pub time_utc: Option<chrono::DateTime<chrono::Utc>>,
    /// The measurements of the recipe's last measured part, asked for once
    /// the parts before this one are recorded (`before_keep`): a part that
    /// could not be measured is exported with these characteristics, each
    /// as an invalid value [default with --record: read from the records].
    pub exchange_template: Option<&'a (dyn Fn() -> Option<Vec<MeasurementRecord>> + Sync)>,
}

/// One part inspected: the exit code `analyze` gives, the record as kept (or
/// as it would have been), and where it was kept or why not.
pub struct Inspected {
    pub code: ExitCode,
    pub record: PartRecord,
    /// The record's row id, or why it was not kept; `None` without --record.
    pub kept: Option<Result<i64, String>>,
}

/// Inspects the part, writes its reports and records it (`--record`).
pub fn inspect_and_record(args: &AnalyzeArgs, options: &RecordOptions) -> anyhow::Result<Inspected> {
    // Where and under which recipe, checked before anything is measured.
    let location = match args.record {
        true => Some(DbLocation::from_option(args.db.as_deref())?),
        false => None,
    };
    let height_map_dir = match &location {
        Some(l) => Some(l.height_map_dir(args.records_dir.as_deref())?),
        None => None,
    };
    // A recipe file is read once, for its name and for the run.
    let loaded = match (&options.recipe, super::recipe_file(args)) {
        (Some(loaded), _) => Some(Arc::clone(loaded)),
        (None, Some(path)) => Some(Arc::new(read_recipe(path)?)),
        (None, None) => None,
    };
    let recipe = match recipe_name(args, loaded.as_deref()) {
        Ok(name) => name,
        // A report alone can do without a recipe; a record cannot.
        Err(_) if !args.record => "inline options".to_string(),
        Err(e) => return Err(e),
    };
    let time_utc = options.time_utc.unwrap_or_else(records::time::now_utc);

    let mut trace = RunTrace::default();
    let recipe_file = loaded.clone();
    let outcome = analyze_traced(args, &mut trace, loaded);
    let read = trace.input.clone().or_else(|| options.every_input_is_a_part.then(|| args.input.clone()).flatten());
    let Some(input) = read else {
        // Nothing was read: a usage error, not a part.
        return Err(outcome.err().unwrap_or_else(|| anyhow::anyhow!("no input was read")));
    };
    let (verdict, reason, analysis, code) = match outcome {
        Ok(a) => {
            let (verdict, reason, code) = part_verdict(&a.table);
            (verdict, reason, Some(a), code)
        }
        Err(e) if trace.measuring || options.every_input_is_a_part => {
            if !args.quiet {
                eprintln!("error: {}", crate::error_text::error_chain(&e));
            }
            (PartVerdict::Error, Some(crate::error_text::error_chain(&e)), None, ExitCode::FAILURE)
        }
        Err(e) => return Err(e),
    };
    let mut record = PartRecord {
        part_id: args.part.clone().unwrap_or_else(|| default_part_id(&input, trace.manifest.is_some())),
        recipe,
        time_utc,
        station: args.station.clone(),
        operator: args.operator.clone(),
        input_path: absolute(&input).display().to_string(),
        input_hash: options.input_hash.clone().or_else(|| input_hash(&input, trace.manifest.as_ref())),
        sheen_version: env!("CARGO_PKG_VERSION").to_string(),
        engine_parameters: trace.params.as_ref().and_then(|p| serde_json::to_string(p).ok()),
        verdict,
        reason,
        height_map_path: None,
        height_map_hash: None,
        inspection: trace.inspection.clone(),
        decision_rule: analysis.as_ref().and_then(|a| a.table.decision_rule()),
        exports: Vec::new(),
        measurements: analysis
            .as_ref()
            .map_or_else(Vec::new, |a| a.table.rows.iter().map(MeasurementRecord::from_row).collect()),
    };

    // Reports and exchange files first: one that cannot be written is the
    // command's failure, but the part is still recorded (noting the files
    // that were written).
    let mut code = code;
    if let Err(e) = write_reports(args, &record, analysis.as_ref()) {
        eprintln!("error: {}", crate::error_text::error_chain(&e));
        code = ExitCode::FAILURE;
    }
    let template = if record.verdict == PartVerdict::Error && (args.dfq.is_some() || args.qif.is_some()) {
        // The parts before this one are recorded first, so the last
        // measured one is known.
        if let Some(wait) = options.before_keep {
            wait();
        }
        options
            .exchange_template
            .and_then(|template| template())
            .or_else(|| location.as_ref().and_then(|l| last_measured(l, &record.recipe)))
    } else {
        None
    };
    let calibration = trace.manifest.as_ref().and_then(calibration_name);
    for e in write_exchange_files(
        args,
        &mut record,
        calibration.as_deref(),
        template.as_deref(),
        recipe_file.as_deref().map(|l| &l.recipe),
    ) {
        eprintln!("error: {}", crate::error_text::error_chain(&e));
        code = ExitCode::FAILURE;
    }
    let (Some(location), Some(height_map_dir)) = (location, height_map_dir) else {
        return Ok(Inspected { code, record, kept: None });
    };
    if let Some(wait) = options.before_keep {
        wait();
    }
    match keep(
        &location,
        &height_map_dir,
        &mut record,
        analysis.as_ref().map(|a| RecordMap::EncodedX3p { bytes: &a.x3p, written_to: Some(&a.x3p_path) }),
    ) {
        Ok(row_id) => {
            if !args.quiet {
                eprintln!(
                    "sheen: part '{}' ({}, {}) recorded in {} (record {row_id})",
                    record.part_id,
                    record.recipe,
                    record.verdict.name(),
                    location.display()
                );
            }
            Ok(Inspected { code, record, kept: Some(Ok(row_id)) })
        }
        Err(reason) => {
            eprintln!("record not kept: {reason}");
            Ok(Inspected { code: ExitCode::FAILURE, record, kept: Some(Err(reason.to_string())) })
        }
    }
}

/// `--report-html` and `--report-pdf` for the part, measured or not.
fn write_reports(args: &AnalyzeArgs, record: &PartRecord, analysis: Option<&Analysis>) -> anyhow::Result<()> {
    if args.report_html.is_none() && args.report_pdf.is_none() {
        return Ok(());
    }
    let empty = MeasurementTable::default();
    let report = record.report(
        analysis.map(|a| &a.map),
        analysis.map_or(&[], |a| a.regions.as_slice()),
        analysis.map_or(&[], |a| a.profiles.as_slice()),
        analysis.map_or(&empty, |a| &a.table),
    );
    // analyze_traced has already refused report paths that are inputs.
    if let Some(path) = &args.report_html {
        io::atomic::write_atomic(path, |w| report::html::write_html(w, &report))
            .with_context(|| "cannot write the HTML report")?;
    }
    if let Some(path) = &args.report_pdf {
        let bytes = report::pdf::pdf_bytes(&report)
            .map_err(|e| anyhow::anyhow!("cannot make the PDF report {}: {e}", path.display()))?;
        io::atomic::write_atomic(path, |w| w.write_all(&bytes)).with_context(|| "cannot write the PDF report")?;
    }
    Ok(())
}

/// `--dfq` and `--qif` for the part, measured or not; each file written is
/// noted in the record. Returns what could not be written.
fn write_exchange_files(
    args: &AnalyzeArgs,
    record: &mut PartRecord,
    calibration: Option<&str>,
    template: Option<&[MeasurementRecord]>,
    recipe: Option<&crate::analysis::recipe::Recipe>,
) -> Vec<anyhow::Error> {
    if args.dfq.is_none() && args.qif.is_none() {
        return Vec::new();
    }
    let mut part = record.exchange(calibration);
    // A recipe may describe the part type and the operation (K1002, K1086).
    if let Some(r) = recipe {
        (part.description, part.operation) = (r.description.clone(), r.operation.clone());
    }
    if let Some(template) = template {
        part.not_measured_like(template);
    }
    let mut errors = Vec::new();
    if let Some(path) = &args.dfq {
        match io::aqdef::write_dfq(path, std::slice::from_ref(&part)) {
            Ok(()) => record.exports.push(absolute(path).display().to_string()),
            Err(e) => errors.push(anyhow::Error::new(e).context("cannot write the AQDEF file")),
        }
    }
    if let Some(path) = &args.qif {
        match io::qif::write_qif(path, &part, env!("CARGO_PKG_VERSION")) {
            Ok(()) => record.exports.push(absolute(path).display().to_string()),
            Err(e) => errors.push(anyhow::Error::new(e).context("cannot write the QIF file")),
        }
    }
    errors
}

/// The rig's calibration as the gauge names it: the calibration file's
/// name, or that the manifest holds it.
fn calibration_name(manifest: &io::manifest::Manifest) -> Option<String> {
    match manifest.calibration.as_ref()? {
        io::manifest::CalibrationSource::File(path) => Some(
            std::path::Path::new(path).file_name().map_or_else(|| path.clone(), |n| n.to_string_lossy().into_owned()),
        ),
        io::manifest::CalibrationSource::Inline(_) => Some("inline in the manifest".into()),
    }
}

/// The measurements of the recipe's last measured part in the records, for
/// exporting a part that could not be measured; `None` when the records
/// cannot be read or hold none.
fn last_measured(location: &DbLocation, recipe: &str) -> Option<Vec<MeasurementRecord>> {
    let mut store = records::Store::open(location).ok()?;
    let filter = records::HistoryFilter { recipe: Some(recipe.to_string()), ..Default::default() };
    let parts = store.parts(&filter).ok()?;
    parts.into_iter().rev().map(|p| p.record.measurements).find(|m| !m.is_empty())
}

/// The part's verdict, why, and the exit code the run would have without
/// --record.
fn part_verdict(table: &MeasurementTable) -> (PartVerdict, Option<String>, ExitCode) {
    let (verdict, reason) = PartVerdict::of_table(table);
    let code = if verdict == PartVerdict::Fail { ExitCode::from(EXIT_TOLERANCE_FAILED) } else { ExitCode::SUCCESS };
    (verdict, reason, code)
}

/// `--recipe`, else the spec's or session's file stem. Inline options alone
/// have no name, and a history grouped under a made-up one would mix
/// different inspections, so they need --recipe.
fn recipe_name(args: &AnalyzeArgs, recipe_file: Option<&LoadedRecipe>) -> anyhow::Result<String> {
    if let Some(loaded) = recipe_file {
        return Ok(loaded.recipe.name.clone());
    }
    if let Some(r) = &args.recipe {
        if r.trim().is_empty() {
            bail!("--recipe: the recipe name is empty");
        }
        return Ok(r.clone());
    }
    match args.spec.as_ref().or(args.session.as_ref()).and_then(|p| p.file_stem()) {
        Some(stem) => Ok(stem.to_string_lossy().into_owned()),
        None => bail!(
            "--record needs a recipe name: give --spec or --session (its file stem is the recipe) or --recipe NAME"
        ),
    }
}
