//! `sheen calibrate`: calibrates the telecentric stereo rig from a
//! calibration set (target images in several poses), or a camera–projector
//! rig from a set of fringe sets recorded with the target in view, prints
//! what each pose contributed and what to worry about, and writes
//! calibration.json and, when asked, the full report.

use std::path::{Path, PathBuf};

use anyhow::bail;
use clap::Args;

use super::progress::ProgressPrinter;
use crate::engine::calibration::camera_projector::{RigCalibrationOptions, RigCalibrationReport};
use crate::engine::calibration::model::DistortionModel;
use crate::engine::calibration::report::CalibrationReport;
use crate::engine::calibration::{CalibrationOptions, MIN_POSES};
use crate::engine::control::RunControl;
use crate::io;
use crate::io::calibration_set::{AnyCalibrationSet, RigCalibrationSet, read_any_calibration_set};

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The calibration set (JSON beside its target images).
    pub set: PathBuf,
    /// The calibration to write (the `calibration` of a fringe-set manifest).
    #[arg(long, value_name = "calibration.json")]
    pub out: PathBuf,
    /// Also write the full report: per pose and camera the detections, residuals
    /// and RMS, the worst points, parameter standard deviations, the rectification.
    #[arg(long, value_name = "REPORT.json")]
    pub report: Option<PathBuf>,
    /// Lens distortion to fit: none, k1 (one radial term), radial (k1, k2) or
    /// full (k1, k2, p1, p2); terms not fitted are written as 0.
    #[arg(long, default_value = "k1", value_name = "MODEL")]
    pub distortion: DistortionModel,
    /// No progress on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    // Checked before the slow part, so a wrong output path costs nothing.
    let set = match read_any_calibration_set(&args.set)? {
        AnyCalibrationSet::Stereo(set) => set,
        AnyCalibrationSet::CameraProjector(set) => return run_camera_projector(args, &set),
    };
    let dir = io::manifest::folder_of(&args.set);
    let images: Vec<PathBuf> = set.poses.iter().flat_map(|p| [dir.join(&p.left), dir.join(&p.right)]).collect();
    check_outputs(args, &images, set.poses.len())?;
    for w in &set.warnings {
        eprintln!("warning: {w}");
    }
    let options = CalibrationOptions { distortion: args.distortion, ..CalibrationOptions::default() };
    let control = RunControl::new();
    let (calibration, report) = {
        let _progress = ProgressPrinter::start(&control, args.quiet);
        io::calibration_set::calibrate_from_set(&args.set, &options, &control)?
    };
    if !args.quiet {
        eprint!("{}", pose_table(&report));
    }
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    io::calibration::write_calibration(&args.out, &calibration)?;
    if let Some(path) = &args.report {
        io::calibration_set::write_calibration_report(path, &report)?;
    }
    if !args.quiet {
        let [l, r] = report.rms_per_camera();
        eprintln!(
            "sheen: calibration written to {} ({} of {} poses, distortion {}, RMS {l:.4} / {r:.4} px left / right{})",
            args.out.display(),
            report.poses.len(),
            set.poses.len(),
            args.distortion,
            args.report.as_ref().map(|p| format!("; report in {}", p.display())).unwrap_or_default()
        );
        if let Some(u) = &calibration.scale_uncertainty {
            let percent = |v: Option<f64>| v.map_or_else(|| "unknown".to_string(), |v| format!("{:.4} %", 100.0 * v));
            eprintln!(
                "sheen: scale uncertainty from the fit (k = 1): height {}, lateral {}; written to the calibration \
                 and carried into every measurement's budget",
                percent(u.height_relative),
                percent(u.lateral_relative)
            );
        }
    }
    Ok(())
}

/// `sheen calibrate` on a camera–projector set: each pose decoded, its
/// target found and carried into the projector, one bundle adjustment of
/// both devices; the calibration in OpenCV's form.
fn run_camera_projector(args: &CalibrateArgs, set: &RigCalibrationSet) -> anyhow::Result<()> {
    let dir = io::manifest::folder_of(&args.set);
    let manifests: Vec<PathBuf> = set.poses.iter().map(|p| dir.join(p)).collect();
    check_outputs(args, &manifests, set.poses.len())?;
    for w in &set.warnings {
        eprintln!("warning: {w}");
    }
    let options = RigCalibrationOptions { distortion: args.distortion, ..RigCalibrationOptions::default() };
    let control = RunControl::new();
    let (calibration, report) = {
        let _progress = ProgressPrinter::start(&control, args.quiet);
        io::calibration_set::calibrate_rig_from_set(&args.set, set, &options, &control)?
    };
    if !args.quiet {
        eprint!("{}", rig_pose_table(&report));
    }
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    io::pinhole_calibration::write_camera_projector_calibration(&args.out, &calibration)?;
    if let Some(path) = &args.report {
        io::calibration_set::write_rig_calibration_report(path, &report)?;
    }
    if !args.quiet {
        let [c, p] = report.rms_per_device();
        eprintln!(
            "sheen: camera–projector calibration written to {} ({} of {} poses, distortion {}, RMS {c:.4} / {p:.4} px \
             camera / projector, baseline {:.2} mm, {:.2} deg between the axes{})",
            args.out.display(),
            report.poses.len(),
            set.poses.len(),
            args.distortion,
            report.baseline_mm,
            report.triangulation_angle_deg,
            args.report.as_ref().map(|p| format!("; report in {}", p.display())).unwrap_or_default()
        );
    }
    Ok(())
}

/// The per-pose table of a camera–projector calibration: target points
/// used and RMS per device, tilt against pose 0; then each device's fit.
pub fn rig_pose_table(report: &RigCalibrationReport) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<10} {:>11} {:>11} {:>11} {:>11} {:>9}",
        "pose", "camera pts", "proj. pts", "camera RMS", "proj. RMS", "tilt"
    );
    for pose in &report.poses {
        let _ = writeln!(
            out,
            "{:<10} {:>11} {:>11} {:>11.4} {:>11.4} {:>5.1} deg",
            pose.name,
            pose.camera_points,
            pose.projector_points,
            pose.camera_rms_px,
            pose.projector_rms_px,
            pose.tilt_deg
        );
    }
    for d in &report.devices {
        let [sfx, sfy, scx, scy] = d.sigma_fx_fy_cx_cy_px;
        let _ = writeln!(
            out,
            "{:<10} fx {:.2} ± {sfx:.2}, fy {:.2} ± {sfy:.2}, cx {:.2} ± {scx:.2}, cy {:.2} ± {scy:.2} px, k1 {:.4}; \
             RMS {:.4} px, max {:.4} px over {} points ({} outliers)",
            d.device,
            d.fx,
            d.fy,
            d.cx,
            d.cy,
            d.distortion[0],
            d.rms_reprojection_px,
            d.max_reprojection_px,
            d.points,
            d.outliers
        );
    }
    out
}

/// Refuses outputs that would overwrite the set, one of its inputs, or each other.
fn check_outputs(args: &CalibrateArgs, files: &[PathBuf], poses: usize) -> anyhow::Result<()> {
    let mut inputs: Vec<PathBuf> = vec![args.set.clone()];
    inputs.extend_from_slice(files);
    let outputs: Vec<&Path> = std::iter::once(args.out.as_path()).chain(args.report.as_deref()).collect();
    for out in &outputs {
        io::atomic::refuse_overwriting_inputs(out, &inputs)?;
        if out.is_dir() {
            bail!("cannot write {}: it is a folder; give a file name such as calibration.json", out.display());
        }
    }
    if let Some(report) = &args.report
        && same_file(report, &args.out)
    {
        bail!("--report {} is the --out file as well; give the report another name", report.display());
    }
    if poses < MIN_POSES {
        // The set is readable but cannot calibrate: say so before detecting anything.
        return Err(anyhow::anyhow!(
            "calibration set {}: lists {poses} pose(s); calibration needs at least {MIN_POSES} (better 6 to 10)",
            args.set.display(),
        ));
    }
    Ok(())
}

fn same_file(a: &Path, b: &Path) -> bool {
    let resolve = |p: &Path| {
        let parent = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        parent.canonicalize().ok().map(|d| d.join(p.file_name().unwrap_or_default()))
    };
    a == b || matches!((resolve(a), resolve(b)), (Some(x), Some(y)) if x == y)
}

/// The per-pose table: points found per camera (outliers set aside), RMS per
/// camera and the tilt against pose 0; skipped poses with their reason.
pub fn pose_table(report: &CalibrationReport) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<10} {:>12} {:>12} {:>10} {:>10} {:>8}",
        "pose", "left pts", "right pts", "left RMS", "right RMS", "tilt"
    );
    // In set order, skipped poses in their place (their reasons follow as warnings).
    let mut rows: Vec<(usize, String)> = Vec::new();
    for pose in &report.poses {
        let cell = |c: usize| {
            pose.cameras.get(c).map_or_else(
                || ("-".to_string(), "-".to_string()),
                |v| {
                    let found = v.points + v.outliers;
                    let pts = if v.outliers > 0 { format!("{found} ({} out)", v.outliers) } else { found.to_string() };
                    (pts, format!("{:.4}", v.rms_reprojection_px))
                },
            )
        };
        let ((lp, lr), (rp, rr)) = (cell(0), cell(1));
        rows.push((
            pose.index,
            format!("{:<10} {lp:>12} {rp:>12} {lr:>10} {rr:>10} {:>5.1} deg", pose.name, pose.tilt_deg),
        ));
    }
    for s in &report.skipped_poses {
        rows.push((s.index, format!("{:<10} skipped (see the warning below)", s.name)));
    }
    rows.sort_by_key(|(index, _)| *index);
    for (_, row) in rows {
        let _ = writeln!(out, "{row}");
    }
    let [l, r] = report.rms_per_camera();
    let _ = writeln!(
        out,
        "{:<10} {:>12} {:>12} {l:>10.4} {r:>10.4}   (px; {} outlier(s), stereo angle {:.2} deg)",
        "all",
        report.cameras.first().map_or(0, |c| c.points),
        report.cameras.get(1).map_or(0, |c| c.points),
        report.outliers,
        report.stereo_angle_deg
    );
    out
}
