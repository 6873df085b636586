//! The uncertainty budget of each kind of inspection row (module docs of
//! [`crate::analysis::uncertainty`]): plane-based rows by propagation,
//! peak-to-valley, coplanarity, texture and profile parameters by Monte
//! Carlo on the map itself, each with the calibration's scale where it
//! applies.

use super::super::coplanarity::coplanarity;
use super::super::height_map::HeightMap;
use super::super::plane_fit::{PlaneFit, fit_plane};
use super::super::region::{NamedRegion, region_grid, region_samples};
use super::super::step_height::{StepHeight, fit_noise};
use super::super::uncertainty::{
    Contribution, NodeNoise, PlaneNoises, ScaleUncertainty, Uncertainty, UncertaintyMethod, height_scale_contribution,
    mean_and_std, monte_carlo, monte_carlo_per_node, plane_covariance, relative_node_variance, tilt_uncertainty_deg,
};

/// What every row's budget draws on besides its own data.
#[derive(Clone, Copy, Debug)]
pub(super) struct Budgets<'a> {
    pub map: &'a HeightMap,
    pub calibration: ScaleUncertainty,
    /// Monte Carlo trials; 0 = rows that need them state no uncertainty.
    pub trials: usize,
    /// The noise measured on the inspection's plane regions: each region's
    /// variogram once, and the correlation of all of them together (every
    /// row's planes use it: one region alone measures it poorly, a small one
    /// not at all).
    pub planes: Option<&'a PlaneNoises>,
}

impl Budgets<'_> {
    fn fit_noise(&self, regions: &[NamedRegion], fit: &PlaneFit) -> (NodeNoise, bool) {
        fit_noise(self.map, regions, fit, self.planes)
    }

    /// "noise of 'base' (σ .. per node, F nodes per independent one ...)".
    fn noise_source(&self, what: &str, noise: NodeNoise, measured: bool) -> String {
        let sigma = if measured {
            format!("σ {:.3} um per node", noise.sigma_um)
        } else {
            format!("residual RMS {:.3} um per node: the region is too small for a variogram", noise.sigma_um)
        };
        format!("height noise of {what} ({sigma}, {})", self.correlation_text(noise, measured))
    }

    fn correlation_text(&self, noise: NodeNoise, measured: bool) -> String {
        match self.planes.and_then(|p| p.pooled_factor.map(|f| (f, p.by_label.len()))) {
            Some((factor, regions)) => format!(
                "{factor:.1} nodes per independent one, the correlation measured on {regions} plane region(s) together"
            ),
            None if measured => format!("{:.1} nodes per independent one", noise.correlation_factor),
            None => "nodes taken as independent".to_string(),
        }
    }
}

/// The calibration's line for a value in `unit`: the height scale for
/// heights (um), the lateral scale for lengths (mm), none otherwise.
fn calibration_line(calibration: &ScaleUncertainty, value: f64, unit: &str) -> Option<Contribution> {
    match unit {
        "um" => Some(height_scale_contribution(calibration, value)),
        "mm" => calibration
            .lateral_relative
            .map(|rel| Contribution::new(format!("calibration lateral scale ({rel:.3e} relative)"), value.abs() * rel)),
        _ => None,
    }
}

/// The height map's resampling, for a result of least-squares planes: the
/// map interpolates the cloud linearly over its triangles, which reproduces
/// a plane exactly (test `a_tilted_planes_map_is_the_plane_at_every_node`),
/// and what it does to the noise (neighbouring nodes share points) is in
/// the node noise measured on the map. Stated, with its reason, so the
/// budget shows it was considered.
fn resampling_line() -> Contribution {
    Contribution::new(
        "height-map resampling (linear over the cloud's triangles: a plane exactly; its effect on the noise is in the \
         node noise measured on the map)",
        0.0,
    )
}

/// `u` with the resampling's line added (it adds nothing to `u`).
fn with_resampling(mut u: Uncertainty) -> Uncertainty {
    u.budget.push(resampling_line());
    u
}

impl Budgets<'_> {
    /// A step height: both planes by propagation, and the height scale.
    pub fn step(&self, s: &StepHeight, reference: &str, measured: &str) -> Uncertainty {
        let ((ref_noise, ref_measured), (meas_noise, meas_measured)) = (s.reference_noise, s.measured_noise);
        Uncertainty::from_budget(
            UncertaintyMethod::Propagation,
            vec![
                Contribution::new(
                    self.noise_source(
                        &format!("reference plane '{reference}' at the measured centroid"),
                        ref_noise,
                        ref_measured,
                    ),
                    s.u_reference_um,
                ),
                Contribution::new(
                    self.noise_source(&format!("measured plane '{measured}'"), meas_noise, meas_measured),
                    s.u_measured_um,
                ),
                height_scale_contribution(&self.calibration, s.height_um),
                resampling_line(),
            ],
        )
    }

    /// Covariance of the slopes (rise over run) of a plane fitted to `regions`.
    fn slope_covariance(&self, regions: &[NamedRegion], fit: &PlaneFit) -> Option<([[f64; 2]; 2], String)> {
        let (noise, measured) = self.fit_noise(regions, fit);
        let points = region_samples(self.map, regions).points_mm;
        // Heights in the map's unit, as its X-Y: the slopes are ratios.
        let sigma = noise.sigma_um / self.map.unit.um_per_unit();
        let weights = relative_node_variance(self.map, regions, &fit.plane, noise.correlation_factor);
        let c = plane_covariance(&points, sigma, noise.correlation_factor, weights.as_deref())?;
        Some((c.slope_cov, self.noise_source(&format!("plane '{}'", fit.region), noise, measured)))
    }

    /// A plane's tilt, against the levelling plane when levelled: the
    /// slopes' covariance of each, and the scales' ratio.
    pub fn tilt(
        &self,
        regions: &[NamedRegion],
        fit: &PlaneFit,
        levelling: Option<(&[NamedRegion], &PlaneFit)>,
    ) -> Option<Uncertainty> {
        let mut g = [fit.plane.slope_x, fit.plane.slope_y];
        let (own, own_source) = self.slope_covariance(regions, fit)?;
        let mut budget = Vec::new();
        let reference = match levelling {
            Some((ref_regions, ref_fit)) => {
                g = [g[0] - ref_fit.plane.slope_x, g[1] - ref_fit.plane.slope_y];
                Some(self.slope_covariance(ref_regions, ref_fit)?)
            }
            None => None,
        };
        budget.push(Contribution::new(own_source, tilt_uncertainty_deg(g, own)));
        if let Some((cov, source)) = reference {
            budget.push(Contribution::new(format!("levelling: {source}"), tilt_uncertainty_deg(g, cov)));
        }
        let norm = g[0].hypot(g[1]);
        let rel = self.calibration.slope_relative();
        budget.push(resampling_line());
        budget.push(if self.calibration.is_known() {
            Contribution::new(
                format!("calibration height and lateral scales ({rel:.3e} relative on the slope)"),
                (norm * rel / (1.0 + norm * norm)).to_degrees(),
            )
        } else {
            Contribution::new("calibration scales (not stated by the calibration: taken as 0)", 0.0)
        });
        Some(Uncertainty::from_budget(UncertaintyMethod::Propagation, budget))
    }

    /// Peak-to-valley and RMS flatness of `region` by Monte Carlo, with the
    /// noise floor (the PV and RMS of the noise alone on its nodes).
    /// `measure` computes (PV, RMS) on a map; `values` are the measured ones.
    pub fn flatness<F>(
        &self,
        region: &NamedRegion,
        fit: &PlaneFit,
        values: [f64; 2],
        seed: u64,
        measure: F,
    ) -> Option<[Uncertainty; 2]>
    where
        F: Fn(&HeightMap) -> Option<(f64, f64)> + Sync,
    {
        if self.trials < 2 {
            return None;
        }
        let regions = std::slice::from_ref(region);
        let (noise, measured) = self.fit_noise(regions, fit);
        let grid = region_grid(self.map, regions)?;
        let pv_rms = |m: &HeightMap| measure(m).map(|(pv, rms)| vec![pv, rms]);
        let trials = monte_carlo(self.map, grid.window(), noise, self.trials, seed, pv_rms);
        let floors = monte_carlo(&self.flattened(), grid.window(), noise, self.trials, seed ^ 0x5eed, pv_rms);
        let source = self.noise_source(&format!("'{}'", region.name), noise, measured);
        let pairs = |t: &[Vec<f64>]| t.iter().map(|t| [t[0], t[1]]).collect::<Vec<_>>();
        Some(self.flatness_statements(&source, values, &pairs(&trials), &pairs(&floors)))
    }

    /// The map's nodes, flat: what a noise floor's trials add the noise
    /// alone to.
    fn flattened(&self) -> HeightMap {
        let mut flat = self.map.clone();
        for z in flat.z.iter_mut().filter(|z| !z.is_nan()) {
            *z = 0.0;
        }
        flat
    }

    /// A Monte Carlo statement: u the spread of the trials' `samples`, and
    /// the calibration's line for `value` in `unit`.
    fn monte_carlo_statement(&self, source: &str, samples: &[f64], value: f64, unit: &str) -> Uncertainty {
        let (_, u) = mean_and_std(samples.iter().copied());
        let mut budget = vec![Contribution::new(format!("{source}, by Monte Carlo"), u)];
        budget.extend(calibration_line(&self.calibration, value, unit));
        Uncertainty::from_budget(UncertaintyMethod::MonteCarlo, budget).with_trials(samples.len())
    }

    /// PV and RMS statements from the trials' (PV, RMS) with the noise
    /// added and of the noise alone (whose median is the noise floor).
    fn flatness_statements(
        &self,
        source: &str,
        values: [f64; 2],
        with_noise: &[[f64; 2]],
        alone: &[[f64; 2]],
    ) -> [Uncertainty; 2] {
        [0, 1].map(|k| {
            let samples: Vec<f64> = with_noise.iter().map(|t| t[k]).collect();
            let mut floor: Vec<f64> = alone.iter().map(|t| t[k]).collect();
            floor.sort_by(f64::total_cmp);
            with_resampling(self.monte_carlo_statement(source, &samples, values[k], "um"))
                .with_noise_floor(floor.get(floor.len() / 2).copied().unwrap_or(f64::NAN))
        })
    }

    /// [`Self::flatness`] of an unfiltered flatness, without a map per
    /// trial: a least-squares plane is linear in the heights, so the
    /// residual of heights plus noise is the measured residual plus the
    /// noise's own residual. Each trial draws the noise on the region's
    /// window, fits its plane at the region's nodes and takes PV and RMS of
    /// the sum (the value's spread) and of the noise alone (the floor): one
    /// pass over the nodes, not a perturbed map measured again.
    pub fn flatness_unfiltered(&self, region: &NamedRegion, fit: &PlaneFit, seed: u64) -> Option<[Uncertainty; 2]> {
        use rand::SeedableRng;
        use rayon::prelude::*;
        if self.trials < 2 {
            return None;
        }
        let regions = std::slice::from_ref(region);
        let (noise, measured) = self.fit_noise(regions, fit);
        let grid = region_grid(self.map, regions)?;
        let cos = fit.plane.cos_tilt();
        let scale = self.map.unit.um_per_unit();
        let [cx, cy, _] = fit.centroid_mm;
        // (window index, centred x, centred y, residual um) of each valid node.
        let mut nodes: Vec<(usize, f64, f64, f64)> = Vec::new();
        for k in 0..grid.height {
            for j in 0..grid.width {
                let (c, r) = (grid.c0 + j, grid.r0 + k);
                let z = self.map.z[r * self.map.width + c];
                if grid.inside[k * grid.width + j] && !z.is_nan() {
                    let (x, y) = (self.map.x_mm(c), self.map.y_mm(r));
                    let residual = (f64::from(z) - fit.plane.z_at(x, y)) * cos * scale;
                    nodes.push((k * grid.width + j, x - cx, y - cy, residual));
                }
            }
        }
        let n = nodes.len() as f64;
        let (sxx, sxy, syy) =
            nodes.iter().fold((0.0, 0.0, 0.0), |(a, b, c), &(_, x, y, _)| (a + x * x, b + x * y, c + y * y));
        let det = sxx * syy - sxy * sxy;
        if nodes.len() < 3 || !(det > 0.0) {
            return None;
        }
        let blur = noise.blur_sigma_nodes();
        // Each node its own share of σ (a peak-to-valley is made by the
        // noisiest nodes), in the order of the region's valid samples.
        let mut node_sigma = vec![1.0; grid.width * grid.height];
        if let Some(relative) = relative_node_variance(self.map, regions, &fit.plane, noise.correlation_factor) {
            for (&(at, ..), w) in nodes.iter().zip(relative) {
                node_sigma[at] = w.sqrt();
            }
        }
        let pv_rms = |values: &mut dyn Iterator<Item = f64>| {
            let (mut lo, mut hi, mut sum2) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
            for v in values {
                lo = lo.min(v);
                hi = hi.max(v);
                sum2 += v * v;
            }
            [hi - lo, (sum2 / n).sqrt()]
        };
        let (with_noise, alone): (Vec<[f64; 2]>, Vec<[f64; 2]>) = (0..self.trials as u64)
            .into_par_iter()
            .map(|i| {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed.wrapping_add(i));
                let field = super::super::uncertainty::correlated_noise(grid.width, grid.height, blur, &mut rng);
                let e = |at: usize| noise.sigma_um * node_sigma[at] * field[at];
                let (mut mean, mut sxe, mut sye) = (0.0, 0.0, 0.0);
                for &(at, x, y, _) in &nodes {
                    let v = e(at);
                    mean += v;
                    sxe += x * v;
                    sye += y * v;
                }
                mean /= n;
                // Centred coordinates: the slopes do not depend on the mean.
                let a = (sxe * syy - sye * sxy) / det;
                let b = (sye * sxx - sxe * sxy) / det;
                let own = |&(at, x, y, _): &(usize, f64, f64, f64)| (e(at) - mean - a * x - b * y) * cos;
                let with_noise = pv_rms(&mut nodes.iter().map(|node| node.3 + own(node)));
                let alone = pv_rms(&mut nodes.iter().map(own));
                (with_noise, alone)
            })
            .unzip();
        let source = self.noise_source(&format!("'{}'", region.name), noise, measured);
        Some(self.flatness_statements(&source, [fit.peak_to_valley_um(), fit.rms_um], &with_noise, &alone))
    }

    /// Coplanarity and each land's largest deviation by Monte Carlo, each
    /// land's nodes perturbed by its own measured noise (one correlation,
    /// pooled over the lands: the resampling that makes it is the same
    /// everywhere).
    pub fn coplanarity(&self, lands: &[NamedRegion], values: &[f64], seed: u64) -> Option<Vec<Uncertainty>> {
        if self.trials < 2 {
            return None;
        }
        let grid = region_grid(self.map, lands)?;
        let (mut var, mut factor, mut nodes, mut all_measured) = (0.0, 0.0, 0.0, true);
        let mut sigma_um = vec![0.0; grid.width * grid.height];
        let mut per_land = Vec::with_capacity(lands.len());
        for land in lands {
            let fit = fit_plane(self.map, std::slice::from_ref(land)).ok()?;
            let (n, measured) = self.fit_noise(std::slice::from_ref(land), &fit);
            let own = region_grid(self.map, std::slice::from_ref(land))?;
            // Each node its own share of the land's variance, in the order
            // of the land's valid samples.
            let relative =
                relative_node_variance(self.map, std::slice::from_ref(land), &fit.plane, n.correlation_factor);
            let mut relative = relative.iter().flatten();
            for (k, _) in own.inside.iter().enumerate().filter(|(_, inside)| **inside) {
                let (c, r) = (own.c0 + k % own.width, own.r0 + k / own.width);
                if self.map.z[r * self.map.width + c].is_nan() {
                    continue;
                }
                let share = relative.next().copied().unwrap_or(1.0);
                sigma_um[(r - grid.r0) * grid.width + (c - grid.c0)] = n.sigma_um * share.sqrt();
            }
            per_land.push(format!("'{}' {:.3}", land.name, n.sigma_um));
            let w = fit.samples as f64;
            var += w * n.sigma_um * n.sigma_um;
            factor += w * n.correlation_factor;
            nodes += w;
            all_measured &= measured;
        }
        let noise = NodeNoise { sigma_um: (var / nodes).sqrt(), correlation_factor: factor / nodes };
        let trials = monte_carlo_per_node(
            self.map,
            grid.window(),
            &sigma_um,
            noise.blur_sigma_nodes(),
            self.trials,
            seed,
            |m| {
                let c = coplanarity(m, lands).ok()?;
                Some(
                    std::iter::once(c.coplanarity_um).chain(c.lands.iter().map(|l| l.max_abs_deviation_um())).collect(),
                )
            },
        );
        let source = format!(
            "height noise of the lands (σ per node {} um, each land its own; {})",
            per_land.join(", "),
            self.correlation_text(noise, all_measured)
        );
        Some(
            values
                .iter()
                .enumerate()
                .map(|(k, &v)| {
                    let samples: Vec<f64> = trials.iter().map(|t| t[k]).collect();
                    with_resampling(self.monte_carlo_statement(&source, &samples, v, "um"))
                })
                .collect(),
        )
    }

    /// Per-parameter uncertainties of a set of parameters (texture, profile)
    /// from Monte Carlo trials of all of them on `window` of the map: one
    /// entry per value of `values`, `None` where too few trials gave it.
    /// Where `extremes[k]` (a peak, a valley, their sum: noise raises them)
    /// the statement carries the noise floor too: the median of the
    /// parameter on the same nodes flattened, with the noise alone, as
    /// `extremes_of` measures it (it may measure the extremes alone, which
    /// is cheaper; a quarter of the trials, at least 3: a median needs
    /// fewer than a spread).
    #[allow(clippy::too_many_arguments)]
    pub fn parameters<F, G>(
        &self,
        window: [usize; 4],
        (noise, noise_source): &(NodeNoise, String),
        trials: usize,
        seed: u64,
        values: &[(f64, &str)],
        measure: F,
        (extremes, extremes_of): (&[bool], G),
    ) -> Vec<Option<Uncertainty>>
    where
        F: Fn(&HeightMap) -> Option<Vec<f64>> + Sync,
        G: Fn(&HeightMap) -> Option<Vec<f64>> + Sync,
    {
        if trials < 2 {
            return vec![None; values.len()];
        }
        let results = monte_carlo(self.map, window, *noise, trials, seed, measure);
        let floors = if extremes.iter().any(|e| *e) {
            monte_carlo(&self.flattened(), window, *noise, (trials / 4).max(3), seed ^ 0x5eed, extremes_of)
        } else {
            Vec::new()
        };
        values
            .iter()
            .enumerate()
            .map(|(k, &(value, unit))| {
                let got: Vec<f64> =
                    results.iter().filter_map(|t| t.get(k).copied()).filter(|v| v.is_finite()).collect();
                if !value.is_finite() || got.len() < trials.div_ceil(2).max(2) {
                    return None;
                }
                let statement = self.monte_carlo_statement(noise_source, &got, value, unit);
                if !extremes.get(k).copied().unwrap_or(false) {
                    return Some(statement);
                }
                let mut alone: Vec<f64> =
                    floors.iter().filter_map(|t| t.get(k).copied()).filter(|v| v.is_finite()).collect();
                alone.sort_by(f64::total_cmp);
                Some(match alone.get(alone.len() / 2) {
                    Some(&floor) => statement.with_noise_floor(floor),
                    None => statement,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::region::Region;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Each land of a coplanarity is perturbed by its own noise: of two
    /// lands placed alike, the one four times noisier states clearly more
    /// uncertainty for its deviation (not four times: its noise moves the
    /// common plane, and with it the quiet land's deviation), where one
    /// pooled σ would give both the same.
    #[test]
    fn coplanarity_trials_give_each_land_its_own_noise() {
        let (w, h, pitch) = (160, 60, 0.01);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        let white = Normal::new(0.0, 1.0).expect("normal");
        let z: Vec<f32> = (0..w * h)
            .map(|i| {
                let sigma_mm = if i % w < w / 2 { 1e-4 } else { 4e-4 };
                (sigma_mm * white.sample(&mut rng)) as f32
            })
            .collect();
        let map = HeightMap::new(w, h, 0.0, 0.0, pitch, z).expect("map");
        let lands = [
            NamedRegion::new("quiet", Region::Rectangle { x_mm: [0.05, 0.7], y_mm: [0.05, 0.55] }),
            NamedRegion::new("noisy", Region::Rectangle { x_mm: [0.9, 1.55], y_mm: [0.05, 0.55] }),
        ];
        let c = coplanarity(&map, &lands).expect("coplanarity");
        let values: Vec<f64> =
            std::iter::once(c.coplanarity_um).chain(c.lands.iter().map(|l| l.max_abs_deviation_um())).collect();
        let budgets = Budgets { map: &map, calibration: ScaleUncertainty::default(), trials: 200, planes: None };
        let u = budgets.coplanarity(&lands, &values, 4).expect("statements");
        let ratio = u[2].u / u[1].u;
        assert!((1.4..4.5).contains(&ratio), "noisy / quiet land: {} / {} um", u[2].u, u[1].u);
        let source = &u[0].budget[0].source;
        assert!(source.contains("'quiet' 0.099") && source.contains("'noisy' 0.398"), "{source}");
    }

    /// The resampling's line of a plane-based budget states 0: the map of a
    /// tilted plane sampled on a rotated, offset pixel grid is the plane at
    /// every node.
    #[test]
    fn a_tilted_planes_map_is_the_plane_at_every_node() {
        use crate::analysis::height_map::{RasterParams, height_map_from_cloud};
        use crate::analysis::testing::{GridSpec, grid_cloud};
        let spec = GridSpec { width: 120, height: 90, pitch_mm: 0.0117, angle_deg: 7.0, origin_mm: [0.013, -0.021] };
        let plane = |x: f64, y: f64| 0.02 * x - 0.013 * y + 0.3;
        let cloud = grid_cloud(&spec, |x, y| Some(plane(x, y)));
        let map = height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(0.01), ..Default::default() })
            .expect("map")
            .map;
        let mut nodes = 0;
        for (i, z) in map.z.iter().enumerate().filter(|(_, z)| !z.is_nan()) {
            let (x, y) = (map.x_mm(i % map.width), map.y_mm(i / map.width));
            // f32 heights of 0.3 mm: a few nm of rounding.
            assert!((f64::from(*z) - plane(x, y)).abs() < 5e-8, "node ({x}, {y}): {z}");
            nodes += 1;
        }
        assert!(nodes > 5000, "{nodes} nodes");
        let line = resampling_line();
        assert_eq!(line.u, 0.0);
        assert!(line.source.contains("resampling"));
    }

    /// The one-pass Monte Carlo of a flatness agrees with measuring
    /// perturbed maps again, and its floor is the PV of noise alone.
    #[test]
    fn the_one_pass_flatness_monte_carlo_agrees_with_remeasuring_maps() {
        let (w, h, pitch) = (120, 80, 0.01);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 2e-4).expect("normal");
        let z: Vec<f32> = (0..w * h)
            .map(|i| {
                let x = (i % w) as f64 * pitch;
                // A 3 um bow along X and 0.2 um of white noise.
                (0.003 * ((x - 0.6) / 0.6).powi(2) + 0.001 * x + noise.sample(&mut rng)) as f32
            })
            .collect();
        let map = HeightMap::new(w, h, 0.0, 0.0, pitch, z).expect("map");
        let region = NamedRegion::new("r", Region::Rectangle { x_mm: [0.05, 1.1], y_mm: [0.05, 0.75] });
        let fit = fit_plane(&map, std::slice::from_ref(&region)).expect("fit");
        let budgets = Budgets { map: &map, calibration: ScaleUncertainty::default(), trials: 200, planes: None };
        let fast = budgets.flatness_unfiltered(&region, &fit, 9).expect("fast");
        let slow = budgets
            .flatness(&region, &fit, [fit.peak_to_valley_um(), fit.rms_um], 9, |m| {
                let f = fit_plane(m, std::slice::from_ref(&region)).ok()?;
                Some((f.peak_to_valley_um(), f.rms_um))
            })
            .expect("slow");
        for k in 0..2 {
            let ratio = fast[k].u / slow[k].u;
            assert!((0.75..1.33).contains(&ratio), "statistic {k}: {} vs {}", fast[k].u, slow[k].u);
            let floors = (fast[k].noise_floor.expect("floor"), slow[k].noise_floor.expect("floor"));
            assert!((floors.0 / floors.1 - 1.0).abs() < 0.1, "{floors:?}");
        }
        // The floor of 0.2 um white noise on ~7000 nodes: about 7.5 sigma PV, sigma RMS.
        let pv_floor = fast[0].noise_floor.expect("floor");
        assert!(pv_floor > 1.2 && pv_floor < 1.9, "{pv_floor}");
        assert!((fast[1].noise_floor.expect("floor") - 0.2).abs() < 0.02);
    }
}
