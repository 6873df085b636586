//! A virtual dual-telecentric fringe projection rig that renders fringe sets
//! with known truth. Uses `engine` types; the engine never uses it.
//!
//! [`simulate`] builds a scene ([`scenes`]), the rig ([`rig`]), casts every
//! camera pixel once ([`raycast`]), shades it ([`material`]) and renders the
//! phase-shifted images of every set from that ([`render`]), returning an
//! in-memory [`Measurement`] with its true calibration and the [`Truth`].
//! Writing files is the io module's job; everything it needs is public here.
//! [`target`] renders calibration-target images through the same rig.

pub mod camera_projector;
pub mod material;
pub mod raycast;
pub mod render;
pub mod rig;
pub mod scene_model;
pub mod scenes;
pub mod target;
pub mod truth;

#[cfg(test)]
mod tests;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::engine::control::{Cancelled, RunControl};
use crate::engine::fringe::{CameraFringes, FringeSetInfo, Measurement, next_measurement_id};

pub use rig::{CameraId, Rig, RigConfig};
pub use scene_model::{Landmark, Scene, SceneKind};
pub use truth::{CameraTruth, HeightGrid, Truth};

use raycast::BoundGrid;
use render::{Radiometry, render_stack, shade_camera, visible_in};

/// Everything that defines a simulated measurement. [`SimConfig::new`] gives
/// the paper's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimConfig {
    pub scene: SceneKind,
    /// Image size of both cameras; the field of view is fixed, so this sets the pixel pitch.
    pub width: usize,
    pub height: usize,
    /// Bits per sample, 8 to 16; full scale (and saturation level) `2^bits - 1`.
    pub bits: u32,
    /// Gaussian read noise, standard deviation in grey levels (0: noise-free).
    pub noise_sigma_dn: f64,
    /// Seed of the read noise.
    pub seed: u64,
    /// Fringe periods in projector pixels, sparsest first.
    pub periods_px: Vec<f64>,
    /// Phase shifts per set: one count for every set, or one per set.
    pub shifts: Vec<usize>,
    /// Image k is shifted by `delta_k = shift_sign 2 pi k / N + shift_offset_rad`
    /// (+1 and 0: the manifest's default convention).
    pub shift_sign: i32,
    pub shift_offset_rad: f64,
    /// Camera gain relative to the scene's nominal exposure.
    pub gain: f64,
    /// Ambient light as a fraction of the projector's full white.
    pub ambient: f64,
    /// The projector's display gamma: a pattern value `P` in 0..1 lights the
    /// stage with `P^gamma` (1: linear, the ideal sinusoid).
    #[serde(default = "one")]
    pub projector_gamma: f64,
    /// The gamma the pattern was pre-corrected for (`P = s^(1/g)`), so the
    /// fringe profile is `s^(gamma / g)`: equal to `projector_gamma` cancels
    /// it, 1 leaves it uncorrected. Real rigs correct only in part, which puts
    /// harmonics into every fringe.
    #[serde(default = "one")]
    pub gamma_compensation: f64,
    /// The camera's black level in grey levels, added to every sample (the
    /// dark frame reads this plus the ambient light).
    #[serde(default)]
    pub black_level_dn: f64,
    /// Cameras rendered: 2 (the stereo rig) or 1 (the left one alone, a
    /// camera-projector rig with no stereo calibration: phases only).
    #[serde(default = "two")]
    pub cameras: usize,
    pub rig: RigConfig,
    /// Where the part lies on the stage: turned about Z by `rotation_deg`
    /// (from +X towards +Y) about the stage origin, then shifted by
    /// `shift_mm`; a part is never placed twice in the same spot on a line.
    #[serde(default)]
    pub part_placement: PartPlacement,
}

/// A rigid motion of the part in the stage plane.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PartPlacement {
    pub rotation_deg: f64,
    pub shift_mm: [f64; 2],
}

fn one() -> f64 {
    1.0
}

fn two() -> usize {
    2
}

/// The paper's fringe periods, sparsest first (projector pixels).
pub const PAPER_PERIODS_PX: [f64; 4] = [912.0, 144.0, 24.0, 12.0];
/// The paper's phase shifts per set.
pub const PAPER_SHIFTS: usize = 12;
/// The periods of a common camera-projector scanner (1024-column projector,
/// the sparsest set one fringe across it), sparsest first.
pub const CAMERA_PROJECTOR_PERIODS_PX: [f64; 3] = [1024.0, 256.0, 64.0];

impl SimConfig {
    /// The paper's settings for `scene` at `width` x `height` (2048 x 1536 is
    /// the paper's camera): 8 bits, periods 912/144/24/12 with 12 shifts, a
    /// 15 degree rig, no noise, no distortion.
    pub fn new(scene: SceneKind, width: usize, height: usize) -> Self {
        Self {
            scene,
            width,
            height,
            bits: 8,
            noise_sigma_dn: 0.0,
            seed: 1,
            periods_px: PAPER_PERIODS_PX.to_vec(),
            shifts: vec![PAPER_SHIFTS],
            shift_sign: 1,
            shift_offset_rad: 0.0,
            gain: 1.0,
            ambient: 0.02,
            projector_gamma: 1.0,
            gamma_compensation: 1.0,
            black_level_dn: 0.0,
            cameras: 2,
            rig: RigConfig::default(),
            part_placement: PartPlacement::default(),
        }
    }

    /// A camera-projector rig as found in the field, the rough data the
    /// paper's rig never shows: 1024/256/64 x 8 with the sparsest set one
    /// fringe across the projector (a unit frequency, `delta_k = 2 pi k / 8`),
    /// a projector gamma of 2.2 corrected for 1.8, a dark exposure (half the
    /// gain) with a 10 DN black level and 4 % ambient light, 1.5 DN read
    /// noise and one camera. With the [`SceneKind::DimPart`] scene, the dim
    /// faces around the part carry 4-12 DN of modulation.
    pub fn camera_projector(scene: SceneKind, width: usize, height: usize) -> Self {
        let mut c = Self::new(scene, width, height);
        c.periods_px = CAMERA_PROJECTOR_PERIODS_PX.to_vec();
        c.shifts = vec![8];
        c.rig.projector.columns = 1024;
        c.projector_gamma = 2.2;
        c.gamma_compensation = 1.8;
        c.gain = 0.5;
        c.ambient = 0.04;
        c.black_level_dn = 10.0;
        c.noise_sigma_dn = 1.5;
        c.cameras = 1;
        c
    }

    /// Exponent of the fringe profile after the partial gamma correction.
    pub fn effective_gamma(&self) -> f64 {
        self.projector_gamma / self.gamma_compensation
    }

    /// Shift count of set `set`.
    pub fn shifts_of(&self, set: usize) -> usize {
        if self.shifts.len() == 1 { self.shifts[0] } else { self.shifts[set] }
    }

    /// The fringe sets as the manifest describes them (period and shifts).
    pub fn fringe_sets(&self) -> Vec<FringeSetInfo> {
        let sign = f64::from(self.shift_sign);
        (0..self.periods_px.len())
            .map(|s| {
                let n = self.shifts_of(s);
                FringeSetInfo {
                    period_px: self.periods_px[s],
                    phase_shifts_rad: (0..n)
                        .map(|k| sign * std::f64::consts::TAU * k as f64 / n as f64 + self.shift_offset_rad)
                        .collect(),
                }
            })
            .collect()
    }

    /// Largest grey level.
    pub fn full_scale_dn(&self) -> u16 {
        ((1u32 << self.bits.clamp(1, 16)) - 1) as u16
    }

    /// Checks every setting; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), SimError> {
        let (w, h) = (self.width, self.height);
        if w < MIN_SIDE_PX || h < MIN_SIDE_PX || w.saturating_mul(h) > MAX_PIXELS {
            return Err(SimError::ImageSize { width: w, height: h });
        }
        let setting = |ok: bool, setting: &'static str, found: String, expected: &'static str| {
            if ok { Ok(()) } else { Err(SimError::Setting { setting, found, expected }) }
        };
        setting((8..=16).contains(&self.bits), "bits", self.bits.to_string(), "8 to 16")?;
        let n = self.noise_sigma_dn;
        setting(n.is_finite() && n >= 0.0, "noise", n.to_string(), "a finite number >= 0 grey levels")?;
        let sets = self.periods_px.len();
        setting((1..=MAX_SETS).contains(&sets), "periods", format!("{sets} periods"), "1 to 16 periods")?;
        for (s, &p) in self.periods_px.iter().enumerate() {
            setting(p.is_finite() && p >= 2.0, "period", format!("{p} px (set {s})"), "at least 2 projector pixels")?;
            if s > 0 && p >= self.periods_px[s - 1] {
                return Err(SimError::PeriodOrder { set: s, period_px: p, previous_px: self.periods_px[s - 1] });
            }
        }
        if !(self.shifts.len() == 1 || self.shifts.len() == sets) {
            return Err(SimError::ShiftCounts { periods: sets, shift_counts: self.shifts.len() });
        }
        for &k in &self.shifts {
            setting((3..=32).contains(&k), "shifts", k.to_string(), "3 to 32 images per set")?;
        }
        setting(self.shift_sign.abs() == 1, "shift sign", self.shift_sign.to_string(), "+1 or -1")?;
        let o = self.shift_offset_rad;
        setting(o.is_finite(), "shift offset", o.to_string(), "a finite angle in radians")?;
        let g = self.gain;
        setting(g.is_finite() && g > 0.0, "gain", g.to_string(), "a finite number > 0")?;
        let a = self.ambient;
        setting(
            a.is_finite() && (0.0..=1.0).contains(&a),
            "ambient",
            a.to_string(),
            "0 to 1 of the projector's white",
        )?;
        for (name, g) in [("projector gamma", self.projector_gamma), ("gamma compensation", self.gamma_compensation)] {
            setting(g.is_finite() && (0.2..=5.0).contains(&g), name, g.to_string(), "0.2 to 5")?;
        }
        let black = self.black_level_dn;
        setting(
            black.is_finite() && black >= 0.0 && black < f64::from(self.full_scale_dn()),
            "black level",
            black.to_string(),
            "0 grey levels or more, below full scale",
        )?;
        setting((1..=2).contains(&self.cameras), "cameras", self.cameras.to_string(), "1 or 2")?;
        let r = &self.rig;
        let t = r.theta_deg;
        setting(t.is_finite() && (1.0..=60.0).contains(&t), "theta", format!("{t} deg"), "1 to 60 degrees")?;
        let roll = r.right_roll_deg;
        setting(roll.is_finite() && roll.abs() <= 45.0, "right roll", format!("{roll} deg"), "-45 to 45 degrees")?;
        let k = r.right_scale;
        setting(k.is_finite() && (0.5..=2.0).contains(&k), "right scale", k.to_string(), "0.5 to 2")?;
        let off = r.right_offset_mm;
        setting(
            off.iter().all(|v| v.is_finite() && v.abs() <= 5.0),
            "right offset",
            format!("{off:?} mm"),
            "within 5 mm of the field centre",
        )?;
        let k1 = r.distortion_k1;
        setting(k1.is_finite() && k1.abs() <= 0.1, "distortion k1", k1.to_string(), "-0.1 to 0.1")?;
        let p = &r.projector;
        setting(p.columns >= 2, "projector columns", p.columns.to_string(), "at least 2")?;
        let c = p.coverage;
        setting(
            c.is_finite() && (0.5..=4.0).contains(&c),
            "projector coverage",
            c.to_string(),
            "0.5 to 4 field widths",
        )?;
        let s0 = p.blur_sigma0_px;
        setting(s0.is_finite() && s0 >= 0.0, "projector blur", s0.to_string(), "a finite sigma >= 0 px")?;
        let kb = p.blur_px_per_mm;
        setting(kb.is_finite() && kb >= 0.0, "projector defocus", kb.to_string(), "a finite rate >= 0 px/mm")?;
        let m = p.modulation;
        setting(m.is_finite() && m > 0.0 && m <= 1.0, "projector modulation", m.to_string(), "above 0, at most 1")?;
        if let Some(f) = p.focus_z_mm {
            setting(f.is_finite(), "projector focus", f.to_string(), "a finite height in mm")?;
        }
        Ok(())
    }
}

/// Smallest image side the simulator renders.
pub const MIN_SIDE_PX: usize = 16;
/// Largest image the simulator renders (per camera), to keep memory bounded.
pub const MAX_PIXELS: usize = 8192 * 8192;
const MAX_SETS: usize = crate::engine::unwrap::MAX_SETS;
/// Steepest smooth slope the bound grid must allow for between its samples.
pub(crate) const BOUND_MAX_SLOPE: f64 = 3.0;
/// Largest spacing of the height samples behind the bounds: the narrowest
/// feature of the scenes (a silkscreen stroke, 140 um) is sampled twice.
pub(crate) const BOUND_SAMPLE_MM: f64 = 0.05;

/// Why a simulation could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(
        "image size {width}x{height} px is not supported: each side must be at least {MIN_SIDE_PX} px and the \
         image at most {MAX_PIXELS} pixels; choose e.g. 2048x1536 (the paper's camera) or 256x192"
    )]
    ImageSize { width: usize, height: usize },
    #[error("simulation setting '{setting}' is {found}, expected {expected}")]
    Setting { setting: &'static str, found: String, expected: &'static str },
    #[error(
        "fringe periods must run from the sparsest to the densest set, but set {set} ({period_px} px) follows \
         {previous_px} px; list them in decreasing order, e.g. 912 144 24 12"
    )]
    PeriodOrder { set: usize, period_px: f64, previous_px: f64 },
    #[error(
        "{periods} fringe periods but {shift_counts} shift counts: give one shift count for all sets or one per set"
    )]
    ShiftCounts { periods: usize, shift_counts: usize },
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// A simulated measurement and its truth.
#[derive(Clone, Debug)]
pub struct Simulation {
    /// The images of both cameras with the true calibration, as if loaded from a manifest.
    pub measurement: Measurement,
    pub truth: Truth,
    pub config: SimConfig,
}

/// Renders the measurement `config` describes. Progress and cancellation go
/// through `control` (stages "simulate: ...").
pub fn simulate(config: &SimConfig, control: &RunControl) -> Result<Simulation, SimError> {
    config.validate()?;
    let mut scene = scenes::build(config.scene);
    scene.placement = config.part_placement;
    let rig = Rig::new(&config.rig, config.width, config.height, scene.focus_z_mm);
    let full_scale = config.full_scale_dn();
    let radiometry = Radiometry {
        full_scale_dn: f64::from(full_scale),
        exposure: scene.exposure * config.gain,
        ambient: config.ambient,
        noise_sigma_dn: config.noise_sigma_dn,
        fringe_gamma: config.effective_gamma(),
        black_level_dn: config.black_level_dn,
        projector_modulation: config.rig.projector.modulation,
    };
    // Marching steps an eighth of a pixel long; bound cells of four pixels,
    // sampled at least every pixel and every 50 um (the finest feature).
    let step_mm = rig.pitch_mm / 8.0;
    control.begin_stage("simulate: bounding the scene");
    let cell_mm = 4.0 * rig.pitch_mm;
    let samples = (cell_mm / rig.pitch_mm.min(BOUND_SAMPLE_MM)).ceil() as usize;
    let grid = BoundGrid::new(&scene, scene.extent, cell_mm, samples, BOUND_MAX_SLOPE);
    control.check()?;

    let shade = |id: CameraId| {
        control.begin_stage(&format!("simulate: ray casting the {} camera", id.name()));
        shade_camera(&scene, &rig, &grid, id, &radiometry, step_mm, control)
    };
    let mut left = shade(CameraId::Left)?;
    let mut right = shade(CameraId::Right)?;
    control.begin_stage("simulate: visibility in the other camera");
    for view in [&mut left, &mut right] {
        let other = view.camera.other();
        view.visible_in_other =
            view.point_mm.par_iter().map(|&p| visible_in(&scene, &rig, &grid, other, p, step_mm)).collect();
        control.check()?;
    }

    let sets = config.fringe_sets();
    let mut cameras = Vec::with_capacity(2);
    for (ci, view) in [&left, &right].into_iter().enumerate().take(config.cameras) {
        control.begin_stage(&format!("simulate: rendering the {} images", view.camera.name()));
        let mut stacks = Vec::with_capacity(sets.len());
        for (si, set) in sets.iter().enumerate() {
            control.check()?;
            stacks.push(render_stack(view, &rig.projector, set, &radiometry, config.bits, config.seed, (ci, si)));
            control.set_fraction((si + 1) as f32 / sets.len() as f32);
        }
        cameras.push(CameraFringes {
            name: view.camera.name().to_owned(),
            width: rig.width,
            height: rig.height,
            stacks,
        });
    }
    let measurement = Measurement {
        bit_depth: config.bits,
        saturation_level: full_scale,
        sets,
        cameras,
        // One camera has no stereo calibration: such a rig measures phases only.
        calibration: (config.cameras == 2).then(|| rig.calibration()),
        label: format!(
            "simulated {} ({}x{} px, {} bit, noise {} DN, seed {}{})",
            config.scene,
            config.width,
            config.height,
            config.bits,
            config.noise_sigma_dn,
            config.seed,
            if config.cameras == 1 { ", one camera" } else { "" }
        ),
        projector: None,
        id: next_measurement_id(),
    };
    let height_grid = HeightGrid::sample(&scene, &rig);
    let truth = Truth { scene, rig, left, right, height_grid };
    Ok(Simulation { measurement, truth, config: config.clone() })
}

/// The app's built-in demo: the watch plate, 8 bits, mild read noise (0.8 DN).
/// Sizes below [`MIN_SIDE_PX`] are raised to it and sizes beyond
/// [`MAX_PIXELS`] are reduced to the paper's camera, so any request renders.
pub fn demo(width: usize, height: usize) -> Simulation {
    let (mut width, mut height) = (width.max(MIN_SIDE_PX), height.max(MIN_SIDE_PX));
    if width.saturating_mul(height) > MAX_PIXELS {
        (width, height) = (rig::PAPER_WIDTH_PX, rig::PAPER_HEIGHT_PX);
    }
    let config = SimConfig { noise_sigma_dn: 0.8, ..SimConfig::new(SceneKind::WatchPlate, width, height) };
    match simulate(&config, &RunControl::new()) {
        Ok(sim) => sim,
        // The configuration above is valid by construction and nobody holds the control to cancel it.
        Err(e) => unreachable!("the demo configuration failed: {e}"),
    }
}
