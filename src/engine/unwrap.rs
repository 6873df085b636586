//! Hierarchical temporal phase unwrapping (Alg. 3, first loop) with a
//! fringe-order check.
//!
//! The paper unwraps set m from set m-1:
//! `k^m = round((Phi^{m-1} per^{m-1}/per^m - phi^m) / 2 pi)`,
//! `Phi^m = phi^m + 2 pi k^m`. It leaves open what happens
//! where an intermediate set is unusable (over-saturated or dark): there the
//! chain would run through garbage. Here each set is unwrapped from the
//! densest sparser set that *is* usable at that pixel (the reference), and the
//! result is accepted only if it is plausible:
//!
//! - the predicted error of the reference, scaled to this period,
//!   `sigma_e = sqrt((r sigma_ref)^2 + sigma_m^2)` with `r = per_ref / per_m`,
//!   must leave the order unambiguous: `sigma_e <= pi / 5` (a wrong order is
//!   then a 5-sigma event);
//! - the residual `e = Phi_ref r - Phi^m` (in (-pi, pi] by construction) must
//!   be consistent with it: `|e| <= max(5 sigma_e, pi / 4)`.
//!
//! A set that fails is flagged at that pixel and not used, neither as a source
//! nor as a reference; fusion then refuses to fall back past a flagged set,
//! because the disagreement cannot be attributed to one of the two sets.

use std::f64::consts::{PI, TAU};

use rayon::prelude::*;

use super::control::{Cancelled, RunControl};
use super::phase_shift::WrappedPhase;

/// Largest predicted unwrapping error (rad) at which an order is still trusted.
pub const MAX_ORDER_SIGMA_RAD: f64 = PI / 5.0;
/// Residuals up to this many predicted sigmas are plausible...
pub const ORDER_RESIDUAL_SIGMAS: f64 = 5.0;
/// ...and never fewer than this (quantisation, model error of real fringes).
pub const MIN_ORDER_RESIDUAL_RAD: f64 = PI / 4.0;

/// Per-set results of the unwrapping, for the sets given (sparsest first).
#[derive(Clone, Debug)]
pub struct Unwrapped {
    /// `Phi^m` in radians of set m's own period; NaN where not unwrapped.
    pub unwrapped_phase_rad: Vec<Vec<f32>>,
    /// Bit m set: set m's fringe order failed the check at this pixel.
    pub order_flags: Vec<u16>,
    /// Per set: pixels unwrapped, and pixels whose order was flagged.
    pub unwrapped_count: Vec<usize>,
    pub order_failures: Vec<usize>,
}

/// At most this many sets take part in one unwrapping (bits of `order_flags`).
pub const MAX_SETS: usize = 16;

/// A row index, its output row of every set, and its flags.
type RowTask<'a> = (usize, Vec<&'a mut [f32]>, &'a mut [u16]);

/// Unwraps `sets` (sparsest first; the first must hold a single fringe over
/// the field, so its wrapped phase is already absolute).
pub fn unwrap_hierarchical(sets: &[&WrappedPhase], control: &RunControl) -> Result<Unwrapped, Cancelled> {
    assert!(!sets.is_empty() && sets.len() <= MAX_SETS, "1..=16 sets");
    let m_count = sets.len();
    let len = sets[0].wrapped_phase_rad.len();
    let width = sets[0].width.max(1);
    // Every element is written by the row kernel: zeroed (calloc) allocation suffices.
    let mut unwrapped: Vec<Vec<f32>> = (0..m_count).map(|_| vec![0f32; len]).collect();
    let mut flags = vec![0u16; len];

    // Work row-wise in parallel; each task writes its rows of every set.
    let mut per_set_rows: Vec<Vec<&mut [f32]>> = unwrapped.iter_mut().map(|v| v.chunks_mut(width).collect()).collect();
    let mut row_tasks: Vec<RowTask<'_>> = flags
        .chunks_mut(width)
        .enumerate()
        .map(|(row, f)| {
            let outs = per_set_rows.iter_mut().map(|rows| std::mem::take(&mut rows[row])).collect();
            (row, outs, f)
        })
        .collect();
    let (unwrapped_count, order_failures) = row_tasks
        .par_iter_mut()
        .map(|(row, outs, row_flags)| {
            let mut counts = vec![0usize; m_count];
            let mut failures = vec![0usize; m_count];
            if control.is_cancelled() {
                return (counts, failures);
            }
            unwrap_row(sets, *row * width, outs, row_flags, &mut counts, &mut failures);
            (counts, failures)
        })
        .reduce(
            || (vec![0; m_count], vec![0; m_count]),
            |(mut a, mut b), (c, d)| {
                a.iter_mut().zip(c).for_each(|(x, y)| *x += y);
                b.iter_mut().zip(d).for_each(|(x, y)| *x += y);
                (a, b)
            },
        );
    drop(row_tasks);
    control.check()?;
    Ok(Unwrapped { unwrapped_phase_rad: unwrapped, order_flags: flags, unwrapped_count, order_failures })
}

/// One image row of the hierarchical unwrapping, compiled for AVX2+FMA when
/// the CPU has them (rounding and square roots are then single instructions
/// instead of library calls).
fn unwrap_row(
    sets: &[&WrappedPhase],
    offset: usize,
    outs: &mut [&mut [f32]],
    row_flags: &mut [u16],
    counts: &mut [usize],
    failures: &mut [usize],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            unsafe { unwrap_row_avx2(sets, offset, outs, row_flags, counts, failures) };
            return;
        }
    }
    unwrap_row_generic(sets, offset, outs, row_flags, counts, failures);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn unwrap_row_avx2(
    sets: &[&WrappedPhase],
    offset: usize,
    outs: &mut [&mut [f32]],
    row_flags: &mut [u16],
    counts: &mut [usize],
    failures: &mut [usize],
) {
    unwrap_row_generic(sets, offset, outs, row_flags, counts, failures);
}

#[inline(always)]
fn unwrap_row_generic(
    sets: &[&WrappedPhase],
    offset: usize,
    outs: &mut [&mut [f32]],
    row_flags: &mut [u16],
    counts: &mut [usize],
    failures: &mut [usize],
) {
    // Set-outer, pixel-inner over tiles of the row, every decision a select:
    // the pixel loop vectorises, and each set's maps stream through once.
    const TILE: usize = 256;
    let width = row_flags.len();
    let mut t0 = 0;
    while t0 < width {
        let n = TILE.min(width - t0);
        let mut ref_phase = [0f64; TILE];
        let mut ref_period = [0f64; TILE];
        let mut ref_sigma = [0f64; TILE];
        let root = &sets[0].wrapped_phase_rad[offset + t0..offset + t0 + n];
        let root_sigma = &sets[0].phase_sigma_rad[offset + t0..offset + t0 + n];
        for j in 0..n {
            ref_phase[j] = f64::from(root[j]);
            ref_period[j] = sets[0].period_px;
            ref_sigma[j] = f64::from(root_sigma[j]);
        }
        outs[0][t0..t0 + n].copy_from_slice(root);
        counts[0] += root.iter().filter(|p| !p.is_nan()).count();
        for (m, set) in sets.iter().enumerate().skip(1) {
            let wrapped = &set.wrapped_phase_rad[offset + t0..offset + t0 + n];
            let sigma = &set.phase_sigma_rad[offset + t0..offset + t0 + n];
            let out = &mut outs[m][t0..t0 + n];
            let flags = &mut row_flags[t0..t0 + n];
            let period = set.period_px;
            let (mut accepted, mut refused) = (0usize, 0usize);
            for j in 0..n {
                let phi = f64::from(wrapped[j]);
                let sigma_m = f64::from(sigma[j]);
                // The reference is NaN exactly where the root set is invalid.
                let has = !(ref_phase[j].is_nan() || phi.is_nan());
                let ratio = ref_period[j] / period;
                let predicted = ref_phase[j] * ratio;
                let order = ((predicted - phi) * (1.0 / TAU)).round();
                let phase = phi + TAU * order;
                let residual = predicted - phase;
                let sigma_e = ((ratio * ref_sigma[j]).powi(2) + sigma_m * sigma_m).sqrt();
                let plausible = has
                    && sigma_e <= MAX_ORDER_SIGMA_RAD
                    && residual.abs() <= (ORDER_RESIDUAL_SIGMAS * sigma_e).max(MIN_ORDER_RESIDUAL_RAD);
                let flagged = has && !plausible;
                out[j] = if plausible { phase as f32 } else { f32::NAN };
                flags[j] |= u16::from(flagged) << m;
                ref_phase[j] = if plausible { phase } else { ref_phase[j] };
                ref_period[j] = if plausible { period } else { ref_period[j] };
                ref_sigma[j] = if plausible { sigma_m } else { ref_sigma[j] };
                accepted += usize::from(plausible);
                refused += usize::from(flagged);
            }
            counts[m] += accepted;
            failures[m] += refused;
        }
        t0 += n;
    }
}

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
            if row.iter().filter(|p| !p.is_nan()).count() < w / 4 {
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
