//! The model that calibration fits: two affine cameras (with optional lens
//! distortion) and one rigid pose of the target per position, shared by both
//! cameras, with pose 0 the world frame.
//!
//! A target point `x` (target-plane coordinates, Z = 0) in pose k lies at the
//! world point `X = R_k x + t_k`, which camera c images at the ideal pixel
//! `P_c (X, 1)` and, through its distortion, at the observed pixel.

use serde::{Deserialize, Serialize};

use crate::engine::camera_model::{AffineCamera, Distortion, cross};

/// Which lens distortion terms calibration fits (centre and scale follow
/// [`Distortion::for_image`] and are never fitted).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DistortionModel {
    /// Affine cameras alone.
    None,
    /// One radial term.
    #[default]
    K1,
    /// k1 and k2.
    Radial,
    /// k1, k2 and the decentering terms p1, p2.
    Full,
}

impl DistortionModel {
    pub const ALL: [DistortionModel; 4] =
        [DistortionModel::None, DistortionModel::K1, DistortionModel::Radial, DistortionModel::Full];

    pub fn name(self) -> &'static str {
        match self {
            DistortionModel::None => "none",
            DistortionModel::K1 => "k1",
            DistortionModel::Radial => "radial",
            DistortionModel::Full => "full",
        }
    }

    /// The fitted terms, in the order of [`distortion_terms`].
    pub fn terms(self) -> &'static [&'static str] {
        match self {
            DistortionModel::None => &[],
            DistortionModel::K1 => &["k1"],
            DistortionModel::Radial => &["k1", "k2"],
            DistortionModel::Full => &["k1", "k2", "p1", "p2"],
        }
    }
}

impl std::str::FromStr for DistortionModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        DistortionModel::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown distortion model '{s}': expected none, k1, radial or full"))
    }
}

impl std::fmt::Display for DistortionModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Value of the fitted term `index` of `model` in `d` (k1, k2, p1, p2 order).
pub fn distortion_term(d: &Distortion, index: usize) -> f64 {
    [d.k1, d.k2, d.p1, d.p2][index]
}

/// Mutable access to term `index` (k1, k2, p1, p2 order).
pub fn distortion_term_mut(d: &mut Distortion, index: usize) -> &mut f64 {
    match index {
        0 => &mut d.k1,
        1 => &mut d.k2,
        2 => &mut d.p1,
        _ => &mut d.p2,
    }
}

/// Where the target lies in one position: `X = R x + t`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Rotation from the target frame to the world frame (rows).
    pub rotation: [[f64; 3]; 3],
    pub translation_mm: [f64; 3],
}

impl Pose {
    pub const IDENTITY: Pose =
        Pose { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation_mm: [0.0, 0.0, 0.0] };

    /// World point of target point `x`.
    #[inline]
    pub fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        std::array::from_fn(|i| r[i][0] * x[0] + r[i][1] * x[1] + r[i][2] * x[2] + self.translation_mm[i])
    }

    /// The pose from a rotation vector (axis times angle, radians) and a translation.
    pub fn from_rotation_vector(rotation_rad: [f64; 3], translation_mm: [f64; 3]) -> Self {
        Self { rotation: rotation_matrix(rotation_rad), translation_mm }
    }

    /// Axis times angle (radians) of the rotation.
    pub fn rotation_vector_rad(&self) -> [f64; 3] {
        let m = nalgebra::Matrix3::from_fn(|i, j| self.rotation[i][j]);
        let r = nalgebra::Rotation3::from_matrix_unchecked(m);
        r.scaled_axis().into()
    }

    /// The target's normal in the world (third column of R).
    pub fn normal(&self) -> [f64; 3] {
        [self.rotation[0][2], self.rotation[1][2], self.rotation[2][2]]
    }

    /// Angle between this pose's target plane and the world XY plane (pose 0).
    pub fn tilt_deg(&self) -> f64 {
        self.rotation[2][2].clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// The composition `self` after `inner`: `x -> self(inner(x))`.
    pub fn compose(&self, inner: &Pose) -> Pose {
        let a = &self.rotation;
        let b = &inner.rotation;
        let rotation = std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()));
        Pose { rotation, translation_mm: self.apply(inner.translation_mm) }
    }

    /// The inverse pose.
    pub fn inverse(&self) -> Pose {
        let r = &self.rotation;
        let rotation: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
        let t = self.translation_mm;
        let translation_mm = std::array::from_fn(|i| -(0..3).map(|k| rotation[i][k] * t[k]).sum::<f64>());
        Pose { rotation, translation_mm }
    }
}

/// Rodrigues' formula: the rotation by `|w|` radians about `w / |w|`.
pub fn rotation_matrix(w: [f64; 3]) -> [[f64; 3]; 3] {
    let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    if angle < 1e-300 {
        return Pose::IDENTITY.rotation;
    }
    let r = nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::new(w[0], w[1], w[2]));
    std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)]))
}

/// The fitted rig: the two cameras (left, right) and the poses (pose 0 the identity).
#[derive(Clone, Debug, PartialEq)]
pub struct RigModel {
    pub cameras: [AffineCamera; 2],
    pub poses: Vec<Pose>,
}

impl RigModel {
    /// Observed pixel of target point `x` in pose `pose` seen by camera `camera`.
    #[inline]
    pub fn project(&self, camera: usize, pose: usize, x: [f64; 3]) -> [f64; 2] {
        self.cameras[camera].project_observed(self.poses[pose].apply(x))
    }

    /// The mirror image through the pose-0 target plane (Z -> -Z): it
    /// reprojects every point identically and negates every height.
    pub fn mirrored(&self) -> RigModel {
        let flip = [1.0, 1.0, -1.0];
        let mut out = self.clone();
        for cam in &mut out.cameras {
            for row in &mut cam.p {
                row[2] = -row[2];
            }
        }
        for pose in &mut out.poses {
            // F R F and F t with F = diag(1, 1, -1).
            for (i, row) in pose.rotation.iter_mut().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    *v *= flip[i] * flip[j];
                }
            }
            pose.translation_mm[2] = -pose.translation_mm[2];
        }
        out
    }

    /// Whether the cameras follow their names: the left camera's viewing
    /// direction has the larger component along the pose-0 X axis.
    pub fn left_is_left(&self) -> bool {
        let dx = |cam: &AffineCamera| {
            let (r1, r2) = cam.rows();
            let d = cross(r1, r2);
            d[0] / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        };
        dx(&self.cameras[0]) > dx(&self.cameras[1])
    }

    /// Resolves the mirror ambiguity by the cameras' names; returns whether it mirrored.
    pub fn name_cameras(&mut self) -> bool {
        if self.left_is_left() {
            return false;
        }
        *self = self.mirrored();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_compose_and_invert() {
        let a = Pose::from_rotation_vector([0.1, -0.2, 0.3], [1.0, 2.0, -3.0]);
        let b = Pose::from_rotation_vector([-0.4, 0.05, 0.2], [0.5, -1.0, 0.25]);
        let x = [0.3, -0.7, 0.0];
        let ab = a.compose(&b).apply(x);
        let direct = a.apply(b.apply(x));
        assert!((0..3).all(|i| (ab[i] - direct[i]).abs() < 1e-12));
        let back = a.inverse().apply(a.apply(x));
        assert!((0..3).all(|i| (back[i] - x[i]).abs() < 1e-12));
        let w = a.rotation_vector_rad();
        assert!((w[0] - 0.1).abs() < 1e-12 && (w[1] + 0.2).abs() < 1e-12 && (w[2] - 0.3).abs() < 1e-12);
        assert!((Pose::from_rotation_vector([0.2, 0.0, 0.0], [0.0; 3]).tilt_deg() - 0.2f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn the_mirror_reprojects_identically_and_swaps_the_names() {
        let cam = |dx: f64, t: f64| AffineCamera {
            width: 100,
            height: 80,
            p: [[100.0, 0.0, dx, 50.0], [0.0, -100.0, 0.0, 40.0 + t]],
            distortion: Some(Distortion { k1: 1e-3, ..Distortion::for_image(100, 80) }),
        };
        // d = r1 x r2 = (dx * 100 * ..): left has d_x > 0 when its P13 > 0.
        let model = RigModel {
            cameras: [cam(26.0, 0.0), cam(-26.0, 1.0)],
            poses: vec![Pose::IDENTITY, Pose::from_rotation_vector([0.3, 0.1, 0.0], [0.1, 0.2, 0.3])],
        };
        assert!(model.left_is_left());
        let m = model.mirrored();
        assert!(!m.left_is_left());
        let x = [0.2, -0.1, 0.0];
        for c in 0..2 {
            for k in 0..2 {
                let (a, b) = (model.project(c, k, x), m.project(c, k, x));
                assert!((a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
            }
        }
        let mut named = m.clone();
        assert!(named.name_cameras());
        assert_eq!(named, model);
    }
}
