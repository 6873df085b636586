//! Epipolar rectification of two telecentric cameras (the paper's section 2.3,
//! after Hu et al. 2019).
//!
//! For affine cameras all epipolar planes are parallel: they contain both
//! viewing directions, so their common normal is `n = d_L x d_R` and a world
//! point's epipolar plane is fixed by `n . X` alone. Because `n` is orthogonal
//! to `d`, it lies in the row space of the camera's 2x3 part `M`: `n = M^T w`
//! with `w = (M M^T)^-1 M n`, so `n . X = w . (p - t)` for the ideal pixel `p`
//! of X. Each image therefore needs only a 2D affine map to make epipolar lines
//! its rows. The left (main) camera's map is a pure rotation with an integer
//! offset, so where the left image rows already are epipolar lines (the usual
//! mounting) its rectified image *is* the camera image and every point keeps
//! its exact left pixel. The right map is a similarity whose rows follow the
//! same `n . X` scale.

use super::camera_model::{AffineCamera, StereoCalibration, cross, dot};

/// Affine map between a camera's ideal pixels and its rectified image.
#[derive(Clone, Debug, PartialEq)]
pub struct RectMap {
    /// Rectified image width in pixels.
    pub width: usize,
    /// `(c, r)^T = to_rect (u, v, 1)^T`.
    pub to_rect: [[f64; 3]; 2],
    /// `(u, v)^T = from_rect (c, r, 1)^T`.
    pub from_rect: [[f64; 3]; 2],
}

impl RectMap {
    fn new(width: usize, to_rect: [[f64; 3]; 2]) -> Self {
        let [[a, b, e], [c, d, f]] = to_rect;
        let det = a * d - b * c;
        let inv = [[d / det, -b / det], [-c / det, a / det]];
        let from_rect = [
            [inv[0][0], inv[0][1], -(inv[0][0] * e + inv[0][1] * f)],
            [inv[1][0], inv[1][1], -(inv[1][0] * e + inv[1][1] * f)],
        ];
        Self { width, to_rect, from_rect }
    }

    #[inline]
    pub fn ideal_pixel(&self, c: f64, r: f64) -> [f64; 2] {
        let m = &self.from_rect;
        [m[0][0] * c + m[0][1] * r + m[0][2], m[1][0] * c + m[1][1] * r + m[1][2]]
    }

    #[inline]
    pub fn rect_pixel(&self, p: [f64; 2]) -> [f64; 2] {
        let m = &self.to_rect;
        [m[0][0] * p[0] + m[0][1] * p[1] + m[0][2], m[1][0] * p[0] + m[1][1] * p[1] + m[1][2]]
    }

    /// True when the map sends integer pixels to integer pixels one-to-one
    /// (identity up to an integer shift).
    pub fn is_integer_shift(&self) -> bool {
        let m = &self.to_rect;
        (m[0][0] - 1.0).abs() < 1e-12
            && m[0][1].abs() < 1e-12
            && m[1][0].abs() < 1e-12
            && (m[1][1] - 1.0).abs() < 1e-12
            && (m[0][2] - m[0][2].round()).abs() < 1e-9
            && (m[1][2] - m[1][2].round()).abs() < 1e-9
    }
}

/// The rectified geometry of the rig.
#[derive(Clone, Debug, PartialEq)]
pub struct Rectification {
    pub left: RectMap,
    pub right: RectMap,
    /// Rectified rows seen by both cameras.
    pub rows: usize,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RectifyError {
    #[error("the left and right cameras share no field of view (no common epipolar rows)")]
    NoCommonField,
}

/// `w` with `M^T w = n` for a camera with rows `r1`, `r2`.
fn row_space_coefficients(cam: &AffineCamera, n: [f64; 3]) -> [f64; 2] {
    let (r1, r2) = cam.rows();
    let g = [[dot(r1, r1), dot(r1, r2)], [dot(r1, r2), dot(r2, r2)]];
    let rhs = [dot(r1, n), dot(r2, n)];
    let det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    [(g[1][1] * rhs[0] - g[0][1] * rhs[1]) / det, (-g[1][0] * rhs[0] + g[0][0] * rhs[1]) / det]
}

/// Minimum-norm world displacement that moves a camera's image by `e`.
fn world_step(cam: &AffineCamera, e: [f64; 2]) -> [f64; 3] {
    let (r1, r2) = cam.rows();
    let g = [[dot(r1, r1), dot(r1, r2)], [dot(r1, r2), dot(r2, r2)]];
    let det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    let y = [(g[1][1] * e[0] - g[0][1] * e[1]) / det, (-g[1][0] * e[0] + g[0][0] * e[1]) / det];
    [r1[0] * y[0] + r2[0] * y[1], r1[1] * y[0] + r2[1] * y[1], r1[2] * y[0] + r2[2] * y[1]]
}

fn corners(cam: &AffineCamera) -> [[f64; 2]; 4] {
    let (w, h) = ((cam.width as f64) - 1.0, (cam.height as f64) - 1.0);
    // Ideal pixels of the image corners; distortion moves them by a few pixels
    // at most, which the range margin below absorbs.
    [[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]].map(|p| cam.ideal_from_observed(p))
}

/// Computes the rectifying maps of a validated calibration.
pub fn rectify(calib: &StereoCalibration) -> Result<Rectification, RectifyError> {
    let (left, right) = (&calib.left, &calib.right);
    let dl = left.viewing_direction();
    let dr = right.viewing_direction();
    // The sign of n is free; pick the one whose rectified rows run down the
    // left image (columns then run along +u), so a left camera whose rows are
    // already epipolar is rectified by an integer shift, not a 180 degree
    // turn. With d_L x d_R alone, a rig with the left camera on the left (the
    // paper's) came out upside down, its phase falling along the rectified
    // rows, and the matcher (which follows rising phase) matched nothing.
    let n = cross(dl, dr);
    let w = row_space_coefficients(left, n);
    let n = if w[1] < 0.0 || (w[1] == 0.0 && w[0] > 0.0) { [-n[0], -n[1], -n[2]] } else { n };
    let wl = row_space_coefficients(left, n);
    let wr = row_space_coefficients(right, n);
    let s = 1.0 / wl[0].hypot(wl[1]);
    let wl_hat = [wl[0] * s, wl[1] * s];
    let q = [wr[0] * s, wr[1] * s];
    let tl = [left.p[0][3], left.p[1][3]];
    let tr = [right.p[0][3], right.p[1][3]];

    // Column directions: perpendicular to the row gradient, oriented so both
    // cameras' columns run the same way through the scene.
    let perp = |w: [f64; 2]| [w[1], -w[0]];
    let col_l = perp(wl_hat);
    let mut col_r = perp(q);
    let across = cross(n, [dl[0] + dr[0], dl[1] + dr[1], dl[2] + dr[2]]);
    let scale_r = q[0].hypot(q[1]);
    let unit_r = [col_r[0] / scale_r, col_r[1] / scale_r];
    if dot(world_step(right, unit_r), across) * dot(world_step(left, col_l), across) < 0.0 {
        col_r = [-col_r[0], -col_r[1]];
    }

    // Raw rectified coordinates (before offsets) of each image's corners.
    let row_l = |p: [f64; 2]| wl_hat[0] * p[0] + wl_hat[1] * p[1];
    let row_r = |p: [f64; 2]| {
        q[0] * p[0] + q[1] * p[1] + (wl_hat[0] * tl[0] + wl_hat[1] * tl[1]) - (q[0] * tr[0] + q[1] * tr[1])
    };
    let range = |vals: [f64; 4]| {
        (vals.iter().copied().fold(f64::INFINITY, f64::min), vals.iter().copied().fold(f64::NEG_INFINITY, f64::max))
    };
    let cl = corners(left);
    let cr = corners(right);
    let (l_lo, l_hi) = range(cl.map(row_l));
    let (r_lo, r_hi) = range(cr.map(row_r));
    let (lo, hi) = (l_lo.max(r_lo), l_hi.min(r_hi));
    if !(hi - lo >= 1.0) {
        return Err(RectifyError::NoCommonField);
    }
    let r0 = -lo.floor();
    let rows = (hi + r0).floor() as usize + 1;

    let col_of = |dir: [f64; 2], p: [f64; 2]| dir[0] * p[0] + dir[1] * p[1];
    let (cl_lo, cl_hi) = range(cl.map(|p| col_of(col_l, p)));
    let c0_l = -cl_lo.floor();
    let width_l = (cl_hi + c0_l).floor() as usize + 1;
    let (cr_lo, cr_hi) = range(cr.map(|p| col_of(col_r, p)));
    let c0_r = -cr_lo;
    let width_r = (cr_hi + c0_r).floor() as usize + 1;

    let left_map = RectMap::new(width_l, [[col_l[0], col_l[1], c0_l], [wl_hat[0], wl_hat[1], r0]]);
    let right_offset = (wl_hat[0] * tl[0] + wl_hat[1] * tl[1]) - (q[0] * tr[0] + q[1] * tr[1]) + r0;
    let right_map = RectMap::new(width_r, [[col_r[0], col_r[1], c0_r], [q[0], q[1], right_offset]]);
    Ok(Rectification { left: left_map, right: right_map, rows })
}

/// Largest phase difference (rad) between neighbours that bilinear
/// resampling bridges; larger ones are discontinuities, not slopes.
pub const RESAMPLE_JUMP_LIMIT_RAD: f32 = std::f32::consts::PI;

/// Resamples a camera's absolute phase map into its rectified frame.
///
/// Each rectified pixel goes to its ideal camera pixel (`from_rect`) and then
/// through the lens distortion to where the observed map is sampled: one
/// resampling, no inversion. The value is the bilinear interpolation of the
/// neighbours that carry weight, and only if all of them are valid and span
/// less than `jump_limit`: interpolating across a hole or a step would invent a
/// phase that no surface point has.
pub fn resample_phase(map: &[f32], cam: &AffineCamera, rect: &RectMap, rows: usize, jump_limit: f32) -> Vec<f32> {
    use rayon::prelude::*;
    let (w, h) = (cam.width, cam.height);
    let mut out = vec![f32::NAN; rect.width * rows];
    out.par_chunks_mut(rect.width.max(1)).enumerate().for_each(|(r, row)| {
        for (c, value) in row.iter_mut().enumerate() {
            let ideal = rect.ideal_pixel(c as f64, r as f64);
            let [x, y] = cam.observed_from_ideal(ideal);
            *value = sample_bilinear(map, w, h, x, y, jump_limit);
        }
    });
    out
}

/// Weights below this are treated as exactly zero, so a map sampled at its own
/// integer pixels returns them unchanged even next to invalid neighbours.
const NEGLIGIBLE_WEIGHT: f64 = 1e-9;

#[inline]
pub fn sample_bilinear(map: &[f32], w: usize, h: usize, x: f64, y: f64, jump_limit: f32) -> f32 {
    if !(x > -0.5 && y > -0.5 && x < w as f64 - 0.5 && y < h as f64 - 0.5) {
        return f32::NAN;
    }
    let x0 = x.floor();
    let y0 = y.floor();
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as isize, y0 as isize);
    let mut sum = 0.0f64;
    let mut weights = 0.0f64;
    let mut lo = f32::INFINITY;
    let mut hi = f32::NEG_INFINITY;
    for (dx, dy, weight) in
        [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
    {
        if weight < NEGLIGIBLE_WEIGHT {
            continue;
        }
        let (xi, yi) = (x0 + dx, y0 + dy);
        if xi < 0 || yi < 0 || xi >= w as isize || yi >= h as isize {
            return f32::NAN;
        }
        let v = map[yi as usize * w + xi as usize];
        if v.is_nan() {
            return f32::NAN;
        }
        lo = lo.min(v);
        hi = hi.max(v);
        sum += weight * f64::from(v);
        weights += weight;
    }
    if hi - lo > jump_limit {
        return f32::NAN;
    }
    (sum / weights) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::camera_model::Distortion;

    /// Telecentric cameras in the X-Z plane at +-theta (the paper's rig): the
    /// camera at `side` (-1 left, +1 right of the stage) looks towards the
    /// other side; `roll_deg`, `scale` and `offset_px` perturb it.
    fn camera(side: f64, roll_deg: f64, scale: f64, offset_px: [f64; 2]) -> AffineCamera {
        let (s, c) = 15f64.to_radians().sin_cos();
        let pitch = 0.05;
        let r1 = [c / pitch, 0.0, -side * s / pitch];
        let r2 = [0.0, -1.0 / pitch, 0.0];
        let (rs, rc) = roll_deg.to_radians().sin_cos();
        let row1: [f64; 3] = std::array::from_fn(|i| scale * (rc * r1[i] - rs * r2[i]));
        let row2: [f64; 3] = std::array::from_fn(|i| scale * (rs * r1[i] + rc * r2[i]));
        AffineCamera {
            width: 200,
            height: 150,
            p: [[row1[0], row1[1], row1[2], 99.5 + offset_px[0]], [row2[0], row2[1], row2[2], 74.5 + offset_px[1]]],
            distortion: None,
        }
    }

    fn calib(left: AffineCamera, right: AffineCamera) -> StereoCalibration {
        StereoCalibration { unit: "mm".into(), left, right, rms_reprojection_px: None }
    }

    #[test]
    fn left_camera_with_epipolar_rows_is_rectified_by_an_integer_shift_either_way_round() {
        // The paper's rig (left camera on the left) and its mirror image.
        for side in [-1.0, 1.0] {
            let c = calib(camera(side, 0.0, 1.0, [0.0, 0.0]), camera(-side, 2.0, 1.02, [12.0, -7.0]));
            let rect = rectify(&c).unwrap();
            assert!(rect.left.is_integer_shift(), "side {side}: {:?}", rect.left.to_rect);
            assert!(rect.rows >= 140, "side {side}: {} rows", rect.rows);
        }
    }

    #[test]
    fn rectified_rows_are_epipolar_and_columns_follow_the_scene_in_both_cameras() {
        let c = calib(camera(-1.0, 0.0, 1.0, [0.0, 0.0]), camera(1.0, 2.0, 1.02, [12.0, -7.0]));
        let rect = rectify(&c).unwrap();
        let to_rect = |cam: &AffineCamera, map: &RectMap, x: [f64; 3]| map.rect_pixel(cam.project(x));
        for x in [[0.0, 0.0, 0.0], [1.3, -0.7, 0.4], [-2.0, 1.5, -0.3]] {
            let l = to_rect(&c.left, &rect.left, x);
            let r = to_rect(&c.right, &rect.right, x);
            // Same world point: same rectified row in both images.
            assert!((l[1] - r[1]).abs() < 1e-9, "{l:?} vs {r:?}");
            // Moving the point along +X moves it to larger columns in both
            // images (the projector's phase grows with X, so it rises along rows).
            let x2 = [x[0] + 0.1, x[1], x[2]];
            assert!(to_rect(&c.left, &rect.left, x2)[0] > l[0]);
            assert!(to_rect(&c.right, &rect.right, x2)[0] > r[0]);
        }
        // A distortion-free map does not depend on Distortion's presence.
        let mut d = c.clone();
        d.left.distortion = Some(Distortion::for_image(200, 150));
        assert_eq!(rectify(&d).unwrap().left, rect.left);
    }
}
