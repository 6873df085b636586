//! The Inspect view's exports: what each export holds, built from what is
//! on screen, and the job that writes it where the operator says.

use std::path::PathBuf;
use std::sync::Arc;

use super::files::{self, Export, ExportKind, Payload};
use super::record::PartFacts;
use super::{FileOutcome, InspectRuntime, InspectView, Unavailable, plot, record};
use crate::app::jobs::Job;

impl InspectRuntime {
    pub(super) fn folder(&self) -> PathBuf {
        let typed = self.export_folder.trim();
        if typed.is_empty() {
            std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."))
        } else {
            PathBuf::from(typed)
        }
    }

    /// Writes `export` off the UI thread: to `path` if given, else where the
    /// operator says (dialog), else (no dialog available, or dialogs off)
    /// to the export folder under the default name.
    pub fn start_export(&mut self, export: Export, path: Option<PathBuf>, repaint: impl Fn() + Send + 'static) {
        if self.file_job.is_some() {
            self.notify("Another export is still being written; try again when it is done.".into(), true);
            return;
        }
        let kind = export.kind;
        let folder = self.folder();
        let use_dialogs = self.use_dialogs;
        let label = format!("Export {}", kind.label());
        let job = Job::spawn(label.clone(), repaint, move |_| {
            let fallback = folder.join(kind.default_file_name());
            let target = match path {
                Some(p) => p,
                None if use_dialogs => match files::ask_path(kind, &folder) {
                    files::Asked::Path(p) => p,
                    files::Asked::Cancelled => return Ok(Ok(FileOutcome::Cancelled)),
                    files::Asked::Unavailable => fallback,
                },
                None => fallback,
            };
            Ok(files::write_export(&export, &target).map(|paths| FileOutcome::Written { kind, paths }))
        });
        self.file_job = Some((label, job));
    }

    /// The export of `kind` built from what is on screen, or why there is none.
    pub fn export_of(
        &self,
        kind: ExportKind,
        result: Option<&crate::app::run_data::ResultSet>,
        settings: &InspectView,
        source: String,
        manifest: Option<PathBuf>,
        facts: Option<PartFacts>,
    ) -> Result<Export, Unavailable<'_>> {
        let analysis = self.analysis.value().ok_or(Unavailable::HeightMapNotReady)?;
        let payload = match kind {
            ExportKind::ProfilesCsv => Payload::Profiles(self.profiles().to_vec()),
            ExportKind::ProfilePlotPng => {
                Payload::Plot { series: plot::series(&self.doc, self.profiles()), cursors: self.cursors }
            }
            ExportKind::MeasurementsCsv => {
                Payload::Table(analysis.report.as_ref().map_err(Unavailable::InspectionCannotRun)?.table.clone())
            }
            ExportKind::MapX3p | ExportKind::MapTiff => {
                Payload::Map { map: Arc::clone(&analysis.map), levelled: analysis.levelling.is_some() }
            }
            ExportKind::MapPng => Payload::MapPng {
                map: Arc::clone(&analysis.map),
                display_um: Arc::new(analysis.display_um.clone()),
                colormap: settings.colormap,
                range_um: settings.range.resolve(analysis.range_um),
            },
            ExportKind::CloudPly if self.opened_map.is_some() => return Err(Unavailable::NoCloudOfMap),
            ExportKind::CloudPly => Payload::Cloud(Arc::clone(&result.ok_or(Unavailable::NoResult)?.reconstruction)),
            ExportKind::ReportPdf | ExportKind::ReportHtml => {
                let report = analysis.report.as_ref().map_err(Unavailable::InspectionCannotRun)?;
                Payload::Report(Box::new(record::ReportPayload {
                    facts: facts.ok_or(Unavailable::NoPartDetails)?,
                    map: Arc::clone(&analysis.map),
                    regions: self.doc.spec().regions,
                    profiles: report.profiles.clone(),
                    table: report.table.clone(),
                }))
            }
            ExportKind::Dfq | ExportKind::Qif => {
                let report = analysis.report.as_ref().map_err(Unavailable::InspectionCannotRun)?;
                Payload::Exchange(Box::new(record::ExchangePayload {
                    facts: facts.ok_or(Unavailable::NoPartDetails)?,
                    table: report.table.clone(),
                }))
            }
            ExportKind::Session | ExportKind::Recipe => return Err(Unavailable::SessionFromFileMenu),
        };
        Ok(Export { kind, payload, source, manifest })
    }
}
