//! ISO 25178-2 §4.2 spatial parameters of a scale-limited surface, through
//! the FFT: Sal (autocorrelation length), Str (texture aspect ratio) and Std
//! (texture direction).
//!
//! The autocorrelation function is `f_ACF(tx, ty) = Σ z(x, y) z(x+tx, y+ty) /
//! Σ z²` (Eq. 4.5). Holes are data here too: with w = 1 on valid nodes and 0
//! on holes, the correlation of `z w` divided by the correlation of `w` is the
//! mean product over the pairs of valid nodes at each lag, so a hole is never
//! a height. Both correlations are taken with the FFT on a grid padded to 1.5
//! times the map, so lags up to half the map do not wrap around.
//!
//! Sal is the shortest lag at which the ACF decays to s = 0.2 (the ISO
//! default), scanned along rays from the origin every 0.5°; Str is that
//! shortest distance over the longest. Lags are searched up to half the map
//! in each direction; where the ACF has not decayed there (a lay along that
//! direction), the longest distance is not known and Str is an upper bound,
//! which [`SpatialParameters::str_is_upper_bound`] says.
//!
//! Std is the direction of the lay: the angular power spectrum (the power
//! spectrum summed over sectors of 0.5°, Eq. 4.6) has its maximum
//! perpendicular to the lay, and Std is that direction turned by 90°, in
//! degrees from the X axis towards Y, in [0, 180).

use rayon::prelude::*;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// ISO 25178-2 default threshold s of Sal and Str.
pub const ACF_THRESHOLD: f64 = 0.2;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialParameters {
    pub sal_mm: f64,
    pub str_ratio: f64,
    /// The ACF did not decay to s within half the map in some direction.
    pub str_is_upper_bound: bool,
    pub std_deg: f64,
}

/// A padded FFT length: 1.5 n rounded up to a multiple of 16, whose small
/// factors keep rustfft on its fast radix paths.
fn padded_len(n: usize) -> usize {
    (n + n.div_ceil(2)).next_multiple_of(16)
}

/// In-place 2-D FFT of a `w` × `h` row-major grid (rows, then columns via a
/// transpose so both passes run over contiguous lines).
/// Rows from `nonzero_rows` on must be zero (the padding): their row
/// transforms are zero too and are skipped. The transposes go by blocks of
/// [`TRANSPOSE_BLOCK`] columns, so each source row is read in runs.
pub(crate) fn fft2(data: &mut [Complex<f32>], w: usize, h: usize, inverse: bool, nonzero_rows: usize) {
    let mut planner = FftPlanner::<f32>::new();
    let mut plan = |n| if inverse { planner.plan_fft_inverse(n) } else { planner.plan_fft_forward(n) };
    let (rows, cols) = (plan(w), plan(h));
    data[..nonzero_rows.min(h) * w].par_chunks_mut(w).for_each_init(
        || vec![Complex::default(); rows.get_inplace_scratch_len()],
        |scratch, line| rows.process_with_scratch(line, scratch),
    );
    let mut t = vec![Complex::default(); w * h];
    transpose(data, &mut t, w, h);
    t.par_chunks_mut(h).for_each_init(
        || vec![Complex::default(); cols.get_inplace_scratch_len()],
        |scratch, line| cols.process_with_scratch(line, scratch),
    );
    transpose(&t, data, h, w);
}

/// `dst` (`w` rows of `h`) = the transpose of `src` (`h` rows of `w`), by
/// blocks of [`TRANSPOSE_BLOCK`] output rows so each source row is read in runs.
fn transpose(src: &[Complex<f32>], dst: &mut [Complex<f32>], w: usize, h: usize) {
    dst.par_chunks_mut(h * TRANSPOSE_BLOCK).enumerate().for_each(|(b, out)| {
        let c0 = b * TRANSPOSE_BLOCK;
        let block = out.len() / h;
        for r in 0..h {
            for (k, v) in src[r * w + c0..r * w + c0 + block].iter().enumerate() {
                out[k * h + r] = *v;
            }
        }
    });
}

/// Columns (rows) moved together by the transposes of [`fft2`].
const TRANSPOSE_BLOCK: usize = 16;

/// The circular autocorrelations (unnormalised) of two real grids packed as
/// `a + i b` on the padded size, in place: afterwards the real part holds the
/// autocorrelation of `a`, the imaginary part that of `b`. Returns the lay
/// direction found on the power spectrum of `a` on the way (Std).
///
/// Two real signals share one complex FFT: with `F = FFT(a + i b)`,
/// `A(k) = (F(k) + conj F(-k)) / 2` and `B(k) = (F(k) - conj F(-k)) / 2i`.
/// Their power spectra are real and even, so their inverse transforms are
/// real and share one inverse FFT as `|A|^2 + i |B|^2`: two FFTs instead of
/// four for the heights and the valid-node mask. `k` and `-k` are
/// rewritten together, so the spectra need no second grid; at 2048 x 1536
/// each full-size grid not made saves some 50 MB of fresh pages.
///
/// The transforms run in f32: half the memory traffic of f64 on grids of
/// millions of nodes, and the ACF is compared with a threshold of 0.2 and
/// divided by pair counts, where relative errors of 1e-6 change nothing.
fn autocorrelations_in_place(
    f: &mut [Complex<f32>],
    pw: usize,
    ph: usize,
    nonzero_rows: usize,
    width: usize,
    height: usize,
) -> f64 {
    fft2(f, pw, ph, false, nonzero_rows);
    // Row r pairs with row (ph - r) % ph, column c with (pw - c) % pw.
    let (lo_end, hi_start) = (ph.div_ceil(2), ph / 2 + 1);
    let (head, rest) = f.split_at_mut(lo_end * pw);
    let (row0, lo) = head.split_at_mut(pw);
    let (middle, hi) = rest.split_at_mut((hi_start - lo_end) * pw);
    lo.par_chunks_mut(pw).zip(hi.par_chunks_mut(pw).rev()).for_each(|(a, b)| {
        for (c, fa) in a.iter_mut().enumerate() {
            let fb = &mut b[(pw - c) % pw];
            (*fa, *fb) = spectra_pair(*fa, *fb);
        }
    });
    for row in [row0, middle].into_iter().filter(|r| !r.is_empty()) {
        for c in 0..=pw / 2 {
            let m = (pw - c) % pw;
            (row[c], row[m]) = spectra_pair(row[c], row[m]);
        }
    }
    let std_deg = lay_direction_deg(f, pw, ph, width, height);
    fft2(f, pw, ph, true, ph);
    std_deg
}

/// `(|A(k)|², |B(k)|²)` and the same at `-k`, packed as complex numbers,
/// from `F(k)` and `F(-k)` (see [`autocorrelations_in_place`]); computed in
/// f64, stored in f32.
fn spectra_pair(fk: Complex<f32>, f_minus_k: Complex<f32>) -> (Complex<f32>, Complex<f32>) {
    let widen = |c: Complex<f32>| Complex::new(f64::from(c.re), f64::from(c.im));
    let (x, y) = (widen(fk), widen(f_minus_k));
    let a = (x + y.conj()) * 0.5;
    let b = (x - y.conj()) * Complex::new(0.0, -0.5);
    // A(-k) = conj A(k) and B(-k) = conj B(k): the same powers at -k.
    let power = Complex::new(a.norm_sqr() as f32, b.norm_sqr() as f32);
    (power, power)
}

/// Sal, Str and Std of `z_um` (`width` × `height`, NaN = hole) at `pitch_mm`;
/// `None` with fewer than 4 × 4 nodes or no valid node.
pub fn spatial_parameters(z_um: &[f64], width: usize, height: usize, pitch_mm: f64) -> Option<SpatialParameters> {
    if width < 4 || height < 4 {
        return None;
    }
    let valid: Vec<f64> = z_um.iter().copied().filter(|v| v.is_finite()).collect();
    if valid.is_empty() {
        return None;
    }
    let mean = valid.iter().sum::<f64>() / valid.len() as f64;
    let holes = valid.len() < z_um.len();
    let (pw, ph) = (padded_len(width), padded_len(height));
    // Heights about the mean in the real part, the valid-node mask in the
    // imaginary part (holes are zero in both).
    let mut grid = vec![Complex::default(); pw * ph];
    for r in 0..height {
        for c in 0..width {
            let v = z_um[r * width + c];
            if v.is_finite() {
                grid[r * pw + c] = Complex::new((v - mean) as f32, 1.0);
            }
        }
    }
    let std_deg = autocorrelations_in_place(&mut grid, pw, ph, height, width, height);
    let scale = 1.0 / (pw * ph) as f64;
    let wrap = |t: i64, n: usize| t.rem_euclid(n as i64) as usize;
    let acf_node = |tx: i64, ty: i64| -> f64 {
        let i = wrap(ty, ph) * pw + wrap(tx, pw);
        // Pairs of valid nodes per lag: counted by the FFT with holes, known otherwise.
        let n = if holes {
            (f64::from(grid[i].im) * scale).round()
        } else {
            ((width as i64 - tx.abs()) * (height as i64 - ty.abs())) as f64
        };
        if n >= 1.0 { f64::from(grid[i].re) * scale / n } else { f64::NAN }
    };
    let zero = acf_node(0, 0);
    if !(zero > 0.0) {
        return None;
    }
    let acf = |x: f64, y: f64| -> f64 {
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let v = acf_node(x0, y0) * (1.0 - fx) * (1.0 - fy)
            + acf_node(x0 + 1, y0) * fx * (1.0 - fy)
            + acf_node(x0, y0 + 1) * (1.0 - fx) * fy
            + acf_node(x0 + 1, y0 + 1) * fx * fy;
        v / zero
    };
    // Rays over half a turn (the ACF is point-symmetric), 0.5° apart, in
    // steps of 0.25 node up to half the map.
    let (half_w, half_h) = ((width / 2) as f64, (height / 2) as f64);
    let decay: Vec<(f64, bool)> = (0..360)
        .into_par_iter()
        .map(|i| {
            let (s, c) = (i as f64 * 0.5).to_radians().sin_cos();
            let r_max = (if c.abs() > 1e-12 { half_w / c.abs() } else { f64::INFINITY }).min(if s.abs() > 1e-12 {
                half_h / s.abs()
            } else {
                f64::INFINITY
            });
            let mut prev = (0.0, 1.0);
            let mut r = 0.25;
            while r <= r_max {
                let v = acf(r * c, r * s);
                if v.is_finite() && v <= ACF_THRESHOLD {
                    // Linear interpolation between the last two steps.
                    let t = (prev.1 - ACF_THRESHOLD) / (prev.1 - v);
                    return (prev.0 + t * (r - prev.0), true);
                }
                if v.is_finite() {
                    prev = (r, v);
                }
                r += 0.25;
            }
            (r_max, false)
        })
        .collect();
    let shortest = decay.iter().filter(|d| d.1).map(|d| d.0).fold(f64::INFINITY, f64::min);
    let longest = decay.iter().map(|d| d.0).fold(0.0, f64::max);
    let str_is_upper_bound = decay.iter().any(|d| !d.1);
    let (sal_mm, str_ratio) =
        if shortest.is_finite() { (shortest * pitch_mm, shortest / longest) } else { (f64::NAN, f64::NAN) };
    Some(SpatialParameters { sal_mm, str_ratio, str_is_upper_bound, std_deg })
}

/// The lay direction from the angular power spectrum (see the module docs).
/// The sector sums find the dominant direction; at low frequencies a sector
/// holds few bins, so the angle is then refined as the direction of the
/// power centroid of the bins within ±5° of it (the window's sinc² spreads a
/// line of the spectrum symmetrically about its true place).
fn lay_direction_deg(spectra: &[Complex<f32>], pw: usize, ph: usize, width: usize, height: usize) -> f64 {
    const BINS: usize = 360;
    // Below one cycle over the map, directions are not resolved.
    let r_min = 1.0 / width.min(height) as f64;
    let freq = |i: usize, n: usize| if i <= n / 2 { i as f64 / n as f64 } else { (i as f64 - n as f64) / n as f64 };
    let power = |v: usize, u: usize| f64::from(spectra[v * pw + u].re);
    let sectors = (0..ph)
        .into_par_iter()
        .fold(
            || [0.0; BINS],
            |mut sectors, v| {
                let fv = freq(v, ph);
                for u in 0..pw {
                    let fu = freq(u, pw);
                    if fu.hypot(fv) >= r_min {
                        let theta = fv.atan2(fu).to_degrees().rem_euclid(180.0);
                        sectors[((theta / 0.5) as usize).min(BINS - 1)] += power(v, u);
                    }
                }
                sectors
            },
        )
        .reduce(
            || [0.0; BINS],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    let peak =
        sectors.iter().enumerate().fold((0, f64::NEG_INFINITY), |b, (i, v)| if *v > b.1 { (i, *v) } else { b }).0;
    let coarse = (peak as f64 + 0.5) * 0.5;
    // Within ±5° of the coarse line (either way along it): |sin(φ - coarse)|
    // ≤ sin 5°, with no angle to compute per bin.
    let (sin_c, cos_c) = coarse.to_radians().sin_cos();
    let sin_window = 5f64.to_radians().sin();
    let (cx, cy) = (0..ph)
        .into_par_iter()
        .map(|v| {
            let fv = freq(v, ph);
            let (mut cx, mut cy) = (0.0, 0.0);
            for u in 0..pw {
                let fu = freq(u, pw);
                let r = fu.hypot(fv);
                if r >= r_min && (fv * cos_c - fu * sin_c).abs() <= sin_window * r {
                    // Fold the half-plane so both lobes of a line add up.
                    let sign = if fu * cos_c + fv * sin_c >= 0.0 { 1.0 } else { -1.0 };
                    let p = power(v, u);
                    cx += sign * fu * p;
                    cy += sign * fv * p;
                }
            }
            (cx, cy)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let spectrum_deg = if cx == 0.0 && cy == 0.0 { coarse } else { cy.atan2(cx).to_degrees() };
    (spectrum_deg + 90.0).rem_euclid(180.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn grid(w: usize, h: usize, f: impl Fn(f64, f64) -> f64) -> Vec<f64> {
        (0..w * h).map(|i| f((i % w) as f64, (i / w) as f64)).collect()
    }

    #[test]
    fn a_sine_has_its_analytic_autocorrelation_length_and_a_lay_across_it() {
        // z = sin(k x), 32 nodes per period: ACF = cos(k tx), down to 0.2 at
        // tx = acos(0.2) / k; along Y it never decays, so Str is a bound. The
        // ACF of a finite surface carries an edge term of order 1 / (k W), so
        // the map holds 32 periods to stay well inside 1 %.
        let (w, h, pitch) = (1024, 64, 0.001);
        let k = 2.0 * PI / 32.0;
        let s = spatial_parameters(&grid(w, h, |x, _| (k * x).sin()), w, h, pitch).unwrap();
        let want = 0.2f64.acos() / k * pitch;
        assert!((s.sal_mm - want).abs() < 0.01 * want, "Sal {} vs {want}", s.sal_mm);
        assert!(s.str_is_upper_bound && s.str_ratio < 0.3, "{s:?}");
        assert!((s.std_deg - 90.0).abs() < 1.0, "Std {}", s.std_deg);
    }

    #[test]
    fn a_product_of_sines_has_the_analytic_aspect_ratio() {
        // ACF = cos(k tx) cos(k ty): fastest decay along X (acos 0.2 / k),
        // slowest along the diagonal (1.5658 / k, found numerically): Str 0.8746.
        let (w, h) = (768, 768);
        let k = 2.0 * PI / 32.0;
        let s = spatial_parameters(&grid(w, h, |x, y| (k * x).sin() * (k * y).sin()), w, h, 0.001).unwrap();
        assert!(!s.str_is_upper_bound);
        assert!((s.str_ratio - 0.8746).abs() < 0.01 * 0.8746, "Str {}", s.str_ratio);
        let want = 0.2f64.acos() / k * 0.001;
        assert!((s.sal_mm - want).abs() < 0.01 * want, "Sal {}", s.sal_mm);
    }

    #[test]
    fn a_lay_whose_spectrum_straddles_the_x_axis_is_found() {
        // Wave vector 1° above the X axis (Std 91°): the window spreads its
        // line over bins on both sides of 0°, which must add up on one side.
        let (w, h) = (512, 400);
        let (s1, c1) = 1f64.to_radians().sin_cos();
        let k = 2.0 * PI / 16.0;
        let z = grid(w, h, |x, y| (k * (x * c1 + y * s1)).sin());
        let s = spatial_parameters(&z, w, h, 0.001).unwrap();
        assert!((s.std_deg - 91.0).abs() < 0.5, "Std {}", s.std_deg);
    }

    #[test]
    fn a_rotated_lay_is_found_and_holes_do_not_move_it() {
        // Ridges along 120°: the wave vector points along 30°.
        let (w, h) = (600, 500);
        let (s30, c30) = 30f64.to_radians().sin_cos();
        let k = 2.0 * PI / 20.0;
        let mut z = grid(w, h, |x, y| (k * (x * c30 + y * s30)).sin());
        let clean = spatial_parameters(&z, w, h, 0.002).unwrap();
        assert!((clean.std_deg - 120.0).abs() < 1.0, "Std {}", clean.std_deg);
        for (i, v) in z.iter_mut().enumerate() {
            if (i * 7919) % 13 == 0 {
                *v = f64::NAN;
            }
        }
        let holed = spatial_parameters(&z, w, h, 0.002).unwrap();
        assert!((holed.std_deg - 120.0).abs() < 1.0, "Std with holes {}", holed.std_deg);
        assert!((holed.sal_mm - clean.sal_mm).abs() < 0.01 * clean.sal_mm, "{} vs {}", holed.sal_mm, clean.sal_mm);
        let want = 0.2f64.acos() / k * 0.002;
        assert!((clean.sal_mm - want).abs() < 0.01 * want, "Sal {} vs {want}", clean.sal_mm);
    }
}
