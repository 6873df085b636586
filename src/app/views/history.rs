//! The History view: the inspection records of a recipe over
//! time. A trend chart of one measurement with its tolerance band, mean and
//! individuals control limits, points coloured by verdict and ringed where
//! they break a run rule; a histogram with the capability indices; the
//! parts as a table. Clicking a point (or Open) opens that part again with
//! its recorded parameters and inspection.
//!
//! The records are read on a worker thread (a PostgreSQL server may be slow
//! or down) and again whenever the database, a filter or the records this
//! app wrote change; a frame only draws. The statistics are
//! `records::trend`'s, the same as `sheen history stats`.

mod gauge;

use std::sync::Arc;

use eframe::egui::{self, Color32, RichText};
use egui_plot::{Bar, BarChart, HLine, Legend, MarkerShape, Plot, PlotPoints, Points, Span, VLine};

use crate::analysis::measurement_table::Verdict;
use crate::app::commands::Command;
use crate::app::jobs::{Job, JobOutcome};
use crate::app::palette;
use crate::records::time::{DateError, RangeEnd, local_display, range_bound};
use crate::records::trend::{Baseline, Trend, trends};
use crate::records::{HistoryFilter, Store, StoredPart};

use crate::app::record_settings::RecordSettings;

const PASS: Color32 = Color32::from_rgb(40, 160, 80);
const FAIL: Color32 = Color32::from_rgb(215, 50, 50);
/// Within U of a limit (ISO 14253-1): neither pass nor fail.
const INCONCLUSIVE: Color32 = Color32::from_rgb(190, 150, 20);
const NO_VERDICT: Color32 = Color32::from_rgb(130, 130, 140);
const RULE: Color32 = Color32::from_rgb(255, 150, 0);
const CONTROL: Color32 = Color32::from_rgb(90, 140, 230);
/// How near (screen points) a click must be to a trend point to pick it.
const PICK_PX: f32 = 10.0;

/// The History view's persisted choices.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct HistoryView {
    pub recipe: String,
    pub measurement: String,
    /// Only this station (empty = all).
    pub station: String,
    /// ISO 8601 dates or times, local unless an offset is given (empty = open).
    pub since: String,
    pub until: String,
    /// The gauge study of the selected measurement (a section of the view).
    pub gauge: gauge::GaugeChoice,
}

impl super::View for HistoryView {
    /// Drawn by [`show`]: it needs no measurement panes.
    fn panes<'a>(
        &self,
        _cx: &super::ViewCx<'a>,
        _cameras: &[usize],
        _commands: &mut Vec<Command>,
    ) -> Vec<super::Pane<'a>> {
        Vec::new()
    }
}

/// A read of the records on a worker thread.
type ReadJob = Job<Result<Read, crate::records::RecordsError>>;

/// What a read found.
enum Read {
    /// The SQLite file does not exist yet: an empty history, not a fault.
    NoDatabase(String),
    /// The selected parts, and when a station filter narrows them without a
    /// date range, the recipe's whole history for the control limits'
    /// baseline ([`Baseline::RecipeStart`]).
    Parts { parts: Vec<StoredPart>, history: Option<Vec<StoredPart>> },
}

/// What was read, for which query.
struct Loaded {
    key: QueryKey,
    parts: Arc<Vec<StoredPart>>,
    history: Option<Arc<Vec<StoredPart>>>,
}

#[derive(Clone, Debug, PartialEq)]
struct QueryKey {
    db: String,
    filter: HistoryFilter,
    /// Records the app wrote since; a new one reloads.
    written: u64,
}

/// The History view's runtime (never persisted).
#[derive(Default)]
pub struct HistoryRuntime {
    job: Option<(QueryKey, ReadJob)>,
    loaded: Option<Loaded>,
    error: Option<String>,
    /// The database that does not exist yet, when that is what a read found.
    no_database: Option<String>,
    /// Where the trend chart drew each measured part (row id, screen
    /// position) in the last frame: what a click is matched against.
    drawn_points: Vec<(i64, egui::Pos2)>,
    /// The selected part's row id.
    pub selected: Option<i64>,
    reload: bool,
    /// The query last read (whatever it gave): a read starts when it changes.
    requested: Option<QueryKey>,
    /// Trends of the loaded parts, with the key they were made for.
    trends: Option<(QueryKey, bool, Arc<Vec<Trend>>)>,
    /// The gauge study's page being saved.
    pub study_exports: gauge::StudyExports,
}

impl HistoryRuntime {
    /// The parts read for the current query, if any.
    pub fn parts(&self) -> Option<&[StoredPart]> {
        self.loaded.as_ref().map(|l| l.parts.as_slice())
    }

    pub fn is_loading(&self) -> bool {
        self.job.is_some()
    }

    /// Why the records cannot be shown.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// The SQLite file the view looked for and found not yet created.
    pub fn no_database(&self) -> Option<&str> {
        self.no_database.as_deref()
    }

    /// The trend chart's points as last drawn: (part row id, screen position).
    pub fn drawn_points(&self) -> &[(i64, egui::Pos2)] {
        &self.drawn_points
    }

    /// Starts reading when the query changed (or a reload was asked), and
    /// collects what a read gave.
    fn update(&mut self, key: QueryKey, location: crate::records::DbLocation, repaint: impl Fn() + Send + 'static) {
        if let Some((job_key, job)) = &self.job
            && let Some(outcome) = job.poll()
        {
            let job_key = job_key.clone();
            self.job = None;
            match outcome {
                JobOutcome::Done(Ok(Read::Parts { parts, history })) => {
                    (self.error, self.no_database) = (None, None);
                    let history = history.map(Arc::new);
                    self.loaded = Some(Loaded { key: job_key, parts: Arc::new(parts), history });
                }
                JobOutcome::Done(Ok(Read::NoDatabase(path))) => {
                    (self.error, self.no_database, self.loaded) = (None, Some(path), None);
                }
                JobOutcome::Done(Err(e)) => {
                    (self.error, self.no_database, self.loaded) = (Some(e.to_string()), None, None)
                }
                JobOutcome::Failed(e) => {
                    (self.error, self.no_database, self.loaded) = (Some(crate::error_text::error_chain(&e)), None, None)
                }
                JobOutcome::Panicked(e) => self.error = Some(format!("reading the records crashed: {e}")),
                JobOutcome::Cancelled => {}
            }
        }
        let wanted = self.reload || self.requested.as_ref() != Some(&key);
        if self.job.is_some() || !wanted {
            return;
        }
        self.reload = false;
        self.requested = Some(key.clone());
        let filter = key.filter.clone();
        let job = Job::spawn("Reading the records", repaint, move |_| {
            if let crate::records::DbLocation::Sqlite(path) = &location
                && !path.exists()
            {
                return Ok(Ok(Read::NoDatabase(path.display().to_string())));
            }
            let read = |store: &mut Store| -> Result<Read, crate::records::RecordsError> {
                let parts = store.parts(&filter)?;
                let dated = filter.since_utc.is_some() || filter.until_utc.is_some();
                let history = match (dated, &filter.station) {
                    (false, Some(_)) => Some(store.parts(&HistoryFilter { station: None, ..filter.clone() })?),
                    _ => None,
                };
                Ok(Read::Parts { parts, history })
            };
            Ok(Store::open(&location).and_then(|mut s| read(&mut s)))
        });
        self.job = Some((key, job));
    }
}

/// A filter field the view cannot use, by the label it has on screen.
#[derive(Debug, thiserror::Error)]
#[error("{field}: {source}")]
struct FieldError {
    field: &'static str,
    source: DateError,
}

/// The filter the view's fields give, or the first field's error.
fn filter_of(view: &HistoryView) -> Result<HistoryFilter, FieldError> {
    let bound =
        |text: &str, end: RangeEnd, field: &'static str| -> Result<Option<chrono::DateTime<chrono::Utc>>, FieldError> {
            let t = text.trim();
            if t.is_empty() {
                Ok(None)
            } else {
                range_bound(t, end).map(Some).map_err(|source| FieldError { field, source })
            }
        };
    Ok(HistoryFilter {
        recipe: None,
        since_utc: bound(&view.since, RangeEnd::Since, "Since")?,
        until_utc: bound(&view.until, RangeEnd::Until, "Until")?,
        station: (!view.station.trim().is_empty()).then(|| view.station.trim().to_string()),
    })
}

/// Draws the History view.
pub fn show(
    ui: &mut egui::Ui,
    view: &mut HistoryView,
    record: &RecordSettings,
    written: u64,
    rt: &mut HistoryRuntime,
    commands: &mut Vec<Command>,
) {
    let location = match record.location() {
        Ok(l) => l,
        Err(e) => {
            ui.colored_label(palette::error_text(ui.visuals()), e.to_string());
            return;
        }
    };
    let filter = filter_of(view);
    ui.horizontal_wrapped(|ui| {
        ui.label("Database:");
        ui.monospace(location.display()).on_hover_text("Set under Inspect > Record > Database.");
        if ui.add_enabled(!rt.is_loading(), egui::Button::new("Reload")).clicked() {
            rt.reload = true;
        }
        if rt.is_loading() {
            ui.spinner();
        }
        ui.separator();
        field(ui, "Station", &mut view.station, "all", 90.0);
        field(ui, "Since", &mut view.since, "2026-12-01", 120.0);
        field(ui, "Until", &mut view.until, "today", 120.0);
    });
    let filter = match filter {
        Ok(f) => f,
        Err(e) => {
            ui.colored_label(palette::error_text(ui.visuals()), e.to_string());
            return;
        }
    };
    let key = QueryKey { db: location.display(), filter, written };
    let ctx = ui.ctx().clone();
    let database = location.display();
    rt.update(key.clone(), location, move || ctx.request_repaint());
    if let Some(e) = &rt.error {
        ui.colored_label(palette::error_text(ui.visuals()), e);
        return;
    }
    if let Some(path) = &rt.no_database {
        ui.label(format!(
            "No parts recorded yet: the records database {path} is created by the first record \
             (Inspect > Record, or sheen analyze --record)."
        ));
        return;
    }
    let Some(loaded) = &rt.loaded else {
        ui.label("Reading the records…");
        return;
    };
    let parts = Arc::clone(&loaded.parts);
    let date_range = !view.since.trim().is_empty() || !view.until.trim().is_empty();
    let fresh = rt.trends.as_ref().is_some_and(|(k, d, _)| *k == loaded.key && *d == date_range);
    if !fresh {
        let baseline = match (&loaded.history, date_range) {
            (_, true) => Baseline::Selection,
            (Some(history), false) => Baseline::RecipeStart(history),
            (None, false) => Baseline::RecipeStart(&parts),
        };
        rt.trends = Some((loaded.key.clone(), date_range, Arc::new(trends(&parts, baseline))));
    }
    let all = rt.trends.as_ref().map_or_else(|| Arc::new(Vec::new()), |(_, _, t)| Arc::clone(t));

    let mut recipes: Vec<&str> = parts.iter().map(|p| p.record.recipe.as_str()).collect();
    recipes.sort_unstable();
    recipes.dedup();
    if recipes.is_empty() {
        ui.label(format!("No records in {} for these filters.", key.db));
        return;
    }
    if !recipes.contains(&view.recipe.as_str()) {
        view.recipe = recipes[0].to_string();
    }
    let names: Vec<&str> = all.iter().filter(|t| t.recipe == view.recipe).map(|t| t.name.as_str()).collect();
    if !names.is_empty() && !names.contains(&view.measurement.as_str()) {
        view.measurement = names[0].to_string();
    }
    ui.horizontal_wrapped(|ui| {
        combo(ui, "Recipe", &mut view.recipe, &recipes);
        combo(ui, "Measurement", &mut view.measurement, &names);
    });
    let recipe_parts: Vec<usize> =
        parts.iter().enumerate().filter(|(_, p)| p.record.recipe == view.recipe).map(|(i, _)| i).collect();
    let trend = all.iter().find(|t| t.recipe == view.recipe && t.name == view.measurement);
    ui.label(summary_line(trend, recipe_parts.len()));
    egui::CollapsingHeader::new("Gauge study").id_salt("history gauge study").show(ui, |ui| {
        let observations = gauge::observations(&parts, &recipe_parts, &view.measurement);
        let source = format!("records of recipe '{}' in {database}", view.recipe);
        gauge::show(ui, &mut view.gauge, &observations, &view.measurement, &source, &mut rt.study_exports);
    });

    let avail = ui.available_size();
    let table_w = 430.0_f32.min(avail.x * 0.48);
    let left_w = (avail.x - table_w - ui.spacing().item_spacing.x).max(200.0);
    ui.horizontal_top(|ui| {
        ui.allocate_ui_with_layout(egui::vec2(left_w, avail.y), egui::Layout::top_down(egui::Align::Min), |ui| {
            ui.set_width(left_w);
            match trend {
                Some(t) => {
                    let trend_h = (avail.y * 0.6).max(160.0);
                    trend_plot(ui, t, &parts, trend_h, rt, commands);
                    histogram(ui, t, (avail.y - trend_h - 30.0).max(100.0));
                }
                None => {
                    ui.label("This recipe's records have no measurements (errors only).");
                }
            }
        });
        ui.allocate_ui_with_layout(egui::vec2(table_w, avail.y), egui::Layout::top_down(egui::Align::Min), |ui| {
            ui.set_width(table_w);
            parts_table(ui, &parts, &recipe_parts, &view.measurement, rt, commands);
        });
    });
}

fn field(ui: &mut egui::Ui, label: &str, text: &mut String, hint: &str, width: f32) {
    ui.label(label);
    let label = label.to_string();
    ui.add(egui::TextEdit::singleline(text).hint_text(hint).desired_width(width))
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, &label));
}

fn combo(ui: &mut egui::Ui, label: &str, value: &mut String, options: &[&str]) {
    ui.label(label);
    egui::ComboBox::from_id_salt(("history", label)).selected_text(value.as_str()).width(200.0).show_ui(ui, |ui| {
        for o in options {
            ui.selectable_value(value, (*o).to_string(), *o);
        }
    });
}

fn fmt(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.4}"))
}

/// "Cp 1.2345  Cpk 1.1000", "CPU 0.9000": the indices the limits call for.
fn capability_text(c: &crate::records::spc::Capability, t: &Trend) -> String {
    c.shown(t.lower, t.upper).iter().map(|(name, v)| format!("{name} {}", fmt(*v))).collect::<Vec<_>>().join("  ")
}

/// "n 42 · mean … · σ … · Cp … Cpk …" (or CPU/CPL for one-sided limits).
fn summary_line(trend: Option<&Trend>, parts: usize) -> String {
    let Some(t) = trend else { return format!("{parts} part record(s).") };
    let Some(s) = t.summary else { return format!("{parts} part record(s); {} not measured.", t.points.len()) };
    let c = t.capability;
    let capability = match (t.lower, t.upper) {
        (None, None) => "no limits".to_string(),
        (Some(_), Some(_)) => capability_text(&c, t),
        (None, Some(_)) => format!("{} (upper limit only)", capability_text(&c, t)),
        (Some(_), None) => format!("{} (lower limit only)", capability_text(&c, t)),
    };
    let control = t.control.map_or_else(
        || "no control limits yet".to_string(),
        |l| format!("UCL {:.4}  LCL {:.4} (first {})", l.upper, l.lower, l.baseline_n),
    );
    format!(
        "{parts} part record(s) · n {} · mean {:.4} {} · σ {} · {capability} · {control} · {} run-rule point(s){}",
        s.n,
        s.mean,
        t.unit,
        fmt(s.sigma),
        t.violations.len(),
        if t.limits_changed { " · limits changed over time (latest shown)" } else { "" }
    )
}

fn verdict_color(v: Option<Verdict>) -> Color32 {
    match v {
        Some(Verdict::Pass) => PASS,
        Some(Verdict::Fail) => FAIL,
        Some(Verdict::Inconclusive) => INCONCLUSIVE,
        None => NO_VERDICT,
    }
}

/// A stored time as local date and minute, for the table (the full time
/// with its offset is the row's tooltip).
fn short_time(t: &chrono::DateTime<chrono::Utc>) -> String {
    t.with_timezone(&chrono::Local).format("%Y-%m-%d %H:%M").to_string()
}

/// Local date and time of a Unix time, for the axis.
fn time_label(t_s: f64) -> String {
    use chrono::TimeZone as _;
    chrono::Local
        .timestamp_micros((t_s * 1e6) as i64)
        .single()
        .map_or_else(String::new, |t| t.format("%m-%d %H:%M:%S").to_string())
}

fn trend_plot(
    ui: &mut egui::Ui,
    t: &Trend,
    parts: &[StoredPart],
    height: f32,
    rt: &mut HistoryRuntime,
    commands: &mut Vec<Command>,
) {
    let measured = t.measured();
    let selected = rt.selected;
    let response = Plot::new("history trend")
        .height(height)
        // Drifting parts climb to the right; the legend keeps the early corner.
        .legend(Legend::default().position(egui_plot::Corner::LeftTop))
        .x_axis_label("time (local)")
        .y_axis_label(format!("{} ({})", t.name, t.unit))
        .x_axis_formatter(|mark, _| time_label(mark.value))
        .label_formatter(|hover| {
            let p = match hover {
                egui_plot::HoverPosition::NearDataPoint { position, .. } => position,
                egui_plot::HoverPosition::Elsewhere { position } => position,
            };
            Some(format!("{}\n{:.4}", time_label(p.x), p.y))
        })
        .allow_drag(false)
        .show(ui, |pui| {
            if let (Some(lo), Some(hi)) = (t.lower, t.upper) {
                pui.span(Span::new("tolerance", lo..=hi).axis(egui_plot::Axis::Y).fill(PASS.gamma_multiply(0.12)));
            }
            for (limit, name) in [(t.lower, "lower limit"), (t.upper, "upper limit")] {
                if let Some(y) = limit {
                    pui.hline(HLine::new(name, y).color(PASS).width(1.5));
                }
            }
            if let Some(s) = t.summary {
                pui.hline(HLine::new("mean", s.mean).color(ui_text_color()).width(1.0));
            }
            if let Some(l) = t.control {
                pui.hline(HLine::new("UCL / LCL", l.upper).color(CONTROL).style(egui_plot::LineStyle::dashed_dense()));
                pui.hline(HLine::new("UCL / LCL", l.lower).color(CONTROL).style(egui_plot::LineStyle::dashed_dense()));
            }
            for (name, verdict) in [("pass", Some(Verdict::Pass)), ("fail", Some(Verdict::Fail)), ("no verdict", None)]
            {
                let pts: Vec<[f64; 2]> = measured
                    .iter()
                    .filter(|p| p.verdict == verdict)
                    .filter_map(|p| p.value.map(|v| [p.time_s, v]))
                    .collect();
                if !pts.is_empty() {
                    pui.points(
                        Points::new(name, PlotPoints::new(pts))
                            .color(verdict_color(verdict))
                            .radius(3.5)
                            .shape(MarkerShape::Circle),
                    );
                }
            }
            let ringed: Vec<[f64; 2]> = measured
                .iter()
                .enumerate()
                .filter(|(i, _)| t.violates(*i))
                .filter_map(|(_, p)| p.value.map(|v| [p.time_s, v]))
                .collect();
            if !ringed.is_empty() {
                pui.points(
                    Points::new("run rule", PlotPoints::new(ringed))
                        .color(RULE)
                        .radius(7.0)
                        .filled(false)
                        .shape(MarkerShape::Circle),
                );
            }
            if let Some(p) = measured.iter().find(|p| Some(parts[p.part].row_id) == selected)
                && let Some(v) = p.value
            {
                pui.vline(VLine::new("selected", p.time_s).color(ui_text_color().gamma_multiply(0.5)));
                pui.points(
                    Points::new("selected", PlotPoints::new(vec![[p.time_s, v]]))
                        .color(ui_text_color())
                        .radius(5.0)
                        .filled(false),
                );
            }
        });
    let r = &response.response;
    r.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "Trend chart"));
    let tr = &response.transform;
    rt.drawn_points = measured
        .iter()
        .filter_map(|p| {
            let at = tr.position_from_point(&egui_plot::PlotPoint::new(p.time_s, p.value?));
            Some((parts[p.part].row_id, at))
        })
        .collect();
    if r.clicked()
        && let Some(pos) = r.interact_pointer_pos()
    {
        // The points as this frame drew them: picking sees what the operator sees.
        let nearest = rt
            .drawn_points
            .iter()
            .map(|&(row_id, at)| (row_id, at.distance(pos)))
            .filter(|(_, d)| *d <= PICK_PX)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some(part) = nearest.and_then(|(row_id, _)| parts.iter().find(|p| p.row_id == row_id)) {
            rt.selected = Some(part.row_id);
            commands.push(Command::OpenRecord(Box::new(part.clone())));
        }
    }
}

fn ui_text_color() -> Color32 {
    Color32::from_gray(160)
}

/// The values' histogram with the limits and the mean.
fn histogram(ui: &mut egui::Ui, t: &Trend, height: f32) {
    let values: Vec<f64> = t.points.iter().filter_map(|p| p.value).collect();
    let Some(s) = t.summary else { return };
    let (mut lo, mut hi) = (s.min, s.max);
    if hi <= lo {
        lo -= 0.5;
        hi += 0.5;
    }
    let bins = ((values.len() as f64).sqrt().round() as usize).clamp(5, 30);
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    for v in &values {
        let b = (((v - lo) / width) as usize).min(bins - 1);
        counts[b] += 1;
    }
    let bars: Vec<Bar> = counts
        .iter()
        .enumerate()
        .map(|(i, &n)| Bar::new(lo + (i as f64 + 0.5) * width, n as f64).width(width * 0.95))
        .collect();
    let c = t.capability;
    let title = match (t.lower, t.upper) {
        (None, None) => "Histogram · no limits".into(),
        _ => format!("Histogram · {}", capability_text(&c, t)),
    };
    ui.label(RichText::new(title).strong());
    Plot::new("history histogram")
        .height(height)
        .x_axis_label(format!("{} ({})", t.name, t.unit))
        .y_axis_label("parts")
        .allow_drag(false)
        .allow_scroll(false)
        .show(ui, |pui| {
            pui.bar_chart(BarChart::new("parts", bars).color(CONTROL));
            for y in [t.lower, t.upper].into_iter().flatten() {
                pui.vline(VLine::new("limit", y).color(PASS).width(1.5));
            }
            pui.vline(VLine::new("mean", s.mean).color(ui_text_color()));
        })
        .response
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "Histogram"));
}

/// The recipe's parts, newest first: time, part, station, the measurement's
/// value and verdict; a row click selects, Open opens.
fn parts_table(
    ui: &mut egui::Ui,
    parts: &[StoredPart],
    recipe_parts: &[usize],
    measurement: &str,
    rt: &mut HistoryRuntime,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        ui.strong(format!("Parts ({})", recipe_parts.len()));
        let selected = rt.selected.and_then(|id| parts.iter().find(|p| p.row_id == id));
        if ui
            .add_enabled(selected.is_some(), egui::Button::new("Open part"))
            .on_hover_text("Open the selected part's measurement with its recorded parameters and inspection.")
            .clicked()
            && let Some(p) = selected
        {
            commands.push(Command::OpenRecord(Box::new(p.clone())));
        }
    });
    egui::ScrollArea::both().id_salt("history parts").show(ui, |ui| {
        egui::Grid::new("history parts grid").striped(true).num_columns(5).show(ui, |ui| {
            let unit = parts
                .iter()
                .flat_map(|p| &p.record.measurements)
                .find(|m| m.name == measurement)
                .map_or(String::new(), |m| format!(" ({})", m.unit));
            for h in ["time", "part", "station", &format!("{measurement}{unit}"), "verdict"] {
                ui.strong(h);
            }
            ui.end_row();
            for &i in recipe_parts.iter().rev() {
                let p = &parts[i];
                let r = &p.record;
                let is_selected = rt.selected == Some(p.row_id);
                let when = short_time(&r.time_utc);
                let row = ui.selectable_label(is_selected, when).on_hover_text(local_display(&r.time_utc));
                if row.clicked() {
                    rt.selected = Some(p.row_id);
                }
                let id = ui.label(&r.part_id);
                if !r.exports.is_empty() {
                    id.on_hover_text(format!("Exchange files written (AQDEF, QIF):\n{}", r.exports.join("\n")));
                }
                ui.label(r.station.as_deref().unwrap_or("—"));
                let m = r.measurements.iter().find(|m| m.name == measurement);
                match m {
                    Some(m) => ui.monospace(match (m.value, &m.uncertainty) {
                        (Some(v), Some(u)) => format!("{v:.4} ± {:.4}", u.expanded),
                        (Some(v), None) => format!("{v:.4}"),
                        (None, _) => "not measured".into(),
                    }),
                    None => ui.weak("—"),
                };
                let (text, color) = match (r.verdict, m.and_then(|m| m.verdict)) {
                    (crate::records::PartVerdict::Error, _) => {
                        (format!("ERROR: {}", r.reason.as_deref().unwrap_or("")), RULE)
                    }
                    (_, Some(v)) => (
                        match m.and_then(|m| m.decision_rule) {
                            Some(rule) => format!("{} ({rule})", v.name().to_uppercase()),
                            None => v.name().to_uppercase(),
                        },
                        verdict_color(Some(v)),
                    ),
                    (v, None) => (v.name().to_uppercase(), NO_VERDICT),
                };
                ui.colored_label(color, text);
                ui.end_row();
            }
        });
    });
}
