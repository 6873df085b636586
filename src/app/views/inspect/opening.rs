//! The Inspect view's files read in: sessions, recipes to follow and other
//! instruments' height maps, each on a job, and the outcome of every file
//! job (exports included) collected once a frame.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::files::{self, ExportKind};
use super::{FileOutcome, InspectRuntime, MapShows, Notice, OpenedMap, describe_manifest, follow};
use crate::analysis::height_map::Rasterized;
use crate::app::jobs::{Job, JobOutcome};
use crate::app::widgets::map_view::ViewTransform;

impl InspectRuntime {
    /// Collects finished file jobs (called every frame by the app, whatever view is shown).
    pub fn poll_files(&mut self) {
        self.poll_record();
        let Some((label, job)) = &self.file_job else { return };
        let Some(outcome) = job.poll() else { return };
        let label = label.clone();
        self.file_job = None;
        match outcome {
            JobOutcome::Done(Ok(FileOutcome::Written { kind, paths })) => {
                if kind == ExportKind::Session {
                    self.saved_session = paths.first().cloned();
                }
                let list = paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
                self.notify(format!("{} written: {list}", kind.label()), false);
            }
            JobOutcome::Done(Ok(FileOutcome::Cancelled)) | JobOutcome::Cancelled => {
                self.status = Some(Notice { text: format!("{label}: cancelled."), is_error: false });
            }
            JobOutcome::Done(Ok(FileOutcome::HeightMap(mut opened))) => {
                self.opened_maps += 1;
                opened.generation = self.opened_maps;
                let m = &opened.raster.map;
                self.notify(
                    format!(
                        "Height map {} opened: {} {}x{} nodes at {:.4} mm{}. Inspect only; Close map returns to the \
                         measurement.",
                        opened.path.display(),
                        opened.format.name(),
                        m.width,
                        m.height,
                        m.pitch_mm,
                        opened.writer.as_ref().map_or_else(String::new, |w| format!(", written by {w}"))
                    ),
                    false,
                );
                for w in &opened.warnings {
                    self.notify(format!("{}: {w}", opened.path.display()), false);
                }
                self.analysis.clear();
                self.transform = ViewTransform::default();
                self.opened_map = Some(*opened);
            }
            JobOutcome::Done(Ok(FileOutcome::Recipe(path, loaded))) => {
                self.followed_recipes += 1;
                let followed = follow::FollowedRecipe::new(path, *loaded, self.followed_recipes);
                self.notify(
                    format!(
                        "Following recipe '{}' ({}): each part is found on its reference and the recipe's inspection \
                         moves with it.",
                        followed.name(),
                        followed.path.display()
                    ),
                    false,
                );
                // Parts are recorded under the recipe's name.
                self.recipe = followed.name().to_string();
                self.followed = Some(Arc::new(followed));
                self.placed_key = None;
            }
            JobOutcome::Done(Ok(FileOutcome::Opened(path, session))) => {
                self.notify(
                    format!("Session {} opened (data: {}).", path.display(), describe_manifest(&session.manifest)),
                    false,
                );
                self.opened = Some((path, session));
            }
            JobOutcome::Done(Err(e)) => {
                self.notify(format!("{label} failed: {}", crate::error_text::error_chain(&e)), true)
            }
            JobOutcome::Failed(e) => {
                self.notify(format!("{label} failed: {}", crate::error_text::error_chain(&e)), true)
            }
            JobOutcome::Panicked(e) => self.notify(format!("{label} crashed: {e}"), true),
        }
    }

    pub fn file_job_running(&self) -> bool {
        self.file_job.is_some()
    }

    /// Opens a session file (asking for it when `path` is `None`) off the UI thread.
    pub fn start_open_session(&mut self, path: Option<PathBuf>, repaint: impl Fn() + Send + 'static) {
        self.start_reading(OpenedKind::Session, path, repaint, |path| {
            files::read_session(&path).map(|s| FileOutcome::Opened(path, Box::new(s)))
        });
    }

    /// Reads a recipe and its reference map off the UI thread; once read,
    /// every map the view measures is registered to the reference and the
    /// recipe's inspection is moved onto the part.
    pub fn start_follow_recipe(&mut self, path: Option<PathBuf>, repaint: impl Fn() + Send + 'static) {
        self.start_reading(OpenedKind::Recipe, path, repaint, |path| {
            crate::io::recipe_file::read_recipe(&path)
                .map(|loaded| FileOutcome::Recipe(path, Box::new(loaded)))
                .map_err(anyhow::Error::from)
        });
    }

    /// Reads a file of `kind` on a job: `path`, else the one the operator
    /// picks in a dialog, else (no dialog on this system) the one of the
    /// default name in the export folder.
    fn start_reading(
        &mut self,
        kind: OpenedKind,
        path: Option<PathBuf>,
        repaint: impl Fn() + Send + 'static,
        read: impl FnOnce(PathBuf) -> anyhow::Result<FileOutcome> + Send + 'static,
    ) {
        if self.file_job.is_some() {
            self.notify("A file is still being read or written; try again when it is done.".into(), true);
            return;
        }
        let folder = self.folder();
        let use_dialogs = self.use_dialogs;
        let label = kind.label();
        let job = Job::spawn(label, repaint, move |_| {
            let path = match path {
                Some(p) => p,
                None if use_dialogs => match kind.ask(&folder) {
                    files::Asked::Path(p) => p,
                    files::Asked::Cancelled => return Ok(Ok(FileOutcome::Cancelled)),
                    files::Asked::Unavailable => kind.default_file(&folder)?,
                },
                None => kind.default_file(&folder)?,
            };
            Ok(read(path))
        });
        self.file_job = Some((label.into(), job));
    }

    /// The recipe followed, if one is: its name and file.
    pub fn followed_recipe(&self) -> Option<(&str, &Path)> {
        self.followed.as_deref().map(|f| (f.name(), f.path.as_path()))
    }

    /// Measures the inspection as it is again, without a recipe.
    pub fn stop_following_recipe(&mut self) {
        if let Some(f) = self.followed.take() {
            self.placing.clear();
            self.placed_key = None;
            if self.map_shows == MapShows::DifferenceToReference {
                self.map_shows = MapShows::Heights;
            }
            self.notify(format!("Recipe '{}' no longer followed.", f.name()), false);
        }
    }

    /// Reads the height map at `path` off the UI thread; once read, the
    /// Inspect view measures it in place of the measurement's map. A TIFF
    /// takes its pixel size and height unit from `tiff`.
    pub fn start_open_height_map(
        &mut self,
        path: PathBuf,
        tiff: crate::io::height_map_file::TiffMapScale,
        repaint: impl Fn() + Send + 'static,
    ) {
        if self.file_job.is_some() {
            self.notify("A file is still being read or written; try again when it is done.".into(), true);
            return;
        }
        let job = Job::spawn("opening a height map", repaint, move |_| {
            let read = match crate::io::height_map_file::read_height_map_file(&path, &tiff) {
                Ok(read) => read,
                Err(e) => return Ok(Err(e.into())),
            };
            // Read as it is: every valid node is a point, nothing was triangulated.
            let stats =
                crate::analysis::height_map::RasterStats { points: read.map.valid_count(), ..Default::default() };
            Ok(Ok(FileOutcome::HeightMap(Box::new(OpenedMap {
                path,
                format: read.format,
                writer: read.writer,
                raster: Arc::new(Rasterized { map: read.map, stats }),
                warnings: read.warnings,
                generation: 0,
            }))))
        });
        self.file_job = Some(("Open height map".into(), job));
    }

    /// The height map opened from a file, if one is inspected.
    pub fn opened_map(&self) -> Option<&OpenedMap> {
        self.opened_map.as_ref()
    }

    /// Back to the measurement's own height map.
    pub fn close_opened_map(&mut self) {
        if self.opened_map.take().is_some() {
            self.analysis.clear();
            self.transform = ViewTransform::default();
        }
    }
}

/// The files the view reads through [`InspectRuntime::start_reading`].
#[derive(Clone, Copy, Debug)]
enum OpenedKind {
    Session,
    Recipe,
}

impl OpenedKind {
    fn label(self) -> &'static str {
        match self {
            OpenedKind::Session => "Open session",
            OpenedKind::Recipe => "Follow recipe",
        }
    }

    fn ask(self, folder: &Path) -> files::Asked {
        match self {
            OpenedKind::Session => files::ask_session_path(Some(folder)),
            OpenedKind::Recipe => files::ask_recipe_path(folder),
        }
    }

    /// Without a file dialog: the file of the default name in the export
    /// folder (where saving without a dialog puts it), or why there is none.
    fn default_file(self, folder: &Path) -> Result<PathBuf, crate::app::jobs::JobError> {
        let (kind, verb) = match self {
            OpenedKind::Session => (ExportKind::Session, "open"),
            OpenedKind::Recipe => (ExportKind::Recipe, "follow"),
        };
        let path = folder.join(kind.default_file_name());
        if path.is_file() {
            Ok(path)
        } else {
            Err(crate::app::jobs::JobError::Failed(anyhow::anyhow!(
                "no file dialog could be shown on this system (it needs xdg-desktop-portal or zenity), and there is \
                 no {} to {verb}; type its folder under Export > Folder",
                path.display()
            )))
        }
    }
}

/// A height map the Inspect view opens on its own (by extension: X3P, SDF,
/// TIFF), rather than a manifest.
pub fn is_height_map_file(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    matches!(ext.as_deref(), Some("x3p" | "sdf" | "tif" | "tiff"))
}

/// Whether `path` names a session file (what File > Open and drag and drop
/// hand to the session reader instead of the manifest loader).
pub fn is_session_file(path: &Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.to_ascii_lowercase().ends_with(".sheen-session.json"))
}
