//! Acceptance tests of the simulator's physics (issue 4): truth geometry,
//! defocus contrast, the intensity model, saturation per set, determinism,
//! occlusion, and a noise-free reconstruction through the engine.

use super::*;
use crate::engine::fringe::Samples;

fn small(scene: SceneKind) -> SimConfig {
    SimConfig::new(scene, 256, 192)
}

#[test]
fn truth_points_project_to_their_pixel_centres() {
    let sim = simulate(&small(SceneKind::StepGauge), &RunControl::new()).unwrap();
    let calib = sim.measurement.calibration.as_ref().unwrap();
    for (truth, cam) in [(&sim.truth.left, &calib.left), (&sim.truth.right, &calib.right)] {
        let mut worst: f64 = 0.0;
        for (i, p) in truth.point_mm.iter().enumerate() {
            let [u, v] = cam.project_observed(*p);
            worst = worst.max((u - (i % 256) as f64).abs()).max((v - (i / 256) as f64).abs());
        }
        assert!(worst < 1e-9, "worst {worst}");
    }
}

/// Per pixel and set: the number of saturated samples.
#[test]
fn engine_reconstructs_the_flat_to_well_under_a_tenth_of_a_micrometre() {
    use crate::engine::pipeline::{Params, run};
    let config = SimConfig { bits: 16, ..small(SceneKind::Flat) };
    let sim = simulate(&config, &RunControl::new()).unwrap();
    let rec = run(&sim.measurement, &Params::default(), None, &RunControl::new()).unwrap();
    let stereo = rec.stereo.as_ref().unwrap();
    let cloud = &stereo.cloud;
    let mut sum2 = 0.0;
    let mut worst: f64 = 0.0;
    for p in &cloud.xyz {
        let dz = p[2] - sim.truth.scene.height_mm(p[0], p[1]);
        sum2 += dz * dz;
        worst = worst.max(dz.abs());
    }
    let rms_um = (sum2 / cloud.len() as f64).sqrt() * 1e3;
    assert!(cloud.len() > 256 * 192 * 8 / 10, "{} points", cloud.len());
    assert!(rms_um < 0.02, "rms {rms_um} um");
    assert!(worst < 1e-4, "worst {} um", worst * 1e3);
}

#[test]
fn demo_is_a_complete_eight_bit_watch_plate_measurement() {
    let sim = demo(96, 72);
    let m = &sim.measurement;
    assert_eq!(sim.config.scene, SceneKind::WatchPlate);
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
