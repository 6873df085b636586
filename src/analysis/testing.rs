//! Synthetic organized clouds and height maps with known truth, shared by the
//! analysis tests (compiled for tests only).

use super::height_map::{HeightMap, RasterParams, height_map_from_cloud};
use crate::engine::point_cloud::PointCloud;

/// A camera-like pixel grid laid on the object: pixel `(c, r)` sits at
/// `origin + R(angle) (c, r) pitch`, as a telecentric camera rotated about Z sees it.
#[derive(Clone, Copy, Debug)]
pub struct GridSpec {
    pub width: usize,
    pub height: usize,
    pub pitch_mm: f64,
    pub angle_deg: f64,
    pub origin_mm: [f64; 2],
}

/// An organized cloud of the surface `z = surface(x, y)` (mm); `None` leaves
/// the pixel without a point (a hole).
pub fn grid_cloud(spec: &GridSpec, surface: impl Fn(f64, f64) -> Option<f64>) -> PointCloud {
    let (s, c) = spec.angle_deg.to_radians().sin_cos();
    let mut cloud = PointCloud {
        unit: crate::engine::length_unit::LengthUnit::Mm,
        grid_width: spec.width,
        grid_height: spec.height,
        ..PointCloud::default()
    };
    for r in 0..spec.height {
        for col in 0..spec.width {
            let (u, v) = (col as f64 * spec.pitch_mm, r as f64 * spec.pitch_mm);
            let x = spec.origin_mm[0] + c * u - s * v;
            let y = spec.origin_mm[1] + s * u + c * v;
            let Some(z) = surface(x, y) else { continue };
            cloud.xyz.push([x, y, z]);
            cloud.pixel_uv.push([col as f32, r as f32]);
            cloud.source_set.push(0);
            cloud.source_period_px.push(12.0);
            cloud.modulation_dn.push(100.0);
            cloud.sigma_z.push(0.0);
            cloud.intensity_dn.push(128.0);
        }
    }
    cloud
}

/// The height map of a synthetic surface on an axis-aligned grid of the given pitch.
pub fn surface_map(spec: &GridSpec, surface: impl Fn(f64, f64) -> Option<f64>) -> HeightMap {
    let cloud = grid_cloud(spec, surface);
    match height_map_from_cloud(&cloud, &RasterParams { pitch_mm: Some(spec.pitch_mm), ..Default::default() }) {
        Ok(r) => r.map,
        Err(e) => panic!("synthetic surface did not rasterize: {e}"),
    }
}

/// A height map given node by node: `z = surface(x, y)` at each node, NaN for `None`.
pub fn node_map(
    width: usize,
    height: usize,
    origin_mm: [f64; 2],
    pitch_mm: f64,
    surface: impl Fn(f64, f64) -> Option<f64>,
) -> HeightMap {
    let mut z = Vec::with_capacity(width * height);
    for r in 0..height {
        for c in 0..width {
            let (x, y) = (origin_mm[0] + c as f64 * pitch_mm, origin_mm[1] + r as f64 * pitch_mm);
            z.push(surface(x, y).map_or(f32::NAN, |v| v as f32));
        }
    }
    match HeightMap::new(width, height, origin_mm[0], origin_mm[1], pitch_mm, z) {
        Ok(m) => m,
        Err(e) => panic!("bad synthetic map: {e}"),
    }
}
