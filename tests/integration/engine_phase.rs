//! Phase retrieval (Algs. 1-2): the f64 reference solvers against known
//! phases, the fast f32 kernel against the reference, saturation handling.

use std::f64::consts::{PI, TAU};

use proptest::prelude::*;
use sheen::engine::control::RunControl;
use sheen::engine::fringe::{FringeSetInfo, uniform_shifts_rad};
use sheen::engine::phase_shift::{
    PhaseParams, SampleSelection, ShiftModel, fast_atan2, fit_pixel, standard_phase, wrapped_phase,
};

use crate::util::{phase_diff, sinusoid, stack_from_fn};

fn all_masks_with_three(n: usize) -> impl Iterator<Item = Vec<bool>> {
    (0u32..(1 << n)).filter(|m| m.count_ones() >= 3).map(move |m| (0..n).map(|k| m & (1 << k) != 0).collect())
}

#[test]
fn standard_formula_recovers_phase_to_1e9() {
    for n in [3, 4, 5, 8, 12] {
        let shifts = uniform_shifts_rad(n);
        for i in 0..50 {
            let phi = TAU * i as f64 / 50.0 + 0.0123;
            let samples: Vec<f64> = shifts.iter().map(|&d| sinusoid(120.0, 80.0, phi, d)).collect();
            let got = standard_phase(&samples, &shifts);
            assert!(phase_diff(got, phi).abs() < 1e-9, "n={n} phi={phi} got={got}");
        }
    }
}

#[test]
fn generalized_recovers_phase_for_every_mask_with_three_samples() {
    // Uniform and non-uniform shift lists, every subset of >= 3 samples.
    let lists: Vec<Vec<f64>> = vec![
        uniform_shifts_rad(4),
        uniform_shifts_rad(12),
        vec![0.0, 0.4, 1.9, 2.2, 3.9, 5.5],
        vec![0.3, -1.2, -2.9, -4.0, 1.1],
    ];
    for shifts in &lists {
        let n = shifts.len();
        for used in all_masks_with_three(n) {
            for &phi in &[0.1, 1.7, 3.0, 4.4, 6.2] {
                let samples: Vec<f64> = shifts.iter().map(|&d| sinusoid(90.0, 55.0, phi, d)).collect();
                let Some(fit) = fit_pixel(&samples, shifts, &used) else {
                    // Only ill-conditioned subsets may be refused.
                    continue;
                };
                assert!(phase_diff(fit.phase_rad, phi).abs() < 1e-9, "shifts={shifts:?} used={used:?}");
                assert!((fit.modulation - 55.0).abs() < 1e-8);
                assert!((fit.offset - 90.0).abs() < 1e-8);
            }
        }
    }
}

#[test]
fn generalized_equals_standard_when_nothing_saturates() {
    for n in [3, 4, 7, 12] {
        let shifts = uniform_shifts_rad(n);
        let used = vec![true; n];
        for i in 0..40 {
            let samples: Vec<f64> = (0..n).map(|k| 100.0 + 37.0 * ((k * 7 + i * 3) as f64).sin()).collect();
            let std = standard_phase(&samples, &shifts);
            let generalized = fit_pixel(&samples, &shifts, &used).expect("full mask").phase_rad;
            assert!(phase_diff(std, generalized).abs() < 1e-12, "n={n}");
        }
    }
}

#[test]
fn fast_atan2_is_accurate_everywhere() {
    let mut worst = 0.0f64;
    for i in 0..20_000 {
        let a = TAU * i as f64 / 20_000.0 - PI;
        for r in [1e-3f64, 1.0, 250.0] {
            let (y, x) = ((a.sin() * r) as f32, (a.cos() * r) as f32);
            let got = f64::from(fast_atan2(y, x));
            let want = f64::from(y).atan2(f64::from(x));
            worst = worst.max(phase_diff(got, want).abs());
        }
    }
    assert!(worst < 1e-6, "worst error {worst}");
}

fn params(threshold: u16, selection: SampleSelection) -> PhaseParams {
    PhaseParams { saturation_threshold: threshold, min_modulation_dn: 1.0, selection }
}

/// The fast f32 kernel agrees with the f64 reference on the same (quantised)
/// samples to 1e-5 rad, for unsaturated and partially saturated pixels and a
/// non-uniform shift list.
#[test]
fn fast_kernel_matches_f64_reference() {
    for shifts in [uniform_shifts_rad(12), uniform_shifts_rad(4), vec![0.0, 0.9, 2.1, 2.8, 4.0, 5.1, 5.9]] {
        let n = shifts.len();
        let (w, h) = (64, 16);
        let phase_of = |i: usize| TAU * ((i % w) as f64 + 0.37 * (i / w) as f64) / 41.0;
        let amp_of = |i: usize| 9000.0 + 300.0 * (i / w) as f64;
        let stack = stack_from_fn(w, h, n, 65535, |i, k| sinusoid(40000.0, amp_of(i) * 3.0, phase_of(i), shifts[k]));
        let set = FringeSetInfo { period_px: 12.0, phase_shifts_rad: shifts.clone() };
        let threshold = 60000;
        let out =
            wrapped_phase(&stack, &set, &params(threshold, SampleSelection::Unsaturated), false, &RunControl::new())
                .expect("not cancelled");
        let mut checked_partial = 0;
        for i in 0..w * h {
            let samples: Vec<f64> = stack.pixel_samples(i).iter().map(|&v| f64::from(v)).collect();
            let used: Vec<bool> = stack.pixel_samples(i).iter().map(|&v| v < threshold).collect();
            let unsat = used.iter().filter(|&&u| u).count();
            assert_eq!(usize::from(out.saturation_count[i]), n - unsat);
            match fit_pixel(&samples, &shifts, &used) {
                Some(fit) if unsat >= 3 => {
                    let got = f64::from(out.wrapped_phase_rad[i]);
                    assert!(phase_diff(got, fit.phase_rad).abs() < 1e-5, "pixel {i}: {got} vs {}", fit.phase_rad);
                    assert!((f64::from(out.modulation_dn[i]) - fit.modulation).abs() < 1e-3 * fit.modulation);
                    if unsat < n {
                        checked_partial += 1;
                    }
                }
                _ => assert!(out.wrapped_phase_rad[i].is_nan(), "pixel {i} should be invalid"),
            }
        }
        assert!(checked_partial > 50, "the test must exercise partially saturated pixels");
    }
}

/// The offset map (the texture) is the fit's mean intensity `A` where the
/// fit had 3 usable samples and 0 where it had not, for the set asked to keep
/// it; a set not asked for it carries none.
#[test]
fn the_kept_offset_map_is_the_fitted_mean_intensity() {
    let shifts = uniform_shifts_rad(4);
    let (w, h) = (64, 16);
    let phase_of = |i: usize| TAU * ((i % w) as f64 + 0.37 * (i / w) as f64) / 41.0;
    let offset_of = |i: usize| 30000.0 + 400.0 * (i % w) as f64;
    let stack = stack_from_fn(w, h, 4, 65535, |i, k| sinusoid(offset_of(i), 27000.0, phase_of(i), shifts[k]));
    let set = FringeSetInfo { period_px: 12.0, phase_shifts_rad: shifts.clone() };
    let threshold = 60000;
    let run = |keep| {
        wrapped_phase(&stack, &set, &params(threshold, SampleSelection::Unsaturated), keep, &RunControl::new())
            .expect("not cancelled")
    };
    assert!(run(false).offset_dn.is_none());
    let kept = run(true);
    let offset = kept.offset_dn.as_ref().expect("kept");
    assert_eq!(offset.len(), w * h);
    let (mut fitted, mut unfitted) = (0, 0);
    for (i, &got) in offset.iter().enumerate() {
        let samples: Vec<f64> = stack.pixel_samples(i).iter().map(|&v| f64::from(v)).collect();
        let used: Vec<bool> = stack.pixel_samples(i).iter().map(|&v| v < threshold).collect();
        match fit_pixel(&samples, &shifts, &used) {
            Some(fit) if used.iter().filter(|&&u| u).count() >= 3 => {
                assert!((f64::from(got) - fit.offset).abs() < 1e-4 * fit.offset, "pixel {i}: {got} vs {}", fit.offset);
                fitted += 1;
            }
            _ => {
                assert_eq!(got, 0.0, "pixel {i} had no fit");
                unfitted += 1;
            }
        }
    }
    assert!(fitted > 100 && unfitted > 0, "both kinds of pixel: {fitted} fitted, {unfitted} not");
}

/// Clipping a 4-step sinusoid: the N-step formula on all samples shows the
/// ripple error of saturation; least squares on the unsaturated samples does not.
#[test]
fn saturation_ripple_standard_vs_generalized() {
    let n = 4;
    let shifts = uniform_shifts_rad(n);
    let (w, h) = (256, 1);
    let truth = |i: usize| TAU * i as f64 / w as f64;
    // 12-bit camera, mean 3200, amplitude 1100: at most one of the four
    // samples (90 deg apart) clips at 4095, for about 40 % of the phases.
    let stack = stack_from_fn(w, h, n, 4095, |i, k| sinusoid(3200.0, 1100.0, truth(i), shifts[k]));
    let set = FringeSetInfo { period_px: 12.0, phase_shifts_rad: shifts };
    let run = |sel| wrapped_phase(&stack, &set, &params(4095, sel), false, &RunControl::new()).expect("run");
    let standard = run(SampleSelection::All);
    let generalized = run(SampleSelection::Unsaturated);
    let masked = run(SampleSelection::RejectSaturated);
    let max_err = |wp: &sheen::engine::phase_shift::WrappedPhase| {
        (0..w)
            .filter(|&i| !wp.wrapped_phase_rad[i].is_nan())
            .map(|i| phase_diff(f64::from(wp.wrapped_phase_rad[i]), truth(i)).abs())
            .fold(0.0, f64::max)
    };
    let sat_pixels = standard.saturation_count.iter().filter(|&&c| c > 0).count();
    assert!(sat_pixels > w / 4, "most pixels must clip ({sat_pixels})");
    // Ripple: tens of milliradians for the standard formula on clipped data...
    assert!(max_err(&standard) > 0.02, "standard error {}", max_err(&standard));
    // ...while the generalized fit is limited by quantisation alone.
    assert!(max_err(&generalized) < 1e-3, "generalized error {}", max_err(&generalized));
    assert_eq!(generalized.stats.valid, w, "every pixel keeps >= 3 unsaturated samples");
    // Masked drops every clipped pixel.
    assert_eq!(masked.stats.valid, w - sat_pixels);
}

#[test]
fn shift_model_detects_uniform_lists_of_any_start_and_sign() {
    assert!(ShiftModel::new(&uniform_shifts_rad(12)).is_uniform());
    let reversed: Vec<f64> = (0..4).map(|k| PI / 2.0 - TAU * k as f64 / 4.0).collect();
    assert!(ShiftModel::new(&reversed).is_uniform());
    assert!(!ShiftModel::new(&[0.0, 0.5, 1.0, 2.0]).is_uniform());
}

/// A reversed shift convention (delta_k = pi/2 - 2 pi k / N) gives the same
/// phase as the plain one once the shift list says so.
#[test]
fn other_shift_conventions_give_the_same_phase() {
    let n = 4;
    let plain = uniform_shifts_rad(n);
    let other: Vec<f64> = (0..n).map(|k| PI / 2.0 - TAU * k as f64 / n as f64).collect();
    for &phi in &[0.2, 2.0, 4.0, 5.9] {
        let s_plain: Vec<f64> = plain.iter().map(|&d| sinusoid(100.0, 50.0, phi, d)).collect();
        let s_other: Vec<f64> = other.iter().map(|&d| sinusoid(100.0, 50.0, phi, d)).collect();
        let a = fit_pixel(&s_plain, &plain, &[true; 4]).expect("fit").phase_rad;
        let b = fit_pixel(&s_other, &other, &[true; 4]).expect("fit").phase_rad;
        assert!(phase_diff(a, phi).abs() < 1e-9 && phase_diff(b, phi).abs() < 1e-9);
    }
}

/// The propagated phase sigma matches the scatter of phases under noise:
/// for uniform shifts it reduces to sqrt(2/N) sigma / B.
#[test]
fn phase_sigma_matches_monte_carlo_scatter() {
    use rand::{RngExt, SeedableRng};
    let n = 12;
    let shifts = uniform_shifts_rad(n);
    let (w, h) = (200, 200);
    let noise = 2.0;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let normal = rand_distr::Normal::new(0.0, noise).expect("normal");
    let mut planes = vec![vec![0u16; w * h]; n];
    for (k, plane) in planes.iter_mut().enumerate() {
        for v in plane.iter_mut() {
            let x: f64 = rng.sample(normal);
            *v = (sinusoid(2000.0, 400.0, 1.0, shifts[k]) + x).round() as u16;
        }
    }
    let stack = sheen::engine::fringe::FringeStack::from_planes_u16(w, h, planes);
    let set = FringeSetInfo { period_px: 12.0, phase_shifts_rad: shifts };
    let out = wrapped_phase(&stack, &set, &params(4095, SampleSelection::Unsaturated), false, &RunControl::new())
        .expect("run");
    let phases: Vec<f64> = out.wrapped_phase_rad.iter().map(|&p| f64::from(p)).collect();
    let mean = phases.iter().sum::<f64>() / phases.len() as f64;
    let scatter = (phases.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / phases.len() as f64).sqrt();
    let predicted = (2.0 / n as f64).sqrt() * noise / 400.0;
    assert!((out.noise.sigma_dn as f64 - noise).abs() < 0.1 * noise, "noise estimate {}", out.noise.sigma_dn);
    let reported = f64::from(out.phase_sigma_rad[w * h / 2]);
    assert!((scatter / predicted - 1.0).abs() < 0.1, "scatter {scatter} vs predicted {predicted}");
    assert!((reported / predicted - 1.0).abs() < 0.1, "reported {reported} vs predicted {predicted}");
}

proptest! {
    /// Any shift list, any mask, any intensities: a finite phase in [0, 2 pi)
    /// or an explicit refusal, never NaN leaking out of a "valid" fit.
    #[test]
    fn fit_pixel_is_finite_or_refuses(
        shifts in proptest::collection::vec(-10.0f64..10.0, 3..16),
        seed in any::<u64>(),
    ) {
        let n = shifts.len();
        let samples: Vec<f64> = (0..n).map(|k| ((seed >> (k % 60)) & 0xffff) as f64).collect();
        let used: Vec<bool> = (0..n).map(|k| (seed >> (k % 64)) & 1 == 1 || k < 3).collect();
        if let Some(fit) = fit_pixel(&samples, &shifts, &used) {
            prop_assert!(fit.phase_rad.is_finite() && (0.0..TAU).contains(&fit.phase_rad));
            prop_assert!(fit.modulation.is_finite());
        }
    }

    /// The fast kernel never produces a non-finite phase outside NaN-marked
    /// invalid pixels, whatever the samples and shifts.
    #[test]
    fn kernel_outputs_valid_or_nan(
        shifts in proptest::collection::vec(-7.0f64..7.0, 3..14),
        values in proptest::collection::vec(0u16..=4095, 14 * 6),
        threshold in 1u16..=4095,
    ) {
        let n = shifts.len();
        let (w, h) = (3, 2);
        let stack = stack_from_fn(w, h, n, 4095, |i, k| f64::from(values[(k * w * h + i) % values.len()]));
        let set = FringeSetInfo { period_px: 12.0, phase_shifts_rad: shifts };
        let p = PhaseParams { saturation_threshold: threshold, min_modulation_dn: 0.0, selection: SampleSelection::Unsaturated };
        let out = wrapped_phase(&stack, &set, &p, true, &RunControl::new()).expect("run");
        for i in 0..w * h {
            let phi = out.wrapped_phase_rad[i];
            prop_assert!(phi.is_nan() || (0.0..std::f32::consts::TAU).contains(&phi));
            if !phi.is_nan() {
                prop_assert!(out.phase_sigma_rad[i].is_finite());
                prop_assert!(out.modulation_dn[i].is_finite());
            }
        }
    }
}
