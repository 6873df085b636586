//! The organized point cloud: at most one point per left-camera pixel, each
//! keeping the pixel it was measured at and the quality figures behind it.

use super::length_unit::LengthUnit;

/// Structure of arrays; all vectors have one entry per point.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Length unit of `xyz` and `sigma_z` (the calibration's, normally mm).
    pub unit: LengthUnit,
    pub xyz: Vec<[f64; 3]>,
    /// Observed left-camera pixel `(u, v)` the point was measured at.
    pub pixel_uv: Vec<[f32; 2]>,
    /// Manifest index of the fringe set whose phase located the point.
    pub source_set: Vec<i8>,
    /// Period (projector pixels) of that set.
    pub source_period_px: Vec<f32>,
    /// Fringe modulation `B` of that set at the left pixel (grey levels).
    pub modulation_dn: Vec<f32>,
    /// Standard deviation of the height propagated from the phase noise, in `unit`.
    pub sigma_z: Vec<f32>,
    /// Mean fringe intensity `A` at the left pixel (grey levels): the texture.
    pub intensity_dn: Vec<f32>,
    /// How the left pixel's fringe orders were decided
    /// (`engine::unwrap::EVIDENCE_*`: 0 own samples, 1 neighbours, 2 patch).
    pub order_evidence: Vec<u8>,
    /// Size of the left image the points are organized on.
    pub grid_width: usize,
    pub grid_height: usize,
}

impl PointCloud {
    pub fn len(&self) -> usize {
        self.xyz.len()
    }

    pub fn is_empty(&self) -> bool {
        self.xyz.is_empty()
    }

    /// Axis-aligned bounds `(min, max)`, or `None` for an empty cloud.
    pub fn bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let first = *self.xyz.first()?;
        Some(self.xyz.iter().fold((first, first), |(lo, hi), p| {
            (std::array::from_fn(|i| lo[i].min(p[i])), std::array::from_fn(|i| hi[i].max(p[i])))
        }))
    }

    /// Micrometres per unit of this cloud.
    pub fn um_per_unit(&self) -> f64 {
        self.unit.um_per_unit()
    }

    /// Reserves room for `additional` more points in every field.
    pub fn reserve(&mut self, additional: usize) {
        self.xyz.reserve(additional);
        self.pixel_uv.reserve(additional);
        self.source_set.reserve(additional);
        self.source_period_px.reserve(additional);
        self.modulation_dn.reserve(additional);
        self.sigma_z.reserve(additional);
        self.intensity_dn.reserve(additional);
        self.order_evidence.reserve(additional);
    }

    /// Appends the points of `other` (same unit and grid).
    pub fn append(&mut self, other: &PointCloud) {
        self.xyz.extend_from_slice(&other.xyz);
        self.pixel_uv.extend_from_slice(&other.pixel_uv);
        self.source_set.extend_from_slice(&other.source_set);
        self.source_period_px.extend_from_slice(&other.source_period_px);
        self.modulation_dn.extend_from_slice(&other.modulation_dn);
        self.sigma_z.extend_from_slice(&other.sigma_z);
        self.intensity_dn.extend_from_slice(&other.intensity_dn);
        self.order_evidence.extend_from_slice(&other.order_evidence);
    }

    /// Keeps only the points for which `keep` is true.
    pub fn retain_by_index(&mut self, keep: &[bool]) {
        fn filter<T: Copy>(v: &mut Vec<T>, keep: &[bool]) {
            let mut i = 0;
            v.retain(|_| {
                let k = keep[i];
                i += 1;
                k
            });
        }
        filter(&mut self.xyz, keep);
        filter(&mut self.pixel_uv, keep);
        filter(&mut self.source_set, keep);
        filter(&mut self.source_period_px, keep);
        filter(&mut self.modulation_dn, keep);
        filter(&mut self.sigma_z, keep);
        filter(&mut self.intensity_dn, keep);
        filter(&mut self.order_evidence, keep);
    }
}
