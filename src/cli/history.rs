//! `sheen history`: the inspection records as a table or CSV,
//! and `sheen history stats`: per measurement the summary, capability,
//! individuals control limits and run-rule violations (records::spc).

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};

use crate::analysis::measurement_table::Verdict;
use crate::io;
use crate::io::csv::field;
use crate::records::time::{DateError, RangeEnd, local_display, range_bound, stored};
use crate::records::trend::{Baseline, trends};
use crate::records::{DbLocation, HistoryFilter, MeasurementRecord, Store, StoredPart};

/// CSV header of `sheen history --csv`.
pub const HISTORY_COLUMNS: &str = "part,time,station,recipe,part_verdict,measurement,value,unit,measurement_verdict";

#[derive(Debug, Args)]
pub struct HistoryArgs {
    #[command(subcommand)]
    pub action: Option<HistoryAction>,
    #[command(flatten)]
    pub filter: FilterArgs,
    /// Also write the listed rows as CSV (one row per part and measurement).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the listed parts as one Q-DAS AQDEF file (.dfq): each
    /// value with the limits it was judged against, parts in error as
    /// invalid values.
    #[arg(long, value_name = "FILE")]
    pub dfq: Option<PathBuf>,
}

#[derive(Debug, Subcommand)]
pub enum HistoryAction {
    /// Per recipe and measurement: n, mean, sigma, min, max, Cp/Cpk (CPU or
    /// CPL for one-sided limits), individuals control limits from the first
    /// 25 parts (or the whole --since/--until range), run-rule violations.
    Stats,
}

/// The filters, accepted before or after `stats`.
#[derive(Debug, Args)]
pub struct FilterArgs {
    /// Records database: a SQLite file or postgres://user@host:port/db
    /// [default: records.sqlite in the platform data folder].
    #[arg(long, value_name = "FILE|URL", global = true)]
    pub db: Option<String>,
    /// Only this recipe.
    #[arg(long, value_name = "NAME", global = true)]
    pub recipe: Option<String>,
    /// From this ISO 8601 date or time on (local time unless an offset is given).
    #[arg(long, value_name = "DATE", global = true)]
    pub since: Option<String>,
    /// Up to this ISO 8601 time, or to the end of this date.
    #[arg(long, value_name = "DATE", global = true)]
    pub until: Option<String>,
    /// Only this station.
    #[arg(long, value_name = "NAME", global = true)]
    pub station: Option<String>,
    /// Only this measurement (parts recorded without measurements, such as
    /// errors, are still listed).
    #[arg(long, value_name = "NAME", global = true)]
    pub measurement: Option<String>,
}

pub fn run(args: &HistoryArgs) -> anyhow::Result<()> {
    let f = &args.filter;
    let location = DbLocation::from_option(f.db.as_deref())?;
    if let DbLocation::Sqlite(path) = &location
        && !path.exists()
    {
        anyhow::bail!(
            "no records database at {}: nothing has been recorded there (sheen analyze --record)",
            path.display()
        );
    }
    let filter = HistoryFilter {
        recipe: f.recipe.clone(),
        since_utc: f.since.as_deref().map(|t| range_bound(t, RangeEnd::Since)).transpose().map_err(since_err)?,
        until_utc: f.until.as_deref().map(|t| range_bound(t, RangeEnd::Until)).transpose().map_err(until_err)?,
        station: f.station.clone(),
    };
    let mut store = Store::open(&location)?;
    let mut parts = store.parts(&filter)?;
    if let Some(name) = &f.measurement {
        for p in &mut parts {
            p.record.measurements.retain(|m| &m.name == name);
        }
        // A part measured without that measurement says nothing about it;
        // one with no measurements at all (an error) is still news.
        parts.retain(|p| !p.record.measurements.is_empty() || p.record.verdict == crate::records::PartVerdict::Error);
    }
    match args.action {
        Some(HistoryAction::Stats) => {
            // A date range is its own baseline; otherwise the recipe's first
            // parts from every station are, which a station filter would cut.
            // Without a station filter the selection is the recipe's history itself.
            let dated = f.since.is_some() || f.until.is_some();
            let history = match (dated, &filter.station) {
                (false, Some(_)) => Some(store.parts(&HistoryFilter { station: None, ..filter.clone() })?),
                _ => None,
            };
            let baseline = match (dated, &history) {
                (true, _) => Baseline::Selection,
                (false, Some(history)) => Baseline::RecipeStart(history),
                (false, None) => Baseline::RecipeStart(&parts),
            };
            print!("{}", stats_text(&parts, baseline));
        }
        None => {
            print!("{}", table_text(&parts));
            if let Some(path) = &args.csv {
                let text = csv_text(&parts);
                io::atomic::write_atomic(path, |w| w.write_all(text.as_bytes()))
                    .with_context(|| "cannot write the history CSV")?;
            }
            if let Some(path) = &args.dfq {
                io::aqdef::write_dfq(path, &exchange_parts(&parts))
                    .with_context(|| "cannot write the history's AQDEF file")?;
            }
        }
    }
    Ok(())
}

/// The parts as the exchange formats take them. A part in error gets the
/// characteristics of its recipe's nearest measured part (the one before
/// it, else the one after), so it is written as invalid values.
pub fn exchange_parts(parts: &[StoredPart]) -> Vec<crate::io::exchange::ExchangePart> {
    let measured = |p: &&StoredPart| !p.record.measurements.is_empty();
    parts
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut part = p.record.exchange(None);
            if p.record.measurements.is_empty() {
                let same_recipe = |q: &&StoredPart| q.record.recipe == p.record.recipe;
                let template = parts[..i]
                    .iter()
                    .rev()
                    .filter(same_recipe)
                    .find(measured)
                    .or_else(|| parts[i + 1..].iter().filter(same_recipe).find(measured));
                if let Some(t) = template {
                    part.not_measured_like(&t.record.measurements);
                }
            }
            part
        })
        .collect()
}

fn since_err(e: DateError) -> anyhow::Error {
    anyhow::anyhow!("--since {e}")
}

fn until_err(e: DateError) -> anyhow::Error {
    anyhow::anyhow!("--until {e}")
}

/// One row per part and measurement; a part without measurements one row
/// with the measurement columns empty and its reason as the verdict.
fn rows(parts: &[StoredPart]) -> Vec<[String; 9]> {
    let mut out = Vec::new();
    for p in parts {
        let r = &p.record;
        let head = |time: String| {
            [r.part_id.clone(), time, r.station.clone().unwrap_or_default(), r.recipe.clone(), r.verdict.name().into()]
        };
        if r.measurements.is_empty() {
            let [a, b, c, d, e] = head(stored(r.time_utc));
            out.push([
                a,
                b,
                c,
                d,
                e,
                String::new(),
                String::new(),
                String::new(),
                r.reason.clone().unwrap_or_default(),
            ]);
        }
        for m in &r.measurements {
            let [a, b, c, d, e] = head(stored(r.time_utc));
            out.push([a, b, c, d, e, m.name.clone(), value_text(m, None), m.unit.clone(), verdict_text(m)]);
        }
    }
    out
}

fn value_text(m: &MeasurementRecord, decimals: Option<usize>) -> String {
    match (m.value, decimals) {
        (Some(v), Some(d)) => format!("{v:.d$}"),
        // Shortest form that reads back as the same number.
        (Some(v), None) => format!("{v}"),
        (None, _) => String::new(),
    }
}

fn verdict_text(m: &MeasurementRecord) -> String {
    m.verdict.map(Verdict::name).unwrap_or("").to_string()
}

fn csv_text(parts: &[StoredPart]) -> String {
    let mut text = format!("{HISTORY_COLUMNS}\n");
    for row in rows(parts) {
        let fields: Vec<String> = row.iter().map(|f| field(f)).collect();
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    text
}

/// The rows as aligned columns, times in local time.
fn table_text(parts: &[StoredPart]) -> String {
    let header = ["part", "time", "station", "recipe", "verdict", "measurement", "value", "unit", "verdict"];
    let mut table: Vec<[String; 9]> = vec![header.map(String::from)];
    for p in parts {
        let r = &p.record;
        let mut push = |m: Option<&MeasurementRecord>| {
            let (name, value, unit, verdict) = match m {
                Some(m) => (m.name.clone(), value_text(m, Some(4)), m.unit.clone(), verdict_text(m)),
                None => ("-".into(), String::new(), String::new(), r.reason.clone().unwrap_or_default()),
            };
            table.push([
                r.part_id.clone(),
                local_display(&r.time_utc),
                r.station.clone().unwrap_or_default(),
                r.recipe.clone(),
                r.verdict.name().into(),
                name,
                value,
                unit,
                verdict,
            ]);
        };
        if r.measurements.is_empty() {
            push(None);
        }
        for m in &r.measurements {
            push(Some(m));
        }
    }
    let mut widths = [0usize; 9];
    for row in &table {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let mut text = String::new();
    for row in &table {
        let mut line = String::new();
        for (i, (cell, w)) in row.iter().zip(widths).enumerate() {
            let last = i == row.len() - 1;
            if i == 6 {
                let _ = write!(line, "{cell:>w$}  ");
            } else if last {
                line.push_str(cell);
            } else {
                let _ = write!(line, "{cell:<w$}  ");
            }
        }
        text.push_str(line.trim_end());
        text.push('\n');
    }
    let n = parts.len();
    let _ = writeln!(text, "{n} part record(s)");
    text
}

fn limits_text(lower: Option<f64>, upper: Option<f64>) -> String {
    match (lower, upper) {
        (Some(l), Some(u)) => format!("{l} .. {u}"),
        (None, Some(u)) => format!("upper {u} only"),
        (Some(l), None) => format!("lower {l} only"),
        (None, None) => "none".into(),
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.4}"))
}

/// The stats report, with control limits from `baseline`.
fn stats_text(parts: &[StoredPart], baseline: Baseline<'_>) -> String {
    let mut text = String::new();
    // The parts' verdicts, inconclusive ones apart (ISO 14253-1: neither
    // accepted nor rejected), and the rules they were judged by.
    let count = |v: crate::records::PartVerdict| parts.iter().filter(|p| p.record.verdict == v).count();
    let rules: std::collections::BTreeSet<String> =
        parts.iter().map(|p| p.record.decision_rule.map_or("simple (no rule recorded)".into(), |r| r.name())).collect();
    if !parts.is_empty() {
        let _ = writeln!(
            text,
            "parts: {}  pass {}  fail {}  inconclusive {}  error {}; decision rule: {}\n",
            parts.len(),
            count(crate::records::PartVerdict::Pass),
            count(crate::records::PartVerdict::Fail),
            count(crate::records::PartVerdict::Inconclusive),
            count(crate::records::PartVerdict::Error),
            rules.into_iter().collect::<Vec<_>>().join(", ")
        );
    }
    let all = trends(parts, baseline);
    if all.is_empty() {
        let _ = writeln!(text, "no measurements recorded for the selection ({} part record(s))", parts.len());
        return text;
    }
    for t in all {
        let _ = writeln!(text, "{} / {} ({}), limits: {}", t.recipe, t.name, t.unit, limits_text(t.lower, t.upper));
        if t.limits_changed {
            let _ = writeln!(text, "  note: the limits changed over these records; the latest are used");
        }
        let measured = t.measured();
        let missing = t.points.len() - measured.len();
        let Some(sum) = t.summary else {
            let _ = writeln!(text, "  n 0 ({missing} not measured)\n");
            continue;
        };
        let not_measured = if missing > 0 { format!(" ({missing} not measured)") } else { String::new() };
        let _ = writeln!(
            text,
            "  n {}{not_measured}  mean {:.4}  sigma {}  min {:.4}  max {:.4}",
            sum.n,
            sum.mean,
            opt(sum.sigma),
            sum.min,
            sum.max
        );
        let c = t.capability;
        let shown = c.shown(t.lower, t.upper);
        let capability = if shown.is_empty() {
            "no limits".to_string()
        } else if shown.iter().all(|(_, v)| v.is_none()) {
            "needs at least two values that vary".to_string()
        } else {
            shown.iter().map(|(name, v)| format!("{name} {}", opt(*v))).collect::<Vec<_>>().join("  ")
        };
        let _ = writeln!(
            text,
            "  capability (within sigma {} = mean moving range / 1.128): {capability}",
            opt(t.within_sigma)
        );
        let Some(limits) = t.control else {
            let _ = writeln!(text, "  control limits: need at least two measured parts\n");
            continue;
        };
        let baseline_n = limits.baseline_n;
        let from = match baseline {
            Baseline::Selection => format!("all {baseline_n} parts of the date range"),
            Baseline::RecipeStart(_) => format!("the recipe's first {baseline_n} parts"),
        };
        let _ = writeln!(
            text,
            "  individuals chart ({from}): centre {:.4}  UCL {:.4}  LCL {:.4}; moving range UCL {:.4}",
            limits.centre, limits.upper, limits.lower, limits.moving_range_upper
        );
        if t.violations.is_empty() {
            let _ = writeln!(text, "  run rules: none broken");
        } else {
            let _ = writeln!(text, "  run rules: {} violation(s)", t.violations.len());
            for v in &t.violations {
                let point = measured[v.index];
                let part = &parts[point.part];
                let value = point.value.unwrap_or(f64::NAN);
                let _ = writeln!(
                    text,
                    "    {}  {}  {value:.4}  {}",
                    local_display(&part.record.time_utc),
                    part.record.part_id,
                    v.rule.describe()
                );
            }
        }
        text.push('\n');
    }
    text
}
