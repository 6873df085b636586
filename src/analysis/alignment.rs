//! Where a part lies on the stage this time: the registration of its height
//! map to a recipe's reference map by a rotation about Z and a shift in the
//! stage plane, so the recipe's regions and sections follow the part.
//!
//! Two stages, coarse to fine, both on the shape itself (no fiducials):
//! 1. Rotation search by cross-correlation. Both maps are block-averaged to
//!    a coarse grid (about 128 nodes across); for each trial rotation the
//!    reference is turned about its centre and cross-correlated with the
//!    part through the FFT, on a grid padded so no shift wraps around. The
//!    best normalised peak gives the rotation to a quarter degree and the
//!    shift to a coarse node.
//! 2. Gauss-Newton least squares on the heights (an image registration by
//!    the Lucas-Kanade scheme): the residual `part(R x + t) - reference(x) -
//!    plane(x)` is minimised over the rotation, the shift and a small plane
//!    (a part that sits a little higher or tilted on its fixture), with the
//!    part's gradient by central differences. It runs on a pyramid of
//!    block-averaged maps from the coarse grid down to the map's pitch, so a
//!    step's edge is broad where the start is a coarse node off and sharp
//!    where it is a fraction of a node off. Residuals beyond 2.5 robust
//!    sigmas are down-weighted (Huber), so a burr, an occlusion or a hole
//!    that differs between the two parts does not pull the fit.
//!
//! The match score is the correlation coefficient of the reference's heights
//! and the aligned part's over the nodes both hold: near 1 for the same
//! part type anywhere in the field, low for another part, whose shape no
//! placement explains.
//!
//! The reference's levels (averaged, smoothed, sampled) depend on the
//! reference alone, so [`ReferenceLevels`] keeps them between parts: a line
//! aligns every part to the same reference.

use std::sync::{Arc, Mutex};

use nalgebra::{Matrix6, Vector6};
use rayon::prelude::*;
use rustfft::num_complex::Complex;

use super::height_map::HeightMap;
use super::inspection::InspectionSpec;
use super::profile::ProfileLine;
use super::region::{NamedRegion, Region};
use super::texture::spatial::fft2;

/// A rigid motion in the stage plane: a reference point `x` lies at
/// `R(rotation) x + shift` on the part's map (stage millimetres).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Placement {
    /// Counter-clockwise, from +X towards +Y.
    pub rotation_deg: f64,
    pub shift_mm: [f64; 2],
}

impl Placement {
    pub const IDENTITY: Placement = Placement { rotation_deg: 0.0, shift_mm: [0.0, 0.0] };

    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        self.motion().apply(p)
    }

    /// The placement with its sine and cosine computed once, for the loops
    /// that move every node of a map.
    fn motion(&self) -> Motion {
        let (sin, cos) = self.rotation_deg.to_radians().sin_cos();
        Motion { sin, cos, shift: self.shift_mm }
    }

    /// The region where it lies on the part: a rectangle turns into the
    /// polygon of its corners (a turned rectangle is not axis-aligned).
    pub fn move_region(&self, region: &Region) -> Region {
        match region {
            Region::Rectangle { x_mm, y_mm } => Region::Polygon {
                vertices_mm: [[x_mm[0], y_mm[0]], [x_mm[1], y_mm[0]], [x_mm[1], y_mm[1]], [x_mm[0], y_mm[1]]]
                    .map(|p| self.apply(p))
                    .to_vec(),
            },
            Region::Polygon { vertices_mm } => {
                Region::Polygon { vertices_mm: vertices_mm.iter().map(|&p| self.apply(p)).collect() }
            }
            Region::Circle { centre_mm, radius_mm } => {
                Region::Circle { centre_mm: self.apply(*centre_mm), radius_mm: *radius_mm }
            }
        }
    }

    /// The section where it lies on the part. A horizontal or vertical
    /// section spans the reference map, so it becomes the segment across the
    /// reference's extent, moved: the same stretch of the part's surface.
    pub fn move_profile_line(&self, line: &ProfileLine, reference_extent: ([f64; 2], [f64; 2])) -> ProfileLine {
        let ([x0, y0], [x1, y1]) = reference_extent;
        let (start, end) = match *line {
            ProfileLine::Segment { start_mm, end_mm } => (start_mm, end_mm),
            ProfileLine::Horizontal { through_mm } => ([x0, through_mm[1]], [x1, through_mm[1]]),
            ProfileLine::Vertical { through_mm } => ([through_mm[0], y0], [through_mm[0], y1]),
        };
        ProfileLine::Segment { start_mm: self.apply(start), end_mm: self.apply(end) }
    }

    /// The inspection with every region and section moved onto the part.
    pub fn move_spec(&self, spec: &InspectionSpec, reference_extent: ([f64; 2], [f64; 2])) -> InspectionSpec {
        let mut moved = spec.clone();
        for r in &mut moved.regions {
            r.region = self.move_region(&r.region);
        }
        for p in &mut moved.profiles {
            p.line = self.move_profile_line(&p.line, reference_extent);
        }
        moved
    }
}

/// A [`Placement`] ready to apply.
#[derive(Clone, Copy)]
struct Motion {
    sin: f64,
    cos: f64,
    shift: [f64; 2],
}

impl Motion {
    #[inline]
    fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = (self.sin, self.cos);
        [c * p[0] - s * p[1] + self.shift[0], s * p[0] + c * p[1] + self.shift[1]]
    }

    /// The reference point a part point shows: `R^T (q - t)`.
    #[inline]
    fn invert(&self, q: [f64; 2]) -> [f64; 2] {
        let (s, c) = (self.sin, self.cos);
        let (dx, dy) = (q[0] - self.shift[0], q[1] - self.shift[1]);
        [c * dx + s * dy, -s * dx + c * dy]
    }
}

/// The first region the placement takes (even partly) out of the part map's
/// field: measuring it would measure something else.
pub fn region_leaving_field<'a>(regions: &'a [NamedRegion], map: &HeightMap) -> Option<&'a NamedRegion> {
    let ([x0, y0], [x1, y1]) = map.extent_mm();
    let margin = 0.5 * map.pitch_mm;
    regions.iter().find(|r| {
        let (lo, hi) = r.region.bounding_box();
        lo[0] < x0 - margin || lo[1] < y0 - margin || hi[0] > x1 + margin || hi[1] > y1 + margin
    })
}

/// How far the search looks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignmentSearch {
    /// Rotations from -max to +max are tried.
    pub max_rotation_deg: f64,
}

impl Default for AlignmentSearch {
    fn default() -> Self {
        Self { max_rotation_deg: 10.0 }
    }
}

/// The placement found and how well it explains the part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    pub placement: Placement,
    /// Correlation coefficient of reference and aligned part heights over
    /// the nodes both hold (1 = the same shape).
    pub score: f64,
    /// Share of the reference's valid nodes that land on the part's data.
    pub overlap: f64,
    /// RMS of the height residual after alignment (um), robust nodes only.
    pub residual_rms_um: f64,
    /// The plane `a + b x + c y` (map units, reference coordinates) by
    /// which the part sits higher or tilted against the reference.
    pub plane: [f64; 3],
}

/// The part's heights less the reference's where the placement puts it
/// (and less the plane between them), on the part's grid: near zero where
/// the part is the reference's shape, the defects and the misplacements
/// stand out. NaN where either map has no height.
pub fn difference_to_reference(reference: &HeightMap, part: &HeightMap, alignment: &Alignment) -> HeightMap {
    let motion = alignment.placement.motion();
    let [a, b, c] = alignment.plane;
    let z = part
        .z
        .par_iter()
        .enumerate()
        .map(|(i, &m)| {
            if m.is_nan() {
                return f32::NAN;
            }
            let at = motion.invert([part.x_mm(i % part.width), part.y_mm(i / part.width)]);
            let r = reference.z_at(at[0], at[1]);
            (f64::from(m) - r - (a + b * at[0] + c * at[1])) as f32
        })
        .collect();
    HeightMap { z, ..part.clone() }
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AlignmentError {
    #[error("the {which} height map has too few valid nodes to align ({valid})")]
    TooFewNodes { which: &'static str, valid: usize },
    #[error("the part's height map and the reference's are in different length units ({part} and {reference})")]
    UnitMismatch { part: &'static str, reference: &'static str },
}

/// Nodes across the coarse grid of the rotation search.
const COARSE_NODES: usize = 128;
/// Rotation steps of the search: every degree, then a quarter degree
/// around the best.
const COARSE_STEP_DEG: f64 = 1.0;
const FINE_STEP_DEG: f64 = 0.25;
/// Nodes across the finest level of the least squares.
const FINEST_NODES: usize = 1024;
/// Gauss-Newton iterations on the finest pyramid level. The robust steps
/// shrink slowly (by about a fifth per iteration on the line bench's step
/// gauge), so the cap, not the tolerance, ends most levels.
const ITERATIONS_FINEST: usize = 12;
/// The same on the coarser levels: they only hand the next level a start
/// well inside its capture range of about a node (after four iterations the
/// step is below 1 % of the node), and took half of the least squares' time
/// at twelve.
const ITERATIONS_COARSER: usize = 4;
/// Reference nodes used per least-squares level (a stride keeps them spread).
const SAMPLES_PER_LEVEL: usize = 40_000;
/// Huber threshold in robust sigmas.
const HUBER_K: f64 = 2.5;

/// Registers `part` to `reference`: the placement that carries the
/// reference's points onto the part's.
pub fn align(reference: &HeightMap, part: &HeightMap, search: &AlignmentSearch) -> Result<Alignment, AlignmentError> {
    align_with(reference, &ReferenceLevels::default(), part, search)
}

/// One level of the reference's pyramid: the map averaged over blocks and
/// smoothed, and the samples the least squares compares at.
struct ReferenceLevel {
    /// The block factor on the reference's own grid.
    block: usize,
    map: HeightMap,
    samples: Vec<([f64; 2], f64)>,
}

/// The levels made from one reference map, kept for the next part (see the
/// module docs). Made for one reference: give it to [`align_with`] with
/// that map only. Clones share the levels.
#[derive(Clone, Default)]
pub struct ReferenceLevels {
    levels: Arc<Mutex<Vec<Arc<ReferenceLevel>>>>,
}

impl std::fmt::Debug for ReferenceLevels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kept: Vec<usize> =
            self.levels.lock().map(|levels| levels.iter().map(|l| l.block).collect()).unwrap_or_default();
        f.debug_struct("ReferenceLevels").field("block_factors", &kept).finish()
    }
}

impl ReferenceLevels {
    fn get(&self, reference: &HeightMap, block: usize) -> Arc<ReferenceLevel> {
        let kept = |levels: &[Arc<ReferenceLevel>]| levels.iter().find(|l| l.block == block).cloned();
        if let Some(level) = self.levels.lock().ok().and_then(|levels| kept(&levels)) {
            return level;
        }
        // Made outside the lock; two parts asking at once make the same level.
        let map = smoothed(&block_mean(reference, block));
        let level = Arc::new(ReferenceLevel { block, samples: spread_samples(&map), map });
        if let Ok(mut levels) = self.levels.lock() {
            if let Some(first) = kept(&levels) {
                return first;
            }
            levels.push(level.clone());
        }
        level
    }
}

/// [`align`] with the reference's levels taken from (and added to) `levels`.
pub fn align_with(
    reference: &HeightMap,
    levels: &ReferenceLevels,
    part: &HeightMap,
    search: &AlignmentSearch,
) -> Result<Alignment, AlignmentError> {
    if reference.unit != part.unit {
        return Err(AlignmentError::UnitMismatch { part: part.unit.as_str(), reference: reference.unit.as_str() });
    }
    for (which, map) in [("reference", reference), ("part", part)] {
        let valid = map.valid_count();
        if valid < 64 {
            return Err(AlignmentError::TooFewNodes { which, valid });
        }
    }
    let pitch = reference.pitch_mm.max(part.pitch_mm);
    let span = |m: &HeightMap| (m.width as f64 * m.pitch_mm).max(m.height as f64 * m.pitch_mm);
    let coarse_factor = ((span(reference).max(span(part)) / COARSE_NODES as f64 / pitch).floor() as usize).max(1);
    // Both maps on the coarser pitch: a finer part map is averaged down first.
    let part_on_pitch =
        |factor: usize| smoothed(&block_mean(part, (factor as f64 * pitch / part.pitch_mm).round() as usize));
    let reference_on_pitch =
        |factor: usize| levels.get(reference, (factor as f64 * pitch / reference.pitch_mm).round() as usize);

    let coarse_reference = reference_on_pitch(coarse_factor);
    let coarse_part = part_on_pitch(coarse_factor);
    let mut state = coarse_search(&coarse_reference.map, &coarse_part, search.max_rotation_deg).to_state();

    // The finest level keeps about FINEST_NODES across: finer adds time, not
    // accuracy (a tenth of its node is a fifth of a 2048-px camera's pixel).
    let finest_factor = ((span(reference).max(span(part)) / FINEST_NODES as f64 / pitch).floor() as usize).max(1);
    let mut factor = coarse_factor;
    let mut maps = Some((coarse_reference, coarse_part));
    loop {
        let (r, p) = maps.take().unwrap_or_else(|| (reference_on_pitch(factor), part_on_pitch(factor)));
        let samples = &r.samples;
        let iterations = if factor <= finest_factor { ITERATIONS_FINEST } else { ITERATIONS_COARSER };
        for _ in 0..iterations {
            let Some(step) = gauss_newton_step(samples, &p, &state) else { break };
            let converged = step[0].abs() < 1e-7 && step[1].abs().max(step[2].abs()) < 1e-4 * p.pitch_mm;
            state += step;
            if converged {
                break;
            }
        }
        if factor <= finest_factor {
            break;
        }
        factor = factor.div_ceil(2).max(finest_factor);
    }
    Ok(score(reference, part, &state))
}

/// Rotation (rad), shift (mm), and the plane `a + b x + c y` (map units)
/// between reference and part.
type State = Vector6<f64>;

impl Placement {
    fn to_state(self) -> State {
        State::new(self.rotation_deg.to_radians(), self.shift_mm[0], self.shift_mm[1], 0.0, 0.0, 0.0)
    }

    fn of_state(s: &State) -> Self {
        Placement { rotation_deg: s[0].to_degrees(), shift_mm: [s[1], s[2]] }
    }
}

/// A map averaged over `factor` x `factor` blocks; a block with fewer than
/// half its nodes valid is a hole (an edge half in the void is not a height).
fn block_mean(map: &HeightMap, factor: usize) -> HeightMap {
    if factor <= 1 {
        return map.clone();
    }
    let (w, h) = ((map.width / factor).max(1), (map.height / factor).max(1));
    let mut z = vec![f32::NAN; w * h];
    z.par_iter_mut().enumerate().for_each(|(i, out)| {
        let (bc, br) = (i % w, i / w);
        let (mut sum, mut n) = (0.0f64, 0usize);
        for r in br * factor..((br + 1) * factor).min(map.height) {
            for c in bc * factor..((bc + 1) * factor).min(map.width) {
                let v = map.z[r * map.width + c];
                if !v.is_nan() {
                    sum += f64::from(v);
                    n += 1;
                }
            }
        }
        if 2 * n >= factor * factor {
            *out = (sum / n as f64) as f32;
        }
    });
    let half = (factor as f64 - 1.0) / 2.0 * map.pitch_mm;
    HeightMap {
        width: w,
        height: h,
        origin_x_mm: map.origin_x_mm + half,
        origin_y_mm: map.origin_y_mm + half,
        pitch_mm: map.pitch_mm * factor as f64,
        z,
        unit: map.unit,
    }
}

/// The map blurred by about one node (the binomial kernel [1 2 1] / 4 along
/// rows and columns, twice: nearly a Gaussian of sigma 1), weighting valid
/// nodes only. A sharp step sampled on a turned grid aliases into a
/// staircase the bilinear model of the least squares cannot follow; blurred
/// on both maps it becomes a ramp it can, and the blur turns with the part.
fn smoothed(map: &HeightMap) -> HeightMap {
    let w = map.width;
    // Heights and weights side by side: (z w, w), zero on holes.
    let mut grid: Vec<[f32; 2]> = map.z.iter().map(|&v| if v.is_nan() { [0.0, 0.0] } else { [v, 1.0] }).collect();
    let blend = |a: [f32; 2], b: [f32; 2], c: [f32; 2]| {
        [0.25 * a[0] + 0.5 * b[0] + 0.25 * c[0], 0.25 * a[1] + 0.5 * b[1] + 0.25 * c[1]]
    };
    const NONE: [f32; 2] = [0.0, 0.0];
    for _ in 0..2 {
        let mut rows = vec![NONE; grid.len()];
        rows.par_chunks_mut(w.max(1)).zip(grid.par_chunks(w.max(1))).for_each(|(out, line)| {
            for k in 0..line.len() {
                let left = if k > 0 { line[k - 1] } else { NONE };
                let right = line.get(k + 1).copied().unwrap_or(NONE);
                out[k] = blend(left, line[k], right);
            }
        });
        let rows_ref = &rows;
        grid.par_chunks_mut(w.max(1)).enumerate().for_each(|(r, out)| {
            let line = |rr: Option<usize>| rr.and_then(|rr| rows_ref.get(rr * w..(rr + 1) * w));
            let (above, here, below) = (line(r.checked_sub(1)), line(Some(r)), line(Some(r + 1)));
            for (k, o) in out.iter_mut().enumerate() {
                let at = |l: Option<&[[f32; 2]]>| l.map_or(NONE, |l| l[k]);
                *o = blend(at(above), at(here), at(below));
            }
        });
    }
    let z = map
        .z
        .par_iter()
        .zip(grid.par_iter())
        .map(|(&v, g)| if v.is_nan() || g[1] <= 0.0 { f32::NAN } else { g[0] / g[1] })
        .collect();
    HeightMap { z, ..map.clone() }
}

fn centre(map: &HeightMap) -> [f64; 2] {
    let ([x0, y0], [x1, y1]) = map.extent_mm();
    [(x0 + x1) / 2.0, (y0 + y1) / 2.0]
}

/// Heights less their mean, holes as zero: what the correlation compares.
fn zero_mean(values: impl Iterator<Item = f64> + Clone) -> Vec<f32> {
    let (sum, n) = values.clone().filter(|v| !v.is_nan()).fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    let mean = sum / n.max(1) as f64;
    values.map(|v| if v.is_nan() { 0.0 } else { (v - mean) as f32 }).collect()
}

/// Stage 1: the best rotation on a degree, then a quarter-degree grid, and
/// the shift of the correlation's peak at it.
fn coarse_search(reference: &HeightMap, part: &HeightMap, max_rotation_deg: f64) -> Placement {
    let (pw, ph) =
        ((reference.width + part.width).next_multiple_of(16), (reference.height + part.height).next_multiple_of(16));
    let part_values = zero_mean(part.z.iter().map(|&v| f64::from(v)));
    let part_energy: f64 = part_values.iter().map(|&v| f64::from(v) * f64::from(v)).sum();
    let mut part_spectrum = padded(&part_values, part.width, part.height, pw, ph);
    fft2(&mut part_spectrum, pw, ph, false, part.height);
    let c = centre(reference);
    let trial = |angle_deg: f64| -> (f64, Placement) {
        let turn = Placement { rotation_deg: angle_deg, shift_mm: [0.0, 0.0] }.motion();
        // The reference turned about its centre, on its own grid.
        let turned = zero_mean((0..reference.z.len()).map(|i| {
            let p = [reference.x_mm(i % reference.width) - c[0], reference.y_mm(i / reference.width) - c[1]];
            let q = turn.invert(p);
            reference.z_at(q[0] + c[0], q[1] + c[1])
        }));
        let energy: f64 = turned.iter().map(|&v| f64::from(v) * f64::from(v)).sum();
        let mut spectrum = padded(&turned, reference.width, reference.height, pw, ph);
        fft2(&mut spectrum, pw, ph, false, reference.height);
        // corr(s) = sum_i a(i) b(i + s) = IFFT(conj(A) B).
        for (a, b) in spectrum.iter_mut().zip(&part_spectrum) {
            *a = a.conj() * b;
        }
        fft2(&mut spectrum, pw, ph, true, ph);
        let (best, peak) = spectrum
            .iter()
            .enumerate()
            .fold((0, f32::NEG_INFINITY), |m, (i, v)| if v.re > m.1 { (i, v.re) } else { m });
        let scale = (pw * ph) as f64 * (energy * part_energy).sqrt().max(f64::MIN_POSITIVE);
        let unwrap = |k: usize, n: usize, size: usize| if k < n { k as f64 } else { k as f64 - size as f64 };
        let (sx, sy) = (unwrap(best % pw, part.width, pw), unwrap(best / pw, part.height, ph));
        // A reference node i turned about c lands on part node i + s.
        let t_turned = [
            part.origin_x_mm - reference.origin_x_mm + sx * part.pitch_mm,
            part.origin_y_mm - reference.origin_y_mm + sy * part.pitch_mm,
        ];
        let rc = turn.apply(c);
        let shift = [c[0] - rc[0] + t_turned[0], c[1] - rc[1] + t_turned[1]];
        (f64::from(peak) / scale, Placement { rotation_deg: angle_deg, shift_mm: shift })
    };
    let steps = (max_rotation_deg / COARSE_STEP_DEG).ceil() as i64;
    // Angles in parallel, the best chosen in angle order: the same on any
    // number of threads.
    let best_of = |angles: Vec<f64>| {
        let trials: Vec<(f64, Placement)> = angles.into_par_iter().map(trial).collect();
        trials.into_iter().fold((f64::NEG_INFINITY, Placement::IDENTITY), |m, t| if t.0 > m.0 { t } else { m })
    };
    let coarse = best_of((-steps..=steps).map(|k| k as f64 * COARSE_STEP_DEG).collect());
    let around = coarse.1.rotation_deg;
    let fine = best_of((-3..=3).map(|k| around + f64::from(k) * FINE_STEP_DEG).collect());
    fine.1
}

fn padded(values: &[f32], w: usize, h: usize, pw: usize, ph: usize) -> Vec<Complex<f32>> {
    let mut out = vec![Complex::default(); pw * ph];
    for r in 0..h {
        for c in 0..w {
            out[r * pw + c] = Complex::new(values[r * w + c], 0.0);
        }
    }
    out
}

/// A spread of the reference's valid nodes (a stride keeps them evenly
/// over the map): position and height.
fn spread_samples(reference: &HeightMap) -> Vec<([f64; 2], f64)> {
    let valid = reference.z.iter().filter(|v| !v.is_nan()).count();
    let stride = valid.div_ceil(SAMPLES_PER_LEVEL).max(1);
    reference
        .z
        .iter()
        .enumerate()
        .filter(|(_, v)| !v.is_nan())
        .step_by(stride)
        .map(|(i, &z)| ([reference.x_mm(i % reference.width), reference.y_mm(i / reference.width)], f64::from(z)))
        .collect()
}

/// Stage 2: one robust Gauss-Newton step on the samples, or `None` with
/// too few of them on the part's data.
fn gauss_newton_step(samples: &[([f64; 2], f64)], part: &HeightMap, state: &State) -> Option<State> {
    let motion = Placement::of_state(state).motion();
    let (s, c) = (motion.sin, motion.cos);
    let d = part.pitch_mm;
    // Residual `part(R x + t) - reference(x) - plane(x)` and its Jacobian.
    let rows: Vec<(f64, Vector6<f64>)> = samples
        .par_iter()
        .filter_map(|&(at, z)| {
            let q = motion.apply(at);
            let m = part.z_at(q[0], q[1]);
            let gx = (part.z_at(q[0] + d, q[1]) - part.z_at(q[0] - d, q[1])) / (2.0 * d);
            let gy = (part.z_at(q[0], q[1] + d) - part.z_at(q[0], q[1] - d)) / (2.0 * d);
            if !(m.is_finite() && gx.is_finite() && gy.is_finite()) {
                return None;
            }
            let residual = m - z - (state[3] + state[4] * at[0] + state[5] * at[1]);
            // d(R x)/d(theta) = (-s x - c y, c x - s y).
            let (dxt, dyt) = (-s * at[0] - c * at[1], c * at[0] - s * at[1]);
            Some((residual, Vector6::new(gx * dxt + gy * dyt, gx, gy, -1.0, -at[0], -at[1])))
        })
        .collect();
    if rows.len() < 16 {
        return None;
    }
    let sigma = robust_sigma(rows.iter().map(|r| r.0));
    let zero = || (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros());
    // Fixed chunks added in order: the same part gives the same placement
    // to the last bit whatever the threads do (a fold and reduce in rayon's
    // order did not).
    let partial: Vec<(Matrix6<f64>, Vector6<f64>)> = rows
        .par_chunks(GAUSS_NEWTON_CHUNK)
        .map(|chunk| {
            chunk.iter().fold(zero(), |(mut jtj, mut jtr), (residual, j)| {
                let weight = huber_weight(*residual, sigma);
                jtj += weight * j * j.transpose();
                jtr += weight * *residual * j;
                (jtj, jtr)
            })
        })
        .collect();
    let (jtj, jtr) = partial.into_iter().fold(zero(), |a, b| (a.0 + b.0, a.1 + b.1));
    // A tiny ridge keeps a featureless direction (a flat map's rotation) still.
    let ridge = 1e-9 * jtj.trace().max(f64::MIN_POSITIVE);
    (jtj + Matrix6::identity() * ridge).cholesky().map(|ch| -ch.solve(&jtr))
}

/// Samples per chunk of a Gauss-Newton step's normal equations.
const GAUSS_NEWTON_CHUNK: usize = 4096;

/// 1.4826 times the median absolute residual: the sigma of the good nodes.
fn robust_sigma(values: impl Iterator<Item = f64>) -> f64 {
    let mut abs: Vec<f64> = values.map(f64::abs).collect();
    if abs.is_empty() {
        return 0.0;
    }
    let mid = abs.len() / 2;
    let (_, median, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *median
}

fn huber_weight(residual: f64, sigma: f64) -> f64 {
    let k = HUBER_K * sigma;
    if k <= 0.0 || residual.abs() <= k { 1.0 } else { k / residual.abs() }
}

/// Residuals the score's robust sigma is taken from.
const SIGMA_SAMPLES: usize = 100_000;

/// Nodes per chunk of the score's sums: fixed chunks summed in order keep
/// the score the same from run to run whatever the threads do.
const SCORE_CHUNK: usize = 1 << 16;

/// Sums over fixed chunks of `values`, in parallel, added in chunk order.
fn chunked_sums<const K: usize>(values: &[(f64, f64)], term: impl Fn(f64, f64) -> [f64; K] + Sync) -> [f64; K] {
    let partial: Vec<[f64; K]> = values
        .par_chunks(SCORE_CHUNK)
        .map(|chunk| {
            let mut sum = [0.0; K];
            for &(a, b) in chunk {
                for (s, t) in sum.iter_mut().zip(term(a, b)) {
                    *s += t;
                }
            }
            sum
        })
        .collect();
    partial.iter().fold([0.0; K], |mut total, p| {
        for (t, v) in total.iter_mut().zip(p) {
            *t += v;
        }
        total
    })
}

/// The final placement with its score, over every valid reference node.
fn score(reference: &HeightMap, part: &HeightMap, state: &State) -> Alignment {
    let placement = Placement::of_state(state);
    let motion = placement.motion();
    let valid = reference.z.par_iter().filter(|v| !v.is_nan()).count();
    let pairs: Vec<(f64, f64)> = reference
        .z
        .par_iter()
        .enumerate()
        .filter(|(_, z)| !z.is_nan())
        .filter_map(|(i, &z)| {
            let at = [reference.x_mm(i % reference.width), reference.y_mm(i / reference.width)];
            let q = motion.apply(at);
            let m = part.z_at(q[0], q[1]);
            let plane = state[3] + state[4] * at[0] + state[5] * at[1];
            m.is_finite().then_some((f64::from(z) + plane, m))
        })
        .collect();
    let n = pairs.len().max(1) as f64;
    let [sa, sb] = chunked_sums(&pairs, |a, b| [a, b]);
    let (ma, mb) = (sa / n, sb / n);
    let [sab, saa, sbb] = chunked_sums(&pairs, |a, b| [(a - ma) * (b - mb), (a - ma) * (a - ma), (b - mb) * (b - mb)]);
    // Rounding can carry a perfect match a hair past 1, which a recipe's
    // upper limit of 1 would fail.
    let score = if saa > 0.0 && sbb > 0.0 { (sab / (saa * sbb).sqrt()).clamp(-1.0, 1.0) } else { 0.0 };
    // A stride of the pairs gives the robust sigma as well as all of them
    // (its relative error goes as 1 / sqrt(n): 0.3 % from 100,000), without
    // selecting the median of millions on one thread.
    let stride = pairs.len().div_ceil(SIGMA_SAMPLES).max(1);
    let sigma = robust_sigma(pairs.iter().step_by(stride).map(|&(a, b)| b - a));
    let limit = HUBER_K * sigma;
    let [kept, sum_squares] = chunked_sums(&pairs, |a, b| {
        let r = b - a;
        if r.abs() <= limit { [1.0, r * r] } else { [0.0, 0.0] }
    });
    let rms = (sum_squares / kept.max(1.0)).sqrt();
    Alignment {
        placement,
        score,
        overlap: pairs.len() as f64 / valid.max(1) as f64,
        residual_rms_um: rms * reference.unit.um_per_unit(),
        plane: [state[3], state[4], state[5]],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A part with features of several scales on a plane: a raised
    /// rectangle, a dome and a groove, off-centre so no rotation of it looks
    /// like another.
    fn part_height_mm(x: f64, y: f64, edge_mm: f64) -> f64 {
        // A step of `edge_mm` width (0: sharp, sampled as the nodes fall).
        let step =
            |d: f64| if edge_mm > 0.0 { 0.5 * (1.0 + (d / edge_mm).tanh()) } else { f64::from(u8::from(d >= 0.0)) };
        let mut z = 0.001 * x;
        z += 0.2 * step(x + 6.0) * step(2.0 - x) * step(y + 3.0) * step(4.0 - y);
        let r2 = (x - 4.0).powi(2) + (y + 2.0).powi(2);
        if r2 < 9.0 {
            z += 0.3 * (1.0 - r2 / 9.0);
        }
        let d = (y - 0.5 * x - 5.0).abs();
        z -= 0.05 * step(0.4 - d);
        z
    }

    /// The part placed by `placement` (stage point q shows the part's point
    /// placement^-1(q)), on a 24 x 18 mm field at `pitch`.
    fn map_of(placement: Placement, pitch: f64, edge_mm: f64) -> HeightMap {
        let (w, h) = ((24.0 / pitch) as usize, (18.0 / pitch) as usize);
        let (s, c) = placement.rotation_deg.to_radians().sin_cos();
        let z = (0..w * h)
            .map(|i| {
                let q = [
                    -12.0 + (i % w) as f64 * pitch - placement.shift_mm[0],
                    -9.0 + (i / w) as f64 * pitch - placement.shift_mm[1],
                ];
                let p = [c * q[0] + s * q[1], -s * q[0] + c * q[1]];
                if p[0].abs() > 10.0 || p[1].abs() > 7.5 {
                    f32::NAN
                } else {
                    part_height_mm(p[0], p[1], edge_mm) as f32
                }
            })
            .collect();
        HeightMap::new(w, h, -12.0, -9.0, pitch, z).expect("map")
    }

    fn check_found(edge_mm: f64, max_rotation_error_deg: f64, max_shift_error_px: f64) {
        let pitch = 0.05;
        let reference = map_of(Placement::IDENTITY, pitch, edge_mm);
        for truth in [
            Placement { rotation_deg: 4.3, shift_mm: [1.7, -1.2] },
            Placement { rotation_deg: -5.0, shift_mm: [-2.0, 1.9] },
            Placement { rotation_deg: 0.0, shift_mm: [0.33, 0.0] },
        ] {
            let part = map_of(truth, pitch, edge_mm);
            let found = align(&reference, &part, &AlignmentSearch::default()).expect("aligned");
            let p = found.placement;
            assert!((p.rotation_deg - truth.rotation_deg).abs() < max_rotation_error_deg, "{truth:?}: {p:?}");
            for k in 0..2 {
                assert!((p.shift_mm[k] - truth.shift_mm[k]).abs() < max_shift_error_px * pitch, "{truth:?}: {p:?}");
            }
            assert!(found.score > 0.99, "{truth:?}: score {}", found.score);
        }
    }

    /// A line's parts share the reference's levels: made on the first part,
    /// taken on the next, and every alignment is the one made from scratch.
    #[test]
    fn kept_reference_levels_give_the_same_alignment_as_fresh_ones() {
        let pitch = 0.05;
        let reference = map_of(Placement::IDENTITY, pitch, 0.1);
        let levels = ReferenceLevels::default();
        let search = AlignmentSearch::default();
        for (i, truth) in [
            Placement { rotation_deg: 3.1, shift_mm: [1.2, -0.7] },
            Placement { rotation_deg: -2.4, shift_mm: [-1.5, 0.4] },
        ]
        .into_iter()
        .enumerate()
        {
            let part = map_of(truth, pitch, 0.1);
            let kept = align_with(&reference, &levels, &part, &search).expect("aligned with kept levels");
            let fresh = align(&reference, &part, &search).expect("aligned from scratch");
            assert_eq!(kept, fresh, "part {i}");
            let made = levels.levels.lock().expect("levels").len();
            assert!(made >= 2, "part {i}: the coarse level and at least one finer kept, {made}");
        }
        // The second part found every level it needed already made.
        let before: Vec<usize> = levels.levels.lock().expect("levels").iter().map(|l| l.block).collect();
        let part = map_of(Placement { rotation_deg: 1.0, shift_mm: [0.5, 0.5] }, pitch, 0.1);
        align_with(&reference, &levels, &part, &search).expect("aligned");
        let after: Vec<usize> = levels.levels.lock().expect("levels").iter().map(|l| l.block).collect();
        assert_eq!(before, after);
    }

    /// Features whose edges span a few nodes are sampled alike however the
    /// part lies: the placement is found to a hundredth of a degree and a
    /// tenth of the pitch.
    #[test]
    fn a_moved_part_is_found_to_a_tenth_of_the_pitch_and_a_hundredth_of_a_degree() {
        check_found(0.1, 0.01, 0.1);
    }

    /// A sharp edge lies anywhere within the node spacing that samples it
    /// (half a pitch either way on the reference): the placement is then
    /// known to about that, far finer than any region's margin.
    #[test]
    fn sharp_steps_place_the_part_to_half_a_pitch() {
        check_found(0.0, 0.1, 0.5);
    }

    /// The difference of a moved part to its reference is the noise-free
    /// zero away from the edges: the placement and the plane explain it all.
    #[test]
    fn the_difference_to_the_reference_vanishes_where_the_part_matches() {
        let reference = map_of(Placement::IDENTITY, 0.05, 0.1);
        let part = map_of(Placement { rotation_deg: 3.0, shift_mm: [1.0, -0.5] }, 0.05, 0.1);
        let found = align(&reference, &part, &AlignmentSearch::default()).expect("aligned");
        let diff = difference_to_reference(&reference, &part, &found);
        let mut abs: Vec<f32> = diff.z.iter().filter(|v| !v.is_nan()).map(|v| v.abs()).collect();
        assert!(abs.len() > part.valid_count() / 2, "{} of {}", abs.len(), part.valid_count());
        abs.sort_by(f32::total_cmp);
        let median_um = 1e3 * abs[abs.len() / 2];
        assert!(median_um < 0.1, "median |difference| {median_um} um");
    }

    #[test]
    fn the_same_shape_scores_at_most_one() {
        // A recipe's reference part measured again, its heights a rounding
        // apart: a score past 1 would fail a recipe whose limit is 1.
        for (pitch, edge) in [(0.05, 0.1), (0.1, 0.1), (0.07, 0.2)] {
            let reference = map_of(Placement::IDENTITY, pitch, edge);
            let mut again = reference.clone();
            for z in again.z.iter_mut().step_by(7) {
                *z = f32::from_bits(z.to_bits() + 1);
            }
            for part in [&reference, &again] {
                let found = align(&reference, part, &AlignmentSearch::default()).expect("aligned");
                assert!(found.score <= 1.0 && found.score > 0.9999, "pitch {pitch}: score {:e}", found.score - 1.0);
            }
        }
    }

    #[test]
    fn another_shape_scores_low() {
        let reference = map_of(Placement::IDENTITY, 0.1, 0.1);
        let other = HeightMap::new(
            240,
            180,
            -12.0,
            -9.0,
            0.1,
            (0..240 * 180)
                .map(|i| {
                    let (x, y) = ((i % 240) as f64 * 0.1 - 12.0, (i / 240) as f64 * 0.1 - 9.0);
                    (0.1 * (x * 0.8).sin() * (y * 1.3).cos()) as f32
                })
                .collect(),
        )
        .expect("map");
        let found = align(&reference, &other, &AlignmentSearch::default()).expect("ran");
        assert!(found.score < 0.5, "score {}", found.score);
    }

    #[test]
    fn regions_and_sections_move_with_the_part() {
        let placement = Placement { rotation_deg: 90.0, shift_mm: [1.0, 0.0] };
        let moved = placement.move_region(&Region::Rectangle { x_mm: [0.0, 2.0], y_mm: [0.0, 1.0] });
        let Region::Polygon { vertices_mm } = moved else { panic!("a turned rectangle is a polygon") };
        let expected = [[1.0, 0.0], [1.0, 2.0], [0.0, 2.0], [0.0, 0.0]];
        for (v, e) in vertices_mm.iter().zip(expected) {
            assert!((v[0] - e[0]).abs() < 1e-12 && (v[1] - e[1]).abs() < 1e-12, "{vertices_mm:?}");
        }
        let line = placement
            .move_profile_line(&ProfileLine::Horizontal { through_mm: [5.0, 1.0] }, ([-3.0, -2.0], [3.0, 2.0]));
        let ProfileLine::Segment { start_mm, end_mm } = line else { panic!("a moved section is a segment") };
        assert!((start_mm[0] - 0.0).abs() < 1e-12 && (start_mm[1] + 3.0).abs() < 1e-12, "{start_mm:?}");
        assert!((end_mm[0] - 0.0).abs() < 1e-12 && (end_mm[1] - 3.0).abs() < 1e-12, "{end_mm:?}");
    }

    #[test]
    fn a_region_moved_past_the_map_edge_is_named() {
        let map = map_of(Placement::IDENTITY, 0.1, 0.1);
        let regions = vec![
            NamedRegion::new("inside", Region::Circle { centre_mm: [0.0, 0.0], radius_mm: 1.0 }),
            NamedRegion::new("edge", Region::Circle { centre_mm: [11.5, 0.0], radius_mm: 1.0 }),
        ];
        assert_eq!(region_leaving_field(&regions, &map).map(|r| r.name.as_str()), Some("edge"));
    }
}
