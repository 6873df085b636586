//! A camera–projector rig's measurement (issue 52): the patterns it projects
//! besides the phase sets along projector x that the paper's stages share
//! (phase sets along y, the Gray code of each axis, white and black), and
//! the absolute projector coordinate maps they give each camera.
//!
//! The sets along x stay the measurement's sets, so the wrapped phases,
//! saturation maps and everything the app shows of them work as for the
//! telecentric pair; the sets along y and the code frames live here, held
//! in the camera's own sample type like every fringe stack.

use super::control::{Cancelled, RunControl};
use super::fringe::{FringeSetInfo, FringeStack, Measurement, Samples};
use super::gray_code::{GrayCodeError, GrayDecode, GrayDecodeParams, decode_axis};
use super::phase_shift::{PhaseParams, WrappedPhase, wrapped_phase};
use super::projector_coordinate::{
    AbsoluteParams, ProjectorCoordinate, ProjectorCoordinateError, SetPhase, absolute_coordinate,
};
use super::warning::Warning;

/// The projector axis along which a set's phase grows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ProjectorAxis {
    /// Fringes along projector columns: the phase grows with the column.
    #[default]
    X,
    /// Fringes along projector rows: the phase grows with the row.
    Y,
}

impl ProjectorAxis {
    pub fn name(self) -> &'static str {
        match self {
            ProjectorAxis::X => "x",
            ProjectorAxis::Y => "y",
        }
    }
}

/// The Gray code's geometry: OpenCV's `GrayCodePattern` layout over cells
/// of `cell_px` projector pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GrayCodeLayout {
    pub cell_px: u32,
    /// Whether a code along rows (projector y) was projected too.
    pub rows: bool,
}

impl GrayCodeLayout {
    /// Code units along an axis of `extent_px` projector pixels.
    pub fn cells(&self, extent_px: usize) -> usize {
        extent_px.div_ceil(self.cell_px.max(1) as usize)
    }

    /// Frames of that axis's code: a pattern and its inverse per bit plane.
    pub fn frames(&self, extent_px: usize) -> usize {
        2 * super::gray_code::bit_planes(self.cells(extent_px))
    }
}

/// One camera's frames of the projector patterns (per camera, in the
/// measurement's camera order).
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPatterns {
    /// The sets along projector y, indexed like [`ProjectorPatterns::y_sets`].
    pub y_stacks: Vec<FringeStack>,
    /// Column code frames in OpenCV order (`shifts` counts the frames).
    pub gray_columns: Option<FringeStack>,
    /// Row code frames, where given.
    pub gray_rows: Option<FringeStack>,
    /// The white frame then the black one, with a code.
    pub white_black: Option<FringeStack>,
}

/// What a camera–projector rig projects besides the sets along x.
#[derive(Clone, Debug, PartialEq)]
pub struct ProjectorPatterns {
    pub projector_width_px: usize,
    pub projector_height_px: usize,
    /// Phase sets along projector y, sparsest first.
    pub y_sets: Vec<FringeSetInfo>,
    pub gray_code: Option<GrayCodeLayout>,
    pub cameras: Vec<CameraPatterns>,
    /// The rig's pinhole calibration, where given: what makes 3D.
    pub calibration: Option<super::pinhole::CameraProjectorCalibration>,
}

/// The absolute projector coordinates one camera sees.
#[derive(Clone, Debug)]
pub struct ProjectorMaps {
    pub camera: String,
    pub x: Option<ProjectorCoordinate>,
    pub y: Option<ProjectorCoordinate>,
    /// The decoded code of each axis (for the views and the inspector).
    pub code_x: Option<GrayDecode>,
    pub code_y: Option<GrayDecode>,
    /// The ripple of sets that disagree beyond their noise.
    pub warnings: Vec<Warning>,
}

/// Why a camera's projector coordinates could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ProjectorMapsError {
    #[error("the manifest describes no camera–projector rig (no 'projector')")]
    NotCameraProjector,
    #[error("the manifest has no Gray code: the phase alone does not give an absolute projector coordinate")]
    NoGrayCode,
    #[error("camera '{camera}', projector {axis}: {source}")]
    Code {
        camera: String,
        axis: &'static str,
        #[source]
        source: GrayCodeError,
    },
    #[error("camera '{camera}', projector {axis}: {source}")]
    Coordinate {
        camera: String,
        axis: &'static str,
        #[source]
        source: ProjectorCoordinateError,
    },
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// A stack's planes, each `width * height` samples.
fn planes<T>(samples: &[T], pixels: usize) -> Vec<&[T]> {
    samples.chunks_exact(pixels.max(1)).collect()
}

/// Decodes a code stack with its white/black stack, in their sample type
/// (the loader reads one camera's frames all at the manifest's bit depth;
/// frames of two types are read as grey levels).
fn decode(
    frames: &FringeStack,
    white_black: &FringeStack,
    cells: usize,
    params: &GrayDecodeParams,
) -> Result<GrayDecode, GrayCodeError> {
    let (w, h, n) = (frames.width, frames.height, frames.pixel_count());
    match (&frames.samples, &white_black.samples) {
        (Samples::U8(f), Samples::U8(wb)) => {
            let wb = planes(wb, n);
            decode_axis(&planes(f, n), wb[0], wb[1], w, h, cells, params)
        }
        (Samples::U16(f), Samples::U16(wb)) => {
            let wb = planes(wb, n);
            decode_axis(&planes(f, n), wb[0], wb[1], w, h, cells, params)
        }
        (f, wb) => {
            let grey = |s: &Samples| -> Vec<f32> { (0..s.len()).map(|i| f32::from(s.get(i))).collect() };
            let (f, wb) = (grey(f), grey(wb));
            let wb = planes(&wb, n);
            decode_axis(&planes(&f, n), wb[0], wb[1], w, h, cells, params)
        }
    }
}

/// The absolute projector coordinate of one axis from its code and sets:
/// the two densest sets where more are given (their beat orders each).
fn axis_coordinate(
    code: &GrayDecode,
    cell_px: f64,
    phases: &[WrappedPhase],
    params: &AbsoluteParams,
) -> Result<ProjectorCoordinate, ProjectorCoordinateError> {
    let first = phases.len().saturating_sub(2);
    let sets: Vec<SetPhase<'_>> = phases[first..].iter().map(SetPhase::of).collect();
    absolute_coordinate(code, cell_px, &sets, params)
}

/// Each camera's decoded Gray code: columns, and rows where projected
/// (what `sheen check` reports, and the first step of [`projector_maps`]).
pub fn decode_gray_codes(m: &Measurement) -> Result<Vec<(GrayDecode, Option<GrayDecode>)>, ProjectorMapsError> {
    let patterns = m.projector.as_ref().ok_or(ProjectorMapsError::NotCameraProjector)?;
    let layout = patterns.gray_code.ok_or(ProjectorMapsError::NoGrayCode)?;
    let params = GrayDecodeParams::default();
    m.cameras
        .iter()
        .zip(&patterns.cameras)
        .map(|(camera, frames)| {
            let (Some(columns), Some(white_black)) = (&frames.gray_columns, &frames.white_black) else {
                return Err(ProjectorMapsError::NoGrayCode);
            };
            let code_err = |axis: &'static str| {
                move |source| ProjectorMapsError::Code { camera: camera.name.clone(), axis, source }
            };
            let x = decode(columns, white_black, layout.cells(patterns.projector_width_px), &params)
                .map_err(code_err("x"))?;
            let y = match &frames.gray_rows {
                Some(rows) => Some(
                    decode(rows, white_black, layout.cells(patterns.projector_height_px), &params)
                        .map_err(code_err("y"))?,
                ),
                None => None,
            };
            Ok((x, y))
        })
        .collect()
}

/// Each camera's absolute projector x (and y, where a row code and sets
/// along y are given) from the Gray code and the phase sets.
pub fn projector_maps(
    m: &Measurement,
    phase: &PhaseParams,
    control: &RunControl,
) -> Result<Vec<ProjectorMaps>, ProjectorMapsError> {
    let patterns = m.projector.as_ref().ok_or(ProjectorMapsError::NotCameraProjector)?;
    let layout = patterns.gray_code.ok_or(ProjectorMapsError::NoGrayCode)?;
    let absolute = AbsoluteParams::default();
    let mut out = Vec::with_capacity(m.cameras.len());
    control.begin_stage("Gray code");
    let codes = decode_gray_codes(m)?;
    for ((camera, frames), (code_x, code_y)) in m.cameras.iter().zip(&patterns.cameras).zip(codes) {
        let name = &camera.name;
        control.begin_stage(&format!("{name}: projector x"));
        let coord_err =
            |axis: &'static str| move |source| ProjectorMapsError::Coordinate { camera: name.clone(), axis, source };
        let x_phases = m
            .sets
            .iter()
            .zip(&camera.stacks)
            .map(|(set, stack)| wrapped_phase(stack, set, phase, false, control))
            .collect::<Result<Vec<_>, _>>()?;
        let x = axis_coordinate(&code_x, f64::from(layout.cell_px), &x_phases, &absolute).map_err(coord_err("x"))?;
        let mut warnings: Vec<Warning> = x.ripple_warnings("x");
        let mut y = None;
        if let Some(code) = &code_y
            && !patterns.y_sets.is_empty()
        {
            control.begin_stage(&format!("{name}: projector y"));
            let y_phases = patterns
                .y_sets
                .iter()
                .zip(&frames.y_stacks)
                .map(|(set, stack)| wrapped_phase(stack, set, phase, false, control))
                .collect::<Result<Vec<_>, _>>()?;
            let coordinate =
                axis_coordinate(code, f64::from(layout.cell_px), &y_phases, &absolute).map_err(coord_err("y"))?;
            warnings.extend(coordinate.ripple_warnings("y"));
            y = Some(coordinate);
        }
        out.push(ProjectorMaps { camera: name.clone(), x: Some(x), y, code_x: Some(code_x), code_y, warnings });
    }
    Ok(out)
}

/// The 3D cloud of a calibrated camera–projector rig's first camera from its
/// projector coordinates ([`super::pinhole::reconstruct`]), textured with the
/// white frame; `None` without a calibration or a projector x.
pub fn rig_point_cloud(m: &Measurement, maps: &[ProjectorMaps]) -> Option<super::point_cloud::PointCloud> {
    let patterns = m.projector.as_ref()?;
    let calibration = patterns.calibration.as_ref()?;
    let (camera, frames) = (maps.first()?, patterns.cameras.first()?);
    let x = camera.x.as_ref()?;
    let texture: Option<Vec<f32>> =
        frames.white_black.as_ref().map(|wb| (0..wb.pixel_count()).map(|i| f32::from(wb.sample(0, i))).collect());
    Some(super::pinhole::reconstruct(calibration, x, camera.y.as_ref(), texture.as_deref()))
}

/// [`rig_point_cloud`] turned to be seen from the camera: x right and y up
/// the image, z towards the camera (`-depth`), so a height map made from it
/// is the surface as the camera sees it, higher towards the camera, and a
/// reference region levels it onto the part (`sheen analyze`, the app).
pub fn rig_cloud_seen_from_camera(m: &Measurement, maps: &[ProjectorMaps]) -> Option<super::point_cloud::PointCloud> {
    let mut cloud = rig_point_cloud(m, maps)?;
    for p in &mut cloud.xyz {
        p[1] = -p[1];
        p[2] = -p[2];
    }
    Some(cloud)
}
