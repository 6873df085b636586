//! The Import dialog: a folder of another rig's fringe images
//! into a manifest, as `sheen import` does. The operator picks a folder and
//! types the pattern, periods, shifts and shift direction; the assignment
//! table (with a thumbnail of the first image of each set), the image
//! checks and the shift check follow live, each computed on a job thread
//! (a newer form cancels an older scan); "Write manifest and open" writes the
//! manifest atomically and opens it. Every error stays in the dialog.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

use eframe::egui::{self, RichText};

use crate::app::widgets::busy_line;
use crate::engine::control::RunControl;
use crate::engine::fringe::{Measurement, Samples};
use crate::engine::shift_estimate::{self, CameraShiftCheck, DEFAULT_TOLERANCE_RAD, PhaseDirection, Verdict};
use crate::io;
use crate::io::import::{self, Assignment, ImageFacts, ImportSpec, Thumbnail};

use super::commands::Command;
use super::jobs::{Job, JobError, JobOutcome};
use super::palette;

/// Seconds of quiet typing before a new scan starts.
const DEBOUNCE_S: f64 = 0.3;
/// Longest side of a thumbnail, in pixels.
const THUMBNAIL_SIDE: usize = 56;

/// Patterns offered in the pattern menu (empty: camera folders in natural order).
pub const EXAMPLE_PATTERNS: [(&str, &str); 5] = [
    ("", "camera folders, files in natural order"),
    ("{camera}/p{period}_{shift:02}.png", "Sheen's own naming"),
    ("{camera}/{index}.bmp", "numbered files per camera folder"),
    ("cam{camera}_{index}.bmp", "one folder, numbered per camera"),
    ("{camera}/set{set}_{shift}.tif", "set and shift numbers"),
];

/// What the operator typed.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct ImportForm {
    pub folder: String,
    pub pattern: String,
    pub periods: String,
    pub shifts: String,
    pub cameras: String,
    pub skip: String,
    pub calibration: String,
    pub bit_depth: String,
    /// The rig shifts the other way: `delta_k = offset - 2 pi k / N`.
    pub reversed: bool,
    pub offset_rad: String,
    /// Where the projector's phase grows in the camera image, if the operator
    /// knows: lets the shift check catch a direction reversed in every set.
    pub phase_grows: Option<PhaseDirection>,
    pub manifest_name: String,
}

impl Default for ImportForm {
    fn default() -> Self {
        Self {
            folder: String::new(),
            pattern: String::new(),
            periods: String::new(),
            shifts: String::new(),
            cameras: String::new(),
            skip: String::new(),
            calibration: String::new(),
            bit_depth: String::new(),
            reversed: false,
            offset_rad: "0".into(),
            phase_grows: None,
            manifest_name: io::dataset::MANIFEST_FILE.into(),
        }
    }
}

/// A field of the import form that does not describe an import.
#[derive(Debug, thiserror::Error)]
pub enum FormError {
    #[error("start '{0}' is not a number of radians")]
    Offset(String),
    #[error("bit depth '{0}' is not a number")]
    BitDepth(String),
    #[error("choose a folder")]
    NoFolder,
    #[error(transparent)]
    Field(#[from] import::ImportFault),
}

impl ImportForm {
    /// The import the form describes, or what is wrong with a field.
    pub fn spec(&self) -> Result<ImportSpec, FormError> {
        let offset: f64 = match self.offset_rad.trim() {
            "" => 0.0,
            t => t.parse().ok().filter(|x: &f64| x.is_finite()).ok_or_else(|| FormError::Offset(t.to_string()))?,
        };
        let bit_depth = match self.bit_depth.trim() {
            "" | "auto" => None,
            t => Some(t.parse::<u32>().map_err(|_| FormError::BitDepth(t.to_string()))?),
        };
        let folder = self.folder().ok_or(FormError::NoFolder)?;
        Ok(ImportSpec {
            periods_px: import::parse_list(&self.periods, "the periods")?,
            shifts: import::parse_list(&self.shifts, "the shifts")?,
            pattern: Some(self.pattern.trim().to_string()).filter(|p| !p.is_empty()),
            cameras: import::parse_cameras(&self.cameras)?,
            skip: self.skip.split(',').map(str::trim).filter(|s| !s.is_empty()).map(str::to_string).collect(),
            calibration: Some(self.calibration.trim()).filter(|c| !c.is_empty()).map(|c| {
                let p = PathBuf::from(c);
                if p.is_absolute() { p } else { folder.join(p) }
            }),
            bit_depth,
            shift_sign: if self.reversed { -1.0 } else { 1.0 },
            shift_offset_rad: offset,
            ..ImportSpec::default()
        })
    }

    pub fn folder(&self) -> Option<PathBuf> {
        let f = self.folder.trim();
        (!f.is_empty()).then(|| PathBuf::from(f))
    }

    /// Where the manifest goes: in the folder, under the given name.
    pub fn manifest_path(&self) -> Option<PathBuf> {
        let name = self.manifest_name.trim();
        let name = if name.is_empty() { io::dataset::MANIFEST_FILE } else { name };
        self.folder().map(|f| f.join(name))
    }

    fn key(&self) -> u64 {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        self.hash(&mut h);
        h.finish()
    }
}

/// What a scan found: the assignment, the image facts from the headers, and
/// a thumbnail of the first image of each camera and set.
pub struct ScanOutput {
    /// The manifest file already exists (writing replaces it).
    pub manifest_exists: bool,
    /// A `calibration.json` lies in the folder.
    pub calibration_beside: bool,
    pub assignment: Assignment,
    pub facts: ImageFacts,
    pub thumbnails: Vec<(String, usize, Thumbnail)>,
}

fn failed(e: impl Into<anyhow::Error>, control: &RunControl) -> JobError {
    if control.is_cancelled() { JobError::Cancelled } else { JobError::Failed(e.into()) }
}

fn scan(form: &ImportForm, control: &RunControl) -> Result<ScanOutput, JobError> {
    let spec = form.spec().map_err(|e| JobError::Failed(e.into()))?;
    let folder = form.folder().ok_or_else(|| JobError::Failed(FormError::NoFolder.into()))?;
    if !folder.is_dir() {
        return Err(JobError::Failed(anyhow::anyhow!("{} is not a folder", folder.display())));
    }
    control.begin_stage("listing files");
    let files = import::list_files(&folder).map_err(|e| failed(e, control))?;
    let assignment =
        import::assign(&files, &spec).map_err(|fault| failed(import::ImportError::new(&folder, fault), control))?;
    control.check()?;
    let facts = import::inspect_images(&folder, &assignment, &spec, false, control).map_err(|e| failed(e, control))?;
    control.begin_stage("thumbnails");
    let mut thumbnails = Vec::new();
    for camera in &assignment.cameras {
        for (s, set) in assignment.sets.iter().enumerate() {
            control.check()?;
            let first = &set.files[camera][0];
            let thumb = import::thumbnail(&folder.join(first), THUMBNAIL_SIDE).map_err(|e| failed(e, control))?;
            thumbnails.push((camera.clone(), s, thumb));
        }
    }
    let calibration_beside = files.iter().any(|f| f == io::dataset::CALIBRATION_FILE);
    let manifest_exists = form.manifest_path().is_some_and(|p| p.is_file());
    Ok(ScanOutput { manifest_exists, calibration_beside, assignment, facts, thumbnails })
}

/// Saturation level for the check: the bit depth's, or the one the samples
/// suggest for 16-bit files of unknown depth.
fn check_threshold(m: &Measurement, measured: bool) -> u16 {
    if measured || m.bit_depth <= 8 {
        return m.saturation_level;
    }
    let max = m
        .cameras
        .iter()
        .flat_map(|c| &c.stacks)
        .map(|s| match &s.samples {
            Samples::U8(v) => v.iter().copied().map(u16::from).max().unwrap_or(0),
            Samples::U16(v) => v.iter().copied().max().unwrap_or(0),
        })
        .max()
        .unwrap_or(0);
    let bits = io::images::bits_for_value(max).max(9);
    let depth = [10u32, 12, 14, 16].into_iter().find(|&d| d >= bits).unwrap_or(16);
    ((1u32 << depth) - 1) as u16
}

fn shift_check(
    form: &ImportForm,
    assignment: &Assignment,
    facts: &ImageFacts,
    control: &RunControl,
) -> Result<Vec<CameraShiftCheck>, JobError> {
    let spec = form.spec().map_err(|e| JobError::Failed(e.into()))?;
    let (Some(folder), Some(path)) = (form.folder(), form.manifest_path()) else {
        return Err(JobError::Failed(FormError::NoFolder.into()));
    };
    let manifest =
        import::build_manifest(&folder, &path, assignment, &spec, facts.bit_depth).map_err(|e| failed(e, control))?;
    control.begin_stage("loading images for the shift check");
    let loaded = io::manifest::load_manifest_measurement(&manifest, &path, control).map_err(|e| failed(e, control))?;
    control.begin_stage("estimating the phase shifts");
    let threshold = check_threshold(&loaded.measurement, spec.bit_depth.is_some());
    Ok(shift_estimate::check_measurement(&loaded.measurement, threshold, form.phase_grows, DEFAULT_TOLERANCE_RAD))
}

/// Everything `sheen import` does before writing, then the write.
fn write(form: &ImportForm, control: &RunControl) -> Result<PathBuf, JobError> {
    let spec = form.spec().map_err(|e| JobError::Failed(e.into()))?;
    let (Some(folder), Some(path)) = (form.folder(), form.manifest_path()) else {
        return Err(JobError::Failed(FormError::NoFolder.into()));
    };
    let files = import::list_files(&folder).map_err(|e| failed(e, control))?;
    let assignment =
        import::assign(&files, &spec).map_err(|fault| failed(import::ImportError::new(&folder, fault), control))?;
    let facts = import::inspect_images(&folder, &assignment, &spec, true, control).map_err(|e| failed(e, control))?;
    let manifest =
        import::build_manifest(&folder, &path, &assignment, &spec, facts.bit_depth).map_err(|e| failed(e, control))?;
    let inputs: Vec<PathBuf> = manifest.input_paths(&path).into_iter().skip(1).collect();
    io::atomic::refuse_overwriting_inputs(&path, &inputs).map_err(|e| failed(e, control))?;
    control.check()?;
    io::manifest::write_manifest(&path, &manifest).map_err(|e| failed(e, control))?;
    Ok(path)
}

/// The dialog: the form, and the jobs and results derived from it.
#[derive(Default)]
pub struct ImportDialog {
    pub open: bool,
    pub form: ImportForm,
    /// The form the current scan (or its result) is for.
    scanned_key: Option<u64>,
    /// When the form last changed without a scan for it (egui time).
    changed_at: Option<f64>,
    scan_job: Option<Job<ScanOutput>>,
    scan: Option<anyhow::Result<ScanOutput>>,
    check_job: Option<Job<Vec<CameraShiftCheck>>>,
    check: Option<anyhow::Result<Vec<CameraShiftCheck>>>,
    write_job: Option<Job<PathBuf>>,
    write_error: Option<String>,
    picker: Option<Job<Option<PathBuf>>>,
    thumbnails: HashMap<(String, usize), egui::TextureHandle>,
}

impl ImportDialog {
    /// Opens the dialog on `folder` (what the folder picker does; tests call it directly).
    pub fn open_with_folder(&mut self, folder: &Path) {
        self.open = true;
        self.form.folder = folder.display().to_string();
    }

    /// True while a scan, check, write or folder picker runs, or a scan is due.
    pub fn is_busy(&self) -> bool {
        self.scan_job.is_some()
            || self.check_job.is_some()
            || self.write_job.is_some()
            || self.picker.is_some()
            || (self.open && self.form.folder().is_some() && self.scanned_key != Some(self.form.key()))
    }

    pub fn assignment(&self) -> Option<&Assignment> {
        self.scan.as_ref()?.as_ref().ok().map(|s| &s.assignment)
    }

    /// The scan's error with its causes, if it failed.
    pub fn scan_error(&self) -> Option<String> {
        self.scan.as_ref()?.as_ref().err().map(crate::error_text::error_chain)
    }

    pub fn shift_check(&self) -> Option<&anyhow::Result<Vec<CameraShiftCheck>>> {
        self.check.as_ref()
    }

    pub fn write_error(&self) -> Option<&str> {
        self.write_error.as_deref()
    }

    pub fn thumbnail_count(&self) -> usize {
        self.thumbnails.len()
    }

    fn cancel_derived(&mut self) {
        if let Some(job) = self.scan_job.take() {
            job.cancel();
        }
        if let Some(job) = self.check_job.take() {
            job.cancel();
        }
    }

    fn start_scan(&mut self, ctx: &egui::Context) {
        self.cancel_derived();
        self.scan = None;
        self.check = None;
        self.write_error = None;
        self.thumbnails.clear();
        self.scanned_key = Some(self.form.key());
        if self.form.folder().is_none() {
            return;
        }
        let form = self.form.clone();
        let repaint = repaint_of(ctx);
        self.scan_job = Some(Job::spawn("import scan", repaint, move |control| scan(&form, control)));
    }

    fn poll(&mut self, ctx: &egui::Context, commands: &mut Vec<Command>) {
        if let Some(outcome) = self.picker.as_ref().and_then(Job::poll) {
            self.picker = None;
            if let JobOutcome::Done(Some(folder)) = outcome {
                self.form.folder = folder.display().to_string();
            }
        }
        if let Some(outcome) = self.scan_job.as_ref().and_then(Job::poll) {
            self.scan_job = None;
            match outcome {
                JobOutcome::Done(out) => {
                    for (camera, set, t) in &out.thumbnails {
                        let rgba: Vec<u8> = t.luma.iter().flat_map(|&v| [v, v, v, 255]).collect();
                        let image = egui::ColorImage::from_rgba_unmultiplied([t.width, t.height], &rgba);
                        let tex =
                            ctx.load_texture(format!("import {camera} {set}"), image, egui::TextureOptions::LINEAR);
                        self.thumbnails.insert((camera.clone(), *set), tex);
                    }
                    let (form, assignment, facts) = (self.form.clone(), out.assignment.clone(), out.facts.clone());
                    self.check_job = Some(Job::spawn("import shift check", repaint_of(ctx), move |control| {
                        shift_check(&form, &assignment, &facts, control)
                    }));
                    self.scan = Some(Ok(out));
                }
                JobOutcome::Failed(e) => self.scan = Some(Err(e)),
                JobOutcome::Panicked(e) => self.scan = Some(Err(anyhow::anyhow!("the scan crashed: {e}"))),
                JobOutcome::Cancelled => {}
            }
        }
        if let Some(outcome) = self.check_job.as_ref().and_then(Job::poll) {
            self.check_job = None;
            match outcome {
                JobOutcome::Done(c) => self.check = Some(Ok(c)),
                JobOutcome::Failed(e) => self.check = Some(Err(e)),
                JobOutcome::Panicked(e) => self.check = Some(Err(anyhow::anyhow!("the shift check crashed: {e}"))),
                JobOutcome::Cancelled => {}
            }
        }
        if let Some(outcome) = self.write_job.as_ref().and_then(Job::poll) {
            self.write_job = None;
            match outcome {
                JobOutcome::Done(path) => {
                    commands.push(Command::Open(path));
                    self.open = false;
                }
                JobOutcome::Failed(e) => {
                    self.write_error = Some(format!("Nothing was written: {}", crate::error_text::error_chain(&e)))
                }
                JobOutcome::Panicked(e) => {
                    self.write_error = Some(format!("Nothing was written: the import crashed ({e})"))
                }
                JobOutcome::Cancelled => {}
            }
        }
    }

    /// Polls the jobs, starts a due scan and draws the dialog when open.
    pub fn show(&mut self, ctx: &egui::Context, commands: &mut Vec<Command>) {
        self.poll(ctx, commands);
        if !self.open {
            return;
        }
        let key = self.form.key();
        if self.scanned_key != Some(key) {
            let now = ctx.input(|i| i.time);
            let since = *self.changed_at.get_or_insert(now);
            if now - since >= DEBOUNCE_S || self.scanned_key.is_none() {
                self.changed_at = None;
                self.start_scan(ctx);
            } else {
                ctx.request_repaint_after(std::time::Duration::from_secs_f64(DEBOUNCE_S));
            }
        }
        if self.is_busy() {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
        let mut open = self.open;
        egui::Window::new("Import a folder of fringe images")
            .id(egui::Id::unique("import dialog"))
            .open(&mut open)
            .default_pos([24.0, 32.0])
            .default_size([900.0, 780.0])
            .resizable(true)
            .collapsible(false)
            .show(ctx, |ui| self.contents(ui));
        self.open = open && self.open;
        if !self.open {
            self.cancel_derived();
        }
    }

    fn contents(&mut self, ui: &mut egui::Ui) {
        self.form_ui(ui);
        ui.separator();
        egui::ScrollArea::vertical()
            .id_salt("import scroll")
            .auto_shrink([false, false])
            .max_height((ui.available_height() - 40.0).max(200.0))
            .show(ui, |ui| {
                self.assignment_ui(ui);
                ui.add_space(6.0);
                self.check_ui(ui);
            });
        ui.separator();
        ui.horizontal(|ui| {
            let ready = matches!(self.scan, Some(Ok(_))) && self.write_job.is_none();
            let target = self.form.manifest_path().map(|p| p.display().to_string()).unwrap_or_default();
            if ui
                .add_enabled(ready, egui::Button::new(RichText::new("Write manifest and open").strong()))
                .on_hover_text(format!("Writes {target} (atomically; images are never touched) and opens it."))
                .clicked()
            {
                let form = self.form.clone();
                self.write_error = None;
                self.write_job = Some(Job::spawn("import write", repaint_of(ui.ctx()), move |c| write(&form, c)));
            }
            if self.write_job.is_some() {
                ui.spinner();
                ui.label("writing…");
            }
            if ui.button("Close").clicked() {
                self.open = false;
            }
            if let Some(Ok(out)) = &self.scan
                && out.manifest_exists
            {
                ui.colored_label(
                    palette::warning_text(ui.visuals()),
                    format!("replaces the existing {}", self.form.manifest_name.trim()),
                );
            }
            if let Some(e) = &self.write_error {
                ui.colored_label(palette::error_text(ui.visuals()), e);
            }
        });
    }

    fn form_ui(&mut self, ui: &mut egui::Ui) {
        let f = &mut self.form;
        egui::Grid::new("import form").num_columns(2).spacing([10.0, 4.0]).show(ui, |ui| {
            ui.label("Folder");
            ui.horizontal(|ui| {
                text_input(ui, &mut f.folder, "Import folder", "/path/to/images", 420.0);
                let picking = self.picker.is_some();
                if ui.add_enabled(!picking, egui::Button::new("Choose…")).clicked() {
                    let start = f.folder().filter(|p| p.is_dir());
                    self.picker = Some(Job::spawn("folder dialog", repaint_of(ui.ctx()), move |_| {
                        let mut d = rfd::FileDialog::new().set_title("Folder of fringe images");
                        if let Some(dir) = start {
                            d = d.set_directory(dir);
                        }
                        Ok(d.pick_folder())
                    }));
                }
            });
            ui.end_row();

            ui.label("Pattern");
            ui.horizontal(|ui| {
                text_input(ui, &mut f.pattern, "Import pattern", "empty: camera folders, natural order", 330.0);
                egui::ComboBox::from_id_salt("pattern examples")
                    .selected_text("examples")
                    .show_ui(ui, |ui| {
                        for (p, what) in EXAMPLE_PATTERNS {
                            let label = if p.is_empty() { what.to_string() } else { format!("{p}   ({what})") };
                            if ui.selectable_label(f.pattern == p, label).clicked() {
                                f.pattern = p.to_string();
                            }
                        }
                    })
                    .response
                    .on_hover_text(
                        "{camera}, {period}, {set}, {shift}, {index} (through all images of a camera, sparsest \
                         set first); {shift:02} means two digits.",
                    );
            });
            ui.end_row();

            ui.label("Periods");
            ui.horizontal(|ui| {
                text_input(ui, &mut f.periods, "Import periods", "912,144,24,12 (in the files' order)", 200.0);
                ui.label("Shifts");
                text_input(ui, &mut f.shifts, "Import shifts", "12, or 12,12,12,4", 130.0);
            })
            .response
            .on_hover_text("Both may stay empty when the pattern has {period} and {shift}: read from the names.");
            ui.end_row();
            ui.label("Shift δk");
            ui.horizontal(|ui| {
                ui.radio_value(&mut f.reversed, false, "+2πk/N");
                ui.radio_value(&mut f.reversed, true, "−2πk/N (reversed)");
                ui.label("start");
                text_input(ui, &mut f.offset_rad, "Import shift start (rad)", "0", 50.0);
                ui.label("rad");
                ui.separator();
                ui.label("Phase grows");
                let name = |d: Option<PhaseDirection>| match d {
                    None => "not known",
                    Some(PhaseDirection::Right) => "to the right",
                    Some(PhaseDirection::Left) => "to the left",
                    Some(PhaseDirection::Down) => "downwards",
                    Some(PhaseDirection::Up) => "upwards",
                };
                egui::ComboBox::from_id_salt("phase grows")
                    .selected_text(name(f.phase_grows))
                    .show_ui(ui, |ui| {
                        for d in [
                            None,
                            Some(PhaseDirection::Right),
                            Some(PhaseDirection::Left),
                            Some(PhaseDirection::Down),
                            Some(PhaseDirection::Up),
                        ] {
                            ui.selectable_value(&mut f.phase_grows, d, name(d));
                        }
                    })
                    .response
                    .on_hover_text(
                        "Where the projector's phase increases in the camera image, if you know it. The images \
                         alone cannot show a shift direction reversed in every set (it only mirrors the phase); \
                         with this the shift check catches it too.",
                    )
                    .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, "Phase grows"));
            });
            ui.end_row();
            ui.label("Cameras");
            ui.horizontal(|ui| {
                text_input(ui, &mut f.cameras, "Import cameras", "all found; or left=cam0,right=cam1", 200.0);
                ui.label("Skip");
                text_input(ui, &mut f.skip, "Import skip", "e.g. gray_*, *_dark.bmp", 130.0);
            });
            ui.end_row();
            ui.label("Bit depth");
            ui.horizontal(|ui| {
                text_input(ui, &mut f.bit_depth, "Import bit depth", "auto", 50.0);
                ui.label("Calibration");
                text_input(ui, &mut f.calibration, "Import calibration", "optional, in the folder", 150.0);
                ui.label("Manifest");
                text_input(ui, &mut f.manifest_name, "Import manifest name", io::dataset::MANIFEST_FILE, 120.0);
            });
            ui.end_row();
        });
    }

    fn assignment_ui(&self, ui: &mut egui::Ui) {
        ui.heading("Assignment");
        if self.scan_job.is_some() {
            busy_line(ui, "reading the folder…");
            return;
        }
        match &self.scan {
            None => {
                ui.weak("Choose a folder to see which file is which camera, set and shift.");
            }
            Some(Err(e)) => {
                ui.colored_label(palette::error_text(ui.visuals()), crate::error_text::error_chain(e));
            }
            Some(Ok(out)) => {
                let a = &out.assignment;
                let sizes: Vec<String> = out
                    .facts
                    .cameras
                    .iter()
                    .map(|c| format!("{} {}x{} px, {}-bit files", c.name, c.width, c.height, c.container_bits))
                    .collect();
                ui.label(format!(
                    "{} camera(s) × {} set(s), {} images · {}",
                    a.cameras.len(),
                    a.sets.len(),
                    a.image_count(),
                    sizes.join(" · ")
                ));
                if a.cameras.len() < 2 || self.form.calibration.trim().is_empty() {
                    ui.weak("Phase maps only: 3D needs two cameras (left and right) and a calibration.");
                    if a.cameras.len() >= 2 && out.calibration_beside {
                        ui.weak("calibration.json lies in the folder: enter it under Calibration for 3D.");
                    }
                }
                for note in a.notes.iter().chain(&out.facts.notes) {
                    ui.weak(note);
                }
                if !a.skipped.is_empty() {
                    ui.weak(format!("{} image(s) skipped, e.g. {}", a.skipped.len(), a.skipped[0]));
                }
                if let Some((f, why)) = a.ignored.first() {
                    ui.colored_label(
                        palette::warning_text(ui.visuals()),
                        format!("{} image(s) not used, e.g. {f}: {why}", a.ignored.len()),
                    );
                }
                egui::Grid::new("import assignment").striped(true).spacing([12.0, 4.0]).show(ui, |ui| {
                    ui.strong("set");
                    ui.strong("period");
                    ui.strong("shifts");
                    for camera in &a.cameras {
                        ui.strong(camera);
                        ui.strong("step: manifest / images")
                            .on_hover_text("The phase step the manifest will say, and the one the images show.");
                    }
                    ui.end_row();
                    for (s, set) in a.sets.iter().enumerate() {
                        ui.label(s.to_string());
                        ui.label(format!("{} px", io::maps::period_label(set.period_px)));
                        ui.label(set.shifts.to_string());
                        for camera in &a.cameras {
                            let files = &set.files[camera];
                            ui.horizontal(|ui| {
                                if let Some(tex) = self.thumbnails.get(&(camera.clone(), s)) {
                                    ui.image((tex.id(), tex.size_vec2()))
                                        .on_hover_text(format!("{} (first image of the set)", files[0]));
                                }
                                let last = files.last().map_or("", String::as_str);
                                ui.label(format!("{} … {last}", files[0]));
                            });
                            self.verdict_cell(ui, camera, s);
                        }
                        ui.end_row();
                    }
                });
            }
        }
    }

    /// "45.0° / 45.0° ok" for one camera and set, once the check has run.
    fn verdict_cell(&self, ui: &mut egui::Ui, camera: &str, set: usize) {
        let found = match &self.check {
            Some(Ok(checks)) => checks.iter().find(|c| c.camera == camera).and_then(|c| c.sets.get(set)),
            _ => None,
        };
        let Some(s) = found else {
            if self.check_job.is_some() {
                ui.spinner();
            } else {
                ui.weak("–");
            }
            return;
        };
        let colour = match s.verdict {
            Verdict::Agrees => ok_text(ui.visuals()),
            Verdict::Unknown(_) => ui.visuals().weak_text_color(),
            _ => palette::error_text(ui.visuals()),
        };
        ui.horizontal(|ui| {
            ui.label(format!("{} / {}", degrees(&s.manifest_steps_rad), degrees(&s.estimated_steps_rad)));
            ui.colored_label(colour, s.verdict.label());
        })
        .response
        .on_hover_text(&s.message);
    }

    fn check_ui(&self, ui: &mut egui::Ui) {
        if !matches!(self.scan, Some(Ok(_))) {
            return;
        }
        ui.heading("Shift check");
        ui.weak("Estimated from the images (bright, unsaturated pixels); per set in the table above.");
        if self.check_job.is_some() {
            busy_line(ui, "estimating the recorded phase shifts from the images…");
            return;
        }
        match &self.check {
            None => {}
            Some(Err(e)) => {
                ui.colored_label(palette::error_text(ui.visuals()), format!("Not checked: {e}"));
            }
            Some(Ok(checks)) => {
                let problems = checks.iter().filter(|c| c.has_problem()).count();
                if problems == 0 {
                    ui.label("The images' phase steps agree with the shifts the manifest will say.");
                } else {
                    ui.colored_label(
                        palette::error_text(ui.visuals()),
                        "The images' phase steps disagree with the manifest: check the order and the shift direction.",
                    );
                }
                for c in checks {
                    for s in c.sets.iter().filter(|s| s.verdict.is_problem()) {
                        ui.colored_label(
                            palette::error_text(ui.visuals()),
                            format!("{} set {}: {}", c.camera, s.set, s.message),
                        );
                    }
                }
            }
        }
    }
}

fn degrees(v: &[f64]) -> String {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min).to_degrees();
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max).to_degrees();
    if !lo.is_finite() {
        "–".into()
    } else if hi - lo < 0.05 {
        format!("{lo:.1}°")
    } else {
        format!("{lo:.1}° … {hi:.1}°")
    }
}

fn ok_text(visuals: &egui::Visuals) -> egui::Color32 {
    if visuals.dark_mode { egui::Color32::from_rgb(120, 210, 120) } else { egui::Color32::from_rgb(20, 120, 40) }
}

fn text_input(ui: &mut egui::Ui, text: &mut String, name: &'static str, hint: &str, width: f32) {
    ui.add(egui::TextEdit::singleline(text).hint_text(hint).desired_width(width))
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, name));
}

fn repaint_of(ctx: &egui::Context) -> impl Fn() + Send + 'static {
    let ctx = ctx.clone();
    move || ctx.request_repaint()
}
