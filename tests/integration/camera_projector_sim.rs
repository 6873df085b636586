//! The simulated camera–projector rig (issue 52, item 5) through the whole
//! pipeline: the frames the simulator renders (pinhole camera and
//! projector, phase sets along x and y, OpenCV's Gray code, white and black)
//! decode to the projector points that really lit each pixel, and the
//! calibrated cloud lies on the rendered surface. Each scene's figures are
//! printed for BENCHMARKS.md (`cargo test --release --test integration
//! camera_projector_sim -- --nocapture`).

use sheen::engine::camera_projector::rig_point_cloud;
use sheen::engine::control::RunControl;
use sheen::engine::pipeline::{Params, run_phase};
use sheen::sim::SceneKind;
use sheen::sim::camera_projector::{PinholeRigConfig, PinholeSimulation, simulate_camera_projector};

/// What one scene measured against its truth.
#[derive(Debug)]
struct Figures {
    lit: usize,
    /// Lit pixels with a projector x; those half the densest period or
    /// more off (a wrong order), and those beyond five of their σ.
    decoded: usize,
    wrong_order: usize,
    beyond_5_sigma: usize,
    /// RMS of the projector x error over the decoded pixels (px).
    x_rms_px: f64,
    points: usize,
    depth_rms_mm: f64,
    worst_mm: f64,
    /// Points more than 0.5 mm off the surface.
    outliers: usize,
    mean_sigma_mm: f64,
}

fn measure(sim: &PinholeSimulation) -> Figures {
    let control = RunControl::new();
    let rec = run_phase(&sim.measurement, &Params::default(), None, &control).expect("phase stages");
    let maps = match rec.projector.expect("a Gray code makes projector maps") {
        Ok(maps) => maps,
        Err(e) => panic!("projector maps: {e}"),
    };
    let truth = &sim.truth;
    let x = maps[0].x.as_ref().expect("projector x");
    let densest = sim.config.periods_px.iter().copied().fold(f64::INFINITY, f64::min);
    let (mut decoded, mut wrong_order, mut beyond_5_sigma, mut sum_sq) = (0, 0, 0, 0.0f64);
    for i in 0..truth.width * truth.height {
        let measured = f64::from(x.coordinate_px[i]);
        if measured.is_nan() {
            continue;
        }
        assert!(truth.is_lit(i), "pixel {i} decoded to {measured} but the projector does not light it");
        let e = measured - truth.projector_px[i][0];
        decoded += 1;
        wrong_order += usize::from(e.abs() >= densest / 2.0);
        beyond_5_sigma += usize::from(e.abs() > 5.0 * f64::from(x.sigma_px[i]));
        sum_sq += e * e;
    }
    let cloud = rig_point_cloud(&sim.measurement, &maps).expect("a calibrated rig's cloud");
    let (mut depth_sq, mut worst, mut outliers, mut sigma_sum) = (0.0f64, 0.0f64, 0, 0.0f64);
    for (p, (uv, sigma)) in cloud.xyz.iter().zip(cloud.pixel_uv.iter().zip(&cloud.sigma_z)) {
        let i = uv[1] as usize * truth.width + uv[0] as usize;
        let e = p[2] - truth.point_camera_mm[i][2];
        depth_sq += e * e;
        worst = worst.max(e.abs());
        outliers += usize::from(e.abs() > 0.5);
        sigma_sum += f64::from(*sigma);
    }
    let n = cloud.len().max(1) as f64;
    Figures {
        lit: truth.lit_count(),
        decoded,
        wrong_order,
        beyond_5_sigma,
        x_rms_px: (sum_sq / decoded.max(1) as f64).sqrt(),
        points: cloud.len(),
        depth_rms_mm: (depth_sq / n).sqrt(),
        worst_mm: worst,
        outliers,
        mean_sigma_mm: sigma_sum / n,
    }
}

fn run(config: &PinholeRigConfig) -> Figures {
    let sim = simulate_camera_projector(config, &RunControl::new()).expect("simulate");
    let f = measure(&sim);
    eprintln!(
        "{} {}-step gamma {}: {} of {} lit pixels decoded ({:.1} %), {} a period off, {} beyond 5 sigma, \
         x RMS {:.3} px; {} points, depth RMS {:.4} mm, worst {:.3} mm, {} beyond 0.5 mm, mean sigma_z {:.4} mm",
        config.scene,
        config.shifts,
        config.projector_gamma,
        f.decoded,
        f.lit,
        100.0 * f.decoded as f64 / f.lit.max(1) as f64,
        f.wrong_order,
        f.beyond_5_sigma,
        f.x_rms_px,
        f.points,
        f.depth_rms_mm,
        f.worst_mm,
        f.outliers,
        f.mean_sigma_mm
    );
    f
}

#[test]
fn a_simulated_plane_decodes_to_the_projector_points_that_lit_it_and_reconstructs_flat() {
    let f = run(&PinholeRigConfig::new(SceneKind::Flat));
    assert!(f.lit > 250_000, "the plane fills the image: {} lit", f.lit);
    assert!(f.decoded as f64 > 0.98 * f.lit as f64, "{f:?}");
    assert_eq!(f.wrong_order, 0, "{f:?}");
    assert!(f.beyond_5_sigma < f.decoded / 1000, "{f:?}");
    assert!(f.x_rms_px < 0.2, "{f:?}");
    assert!(f.depth_rms_mm < 0.02 && f.outliers == 0, "{f:?}");
    assert!(f.mean_sigma_mm > 0.3 * f.depth_rms_mm && f.mean_sigma_mm < 3.0 * f.depth_rms_mm, "{f:?}");
}

/// Issue 52's scenes: a sphere, steps (10 to 500 um blocks), a shiny
/// nickel watch plate that saturates the camera (3 steps leave no phase
/// where one sample saturates; 8 steps keep the pixel on its unsaturated
/// samples), and a projector with gamma 2.2, whose ripple of the 3-step
/// sets Sheen fits from their disagreement and takes out (uncorrected it
/// is 0.07 mm of depth error).
#[test]
fn sphere_steps_shiny_parts_and_a_gamma_of_2_2_decode_and_reconstruct() {
    let config = |scene, shifts: usize, gamma: f64| PinholeRigConfig {
        shifts,
        projector_gamma: gamma,
        ..PinholeRigConfig::new(scene)
    };
    // (scene, steps, gamma, least share of the lit pixels measured, largest depth RMS mm)
    let cases = [
        (SceneKind::Sphere, 3, 1.0, 0.98, 0.008),
        (SceneKind::StepGauge, 3, 1.0, 0.98, 0.008),
        (SceneKind::WatchPlate, 3, 1.0, 0.55, 0.01),
        (SceneKind::WatchPlate, 8, 1.0, 0.93, 0.006),
        (SceneKind::Flat, 3, 2.2, 0.98, 0.01),
        (SceneKind::WatchPlate, 3, 2.2, 0.55, 0.012),
    ];
    for (scene, shifts, gamma, share, rms) in cases {
        let f = run(&config(scene, shifts, gamma));
        let what = format!("{scene} {shifts}-step gamma {gamma}: {f:?}");
        assert!(f.decoded as f64 >= share * f.lit as f64, "{what}");
        assert_eq!(f.wrong_order, 0, "{what}");
        assert!(f.beyond_5_sigma <= f.decoded / 500, "{what}");
        assert!(f.depth_rms_mm <= rms && f.outliers == 0, "{what}");
    }
}
