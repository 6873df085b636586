//! Gaussian filters of ISO 16610-21 (profile) and ISO 16610-61 (areal), and
//! the F-operator (form removal) that precedes them.
//!
//! The weighting function is ISO 16610-21 Eq. (1),
//! `s(x) = 1/(α λc) · exp(-π (x / (α λc))²)` with `α = √(ln 2 / π)`, so a sine
//! of wavelength λc keeps 50 % of its amplitude in the mean line. The areal
//! filter of ISO 16610-61 is the product of two such functions, so it is
//! applied as two separable passes (rows, then columns).
//!
//! Holes are data: the filter is a normalised convolution. Numerator
//! `Σ s·w·z` and denominator `Σ s·w` (w = 1 on valid nodes, 0 on holes) are
//! both separable, so their quotient is exactly the areal normalised
//! convolution, and a hole is never read as a height. The same normalisation
//! is the end-effect handling at the map border: the truncated kernel is
//! renormalised over the nodes it covers (the zero-order end correction that
//! ISO 16610-28 describes for profiles). Nodes whose kernel was cut by the
//! border or by a hole are counted in [`FilterReport::incomplete_nodes`] so a
//! report can say how much of the surface rests on a partial kernel.
//!
//! The kernel is truncated at ±λc (truncation constant 1): there the weight is
//! `exp(-π/α²) ≈ 6.5e-7` of its peak, so truncation shifts the transmission
//! by far less than the 1 % the tests allow.

use rayon::prelude::*;

/// ISO 16610-21 constant α = √(ln 2 / π).
pub fn gaussian_alpha() -> f64 {
    (std::f64::consts::LN_2 / std::f64::consts::PI).sqrt()
}

/// Sampled, normalised Gaussian weights for cut-off `cutoff_mm` at node
/// spacing `pitch_mm`, index `i` at offset `i - half` nodes, truncated at ±λc.
pub fn gaussian_kernel(cutoff_mm: f64, pitch_mm: f64) -> Vec<f64> {
    let half = (cutoff_mm / pitch_mm).ceil().max(1.0) as isize;
    let a_lc = gaussian_alpha() * cutoff_mm;
    let mut k: Vec<f64> = (-half..=half)
        .map(|i| {
            let x = i as f64 * pitch_mm / a_lc;
            (-std::f64::consts::PI * x * x).exp()
        })
        .collect();
    let sum: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= sum);
    k
}

/// What a filter pass saw.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FilterReport {
    /// Valid nodes whose kernel covered a hole or ran over the border
    /// (their mean line rests on the renormalised, partial kernel).
    pub incomplete_nodes: usize,
    /// Valid nodes filtered.
    pub valid_nodes: usize,
}

impl FilterReport {
    /// Share of valid nodes on a partial kernel, in percent.
    pub fn incomplete_percent(&self) -> f64 {
        if self.valid_nodes == 0 { 0.0 } else { 100.0 * self.incomplete_nodes as f64 / self.valid_nodes as f64 }
    }
}

/// Normalised convolution of one line: `num[i] = Σ k z w`, `den[i] = Σ k w`
/// over the kernel's extent inside the line. `z` must be zero where `w` is
/// (holes), so `z w = z`.
///
/// Where the whole kernel lies inside the line, its symmetry pairs the taps
/// at ±d: one multiplication per pair instead of two, which is most of the
/// time of a ±λc L-filter (139 taps at the camera pitch). (Pairing the rows
/// of the second, column-wise pass the same way gains nothing measurable:
/// that pass is bound by memory, not arithmetic.)
fn convolve_line(z: &[f64], w: &[f64], kernel: &[f64], num: &mut [f64], den: &mut [f64]) {
    let n = z.len() as isize;
    let half = (kernel.len() / 2) as isize;
    let h = half as usize;
    for i in h..z.len().saturating_sub(h) {
        let (mut s_num, mut s_den) = (kernel[h] * z[i], kernel[h] * w[i]);
        for d in 1..=h {
            let k = kernel[h + d];
            s_num += k * (z[i - d] + z[i + d]);
            s_den += k * (w[i - d] + w[i + d]);
        }
        num[i] = s_num;
        den[i] = s_den;
    }
    for i in (0..n).filter(|&i| i < half || i >= n - half) {
        let lo = (i - half).max(0);
        let hi = (i + half).min(n - 1);
        let (mut s_num, mut s_den) = (0.0, 0.0);
        for j in lo..=hi {
            let kw = kernel[(j - i + half) as usize] * w[j as usize];
            s_num += kw * z[j as usize];
            s_den += kw;
        }
        num[i as usize] = s_num;
        den[i as usize] = s_den;
    }
}

/// The Gaussian mean line of a profile sampled at `pitch_mm` (ISO 16610-21);
/// NaN samples are holes, stay NaN and are never read.
pub fn gaussian_profile_mean_line(z: &[f64], pitch_mm: f64, cutoff_mm: f64) -> (Vec<f64>, FilterReport) {
    let kernel = gaussian_kernel(cutoff_mm, pitch_mm);
    let w: Vec<f64> = z.iter().map(|v| if v.is_finite() { 1.0 } else { 0.0 }).collect();
    let zz: Vec<f64> = z.iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect();
    let (mut num, mut den) = (vec![0.0; z.len()], vec![0.0; z.len()]);
    convolve_line(&zz, &w, &kernel, &mut num, &mut den);
    let mut report = FilterReport::default();
    let out = (0..z.len())
        .map(|i| {
            if w[i] == 0.0 {
                return f64::NAN;
            }
            report.valid_nodes += 1;
            if den[i] < 1.0 - 1e-9 {
                report.incomplete_nodes += 1;
            }
            num[i] / den[i]
        })
        .collect();
    (out, report)
}

/// The Gaussian mean surface of `z` (`width` × `height`, row-major, NaN =
/// hole) at node spacing `pitch_mm` (ISO 16610-61). Holes stay NaN.
pub fn gaussian_areal_mean_surface(
    z: &[f64],
    width: usize,
    height: usize,
    pitch_mm: f64,
    cutoff_mm: f64,
) -> (Vec<f64>, FilterReport) {
    let (out, _, report) = gaussian_areal_mean_surface_with_coverage(z, width, height, pitch_mm, cutoff_mm);
    (out, report)
}

/// [`gaussian_areal_mean_surface`] with each node's kernel coverage: the
/// share of the (renormalised) weighting function that fell on valid data
/// (1 inside, about 0.5 on a straight edge, 0.25 in a corner; NaN on holes).
pub fn gaussian_areal_mean_surface_with_coverage(
    z: &[f64],
    width: usize,
    height: usize,
    pitch_mm: f64,
    cutoff_mm: f64,
) -> (Vec<f64>, Vec<f32>, FilterReport) {
    let kernel = gaussian_kernel(cutoff_mm, pitch_mm);
    let half = kernel.len() / 2;
    let w: Vec<f64> = z.iter().map(|v| if v.is_finite() { 1.0 } else { 0.0 }).collect();
    let zw: Vec<f64> = z.iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect();
    // Pass 1: along X, each row independent.
    let mut num_x = vec![0.0; z.len()];
    let mut den_x = vec![0.0; z.len()];
    num_x.par_chunks_mut(width).zip(den_x.par_chunks_mut(width)).enumerate().for_each(|(r, (num, den))| {
        let row = r * width..(r + 1) * width;
        convolve_line(&zw[row.clone()], &w[row], &kernel, num, den);
    });
    // Pass 2: along Y; each output row is a weighted sum of input rows, which
    // keeps the inner loop contiguous (and vectorisable) in memory.
    let mut out = vec![0.0; z.len()];
    let mut coverage = vec![f32::NAN; z.len()];
    let incomplete: usize = out
        .par_chunks_mut(width)
        .zip(coverage.par_chunks_mut(width))
        .enumerate()
        .map(|(r, (out_row, coverage_row))| {
            let lo = r.saturating_sub(half);
            let hi = (r + half).min(height - 1);
            let mut num = vec![0.0; width];
            let mut den = vec![0.0; width];
            for rr in lo..=hi {
                let k = kernel[rr + half - r];
                let src_n = &num_x[rr * width..(rr + 1) * width];
                let src_d = &den_x[rr * width..(rr + 1) * width];
                for c in 0..width {
                    num[c] += k * src_n[c];
                    den[c] += k * src_d[c];
                }
            }
            let mut incomplete = 0;
            for c in 0..width {
                let i = r * width + c;
                if w[i] == 0.0 {
                    out_row[c] = f64::NAN;
                } else {
                    if den[c] < 1.0 - 1e-9 {
                        incomplete += 1;
                    }
                    out_row[c] = num[c] / den[c];
                    coverage_row[c] = den[c] as f32;
                }
            }
            incomplete
        })
        .sum();
    let valid_nodes = w.iter().filter(|v| **v > 0.0).count();
    (out, coverage, FilterReport { incomplete_nodes: incomplete, valid_nodes })
}

/// The F-operator (ISO 25178-2 §3.1.4): the form removed before filtering.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FormRemoval {
    None,
    /// Least-squares plane.
    Plane,
    /// Least-squares polynomial in x and y of total order n.
    Polynomial(u8),
}

/// Residual of `z` after removing the least-squares form; holes stay NaN.
/// Coordinates are node indices scaled to [-1, 1] so high orders stay well
/// conditioned. Returns `None` when fewer valid nodes than terms exist.
pub fn remove_form(z: &[f64], width: usize, height: usize, form: FormRemoval) -> Option<Vec<f64>> {
    let order = match form {
        FormRemoval::None => return Some(z.to_vec()),
        FormRemoval::Plane => 1,
        FormRemoval::Polynomial(n) => n as usize,
    };
    let terms: Vec<(i32, i32)> = (0..=order as i32).flat_map(|i| (0..=order as i32 - i).map(move |j| (i, j))).collect();
    let sx = 2.0 / (width.max(2) - 1) as f64;
    let sy = 2.0 / (height.max(2) - 1) as f64;
    let basis = |c: usize, r: usize, out: &mut [f64]| {
        let (x, y) = (c as f64 * sx - 1.0, r as f64 * sy - 1.0);
        for (o, (i, j)) in out.iter_mut().zip(&terms) {
            *o = x.powi(*i) * y.powi(*j);
        }
    };
    let m = terms.len();
    let mut ata = nalgebra::DMatrix::<f64>::zeros(m, m);
    let mut atb = nalgebra::DVector::<f64>::zeros(m);
    let mut b = vec![0.0; m];
    let mut valid = 0;
    for r in 0..height {
        for c in 0..width {
            let v = z[r * width + c];
            if !v.is_finite() {
                continue;
            }
            valid += 1;
            basis(c, r, &mut b);
            for p in 0..m {
                atb[p] += b[p] * v;
                for q in 0..m {
                    ata[(p, q)] += b[p] * b[q];
                }
            }
        }
    }
    if valid < m {
        return None;
    }
    let coef = ata.cholesky()?.solve(&atb);
    let mut out = z.to_vec();
    for r in 0..height {
        for c in 0..width {
            let i = r * width + c;
            if out[i].is_finite() {
                basis(c, r, &mut b);
                out[i] -= b.iter().zip(coef.iter()).map(|(x, k)| x * k).sum::<f64>();
            }
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Amplitude of the sine component of wavelength `lambda` in `z`.
    fn sine_amplitude(z: &[f64], pitch: f64, lambda: f64) -> f64 {
        let k = 2.0 * std::f64::consts::PI / lambda;
        let (mut s, mut c) = (0.0, 0.0);
        for (i, v) in z.iter().enumerate() {
            let x = i as f64 * pitch;
            s += v * (k * x).sin();
            c += v * (k * x).cos();
        }
        2.0 * (s * s + c * c).sqrt() / z.len() as f64
    }

    #[test]
    fn alpha_is_iso_value() {
        assert!((gaussian_alpha() - 0.469_718_639_349_825_8).abs() < 1e-12);
    }

    #[test]
    fn profile_mean_keeps_half_at_cutoff_and_the_residual_99_percent_at_a_third() {
        let (pitch, lc) = (0.001_f64, 0.8_f64);
        for (lambda, expect, tol) in [(lc, 0.5, 0.005), (lc / 3.0, 1.0, 0.01)] {
            // Whole periods over a long profile; judge only the middle, where
            // the kernel is complete.
            let periods = 40.0;
            let n = (periods * lambda / pitch).round() as usize;
            let z: Vec<f64> = (0..n).map(|i| (2.0 * std::f64::consts::PI * i as f64 * pitch / lambda).sin()).collect();
            let (mean, _) = gaussian_profile_mean_line(&z, pitch, lc);
            let m = (lc / pitch).ceil() as usize;
            // The mean line keeps 50 % at λc; the roughness profile z - mean
            // keeps the short waves, > 99 % at λc/3 (ISO 16610-21 Fig. 2).
            let judged: Vec<f64> =
                if expect == 1.0 { z.iter().zip(&mean).map(|(a, b)| a - b).collect() } else { mean.clone() };
            let inner = &judged[m..n - m];
            let period_n = (lambda / pitch).round() as usize;
            let whole = inner.len() / period_n * period_n;
            let a = sine_amplitude(&inner[..whole], pitch, lambda);
            assert!((a - expect).abs() < tol, "λ {lambda}: mean-line amplitude {a}, expected {expect}");
            if expect == 1.0 {
                assert!(a > 0.99);
            }
        }
    }

    #[test]
    fn areal_mean_keeps_half_at_cutoff_and_the_residual_99_percent_at_a_third() {
        // 96 nodes per cut-off: λc and λc/3 both span whole numbers of nodes.
        let (pitch, lc) = (0.8_f64 / 96.0, 0.8_f64);
        for (lambda, expect) in [(lc, 0.5), (lc / 3.0, 1.0)] {
            let (w, h) = ((12.0 * lambda / pitch).round() as usize, 2 * (lc / pitch) as usize + 9);
            let z: Vec<f64> =
                (0..w * h).map(|i| (2.0 * std::f64::consts::PI * (i % w) as f64 * pitch / lambda).sin()).collect();
            let (mean, report) = gaussian_areal_mean_surface(&z, w, h, pitch, lc);
            assert!(report.incomplete_nodes > 0 && report.incomplete_nodes < report.valid_nodes);
            let m = (lc / pitch).ceil() as usize;
            let mid = (h / 2) * w..(h / 2 + 1) * w;
            let row: Vec<f64> = if expect == 1.0 {
                z[mid.clone()].iter().zip(&mean[mid]).map(|(a, b)| a - b).collect()
            } else {
                mean[mid].to_vec()
            };
            let inner = &row[m..w - m];
            let period_n = (lambda / pitch).round() as usize;
            let whole = inner.len() / period_n * period_n;
            let a = sine_amplitude(&inner[..whole], pitch, lambda);
            assert!((a - expect).abs() < 0.005 * expect.max(1.0), "λ {lambda}: amplitude {a}");
            if expect == 1.0 {
                assert!(a > 0.99);
            }
        }
    }

    #[test]
    fn plane_and_polynomial_form_are_removed_exactly() {
        let (w, h) = (40, 30);
        let z: Vec<f64> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                if i % 7 == 3 { f64::NAN } else { 2.0 + 0.3 * x - 0.1 * y + 0.01 * x * x - 0.002 * x * y }
            })
            .collect();
        let plane = remove_form(&z, w, h, FormRemoval::Plane).unwrap();
        let poly = remove_form(&z, w, h, FormRemoval::Polynomial(2)).unwrap();
        let rms = |v: &[f64]| {
            let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
            (f.iter().map(|x| x * x).sum::<f64>() / f.len() as f64).sqrt()
        };
        assert!(rms(&plane) > 0.1, "a plane leaves the quadratic term");
        assert!(rms(&poly) < 1e-9, "order 2 removes a quadratic form, rms {}", rms(&poly));
        assert!(poly[3].is_nan(), "holes stay holes");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Holes are never read (a hole's stored value cannot change any
        /// result) and nodes whose kernel saw no hole equal the hole-free result.
        #[test]
        fn holes_are_never_read(
            w in 8usize..30, h in 8usize..30,
            holes in proptest::collection::vec(0usize..900, 0..12),
            seed in 0u64..1000,
        ) {
            let (pitch, lc) = (0.01, 0.03);
            let full: Vec<f64> = (0..w * h)
                .map(|i| ((i as u64 * 2654435761 + seed) % 1000) as f64 / 100.0)
                .collect();
            let mut with_holes = full.clone();
            let mut hole_at = vec![false; w * h];
            for at in &holes {
                let i = at % (w * h);
                with_holes[i] = f64::NAN;
                hole_at[i] = true;
            }
            let (clean, _) = gaussian_areal_mean_surface(&full, w, h, pitch, lc);
            let (got, _) = gaussian_areal_mean_surface(&with_holes, w, h, pitch, lc);
            // A hole read as a height (even times a zero weight) would turn its
            // neighbours NaN, so finite values around NaN holes prove it is not read.
            let half = (lc / pitch).ceil() as isize;
            for r in 0..h as isize {
                for c in 0..w as isize {
                    let i = (r as usize) * w + c as usize;
                    if hole_at[i] {
                        prop_assert!(got[i].is_nan());
                        continue;
                    }
                    prop_assert!(got[i].is_finite(), "a valid node got no value");
                    let saw_hole = (-half..=half).any(|dr| (-half..=half).any(|dc| {
                        let (rr, cc) = (r + dr, c + dc);
                        rr >= 0 && cc >= 0 && rr < h as isize && cc < w as isize
                            && hole_at[rr as usize * w + cc as usize]
                    }));
                    if !saw_hole {
                        prop_assert!((got[i] - clean[i]).abs() < 1e-9, "node {i}: {} vs {}", got[i], clean[i]);
                    }
                }
            }
        }
    }
}
