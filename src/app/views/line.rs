//! The Line view: the production line from the app. It runs the same watch
//! as the command line (`sheen watch --json`, the app's own binary, as a
//! child process: one code path for both, and a crash of a part never
//! takes the app with it) and shows what a line operator looks at: the
//! last part's verdict in large type, its height map with the regions where
//! the recipe found them, the last 50 parts as a table and the trend of each
//! toleranced measurement. Stop closes the watch's standard input
//! (`--stop-on-stdin-close`, the same on every platform): the parts in hand
//! finish.
//!
//! A reader thread parses the watch's JSON lines and renders each part's
//! map (read back from its results folder) off the UI thread; a frame only
//! drains the channel and draws.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};

use eframe::egui::{self, Color32, RichText};
use egui_plot::{HLine, Line, Plot, PlotPoints, Points};

use crate::analysis::inspection::InspectionSpec;
use crate::analysis::measurement_table::{PartVerdict, Verdict};
use crate::app::palette;
use crate::app::record_settings::RecordSettings;
use crate::engine::length_unit::LengthUnit;
use crate::io::height_map_file::{TiffMapScale, read_height_map_file};
use crate::io::report::{headline, render_inspection_map};
use crate::io::watch_line::{WatchLine, WatchValue};

const PASS: Color32 = Color32::from_rgb(40, 160, 80);
const FAIL: Color32 = Color32::from_rgb(215, 50, 50);
const INCONCLUSIVE: Color32 = Color32::from_rgb(190, 150, 20);
const ERROR: Color32 = Color32::from_rgb(230, 140, 20);
/// Parts kept for the trends; the table shows the last [`TABLE_ROWS`].
const KEPT_PARTS: usize = 500;
const TABLE_ROWS: usize = 50;
/// Side of the rendered map, in pixels.
const MAP_SIDE_PX: u32 = 520;

/// The Line view's persisted choices.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LineView {
    /// The folder the acquisition software drops each part's folder into.
    pub inbox: String,
    /// The part type's recipe (`sheen recipe`, or Inspect > Save as recipe).
    pub recipe: String,
    /// Results folder (empty = INBOX.results beside the inbox).
    pub out: String,
    pub report_pdf: bool,
    /// Folder each part's Q-DAS AQDEF file goes to (empty: none).
    pub dfq_dir: String,
    /// Folder each part's QIF 3.0 Results file goes to (empty: none).
    pub qif_dir: String,
    /// Show the part less its aligned reference instead of its heights.
    pub show_difference: bool,
}

impl super::View for LineView {
    /// Drawn by [`show`]: it needs no measurement panes.
    fn panes<'a>(
        &self,
        _cx: &super::ViewCx<'a>,
        _cameras: &[usize],
        _commands: &mut Vec<super::Command>,
    ) -> Vec<super::Pane<'a>> {
        Vec::new()
    }
}

enum Event {
    /// A part, its map with the regions and its difference to the reference.
    Part(Box<WatchLine>, Option<egui::ColorImage>, Option<egui::ColorImage>),
    /// A line of the watch's stderr (start, backlog, errors).
    Message(String),
    /// The watch's output closed: it has ended.
    Exited,
}

struct Running {
    child: Child,
    /// The watch's standard input: closing it asks the watch to stop
    /// (`--stop-on-stdin-close`), the same on every platform.
    stdin: Option<std::process::ChildStdin>,
    events: Receiver<Event>,
    stopping: bool,
}

/// The running watch and what it reported.
pub struct LineRuntime {
    /// The `sheen` binary run as `sheen watch` (the app's own by default).
    pub program: PathBuf,
    running: Option<Running>,
    parts: VecDeque<WatchLine>,
    map: Option<(String, egui::TextureHandle)>,
    difference: Option<(String, egui::TextureHandle)>,
    /// The watch's last message, and whether it is an error.
    status: Option<(String, bool)>,
}

impl Default for LineRuntime {
    fn default() -> Self {
        Self {
            program: std::env::current_exe().unwrap_or_else(|_| PathBuf::from("sheen")),
            running: None,
            parts: VecDeque::new(),
            map: None,
            difference: None,
            status: None,
        }
    }
}

impl LineRuntime {
    pub fn is_running(&self) -> bool {
        self.running.is_some()
    }

    /// The parts reported so far, oldest first.
    pub fn parts(&self) -> &VecDeque<WatchLine> {
        &self.parts
    }

    /// The part whose map is shown.
    pub fn map_part(&self) -> Option<&str> {
        self.map.as_ref().map(|(p, _)| p.as_str())
    }

    /// The part whose difference to the reference is shown.
    pub fn difference_part(&self) -> Option<&str> {
        self.difference.as_ref().map(|(p, _)| p.as_str())
    }

    pub fn status(&self) -> Option<&(String, bool)> {
        self.status.as_ref()
    }

    /// Starts `sheen watch` on the view's inbox and recipe with the record settings.
    pub fn start(&mut self, view: &LineView, record: &RecordSettings) -> Result<(), String> {
        if self.running.is_some() {
            return Ok(());
        }
        let (inbox, recipe) = (view.inbox.trim(), view.recipe.trim());
        if inbox.is_empty() || recipe.is_empty() {
            return Err("choose the inbox folder and the recipe first".into());
        }
        let out = if view.out.trim().is_empty() {
            crate::io::paths::default_results_folder(Path::new(inbox))
        } else {
            PathBuf::from(view.out.trim())
        };
        let mut command = Command::new(&self.program);
        // The view shows every part's difference to the reference, so every
        // part's pictures are written (the command line's default writes them
        // for failed parts only).
        command
            .args([
                "watch",
                inbox,
                "--recipe",
                recipe,
                "--json",
                "--map-images",
                "always",
                "--stop-on-stdin-close",
                "--out",
            ])
            .arg(&out);
        for (option, value) in [("--db", &record.db), ("--station", &record.station), ("--operator", &record.operator)]
        {
            if !value.trim().is_empty() {
                command.args([option, value.trim()]);
            }
        }
        if view.report_pdf {
            command.arg("--report-pdf");
        }
        for (option, folder) in [("--dfq-dir", &view.dfq_dir), ("--qif-dir", &view.qif_dir)] {
            if !folder.trim().is_empty() {
                command.args([option, folder.trim()]);
            }
        }
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {} watch: {e}", self.program.display()))?;
        let (tx, events) = channel();
        if let Some(stderr) = child.stderr.take() {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                    let _ = tx.send(Event::Message(line));
                }
            });
        }
        if let Some(stdout) = child.stdout.take() {
            std::thread::spawn(move || read_parts(stdout, out, tx));
        }
        let stdin = child.stdin.take();
        self.running = Some(Running { child, stdin, events, stopping: false });
        self.status = Some(("starting the watch…".into(), false));
        Ok(())
    }

    /// Asks the watch to stop after the parts in hand, by closing its
    /// standard input.
    pub fn stop(&mut self) {
        let Some(running) = &mut self.running else { return };
        running.stopping = true;
        drop(running.stdin.take());
    }

    /// Takes what the watch reported since the last frame.
    pub fn poll(&mut self, ctx: &egui::Context) {
        let Some(running) = &mut self.running else { return };
        let mut exited = None;
        while let Ok(event) = running.events.try_recv() {
            match event {
                Event::Part(part, image, difference) => {
                    if let Some(image) = image {
                        let texture = ctx.load_texture("line-map", image, egui::TextureOptions::NEAREST);
                        self.map = Some((part.part.clone(), texture));
                    }
                    if let Some(image) = difference {
                        let texture = ctx.load_texture("line-difference", image, egui::TextureOptions::LINEAR);
                        self.difference = Some((part.part.clone(), texture));
                    }
                    self.parts.push_back(*part);
                    while self.parts.len() > KEPT_PARTS {
                        self.parts.pop_front();
                    }
                }
                Event::Message(line) => {
                    let line = line.strip_prefix("sheen: ").unwrap_or(&line).to_string();
                    let is_error = line.starts_with("error:");
                    self.status = Some((line, is_error));
                }
                Event::Exited => exited = Some(running.child.wait().ok().and_then(|s| s.code())),
            }
        }
        if let Some(code) = exited {
            let stopping = running.stopping;
            self.running = None;
            if code != Some(0) && !stopping {
                let text = self.status.take().map_or_else(|| format!("the watch ended ({code:?})"), |s| s.0);
                self.status = Some((text, true));
            } else if code == Some(0) {
                self.status = Some(("the watch stopped".into(), false));
            }
        }
        if self.running.is_some() {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
    }
}

impl Drop for LineRuntime {
    fn drop(&mut self) {
        self.stop();
        if let Some(running) = &mut self.running {
            let _ = running.child.wait();
        }
    }
}

/// The reader thread: one part per JSON line, its map rendered from the
/// part's results folder (as measured, with the moved regions).
fn read_parts(stdout: std::process::ChildStdout, out: PathBuf, tx: Sender<Event>) {
    for line in BufReader::new(stdout).lines().map_while(Result::ok) {
        let Ok(part) = WatchLine::from_json(&line) else { continue };
        let folder = out.join(&part.folder);
        let measured = part.measured().is_some();
        let image = measured.then(|| part_map(&folder)).flatten();
        let difference = measured.then(|| png_image(&folder.join("difference_to_reference.png"))).flatten();
        if tx.send(Event::Part(Box::new(part), image, difference)).is_err() {
            return;
        }
    }
    let _ = tx.send(Event::Exited);
}

/// The part's height map with its regions, as the report draws it; `None`
/// for a part that was not measured.
fn part_map(folder: &Path) -> Option<egui::ColorImage> {
    let map =
        read_height_map_file(&folder.join("height_map.x3p"), &TiffMapScale { pixel_mm: None, z_unit: LengthUnit::Um })
            .ok()?
            .map;
    let spec = std::fs::read_to_string(folder.join("inspection.json"))
        .ok()
        .and_then(|text| InspectionSpec::from_json(&text).ok())
        .unwrap_or_default();
    let (image, _) = render_inspection_map(&map, &spec.regions, &[], MAP_SIDE_PX);
    let size = [image.width() as usize, image.height() as usize];
    Some(egui::ColorImage::from_rgba_unmultiplied(size, image.as_raw()))
}

/// A PNG the watch wrote, as an egui image.
fn png_image(path: &Path) -> Option<egui::ColorImage> {
    let image = image::open(path).ok()?.to_rgba8();
    let size = [image.width() as usize, image.height() as usize];
    Some(egui::ColorImage::from_rgba_unmultiplied(size, image.as_raw()))
}

fn verdict_color(verdict: Option<PartVerdict>) -> Color32 {
    match verdict {
        Some(PartVerdict::Pass) => PASS,
        Some(PartVerdict::Fail) => FAIL,
        Some(PartVerdict::Error) => ERROR,
        Some(PartVerdict::Inconclusive) => INCONCLUSIVE,
        None => Color32::GRAY,
    }
}

/// The verdict as the reports print it; SKIPPED for a part not measured.
fn verdict_text(verdict: Option<PartVerdict>) -> &'static str {
    verdict.map_or("SKIPPED", headline)
}

/// Draws the Line view.
pub fn show(ui: &mut egui::Ui, view: &mut LineView, record: &RecordSettings, rt: &mut LineRuntime) {
    rt.poll(ui.ctx());
    let running = rt.is_running();
    ui.horizontal_wrapped(|ui| {
        ui.add_enabled_ui(!running, |ui| {
            path_field(ui, "Inbox", &mut view.inbox, true, "The folder each part's folder is dropped into.");
            path_field(
                ui,
                "Recipe",
                &mut view.recipe,
                false,
                "The part type's recipe (sheen recipe, or Inspect > Save as recipe).",
            );
            ui.label("Results:");
            ui.add(egui::TextEdit::singleline(&mut view.out).hint_text("INBOX.results").desired_width(140.0))
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Results"));
            ui.checkbox(&mut view.report_pdf, "PDF reports");
        });
        ui.separator();
        if running {
            let stopping = rt.running.as_ref().is_some_and(|r| r.stopping);
            if ui
                .add_enabled(!stopping, egui::Button::new("Stop"))
                .on_hover_text("Stop after the parts in hand.")
                .clicked()
            {
                rt.stop();
            }
            ui.spinner();
        } else if ui.button("Start").on_hover_text("Watch the inbox and inspect every part that arrives.").clicked()
            && let Err(e) = rt.start(view, record)
        {
            rt.status = Some((e, true));
        }
    });
    ui.add_enabled_ui(!running, |ui| {
        ui.horizontal_wrapped(|ui| {
            path_field(
                ui,
                "AQDEF folder",
                &mut view.dfq_dir,
                true,
                "Each part's values as a Q-DAS AQDEF file (.dfq) in this folder, for the plant's SPC to collect \
                     (empty: none).",
            );
            path_field(
                ui,
                "QIF folder",
                &mut view.qif_dir,
                true,
                "Each part's results as a QIF 3.0 Results file in this folder (empty: none).",
            );
        });
    });
    ui.horizontal_wrapped(|ui| {
        ui.label("Records:");
        let db = record.location().map_or_else(|e| e.to_string(), |l| l.display());
        ui.monospace(db).on_hover_text("Set under Inspect > Record > Database, with the station and operator.");
        if let Some((text, is_error)) = &rt.status {
            ui.separator();
            let color = if *is_error { palette::error_text(ui.visuals()) } else { ui.visuals().text_color() };
            ui.colored_label(color, text);
        }
    });
    ui.separator();
    egui::ScrollArea::vertical()
        .id_salt("line-view")
        .auto_shrink([false, false])
        .show(ui, |ui| parts_shown(ui, view, rt));
}

/// The last part in large type, its map, the parts table and the trends.
fn parts_shown(ui: &mut egui::Ui, view: &mut LineView, rt: &LineRuntime) {
    let Some((last, measured)) = rt.parts.iter().rev().find_map(|p| p.measured().map(|m| (p, m))) else {
        ui.label("No parts yet: start the watch; each part dropped into the inbox appears here with its verdict.");
        return;
    };
    ui.horizontal(|ui| {
        let verdict = Some(measured.verdict);
        ui.label(RichText::new(verdict_text(verdict)).size(44.0).strong().color(verdict_color(verdict)));
        ui.vertical(|ui| {
            ui.label(RichText::new(&last.part).size(20.0).strong());
            ui.label(format!("{:.2} s", measured.seconds));
            if let Some(reason) = &measured.reason {
                ui.colored_label(palette::error_text(ui.visuals()), reason);
            }
        });
    });
    let followed = toleranced(&rt.parts);
    ui.horizontal_top(|ui| {
        let shown = if view.show_difference { &rt.difference } else { &rt.map };
        ui.vertical(|ui| {
            ui.checkbox(&mut view.show_difference, "Difference to the reference").on_hover_text(
                "The part less the recipe's reference where the part was found (um, zero in the middle of the \
                 colours): the alignment and the part's deviations at a glance.",
            );
            if let Some((part, texture)) = shown {
                ui.label(if view.show_difference {
                    format!("{part} less the aligned reference")
                } else {
                    format!("Height map of {part}, regions where the recipe found them")
                });
                let size = texture.size_vec2();
                let scale = (360.0 / size.y.max(1.0)).min(1.0);
                ui.image((texture.id(), size * scale));
            }
        });
        ui.vertical(|ui| parts_table(ui, &rt.parts, &followed));
    });
    ui.separator();
    trends(ui, &rt.parts, &followed);
}

fn path_field(ui: &mut egui::Ui, label: &str, value: &mut String, folder: bool, hint: &str) {
    ui.label(format!("{label}:")).on_hover_text(hint);
    let name = label.to_string();
    ui.add(egui::TextEdit::singleline(value).desired_width(180.0))
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, &name));
    let choose = format!("Choose the {}", label.to_lowercase());
    if ui.add(egui::Button::new("…")).on_hover_text(&choose).clicked() {
        let dialog = rfd::FileDialog::new();
        let picked = if folder { dialog.pick_folder() } else { dialog.add_filter("recipe", &["json"]).pick_file() };
        if let Some(path) = picked {
            *value = path.display().to_string();
        }
    }
}

/// The measurements a line follows: the toleranced ones.
fn toleranced(parts: &VecDeque<WatchLine>) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for m in parts.iter().filter_map(WatchLine::measured).flat_map(|p| p.toleranced()) {
        if !names.contains(&m.name) {
            names.push(m.name.clone());
        }
    }
    names
}

fn parts_table(ui: &mut egui::Ui, parts: &VecDeque<WatchLine>, names: &[String]) {
    ui.label(format!("Last {} parts", parts.len().min(TABLE_ROWS)));
    egui::ScrollArea::vertical().id_salt("line-parts").max_height(360.0).show(ui, |ui| {
        egui::Grid::new("line-parts-grid").striped(true).show(ui, |ui| {
            ui.strong("Part");
            ui.strong("Verdict");
            for n in names.iter().take(4) {
                ui.strong(n);
            }
            ui.strong("s");
            ui.end_row();
            for p in parts.iter().rev().take(TABLE_ROWS) {
                ui.label(&p.part);
                ui.colored_label(verdict_color(p.verdict()), verdict_text(p.verdict()));
                let values = p.measured().map_or(&[][..], |m| m.measurements.as_slice());
                for n in names.iter().take(4) {
                    let m = values.iter().find(|m| &m.name == n);
                    match m.and_then(|m| m.value.map(|v| (v, m))) {
                        Some((v, m)) => {
                            let color = match m.verdict {
                                Some(Verdict::Fail) => FAIL,
                                Some(Verdict::Inconclusive) => INCONCLUSIVE,
                                _ => ui.visuals().text_color(),
                            };
                            let text = match m.expanded_uncertainty {
                                Some(u) => format!("{v:.3} ± {u:.3} {}", m.unit),
                                None => format!("{v:.3} {}", m.unit),
                            };
                            ui.colored_label(color, text);
                        }
                        None => {
                            ui.label("–");
                        }
                    }
                }
                ui.label(p.measured().map_or_else(|| "–".into(), |m| format!("{:.2}", m.seconds)));
                ui.end_row();
            }
        });
    });
}

/// One small trend per toleranced measurement over the parts kept.
fn trends(ui: &mut egui::Ui, parts: &VecDeque<WatchLine>, names: &[String]) {
    if names.is_empty() {
        return;
    }
    ui.label("Trends");
    ui.horizontal_wrapped(|ui| {
        for name in names.iter().take(6) {
            ui.vertical(|ui| {
                ui.label(name);
                let values: Vec<(usize, &WatchValue)> = parts
                    .iter()
                    .enumerate()
                    .filter_map(|(i, p)| {
                        p.measured().and_then(|p| p.measurements.iter().find(|m| &m.name == name)).map(|m| (i, m))
                    })
                    .collect();
                let points: Vec<[f64; 2]> =
                    values.iter().filter_map(|(i, m)| m.value.map(|v| [*i as f64, v])).collect();
                let limits = values.last().map(|(_, m)| (m.lower_limit, m.upper_limit));
                Plot::new(format!("line trend {name}")).width(260.0).height(140.0).allow_scroll(false).show(
                    ui,
                    |plot| {
                        if let Some((lower, upper)) = limits {
                            for limit in [lower, upper].into_iter().flatten() {
                                plot.hline(HLine::new("limit", limit).color(PASS).width(1.5));
                            }
                        }
                        plot.line(Line::new(name.as_str(), PlotPoints::new(points.clone())));
                        plot.points(Points::new(name.as_str(), PlotPoints::new(points)).radius(2.5));
                    },
                );
            });
        }
    });
}
