//! The wgpu side of the 3D cloud view: the pipelines, the point buffer (one
//! upload per result and colour mode), the colour lookup texture, and the
//! egui paint callback.
//!
//! Points are drawn in `prepare` into an offscreen colour + linear-depth +
//! depth-buffer target of the view's size, then composited (with optional
//! eye-dome lighting) into egui's render pass in `paint`. That keeps the depth
//! test independent of egui's pass, which normally has no depth attachment
//! (and never has one under egui_kittest); the composite pipeline matches the
//! pass egui draws in ([`PassFormat`]): its colour format, its depth format if
//! any, its sample count.

use bytemuck::{Pod, Zeroable};
use eframe::egui;
use eframe::egui_wgpu::{self, wgpu};

use super::points::{GpuPoint, LOD_LEVELS, LUT_ENTRIES, ScreenTransform};

/// What egui's render pass looks like, so the composite pipeline can draw in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassFormat {
    pub color: wgpu::TextureFormat,
    /// The depth attachment of egui's pass, if it has one.
    pub depth: Option<wgpu::TextureFormat>,
    pub samples: u32,
}

impl PassFormat {
    /// egui's pass in this app: `app::run` leaves eframe's `depth_buffer` at 0
    /// and `multisampling` at 0 (none), and egui_kittest's pass has neither.
    pub fn egui(color: wgpu::TextureFormat) -> Self {
        Self { color, depth: None, samples: 1 }
    }
}

/// The offscreen formats (fixed: the composite reads them with `textureLoad`).
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// The linear depth's f32 bits in an integer target: `R32Float` is not
/// colour-renderable on OpenGL ES 3 (wgpu's GL backend, Mesa's llvmpipe
/// among them: "Format R32Float is not renderable"), while `R32Uint` is on
/// every backend WebGPU describes. The bits go in and come out unchanged
/// (`bitcast` both ways), so the picture is the same as with a float target.
const LINEAR_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The shader's uniforms (layout of `Uniforms` in cloud.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Uniforms {
    /// Column-major offset-to-clip matrix.
    pub clip: [[f32; 4]; 4],
    pub depth_row: [f32; 4],
    /// Target width, height, point size, eye-dome radius (physical pixels).
    pub viewport: [f32; 4],
    /// Scalar span lo, hi; eye-dome strength; unused.
    pub shading: [f32; 4],
    /// Scene units per physical pixel at depth d: `[0] * d + [1]`.
    pub screen_unit: [f32; 4],
    pub no_value: [f32; 4],
}

/// How points look, besides the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Style {
    /// Point diameter in screen units (egui points).
    pub point_size: f32,
    /// Scalar values at the first and last lookup entries.
    pub scalar_span: (f32, f32),
    /// Eye-dome lighting strength; 0 turns it off.
    pub edl_strength: f32,
    /// Colour of points without a value (sRGB bytes).
    pub no_value_rgba: [u8; 4],
}

/// Eye-dome sampling radius in screen units.
const EDL_RADIUS: f32 = 1.5;

impl Uniforms {
    /// The uniforms of a frame drawn into a target of `target_px` physical
    /// pixels, with `pixels_per_point` physical pixels per screen unit.
    pub fn new(t: &ScreenTransform, style: &Style, target_px: [u32; 2], pixels_per_point: f32) -> Self {
        let r = &t.clip_rows;
        let ppp = pixels_per_point.max(1e-3);
        let rgba = style.no_value_rgba.map(|c| f32::from(c) / 255.0);
        Self {
            clip: std::array::from_fn(|c| std::array::from_fn(|row| r[row][c])),
            depth_row: t.depth_row,
            viewport: [
                target_px[0].max(1) as f32,
                target_px[1].max(1) as f32,
                (style.point_size * ppp).max(1.0),
                (EDL_RADIUS * ppp).max(1.0),
            ],
            shading: [style.scalar_span.0, style.scalar_span.1, style.edl_strength.max(0.0), 0.0],
            screen_unit: [t.screen_unit[0] / ppp, t.screen_unit[1] / ppp, 0.0, 0.0],
            no_value: rgba,
        }
    }

    /// Whether points are drawn as single-pixel primitives rather than quads.
    pub fn draws_dots(&self) -> bool {
        self.viewport[2] <= 1.0
    }
}

struct PointBuffer {
    buffer: wgpu::Buffer,
    count: u32,
}

/// The GPU buffers of one packed cloud: the full cloud, then its coarse levels.
pub struct PointBuffers(Vec<PointBuffer>);

/// Creates the point buffers of a packed cloud and queues their contents.
/// wgpu's device and queue may be used from any thread, so the app does this
/// on a worker and the UI thread only swaps the finished buffers in
/// ([`CloudGpu::set_points`]); the old and the new cloud then share GPU
/// memory for a moment (about 60 MB each at 3 million points).
pub fn point_buffers(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    full: &[GpuPoint],
    coarse: &[Vec<GpuPoint>],
) -> Result<PointBuffers, UploadError> {
    let bytes = std::mem::size_of_val(full) as u64;
    let limit = device.limits().max_buffer_size;
    if bytes > limit {
        return Err(UploadError::BeyondBufferLimit { points: full.len(), mb: bytes >> 20, limit_mb: limit >> 20 });
    }
    if u32::try_from(full.len()).is_err() {
        return Err(UploadError::TooManyPoints(full.len()));
    }
    let buffers = std::iter::once(full)
        .chain(coarse.iter().take(LOD_LEVELS).map(Vec::as_slice))
        .map(|points| {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("cloud points"),
                size: (std::mem::size_of_val(points) as u64).max(std::mem::size_of::<GpuPoint>() as u64),
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            if !points.is_empty() {
                queue.write_buffer(&buffer, 0, bytemuck::cast_slice(points));
            }
            PointBuffer { buffer, count: points.len() as u32 }
        })
        .collect();
    Ok(PointBuffers(buffers))
}

/// The offscreen targets of one view size.
struct Targets {
    size: [u32; 2],
    color: wgpu::TextureView,
    linear_depth: wgpu::TextureView,
    depth: wgpu::TextureView,
    bind_group: wgpu::BindGroup,
}

/// Everything the view keeps on the GPU; lives in egui_wgpu's callback resources.
pub struct CloudGpu {
    quads: wgpu::RenderPipeline,
    dots: wgpu::RenderPipeline,
    composite: wgpu::RenderPipeline,
    uniforms: wgpu::Buffer,
    scene_bind_group: wgpu::BindGroup,
    target_layout: wgpu::BindGroupLayout,
    lut: wgpu::Texture,
    lut_key: Option<u64>,
    /// The full cloud, then its coarse levels (see `PackedCloud::coarse_levels`).
    points: Vec<PointBuffer>,
    targets: Option<Targets>,
}

fn texture_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    texture_entry_of(binding, visibility, wgpu::TextureSampleType::Float { filterable: false })
}

fn texture_entry_of(
    binding: u32,
    visibility: wgpu::ShaderStages,
    sample_type: wgpu::TextureSampleType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            multisampled: false,
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D2,
        },
        count: None,
    }
}

impl CloudGpu {
    /// Compiles the shaders and builds the pipelines for drawing into `pass`.
    pub fn new(device: &wgpu::Device, pass: PassFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("cloud.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("cloud.wgsl").into()),
        });
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cloud uniforms"),
            size: std::mem::size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let lut = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("cloud colour lookup"),
            size: wgpu::Extent3d { width: LUT_ENTRIES as u32, height: 1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let scene_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cloud scene"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: std::num::NonZeroU64::new(std::mem::size_of::<Uniforms>() as u64),
                    },
                    count: None,
                },
                texture_entry(1, wgpu::ShaderStages::VERTEX),
            ],
        });
        let lut_view = lut.create_view(&wgpu::TextureViewDescriptor::default());
        let scene_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cloud scene"),
            layout: &scene_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&lut_view) },
            ],
        });
        let target_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cloud offscreen targets"),
            entries: &[
                texture_entry(0, wgpu::ShaderStages::FRAGMENT),
                texture_entry_of(1, wgpu::ShaderStages::FRAGMENT, wgpu::TextureSampleType::Uint),
            ],
        });
        let points_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("cloud points"),
            bind_group_layouts: &[Some(&scene_layout)],
            immediate_size: 0,
        });
        let composite_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("cloud composite"),
            bind_group_layouts: &[Some(&scene_layout), Some(&target_layout)],
            immediate_size: 0,
        });
        let point_pipeline = |entry: &str, step_mode, topology| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(&points_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(entry),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<GpuPoint>() as u64,
                        step_mode,
                        attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32],
                    })],
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                },
                primitive: wgpu::PrimitiveState { topology, ..wgpu::PrimitiveState::default() },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: wgpu::StencilState::default(),
                    bias: wgpu::DepthBiasState::default(),
                }),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_point"),
                    targets: &[Some(COLOR_FORMAT.into()), Some(LINEAR_DEPTH_FORMAT.into())],
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let quads = point_pipeline("vs_quad", wgpu::VertexStepMode::Instance, wgpu::PrimitiveTopology::TriangleList);
        let dots = point_pipeline("vs_dot", wgpu::VertexStepMode::Vertex, wgpu::PrimitiveTopology::PointList);
        // Drawn in egui's pass: premultiplied alpha like egui, and the pass's
        // depth attachment (if any) neither tested nor written.
        let composite = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("cloud composite"),
            layout: Some(&composite_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_composite"),
                buffers: &[],
                compilation_options: wgpu::PipelineCompilationOptions::default(),
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: pass.depth.map(|format| wgpu::DepthStencilState {
                format,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::Always),
                stencil: wgpu::StencilState::default(),
                bias: wgpu::DepthBiasState::default(),
            }),
            multisample: wgpu::MultisampleState { count: pass.samples.max(1), ..wgpu::MultisampleState::default() },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some(if pass.color.is_srgb() { "fs_composite_linear" } else { "fs_composite" }),
                targets: &[Some(wgpu::ColorTargetState {
                    format: pass.color,
                    blend: Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
                compilation_options: wgpu::PipelineCompilationOptions::default(),
            }),
            multiview_mask: None,
            cache: None,
        });
        Self {
            quads,
            dots,
            composite,
            uniforms,
            scene_bind_group,
            target_layout,
            lut,
            lut_key: None,
            points: Vec::new(),
            targets: None,
        }
    }

    pub fn lut_key(&self) -> Option<u64> {
        self.lut_key
    }

    /// Replaces the point buffers (once per result and colour mode).
    pub fn set_points(&mut self, buffers: PointBuffers) {
        self.points = buffers.0;
    }

    /// Replaces the colour lookup table.
    pub fn upload_lut(&mut self, queue: &wgpu::Queue, key: u64, lut: &[[u8; 4]]) {
        if lut.len() != LUT_ENTRIES {
            return;
        }
        queue.write_texture(
            self.lut.as_image_copy(),
            bytemuck::cast_slice(lut),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * LUT_ENTRIES as u32),
                rows_per_image: None,
            },
            wgpu::Extent3d { width: LUT_ENTRIES as u32, height: 1, depth_or_array_layers: 1 },
        );
        self.lut_key = Some(key);
    }

    fn ensure_targets(&mut self, device: &wgpu::Device, size: [u32; 2]) {
        let max = device.limits().max_texture_dimension_2d.max(1);
        let size = [size[0].clamp(1, max), size[1].clamp(1, max)];
        if self.targets.as_ref().is_some_and(|t| t.size == size) {
            return;
        }
        self.targets = None;
        let texture = |label, format, usage| {
            device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
                .create_view(&wgpu::TextureViewDescriptor::default())
        };
        let sampled = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let color = texture("cloud colour", COLOR_FORMAT, sampled);
        let linear_depth = texture("cloud linear depth", LINEAR_DEPTH_FORMAT, sampled);
        let depth = texture("cloud depth", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cloud offscreen targets"),
            layout: &self.target_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&color) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&linear_depth) },
            ],
        });
        self.targets = Some(Targets { size, color, linear_depth, depth, bind_group });
    }

    /// Pass 1: draws the points into the offscreen targets of `size` pixels.
    pub fn render_points(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        size: [u32; 2],
        uniforms: &Uniforms,
        level: usize,
    ) {
        self.ensure_targets(device, size);
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(uniforms));
        let Some(targets) = &self.targets else {
            return;
        };
        let clear = |view| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("cloud points"),
            color_attachments: &[clear(&targets.color), clear(&targets.linear_depth)],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            ..wgpu::RenderPassDescriptor::default()
        });
        let level = level.min(self.points.len().saturating_sub(1));
        let Some(points) = self.points.get(level).filter(|p| p.count > 0) else {
            return;
        };
        pass.set_bind_group(0, &self.scene_bind_group, &[]);
        pass.set_vertex_buffer(0, points.buffer.slice(..));
        if uniforms.draws_dots() {
            pass.set_pipeline(&self.dots);
            pass.draw(0..points.count, 0..1);
        } else {
            pass.set_pipeline(&self.quads);
            pass.draw(0..6, 0..points.count);
        }
    }

    /// Pass 2: composites the offscreen image into `pass` (egui's), filling its viewport.
    pub fn composite(&self, pass: &mut wgpu::RenderPass<'_>) {
        let Some(targets) = &self.targets else {
            return;
        };
        pass.set_pipeline(&self.composite);
        pass.set_bind_group(0, &self.scene_bind_group, &[]);
        pass.set_bind_group(1, &targets.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// The paint callback of one frame of the view.
pub struct CloudCallback {
    /// The view's area in egui points (the callback's rect).
    pub rect: egui::Rect,
    pub transform: ScreenTransform,
    pub style: Style,
    /// Typical X-Y distance between neighbouring points (scene units), for the level of detail.
    pub spacing: f32,
}

impl CloudCallback {
    /// The level of detail to draw at `pixels_per_point`: the on-screen
    /// spacing is taken at the nearest depth of the scene, where it is largest.
    pub fn level(&self, pixels_per_point: f32, near_depth: f32) -> usize {
        let per_px = self.transform.scene_per_screen(near_depth) / pixels_per_point.max(1e-3);
        let spacing_px = if per_px > 0.0 { self.spacing / per_px } else { 0.0 };
        super::points::lod_level(spacing_px, (self.style.point_size * pixels_per_point).max(1.0))
    }
}

impl egui_wgpu::CallbackTrait for CloudCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        screen: &egui_wgpu::ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(gpu) = resources.get_mut::<CloudGpu>() else {
            return Vec::new();
        };
        // The same rounding egui uses for the callback's viewport.
        let px =
            egui::epaint::ViewportInPixels::from_points(&self.rect, screen.pixels_per_point, screen.size_in_pixels);
        let size = [px.width_px.max(1) as u32, px.height_px.max(1) as u32];
        let uniforms = Uniforms::new(&self.transform, &self.style, size, screen.pixels_per_point);
        let level = self.level(screen.pixels_per_point, self.transform.near_depth);
        gpu.render_points(device, queue, encoder, size, &uniforms, level);
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(gpu) = resources.get::<CloudGpu>() {
            gpu.composite(pass);
        }
    }
}

/// Runs a future that wgpu resolves without waiting (native backends answer
/// error scopes and adapter requests synchronously); gives up after a bounded
/// number of polls instead of hanging the UI thread.
pub fn resolve_now<F: std::future::Future>(future: F) -> Option<F::Output> {
    let mut future = std::pin::pin!(future);
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    for _ in 0..1000 {
        if let std::task::Poll::Ready(out) = future.as_mut().poll(&mut cx) {
            return Some(out);
        }
        std::thread::yield_now();
    }
    None
}

/// Builds the GPU side inside an error scope, so a driver that refuses the
/// shaders or pipelines gives a message instead of a crash.
pub fn create_gpu(device: &wgpu::Device, pass: PassFormat) -> Result<CloudGpu, wgpu::Error> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let gpu = CloudGpu::new(device, pass);
    match resolve_now(scope.pop()) {
        Some(Some(e)) => Err(e),
        _ => Ok(gpu),
    }
}

/// Why a cloud's points did not reach the GPU.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UploadError {
    #[error("the cloud has {points} points ({mb} MB), more than this GPU's largest buffer ({limit_mb} MB)")]
    BeyondBufferLimit { points: usize, mb: u64, limit_mb: u64 },
    #[error("{0} points are too many to draw")]
    TooManyPoints(usize),
    #[error("the 3D renderer's resources are missing")]
    ResourcesMissing,
    /// The packing job stopped; its error chain as the job reported it.
    #[error("{0}")]
    Packing(String),
}

#[cfg(test)]
mod tests {
    //! Offscreen renders of a known scene through the real pipelines: a disc
    //! raised 100 µm on a plane, with a hidden layer below the disc drawn last
    //! (it would show through without the depth test). These need a wgpu
    //! adapter (lavapipe will do); without one they are skipped with a message,
    //! unless SHEEN_REQUIRE_GPU_TESTS is set, which makes that a failure.

    use super::*;
    use crate::app::views::cloud::camera::{OrbitCamera, Projection, ViewPreset, Viewport};
    use crate::app::views::cloud::points::{ColorBy, PackedCloud, lut_rgba};
    use crate::engine::point_cloud::PointCloud;
    use crate::io::colormap::{Colormap, ValueRange};

    const DISC_CENTER_MM: [f64; 2] = [1.5, 0.5];
    const DISC_RADIUS_MM: f64 = 2.0;
    const DISC_HEIGHT_MM: f64 = 0.1;
    const PLANE_HALF_MM: [f64; 2] = [5.0, 3.75];
    const PITCH_MM: f64 = 0.05;

    fn on_disc(x: f64, y: f64) -> bool {
        (x - DISC_CENTER_MM[0]).hypot(y - DISC_CENTER_MM[1]) < DISC_RADIUS_MM
    }

    /// The plane and disc sampled every `pitch_mm`, organized like a camera image.
    fn scene(pitch_mm: f64) -> PointCloud {
        let mut cloud = PointCloud { unit: crate::engine::length_unit::LengthUnit::Mm, ..PointCloud::default() };
        let (nx, ny) = ((2.0 * PLANE_HALF_MM[0] / pitch_mm) as usize, (2.0 * PLANE_HALF_MM[1] / pitch_mm) as usize);
        (cloud.grid_width, cloud.grid_height) = (nx + 1, ny + 1);
        let mut push = |i: usize, j: usize, z: f64| {
            let (x, y) = (i as f64 * pitch_mm - PLANE_HALF_MM[0], j as f64 * pitch_mm - PLANE_HALF_MM[1]);
            cloud.xyz.push([x, y, z]);
            cloud.pixel_uv.push([i as f32, j as f32]);
            cloud.source_set.push(0);
            cloud.source_period_px.push(20.0);
            cloud.modulation_dn.push(50.0);
            cloud.sigma_z.push(0.001);
            cloud.intensity_dn.push(100.0);
        };
        let grid = (0..=ny).flat_map(|j| (0..=nx).map(move |i| (i, j)));
        let at = |i: usize, j: usize| (i as f64 * pitch_mm - PLANE_HALF_MM[0], j as f64 * pitch_mm - PLANE_HALF_MM[1]);
        for (i, j) in grid.clone() {
            let (x, y) = at(i, j);
            push(i, j, if on_disc(x, y) { DISC_HEIGHT_MM } else { 0.0 });
        }
        // Hidden under the disc, 0.3 mm down, and drawn after it.
        for (i, j) in grid {
            let (x, y) = at(i, j);
            if on_disc(x, y) {
                push(i, j, -0.3);
            }
        }
        cloud
    }

    fn device() -> Option<(wgpu::Device, wgpu::Queue)> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = resolve_now(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))?.ok()?;
        // CI runs these once with WGPU_BACKEND=gl: the run must really be on it.
        let backend = adapter.get_info().backend;
        if let Some(wanted) = wgpu::Backends::from_env() {
            assert!(
                wanted.contains(wgpu::Backends::from(backend)),
                "WGPU_BACKEND asked for {wanted:?}, got {backend:?}"
            );
        }
        resolve_now(adapter.request_device(&wgpu::DeviceDescriptor::default()))?.ok()
    }

    fn device_or_skip(test: &str) -> Option<(wgpu::Device, wgpu::Queue)> {
        let found = device();
        if found.is_none() {
            assert!(
                std::env::var_os("SHEEN_REQUIRE_GPU_TESTS").is_none(),
                "{test}: no wgpu adapter, and SHEEN_REQUIRE_GPU_TESTS is set (install mesa-vulkan-drivers)"
            );
            eprintln!("skipping {test}: no wgpu adapter here (set SHEEN_REQUIRE_GPU_TESTS to make this a failure)");
        }
        found
    }

    struct Shot {
        size: [u32; 2],
        rgba: Vec<[u8; 4]>,
        /// The level of detail drawn.
        level: usize,
    }

    impl Shot {
        fn at(&self, x: u32, y: u32) -> [u8; 4] {
            self.rgba[(y * self.size[0] + x) as usize]
        }
    }

    /// Renders `packed` through pass 1 and the composite into a target of `pass`'s format.
    fn render(
        (device, queue): &(wgpu::Device, wgpu::Queue),
        pass: PassFormat,
        (cloud, packed): (&PointCloud, &PackedCloud),
        transform: &ScreenTransform,
        style: &Style,
    ) -> Shot {
        let size = [transform.viewport.size[0] as u32, transform.viewport.size[1] as u32];
        let mut gpu = create_gpu(device, pass).expect("the pipelines build");
        gpu.set_points(point_buffers(device, queue, &packed.points, &packed.coarse_levels(cloud)).expect("upload"));
        gpu.upload_lut(queue, 1, &lut_rgba(ColorBy::Height, Colormap::Viridis));
        let uniforms = Uniforms::new(transform, style, size, 1.0);
        let extent = wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 };
        let target = |format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("test target"),
                size: extent,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let output = target(pass.color, wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC);
        let output_view = output.create_view(&wgpu::TextureViewDescriptor::default());
        let depth = pass.depth.map(|f| {
            target(f, wgpu::TextureUsages::RENDER_ATTACHMENT).create_view(&wgpu::TextureViewDescriptor::default())
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let callback =
            CloudCallback { rect: egui::Rect::NOTHING, transform: *transform, style: *style, spacing: packed.spacing };
        let level = callback.level(1.0, transform.near_depth);
        gpu.render_points(device, queue, &mut encoder, size, &uniforms, level);
        {
            let mut egui_pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("stands for egui's pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &output_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: depth.as_ref().map(|view| wgpu::RenderPassDepthStencilAttachment {
                    view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                ..wgpu::RenderPassDescriptor::default()
            });
            gpu.composite(&mut egui_pass);
        }
        let row = (size[0] * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(row * size[1]),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            output.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
            },
            extent,
        );
        let submission = queue.submit([encoder.finish()]);
        let (sender, receiver) = std::sync::mpsc::channel();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| drop(sender.send(r)));
        device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: Some(std::time::Duration::from_secs(30)),
            })
            .expect("the GPU finishes");
        receiver.recv().expect("map callback").expect("mapped");
        let data = buffer.slice(..).get_mapped_range().expect("mapped range").to_vec();
        let bgra = matches!(pass.color, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb);
        let rgba = data
            .chunks_exact(row as usize)
            .flat_map(|r| r[..size[0] as usize * 4].chunks_exact(4))
            .map(|p| if bgra { [p[2], p[1], p[0], p[3]] } else { [p[0], p[1], p[2], p[3]] })
            .collect();
        Shot { size, rgba, level }
    }

    fn viridis(t: f32) -> [u8; 4] {
        Colormap::Viridis.rgba(t, ValueRange::new(0.0, 1.0))
    }

    fn style(point_size: f32, edl_strength: f32) -> Style {
        // Height colours span 0..100 µm: the plane is the low end, the disc the high end.
        Style { point_size, scalar_span: (0.0, 100.0), edl_strength, no_value_rgba: [255, 0, 255, 255] }
    }

    fn top_view(packed: &PackedCloud, size: [f64; 2]) -> (OrbitCamera, ScreenTransform) {
        let viewport = Viewport::new([0.0, 0.0], size);
        let (lo, hi) = packed.scene_bounds(1.0);
        let camera = OrbitCamera::framing(lo, hi, ViewPreset::Top, Projection::Orthographic, viewport.aspect());
        (camera, ScreenTransform::new(&camera, 1.0, viewport))
    }

    /// What a pixel of the top view should show, from the camera's ray through
    /// its centre; `None` within two pixels of an edge, where splats blur it.
    fn expected(packed: &PackedCloud, camera: &OrbitCamera, t: &ScreenTransform, x: u32, y: u32) -> Option<[u8; 4]> {
        let ray = camera.ray_through([f64::from(x) + 0.5, f64::from(y) + 0.5], &t.viewport);
        // Scene space is the offset from the cloud centre; the plane is centred at the origin.
        let (cx, cy) = (ray.origin.x + packed.center[0], ray.origin.y + packed.center[1]);
        let margin = 2.0 * f64::from(t.scene_per_screen(0.0));
        let r = (cx - DISC_CENTER_MM[0]).hypot(cy - DISC_CENTER_MM[1]);
        let outside = cx.abs() - PLANE_HALF_MM[0] > margin || cy.abs() - PLANE_HALF_MM[1] > margin;
        let inside = cx.abs() - PLANE_HALF_MM[0] < -margin && cy.abs() - PLANE_HALF_MM[1] < -margin;
        if outside {
            Some([0, 0, 0, 0])
        } else if !inside || (r - DISC_RADIUS_MM).abs() < margin {
            None
        } else if r < DISC_RADIUS_MM {
            Some(viridis(1.0))
        } else {
            Some(viridis(0.0))
        }
    }

    /// Renders the scene sampled at `pitch_mm` from the top and checks every
    /// pixel away from edges against the camera's rays; returns the level drawn.
    fn check_top_view(gpu: &(wgpu::Device, wgpu::Queue), pitch_mm: f64) -> usize {
        let cloud = scene(pitch_mm);
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, Some([0.0; 3]));
        let (camera, t) = top_view(&packed, [320.0, 240.0]);
        let shot =
            render(gpu, PassFormat::egui(wgpu::TextureFormat::Rgba8Unorm), (&cloud, &packed), &t, &style(3.0, 0.0));
        let (mut checked, mut disc, mut wrong) = (0, 0, Vec::new());
        for y in 0..shot.size[1] {
            for x in 0..shot.size[0] {
                let Some(want) = expected(&packed, &camera, &t, x, y) else {
                    continue;
                };
                checked += 1;
                disc += usize::from(want == viridis(1.0));
                if shot.at(x, y) != want {
                    wrong.push((x, y, shot.at(x, y), want));
                }
            }
        }
        assert!(
            wrong.is_empty(),
            "{} of {checked} pixels differ, e.g. {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(5)]
        );
        // The checked disc pixels fill the disc less its edge band, at the scale the camera says.
        let radius_px = DISC_RADIUS_MM / f64::from(t.scene_per_screen(0.0)) - 2.0;
        let disc_px = std::f64::consts::PI * radius_px * radius_px;
        assert!((disc as f64 - disc_px).abs() < 0.01 * disc_px, "disc pixels {disc} vs {disc_px:.0}");
        assert!(checked > 60_000, "most of the image is checked: {checked}");
        shot.level
    }

    #[test]
    fn the_top_view_puts_the_disc_where_the_camera_says_with_height_colours() {
        let Some(gpu) = device_or_skip("the_top_view_puts_the_disc_where_the_camera_says_with_height_colours") else {
            return;
        };
        assert_eq!(check_top_view(&gpu, PITCH_MM), 0, "points 1.5 px apart are all drawn");
    }

    #[test]
    fn a_dense_cloud_is_drawn_from_a_coarse_level_without_holes() {
        let Some(gpu) = device_or_skip("a_dense_cloud_is_drawn_from_a_coarse_level_without_holes") else {
            return;
        };
        // 0.01 mm pitch: some 0.3 px apart on screen, so 3 px splats cover it from every 4th row and column.
        assert_eq!(check_top_view(&gpu, 0.01), 2);
    }

    #[test]
    fn egui_passes_with_a_depth_attachment_or_srgb_give_the_same_image() {
        let Some(gpu) = device_or_skip("egui_passes_with_a_depth_attachment_or_srgb_give_the_same_image") else {
            return;
        };
        let cloud = scene(PITCH_MM);
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, Some([0.0; 3]));
        let (_, t) = top_view(&packed, [160.0, 120.0]);
        let plain =
            render(&gpu, PassFormat::egui(wgpu::TextureFormat::Rgba8Unorm), (&cloud, &packed), &t, &style(3.0, 1.0));
        let with_depth = PassFormat {
            depth: Some(wgpu::TextureFormat::Depth32Float),
            ..PassFormat::egui(wgpu::TextureFormat::Rgba8Unorm)
        };
        assert_eq!(render(&gpu, with_depth, (&cloud, &packed), &t, &style(3.0, 1.0)).rgba, plain.rgba);
        let bgra =
            render(&gpu, PassFormat::egui(wgpu::TextureFormat::Bgra8Unorm), (&cloud, &packed), &t, &style(3.0, 1.0));
        assert_eq!(bgra.rgba, plain.rgba);
        // An sRGB target encodes on write: the shader decodes first, so the bytes match within rounding.
        let srgb = render(
            &gpu,
            PassFormat::egui(wgpu::TextureFormat::Rgba8UnormSrgb),
            (&cloud, &packed),
            &t,
            &style(3.0, 1.0),
        );
        for (a, b) in srgb.rgba.iter().zip(&plain.rgba) {
            assert!(a.iter().zip(b).all(|(x, y)| x.abs_diff(*y) <= 1), "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn eye_dome_lighting_darkens_the_foot_of_the_step_only() {
        let Some(gpu) = device_or_skip("eye_dome_lighting_darkens_the_foot_of_the_step_only") else {
            return;
        };
        let cloud = scene(PITCH_MM);
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, Some([0.0; 3]));
        let (camera, t) = top_view(&packed, [320.0, 240.0]);
        let shot =
            render(&gpu, PassFormat::egui(wgpu::TextureFormat::Rgba8Unorm), (&cloud, &packed), &t, &style(3.0, 1.0));
        let px_mm = f64::from(t.scene_per_screen(0.0));
        let pixel_at = |x_mm: f64, y_mm: f64| {
            let s = camera.project(&nalgebra::Point3::new(x_mm, y_mm, 0.0), &t.viewport).expect("in view");
            shot.at(s.pos[0] as u32, s.pos[1] as u32)
        };
        let [cx, cy] = DISC_CENTER_MM;
        // Flat areas facing the eye keep their colour.
        assert_eq!(pixel_at(cx, cy), viridis(1.0));
        assert_eq!(pixel_at(-4.0, -3.0), viridis(0.0));
        // Walking out from the disc centre along -X: the disc colour up to the
        // rim, then the first plane pixels see the disc nearer the eye: darker.
        let centre = camera.project(&nalgebra::Point3::new(cx, cy, 0.0), &t.viewport).expect("in view").pos;
        let (x0, y) = (centre[0] as u32, centre[1] as u32);
        let rim = (0..x0).rev().find(|&x| shot.at(x, y) != viridis(1.0)).expect("the disc ends");
        let expected_rim = centre[0] - DISC_RADIUS_MM / px_mm;
        assert!((f64::from(rim) - expected_rim).abs() < 2.5, "rim at {rim}, expected {expected_rim:.1}");
        let luma = |c: [u8; 4]| u32::from(c[0]) + u32::from(c[1]) + u32::from(c[2]);
        let (foot, plane) = (shot.at(rim, y), viridis(0.0));
        assert!(luma(foot) * 10 < luma(plane) * 7, "foot {foot:?} vs plane {plane:?}");
        // A few pixels further out the disc is beyond the sampling radius: plain plane colour.
        assert_eq!(shot.at(rim - 4, y), plane);
    }

    #[test]
    fn single_pixel_points_in_an_oblique_perspective_land_where_projected() {
        let Some(gpu) = device_or_skip("single_pixel_points_in_an_oblique_perspective_land_where_projected") else {
            return;
        };
        let cloud = scene(PITCH_MM);
        let packed = PackedCloud::pack(&cloud, ColorBy::Height, Some([0.0; 3]));
        let viewport = Viewport::new([0.0, 0.0], [400.0, 300.0]);
        let (lo, hi) = packed.scene_bounds(10.0);
        let camera = OrbitCamera::framing(lo, hi, ViewPreset::Oblique, Projection::Perspective, viewport.aspect());
        let t = ScreenTransform::new(&camera, 10.0, viewport);
        let dots = style(1.0, 0.0);
        assert!(Uniforms::new(&t, &dots, [400, 300], 1.0).draws_dots());
        let shot = render(&gpu, PassFormat::egui(wgpu::TextureFormat::Rgba8Unorm), (&cloud, &packed), &t, &dots);
        let at = |x: f64, y: f64, z: f64| {
            let s = camera.project(&nalgebra::Point3::new(x, y, z * 10.0), &viewport).expect("in view");
            shot.at(s.pos[0].floor() as u32, s.pos[1].floor() as u32)
        };
        let [cx, cy] = DISC_CENTER_MM;
        assert_eq!(at(cx, cy, DISC_HEIGHT_MM), viridis(1.0), "the disc centre, raised 10x");
        assert_eq!(at(-4.0, -3.0, 0.0), viridis(0.0), "a plane point in front of the disc");
        let covered = shot.rgba.iter().filter(|p| p[3] == 255).count();
        assert!(covered > 10_000, "the cloud covers much of the image: {covered} px");
        assert!(shot.rgba.iter().all(|p| p[3] == 0 || p[3] == 255), "points are opaque, the rest transparent");
    }
}
