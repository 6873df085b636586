//! The cloud as the GPU and the picker see it, with no GUI types: one compact
//! record per point (f32 offset from the cloud centre plus the one scalar the
//! colour mode shows), the colour-map lookup table the shader reads, the
//! model-to-screen transform shared by the shader and the picker, and CPU
//! picking over the projected points.

use bytemuck::{Pod, Zeroable};
use nalgebra::{Matrix4, Point3};
use rayon::prelude::*;

use crate::engine::point_cloud::PointCloud;
use crate::io::colormap::{Colormap, INVALID_RGBA, ValueRange};

use super::camera::{OrbitCamera, Projection, Viewport};

/// What the colour of a point shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum ColorBy {
    /// Height Z (µm): the measurement itself.
    #[default]
    Height,
    /// The fringe set whose phase located the point (Alg. 3's source map).
    SourceSet,
    /// Fringe modulation B of that set (grey levels): how trustworthy the phase is.
    Modulation,
    /// Mean fringe intensity A (grey levels): the part's texture.
    Intensity,
}

impl ColorBy {
    pub const ALL: [ColorBy; 4] = [ColorBy::Height, ColorBy::SourceSet, ColorBy::Modulation, ColorBy::Intensity];

    pub fn name(self) -> &'static str {
        match self {
            ColorBy::Height => "height",
            ColorBy::SourceSet => "source set",
            ColorBy::Modulation => "modulation",
            ColorBy::Intensity => "intensity (texture)",
        }
    }

    pub fn tooltip(self) -> &'static str {
        match self {
            ColorBy::Height => "Colour by height Z in micrometres.",
            ColorBy::SourceSet => "Colour by the fringe set that supplied each point's phase (HDR fusion).",
            ColorBy::Modulation => "Colour by fringe modulation B: low values mean noisy, less trustworthy points.",
            ColorBy::Intensity => "Colour by mean fringe intensity A: the part's texture in grey.",
        }
    }

    /// Whether values are categories (no range, no colour-map choice).
    pub fn is_categorical(self) -> bool {
        self == ColorBy::SourceSet
    }
}

/// Scalar of a point without a value (shaders do not handle NaN portably).
pub const NO_VALUE: f32 = -f32::MAX;

/// One point as uploaded: 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuPoint {
    /// Position minus the cloud centre, in the cloud's unit.
    pub offset: [f32; 3],
    /// The value the colour mode shows ([`NO_VALUE`] if none).
    pub scalar: f32,
}

/// A cloud packed for drawing and picking; point `i` is the cloud's point `i`.
#[derive(Clone, Debug)]
pub struct PackedCloud {
    /// The cloud's centre (its unit): scene space is the offset from here.
    pub center: [f64; 3],
    pub points: Vec<GpuPoint>,
    /// Bounds of the finite offsets (unscaled); zero for an empty cloud.
    pub lo: [f32; 3],
    pub hi: [f32; 3],
    /// Points per category (index = scalar) for categorical modes, else empty.
    pub category_counts: Vec<usize>,
    /// Bounds of the finite offsets of each run of [`PICK_CHUNK`] points
    /// (empty boxes have lo > hi). The cloud is organized by pixel, so a run is
    /// a compact piece of surface: picking skips every run whose box misses
    /// the cursor.
    pub chunk_bounds: Vec<([f32; 3], [f32; 3])>,
    /// Typical distance between neighbouring points in X-Y (scene units),
    /// from the area they cover; 0 when unknown.
    pub spacing: f32,
}

impl PackedCloud {
    /// Packs `cloud` for `color_by`, about `center` if given (keeping the
    /// previous result's centre keeps the view steady when a re-run changes
    /// the cloud's extent a little), else about the middle of its bounds.
    pub fn pack(cloud: &PointCloud, color_by: ColorBy, center: Option<[f64; 3]>) -> Self {
        let center = center
            .or_else(|| finite_bounds(&cloud.xyz).map(|(lo, hi)| std::array::from_fn(|i| (lo[i] + hi[i]) / 2.0)))
            .unwrap_or([0.0; 3]);
        let z_scale = cloud.um_per_unit();
        let points: Vec<GpuPoint> = (0..cloud.len())
            .into_par_iter()
            .map(|i| {
                let p = cloud.xyz[i];
                let scalar = match color_by {
                    ColorBy::Height => (p[2] * z_scale) as f32,
                    ColorBy::SourceSet => cloud.source_set.get(i).map_or(f32::NAN, |&s| f32::from(s)),
                    ColorBy::Modulation => cloud.modulation_dn.get(i).copied().unwrap_or(f32::NAN),
                    ColorBy::Intensity => cloud.intensity_dn.get(i).copied().unwrap_or(f32::NAN),
                };
                GpuPoint {
                    offset: std::array::from_fn(|k| (p[k] - center[k]) as f32),
                    scalar: if scalar.is_finite() { scalar } else { NO_VALUE },
                }
            })
            .collect();
        let category_counts = if color_by.is_categorical() {
            points
                .par_iter()
                .fold(
                    || vec![0usize; LUT_ENTRIES],
                    |mut counts, p| {
                        if p.scalar >= 0.0 {
                            counts[(p.scalar as usize).min(LUT_ENTRIES - 1)] += 1;
                        }
                        counts
                    },
                )
                .reduce(|| vec![0usize; LUT_ENTRIES], |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect())
        } else {
            Vec::new()
        };
        Self::from_points(center, points, category_counts)
    }

    /// A packed cloud of `points` about `center`, with its bounds and run boxes.
    pub fn from_points(center: [f64; 3], points: Vec<GpuPoint>, category_counts: Vec<usize>) -> Self {
        let chunk_bounds: Vec<([f32; 3], [f32; 3])> = points.par_chunks(PICK_CHUNK).map(offset_bounds).collect();
        let (lo, hi) = chunk_bounds.iter().fold(EMPTY_BOX, |(lo, hi), (a, b)| {
            (std::array::from_fn(|i| lo[i].min(a[i])), std::array::from_fn(|i| hi[i].max(b[i])))
        });
        let (lo, hi) = if lo[0] <= hi[0] { (lo, hi) } else { ([0.0; 3], [0.0; 3]) };
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        let spacing = if points.is_empty() { 0.0 } else { (area / points.len() as f32).sqrt() };
        Self { center, points, lo, hi, category_counts, chunk_bounds, spacing }
    }

    /// Coarser copies for zoomed-out views: level `l` (1..=[`LOD_LEVELS`])
    /// keeps the points measured at pixels whose u and v are multiples of
    /// `2^l`, a quarter of the previous level, spread evenly over the surface.
    pub fn coarse_levels(&self, cloud: &PointCloud) -> Vec<Vec<GpuPoint>> {
        if cloud.pixel_uv.len() != self.points.len() {
            return Vec::new();
        }
        (1..=LOD_LEVELS)
            .map(|level| {
                let step = 1i64 << level;
                let on_grid = |c: f32| (c.round() as i64).rem_euclid(step) == 0;
                cloud
                    .pixel_uv
                    .par_iter()
                    .zip(self.points.par_iter())
                    .filter(|(uv, _)| on_grid(uv[0]) && on_grid(uv[1]))
                    .map(|(_, p)| *p)
                    .collect()
            })
            .collect()
    }

    /// Scene-space bounds for a Z exaggeration of `z_scale`.
    pub fn scene_bounds(&self, z_scale: f64) -> ([f64; 3], [f64; 3]) {
        let scale = [1.0, 1.0, z_scale];
        (
            std::array::from_fn(|i| f64::from(self.lo[i]) * scale[i]),
            std::array::from_fn(|i| f64::from(self.hi[i]) * scale[i]),
        )
    }

    /// Scene-space position of point `index`.
    pub fn scene_point(&self, index: usize, z_scale: f64) -> Option<Point3<f64>> {
        let p = self.points.get(index)?.offset;
        Some(Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]) * z_scale))
    }
}

const EMPTY_BOX: ([f32; 3], [f32; 3]) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);

/// Bounds of the finite offsets of `points` (lo > hi when there are none).
fn offset_bounds(points: &[GpuPoint]) -> ([f32; 3], [f32; 3]) {
    points.iter().filter(|p| p.offset.iter().all(|v| v.is_finite())).fold(EMPTY_BOX, |(lo, hi), p| {
        (std::array::from_fn(|i| lo[i].min(p.offset[i])), std::array::from_fn(|i| hi[i].max(p.offset[i])))
    })
}

/// Bounds of the finite points, in parallel (3 million points in a few ms).
fn finite_bounds(xyz: &[[f64; 3]]) -> Option<([f64; 3], [f64; 3])> {
    let (lo, hi) = xyz
        .par_iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .fold(
            || ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
            |(lo, hi), p| (std::array::from_fn(|i| lo[i].min(p[i])), std::array::from_fn(|i| hi[i].max(p[i]))),
        )
        .reduce(
            || ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
            |a, b| (std::array::from_fn(|i| a.0[i].min(b.0[i])), std::array::from_fn(|i| a.1[i].max(b.1[i]))),
        );
    (lo[0] <= hi[0]).then_some((lo, hi))
}

/// Coarse levels besides the full cloud (1/4, 1/16, 1/64 of the points).
pub const LOD_LEVELS: usize = 3;

/// The coarsest level that still covers the surface without holes: a level
/// multiplies the on-screen spacing of neighbouring points (`spacing_px`,
/// physical pixels) by 2 per step, and splats of `point_size_px` close gaps
/// up to half their size (single-pixel dots need two points per pixel).
/// Drawing 3 million points when a few hundred thousand cover every pixel
/// only costs time, which matters most on software renderers.
pub fn lod_level(spacing_px: f32, point_size_px: f32) -> usize {
    if !(spacing_px > 0.0) {
        return 0;
    }
    let limit = if point_size_px <= 1.0 { 0.5 } else { 0.5 * point_size_px };
    (0..=LOD_LEVELS).rev().find(|&level| spacing_px * (1u32 << level) as f32 <= limit).unwrap_or(0)
}

/// Entries of the colour lookup table.
pub const LUT_ENTRIES: usize = 256;

/// The lookup table the shader indexes: a continuous map's 256 colours
/// (io's tables, as in the 2D views and the PNG exports), or the categorical
/// set colours at the set's index.
pub fn lut_rgba(color_by: ColorBy, height_map: Colormap) -> Vec<[u8; 4]> {
    let unit = ValueRange::new(0.0, 1.0);
    (0..LUT_ENTRIES)
        .map(|i| {
            let t = i as f32 / (LUT_ENTRIES - 1) as f32;
            let rgba = match color_by {
                ColorBy::Height => height_map.rgba(t, unit),
                ColorBy::Modulation => Colormap::Viridis.rgba(t, unit),
                ColorBy::Intensity => Colormap::Gray.rgba(t, unit),
                ColorBy::SourceSet => Colormap::SourceSet.rgba(i as f32, unit),
            };
            if rgba == INVALID_RGBA { [0, 0, 0, 255] } else { rgba }
        })
        .collect()
}

/// The scalar values at the first and last table entries: the operator's
/// range for continuous maps, the entry index itself for categories.
pub fn lut_span(color_by: ColorBy, range: (f32, f32)) -> (f32, f32) {
    if color_by.is_categorical() { (0.0, (LUT_ENTRIES - 1) as f32) } else { range }
}

/// Model-to-screen mapping of packed points for one frame: the same numbers
/// the shader gets, so what the picker finds is what is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenTransform {
    /// Offset (unscaled) to clip space, row-major: Z exaggeration, view and projection.
    pub clip_rows: [[f32; 4]; 4],
    /// Offset to view depth (distance in front of the eye, scene units).
    pub depth_row: [f32; 4],
    /// Scene units per screen unit at depth d: `a * d + b`.
    pub screen_unit: [f32; 2],
    pub viewport: Viewport,
    /// Depth of the scene's nearest part (the near clip plane).
    pub near_depth: f32,
}

impl ScreenTransform {
    pub fn new(camera: &OrbitCamera, z_scale: f64, viewport: Viewport) -> Self {
        let model = Matrix4::new_nonuniform_scaling(&nalgebra::Vector3::new(1.0, 1.0, z_scale));
        let view = camera.view_matrix() * model;
        let clip = camera.projection_matrix(viewport.aspect()) * view;
        let rows =
            |m: &Matrix4<f64>| -> [[f32; 4]; 4] { std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)] as f32)) };
        // View space looks down -z, so depth is minus its z row.
        let depth_row = std::array::from_fn(|c| -view[(2, c)] as f32);
        let height = viewport.size[1];
        let screen_unit = match camera.projection {
            Projection::Perspective => [camera.scene_per_screen(1.0, height) as f32, 0.0],
            Projection::Orthographic => [0.0, camera.scene_per_screen(1.0, height) as f32],
        };
        let near_depth = camera.near_far().0.max(0.0) as f32;
        Self { clip_rows: rows(&clip), depth_row, screen_unit, viewport, near_depth }
    }

    /// Screen position and depth of a packed offset; `None` outside the clip volume's depth range.
    #[inline]
    pub fn project(&self, p: [f32; 3]) -> Option<([f32; 2], f32)> {
        let row = |r: &[f32; 4]| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3];
        let [rx, ry, rz, rw] = &self.clip_rows;
        let w = row(rw);
        let z = row(rz);
        if !(w > 0.0 && z >= 0.0 && z <= w) {
            return None;
        }
        Some((self.ndc_to_screen([row(rx) / w, row(ry) / w]), row(&self.depth_row)))
    }

    /// Scene units per screen unit at `depth`.
    pub fn scene_per_screen(&self, depth: f32) -> f32 {
        self.screen_unit[0] * depth + self.screen_unit[1]
    }
}

/// A picked point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pick {
    /// Index in the cloud.
    pub index: usize,
    /// From the cursor, in screen units.
    pub screen_distance: f32,
    /// In front of the eye, scene units.
    pub depth: f32,
}

/// Points per run with its own bounding box (see [`PackedCloud::chunk_bounds`]).
pub const PICK_CHUNK: usize = 512;

impl ScreenTransform {
    /// Whether the screen square of half-size `radius` about `cursor` may
    /// meet the projection of the box `(lo, hi)`: false only when all eight
    /// corners are in front of the eye and their screen bounds miss the square
    /// (the projection of a box in front of the eye lies within its corners' hull).
    fn box_may_cover(&self, (lo, hi): &([f32; 3], [f32; 3]), cursor: [f32; 2], radius: f32) -> bool {
        if !(lo[0] <= hi[0]) {
            return false;
        }
        let (mut min, mut max) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for corner in 0..8 {
            let p = [
                if corner & 1 == 0 { lo[0] } else { hi[0] },
                if corner & 2 == 0 { lo[1] } else { hi[1] },
                if corner & 4 == 0 { lo[2] } else { hi[2] },
            ];
            let row = |r: &[f32; 4]| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3];
            let w = row(&self.clip_rows[3]);
            if !(w > 0.0) {
                return true;
            }
            let s = self.ndc_to_screen([row(&self.clip_rows[0]) / w, row(&self.clip_rows[1]) / w]);
            for k in 0..2 {
                min[k] = min[k].min(s[k]);
                max[k] = max[k].max(s[k]);
            }
        }
        (0..2).all(|k| min[k] <= cursor[k] + radius && max[k] >= cursor[k] - radius)
    }

    fn ndc_to_screen(&self, [x, y]: [f32; 2]) -> [f32; 2] {
        let vp = &self.viewport;
        [vp.min[0] as f32 + (x + 1.0) * 0.5 * vp.size[0] as f32, vp.min[1] as f32 + (1.0 - y) * 0.5 * vp.size[1] as f32]
    }
}

/// The point drawn under `cursor`: among the points within `radius` (screen
/// units) of it, those on the front surface (no deeper than the nearest one
/// by two radii's worth of scene at that depth), and of those the closest to
/// the cursor. Runs of points whose box misses the cursor are skipped, so a
/// pick over 3 million points tests only the few thousand near the cursor.
pub fn pick(packed: &PackedCloud, transform: &ScreenTransform, cursor: [f32; 2], radius: f32) -> Option<Pick> {
    let r2 = radius * radius;
    let candidates: Vec<Pick> = packed
        .points
        .par_chunks(PICK_CHUNK)
        .zip(packed.chunk_bounds.par_iter())
        .enumerate()
        .filter(|(_, (_, bounds))| transform.box_may_cover(bounds, cursor, radius))
        .map(|(chunk_index, (chunk, _))| {
            let mut found = Vec::new();
            for (i, p) in chunk.iter().enumerate() {
                let Some((s, depth)) = transform.project(p.offset) else {
                    continue;
                };
                let (dx, dy) = (s[0] - cursor[0], s[1] - cursor[1]);
                let d2 = dx * dx + dy * dy;
                if d2 <= r2 {
                    found.push(Pick { index: chunk_index * PICK_CHUNK + i, screen_distance: d2.sqrt(), depth });
                }
            }
            found
        })
        .reduce(Vec::new, |mut a, mut b| {
            a.append(&mut b);
            a
        });
    let front = candidates.iter().map(|c| c.depth).fold(f32::INFINITY, f32::min);
    if !front.is_finite() {
        return None;
    }
    let tolerance = 2.0 * radius * transform.scene_per_screen(front);
    candidates
        .into_iter()
        .filter(|c| c.depth <= front + tolerance)
        .min_by(|a, b| a.screen_distance.total_cmp(&b.screen_distance).then(a.depth.total_cmp(&b.depth)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::views::cloud::camera::ViewPreset;

    /// A 101 x 51 grid at 0.1 mm pitch, z = 0 except a 0.2 mm bump on one column.
    fn grid_cloud() -> PointCloud {
        let mut cloud = PointCloud {
            unit: crate::engine::length_unit::LengthUnit::Mm,
            grid_width: 101,
            grid_height: 51,
            ..PointCloud::default()
        };
        for v in 0..51 {
            for u in 0..101 {
                let z = if u == 70 { 0.2 } else { 0.0 };
                cloud.xyz.push([u as f64 * 0.1 + 100.0, -(v as f64) * 0.1, z]);
                cloud.pixel_uv.push([u as f32, v as f32]);
                cloud.source_set.push((u % 3) as i8);
                cloud.source_period_px.push(20.0);
                cloud.modulation_dn.push(if u == 0 { f32::NAN } else { u as f32 });
                cloud.sigma_z.push(0.001);
                cloud.intensity_dn.push(v as f32);
            }
        }
        cloud
    }

    #[test]
    fn packing_keeps_order_centres_and_picks_the_scalar() {
        let cloud = grid_cloud();
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, None);
        assert_eq!(packed.points.len(), cloud.len());
        assert_eq!(packed.center, [105.0, -2.5, 0.1]);
        assert_eq!(packed.lo, [-5.0, -2.5, -0.1]);
        assert_eq!(packed.hi, [5.0, 2.5, 0.1]);
        let i = 3 * 101 + 70;
        assert!((packed.points[i].offset[0] - 2.0).abs() < 1e-5);
        assert_eq!(packed.points[i].scalar, 200.0, "height in micrometres");
        let by_set = PackedCloud::pack(&cloud, ColorBy::SourceSet, Some(packed.center));
        assert_eq!(by_set.points[i].scalar, 1.0);
        assert_eq!(&by_set.category_counts[..4], &[34 * 51, 34 * 51, 33 * 51, 0]);
        assert_eq!(by_set.points[i].offset, packed.points[i].offset);
        let by_modulation = PackedCloud::pack(&cloud, ColorBy::Modulation, None);
        assert_eq!(by_modulation.points[0].scalar, NO_VALUE, "NaN becomes the no-value mark");
        assert_eq!(PackedCloud::pack(&cloud, ColorBy::Intensity, None).points[i].scalar, 3.0);
        let empty = PackedCloud::pack(&PointCloud::default(), ColorBy::Height, None);
        assert!(empty.points.is_empty());
        assert_eq!((empty.lo, empty.hi), ([0.0; 3], [0.0; 3]));
    }

    #[test]
    fn lookup_tables_follow_io_colormaps() {
        let lut = lut_rgba(ColorBy::Height, Colormap::Turbo);
        assert_eq!(lut.len(), LUT_ENTRIES);
        assert_eq!(lut[0], Colormap::Turbo.rgba(0.0, ValueRange::new(0.0, 1.0)));
        assert_eq!(lut[255], Colormap::Turbo.rgba(1.0, ValueRange::new(0.0, 1.0)));
        let sets = lut_rgba(ColorBy::SourceSet, Colormap::Turbo);
        for (s, rgba) in sets.iter().enumerate().take(4) {
            assert_eq!(*rgba, crate::io::colormap::set_rgba(s));
        }
        assert_eq!(lut_span(ColorBy::SourceSet, (3.0, 4.0)), (0.0, 255.0));
        assert_eq!(lut_span(ColorBy::Modulation, (3.0, 4.0)), (3.0, 4.0));
    }

    fn top_view(packed: &PackedCloud, z_scale: f64, viewport: Viewport) -> (OrbitCamera, ScreenTransform) {
        let (lo, hi) = packed.scene_bounds(z_scale);
        let camera = OrbitCamera::framing(lo, hi, ViewPreset::Top, Projection::Orthographic, viewport.aspect());
        (camera, ScreenTransform::new(&camera, z_scale, viewport))
    }

    #[test]
    fn the_screen_transform_agrees_with_the_camera() {
        let packed = PackedCloud::pack(&grid_cloud(), ColorBy::Height, None);
        let viewport = Viewport::new([5.0, 7.0], [500.0, 300.0]);
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let (lo, hi) = packed.scene_bounds(10.0);
            let camera = OrbitCamera::framing(lo, hi, ViewPreset::Oblique, projection, viewport.aspect());
            let t = ScreenTransform::new(&camera, 10.0, viewport);
            for i in [0, 500, 3 * 101 + 70, packed.points.len() - 1] {
                let expected = camera.project(&packed.scene_point(i, 10.0).expect("point"), &viewport).expect("front");
                let (s, depth) = t.project(packed.points[i].offset).expect("in the clip volume");
                assert!((f64::from(s[0]) - expected.pos[0]).abs() < 1e-3, "{projection:?}");
                assert!((f64::from(s[1]) - expected.pos[1]).abs() < 1e-3, "{projection:?}");
                assert!((f64::from(depth) - expected.depth).abs() < 1e-4 * expected.depth.abs().max(1.0));
            }
        }
    }

    #[test]
    fn picking_finds_the_point_under_the_cursor_and_the_front_one() {
        let packed = PackedCloud::pack(&grid_cloud(), ColorBy::Height, None);
        let viewport = Viewport::new([0.0, 0.0], [800.0, 600.0]);
        let (_, t) = top_view(&packed, 1.0, viewport);
        let target = 20 * 101 + 33;
        let (s, _) = t.project(packed.points[target].offset).expect("visible");
        let hit = pick(&packed, &t, [s[0] + 1.0, s[1] - 1.0], 3.0).expect("a point");
        assert_eq!(hit.index, target);
        assert!((hit.screen_distance - 2f32.sqrt()).abs() < 1e-3);
        // Nothing far from the cloud.
        assert_eq!(pick(&packed, &t, [1.0, 1.0], 3.0), None);
        // Seen edge-on from the front, the points of a column overlap: the front one wins.
        let (lo, hi) = packed.scene_bounds(1.0);
        let camera = OrbitCamera::framing(lo, hi, ViewPreset::Front, Projection::Orthographic, viewport.aspect());
        let front = ScreenTransform::new(&camera, 1.0, viewport);
        let (s, _) = front.project(packed.points[33].offset).expect("visible");
        let hit = pick(&packed, &front, s, 2.0).expect("a point");
        assert_eq!(hit.index % 101, 33, "same column");
        assert_eq!(hit.index / 101, 50, "the row nearest the eye (front view looks along +Y from -Y)");
    }

    #[test]
    fn picking_three_million_points_is_correct_at_scale() {
        let n: usize = 3_000_000;
        let side = 2000;
        let points: Vec<GpuPoint> = (0..n)
            .map(|i| GpuPoint {
                offset: [(i % side) as f32 * 0.005 - 5.0, (i / side) as f32 * 0.005 - 3.75, 0.0],
                scalar: 0.0,
            })
            .collect();
        let packed = PackedCloud::from_points([0.0; 3], points, Vec::new());
        assert!((packed.hi[0] - 4.995).abs() < 1e-4 && (packed.lo[1] + 3.75).abs() < 1e-6);
        assert_eq!(packed.chunk_bounds.len(), n.div_ceil(PICK_CHUNK));
        let viewport = Viewport::new([0.0, 0.0], [1000.0, 750.0]);
        let (_, t) = top_view(&packed, 1.0, viewport);
        let target = 1234 * side + 777;
        let (s, _) = t.project(packed.points[target].offset).expect("visible");
        let hit = pick(&packed, &t, s, 1.0).expect("a point");
        assert_eq!(hit.index, target);
    }

    /// The same rule as `pick`, over every point without run culling.
    fn pick_everything(packed: &PackedCloud, t: &ScreenTransform, cursor: [f32; 2], radius: f32) -> Option<Pick> {
        let candidates: Vec<Pick> = packed
            .points
            .iter()
            .enumerate()
            .filter_map(|(index, p)| {
                let (s, depth) = t.project(p.offset)?;
                let (dx, dy) = (s[0] - cursor[0], s[1] - cursor[1]);
                let d2 = dx * dx + dy * dy;
                (d2 <= radius * radius).then_some(Pick { index, screen_distance: d2.sqrt(), depth })
            })
            .collect();
        let front = candidates.iter().map(|c| c.depth).fold(f32::INFINITY, f32::min);
        let tolerance = 2.0 * radius * t.scene_per_screen(front);
        candidates
            .into_iter()
            .filter(|c| c.depth <= front + tolerance)
            .min_by(|a, b| a.screen_distance.total_cmp(&b.screen_distance).then(a.depth.total_cmp(&b.depth)))
    }

    #[test]
    fn skipping_runs_never_changes_the_pick() {
        // A wavy surface with a tall ridge, so runs overlap on screen in oblique views.
        let mut cloud = grid_cloud();
        for (i, p) in cloud.xyz.iter_mut().enumerate() {
            p[2] += 0.3 * ((i % 101) as f64 * 0.2).sin() + if i % 101 > 80 { 1.0 } else { 0.0 };
        }
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, None);
        let viewport = Viewport::new([20.0, 10.0], [300.0, 200.0]);
        let mut compared = 0;
        for projection in [Projection::Perspective, Projection::Orthographic] {
            for preset in ViewPreset::ALL {
                for z_scale in [1.0, 8.0] {
                    let (lo, hi) = packed.scene_bounds(z_scale);
                    let mut camera = OrbitCamera::framing(lo, hi, preset, projection, viewport.aspect());
                    // Close in, so some runs straddle the eye plane.
                    camera.zoom_towards(0.3, [170.0, 110.0], &viewport);
                    let t = ScreenTransform::new(&camera, z_scale, viewport);
                    for y in (10..210).step_by(7) {
                        for x in (20..320).step_by(7) {
                            let cursor = [x as f32 + 0.5, y as f32 + 0.25];
                            let fast = pick(&packed, &t, cursor, 3.0);
                            assert_eq!(fast, pick_everything(&packed, &t, cursor, 3.0), "{preset:?} {projection:?}");
                            compared += usize::from(fast.is_some());
                        }
                    }
                }
            }
        }
        assert!(compared > 5000, "most cursors hit the cloud: {compared}");
    }

    #[test]
    fn coarse_levels_keep_every_second_pixel_per_step_and_the_level_fits_the_splats() {
        let cloud = grid_cloud();
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, None);
        assert!((packed.spacing - 0.1).abs() < 0.002, "grid pitch 0.1 mm: {}", packed.spacing);
        let levels = packed.coarse_levels(&cloud);
        assert_eq!(levels.len(), LOD_LEVELS);
        // 101 x 51 pixels: multiples of 2 are 51 x 26, of 4 are 26 x 13, of 8 are 13 x 7.
        let counts: Vec<usize> = levels.iter().map(Vec::len).collect();
        assert_eq!(counts, vec![51 * 26, 26 * 13, 13 * 7]);
        assert_eq!(levels[1][1], packed.points[4], "level 2, second point: pixel (4, 0)");
        // Levels: none while points are a pixel apart or more.
        assert_eq!(lod_level(1.0, 2.0), 0);
        assert_eq!(lod_level(0.5, 1.0), 0);
        assert_eq!(lod_level(0.25, 1.0), 1);
        assert_eq!(lod_level(0.25, 2.0), 2);
        assert_eq!(lod_level(0.01, 8.0), LOD_LEVELS);
        assert_eq!(lod_level(0.0, 2.0), 0);
        assert_eq!(lod_level(f32::NAN, 2.0), 0);
    }
}
