//! The areal material ratio curve (Abbott-Firestone curve) and the parameters
//! read from it: Smr(c), Smc(mr), the Sk family and the volume parameters of
//! ISO 25178-2 §4.4 and §4.5 (the same construction as ISO 13565-2 for
//! profiles, so the profile Rmr(c) and Rdc reuse it).
//!
//! The curve is evaluated on the sorted heights themselves: with N valid
//! nodes, the material ratio of height `h` is the share of nodes at or above
//! it. Integrals over the curve (peak and valley areas, volumes) are sums over
//! nodes, so they are exact for the sampled surface rather than a quadrature
//! of an interpolated curve.

/// Heights sorted from highest to lowest, the material ratio curve's
/// ordinates at `mr_i = (i + 0.5) / N`.
#[derive(Clone, Debug)]
pub struct MaterialRatioCurve {
    descending_um: Vec<f64>,
}

/// The Sk family (ISO 25178-2 §4.5, ISO 13565-2 §4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoreParameters {
    pub sk_um: f64,
    pub spk_um: f64,
    pub svk_um: f64,
    pub smr1_percent: f64,
    pub smr2_percent: f64,
}

impl MaterialRatioCurve {
    /// The curve of the finite values in `heights_um`; `None` when fewer than two.
    pub fn new(heights_um: &[f64]) -> Option<Self> {
        let mut d: Vec<f64> = heights_um.iter().copied().filter(|v| v.is_finite()).collect();
        if d.len() < 2 {
            return None;
        }
        d.sort_unstable_by(|a, b| b.total_cmp(a));
        Some(Self { descending_um: d })
    }

    fn n(&self) -> f64 {
        self.descending_um.len() as f64
    }

    /// Smr(c): share of the surface at or above height `c_um`, in percent.
    pub fn material_ratio_percent(&self, c_um: f64) -> f64 {
        let above = self.descending_um.partition_point(|h| *h >= c_um);
        100.0 * above as f64 / self.n()
    }

    /// Smc(mr): the height at which the material ratio is `mr_percent`
    /// (inverse of Smr), linearly interpolated between nodes.
    pub fn height_at_ratio_um(&self, mr_percent: f64) -> f64 {
        let d = &self.descending_um;
        let pos = (mr_percent / 100.0 * self.n() - 0.5).clamp(0.0, self.n() - 1.0);
        let i = pos.floor() as usize;
        let j = (i + 1).min(d.len() - 1);
        let t = pos - i as f64;
        d[i] * (1.0 - t) + d[j] * t
    }

    /// Vm(p): material volume per unit area above the height at ratio `p`
    /// (µm³/µm², reported in µm), ISO 25178-2 Eq. (4.16).
    pub fn material_volume_um(&self, p_percent: f64) -> f64 {
        let c = self.height_at_ratio_um(p_percent);
        self.descending_um.iter().take_while(|h| **h > c).map(|h| h - c).sum::<f64>() / self.n()
    }

    /// Vv(p): void volume per unit area below the height at ratio `p`,
    /// ISO 25178-2 Eq. (4.15).
    pub fn void_volume_um(&self, p_percent: f64) -> f64 {
        let c = self.height_at_ratio_um(p_percent);
        self.descending_um.iter().rev().take_while(|h| **h < c).map(|h| c - h).sum::<f64>() / self.n()
    }

    /// The Sk family. The equivalent straight line is the secant over a 40 %
    /// material-ratio window with the least gradient (ISO 13565-2 §4.3); its
    /// heights at 0 % and 100 % bound the core. Spk and Svk are the heights of
    /// triangles with the same area as the peaks above and the valleys below
    /// the core (§4.4).
    pub fn core_parameters(&self) -> CoreParameters {
        // Scan the window start in 0.1 % steps, as fine as the ratio matters.
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for step in 0..=600 {
            let m0 = step as f64 * 0.1;
            let (c0, c1) = (self.height_at_ratio_um(m0), self.height_at_ratio_um(m0 + 40.0));
            let gradient = (c0 - c1) / 40.0; // µm per %, ≥ 0 on a descending curve
            if gradient < best.0 {
                best = (gradient, m0, c0);
            }
        }
        let (gradient, m0, c0) = best;
        let top = c0 + gradient * m0;
        let bottom = c0 - gradient * (100.0 - m0);
        let smr1 = self.material_ratio_percent(top);
        let smr2 = self.material_ratio_percent(bottom);
        let n = self.n();
        let peak_area: f64 = self.descending_um.iter().take_while(|h| **h > top).map(|h| h - top).sum::<f64>() / n;
        let valley_area: f64 =
            self.descending_um.iter().rev().take_while(|h| **h < bottom).map(|h| bottom - h).sum::<f64>() / n;
        let spk = if smr1 > 0.0 { 2.0 * peak_area / (smr1 / 100.0) } else { 0.0 };
        let svk = if smr2 < 100.0 { 2.0 * valley_area / (1.0 - smr2 / 100.0) } else { 0.0 };
        CoreParameters { sk_um: top - bottom, spk_um: spk, svk_um: svk, smr1_percent: smr1, smr2_percent: smr2 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Heights whose material ratio curve is exactly `c(mr)`.
    fn heights_of_curve(n: usize, c: impl Fn(f64) -> f64) -> Vec<f64> {
        (0..n).map(|i| c((i as f64 + 0.5) / n as f64)).collect()
    }

    fn close(got: f64, want: f64, what: &str) {
        assert!((got - want).abs() <= 0.01 * want.abs().max(1e-3), "{what}: {got}, expected {want}");
    }

    #[test]
    fn uniform_heights_have_a_linear_curve_and_known_volumes() {
        // Heights uniform on [-h, h]: c(mr) = h (1 - 2 mr), Vm(p) = h p², Vv(p) = h (1 - p)².
        let h = 2.0;
        let curve = MaterialRatioCurve::new(&heights_of_curve(100_000, |m| h * (1.0 - 2.0 * m))).unwrap();
        close(curve.material_ratio_percent(0.0), 50.0, "Smr(0)");
        close(curve.material_ratio_percent(h / 2.0), 25.0, "Smr(h/2)");
        close(curve.height_at_ratio_um(10.0), 0.8 * h, "Smc(10 %)");
        close(curve.material_volume_um(10.0), h * 0.01, "Vm(10 %)");
        close(curve.void_volume_um(80.0), h * 0.04, "Vv(80 %)");
        let core = curve.core_parameters();
        close(core.sk_um, 2.0 * h, "Sk");
        assert!(core.spk_um.abs() < 0.01 && core.svk_um.abs() < 0.01);
    }

    #[test]
    fn piecewise_linear_curve_gives_analytic_core_parameters() {
        // Peaks 3 → 1 over 0-10 %, core 1 → -1 over 10-90 %, valleys -1 → -4
        // over 90-100 %. Core line: slope -2.5 µm per unit ratio through the
        // core, so top 1.25, bottom -1.25; Sk 2.5; Smr1 8.75 %, Smr2 90.8333 %;
        // the triangles' heights are 3 - 1.25 and 4 - 1.25.
        let c = |m: f64| {
            if m < 0.1 {
                3.0 - 20.0 * m
            } else if m < 0.9 {
                1.0 - 2.5 * (m - 0.1)
            } else {
                -1.0 - 30.0 * (m - 0.9)
            }
        };
        let curve = MaterialRatioCurve::new(&heights_of_curve(200_000, c)).unwrap();
        let core = curve.core_parameters();
        close(core.sk_um, 2.5, "Sk");
        close(core.smr1_percent, 8.75, "Smr1");
        close(core.smr2_percent, 90.0 + 0.25 / 30.0 * 100.0, "Smr2");
        close(core.spk_um, 1.75, "Spk");
        close(core.svk_um, 2.75, "Svk");
    }
}
