//! Temporal unwrapping and HDR fusion (Alg. 3), through `pipeline::run_phase`.

use std::f64::consts::TAU;

use sheen::engine::control::RunControl;
use sheen::engine::fusion::{SOURCE_NONE, SOURCE_ORDER_FAILED};
use sheen::engine::pipeline::{Method, Params, run_phase};
use sheen::engine::unwrap::OrderCheck;
use sheen::engine::warning::WarningKind;

use crate::util::measurement;

const PAPER_PERIODS: [f64; 4] = [912.0, 144.0, 24.0, 12.0];

fn params(method: Method) -> Params {
    Params { method, min_modulation_dn: 2.0, ..Params::default() }
}

/// Noise-free 16-bit data over the paper's periods: every pixel unwraps to its
/// true absolute phase.
#[test]
fn unwrapping_is_exact_on_noise_free_data() {
    let (w, h) = (400, 8);
    let x_p = |i: usize| 40.0 + 830.0 * (i % w) as f64 / w as f64 + 0.7 * (i / w) as f64;
    let m = measurement(w, h, 65535, &PAPER_PERIODS, 12, x_p, |_, _| (30000.0, 20000.0));
    let rec = run_phase(&m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
    let cam = &rec.cameras[0];
    for (k, &period) in PAPER_PERIODS.iter().enumerate() {
        let unwrapped = cam.unwrapped_phase(k).expect("enabled");
        for (i, &phase) in unwrapped.iter().enumerate() {
            let truth = TAU * x_p(i) / period;
            assert!((f64::from(phase) - truth).abs() < 2e-3, "set {k} pixel {i}: {phase} vs {truth}");
        }
    }
    for i in 0..w * h {
        assert_eq!(cam.fused.source_set[i], 3);
        let truth = TAU * x_p(i) / 12.0;
        assert!((f64::from(cam.fused.fused_phase_rad[i]) - truth).abs() < 2e-3);
    }
    assert_eq!(cam.unwrapped.order_failures.iter().sum::<usize>(), 0);
    assert!(rec.warnings.is_empty(), "{:?}", rec.warnings);
}

/// Per pixel a constructed over-saturation pattern over the three denser sets;
/// the source map must be the set Alg. 3 prescribes (the densest set that is
/// not over-saturated), computed here from the engine's own saturation counts.
#[test]
fn fusion_picks_the_set_algorithm_3_prescribes() {
    let (w, h) = (64, 16);
    let sat = 4095.0;
    let x_p = |i: usize| 100.0 + 700.0 * (i % w) as f64 / w as f64;
    // Pattern bits 0..2 for sets 1..3: over-saturated (all samples clip) or a
    // partially saturated set with enough unsaturated samples, so all three
    // regimes of the paper occur.
    let pattern = |i: usize| ((i * 2_654_435_761usize) >> 7) % 8;
    let oa = move |m: usize, i: usize| {
        if m > 0 && pattern(i) & (1 << (m - 1)) != 0 {
            (1.6 * sat, 0.2 * sat)
        } else if (i / w).is_multiple_of(2) {
            (0.8 * sat, 0.4 * sat) // partially saturated: ~4 of 12 samples clip
        } else {
            (0.45 * sat, 0.3 * sat)
        }
    };
    let m = measurement(w, h, 4095, &PAPER_PERIODS, 12, x_p, oa);
    let rec = run_phase(&m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
    let cam = &rec.cameras[0];
    let n = 12;
    let mut seen = [0usize; 4];
    for i in 0..w * h {
        let over: Vec<bool> = cam.sets.iter().map(|s| usize::from(s.saturation_count[i]) > n - 3).collect();
        let prescribed = (0..4).rev().find(|&s| !over[s]).expect("root never over-saturated");
        assert_eq!(cam.fused.source_set[i], prescribed as i8, "pixel {i}, over-saturated {over:?}");
        seen[prescribed] += 1;
        // The filled phase is the equivalent phase of that set, scaled to the densest period.
        let truth = TAU * x_p(i) / 12.0;
        let tol = 0.02 * PAPER_PERIODS[prescribed] / 12.0;
        assert!((f64::from(cam.fused.fused_phase_rad[i]) - truth).abs() < tol, "pixel {i}");
    }
    assert!(seen.iter().all(|&c| c > 0), "every source occurs: {seen:?}");
    let partial = cam.sets[3].saturation_count.iter().filter(|&&c| c > 0 && c as usize <= n - 3).count();
    assert!(partial > 0, "partially saturated pixels exist in the densest set");

    // The traditional methods: generalized keeps only densest-set pixels...
    let generalized = run_phase(&m, &params(Method::Generalized), Some(&rec), &RunControl::new()).expect("run");
    let dense_ok = (0..w * h).filter(|&i| cam.fused.source_set[i] == 3).count();
    assert_eq!(generalized.cameras[0].fused.valid_count(), dense_ok);
    // ...and masked drops every pixel with a saturated sample in the root or
    // the densest set (intermediate sets may be skipped by the chain).
    let masked = run_phase(&m, &params(Method::Masked), None, &RunControl::new()).expect("run");
    let unsat_dense =
        (0..w * h).filter(|&i| cam.sets[0].saturation_count[i] == 0 && cam.sets[3].saturation_count[i] == 0).count();
    assert_eq!(masked.cameras[0].fused.valid_count(), unsat_dense);
}

/// Where an intermediate set is unusable, the densest set is unwrapped from
/// the sparser set that is usable, not through garbage.
#[test]
fn unusable_intermediate_set_is_skipped() {
    let (w, h) = (200, 4);
    let x_p = |i: usize| 50.0 + 800.0 * (i % w) as f64 / w as f64;
    // Set 1 (period 144) dark in the left half: below the modulation floor.
    let oa = move |m: usize, i: usize| if m == 1 && (i % w) < w / 2 { (20000.0, 1.0) } else { (30000.0, 20000.0) };
    let m = measurement(w, h, 65535, &[912.0, 144.0, 24.0], 12, x_p, oa);
    let rec = run_phase(&m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
    let cam = &rec.cameras[0];
    for i in 0..w * h {
        assert_eq!(cam.fused.source_set[i], 2, "pixel {i}");
        let truth = TAU * x_p(i) / 24.0;
        assert!((f64::from(cam.fused.fused_phase_rad[i]) - truth).abs() < 2e-3, "pixel {i}");
    }
    assert!(cam.unwrapped_phase(1).expect("enabled")[0].is_nan());
}

/// A set whose phase disagrees with its reference by more than its noise
/// allows is flagged, and the pixel is refused rather than filled from a set
/// that may be the wrong one.
#[test]
fn implausible_fringe_order_is_flagged_not_guessed() {
    let (w, h) = (120, 4);
    let x_p = |i: usize| 100.0 + 600.0 * (i % w) as f64 / w as f64;
    let m0 = measurement(w, h, 65535, &[912.0, 144.0, 12.0], 12, x_p, |_, _| (30000.0, 20000.0));
    // Corrupt the densest set in the right third by 2.5 rad (a wrong reading).
    let corrupt = measurement(
        w,
        h,
        65535,
        &[912.0, 144.0, 12.0],
        12,
        move |i| if (i % w) >= 2 * w / 3 { x_p(i) + 2.5 / TAU * 12.0 } else { x_p(i) },
        |_, _| (30000.0, 20000.0),
    );
    let mut m = m0.clone();
    m.cameras[0].stacks[2] = corrupt.cameras[0].stacks[2].clone();
    let rec = run_phase(&m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
    let cam = &rec.cameras[0];
    for i in 0..w * h {
        if (i % w) >= 2 * w / 3 {
            assert_eq!(cam.fused.source_set[i], SOURCE_ORDER_FAILED, "pixel {i}");
            assert!(cam.fused.fused_phase_rad[i].is_nan());
            assert_ne!(cam.unwrapped.order_flags[i] & 0b100, 0);
        } else {
            assert_eq!(cam.fused.source_set[i], 2);
        }
    }
    assert_eq!(cam.fused.order_failed_count, (w - 2 * w / 3) * h);
}

/// The fusion's counts are the tally of its source map: pixels per source
/// set, pixels with no usable set and pixels refused for disagreeing orders,
/// over more than one of the fusion's parallel chunks.
#[test]
fn fusion_counts_are_the_tally_of_its_source_map() {
    let (w, h) = (120, 40);
    let periods = [912.0, 144.0, 24.0, 12.0];
    // Regions of unequal widths, so no two outcomes have the same count.
    let region = move |i: usize| match i % w {
        0..40 => 0,
        40..70 => 1,
        70..90 => 2,
        _ => 3,
    };
    let x_p = move |i: usize| 100.0 + 600.0 * (i % w) as f64 / w as f64;
    // Region 0 plain, region 1 with its densest set over-saturated, region 2
    // without fringes, region 3 with its densest set read 2.5 rad wrong.
    let offset_amplitude = move |m: usize, i: usize| match (region(i), m) {
        (1, 3) => (90000.0, 20000.0),
        (2, _) => (30000.0, 0.0),
        _ => (30000.0, 20000.0),
    };
    let mut m = measurement(w, h, 65535, &periods, 12, x_p, offset_amplitude);
    let corrupt = measurement(
        w,
        h,
        65535,
        &periods,
        12,
        move |i| if region(i) == 3 { x_p(i) + 2.5 / TAU * 12.0 } else { x_p(i) },
        offset_amplitude,
    );
    m.cameras[0].stacks[3] = corrupt.cameras[0].stacks[3].clone();
    let rec = run_phase(&m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
    let fused = &rec.cameras[0].fused;
    let tally = |source: i8| fused.source_set.iter().filter(|&&s| s == source).count();
    for (set, &count) in fused.source_counts.iter().enumerate() {
        assert_eq!(count, tally(set as i8), "set {set}");
    }
    assert_eq!(fused.none_count, tally(SOURCE_NONE));
    assert_eq!(fused.order_failed_count, tally(SOURCE_ORDER_FAILED));
    // Each outcome occurs, region by region.
    assert_eq!(fused.source_counts[3], 40 * h);
    assert_eq!(fused.source_counts[2], 30 * h);
    assert_eq!(fused.none_count, 20 * h);
    assert_eq!(fused.order_failed_count, 30 * h);
}

/// Disabling the sparsest set leaves a root whose period does not cover the
/// field: the result says so instead of pretending the phase is absolute.
#[test]
fn phase_ambiguity_is_reported() {
    let (w, h) = (300, 6);
    let x_p = |i: usize| 30.0 + 850.0 * (i % w) as f64 / w as f64;
    let m = measurement(w, h, 65535, &PAPER_PERIODS, 8, x_p, |_, _| (30000.0, 20000.0));
    let mut p = params(Method::Hdr);
    p.enabled_sets = vec![false, true, true, true];
    let rec = run_phase(&m, &p, None, &RunControl::new()).expect("run");
    assert!(rec.cameras[0].root_wrap_fraction > 0.9);
    let wraps: Vec<_> = rec.warnings.iter().filter(|w| w.kind == WarningKind::SparsestSetWraps).collect();
    assert!(wraps.len() == 1 && wraps[0].message.contains("period 144 px"), "{:?}", rec.warnings);
}

/// 8-bit measurement with Gaussian camera noise added sample by sample.
fn noisy_measurement(
    w: usize,
    h: usize,
    periods: &[f64],
    shifts: usize,
    x_p: impl Fn(usize) -> f64,
    offset_modulation_dn: (f64, f64),
    noise_dn: f64,
) -> sheen::engine::fringe::Measurement {
    use rand::{RngExt, SeedableRng};
    let mut m = measurement(w, h, 255, periods, shifts, x_p, |_, _| offset_modulation_dn);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let normal = rand_distr::Normal::new(0.0, noise_dn).expect("normal");
    for stack in m.cameras[0].stacks.iter_mut() {
        if let sheen::engine::fringe::Samples::U8(v) = &mut stack.samples {
            for x in v.iter_mut() {
                *x = (f64::from(*x) + rng.sample(normal)).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    m
}

/// Unwrapped pixels of set `m`, and those more than pi from the truth (a wrong order).
fn kept_and_wrong(
    rec: &sheen::engine::pipeline::Reconstruction,
    m: usize,
    truth_rad: impl Fn(usize) -> f64,
) -> (usize, usize) {
    let phase = &rec.cameras[0].unwrapped.unwrapped_phase_rad[m];
    let kept = phase.iter().filter(|p| !p.is_nan()).count();
    let wrong = (0..phase.len())
        .filter(|&i| !phase[i].is_nan() && (f64::from(phase[i]) - truth_rad(i)).abs() > std::f64::consts::PI)
        .count();
    (kept, wrong)
}

/// Unwrapping straight from 912 to 12 (ratio 76) with 8-bit noise cannot
/// resolve the order: the result warns with the reason and does not use the
/// dense set, in every mode that checks orders; nothing wrong slips through.
#[test]
fn too_large_period_ratio_is_warned() {
    let (w, h) = (200, 50);
    let x_p = |i: usize| 40.0 + 800.0 * (i % w) as f64 / w as f64;
    let m = noisy_measurement(w, h, &[912.0, 12.0], 4, x_p, (120.0, 30.0), 3.0);
    for check in [OrderCheck::Evidence, OrderCheck::Strict] {
        let mut p = params(Method::Hdr);
        p.order_check = check;
        let rec = run_phase(&m, &p, None, &RunControl::new()).expect("run");
        let ratio: Vec<_> = rec.warnings.iter().filter(|w| w.kind == WarningKind::PeriodRatioTooLarge).collect();
        assert!(ratio.len() == 1 && ratio[0].message.contains("period ratio 76.0"), "{check}: {:?}", rec.warnings);
        let u = &rec.cameras[0].unwrapped;
        let (kept, wrong) = kept_and_wrong(&rec, 1, |i| TAU * x_p(i) / 12.0);
        assert!(kept < w * h / 2, "{check}: kept {kept}, flagged {:?}, undecided {:?}", u.order_failures, u.undecided);
        assert_eq!(wrong, 0, "{check}: wrong orders accepted");
    }
}

/// Issue 18: dim fringes (12 DN modulation, 3 DN noise) unwrapped from a
/// sparser set at ratio 6.3 are ambiguous on their own (wrong with a
/// probability near 0.5 %): `strict` refuses nearly all of them, `off` keeps
/// all with some wrong orders, and `evidence` keeps nearly all with none wrong,
/// confirmed by the patch's mean residual and its neighbours.
#[test]
fn evidence_keeps_dim_pixels_with_no_wrong_order() {
    let (w, h) = (240, 60);
    let x_p = |i: usize| 40.0 + 800.0 * (i % w) as f64 / w as f64;
    let m = noisy_measurement(w, h, &[912.0, 144.0], 8, x_p, (60.0, 12.0), 3.0);
    let truth = |i: usize| TAU * x_p(i) / 144.0;
    let run = |check: OrderCheck| {
        let mut p = params(Method::Hdr);
        p.order_check = check;
        p.min_modulation_dn = 4.0;
        let rec = run_phase(&m, &p, None, &RunControl::new()).expect("run");
        let (kept, wrong) = kept_and_wrong(&rec, 1, truth);
        (kept, wrong, rec)
    };
    let (strict_kept, strict_wrong, _) = run(OrderCheck::Strict);
    let (off_kept, off_wrong, _) = run(OrderCheck::Off);
    let (kept, wrong, rec) = run(OrderCheck::Evidence);
    let u = &rec.cameras[0].unwrapped;
    assert_eq!(strict_wrong, 0);
    assert!(strict_kept < w * h / 10, "strict kept {strict_kept}");
    assert!(off_wrong > 0, "the scene must be hard enough for the plain rule to fail");
    assert_eq!(wrong, 0, "evidence accepted a wrong order");
    assert!(kept + off_wrong >= off_kept * 98 / 100, "evidence kept {kept}, off kept {off_kept} ({off_wrong} wrong)");
    assert!(
        u.confirmed_by_neighbours[1] + u.confirmed_by_patch[1] > w * h / 2,
        "{:?} {:?}",
        u.confirmed_by_neighbours,
        u.confirmed_by_patch
    );
    // Which pixels rest on their neighbours' evidence reaches the fused result.
    let fused = &rec.cameras[0].fused;
    assert!(fused.confirmed_counts[0] + fused.confirmed_counts[1] > w * h / 2);
}

/// Re-running with only the enabled sets changed reuses the per-set phases.
#[test]
fn per_set_phases_are_reused_when_only_fusion_inputs_change() {
    let (w, h) = (50, 5);
    let m = measurement(w, h, 4095, &PAPER_PERIODS, 6, |i| 100.0 + (i % w) as f64, |_, _| (2000.0, 1000.0));
    let first = run_phase(&m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
    let mut p = params(Method::Generalized);
    p.enabled_sets = vec![true, true, false, true];
    let second = run_phase(&m, &p, Some(&first), &RunControl::new()).expect("run");
    for s in 0..4 {
        assert!(std::sync::Arc::ptr_eq(&first.cameras[0].sets[s], &second.cameras[0].sets[s]));
    }
    assert_eq!(second.cameras[0].enabled, vec![0, 1, 3]);
    // A threshold change recomputes them.
    let mut p3 = params(Method::Hdr);
    p3.saturation_threshold = Some(3000);
    let third = run_phase(&m, &p3, Some(&second), &RunControl::new()).expect("run");
    assert!(!std::sync::Arc::ptr_eq(&first.cameras[0].sets[0], &third.cameras[0].sets[0]));
}

/// Cancelling returns `Cancelled`, never a partial result.
#[test]
fn cancelled_run_returns_no_result() {
    let m = measurement(64, 64, 255, &PAPER_PERIODS, 4, |i| (i % 64) as f64 * 10.0, |_, _| (100.0, 50.0));
    let control = RunControl::new();
    control.cancel();
    let err = run_phase(&m, &params(Method::Hdr), None, &control).expect_err("cancelled");
    assert!(matches!(err, sheen::engine::pipeline::EngineError::Cancelled(_)));
}

/// Issue 18 item 2: with projector gamma the fringes carry harmonics; the
/// noise Sheen uses for order decisions is still the random noise the rig
/// adds (1.5 DN here), and the harmonics are reported apart. The separation
/// needs modulation that varies over the image (the dim part's faces): on a
/// uniformly lit flat the harmonics are taken for noise (11 DN), which is
/// conservative (orders refused, none wrong) but not separated.
#[test]
fn the_noise_model_separates_random_noise_from_gamma_harmonics() {
    use sheen::sim::{SceneKind, SimConfig, simulate};
    let run = |gamma: f64| {
        let mut config = SimConfig::camera_projector(SceneKind::DimPart, 256, 192);
        config.projector_gamma = gamma;
        config.gamma_compensation = 1.0;
        let s = simulate(&config, &RunControl::new()).expect("simulate");
        run_phase(&s.measurement, &Params::default(), None, &RunControl::new()).expect("phases")
    };
    let (linear, gamma) = (run(1.0), run(2.2));
    for (rec, name) in [(&linear, "linear"), (&gamma, "gamma 2.2")] {
        for set in &rec.cameras[0].sets {
            let noise = set.noise.sigma_dn;
            assert!(set.noise.measured && (noise - 1.5).abs() < 0.3, "{name}: noise {noise} DN against 1.5");
        }
    }
    let harmonics = |rec: &sheen::engine::pipeline::Reconstruction| {
        rec.cameras[0].sets.iter().map(|s| s.noise.harmonic_percent.expect("harmonics estimated")).fold(0.0, f32::max)
    };
    assert!(harmonics(&linear) < 1.0, "linear projector: {} % harmonics", harmonics(&linear));
    assert!(harmonics(&gamma) > 5.0, "gamma 2.2 uncorrected: {} % harmonics", harmonics(&gamma));
}

/// Issue 18 item 1: a measurement can leave out the pixels whose orders
/// needed evidence beyond their own samples.
#[test]
fn own_orders_only_leaves_out_exactly_the_pixels_confirmed_by_evidence() {
    use sheen::engine::unwrap::EVIDENCE_OWN;
    use sheen::sim::{SceneKind, SimConfig, simulate};
    let config = SimConfig::camera_projector(SceneKind::DimPart, 256, 192);
    let s = simulate(&config, &RunControl::new()).expect("simulate");
    let run = |own_orders_only: bool| {
        let params = Params { own_orders_only, ..Params::default() };
        run_phase(&s.measurement, &params, None, &RunControl::new()).expect("phases")
    };
    let (all, own) = (run(false), run(true));
    let (all, own) = (&all.cameras[0].fused, &own.cameras[0].fused);
    let confirmed =
        all.order_evidence.iter().zip(&all.fused_phase_rad).filter(|&(&e, p)| e != EVIDENCE_OWN && !p.is_nan()).count();
    assert!(confirmed > 0, "the dim part needs evidence somewhere");
    assert_eq!(own.valid_count(), all.valid_count() - confirmed);
    assert_eq!(own.excluded_confirmed, confirmed);
    for p in 0..all.fused_phase_rad.len() {
        if !own.fused_phase_rad[p].is_nan() {
            assert_eq!(own.order_evidence[p], EVIDENCE_OWN, "pixel {p} kept without its own evidence");
        }
    }
}

/// Where a set's noise comes from is measured, never assumed, and said: a
/// 3-step set borrows the residual noise of the camera's sets with more
/// shifts, and with only 3-step sets the noise comes from the spread of the
/// offset between sets. A uniform modulation cannot separate harmonics from
/// noise, and the report then claims no harmonic share.
#[test]
fn three_step_noise_is_measured_from_other_sets_or_offsets_and_the_report_says_which() {
    use sheen::engine::phase_shift::NoiseSource;
    let (w, h) = (200, 60);
    let x_p = |i: usize| 40.0 + 800.0 * (i % w) as f64 / w as f64;
    let sigma_dn = 2.0;
    let report = |m: &sheen::engine::fringe::Measurement| {
        let rec = run_phase(m, &params(Method::Hdr), None, &RunControl::new()).expect("run");
        let json = serde_json::to_value(sheen::engine::report::Report::new(&rec)).expect("json");
        (rec, json)
    };

    // Only 3-step sets: the offsets' spread between sets.
    let three = noisy_measurement(w, h, &[912.0, 144.0, 24.0], 3, x_p, (120.0, 60.0), sigma_dn);
    let (rec, json) = report(&three);
    for (s, set) in rec.cameras[0].sets.iter().enumerate() {
        assert_eq!(set.noise.source, NoiseSource::CrossSetOffsets, "set {s}");
        let got = f64::from(set.noise.sigma_dn);
        assert!((got - sigma_dn).abs() < 0.3 * sigma_dn, "set {s}: {got} DN for {sigma_dn}");
        let r = &json["cameras"][0]["sets"][s];
        assert_eq!((&r["noise_source"], &r["harmonics"]), (&"cross_set_offsets".into(), &"no residual".into()), "{r}");
    }

    // A 3-step set beside 4-step ones borrows their residual noise.
    let four = noisy_measurement(w, h, &[912.0, 144.0, 24.0], 4, x_p, (120.0, 60.0), sigma_dn);
    let mut mixed = four.clone();
    mixed.sets[2] = three.sets[2].clone();
    mixed.cameras[0].stacks[2] = three.cameras[0].stacks[2].clone();
    let (rec, json) = report(&mixed);
    let sets = &rec.cameras[0].sets;
    assert_eq!(sets[2].noise.source, NoiseSource::OtherSets);
    // The median of the measured sets (of two, the upper one).
    assert_eq!(sets[2].noise.sigma_dn, sets[0].noise.sigma_dn.max(sets[1].noise.sigma_dn));
    let borrowed = f64::from(sets[2].noise.sigma_dn);
    assert!((borrowed - sigma_dn).abs() < 0.2 * sigma_dn, "{borrowed} DN");
    assert_eq!(json["cameras"][0]["sets"][2]["noise_source"], "other_sets");

    // 4-step sets with one modulation everywhere: residual noise, but no
    // harmonic share can be told from it.
    for (s, set) in sets.iter().enumerate().take(2) {
        assert_eq!(set.noise.source, NoiseSource::FitResidual, "set {s}");
        assert_eq!(set.noise.harmonic_percent, None, "set {s}: a uniform modulation separates nothing");
        assert_eq!(json["cameras"][0]["sets"][s]["harmonics"], "not separable");
    }
}
