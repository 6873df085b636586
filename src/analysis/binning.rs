//! Nearest-neighbour binning of an unorganized cloud (a PLY without pixel
//! columns) onto pseudo pixels, so that the height map's triangles can be
//! formed from neighbours as they are for an organized cloud.

use super::error::AnalysisError;
use crate::engine::length_unit::LengthUnit;

/// Pseudo pixel coordinates for an unorganized cloud: X-Y binned on `pitch`
/// (in the cloud's unit; default: the spacing of points spread evenly over
/// their bounding box). Points sharing a bin are left out by the rasterizer
/// (counted as unplaced).
pub fn bin_unorganized(
    xyz: &[[f64; 3]],
    pitch_mm: Option<f64>,
    unit: LengthUnit,
) -> Result<(Vec<[f32; 2]>, f64), AnalysisError> {
    let scale = unit.mm_per_unit();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in xyz.iter().filter(|p| p[0].is_finite() && p[1].is_finite()) {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let pitch = match pitch_mm {
        Some(p) => p / scale,
        None => median_neighbour_distance(xyz, lo, hi),
    };
    if !(pitch.is_finite() && pitch > 0.0) {
        return Err(AnalysisError::NoArea);
    }
    let uv = xyz
        .iter()
        .map(|p| [((p[0] - lo[0]) / pitch).round() as f32, ((p[1] - lo[1]) / pitch).round() as f32])
        .collect();
    Ok((uv, pitch))
}

/// Median X-Y distance from a point to its nearest neighbour (a bucket grid
/// of the mean spacing, searched 3x3), the spacing a scan grid had.
pub fn median_neighbour_distance(xyz: &[[f64; 3]], lo: [f64; 2], hi: [f64; 2]) -> f64 {
    let finite: Vec<[f64; 2]> =
        xyz.iter().filter(|p| p[0].is_finite() && p[1].is_finite()).map(|p| [p[0], p[1]]).collect();
    let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
    let cell = (area / finite.len().max(1) as f64).sqrt() * 2.0;
    if !(cell.is_finite() && cell > 0.0) {
        return f64::NAN;
    }
    let key = |p: [f64; 2]| (((p[0] - lo[0]) / cell) as usize, ((p[1] - lo[1]) / cell) as usize);
    let mut buckets: std::collections::HashMap<(usize, usize), Vec<usize>> = std::collections::HashMap::new();
    for (i, &p) in finite.iter().enumerate() {
        buckets.entry(key(p)).or_default().push(i);
    }
    let mut nearest: Vec<f64> = finite
        .iter()
        .enumerate()
        .filter_map(|(i, &p)| {
            let (c, r) = key(p);
            let mut best = f64::INFINITY;
            for rr in r.saturating_sub(1)..=r + 1 {
                for cc in c.saturating_sub(1)..=c + 1 {
                    for &j in buckets.get(&(cc, rr)).map_or(&[][..], Vec::as_slice) {
                        let d = (finite[j][0] - p[0]).hypot(finite[j][1] - p[1]);
                        if j != i && d > 0.0 {
                            best = best.min(d);
                        }
                    }
                }
            }
            best.is_finite().then_some(best)
        })
        .collect();
    if nearest.is_empty() {
        return f64::NAN;
    }
    let mid = nearest.len() / 2;
    *nearest.select_nth_unstable_by(mid, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shuffled_scan_grid_bins_back_onto_its_grid_at_its_spacing() {
        let (w, h, pitch) = (7usize, 5usize, 0.02);
        let mut xyz: Vec<[f64; 3]> =
            (0..w * h).map(|i| [1.0 + (i % w) as f64 * pitch, -2.0 + (i / w) as f64 * pitch, 0.1]).collect();
        xyz.reverse();
        let (uv, found) = bin_unorganized(&xyz, None, LengthUnit::Mm).unwrap();
        assert!((found - pitch).abs() < 1e-12, "{found}");
        for (p, q) in xyz.iter().zip(&uv) {
            let expect = [((p[0] - 1.0) / pitch).round() as f32, ((p[1] + 2.0) / pitch).round() as f32];
            assert_eq!(*q, expect);
        }
        // A pitch in mm applies in the cloud's unit: 20 um on a cloud in um.
        let um: Vec<[f64; 3]> = xyz.iter().map(|p| [p[0] * 1e3, p[1] * 1e3, p[2]]).collect();
        let (_, pitch_um) = bin_unorganized(&um, Some(pitch), LengthUnit::Um).unwrap();
        assert!((pitch_um - 20.0).abs() < 1e-9, "{pitch_um}");
    }

    #[test]
    fn points_on_a_line_cannot_be_binned() {
        let xyz: Vec<[f64; 3]> = (0..10).map(|i| [f64::from(i) * 0.1, 0.0, 0.0]).collect();
        assert!(matches!(bin_unorganized(&xyz, None, LengthUnit::Mm), Err(AnalysisError::NoArea)));
    }
}
