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
    let mut n = cross(dl, dr);
    let mut wl = row_space_coefficients(left, n);
    // Orient the epipolar normal so rectified rows run down the left image
    // (the left map is then the identity for the usual mounting, not a flip).
    if wl[1] < 0.0 || (wl[1] == 0.0 && wl[0] < 0.0) {
        n = n.map(|x| -x);
        wl = wl.map(|x| -x);
    }
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
