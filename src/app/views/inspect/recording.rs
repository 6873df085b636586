//! The Inspect view's recording room: whether the part on screen can be
//! recorded, the record job and its outcome, "always record".

use std::sync::Arc;

use super::record::PartFacts;
use super::{InspectRuntime, Unavailable, record};
use crate::app::jobs::{Job, JobOutcome};

impl InspectRuntime {
    /// Whether the inspection on screen is measured and current, so a record
    /// would keep what the operator sees.
    pub fn can_record(&self) -> Result<(), Unavailable<'_>> {
        if self.opened_map.is_some() {
            return Err(Unavailable::OpenedMapNotRecorded);
        }
        if !self.is_current() || self.analysis.is_running() {
            return Err(Unavailable::StillMeasuring);
        }
        if self.followed.is_some() {
            match self.placing.result() {
                _ if !self.placing.is_current() => return Err(Unavailable::StillMeasuring),
                Some(Err(_)) => return Err(Unavailable::PartNotFound),
                _ => {}
            }
        }
        let analysis = self.analysis.value().ok_or(Unavailable::HeightMapNotReady)?;
        analysis.report.as_ref().map(|_| ()).map_err(Unavailable::InspectionCannotRun)
    }

    /// Starts writing the record of the part on screen (off the UI thread).
    pub fn start_record(
        &mut self,
        facts: PartFacts,
        location: crate::records::DbLocation,
        repaint: impl Fn() + Send + 'static,
    ) {
        if self.record_job.is_some() {
            self.notify("A record is still being written; try again when it is done.".into(), true);
            return;
        }
        if let Err(e) = self.can_record() {
            self.notify(format!("Not recorded: {e}."), true);
            return;
        }
        let (Some(raster), Some(report)) = (self.raster.value(), self.report()) else { return };
        let request =
            record::RecordRequest { facts, table: report.table.clone(), map: Arc::new(raster.map.clone()), location };
        self.record_job = Some(Job::spawn("Record", repaint, move |_| Ok(record::write_record(&request))));
    }

    /// Collects a finished record job.
    pub(super) fn poll_record(&mut self) {
        let Some(job) = &self.record_job else { return };
        let Some(outcome) = job.poll() else { return };
        self.record_job = None;
        match outcome {
            JobOutcome::Done(Ok(line)) => {
                self.records_written += 1;
                self.notify(line, false);
            }
            JobOutcome::Done(Err(e)) => {
                self.notify(format!("Record failed: {}", crate::error_text::error_chain(&e)), true)
            }
            JobOutcome::Failed(e) => {
                self.notify(format!("Record failed: {}", crate::error_text::error_chain(&e)), true)
            }
            JobOutcome::Cancelled => {}
            JobOutcome::Panicked(e) => self.notify(format!("Record crashed: {e}"), true),
        }
    }

    pub fn record_job_running(&self) -> bool {
        self.record_job.is_some()
    }

    /// How many records this session has written (the History view reloads
    /// when it changes).
    pub fn records_written(&self) -> u64 {
        self.records_written
    }

    /// With "always record": whether the result `key` (result and
    /// measurement generation) is measured and not yet recorded; marks it
    /// recorded when it is.
    pub fn take_auto_record(&mut self, key: (u64, u64)) -> bool {
        if self.auto_recorded == Some(key) || self.record_job.is_some() || self.can_record().is_err() {
            return false;
        }
        self.auto_recorded = Some(key);
        true
    }
}
