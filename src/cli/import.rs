//! `sheen import FOLDER`: a manifest for a folder of images written by
//! another rig (`io::import`): assignment table, image checks, the shift
//! check (`sheen check`), then the manifest, written atomically.

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;

use super::check::{check_loaded, check_table, parse_direction};
use super::progress::ProgressPrinter;
use crate::engine::control::RunControl;
use crate::engine::shift_estimate::{DEFAULT_TOLERANCE_RAD, PhaseDirection};
use crate::io;
use crate::io::import::{self, ImportError, ImportSpec};

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The folder holding the images (one subfolder per camera without --pattern).
    pub folder: PathBuf,
    /// The manifest to write; in FOLDER or a folder above it [default: FOLDER/fringe-set.json].
    #[arg(long, value_name = "MANIFEST.json")]
    pub out: Option<PathBuf>,
    /// Fringe periods in projector pixels, sparsest first, e.g. 912,144,24,12
    /// (may be left out when the pattern has {period}).
    #[arg(long, value_delimiter = ',')]
    pub periods: Vec<f64>,
    /// Shifts per set: one count for all sets or one per set, e.g. 12 or
    /// 12,12,12,4 (may be left out when the pattern has {shift}).
    #[arg(long, value_delimiter = ',')]
    pub shifts: Vec<usize>,
    /// File names with placeholders {camera}, {period}, {set}, {shift},
    /// {index} (through all images of a camera, sparsest set first), e.g.
    /// '{camera}/p{period}_{shift:02}.png' or 'cam{camera}_{index}.bmp'.
    #[arg(long)]
    pub pattern: Option<String>,
    /// Cameras to take, in order: left,right, or NAME=KEY to rename what the
    /// files call a camera (left=cam0,right=cam1).
    #[arg(long)]
    pub cameras: Option<String>,
    /// Calibration file, in the manifest's folder or below it.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Bits per sample of the camera [default: 8 for 8-bit files, else
    /// measured from the largest value].
    #[arg(long = "bit-depth", value_name = "B")]
    pub bit_depth: Option<u32>,
    /// Files to leave out (globs with * and ?, matched against the path and
    /// the file name), e.g. 'gray_*'; repeat or separate with commas.
    #[arg(long, value_delimiter = ',')]
    pub skip: Vec<String>,
    /// -1 when the rig shifts the other way: delta_k = offset - 2 pi k / N.
    #[arg(long = "shift-sign", default_value_t = 1, allow_negative_numbers = true, value_parser = clap::value_parser!(i32).range(-1..=1))]
    pub shift_sign: i32,
    /// Phase shift of the first image of every set, in radians.
    #[arg(long = "shift-offset", value_name = "RAD", default_value_t = 0.0, allow_negative_numbers = true)]
    pub shift_offset: f64,
    /// Where the phase grows in the camera image (right, left, down, up),
    /// for the shift check.
    #[arg(long = "phase-grows", value_name = "DIR", value_parser = parse_direction)]
    pub phase_grows: Option<PhaseDirection>,
    /// The projector axis of each set, in the order of --periods (x: phase
    /// along projector columns, y: along rows), e.g. x,x,y,y; needs
    /// --projector. Default: every set along x.
    #[arg(long, value_name = "AXES")]
    pub axes: Option<String>,
    /// A camera–projector rig's projector, WIDTHxHEIGHT in its pixels (e.g.
    /// 1920x1080).
    #[arg(long, value_name = "WxH")]
    pub projector: Option<String>,
    /// Gray code frames follow the sets in OpenCV's GrayCodePattern layout
    /// (per axis, bit planes most significant first, each pattern then its
    /// inverse; columns, then rows, then white, then black), CELL_PX
    /// projector pixels per code unit; needs --projector.
    #[arg(long = "gray-code", value_name = "CELL_PX")]
    pub gray_code: Option<u32>,
    /// The Gray code has columns only (no row frames).
    #[arg(long = "gray-code-columns-only", requires = "gray_code")]
    pub gray_code_columns_only: bool,
    /// Skip the shift check (it decodes every image).
    #[arg(long = "no-check")]
    pub no_check: bool,
    /// One line per camera and set instead of one per image.
    #[arg(long)]
    pub summary: bool,
    /// Print the assignment and checks, write nothing.
    #[arg(long = "dry-run")]
    pub dry_run: bool,
    /// No progress or notes on stderr (the tables still go to stdout).
    #[arg(long, short)]
    pub quiet: bool,
}

impl ImportArgs {
    pub fn spec(&self) -> anyhow::Result<ImportSpec> {
        if self.shift_sign == 0 {
            bail!("--shift-sign must be 1 or -1");
        }
        if !self.shift_offset.is_finite() {
            bail!("--shift-offset must be a number of radians");
        }
        let at = |fault| ImportError::new(&self.folder, fault);
        Ok(ImportSpec {
            periods_px: self.periods.clone(),
            shifts: self.shifts.clone(),
            pattern: self.pattern.clone(),
            cameras: match &self.cameras {
                Some(c) => import::parse_cameras(c).map_err(at)?,
                None => Vec::new(),
            },
            skip: self.skip.clone(),
            calibration: self.calibration.clone(),
            bit_depth: self.bit_depth,
            shift_sign: f64::from(self.shift_sign),
            shift_offset_rad: self.shift_offset,
            axes: match &self.axes {
                Some(a) => import::parse_axes(a).map_err(at)?,
                None => Vec::new(),
            },
            projector: self.projector.as_deref().map(import::parse_projector).transpose().map_err(at)?,
            gray_code: match self.gray_code {
                Some(0) => bail!("--gray-code must be a cell of 1 or more projector pixels"),
                Some(cell_px) => Some(import::ImportGrayCode { cell_px, rows: !self.gray_code_columns_only }),
                None => None,
            },
        })
    }

    pub fn manifest_path(&self) -> PathBuf {
        self.out.clone().unwrap_or_else(|| self.folder.join(io::dataset::MANIFEST_FILE))
    }
}

/// `sheen import`'s options as a recipe keeps them, for a part's folder.
#[derive(clap::Parser)]
struct ImportCommand {
    #[command(flatten)]
    args: ImportArgs,
}

/// The folder a recipe's import options are parsed against: they describe
/// every part's folder, not one of them.
const ANY_PART_FOLDER: &str = "PART_FOLDER";

/// A recipe's `sheen import` options, parsed and checked once (when the
/// recipe is made and when the watch starts), so a mistake in them is one
/// clear error there instead of an error on every part.
pub fn recipe_import_spec(options: &[String]) -> anyhow::Result<ImportSpec> {
    let argv = ["sheen import".to_string(), ANY_PART_FOLDER.to_string()].into_iter().chain(options.iter().cloned());
    let args = <ImportCommand as clap::Parser>::try_parse_from(argv)
        .map_err(|e| {
            let text = e.to_string();
            // clap's first line names the problem; the rest is usage help.
            let first = text.lines().next().unwrap_or_default().trim_start_matches("error: ").to_string();
            anyhow::anyhow!("the import options: {first}")
        })?
        .args;
    if args.out.is_some() || args.dry_run {
        bail!(
            "the import options: --out and --dry-run do not apply to a recipe (the watch writes each part's manifest)"
        );
    }
    args.spec().map_err(|e| anyhow::anyhow!("the import options: {e}"))
}

/// Writes the manifest of a part's folder of images with a recipe's import
/// options (`sheen watch`), printing nothing: the assignment, the image
/// checks and the manifest as `sheen import --no-check` makes them.
pub fn import_part(folder: &std::path::Path, spec: &ImportSpec) -> anyhow::Result<PathBuf> {
    let out = folder.join(io::dataset::MANIFEST_FILE);
    let files = import::list_files(folder)?;
    let assignment = import::assign(&files, spec).map_err(|fault| ImportError::new(folder, fault))?;
    let facts = import::inspect_images(folder, &assignment, spec, true, &RunControl::new())?;
    let manifest = import::build_manifest(folder, &out, &assignment, spec, facts.bit_depth)?;
    let inputs: Vec<PathBuf> = manifest.input_paths(&out).into_iter().skip(1).collect();
    io::atomic::refuse_overwriting_inputs(&out, &inputs)?;
    io::manifest::write_manifest(&out, &manifest)?;
    Ok(out)
}

pub fn run(args: &ImportArgs) -> anyhow::Result<()> {
    let spec = args.spec()?;
    let folder = &args.folder;
    if !folder.is_dir() {
        bail!("{} is not a folder", folder.display());
    }
    let out = args.manifest_path();
    let control = RunControl::new();
    let progress = ProgressPrinter::start(&control, args.quiet);
    let files = import::list_files(folder)?;
    let assignment = import::assign(&files, &spec).map_err(|fault| ImportError::new(folder, fault))?;
    print!("{}", if args.summary { assignment.table() } else { assignment.listing() });
    report_left_out(&assignment, args.quiet);
    let facts = import::inspect_images(folder, &assignment, &spec, true, &control)?;
    for note in assignment.notes.iter().chain(&facts.notes) {
        eprintln!("note: {note}");
    }
    let manifest = import::build_manifest(folder, &out, &assignment, &spec, facts.bit_depth)?;
    // The manifest must not replace an image or the calibration.
    let inputs: Vec<PathBuf> = manifest.input_paths(&out).into_iter().skip(1).collect();
    io::atomic::refuse_overwriting_inputs(&out, &inputs)?;
    let mut problems = 0;
    if !args.no_check {
        control.begin_stage("loading images for the shift check");
        let loaded = io::manifest::load_manifest_measurement(&manifest, &out, &control)?;
        control.begin_stage("estimating the phase shifts");
        let checks = check_loaded(&loaded.measurement, None, args.phase_grows, DEFAULT_TOLERANCE_RAD.to_degrees());
        print!("{}", check_table(&checks, DEFAULT_TOLERANCE_RAD));
        problems = checks.iter().map(|c| c.sets.iter().filter(|s| s.verdict.is_problem()).count()).sum();
    }
    drop(progress);
    let sizes: Vec<String> = facts.cameras.iter().map(|c| format!("{} {}x{} px", c.name, c.width, c.height)).collect();
    if args.dry_run {
        eprintln!("sheen: dry run, nothing written ({}; {}-bit)", sizes.join(", "), facts.bit_depth);
    } else {
        if out.is_file() && !args.quiet {
            eprintln!("note: replacing the existing {}", out.display());
        }
        io::manifest::write_manifest(&out, &manifest)?;
        if !args.quiet {
            eprintln!(
                "sheen: wrote {}: {} camera(s) ({}), {} set(s), {} images{}, {}-bit{}",
                out.display(),
                assignment.cameras.len(),
                sizes.join(", "),
                assignment.sets.len(),
                assignment.image_count(),
                match assignment.gray_frames.values().next() {
                    Some(frames) => format!(" and {} Gray code frames per camera", frames.len()),
                    None => String::new(),
                },
                facts.bit_depth,
                if manifest.calibration.is_some() { ", calibrated" } else { ", no calibration (sheen phase)" }
            );
        }
    }
    if problems > 0 {
        eprintln!(
            "warning: {problems} set(s) disagree with the phase shifts the manifest assumes (see above): check the \
             image order and --shift-sign before measuring"
        );
    }
    Ok(())
}

fn report_left_out(a: &import::Assignment, quiet: bool) {
    if quiet {
        return;
    }
    if !a.skipped.is_empty() {
        eprintln!("note: {} image(s) skipped by --skip (e.g. {})", a.skipped.len(), a.skipped[0]);
    }
    if !a.ignored.is_empty() {
        let (f, why) = &a.ignored[0];
        eprintln!("note: {} image(s) not used (e.g. {f}: {why})", a.ignored.len());
    }
}
