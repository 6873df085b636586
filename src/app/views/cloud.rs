//! The 3D view: the final point cloud drawn with wgpu inside the
//! egui app (the paper's Figs. 6-7), through an `egui_wgpu` paint callback
//! with its own pipelines and GPU buffers.
//!
//! [`CloudView`] owns the persisted settings (colouring, range, point size,
//! Z exaggeration, projection, eye-dome shading); [`CloudRuntime`] the runtime
//! side (the render state, the packed cloud uploaded once per result and
//! colour mode, the orbit camera, the hovered point). Orbit with the left
//! mouse button, pan with the right or middle one (or shift + left), zoom with
//! the wheel towards the cursor; with the view focused (click it), the arrows
//! orbit, + and - zoom and R resets. Clicking a point selects its left-camera
//! pixel in the pixel inspector, so the 2D views follow.
//!
//! Submodules: `camera` (orbit maths), `points` (packing, lookup tables,
//! picking), `renderer` (wgpu pipelines and the paint callback), `cloud.wgsl`.

mod camera;
mod points;
mod renderer;

use std::sync::Arc;

use eframe::egui::{self, Color32, Key, Pos2, Sense, Stroke, vec2};
use eframe::egui_wgpu;

use crate::app::commands::{Command, PixelRef};
use crate::app::jobs::{Job, JobError, JobOutcome};
use crate::app::palette::{self, Colormap};
use crate::app::run_data::ResultSet;
use crate::app::textures::key_of;
use crate::app::widgets::busy_line;
use crate::app::widgets::legend::{self, Legend, LegendEntry};
use crate::engine::point_cloud::PointCloud;

use super::{Pane, PaneContent, RangeSetting, View, ViewCx, ViewRuntime, colormap_picker, robust_range};

pub use camera::{OrbitCamera, Projection, ViewPreset, Viewport};
pub use points::ColorBy;
use points::{PackedCloud, ScreenTransform, pick};
use renderer::{CloudGpu, PassFormat, PointBuffers, Style, UploadError, create_gpu, point_buffers};

/// The camera the cloud is organized on: the main (left) camera.
const CLOUD_CAMERA: usize = 0;
/// Zoom per scrolled point (as in the 2D maps) and per key press.
const WHEEL_ZOOM_PER_POINT: f64 = 0.0025;
const KEY_ZOOM: f64 = 1.25;
/// Orbit per arrow-key press, in drag units.
const KEY_ORBIT: f64 = 20.0;
/// The preset of a fresh view and of "Reset view".
const HOME_PRESET: ViewPreset = ViewPreset::Oblique;

/// The 3D view's persisted settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct CloudView {
    pub color_by: ColorBy,
    pub height_colormap: Colormap,
    pub height_range: RangeSetting,
    pub modulation_range: RangeSetting,
    pub intensity_range: RangeSetting,
    /// Point diameter in screen points.
    pub point_size: f32,
    /// Factor on heights (micrometre relief over millimetre fields is flat at true scale).
    pub z_exaggeration: f32,
    pub projection: Projection,
    /// Eye-dome lighting: shape reads without colour.
    pub eye_dome: bool,
    pub eye_dome_strength: f32,
}

impl Default for CloudView {
    fn default() -> Self {
        Self {
            color_by: ColorBy::Height,
            height_colormap: Colormap::Viridis,
            height_range: RangeSetting::default(),
            modulation_range: RangeSetting::default(),
            intensity_range: RangeSetting::default(),
            point_size: 2.0,
            z_exaggeration: 1.0,
            projection: Projection::Perspective,
            eye_dome: true,
            eye_dome_strength: 1.0,
        }
    }
}

/// The scalar a colour mode shows, its unit, and its colour table for the legend.
struct Scale {
    unit: String,
    lut: &'static [Color32; palette::LUT_SIZE],
    auto: Option<(f32, f32)>,
}

impl CloudView {
    fn range_mut(&mut self) -> Option<&mut RangeSetting> {
        match self.color_by {
            ColorBy::Height => Some(&mut self.height_range),
            ColorBy::Modulation => Some(&mut self.modulation_range),
            ColorBy::Intensity => Some(&mut self.intensity_range),
            ColorBy::SourceSet => None,
        }
    }

    fn range(&self) -> Option<&RangeSetting> {
        match self.color_by {
            ColorBy::Height => Some(&self.height_range),
            ColorBy::Modulation => Some(&self.modulation_range),
            ColorBy::Intensity => Some(&self.intensity_range),
            ColorBy::SourceSet => None,
        }
    }

    /// Unit, legend table and automatic (robust 1-99 %) range of the colour mode.
    fn scale(&self, cx: &ViewCx<'_>) -> Scale {
        let result = cx.result;
        let cloud = result.and_then(|r| r.reconstruction.cloud());
        let range_of = |key: &str, values: fn(&PointCloud) -> &[f32]| {
            cx.memo_range(("cloud", key), || cloud.and_then(|c| robust_range(values(c), 0.01, 0.99)))
        };
        match self.color_by {
            ColorBy::Height => Scale {
                unit: result.map_or("µm", |r| r.derived.height_unit.as_str()).to_owned(),
                lut: palette::lut(self.height_colormap),
                // The height view's key: both views share one automatic range.
                auto: cx.memo_range("height", || {
                    result.and_then(|r| r.derived.height.as_deref().and_then(|h| robust_range(h, 0.01, 0.99)))
                }),
            },
            ColorBy::Modulation => Scale {
                unit: "dn".into(),
                lut: palette::lut(Colormap::Viridis),
                auto: range_of("modulation", |c| &c.modulation_dn),
            },
            ColorBy::Intensity => Scale {
                unit: "dn".into(),
                lut: palette::lut(Colormap::Gray),
                auto: range_of("intensity", |c| &c.intensity_dn),
            },
            ColorBy::SourceSet => Scale { unit: String::new(), lut: palette::lut(Colormap::Viridis), auto: None },
        }
    }
}

impl View for CloudView {
    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        ui.label("Colour:");
        egui::ComboBox::from_id_salt("cloud colour by")
            .selected_text(self.color_by.name())
            .show_ui(ui, |ui| {
                for c in ColorBy::ALL {
                    ui.selectable_value(&mut self.color_by, c, c.name()).on_hover_text(c.tooltip());
                }
            })
            .response
            .on_hover_text("What the colour of a point shows.")
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, "Colour by"));
        if self.color_by == ColorBy::Height {
            colormap_picker(ui, "cloud colormap", &mut self.height_colormap);
        }
        let scale = self.scale(cx);
        if let Some(range) = self.range_mut() {
            range.ui(ui, &scale.unit, scale.auto);
        }
        // A slider lays out as one group that cannot wrap: start a row with it, and keep it short.
        ui.end_row();
        ui.spacing_mut().slider_width = 80.0;
        ui.add(
            egui::Slider::new(&mut self.z_exaggeration, 0.1..=100.0)
                .logarithmic(true)
                .text("Z exaggeration")
                .suffix("×"),
        )
        .on_hover_text("Heights are micrometres over millimetres: stretch Z to see the relief.");
        ui.separator();
        ui.label("Point size");
        ui.add(egui::DragValue::new(&mut self.point_size).range(1.0..=8.0).speed(0.05).suffix(" pt"))
            .on_hover_text("Diameter of each point on screen; 1 draws single pixels.")
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Point size"));
        ui.separator();
        ui.selectable_value(&mut self.projection, Projection::Perspective, Projection::Perspective.name())
            .on_hover_text("Perspective projection: near things look bigger.");
        ui.selectable_value(&mut self.projection, Projection::Orthographic, Projection::Orthographic.name())
            .on_hover_text("Orthographic projection: true proportions, as telecentric optics see the part.");
        ui.separator();
        ui.checkbox(&mut self.eye_dome, "Shading").on_hover_text(
            "Eye-dome lighting: darken steps and slopes from the depth image so the shape reads without colour.",
        );
        ui.add_enabled(
            self.eye_dome,
            egui::DragValue::new(&mut self.eye_dome_strength).range(0.1..=5.0).speed(0.02).prefix("strength "),
        )
        .on_hover_text("How strongly eye-dome shading darkens steps and slopes.")
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Shading strength"));
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, _cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let camera = CLOUD_CAMERA;
        let title = format!("{} · 3D point cloud", cx.camera_name(camera));
        let Some(result) = cx.result else {
            return vec![Pane::message(camera, title, "No result yet: the engine is running or has not run.")];
        };
        let rec = &result.reconstruction;
        let Some(cloud) = rec.cloud() else {
            let why = rec.stereo_skipped.as_deref().unwrap_or("no stereo result");
            return vec![Pane::message(camera, title, format!("No 3D points: {why}."))];
        };
        if cloud.is_empty() {
            return vec![Pane::message(
                camera,
                title,
                "The cloud is empty: no pixel could be matched in both cameras.",
            )];
        }
        let scale = self.scale(cx);
        let frame = DrawInputs {
            settings: self.clone(),
            result,
            cloud,
            range: self.range().map_or((0.0, 1.0), |r| r.resolve(scale.auto)),
            scale,
            measurement_generation: cx.measurement_generation,
        };
        let content = PaneContent::Custom(Box::new(move |ui: &mut egui::Ui, rt: &mut ViewRuntime<'_>| {
            frame.show(ui, rt);
        }));
        vec![Pane { camera, title, content }]
    }
}

/// Values of one cloud point, as the operator reads them.
#[derive(Clone, Debug, PartialEq)]
pub struct PointInfo {
    /// Index in the cloud.
    pub index: usize,
    /// Left-camera pixel the point was measured at (rounded), if on the grid.
    pub pixel: Option<[usize; 2]>,
    pub xyz: [f64; 3],
    pub unit: String,
    /// Height in micrometres when the unit is a known length.
    pub z_um: Option<f64>,
    pub source_set: Option<i8>,
}

impl PointInfo {
    fn of(cloud: &PointCloud, index: usize) -> Option<Self> {
        let xyz = *cloud.xyz.get(index)?;
        let pixel = cloud.pixel_uv.get(index).and_then(|uv| {
            let (u, v) = (uv[0].round(), uv[1].round());
            (u >= 0.0 && v >= 0.0 && (u as usize) < cloud.grid_width && (v as usize) < cloud.grid_height)
                .then_some([u as usize, v as usize])
        });
        Some(Self {
            index,
            pixel,
            xyz,
            unit: cloud.unit.to_string(),
            z_um: Some(xyz[2] * cloud.um_per_unit()),
            source_set: cloud.source_set.get(index).copied(),
        })
    }

    /// "X 1.2345 mm · Y -0.5000 mm · Z 12.34 µm · pixel u 105, v 50 · set 1".
    pub fn describe(&self) -> String {
        let [x, y, z] = self.xyz;
        let unit = &self.unit;
        let mut text = format!("X {x:.4} {unit} · Y {y:.4} {unit} · ");
        match self.z_um {
            Some(z_um) => text.push_str(&format!("Z {z_um:.2} µm")),
            None => text.push_str(&format!("Z {z:.4} {unit}")),
        }
        if let Some([u, v]) = self.pixel {
            text.push_str(&format!(" · pixel u {u}, v {v}"));
        }
        if let Some(s) = self.source_set.filter(|s| *s >= 0) {
            text.push_str(&format!(" · set {s}"));
        }
        text
    }
}

/// Whether the GPU side exists.
enum GpuStatus {
    NotCreated,
    Ready,
    /// The driver's message for the shaders or pipelines it refused.
    Failed(String),
}

/// Why the 3D view draws a message instead of the cloud.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
enum CloudUnavailable {
    #[error(
        "The 3D view needs the wgpu renderer, and none is running: no graphics adapter was found, or the app \
         was started with another renderer. The Height view shows the same points as a map."
    )]
    NoRenderer,
    #[error("The graphics device refused the 3D view's shaders: {0}")]
    ShadersRefused(String),
    #[error("The 3D renderer is not ready.")]
    NotReady,
    #[error("The cloud could not be put on the GPU: {0}.")]
    Upload(UploadError),
}

/// The hover pick of one pointer position and frame, reused while neither changes.
#[derive(Clone, Copy, PartialEq)]
struct HoverKey {
    pointer: [f32; 2],
    transform: ScreenTransform,
    points_key: u64,
}

/// A cloud packed and put into GPU buffers on a worker.
struct PreparedCloud {
    packed: PackedCloud,
    buffers: Result<PointBuffers, UploadError>,
}

/// What a packed cloud is made from.
struct Origin {
    /// Hash of the result generation, measurement generation and colour mode.
    key: u64,
    measurement: u64,
    color_by: ColorBy,
    /// The result itself. The view reads point attributes and the
    /// pixel-to-point index from it, not from the newest result, so picking
    /// stays right while a newer result is being packed.
    source: ResultSet,
}

/// The packing job of one result and colour mode.
struct Packing {
    origin: Origin,
    job: Job<PreparedCloud>,
}

/// The 3D view's runtime resources (never persisted).
pub struct CloudRuntime {
    render_state: Option<egui_wgpu::RenderState>,
    gpu: GpuStatus,
    /// The cloud on the GPU and what it was made from.
    packed: Option<(Arc<PackedCloud>, Origin)>,
    /// The key of the last packing that ended, well or not: a failed one is
    /// not retried for the same result and colour mode.
    settled_key: u64,
    /// Packing and uploading 3 million points takes 40 to 90 ms on the
    /// development VM: a worker does it and the view draws the previous
    /// cloud meanwhile, so a new result never stalls the UI thread.
    packing: Option<Packing>,
    camera: Option<OrbitCamera>,
    camera_measurement: u64,
    /// The Z exaggeration the camera's target was set for.
    camera_z_scale: f64,
    /// The last frame's mapping from points to the screen.
    transform: Option<ScreenTransform>,
    hover: Option<(HoverKey, Option<PointInfo>)>,
    uploads: u64,
    upload_error: Option<UploadError>,
}

impl CloudRuntime {
    /// `render_state` is eframe's wgpu state (`None` with another renderer or no GPU).
    pub fn new(render_state: Option<egui_wgpu::RenderState>) -> Self {
        Self {
            render_state,
            gpu: GpuStatus::NotCreated,
            packed: None,
            settled_key: 0,
            packing: None,
            camera: None,
            camera_measurement: 0,
            camera_z_scale: 1.0,
            transform: None,
            hover: None,
            uploads: 0,
            upload_error: None,
        }
    }

    /// Point uploads to the GPU so far (one per result and colour mode).
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Whether a cloud is being packed for the GPU (the view shows the
    /// previous one meanwhile).
    pub fn is_packing(&self) -> bool {
        self.packing.is_some()
    }

    /// While the view is hidden: lets go of a packed cloud, and stops a
    /// packing, made from another result than `generation`. Each holds its
    /// whole result (about 0.75 GB at full size), which would otherwise stay
    /// in memory until the 3D view is shown again.
    pub fn forget_other_results(&mut self, generation: Option<u64>) {
        if self.packed.take_if(|(_, origin)| Some(origin.source.generation) != generation).is_some() {
            self.hover = None;
        }
        if let Some(packing) = self.packing.take_if(|p| Some(p.origin.source.generation) != generation) {
            packing.job.cancel();
        }
    }

    /// Whether the view holds a packed cloud or a packing job of any result.
    pub fn holds_a_result(&self) -> bool {
        self.packed.is_some() || self.packing.is_some()
    }

    pub fn camera(&self) -> Option<OrbitCamera> {
        self.camera
    }

    /// The point under the pointer in the last frame.
    pub fn hovered(&self) -> Option<&PointInfo> {
        self.hover.as_ref().and_then(|(_, info)| info.as_ref())
    }

    /// Where cloud point `index` was drawn in the last frame (screen points).
    pub fn screen_position(&self, index: usize) -> Option<Pos2> {
        let p = self.packed.as_ref()?.0.points.get(index)?;
        let (s, _) = self.transform?.project(p.offset)?;
        Some(egui::pos2(s[0], s[1]))
    }

    /// Creates the pipelines the first time the view is drawn; the reason if
    /// the view cannot draw.
    fn ensure_gpu(&mut self) -> Result<&egui_wgpu::RenderState, CloudUnavailable> {
        let Some(rs) = self.render_state.as_ref() else {
            return Err(CloudUnavailable::NoRenderer);
        };
        if matches!(self.gpu, GpuStatus::NotCreated) {
            self.gpu = match create_gpu(&rs.device, PassFormat::egui(rs.target_format)) {
                Ok(gpu) => {
                    rs.renderer.write().callback_resources.insert(gpu);
                    GpuStatus::Ready
                }
                Err(e) => GpuStatus::Failed(e.to_string()),
            };
        }
        match &self.gpu {
            GpuStatus::Ready => Ok(rs),
            GpuStatus::Failed(e) => Err(CloudUnavailable::ShadersRefused(e.clone())),
            GpuStatus::NotCreated => Err(CloudUnavailable::NotReady),
        }
    }

    /// Packs and uploads the cloud on a worker when the result or colour mode
    /// changed, installs it when ready, and uploads the lookup table when the
    /// colours changed.
    fn sync(&mut self, ctx: &egui::Context, frame: &DrawInputs<'_>) -> Result<(), CloudUnavailable> {
        let rs = self.ensure_gpu()?.clone();
        let settings = &frame.settings;
        let key = key_of(&(frame.result.generation, frame.measurement_generation, settings.color_by));
        if let Some(outcome) = self.packing.as_ref().and_then(|p| p.job.poll())
            && let Some(packing) = self.packing.take()
        {
            match outcome {
                JobOutcome::Done(prepared) => {
                    let mut renderer = rs.renderer.write();
                    let result = match (renderer.callback_resources.get_mut::<CloudGpu>(), prepared.buffers) {
                        (Some(gpu), Ok(buffers)) => {
                            gpu.set_points(buffers);
                            Ok(())
                        }
                        (None, _) => Err(UploadError::ResourcesMissing),
                        (_, Err(e)) => Err(e),
                    };
                    drop(renderer);
                    self.uploads += 1;
                    self.upload_error = result.err();
                    self.settled_key = packing.origin.key;
                    self.packed = Some((Arc::new(prepared.packed), packing.origin));
                    self.hover = None;
                }
                JobOutcome::Failed(_) | JobOutcome::Panicked(_) => {
                    let why = match outcome {
                        JobOutcome::Failed(e) => crate::error_text::error_chain(&e),
                        JobOutcome::Panicked(e) => format!("packing crashed: {e}"),
                        _ => unreachable!("matched above"),
                    };
                    self.upload_error = Some(UploadError::Packing(why));
                    self.settled_key = packing.origin.key;
                }
                JobOutcome::Cancelled => {}
            }
        }
        let shown_key = self.packed.as_ref().map(|(_, origin)| origin.key);
        let wanted = shown_key != Some(key) && !(self.settled_key == key && self.upload_error.is_some());
        if wanted && self.packing.as_ref().is_none_or(|p| p.origin.key != key) {
            if let Some(old) = self.packing.take() {
                old.job.cancel();
            }
            // Keep the centre while the measurement is the same: the view stays put across re-runs.
            let center = self
                .packed
                .as_ref()
                .filter(|(_, origin)| origin.measurement == frame.measurement_generation)
                .map(|(p, _)| p.center);
            let (source, color_by) = (frame.result.clone(), settings.color_by);
            let job_source = source.clone();
            let (device, queue) = (rs.device.clone(), rs.queue.clone());
            let repaint = ctx.clone();
            let job = Job::spawn(
                "packing the cloud for the 3D view",
                move || repaint.request_repaint(),
                move |control| {
                    let cloud = job_source
                        .reconstruction
                        .cloud()
                        .ok_or_else(|| JobError::Failed(anyhow::anyhow!("the result has no cloud")))?;
                    let packed = PackedCloud::pack(cloud, color_by, center);
                    control.check()?;
                    let coarse = packed.coarse_levels(cloud);
                    control.check()?;
                    let buffers = point_buffers(&device, &queue, &packed.points, &coarse);
                    Ok(PreparedCloud { packed, buffers })
                },
            );
            let origin = Origin { key, measurement: frame.measurement_generation, color_by, source };
            self.packing = Some(Packing { origin, job });
        }
        if let Some(e) = &self.upload_error {
            return Err(CloudUnavailable::Upload(e.clone()));
        }
        let lut_key = key_of(&(settings.color_by, settings.height_colormap));
        let mut renderer = rs.renderer.write();
        if let Some(gpu) = renderer.callback_resources.get_mut::<CloudGpu>()
            && gpu.lut_key() != Some(lut_key)
        {
            gpu.upload_lut(&rs.queue, lut_key, &points::lut_rgba(settings.color_by, settings.height_colormap));
        }
        Ok(())
    }
}

/// Everything one frame of the view draws from (not called `Frame`: in app
/// code that name is eframe's).
struct DrawInputs<'a> {
    settings: CloudView,
    result: &'a ResultSet,
    cloud: &'a PointCloud,
    scale: Scale,
    range: (f32, f32),
    measurement_generation: u64,
}

impl DrawInputs<'_> {
    fn z_scale(&self) -> f64 {
        f64::from(self.settings.z_exaggeration).clamp(1e-3, 1e4)
    }

    /// The camera: fresh for a new measurement, otherwise the operator's,
    /// its target and scene sphere following the Z exaggeration.
    fn camera_for(
        &self,
        runtime: &CloudRuntime,
        (lo, hi): ([f64; 3], [f64; 3]),
        z_scale: f64,
        viewport: &Viewport,
    ) -> OrbitCamera {
        let fresh = runtime.camera.is_none() || runtime.camera_measurement != self.measurement_generation;
        let mut camera = match runtime.camera {
            Some(c) if !fresh => c,
            _ => OrbitCamera::framing(lo, hi, HOME_PRESET, self.settings.projection, viewport.aspect()),
        };
        camera.projection = self.settings.projection;
        // A new exaggeration stretches the scene about the cloud's centre: the target goes with it.
        if !fresh && runtime.camera_z_scale != z_scale {
            camera.target.z *= z_scale / runtime.camera_z_scale;
        }
        // The scene sphere follows the Z exaggeration (clip planes).
        let frame_box = OrbitCamera::framing(lo, hi, HOME_PRESET, camera.projection, viewport.aspect());
        camera.scene_center = frame_box.scene_center;
        camera.scene_radius = frame_box.scene_radius;
        camera
    }

    fn legend(&self, packed: &PackedCloud) -> Legend {
        if self.settings.color_by.is_categorical() {
            let total = self.cloud.len().max(1);
            let entries = packed
                .category_counts
                .iter()
                .enumerate()
                .filter(|(_, n)| **n > 0)
                .map(|(set, &n)| LegendEntry {
                    color: palette::source_color(set as i8),
                    label: format!("set {set}: {:.1} %", 100.0 * n as f64 / total as f64),
                })
                .collect();
            return Legend::classes(entries);
        }
        let (lo, hi) = self.range;
        Legend::bar(self.scale.lut, f64::from(lo), f64::from(hi), &self.scale.unit)
    }

    fn show(self, ui: &mut egui::Ui, rt: &mut ViewRuntime<'_>) {
        let runtime = &mut *rt.cloud;
        if let Err(message) = runtime.sync(ui.ctx(), &self) {
            ui.add_space(12.0);
            ui.colored_label(palette::warning_text(ui.visuals()), message.to_string());
            return;
        }
        // The packed cloud and the result it came from (a newer one may be
        // packing). Another measurement's cloud, or one coloured by another
        // quantity (its values would be read through the new colour map), is
        // not shown meanwhile.
        let ready = runtime.packed.as_ref().filter(|(_, origin)| {
            origin.measurement == self.measurement_generation && origin.color_by == self.settings.color_by
        });
        let Some((packed, source, points_key)) =
            ready.map(|(packed, origin)| (Arc::clone(packed), origin.source.clone(), origin.key))
        else {
            ui.add_space(12.0);
            busy_line(ui, format!("Preparing {} points for the 3D view…", self.cloud.len()));
            return;
        };
        let Some(cloud) = source.reconstruction.cloud() else {
            return;
        };
        let z_scale = self.z_scale();
        let (lo, hi) = packed.scene_bounds(z_scale);

        let mut preset = preset_toolbar(ui);

        let spacing = ui.spacing().item_spacing;
        let legend = self.legend(&packed);
        let legend_w = legend::width(ui, &legend);
        let footer_h = 2.0 * (ui.text_style_height(&egui::TextStyle::Monospace) + spacing.y);
        let avail = ui.available_size();
        let canvas_size = vec2((avail.x - legend_w - spacing.x).max(60.0), (avail.y - footer_h - 4.0).max(60.0));
        let (canvas, response) = ui
            .horizontal_top(|ui| {
                let (rect, response) = ui.allocate_exact_size(canvas_size, Sense::click_and_drag());
                legend::show(ui, &legend, vec2(legend_w, canvas_size.y));
                (rect, response)
            })
            .inner;
        response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "3D point cloud"));
        let viewport = Viewport::new(
            [f64::from(canvas.min.x), f64::from(canvas.min.y)],
            [f64::from(canvas.width()), f64::from(canvas.height())],
        );

        let mut camera = self.camera_for(runtime, (lo, hi), z_scale, &viewport);
        if interact(ui, &response, &mut camera, &viewport) {
            preset = Some(HOME_PRESET);
        }
        if let Some(p) = preset {
            camera = OrbitCamera::framing(lo, hi, p, camera.projection, viewport.aspect());
        }
        runtime.camera = Some(camera);
        runtime.camera_measurement = self.measurement_generation;
        runtime.camera_z_scale = z_scale;

        let transform = ScreenTransform::new(&camera, z_scale, viewport);
        runtime.transform = Some(transform);
        let style = Style {
            point_size: self.settings.point_size.clamp(1.0, 64.0),
            scalar_span: points::lut_span(self.settings.color_by, self.range),
            edl_strength: if self.settings.eye_dome { self.settings.eye_dome_strength } else { 0.0 },
            no_value_rgba: palette::INVALID.to_array(),
        };
        let painter = ui.painter_at(canvas);
        painter.rect_filled(canvas, 0.0, ui.visuals().extreme_bg_color);
        painter.add(egui_wgpu::Callback::new_paint_callback(
            canvas,
            renderer::CloudCallback { rect: canvas, transform, style, spacing: packed.spacing },
        ));

        let radius = (style.point_size / 2.0 + 1.0).max(3.0);
        let hovered = pick_points(ui, &response, runtime, &packed, cloud, &transform, points_key, radius, rt.commands);

        // The selected pixel's point, wherever it was selected.
        let selected = rt.selection.filter(|s| s.camera == CLOUD_CAMERA && s.u < cloud.grid_width).and_then(|s| {
            let index_map = source.derived.point_index.as_ref()?;
            let index = *index_map.get(s.v * cloud.grid_width + s.u)?;
            (index != u32::MAX).then_some((s, index as usize))
        });
        if let Some((_, index)) = selected
            && let Some(p) = packed.scene_point(index, z_scale)
            && let Some(s) = camera.project(&p, &viewport)
        {
            let c = egui::pos2(s.pos[0] as f32, s.pos[1] as f32);
            if canvas.contains(c) {
                marker(&painter, c);
            }
        }
        if self.settings.z_exaggeration != 1.0 {
            painter.text(
                canvas.right_bottom() - vec2(4.0, 4.0),
                egui::Align2::RIGHT_BOTTOM,
                format!("Z exaggerated {:.1}×", self.settings.z_exaggeration),
                egui::FontId::proportional(11.0),
                ui.visuals().weak_text_color(),
            );
        }

        footer(ui, [avail.x, footer_h], hovered.as_ref(), selected, cloud, &source, rt);
    }
}

/// The two lines under the canvas: the hovered point, and the selected one
/// with "Sections here".
fn footer(
    ui: &mut egui::Ui,
    [width, footer_h]: [f32; 2],
    hovered: Option<&PointInfo>,
    selected: Option<(PixelRef, usize)>,
    cloud: &PointCloud,
    source: &ResultSet,
    rt: &mut ViewRuntime<'_>,
) {
    let hover_text = match hovered {
        Some(info) => info.describe(),
        None => "Drag orbits · right-drag or shift-drag pans · wheel zooms · click selects a pixel".to_owned(),
    };
    let line = |ui: &mut egui::Ui, text: String| {
        ui.add_sized([width, footer_h / 2.0], egui::Label::new(egui::RichText::new(text).monospace()).truncate());
    };
    line(ui, hover_text);
    let selected_text = match selected {
        Some((s, index)) => match PointInfo::of(cloud, index) {
            Some(info) => format!("Selected: {}", info.describe()),
            None => format!("Selected pixel u {}, v {}", s.u, s.v),
        },
        None => match rt.selection.filter(|s| s.camera == CLOUD_CAMERA) {
            Some(s) => format!("Selected pixel u {}, v {}: no 3D point there", s.u, s.v),
            None => format!("{} points · Z in {}", cloud.len(), source.derived.height_unit),
        },
    };
    // A picked point leads to the section tools: profiles through it.
    let selected_xy_mm = selected.and_then(|(_, index)| {
        let p = cloud.xyz.get(index)?;
        let mm = cloud.unit.mm_per_unit();
        Some([p[0] * mm, p[1] * mm])
    });
    ui.allocate_ui(vec2(width, footer_h / 2.0), |ui| {
        ui.horizontal(|ui| {
            if let Some([x_mm, y_mm]) = selected_xy_mm
                && ui
                    .small_button("Sections here")
                    .on_hover_text("Horizontal and vertical section profiles through this point, in the Inspect view")
                    .clicked()
            {
                rt.commands.push(Command::SectionsThrough { x_mm, y_mm });
            }
            ui.add(egui::Label::new(egui::RichText::new(selected_text).monospace()).truncate());
        });
    });
}

/// The view presets and Reset view; the one clicked, if any.
fn preset_toolbar(ui: &mut egui::Ui) -> Option<ViewPreset> {
    let mut preset = None;
    ui.horizontal(|ui| {
        ui.label("View:");
        for p in ViewPreset::ALL {
            let tip = match p {
                ViewPreset::Top => "Look straight down: X right, Y up, like the height map.",
                ViewPreset::Front => "Look along +Y: X right, Z up.",
                ViewPreset::Side => "Look along -X: Y right, Z up.",
                ViewPreset::Oblique => "From the front right and above.",
            };
            if ui.button(p.name()).on_hover_text(tip).clicked() {
                preset = Some(p);
            }
        }
        if ui
            .button("Reset view")
            .on_hover_text("The whole cloud from the oblique view (R, or double-click).")
            .clicked()
        {
            preset = Some(HOME_PRESET);
        }
    });
    preset
}

/// Picking: hovering reads a point's values (cached while nothing moves), a
/// click selects its pixel in every view.
#[allow(clippy::too_many_arguments)]
fn pick_points(
    ui: &egui::Ui,
    response: &egui::Response,
    runtime: &mut CloudRuntime,
    packed: &PackedCloud,
    cloud: &PointCloud,
    transform: &ScreenTransform,
    points_key: u64,
    radius: f32,
    commands: &mut Vec<Command>,
) -> Option<PointInfo> {
    let dragging = response.dragged() || ui.input(|i| i.pointer.any_down());
    let hovered = match response.hover_pos() {
        Some(pos) if !dragging => {
            let key = HoverKey { pointer: [pos.x, pos.y], transform: *transform, points_key };
            match &runtime.hover {
                Some((k, info)) if *k == key => info.clone(),
                _ => {
                    let info =
                        pick(packed, transform, [pos.x, pos.y], radius).and_then(|p| PointInfo::of(cloud, p.index));
                    runtime.hover = Some((key, info.clone()));
                    info
                }
            }
        }
        _ => None,
    };
    if !response.hovered() {
        runtime.hover = None;
    }
    if response.clicked()
        && let Some(pos) = response.interact_pointer_pos()
    {
        let info = pick(packed, transform, [pos.x, pos.y], radius).and_then(|p| PointInfo::of(cloud, p.index));
        if let Some([u, v]) = info.and_then(|i| i.pixel) {
            commands.push(Command::SelectPixel(PixelRef { camera: CLOUD_CAMERA, u, v }));
        }
    }
    hovered
}

/// Mouse and keyboard gestures on the canvas; returns whether the view is to
/// be reset (double-click, or R with the view focused).
fn interact(ui: &egui::Ui, response: &egui::Response, camera: &mut OrbitCamera, viewport: &Viewport) -> bool {
    if response.clicked() || response.drag_started() {
        response.request_focus();
    }
    let (shift, pointer) = ui.input(|i| (i.modifiers.shift, i.pointer.clone()));
    if response.dragged() {
        let d = response.drag_delta();
        let (dx, dy) = (f64::from(d.x), f64::from(d.y));
        let panning = response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (shift && response.dragged_by(egui::PointerButton::Primary));
        if panning {
            camera.pan(dx, dy, viewport);
        } else if response.dragged_by(egui::PointerButton::Primary) {
            camera.orbit(dx, dy);
        }
    }
    if response.hovered() {
        let (scroll, pinch) = ui.input(|i| (i.smooth_scroll_delta.y, i.zoom_delta()));
        let factor = (-f64::from(scroll) * WHEEL_ZOOM_PER_POINT).exp() / f64::from(pinch).max(1e-3);
        if (factor - 1.0).abs() > 1e-6
            && let Some(pos) = pointer.hover_pos()
        {
            camera.zoom_towards(factor, [f64::from(pos.x), f64::from(pos.y)], viewport);
        }
    }
    let mut reset = response.double_clicked();
    if response.has_focus() {
        // Keep the arrows for the view instead of moving the focus.
        ui.memory_mut(|m| {
            m.set_focus_lock_filter(
                response.id,
                egui::EventFilter { horizontal_arrows: true, vertical_arrows: true, ..egui::EventFilter::default() },
            )
        });
        let pressed = |key| ui.input(|i| i.key_pressed(key) && i.modifiers.is_none());
        let centre = [viewport.min[0] + viewport.size[0] / 2.0, viewport.min[1] + viewport.size[1] / 2.0];
        for (key, dx, dy) in [
            (Key::ArrowLeft, -KEY_ORBIT, 0.0),
            (Key::ArrowRight, KEY_ORBIT, 0.0),
            (Key::ArrowUp, 0.0, -KEY_ORBIT),
            (Key::ArrowDown, 0.0, KEY_ORBIT),
        ] {
            if pressed(key) {
                camera.orbit(dx, dy);
            }
        }
        if pressed(Key::Plus) || pressed(Key::Equals) {
            camera.zoom_towards(1.0 / KEY_ZOOM, centre, viewport);
        }
        if pressed(Key::Minus) {
            camera.zoom_towards(KEY_ZOOM, centre, viewport);
        }
        reset |= pressed(Key::R);
    }
    reset
}

/// A crosshair ring at a selected point (as on the 2D maps).
fn marker(painter: &egui::Painter, c: Pos2) {
    let outer = Stroke::new(3.0, Color32::BLACK);
    let inner = Stroke::new(1.5, Color32::from_rgb(0, 230, 255));
    for stroke in [outer, inner] {
        painter.circle_stroke(c, 7.0, stroke);
        for (a, b) in [
            (vec2(-13.0, 0.0), vec2(-7.0, 0.0)),
            (vec2(7.0, 0.0), vec2(13.0, 0.0)),
            (vec2(0.0, -13.0), vec2(0.0, -7.0)),
            (vec2(0.0, 7.0), vec2(0.0, 13.0)),
        ] {
            painter.line_segment([c + a, c + b], stroke);
        }
    }
}
