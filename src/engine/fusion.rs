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

use super::phase_shift::WrappedPhase;
use super::unwrap::Unwrapped;

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
    /// Pixels supplied per set, indexed like `set_indices`.
    pub source_counts: Vec<usize>,
    pub none_count: usize,
    pub order_failed_count: usize,
}

impl Fused {
    pub fn valid_count(&self) -> usize {
        self.source_counts.iter().sum()
    }
}

/// Fuses the unwrapped phases of `sets` (sparsest first). `set_indices[m]` is
/// the manifest index of `sets[m]`, written into the source map.
pub fn fuse(sets: &[&WrappedPhase], unwrapped: &Unwrapped, set_indices: &[usize], rule: FusionRule) -> Fused {
    let m_count = sets.len();
    let densest_period = sets[m_count - 1].period_px;
    let len = unwrapped.order_flags.len();
    let mut phase = vec![f32::NAN; len];
    let mut sigma = vec![f32::NAN; len];
    let mut source = vec![SOURCE_NONE; len];
    let scale: Vec<f64> = sets.iter().map(|s| s.period_px / densest_period).collect();
    const CHUNK: usize = 4096;
    let counts = phase
        .par_chunks_mut(CHUNK)
        .zip(sigma.par_chunks_mut(CHUNK))
        .zip(source.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(t, ((p, s), src))| {
            let mut counts = vec![0usize; m_count + 2];
            for j in 0..p.len() {
                let i = t * CHUNK + j;
                let usable = |m: &usize| !unwrapped.unwrapped_phase_rad[*m][i].is_nan();
                let chosen = match rule {
                    FusionRule::DensestOnly => Some(m_count - 1).filter(usable),
                    FusionRule::DensestUsable => (0..m_count).rev().find(usable),
                };
                let flags = unwrapped.order_flags[i];
                match chosen {
                    // A flagged denser set means two sets disagree at this pixel: refuse.
                    Some(m) if flags >> (m + 1) != 0 => {
                        src[j] = SOURCE_ORDER_FAILED;
                        counts[m_count + 1] += 1;
                    }
                    Some(m) => {
                        p[j] = (f64::from(unwrapped.unwrapped_phase_rad[m][i]) * scale[m]) as f32;
                        s[j] = (f64::from(sets[m].phase_sigma_rad[i]) * scale[m]) as f32;
                        src[j] = set_indices[m] as i8;
                        counts[m] += 1;
                    }
                    None if flags != 0 => {
                        src[j] = SOURCE_ORDER_FAILED;
                        counts[m_count + 1] += 1;
                    }
                    None => counts[m_count] += 1,
                }
            }
            counts
        })
        .reduce(
            || vec![0usize; m_count + 2],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    Fused {
        fused_phase_rad: phase,
        fused_sigma_rad: sigma,
        source_set: source,
        source_counts: counts[..m_count].to_vec(),
        none_count: counts[m_count],
        order_failed_count: counts[m_count + 1],
    }
}
