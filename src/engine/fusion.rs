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
    let densest = m_count - 1;
    let sparsest_candidate = if rule == FusionRule::DensestOnly { densest } else { 0 };
    const CHUNK: usize = 4096;
    let counts = phase
        .par_chunks_mut(CHUNK)
        .zip(sigma.par_chunks_mut(CHUNK))
        .zip(source.par_chunks_mut(CHUNK))
        .zip(evidence.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(t, (((p, s), src), ev))| {
            let range = t * CHUNK..t * CHUNK + p.len();
            let phases: Vec<&[f32]> = unwrapped.unwrapped_phase_rad.iter().map(|u| &u[range.clone()]).collect();
            let sigmas: Vec<&[f32]> = sets.iter().map(|set| &set.phase_sigma_rad[range.clone()]).collect();
            let densest_phase = phases[densest];
            let flags = &unwrapped.order_flags[range.clone()];
            let codes = &unwrapped.order_evidence[range.clone()];
            // Each pixel's outcome: its set, or u8::MAX (none) or u8::MAX - 1
            // (order failed); counted afterwards in one pass per outcome,
            // where a histogram's increments wait on each other (neighbours
            // mostly share their source).
            let mut chosen = [u8::MAX; CHUNK];
            let chosen = &mut chosen[..p.len()];
            // `counts[m_count + 2..]`: the neighbour- and patch-confirmed
            // pixels and those left out.
            let mut counts = vec![0usize; m_count + 5];
            for (j, outcome) in chosen.iter_mut().enumerate() {
                // The densest usable set: nearly every pixel has the densest
                // one, the rest look further down (a branch that is mostly
                // not taken, where a select per set and pixel cost four
                // passes over every map).
                let usable = if !densest_phase[j].is_nan() {
                    Some(densest)
                } else {
                    // A plain loop: the iterator search was a call per pixel.
                    let mut usable = None;
                    for m in (sparsest_candidate..densest).rev() {
                        if !phases[m][j].is_nan() {
                            usable = Some(m);
                            break;
                        }
                    }
                    usable
                };
                // A flagged set denser than the chosen one (or any flagged
                // set when none is usable) means two sets disagree: refuse.
                let denser_flags = match usable {
                    Some(m) => flags[j].checked_shr(m as u32 + 1).unwrap_or(0),
                    None => flags[j],
                };
                if denser_flags != 0 {
                    *outcome = u8::MAX - 1;
                    src[j] = SOURCE_ORDER_FAILED;
                    continue;
                }
                let Some(m) = usable else { continue };
                // Evidence of the chosen set's chain.
                let level = ((codes[j] >> (2 * m as u32)) & 3) as u8;
                if level != EVIDENCE_OWN && own_orders_only {
                    counts[m_count + 4] += 1;
                    continue;
                }
                if level != EVIDENCE_OWN {
                    counts[m_count + 1 + usize::from(level)] += 1;
                }
                *outcome = m as u8;
                p[j] = (f64::from(phases[m][j]) * scale[m]) as f32;
                s[j] = (f64::from(sigmas[m][j]) * scale[m]) as f32;
                src[j] = set_indices[m] as i8;
                ev[j] = level;
            }
            // Counted in bytes, 255 pixels at a time: a byte per pixel fills
            // a SIMD register, where a usize per pixel held two.
            let count_of = |v: u8| {
                chosen
                    .chunks(255)
                    .map(|block| usize::from(block.iter().fold(0u8, |n, &c| n.wrapping_add(u8::from(c == v)))))
                    .sum::<usize>()
            };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::phase_shift::{NoiseEstimate, NoiseSource, SetStats};
    use crate::engine::unwrap::{MAX_SETS, OrderCheck};

    fn set(period_px: f64, sigma_rad: Vec<f32>) -> WrappedPhase {
        let len = sigma_rad.len();
        WrappedPhase {
            width: len,
            height: 1,
            period_px,
            shifts: 12,
            saturation_count: vec![0; len],
            wrapped_phase_rad: vec![0.0; len],
            modulation_dn: vec![50.0; len],
            phase_sigma_rad: sigma_rad,
            offset_dn: None,
            noise: NoiseEstimate {
                sigma_dn: 1.0,
                measured: true,
                pixels: len,
                source: NoiseSource::FitResidual,
                harmonic_percent: None,
            },
            stats: SetStats::default(),
        }
    }

    /// With the most sets a run takes, the densest one supplying a pixel
    /// must not make "the sets denser than the chosen one" every set: a
    /// sparser set's flag is no disagreement with the densest phase.
    #[test]
    fn with_sixteen_sets_only_flags_denser_than_the_chosen_set_refuse() {
        let n = MAX_SETS;
        let len = 4;
        // Pixel 0: every set usable, set 3 flagged. Pixel 1: the densest set
        // flagged, the next one usable. Pixel 2: only the sparsest usable.
        // Pixel 3: every set usable, nothing flagged.
        let usable = |m: usize, p: usize| match p {
            1 => m < n - 1,
            2 => m == 0,
            _ => true,
        };
        let periods: Vec<f64> = (0..n).map(|m| f64::from(1u32 << (n - 1 - m))).collect();
        let sets: Vec<WrappedPhase> = periods.iter().map(|&per| set(per, vec![0.01; len])).collect();
        let refs: Vec<&WrappedPhase> = sets.iter().collect();
        let unwrapped = Unwrapped {
            unwrapped_phase_rad: (0..n)
                .map(|m| (0..len).map(|p| if usable(m, p) { 3.0 + m as f32 } else { f32::NAN }).collect())
                .collect(),
            order_flags: vec![1 << 3, 1 << (n - 1), 0, 0],
            order_contradicted: Vec::new(),
            order_evidence: vec![0; len],
            unwrapped_count: vec![0; n],
            order_failures: vec![0; n],
            confirmed_by_neighbours: vec![0; n],
            confirmed_by_patch: vec![0; n],
            undecided: vec![0; n],
            contradicted: vec![0; n],
            check: OrderCheck::Evidence,
            root_wrap_fraction: 0.0,
        };
        let indices: Vec<usize> = (0..n).collect();
        let fused = fuse(&refs, &unwrapped, &indices, FusionRule::DensestUsable, false);
        assert_eq!(fused.source_set, vec![15, SOURCE_ORDER_FAILED, 0, 15]);
        assert_eq!(fused.fused_phase_rad[0], 3.0 + 15.0);
        assert!(fused.fused_phase_rad[1].is_nan());
        // The sparsest set's phase in radians of the densest period.
        assert_eq!(fused.fused_phase_rad[2], 3.0 * 32768.0);
        assert_eq!(fused.fused_sigma_rad[2], 0.01 * 32768.0);
        assert_eq!((fused.source_counts[15], fused.source_counts[0], fused.order_failed_count), (2, 1, 1));
    }
}
