//! Gauge studies: is this measuring system capable for this tolerance?
//!
//! - [`type1`]: the Type-1 study of VDA 5 and Bosch booklet 10: n >= 25
//!   repeats of one reference part of known value `xm` against a tolerance
//!   `T`; `Cg = 0.2 T / (6 s)`, `Cgk = (0.1 T - |mean - xm|) / (3 s)`,
//!   capable when both are at least 1.33; the bias tested with Student's t.
//! - [`gage_rr`]: the Gage R&R study of AIAG MSA (4th edition): parts x
//!   operators x trials, by the ANOVA method (the part-by-operator
//!   interaction pooled into the error when its p-value exceeds 0.25, as
//!   AIAG does) or by the average-and-range method (the manual's K1, K2, K3
//!   constants); every figure a standard deviation (1 sigma), percentages
//!   of the total variation, of the tolerance where one is given (6 sigma
//!   against it), and the number of distinct categories, truncated.
//!
//! Pure computation: the values come from the records or a CSV (`cli`).

use std::collections::HashMap;

use serde::Serialize;
use statrs::distribution::{ContinuousCDF as _, FisherSnedecor, StudentsT};

/// Why a study cannot be computed; the text names the problem.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GaugeError {
    #[error("a Type-1 study needs at least {needed} repeats; {found} given")]
    TooFewRepeats { needed: usize, found: usize },
    #[error("the tolerance must be a positive width; {0} given")]
    BadTolerance(f64),
    #[error("the values do not vary at all (s = 0): the gauge's resolution is too coarse for a study")]
    NoVariation,
    #[error("a Gage R&R study needs at least {needed} {what}; {found} given")]
    TooFew { what: &'static str, needed: usize, found: usize },
    #[error(
        "the study is unbalanced: part '{part}' by operator '{operator}' has {found} trials where the others have {expected}"
    )]
    Unbalanced { part: String, operator: String, found: usize, expected: usize },
    #[error("a value is not a finite number (part '{part}', operator '{operator}')")]
    NotFinite { part: String, operator: String },
    #[error("the average-and-range method has constants for {what} from 2 to {max}; {found} given")]
    NoConstant { what: &'static str, max: usize, found: usize },
}

/// Capability limit of VDA 5 / Bosch booklet 10 for Cg and Cgk.
pub const TYPE1_CAPABLE: f64 = 1.33;
/// Fewest repeats a Type-1 study takes (VDA 5 asks for 25, Bosch for 50).
pub const TYPE1_MIN_REPEATS: usize = 25;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Type1 {
    pub n: usize,
    pub mean: f64,
    /// Sample standard deviation (n - 1).
    pub s: f64,
    /// `mean - reference`.
    pub bias: f64,
    /// Student's t of the bias, `bias / (s / sqrt n)`, and its two-sided p-value.
    pub t: f64,
    pub bias_p_value: f64,
    /// The bias differs from zero at the 5 % level.
    pub bias_significant: bool,
    pub cg: f64,
    pub cgk: f64,
    pub capable: bool,
    pub reference: f64,
    pub tolerance: f64,
}

/// The Type-1 study of `values` (repeats of one part whose reference value
/// is `reference`) against the tolerance width `tolerance`.
pub fn type1(values: &[f64], reference: f64, tolerance: f64) -> Result<Type1, GaugeError> {
    if values.len() < TYPE1_MIN_REPEATS {
        return Err(GaugeError::TooFewRepeats { needed: TYPE1_MIN_REPEATS, found: values.len() });
    }
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(GaugeError::BadTolerance(tolerance));
    }
    if values.iter().any(|v| !v.is_finite()) {
        return Err(GaugeError::NotFinite { part: "reference".into(), operator: "-".into() });
    }
    let n = values.len();
    let mean = values.iter().sum::<f64>() / n as f64;
    let s = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    if !(s > 0.0) {
        return Err(GaugeError::NoVariation);
    }
    let bias = mean - reference;
    let t = bias / (s / (n as f64).sqrt());
    let dist = StudentsT::new(0.0, 1.0, (n - 1) as f64).map_err(|_| GaugeError::NoVariation)?;
    let bias_p_value = 2.0 * (1.0 - dist.cdf(t.abs()));
    let cg = 0.2 * tolerance / (6.0 * s);
    let cgk = (0.1 * tolerance - bias.abs()) / (3.0 * s);
    Ok(Type1 {
        n,
        mean,
        s,
        bias,
        t,
        bias_p_value,
        bias_significant: bias_p_value < 0.05,
        cg,
        cgk,
        capable: cg >= TYPE1_CAPABLE && cgk >= TYPE1_CAPABLE,
        reference,
        tolerance,
    })
}

/// One measured value of a Gage R&R study.
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    pub part: String,
    pub operator: String,
    pub value: f64,
}

/// How the variance components are estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RrMethod {
    Anova,
    Range,
}

/// One line of the two-way ANOVA table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AnovaRow {
    pub source: &'static str,
    pub df: f64,
    pub ss: f64,
    pub ms: f64,
    /// F against the error (parts and operators against the interaction
    /// when it is kept), and its p-value; `None` on the error and total rows.
    pub f: Option<f64>,
    pub p: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Anova {
    pub rows: Vec<AnovaRow>,
    /// The interaction's p-value exceeded 0.25: it was pooled into the error.
    pub interaction_pooled: bool,
    /// The interaction's standard deviation (0 when pooled).
    pub interaction: f64,
}

/// AIAG's reading of %GRR.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RrBand {
    /// Under 10 %.
    Acceptable,
    /// 10 to 30 %: may be acceptable for the application.
    Conditional,
    /// Over 30 %.
    NotAcceptable,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GageRr {
    pub method: RrMethod,
    pub parts: usize,
    pub operators: usize,
    pub trials: usize,
    /// Repeatability (equipment variation), reproducibility (appraiser
    /// variation), their combination, part variation, total variation:
    /// standard deviations.
    pub ev: f64,
    pub av: f64,
    pub grr: f64,
    pub pv: f64,
    pub tv: f64,
    /// Each as a percentage of the total variation.
    pub percent_ev: f64,
    pub percent_av: f64,
    pub percent_grr: f64,
    pub percent_pv: f64,
    /// 6 GRR as a percentage of the tolerance, where one is given.
    pub percent_tolerance: Option<f64>,
    /// Number of distinct categories, `1.41 PV / GRR` truncated.
    pub ndc: u32,
    /// AIAG's band of %GRR (of the tolerance where given, else of TV).
    pub band: RrBand,
    pub anova: Option<Anova>,
    /// Per operator, per part: the mean and the range of the trials (the
    /// range and mean charts).
    pub cells: Vec<RrCell>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RrCell {
    pub part: String,
    pub operator: String,
    pub mean: f64,
    pub range: f64,
}

/// AIAG MSA 4th edition: K1 by trials, K2 by operators, K3 by parts
/// (1 / d2* of the manual's tables), index = count. The manual's four-digit
/// values, not 1/sqrt(2) and the like: its results are computed with these.
#[allow(clippy::approx_constant)]
const K1: [f64; 4] = [f64::NAN, f64::NAN, 0.8862, 0.5908];
#[allow(clippy::approx_constant)]
const K2: [f64; 4] = [f64::NAN, f64::NAN, 0.7071, 0.5231];
#[allow(clippy::approx_constant)]
const K3: [f64; 11] = [f64::NAN, f64::NAN, 0.7071, 0.5231, 0.4467, 0.4030, 0.3742, 0.3534, 0.3375, 0.3249, 0.3146];

/// The balanced layout of a study: parts and operators in first-seen order,
/// `values[part][operator]` the trials in order.
struct Layout {
    parts: Vec<String>,
    operators: Vec<String>,
    values: Vec<Vec<Vec<f64>>>,
    trials: usize,
}

fn layout(observations: &[Observation]) -> Result<Layout, GaugeError> {
    // Indices in first-seen order, looked up by name once per value: the
    // History view makes a study of a recipe's whole history, where every
    // part ID may be new (a linear search per value was quadratic there).
    fn index_of(names: &mut Vec<String>, index: &mut HashMap<String, usize>, name: &str) -> usize {
        *index.entry(name.to_string()).or_insert_with(|| {
            names.push(name.to_string());
            names.len() - 1
        })
    }
    let (mut parts, mut operators) = (Vec::new(), Vec::new());
    let (mut part_index, mut operator_index) = (HashMap::new(), HashMap::new());
    let mut cells = Vec::with_capacity(observations.len());
    for o in observations {
        if !o.value.is_finite() {
            return Err(GaugeError::NotFinite { part: o.part.clone(), operator: o.operator.clone() });
        }
        let p = index_of(&mut parts, &mut part_index, &o.part);
        let a = index_of(&mut operators, &mut operator_index, &o.operator);
        cells.push((p, a, o.value));
    }
    let mut values = vec![vec![Vec::new(); operators.len()]; parts.len()];
    for (p, a, value) in cells {
        values[p][a].push(value);
    }
    for (what, needed, found) in [("parts", 2, parts.len()), ("operators", 2, operators.len())] {
        if found < needed {
            return Err(GaugeError::TooFew { what, needed, found });
        }
    }
    let trials = values[0][0].len();
    if trials < 2 {
        return Err(GaugeError::TooFew { what: "trials per part and operator", needed: 2, found: trials });
    }
    for (p, row) in values.iter().enumerate() {
        for (a, cell) in row.iter().enumerate() {
            if cell.len() != trials {
                return Err(GaugeError::Unbalanced {
                    part: parts[p].clone(),
                    operator: operators[a].clone(),
                    found: cell.len(),
                    expected: trials,
                });
            }
        }
    }
    Ok(Layout { parts, operators, values, trials })
}

fn mean(v: impl IntoIterator<Item = f64>) -> f64 {
    let (sum, n) = v.into_iter().fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    sum / n as f64
}

fn range(v: &[f64]) -> f64 {
    let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    hi - lo
}

/// The Gage R&R study of `observations` by `method`; `tolerance` (the
/// width USL - LSL) adds %GRR of the tolerance.
pub fn gage_rr(observations: &[Observation], method: RrMethod, tolerance: Option<f64>) -> Result<GageRr, GaugeError> {
    if let Some(t) = tolerance
        && !(t.is_finite() && t > 0.0)
    {
        return Err(GaugeError::BadTolerance(t));
    }
    let l = layout(observations)?;
    let (n, k, r) = (l.parts.len(), l.operators.len(), l.trials);
    let cells: Vec<RrCell> = (0..k)
        .flat_map(|a| (0..n).map(move |p| (p, a)))
        .map(|(p, a)| RrCell {
            part: l.parts[p].clone(),
            operator: l.operators[a].clone(),
            mean: mean(l.values[p][a].iter().copied()),
            range: range(&l.values[p][a]),
        })
        .collect();
    let (ev, av, pv, anova) = match method {
        RrMethod::Range => {
            let constant = |table: &[f64], what: &'static str, count: usize| {
                table.get(count).copied().filter(|c| c.is_finite()).ok_or(GaugeError::NoConstant {
                    what,
                    max: table.len() - 1,
                    found: count,
                })
            };
            let (k1, k2, k3) =
                (constant(&K1, "trials", r)?, constant(&K2, "operators", k)?, constant(&K3, "parts", n)?);
            let r_bar = mean(cells.iter().map(|c| c.range));
            let operator_means: Vec<f64> =
                (0..k).map(|a| mean((0..n).flat_map(|p| l.values[p][a].iter().copied()))).collect();
            let x_diff = range(&operator_means);
            let part_means: Vec<f64> =
                (0..n).map(|p| mean((0..k).flat_map(|a| l.values[p][a].iter().copied()))).collect();
            let ev = r_bar * k1;
            let av = ((x_diff * k2).powi(2) - ev * ev / (n * r) as f64).max(0.0).sqrt();
            let pv = range(&part_means) * k3;
            (ev, av, pv, None)
        }
        RrMethod::Anova => {
            let (ev, av, pv, anova) = anova_components(&l);
            (ev, av, pv, Some(anova))
        }
    };
    let interaction = anova.as_ref().map_or(0.0, |a| a.interaction);
    let grr = (ev * ev + av * av + interaction * interaction).sqrt();
    let tv = (grr * grr + pv * pv).sqrt();
    if !(tv > 0.0) {
        return Err(GaugeError::NoVariation);
    }
    let percent = |x: f64| 100.0 * x / tv;
    let percent_tolerance = tolerance.map(|t| 100.0 * 6.0 * grr / t);
    let judged = percent_tolerance.unwrap_or(percent(grr));
    let band = if judged < 10.0 {
        RrBand::Acceptable
    } else if judged <= 30.0 {
        RrBand::Conditional
    } else {
        RrBand::NotAcceptable
    };
    let ndc = if grr > 0.0 { (1.41 * pv / grr).floor().max(0.0) as u32 } else { u32::MAX };
    Ok(GageRr {
        method,
        parts: n,
        operators: k,
        trials: r,
        ev,
        av,
        grr,
        pv,
        tv,
        percent_ev: percent(ev),
        percent_av: percent(av),
        percent_grr: percent(grr),
        percent_pv: percent(pv),
        percent_tolerance,
        ndc,
        band,
        anova,
        cells,
    })
}

/// AIAG's two-way ANOVA with interaction: the sums of squares, and the
/// variance components from the mean squares (negative estimates are zero).
fn anova_components(l: &Layout) -> (f64, f64, f64, Anova) {
    let (n, k, r) = (l.parts.len(), l.operators.len(), l.trials);
    let all = || l.values.iter().flatten().flatten().copied();
    let grand = mean(all());
    let part_means: Vec<f64> = (0..n).map(|p| mean((0..k).flat_map(|a| l.values[p][a].iter().copied()))).collect();
    let operator_means: Vec<f64> = (0..k).map(|a| mean((0..n).flat_map(|p| l.values[p][a].iter().copied()))).collect();
    let ss_total: f64 = all().map(|x| (x - grand).powi(2)).sum();
    let ss_part: f64 = (k * r) as f64 * part_means.iter().map(|m| (m - grand).powi(2)).sum::<f64>();
    let ss_operator: f64 = (n * r) as f64 * operator_means.iter().map(|m| (m - grand).powi(2)).sum::<f64>();
    let ss_error: f64 = (0..n)
        .flat_map(|p| (0..k).map(move |a| (p, a)))
        .map(|(p, a)| {
            let m = mean(l.values[p][a].iter().copied());
            l.values[p][a].iter().map(|x| (x - m).powi(2)).sum::<f64>()
        })
        .sum();
    let ss_interaction = (ss_total - ss_part - ss_operator - ss_error).max(0.0);
    let (df_p, df_a) = ((n - 1) as f64, (k - 1) as f64);
    let df_pa = df_p * df_a;
    let df_e = (n * k * (r - 1)) as f64;
    let (ms_p, ms_a, ms_pa, ms_e) = (ss_part / df_p, ss_operator / df_a, ss_interaction / df_pa, ss_error / df_e);
    let p_of = |f: f64, d1: f64, d2: f64| {
        FisherSnedecor::new(d1, d2).ok().map(|dist| if f.is_finite() { 1.0 - dist.cdf(f) } else { 0.0 })
    };
    let f_pa = ms_pa / ms_e;
    let p_pa = p_of(f_pa, df_pa, df_e).unwrap_or(0.0);
    let pooled = p_pa > 0.25;
    // Parts and operators are tested against, and their components taken
    // above, the pooled error when the interaction is pooled, else the
    // interaction (AIAG's model with interaction).
    let df_pooled = df_pa + df_e;
    let ms_pooled = (ss_interaction + ss_error) / df_pooled;
    let (ms_against, df_against) = if pooled { (ms_pooled, df_pooled) } else { (ms_pa, df_pa) };
    let (var_e, var_pa) = if pooled { (ms_pooled, 0.0) } else { (ms_e, ((ms_pa - ms_e) / r as f64).max(0.0)) };
    let var_a = ((ms_a - ms_against) / (n * r) as f64).max(0.0);
    let var_p = ((ms_p - ms_against) / (k * r) as f64).max(0.0);
    let tested = |source, df, ss, ms: f64| {
        let f = ms / ms_against;
        AnovaRow { source, df, ss, ms, f: Some(f), p: p_of(f, df, df_against) }
    };
    let mut rows = vec![
        tested("parts", df_p, ss_part, ms_p),
        tested("operators", df_a, ss_operator, ms_a),
        AnovaRow {
            source: "parts x operators",
            df: df_pa,
            ss: ss_interaction,
            ms: ms_pa,
            f: Some(f_pa),
            p: Some(p_pa),
        },
        AnovaRow { source: "repeatability", df: df_e, ss: ss_error, ms: ms_e, f: None, p: None },
    ];
    if pooled {
        let (source, ss) = ("repeatability (pooled)", ss_interaction + ss_error);
        rows.push(AnovaRow { source, df: df_pooled, ss, ms: ms_pooled, f: None, p: None });
    }
    rows.push(AnovaRow { source: "total", df: (n * k * r - 1) as f64, ss: ss_total, ms: f64::NAN, f: None, p: None });
    for row in &mut rows {
        if !row.ms.is_finite() {
            row.ms = 0.0;
        }
    }
    let anova = Anova { rows, interaction_pooled: pooled, interaction: var_pa.sqrt() };
    (var_e.sqrt(), var_a.sqrt(), var_p.sqrt(), anova)
}

/// The study as the command line prints it and the app shows it.
pub fn type1_text(t: &Type1) -> String {
    let verdict = if t.capable { "CAPABLE" } else { "NOT CAPABLE" };
    format!(
        "Type-1 study: {} repeats, reference {}, tolerance {}\n\
         mean {:.6}  s {:.6}  bias {:+.6} (t = {:.2}, p = {:.4}: {})\n\
         Cg {:.2}  Cgk {:.2}  (capable when both >= {:.2}): {verdict}\n",
        t.n,
        t.reference,
        t.tolerance,
        t.mean,
        t.s,
        t.bias,
        t.t,
        t.bias_p_value,
        if t.bias_significant { "significant at 5 %" } else { "not significant" },
        t.cg,
        t.cgk,
        TYPE1_CAPABLE,
    )
}

/// The study as the command line prints it and the app shows it.
pub fn rr_text(r: &GageRr) -> String {
    let mut out = format!(
        "Gage R&R ({}): {} parts x {} operators x {} trials\n",
        match r.method {
            RrMethod::Anova => "ANOVA",
            RrMethod::Range => "average and range",
        },
        r.parts,
        r.operators,
        r.trials
    );
    if let Some(anova) = &r.anova {
        out.push_str("source                   df          SS          MS         F       p\n");
        for row in &anova.rows {
            let f = row.f.map_or(String::new(), |f| format!("{f:9.3}"));
            let p = row.p.map_or(String::new(), |p| format!("{p:7.4}"));
            out.push_str(&format!("{:<22} {:4.0} {:11.5} {:11.5} {f:>9} {p:>7}\n", row.source, row.df, row.ss, row.ms));
        }
        if anova.interaction_pooled {
            out.push_str("(the interaction's p > 0.25: pooled into repeatability)\n");
        }
    }
    out.push_str("                 sigma   % study var\n");
    for (name, sigma, percent) in [
        ("repeatability EV", r.ev, r.percent_ev),
        ("reproducib. AV", r.av, r.percent_av),
        ("GRR", r.grr, r.percent_grr),
        ("part PV", r.pv, r.percent_pv),
        ("total TV", r.tv, 100.0),
    ] {
        out.push_str(&format!("{name:<16} {sigma:8.5} {percent:9.2} %\n"));
    }
    if let Some(t) = r.percent_tolerance {
        out.push_str(&format!("%GRR of the tolerance (6 GRR / T): {t:.2} %\n"));
    }
    let band = match r.band {
        RrBand::Acceptable => "acceptable (< 10 %)",
        RrBand::Conditional => "conditionally acceptable (10-30 %)",
        RrBand::NotAcceptable => "not acceptable (> 30 %)",
    };
    out.push_str(&format!("ndc {}  AIAG: {band}\n", r.ndc));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// AIAG MSA 4th edition, the Gage R&R example: 10 parts, appraisers A,
    /// B, C, 3 trials; rows are trials, columns parts.
    const MSA_EXAMPLE: [(&str, [[f64; 10]; 3]); 3] = [
        (
            "A",
            [
                [0.29, -0.56, 1.34, 0.47, -0.80, 0.02, 0.59, -0.31, 2.26, -1.36],
                [0.41, -0.68, 1.17, 0.50, -0.92, -0.11, 0.75, -0.20, 1.99, -1.25],
                [0.64, -0.58, 1.27, 0.64, -0.84, -0.21, 0.66, -0.17, 2.01, -1.31],
            ],
        ),
        (
            "B",
            [
                [0.08, -0.47, 1.19, 0.01, -0.56, -0.20, 0.47, -0.63, 1.80, -1.68],
                [0.25, -1.22, 0.94, 1.03, -1.20, 0.22, 0.55, 0.08, 2.12, -1.62],
                [0.07, -0.68, 1.34, 0.20, -1.28, 0.06, 0.83, -0.34, 2.19, -1.50],
            ],
        ),
        (
            "C",
            [
                [0.04, -1.38, 0.88, 0.14, -1.46, -0.29, 0.02, -0.46, 1.77, -1.49],
                [-0.11, -1.13, 1.09, 0.20, -1.07, -0.67, 0.01, -0.56, 1.45, -1.77],
                [-0.15, -0.96, 0.67, 0.11, -1.45, -0.49, 0.21, -0.49, 1.87, -2.16],
            ],
        ),
    ];

    pub fn msa_example() -> Vec<Observation> {
        let mut out = Vec::new();
        for (operator, trials) in MSA_EXAMPLE {
            for trial in trials {
                for (p, value) in trial.iter().enumerate() {
                    out.push(Observation { part: format!("{}", p + 1), operator: operator.into(), value: *value });
                }
            }
        }
        out
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    /// The manual's average-and-range figures: R-bar 0.3417, X-diff 0.4446,
    /// Rp 3.511; EV 0.20188, AV 0.22963, GRR 0.30575, PV 1.10456, TV
    /// 1.14610, %EV 17.62, %AV 20.04, %GRR 26.68, %PV 96.38, ndc 5.
    #[test]
    fn the_average_and_range_method_gives_the_msa_manuals_figures() {
        let rr = gage_rr(&msa_example(), RrMethod::Range, None).expect("study");
        assert_eq!((rr.parts, rr.operators, rr.trials), (10, 3, 3));
        for (name, got, want) in [
            ("EV", rr.ev, 0.20188),
            ("AV", rr.av, 0.22963),
            ("GRR", rr.grr, 0.30575),
            ("PV", rr.pv, 1.10456),
            ("TV", rr.tv, 1.14610),
        ] {
            assert!(close(got, want, 0.000_06), "{name}: {got} against {want}");
        }
        for (name, got, want) in [
            ("%EV", rr.percent_ev, 17.62),
            ("%AV", rr.percent_av, 20.04),
            ("%GRR", rr.percent_grr, 26.68),
            ("%PV", rr.percent_pv, 96.38),
        ] {
            // The manual divides its rounded sigmas: its last digit may differ by one.
            assert!(close(got, want, 0.011), "{name}: {got} against {want}");
        }
        assert_eq!(rr.ndc, 5);
        assert_eq!(rr.band, RrBand::Conditional);
    }

    /// The manual's ANOVA table (SS: appraiser 3.1673, parts 88.3619,
    /// appraiser by part 0.3590, equipment 2.7589, total 94.6471); the
    /// interaction is not significant and is pooled.
    #[test]
    fn the_anova_method_gives_the_msa_manuals_table() {
        let rr = gage_rr(&msa_example(), RrMethod::Anova, Some(6.0)).expect("study");
        let anova = rr.anova.as_ref().expect("table");
        let ss = |source: &str| anova.rows.iter().find(|r| r.source == source).map(|r| r.ss).expect(source);
        for (source, want) in [
            ("operators", 3.1673),
            ("parts", 88.3619),
            ("parts x operators", 0.3590),
            ("repeatability", 2.7589),
            ("total", 94.6471),
        ] {
            assert!(close(ss(source), want, 0.000_06), "SS {source}: {} against {want}", ss(source));
        }
        assert!(anova.interaction_pooled, "F = 0.434 for the interaction: pooled");
        // Hand computation from the pooled mean squares.
        let ms_pooled: f64 = (0.3590 + 2.7589) / 78.0;
        assert!(close(rr.ev, ms_pooled.sqrt(), 0.000_1), "EV {}", rr.ev);
        assert!(close(rr.av, ((3.1673 / 2.0 - ms_pooled) / 30.0).sqrt(), 0.000_1), "AV {}", rr.av);
        assert!(close(rr.pv, ((88.3619 / 9.0 - ms_pooled) / 9.0).sqrt(), 0.000_1), "PV {}", rr.pv);
        assert_eq!(rr.ndc, 4);
        let percent_tolerance = rr.percent_tolerance.expect("with a tolerance");
        assert!(close(percent_tolerance, 100.0 * 6.0 * rr.grr / 6.0, 1e-9));
    }

    /// Type-1 against a hand computation: 25 values 10.001 / 9.999
    /// alternating (mean 10.00004), xm = 10.001, T = 0.03.
    #[test]
    fn a_type1_study_matches_a_hand_computation() {
        let values: Vec<f64> = (0..25).map(|i| if i % 2 == 0 { 10.001 } else { 9.999 }).collect();
        let t = type1(&values, 10.001, 0.03).expect("study");
        let mean = (13.0 * 10.001 + 12.0 * 9.999) / 25.0;
        let s = ((13.0 * (10.001f64 - mean).powi(2) + 12.0 * (9.999f64 - mean).powi(2)) / 24.0).sqrt();
        assert!(close(t.mean, mean, 1e-12) && close(t.s, s, 1e-12));
        assert!(close(t.cg, 0.2 * 0.03 / (6.0 * s), 1e-9), "Cg {}", t.cg);
        assert!(close(t.cgk, (0.1 * 0.03 - (mean - 10.001f64).abs()) / (3.0 * s), 1e-9), "Cgk {}", t.cgk);
        assert!(!t.capable, "Cg {:.3} Cgk {:.3}: s of 1 um is too much for 30 um", t.cg, t.cgk);
        // The bias (0.00096) is large against s / sqrt(n) (0.0002): t = -4.7.
        assert!(t.bias_significant && t.bias_p_value < 0.05, "p {}", t.bias_p_value);
        let capable = type1(&values, 10.00004, 0.3).expect("study");
        assert!(capable.capable && !capable.bias_significant, "{capable:?}");
    }

    /// Operators that disagree part by part (A reads part 1 high, B part 2)
    /// make a significant interaction: kept, not pooled, and part of GRR.
    #[test]
    fn a_significant_interaction_is_kept_in_grr() {
        let mut data = Vec::new();
        for (part, operator, base) in
            [("1", "A", 10.5), ("1", "B", 10.0), ("2", "A", 20.0), ("2", "B", 20.5), ("3", "A", 30.0), ("3", "B", 30.0)]
        {
            for noise in [-0.01, 0.01, 0.0] {
                data.push(Observation { part: part.into(), operator: operator.into(), value: base + noise });
            }
        }
        let rr = gage_rr(&data, RrMethod::Anova, None).expect("study");
        let anova = rr.anova.as_ref().expect("table");
        assert!(!anova.interaction_pooled && anova.interaction > 0.2, "{anova:?}");
        let total: f64 = anova.rows.iter().filter(|r| r.source != "total").map(|r| r.ss).sum();
        let listed = anova.rows.iter().find(|r| r.source == "total").expect("total").ss;
        assert!((total - listed).abs() < 1e-9, "the sums of squares add up: {total} against {listed}");
        assert!((rr.grr - (rr.ev.powi(2) + rr.av.powi(2) + anova.interaction.powi(2)).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn bad_studies_are_refused_with_the_reason() {
        assert_eq!(type1(&[1.0; 10], 1.0, 1.0), Err(GaugeError::TooFewRepeats { needed: 25, found: 10 }));
        assert_eq!(type1(&[1.0; 30], 1.0, 1.0), Err(GaugeError::NoVariation));
        assert_eq!(type1(&[1.0, 2.0].repeat(15), 1.0, 0.0), Err(GaugeError::BadTolerance(0.0)));
        let mut unbalanced = msa_example();
        unbalanced.pop();
        assert!(matches!(gage_rr(&unbalanced, RrMethod::Anova, None), Err(GaugeError::Unbalanced { .. })));
        let one_operator: Vec<Observation> = msa_example().into_iter().filter(|o| o.operator == "A").collect();
        assert_eq!(
            gage_rr(&one_operator, RrMethod::Range, None),
            Err(GaugeError::TooFew { what: "operators", needed: 2, found: 1 })
        );
        let flat: Vec<Observation> = msa_example().into_iter().map(|o| Observation { value: 1.0, ..o }).collect();
        assert_eq!(gage_rr(&flat, RrMethod::Anova, None), Err(GaugeError::NoVariation));
    }
}
