//! Exact ray casting of a heightfield with occlusion.
//!
//! A ray enters above the scene's highest point and descends. A grid of
//! conservative upper bounds of the height lets it skip, a coarse segment at
//! a time, everything it passes high above; where a segment dips below the
//! bound, it marches in steps small against the pixel pitch until it is at or
//! below the surface, then narrows the last step to 1e-12 mm (false position,
//! falling back to bisection whenever a step fails to halve the bracket). The
//! first crossing is the visible point, so anything the ray meets earlier (a
//! step, a boss) occludes what lies behind. A crossing where the height
//! itself jumps is a point on a vertical wall.

use rayon::prelude::*;

use super::rig::Ray;
use super::scene_model::Region;

/// Anything with a height at every point of a region of the stage, made of
/// smooth pieces.
pub trait HeightField: Sync {
    /// Height at `(x, y)` (NaN outside the field) and the piece of surface it
    /// belongs to: within a piece the height is continuous and rises no faster
    /// than the bound grid's `max_slope`; it may jump only where the piece
    /// changes (a wall).
    fn sample(&self, x_mm: f64, y_mm: f64) -> (f64, u32);
}

impl HeightField for super::scene_model::Scene {
    /// The pieces are the scene's features: each feature's surface is smooth.
    #[inline]
    fn sample(&self, x_mm: f64, y_mm: f64) -> (f64, u32) {
        match self.stage_point(x_mm, y_mm) {
            Some(p) => (p.surface.z_mm, p.feature as u32),
            None => (f64::NAN, u32::MAX),
        }
    }
}

/// Bisection stops when the bracket is this short (mm along Z).
pub const BISECTION_TOLERANCE_MM: f64 = 1e-12;
/// A crossing whose clearance is this small is on the surface.
pub const SURFACE_TOLERANCE_MM: f64 = 1e-13;
/// A height jump larger than this across the final bracket marks a wall.
const WALL_JUMP_MM: f64 = 1e-9;

/// Upper bounds of the height on one grid of square cells.
#[derive(Clone, Debug)]
struct BoundLevel {
    cell_mm: f64,
    cols: usize,
    rows: usize,
    /// Per cell: an upper bound of the height over the cell (NEG_INFINITY: nothing).
    max_z_mm: Vec<f64>,
}

impl BoundLevel {
    /// Largest bound over the cells touched by the box spanned by two points
    /// (at most 2 x 2 cells for the segments the caster uses); cells outside
    /// the grid hold nothing.
    #[inline]
    fn bound_over(&self, origin: [f64; 2], a: [f64; 3], b: [f64; 3]) -> f64 {
        let cell = |v: f64, v0: f64| ((v - v0) / self.cell_mm).floor();
        let (c0, c1) = (cell(a[0].min(b[0]), origin[0]).max(0.0), cell(a[0].max(b[0]), origin[0]));
        let (r0, r1) = (cell(a[1].min(b[1]), origin[1]).max(0.0), cell(a[1].max(b[1]), origin[1]));
        let (c1, r1) = (c1.min(self.cols as f64 - 1.0), r1.min(self.rows as f64 - 1.0));
        let mut m = f64::NEG_INFINITY;
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

/// Conservative upper bounds of the height over a field's extent, on a fine
/// grid and on a coarse one (blocks of fine cells) so rays skip high empty
/// space in long steps.
#[derive(Clone, Debug)]
pub struct BoundGrid {
    origin_mm: [f64; 2],
    fine: BoundLevel,
    coarse: BoundLevel,
    /// Above every point of the field.
    pub top_mm: f64,
    /// Below every point of the field.
    pub bottom_mm: f64,
    /// Steepest rise of a smooth part the bounds and the adaptive steps allow for.
    pub max_slope: f64,
}

impl BoundGrid {
    /// Fine cells per coarse cell side.
    const BLOCK: usize = 8;

    /// Bounds `field` over `extent` with fine cells of `cell_mm`, from samples
    /// on a lattice `cell_mm / samples_per_cell` apart that reaches one sample
    /// beyond each cell (so a raised sliver at its edge is not missed). A
    /// cell's bound is its largest sample plus the largest rise between
    /// neighbouring samples, capped at `max_slope` per spacing: a smooth
    /// surface cannot climb above its samples by more than that between them,
    /// and a jump is caught by the samples on its high side. Features narrower
    /// than the sample spacing are assumed absent.
    pub fn new(field: &dyn HeightField, extent: Region, cell_mm: f64, samples_per_cell: usize, max_slope: f64) -> Self {
        let n = samples_per_cell.max(1);
        let cols = ((extent.x_max_mm - extent.x_min_mm) / cell_mm).ceil().max(1.0) as usize;
        let rows = ((extent.y_max_mm - extent.y_min_mm) / cell_mm).ceil().max(1.0) as usize;
        let spacing = cell_mm / n as f64;
        let cap = max_slope * spacing;
        // Lattice node (i, j) sits at extent corner + (i - 1, j - 1) spacings.
        let (nx, ny) = (cols * n + 3, rows * n + 3);
        let origin = [extent.x_min_mm, extent.y_min_mm];
        let lattice: Vec<f64> = (0..nx * ny)
            .into_par_iter()
            .map(|i| {
                let (x, y) = ((i % nx) as f64 - 1.0, (i / nx) as f64 - 1.0);
                field.sample(origin[0] + x * spacing, origin[1] + y * spacing).0
            })
            .collect();
        // Largest height change from each node to its right, upper and diagonal neighbours.
        let rise: Vec<f64> = (0..nx * ny)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % nx, i / nx);
                let v = lattice[i];
                let mut r = 0.0f64;
                for (dx, dy) in [(1, 0), (0, 1), (1, 1)] {
                    if x + dx < nx && y + dy < ny {
                        let w = lattice[(y + dy) * nx + x + dx];
                        if (v - w).is_finite() {
                            r = r.max((v - w).abs());
                        }
                    }
                }
                r
            })
            .collect();
        let cells: Vec<(f64, f64)> = (0..rows * cols)
            .into_par_iter()
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                let (mut hi, mut lo, mut up) = (f64::NEG_INFINITY, f64::INFINITY, 0.0f64);
                for y in r * n..=(r + 1) * n + 2 {
                    for x in c * n..=(c + 1) * n + 2 {
                        let v = lattice[y * nx + x];
                        if v.is_finite() {
                            hi = hi.max(v);
                            lo = lo.min(v);
                            up = up.max(rise[y * nx + x]);
                        }
                    }
                }
                (hi + up.min(cap) + 1e-9, lo)
            })
            .collect();
        let fine = BoundLevel { cell_mm, cols, rows, max_z_mm: cells.iter().map(|v| v.0).collect() };
        let (cc, cr) = (cols.div_ceil(Self::BLOCK), rows.div_ceil(Self::BLOCK));
        let mut coarse = vec![f64::NEG_INFINITY; cc * cr];
        for r in 0..rows {
            for c in 0..cols {
                let k = (r / Self::BLOCK) * cc + c / Self::BLOCK;
                coarse[k] = coarse[k].max(fine.max_z_mm[r * cols + c]);
            }
        }
        let coarse = BoundLevel { cell_mm: cell_mm * Self::BLOCK as f64, cols: cc, rows: cr, max_z_mm: coarse };
        let top = fine.max_z_mm.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 1e-3;
        let bottom = cells.iter().map(|v| v.1).fold(f64::INFINITY, f64::min) - cap - 1e-3;
        Self { origin_mm: origin, fine, coarse, top_mm: top, bottom_mm: bottom, max_slope }
    }

    #[inline]
    fn fine_bound(&self, a: [f64; 3], b: [f64; 3]) -> f64 {
        self.fine.bound_over(self.origin_mm, a, b)
    }

    #[inline]
    fn coarse_bound(&self, a: [f64; 3], b: [f64; 3]) -> f64 {
        self.coarse.bound_over(self.origin_mm, a, b)
    }
}

/// The first point where a ray meets the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// On the ray (so it projects exactly onto the ray's pixel) and on the
    /// surface: its height is `h(x, y)` to [`SURFACE_TOLERANCE_MM`], or on a
    /// wall, the wall's position to [`BISECTION_TOLERANCE_MM`].
    pub point_mm: [f64; 3],
    /// The ray met a vertical wall (a jump of the height) rather than a top surface.
    pub on_wall: bool,
}

/// How a ray marches: over the coarse and the fine bound grid in steps half
/// a cell long horizontally, and below the bounds in fine steps from
/// `step_mm` up to 8 `step_mm` horizontally, as far as the clearance allows
/// (a near-vertical ray still steps).
struct Marching {
    coarse_dz: f64,
    cell_dz: f64,
    fine_dz: f64,
    max_fine_dz: f64,
    /// Largest drop of the clearance per unit of vertical travel: the ray's
    /// own descent plus the steepest allowed rise of the surface under it.
    clearance_rate: f64,
}

impl Marching {
    fn new(grid: &BoundGrid, ray: &Ray, step_mm: f64) -> Self {
        let slope = ray.slope[0].hypot(ray.slope[1]);
        let dz_per_mm = if slope > 1e-9 { (1.0 / slope).min(100.0) } else { 100.0 };
        let range = grid.top_mm - grid.bottom_mm;
        Self {
            coarse_dz: (0.5 * grid.coarse.cell_mm * dz_per_mm).min(range),
            cell_dz: (0.5 * grid.fine.cell_mm * dz_per_mm).min(range),
            fine_dz: step_mm * dz_per_mm,
            max_fine_dz: 8.0 * step_mm * dz_per_mm,
            clearance_rate: 1.0 + grid.max_slope * slope,
        }
    }

    /// Largest height change a smooth surface makes under a ray segment of
    /// vertical length `dz`; more means a jump (a step) lies under it.
    #[inline]
    fn smooth_change(&self, dz: f64) -> f64 {
        (self.clearance_rate - 1.0) * dz + WALL_JUMP_MM
    }

    /// The next fine step from a point with clearance `f`: a surface rising at
    /// most `max_slope` cannot close a gap of `f` sooner, so stepping that far
    /// cannot miss a crossing (jumps are crossed and then found by refinement;
    /// only features narrower than the step could slip through).
    #[inline]
    fn step(&self, f: f64) -> f64 {
        (f.abs() / self.clearance_rate).clamp(self.fine_dz, self.max_fine_dz)
    }
}

/// The surface under one height `z` of a ray.
#[derive(Clone, Copy, Debug)]
struct Probe {
    z: f64,
    /// NaN outside the field.
    h: f64,
    piece: u32,
}

impl Probe {
    /// `z - h`: positive while the ray is above the surface (outside the field: clear).
    #[inline]
    fn clearance(&self) -> f64 {
        if self.h.is_nan() { f64::INFINITY } else { self.z - self.h }
    }
}

#[inline]
fn probe(field: &dyn HeightField, ray: &Ray, z: f64) -> Probe {
    let p = ray.at(z);
    let (h, piece) = field.sample(p[0], p[1]);
    Probe { z, h, piece }
}

/// Casts `ray` into `field`; `None` when it leaves the field without a hit.
/// `step_mm` is the horizontal length of a marching step.
pub fn cast(field: &dyn HeightField, grid: &BoundGrid, ray: &Ray, step_mm: f64) -> Option<RayHit> {
    let march = Marching::new(grid, ray, step_mm);
    let mut z = grid.top_mm;
    while z > grid.bottom_mm {
        let z_next = (z - march.coarse_dz).max(grid.bottom_mm);
        if z_next <= grid.coarse_bound(ray.at(z), ray.at(z_next))
            && let Some(hit) = descend(field, grid, ray, &march, z, z_next)
        {
            return Some(hit);
        }
        z = z_next;
    }
    None
}

/// The caster's work within one coarse segment `[z_to, z_from]`: fine-cell
/// segments the ray passes above are skipped, the rest is marched.
fn descend(
    field: &dyn HeightField,
    grid: &BoundGrid,
    ray: &Ray,
    march: &Marching,
    z_from: f64,
    z_to: f64,
) -> Option<RayHit> {
    let mut z = z_from;
    while z > z_to {
        let z_next = (z - march.cell_dz).max(z_to);
        let bound = grid.fine_bound(ray.at(z), ray.at(z_next));
        if z_next > bound {
            z = z_next;
            continue;
        }
        // Above the bound the ray cannot be in the surface: march from there.
        let mut upper: Option<Probe> = None;
        let mut zc = z.min(bound);
        loop {
            let p = probe(field, ray, zc);
            // Between two probes the ray may cut the corner of a step.
            if let Some(u) = upper
                && let Some((above, below)) = corner_crossing(field, ray, march, u, p)
            {
                return Some(refine(field, ray, march, above, below));
            }
            let f = p.clearance();
            if f <= 0.0 {
                let above = upper.unwrap_or_else(|| probe(field, ray, z));
                return Some(refine(field, ray, march, above, p));
            }
            if zc <= z_next {
                break;
            }
            upper = Some(p);
            zc = (zc - if f.is_finite() { march.step(f) } else { march.fine_dz }).max(z_next);
        }
        z = z_next;
    }
    None
}

/// Between two probes where the ray is clear, finds a point where it is not,
/// if the ray cuts the corner of a step there: only possible if the surface
/// changes piece between them (a wall) and the higher side reaches above the
/// ray's lower end. Halving towards the change of piece, every midpoint is
/// tested, so a cut corner is found however thin the sliver. Returns
/// `(clear probe, probe at or below the surface)` for [`refine`].
fn corner_crossing(
    field: &dyn HeightField,
    ray: &Ray,
    march: &Marching,
    upper: Probe,
    lower: Probe,
) -> Option<(Probe, Probe)> {
    let top = |p: &Probe| if p.h.is_nan() { f64::NEG_INFINITY } else { p.h };
    if upper.piece == lower.piece || top(&upper).max(top(&lower)) + march.smooth_change(upper.z - lower.z) <= lower.z {
        return None;
    }
    let (mut a, mut b) = (upper, lower);
    while a.z - b.z > BISECTION_TOLERANCE_MM {
        let mid = 0.5 * (a.z + b.z);
        if !(mid > b.z && mid < a.z) {
            break;
        }
        let m = probe(field, ray, mid);
        if m.clearance() <= 0.0 {
            return Some((a, m));
        }
        // Follow the change of piece; on the upper side first.
        if m.piece != a.piece {
            b = m;
        } else {
            a = m;
        }
    }
    None
}

/// Narrows a bracket (the ray clear at `hi` and nowhere below the surface
/// above it, at or below the surface at `lo`) to the first crossing: false
/// position while it at least halves the bracket, bisection otherwise, until
/// the clearance is below [`SURFACE_TOLERANCE_MM`] or the bracket below
/// [`BISECTION_TOLERANCE_MM`]. A bracket can hold several crossings (a cut
/// corner above a floor), so before a trial point is accepted as clear or as
/// the hit, the part above it is searched by [`corner_crossing`].
fn refine(field: &dyn HeightField, ray: &Ray, march: &Marching, mut hi: Probe, mut lo: Probe) -> RayHit {
    let mut bisect = !hi.clearance().is_finite();
    loop {
        if lo.clearance() > -SURFACE_TOLERANCE_MM {
            match corner_crossing(field, ray, march, hi, lo) {
                None => return RayHit { point_mm: ray.at(lo.z), on_wall: false },
                Some((a, b)) => (hi, lo) = (a, b),
            }
            continue;
        }
        let width = hi.z - lo.z;
        if width <= BISECTION_TOLERANCE_MM {
            break;
        }
        let (f_hi, f_lo) = (hi.clearance(), lo.clearance());
        let mut z = if bisect { 0.5 * (hi.z + lo.z) } else { hi.z - f_hi * width / (f_hi - f_lo) };
        if !(z > lo.z && z < hi.z) {
            z = 0.5 * (hi.z + lo.z);
            if !(z > lo.z && z < hi.z) {
                break; // the bracket is down to adjacent floating-point numbers
            }
        }
        let p = probe(field, ray, z);
        if p.clearance() < -SURFACE_TOLERANCE_MM {
            lo = p;
        } else if let Some((a, b)) = corner_crossing(field, ray, march, hi, p) {
            (hi, lo) = (a, b);
        } else if p.clearance() <= SURFACE_TOLERANCE_MM {
            return RayHit { point_mm: ray.at(p.z), on_wall: false };
        } else {
            hi = p;
        }
        bisect = hi.z - lo.z > 0.5 * width || !hi.clearance().is_finite();
    }
    // The bracket closed on a jump of the height: the ray meets a wall
    // between the two heights.
    let on_wall = !(lo.h - hi.h).abs().le(&WALL_JUMP_MM);
    RayHit { point_mm: ray.at(0.5 * (hi.z + lo.z)), on_wall }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A level floor at 0 with a block of height 0.5 for x > 1.
    struct Step;
    impl HeightField for Step {
        fn sample(&self, x: f64, y: f64) -> (f64, u32) {
            if x.abs() > 10.0 || y.abs() > 10.0 {
                (f64::NAN, u32::MAX)
            } else if x > 1.0 {
                (0.5, 1)
            } else {
                (0.0, 0)
            }
        }
    }

    fn extent() -> Region {
        Region { x_min_mm: -10.0, x_max_mm: 10.0, y_min_mm: -10.0, y_max_mm: 10.0 }
    }

    #[test]
    fn hits_floor_block_wall_and_occludes() {
        let grid = BoundGrid::new(&Step, extent(), 0.2, 8, 0.0);
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

    #[test]
    fn a_ray_cutting_a_steps_corner_hits_it_whatever_the_step() {
        let grid = BoundGrid::new(&Step, extent(), 0.2, 8, 0.0);
        let t = 15f64.to_radians().tan();
        for miss_mm in [1e-3, 1e-6, 1e-9] {
            // A right-camera ray that passes the block's top edge (x = 1, z = 0.5)
            // just below it: it cuts a sliver of the block's top, miss_mm tan(theta)
            // wide, far narrower than the 10 um marching step.
            let ray = Ray { origin_mm: [1.0 - t * (0.5 - miss_mm), 0.0], slope: [t, 0.0] };
            let hit = cast(&Step, &grid, &ray, 0.01).unwrap();
            assert!((hit.point_mm[2] - 0.5).abs() <= 1e-12 && hit.point_mm[0] >= 1.0, "{miss_mm}: {hit:?}");
        }
    }

    /// A smooth dome: the refinement must land on it to the surface tolerance.
    struct Dome;
    impl HeightField for Dome {
        fn sample(&self, x: f64, y: f64) -> (f64, u32) {
            ((4.0 - x * x - y * y).max(0.0).sqrt(), 0)
        }
    }

    #[test]
    fn smooth_surface_hits_are_on_the_surface() {
        let ext = Region { x_min_mm: -3.0, x_max_mm: 3.0, y_min_mm: -3.0, y_max_mm: 3.0 };
        let grid = BoundGrid::new(&Dome, ext, 0.05, 4, 3.0);
        let t = 15f64.to_radians().tan();
        for k in 0..200 {
            let x0 = -2.5 + k as f64 * 0.025;
            let ray = Ray { origin_mm: [x0, 0.3], slope: [-t, 0.0] };
            let hit = cast(&Dome, &grid, &ray, 0.002).unwrap();
            let [x, y, z] = hit.point_mm;
            assert!((z - Dome.sample(x, y).0).abs() <= 1e-12, "x0 {x0}: {:?}", hit.point_mm);
            // On the ray.
            assert!((x - (x0 - t * z)).abs() < 1e-12);
        }
    }
}
