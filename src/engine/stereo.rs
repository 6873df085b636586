//! Step three of the method (section 2.3): rectify both absolute phase maps,
//! match along rows, triangulate, and organize the points by left pixel.

use rayon::prelude::*;

use super::camera_model::StereoCalibration;
use super::control::{Cancelled, RunControl};
use super::point_cloud::PointCloud;
use super::rectify::{RESAMPLE_JUMP_LIMIT_RAD, Rectification, RectifyError, rectify, resample_phase};
use super::stereo_match::{MatchStats, match_rows};
use super::triangulate::Triangulator;

/// What stereo needs from one camera's phase stage.
pub struct PhaseMapView<'a> {
    pub width: usize,
    pub height: usize,
    /// Absolute phase in radians of the densest enabled period, NaN invalid.
    pub phase_rad: &'a [f32],
    pub sigma_rad: &'a [f32],
}

/// Per-pixel attributes of the left camera carried into the cloud.
pub struct LeftAttributes<'a> {
    pub source_set: &'a [i8],
    /// Period of each manifest set.
    pub periods_px: &'a [f64],
    /// Modulation map of each manifest set.
    pub modulation_dn: Vec<&'a [f32]>,
    pub texture_dn: &'a [f32],
}

#[derive(Clone, Debug)]
pub struct StereoResult {
    pub rectification: Rectification,
    pub left_rectified_phase_rad: Vec<f32>,
    pub right_rectified_phase_rad: Vec<f32>,
    /// Per left rectified pixel: matched right rectified column (NaN if none).
    pub right_column: Vec<f32>,
    pub match_stats: MatchStats,
    pub cloud: PointCloud,
}

#[derive(Debug, thiserror::Error)]
pub enum StereoError {
    #[error(transparent)]
    Rectify(#[from] RectifyError),
    #[error("the two cameras' projection matrices do not determine a point (singular stereo system)")]
    Singular,
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// Rectification, matching (Eq. 7) and triangulation.
pub fn reconstruct(
    calib: &StereoCalibration,
    left: &PhaseMapView<'_>,
    right: &PhaseMapView<'_>,
    attributes: &LeftAttributes<'_>,
    control: &RunControl,
) -> Result<StereoResult, StereoError> {
    let rect = rectify(calib)?;
    let tri = Triangulator::new(calib).ok_or(StereoError::Singular)?;
    control.begin_stage("rectification");
    let left_rect = resample_phase(left.phase_rad, &calib.left, &rect.left, rect.rows, RESAMPLE_JUMP_LIMIT_RAD);
    control.set_fraction(0.5);
    control.check()?;
    let right_rect = resample_phase(right.phase_rad, &calib.right, &rect.right, rect.rows, RESAMPLE_JUMP_LIMIT_RAD);
    control.check()?;
    control.begin_stage("matching");
    // Matching wants phase rising along rows; a projector or rig mounted the
    // other way round gives falling phase, which negating both maps fixes.
    let matches = if phase_falls_along_rows(&left_rect, rect.left.width) {
        let negated = |m: &[f32]| m.iter().map(|p| -p).collect::<Vec<f32>>();
        let (l, r) = (negated(&left_rect), negated(&right_rect));
        match_rows(&l, rect.left.width, &r, rect.right.width, rect.rows, RESAMPLE_JUMP_LIMIT_RAD)
    } else {
        match_rows(&left_rect, rect.left.width, &right_rect, rect.right.width, rect.rows, RESAMPLE_JUMP_LIMIT_RAD)
    };
    control.check()?;
    control.begin_stage("triangulation");

    let wl = rect.left.width;
    // d(ideal right pixel)/d(rectified right column): first column of from_rect.
    let d_right = [rect.right.from_rect[0][0], rect.right.from_rect[1][0]];
    let dz_dc = tri.d_point_d_right(d_right)[2].abs();
    let rows: Vec<Vec<MatchedPoint>> = (0..rect.rows)
        .into_par_iter()
        .map(|r| {
            let mut out = Vec::new();
            for c in 0..wl {
                let i = r * wl + c;
                let cr = matches.right_column[i];
                if cr.is_nan() {
                    continue;
                }
                let ideal_l = rect.left.ideal_pixel(c as f64, r as f64);
                let ideal_r = rect.right.ideal_pixel(f64::from(cr), r as f64);
                let [u, v] = calib.left.observed_from_ideal(ideal_l);
                let (ui, vi) = (u.round(), v.round());
                if ui < 0.0 || vi < 0.0 || ui >= left.width as f64 || vi >= left.height as f64 {
                    continue;
                }
                let pixel = vi as usize * left.width + ui as usize;
                let [ur, vr] = calib.right.observed_from_ideal(ideal_r);
                let sigma_r = pixel_value(right.sigma_rad, right.width, right.height, ur, vr);
                let sigma_l = f64::from(left.sigma_rad[pixel]);
                let slope = f64::from(matches.phase_slope[i]);
                let sigma_c = (sigma_l * sigma_l + sigma_r * sigma_r).sqrt() / slope;
                let x = tri.point(ideal_l, ideal_r);
                out.push(MatchedPoint { pixel, xyz: x, uv: [u as f32, v as f32], sigma_z: (dz_dc * sigma_c) as f32 });
            }
            out
        })
        .collect();
    control.check()?;

    let mut cloud = PointCloud {
        unit: calib.unit.clone(),
        grid_width: left.width,
        grid_height: left.height,
        ..PointCloud::default()
    };
    // A rotated left map can send two rectified pixels to one camera pixel:
    // keep the first so the cloud stays organized (one point per pixel).
    let mut taken = vec![false; left.width * left.height];
    for MatchedPoint { pixel, xyz: x, uv, sigma_z } in rows.into_iter().flatten() {
        if std::mem::replace(&mut taken[pixel], true) {
            continue;
        }
        let source = attributes.source_set[pixel];
        let (period, modulation) = if source >= 0 {
            let s = source as usize;
            (attributes.periods_px[s] as f32, attributes.modulation_dn[s][pixel])
        } else {
            (f32::NAN, f32::NAN)
        };
        cloud.xyz.push(x);
        cloud.pixel_uv.push(uv);
        cloud.source_set.push(source);
        cloud.source_period_px.push(period);
        cloud.modulation_dn.push(modulation);
        cloud.sigma_z.push(sigma_z);
        cloud.intensity_dn.push(attributes.texture_dn[pixel]);
    }
    Ok(StereoResult {
        rectification: rect,
        left_rectified_phase_rad: left_rect,
        right_rectified_phase_rad: right_rect,
        right_column: matches.right_column,
        match_stats: matches.stats,
        cloud,
    })
}

/// A triangulated match before it joins the organized cloud.
struct MatchedPoint {
    /// Linear index of the left pixel.
    pixel: usize,
    xyz: [f64; 3],
    uv: [f32; 2],
    sigma_z: f32,
}

/// Nearest-pixel value of a map at an observed position, NaN outside.
fn pixel_value(map: &[f32], w: usize, h: usize, u: f64, v: f64) -> f64 {
    let (ui, vi) = (u.round(), v.round());
    if ui < 0.0 || vi < 0.0 || ui >= w as f64 || vi >= h as f64 {
        return f64::NAN;
    }
    f64::from(map[vi as usize * w + ui as usize])
}

/// True when most valid neighbour pairs of the map fall from left to right.
fn phase_falls_along_rows(map: &[f32], width: usize) -> bool {
    let (mut rising, mut falling) = (0usize, 0usize);
    for row in map.chunks(width.max(1)).step_by(4) {
        for pair in row.windows(2) {
            let d = pair[1] - pair[0];
            if d > 0.0 {
                rising += 1;
            } else if d < 0.0 {
                falling += 1;
            }
        }
    }
    falling > rising
}
