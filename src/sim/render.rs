//! From rays to fringe images: each camera pixel is cast once and shaded once
//! into `(A, B, x_p, Z)`, and every phase-shifted image is rendered from those:
//!
//! `I_k = A + B c(Z, p) cos(2 pi x_p / p + delta_k)`, then read noise,
//! clipping at the saturation level and quantisation. With a projector gamma
//! the stage receives the pattern `(1 + m c cos(...)) / 2` raised to the
//! fringe gamma instead, so its harmonics reach the images as on real rigs.
//!
//! `A` and `B` come from the projector's pattern `(1 + m cos Phi) / 2` reflected
//! by the material (see [`Material::reflectance`](super::material::Material::reflectance))
//! plus ambient light; `c(Z, p)` is the projector's defocus contrast. Noise is
//! drawn from one ChaCha8 stream per (seed, camera, set, shift, row), so the
//! images do not depend on how rayon splits the work.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::engine::control::{Cancelled, RunControl};
use crate::engine::fringe::{FringeSetInfo, FringeStack, Samples};

use super::raycast::{BoundGrid, cast};
use super::rig::{CameraId, Projector, Rig};
use super::scene_model::Scene;
use super::truth::CameraTruth;

/// Camera response shared by all pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Radiometry {
    /// Largest grey level (`2^bits - 1`), also the saturation level.
    pub full_scale_dn: f64,
    /// Full-scale fraction per unit of reflected projector white (scene
    /// exposure times the operator's gain).
    pub exposure: f64,
    /// Ambient light, as a fraction of the projector's full white.
    pub ambient: f64,
    /// Standard deviation of the read noise in grey levels (0: noise-free).
    pub noise_sigma_dn: f64,
    /// Exponent of the fringe profile the stage receives: the projector's
    /// gamma over the gamma its pattern was corrected for (1: a pure sinusoid).
    pub fringe_gamma: f64,
    /// Camera black level in grey levels, added to every sample.
    pub black_level_dn: f64,
    /// The projector's in-focus fringe modulation `m`, which splits a pixel's
    /// `(A, B)` back into its ambient and its projector light.
    pub projector_modulation: f64,
}

/// Casts and shades every pixel of camera `id` (`visible_in_other` is left
/// false: it needs the other camera, see [`visible_in`]). `step_mm` is the
/// horizontal marching step.
pub fn shade_camera(
    scene: &Scene,
    rig: &Rig,
    grid: &BoundGrid,
    id: CameraId,
    radiometry: &Radiometry,
    step_mm: f64,
    control: &RunControl,
) -> Result<CameraTruth, Cancelled> {
    let (w, h) = (rig.width, rig.height);
    let to_camera = rig.to_camera(id);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let pixels: Vec<PixelView> = (0..h)
        .into_par_iter()
        .flat_map_iter(|v| {
            let cancelled = control.is_cancelled();
            let row: Vec<PixelView> = (0..w)
                .map(|u| {
                    let hit = if cancelled {
                        None
                    } else {
                        cast(scene, grid, &rig.pixel_ray(id, [u as f64, v as f64]), step_mm)
                    };
                    let Some(hit) = hit else {
                        return PixelView::MISS;
                    };
                    let (a, b) = shade_point(scene, rig, hit.point_mm, hit.on_wall, to_camera, radiometry);
                    PixelView {
                        projector_column_px: rig.projector.column_px(hit.point_mm[0]),
                        point_mm: hit.point_mm,
                        on_wall: hit.on_wall,
                        offset_dn: a as f32,
                        amplitude_dn: b as f32,
                    }
                })
                .collect();
            let finished = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if finished.is_multiple_of(16) {
                control.set_fraction(finished as f32 / h as f32);
            }
            row
        })
        .collect();
    control.check()?;
    Ok(CameraTruth {
        camera: id,
        width: w,
        height: h,
        point_mm: pixels.iter().map(|p| p.point_mm).collect(),
        on_wall: pixels.iter().map(|p| p.on_wall).collect(),
        visible_in_other: vec![false; w * h],
        projector_column_px: pixels.iter().map(|p| p.projector_column_px).collect(),
        offset_dn: pixels.iter().map(|p| p.offset_dn).collect(),
        amplitude_dn: pixels.iter().map(|p| p.amplitude_dn).collect(),
    })
}

/// One pixel's cast and shading, before it is split into the truth maps.
struct PixelView {
    projector_column_px: f64,
    point_mm: [f64; 3],
    on_wall: bool,
    offset_dn: f32,
    amplitude_dn: f32,
}

impl PixelView {
    const MISS: PixelView = PixelView {
        projector_column_px: f64::NAN,
        point_mm: [f64::NAN; 3],
        on_wall: false,
        offset_dn: 0.0,
        amplitude_dn: 0.0,
    };
}

/// `(A, B)` in grey levels at a surface point seen from the direction `to_camera`.
pub fn shade_point(
    scene: &Scene,
    rig: &Rig,
    point_mm: [f64; 3],
    on_wall: bool,
    to_camera: [f64; 3],
    radiometry: &Radiometry,
) -> (f64, f64) {
    let [x, y, _] = point_mm;
    // A wall point belongs to the feature on its lower side or its upper side;
    // either way its normal is horizontal, so only the albedo matters.
    let Some(stage) = scene.stage_point(x, y) else {
        return (0.0, 0.0);
    };
    let material = scene.material_of(stage.feature);
    let reflectance = if on_wall {
        0.0 // a vertical wall receives no light from a projector looking straight down
    } else {
        let g = stage.surface;
        let norm = (g.dz_dx * g.dz_dx + g.dz_dy * g.dz_dy + 1.0).sqrt();
        let normal = [-g.dz_dx / norm, -g.dz_dy / norm, 1.0 / norm];
        material.reflectance(normal, to_camera, x, y)
    };
    let scale = radiometry.full_scale_dn * radiometry.exposure;
    let offset = scale * (0.5 * reflectance + radiometry.ambient * material.albedo);
    let amplitude = scale * 0.5 * rig.projector.modulation * reflectance;
    (offset, amplitude)
}

/// Identifies one noise stream; mixing keeps nearby tuples uncorrelated.
pub fn stream_seed(seed: u64, camera: usize, set: usize, shift: usize, row: usize) -> u64 {
    let mut z = seed;
    for v in [camera as u64, set as u64, shift as u64, row as u64] {
        z = (z ^ v.wrapping_add(0x9e37_79b9_7f4a_7c15)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z ^= z >> 31;
        z = z.wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 29;
    }
    z
}

/// Renders the N images of one fringe set for one camera.
pub fn render_stack(
    shading: &CameraTruth,
    projector: &Projector,
    set: &FringeSetInfo,
    radiometry: &Radiometry,
    bits: u32,
    seed: u64,
    (camera_index, set_index): (usize, usize),
) -> FringeStack {
    let (w, h) = (shading.width, shading.height);
    let len = w * h;
    let period = set.period_px;
    // Per pixel: A, B c(Z, p), cos Phi, sin Phi (cos(Phi + d) = cos Phi cos d - sin Phi sin d), c(Z, p).
    let per_pixel: Vec<[f32; 5]> = (0..len)
        .into_par_iter()
        .map(|i| {
            let xp = shading.projector_column_px[i];
            if xp.is_nan() {
                return [0.0, 0.0, 0.0, 0.0, 1.0];
            }
            let z = shading.point_mm[i][2];
            let contrast = projector.contrast(z, period);
            let b = f64::from(shading.amplitude_dn[i]) * contrast;
            let (s, c) = (std::f64::consts::TAU * xp / period).sin_cos();
            [shading.offset_dn[i], b as f32, c as f32, s as f32, contrast as f32]
        })
        .collect();
    let shifts = set.phase_shifts_rad.len();
    let model = RowModel {
        per_pixel: &per_pixel,
        width: w,
        height: h,
        shifts_rad: &set.phase_shifts_rad,
        full_scale_dn: radiometry.full_scale_dn,
        noise_sigma_dn: radiometry.noise_sigma_dn,
        fringe_gamma: radiometry.fringe_gamma,
        black_level_dn: radiometry.black_level_dn,
        modulation: radiometry.projector_modulation,
        stream: (seed, camera_index, set_index),
    };
    let samples =
        if bits <= 8 { Samples::U8(model.render(|v| v as u8)) } else { Samples::U16(model.render(|v| v as u16)) };
    FringeStack { width: w, height: h, shifts, samples }
}

/// Everything needed to render any row of any image of one stack.
struct RowModel<'a> {
    /// Per pixel: `A`, `B c(Z, p)`, `cos Phi`, `sin Phi`, `c(Z, p)`.
    per_pixel: &'a [[f32; 5]],
    width: usize,
    height: usize,
    shifts_rad: &'a [f64],
    full_scale_dn: f64,
    noise_sigma_dn: f64,
    fringe_gamma: f64,
    black_level_dn: f64,
    modulation: f64,
    /// (seed, camera, set) of the noise streams.
    stream: (u64, usize, usize),
}

impl RowModel<'_> {
    /// All images, shift-major, rendered row by row in parallel; `to_sample`
    /// converts a clipped, rounded grey level to the sample type.
    fn render<T: Copy + Default + Send>(&self, to_sample: impl Fn(f64) -> T + Sync) -> Vec<T> {
        let (w, h) = (self.width.max(1), self.height.max(1));
        let mut data = vec![T::default(); self.width * self.height * self.shifts_rad.len()];
        data.par_chunks_mut(w).enumerate().for_each(|(j, out)| self.row(j / h, j % h, out, &to_sample));
        data
    }

    fn row<T>(&self, shift: usize, row: usize, out: &mut [T], to_sample: &impl Fn(f64) -> T) {
        let (sd, cd) = self.shifts_rad[shift].sin_cos();
        let sigma = self.noise_sigma_dn;
        let (seed, camera, set) = self.stream;
        let mut rng = (sigma > 0.0).then(|| ChaCha8Rng::seed_from_u64(stream_seed(seed, camera, set, shift, row)));
        let pixels = &self.per_pixel[row * self.width..(row + 1) * self.width];
        let linear = self.fringe_gamma == 1.0;
        for (sample, p) in out.iter_mut().zip(pixels) {
            let cos_phase = f64::from(p[2]) * cd - f64::from(p[3]) * sd;
            let light = if linear {
                f64::from(p[0]) + f64::from(p[1]) * cos_phase
            } else {
                // A = ambient + W / 2 and B c = W m c / 2, with W the reflected
                // projector white; the stage receives ((1 + m c cos) / 2)^gamma of it.
                let m_c = self.modulation * f64::from(p[4]);
                let white = if m_c > 0.0 { 2.0 * f64::from(p[1]) / m_c } else { 0.0 };
                let ambient = f64::from(p[0]) - 0.5 * white;
                ambient + white * (0.5 * (1.0 + m_c * cos_phase)).max(0.0).powf(self.fringe_gamma)
            };
            let mut v = light + self.black_level_dn;
            if let Some(rng) = rng.as_mut() {
                let n: f64 = StandardNormal.sample(rng);
                v += sigma * n;
            }
            *sample = to_sample(v.round().clamp(0.0, self.full_scale_dn));
        }
    }
}

/// Whether the point a camera sees is also seen by the other camera: it
/// projects inside the other image and is the first surface point on the
/// other camera's ray through it.
pub fn visible_in(
    scene: &Scene,
    rig: &Rig,
    grid: &BoundGrid,
    other: CameraId,
    point_mm: [f64; 3],
    step_mm: f64,
) -> bool {
    if point_mm[0].is_nan() {
        return false;
    }
    let cam = rig.camera(other);
    let [u, v] = cam.project_observed(point_mm);
    if !(u >= -0.5 && v >= -0.5 && u < cam.width as f64 - 0.5 && v < cam.height as f64 - 0.5) {
        return false;
    }
    // Cast from the camera's side rather than marching up from the point: a
    // ray that grazes an edge meets its broad top surface, not a sliver.
    let ray = rig.ray(other, cam.project(point_mm));
    cast(scene, grid, &ray, step_mm).is_some_and(|hit| {
        let d: [f64; 3] = std::array::from_fn(|i| hit.point_mm[i] - point_mm[i]);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < SAME_POINT_MM
    })
}

/// Two casts meet the same surface point to this distance (each is exact to ~1e-12 mm).
const SAME_POINT_MM: f64 = 1e-7;
