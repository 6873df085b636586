//! Section profiles through the height map (the gasket sections of the
//! paper's Fig. 7): along a line between two points, or a horizontal or
//! vertical section through a point across the whole map.
//!
//! Stations are evenly spaced from start to end, both included: the requested
//! step is shrunk to divide the line evenly and the step used is reported.
//! At each station the height is the mean of bilinear samples on parallel
//! lines spread evenly across the averaging width (spacing at most one
//! pitch, the centre line always included); holes are left out of the mean
//! and the count of samples used is kept, so a station with no valid sample
//! is NaN rather than invented.

use serde::{Deserialize, Serialize};

use super::error::AnalysisError;
use super::height_map::HeightMap;

/// Where a profile runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ProfileLine {
    Segment {
        start_mm: [f64; 2],
        end_mm: [f64; 2],
    },
    /// Along +X through the point, from the map's first to last column.
    Horizontal {
        through_mm: [f64; 2],
    },
    /// Along +Y through the point, from the map's first to last row.
    Vertical {
        through_mm: [f64; 2],
    },
}

/// A named profile request; the GUI adds a colour of its own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileSpec {
    pub name: String,
    pub line: ProfileLine,
    /// Distance between stations; `None` = the map pitch.
    #[serde(default)]
    pub step_mm: Option<f64>,
    /// Averaging width across the line; 0 = the line alone.
    #[serde(default)]
    pub width_mm: f64,
    /// Also return the map nodes near the line, to plot beside the profile.
    #[serde(default)]
    pub raw_samples: bool,
}

/// How heights between map nodes are obtained.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    #[default]
    Bilinear,
}

impl Interpolation {
    /// The sentence written into exports and shown under plots.
    pub fn describe(self) -> &'static str {
        match self {
            Interpolation::Bilinear => {
                "bilinear between the 4 nearest height-map nodes; NaN where any of them with non-zero weight is a hole"
            }
        }
    }
}

/// One station of a profile.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileSample {
    /// Along the line from its start.
    pub distance_mm: f64,
    pub x_mm: f64,
    pub y_mm: f64,
    /// Mean height of the `n` valid samples across the line; NaN when `n == 0`.
    pub z_um: f64,
    pub n: u32,
}

/// A map node near the line, for plotting the data behind the averaged profile.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RawSample {
    /// Projection onto the line.
    pub distance_mm: f64,
    /// Signed distance from the line (positive to the left of start -> end).
    pub offset_mm: f64,
    pub x_mm: f64,
    pub y_mm: f64,
    pub z_um: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    pub name: String,
    pub start_mm: [f64; 2],
    pub end_mm: [f64; 2],
    pub length_mm: f64,
    /// Station spacing used (at most the requested step).
    pub step_mm: f64,
    pub width_mm: f64,
    /// Parallel lines averaged at each station.
    pub lines_across: usize,
    pub interpolation: Interpolation,
    pub samples: Vec<ProfileSample>,
    /// Nodes within half the width (at least half a pitch) of the line, by distance.
    pub raw: Vec<RawSample>,
}

/// Most stations in one profile, and most bilinear samples (stations x
/// parallel lines): a wrong step or width fails instead of exhausting memory.
pub const MAX_PROFILE_SAMPLES: usize = 10_000_000;
pub const MAX_PROFILE_EVALUATIONS: usize = 200_000_000;

impl ProfileSpec {
    /// End points of the line on `map`.
    pub fn end_points(&self, map: &HeightMap) -> ([f64; 2], [f64; 2]) {
        let ([x0, y0], [x1, y1]) = map.extent_mm();
        match self.line {
            ProfileLine::Segment { start_mm, end_mm } => (start_mm, end_mm),
            ProfileLine::Horizontal { through_mm: [_, y] } => ([x0, y], [x1, y]),
            ProfileLine::Vertical { through_mm: [x, _] } => ([x, y0], [x, y1]),
        }
    }

    fn invalid(&self, reason: String) -> AnalysisError {
        AnalysisError::InvalidProfile { name: self.name.clone(), reason }
    }

    /// Checks the request on its own (name, finite geometry, step, width).
    pub fn validate(&self) -> Result<(), AnalysisError> {
        if self.name.trim().is_empty() {
            return Err(self.invalid("the name is empty; give every profile a name".into()));
        }
        let points: Vec<f64> = match self.line {
            ProfileLine::Segment { start_mm, end_mm } => start_mm.into_iter().chain(end_mm).collect(),
            ProfileLine::Horizontal { through_mm } | ProfileLine::Vertical { through_mm } => through_mm.to_vec(),
        };
        if !points.iter().all(|v| v.is_finite()) {
            return Err(self.invalid("a line point is not finite".into()));
        }
        if let ProfileLine::Segment { start_mm, end_mm } = self.line
            && start_mm == end_mm
        {
            return Err(self.invalid(format!("start and end are the same point {start_mm:?} mm; draw a line")));
        }
        if let Some(step) = self.step_mm
            && !(step.is_finite() && step > 0.0)
        {
            return Err(self.invalid(format!("step {step} mm is not a positive length")));
        }
        if !(self.width_mm.is_finite() && self.width_mm >= 0.0) {
            return Err(self.invalid(format!("averaging width {} mm is negative or not finite", self.width_mm)));
        }
        Ok(())
    }
}

/// Extracts the profile described by `spec` from `map` (module docs).
pub fn extract_profile(map: &HeightMap, spec: &ProfileSpec) -> Result<Profile, AnalysisError> {
    spec.validate()?;
    let (start, end) = spec.end_points(map);
    let (dx, dy) = (end[0] - start[0], end[1] - start[1]);
    let length_mm = dx.hypot(dy);
    if length_mm.is_nan() || length_mm <= 0.0 {
        return Err(spec.invalid("the line has no length on this map (a single row or column)".into()));
    }
    let requested = spec.step_mm.unwrap_or(map.pitch_mm);
    let intervals_f = (length_mm / requested - 1e-9).ceil().max(1.0);
    if intervals_f >= MAX_PROFILE_SAMPLES as f64 {
        return Err(spec.invalid(format!(
            "{length_mm:.4} mm at a step of {requested} mm gives more than {MAX_PROFILE_SAMPLES} stations; use a \
             larger step"
        )));
    }
    let intervals = intervals_f as usize;
    let (ux, uy) = (dx / length_mm, dy / length_mm);
    let (nx, ny) = (-uy, ux); // left normal
    let lines_across = if spec.width_mm > 0.0 {
        2 * ((spec.width_mm / (2.0 * map.pitch_mm)) - 1e-9).ceil().max(1.0) as usize + 1
    } else {
        1
    };
    if (intervals + 1).saturating_mul(lines_across) > MAX_PROFILE_EVALUATIONS {
        return Err(spec.invalid(format!(
            "{} stations x {lines_across} parallel lines (width {} mm at pitch {} mm) exceed {MAX_PROFILE_EVALUATIONS} \
             samples; use a narrower width or a larger step",
            intervals + 1,
            spec.width_mm,
            map.pitch_mm
        )));
    }
    let offsets: Vec<f64> = if lines_across == 1 {
        vec![0.0]
    } else {
        let half = (lines_across / 2) as f64;
        (0..lines_across).map(|j| (j as f64 - half) / half * spec.width_mm / 2.0).collect()
    };
    let samples = (0..=intervals)
        .map(|k| {
            let f = k as f64 / intervals as f64;
            let (x, y) = (start[0] + f * dx, start[1] + f * dy);
            let (sum, n) = offsets
                .iter()
                .map(|o| map.z_at(x + o * nx, y + o * ny))
                .filter(|z| !z.is_nan())
                .fold((0.0, 0u32), |(s, n), z| (s + z, n + 1));
            let z_um = if n > 0 { sum / f64::from(n) * 1e3 } else { f64::NAN };
            ProfileSample { distance_mm: f * length_mm, x_mm: x, y_mm: y, z_um, n }
        })
        .collect();
    let raw = if spec.raw_samples {
        raw_near_line(map, start, [ux, uy], length_mm, (spec.width_mm / 2.0).max(map.pitch_mm / 2.0))
    } else {
        Vec::new()
    };
    Ok(Profile {
        name: spec.name.clone(),
        start_mm: start,
        end_mm: end,
        length_mm,
        step_mm: length_mm / intervals as f64,
        width_mm: spec.width_mm,
        lines_across,
        interpolation: Interpolation::Bilinear,
        samples,
        raw,
    })
}

/// Valid nodes whose projection falls on the segment and whose distance from
/// it is at most `half_width`, sorted by distance along the line.
fn raw_near_line(map: &HeightMap, start: [f64; 2], u: [f64; 2], length: f64, half_width: f64) -> Vec<RawSample> {
    let end = [start[0] + u[0] * length, start[1] + u[1] * length];
    let lo = [start[0].min(end[0]) - half_width, start[1].min(end[1]) - half_width];
    let hi = [start[0].max(end[0]) + half_width, start[1].max(end[1]) + half_width];
    let (gx0, gy0) = map.grid_position(lo[0], lo[1]);
    let (gx1, gy1) = map.grid_position(hi[0], hi[1]);
    let c0 = gx0.ceil().max(0.0) as usize;
    let r0 = gy0.ceil().max(0.0) as usize;
    let c1 = (gx1.floor().min(map.width as f64 - 1.0)).max(-1.0);
    let r1 = (gy1.floor().min(map.height as f64 - 1.0)).max(-1.0);
    let mut out = Vec::new();
    if c1 < 0.0 || r1 < 0.0 {
        return out;
    }
    for row in r0..=r1 as usize {
        for col in c0..=c1 as usize {
            let z = map.node_z_mm(col, row);
            if z.is_nan() {
                continue;
            }
            let (x, y) = (map.x_mm(col), map.y_mm(row));
            let (px, py) = (x - start[0], y - start[1]);
            let t = px * u[0] + py * u[1];
            let o = -px * u[1] + py * u[0];
            if t >= -1e-12 && t <= length + 1e-12 && o.abs() <= half_width + 1e-12 {
                out.push(RawSample { distance_mm: t, offset_mm: o, x_mm: x, y_mm: y, z_um: f64::from(z) * 1e3 });
            }
        }
    }
    out.sort_by(|a, b| a.distance_mm.total_cmp(&b.distance_mm));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::testing::{GridSpec, node_map, surface_map};
    use proptest::prelude::*;

    fn segment(name: &str, start: [f64; 2], end: [f64; 2], width_mm: f64) -> ProfileSpec {
        ProfileSpec {
            name: name.into(),
            line: ProfileLine::Segment { start_mm: start, end_mm: end },
            step_mm: None,
            width_mm,
            raw_samples: false,
        }
    }

    /// A V-groove along Y at x = X0: 30 um deep, flanks of slope 0.1.
    const X0: f64 = 0.503;
    fn v_groove(x: f64) -> f64 {
        (0.1 * (x - X0).abs() - 0.030).min(0.0)
    }

    #[test]
    fn section_across_a_v_groove_matches_the_true_section() {
        // The cloud's pixel grid is rotated 20 deg to the map grid: a real
        // resampling, not node copying.
        let spec = GridSpec { width: 120, height: 120, pitch_mm: 0.01, angle_deg: 20.0, origin_mm: [0.2, -0.2] };
        let map = surface_map(&spec, |x, _| Some(v_groove(x)));
        // The groove's top edges (kinks) are at X0 +- 0.3 mm: stay inside them.
        let p = extract_profile(&map, &segment("groove", [0.25, 0.5], [0.75, 0.5], 0.05)).unwrap();
        assert_eq!(p.lines_across, 7);
        let mut near_apex = 0.0f64;
        for s in &p.samples {
            assert_eq!(s.n, 7, "a station lost samples at x={}", s.x_mm);
            let err_um = (s.z_um - v_groove(s.x_mm) * 1e3).abs();
            if (s.x_mm - X0).abs() > 0.03 {
                // Planar flanks are reproduced exactly (f32 storage only).
                assert!(err_um < 1e-3, "x={} err {err_um} um", s.x_mm);
            } else {
                near_apex = near_apex.max(err_um);
            }
        }
        // At the apex linear interpolation cuts the corner by at most half
        // the slope times the sample spacing: sqrt2 pitch across a triangle,
        // then one pitch for the bilinear stage: 0.1 x (7.1 + 5) um.
        assert!(near_apex < 1.25, "apex error {near_apex} um");
        // The deepest sample is at the groove's bottom.
        let deepest = p.samples.iter().min_by(|a, b| a.z_um.total_cmp(&b.z_um)).unwrap();
        assert!((deepest.x_mm - X0).abs() < 0.011 && (deepest.z_um + 30.0).abs() < 1.0);
    }

    #[test]
    fn sections_through_a_circular_indentation_match_the_sphere() {
        // Spherical indentation (gasket dent): radius 5 mm, 20 um deep.
        let (c, r_mm, depth) = ([0.6, 0.6], 5.0, 0.020);
        let cap = move |x: f64, y: f64| {
            let d2 = (x - c[0]).powi(2) + (y - c[1]).powi(2);
            let sag = r_mm - (r_mm * r_mm - d2).max(0.0).sqrt();
            (sag - depth).min(0.0)
        };
        let spec = GridSpec { width: 130, height: 130, pitch_mm: 0.01, angle_deg: 7.0, origin_mm: [0.05, 0.0] };
        let map = surface_map(&spec, |x, y| Some(cap(x, y)));
        let horizontal = ProfileSpec {
            name: "h".into(),
            line: ProfileLine::Horizontal { through_mm: [0.0, 0.6] },
            step_mm: Some(0.005),
            width_mm: 0.0,
            raw_samples: true,
        };
        let vertical = ProfileSpec {
            name: "v".into(),
            line: ProfileLine::Vertical { through_mm: [0.6, 0.0] },
            ..horizontal.clone()
        };
        // Linear interpolation of curvature 1/R over a right triangle of legs
        // p errs by at most p^2 / (4 R) (half its circumradius squared over R),
        // bilinear sampling of the nodes by as much again: p^2 / (2 R) = 0.01
        // um here; 1.5x that allows for the sphere not being a paraboloid.
        let bound_um = 1.5 * 0.01f64.powi(2) / (2.0 * r_mm) * 1e3;
        for spec in [horizontal, vertical] {
            let p = extract_profile(&map, &spec).unwrap();
            assert!(p.step_mm <= 0.005 + 1e-12);
            let mut checked = 0;
            for s in p.samples.iter().filter(|s| s.n > 0) {
                let err = (s.z_um - cap(s.x_mm, s.y_mm) * 1e3).abs();
                // The rim of the dent is a kink: skip within a pitch of it.
                let d = (s.x_mm - c[0]).hypot(s.y_mm - c[1]);
                if (d - (2.0 * r_mm * depth - depth * depth).sqrt()).abs() > 0.015 {
                    assert!(err < bound_um, "{}: d={d} err {err} um > {bound_um}", p.name);
                    checked += 1;
                }
            }
            assert!(checked > 100, "{checked}");
            assert!(!p.raw.is_empty() && p.raw.windows(2).all(|w| w[0].distance_mm <= w[1].distance_mm));
            assert!(p.raw.iter().all(|r| r.offset_mm.abs() <= 0.005 + 1e-12));
        }
    }

    #[test]
    fn holes_give_nan_stations_with_zero_count_and_thin_the_average() {
        let map = node_map(50, 20, [0.0, 0.0], 0.01, |x, y| {
            let hole = (0.2..0.3).contains(&x) || (y > 0.105 && (0.35..0.4).contains(&x));
            (!hole).then_some(0.001)
        });
        let p = extract_profile(&map, &segment("p", [0.0, 0.1], [0.49, 0.1], 0.02)).unwrap();
        assert_eq!(p.lines_across, 3);
        for s in &p.samples {
            if s.x_mm > 0.2 && s.x_mm < 0.28 {
                assert!(s.z_um.is_nan() && s.n == 0, "x={} z={} n={}", s.x_mm, s.z_um, s.n);
            }
            if s.x_mm > 0.36 && s.x_mm < 0.39 {
                // The line above y = 0.105 falls in the half-hole: 2 of 3 used.
                assert_eq!(s.n, 2);
                assert!((s.z_um - 1.0).abs() < 1e-4); // 0.001 mm stored as f32
            }
        }
    }

    #[test]
    fn bad_requests_are_refused_with_the_profile_name() {
        let map = node_map(5, 5, [0.0, 0.0], 0.1, |_, _| Some(0.0));
        for bad in [
            segment("same", [0.1, 0.1], [0.1, 0.1], 0.0),
            segment("wide", [0.0, 0.0], [0.4, 0.4], -1.0),
            ProfileSpec { step_mm: Some(0.0), ..segment("step", [0.0, 0.0], [0.4, 0.4], 0.0) },
            ProfileSpec { step_mm: Some(1e-12), ..segment("tiny", [0.0, 0.0], [0.4, 0.4], 0.0) },
            ProfileSpec { step_mm: Some(1e-7), ..segment("heavy", [0.0, 0.0], [0.4, 0.4], 10.0) },
        ] {
            let e = extract_profile(&map, &bad).unwrap_err();
            assert!(e.to_string().contains(&format!("'{}'", bad.name)), "{e}");
        }
    }

    fn wavy_map() -> HeightMap {
        node_map(40, 30, [1.0, 2.0], 0.02, |x, y| {
            let z = 0.003 * (7.0 * x).sin() * (5.0 * y).cos() + 0.001 * x;
            ((x - 1.4).hypot(y - 2.3) >= 0.06).then_some(z)
        })
    }

    proptest! {
        #[test]
        fn a_reversed_line_gives_the_reversed_profile(
            sx in 1.0..1.78f64, sy in 2.0..2.58f64, ex in 1.0..1.78f64, ey in 2.0..2.58f64,
            width in 0.0..0.1f64, step in 0.005..0.05f64,
        ) {
            prop_assume!((ex - sx).hypot(ey - sy) > 0.01);
            let map = wavy_map();
            let fwd = ProfileSpec { step_mm: Some(step), ..segment("f", [sx, sy], [ex, ey], width) };
            let back = ProfileSpec { step_mm: Some(step), ..segment("b", [ex, ey], [sx, sy], width) };
            let (f, b) = (extract_profile(&map, &fwd).unwrap(), extract_profile(&map, &back).unwrap());
            prop_assert_eq!(f.samples.len(), b.samples.len());
            for (p, q) in f.samples.iter().zip(b.samples.iter().rev()) {
                prop_assert!((p.distance_mm - (f.length_mm - q.distance_mm)).abs() < 1e-9);
                prop_assert_eq!(p.n, q.n);
                if p.n > 0 {
                    prop_assert!((p.z_um - q.z_um).abs() < 1e-6, "{} vs {}", p.z_um, q.z_um);
                }
            }
        }

        #[test]
        fn zero_width_profile_equals_point_sampling(
            sx in 1.0..1.78f64, sy in 2.0..2.58f64, ex in 1.0..1.78f64, ey in 2.0..2.58f64,
        ) {
            prop_assume!((ex - sx).hypot(ey - sy) > 0.01);
            let map = wavy_map();
            let p = extract_profile(&map, &segment("p", [sx, sy], [ex, ey], 0.0)).unwrap();
            prop_assert!(p.step_mm <= map.pitch_mm + 1e-12);
            for s in &p.samples {
                let z = map.z_at(s.x_mm, s.y_mm) * 1e3;
                prop_assert!(z == s.z_um || (z.is_nan() && s.z_um.is_nan() && s.n == 0));
            }
        }
    }
}
