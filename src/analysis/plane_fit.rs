//! Least-squares planes over regions of the height map, flatness, and
//! levelling to a reference plane.
//!
//! The plane `z = a x + b y + c` minimises the sum of squared vertical
//! residuals. Coordinates are centred on the samples' mean before the normal
//! equations are formed, so the 2x2 system for the slopes is well conditioned
//! however far the part sits from the rig's origin:
//! `[Sxx Sxy; Sxy Syy] (a, b)^T = (Sxz, Syz)^T`, `c = z̄ - a x̄ - b ȳ`, with
//! `Suv = Σ (u - ū)(v - v̄)`. Residuals and flatness are reported along the
//! plane normal (vertical residual times `cos θ`, `θ` the plane's tilt), in
//! micrometres.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::height_map::HeightMap;
use super::region::{NamedRegion, region_samples};

/// `z = slope_x x + slope_y y + z0_mm`, lengths in mm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plane {
    pub slope_x: f64,
    pub slope_y: f64,
    pub z0_mm: f64,
}

impl Plane {
    #[inline]
    pub fn z_at(&self, x_mm: f64, y_mm: f64) -> f64 {
        self.slope_x * x_mm + self.slope_y * y_mm + self.z0_mm
    }

    /// Cosine of the angle between the plane normal and Z.
    pub fn cos_tilt(&self) -> f64 {
        1.0 / (1.0 + self.slope_x * self.slope_x + self.slope_y * self.slope_y).sqrt()
    }

    /// Angle between the plane and the X-Y plane.
    pub fn tilt_deg(&self) -> f64 {
        self.cos_tilt().clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Unit normal pointing to +Z: `(-a, -b, 1) cos θ`.
    pub fn unit_normal(&self) -> [f64; 3] {
        let c = self.cos_tilt();
        [-self.slope_x * c, -self.slope_y * c, c]
    }

    /// Signed distance of a point from the plane along its normal (positive
    /// above, towards +Z), in mm.
    #[inline]
    pub fn normal_distance_mm(&self, p: [f64; 3]) -> f64 {
        (p[2] - self.z_at(p[0], p[1])) * self.cos_tilt()
    }

    /// Angle between the normals of two planes.
    pub fn angle_to_deg(&self, other: &Plane) -> f64 {
        let (n, m) = (self.unit_normal(), other.unit_normal());
        let d = n[0] * m[0] + n[1] * m[1] + n[2] * m[2];
        d.clamp(-1.0, 1.0).acos().to_degrees()
    }
}

/// A plane fitted to the valid samples of one or more regions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlaneFit {
    /// Names of the regions fitted (joined with '+').
    pub region: String,
    pub plane: Plane,
    /// Mean X, Y, Z of the samples (a point of the plane, where it is best known).
    pub centroid_mm: [f64; 3],
    /// Valid samples used.
    pub samples: usize,
    /// Nodes inside the regions, holes included.
    pub nodes_inside: usize,
    /// Residual RMS along the normal: the RMS flatness deviation.
    pub rms_um: f64,
    pub min_residual_um: f64,
    pub max_residual_um: f64,
}

impl PlaneFit {
    /// Flatness deviation: highest minus lowest residual (peak to valley).
    pub fn peak_to_valley_um(&self) -> f64 {
        self.max_residual_um - self.min_residual_um
    }
}

/// Least-squares plane through points; `None` for fewer than 3 points or
/// points on one line. Returns the plane and the points' centroid.
pub fn fit_plane_points(points: &[[f64; 3]]) -> Option<(Plane, [f64; 3])> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let mut mean = [0.0; 3];
    for p in points {
        for k in 0..3 {
            mean[k] += p[k];
        }
    }
    mean = mean.map(|m| m / n);
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let (x, y, z) = (p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        sxz += x * z;
        syz += y * z;
    }
    let det = sxx * syy - sxy * sxy;
    // Collinear (or coincident) X-Y positions leave the slopes undetermined.
    // The X-Y scatter matrix must have a smallest eigenvalue clear of the
    // rounding of the centring itself (a row of nodes at y = 0.1 mm centres
    // to ~1e-17, not 0): per sample above (1e-9 x the coordinate scale)^2,
    // and above 1e-12 of the largest eigenvalue.
    let trace = sxx + syy;
    let lambda_max = trace / 2.0 + ((sxx - syy).powi(2) / 4.0 + sxy * sxy).sqrt();
    let lambda_min = if lambda_max > 0.0 { det / lambda_max } else { 0.0 };
    let scale = mean[0].abs().max(mean[1].abs()).max((trace / n).sqrt());
    if !(lambda_min > 1e-12 * lambda_max && lambda_min / n > (1e-9 * scale).powi(2)) {
        return None;
    }
    let a = (sxz * syy - syz * sxy) / det;
    let b = (syz * sxx - sxz * sxy) / det;
    let plane = Plane { slope_x: a, slope_y: b, z0_mm: mean[2] - a * mean[0] - b * mean[1] };
    Some((plane, mean))
}

/// Plane fitted to the valid samples of the union of `regions`, with its
/// residual statistics.
pub fn fit_plane(map: &HeightMap, regions: &[NamedRegion]) -> Result<PlaneFit, AnalysisError> {
    for r in regions {
        r.validate()?;
    }
    let samples = region_samples(map, regions);
    fit_samples(&samples.label, &samples.points_mm, samples.nodes_inside)
}

pub(crate) fn fit_samples(label: &str, points: &[[f64; 3]], nodes_inside: usize) -> Result<PlaneFit, AnalysisError> {
    if points.len() < 3 {
        return Err(AnalysisError::TooFewSamples { region: label.to_string(), found: points.len(), needed: 3 });
    }
    let (plane, centroid_mm) = fit_plane_points(points)
        .ok_or_else(|| AnalysisError::CollinearSamples { region: label.to_string(), samples: points.len() })?;
    let cos = plane.cos_tilt();
    let (mut sum2, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
    for p in points {
        // Centred form of z - plane(x, y), exact to the last bit for the data's scale.
        let r = ((p[2] - centroid_mm[2])
            - plane.slope_x * (p[0] - centroid_mm[0])
            - plane.slope_y * (p[1] - centroid_mm[1]))
            * cos;
        sum2 += r * r;
        lo = lo.min(r);
        hi = hi.max(r);
    }
    Ok(PlaneFit {
        region: label.to_string(),
        plane,
        centroid_mm,
        samples: points.len(),
        nodes_inside,
        rms_um: (sum2 / points.len() as f64).sqrt() * 1e3,
        min_residual_um: lo * 1e3,
        max_residual_um: hi * 1e3,
    })
}

/// Flatness of a region: its least-squares plane with the peak-to-valley and
/// RMS of the residual ([`PlaneFit::peak_to_valley_um`], [`PlaneFit::rms_um`]).
pub fn flatness(map: &HeightMap, region: &NamedRegion) -> Result<PlaneFit, AnalysisError> {
    fit_plane(map, std::slice::from_ref(region))
}

/// Height of every valid node above `plane`, measured along the plane's
/// normal: `(z - a x - b y - c) cos θ`. Nodes keep their X-Y; the foot of the
/// normal lies `h sin θ` away from it (0.35 um for 20 um at 1 deg, far below
/// a pitch), while the heights are exact, unlike a vertical subtraction that
/// stretches them by `1 / cos θ`.
pub fn height_above_plane(map: &HeightMap, plane: &Plane) -> HeightMap {
    let mut out = map.clone();
    let cos = plane.cos_tilt();
    for row in 0..map.height {
        let y = map.y_mm(row);
        for col in 0..map.width {
            let cell = &mut out.z[row * map.width + col];
            if !cell.is_nan() {
                *cell = ((f64::from(*cell) - plane.z_at(map.x_mm(col), y)) * cos) as f32;
            }
        }
    }
    out
}

/// A map levelled to a reference plane.
#[derive(Clone, Debug, PartialEq)]
pub struct Levelled {
    pub map: HeightMap,
    /// The plane fitted to the reference regions (in the original map's frame).
    pub reference: PlaneFit,
}

/// Fits a reference plane to the union of `reference` regions and returns
/// the map as heights above it ([`height_above_plane`]): the reference lies
/// at Z = 0 and a land parallel to it at its true distance.
pub fn level(map: &HeightMap, reference: &[NamedRegion]) -> Result<Levelled, AnalysisError> {
    let fit = fit_plane(map, reference)?;
    Ok(Levelled { map: height_above_plane(map, &fit.plane), reference: fit })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::region::Region;
    use crate::analysis::testing::{GridSpec, surface_map};
    use proptest::prelude::*;

    fn spec() -> GridSpec {
        GridSpec { width: 120, height: 90, pitch_mm: 0.0117, angle_deg: 0.0, origin_mm: [2.0, -1.0] }
    }

    fn everything() -> NamedRegion {
        NamedRegion::new("all", Region::Rectangle { x_mm: [-100.0, 100.0], y_mm: [-100.0, 100.0] })
    }

    #[test]
    fn one_degree_tilted_plane_levels_to_nanometres() {
        let t = 1f64.to_radians().tan();
        let map = surface_map(&spec(), |x, y| Some(t * (0.6 * x + 0.8 * y) + 0.25));
        let levelled = level(&map, &[everything()]).unwrap();
        assert!(levelled.map.z_range_mm().unwrap().1.abs() < 1e-7);
        assert!((levelled.reference.plane.tilt_deg() - 1.0).abs() < 1e-6);
        let flat = flatness(&levelled.map, &everything()).unwrap();
        // f32 storage of heights of a few tenths of a millimetre: ~1e-5 um.
        assert!(flat.rms_um < 1e-4, "rms {} um", flat.rms_um);
        assert!(flat.peak_to_valley_um() < 1e-3, "pv {} um", flat.peak_to_valley_um());
        assert!(flat.plane.tilt_deg() < 1e-6);
        assert_eq!(flat.samples, levelled.map.valid_count());
    }

    #[test]
    fn flatness_of_a_known_waviness() {
        // z = A cos(2 pi x / L) over one period, even about its middle so no
        // tilt absorbs it: RMS A/sqrt2, PV 2A.
        let amp_mm = 0.002;
        let period = 0.117 * 2.0;
        let s = GridSpec { width: 201, height: 20, pitch_mm: 0.00117, angle_deg: 0.0, origin_mm: [0.0, 0.0] };
        let map = surface_map(&s, |x, _| Some(amp_mm * (2.0 * std::f64::consts::PI * x / period).cos()));
        let fit = flatness(&map, &everything()).unwrap();
        assert!((fit.rms_um - 2.0 / 2f64.sqrt()).abs() < 0.02, "rms {}", fit.rms_um);
        assert!((fit.peak_to_valley_um() - 4.0).abs() < 0.01, "pv {}", fit.peak_to_valley_um());
    }

    #[test]
    fn holes_are_counted_but_never_fitted() {
        // A plane with a hole: the fit uses exactly the valid nodes, and a
        // region wholly inside the hole has nothing to fit.
        let t = 0.01;
        let map = surface_map(&spec(), |x, y| ((x - 2.6).hypot(y + 0.5) > 0.1).then_some(t * x + 0.2));
        let region = NamedRegion::new("around", Region::Circle { centre_mm: [2.6, -0.5], radius_mm: 0.3 });
        let fit = fit_plane(&map, std::slice::from_ref(&region)).unwrap();
        let mask = crate::analysis::region::region_mask(&map, std::slice::from_ref(&region));
        let valid_inside = mask.iter().zip(&map.z).filter(|(m, z)| **m && !z.is_nan()).count();
        assert_eq!(fit.samples, valid_inside);
        assert!(fit.nodes_inside - fit.samples > 200, "{} of {}", fit.samples, fit.nodes_inside);
        assert!((fit.plane.slope_x - t).abs() < 1e-6 && fit.rms_um < 1e-3);
        let inside = NamedRegion::new("inside", Region::Circle { centre_mm: [2.6, -0.5], radius_mm: 0.05 });
        assert!(matches!(flatness(&map, &inside), Err(AnalysisError::TooFewSamples { found: 0, .. })));
    }

    #[test]
    fn degenerate_regions_are_refused_with_reasons() {
        let map = surface_map(&spec(), |_, _| Some(0.0));
        let tiny = NamedRegion::new("tiny", Region::Circle { centre_mm: [2.5, -0.5], radius_mm: 0.001 });
        let e = fit_plane(&map, &[tiny]).unwrap_err();
        assert!(matches!(e, AnalysisError::TooFewSamples { found: 0, needed: 3, .. }), "{e}");
        let y0 = map.y_mm(10);
        let line = NamedRegion::new("line", Region::Rectangle { x_mm: [2.0, 3.0], y_mm: [y0 - 1e-4, y0 + 1e-4] });
        let e = fit_plane(&map, &[line]).unwrap_err();
        assert!(matches!(e, AnalysisError::CollinearSamples { .. }), "{e}");
    }

    /// Naive reference: least squares of `[x y 1] p = z` by nalgebra's SVD.
    fn naive_fit(points: &[[f64; 3]]) -> [f64; 3] {
        let a = nalgebra::DMatrix::from_fn(points.len(), 3, |i, j| if j < 2 { points[i][j] } else { 1.0 });
        let b = nalgebra::DVector::from_fn(points.len(), |i, _| points[i][2]);
        let x = a.svd(true, true).solve(&b, 1e-14).unwrap();
        [x[0], x[1], x[2]]
    }

    fn cloud_strategy() -> impl Strategy<Value = Vec<[f64; 3]>> {
        prop::collection::vec((-5.0..5.0f64, -5.0..5.0f64, -0.1..0.1f64), 8..60)
            .prop_map(|v| v.into_iter().map(|(x, y, z)| [x, y, z]).collect())
    }

    proptest! {
        #[test]
        fn plane_fit_matches_the_naive_solution(points in cloud_strategy()) {
            let Some((plane, _)) = fit_plane_points(&points) else { return Ok(()) };
            let p = naive_fit(&points);
            prop_assert!((plane.slope_x - p[0]).abs() < 1e-9);
            prop_assert!((plane.slope_y - p[1]).abs() < 1e-9);
            prop_assert!((plane.z0_mm - p[2]).abs() < 1e-9);
        }

        #[test]
        fn plane_fit_is_invariant_to_translation(
            points in cloud_strategy(),
            t in (-500.0..500.0f64, -500.0..500.0f64, -50.0..50.0f64),
        ) {
            let moved: Vec<[f64; 3]> = points.iter().map(|p| [p[0] + t.0, p[1] + t.1, p[2] + t.2]).collect();
            let (Ok(f), Ok(g)) = (fit_samples("a", &points, points.len()), fit_samples("b", &moved, moved.len()))
            else { return Ok(()) };
            prop_assert!((f.plane.slope_x - g.plane.slope_x).abs() < 1e-9);
            prop_assert!((f.plane.slope_y - g.plane.slope_y).abs() < 1e-9);
            let z0 = f.plane.z0_mm + t.2 - f.plane.slope_x * t.0 - f.plane.slope_y * t.1;
            prop_assert!((g.plane.z0_mm - z0).abs() < 1e-8);
            prop_assert!((f.rms_um - g.rms_um).abs() < 1e-6);
            prop_assert!((f.peak_to_valley_um() - g.peak_to_valley_um()).abs() < 1e-6);
        }
    }
}
