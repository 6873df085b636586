//! A camera–projector rig with pinhole optics (issue 52, item 5): one
//! entocentric camera looking at the stage from the side and a projector
//! (an inverse camera) straight above it, projecting phase sets along x and
//! y, OpenCV's Gray code with inverse frames, white and black, onto the
//! simulator's scenes. The result is an in-memory [`Measurement`] with the
//! true [`CameraProjectorCalibration`] and the truth of every camera pixel
//! (its surface point in the camera's frame and the projector point that
//! lights it), so every stage of the camera–projector pipeline is checked
//! against what was rendered.
//!
//! Geometry, world millimetres as in [`rig`](super::rig) (X right, Y up the
//! image, Z up): the projector's centre is `working_distance_mm` above the
//! scene's focus, its axis straight down; the camera's centre is as far
//! from the focus point, turned `triangulation_angle_deg` from the vertical
//! towards -X. Both devices follow OpenCV's conventions (x right, y down,
//! z forward), so the camera's rows run along -Y like the telecentric rig's.
//!
//! Shading uses the scenes' materials with the light straight down (the
//! projector's rays are within 7° of vertical over the field); a point the
//! projector's ray meets something else before is in shadow (ambient light
//! only). The projector's gamma bends the fringes (`s^gamma`, `s` the
//! pattern value in 0..1) but not the code, which is 0 or 1.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::Serialize;

use super::raycast::{BoundGrid, cast};
use super::render::stream_seed;
use super::rig::Ray;
use super::scene_model::{Scene, SceneKind};
use super::target::{Paint, Pattern, TargetLook};
use super::{BOUND_MAX_SLOPE, BOUND_SAMPLE_MM, SimError, scenes};
use crate::engine::calibration::model::Pose as TargetPose;
use crate::engine::calibration::target::{Target, TargetKind};
use crate::engine::camera_projector::{CameraPatterns, GrayCodeLayout, ProjectorPatterns};
use crate::engine::control::RunControl;
use crate::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Measurement, Samples, next_measurement_id};
use crate::engine::gray_code::{bit_planes, pattern_is_bright};
use crate::engine::length_unit::LengthUnit;
use crate::engine::pinhole::{CameraProjectorCalibration, PinholeDevice};

/// The camera's name in the measurement and its files.
pub const CAMERA_NAME: &str = "camera";

/// Everything that defines a simulated camera–projector measurement.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PinholeRigConfig {
    pub scene: SceneKind,
    pub camera_width: usize,
    pub camera_height: usize,
    pub projector_width: usize,
    pub projector_height: usize,
    /// Phase set periods in projector pixels, sparsest first; the same sets
    /// are projected along x and along y.
    pub periods_px: Vec<f64>,
    pub shifts: usize,
    /// Image k of a set is shifted by `2 pi k / N + shift_offset_rad`.
    pub shift_offset_rad: f64,
    /// Projector pixels per Gray code cell.
    pub cell_px: u32,
    /// The projector's gamma: a pattern value `s` lights the scene with `s^gamma`.
    pub projector_gamma: f64,
    pub bits: u32,
    pub noise_sigma_dn: f64,
    pub seed: u64,
    /// Camera gain relative to the scene's nominal exposure.
    pub gain: f64,
    /// Ambient light as a fraction of the projector's white.
    pub ambient: f64,
    /// Radial distortion k1 of the camera (the projector gets half of it).
    pub distortion_k1: f64,
    /// Angle between the camera's axis and the projector's.
    pub triangulation_angle_deg: f64,
    /// Distance from each device's centre to the scene's focus point.
    pub working_distance_mm: f64,
}

impl PinholeRigConfig {
    /// A bench rig: a 640 x 480 camera seeing the 32 x 24 mm field, a
    /// 1280 x 800 projector covering 36 mm, 200 mm away at 20°, two 3-step
    /// sets of 48 and 32 px per axis (their 96 px beat ordered by a 32 px
    /// code), shifts -2π/3, 0, 2π/3 (OpenCV's), 8 bits, 1 DN of noise, a
    /// linear projector.
    pub fn new(scene: SceneKind) -> Self {
        Self {
            scene,
            camera_width: 640,
            camera_height: 480,
            projector_width: 1280,
            projector_height: 800,
            periods_px: vec![48.0, 32.0],
            shifts: 3,
            shift_offset_rad: -std::f64::consts::TAU / 3.0,
            cell_px: 32,
            projector_gamma: 1.0,
            bits: 8,
            noise_sigma_dn: 1.0,
            seed: 1,
            gain: 1.0,
            ambient: 0.03,
            distortion_k1: 0.0,
            triangulation_angle_deg: 20.0,
            working_distance_mm: 200.0,
        }
    }

    pub fn full_scale_dn(&self) -> f64 {
        f64::from((1u32 << self.bits.clamp(1, 16)) - 1)
    }

    /// The sets as the manifest describes them (one axis).
    pub fn fringe_sets(&self) -> Vec<FringeSetInfo> {
        let n = self.shifts;
        let shifts: Vec<f64> =
            (0..n).map(|k| std::f64::consts::TAU * k as f64 / n as f64 + self.shift_offset_rad).collect();
        self.periods_px.iter().map(|&period_px| FringeSetInfo { period_px, phase_shifts_rad: shifts.clone() }).collect()
    }

    /// Checks every setting; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), SimError> {
        let setting = |ok: bool, setting: &'static str, found: String, expected: &'static str| {
            if ok { Ok(()) } else { Err(SimError::Setting { setting, found, expected }) }
        };
        let (w, h) = (self.camera_width, self.camera_height);
        if w < super::MIN_SIDE_PX || h < super::MIN_SIDE_PX || w.saturating_mul(h) > super::MAX_PIXELS {
            return Err(SimError::ImageSize { width: w, height: h });
        }
        setting((8..=16).contains(&self.bits), "bits", self.bits.to_string(), "8 to 16")?;
        setting(
            (64..=8192).contains(&self.projector_width) && (64..=8192).contains(&self.projector_height),
            "projector",
            format!("{}x{}", self.projector_width, self.projector_height),
            "64 to 8192 pixels a side",
        )?;
        setting(self.shifts >= 3 && self.shifts <= 64, "shifts", self.shifts.to_string(), "3 to 64")?;
        setting(
            !self.periods_px.is_empty() && self.periods_px.iter().all(|p| p.is_finite() && *p >= 3.0),
            "periods",
            format!("{:?}", self.periods_px),
            "at least one period of 3 projector pixels or more",
        )?;
        for (set, pair) in self.periods_px.windows(2).enumerate() {
            if pair[1] >= pair[0] {
                return Err(SimError::PeriodOrder { set: set + 1, period_px: pair[1], previous_px: pair[0] });
            }
        }
        setting(
            self.cell_px >= 1 && (self.cell_px as usize) < self.projector_width.min(self.projector_height),
            "gray-code cell",
            self.cell_px.to_string(),
            "1 projector pixel or more, less than the projector's side",
        )?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        setting(
            positive(self.projector_gamma) && self.projector_gamma <= 5.0,
            "gamma",
            self.projector_gamma.to_string(),
            "above 0, at most 5",
        )?;
        setting(
            self.noise_sigma_dn.is_finite() && self.noise_sigma_dn >= 0.0,
            "noise",
            self.noise_sigma_dn.to_string(),
            "0 or more grey levels",
        )?;
        setting(positive(self.gain), "gain", self.gain.to_string(), "above 0")?;
        setting(
            self.ambient.is_finite() && (0.0..=1.0).contains(&self.ambient),
            "ambient",
            self.ambient.to_string(),
            "0 to 1",
        )?;
        setting(
            self.distortion_k1.is_finite() && self.distortion_k1.abs() <= 0.5,
            "distortion",
            self.distortion_k1.to_string(),
            "-0.5 to 0.5",
        )
    }
}

/// What each camera pixel really sees.
#[derive(Clone, Debug, PartialEq)]
pub struct PinholeTruth {
    pub width: usize,
    pub height: usize,
    /// The first surface point on the pixel's ray, in the camera's frame
    /// (mm); NaN where the ray misses the scene.
    pub point_camera_mm: Vec<[f64; 3]>,
    /// The projector point `(x_p, y_p)` lighting the surface point; NaN
    /// where the projector does not light it (shadow, a wall, outside its
    /// image).
    pub projector_px: Vec<[f64; 2]>,
    /// The camera's frame from the simulator's world (`X_c = R X_w + t`):
    /// where a scene's landmarks lie in the cloud.
    pub camera_from_world: TargetPose,
}

impl PinholeTruth {
    pub fn is_lit(&self, pixel: usize) -> bool {
        !self.projector_px[pixel][0].is_nan()
    }

    pub fn lit_count(&self) -> usize {
        (0..self.projector_px.len()).filter(|&i| self.is_lit(i)).count()
    }
}

/// A simulated camera–projector measurement and its truth.
#[derive(Clone, Debug)]
pub struct PinholeSimulation {
    /// The frames, with the true calibration in `projector.calibration`.
    pub measurement: Measurement,
    pub calibration: CameraProjectorCalibration,
    pub truth: PinholeTruth,
    pub config: PinholeRigConfig,
}

/// A device's pose: `X_device = rotation (X_world - centre)`.
#[derive(Clone, Copy, Debug)]
struct Pose {
    rotation: [[f64; 3]; 3],
    centre: [f64; 3],
}

impl Pose {
    /// Looking at `target` from `distance` away, turned `angle` about the
    /// world's Y axis from the vertical (positive: the device stands at -X).
    fn looking_down(target: [f64; 3], distance: f64, angle_rad: f64) -> Self {
        let (s, c) = angle_rad.sin_cos();
        let centre = [target[0] - distance * s, target[1], target[2] + distance * c];
        // Rows: the device's x (right), y (down the image, along -Y) and z (forward) in world axes.
        Self { rotation: [[c, 0.0, s], [0.0, -1.0, 0.0], [s, 0.0, -c]], centre }
    }

    fn to_device(self, p: [f64; 3]) -> [f64; 3] {
        let d: [f64; 3] = std::array::from_fn(|i| p[i] - self.centre[i]);
        std::array::from_fn(|i| (0..3).map(|k| self.rotation[i][k] * d[k]).sum())
    }

    /// The world direction of a device-frame direction.
    fn to_world_direction(self, d: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|k| self.rotation[k][i] * d[k]).sum())
    }

    /// The world ray through the device's centre along world direction `d`
    /// (`d[2] != 0`), as the caster takes it.
    fn ray(self, d: [f64; 3]) -> Ray {
        let slope = [d[0] / d[2], d[1] / d[2]];
        Ray {
            origin_mm: [self.centre[0] - slope[0] * self.centre[2], self.centre[1] - slope[1] * self.centre[2]],
            slope,
        }
    }
}

/// One camera pixel's view: what the frames need and what the truth keeps.
#[derive(Clone, Copy, Debug)]
struct PixelView {
    point_camera_mm: [f64; 3],
    projector_px: [f64; 2],
    /// Grey levels of the projector's white reflected towards the camera.
    white_dn: f64,
    /// Grey levels of the ambient light.
    ambient_dn: f64,
}

impl PixelView {
    const MISS: PixelView =
        PixelView { point_camera_mm: [f64::NAN; 3], projector_px: [f64::NAN; 2], white_dn: 0.0, ambient_dn: 0.0 };
}

/// Renders the measurement `config` describes. Stages "simulate: ..." go
/// through `control`.
pub fn simulate_camera_projector(
    config: &PinholeRigConfig,
    control: &RunControl,
) -> Result<PinholeSimulation, SimError> {
    config.validate()?;
    let scene = scenes::build(config.scene);
    let (w, h) = (config.camera_width, config.camera_height);
    let field_x_mm = scene.extent.x_max_mm - scene.extent.x_min_mm;
    let (camera_pose, projector_pose, calibration) = rig_geometry(config, [0.0, 0.0, scene.focus_z_mm], field_x_mm);

    control.begin_stage("simulate: bounding the scene");
    let pitch_mm = field_x_mm / w as f64;
    let step_mm = pitch_mm / 8.0;
    let cell_mm = 4.0 * pitch_mm;
    let samples = (cell_mm / pitch_mm.min(BOUND_SAMPLE_MM)).ceil() as usize;
    let grid = BoundGrid::new(&scene, scene.extent, cell_mm, samples, BOUND_MAX_SLOPE);
    control.check()?;

    control.begin_stage("simulate: ray casting the camera and the projector");
    let scale_dn = config.full_scale_dn() * scene.exposure * config.gain;
    let views: Vec<PixelView> =
        (0..w * h)
            .into_par_iter()
            .map(|i| {
                if control.is_cancelled() {
                    return PixelView::MISS;
                }
                view_pixel(&scene, &grid, &calibration, (&camera_pose, &projector_pose), (i % w, i / w), step_mm)
                    .map_or(PixelView::MISS, |(point, projector_px, white, ambient)| PixelView {
                        point_camera_mm: point,
                        projector_px,
                        white_dn: scale_dn * white,
                        ambient_dn: scale_dn * config.ambient * ambient,
                    })
            })
            .collect();
    control.check()?;

    let label = format!(
        "simulated {} through a camera–projector rig ({}x{} px, projector {}x{}, gamma {}, noise {} DN, seed {})",
        config.scene,
        w,
        h,
        config.projector_width,
        config.projector_height,
        config.projector_gamma,
        config.noise_sigma_dn,
        config.seed
    );
    let measurement = render_measurement(config, &views, &calibration, label, control)?;
    let truth = PinholeTruth {
        camera_from_world: TargetPose {
            rotation: camera_pose.rotation,
            translation_mm: camera_pose.to_device([0.0; 3]),
        },
        width: w,
        height: h,
        point_camera_mm: views.iter().map(|v| v.point_camera_mm).collect(),
        projector_px: views.iter().map(|v| v.projector_px).collect(),
    };
    Ok(PinholeSimulation { measurement, calibration, truth, config: config.clone() })
}

/// The camera's and the projector's poses in the world, both `working_distance_mm`
/// from `focus` (the projector straight above it, the camera turned
/// `triangulation_angle_deg` towards -X), and the rig's calibration: the
/// camera sees 94 % of `field_x_mm`, the projector lights 112.5 % of it.
fn rig_geometry(
    config: &PinholeRigConfig,
    focus: [f64; 3],
    field_x_mm: f64,
) -> (Pose, Pose, CameraProjectorCalibration) {
    let distance = config.working_distance_mm;
    let camera_pose = Pose::looking_down(focus, distance, config.triangulation_angle_deg.to_radians());
    let projector_pose = Pose::looking_down(focus, distance, 0.0);
    let device = |width: usize, height: usize, covered_mm: f64, k1: f64| {
        let f = width as f64 * distance / covered_mm;
        PinholeDevice {
            width,
            height,
            fx: f,
            fy: f,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            distortion: [k1, 0.0, 0.0, 0.0, 0.0],
        }
    };
    let camera = device(config.camera_width, config.camera_height, field_x_mm * 0.94, config.distortion_k1);
    let projector =
        device(config.projector_width, config.projector_height, field_x_mm * 1.125, config.distortion_k1 / 2.0);
    // X_p = R_p (R_c^T X_c + C_c - C_p).
    let rp = projector_pose.rotation;
    let rc = camera_pose.rotation;
    let r: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| rp[i][k] * rc[j][k]).sum()));
    let t = projector_pose.to_device(camera_pose.centre);
    (camera_pose, projector_pose, CameraProjectorCalibration { unit: LengthUnit::Mm, camera, projector, r, t })
}

/// Every frame the rig projects (the sets along x and y, the column and row
/// codes with their inverses, white and black) as the camera records them
/// over `views`.
fn render_measurement(
    config: &PinholeRigConfig,
    views: &[PixelView],
    calibration: &CameraProjectorCalibration,
    label: String,
    control: &RunControl,
) -> Result<Measurement, SimError> {
    let (w, h) = (config.camera_width, config.camera_height);
    control.begin_stage("simulate: rendering the frames");
    let sets = config.fringe_sets();
    let layout = GrayCodeLayout { cell_px: config.cell_px, rows: true };
    let render = |frames: &[Frame], first: usize| stack(config, views, frames, first);
    let mut frame_index = 0;
    let mut next_stacks = |axis: Axis| -> Vec<FringeStack> {
        sets.iter()
            .map(|set| {
                let frames: Vec<Frame> = set
                    .phase_shifts_rad
                    .iter()
                    .map(|&shift_rad| Frame::Fringe { axis, period_px: set.period_px, shift_rad })
                    .collect();
                let s = render(&frames, frame_index);
                frame_index += frames.len();
                s
            })
            .collect()
    };
    let x_stacks = next_stacks(Axis::X);
    let y_stacks = next_stacks(Axis::Y);
    control.check()?;
    let mut code = |axis: Axis, extent_px: usize| {
        let planes = bit_planes(layout.cells(extent_px));
        let frames: Vec<Frame> = (0..planes)
            .flat_map(|plane| [false, true].map(|inverse| Frame::Code { axis, planes, plane, inverse }))
            .collect();
        let s = render(&frames, frame_index);
        frame_index += frames.len();
        s
    };
    let gray_columns = code(Axis::X, config.projector_width);
    let gray_rows = code(Axis::Y, config.projector_height);
    let white_black = render(&[Frame::Uniform(1.0), Frame::Uniform(0.0)], frame_index);
    control.check()?;

    Ok(Measurement {
        bit_depth: config.bits,
        saturation_level: config.full_scale_dn() as u16,
        sets: sets.clone(),
        cameras: vec![CameraFringes { name: CAMERA_NAME.to_owned(), width: w, height: h, stacks: x_stacks }],
        calibration: None,
        label,
        projector: Some(ProjectorPatterns {
            projector_width_px: config.projector_width,
            projector_height_px: config.projector_height,
            y_sets: sets,
            gray_code: Some(layout),
            cameras: vec![CameraPatterns {
                y_stacks,
                gray_columns: Some(gray_columns),
                gray_rows: Some(gray_rows),
                white_black: Some(white_black),
            }],
            calibration: Some(calibration.clone()),
        }),
        id: next_measurement_id(),
    })
}

/// The field of every scene, along x (the scenes' common extent).
const FIELD_X_MM: f64 = 32.0;

/// The calibration target for this rig: a 9 x 11 grid of `kind` at 1.5 mm
/// pitch, about 60 % of the camera's field high.
pub fn rig_calibration_target(kind: TargetKind) -> Target {
    Target { kind, rows: 9, cols: 11, pitch_mm: 1.5, dark_on_light: true }
}

/// `count` poses of `target` (target frame → world) around the rig's focus:
/// pose 0 flat, the others tilted by `tilt_deg` (or 70 % of it about both
/// axes) towards directions spread around the circle, turned a few degrees
/// in their plane and a little nearer or farther, as an operator holds a
/// plate for a pinhole calibration (Zhang 2000 needs the tilts).
pub fn calibration_poses(target: &Target, count: usize, tilt_deg: f64) -> Vec<TargetPose> {
    let t = tilt_deg;
    let d = 0.7 * t;
    let tilts = [
        [0.0, 0.0, 2.0],
        [t, 0.0, 5.0],
        [-t, 0.0, -5.0],
        [0.0, t, 3.0],
        [0.0, -t, -3.0],
        [d, d, 0.0],
        [-d, d, 8.0],
        [d, -d, -8.0],
    ];
    (0..count)
        .map(|k| {
            let lap = (k / tilts.len()) as f64;
            let deg = tilts[k % tilts.len()];
            let z_mm = [0.0, 6.0, -6.0, 4.0, -4.0, 8.0, -8.0, 2.0][k % 8] + 0.7 * lap;
            let rotation_rad = [deg[0].to_radians(), deg[1].to_radians(), (deg[2] + 11.0 * lap).to_radians()];
            super::target::centred_pose(target, rotation_rad, [0.4 * lap, -0.3 * lap, z_mm])
        })
        .collect()
}

/// One simulated pose of a calibration set for this rig: every frame the
/// rig projects onto the target, and the truth.
#[derive(Clone, Debug)]
pub struct CalibrationPoseSimulation {
    pub measurement: Measurement,
    /// The target's frame in the camera's (`X_c = R x + t`).
    pub target_in_camera: TargetPose,
    /// The true camera and projector pixel of every target point (row-major).
    pub camera_points_px: Vec<[f64; 2]>,
    pub projector_points_px: Vec<[f64; 2]>,
}

/// The rig's true calibration (the same for every scene: both devices look
/// at the scene's focus from the same place relative to it).
pub fn rig_calibration(config: &PinholeRigConfig) -> CameraProjectorCalibration {
    rig_geometry(config, [0.0; 3], FIELD_X_MM).2
}

/// Renders `target` in `pose` (target frame → world, the focus at the
/// origin) under every frame of the rig: the plate and its print reflect
/// diffusely (`look`'s grey levels as albedo), each pixel's print averaged
/// over 4 x 4 sub-samples so the dots' edges are anti-aliased; beyond the
/// plate the surround continues the plane.
pub fn simulate_calibration_pose(
    config: &PinholeRigConfig,
    target: &Target,
    look: &TargetLook,
    pose: &TargetPose,
    index: usize,
    control: &RunControl,
) -> Result<CalibrationPoseSimulation, SimError> {
    config.validate()?;
    let (camera_pose, projector_pose, calibration) = rig_geometry(config, [0.0; 3], FIELD_X_MM);
    let (w, h) = (config.camera_width, config.camera_height);
    let pattern = Pattern { target, look };
    let full = f64::from(look.full_scale_dn);
    let albedo = |paint: Paint| match paint {
        Paint::Plate => look.plate_dn / full,
        Paint::Ink => look.ink_dn / full,
        Paint::Surround => look.surround_dn / full,
    };
    let normal = pose.normal();
    let origin = pose.translation_mm;
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // The target-plane point a camera pixel (sub-sample) sees, in the world.
    let on_plane = |u: f64, v: f64| -> Option<[f64; 3]> {
        let (x, y) = calibration.camera.undistort(u, v);
        let d = camera_pose.to_world_direction([x, y, 1.0]);
        let c = camera_pose.centre;
        let s = dot(normal, std::array::from_fn(|i| origin[i] - c[i])) / dot(normal, d);
        (s.is_finite() && s > 0.0).then(|| std::array::from_fn(|i| c[i] + s * d[i]))
    };
    let in_target = |p: [f64; 3]| {
        let q: [f64; 3] = std::array::from_fn(|i| p[i] - origin[i]);
        let r = &pose.rotation;
        [(0..3).map(|k| r[k][0] * q[k]).sum::<f64>(), (0..3).map(|k| r[k][1] * q[k]).sum::<f64>()]
    };
    let scale_dn = config.full_scale_dn() * 0.95 * config.gain;
    control.begin_stage(&format!("simulate: calibration pose {index}"));
    let views: Vec<PixelView> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (u, v) = ((i % w) as f64, (i / w) as f64);
            let Some(p) = on_plane(u, v) else { return PixelView::MISS };
            let mut sum = 0.0;
            for a in 0..4 {
                for b in 0..4 {
                    let sub = on_plane(u + (a as f64 + 0.5) / 4.0 - 0.5, v + (b as f64 + 0.5) / 4.0 - 0.5);
                    sum += sub.map_or(0.0, |q| {
                        let [x, y] = in_target(q);
                        albedo(pattern.paint(x, y).0)
                    });
                }
            }
            let a = sum / 16.0;
            let (up, vp) = calibration.projector.project(projector_pose.to_device(p));
            let inside = (-0.5..config.projector_width as f64 - 0.5).contains(&up)
                && (-0.5..config.projector_height as f64 - 0.5).contains(&vp);
            let to_projector: [f64; 3] = std::array::from_fn(|k| projector_pose.centre[k] - p[k]);
            let cos = dot(normal, to_projector) / dot(to_projector, to_projector).sqrt();
            PixelView {
                point_camera_mm: camera_pose.to_device(p),
                projector_px: if inside && cos > 0.0 { [up, vp] } else { [f64::NAN; 2] },
                white_dn: scale_dn * a * cos.max(0.0),
                ambient_dn: scale_dn * config.ambient * a,
            }
        })
        .collect();
    control.check()?;
    let label = format!(
        "simulated {} x {} {} calibration target, pose {index}, through a camera–projector rig ({w}x{h} px, \
         projector {}x{}, noise {} DN, seed {})",
        target.rows,
        target.cols,
        target.kind,
        config.projector_width,
        config.projector_height,
        config.noise_sigma_dn,
        config.seed
    );
    // Each pose its own noise.
    let posed = PinholeRigConfig { seed: config.seed.wrapping_add(1000 * (index as u64 + 1)), ..config.clone() };
    let measurement = render_measurement(&posed, &views, &calibration, label, control)?;
    let to_camera = TargetPose { rotation: camera_pose.rotation, translation_mm: camera_pose.to_device([0.0; 3]) };
    let target_in_camera = to_camera.compose(pose);
    let points = target.points_mm();
    let camera_points_px = points
        .iter()
        .map(|&x| {
            let (u, v) = calibration.camera.project(target_in_camera.apply(x));
            [u, v]
        })
        .collect();
    let projector_points_px = points
        .iter()
        .map(|&x| {
            let (u, v) = calibration.projector.project(projector_pose.to_device(pose.apply(x)));
            [u, v]
        })
        .collect();
    Ok(CalibrationPoseSimulation { measurement, target_in_camera, camera_points_px, projector_points_px })
}

/// Camera pixel `(u, v)`: its surface point in the camera's frame, the
/// projector point lighting it (NaN in shadow), and its reflected white and
/// ambient light as fractions of full scale per unit exposure. `None` where
/// the ray misses the scene.
fn view_pixel(
    scene: &Scene,
    grid: &BoundGrid,
    calibration: &CameraProjectorCalibration,
    (camera_pose, projector_pose): (&Pose, &Pose),
    (u, v): (usize, usize),
    step_mm: f64,
) -> Option<([f64; 3], [f64; 2], f64, f64)> {
    let (x, y) = calibration.camera.undistort(u as f64, v as f64);
    let direction = camera_pose.to_world_direction([x, y, 1.0]);
    let hit = cast(scene, grid, &camera_pose.ray(direction), step_mm)?;
    let p = hit.point_mm;
    let point_camera = camera_pose.to_device(p);
    let stage = scene.stage_point(p[0], p[1])?;
    let material = scene.material_of(stage.feature);
    let ambient = material.albedo;
    // In the projector's light: not on a wall, nothing in between, inside its image.
    let to_projector: [f64; 3] = std::array::from_fn(|i| p[i] - projector_pose.centre[i]);
    let first = cast(scene, grid, &projector_pose.ray(to_projector), step_mm)?;
    let gap = (0..3).map(|i| (first.point_mm[i] - p[i]).powi(2)).sum::<f64>().sqrt();
    let (up, vp) = calibration.projector.project(projector_pose.to_device(p));
    let inside = (-0.5..calibration.projector.width as f64 - 0.5).contains(&up)
        && (-0.5..calibration.projector.height as f64 - 0.5).contains(&vp);
    if hit.on_wall || gap > 1e-6 || !inside {
        return Some((point_camera, [f64::NAN; 2], 0.0, ambient));
    }
    let g = stage.surface;
    let norm = (g.dz_dx * g.dz_dx + g.dz_dy * g.dz_dy + 1.0).sqrt();
    let normal = [-g.dz_dx / norm, -g.dz_dy / norm, 1.0 / norm];
    let to_camera: [f64; 3] = {
        let d: [f64; 3] = std::array::from_fn(|i| camera_pose.centre[i] - p[i]);
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|c| c / n)
    };
    let white = material.reflectance(normal, to_camera, p[0], p[1]);
    Some((point_camera, [up, vp], white, ambient))
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Axis {
    X,
    Y,
}

/// What the projector shows in one frame.
#[derive(Clone, Copy, Debug)]
enum Frame {
    /// `s = (1 + cos(2 pi x / p + delta)) / 2` along the axis.
    Fringe {
        axis: Axis,
        period_px: f64,
        shift_rad: f64,
    },
    /// Bit `plane` (most significant first) of the Gray code of the cell, or its inverse.
    Code {
        axis: Axis,
        planes: usize,
        plane: usize,
        inverse: bool,
    },
    Uniform(f64),
}

impl Frame {
    /// The pattern's value in 0..1 at projector point `(x, y)`, before gamma.
    fn value(&self, [x, y]: [f64; 2], cell_px: u32) -> f64 {
        let along = |axis: Axis| if axis == Axis::X { x } else { y };
        match *self {
            Frame::Fringe { axis, period_px, shift_rad } => {
                0.5 * (1.0 + (std::f64::consts::TAU * along(axis) / period_px + shift_rad).cos())
            }
            Frame::Code { axis, planes, plane, inverse } => {
                // The projector pixel lit: pixel centres are at integer coordinates.
                let pixel = (along(axis) + 0.5).floor().max(0.0);
                let cell = (pixel / f64::from(cell_px)) as u32;
                f64::from(u8::from(pattern_is_bright(cell, planes, plane) != inverse))
            }
            Frame::Uniform(s) => s,
        }
    }
}

/// The stack of `frames` (numbered from `first` for the noise streams).
fn stack(config: &PinholeRigConfig, views: &[PixelView], frames: &[Frame], first: usize) -> FringeStack {
    let (w, h) = (config.camera_width, config.camera_height);
    let full_scale = config.full_scale_dn();
    let plane = |k: usize| -> Vec<f64> {
        let frame = frames[k];
        (0..h)
            .into_par_iter()
            .flat_map_iter(|row| {
                let mut rng = ChaCha8Rng::seed_from_u64(stream_seed(config.seed, 0, first + k, 0, row));
                views[row * w..(row + 1) * w]
                    .iter()
                    .map(|view| {
                        let lit = if view.projector_px[0].is_nan() {
                            0.0
                        } else {
                            let s = frame.value(view.projector_px, config.cell_px);
                            view.white_dn * s.powf(config.projector_gamma)
                        };
                        let noise: f64 = StandardNormal.sample(&mut rng);
                        (lit + view.ambient_dn + config.noise_sigma_dn * noise).round().clamp(0.0, full_scale)
                    })
                    .collect::<Vec<f64>>()
            })
            .collect()
    };
    let planes: Vec<Vec<f64>> = (0..frames.len()).map(plane).collect();
    let samples = if config.bits <= 8 {
        Samples::U8(planes.iter().flatten().map(|&v| v as u8).collect())
    } else {
        Samples::U16(planes.iter().flatten().map(|&v| v as u16).collect())
    };
    FringeStack { width: w, height: h, shifts: frames.len(), samples }
}
