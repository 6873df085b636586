//! The height map: the organized point cloud resampled onto a regular X-Y grid
//! in millimetres, the form every quality-control measurement works on (as a
//! Gwyddion data field carries its real size and units).
//!
//! Resampling uses the cloud's organization: points know the left-camera pixel
//! they were measured at, so neighbouring pixels form quads, each quad gives
//! two triangles, and each triangle is rasterized onto the grid nodes it covers
//! with barycentric (linear) interpolation of Z. A triangle is skipped when one
//! of its edges spans a discontinuity: longer than a few pitches in X-Y
//! (occlusion, outliers) or a Z jump far above what the neighbouring edges in
//! the same direction show (a step seen without points on its wall). Holes
//! therefore stay holes (NaN) and no height is invented across them.
//!
//! Hole filling exists for display only and returns its own type with a mask
//! of filled nodes, so filled values cannot reach a measurement.

use crate::engine::warning::{Warning, WarningKind};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use crate::engine::camera_model::AffineCamera;
use crate::engine::length_unit::LengthUnit;
use crate::engine::point_cloud::PointCloud;

/// Largest map built (64 Mi nodes, 256 MiB of `f32`): far above a 2048x1536
/// camera, low enough that a wrong pitch fails with a message, not an abort.
pub const MAX_MAP_NODES: usize = 64 << 20;

/// Heights on a regular grid. Node `(col, row)` lies at
/// `x = origin_x_mm + col * pitch_mm`, `y = origin_y_mm + row * pitch_mm`;
/// `z` is row-major (X fastest, as in ISO 25178-72 files), NaN marks a hole.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightMap {
    pub width: usize,
    pub height: usize,
    pub origin_x_mm: f64,
    pub origin_y_mm: f64,
    pub pitch_mm: f64,
    /// Height of each node in `unit`; NaN = no data.
    pub z: Vec<f32>,
    /// Length unit of X, Y and Z: always mm for maps built here (results
    /// are reported in micrometres).
    pub unit: LengthUnit,
}

impl HeightMap {
    /// A map of the given values, checked for shape and pitch.
    pub fn new(
        width: usize,
        height: usize,
        origin_x_mm: f64,
        origin_y_mm: f64,
        pitch_mm: f64,
        z: Vec<f32>,
    ) -> Result<Self, AnalysisError> {
        if !(pitch_mm.is_finite() && pitch_mm > 0.0) {
            return Err(AnalysisError::InvalidPitch { pitch_mm });
        }
        if width.checked_mul(height) != Some(z.len()) {
            return Err(AnalysisError::MapShape { width, height, found: z.len() });
        }
        Ok(Self { width, height, origin_x_mm, origin_y_mm, pitch_mm, z, unit: LengthUnit::Mm })
    }

    /// A map from a grid whose X and Y increments may differ, as
    /// profilometers and some confocal instruments write them (ISO 25178-72
    /// allows it, `HeightMap` has one pitch): such a grid is resampled
    /// bilinearly onto a square grid at the finer increment, so no measured
    /// detail is thrown away, and a hole is never bridged (as [`Self::z_at`]).
    /// The second value says what was done, for the caller's warnings.
    pub fn from_rectangular_grid(
        width: usize,
        height: usize,
        origin_x_mm: f64,
        origin_y_mm: f64,
        [dx_mm, dy_mm]: [f64; 2],
        z: Vec<f32>,
    ) -> Result<(Self, Option<Warning>), AnalysisError> {
        if !(dy_mm.is_finite() && dy_mm > 0.0) {
            return Err(AnalysisError::InvalidPitch { pitch_mm: dy_mm });
        }
        if ((dx_mm - dy_mm) / dx_mm).abs() <= 1e-9 || width < 2 || height < 2 {
            let pitch_mm = if width < 2 { dy_mm } else { dx_mm };
            return Ok((Self::new(width, height, origin_x_mm, origin_y_mm, pitch_mm, z)?, None));
        }
        let source = Self::new(width, height, 0.0, 0.0, 1.0, z)?;
        let pitch_mm = dx_mm.min(dy_mm);
        // Nodes of the new grid that lie on or inside the old one (a ulp of
        // slack so that an exact multiple keeps its last node).
        let span = |n: usize, d: f64| ((n - 1) as f64 * d / pitch_mm + 1e-9).floor() as usize + 1;
        let (w, h) = (span(width, dx_mm), span(height, dy_mm));
        if w.saturating_mul(h) > MAX_MAP_NODES {
            return Err(AnalysisError::MapTooLarge { width: w, height: h, pitch_mm, max_nodes: MAX_MAP_NODES });
        }
        let mut out = vec![f32::NAN; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(row, line)| {
            let gy = row as f64 * pitch_mm / dy_mm;
            for (col, z) in line.iter_mut().enumerate() {
                *z = source.z_at(col as f64 * pitch_mm / dx_mm, gy) as f32;
            }
        });
        let note = format!(
            "X and Y increments differ ({dx_mm} mm, {dy_mm} mm): resampled bilinearly from {width}x{height} onto a \
             {w}x{h} square grid at {pitch_mm} mm (holes not bridged)"
        );
        Ok((
            Self::new(w, h, origin_x_mm, origin_y_mm, pitch_mm, out)?,
            Some(Warning::new(WarningKind::HeightMapResampled, note)),
        ))
    }

    /// X of column `col`.
    #[inline]
    pub fn x_mm(&self, col: usize) -> f64 {
        self.origin_x_mm + col as f64 * self.pitch_mm
    }

    /// Y of row `row`.
    #[inline]
    pub fn y_mm(&self, row: usize) -> f64 {
        self.origin_y_mm + row as f64 * self.pitch_mm
    }

    /// Stored height of a node (NaN for a hole or outside the map).
    #[inline]
    pub fn node_z_mm(&self, col: usize, row: usize) -> f32 {
        if col < self.width && row < self.height { self.z[row * self.width + col] } else { f32::NAN }
    }

    /// Fractional grid position `(col, row)` of a point.
    #[inline]
    pub fn grid_position(&self, x_mm: f64, y_mm: f64) -> (f64, f64) {
        ((x_mm - self.origin_x_mm) / self.pitch_mm, (y_mm - self.origin_y_mm) / self.pitch_mm)
    }

    /// Bilinear height at `(x, y)` from the (up to) four surrounding nodes.
    /// NaN outside the map or when any node with a non-zero weight is a hole:
    /// a hole is never bridged, not even partly.
    #[inline]
    pub fn z_at(&self, x_mm: f64, y_mm: f64) -> f64 {
        let (gx, gy) = self.grid_position(x_mm, y_mm);
        // Inside the map and off the nodes' lines by more than the snap, all
        // four nodes count: the general case below in a few instructions
        // (the same sums in the same order, so the same value), which matters
        // to alignment's millions of samples.
        let (cf, rf) = (gx.floor(), gy.floor());
        let (fx, fy) = (gx - cf, gy - rf);
        if fx > SPLIT_SNAP
            && fx < 1.0 - SPLIT_SNAP
            && fy > SPLIT_SNAP
            && fy < 1.0 - SPLIT_SNAP
            && cf >= 0.0
            && rf >= 0.0
            && cf + 1.0 < self.width as f64
            && rf + 1.0 < self.height as f64
        {
            let i = rf as usize * self.width + cf as usize;
            let z = |k: usize| f64::from(self.z[k]);
            let mut sum = 0.0;
            sum += (1.0 - fx) * (1.0 - fy) * z(i);
            sum += (1.0 - fx) * fy * z(i + self.width);
            sum += fx * (1.0 - fy) * z(i + 1);
            sum += fx * fy * z(i + self.width + 1);
            // A hole among the four makes the sum NaN, as below.
            return sum;
        }
        let Some((c0, fx)) = split_axis(gx, self.width) else { return f64::NAN };
        let Some((r0, fy)) = split_axis(gy, self.height) else { return f64::NAN };
        let mut sum = 0.0;
        for (dc, wx) in [(0, 1.0 - fx), (1, fx)] {
            for (dr, wy) in [(0, 1.0 - fy), (1, fy)] {
                let w = wx * wy;
                if w == 0.0 {
                    continue;
                }
                let z = f64::from(self.z[(r0 + dr) * self.width + c0 + dc]);
                if z.is_nan() {
                    return f64::NAN;
                }
                sum += w * z;
            }
        }
        sum
    }

    /// Number of nodes holding a height.
    pub fn valid_count(&self) -> usize {
        self.z.iter().filter(|z| !z.is_nan()).count()
    }

    /// Lowest and highest height, or `None` for a map without data.
    pub fn z_range_mm(&self) -> Option<(f64, f64)> {
        let mut it = self.z.iter().filter(|z| !z.is_nan()).map(|&z| f64::from(z));
        let first = it.next()?;
        Some(it.fold((first, first), |(lo, hi), z| (lo.min(z), hi.max(z))))
    }

    /// X-Y of the first and the last node.
    pub fn extent_mm(&self) -> ([f64; 2], [f64; 2]) {
        let last = |n: usize| n.saturating_sub(1);
        ([self.origin_x_mm, self.origin_y_mm], [self.x_mm(last(self.width)), self.y_mm(last(self.height))])
    }
}

/// Grid positions within this many pitches of a node are taken as on it, so
/// decimal coordinates such as 0.1 mm on a 0.01 mm grid (10.000000000000002
/// pitches in binary) do not pick up a neighbour, or its hole, with a weight
/// of 2e-15.
const SPLIT_SNAP: f64 = 1e-9;

/// Splits a fractional grid coordinate into a base node and a fraction in
/// `[0, 1]`; `None` outside `[0, n-1]`, positions within [`SPLIT_SNAP`] of a
/// node snapped onto it.
fn split_axis(g: f64, n: usize) -> Option<(usize, f64)> {
    let last = n.checked_sub(1)? as f64;
    if !(g >= -SPLIT_SNAP && g <= last + SPLIT_SNAP) {
        return None;
    }
    let g = if (g - g.round()).abs() < SPLIT_SNAP { g.round() } else { g }.clamp(0.0, last);
    if n == 1 {
        return Some((0, 0.0));
    }
    let base = (g.floor() as usize).min(n - 2);
    Some((base, g - base as f64))
}

/// How the cloud is resampled.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RasterParams {
    /// Grid pitch; `None` = estimated from the cloud's neighbour spacing. The
    /// natural choice with a calibration is [`camera_pitch_mm`] of the left camera.
    pub pitch_mm: Option<f64>,
    /// A triangle edge longer than this many pitches in X-Y (diagonals: times
    /// sqrt 2) bridges a gap, not the surface.
    pub max_edge_pitches: f64,
    /// A triangle edge whose |dZ| exceeds this multiple of the change expected
    /// from the neighbouring edges' slope (or of the noise floor) is a jump.
    pub max_jump_ratio: f64,
    /// Height changes below `max_jump_ratio` times this are never jumps, so
    /// noise on a flat surface does not cut it apart.
    pub z_noise_floor_um: f64,
}

impl Default for RasterParams {
    fn default() -> Self {
        Self { pitch_mm: None, max_edge_pitches: 3.0, max_jump_ratio: 6.0, z_noise_floor_um: 0.5 }
    }
}

/// What resampling did, for the warnings shown next to the map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterStats {
    pub points: usize,
    pub triangles: usize,
    /// Triangles dropped for an edge longer than the limit.
    pub cut_long_edge: usize,
    /// Triangles dropped for a height jump.
    pub cut_jump: usize,
    /// Points whose pixel lay outside the cloud's grid or repeated a pixel.
    pub unplaced_points: usize,
}

/// A height map and how it was made.
#[derive(Clone, Debug, PartialEq)]
pub struct Rasterized {
    pub map: HeightMap,
    pub stats: RasterStats,
}

/// Heights of `map` in micrometres, row order kept.
pub fn z_um(map: &HeightMap) -> Vec<f32> {
    let scale = map.unit.um_per_unit();
    map.z.iter().map(|&z| (f64::from(z) * scale) as f32).collect()
}

/// A map's node values with rows reversed, first row = largest Y ("north
/// up"): how image exports (TIFF, PNG) show the part as the camera sees it,
/// while the map and the X3P keep row 0 at the smallest Y.
pub fn rows_north_up(values: &[f32], width: usize) -> Vec<f32> {
    values.chunks_exact(width.max(1)).rev().flatten().copied().collect()
}

/// The camera's pixel pitch on the object, `1 / pixels_per_unit`, in mm: the
/// finest grid the data supports without inventing detail.
pub fn camera_pitch_mm(camera: &AffineCamera, unit: LengthUnit) -> Result<f64, AnalysisError> {
    let pitch_mm = unit.mm_per_unit() / camera.pixels_per_unit();
    if pitch_mm.is_finite() && pitch_mm > 0.0 { Ok(pitch_mm) } else { Err(AnalysisError::InvalidPitch { pitch_mm }) }
}

const NONE: u32 = u32::MAX;

/// Largest camera pixel grid accepted (256 Mi pixels, a 16k x 16k sensor).
pub const MAX_PIXEL_GRID: usize = 256 << 20;

/// The cloud laid out on its pixel grid, coordinates in mm.
struct PixelGrid {
    width: usize,
    height: usize,
    /// Per pixel: index of its point in the cloud (and in `xyz_mm`), or `NONE`.
    point: Vec<u32>,
    /// Every point of the cloud in mm, placed or not.
    xyz_mm: Vec<[f64; 3]>,
    sigma_mm: Vec<f64>,
    /// Points on the grid.
    placed: usize,
    unplaced: usize,
}

impl PixelGrid {
    fn build(cloud: &PointCloud) -> Result<Self, AnalysisError> {
        if cloud.pixel_uv.len() != cloud.xyz.len() {
            return Err(AnalysisError::NotOrganized { points: cloud.xyz.len(), pixels: cloud.pixel_uv.len() });
        }
        let scale = cloud.unit.mm_per_unit();
        // A cloud read from a file may not state its grid: take it from the pixels.
        let (mut width, mut height) = (cloud.grid_width, cloud.grid_height);
        if width == 0 || height == 0 {
            for uv in &cloud.pixel_uv {
                if uv[0].is_finite() && uv[1].is_finite() && uv[0] > -0.5 && uv[1] > -0.5 {
                    width = width.max(uv[0].round() as usize + 1);
                    height = height.max(uv[1].round() as usize + 1);
                }
            }
        }
        // Pixel coordinates come from files too: refuse a grid no camera has
        // before allocating it.
        if width.checked_mul(height).is_none_or(|n| n > MAX_PIXEL_GRID) {
            return Err(AnalysisError::PixelGridTooLarge { width, height, max_pixels: MAX_PIXEL_GRID });
        }
        // Every point converted in parallel (at full size these are 100 MB of
        // fresh memory), indexed as in the cloud; only the placing is serial,
        // as the first point on a pixel wins.
        let (xyz_mm, sigma_mm): (Vec<[f64; 3]>, Vec<f64>) = rayon::join(
            || cloud.xyz.par_iter().map(|p| [p[0] * scale, p[1] * scale, p[2] * scale]).collect(),
            || {
                (0..cloud.xyz.len())
                    .into_par_iter()
                    .map(|i| {
                        let s = cloud.sigma_z.get(i).map_or(f64::NAN, |&s| f64::from(s) * scale);
                        if s.is_finite() && s > 0.0 { s } else { 0.0 }
                    })
                    .collect()
            },
        );
        let mut point = vec![NONE; width * height];
        let (mut placed, mut unplaced) = (0, 0);
        for (i, (p, uv)) in cloud.xyz.iter().zip(&cloud.pixel_uv).enumerate() {
            let (u, v) = (uv[0].round(), uv[1].round());
            let finite = p.iter().all(|c| c.is_finite());
            let inside = u >= 0.0 && v >= 0.0 && (u as usize) < width && (v as usize) < height;
            if !(finite && inside) {
                unplaced += 1;
                continue;
            }
            let pixel = v as usize * width + u as usize;
            if point[pixel] != NONE {
                unplaced += 1;
                continue;
            }
            match u32::try_from(i) {
                Ok(index) if index != NONE => {
                    point[pixel] = index;
                    placed += 1;
                }
                _ => unplaced += 1,
            }
        }
        Ok(Self { width, height, point, xyz_mm, sigma_mm, placed, unplaced })
    }

    #[inline]
    fn at(&self, c: isize, r: isize) -> Option<u32> {
        if c < 0 || r < 0 || c as usize >= self.width || r as usize >= self.height {
            return None;
        }
        let p = self.point[r as usize * self.width + c as usize];
        (p != NONE).then_some(p)
    }

    /// `(|dXY|, |dZ|)` between two points. (A square root, not `hypot`:
    /// lengths of millimetres cannot overflow, and libm's `hypot` was a
    /// twentieth of a full-size height map's time.)
    #[inline]
    fn delta(&self, a: u32, b: u32) -> (f64, f64) {
        let (pa, pb) = (self.xyz_mm[a as usize], self.xyz_mm[b as usize]);
        let (dx, dy) = (pb[0] - pa[0], pb[1] - pa[1]);
        ((dx * dx + dy * dy).sqrt(), (pb[2] - pa[2]).abs())
    }

    /// The squared 3-D distance between two points.
    #[inline]
    fn distance_squared(&self, a: u32, b: u32) -> f64 {
        let (pa, pb) = (self.xyz_mm[a as usize], self.xyz_mm[b as usize]);
        (0..3).map(|k| (pb[k] - pa[k]) * (pb[k] - pa[k])).sum()
    }

    /// Slope |dZ|/|dXY| of the edge from pixel `(c, r)` to `(c+dc, r+dr)`.
    fn slope(&self, c: isize, r: isize, dc: isize, dr: isize) -> Option<f64> {
        let (a, b) = (self.at(c, r)?, self.at(c + dc, r + dr)?);
        let (dxy, dz) = self.delta(a, b);
        (dxy > 0.0).then(|| dz / dxy)
    }

    /// Median X-Y spacing of horizontal and vertical neighbours (subsampled),
    /// combined as their geometric mean: the area per pixel on the object.
    fn estimate_pitch_mm(&self) -> Option<f64> {
        let mut du = Vec::new();
        let mut dv = Vec::new();
        let stride = ((self.width * self.height) / 200_000).max(1);
        for pixel in (0..self.width * self.height).step_by(stride) {
            let (c, r) = ((pixel % self.width) as isize, (pixel / self.width) as isize);
            let Some(a) = self.at(c, r) else { continue };
            if let Some(b) = self.at(c + 1, r) {
                du.push(self.delta(a, b).0);
            }
            if let Some(b) = self.at(c, r + 1) {
                dv.push(self.delta(a, b).0);
            }
        }
        let median = |v: &mut Vec<f64>| -> Option<f64> {
            v.retain(|d| d.is_finite() && *d > 0.0);
            if v.is_empty() {
                return None;
            }
            let mid = v.len() / 2;
            Some(*v.select_nth_unstable_by(mid, f64::total_cmp).1)
        };
        match (median(&mut du), median(&mut dv)) {
            (Some(a), Some(b)) => Some((a * b).sqrt()),
            (Some(a), None) | (None, Some(a)) => Some(a),
            (None, None) => None,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum EdgeVerdict {
    /// An end point has no point.
    Missing,
    Surface,
    LongEdge,
    Jump,
}

/// Per pixel, the slope |dZ|/|dXY| of its edges to the right (`u`) and
/// down (`v`) neighbour (NaN where one is missing or they coincide in X-Y),
/// and each edge's verdict. Computed once; every quad then looks them up.
struct EdgeMaps {
    slope_u: Vec<f32>,
    slope_v: Vec<f32>,
    verdict_u: Vec<EdgeVerdict>,
    verdict_v: Vec<EdgeVerdict>,
}

struct EdgeTest<'a> {
    grid: &'a PixelGrid,
    max_side_mm: f64,
    max_jump_ratio: f64,
    floor_mm: f64,
}

impl EdgeTest<'_> {
    /// The edge `a`-`b` belongs to the surface unless it is too long in X-Y
    /// or its height change is far above `slope_ref * |dXY|` (the change the
    /// neighbouring edges predict), the noise of its two points and the floor.
    fn verdict(&self, a: u32, b: u32, slope_ref: f64, length_factor: f64) -> EdgeVerdict {
        let (dxy, dz) = self.grid.delta(a, b);
        if dxy > self.max_side_mm * length_factor {
            return EdgeVerdict::LongEdge;
        }
        let predicted = (slope_ref * dxy).max(self.floor_mm);
        // Most edges are surface by the prediction alone; the points' noise
        // can only raise the bar, so its square root is taken only where it
        // could decide (the same verdict: a product with a non-negative ratio
        // never falls as its factor grows).
        if self.max_jump_ratio >= 0.0 && dz <= self.max_jump_ratio * predicted {
            return EdgeVerdict::Surface;
        }
        let sa = self.grid.sigma_mm[a as usize];
        let sb = self.grid.sigma_mm[b as usize];
        let expected = predicted.max((sa * sa + sb * sb).sqrt());
        if dz > self.max_jump_ratio * expected { EdgeVerdict::Jump } else { EdgeVerdict::Surface }
    }

    fn edge_maps(&self) -> EdgeMaps {
        let g = self.grid;
        let (w, h) = (g.width, g.height);
        let slopes = |dc: isize, dr: isize| -> Vec<f32> {
            let mut out = vec![f32::NAN; w * h];
            out.par_chunks_mut(w.max(1)).enumerate().for_each(|(r, row)| {
                for (c, s) in row.iter_mut().enumerate() {
                    *s = g.slope(c as isize, r as isize, dc, dr).map_or(f32::NAN, |v| v as f32);
                }
            });
            out
        };
        let slope_u = slopes(1, 0);
        let slope_v = slopes(0, 1);
        let at = |map: &[f32], c: isize, r: isize| -> f32 {
            if c < 0 || r < 0 || c as usize >= w || r as usize >= h {
                f32::NAN
            } else {
                map[r as usize * w + c as usize]
            }
        };
        let max_finite = |values: &[f32]| values.iter().copied().filter(|v| v.is_finite()).reduce(f32::max);
        // Reference slope of the side from (c, r) along (dc, dr): the steeper
        // of the two sides continuing it in the same direction, or when
        // neither exists, of the sides across it at its end points. On a step
        // seen without wall points both continuations are flat and the jump
        // stands out; on a wall imaged over several pixels the continuations
        // are steep too and the wall is kept.
        let reference = |c: isize, r: isize, horizontal: bool| -> f64 {
            let (along, across) = if horizontal { (&slope_u, &slope_v) } else { (&slope_v, &slope_u) };
            let (dc, dr) = if horizontal { (1, 0) } else { (0, 1) };
            let (pc, pr) = (dr, dc);
            if let Some(s) = max_finite(&[at(along, c - dc, r - dr), at(along, c + dc, r + dr)]) {
                return f64::from(s);
            }
            let sides = [
                at(across, c, r),
                at(across, c - pc, r - pr),
                at(across, c + dc, r + dr),
                at(across, c + dc - pc, r + dr - pr),
            ];
            max_finite(&sides).map_or(0.0, f64::from)
        };
        let verdicts = |horizontal: bool| -> Vec<EdgeVerdict> {
            let (dc, dr) = if horizontal { (1, 0) } else { (0, 1) };
            let mut out = vec![EdgeVerdict::Missing; w * h];
            out.par_chunks_mut(w.max(1)).enumerate().for_each(|(r, row)| {
                let r = r as isize;
                for (c, v) in row.iter_mut().enumerate() {
                    let c = c as isize;
                    if let (Some(a), Some(b)) = (g.at(c, r), g.at(c + dc, r + dr)) {
                        *v = self.verdict(a, b, reference(c, r, horizontal), 1.0);
                    }
                }
            });
            out
        };
        let verdict_u = verdicts(true);
        let verdict_v = verdicts(false);
        EdgeMaps { slope_u, slope_v, verdict_u, verdict_v }
    }
}

/// Outcome for one candidate triangle of a quad.
enum Candidate {
    /// A corner has no point.
    Missing,
    Kept([u32; 3]),
    Cut(EdgeVerdict),
}

/// Triangles of the quad with top-left pixel `(c, r)`, pushed as point-index
/// triples; returns how many were cut for a long edge and for a jump.
fn quad_triangles(
    test: &EdgeTest<'_>,
    edges: &EdgeMaps,
    c: usize,
    r: usize,
    out: &mut Vec<[u32; 3]>,
) -> (usize, usize) {
    let g = test.grid;
    let w = g.width;
    // Corners: 0 = (c, r), 1 = (c+1, r), 2 = (c, r+1), 3 = (c+1, r+1).
    let (ci, ri) = (c as isize, r as isize);
    let corner = [g.at(ci, ri), g.at(ci + 1, ri), g.at(ci, ri + 1), g.at(ci + 1, ri + 1)];
    if corner.iter().flatten().count() < 3 {
        return (0, 0);
    }
    let (top, bottom, left, right) = (r * w + c, (r + 1) * w + c, r * w + c, r * w + c + 1);
    // Verdict per corner pair: sides from the edge maps, diagonals against
    // the steepest side of the quad.
    let mut verdict = [[EdgeVerdict::Missing; 4]; 4];
    verdict[0][1] = edges.verdict_u[top];
    verdict[2][3] = edges.verdict_u[bottom];
    verdict[0][2] = edges.verdict_v[left];
    verdict[1][3] = edges.verdict_v[right];
    let steepest_side = [edges.slope_u[top], edges.slope_u[bottom], edges.slope_v[left], edges.slope_v[right]]
        .into_iter()
        .filter(|s| s.is_finite())
        .fold(0.0f32, f32::max);
    for (i, j) in [(0, 3), (1, 2)] {
        if let (Some(a), Some(b)) = (corner[i], corner[j]) {
            verdict[i][j] = test.verdict(a, b, f64::from(steepest_side), std::f64::consts::SQRT_2);
        }
    }
    // A triangle is kept when its corners exist and its three edges are surface.
    let candidate = |t: [usize; 3]| -> Candidate {
        let mut cut = None;
        for (i, j) in [(t[0], t[1]), (t[1], t[2]), (t[0], t[2])] {
            match verdict[i.min(j)][i.max(j)] {
                EdgeVerdict::Missing => return Candidate::Missing,
                EdgeVerdict::Surface => {}
                v => cut = cut.or(Some(v)),
            }
        }
        match (cut, corner[t[0]], corner[t[1]], corner[t[2]]) {
            (Some(v), ..) => Candidate::Cut(v),
            (None, Some(a), Some(b), Some(d)) => Candidate::Kept([a, b, d]),
            _ => Candidate::Missing,
        }
    };
    // The two ways to split the quad: prefer the shorter diagonal (closer to
    // a curved surface), take the other when it keeps more triangles.
    let diagonal_squared = |i: usize, j: usize| match (corner[i], corner[j]) {
        (Some(a), Some(b)) => g.distance_squared(a, b),
        _ => f64::INFINITY,
    };
    // Written out, not `[..].map(candidate)`: the array map was not inlined
    // and took two thirds of a full-size map's quad pass.
    let split_03 = [candidate([0, 1, 3]), candidate([0, 3, 2])];
    let split_12 = [candidate([0, 1, 2]), candidate([1, 3, 2])];
    let kept = |s: &[Candidate; 2]| s.iter().filter(|t| matches!(t, Candidate::Kept(_))).count();
    let prefer_12 = diagonal_squared(1, 2) < diagonal_squared(0, 3) * (1.0 - 2e-9);
    let (first, second) = if prefer_12 { (split_12, split_03) } else { (split_03, split_12) };
    let chosen = if kept(&second) > kept(&first) { second } else { first };
    let (mut long, mut jump) = (0, 0);
    for t in chosen {
        match t {
            Candidate::Kept(tri) => out.push(tri),
            Candidate::Cut(EdgeVerdict::LongEdge) => long += 1,
            Candidate::Cut(_) => jump += 1,
            Candidate::Missing => {}
        }
    }
    (long, jump)
}

/// Resamples an organized cloud onto a regular grid (module docs: quads of
/// neighbouring pixels, discontinuity tests, barycentric rasterization).
/// Where triangles overlap in X-Y (folds at steep walls) the highest Z is
/// kept: the surface as seen from +Z.
pub fn height_map_from_cloud(cloud: &PointCloud, params: &RasterParams) -> Result<Rasterized, AnalysisError> {
    let grid = PixelGrid::build(cloud)?;
    let pitch_mm = match params.pitch_mm {
        Some(p) => p,
        None => grid.estimate_pitch_mm().unwrap_or(f64::NAN),
    };
    if !(pitch_mm.is_finite() && pitch_mm > 0.0) {
        return Err(AnalysisError::InvalidPitch { pitch_mm });
    }
    let test = EdgeTest {
        grid: &grid,
        max_side_mm: params.max_edge_pitches * pitch_mm,
        max_jump_ratio: params.max_jump_ratio,
        floor_mm: params.z_noise_floor_um * 1e-3,
    };
    let edges = test.edge_maps();
    // Rows of quads in parallel; concatenated in row order, so the result
    // does not depend on the thread count.
    let rows: Vec<(Vec<[u32; 3]>, usize, usize, usize)> = (0..grid.height.saturating_sub(1))
        .into_par_iter()
        .map(|r| {
            let mut tris = Vec::with_capacity(2 * grid.width.saturating_sub(1));
            let (mut long, mut jump, mut quads) = (0, 0, 0);
            for c in 0..grid.width.saturating_sub(1) {
                let before = tris.len();
                let (l, j) = quad_triangles(&test, &edges, c, r, &mut tris);
                if l + j > 0 || tris.len() > before {
                    quads += 1;
                }
                long += l;
                jump += j;
            }
            (tris, long, jump, quads)
        })
        .collect();
    let (long, jump, quads) = rows.iter().fold((0, 0, 0), |a, r| (a.0 + r.1, a.1 + r.2, a.2 + r.3));
    // Each row's triangles stay in their own list: concatenated they were a
    // second copy of 70 MB at full size, made on one thread.
    let triangles: Vec<Vec<[u32; 3]>> = rows.into_iter().map(|r| r.0).collect();
    let triangle_count: usize = triangles.iter().map(Vec::len).sum();
    if triangle_count == 0 {
        return Err(AnalysisError::NoSurface {
            quads,
            long_edge: long,
            jump,
            max_edge_pitches: params.max_edge_pitches,
            pitch_mm,
        });
    }
    // What only the triangles needed goes before drawing, and the points
    // become grid units in place: at full size the drawing no longer holds
    // a second copy of the cloud (70 MB) and the pixel maps beside it.
    drop(edges);
    let PixelGrid { xyz_mm, placed, unplaced, .. } = grid;
    let map = rasterize(xyz_mm, &triangles, pitch_mm)?;
    let stats = RasterStats {
        points: placed,
        triangles: triangle_count,
        cut_long_edge: long,
        cut_jump: jump,
        unplaced_points: unplaced,
    };
    Ok(Rasterized { map, stats })
}

/// Barycentric rasterization of triangles onto a grid snapped to multiples of
/// the pitch (so maps of one part line up between measurements).
fn rasterize(
    mut xyz_mm: Vec<[f64; 3]>,
    triangle_rows: &[Vec<[u32; 3]>],
    pitch_mm: f64,
) -> Result<HeightMap, AnalysisError> {
    // Batches of up to RASTER_BATCH_TRIANGLES triangles, none across two
    // rows of quads; the X-Y extent of each, then of them all.
    let batches: Vec<&[[u32; 3]]> = triangle_rows.iter().flat_map(|row| row.chunks(RASTER_BATCH_TRIANGLES)).collect();
    let extents: Vec<[[f64; 2]; 2]> = batches
        .par_iter()
        .map(|batch| {
            let mut lo = [f64::INFINITY; 2];
            let mut hi = [f64::NEG_INFINITY; 2];
            for &i in batch.iter().flatten() {
                let p = xyz_mm[i as usize];
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            [lo, hi]
        })
        .collect();
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for [blo, bhi] in &extents {
        for k in 0..2 {
            lo[k] = lo[k].min(blo[k]);
            hi[k] = hi[k].max(bhi[k]);
        }
    }
    let origin = [(lo[0] / pitch_mm).floor() * pitch_mm, (lo[1] / pitch_mm).floor() * pitch_mm];
    let nodes = |k: usize| ((hi[k] - origin[k]) / pitch_mm).floor() + 1.0;
    let (wf, hf) = (nodes(0), nodes(1));
    if wf.is_nan() || hf.is_nan() || wf * hf > MAX_MAP_NODES as f64 {
        return Err(AnalysisError::MapTooLarge {
            width: wf.min(usize::MAX as f64) as usize,
            height: hf.min(usize::MAX as f64) as usize,
            pitch_mm,
            max_nodes: MAX_MAP_NODES,
        });
    }
    let (width, height) = (wf as usize, hf as usize);
    let mut z = vec![f32::NAN; width * height];
    // Bands of map rows are drawn in parallel, each from the batches of
    // triangles whose rows reach it (a triangle across two bands is drawn
    // into each, clipped to its rows). A node keeps the highest Z whichever
    // triangle comes first, so the map is the same as drawn in one pass.
    let row_of = |y: f64| (y - origin[1]) / pitch_mm;
    // Every point in grid units (columns, rows, Z) once, so drawing a
    // triangle divides by nothing but its own determinant.
    xyz_mm.par_iter_mut().for_each(|p| *p = [(p[0] - origin[0]) / pitch_mm, row_of(p[1]), p[2]]);
    let on_grid = xyz_mm;
    let batches: Vec<(&[[u32; 3]], [f64; 2])> = batches
        .iter()
        .zip(&extents)
        .map(|(batch, [lo, hi])| (*batch, [row_of(lo[1]) - 1.0, row_of(hi[1]) + 1.0]))
        .collect();
    z.par_chunks_mut(RASTER_BAND_ROWS * width.max(1)).enumerate().for_each(|(band, cells)| {
        let rows = band * RASTER_BAND_ROWS..band * RASTER_BAND_ROWS + cells.len() / width.max(1);
        for (batch, [lo, hi]) in &batches {
            if hi < &(rows.start as f64) || lo > &(rows.end as f64) {
                continue;
            }
            for t in batch.iter() {
                draw_triangle(t.map(|i| on_grid[i as usize]), width, &rows, cells);
            }
        }
    });
    HeightMap::new(width, height, origin[0], origin[1], pitch_mm, z)
}

/// Triangles per batch of the rasterizer: a batch is a stretch of one pixel
/// row of quads, so its Y extent stays small and few bands read it.
const RASTER_BATCH_TRIANGLES: usize = 256;
/// Map rows per band the rasterizer draws on one thread.
const RASTER_BAND_ROWS: usize = 32;

/// Draws one triangle, its corners in grid units (column, row, Z), into
/// `cells`, the map rows `rows` (a band of the map `width` nodes wide):
/// barycentric interpolation at every node inside it, the highest Z kept
/// where triangles overlap.
fn draw_triangle([p0, p1, p2]: [[f64; 3]; 3], width: usize, rows: &std::ops::Range<usize>, cells: &mut [f32]) {
    // Nodes on a shared edge belong to both triangles; the tolerance keeps
    // them from falling between the two through rounding.
    const INSIDE: f64 = -1e-9;
    // Coordinates relative to p2 keep the arithmetic well scaled.
    let (a, b) = ([p0[0] - p2[0], p0[1] - p2[1]], [p1[0] - p2[0], p1[1] - p2[1]]);
    let det = (b[1]) * (a[0]) - (b[0]) * (a[1]);
    if det.abs() < 1e-12 {
        return; // no area: covers no node that its neighbours do not
    }
    let (xmin, xmax) = (p0[0].min(p1[0]).min(p2[0]), p0[0].max(p1[0]).max(p2[0]));
    let (ymin, ymax) = (p0[1].min(p1[1]).min(p2[1]), p0[1].max(p1[1]).max(p2[1]));
    let c0 = (xmin - 1e-9).ceil().max(0.0) as usize;
    let c1 = ((xmax + 1e-9).floor().max(-1.0) as isize).min(width as isize - 1);
    let r0 = ((ymin - 1e-9).ceil().max(0.0) as usize).max(rows.start);
    let r1 = ((ymax + 1e-9).floor().max(-1.0) as isize).min(rows.end as isize - 1);
    if c1 < 0 || r1 < r0 as isize {
        return;
    }
    for row in r0..=r1 as usize {
        let py = row as f64 - p2[1];
        let line = &mut cells[(row - rows.start) * width..(row - rows.start + 1) * width];
        for (col, cell) in line.iter_mut().enumerate().take(c1 as usize + 1).skip(c0) {
            let px = col as f64 - p2[0];
            // Barycentric weights of p0 and p1 (p2 gets the rest).
            let l0 = (b[1] * px - b[0] * py) / det;
            let l1 = (a[0] * py - a[1] * px) / det;
            let l2 = 1.0 - l0 - l1;
            if l0 < INSIDE || l1 < INSIDE || l2 < INSIDE {
                continue;
            }
            let zi = l0 * p0[2] + l1 * p1[2] + l2 * p2[2];
            if cell.is_nan() || zi as f32 > *cell {
                *cell = zi as f32;
            }
        }
    }
}

/// Which holes [`fill_holes_for_display`] fills.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DisplayFillParams {
    /// Holes (4-connected groups of NaN nodes) with more nodes stay empty.
    pub max_hole_nodes: usize,
    /// Also fill NaN groups touching the map border (usually outside the part).
    pub fill_border_holes: bool,
}

impl Default for DisplayFillParams {
    fn default() -> Self {
        Self { max_hole_nodes: 400, fill_border_holes: false }
    }
}

/// Heights for display with small holes filled. Deliberately not a
/// [`HeightMap`]: no measurement function accepts it, so filled values can
/// only be drawn, and `filled` tells the view which nodes to mark.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayFill {
    pub width: usize,
    pub height: usize,
    /// Measured heights plus filled ones (mm); NaN where holes stay.
    pub z_mm: Vec<f32>,
    /// True at nodes that hold a filled (not measured) value.
    pub filled: Vec<bool>,
    pub holes_filled: usize,
    pub holes_left: usize,
}

/// Fills small holes by harmonic (Laplace) interpolation from the hole's rim:
/// first layer by layer from the rim inwards, then relaxed so each filled
/// node is the mean of its four neighbours. For display only.
pub fn fill_holes_for_display(map: &HeightMap, params: &DisplayFillParams) -> DisplayFill {
    let (w, h) = (map.width, map.height);
    let mut z = map.z.clone();
    let mut filled = vec![false; z.len()];
    let mut seen = vec![false; z.len()];
    let (mut holes_filled, mut holes_left) = (0, 0);
    for start in 0..z.len() {
        if seen[start] || !map.z[start].is_nan() {
            continue;
        }
        // Flood the 4-connected NaN component.
        let mut component = vec![start];
        seen[start] = true;
        let mut touches_border = false;
        let mut k = 0;
        while k < component.len() {
            let i = component[k];
            k += 1;
            let (c, r) = (i % w, i / w);
            touches_border |= c == 0 || r == 0 || c + 1 == w || r + 1 == h;
            for n in neighbours4(c, r, w, h).into_iter().flatten() {
                if !seen[n] && map.z[n].is_nan() {
                    seen[n] = true;
                    component.push(n);
                }
            }
        }
        let has_rim = component
            .iter()
            .any(|&i| neighbours4(i % w, i / w, w, h).into_iter().flatten().any(|n| !map.z[n].is_nan()));
        if component.len() > params.max_hole_nodes || (touches_border && !params.fill_border_holes) || !has_rim {
            holes_left += 1;
            continue;
        }
        fill_component(&mut z, &mut filled, &component, w, h);
        holes_filled += 1;
    }
    DisplayFill { width: w, height: h, z_mm: z, filled, holes_filled, holes_left }
}

fn neighbours4(c: usize, r: usize, w: usize, h: usize) -> [Option<usize>; 4] {
    [
        (c > 0).then(|| r * w + c - 1),
        (c + 1 < w).then(|| r * w + c + 1),
        (r > 0).then(|| (r - 1) * w + c),
        (r + 1 < h).then(|| (r + 1) * w + c),
    ]
}

fn fill_component(z: &mut [f32], filled: &mut [bool], component: &[usize], w: usize, h: usize) {
    // Onion peeling: each pass gives the nodes touching known values the mean
    // of those values, so the relaxation starts close to its solution.
    let mut pending: Vec<usize> = component.to_vec();
    while !pending.is_empty() {
        let mut layer = Vec::new();
        for &i in &pending {
            let known: Vec<f32> =
                neighbours4(i % w, i / w, w, h).into_iter().flatten().map(|n| z[n]).filter(|v| !v.is_nan()).collect();
            if !known.is_empty() {
                layer.push((i, known.iter().sum::<f32>() / known.len() as f32));
            }
        }
        if layer.is_empty() {
            break;
        }
        for &(i, v) in &layer {
            z[i] = v;
            filled[i] = true;
        }
        pending.retain(|i| z[*i].is_nan());
    }
    // Gauss-Seidel on the discrete Laplace equation over the hole.
    let scale = component.iter().map(|&i| z[i].abs()).fold(0.0f32, f32::max).max(1e-6);
    for _ in 0..(4 * component.len()).clamp(50, 2000) {
        let mut change = 0.0f32;
        for &i in component {
            let (sum, n) = neighbours4(i % w, i / w, w, h)
                .into_iter()
                .flatten()
                .map(|n| z[n])
                .filter(|v| !v.is_nan())
                .fold((0.0f32, 0u32), |(s, n), v| (s + v, n + 1));
            if n > 0 {
                let v = sum / n as f32;
                change = change.max((v - z[i]).abs());
                z[i] = v;
            }
        }
        if change <= 1e-6 * scale {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rectangular_grid_is_resampled_at_its_finer_increment_without_bridging_holes() {
        // z = 2x + 3y mm on a 5x3 grid with dx = 0.2, dy = 0.1 mm: bilinear
        // resampling of a plane is exact.
        let (w, h, dx, dy) = (5, 3, 0.2, 0.1);
        let mut z: Vec<f32> =
            (0..h).flat_map(|r| (0..w).map(move |c| (2.0 * c as f64 * dx + 3.0 * r as f64 * dy) as f32)).collect();
        z[2 * w + 4] = f32::NAN;
        let (map, note) = HeightMap::from_rectangular_grid(w, h, 1.0, 2.0, [dx, dy], z).unwrap();
        let note = note.expect("a resampling note");
        assert!(note.kind == WarningKind::HeightMapResampled && note.message.contains("resampled"), "{note:?}");
        assert_eq!((map.width, map.height, map.pitch_mm), (9, 3, 0.1));
        for row in 0..map.height {
            for col in 0..map.width {
                let (x, y) = (col as f64 * 0.1, row as f64 * 0.1);
                let z = map.node_z_mm(col, row);
                // The hole at (0.8, 0.2) reaches the new nodes at x 0.7 and 0.8 of the last row only.
                if row == 2 && col >= 7 {
                    assert!(z.is_nan(), "node ({col}, {row}) bridged a hole");
                } else {
                    assert!((f64::from(z) - (2.0 * x + 3.0 * y)).abs() < 1e-6, "node ({col}, {row}): {z}");
                }
            }
        }
        assert_eq!((map.origin_x_mm, map.origin_y_mm), (1.0, 2.0));
        let (same, none) = HeightMap::from_rectangular_grid(2, 2, 0.0, 0.0, [0.1, 0.1], vec![0.0; 4]).unwrap();
        assert_eq!((same.pitch_mm, none), (0.1, None));
    }
    use crate::analysis::testing::{GridSpec, grid_cloud};

    fn flat_spec() -> GridSpec {
        GridSpec { width: 40, height: 30, pitch_mm: 0.01, angle_deg: 0.0, origin_mm: [0.0, 0.0] }
    }

    #[test]
    fn tilted_plane_is_reproduced_at_every_node() {
        let (a, b, c) = (0.0174, -0.0052, 0.3);
        let spec = GridSpec { angle_deg: 17.0, ..flat_spec() };
        let cloud = grid_cloud(&spec, |x, y| Some(a * x + b * y + c));
        let r = height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(0.01), ..Default::default() }).unwrap();
        let map = &r.map;
        assert_eq!(r.stats.cut_jump + r.stats.cut_long_edge, 0);
        let mut checked = 0;
        for row in 0..map.height {
            for col in 0..map.width {
                let zm = map.node_z_mm(col, row);
                if zm.is_nan() {
                    continue;
                }
                let truth = a * map.x_mm(col) + b * map.y_mm(row) + c;
                assert!((f64::from(zm) - truth).abs() < 1e-7, "node {col},{row}: {zm} vs {truth}");
                checked += 1;
            }
        }
        // A 17 deg rotated 40x30 grid at the same pitch covers ~ 39*29 node areas.
        assert!(checked > 1000, "only {checked} nodes");
    }

    #[test]
    fn drawing_in_bands_gives_the_map_of_one_pass_over_every_triangle() {
        // Rotated 23 deg, so pixel rows cross many map rows and bands; a
        // wavy surface with a step gives overlapping triangles at the fold.
        let spec = GridSpec { width: 300, height: 220, pitch_mm: 0.01, angle_deg: 23.0, origin_mm: [0.1, -0.2] };
        let cloud = grid_cloud(&spec, |x, y| {
            let wave = 0.02 * (40.0 * x).sin() * (25.0 * y).cos();
            Some(wave + if x + 0.5 * y > 1.0 { 0.05 } else { 0.0 })
        });
        let grid = PixelGrid::build(&cloud).unwrap();
        let triangles: Vec<[u32; 3]> = (0..grid.height - 1)
            .flat_map(|r| (0..grid.width - 1).map(move |c| (c, r)))
            .flat_map(|(c, r)| {
                let corner = |dc: usize, dr: usize| grid.point[(r + dr) * grid.width + c + dc];
                [[corner(0, 0), corner(1, 0), corner(1, 1)], [corner(0, 0), corner(1, 1), corner(0, 1)]]
            })
            .filter(|t| t.iter().all(|&p| p != NONE))
            .collect();
        // Far more triangles than one batch and map rows than one band.
        assert!(triangles.len() > 40 * RASTER_BATCH_TRIANGLES);
        let pitch = 0.0093;
        // In rows of quads as the map is made, of uneven lengths.
        let rows: Vec<Vec<[u32; 3]>> = triangles.chunks(1000).map(|c| c[..c.len() - c.len() / 7].to_vec()).collect();
        let triangles: Vec<[u32; 3]> = rows.concat();
        let map = rasterize(grid.xyz_mm.clone(), &rows, pitch).unwrap();
        assert!(map.height > 5 * RASTER_BAND_ROWS, "{} rows", map.height);
        let on_grid: Vec<[f64; 3]> = grid
            .xyz_mm
            .iter()
            .map(|p| [(p[0] - map.origin_x_mm) / pitch, (p[1] - map.origin_y_mm) / pitch, p[2]])
            .collect();
        let mut one_pass = vec![f32::NAN; map.width * map.height];
        for t in &triangles {
            draw_triangle(t.map(|i| on_grid[i as usize]), map.width, &(0..map.height), &mut one_pass);
        }
        assert!(one_pass.iter().filter(|z| !z.is_nan()).count() > 50_000);
        for (i, (a, b)) in map.z.iter().zip(&one_pass).enumerate() {
            assert!(a.to_bits() == b.to_bits(), "node {i}: {a} in bands, {b} in one pass");
        }
    }

    #[test]
    fn pitch_is_estimated_from_neighbour_spacing_and_taken_from_the_camera() {
        let spec = GridSpec { pitch_mm: 0.0117, ..flat_spec() };
        let cloud = grid_cloud(&spec, |_, _| Some(0.0));
        let r = height_map_from_cloud(&cloud, &RasterParams::default()).unwrap();
        assert!((r.map.pitch_mm - 0.0117).abs() < 1e-12);
        // A camera with 85.47 px/mm images 0.0117 mm per pixel.
        let k = 1.0 / 0.0117;
        let cam = AffineCamera { width: 10, height: 10, p: [[k, 0.0, 0.0, 0.0], [0.0, k, 0.0, 0.0]], distortion: None };
        assert!((camera_pitch_mm(&cam, LengthUnit::Mm).unwrap() - 0.0117).abs() < 1e-15);
        assert!((camera_pitch_mm(&cam, LengthUnit::Um).unwrap() - 0.0117e-3).abs() < 1e-18);
        assert!((camera_pitch_mm(&cam, LengthUnit::Nm).unwrap() - 0.0117e-6).abs() < 1e-21);
    }

    #[test]
    fn holes_stay_holes_and_nothing_bridges_them() {
        // A 10-pitch-wide hole through the middle of a plane.
        let spec = flat_spec();
        let cloud = grid_cloud(&spec, |x, y| {
            let d = ((x - 0.2).powi(2) + (y - 0.15).powi(2)).sqrt();
            (d > 0.05).then_some(0.1 + 0.01 * x)
        });
        let map =
            height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(0.01), ..Default::default() }).unwrap().map;
        for row in 0..map.height {
            for col in 0..map.width {
                let d = ((map.x_mm(col) - 0.2).powi(2) + (map.y_mm(row) - 0.15).powi(2)).sqrt();
                let z = map.node_z_mm(col, row);
                if d < 0.05 - 1e-9 {
                    assert!(z.is_nan(), "node inside the hole at d={d} got {z}");
                }
                if d > 0.05 + 0.02 {
                    assert!(!z.is_nan(), "node outside the hole at d={d} lost");
                }
            }
        }
        assert!(map.z_at(0.2, 0.15).is_nan());
        // Bilinear sampling never reaches across the rim.
        assert!(map.z_at(0.2 + 0.0455, 0.15).is_nan());
    }

    #[test]
    fn a_step_without_wall_points_is_cut_and_a_wall_with_points_is_kept() {
        let spec = flat_spec();
        // Step of 20 um between columns at x < 0.2 and x >= 0.2.
        let step = grid_cloud(&spec, |x, _| Some(if x < 0.2 - 1e-9 { 0.0 } else { 0.020 }));
        let r = height_map_from_cloud(&step, &RasterParams { pitch_mm: Some(0.01), ..Default::default() }).unwrap();
        assert!(r.stats.cut_jump > 0);
        let map = r.map;
        for row in 0..map.height {
            for col in 0..map.width {
                let (x, z) = (map.x_mm(col), map.node_z_mm(col, row));
                if !z.is_nan() {
                    let truth = if x < 0.2 - 1e-9 { 0.0 } else { 0.020 };
                    assert!((f64::from(z) - truth).abs() < 1e-9, "x={x} z={z}: interpolated across the step");
                }
            }
        }
        // A 45-degree wall sampled by several points is surface, not a jump.
        let ramp = grid_cloud(&spec, |x, _| Some((x - 0.1).clamp(0.0, 0.08)));
        let r = height_map_from_cloud(&ramp, &RasterParams { pitch_mm: Some(0.01), ..Default::default() }).unwrap();
        assert_eq!(r.stats.cut_jump, 0);
        assert_eq!(r.map.valid_count(), r.map.width * r.map.height);
    }

    #[test]
    fn noise_does_not_cut_a_flat_surface_apart() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 0.5e-3).unwrap();
        let spec = flat_spec();
        let mut cloud = grid_cloud(&spec, |_, _| Some(0.0));
        for (p, s) in cloud.xyz.iter_mut().zip(cloud.sigma_z.iter_mut()) {
            p[2] += noise.sample(&mut rng);
            *s = 0.5e-3;
        }
        let r = height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(0.01), ..Default::default() }).unwrap();
        assert_eq!(r.stats.cut_jump, 0, "{:?}", r.stats);
    }

    #[test]
    fn bilinear_sampling_interpolates_and_propagates_nan() {
        let z = vec![0.0, 1.0, 2.0, 3.0, f32::NAN, 5.0];
        let map = HeightMap::new(3, 2, 10.0, 20.0, 0.5, z).unwrap();
        assert_eq!(map.z_at(10.0, 20.0), 0.0);
        assert_eq!(map.z_at(10.25, 20.0), 0.5);
        assert_eq!(map.z_at(11.0, 20.0), 2.0); // on the last column
        assert!(map.z_at(10.25, 20.25).is_nan()); // (1,1) is a hole with weight 1/4
        assert_eq!(map.z_at(10.0, 20.5), 3.0); // next to the hole, weight 0
        assert!(map.z_at(9.99, 20.0).is_nan());
        assert!(map.z_at(11.01, 20.0).is_nan());
        assert!(matches!(HeightMap::new(3, 2, 0.0, 0.0, 0.5, vec![0.0; 5]), Err(AnalysisError::MapShape { .. })));
        assert!(matches!(HeightMap::new(1, 1, 0.0, 0.0, 0.0, vec![0.0]), Err(AnalysisError::InvalidPitch { .. })));
    }

    #[test]
    fn sampling_inside_the_cells_equals_the_weighted_sum_of_the_four_nodes() {
        // Heights with holes; points everywhere in and around the map,
        // on nodes, on the lines between them and inside the cells.
        let (w, h) = (7, 5);
        let z: Vec<f32> =
            (0..w * h).map(|i| if i % 11 == 4 { f32::NAN } else { (i as f32 * 0.37).sin() * 3.0 }).collect();
        let map = HeightMap::new(w, h, -1.0, 2.0, 0.25, z.clone()).unwrap();
        let mut inside = 0;
        for k in 0..4000 {
            let (gx, gy) = ((k % 80) as f64 * 0.0831 - 0.3, (k / 80) as f64 * 0.0997 - 0.2);
            let got = map.z_at(-1.0 + gx * 0.25, 2.0 + gy * 0.25);
            let (c, r) = (gx.floor(), gy.floor());
            let (fx, fy) = (gx - c, gy - r);
            if !(c >= 0.0 && r >= 0.0 && (c as usize) < w - 1 && (r as usize) < h - 1 && fx > 1e-6 && fy > 1e-6) {
                continue;
            }
            let node = |dc: usize, dr: usize| f64::from(z[(r as usize + dr) * w + c as usize + dc]);
            let expected = (1.0 - fx) * (1.0 - fy) * node(0, 0)
                + (1.0 - fx) * fy * node(0, 1)
                + fx * (1.0 - fy) * node(1, 0)
                + fx * fy * node(1, 1);
            assert_eq!(got.is_nan(), expected.is_nan(), "({gx}, {gy})");
            if !expected.is_nan() {
                assert!((got - expected).abs() < 1e-12, "({gx}, {gy}): {got} vs {expected}");
                inside += 1;
            }
        }
        assert!(inside > 1000, "{inside}");
    }

    #[test]
    fn the_first_point_on_a_pixel_wins_and_the_others_are_counted_unplaced() {
        let mut cloud = grid_cloud(&flat_spec(), |_, _| Some(0.1));
        let n = cloud.len();
        // A second point on pixel (5, 5) 1 mm higher, one off the grid, one
        // not finite.
        for (uv, z) in [([5.0, 5.0], 1.1), ([400.0, 5.0], 0.1), ([6.0, 6.0], f64::NAN)] {
            let first = (5 * 40 + 5) as usize;
            let xy = cloud.xyz[first];
            cloud.xyz.push([xy[0], xy[1], z]);
            cloud.pixel_uv.push(uv);
            cloud.sigma_z.push(0.0);
        }
        let r = height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(0.01), ..Default::default() }).unwrap();
        assert_eq!((r.stats.points, r.stats.unplaced_points), (n, 3));
        let top = r.map.z.iter().filter(|z| !z.is_nan()).fold(f32::MIN, |a, &b| a.max(b));
        assert!((f64::from(top) - 0.1).abs() < 1e-6, "the later, higher point on (5, 5) was drawn: {top}");
    }

    #[test]
    fn a_cloud_without_pixels_is_refused_with_the_counts() {
        let mut cloud = grid_cloud(&flat_spec(), |_, _| Some(0.0));
        cloud.pixel_uv.clear();
        let e = height_map_from_cloud(&cloud, &RasterParams::default()).unwrap_err();
        assert!(matches!(e, AnalysisError::NotOrganized { points: 1200, pixels: 0 }), "{e}");
        // Pixel columns that are not camera pixels (a foreign PLY's u, v).
        let mut cloud = grid_cloud(&flat_spec(), |_, _| Some(0.0));
        cloud.grid_width = 0;
        cloud.grid_height = 0;
        cloud.pixel_uv[5] = [3e9, 2e9];
        let e = height_map_from_cloud(&cloud, &RasterParams::default()).unwrap_err();
        assert!(matches!(e, AnalysisError::PixelGridTooLarge { .. }), "{e}");
    }

    #[test]
    fn display_fill_marks_what_it_fills_and_leaves_big_and_border_holes() {
        let (w, h) = (20, 20);
        let mut z: Vec<f32> = (0..w * h).map(|i| (i % w) as f32 * 0.1).collect();
        // Small interior hole (2x2), large interior hole (8x8), border hole.
        for (c, r) in [(3, 3), (4, 3), (3, 4), (4, 4)] {
            z[r * w + c] = f32::NAN;
        }
        for r in 8..16 {
            for c in 8..16 {
                z[r * w + c] = f32::NAN;
            }
        }
        z[0] = f32::NAN;
        let map = HeightMap::new(w, h, 0.0, 0.0, 1.0, z).unwrap();
        let fill = fill_holes_for_display(&map, &DisplayFillParams { max_hole_nodes: 10, fill_border_holes: false });
        assert_eq!((fill.holes_filled, fill.holes_left), (1, 2));
        assert_eq!(fill.filled.iter().filter(|f| **f).count(), 4);
        // Harmonic fill of a linear field is the linear field.
        for (c, r) in [(3, 3), (4, 3), (3, 4), (4, 4)] {
            assert!(fill.filled[r * w + c]);
            assert!((fill.z_mm[r * w + c] - c as f32 * 0.1).abs() < 1e-4);
        }
        assert!(fill.z_mm[10 * w + 10].is_nan() && fill.z_mm[0].is_nan());
        // The source map is untouched.
        assert!(map.z[3 * w + 3].is_nan());
    }
}
