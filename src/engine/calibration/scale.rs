//! How well a calibration knows the scales it measures with: the relative
//! standard uncertainties of the height (Z) and lateral (X-Y) scales,
//! propagated from the covariance of the fitted cameras (GUM, the law of
//! propagation of uncertainty, with the Jacobian by central differences).
//!
//! A length ΔX in the world reaches the pixels through the rig's true affine
//! matrices `A` (the left columns of both cameras' `P`, stacked 4x3) and is
//! reconstructed through the fitted ones `A'` by least squares:
//! `ΔX' = (A'ᵀA')⁻¹ A'ᵀ A ΔX` (the offsets cancel in a difference). At the
//! fit both are the same and the scale is 1; the fit's covariance moves
//! `A'`, and with it `|ΔX'| / |ΔX|` along Z (the height scale) and along X
//! and Y (the lateral scale, their mean). Distortion is left out: it bends
//! the field rather than scaling it.

use nalgebra::{Matrix3, Matrix4x3, Vector3};

use crate::engine::camera_model::{AffineCamera, ScaleUncertainty};

/// The relative standard uncertainties of the height and lateral scales of
/// cameras fitted with `covariance` (of `left.P` then `right.P`, row-major).
pub fn scale_uncertainty(cameras: [&AffineCamera; 2], covariance: &[[f64; 16]; 16]) -> ScaleUncertainty {
    let theta = parameters(cameras);
    let truth = stacked(&theta);
    let scales = |t: &[f64; 16]| -> [f64; 2] {
        let Some(m) = reconstruction(&stacked(t), &truth) else { return [f64::NAN; 2] };
        let length = |axis: Vector3<f64>| (m * axis).norm();
        [length(Vector3::z()), 0.5 * (length(Vector3::x()) + length(Vector3::y()))]
    };
    let mut jacobian = [[0.0; 16]; 2];
    for k in 0..16 {
        let step = 1e-6 * theta[k].abs().max(1e-3);
        let (mut up, mut down) = (theta, theta);
        up[k] += step;
        down[k] -= step;
        let (a, b) = (scales(&up), scales(&down));
        for s in 0..2 {
            jacobian[s][k] = (a[s] - b[s]) / (2.0 * step);
        }
    }
    let propagated = |j: &[f64; 16]| -> f64 {
        let mut variance = 0.0;
        for (a, row) in covariance.iter().enumerate() {
            for (b, c) in row.iter().enumerate() {
                variance += j[a] * c * j[b];
            }
        }
        variance.max(0.0).sqrt()
    };
    ScaleUncertainty {
        height_relative: Some(propagated(&jacobian[0])),
        lateral_relative: Some(propagated(&jacobian[1])),
    }
}

fn parameters(cameras: [&AffineCamera; 2]) -> [f64; 16] {
    let mut theta = [0.0; 16];
    for (c, cam) in cameras.iter().enumerate() {
        for row in 0..2 {
            for col in 0..4 {
                theta[c * 8 + row * 4 + col] = cam.p[row][col];
            }
        }
    }
    theta
}

/// The two cameras' `P[.][0..3]` stacked: pixel rows of a world direction.
fn stacked(theta: &[f64; 16]) -> Matrix4x3<f64> {
    Matrix4x3::from_fn(|r, c| theta[(r / 2) * 8 + (r % 2) * 4 + c])
}

/// `(A'ᵀA')⁻¹ A'ᵀ A`: a world displacement as the fitted cameras
/// reconstruct what the true ones saw.
fn reconstruction(fitted: &Matrix4x3<f64>, truth: &Matrix4x3<f64>) -> Option<Matrix3<f64>> {
    let normal = fitted.transpose() * fitted;
    Some(normal.try_inverse()? * fitted.transpose() * truth)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(p: [[f64; 4]; 2]) -> AffineCamera {
        AffineCamera { width: 640, height: 480, p, distortion: None }
    }

    /// Two cameras 15 degrees apart about Y at 100 px/mm.
    fn rig() -> [AffineCamera; 2] {
        let (s, c) = (15f64.to_radians().sin(), 15f64.to_radians().cos());
        [
            camera([[100.0, 0.0, 0.0, 320.0], [0.0, 100.0, 0.0, 240.0]]),
            camera([[100.0 * c, 0.0, 100.0 * s, 320.0], [0.0, 100.0, 0.0, 240.0]]),
        ]
    }

    #[test]
    fn an_exact_fit_has_exact_scales() {
        let [l, r] = rig();
        let u = scale_uncertainty([&l, &r], &[[0.0; 16]; 16]);
        assert_eq!((u.height_relative, u.lateral_relative), (Some(0.0), Some(0.0)));
    }

    /// The propagation agrees with sampling the fitted cameras from the
    /// same covariance and measuring the scales they give.
    #[test]
    fn the_propagated_scale_uncertainty_matches_sampled_cameras() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let [l, r] = rig();
        // Independent noise of 0.01 px/mm on every matrix element, and a
        // correlated pair: both cameras' x-magnification move together.
        let mut cov = [[0.0; 16]; 16];
        for (k, row) in cov.iter_mut().enumerate() {
            row[k] = 1e-4;
        }
        cov[0][8] = 0.8e-4;
        cov[8][0] = 0.8e-4;
        let u = scale_uncertainty([&l, &r], &cov);
        let theta = parameters([&l, &r]);
        let truth = stacked(&theta);
        // Cholesky of the covariance, then seeded normal samples.
        let chol = nalgebra::SMatrix::<f64, 16, 16>::from_fn(|i, j| cov[i][j]).cholesky().expect("positive definite");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let normal = Normal::new(0.0, 1.0).expect("normal");
        let (mut heights, mut laterals) = (Vec::new(), Vec::new());
        for _ in 0..4000 {
            let z = nalgebra::SVector::<f64, 16>::from_fn(|_, _| normal.sample(&mut rng));
            let d = chol.l() * z;
            let mut t = theta;
            for k in 0..16 {
                t[k] += d[k];
            }
            let m = reconstruction(&stacked(&t), &truth).expect("invertible");
            heights.push((m * Vector3::z()).norm());
            laterals.push(0.5 * ((m * Vector3::x()).norm() + (m * Vector3::y()).norm()));
        }
        let std = |v: &[f64]| {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        let (h, l) = (u.height_relative.unwrap(), u.lateral_relative.unwrap());
        assert!(h > 0.0 && l > 0.0);
        assert!((std(&heights) / h - 1.0).abs() < 0.08, "sampled {} propagated {h}", std(&heights));
        assert!((std(&laterals) / l - 1.0).abs() < 0.08, "sampled {} propagated {l}", std(&laterals));
        // A 15 degree rig knows height worse than lateral: Z comes from the
        // disparity of a small angle.
        assert!(h > 2.0 * l, "height {h} lateral {l}");
    }
}
