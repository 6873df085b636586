//! Regions of interest on the height map (rectangle, polygon, circle, in mm)
//! and the samples they select. Selection is by node position: a node belongs
//! to a region when its X-Y lies inside or within [`BOUNDARY_MM`] of the
//! boundary; holes inside a region are counted but never used.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::height_map::HeightMap;

/// Nodes this close to a region's boundary are inside. Node positions are
/// computed in binary (0.3 mm on a 0.1 mm grid is 0.30000000000000004), so
/// a boundary typed on node positions would otherwise keep some and drop
/// others; 1 pm is far below any measurable length.
pub const BOUNDARY_MM: f64 = 1e-9;

/// A shape in the X-Y plane of the height map, in millimetres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum Region {
    /// Axis-aligned; each range may be given in either order.
    Rectangle {
        x_mm: [f64; 2],
        y_mm: [f64; 2],
    },
    /// Simple or self-intersecting polygon (even-odd rule); closed implicitly.
    Polygon {
        vertices_mm: Vec<[f64; 2]>,
    },
    Circle {
        centre_mm: [f64; 2],
        radius_mm: f64,
    },
}

/// A region with the name results and specs refer to it by.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedRegion {
    pub name: String,
    pub region: Region,
}

impl NamedRegion {
    pub fn new(name: impl Into<String>, region: Region) -> Self {
        Self { name: name.into(), region }
    }

    pub fn contains(&self, x_mm: f64, y_mm: f64) -> bool {
        self.region.contains(x_mm, y_mm)
    }

    /// Checks the shape is finite and has an area.
    pub fn validate(&self) -> Result<(), AnalysisError> {
        let bad = |reason: String| Err(AnalysisError::InvalidRegion { name: self.name.clone(), reason });
        if self.name.trim().is_empty() {
            return bad("the name is empty; give every region a name".into());
        }
        match &self.region {
            Region::Rectangle { x_mm, y_mm } => {
                if !x_mm.iter().chain(y_mm).all(|v| v.is_finite()) {
                    return bad(format!("rectangle corners x {x_mm:?} y {y_mm:?} mm are not all finite"));
                }
                if x_mm[0] == x_mm[1] || y_mm[0] == y_mm[1] {
                    return bad(format!(
                        "rectangle x {x_mm:?} y {y_mm:?} mm has no area; drag a rectangle, not a line"
                    ));
                }
            }
            Region::Polygon { vertices_mm } => {
                if vertices_mm.len() < 3 {
                    return bad(format!("a polygon needs at least 3 vertices, {} given", vertices_mm.len()));
                }
                if !vertices_mm.iter().flatten().all(|v| v.is_finite()) {
                    return bad("a polygon vertex is not finite".into());
                }
                if self.region.area_mm2() == 0.0 {
                    return bad("the polygon has no area (its vertices lie on one line)".into());
                }
            }
            Region::Circle { centre_mm, radius_mm } => {
                if !(centre_mm.iter().all(|v| v.is_finite()) && radius_mm.is_finite() && *radius_mm > 0.0) {
                    return bad(format!(
                        "circle centre {centre_mm:?} mm radius {radius_mm} mm: the centre must be finite and the \
                         radius positive"
                    ));
                }
            }
        }
        Ok(())
    }
}

impl Region {
    /// Whether `(x, y)` lies inside or on the boundary.
    pub fn contains(&self, x_mm: f64, y_mm: f64) -> bool {
        match self {
            Region::Rectangle { x_mm: xr, y_mm: yr } => {
                let e = BOUNDARY_MM;
                x_mm >= xr[0].min(xr[1]) - e
                    && x_mm <= xr[0].max(xr[1]) + e
                    && y_mm >= yr[0].min(yr[1]) - e
                    && y_mm <= yr[0].max(yr[1]) + e
            }
            Region::Circle { centre_mm, radius_mm } => {
                let (dx, dy) = (x_mm - centre_mm[0], y_mm - centre_mm[1]);
                // Squares, not `hypot`: a region's mask tests every node of
                // its window, and libm's `hypot` is several times a product.
                let reach = radius_mm + BOUNDARY_MM;
                dx * dx + dy * dy <= reach * reach
            }
            Region::Polygon { vertices_mm } => point_in_polygon(vertices_mm, x_mm, y_mm),
        }
    }

    /// Lower-left and upper-right corners of the axis-aligned bounding box.
    pub fn bounding_box(&self) -> ([f64; 2], [f64; 2]) {
        match self {
            Region::Rectangle { x_mm, y_mm } => {
                ([x_mm[0].min(x_mm[1]), y_mm[0].min(y_mm[1])], [x_mm[0].max(x_mm[1]), y_mm[0].max(y_mm[1])])
            }
            Region::Circle { centre_mm: c, radius_mm: r } => ([c[0] - r, c[1] - r], [c[0] + r, c[1] + r]),
            Region::Polygon { vertices_mm } => {
                vertices_mm.iter().fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), v| {
                    ([lo[0].min(v[0]), lo[1].min(v[1])], [hi[0].max(v[0]), hi[1].max(v[1])])
                })
            }
        }
    }

    /// Enclosed area (polygon: absolute shoelace area).
    pub fn area_mm2(&self) -> f64 {
        match self {
            Region::Rectangle { x_mm, y_mm } => (x_mm[1] - x_mm[0]).abs() * (y_mm[1] - y_mm[0]).abs(),
            Region::Circle { radius_mm, .. } => std::f64::consts::PI * radius_mm * radius_mm,
            Region::Polygon { vertices_mm: v } => {
                let n = v.len();
                let twice: f64 = (0..n).map(|i| v[i][0] * v[(i + 1) % n][1] - v[(i + 1) % n][0] * v[i][1]).sum();
                twice.abs() / 2.0
            }
        }
    }
}

/// Even-odd crossing test (W. R. Franklin's PNPOLY), plus an explicit
/// on-edge check (within [`BOUNDARY_MM`]) so boundary nodes count as inside
/// as for the other shapes.
fn point_in_polygon(v: &[[f64; 2]], x: f64, y: f64) -> bool {
    let n = v.len();
    if n < 3 {
        return false;
    }
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (v[i], v[j]);
        if on_segment(a, b, x, y) {
            return true;
        }
        if (a[1] > y) != (b[1] > y) && x < (b[0] - a[0]) * (y - a[1]) / (b[1] - a[1]) + a[0] {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Whether `(x, y)` lies within [`BOUNDARY_MM`] of the segment `a`-`b`.
/// A point that near lies within the segment's box grown by as much, which
/// settles almost every node of a mask without the projection.
fn on_segment(a: [f64; 2], b: [f64; 2], x: f64, y: f64) -> bool {
    let e = BOUNDARY_MM;
    if x < a[0].min(b[0]) - e || x > a[0].max(b[0]) + e || y < a[1].min(b[1]) - e || y > a[1].max(b[1]) + e {
        return false;
    }
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((x - a[0]) * dx + (y - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (ex, ey) = (x - a[0] - t * dx, y - a[1] - t * dy);
    ex * ex + ey * ey <= e * e
}

/// Nodes of the map inside any of the regions (their union).
pub fn region_mask(map: &HeightMap, regions: &[NamedRegion]) -> Vec<bool> {
    let mut mask = vec![false; map.width * map.height];
    if let Some(window) = NodeWindow::of_union(map, regions) {
        let inside = window.mask(map, regions);
        for (row, line) in (window.r0..=window.r1).zip(inside.chunks(window.width())) {
            mask[row * map.width + window.c0..][..line.len()].copy_from_slice(line);
        }
    }
    mask
}

/// Whether the region holds at least one node of the map (hole or not).
pub fn region_reaches_a_node(map: &HeightMap, region: &NamedRegion) -> bool {
    let (lo, hi) = region.region.bounding_box();
    let Some((c0, c1, r0, r1)) = node_window(map, lo, hi) else { return false };
    (r0..=r1).any(|row| {
        let y = map.y_mm(row);
        (c0..=c1).any(|col| region.region.contains(map.x_mm(col), y))
    })
}

/// The nodes of the map within the union of some regions' bounding boxes:
/// where a selection has to look, a few rows of a full-size map for most
/// regions.
struct NodeWindow {
    c0: usize,
    c1: usize,
    r0: usize,
    r1: usize,
}

impl NodeWindow {
    fn of_union(map: &HeightMap, regions: &[NamedRegion]) -> Option<Self> {
        regions
            .iter()
            .filter_map(|r| {
                let (lo, hi) = r.region.bounding_box();
                node_window(map, lo, hi)
            })
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1), a.2.min(b.2), a.3.max(b.3)))
            .map(|(c0, c1, r0, r1)| NodeWindow { c0, c1, r0, r1 })
    }

    fn width(&self) -> usize {
        self.c1 - self.c0 + 1
    }

    /// Row-major over the window: whether each node is inside any region.
    /// Rows in parallel (a large region on a full-size map is a million
    /// point-in-polygon tests).
    fn mask(&self, map: &HeightMap, regions: &[NamedRegion]) -> Vec<bool> {
        use rayon::prelude::*;
        let mut inside = vec![false; self.width() * (self.r1 - self.r0 + 1)];
        inside.par_chunks_mut(self.width()).enumerate().for_each(|(k, line)| {
            let y = map.y_mm(self.r0 + k);
            for (j, node) in line.iter_mut().enumerate() {
                let x = map.x_mm(self.c0 + j);
                *node = regions.iter().any(|r| r.region.contains(x, y));
            }
        });
        inside
    }
}

/// Column and row ranges of the nodes within a box, `None` if it misses the map.
pub(crate) fn node_window(map: &HeightMap, lo: [f64; 2], hi: [f64; 2]) -> Option<(usize, usize, usize, usize)> {
    let (gx0, gy0) = map.grid_position(lo[0], lo[1]);
    let (gx1, gy1) = map.grid_position(hi[0], hi[1]);
    let range = |g0: f64, g1: f64, n: usize| -> Option<(usize, usize)> {
        // The window is widened by the boundary slack (and rounding) so no node
        // that `contains` accepts is missed.
        let slack = BOUNDARY_MM / map.pitch_mm + 1e-9;
        let a = (g0 - slack).ceil().max(0.0);
        let b = (g1 + slack).floor().min(n as f64 - 1.0);
        (a <= b && n > 0).then_some((a as usize, b as usize))
    };
    let (c0, c1) = range(gx0, gx1, map.width)?;
    let (r0, r1) = range(gy0, gy1, map.height)?;
    Some((c0, c1, r0, r1))
}

/// The valid samples selected by a set of regions, in f64 mm.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RegionSamples {
    /// Names of the regions joined with '+', for messages and tables.
    pub label: String,
    pub points_mm: Vec<[f64; 3]>,
    /// Nodes inside the regions, holes included.
    pub nodes_inside: usize,
}

/// Valid (non-hole) samples inside the union of the regions, in map order.
pub fn region_samples(map: &HeightMap, regions: &[NamedRegion]) -> RegionSamples {
    let mut points_mm = Vec::new();
    let mut nodes_inside = 0;
    // Only the window the regions reach is looked at (a small region on a
    // full-size map is a few hundred of its 3 M nodes).
    if let Some(window) = NodeWindow::of_union(map, regions) {
        let inside = window.mask(map, regions);
        for (row, line) in (window.r0..=window.r1).zip(inside.chunks(window.width())) {
            for (col, _) in (window.c0..).zip(line).filter(|(_, m)| **m) {
                nodes_inside += 1;
                let z = map.z[row * map.width + col];
                if !z.is_nan() {
                    points_mm.push([map.x_mm(col), map.y_mm(row), f64::from(z)]);
                }
            }
        }
    }
    RegionSamples { label: label(regions), points_mm, nodes_inside }
}

/// The window of map nodes the union of some regions reaches, with which
/// of them lie inside: for work on the nodes' grid neighbourhoods (the
/// noise's correlation, a Monte Carlo's window).
#[derive(Clone, Debug, PartialEq)]
pub struct RegionGrid {
    /// First column and row of the window on the map.
    pub c0: usize,
    pub r0: usize,
    pub width: usize,
    pub height: usize,
    /// Row-major over the window.
    pub inside: Vec<bool>,
}

impl RegionGrid {
    /// `[c0, c1, r0, r1]`, inclusive.
    pub fn window(&self) -> [usize; 4] {
        [self.c0, self.c0 + self.width - 1, self.r0, self.r0 + self.height - 1]
    }
}

/// [`RegionGrid`] of `regions` on `map`; `None` if they miss it.
pub fn region_grid(map: &HeightMap, regions: &[NamedRegion]) -> Option<RegionGrid> {
    let window = NodeWindow::of_union(map, regions)?;
    let inside = window.mask(map, regions);
    Some(RegionGrid { c0: window.c0, r0: window.r0, width: window.width(), height: window.r1 - window.r0 + 1, inside })
}

/// Region names joined with '+'.
pub fn label(regions: &[NamedRegion]) -> String {
    regions.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join("+")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> HeightMap {
        let mut z = vec![0.0f32; 11 * 11];
        z[5 * 11 + 5] = f32::NAN;
        HeightMap::new(11, 11, 0.0, 0.0, 0.1, z).unwrap()
    }

    #[test]
    fn shapes_contain_what_they_should() {
        let rect = Region::Rectangle { x_mm: [0.5, 0.2], y_mm: [0.1, 0.3] };
        assert!(rect.contains(0.2, 0.1) && rect.contains(0.35, 0.2) && !rect.contains(0.51, 0.2));
        let circle = Region::Circle { centre_mm: [0.5, 0.5], radius_mm: 0.2 };
        assert!(circle.contains(0.7, 0.5) && !circle.contains(0.65, 0.65));
        // An L-shaped polygon: the notch is outside.
        let l = Region::Polygon {
            vertices_mm: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 0.4], [0.4, 0.4], [0.4, 1.0], [0.0, 1.0]],
        };
        assert!(l.contains(0.2, 0.8) && l.contains(0.8, 0.2) && !l.contains(0.8, 0.8));
        assert!(l.contains(0.4, 0.7), "a point on an edge is inside");
        assert!((l.area_mm2() - 0.64).abs() < 1e-12);
    }

    #[test]
    fn masks_and_samples_count_nodes_and_skip_holes() {
        let m = map();
        let regions = [NamedRegion::new("c", Region::Circle { centre_mm: [0.5, 0.5], radius_mm: 0.1 })];
        let mask = region_mask(&m, &regions);
        // Centre node plus its four neighbours at exactly one pitch.
        assert_eq!(mask.iter().filter(|v| **v).count(), 5);
        let s = region_samples(&m, &regions);
        assert_eq!((s.nodes_inside, s.points_mm.len()), (5, 4));
        // Union of two overlapping rectangles counts shared nodes once.
        let two = [
            NamedRegion::new("a", Region::Rectangle { x_mm: [0.0, 0.2], y_mm: [0.0, 0.2] }),
            NamedRegion::new("b", Region::Rectangle { x_mm: [0.1, 0.3], y_mm: [0.0, 0.2] }),
        ];
        let s = region_samples(&m, &two);
        assert_eq!(s.nodes_inside, 4 * 3);
        assert_eq!(s.label, "a+b");
        // A region off the map selects nothing.
        let off = [NamedRegion::new("off", Region::Circle { centre_mm: [5.0, 5.0], radius_mm: 0.5 })];
        assert_eq!(region_samples(&m, &off).nodes_inside, 0);
        assert!(!region_reaches_a_node(&m, &off[0]));
        assert!(region_reaches_a_node(&m, &regions[0]));
        // Between nodes: its box is on the map, no node is inside.
        let between = NamedRegion::new("gap", Region::Circle { centre_mm: [0.45, 0.45], radius_mm: 0.02 });
        assert!(!region_reaches_a_node(&m, &between));
        assert!(region_mask(&m, std::slice::from_ref(&between)).iter().all(|v| !v));
    }

    /// The selection looks only at the window the regions reach: the same
    /// nodes, in map order, as testing every node of the map.
    #[test]
    fn samples_are_those_of_every_node_tested_in_map_order() {
        let (w, h) = (37, 23);
        let z: Vec<f32> = (0..w * h).map(|i| if i % 7 == 3 { f32::NAN } else { i as f32 * 0.01 }).collect();
        let m = HeightMap::new(w, h, -1.0, 0.5, 0.05, z).unwrap();
        let regions = [
            NamedRegion::new("c", Region::Circle { centre_mm: [-0.4, 0.9], radius_mm: 0.22 }),
            NamedRegion::new(
                "p",
                Region::Polygon { vertices_mm: vec![[-0.2, 0.6], [0.5, 0.75], [0.1, 1.4], [-0.3, 1.1]] },
            ),
            NamedRegion::new("r", Region::Rectangle { x_mm: [0.3, 0.62], y_mm: [1.3, 0.95] }),
        ];
        let mut expected = Vec::new();
        let mut inside = 0;
        for i in 0..w * h {
            let (x, y) = (m.x_mm(i % w), m.y_mm(i / w));
            if regions.iter().any(|r| r.region.contains(x, y)) {
                inside += 1;
                if !m.z[i].is_nan() {
                    expected.push([x, y, f64::from(m.z[i])]);
                }
            }
        }
        let s = region_samples(&m, &regions);
        assert!(inside > 50, "the regions hold {inside} nodes");
        assert_eq!((s.nodes_inside, &s.points_mm), (inside, &expected));
        let mask = region_mask(&m, &regions);
        assert_eq!(mask.iter().filter(|v| **v).count(), inside);
        for (i, &v) in mask.iter().enumerate() {
            assert_eq!(v, regions.iter().any(|r| r.region.contains(m.x_mm(i % w), m.y_mm(i / w))), "node {i}");
        }
    }

    #[test]
    fn validation_names_the_region_and_the_problem() {
        let e = NamedRegion::new("land 3", Region::Circle { centre_mm: [0.0, 0.0], radius_mm: -1.0 }).validate();
        let msg = e.unwrap_err().to_string();
        assert!(msg.contains("land 3") && msg.contains("radius"), "{msg}");
        let line = NamedRegion::new("p", Region::Polygon { vertices_mm: vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]] });
        let msg = line.validate().unwrap_err().to_string();
        assert!(msg.starts_with("region 'p':"), "{msg}");
        assert!(msg.contains("no area"), "{msg}");
        let ok = NamedRegion::new("r", Region::Rectangle { x_mm: [0.0, 1.0], y_mm: [1.0, 0.0] });
        assert!(ok.validate().is_ok());
    }

    #[test]
    fn regions_round_trip_through_json() {
        let r = NamedRegion::new("base", Region::Polygon { vertices_mm: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]] });
        let text = serde_json::to_string(&r).unwrap();
        assert!(text.contains("\"shape\":\"polygon\""), "{text}");
        assert_eq!(serde_json::from_str::<NamedRegion>(&text).unwrap(), r);
        let typo = r#"{"name":"x","region":{"shape":"circle","centre_mm":[0,0],"raduis_mm":1}}"#;
        let msg = serde_json::from_str::<NamedRegion>(typo).unwrap_err().to_string();
        assert!(msg.contains("raduis_mm"), "the misspelt field is named: {msg}");
    }
}
