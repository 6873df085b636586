//! Target detection on rendered targets: sub-pixel exactness against the
//! true projections, and targets that are partly hidden, cut by the image
//! border or of another size are reported, never mis-ordered.

use sheen::engine::calibration::detect::{DetectionError, DetectionParams, detect_target};
use sheen::engine::calibration::grid::GridError;
use sheen::engine::calibration::model::Pose;
use sheen::engine::calibration::target::{Target, TargetKind};
use sheen::engine::camera_model::{AffineCamera, Distortion};
use sheen::sim::target::{TargetLook, render_target, true_points_px};

use crate::util::telecentric_camera;

const W: usize = 640;
const H: usize = 480;
const PX_PER_MM: f64 = 26.7;

fn cameras(k1: f64) -> [AffineCamera; 2] {
    let d = (k1 != 0.0).then(|| Distortion { k1, ..Distortion::for_image(W, H) });
    let mut left = telecentric_camera(15.0, 0.0, PX_PER_MM, W, H, [0.0, 0.0]);
    let mut right = telecentric_camera(-15.0, 2.0, PX_PER_MM * 1.02, W, H, [9.0, -6.0]);
    left.distortion = d;
    right.distortion = d;
    [left, right]
}

fn target(kind: TargetKind) -> Target {
    Target { kind, rows: 9, cols: 11, pitch_mm: 1.5, dark_on_light: true }
}

/// The target tilted by `rotation_rad` about its centre, its centre at `centre_mm`.
pub fn centred_pose(target: &Target, rotation_rad: [f64; 3], centre_mm: [f64; 3]) -> Pose {
    let r = Pose::from_rotation_vector(rotation_rad, [0.0; 3]);
    let mid =
        [(target.cols as f64 - 1.0) * target.pitch_mm / 2.0, -(target.rows as f64 - 1.0) * target.pitch_mm / 2.0, 0.0];
    let rm = r.apply(mid);
    Pose { translation_mm: std::array::from_fn(|i| centre_mm[i] - rm[i]), ..r }
}

fn poses(t: &Target) -> Vec<Pose> {
    [
        ([0.0, 0.0, 0.05], [0.0, 0.0, 0.0]),
        ([0.4, 0.0, 0.0], [0.5, -0.4, 0.3]),
        ([0.0, -0.45, 0.2], [-0.6, 0.3, -0.2]),
        ([-0.3, 0.3, -0.25], [0.2, 0.0, 0.4]),
    ]
    .iter()
    .map(|&(r, c)| centred_pose(t, r, c))
    .collect()
}

fn worst_error(kind: TargetKind, k1: f64) -> f64 {
    let t = target(kind);
    let look = TargetLook::default();
    let mut worst = 0.0f64;
    for (k, pose) in poses(&t).iter().enumerate() {
        for (c, cam) in cameras(k1).iter().enumerate() {
            let img = render_target(cam, &t, pose, &look, 0, c, k);
            let found = detect_target(&img, &t, &DetectionParams::default())
                .unwrap_or_else(|e| panic!("{kind} pose {k} camera {c}: {e}"));
            let truth = true_points_px(cam, &t, pose);
            for (a, b) in found.points_px.iter().zip(&truth) {
                worst = worst.max((a[0] - b[0]).hypot(a[1] - b[1]));
            }
        }
    }
    worst
}

#[test]
fn dots_are_found_to_a_hundredth_of_a_pixel_without_noise() {
    let worst = worst_error(TargetKind::Circles, 1e-3);
    assert!(worst < 0.01, "worst dot error {worst} px");
}

#[test]
fn checkerboard_corners_are_found_to_a_hundredth_of_a_pixel_without_noise() {
    let worst = worst_error(TargetKind::Checkerboard, 1e-3);
    assert!(worst < 0.01, "worst corner error {worst} px");
}

/// Renders pose 1 of `kind` in the left camera, lets `edit` change the image,
/// and detects with `declared` rows and columns.
fn detect_edited(
    kind: TargetKind,
    pose: Pose,
    declared: (usize, usize),
    edit: impl Fn(&mut sheen::engine::calibration::gray_image::GrayImage),
) -> Result<Vec<[f64; 2]>, DetectionError> {
    let t = target(kind);
    let cam = &cameras(0.0)[0];
    let mut img = render_target(cam, &t, &pose, &TargetLook { noise_sigma_dn: 1.0, ..TargetLook::default() }, 3, 0, 1);
    edit(&mut img);
    let declared = Target { rows: declared.0, cols: declared.1, ..t };
    detect_target(&img, &declared, &DetectionParams::default()).map(|d| d.points_px)
}

#[test]
fn a_dot_hidden_by_dirt_is_reported_with_its_place() {
    let t = target(TargetKind::Circles);
    let pose = poses(&t)[1];
    let hidden = true_points_px(&cameras(0.0)[0], &t, &pose)[4 * 11 + 5];
    // A smear of plate-coloured dirt over dot (4, 5).
    let result = detect_edited(TargetKind::Circles, pose, (9, 11), |img| {
        for v in 0..img.height {
            for u in 0..img.width {
                if (u as f64 - hidden[0]).hypot(v as f64 - hidden[1]) < 14.0 {
                    img.pixels_dn[v * img.width + u] = 200.0;
                }
            }
        }
    });
    let located = |result: Result<Vec<[f64; 2]>, DetectionError>| match result {
        Err(DetectionError::Grid(GridError::Incomplete { found: 98, expected: 99, missing_px, .. })) => {
            assert!((missing_px[0][0] - hidden[0]).hypot(missing_px[0][1] - hidden[1]) < 1.0, "{missing_px:?}");
        }
        other => panic!("{other:?}"),
    };
    located(result);
    // Half covered: the dot is smaller than the others and left out.
    let result = detect_edited(TargetKind::Circles, pose, (9, 11), |img| {
        for v in 0..img.height {
            for u in 0..img.width {
                if (u as f64) < hidden[0] && (v as f64 - hidden[1]).abs() < 14.0 && (u as f64) > hidden[0] - 14.0 {
                    img.pixels_dn[v * img.width + u] = 200.0;
                }
            }
        }
    });
    located(result);
}

#[test]
fn a_missing_dot_among_clutter_is_located() {
    let t = target(TargetKind::Circles);
    let pose = poses(&t)[0];
    let truth = true_points_px(&cameras(0.0)[0], &t, &pose);
    // The speck sits in the middle of a grid cell, off the lattice.
    let (hidden, spare) = (truth[2 * 11 + 7], [(truth[0][0] + truth[12][0]) / 2.0, (truth[0][1] + truth[12][1]) / 2.0]);
    // Dot (2, 7) is painted over and a dot-like speck lies off the grid.
    let result = detect_edited(TargetKind::Circles, pose, (9, 11), |img| {
        for v in 0..img.height {
            for u in 0..img.width {
                let (x, y) = (u as f64, v as f64);
                if (x - hidden[0]).hypot(y - hidden[1]) < 14.0 {
                    img.pixels_dn[v * img.width + u] = 200.0;
                }
                if (x - spare[0]).hypot(y - spare[1]) < 9.0 {
                    img.pixels_dn[v * img.width + u] = 35.0;
                }
            }
        }
    });
    match result {
        Err(DetectionError::Grid(GridError::Incomplete {
            found: 98,
            lattice_rows: 9,
            lattice_cols: 11,
            missing_px,
            ..
        })) => {
            assert!((missing_px[0][0] - hidden[0]).hypot(missing_px[0][1] - hidden[1]) < 1.0, "{missing_px:?}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_target_cut_by_the_image_border_is_reported() {
    let t = target(TargetKind::Circles);
    // Shifted 5 mm to the right: the last columns leave the image.
    let pose = centred_pose(&t, [0.1, 0.0, 0.0], [5.0, 0.0, 0.0]);
    let result = detect_edited(TargetKind::Circles, pose, (9, 11), |_| {});
    assert!(matches!(result, Err(DetectionError::AtBorder { .. })), "{result:?}");
    let text = result.map(|_| ()).unwrap_err().to_string();
    assert!(text.contains("beyond the image"), "{text}");
}

#[test]
fn a_declared_grid_of_another_size_is_reported_not_forced() {
    let t = target(TargetKind::Circles);
    let pose = poses(&t)[2];
    for declared in [(8, 11), (9, 10), (11, 9)] {
        match detect_edited(TargetKind::Circles, pose, declared, |_| {}) {
            Err(DetectionError::Grid(GridError::WrongSize { found_rows: 9, found_cols: 11, .. })) => {}
            other => panic!("{declared:?}: {other:?}"),
        }
    }
    // More points declared than printed.
    match detect_edited(TargetKind::Checkerboard, poses(&t)[3], (10, 11), |_| {}) {
        Err(DetectionError::Grid(GridError::WrongSize {
            found_rows: 9, found_cols: 11, rows: 10, cols: 11, ..
        })) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn noisy_dots_are_still_found_precisely() {
    let t = target(TargetKind::Circles);
    let pose = poses(&t)[3];
    let cam = &cameras(1e-3)[1];
    let img = render_target(cam, &t, &pose, &TargetLook { noise_sigma_dn: 2.0, ..TargetLook::default() }, 9, 1, 3);
    let found = detect_target(&img, &t, &DetectionParams::default()).expect("detected");
    let truth = true_points_px(cam, &t, &pose);
    let rms =
        (found.points_px.iter().zip(&truth).map(|(a, b)| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sum::<f64>()
            / truth.len() as f64)
            .sqrt();
    assert!(rms < 0.02, "rms {rms} px");
    assert!((found.feature_size_px - 0.75 * PX_PER_MM).abs() < 0.2 * 0.75 * PX_PER_MM, "{}", found.feature_size_px);
}

#[test]
fn light_dots_on_a_dark_plate_are_found_too() {
    let t = Target { dark_on_light: false, ..target(TargetKind::Circles) };
    let pose = poses(&t)[2];
    let cam = &cameras(1e-3)[0];
    let look = TargetLook { plate_dn: 30.0, ink_dn: 220.0, surround_dn: 10.0, ..TargetLook::default() };
    let img = render_target(cam, &t, &pose, &look, 0, 0, 2);
    let found = detect_target(&img, &t, &DetectionParams::default()).expect("detected");
    let truth = true_points_px(cam, &t, &pose);
    let worst = found.points_px.iter().zip(&truth).map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1])).fold(0.0, f64::max);
    assert!(worst < 0.01, "worst {worst} px");
    // Declared the wrong way round, the plate's gaps are no dots.
    let wrong = Target { dark_on_light: true, ..t };
    match detect_target(&img, &wrong, &DetectionParams::default()) {
        Err(DetectionError::Grid(_) | DetectionError::AtBorder { .. }) => {}
        other => panic!("dots of the wrong polarity must leave no grid: {other:?}"),
    }
}
