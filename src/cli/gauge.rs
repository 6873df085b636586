//! `sheen gauge type1|rr`: gauge studies (`analysis::gauge`) from a CSV or
//! from the inspection records, printed as a table and, on request, as JSON.
//!
//! From the records, a study takes one recipe's measurement (and a date
//! range): every record's part ID is the part, its operator the operator
//! (`-` where none was recorded), and repeats of the same part by the same
//! operator are its trials in time order. A CSV has a header naming its
//! columns: `part,operator,trial,value` for Gage R&R (trials in file order
//! where there is no `trial` column), a `value` column for a Type-1 study.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::{Args, Subcommand, ValueEnum};

use crate::analysis::gauge::{self, Observation, RrMethod};
use crate::io;
use crate::io::report::study::{StudyPage, write_study_html};
use crate::records::query::HistoryFilter;
use crate::records::time::{RangeEnd, range_bound};
use crate::records::{DbLocation, Store};

#[derive(Debug, Args)]
pub struct GaugeArgs {
    #[command(subcommand)]
    pub study: GaugeStudy,
}

#[derive(Debug, Subcommand)]
pub enum GaugeStudy {
    /// Type-1 study (VDA 5, Bosch booklet 10): at least 25 repeats of one
    /// reference part; Cg, Cgk (capable when both >= 1.33) and the bias's t-test.
    Type1(Type1Args),
    /// Gage R&R (AIAG MSA 4th edition): parts x operators x trials; EV, AV,
    /// GRR, PV, TV, their % of the study variation (and of the tolerance),
    /// ndc and AIAG's band.
    Rr(RrArgs),
}

/// Where the values come from: a CSV, or one measurement of a recipe's records.
#[derive(Debug, Args)]
pub struct StudySource {
    /// A CSV with a header: `part,operator,trial,value` (R&R) or a `value` column (Type-1).
    #[arg(value_name = "CSV", conflicts_with_all = ["db", "recipe"])]
    pub csv: Option<PathBuf>,
    /// Records database: a SQLite file or postgres://user@host:port/db
    /// [default: records.sqlite in the platform data folder].
    #[arg(long, value_name = "FILE|URL")]
    pub db: Option<String>,
    /// The recipe whose records make the study.
    #[arg(long, value_name = "NAME", requires = "measurement")]
    pub recipe: Option<String>,
    /// The measurement (its name in the records) the study is of.
    #[arg(long, value_name = "NAME", requires = "recipe")]
    pub measurement: Option<String>,
    /// Records from this ISO 8601 date or time on.
    #[arg(long, value_name = "DATE")]
    pub since: Option<String>,
    /// Records up to this ISO 8601 time, or to the end of this date.
    #[arg(long, value_name = "DATE")]
    pub until: Option<String>,
    /// Write the result as JSON too.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write the study as a self-contained HTML page too: verdict, figures
    /// and every value it was made of, for the lab file.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
    /// Write the study as an A4 PDF too (the same content as --html).
    #[arg(long, value_name = "FILE")]
    pub pdf: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct Type1Args {
    #[command(flatten)]
    pub source: StudySource,
    /// The reference part's calibrated value xm, in the values' unit.
    #[arg(long, value_name = "XM", allow_negative_numbers = true)]
    pub reference: f64,
    /// The tolerance width T (USL - LSL), in the values' unit.
    #[arg(long, value_name = "T")]
    pub tolerance: f64,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum MethodArg {
    /// Two-way ANOVA with interaction (pooled when p > 0.25).
    Anova,
    /// Average and range, with the manual's K1, K2, K3.
    Range,
}

#[derive(Debug, Args)]
pub struct RrArgs {
    #[command(flatten)]
    pub source: StudySource,
    #[arg(long, value_enum, default_value = "anova")]
    pub method: MethodArg,
    /// The tolerance width T (USL - LSL), for %GRR of the tolerance.
    #[arg(long, value_name = "T")]
    pub tolerance: Option<f64>,
}

pub fn run(args: &GaugeArgs) -> anyhow::Result<()> {
    match &args.study {
        GaugeStudy::Type1(a) => {
            let data = observations(&a.source, Study::Type1)?;
            let values: Vec<f64> = data.iter().map(|o| o.value).collect();
            let study = gauge::type1(&values, a.reference, a.tolerance).context("Type-1 study")?;
            let page = StudyPage::type1(&study, &data, source_text(&a.source));
            print!("{}", page.figures);
            write_json(&a.source, &study)?;
            write_html(&a.source, &page)
        }
        GaugeStudy::Rr(a) => {
            let method = match a.method {
                MethodArg::Anova => RrMethod::Anova,
                MethodArg::Range => RrMethod::Range,
            };
            let data = observations(&a.source, Study::Rr)?;
            let study = gauge::gage_rr(&data, method, a.tolerance).context("Gage R&R study")?;
            let page = StudyPage::rr(&study, &data, source_text(&a.source));
            print!("{}", page.figures);
            write_json(&a.source, &study)?;
            write_html(&a.source, &page)
        }
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Study {
    Type1,
    Rr,
}

/// `--html` and `--pdf`: the study's page for the lab file.
fn write_html(source: &StudySource, page: &StudyPage<'_>) -> anyhow::Result<()> {
    if let Some(path) = &source.html {
        io::atomic::write_atomic(path, |w| write_study_html(w, page)).context("cannot write the study's HTML page")?;
    }
    if let Some(path) = &source.pdf {
        let bytes = io::report::pdf::study_pdf_bytes(page)
            .map_err(|e| anyhow::anyhow!("cannot make the study's PDF {}: {e}", path.display()))?;
        io::atomic::write_atomic(path, |w| w.write_all(&bytes)).context("cannot write the study's PDF")?;
    }
    Ok(())
}

/// Where the study's values came from, for its page.
fn source_text(source: &StudySource) -> String {
    match (&source.csv, &source.recipe, &source.measurement) {
        (Some(csv), _, _) => csv.display().to_string(),
        (None, Some(recipe), Some(measurement)) => {
            let db = DbLocation::from_option(source.db.as_deref()).map_or_else(|e| e.to_string(), |l| l.display());
            let range = match (&source.since, &source.until) {
                (None, None) => String::new(),
                (since, until) => format!(
                    ", {} to {}",
                    since.as_deref().unwrap_or("the first record"),
                    until.as_deref().unwrap_or("the last")
                ),
            };
            format!("records of recipe '{recipe}', measurement '{measurement}', in {db}{range}")
        }
        _ => String::new(),
    }
}

fn write_json(source: &StudySource, value: &impl serde::Serialize) -> anyhow::Result<()> {
    let Some(path) = &source.json else { return Ok(()) };
    let text = serde_json::to_string_pretty(value).context("the study as JSON")?;
    io::atomic::write_atomic(path, |w| w.write_all(text.as_bytes())).context("cannot write the study's JSON")?;
    Ok(())
}

fn observations(source: &StudySource, study: Study) -> anyhow::Result<Vec<Observation>> {
    match (&source.csv, &source.recipe, &source.measurement) {
        (Some(csv), _, _) => {
            let text =
                std::fs::read_to_string(csv).map_err(|source| io::IoError::Read { path: csv.clone(), source })?;
            read_csv(&text, study).with_context(|| csv.display().to_string())
        }
        (None, Some(recipe), Some(measurement)) => from_records(source, recipe, measurement),
        _ => bail!("give the study's CSV, or --recipe and --measurement to take it from the records"),
    }
}

/// One CSV line's fields: commas separate, double quotes quote (`""` is a quote).
fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = Vec::new();
    let mut field = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                field.push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            (c, _) => field.push(c),
        }
    }
    fields.push(field);
    fields.into_iter().map(|f| f.trim().to_string()).collect()
}

fn read_csv(text: &str, study: Study) -> anyhow::Result<Vec<Observation>> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else { bail!("the CSV is empty") };
    let header: Vec<String> = csv_fields(header).into_iter().map(|h| h.to_ascii_lowercase()).collect();
    let column = |name: &str| header.iter().position(|h| h == name);
    let value_col = column("value").context("the CSV has no 'value' column (the header names the columns)")?;
    let (part_col, operator_col) = match study {
        Study::Type1 => (None, None),
        Study::Rr => (
            Some(column("part").context("the CSV has no 'part' column (header: part,operator,trial,value)")?),
            Some(column("operator").context("the CSV has no 'operator' column (header: part,operator,trial,value)")?),
        ),
    };
    let trial_col = column("trial");
    let mut rows: Vec<(usize, f64, Observation)> = Vec::new();
    for (n, line) in lines {
        let fields = csv_fields(line);
        let field = |col: usize, name: &str| {
            fields.get(col).filter(|f| !f.is_empty()).cloned().with_context(|| format!("line {}: no {name}", n + 1))
        };
        let value_text = field(value_col, "value")?;
        let value: f64 = value_text
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .with_context(|| format!("line {}: value '{value_text}' is not a number", n + 1))?;
        let trial = match trial_col.and_then(|c| fields.get(c)).filter(|t| !t.is_empty()) {
            Some(t) => t.parse::<f64>().with_context(|| format!("line {}: trial '{t}' is not a number", n + 1))?,
            None => rows.len() as f64,
        };
        let part = part_col.map(|c| field(c, "part")).transpose()?.unwrap_or_else(|| "reference".into());
        let operator = operator_col.map(|c| field(c, "operator")).transpose()?.unwrap_or_else(|| "-".into());
        rows.push((rows.len(), trial, Observation { part, operator, value }));
    }
    // Trials in their stated order within each part and operator.
    rows.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    if rows.is_empty() {
        bail!("the CSV has a header but no values");
    }
    Ok(rows.into_iter().map(|(_, _, o)| o).collect())
}

fn from_records(source: &StudySource, recipe: &str, measurement: &str) -> anyhow::Result<Vec<Observation>> {
    let location = DbLocation::from_option(source.db.as_deref())?;
    if let DbLocation::Sqlite(path) = &location
        && !path.exists()
    {
        bail!("no records database at {}: nothing has been recorded there (sheen analyze --record)", path.display());
    }
    let filter = HistoryFilter {
        recipe: Some(recipe.to_string()),
        since_utc: source
            .since
            .as_deref()
            .map(|t| range_bound(t, RangeEnd::Since))
            .transpose()
            .map_err(|e| anyhow::anyhow!("--since {e}"))?,
        until_utc: source
            .until
            .as_deref()
            .map(|t| range_bound(t, RangeEnd::Until))
            .transpose()
            .map_err(|e| anyhow::anyhow!("--until {e}"))?,
        station: None,
    };
    let parts = Store::open(&location)?.parts(&filter)?;
    let observations: Vec<Observation> = parts
        .iter()
        .flat_map(|p| {
            p.record.measurements.iter().filter(|m| m.name == measurement).filter_map(move |m| {
                Some(Observation {
                    part: p.record.part_id.clone(),
                    operator: p.record.operator.clone().unwrap_or_else(|| "-".into()),
                    value: m.value?,
                })
            })
        })
        .collect();
    if observations.is_empty() {
        bail!("recipe '{recipe}' has no recorded value of '{measurement}' in {}", location.display());
    }
    Ok(observations)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_take_quotes_and_doubled_quotes() {
        assert_eq!(csv_fields(r#"a, "b,c" ,"say ""hi""",4"#), ["a", "b,c", "say \"hi\"", "4"]);
    }

    #[test]
    fn a_csv_without_its_columns_or_with_text_values_is_refused_by_line() {
        let e = read_csv("part,value\n1,2\n", Study::Rr).unwrap_err().to_string();
        assert!(e.contains("'operator'"), "{e}");
        let e = read_csv("part,operator,trial,value\n1,A,1,2\n1,A,2,x\n", Study::Rr).unwrap_err().to_string();
        assert_eq!(e, "line 3: value 'x' is not a number");
        let got = read_csv("value\n1.5\n2.5\n", Study::Type1).expect("reads");
        assert_eq!(got.iter().map(|o| o.value).collect::<Vec<_>>(), [1.5, 2.5]);
    }

    /// Trials are taken in their stated order, whatever the file's.
    #[test]
    fn trials_follow_the_trial_column() {
        let got = read_csv("part,operator,trial,value\np,A,2,20\np,A,1,10\n", Study::Rr).expect("reads");
        assert_eq!(got.iter().map(|o| o.value).collect::<Vec<_>>(), [10.0, 20.0]);
    }
}
