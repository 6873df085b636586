//! Calibration of a camera–projector rig (issue 52, item 3) from a planar
//! target in several poses with the Gray code and the phase sets projected
//! onto it, after Moreno & Taubin (2012), "Simple, accurate, and robust
//! projector-camera calibration":
//!
//! 1. the target's points in the camera's white frame (the stereo rig's
//!    detectors, [`detect_target`]);
//! 2. each point's projector coordinate from a *local homography* of the
//!    decoded projector x and y over the camera pixels around it
//!    ([`projector_point_at`]): decoding is per pixel, a feature lies
//!    between pixels, and a plane maps camera to projector by a homography
//!    up to lens distortion, so a small window fits it exactly and averages
//!    the decoding noise of a few hundred pixels;
//! 3. start values per device by Zhang's method (2000) from the homographies
//!    target plane → image, the rig's `R, t` from the poses;
//! 4. one bundle adjustment (Levenberg–Marquardt) of both devices'
//!    intrinsics and distortion, `R, t` and every pose, each device's
//!    residuals weighted by its own robust noise, outliers set aside.
//!
//! The result follows the calibration file's conventions: the camera's
//! frame, `X_p = R X_c + t`, millimetres, pixel centres at integers.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde::Serialize;

use super::detect::{DetectionParams, detect_target};
use super::gray_image::GrayImage;
use super::model::{DistortionModel, Pose};
use super::target::{Target, TargetError};
use super::{MIN_POSES, MIN_TILT_SPREAD_DEG, RECOMMENDED_POSES};
use crate::engine::control::{Cancelled, RunControl};
use crate::engine::fringe::Measurement;
use crate::engine::length_unit::LengthUnit;
use crate::engine::pinhole::{CameraProjectorCalibration, PinholeDevice};
use crate::engine::projector_coordinate::ProjectorCoordinate;
use crate::engine::warning::{Warning, WarningKind};

/// The two devices, in the order of the report and the parameter vector.
pub const DEVICE_NAMES: [&str; 2] = ["camera", "projector"];

/// Fewest decoded pixels around a feature for its local homography.
const MIN_WINDOW_PIXELS: usize = 24;

/// What one pose shows: the target's points in the camera and, where the
/// pixels around them decoded, in the projector.
#[derive(Clone, Debug, PartialEq)]
pub struct RigPoseObservation {
    pub name: String,
    /// Camera pixel of each target point, row-major as [`Target::points_mm`].
    pub camera_px: Vec<[f64; 2]>,
    /// Projector pixel of each target point; `None` where too few pixels
    /// around it have both projector coordinates.
    pub projector_px: Vec<Option<[f64; 2]>>,
}

/// How the rig is calibrated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigCalibrationOptions {
    /// Lens distortion fitted for each device.
    pub distortion: DistortionModel,
    pub detection: DetectionParams,
    /// Radius of the camera window whose decoded pixels give a feature's
    /// local homography; `None`: 45 % of the target's pitch in the image,
    /// so the window reaches past a dark dot (which may decode nothing)
    /// onto the plate around it but not to the next dot.
    pub window_radius_px: Option<f64>,
    /// Residuals beyond this many robust standard deviations of their
    /// device are set aside, but none nearer than `min_outlier_threshold_px`
    /// (a few hundredths of a pixel is the detectors' scatter, not a blunder).
    pub outlier_threshold_sigma: f64,
    pub min_outlier_threshold_px: f64,
    pub max_iterations: usize,
}

impl Default for RigCalibrationOptions {
    fn default() -> Self {
        Self {
            distortion: DistortionModel::K1,
            detection: DetectionParams::default(),
            window_radius_px: None,
            outlier_threshold_sigma: 5.0,
            min_outlier_threshold_px: 0.2,
            max_iterations: 200,
        }
    }
}

/// Why a camera–projector rig cannot be calibrated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RigCalibrateError {
    #[error(transparent)]
    Target(#[from] TargetError),
    #[error(
        "only {usable} pose(s) have the whole target in the camera and decoded projector coordinates around it; at \
         least {required} are needed{}",
        if skipped.is_empty() { String::new() } else { format!(". Skipped: {}", skipped.join("; ")) }
    )]
    TooFewPoses { usable: usize, required: usize, skipped: Vec<String> },
    #[error(
        "no start for the {device}: {reason}; tilt the target by 10 to 30 deg in different directions and keep it \
         inside the projector's image"
    )]
    NoStart { device: &'static str, reason: String },
    #[error(
        "the bundle adjustment diverged (its normal equations became singular); the poses do not determine the rig"
    )]
    Singular,
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// One device's fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DeviceReport {
    pub device: &'static str,
    pub width: usize,
    pub height: usize,
    pub points: usize,
    pub outliers: usize,
    pub rms_reprojection_px: f64,
    pub max_reprojection_px: f64,
    /// Robust standard deviation of a residual coordinate, the weight's base.
    pub robust_sigma_px: f64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// `k1, k2, p1, p2, k3`.
    pub distortion: [f64; 5],
    /// Standard deviations (k = 1) of `fx, fy, cx, cy` from the fit, pixels.
    pub sigma_fx_fy_cx_cy_px: [f64; 4],
}

/// One pose's part of the fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RigPoseReport {
    pub name: String,
    pub camera_points: usize,
    pub projector_points: usize,
    pub camera_rms_px: f64,
    pub projector_rms_px: f64,
    /// Angle between this pose's target plane and pose 0's.
    pub tilt_deg: f64,
}

/// What the calibration of a camera–projector rig found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RigCalibrationReport {
    pub target: Target,
    pub distortion_model: &'static str,
    pub devices: Vec<DeviceReport>,
    pub poses: Vec<RigPoseReport>,
    pub skipped_poses: Vec<String>,
    /// Distance between the camera's and the projector's centres.
    pub baseline_mm: f64,
    /// Angle between the two optical axes.
    pub triangulation_angle_deg: f64,
    /// Standard deviations (k = 1) of the rig's rotation (degrees, per axis)
    /// and translation (mm).
    pub sigma_rotation_deg: [f64; 3],
    pub sigma_translation_mm: [f64; 3],
    pub tilt_spread_deg: f64,
    pub iterations: usize,
    pub warnings: Vec<Warning>,
}

impl RigCalibrationReport {
    /// RMS reprojection error of the camera and the projector.
    pub fn rms_per_device(&self) -> [f64; 2] {
        [0, 1].map(|d| self.devices.get(d).map_or(f64::NAN, |r| r.rms_reprojection_px))
    }
}

/// Detects the target in the camera's white frame and finds every target
/// point's projector coordinate; `Err` names why the pose cannot be used.
pub fn observe_pose(
    name: &str,
    white: &GrayImage,
    projector_x: &ProjectorCoordinate,
    projector_y: Option<&ProjectorCoordinate>,
    target: &Target,
    options: &RigCalibrationOptions,
) -> Result<RigPoseObservation, String> {
    let projector_y = projector_y.ok_or_else(|| {
        "no projector y: a camera–projector calibration needs the row code and phase sets along y".to_owned()
    })?;
    let detection = detect_target(white, target, &options.detection).map_err(|e| e.to_string())?;
    let radius_px = options.window_radius_px.unwrap_or_else(|| 0.45 * pitch_px(&detection.points_px, target));
    let projector_px: Vec<Option<[f64; 2]>> =
        detection.points_px.iter().map(|&at| projector_point_at(projector_x, projector_y, at, radius_px)).collect();
    let decoded = projector_px.iter().flatten().count();
    if decoded < 8 {
        return Err(format!(
            "only {decoded} of {} target points have decoded projector coordinates around them; is the target in \
             the projector's light?",
            projector_px.len()
        ));
    }
    Ok(RigPoseObservation { name: name.to_owned(), camera_px: detection.points_px, projector_px })
}

/// One pose of a calibration set as recorded (the target under every frame
/// the rig projects): its projector coordinates decoded as a measurement's
/// ([`projector_maps`](crate::engine::camera_projector::projector_maps),
/// default phase parameters), the target found in the white frame.
/// `Err` says why the pose cannot be used; a cancelled run says so too.
pub fn observe_measurement(
    name: &str,
    m: &Measurement,
    target: &Target,
    options: &RigCalibrationOptions,
    control: &RunControl,
) -> Result<RigPoseObservation, String> {
    let phase = crate::engine::pipeline::Params::default().phase_params(m);
    let maps = crate::engine::camera_projector::projector_maps(m, &phase, control).map_err(|e| e.to_string())?;
    let (Some(camera), Some(frames)) = (maps.first(), m.projector.as_ref().and_then(|p| p.cameras.first())) else {
        return Err("not a camera–projector measurement".to_owned());
    };
    let Some(white_black) = frames.white_black.as_ref() else {
        return Err("no white frame to find the target in".to_owned());
    };
    let Some(x) = camera.x.as_ref() else {
        return Err("no projector x".to_owned());
    };
    let white = GrayImage {
        width: white_black.width,
        height: white_black.height,
        pixels_dn: (0..white_black.pixel_count()).map(|i| f32::from(white_black.sample(0, i))).collect(),
    };
    observe_pose(name, &white, x, camera.y.as_ref(), target, options)
}

/// The median distance in the image between neighbouring target points.
fn pitch_px(points: &[[f64; 2]], target: &Target) -> f64 {
    let along_rows: Vec<f64> = (0..target.rows)
        .flat_map(|i| (0..target.cols - 1).map(move |j| (i * target.cols + j, i * target.cols + j + 1)))
        .filter_map(|(a, b)| Some(distance(*points.get(a)?, *points.get(b)?)))
        .collect();
    median(&along_rows)
}

/// The projector point of camera point `at_px` from the local homography of
/// the decoded projector coordinates within `radius_px` (Moreno & Taubin
/// 2012, eq. 1). Pixels the homography misses by more than three robust
/// deviations (a decoding error at a dot's rim) are dropped and the fit is
/// repeated once.
pub fn projector_point_at(
    x: &ProjectorCoordinate,
    y: &ProjectorCoordinate,
    at_px: [f64; 2],
    radius_px: f64,
) -> Option<[f64; 2]> {
    let (w, h) = (x.width, x.height);
    let r = radius_px.max(2.0);
    let (u0, u1) = ((at_px[0] - r).floor().max(0.0) as usize, ((at_px[0] + r).ceil().max(0.0) as usize).min(w - 1));
    let (v0, v1) = ((at_px[1] - r).floor().max(0.0) as usize, ((at_px[1] + r).ceil().max(0.0) as usize).min(h - 1));
    let mut camera = Vec::new();
    let mut projector = Vec::new();
    let mut in_disc = 0usize;
    for v in v0..=v1 {
        for u in u0..=u1 {
            if (u as f64 - at_px[0]).hypot(v as f64 - at_px[1]) > r {
                continue;
            }
            in_disc += 1;
            let i = v * w + u;
            let (xp, yp) = (x.coordinate_px[i], y.coordinate_px[i]);
            if xp.is_finite() && yp.is_finite() {
                camera.push([u as f64, v as f64]);
                projector.push([f64::from(xp), f64::from(yp)]);
            }
        }
    }
    // A window mostly undecoded is at the target's rim or in a shadow; one
    // decoded on one side only would extrapolate.
    if camera.len() < MIN_WINDOW_PIXELS || 4 * camera.len() < in_disc {
        return None;
    }
    let n = camera.len() as f64;
    let mean = camera.iter().fold([0.0, 0.0], |m, c| [m[0] + c[0] / n, m[1] + c[1] / n]);
    if distance(mean, at_px) > 0.35 * r {
        return None;
    }
    let mut hom = homography(&camera, &projector)?;
    let misses: Vec<f64> = camera.iter().zip(&projector).map(|(c, p)| distance(apply(&hom, *c), *p)).collect();
    let limit = 3.0 * 1.4826 * median(&misses).max(1e-9) + 1e-6;
    if misses.iter().any(|&m| m > limit) {
        let keep: Vec<usize> = (0..camera.len()).filter(|&k| misses[k] <= limit).collect();
        if keep.len() < MIN_WINDOW_PIXELS {
            return None;
        }
        let c: Vec<[f64; 2]> = keep.iter().map(|&k| camera[k]).collect();
        let p: Vec<[f64; 2]> = keep.iter().map(|&k| projector[k]).collect();
        hom = homography(&c, &p)?;
    }
    let out = apply(&hom, at_px);
    out.iter().all(|v| v.is_finite()).then_some(out)
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() { 0.0 } else { v[v.len() / 2] }
}

fn apply(h: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    let q = h * Vector3::new(p[0], p[1], 1.0);
    [q.x / q.z, q.y / q.z]
}

/// Hartley's normalisation: centroid to the origin, mean distance √2.
fn normalisation(points: &[[f64; 2]]) -> Matrix3<f64> {
    let n = points.len() as f64;
    let (mx, my) = points.iter().fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
    let spread = points.iter().map(|p| (p[0] - mx).hypot(p[1] - my)).sum::<f64>() / n;
    let s = if spread > 0.0 { std::f64::consts::SQRT_2 / spread } else { 1.0 };
    Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
}

/// The homography `dst ~ H src` by the normalised direct linear transform.
pub fn homography(src: &[[f64; 2]], dst: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    if src.len() < 4 || src.len() != dst.len() {
        return None;
    }
    let (ts, td) = (normalisation(src), normalisation(dst));
    let mut ata = nalgebra::SMatrix::<f64, 9, 9>::zeros();
    for (s, d) in src.iter().zip(dst) {
        let a = apply(&ts, *s);
        let b = apply(&td, *d);
        let rows = [
            [a[0], a[1], 1.0, 0.0, 0.0, 0.0, -b[0] * a[0], -b[0] * a[1], -b[0]],
            [0.0, 0.0, 0.0, a[0], a[1], 1.0, -b[1] * a[0], -b[1] * a[1], -b[1]],
        ];
        for row in rows {
            let r = nalgebra::SVector::<f64, 9>::from(row);
            ata += r * r.transpose();
        }
    }
    let eigen = ata.symmetric_eigen();
    let k = eigen.eigenvalues.imin();
    let e = eigen.eigenvectors.column(k);
    let hn = Matrix3::new(e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7], e[8]);
    let h = td.try_inverse()? * hn * ts;
    let scale = h[(2, 2)];
    (scale.abs() > 1e-300 && h.iter().all(|v| v.is_finite())).then(|| h / scale)
}

/// Zhang's (2000) closed form for `fx, fy, cx, cy` (no skew) from the
/// homographies target plane → image of at least three poses; with a
/// principal point at the image centre (`centre`) as the fallback when the
/// poses leave it undetermined.
fn intrinsics_from_homographies(hs: &[Matrix3<f64>], centre: [f64; 2]) -> Option<[f64; 4]> {
    let v = |h: &Matrix3<f64>, i: usize, j: usize| {
        let (a, b) = (h.column(i), h.column(j));
        [
            a[0] * b[0],
            a[0] * b[1] + a[1] * b[0],
            a[1] * b[1],
            a[2] * b[0] + a[0] * b[2],
            a[2] * b[1] + a[1] * b[2],
            a[2] * b[2],
        ]
    };
    // Condition by the image scale so the six unknowns are comparable.
    let s = centre[0].max(centre[1]).max(1.0);
    let t = Matrix3::new(1.0 / s, 0.0, 0.0, 0.0, 1.0 / s, 0.0, 0.0, 0.0, 1.0);
    let mut vtv = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    for h in hs {
        let h = t * h;
        let h = h / h.norm();
        let v12 = nalgebra::SVector::<f64, 6>::from(v(&h, 0, 1));
        let v11 = nalgebra::SVector::<f64, 6>::from(v(&h, 0, 0));
        let v22 = nalgebra::SVector::<f64, 6>::from(v(&h, 1, 1));
        let d = v11 - v22;
        vtv += v12 * v12.transpose() + d * d.transpose();
    }
    // Zero skew: B12 = 0.
    let skew = nalgebra::SVector::<f64, 6>::from([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
    vtv += skew * skew.transpose() * vtv.trace();
    let eigen = vtv.symmetric_eigen();
    let b = eigen.eigenvectors.column(eigen.eigenvalues.imin()).into_owned();
    let b = if b[0] < 0.0 { -b } else { b };
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha = (lambda / b11).sqrt();
    let beta = (lambda * b11 / den).sqrt();
    let u0 = -b13 * alpha * alpha / lambda;
    let k = [alpha * s, beta * s, u0 * s, v0 * s];
    let inside = |c: f64, side: f64| (-0.5 * side..=1.5 * side).contains(&c);
    if k.iter().all(|v| v.is_finite())
        && k[0] > 0.0
        && k[1] > 0.0
        && inside(k[2], 2.0 * centre[0])
        && inside(k[3], 2.0 * centre[1])
    {
        return Some(k);
    }
    focal_with_centred_principal_point(hs, centre).map(|f| [f, f, centre[0], centre[1]])
}

/// One focal length from the orthogonality of `r1, r2` with the principal
/// point given (linear in `1/f²`).
fn focal_with_centred_principal_point(hs: &[Matrix3<f64>], centre: [f64; 2]) -> Option<f64> {
    let shift = Matrix3::new(1.0, 0.0, -centre[0], 0.0, 1.0, -centre[1], 0.0, 0.0, 1.0);
    let (mut num, mut den) = (0.0, 0.0);
    for h in hs {
        let h = shift * h;
        let h = h / h.norm();
        let (a, b) = (h.column(0), h.column(1));
        for (c, d) in [
            (a[0] * b[0] + a[1] * b[1], a[2] * b[2]),
            (a[0] * a[0] + a[1] * a[1] - b[0] * b[0] - b[1] * b[1], a[2] * a[2] - b[2] * b[2]),
        ] {
            num -= c * d;
            den += c * c;
        }
    }
    let a = num / den;
    (a.is_finite() && a > 0.0).then(|| 1.0 / a.sqrt())
}

/// The pose target → device from a homography and the device's intrinsics
/// (Zhang 2000, section 3.1), its rotation made orthonormal.
fn pose_from_homography(h: &Matrix3<f64>, k: [f64; 4]) -> Option<Pose> {
    let kinv = Matrix3::new(1.0 / k[0], 0.0, -k[2] / k[0], 0.0, 1.0 / k[1], -k[3] / k[1], 0.0, 0.0, 1.0);
    let m = kinv * h;
    let (m1, m2, m3) = (m.column(0).into_owned(), m.column(1).into_owned(), m.column(2).into_owned());
    let mut lambda = 2.0 / (m1.norm() + m2.norm());
    if m3.z * lambda < 0.0 {
        lambda = -lambda;
    }
    let (r1, r2, t) = (m1 * lambda, m2 * lambda, m3 * lambda);
    let r3 = r1.cross(&r2);
    let r = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = r.svd(true, true);
    let mut rot = svd.u? * svd.v_t?;
    if rot.determinant() < 0.0 {
        rot = -rot;
    }
    rot.iter().all(|v| v.is_finite()).then(|| Pose {
        rotation: std::array::from_fn(|i| std::array::from_fn(|j| rot[(i, j)])),
        translation_mm: [t.x, t.y, t.z],
    })
}

/// One residual's source: a target point of a pose seen by a device.
#[derive(Clone, Copy, Debug)]
struct Observation {
    pose: usize,
    point: usize,
    device: usize,
    observed_px: [f64; 2],
}

/// The parameter vector's layout: per device `fx, fy, cx, cy` and its
/// distortion terms, the rig's rotation vector and translation, then each
/// pose's (target → camera).
#[derive(Clone, Copy)]
struct Layout {
    terms: usize,
    poses: usize,
}

impl Layout {
    fn device(&self, d: usize) -> usize {
        d * (4 + self.terms)
    }
    fn rig(&self) -> usize {
        2 * (4 + self.terms)
    }
    fn pose(&self, k: usize) -> usize {
        self.rig() + 6 + 6 * k
    }
    fn len(&self) -> usize {
        self.pose(self.poses)
    }
}

/// Positions in `k1, k2, p1, p2, k3` of the fitted terms.
fn term_slot(model: DistortionModel, term: usize) -> usize {
    match (model, term) {
        (_, t) if t < 2 => t,
        (DistortionModel::Full, t) => t,
        _ => 4,
    }
}

fn device_of(p: &[f64], layout: &Layout, model: DistortionModel, d: usize, size: [usize; 2]) -> PinholeDevice {
    let o = layout.device(d);
    let mut distortion = [0.0; 5];
    for t in 0..layout.terms {
        distortion[term_slot(model, t)] = p[o + 4 + t];
    }
    PinholeDevice { width: size[0], height: size[1], fx: p[o], fy: p[o + 1], cx: p[o + 2], cy: p[o + 3], distortion }
}

fn pose_at(p: &[f64], o: usize) -> Pose {
    Pose::from_rotation_vector([p[o], p[o + 1], p[o + 2]], [p[o + 3], p[o + 4], p[o + 5]])
}

struct Problem<'a> {
    layout: Layout,
    model: DistortionModel,
    sizes: [[usize; 2]; 2],
    points_mm: &'a [[f64; 3]],
    observations: &'a [Observation],
}

impl Problem<'_> {
    /// Reprojection error (projected − observed) of every observation.
    fn errors(&self, p: &[f64]) -> Vec<[f64; 2]> {
        let devices = [0, 1].map(|d| device_of(p, &self.layout, self.model, d, self.sizes[d]));
        let rig = pose_at(p, self.layout.rig());
        let poses: Vec<Pose> = (0..self.layout.poses).map(|k| pose_at(p, self.layout.pose(k))).collect();
        self.observations
            .iter()
            .map(|o| {
                let camera = poses[o.pose].apply(self.points_mm[o.point]);
                let x = if o.device == 0 { camera } else { rig.apply(camera) };
                if x[2] <= 0.0 {
                    return [1e6, 1e6];
                }
                let (u, v) = devices[o.device].project(x);
                [u - o.observed_px[0], v - o.observed_px[1]]
            })
            .collect()
    }

    fn weighted(&self, p: &[f64], weights: &[f64]) -> DVector<f64> {
        let e = self.errors(p);
        DVector::from_iterator(2 * e.len(), e.iter().zip(weights).flat_map(|(e, w)| [e[0] * w, e[1] * w]))
    }

    /// The Jacobian by central differences; each parameter touches few
    /// residuals, but with a few thousand residuals the dense form is fast.
    fn jacobian(&self, p: &[f64], weights: &[f64]) -> DMatrix<f64> {
        let n = p.len();
        let columns: Vec<DVector<f64>> = (0..n)
            .map(|j| {
                let step = 1e-6 * p[j].abs().max(1e-2);
                let mut plus = p.to_vec();
                let mut minus = p.to_vec();
                plus[j] += step;
                minus[j] -= step;
                (self.weighted(&plus, weights) - self.weighted(&minus, weights)) / (2.0 * step)
            })
            .collect();
        DMatrix::from_columns(&columns)
    }
}

struct Fit {
    params: Vec<f64>,
    iterations: usize,
    /// `(Jᵀ J)⁻¹` at the solution (weighted residuals).
    covariance: Option<DMatrix<f64>>,
}

/// Levenberg–Marquardt on the weighted residuals.
fn levenberg_marquardt(
    problem: &Problem<'_>,
    start: Vec<f64>,
    weights: &[f64],
    max_iterations: usize,
    control: &RunControl,
) -> Result<Fit, RigCalibrateError> {
    let mut p = start;
    let mut r = problem.weighted(&p, weights);
    let mut cost = r.norm_squared();
    let mut lambda = 1e-3;
    let mut iterations = 0;
    for _ in 0..max_iterations {
        control.check()?;
        iterations += 1;
        let j = problem.jacobian(&p, weights);
        let jtj = j.transpose() * &j;
        let g = j.transpose() * &r;
        let mut improved = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for i in 0..a.nrows() {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = p.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let rt = problem.weighted(&trial, weights);
            let ct = rt.norm_squared();
            if ct.is_finite() && ct < cost {
                let relative = (cost - ct) / cost.max(1e-300);
                p = trial;
                r = rt;
                cost = ct;
                lambda = (lambda / 3.0).max(1e-12);
                improved = true;
                if relative < 1e-12 {
                    return finish(problem, p, weights, iterations);
                }
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    finish(problem, p, weights, iterations)
}

fn finish(problem: &Problem<'_>, p: Vec<f64>, weights: &[f64], iterations: usize) -> Result<Fit, RigCalibrateError> {
    let j = problem.jacobian(&p, weights);
    let covariance = (j.transpose() * &j).try_inverse();
    if p.iter().any(|v| !v.is_finite()) {
        return Err(RigCalibrateError::Singular);
    }
    Ok(Fit { params: p, iterations, covariance })
}

/// A 2D residual's robust standard deviation per coordinate from the median
/// of its length (`|e|² ~ 2σ² χ²₂/2`, whose median is `2 ln 2 σ²`).
fn robust_sigma(lengths: &[f64]) -> f64 {
    let m = median(lengths);
    m / (2.0 * std::f64::consts::LN_2).sqrt()
}

/// Calibrates the rig from the observed poses (`sizes`: camera and
/// projector `[width, height]`); `skipped` are the poses left out and why.
pub fn solve_rig(
    target: &Target,
    poses: &[RigPoseObservation],
    sizes: [[usize; 2]; 2],
    skipped: &[String],
    options: &RigCalibrationOptions,
    control: &RunControl,
) -> Result<(CameraProjectorCalibration, RigCalibrationReport), RigCalibrateError> {
    target.validate()?;
    if poses.len() < MIN_POSES {
        return Err(RigCalibrateError::TooFewPoses {
            usable: poses.len(),
            required: MIN_POSES,
            skipped: skipped.to_vec(),
        });
    }
    control.begin_stage("closed-form start");
    let points_mm = target.points_mm();
    let plane: Vec<[f64; 2]> = points_mm.iter().map(|p| [p[0], p[1]]).collect();
    let camera_h: Vec<Matrix3<f64>> =
        poses.iter().map(|o| homography(&plane, &o.camera_px)).collect::<Option<Vec<_>>>().ok_or_else(|| {
            RigCalibrateError::NoStart { device: "camera", reason: "a pose's homography is degenerate".into() }
        })?;
    let projector_h: Vec<Option<Matrix3<f64>>> = poses
        .iter()
        .map(|o| {
            let (src, dst): (Vec<[f64; 2]>, Vec<[f64; 2]>) =
                plane.iter().zip(&o.projector_px).filter_map(|(s, d)| d.map(|d| (*s, d))).unzip();
            homography(&src, &dst)
        })
        .collect();
    let centre = |d: usize| [(sizes[d][0] as f64 - 1.0) / 2.0, (sizes[d][1] as f64 - 1.0) / 2.0];
    let k_camera = intrinsics_from_homographies(&camera_h, centre(0))
        .ok_or_else(|| RigCalibrateError::NoStart { device: "camera", reason: "Zhang's closed form failed".into() })?;
    let usable_projector: Vec<Matrix3<f64>> = projector_h.iter().flatten().copied().collect();
    if usable_projector.len() < MIN_POSES {
        return Err(RigCalibrateError::NoStart {
            device: "projector",
            reason: format!("only {} pose(s) have enough decoded target points", usable_projector.len()),
        });
    }
    let k_projector = intrinsics_from_homographies(&usable_projector, centre(1)).ok_or_else(|| {
        RigCalibrateError::NoStart { device: "projector", reason: "Zhang's closed form failed".into() }
    })?;
    let camera_poses: Vec<Pose> =
        camera_h.iter().map(|h| pose_from_homography(h, k_camera)).collect::<Option<Vec<_>>>().ok_or_else(|| {
            RigCalibrateError::NoStart { device: "camera", reason: "a pose could not be recovered".into() }
        })?;
    // R, t from every pose both devices see: X_p = R_p R_cᵀ (X_c − t_c) + t_p.
    let mut rotation_sum = Matrix3::<f64>::zeros();
    let mut translation_sum = Vector3::<f64>::zeros();
    let mut counted = 0.0;
    for (camera_pose, h) in camera_poses.iter().zip(&projector_h) {
        let Some(projector_pose) = h.and_then(|h| pose_from_homography(&h, k_projector)) else { continue };
        let rig = projector_pose.compose(&camera_pose.inverse());
        rotation_sum += Matrix3::from_fn(|i, j| rig.rotation[i][j]);
        translation_sum += Vector3::from(rig.translation_mm);
        counted += 1.0;
    }
    let svd = rotation_sum.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(RigCalibrateError::NoStart { device: "projector", reason: "no relative pose".into() });
    };
    let rig_rotation = u * vt;
    let rig_start = Pose {
        rotation: std::array::from_fn(|i| std::array::from_fn(|j| rig_rotation[(i, j)])),
        translation_mm: (translation_sum / counted).into(),
    };

    let layout = Layout { terms: options.distortion.terms().len(), poses: poses.len() };
    let mut start = vec![0.0; layout.len()];
    for (d, k) in [k_camera, k_projector].into_iter().enumerate() {
        start[layout.device(d)..layout.device(d) + 4].copy_from_slice(&k);
    }
    let put_pose = |p: &mut [f64], o: usize, pose: &Pose| {
        p[o..o + 3].copy_from_slice(&pose.rotation_vector_rad());
        p[o + 3..o + 6].copy_from_slice(&pose.translation_mm);
    };
    put_pose(&mut start, layout.rig(), &rig_start);
    for (k, pose) in camera_poses.iter().enumerate() {
        put_pose(&mut start, layout.pose(k), pose);
    }

    let mut observations = Vec::new();
    for (k, pose) in poses.iter().enumerate() {
        for (point, &observed_px) in pose.camera_px.iter().enumerate() {
            observations.push(Observation { pose: k, point, device: 0, observed_px });
        }
        for (point, observed) in pose.projector_px.iter().enumerate() {
            if let Some(observed_px) = *observed {
                observations.push(Observation { pose: k, point, device: 1, observed_px });
            }
        }
    }

    control.begin_stage("bundle adjustment");
    // First unweighted, then each device weighted by its robust noise with
    // the outliers set aside, twice (the second settles the weights).
    let mut inlier = vec![true; observations.len()];
    let mut sigma = [1.0f64; 2];
    let mut params = start;
    let mut iterations = 0;
    let mut covariance = None;
    for round in 0..3 {
        let kept: Vec<Observation> = observations.iter().zip(&inlier).filter(|(_, k)| **k).map(|(o, _)| *o).collect();
        let weights: Vec<f64> = kept.iter().map(|o| 1.0 / sigma[o.device]).collect();
        let problem = Problem { layout, model: options.distortion, sizes, points_mm: &points_mm, observations: &kept };
        let fit = levenberg_marquardt(&problem, params, &weights, options.max_iterations, control)?;
        params = fit.params;
        iterations += fit.iterations;
        covariance = fit.covariance;
        if round == 2 {
            break;
        }
        let all = Problem { observations: &observations, ..problem };
        let lengths: Vec<f64> = all.errors(&params).iter().map(|e| e[0].hypot(e[1])).collect();
        sigma = [0, 1].map(|d| {
            let own: Vec<f64> = observations
                .iter()
                .zip(&lengths)
                .zip(&inlier)
                .filter(|((o, _), k)| o.device == d && **k)
                .map(|((_, l), _)| *l)
                .collect();
            robust_sigma(&own).max(1e-4)
        });
        for ((o, l), k) in observations.iter().zip(&lengths).zip(inlier.iter_mut()) {
            let limit = options.outlier_threshold_sigma * sigma[o.device] * std::f64::consts::SQRT_2;
            *k = *l <= limit.max(options.min_outlier_threshold_px);
        }
    }

    let full = Problem { layout, model: options.distortion, sizes, points_mm: &points_mm, observations: &observations };
    let errors = full.errors(&params);
    let lengths: Vec<f64> = errors.iter().map(|e| e[0].hypot(e[1])).collect();
    // Weighted residuals have unit variance when the weights are right;
    // scale by the residuals' own variance otherwise.
    let (kept_count, chi2) = observations
        .iter()
        .zip(&lengths)
        .zip(&inlier)
        .filter(|(_, k)| **k)
        .fold((0usize, 0.0), |(n, c), ((o, l), _)| (n + 1, c + (l / sigma[o.device]).powi(2)));
    let variance_factor = chi2 / (2 * kept_count).saturating_sub(full.layout.len()).max(1) as f64;
    let kept_params_sigma = |index: usize| -> f64 {
        covariance.as_ref().map_or(f64::NAN, |c| (c[(index, index)] * variance_factor).sqrt())
    };
    let camera = device_of(&params, &full.layout, options.distortion, 0, sizes[0]);
    let projector = device_of(&params, &full.layout, options.distortion, 1, sizes[1]);
    let rig = pose_at(&params, full.layout.rig());
    let calibration = CameraProjectorCalibration {
        unit: LengthUnit::Mm,
        camera: camera.clone(),
        projector: projector.clone(),
        r: rig.rotation,
        t: rig.translation_mm,
    };

    let stats = |select: &dyn Fn(&Observation) -> bool| -> (usize, usize, f64, f64) {
        let (mut n, mut out, mut sum, mut max) = (0usize, 0usize, 0.0, 0.0f64);
        for ((o, l), k) in observations.iter().zip(&lengths).zip(&inlier) {
            if !select(o) {
                continue;
            }
            if *k {
                n += 1;
                sum += l * l;
                max = max.max(*l);
            } else {
                out += 1;
            }
        }
        (n, out, if n > 0 { (sum / n as f64).sqrt() } else { f64::NAN }, max)
    };
    let devices: Vec<DeviceReport> = [&camera, &projector]
        .into_iter()
        .enumerate()
        .map(|(d, dev)| {
            let (points, outliers, rms, max) = stats(&|o| o.device == d);
            let o = full.layout.device(d);
            DeviceReport {
                device: DEVICE_NAMES[d],
                width: dev.width,
                height: dev.height,
                points,
                outliers,
                rms_reprojection_px: rms,
                max_reprojection_px: max,
                robust_sigma_px: sigma[d],
                fx: dev.fx,
                fy: dev.fy,
                cx: dev.cx,
                cy: dev.cy,
                distortion: dev.distortion,
                sigma_fx_fy_cx_cy_px: std::array::from_fn(|i| kept_params_sigma(o + i)),
            }
        })
        .collect();
    let fitted_poses: Vec<Pose> = (0..poses.len()).map(|k| pose_at(&params, full.layout.pose(k))).collect();
    let normal = |p: &Pose| Vector3::from(p.normal());
    let angle_deg = |a: &Pose, b: &Pose| normal(a).dot(&normal(b)).clamp(-1.0, 1.0).acos().to_degrees();
    let pose_reports: Vec<RigPoseReport> = poses
        .iter()
        .enumerate()
        .map(|(k, pose)| {
            let (camera_points, _, camera_rms_px, _) = stats(&|o| o.pose == k && o.device == 0);
            let (projector_points, _, projector_rms_px, _) = stats(&|o| o.pose == k && o.device == 1);
            RigPoseReport {
                name: pose.name.clone(),
                camera_points,
                projector_points,
                camera_rms_px,
                projector_rms_px,
                tilt_deg: angle_deg(&fitted_poses[k], &fitted_poses[0]),
            }
        })
        .collect();
    let tilt_spread_deg = fitted_poses
        .iter()
        .flat_map(|a| fitted_poses.iter().map(move |b| (a, b)))
        .map(|(a, b)| angle_deg(a, b))
        .fold(0.0, f64::max);
    let centre_of_projector = rig.inverse().translation_mm;
    let baseline_mm = Vector3::from(centre_of_projector).norm();
    let projector_axis = Vector3::new(rig.rotation[2][0], rig.rotation[2][1], rig.rotation[2][2]);
    let triangulation_angle_deg = projector_axis.z.clamp(-1.0, 1.0).acos().to_degrees();
    let rig_offset = full.layout.rig();

    let mut warnings: Vec<Warning> =
        skipped.iter().map(|s| Warning::new(WarningKind::PoseSkipped, s.clone())).collect();
    if poses.len() < RECOMMENDED_POSES {
        warnings.push(Warning::new(
            WarningKind::FewPoses,
            format!(
                "only {} poses are usable; {RECOMMENDED_POSES} or more, tilted in different directions, determine \
                 the camera and the projector reliably",
                poses.len()
            ),
        ));
    }
    if tilt_spread_deg < MIN_TILT_SPREAD_DEG {
        warnings.push(Warning::new(
            WarningKind::SmallTiltSpread,
            format!(
                "the poses tilt at most {tilt_spread_deg:.1} deg against each other: the focal lengths and the \
                 distance are poorly determined; tilt the target by 10 to 30 deg in different directions"
            ),
        ));
    }
    let outliers: usize = devices.iter().map(|d| d.outliers).sum();
    if outliers > 0 {
        warnings.push(Warning::new(
            WarningKind::DetectionOutliers,
            format!(
                "{outliers} of {} target points were set aside as outliers (camera {}, projector {}; farther than \
                 {:.1} robust deviations from their reprojection)",
                observations.len(),
                devices[0].outliers,
                devices[1].outliers,
                options.outlier_threshold_sigma
            ),
        ));
    }
    let report = RigCalibrationReport {
        target: *target,
        distortion_model: options.distortion.name(),
        devices,
        poses: pose_reports,
        skipped_poses: skipped.to_vec(),
        baseline_mm,
        triangulation_angle_deg,
        sigma_rotation_deg: std::array::from_fn(|i| kept_params_sigma(rig_offset + i).to_degrees()),
        sigma_translation_mm: std::array::from_fn(|i| kept_params_sigma(rig_offset + 3 + i)),
        tilt_spread_deg,
        iterations,
        warnings,
    };
    Ok((calibration, report))
}

/// The angle of the rotation between two rotation matrices (for truth
/// comparisons of a fitted rig).
pub fn rotation_angle_deg(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> f64 {
    let m = Matrix3::from_fn(|i, j| (0..3).map(|k| a[i][k] * b[j][k]).sum::<f64>());
    ((m.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::calibration::model::rotation_matrix;
    use crate::engine::calibration::target::TargetKind;

    fn device(width: usize, height: usize, f: f64, k1: f64) -> PinholeDevice {
        PinholeDevice {
            width,
            height,
            fx: f,
            fy: f * 1.001,
            cx: (width as f64 - 1.0) / 2.0 + 7.0,
            cy: (height as f64 - 1.0) / 2.0 - 5.0,
            distortion: [k1, 0.0, 0.0, 0.0, 0.0],
        }
    }

    fn rig() -> CameraProjectorCalibration {
        let r = rotation_matrix([0.0, 20f64.to_radians(), 0.0]);
        CameraProjectorCalibration {
            unit: LengthUnit::Mm,
            camera: device(640, 480, 4000.0, -0.08),
            projector: device(1280, 800, 7100.0, -0.04),
            r,
            t: [68.0, 0.5, 12.0],
        }
    }

    /// Exact observations of a 9 x 11 target in eight poses, 200 mm away.
    fn observations(c: &CameraProjectorCalibration, target: &Target) -> Vec<RigPoseObservation> {
        let rotations = [
            [0.0, 0.0, 0.0],
            [20.0, 0.0, 5.0],
            [-20.0, 0.0, -5.0],
            [0.0, 20.0, 3.0],
            [0.0, -20.0, -3.0],
            [14.0, 14.0, 0.0],
            [-14.0, 14.0, 8.0],
            [14.0, -14.0, -8.0],
        ];
        let projector_pose = Pose { rotation: c.r, translation_mm: c.t };
        rotations
            .iter()
            .enumerate()
            .map(|(k, deg)| {
                let w = deg.map(|d: f64| d.to_radians());
                let half = [5.0 * target.pitch_mm, -4.0 * target.pitch_mm, 0.0];
                let r = rotation_matrix(w);
                let centre = [0.0, 0.0, 200.0 + k as f64];
                let t: [f64; 3] = std::array::from_fn(|i| centre[i] - (0..3).map(|j| r[i][j] * half[j]).sum::<f64>());
                let pose = Pose { rotation: r, translation_mm: t };
                let points = target.points_mm();
                RigPoseObservation {
                    name: format!("pose{k}"),
                    camera_px: points
                        .iter()
                        .map(|&x| {
                            let (u, v) = c.camera.project(pose.apply(x));
                            [u, v]
                        })
                        .collect(),
                    projector_px: points
                        .iter()
                        .map(|&x| {
                            let (u, v) = c.projector.project(projector_pose.apply(pose.apply(x)));
                            Some([u, v])
                        })
                        .collect(),
                }
            })
            .collect()
    }

    #[test]
    fn exact_observations_give_back_the_rig() {
        let truth = rig();
        let target = Target { kind: TargetKind::Circles, rows: 9, cols: 11, pitch_mm: 1.25, dark_on_light: true };
        let obs = observations(&truth, &target);
        let options = RigCalibrationOptions { distortion: DistortionModel::K1, ..Default::default() };
        let (fitted, report) =
            solve_rig(&target, &obs, [[640, 480], [1280, 800]], &[], &options, &RunControl::new()).expect("solves");
        for (a, b) in [(&fitted.camera, &truth.camera), (&fitted.projector, &truth.projector)] {
            assert!((a.fx - b.fx).abs() < 1e-3 * b.fx, "fx {} vs {}", a.fx, b.fx);
            assert!((a.cx - b.cx).abs() < 0.5 && (a.cy - b.cy).abs() < 0.5, "{a:?} vs {b:?}");
            assert!((a.distortion[0] - b.distortion[0]).abs() < 1e-3, "k1 {:?}", a.distortion);
        }
        assert!(rotation_angle_deg(&fitted.r, &truth.r) < 1e-3);
        let dt = (0..3).map(|i| (fitted.t[i] - truth.t[i]).powi(2)).sum::<f64>().sqrt();
        assert!(dt < 1e-2, "t {:?}", fitted.t);
        assert!(report.rms_per_device().iter().all(|r| *r < 1e-4), "{:?}", report.rms_per_device());
        assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    }

    #[test]
    fn a_local_homography_finds_the_projector_point_between_pixels() {
        let (w, h) = (40, 30);
        let hom = Matrix3::new(2.1, 0.1, 100.0, -0.05, 1.9, 50.0, 1e-4, 2e-4, 1.0);
        let map = |axis: usize| ProjectorCoordinate {
            width: w,
            height: h,
            coordinate_px: (0..w * h)
                .map(|i| {
                    // A dark dot in the middle decodes nothing.
                    let (u, v) = ((i % w) as f64, (i / w) as f64);
                    if (u - 20.3).hypot(v - 14.6) < 3.0 { f32::NAN } else { apply(&hom, [u, v])[axis] as f32 }
                })
                .collect(),
            sigma_px: vec![0.1; w * h],
            refusal: vec![None; w * h],
            set_agreement: None,
            ripple: None,
        };
        let (x, y) = (map(0), map(1));
        let at = [20.3, 14.6];
        let found = projector_point_at(&x, &y, at, 10.0).expect("decoded around the dot");
        let truth = apply(&hom, at);
        assert!(distance(found, truth) < 1e-3, "{found:?} vs {truth:?}");
        assert_eq!(projector_point_at(&x, &y, at, 2.5), None, "a window inside the dot has nothing to fit");
    }
}
