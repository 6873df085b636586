//! Saturation counting (Alg. 1) and wrapped-phase retrieval (Alg. 2): the
//! standard N-step formula (Eq. 5) where no sample is saturated and the
//! generalized least-squares phase shifting of Lai & Yatagai (Eqs. 2-4) on the
//! unsaturated samples where some are.
//!
//! Model (the paper's Eq. 1, written with the fringe-set contract's symbols):
//! `I_k = A + B cos(Phi + delta_k) = a0 + a1 cos(delta_k) + a2 sin(delta_k)` with
//! `a1 = B cos Phi`, `a2 = -B sin Phi`. Least squares over the used samples gives
//! `(a0, a1, a2) = C (sum I, sum I cos delta, sum I sin delta)` with `C = A^-1`,
//! `A` the normal matrix of Eq. 4, and `Phi = atan2(-a2, a1)`, Eq. 2.
//!
//! For a uniform shift list (any start, either sign) and all samples used, `C`
//! is `diag(1/N, 2/N, 2/N)` and the same expression *is* Eq. 5, so the kernel
//! has one code path: what differs per pixel is only which `C` it uses. `C`
//! depends only on the set of unsaturated samples, so the kernel looks it up in
//! a table indexed by that mask instead of inverting a 3x3 matrix per pixel.

use std::f32::consts::{FRAC_PI_2, PI, TAU};
use std::mem::MaybeUninit;

use rayon::prelude::*;

use super::control::{Cancelled, RunControl};
use super::fringe::{FringeSetInfo, FringeStack, Samples};
use super::simd;

/// Which samples the phase of a pixel is computed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SampleSelection {
    /// Every sample, saturated or not (the traditional algorithm).
    All,
    /// Only unsaturated samples; a pixel needs at least 3 (Alg. 2).
    Unsaturated,
    /// Every sample, but a pixel with any saturated sample is invalid.
    RejectSaturated,
}

/// Operator parameters of the per-set phase stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhaseParams {
    /// Samples at or above this value are saturated (Alg. 1, `sat_thr`).
    pub saturation_threshold: u16,
    /// Pixels whose fitted modulation `B` is below this (in grey levels) are invalid.
    pub min_modulation_dn: f32,
    pub selection: SampleSelection,
}

/// At most this many shifts per set: the saturation mask is a `u32`.
pub const MAX_SHIFTS: usize = 32;
/// Up to this many shifts the mask-indexed coefficient table holds all 2^N masks.
const MAX_TABLE_SHIFTS: usize = 16;

/// The entries of the symmetric `C = A^-1` that Eqs. 2-3 need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients {
    pub c00: f32,
    pub c01: f32,
    pub c02: f32,
    pub c11: f32,
    pub c12: f32,
    pub c22: f32,
}

impl Coefficients {
    const INVALID: Coefficients =
        Coefficients { c00: f32::NAN, c01: f32::NAN, c02: f32::NAN, c11: f32::NAN, c12: f32::NAN, c22: f32::NAN };

    #[inline(always)]
    fn is_valid(&self) -> bool {
        self.c11.is_finite()
    }
}

/// `C = A^-1` (Eq. 4) for the shifts selected by `mask`, in f64, or `None`
/// when fewer than 3 samples are selected or the shifts do not determine the
/// three unknowns (e.g. repeated shifts).
pub fn normal_matrix_inverse(shifts_rad: &[f64], mask: u32) -> Option<[[f64; 3]; 3]> {
    let mut a = [[0.0f64; 3]; 3];
    let mut used = 0;
    for (k, &d) in shifts_rad.iter().enumerate() {
        if mask & (1 << k) == 0 {
            continue;
        }
        used += 1;
        let row = [1.0, d.cos(), d.sin()];
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += row[i] * row[j];
            }
        }
    }
    if used < 3 {
        return None;
    }
    // Conditioning by the Hadamard ratio det(A) / (A00 A11 A22), in (0, 1]:
    // nearly equal shifts leave the fit formally solvable but with unbounded
    // noise gain, and the ratio then collapses towards 0.
    let m = nalgebra::Matrix3::from_fn(|i, j| a[i][j]);
    let det = m.determinant();
    let diagonal = a[0][0] * a[1][1] * a[2][2];
    if !(diagonal > 0.0 && det / diagonal > 1e-9) {
        return None;
    }
    let inv = m.try_inverse()?;
    Some(std::array::from_fn(|i| std::array::from_fn(|j| inv[(i, j)])))
}

fn to_coefficients(c: &[[f64; 3]; 3]) -> Coefficients {
    Coefficients {
        c00: c[0][0] as f32,
        c01: c[0][1] as f32,
        c02: c[0][2] as f32,
        c11: c[1][1] as f32,
        c12: c[1][2] as f32,
        c22: c[2][2] as f32,
    }
}

/// Precomputed per-set quantities: the shift cosines and sines and the
/// coefficient table indexed by the mask of *used* samples.
pub struct ShiftModel {
    pub shifts_rad: Vec<f64>,
    cos: Vec<f32>,
    sin: Vec<f32>,
    full_mask: u32,
    table: Vec<Coefficients>,
}

impl ShiftModel {
    /// The model for a shift list, built once per distinct list and shared:
    /// the table costs a few milliseconds, every run of every set needs it.
    pub fn shared(shifts_rad: &[f64]) -> std::sync::Arc<ShiftModel> {
        use std::collections::HashMap;
        use std::sync::{Arc, Mutex, OnceLock};
        static CACHE: OnceLock<Mutex<HashMap<Vec<u64>, Arc<ShiftModel>>>> = OnceLock::new();
        let key: Vec<u64> = shifts_rad.iter().map(|d| d.to_bits()).collect();
        let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
        if let Some(model) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
            return model;
        }
        let model = Arc::new(ShiftModel::new(shifts_rad));
        if let Ok(mut c) = cache.lock() {
            c.insert(key, Arc::clone(&model));
        }
        model
    }

    pub fn new(shifts_rad: &[f64]) -> Self {
        let n = shifts_rad.len();
        assert!((1..=MAX_SHIFTS).contains(&n), "1..=32 shifts");
        let full_mask = if n == 32 { u32::MAX } else { (1u32 << n) - 1 };
        let table = if n <= MAX_TABLE_SHIFTS {
            (0..=full_mask)
                .map(|mask| {
                    normal_matrix_inverse(shifts_rad, mask).map_or(Coefficients::INVALID, |c| to_coefficients(&c))
                })
                .collect()
        } else {
            Vec::new()
        };
        Self {
            shifts_rad: shifts_rad.to_vec(),
            cos: shifts_rad.iter().map(|d| d.cos() as f32).collect(),
            sin: shifts_rad.iter().map(|d| d.sin() as f32).collect(),
            full_mask,
            table,
        }
    }

    pub fn shifts(&self) -> usize {
        self.shifts_rad.len()
    }

    /// Coefficients for the samples selected by `used_mask`.
    #[inline(always)]
    pub fn coefficients(&self, used_mask: u32) -> Coefficients {
        if self.table.is_empty() {
            normal_matrix_inverse(&self.shifts_rad, used_mask).map_or(Coefficients::INVALID, |c| to_coefficients(&c))
        } else {
            self.table[used_mask as usize]
        }
    }

    /// True when the shifts are evenly spread over a full turn (any start, either
    /// sign), so the full-mask fit reduces to the standard formula, Eq. 5.
    pub fn is_uniform(&self) -> bool {
        let n = self.shifts();
        if n < 3 {
            return false;
        }
        let step = self.shifts_rad[1] - self.shifts_rad[0];
        let expected = std::f64::consts::TAU / n as f64;
        let step_ok = (step.abs() - expected).abs() < 1e-6;
        step_ok && self.shifts_rad.windows(2).all(|w| ((w[1] - w[0]) - step).abs() < 1e-6)
    }
}

/// Least-squares fit of one pixel in f64 (Eqs. 2-4): the reference the fast
/// kernel is tested against, and what the pixel inspector plots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelFit {
    /// Wrapped phase in [0, 2 pi).
    pub phase_rad: f64,
    /// Fringe modulation `B`.
    pub modulation: f64,
    /// Mean intensity `A`.
    pub offset: f64,
    /// Number of samples the fit used.
    pub used: usize,
    /// RMS of the fit residual over the used samples.
    pub residual_rms: f64,
}

/// Fits `I_k = A + B cos(Phi + delta_k)` to the samples with `used[k]`.
pub fn fit_pixel(samples: &[f64], shifts_rad: &[f64], used: &[bool]) -> Option<PixelFit> {
    let mask = used.iter().enumerate().fold(0u32, |m, (k, &u)| if u { m | (1 << k) } else { m });
    let c = normal_matrix_inverse(shifts_rad, mask)?;
    let mut b = [0.0f64; 3];
    for (k, (&i, &d)) in samples.iter().zip(shifts_rad).enumerate() {
        if used[k] {
            b[0] += i;
            b[1] += i * d.cos();
            b[2] += i * d.sin();
        }
    }
    let a: [f64; 3] = std::array::from_fn(|r| c[r][0] * b[0] + c[r][1] * b[1] + c[r][2] * b[2]);
    let phase = (-a[2]).atan2(a[1]).rem_euclid(std::f64::consts::TAU);
    let n_used = used.iter().filter(|&&u| u).count();
    let rss: f64 = samples
        .iter()
        .zip(shifts_rad)
        .zip(used)
        .filter(|(_, u)| **u)
        .map(|((&i, &d), _)| {
            let r = i - (a[0] + a[1] * d.cos() + a[2] * d.sin());
            r * r
        })
        .sum();
    Some(PixelFit {
        phase_rad: phase,
        modulation: a[1].hypot(a[2]),
        offset: a[0],
        used: n_used,
        residual_rms: (rss / n_used as f64).sqrt(),
    })
}

/// The standard N-step formula, Eq. 5, for uniform shift lists.
pub fn standard_phase(samples: &[f64], shifts_rad: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (&i, &d) in samples.iter().zip(shifts_rad) {
        num += i * d.sin();
        den += i * d.cos();
    }
    (-num).atan2(den).rem_euclid(std::f64::consts::TAU)
}

/// `atan2(y, x)` to about 3e-7 rad, branch-free so the per-pixel loop vectorises.
/// Odd minimax polynomial of degree 13 for `atan` on [0, 1] plus octant folding.
#[inline(always)]
pub fn fast_atan2(y: f32, x: f32) -> f32 {
    let ax = x.abs();
    let ay = y.abs();
    let hi = ax.max(ay);
    let lo = ax.min(ay);
    let a = if hi > 0.0 { lo / hi } else { 0.0 };
    let s = a * a;
    // Plain multiply-adds (not `mul_add`, which is a library call on CPUs
    // without FMA); the dispatched kernels let the compiler fuse them.
    let p = 0.006_811_779_5_f32;
    let p = p * s - 0.033_604_18;
    let p = p * s + 0.079_623_625;
    let p = p * s - 0.132_333_4;
    let p = p * s + 0.198_078_16;
    let p = p * s - 0.333_173_7;
    let p = p * s + 0.999_996_1;
    let r = a * p;
    let r = if ay > ax { FRAC_PI_2 - r } else { r };
    let r = if x < 0.0 { PI - r } else { r };
    if y < 0.0 { -r } else { r }
}

/// Result of the phase stage for one camera and one fringe set.
#[derive(Clone, Debug)]
pub struct WrappedPhase {
    pub width: usize,
    pub height: usize,
    pub period_px: f64,
    pub shifts: usize,
    /// Saturated samples per pixel (Alg. 1, `sat_map^m`).
    pub saturation_count: Vec<u8>,
    /// Wrapped phase `phi^m` in [0, 2 pi); NaN where invalid.
    pub wrapped_phase_rad: Vec<f32>,
    /// Fitted modulation `B` in grey levels; 0 where fewer than 3 samples were usable.
    pub modulation_dn: Vec<f32>,
    /// Standard deviation of the wrapped phase from the fit's normal matrix and
    /// the camera noise: `sigma^2 / B^2 * g^T C g`, `g = (0, sin phi, cos phi)`.
    pub phase_sigma_rad: Vec<f32>,
    /// Fitted mean intensity `A`; kept only when asked for (it serves as texture).
    pub offset_dn: Option<Vec<f32>>,
    pub noise: NoiseEstimate,
    pub stats: SetStats,
}

/// Pixel counts of one set, for reports and the statistics panel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SetStats {
    pub pixels: usize,
    /// Pixels with at least one saturated sample.
    pub partially_saturated: usize,
    /// Pixels with fewer than 3 unsaturated samples (the paper's `ind^m`).
    pub over_saturated: usize,
    /// Pixels rejected for modulation below the threshold.
    pub low_modulation: usize,
    /// Pixels with a valid wrapped phase.
    pub valid: usize,
}

impl SetStats {
    pub fn merge(a: Self, b: Self) -> Self {
        Self {
            pixels: a.pixels + b.pixels,
            partially_saturated: a.partially_saturated + b.partially_saturated,
            over_saturated: a.over_saturated + b.over_saturated,
            low_modulation: a.low_modulation + b.low_modulation,
            valid: a.valid + b.valid,
        }
    }
}

/// Where a set's noise figure comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseSource {
    /// The fit residuals of its own samples, with the part that grows with
    /// the modulation (projector gamma's harmonics) taken apart.
    FitResidual,
    /// A 3-step set leaves no residual: the fit residuals of this camera's
    /// sets with more shifts (the noise is the camera's, not the set's).
    OtherSets,
    /// No set of the camera has a residual: the spread of the offset `A` between
    /// this camera's sets at the same pixels (the projected mean is the same
    /// in every set, so the difference is noise).
    CrossSetOffsets,
    /// Nothing to measure it from: one grey level assumed.
    Assumed,
}

/// Camera noise of one set: the random part, measured robustly, and the
/// deterministic harmonics apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseEstimate {
    /// Random noise, standard deviation in grey levels.
    pub sigma_dn: f32,
    /// False when `sigma_dn` is an assumed value.
    pub measured: bool,
    pub pixels: usize,
    pub source: NoiseSource,
    /// RMS of the fringe's harmonics (projector gamma) relative to its
    /// modulation, in percent, where the residuals show them.
    pub harmonic_percent: Option<f32>,
}

/// Noise assumed where it cannot be measured: one grey level.
const ASSUMED_NOISE_DN: f32 = 1.0;

/// Quantisation alone leaves 1/12 grey level^2; no estimate reports less.
const QUANTISATION_VARIANCE_DN2: f64 = 1.0 / 12.0;

impl NoiseEstimate {
    fn assumed() -> Self {
        Self {
            sigma_dn: ASSUMED_NOISE_DN,
            measured: false,
            pixels: 0,
            source: NoiseSource::Assumed,
            harmonic_percent: None,
        }
    }
}

/// Estimates the camera noise from a subsample of rows: per pixel the residual
/// variance of the fit over all-unsaturated samples, `rss / (N - 3)`, and its
/// modulation `B`.
///
/// A real projector's gamma puts harmonics into every fringe; the fit
/// residuals then hold them too, with a power that grows as `B^2`, while the
/// camera's random noise does not depend on `B`. So the residual variance is
/// modelled as `sigma^2 + c B^2`: over groups of pixels ordered by `B`, the
/// median variance (divided by the median of `chi^2_k / k`, Wilson-Hilferty,
/// so that edges barely move it) is fitted by a line in `B^2` whose intercept
/// is the random noise and whose slope gives the harmonics. Where `B` varies
/// too little to separate them, the plain median is used.
pub fn estimate_noise(stack: &FringeStack, model: &ShiftModel, params: &PhaseParams) -> NoiseEstimate {
    let n = model.shifts();
    if n <= 3 || stack.pixel_count() == 0 {
        return NoiseEstimate::assumed();
    }
    let Some(c) = normal_matrix_inverse(&model.shifts_rad, model.full_mask) else {
        return NoiseEstimate::assumed();
    };
    let row_step = (stack.height / 48).max(1);
    let col_step = (stack.width / 256).max(1);
    let mut points: Vec<(f64, f64)> = (0..stack.height)
        .step_by(row_step)
        .collect::<Vec<_>>()
        .par_iter()
        .flat_map_iter(|&row| {
            let mut local = Vec::new();
            let mut samples = vec![0.0f64; n];
            for col in (0..stack.width).step_by(col_step) {
                let pixel = row * stack.width + col;
                let mut saturated = false;
                for (k, s) in samples.iter_mut().enumerate() {
                    let v = stack.sample(k, pixel);
                    saturated |= v >= params.saturation_threshold;
                    *s = f64::from(v);
                }
                if saturated {
                    continue;
                }
                let a = fit_full(&samples, model, &c);
                let modulation = a[1].hypot(a[2]);
                if modulation < f64::from(params.min_modulation_dn) {
                    continue;
                }
                let rss: f64 = samples
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| {
                        let r = v - (a[0] + a[1] * f64::from(model.cos[k]) + a[2] * f64::from(model.sin[k]));
                        r * r
                    })
                    .sum();
                local.push((modulation * modulation, rss / (n - 3) as f64));
            }
            local
        })
        .collect();
    if points.len() < 16 {
        return NoiseEstimate::assumed();
    }
    let dof = (n - 3) as f64;
    let chi2_median_over_dof = (1.0 - 2.0 / (9.0 * dof)).powi(3);
    let pixels = points.len();
    // Without a modulation spread the harmonics cannot be told from the
    // noise: the median holds both, and no harmonic share is claimed (a 0 %
    // would read as "no gamma" while the noise figure carries it).
    let (variance, harmonic_percent) = match intercept_and_slope(&mut points) {
        Some((intercept, slope)) => {
            // A residual variance c B^2 spread over the N - 3 residual degrees
            // of freedom is a harmonic power of c B^2 (N - 3) / N per sample,
            // i.e. a harmonic RMS amplitude of sqrt(2 c (N - 3) / N) B.
            let slope = slope / chi2_median_over_dof;
            let harmonic = (2.0 * slope * dof / n as f64).sqrt() * 100.0;
            (intercept / chi2_median_over_dof, Some(harmonic as f32))
        }
        None => {
            let mut v: Vec<f64> = points.iter().map(|p| p.1).collect();
            let mid = v.len() / 2;
            let (_, median, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
            (*median / chi2_median_over_dof, None)
        }
    };
    NoiseEstimate {
        sigma_dn: variance.max(QUANTISATION_VARIANCE_DN2).sqrt() as f32,
        measured: true,
        pixels,
        source: NoiseSource::FitResidual,
        harmonic_percent,
    }
}

/// The least-squares offsets `(A, B cos, B sin)` of a pixel's samples over all shifts.
fn fit_full(samples: &[f64], model: &ShiftModel, c: &[[f64; 3]; 3]) -> [f64; 3] {
    let mut b = [0.0f64; 3];
    for (k, &v) in samples.iter().enumerate() {
        b[0] += v;
        b[1] += v * f64::from(model.cos[k]);
        b[2] += v * f64::from(model.sin[k]);
    }
    std::array::from_fn(|r| c[r][0] * b[0] + c[r][1] * b[1] + c[r][2] * b[2])
}

/// Groups of pixels for the residual-against-modulation fit.
const NOISE_GROUPS: usize = 8;

/// Line `y = intercept + slope x` through the medians of `y` in groups of
/// points ordered by `x` (each a median, so outliers barely move it); `None`
/// when `x` spans too little to extrapolate to 0. The intercept is kept
/// between the quantisation floor and the smallest group median.
fn intercept_and_slope(points: &mut [(f64, f64)]) -> Option<(f64, f64)> {
    if points.len() < NOISE_GROUPS * 16 {
        return None;
    }
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let size = points.len() / NOISE_GROUPS;
    let groups: Vec<(f64, f64)> = points
        .chunks(size)
        .filter(|g| g.len() == size)
        .map(|g| {
            let mut ys: Vec<f64> = g.iter().map(|p| p.1).collect();
            let mid = ys.len() / 2;
            let (_, y, _) = ys.select_nth_unstable_by(mid, f64::total_cmp);
            (g[g.len() / 2].0, *y)
        })
        .collect();
    let (x_lo, x_hi) = (groups.first()?.0, groups.last()?.0);
    // Modulation spanning less than a factor of 1.5 cannot tell a constant from B^2.
    if !(x_hi > 2.25 * x_lo) {
        return None;
    }
    let k = groups.len() as f64;
    let (mx, my) = (groups.iter().map(|g| g.0).sum::<f64>() / k, groups.iter().map(|g| g.1).sum::<f64>() / k);
    let sxx: f64 = groups.iter().map(|g| (g.0 - mx).powi(2)).sum();
    let sxy: f64 = groups.iter().map(|g| (g.0 - mx) * (g.1 - my)).sum();
    let slope = (sxy / sxx).max(0.0);
    let y_min = groups.iter().map(|g| g.1).fold(f64::INFINITY, f64::min);
    let intercept = (my - slope * mx).clamp(QUANTISATION_VARIANCE_DN2.min(y_min), y_min);
    Some((intercept, slope))
}

/// The random noise of a camera from the offsets `A` of its sets at the same
/// pixels: every set projects the same mean level, so `A_s - A_t` is noise of
/// variance `sigma^2 (g_s + g_t)`, `g` the offset's variance gain (`1/N` for
/// uniform shifts). The spread is taken robustly (1.4826 MAD) per pair of
/// sets and the median over pairs returned. For 3-step sets, whose fit
/// leaves no residual.
pub fn cross_set_noise(stacks: &[&FringeStack], shifts_rad: &[&[f64]], params: &PhaseParams) -> Option<(f32, usize)> {
    if stacks.len() < 2 {
        return None;
    }
    let (w, h) = (stacks[0].width, stacks[0].height);
    let models: Vec<(std::sync::Arc<ShiftModel>, [[f64; 3]; 3])> = shifts_rad
        .iter()
        .map(|d| {
            let model = ShiftModel::shared(d);
            let c = normal_matrix_inverse(d, model.full_mask)?;
            Some((model, c))
        })
        .collect::<Option<_>>()?;
    let row_step = (h / 64).max(1);
    let col_step = (w / 256).max(1);
    let pixels: Vec<usize> =
        (0..h).step_by(row_step).flat_map(|r| (0..w).step_by(col_step).map(move |c| r * w + c)).collect();
    // Per set and sampled pixel: the offset, NaN where unusable.
    let offsets: Vec<Vec<f64>> = stacks
        .par_iter()
        .zip(&models)
        .map(|(stack, (model, c))| {
            let n = model.shifts();
            let mut samples = vec![0.0f64; n];
            pixels
                .iter()
                .map(|&p| {
                    let mut saturated = false;
                    for (k, s) in samples.iter_mut().enumerate() {
                        let v = stack.sample(k, p);
                        saturated |= v >= params.saturation_threshold;
                        *s = f64::from(v);
                    }
                    let a = fit_full(&samples, model, c);
                    let usable = !saturated && a[1].hypot(a[2]) >= f64::from(params.min_modulation_dn);
                    if usable { a[0] } else { f64::NAN }
                })
                .collect()
        })
        .collect();
    let mut estimates = Vec::new();
    let mut used = 0;
    for s in 0..stacks.len() - 1 {
        let gain = models[s].1[0][0] + models[s + 1].1[0][0];
        let mut d: Vec<f64> =
            offsets[s].iter().zip(&offsets[s + 1]).map(|(a, b)| a - b).filter(|d| d.is_finite()).collect();
        if d.len() < 64 {
            continue;
        }
        used = used.max(d.len());
        let mid = d.len() / 2;
        let median = *d.select_nth_unstable_by(mid, f64::total_cmp).1;
        let mut dev: Vec<f64> = d.iter().map(|x| (x - median).abs()).collect();
        let mad = *dev.select_nth_unstable_by(mid, f64::total_cmp).1;
        let sigma_d = 1.4826 * mad;
        estimates.push((sigma_d * sigma_d / gain).max(QUANTISATION_VARIANCE_DN2));
    }
    if estimates.is_empty() {
        return None;
    }
    let mid = estimates.len() / 2;
    let variance = *estimates.select_nth_unstable_by(mid, f64::total_cmp).1;
    Some((variance.sqrt() as f32, used))
}

impl WrappedPhase {
    /// Replaces an assumed noise figure by one measured elsewhere (the phase
    /// sigma is proportional to it).
    pub fn rescale_noise(&mut self, sigma_dn: f32, pixels: usize, source: NoiseSource) {
        let factor = sigma_dn / self.noise.sigma_dn;
        self.phase_sigma_rad.par_iter_mut().for_each(|s| *s *= factor);
        self.noise = NoiseEstimate { sigma_dn, measured: true, pixels, source, harmonic_percent: None };
    }
}

/// Pixels per parallel task: enough to amortise scheduling, few enough to balance.
const PIXELS_PER_TASK: usize = 16 * 1024;

/// Alg. 1 and Alg. 2 for one stack, fused into one pass over its samples.
pub fn wrapped_phase(
    stack: &FringeStack,
    set: &FringeSetInfo,
    params: &PhaseParams,
    keep_offset: bool,
    control: &RunControl,
) -> Result<WrappedPhase, Cancelled> {
    let model = ShiftModel::shared(&set.phase_shifts_rad);
    let noise = estimate_noise(stack, &model, params);
    control.check()?;
    let (w, h) = (stack.width, stack.height);
    let len = w * h;
    // Not zeroed first: the kernel writes every element of every map, and a
    // long-running process (the line, the app) reuses freed memory, where
    // zeroing five maps per set was 0.4 GB of stores per full-size part.
    let mut saturation_count = Vec::<u8>::with_capacity(len);
    let mut wrapped = Vec::<f32>::with_capacity(len);
    let mut modulation = Vec::<f32>::with_capacity(len);
    let mut sigma = Vec::<f32>::with_capacity(len);
    // The offset map is cheap to compute alongside, but only one set per
    // camera keeps it (as texture): the others never allocate or write one.
    let mut offset = Vec::<f32>::with_capacity(if keep_offset { len } else { 0 });
    let chunk = PIXELS_PER_TASK;
    let kernel = Kernel { model: model.as_ref(), params, noise_sigma_dn: noise.sigma_dn, plane_len: len };
    let done = std::sync::atomic::AtomicUsize::new(0);
    let tasks = len.div_ceil(chunk);
    let total_tasks = tasks.max(1);
    let offset_chunks: Vec<Option<&mut [MaybeUninit<f32>]>> = if keep_offset {
        offset.spare_capacity_mut()[..len].chunks_mut(chunk).map(Some).collect()
    } else {
        (0..tasks).map(|_| None).collect()
    };
    let stats = saturation_count.spare_capacity_mut()[..len]
        .par_chunks_mut(chunk)
        .zip(wrapped.spare_capacity_mut()[..len].par_chunks_mut(chunk))
        .zip(modulation.spare_capacity_mut()[..len].par_chunks_mut(chunk))
        .zip(sigma.spare_capacity_mut()[..len].par_chunks_mut(chunk))
        .zip(offset_chunks.into_par_iter())
        .enumerate()
        .map(|(t, ((((count, phase), modu), sig), off))| {
            if control.is_cancelled() {
                return SetStats::default();
            }
            let start = t * chunk;
            let mut stats = SetStats::default();
            let pixels = count.len();
            let out = BlockOut { count, phase, modulation: modu, sigma: sig, offset: off };
            let written = match &stack.samples {
                Samples::U8(data) => kernel.block(data, start, out, &mut stats),
                Samples::U16(data) => kernel.block(data, start, out, &mut stats),
            };
            debug_assert_eq!(written, pixels, "task {t}: the phase kernel left pixels unwritten");
            let finished = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if finished.is_multiple_of(64) {
                control.set_fraction(finished as f32 / total_tasks as f32);
            }
            stats
        })
        .reduce(SetStats::default, SetStats::merge);
    control.check()?;
    // A task is skipped only when the run was cancelled.
    if done.into_inner() != tasks {
        return Err(Cancelled);
    }
    // SAFETY: every task ran, and a task's `tile`s write each of the four
    // maps, and the offset map where it is kept, at every pixel of its chunk;
    // the chunks cover `0..len`.
    unsafe {
        saturation_count.set_len(len);
        wrapped.set_len(len);
        modulation.set_len(len);
        sigma.set_len(len);
        if keep_offset {
            offset.set_len(len);
        }
    }
    Ok(WrappedPhase {
        width: w,
        height: h,
        period_px: set.period_px,
        shifts: model.shifts(),
        saturation_count,
        wrapped_phase_rad: wrapped,
        modulation_dn: modulation,
        phase_sigma_rad: sigma,
        offset_dn: keep_offset.then_some(offset),
        noise,
        stats,
    })
}

trait Sample: Copy + Send + Sync {
    fn to_f32(self) -> f32;
}

impl Sample for u8 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}

impl Sample for u16 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}

/// Output slices of one block of consecutive pixels, not yet written: a
/// tile writes every element of each.
struct BlockOut<'a> {
    count: &'a mut [MaybeUninit<u8>],
    phase: &'a mut [MaybeUninit<f32>],
    modulation: &'a mut [MaybeUninit<f32>],
    sigma: &'a mut [MaybeUninit<f32>],
    /// Only where the set's offset map is kept.
    offset: Option<&'a mut [MaybeUninit<f32>]>,
}

struct Kernel<'a> {
    model: &'a ShiftModel,
    params: &'a PhaseParams,
    noise_sigma_dn: f32,
    plane_len: usize,
}

/// Pixels whose sums the accumulation keeps in registers at once: two AVX2
/// registers of f32 per sum.
const LANES: usize = 16;

/// Pixels per tile: the tile's accumulators (3 x f32 + u32 per pixel, 4 kB)
/// stay in L1 while the N planes stream through.
const TILE: usize = 256;

/// A tile's per-pixel [`Coefficients`], one array per coefficient.
struct CoefficientColumns {
    c00: [f32; TILE],
    c01: [f32; TILE],
    c02: [f32; TILE],
    c11: [f32; TILE],
    c12: [f32; TILE],
    c22: [f32; TILE],
}

impl CoefficientColumns {
    fn new() -> Self {
        Self {
            c00: [0.0; TILE],
            c01: [0.0; TILE],
            c02: [0.0; TILE],
            c11: [0.0; TILE],
            c12: [0.0; TILE],
            c22: [0.0; TILE],
        }
    }

    #[inline(always)]
    fn set(&mut self, j: usize, c: Coefficients) {
        self.c00[j] = c.c00;
        self.c01[j] = c.c01;
        self.c02[j] = c.c02;
        self.c11[j] = c.c11;
        self.c12[j] = c.c12;
        self.c22[j] = c.c22;
    }

    #[inline(always)]
    fn fill(&mut self, range: std::ops::Range<usize>, c: Coefficients) {
        self.c00[range.clone()].fill(c.c00);
        self.c01[range.clone()].fill(c.c01);
        self.c02[range.clone()].fill(c.c02);
        self.c11[range.clone()].fill(c.c11);
        self.c12[range.clone()].fill(c.c12);
        self.c22[range].fill(c.c22);
    }

    #[inline(always)]
    fn get(&self, j: usize) -> Coefficients {
        Coefficients {
            c00: self.c00[j],
            c01: self.c01[j],
            c02: self.c02[j],
            c11: self.c11[j],
            c12: self.c12[j],
            c22: self.c22[j],
        }
    }
}

/// What one plane adds to a pixel's sums of Eq. 3.
#[derive(Clone, Copy)]
struct SampleStep {
    threshold: f32,
    /// The plane's index: its bit in the saturation mask.
    shift: u32,
    cos: f32,
    sin: f32,
    zero_saturated: bool,
}

/// Adds one sample to a pixel's saturation mask and sums (Alg. 1 and Eq. 3).
/// Shift-and-or builds the mask, not a select: a select compiles to a
/// masked store that stalls store-to-load forwarding.
#[inline(always)]
fn add_sample(v: f32, (mask, s0, sc, ss): (&mut u32, &mut f32, &mut f32, &mut f32), step: SampleStep) {
    let sat = v >= step.threshold;
    *mask |= u32::from(sat) << step.shift;
    let vm = if sat && step.zero_saturated { 0.0 } else { v };
    *s0 += vm;
    *sc += vm * step.cos;
    *ss += vm * step.sin;
}

/// Per-pixel solution of Eqs. 2-3 for given coefficients and sums:
/// `(phase, modulation, sigma, offset)`, phase and sigma NaN when the
/// modulation is below the floor. Branch-free so tile loops vectorise.
#[inline(always)]
fn solve(c: &Coefficients, b0: f32, b1: f32, b2: f32, noise_sigma_dn: f32, min_mod: f32) -> (f32, f32, f32, f32) {
    let a0 = c.c00 * b0 + c.c01 * b1 + c.c02 * b2;
    let a1 = c.c01 * b0 + c.c11 * b1 + c.c12 * b2;
    let a2 = c.c02 * b0 + c.c12 * b1 + c.c22 * b2;
    let modulation = (a1 * a1 + a2 * a2).sqrt();
    let mut phi = fast_atan2(-a2, a1);
    phi = if phi < 0.0 { phi + TAU } else { phi };
    phi = if phi >= TAU { phi - TAU } else { phi };
    // g = (0, sin phi, cos phi) with sin phi = -a2/B, cos phi = a1/B.
    let inv = 1.0 / modulation;
    let (sn, cs) = (-a2 * inv, a1 * inv);
    let gcg = c.c11 * sn * sn + 2.0 * c.c12 * sn * cs + c.c22 * cs * cs;
    let sigma = noise_sigma_dn * gcg.max(0.0).sqrt() * inv;
    let valid = modulation >= min_mod && modulation > 0.0;
    (if valid { phi } else { f32::NAN }, modulation, if valid { sigma } else { f32::NAN }, a0)
}

impl Kernel<'_> {
    /// Alg. 1 + Alg. 2 over pixels `start..start + out.count.len()`, picking
    /// the widest SIMD the CPU has at run time.
    /// Returns the pixels written: every pixel of `out` (checked in debug
    /// builds here and by the caller, whose `set_len` relies on it).
    fn block<T: Sample>(&self, data: &[T], start: usize, out: BlockOut<'_>, stats: &mut SetStats) -> usize {
        simd::dispatch(
            #[inline(always)]
            || self.block_generic(data, start, out, stats),
        )
    }

    #[inline(always)]
    fn block_generic<T: Sample>(&self, data: &[T], start: usize, mut out: BlockOut<'_>, stats: &mut SetStats) -> usize {
        let len = out.count.len();
        let mut written = 0;
        // Once per block: zeroing it per tile would be as many stores as the
        // tile's coefficients themselves.
        let mut cols = CoefficientColumns::new();
        let mut t0 = 0;
        while t0 < len {
            let n = TILE.min(len - t0);
            let range = t0..t0 + n;
            written += self.tile(
                data,
                start + t0,
                BlockOut {
                    count: &mut out.count[range.clone()],
                    phase: &mut out.phase[range.clone()],
                    modulation: &mut out.modulation[range.clone()],
                    sigma: &mut out.sigma[range.clone()],
                    offset: out.offset.as_deref_mut().map(|o| &mut o[range]),
                },
                &mut cols,
                stats,
            );
            t0 += n;
        }
        debug_assert_eq!(written, len, "the phase kernel left pixels of a block unwritten");
        written
    }

    /// One tile: accumulate the three sums of Eq. 3 over the N planes (a
    /// group of pixels at a time, its sums in registers), pick each pixel's
    /// coefficients (the full mask's, Eq. 5 for uniform shifts, or the
    /// unsaturated samples' from the mask table) and solve every pixel in a
    /// vectorised pass. Returns the pixels written to every map (the
    /// tile's length).
    #[inline(always)]
    fn tile<T: Sample>(
        &self,
        data: &[T],
        start: usize,
        out: BlockOut<'_>,
        cols: &mut CoefficientColumns,
        stats: &mut SetStats,
    ) -> usize {
        let n = out.count.len();
        let mut s0 = [0f32; TILE];
        let mut sc = [0f32; TILE];
        let mut ss = [0f32; TILE];
        let mut mask = [0u32; TILE];

        let (s0, sc, ss, mask) = (&mut s0[..n], &mut sc[..n], &mut ss[..n], &mut mask[..n]);
        let thr = f32::from(self.params.saturation_threshold);
        let selection = self.params.selection;
        let zero_saturated = selection == SampleSelection::Unsaturated;
        // Groups of LANES pixels keep their four sums in registers over all
        // N planes and are stored once, instead of loading and storing the
        // tile's sums once per plane. Per pixel the samples are summed in the
        // same order with the same operations, so the sums are the same.
        let shifts_n = self.model.shifts();
        let groups = n / LANES;
        for g in 0..groups {
            let j = g * LANES;
            let (mut m, mut a0, mut ac, mut as_) = ([0u32; LANES], [0f32; LANES], [0f32; LANES], [0f32; LANES]);
            for k in 0..shifts_n {
                let base = k * self.plane_len + start + j;
                let plane: &[T; LANES] = data[base..base + LANES].try_into().expect("a group of LANES samples");
                let (cos, sin) = (self.model.cos[k], self.model.sin[k]);
                let step = SampleStep { threshold: thr, shift: k as u32, cos, sin, zero_saturated };
                for l in 0..LANES {
                    add_sample(plane[l].to_f32(), (&mut m[l], &mut a0[l], &mut ac[l], &mut as_[l]), step);
                }
            }
            mask[j..j + LANES].copy_from_slice(&m);
            s0[j..j + LANES].copy_from_slice(&a0);
            sc[j..j + LANES].copy_from_slice(&ac);
            ss[j..j + LANES].copy_from_slice(&as_);
        }
        let rest = groups * LANES;
        for k in 0..shifts_n {
            let base = k * self.plane_len + start;
            let plane = &data[base + rest..base + n];
            let (cos, sin) = (self.model.cos[k], self.model.sin[k]);
            let step = SampleStep { threshold: thr, shift: k as u32, cos, sin, zero_saturated };
            for ((((&v, m), a0), ac), as_) in plane
                .iter()
                .zip(mask[rest..].iter_mut())
                .zip(s0[rest..].iter_mut())
                .zip(sc[rest..].iter_mut())
                .zip(ss[rest..].iter_mut())
            {
                add_sample(v.to_f32(), (m, a0, ac, as_), step);
            }
        }
        let full = self.model.full_mask;
        let full_coeff = self.model.coefficients(full);
        let min_mod = self.params.min_modulation_dn;
        let noise = self.noise_sigma_dn;
        let shifts = self.model.shifts() as u32;
        // Per-pixel coefficients: the full-mask ones (Eq. 5 for uniform
        // shifts) or, with saturated samples, the mask table's (Eqs. 2-4),
        // one array per coefficient so the solve below is one vectorised
        // loop without transposes. A group of pixels none of which saturated
        // (most of a part away from its highlights) takes the full-mask
        // coefficients without a per-pixel lookup.
        let coeff = &mut *cols;
        const GROUP: usize = 8;
        let mut g0 = 0;
        while g0 < n {
            let g1 = (g0 + GROUP).min(n);
            let any_saturated = mask[g0..g1].iter().fold(0, |a, &m| a | m) != 0;
            if !any_saturated || selection == SampleSelection::All {
                coeff.fill(g0..g1, full_coeff);
            } else {
                // Without a branch per pixel (about half the pixels of a
                // shiny part saturate somewhere, in no predictable pattern):
                // the coefficients of the used samples are the full mask's
                // where none saturated and invalid where fewer than 3 are
                // left, as for the mask with no sample used.
                for (j, &m) in mask.iter().enumerate().take(g1).skip(g0) {
                    let used = if selection == SampleSelection::RejectSaturated {
                        if m == 0 { full } else { 0 }
                    } else {
                        full & !m
                    };
                    coeff.set(j, self.model.coefficients(used));
                }
            }
            g0 = g1;
        }
        let mut offsets = [0f32; TILE];
        let offsets = &mut offsets[..n];
        let (mut partial, mut over, mut valid, mut low) = (0u32, 0u32, 0u32, 0u32);
        debug_assert!(
            [out.phase.len(), out.modulation.len(), out.sigma.len()].iter().all(|&l| l == n)
                && out.offset.as_ref().is_none_or(|o| o.len() == n),
            "a tile's maps differ in length"
        );
        for j in 0..n {
            let c = coeff.get(j);
            let (phi, modulation, sigma, offset) = solve(&c, s0[j], sc[j], ss[j], noise, min_mod);
            let fitted = c.is_valid();
            let saturated = mask[j].count_ones();
            out.phase[j] = MaybeUninit::new(phi);
            out.modulation[j] = MaybeUninit::new(if fitted { modulation } else { 0.0 });
            out.sigma[j] = MaybeUninit::new(sigma);
            offsets[j] = if fitted { offset } else { 0.0 };
            out.count[j] = MaybeUninit::new(saturated as u8);
            let is_valid = !phi.is_nan();
            partial += u32::from(mask[j] != 0);
            over += u32::from(shifts - saturated < 3);
            valid += u32::from(is_valid);
            low += u32::from(!is_valid && fitted);
        }
        if let Some(out_offset) = out.offset {
            out_offset.iter_mut().zip(offsets.iter()).for_each(|(o, &v)| {
                o.write(v);
            });
        }
        stats.partially_saturated += partial as usize;
        stats.over_saturated += over as usize;
        stats.valid += valid as usize;
        stats.low_modulation += low as usize;
        stats.pixels += n;
        n
    }
}
