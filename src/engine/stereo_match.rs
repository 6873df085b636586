//! Phase-based stereo matching along rectified rows (the paper's Eq. 7).
//!
//! For a left pixel with absolute phase `Phi_L`, the right image row is searched
//! for the pixel whose phase is nearest and the sub-pixel column follows by
//! inverse linear interpolation between the two right pixels that bracket
//! `Phi_L`. That is only sound where the right phase rises monotonically
//! between valid neighbours, so the row is first cut into *monotone runs*:
//! maximal stretches of valid pixels whose phase strictly increases by less
//! than a jump limit per pixel. A match must fall inside a run (so it never
//! bridges invalid pixels or a discontinuity) and inside exactly one run
//! (several candidates mean a fold or occlusion: the match is ambiguous and
//! rejected rather than guessed).

use rayon::prelude::*;

use super::continuity::{Continuity, flanking_step};

/// How strictly stereo keeps to continuous surfaces (`--stereo-continuity`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StereoContinuity {
    /// Never interpolate or match across a step, hole or occlusion ([`Continuity`]).
    #[default]
    Strict,
    /// Plain matching along the row: any rising pair of valid pixels brackets
    /// (the nearest monotone bracket of Eq. 7), resampling from any valid pixels.
    Plain,
}

impl StereoContinuity {
    pub const ALL: [StereoContinuity; 2] = [StereoContinuity::Strict, StereoContinuity::Plain];

    pub fn name(self) -> &'static str {
        match self {
            StereoContinuity::Strict => "strict",
            StereoContinuity::Plain => "plain",
        }
    }

    pub fn continuity(self) -> Continuity {
        match self {
            StereoContinuity::Strict => Continuity::default(),
            StereoContinuity::Plain => Continuity::plain(),
        }
    }
}

impl std::str::FromStr for StereoContinuity {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        StereoContinuity::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown stereo continuity '{s}': expected strict or plain"))
    }
}

impl std::fmt::Display for StereoContinuity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Result of matching one rectified image pair.
#[derive(Clone, Debug)]
pub struct RowMatches {
    /// Per left rectified pixel: the matched right rectified column, NaN if none.
    pub right_column: Vec<f32>,
    /// Per left rectified pixel: the right phase slope `dPhi/dc` at the match
    /// (rad/px), the smaller of the bracketing step and the steps beside it.
    pub phase_slope: Vec<f32>,
    /// Per left rectified pixel: the column error the curvature of the right
    /// phase can cause in the inverse linear interpolation (px).
    pub interpolation_px: Vec<f32>,
    pub stats: MatchStats,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MatchStats {
    /// Left pixels with a valid phase.
    pub candidates: usize,
    pub matched: usize,
    /// Phase found in no monotone run of the right row (occluded, invalid or outside).
    pub unmatched: usize,
    /// Of those, phases inside a rising step of the right row that the
    /// continuity rule refused as a discontinuity (a step, an occlusion, or a
    /// noisy pair the rule took for one); the rest lie beyond every valid
    /// right phase of the row or in an invalid stretch of it.
    pub unmatched_at_discontinuity: usize,
    /// Phase found in several runs.
    pub ambiguous: usize,
}

impl MatchStats {
    fn merge(a: Self, b: Self) -> Self {
        Self {
            candidates: a.candidates + b.candidates,
            matched: a.matched + b.matched,
            unmatched: a.unmatched + b.unmatched,
            unmatched_at_discontinuity: a.unmatched_at_discontinuity + b.unmatched_at_discontinuity,
            ambiguous: a.ambiguous + b.ambiguous,
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Run {
    start: usize,
    end: usize,
    phase_start: f32,
    phase_end: f32,
}

/// The monotone runs of a right row, sorted by their first phase, and the
/// rising steps the continuity rule refused (`[low, high]` phase intervals).
fn monotone_runs(
    row: &[f32],
    sigma: &[f32],
    continuity: &Continuity,
    runs: &mut Vec<Run>,
    refused: &mut Vec<(f32, f32)>,
) {
    runs.clear();
    refused.clear();
    let mut start: Option<usize> = None;
    for c in 0..row.len().saturating_sub(1) {
        let (a, b) = (row[c], row[c + 1]);
        let step_sigma = (sigma[c] * sigma[c] + sigma[c + 1] * sigma[c + 1]).sqrt();
        // Rising (false for NaN) and continuous with the steps beside it: an
        // occlusion shows as a step much larger than its flanks.
        let rising = b > a && continuity.allows_flanked(b - a, flanking_step(row, c), step_sigma);
        if b > a && !rising {
            refused.push((a, b));
        }
        match (rising, start) {
            (true, None) => start = Some(c),
            (false, Some(s)) => {
                runs.push(Run { start: s, end: c, phase_start: row[s], phase_end: row[c] });
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        let end = row.len() - 1;
        runs.push(Run { start: s, end, phase_start: row[s], phase_end: row[end] });
    }
    runs.sort_by(|a, b| a.phase_start.total_cmp(&b.phase_start));
}

/// Matches every rectified row: `left` is `rows` rows of `left_width`, `right`
/// `rows` rows of `right_width` (with its phase sigma), both absolute phase in
/// the same radians.
pub fn match_rows(
    left: &[f32],
    left_width: usize,
    right: &[f32],
    right_sigma: &[f32],
    right_width: usize,
    rows: usize,
    continuity: &Continuity,
) -> RowMatches {
    let mut right_column = vec![f32::NAN; left_width * rows];
    let mut phase_slope = vec![f32::NAN; left_width * rows];
    let mut interpolation_px = vec![0f32; left_width * rows];
    let stats = right_column
        .par_chunks_mut(left_width.max(1))
        .zip(phase_slope.par_chunks_mut(left_width.max(1)))
        .zip(interpolation_px.par_chunks_mut(left_width.max(1)))
        .enumerate()
        .map(|(r, ((cols, slopes), curvature))| {
            let l = &left[r * left_width..(r + 1) * left_width];
            let rr = &right[r * right_width..(r + 1) * right_width];
            let rs = &right_sigma[r * right_width..(r + 1) * right_width];
            let (mut runs, mut refused) = (Vec::new(), Vec::new());
            monotone_runs(rr, rs, continuity, &mut runs, &mut refused);
            // prefix_max_end[j] = max phase_end over runs[..=j], to stop the
            // backward candidate scan early.
            let mut prefix_max_end = Vec::with_capacity(runs.len());
            let mut m = f32::NEG_INFINITY;
            for run in &runs {
                m = m.max(run.phase_end);
                prefix_max_end.push(m);
            }
            let mut stats = MatchStats::default();
            for (c, &phi) in l.iter().enumerate() {
                if phi.is_nan() {
                    continue;
                }
                stats.candidates += 1;
                let upto = runs.partition_point(|run| run.phase_start <= phi);
                let mut found: Option<&Run> = None;
                let mut count = 0;
                for j in (0..upto).rev() {
                    if prefix_max_end[j] < phi {
                        break;
                    }
                    if runs[j].phase_end >= phi {
                        count += 1;
                        found = Some(&runs[j]);
                    }
                }
                match (count, found) {
                    (1, Some(run)) => {
                        let seg = &rr[run.start..=run.end];
                        // Largest k with seg[k] <= phi, and the bracket [k, k+1].
                        let k = seg.partition_point(|&v| v <= phi).saturating_sub(1).min(seg.len() - 2);
                        let (p0, p1) = (seg[k], seg[k + 1]);
                        let slope = p1 - p0;
                        let k_abs = run.start + k;
                        cols[c] = k_abs as f32 + (phi - p0) / slope;
                        // For the uncertainty, the gentler of the bracket and
                        // its flanks: one steep noisy pair must not make a
                        // match look more certain than its neighbourhood.
                        slopes[c] = flanking_step(rr, k_abs).map_or(slope, |f| slope.min(f.abs()));
                        // Inverse linear interpolation of a curved phase
                        // Phi = a x + b x^2 / 2 errs by up to b / (8 a) px;
                        // the flanking steps differ by 2 b.
                        let step_at =
                            |i: usize| (i + 1 < rr.len()).then(|| rr[i + 1] - rr[i]).filter(|d| d.is_finite());
                        let before = k_abs.checked_sub(1).and_then(step_at);
                        let after = step_at(k_abs + 1);
                        curvature[c] = match (before, after) {
                            (Some(a), Some(b)) => (b - a).abs() / (16.0 * slope),
                            _ => 0.0,
                        };
                        stats.matched += 1;
                    }
                    (0, _) => {
                        stats.unmatched += 1;
                        if refused.iter().any(|&(lo, hi)| lo <= phi && phi <= hi) {
                            stats.unmatched_at_discontinuity += 1;
                        }
                    }
                    _ => stats.ambiguous += 1,
                }
            }
            stats
        })
        .reduce(MatchStats::default, MatchStats::merge);
    RowMatches { right_column, phase_slope, interpolation_px, stats }
}
