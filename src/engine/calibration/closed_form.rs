//! Closed-form start for the refinement: both affine cameras and all poses
//! from the per-image affine maps target plane -> image.
//!
//! Camera c sees pose k through `A_ck = M_c [R_k e1, R_k e2 | t_k] + [0 | p_c]`
//! (2x3, fitted by least squares; distortion is ignored here). Pose 0 is the
//! world frame, so `A_c0 = [m1 m2 | p_c]` gives all of camera c but the third
//! column `m3` of its 2x3 part `M_c = [m1 m2 m3]`. For pose k with unit normal
//! n_k, `Q_k Q_k^T = I - n_k n_k^T` turns the 2x2 part `B_ck = M_c Q_k` into
//! `B_ck B_ck^T = G_c + m3 m3^T - w w^T` with `G_c = B_c0 B_c0^T` and
//! `w = M_c n_k`, so `det(G_c - B_ck B_ck^T + m3 m3^T) = 0`. Written in the
//! entries of `mu = m3 m3^T` (rank one, `det mu = 0`) each pose gives one
//! linear equation, `D22 mu11 - 2 D12 mu12 + D11 mu22 = -det D` with
//! `D = G_c - B_ck B_ck^T`: three or more tilted poses besides pose 0 fix `mu`
//! linearly; two fix it with the rank-one condition (a quadratic). `mu`
//! leaves the sign of `m3` open in each camera. The relative sign is fixed by
//! the poses: only with the right one do both cameras see the same rotation
//! `Q_k` (solved jointly from `[M_L; M_R] Q_k = [B_Lk; B_Rk]`). The common sign
//! is the mirror through the target plane, which no image can decide; the
//! cameras' names do (see [`RigModel::name_cameras`]).

use nalgebra::{DMatrix, DVector, Matrix2, Matrix3x2, Matrix4x2, Matrix4x3, Vector3, Vector4};

use super::PoseObservations;
use super::model::{Pose, RigModel};
use super::target::Target;
use crate::engine::camera_model::AffineCamera;

/// Why no start could be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ClosedFormError {
    #[error("{poses} pose(s) given; the closed-form start needs at least 3")]
    TooFewPoses { poses: usize },
    #[error("pose {pose} camera {camera}: the target points do not determine an affine map (collinear or too few)")]
    DegenerateImage { pose: usize, camera: &'static str },
    #[error(
        "camera {camera}: the poses do not determine the camera's depth axis; tilt the target by 10 to 30 deg \
         against pose 0, in at least two different directions"
    )]
    TooLittleTilt { camera: &'static str },
}

const CAMERA_NAMES: [&str; 2] = ["left", "right"];

/// Smallest useful size of the tilt equations relative to `|G|`: about
/// `sin^2` of the tilt, so 1e-6 is a tilt of 0.06 deg.
const MIN_RELATIVE_TILT_SIGNAL: f64 = 1e-6;

/// Affine map `[x, y, 1] -> (u, v)` of each camera and pose, least squares.
pub fn fit_affine(target_xy: &[[f64; 2]], image_px: &[[f64; 2]]) -> Option<[[f64; 3]; 2]> {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atu = Vector3::<f64>::zeros();
    let mut atv = Vector3::<f64>::zeros();
    for (x, p) in target_xy.iter().zip(image_px) {
        let f = Vector3::new(x[0], x[1], 1.0);
        ata += f * f.transpose();
        atu += f * p[0];
        atv += f * p[1];
    }
    let inv = ata.try_inverse()?;
    let (a, b) = (inv * atu, inv * atv);
    Some([[a[0], a[1], a[2]], [b[0], b[1], b[2]]])
}

/// The closed-form rig, named so that the left camera is on the left.
pub fn closed_form(
    target: &Target,
    poses: &[PoseObservations],
    image_sizes_px: [[usize; 2]; 2],
) -> Result<RigModel, ClosedFormError> {
    if poses.len() < 3 {
        return Err(ClosedFormError::TooFewPoses { poses: poses.len() });
    }
    let target_xy: Vec<[f64; 2]> = target.points_mm().iter().map(|p| [p[0], p[1]]).collect();
    let mut affine = [Vec::new(), Vec::new()];
    for (k, pose) in poses.iter().enumerate() {
        for (c, points) in [&pose.left_px, &pose.right_px].into_iter().enumerate() {
            let a = fit_affine(&target_xy, points)
                .ok_or(ClosedFormError::DegenerateImage { pose: k, camera: CAMERA_NAMES[c] })?;
            affine[c].push(a);
        }
    }
    let block = |a: &[[f64; 3]; 2]| Matrix2::new(a[0][0], a[0][1], a[1][0], a[1][1]);
    // Candidates for m3 of each camera (up to sign).
    let mut m3_candidates: [Vec<[f64; 2]>; 2] = [Vec::new(), Vec::new()];
    for c in 0..2 {
        let b0 = block(&affine[c][0]);
        let g = b0 * b0.transpose();
        let rows: Vec<([f64; 3], f64)> = affine[c][1..]
            .iter()
            .map(|a| {
                let b = block(a);
                let d = g - b * b.transpose();
                ([d[(1, 1)], -2.0 * d[(0, 1)], d[(0, 0)]], -d.determinant())
            })
            .collect();
        m3_candidates[c] = depth_column_candidates(&rows, g.norm());
        if m3_candidates[c].is_empty() {
            return Err(ClosedFormError::TooLittleTilt { camera: CAMERA_NAMES[c] });
        }
    }
    // Choose the pair (and relative sign) under which both cameras agree on
    // every pose's rotation.
    let mut best: Option<(f64, [[f64; 2]; 2])> = None;
    for &ml in &m3_candidates[0] {
        for &mr in &m3_candidates[1] {
            for sign in [1.0, -1.0] {
                let pair = [ml, [sign * mr[0], sign * mr[1]]];
                let matrices = [0, 1].map(|c| camera_block(&affine[c][0], pair[c]));
                let cost: f64 = (1..poses.len())
                    .map(|k| rotation_from_both(&matrices, &block(&affine[0][k]), &block(&affine[1][k])).1)
                    .sum();
                if best.as_ref().is_none_or(|b| cost < b.0) {
                    best = Some((cost, pair));
                }
            }
        }
    }
    let Some((_, m3)) = best else {
        return Err(ClosedFormError::TooLittleTilt { camera: CAMERA_NAMES[0] });
    };
    let matrices = [0, 1].map(|c| camera_block(&affine[c][0], m3[c]));
    let cameras = [0, 1].map(|c| {
        let a0 = &affine[c][0];
        let m = &matrices[c];
        AffineCamera {
            width: image_sizes_px[c][0],
            height: image_sizes_px[c][1],
            p: [[m[(0, 0)], m[(0, 1)], m[(0, 2)], a0[0][2]], [m[(1, 0)], m[(1, 1)], m[(1, 2)], a0[1][2]]],
            distortion: None,
        }
    });
    let stacked = Matrix4x3::from_rows(&[
        matrices[0].row(0).into_owned(),
        matrices[0].row(1).into_owned(),
        matrices[1].row(0).into_owned(),
        matrices[1].row(1).into_owned(),
    ]);
    let pinv = (stacked.transpose() * stacked).try_inverse().map(|inv| inv * stacked.transpose());
    let mut model_poses = vec![Pose::IDENTITY];
    for (al, ar) in affine[0].iter().zip(&affine[1]).skip(1) {
        let (q, _) = rotation_from_both(&matrices, &block(al), &block(ar));
        let n = q.column(0).cross(&q.column(1));
        let rotation = std::array::from_fn(|i| [q[(i, 0)], q[(i, 1)], n[i]]);
        let rhs = Vector4::new(
            al[0][2] - cameras[0].p[0][3],
            al[1][2] - cameras[0].p[1][3],
            ar[0][2] - cameras[1].p[0][3],
            ar[1][2] - cameras[1].p[1][3],
        );
        let t = pinv.map(|p| p * rhs).unwrap_or_else(Vector3::zeros);
        model_poses.push(Pose { rotation, translation_mm: [t[0], t[1], t[2]] });
    }
    let mut model = RigModel { cameras, poses: model_poses };
    model.name_cameras();
    Ok(model)
}

/// `M = [m1 m2 m3]` from pose 0's map and the depth column.
fn camera_block(a0: &[[f64; 3]; 2], m3: [f64; 2]) -> nalgebra::Matrix2x3<f64> {
    nalgebra::Matrix2x3::new(a0[0][0], a0[0][1], m3[0], a0[1][0], a0[1][1], m3[1])
}

/// The rotation's first two columns seen by both cameras (least squares, then
/// the nearest orthonormal pair) and how badly the cameras disagree.
fn rotation_from_both(
    m: &[nalgebra::Matrix2x3<f64>; 2],
    bl: &Matrix2<f64>,
    br: &Matrix2<f64>,
) -> (Matrix3x2<f64>, f64) {
    let stacked = Matrix4x3::from_rows(&[
        m[0].row(0).into_owned(),
        m[0].row(1).into_owned(),
        m[1].row(0).into_owned(),
        m[1].row(1).into_owned(),
    ]);
    let rhs = Matrix4x2::from_rows(&[
        bl.row(0).into_owned(),
        bl.row(1).into_owned(),
        br.row(0).into_owned(),
        br.row(1).into_owned(),
    ]);
    let Some(inv) = (stacked.transpose() * stacked).try_inverse() else {
        return (Matrix3x2::identity(), f64::INFINITY);
    };
    let q = inv * stacked.transpose() * rhs;
    // Polar decomposition: the orthonormal pair nearest to q.
    let svd = q.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (Matrix3x2::identity(), f64::INFINITY);
    };
    let q_orth = u * v_t;
    let residual = (stacked * q_orth - rhs).norm_squared();
    (q_orth, residual)
}

/// Candidates for the depth column `m3` (one sign each) from the linear
/// equations `rows . (mu11, mu12, mu22) = rhs`.
/// `scale` is the size of `G` (pixels^2 per mm^2), so the equations' entries
/// relative to it measure the tilt.
fn depth_column_candidates(rows: &[([f64; 3], f64)], scale: f64) -> Vec<[f64; 2]> {
    if rows.is_empty() {
        return Vec::new();
    }
    // Equations are weighted by their size, which grows with the pose's tilt
    // (sin^2): an untilted pose carries no information and rounding noise
    // must not be blown up into an equation. `scale` makes them dimensionless.
    let n = rows.len();
    let mut a = DMatrix::<f64>::zeros(n.max(3), 3);
    let mut b = DVector::<f64>::zeros(n.max(3));
    for (i, (r, rhs)) in rows.iter().enumerate() {
        for j in 0..3 {
            a[(i, j)] = r[j] / scale;
        }
        b[i] = rhs / (scale * scale);
    }
    let svd = a.svd(true, true);
    let Some(v_t) = svd.v_t.as_ref() else { return Vec::new() };
    let sv = &svd.singular_values;
    let largest = sv.max();
    // Below this the poses are tilted by well under a degree against pose 0.
    if !(largest > MIN_RELATIVE_TILT_SIGNAL) {
        return Vec::new();
    }
    let mut mus: Vec<[f64; 3]> = Vec::new();
    // Singular values come sorted in decreasing order.
    let well_posed = sv[2] > 1e-6 * largest;
    let particular = |rank: usize| {
        let ut_b = svd.u.as_ref().map(|u| u.transpose() * &b);
        let mut x = [0.0; 3];
        if let Some(ut_b) = ut_b {
            for k in 0..rank {
                for (j, xj) in x.iter_mut().enumerate() {
                    *xj += v_t[(k, j)] * ut_b[k] / sv[k];
                }
            }
        }
        x
    };
    if well_posed {
        mus.push(particular(3));
    }
    if sv[1] > 1e-6 * largest {
        // mu = mu_p + s h along the weakest direction, with det(mu) = 0.
        let mp = particular(2);
        let h = [v_t[(2, 0)], v_t[(2, 1)], v_t[(2, 2)]];
        let qa = h[0] * h[2] - h[1] * h[1];
        let qb = mp[0] * h[2] + mp[2] * h[0] - 2.0 * mp[1] * h[1];
        let qc = mp[0] * mp[2] - mp[1] * mp[1];
        let roots: Vec<f64> = if qa.abs() < 1e-300 {
            if qb.abs() > 0.0 { vec![-qc / qb] } else { Vec::new() }
        } else {
            let disc = qb * qb - 4.0 * qa * qc;
            if disc < 0.0 {
                // Noise pushed the roots apart: the nearest real point.
                vec![-qb / (2.0 * qa)]
            } else {
                let sq = disc.sqrt();
                vec![(-qb + sq) / (2.0 * qa), (-qb - sq) / (2.0 * qa)]
            }
        };
        for s in roots {
            mus.push([mp[0] + s * h[0], mp[1] + s * h[1], mp[2] + s * h[2]]);
        }
    }
    mus.iter()
        .filter_map(|mu| {
            // Nearest rank-one positive semi-definite matrix: the largest eigenpair.
            // The equations were solved for mu / scale.
            let m = Matrix2::new(mu[0], mu[1], mu[1], mu[2]) * scale;
            let eig = m.symmetric_eigen();
            let i = if eig.eigenvalues[0] >= eig.eigenvalues[1] { 0 } else { 1 };
            let lambda = eig.eigenvalues[i];
            (lambda > 0.0).then(|| {
                let e = eig.eigenvectors.column(i);
                [lambda.sqrt() * e[0], lambda.sqrt() * e[1]]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::calibration::target::TargetKind;

    fn camera(theta_deg: f64, roll_deg: f64, scale: f64, offset: [f64; 2]) -> AffineCamera {
        let t = theta_deg.to_radians();
        let ex = [t.cos(), 0.0, t.sin()];
        let ey = [0.0, -1.0, 0.0];
        let (s, c) = roll_deg.to_radians().sin_cos();
        let r1: [f64; 3] = std::array::from_fn(|i| scale * (c * ex[i] - s * ey[i]));
        let r2: [f64; 3] = std::array::from_fn(|i| scale * (s * ex[i] + c * ey[i]));
        AffineCamera {
            width: 640,
            height: 480,
            p: [[r1[0], r1[1], r1[2], 320.0 + offset[0]], [r2[0], r2[1], r2[2], 240.0 + offset[1]]],
            distortion: None,
        }
    }

    fn observe(model: &RigModel, target: &Target) -> Vec<PoseObservations> {
        let pts = target.points_mm();
        (0..model.poses.len())
            .map(|k| PoseObservations {
                left_px: pts.iter().map(|&x| model.project(0, k, x)).collect(),
                right_px: pts.iter().map(|&x| model.project(1, k, x)).collect(),
            })
            .collect()
    }

    fn assert_models_close(a: &RigModel, b: &RigModel, tol: f64) {
        for c in 0..2 {
            for r in 0..2 {
                for j in 0..4 {
                    let (x, y) = (a.cameras[c].p[r][j], b.cameras[c].p[r][j]);
                    assert!((x - y).abs() < tol * (1.0 + y.abs()), "camera {c} P[{r}][{j}]: {x} vs {y}");
                }
            }
        }
        for (k, (pa, pb)) in a.poses.iter().zip(&b.poses).enumerate() {
            for i in 0..3 {
                assert!((pa.translation_mm[i] - pb.translation_mm[i]).abs() < tol, "pose {k} t");
                for j in 0..3 {
                    assert!((pa.rotation[i][j] - pb.rotation[i][j]).abs() < tol, "pose {k} R");
                }
            }
        }
    }

    fn truth(poses: usize) -> (RigModel, Target) {
        let target = Target { kind: TargetKind::Circles, rows: 7, cols: 9, pitch_mm: 1.0, dark_on_light: true };
        let all = [
            Pose::IDENTITY,
            Pose::from_rotation_vector([0.3, 0.0, 0.05], [-0.5, 0.2, 0.3]),
            Pose::from_rotation_vector([0.0, -0.35, -0.1], [0.4, -0.3, -0.2]),
            Pose::from_rotation_vector([-0.25, 0.2, 0.0], [0.1, 0.6, 0.5]),
            Pose::from_rotation_vector([0.15, 0.3, 0.2], [-0.3, -0.1, 0.1]),
        ];
        let model = RigModel {
            cameras: [camera(15.0, 0.0, 40.0, [-160.0, 120.0]), camera(-15.0, 2.0, 40.8, [-150.0, 115.0])],
            poses: all[..poses].to_vec(),
        };
        (model, target)
    }

    #[test]
    fn recovers_an_exact_rig_from_four_and_three_poses() {
        for n in [5, 4, 3] {
            let (model, target) = truth(n);
            let obs = observe(&model, &target);
            let est = closed_form(&target, &obs, [[640, 480], [640, 480]]).expect("closed form");
            assert_models_close(&est, &model, 1e-9);
        }
    }

    #[test]
    fn names_decide_the_mirror() {
        // A rig whose "left" camera sits on the right is mirrored back.
        let (model, target) = truth(4);
        let swapped = RigModel { cameras: [model.cameras[1].clone(), model.cameras[0].clone()], poses: model.poses };
        let obs = observe(&swapped, &target);
        let est = closed_form(&target, &obs, [[640, 480], [640, 480]]).expect("closed form");
        assert!(est.left_is_left());
        assert_models_close(&est, &swapped.mirrored(), 1e-9);
    }

    #[test]
    fn untilted_poses_are_reported() {
        let (mut model, target) = truth(4);
        for (k, pose) in model.poses.iter_mut().enumerate() {
            *pose = Pose::from_rotation_vector([0.0, 0.0, 0.1 * k as f64], [0.1 * k as f64, 0.0, 0.0]);
        }
        let obs = observe(&model, &target);
        assert!(matches!(
            closed_form(&target, &obs, [[640, 480], [640, 480]]),
            Err(ClosedFormError::TooLittleTilt { .. })
        ));
    }
}
