//! Step height between two regions, evaluated as step-height standards are:
//! a least-squares plane is fitted to the reference region(s) and one to the
//! measured region(s); the step is the distance of the measured plane from
//! the reference plane at the centroid of the measured samples, taken along
//! the reference plane's normal. At the centroid the measured plane equals
//! the samples' mean height, where a fitted plane is best determined.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::height_map::HeightMap;
use super::plane_fit::{PlaneFit, fit_plane};
use super::region::{NamedRegion, label, region_samples};
use super::uncertainty::{NodeNoise, PlaneNoises, node_noise, plane_covariance, relative_node_variance};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepHeight {
    /// Measured plane minus reference plane along the reference normal
    /// (positive when the measured surface is on the +Z side).
    pub height_um: f64,
    /// Standard uncertainty of `height_um` from the node noise of both
    /// planes (Type A, [`node_noise`]: its spatial correlation included),
    /// the root sum of `u_reference_um` and `u_measured_um`; the
    /// calibration is added by the inspection.
    pub uncertainty_um: f64,
    /// The reference plane's height at `at_mm`: `σ² F (1/N + dᵀS⁻¹d)`.
    pub u_reference_um: f64,
    /// The measured plane's height at its own centroid: `σ² F / N`.
    pub u_measured_um: f64,
    /// The node noise each plane's u was propagated from, and whether it
    /// was measured ([`fit_noise`]: false where the region is too small for
    /// the correlation, and its residual RMS stands for independent noise).
    #[serde(skip)]
    pub reference_noise: (NodeNoise, bool),
    #[serde(skip)]
    pub measured_noise: (NodeNoise, bool),
    /// X-Y where the planes are compared: centroid of the measured samples.
    pub at_mm: [f64; 2],
    pub reference: PlaneFit,
    pub measured: PlaneFit,
    /// Angle between the two planes' normals (parallelism of the surfaces).
    pub planes_angle_deg: f64,
}

/// The noise of a fit's nodes: σ measured where the region allows (from
/// the inspection's `known` variograms where it measured this region),
/// else its residual RMS; the correlation factor pooled over the
/// inspection's plane regions where known, else the region's own (1,
/// independent nodes, where it is too small).
pub(crate) fn fit_noise(
    map: &HeightMap,
    regions: &[NamedRegion],
    fit: &PlaneFit,
    known: Option<&PlaneNoises>,
) -> (NodeNoise, bool) {
    let own = match known.and_then(|k| k.variogram(&label(regions))) {
        Some(v) => Some(v.node_noise()),
        None => node_noise(map, regions, &fit.plane),
    };
    let (own, measured) = match own {
        Some(n) => (n, true),
        None => (NodeNoise { sigma_um: fit.rms_um / fit.plane.cos_tilt(), correlation_factor: 1.0 }, false),
    };
    let pooled = known.and_then(|k| k.pooled_factor);
    (NodeNoise { correlation_factor: pooled.unwrap_or(own.correlation_factor), ..own }, measured)
}

/// Step height of `measured` over `reference` (module docs), each plane's
/// noise correlated as its own region measures.
pub fn step_height(
    map: &HeightMap,
    reference: &[NamedRegion],
    measured: &[NamedRegion],
) -> Result<StepHeight, AnalysisError> {
    step_height_pooled(map, reference, measured, None)
}

/// [`step_height`] with the noise an inspection measured on its plane
/// regions: their variograms, and the correlation factor they give together.
pub fn step_height_pooled(
    map: &HeightMap,
    reference: &[NamedRegion],
    measured: &[NamedRegion],
    known: Option<&PlaneNoises>,
) -> Result<StepHeight, AnalysisError> {
    let ref_fit = fit_plane(map, reference)?;
    let meas_fit = fit_plane(map, measured)?;
    let [cx, cy, cz] = meas_fit.centroid_mm;
    let height_um = ref_fit.plane.normal_distance_mm([cx, cy, cz]) * 1e3;

    // GUM propagation through both least-squares planes: the reference
    // plane's height at (cx, cy) and the measured plane's at its centroid.
    let reference_noise = fit_noise(map, reference, &ref_fit, known);
    let measured_noise = fit_noise(map, measured, &meas_fit, known);
    let (ref_noise, meas_noise) = (reference_noise.0, measured_noise.0);
    let cos = ref_fit.plane.cos_tilt();
    let ref_points = region_samples(map, reference).points_mm;
    // Each node's own noise: the reference plane's height away from its
    // centroid weighs its nodes unevenly ([`relative_node_variance`]).
    let ref_weights = relative_node_variance(map, reference, &ref_fit.plane, ref_noise.correlation_factor);
    let u_reference_um =
        plane_covariance(&ref_points, ref_noise.sigma_um, ref_noise.correlation_factor, ref_weights.as_deref())
            .map_or(f64::NAN, |c| c.var_height_at(cx, cy).sqrt() * cos);
    let u_measured_um = centroid_height_u(meas_noise, meas_fit.samples) * cos;
    let planes_angle_deg = ref_fit.plane.angle_to_deg(&meas_fit.plane);
    Ok(StepHeight {
        height_um,
        uncertainty_um: u_reference_um.hypot(u_measured_um),
        u_reference_um,
        u_measured_um,
        reference_noise,
        measured_noise,
        at_mm: [cx, cy],
        reference: ref_fit,
        measured: meas_fit,
        planes_angle_deg,
    })
}

/// u of a plane's height at its own centroid: `σ sqrt(F / N)`.
fn centroid_height_u(noise: NodeNoise, samples: usize) -> f64 {
    noise.sigma_um * (noise.correlation_factor / samples as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::height_map::{RasterParams, height_map_from_cloud};
    use crate::analysis::region::Region;
    use crate::analysis::testing::{GridSpec, grid_cloud};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    const STEP_UM: f64 = 20.0;

    /// Pixels on whole multiples of the map pitch, so nodes are points and
    /// the noise reaches the map unsmoothed.
    fn spec() -> GridSpec {
        GridSpec {
            width: 160,
            height: 100,
            pitch_mm: 0.0117,
            angle_deg: 0.0,
            origin_mm: [427.0 * 0.0117, 256.0 * 0.0117],
        }
    }

    /// A step gauge tilted by 1 deg: land for x >= 5.9 mm, STEP_UM above
    /// the base measured perpendicular to the (parallel) surfaces.
    fn gauge(x: f64, y: f64) -> f64 {
        let t = 1f64.to_radians();
        let base = t.tan() * (0.8 * (x - 5.0) - 0.6 * (y - 3.0)) + 0.4;
        // Perpendicular STEP_UM between planes of slope tan t is STEP_UM / cos t vertically.
        let vertical = STEP_UM * 1e-3 / t.cos();
        if x >= 5.9 { base + vertical } else { base }
    }

    fn regions() -> (NamedRegion, NamedRegion) {
        (
            NamedRegion::new("base", Region::Rectangle { x_mm: [5.1, 5.8], y_mm: [3.1, 4.1] }),
            NamedRegion::new("land", Region::Rectangle { x_mm: [6.0, 6.8], y_mm: [3.1, 4.1] }),
        )
    }

    fn map_of(cloud: &crate::engine::point_cloud::PointCloud) -> HeightMap {
        height_map_from_cloud(cloud, &RasterParams { pitch_mm: Some(0.0117), ..Default::default() }).unwrap().map
    }

    #[test]
    fn noise_free_step_is_recovered_exactly() {
        let map = map_of(&grid_cloud(&spec(), |x, y| Some(gauge(x, y))));
        let (base, land) = regions();
        let s = step_height(&map, &[base], &[land]).unwrap();
        assert!((s.height_um - STEP_UM).abs() < 1e-3, "step {} um", s.height_um);
        assert!(s.planes_angle_deg < 1e-5);
        assert!(s.reference.rms_um < 1e-3 && s.measured.rms_um < 1e-3);
        assert!(s.at_mm[0] > 6.0 && s.at_mm[0] < 6.8);
        // Reversed roles give the negative step.
        let (base, land) = regions();
        let r = step_height(&map, &[land], &[base]).unwrap();
        assert!((r.height_um + STEP_UM).abs() < 1e-3);
    }

    #[test]
    fn noisy_step_agrees_within_its_uncertainty() {
        let sigma_mm = 1e-3;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, sigma_mm).unwrap();
        let mut cloud = grid_cloud(&spec(), |x, y| Some(gauge(x, y)));
        for (p, s) in cloud.xyz.iter_mut().zip(cloud.sigma_z.iter_mut()) {
            p[2] += noise.sample(&mut rng);
            *s = sigma_mm as f32;
        }
        let map = map_of(&cloud);
        let (base, land) = regions();
        let s = step_height(&map, &[base], &[land]).unwrap();
        // Residual RMS is the noise (nodes coincide with points here).
        assert!((s.reference.rms_um - 1.0).abs() < 0.05, "{}", s.reference.rms_um);
        assert!((s.measured.rms_um - 1.0).abs() < 0.05, "{}", s.measured.rms_um);
        // ~5000 samples per region: u ~ 1 um * sqrt(2/5000) plus leverage.
        let n = (s.reference.samples as f64).min(s.measured.samples as f64);
        assert!(s.uncertainty_um > (2.0 / n).sqrt() * 0.9 && s.uncertainty_um < 0.2, "u {}", s.uncertainty_um);
        assert!((s.height_um - STEP_UM).abs() < 4.0 * s.uncertainty_um, "{} +- {}", s.height_um, s.uncertainty_um);
        assert!((s.height_um - STEP_UM).abs() < 0.5);
    }
}
