//! Rectification, matching (Eq. 7) and triangulation on analytic phase maps of
//! known surfaces seen by a rig whose right camera is rolled, scaled and offset.

use std::f64::consts::TAU;

use sheen::engine::camera_model::{AffineCamera, Distortion, StereoCalibration};
use sheen::engine::control::RunControl;
use sheen::engine::rectify::rectify;
use sheen::engine::stereo::{LeftAttributes, PhaseMapView, StereoResult, reconstruct};

use crate::util::{paper_like_rig, surface_point};

/// Projector: 912 px over 30 mm in X, densest period 12 px.
fn absolute_phase_rad(x_mm: f64) -> f64 {
    let x_p = (x_mm + 15.0) / (30.0 / 912.0);
    TAU * x_p / 12.0
}

/// The phase map a camera observes of `height`, pixel centres through the
/// camera's distortion (observed -> ideal) onto the surface.
fn phase_map(cam: &AffineCamera, height: &impl Fn(f64, f64) -> f64) -> Vec<f32> {
    let mut map = vec![f32::NAN; cam.width * cam.height];
    for v in 0..cam.height {
        for u in 0..cam.width {
            let ideal = cam.ideal_from_observed([u as f64, v as f64]);
            if let Some(x) = surface_point(cam, ideal[0], ideal[1], height) {
                map[v * cam.width + u] = absolute_phase_rad(x[0]) as f32;
            }
        }
    }
    map
}

struct Outcome {
    rms_um: f64,
    max_um: f64,
    points: usize,
    integer_pixels: bool,
}

fn reconstruct_surface(
    calib_truth: &StereoCalibration,
    calib_used: &StereoCalibration,
    height: impl Fn(f64, f64) -> f64,
) -> Outcome {
    let sigma = vec![0.01f32; calib_truth.left.width * calib_truth.left.height];
    let result = reconstruct_with(calib_truth, calib_used, &height, &sigma, f64::INFINITY);
    let cloud = &result.cloud;
    let errors: Vec<f64> = cloud.xyz.iter().map(|p| (p[2] - height(p[0], p[1])) * 1e3).collect();
    let rms_um = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    let max_um = errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    let integer_pixels = cloud.pixel_uv.iter().all(|uv| uv[0].fract() == 0.0 && uv[1].fract() == 0.0);
    Outcome { rms_um, max_um, points: cloud.len(), integer_pixels }
}

/// Stereo of `height` with the left camera's phase sigma `left_sigma` (the
/// right camera's 0.01 rad) and a height-uncertainty limit.
fn reconstruct_with(
    calib_truth: &StereoCalibration,
    calib_used: &StereoCalibration,
    height: &impl Fn(f64, f64) -> f64,
    left_sigma: &[f32],
    max_sigma_z: f64,
) -> StereoResult {
    let left = phase_map(&calib_truth.left, height);
    let right = phase_map(&calib_truth.right, height);
    let sigma = vec![0.01f32; left.len()];
    let (w, h) = (calib_truth.left.width, calib_truth.left.height);
    let source = vec![0i8; w * h];
    let modulation = vec![50.0f32; w * h];
    // Each pixel's texture names the pixel, so a point shows whose attributes it took.
    let texture: Vec<f32> = (0..w * h).map(|i| i as f32).collect();
    let order_evidence = vec![0u8; w * h];
    let attributes = LeftAttributes {
        source_set: &source,
        periods_px: &[12.0],
        modulation_dn: vec![&modulation],
        texture_dn: &texture,
        order_evidence: &order_evidence,
    };
    let lv = PhaseMapView { width: w, height: h, phase_rad: &left, sigma_rad: left_sigma };
    let rv = PhaseMapView { width: w, height: h, phase_rad: &right, sigma_rad: &sigma };
    reconstruct(
        calib_used,
        &lv,
        &rv,
        &attributes,
        max_sigma_z,
        sheen::engine::continuity::Continuity::default(),
        &RunControl::new(),
    )
    .expect("stereo")
}

const W: usize = 160;
const H: usize = 120;
/// Pixels per mm so the 160 px field spans about 20 mm.
const PX_PER_MM: f64 = 8.0;

#[test]
fn tilted_plane_is_reconstructed_exactly() {
    let rig = paper_like_rig(W, H, PX_PER_MM);
    let plane = |x: f64, y: f64| 0.02 * x - 0.015 * y + 0.3;
    let out = reconstruct_surface(&rig, &rig, plane);
    assert!(out.points > W * H * 7 / 10, "points {}", out.points);
    assert!(out.rms_um < 0.01, "rms {} um", out.rms_um);
    assert!(out.max_um < 0.05, "max {} um", out.max_um);
    assert!(out.integer_pixels, "the unrolled left camera keeps its exact pixels");
}

#[test]
fn curved_surface_is_reconstructed_within_interpolation_error() {
    let rig = paper_like_rig(W, H, PX_PER_MM);
    let bump = |x: f64, y: f64| 0.5 * (-(x * x + y * y) / 40.0).exp();
    let out = reconstruct_surface(&rig, &rig, bump);
    assert!(out.points > W * H * 6 / 10, "points {}", out.points);
    assert!(out.rms_um < 0.1, "rms {} um", out.rms_um);
}

#[test]
fn rectified_rows_are_epipolar_lines() {
    let rig = paper_like_rig(W, H, PX_PER_MM);
    let rect = rectify(&rig).expect("rectify");
    // Any world point lands on the same rectified row in both cameras.
    for &x in &[[0.0, 0.0, 0.0], [3.0, -2.0, 0.7], [-5.5, 4.0, -0.4]] {
        let rl = rect.left.rect_pixel(rig.left.project(x));
        let rr = rect.right.rect_pixel(rig.right.project(x));
        assert!((rl[1] - rr[1]).abs() < 1e-9, "{rl:?} vs {rr:?}");
    }
    assert!(rect.left.is_integer_shift());
    assert!(!rect.right.is_integer_shift(), "the rolled right camera needs a real resampling");
}

/// Whether a match becomes a point is decided with the left camera's sigma
/// at the match's own pixel: on a rig whose left map is a shifted copy of the
/// image (the usual left camera), pixels made a hundred times noisier get no
/// point and the others keep theirs, each with its own pixel's attributes.
#[test]
fn a_point_is_kept_by_the_sigma_of_its_own_left_pixel() {
    let rig = paper_like_rig(W, H, PX_PER_MM);
    let rect = rectify(&rig).expect("rectify");
    assert!(rect.left.is_integer_shift());
    assert_ne!(rect.left.to_rect[1][2], 0.0, "the left map shifts the rows");
    let noisy = |u: usize, v: usize| (u * 7 + v * 3).is_multiple_of(5);
    let sigma: Vec<f32> = (0..W * H).map(|i| if noisy(i % W, i / W) { 1.0 } else { 0.01 }).collect();
    let plane = |x: f64, y: f64| 0.02 * x - 0.015 * y + 0.3;
    let result = reconstruct_with(&rig, &rig, &plane, &sigma, 0.01);
    let cloud = &result.cloud;
    for (uv, &texture) in cloud.pixel_uv.iter().zip(&cloud.intensity_dn) {
        assert!(!noisy(uv[0] as usize, uv[1] as usize), "a point at noisy pixel {uv:?}");
        assert_eq!(texture, (uv[1] as usize * W + uv[0] as usize) as f32, "the attributes of pixel {uv:?}");
    }
    let quiet = (0..W * H).filter(|&i| !noisy(i % W, i / W)).count();
    assert!(cloud.len() > quiet * 7 / 10, "{} points of {quiet} quiet pixels", cloud.len());
    assert!(result.too_uncertain > W * H / 5 * 7 / 10, "{} left out", result.too_uncertain);
}

/// Distortion in the calibration is honoured when resampling; ignoring it
/// costs accuracy, which is what proves it is used.
#[test]
fn lens_distortion_is_honoured() {
    let mut rig = paper_like_rig(W, H, PX_PER_MM);
    for cam in [&mut rig.left, &mut rig.right] {
        let mut d = Distortion::for_image(cam.width, cam.height);
        d.k1 = 2e-3;
        cam.distortion = Some(d);
    }
    let plane = |x: f64, y: f64| 0.01 * x + 0.2 + 0.0 * y;
    let honoured = reconstruct_surface(&rig, &rig, plane);
    assert!(honoured.rms_um < 0.05, "rms with distortion honoured {} um", honoured.rms_um);
    let mut ignorant = rig.clone();
    ignorant.left.distortion = None;
    ignorant.right.distortion = None;
    let ignored = reconstruct_surface(&rig, &ignorant, plane);
    assert!(ignored.rms_um > 20.0 * honoured.rms_um.max(0.01), "ignoring distortion: {} um", ignored.rms_um);
}

/// A step seen by both cameras: no point bridges the discontinuity (no
/// invented heights between the two levels).
#[test]
fn step_edge_produces_no_bridging_points() {
    let rig = paper_like_rig(W, H, PX_PER_MM);
    let step = |x: f64, _y: f64| if x > 0.0 { 0.5 } else { 0.0 };
    let out = reconstruct_surface(&rig, &rig, step);
    assert!(out.max_um < 0.1, "max error {} um: a point was invented on the step", out.max_um);
    assert!(out.points > W * H / 2);
}

/// Strict matching extends a right run to the edge its surface stops at (the
/// resampling leaves the cell that straddles the step invalid), but only for a
/// left pixel that continues its matched neighbour's surface: one on the far
/// side of a step in the left row, one beyond the reach of a run, or one past a
/// run whose phase curves (a silhouette) stays unmatched, and plain matching
/// never extends.
#[test]
fn strict_matching_extends_a_run_to_its_edge_only_for_the_same_surface() {
    use sheen::engine::continuity::Continuity;
    use sheen::engine::stereo_match::match_rows;
    // Right row: surface A (1 rad/px) to column 9, the straddling column 10
    // left invalid, surface B from column 11 at 30 rad higher.
    let right: Vec<f32> = (0..20)
        .map(|c| {
            if c < 10 {
                c as f32
            } else if c == 10 {
                f32::NAN
            } else {
                30.0 + c as f32
            }
        })
        .collect();
    let sigma = vec![0.01f32; right.len()];
    let columns = |left: &[f32], right: &[f32], continuity: &Continuity| {
        let m = match_rows(left, left.len(), right, &sigma, right.len(), 1, continuity);
        (m.right_column, m.stats)
    };
    // Continuing A past its last sample: extended by 0.3 px and by 0.9 px.
    for end in [9.3f32, 9.9] {
        let (cols, stats) = columns(&[end - 2.0, end - 1.0, end], &right, &Continuity::default());
        assert!((cols[2] - end).abs() < 1e-5, "{cols:?}");
        assert_eq!((stats.extended_to_edge, stats.unmatched), (1, 0));
    }
    // Reaching B's first sample from below, its matched neighbour on the
    // right; one pixel further would be beyond reach.
    let (cols, stats) = columns(&[39.6, 40.6, 41.6, 42.6], &right, &Continuity::default());
    assert!(cols[0].is_nan() && (cols[1] - 10.6).abs() < 1e-5, "{cols:?}");
    assert_eq!(stats.extended_to_edge, 1);
    // Beyond a pixel's reach: refused.
    let (cols, _) = columns(&[7.1, 8.1, 9.1, 10.1], &right, &Continuity::default());
    assert!((cols[2] - 9.1).abs() < 1e-5 && cols[3].is_nan(), "{cols:?}");
    // A jump in the left row (a surface the right camera does not see): refused.
    let (cols, stats) = columns(&[7.3, 8.3, 9.95], &right, &Continuity::default());
    assert!(cols[2].is_nan(), "{cols:?}");
    assert_eq!((stats.extended_to_edge, stats.unmatched), (0, 1));
    // A run whose phase steepens towards its end (a silhouette): refused.
    let mut curved = right.clone();
    for (c, step) in [(8, 1.2f32), (9, 1.6)] {
        curved[c] = curved[c - 1] + step;
    }
    let (cols, _) = columns(&[7.5, 8.5, 9.5, 10.3], &curved, &Continuity::default());
    assert!(!cols[2].is_nan() && cols[3].is_nan(), "{cols:?}");
    // Plain matching never extends.
    let (cols, stats) = columns(&[7.3, 8.3, 9.3], &right, &Continuity::plain());
    assert!(cols[2].is_nan() && stats.extended_to_edge == 0, "{cols:?}");
}
