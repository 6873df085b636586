//! Importing a folder of fringe images written by another rig's acquisition
//! software: which file is which camera, set and shift, checked
//! before anything is written, and the fringe-set manifest that says so.
//!
//! Three ways to name the files:
//!
//! - a PATTERN with placeholders, matched against each file's path relative
//!   to the folder: `{camera}`, `{period}` (projector pixels), `{set}` (set
//!   number, sparsest first), `{shift}`, and `{index}`, which counts through
//!   all images of a camera in set order, sparsest first. Numeric
//!   placeholders take a width, `{shift:02}`, meaning exactly that many
//!   digits. Numbering may start anywhere (0 or 1 are usual): the smallest
//!   number found is the first image;
//! - without a pattern, one subfolder per camera (or the folder itself for
//!   one camera), its image files in natural sort order (`2.bmp` before
//!   `10.bmp`), assigned to sets and shifts in turn;
//! - in both cases `--skip` globs (`*`, `?`) leave out Gray-code or other
//!   extra images.
//!
//! [`assign`] is pure (it sees only file names), [`inspect_images`] reads
//! headers (and samples only where the bit depth must be measured), and
//! [`build_manifest`] writes paths relative to the manifest.

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::error::IoError;
use super::images::{self, GrayPixels};
use super::manifest::{CalibrationSource, Manifest, ManifestGrayCode, ManifestSet, ProjectorSize};
use crate::engine::camera_projector::{GrayCodeLayout, ProjectorAxis};
use crate::engine::control::RunControl;
use crate::engine::phase_shift::MAX_SHIFTS;
use crate::engine::unwrap::MAX_SETS;

mod assign;
mod files;
mod image_checks;
mod manifest_out;
mod pattern;

pub use self::assign::*;
pub use self::files::*;
pub use self::image_checks::*;
pub use self::manifest_out::*;
pub use self::pattern::*;

/// File extensions taken as images (case-insensitive).
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "tif", "tiff", "bmp", "pgm", "pnm"];

/// Camera name used when the data has one camera and none is named.
pub const DEFAULT_CAMERA: &str = "camera";

/// A camera of the import: its manifest name and what identifies its files
/// (the `{camera}` text, or the subfolder name).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CameraSpec {
    pub name: String,
    pub key: String,
}

/// What the user said about the folder.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportSpec {
    /// Fringe periods in projector pixels, sparsest first; may be empty when
    /// the pattern has `{period}` (then the periods found are used).
    pub periods_px: Vec<f64>,
    /// Shifts per set: one number for every set, or one per set; may be empty
    /// when the pattern has `{shift}` (then counted from the files).
    pub shifts: Vec<usize>,
    pub pattern: Option<String>,
    /// Cameras to take, in order; empty: every camera found.
    pub cameras: Vec<CameraSpec>,
    /// Globs of files to leave out (matched against the relative path and the file name).
    pub skip: Vec<String>,
    /// Calibration file (absolute, or relative to the working folder).
    pub calibration: Option<PathBuf>,
    pub bit_depth: Option<u32>,
    /// +1: `delta_k = offset + 2 pi k / N`; -1: `offset - 2 pi k / N`.
    pub shift_sign: f64,
    pub shift_offset_rad: f64,
    /// The projector axis of each set, in the order of the periods; empty:
    /// every set along x.
    pub axes: Vec<ProjectorAxis>,
    /// A camera–projector rig's projector (issue 52).
    pub projector: Option<ProjectorSize>,
    /// A Gray code in OpenCV's layout after the sets: column frames, row
    /// frames (where `rows`), white, black, in file order.
    pub gray_code: Option<ImportGrayCode>,
}

/// The Gray code of a camera–projector import.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImportGrayCode {
    pub cell_px: u32,
    pub rows: bool,
}

impl ImportGrayCode {
    /// Frames after the sets: per axis a pattern and inverse per bit plane,
    /// then white and black.
    pub fn frames(&self, projector: ProjectorSize) -> usize {
        let (columns, rows) = self.frames_per_axis(projector);
        columns + rows + 2
    }

    /// Column frames and row frames (0 without rows).
    pub fn frames_per_axis(&self, projector: ProjectorSize) -> (usize, usize) {
        let layout = GrayCodeLayout { cell_px: self.cell_px, rows: self.rows };
        (layout.frames(projector.width_px), if self.rows { layout.frames(projector.height_px) } else { 0 })
    }
}

impl Default for ImportSpec {
    fn default() -> Self {
        Self {
            periods_px: Vec::new(),
            shifts: Vec::new(),
            pattern: None,
            cameras: Vec::new(),
            skip: Vec::new(),
            calibration: None,
            bit_depth: None,
            shift_sign: 1.0,
            shift_offset_rad: 0.0,
            axes: Vec::new(),
            projector: None,
            gray_code: None,
        }
    }
}

impl ImportSpec {
    /// The phase shifts the manifest will give a set of `n` images, or `None`
    /// for the default `2 pi k / N`.
    pub fn phase_shifts_rad(&self, n: usize) -> Option<Vec<f64>> {
        if self.shift_sign > 0.0 && self.shift_offset_rad == 0.0 {
            return None;
        }
        let sign = if self.shift_sign < 0.0 { -1.0 } else { 1.0 };
        Some((0..n).map(|k| self.shift_offset_rad + sign * std::f64::consts::TAU * k as f64 / n as f64).collect())
    }
}

/// Parses `left,right` or `left=L,right=R` (manifest name = file key).
pub fn parse_cameras(text: &str) -> Result<Vec<CameraSpec>, ImportFault> {
    let mut out: Vec<CameraSpec> = Vec::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (name, key) = match item.split_once('=') {
            Some((n, k)) => (n.trim(), k.trim()),
            None => (item, item),
        };
        if !valid_camera_name(name) || key.is_empty() {
            return Err(ImportFault::BadCameraName { name: item.to_string() });
        }
        if out.iter().any(|c| c.name == name || c.key == key) {
            return Err(ImportFault::RepeatedCamera { name: item.to_string() });
        }
        out.push(CameraSpec { name: name.to_string(), key: key.to_string() });
    }
    Ok(out)
}

/// Parses `x,x,y,y`: the projector axis of each set.
pub fn parse_axes(text: &str) -> Result<Vec<ProjectorAxis>, ImportFault> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| match s {
            "x" | "X" => Ok(ProjectorAxis::X),
            "y" | "Y" => Ok(ProjectorAxis::Y),
            _ => Err(ImportFault::BadAxis { found: s.to_string() }),
        })
        .collect()
}

/// Parses `1920x1080`: a projector's width and height in its pixels.
pub fn parse_projector(text: &str) -> Result<ProjectorSize, ImportFault> {
    let bad = || ImportFault::BadProjector { found: text.to_string() };
    let (w, h) = text.trim().split_once(['x', 'X']).ok_or_else(bad)?;
    let side = |s: &str| s.trim().parse::<usize>().ok().filter(|&n| (1..=1 << 20).contains(&n)).ok_or_else(bad);
    Ok(ProjectorSize { width_px: side(w)?, height_px: side(h)? })
}

/// Parses a list of numbers such as `912,144,24,12`.
pub fn parse_list<T: std::str::FromStr>(text: &str, what: &'static str) -> Result<Vec<T>, ImportFault> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| ImportFault::BadNumber { what, found: s.to_string() }))
        .collect()
}

/// What is wrong with an import (the folder is named by [`ImportError`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ImportFault {
    #[error("'{found}' in {what} is not a number")]
    BadNumber { what: &'static str, found: String },
    #[error("camera '{name}' is not usable: write NAME or NAME=KEY with letters, digits, '-' or '_'")]
    BadCameraName { name: String },
    #[error("camera '{name}' is given twice")]
    RepeatedCamera { name: String },
    #[error("pattern '{pattern}': {problem}")]
    BadPattern { pattern: String, problem: String },
    #[error("--skip '{glob}' is not a glob: {problem}")]
    BadSkip { glob: String, problem: String },
    #[error("no fringe periods: give the periods (--periods), e.g. 912,144,24,12, sparsest first")]
    NoPeriods,
    #[error("periods {periods} must be positive and all different within an axis (one period per set)")]
    PeriodOrder { periods: String },
    #[error("--axes lists {found} axes for {sets} sets; give one axis (x or y) per period")]
    AxesLength { found: usize, sets: usize },
    #[error("'{found}' in --axes is not an axis: write x or y")]
    BadAxis { found: String },
    #[error("sets along projector y and a Gray code belong to a camera–projector rig: give --projector WIDTHxHEIGHT")]
    NoProjector,
    #[error("--projector must be WIDTHxHEIGHT in projector pixels, e.g. 1920x1080, found '{found}'")]
    BadProjector { found: String },
    #[error(
        "with --axes or --gray-code the images are taken in file order: use a pattern with {{index}} or one folder \
         per camera"
    )]
    NeedsFileOrder,
    #[error("{sets} fringe sets; at most {MAX_SETS} are supported")]
    TooManySets { sets: usize },
    #[error("no shift counts: give the shifts per set (--shifts), e.g. 12, or 12,12,12,4 per set")]
    NoShifts,
    #[error("--shifts lists {found} counts for {sets} sets; give one count, or one per set")]
    ShiftsLength { found: usize, sets: usize },
    #[error("a set needs 3 to {MAX_SHIFTS} shifts, found {found}")]
    BadShiftCount { found: usize },
    #[error("--shift-sign must be 1 or -1, found {found}")]
    BadShiftSign { found: String },
    #[error("holds no image files (PNG, TIFF, BMP or PGM){}", if *skipped > 0 { format!(" that --skip leaves in ({skipped} skipped)") } else { String::new() })]
    NoImages { skipped: usize },
    #[error("no file matches the pattern '{pattern}'{}", example.as_ref().map(|e| format!(" (e.g. {e} does not)")).unwrap_or_default())]
    NothingMatches { pattern: String, example: Option<String> },
    #[error("camera '{camera}' is not in the folder (found: {found})")]
    CameraMissing { camera: String, found: String },
    #[error("camera name '{key}' (from {file}) is not usable in file names: name it with --cameras NAME={key}")]
    UnusableCameraKey { key: String, file: String },
    #[error("holds images of both camera subfolders and loose files; give a --pattern, or --skip the loose ones")]
    Ambiguous,
    #[error("{what} has {found} images but the sets need {needed} ({counts}){hint}")]
    Count { what: String, found: usize, needed: usize, counts: String, hint: &'static str },
    #[error("{what}: {a} and {b} both give {number}")]
    Duplicate { what: String, a: String, b: String, number: String },
    #[error("{what}: image number {missing} is missing (numbers {first} to {last} expected){}", after.as_ref().map(|a| format!(", after {a}")).unwrap_or_default())]
    Gap { what: String, missing: u64, first: u64, last: u64, after: Option<String> },
    #[error("period {period} (from {file}) is not one of --periods {periods}")]
    UnknownPeriod { period: String, file: String, periods: String },
    #[error("camera '{camera}' has no images of set {set} (period {period} px)")]
    SetMissing { camera: String, set: usize, period: String },
    #[error("set {set} (period {period} px) has {a} shifts for camera '{cam_a}' but {b} for '{cam_b}'")]
    ShiftsDiffer { set: usize, period: String, cam_a: String, a: usize, cam_b: String, b: usize },
    #[error("set numbers {found} from {{set}} do not fit --periods ({sets} sets)")]
    SetNumbers { found: String, sets: usize },
    #[error(
        "{file} is {width}x{height} px, but {reference} is {ref_width}x{ref_height} px: one camera's images must all have one size"
    )]
    SizeMismatch { file: String, width: usize, height: usize, reference: String, ref_width: usize, ref_height: usize },
    #[error(
        "{file} is a {bits}-bit file, but {reference} is {ref_bits}-bit: one camera's images must share one sample type"
    )]
    MixedContainers { file: String, bits: u32, reference: String, ref_bits: u32 },
    #[error("--bit-depth {bit_depth} does not fit {file}: {problem}")]
    BitDepth { bit_depth: u32, file: String, problem: String },
    #[error(
        "the manifest {} must be in the image folder or a folder above it (its paths are relative and stay inside its folder)",
        manifest.display()
    )]
    ManifestOutside { manifest: PathBuf },
    #[error(
        "the calibration {} is not in the manifest's folder {} or below it: copy it there (manifest paths stay inside that folder)",
        calibration.display(),
        folder.display()
    )]
    CalibrationOutside { calibration: PathBuf, folder: PathBuf },
    #[error("refusing to write the manifest over {}: it is one of the images", path.display())]
    ManifestIsImage { path: PathBuf },
}

/// An import failure: what, and in which folder.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("import {}: {fault}", folder.display())]
    Fault { folder: PathBuf, fault: Box<ImportFault> },
    #[error(transparent)]
    Io(#[from] IoError),
}

impl ImportError {
    /// `fault` found while importing `folder`.
    pub fn new(folder: &Path, fault: ImportFault) -> Self {
        ImportError::Fault { folder: folder.to_path_buf(), fault: Box::new(fault) }
    }

    fn at(folder: &Path) -> impl Fn(ImportFault) -> ImportError + '_ {
        move |fault| ImportError::new(folder, fault)
    }
}

#[cfg(test)]
mod tests;
