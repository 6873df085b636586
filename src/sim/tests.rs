//! Acceptance tests of the simulator's physics: truth geometry,
//! defocus contrast, the intensity model, saturation per set, determinism,
//! occlusion, and a noise-free reconstruction through the engine.

use std::f64::consts::{PI, TAU};

use super::*;
use crate::engine::fringe::{Measurement, Samples};
use crate::engine::phase_shift::fit_pixel;

fn small(scene: SceneKind) -> SimConfig {
    SimConfig::new(scene, 256, 192)
}

fn run_sim(config: &SimConfig) -> Simulation {
    simulate(config, &RunControl::new()).expect("valid test configuration")
}

/// All samples of pixel `i` in set `s` of camera `c`, as f64.
fn samples(m: &Measurement, c: usize, s: usize, i: usize) -> Vec<f64> {
    m.cameras[c].stacks[s].pixel_samples(i).into_iter().map(f64::from).collect()
}

fn unsaturated_everywhere(m: &Measurement, c: usize, i: usize) -> bool {
    (0..m.sets.len()).all(|s| samples(m, c, s, i).iter().all(|&v| v > 0.0 && v < f64::from(m.saturation_level)))
}

#[test]
fn truth_points_project_to_their_pixel_centres_with_and_without_distortion() {
    for (scene, k1) in [(SceneKind::StepGauge, 0.0), (SceneKind::StepGauge, 0.02), (SceneKind::Sphere, -0.015)] {
        let mut config = small(scene);
        config.rig.distortion_k1 = k1;
        let sim = run_sim(&config);
        let calib = sim.measurement.calibration.as_ref().unwrap();
        assert_eq!(calib.left.distortion.is_some(), k1 != 0.0);
        for (truth, cam, other) in
            [(&sim.truth.left, &calib.left, &calib.right), (&sim.truth.right, &calib.right, &calib.left)]
        {
            assert_eq!(truth.hit_count(), 256 * 192, "every ray meets the stage");
            let mut worst: f64 = 0.0;
            for (i, p) in truth.point_mm.iter().enumerate() {
                let [u, v] = cam.project_observed(*p);
                let err = (u - (i % 256) as f64).abs().max((v - (i / 256) as f64).abs());
                assert!(err.is_finite());
                worst = worst.max(err);
                // A point the other camera sees lands inside its image.
                if truth.visible_in_other[i] {
                    let [uo, vo] = other.project_observed(*p);
                    assert!(uo > -0.5 && vo > -0.5 && uo < 255.5 && vo < 191.5);
                }
            }
            assert!(worst < 1e-9, "{scene} k1 {k1}: worst reprojection {worst} px");
        }
        // Distortion moves the image corners by pixels, so it really was applied.
        if k1 != 0.0 {
            let ideal = calib.left.project(sim.truth.left.point_mm[0]);
            assert!(ideal[0].hypot(ideal[1]) > 2.0, "corner ideal pixel {ideal:?}");
        }
    }
}

#[test]
fn truth_points_lie_on_the_scene_surface_or_on_a_wall() {
    for scene in SceneKind::ALL {
        let sim = run_sim(&SimConfig::new(scene, 128, 96));
        let h = |x: f64, y: f64| sim.truth.scene.height_mm(x, y);
        for truth in [&sim.truth.left, &sim.truth.right] {
            let mut walls = 0;
            for (p, &wall) in truth.point_mm.iter().zip(&truth.on_wall) {
                if wall {
                    // Between the heights on the two sides of the wall, along the ray's direction.
                    walls += 1;
                    let (a, b) = (h(p[0] - 1e-6, p[1]), h(p[0] + 1e-6, p[1]));
                    assert!((a - b).abs() > 1e-6, "{scene}: wall point {p:?} has no jump");
                    assert!(p[2] >= a.min(b) - 1e-9 && p[2] <= a.max(b) + 1e-9, "{scene}: {p:?} off its wall");
                } else {
                    // The crossing is bracketed to 1e-12 mm in Z; over that the
                    // height can change by the slope along the ray.
                    let g = sim.truth.scene.stage_point(p[0], p[1]).unwrap().surface;
                    let tol = 1e-12 * (1.0 + 0.3 * g.dz_dx.hypot(g.dz_dy));
                    assert!((p[2] - h(p[0], p[1])).abs() <= tol, "{scene}: {p:?} vs h {}", h(p[0], p[1]));
                }
            }
            if matches!(scene, SceneKind::Flat | SceneKind::Sphere) {
                assert_eq!(walls, 0, "{scene} has no walls");
            }
        }
    }
}

#[test]
fn landmarks_agree_with_the_height_function() {
    for scene in SceneKind::ALL.map(scenes::build) {
        assert!(!scene.landmarks.is_empty(), "{}", scene.kind);
        let level = |r: &scene_model::Region, height: f64| {
            for j in 0..=20 {
                for k in 0..=20 {
                    let x = r.x_min_mm + (r.x_max_mm - r.x_min_mm) * k as f64 / 20.0;
                    let y = r.y_min_mm + (r.y_max_mm - r.y_min_mm) * j as f64 / 20.0;
                    let z = scene.height_mm(x, y);
                    assert!((z - height).abs() < 1e-12, "{}: h({x}, {y}) = {z}, expected {height}", scene.kind);
                }
            }
        };
        for lm in &scene.landmarks {
            match lm {
                Landmark::Land { region, height_mm, .. } => level(region, *height_mm),
                Landmark::Step { reference, measured, height_mm, .. } => {
                    let base = scene.height_mm(reference.x_min_mm, reference.y_min_mm);
                    level(reference, base);
                    level(measured, base + height_mm);
                }
                Landmark::Plane { z0_mm, slope_x, slope_y, region, .. } => {
                    let center = (0.5 * (region.x_min_mm + region.x_max_mm), 0.5 * (region.y_min_mm + region.y_max_mm));
                    for (x, y) in [(region.x_min_mm, region.y_min_mm), (region.x_max_mm, region.y_max_mm), center] {
                        let z = scene.height_mm(x, y);
                        assert!((z - (z0_mm + slope_x * x + slope_y * y)).abs() < 1e-12, "{}", lm.name());
                    }
                }
                Landmark::Sphere { center_mm: c, radius_mm, .. } => {
                    let (x, y) = (c[0] + 0.3, c[1] - 0.2);
                    let z = scene.height_mm(x, y);
                    let r = ((x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt();
                    assert!((r - radius_mm).abs() < 1e-12, "{}: radius {r}", lm.name());
                }
                Landmark::Bore { center_mm: c, floor_mm, .. } => {
                    assert!((scene.height_mm(c[0], c[1]) - floor_mm).abs() < 1e-12, "{}", lm.name());
                }
                Landmark::Thread { pitch_mm, major_radius_mm, minor_radius_mm, axis_y_mm, axis_z_mm, .. } => {
                    // Along the top line the height runs between the radii with the thread's pitch.
                    let z: Vec<f64> = (0..800).map(|k| scene.height_mm(-8.0 + k as f64 * 0.004, *axis_y_mm)).collect();
                    let (lo, hi) = z.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
                    assert!(
                        (hi - (axis_z_mm + major_radius_mm)).abs() < 1e-12
                            && (lo - (axis_z_mm + minor_radius_mm)).abs() < 1e-12
                    );
                    let x = -5.0;
                    assert!((scene.height_mm(x, *axis_y_mm) - scene.height_mm(x + pitch_mm, *axis_y_mm)).abs() < 1e-12);
                }
                Landmark::Section { from_mm, to_mm, .. } => {
                    assert!(scene.extent.contains(from_mm[0], from_mm[1]) && scene.extent.contains(to_mm[0], to_mm[1]));
                }
            }
        }
    }
    // The step gauge carries the advertised steps.
    let gauge = scenes::build(SceneKind::StepGauge);
    let steps: Vec<f64> = gauge
        .landmarks
        .iter()
        .filter_map(|l| if let Landmark::Step { height_mm, .. } = l { Some(height_mm * 1e3) } else { None })
        .collect();
    assert_eq!(steps, scenes::STEP_GAUGE_HEIGHTS_UM);
}

#[test]
fn defocus_contrast_follows_the_gaussian_blur_formula() {
    // 16-bit, noise-free, with strong defocus so the contrast spans a wide range.
    let mut config = SimConfig { bits: 16, ..small(SceneKind::Sphere) };
    config.rig.projector.blur_px_per_mm = 3.0;
    let sim = run_sim(&config);
    let m = &sim.measurement;
    let projector = &sim.truth.rig.projector;
    let truth = &sim.truth.left;
    let (mut checked, mut lowest, mut highest) = (0, f64::INFINITY, 0.0f64);
    for i in (0..truth.point_mm.len()).step_by(7) {
        if truth.on_wall[i] || !unsaturated_everywhere(m, 0, i) {
            continue;
        }
        let z = truth.point_mm[i][2];
        let fits: Vec<_> = m
            .sets
            .iter()
            .enumerate()
            .map(|(s, set)| fit_pixel(&samples(m, 0, s, i), &set.phase_shifts_rad, &[true; 12]).unwrap())
            .collect();
        if fits[0].modulation < 2000.0 {
            continue; // quantisation would dominate the ratios
        }
        let sigma = projector.blur_sigma_px(z);
        for (s, set) in m.sets.iter().enumerate() {
            let p = set.period_px;
            let formula = (-2.0 * PI * PI * sigma * sigma / (p * p)).exp();
            // B/A against the truth's in-focus B/A times the formula.
            let in_focus = f64::from(truth.amplitude_dn[i]) / f64::from(truth.offset_dn[i]);
            let measured = fits[s].modulation / fits[s].offset;
            assert!(
                (measured / in_focus - formula).abs() < 2e-3,
                "pixel {i} z {z} period {p}: {measured} vs {}",
                in_focus * formula
            );
            // Relative to the sparsest set: no truth needed beyond Z.
            let sparse = (-2.0 * PI * PI * sigma * sigma / (912.0 * 912.0)).exp();
            let ratio = fits[s].modulation / fits[0].modulation;
            assert!(
                (ratio - formula / sparse).abs() < 2e-3,
                "pixel {i} period {p}: ratio {ratio} vs {}",
                formula / sparse
            );
            if s == 3 {
                lowest = lowest.min(ratio);
                highest = highest.max(ratio);
            }
        }
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} pixels checked");
    // Dense fringes lose contrast with defocus: the densest set's contrast spans a wide range.
    assert!(lowest < 0.3 && highest > 0.6, "contrast of period 12 spans {lowest}..{highest}");
}

#[test]
fn noise_free_16_bit_samples_fit_the_fringe_model_to_quantisation() {
    // An unusual convention too: other periods, shift counts, sign and offset.
    let standard = SimConfig { bits: 16, ..small(SceneKind::WatchPlate) };
    let unusual = SimConfig {
        periods_px: vec![912.0, 100.0, 20.0, 9.0],
        shifts: vec![12, 7, 5, 4],
        shift_sign: -1,
        shift_offset_rad: 0.4,
        ..standard.clone()
    };
    for config in [standard, unusual] {
        let sim = run_sim(&config);
        let m = &sim.measurement;
        let truth = &sim.truth.left;
        let mut checked = 0;
        for i in (0..truth.point_mm.len()).step_by(3) {
            if truth.on_wall[i] || !unsaturated_everywhere(m, 0, i) {
                continue;
            }
            for (s, set) in m.sets.iter().enumerate() {
                let phase = truth.phase_rad(i, set.period_px);
                let iv = samples(m, 0, s, i);
                // The model with A, B and the phase from truth, to quantisation
                // (plus the f32 storage of the per-pixel terms).
                let (a_true, b_true) = (
                    f64::from(truth.offset_dn[i]),
                    f64::from(truth.amplitude_dn[i])
                        * sim.truth.rig.projector.contrast(truth.point_mm[i][2], set.period_px),
                );
                let basis: Vec<f64> = set.phase_shifts_rad.iter().map(|d| (phase + d).cos()).collect();
                let worst = iv.iter().zip(&basis).map(|(v, c)| (v - a_true - b_true * c).abs()).fold(0.0, f64::max);
                assert!(worst <= 0.5 + 0.01, "pixel {i} set {s}: {worst} DN from the model");
                // Least squares for A and B with the phase from truth leaves only quantisation.
                let n = iv.len() as f64;
                let (sc, scc) = (basis.iter().sum::<f64>(), basis.iter().map(|c| c * c).sum::<f64>());
                let (si, sci) = (iv.iter().sum::<f64>(), iv.iter().zip(&basis).map(|(v, c)| v * c).sum::<f64>());
                let det = n * scc - sc * sc;
                let b = (n * sci - sc * si) / det;
                let a = (si - b * sc) / n;
                let rms = (iv.iter().zip(&basis).map(|(v, c)| (v - a - b * c).powi(2)).sum::<f64>() / n).sqrt();
                assert!(rms <= 0.51, "pixel {i} set {s}: rms {rms}");
                // The engine's own fit recovers the true phase.
                let fit = fit_pixel(&iv, &set.phase_shifts_rad, &vec![true; iv.len()]).unwrap();
                let dphi = (fit.phase_rad - phase).rem_euclid(TAU);
                let dphi = dphi.min(TAU - dphi);
                assert!(dphi < 2.0 / fit.modulation, "pixel {i} set {s}: phase off by {dphi} rad (B = {b})");
            }
            checked += 1;
        }
        assert!(checked > 2000, "only {checked} unsaturated pixels");
    }
}

/// Per set, per pixel: the number of saturated samples.
fn saturation_counts(m: &Measurement, camera: usize) -> Vec<Vec<usize>> {
    m.cameras[camera]
        .stacks
        .iter()
        .map(|s| {
            (0..s.pixel_count())
                .map(|i| (0..s.shifts).filter(|&k| s.sample(k, i) >= m.saturation_level).count())
                .collect()
        })
        .collect()
}

#[test]
fn shiny_scenes_saturate_as_in_the_paper() {
    for scene in SceneKind::SHINY {
        let sim = run_sim(&small(scene));
        for camera in 0..2 {
            let counts = saturation_counts(&sim.measurement, camera);
            let n = 12;
            let pixels = counts[0].len() as f64;
            let fraction = |f: &dyn Fn(usize) -> bool| (0..counts[0].len()).filter(|&i| f(i)).count() as f64 / pixels;
            let over = |s: usize, i: usize| counts[s][i] + 3 > n;
            let densest = counts.len() - 1;
            let partially: Vec<f64> =
                (0..counts.len()).map(|s| fraction(&|i| counts[s][i] >= 1 && !over(s, i))).collect();
            let over_per_set: Vec<f64> = (0..counts.len()).map(|s| fraction(&|i| over(s, i))).collect();
            let only_densest = fraction(&|i| over(densest, i) && !over(densest - 1, i));
            let several = fraction(&|i| (0..counts.len()).filter(|&s| over(s, i)).count() >= 2);
            let context = format!("{scene} camera {camera}: partial {partially:?}, over {over_per_set:?}");
            // Partially saturated pixels (generalized phase shifting's case) in every set.
            assert!(partially.iter().all(|&f| f > 0.002), "{context}");
            // Pixels only the densest set loses (the paper's Fig. 2e/f) and pixels lost by several.
            assert!(only_densest > 0.003, "{context}: only densest {only_densest}");
            assert!(several > 0.002, "{context}: several {several}");
            // Over-saturation grows with fringe density (defocus lowers the dense
            // sets' contrast). The 912 and 144 px sets keep nearly the same
            // contrast, and where the 12 samples fall on the fringe decides, so
            // they only have to agree.
            assert!(over_per_set[1] > 0.7 * over_per_set[0] && over_per_set[1] < 1.3 * over_per_set[0], "{context}");
            assert!(over_per_set[2] > over_per_set[0].max(over_per_set[1]), "{context}");
            assert!(
                over_per_set[densest] > over_per_set[2] && over_per_set[densest] > 2.0 * over_per_set[0],
                "{context}"
            );
        }
    }
}

#[test]
fn metrology_artefacts_do_not_saturate() {
    for scene in [SceneKind::Flat, SceneKind::StepGauge, SceneKind::Sphere] {
        let sim = run_sim(&small(scene));
        for camera in 0..2 {
            let counts = saturation_counts(&sim.measurement, camera);
            assert!(counts.iter().flatten().all(|&k| k == 0), "{scene} camera {camera} saturates");
        }
    }
}

#[test]
fn highlights_differ_between_the_cameras() {
    let sim = run_sim(&small(SceneKind::WatchPlate));
    let (truth, rig) = (&sim.truth, &sim.truth.rig);
    let radiometry = render::Radiometry {
        full_scale_dn: 255.0,
        exposure: truth.scene.exposure,
        ambient: 0.02,
        noise_sigma_dn: 0.0,
        fringe_gamma: 1.0,
        black_level_dn: 0.0,
        projector_modulation: 0.95,
    };
    let (mut differ, mut total) = (0, 0);
    for (i, p) in truth.left.point_mm.iter().enumerate() {
        if truth.left.on_wall[i] || !truth.left.visible_in_other[i] {
            continue;
        }
        let right = render::shade_point(&truth.scene, rig, *p, false, rig.to_camera(CameraId::Right), &radiometry).0;
        let left = f64::from(truth.left.offset_dn[i]);
        total += 1;
        if (left - right).abs() > 0.3 * left.max(right) {
            differ += 1;
        }
    }
    assert!(differ as f64 > 0.05 * total as f64, "{differ} of {total} points differ by more than 30 %");
}

#[test]
fn same_seed_gives_the_same_images_on_one_or_two_threads() {
    let config = SimConfig { noise_sigma_dn: 1.5, seed: 7, ..SimConfig::new(SceneKind::Gaskets, 96, 72) };
    let on = |threads: usize, config: &SimConfig| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| run_sim(config))
    };
    let one = on(1, &config);
    let two = on(2, &config);
    for (a, b) in one.measurement.cameras.iter().zip(&two.measurement.cameras) {
        assert_eq!(a, b, "camera {}", a.name);
    }
    assert_eq!(one.truth.left, two.truth.left);
    assert_eq!(one.truth.right, two.truth.right);
    // Noise is really there, and depends on the seed.
    let other = on(2, &SimConfig { seed: 8, ..config.clone() });
    assert_ne!(one.measurement.cameras[0].stacks[3], other.measurement.cameras[0].stacks[3]);
    let quiet = on(2, &SimConfig { noise_sigma_dn: 0.0, ..config });
    let differing = (0..96 * 72 * 12)
        .filter(|&i| {
            let (a, b) =
                (&one.measurement.cameras[0].stacks[3].samples, &quiet.measurement.cameras[0].stacks[3].samples);
            a.get(i) != b.get(i)
        })
        .count();
    assert!(differing > 96 * 72 * 12 / 4, "{differing} samples changed by noise");
}

#[test]
fn step_walls_occlude_the_base_beside_them() {
    let sim = run_sim(&small(SceneKind::StepGauge));
    let (truth, rig) = (&sim.truth, &sim.truth.rig);
    let tan = rig.theta_deg.to_radians().tan();
    let blocks: Vec<(f64, f64)> =
        (0..4).map(|i| (-8.0 + 5.5 * i as f64, scenes::STEP_GAUGE_HEIGHTS_UM[i] * 1e-3)).collect();
    let (half_x, half_y) = (1.8, 6.5);
    // Each camera loses the base beside the walls facing away from it: the
    // right camera (looking towards -X) the strip left of each block, the left
    // camera the strip right of it, h tan(theta) wide.
    for (view, own, other, side) in
        [(&truth.left, &rig.left, &rig.right, -1.0), (&truth.right, &rig.right, &rig.left, 1.0)]
    {
        let in_shadow = |p: &[f64; 3], margin: f64| {
            blocks.iter().position(|&(cx, h)| {
                let d = side * (p[0] - (cx + side * half_x));
                p[2].abs() < 1e-12 && d > margin && d < h * tan - margin && p[1].abs() < half_y - margin
            })
        };
        let mut per_block = [0usize; 4];
        for (i, p) in view.point_mm.iter().enumerate() {
            let [u, v] = other.project_observed(*p);
            if !(u > -0.5 && v > -0.5 && u < 255.5 && v < 191.5) || view.on_wall[i] {
                continue;
            }
            match (view.visible_in_other[i], in_shadow(p, -1e-9)) {
                (false, Some(b)) => per_block[b] += 1,
                (false, None) => panic!("{:?} pixel {i} at {p:?} is hidden but in no shadow", view.camera),
                // Well inside a shadow strip, the point must be hidden.
                (true, _) => {
                    assert!(in_shadow(p, 1e-9).is_none(), "{:?} pixel {i} at {p:?} is in a shadow", view.camera)
                }
            }
        }
        // The left camera's columns are aligned with the walls, so its rows all
        // sample a strip alike; the rolled right camera samples it evenly, so
        // its hidden pixels cover the strips' area (pixel footprint 1/|det M_xy|).
        if side > 0.0 {
            let footprint = 1.0 / (own.p[0][0] * own.p[1][1] - own.p[0][1] * own.p[1][0]).abs();
            for (b, &(_, h)) in blocks.iter().enumerate().skip(1) {
                let expected = h * tan * 2.0 * half_y / footprint;
                let got = per_block[b] as f64;
                assert!((got - expected).abs() < 0.1 * expected + 3.0, "block {b}: {got} hidden, expected {expected}");
            }
        }
        assert!(per_block[3] > 100, "{:?}: {per_block:?}", view.camera);
    }
    // The left camera sees the walls facing it; they get no projector light.
    let walls: Vec<usize> = (0..truth.left.on_wall.len()).filter(|&i| truth.left.on_wall[i]).collect();
    assert!(walls.len() > 100);
    for &i in &walls {
        assert_eq!(truth.left.amplitude_dn[i], 0.0);
        assert!(f64::from(truth.left.offset_dn[i]) < 5.0);
        let x = truth.left.point_mm[i][0];
        assert!(blocks.iter().any(|&(cx, _)| (x - (cx - half_x)).abs() < 1e-9), "wall at x = {x}");
    }
}

#[test]
fn engine_reconstructs_the_flat_to_well_under_a_tenth_of_a_micrometre() {
    use crate::engine::pipeline::{Params, run};
    let config = SimConfig { bits: 16, ..small(SceneKind::Flat) };
    let sim = run_sim(&config);
    let rec = run(&sim.measurement, &Params::default(), None, &RunControl::new()).unwrap();
    assert!(rec.warnings.is_empty(), "{:?}", rec.warnings);
    let cloud = &rec.stereo.as_ref().expect("stereo ran").cloud;
    let mut sum2 = 0.0;
    let mut worst: f64 = 0.0;
    for p in &cloud.xyz {
        let dz = p[2] - sim.truth.scene.height_mm(p[0], p[1]);
        sum2 += dz * dz;
        worst = worst.max(dz.abs());
    }
    let rms_um = (sum2 / cloud.len() as f64).sqrt() * 1e3;
    let both = sim.truth.left.visible_in_other.iter().filter(|&&v| v).count();
    assert!(cloud.len() as f64 > 0.97 * both as f64, "{} points of {both} seen by both cameras", cloud.len());
    assert!(rms_um < 0.02, "rms {rms_um} um");
    assert!(worst < 1e-4, "worst {} um", worst * 1e3);
}

#[test]
fn demo_is_a_complete_eight_bit_watch_plate_measurement() {
    let sim = demo(96, 72);
    let m = &sim.measurement;
    assert_eq!(sim.config.scene, SceneKind::WatchPlate);
    assert!(sim.config.noise_sigma_dn > 0.0);
    assert_eq!((m.bit_depth, m.saturation_level), (8, 255));
    assert_eq!(m.periods_px(), vec![912.0, 144.0, 24.0, 12.0]);
    assert!(m.label.starts_with("simulated watch-plate"));
    assert_eq!(m.cameras.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["left", "right"]);
    for cam in &m.cameras {
        assert_eq!((cam.width, cam.height, cam.stacks.len()), (96, 72, 4));
        assert!(cam.stacks.iter().all(|s| s.shifts == 12 && matches!(s.samples, Samples::U8(_))));
    }
    assert!(m.calibration.as_ref().is_some_and(|c| c.validate().is_ok()));
    // Sizes below the minimum are raised instead of failing.
    let tiny = demo(0, 3);
    assert_eq!((tiny.measurement.cameras[0].width, tiny.measurement.cameras[0].height), (MIN_SIDE_PX, MIN_SIDE_PX));
}

#[test]
fn the_sparsest_set_is_absolute_over_both_images() {
    // Its phase stays clear of 0 and 2 pi wherever either camera sees the scene.
    for scene in SceneKind::ALL {
        let sim = run_sim(&SimConfig::new(scene, 64, 48));
        for truth in [&sim.truth.left, &sim.truth.right] {
            for i in 0..truth.point_mm.len() {
                let phase = truth.phase_rad(i, 912.0);
                assert!(phase > 0.2 && phase < TAU - 0.2, "{scene}: phase {phase} at pixel {i}");
            }
        }
    }
}

#[test]
fn bad_settings_are_refused_with_the_setting_named() {
    let ok = small(SceneKind::Flat);
    let check = |config: SimConfig, needle: &str| {
        let err = simulate(&config, &RunControl::new()).expect_err("refused").to_string();
        assert!(err.contains(needle), "'{err}' should mention '{needle}'");
    };
    check(SimConfig { width: 8, ..ok.clone() }, "8x192");
    check(SimConfig { bits: 7, ..ok.clone() }, "bits");
    check(SimConfig { noise_sigma_dn: -1.0, ..ok.clone() }, "noise");
    check(SimConfig { periods_px: vec![912.0, 12.0, 24.0], ..ok.clone() }, "decreasing order");
    check(SimConfig { periods_px: vec![], ..ok.clone() }, "periods");
    check(SimConfig { shifts: vec![12, 12], ..ok.clone() }, "shift counts");
    check(SimConfig { shifts: vec![2], ..ok.clone() }, "shifts");
    check(SimConfig { shift_sign: 0, ..ok.clone() }, "shift sign");
    check(SimConfig { gain: 0.0, ..ok.clone() }, "gain");
    let mut bad = ok.clone();
    bad.rig.theta_deg = 0.0;
    check(bad, "theta");
    let mut bad = ok;
    bad.rig.projector.modulation = f64::NAN;
    check(bad, "projector modulation");
}

#[test]
fn cancelling_stops_the_simulation() {
    let control = RunControl::new();
    control.cancel();
    assert!(matches!(simulate(&small(SceneKind::Flat), &control), Err(SimError::Cancelled(_))));
}

#[test]
fn scene_names_round_trip() {
    for kind in SceneKind::ALL {
        assert_eq!(kind.name().parse::<SceneKind>(), Ok(kind));
        assert_eq!(serde_json::to_value(kind).unwrap(), serde_json::Value::String(kind.to_string()));
    }
    let err = "teapot".parse::<SceneKind>().unwrap_err();
    assert!(err.contains("teapot") && err.contains("watch-plate") && err.contains("sphere"), "{err}");
}

#[test]
fn truth_serialises_with_the_true_cameras() {
    let sim = run_sim(&SimConfig::new(SceneKind::Sphere, 32, 24));
    let rig = serde_json::to_value(&sim.truth.rig).unwrap();
    let calib = sim.measurement.calibration.as_ref().unwrap();
    for (name, cam) in [("left", &calib.left), ("right", &calib.right)] {
        let p: [[f64; 4]; 2] = serde_json::from_value(rig[name]["P"].clone()).unwrap();
        assert_eq!(p, cam.p);
        assert_eq!(rig[name]["width"], 32);
    }
    let scene = serde_json::to_value(&sim.truth.scene).unwrap();
    assert_eq!(scene["kind"], "sphere");
    assert_eq!(scene["landmarks"][0]["kind"], "sphere");
    assert_eq!(scene["landmarks"][0]["radius_mm"], 4.0);
    let truth = serde_json::to_value(&sim.truth).unwrap();
    assert_eq!(truth["height_grid"]["z_mm"].as_array().unwrap().len(), 32 * 24);
    // The scene survives a round trip and still answers heights.
    let mut back: Scene = serde_json::from_value(scene).unwrap();
    back.reindex();
    assert_eq!(back.height_mm(0.5, 0.25), sim.truth.scene.height_mm(0.5, 0.25));
}
