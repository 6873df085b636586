//! Pinhole geometry of a camera–projector rig (issue 52): the camera and
//! the projector (an inverse camera) in OpenCV's conventions (x right,
//! y down, z forward; pixel centres at integer coordinates; Brown–Conrady
//! distortion `k1, k2, p1, p2, k3`), `X_p = R X_c + t` from the camera's
//! frame to the projector's, and the 3D point of a camera pixel from its
//! absolute projector coordinate: the camera ray meets the projector's
//! column plane, or, with the row too, the projector ray (least squares).
//! The telecentric pair's geometry is `camera_model`; the phase stages
//! before this are shared.

use rayon::prelude::*;

use super::length_unit::LengthUnit;
use super::point_cloud::PointCloud;
use super::projector_coordinate::ProjectorCoordinate;

/// One pinhole device: its image size, intrinsics and distortion.
#[derive(Clone, Debug, PartialEq)]
pub struct PinholeDevice {
    pub width: usize,
    pub height: usize,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// `k1, k2, p1, p2, k3` (OpenCV's order).
    pub distortion: [f64; 5],
}

impl PinholeDevice {
    /// Ideal normalised coordinates to distorted ones (OpenCV's model).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// The pixel a point `(X, Y, Z)` of the device's frame images to.
    pub fn project(&self, p: [f64; 3]) -> (f64, f64) {
        let (x, y) = self.distort(p[0] / p[2], p[1] / p[2]);
        (self.fx * x + self.cx, self.fy * y + self.cy)
    }

    /// The ideal normalised coordinates of a pixel: the distortion inverted
    /// by fixed-point iteration (as OpenCV's `undistortPoints`), which
    /// converges for the distortion of real lenses within their image.
    pub fn undistort(&self, u: f64, v: f64) -> (f64, f64) {
        let (xd, yd) = ((u - self.cx) / self.fx, (v - self.cy) / self.fy);
        if self.distortion == [0.0; 5] {
            return (xd, yd);
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (dx, dy) = self.distort(x, y);
            let (ex, ey) = (dx - xd, dy - yd);
            x -= ex;
            y -= ey;
            if ex.abs().max(ey.abs()) < 1e-14 {
                break;
            }
        }
        (x, y)
    }
}

/// A calibrated camera–projector rig.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraProjectorCalibration {
    pub unit: LengthUnit,
    pub camera: PinholeDevice,
    pub projector: PinholeDevice,
    /// `X_p = R X_c + t`.
    pub r: [[f64; 3]; 3],
    pub t: [f64; 3],
}

fn mul(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
}

fn mul_transposed(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2])
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl CameraProjectorCalibration {
    /// The projector point's frame coordinates of a camera-frame point.
    pub fn to_projector(&self, p: [f64; 3]) -> [f64; 3] {
        let q = mul(&self.r, p);
        [q[0] + self.t[0], q[1] + self.t[1], q[2] + self.t[2]]
    }

    /// The point (camera frame) where the ray of camera pixel `(u, v)` meets
    /// the plane of projector column `u_p`. Without projector distortion the
    /// column is a plane through the projector's centre; with it, the
    /// column is undistorted at the row the point projects to, iterated.
    pub fn triangulate_column(&self, u: f64, v: f64, u_p: f64) -> Option<[f64; 3]> {
        self.column_on_ray(self.camera_ray(u, v), u_p)
    }

    /// The ray `(x, y, 1)` of camera pixel `(u, v)`, undistorted: computed
    /// once per pixel, whatever the projector coordinates it is met with.
    pub fn camera_ray(&self, u: f64, v: f64) -> [f64; 3] {
        let (x, y) = self.camera.undistort(u, v);
        [x, y, 1.0]
    }

    fn column_on_ray(&self, ray: [f64; 3], u_p: f64) -> Option<[f64; 3]> {
        let ray_p = mul(&self.r, ray);
        let mut v_p = self.projector.cy;
        let mut point = None;
        for _ in 0..8 {
            let (x_p, _) = self.projector.undistort(u_p, v_p);
            // Plane x = x_p z in the projector's frame: n = (1, 0, -x_p).
            let n = [1.0, 0.0, -x_p];
            let denominator = dot(n, ray_p);
            if denominator.abs() < 1e-12 {
                return None;
            }
            let s = -dot(n, self.t) / denominator;
            if !(s > 0.0) {
                return None;
            }
            let p = [s * ray[0], s * ray[1], s];
            let q = self.to_projector(p);
            if !(q[2] > 0.0) {
                return None;
            }
            let previous = v_p;
            v_p = self.projector.project(q).1;
            point = Some(p);
            if self.projector.distortion == [0.0; 5] || (v_p - previous).abs() < 1e-6 {
                break;
            }
        }
        point
    }

    /// The point (camera frame) nearest both the camera ray of `(u, v)` and
    /// the projector ray of `(u_p, v_p)`: the midpoint of their common
    /// perpendicular.
    pub fn triangulate_point(&self, u: f64, v: f64, u_p: f64, v_p: f64) -> Option<[f64; 3]> {
        self.point_on_ray(self.camera_ray(u, v), u_p, v_p)
    }

    fn point_on_ray(&self, d1: [f64; 3], u_p: f64, v_p: f64) -> Option<[f64; 3]> {
        let (xp, yp) = self.projector.undistort(u_p, v_p);
        // The projector's centre and ray in the camera's frame.
        let c2 = mul_transposed(&self.r, [-self.t[0], -self.t[1], -self.t[2]]);
        let d2 = mul_transposed(&self.r, [xp, yp, 1.0]);
        let (a, b, c) = (dot(d1, d1), dot(d1, d2), dot(d2, d2));
        let (d, e) = (dot(d1, c2), dot(d2, c2));
        let det = a * c - b * b;
        if det.abs() < 1e-12 * a * c {
            return None;
        }
        let s1 = (c * d - b * e) / det;
        let s2 = (b * d - a * e) / det;
        if !(s1 > 0.0 && s2 > 0.0) {
            return None;
        }
        Some(std::array::from_fn(|i| 0.5 * (s1 * d1[i] + c2[i] + s2 * d2[i])))
    }
}

/// The cloud of a camera–projector rig: one point per camera pixel with a
/// projector x (and, where given, y), in the camera's frame, `u, v` the
/// camera pixel, `sigma_z` the depth's standard deviation propagated from
/// the projector coordinates' (a finite difference of the triangulation).
pub fn reconstruct(
    calibration: &CameraProjectorCalibration,
    x: &ProjectorCoordinate,
    y: Option<&ProjectorCoordinate>,
    intensity_dn: Option<&[f32]>,
) -> PointCloud {
    let (w, h) = (x.width, x.height);
    let points: Vec<Option<([f64; 3], f32)>> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let u_p = f64::from(x.coordinate_px[i]);
            if u_p.is_nan() {
                return None;
            }
            let ray = calibration.camera_ray((i % w) as f64, (i / w) as f64);
            let sigma_x = f64::from(x.sigma_px[i]);
            let row = y.map(|y| (f64::from(y.coordinate_px[i]), f64::from(y.sigma_px[i])));
            match row {
                Some((v_p, sigma_y)) if !v_p.is_nan() => {
                    let p = calibration.point_on_ray(ray, u_p, v_p)?;
                    let dz_x = calibration.point_on_ray(ray, u_p + 0.5, v_p).map(|q| 2.0 * (q[2] - p[2]));
                    let dz_y = calibration.point_on_ray(ray, u_p, v_p + 0.5).map(|q| 2.0 * (q[2] - p[2]));
                    let sigma =
                        ((dz_x.unwrap_or(0.0) * sigma_x).powi(2) + (dz_y.unwrap_or(0.0) * sigma_y).powi(2)).sqrt();
                    Some((p, sigma as f32))
                }
                _ => {
                    let p = calibration.column_on_ray(ray, u_p)?;
                    let dz = calibration.column_on_ray(ray, u_p + 0.5).map(|q| 2.0 * (q[2] - p[2]));
                    Some((p, (dz.unwrap_or(0.0) * sigma_x).abs() as f32))
                }
            }
        })
        .collect();
    let mut cloud = PointCloud { unit: calibration.unit, grid_width: w, grid_height: h, ..PointCloud::default() };
    let n = points.iter().flatten().count();
    cloud.reserve(n);
    for (i, (p, sigma)) in points.into_iter().enumerate().filter_map(|(i, p)| p.map(|p| (i, p))) {
        cloud.xyz.push(p);
        cloud.pixel_uv.push([(i % w) as f32, (i / w) as f32]);
        cloud.source_set.push(0);
        cloud.source_period_px.push(f32::NAN);
        cloud.modulation_dn.push(f32::NAN);
        cloud.sigma_z.push(sigma);
        cloud.intensity_dn.push(intensity_dn.map_or(f32::NAN, |t| t[i]));
        cloud.order_evidence.push(0);
    }
    cloud
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig(distortion: [f64; 5]) -> CameraProjectorCalibration {
        let (s, c) = (0.25f64.sin(), 0.25f64.cos());
        CameraProjectorCalibration {
            unit: LengthUnit::Mm,
            camera: PinholeDevice { width: 640, height: 480, fx: 800.0, fy: 805.0, cx: 319.5, cy: 239.5, distortion },
            projector: PinholeDevice {
                width: 800,
                height: 600,
                fx: 1200.0,
                fy: 1200.0,
                cx: 399.5,
                cy: 299.5,
                distortion: [-0.5 * distortion[0], distortion[1], 0.0, 0.0, 0.0],
            },
            r: [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]],
            t: [-120.0, 5.0, 30.0],
        }
    }

    #[test]
    fn undistortion_inverts_the_distortion() {
        let device = rig([-0.2, 0.08, 0.001, -0.002, 0.01]).camera;
        for (u, v) in [(0.0, 0.0), (639.0, 479.0), (320.0, 10.0), (17.0, 400.0)] {
            let (x, y) = device.undistort(u, v);
            let (xd, yd) = device.distort(x, y);
            let (u2, v2) = (device.fx * xd + device.cx, device.fy * yd + device.cy);
            assert!((u2 - u).abs() < 1e-9 && (v2 - v).abs() < 1e-9, "({u}, {v}) -> ({u2}, {v2})");
        }
    }

    /// A point seen by both devices comes back from its two pixels, by the
    /// column plane and by the two rays, with and without distortion.
    #[test]
    fn triangulation_recovers_the_point_a_pixel_and_its_projector_coordinate_see() {
        for distortion in [[0.0; 5], [-0.2, 0.08, 0.001, -0.002, 0.01]] {
            let cal = rig(distortion);
            for p in [[0.0, 0.0, 400.0], [-60.0, 40.0, 350.0], [50.0, -30.0, 520.0]] {
                let (u, v) = cal.camera.project(p);
                let (u_p, v_p) = cal.projector.project(cal.to_projector(p));
                let by_column = cal.triangulate_column(u, v, u_p).expect("a point");
                let by_rays = cal.triangulate_point(u, v, u_p, v_p).expect("a point");
                for q in [by_column, by_rays] {
                    let error = (0..3).map(|i| (q[i] - p[i]).powi(2)).sum::<f64>().sqrt();
                    assert!(error < 1e-6, "{p:?} -> {q:?} ({distortion:?})");
                }
            }
        }
    }
}
