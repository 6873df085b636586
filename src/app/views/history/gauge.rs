//! The History view's gauge study: the selected recipe's measurement, as
//! recorded, as a Type-1 study or a Gage R&R (`analysis::gauge`, the same
//! as `sheen gauge`), with the figures, AIAG's band and a chart: the run of
//! the repeats with xm and xm ± 0.1 T, or each operator's part means.

use eframe::egui::{self, Color32, RichText};
use egui_plot::{HLine, Legend, Line, Plot, PlotPoints, Points};

use std::path::PathBuf;

use crate::analysis::gauge::{self, Observation, RrBand, RrMethod};
use crate::app::jobs::{Job, JobError, JobOutcome};
use crate::app::palette;
use crate::io::report::study::{StudyPage, write_study_html};
use crate::records::StoredPart;

/// Which study, and its inputs as typed (persisted with the view).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct GaugeChoice {
    pub rr: bool,
    pub range_method: bool,
    /// Type-1: the reference value xm; both: the tolerance width T (empty =
    /// none, for R&R).
    pub reference: String,
    pub tolerance: String,
    /// Folder the study's HTML and PDF pages are saved to (empty: the
    /// current folder).
    pub export_folder: String,
}

/// The study's page being saved, and how the last save went.
#[derive(Default)]
pub struct StudyExports {
    job: Option<Job<PathBuf>>,
    /// The last save's outcome: what was written, or why not (an error).
    pub status: Option<(String, bool)>,
}

impl StudyExports {
    pub fn is_running(&self) -> bool {
        self.job.is_some()
    }

    fn poll(&mut self) {
        let Some(outcome) = self.job.as_ref().and_then(Job::poll) else { return };
        self.job = None;
        self.status = Some(match outcome {
            JobOutcome::Done(path) => (format!("Saved {}", path.display()), false),
            JobOutcome::Failed(e) => (crate::error_text::error_chain(&e), true),
            JobOutcome::Panicked(e) => (format!("saving the study crashed: {e}"), true),
            JobOutcome::Cancelled => ("saving the study was cancelled".into(), true),
        });
    }

    /// Saves the page as HTML or PDF under `folder`: the page is made and
    /// written off the UI thread (a PDF subsets and embeds its font).
    fn save(&mut self, page: &StudyPage<'_>, folder: &str, name: &str, pdf: bool, ctx: &egui::Context) {
        let folder = if folder.trim().is_empty() {
            std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."))
        } else {
            PathBuf::from(folder.trim())
        };
        let path = folder.join(format!("{name}.{}", if pdf { "pdf" } else { "html" }));
        let (title, data) = (page.title.to_string(), page.data.to_vec());
        let (headline, good, figures, source) =
            (page.headline.clone(), page.good, page.figures.clone(), page.source.clone());
        let ctx = ctx.clone();
        self.job = Some(Job::spawn(
            "Saving the gauge study",
            move || ctx.request_repaint(),
            move |_| {
                let page = StudyPage { title: &title, headline, good, figures, source, data: &data };
                let failed = |e: anyhow::Error| JobError::Failed(e.context("cannot save the gauge study"));
                let bytes = if pdf {
                    crate::io::report::pdf::study_pdf_bytes(&page).map_err(|e| failed(anyhow::anyhow!(e)))?
                } else {
                    let mut b = Vec::new();
                    write_study_html(&mut b, &page).map_err(|e| failed(e.into()))?;
                    b
                };
                crate::io::atomic::write_atomic(&path, |w| std::io::Write::write_all(w, &bytes))
                    .map_err(|e| failed(e.into()))?;
                Ok(path)
            },
        ));
    }
}

/// The records' values of `measurement` for the study, oldest first: the
/// part ID is the part, the operator the operator ("-" where none).
pub fn observations(parts: &[StoredPart], indices: &[usize], measurement: &str) -> Vec<Observation> {
    indices
        .iter()
        .filter_map(|&i| parts.get(i))
        .flat_map(|p| {
            p.record.measurements.iter().filter(|m| m.name == measurement).filter_map(|m| {
                Some(Observation {
                    part: p.record.part_id.clone(),
                    operator: p.record.operator.clone().unwrap_or_else(|| "-".into()),
                    value: m.value?,
                })
            })
        })
        .collect()
}

fn number(text: &str) -> Option<Result<f64, String>> {
    let t = text.trim();
    (!t.is_empty()).then(|| t.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(format!("'{t}' is not a number")))
}

/// Draws the study for `observations` of `measurement`.
pub fn show(
    ui: &mut egui::Ui,
    choice: &mut GaugeChoice,
    observations: &[Observation],
    measurement: &str,
    source: &str,
    exports: &mut StudyExports,
) {
    exports.poll();
    ui.horizontal_wrapped(|ui| {
        ui.selectable_value(&mut choice.rr, false, "Type-1")
            .on_hover_text("VDA 5 / Bosch booklet 10: repeats of one reference part; Cg, Cgk capable at 1.33.");
        ui.selectable_value(&mut choice.rr, true, "Gage R&R")
            .on_hover_text("AIAG MSA: parts x operators x trials (the records' part IDs and operators).");
        ui.separator();
        if choice.rr {
            ui.selectable_value(&mut choice.range_method, false, "ANOVA");
            ui.selectable_value(&mut choice.range_method, true, "Average and range");
        } else {
            ui.label("Reference xm:");
            ui.add(egui::TextEdit::singleline(&mut choice.reference).desired_width(80.0))
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Reference xm"));
        }
        ui.label("Tolerance T:");
        ui.add(egui::TextEdit::singleline(&mut choice.tolerance).desired_width(80.0).hint_text("USL - LSL"))
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Tolerance T"));
    });
    ui.label(format!("{} recorded value(s) of '{measurement}'.", observations.len()));
    let error = |ui: &mut egui::Ui, text: String| {
        ui.colored_label(palette::error_text(ui.visuals()), text);
    };
    let tolerance = match number(&choice.tolerance).transpose() {
        Ok(t) => t,
        Err(e) => return error(ui, format!("Tolerance: {e}")),
    };
    if choice.rr {
        let method = if choice.range_method { RrMethod::Range } else { RrMethod::Anova };
        match gauge::gage_rr(observations, method, tolerance) {
            Ok(rr) => {
                let color = match rr.band {
                    RrBand::Acceptable => Color32::from_rgb(40, 160, 80),
                    RrBand::Conditional => Color32::from_rgb(230, 140, 20),
                    RrBand::NotAcceptable => Color32::from_rgb(215, 50, 50),
                };
                let judged = rr.percent_tolerance.unwrap_or(rr.percent_grr);
                ui.label(
                    RichText::new(format!("%GRR {judged:.1} %   ndc {}", rr.ndc)).size(18.0).strong().color(color),
                );
                let page = StudyPage::rr(&rr, observations, source.to_string());
                ui.monospace(&page.figures);
                operator_means_chart(ui, &rr);
                save_row(ui, choice, exports, &page, &format!("gage-rr {measurement}"));
            }
            Err(e) => error(ui, format!("Gage R&R: {e}")),
        }
    } else {
        let reference = match number(&choice.reference) {
            Some(Ok(v)) => v,
            Some(Err(e)) => return error(ui, format!("Reference: {e}")),
            None => return error(ui, "Type the reference part's calibrated value xm and the tolerance T.".into()),
        };
        let Some(tolerance) = tolerance else {
            return error(ui, "Type the tolerance width T (USL - LSL).".into());
        };
        let values: Vec<f64> = observations.iter().map(|o| o.value).collect();
        match gauge::type1(&values, reference, tolerance) {
            Ok(t) => {
                let color = if t.capable { Color32::from_rgb(40, 160, 80) } else { Color32::from_rgb(215, 50, 50) };
                let verdict = if t.capable { "CAPABLE" } else { "NOT CAPABLE" };
                ui.label(
                    RichText::new(format!("Cg {:.2}  Cgk {:.2}  {verdict}", t.cg, t.cgk))
                        .size(18.0)
                        .strong()
                        .color(color),
                );
                let page = StudyPage::type1(&t, observations, source.to_string());
                ui.monospace(&page.figures);
                run_chart(ui, &values, reference, tolerance);
                save_row(ui, choice, exports, &page, &format!("type-1 {measurement}"));
            }
            Err(e) => error(ui, format!("Type-1 study: {e}")),
        }
    }
}

/// The folder and the buttons that save the study's page for the lab file,
/// with how the last save went.
fn save_row(ui: &mut egui::Ui, choice: &mut GaugeChoice, exports: &mut StudyExports, page: &StudyPage<'_>, name: &str) {
    let name = crate::io::paths::safe_file_stem(name);
    ui.horizontal_wrapped(|ui| {
        ui.label("Save to:");
        ui.add(egui::TextEdit::singleline(&mut choice.export_folder).hint_text("current folder").desired_width(200.0))
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Study folder"));
        ui.add_enabled_ui(!exports.is_running(), |ui| {
            for (label, pdf) in [("Save study HTML", false), ("Save study PDF", true)] {
                let tip = "The verdict, the figures and every value the study was made of, for the lab file.";
                if ui.button(label).on_hover_text(tip).clicked() {
                    exports.save(page, &choice.export_folder, &name, pdf, ui.ctx());
                }
            }
        });
        if exports.is_running() {
            ui.spinner();
        }
    });
    if let Some((text, is_error)) = &exports.status {
        let color = if *is_error { palette::error_text(ui.visuals()) } else { ui.visuals().text_color() };
        ui.colored_label(color, text);
    }
}

/// The repeats in order with xm and xm ± 0.1 T (the Type-1 band).
fn run_chart(ui: &mut egui::Ui, values: &[f64], reference: f64, tolerance: f64) {
    let points: Vec<[f64; 2]> = values.iter().enumerate().map(|(i, v)| [i as f64 + 1.0, *v]).collect();
    Plot::new("gauge run chart").height(180.0).legend(Legend::default()).show(ui, |plot| {
        plot.line(Line::new("values", PlotPoints::from(points.clone())));
        plot.points(Points::new("repeats", PlotPoints::from(points)).radius(2.5));
        plot.hline(HLine::new("xm", reference).color(Color32::GRAY));
        plot.hline(HLine::new("xm ± 0.1 T", reference + 0.1 * tolerance).color(Color32::from_rgb(230, 140, 20)));
        plot.hline(HLine::new("xm ± 0.1 T", reference - 0.1 * tolerance).color(Color32::from_rgb(230, 140, 20)));
    });
}

/// Each operator's mean per part: lines that lie on each other are a
/// reproducible gauge.
fn operator_means_chart(ui: &mut egui::Ui, rr: &gauge::GageRr) {
    let mut operators: Vec<&str> = rr.cells.iter().map(|c| c.operator.as_str()).collect();
    operators.dedup();
    Plot::new("gauge operator means").height(180.0).legend(Legend::default()).show(ui, |plot| {
        for operator in operators {
            let points: Vec<[f64; 2]> = rr
                .cells
                .iter()
                .filter(|c| c.operator == operator)
                .enumerate()
                .map(|(i, c)| [i as f64 + 1.0, c.mean])
                .collect();
            plot.line(Line::new(format!("operator {operator}"), PlotPoints::from(points)));
        }
    });
}
