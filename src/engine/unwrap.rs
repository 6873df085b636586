//! Hierarchical temporal phase unwrapping (Alg. 3, first loop) with a
//! fringe-order check decided by evidence.
//!
//! The paper unwraps set m from set m-1:
//! `k^m = round((Phi^{m-1} per^{m-1}/per^m - phi^m) / 2 pi)`,
//! `Phi^m = phi^m + 2 pi k^m`. It leaves open what happens where an
//! intermediate set is unusable (over-saturated or dark): there the chain
//! would run through garbage. Here each set is unwrapped from the densest
//! sparser set that *is* usable at that pixel (the reference).
//!
//! Whether the rounded order is right is a probability. With the reference's
//! error scaled to this period, `sigma_e = sqrt((r sigma_ref)^2 + sigma_m^2)`
//! (`r = per_ref / per_m`, both sigmas from the measured noise), the order is
//! wrong when the error exceeds pi: `P = erfc(pi / (sigma_e sqrt 2))`.
//! [`OrderCheck::Evidence`] (the default) decides in three tiers:
//!
//! - **own**: `P <= 1e-6` and the residual `e = Phi_ref r - Phi^m` is
//!   consistent with `sigma_e` (`|e| <= max(5 sigma_e, pi / 4)`): accepted
//!   on the pixel's own samples;
//! - **ambiguous**: `P <= 5 %`: accepted only when the neighbourhood on the
//!   same surface confirms the order. Spatially the order is known from any
//!   decided neighbour whose wrapped phase continues into this pixel
//!   (`|wrap(phi_p - phi_q)| <= 2 pi / 3`): the pixel is confirmed when at
//!   least one such neighbour implies the same order and none implies another
//!   (two independent witnesses, temporal and spatial, must agree), and refused
//!   as contradicted when they disagree (then the sparser set, whose order is
//!   decided, fills in: the rounding error is expected at the rate `P` states,
//!   it is no disagreement between the sets). A patch of ambiguous pixels that
//!   touches no decided pixel is unwrapped spatially as a whole and its order
//!   taken from the mean residual against the reference over the patch,
//!   whose uncertainty falls with the patch's size: a patch with one wrong
//!   order looks smooth inside, but not against the sparser set's phase.
//!   A pixel that neither decides (a lone valid pixel on a dim face), and
//!   any pixel whose own `P` exceeds 5 %, is decided against the sparser
//!   set's phase smoothed by a weighted plane over its 7x7 neighbourhood,
//!   when that neighbourhood lies on one plane within its noise and the
//!   smoothed reference makes the order unambiguous (`P <= 1e-6`);
//! - **undecidable**: `P > 5 %` and the smoothed reference does not decide
//!   either: this set is not used at the pixel (no flag: nothing disagrees,
//!   the densest sparser set fills in as for over-saturation).
//!
//! The sparsest set is taken as absolute, which it is only while its phase
//! stays inside `[0, 2 pi)`: in evidence mode a pixel that noise may have
//! carried across either end gets its side from its neighbourhood, or is
//! not used (see `settle_root`).
//!
//! [`OrderCheck::Strict`] is the rule of earlier versions (every pixel must be
//! unambiguous on its own, `sigma_e <= pi / 5`); [`OrderCheck::Off`] takes the
//! rounded order as the paper does. A set that fails is flagged at that pixel
//! and not used, neither as a source nor as a reference; fusion then refuses
//! to fall back past a flagged set, because the disagreement cannot be
//! attributed to one of the two sets.

use std::collections::VecDeque;
use std::f64::consts::{PI, SQRT_2, TAU};
use std::hint::select_unpredictable;

use rayon::prelude::*;

use super::buffers::filled;
use super::control::{Cancelled, RunControl};
use super::phase_shift::WrappedPhase;
use super::simd;

/// How fringe orders are accepted (`--order-check`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OrderCheck {
    /// Every order must be unambiguous on its own pixel (`sigma_e <= pi/5`);
    /// ambiguous pixels are refused. The rule of Sheen 0.1.
    Strict,
    /// Unambiguous orders on their own, ambiguous ones when the neighbourhood
    /// or the patch confirms them (module docs).
    #[default]
    Evidence,
    /// The paper's rule: the rounded order, no plausibility test (an
    /// unusable intermediate set is still skipped).
    Off,
}

impl OrderCheck {
    pub const ALL: [OrderCheck; 3] = [OrderCheck::Strict, OrderCheck::Evidence, OrderCheck::Off];

    pub fn name(self) -> &'static str {
        match self {
            OrderCheck::Strict => "strict",
            OrderCheck::Evidence => "evidence",
            OrderCheck::Off => "off",
        }
    }

    /// The predicted order error (rad) above which a set pair is warned about.
    pub fn warning_sigma_rad(self) -> f64 {
        match self {
            OrderCheck::Strict => MAX_ORDER_SIGMA_RAD,
            OrderCheck::Evidence | OrderCheck::Off => AMBIGUOUS_ORDER_SIGMA_RAD,
        }
    }
}

impl std::str::FromStr for OrderCheck {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        OrderCheck::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown order check '{s}': expected strict, evidence or off"))
    }
}

impl std::fmt::Display for OrderCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Strict rule: largest predicted unwrapping error (rad) at which an order is trusted.
pub const MAX_ORDER_SIGMA_RAD: f64 = PI / 5.0;
/// Residuals up to this many predicted sigmas are plausible...
pub const ORDER_RESIDUAL_SIGMAS: f64 = 5.0;
/// ...and never fewer than this (quantisation, model error of real fringes).
pub const MIN_ORDER_RESIDUAL_RAD: f64 = PI / 4.0;

/// Evidence rule: a wrong order at most this probable is accepted on the pixel alone.
pub const OWN_WRONG_ORDER_PROBABILITY: f64 = 1e-6;
/// Evidence rule: a wrong order at most this probable is accepted when the
/// neighbourhood confirms it; beyond, the set is not used at the pixel.
pub const AMBIGUOUS_WRONG_ORDER_PROBABILITY: f64 = 0.05;
/// `sigma_e` of [`OWN_WRONG_ORDER_PROBABILITY`]: pi / 4.8916 (standard normal
/// two-sided quantile of 1e-6).
pub const OWN_ORDER_SIGMA_RAD: f64 = PI / 4.891_638;
/// `sigma_e` of [`AMBIGUOUS_WRONG_ORDER_PROBABILITY`]: pi / 1.95996.
pub const AMBIGUOUS_ORDER_SIGMA_RAD: f64 = PI / 1.959_964;
/// Neighbours whose wrapped phases differ by more than this are not taken to
/// lie on one continuous surface (the densest fringes advance at most about
/// 1 rad per pixel; noise adds a few tenths).
pub const CONTINUITY_RAD: f64 = TAU / 3.0;
/// A patch decided by its mean residual needs at least this many pixels...
pub const MIN_PATCH_PIXELS: usize = 24;
/// ...and its mean is credited with at most this many independent pixels,
/// since a sparser set's error is partly shared by neighbours (defocus,
/// harmonics of the projector's gamma).
pub const PATCH_INDEPENDENT_PIXELS: usize = 64;
/// Share of a patch's pixels whose own rounded order must equal the patch's.
pub const PATCH_AGREEMENT: f64 = 0.9;

/// How the order of a set at a pixel was decided (2 bits per set in
/// [`Unwrapped::order_evidence`], the highest along the reference chain).
pub const EVIDENCE_OWN: u8 = 0;
/// Confirmed by decided neighbours on the same surface.
pub const EVIDENCE_NEIGHBOURS: u8 = 1;
/// Confirmed against the sparser set's phase averaged over an area: the mean
/// residual of its patch, or the plane through its neighbourhood.
pub const EVIDENCE_PATCH: u8 = 2;

/// Probability that rounding picks a wrong fringe order when the predicted
/// phase has Gaussian error `sigma_e_rad`: `P(|e| > pi)`.
pub fn wrong_order_probability(sigma_e_rad: f64) -> f64 {
    if !(sigma_e_rad > 0.0) {
        return 0.0;
    }
    erfc(PI / (sigma_e_rad * SQRT_2))
}

/// Probability that the order next to the rounded one is the right one,
/// given the observed residual `e` (|e| <= pi) and Gaussian error `sigma_e`:
/// the likelihood ratio of `e` against `2 pi - |e|`.
pub fn adjacent_order_probability(residual_rad: f64, sigma_e_rad: f64) -> f64 {
    let e = residual_rad.abs();
    let log_ratio = (TAU - e).powi(2).mul_add(0.5, -0.5 * e * e) / (sigma_e_rad * sigma_e_rad);
    1.0 / (1.0 + log_ratio.exp())
}

/// Complementary error function (Numerical Recipes' Chebyshev fit, relative
/// error below 1.2e-7), enough for the probabilities quoted in reports.
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// Per-set results of the unwrapping, for the sets given (sparsest first).
#[derive(Clone, Debug)]
pub struct Unwrapped {
    /// `Phi^m` in radians of set m's own period; NaN where not unwrapped.
    pub unwrapped_phase_rad: Vec<Vec<f32>>,
    /// Bit m set: set m's fringe order failed the check at this pixel.
    pub order_flags: Vec<u16>,
    /// Bit m set: set m's ambiguous order was contradicted by its continuous
    /// neighbours or its patch at this pixel (refused; a sparser set fills
    /// in). Empty unless the evidence check contradicted some pixel. A pixel
    /// of set m with both phases, unwrapped from nothing and neither flagged
    /// nor contradicted, was left undecided.
    pub order_contradicted: Vec<u16>,
    /// Bits `2m..2m+2`: how set m's order (and its references') was decided,
    /// `EVIDENCE_*`; meaningful where set m is unwrapped.
    pub order_evidence: Vec<u32>,
    /// Per set: pixels unwrapped, and pixels whose order was flagged.
    pub unwrapped_count: Vec<usize>,
    pub order_failures: Vec<usize>,
    /// Per set: pixels whose own order was confirmed by neighbours or by its patch.
    pub confirmed_by_neighbours: Vec<usize>,
    pub confirmed_by_patch: Vec<usize>,
    /// Per set: pixels with both phases whose order could not be decided
    /// (ambiguous and unconfirmed, or beyond the ambiguity limit): the set is
    /// not used there, and a sparser one fills in.
    pub undecided: Vec<usize>,
    /// Per set: ambiguous pixels whose order their continuous neighbours (or
    /// their patch) contradicted: refused, and a sparser set fills in.
    pub contradicted: Vec<usize>,
    pub check: OrderCheck,
    /// [`root_wrap_fraction`] of the sparsest set.
    pub root_wrap_fraction: f64,
}

impl Unwrapped {
    /// How set `m`'s order at `pixel` was decided (`EVIDENCE_*`).
    pub fn evidence(&self, m: usize, pixel: usize) -> u8 {
        self.order_evidence.get(pixel).map_or(EVIDENCE_OWN, |e| ((e >> (2 * m)) & 3) as u8)
    }
}

/// At most this many sets take part in one unwrapping (bits of `order_flags`).
pub const MAX_SETS: usize = 16;

/// Pixel states of one set during the evidence pass.
const NONE: u8 = 0;
const DECIDED: u8 = 1;
const CANDIDATE: u8 = 2;
const CONTRADICTED: u8 = 3;
const BY_NEIGHBOURS: u8 = 4;
const BY_PATCH: u8 = 5;

/// Pixel states of one set that only the final tally reads.
const FLAGGED: u8 = 6;
const UNDECIDED: u8 = 7;

/// One pixel's order decision for one set against its reference (the densest
/// decided sparser set at the pixel).
#[derive(Clone, Copy)]
struct OrderDecision {
    phase: f64,
    residual: f64,
    sigma_e: f64,
    has: bool,
    decided: bool,
    flagged: bool,
    candidate: bool,
}

impl OrderDecision {
    #[inline(always)]
    fn state(self) -> u8 {
        if self.decided {
            DECIDED
        } else if self.candidate {
            CANDIDATE
        } else if self.flagged {
            FLAGGED
        } else if self.has {
            UNDECIDED
        } else {
            NONE
        }
    }
}

/// The reference a pixel's next set is unwrapped from.
#[derive(Clone, Copy)]
struct Reference {
    phase_rad: f64,
    period_px: f64,
    sigma_rad: f64,
    /// Highest `EVIDENCE_*` along the chain that decided the reference.
    evidence: u8,
}

impl Reference {
    fn decide(self, phi: f64, sigma_m: f64, period: f64, check: OrderCheck) -> OrderDecision {
        decide_order(self.phase_rad, self.period_px, self.sigma_rad, phi, sigma_m, period, check)
    }
}

/// Alg. 3's order `k = round((Phi_ref r - phi) / 2 pi)` and the tiers of
/// [`OrderCheck`] (module docs) for one pixel.
#[inline(always)]
fn decide_order(
    ref_phase_rad: f64,
    ref_period_px: f64,
    ref_sigma_rad: f64,
    phi: f64,
    sigma_m: f64,
    period: f64,
    check: OrderCheck,
) -> OrderDecision {
    // The reference is NaN exactly where no sparser set is decided.
    let has = !(ref_phase_rad.is_nan() || phi.is_nan());
    let ratio = ref_period_px / period;
    let predicted = ref_phase_rad * ratio;
    let order = ((predicted - phi) * (1.0 / TAU)).round();
    let phase = phi + TAU * order;
    let residual = predicted - phase;
    let sigma_e = ((ratio * ref_sigma_rad).powi(2) + sigma_m * sigma_m).sqrt();
    let consistent = residual.abs() <= (ORDER_RESIDUAL_SIGMAS * sigma_e).max(MIN_ORDER_RESIDUAL_RAD);
    let (decided, flagged, candidate) = match check {
        OrderCheck::Off => (has, false, false),
        OrderCheck::Strict => {
            let ok = has && sigma_e <= MAX_ORDER_SIGMA_RAD && consistent;
            (ok, has && !ok, false)
        }
        OrderCheck::Evidence => {
            let own = sigma_e <= OWN_ORDER_SIGMA_RAD;
            // The residual itself is evidence too: near pi the next order
            // explains the samples as well, and neighbours alone would then
            // decide; such a pixel is left to the sparser set.
            // `adjacent_order_probability <= 5 %` without the exponential:
            // its log-odds `2 pi (pi - |e|) / sigma_e^2` at least ln 19.
            let candidate = has
                && !own
                && sigma_e <= AMBIGUOUS_ORDER_SIGMA_RAD
                && TAU * (PI - residual.abs()) >= AMBIGUOUS_LOG_ODDS * sigma_e * sigma_e;
            (has && own && consistent, has && own && !consistent, candidate)
        }
    };
    OrderDecision { phase, residual, sigma_e, has, decided, flagged, candidate }
}

/// `ln((1 - P) / P)` of [`AMBIGUOUS_WRONG_ORDER_PROBABILITY`]: ln 19.
const AMBIGUOUS_LOG_ODDS: f64 = 2.944_438_979_166_440_3;

/// Unwraps `sets` (sparsest first; the first must hold a single fringe over
/// the field, so its wrapped phase is already absolute).
///
/// Every pixel's own decision for every set is made in one row-parallel pass
/// (a tile of a row walks all sets, the reference in registers); in evidence
/// mode the candidates of each set are then settled by their neighbourhood,
/// sparsest first, and where one is confirmed the denser sets' decisions at
/// that pixel are made again from it. The result is the same as deciding set
/// by set over full-size reference maps, at the memory traffic of one pass.
pub fn unwrap_hierarchical(
    sets: &[&WrappedPhase],
    check: OrderCheck,
    control: &RunControl,
) -> Result<Unwrapped, Cancelled> {
    assert!(!sets.is_empty() && sets.len() <= MAX_SETS, "1..=16 sets");
    let m_count = sets.len();
    let root = sets[0];
    let len = root.wrapped_phase_rad.len();
    let width = root.width.max(1);
    let height = len / width;
    let evidence_mode = check == OrderCheck::Evidence;
    // A sparsest set that wraps inside the field is not absolute anyway (the
    // run warns); deciding its side of a wrap would only cut pixels there.
    let root_wraps = root_wrap_fraction(root);
    let root_settled = if evidence_mode && root_wraps <= ROOT_WRAP_WARNING_FRACTION {
        settle_root(root, width)
    } else {
        RootSettled { phase_rad: root.wrapped_phase_rad.clone(), settled: Vec::new(), undecided: 0 }
    };
    let mut evidence = filled(len, 0u32);
    for &p in &root_settled.settled {
        evidence[p] = u32::from(EVIDENCE_PATCH);
    }
    let root_count = root_settled.phase_rad.par_chunks(width).map(valid_count).sum();
    let mut unwrapped: Vec<Vec<f32>> = Vec::with_capacity(m_count);
    unwrapped.push(root_settled.phase_rad);
    // Every element is written by the row kernel; the fill only makes the
    // vectors, on all cores.
    unwrapped.extend((1..m_count).map(|_| filled(len, 0f32)));
    let mut flags = filled(len, 0u16);
    // Per-set evidence-pass states (the sparsest set's unused).
    let states_len = if evidence_mode { len } else { 0 };
    let mut states: Vec<Vec<u8>> = (0..m_count).map(|m| filled(if m == 0 { 0 } else { states_len }, NONE)).collect();
    let kernel_counts = first_pass(sets, check, &mut unwrapped, &mut flags, &mut evidence, &mut states, width, control);
    control.check()?;

    let mut counts = kernel_counts;
    if evidence_mode {
        for m in 1..m_count {
            control.check()?;
            if counts[m].candidates == 0 && counts[m].undecided == 0 {
                continue;
            }
            let candidates = pixels_in_state(&states[m], CANDIDATE);
            let undecided = pixels_in_state(&states[m], UNDECIDED);
            let field = Field { width, height, wrapped: &sets[m].wrapped_phase_rad };
            let (sparser, rest) = unwrapped.split_at_mut(m);
            let (out, denser) = rest.split_first_mut().expect("set m");
            let (state_sparser, state_rest) = states.split_at_mut(m);
            let (state, state_denser) = state_rest.split_first_mut().expect("set m");
            let neighbourhood = Neighbourhood { sets, m, sparser, state_sparser, width, height };
            // sigma_e and residual of a candidate, from its reference (the
            // densest decided sparser set): needed only inside patches.
            let order_error = |p: usize| -> (f64, f64) {
                let reference = neighbourhood.reference_set(p);
                let r = Reference {
                    phase_rad: f64::from(sparser[reference][p]),
                    period_px: sets[reference].period_px,
                    sigma_rad: f64::from(sets[reference].phase_sigma_rad[p]),
                    evidence: 0,
                };
                let set = sets[m];
                let d = r.decide(
                    f64::from(set.wrapped_phase_rad[p]),
                    f64::from(set.phase_sigma_rad[p]),
                    set.period_px,
                    check,
                );
                (d.sigma_e, d.residual)
            };
            decide_by_evidence(&field, state, out, &order_error, &candidates, control)?;
            decide_by_smoothed_reference(&neighbourhood, state, out, &candidates, check);
            decide_by_smoothed_reference(&neighbourhood, state, out, &undecided, check);
            let mut denser_maps = DenserMaps { unwrapped: denser, state: state_denser };
            let mut maps =
                SettleMaps { state, out, flags: &mut flags, evidence: &mut evidence, counts: &mut counts[m..] };
            settle(sets, m, &candidates, CANDIDATE, &mut maps, &mut denser_maps, check);
            settle(sets, m, &undecided, UNDECIDED, &mut maps, &mut denser_maps, check);
        }
    }
    control.check()?;
    let mut contradicted_bits = Vec::new();
    for m in (1..m_count).filter(|&m| counts[m].contradicted > 0) {
        contradicted_bits.resize(len, 0u16);
        for p in pixels_in_state(&states[m], CONTRADICTED) {
            contradicted_bits[p] |= 1 << m;
        }
    }
    let mut unwrapped_count = vec![root_count];
    unwrapped_count.extend(counts[1..].iter().map(|c| c.decided));
    let mut confirmed_by_patch = vec![root_settled.settled.len()];
    confirmed_by_patch.extend(counts[1..].iter().map(|c| c.by_patch));
    let mut undecided = vec![root_settled.undecided];
    undecided.extend(counts[1..].iter().map(|c| c.undecided));
    Ok(Unwrapped {
        unwrapped_phase_rad: unwrapped,
        order_flags: flags,
        order_contradicted: contradicted_bits,
        order_evidence: evidence,
        unwrapped_count,
        order_failures: counts.iter().map(|c| c.flagged).collect(),
        confirmed_by_neighbours: counts.iter().map(|c| c.by_neighbours).collect(),
        confirmed_by_patch,
        undecided,
        contradicted: counts.iter().map(|c| c.contradicted).collect(),
        check,
        root_wrap_fraction: root_wraps,
    })
}

/// Per-set pixel counts by state (`candidates` are pending the evidence pass).
#[derive(Clone, Copy, Default)]
struct PassCounts {
    decided: usize,
    flagged: usize,
    undecided: usize,
    candidates: usize,
    contradicted: usize,
    by_neighbours: usize,
    by_patch: usize,
}

impl PassCounts {
    fn add(self, o: Self) -> Self {
        Self {
            decided: self.decided + o.decided,
            flagged: self.flagged + o.flagged,
            undecided: self.undecided + o.undecided,
            candidates: self.candidates + o.candidates,
            contradicted: self.contradicted + o.contradicted,
            by_neighbours: self.by_neighbours + o.by_neighbours,
            by_patch: self.by_patch + o.by_patch,
        }
    }

    /// The counter of `state`; confirmed pixels count as decided as well.
    fn counters(&mut self, state: u8) -> [Option<&mut usize>; 2] {
        match state {
            DECIDED => [Some(&mut self.decided), None],
            BY_NEIGHBOURS => [Some(&mut self.decided), Some(&mut self.by_neighbours)],
            BY_PATCH => [Some(&mut self.decided), Some(&mut self.by_patch)],
            FLAGGED => [Some(&mut self.flagged), None],
            UNDECIDED => [Some(&mut self.undecided), None],
            CANDIDATE => [Some(&mut self.candidates), None],
            CONTRADICTED => [Some(&mut self.contradicted), None],
            _ => [None, None],
        }
    }

    /// A pixel of this set moved from state `from` to `to`.
    fn moved(&mut self, from: u8, to: u8) {
        self.counters(from).into_iter().flatten().for_each(|c| *c -= 1);
        self.counters(to).into_iter().flatten().for_each(|c| *c += 1);
    }
}

/// Indices of the pixels in `wanted` state, ascending.
fn pixels_in_state(state: &[u8], wanted: u8) -> Vec<usize> {
    const CHUNK: usize = 1 << 16;
    let parts: Vec<Vec<usize>> = state
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| chunk.iter().enumerate().filter(|&(_, &s)| s == wanted).map(|(i, _)| c * CHUNK + i).collect())
        .collect();
    parts.concat()
}

/// One image row of every map the first pass writes.
struct RowTask<'a> {
    row: usize,
    outs: Vec<&'a mut [f32]>,
    flags: &'a mut [u16],
    evidence: &'a mut [u32],
    state: Vec<&'a mut [u8]>,
}

/// Splits each of `maps` into its rows (empty rows for empty maps).
fn rows_of<T>(maps: &mut [Vec<T>], width: usize, rows: usize) -> Vec<std::vec::IntoIter<&mut [T]>> {
    maps.iter_mut()
        .map(|v| {
            let r: Vec<&mut [T]> = if v.is_empty() {
                (0..rows).map(|_| Default::default()).collect()
            } else {
                v.chunks_mut(width).collect()
            };
            r.into_iter()
        })
        .collect()
}

fn next_rows<'a, T>(rows: &mut [std::vec::IntoIter<&'a mut [T]>]) -> Vec<&'a mut [T]> {
    rows.iter_mut().map(|it| it.next().expect("one row per map")).collect()
}

/// Every pixel's own decision for every set, row parallel.
#[allow(clippy::too_many_arguments)]
fn first_pass(
    sets: &[&WrappedPhase],
    check: OrderCheck,
    unwrapped: &mut [Vec<f32>],
    flags: &mut [u16],
    evidence: &mut [u32],
    states: &mut [Vec<u8>],
    width: usize,
    control: &RunControl,
) -> Vec<PassCounts> {
    let m_count = sets.len();
    let rows = flags.len() / width;
    let mut out_rows = rows_of(unwrapped, width, rows);
    let mut state_rows = rows_of(states, width, rows);
    let mut tasks: Vec<RowTask<'_>> = Vec::with_capacity(rows);
    for ((row, f), ev) in flags.chunks_mut(width).enumerate().zip(evidence.chunks_mut(width)) {
        tasks.push(RowTask {
            row,
            outs: next_rows(&mut out_rows),
            flags: f,
            evidence: ev,
            state: next_rows(&mut state_rows),
        });
    }
    tasks
        .par_iter_mut()
        .map(|task| {
            let mut counts = vec![PassCounts::default(); m_count];
            if !control.is_cancelled() {
                decide_row(sets, check, task, &mut counts);
            }
            counts
        })
        .reduce(|| vec![PassCounts::default(); m_count], |a, b| a.into_iter().zip(b).map(|(x, y)| x.add(y)).collect())
}

/// One image row of the first pass, compiled once per order check (the
/// check is then a constant in the pixel loop) and once per instruction set
/// (`simd::dispatch`: with AVX2 rounding and square roots are single
/// instructions instead of library calls; with AVX-512 the comparisons' masks
/// select and store without packing f64 lanes into bytes).
fn decide_row(sets: &[&WrappedPhase], check: OrderCheck, task: &mut RowTask<'_>, counts: &mut [PassCounts]) {
    match check {
        OrderCheck::Strict => decide_row_for::<CHECK_STRICT>(sets, task, counts),
        OrderCheck::Evidence => decide_row_for::<CHECK_EVIDENCE>(sets, task, counts),
        OrderCheck::Off => decide_row_for::<CHECK_OFF>(sets, task, counts),
    }
}

const CHECK_STRICT: u8 = 0;
const CHECK_EVIDENCE: u8 = 1;
const CHECK_OFF: u8 = 2;

fn decide_row_for<const CHECK: u8>(sets: &[&WrappedPhase], task: &mut RowTask<'_>, counts: &mut [PassCounts]) {
    simd::dispatch(
        #[inline(always)]
        || decide_row_generic::<CHECK>(sets, task, counts),
    );
}

#[inline(always)]
fn decide_row_generic<const CHECK: u8>(sets: &[&WrappedPhase], task: &mut RowTask<'_>, counts: &mut [PassCounts]) {
    // Set-outer, pixel-inner over tiles of the row: each set's maps stream
    // through once while the tile's references stay in cache.
    const TILE: usize = 256;
    let check = match CHECK {
        CHECK_STRICT => OrderCheck::Strict,
        CHECK_EVIDENCE => OrderCheck::Evidence,
        _ => OrderCheck::Off,
    };
    let evidence_mode = CHECK == CHECK_EVIDENCE;
    let width = task.flags.len();
    let offset = task.row * width;
    let mut t0 = 0;
    while t0 < width {
        let n = TILE.min(width - t0);
        // The tile's references, one array per field so the pixel loop vectorises.
        let mut ref_phase = [0f64; TILE];
        let mut ref_period = [0f64; TILE];
        let mut ref_sigma = [0f64; TILE];
        let mut ref_level = [0u32; TILE];
        let root_phase = &task.outs[0][t0..t0 + n];
        let root_sigma = &sets[0].phase_sigma_rad[offset + t0..offset + t0 + n];
        let root_level = &task.evidence[t0..t0 + n];
        for j in 0..n {
            ref_phase[j] = f64::from(root_phase[j]);
            ref_period[j] = sets[0].period_px;
            ref_sigma[j] = f64::from(root_sigma[j]);
            ref_level[j] = root_level[j] & 3;
        }
        for (m, set) in sets.iter().enumerate().skip(1) {
            let wrapped = &set.wrapped_phase_rad[offset + t0..offset + t0 + n];
            let sigma = &set.phase_sigma_rad[offset + t0..offset + t0 + n];
            let out = &mut task.outs[m][t0..t0 + n];
            let flags = &mut task.flags[t0..t0 + n];
            let evidence = &mut task.evidence[t0..t0 + n];
            let state: &mut [u8] = if evidence_mode { &mut task.state[m][t0..t0 + n] } else { &mut [] };
            let period = set.period_px;
            let shift = 2 * m as u32;
            let (mut decided, mut flagged, mut undecided, mut candidates) = (0usize, 0usize, 0usize, 0usize);
            for j in 0..n {
                let (phi, sigma_m) = (f64::from(wrapped[j]), f64::from(sigma[j]));
                let d = decide_order(ref_phase[j], ref_period[j], ref_sigma[j], phi, sigma_m, period, check);
                let used = d.decided || d.candidate;
                out[j] = if used { d.phase as f32 } else { f32::NAN };
                flags[j] |= u16::from(d.flagged) << m;
                // A candidate carries its reference's level until it is settled.
                // Selects, not `if`s: LLVM made those masked stores, which on
                // AMD cores cost more than a blend and a store.
                evidence[j] |= select_unpredictable(used, ref_level[j] << shift, 0);
                ref_phase[j] = select_unpredictable(d.decided, d.phase, ref_phase[j]);
                ref_period[j] = select_unpredictable(d.decided, period, ref_period[j]);
                ref_sigma[j] = select_unpredictable(d.decided, sigma_m, ref_sigma[j]);
                if evidence_mode {
                    state[j] = d.state();
                }
                decided += usize::from(d.decided);
                flagged += usize::from(d.flagged);
                undecided += usize::from(d.has && !used && !d.flagged);
                candidates += usize::from(d.candidate);
            }
            counts[m] = counts[m].add(PassCounts { decided, flagged, undecided, candidates, ..PassCounts::default() });
        }
        t0 += n;
    }
}

/// The maps of the sets denser than the one being settled.
struct DenserMaps<'a> {
    unwrapped: &'a mut [Vec<f32>],
    state: &'a mut [Vec<u8>],
}
/// The sparsest set after its own order check.
struct RootSettled {
    phase_rad: Vec<f32>,
    /// Pixels whose side of the wrap was taken from their neighbourhood, ascending.
    settled: Vec<usize>,
    /// Pixels left out: neither they nor their neighbourhood tell the side.
    undecided: usize,
}

/// Half-width of the neighbourhood that decides a sparsest-set pixel near the wrap.
const ROOT_NEIGHBOURHOOD_RADIUS: usize = 2;
/// One-sided standard normal quantile of [`OWN_WRONG_ORDER_PROBABILITY`] (1e-6).
const ROOT_CROSSING_SIGMAS: f64 = 4.753_424;

/// The sparsest set is absolute only if its phase stayed in `[0, 2 pi)`: a
/// pixel whose true phase lies just below 2 pi (where the projector's pattern
/// ends) reads just above 0 when the noise carries it across, and the whole
/// chain of denser sets then inherits an order one sparsest period wrong.
/// Such a crossing is likely only for pixels near either end with a large
/// sigma (dim surfaces): for them, the weighted mean of the 5x5
/// neighbourhood's phases, each continued from the pixel (`wrap(phi_q - phi)`),
/// decides on which side the pixel lies, as long as that mean itself is
/// unambiguous (`P <= 1e-6` from its sigma); otherwise the set is not used at
/// the pixel. A pixel continued past 2 pi keeps its value above 2 pi (its
/// true phase is just below; the noise is above).
fn settle_root(root: &WrappedPhase, width: usize) -> RootSettled {
    let phase = &root.wrapped_phase_rad;
    let sigma = &root.phase_sigma_rad;
    let len = phase.len();
    let height = len / width.max(1);
    // Whether a value with this sigma may have crossed the nearer end of
    // [0, 2 pi): the one-sided tail beyond its distance exceeds 1e-6. The
    // quantile keeps erfc out of the per-pixel loop.
    let may_cross = |value: f64, sigma: f64| -> bool {
        let d = value.min(TAU - value);
        !(d >= ROOT_CROSSING_SIGMAS * sigma)
    };
    let mut phase_rad = phase.clone();
    let width = width.max(1);
    let (settled, undecided) = phase_rad
        .par_chunks_mut(width)
        .enumerate()
        .map(|(y, out)| {
            let (mut confirmed, mut refused) = (Vec::new(), 0usize);
            // The few pixels that may have crossed, found in a branch-free
            // pass that vectorises; a zero sigma (noise-free data) cannot
            // cross. The loop below visits only them.
            let row = y * width..(y + 1) * width;
            let may_have_crossed: Vec<bool> = phase[row.clone()]
                .iter()
                .zip(&sigma[row])
                .map(|(&phi, &sigma_i)| {
                    let (phi, sigma_i) = (f64::from(phi), f64::from(sigma_i));
                    !phi.is_nan() & (sigma_i > 0.0) & may_cross(phi, sigma_i)
                })
                .collect();
            for (x, out) in out.iter_mut().enumerate() {
                if !may_have_crossed[x] {
                    continue;
                }
                let i = y * width + x;
                let (phi, sigma_i) = (f64::from(phase[i]), f64::from(sigma[i]));
                if wrong_order_probability(sigma_i) > AMBIGUOUS_WRONG_ORDER_PROBABILITY {
                    *out = f32::NAN;
                    refused += 1;
                    continue;
                }
                let (mut sum_w, mut sum_wd) = (0.0, 0.0);
                let rows = y.saturating_sub(ROOT_NEIGHBOURHOOD_RADIUS)..(y + ROOT_NEIGHBOURHOOD_RADIUS + 1).min(height);
                for ny in rows {
                    let cols =
                        x.saturating_sub(ROOT_NEIGHBOURHOOD_RADIUS)..(x + ROOT_NEIGHBOURHOOD_RADIUS + 1).min(width);
                    for nx in cols {
                        let q = ny * width + nx;
                        let (phi_q, sigma_q) = (f64::from(phase[q]), f64::from(sigma[q]));
                        if phi_q.is_nan() || !(sigma_q > 0.0) {
                            continue;
                        }
                        let w = 1.0 / (sigma_q * sigma_q);
                        sum_w += w;
                        sum_wd += w * wrap_pi(phi_q - phi);
                    }
                }
                let mean = (phi + sum_wd / sum_w).rem_euclid(TAU);
                if !(sum_w > 0.0) || may_cross(mean, 1.0 / sum_w.sqrt()) {
                    *out = f32::NAN;
                    refused += 1;
                    continue;
                }
                *out = (phi + TAU * ((mean - phi) / TAU).round()) as f32;
                confirmed.push(i);
            }
            (confirmed, refused)
        })
        .reduce(
            || (Vec::new(), 0),
            |(mut a, n), (b, k)| {
                a.extend(b);
                (a, n + k)
            },
        );
    RootSettled { phase_rad, settled, undecided }
}

/// The wrapped phase of the set being decided, as an image.
struct Field<'a> {
    width: usize,
    height: usize,
    wrapped: &'a [f32],
}

impl Field<'_> {
    /// `Phi_q + wrap(phi_p - phi_q)`: the unwrapped phase continuity from
    /// neighbour q predicts for p, when the two lie on one surface.
    #[inline]
    fn continued(&self, p: usize, q: usize, phase_q: f32) -> Option<f64> {
        let d = wrap_pi(f64::from(self.wrapped[p]) - f64::from(self.wrapped[q]));
        (d.abs() <= CONTINUITY_RAD).then(|| f64::from(phase_q) + d)
    }

    fn neighbours8(&self, p: usize) -> impl Iterator<Item = usize> + '_ {
        let (w, h) = (self.width as isize, self.height as isize);
        let (x, y) = ((p % self.width) as isize, (p / self.width) as isize);
        (-1..=1isize)
            .flat_map(move |dy| (-1..=1isize).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| dx != 0 || dy != 0)
            .filter_map(move |(dx, dy)| {
                let (nx, ny) = (x + dx, y + dy);
                (nx >= 0 && ny >= 0 && nx < w && ny < h).then(|| (ny * w + nx) as usize)
            })
    }

    fn neighbours4(&self, p: usize) -> impl Iterator<Item = usize> + '_ {
        self.neighbours8(p).filter(move |&q| q % self.width == p % self.width || q / self.width == p / self.width)
    }
}

fn wrap_pi(x: f64) -> f64 {
    x - TAU * (x * (1.0 / TAU)).round()
}

fn is_decided(state: u8) -> bool {
    matches!(state, DECIDED | BY_NEIGHBOURS | BY_PATCH)
}

/// The evidence pass over one set's candidates: growth from decided pixels,
/// then patches that touch none, then growth again from the patches.
fn decide_by_evidence(
    field: &Field<'_>,
    state: &mut [u8],
    phase: &mut [f32],
    order_error: &dyn Fn(usize) -> (f64, f64),
    candidates: &[usize],
    control: &RunControl,
) -> Result<(), Cancelled> {
    let seeds: Vec<usize> =
        candidates.par_iter().copied().filter(|&p| field.neighbours8(p).any(|q| is_decided(state[q]))).collect();
    grow(field, state, phase, seeds);
    control.check()?;
    let patch_seeds = decide_patches(field, state, phase, order_error, candidates);
    control.check()?;
    let seeds: Vec<usize> = patch_seeds
        .into_iter()
        .flat_map(|p| field.neighbours8(p).collect::<Vec<_>>())
        .filter(|&q| state[q] == CANDIDATE)
        .collect();
    grow(field, state, phase, seeds);
    Ok(())
}

/// Region growing from decided pixels: a candidate whose continuous decided
/// neighbours all imply its own rounded order (at least one does) is
/// confirmed and may confirm its neighbours in turn; one that a continuous
/// decided neighbour contradicts is refused.
fn grow(field: &Field<'_>, state: &mut [u8], phase: &mut [f32], seeds: Vec<usize>) {
    let mut queue: VecDeque<usize> = seeds.into();
    while let Some(p) = queue.pop_front() {
        if state[p] != CANDIDATE {
            continue;
        }
        let (mut agree, mut disagree) = (0u32, 0u32);
        for q in field.neighbours8(p) {
            if !is_decided(state[q]) {
                continue;
            }
            if let Some(continued) = field.continued(p, q, phase[q]) {
                if (continued - f64::from(phase[p])).abs() < PI {
                    agree += 1;
                } else {
                    disagree += 1;
                }
            }
        }
        if disagree > 0 {
            state[p] = CONTRADICTED;
        } else if agree > 0 {
            state[p] = BY_NEIGHBOURS;
            queue.extend(field.neighbours8(p).filter(|&q| state[q] == CANDIDATE));
        }
    }
}

/// Half-width of the neighbourhood (7x7) whose sparser-set phase predicts a
/// pixel that neither neighbours nor a patch could decide.
const REFERENCE_NEIGHBOURHOOD_RADIUS: isize = 3;
/// The neighbourhood's plane needs at least this many reference pixels.
const MIN_REFERENCE_NEIGHBOURS: usize = 12;

/// The sets sparser than `m`, for reading a candidate's neighbourhood.
struct Neighbourhood<'a> {
    sets: &'a [&'a WrappedPhase],
    m: usize,
    sparser: &'a [Vec<f32>],
    state_sparser: &'a [Vec<u8>],
    width: usize,
    height: usize,
}

impl Neighbourhood<'_> {
    /// The densest sparser set decided at `p` (0, the sparsest, if none is).
    fn reference_set(&self, p: usize) -> usize {
        (1..self.m).rev().find(|&k| is_decided(self.state_sparser[k][p])).unwrap_or(0)
    }

    fn decided_in(&self, k: usize, q: usize) -> bool {
        if k == 0 { !self.sparser[0][q].is_nan() } else { is_decided(self.state_sparser[k][q]) }
    }

    /// The reference set's unwrapped phase at `p` from the weighted
    /// least-squares plane through its 7x7 neighbourhood, with the sigma of
    /// that estimate; `None` when too few neighbours have it or when they do
    /// not lie on one plane within their noise (a step, an edge, harmonics).
    fn smoothed_reference(&self, p: usize) -> Option<Reference> {
        let k = self.reference_set(p);
        let (phase, sigma) = (&self.sparser[k], &self.sets[k].phase_sigma_rad);
        let (x, y) = ((p % self.width) as isize, (p / self.width) as isize);
        let centre = f64::from(phase[p]);
        let mut normal = nalgebra::Matrix3::<f64>::zeros();
        let mut rhs = nalgebra::Vector3::<f64>::zeros();
        let mut samples: Vec<(f64, f64, f64, f64)> = Vec::with_capacity(25);
        let r = REFERENCE_NEIGHBOURHOOD_RADIUS;
        for dy in -r..=r {
            for dx in -r..=r {
                let (qx, qy) = (x + dx, y + dy);
                if qx < 0 || qy < 0 || qx >= self.width as isize || qy >= self.height as isize {
                    continue;
                }
                let q = qy as usize * self.width + qx as usize;
                let s = f64::from(sigma[q]);
                if !self.decided_in(k, q) || !(s > 0.0) {
                    continue;
                }
                let (fx, fy, z, w) = (dx as f64, dy as f64, f64::from(phase[q]) - centre, 1.0 / (s * s));
                let row = nalgebra::Vector3::new(1.0, fx, fy);
                normal += w * row * row.transpose();
                rhs += w * z * row;
                samples.push((fx, fy, z, w));
            }
        }
        let n = samples.len();
        if n < MIN_REFERENCE_NEIGHBOURS {
            return None;
        }
        let inverse = normal.try_inverse()?;
        let plane = inverse * rhs;
        // Chi-square of the plane against the stated noise: beyond its mean
        // plus 4 standard deviations the neighbourhood is not one smooth
        // surface of honest noise, and its mean is no evidence.
        let chi2: f64 =
            samples.iter().map(|&(fx, fy, z, w)| w * (z - plane[0] - plane[1] * fx - plane[2] * fy).powi(2)).sum();
        let dof = (n - 3) as f64;
        if !(chi2 <= dof + 4.0 * (2.0 * dof).sqrt()) {
            return None;
        }
        // Neighbours share part of their error (defocus, gamma harmonics):
        // credit at most a patch's worth of independent pixels, as patches do.
        let variance = inverse[(0, 0)].max(f64::from(sigma[p]).powi(2) / PATCH_INDEPENDENT_PIXELS as f64);
        Some(Reference {
            phase_rad: centre + plane[0],
            period_px: self.sets[k].period_px,
            sigma_rad: variance.sqrt(),
            evidence: 0,
        })
    }
}

/// Pixels left undecided by neighbours and patches (a lone valid pixel among
/// invalid ones on a dim face, or one whose own order is beyond the
/// ambiguity limit) are decided again from the sparser set's phase smoothed
/// over their neighbourhood: averaging its noise over
/// the neighbourhood takes `sigma_e` under the own-pixel limit where the
/// pixel's reference alone is ambiguous. The pixel's order must then pass
/// the own-pixel test against that smoothed reference.
fn decide_by_smoothed_reference(
    neighbourhood: &Neighbourhood<'_>,
    state: &mut [u8],
    phase: &mut [f32],
    candidates: &[usize],
    check: OrderCheck,
) {
    let set = neighbourhood.sets[neighbourhood.m];
    let decided: Vec<(usize, f32)> = candidates
        .par_iter()
        .copied()
        .filter(|&p| matches!(state[p], CANDIDATE | UNDECIDED))
        .filter_map(|p| {
            let reference = neighbourhood.smoothed_reference(p)?;
            let d = reference.decide(
                f64::from(set.wrapped_phase_rad[p]),
                f64::from(set.phase_sigma_rad[p]),
                set.period_px,
                check,
            );
            d.decided.then_some((p, d.phase as f32))
        })
        .collect();
    for (p, value) in decided {
        state[p] = BY_PATCH;
        phase[p] = value;
    }
}

/// Patches of candidates that touch no decided pixel: each is unwrapped
/// spatially (breadth first over continuous 4-neighbours), its order offset
/// taken from the inverse-variance weighted mean residual against the
/// reference, and accepted when that mean is unambiguous and nearly every
/// pixel's own rounded order agrees. Returns the confirmed pixels.
fn decide_patches(
    field: &Field<'_>,
    state: &mut [u8],
    phase: &mut [f32],
    order_error: &dyn Fn(usize) -> (f64, f64),
    candidates: &[usize],
) -> Vec<usize> {
    let mut confirmed = Vec::new();
    let mut visited = vec![false; state.len()];
    // Spatially unwrapped phase of the patch being built, by pixel.
    let mut spatial: Vec<(usize, f64)> = Vec::new();
    let mut queue = VecDeque::new();
    for &start in candidates {
        if state[start] != CANDIDATE || visited[start] {
            continue;
        }
        spatial.clear();
        visited[start] = true;
        queue.push_back((start, f64::from(phase[start])));
        while let Some((p, psi)) = queue.pop_front() {
            spatial.push((p, psi));
            for q in field.neighbours4(p) {
                if visited[q] || state[q] != CANDIDATE {
                    continue;
                }
                let d = wrap_pi(f64::from(field.wrapped[q]) - f64::from(field.wrapped[p]));
                if d.abs() <= CONTINUITY_RAD {
                    visited[q] = true;
                    queue.push_back((q, psi + d));
                }
            }
        }
        if spatial.len() < MIN_PATCH_PIXELS {
            continue;
        }
        let (mut sum_w, mut sum_wd, mut sum_var) = (0.0f64, 0.0f64, 0.0f64);
        for &(p, psi) in &spatial {
            let (sigma_e, residual) = order_error(p);
            let s = sigma_e.max(1e-3);
            let w = 1.0 / (s * s);
            // pred - Psi = (Phi_t + e) - Psi.
            let d = f64::from(phase[p]) + residual - psi;
            sum_w += w;
            sum_wd += w * d;
            sum_var += s * s;
        }
        let n = spatial.len();
        let mean = sum_wd / sum_w;
        let order = (mean / TAU).round();
        // Credit at most PATCH_INDEPENDENT_PIXELS independent pixels.
        let sigma_mean = (sum_var / n as f64).sqrt() / (n.min(PATCH_INDEPENDENT_PIXELS) as f64).sqrt();
        let offset_residual = mean - TAU * order;
        let unambiguous = sigma_mean <= OWN_ORDER_SIGMA_RAD
            && offset_residual.abs() <= (ORDER_RESIDUAL_SIGMAS * sigma_mean).max(MIN_ORDER_RESIDUAL_RAD);
        let agrees = |phase: &[f32], p: usize, psi: f64| (psi + TAU * order - f64::from(phase[p])).abs() < PI;
        let agreeing = spatial.iter().filter(|&&(p, psi)| agrees(phase, p, psi)).count();
        if !unambiguous || (agreeing as f64) < PATCH_AGREEMENT * n as f64 {
            continue;
        }
        for &(p, psi) in &spatial {
            if agrees(phase, p, psi) {
                state[p] = BY_PATCH;
                confirmed.push(p);
            } else {
                state[p] = CONTRADICTED;
                phase[p] = f32::NAN;
            }
        }
    }
    confirmed
}

/// Set `m`'s maps while its evidence pass is settled.
struct SettleMaps<'a> {
    state: &'a mut [u8],
    out: &'a mut [f32],
    flags: &'a mut [u16],
    evidence: &'a mut [u32],
    /// Counts of set `m` and the denser sets.
    counts: &'a mut [PassCounts],
}

/// Turns set `m`'s evidence-pass states into results: confirmed pixels join
/// the reference, and the denser sets' decisions there are made again from
/// them; contradicted and unconfirmed ones are left to a sparser set.
fn settle(
    sets: &[&WrappedPhase],
    m: usize,
    pixels: &[usize],
    from: u8,
    maps: &mut SettleMaps<'_>,
    denser: &mut DenserMaps<'_>,
    check: OrderCheck,
) {
    let shift = 2 * m as u32;
    for &p in pixels {
        let state = maps.state[p];
        match state {
            BY_NEIGHBOURS | BY_PATCH => {
                let own = if state == BY_NEIGHBOURS { EVIDENCE_NEIGHBOURS } else { EVIDENCE_PATCH };
                // The first pass left the reference's level in the set's bits.
                let level = own.max(((maps.evidence[p] >> shift) & 3) as u8);
                maps.evidence[p] = (maps.evidence[p] & !(3 << shift)) | (u32::from(level) << shift);
                let reference = Reference {
                    phase_rad: f64::from(maps.out[p]),
                    period_px: sets[m].period_px,
                    sigma_rad: f64::from(sets[m].phase_sigma_rad[p]),
                    evidence: level,
                };
                redecide_denser(sets, m, p, reference, maps, denser, check);
            }
            // An ambiguous order that continuity contradicts is expected at
            // the rate the probability states; it is not a disagreement
            // between the sets (the reference is decided), so the sparser
            // set fills in rather than the pixel being lost.
            CONTRADICTED | CANDIDATE => {
                maps.out[p] = f32::NAN;
                maps.evidence[p] &= !(3 << shift);
                if state == CANDIDATE {
                    maps.state[p] = UNDECIDED;
                }
            }
            _ => {}
        }
        maps.counts[0].moved(from, maps.state[p]);
    }
}

/// Decides the sets denser than `m` at pixel `p` again, from the reference
/// that set `m`'s confirmed order now gives there.
fn redecide_denser(
    sets: &[&WrappedPhase],
    m: usize,
    p: usize,
    mut reference: Reference,
    maps: &mut SettleMaps<'_>,
    denser: &mut DenserMaps<'_>,
    check: OrderCheck,
) {
    for (k, set) in sets.iter().enumerate().skip(m + 1) {
        let i = k - m - 1;
        let sigma_m = f64::from(set.phase_sigma_rad[p]);
        let d = reference.decide(f64::from(set.wrapped_phase_rad[p]), sigma_m, set.period_px, check);
        let shift = 2 * k as u32;
        denser.unwrapped[i][p] = if d.decided || d.candidate { d.phase as f32 } else { f32::NAN };
        maps.flags[p] = (maps.flags[p] & !(1 << k)) | (u16::from(d.flagged) << k);
        let level = if d.decided || d.candidate { u32::from(reference.evidence) } else { 0 };
        maps.evidence[p] = (maps.evidence[p] & !(3 << shift)) | (level << shift);
        maps.counts[k - m].moved(denser.state[i][p], d.state());
        denser.state[i][p] = d.state();
        if d.decided {
            reference = Reference {
                phase_rad: d.phase,
                period_px: set.period_px,
                sigma_rad: sigma_m,
                evidence: reference.evidence,
            };
        }
    }
}

/// Share of rows in which the sparsest set wraps, beyond which it is taken
/// (and warned about) as not absolute.
pub const ROOT_WRAP_WARNING_FRACTION: f64 = 0.05;

/// Share of image rows in which the root set's wrapped phase wraps cleanly
/// (drops by more than pi between neighbours and stays wrapped), which means
/// its period does not cover the field and absolute phase is ambiguous.
pub fn root_wrap_fraction(root: &WrappedPhase) -> f64 {
    let w = root.width;
    if w < 8 || root.height == 0 {
        return 0.0;
    }
    const SIDE: usize = 3;
    let rows_with_valid = std::sync::atomic::AtomicUsize::new(0);
    let wrapped_rows: usize = root
        .wrapped_phase_rad
        .par_chunks(w)
        .map(|row| {
            if valid_count(row) < w / 4 {
                return 0;
            }
            rows_with_valid.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let wraps = (SIDE..w - SIDE).any(|u| {
                let before = &row[u + 1 - SIDE..=u];
                let after = &row[u + 1..=u + SIDE];
                before.iter().all(|&p| f64::from(p) > 1.5 * PI) && after.iter().all(|&p| f64::from(p) < 0.5 * PI)
            });
            usize::from(wraps)
        })
        .sum();
    let valid = rows_with_valid.into_inner();
    if valid == 0 { 0.0 } else { wrapped_rows as f64 / valid as f64 }
}

/// The values of `values` that are not NaN, counted in u32: a `usize` per
/// element (what `filter().count()` sums) holds half as many per SIMD
/// register as the f32 compared.
fn valid_count(values: &[f32]) -> usize {
    values.chunks(1 << 20).map(|block| block.iter().fold(0u32, |n, v| n + u32::from(!v.is_nan())) as usize).sum()
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_residual_near_pi_leaves_the_order_open() {
        // At |e| = pi both orders explain the samples equally well.
        assert!((super::adjacent_order_probability(std::f64::consts::PI, 1.0) - 0.5).abs() < 1e-12);
        // Small residuals leave the adjacent order improbable.
        assert!(super::adjacent_order_probability(0.5, 1.0) < 1e-6);
        assert!(super::adjacent_order_probability(2.9, 1.0) > super::AMBIGUOUS_WRONG_ORDER_PROBABILITY);
    }

    use super::*;

    #[test]
    fn wrong_order_probabilities_match_the_normal_tail() {
        // P(|N(0,1)| > z) for z = 1.96, 3, 4.8916: 5 %, 0.27 %, 1e-6.
        assert!((wrong_order_probability(PI / 1.959_964) - 0.05).abs() < 1e-6);
        assert!((wrong_order_probability(PI / 3.0) - 2.699_8e-3).abs() < 1e-7);
        assert!((wrong_order_probability(OWN_ORDER_SIGMA_RAD) / 1e-6 - 1.0).abs() < 1e-3);
        assert!(
            (wrong_order_probability(AMBIGUOUS_ORDER_SIGMA_RAD) / AMBIGUOUS_WRONG_ORDER_PROBABILITY - 1.0).abs() < 1e-4
        );
        // A real dark scan's case: ratio 4, sigma 0.2 rad in the sparser set.
        let p = wrong_order_probability(0.8);
        assert!(p > 5e-5 && p < 1.5e-4, "{p}");
        assert_eq!(wrong_order_probability(0.0), 0.0);
    }

    #[test]
    fn the_candidate_test_without_the_exponential_is_the_probability_test() {
        // The first pass tests `2 pi (pi - |e|) >= ln 19 sigma_e^2` instead of
        // evaluating the adjacent order's probability at every pixel.
        assert!(
            (AMBIGUOUS_LOG_ODDS - ((1.0 - AMBIGUOUS_WRONG_ORDER_PROBABILITY) / AMBIGUOUS_WRONG_ORDER_PROBABILITY).ln())
                .abs()
                < 1e-15
        );
        for sigma in [0.3, 0.65, 1.0, 1.5] {
            for k in 0..=400 {
                let e = PI * f64::from(k) / 400.0;
                let p = adjacent_order_probability(e, sigma);
                let d = decide_order(0.0, 2.0, 0.0, -e, sigma, 1.0, OrderCheck::Evidence);
                // Away from the boundary itself (rounding), the two agree.
                if (p / AMBIGUOUS_WRONG_ORDER_PROBABILITY - 1.0).abs() > 1e-9 {
                    let ambiguous = sigma > OWN_ORDER_SIGMA_RAD && sigma <= AMBIGUOUS_ORDER_SIGMA_RAD;
                    assert_eq!(d.candidate, ambiguous && p <= AMBIGUOUS_WRONG_ORDER_PROBABILITY, "e {e} sigma {sigma}");
                }
            }
        }
    }

    #[test]
    fn valid_count_counts_every_value_but_nan_across_blocks() {
        let len = (1 << 20) + 1000;
        let values: Vec<f32> = (0..len).map(|i| if i % 7 == 3 { f32::NAN } else { i as f32 - 5.0 }).collect();
        let expected = values.iter().filter(|v| !v.is_nan()).count();
        assert_eq!(valid_count(&values), expected);
        assert_eq!(valid_count(&values[..10]), 9);
        assert_eq!(valid_count(&[]), 0);
        assert_eq!(valid_count(&[f32::INFINITY, f32::NAN, -0.0]), 2);
    }

    #[test]
    fn order_check_names_round_trip() {
        for c in OrderCheck::ALL {
            assert_eq!(c.name().parse::<OrderCheck>(), Ok(c));
        }
        assert!("loose".parse::<OrderCheck>().expect_err("unknown").contains("strict, evidence or off"));
    }

    /// A set with phase `2 pi x / period` (x = column + 5) and the given
    /// per-pixel sigma and phase error.
    fn synthetic_set(
        (w, h): (usize, usize),
        period_px: f64,
        sigma: impl Fn(usize) -> f32,
        error: impl Fn(usize) -> f64,
    ) -> WrappedPhase {
        let phase = |p: usize| (TAU * ((p % w) as f64 + 5.0) / period_px + error(p)).rem_euclid(TAU) as f32;
        WrappedPhase {
            width: w,
            height: h,
            period_px,
            shifts: 8,
            saturation_count: vec![0; w * h],
            wrapped_phase_rad: (0..w * h).map(phase).collect(),
            modulation_dn: vec![50.0; w * h],
            phase_sigma_rad: (0..w * h).map(sigma).collect(),
            offset_dn: None,
            noise: crate::engine::phase_shift::NoiseEstimate {
                sigma_dn: 1.0,
                measured: true,
                pixels: w * h,
                source: crate::engine::phase_shift::NoiseSource::FitResidual,
                harmonic_percent: None,
            },
            stats: crate::engine::phase_shift::SetStats::default(),
        }
    }

    /// One dense pixel whose sparser phase is off by 0.4 rad (4 rad at the
    /// dense period: rounding picks the next order) and uncertain enough to
    /// be ambiguous: its continuous, decided neighbours imply the right
    /// order, so it is contradicted, and marked so for the pixel inspector,
    /// which tells contradicted from undecided.
    #[test]
    fn an_ambiguous_order_its_neighbours_contradict_is_refused_and_marked() {
        let (w, h) = (64, 16);
        let bad = 8 * w + 30;
        let sparse =
            synthetic_set((w, h), 160.0, |p| if p == bad { 0.1 } else { 0.03 }, |p| if p == bad { 0.4 } else { 0.0 });
        let dense = synthetic_set((w, h), 16.0, |_| 0.02, |_| 0.0);
        let u = unwrap_hierarchical(&[&sparse, &dense], OrderCheck::Evidence, &RunControl::new()).expect("unwrapped");
        assert_eq!(u.contradicted[1], 1, "undecided {:?}, flagged {:?}", u.undecided, u.order_failures);
        assert!(u.unwrapped_phase_rad[1][bad].is_nan(), "the dense set is not used there");
        assert_eq!(u.order_contradicted.len(), w * h);
        let marked: Vec<usize> = (0..w * h).filter(|&p| u.order_contradicted[p] & (1 << 1) != 0).collect();
        assert_eq!(marked, vec![bad]);
        assert_eq!(u.order_flags[bad], 0, "a contradicted order is no disagreement between the sets");
        // Every other dense pixel is right.
        for p in (0..w * h).filter(|&p| p != bad) {
            let truth = TAU * ((p % w) as f64 + 5.0) / 16.0;
            assert!((f64::from(u.unwrapped_phase_rad[1][p]) - truth).abs() < 1e-3, "pixel {p}");
        }
        // Nothing contradicted: no marks are kept at all.
        let clean = synthetic_set((w, h), 160.0, |_| 0.03, |_| 0.0);
        let u = unwrap_hierarchical(&[&clean, &dense], OrderCheck::Evidence, &RunControl::new()).expect("unwrapped");
        assert!(u.order_contradicted.is_empty() && u.contradicted[1] == 0);
    }

    /// A patch of ambiguous pixels that touches no decided pixel (every
    /// sparser sigma too large for an own decision) is unwrapped spatially as
    /// a whole, which makes it smooth inside whatever order it started from:
    /// the order must come from the mean residual against the sparser set.
    /// Seeded at a pixel whose own rounding is one order off (and with
    /// rounding errors scattered by noise), no dense pixel may keep a wrong
    /// order, and the patch is still measured.
    #[test]
    fn a_patch_unwrapped_as_a_whole_takes_its_order_from_the_mean_residual() {
        let (w, h) = (64, 16);
        // Deterministic Gaussian noise (Box-Muller over a 64-bit LCG).
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = move || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let noise: Vec<f64> =
            (0..w * h).map(|_| 0.1 * (-2.0 * uniform().ln()).sqrt() * (TAU * uniform()).cos()).collect();
        for seed_error in [0.0, 0.45, -0.45] {
            // Pixels 0 and the patch's first rows start one order off.
            let error = |p: usize| if p < w { seed_error } else { noise[p] };
            let sparse = synthetic_set((w, h), 160.0, |_| 0.1, error);
            let dense = synthetic_set((w, h), 16.0, |_| 0.02, |_| 0.0);
            let u =
                unwrap_hierarchical(&[&sparse, &dense], OrderCheck::Evidence, &RunControl::new()).expect("unwrapped");
            let (mut kept, mut wrong) = (0, 0);
            for p in 0..w * h {
                let phi = u.unwrapped_phase_rad[1][p];
                if phi.is_nan() {
                    continue;
                }
                kept += 1;
                let truth = TAU * ((p % w) as f64 + 5.0) / 16.0;
                if (f64::from(phi) - truth).abs() > PI {
                    wrong += 1;
                }
            }
            assert_eq!(wrong, 0, "seed error {seed_error}: {wrong} of {kept} pixels one order off");
            assert!(kept * 10 >= w * h * 9, "seed error {seed_error}: only {kept} of {} kept", w * h);
            assert!(u.confirmed_by_patch[1] > 0, "seed error {seed_error}: decided by the patch");
        }
    }
}
