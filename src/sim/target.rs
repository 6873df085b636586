//! Images of a calibration target (dot grid or checkerboard) in a known pose,
//! seen through one of the rig's telecentric cameras: the ground truth for
//! calibration.
//!
//! Each observed pixel is traced back through the camera's distortion (one
//! Newton inversion per pixel, then its local Jacobian for the sub-samples)
//! and the affine projection onto the target plane, where the pattern is
//! evaluated exactly. Pixels that straddle an edge are integrated over the
//! pixel area (a box-filter sensor) with the 377 points of a Fibonacci
//! lattice: unlike a square sub-sample grid, which moves an axis-parallel
//! edge in steps of a whole sub-sample row, it places edges of any direction
//! to about 1/377 px, so dots and corners are anti-aliased and their true
//! positions are measurable to well under a hundredth of a pixel. Read noise is Gaussian, drawn from one
//! ChaCha8 stream per (seed, camera, pose, row), then the image is quantised.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::engine::calibration::gray_image::GrayImage;
use crate::engine::calibration::model::Pose;
use crate::engine::calibration::target::{Target, TargetKind};
use crate::engine::camera_model::AffineCamera;

/// Radiometry and printing of the simulated target.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TargetLook {
    /// Grey level of the plate (the light squares of a checkerboard).
    pub plate_dn: f64,
    /// Grey level of the dots (the dark squares).
    pub ink_dn: f64,
    /// Grey level of what lies beyond the plate.
    pub surround_dn: f64,
    /// Dot diameter as a share of the pitch.
    pub dot_diameter_pitch: f64,
    /// Plate border around the outermost points, in pitches.
    pub margin_pitch: f64,
    /// Read noise (standard deviation) in grey levels; 0: noise-free.
    pub noise_sigma_dn: f64,
    /// Largest grey level (255 for 8-bit images).
    pub full_scale_dn: u16,
}

/// Points of the Fibonacci lattice that integrates edge pixels, and its generator.
const EDGE_SAMPLES: usize = 377;
const EDGE_GENERATOR: usize = 233;

impl Default for TargetLook {
    fn default() -> Self {
        Self {
            plate_dn: 200.0,
            ink_dn: 35.0,
            surround_dn: 70.0,
            dot_diameter_pitch: 0.5,
            margin_pitch: 1.0,
            noise_sigma_dn: 0.0,
            full_scale_dn: 255,
        }
    }
}

/// What the target's printed pattern is at one point of its plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Paint {
    Plate,
    Ink,
    Surround,
}

/// The target's pattern in its own plane, with the distance to the nearest
/// edge so smooth pixels need no sub-samples.
pub(crate) struct Pattern<'a> {
    pub(crate) target: &'a Target,
    pub(crate) look: &'a TargetLook,
}

impl Pattern<'_> {
    /// Paint at (x, y) mm and a lower bound of the distance to the nearest edge.
    pub(crate) fn paint(&self, x: f64, y: f64) -> (Paint, f64) {
        let t = self.target;
        let p = t.pitch_mm;
        let margin = self.look.margin_pitch * p;
        // The plate: the grid's extent plus the margin (a checkerboard's
        // squares reach one pitch beyond its inner corners).
        let reach = if t.kind == TargetKind::Checkerboard { p + margin } else { margin };
        let (x0, x1) = (-reach, (t.cols as f64 - 1.0) * p + reach);
        let (y0, y1) = (-((t.rows as f64 - 1.0) * p + reach), reach);
        let to_border = (x - x0).min(x1 - x).min(y - y0).min(y1 - y);
        if to_border < 0.0 {
            return (Paint::Surround, -to_border);
        }
        match t.kind {
            TargetKind::Circles => {
                let j = (x / p).round().clamp(0.0, t.cols as f64 - 1.0);
                let i = (-y / p).round().clamp(0.0, t.rows as f64 - 1.0);
                let d = (x - j * p).hypot(y + i * p);
                let r = 0.5 * self.look.dot_diameter_pitch * p;
                let paint = if d < r { Paint::Ink } else { Paint::Plate };
                (paint, (d - r).abs().min(to_border))
            }
            TargetKind::Checkerboard => {
                let (a, b) = ((x / p).floor(), (-y / p).floor());
                let on_board = a >= -1.0 && a < t.cols as f64 && b >= -1.0 && b < t.rows as f64;
                if !on_board {
                    let (cols, rows) = (t.cols as f64, t.rows as f64);
                    let to_board = (-p - x).max(x - cols * p).max(y - p).max(-rows * p - y).max(0.0);
                    return (Paint::Plate, to_board.min(to_border));
                }
                let to_line = (x - a * p).min((a + 1.0) * p - x).min((-y - b * p).min((b + 1.0) * p + y));
                // The top-left square (a = b = -1) is dark.
                let paint = if (a + b).rem_euclid(2.0) == 0.0 { Paint::Ink } else { Paint::Plate };
                (paint, to_line)
            }
        }
    }
}

/// Seed of the noise stream of one image row.
fn row_seed(seed: u64, camera: usize, pose: usize, row: usize) -> u64 {
    let mut z = seed ^ 0x7a11_ca1b_0000_0000;
    for v in [camera as u64, pose as u64, row as u64] {
        z = (z ^ v).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        z ^= z >> 31;
    }
    z
}

/// Renders `target` in `pose` (target frame -> world) as seen by `camera`.
/// `camera_index` and `pose_index` select the noise streams.
pub fn render_target(
    camera: &AffineCamera,
    target: &Target,
    pose: &Pose,
    look: &TargetLook,
    seed: u64,
    camera_index: usize,
    pose_index: usize,
) -> GrayImage {
    let (w, h) = (camera.width, camera.height);
    // Ideal pixel of target point (x, y): H (x, y) + c.
    let r = &pose.rotation;
    let p = &camera.p;
    let hm = [
        [
            p[0][0] * r[0][0] + p[0][1] * r[1][0] + p[0][2] * r[2][0],
            p[0][0] * r[0][1] + p[0][1] * r[1][1] + p[0][2] * r[2][1],
        ],
        [
            p[1][0] * r[0][0] + p[1][1] * r[1][0] + p[1][2] * r[2][0],
            p[1][0] * r[0][1] + p[1][1] * r[1][1] + p[1][2] * r[2][1],
        ],
    ];
    let c = camera.project(pose.translation_mm);
    let det = hm[0][0] * hm[1][1] - hm[0][1] * hm[1][0];
    let inv = [[hm[1][1] / det, -hm[0][1] / det], [-hm[1][0] / det, hm[0][0] / det]];
    let to_plane = |ideal: [f64; 2]| {
        let (du, dv) = (ideal[0] - c[0], ideal[1] - c[1]);
        [inv[0][0] * du + inv[0][1] * dv, inv[1][0] * du + inv[1][1] * dv]
    };
    // Largest stretch of the inverse map: mm per ideal pixel.
    let frob = (inv[0][0].powi(2) + inv[0][1].powi(2) + inv[1][0].powi(2) + inv[1][1].powi(2)).sqrt();
    let pattern = Pattern { target, look };
    let level = |paint: Paint| match paint {
        Paint::Plate => look.plate_dn,
        Paint::Ink => look.ink_dn,
        Paint::Surround => look.surround_dn,
    };
    let mut pixels = vec![0f32; w * h];
    pixels.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        let mut rng =
            (look.noise_sigma_dn > 0.0).then(|| ChaCha8Rng::seed_from_u64(row_seed(seed, camera_index, pose_index, v)));
        for (u, out) in row.iter_mut().enumerate() {
            let observed = [u as f64, v as f64];
            let ideal = camera.ideal_from_observed(observed);
            // Ideal-pixel offsets of observed sub-pixel offsets: the inverse
            // of the distortion's Jacobian (finite differences; the map is
            // smooth and near the identity).
            let step = 1e-3;
            let du = camera.observed_from_ideal([ideal[0] + step, ideal[1]]);
            let dv = camera.observed_from_ideal([ideal[0], ideal[1] + step]);
            let o = camera.observed_from_ideal(ideal);
            let j = [[(du[0] - o[0]) / step, (dv[0] - o[0]) / step], [(du[1] - o[1]) / step, (dv[1] - o[1]) / step]];
            let jd = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            let jinv = [[j[1][1] / jd, -j[0][1] / jd], [-j[1][0] / jd, j[0][0] / jd]];
            let centre = to_plane(ideal);
            let (paint, clearance) = pattern.paint(centre[0], centre[1]);
            let jnorm = (jinv[0][0].powi(2) + jinv[0][1].powi(2) + jinv[1][0].powi(2) + jinv[1][1].powi(2)).sqrt();
            // The pixel's footprint on the plate lies within this radius.
            let footprint = 0.75 * frob * jnorm;
            let mut value = if clearance > footprint {
                level(paint)
            } else {
                let mut sum = 0.0;
                for k in 0..EDGE_SAMPLES {
                    let ox = (k as f64 + 0.5) / EDGE_SAMPLES as f64 - 0.5;
                    let oy = (((k * EDGE_GENERATOR) % EDGE_SAMPLES) as f64 + 0.5) / EDGE_SAMPLES as f64 - 0.5;
                    let sub =
                        [ideal[0] + jinv[0][0] * ox + jinv[0][1] * oy, ideal[1] + jinv[1][0] * ox + jinv[1][1] * oy];
                    let q = to_plane(sub);
                    sum += level(pattern.paint(q[0], q[1]).0);
                }
                sum / EDGE_SAMPLES as f64
            };
            if let Some(rng) = rng.as_mut() {
                let z: f64 = StandardNormal.sample(rng);
                value += look.noise_sigma_dn * z;
            }
            *out = value.round().clamp(0.0, f64::from(look.full_scale_dn)) as f32;
        }
    });
    GrayImage { width: w, height: h, pixels_dn: pixels }
}

/// Observed pixel of every target point (row-major): where a perfect
/// detector would find them.
pub fn true_points_px(camera: &AffineCamera, target: &Target, pose: &Pose) -> Vec<[f64; 2]> {
    target.points_mm().iter().map(|&x| camera.project_observed(pose.apply(x))).collect()
}

/// Settings of a simulated calibration set.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationTargetConfig {
    pub target: Target,
    /// Poses rendered; pose 0 lies flat on the stage (the world frame of the calibration).
    pub poses: usize,
    /// Tilt of the other poses against the stage (alternately 100 % and 70 % of it).
    pub tilt_deg: f64,
    pub look: TargetLook,
    pub seed: u64,
}

impl CalibrationTargetConfig {
    /// A 9 x 11 target (dots, or a checkerboard's inner corners) whose pitch
    /// makes it about half as high as the field of `camera`, 8 poses tilted by 20 deg.
    pub fn for_field(kind: TargetKind, camera: &AffineCamera) -> Self {
        let (rows, cols) = (9usize, 11usize);
        let field_height_mm = camera.height as f64 / camera.pixels_per_unit();
        let raw = 0.55 * field_height_mm / (rows as f64 + 0.5);
        // A pitch a plate maker would print: 1, 2 or 5 times a power of ten, or a quarter step.
        let decade = 10f64.powf(raw.log10().floor());
        let pitch_mm = [1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0]
            .iter()
            .map(|m| m * decade)
            .rfind(|&p| p <= raw * 1.0001)
            .unwrap_or(decade);
        Self {
            target: Target { kind, rows, cols, pitch_mm, dark_on_light: true },
            poses: 8,
            tilt_deg: 20.0,
            look: TargetLook::default(),
            seed: 1,
        }
    }
}

/// Why a calibration set cannot be simulated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TargetSimError {
    #[error(
        "a {rows} x {cols} target of pitch {pitch_mm} mm does not fit into both cameras' fields even lying flat; use a smaller pitch or fewer points"
    )]
    DoesNotFit { rows: usize, cols: usize, pitch_mm: f64 },
    #[error("{poses} poses asked for; a calibration needs at least 3")]
    TooFewPoses { poses: usize },
    #[error(transparent)]
    Target(#[from] crate::engine::calibration::target::TargetError),
}

/// The truth of a simulated calibration set.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationTargetTruth {
    /// The rig's cameras in the simulator's world.
    pub calibration_world: crate::engine::camera_model::StereoCalibration,
    /// Each pose's target frame in the simulator's world.
    pub poses_world: Vec<Pose>,
    /// The same cameras in the frame a calibration reports: the target frame
    /// of pose 0 (`X_world = pose0 (X_pose0)`).
    pub calibration_pose0: crate::engine::camera_model::StereoCalibration,
    /// True observed pixel of every target point, per pose and camera.
    pub points_px: Vec<[Vec<[f64; 2]>; 2]>,
}

/// A rendered calibration set.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationTargetSet {
    pub config: CalibrationTargetConfig,
    /// Left and right image of each pose.
    pub images: Vec<[GrayImage; 2]>,
    pub truth: CalibrationTargetTruth,
}

/// The cameras `P X` re-expressed in the frame `frame` (`X = frame(x)`): `P' = P [R t; 0 1]`.
pub fn camera_in_frame(camera: &AffineCamera, frame: &Pose) -> AffineCamera {
    let r = &frame.rotation;
    let p = &camera.p;
    let mut out = camera.clone();
    for (out_row, row) in out.p.iter_mut().zip(p) {
        for (col, value) in out_row.iter_mut().take(3).enumerate() {
            *value = (0..3).map(|k| row[k] * r[k][col]).sum();
        }
        out_row[3] = (0..3).map(|k| row[k] * frame.translation_mm[k]).sum::<f64>() + row[3];
    }
    out
}

/// Whether the target (with the part around its points that detection
/// needs) lies inside the image of `camera` in `pose`.
fn fits(camera: &AffineCamera, target: &Target, pose: &Pose) -> bool {
    let p = target.pitch_mm;
    let around = match target.kind {
        TargetKind::Circles => 0.75 * p,
        TargetKind::Checkerboard => 1.25 * p,
    };
    let (x0, x1) = (-around, (target.cols as f64 - 1.0) * p + around);
    let (y0, y1) = (-((target.rows as f64 - 1.0) * p + around), around);
    let margin_px = 4.0;
    (0..=8).all(|a| {
        (0..=8).all(|b| {
            let on_edge = a == 0 || a == 8 || b == 0 || b == 8;
            let x = x0 + (x1 - x0) * a as f64 / 8.0;
            let y = y0 + (y1 - y0) * b as f64 / 8.0;
            let q = camera.project_observed(pose.apply([x, y, 0.0]));
            !on_edge
                || (q[0] >= margin_px
                    && q[1] >= margin_px
                    && q[0] <= camera.width as f64 - 1.0 - margin_px
                    && q[1] <= camera.height as f64 - 1.0 - margin_px)
        })
    })
}

/// The target tilted by `rotation_rad` about its centre, its centre at `centre_mm`.
pub fn centred_pose(target: &Target, rotation_rad: [f64; 3], centre_mm: [f64; 3]) -> Pose {
    let r = Pose::from_rotation_vector(rotation_rad, [0.0; 3]);
    let mid =
        [(target.cols as f64 - 1.0) * target.pitch_mm / 2.0, -(target.rows as f64 - 1.0) * target.pitch_mm / 2.0, 0.0];
    let rm = r.apply(mid);
    Pose { translation_mm: std::array::from_fn(|i| centre_mm[i] - rm[i]), ..r }
}

/// Poses that keep the target inside both images: pose 0 flat on the stage
/// (turned 2 deg in its plane) at the centre of the left camera's field, the
/// others tilted towards directions spread around the circle, shifted away
/// from the centre as far as the fields allow.
pub fn plan_poses(cameras: &[AffineCamera; 2], config: &CalibrationTargetConfig) -> Result<Vec<Pose>, TargetSimError> {
    let target = &config.target;
    target.validate()?;
    if config.poses < 3 {
        return Err(TargetSimError::TooFewPoses { poses: config.poses });
    }
    // The stage point at the centre of the left image.
    let left = &cameras[0];
    let p = &left.p;
    let centre_px = [(left.width as f64 - 1.0) / 2.0 - p[0][3], (left.height as f64 - 1.0) / 2.0 - p[1][3]];
    let det = p[0][0] * p[1][1] - p[0][1] * p[1][0];
    let centre = [
        (p[1][1] * centre_px[0] - p[0][1] * centre_px[1]) / det,
        (-p[1][0] * centre_px[0] + p[0][0] * centre_px[1]) / det,
        0.0,
    ];
    let visible = |pose: &Pose| cameras.iter().all(|c| fits(c, target, pose));
    let flat = centred_pose(target, [0.0, 0.0, 2f64.to_radians()], centre);
    if !visible(&flat) {
        return Err(TargetSimError::DoesNotFit { rows: target.rows, cols: target.cols, pitch_mm: target.pitch_mm });
    }
    let field_mm = left.width.min(left.height) as f64 / left.pixels_per_unit();
    let mut poses = vec![flat];
    let others = config.poses - 1;
    for k in 0..others {
        let azimuth = std::f64::consts::TAU * k as f64 / others as f64 + 0.3;
        let mut tilt = config.tilt_deg.to_radians() * if k % 2 == 0 { 1.0 } else { 0.7 };
        let spin = (if k % 2 == 0 { 4.0f64 } else { -3.0 }).to_radians();
        let (s, c) = azimuth.sin_cos();
        // Shift across the tilt axis, and up or down a little.
        let shift = [-s * 0.4 * field_mm, c * 0.4 * field_mm, 0.3 * (2.0 * azimuth).sin()];
        let mut chosen = None;
        'search: for _ in 0..12 {
            for step in 0..=10 {
                let f = 1.0 - step as f64 / 10.0;
                let centre_k = [centre[0] + f * shift[0], centre[1] + f * shift[1], shift[2]];
                let pose = centred_pose(target, [tilt * c, tilt * s, spin], centre_k);
                if visible(&pose) {
                    chosen = Some(pose);
                    break 'search;
                }
            }
            tilt *= 0.8;
        }
        // Flat at the centre fits (checked above), so the search ends there at worst.
        poses.push(chosen.unwrap_or(flat));
    }
    Ok(poses)
}

/// Renders a calibration set through `cameras` (the rig's, in the
/// simulator's world) with its truth.
pub fn render_calibration_set(
    cameras: &[AffineCamera; 2],
    config: &CalibrationTargetConfig,
) -> Result<CalibrationTargetSet, TargetSimError> {
    let poses = plan_poses(cameras, config)?;
    let images: Vec<[GrayImage; 2]> = poses
        .iter()
        .enumerate()
        .map(|(k, pose)| {
            [0, 1].map(|c| render_target(&cameras[c], &config.target, pose, &config.look, config.seed, c, k))
        })
        .collect();
    let points_px =
        poses.iter().map(|pose| [0, 1].map(|c| true_points_px(&cameras[c], &config.target, pose))).collect();
    let world = crate::engine::camera_model::StereoCalibration {
        unit: crate::engine::length_unit::LengthUnit::Mm,
        left: cameras[0].clone(),
        right: cameras[1].clone(),
        rms_reprojection_px: None,
        scale_uncertainty: None,
    };
    let pose0 = crate::engine::camera_model::StereoCalibration {
        left: camera_in_frame(&cameras[0], &poses[0]),
        right: camera_in_frame(&cameras[1], &poses[0]),
        ..world.clone()
    };
    Ok(CalibrationTargetSet {
        config: *config,
        images,
        truth: CalibrationTargetTruth {
            calibration_world: world,
            poses_world: poses,
            calibration_pose0: pose0,
            points_px,
        },
    })
}

/// The calibration-target counterpart of [`crate::sim::simulate`]: a set of
/// `kind` targets seen through the rig of `config` (image size, bit depth,
/// read noise, seed and lens distortion all as for its fringe scenes), with
/// the default target and poses of [`CalibrationTargetConfig::for_field`].
pub fn simulate_calibration_target(
    config: &crate::sim::SimConfig,
    kind: TargetKind,
) -> Result<CalibrationTargetSet, TargetSimError> {
    let (cameras, target_config) = calibration_target_setup(config, kind);
    render_calibration_set(&cameras, &target_config)
}

/// The rig's cameras and the default target settings that
/// [`simulate_calibration_target`] renders with, for callers that change
/// some of them (the number of poses, the tilt) before rendering.
pub fn calibration_target_setup(
    config: &crate::sim::SimConfig,
    kind: TargetKind,
) -> ([AffineCamera; 2], CalibrationTargetConfig) {
    let rig = crate::sim::Rig::new(&config.rig, config.width, config.height, 0.0);
    let cameras = [rig.left, rig.right];
    let mut target_config = CalibrationTargetConfig::for_field(kind, &cameras[0]);
    // The default look is for 8-bit images; deeper images keep its proportions.
    let full_scale = config.full_scale_dn();
    let scale = f64::from(full_scale) / 255.0;
    let look = &mut target_config.look;
    look.plate_dn *= scale;
    look.ink_dn *= scale;
    look.surround_dn *= scale;
    look.full_scale_dn = full_scale;
    look.noise_sigma_dn = config.noise_sigma_dn;
    target_config.seed = config.seed;
    (cameras, target_config)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::camera_model::Distortion;

    fn camera() -> AffineCamera {
        AffineCamera {
            width: 200,
            height: 160,
            p: [[20.0, 0.0, 5.0, 40.0], [0.0, -20.0, 0.0, 30.0]],
            distortion: Some(Distortion { k1: 1e-3, ..Distortion::for_image(200, 160) }),
        }
    }

    #[test]
    fn dots_are_dark_on_the_plate_and_the_surround_beyond() {
        let target = Target { kind: TargetKind::Circles, rows: 4, cols: 5, pitch_mm: 1.0, dark_on_light: true };
        let cam = camera();
        let img = render_target(&cam, &target, &Pose::IDENTITY, &TargetLook::default(), 1, 0, 0);
        let look = TargetLook::default();
        let at = |p: [f64; 2]| img.get(p[0].round() as usize, p[1].round() as usize);
        let centres = true_points_px(&cam, &target, &Pose::IDENTITY);
        assert_eq!(at(centres[0]), look.ink_dn as f32);
        assert_eq!(at(centres[19]), look.ink_dn as f32);
        // Half a pitch right of a dot: plate; far away: surround.
        let between = cam.project_observed([0.5, 0.0, 0.0]);
        assert_eq!(at(between), look.plate_dn as f32);
        assert_eq!(img.get(190, 150), look.surround_dn as f32);
        // Edge pixels are mixtures.
        assert!(img.pixels_dn.iter().any(|&v| v > 40.0 && v < 190.0 && v != 70.0));
    }

    #[test]
    fn noise_is_reproducible_and_has_the_asked_spread() {
        let target = Target { kind: TargetKind::Checkerboard, rows: 3, cols: 4, pitch_mm: 1.0, dark_on_light: true };
        let cam = AffineCamera { distortion: None, ..camera() };
        let look = TargetLook { noise_sigma_dn: 2.0, plate_dn: 100.0, surround_dn: 100.0, ..TargetLook::default() };
        let a = render_target(&cam, &target, &Pose::IDENTITY, &look, 7, 1, 2);
        let b = render_target(&cam, &target, &Pose::IDENTITY, &look, 7, 1, 2);
        assert_eq!(a, b);
        // Far from the board the level is flat 100 plus noise.
        let flat: Vec<f64> =
            (0..40).flat_map(|v| (150..200).map(move |u| (u, v))).map(|(u, v)| f64::from(a.get(u, v))).collect();
        let mean = flat.iter().sum::<f64>() / flat.len() as f64;
        let sd = (flat.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / flat.len() as f64).sqrt();
        assert!((mean - 100.0).abs() < 0.2 && (sd - 2.0).abs() < 0.2, "mean {mean} sd {sd}");
    }
}
