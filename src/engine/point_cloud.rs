//! The organized point cloud: at most one point per left-camera pixel, each
//! keeping the pixel it was measured at and the quality figures behind it.

use std::mem::MaybeUninit;

use rayon::prelude::*;

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

    /// Appends `counts.iter().sum()` points, written in parallel straight into
    /// the fields' storage, never filled first (a full-size cloud is 145 MB):
    /// `write_row(r, row)` must push exactly `counts[r]` points, in order,
    /// and the rows land one after the other.
    ///
    /// # Panics
    /// When a row pushes fewer points than its count (more panic at the push).
    pub fn append_rows_in_parallel<F>(&mut self, counts: &[usize], write_row: F)
    where
        F: Fn(usize, &mut CloudRowWriter<'_>) + Sync,
    {
        let total: usize = counts.iter().sum();
        // The fields are public, so their lengths are checked rather than
        // trusted; each field's length is also set from its own below, so
        // even a cloud that slipped past this check could not reach memory
        // beyond a field's capacity.
        assert!(self.fields_have_one_length(), "append_rows_in_parallel: the cloud's fields differ in length");
        self.reserve(total);
        {
            let rows: Vec<CloudRowWriter<'_>> =
                split_rows(&mut self.xyz.spare_capacity_mut()[..total], counts)
                    .into_iter()
                    .zip(split_rows(&mut self.pixel_uv.spare_capacity_mut()[..total], counts))
                    .zip(split_rows(&mut self.source_set.spare_capacity_mut()[..total], counts))
                    .zip(split_rows(&mut self.source_period_px.spare_capacity_mut()[..total], counts))
                    .zip(split_rows(&mut self.modulation_dn.spare_capacity_mut()[..total], counts))
                    .zip(split_rows(&mut self.sigma_z.spare_capacity_mut()[..total], counts))
                    .zip(split_rows(&mut self.intensity_dn.spare_capacity_mut()[..total], counts))
                    .zip(split_rows(&mut self.order_evidence.spare_capacity_mut()[..total], counts))
                    .map(|(((((((xyz, uv), source), period), modulation), sigma_z), intensity), evidence)| {
                        CloudRowWriter { written: 0, xyz, uv, source, period, modulation, sigma_z, intensity, evidence }
                    })
                    .collect();
            rows.into_par_iter().enumerate().for_each(|(r, mut row)| {
                write_row(r, &mut row);
                // The lengths are set below as if every element of the row's
                // slices was written.
                assert_eq!(row.written, row.xyz.len(), "row {r}: fewer points written than counted");
            });
        }
        // SAFETY: for each field, the rows' slices are consecutive and
        // together the first `total` elements of that field's spare capacity
        // (`split_rows` of `counts`, which sum to `total`, after `reserve`
        // gave each field room for `total` more), and every row wrote all of
        // its slices' elements (asserted above; a failed assertion panics
        // before this point). Each length grows from the field's own.
        unsafe {
            grow_len(&mut self.xyz, total);
            grow_len(&mut self.pixel_uv, total);
            grow_len(&mut self.source_set, total);
            grow_len(&mut self.source_period_px, total);
            grow_len(&mut self.modulation_dn, total);
            grow_len(&mut self.sigma_z, total);
            grow_len(&mut self.intensity_dn, total);
            grow_len(&mut self.order_evidence, total);
        }
    }

    /// Whether every per-point field has as many entries as `xyz`.
    pub fn fields_have_one_length(&self) -> bool {
        let n = self.xyz.len();
        [
            self.pixel_uv.len(),
            self.source_set.len(),
            self.source_period_px.len(),
            self.modulation_dn.len(),
            self.sigma_z.len(),
            self.intensity_dn.len(),
            self.order_evidence.len(),
        ]
        .iter()
        .all(|&len| len == n)
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

/// One point with all its fields, as [`CloudRowWriter::push`] takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudPoint {
    pub xyz: [f64; 3],
    pub pixel_uv: [f32; 2],
    pub source_set: i8,
    pub source_period_px: f32,
    pub modulation_dn: f32,
    pub sigma_z: f32,
    pub intensity_dn: f32,
    pub order_evidence: u8,
}

/// One row's share of every field's storage in
/// [`PointCloud::append_rows_in_parallel`], not yet written.
pub struct CloudRowWriter<'a> {
    written: usize,
    xyz: &'a mut [MaybeUninit<[f64; 3]>],
    uv: &'a mut [MaybeUninit<[f32; 2]>],
    source: &'a mut [MaybeUninit<i8>],
    period: &'a mut [MaybeUninit<f32>],
    modulation: &'a mut [MaybeUninit<f32>],
    sigma_z: &'a mut [MaybeUninit<f32>],
    intensity: &'a mut [MaybeUninit<f32>],
    evidence: &'a mut [MaybeUninit<u8>],
}

impl CloudRowWriter<'_> {
    /// Writes the row's next point.
    ///
    /// # Panics
    /// When the row already holds as many points as it was counted.
    #[inline]
    pub fn push(&mut self, p: CloudPoint) {
        let k = self.written;
        self.xyz[k].write(p.xyz);
        self.uv[k].write(p.pixel_uv);
        self.source[k].write(p.source_set);
        self.period[k].write(p.source_period_px);
        self.modulation[k].write(p.modulation_dn);
        self.sigma_z[k].write(p.sigma_z);
        self.intensity[k].write(p.intensity_dn);
        self.evidence[k].write(p.order_evidence);
        self.written = k + 1;
    }
}

/// Extends `v`'s length by `additional` elements.
///
/// # Safety
/// The `additional` elements after `v.len()` must lie within its capacity
/// and have been initialised.
unsafe fn grow_len<T>(v: &mut Vec<T>, additional: usize) {
    debug_assert!(v.len() + additional <= v.capacity());
    // SAFETY: the caller's promise.
    unsafe { v.set_len(v.len() + additional) };
}

/// Splits `v` into consecutive slices of the given lengths.
fn split_rows<'a, T>(mut v: &'a mut [T], counts: &[usize]) -> Vec<&'a mut [T]> {
    counts
        .iter()
        .map(|&n| {
            let (head, tail) = std::mem::take(&mut v).split_at_mut(n);
            v = tail;
            head
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(i: usize) -> CloudPoint {
        let f = i as f32;
        CloudPoint {
            xyz: [i as f64, -(i as f64), 0.5 * i as f64],
            pixel_uv: [f, f + 0.5],
            source_set: (i % 4) as i8,
            source_period_px: 12.0 * f,
            modulation_dn: f + 1.0,
            sigma_z: 0.001 * f,
            intensity_dn: f + 2.0,
            order_evidence: (i % 3) as u8,
        }
    }

    fn fields(cloud: &PointCloud, k: usize) -> CloudPoint {
        CloudPoint {
            xyz: cloud.xyz[k],
            pixel_uv: cloud.pixel_uv[k],
            source_set: cloud.source_set[k],
            source_period_px: cloud.source_period_px[k],
            modulation_dn: cloud.modulation_dn[k],
            sigma_z: cloud.sigma_z[k],
            intensity_dn: cloud.intensity_dn[k],
            order_evidence: cloud.order_evidence[k],
        }
    }

    #[test]
    fn rows_written_in_parallel_land_after_the_cloud_in_row_order() {
        let mut cloud = PointCloud::default();
        cloud.append_rows_in_parallel(&[2], |_, row| (0..2).for_each(|i| row.push(point(i))));
        // Rows of every size, empty ones included; row r holds points
        // first[r]..first[r] + counts[r] of the sequence.
        let counts = [3, 0, 1, 700, 0, 5];
        let first: Vec<usize> = counts.iter().scan(2, |next, &n| Some(std::mem::replace(next, *next + n))).collect();
        cloud.append_rows_in_parallel(&counts, |r, row| {
            (first[r]..first[r] + counts[r]).for_each(|i| row.push(point(i)))
        });
        assert_eq!(cloud.len(), 2 + counts.iter().sum::<usize>());
        for k in 0..cloud.len() {
            assert_eq!(fields(&cloud, k), point(k), "point {k}");
        }
    }

    #[test]
    #[should_panic(expected = "fewer points written than counted")]
    fn a_row_that_writes_fewer_points_than_counted_panics() {
        PointCloud::default().append_rows_in_parallel(&[2, 3], |r, row| {
            row.push(point(r));
        });
    }

    /// A cloud whose public fields were given different lengths is refused
    /// before anything is written past a field's end (the old code set every
    /// field's length from `xyz`'s, reaching past `sigma_z`'s capacity here).
    #[test]
    #[should_panic(expected = "the cloud's fields differ in length")]
    fn a_cloud_whose_fields_differ_in_length_is_refused() {
        let mut cloud = PointCloud::default();
        cloud.append_rows_in_parallel(&[2], |_, row| (0..2).for_each(|i| row.push(point(i))));
        cloud.sigma_z.clear();
        cloud.sigma_z.shrink_to_fit();
        cloud.append_rows_in_parallel(&[1], |_, row| row.push(point(9)));
    }
}
