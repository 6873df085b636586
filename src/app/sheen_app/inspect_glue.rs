//! The Inspect view's actions that need the app: exports name the data
//! source and protect its inputs, sessions store the manifest and the
//! parameters, and opening a session loads its data (unless it is already
//! on screen) with its parameters and inspection.

use std::path::PathBuf;

use super::SheenApp;
use crate::analysis::session::Session;
use crate::app::commands::Command;
use crate::app::run_data::DataSource;
use crate::app::state::fit_params_to;
use crate::app::views::inspect::{self, Export, ExportKind, InspectDoc, PartFacts, Payload};
use crate::app::views::{InspectRuntime, ViewKind};

/// Key of the Inspect view's display settings (colour map, range, hole
/// filling) in a session's `view`.
const DISPLAY_KEY: &str = "inspect_display";

impl SheenApp {
    /// The Inspect view's inspection, results and file jobs.
    pub fn inspect(&self) -> &InspectRuntime {
        &self.inspect
    }

    pub fn inspect_mut(&mut self) -> &mut InspectRuntime {
        &mut self.inspect
    }

    /// The History view's records.
    pub fn history(&self) -> &crate::app::views::HistoryRuntime {
        &self.history
    }

    pub fn history_mut(&mut self) -> &mut crate::app::views::HistoryRuntime {
        &mut self.history
    }

    /// The Line view's watch and the parts it reported.
    pub fn line(&self) -> &crate::app::views::LineRuntime {
        &self.line
    }

    pub fn line_mut(&mut self) -> &mut crate::app::views::LineRuntime {
        &mut self.line
    }

    /// What the data is, for file headers, and its manifest (whose inputs are protected).
    fn data_source(&self) -> (String, Option<PathBuf>) {
        if let Some(opened) = self.inspect.opened_map() {
            return (opened.path.display().to_string(), None);
        }
        match self.session.as_ref().map(|s| &s.source) {
            Some(DataSource::File(path)) => (path.display().to_string(), Some(path.clone())),
            Some(source @ DataSource::Simulated { .. }) => (format!("{} (simulated)", source.describe()), None),
            None => ("no data".into(), None),
        }
    }

    pub(super) fn inspect_export(&mut self, kind: ExportKind) {
        let (source, manifest) = self.data_source();
        let result = self.session.as_ref().and_then(|s| s.result.as_ref());
        let facts = kind.needs_part_facts().then(|| self.part_facts());
        match self.inspect.export_of(kind, result, &self.state.views.inspect, source, manifest, facts) {
            Ok(export) => {
                let repaint = self.repaint_handle();
                self.inspect.start_export(export, None, repaint);
            }
            Err(e) => self.show_error(format!("Cannot export {}: {e}.", kind.label())),
        }
    }

    /// The part on screen as the Record form describes it.
    fn part_facts(&self) -> PartFacts {
        let (source, manifest) = self.data_source();
        let inspection = Some(self.inspect.doc.spec().to_json());
        let params = serde_json::to_string(&self.state.params).ok();
        PartFacts::new(
            &self.inspect.part_id,
            &self.inspect.recipe,
            &self.state.views.inspect.record,
            manifest,
            source,
            params,
            inspection,
        )
    }

    /// Inspect > Record: the part on screen into the records database.
    pub(super) fn inspect_record(&mut self) {
        let location = match self.state.views.inspect.record.location() {
            Ok(l) => l,
            Err(e) => return self.show_error(format!("Not recorded: {e}.")),
        };
        let facts = self.part_facts();
        let repaint = self.repaint_handle();
        self.inspect.start_record(facts, location, repaint);
    }

    /// "Always record": each new result of a real measurement is recorded
    /// once its inspection is measured (the simulated demo is not a part,
    /// and a part opened from History for review is not measured anew).
    fn auto_record(&mut self) {
        if !self.state.views.inspect.record.always {
            return;
        }
        let Some(session) = &self.session else { return };
        if session.source.is_simulated() {
            return;
        }
        if let Some(review) = &mut self.inspect.reviewing {
            if review.holds(&session.source, session.measurement_generation) {
                return;
            }
            self.inspect.reviewing = None;
        }
        let Some(result) = &session.result else { return };
        let key = (result.generation, session.measurement_generation);
        if self.inspect.take_auto_record(key) {
            self.inspect_record();
        }
    }

    /// Opens a recorded part again: its manifest with the recorded engine
    /// parameters and inspection, as a session would.
    pub(super) fn open_record(&mut self, part: crate::records::StoredPart) {
        let r = &part.record;
        let manifest = PathBuf::from(&r.input_path);
        if !manifest.is_file() {
            return self.show_error(format!(
                "Part '{}' cannot be opened: its input {} is not there any more.",
                r.part_id, r.input_path
            ));
        }
        let params = match r.engine_parameters.as_deref().map(serde_json::from_str) {
            Some(Ok(p)) => p,
            Some(Err(e)) => {
                return self
                    .show_error(format!("Part '{}': its recorded engine parameters cannot be read: {e}.", r.part_id));
            }
            None => self.state.params.clone(),
        };
        let mut session = Session::new(&manifest, params);
        if let Some(text) = &r.inspection {
            match crate::analysis::inspection::InspectionSpec::from_json(text) {
                Ok(spec) => session.inspection = spec,
                Err(e) => {
                    self.log.warning(format!("Part '{}': its recorded inspection cannot be read ({e}).", r.part_id))
                }
            }
        }
        self.inspect.part_id = r.part_id.clone();
        self.inspect.recipe = r.recipe.clone();
        self.inspect.reviewing = Some(inspect::ReviewedPart::new(manifest.clone(), self.measurement_counter));
        self.log.info(format!(
            "Opening part '{}' recorded {} ({}).",
            r.part_id,
            crate::records::time::local_display(&r.time_utc),
            r.verdict.name()
        ));
        self.apply_session(session);
    }

    pub(super) fn save_session(&mut self, path: Option<PathBuf>) {
        let (source, manifest) = self.data_source();
        if self.session.is_none() {
            self.show_error("Cannot save a session: no data is loaded.".into());
            return;
        }
        // An empty manifest path stands for the simulated demo.
        let mut session = self.inspect.session(&manifest.clone().unwrap_or_default(), self.state.params.clone());
        if let (Some(view), Ok(display)) =
            (session.view.as_object_mut(), serde_json::to_value(&self.state.views.inspect))
        {
            view.insert(DISPLAY_KEY.into(), display);
        }
        let export =
            Export { kind: ExportKind::Session, payload: Payload::Session(Box::new(session)), source, manifest };
        let repaint = self.repaint_handle();
        self.inspect.start_export(export, path, repaint);
    }

    /// The session and the measured map as a line's recipe.
    pub(super) fn save_recipe(&mut self, path: Option<PathBuf>) {
        let (source, manifest) = self.data_source();
        if self.session.is_none() {
            self.show_error("Cannot save a recipe: no data is loaded.".into());
            return;
        }
        if self.inspect.opened_map().is_some() {
            self.show_error(
                "Cannot save a recipe from an opened height map: a recipe is made from a measurement with its \
                 engine parameters; close the map first."
                    .into(),
            );
            return;
        }
        let Some(map) = self.inspect.measured_map() else {
            self.show_error("Cannot save a recipe yet: the height map is still being measured.".into());
            return;
        };
        let session = self.inspect.session(&manifest.clone().unwrap_or_default(), self.state.params.clone());
        let payload = Payload::Recipe { session: Box::new(session), map };
        let export = Export { kind: ExportKind::Recipe, payload, source, manifest };
        let repaint = self.repaint_handle();
        self.inspect.start_export(export, path, repaint);
    }

    /// Collects the Inspect view's file jobs and messages; applies an opened session.
    pub(super) fn poll_inspect(&mut self) {
        self.inspect.poll_files();
        self.auto_record();
        for notice in self.inspect.take_notices() {
            if notice.is_error {
                self.show_error(notice.text);
            } else {
                self.log.info(notice.text);
            }
        }
        if let Some(path) = self.inspect.take_saved_session() {
            self.state.remember_file(&path);
        }
        if let Some((path, session)) = self.inspect.take_opened_session() {
            self.state.remember_file(&path);
            // The session names the recipe its parts are recorded under.
            self.inspect.recipe = session_recipe(&path);
            self.apply_session(session);
        }
    }

    fn apply_session(&mut self, session: Session) {
        let extras = inspect::extras_of(&session);
        let cursors = extras.as_ref().map_or([None, None], |e| e.cursors);
        self.inspect.load_doc(InspectDoc::from_spec(&session.inspection, extras.as_ref()), cursors);
        self.state.params = session.params.clone();
        if let Some(display) = session.view.get(DISPLAY_KEY).and_then(|v| serde_json::from_value(v.clone()).ok()) {
            self.state.views.inspect = display;
        }
        self.state.views.active = ViewKind::Inspect;
        let wanted = session.manifest;
        let on_screen = match self.session.as_ref().map(|s| &s.source) {
            Some(DataSource::File(path)) => {
                !wanted.as_os_str().is_empty()
                    && (path == &wanted
                        || path.canonicalize().ok().is_some_and(|p| Some(p) == wanted.canonicalize().ok()))
            }
            Some(DataSource::Simulated { .. }) => wanted.as_os_str().is_empty(),
            None => false,
        };
        if on_screen {
            if let Some(s) = &self.session {
                let measurement = std::sync::Arc::clone(&s.measurement);
                for note in fit_params_to(&mut self.state.params, &measurement) {
                    self.log.info(note);
                }
            }
            self.commands.push(Command::Run);
        } else if wanted.as_os_str().is_empty() {
            self.commands.push(Command::OpenDemo);
        } else {
            self.commands.push(Command::Open(wanted));
        }
    }
}

/// A session file's recipe name: its file name without `.sheen-session.json`
/// (or `.json`).
fn session_recipe(path: &std::path::Path) -> String {
    let name = path.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let lower = name.to_ascii_lowercase();
    for suffix in [".sheen-session.json", ".json"] {
        if lower.ends_with(suffix) {
            return name[..name.len() - suffix.len()].to_string();
        }
    }
    name
}
