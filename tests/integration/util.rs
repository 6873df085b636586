//! Shared builders of synthetic inputs with known truth.

use std::f64::consts::TAU;

use sheen::engine::camera_model::{AffineCamera, StereoCalibration};
use sheen::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Measurement, next_measurement_id};

/// A stack of `w x h` pixels whose sample k at pixel i is `intensity(i, k)`,
/// rounded and clipped to `[0, max]` and stored as u8 when `max <= 255`.
pub fn stack_from_fn(
    w: usize,
    h: usize,
    shifts: usize,
    max: u16,
    intensity: impl Fn(usize, usize) -> f64,
) -> FringeStack {
    let planes: Vec<Vec<f64>> = (0..shifts).map(|k| (0..w * h).map(|i| intensity(i, k)).collect()).collect();
    let clip = |v: f64| v.round().clamp(0.0, f64::from(max));
    if max <= 255 {
        FringeStack::from_planes_u8(w, h, planes.iter().map(|p| p.iter().map(|&v| clip(v) as u8).collect()).collect())
    } else {
        FringeStack::from_planes_u16(w, h, planes.iter().map(|p| p.iter().map(|&v| clip(v) as u16).collect()).collect())
    }
}

/// `I_k = a + b cos(phi + delta_k)`.
pub fn sinusoid(a: f64, b: f64, phi: f64, delta: f64) -> f64 {
    a + b * (phi + delta).cos()
}

/// Smallest signed difference of two phases.
pub fn phase_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    if d > std::f64::consts::PI { d - TAU } else { d }
}

/// A telecentric camera at `theta_deg` from vertical in the X-Z plane (positive:
/// on the left, looking right), rolled by `roll_deg` about its axis, with
/// `px_per_mm` magnification and the field centre at pixel (cx, cy).
pub fn telecentric_camera(
    theta_deg: f64,
    roll_deg: f64,
    px_per_mm: f64,
    w: usize,
    h: usize,
    offset_px: [f64; 2],
) -> AffineCamera {
    let t = theta_deg.to_radians();
    let ex = [t.cos(), 0.0, t.sin()];
    let ey = [0.0, -1.0, 0.0];
    let (c, s) = (roll_deg.to_radians().cos(), roll_deg.to_radians().sin());
    let r1: [f64; 3] = std::array::from_fn(|i| px_per_mm * (c * ex[i] - s * ey[i]));
    let r2: [f64; 3] = std::array::from_fn(|i| px_per_mm * (s * ex[i] + c * ey[i]));
    let cx = (w as f64 - 1.0) / 2.0 + offset_px[0];
    let cy = (h as f64 - 1.0) / 2.0 + offset_px[1];
    AffineCamera { width: w, height: h, p: [[r1[0], r1[1], r1[2], cx], [r2[0], r2[1], r2[2], cy]], distortion: None }
}

/// A rig like the paper's: +-15 deg, the right camera rolled, scaled and offset.
pub fn paper_like_rig(w: usize, h: usize, px_per_mm: f64) -> StereoCalibration {
    StereoCalibration {
        unit: sheen::engine::length_unit::LengthUnit::Mm,
        left: telecentric_camera(15.0, 0.0, px_per_mm, w, h, [0.0, 0.0]),
        right: telecentric_camera(-15.0, 2.0, px_per_mm * 1.02, w, h, [7.3, -4.6]),
        rms_reprojection_px: None,
        scale_uncertainty: None,
    }
}

/// The first point where the viewing line of ideal pixel `(u, v)` meets the
/// surface `z = height(x, y)` coming from above, by marching down and
/// bisecting; `None` when the ray ends on a vertical wall (a discontinuity),
/// which a real camera sees unlit.
pub fn surface_point(cam: &AffineCamera, u: f64, v: f64, height: &impl Fn(f64, f64) -> f64) -> Option<[f64; 3]> {
    let p = &cam.p;
    let (a, b, c, d) = (p[0][0], p[0][1], p[1][0], p[1][1]);
    let det = a * d - b * c;
    let xy_at = |z: f64| {
        let r0 = u - p[0][3] - p[0][2] * z;
        let r1 = v - p[1][3] - p[1][2] * z;
        [(d * r0 - b * r1) / det, (-c * r0 + a * r1) / det]
    };
    let above = |z: f64| {
        let xy = xy_at(z);
        z - height(xy[0], xy[1])
    };
    let (top, bottom, step) = (3.0, -3.0, 1e-3);
    let mut hi = top;
    let mut lo = top;
    while lo > bottom {
        lo = hi - step;
        if above(lo) <= 0.0 {
            break;
        }
        hi = lo;
    }
    if above(lo) > 0.0 {
        return None;
    }
    for _ in 0..80 {
        let mid = 0.5 * (hi + lo);
        if above(mid) > 0.0 { hi = mid } else { lo = mid }
    }
    let xy_hi = xy_at(hi);
    let xy_lo = xy_at(lo);
    if (height(xy_hi[0], xy_hi[1]) - height(xy_lo[0], xy_lo[1])).abs() > 1e-9 {
        return None;
    }
    Some([xy_lo[0], xy_lo[1], height(xy_lo[0], xy_lo[1])])
}

/// One camera, `w x h`, projector column `x_p(i)` at pixel i, and per set
/// and pixel the offset and amplitude `(A, B)` of the fringes.
pub fn measurement(
    w: usize,
    h: usize,
    max: u16,
    periods: &[f64],
    shifts: usize,
    x_p: impl Fn(usize) -> f64,
    offset_amplitude: impl Fn(usize, usize) -> (f64, f64),
) -> Measurement {
    let sets: Vec<FringeSetInfo> = periods.iter().map(|&p| FringeSetInfo::uniform(p, shifts)).collect();
    let stacks = sets
        .iter()
        .enumerate()
        .map(|(m, set)| {
            stack_from_fn(w, h, shifts, max, |i, k| {
                let (a, b) = offset_amplitude(m, i);
                sinusoid(a, b, TAU * x_p(i) / set.period_px, set.phase_shifts_rad[k])
            })
        })
        .collect();
    Measurement {
        bit_depth: if max > 255 { 16 } else { 8 },
        saturation_level: max,
        sets,
        cameras: vec![CameraFringes { name: "left".into(), width: w, height: h, stacks }],
        calibration: None,
        label: "synthetic".into(),
        projector: None,
        id: next_measurement_id(),
    }
}
