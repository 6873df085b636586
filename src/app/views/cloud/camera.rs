//! Orbit-camera maths of the 3D cloud view, with no GUI types: where the eye
//! is, the view and projection matrices (wgpu clip space, depth 0..1), where a
//! scene point lands on screen, the ray through a screen position (picking),
//! and the operator's gestures (orbit, pan, zoom towards the cursor, presets).
//!
//! The camera works in *scene space*: the cloud's coordinates relative to its
//! centre, with Z multiplied by the exaggeration factor (heights are
//! micrometres over millimetres, so a true-scale view of a flat part is flat).
//! Scene Z is up; the camera orbits about `target` at `distance`, at an
//! azimuth `yaw_rad` about Z and an elevation `pitch_rad` above the X-Y plane.
//! Screen coordinates are in a [`Viewport`], x to the right, y down.

use nalgebra::{Matrix4, Point3, Vector3, Vector4};

/// Vertical field of view of the perspective projection; the orthographic one
/// shows the same extent at the target, so switching keeps the framing.
pub const FOV_Y_RAD: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// Orbit speed of a mouse drag.
pub const ORBIT_RAD_PER_PX: f64 = 0.008;
/// Zoom limits, as multiples of the scene radius.
const MIN_DISTANCE_RADII: f64 = 1e-3;
const MAX_DISTANCE_RADII: f64 = 200.0;
/// Elevation limit: a hair short of the poles keeps the basis continuous.
const MAX_PITCH_RAD: f64 = std::f64::consts::FRAC_PI_2;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Projection {
    #[default]
    Perspective,
    Orthographic,
}

impl Projection {
    pub fn name(self) -> &'static str {
        match self {
            Projection::Perspective => "Perspective",
            Projection::Orthographic => "Orthographic",
        }
    }
}

/// The standard views.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewPreset {
    /// Looking down -Z: X to the right, Y up (the layout of a height map).
    Top,
    /// Looking along +Y: X to the right, Z up.
    Front,
    /// Looking along -X: Y to the right, Z up.
    Side,
    /// From the front-right and above, the usual first look at a part.
    Oblique,
}

impl ViewPreset {
    pub const ALL: [ViewPreset; 4] = [ViewPreset::Top, ViewPreset::Front, ViewPreset::Side, ViewPreset::Oblique];

    pub fn name(self) -> &'static str {
        match self {
            ViewPreset::Top => "Top",
            ViewPreset::Front => "Front",
            ViewPreset::Side => "Side",
            ViewPreset::Oblique => "Oblique",
        }
    }

    /// Azimuth and elevation of the eye direction (from target to eye).
    pub fn angles_rad(self) -> (f64, f64) {
        let deg = f64::to_radians;
        match self {
            ViewPreset::Top => (deg(-90.0), MAX_PITCH_RAD),
            ViewPreset::Front => (deg(-90.0), 0.0),
            ViewPreset::Side => (0.0, 0.0),
            ViewPreset::Oblique => (deg(-60.0), deg(35.0)),
        }
    }
}

/// A screen area: top-left corner and size, in the caller's units (egui points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Viewport {
    pub min: [f64; 2],
    pub size: [f64; 2],
}

impl Viewport {
    pub fn new(min: [f64; 2], size: [f64; 2]) -> Self {
        Self { min, size: [size[0].max(1.0), size[1].max(1.0)] }
    }

    pub fn aspect(&self) -> f64 {
        self.size[0] / self.size[1]
    }

    /// Normalized device coordinates (-1..1, y up) of a screen position.
    pub fn ndc_at(&self, pos: [f64; 2]) -> [f64; 2] {
        [2.0 * (pos[0] - self.min[0]) / self.size[0] - 1.0, 1.0 - 2.0 * (pos[1] - self.min[1]) / self.size[1]]
    }

    /// Screen position of normalized device coordinates.
    pub fn screen_at(&self, ndc: [f64; 2]) -> [f64; 2] {
        [self.min[0] + (ndc[0] + 1.0) * 0.5 * self.size[0], self.min[1] + (1.0 - ndc[1]) * 0.5 * self.size[1]]
    }
}

/// Where a scene point lands on screen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenPoint {
    pub pos: [f64; 2],
    /// Distance in front of the eye along the viewing direction (scene units).
    pub depth: f64,
}

/// A half-line in scene space (`dir` has unit length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Point3<f64>,
    pub dir: Vector3<f64>,
}

impl Ray {
    /// Distance from `p` to the ray's line.
    pub fn distance_to(&self, p: &Point3<f64>) -> f64 {
        let v = p - self.origin;
        (v - self.dir * v.dot(&self.dir)).norm()
    }
}

/// The eye of the 3D view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// The point orbited about (scene space).
    pub target: Point3<f64>,
    /// Azimuth of the eye about +Z, from +X.
    pub yaw_rad: f64,
    /// Elevation of the eye above the X-Y plane, in [-90°, 90°].
    pub pitch_rad: f64,
    /// Eye to target (perspective); sets the extent shown (both projections).
    pub distance: f64,
    pub projection: Projection,
    /// Bounding sphere of the scene, for the clip planes.
    pub scene_center: Point3<f64>,
    pub scene_radius: f64,
}

impl OrbitCamera {
    /// A camera at `preset` framing the box `[lo, hi]` (scene space) in a
    /// viewport of `aspect` (width / height).
    pub fn framing(lo: [f64; 3], hi: [f64; 3], preset: ViewPreset, projection: Projection, aspect: f64) -> Self {
        let center = Point3::from(std::array::from_fn(|i| (lo[i] + hi[i]) / 2.0));
        let half = Vector3::from(std::array::from_fn(|i| ((hi[i] - lo[i]) / 2.0).abs()));
        let radius = half.norm().max(1e-9);
        let mut camera = Self {
            target: center,
            yaw_rad: 0.0,
            pitch_rad: 0.0,
            distance: radius,
            projection,
            scene_center: center,
            scene_radius: radius,
        };
        camera.look_from(preset);
        camera.fit_box(&half, aspect);
        camera
    }

    /// Turns the eye to `preset` about the current target.
    pub fn look_from(&mut self, preset: ViewPreset) {
        (self.yaw_rad, self.pitch_rad) = preset.angles_rad();
    }

    /// Sets the distance so the box of half-extents `half` about the target
    /// fills the viewport (with a small margin), whatever the orientation:
    /// every corner at lateral offsets (x, y) and depth offset z from the
    /// target must satisfy |x| <= (d + z) tan(fov/2) aspect and |y| <= (d + z) tan(fov/2).
    pub fn fit_box(&mut self, half: &Vector3<f64>, aspect: f64) {
        const MARGIN: f64 = 1.05;
        let (right, up, forward) = self.basis();
        let tan = (FOV_Y_RAD / 2.0).tan();
        let aspect = aspect.max(1e-6);
        let mut perspective: f64 = 0.0;
        let mut orthographic: f64 = 0.0;
        for corner in 0..8 {
            let sign = |bit: usize| if corner & bit == 0 { -1.0 } else { 1.0 };
            let c = Vector3::new(sign(1) * half.x, sign(2) * half.y, sign(4) * half.z);
            let (x, y, z) = (c.dot(&right).abs() * MARGIN, c.dot(&up).abs() * MARGIN, c.dot(&forward));
            let half_h = (x / aspect).max(y);
            perspective = perspective.max(half_h / tan - z);
            orthographic = orthographic.max(half_h / tan);
        }
        self.distance = match self.projection {
            Projection::Perspective => perspective,
            Projection::Orthographic => orthographic,
        }
        .max(self.scene_radius * MIN_DISTANCE_RADII);
    }

    /// Unit direction from the target to the eye.
    pub fn eye_direction(&self) -> Vector3<f64> {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        Vector3::new(cp * cy, cp * sy, sp)
    }

    /// Screen right, screen up and viewing direction, orthonormal and
    /// right-handed (right x up = -forward); continuous through the poles.
    pub fn basis(&self) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let right = Vector3::new(-sy, cy, 0.0);
        let forward = -self.eye_direction();
        let up = right.cross(&forward);
        (right, up, forward)
    }

    /// How far the eye sits from the target. Perspective: `distance`. An
    /// orthographic eye only needs to be outside the scene, so it is moved back
    /// far enough that every point has a positive depth.
    pub fn eye_distance(&self) -> f64 {
        match self.projection {
            Projection::Perspective => self.distance,
            Projection::Orthographic => {
                self.distance.max((self.target - self.scene_center).norm() + 2.0 * self.scene_radius)
            }
        }
    }

    pub fn eye(&self) -> Point3<f64> {
        self.target + self.eye_direction() * self.eye_distance()
    }

    /// Half height of the view at the target (scene units).
    pub fn half_height_at_target(&self) -> f64 {
        self.distance * (FOV_Y_RAD / 2.0).tan()
    }

    /// Scene units per screen unit at `depth` in front of the eye, for a viewport `height` high.
    pub fn scene_per_screen(&self, depth: f64, height: f64) -> f64 {
        let half = match self.projection {
            Projection::Perspective => depth * (FOV_Y_RAD / 2.0).tan(),
            Projection::Orthographic => self.half_height_at_target(),
        };
        2.0 * half / height.max(1.0)
    }

    /// Near and far clip depths enclosing the scene sphere.
    pub fn near_far(&self) -> (f64, f64) {
        let (_, _, forward) = self.basis();
        let center_depth = (self.scene_center - self.eye()).dot(&forward);
        let r = self.scene_radius * 1.05;
        let far = (center_depth + r).max(self.scene_radius * 1e-3);
        let near = match self.projection {
            Projection::Perspective => (center_depth - r).max(far * 1e-4),
            Projection::Orthographic => center_depth - r,
        };
        (near, far)
    }

    /// World-to-eye matrix: x right, y up, looking down -z.
    pub fn view_matrix(&self) -> Matrix4<f64> {
        let (right, up, forward) = self.basis();
        let eye = self.eye().coords;
        let back = -forward;
        #[rustfmt::skip]
        let m = Matrix4::new(
            right.x, right.y, right.z, -right.dot(&eye),
            up.x, up.y, up.z, -up.dot(&eye),
            back.x, back.y, back.z, -back.dot(&eye),
            0.0, 0.0, 0.0, 1.0,
        );
        m
    }

    /// Eye-to-clip matrix for wgpu (depth 0 at the near plane, 1 at the far one).
    pub fn projection_matrix(&self, aspect: f64) -> Matrix4<f64> {
        let (near, far) = self.near_far();
        let aspect = aspect.max(1e-6);
        match self.projection {
            Projection::Perspective => {
                let f = 1.0 / (FOV_Y_RAD / 2.0).tan();
                #[rustfmt::skip]
                let m = Matrix4::new(
                    f / aspect, 0.0, 0.0, 0.0,
                    0.0, f, 0.0, 0.0,
                    0.0, 0.0, far / (near - far), near * far / (near - far),
                    0.0, 0.0, -1.0, 0.0,
                );
                m
            }
            Projection::Orthographic => {
                let half_h = self.half_height_at_target().max(1e-12);
                let half_w = half_h * aspect;
                #[rustfmt::skip]
                let m = Matrix4::new(
                    1.0 / half_w, 0.0, 0.0, 0.0,
                    0.0, 1.0 / half_h, 0.0, 0.0,
                    0.0, 0.0, 1.0 / (near - far), near / (near - far),
                    0.0, 0.0, 0.0, 1.0,
                );
                m
            }
        }
    }

    pub fn view_projection(&self, aspect: f64) -> Matrix4<f64> {
        self.projection_matrix(aspect) * self.view_matrix()
    }

    /// Where `p` (scene space) lands in `viewport`; `None` behind the eye.
    pub fn project(&self, p: &Point3<f64>, viewport: &Viewport) -> Option<ScreenPoint> {
        let clip = self.view_projection(viewport.aspect()) * Vector4::new(p.x, p.y, p.z, 1.0);
        if !(clip.w > 0.0) {
            return None;
        }
        let (_, _, forward) = self.basis();
        let depth = (p - self.eye()).dot(&forward);
        Some(ScreenPoint { pos: viewport.screen_at([clip.x / clip.w, clip.y / clip.w]), depth })
    }

    /// The ray of scene points that land on screen position `pos`.
    pub fn ray_through(&self, pos: [f64; 2], viewport: &Viewport) -> Ray {
        let [x, y] = viewport.ndc_at(pos);
        let (right, up, forward) = self.basis();
        let eye = self.eye();
        let tan = (FOV_Y_RAD / 2.0).tan();
        match self.projection {
            Projection::Perspective => {
                let dir = forward + right * (x * tan * viewport.aspect()) + up * (y * tan);
                Ray { origin: eye, dir: dir.normalize() }
            }
            Projection::Orthographic => {
                let half_h = self.half_height_at_target();
                let origin = eye + right * (x * half_h * viewport.aspect()) + up * (y * half_h);
                Ray { origin, dir: forward }
            }
        }
    }

    /// The point at screen `pos` on the plane through the target facing the eye.
    pub fn point_on_target_plane(&self, pos: [f64; 2], viewport: &Viewport) -> Point3<f64> {
        let ray = self.ray_through(pos, viewport);
        let (_, _, forward) = self.basis();
        let t = (self.target - ray.origin).dot(&forward) / ray.dir.dot(&forward).max(1e-12);
        ray.origin + ray.dir * t
    }

    /// Turns the eye about the target by a drag of `(dx, dy)` screen units:
    /// right drags turn the scene to the right, down drags tilt it towards the eye.
    pub fn orbit(&mut self, dx: f64, dy: f64) {
        self.yaw_rad = (self.yaw_rad - dx * ORBIT_RAD_PER_PX).rem_euclid(std::f64::consts::TAU);
        self.pitch_rad = (self.pitch_rad + dy * ORBIT_RAD_PER_PX).clamp(-MAX_PITCH_RAD, MAX_PITCH_RAD);
    }

    /// Moves the target so the scene follows a drag of `(dx, dy)` screen units.
    pub fn pan(&mut self, dx: f64, dy: f64, viewport: &Viewport) {
        let (right, up, _) = self.basis();
        let per_unit = self.scene_per_screen(self.distance, viewport.size[1]);
        self.target += (-right * dx + up * dy) * per_unit;
    }

    /// Scales the distance by `factor` (< 1 zooms in) keeping the scene point
    /// under `cursor` (on the target plane) where it is on screen.
    pub fn zoom_towards(&mut self, factor: f64, cursor: [f64; 2], viewport: &Viewport) {
        let limits = (self.scene_radius * MIN_DISTANCE_RADII, self.scene_radius * MAX_DISTANCE_RADII);
        let new_distance = (self.distance * factor).clamp(limits.0, limits.1);
        let factor = new_distance / self.distance;
        let anchor = self.point_on_target_plane(cursor, viewport);
        self.target = anchor + (self.target - anchor) * factor;
        self.distance = new_distance;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const VIEWPORT: Viewport = Viewport { min: [10.0, 20.0], size: [400.0, 300.0] };

    /// A 20 x 10 mm part with 0.5 mm of relief, as a scene box about the origin.
    fn camera(preset: ViewPreset, projection: Projection) -> OrbitCamera {
        OrbitCamera::framing([-10.0, -5.0, -0.25], [10.0, 5.0, 0.25], preset, projection, VIEWPORT.aspect())
    }

    fn close(a: [f64; 2], b: [f64; 2], tol: f64) -> bool {
        (a[0] - b[0]).abs() <= tol && (a[1] - b[1]).abs() <= tol
    }

    fn centre() -> [f64; 2] {
        [VIEWPORT.min[0] + VIEWPORT.size[0] / 2.0, VIEWPORT.min[1] + VIEWPORT.size[1] / 2.0]
    }

    #[test]
    fn the_basis_is_orthonormal_and_right_handed_everywhere() {
        for yaw in [-3.0, -1.0, 0.0, 0.5, 2.0] {
            for pitch in [-MAX_PITCH_RAD, -0.7, 0.0, 0.3, MAX_PITCH_RAD] {
                let c =
                    OrbitCamera { yaw_rad: yaw, pitch_rad: pitch, ..camera(ViewPreset::Top, Projection::Perspective) };
                let (r, u, f) = c.basis();
                for (a, b) in [(r, u), (u, f), (f, r)] {
                    assert!(a.dot(&b).abs() < 1e-12);
                }
                for v in [r, u, f] {
                    assert!((v.norm() - 1.0).abs() < 1e-12);
                }
                assert!((r.cross(&u) + f).norm() < 1e-12, "right x up = -forward");
            }
        }
    }

    #[test]
    fn the_top_preset_looks_down_with_x_right_and_y_up() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let c = camera(ViewPreset::Top, projection);
            let at = |x, y, z| c.project(&Point3::new(x, y, z), &VIEWPORT).expect("in front").pos;
            assert!(close(at(0.0, 0.0, 0.0), centre(), 1e-9), "the target is at the centre");
            let (o, px, py) = (at(0.0, 0.0, 0.0), at(5.0, 0.0, 0.0), at(0.0, 3.0, 0.0));
            assert!(px[0] > o[0] + 10.0 && (px[1] - o[1]).abs() < 1e-9, "+X goes right: {o:?} {px:?}");
            assert!(py[1] < o[1] - 10.0 && (py[0] - o[0]).abs() < 1e-9, "+Y goes up: {o:?} {py:?}");
            // Higher points are nearer the eye.
            let low = c.project(&Point3::new(1.0, 1.0, -0.2), &VIEWPORT).expect("in front").depth;
            let high = c.project(&Point3::new(1.0, 1.0, 0.2), &VIEWPORT).expect("in front").depth;
            assert!((low - high - 0.4).abs() < 1e-9, "{low} {high}");
        }
    }

    #[test]
    fn front_and_side_presets_put_z_up() {
        for (preset, axis) in [(ViewPreset::Front, [1.0, 0.0, 0.0]), (ViewPreset::Side, [0.0, 1.0, 0.0])] {
            let c = camera(preset, Projection::Orthographic);
            let at = |p: [f64; 3]| c.project(&Point3::from(p), &VIEWPORT).expect("in front").pos;
            let (o, right, up) = (at([0.0; 3]), at(axis), at([0.0, 0.0, 0.2]));
            assert!(right[0] > o[0] && (right[1] - o[1]).abs() < 1e-9, "{preset:?}: {o:?} {right:?}");
            assert!(up[1] < o[1] && (up[0] - o[0]).abs() < 1e-9, "{preset:?}: Z up");
        }
    }

    #[test]
    fn orthographic_projection_is_linear_with_the_expected_scale() {
        let c = camera(ViewPreset::Top, Projection::Orthographic);
        // Half height at the target covers half the viewport height.
        let h = c.half_height_at_target();
        let p = c.project(&Point3::new(0.0, h, 0.0), &VIEWPORT).expect("in front").pos;
        assert!(close(p, [centre()[0], VIEWPORT.min[1]], 1e-9), "{p:?}");
        let q = c.project(&Point3::new(h * VIEWPORT.aspect(), 0.0, 0.3), &VIEWPORT).expect("in front").pos;
        assert!(close(q, [VIEWPORT.min[0] + VIEWPORT.size[0], centre()[1]], 1e-9), "{q:?}");
    }

    #[test]
    fn perspective_shrinks_with_depth() {
        let c = camera(ViewPreset::Front, Projection::Perspective);
        // Two equal segments along X, one nearer the eye (front view looks along +Y).
        let len = |y: f64| {
            let a = c.project(&Point3::new(0.0, y, 0.0), &VIEWPORT).expect("front").pos;
            let b = c.project(&Point3::new(1.0, y, 0.0), &VIEWPORT).expect("front").pos;
            b[0] - a[0]
        };
        assert!(len(-2.0) > len(2.0) * 1.05);
        // Pinhole model: screen length * depth is constant.
        let d = |y: f64| c.project(&Point3::new(0.0, y, 0.0), &VIEWPORT).expect("front").depth;
        assert!((len(-2.0) * d(-2.0) - len(2.0) * d(2.0)).abs() < 1e-9 * len(2.0) * d(2.0));
    }

    #[test]
    fn framing_keeps_the_whole_box_on_screen_from_every_preset() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            for preset in ViewPreset::ALL {
                let c = camera(preset, projection);
                let mut max_extent: f64 = 0.0;
                for corner in 0..8 {
                    let p = Point3::new(
                        if corner & 1 == 0 { -10.0 } else { 10.0 },
                        if corner & 2 == 0 { -5.0 } else { 5.0 },
                        if corner & 4 == 0 { -0.25 } else { 0.25 },
                    );
                    let s = c.project(&p, &VIEWPORT).expect("in front");
                    let (near, far) = c.near_far();
                    assert!(s.depth > near && s.depth < far, "{preset:?} {projection:?}: clipped corner");
                    let [x, y] = VIEWPORT.ndc_at(s.pos);
                    assert!(x.abs() <= 1.0 && y.abs() <= 1.0, "{preset:?} {projection:?}: corner off screen");
                    max_extent = max_extent.max(x.abs()).max(y.abs());
                }
                // The limiting corner sits exactly at the margin.
                let expected = 1.0 / 1.05;
                assert!((max_extent - expected).abs() < 1e-9, "{preset:?} {projection:?}: {max_extent}");
            }
        }
    }

    #[test]
    fn orbiting_keeps_the_target_and_distance() {
        let mut c = camera(ViewPreset::Oblique, Projection::Perspective);
        let (target, distance) = (c.target, c.distance);
        for (dx, dy) in [(40.0, 0.0), (-15.0, 30.0), (0.0, -500.0), (0.0, 900.0)] {
            c.orbit(dx, dy);
            assert_eq!(c.target, target);
            assert!(((c.eye() - c.target).norm() - distance).abs() < 1e-9);
            assert!(c.pitch_rad.abs() <= MAX_PITCH_RAD);
            let centre_now = c.project(&target, &VIEWPORT).expect("in front").pos;
            assert!(close(centre_now, centre(), 1e-9));
        }
        assert_eq!(c.pitch_rad, MAX_PITCH_RAD, "a long drag stops at the pole");
    }

    #[test]
    fn zooming_keeps_the_point_under_the_cursor() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let mut c = camera(ViewPreset::Oblique, projection);
            let cursor = [120.0, 90.0];
            let anchor = c.point_on_target_plane(cursor, &VIEWPORT);
            let d0 = c.distance;
            c.zoom_towards(0.5, cursor, &VIEWPORT);
            assert!((c.distance - d0 * 0.5).abs() < 1e-12);
            let after = c.project(&anchor, &VIEWPORT).expect("in front").pos;
            assert!(close(after, cursor, 1e-6), "{projection:?}: {after:?}");
            c.zoom_towards(1e9, cursor, &VIEWPORT);
            assert!(c.distance <= c.scene_radius * MAX_DISTANCE_RADII * (1.0 + 1e-12), "zoom out is bounded");
        }
    }

    #[test]
    fn panning_moves_the_scene_with_the_mouse() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let mut c = camera(ViewPreset::Oblique, projection);
            let p = c.target;
            let before = c.project(&p, &VIEWPORT).expect("in front").pos;
            c.pan(25.0, -12.0, &VIEWPORT);
            let after = c.project(&p, &VIEWPORT).expect("in front").pos;
            assert!(close(after, [before[0] + 25.0, before[1] - 12.0], 1e-6), "{projection:?}: {after:?}");
        }
    }

    #[test]
    fn the_picking_ray_passes_through_what_projects_to_the_pixel() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            for preset in ViewPreset::ALL {
                let c = camera(preset, projection);
                for p in [Point3::new(3.0, -2.0, 0.1), Point3::new(-8.0, 4.0, -0.2), Point3::new(0.0, 0.0, 0.0)] {
                    let s = c.project(&p, &VIEWPORT).expect("in front");
                    let ray = c.ray_through(s.pos, &VIEWPORT);
                    assert!(ray.distance_to(&p) < 1e-9, "{preset:?} {projection:?}: {}", ray.distance_to(&p));
                    assert!((p - ray.origin).dot(&ray.dir) > 0.0, "the point is in front of the ray's origin");
                }
            }
        }
    }
}
