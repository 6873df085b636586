//! Triangulation for two affine cameras: the four linear equations
//! `M_L X = p_L - t_L`, `M_R X = p_R - t_R` solved in the least-squares sense.
//! For affine cameras the system matrix does not depend on the point, so its
//! 3x4 pseudo-inverse is computed once per rig and each point costs 12
//! multiply-adds.

use super::camera_model::StereoCalibration;

#[derive(Clone, Debug, PartialEq)]
pub struct Triangulator {
    /// `(A^T A)^-1 A^T` with `A = [M_L; M_R]` (4x3).
    pub pseudo_inverse: [[f64; 4]; 3],
    offsets: [f64; 4],
}

impl Triangulator {
    pub fn new(calib: &StereoCalibration) -> Option<Self> {
        let l = &calib.left.p;
        let r = &calib.right.p;
        let a = nalgebra::Matrix4x3::new(
            l[0][0], l[0][1], l[0][2], //
            l[1][0], l[1][1], l[1][2], //
            r[0][0], r[0][1], r[0][2], //
            r[1][0], r[1][1], r[1][2],
        );
        let ata = a.transpose() * a;
        let pinv = ata.try_inverse()? * a.transpose();
        Some(Self {
            pseudo_inverse: std::array::from_fn(|i| std::array::from_fn(|j| pinv[(i, j)])),
            offsets: [l[0][3], l[1][3], r[0][3], r[1][3]],
        })
    }

    /// World point from the ideal left and right pixels of one match.
    #[inline]
    pub fn point(&self, left: [f64; 2], right: [f64; 2]) -> [f64; 3] {
        let b = [
            left[0] - self.offsets[0],
            left[1] - self.offsets[1],
            right[0] - self.offsets[2],
            right[1] - self.offsets[3],
        ];
        let m = &self.pseudo_inverse;
        std::array::from_fn(|i| m[i][0] * b[0] + m[i][1] * b[1] + m[i][2] * b[2] + m[i][3] * b[3])
    }

    /// Derivative of the world point with respect to the right ideal pixel.
    pub fn d_point_d_right(&self, d_right: [f64; 2]) -> [f64; 3] {
        let m = &self.pseudo_inverse;
        std::array::from_fn(|i| m[i][2] * d_right[0] + m[i][3] * d_right[1])
    }
}
