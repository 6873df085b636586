//! The fringe-set manifest: a JSON file beside its images
//! that says which image is which, and loading it into an
//! `engine::fringe::Measurement`.
//!
//! ```json
//! {"sheen_fringe_set": 1, "bit_depth": 8, "saturation_level": 255, "calibration": "calibration.json",
//!  "sets": [{"period": 912, "shifts": 12, "phase_shifts_rad": [0, 0.5236, ...],
//!            "images": {"left": ["left/p0912_00.png", ...], "right": ["right/p0912_00.png", ...]}}, ...]}
//! ```
//!
//! Paths are relative to the manifest and may not leave its folder. Sets go
//! from the sparsest (largest period, a single fringe over the field: Alg. 3
//! unwraps from it) to the densest, periods strictly decreasing. Image `k` of
//! a set has phase shift `delta_k` in `I_k = A + B cos(Phi + delta_k)`:
//! `phase_shifts_rad[k]`, or `2 pi k / N` without that key. Cameras may have
//! any name; `left` and `right` make a stereo pair (left = main), and one
//! camera alone is a phase-only measurement.
//!
//! A camera–projector rig (issue 52) says so and adds its projector, the
//! axis of each set and its Gray code (OpenCV's `GrayCodePattern` layout:
//! per axis, bit planes most significant first, each pattern then its
//! inverse; `cell_px` projector pixels per code unit):
//!
//! ```json
//! {"sheen_fringe_set": 1, "bit_depth": 8, "rig": "camera-projector",
//!  "projector": {"width": 1920, "height": 1080},
//!  "sets": [{"period": 100, "shifts": 3, "axis": "x", "images": {"cam": [...]}},
//!           {"period": 100, "shifts": 3, "axis": "y", "images": {"cam": [...]}}],
//!  "gray_code": {"layout": "opencv", "cell_px": 100, "columns": {"cam": [...]},
//!                "rows": {"cam": [...]}, "white": {"cam": "white.png"}, "black": {"cam": "black.png"}}}
//! ```
//!
//! `axis` is the projector axis along which the phase grows (`x`, the
//! default, or `y`); the periods decrease strictly within each axis. The
//! sets along x are the measurement's sets; those along y, the code and
//! the white and black frames are the rig's other patterns.

use crate::engine::warning::{Warning, WarningKind};
use std::collections::{BTreeMap, HashMap};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;
use serde_json::{Value, json};

use super::atomic::write_atomic;
use super::calibration::{self, CalibrationFault, calibration_from_value, read_calibration};
use super::error::IoError;
use super::images::{self, ImageLocation, PlaneMut};
use super::json::{self, JsonFault, child};
use super::pinhole_calibration::{camera_projector_calibration_from_value, read_camera_projector_calibration};
use crate::engine::camera_model::StereoCalibration;
use crate::engine::camera_projector::{CameraPatterns, GrayCodeLayout, ProjectorAxis, ProjectorPatterns};
use crate::engine::control::RunControl;
use crate::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Measurement, Samples, next_measurement_id};
use crate::engine::phase_shift::{MAX_SHIFTS, normal_matrix_inverse};
use crate::engine::pinhole::CameraProjectorCalibration;
use crate::engine::unwrap::MAX_SETS;

/// The manifest version this Sheen reads and writes (`"sheen_fringe_set": 1`).
pub const MANIFEST_VERSION: i64 = 1;

const TOP_KEYS: [&str; 8] =
    ["sheen_fringe_set", "bit_depth", "saturation_level", "calibration", "rig", "projector", "sets", "gray_code"];
const SET_KEYS: [&str; 5] = ["period", "shifts", "axis", "phase_shifts_rad", "images"];
const GRAY_CODE_KEYS: [&str; 6] = ["layout", "cell_px", "columns", "rows", "white", "black"];

/// The `rig` of a camera–projector manifest.
pub const CAMERA_PROJECTOR_RIG: &str = "camera-projector";
/// The only Gray code layout read: OpenCV's `GrayCodePattern`.
pub const OPENCV_LAYOUT: &str = "opencv";

/// Where the calibration of a measurement is.
#[derive(Clone, Debug, PartialEq)]
pub enum CalibrationSource {
    /// A calibration file, relative to the manifest.
    File(String),
    /// The calibration object itself, inline in the manifest.
    Inline(Value),
}

/// One fringe set: a period and, per camera, its phase-shifted images.
#[derive(Clone, Debug, PartialEq)]
pub struct ManifestSet {
    /// Fringe period in projector pixels (`per^m`).
    pub period_px: f64,
    pub shifts: usize,
    /// `delta_k` per image; `None` means `2 pi k / N`.
    pub phase_shifts_rad: Option<Vec<f64>>,
    /// The projector axis along which the phase grows (x unless a
    /// camera–projector rig says y).
    pub axis: ProjectorAxis,
    /// Per camera, the image of each shift, relative to the manifest.
    pub images: BTreeMap<String, Vec<String>>,
}

/// A camera–projector rig's projector, in its own pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProjectorSize {
    pub width_px: usize,
    pub height_px: usize,
}

/// A camera–projector rig's Gray code frames (OpenCV layout), per camera.
#[derive(Clone, Debug, PartialEq)]
pub struct ManifestGrayCode {
    /// Projector pixels per code unit (1: every column its own code).
    pub cell_px: u32,
    /// Column code frames: pattern then inverse per bit plane, most significant first.
    pub columns: BTreeMap<String, Vec<String>>,
    /// Row code frames the same way, where projected.
    pub rows: Option<BTreeMap<String, Vec<String>>>,
    pub white: BTreeMap<String, String>,
    pub black: BTreeMap<String, String>,
}

impl ManifestGrayCode {
    /// The frames a camera's code needs along an axis of `extent_px` projector pixels.
    pub fn frames_needed(&self, extent_px: usize) -> usize {
        GrayCodeLayout { cell_px: self.cell_px, rows: self.rows.is_some() }.frames(extent_px)
    }
}

/// A fringe-set manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct Manifest {
    pub bit_depth: u32,
    /// `None`: `2^bit_depth - 1`.
    pub saturation_level: Option<u16>,
    pub calibration: Option<CalibrationSource>,
    /// `Some` for a camera–projector rig (`"rig": "camera-projector"`).
    pub projector: Option<ProjectorSize>,
    /// Sparsest (largest period) first within each axis.
    pub sets: Vec<ManifestSet>,
    /// A camera–projector rig's Gray code, where projected.
    pub gray_code: Option<ManifestGrayCode>,
    /// What reading noticed without refusing (unknown keys, repeated images).
    pub warnings: Vec<Warning>,
}

/// What is wrong with a manifest.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ManifestFault {
    #[error(transparent)]
    Json(#[from] JsonFault),
    #[error(
        "declares sheen_fringe_set {found}; this Sheen reads version {MANIFEST_VERSION}: update Sheen or rewrite the manifest"
    )]
    UnsupportedVersion { found: String },
    #[error("bit_depth must be 8 (8-bit images) or 9 to 16 (16-bit images holding the camera's bits), found {found}")]
    BadBitDepth { found: String },
    #[error("saturation_level must be 1 to {max} (2^bit_depth - 1), found {found}")]
    BadSaturationLevel { found: String, max: u32 },
    #[error("lists no fringe set; 'sets' needs at least one, the sparsest (largest period) first")]
    NoSets,
    #[error("lists {sets} fringe sets; at most {max} are supported")]
    TooManySets { sets: usize, max: usize },
    #[error("set {set}: period must be a positive number of projector pixels, found {found}")]
    BadPeriod { set: usize, found: String },
    #[error(
        "set {set} (period {period} px) does not follow set {previous_set} (period {previous} px): list the sets \
         from the largest period to the smallest, each strictly smaller than the one before"
    )]
    PeriodOrder { set: usize, period: f64, previous_set: usize, previous: f64 },
    #[error("set {set} (period {period} px): shifts must be 3 to {max}, found {found}")]
    BadShiftCount { set: usize, period: f64, found: String, max: usize },
    #[error(
        "set {set} (period {period} px): phase_shifts_rad lists {found} shifts but shifts is {shifts}; give one \
         shift per image"
    )]
    ShiftListLength { set: usize, period: f64, shifts: usize, found: usize },
    #[error(
        "set {set} (period {period} px): phase_shifts_rad do not determine a phase (repeated or nearly equal \
         shifts); give at least 3 distinct shifts"
    )]
    DegenerateShifts { set: usize, period: f64 },
    #[error("set {set} (period {period} px) lists no camera under 'images'")]
    NoCameras { set: usize, period: f64 },
    #[error(
        "set {set} (period {period} px) has cameras [{found}] but set 0 has [{expected}]; every set needs the same \
         cameras"
    )]
    CamerasMismatch { set: usize, period: f64, found: String, expected: String },
    #[error("set {set}: camera name '{camera}' is not usable (it names output files): use letters, digits, '-' or '_'")]
    BadCameraName { set: usize, camera: String },
    #[error(
        "set {set} (period {period} px) camera '{camera}' lists {found} images but shifts is {shifts}; list one \
         image per shift"
    )]
    ImageCount { set: usize, period: f64, camera: String, shifts: usize, found: usize },
    #[error("set {set} camera '{camera}' image {image} path '{path}' {reason}")]
    BadImagePath { set: usize, camera: String, image: usize, path: String, reason: &'static str },
    #[error("calibration path '{path}' {reason}; or put the calibration inline in the manifest")]
    BadCalibrationPath { path: String, reason: &'static str },
    #[error("'calibration' must be a file name or a calibration object, found {found}")]
    BadCalibration { found: String },
    #[error("rig must be \"{CAMERA_PROJECTOR_RIG}\" (or left out for the telecentric camera pair), found {found}")]
    BadRig { found: String },
    #[error(
        "a camera–projector rig needs its projector's size: \"projector\": {{\"width\": W, \"height\": H}} in \
         projector pixels"
    )]
    NoProjector,
    #[error("'projector' is given but rig is not \"{CAMERA_PROJECTOR_RIG}\": add \"rig\": \"{CAMERA_PROJECTOR_RIG}\"")]
    ProjectorWithoutRig,
    #[error("projector {key} must be a positive number of projector pixels, found {found}")]
    BadProjector { key: &'static str, found: String },
    #[error("set {set}: axis must be \"x\" or \"y\", found {found}")]
    BadAxis { set: usize, found: String },
    #[error(
        "set {set} (period {period} px) runs along projector y, which only a camera–projector rig has: add \
         \"rig\": \"{CAMERA_PROJECTOR_RIG}\" and its projector"
    )]
    AxisWithoutProjector { set: usize, period: f64 },
    #[error("lists no fringe set along projector x; the sets along x are the measurement's phases")]
    NoSetAlongX,
    #[error("'gray_code' belongs to a camera–projector rig: add \"rig\": \"{CAMERA_PROJECTOR_RIG}\" and its projector")]
    GrayCodeWithoutProjector,
    #[error("gray_code.layout must be \"{OPENCV_LAYOUT}\" (OpenCV's GrayCodePattern order), found {found}")]
    BadGrayLayout { found: String },
    #[error("gray_code.cell_px must be a whole number of projector pixels from 1 up, found {found}")]
    BadCellSize { found: String },
    #[error("gray_code.{list} has cameras [{found}] but the sets have [{expected}]; give every camera's frames")]
    GrayCodeCameras { list: &'static str, found: String, expected: String },
    #[error(
        "gray_code.{list} camera '{camera}' lists {found} frames, but a code of {cells} cells of {cell_px} px over \
         the projector's {extent_px} px needs {expected} (a pattern and its inverse per bit plane): a frame is \
         missing or extra, or cell_px or the projector size is wrong",
        cells = extent_px.div_ceil(*cell_px)
    )]
    GrayFrameCount { list: &'static str, camera: String, found: u32, expected: u32, cell_px: u32, extent_px: u32 },
    /// `frame`: camera, image and path, as `camera 'cam' image 3 path 'x.png'`.
    #[error("gray_code.{list} {frame} {reason}")]
    BadGrayPath { list: &'static str, frame: String, reason: &'static str },
}

impl Manifest {
    /// The saturation level in force: given, or `2^bit_depth - 1`.
    pub fn saturation_level_dn(&self) -> u16 {
        self.saturation_level.unwrap_or_else(|| ((1u32 << self.bit_depth.clamp(1, 16)) - 1) as u16)
    }

    /// Camera names in measurement order: `left`, `right`, then the others sorted.
    pub fn camera_names(&self) -> Vec<String> {
        let Some(first) = self.sets.first() else { return Vec::new() };
        let mut names: Vec<String> = first.images.keys().cloned().collect();
        let rank = |n: &str| match n {
            "left" => 0,
            "right" => 1,
            _ => 2,
        };
        names.sort_by(|a, b| rank(a).cmp(&rank(b)).then_with(|| a.cmp(b)));
        names
    }

    /// Period and phase shifts of each set along `axis`, for the engine
    /// (along x: the measurement's sets).
    pub fn set_infos(&self, axis: ProjectorAxis) -> Vec<FringeSetInfo> {
        self.sets
            .iter()
            .filter(|s| s.axis == axis)
            .map(|s| match &s.phase_shifts_rad {
                Some(shifts) => FringeSetInfo { period_px: s.period_px, phase_shifts_rad: shifts.clone() },
                None => FringeSetInfo::uniform(s.period_px, s.shifts),
            })
            .collect()
    }

    /// Every image list of one camera and what each is, in manifest order:
    /// the sets, then the Gray code's columns, rows, white and black.
    fn image_groups(&self, camera: &str) -> Vec<(ImageGroup, Vec<&str>)> {
        let mut groups: Vec<(ImageGroup, Vec<&str>)> = self
            .sets
            .iter()
            .enumerate()
            .map(|(i, set)| (ImageGroup::Set(i), set.images[camera].iter().map(String::as_str).collect()))
            .collect();
        if let Some(code) = &self.gray_code {
            fn list<'a>(map: &'a BTreeMap<String, Vec<String>>, camera: &str) -> Vec<&'a str> {
                map[camera].iter().map(String::as_str).collect()
            }
            groups.push((ImageGroup::GrayColumns, list(&code.columns, camera)));
            if let Some(rows) = &code.rows {
                groups.push((ImageGroup::GrayRows, list(rows, camera)));
            }
            groups.push((ImageGroup::WhiteBlack, vec![code.white[camera].as_str(), code.black[camera].as_str()]));
        }
        groups
    }

    /// Every file this manifest reads (itself, calibration, images): what
    /// exports must never overwrite.
    pub fn input_paths(&self, manifest_path: &Path) -> Vec<PathBuf> {
        let dir = folder_of(manifest_path);
        let mut paths = vec![manifest_path.to_path_buf()];
        if let Some(CalibrationSource::File(f)) = &self.calibration {
            paths.push(dir.join(f));
        }
        for set in &self.sets {
            paths.extend(set.images.values().flatten().map(|p| dir.join(p)));
        }
        if let Some(code) = &self.gray_code {
            paths.extend(
                code.columns.values().chain(code.rows.iter().flat_map(|r| r.values())).flatten().map(|p| dir.join(p)),
            );
            paths.extend(code.white.values().chain(code.black.values()).map(|p| dir.join(p)));
        }
        paths
    }

    /// Checks everything that does not need the images; returns warnings
    /// (repeated images). Manifests built in code go through the same checks
    /// as read ones.
    pub fn validate(&self, manifest_path: &Path) -> Result<Vec<Warning>, IoError> {
        self.check(&manifest_path.display().to_string())
            .map_err(|fault| IoError::Manifest { path: manifest_path.to_path_buf(), fault })
    }

    fn check(&self, file: &str) -> Result<Vec<Warning>, ManifestFault> {
        if !(8..=16).contains(&self.bit_depth) {
            return Err(ManifestFault::BadBitDepth { found: self.bit_depth.to_string() });
        }
        let max = (1u32 << self.bit_depth) - 1;
        if let Some(level) = self.saturation_level
            && (level == 0 || u32::from(level) > max)
        {
            return Err(ManifestFault::BadSaturationLevel { found: level.to_string(), max });
        }
        if let Some(CalibrationSource::File(f)) = &self.calibration
            && let Err(reason) = check_relative(f)
        {
            return Err(ManifestFault::BadCalibrationPath { path: f.clone(), reason });
        }
        if self.sets.is_empty() {
            return Err(ManifestFault::NoSets);
        }
        if let Some(p) = self.projector {
            for (key, v) in [("width", p.width_px), ("height", p.height_px)] {
                if v == 0 {
                    return Err(ManifestFault::BadProjector { key, found: v.to_string() });
                }
            }
        }
        if !self.sets.iter().any(|s| s.axis == ProjectorAxis::X) {
            return Err(ManifestFault::NoSetAlongX);
        }
        if self.sets.len() > MAX_SETS {
            return Err(ManifestFault::TooManySets { sets: self.sets.len(), max: MAX_SETS });
        }
        let mut warnings = Vec::new();
        let mut seen: HashMap<&str, (usize, &str, usize)> = HashMap::new();
        for (i, set) in self.sets.iter().enumerate() {
            let period = set.period_px;
            if !(period.is_finite() && period > 0.0) {
                return Err(ManifestFault::BadPeriod { set: i, found: period.to_string() });
            }
            if set.axis == ProjectorAxis::Y && self.projector.is_none() {
                return Err(ManifestFault::AxisWithoutProjector { set: i, period });
            }
            // Within an axis, sparsest first (Alg. 3 unwraps in that order).
            if let Some(previous_set) = (0..i).rev().find(|&j| self.sets[j].axis == set.axis)
                && period >= self.sets[previous_set].period_px
            {
                let previous = self.sets[previous_set].period_px;
                return Err(ManifestFault::PeriodOrder { set: i, period, previous_set, previous });
            }
            if !(3..=MAX_SHIFTS).contains(&set.shifts) {
                let found = set.shifts.to_string();
                return Err(ManifestFault::BadShiftCount { set: i, period, found, max: MAX_SHIFTS });
            }
            if let Some(list) = &set.phase_shifts_rad {
                if list.len() != set.shifts {
                    return Err(ManifestFault::ShiftListLength {
                        set: i,
                        period,
                        shifts: set.shifts,
                        found: list.len(),
                    });
                }
                let full_mask = (1u32 << set.shifts) - 1;
                if list.iter().any(|d| !d.is_finite()) || normal_matrix_inverse(list, full_mask).is_none() {
                    return Err(ManifestFault::DegenerateShifts { set: i, period });
                }
            }
            if set.images.is_empty() {
                return Err(ManifestFault::NoCameras { set: i, period });
            }
            if i > 0 && !set.images.keys().eq(self.sets[0].images.keys()) {
                let names = |s: &ManifestSet| s.images.keys().cloned().collect::<Vec<_>>().join(", ");
                return Err(ManifestFault::CamerasMismatch {
                    set: i,
                    period,
                    found: names(set),
                    expected: names(&self.sets[0]),
                });
            }
            for (camera, paths) in &set.images {
                if !valid_camera_name(camera) {
                    return Err(ManifestFault::BadCameraName { set: i, camera: camera.clone() });
                }
                if paths.len() != set.shifts {
                    return Err(ManifestFault::ImageCount {
                        set: i,
                        period,
                        camera: camera.clone(),
                        shifts: set.shifts,
                        found: paths.len(),
                    });
                }
                for (k, p) in paths.iter().enumerate() {
                    if let Err(reason) = check_relative(p) {
                        return Err(ManifestFault::BadImagePath {
                            set: i,
                            camera: camera.clone(),
                            image: k,
                            path: p.clone(),
                            reason,
                        });
                    }
                    if let Some((s0, c0, k0)) = seen.insert(p.as_str(), (i, camera.as_str(), k)) {
                        warnings.push(Warning::new(
                            WarningKind::RepeatedImage,
                            format!(
                                "{file}: set {i} camera '{camera}' image {k} repeats {p}, already set {s0} camera \
                                 '{c0}' image {k0}; is the list right?"
                            ),
                        ));
                    }
                }
            }
        }
        if let Some(code) = &self.gray_code {
            self.check_gray_code(code, &mut seen, file, &mut warnings)?;
        }
        Ok(warnings)
    }

    /// The Gray code's frames: the sets' cameras, a pattern and its inverse
    /// per bit plane of the projector's code, paths inside the folder.
    fn check_gray_code<'a>(
        &self,
        code: &'a ManifestGrayCode,
        seen: &mut HashMap<&'a str, (usize, &'a str, usize)>,
        file: &str,
        warnings: &mut Vec<Warning>,
    ) -> Result<(), ManifestFault> {
        let Some(projector) = self.projector else {
            return Err(ManifestFault::GrayCodeWithoutProjector);
        };
        if code.cell_px == 0 {
            return Err(ManifestFault::BadCellSize { found: "0".into() });
        }
        let expected: Vec<&String> = self.sets[0].images.keys().collect();
        let names = |keys: Vec<&String>| keys.into_iter().cloned().collect::<Vec<_>>().join(", ");
        // (list, per camera its paths, the projector extent a code spans)
        type FrameLists<'a> = Vec<(&'static str, Vec<(&'a String, Vec<&'a String>)>, Option<usize>)>;
        let mut lists: FrameLists<'a> = vec![(
            "columns",
            code.columns.iter().map(|(c, l)| (c, l.iter().collect())).collect(),
            Some(projector.width_px),
        )];
        if let Some(rows) = &code.rows {
            lists.push((
                "rows",
                rows.iter().map(|(c, l)| (c, l.iter().collect())).collect(),
                Some(projector.height_px),
            ));
        }
        lists.push(("white", code.white.iter().map(|(c, p)| (c, vec![p])).collect(), None));
        lists.push(("black", code.black.iter().map(|(c, p)| (c, vec![p])).collect(), None));
        for (list, per_camera, extent_px) in lists {
            let cameras: Vec<&String> = per_camera.iter().map(|(c, _)| *c).collect();
            if cameras != expected {
                return Err(ManifestFault::GrayCodeCameras {
                    list,
                    found: names(cameras),
                    expected: names(expected.clone()),
                });
            }
            for (camera, paths) in per_camera {
                if let Some(extent_px) = extent_px {
                    let expected = code.frames_needed(extent_px);
                    if paths.len() != expected {
                        return Err(ManifestFault::GrayFrameCount {
                            list,
                            camera: camera.clone(),
                            found: paths.len() as u32,
                            expected: expected as u32,
                            cell_px: code.cell_px,
                            extent_px: extent_px as u32,
                        });
                    }
                }
                for (k, p) in paths.into_iter().enumerate() {
                    if let Err(reason) = check_relative(p) {
                        return Err(ManifestFault::BadGrayPath {
                            list,
                            frame: format!("camera '{camera}' image {k} path '{p}'"),
                            reason,
                        });
                    }
                    if let Some((s0, c0, k0)) = seen.insert(p.as_str(), (usize::MAX, camera.as_str(), k)) {
                        let first =
                            if s0 == usize::MAX { "a Gray code frame".to_string() } else { format!("set {s0}") };
                        warnings.push(Warning::new(
                            WarningKind::RepeatedImage,
                            format!(
                                "{file}: gray_code.{list} camera '{camera}' image {k} repeats {p}, already {first} \
                                 camera '{c0}' image {k0}; is the list right?"
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

/// Which list of a manifest an image belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ImageGroup {
    Set(usize),
    GrayColumns,
    GrayRows,
    WhiteBlack,
}

/// Camera names become parts of output file names (`{camera}_fused_phase.tif`).
fn valid_camera_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name.chars().all(|c| c.is_alphanumeric() || c == '-' || c == '_' || c == '.')
        && !name.starts_with('.')
}

/// A manifest path must be relative and stay inside the manifest's folder,
/// so a manifest can be moved with its images and never reaches elsewhere.
pub(crate) fn check_relative(p: &str) -> Result<(), &'static str> {
    if p.is_empty() {
        return Err("is empty");
    }
    let path = Path::new(p);
    let windows_absolute = p.starts_with('\\') || (p.len() >= 2 && p.as_bytes()[1] == b':');
    if path.is_absolute() || windows_absolute {
        return Err("is absolute; write it relative to the manifest's folder");
    }
    let mut depth = 0i64;
    for component in path.components() {
        match component {
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
            Component::ParentDir => {
                depth -= 1;
                if depth < 0 {
                    return Err("leaves the manifest's folder ('..'); keep the files in or below that folder");
                }
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err("is absolute; write it relative to the manifest's folder");
            }
        }
    }
    if depth == 0 {
        return Err("names the manifest's folder itself, not a file");
    }
    Ok(())
}

pub(crate) fn folder_of(manifest_path: &Path) -> PathBuf {
    match manifest_path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Reads and checks a manifest (not its images).
pub fn read_manifest(path: &Path) -> Result<Manifest, IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    parse_manifest_bytes(&bytes, path)
}

/// Parses and checks manifest bytes; `path` is named in errors and warnings.
pub fn parse_manifest_bytes(bytes: &[u8], path: &Path) -> Result<Manifest, IoError> {
    let fault = |fault| IoError::Manifest { path: path.to_path_buf(), fault };
    let file = path.display().to_string();
    let value = json::parse(bytes).map_err(|e| fault(e.into()))?;
    let mut manifest = parse_manifest(&value, &file).map_err(fault)?;
    let more = manifest.check(&file).map_err(fault)?;
    manifest.warnings.extend(more);
    Ok(manifest)
}

fn parse_manifest(value: &Value, file: &str) -> Result<Manifest, ManifestFault> {
    let mut warnings = Vec::new();
    let top = json::as_object(value, "")?;
    json::warn_unknown_keys(top, "", &TOP_KEYS, file, &mut warnings);
    let version = json::require(
        top,
        "",
        "sheen_fringe_set",
        " (the first key of a fringe-set manifest: \"sheen_fringe_set\": 1)",
    )?;
    if json::integer(version, "sheen_fringe_set", "1").ok() != Some(MANIFEST_VERSION) {
        return Err(ManifestFault::UnsupportedVersion { found: version.to_string() });
    }
    let bd = json::require(top, "", "bit_depth", " (8 for 8-bit images, else the camera's bits, e.g. 12)")?;
    let bit_depth = match json::integer(bd, "bit_depth", "an integer") {
        Ok(b) if (8..=16).contains(&b) => b as u32,
        _ => return Err(ManifestFault::BadBitDepth { found: json::describe(bd) }),
    };
    let saturation_level = match top.get("saturation_level") {
        None | Some(Value::Null) => None,
        Some(v) => {
            let max = (1u32 << bit_depth) - 1;
            match json::integer(v, "saturation_level", "an integer") {
                Ok(l) if l >= 1 && l <= i64::from(max) => Some(l as u16),
                _ => return Err(ManifestFault::BadSaturationLevel { found: json::describe(v), max }),
            }
        }
    };
    let calibration = match top.get("calibration") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(CalibrationSource::File(s.clone())),
        Some(v @ Value::Object(_)) => Some(CalibrationSource::Inline(v.clone())),
        Some(v) => return Err(ManifestFault::BadCalibration { found: json::describe(v) }),
    };
    let camera_projector = match top.get("rig") {
        None | Some(Value::Null) => false,
        Some(Value::String(r)) if r == CAMERA_PROJECTOR_RIG => true,
        Some(v) => return Err(ManifestFault::BadRig { found: json::describe(v) }),
    };
    let projector = match (top.get("projector"), camera_projector) {
        (None | Some(Value::Null), false) => None,
        (None | Some(Value::Null), true) => return Err(ManifestFault::NoProjector),
        (Some(_), false) => return Err(ManifestFault::ProjectorWithoutRig),
        (Some(v), true) => {
            let object = json::as_object(v, "projector")?;
            json::warn_unknown_keys(object, "projector", &["width", "height"], file, &mut warnings);
            let side = |key: &'static str| {
                let v = json::require(object, "projector", key, " (projector pixels)")?;
                match json::integer(v, key, "an integer") {
                    Ok(n) if (1..=1 << 20).contains(&n) => Ok(n as usize),
                    _ => Err(ManifestFault::BadProjector { key, found: json::describe(v) }),
                }
            };
            Some(ProjectorSize { width_px: side("width")?, height_px: side("height")? })
        }
    };
    let sets_value = json::require(top, "", "sets", " (the list of fringe sets, sparsest first)")?;
    let sets = json::array(sets_value, "sets", "a list of fringe sets")?
        .iter()
        .enumerate()
        .map(|(i, v)| parse_set(v, i, file, &mut warnings))
        .collect::<Result<Vec<_>, _>>()?;
    let gray_code = match top.get("gray_code") {
        None | Some(Value::Null) => None,
        Some(v) => Some(parse_gray_code(v, file, &mut warnings)?),
    };
    Ok(Manifest { bit_depth, saturation_level, calibration, projector, sets, gray_code, warnings })
}

/// Per camera, a list of paths (`{"cam": ["a.png", ...]}`).
fn parse_path_lists(v: &Value, key: &str) -> Result<BTreeMap<String, Vec<String>>, ManifestFault> {
    let mut out = BTreeMap::new();
    for (camera, list) in json::as_object(v, key)? {
        let key = child(key, camera);
        let paths = json::array(list, &key, "a list of image paths")?
            .iter()
            .enumerate()
            .map(|(k, p)| json::string(p, &format!("{key}[{k}]")).map(str::to_string))
            .collect::<Result<Vec<_>, _>>()?;
        out.insert(camera.clone(), paths);
    }
    Ok(out)
}

fn parse_gray_code(v: &Value, file: &str, warnings: &mut Vec<Warning>) -> Result<ManifestGrayCode, ManifestFault> {
    let object = json::as_object(v, "gray_code")?;
    json::warn_unknown_keys(object, "gray_code", &GRAY_CODE_KEYS, file, warnings);
    let layout = json::require(object, "gray_code", "layout", " (\"opencv\": OpenCV's GrayCodePattern order)")?;
    if layout.as_str() != Some(OPENCV_LAYOUT) {
        return Err(ManifestFault::BadGrayLayout { found: json::describe(layout) });
    }
    let cell = json::require(object, "gray_code", "cell_px", " (projector pixels per code unit, 1 for one per pixel)")?;
    let cell_px = match json::integer(cell, "gray_code.cell_px", "an integer") {
        Ok(n) if (1..=1 << 20).contains(&n) => n as u32,
        _ => return Err(ManifestFault::BadCellSize { found: json::describe(cell) }),
    };
    let columns = parse_path_lists(
        json::require(object, "gray_code", "columns", " (per camera, the column code's frames)")?,
        "gray_code.columns",
    )?;
    let rows = match object.get("rows") {
        None | Some(Value::Null) => None,
        Some(v) => Some(parse_path_lists(v, "gray_code.rows")?),
    };
    let single = |key: &'static str| -> Result<BTreeMap<String, String>, ManifestFault> {
        let path = child("gray_code", key);
        let v = json::require(object, "gray_code", key, " (per camera, one image)")?;
        json::as_object(v, &path)?
            .iter()
            .map(|(camera, p)| Ok((camera.clone(), json::string(p, &child(&path, camera))?.to_string())))
            .collect()
    };
    Ok(ManifestGrayCode { cell_px, columns, rows, white: single("white")?, black: single("black")? })
}

fn parse_set(v: &Value, i: usize, file: &str, warnings: &mut Vec<Warning>) -> Result<ManifestSet, ManifestFault> {
    let path = format!("sets[{i}]");
    let set = json::as_object(v, &path)?;
    json::warn_unknown_keys(set, &path, &SET_KEYS, file, warnings);
    let pv = json::require(set, &path, "period", " (the fringe period in projector pixels)")?;
    let period_px = match pv.as_f64() {
        Some(p) if p.is_finite() && p > 0.0 => p,
        _ => return Err(ManifestFault::BadPeriod { set: i, found: json::describe(pv) }),
    };
    let sv = json::require(set, &path, "shifts", " (the number of phase-shifted images)")?;
    let shifts = match json::integer(sv, &child(&path, "shifts"), "an integer") {
        Ok(n) if (3..=MAX_SHIFTS as i64).contains(&n) => n as usize,
        _ => {
            return Err(ManifestFault::BadShiftCount {
                set: i,
                period: period_px,
                found: json::describe(sv),
                max: MAX_SHIFTS,
            });
        }
    };
    let phase_shifts_rad = match set.get("phase_shifts_rad") {
        None | Some(Value::Null) => None,
        Some(list) => {
            let key = child(&path, "phase_shifts_rad");
            let items = json::array(list, &key, "a list of numbers (radians)")?;
            Some(
                items
                    .iter()
                    .enumerate()
                    .map(|(k, x)| json::number(x, &format!("{key}[{k}]")))
                    .collect::<Result<Vec<_>, _>>()?,
            )
        }
    };
    let axis = match set.get("axis") {
        None | Some(Value::Null) => ProjectorAxis::X,
        Some(Value::String(a)) if a == "x" => ProjectorAxis::X,
        Some(Value::String(a)) if a == "y" => ProjectorAxis::Y,
        Some(v) => return Err(ManifestFault::BadAxis { set: i, found: json::describe(v) }),
    };
    let iv = json::require(set, &path, "images", " (per camera, the list of image files)")?;
    let images = parse_path_lists(iv, &child(&path, "images"))?;
    Ok(ManifestSet { period_px, shifts, phase_shifts_rad, axis, images })
}

/// A period as the manifest writes it: an integer when it is one.
fn period_json(p: f64) -> Value {
    if p.fract() == 0.0 && p.abs() < 9.0e15 { json!(p as i64) } else { json!(p) }
}

/// The manifest as written, keys in the contract's order (a struct, because
/// serde_json's map would sort them and bury the version key).
#[derive(serde::Serialize)]
struct ManifestOut<'a> {
    sheen_fringe_set: i64,
    bit_depth: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    saturation_level: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    calibration: Option<Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rig: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    projector: Option<ProjectorOut>,
    sets: Vec<SetOut<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    gray_code: Option<GrayCodeOut<'a>>,
}

#[derive(serde::Serialize)]
struct ProjectorOut {
    width: usize,
    height: usize,
}

#[derive(serde::Serialize)]
struct GrayCodeOut<'a> {
    layout: &'static str,
    cell_px: u32,
    columns: &'a BTreeMap<String, Vec<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rows: Option<&'a BTreeMap<String, Vec<String>>>,
    white: &'a BTreeMap<String, String>,
    black: &'a BTreeMap<String, String>,
}

#[derive(serde::Serialize)]
struct SetOut<'a> {
    period: Value,
    shifts: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    axis: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    phase_shifts_rad: Option<&'a [f64]>,
    images: &'a BTreeMap<String, Vec<String>>,
}

fn manifest_out(m: &Manifest) -> ManifestOut<'_> {
    ManifestOut {
        sheen_fringe_set: MANIFEST_VERSION,
        bit_depth: m.bit_depth,
        saturation_level: m.saturation_level,
        calibration: m.calibration.as_ref().map(|c| match c {
            CalibrationSource::File(f) => json!(f),
            CalibrationSource::Inline(v) => v.clone(),
        }),
        rig: m.projector.map(|_| CAMERA_PROJECTOR_RIG),
        projector: m.projector.map(|p| ProjectorOut { width: p.width_px, height: p.height_px }),
        gray_code: m.gray_code.as_ref().map(|g| GrayCodeOut {
            layout: OPENCV_LAYOUT,
            cell_px: g.cell_px,
            columns: &g.columns,
            rows: g.rows.as_ref(),
            white: &g.white,
            black: &g.black,
        }),
        sets: m
            .sets
            .iter()
            .map(|s| SetOut {
                period: period_json(s.period_px),
                shifts: s.shifts,
                // Written for a camera–projector rig only: a telecentric
                // pair's manifest stays as before.
                axis: m.projector.map(|_| s.axis.name()),
                phase_shifts_rad: s.phase_shifts_rad.as_deref(),
                images: &s.images,
            })
            .collect(),
    }
}

/// The manifest as a JSON value (what [`write_manifest`] writes).
pub fn manifest_to_json(m: &Manifest) -> Value {
    serde_json::to_value(manifest_out(m)).unwrap_or(Value::Null)
}

/// Writes a manifest atomically as pretty JSON. Absolute paths inside the
/// manifest's folder are made relative to it; the result must pass the same
/// checks as a read manifest (an unreadable manifest is never written).
pub fn write_manifest(path: &Path, manifest: &Manifest) -> Result<(), IoError> {
    let dir = folder_of(path);
    let mut m = manifest.clone();
    m.warnings.clear();
    let relative = |p: &mut String| {
        let as_path = Path::new(p.as_str());
        if !as_path.is_absolute() {
            return;
        }
        let stripped =
            as_path.strip_prefix(&dir).ok().map(Path::to_path_buf).or_else(|| {
                Some(as_path.canonicalize().ok()?.strip_prefix(dir.canonicalize().ok()?).ok()?.to_path_buf())
            });
        if let Some(rel) = stripped.and_then(|r| r.to_str().map(|s| s.replace('\\', "/"))) {
            *p = rel;
        }
    };
    for set in &mut m.sets {
        set.images.values_mut().flatten().for_each(relative);
    }
    if let Some(code) = &mut m.gray_code {
        code.columns.values_mut().chain(code.rows.iter_mut().flat_map(|r| r.values_mut())).flatten().for_each(relative);
        code.white.values_mut().chain(code.black.values_mut()).for_each(relative);
    }
    if let Some(CalibrationSource::File(f)) = &mut m.calibration {
        relative(f);
    }
    m.validate(path)?;
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &manifest_out(&m)).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
}

/// A measurement decoded from a manifest, with what loading noticed.
#[derive(Clone, Debug)]
pub struct Loaded {
    pub measurement: Measurement,
    pub warnings: Vec<Warning>,
}

/// Reads a manifest and decodes all its images ([`load_manifest_measurement`]).
pub fn load_measurement(path: &Path, control: &RunControl) -> Result<Loaded, IoError> {
    let manifest = read_manifest(path)?;
    load_manifest_measurement(&manifest, path, control)
}

/// A decoded image's warning (empty if none) and largest sample, or `None`
/// when the job was skipped after a failure or cancel.
type JobOutcome = Result<Option<(String, u16)>, IoError>;

/// At most this many per-image warnings are listed; the rest are counted.
const MAX_IMAGE_WARNINGS: usize = 3;

/// Decodes the images of an in-memory manifest that lives (or will live) at
/// `manifest_path`: relative paths resolve against its folder, and it is the
/// measurement's label. Images decode in parallel straight into each stack's
/// buffer (`u8` for bit depth 8, `u16` otherwise); progress goes to
/// `control`, which can cancel.
pub fn load_manifest_measurement(
    manifest: &Manifest,
    manifest_path: &Path,
    control: &RunControl,
) -> Result<Loaded, IoError> {
    let mut warnings = manifest.warnings.clone();
    for w in manifest.validate(manifest_path)? {
        if !warnings.contains(&w) {
            warnings.push(w);
        }
    }
    let dir = folder_of(manifest_path);
    // A camera–projector rig's calibration is a pinhole model of both
    // devices; the telecentric pair's is the affine stereo one.
    let (calibration, rig_calibration) = match manifest.projector {
        Some(_) => (None, resolve_rig_calibration(manifest, manifest_path, &dir, &mut warnings)?),
        None => (resolve_calibration(manifest, manifest_path, &dir, &mut warnings)?, None),
    };
    let cameras = manifest.camera_names();
    // Per camera, every list of images: the sets, then the Gray code's.
    let groups: Vec<Vec<(ImageGroup, Vec<&str>)>> = cameras.iter().map(|c| manifest.image_groups(c)).collect();
    let location = |camera: usize, group: usize, image: usize| {
        let (kind, paths) = &groups[camera][group];
        let (set, gray_code, image) = match kind {
            ImageGroup::Set(set) => (*set, None, image),
            ImageGroup::GrayColumns => (0, Some("columns"), image),
            ImageGroup::GrayRows => (0, Some("rows"), image),
            ImageGroup::WhiteBlack => (0, Some(if image == 0 { "white" } else { "black" }), 0),
        };
        ImageLocation { camera: cameras[camera].clone(), set, gray_code, image, listed_as: paths[image].to_string() }
    };

    // The first image of each camera fixes its size; check it against the
    // calibration before decoding anything else.
    let mut sizes = Vec::with_capacity(cameras.len());
    for name in &cameras {
        let first = &manifest.sets[0].images[name][0];
        let path = dir.join(first);
        let header = images::probe(&path).map_err(|fault| IoError::Image {
            path: path.clone(),
            location: Some(Box::new(location(sizes.len(), 0, 0))),
            fault,
        })?;
        sizes.push((header.width, header.height));
    }
    if let (Some((rig, path, inline)), Some(&(w, h))) = (&rig_calibration, sizes.first())
        && (rig.camera.width, rig.camera.height) != (w, h)
    {
        let image = PathBuf::from(&manifest.sets[0].images[&cameras[0]][0]);
        return Err(IoError::Calibration {
            path: path.clone(),
            inline: *inline,
            fault: CalibrationFault::ImageSize {
                camera: cameras[0].clone(),
                calibration_width: rig.camera.width,
                calibration_height: rig.camera.height,
                image,
                image_width: w,
                image_height: h,
            },
        });
    }
    if let Some((calib, calib_path, inline)) = &calibration {
        if cameras.len() >= 2 && (cameras[0] != "left" || cameras[1] != "right") {
            warnings.push(Warning::new(
                WarningKind::CamerasPairedByOrder,
                format!(
                    "{}: the calibration's cameras are 'left' and 'right', but the manifest's are '{}' and '{}'; \
                     they are paired in that order (name them left and right to be explicit)",
                    manifest_path.display(),
                    cameras[0],
                    cameras[1]
                ),
            ));
        }
        for (i, model) in [&calib.left, &calib.right].into_iter().enumerate().take(cameras.len()) {
            let image = PathBuf::from(&manifest.sets[0].images[&cameras[i]][0]);
            calibration::check_image_size(&cameras[i], model, &image, sizes[i].0, sizes[i].1)
                .map_err(|fault| IoError::Calibration { path: calib_path.clone(), inline: *inline, fault })?;
        }
    }

    // Allocate every stack up front: a measurement too large for memory is
    // refused with what it would need instead of failing midway.
    let sixteen = manifest.bit_depth > 8;
    let mut stacks: Vec<Vec<Samples>> = Vec::with_capacity(cameras.len());
    let images_per_camera = groups.first().map_or(0, |g| g.iter().map(|(_, paths)| paths.len() as u64).sum::<u64>());
    let total_bytes: u64 =
        sizes.iter().map(|(w, h)| (w * h) as u64).sum::<u64>() * images_per_camera * if sixteen { 2 } else { 1 };
    let available = available_memory_bytes();
    let out_of_memory = || IoError::OutOfMemory { path: manifest_path.to_path_buf(), bytes: total_bytes, available };
    if available.is_some_and(|a| total_bytes > a) {
        return Err(out_of_memory());
    }
    for (ci, &(w, h)) in sizes.iter().enumerate() {
        let mut per_set = Vec::with_capacity(groups[ci].len());
        for (_, paths) in &groups[ci] {
            let len = w * h * paths.len();
            let samples = if sixteen { alloc(len).map(Samples::U16) } else { alloc(len).map(Samples::U8) };
            per_set.push(samples.ok_or_else(out_of_memory)?);
        }
        stacks.push(per_set);
    }

    struct Job<'a> {
        order: usize,
        camera: usize,
        group: usize,
        image: usize,
        plane: PlaneMut<'a>,
    }
    let mut jobs = Vec::new();
    for (ci, per_set) in stacks.iter_mut().enumerate() {
        let n = sizes[ci].0 * sizes[ci].1;
        for (si, samples) in per_set.iter_mut().enumerate() {
            let planes: Vec<PlaneMut<'_>> = match samples {
                Samples::U8(v) => v.chunks_mut(n.max(1)).map(PlaneMut::U8).collect(),
                Samples::U16(v) => v.chunks_mut(n.max(1)).map(PlaneMut::U16).collect(),
            };
            for (k, plane) in planes.into_iter().enumerate() {
                jobs.push(Job { order: 0, camera: ci, group: si, image: k, plane });
            }
        }
    }
    // Manifest order (set, camera, image) decides which error is reported first.
    jobs.sort_by_key(|j| (j.group, j.camera, j.image));
    jobs.iter_mut().enumerate().for_each(|(i, j)| j.order = i);
    let job_count = jobs.len();
    let done = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    control.begin_stage("load images");
    let results: Vec<(usize, JobOutcome)> = jobs
        .into_par_iter()
        .map(|job| {
            if failed.load(Ordering::Relaxed) || control.is_cancelled() {
                return (job.order, Ok(None));
            }
            let listed = groups[job.camera][job.group].1[job.image];
            let path = dir.join(listed);
            let reference = Path::new(groups[job.camera][0].1[0]);
            let (w, h) = sizes[job.camera];
            let loc = location(job.camera, job.group, job.image);
            let result = images::decode_into(&path, &loc.to_string(), job.plane, w, h, reference, manifest.bit_depth)
                .map(|d| Some((d.warning.unwrap_or_default(), d.max_value_dn)))
                .map_err(|fault| IoError::Image { path: path.clone(), location: Some(Box::new(loc)), fault });
            if result.is_err() {
                failed.store(true, Ordering::Relaxed);
            }
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            control.set_fraction(n as f32 / job_count.max(1) as f32);
            (job.order, result)
        })
        .collect();
    control.check()?;
    let mut image_warnings = Vec::new();
    let mut max_value_dn = 0u16;
    let mut ordered = results;
    ordered.sort_by_key(|(order, _)| *order);
    for (_, result) in ordered {
        if let Some((warning, max)) = result? {
            max_value_dn = max_value_dn.max(max);
            if !warning.is_empty() {
                image_warnings.push(warning);
            }
        }
    }
    let extra = image_warnings.len().saturating_sub(MAX_IMAGE_WARNINGS);
    warnings.extend(
        image_warnings.into_iter().take(MAX_IMAGE_WARNINGS).map(|w| Warning::new(WarningKind::ImageConverted, w)),
    );
    if extra > 0 {
        warnings.push(Warning::new(
            WarningKind::ImageConverted,
            format!("... and {extra} more images converted the same way"),
        ));
    }
    if manifest.saturation_level.is_none() && images::bits_for_value(max_value_dn) < manifest.bit_depth {
        warnings.push(Warning::new(
            WarningKind::BitDepthUnreached,
            format!(
                "{}: the largest sample is {max_value_dn} but bit_depth is {}, so saturation is detected only at {}: \
                 if the camera is {}-bit, set bit_depth (or saturation_level) accordingly, or saturated pixels go \
                 unnoticed",
                manifest_path.display(),
                manifest.bit_depth,
                manifest.saturation_level_dn(),
                images::bits_for_value(max_value_dn)
            ),
        ));
    }

    // Sort each camera's stacks: sets along x are the measurement's, the
    // rest the rig's other patterns.
    let mut camera_fringes = Vec::with_capacity(cameras.len());
    let mut camera_patterns = Vec::with_capacity(cameras.len());
    for (((name, per_group), &(width, height)), kinds) in cameras.iter().zip(stacks).zip(&sizes).zip(&groups) {
        let mut x_stacks = Vec::new();
        let mut patterns =
            CameraPatterns { y_stacks: Vec::new(), gray_columns: None, gray_rows: None, white_black: None };
        for (samples, (kind, paths)) in per_group.into_iter().zip(kinds) {
            let stack = FringeStack { width, height, shifts: paths.len(), samples };
            match kind {
                ImageGroup::Set(i) if manifest.sets[*i].axis == ProjectorAxis::X => x_stacks.push(stack),
                ImageGroup::Set(_) => patterns.y_stacks.push(stack),
                ImageGroup::GrayColumns => patterns.gray_columns = Some(stack),
                ImageGroup::GrayRows => patterns.gray_rows = Some(stack),
                ImageGroup::WhiteBlack => patterns.white_black = Some(stack),
            }
        }
        camera_fringes.push(CameraFringes { name: name.clone(), width, height, stacks: x_stacks });
        camera_patterns.push(patterns);
    }
    let projector = manifest.projector.map(|p| ProjectorPatterns {
        projector_width_px: p.width_px,
        projector_height_px: p.height_px,
        y_sets: manifest.set_infos(ProjectorAxis::Y),
        gray_code: manifest.gray_code.as_ref().map(|g| GrayCodeLayout { cell_px: g.cell_px, rows: g.rows.is_some() }),
        cameras: camera_patterns,
        calibration: rig_calibration.map(|(c, _, _)| c),
    });
    let cameras = camera_fringes;
    let measurement = Measurement {
        bit_depth: manifest.bit_depth,
        saturation_level: manifest.saturation_level_dn(),
        sets: manifest.set_infos(ProjectorAxis::X),
        cameras,
        calibration: calibration.map(|(c, _, _)| c),
        label: manifest_path.display().to_string(),
        projector,
        id: next_measurement_id(),
    };
    Ok(Loaded { measurement, warnings })
}

/// Memory the system can still give (Linux `MemAvailable`), if known.
pub(crate) fn available_memory_bytes() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// A zeroed buffer, or `None` when memory cannot be had.
///
/// Asked of the allocator as zeroed memory rather than filled after
/// reserving: fresh pages come zeroed from the OS, so nothing writes the
/// 300 MB of a full-size set before the decoders do, and their pages are
/// first touched by the parallel decoders instead of by one thread's fill
/// (40 ms of a one-shot run's start, docs/benchmarks-history.md).
fn alloc<T: bytemuck::Zeroable>(len: usize) -> Option<Vec<T>> {
    bytemuck::allocation::try_zeroed_vec(len).ok()
}

/// A camera–projector rig's calibration and where it came from, its
/// devices checked against the camera's image and the projector's size.
type RigCalibration = (CameraProjectorCalibration, PathBuf, bool);

fn resolve_rig_calibration(
    manifest: &Manifest,
    manifest_path: &Path,
    dir: &Path,
    warnings: &mut Vec<Warning>,
) -> Result<Option<RigCalibration>, IoError> {
    let (calibration, path, inline) =
        match &manifest.calibration {
            None => return Ok(None),
            Some(CalibrationSource::File(f)) => {
                let path = dir.join(f);
                let (c, w) = read_camera_projector_calibration(&path)?;
                warnings.extend(w);
                (c, path, false)
            }
            Some(CalibrationSource::Inline(v)) => {
                let origin = format!("inline calibration in {}", manifest_path.display());
                let (c, w) = camera_projector_calibration_from_value(v, &origin)
                    .map_err(|fault| IoError::Calibration { path: manifest_path.to_path_buf(), inline: true, fault })?;
                warnings.extend(w);
                (c, manifest_path.to_path_buf(), true)
            }
        };
    let fault = |key: &str, problem: String| IoError::Calibration {
        path: path.clone(),
        inline,
        fault: CalibrationFault::Pinhole { key: key.to_string(), problem },
    };
    if let Some(p) = manifest.projector
        && (p.width_px, p.height_px) != (calibration.projector.width, calibration.projector.height)
    {
        return Err(fault(
            "projector",
            format!(
                "is calibrated as {}x{} px but the manifest's projector is {}x{} px: use the calibration of this rig",
                calibration.projector.width, calibration.projector.height, p.width_px, p.height_px
            ),
        ));
    }
    if manifest.camera_names().len() != 1 {
        return Err(fault(
            "camera",
            format!("calibrates one camera, but the manifest has {}", manifest.camera_names().join(", ")),
        ));
    }
    Ok(Some((calibration, path, inline)))
}

/// The calibration, where it came from (file, or the manifest when inline).
fn resolve_calibration(
    manifest: &Manifest,
    manifest_path: &Path,
    dir: &Path,
    warnings: &mut Vec<Warning>,
) -> Result<Option<(StereoCalibration, PathBuf, bool)>, IoError> {
    Ok(match &manifest.calibration {
        None => None,
        Some(CalibrationSource::File(f)) => {
            let path = dir.join(f);
            let (c, w) = read_calibration(&path)?;
            warnings.extend(w);
            Some((c, path, false))
        }
        Some(CalibrationSource::Inline(v)) => {
            let (c, w) = calibration_from_value(v, manifest_path)?;
            warnings.extend(w);
            Some((c, manifest_path.to_path_buf(), true))
        }
    })
}

#[cfg(test)]
mod tests;
