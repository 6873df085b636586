//! Target detection in one image, whatever the target's kind: the ordered
//! sub-pixel points, or why the target was not found completely.

use super::detect_checkerboard::{CheckerboardDetectionParams, detect_checkerboard};
use super::detect_circles::{CircleDetectionParams, detect_circles};
use super::gray_image::GrayImage;
use super::grid::GridError;
use super::target::{Target, TargetKind};

/// The target's points found in one image.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetDetection {
    /// Observed pixel of each grid point, row-major (`i * cols + j`).
    pub points_px: Vec<[f64; 2]>,
    /// Typical size of a feature in pixels (dot diameter, or the corner
    /// refinement window): the report shows it, the GUI scales markers with it.
    pub feature_size_px: f64,
    /// Point-like candidates found before ordering (clutter included).
    pub candidates: usize,
}

/// Why the target was not found completely in an image.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DetectionError {
    #[error("the image is flat (no grey-level contrast): no target can be seen")]
    NoContrast,
    #[error(transparent)]
    Grid(GridError),
    #[error("{grid}; {border_blobs} blob(s) touch the image border, so the target probably extends beyond the image")]
    AtBorder { border_blobs: usize, grid: GridError },
    #[error(
        "inner corner (row {row}, column {col}) near pixel ({:.0}, {:.0}) is no clean saddle point, so it cannot be \
         located to sub-pixel accuracy; check the image for blur, glare or dirt there",
        .near_px[0], .near_px[1]
    )]
    Refinement { row: usize, col: usize, near_px: [f64; 2] },
    #[error("the image is {width}x{height} px, too small to hold a {rows} x {cols} target")]
    TooSmall { width: usize, height: usize, rows: usize, cols: usize },
}

/// Detection settings for both kinds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DetectionParams {
    pub circles: CircleDetectionParams,
    pub checkerboard: CheckerboardDetectionParams,
}

/// Finds and orders the target's points in `image`.
pub fn detect_target(
    image: &GrayImage,
    target: &Target,
    params: &DetectionParams,
) -> Result<TargetDetection, DetectionError> {
    // Each point needs a few pixels around it to be found at all.
    if image.width < 3 * target.cols || image.height < 3 * target.rows {
        return Err(DetectionError::TooSmall {
            width: image.width,
            height: image.height,
            rows: target.rows,
            cols: target.cols,
        });
    }
    match target.kind {
        TargetKind::Circles => detect_circles(image, target, &params.circles),
        TargetKind::Checkerboard => detect_checkerboard(image, target, &params.checkerboard),
    }
}
