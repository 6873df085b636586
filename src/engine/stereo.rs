//! Step three of the method (section 2.3): rectify both absolute phase maps,
//! match along rows, triangulate, and organize the points by left pixel.

use rayon::prelude::*;

use super::buffers::filled;
use super::camera_model::StereoCalibration;
use super::continuity::Continuity;
use super::control::{Cancelled, RunControl};
use super::point_cloud::{CloudPoint, PointCloud};
use super::rectify::{Rectification, RectifyError, rectify, resample_phase};
use super::stereo_match::{MatchStats, match_rows};
use super::triangulate::Triangulator;

/// How the sub-stages' timings are named (`stereo: matching`): a run's total
/// leaves them out, since the stereo total holds them.
pub const STAGE_PREFIX: &str = "stereo: ";

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
    /// How each pixel's fringe orders were decided (`unwrap::EVIDENCE_*`).
    pub order_evidence: &'a [u8],
}

#[derive(Clone, Debug)]
pub struct StereoResult {
    pub rectification: Rectification,
    pub left_rectified_phase_rad: Vec<f32>,
    pub right_rectified_phase_rad: Vec<f32>,
    /// Per left rectified pixel: matched right rectified column (NaN if none).
    pub right_column: Vec<f32>,
    pub match_stats: MatchStats,
    /// Wall time of the sub-stages, in order.
    pub timings: Vec<(String, f64)>,
    /// Matches left out because their height sigma exceeded the limit.
    pub too_uncertain: usize,
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
    max_sigma_z: f64,
    continuity: Continuity,
    control: &RunControl,
) -> Result<StereoResult, StereoError> {
    let rect = rectify(calib)?;
    let tri = Triangulator::new(calib).ok_or(StereoError::Singular)?;
    let mut timings = Vec::new();
    let t0 = std::time::Instant::now();
    control.begin_stage("rectification");
    let (left_rect, _) =
        resample_phase(left.phase_rad, left.sigma_rad, &calib.left, &rect.left, rect.rows, &continuity);
    control.set_fraction(0.5);
    control.check()?;
    let (right_rect, right_sigma) =
        resample_phase(right.phase_rad, right.sigma_rad, &calib.right, &rect.right, rect.rows, &continuity);
    control.check()?;
    timings.push((format!("{STAGE_PREFIX}rectification"), t0.elapsed().as_secs_f64()));
    let t0 = std::time::Instant::now();
    control.begin_stage("matching");
    // Matching wants phase rising along rows; a projector or rig mounted the
    // other way round gives falling phase, which negating both maps fixes.
    let matches = if phase_falls_along_rows(&left_rect, rect.left.width) {
        let negated = |m: &[f32]| m.iter().map(|p| -p).collect::<Vec<f32>>();
        let (l, r) = (negated(&left_rect), negated(&right_rect));
        match_rows(&l, rect.left.width, &r, &right_sigma, rect.right.width, rect.rows, &continuity)
    } else {
        match_rows(&left_rect, rect.left.width, &right_rect, &right_sigma, rect.right.width, rect.rows, &continuity)
    };
    control.check()?;
    timings.push((format!("{STAGE_PREFIX}matching"), t0.elapsed().as_secs_f64()));
    let t0 = std::time::Instant::now();
    control.begin_stage("triangulation");

    let wl = rect.left.width;
    // d(ideal right pixel)/d(rectified right column): first column of from_rect.
    let d_right = [rect.right.from_rect[0][0], rect.right.from_rect[1][0]];
    let dz_dc = tri.d_point_d_right(d_right)[2].abs();
    let empty =
        || PointCloud { unit: calib.unit, grid_width: left.width, grid_height: left.height, ..PointCloud::default() };
    let locator = MatchLocator::new(calib, &rect, left.width, left.height);
    let wr = rect.right.width;
    // The height uncertainty of a located match: what decides whether it
    // becomes a point. Phase noise of both cameras, and the interpolation
    // error of a curved phase (twice the matching term: the right map's
    // resampling interpolates too), as standard deviations.
    let sigma_z_of = |sigma_l: f32, sigma_r: f32, slope: f32, interpolation_px: f32| -> f64 {
        let (sigma_l, sigma_r, slope) = (f64::from(sigma_l), f64::from(sigma_r), f64::from(slope));
        let interpolation = 2.0 * f64::from(interpolation_px);
        let sigma_c =
            ((sigma_l * sigma_l + sigma_r * sigma_r) / (slope * slope) + interpolation * interpolation).sqrt();
        dz_dc * sigma_c
    };
    let row_of = |r: usize| r * wl..(r + 1) * wl;
    // Two passes over the matches: decide and count each row's points, then
    // write every row straight into its place in the final arrays.
    // Collecting per-row chunks and concatenating them moved the ~150 MB of a
    // full-resolution cloud twice and cost more than the triangulation
    // itself. The first pass keeps each point's height uncertainty (NaN: no
    // point), so the second computes no uncertainty again.
    let mut point_sigma_z = filled(wl * rect.rows, f32::NAN);
    let row_counts: Vec<(usize, usize)> = point_sigma_z
        .par_chunks_mut(wl.max(1))
        .enumerate()
        .map(|(r, row_sigma_z)| {
            let row = row_of(r);
            let (columns, slopes) = (&matches.right_column[row.clone()], &matches.phase_slope[row.clone()]);
            let interpolation = &matches.interpolation_px[row];
            let right_sigma_row = &right_sigma[r * wr..(r + 1) * wr];
            // A NaN column (no match) converts to column 0: read, then not used.
            let right_sigma_at = |column: f32| right_sigma_row[(column.round() as usize).min(wr - 1)];
            let (mut points, mut uncertain) = (0, 0);
            if let Some((dc, dr)) = locator.integer_shift {
                // The usual left camera: rectified pixel (c, r) is camera
                // pixel (c - dc, r - dr), so the row's pixels are a slice and
                // the pass runs without a branch (the same test per pixel).
                let (w, h) = (left.width as isize, left.height as isize);
                let y = r as isize - dr;
                let (c_lo, c_hi) = (dc.clamp(0, wl as isize), (w + dc).clamp(0, wl as isize));
                if y < 0 || y >= h || c_hi <= c_lo {
                    return (0, 0);
                }
                let (c_lo, c_hi) = (c_lo as usize, c_hi as usize);
                let first = y as usize * left.width + (c_lo as isize - dc) as usize;
                let sigma_l = &left.sigma_rad[first..first + (c_hi - c_lo)];
                let span = c_lo..c_hi;
                let (columns, slopes, interpolation) =
                    (&columns[span.clone()], &slopes[span.clone()], &interpolation[span.clone()]);
                for (k, kept) in row_sigma_z[span].iter_mut().enumerate() {
                    let right_column = columns[k];
                    let matched = !right_column.is_nan();
                    let sigma_z = sigma_z_of(sigma_l[k], right_sigma_at(right_column), slopes[k], interpolation[k]);
                    let certain = sigma_z <= max_sigma_z;
                    *kept = if matched & certain { sigma_z as f32 } else { f32::NAN };
                    points += usize::from(matched & certain);
                    uncertain += usize::from(matched & !certain);
                }
                return (points, uncertain);
            }
            for (c, kept) in row_sigma_z.iter_mut().enumerate() {
                let right_column = columns[c];
                if right_column.is_nan() {
                    continue;
                }
                let Some(pixel) = locator.left_pixel(r, c) else { continue };
                let sigma_z =
                    sigma_z_of(left.sigma_rad[pixel.index], right_sigma_at(right_column), slopes[c], interpolation[c]);
                if sigma_z <= max_sigma_z {
                    *kept = sigma_z as f32;
                    points += 1;
                } else {
                    uncertain += 1;
                }
            }
            (points, uncertain)
        })
        .collect();
    control.check()?;
    let too_uncertain = row_counts.iter().map(|&(_, u)| u).sum();
    let counts: Vec<usize> = row_counts.iter().map(|&(n, _)| n).collect();
    let mut cloud = empty();
    cloud.append_rows_in_parallel(&counts, |r, row| {
        let columns = &matches.right_column[row_of(r)];
        for (c, &sigma_z) in point_sigma_z[row_of(r)].iter().enumerate() {
            if sigma_z.is_nan() {
                continue;
            }
            // Located in the first pass: a kept match has its pixel.
            let Some(pixel) = locator.kept_pixel(r, c) else { continue };
            let ideal_r = rect.right.ideal_pixel(f64::from(columns[c]), r as f64);
            let i = pixel.index;
            let source = attributes.source_set[i];
            let (period, modulation) = if source >= 0 {
                let s = source as usize;
                (attributes.periods_px[s] as f32, attributes.modulation_dn[s][i])
            } else {
                (f32::NAN, f32::NAN)
            };
            row.push(CloudPoint {
                xyz: tri.point(pixel.ideal, ideal_r),
                pixel_uv: [pixel.observed[0] as f32, pixel.observed[1] as f32],
                source_set: source,
                source_period_px: period,
                modulation_dn: modulation,
                sigma_z,
                intensity_dn: attributes.texture_dn[i],
                order_evidence: attributes.order_evidence[i],
            });
        }
    });
    control.check()?;

    // A rotated or distorted left map can send two rectified pixels to one
    // camera pixel: keep the first so the cloud stays organized.
    if locator.integer_shift.is_none() {
        let mut taken = vec![false; left.width * left.height];
        let keep: Vec<bool> = cloud
            .pixel_uv
            .iter()
            .map(|uv| {
                !std::mem::replace(&mut taken[uv[1].round() as usize * left.width + uv[0].round() as usize], true)
            })
            .collect();
        cloud.retain_by_index(&keep);
    }
    timings.push((format!("{STAGE_PREFIX}triangulation"), t0.elapsed().as_secs_f64()));
    Ok(StereoResult {
        timings,
        rectification: rect,
        left_rectified_phase_rad: left_rect,
        right_rectified_phase_rad: right_rect,
        right_column: matches.right_column,
        match_stats: matches.stats,
        too_uncertain,
        cloud,
    })
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

/// Where a left rectified pixel lies in the left image. Its methods are
/// inlined into the per-pixel loops: called out of line, the `Option` it
/// returns went through memory, once per pixel in each of the two passes.
struct MatchLocator<'a> {
    map: &'a super::rectify::RectMap,
    /// The left camera's distortion, `None` when it is the identity.
    distortion: Option<super::camera_model::Distortion>,
    /// `(dc, dr)` when rectified pixel `(c, r)` is camera pixel
    /// `(c - dc, r - dr)`: an undistorted camera whose map is an integer shift.
    integer_shift: Option<(isize, isize)>,
    width: usize,
    height: usize,
}

/// A left rectified pixel in the left image.
struct LeftPixel {
    /// Ideal pixel.
    ideal: [f64; 2],
    /// Observed pixel.
    observed: [f64; 2],
    /// Index of the nearest pixel.
    index: usize,
}

impl<'a> MatchLocator<'a> {
    fn new(calib: &StereoCalibration, rect: &'a Rectification, width: usize, height: usize) -> Self {
        let distortion = calib.left.active_distortion().copied();
        let integer_shift = rect.left.pixel_shift(&calib.left);
        Self { map: &rect.left, distortion, integer_shift, width, height }
    }

    /// The left pixel of rectified pixel `(c, r)`, `None` outside the image.
    #[inline(always)]
    fn left_pixel(&self, r: usize, c: usize) -> Option<LeftPixel> {
        let ideal = self.map.ideal_pixel(c as f64, r as f64);
        let observed = match &self.distortion {
            Some(d) => d.distort(ideal),
            None => ideal,
        };
        let (ui, vi) = (observed[0].round(), observed[1].round());
        if ui < 0.0 || vi < 0.0 || ui >= self.width as f64 || vi >= self.height as f64 {
            return None;
        }
        Some(LeftPixel { ideal, observed, index: vi as usize * self.width + ui as usize })
    }

    /// [`MatchLocator::left_pixel`] of a match the first pass kept: for the
    /// usual left camera the pixel is `(c - dc, r - dr)`, inside the image
    /// (the first pass only keeps those), without rounding and bounds tests.
    #[inline(always)]
    fn kept_pixel(&self, r: usize, c: usize) -> Option<LeftPixel> {
        let Some((dc, dr)) = self.integer_shift else { return self.left_pixel(r, c) };
        let ideal = self.map.ideal_pixel(c as f64, r as f64);
        let index = (r as isize - dr) as usize * self.width + (c as isize - dc) as usize;
        Some(LeftPixel { ideal, observed: ideal, index })
    }
}
