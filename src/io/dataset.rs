//! Writing a whole in-memory measurement as a fringe set on disk: one PNG per
//! image under a folder per camera, the calibration file and the manifest
//! (the contract of `io::manifest`); a camera–projector rig's sets along y,
//! Gray code, white and black frames and pinhole calibration too. The simulator's output and test
//! fixtures go through here, so what Sheen writes is what Sheen reads.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::error::IoError;
use super::images::{GrayPixels, write_gray_png, write_gray_tiff};
use std::collections::BTreeMap;

use super::manifest::{CalibrationSource, Manifest, ManifestGrayCode, ManifestSet, ProjectorSize, write_manifest};
use crate::engine::camera_projector::ProjectorAxis;
use crate::engine::fringe::{FringeSetInfo, FringeStack, Measurement, Samples, uniform_shifts_rad};

/// File name of the manifest [`write_measurement`] writes.
pub const MANIFEST_FILE: &str = "fringe-set.json";
/// File name of the calibration it writes beside the manifest.
pub const CALIBRATION_FILE: &str = "calibration.json";

/// How [`write_measurement_as`] stores the images.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ImageFileFormat {
    /// Lossless, compressed (fast setting): small fringe sets.
    #[default]
    Png,
    /// Uncompressed TIFF, as many cameras' own software saves.
    Tiff,
}

impl ImageFileFormat {
    pub fn extension(self) -> &'static str {
        match self {
            ImageFileFormat::Png => "png",
            ImageFileFormat::Tiff => "tif",
        }
    }
}

/// `p0912_03.png`: the period (zero-padded to 4 digits when integral) and the shift.
pub fn image_file_name(period_px: f64, shift: usize) -> String {
    image_file_name_as(period_px, shift, ImageFileFormat::Png)
}

fn image_file_name_as(period_px: f64, shift: usize, format: ImageFileFormat) -> String {
    let ext = format.extension();
    if period_px.fract() == 0.0 && (0.0..1e9).contains(&period_px) {
        format!("p{:04}_{shift:02}.{ext}", period_px as u64)
    } else {
        format!("p{}_{shift:02}.{ext}", super::maps::period_label(period_px))
    }
}

/// Writes `m` into `dir` (created if needed) with PNG images and returns the
/// manifest path.
pub fn write_measurement(dir: &Path, m: &Measurement) -> Result<PathBuf, IoError> {
    write_measurement_as(dir, m, ImageFileFormat::Png)
}

/// Writes `m` into `dir` (created if needed) with images in `format` and
/// returns the manifest path. Images are encoded in parallel; every file is
/// written atomically.
pub fn write_measurement_as<'m>(dir: &Path, m: &'m Measurement, format: ImageFileFormat) -> Result<PathBuf, IoError> {
    let mkdir =
        |d: &Path| std::fs::create_dir_all(d).map_err(|source| IoError::Write { path: d.to_path_buf(), source });
    mkdir(dir)?;
    let mut jobs: Vec<(PathBuf, &'m FringeStack, usize)> = Vec::new();
    let mut sets: Vec<ManifestSet> = m.sets.iter().map(|set| manifest_set(set, ProjectorAxis::X)).collect();
    for cam in &m.cameras {
        mkdir(&dir.join(&cam.name))?;
        for (s, (set, stack)) in m.sets.iter().zip(&cam.stacks).enumerate() {
            let files = stack_files(&cam.name, "", stack, |k| image_file_name_as(set.period_px, k, format));
            jobs.extend(files.iter().enumerate().map(|(k, file)| (dir.join(file), stack, k)));
            sets[s].images.insert(cam.name.clone(), files);
        }
    }
    // A camera–projector rig's sets along y and its Gray code, with the
    // prefixes `y_` and `gray_` beside the sets along x.
    let mut projector = None;
    let mut gray_code = None;
    if let Some(patterns) = &m.projector {
        projector =
            Some(ProjectorSize { width_px: patterns.projector_width_px, height_px: patterns.projector_height_px });
        let first_y = sets.len();
        sets.extend(patterns.y_sets.iter().map(|set| manifest_set(set, ProjectorAxis::Y)));
        let mut code = patterns.gray_code.map(|layout| ManifestGrayCode {
            cell_px: layout.cell_px,
            columns: BTreeMap::new(),
            rows: layout.rows.then(BTreeMap::new),
            white: BTreeMap::new(),
            black: BTreeMap::new(),
        });
        let ext = format.extension();
        for (cam, frames) in m.cameras.iter().zip(&patterns.cameras) {
            for (s, (set, stack)) in patterns.y_sets.iter().zip(&frames.y_stacks).enumerate() {
                let files = stack_files(&cam.name, "y_", stack, |k| image_file_name_as(set.period_px, k, format));
                jobs.extend(files.iter().enumerate().map(|(k, file)| (dir.join(file), stack, k)));
                sets[first_y + s].images.insert(cam.name.clone(), files);
            }
            let Some(code) = code.as_mut() else { continue };
            let mut frames_of = |stack: &'m FringeStack, name: &str| {
                let files = stack_files(&cam.name, "gray_", stack, |k| format!("{name}_{k:02}.{ext}"));
                jobs.extend(files.iter().enumerate().map(|(k, file)| (dir.join(file), stack, k)));
                files
            };
            if let Some(stack) = &frames.gray_columns {
                code.columns.insert(cam.name.clone(), frames_of(stack, "columns"));
            }
            if let (Some(stack), Some(rows)) = (&frames.gray_rows, code.rows.as_mut()) {
                rows.insert(cam.name.clone(), frames_of(stack, "rows"));
            }
            if let Some(stack) = &frames.white_black {
                let files = frames_of(stack, "white_black");
                if let [white, black] = &files[..] {
                    code.white.insert(cam.name.clone(), white.clone());
                    code.black.insert(cam.name.clone(), black.clone());
                }
            }
        }
        gray_code = code;
    }
    jobs.par_iter().try_for_each(|(path, stack, k)| {
        let plane = stack.pixel_count();
        let range = k * plane..(k + 1) * plane;
        let pixels = match &stack.samples {
            Samples::U8(v) => GrayPixels::U8(v[range].to_vec()),
            Samples::U16(v) => GrayPixels::U16(v[range].to_vec()),
        };
        match format {
            ImageFileFormat::Png => write_gray_png(path, stack.width, stack.height, &pixels),
            ImageFileFormat::Tiff => write_gray_tiff(path, stack.width, stack.height, &pixels),
        }
    })?;
    let pinhole = m.projector.as_ref().and_then(|p| p.calibration.as_ref());
    let calibration = match (&m.calibration, pinhole) {
        (Some(c), _) => {
            super::calibration::write_calibration(&dir.join(CALIBRATION_FILE), c)?;
            Some(CalibrationSource::File(CALIBRATION_FILE.into()))
        }
        (None, Some(c)) => {
            super::pinhole_calibration::write_camera_projector_calibration(&dir.join(CALIBRATION_FILE), c)?;
            Some(CalibrationSource::File(CALIBRATION_FILE.into()))
        }
        (None, None) => None,
    };
    let default_level = if m.bit_depth >= 16 { u16::MAX } else { (1u16 << m.bit_depth) - 1 };
    let manifest = Manifest {
        bit_depth: m.bit_depth,
        saturation_level: (m.saturation_level != default_level).then_some(m.saturation_level),
        calibration,
        projector,
        sets,
        gray_code,
        warnings: Vec::new(),
    };
    let path = dir.join(MANIFEST_FILE);
    write_manifest(&path, &manifest)?;
    Ok(path)
}

fn manifest_set(set: &FringeSetInfo, axis: ProjectorAxis) -> ManifestSet {
    ManifestSet {
        period_px: set.period_px,
        shifts: set.shifts(),
        phase_shifts_rad: (set.phase_shifts_rad != uniform_shifts_rad(set.shifts()))
            .then(|| set.phase_shifts_rad.clone()),
        axis,
        images: Default::default(),
    }
}

/// The files of a stack's planes under the camera's folder: `{camera}/{prefix}{name(k)}`.
fn stack_files(camera: &str, prefix: &str, stack: &FringeStack, name: impl Fn(usize) -> String) -> Vec<String> {
    (0..stack.shifts).map(|k| format!("{camera}/{prefix}{}", name(k))).collect()
}
