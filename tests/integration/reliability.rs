//! Bad data gets an explanation, never garbage points (issue 9): dark or
//! saturated sets, cameras that share no field, unusable calibrations.

use sheen::engine::camera_model::StereoCalibration;
use sheen::engine::control::RunControl;
use sheen::engine::fringe::Samples;
use sheen::engine::pipeline::{Params, run};
use sheen::engine::warning::WarningKind;
use sheen::sim::{SceneKind, SimConfig, simulate};

fn flat_measurement() -> sheen::engine::fringe::Measurement {
    let c = SimConfig::new(SceneKind::Flat, 128, 96);
    simulate(&c, &RunControl::new()).expect("simulate").measurement
}

fn fill_set(m: &mut sheen::engine::fringe::Measurement, set: usize, value: u8) {
    for cam in &mut m.cameras {
        if let Samples::U8(v) = &mut cam.stacks[set].samples {
            v.iter_mut().for_each(|x| *x = value);
        }
    }
}

#[test]
fn an_all_dark_set_is_reported_and_the_rest_still_measures() {
    let mut m = flat_measurement();
    fill_set(&mut m, 2, 3);
    let rec = run(&m, &Params::default(), None, &RunControl::new()).expect("run");
    let dark: Vec<_> = rec.warnings.iter().filter(|w| w.kind == WarningKind::SetTooDark).collect();
    assert!(dark.len() == 2 && dark.iter().all(|w| w.message.contains("set 2")), "one per camera: {:?}", rec.warnings);
    // Recovery: set 3 is unwrapped from set 1 across the dead set 2 where the
    // ratio allows, so the points that remain are located by the densest set
    // and are the very points of the intact measurement, not guesses.
    let clean = run(&flat_measurement(), &Params::default(), None, &RunControl::new()).expect("run");
    let (cloud, reference) =
        (&rec.stereo.as_ref().expect("stereo").cloud, &clean.stereo.as_ref().expect("stereo").cloud);
    let at_pixel: std::collections::HashMap<[u32; 2], usize> =
        reference.pixel_uv.iter().enumerate().map(|(i, uv)| ([uv[0].to_bits(), uv[1].to_bits()], i)).collect();
    let mut same = 0;
    for (i, uv) in cloud.pixel_uv.iter().enumerate() {
        assert_eq!(cloud.source_set[i], 3, "point {i} is located by set {}", cloud.source_set[i]);
        let j = *at_pixel.get(&[uv[0].to_bits(), uv[1].to_bits()]).expect("a pixel the intact run measured too");
        let dz_um = (cloud.xyz[i][2] - reference.xyz[j][2]).abs() * 1e3;
        assert!(dz_um < 0.01, "point {i} at {uv:?}: {dz_um} um from the intact run's");
        same += 1;
    }
    eprintln!("dark set 2: {} of {} points recovered", same, reference.len());
    // On this flat scene the ratio 144/12 allows every pixel (all 11,587 are
    // recovered today); 95 % leaves room for a stricter order check.
    assert!(same * 100 >= reference.len() * 95, "only {same} of {} points recovered", reference.len());
}

#[test]
fn an_all_saturated_measurement_gives_no_points_and_says_why() {
    let mut m = flat_measurement();
    for s in 0..m.sets.len() {
        fill_set(&mut m, s, 255);
    }
    let rec = run(&m, &Params::default(), None, &RunControl::new()).expect("run");
    assert_eq!(rec.point_count(), 0);
    let count = |kind| rec.warnings.iter().filter(|w| w.kind == kind).count();
    let sets = m.sets.len();
    assert_eq!(count(WarningKind::SetAllSaturated), 2 * sets, "every set of both cameras: {:?}", rec.warnings);
    assert_eq!(count(WarningKind::NoAbsolutePhase), 2, "{:?}", rec.warnings);
}

#[test]
fn cameras_that_share_no_field_give_a_message_not_points() {
    let mut m = flat_measurement();
    let calib: &mut StereoCalibration = m.calibration.as_mut().expect("calibrated");
    // Shift the right camera's image by far more than its height: no common rows.
    calib.right.p[1][3] += 10_000.0;
    let rec = run(&m, &Params::default(), None, &RunControl::new()).expect("run");
    assert_eq!(rec.point_count(), 0);
    let why = rec.stereo_skipped.as_deref().unwrap_or("");
    assert!(why.contains("share no field"), "{why}");
    assert!(rec.warnings.iter().any(|w| w.kind == WarningKind::StereoFailed), "{:?}", rec.warnings);
}

#[test]
fn an_unusable_calibration_keeps_the_phase_results() {
    let mut m = flat_measurement();
    let calib = m.calibration.as_mut().expect("calibrated");
    calib.right.p = calib.left.p; // parallel viewing directions: no baseline
    let rec = run(&m, &Params::default(), None, &RunControl::new()).expect("run");
    assert!(rec.stereo.is_none());
    assert!(rec.stereo_skipped.as_deref().unwrap_or("").contains("parallel"), "{:?}", rec.stereo_skipped);
    assert!(rec.cameras.iter().all(|c| c.fused.valid_count() > 0), "per-camera results stay available");
}

#[test]
fn calibration_for_other_image_sizes_is_refused_with_both_sizes() {
    let mut m = flat_measurement();
    m.calibration.as_mut().expect("calibrated").left.width = 2048;
    let rec = run(&m, &Params::default(), None, &RunControl::new()).expect("run");
    let why = rec.stereo_skipped.as_deref().unwrap_or("");
    assert!(why.contains("2048x96") && why.contains("128x96"), "{why}");
}

#[test]
fn no_nan_reaches_the_points() {
    let mut c = SimConfig::new(SceneKind::WatchPlate, 128, 96);
    c.noise_sigma_dn = 2.0;
    let m = simulate(&c, &RunControl::new()).expect("simulate").measurement;
    let rec = run(&m, &Params { max_sigma_z_um: None, ..Params::default() }, None, &RunControl::new()).expect("run");
    let cloud = &rec.stereo.as_ref().expect("stereo").cloud;
    assert!(!cloud.is_empty());
    assert!(cloud.xyz.iter().flatten().all(|v| v.is_finite()));
    assert!(cloud.sigma_z.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert!(cloud.pixel_uv.iter().flatten().all(|v| v.is_finite()));
}
