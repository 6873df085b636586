//! What a run warns about, as a kind a program can act on and a sentence an
//! operator can read. Tests and front ends tell warnings apart by kind; the
//! message is free to be reworded. The run report writes both.

use serde::Serialize;

/// The kinds of run warnings, one per cause.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningKind {
    /// A fringe set gave no usable pixel in a camera: every pixel had fewer
    /// than 3 unsaturated samples.
    SetAllSaturated,
    /// A fringe set gave no usable pixel: none reached the minimum modulation.
    SetTooDark,
    /// The sparsest enabled set wraps inside the field, so no phase is absolute.
    SparsestSetWraps,
    /// A period ratio is too large for the measured phase noise (paper §2.3:
    /// the order error grows with the ratio times the sparser set's sigma).
    PeriodRatioTooLarge,
    /// No pixel of a camera has an absolute phase.
    NoAbsolutePhase,
    /// The calibration cannot be used for triangulation.
    CalibrationUnusable,
    /// The calibration is for images of another size.
    CalibrationSizeMismatch,
    /// Stereo matching found no pair: the cameras may share no field.
    NoStereoMatch,
    /// Rectification or matching failed.
    StereoFailed,
    /// Calibration: a pose was left out (its target not found in a camera).
    PoseSkipped,
    /// Calibration: fewer poses than determine the cameras reliably.
    FewPoses,
    /// Calibration: the poses tilt too little against each other.
    SmallTiltSpread,
    /// Calibration: detections set aside as outliers.
    DetectionOutliers,
    /// Calibration: the solved cameras cannot be rectified (no common field).
    NoRectification,
    /// An input file holds something Sheen does not read (an unknown key, a
    /// camera the rig does not use).
    IgnoredInput,
    /// A manifest lists one image file at two places.
    RepeatedImage,
    /// The calibration's cameras are paired with the manifest's by order,
    /// not by name.
    CamerasPairedByOrder,
    /// Images were converted on reading (colour to grey, a wider sample).
    ImageConverted,
    /// The samples never reach the declared bit depth, so saturation may go
    /// unnoticed.
    BitDepthUnreached,
    /// A file gave no length unit; the default was assumed.
    UnitAssumed,
    /// A height map was resampled on reading (unequal X and Y increments).
    HeightMapResampled,
    /// A file's checksum could not be verified.
    ChecksumUnverified,
    /// A file's checksum disagrees with its content.
    ChecksumMismatch,
    /// A spec's height-map pitch does not apply to a map read at its own pitch.
    PitchNotApplied,
    /// A PLY has no quality fields or pixel columns; they are left empty or
    /// rebuilt by binning.
    CloudFieldsMissing,
    /// Points of a cloud fell outside or on top of others on the pixel grid.
    PointsUnplaced,
    /// A profile runs outside the measured surface.
    ProfileOffSurface,
    /// A measurement could not be made (its row says why).
    NotMeasured,
    /// The levelling could not be fitted; heights are shown as measured.
    NotLevelled,
    /// A row's 2U reaches its tolerance's width: no measurement can prove
    /// conformity (ISO 14253-1).
    ToleranceBelowUncertainty,
    /// The calibration states no scale uncertainty; the budgets take it as 0.
    CalibrationUncertaintyUnknown,
    /// Two phase sets of one axis disagree by far more than their noise:
    /// harmonics (an uncorrected projector gamma) ripple the coordinate.
    PhaseSetsRipple,
}

/// One warning of a run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Warning {
    pub kind: WarningKind,
    pub message: String,
}

impl Warning {
    pub fn new(kind: WarningKind, message: impl Into<String>) -> Self {
        Self { kind, message: message.into() }
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_carry_the_kind_beside_the_message() {
        let w = Warning::new(WarningKind::PeriodRatioTooLarge, "camera 'left': period ratio 76.0 ...");
        let json = serde_json::to_value(&w).expect("serialize");
        assert_eq!(json, serde_json::json!({"kind": "period_ratio_too_large", "message": w.message}));
        assert_eq!(w.to_string(), w.message, "operators read the message alone");
    }
}
