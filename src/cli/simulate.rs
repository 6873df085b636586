//! `sheen simulate`: renders a scene through the virtual rig and writes it as
//! a fringe set (manifest, images, calibration) plus its ground truth, or
//! (`--scene calibration-target`) a calibration set of target images seen
//! through the same rig, with the truth of the cameras and the poses.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;

use super::progress::ProgressPrinter;
use crate::engine::calibration::target::TargetKind;
use crate::engine::control::RunControl;
use crate::io;
use crate::io::maps::{TiffCompression, write_f32_tiff};
use crate::sim::camera_projector::{PinholeRigConfig, PinholeSimulation, simulate_camera_projector};
use crate::sim::{SceneKind, SimConfig, Simulation, simulate};

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// watch-plate, gaskets, pcb, screw-thread, flat, step-gauge, sphere or dim-part (a
    /// fringe set), or calibration-target (a calibration set for `sheen calibrate`).
    #[arg(long)]
    pub scene: SimScene,
    /// Output folder (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Image width in pixels (the field of view is fixed; this sets the pixel pitch).
    #[arg(long, default_value_t = 2048)]
    pub width: usize,
    /// Place the part on the stage: shifted by DX, DY mm and turned by DEG
    /// degrees about the stage origin (from +X towards +Y), as a line's parts
    /// never lie twice in the same spot.
    #[arg(long, value_name = "DX,DY,DEG", value_parser = parse_placement, allow_hyphen_values = true)]
    pub place: Option<crate::sim::PartPlacement>,
    /// Image height in pixels.
    #[arg(long, default_value_t = 1536)]
    pub height: usize,
    /// Bits per sample: 8, or up to 16 (stored in 16-bit PNG).
    #[arg(long, default_value_t = 8)]
    pub bits: u32,
    /// Gaussian read noise, standard deviation in grey levels (default: 0,
    /// noise-free, or the preset's).
    #[arg(long, value_name = "SIGMA")]
    pub noise: Option<f64>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Fringe periods in projector pixels, sparsest first (default: the
    /// preset's, 912,144,24,12 for the paper's rig).
    #[arg(long, value_delimiter = ',')]
    pub periods: Option<Vec<f64>>,
    /// Phase shifts per set: one count for all sets or one per set (default:
    /// the preset's, 12 for the paper's rig).
    #[arg(long, value_delimiter = ',')]
    pub shifts: Option<Vec<usize>>,
    /// The rig: `paper` (the paper's dual-camera telecentric rig, 912/144/24/12
    /// x 12), `camera-projector` (a pinhole camera 20° beside a pinhole
    /// projector straight above, 200 mm away: two 3-step sets of 48 and
    /// 32 px along x and along y, OpenCV's Gray code of 32 px cells with
    /// inverse frames, white, black, and the pinhole calibration; 1 DN
    /// noise) or `rough-scanner` (one telecentric camera, phases only,
    /// 1024/256/64 x 8 with a unit-frequency sparsest set, projector gamma
    /// 2.2 corrected for 1.8, gain 0.5, black level 10 DN, 4 % ambient,
    /// 1.5 DN noise). Options given explicitly override the preset.
    #[arg(long, default_value = "paper")]
    pub rig: RigPreset,
    /// `--rig camera-projector`: the projector's resolution.
    #[arg(long, value_name = "WxH", default_value = "1280x800")]
    pub projector: String,
    /// `--rig camera-projector`: projector pixels per Gray code cell.
    #[arg(long, value_name = "PX", default_value_t = 32)]
    pub gray_code: u32,
    /// Projector gamma (1 = linear).
    #[arg(long, value_name = "GAMMA")]
    pub gamma: Option<f64>,
    /// Gamma the projected pattern was pre-corrected for (equal to --gamma:
    /// fully corrected, 1: not at all).
    #[arg(long, value_name = "GAMMA")]
    pub gamma_compensation: Option<f64>,
    /// Camera black level in grey levels (what a dark frame reads besides ambient light).
    #[arg(long, value_name = "DN")]
    pub black_level: Option<f64>,
    /// Camera gain relative to the scene's nominal exposure (below 1: a dark exposure).
    #[arg(long)]
    pub gain: Option<f64>,
    /// Ambient light, as a fraction of the projector's white.
    #[arg(long)]
    pub ambient: Option<f64>,
    /// Cameras to render: 2 (stereo) or 1 (the left camera alone, phases only).
    #[arg(long)]
    pub cameras: Option<usize>,
    /// Image files of a fringe set: png (compressed, lossless) or tiff
    /// (uncompressed, as many cameras' software saves).
    #[arg(long, default_value = "png", value_name = "FORMAT")]
    pub image_format: ImageFormatArg,
    /// Radial lens distortion k1 of both cameras (0 = none), for fringe
    /// scenes and calibration targets alike.
    #[arg(long, default_value_t = 0.0, value_name = "K1")]
    pub distortion: f64,
    /// Calibration target: circles (a dot grid) or checkerboard.
    #[arg(long, default_value = "circles")]
    pub target: TargetKind,
    /// Calibration target: number of poses (pose 0 flat on the stage, the
    /// others tilted in directions spread around the circle).
    #[arg(long, default_value_t = 8, value_name = "N")]
    pub poses: usize,
    /// Calibration target: tilt of the tilted poses against the stage,
    /// degrees (default 20 for the telecentric pair, 30 for a camera–projector
    /// rig, whose focal lengths need the stronger perspective).
    #[arg(long, value_name = "DEG")]
    pub tilt: Option<f64>,
    #[arg(long, short)]
    pub quiet: bool,
}

/// What `--image-format` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ImageFormatArg {
    Png,
    Tiff,
}

/// What `--rig` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RigPreset {
    Paper,
    CameraProjector,
    RoughScanner,
}

/// What `--scene` names: a fringe scene, or the calibration target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimScene {
    Fringe(SceneKind),
    CalibrationTarget,
}

impl std::str::FromStr for SimScene {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "calibration-target" {
            return Ok(SimScene::CalibrationTarget);
        }
        s.parse().map(SimScene::Fringe).map_err(|_| {
            let names: Vec<&str> = SceneKind::ALL.iter().map(|k| k.name()).collect();
            format!("unknown scene '{s}': expected one of {}, calibration-target", names.join(", "))
        })
    }
}

fn parse_placement(text: &str) -> Result<crate::sim::PartPlacement, String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("'{text}': expected three numbers DX,DY,DEG"))?;
    match values[..] {
        [dx, dy, deg] => Ok(crate::sim::PartPlacement { rotation_deg: deg, shift_mm: [dx, dy] }),
        _ => Err(format!("'{text}': expected three numbers DX,DY,DEG, found {}", values.len())),
    }
}

impl SimulateArgs {
    /// The rig settings; the scene is a placeholder for the calibration target
    /// (it renders no scene, only the rig's cameras are used).
    fn config(&self) -> SimConfig {
        let scene = match self.scene {
            SimScene::Fringe(kind) => kind,
            SimScene::CalibrationTarget => SceneKind::Flat,
        };
        let mut c = match self.rig {
            RigPreset::Paper => SimConfig::new(scene, self.width, self.height),
            RigPreset::CameraProjector | RigPreset::RoughScanner => {
                SimConfig::camera_projector(scene, self.width, self.height)
            }
        };
        c.bits = self.bits;
        c.seed = self.seed;
        c.rig.distortion_k1 = self.distortion;
        if let Some(periods) = &self.periods {
            c.periods_px = periods.clone();
        }
        if let Some(shifts) = &self.shifts {
            c.shifts = shifts.clone();
        }
        let set = |field: &mut f64, value: Option<f64>| {
            if let Some(v) = value {
                *field = v;
            }
        };
        set(&mut c.noise_sigma_dn, self.noise);
        set(&mut c.projector_gamma, self.gamma);
        set(&mut c.gamma_compensation, self.gamma_compensation);
        set(&mut c.black_level_dn, self.black_level);
        set(&mut c.gain, self.gain);
        set(&mut c.ambient, self.ambient);
        if let Some(n) = self.cameras {
            c.cameras = n;
        }
        if let Some(placement) = self.place {
            c.part_placement = placement;
        }
        c
    }
}

pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    if args.rig == RigPreset::CameraProjector {
        return run_camera_projector(args);
    }
    if args.scene == SimScene::CalibrationTarget {
        return run_calibration_target(args);
    }
    let control = RunControl::new();
    let _progress = ProgressPrinter::start(&control, args.quiet);
    let sim = simulate(&args.config(), &control)?;
    write_fringe_set(args, &control, &sim.measurement, |dir| write_truth(dir, &sim))
}

/// Writes a simulated fringe set under `--out` in `--image-format`, then its
/// truth (`write_truth` into `truth/`), and says where.
fn write_fringe_set(
    args: &SimulateArgs,
    control: &RunControl,
    measurement: &crate::engine::fringe::Measurement,
    write_truth: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    control.begin_stage("writing images");
    let format = match args.image_format {
        ImageFormatArg::Png => io::dataset::ImageFileFormat::Png,
        ImageFormatArg::Tiff => io::dataset::ImageFileFormat::Tiff,
    };
    let manifest = io::dataset::write_measurement_as(&args.out, measurement, format)?;
    control.begin_stage("writing truth");
    let truth = args.out.join("truth");
    write_truth(&truth)?;
    if !args.quiet {
        eprintln!("sheen: {} written to {} (truth in {})", measurement.label, manifest.display(), truth.display());
    }
    Ok(())
}

/// The ground truth beside the fringe set: `truth.json` (scene, settings,
/// landmarks, rig) and float32 TIFF maps per camera (surface point, whether
/// the other camera sees it, the projector column) and of the height field.
pub fn write_truth(dir: &Path, sim: &Simulation) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let t = &sim.truth;
    let grid = &t.height_grid;
    let json = serde_json::json!({
        "sheen_truth": 1,
        "scene": t.scene,
        "config": sim.config,
        "rig": t.rig,
        "calibration": io::calibration::calibration_to_value(&t.rig.calibration()),
        "height_grid": {
            "file": "height_grid_mm.tif",
            "origin_mm": grid.origin_mm,
            "pitch_mm": grid.pitch_mm,
            "cols": grid.cols,
            "rows": grid.rows,
            "note": "height of the scene at (origin + col * pitch, origin + row * pitch), millimetres"
        },
        "camera_maps": "{camera}_point_{x,y,z}_mm.tif (NaN where the pixel sees no surface), \
                        {camera}_visible_in_other.tif (1/0), {camera}_projector_column_px.tif: \
                        the true phase of set m is 2 pi column / period_m"
    });
    let text = serde_json::to_vec_pretty(&json).context("cannot serialise the truth")?;
    io::atomic::write_atomic(&dir.join("truth.json"), |w| std::io::Write::write_all(w, &text))?;
    let z: Vec<f32> = grid.z_mm.iter().map(|&v| v as f32).collect();
    write_f32_tiff(&dir.join("height_grid_mm.tif"), grid.cols, grid.rows, &z, TiffCompression::None)?;
    for cam in [&t.left, &t.right] {
        let name = cam.camera.name();
        let (w, h) = (cam.width, cam.height);
        for (axis, label) in ["x", "y", "z"].iter().enumerate() {
            let v: Vec<f32> = cam.point_mm.iter().map(|p| p[axis] as f32).collect();
            write_f32_tiff(&dir.join(format!("{name}_point_{label}_mm.tif")), w, h, &v, TiffCompression::None)?;
        }
        let visible: Vec<f32> = cam.visible_in_other.iter().map(|&b| f32::from(u8::from(b))).collect();
        write_f32_tiff(&dir.join(format!("{name}_visible_in_other.tif")), w, h, &visible, TiffCompression::None)?;
        let column: Vec<f32> = cam.projector_column_px.iter().map(|&c| c as f32).collect();
        write_f32_tiff(&dir.join(format!("{name}_projector_column_px.tif")), w, h, &column, TiffCompression::None)?;
    }
    Ok(())
}

/// `--scene calibration-target`: the target in `--poses` poses through the
/// rig's two cameras, written as a calibration set with its truth (the true
/// cameras in the pose-0 target frame and in the simulator's world, every
/// pose's frame in the world, the true pixel of every target point).
fn run_calibration_target(args: &SimulateArgs) -> anyhow::Result<()> {
    let config = args.config();
    config.validate()?;
    let tilt_deg = checked_tilt(args.tilt.unwrap_or(20.0))?;
    let (cameras, mut target_config) = crate::sim::target::calibration_target_setup(&config, args.target);
    target_config.poses = args.poses;
    target_config.tilt_deg = tilt_deg;
    if !args.quiet {
        eprintln!(
            "sheen: rendering a {} x {} {} target (pitch {} mm) in {} poses, {}x{} px",
            target_config.target.rows,
            target_config.target.cols,
            args.target,
            target_config.target.pitch_mm,
            args.poses,
            args.width,
            args.height
        );
    }
    let set = crate::sim::target::render_calibration_set(&cameras, &target_config)?;
    let settings = serde_json::json!({
        "scene": "calibration-target",
        "width": config.width,
        "height": config.height,
        "bits": config.bits,
        "noise_sigma_dn": config.noise_sigma_dn,
        "seed": config.seed,
        "rig": config.rig,
        "target": target_config,
    });
    let sim = io::calibration_set::SimulatedCalibrationSet {
        target: target_config.target,
        images: &set.images,
        full_scale_dn: target_config.look.full_scale_dn,
        calibration_world: &set.truth.calibration_world,
        calibration_pose0: &set.truth.calibration_pose0,
        poses_world: &set.truth.poses_world,
        points_px: &set.truth.points_px,
        settings,
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let written = io::calibration_set::write_simulated_calibration_set(&args.out, &sim)?;
    if !args.quiet {
        eprintln!(
            "sheen: calibration set written to {} (truth in {} and {})",
            written.set.display(),
            written.truth_calibration.display(),
            written.truth.display()
        );
    }
    Ok(())
}

/// `--rig camera-projector`: the scene through a pinhole camera and
/// projector (`sim::camera_projector`), written as a camera–projector fringe
/// set with its calibration, and the truth per camera pixel.
fn run_camera_projector(args: &SimulateArgs) -> anyhow::Result<()> {
    let c = pinhole_config(args)?;
    let control = RunControl::new();
    let _progress = ProgressPrinter::start(&control, args.quiet);
    if args.scene == SimScene::CalibrationTarget {
        return run_camera_projector_calibration_target(args, &c, &control);
    }
    let sim = simulate_camera_projector(&c, &control)?;
    write_fringe_set(args, &control, &sim.measurement, |dir| write_camera_projector_truth(dir, &sim))
}

fn checked_tilt(tilt_deg: f64) -> anyhow::Result<f64> {
    if !(tilt_deg.is_finite() && (0.0..=60.0).contains(&tilt_deg)) {
        anyhow::bail!("--tilt {tilt_deg}: expected 0 to 60 degrees (10 to 30 calibrate best)");
    }
    Ok(tilt_deg)
}

/// The pinhole rig the options describe (the scene a flat for a calibration set).
fn pinhole_config(args: &SimulateArgs) -> anyhow::Result<PinholeRigConfig> {
    let scene = match args.scene {
        SimScene::Fringe(scene) => scene,
        SimScene::CalibrationTarget => SceneKind::Flat,
    };
    let not_used = [
        ("--cameras", args.cameras.is_some()),
        ("--place", args.place.is_some()),
        ("--black-level", args.black_level.is_some()),
        ("--gamma-compensation", args.gamma_compensation.is_some()),
    ];
    if let Some((option, _)) = not_used.iter().find(|(_, given)| *given) {
        bail!("{option} is not used by --rig camera-projector (one camera, the projector's own gamma)");
    }
    let projector =
        crate::io::import::parse_projector(&args.projector).map_err(|e| anyhow::anyhow!("--projector: {e}"))?;
    let mut c = PinholeRigConfig::new(scene);
    (c.camera_width, c.camera_height) = (args.width, args.height);
    (c.projector_width, c.projector_height) = (projector.width_px, projector.height_px);
    c.cell_px = args.gray_code;
    c.bits = args.bits;
    c.seed = args.seed;
    c.distortion_k1 = args.distortion;
    if let Some(periods) = &args.periods {
        c.periods_px = periods.clone();
    }
    match args.shifts.as_deref() {
        None => {}
        Some([n]) => c.shifts = *n,
        Some(_) => bail!("--rig camera-projector takes one shift count for all its sets"),
    }
    for (field, value) in [
        (&mut c.noise_sigma_dn, args.noise),
        (&mut c.projector_gamma, args.gamma),
        (&mut c.gain, args.gain),
        (&mut c.ambient, args.ambient),
    ] {
        if let Some(v) = value {
            *field = v;
        }
    }
    c.validate()?;
    Ok(c)
}

/// `--rig camera-projector --scene calibration-target`: the target in
/// `--poses` poses under every frame of the rig, each pose a fringe set
/// (`poseNN/`, without the calibration), the set's file
/// `calibration_set.json`, and the truth: the rig (`truth/calibration.json`)
/// and per pose the target's frame in the camera's and the true camera and
/// projector pixel of every target point (`truth/target_truth.json`).
fn run_camera_projector_calibration_target(
    args: &SimulateArgs,
    c: &PinholeRigConfig,
    control: &RunControl,
) -> anyhow::Result<()> {
    use crate::sim::camera_projector::{
        calibration_poses, rig_calibration, rig_calibration_target, simulate_calibration_pose,
    };
    let tilt_deg = checked_tilt(args.tilt.unwrap_or(30.0))?;
    if args.poses < crate::engine::calibration::MIN_POSES {
        bail!("--poses {}: a calibration needs at least {}", args.poses, crate::engine::calibration::MIN_POSES);
    }
    let target = rig_calibration_target(args.target);
    let look = crate::sim::target::TargetLook::default();
    let mut manifests = Vec::with_capacity(args.poses);
    let mut truth_poses = Vec::with_capacity(args.poses);
    for (k, pose) in calibration_poses(&target, args.poses, tilt_deg).iter().enumerate() {
        let mut sim = simulate_calibration_pose(c, &target, &look, pose, k, control)?;
        // The set is what a user records: the rig is what it is to find.
        if let Some(p) = sim.measurement.projector.as_mut() {
            p.calibration = None;
        }
        control.begin_stage(&format!("writing pose {k}"));
        let folder = format!("pose{k:02}");
        let manifest = io::dataset::write_measurement_as(
            &args.out.join(&folder),
            &sim.measurement,
            io::dataset::ImageFileFormat::Png,
        )?;
        let file = manifest.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        manifests.push(format!("{folder}/{file}"));
        truth_poses.push(serde_json::json!({
            "target_in_camera": {"rotation": sim.target_in_camera.rotation,
                                 "translation_mm": sim.target_in_camera.translation_mm},
            "camera_points_px": sim.camera_points_px,
            "projector_points_px": sim.projector_points_px,
        }));
    }
    let set = args.out.join("calibration_set.json");
    io::calibration_set::write_rig_calibration_set(&set, &target, &manifests)?;
    let truth_dir = args.out.join("truth");
    std::fs::create_dir_all(&truth_dir).with_context(|| format!("cannot create {}", truth_dir.display()))?;
    let truth_calibration = truth_dir.join("calibration.json");
    io::pinhole_calibration::write_camera_projector_calibration(&truth_calibration, &rig_calibration(c))?;
    let json = serde_json::json!({
        "sheen_truth": 1,
        "rig": "camera-projector",
        "scene": "calibration-target",
        "config": c,
        "target": target,
        "tilt_deg": tilt_deg,
        "description": "per pose: X_camera = R X_target + t, and the true camera and projector pixel of every \
                        target point (row-major); calibration.json is the rig rendered",
        "poses": truth_poses,
    });
    let text = serde_json::to_vec_pretty(&json).context("cannot serialise the truth")?;
    io::atomic::write_atomic(&truth_dir.join("target_truth.json"), |w| std::io::Write::write_all(w, &text))?;
    if !args.quiet {
        eprintln!(
            "sheen: a camera–projector calibration set of {} poses written to {} (truth in {})",
            args.poses,
            set.display(),
            truth_dir.display()
        );
    }
    Ok(())
}

/// `truth.json` (settings, calibration) and float32 maps per camera pixel:
/// the surface point in the camera's frame (`camera_point_{x,y,z}_mm.tif`,
/// NaN where the ray misses) and the projector point lighting it
/// (`camera_projector_{x,y}_px.tif`, NaN in shadow).
fn write_camera_projector_truth(dir: &Path, sim: &PinholeSimulation) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let t = &sim.truth;
    let json = serde_json::json!({
        "sheen_truth": 1,
        "rig": "camera-projector",
        "config": sim.config,
        "calibration": io::pinhole_calibration::camera_projector_calibration_to_value(&sim.calibration),
        "camera_maps": "camera_point_{x,y,z}_mm.tif: the surface point each camera pixel sees, in the camera's \
                        frame (NaN where it sees none); camera_projector_{x,y}_px.tif: the projector point lighting \
                        it (NaN in shadow)"
    });
    let text = serde_json::to_vec_pretty(&json).context("cannot serialise the truth")?;
    io::atomic::write_atomic(&dir.join("truth.json"), |w| std::io::Write::write_all(w, &text))?;
    let (w, h) = (t.width, t.height);
    for (axis, label) in ["x", "y", "z"].iter().enumerate() {
        let v: Vec<f32> = t.point_camera_mm.iter().map(|p| p[axis] as f32).collect();
        write_f32_tiff(&dir.join(format!("camera_point_{label}_mm.tif")), w, h, &v, TiffCompression::None)?;
    }
    for (axis, label) in ["x", "y"].iter().enumerate() {
        let v: Vec<f32> = t.projector_px.iter().map(|p| p[axis] as f32).collect();
        write_f32_tiff(&dir.join(format!("camera_projector_{label}_px.tif")), w, h, &v, TiffCompression::None)?;
    }
    Ok(())
}
