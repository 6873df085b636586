//! Measurement uncertainty of every inspection result, as the GUM states it
//! (JCGM 100:2008): a standard uncertainty `u` combined from a budget of
//! contributions by the law of propagation, or from a Monte Carlo
//! simulation where the result is not linear in the data (JCGM 101:2008),
//! and the expanded uncertainty `U = k u` with the coverage factor k = 2.
//!
//! The random part comes from the height noise of the map's nodes. The
//! nodes of a height map are not independent: the cloud is resampled onto a
//! grid finer than the points and the phase is smoothed, so neighbours share
//! noise. Treating them as independent makes `u` of a plane's height
//! 1.5-1.7 times too small on the simulator's watch plate. [`node_noise`]
//! therefore measures the noise of a region from the variogram of its plane
//! residual (JCGM 100 4.2: a Type A evaluation): the plateau gives the
//! variance, the short lags its correlation, and the sum of the
//! correlations over the lags the variance inflation `F` of a mean (the
//! number of nodes that count as one independent observation). A smooth
//! form left in the residual (a bow) adds little at the short lags used,
//! so it does not pass for noise.
//!
//! Least-squares planes propagate it by their covariance
//! `σ² F (AᵀA)⁻¹` ([`plane_covariance`]); peak-to-valley, coplanarity,
//! texture and profile parameters are recomputed on the map with synthetic
//! noise of the same variance and correlation added ([`monte_carlo`]), from
//! a seed, so a rerun states the same `u`.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::height_map::HeightMap;
use super::plane_fit::Plane;
use super::region::{NamedRegion, RegionGrid, region_grid};
pub use crate::engine::camera_model::ScaleUncertainty;

/// Coverage factor of the expanded uncertainty (about 95 % for a normal
/// distribution, JCGM 100 6.3).
pub const COVERAGE_FACTOR: f64 = 2.0;

/// Monte Carlo trials of a row unless set otherwise (JCGM 101 7.2 asks for
/// more where a coverage interval's ends matter; the standard deviation of
/// 50 trials is within about 10 % of its limit).
pub const DEFAULT_TRIALS: usize = 50;

/// How `u` was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UncertaintyMethod {
    /// The GUM law of propagation (JCGM 100 5.1).
    Propagation,
    /// Monte Carlo propagation of distributions (JCGM 101).
    MonteCarlo,
}

impl UncertaintyMethod {
    pub fn name(self) -> &'static str {
        match self {
            UncertaintyMethod::Propagation => "propagation",
            UncertaintyMethod::MonteCarlo => "monte-carlo",
        }
    }

    pub fn from_name(text: &str) -> Option<Self> {
        [UncertaintyMethod::Propagation, UncertaintyMethod::MonteCarlo].into_iter().find(|m| m.name() == text)
    }
}

/// One line of an uncertainty budget: a source and its standard
/// uncertainty in the value's unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Contribution {
    pub source: String,
    pub u: f64,
}

impl Contribution {
    pub fn new(source: impl Into<String>, u: f64) -> Self {
        Self { source: source.into(), u }
    }
}

/// A result's stated uncertainty, in the result's unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// Combined standard uncertainty.
    pub u: f64,
    /// Expanded uncertainty `k u`.
    #[serde(rename = "U")]
    pub expanded: f64,
    pub k: f64,
    pub method: UncertaintyMethod,
    /// The contributions, combined as a root sum of squares (uncorrelated).
    pub budget: Vec<Contribution>,
    /// Monte Carlo trials behind the random contribution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trials: Option<usize>,
    /// What noise alone gives for this result on as many nodes (for a
    /// peak-to-valley: noise raises it; a value near its floor is noise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_floor: Option<f64>,
}

impl Uncertainty {
    /// `u` as the root sum of squares of the budget, `U = k u`.
    pub fn from_budget(method: UncertaintyMethod, budget: Vec<Contribution>) -> Self {
        let u = budget.iter().map(|c| c.u * c.u).sum::<f64>().sqrt();
        Self { u, expanded: COVERAGE_FACTOR * u, k: COVERAGE_FACTOR, method, budget, trials: None, noise_floor: None }
    }

    pub fn with_trials(mut self, trials: usize) -> Self {
        self.trials = Some(trials);
        self
    }

    pub fn with_noise_floor(mut self, floor: f64) -> Self {
        self.noise_floor = floor.is_finite().then_some(floor);
        self
    }
}

/// The budget line of a result that scales with height, `|value| u_rel`
/// (0 with a note where the calibration states nothing).
pub fn height_scale_contribution(calibration: &ScaleUncertainty, value: f64) -> Contribution {
    match calibration.height_relative {
        Some(rel) => Contribution::new(format!("calibration height scale ({rel:.3e} relative)"), value.abs() * rel),
        None => Contribution::new("calibration height scale (not stated by the calibration: taken as 0)", 0.0),
    }
}

/// Noise of a region's nodes measured from its plane residual.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeNoise {
    /// Standard deviation of one node's height.
    pub sigma_um: f64,
    /// Variance inflation of a mean over many nodes: `Σ_h ρ(h)` over the
    /// lags `h` where the noise is correlated (1 for independent nodes).
    pub correlation_factor: f64,
}

/// No noise, nodes independent (what a result read back without its noise states).
impl Default for NodeNoise {
    fn default() -> Self {
        Self { sigma_um: 0.0, correlation_factor: 1.0 }
    }
}

impl NodeNoise {
    /// Standard deviation (nodes) of the Gaussian whose blur of white noise
    /// ([`correlated_noise`]) has this correlation factor. A continuous
    /// Gaussian gives `4 π s²`, but the kernel is sampled on the nodes, and
    /// at the factors maps have (3-4) its samples give a fifth less (3.4
    /// asks for s = 0.52, whose five taps give 2.7): `s` is solved for the
    /// sampled kernel, whose factor per axis is `(Σ w)² / Σ w²`.
    pub fn blur_sigma_nodes(&self) -> f64 {
        let target = self.correlation_factor.max(1.0).sqrt();
        let (mut lo, mut hi) = (0.0f64, 2.0 * (self.correlation_factor / (4.0 * std::f64::consts::PI)).sqrt() + 1.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if sampled_blur_factor(mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// "σ 0.21 um per node, correlated over ~2.4 nodes" for budgets.
    pub fn describe(&self) -> String {
        format!("σ {:.3} um per node, {:.1} nodes per independent one", self.sigma_um, self.correlation_factor)
    }
}

/// Lags (in nodes, Chebyshev distance) whose variogram gives the noise
/// variance: beyond the correlation the resampling and the phase filters
/// leave, short enough that a bow adds little.
const PLATEAU_LAGS: [usize; 2] = [6, 7];

/// Longest lag summed into the correlation factor.
const MAX_CORRELATION_LAG: usize = 5;

/// Anchors of the variogram at most (a full-size region has millions of
/// nodes; a regular subset gives the same variogram to a few per cent).
const MAX_ANCHORS: usize = 200_000;

/// Noise of the nodes of `regions` around `plane` (module docs): `None`
/// with fewer than a few hundred node pairs per lag.
pub fn node_noise(map: &HeightMap, regions: &[NamedRegion], plane: &Plane) -> Option<NodeNoise> {
    region_variogram(map, regions, plane).map(|v| v.node_noise())
}

/// The [`Variogram`] of the residual of `regions` around `plane`.
pub fn region_variogram(map: &HeightMap, regions: &[NamedRegion], plane: &Plane) -> Option<Variogram> {
    let (grid, residual) = region_residual(map, regions, plane)?;
    variogram_of_residual(&residual, grid.width, grid.height)
}

/// The residual of `regions` around `plane` along its normal, in um, on the
/// regions' window (NaN outside them and at holes).
fn region_residual(map: &HeightMap, regions: &[NamedRegion], plane: &Plane) -> Option<(RegionGrid, Vec<f64>)> {
    let grid = region_grid(map, regions)?;
    let scale_um = map.unit.um_per_unit();
    let cos = plane.cos_tilt();
    let residual: Vec<f64> = (0..grid.height)
        .flat_map(|k| (0..grid.width).map(move |j| (j, k)))
        .map(|(j, k)| {
            let (c, r) = (grid.c0 + j, grid.r0 + k);
            let z = map.z[r * map.width + c];
            if grid.inside[k * grid.width + j] && !z.is_nan() {
                (f64::from(z) - plane.z_at(map.x_mm(c), map.y_mm(r))) * cos * scale_um
            } else {
                f64::NAN
            }
        })
        .collect();
    Some((grid, residual))
}

/// Half-width in nodes of the window a node's own noise variance is read
/// in ([`relative_node_variance`]): 81 nodes, about 20 independent ones at
/// the correlation of a resampled map, and narrow against a form's bow.
const LOCAL_VARIANCE_HALF_WIDTH: usize = 4;

/// Each valid node's noise variance relative to the mean over the nodes of
/// `regions` (mean 1), in the order of
/// [`region_samples`](super::region::region_samples)' points; `None` where
/// the regions hold no node or no noise. `correlation_factor` is the
/// noise's ([`NodeNoise`]).
///
/// The noise of a map is not the same everywhere: a pixel whose phase came
/// from a sparser set, or was fitted to fewer unsaturated samples, or saw
/// little modulation, is several times noisier than its neighbours, and on
/// glossy metal such pixels gather where the highlights are. A plane's
/// height at its centroid does not care (every node weighs 1/n), but its
/// slopes weigh the nodes by their distance from the centroid, and on the
/// simulator's brushed watch plate the noisy nodes lie where that weight is
/// large: the slope's variance is 1.5 times what uniform noise of the same
/// mean gives; a peak-to-valley is made by the noisiest nodes.
///
/// Each node's share is the mean of the squared second differences of the
/// residual (along X and along Y: a locally linear form cancels) in a
/// window around it, a Type A evaluation from the one measurement. Those
/// window means scatter even where the noise is uniform, and a scatter read
/// as heteroscedasticity would raise a peak-to-valley's noise floor by a
/// tenth on white noise: the shares are shrunk towards 1 by the part of
/// their scatter that uniform noise of the same correlation, on the same
/// nodes, gives (drawn from a fixed seed), as an empirical Bayes estimate.
pub fn relative_node_variance(
    map: &HeightMap,
    regions: &[NamedRegion],
    plane: &Plane,
    correlation_factor: f64,
) -> Option<Vec<f64>> {
    let (grid, residual) = region_residual(map, regions, plane)?;
    let (w, h) = (grid.width, grid.height);
    let shares = |field: &[f64]| -> Option<Vec<f64>> {
        let at = |c: usize, r: usize| field[r * w + c];
        let squared = |v: f64| if v.is_nan() { None } else { Some(v * v) };
        let q: Vec<f64> = (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                if field[i].is_nan() {
                    return f64::NAN;
                }
                let along_x = (c > 0 && c + 1 < w).then(|| squared(at(c - 1, r) - 2.0 * at(c, r) + at(c + 1, r)));
                let along_y = (r > 0 && r + 1 < h).then(|| squared(at(c, r - 1) - 2.0 * at(c, r) + at(c, r + 1)));
                match (along_x.flatten(), along_y.flatten()) {
                    (Some(a), Some(b)) => (a + b) / 2.0,
                    (Some(a), None) | (None, Some(a)) => a,
                    (None, None) => f64::NAN,
                }
            })
            .collect();
        let local = box_means(&q, w, h, LOCAL_VARIANCE_HALF_WIDTH);
        let valid: Vec<f64> = (0..w * h).filter(|&i| !field[i].is_nan()).map(|i| local[i]).collect();
        let known: Vec<f64> = valid.iter().copied().filter(|v| !v.is_nan()).collect();
        let mean = known.iter().sum::<f64>() / known.len().max(1) as f64;
        (mean > 0.0).then(|| valid.iter().map(|v| if v.is_nan() { 1.0 } else { v / mean }).collect())
    };
    let measured = shares(&residual)?;
    let mut rng = ChaCha8Rng::seed_from_u64(0x5a4d_0e5e);
    let noise = NodeNoise { sigma_um: 1.0, correlation_factor };
    let uniform: Vec<f64> = correlated_noise(w, h, noise.blur_sigma_nodes(), &mut rng)
        .into_iter()
        .zip(&residual)
        .map(|(e, r)| if r.is_nan() { f64::NAN } else { e })
        .collect();
    let scatter = |s: &[f64]| s.iter().map(|v| (v - 1.0).powi(2)).sum::<f64>() / s.len().max(1) as f64;
    let by_chance = shares(&uniform).map_or(0.0, |s| scatter(&s));
    let kept = (1.0 - by_chance / scatter(&measured).max(f64::MIN_POSITIVE)).max(0.0);
    Some(measured.iter().map(|v| 1.0 + kept * (v - 1.0)).collect())
}

/// Mean of the non-NaN values of a `width` x `height` field in a square
/// window of half-width `half` around each node (NaN where it holds fewer
/// than 9), by summed-area tables.
fn box_means(field: &[f64], width: usize, height: usize, half: usize) -> Vec<f64> {
    let (w, h) = (width, height);
    let mut tables = vec![[0.0f64; 2]; (w + 1) * (h + 1)];
    for r in 0..h {
        let mut row = [0.0f64; 2];
        for c in 0..w {
            let v = field[r * w + c];
            if !v.is_nan() {
                row[0] += 1.0;
                row[1] += v;
            }
            let above = tables[r * (w + 1) + c + 1];
            tables[(r + 1) * (w + 1) + c + 1] = [above[0] + row[0], above[1] + row[1]];
        }
    }
    (0..w * h)
        .map(|i| {
            let (c, r) = (i % w, i / w);
            let (c0, c1) = (c.saturating_sub(half), (c + half + 1).min(w));
            let (r0, r1) = (r.saturating_sub(half), (r + half + 1).min(h));
            let t = |c: usize, r: usize| tables[r * (w + 1) + c];
            let (a, b, d, e) = (t(c1, r1), t(c0, r1), t(c1, r0), t(c0, r0));
            let n = a[0] - b[0] - d[0] + e[0];
            if n >= 9.0 { (a[1] - b[1] - d[1] + e[1]) / n } else { f64::NAN }
        })
        .collect()
}

/// The residual less its least-squares quadratic surface: a bow or a
/// saddle left by the plane would otherwise pass for noise at the plateau
/// lags (a 5 um bow over 6 mm changes by about 1 um over 7 nodes of 45 um);
/// six parameters taken from thousands of nodes leave the noise as it is.
fn without_quadratic_form(residual: &[f64], width: usize, height: usize) -> Vec<f64> {
    use nalgebra::{Matrix6, Vector6};
    let (cx, cy) = (width as f64 / 2.0, height as f64 / 2.0);
    let scale = (width.max(height) as f64 / 2.0).max(1.0);
    let terms = |c: usize, r: usize| {
        let (x, y) = ((c as f64 - cx) / scale, (r as f64 - cy) / scale);
        Vector6::new(1.0, x, y, x * x, x * y, y * y)
    };
    let (mut ata, mut atb) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros());
    for (i, &v) in residual.iter().enumerate().filter(|(_, v)| !v.is_nan()) {
        let t = terms(i % width, i / width);
        ata += t * t.transpose();
        atb += t * v;
    }
    let Some(coef) = ata.cholesky().map(|c| c.solve(&atb)) else { return residual.to_vec() };
    residual.iter().enumerate().map(|(i, &v)| v - terms(i % width, i / width).dot(&coef)).collect()
}

/// [`node_noise`] of a residual on a `width` x `height` grid (NaN: none),
/// its quadratic form removed first.
pub fn node_noise_of_residual(residual: &[f64], width: usize, height: usize) -> Option<NodeNoise> {
    variogram_of_residual(residual, width, height).map(|v| v.node_noise())
}

/// What a region's residual says about its noise: the variance from the
/// variogram's plateau, and per ring of lags (Chebyshev distance 1, 2, ..)
/// the mean correlation and the node pairs behind it, so that regions can
/// be pooled ([`pooled_correlation_factor`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Variogram {
    pub sigma_um: f64,
    /// `(mean ρ over the ring's lags, node pairs)` for rings 1..=5.
    pub rings: Vec<(f64, usize)>,
}

impl Variogram {
    /// This region's noise alone: its σ and its own correlation factor.
    pub fn node_noise(&self) -> NodeNoise {
        let factor = pooled_correlation_factor(std::slice::from_ref(self)).unwrap_or(1.0);
        NodeNoise { sigma_um: self.sigma_um, correlation_factor: factor }
    }
}

/// The correlation factor `F = Σ_h ρ(h)` of the noise of several regions
/// together: per ring, the correlations weighted by their node pairs;
/// rings summed outwards while their mean correlation stands above its own
/// estimation noise, so the far lags' ρ ≈ 0 does not add up.
///
/// The correlation comes from the pipeline (rectification, matching, the
/// resampling onto the map), the same on every surface; a region's own
/// estimate of a few thousand nodes is noisy (on the simulator's watch
/// plate a 3 x 2 mm plate gives F = 2.9 ± 1.1 where its noise has 3.5),
/// the inspection's plane regions together are not. `None` for no regions.
pub fn pooled_correlation_factor(variograms: &[Variogram]) -> Option<f64> {
    if variograms.is_empty() {
        return None;
    }
    let mut factor = 1.0f64;
    for d in 0..MAX_CORRELATION_LAG {
        let (weighted, pairs) = variograms
            .iter()
            .filter_map(|v| v.rings.get(d))
            .fold((0.0, 0usize), |(s, n), &(rho, pairs)| (s + rho * pairs as f64, n + pairs));
        if pairs == 0 {
            break;
        }
        let rho = weighted / pairs as f64;
        // Pairs share noise (about F of them count as one): twice the
        // standard error of a mean ρ, and never below half a per cent.
        let noise = 2.0 * (factor / pairs as f64).sqrt();
        if rho < noise.max(0.005) {
            break;
        }
        let ring_lags = 8 * (d + 1);
        factor += rho * ring_lags as f64;
    }
    Some(factor.max(1.0))
}

/// The variograms an inspection measured on its plane regions, by the
/// regions' label ([`crate::analysis::region::label`]), and the correlation
/// factor they give together: measured once per inspection, read by every
/// row whose planes use those regions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlaneNoises {
    pub by_label: Vec<(String, Variogram)>,
    pub pooled_factor: Option<f64>,
}

impl PlaneNoises {
    pub fn new(by_label: Vec<(String, Variogram)>) -> Self {
        let variograms: Vec<Variogram> = by_label.iter().map(|(_, v)| v.clone()).collect();
        Self { pooled_factor: pooled_correlation_factor(&variograms), by_label }
    }

    pub fn variogram(&self, label: &str) -> Option<&Variogram> {
        self.by_label.iter().find(|(l, _)| l == label).map(|(_, v)| v)
    }
}

/// [`Variogram`] of a residual on a `width` x `height` grid (NaN: none),
/// its quadratic form removed first.
///
/// The plain variogram of increments, `γ(d) = E[(r(p+d) - r(p))²] / 2 =
/// C(0) - C(d)` for noise of covariance C, keeps whatever form a quadratic
/// leaves, times d: on a narrow strip of a loaded gasket it read σ 0.33 um
/// and 56 nodes per independent one where the noise has 0.15 um and 5, and
/// a flatness's U was 4.5 times its spread. Second differences cancel a
/// locally linear form: `γ₂(d) = E[(r(p-d) - 2 r(p) + r(p+d))²] / 6`,
/// which is `C(0) - 4/3 C(d) + 1/3 C(2d)`, each lag's covariance from γ₂ and
/// the covariance at twice the lag, outwards in. Both see the same noise,
/// but the noise's weak correlation beyond the plateau lags lowers γ₂'s
/// plateau more than γ's (on the brushed watch plate the steps' coverage
/// fell from 93-95 % to 92 %). So the plain variogram is kept unless it
/// reads more than [`FORM_LEAK_RATIO`] times the second differences'
/// variance: then it is the region's form, not its noise.
pub fn variogram_of_residual(residual: &[f64], width: usize, height: usize) -> Option<Variogram> {
    let residual = &without_quadratic_form(residual, width, height);
    let max_lag = PLATEAU_LAGS[PLATEAU_LAGS.len() - 1];
    let valid = residual.iter().filter(|r| !r.is_nan()).count();
    let stride = ((valid as f64 / MAX_ANCHORS as f64).sqrt().ceil() as usize).max(1);
    // Half-plane of lags (dx, dy): dy > 0, or dy = 0 and dx > 0.
    let lags: Vec<(isize, isize)> = (-(max_lag as isize)..=max_lag as isize)
        .flat_map(|dx| (0..=max_lag as isize).map(move |dy| (dx, dy)))
        .filter(|&(dx, dy)| dy > 0 || dx > 0)
        .collect();
    let at = |c: isize, r: isize| {
        if c < 0 || r < 0 || c >= width as isize || r >= height as isize {
            f64::NAN
        } else {
            residual[r as usize * width + c as usize]
        }
    };
    // Per lag: (Σ increment², pairs) and (Σ second difference², triples).
    let sums: Vec<[(f64, usize); 2]> = lags
        .par_iter()
        .map(|&(dx, dy)| {
            let mut out = [(0.0, 0usize); 2];
            for r in (0..height as isize).step_by(stride) {
                for c in (0..width as isize).step_by(stride) {
                    let (before, here, after) = (at(c - dx, r - dy), at(c, r), at(c + dx, r + dy));
                    let first = after - here;
                    if !first.is_nan() {
                        out[0].0 += first * first;
                        out[0].1 += 1;
                    }
                    let second = before - 2.0 * here + after;
                    if !second.is_nan() {
                        out[1].0 += second * second;
                        out[1].1 += 1;
                    }
                }
            }
            out
        })
        .collect();
    let plain = variogram_from_sums(&lags, &sums.iter().map(|s| s[0]).collect::<Vec<_>>(), false);
    let second = variogram_from_sums(&lags, &sums.iter().map(|s| s[1]).collect::<Vec<_>>(), true);
    match (plain, second) {
        (Some(p), Some(s)) if p.sigma_um.powi(2) > FORM_LEAK_RATIO * s.sigma_um.powi(2) => Some(s),
        (Some(p), _) => Some(p),
        (None, s) => s,
    }
}

/// How much more variance the plain variogram may read than the second
/// differences' before it is taken for form ([`variogram_of_residual`]);
/// on noise alone the two agree within a tenth.
const FORM_LEAK_RATIO: f64 = 1.5;

/// The variogram of per-lag sums of squared increments (`second`: second
/// differences) over pairs: the plateau's variance, then each ring's mean
/// correlation.
fn variogram_from_sums(lags: &[(isize, isize)], sums: &[(f64, usize)], second: bool) -> Option<Variogram> {
    let ring = |&(dx, dy): &(isize, isize)| dx.unsigned_abs().max(dy.unsigned_abs());
    let divisor = if second { 6.0 } else { 2.0 };
    let gamma = |(sum, n): (f64, usize)| sum / (divisor * n as f64);
    let (mut plateau, mut plateau_pairs) = (0.0, 0);
    for (lag, s) in lags.iter().zip(sums) {
        if PLATEAU_LAGS.contains(&ring(lag)) && s.1 > 0 {
            plateau += gamma(*s) * s.1 as f64;
            plateau_pairs += s.1;
        }
    }
    // A narrow strip has no triples along its short side at the plateau
    // lags; the other lags say what the noise is, given enough of them.
    if plateau_pairs < 100 * PLATEAU_LAGS.len() {
        return None;
    }
    let variance = plateau / plateau_pairs as f64;
    if !(variance > 0.0) {
        return None;
    }
    let index = |(dx, dy): (isize, isize)| {
        let (dx, dy) = if dy < 0 || (dy == 0 && dx < 0) { (-dx, -dy) } else { (dx, dy) };
        lags.iter().position(|&l| l == (dx, dy))
    };
    // Plain: C(d) = σ² - γ(d). Second differences: C(d) = (6 σ² - 6 γ₂(d) +
    // 2 C(2d)) / 8, rings outwards in (C(2d) beyond the summed rings is 0).
    let mut covariance = vec![0.0; lags.len()];
    for d in (1..=MAX_CORRELATION_LAG).rev() {
        for (i, lag) in lags.iter().enumerate().filter(|(i, l)| ring(l) == d && sums[*i].1 > 0) {
            covariance[i] = if second {
                let twice = if 2 * d <= MAX_CORRELATION_LAG {
                    index((2 * lag.0, 2 * lag.1)).map_or(0.0, |j| covariance[j])
                } else {
                    0.0
                };
                (6.0 * variance - 6.0 * gamma(sums[i]) + 2.0 * twice) / 8.0
            } else {
                variance - gamma(sums[i])
            };
        }
    }
    let rings = (1..=MAX_CORRELATION_LAG)
        .map(|d| {
            let in_ring: Vec<(f64, usize)> = lags
                .iter()
                .enumerate()
                .filter(|(i, lag)| ring(lag) == d && sums[*i].1 > 0)
                .map(|(i, _)| (covariance[i] / variance, sums[i].1))
                .collect();
            let rho = in_ring.iter().map(|s| s.0).sum::<f64>() / in_ring.len().max(1) as f64;
            (rho, in_ring.iter().map(|s| s.1).sum())
        })
        .collect();
    Some(Variogram { sigma_um: variance.sqrt(), rings })
}

/// Covariance of a least-squares plane `z = a x + b y + c` fitted to
/// `points` whose heights have standard deviation `sigma` and the
/// correlation factor `F` ([`NodeNoise`]): `σ² F (AᵀA)⁻¹` in coordinates
/// centred on the points for uniform noise; with each node's own variance
/// `σ² wᵢ` ([`relative_node_variance`]) the GUM's law of propagation through
/// the same (unweighted) fit gives `σ² F (AᵀA)⁻¹ (AᵀWA) (AᵀA)⁻¹`, where the
/// height at the centroid and the slopes are no longer uncorrelated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneCovariance {
    pub centroid_mm: [f64; 2],
    /// Variance of the plane's height at the centroid (σ² F / n for uniform noise).
    pub var_height_at_centroid: f64,
    /// Covariance of that height with (slope_x, slope_y).
    pub height_slope_cov: [f64; 2],
    /// Covariance of (slope_x, slope_y), in (height unit / mm)².
    pub slope_cov: [[f64; 2]; 2],
}

impl PlaneCovariance {
    /// Variance of the plane's height at (x, y).
    pub fn var_height_at(&self, x_mm: f64, y_mm: f64) -> f64 {
        let d = [x_mm - self.centroid_mm[0], y_mm - self.centroid_mm[1]];
        let c = &self.slope_cov;
        self.var_height_at_centroid
            + 2.0 * (d[0] * self.height_slope_cov[0] + d[1] * self.height_slope_cov[1])
            + d[0] * d[0] * c[0][0]
            + 2.0 * d[0] * d[1] * c[0][1]
            + d[1] * d[1] * c[1][1]
    }
}

/// [`PlaneCovariance`] of points (x, y in mm) with height noise `sigma`
/// (any unit: the covariance is in it), correlation factor `F` and, where
/// given, each point's variance relative to `sigma²` (as many as points);
/// `None` for fewer than 3 points or points on a line.
pub fn plane_covariance(
    points: &[[f64; 3]],
    sigma: f64,
    correlation_factor: f64,
    relative_variance: Option<&[f64]>,
) -> Option<PlaneCovariance> {
    let n = points.len();
    if n < 3 || relative_variance.is_some_and(|w| w.len() != n) {
        return None;
    }
    let (mx, my) = points.iter().fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
    let (mx, my) = (mx / n as f64, my / n as f64);
    // Moments of the centred design, plain (AᵀA) and weighted (AᵀWA).
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut w0, mut wx, mut wy, mut wxx, mut wxy, mut wyy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, p) in points.iter().enumerate() {
        let (x, y) = (p[0] - mx, p[1] - my);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        let w = relative_variance.map_or(1.0, |w| w[i]);
        w0 += w;
        wx += w * x;
        wy += w * y;
        wxx += w * x * x;
        wxy += w * x * y;
        wyy += w * y * y;
    }
    let det = sxx * syy - sxy * sxy;
    if !(det > 0.0) {
        return None;
    }
    let v = sigma * sigma * correlation_factor;
    let s_inv = [[syy / det, -sxy / det], [-sxy / det, sxx / det]];
    let mul =
        |a: [[f64; 2]; 2], b: [[f64; 2]; 2]| [0, 1].map(|i| [0, 1].map(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j]));
    let slope_cov = mul(mul(s_inv, [[wxx, wxy], [wxy, wyy]]), s_inv).map(|row| row.map(|c| v * c));
    let height_slope_cov = [0, 1].map(|j| v / n as f64 * (wx * s_inv[0][j] + wy * s_inv[1][j]));
    Some(PlaneCovariance {
        centroid_mm: [mx, my],
        var_height_at_centroid: v * w0 / (n * n) as f64,
        height_slope_cov,
        slope_cov,
    })
}

/// The standard uncertainty of a plane's tilt `atan |g|` (g its slope
/// vector, relative to a reference plane when levelled) from the covariance
/// of g, in degrees.
///
/// Where the tilt is resolved (|g| beyond three times the noise σ of g
/// along its noisiest direction) the angle is linear in g along the slope.
/// Below that, |g| is not: a level surface measures a tilt that is never
/// zero (Rayleigh-distributed for round noise, half-normal for noise along
/// one direction, as on a long narrow strip), and the linear `u` would hold
/// its true tilt within `k u` only 86 % of the time for round noise. There
/// `k u` is the 95 % quantile of |g| for a true g of zero
/// ([`zero_tilt_quantile_95`]).
pub fn tilt_uncertainty_deg(g: [f64; 2], cov: [[f64; 2]; 2]) -> f64 {
    let norm2 = g[0] * g[0] + g[1] * g[1];
    let half_trace = (cov[0][0] + cov[1][1]) / 2.0;
    let spread = (((cov[0][0] - cov[1][1]) / 2.0).powi(2) + cov[0][1] * cov[0][1]).sqrt();
    let (largest, smallest) = (half_trace + spread, (half_trace - spread).max(0.0));
    let u = if norm2 > 9.0 * largest {
        ((g[0] * g[0] * cov[0][0] + 2.0 * g[0] * g[1] * cov[0][1] + g[1] * g[1] * cov[1][1]) / norm2).sqrt()
    } else {
        zero_tilt_quantile_95(largest, smallest) / COVERAGE_FACTOR
    };
    (u / (1.0 + norm2)).to_degrees()
}

/// The 95 % quantile of |g| for g ~ N(0, C), C with eigenvalues `l1 >= l2`:
/// 1.96 sqrt(l1) for l2 = 0, 2.45 sqrt(l1) (the Rayleigh's) for l2 = l1.
/// It is sqrt(l1) times a function of l2 / l1 alone, tabulated once
/// ([`unit_zero_tilt_quantile_95`]) and interpolated.
pub fn zero_tilt_quantile_95(l1: f64, l2: f64) -> f64 {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    const STEPS: usize = 100;
    if !(l1 > 0.0) {
        return 0.0;
    }
    let table =
        TABLE.get_or_init(|| (0..=STEPS).map(|i| unit_zero_tilt_quantile_95(i as f64 / STEPS as f64)).collect());
    let at = (l2 / l1).clamp(0.0, 1.0) * STEPS as f64;
    let i = (at as usize).min(STEPS - 1);
    let t = at - i as f64;
    l1.sqrt() * (table[i] * (1.0 - t) + table[i + 1] * t)
}

/// [`zero_tilt_quantile_95`] for `l1 = 1`, `l2 = ratio`: `|g|² = z1² +
/// ratio z2²`, whose distribution is one integral over z1 of the normal
/// probability that |z2| stays within the rest (Simpson's rule), the
/// quantile found by bisection.
fn unit_zero_tilt_quantile_95(ratio: f64) -> f64 {
    use statrs::function::erf::erf;
    let s2 = ratio.sqrt();
    let below = |q: f64| {
        let steps = 400;
        let h = 2.0 * q / steps as f64;
        (0..=steps)
            .map(|i| {
                let z1 = -q + i as f64 * h;
                let rest = (q * q - z1 * z1).max(0.0).sqrt();
                let inner = if s2 > 0.0 { erf(rest / (s2 * std::f64::consts::SQRT_2)) } else { 1.0 };
                let density = (-z1 * z1 / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt();
                let weight = if i == 0 || i == steps {
                    1.0
                } else if i % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                weight * density * inner
            })
            .sum::<f64>()
            * h
            / 3.0
    };
    let (mut lo, mut hi) = (1.9, 2.5);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if below(mid) < 0.95 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The taps of [`correlated_noise`]'s Gaussian of `s` nodes, normalised to
/// unit variance of the blurred noise (one axis); empty below 0.35 nodes,
/// where the noise stays white.
fn blur_kernel(s: f64) -> Vec<f64> {
    if s < 0.35 {
        return Vec::new();
    }
    let radius = (3.0 * s).ceil() as usize;
    let kernel: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let d = i as f64 - radius as f64;
            (-d * d / (2.0 * s * s)).exp()
        })
        .collect();
    // Unit variance after both passes: each pass scales it by Σ w².
    let norm = kernel.iter().map(|w| w * w).sum::<f64>().sqrt();
    kernel.iter().map(|w| w / norm).collect()
}

/// Correlation factor per axis of the blur of `s` nodes: `(Σ w)²` for
/// taps of unit `Σ w²` (1 for white noise).
fn sampled_blur_factor(s: f64) -> f64 {
    let k = blur_kernel(s);
    if k.is_empty() { 1.0 } else { k.iter().sum::<f64>().powi(2) }
}

/// Correlated Gaussian noise of standard deviation 1 on a `width` x
/// `height` grid: white noise blurred by a Gaussian of `blur_sigma_nodes`
/// and rescaled, so its correlation factor is that of the measured noise.
pub fn correlated_noise(width: usize, height: usize, blur_sigma_nodes: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let white = |n: usize, rng: &mut ChaCha8Rng| -> Vec<f64> { (0..n).map(|_| StandardNormal.sample(rng)).collect() };
    let kernel = blur_kernel(blur_sigma_nodes);
    if kernel.is_empty() {
        return white(width * height, rng);
    }
    let radius = kernel.len() / 2;
    let (pw, ph) = (width + 2 * radius, height + 2 * radius);
    let source = white(pw * ph, rng);
    let mut rows = vec![0.0; width * ph];
    for r in 0..ph {
        for c in 0..width {
            rows[r * width + c] = kernel.iter().enumerate().map(|(k, w)| w * source[r * pw + c + k]).sum();
        }
    }
    let mut out = vec![0.0; width * height];
    for r in 0..height {
        for c in 0..width {
            out[r * width + c] = kernel.iter().enumerate().map(|(k, w)| w * rows[(r + k) * width + c]).sum();
        }
    }
    out
}

/// A Monte Carlo simulation (JCGM 101) of results computed on a map: each
/// trial adds correlated noise ([`correlated_noise`], `noise`) to the nodes
/// of the window `[c0, c1] x [r0, r1]` of `map` and evaluates `measure` on
/// the perturbed map. Trials run in parallel, trial `i` from seed
/// `seed + i`, so the result does not depend on the thread count. Returns
/// the results of the trials `measure` could evaluate, each a vector of
/// the same length.
pub fn monte_carlo<F>(
    map: &HeightMap,
    window: [usize; 4],
    noise: NodeNoise,
    trials: usize,
    seed: u64,
    measure: F,
) -> Vec<Vec<f64>>
where
    F: Fn(&HeightMap) -> Option<Vec<f64>> + Sync,
{
    let [c0, c1, r0, r1] = window;
    let sigma_um = vec![noise.sigma_um; (c1 + 1 - c0) * (r1 + 1 - r0)];
    monte_carlo_per_node(map, window, &sigma_um, noise.blur_sigma_nodes(), trials, seed, measure)
}

/// [`monte_carlo`] with each node's own standard deviation (`sigma_um`, row
/// major over the window) and one correlation (`blur_sigma_nodes`): regions
/// of one result may differ in noise (a brushed plate beside lapped lands,
/// 0.15 against 0.09 um on the simulator's watch plate), and one pooled σ
/// would understate the noisier region's part.
pub fn monte_carlo_per_node<F>(
    map: &HeightMap,
    window: [usize; 4],
    sigma_um: &[f64],
    blur_sigma_nodes: f64,
    trials: usize,
    seed: u64,
    measure: F,
) -> Vec<Vec<f64>>
where
    F: Fn(&HeightMap) -> Option<Vec<f64>> + Sync,
{
    let [c0, c1, r0, r1] = window;
    let (w, h) = (c1 + 1 - c0, r1 + 1 - r0);
    debug_assert_eq!(sigma_um.len(), w * h);
    // Trials perturb a copy of the window only (a region of a full-size map
    // is a small part of its 12 MB); regions are in mm, so they find the
    // same nodes on it.
    let mut z = Vec::with_capacity(w * h);
    for r in r0..=r1 {
        z.extend_from_slice(&map.z[r * map.width + c0..=r * map.width + c1]);
    }
    let window_map = HeightMap {
        width: w,
        height: h,
        origin_x_mm: map.x_mm(c0),
        origin_y_mm: map.y_mm(r0),
        pitch_mm: map.pitch_mm,
        z,
        unit: map.unit,
    };
    let to_map_unit = 1.0 / map.unit.um_per_unit();
    (0..trials as u64)
        .into_par_iter()
        .filter_map(|i| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_add(i));
            let e = correlated_noise(w, h, blur_sigma_nodes, &mut rng);
            let z = window_map
                .z
                .iter()
                .zip(&e)
                .zip(sigma_um)
                .map(|((&z, e), s)| (f64::from(z) + s * to_map_unit * e) as f32)
                .collect();
            measure(&HeightMap { z, ..window_map.clone() })
        })
        .collect()
}

/// Mean and sample standard deviation.
pub fn mean_and_std(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count() as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

/// A seed for a row from its name, so rows of one inspection draw
/// different noise and a rerun draws the same.
pub fn seed_of(name: &str) -> u64 {
    // FNV-1a: stable across platforms and releases (std's hasher is not).
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_3x3_grid_with_sigma_1_gives_the_hand_propagation() {
        // Centred x, y in {-1, 0, 1}: Sxx = Syy = 6, Sxy = 0; the height at
        // the centroid has u = 1 / sqrt(9) = 1/3, each slope 1 / sqrt(6).
        let points: Vec<[f64; 3]> = (0..9).map(|i| [f64::from(i % 3) + 10.0, f64::from(i / 3) - 4.0, 0.0]).collect();
        let c = plane_covariance(&points, 1.0, 1.0, None).expect("a plane");
        assert!((c.var_height_at_centroid.sqrt() - 1.0 / 3.0).abs() < 1e-12);
        assert!((c.slope_cov[0][0].sqrt() - 1.0 / 6f64.sqrt()).abs() < 1e-12);
        assert!((c.slope_cov[1][1].sqrt() - 1.0 / 6f64.sqrt()).abs() < 1e-12);
        assert!(c.slope_cov[0][1].abs() < 1e-12);
        // At a corner (1, 1) from the centroid: 1/9 + 1/6 + 1/6.
        assert!((c.var_height_at(12.0, -2.0) - (1.0 / 9.0 + 2.0 / 6.0)).abs() < 1e-12);
        // The correlation factor scales the variance.
        let f = plane_covariance(&points, 1.0, 4.0, None).expect("a plane");
        assert!((f.var_height_at_centroid.sqrt() - 2.0 / 3.0).abs() < 1e-12);
        let line: Vec<[f64; 3]> = (0..5).map(|i| [f64::from(i), 0.0, 0.0]).collect();
        assert!(plane_covariance(&line, 1.0, 1.0, None).is_none());
    }

    #[test]
    fn nodes_noisier_where_the_slope_weighs_them_widen_the_far_height_as_much_as_they_do() {
        use crate::analysis::plane_fit::fit_plane;
        use crate::analysis::region::{Region, region_samples};
        // A 60 x 40 plane whose 10 columns at either end are 3 times
        // noisier than the middle (independent nodes): the plane's height
        // 3 mm beyond its end rests on its slope, which weighs those ends most.
        let (w, h, pitch) = (60usize, 40usize, 0.05);
        let sigma_of = |c: usize| if !(10..50).contains(&c) { 3.0e-3 } else { 1.0e-3 };
        let region = [NamedRegion::new("plate", Region::Rectangle { x_mm: [0.0, 3.0], y_mm: [0.0, 2.0] })];
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut realisation = || {
            let z = (0..w * h)
                .map(|i| {
                    let e: f64 = StandardNormal.sample(&mut rng);
                    (e * sigma_of(i % w)) as f32
                })
                .collect();
            HeightMap::new(w, h, 0.0, 0.0, pitch, z).expect("a map")
        };
        let far = [-1.5, 1.0];
        let heights_um: Vec<f64> = (0..400)
            .map(|_| fit_plane(&realisation(), &region).expect("a plane").plane.z_at(far[0], far[1]) * 1e3)
            .collect();
        let (_, seen_um) = mean_and_std(heights_um.iter().copied());

        let map = realisation();
        let plane = fit_plane(&map, &region).expect("a plane").plane;
        let points = region_samples(&map, &region).points_mm;
        let relative = relative_node_variance(&map, &region, &plane, 1.0).expect("noise");
        assert_eq!(relative.len(), points.len());
        // The mean variance, as the variogram states it (3.67 um²).
        let sigma_um = ((20.0 * 9.0 + 40.0) / 60.0f64).sqrt();
        let stated = |weights: Option<&[f64]>| {
            plane_covariance(&points, sigma_um, 1.0, weights).expect("a plane").var_height_at(far[0], far[1]).sqrt()
        };
        let (own, uniform) = (stated(Some(&relative)), stated(None));
        assert!((own / seen_um - 1.0).abs() < 0.12, "stated {own:.4} um, seen {seen_um:.4} um");
        assert!(uniform / seen_um < 0.8, "uniform noise would state {uniform:.4} um for {seen_um:.4} um");
        // Uniform noise reads as uniform: the propagation is unchanged.
        let flat = vec![1.0; points.len()];
        assert!((stated(Some(&flat)) - uniform).abs() < 1e-12);
    }

    #[test]
    fn uniform_noise_on_a_bowed_plane_gets_uniform_shares() {
        use crate::analysis::plane_fit::fit_plane;
        use crate::analysis::region::Region;
        // White noise of 0.2 um on a 3 um bow: without the shrinkage the
        // window means scatter by about 15 %, and the bow's slope would
        // count as noise at the ends without second differences.
        let (w, h, pitch) = (120usize, 80usize, 0.01);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let z = (0..w * h)
            .map(|i| {
                let x = (i % w) as f64 * pitch;
                let e: f64 = StandardNormal.sample(&mut rng);
                (0.003 * ((x - 0.6) / 0.6).powi(2) + 2e-4 * e) as f32
            })
            .collect();
        let map = HeightMap::new(w, h, 0.0, 0.0, pitch, z).expect("a map");
        let region = [NamedRegion::new("r", Region::Rectangle { x_mm: [0.0, 1.19], y_mm: [0.0, 0.79] })];
        let plane = fit_plane(&map, &region).expect("a plane").plane;
        let shares = relative_node_variance(&map, &region, &plane, 1.0).expect("noise");
        let worst = shares.iter().map(|s| (s - 1.0).abs()).fold(0.0, f64::max);
        assert!(worst < 0.06, "a share {worst:.3} away from 1");
    }

    #[test]
    fn a_strips_form_does_not_pass_for_noise() {
        // A strip 9 nodes across and 130 long whose form a quadratic does
        // not follow (a cubic of 3 um and a wave of 0.5 um along it), with
        // white noise of 0.15 um: the plain variogram reads the form's
        // slope; the second differences read the noise.
        let (w, h) = (130usize, 9usize);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let residual: Vec<f64> = (0..w * h)
            .map(|i| {
                let t = (i % w) as f64 / w as f64 * 2.0 - 1.0;
                let e: f64 = StandardNormal.sample(&mut rng);
                3.0 * t.powi(3) + 0.5 * (t * std::f64::consts::PI).cos() + 0.15 * e
            })
            .collect();
        let v = variogram_of_residual(&residual, w, h).expect("a variogram");
        assert!((v.sigma_um / 0.15 - 1.0).abs() < 0.1, "σ {:.3}", v.sigma_um);
        // The plain variogram reads σ 0.22 um here. The form's curvature
        // still lifts the short lags' correlation a little (F 4.6 for white
        // noise's 1): an overstatement, not a form taken for noise.
        assert!(v.node_noise().correlation_factor < 6.0, "{:?}", v.node_noise());
    }

    #[test]
    fn the_variogram_finds_the_noise_and_its_correlation_and_ignores_a_bow() {
        let (w, h) = (300, 200);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // White noise: F = 1, σ as drawn.
        let white = correlated_noise(w, h, 0.0, &mut rng);
        let n = node_noise_of_residual(&white, w, h).expect("noise");
        assert!((n.sigma_um - 1.0).abs() < 0.03, "{n:?}");
        assert!(n.correlation_factor < 1.15, "{n:?}");
        // Blurred noise: the factor the blur gives (4 π s² for s = 1.2,
        // 18.1), σ still 1; a bow of 3 σ over the grid changes neither much.
        let blurred = correlated_noise(w, h, 1.2, &mut rng);
        let bowed: Vec<f64> = blurred
            .iter()
            .enumerate()
            .map(|(i, e)| {
                let (x, y) = ((i % w) as f64 / w as f64 - 0.5, (i / w) as f64 / h as f64 - 0.5);
                e + 3.0 * 4.0 * (x * x + y * y)
            })
            .collect();
        for field in [&blurred, &bowed] {
            let n = node_noise_of_residual(field, w, h).expect("noise");
            assert!((n.sigma_um - 1.0).abs() < 0.1, "{n:?}");
            let expected = 4.0 * std::f64::consts::PI * 1.2 * 1.2;
            assert!((n.correlation_factor / expected - 1.0).abs() < 0.25, "{n:?} vs {expected}");
        }
        // The mean of a blurred field spreads as σ sqrt(F / n): checked
        // over realisations, so the factor is the one that matters.
        let means: Vec<f64> =
            (0..200).map(|_| correlated_noise(60, 60, 1.2, &mut rng).iter().sum::<f64>() / 3600.0).collect();
        let (_, spread) = mean_and_std(means.iter().copied());
        let stated = (4.0 * std::f64::consts::PI * 1.44 / 3600.0).sqrt();
        assert!((spread / stated - 1.0).abs() < 0.15, "spread {spread} stated {stated}");
    }

    #[test]
    fn the_monte_carlo_noise_has_the_correlation_factor_it_is_asked_for() {
        // The spread of a mean over n nodes is σ sqrt(F / n): the factor the
        // trials draw must be the measured one, including the small factors
        // (3-4) of real maps, where a sampled Gaussian falls short.
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        for factor in [2.0, 3.4, 8.0] {
            let blur = NodeNoise { sigma_um: 1.0, correlation_factor: factor }.blur_sigma_nodes();
            let means: Vec<f64> =
                (0..400).map(|_| correlated_noise(60, 60, blur, &mut rng).iter().sum::<f64>() / 3600.0).collect();
            let (_, spread) = mean_and_std(means.iter().copied());
            let stated = (factor / 3600.0).sqrt();
            assert!((spread / stated - 1.0).abs() < 0.1, "F {factor}: spread {spread} stated {stated}");
        }
        assert!(NodeNoise::default().blur_sigma_nodes() < 0.35, "F = 1 stays white");
    }

    #[test]
    fn pooled_regions_measure_the_correlation_that_one_small_region_cannot() {
        // Twelve regions of 40 x 30 nodes with F = 3.4: each alone scatters
        // and, with its ring cut-off, reads low; together they give F.
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let blur = NodeNoise { sigma_um: 1.0, correlation_factor: 3.4 }.blur_sigma_nodes();
        let variograms: Vec<Variogram> = (0..12)
            .map(|_| variogram_of_residual(&correlated_noise(40, 30, blur, &mut rng), 40, 30).expect("variogram"))
            .collect();
        let own: Vec<f64> = variograms.iter().map(|v| v.node_noise().correlation_factor).collect();
        let (own_mean, own_spread) = mean_and_std(own.iter().copied());
        let pooled = pooled_correlation_factor(&variograms).expect("pooled");
        assert!((pooled / 3.4 - 1.0).abs() < 0.15, "pooled {pooled}");
        assert!(own_spread > 0.2 && (pooled - 3.4).abs() < (own_mean - 3.4).abs() + own_spread, "{own:?}");
        assert!(variograms.iter().all(|v| (v.sigma_um - 1.0).abs() < 0.15));
        assert_eq!(pooled_correlation_factor(&[]), None);
    }

    #[test]
    fn tilt_uncertainty_follows_the_slope_noise_along_the_slope() {
        let cov = [[4e-8, 0.0], [0.0, 1e-8]];
        // Along x: u(g) = 2e-4 rad at a resolved tilt.
        let u = tilt_uncertainty_deg([0.01, 0.0], cov);
        assert!((u - (2e-4f64 / (1.0 + 1e-4)).to_degrees()).abs() < 1e-9, "{u}");
        let u = tilt_uncertainty_deg([0.0, 0.01], cov);
        assert!((u - (1e-4f64 / (1.0 + 1e-4)).to_degrees()).abs() < 1e-9, "{u}");
        // Unresolved: k u is the 95 % quantile of |g| for a level plane:
        // the Rayleigh's for round noise, the half-normal's for noise along
        // one direction.
        let round = tilt_uncertainty_deg([0.0, 0.0], [[4e-8, 0.0], [0.0, 4e-8]]);
        assert!((2.0 * round - 2.44775 * 2e-4f64.to_degrees()).abs() < 1e-5, "{round}");
        let along_x = tilt_uncertainty_deg([0.0, 0.0], [[4e-8, 0.0], [0.0, 0.0]]);
        assert!((2.0 * along_x - 1.96 * 2e-4f64.to_degrees()).abs() < 1e-5, "{along_x}");
        assert!((zero_tilt_quantile_95(4.0, 4.0) - 2.0 * 2.44775).abs() < 1e-3);
        assert!((zero_tilt_quantile_95(1.0, 0.0) - 1.95996).abs() < 1e-3);
    }

    #[test]
    fn a_level_and_a_tilted_plane_are_held_within_k_u_about_95_percent_of_the_time() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // Round-ish noise, and noise along x only (a long narrow strip).
        for (cov, true_g) in [
            ([[4e-8, 1e-8], [1e-8, 2e-8]], [0.0, 0.0]),
            ([[4e-8, 1e-8], [1e-8, 2e-8]], [3e-4, -2e-4]),
            ([[4e-8, 1e-8], [1e-8, 2e-8]], [0.02, 0.01]),
            ([[4e-8, 0.0], [0.0, 1e-11]], [0.0, 0.0]),
            ([[4e-8, 0.0], [0.0, 1e-11]], [1e-3, 0.0]),
        ] {
            let chol = nalgebra::Matrix2::new(cov[0][0], cov[0][1], cov[1][0], cov[1][1]).cholesky().expect("spd").l();
            let true_tilt = f64::hypot(true_g[0], true_g[1]).atan().to_degrees();
            let trials = 20_000;
            let covered = (0..trials)
                .filter(|_| {
                    let n = nalgebra::Vector2::new(StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
                    let e = chol * n;
                    let g = [true_g[0] + e[0], true_g[1] + e[1]];
                    let tilt = f64::hypot(g[0], g[1]).atan().to_degrees();
                    (tilt - true_tilt).abs() <= COVERAGE_FACTOR * tilt_uncertainty_deg(g, cov)
                })
                .count();
            let coverage = covered as f64 / trials as f64;
            assert!((0.93..=0.975).contains(&coverage), "true g {true_g:?}: coverage {coverage}");
        }
    }

    #[test]
    fn monte_carlo_is_reproducible_and_independent_of_threads() {
        let map = HeightMap::new(40, 30, 0.0, 0.0, 0.01, vec![0.0; 1200]).expect("map");
        let noise = NodeNoise { sigma_um: 0.5, correlation_factor: 6.0 };
        let mean = |m: &HeightMap| Some(vec![m.z.iter().map(|&z| f64::from(z)).sum::<f64>() * 1e3 / 1200.0]);
        let a = monte_carlo(&map, [0, 39, 0, 29], noise, 20, 3, mean);
        let b = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| monte_carlo(&map, [0, 39, 0, 29], noise, 20, 3, mean));
        assert_eq!(a, b);
        assert_eq!(a.len(), 20);
        assert_ne!(a, monte_carlo(&map, [0, 39, 0, 29], noise, 20, 4, mean));
    }

    #[test]
    fn budgets_combine_as_a_root_sum_of_squares() {
        let u = Uncertainty::from_budget(
            UncertaintyMethod::Propagation,
            vec![Contribution::new("a", 0.3), Contribution::new("b", 0.4)],
        );
        assert!((u.u - 0.5).abs() < 1e-12 && (u.expanded - 1.0).abs() < 1e-12 && u.k == 2.0);
        let json = serde_json::to_value(&u).expect("json");
        assert_eq!(json["U"], 1.0);
        assert_eq!(json["method"], "propagation");
        assert_eq!(json["budget"][1]["source"], "b");
        assert_eq!(serde_json::from_value::<Uncertainty>(json).expect("reads back"), u);
    }
}
