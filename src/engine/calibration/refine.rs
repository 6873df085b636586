//! Joint refinement of the rig by Levenberg-Marquardt on the reprojection
//! error: both cameras' `P` (2x4 each), the distortion terms asked for, and
//! one pose per target position shared by the two cameras (pose 0 fixed: it is
//! the world frame).
//!
//! Residual of an observation: `r = D_c(P_c (R_k x + t_k, 1)) - observed`, with
//! `D_c` the camera's distortion (the forward model, centre and scale
//! fixed). Pose rotations are updated multiplicatively, `R <- exp([w]x) R`, so
//! the three rotation parameters are always a small local increment. The
//! Jacobian is analytic. Robustness: after a fit, detections farther than
//! `max(k sigma, floor)` from their reprojection (sigma from the median
//! residual) are set aside and the fit is repeated until the set is stable.
//! Standard deviations come from `sigma^2 (J^T J)^-1` at the solution.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::model::{DistortionModel, RigModel, distortion_term, distortion_term_mut, rotation_matrix};
use super::target::Target;
use crate::engine::camera_model::{Distortion, dot};
use crate::engine::control::{Cancelled, RunControl};

/// One detected point: target point `point` of pose `pose` seen by `camera` (0 left, 1 right).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    pub pose: usize,
    pub camera: usize,
    pub point: usize,
    pub observed_px: [f64; 2],
}

/// Settings of the refinement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineOptions {
    pub distortion: DistortionModel,
    /// Detections farther than this many robust standard deviations are outliers.
    pub outlier_threshold_sigma: f64,
    /// ... but never closer than this.
    pub min_outlier_threshold_px: f64,
    pub max_iterations: usize,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            distortion: DistortionModel::K1,
            outlier_threshold_sigma: 5.0,
            min_outlier_threshold_px: 0.1,
            max_iterations: 200,
        }
    }
}

/// A fitted parameter with its standard deviation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParameterStd {
    pub name: String,
    pub value: f64,
    pub std: f64,
}

/// Result of the refinement.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    pub model: RigModel,
    /// Observed minus reprojected pixel, per observation (outliers too).
    pub residuals_px: Vec<[f64; 2]>,
    pub inlier: Vec<bool>,
    /// Per-coordinate standard deviation of the detections, from the median residual.
    pub robust_sigma_px: f64,
    pub outlier_threshold_px: f64,
    pub parameters: Vec<ParameterStd>,
    /// Covariance of the two cameras' affine matrices (`left.P` then
    /// `right.P`, row-major: 16 parameters), for the scales' uncertainty
    /// ([`super::scale::scale_uncertainty`]).
    pub camera_covariance: [[f64; 16]; 16],
    /// Levenberg-Marquardt iterations over all rounds.
    pub iterations: usize,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RefineError {
    #[error(
        "the reprojection problem is singular ({observations} detections for {parameters} parameters): \
         the poses do not determine the cameras; add poses tilted in different directions"
    )]
    Singular { observations: usize, parameters: usize },
    #[error("an observation refers to pose {pose} of camera {camera}, but the model has {poses} poses and 2 cameras")]
    UnknownPose { pose: usize, camera: usize, poses: usize },
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// Index of each parameter in the vector.
#[derive(Clone, Copy, Debug)]
struct Layout {
    terms: usize,
    poses: usize,
}

impl Layout {
    fn len(&self) -> usize {
        16 + 2 * self.terms + 6 * (self.poses - 1)
    }
    fn p(&self, camera: usize, row: usize, col: usize) -> usize {
        camera * 8 + row * 4 + col
    }
    fn term(&self, camera: usize, term: usize) -> usize {
        16 + camera * self.terms + term
    }
    fn pose(&self, pose: usize) -> Option<usize> {
        (pose > 0).then(|| 16 + 2 * self.terms + 6 * (pose - 1))
    }
}

/// Observed pixel of an ideal one, its 2x2 Jacobian, and the derivatives by
/// the first `terms` distortion terms (k1, k2, p1, p2).
fn distort_with_jacobian(
    d: Option<&Distortion>,
    ideal: [f64; 2],
    terms: usize,
) -> ([f64; 2], [[f64; 2]; 2], [[f64; 2]; 4]) {
    let Some(d) = d else {
        return (ideal, [[1.0, 0.0], [0.0, 1.0]], [[0.0; 2]; 4]);
    };
    let s = d.scale_px;
    let x = (ideal[0] - d.center_px[0]) / s;
    let y = (ideal[1] - d.center_px[1]) / s;
    let r2 = x * x + y * y;
    let radial = 1.0 + d.k1 * r2 + d.k2 * r2 * r2;
    let d_radial = d.k1 + 2.0 * d.k2 * r2;
    let xd = x * radial + 2.0 * d.p1 * x * y + d.p2 * (r2 + 2.0 * x * x);
    let yd = y * radial + d.p1 * (r2 + 2.0 * y * y) + 2.0 * d.p2 * x * y;
    let jacobian = [
        [
            radial + 2.0 * x * x * d_radial + 2.0 * d.p1 * y + 6.0 * d.p2 * x,
            2.0 * x * y * d_radial + 2.0 * d.p1 * x + 2.0 * d.p2 * y,
        ],
        [
            2.0 * x * y * d_radial + 2.0 * d.p1 * x + 2.0 * d.p2 * y,
            radial + 2.0 * y * y * d_radial + 6.0 * d.p1 * y + 2.0 * d.p2 * x,
        ],
    ];
    let all = [
        [s * x * r2, s * y * r2],
        [s * x * r2 * r2, s * y * r2 * r2],
        [s * 2.0 * x * y, s * (r2 + 2.0 * y * y)],
        [s * (r2 + 2.0 * x * x), s * 2.0 * x * y],
    ];
    let mut by_term = [[0.0; 2]; 4];
    by_term[..terms].copy_from_slice(&all[..terms]);
    ([d.center_px[0] + s * xd, d.center_px[1] + s * yd], jacobian, by_term)
}

/// Residual (predicted - observed) of one observation and its non-zero
/// Jacobian columns.
fn linearize(
    model: &RigModel,
    layout: &Layout,
    target_point: [f64; 3],
    obs: &Observation,
) -> ([f64; 2], Vec<(usize, [f64; 2])>) {
    let pose = &model.poses[obs.pose];
    let cam = &model.cameras[obs.camera];
    let r = &pose.rotation;
    let rx: [f64; 3] = std::array::from_fn(|i| dot(r[i], target_point));
    let y: [f64; 3] = std::array::from_fn(|i| rx[i] + pose.translation_mm[i]);
    let ideal = cam.project(y);
    let (pred, jd, by_term) = distort_with_jacobian(cam.distortion.as_ref(), ideal, layout.terms);
    let residual = [pred[0] - obs.observed_px[0], pred[1] - obs.observed_px[1]];
    let through = |v: [f64; 2]| [jd[0][0] * v[0] + jd[0][1] * v[1], jd[1][0] * v[0] + jd[1][1] * v[1]];
    let mut columns = Vec::with_capacity(8 + layout.terms + 6);
    let yh = [y[0], y[1], y[2], 1.0];
    // d(observed)/dP[row][col] = J_d e_row yh[col]: column `row` of J_d.
    let jd_columns = [[jd[0][0], jd[1][0]], [jd[0][1], jd[1][1]]];
    for (row, jd_column) in jd_columns.iter().enumerate() {
        for (col, &value) in yh.iter().enumerate() {
            columns.push((layout.p(obs.camera, row, col), [jd_column[0] * value, jd_column[1] * value]));
        }
    }
    for (t, column) in by_term.iter().enumerate().take(layout.terms) {
        columns.push((layout.term(obs.camera, t), *column));
    }
    if let Some(base) = layout.pose(obs.pose) {
        let (m1, m2) = cam.rows();
        let image_of = |v: [f64; 3]| through([dot(m1, v), dot(m2, v)]);
        // d(exp([w]x) R x)/dw_i = e_i x (R x).
        let e_cross = [[0.0, -rx[2], rx[1]], [rx[2], 0.0, -rx[0]], [-rx[1], rx[0], 0.0]];
        for (i, v) in e_cross.iter().enumerate() {
            columns.push((base + i, image_of(*v)));
        }
        for i in 0..3 {
            let mut e = [0.0; 3];
            e[i] = 1.0;
            columns.push((base + 3 + i, image_of(e)));
        }
    }
    (residual, columns)
}

fn with_step(model: &RigModel, layout: &Layout, step: &DVector<f64>) -> RigModel {
    let mut out = model.clone();
    for (c, cam) in out.cameras.iter_mut().enumerate() {
        for row in 0..2 {
            for col in 0..4 {
                cam.p[row][col] += step[layout.p(c, row, col)];
            }
        }
        if let Some(d) = cam.distortion.as_mut() {
            for t in 0..layout.terms {
                *distortion_term_mut(d, t) += step[layout.term(c, t)];
            }
        }
    }
    for (k, pose) in out.poses.iter_mut().enumerate() {
        let Some(base) = layout.pose(k) else { continue };
        let w = rotation_matrix([step[base], step[base + 1], step[base + 2]]);
        let r = pose.rotation;
        pose.rotation = std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|m| w[i][m] * r[m][j]).sum()));
        for i in 0..3 {
            pose.translation_mm[i] += step[base + 3 + i];
        }
    }
    out
}

struct Normal {
    jtj: DMatrix<f64>,
    jtr: DVector<f64>,
    cost: f64,
}

fn normal_equations(
    model: &RigModel,
    layout: &Layout,
    points: &[[f64; 3]],
    obs: &[Observation],
    inlier: &[bool],
) -> Normal {
    let n = layout.len();
    let mut jtj = DMatrix::<f64>::zeros(n, n);
    let mut jtr = DVector::<f64>::zeros(n);
    let mut cost = 0.0;
    for (o, _) in obs.iter().zip(inlier).filter(|(_, keep)| **keep) {
        let (r, cols) = linearize(model, layout, points[o.point], o);
        cost += r[0] * r[0] + r[1] * r[1];
        for (a, ca) in &cols {
            jtr[*a] += ca[0] * r[0] + ca[1] * r[1];
            for (b, cb) in &cols {
                jtj[(*a, *b)] += ca[0] * cb[0] + ca[1] * cb[1];
            }
        }
    }
    Normal { jtj, jtr, cost }
}

fn cost(model: &RigModel, points: &[[f64; 3]], obs: &[Observation], inlier: &[bool]) -> f64 {
    obs.iter()
        .zip(inlier)
        .filter(|(_, keep)| **keep)
        .map(|(o, _)| {
            let p = model.project(o.camera, o.pose, points[o.point]);
            (p[0] - o.observed_px[0]).powi(2) + (p[1] - o.observed_px[1]).powi(2)
        })
        .sum()
}

/// Levenberg-Marquardt with Marquardt's diagonal scaling; returns the
/// iterations taken.
fn levenberg_marquardt(
    model: &mut RigModel,
    layout: &Layout,
    points: &[[f64; 3]],
    obs: &[Observation],
    inlier: &[bool],
    max_iterations: usize,
    control: &RunControl,
) -> Result<usize, RefineError> {
    let mut lambda = 1e-3;
    let mut iterations = 0;
    for _ in 0..max_iterations {
        control.check()?;
        iterations += 1;
        let normal = normal_equations(model, layout, points, obs, inlier);
        let diag_max = normal.jtj.diagonal().max();
        let mut improved = false;
        while lambda < 1e16 {
            let mut a = normal.jtj.clone();
            for i in 0..a.nrows() {
                a[(i, i)] += lambda * normal.jtj[(i, i)].max(1e-12 * diag_max);
            }
            let Some(chol) = a.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let step = -chol.solve(&normal.jtr);
            let candidate = with_step(model, layout, &step);
            let new_cost = cost(&candidate, points, obs, inlier);
            if new_cost < normal.cost {
                let decrease = (normal.cost - new_cost) / normal.cost.max(1e-300);
                *model = candidate;
                lambda = (lambda * 0.1).max(1e-12);
                improved = true;
                if decrease < 1e-12 {
                    return Ok(iterations);
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Ok(iterations)
}

/// Median of the residual lengths divided by `sqrt(2 ln 2)`: for Gaussian
/// noise of standard deviation sigma per coordinate the lengths are Rayleigh
/// distributed with that median.
fn robust_sigma(lengths: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = lengths.collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let median = if v.len() % 2 == 1 { v[v.len() / 2] } else { 0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2]) };
    median / (2.0 * std::f64::consts::LN_2).sqrt()
}

/// Refines `start` on `observations` of `target`; `pose_names` label the
/// poses in the parameter list.
pub fn refine(
    start: &RigModel,
    target: &Target,
    observations: &[Observation],
    pose_names: &[String],
    options: &RefineOptions,
    control: &RunControl,
) -> Result<Refined, RefineError> {
    let terms = options.distortion.terms().len();
    if start.poses.is_empty() {
        return Err(RefineError::Singular { observations: observations.len(), parameters: 16 });
    }
    if let Some(o) = observations.iter().find(|o| o.pose >= start.poses.len() || o.camera > 1) {
        return Err(RefineError::UnknownPose { pose: o.pose, camera: o.camera, poses: start.poses.len() });
    }
    let layout = Layout { terms, poses: start.poses.len() };
    let mut model = start.clone();
    for cam in &mut model.cameras {
        cam.distortion = match options.distortion {
            DistortionModel::None => None,
            _ => {
                let mut d = cam.distortion.unwrap_or_else(|| Distortion::for_image(cam.width, cam.height));
                // Terms not fitted are exactly zero.
                for t in terms..4 {
                    *distortion_term_mut(&mut d, t) = 0.0;
                }
                Some(d)
            }
        };
    }
    let points = target.points_mm();
    let n_params = layout.len();
    if 2 * observations.len() <= n_params {
        return Err(RefineError::Singular { observations: observations.len(), parameters: n_params });
    }
    let mut inlier = vec![true; observations.len()];
    let mut iterations = 0;
    let mut threshold = f64::INFINITY;
    let mut sigma = 0.0;
    for _round in 0..6 {
        iterations +=
            levenberg_marquardt(&mut model, &layout, &points, observations, &inlier, options.max_iterations, control)?;
        let lengths: Vec<f64> = observations
            .iter()
            .map(|o| {
                let p = model.project(o.camera, o.pose, points[o.point]);
                (p[0] - o.observed_px[0]).hypot(p[1] - o.observed_px[1])
            })
            .collect();
        sigma = robust_sigma(lengths.iter().zip(&inlier).filter(|(_, k)| **k).map(|(l, _)| *l));
        threshold = (options.outlier_threshold_sigma * sigma).max(options.min_outlier_threshold_px);
        let next: Vec<bool> = lengths.iter().map(|&l| l <= threshold).collect();
        let kept = next.iter().filter(|k| **k).count();
        if next == inlier || 2 * kept <= n_params {
            break;
        }
        inlier = next;
    }
    model.name_cameras();
    let normal = normal_equations(&model, &layout, &points, observations, &inlier);
    let kept = inlier.iter().filter(|k| **k).count();
    let dof = (2 * kept).saturating_sub(n_params).max(1);
    let variance = normal.cost / dof as f64;
    // Scale to unit diagonal before inverting: the parameters span many
    // orders of magnitude (k1 against P).
    let scale: Vec<f64> =
        (0..n_params).map(|i| if normal.jtj[(i, i)] > 0.0 { 1.0 / normal.jtj[(i, i)].sqrt() } else { 0.0 }).collect();
    let scaled = DMatrix::from_fn(n_params, n_params, |i, j| normal.jtj[(i, j)] * scale[i] * scale[j]);
    let Some(inverse) = scaled.clone().try_inverse() else {
        return Err(RefineError::Singular { observations: observations.len(), parameters: n_params });
    };
    let std = |i: usize| (variance * inverse[(i, i)]).max(0.0).sqrt() * scale[i];
    let mut parameters = Vec::with_capacity(n_params);
    for (c, name) in ["left", "right"].iter().enumerate() {
        for row in 0..2 {
            for col in 0..4 {
                let i = layout.p(c, row, col);
                parameters.push(ParameterStd {
                    name: format!("{name}.P[{row}][{col}]"),
                    value: model.cameras[c].p[row][col],
                    std: std(i),
                });
            }
        }
        if let Some(d) = &model.cameras[c].distortion {
            for (t, term) in options.distortion.terms().iter().enumerate() {
                parameters.push(ParameterStd {
                    name: format!("{name}.{term}"),
                    value: distortion_term(d, t),
                    std: std(layout.term(c, t)),
                });
            }
        }
    }
    for (k, pose) in model.poses.iter().enumerate() {
        let Some(base) = layout.pose(k) else { continue };
        let label = pose_names.get(k).cloned().unwrap_or_else(|| format!("pose {k}"));
        let w = pose.rotation_vector_rad();
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            parameters.push(ParameterStd {
                name: format!("{label}.rotation_{axis}_deg"),
                value: w[i].to_degrees(),
                std: std(base + i).to_degrees(),
            });
        }
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            parameters.push(ParameterStd {
                name: format!("{label}.t{axis}_mm"),
                value: pose.translation_mm[i],
                std: std(base + 3 + i),
            });
        }
    }
    let residuals_px = observations
        .iter()
        .map(|o| {
            let p = model.project(o.camera, o.pose, points[o.point]);
            [o.observed_px[0] - p[0], o.observed_px[1] - p[1]]
        })
        .collect();
    let mut camera_covariance = [[0.0; 16]; 16];
    for (i, row) in camera_covariance.iter_mut().enumerate() {
        for (j, c) in row.iter_mut().enumerate() {
            *c = variance * inverse[(i, j)] * scale[i] * scale[j];
        }
    }
    Ok(Refined {
        model,
        residuals_px,
        inlier,
        robust_sigma_px: sigma,
        outlier_threshold_px: threshold,
        parameters,
        camera_covariance,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::calibration::model::Pose;
    use crate::engine::calibration::target::TargetKind;
    use crate::engine::camera_model::AffineCamera;

    fn rig(k1: f64) -> (RigModel, Target) {
        let target = Target { kind: TargetKind::Circles, rows: 6, cols: 8, pitch_mm: 1.0, dark_on_light: true };
        let cam = |theta: f64, roll: f64, scale: f64, t: [f64; 2]| {
            let (s, c) = theta.to_radians().sin_cos();
            let (rs, rc) = roll.to_radians().sin_cos();
            let r1 = [c, 0.0, s];
            let r2 = [0.0, -1.0, 0.0];
            let a: [f64; 3] = std::array::from_fn(|i| scale * (rc * r1[i] - rs * r2[i]));
            let b: [f64; 3] = std::array::from_fn(|i| scale * (rs * r1[i] + rc * r2[i]));
            AffineCamera {
                width: 400,
                height: 300,
                p: [[a[0], a[1], a[2], t[0]], [b[0], b[1], b[2], t[1]]],
                distortion: Some(Distortion { k1, ..Distortion::for_image(400, 300) }),
            }
        };
        let model = RigModel {
            cameras: [cam(15.0, 0.0, 40.0, [60.0, 50.0]), cam(-15.0, 2.0, 40.8, [70.0, 55.0])],
            poses: vec![
                Pose::IDENTITY,
                Pose::from_rotation_vector([0.3, 0.0, 0.05], [-0.5, 0.2, 0.3]),
                Pose::from_rotation_vector([0.0, -0.35, -0.1], [0.4, -0.3, -0.2]),
                Pose::from_rotation_vector([-0.25, 0.2, 0.0], [0.1, 0.6, 0.5]),
                Pose::from_rotation_vector([0.15, 0.3, 0.2], [-0.3, -0.1, 0.1]),
            ],
        };
        (model, target)
    }

    fn observations(model: &RigModel, target: &Target) -> Vec<Observation> {
        let mut out = Vec::new();
        for pose in 0..model.poses.len() {
            for camera in 0..2 {
                for (point, &x) in target.points_mm().iter().enumerate() {
                    out.push(Observation { pose, camera, point, observed_px: model.project(camera, pose, x) });
                }
            }
        }
        out
    }

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        let (mut model, target) = rig(2e-3);
        for cam in &mut model.cameras {
            if let Some(d) = cam.distortion.as_mut() {
                d.k2 = -1e-3;
                d.p1 = 5e-4;
                d.p2 = -3e-4;
            }
        }
        let layout = Layout { terms: 4, poses: model.poses.len() };
        let points = target.points_mm();
        let obs = Observation { pose: 3, camera: 1, point: 13, observed_px: [0.0, 0.0] };
        let (r0, cols) = linearize(&model, &layout, points[13], &obs);
        for (index, analytic) in cols {
            let h = 1e-6;
            let mut step = DVector::zeros(layout.len());
            step[index] = h;
            let (r1, _) = linearize(&with_step(&model, &layout, &step), &layout, points[13], &obs);
            for d in 0..2 {
                let numeric = (r1[d] - r0[d]) / h;
                assert!(
                    (numeric - analytic[d]).abs() < 1e-4 * (1.0 + analytic[d].abs()),
                    "{index}: {numeric} vs {analytic:?}"
                );
            }
        }
    }

    #[test]
    fn converges_to_the_truth_from_a_perturbed_start() {
        let (truth, target) = rig(1e-3);
        let obs = observations(&truth, &target);
        let mut start = truth.clone();
        for cam in &mut start.cameras {
            cam.p[0][2] *= 1.05;
            cam.p[1][3] += 1.5;
            cam.distortion = None;
        }
        start.poses[2].translation_mm[2] += 0.2;
        start.poses[3] = Pose { rotation: rotation_matrix([-0.22, 0.21, 0.01]), ..start.poses[3] };
        let names: Vec<String> = (0..5).map(|k| format!("pose {k}")).collect();
        let refined =
            refine(&start, &target, &obs, &names, &RefineOptions::default(), &RunControl::new()).expect("refined");
        for c in 0..2 {
            for r in 0..2 {
                for j in 0..4 {
                    let (a, b) = (refined.model.cameras[c].p[r][j], truth.cameras[c].p[r][j]);
                    assert!((a - b).abs() < 1e-7 * (1.0 + b.abs()), "P{c}[{r}][{j}] {a} vs {b}");
                }
            }
            let k1 = refined.model.cameras[c].distortion.map(|d| d.k1).unwrap_or(f64::NAN);
            assert!((k1 - 1e-3).abs() < 1e-10, "k1 {k1}");
        }
        assert!(refined.inlier.iter().all(|k| *k));
        assert!(refined.residuals_px.iter().all(|r| r[0].hypot(r[1]) < 1e-8));
        assert_eq!(refined.parameters.len(), 2 * 9 + 4 * 6);
    }

    #[test]
    fn a_bad_detection_is_rejected_and_does_not_bend_the_fit() {
        let (truth, target) = rig(0.0);
        let mut obs = observations(&truth, &target);
        // Deterministic noise of 0.02 px and one detection 2 px off.
        for (i, o) in obs.iter_mut().enumerate() {
            let a = (i as f64 * 12.9898).sin() * 43758.5453;
            let b = (i as f64 * 78.233).sin() * 12345.678;
            o.observed_px[0] += 0.02 * (a - a.floor() - 0.5) * 3.46;
            o.observed_px[1] += 0.02 * (b - b.floor() - 0.5) * 3.46;
        }
        obs[100].observed_px[0] += 2.0;
        let names: Vec<String> = (0..5).map(|k| format!("pose {k}")).collect();
        let options = RefineOptions { distortion: DistortionModel::None, ..RefineOptions::default() };
        let refined = refine(&truth, &target, &obs, &names, &options, &RunControl::new()).expect("refined");
        assert!(!refined.inlier[100]);
        assert_eq!(refined.inlier.iter().filter(|k| !**k).count(), 1);
        assert!((refined.residuals_px[100][0] - 2.0).abs() < 0.05);
        assert!(refined.robust_sigma_px > 0.01 && refined.robust_sigma_px < 0.03, "{}", refined.robust_sigma_px);
        // Standard deviations are positive and small for well-determined P.
        let p00 = &refined.parameters[0];
        assert!(p00.std > 0.0 && p00.std < 1e-2, "{p00:?}");
    }
}
