//! `sheen reconstruct` and `sheen phase`: the whole method, or its per-camera
//! stages, on a fringe-set manifest, writing the cloud, the maps and a report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;

use super::progress::ProgressPrinter;
use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::engine::pipeline::{self, Method, Params, Reconstruction};
use crate::engine::report::{ProcessTimes, Report};
use crate::io;

/// Options shared by every command that runs the engine.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The fringe-set manifest (JSON beside its images).
    pub manifest: PathBuf,
    /// hdr (the paper's scheme), standard, masked or generalized.
    #[arg(long, default_value = "hdr")]
    pub method: Method,
    /// Samples at or above this grey level count as saturated [default: the
    /// manifest's saturation level].
    #[arg(long = "sat-threshold", value_name = "T")]
    pub sat_threshold: Option<u16>,
    /// Pixels whose fringe modulation is below this (grey levels) are invalid.
    #[arg(long = "min-modulation", value_name = "B", default_value_t = Params::default().min_modulation_dn)]
    pub min_modulation: f32,
    /// Leave this set (0-based manifest index, sparsest first) out of
    /// unwrapping and fusion; repeat for several.
    #[arg(long = "disable-set", value_name = "SET")]
    pub disable_set: Vec<usize>,
    /// Leave out points whose height standard deviation (propagated from the
    /// phase noise) exceeds this many micrometres.
    #[arg(long = "max-sigma-z", value_name = "UM", default_value_t = crate::engine::pipeline::DEFAULT_MAX_SIGMA_Z_UM)]
    pub max_sigma_z: f32,
    /// Keep every point, however uncertain (overrides --max-sigma-z).
    #[arg(long = "keep-uncertain")]
    pub keep_uncertain: bool,
    /// How fringe orders are accepted: evidence (on the pixel's own samples,
    /// or confirmed by its neighbours or its patch), strict (own samples
    /// only, as Sheen 0.1) or off (the rounded order, as the paper).
    #[arg(long = "order-check", value_name = "RULE", default_value = "evidence")]
    pub order_check: crate::engine::unwrap::OrderCheck,
    /// Leave out pixels whose fringe orders needed their neighbours' or
    /// their patch's evidence.
    #[arg(long = "own-orders-only")]
    pub own_orders_only: bool,
    /// Stereo matching: strict (never across a step, hole or occlusion) or
    /// plain (the nearest monotone bracket along the row, Eq. 7 as the paper).
    #[arg(long = "stereo-continuity", value_name = "RULE", default_value = "strict")]
    pub stereo_continuity: crate::engine::stereo_match::StereoContinuity,
    /// Write the run report (counts, saturation, sources, timings) as JSON.
    #[arg(long, value_name = "REPORT.json")]
    pub report: Option<PathBuf>,
    /// Write every intermediate map as float32 TIFF plus a colour-mapped PNG.
    #[arg(long, value_name = "DIR")]
    pub maps: Option<PathBuf>,
    /// No progress on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct ReconstructArgs {
    #[command(flatten)]
    pub run: RunArgs,
    /// The point cloud to write (PLY).
    #[arg(long, value_name = "CLOUD.ply")]
    pub out: PathBuf,
    /// Write an ASCII PLY instead of binary little-endian.
    #[arg(long)]
    pub ascii: bool,
}

#[derive(Debug, Args)]
pub struct PhaseArgs {
    #[command(flatten)]
    pub run: RunArgs,
}

impl RunArgs {
    fn params(&self, m: &Measurement) -> anyhow::Result<Params> {
        for &s in &self.disable_set {
            if s >= m.sets.len() {
                bail!("--disable-set {s}: the manifest has {} sets (0 to {})", m.sets.len(), m.sets.len() - 1);
            }
        }
        let max = if m.bit_depth >= 16 { u16::MAX } else { (1u16 << m.bit_depth) - 1 };
        if let Some(t) = self.sat_threshold
            && (t == 0 || t > max)
        {
            bail!("--sat-threshold {t} is outside 1..={max} for {}-bit data", m.bit_depth);
        }
        if !(self.max_sigma_z > 0.0) {
            bail!("--max-sigma-z must be a positive number of micrometres, got {}", self.max_sigma_z);
        }
        if !(self.min_modulation >= 0.0) {
            bail!("--min-modulation must be a non-negative number of grey levels, got {}", self.min_modulation);
        }
        Ok(Params {
            method: self.method,
            saturation_threshold: self.sat_threshold,
            min_modulation_dn: self.min_modulation,
            enabled_sets: (0..m.sets.len()).map(|s| !self.disable_set.contains(&s)).collect(),
            max_sigma_z_um: (!self.keep_uncertain).then_some(self.max_sigma_z),
            order_check: self.order_check,
            own_orders_only: self.own_orders_only,
            stereo_continuity: self.stereo_continuity,
        })
    }

    fn outputs(&self) -> Vec<&Path> {
        self.report.iter().chain(&self.maps).map(PathBuf::as_path).collect()
    }
}

fn load(args: &RunArgs, control: &RunControl, outputs: &[&Path]) -> anyhow::Result<Measurement> {
    control.begin_stage("loading images");
    let manifest = io::manifest::read_manifest(&args.manifest)?;
    // Refuse before the (long) load: exports never overwrite inputs.
    let inputs = manifest.input_paths(&args.manifest);
    for out in outputs {
        io::atomic::refuse_overwriting_inputs(out, &inputs)?;
    }
    let loaded = io::manifest::load_manifest_measurement(&manifest, &args.manifest, control)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    Ok(loaded.measurement)
}

/// Wall-clock marks of a command-line run, for the report's `process_s`.
struct ProcessClock {
    start: Instant,
    loaded: f64,
    computed: f64,
}

impl ProcessClock {
    /// Counts from the process's start ([`super::process_started`]).
    fn start() -> Self {
        Self { start: super::process_started(), loaded: 0.0, computed: 0.0 }
    }

    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    fn times(&self) -> ProcessTimes {
        let total = self.now();
        ProcessTimes { load: self.loaded, compute: self.computed - self.loaded, write: total - self.computed, total }
    }
}

fn write_maps(args: &RunArgs, m: &Measurement, rec: &Reconstruction) -> anyhow::Result<()> {
    for w in &rec.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(dir) = &args.maps {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create the maps folder {}", dir.display()))?;
        for cam in &rec.cameras {
            io::maps::write_camera_maps(dir, cam, &m.periods_px())?;
        }
    }
    Ok(())
}

/// The report goes last, so that it can say how long writing the rest took.
fn write_report(args: &RunArgs, rec: &Reconstruction, clock: &ProcessClock) -> anyhow::Result<()> {
    if let Some(path) = &args.report {
        let report = Report { process_s: Some(clock.times()), ..Report::new(rec) };
        let json = serde_json::to_vec_pretty(&report).context("cannot serialise the report")?;
        io::atomic::write_atomic(path, |w| std::io::Write::write_all(w, &json))?;
    }
    Ok(())
}

fn summary(rec: &Reconstruction) -> String {
    // A camera–projector rig's measure is its projector coordinates: its
    // x sets' fused phase alone (no Gray code) is not what it measures.
    let valid: Vec<String> = match &rec.projector {
        Some(Ok(maps)) => maps
            .iter()
            .map(|m| {
                let axes: Vec<String> = [("x", &m.x), ("y", &m.y)]
                    .into_iter()
                    .filter_map(|(axis, c)| {
                        let (lit, measured) = c.as_ref()?.lit_and_measured();
                        Some(format!("{axis} {:.1} %", 100.0 * measured as f64 / lit.max(1) as f64))
                    })
                    .collect();
                format!("{} projector {} of the lit pixels", m.camera, axes.join(", "))
            })
            .collect(),
        _ => rec
            .cameras
            .iter()
            .zip(rec.completeness())
            .map(|(c, share)| format!("{} {:.1} % valid", c.camera, 100.0 * share))
            .collect(),
    };
    let total = rec.total_seconds();
    format!("{}; {:.2} s", valid.join(", "), total)
}

pub fn reconstruct(args: &ReconstructArgs) -> anyhow::Result<()> {
    let mut clock = ProcessClock::start();
    let control = RunControl::new();
    let _progress = ProgressPrinter::start(&control, args.run.quiet);
    let mut outputs = args.run.outputs();
    outputs.push(&args.out);
    // Refused before the images are decoded: a phase-only manifest is no
    // reason to wait.
    let manifest = io::manifest::read_manifest(&args.run.manifest)?;
    if manifest.projector.is_some() {
        return reconstruct_camera_projector(args, &manifest, &control, &outputs);
    }
    let cams = manifest.camera_names();
    if cams.len() < 2 || manifest.calibration.is_none() {
        bail!(
            "reconstruct needs two cameras and a calibration, but {} has {} camera(s) ({}) and {}; use `sheen \
             phase {} --maps DIR` for the per-camera stages",
            args.run.manifest.display(),
            cams.len(),
            cams.join(", "),
            if manifest.calibration.is_some() { "a calibration" } else { "no calibration" },
            args.run.manifest.display()
        );
    }
    let m = load(&args.run, &control, &outputs)?;
    clock.loaded = clock.now();
    let params = args.run.params(&m)?;
    // Stereo needs only the fused phase maps: freeing each camera's samples
    // once its phases exist, and the per-set maps when none are written,
    // keeps a full-resolution run's peak memory near the samples plus 400 MB.
    let mut m = m;
    let per_set_maps = if args.run.maps.is_some() { pipeline::PerSetMaps::Keep } else { pipeline::PerSetMaps::Release };
    let mut rec = pipeline::run_phase_releasing_samples(&mut m, &params, per_set_maps, &control)?;
    pipeline::run_stereo(&m, &params, &mut rec, &control)?;
    clock.computed = clock.now();
    write_maps(&args.run, &m, &rec)?;
    let Some(stereo) = rec.stereo.as_ref() else {
        write_report(&args.run, &rec, &clock)?;
        bail!("no 3D result: {}", rec.stereo_skipped.as_deref().unwrap_or("stereo did not run"));
    };
    if stereo.cloud.is_empty() {
        write_report(&args.run, &rec, &clock)?;
        bail!(
            "no 3D point could be measured ({} left pixels had a phase); see the warnings above",
            stereo.match_stats.candidates
        );
    }
    let options = io::ply::PlyWriteOptions {
        format: if args.ascii { io::ply::PlyFormat::Ascii } else { io::ply::PlyFormat::BinaryLittleEndian },
        source: Some(args.run.manifest.display().to_string()),
    };
    io::ply::write_ply(&args.out, &stereo.cloud, &options)?;
    write_report(&args.run, &rec, &clock)?;
    if !args.run.quiet {
        eprintln!("sheen: {} points written to {} ({})", stereo.cloud.len(), args.out.display(), summary(&rec));
    }
    Ok(())
}

/// A camera–projector rig's cloud (issue 52): the absolute projector
/// coordinates from the Gray code and the phase sets, each camera pixel's
/// ray met with the projector's column plane (or ray, with rows).
fn reconstruct_camera_projector(
    args: &ReconstructArgs,
    manifest: &io::manifest::Manifest,
    control: &RunControl,
    outputs: &[&Path],
) -> anyhow::Result<()> {
    let path = args.run.manifest.display();
    if manifest.gray_code.is_none() {
        bail!("{path}: a camera–projector rig is reconstructed from its Gray code, and the manifest has none");
    }
    if manifest.calibration.is_none() {
        bail!(
            "{path}: reconstruct needs the rig's calibration (\"calibration\": a file with \"model\": \
             \"pinhole-camera-projector\"); without it `sheen phase {path} --maps DIR` writes the projector coordinates"
        );
    }
    if args.run.report.is_some() {
        bail!("--report is written for the telecentric pair only so far; leave it out for a camera–projector rig");
    }
    let m = load(&args.run, control, outputs)?;
    let params = args.run.params(&m)?;
    let maps = super::camera_projector::projector_maps(
        &m,
        &params.phase_params(&m),
        &args.run.manifest,
        control,
        args.run.quiet,
    )?
    .unwrap_or_default();
    let Some(camera) = maps.first() else { bail!("{path}: no camera") };
    let Some(x) = &camera.x else { bail!("{path}: no projector x") };
    let pixels = x.width * x.height;
    if let Some(dir) = &args.run.maps {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create the maps folder {}", dir.display()))?;
        io::maps::write_projector_maps(dir, camera, &io::maps::MapWriteOptions::default())?;
    }
    control.begin_stage("triangulate");
    let cloud = crate::engine::camera_projector::rig_point_cloud(&m, &maps).context("the rig's calibration")?;
    if cloud.is_empty() {
        bail!("no 3D point could be measured: no pixel has a projector coordinate (see the lines above)");
    }
    let options = io::ply::PlyWriteOptions {
        format: if args.ascii { io::ply::PlyFormat::Ascii } else { io::ply::PlyFormat::BinaryLittleEndian },
        source: Some(args.run.manifest.display().to_string()),
    };
    control.begin_stage("writing the cloud");
    io::ply::write_ply(&args.out, &cloud, &options)?;
    if !args.run.quiet {
        eprintln!(
            "sheen: {} points written to {} ({:.1} % of the camera's pixels)",
            cloud.len(),
            args.out.display(),
            100.0 * cloud.len() as f64 / pixels as f64
        );
    }
    Ok(())
}

pub fn phase(args: &PhaseArgs) -> anyhow::Result<()> {
    if args.run.maps.is_none() && args.run.report.is_none() {
        bail!("nothing to write: give --maps DIR and/or --report REPORT.json");
    }
    let mut clock = ProcessClock::start();
    let control = RunControl::new();
    let _progress = ProgressPrinter::start(&control, args.run.quiet);
    let m = load(&args.run, &control, &args.run.outputs())?;
    clock.loaded = clock.now();
    let params = args.run.params(&m)?;
    let rec = pipeline::run_phase(&m, &params, None, &control)?;
    let projector = match &rec.projector {
        None => None,
        Some(Ok(maps)) => {
            super::camera_projector::report(maps, args.run.quiet);
            Some(maps)
        }
        Some(Err(e)) => return Err(super::camera_projector::explain(e, &args.run.manifest)),
    };
    clock.computed = clock.now();
    write_maps(&args.run, &m, &rec)?;
    if let (Some(dir), Some(maps)) = (&args.run.maps, projector) {
        for camera in maps.iter() {
            io::maps::write_projector_maps(dir, camera, &io::maps::MapWriteOptions::default())?;
        }
    }
    write_report(&args.run, &rec, &clock)?;
    if !args.run.quiet {
        eprintln!("sheen: phase maps of {} camera(s) ({})", rec.cameras.len(), summary(&rec));
    }
    Ok(())
}
