//! Absolute projector coordinates of a camera–projector rig (issue 52): the
//! Gray code's cell makes the phase absolute, the phase makes it precise.
//!
//! The code alone is coarse (a cell of `cell_px` projector pixels) and its
//! cell edges may fall on the wraps of a phase set, as in the real mug
//! capture, where the 100 px set wraps exactly at every 100 px cell edge:
//! ordering that set by the cell would pick its period by chance at every
//! edge. So the code orders the *beat* of two sets (periods p₁ < p₂ give
//! `φ₁ - φ₂`, of period `p₁ p₂ / (p₂ - p₁)`: 200 px for 200/3 and 100 px),
//! which needs the cell's centre within half a beat of the truth (a cell of
//! 100 px leaves 50 px of margin, enough for a cell decoded one off at its
//! edge); the beat then orders each set, and the two sets' ordered
//! coordinates, weighted by their phase noise, give the projector pixel.
//! This is the paper's hierarchical temporal unwrapping (Section 2.2) with
//! the Gray code as its sparsest level.
//!
//! A pixel is refused, with its reason, where the code has none, where a
//! set has no phase, where the two sets' coordinates disagree by more than
//! their noise and their harmonic ripple allow (a wrong order of one set),
//! or where the result lies outside the decoded cell by more than a
//! margin (code and phase disagree): never a guess. Every phase's origin
//! is projector coordinate 0 (`I = A + B cos(2π x / p + δ)`).

use super::gray_code::{GrayDecode, GrayRefusal};
use super::phase_shift::WrappedPhase;
use super::warning::{Warning, WarningKind};

/// One phase set along the axis: its wrapped phase in [0, 2π) (NaN where it
/// has none) and its standard deviation, per pixel.
#[derive(Clone, Copy, Debug)]
pub struct SetPhase<'a> {
    pub period_px: f64,
    /// Phase steps `N`: the fringes' harmonics ripple the phase at `N φ`.
    pub shifts: usize,
    pub wrapped_phase_rad: &'a [f32],
    pub phase_sigma_rad: &'a [f32],
}

impl<'a> SetPhase<'a> {
    pub fn of(phase: &'a WrappedPhase) -> Self {
        Self {
            period_px: phase.period_px,
            shifts: phase.shifts,
            wrapped_phase_rad: &phase.wrapped_phase_rad,
            phase_sigma_rad: &phase.phase_sigma_rad,
        }
    }
}

/// When the phase and the code are trusted together.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AbsoluteParams {
    /// Two sets' ordered coordinates may differ by at most this much, or
    /// four times their combined noise where that is more (projector
    /// pixels). Uncorrected gamma ripples a 3-step set by a few pixels: the
    /// real capture's sets differ by about 5 px RMS (15 px refuses 0.03 %
    /// of its pixels more than 20 px, and the one pixel 72 px off that 20
    /// let through), and a wrong order of one set by its whole period (67
    /// or 100 px).
    pub max_set_disagreement_px: f64,
    /// How far outside its decoded cell a coordinate may fall (projector
    /// pixels): a cell edge blurs over a few camera pixels. A code one cell
    /// off further from its edge puts the beat a whole beat away, outside
    /// the cell unless within this margin of it; a code two cells off is a
    /// whole beat, which no phase can see (the inverse frames are what
    /// keep a bit from flipping).
    pub cell_margin_px: f64,
}

impl Default for AbsoluteParams {
    fn default() -> Self {
        Self { max_set_disagreement_px: 15.0, cell_margin_px: 10.0 }
    }
}

/// Why a pixel has no projector coordinate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoordinateRefusal {
    /// The Gray code gave no cell.
    Code(GrayRefusal),
    /// A phase set has no phase at the pixel (saturated, or no modulation).
    NoPhase,
    /// The two sets' ordered coordinates disagree: one of them is a period off.
    SetsDisagree,
    /// The coordinate lies outside the decoded cell: code and phase disagree.
    OutsideCell,
}

impl CoordinateRefusal {
    pub fn describe(self) -> String {
        match self {
            CoordinateRefusal::Code(GrayRefusal::Shadow) => {
                "in the projector's shadow (white minus black too small)".into()
            }
            CoordinateRefusal::Code(GrayRefusal::AmbiguousBit { plane }) => {
                format!("Gray code bit plane {plane}: pattern and inverse too close to decide")
            }
            CoordinateRefusal::Code(GrayRefusal::OutOfRange) => "the Gray code decodes beyond the projector".into(),
            CoordinateRefusal::Code(GrayRefusal::AtCellEdge { .. }) => "on a Gray code cell edge".into(),
            CoordinateRefusal::NoPhase => "a phase set has no phase here".into(),
            CoordinateRefusal::SetsDisagree => "the phase sets disagree (one is a whole period off)".into(),
            CoordinateRefusal::OutsideCell => "the phase lies outside the Gray code's cell".into(),
        }
    }
}

/// The absolute projector coordinate of each pixel along one axis.
#[derive(Clone, Debug)]
pub struct ProjectorCoordinate {
    pub width: usize,
    pub height: usize,
    /// Projector pixels along the axis; NaN where refused.
    pub coordinate_px: Vec<f32>,
    /// Its standard deviation from the phase noise (projector pixels).
    pub sigma_px: Vec<f32>,
    /// Why each refused pixel was refused (`None` where it has a coordinate).
    pub refusal: Vec<Option<CoordinateRefusal>>,
    /// With two sets: how far apart their coordinates lie where both were
    /// kept (after the ripple correction).
    pub set_agreement: Option<SetAgreement>,
    /// With two sets: their harmonic ripple, taken out of the coordinate.
    pub ripple: Option<RippleCorrection>,
}

/// How well two phase sets of one axis agree over the pixels kept.
///
/// Random noise makes them differ by `sqrt(σ₁² + σ₂²)`. A projector's gamma
/// not corrected puts harmonics into every fringe, and a 3-step set turns
/// the second harmonic into a ripple of its phase at three times the
/// fringe frequency, a deterministic error of a few projector pixels that
/// the noise estimate does not include (the real mug capture: 4.9 px RMS
/// against 0.8-0.9 px of noise). [`fit_ripple`] takes it out; what is left
/// beyond the noise is reported rather than passed on silently.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SetAgreement {
    pub pixels: usize,
    /// RMS of the two sets' coordinate difference (projector pixels).
    pub rms_px: f64,
    /// What their phase noise alone would give.
    pub expected_rms_px: f64,
}

impl SetAgreement {
    /// The sets disagree this many times more than their noise before the
    /// ripple is reported (and by at least a projector pixel).
    pub const RIPPLE_RATIO: f64 = 3.0;

    /// The warning, where the disagreement is a ripple rather than noise.
    pub fn ripple_warning(&self, axis: &str) -> Option<Warning> {
        (self.rms_px > Self::RIPPLE_RATIO * self.expected_rms_px && self.rms_px > 1.0).then(|| {
            Warning::new(
                WarningKind::PhaseSetsRipple,
                format!(
                    "projector {axis}: the two phase sets disagree by {:.1} px RMS where their noise gives {:.1} px: \
                     an error that is not a harmonic ripple of the fringes (or one Sheen could not fit) moves the \
                     coordinate by a few pixels; check the projector's gamma and the phase steps",
                    self.rms_px, self.expected_rms_px
                ),
            )
        })
    }
}

impl ProjectorCoordinate {
    /// What the user should know of the sets' agreement: a ripple taken
    /// out, or sets that still disagree beyond their noise.
    pub fn ripple_warnings(&self, axis: &str) -> Vec<Warning> {
        let corrected = self.ripple.and_then(|r| r.warning(axis, self.set_agreement.as_ref()));
        let left = self.set_agreement.and_then(|a| a.ripple_warning(axis));
        corrected.into_iter().chain(left).collect()
    }

    /// Pixels the white/black mask keeps, and of those how many have a coordinate.
    pub fn lit_and_measured(&self) -> (usize, usize) {
        let lit = self.refusal.iter().filter(|r| **r != Some(CoordinateRefusal::Code(GrayRefusal::Shadow))).count();
        (lit, self.refusal.iter().filter(|r| r.is_none()).count())
    }

    /// One pixel in words, with its Gray code cell: `x_p = 812.31 ± 0.40 px
    /// (Gray code cell 8)` or why it has no coordinate (the Projector view's
    /// hover and the pixel inspector).
    pub fn explain_pixel(&self, code: &GrayDecode, axis: &str, pixel: usize) -> String {
        let cell = match code.cells[pixel] {
            Ok(c) => format!("Gray code cell {c}"),
            Err(GrayRefusal::AtCellEdge { lower_cell }) => {
                format!("on the edge of Gray code cells {lower_cell} and {}", lower_cell + 1)
            }
            Err(_) => "no Gray code".to_string(),
        };
        match self.refusal[pixel] {
            None => format!("{axis}_p = {:.2} ± {:.2} px ({cell})", self.coordinate_px[pixel], self.sigma_px[pixel]),
            Some(why) => format!("refused: {} ({cell})", why.describe()),
        }
    }

    /// Refused pixels per reason, in a fixed order.
    pub fn refusal_counts(&self) -> Vec<(CoordinateRefusal, usize)> {
        let mut counts: Vec<(CoordinateRefusal, usize)> = Vec::new();
        for r in self.refusal.iter().flatten() {
            match counts.iter_mut().find(|(k, _)| k == r) {
                Some((_, n)) => *n += 1,
                None => counts.push((*r, 1)),
            }
        }
        counts
    }
}

/// What cannot be combined, before any pixel is looked at.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ProjectorCoordinateError {
    #[error("a phase set has {found} pixels where the Gray code has {expected}")]
    SetSize { expected: usize, found: usize },
    #[error("{sets} phase sets along one axis: 1 or 2 are combined with a Gray code")]
    SetCount { sets: usize },
    #[error(
        "a Gray code cell of {cell_px} px cannot order a period of {period_px:.1} px: the cell must be at most half of it \
         (give two sets whose beat is long enough, or a finer code)"
    )]
    CellTooCoarse { cell_px: f64, period_px: f64 },
    #[error("two phase sets of the same period ({period_px} px) have no beat")]
    NoBeat { period_px: f64 },
}

/// One pixel's coordinate, σ and refusal, and with two sets their
/// difference and its expected variance.
type PixelResult = (f32, f32, Option<CoordinateRefusal>, Option<(f64, f64)>);

/// A pixel's sets ordered by its code: per set the coordinate, its σ and
/// the phase it came from (px, px, rad), and where the code put the pixel.
#[derive(Clone, Copy, Debug)]
struct Ordered {
    centre: f64,
    sets: [(f64, f64, f64); 2],
    count: usize,
}

/// Orders of the ripple fitted: `j N φ` for `j` = 1 to 6 (the harmonics
/// that alias, and what a ripple of a few pixels adds to itself; gamma 2.2
/// still leaves a hundredth of a pixel at the sixth).
const RIPPLE_ORDERS: usize = 10;

/// The harmonic ripple of the sets of one axis, fitted from their
/// disagreement and taken out of each (see [`fit_ripple`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RippleCorrection {
    /// Per order `j`, the phase error `a sin(jNφ) + b cos(jNφ)` (radians)
    /// every set of the axis shares.
    pub sin_cos_rad: [[f64; 2]; RIPPLE_ORDERS],
    /// The sets' disagreement before the correction (RMS, projector pixels).
    pub rms_before_px: f64,
    /// Pixels the fit used.
    pub pixels: usize,
    /// The sets' steps `N` and periods.
    pub shifts: usize,
    pub periods_px: [f64; 2],
}

impl RippleCorrection {
    /// Peak of the ripple taken out of the sparser set (projector pixels).
    pub fn peak_px(&self) -> f64 {
        self.peak_rad(self.shifts) / std::f64::consts::TAU * self.periods_px[0].max(self.periods_px[1])
    }

    /// Said where the ripple taken out reached a projector pixel: the
    /// projector's gamma wants correcting, even though the map is mended.
    pub fn warning(&self, axis: &str, after: Option<&SetAgreement>) -> Option<Warning> {
        (self.peak_px() >= 1.0).then(|| {
            let after = after.map_or(String::new(), |a| {
                format!("; they now agree to {:.1} px RMS (noise {:.1} px)", a.rms_px, a.expected_rms_px)
            });
            Warning::new(
                WarningKind::PhaseSetsRipple,
                format!(
                    "projector {axis}: the phase sets rippled by up to {:.1} px (harmonics of the fringes: an \
                     uncorrected projector gamma) and disagreed by {:.1} px RMS; the ripple, fitted from their \
                     disagreement over {} pixels, was taken out{after}. Correct the projector's gamma or use more \
                     phase steps to measure without it",
                    self.peak_px(),
                    self.rms_before_px,
                    self.pixels
                ),
            )
        })
    }

    /// The phase error `R(φ)` at measured phase `phase_rad` of a set of
    /// `shifts` steps, and its slope `dR/dφ`: the correction stretches the
    /// phase's noise by `|1 - dR/dφ|` (steep where the ripple is).
    pub fn ripple_and_slope(&self, shifts: usize, phase_rad: f64) -> (f64, f64) {
        let n = shifts as f64;
        let (mut value, mut slope) = (0.0, 0.0);
        // e^{ijNφ} by repeated multiplication: one sin_cos per pixel.
        let base = (n * phase_rad).sin_cos();
        let mut power = base;
        for (j, [a, b]) in self.sin_cos_rad.iter().enumerate() {
            let (s, c) = power;
            value += a * s + b * c;
            slope += (j + 1) as f64 * n * (a * c - b * s);
            power = (s * base.1 + c * base.0, c * base.1 - s * base.0);
        }
        (value, slope)
    }

    /// `R(φ)` alone.
    pub fn ripple_rad(&self, shifts: usize, phase_rad: f64) -> f64 {
        self.ripple_and_slope(shifts, phase_rad).0
    }

    /// `R` and `dR/dφ` tabulated over one period of `N φ`, for the map's
    /// millions of pixels (a lookup instead of ten harmonics each).
    fn table(&self, shifts: usize) -> RippleTable {
        let step = std::f64::consts::TAU / (shifts.max(1) * RippleTable::SIZE) as f64;
        RippleTable {
            per_rad: 1.0 / step,
            values: (0..=RippleTable::SIZE).map(|k| self.ripple_and_slope(shifts, k as f64 * step)).collect(),
        }
    }

    /// Peak of the phase error over a period (radians).
    pub fn peak_rad(&self, shifts: usize) -> f64 {
        (0..720).map(|k| self.ripple_rad(shifts, f64::from(k).to_radians() / 2.0).abs()).fold(0.0, f64::max)
    }
}

/// [`RippleCorrection::ripple_and_slope`] sampled over one period of `N φ`.
struct RippleTable {
    per_rad: f64,
    /// `SIZE + 1` samples: the last closes the period.
    values: Vec<(f64, f64)>,
}

impl RippleTable {
    /// Samples per period: the ripple's tenth order gets 100 of them.
    const SIZE: usize = 1024;

    fn at(&self, phase_rad: f64) -> (f64, f64) {
        let t = (phase_rad * self.per_rad).rem_euclid(Self::SIZE as f64);
        let k = (t as usize).min(Self::SIZE - 1);
        let f = t - k as f64;
        let (a, b) = (self.values[k], self.values[k + 1]);
        (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
    }
}

/// The projector coordinate along one axis from its decoded Gray code
/// (`cell_px` projector pixels per code unit) and one or two phase sets
/// (module docs). With two sets, their harmonic ripple is fitted and taken
/// out first ([`fit_ripple`]).
pub fn absolute_coordinate(
    code: &GrayDecode,
    cell_px: f64,
    sets: &[SetPhase<'_>],
    params: &AbsoluteParams,
) -> Result<ProjectorCoordinate, ProjectorCoordinateError> {
    use rayon::prelude::*;
    use std::f64::consts::TAU;
    let pixels = code.width * code.height;
    if let Some(s) = sets.iter().find(|s| s.wrapped_phase_rad.len() != pixels || s.phase_sigma_rad.len() != pixels) {
        return Err(ProjectorCoordinateError::SetSize { expected: pixels, found: s.wrapped_phase_rad.len() });
    }
    // The level the code orders: the beat of two sets, or the one set.
    let ordered_period = match sets {
        [one] => one.period_px,
        [a, b] => {
            let (lo, hi) = (a.period_px.min(b.period_px), a.period_px.max(b.period_px));
            if hi - lo < 1e-9 * hi {
                return Err(ProjectorCoordinateError::NoBeat { period_px: hi });
            }
            lo * hi / (hi - lo)
        }
        _ => return Err(ProjectorCoordinateError::SetCount { sets: sets.len() }),
    };
    if cell_px > ordered_period / 2.0 {
        return Err(ProjectorCoordinateError::CellTooCoarse { cell_px, period_px: ordered_period });
    }
    // Coordinate within its period of a phase.
    let within = |phase: f64, period: f64| phase / TAU * period;
    // The candidate of `x + k period` nearest `guess`.
    let nearest = |x: f64, period: f64, guess: f64| x + ((guess - x) / period).round() * period;
    let order = |i: usize| -> Result<Ordered, CoordinateRefusal> {
        // Where the code puts the pixel: its cell's centre, or the edge
        // it lies on (within a pixel or two of the truth).
        let centre = match code.cells[i] {
            Ok(c) => (f64::from(c) + 0.5) * cell_px,
            Err(GrayRefusal::AtCellEdge { lower_cell }) => (f64::from(lower_cell) + 1.0) * cell_px,
            Err(r) => return Err(CoordinateRefusal::Code(r)),
        };
        // One or two sets (checked above): fixed arrays, no allocation per pixel.
        let mut phases = [(0.0, 0.0, 0.0); 2];
        for (p, s) in phases.iter_mut().zip(sets) {
            *p = (f64::from(s.wrapped_phase_rad[i]), f64::from(s.phase_sigma_rad[i]), s.period_px);
        }
        let phases = &phases[..sets.len()];
        if phases.iter().any(|p| !p.0.is_finite()) {
            return Err(CoordinateRefusal::NoPhase);
        }
        let coarse = match *phases {
            [(phase, _, period)] => nearest(within(phase, period), period, centre),
            [(pa, _, a), (pb, _, b)] => {
                // φ_short - φ_long grows by 2π over the beat.
                let (short, long) = if a < b { (pa, pb) } else { (pb, pa) };
                nearest(within((short - long).rem_euclid(TAU), ordered_period), ordered_period, centre)
            }
            _ => unreachable!("one or two sets, checked above"),
        };
        // Each set ordered by the coarse coordinate.
        let mut ordered = Ordered { centre, sets: [(0.0, 0.0, 0.0); 2], count: phases.len() };
        for (o, &(phase, sigma, period)) in ordered.sets.iter_mut().zip(phases) {
            let sigma_px = (sigma / TAU * period).max(1e-6);
            *o = (nearest(within(phase, period), period, coarse), sigma_px, phase);
        }
        Ok(ordered)
    };
    let allowed = |sa: f64, sb: f64| params.max_set_disagreement_px.max(4.0 * sa.hypot(sb));
    let ripple = match sets {
        [a, b] if a.shifts == b.shifts => fit_ripple(pixels, a.shifts, [a.period_px, b.period_px], |i| {
            let o = order(i).ok()?;
            let [(xa, sa, pa), (xb, sb, pb)] = o.sets;
            ((xa - xb).abs() <= allowed(sa, sb)).then_some((xa - xb, sa * sa + sb * sb, [pa, pb]))
        }),
        _ => None,
    };
    let tables: Option<Vec<RippleTable>> = ripple.map(|r| sets.iter().map(|s| r.table(s.shifts)).collect());
    let results: Vec<PixelResult> = (0..pixels)
        .into_par_iter()
        .map(|i| {
            let refuse = |r| (f32::NAN, f32::NAN, Some(r), None);
            let mut o = match order(i) {
                Ok(o) => o,
                Err(r) => return refuse(r),
            };
            if let Some(tables) = &tables {
                for (k, (x, sigma, phase)) in o.sets.iter_mut().enumerate() {
                    let (r, slope) = tables[k].at(*phase);
                    *x -= r / TAU * sets[k].period_px;
                    *sigma *= (1.0 - slope).abs().max(0.1);
                }
            }
            let ordered = &o.sets[..o.count];
            let mut difference = None;
            if let [(xa, sa, _), (xb, sb, _)] = *ordered {
                if (xa - xb).abs() > allowed(sa, sb) {
                    return refuse(CoordinateRefusal::SetsDisagree);
                }
                difference = Some((xa - xb, sa * sa + sb * sb));
            }
            // The sets weighted by their noise.
            let weight: f64 = ordered.iter().map(|(_, s, _)| 1.0 / (s * s)).sum();
            let x = ordered.iter().map(|(x, s, _)| x / (s * s)).sum::<f64>() / weight;
            if (x - o.centre).abs() > cell_px / 2.0 + params.cell_margin_px {
                return refuse(CoordinateRefusal::OutsideCell);
            }
            (x as f32, (1.0 / weight.sqrt()) as f32, None, difference)
        })
        .collect();
    let mut out = ProjectorCoordinate {
        width: code.width,
        height: code.height,
        coordinate_px: Vec::with_capacity(pixels),
        sigma_px: Vec::with_capacity(pixels),
        refusal: Vec::with_capacity(pixels),
        set_agreement: None,
        ripple,
    };
    let (mut n, mut squares, mut expected) = (0usize, 0.0, 0.0);
    for (x, s, r, d) in results {
        out.coordinate_px.push(x);
        out.sigma_px.push(s);
        out.refusal.push(r);
        if let Some((d, v)) = d {
            n += 1;
            squares += d * d;
            expected += v;
        }
    }
    if n > 0 {
        out.set_agreement = Some(SetAgreement {
            pixels: n,
            rms_px: (squares / n as f64).sqrt(),
            expected_rms_px: (expected / n as f64).sqrt(),
        });
    }
    Ok(out)
}

/// Fewest pixels a ripple is fitted from.
const MIN_RIPPLE_PIXELS: usize = 1000;
/// Most pixels the fit samples.
const MAX_RIPPLE_PIXELS: usize = 50_000;

/// The harmonic ripple of two sets from their disagreement.
///
/// An `N`-step set turns the fringes' harmonics `N ± 1` (a projector's
/// gamma: mostly the second, for `N = 3`) into an error of its phase that
/// is a function of the phase alone, periodic in `N φ`: the same at every
/// pixel whatever its brightness (gamma bends every fringe alike) and the
/// same for every set of the axis (same steps, same projector). Two sets
/// of different periods ripple at different places along the projector,
/// so their difference `d = (R(φ_a) p_a - R(φ_b) p_b) / 2π + noise`, with
/// `R(φ) = Σ_j s_j sin(jNφ) + c_j cos(jNφ)`, gives `R` by weighted least
/// squares over every pixel both sets order alike (`pixel(i)`: the
/// difference in projector pixels, its variance and the two phases). One
/// `R` for both sets is what separates them: each set's own ripple would
/// leave the orders where `j_a / p_a = j_b / p_b` (the third of the 48 px
/// set and the second of the 32 px one) seen only through their difference.
/// `None` with too few pixels or phases that do not tell the orders apart.
fn fit_ripple(
    pixels: usize,
    shifts: usize,
    periods_px: [f64; 2],
    pixel: impl Fn(usize) -> Option<(f64, f64, [f64; 2])> + Sync,
) -> Option<RippleCorrection> {
    use nalgebra::{SMatrix, SVector};
    use rayon::prelude::*;
    use std::f64::consts::TAU;
    const TERMS: usize = 2 * RIPPLE_ORDERS;
    type Normal = SMatrix<f64, TERMS, TERMS>;
    type Terms = SVector<f64, TERMS>;
    let (scale_a, scale_b) = (periods_px[0] / TAU, periods_px[1] / TAU);
    let regressors = |[pa, pb]: [f64; 2]| {
        let mut g = Terms::zeros();
        let n = shifts as f64;
        let (base_a, base_b) = ((n * pa).sin_cos(), (n * pb).sin_cos());
        let (mut a, mut b) = (base_a, base_b);
        for j in 0..RIPPLE_ORDERS {
            g[2 * j] = a.0 * scale_a - b.0 * scale_b;
            g[2 * j + 1] = a.1 * scale_a - b.1 * scale_b;
            a = (a.0 * base_a.1 + a.1 * base_a.0, a.1 * base_a.1 - a.0 * base_a.0);
            b = (b.0 * base_b.1 + b.1 * base_b.0, b.1 * base_b.1 - b.0 * base_b.0);
        }
        g
    };
    type Sums = (Normal, Terms, f64, usize);
    let zero = || -> Sums { (Normal::zeros(), Terms::zeros(), 0.0, 0) };
    // A sample of the pixels is plenty for a few coefficients (and keeps
    // the fit a small part of the map's time).
    let stride = (pixels / MAX_RIPPLE_PIXELS).max(1);
    let (normal, rhs, squares, n) = (0..pixels)
        .into_par_iter()
        .step_by(stride)
        .fold(zero, |(mut m, mut v, mut sq, n), i| {
            if let Some((d, variance, phases)) = pixel(i) {
                let g = regressors(phases);
                let w = 1.0 / variance.max(1e-12);
                m += w * g * g.transpose();
                v += w * d * g;
                sq += d * d;
                return (m, v, sq, n + 1);
            }
            (m, v, sq, n)
        })
        .reduce(zero, |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3));
    if n < MIN_RIPPLE_PIXELS {
        return None;
    }
    // Well conditioned: each coefficient seen on its own, not only as a
    // sum with another (a narrow range of the projector).
    let cholesky = normal.cholesky()?;
    let inverse = cholesky.inverse();
    if (0..TERMS).any(|k| !(inverse[(k, k)] * normal[(k, k)] < 10.0)) {
        return None;
    }
    let x = cholesky.solve(&rhs);
    Some(RippleCorrection {
        sin_cos_rad: std::array::from_fn(|j| [x[2 * j], x[2 * j + 1]]),
        rms_before_px: (squares / n as f64).sqrt(),
        pixels: n,
        shifts,
        periods_px,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::gray_code::{GrayDecodeParams, bit_planes, decode_axis, pattern_is_bright};
    use std::f64::consts::TAU;

    /// A projector line of `width` px seen by a camera row one to one, with
    /// the real capture's code (100 px cells) and sets (200/3 and 100 px).
    fn scene(width: usize, shift_px: f64) -> (GrayDecode, Vec<f64>) {
        let cells = width.div_ceil(100);
        let planes = bit_planes(cells);
        let x_of = |c: usize| c as f64 + shift_px;
        let mut frames = Vec::new();
        for plane in 0..planes {
            for inverse in [false, true] {
                frames.push(
                    (0..width)
                        .map(|c| {
                            let cell = (x_of(c) / 100.0).floor().clamp(0.0, cells as f64 - 1.0) as u32;
                            if pattern_is_bright(cell, planes, plane) != inverse { 200.0 } else { 20.0 }
                        })
                        .collect::<Vec<f32>>(),
                );
            }
        }
        let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
        let (white, black) = (vec![200.0f32; width], vec![20.0f32; width]);
        let code = decode_axis(&refs, &white, &black, width, 1, cells, &GrayDecodeParams::default()).expect("decode");
        (code, (0..width).map(x_of).collect())
    }

    fn phase_of(x: &[f64], period: f64, ripple_px: f64) -> Vec<f32> {
        x.iter().map(|&x| ((x + ripple_px * (TAU * x / 23.0).sin()) / period * TAU).rem_euclid(TAU) as f32).collect()
    }

    #[test]
    fn the_code_orders_the_beat_even_where_a_cell_edge_is_a_wrap() {
        // 1900 px: every 100 px cell edge is a wrap of the 100 px set, and
        // every second one of the 200/3 px set.
        let (code, truth) = scene(1900, 0.25);
        let sigma = vec![0.01f32; truth.len()];
        let (a, b) = (phase_of(&truth, 200.0 / 3.0, 0.0), phase_of(&truth, 100.0, 0.0));
        let sets = [
            SetPhase { period_px: 200.0 / 3.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
            SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &b, phase_sigma_rad: &sigma },
        ];
        let p = absolute_coordinate(&code, 100.0, &sets, &AbsoluteParams::default()).expect("coordinates");
        for (x, t) in p.coordinate_px.iter().zip(&truth) {
            assert!((f64::from(*x) - t).abs() < 1e-3, "{x} for {t}");
        }
        // The noise of two sets of σ 0.01 rad: 0.01/2π of each period, combined.
        let (sa, sb) = (0.01 / TAU * 200.0 / 3.0, 0.01 / TAU * 100.0);
        let combined = 1.0 / (1.0 / (sa * sa) + 1.0 / (sb * sb)).sqrt();
        assert!((f64::from(p.sigma_px[500]) - combined).abs() < 1e-6);
        // The 100 px set ordered by the code alone would be a whole period
        // off somewhere near its edges; the cell's centre is not enough.
        assert!(matches!(
            absolute_coordinate(&code, 100.0, &sets[1..], &AbsoluteParams::default()),
            Err(ProjectorCoordinateError::CellTooCoarse { .. })
        ));
    }

    #[test]
    fn sets_rippled_by_harmonics_are_reported_and_noise_is_not() {
        let (code, truth) = scene(1900, 0.0);
        let sigma = vec![0.05f32; truth.len()];
        let run = |ripple_px: f64| {
            // The short set rippled, the long one not: they part by the ripple.
            let (a, b) = (phase_of(&truth, 200.0 / 3.0, ripple_px), phase_of(&truth, 100.0, 0.0));
            let sets = [
                SetPhase { period_px: 200.0 / 3.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
                SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &b, phase_sigma_rad: &sigma },
            ];
            let p = absolute_coordinate(&code, 100.0, &sets, &AbsoluteParams::default()).expect("coordinates");
            p.set_agreement.expect("two sets")
        };
        let rippled = run(5.0);
        assert!((rippled.rms_px - 5.0 / 2f64.sqrt()).abs() < 0.2, "{rippled:?}");
        let w = rippled.ripple_warning("x").expect("a ripple of 5 px is reported");
        assert_eq!(w.kind, WarningKind::PhaseSetsRipple);
        assert!(w.message.contains("projector x"), "{}", w.message);
        // Noise of 0.05 rad gives 0.5-0.8 px per set; a ripple of a tenth
        // of a pixel is within it.
        let calm = run(0.1);
        assert!(calm.ripple_warning("x").is_none(), "{calm:?}");
    }

    /// The 3-step phase of fringes `((1 + cos(φ + δ)) / 2)^gamma`: a
    /// projector's gamma, the error a function of the phase alone.
    fn three_step_phase_of(x: &[f64], period: f64, gamma: f64) -> Vec<f32> {
        let shifts = [-TAU / 3.0, 0.0, TAU / 3.0];
        x.iter()
            .map(|&x| {
                let phase = TAU * x / period;
                let (mut s, mut c) = (0.0, 0.0);
                for d in shifts {
                    let sample = (0.5 * (1.0 + (phase + d).cos())).powf(gamma);
                    s -= sample * d.sin();
                    c += sample * d.cos();
                }
                s.atan2(c).rem_euclid(TAU) as f32
            })
            .collect()
    }

    #[test]
    fn a_projector_gammas_ripple_is_fitted_from_two_sets_and_taken_out() {
        let (code, truth) = scene(1900, 0.3);
        let sigma = vec![0.01f32; truth.len()];
        let run = |gamma: f64| {
            let (a, b) = (three_step_phase_of(&truth, 200.0 / 3.0, gamma), three_step_phase_of(&truth, 100.0, gamma));
            let sets = [
                SetPhase { period_px: 200.0 / 3.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
                SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &b, phase_sigma_rad: &sigma },
            ];
            absolute_coordinate(&code, 100.0, &sets, &AbsoluteParams::default()).expect("coordinates")
        };
        let worst = |p: &ProjectorCoordinate| {
            p.coordinate_px.iter().zip(&truth).map(|(x, t)| (f64::from(*x) - t).abs()).fold(0.0, f64::max)
        };
        // Gamma 2.2 ripples the 100 px set by about 5 px; what is left is
        // a hundredth of that.
        let p = run(2.2);
        let ripple = p.ripple.expect("fitted");
        assert!(ripple.peak_px() > 4.0 && ripple.rms_before_px > 2.0, "{ripple:?}");
        assert!(worst(&p) < 0.02, "{} px off after the correction", worst(&p));
        assert_eq!(p.lit_and_measured(), (1900, 1900));
        let warnings = p.ripple_warnings("x");
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].message.contains("was taken out"), "{}", warnings[0]);
        // A linear projector: nothing to take out, nothing said.
        let p = run(1.0);
        assert!(worst(&p) < 1e-3 && p.ripple_warnings("x").is_empty(), "{:?}", p.ripple);
    }

    #[test]
    fn a_cell_decoded_one_off_at_its_edge_still_gives_the_right_coordinate() {
        let (mut code, truth) = scene(1000, 0.0);
        // Pixels 3 px either side of each edge read the neighbouring cell.
        for (i, t) in truth.iter().enumerate() {
            let into_cell = t.rem_euclid(100.0);
            if let Ok(c) = code.cells[i] {
                if into_cell < 3.0 && c > 0 {
                    code.cells[i] = Ok(c - 1);
                } else if into_cell > 97.0 && c < 9 {
                    code.cells[i] = Ok(c + 1);
                }
            }
        }
        let sigma = vec![0.02f32; truth.len()];
        let (a, b) = (phase_of(&truth, 200.0 / 3.0, 2.0), phase_of(&truth, 100.0, 2.0));
        let sets = [
            SetPhase { period_px: 200.0 / 3.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
            SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &b, phase_sigma_rad: &sigma },
        ];
        let p = absolute_coordinate(&code, 100.0, &sets, &AbsoluteParams::default()).expect("coordinates");
        let worst = p.coordinate_px.iter().zip(&truth).map(|(x, t)| (f64::from(*x) - t).abs()).fold(0.0, f64::max);
        assert!(worst < 3.0, "{worst} px off (the ripple is 2 px)");
        assert_eq!(p.lit_and_measured(), (1000, 1000));
    }

    #[test]
    fn a_set_a_period_off_a_missing_phase_and_a_wrong_cell_are_refused() {
        let (mut code, truth) = scene(600, 0.0);
        let sigma = vec![0.01f32; truth.len()];
        let a = phase_of(&truth, 200.0 / 3.0, 0.0);
        let mut b = phase_of(&truth, 100.0, 0.0);
        // Pixel 150: the 100 px set's phase half a turn off (a sampling
        // error that moves it 50 px).
        b[150] = (f64::from(b[150]) + TAU / 2.0).rem_euclid(TAU) as f32;
        // Pixel 250: no phase. Pixel 330: the next cell, 70 px from the edge.
        let mut a = a;
        a[250] = f32::NAN;
        code.cells[330] = Ok(4);
        let sets = [
            SetPhase { period_px: 200.0 / 3.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
            SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &b, phase_sigma_rad: &sigma },
        ];
        let p = absolute_coordinate(&code, 100.0, &sets, &AbsoluteParams::default()).expect("coordinates");
        // (Its beat moves by 100 px too: whichever check sees it first.)
        assert!(
            matches!(p.refusal[150], Some(CoordinateRefusal::SetsDisagree | CoordinateRefusal::OutsideCell)),
            "{:?}",
            p.refusal[150]
        );
        assert_eq!(p.refusal[250], Some(CoordinateRefusal::NoPhase));
        assert_eq!(p.refusal[330], Some(CoordinateRefusal::OutsideCell), "{}", p.coordinate_px[330]);
        assert!(p.coordinate_px[150].is_nan() && p.coordinate_px[250].is_nan() && p.coordinate_px[330].is_nan());
        let refused: usize = p.refusal_counts().iter().map(|(_, n)| n).sum();
        assert_eq!(refused, 3);
        // Every other pixel is exact.
        for (i, (x, t)) in p.coordinate_px.iter().zip(&truth).enumerate() {
            if ![150, 250, 330].contains(&i) {
                assert!((f64::from(*x) - t).abs() < 1e-3, "pixel {i}: {x} for {t}");
            }
        }
    }

    #[test]
    fn mismatched_sets_are_errors_not_pixels() {
        let (code, truth) = scene(300, 0.0);
        let short = vec![0.0f32; 10];
        let sigma = vec![0.01f32; truth.len()];
        let a = phase_of(&truth, 100.0, 0.0);
        let bad = [SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &short, phase_sigma_rad: &short }];
        assert!(matches!(
            absolute_coordinate(&code, 1.0, &bad, &AbsoluteParams::default()),
            Err(ProjectorCoordinateError::SetSize { .. })
        ));
        let same = [
            SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
            SetPhase { period_px: 100.0, shifts: 3, wrapped_phase_rad: &a, phase_sigma_rad: &sigma },
        ];
        assert!(matches!(
            absolute_coordinate(&code, 1.0, &same, &AbsoluteParams::default()),
            Err(ProjectorCoordinateError::NoBeat { .. })
        ));
        assert!(matches!(
            absolute_coordinate(&code, 1.0, &[], &AbsoluteParams::default()),
            Err(ProjectorCoordinateError::SetCount { sets: 0 })
        ));
    }
}
