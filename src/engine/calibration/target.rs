//! The planar calibration target: its kind, grid size and pitch, and the
//! target-plane coordinates of its points.
//!
//! Point (i, j) (row i, column j, 0-based) lies at `(j * pitch, -i * pitch, 0)`:
//! X along the columns, Y up the image, Z = X x Y towards the cameras
//! (the calibration contract). In every image j runs to the right and
//! i to the bottom, so (0, 0) is the top-left point of the grid.

use serde::{Deserialize, Serialize};

/// What is printed on the plate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TargetKind {
    /// A symmetric grid of filled circles; `rows x cols` circles.
    Circles,
    /// A checkerboard; `rows x cols` inner corners.
    Checkerboard,
}

impl TargetKind {
    pub const ALL: [TargetKind; 2] = [TargetKind::Circles, TargetKind::Checkerboard];

    pub fn name(self) -> &'static str {
        match self {
            TargetKind::Circles => "circles",
            TargetKind::Checkerboard => "checkerboard",
        }
    }

    /// What one grid point is called in messages.
    pub fn point_noun(self) -> &'static str {
        match self {
            TargetKind::Circles => "dots",
            TargetKind::Checkerboard => "inner corners",
        }
    }
}

impl std::str::FromStr for TargetKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        TargetKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown target kind '{s}': expected circles or checkerboard"))
    }
}

impl std::fmt::Display for TargetKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Description of a calibration target.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Target {
    pub kind: TargetKind,
    /// Grid rows (circles, or inner-corner rows of a checkerboard).
    pub rows: usize,
    /// Grid columns.
    pub cols: usize,
    /// Centre-to-centre (corner-to-corner) spacing.
    pub pitch_mm: f64,
    /// Dark dots on a light plate (circles only; checkerboards have both).
    pub dark_on_light: bool,
}

/// Why a target description cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TargetError {
    #[error("the target grid is {rows} x {cols}; at least 3 x 3 points are needed to find and order it")]
    GridTooSmall { rows: usize, cols: usize },
    #[error("the target pitch is {pitch_mm} mm; it must be a positive, finite length")]
    BadPitch { pitch_mm: f64 },
}

impl Target {
    /// Checks the grid size and pitch.
    pub fn validate(&self) -> Result<(), TargetError> {
        if self.rows < 3 || self.cols < 3 {
            return Err(TargetError::GridTooSmall { rows: self.rows, cols: self.cols });
        }
        if !(self.pitch_mm.is_finite() && self.pitch_mm > 0.0) {
            return Err(TargetError::BadPitch { pitch_mm: self.pitch_mm });
        }
        Ok(())
    }

    pub fn point_count(&self) -> usize {
        self.rows * self.cols
    }

    /// Target-plane coordinates of point (i, j): `(j * pitch, -i * pitch, 0)`.
    #[inline]
    pub fn point_mm(&self, i: usize, j: usize) -> [f64; 3] {
        [j as f64 * self.pitch_mm, -(i as f64) * self.pitch_mm, 0.0]
    }

    /// All points, row-major (index `i * cols + j`).
    pub fn points_mm(&self) -> Vec<[f64; 3]> {
        (0..self.rows).flat_map(|i| (0..self.cols).map(move |j| self.point_mm(i, j))).collect()
    }

    /// (row, column) of row-major index `k`.
    #[inline]
    pub fn row_col(&self, k: usize) -> (usize, usize) {
        (k / self.cols, k % self.cols)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_follow_the_contract() {
        let t = Target { kind: TargetKind::Circles, rows: 3, cols: 4, pitch_mm: 0.5, dark_on_light: true };
        assert!(t.validate().is_ok());
        let p = t.points_mm();
        assert_eq!(p.len(), 12);
        assert_eq!(p[0], [0.0, 0.0, 0.0]);
        assert_eq!(p[3], [1.5, 0.0, 0.0]);
        assert_eq!(p[4], [0.0, -0.5, 0.0]);
        assert_eq!(t.row_col(7), (1, 3));
        assert_eq!(t.point_mm(1, 3), p[7]);
    }

    #[test]
    fn bad_targets_are_rejected() {
        let t = Target { kind: TargetKind::Checkerboard, rows: 2, cols: 7, pitch_mm: 1.0, dark_on_light: true };
        assert_eq!(t.validate(), Err(TargetError::GridTooSmall { rows: 2, cols: 7 }));
        let t = Target { rows: 5, pitch_mm: -1.0, ..t };
        assert!(matches!(t.validate(), Err(TargetError::BadPitch { .. })));
        assert_eq!("checkerboard".parse::<TargetKind>(), Ok(TargetKind::Checkerboard));
        assert!("dots".parse::<TargetKind>().unwrap_err().contains("circles or checkerboard"));
    }
}
