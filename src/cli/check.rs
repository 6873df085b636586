//! `sheen check MANIFEST`: estimates the phase shifts actually recorded in
//! each set from the images and compares them with the manifest's
//! (`engine::shift_estimate`); exits non-zero when a set clearly disagrees.

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;

use super::progress::ProgressPrinter;
use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::engine::shift_estimate::{self, CameraShiftCheck, DEFAULT_TOLERANCE_RAD, PhaseDirection, Verdict};
use crate::io;

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The fringe-set manifest (JSON beside its images).
    pub manifest: PathBuf,
    /// Samples at or above this grey level are left out of the estimate
    /// [default: the manifest's saturation level].
    #[arg(long = "sat-threshold", value_name = "T")]
    pub sat_threshold: Option<u16>,
    /// Where the phase grows in the camera image (right, left, down, up),
    /// when the rig is known: then a sequence reversed in every set is
    /// caught too (the images alone cannot tell that sign).
    #[arg(long = "phase-grows", value_name = "DIR", value_parser = parse_direction)]
    pub phase_grows: Option<PhaseDirection>,
    /// Steps within this many degrees of the manifest's agree.
    #[arg(long = "tolerance-deg", value_name = "DEG", default_value_t = DEFAULT_TOLERANCE_RAD.to_degrees())]
    pub tolerance_deg: f64,
    /// No progress on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

pub(crate) fn parse_direction(text: &str) -> Result<PhaseDirection, String> {
    PhaseDirection::parse(text).ok_or_else(|| format!("'{text}' is not right, left, down or up"))
}

fn degrees(v: &[f64]) -> String {
    let finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return "-".into();
    }
    let lo = finite.iter().copied().fold(f64::INFINITY, f64::min).to_degrees();
    let hi = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max).to_degrees();
    if (hi - lo).abs() < 0.05 { format!("{lo:.1}") } else { format!("{lo:.1}..{hi:.1}") }
}

/// The check as a table, one row per camera and set, then one line per problem.
/// "fit": the manifest's residual over the estimate's ([`shift_estimate::MANIFEST_FIT_RATIO`]).
pub fn check_table(checks: &[CameraShiftCheck], tolerance_rad: f64) -> String {
    let mut out = format!(
        "{:<10} {:>3} {:>8} {:>6} {:>16} {:>16} {:>8} {:>8} {:>6}  verdict\n",
        "camera", "set", "period", "shifts", "manifest step °", "measured step °", "spread °", "diff °", "fit"
    );
    for cam in checks {
        for s in &cam.sets {
            let spread = s.step_spread_rad.iter().copied().filter(|x| x.is_finite()).fold(f64::NAN, f64::max);
            out.push_str(&format!(
                "{:<10} {:>3} {:>8} {:>6} {:>16} {:>16} {:>8} {:>8} {:>6}  {}\n",
                cam.camera,
                s.set,
                io::maps::period_label(s.period_px),
                s.manifest_steps_rad.len() + 1,
                degrees(&s.manifest_steps_rad),
                degrees(&s.estimated_steps_rad),
                if spread.is_finite() { format!("{:.2}", spread.to_degrees()) } else { "-".into() },
                if s.max_difference_rad.is_finite() {
                    format!("{:.1}", s.max_difference_rad.to_degrees())
                } else {
                    "-".into()
                },
                s.manifest_fit_ratio.map_or_else(|| "-".into(), |r| format!("{r:.2}")),
                s.verdict.label()
            ));
        }
    }
    for cam in checks {
        for s in cam.sets.iter().filter(|s| s.verdict != Verdict::Agrees || s.max_difference_rad > tolerance_rad) {
            out.push_str(&format!(
                "{} set {} (period {} px): {}\n",
                cam.camera,
                s.set,
                io::maps::period_label(s.period_px),
                s.message
            ));
        }
    }
    out
}

/// Runs the check on a loaded measurement.
pub fn check_loaded(
    m: &Measurement,
    args_threshold: Option<u16>,
    dir: Option<PhaseDirection>,
    tol_deg: f64,
) -> Vec<CameraShiftCheck> {
    let threshold = args_threshold.unwrap_or(m.saturation_level);
    let mut checks = shift_estimate::check_measurement(m, threshold, dir, tol_deg.to_radians());
    // A camera–projector rig's sets along y, numbered after those along x
    // (the order `sheen import` writes them in); their phase grows along
    // the image's other axis, so their sign is resolved among themselves.
    if let Some(patterns) = m.projector.as_ref().filter(|p| !p.y_sets.is_empty()) {
        for ((check, camera), frames) in checks.iter_mut().zip(&m.cameras).zip(&patterns.cameras) {
            let along_y = crate::engine::fringe::CameraFringes {
                name: camera.name.clone(),
                width: camera.width,
                height: camera.height,
                stacks: frames.y_stacks.clone(),
            };
            let y = shift_estimate::check_camera(&along_y, &patterns.y_sets, threshold, None, tol_deg.to_radians());
            check.sets.extend(y.sets.into_iter().map(|mut s| {
                s.set += m.sets.len();
                s
            }));
        }
    }
    checks
}

/// Exit code of a check whose sets disagree with the manifest (1 stays
/// "the input could not be read", as for every command).
pub const EXIT_SHIFTS_DISAGREE: u8 = 3;

pub fn run(args: &CheckArgs) -> anyhow::Result<std::process::ExitCode> {
    if !(args.tolerance_deg > 0.0 && args.tolerance_deg < 90.0) {
        bail!("--tolerance-deg must be between 0 and 90 degrees, got {}", args.tolerance_deg);
    }
    let control = RunControl::new();
    let progress = ProgressPrinter::start(&control, args.quiet);
    control.begin_stage("loading images");
    let loaded = io::manifest::load_measurement(&args.manifest, &control)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    control.begin_stage("estimating the phase shifts");
    let checks = check_loaded(&loaded.measurement, args.sat_threshold, args.phase_grows, args.tolerance_deg);
    drop(progress);
    print!("{}", check_table(&checks, args.tolerance_deg.to_radians()));
    let problems: usize = checks.iter().map(|c| c.sets.iter().filter(|s| s.verdict.is_problem()).count()).sum();
    // A camera–projector rig's Gray code: frames out of order or white and
    // black swapped are errors naming the files.
    if loaded.measurement.projector.as_ref().is_some_and(|p| p.gray_code.is_some()) {
        match super::camera_projector::gray_code_lines(&loaded.measurement, &args.manifest) {
            Ok(lines) => lines.iter().for_each(|l| println!("{l}")),
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(std::process::ExitCode::from(EXIT_SHIFTS_DISAGREE));
            }
        }
    }
    if problems > 0 {
        eprintln!(
            "error: {}: {problems} set(s) disagree with the manifest's phase shifts (see above); fix the manifest or \
             re-import with the right --shift-sign / order",
            args.manifest.display()
        );
        return Ok(std::process::ExitCode::from(EXIT_SHIFTS_DISAGREE));
    }
    Ok(std::process::ExitCode::SUCCESS)
}
