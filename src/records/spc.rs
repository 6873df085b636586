//! Statistical process control on one measurement's values in time order:
//! summary statistics, process capability, individuals / moving-range
//! control limits and the run rules. Pure functions on slices.
//!
//! The short-term ("within") sigma is the individuals chart's: the mean
//! moving range of consecutive values over d2 = 1.128 (the d2 of subgroups of
//! two). Cp and Cpk use it, as the capability indices of an individuals chart
//! do (Montgomery, *Introduction to Statistical Quality Control*, 6.4); the
//! summary's sigma is the plain sample standard deviation of all values.

/// d2 for moving ranges of two consecutive values.
pub const D2: f64 = 1.128;
/// D4 for moving ranges of two: the moving-range chart's upper limit factor.
pub const D4: f64 = 3.267;
/// How many of a recipe's first parts set its control limits by default.
pub const BASELINE_PARTS: usize = 25;

/// n, mean, sample sigma (n - 1; `None` below two values), min, max.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    pub n: usize,
    pub mean: f64,
    pub sigma: Option<f64>,
    pub min: f64,
    pub max: f64,
}

pub fn summary(values: &[f64]) -> Option<Summary> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let sigma = (n >= 2).then(|| (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt());
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some(Summary { n, mean, sigma, min, max })
}

/// The mean of |x[i] - x[i-1]|; `None` below two values.
pub fn mean_moving_range(values: &[f64]) -> Option<f64> {
    (values.len() >= 2).then(|| values.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / (values.len() - 1) as f64)
}

/// The within sigma, mean moving range / d2.
pub fn sigma_within(values: &[f64]) -> Option<f64> {
    mean_moving_range(values).map(|mr| mr / D2)
}

/// Capability against the limits a measurement has: Cp and Cpk with both,
/// only CPU with an upper limit alone, only CPL with a lower limit alone.
/// All `None` when sigma is zero or unknown.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Capability {
    pub cp: Option<f64>,
    pub cpk: Option<f64>,
    pub cpu: Option<f64>,
    pub cpl: Option<f64>,
}

impl Capability {
    /// The indices a measurement's limits call for, named as printed, in
    /// one place for `sheen history stats` and the History view: Cp and Cpk
    /// for two limits, CPU for an upper limit alone (a flatness `<=`), CPL for
    /// a lower one alone, none without limits; a value is `None` where the
    /// within sigma is unknown or zero.
    pub fn shown(&self, lower: Option<f64>, upper: Option<f64>) -> Vec<(&'static str, Option<f64>)> {
        match (lower, upper) {
            (Some(_), Some(_)) => vec![("Cp", self.cp), ("Cpk", self.cpk)],
            (None, Some(_)) => vec![("CPU", self.cpu)],
            (Some(_), None) => vec![("CPL", self.cpl)],
            (None, None) => Vec::new(),
        }
    }
}

pub fn capability(mean: f64, sigma: Option<f64>, lower: Option<f64>, upper: Option<f64>) -> Capability {
    let Some(s) = sigma.filter(|s| s.is_finite() && *s > 0.0) else { return Capability::default() };
    let cpu = upper.map(|u| (u - mean) / (3.0 * s));
    let cpl = lower.map(|l| (mean - l) / (3.0 * s));
    match (lower, upper, cpu, cpl) {
        (Some(l), Some(u), Some(cu), Some(cl)) => {
            Capability { cp: Some((u - l) / (6.0 * s)), cpk: Some(cu.min(cl)), cpu: Some(cu), cpl: Some(cl) }
        }
        _ => Capability { cp: None, cpk: None, cpu, cpl },
    }
}

/// Individuals chart limits (centre ± 3 within sigma) and the moving-range
/// chart's upper limit, from a baseline of values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlLimits {
    pub baseline_n: usize,
    pub centre: f64,
    pub sigma: f64,
    pub lower: f64,
    pub upper: f64,
    pub moving_range_upper: f64,
}

/// `None` below two baseline values (no moving range).
pub fn individuals_limits(baseline: &[f64]) -> Option<ControlLimits> {
    let mr = mean_moving_range(baseline)?;
    let centre = baseline.iter().sum::<f64>() / baseline.len() as f64;
    let sigma = mr / D2;
    Some(ControlLimits {
        baseline_n: baseline.len(),
        centre,
        sigma,
        lower: centre - 3.0 * sigma,
        upper: centre + 3.0 * sigma,
        moving_range_upper: D4 * mr,
    })
}

/// A run rule (Western Electric / Nelson rules 1, 2 and 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunRule {
    /// A point beyond the 3-sigma control limits.
    BeyondThreeSigma,
    /// The 9th (or later) point in a row on one side of the centre line.
    NineOnOneSide,
    /// The 6th (or later) point in a row steadily rising or falling.
    SixTrending,
}

impl RunRule {
    pub fn describe(self) -> &'static str {
        match self {
            RunRule::BeyondThreeSigma => "beyond 3 sigma",
            RunRule::NineOnOneSide => "9 in a row on one side of the mean",
            RunRule::SixTrending => "6 in a row rising or falling",
        }
    }
}

/// A point breaking a rule: its index in the values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Violation {
    pub index: usize,
    pub rule: RunRule,
}

/// The points of `values` (time order) breaking each rule against `limits`.
/// A point on the centre line ends a run on one side; an equal neighbour
/// ends a trend. A point is listed once per rule it breaks.
pub fn run_rule_violations(values: &[f64], limits: &ControlLimits) -> Vec<Violation> {
    let mut out = Vec::new();
    let (mut side_run, mut side) = (0usize, 0i8);
    let (mut trend_run, mut trend) = (1usize, 0i8);
    for (i, &v) in values.iter().enumerate() {
        if v > limits.upper || v < limits.lower {
            out.push(Violation { index: i, rule: RunRule::BeyondThreeSigma });
        }
        let s = if v > limits.centre {
            1
        } else if v < limits.centre {
            -1
        } else {
            0
        };
        if s != 0 && s == side {
            side_run += 1;
        } else {
            side = s;
            side_run = usize::from(s != 0);
        }
        if side_run >= 9 {
            out.push(Violation { index: i, rule: RunRule::NineOnOneSide });
        }
        if i > 0 {
            let d = if v > values[i - 1] {
                1
            } else if v < values[i - 1] {
                -1
            } else {
                0
            };
            if d != 0 && d == trend {
                trend_run += 1;
            } else {
                trend = d;
                trend_run = if d != 0 { 2 } else { 1 };
            }
            if trend_run >= 6 {
                out.push(Violation { index: i, rule: RunRule::SixTrending });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_indices_shown_follow_the_limits() {
        let c = super::capability(10.0, Some(1.0), Some(4.0), Some(19.0));
        assert_eq!(c.shown(Some(4.0), Some(19.0)), vec![("Cp", Some(2.5)), ("Cpk", Some(2.0))]);
        let upper = super::capability(10.0, Some(1.0), None, Some(19.0));
        assert_eq!(upper.shown(None, Some(19.0)), vec![("CPU", Some(3.0))]);
        let lower = super::capability(10.0, Some(1.0), Some(4.0), None);
        assert_eq!(lower.shown(Some(4.0), None), vec![("CPL", Some(2.0))]);
        assert!(super::capability(10.0, Some(1.0), None, None).shown(None, None).is_empty());
        assert_eq!(super::capability(10.0, None, None, Some(19.0)).shown(None, Some(19.0)), vec![("CPU", None)]);
    }

    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-6
    }

    // Hand-computed for x = 10, 12, 11, 13, 12:
    // mean 58/5 = 11.6; squared deviations 2.56 .16 .36 1.96 .16 = 5.2,
    // sigma = sqrt(5.2 / 4) = 1.1401754; moving ranges 2 1 2 1, mean 1.5,
    // within sigma 1.5 / 1.128 = 1.3297872.
    const X: [f64; 5] = [10.0, 12.0, 11.0, 13.0, 12.0];

    #[test]
    fn summary_and_within_sigma_by_hand() {
        let s = summary(&X).unwrap();
        assert_eq!((s.n, s.min, s.max), (5, 10.0, 13.0));
        assert!(close(s.mean, 11.6));
        assert!(close(s.sigma.unwrap(), 1.1401754));
        assert!(close(mean_moving_range(&X).unwrap(), 1.5));
        assert!(close(sigma_within(&X).unwrap(), 1.3297872));
        assert_eq!(summary(&[]), None);
        assert_eq!(summary(&[3.0]).unwrap().sigma, None);
        assert_eq!(sigma_within(&[3.0]), None);
    }

    #[test]
    fn capability_by_hand() {
        let sw = sigma_within(&X);
        // Limits 8..16: Cp = 8 / (6 * 1.3297872) = 1.0026667,
        // CPU = 4.4 / 3.9893617 = 1.1029333, CPL = 3.6 / 3.9893617 = 0.9024000.
        let c = capability(11.6, sw, Some(8.0), Some(16.0));
        assert!(close(c.cp.unwrap(), 1.0026667));
        assert!(close(c.cpu.unwrap(), 1.1029333));
        assert!(close(c.cpl.unwrap(), 0.9024));
        assert!(close(c.cpk.unwrap(), 0.9024));
        // Upper limit only (a flatness): CPU, no Cp against a lower limit of 0.
        let c = capability(11.6, sw, None, Some(16.0));
        assert_eq!((c.cp, c.cpk, c.cpl), (None, None, None));
        assert!(close(c.cpu.unwrap(), 1.1029333));
        let c = capability(11.6, sw, Some(8.0), None);
        assert!(close(c.cpl.unwrap(), 0.9024) && c.cpu.is_none() && c.cp.is_none());
        assert_eq!(capability(11.6, Some(0.0), Some(8.0), Some(16.0)), Capability::default());
        assert_eq!(capability(11.6, None, Some(8.0), Some(16.0)), Capability::default());
    }

    #[test]
    fn control_limits_by_hand() {
        // Centre 11.6, UCL 11.6 + 3 * 1.3297872 = 15.5893617, LCL 7.6106383,
        // moving-range UCL 3.267 * 1.5 = 4.9005.
        let l = individuals_limits(&X).unwrap();
        assert_eq!(l.baseline_n, 5);
        assert!(close(l.centre, 11.6) && close(l.sigma, 1.3297872));
        assert!(close(l.upper, 15.5893617) && close(l.lower, 7.6106383));
        assert!(close(l.moving_range_upper, 4.9005));
        assert_eq!(individuals_limits(&[1.0]), None);
    }

    fn unit_limits() -> ControlLimits {
        ControlLimits { baseline_n: 25, centre: 0.0, sigma: 1.0, lower: -3.0, upper: 3.0, moving_range_upper: 3.7 }
    }

    fn flagged(values: &[f64], rule: RunRule) -> Vec<usize> {
        run_rule_violations(values, &unit_limits()).into_iter().filter(|v| v.rule == rule).map(|v| v.index).collect()
    }

    #[test]
    fn beyond_three_sigma() {
        assert_eq!(flagged(&[0.0, 3.0, 3.01, -3.5, -2.9], RunRule::BeyondThreeSigma), vec![2, 3]);
    }

    #[test]
    fn nine_on_one_side() {
        // Alternating magnitudes so no trend rule fires; eight above, then a
        // ninth and a tenth.
        let above = [0.5, 0.2, 0.6, 0.1, 0.7, 0.3, 0.5, 0.2, 0.4, 0.6];
        assert_eq!(flagged(&above, RunRule::NineOnOneSide), vec![8, 9]);
        // A point on the centre line, or one below, restarts the count.
        let broken = [0.5, 0.2, 0.6, 0.1, 0.0, 0.7, 0.3, 0.5, 0.2, 0.4, 0.6];
        assert!(flagged(&broken, RunRule::NineOnOneSide).is_empty());
        let below: Vec<f64> = above.iter().map(|v| -v).collect();
        assert_eq!(flagged(&below, RunRule::NineOnOneSide), vec![8, 9]);
    }

    #[test]
    fn six_rising_or_falling() {
        // Five rising points, then a sixth: flagged at the sixth and seventh.
        let rising = [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 1.0];
        assert_eq!(flagged(&rising, RunRule::SixTrending), vec![5, 6]);
        // A tie breaks the trend.
        let tie = [-1.0, -0.5, 0.0, 0.0, 0.5, 1.0, 1.5];
        assert!(flagged(&tie, RunRule::SixTrending).is_empty());
        let falling = [2.0, 1.5, 1.0, 0.5, 0.0, -0.5];
        assert_eq!(flagged(&falling, RunRule::SixTrending), vec![5]);
        // Five in a row is not yet a trend.
        assert!(flagged(&falling[..5], RunRule::SixTrending).is_empty());
    }
}
