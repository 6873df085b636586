//! ISO 25178-2 areal field parameters of a scale-limited surface: height
//! (§4.1: Sq, Ssk, Sku, Sp, Sv, Sz, Sa), hybrid (§4.3: Sdq, Sdr), material
//! ratio and volume (§4.4, §4.5, via [`super::material_ratio`]).
//!
//! Heights are in µm about the mean of the valid nodes (the reference
//! surface after the F-operator and filters). Holes (NaN) are skipped; the
//! gradient at a node uses central differences and exists only where both
//! neighbours along X and along Y are valid, so no slope spans a hole.

use super::material_ratio::{CoreParameters, MaterialRatioCurve};
use crate::engine::length_unit::LengthUnit;

/// ISO 25178-2 default material ratios for Vmp/Vmc/Vvc/Vvv: p = 10 %, q = 80 %.
pub const DEFAULT_P_PERCENT: f64 = 10.0;
pub const DEFAULT_Q_PERCENT: f64 = 80.0;

/// Where Smr(c) and Smc(mr) are read on the material ratio curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialRatioPoints {
    /// Height c of Smr(c), µm above the mean plane (ISO 25178-2 §4.4.1; the
    /// mean plane, c = 0, unless a specification gives another).
    pub smr_c_um: f64,
    /// Material ratio mr of Smc(mr), % (10 % unless given).
    pub smc_mr_percent: f64,
}

impl Default for MaterialRatioPoints {
    fn default() -> Self {
        Self { smr_c_um: 0.0, smc_mr_percent: 10.0 }
    }
}

/// The areal parameters of one surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArealParameters {
    pub sq_um: f64,
    pub ssk: f64,
    pub sku: f64,
    pub sp_um: f64,
    pub sv_um: f64,
    pub sz_um: f64,
    pub sa_um: f64,
    /// Root mean square gradient (1).
    pub sdq: f64,
    /// Developed interfacial area ratio (%).
    pub sdr_percent: f64,
    /// Smr(c) at [`MaterialRatioPoints::smr_c_um`] (%).
    pub smr_percent: f64,
    /// Smc(mr) at [`MaterialRatioPoints::smc_mr_percent`] (µm above the mean plane).
    pub smc_um: f64,
    pub core: CoreParameters,
    pub vmp_um: f64,
    pub vmc_um: f64,
    pub vvc_um: f64,
    pub vvv_um: f64,
    /// Valid nodes the parameters rest on.
    pub nodes: usize,
}

/// Parameters of `z_um` (`width` × `height` row-major, NaN = hole) at node
/// spacing `pitch_mm`, Smr and Smc read at `points`; `None` with fewer than
/// two valid nodes.
pub fn areal_parameters(
    z_um: &[f64],
    width: usize,
    height: usize,
    pitch_mm: f64,
    points: MaterialRatioPoints,
) -> Option<ArealParameters> {
    let valid: Vec<f64> = z_um.iter().copied().filter(|v| v.is_finite()).collect();
    let n = valid.len();
    if n < 2 {
        return None;
    }
    let m = HeightMoments::of(&valid);
    let mean = m.mean;
    let (sdq, sdr) = gradient_parameters(z_um, width, height, pitch_mm * LengthUnit::Mm.um_per_unit());
    let centred: Vec<f64> = valid.iter().map(|v| v - mean).collect();
    let curve = MaterialRatioCurve::new(&centred)?;
    let (p, q) = (DEFAULT_P_PERCENT, DEFAULT_Q_PERCENT);
    // ISO 25178-2 §4.5.2-4.5.5: Vmp = Vm(p), Vmc = Vm(q) - Vm(p),
    // Vvc = Vv(p) - Vv(q), Vvv = Vv(q).
    Some(ArealParameters {
        sq_um: m.rms,
        ssk: m.skewness,
        sku: m.kurtosis,
        sp_um: m.highest,
        sv_um: -m.lowest,
        sz_um: m.highest - m.lowest,
        sa_um: m.mean_abs,
        sdq,
        sdr_percent: sdr,
        smr_percent: curve.material_ratio_percent(points.smr_c_um),
        smc_um: curve.height_at_ratio_um(points.smc_mr_percent),
        core: curve.core_parameters(),
        vmp_um: curve.material_volume_um(p),
        vmc_um: curve.material_volume_um(q) - curve.material_volume_um(p),
        vvc_um: curve.void_volume_um(p) - curve.void_volume_um(q),
        vvv_um: curve.void_volume_um(q),
        nodes: n,
    })
}

/// The amplitude parameters of heights about their mean: ISO 25178-2
/// Eqs. (4.1)-(4.4), (4.7) for a surface (Sa, Sq, Ssk, Sku, Sp, Sv) and
/// ISO 21920-2 §4.4 for a profile (Ra, Rq, Rsk, Rku), which are the same
/// sums over samples instead of nodes.
pub(crate) struct HeightMoments {
    pub mean: f64,
    /// Arithmetical mean deviation (Sa, Ra).
    pub mean_abs: f64,
    /// Root mean square deviation (Sq, Rq).
    pub rms: f64,
    /// Skewness (Ssk, Rsk); 0 for a surface without spread.
    pub skewness: f64,
    /// Kurtosis (Sku, Rku); 0 for a surface without spread.
    pub kurtosis: f64,
    /// The highest and lowest height about the mean.
    pub highest: f64,
    pub lowest: f64,
}

impl HeightMoments {
    /// The moments of `valid` (finite heights; at least one).
    pub(crate) fn of(valid: &[f64]) -> Self {
        let n = valid.len() as f64;
        let mean = valid.iter().sum::<f64>() / n;
        let (mut m1, mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0, 0.0);
        let (mut highest, mut lowest) = (f64::NEG_INFINITY, f64::INFINITY);
        for v in valid {
            let d = v - mean;
            let d2 = d * d;
            m1 += d.abs();
            m2 += d2;
            m3 += d2 * d;
            m4 += d2 * d2;
            highest = highest.max(d);
            lowest = lowest.min(d);
        }
        let rms = (m2 / n).sqrt();
        let (skewness, kurtosis) = if rms > 0.0 { (m3 / n / rms.powi(3), m4 / n / rms.powi(4)) } else { (0.0, 0.0) };
        Self { mean, mean_abs: m1 / n, rms, skewness, kurtosis, highest, lowest }
    }
}

/// Sdq (ISO 25178-2 Eq. 4.8) and Sdr in % (Eq. 4.9) from central differences
/// with the lateral spacing `pitch_um` in the heights' unit.
fn gradient_parameters(z: &[f64], width: usize, height: usize, pitch_um: f64) -> (f64, f64) {
    let (mut sum_g2, mut sum_area, mut count) = (0.0, 0.0, 0usize);
    for r in 1..height.saturating_sub(1) {
        for c in 1..width.saturating_sub(1) {
            let i = r * width + c;
            let (l, rt, u, d) = (z[i - 1], z[i + 1], z[i - width], z[i + width]);
            if !(z[i].is_finite() && l.is_finite() && rt.is_finite() && u.is_finite() && d.is_finite()) {
                continue;
            }
            let gx = (rt - l) / (2.0 * pitch_um);
            let gy = (d - u) / (2.0 * pitch_um);
            let g2 = gx * gx + gy * gy;
            sum_g2 += g2;
            sum_area += (1.0 + g2).sqrt() - 1.0;
            count += 1;
        }
    }
    if count == 0 {
        return (f64::NAN, f64::NAN);
    }
    ((sum_g2 / count as f64).sqrt(), 100.0 * sum_area / count as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn close(got: f64, want: f64, what: &str) {
        assert!((got - want).abs() <= 0.01 * want.abs().max(1e-3), "{what}: {got}, expected {want}");
    }

    /// A map of `f(x_um, y_um)` over whole periods of wavelength `lambda_um`.
    fn map(periods: usize, per_period: usize, lambda_um: f64, f: impl Fn(f64, f64) -> f64) -> (Vec<f64>, usize, f64) {
        let n = periods * per_period;
        let pitch_um = lambda_um / per_period as f64;
        let z = (0..n * n).map(|i| f((i % n) as f64 * pitch_um, (i / n) as f64 * pitch_um)).collect();
        (z, n, pitch_um / 1000.0)
    }

    #[test]
    fn sine_in_x_matches_the_analytic_values() {
        let (a, lambda) = (0.5, 100.0);
        let k = 2.0 * PI / lambda;
        let (z, n, pitch_mm) = map(8, 64, lambda, |x, _| a * (k * x).sin());
        let s = areal_parameters(&z, n, n, pitch_mm, MaterialRatioPoints::default()).unwrap();
        close(s.sa_um, 2.0 * a / PI, "Sa");
        close(s.sq_um, a / 2f64.sqrt(), "Sq");
        assert!(s.ssk.abs() < 0.01, "Ssk {}", s.ssk);
        close(s.sku, 1.5, "Sku");
        close(s.sz_um, 2.0 * a, "Sz");
        close(s.sdq, a * k / 2f64.sqrt(), "Sdq");
        close(s.smr_percent, 50.0, "Smr(0)");
    }

    #[test]
    fn product_of_sines_matches_the_analytic_values() {
        let (a, lambda) = (1.5, 80.0);
        let k = 2.0 * PI / lambda;
        let (z, n, pitch_mm) = map(6, 64, lambda, |x, y| a * (k * x).sin() * (k * y).sin());
        let s = areal_parameters(&z, n, n, pitch_mm, MaterialRatioPoints::default()).unwrap();
        close(s.sq_um, a / 2.0, "Sq");
        close(s.sa_um, 4.0 * a / (PI * PI), "Sa");
        close(s.sku, 2.25, "Sku");
    }

    #[test]
    fn holes_are_skipped_not_read() {
        let (a, lambda) = (0.5, 100.0);
        let k = 2.0 * PI / lambda;
        let (mut z, n, pitch_mm) = map(8, 64, lambda, |x, _| a * (k * x).sin());
        let full = areal_parameters(&z, n, n, pitch_mm, MaterialRatioPoints::default()).unwrap();
        // Knock out every fifth row (each row holds whole periods): the remaining
        // heights keep the same distribution, so Sq must not move.
        for (i, v) in z.iter_mut().enumerate() {
            if (i / n) % 5 == 2 {
                *v = f64::NAN;
            }
        }
        let holed = areal_parameters(&z, n, n, pitch_mm, MaterialRatioPoints::default()).unwrap();
        assert!(holed.nodes < full.nodes);
        close(holed.sq_um, full.sq_um, "Sq with holes");
        assert!(holed.sdq.is_finite() && holed.sdr_percent.is_finite());
    }

    #[test]
    fn volume_parameters_of_uniform_heights() {
        // A ramp z = x over a square has uniformly distributed heights on
        // [-h, h] about its mean: Vm(p) = h p², Vv(p) = h (1-p)².
        let n = 1000;
        let h = 1.0;
        let z: Vec<f64> = (0..n * n).map(|i| -h + 2.0 * h * ((i % n) as f64 + 0.5) / n as f64).collect();
        let s = areal_parameters(&z, n, n, 0.001, MaterialRatioPoints::default()).unwrap();
        close(s.vmp_um, h * 0.01, "Vmp");
        close(s.vmc_um, h * (0.64 - 0.01), "Vmc");
        close(s.vvc_um, h * (0.81 - 0.04), "Vvc");
        close(s.vvv_um, h * 0.04, "Vvv");
        close(s.core.sk_um, 2.0 * h, "Sk");
        close(s.sdq, 2.0 * h / 1000.0, "Sdq of a ramp 2 µm over 1000 µm");
    }
}
