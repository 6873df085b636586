//! The calibration view's work off the UI thread, with no GUI types: reading
//! a calibration set and detecting the target in every pose, solving with a
//! chosen set of poses and distortion model, saving the calibration, and
//! giving the open fringe set a new calibration.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use crate::app::jobs::JobError;
use crate::engine::calibration::model::DistortionModel;
use crate::engine::calibration::report::CalibrationReport;
use crate::engine::calibration::{CalibrationOptions, PoseDetections, SkippedPose, solve};
use crate::engine::camera_model::StereoCalibration;
use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::io;
use crate::io::calibration_set::{CalibrationSet, detect_set, read_calibration_set};
use crate::io::images::{GrayPixels, read_gray_image};

/// An image scaled to 8 bits for display (the detector works on the file's own levels).
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayImage {
    pub width: usize,
    pub height: usize,
    pub gray: Vec<u8>,
}

/// A calibration set with the target detected in every pose.
#[derive(Debug)]
pub struct DetectedSet {
    pub path: PathBuf,
    pub set: CalibrationSet,
    /// Poses with the complete target in both cameras, in set order.
    pub detected: Vec<PoseDetections>,
    pub skipped: Vec<SkippedPose>,
    /// Left and right image of every pose of the set (skipped ones too).
    pub images: Vec<[DisplayImage; 2]>,
}

impl DetectedSet {
    /// The detections of set pose `index`, if it is usable.
    pub fn detection(&self, index: usize) -> Option<&PoseDetections> {
        self.detected.iter().find(|p| p.source.index == index)
    }

    pub fn skipped(&self, index: usize) -> Option<&SkippedPose> {
        self.skipped.iter().find(|p| p.source.index == index)
    }

    /// Every file the set reads (the set and its images): never written over.
    pub fn inputs(&self) -> Vec<PathBuf> {
        let dir = self.path.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut inputs = vec![self.path.clone()];
        for pose in &self.set.poses {
            inputs.push(dir.join(&pose.left));
            inputs.push(dir.join(&pose.right));
        }
        inputs
    }
}

fn failed(control: &RunControl, e: impl Into<anyhow::Error>) -> JobError {
    if control.is_cancelled() { JobError::Cancelled } else { JobError::Failed(e.into()) }
}

/// Reads the set at `path`, detects the target in every pose (in parallel)
/// and decodes the images for display.
pub fn detect(path: &Path, control: &RunControl) -> Result<DetectedSet, JobError> {
    control.begin_stage("reading the calibration set");
    let set = read_calibration_set(path).map_err(|e| failed(control, e))?;
    let options = CalibrationOptions::default();
    let (detected, skipped) = detect_set(path, &set, &options, control).map_err(|e| failed(control, e))?;
    control.begin_stage("preparing the images");
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let images = set
        .poses
        .par_iter()
        .map(|pose| -> Result<[DisplayImage; 2], JobError> {
            control.check()?;
            let left = display_image(&dir.join(&pose.left)).map_err(|e| failed(control, e))?;
            let right = display_image(&dir.join(&pose.right)).map_err(|e| failed(control, e))?;
            Ok([left, right])
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(DetectedSet { path: path.to_path_buf(), set, detected, skipped, images })
}

/// The image at `path` stretched from 0 to its brightest sample into 8 bits.
fn display_image(path: &Path) -> Result<DisplayImage, io::error::IoError> {
    let img = read_gray_image(path)?;
    let gray = match img.pixels {
        GrayPixels::U8(v) => v,
        GrayPixels::U16(v) => {
            let max = f32::from(v.iter().copied().max().unwrap_or(1).max(1));
            v.iter().map(|&s| (f32::from(s) * 255.0 / max).round() as u8).collect()
        }
    };
    Ok(DisplayImage { width: img.width, height: img.height, gray })
}

/// A solved calibration and what it was solved from.
#[derive(Clone, Debug)]
pub struct Solved {
    pub calibration: StereoCalibration,
    pub report: CalibrationReport,
    pub distortion: DistortionModel,
    /// Set poses the operator left out.
    pub excluded: BTreeSet<usize>,
}

/// Solves with the usable poses the operator kept; the first kept pose is the world frame.
pub fn solve_set(
    set: &Arc<DetectedSet>,
    excluded: &BTreeSet<usize>,
    distortion: DistortionModel,
    control: &RunControl,
) -> Result<Solved, JobError> {
    let kept: Vec<PoseDetections> =
        set.detected.iter().filter(|p| !excluded.contains(&p.source.index)).cloned().collect();
    let options = CalibrationOptions { distortion, ..CalibrationOptions::default() };
    let (calibration, mut report) =
        solve(&set.set.target, &kept, &set.skipped, &options, control).map_err(|e| failed(control, e))?;
    report.warnings = crate::io::calibration_set::set_warnings(&set.set.warnings).chain(report.warnings).collect();
    Ok(Solved { calibration, report, distortion, excluded: excluded.clone() })
}

/// Writes `calibration` to `path` atomically, refusing to write over the set's files.
pub fn save(path: &Path, calibration: &StereoCalibration, inputs: &[PathBuf]) -> Result<PathBuf, JobError> {
    if path.as_os_str().is_empty() {
        return Err(JobError::Failed(anyhow::anyhow!("no file name given for the calibration")));
    }
    io::atomic::refuse_overwriting_inputs(path, inputs).map_err(|e| JobError::Failed(e.into()))?;
    io::calibration::write_calibration(path, calibration).map_err(|e| JobError::Failed(e.into()))?;
    Ok(path.to_path_buf())
}

/// The open measurement with `calibration` in place of its own. The id is
/// kept: phases do not depend on the calibration, so the next run reuses
/// them and only redoes the stereo stage. Copying the samples of a large
/// measurement takes a while, so this runs on a job too.
pub fn with_calibration(
    measurement: &Measurement,
    calibration: StereoCalibration,
    control: &RunControl,
) -> Result<Measurement, JobError> {
    control.begin_stage("applying the calibration");
    if measurement.cameras.len() < 2 {
        return Err(JobError::Failed(anyhow::anyhow!(
            "{} has {} camera(s); a stereo calibration needs the left and right camera",
            measurement.label,
            measurement.cameras.len()
        )));
    }
    for (cam, model) in measurement.cameras.iter().zip([&calibration.left, &calibration.right]) {
        if cam.width != model.width || cam.height != model.height {
            return Err(JobError::Failed(anyhow::anyhow!(
                "the calibration is for {}x{} px images but camera '{}' of {} has {}x{} px images",
                model.width,
                model.height,
                cam.name,
                measurement.label,
                cam.width,
                cam.height
            )));
        }
    }
    let mut m = measurement.clone();
    control.check()?;
    m.calibration = Some(calibration);
    Ok(m)
}

/// A magnification that draws a residual of the solution's RMS a quarter
/// of the target's point spacing long, rounded to 1, 2 or 5 times a power of ten.
pub fn residual_magnification(set: &DetectedSet, report: &CalibrationReport) -> f32 {
    let spacing_px = set
        .detected
        .first()
        .and_then(|p| match p.left.points_px.as_slice() {
            [a, b, ..] => Some((b[0] - a[0]).hypot(b[1] - a[1])),
            _ => None,
        })
        .unwrap_or(20.0);
    let rms = report.rms_reprojection_px.max(1e-4);
    let raw = 0.25 * spacing_px / rms;
    let decade = 10f64.powf(raw.log10().floor());
    let nice = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * decade).rfind(|&v| v <= raw * 1.0001).unwrap_or(decade);
    nice.clamp(1.0, 20000.0) as f32
}

/// Which grid points to number when drawn `spacing_px` apart on screen: all
/// when there is room, else the first row and column and every few.
pub fn numbered(row: usize, col: usize, spacing_px: f32) -> bool {
    if spacing_px >= 22.0 {
        return true;
    }
    let every = (22.0 / spacing_px.max(1.0)).ceil() as usize;
    row.is_multiple_of(every) && col.is_multiple_of(every)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_projector_set_is_named_with_the_command_that_solves_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("rig-set.json");
        let set = r#"{"sheen_calibration_set": 1, "rig": "camera-projector",
            "target": {"kind": "circles", "rows": 9, "cols": 11, "pitch_mm": 1.5},
            "poses": [{"fringe_set": "pose00/fringe-set.json"}]}"#;
        std::fs::write(&path, set).expect("write");
        let Err(JobError::Failed(e)) = detect(&path, &RunControl::new()) else {
            panic!("a camera–projector set opened")
        };
        let text = format!("{e:#}");
        assert!(text.contains("rig-set.json") && text.contains("camera–projector calibration set"), "{text}");
        assert!(text.contains("sheen calibrate SET --out calibration.json"), "{text}");
    }

    #[test]
    fn sparse_numbering_keeps_the_corner_and_thins_out() {
        assert!(numbered(3, 5, 30.0));
        assert!(numbered(0, 0, 5.0));
        assert!(!numbered(1, 1, 8.0));
        assert!(numbered(3, 6, 8.0));
    }
}
