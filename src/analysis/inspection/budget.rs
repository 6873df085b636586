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
    Contribution, NodeNoise, ScaleUncertainty, Uncertainty, UncertaintyMethod, height_scale_contribution, mean_and_std,
    monte_carlo, plane_covariance, tilt_uncertainty_deg,
};

/// What every row's budget draws on besides its own data.
#[derive(Clone, Copy, Debug)]
pub(super) struct Budgets<'a> {
    pub map: &'a HeightMap,
    pub calibration: ScaleUncertainty,
    /// Monte Carlo trials; 0 = rows that need them state no uncertainty.
    pub trials: usize,
}

/// "noise of 'base' (σ .. per node, F nodes per independent one)".
fn noise_source(what: &str, noise: NodeNoise, measured: bool) -> String {
    if measured {
        format!("height noise of {what} ({})", noise.describe())
    } else {
        format!(
            "height noise of {what} (residual RMS {:.3} um as independent node noise: the region is too small to \
             measure its correlation)",
            noise.sigma_um
        )
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

impl Budgets<'_> {
    /// A step height: both planes by propagation, and the height scale.
    pub fn step(&self, s: &StepHeight, reference: &str, measured: &str) -> Uncertainty {
        let noise = |n: Option<NodeNoise>, fit: &PlaneFit| {
            n.unwrap_or(NodeNoise { sigma_um: fit.rms_um / fit.plane.cos_tilt(), correlation_factor: 1.0 })
        };
        Uncertainty::from_budget(
            UncertaintyMethod::Propagation,
            vec![
                Contribution::new(
                    noise_source(
                        &format!("reference plane '{reference}' at the measured centroid"),
                        noise(s.reference_noise, &s.reference),
                        s.reference_noise.is_some(),
                    ),
                    s.u_reference_um,
                ),
                Contribution::new(
                    noise_source(
                        &format!("measured plane '{measured}'"),
                        noise(s.measured_noise, &s.measured),
                        s.measured_noise.is_some(),
                    ),
                    s.u_measured_um,
                ),
                height_scale_contribution(&self.calibration, s.height_um),
            ],
        )
    }

    /// Covariance of the slopes (rise over run) of a plane fitted to `regions`.
    fn slope_covariance(&self, regions: &[NamedRegion], fit: &PlaneFit) -> Option<([[f64; 2]; 2], String)> {
        let (noise, measured) = fit_noise(self.map, regions, fit);
        let points = region_samples(self.map, regions).points_mm;
        // Heights in the map's unit, as its X-Y: the slopes are ratios.
        let sigma = noise.sigma_um / self.map.unit.um_per_unit();
        let c = plane_covariance(&points, sigma, noise.correlation_factor)?;
        Some((c.slope_cov, noise_source(&format!("plane '{}'", fit.region), noise, measured)))
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
        let (noise, measured) = fit_noise(self.map, regions, fit);
        let grid = region_grid(self.map, regions)?;
        let pv_rms = |m: &HeightMap| measure(m).map(|(pv, rms)| vec![pv, rms]);
        let trials = monte_carlo(self.map, grid.window(), noise, self.trials, seed, pv_rms);
        // The noise alone: the same nodes, flat.
        let mut flat = self.map.clone();
        for z in flat.z.iter_mut().filter(|z| !z.is_nan()) {
            *z = 0.0;
        }
        let floors = monte_carlo(&flat, grid.window(), noise, self.trials, seed ^ 0x5eed, pv_rms);
        let source = noise_source(&format!("'{}'", region.name), noise, measured);
        Some([0, 1].map(|k| {
            let (_, u) = mean_and_std(trials.iter().map(|t| t[k]));
            let mut floor: Vec<f64> = floors.iter().map(|t| t[k]).collect();
            floor.sort_by(f64::total_cmp);
            Uncertainty::from_budget(
                UncertaintyMethod::MonteCarlo,
                vec![
                    Contribution::new(format!("{source}, by Monte Carlo"), u),
                    height_scale_contribution(&self.calibration, values[k]),
                ],
            )
            .with_trials(trials.len())
            .with_noise_floor(floor.get(floor.len() / 2).copied().unwrap_or(f64::NAN))
        }))
    }

    /// Coplanarity and each land's largest deviation by Monte Carlo (the
    /// noise pooled over the lands, each measured around its own plane).
    pub fn coplanarity(&self, lands: &[NamedRegion], values: &[f64], seed: u64) -> Option<Vec<Uncertainty>> {
        if self.trials < 2 {
            return None;
        }
        let (mut var, mut factor, mut nodes, mut all_measured) = (0.0, 0.0, 0.0, true);
        for land in lands {
            let fit = fit_plane(self.map, std::slice::from_ref(land)).ok()?;
            let (n, measured) = fit_noise(self.map, std::slice::from_ref(land), &fit);
            let w = fit.samples as f64;
            var += w * n.sigma_um * n.sigma_um;
            factor += w * n.correlation_factor;
            nodes += w;
            all_measured &= measured;
        }
        let noise = NodeNoise { sigma_um: (var / nodes).sqrt(), correlation_factor: factor / nodes };
        let grid = region_grid(self.map, lands)?;
        let trials = monte_carlo(self.map, grid.window(), noise, self.trials, seed, |m| {
            let c = coplanarity(m, lands).ok()?;
            Some(std::iter::once(c.coplanarity_um).chain(c.lands.iter().map(|l| l.max_abs_deviation_um())).collect())
        });
        let source = noise_source("the lands", noise, all_measured);
        Some(
            values
                .iter()
                .enumerate()
                .map(|(k, &v)| {
                    let (_, u) = mean_and_std(trials.iter().map(|t| t[k]));
                    Uncertainty::from_budget(
                        UncertaintyMethod::MonteCarlo,
                        vec![
                            Contribution::new(format!("{source}, by Monte Carlo"), u),
                            height_scale_contribution(&self.calibration, v),
                        ],
                    )
                    .with_trials(trials.len())
                })
                .collect(),
        )
    }

    /// Per-parameter uncertainties of a set of parameters (texture, profile)
    /// from Monte Carlo trials of all of them on `window` of the map: one
    /// entry per value of `values`, `None` where too few trials gave it.
    pub fn parameters<F>(
        &self,
        window: [usize; 4],
        (noise, noise_source): &(NodeNoise, String),
        trials: usize,
        seed: u64,
        values: &[(f64, &str)],
        measure: F,
    ) -> Vec<Option<Uncertainty>>
    where
        F: Fn(&HeightMap) -> Option<Vec<f64>> + Sync,
    {
        if trials < 2 {
            return vec![None; values.len()];
        }
        let results = monte_carlo(self.map, window, *noise, trials, seed, measure);
        values
            .iter()
            .enumerate()
            .map(|(k, &(value, unit))| {
                let got: Vec<f64> =
                    results.iter().filter_map(|t| t.get(k).copied()).filter(|v| v.is_finite()).collect();
                if !value.is_finite() || got.len() < trials.div_ceil(2).max(2) {
                    return None;
                }
                let (_, u) = mean_and_std(got.iter().copied());
                let mut budget = vec![Contribution::new(format!("{noise_source}, by Monte Carlo"), u)];
                budget.extend(calibration_line(&self.calibration, value, unit));
                Some(Uncertainty::from_budget(UncertaintyMethod::MonteCarlo, budget).with_trials(got.len()))
            })
            .collect()
    }
}
