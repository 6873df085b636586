//! A gauge study (`analysis::gauge`) as one self-contained HTML page for the
//! lab file: what was studied and from which data, the verdict, the figures
//! as `sheen gauge` prints them, and every value the study was made of.

use std::io::Write;

use super::html::escape;
use crate::analysis::gauge::{self, GageRr, Observation, RrBand, RrMethod, Type1};

/// What the page shows.
pub struct StudyPage<'a> {
    /// "Type-1 study", "Gage R&R (ANOVA)".
    pub title: &'a str,
    /// The verdict line in large type: "CAPABLE · Cg 3.43 · Cgk 3.08".
    pub headline: String,
    /// Whether the verdict is good (green) or not (red).
    pub good: bool,
    /// The figures as the command line prints them.
    pub figures: String,
    /// Where the values came from (a CSV, or a recipe's records).
    pub source: String,
    pub data: &'a [Observation],
}

impl<'a> StudyPage<'a> {
    /// A Type-1 study's page: CAPABLE or NOT CAPABLE with Cg and Cgk.
    pub fn type1(study: &Type1, data: &'a [Observation], source: String) -> Self {
        let verdict = if study.capable { "CAPABLE" } else { "NOT CAPABLE" };
        StudyPage {
            title: "Type-1 study",
            headline: format!("{verdict} · Cg {:.2} · Cgk {:.2}", study.cg, study.cgk),
            good: study.capable,
            figures: gauge::type1_text(study),
            source,
            data,
        }
    }

    /// A Gage R&R's page: AIAG's band with %GRR (of the tolerance where
    /// one is given) and ndc.
    pub fn rr(study: &GageRr, data: &'a [Observation], source: String) -> Self {
        let band = match study.band {
            RrBand::Acceptable => "ACCEPTABLE",
            RrBand::Conditional => "CONDITIONALLY ACCEPTABLE",
            RrBand::NotAcceptable => "NOT ACCEPTABLE",
        };
        let judged = study.percent_tolerance.unwrap_or(study.percent_grr);
        StudyPage {
            title: match study.method {
                RrMethod::Anova => "Gage R&R (ANOVA)",
                RrMethod::Range => "Gage R&R (average and range)",
            },
            headline: format!("{band} · %GRR {judged:.1} % · ndc {}", study.ndc),
            good: study.band == RrBand::Acceptable,
            figures: gauge::rr_text(study),
            source,
            data,
        }
    }
}

pub fn write_study_html(w: &mut impl Write, page: &StudyPage<'_>) -> std::io::Result<()> {
    let rgb = if page.good { "22,128,60" } else { "190,30,45" };
    writeln!(w, "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">")?;
    writeln!(w, "<title>{} · Sheen</title>", escape(page.title))?;
    writeln!(
        w,
        "<style>body {{ font-family: sans-serif; font-size: 10pt; max-width: 182mm; margin: auto; }} \
         .verdict {{ display: inline-block; color: white; font-size: 20pt; font-weight: bold; padding: 4pt 12pt; \
         border-radius: 4pt; background: rgb({rgb}); }} pre {{ font-size: 9pt; }} \
         table {{ border-collapse: collapse; }} td, th {{ padding: 1pt 8pt; border-bottom: 1px solid #ddd; text-align: left; }} \
         td.num {{ text-align: right; font-variant-numeric: tabular-nums; }}</style></head><body>"
    )?;
    writeln!(w, "<h1>{}</h1>", escape(page.title))?;
    writeln!(w, "<p><span class=\"verdict\">{}</span></p>", escape(&page.headline))?;
    writeln!(w, "<p>Data: {}</p>", escape(&page.source))?;
    writeln!(w, "<pre>{}</pre>", escape(&page.figures))?;
    writeln!(w, "<h2>Data ({} values)</h2>", page.data.len())?;
    writeln!(w, "<table><tr><th>#</th><th>part</th><th>operator</th><th>value</th></tr>")?;
    for (i, o) in page.data.iter().enumerate() {
        writeln!(
            w,
            "<tr><td class=\"num\">{}</td><td>{}</td><td>{}</td><td class=\"num\">{}</td></tr>",
            i + 1,
            escape(&o.part),
            escape(&o.operator),
            o.value
        )?;
    }
    writeln!(w, "</table>\n<p>Sheen {}</p>\n</body></html>", env!("CARGO_PKG_VERSION"))
}
