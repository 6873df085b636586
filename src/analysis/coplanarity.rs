//! Coplanarity of several lands (the mounting faces of a watch plate, the
//! paper's Fig. 6): each land gets its own least-squares plane, and one common
//! least-squares plane is fitted through the samples of all lands. A land's
//! deviation is its plane minus the common plane, along the common normal,
//! evaluated at the land's valid samples; the coplanarity is the largest
//! signed deviation of any land minus the smallest.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::height_map::HeightMap;
use super::plane_fit::{PlaneFit, fit_plane};
use super::region::{NamedRegion, region_samples};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LandDeviation {
    /// The land's own plane (`fit.region` is the land's name).
    pub fit: PlaneFit,
    /// Smallest and largest signed deviation from the common plane over the land.
    pub min_deviation_um: f64,
    pub max_deviation_um: f64,
    /// Deviation at the land's centroid: how high the land sits.
    pub mean_deviation_um: f64,
}

impl LandDeviation {
    /// Largest |deviation| over the land.
    pub fn max_abs_deviation_um(&self) -> f64 {
        self.min_deviation_um.abs().max(self.max_deviation_um.abs())
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coplanarity {
    /// Plane through the samples of all lands.
    pub common: PlaneFit,
    pub lands: Vec<LandDeviation>,
    /// Largest minus smallest signed deviation over all lands.
    pub coplanarity_um: f64,
}

/// Coplanarity of at least two lands (module docs).
pub fn coplanarity(map: &HeightMap, lands: &[NamedRegion]) -> Result<Coplanarity, AnalysisError> {
    if lands.len() < 2 {
        return Err(AnalysisError::TooFewLands { found: lands.len() });
    }
    let common = fit_plane(map, lands)?;
    let cos = common.plane.cos_tilt();
    let mut out = Vec::with_capacity(lands.len());
    for land in lands {
        let fit = fit_plane(map, std::slice::from_ref(land))?;
        let deviation_um = |x: f64, y: f64| (fit.plane.z_at(x, y) - common.plane.z_at(x, y)) * cos * 1e3;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in region_samples(map, std::slice::from_ref(land)).points_mm {
            let d = deviation_um(p[0], p[1]);
            lo = lo.min(d);
            hi = hi.max(d);
        }
        let mean_deviation_um = deviation_um(fit.centroid_mm[0], fit.centroid_mm[1]);
        out.push(LandDeviation { fit, min_deviation_um: lo, max_deviation_um: hi, mean_deviation_um });
    }
    let lo = out.iter().map(|l| l.min_deviation_um).fold(f64::INFINITY, f64::min);
    let hi = out.iter().map(|l| l.max_deviation_um).fold(f64::NEG_INFINITY, f64::max);
    Ok(Coplanarity { common, lands: out, coplanarity_um: hi - lo })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::region::Region;
    use crate::analysis::testing::node_map;

    const PITCH: f64 = 0.01;
    const HALF: usize = 100;

    /// Four square lands centred at (+-0.5, +-0.5) mm; bounds half-way
    /// between nodes so mirrored lands hold mirrored nodes.
    fn lands() -> Vec<NamedRegion> {
        let square =
            |cx: f64, cy: f64| Region::Rectangle { x_mm: [cx - 0.155, cx + 0.155], y_mm: [cy - 0.155, cy + 0.155] };
        vec![
            NamedRegion::new("ne", square(0.5, 0.5)),
            NamedRegion::new("sw", square(-0.5, -0.5)),
            NamedRegion::new("se", square(0.5, -0.5)),
            NamedRegion::new("nw", square(-0.5, 0.5)),
        ]
    }

    fn tilted_base(x: f64, y: f64) -> f64 {
        0.3 + 0.012 * x - 0.007 * y
    }

    fn map_with(land_z: impl Fn(usize, f64, f64) -> f64) -> HeightMap {
        let lands = lands();
        let origin = -(HALF as f64) * PITCH;
        node_map(2 * HALF + 1, 2 * HALF + 1, [origin, origin], PITCH, |x, y| {
            // Between lands: recessed, not measured.
            lands.iter().position(|l| l.contains(x, y)).map(|k| land_z(k, x, y))
        })
    }

    #[test]
    fn rocking_lands_with_known_offsets() {
        // Saddle pattern +a, +a, -a, -a (ne, sw, se, nw): the common plane is the
        // base, each land deviates by its offset, coplanarity is 2a.
        let a_um = 3.0;
        let cos = 1.0 / (1.0f64 + 0.012 * 0.012 + 0.007 * 0.007).sqrt();
        let sign = [1.0, 1.0, -1.0, -1.0];
        let map = map_with(|k, x, y| tilted_base(x, y) + sign[k] * a_um * 1e-3 / cos);
        let c = coplanarity(&map, &lands()).unwrap();
        assert!((c.coplanarity_um - 2.0 * a_um).abs() < 1e-3, "{}", c.coplanarity_um);
        for (land, s) in c.lands.iter().zip(sign) {
            assert!(
                (land.mean_deviation_um - s * a_um).abs() < 1e-3,
                "{}: {}",
                land.fit.region,
                land.mean_deviation_um
            );
            assert!((land.max_deviation_um - land.min_deviation_um).abs() < 1e-3, "lands are parallel");
        }
        assert!((c.common.plane.slope_x - 0.012).abs() < 1e-6 && (c.common.plane.slope_y + 0.007).abs() < 1e-6);
    }

    /// Naive reference: every plane by nalgebra's SVD least squares, deviations
    /// at every sample, straight from the definition.
    fn naive(map: &HeightMap, lands: &[NamedRegion]) -> (f64, Vec<(f64, f64)>) {
        let pts = |regions: &[NamedRegion]| region_samples(map, regions).points_mm;
        let lsq = |p: &[[f64; 3]]| {
            let a = nalgebra::DMatrix::from_fn(p.len(), 3, |i, j| if j < 2 { p[i][j] } else { 1.0 });
            let b = nalgebra::DVector::from_fn(p.len(), |i, _| p[i][2]);
            let s = a.svd(true, true).solve(&b, 1e-14).unwrap();
            [s[0], s[1], s[2]]
        };
        let c = lsq(&pts(lands));
        let cos = 1.0 / (1.0 + c[0] * c[0] + c[1] * c[1]).sqrt();
        let mut per = Vec::new();
        for land in lands {
            let p = pts(std::slice::from_ref(land));
            let l = lsq(&p);
            let d: Vec<f64> =
                p.iter().map(|q| ((l[0] - c[0]) * q[0] + (l[1] - c[1]) * q[1] + (l[2] - c[2])) * cos * 1e3).collect();
            per.push((
                d.iter().copied().fold(f64::INFINITY, f64::min),
                d.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ));
        }
        let lo = per.iter().map(|d| d.0).fold(f64::INFINITY, f64::min);
        let hi = per.iter().map(|d| d.1).fold(f64::NEG_INFINITY, f64::max);
        (hi - lo, per)
    }

    #[test]
    fn tilted_and_offset_lands_match_the_definition() {
        // Each land with its own offset and tilt (a few um over the land).
        let offs = [2.0e-3, -1.0e-3, 4.0e-3, 0.5e-3];
        let tilts = [[0.004, 0.0], [0.0, -0.006], [0.003, 0.003], [-0.002, 0.001]];
        let centres = [[0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5]];
        let map = map_with(|k, x, y| {
            tilted_base(x, y) + offs[k] + tilts[k][0] * (x - centres[k][0]) + tilts[k][1] * (y - centres[k][1])
        });
        let c = coplanarity(&map, &lands()).unwrap();
        let (expected, per) = naive(&map, &lands());
        assert!((c.coplanarity_um - expected).abs() < 1e-6, "{} vs {expected}", c.coplanarity_um);
        for (land, (lo, hi)) in c.lands.iter().zip(per) {
            assert!((land.min_deviation_um - lo).abs() < 1e-6 && (land.max_deviation_um - hi).abs() < 1e-6);
        }
        // The tilts show: a land's deviation spans tilt x land width.
        assert!(c.lands[1].max_deviation_um - c.lands[1].min_deviation_um > 1.5);
    }

    #[test]
    fn one_land_is_not_a_coplanarity() {
        let map = map_with(|_, x, y| tilted_base(x, y));
        let e = coplanarity(&map, &lands()[..1]).unwrap_err();
        assert!(matches!(e, AnalysisError::TooFewLands { found: 1 }));
    }
}
