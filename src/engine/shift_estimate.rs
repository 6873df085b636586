//! Estimating the phase shifts actually recorded, from the images:
//! a wrong shift order or sign is the most common cause of garbage phase in
//! imported data, and the images themselves say what the steps were.
//!
//! Per set, on a subsample of bright, unsaturated, well-modulated pixels:
//! an initial estimate by principal component analysis of the mean-free
//! samples (Vargas et al. 2011: the two main temporal components are
//! `cos delta_k` and `sin delta_k` up to a rotation), refined by the advanced
//! iterative algorithm of Wang & Han (2004), with per-pixel background and
//! modulation: alternately the per-pixel least-squares phase for the current
//! shifts (Eqs. 2-4) and the per-image least-squares shift for the current
//! phases, until the shifts stop moving.
//!
//! From one set alone the direction of the shifts cannot be known: the images
//! of `Phi + delta_k` and of `-Phi - delta_k` are identical. What the data do
//! fix is the direction in which each set's phase grows across the image,
//! and all sets of a camera must grow the same way (the phase of every set
//! grows with the projector column). So the sets are compared with each
//! other through their phase gradients, and the one remaining sign is either
//! given (the direction the phase grows in the image, when the rig is known)
//! or chosen to agree best with the manifest.

use std::f64::consts::{PI, TAU};

use super::fringe::{CameraFringes, FringeSetInfo, FringeStack};
use super::phase_shift::normal_matrix_inverse;

/// At most this many pixels enter the estimate (a regular subsample).
const MAX_PIXELS: usize = 20_000;
/// Groups of pixels whose separate estimates give the spread.
const GROUPS: usize = 8;
const MAX_ITERATIONS: usize = 60;

/// Steps that differ by less than this from the manifest's agree (5 degrees).
pub const DEFAULT_TOLERANCE_RAD: f64 = 5.0 * PI / 180.0;
/// The manifest's shifts agree, whatever the estimate's steps, when they
/// explain the images within this factor of the estimate's residual
/// ([`ShiftEstimate::manifest_fit_ratio`]). Correct data give about 1 (the
/// estimate itself is biased by harmonics where a set spans little of a
/// period); a swapped, repeated or missing image gives several.
pub const MANIFEST_FIT_RATIO: f64 = 2.0;

/// The shifts estimated for one set.
#[derive(Clone, Debug, PartialEq)]
pub struct ShiftEstimate {
    /// `delta_k`, with `delta_0 = 0` and a positive mean step (the sign
    /// itself is not in the data; see the module notes).
    pub shifts_rad: Vec<f64>,
    /// Consecutive steps `delta_{k+1} - delta_k`, in (-pi, pi].
    pub steps_rad: Vec<f64>,
    /// Per step, the standard deviation of its estimate over 8 groups of pixels.
    pub step_spread_rad: Vec<f64>,
    /// Mean spatial gradient of the phase computed with `shifts_rad`
    /// (rad per pixel along u, along v).
    pub phase_gradient: [f64; 2],
    pub pixels: usize,
    pub iterations: usize,
    /// RMS of the fit residual relative to the modulation.
    pub relative_residual: f64,
    /// How well the manifest's shifts explain the images against the
    /// estimated ones: the residual of a per-pixel fit with the fringe's
    /// first harmonics (projector gamma) for the manifest's shifts over that
    /// for the estimate. Near 1 or below: the manifest fits as well as the
    /// data allow; a swapped or missing image fits far worse. `None` where
    /// not asked for or the shift count leaves no residual.
    pub manifest_fit_ratio: Option<f64>,
}

/// Why a set's shifts could not be estimated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EstimateFault {
    #[error("only {found} pixels are bright, unsaturated and well modulated (at least 200 needed)")]
    TooFewPixels { found: usize },
    #[error("the phase varies too little across the image to tell the shifts apart")]
    PhaseTooUniform,
    #[error("the estimate did not settle (the images may not be phase-shifted fringes)")]
    NoConvergence,
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_pi(x: f64) -> f64 {
    let y = (x + PI).rem_euclid(TAU) - PI;
    if y <= -PI { y + TAU } else { y }
}

/// Consecutive steps of a shift list, wrapped to (-pi, pi].
pub fn steps_of(shifts_rad: &[f64]) -> Vec<f64> {
    shifts_rad.windows(2).map(|w| wrap_pi(w[1] - w[0])).collect()
}

/// Pixels used for the estimate: each with its right and lower neighbours
/// (for the phase gradient), all unsaturated and well modulated.
fn select_pixels(stack: &FringeStack, saturation_threshold: u16) -> Vec<usize> {
    let (w, h) = (stack.width, stack.height);
    if w < 2 || h < 2 {
        return Vec::new();
    }
    let step = (((w - 1) * (h - 1)) as f64 / MAX_PIXELS as f64).sqrt().ceil().max(1.0) as usize;
    let range = |p: usize| -> Option<f64> {
        let (mut lo, mut hi) = (u16::MAX, 0u16);
        for k in 0..stack.shifts {
            let v = stack.sample(k, p);
            if v >= saturation_threshold {
                return None;
            }
            lo = lo.min(v);
            hi = hi.max(v);
        }
        Some(f64::from(hi - lo))
    };
    let mut candidates = Vec::new();
    for v in (0..h - 1).step_by(step) {
        for u in (0..w - 1).step_by(step) {
            let p = v * w + u;
            if let (Some(a), Some(b), Some(c)) = (range(p), range(p + 1), range(p + w)) {
                candidates.push((p, a.min(b).min(c)));
            }
        }
    }
    if candidates.is_empty() {
        return Vec::new();
    }
    let mut ranges: Vec<f64> = candidates.iter().map(|c| c.1).collect();
    let i90 = ((ranges.len() * 9) / 10).min(ranges.len() - 1);
    let p90 = *ranges.select_nth_unstable_by(i90, f64::total_cmp).1;
    let floor = (0.25 * p90).max(6.0);
    candidates.into_iter().filter(|c| c.1 >= floor).map(|c| c.0).collect()
}

/// Per-pixel least-squares fit for shifts with inverse normal matrix `c`:
/// `(A, B cos Phi, B sin Phi)`.
fn fit(samples: &[f64], cos: &[f64], sin: &[f64], c: &[[f64; 3]; 3]) -> [f64; 3] {
    let mut b = [0.0; 3];
    for ((&i, &ck), &sk) in samples.iter().zip(cos).zip(sin) {
        b[0] += i;
        b[1] += i * ck;
        b[2] += i * sk;
    }
    let a: [f64; 3] = std::array::from_fn(|r| c[r][0] * b[0] + c[r][1] * b[1] + c[r][2] * b[2]);
    // I = a0 + a1 cos d + a2 sin d = A + B cos(Phi + d): B cos Phi = a1, B sin Phi = -a2.
    [a[0], a[1], -a[2]]
}

/// Estimates the shifts of one stack (see the module notes).
pub fn estimate_shifts(stack: &FringeStack, saturation_threshold: u16) -> Result<ShiftEstimate, EstimateFault> {
    estimate_shifts_against(stack, saturation_threshold, None)
}

/// [`estimate_shifts`], and how well `manifest_shifts_rad` explains the
/// same pixels ([`ShiftEstimate::manifest_fit_ratio`]).
pub fn estimate_shifts_against(
    stack: &FringeStack,
    saturation_threshold: u16,
    manifest_shifts_rad: Option<&[f64]>,
) -> Result<ShiftEstimate, EstimateFault> {
    let n = stack.shifts;
    let pixels = select_pixels(stack, saturation_threshold);
    if pixels.len() < 200 {
        return Err(EstimateFault::TooFewPixels { found: pixels.len() });
    }
    let samples: Vec<Vec<f64>> =
        pixels.iter().map(|&p| (0..n).map(|k| f64::from(stack.sample(k, p))).collect()).collect();

    // Initial shifts: the two main temporal components of the mean-free samples.
    let mut cov = nalgebra::DMatrix::<f64>::zeros(n, n);
    for s in &samples {
        let mean = s.iter().sum::<f64>() / n as f64;
        let x = nalgebra::DVector::from_iterator(n, s.iter().map(|v| v - mean));
        cov += &x * x.transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(cov);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let (u1, u2) = (eig.eigenvectors.column(order[0]), eig.eigenvectors.column(order[1]));
    let mut shifts: Vec<f64> = (0..n).map(|k| u2[k].atan2(u1[k])).collect();
    normalise(&mut shifts);

    let mut iterations = 0;
    let mut change = f64::INFINITY;
    while iterations < MAX_ITERATIONS && change > 1e-9 {
        iterations += 1;
        let next = refine(&samples, &shifts, None)?;
        change = next.iter().zip(&shifts).map(|(a, b)| wrap_pi(a - b).abs()).fold(0.0, f64::max);
        shifts = next;
    }
    // Slow convergence is fine once the shifts barely move.
    if change > 1e-4 {
        return Err(EstimateFault::NoConvergence);
    }
    let mut steps = steps_of(&shifts);
    // The data cannot tell the sign; report a positive mean step.
    let (sum_s, sum_c) = steps.iter().fold((0.0, 0.0), |(s, c), d| (s + d.sin(), c + d.cos()));
    let flip = sum_s.atan2(sum_c) < 0.0;
    if flip {
        shifts.iter_mut().for_each(|d| *d = wrap_pi(-*d));
        steps = steps_of(&shifts);
    }

    // Spread: the same per-image fit on groups of pixels.
    let mut group_steps: Vec<Vec<f64>> = Vec::new();
    for g in 0..GROUPS {
        if let Ok(s) = refine(&samples, &shifts, Some(g)) {
            group_steps.push(steps_of(&s));
        }
    }
    let step_spread_rad = (0..n - 1)
        .map(|k| {
            if group_steps.len() < 2 {
                return f64::NAN;
            }
            let diffs: Vec<f64> = group_steps.iter().map(|s| wrap_pi(s[k] - steps[k])).collect();
            let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
            (diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (diffs.len() - 1) as f64).sqrt()
        })
        .collect();

    // Phase gradient and residual with the final shifts.
    let c = normal_matrix_inverse(&shifts, full_mask(n)).ok_or(EstimateFault::PhaseTooUniform)?;
    let (cos, sin): (Vec<f64>, Vec<f64>) = shifts.iter().map(|d| (d.cos(), d.sin())).unzip();
    let phase_at = |p: usize| {
        let s: Vec<f64> = (0..n).map(|k| f64::from(stack.sample(k, p))).collect();
        let a = fit(&s, &cos, &sin, &c);
        a[2].atan2(a[1])
    };
    let (mut gu, mut gv) = (0.0, 0.0);
    let (mut rss, mut b2) = (0.0, 0.0);
    for (&p, s) in pixels.iter().zip(&samples) {
        let a = fit(s, &cos, &sin, &c);
        let phi = a[2].atan2(a[1]);
        gu += wrap_pi(phase_at(p + 1) - phi);
        gv += wrap_pi(phase_at(p + stack.width) - phi);
        let b = a[1].hypot(a[2]);
        for k in 0..n {
            let model = a[0] + a[1] * cos[k] - a[2] * sin[k];
            rss += (s[k] - model).powi(2);
        }
        b2 += b * b * n as f64;
    }
    let m = pixels.len() as f64;
    let manifest_fit_ratio = manifest_shifts_rad.filter(|man| man.len() == n).and_then(|man| {
        let harmonics = harmonics_for(n);
        // Quantisation noise (1/12 DN^2 per residual sample) keeps noise-free data from dividing zero by zero.
        let floor = pixels.len() as f64 * (n - 1 - 2 * harmonics) as f64 / 12.0;
        let manifest = harmonic_rss(&samples, man, harmonics)?;
        let estimated = harmonic_rss(&samples, &shifts, harmonics)?;
        Some((manifest + floor) / (estimated + floor))
    });
    Ok(ShiftEstimate {
        shifts_rad: shifts,
        steps_rad: steps,
        step_spread_rad,
        phase_gradient: [gu / m, gv / m],
        pixels: pixels.len(),
        iterations,
        relative_residual: (rss / b2.max(f64::MIN_POSITIVE)).sqrt(),
        manifest_fit_ratio,
    })
}

fn full_mask(n: usize) -> u32 {
    if n >= 32 { u32::MAX } else { (1u32 << n) - 1 }
}

/// `delta_0 = 0`, every shift in (-pi, pi].
fn normalise(shifts: &mut [f64]) {
    let d0 = shifts[0];
    shifts.iter_mut().for_each(|d| *d = wrap_pi(*d - d0));
}

/// One iteration of the advanced iterative algorithm: per-pixel phases for
/// `shifts`, then per-image shifts for those phases (over the pixels of
/// `group` only, when given).
fn refine(samples: &[Vec<f64>], shifts: &[f64], group: Option<usize>) -> Result<Vec<f64>, EstimateFault> {
    let n = shifts.len();
    let c = normal_matrix_inverse(shifts, full_mask(n)).ok_or(EstimateFault::PhaseTooUniform)?;
    let (cos, sin): (Vec<f64>, Vec<f64>) = shifts.iter().map(|d| (d.cos(), d.sin())).unzip();
    // Normal equations per image: y_k = X1 c_k - X2 s_k with X1 = B cos Phi, X2 = B sin Phi.
    let (mut s11, mut s12, mut s22) = (0.0, 0.0, 0.0);
    let mut r1 = vec![0.0; n];
    let mut r2 = vec![0.0; n];
    for (j, s) in samples.iter().enumerate() {
        if group.is_some_and(|g| j % GROUPS != g) {
            continue;
        }
        let a = fit(s, &cos, &sin, &c);
        let (x1, x2) = (a[1], a[2]);
        s11 += x1 * x1;
        s12 += x1 * x2;
        s22 += x2 * x2;
        for k in 0..n {
            let y = s[k] - a[0];
            r1[k] += x1 * y;
            r2[k] -= x2 * y;
        }
    }
    // [s11, -s12; -s12, s22] [c; s] = [r1; r2]
    let det = s11 * s22 - s12 * s12;
    if !(det > 1e-6 * (s11 + s22).powi(2)) {
        return Err(EstimateFault::PhaseTooUniform);
    }
    let mut next: Vec<f64> = (0..n)
        .map(|k| {
            let ck = (s22 * r1[k] + s12 * r2[k]) / det;
            let sk = (s12 * r1[k] + s11 * r2[k]) / det;
            sk.atan2(ck)
        })
        .collect();
    normalise(&mut next);
    Ok(next)
}

/// Harmonics of the fringe profile fitted per pixel with `n` shifts: the
/// model `A + sum_h (a_h cos h delta + b_h sin h delta)` keeps at least two
/// samples for the residual and stays below the aliasing order `n / 2`.
fn harmonics_for(n: usize) -> usize {
    (n.saturating_sub(3) / 2).clamp(1, 3)
}

/// Residual sum of squares of the per-pixel least-squares fit of
/// `A + sum_h (a_h cos h delta_k + b_h sin h delta_k)` for the given shifts,
/// over the pixels of [`estimate_shifts`]; `None` where the shift count
/// leaves no residual or the shifts do not separate the terms.
fn harmonic_rss(samples: &[Vec<f64>], shifts: &[f64], harmonics: usize) -> Option<f64> {
    let terms = 1 + 2 * harmonics;
    if shifts.len() <= terms {
        return None;
    }
    let design = nalgebra::DMatrix::<f64>::from_fn(shifts.len(), terms, |k, t| {
        let h = t.div_ceil(2) as f64;
        match t {
            0 => 1.0,
            t if t % 2 == 1 => (h * shifts[k]).cos(),
            _ => (h * shifts[k]).sin(),
        }
    });
    let normal = design.transpose() * &design;
    // Relative conditioning: equal or nearly equal shifts cannot separate the harmonics.
    let eig = nalgebra::SymmetricEigen::new(normal.clone());
    let (lo, hi) = eig.eigenvalues.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| (lo.min(e), hi.max(e)));
    if !(lo > 1e-6 * hi) {
        return None;
    }
    // Residual maker I - X (X'X)^-1 X', applied to every pixel's samples.
    let inverse = normal.try_inverse()?;
    let residual_maker =
        nalgebra::DMatrix::<f64>::identity(shifts.len(), shifts.len()) - &design * inverse * design.transpose();
    let mut rss = 0.0;
    for s in samples {
        let y = nalgebra::DVector::from_column_slice(s);
        rss += (&residual_maker * y).norm_squared();
    }
    Some(rss)
}

/// The check's conclusion for one set.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// The manifest's steps agree with the data.
    Agrees,
    /// The data run the other way: the images are in reverse shift order, or
    /// the shift sign differs.
    Reversed,
    /// The steps differ in size or vary: wrong shift count, wrong order
    /// (e.g. `10.bmp` sorted before `2.bmp`), or uneven shifts.
    Mismatch,
    /// Could not be estimated (why).
    Unknown(String),
}

impl Verdict {
    pub fn is_problem(&self) -> bool {
        matches!(self, Verdict::Reversed | Verdict::Mismatch)
    }

    pub fn label(&self) -> &'static str {
        match self {
            Verdict::Agrees => "ok",
            Verdict::Reversed => "REVERSED",
            Verdict::Mismatch => "MISMATCH",
            Verdict::Unknown(_) => "unknown",
        }
    }
}

/// One set of one camera, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct SetShiftCheck {
    pub set: usize,
    pub period_px: f64,
    /// The manifest's consecutive steps.
    pub manifest_steps_rad: Vec<f64>,
    /// The estimated steps, with the sign resolved across the sets (see
    /// the module notes); empty when not estimated.
    pub estimated_steps_rad: Vec<f64>,
    pub step_spread_rad: Vec<f64>,
    /// Largest difference between estimated and manifest steps.
    pub max_difference_rad: f64,
    /// [`ShiftEstimate::manifest_fit_ratio`], where computed.
    pub manifest_fit_ratio: Option<f64>,
    pub verdict: Verdict,
    /// One sentence for the user.
    pub message: String,
}

/// Direction in which the phase grows in the camera image, when known.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PhaseDirection {
    Right,
    Left,
    Down,
    Up,
}

impl PhaseDirection {
    fn vector(self) -> [f64; 2] {
        match self {
            PhaseDirection::Right => [1.0, 0.0],
            PhaseDirection::Left => [-1.0, 0.0],
            PhaseDirection::Down => [0.0, 1.0],
            PhaseDirection::Up => [0.0, -1.0],
        }
    }

    pub fn parse(text: &str) -> Option<Self> {
        match text.trim().to_ascii_lowercase().as_str() {
            "right" | "+u" => Some(Self::Right),
            "left" | "-u" => Some(Self::Left),
            "down" | "+v" => Some(Self::Down),
            "up" | "-v" => Some(Self::Up),
            _ => None,
        }
    }
}

/// The check of one camera: every set, the direction the phase grows.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraShiftCheck {
    pub camera: String,
    pub sets: Vec<SetShiftCheck>,
    /// Unit vector (u, v) in which the phase grows with the manifest's shift
    /// direction, when the sets agree on one.
    pub phase_direction: Option<[f64; 2]>,
}

impl CameraShiftCheck {
    pub fn has_problem(&self) -> bool {
        self.sets.iter().any(|s| s.verdict.is_problem())
    }
}

fn unit(g: [f64; 2]) -> Option<[f64; 2]> {
    let n = g[0].hypot(g[1]);
    (n > 1e-6).then(|| [g[0] / n, g[1] / n])
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn max_diff(est: &[f64], man: &[f64], sign: f64) -> f64 {
    est.iter().zip(man).map(|(e, m)| wrap_pi(sign * e - m).abs()).fold(0.0, f64::max)
}

/// Whether the manifest's steps agree with the estimate taken with `sign`:
/// within the tolerance, or (the estimate's steps being biased where the
/// set spans little of a period) the manifest explains the images as well as
/// the estimate while running the same way.
fn agrees(e: &ShiftEstimate, man: &[f64], sign: f64, tolerance_rad: f64) -> bool {
    let diff = max_diff(&e.steps_rad, man, sign);
    diff <= tolerance_rad || (fits_manifest(e) && diff < max_diff(&e.steps_rad, man, -sign))
}

fn fits_manifest(e: &ShiftEstimate) -> bool {
    e.manifest_fit_ratio.is_some_and(|r| r <= MANIFEST_FIT_RATIO)
}

/// Checks every set of a camera against the manifest's shifts. `direction`
/// is where the phase must grow in the image, when the rig is known; without
/// it the sets are checked against each other and against the manifest.
pub fn check_camera(
    camera: &CameraFringes,
    sets: &[FringeSetInfo],
    saturation_threshold: u16,
    direction: Option<PhaseDirection>,
    tolerance_rad: f64,
) -> CameraShiftCheck {
    let estimates: Vec<Result<ShiftEstimate, EstimateFault>> = camera
        .stacks
        .iter()
        .zip(sets)
        .map(|(s, set)| estimate_shifts_against(s, saturation_threshold, Some(&set.phase_shifts_rad)))
        .collect();
    // Each set's "positive-step" phase grows along its gradient; the true
    // phase of every set grows the same way. Reference: the given direction,
    // else the best-determined set (largest gradient relative to its period).
    let reference: Option<[f64; 2]> = direction.map(PhaseDirection::vector).or_else(|| {
        estimates
            .iter()
            .zip(sets)
            .filter_map(|(e, s)| e.as_ref().ok().map(|e| (e.phase_gradient, s.period_px)))
            .filter_map(|(g, p)| unit(g).map(|u| (u, g[0].hypot(g[1]) * p)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(u, _)| u)
    });
    // Relative sign of each set against the reference (+1: the positive-step
    // estimate grows along it).
    let relative: Vec<Option<f64>> = estimates
        .iter()
        .map(|e| {
            let e = e.as_ref().ok()?;
            let d = dot(unit(e.phase_gradient)?, reference?);
            (d.abs() > 0.5).then_some(d.signum())
        })
        .collect();
    let manifest_steps: Vec<Vec<f64>> = sets.iter().map(|s| steps_of(&s.phase_shifts_rad)).collect();
    // The one sign the data leave open, unless the direction was given.
    let global = if direction.is_some() {
        1.0
    } else {
        // Fewest disagreeing sets wins (one odd set is the usual fault); on a
        // tie the sparsest set is trusted, then the smaller total difference.
        let cost = |g: f64| -> (usize, bool, f64) {
            let diffs: Vec<Option<(bool, f64)>> = estimates
                .iter()
                .zip(&relative)
                .zip(&manifest_steps)
                .map(|((e, r), m)| {
                    let e = e.as_ref().ok()?;
                    let sign = g * (*r)?;
                    Some((agrees(e, m, sign, tolerance_rad), max_diff(&e.steps_rad, m, sign)))
                })
                .collect();
            let disagree = diffs.iter().flatten().filter(|d| !d.0).count();
            let first = diffs.iter().flatten().next().is_some_and(|d| !d.0);
            (disagree, first, diffs.iter().flatten().map(|d| d.1).sum())
        };
        let (plus, minus) = (cost(1.0), cost(-1.0));
        let minus_better = (minus.0, minus.1).cmp(&(plus.0, plus.1)).then(minus.2.total_cmp(&plus.2)).is_lt();
        if minus_better { -1.0 } else { 1.0 }
    };
    let mut checks = Vec::new();
    for (s, ((est, rel), man)) in estimates.iter().zip(&relative).zip(&manifest_steps).enumerate() {
        let period_px = sets[s].period_px;
        let mut check = SetShiftCheck {
            set: s,
            period_px,
            manifest_steps_rad: man.clone(),
            estimated_steps_rad: Vec::new(),
            step_spread_rad: Vec::new(),
            max_difference_rad: f64::NAN,
            manifest_fit_ratio: est.as_ref().ok().and_then(|e| e.manifest_fit_ratio),
            verdict: Verdict::Unknown(String::new()),
            message: String::new(),
        };
        match est {
            Err(e) => {
                check.message = format!("not estimated: {e}");
                check.verdict = Verdict::Unknown(e.to_string());
            }
            Ok(e) => {
                check.step_spread_rad = e.step_spread_rad.clone();
                let Some(r) = rel else {
                    // Without a direction, only the size and evenness of the steps can be compared.
                    let best = max_diff(&e.steps_rad, man, 1.0).min(max_diff(&e.steps_rad, man, -1.0));
                    check.estimated_steps_rad = e.steps_rad.clone();
                    check.max_difference_rad = best;
                    if best <= tolerance_rad || fits_manifest(e) {
                        check.verdict =
                            Verdict::Unknown("the direction of its phase across the image is unclear".into());
                        check.message =
                            "step sizes agree; the direction could not be compared with the other sets".to_string();
                    } else {
                        check.verdict = Verdict::Mismatch;
                        check.message = mismatch_message(&e.steps_rad, man);
                    }
                    checks.push(check);
                    continue;
                };
                let sign = global * r;
                check.estimated_steps_rad = e.steps_rad.iter().map(|d| wrap_pi(sign * d)).collect();
                let diff = max_diff(&e.steps_rad, man, sign);
                check.max_difference_rad = diff;
                if diff <= tolerance_rad {
                    check.verdict = Verdict::Agrees;
                    check.message = format!(
                        "steps agree within {:.1}° (spread {:.2}°)",
                        diff.to_degrees(),
                        e.step_spread_rad.iter().copied().filter(|x| x.is_finite()).fold(0.0, f64::max).to_degrees()
                    );
                } else if agrees(e, man, sign, tolerance_rad) {
                    check.verdict = Verdict::Agrees;
                    check.message = format!(
                        "the estimated steps differ by up to {:.1}°, but the manifest's shifts explain the images as \
                         well as the estimate (residual ratio {:.2} with the fringe's harmonics): the estimate is \
                         biased by harmonics where the set spans little of a fringe period",
                        diff.to_degrees(),
                        e.manifest_fit_ratio.unwrap_or(f64::NAN)
                    );
                } else if agrees(e, man, -sign, tolerance_rad) {
                    check.verdict = Verdict::Reversed;
                    check.message = if direction.is_some() {
                        "the shifts run the other way than the manifest says (with its shifts the phase would fall \
                         where the rig's phase grows): import with the other --shift-sign, or negate phase_shifts_rad"
                            .to_string()
                    } else {
                        "the shifts run the other way than in the other sets: this set's images are in reverse \
                         shift order (or its shift sign differs); give it phase_shifts_rad with the other sign"
                            .to_string()
                    };
                } else {
                    check.verdict = Verdict::Mismatch;
                    check.message = mismatch_message(&check.estimated_steps_rad, man);
                }
            }
        }
        checks.push(check);
    }
    let phase_direction = reference.map(|r| if global < 0.0 { [-r[0], -r[1]] } else { r });
    CameraShiftCheck { camera: camera.name.clone(), sets: checks, phase_direction }
}

/// [`check_camera`] for every camera of a measurement (in parallel).
pub fn check_measurement(
    m: &super::fringe::Measurement,
    saturation_threshold: u16,
    direction: Option<PhaseDirection>,
    tolerance_rad: f64,
) -> Vec<CameraShiftCheck> {
    use rayon::prelude::*;
    m.cameras.par_iter().map(|c| check_camera(c, &m.sets, saturation_threshold, direction, tolerance_rad)).collect()
}

fn mismatch_message(estimated: &[f64], manifest: &[f64]) -> String {
    let deg = |v: &[f64]| -> (f64, f64) {
        v.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| (lo.min(d.to_degrees()), hi.max(d.to_degrees())))
    };
    let (elo, ehi) = deg(estimated);
    let (mlo, mhi) = deg(manifest);
    if ehi - elo > 10.0 {
        format!(
            "the measured steps vary from {elo:.0}° to {ehi:.0}° (manifest: {mlo:.0}° to {mhi:.0}°): the images are \
             not in shift order (numbering sorted as text puts 10 before 2?) or a shift is missing"
        )
    } else {
        format!(
            "the measured step is {:.1}° but the manifest says {:.1}°: check the number of shifts of this set",
            (elo + ehi) / 2.0,
            (mlo + mhi) / 2.0
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fringe::FringeStack;

    /// A stack of `I = 120 + 80 cos(Phi + delta_k)` with Phi growing along u
    /// (`periods_u` fringes across the width), plus a mild tilt along v.
    fn stack(width: usize, height: usize, fringes: f64, shifts: &[f64]) -> FringeStack {
        stack_from(width, height, shifts, |u, v, d| {
            let phi = TAU * fringes * u / width as f64 + 0.3 * v / height as f64;
            let a = 120.0 + 20.0 * (u / width as f64);
            a + 80.0 * (phi + d).cos()
        })
    }

    /// An 8-bit stack of `intensity(u, v, delta_k)`, rounded and clipped.
    fn stack_from(
        width: usize,
        height: usize,
        shifts: &[f64],
        mut intensity: impl FnMut(f64, f64, f64) -> f64,
    ) -> FringeStack {
        let planes = shifts
            .iter()
            .map(|&d| {
                (0..width * height)
                    .map(|i| {
                        let value = intensity((i % width) as f64, (i / width) as f64, d);
                        value.round().clamp(0.0, 255.0) as u8
                    })
                    .collect()
            })
            .collect();
        FringeStack::from_planes_u8(width, height, planes)
    }

    fn uniform(n: usize, sign: f64, start: f64) -> Vec<f64> {
        (0..n).map(|k| start + sign * TAU * k as f64 / n as f64).collect()
    }

    #[test]
    fn uniform_steps_are_recovered() {
        for n in [3, 4, 8, 12] {
            let e = estimate_shifts(&stack(200, 120, 7.0, &uniform(n, 1.0, 0.0)), 255).expect("estimate");
            for s in &e.steps_rad {
                assert!((s - TAU / n as f64).abs() < 0.01, "N = {n}: {:?}", e.steps_rad);
            }
            assert!(e.phase_gradient[0] > 0.0, "positive steps: phase grows along u");
        }
    }

    #[test]
    fn uneven_steps_are_recovered() {
        let shifts = [0.0, 1.2, 2.0, 3.5, 4.1, 5.3];
        let e = estimate_shifts(&stack(240, 160, 9.0, &shifts), 255).expect("estimate");
        for (est, truth) in e.steps_rad.iter().zip(steps_of(&shifts)) {
            assert!((est - truth).abs() < 0.02, "{:?}", e.steps_rad);
        }
    }

    #[test]
    fn reversed_steps_give_the_same_images_but_the_opposite_gradient() {
        let fwd = estimate_shifts(&stack(200, 120, 7.0, &uniform(6, 1.0, 0.0)), 255).expect("fwd");
        let rev = estimate_shifts(&stack(200, 120, 7.0, &uniform(6, -1.0, 1.0)), 255).expect("rev");
        assert!(rev.steps_rad.iter().all(|s| (s - TAU / 6.0).abs() < 0.01), "reported with a positive step");
        assert!(fwd.phase_gradient[0] > 0.0 && rev.phase_gradient[0] < 0.0);
    }

    fn camera(stacks: Vec<FringeStack>) -> CameraFringes {
        CameraFringes { name: "left".into(), width: stacks[0].width, height: stacks[0].height, stacks }
    }

    #[test]
    fn a_set_running_the_other_way_is_reported_reversed() {
        let sets = [FringeSetInfo::uniform(100.0, 8), FringeSetInfo::uniform(20.0, 4)];
        let cam = camera(vec![
            stack(200, 120, 2.0, &uniform(8, 1.0, 0.0)),
            // The dense set recorded with the opposite sign and a start of pi/2.
            stack(200, 120, 10.0, &uniform(4, -1.0, PI / 2.0)),
        ]);
        let check = check_camera(&cam, &sets, 255, None, DEFAULT_TOLERANCE_RAD);
        assert_eq!(check.sets[0].verdict, Verdict::Agrees, "{:?}", check.sets[0]);
        assert_eq!(check.sets[1].verdict, Verdict::Reversed, "{:?}", check.sets[1]);
        assert!(check.has_problem());
        // Told so, the manifest agrees.
        let told = [sets[0].clone(), FringeSetInfo { period_px: 20.0, phase_shifts_rad: uniform(4, -1.0, PI / 2.0) }];
        let check = check_camera(&cam, &told, 255, None, DEFAULT_TOLERANCE_RAD);
        assert!(!check.has_problem(), "{:?}", check.sets);
        // With the direction known, an all-reversed manifest is caught too.
        let reversed_all = [
            FringeSetInfo { period_px: 100.0, phase_shifts_rad: uniform(8, -1.0, 0.0) },
            FringeSetInfo { period_px: 20.0, phase_shifts_rad: uniform(4, 1.0, 0.0) },
        ];
        let plain = check_camera(&cam, &reversed_all, 255, None, DEFAULT_TOLERANCE_RAD);
        assert!(!plain.has_problem(), "without a direction the common sign is free");
        let right = check_camera(&cam, &reversed_all, 255, Some(PhaseDirection::Right), DEFAULT_TOLERANCE_RAD);
        assert!(right.sets.iter().all(|s| s.verdict == Verdict::Reversed), "{:?}", right.sets);
    }

    #[test]
    fn images_out_of_order_are_a_mismatch() {
        // 12 shifts stored as 0, 1, 10, 11, 2, ... 9 (text order).
        let truth = uniform(12, 1.0, 0.0);
        let text_order = [0usize, 1, 10, 11, 2, 3, 4, 5, 6, 7, 8, 9];
        let shuffled: Vec<f64> = text_order.iter().map(|&k| truth[k]).collect();
        let cam = camera(vec![stack(200, 120, 7.0, &shuffled)]);
        let check = check_camera(&cam, &[FringeSetInfo::uniform(30.0, 12)], 255, None, DEFAULT_TOLERANCE_RAD);
        assert_eq!(check.sets[0].verdict, Verdict::Mismatch, "{:?}", check.sets[0]);
        assert!(check.sets[0].message.contains("not in shift order"), "{}", check.sets[0].message);
    }

    /// Issue 18: a set with less than one fringe across the image and a
    /// projector gamma of 2.2 corrected for 1.8 (the harmonics every real
    /// projector adds). `I = 20 + 200 ((1 + 0.9 cos(Phi + d)) / 2)^1.22` over
    /// 0.4 of a period (a part in the middle of the field), 8-bit, 1.5 DN noise.
    fn gamma_stack(shifts: &[f64]) -> FringeStack {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let (width, height) = (240, 160);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let noise = rand_distr::Normal::new(0.0, 1.5).expect("normal");
        stack_from(width, height, shifts, |u, v, d| {
            let phi = 1.0 + 0.4 * TAU * u / width as f64 + 0.2 * v / height as f64;
            let pattern = 0.5 * (1.0 + 0.9 * (phi + d).cos());
            20.0 + 200.0 * pattern.powf(2.2 / 1.8) + noise.sample(&mut rng)
        })
    }

    #[test]
    fn harmonics_in_a_set_spanning_less_than_a_period_are_no_false_alarm() {
        let truth = uniform(8, 1.0, 0.0);
        let set = [FringeSetInfo::uniform(1024.0, 8)];
        let e = estimate_shifts(&gamma_stack(&truth), 255).expect("estimate");
        let bias = max_diff(&e.steps_rad, &steps_of(&truth), 1.0);
        assert!(bias > DEFAULT_TOLERANCE_RAD, "the sinusoidal estimate is biased: {:.1} deg", bias.to_degrees());
        let check = check_camera(&camera(vec![gamma_stack(&truth)]), &set, 255, None, DEFAULT_TOLERANCE_RAD);
        assert_eq!(check.sets[0].verdict, Verdict::Agrees, "{:?}", check.sets[0]);
        let ratio = check.sets[0].manifest_fit_ratio.expect("8 shifts leave a residual");
        assert!(ratio < 1.2, "ratio {ratio}");
        // Two images swapped, one image repeated in place of the next, the
        // last four in the wrong place: each fits far worse than the estimate.
        let mut swapped = truth.clone();
        swapped.swap(2, 3);
        let mut repeated = truth.clone();
        repeated[3] = truth[4];
        let moved = [0usize, 1, 2, 4, 5, 6, 7, 3].map(|k| truth[k]).to_vec();
        for (name, recorded) in [("swapped", swapped), ("repeated", repeated), ("moved", moved)] {
            let check = check_camera(&camera(vec![gamma_stack(&recorded)]), &set, 255, None, DEFAULT_TOLERANCE_RAD);
            assert_eq!(check.sets[0].verdict, Verdict::Mismatch, "{name}: {:?}", check.sets[0]);
            assert!(check.sets[0].manifest_fit_ratio.is_some_and(|r| r > 10.0), "{name}: {:?}", check.sets[0]);
        }
    }

    #[test]
    fn flat_images_are_not_estimated() {
        let planes = vec![vec![100u8; 64 * 48]; 4];
        let e = estimate_shifts(&FringeStack::from_planes_u8(64, 48, planes), 255);
        assert!(matches!(e, Err(EstimateFault::TooFewPixels { .. })), "{e:?}");
    }
}
