//! Ordering detected target points into the `rows x cols` grid.
//!
//! A telecentric camera images the planar grid through an affine map (plus a
//! little lens distortion), so the detected points form a 2D lattice. The
//! lattice is grown from a point near the middle: its two shortest
//! independent neighbour vectors are a basis of the lattice (in 2D the
//! successive minima always are), and each neighbour is predicted from the
//! local step, which follows a slowly varying distortion. Points that do not
//! fall on the lattice (dust, labels) are left out. The lattice must then be
//! exactly `rows x cols` and complete; it is labelled so that j runs to the
//! image right and i to its bottom, each within 45 degrees, which makes (0, 0)
//! the top-left point and the labelling the same in both cameras. Anything
//! else is reported with its reason, never guessed.

use std::collections::{HashMap, VecDeque};

/// Why the points do not form the expected grid.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GridError {
    #[error(
        "found {found} {noun}, the target has {rows} x {cols} = {expected}: it is partly hidden or outside the image, \
         or the grid size in the calibration set is wrong"
    )]
    TooFewPoints { found: usize, expected: usize, rows: usize, cols: usize, noun: &'static str },
    #[error("the {found} {noun} found do not form a regular grid (no two independent neighbour directions)")]
    NotALattice { found: usize, noun: &'static str },
    #[error(
        "the {noun} do not lie on a smooth grid (a point is {worst_px:.2} px off a quadratic fit); \
         check the image for dirt, reflections or strong blur"
    )]
    Irregular { worst_px: f64, noun: &'static str },
    #[error(
        "found {found} of the target's {expected} {noun}, in a lattice of {lattice_rows} x {lattice_cols}{missing}: \
         the target is partly hidden or outside the image",
        missing = describe_missing(.missing_px)
    )]
    Incomplete {
        found: usize,
        expected: usize,
        lattice_rows: usize,
        lattice_cols: usize,
        /// Where the absent points of the lattice would be, in pixels (at most a few).
        missing_px: Vec<[f64; 2]>,
        noun: &'static str,
    },
    #[error(
        "found a complete grid of {found_rows} x {found_cols} {noun}, the calibration set declares {rows} x {cols}: \
         correct `rows` and `cols` (a checkerboard counts inner corners), turn the target so its rows run \
         across the image, or, if part of the target is hidden or outside the image, make all of it visible"
    )]
    WrongSize { found_rows: usize, found_cols: usize, rows: usize, cols: usize, noun: &'static str },
    #[error(
        "the grid's rows run at {row_angle_deg:.1} deg to the image rows and its columns at {col_angle_deg:.1} deg \
         to the image columns; they must be within 45 deg (40 deg for a square grid) so the labelling is \
         unambiguous: rotate the target"
    )]
    Orientation { row_angle_deg: f64, col_angle_deg: f64 },
}

fn describe_missing(missing: &[[f64; 2]]) -> String {
    if missing.is_empty() {
        return String::new();
    }
    let list: Vec<String> = missing.iter().map(|p| format!("({:.0}, {:.0})", p[0], p[1])).collect();
    format!(" (missing near pixel {})", list.join(", "))
}

/// Lattice cells at most this fraction of the shorter basis vector away from
/// their prediction are accepted.
const MATCH_TOLERANCE: f64 = 0.3;
/// Largest angle between a square grid's axes and the image axes: a margin
/// below 45 degrees so both cameras of the rig label the grid the same way.
pub const SQUARE_GRID_ANGLE_LIMIT_DEG: f64 = 40.0;
/// Seeds tried, nearest to the middle of the points first.
const MAX_SEEDS: usize = 12;

type Cell = (i64, i64);

/// Orders `points` into the grid: returns, for each grid point in row-major
/// order (`i * cols + j`), the index of its point.
pub fn order_grid(points: &[[f64; 2]], rows: usize, cols: usize, noun: &'static str) -> Result<Vec<usize>, GridError> {
    let expected = rows * cols;
    let Some(cells) = best_lattice(points) else {
        return Err(if points.len() < expected {
            GridError::TooFewPoints { found: points.len(), expected, rows, cols, noun }
        } else {
            GridError::NotALattice { found: points.len(), noun }
        });
    };
    let cells = align_to_grid(cells);
    let fit = LatticeFit::new(points, &cells);
    let worst_px = cells.iter().map(|(c, &k)| dist(fit.predict_quadratic(*c), points[k])).fold(0.0, f64::max);
    if worst_px > 0.25 * fit.min_step_px() {
        return Err(GridError::Irregular { worst_px, noun });
    }
    let (m_lo, m_hi) = extent(cells.keys().map(|c| c.0));
    let (n_lo, n_hi) = extent(cells.keys().map(|c| c.1));
    let ext_m = (m_hi - m_lo + 1) as usize;
    let ext_n = (n_hi - n_lo + 1) as usize;
    // The size as the image shows it: the axis nearer the image rows counts columns.
    let (found_rows, found_cols) = if fit.m_is_horizontal() { (ext_n, ext_m) } else { (ext_m, ext_n) };
    let filled = cells.len() == ext_m * ext_n;
    if filled && (found_rows, found_cols) != (rows, cols) {
        return Err(GridError::WrongSize { found_rows, found_cols, rows, cols, noun });
    }
    if !filled {
        let declared_extent = (ext_m == cols && ext_n == rows) || (ext_m == rows && ext_n == cols);
        if points.len() < expected && !declared_extent {
            return Err(GridError::TooFewPoints { found: points.len(), expected, rows, cols, noun });
        }
        let mut missing_px = Vec::new();
        for m in m_lo..=m_hi {
            for n in n_lo..=n_hi {
                if !cells.contains_key(&(m, n)) && missing_px.len() < 4 {
                    missing_px.push(fit.predict_quadratic((m, n)));
                }
            }
        }
        return Err(GridError::Incomplete {
            found: cells.len(),
            expected,
            lattice_rows: found_rows,
            lattice_cols: found_cols,
            missing_px,
            noun,
        });
    }
    label(&cells, &fit, rows, cols, (m_lo, m_hi), (n_lo, n_hi))
}

fn extent(values: impl Iterator<Item = i64>) -> (i64, i64) {
    values.fold((i64::MAX, i64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)))
}

#[inline]
fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

#[inline]
fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

#[inline]
fn dot2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The lattice with the most points over the seeds tried; `None` when no
/// seed has two independent neighbours.
fn best_lattice(points: &[[f64; 2]]) -> Option<HashMap<Cell, usize>> {
    if points.len() < 4 {
        return None;
    }
    let mut xs: Vec<f64> = points.iter().map(|p| p[0]).collect();
    let mut ys: Vec<f64> = points.iter().map(|p| p[1]).collect();
    xs.sort_by(f64::total_cmp);
    ys.sort_by(f64::total_cmp);
    let middle = [xs[xs.len() / 2], ys[ys.len() / 2]];
    let mut seeds: Vec<usize> = (0..points.len()).collect();
    seeds.sort_by(|&a, &b| dist(points[a], middle).total_cmp(&dist(points[b], middle)));
    let mut best: Option<HashMap<Cell, usize>> = None;
    for &seed in seeds.iter().take(MAX_SEEDS) {
        let Some(basis) = basis_at(points, seed) else { continue };
        let Some(cells) = grow(points, seed, basis) else { continue };
        if best.as_ref().is_none_or(|b| cells.len() > b.len()) {
            best = Some(cells);
        }
    }
    best.filter(|b| b.len() >= 4)
}

/// A reduced lattice basis from the neighbours of `seed`.
fn basis_at(points: &[[f64; 2]], seed: usize) -> Option<[[f64; 2]; 2]> {
    let p = points[seed];
    let mut neighbours: Vec<[f64; 2]> =
        points.iter().enumerate().filter(|&(k, _)| k != seed).map(|(_, &q)| sub(q, p)).collect();
    neighbours.sort_by(|a, b| dot2(*a, *a).total_cmp(&dot2(*b, *b)));
    let a = *neighbours.first()?;
    let la = dot2(a, a).sqrt();
    if la <= 0.0 {
        return None;
    }
    // The second successive minimum of a 2D lattice is at 60-120 degrees to
    // the first, so anything within 30 degrees of `a` is a multiple or clutter.
    let b = *neighbours.iter().find(|b| {
        let lb = dot2(**b, **b).sqrt();
        (a[0] * b[1] - a[1] * b[0]).abs() > 0.5 * la * lb
    })?;
    // Gauss (Lagrange) reduction, in case clutter gave a longer vector.
    let (mut a, mut b) = (a, b);
    for _ in 0..16 {
        if dot2(b, b) < dot2(a, a) {
            std::mem::swap(&mut a, &mut b);
        }
        let mu = (dot2(a, b) / dot2(a, a)).round();
        if mu == 0.0 {
            break;
        }
        b = [b[0] - mu * a[0], b[1] - mu * a[1]];
    }
    Some([a, b])
}

/// Breadth-first growth of the lattice from `seed`; `None` on a conflict (a
/// point claimed by two cells), which means the basis is wrong.
fn grow(points: &[[f64; 2]], seed: usize, basis: [[f64; 2]; 2]) -> Option<HashMap<Cell, usize>> {
    let tolerance = MATCH_TOLERANCE * dot2(basis[0], basis[0]).sqrt().min(dot2(basis[1], basis[1]).sqrt());
    let mut cells: HashMap<Cell, usize> = HashMap::new();
    let mut owner: Vec<Option<Cell>> = vec![None; points.len()];
    let mut queue = VecDeque::new();
    cells.insert((0, 0), seed);
    owner[seed] = Some((0, 0));
    queue.push_back((0i64, 0i64));
    while let Some(cell) = queue.pop_front() {
        let p = points[cells[&cell]];
        for (dm, dn, g) in [(1, 0, basis[0]), (-1, 0, basis[0]), (0, 1, basis[1]), (0, -1, basis[1])] {
            let next = (cell.0 + dm, cell.1 + dn);
            if cells.contains_key(&next) {
                continue;
            }
            let sign = (dm + dn) as f64;
            // The step from the cell behind follows local distortion better
            // than the global basis.
            let step = match cells.get(&(cell.0 - dm, cell.1 - dn)) {
                Some(&behind) => sub(p, points[behind]),
                None => [sign * g[0], sign * g[1]],
            };
            let predicted = [p[0] + step[0], p[1] + step[1]];
            let nearest = points
                .iter()
                .enumerate()
                .map(|(k, &q)| (k, dist(q, predicted)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|&(_, d)| d < tolerance);
            if let Some((k, _)) = nearest {
                match owner[k] {
                    None => {
                        owner[k] = Some(next);
                        cells.insert(next, k);
                        queue.push_back(next);
                    }
                    Some(other) if other != next => return None,
                    Some(_) => {}
                }
            }
        }
    }
    Some(cells)
}

/// Re-expresses the lattice in the basis of the grid's rows and columns.
///
/// The reduced basis found by growth is the grid's own basis unless the image
/// shears the grid strongly (its axes closer than 60 degrees); then the grid
/// is a parallelogram in lattice cells. Of the unimodular changes of basis
/// with small entries, the one whose bounding box of the cells is smallest
/// makes the grid a rectangle (for a complete grid the box is then exactly
/// filled).
fn align_to_grid(cells: HashMap<Cell, usize>) -> HashMap<Cell, usize> {
    let area = |t: [[i64; 2]; 2]| {
        let (m, n) = cells
            .keys()
            .map(|&(m, n)| (t[0][0] * m + t[0][1] * n, t[1][0] * m + t[1][1] * n))
            .fold(((i64::MAX, i64::MIN), (i64::MAX, i64::MIN)), |((a, b), (c, d)), (m, n)| {
                ((a.min(m), b.max(m)), (c.min(n), d.max(n)))
            });
        (m.1 - m.0 + 1) * (n.1 - n.0 + 1)
    };
    let identity = [[1, 0], [0, 1]];
    let mut best = (area(identity), identity);
    for a in -2..=2i64 {
        for b in -2..=2i64 {
            for c in -2..=2i64 {
                for d in -2..=2i64 {
                    if (a * d - b * c).abs() != 1 {
                        continue;
                    }
                    let t = [[a, b], [c, d]];
                    let candidate = area(t);
                    if candidate < best.0 {
                        best = (candidate, t);
                    }
                }
            }
        }
    }
    let t = best.1;
    cells.into_iter().map(|((m, n), k)| ((t[0][0] * m + t[0][1] * n, t[1][0] * m + t[1][1] * n), k)).collect()
}

/// Least-squares maps from lattice cells to pixels: affine (for the axis
/// directions) and quadratic (for the regularity check and predictions).
struct LatticeFit {
    /// `p = origin + m * axis_m + n * axis_n`.
    axis_m: [f64; 2],
    axis_n: [f64; 2],
    quadratic: [[f64; 6]; 2],
}

impl LatticeFit {
    fn new(points: &[[f64; 2]], cells: &HashMap<Cell, usize>) -> Self {
        let solve = |basis: &dyn Fn(Cell) -> Vec<f64>, n: usize| -> [Vec<f64>; 2] {
            let mut ata = nalgebra::DMatrix::<f64>::zeros(n, n);
            let mut atb = [nalgebra::DVector::<f64>::zeros(n), nalgebra::DVector::<f64>::zeros(n)];
            for (&c, &k) in cells {
                let f = nalgebra::DVector::from_vec(basis(c));
                ata += &f * f.transpose();
                for (d, rhs) in atb.iter_mut().enumerate() {
                    *rhs += &f * points[k][d];
                }
            }
            // Fewer cells than terms (tiny lattices) leave the normal matrix
            // singular; the pseudo-inverse then gives the minimum-norm fit.
            let inverse = ata.clone().pseudo_inverse(1e-12).unwrap_or(ata);
            [(&inverse * &atb[0]).iter().copied().collect(), (&inverse * &atb[1]).iter().copied().collect()]
        };
        let affine = solve(&|(m, n)| vec![1.0, m as f64, n as f64], 3);
        let quad = solve(&|(m, n)| quadratic_terms((m, n)).to_vec(), 6);
        let q = |v: &Vec<f64>| std::array::from_fn(|i| v.get(i).copied().unwrap_or(0.0));
        Self {
            axis_m: [affine[0][1], affine[1][1]],
            axis_n: [affine[0][2], affine[1][2]],
            quadratic: [q(&quad[0]), q(&quad[1])],
        }
    }

    fn predict_quadratic(&self, cell: Cell) -> [f64; 2] {
        let t = quadratic_terms(cell);
        let row = |c: &[f64; 6]| c.iter().zip(t.iter()).map(|(a, b)| a * b).sum::<f64>();
        [row(&self.quadratic[0]), row(&self.quadratic[1])]
    }

    fn min_step_px(&self) -> f64 {
        dot2(self.axis_m, self.axis_m).sqrt().min(dot2(self.axis_n, self.axis_n).sqrt())
    }

    /// Whether the m axis is closer to the image rows (u) than the n axis.
    fn m_is_horizontal(&self) -> bool {
        let slope = |a: [f64; 2]| a[0].abs() / dot2(a, a).sqrt();
        slope(self.axis_m) >= slope(self.axis_n)
    }
}

fn quadratic_terms((m, n): Cell) -> [f64; 6] {
    let (m, n) = (m as f64, n as f64);
    [1.0, m, n, m * m, m * n, n * n]
}

/// Chooses the unique labelling with j within 45 degrees of the image right
/// and i within 45 degrees of the image bottom. A square grid can also be
/// labelled turned by 90 degrees; near 45 degrees the two cameras could then
/// choose differently, so square grids must sit within
/// [`SQUARE_GRID_ANGLE_LIMIT_DEG`].
fn label(
    cells: &HashMap<Cell, usize>,
    fit: &LatticeFit,
    rows: usize,
    cols: usize,
    (m_lo, m_hi): (i64, i64),
    (n_lo, n_hi): (i64, i64),
) -> Result<Vec<usize>, GridError> {
    let ext_m = (m_hi - m_lo + 1) as usize;
    let ext_n = (n_hi - n_lo + 1) as usize;
    let limit_deg = if rows == cols { SQUARE_GRID_ANGLE_LIMIT_DEG } else { 45.0 };
    // (j along m?, sign of j, sign of i)
    let mut admissible = Vec::new();
    let mut best_angles = (f64::INFINITY, f64::INFINITY);
    for j_along_m in [true, false] {
        let (ext_j, ext_i) = if j_along_m { (ext_m, ext_n) } else { (ext_n, ext_m) };
        if ext_j != cols || ext_i != rows {
            continue;
        }
        let (axis_j, axis_i) = if j_along_m { (fit.axis_m, fit.axis_n) } else { (fit.axis_n, fit.axis_m) };
        for sj in [1i64, -1] {
            for si in [1i64, -1] {
                let (fj, fi) = (sj as f64, si as f64);
                let row_angle = (fj * axis_j[1]).atan2(fj * axis_j[0]).to_degrees().abs();
                let col_angle = (fi * axis_i[0]).atan2(fi * axis_i[1]).to_degrees().abs();
                if row_angle < limit_deg && col_angle < limit_deg {
                    admissible.push((j_along_m, sj, si));
                }
                if row_angle.max(col_angle) < best_angles.0.max(best_angles.1) {
                    best_angles = (row_angle, col_angle);
                }
            }
        }
    }
    let orientation_error = GridError::Orientation { row_angle_deg: best_angles.0, col_angle_deg: best_angles.1 };
    let [(j_along_m, sj, si)] = admissible[..] else {
        return Err(orientation_error);
    };
    let coordinate = |index: i64, sign: i64, lo: i64, hi: i64| if sign > 0 { lo + index } else { hi - index };
    let mut order = Vec::with_capacity(rows * cols);
    for i in 0..rows as i64 {
        for j in 0..cols as i64 {
            let cell = if j_along_m {
                (coordinate(j, sj, m_lo, m_hi), coordinate(i, si, n_lo, n_hi))
            } else {
                (coordinate(i, si, m_lo, m_hi), coordinate(j, sj, n_lo, n_hi))
            };
            // The caller checked that the lattice is complete.
            let Some(&k) = cells.get(&cell) else {
                return Err(orientation_error);
            };
            order.push(k);
        }
    }
    Ok(order)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grid points through an affine map with a roll of `roll_deg`, shuffled.
    fn grid_points(rows: usize, cols: usize, roll_deg: f64, shear: f64) -> (Vec<[f64; 2]>, Vec<usize>) {
        let (s, c) = roll_deg.to_radians().sin_cos();
        let mut pts = Vec::new();
        for i in 0..rows {
            for j in 0..cols {
                let (x, y) = (j as f64 * 20.0 + i as f64 * shear, i as f64 * 14.0);
                pts.push([300.0 + c * x - s * y, 200.0 + s * x + c * y]);
            }
        }
        // A fixed permutation so the order must be recovered.
        let n = pts.len();
        let perm: Vec<usize> = (0..n).map(|k| (k * 37 + 11) % n).collect();
        let shuffled: Vec<[f64; 2]> = perm.iter().map(|&k| pts[k]).collect();
        // truth[k] = index in `shuffled` of grid point k
        let mut truth = vec![0; n];
        for (pos, &k) in perm.iter().enumerate() {
            truth[k] = pos;
        }
        (shuffled, truth)
    }

    #[test]
    fn orders_rolled_and_sheared_grids() {
        for (roll, shear) in [(0.0, 0.0), (30.0, 0.0), (-25.0, 3.0), (10.0, -8.0), (5.0, 15.0)] {
            let (pts, truth) = grid_points(5, 7, roll, shear);
            let order = order_grid(&pts, 5, 7, "dots").expect("ordered");
            assert_eq!(order, truth, "roll {roll} shear {shear}");
        }
    }

    #[test]
    fn clutter_off_the_lattice_is_ignored() {
        let (mut pts, truth) = grid_points(4, 6, 5.0, 0.0);
        pts.push([311.0, 207.0]);
        pts.push([10.0, 10.0]);
        let order = order_grid(&pts, 4, 6, "dots").expect("ordered");
        assert_eq!(order, truth);
    }

    #[test]
    fn missing_points_and_wrong_sizes_are_reported() {
        let (mut pts, _) = grid_points(5, 7, 0.0, 0.0);
        let removed = pts.remove(3);
        // The hole is found and located, with or without clutter about.
        for clutter in [false, true] {
            if clutter {
                pts.push([1000.0, 1000.0]);
            }
            match order_grid(&pts, 5, 7, "dots") {
                Err(GridError::Incomplete { found: 34, lattice_rows: 5, lattice_cols: 7, missing_px, .. }) => {
                    assert!(dist(missing_px[0], removed) < 1e-6, "{missing_px:?} vs {removed:?}");
                }
                other => panic!("{other:?}"),
            }
        }
        // A whole column missing: a complete grid of another size.
        let (pts, _) = grid_points(5, 7, 0.0, 0.0);
        let cut: Vec<[f64; 2]> = pts.into_iter().filter(|p| p[0] < 300.0 + 6.0 * 20.0 - 1.0).collect();
        assert!(matches!(
            order_grid(&cut, 5, 7, "dots"),
            Err(GridError::WrongSize { found_rows: 5, found_cols: 6, .. })
        ));
        // Too few points to say more, down to none at all.
        for n in [3, 0] {
            let few: Vec<[f64; 2]> = grid_points(5, 7, 0.0, 0.0).0.into_iter().take(n).collect();
            assert!(matches!(order_grid(&few, 5, 7, "dots"), Err(GridError::TooFewPoints { found, .. }) if found == n));
        }
        let (pts, _) = grid_points(5, 7, 0.0, 0.0);
        match order_grid(&pts, 4, 7, "dots") {
            Err(GridError::WrongSize { found_rows: 5, found_cols: 7, .. }) => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn grids_near_45_degrees_are_reported() {
        // A 5 x 7 grid rolled 50 degrees: its long axis runs closer to the
        // image columns, so the image shows a 7 x 5 grid.
        let (pts, _) = grid_points(5, 7, 50.0, 0.0);
        assert!(matches!(
            order_grid(&pts, 5, 7, "dots"),
            Err(GridError::WrongSize { found_rows: 7, found_cols: 5, .. })
        ));
        // A square grid rolled 43 degrees could be labelled either way round.
        let (pts, _) = grid_points(5, 5, 43.0, 0.0);
        assert!(matches!(order_grid(&pts, 5, 5, "dots"), Err(GridError::Orientation { .. })));
        // At 60 degrees it is a square grid turned by 90 - 60 = 30 degrees: labelled.
        let (pts, _) = grid_points(5, 5, 60.0, 0.0);
        let order = order_grid(&pts, 5, 5, "dots").expect("labelled");
        // (0, 0) is the top-left point: smallest u + v.
        let first = pts[order[0]];
        assert!(pts.iter().all(|p| p[0] + p[1] >= first[0] + first[1] - 1e-9));
    }
}
