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

use super::buffers::filled;
use super::camera_model::{AffineCamera, StereoCalibration, cross, dot};
use super::continuity::{Continuity, continuous_pair, flanking_step_by};
use super::simd;

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

    /// `(dc, dr)` when the map is the identity up to that integer shift:
    /// rectified pixel `(c, r)` is camera pixel `(c - dc, r - dr)`.
    pub fn integer_shift(&self) -> Option<(isize, isize)> {
        let m = &self.to_rect;
        self.is_integer_shift().then(|| (m[0][2].round() as isize, m[1][2].round() as isize))
    }

    /// `(dc, dr)` when camera `cam`, mapped by this map, has its rectified
    /// pixel `(c, r)` at its own pixel `(c - dc, r - dr)`: an integer shift
    /// and no lens distortion. Its rectified image is then a copy, and a
    /// match's camera pixel needs no rounding.
    pub fn pixel_shift(&self, cam: &AffineCamera) -> Option<(isize, isize)> {
        self.integer_shift().filter(|_| cam.active_distortion().is_none())
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

/// Resamples a camera's absolute phase map (and, nearest-neighbour, its sigma
/// map) into its rectified frame.
///
/// Each rectified pixel goes to its ideal camera pixel (`from_rect`) and then
/// through the lens distortion to where the observed map is sampled: one
/// resampling, no inversion. See [`sample_phase`] for how holes and jumps are
/// kept out of the interpolation.
pub fn resample_phase(
    map: &[f32],
    sigma: &[f32],
    cam: &AffineCamera,
    rect: &RectMap,
    rows: usize,
    continuity: &Continuity,
) -> (Vec<f32>, Vec<f32>) {
    use rayon::prelude::*;
    let (w, h) = (cam.width, cam.height);
    let mut out = filled(rect.width * rows, f32::NAN);
    let mut out_sigma = filled(rect.width * rows, f32::NAN);
    if let Some((dc, dr)) = rect.pixel_shift(cam) {
        // The usual main camera: its rectified image is the image itself.
        out.par_chunks_mut(rect.width.max(1)).zip(out_sigma.par_chunks_mut(rect.width.max(1))).enumerate().for_each(
            |(r, (row, row_sigma))| {
                let y = r as isize - dr;
                if y < 0 || y >= h as isize {
                    return;
                }
                for (c, (value, value_sigma)) in row.iter_mut().zip(row_sigma.iter_mut()).enumerate() {
                    let x = c as isize - dc;
                    if x >= 0 && x < w as isize {
                        let i = y as usize * w + x as usize;
                        *value = map[i];
                        *value_sigma = if map[i].is_nan() { f32::NAN } else { sigma[i] };
                    }
                }
            },
        );
        return (out, out_sigma);
    }
    let continuous = ContinuityFlags::new(map, sigma, w, h, continuity);
    out.par_chunks_mut(rect.width.max(1)).zip(out_sigma.par_chunks_mut(rect.width.max(1))).enumerate().for_each(
        |(r, (row, row_sigma))| {
            for (c, (value, value_sigma)) in row.iter_mut().zip(row_sigma.iter_mut()).enumerate() {
                let ideal = rect.ideal_pixel(c as f64, r as f64);
                let [x, y] = cam.observed_from_ideal(ideal);
                if !(x > -0.5 && y > -0.5 && x < w as f64 - 0.5 && y < h as f64 - 0.5) {
                    continue;
                }
                let (xf, yf) = (x.floor() as isize, y.floor() as isize);
                // The common case first, from the cell's flags alone: inside
                // the map, four valid pixels (a continuous pair has two) that
                // are pairwise continuous, with finite sigmas.
                if xf >= 0 && yf >= 0 && (xf as usize) + 1 < w && (yf as usize) + 1 < h {
                    let i = yf as usize * w + xf as usize;
                    let corners = [sigma[i], sigma[i + 1], sigma[i + w], sigma[i + w + 1]];
                    if continuous.cell(i) && corners.iter().all(|c| c.is_finite()) {
                        let (fx, fy) = (x - xf as f64, y - yf as f64);
                        let top = f64::from(map[i]) + fx * f64::from(map[i + 1] - map[i]);
                        let bottom = f64::from(map[i + w]) + fx * f64::from(map[i + w + 1] - map[i + w]);
                        *value = (top + fy * (bottom - top)) as f32;
                        *value_sigma = corners[0].max(corners[1]).max(corners[2]).max(corners[3]);
                        continue;
                    }
                }
                // The largest sigma of the surrounding valid pixels: the
                // interpolated phase is no better than its worst input.
                let mut s = f32::NAN;
                let mut valid = 0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (xi, yi) = (xf + dx, yf + dy);
                    if xi >= 0 && yi >= 0 && xi < w as isize && yi < h as isize {
                        let c = sigma[yi as usize * w + xi as usize];
                        if c.is_finite() && !map[yi as usize * w + xi as usize].is_nan() {
                            s = if s.is_nan() { c } else { s.max(c) };
                            valid += 1;
                        }
                    }
                }
                if s.is_nan() {
                    continue;
                }
                *value = if valid == 4 {
                    // Four valid pixels that are not pairwise continuous (the
                    // continuous ones took the bilinear value above): a step
                    // or an occlusion runs through the cell.
                    f32::NAN
                } else {
                    sample_phase(map, w, h, x, y, s, continuity)
                };
                if !value.is_nan() {
                    *value_sigma = s;
                }
            }
        },
    );
    (out, out_sigma)
}

/// Per pixel of a map, whether the step to its right and the step below it
/// are continuous ([`Continuity`]): computed once per map so resampling
/// checks a 2x2 cell with four lookups.
struct ContinuityFlags {
    width: usize,
    /// Bit 0: the pair (i, i + 1) is continuous; bit 1: the pair (i, i + width).
    flags: Vec<u8>,
}

impl ContinuityFlags {
    fn new(map: &[f32], sigma: &[f32], w: usize, h: usize, continuity: &Continuity) -> Self {
        use rayon::prelude::*;
        let mut flags = filled(w * h, 0u8);
        // The flanks are read from the row and the rows around it directly,
        // NaN outside the map (rows without a row above or two below read a
        // NaN row): every pair is one `continuous_pair` test over slices of
        // equal length, which vectorises (a bounds-checked lookup per sample
        // was a third of the rectification's time before).
        let no_row = vec![f32::NAN; w];
        flags.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row_flags)| {
            let line = |r: usize| &map[r * w..(r + 1) * w];
            let row = line(y);
            let row_sigma = &sigma[y * w..(y + 1) * w];
            let above = y.checked_sub(1).map_or(&no_row[..], line);
            let (below, below2) = ((y + 1 < h).then(|| line(y + 1)), (y + 2 < h).then(|| line(y + 2)));
            let has_below = u8::from(below.is_some());
            let (below, below2) = (below.unwrap_or(&no_row), below2.unwrap_or(&no_row));
            let below_sigma = if y + 1 < h { &sigma[(y + 1) * w..(y + 2) * w] } else { &no_row[..] };
            // A fn, not a closure, so it can be marked: the dispatched copies below inline it.
            #[inline(always)]
            fn pair_sigma(a: f32, b: f32) -> f32 {
                std::f32::consts::SQRT_2 * a.max(b)
            }
            let vertical_flag = |x: usize| {
                let vertical = [above[x], row[x], below[x], below2[x]];
                u8::from(continuous_pair(continuity, vertical, pair_sigma(row_sigma[x], below_sigma[x]))) & has_below
            };
            // Both ends of the row: flanks outside it are NaN; the last pixel
            // has no pair to its right.
            let at = |x: isize| if x >= 0 && (x as usize) < w { row[x as usize] } else { f32::NAN };
            for x in [0, w.saturating_sub(2), w.saturating_sub(1)] {
                if x >= w {
                    continue;
                }
                let across = x + 1 < w && {
                    let xi = x as isize;
                    let horizontal = [at(xi - 1), row[x], row[x + 1], at(xi + 2)];
                    continuous_pair(continuity, horizontal, pair_sigma(row_sigma[x], row_sigma[x + 1]))
                };
                row_flags[x] = u8::from(across) | vertical_flag(x) << 1;
            }
            // Pixels with both horizontal flanks inside the row.
            let n = w.saturating_sub(3);
            if n == 0 {
                return;
            }
            let (r0, r1, r2, r3) = (&row[..n], &row[1..=n], &row[2..n + 2], &row[3..n + 3]);
            let (up, down, down2) = (&above[1..=n], &below[1..=n], &below2[1..=n]);
            let (s1, s2, s_down) = (&row_sigma[1..=n], &row_sigma[2..n + 2], &below_sigma[1..=n]);
            // With AVX-512 the comparisons' masks become the flag bytes directly.
            simd::dispatch(
                #[inline(always)]
                || {
                    for (k, flag) in row_flags[1..=n].iter_mut().enumerate() {
                        let across =
                            continuous_pair(continuity, [r0[k], r1[k], r2[k], r3[k]], pair_sigma(s1[k], s2[k]));
                        let vertical = continuous_pair(
                            continuity,
                            [up[k], r1[k], down[k], down2[k]],
                            pair_sigma(s1[k], s_down[k]),
                        );
                        *flag = u8::from(across) | (u8::from(vertical) & has_below) << 1;
                    }
                },
            );
        });
        Self { width: w, flags }
    }

    /// All four pairs of the 2x2 cell whose top-left pixel is `i` are continuous.
    #[inline]
    fn cell(&self, i: usize) -> bool {
        let w = self.width;
        self.flags[i] == 3 && self.flags[i + w] & 1 == 1 && self.flags[i + 1] & 2 == 2
    }
}

/// Sub-pixel offsets below this count as on the pixel centre, so a map
/// sampled at its own pixels returns them unchanged even next to holes.
const NEGLIGIBLE_OFFSET: f64 = 1e-9;

/// The phase at sub-pixel `(x, y)` of a map, or NaN.
///
/// The phase of vertical fringes is locally linear, so the value comes from a
/// local linear model of the valid pixels only, never reading an invalid one:
/// bilinear interpolation when all four surrounding pixels are valid; the
/// plane through three when one is invalid; with two valid pixels on a row
/// (or a column), the interpolation along it plus the step across it that the
/// next row (column) shows. Every step used must be continuous with its
/// flanking step ([`Continuity`]), so nothing is interpolated across a step,
/// an occlusion or a phase jump; anything else (two diagonal holes, a jump,
/// the image border) gives NaN rather than a phase no surface point has.
#[inline]
pub fn sample_phase(map: &[f32], w: usize, h: usize, x: f64, y: f64, sigma: f32, continuity: &Continuity) -> f32 {
    if !(x > -0.5 && y > -0.5 && x < w as f64 - 0.5 && y < h as f64 - 0.5) {
        return f32::NAN;
    }
    let (x0f, y0f) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0f, y - y0f);
    let (x0, y0) = (x0f as isize, y0f as isize);
    let at = |xi: isize, yi: isize| -> Option<f32> {
        (xi >= 0 && yi >= 0 && xi < w as isize && yi < h as isize).then(|| map[yi as usize * w + xi as usize])
    };
    // On a pixel centre (to rounding): the pixel itself, whatever its neighbours are.
    let on_x = !(NEGLIGIBLE_OFFSET..=1.0 - NEGLIGIBLE_OFFSET).contains(&fx);
    let on_y = !(NEGLIGIBLE_OFFSET..=1.0 - NEGLIGIBLE_OFFSET).contains(&fy);
    if on_x && on_y {
        return at(x0 + isize::from(fx > 0.5), y0 + isize::from(fy > 0.5)).unwrap_or(f32::NAN);
    }
    // Corners (0,0), (1,0), (0,1), (1,1); a missing corner is NaN.
    let v = [at(x0, y0), at(x0 + 1, y0), at(x0, y0 + 1), at(x0 + 1, y0 + 1)].map(|c| c.unwrap_or(f32::NAN));
    let ok = v.map(|c| !c.is_nan());
    let step_sigma = std::f32::consts::SQRT_2 * sigma;
    // The signed step from corner a to corner b if both are valid and it is
    // continuous with its flank on the same line; `Err` for a discontinuity.
    let step = |a: usize, b: usize, horizontal: bool| -> Result<Option<f32>, ()> {
        if !(ok[a] && ok[b]) {
            return Ok(None);
        }
        let (xa, ya) = (x0 + (a & 1) as isize, y0 + (a >> 1) as isize);
        let flank = if horizontal { flanking_step_by(|i| at(i, ya), xa) } else { flanking_step_by(|i| at(xa, i), ya) };
        let d = v[b] - v[a];
        if continuity.allows_flanked(d, flank, step_sigma) { Ok(Some(d)) } else { Err(()) }
    };
    // The step across a line of two valid corners: the step its continuation
    // beyond the cell shows (the flank of the cell's broken pair on that line).
    let outer_step = |xi: isize, yi: isize, horizontal: bool| -> Option<f32> {
        if horizontal { flanking_step_by(|i| at(i, yi), xi) } else { flanking_step_by(|i| at(xi, i), yi) }
    };
    let (h_top, h_bottom, v_left, v_right) =
        match (step(0, 1, true), step(2, 3, true), step(0, 2, false), step(1, 3, false)) {
            (Ok(a), Ok(b), Ok(c), Ok(d)) => (a, b, c, d),
            _ => return f32::NAN,
        };
    let valid = ok.iter().filter(|&&o| o).count();
    let value = match valid {
        4 => {
            let top = f64::from(v[0]) + fx * f64::from(h_top.unwrap_or(0.0));
            let bottom = f64::from(v[2]) + fx * f64::from(h_bottom.unwrap_or(0.0));
            top + fy * (bottom - top)
        }
        3 => {
            // The plane through the corner opposite the missing one and its two neighbours.
            let missing = ok.iter().position(|&o| !o).unwrap_or(0);
            let o = 3 - missing;
            let (ox, oy) = ((o & 1) as f64, (o >> 1) as f64);
            let vo = f64::from(v[o]);
            let gx = (f64::from(v[o ^ 1]) - vo) * if o & 1 == 0 { 1.0 } else { -1.0 };
            let gy = (f64::from(v[o ^ 2]) - vo) * if o >> 1 == 0 { 1.0 } else { -1.0 };
            vo + (fx - ox) * gx + (fy - oy) * gy
        }
        2 if ok[0] && ok[1] || ok[2] && ok[3] => {
            // A valid row: along it, plus the vertical step its columns show beyond the cell.
            let (row, yi, d) = if ok[0] { (0, y0, h_top) } else { (2, y0 + 1, h_bottom) };
            let Some(d) = d else { return f32::NAN };
            let Some(gy) = outer_step(x0, yi, false).or_else(|| outer_step(x0 + 1, yi, false)) else {
                return f32::NAN;
            };
            let dy = if row == 0 { fy } else { fy - 1.0 };
            f64::from(v[row]) + fx * f64::from(d) + dy * f64::from(gy)
        }
        2 if ok[0] && ok[2] || ok[1] && ok[3] => {
            // A valid column: along it, plus the horizontal step its rows show beyond the cell.
            let (col, xi, d) = if ok[0] { (0, x0, v_left) } else { (1, x0 + 1, v_right) };
            let Some(d) = d else { return f32::NAN };
            let Some(gx) = outer_step(xi, y0, true).or_else(|| outer_step(xi, y0 + 1, true)) else {
                return f32::NAN;
            };
            let dx = if col == 0 { fx } else { fx - 1.0 };
            f64::from(v[col]) + fy * f64::from(d) + dx * f64::from(gx)
        }
        _ => return f32::NAN,
    };
    value as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flags by their definition: each pair's step against the nearer of
    /// its flanking steps on the same line, looked up one sample at a time.
    fn flags_by_definition(map: &[f32], sigma: &[f32], w: usize, h: usize, continuity: &Continuity) -> Vec<u8> {
        let at = |x: isize, y: isize| {
            (x >= 0 && y >= 0 && x < w as isize && y < h as isize).then(|| map[y as usize * w + x as usize])
        };
        let mut flags = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let pair_sigma = |j: usize| std::f32::consts::SQRT_2 * sigma[i].max(sigma[j]);
                if x + 1 < w && !map[i].is_nan() && !map[i + 1].is_nan() {
                    let flank = flanking_step_by(|k| at(k, y as isize), x as isize);
                    if continuity.allows_flanked(map[i + 1] - map[i], flank, pair_sigma(i + 1)) {
                        flags[i] |= 1;
                    }
                }
                if y + 1 < h && !map[i].is_nan() && !map[i + w].is_nan() {
                    let flank = flanking_step_by(|k| at(x as isize, k), y as isize);
                    if continuity.allows_flanked(map[i + w] - map[i], flank, pair_sigma(i + w)) {
                        flags[i] |= 2;
                    }
                }
            }
        }
        flags
    }

    #[test]
    fn a_sheared_resampling_of_a_plane_is_the_plane_with_its_worst_corner_sigma() {
        // A phase plane with holes, resampled through a rotated, shifted map:
        // every rectified pixel lands between pixels, most on four valid ones.
        let (w, h) = (40, 30);
        let plane = |x: f64, y: f64| 0.3 * x + 0.05 * y + 2.0;
        let hole = |x: usize, y: usize| (x * 7 + y * 13).is_multiple_of(23);
        let mut map = vec![f32::NAN; w * h];
        let mut sigma = vec![f32::NAN; w * h];
        for y in 0..h {
            for x in 0..w {
                if !hole(x, y) {
                    map[y * w + x] = plane(x as f64, y as f64) as f32;
                    sigma[y * w + x] = 0.01 + 0.001 * ((x * 3 + y * 5) % 11) as f32;
                }
            }
        }
        let cam =
            AffineCamera { width: w, height: h, p: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]], distortion: None };
        let (cos, sin) = (0.03f64.cos(), 0.03f64.sin());
        let from_rect = [[cos, -sin, 0.37], [sin, cos, 0.61]];
        let to_rect = [[cos, sin, -(cos * 0.37 + sin * 0.61)], [-sin, cos, sin * 0.37 - cos * 0.61]];
        let rect = RectMap { width: w, to_rect, from_rect };
        let (out, out_sigma) = resample_phase(&map, &sigma, &cam, &rect, h, &Continuity::default());
        let mut four_valid = 0;
        for r in 0..h {
            for c in 0..w {
                let [x, y] = rect.ideal_pixel(c as f64, r as f64);
                // Cells whose pairs all have their flanks: the 4x4 pixels
                // around them inside the map and valid.
                let (xf, yf) = (x.floor(), y.floor());
                if xf < 1.0 || yf < 1.0 || xf + 2.0 >= w as f64 || yf + 2.0 >= h as f64 {
                    continue;
                }
                let (xi, yi) = (xf as usize, yf as usize);
                if (xi - 1..=xi + 2).any(|cx| (yi - 1..=yi + 2).any(|cy| hole(cx, cy))) {
                    continue;
                }
                let corners = [(xi, yi), (xi + 1, yi), (xi, yi + 1), (xi + 1, yi + 1)];
                four_valid += 1;
                let i = r * w + c;
                assert!((f64::from(out[i]) - plane(x, y)).abs() < 1e-5, "({c}, {r}): {} vs {}", out[i], plane(x, y));
                let worst = corners.iter().map(|&(cx, cy)| sigma[cy * w + cx]).fold(f32::MIN, f32::max);
                assert_eq!(out_sigma[i], worst, "({c}, {r})");
            }
        }
        assert!(four_valid > w * h / 4, "{four_valid}");
    }

    #[test]
    fn continuity_flags_are_the_flanked_step_test_of_every_pair() {
        // A sloped phase with holes, steps of every size, noisy sigmas and
        // single-pixel strips next to the borders.
        let (w, h) = (37, 23);
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut map = vec![0f32; w * h];
        let mut sigma = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let r = next();
                map[i] = 0.2 * x as f32 + 0.01 * y as f32 + if r < 0.1 { 3.0 * next() } else { 0.0 };
                if r > 0.9 {
                    map[i] = f32::NAN;
                }
                sigma[i] = 0.001 + 0.02 * next();
            }
        }
        let mut tested = 0;
        for continuity in [Continuity::default(), Continuity::plain()] {
            let flags = ContinuityFlags::new(&map, &sigma, w, h, &continuity);
            let expected = flags_by_definition(&map, &sigma, w, h, &continuity);
            assert_eq!(flags.flags, expected);
            tested += expected.iter().filter(|&&f| f != 0).count();
        }
        // Both kinds of pair were judged, and some were refused.
        let enforced = ContinuityFlags::new(&map, &sigma, w, h, &Continuity::default());
        assert!(enforced.flags.contains(&1) && enforced.flags.contains(&2));
        assert!(tested > w * h);
    }
}
