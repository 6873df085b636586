//! The calibration-set contract: a JSON file beside the target
//! images of several poses, calibrating the rig from it, and writing sets
//! (for the simulator), calibration reports and truths.
//!
//! ```json
//! {"sheen_calibration_set": 1,
//!  "target": {"kind": "circles", "rows": 9, "cols": 11, "pitch_mm": 0.5, "dark_on_light": true},
//!  "poses": [{"left": "left/pose00.png", "right": "right/pose00.png"}, ...]}
//! ```
//!
//! `kind` is `circles` (`rows x cols` filled circles) or `checkerboard`
//! (`rows x cols` inner corners); `dark_on_light` defaults to true. Paths are
//! relative to the set's file and may not leave its folder; images are
//! grayscale PNG, TIFF, BMP or PGM like a fringe set's. Pose 0 is the world
//! frame of the result. Every pose needs both cameras' images; a pose whose
//! target is not found completely is skipped with a warning naming the image,
//! and fewer than 3 usable poses is an error naming the set.
//!
//! A camera–projector rig's set (`"rig": "camera-projector"`) lists one
//! fringe set per pose instead ([`RigCalibrationSet`]).

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde_json::{Value, json};

use super::atomic::write_atomic;
use super::calibration::calibration_to_value;
use super::error::IoError;
use super::images::{GrayPixels, read_gray_image};
use super::json::{self, JsonFault, child};
use super::manifest::load_measurement;
use super::manifest::{check_relative, folder_of};
use crate::engine::calibration::camera_projector::{
    RigCalibrateError, RigCalibrationOptions, RigCalibrationReport, observe_measurement, solve_rig,
};
use crate::engine::calibration::detect::DetectionError;
use crate::engine::calibration::gray_image::GrayImage;
use crate::engine::calibration::grid::GridError;
use crate::engine::calibration::model::Pose;
use crate::engine::calibration::report::CalibrationReport;
use crate::engine::calibration::target::{Target, TargetKind};
use crate::engine::calibration::{
    CAMERA_NAMES, CalibrateError, CalibrationOptions, MIN_POSES, PoseDetections, PoseOutcome, PoseSource, SkippedPose,
    detect_pose, solve,
};
use crate::engine::camera_model::StereoCalibration;
use crate::engine::control::RunControl;
use crate::engine::pinhole::CameraProjectorCalibration;
use crate::engine::warning::Warning;

/// The set version this Sheen reads and writes (`"sheen_calibration_set": 1`).
pub const CALIBRATION_SET_VERSION: i64 = 1;

const TOP_KEYS: [&str; 3] = ["sheen_calibration_set", "target", "poses"];
const RIG_TOP_KEYS: [&str; 4] = ["sheen_calibration_set", "rig", "target", "poses"];
/// The `rig` of a camera–projector calibration set.
pub const CAMERA_PROJECTOR_RIG: &str = "camera-projector";
const TARGET_KEYS: [&str; 5] = ["kind", "rows", "cols", "pitch_mm", "dark_on_light"];
const POSE_KEYS: [&str; 2] = ["left", "right"];

/// The images of one pose, relative to the set's file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SetPose {
    pub left: String,
    pub right: String,
}

impl SetPose {
    pub fn image(&self, camera: usize) -> &str {
        if camera == 0 { &self.left } else { &self.right }
    }
}

/// A calibration set as read.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationSet {
    pub target: Target,
    pub poses: Vec<SetPose>,
    /// What reading noticed without refusing (unknown keys).
    pub warnings: Vec<Warning>,
}

/// What is wrong with a calibration set.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CalibrationSetFault {
    #[error(transparent)]
    Json(#[from] JsonFault),
    #[error(
        "declares sheen_calibration_set {found}; this Sheen reads version {CALIBRATION_SET_VERSION}: update Sheen or \
         rewrite the set"
    )]
    UnsupportedVersion { found: String },
    #[error("target.kind '{found}' is unknown; use \"circles\" (a dot grid) or \"checkerboard\" (inner corners)")]
    UnknownKind { found: String },
    #[error("target.{key} must be a whole number of at least 3 points, found {found}")]
    BadGrid { key: &'static str, found: String },
    #[error("target.pitch_mm must be a positive length in millimetres, found {found}")]
    BadPitch { found: String },
    #[error("lists no pose; 'poses' needs at least {MIN_POSES} (better 6 to 10), pose 0 lying flat on the stage")]
    NoPoses,
    #[error("pose {pose}: the {camera} image path '{path}' {reason}")]
    BadImagePath { pose: usize, camera: &'static str, path: String, reason: &'static str },
    #[error("pose {pose} lacks the {camera} image (key '{key}'); every pose needs both cameras' images")]
    MissingCamera { pose: usize, camera: &'static str, key: String },
    #[error(
        "pose {pose}: the {camera} image {} does not exist; every pose needs both cameras' images: copy it or remove \
         the pose",
        image.display()
    )]
    ImageMissing { pose: usize, camera: &'static str, image: PathBuf },
    #[error(
        "pose {pose}: the {camera} image {} is {width}x{height} px, but {} is {expected_width}x{expected_height} px; \
         all images of a camera must have one size",
        image.display(),
        reference.display()
    )]
    ImageSize {
        pose: usize,
        camera: &'static str,
        image: PathBuf,
        width: usize,
        height: usize,
        reference: PathBuf,
        expected_width: usize,
        expected_height: usize,
    },
    #[error(
        "the target is declared as {rows} x {cols} {noun}, but the images show {found_rows} x {found_cols} (in {}); \
         correct target.rows and target.cols",
        images.join(", ")
    )]
    GridMismatch {
        rows: usize,
        cols: usize,
        found_rows: usize,
        found_cols: usize,
        noun: &'static str,
        images: Vec<String>,
    },
    #[error("{0}")]
    Calibration(CalibrateError),
    #[error(
        "rig '{found}' is unknown; a calibration set is for \"telecentric-stereo\" (the default) or \"camera-projector\""
    )]
    UnknownRig { found: String },
    #[error(
        "a camera–projector calibration set (\"rig\": \"camera-projector\"), which only `sheen calibrate` solves: \
         `sheen calibrate SET --out calibration.json`; the app's calibration window solves the telecentric pair"
    )]
    CameraProjectorSet,
    #[error(
        "pose {pose} lacks 'fringe_set': a camera–projector pose is a fringe set (its manifest) recorded with the target in view"
    )]
    MissingFringeSet { pose: usize },
    #[error("pose {pose}: the fringe set path '{path}' {reason}")]
    BadFringeSetPath { pose: usize, path: String, reason: &'static str },
    #[error("pose {pose}: the fringe set {} does not exist", path.display())]
    FringeSetMissing { pose: usize, path: PathBuf },
    #[error("pose {pose}: {} is not a camera–projector fringe set (no 'rig': \"camera-projector\" with a Gray code)", path.display())]
    NotCameraProjector { pose: usize, path: PathBuf },
    #[error(
        "pose {pose}: {} has a {found_w}x{found_h} px camera and a {found_pw}x{found_ph} px projector, but the first \
         pose {expected_w}x{expected_h} and {expected_pw}x{expected_ph}; every pose must come from the same rig",
        path.display()
    )]
    RigSizes {
        pose: usize,
        path: PathBuf,
        found_w: usize,
        found_h: usize,
        found_pw: usize,
        found_ph: usize,
        expected_w: usize,
        expected_h: usize,
        expected_pw: usize,
        expected_ph: usize,
    },
    #[error("{0}")]
    RigCalibration(RigCalibrateError),
}

/// Reads and checks a calibration set: the JSON, the paths, and that every
/// listed image exists.
pub fn read_calibration_set(path: &Path) -> Result<CalibrationSet, IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    let fault = |fault| IoError::CalibrationSet { path: path.to_path_buf(), fault: Box::new(fault) };
    let value = json::parse(&bytes).map_err(|e| fault(e.into()))?;
    if value.get("rig").and_then(Value::as_str) == Some(CAMERA_PROJECTOR_RIG) {
        return Err(fault(CalibrationSetFault::CameraProjectorSet));
    }
    let set = parse_set(&value, &path.display().to_string()).map_err(fault)?;
    let dir = folder_of(path);
    for (k, pose) in set.poses.iter().enumerate() {
        for (c, camera) in CAMERA_NAMES.iter().enumerate() {
            let image = dir.join(pose.image(c));
            if !image.is_file() {
                return Err(fault(CalibrationSetFault::ImageMissing { pose: k, camera, image }));
            }
        }
    }
    Ok(set)
}

fn parse_set(value: &Value, origin: &str) -> Result<CalibrationSet, CalibrationSetFault> {
    let mut warnings = Vec::new();
    let top = json::as_object(value, "")?;
    json::warn_unknown_keys(top, "", &TOP_KEYS, origin, &mut warnings);
    let target = parse_target(top, origin, &mut warnings)?;
    let list = pose_list(top, " (a list of {\"left\": ..., \"right\": ...})")?;
    let mut poses = Vec::with_capacity(list.len());
    for (k, pose) in list.iter().enumerate() {
        let key = format!("poses[{k}]");
        let map = json::as_object(pose, &key)?;
        json::warn_unknown_keys(map, &key, &POSE_KEYS, origin, &mut warnings);
        let mut paths = Vec::with_capacity(2);
        for camera in CAMERA_NAMES {
            let Some(v) = map.get(camera) else {
                return Err(CalibrationSetFault::MissingCamera { pose: k, camera, key: child(&key, camera) });
            };
            let p = json::string(v, &child(&key, camera))?;
            check_relative(p).map_err(|reason| CalibrationSetFault::BadImagePath {
                pose: k,
                camera,
                path: p.to_string(),
                reason,
            })?;
            paths.push(p.to_string());
        }
        poses.push(SetPose { left: paths[0].clone(), right: paths[1].clone() });
    }
    Ok(CalibrationSet { target, poses, warnings })
}

/// The set's non-empty `poses` list (`hint` says what an entry holds).
fn pose_list<'v>(
    top: &'v serde_json::Map<String, Value>,
    hint: &'static str,
) -> Result<&'v [Value], CalibrationSetFault> {
    let list = json::array(json::require(top, "", "poses", hint)?, "poses", "a list")?;
    if list.is_empty() {
        return Err(CalibrationSetFault::NoPoses);
    }
    Ok(list)
}

/// The contract's JSON for a target.
fn target_to_value(t: &Target) -> Value {
    json!({"kind": t.kind.name(), "rows": t.rows, "cols": t.cols, "pitch_mm": t.pitch_mm,
           "dark_on_light": t.dark_on_light})
}

/// The set's version and target, common to both rigs' sets.
fn parse_target(
    top: &serde_json::Map<String, Value>,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<Target, CalibrationSetFault> {
    let version_value =
        json::require(top, "", "sheen_calibration_set", " (write \"sheen_calibration_set\": 1 at the top)")?;
    match json::integer(version_value, "sheen_calibration_set", "the version number 1") {
        Ok(CALIBRATION_SET_VERSION) => {}
        _ => return Err(CalibrationSetFault::UnsupportedVersion { found: json::describe(version_value) }),
    }
    let t =
        json::as_object(json::require(top, "", "target", " (the target's kind, rows, cols and pitch_mm)")?, "target")?;
    json::warn_unknown_keys(t, "target", &TARGET_KEYS, origin, warnings);
    let kind_text =
        json::string(json::require(t, "target", "kind", " (\"circles\" or \"checkerboard\")")?, "target.kind")?;
    let kind: TargetKind =
        kind_text.parse().map_err(|_| CalibrationSetFault::UnknownKind { found: kind_text.to_string() })?;
    let grid = |key: &'static str| -> Result<usize, CalibrationSetFault> {
        let v = json::require(t, "target", key, "")?;
        match json::integer(v, &child("target", key), "a whole number") {
            Ok(n) if (3..=1000).contains(&n) => Ok(n as usize),
            _ => Err(CalibrationSetFault::BadGrid { key, found: json::describe(v) }),
        }
    };
    let (rows, cols) = (grid("rows")?, grid("cols")?);
    let pitch_value = json::require(t, "target", "pitch_mm", " (the centre-to-centre spacing in mm)")?;
    let pitch_mm = match json::number(pitch_value, "target.pitch_mm") {
        Ok(p) if p > 0.0 => p,
        _ => return Err(CalibrationSetFault::BadPitch { found: json::describe(pitch_value) }),
    };
    let dark_on_light = match t.get("dark_on_light") {
        None => true,
        Some(v) => v.as_bool().ok_or_else(|| json::wrong("target.dark_on_light", "true or false", v))?,
    };
    Ok(Target { kind, rows, cols, pitch_mm, dark_on_light })
}

/// A camera–projector calibration set as read: each pose is a fringe set
/// (its manifest, relative to the set's file) recorded with the target in
/// view under the rig's Gray code and phase sets.
///
/// ```json
/// {"sheen_calibration_set": 1, "rig": "camera-projector",
///  "target": {"kind": "checkerboard", "rows": 9, "cols": 11, "pitch_mm": 1.5},
///  "poses": [{"fringe_set": "pose00/manifest.json"}, ...]}
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct RigCalibrationSet {
    pub target: Target,
    pub poses: Vec<String>,
    pub warnings: Vec<Warning>,
}

/// A calibration set of either rig.
#[derive(Clone, Debug, PartialEq)]
pub enum AnyCalibrationSet {
    Stereo(CalibrationSet),
    CameraProjector(RigCalibrationSet),
}

/// Reads a calibration set of either rig (its `rig` key; the telecentric
/// stereo pair without one) and checks that every file it lists exists.
pub fn read_any_calibration_set(path: &Path) -> Result<AnyCalibrationSet, IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    let fault = |fault| IoError::CalibrationSet { path: path.to_path_buf(), fault: Box::new(fault) };
    let value = json::parse(&bytes).map_err(|e| fault(e.into()))?;
    match value.get("rig").map(|r| r.as_str()) {
        None | Some(Some("telecentric-stereo")) => return read_calibration_set(path).map(AnyCalibrationSet::Stereo),
        Some(Some(CAMERA_PROJECTOR_RIG)) => {}
        Some(other) => {
            let found = other.map_or_else(|| json::describe(&value["rig"]), str::to_owned);
            return Err(fault(CalibrationSetFault::UnknownRig { found }));
        }
    }
    let set = parse_rig_set(&value, &path.display().to_string()).map_err(fault)?;
    let dir = folder_of(path);
    for (pose, manifest) in set.poses.iter().enumerate() {
        let file = dir.join(manifest);
        if !file.is_file() {
            return Err(fault(CalibrationSetFault::FringeSetMissing { pose, path: file }));
        }
    }
    Ok(AnyCalibrationSet::CameraProjector(set))
}

fn parse_rig_set(value: &Value, origin: &str) -> Result<RigCalibrationSet, CalibrationSetFault> {
    let mut warnings = Vec::new();
    let top = json::as_object(value, "")?;
    json::warn_unknown_keys(top, "", &RIG_TOP_KEYS, origin, &mut warnings);
    let target = parse_target(top, origin, &mut warnings)?;
    let list = pose_list(top, " (a list of {\"fringe_set\": ...})")?;
    let mut poses = Vec::with_capacity(list.len());
    for (k, pose) in list.iter().enumerate() {
        let key = format!("poses[{k}]");
        let map = json::as_object(pose, &key)?;
        json::warn_unknown_keys(map, &key, &["fringe_set"], origin, &mut warnings);
        let v = map.get("fringe_set").ok_or(CalibrationSetFault::MissingFringeSet { pose: k })?;
        let p = json::string(v, &child(&key, "fringe_set"))?;
        check_relative(p).map_err(|reason| CalibrationSetFault::BadFringeSetPath {
            pose: k,
            path: p.to_string(),
            reason,
        })?;
        poses.push(p.to_string());
    }
    Ok(RigCalibrationSet { target, poses, warnings })
}

/// Writes a camera–projector calibration set's file (the poses' fringe
/// sets are written beside it by their own writer).
pub fn write_rig_calibration_set(path: &Path, target: &Target, poses: &[String]) -> Result<(), IoError> {
    let value = json!({
        "sheen_calibration_set": CALIBRATION_SET_VERSION,
        "rig": CAMERA_PROJECTOR_RIG,
        "target": target_to_value(target),
        "poses": poses.iter().map(|p| json!({"fringe_set": p})).collect::<Vec<_>>(),
    });
    parse_rig_set(&value, &path.display().to_string())
        .map_err(|fault| IoError::CalibrationSet { path: path.to_path_buf(), fault: Box::new(fault) })?;
    write_json(path, &value)
}

/// Calibrates a camera–projector rig from a set read from `path`: each
/// pose's fringe set is loaded, decoded and its target found in turn (one
/// pose in memory at a time); a pose whose target is not found, or not in
/// the projector's light, is skipped with its reason.
pub fn calibrate_rig_from_set(
    path: &Path,
    set: &RigCalibrationSet,
    options: &RigCalibrationOptions,
    control: &RunControl,
) -> Result<(CameraProjectorCalibration, RigCalibrationReport), IoError> {
    let fault = |fault| IoError::CalibrationSet { path: path.to_path_buf(), fault: Box::new(fault) };
    let dir = folder_of(path);
    let mut observations = Vec::new();
    let mut skipped = Vec::new();
    let mut sizes: Option<[[usize; 2]; 2]> = None;
    for (pose, manifest) in set.poses.iter().enumerate() {
        control.begin_stage(&format!("pose {} of {}: decoding", pose + 1, set.poses.len()));
        let file = dir.join(manifest);
        let loaded = load_measurement(&file, control)?;
        let m = &loaded.measurement;
        let (Some(patterns), Some(camera)) = (m.projector.as_ref(), m.cameras.first()) else {
            return Err(fault(CalibrationSetFault::NotCameraProjector { pose, path: file }));
        };
        let found = [[camera.width, camera.height], [patterns.projector_width_px, patterns.projector_height_px]];
        match sizes {
            None => sizes = Some(found),
            Some(expected) if expected != found => {
                return Err(fault(CalibrationSetFault::RigSizes {
                    pose,
                    path: file,
                    found_w: found[0][0],
                    found_h: found[0][1],
                    found_pw: found[1][0],
                    found_ph: found[1][1],
                    expected_w: expected[0][0],
                    expected_h: expected[0][1],
                    expected_pw: expected[1][0],
                    expected_ph: expected[1][1],
                }));
            }
            Some(_) => {}
        }
        let name = Path::new(manifest)
            .parent()
            .and_then(|p| p.file_name())
            .map_or_else(|| format!("pose{pose:02}"), |n| n.to_string_lossy().into_owned());
        match observe_measurement(&name, m, &set.target, options, control) {
            Ok(obs) => observations.push(obs),
            Err(reason) => {
                control.check().map_err(|c| fault(CalibrationSetFault::RigCalibration(c.into())))?;
                skipped.push(format!("{name} ({}) skipped: {reason}", file.display()));
            }
        }
    }
    let sizes = sizes.ok_or_else(|| fault(CalibrationSetFault::NoPoses))?;
    solve_rig(&set.target, &observations, sizes, &skipped, options, control)
        .map_err(|e| fault(CalibrationSetFault::RigCalibration(e)))
}

/// Writes a camera–projector calibration report (JSON).
pub fn write_rig_calibration_report(path: &Path, report: &RigCalibrationReport) -> Result<(), IoError> {
    let value = serde_json::to_value(report)
        .map_err(|e| IoError::Write { path: path.to_path_buf(), source: std::io::Error::other(e) })?;
    write_json(path, &value)
}

/// The contract's JSON for a set.
pub fn calibration_set_to_value(set: &CalibrationSet) -> Value {
    json!({
        "sheen_calibration_set": CALIBRATION_SET_VERSION,
        "target": target_to_value(&set.target),
        "poses": set.poses.iter().map(|p| json!({"left": p.left, "right": p.right})).collect::<Vec<_>>(),
    })
}

/// Writes a set atomically; it must pass the checks of a read set (images
/// are not checked: they may be written after it).
pub fn write_calibration_set(path: &Path, set: &CalibrationSet) -> Result<(), IoError> {
    let value = calibration_set_to_value(set);
    parse_set(&value, &path.display().to_string())
        .map_err(|fault| IoError::CalibrationSet { path: path.to_path_buf(), fault: Box::new(fault) })?;
    write_json(path, &value)
}

fn write_json(path: &Path, value: &Value) -> Result<(), IoError> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
}

/// An image of the set as the detectors take it (grey levels as `f32`).
fn load_image(path: &Path) -> Result<GrayImage, IoError> {
    let img = read_gray_image(path)?;
    let pixels_dn = match img.pixels {
        GrayPixels::U8(v) => v.into_iter().map(f32::from).collect(),
        GrayPixels::U16(v) => v.into_iter().map(f32::from).collect(),
    };
    Ok(GrayImage { width: img.width, height: img.height, pixels_dn })
}

/// Detects the target in every pose of `set` (read from `path`), in
/// parallel, checking that each camera's images share one size.
pub fn detect_set(
    path: &Path,
    set: &CalibrationSet,
    options: &CalibrationOptions,
    control: &RunControl,
) -> Result<(Vec<PoseDetections>, Vec<SkippedPose>), IoError> {
    let dir = folder_of(path);
    control.begin_stage("target detection");
    let done = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<Result<PoseOutcome, IoError>> = set
        .poses
        .par_iter()
        .enumerate()
        .map(|(k, pose)| {
            control.check()?;
            let left = load_image(&dir.join(&pose.left))?;
            let right = load_image(&dir.join(&pose.right))?;
            let source = PoseSource {
                index: k,
                name: format!("pose {k}"),
                left_image: pose.left.clone(),
                right_image: pose.right.clone(),
            };
            let result = detect_pose(source, &left, &right, &set.target, &options.detection);
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            control.set_fraction(n as f32 / set.poses.len() as f32);
            Ok(result)
        })
        .collect();
    let mut found = Vec::new();
    let mut skipped = Vec::new();
    for result in results {
        match result? {
            PoseOutcome::Detected(p) => found.push(p),
            PoseOutcome::Skipped(s) => skipped.push(s),
        }
    }
    // Image sizes per camera: the first usable pose is the reference.
    if let Some(first) = found.first() {
        for pose in &found {
            for (c, camera) in CAMERA_NAMES.iter().enumerate() {
                let [w, h] = pose.image_size_px[c];
                let [ew, eh] = first.image_size_px[c];
                if [w, h] != [ew, eh] {
                    let name = |p: &PoseDetections| {
                        dir.join(if c == 0 { &p.source.left_image } else { &p.source.right_image })
                    };
                    return Err(IoError::CalibrationSet {
                        path: path.to_path_buf(),
                        fault: Box::new(CalibrationSetFault::ImageSize {
                            pose: pose.source.index,
                            camera,
                            image: name(pose),
                            width: w,
                            height: h,
                            reference: name(first),
                            expected_width: ew,
                            expected_height: eh,
                        }),
                    });
                }
            }
        }
    }
    Ok((found, skipped))
}

/// Calibrates the rig from the calibration set at `path`: reads it, detects
/// the target in every image, solves, and returns the calibration with its
/// report (the set's reading warnings included).
pub fn calibrate_from_set(
    path: &Path,
    options: &CalibrationOptions,
    control: &RunControl,
) -> Result<(StereoCalibration, CalibrationReport), IoError> {
    let set = read_calibration_set(path)?;
    let (found, skipped) = detect_set(path, &set, options, control)?;
    let fault = |fault| IoError::CalibrationSet { path: path.to_path_buf(), fault: Box::new(fault) };
    match solve(&set.target, &found, &skipped, options, control) {
        Ok((calibration, mut report)) => {
            report.warnings = set_warnings(&set.warnings).chain(report.warnings).collect();
            Ok((calibration, report))
        }
        Err(CalibrateError::Cancelled(c)) => Err(IoError::Cancelled(c)),
        Err(e @ CalibrateError::TooFewPoses { .. }) => {
            Err(fault(grid_mismatch(&set.target, &skipped).unwrap_or(CalibrationSetFault::Calibration(e))))
        }
        Err(e) => Err(fault(CalibrationSetFault::Calibration(e))),
    }
}

/// When most images show a complete grid of another size than declared, the
/// declaration is wrong: say so rather than list every skipped pose.
fn grid_mismatch(target: &Target, skipped: &[SkippedPose]) -> Option<CalibrationSetFault> {
    let mut sizes = Vec::new();
    let mut images = Vec::new();
    for s in skipped {
        for (camera, error) in &s.errors {
            if let DetectionError::Grid(GridError::WrongSize { found_rows, found_cols, .. }) = error {
                sizes.push((*found_rows, *found_cols));
                images.push(if *camera == 0 { s.source.left_image.clone() } else { s.source.right_image.clone() });
            }
        }
    }
    let &(found_rows, found_cols) = sizes.first()?;
    // Half the images or more agree on one size.
    let agreeing = sizes.iter().filter(|&&s| s == (found_rows, found_cols)).count();
    let total: usize = skipped.iter().map(|s| s.errors.len()).sum();
    (2 * agreeing >= total).then(|| CalibrationSetFault::GridMismatch {
        rows: target.rows,
        cols: target.cols,
        found_rows,
        found_cols,
        noun: target.kind.point_noun(),
        images,
    })
}

/// Writes the calibration report JSON (atomically).
pub fn write_calibration_report(path: &Path, report: &CalibrationReport) -> Result<(), IoError> {
    let value = serde_json::to_value(report)
        .map_err(|e| IoError::Write { path: path.to_path_buf(), source: std::io::Error::other(e) })?;
    write_json(path, &value)
}

/// A simulated calibration set and its truth, as the simulator hands it over
/// (io never depends on the simulator; the front end passes its parts).
pub struct SimulatedCalibrationSet<'a> {
    pub target: Target,
    /// Left and right image of each pose; grey levels already quantised.
    pub images: &'a [[GrayImage; 2]],
    /// Largest grey level: 255 writes 8-bit PNG, more writes 16-bit PNG.
    pub full_scale_dn: u16,
    /// The true cameras in the simulator's world.
    pub calibration_world: &'a StereoCalibration,
    /// The true cameras in the pose-0 target frame (what calibration should find).
    pub calibration_pose0: &'a StereoCalibration,
    /// Each pose's target frame in the simulator's world.
    pub poses_world: &'a [Pose],
    /// True observed pixel of every target point, per pose and camera.
    pub points_px: &'a [[Vec<[f64; 2]>; 2]],
    /// The simulator's settings, kept verbatim in the truth file.
    pub settings: Value,
}

/// File names of a written simulated set.
#[derive(Clone, Debug, PartialEq)]
pub struct WrittenSet {
    pub set: PathBuf,
    /// `truth/calibration.json`: the true calibration in the pose-0 frame.
    pub truth_calibration: PathBuf,
    /// `truth/target_truth.json`: poses, the pose-0 frame in the world, true points.
    pub truth: PathBuf,
}

/// Writes a simulated set into `dir`: `calibration_set.json`, the images
/// `left/poseNN.png` and `right/poseNN.png`, and the truth under `truth/`.
pub fn write_simulated_calibration_set(dir: &Path, sim: &SimulatedCalibrationSet<'_>) -> Result<WrittenSet, IoError> {
    let mut poses = Vec::with_capacity(sim.images.len());
    for (k, pair) in sim.images.iter().enumerate() {
        let mut names = Vec::with_capacity(2);
        for (c, camera) in CAMERA_NAMES.iter().enumerate() {
            let relative = format!("{camera}/pose{k:02}.png");
            let file = dir.join(&relative);
            create_parent(&file)?;
            write_png(&file, &pair[c], sim.full_scale_dn)?;
            names.push(relative);
        }
        poses.push(SetPose { left: names[0].clone(), right: names[1].clone() });
    }
    let set_path = dir.join("calibration_set.json");
    write_calibration_set(&set_path, &CalibrationSet { target: sim.target, poses, warnings: Vec::new() })?;
    let truth_calibration = dir.join("truth").join("calibration.json");
    create_parent(&truth_calibration)?;
    write_json(&truth_calibration, &calibration_to_value(sim.calibration_pose0))?;
    let pose_value = |p: &Pose| json!({"rotation": p.rotation, "translation_mm": p.translation_mm});
    let truth_value = json!({
        "description": "X_world = R X_target + t for each pose; calibration.json is the rig in the pose-0 target frame \
                        (X_world = pose0_in_world(X_pose0)); calibration_world the same rig in the simulator's world",
        "pose0_in_world": sim.poses_world.first().map(pose_value),
        "poses_in_world": sim.poses_world.iter().map(pose_value).collect::<Vec<_>>(),
        "calibration_world": calibration_to_value(sim.calibration_world),
        "points_px": sim.points_px.iter().map(|[l, r]| json!({"left": l, "right": r})).collect::<Vec<_>>(),
        "settings": sim.settings,
    });
    let truth = dir.join("truth").join("target_truth.json");
    write_json(&truth, &truth_value)?;
    Ok(WrittenSet { set: set_path, truth_calibration, truth })
}

fn create_parent(file: &Path) -> Result<(), IoError> {
    match file.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => {
            std::fs::create_dir_all(parent).map_err(|source| IoError::Write { path: parent.to_path_buf(), source })
        }
        _ => Ok(()),
    }
}

/// Writes a grayscale PNG: 8-bit for `full_scale_dn` 255, else 16-bit.
fn write_png(path: &Path, img: &GrayImage, full_scale_dn: u16) -> Result<(), IoError> {
    use image::ImageEncoder;
    let (w, h) = (img.width as u32, img.height as u32);
    let clamp = |v: f32| v.round().clamp(0.0, f32::from(full_scale_dn));
    write_atomic(path, |out| {
        let encoder = image::codecs::png::PngEncoder::new(out);
        if full_scale_dn <= 255 {
            let bytes: Vec<u8> = img.pixels_dn.iter().map(|&v| clamp(v) as u8).collect();
            encoder.write_image(&bytes, w, h, image::ExtendedColorType::L8)
        } else {
            let samples: Vec<u16> = img.pixels_dn.iter().map(|&v| clamp(v) as u16).collect();
            encoder.write_image(bytemuck::cast_slice(&samples), w, h, image::ExtendedColorType::L16)
        }
        .map_err(std::io::Error::other)
    })
}

/// The set file's reading warnings (unknown keys) as the report's first.
pub fn set_warnings(warnings: &[Warning]) -> impl Iterator<Item = Warning> + '_ {
    warnings.iter().cloned()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(v: Value) -> Result<CalibrationSet, CalibrationSetFault> {
        parse_set(&v, "set.json")
    }

    fn valid() -> Value {
        json!({"sheen_calibration_set": 1,
               "target": {"kind": "circles", "rows": 9, "cols": 11, "pitch_mm": 0.5, "dark_on_light": true},
               "poses": [{"left": "left/pose00.png", "right": "right/pose00.png"}]})
    }

    #[test]
    fn a_valid_set_round_trips() {
        let set = parse(valid()).expect("valid");
        assert_eq!(
            set.target,
            Target { kind: TargetKind::Circles, rows: 9, cols: 11, pitch_mm: 0.5, dark_on_light: true }
        );
        assert_eq!(set.poses, vec![SetPose { left: "left/pose00.png".into(), right: "right/pose00.png".into() }]);
        assert_eq!(calibration_set_to_value(&set), valid());
    }

    #[test]
    fn faults_name_what_is_wrong() {
        let mut v = valid();
        v["target"]["kind"] = json!("dots");
        assert_eq!(parse(v).unwrap_err(), CalibrationSetFault::UnknownKind { found: "dots".into() });
        let mut v = valid();
        v["target"]["rows"] = json!(2);
        assert!(matches!(parse(v), Err(CalibrationSetFault::BadGrid { key: "rows", .. })));
        let mut v = valid();
        v["target"]["pitch_mm"] = json!(0);
        assert!(matches!(parse(v), Err(CalibrationSetFault::BadPitch { .. })));
        let mut v = valid();
        v["poses"][0] = json!({"left": "left/a.png"});
        let e = parse(v).unwrap_err();
        assert!(e.to_string().contains("pose 0 lacks the right image"), "{e}");
        let mut v = valid();
        v["poses"][0]["left"] = json!("../elsewhere/a.png");
        assert!(matches!(parse(v), Err(CalibrationSetFault::BadImagePath { camera: "left", .. })));
        let mut v = valid();
        v["sheen_calibration_set"] = json!(2);
        assert!(matches!(parse(v), Err(CalibrationSetFault::UnsupportedVersion { .. })));
        let mut v = valid();
        v["poses"] = json!([]);
        assert_eq!(parse(v).unwrap_err(), CalibrationSetFault::NoPoses);
        let mut v = valid();
        v["target"]["colour"] = json!("white");
        let w = &parse(v).expect("valid").warnings[0];
        assert!(w.kind == crate::engine::warning::WarningKind::IgnoredInput && w.message.contains("target.colour"));
    }
}
