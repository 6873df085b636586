//! HDR phase fusion (Alg. 3, replacement loops): where the densest set is
//! over-saturated, take the equivalent phase `Phi^m_eq = Phi^m per^m / per^M`
//! of the densest sparser set that is usable there.
//!
//! The paper marks a set unusable by over-saturation alone (`ind^m =
//! sat_map^m > N_S - 3`); here "usable" is what the earlier stages established
//! per pixel: a valid wrapped phase (>= 3 unsaturated samples, enough
//! modulation) whose fringe order was unwrapped and passed the order check.
//! On data where only saturation decides, both rules pick the same set.

use rayon::prelude::*;

use super::buffers::filled;
use super::phase_shift::WrappedPhase;
use super::unwrap::{EVIDENCE_OWN, Unwrapped};

/// `source_set` value for pixels that no set could recover.
pub const SOURCE_NONE: i8 = -1;
/// `source_set` value for pixels rejected because a fringe order failed its check.
pub const SOURCE_ORDER_FAILED: i8 = -2;

/// Which set supplies the final phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FusionRule {
    /// The paper's scheme: the densest usable set (Alg. 3).
    DensestUsable,
    /// Traditional: the densest set or nothing.
    DensestOnly,
}

/// The final phase map of one camera.
#[derive(Clone, Debug)]
pub struct Fused {
    /// Absolute phase in radians of the densest period; NaN where invalid.
    pub fused_phase_rad: Vec<f32>,
    /// Its standard deviation, in the same radians.
    pub fused_sigma_rad: Vec<f32>,
    /// Manifest index of the set that supplied each pixel, or
    /// [`SOURCE_NONE`] / [`SOURCE_ORDER_FAILED`].
    pub source_set: Vec<i8>,
    /// How the fringe orders behind each pixel's phase were decided
    /// (`unwrap::EVIDENCE_*`: on the pixel's own samples, confirmed by its
    /// neighbours, or by its patch), the highest along the reference chain of
    /// the supplying set; [`EVIDENCE_OWN`] where invalid.
    pub order_evidence: Vec<u8>,
    /// Pixels supplied per set, indexed like `set_indices`.
    pub source_counts: Vec<usize>,
    pub none_count: usize,
    pub order_failed_count: usize,
    /// Valid pixels whose orders needed neighbours' (index 0) or their
    /// patch's (index 1) evidence.
    pub confirmed_counts: [usize; 2],
    /// Pixels left out because their orders needed evidence beyond their own
    /// samples and the run asked for own-evidence orders only.
    pub excluded_confirmed: usize,
}

impl Fused {
    pub fn valid_count(&self) -> usize {
        self.source_counts.iter().sum()
    }
}

/// Fuses the unwrapped phases of `sets` (sparsest first). `set_indices[m]` is
/// the manifest index of `sets[m]`, written into the source map. With
/// `own_orders_only`, pixels whose orders were confirmed by neighbours or by
/// their patch are left out (invalid, source [`SOURCE_NONE`]).
pub fn fuse(
    sets: &[&WrappedPhase],
    unwrapped: &Unwrapped,
    set_indices: &[usize],
    rule: FusionRule,
    own_orders_only: bool,
) -> Fused {
    let m_count = sets.len();
    let densest_period = sets[m_count - 1].period_px;
    let len = unwrapped.order_flags.len();
    let mut phase = filled(len, f32::NAN);
    let mut sigma = filled(len, f32::NAN);
    let mut source = filled(len, SOURCE_NONE);
    let mut evidence = filled(len, EVIDENCE_OWN);
    let scale: Vec<f64> = sets.iter().map(|s| s.period_px / densest_period).collect();
    const CHUNK: usize = 4096;
    let counts = phase
        .par_chunks_mut(CHUNK)
        .zip(sigma.par_chunks_mut(CHUNK))
        .zip(source.par_chunks_mut(CHUNK))
        .zip(evidence.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(t, (((p, s), src), ev))| {
            let range = t * CHUNK..t * CHUNK + p.len();
            // Set-outer over the chunk, each decision a select, so the pixel
            // loops vectorise: later (denser) usable sets override earlier ones.
            let mut chosen = [u8::MAX; CHUNK];
            let chosen = &mut chosen[..p.len()];
            for m in 0..m_count {
                if rule == FusionRule::DensestOnly && m + 1 != m_count {
                    continue;
                }
                let phase_m = &unwrapped.unwrapped_phase_rad[m][range.clone()];
                let sigma_m = &sets[m].phase_sigma_rad[range.clone()];
                let (scale_m, index_m) = (scale[m], set_indices[m] as i8);
                for j in 0..p.len() {
                    let usable = !phase_m[j].is_nan();
                    p[j] = if usable { (f64::from(phase_m[j]) * scale_m) as f32 } else { p[j] };
                    s[j] = if usable { (f64::from(sigma_m[j]) * scale_m) as f32 } else { s[j] };
                    src[j] = if usable { index_m } else { src[j] };
                    chosen[j] = if usable { m as u8 } else { chosen[j] };
                }
            }
            // A flagged set denser than the chosen one (or any flagged set
            // when none is usable) means two sets disagree here: refuse.
            let flags = &unwrapped.order_flags[range.clone()];
            for j in 0..p.len() {
                let denser = if chosen[j] == u8::MAX { flags[j] } else { flags[j] >> (u32::from(chosen[j]) + 1) };
                if denser != 0 {
                    p[j] = f32::NAN;
                    s[j] = f32::NAN;
                    src[j] = SOURCE_ORDER_FAILED;
                    chosen[j] = u8::MAX - 1;
                }
            }
            // Evidence of the chosen set's chain; `counts[m_count + 2..]` are
            // the neighbour- and patch-confirmed pixels and those left out.
            let mut counts = vec![0usize; m_count + 5];
            let codes = &unwrapped.order_evidence[range];
            for j in 0..p.len() {
                let c = chosen[j];
                if usize::from(c) >= m_count {
                    continue;
                }
                let level = ((codes[j] >> (2 * u32::from(c))) & 3) as u8;
                if level != EVIDENCE_OWN && own_orders_only {
                    p[j] = f32::NAN;
                    s[j] = f32::NAN;
                    src[j] = SOURCE_NONE;
                    chosen[j] = u8::MAX;
                    counts[m_count + 4] += 1;
                    continue;
                }
                ev[j] = level;
                if level != EVIDENCE_OWN {
                    counts[m_count + 1 + usize::from(level)] += 1;
                }
            }
            // One counting pass per outcome: each vectorises, where a
            // histogram's increments wait on each other (neighbours mostly
            // share their source).
            let count_of = |v: u8| chosen.iter().map(|&c| usize::from(c == v)).sum::<usize>();
            for (m, count) in counts[..m_count].iter_mut().enumerate() {
                *count += count_of(m as u8);
            }
            counts[m_count] += count_of(u8::MAX);
            counts[m_count + 1] += count_of(u8::MAX - 1);
            counts
        })
        .reduce(
            || vec![0usize; m_count + 5],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    Fused {
        fused_phase_rad: phase,
        fused_sigma_rad: sigma,
        source_set: source,
        order_evidence: evidence,
        source_counts: counts[..m_count].to_vec(),
        none_count: counts[m_count],
        order_failed_count: counts[m_count + 1],
        confirmed_counts: [counts[m_count + 2], counts[m_count + 3]],
        excluded_confirmed: counts[m_count + 4],
    }
}
