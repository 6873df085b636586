//! Exact ray casting of a heightfield with occlusion.
//!
//! A ray enters above the scene's highest point and descends. A grid of
//! conservative upper bounds of the height lets it skip, a coarse segment at
//! a time, everything it passes high above; where a segment dips below the
//! bound, it marches in steps small against the pixel pitch until it is at or
//! below the surface, then bisects the last step to 1e-12 mm. The first
//! crossing is the visible point, so anything the ray meets earlier (a step,
//! a boss) occludes what lies behind. A crossing where the height itself
//! jumps is a point on a vertical wall.

use rayon::prelude::*;

use super::rig::Ray;
use super::scene::Region;

/// Anything with a height at every point of a region of the stage.
pub trait HeightField: Sync {
    /// Height at `(x, y)`; NaN where the field is undefined (outside it).
    fn height_mm(&self, x_mm: f64, y_mm: f64) -> f64;
}

impl HeightField for super::scene::Scene {
    #[inline]
    fn height_mm(&self, x_mm: f64, y_mm: f64) -> f64 {
        super::scene::Scene::height_mm(self, x_mm, y_mm)
    }
}

/// Bisection stops when the bracket is this short (mm along Z).
pub const BISECTION_TOLERANCE_MM: f64 = 1e-12;
/// A height jump larger than this across the final bracket marks a wall.
const WALL_JUMP_MM: f64 = 1e-9;

/// Upper bounds of the height per cell of a grid over the field's extent.
#[derive(Clone, Debug)]
pub struct BoundGrid {
    x0_mm: f64,
    y0_mm: f64,
    cell_mm: f64,
    cols: usize,
    rows: usize,
    /// Per cell: an upper bound of the height over the cell (NEG_INFINITY: nothing).
    max_z_mm: Vec<f64>,
    /// Above every point of the field.
    pub top_mm: f64,
    /// Below every point of the field.
    pub bottom_mm: f64,
}

impl BoundGrid {
    /// Samples per cell side when bounding a cell.
    const SAMPLES: usize = 8;

    /// Bounds `field` over `extent` with cells of `cell_mm`. Each cell's bound
    /// is the largest of its samples and those of its eight neighbours, plus a
    /// margin: smooth parts between samples cannot rise above it unless their
    /// slope exceeds `max_slope` over a sample spacing, and features narrower
    /// than the sample spacing are not part of the scenes.
    pub fn new(field: &dyn HeightField, extent: Region, cell_mm: f64, max_slope: f64) -> Self {
        let cols = ((extent.x_max_mm - extent.x_min_mm) / cell_mm).ceil().max(1.0) as usize;
        let rows = ((extent.y_max_mm - extent.y_min_mm) / cell_mm).ceil().max(1.0) as usize;
        let n = Self::SAMPLES;
        let spacing = cell_mm / n as f64;
        let margin = max_slope * spacing + 1e-9;
        let raw: Vec<(f64, f64)> = (0..rows * cols)
            .into_par_iter()
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                let (x0, y0) = (extent.x_min_mm + c as f64 * cell_mm, extent.y_min_mm + r as f64 * cell_mm);
                let mut hi = f64::NEG_INFINITY;
                let mut lo = f64::INFINITY;
                for j in 0..=n {
                    for k in 0..=n {
                        let z = field.height_mm(x0 + k as f64 * spacing, y0 + j as f64 * spacing);
                        if z.is_finite() {
                            hi = hi.max(z);
                            lo = lo.min(z);
                        }
                    }
                }
                (hi, lo)
            })
            .collect();
        let mut max_z_mm = vec![f64::NEG_INFINITY; rows * cols];
        for r in 0..rows {
            for c in 0..cols {
                let mut m = f64::NEG_INFINITY;
                for rr in r.saturating_sub(1)..=(r + 1).min(rows - 1) {
                    for cc in c.saturating_sub(1)..=(c + 1).min(cols - 1) {
                        m = m.max(raw[rr * cols + cc].0);
                    }
                }
                max_z_mm[r * cols + c] = m + margin;
            }
        }
        let top = raw.iter().map(|v| v.0).fold(f64::NEG_INFINITY, f64::max) + margin + 1e-3;
        let bottom = raw.iter().map(|v| v.1).fold(f64::INFINITY, f64::min) - margin - 1e-3;
        Self {
            x0_mm: extent.x_min_mm,
            y0_mm: extent.y_min_mm,
            cell_mm,
            cols,
            rows,
            max_z_mm,
            top_mm: top,
            bottom_mm: bottom,
        }
    }

    /// Largest bound over the cells touched by the box spanned by two points
    /// (at most 2 x 2 cells for the segments the caster uses); cells outside
    /// the grid hold nothing.
    #[inline]
    fn bound_over(&self, a: [f64; 3], b: [f64; 3]) -> f64 {
        let cell = |v: f64, v0: f64| ((v - v0) / self.cell_mm).floor();
        let (c0, c1) = (cell(a[0].min(b[0]), self.x0_mm), cell(a[0].max(b[0]), self.x0_mm));
        let (r0, r1) = (cell(a[1].min(b[1]), self.y0_mm), cell(a[1].max(b[1]), self.y0_mm));
        let mut m = f64::NEG_INFINITY;
        let (c0, c1) = (c0.max(0.0), c1.min(self.cols as f64 - 1.0));
        let (r0, r1) = (r0.max(0.0), r1.min(self.rows as f64 - 1.0));
        if c0 > c1 || r0 > r1 {
            return m;
        }
        for r in r0 as usize..=r1 as usize {
            for c in c0 as usize..=c1 as usize {
                m = m.max(self.max_z_mm[r * self.cols + c]);
            }
        }
        m
    }
}

/// The first point where a ray meets the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// On the ray (so it projects exactly onto the ray's pixel) and on the
    /// surface to within [`BISECTION_TOLERANCE_MM`].
    pub point_mm: [f64; 3],
    /// The ray met a vertical wall (a jump of the height) rather than a top surface.
    pub on_wall: bool,
}

/// Casts `ray` into `field`; `None` when it leaves the field without a hit.
/// `step_mm` is the horizontal length of a marching step.
pub fn cast(field: &dyn HeightField, grid: &BoundGrid, ray: &Ray, step_mm: f64) -> Option<RayHit> {
    let slope = ray.slope[0].hypot(ray.slope[1]);
    // Z per horizontal mm; a near-vertical ray is capped so it still steps.
    let dz_per_mm = if slope > 1e-9 { 1.0 / slope } else { 1e9 };
    let coarse_dz = (0.5 * grid.cell_mm * dz_per_mm).min(grid.top_mm - grid.bottom_mm);
    let fine_dz = step_mm * dz_per_mm.min(100.0);
    // f(z) > 0: the ray at height z is above the surface (NaN: outside, counts as above).
    let above = |z: f64| -> Option<f64> {
        let p = ray.at(z);
        let h = field.height_mm(p[0], p[1]);
        if h.is_nan() { None } else { Some(z - h) }
    };
    let mut z = grid.top_mm;
    while z > grid.bottom_mm {
        let z_next = (z - coarse_dz).max(grid.bottom_mm);
        let bound = grid.bound_over(ray.at(z), ray.at(z_next));
        if z_next > bound {
            z = z_next;
            continue;
        }
        // Above the bound the ray cannot be in the surface: march from there.
        let mut z_hi = z;
        let mut zc = z.min(bound);
        loop {
            if let Some(f) = above(zc)
                && f <= 0.0
            {
                return Some(refine(field, ray, z_hi, zc));
            }
            if zc <= z_next {
                break;
            }
            z_hi = zc;
            zc = (zc - fine_dz).max(z_next);
        }
        z = z_next;
    }
    None
}

/// Bisects between `z_hi` (ray above the surface) and `z_lo` (at or below it).
fn refine(field: &dyn HeightField, ray: &Ray, mut z_hi: f64, mut z_lo: f64) -> RayHit {
    let height = |z: f64| {
        let p = ray.at(z);
        field.height_mm(p[0], p[1])
    };
    while z_hi - z_lo > BISECTION_TOLERANCE_MM {
        let mid = 0.5 * (z_hi + z_lo);
        if mid <= z_lo || mid >= z_hi {
            break; // the bracket is down to adjacent floating-point numbers
        }
        let h = height(mid);
        if h.is_nan() || mid - h > 0.0 {
            z_hi = mid;
        } else {
            z_lo = mid;
        }
    }
    let (h_hi, h_lo) = (height(z_hi), height(z_lo));
    let on_wall = !(h_lo - h_hi).abs().le(&WALL_JUMP_MM);
    let z = 0.5 * (z_hi + z_lo);
    RayHit { point_mm: ray.at(z), on_wall }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A level floor at 0 with a block of height 0.5 for x > 1.
    struct Step;
    impl HeightField for Step {
        fn height_mm(&self, x: f64, y: f64) -> f64 {
            if x.abs() > 10.0 || y.abs() > 10.0 {
                f64::NAN
            } else if x > 1.0 {
                0.5
            } else {
                0.0
            }
        }
    }

    fn extent() -> Region {
        Region { x_min_mm: -10.0, x_max_mm: 10.0, y_min_mm: -10.0, y_max_mm: 10.0 }
    }

    #[test]
    fn hits_floor_block_wall_and_occludes() {
        let grid = BoundGrid::new(&Step, extent(), 0.2, 0.0);
        let t = 15f64.to_radians().tan();
        // X = x_at_0 + slope Z: a left-camera ray moves to +X as it descends, a right one to -X.
        let left = |x_at_0: f64| Ray { origin_mm: [x_at_0, 0.0], slope: [-t, 0.0] };
        let right = |x_at_0: f64| Ray { origin_mm: [x_at_0, 0.0], slope: [t, 0.0] };
        // Lands on the floor far from the block.
        let hit = cast(&Step, &grid, &left(-3.0), 0.001).unwrap();
        assert!(!hit.on_wall && hit.point_mm[2].abs() <= 1e-12 && (hit.point_mm[0] + 3.0).abs() < 1e-11);
        // A left ray that would reach the floor at x = 1.05 enters the block's
        // wall (it faces the left camera) at x = 1, height 0.05 / tan(theta).
        let hit = cast(&Step, &grid, &left(1.05), 0.001).unwrap();
        assert!(hit.on_wall, "{hit:?}");
        assert!((hit.point_mm[0] - 1.0).abs() < 1e-11, "{:?}", hit.point_mm);
        assert!((hit.point_mm[2] - 0.05 / t).abs() < 1e-10);
        // A right ray aimed at the floor just left of the wall is stopped by the
        // block's top: that floor is occluded for the right camera.
        let hit = cast(&Step, &grid, &right(0.95), 0.001).unwrap();
        assert!(!hit.on_wall && (hit.point_mm[2] - 0.5).abs() <= 1e-12);
        assert!((hit.point_mm[0] - (0.95 + 0.5 * t)).abs() < 1e-11);
        // Outside the field: no hit.
        assert!(cast(&Step, &grid, &left(30.0), 0.001).is_none());
    }
}
