//! Surface reflectance of the simulated parts: a diffuse (Lambertian) albedo
//! plus a Blinn-Phong specular lobe around the half vector between the
//! projector and the camera, and a brushed texture that varies the gloss and
//! tilts the micro-facets across the brushing lines.
//!
//! Why this model: it makes what the paper fights. A specular lobe is seen by
//! one camera and not the other (the half vectors of the two cameras differ by
//! the stereo angle), so highlights differ between the views; brushing makes
//! the brightness vary on a fine scale, so one part holds unsaturated,
//! partially saturated and over-saturated pixels side by side.

use serde::{Deserialize, Serialize};

/// Brushing marks: parallel lines whose gloss and micro-facet tilt vary much
/// faster across the lines than along them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Brush {
    /// Direction of the lines, degrees counter-clockwise from +X.
    pub direction_deg: f64,
    /// Standard scale of the log gloss: the specular lobe is multiplied by
    /// `exp(gloss_variation * n)`, `n` a smooth noise in [-1, 1].
    pub gloss_variation: f64,
    /// Correlation lengths of the texture along and across the lines.
    pub along_mm: f64,
    pub across_mm: f64,
    /// Largest tilt of the micro-facets across the lines (shading only; the
    /// geometry is unchanged because the marks are far below a pixel).
    pub tilt_rad: f64,
}

/// How a surface reflects the projector's light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    /// Lambertian albedo (1: a perfect white diffuser).
    pub albedo: f64,
    /// Peak of the specular lobe relative to a white diffuser lit head-on.
    pub specular: f64,
    /// Blinn-Phong exponent: the larger, the narrower and glossier the lobe.
    pub shininess: f64,
    pub brush: Option<Brush>,
}

impl Material {
    pub fn matte(name: &str, albedo: f64) -> Self {
        Self { name: name.to_owned(), albedo, specular: 0.0, shininess: 1.0, brush: None }
    }

    pub fn glossy(name: &str, albedo: f64, specular: f64, shininess: f64, brush: Option<Brush>) -> Self {
        Self { name: name.to_owned(), albedo, specular, shininess, brush }
    }

    /// Light reflected towards a camera per unit projector irradiance, relative
    /// to a white diffuser lit head-on: `albedo (n.L) + specular g (n'.H)^s`,
    /// with `L = (0, 0, 1)` (the projector looks straight down), `H` the unit
    /// half vector of `L` and `to_camera`, `n` the surface normal, `n'` the
    /// micro-facet normal tilted by the brush and `g` the brush's gloss factor.
    /// Surfaces facing away from the projector (walls) get no light.
    pub fn reflectance(&self, normal: [f64; 3], to_camera: [f64; 3], x_mm: f64, y_mm: f64) -> f64 {
        let n_dot_l = normal[2];
        if n_dot_l <= 1e-9 {
            return 0.0;
        }
        let diffuse = self.albedo * n_dot_l;
        if self.specular <= 0.0 {
            return diffuse;
        }
        let (gloss, facet) = match &self.brush {
            Some(b) => b.texture(normal, x_mm, y_mm),
            None => (1.0, normal),
        };
        let h = normalize([to_camera[0], to_camera[1], to_camera[2] + 1.0]);
        let n_dot_h = (facet[0] * h[0] + facet[1] * h[1] + facet[2] * h[2]).max(0.0);
        diffuse + self.specular * gloss * n_dot_h.powf(self.shininess)
    }
}

impl Brush {
    /// Gloss factor and micro-facet normal at `(x, y)` for surface normal `normal`.
    fn texture(&self, normal: [f64; 3], x_mm: f64, y_mm: f64) -> (f64, [f64; 3]) {
        let (s, c) = self.direction_deg.to_radians().sin_cos();
        let along = (x_mm * c + y_mm * s) / self.along_mm;
        let across = (-x_mm * s + y_mm * c) / self.across_mm;
        let gloss = (self.gloss_variation * fractal_noise(along, across, 0x5eed_0001)).exp();
        // Tilt about the line direction: the facet normal leans across the lines.
        let angle = self.tilt_rad * fractal_noise(along, across, 0x5eed_0002);
        let axis = [c, s, 0.0];
        (gloss, rotate(normal, axis, angle))
    }
}

/// Rodrigues rotation of `v` about the unit `axis` by `angle` radians.
fn rotate(v: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let k = axis;
    let kxv = [k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2], k[0] * v[1] - k[1] * v[0]];
    let kdv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2];
    std::array::from_fn(|i| v[i] * c + kxv[i] * s + k[i] * kdv * (1.0 - c))
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

/// A fixed pseudo-random value in [-1, 1] per lattice point (SplitMix64 finaliser).
#[inline]
fn lattice_value(i: i64, j: i64, salt: u64) -> f64 {
    let mut z = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (j as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f) ^ salt;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// Smooth value noise in [-1, 1] with unit correlation length (quintic fade).
#[inline]
fn value_noise(x: f64, y: f64, salt: u64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (i, j) = (xf as i64, yf as i64);
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (fade(x - xf), fade(y - yf));
    let a = lattice_value(i, j, salt);
    let b = lattice_value(i + 1, j, salt);
    let c = lattice_value(i, j + 1, salt);
    let d = lattice_value(i + 1, j + 1, salt);
    let top = a + (b - a) * u;
    let bottom = c + (d - c) * u;
    top + (bottom - top) * v
}

/// Two octaves of value noise, rescaled to about [-1, 1]: the coarse octave
/// gives patches, the fine one the streaks within them.
pub fn fractal_noise(x: f64, y: f64, salt: u64) -> f64 {
    (value_noise(x, y, salt) + 0.5 * value_noise(2.03 * x + 17.1, 2.03 * y - 5.3, salt ^ 0xa5a5)) / 1.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_and_deterministic() {
        for k in 0..10_000 {
            let (x, y) = (k as f64 * 0.137 - 300.0, k as f64 * -0.071 + 40.0);
            let n = fractal_noise(x, y, 7);
            assert!((-1.0..=1.0).contains(&n), "noise {n} at ({x}, {y})");
            assert_eq!(n, fractal_noise(x, y, 7));
        }
    }

    #[test]
    fn walls_get_no_light_and_lobe_peaks_at_half_vector() {
        let m = Material::glossy("steel", 0.3, 2.0, 50.0, None);
        let t = 15f64.to_radians();
        let to_left = [-t.sin(), 0.0, t.cos()];
        assert_eq!(m.reflectance([1.0, 0.0, 0.0], to_left, 0.0, 0.0), 0.0);
        // A facet tilted by theta/2 towards the left camera reflects its peak.
        let h = normalize([to_left[0], 0.0, to_left[2] + 1.0]);
        let peak = m.reflectance(h, to_left, 0.0, 0.0);
        assert!((peak - (0.3 * h[2] + 2.0)).abs() < 1e-12);
        // The right camera sees that facet far off its lobe.
        let to_right = [t.sin(), 0.0, t.cos()];
        assert!(m.reflectance(h, to_right, 0.0, 0.0) < 0.3 * h[2] + 2.0 * 0.2);
    }

    #[test]
    fn rotation_keeps_length() {
        let v = rotate([0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 0.3);
        assert!((v[0] - 0.3f64.sin()).abs() < 1e-15 && (v[2] - 0.3f64.cos()).abs() < 1e-15);
    }
}
