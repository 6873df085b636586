//! Calibrations in m, mm, µm and nm (issue 23): the same rig in each unit,
//! written to a calibration file and read back, gives the same cloud and
//! height map in physical terms, and the height-uncertainty limit removes the
//! same points in every unit (a calibration in nm once switched it off).

use sheen::analysis::height_map::{RasterParams, camera_pitch_mm, height_map_from_cloud};
use sheen::engine::camera_model::{AffineCamera, StereoCalibration};
use sheen::engine::control::RunControl;
use sheen::engine::length_unit::LengthUnit;
use sheen::engine::pipeline::{Params, run};
use sheen::engine::point_cloud::PointCloud;
use sheen::io::calibration::{read_calibration, write_calibration};
use sheen::sim::{SceneKind, SimConfig, simulate};

/// The rig with world coordinates in `unit` instead of mm: `X_unit = X_mm /
/// f` with `f` mm per unit, so the 2x3 part of each `P` scales by `f` and the
/// pixel offsets stay; distortion acts on pixels and stays too.
fn rig_in(mm_rig: &StereoCalibration, unit: LengthUnit) -> StereoCalibration {
    let f = unit.mm_per_unit();
    let scaled = |cam: &AffineCamera| {
        let mut cam = cam.clone();
        for row in &mut cam.p {
            for coefficient in &mut row[..3] {
                *coefficient *= f;
            }
        }
        cam
    };
    StereoCalibration { unit, left: scaled(&mm_rig.left), right: scaled(&mm_rig.right), ..mm_rig.clone() }
}

/// A limit in µm between two neighbouring sigmas near the median with the
/// widest gap, so that rounding in another unit cannot move a point across it.
fn limit_between_sigmas_um(cloud: &PointCloud) -> f32 {
    let mut sigma_um: Vec<f64> = cloud.sigma_z.iter().map(|&s| f64::from(s) * cloud.um_per_unit()).collect();
    sigma_um.sort_by(f64::total_cmp);
    let n = sigma_um.len();
    let (lo, hi) = (n / 3..2 * n / 3)
        .map(|i| (sigma_um[i], sigma_um[i + 1]))
        .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)))
        .expect("enough points");
    assert!(hi > lo, "sigmas near the median are all equal: {lo}");
    ((lo + hi) / 2.0) as f32
}

#[test]
fn calibrations_in_m_mm_um_and_nm_give_the_same_cloud_and_map() {
    let mut config = SimConfig::new(SceneKind::StepGauge, 160, 120);
    config.noise_sigma_dn = 1.5;
    let mut sim = simulate(&config, &RunControl::new()).expect("simulate");
    let mm_rig = sim.measurement.calibration.clone().expect("the simulator's true calibration");
    assert_eq!(mm_rig.unit, LengthUnit::Mm);

    let cloud_of = |m: &sheen::engine::fringe::Measurement, max_sigma_z_um| {
        let params = Params { max_sigma_z_um, ..Params::default() };
        run(m, &params, None, &RunControl::new()).expect("run").stereo.expect("stereo").cloud
    };
    let unlimited = cloud_of(&sim.measurement, None);
    let limit_um = limit_between_sigmas_um(&unlimited);
    let reference = cloud_of(&sim.measurement, Some(limit_um));
    assert!(
        reference.len() < unlimited.len() * 3 / 4 && reference.len() > unlimited.len() / 4,
        "the limit {limit_um} um must remove a good share of the points: {} of {}",
        reference.len(),
        unlimited.len()
    );
    let reference_map = height_map_from_cloud(
        &reference,
        &RasterParams { pitch_mm: Some(camera_pitch_mm(&mm_rig.left, LengthUnit::Mm).unwrap()), ..Default::default() },
    )
    .expect("map")
    .map;

    let dir = tempfile::tempdir().expect("tempdir");
    for unit in [LengthUnit::M, LengthUnit::Mm, LengthUnit::Um, LengthUnit::Nm] {
        // Through the file, as a user's calibration arrives.
        let path = dir.path().join(format!("calibration_{unit}.json"));
        write_calibration(&path, &rig_in(&mm_rig, unit)).expect("write");
        let (rig, warnings) = read_calibration(&path).expect("read");
        assert!(warnings.is_empty(), "{unit}: {warnings:?}");
        assert_eq!(rig.unit, unit);
        let text = std::fs::read_to_string(&path).expect("text");
        assert!(text.contains(&format!("\"unit\": \"{unit}\"")), "{text}");

        sim.measurement.calibration = Some(rig.clone());
        let cloud = cloud_of(&sim.measurement, Some(limit_um));
        assert_eq!(cloud.unit, unit);
        assert_eq!(cloud.len(), reference.len(), "{unit}: the sigma limit must keep the same points");
        // The same pixels (back through the rectification: to rounding).
        for (i, (a, b)) in cloud.pixel_uv.iter().zip(&reference.pixel_uv).enumerate() {
            assert!((a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4, "{unit} point {i}: {a:?} vs {b:?} px");
        }
        let f = unit.mm_per_unit();
        for (i, (p, q)) in cloud.xyz.iter().zip(&reference.xyz).enumerate() {
            for k in 0..3 {
                assert!((p[k] * f - q[k]).abs() <= 1e-9 * (1.0 + q[k].abs()), "{unit} point {i}: {p:?} vs {q:?} mm");
            }
        }
        for (s, r) in cloud.sigma_z.iter().zip(&reference.sigma_z) {
            let s_mm = f64::from(*s) * f;
            assert!((s_mm - f64::from(*r)).abs() <= 1e-5 * f64::from(*r), "{unit}: sigma {s_mm} vs {r} mm");
        }

        // The height map is in mm whatever the calibration's unit.
        let pitch_mm = camera_pitch_mm(&rig.left, rig.unit).expect("pitch");
        assert!((pitch_mm - reference_map.pitch_mm).abs() <= 1e-12 * pitch_mm, "{unit}: pitch {pitch_mm} mm");
        let map = height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(pitch_mm), ..Default::default() })
            .expect("map")
            .map;
        assert_eq!((map.width, map.height, map.unit), (reference_map.width, reference_map.height, LengthUnit::Mm));
        assert!((map.origin_x_mm - reference_map.origin_x_mm).abs() < 1e-9, "{unit}");
        assert!((map.origin_y_mm - reference_map.origin_y_mm).abs() < 1e-9, "{unit}");
        assert_eq!(map.valid_count(), reference_map.valid_count(), "{unit}");
        for (a, b) in map.z.iter().zip(&reference_map.z) {
            assert!(a.is_nan() && b.is_nan() || (a - b).abs() <= 1e-6, "{unit}: {a} vs {b} mm");
        }
    }
}
