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
//! rejected rather than guessed). With the strict continuity rule a run may
//! then be extended by up to a pixel towards the edge where its surface stops,
//! for left pixels that continue their matched neighbour's surface
//! ([`extend_runs_to_edges`]).

use rayon::prelude::*;

use super::buffers::filled;
use super::continuity::{Continuity, continuous_pair, flanking_step};

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
    /// Of `matched`: left pixels matched by extending a monotone run of the
    /// right row by at most [`MAX_EDGE_EXTENSION_PX`] towards the edge it
    /// stops at (strict continuity only; see [`extend_runs_to_edges`]).
    pub extended_to_edge: usize,
}

impl MatchStats {
    fn merge(a: Self, b: Self) -> Self {
        Self {
            candidates: a.candidates + b.candidates,
            matched: a.matched + b.matched,
            unmatched: a.unmatched + b.unmatched,
            unmatched_at_discontinuity: a.unmatched_at_discontinuity + b.unmatched_at_discontinuity,
            ambiguous: a.ambiguous + b.ambiguous,
            extended_to_edge: a.extended_to_edge + b.extended_to_edge,
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

/// The sigma of the step between two samples with these sigmas.
#[inline(always)]
fn step_sigma(a: f32, b: f32) -> f32 {
    (a * a + b * b).sqrt()
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
    // Whether each step (c, c + 1) rises and is continuous with the steps
    // beside it (an occlusion shows as a step much larger than its flanks),
    // in a branch-free pass that vectorises; the two end steps, whose flank
    // outside the row reads NaN, one at a time with the same test.
    let steps = row.len().saturating_sub(1);
    let at = |i: isize| usize::try_from(i).ok().and_then(|i| row.get(i).copied()).unwrap_or(f32::NAN);
    let mut rising = vec![false; steps];
    for c in [0, steps.saturating_sub(1)].into_iter().filter(|&c| c < steps) {
        let (a, b) = (row[c], row[c + 1]);
        let line = [at(c as isize - 1), a, b, at(c as isize + 2)];
        rising[c] = b > a && continuous_pair(continuity, line, step_sigma(sigma[c], sigma[c + 1]));
    }
    if steps >= 3 {
        let inner = steps - 2;
        let (r0, r1, r2, r3) = (&row[..inner], &row[1..=inner], &row[2..inner + 2], &row[3..inner + 3]);
        let (s1, s2) = (&sigma[1..=inner], &sigma[2..inner + 2]);
        for (k, up) in rising[1..=inner].iter_mut().enumerate() {
            let sigma_step = step_sigma(s1[k], s2[k]);
            *up = (r2[k] > r1[k]) & continuous_pair(continuity, [r0[k], r1[k], r2[k], r3[k]], sigma_step);
        }
    }
    let mut start: Option<usize> = None;
    for (c, &rising) in rising.iter().enumerate() {
        let (a, b) = (row[c], row[c + 1]);
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

/// Steps walked from a hint before bisecting the rest.
const BRACKET_WALK: usize = 8;

/// The start `k` of the bracket `[k, k + 1]` of `phi` in the rising `seg`
/// (at least two samples): the largest `k` with `seg[k] <= phi`, kept at most
/// `seg.len() - 2`. `hint`, a bracket start of the same run for a smaller
/// phase, is walked on from instead of bisecting the whole run; the answer is
/// the same either way.
#[inline]
fn bracket_start(seg: &[f32], phi: f32, hint: Option<usize>) -> usize {
    let last = seg.len() - 2;
    let after = |k: usize| k + seg[k..].partition_point(|&v| v <= phi);
    let past = match hint {
        Some(h) if h < seg.len() && seg[h] <= phi => {
            let mut k = h;
            let mut walked = 0;
            while k < seg.len() - 1 && seg[k + 1] <= phi && walked < BRACKET_WALK {
                k += 1;
                walked += 1;
            }
            if walked == BRACKET_WALK { after(k) } else { k + 1 }
        }
        _ => after(0),
    };
    past.saturating_sub(1).min(last)
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
    let mut right_column = filled(left_width * rows, f32::NAN);
    let mut phase_slope = filled(left_width * rows, f32::NAN);
    let mut interpolation_px = filled(left_width * rows, 0f32);
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
            let mut state = vec![MatchState::NoPhase; l.len()];
            // The bracket of the previous match: along a row the left phase
            // mostly rises by about one right pixel's step, so the next
            // bracket is found a step or two on instead of by bisection.
            let mut last_bracket: Option<(usize, usize)> = None;
            let mut last_upto = 0;
            for (c, &phi) in l.iter().enumerate() {
                if phi.is_nan() {
                    continue;
                }
                stats.candidates += 1;
                // Runs starting at or below phi: along a row mostly the same
                // count as for the pixel before, which two comparisons
                // confirm; a search over the row's runs otherwise.
                let starts_below = |k: usize| runs[k].phase_start <= phi;
                let upto = if (last_upto == 0 || starts_below(last_upto - 1))
                    && (last_upto == runs.len() || !starts_below(last_upto))
                {
                    last_upto
                } else {
                    runs.partition_point(|run| run.phase_start <= phi)
                };
                last_upto = upto;
                let mut found: Option<usize> = None;
                let mut count = 0;
                for j in (0..upto).rev() {
                    if prefix_max_end[j] < phi {
                        break;
                    }
                    if runs[j].phase_end >= phi {
                        count += 1;
                        found = Some(j);
                    }
                }
                match (count, found) {
                    (1, Some(j)) => {
                        let run = &runs[j];
                        state[c] = MatchState::InRun(j);
                        let seg = &rr[run.start..=run.end];
                        // Largest k with seg[k] <= phi, and the bracket [k, k+1].
                        let k = bracket_start(seg, phi, last_bracket.filter(|b| b.0 == j).map(|b| b.1));
                        last_bracket = Some((j, k));
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
                        let at_discontinuity = refused.iter().any(|&(lo, hi)| lo <= phi && phi <= hi);
                        if at_discontinuity {
                            stats.unmatched_at_discontinuity += 1;
                        }
                        state[c] = MatchState::Unmatched { at_discontinuity };
                    }
                    _ => stats.ambiguous += 1,
                }
            }
            if continuity.enforced {
                let mut row = RowMatch { cols, slopes, curvature, state: &mut state, stats: &mut stats };
                extend_runs_to_edges(l, rr, rs, &runs, continuity, &mut row);
            }
            stats
        })
        .reduce(MatchStats::default, MatchStats::merge);
    RowMatches { right_column, phase_slope, interpolation_px, stats }
}

/// How far beyond its last valid sample a monotone run of the right row may
/// be extended (px). The strict resampling leaves the rectified pixels whose
/// cell straddles a step invalid, so a run stops up to a pixel short of the
/// edge that ends its surface; a point of that surface between the last
/// sample and the edge is still measured by extending the run.
pub const MAX_EDGE_EXTENSION_PX: f32 = 1.0;

/// Largest departure of a run's last steps from their mean, as a share of
/// it, for the run to be extended: linear extrapolation of a curved phase (a
/// sphere towards its silhouette) errs by the curvature times `d (d + 1) / 2`.
const MAX_EDGE_CURVATURE_SHARE: f32 = 0.1;

#[derive(Clone, Copy, Debug, PartialEq)]
enum MatchState {
    NoPhase,
    /// Matched inside the run of this index.
    InRun(usize),
    /// Matched by extending a run: no evidence for a further neighbour, so
    /// extensions never chain.
    Extended,
    Unmatched {
        at_discontinuity: bool,
    },
}

/// One row's match outputs, as [`match_rows`] fills them.
struct RowMatch<'a> {
    cols: &'a mut [f32],
    slopes: &'a mut [f32],
    curvature: &'a mut [f32],
    state: &'a mut [MatchState],
    stats: &'a mut MatchStats,
}

/// Matches unmatched left pixels that continue the surface of their matched
/// left-row neighbour past the end of that neighbour's right run.
///
/// A left pixel is taken as the same surface as its neighbour only when the
/// left row's phase step between them is continuous with the step before
/// ([`Continuity`]): at a step edge or an occlusion the left row jumps too, so
/// a pixel seen by the left camera on the far side of a step (hidden from the
/// right) is not put on the near surface. The right run is extended by the
/// mean of its last steps, only where they are steady (a straight phase, not
/// the steep curve before a silhouette), the noise is small against the slope,
/// and by at most [`MAX_EDGE_EXTENSION_PX`].
/// Extending a surface's own phase field gives that surface's point even where
/// the right camera no longer sees it, so no value is made up across the edge.
fn extend_runs_to_edges(
    l: &[f32],
    rr: &[f32],
    rs: &[f32],
    runs: &[Run],
    continuity: &Continuity,
    row: &mut RowMatch<'_>,
) {
    let n = l.len();
    // Towards higher phase: the neighbour on the left, the run's top end.
    for c in 2..n {
        let (MatchState::Unmatched { .. }, MatchState::InRun(j)) = (row.state[c], row.state[c - 1]) else { continue };
        let run = runs[j];
        let steps = edge_steps(run.end - run.start, |i| rr[run.end - i] - rr[run.end - i - 1]);
        let Some((slope, curvature)) = steady_slope(&steps.0[..steps.1], rs[run.end]) else { continue };
        let d = (l[c] - rr[run.end]) / slope;
        let left = (l[c] - l[c - 1], l[c - 1] - l[c - 2]);
        if let Some(extra) = edge_extension(left, slope, curvature, d, rs[run.end], continuity) {
            row.take(c, run.end as f32 + d, slope, extra);
        }
    }
    // Towards lower phase: the neighbour on the right, the run's first sample.
    for c in (0..n.saturating_sub(2)).rev() {
        let (MatchState::Unmatched { .. }, MatchState::InRun(j)) = (row.state[c], row.state[c + 1]) else { continue };
        let run = runs[j];
        let steps = edge_steps(run.end - run.start, |i| rr[run.start + i + 1] - rr[run.start + i]);
        let Some((slope, curvature)) = steady_slope(&steps.0[..steps.1], rs[run.start]) else { continue };
        let d = (rr[run.start] - l[c]) / slope;
        let left = (l[c + 1] - l[c], l[c + 2] - l[c + 1]);
        if let Some(extra) = edge_extension(left, slope, curvature, d, rs[run.start], continuity) {
            row.take(c, run.start as f32 - d, slope, extra);
        }
    }
}

/// Steps of a run read from the edge inwards (`step(0)` the one at the
/// edge), at most [`EDGE_SLOPE_STEPS`] of its `run_steps`.
fn edge_steps(run_steps: usize, step: impl Fn(usize) -> f32) -> ([f32; EDGE_SLOPE_STEPS], usize) {
    let count = run_steps.min(EDGE_SLOPE_STEPS);
    let mut steps = [0.0; EDGE_SLOPE_STEPS];
    for (i, s) in steps.iter_mut().enumerate().take(count) {
        *s = step(i);
    }
    (steps, count)
}

/// Largest sigma of a phase step, as a share of the slope, for a run to be
/// extended ([`edge_extension`]).
const MAX_EDGE_NOISE_SHARE: f32 = 0.25;

/// Steps averaged for the slope a run is extended by: one noisy step would
/// put its noise into every extended column.
const EDGE_SLOPE_STEPS: usize = 3;

/// The mean of a run's last steps and their change per pixel (the phase's
/// curvature), where the steps are steady: each within
/// [`MAX_EDGE_CURVATURE_SHARE`] of the mean plus two sigma of a step's noise.
fn steady_slope(steps: &[f32], sigma: f32) -> Option<(f32, f32)> {
    if steps.len() < 2 {
        return None;
    }
    let slope = steps.iter().sum::<f32>() / steps.len() as f32;
    let slack = MAX_EDGE_CURVATURE_SHARE * slope + 2.0 * std::f32::consts::SQRT_2 * sigma;
    let steady = slope > 0.0 && steps.iter().all(|s| (s - slope).abs() <= slack);
    let curvature = (steps[0] - steps[steps.len() - 1]).abs() / (steps.len() - 1) as f32;
    steady.then_some((slope, curvature))
}

/// Whether a run may be extended by `d` px for a left pixel whose step to
/// its matched neighbour and the step on the neighbour's far side are `left`;
/// `Some` of the column error that linear extrapolation of a phase with this
/// curvature (rad/px^2) may make.
fn edge_extension(
    left: (f32, f32),
    slope: f32,
    curvature: f32,
    d: f32,
    sigma: f32,
    continuity: &Continuity,
) -> Option<f32> {
    let (left_step, left_flank) = left;
    // Where a step's noise reaches a quarter of the slope, the continuity test
    // can no longer tell a pixel's worth of hidden surface from noise, so the
    // left row's evidence that the pixel continues the surface is void.
    let step_sigma = std::f32::consts::SQRT_2 * sigma;
    let ok = step_sigma <= MAX_EDGE_NOISE_SHARE * slope
        && d > 0.0
        && d <= MAX_EDGE_EXTENSION_PX
        && left_step.is_finite()
        && left_flank.is_finite()
        && continuity.allows(left_step, left_flank, step_sigma);
    ok.then(|| curvature * d * (d + 1.0) / (2.0 * slope))
}

impl RowMatch<'_> {
    fn take(&mut self, c: usize, column: f32, slope: f32, interpolation_px: f32) {
        let MatchState::Unmatched { at_discontinuity } = self.state[c] else { return };
        self.cols[c] = column;
        self.slopes[c] = slope;
        self.curvature[c] = interpolation_px;
        self.state[c] = MatchState::Extended;
        self.stats.unmatched -= 1;
        self.stats.unmatched_at_discontinuity -= usize::from(at_discontinuity);
        self.stats.matched += 1;
        self.stats.extended_to_edge += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A right row of rising runs at overlapping phases, split by holes,
        /// and a left row whose phases jump back and forth: each left phase
        /// inside exactly one run is matched to where that run reaches it,
        /// one inside several is ambiguous, one inside none unmatched, as
        /// the runs containing it say, whatever the pixel before found.
        #[test]
        fn every_left_phase_is_matched_by_the_runs_that_contain_it(
            runs in prop::collection::vec((-5.0f32..5.0, prop::collection::vec(0.05f32..1.0, 1..12)), 1..8),
            left in prop::collection::vec(-6.0f32..12.0, 1..64),
        ) {
            let mut right = Vec::new();
            let mut ranges = Vec::new();
            for (start, steps) in &runs {
                let first = right.len();
                right.push(*start);
                for s in steps {
                    let next = right[right.len() - 1] + s;
                    right.push(next);
                }
                ranges.push((first, right.len() - 1));
                right.push(f32::NAN);
            }
            let sigma = vec![0.001f32; right.len()];
            let out = match_rows(&left, left.len(), &right, &sigma, right.len(), 1, &Continuity::plain());
            let (mut matched, mut ambiguous, mut unmatched) = (0, 0, 0);
            for (c, &phi) in left.iter().enumerate() {
                let containing: Vec<_> =
                    ranges.iter().filter(|&&(a, b)| right[a] <= phi && phi <= right[b]).collect();
                match *containing.as_slice() {
                    [] => unmatched += 1,
                    [&(a, b)] => {
                        matched += 1;
                        let col = out.right_column[c];
                        prop_assert!(col >= a as f32 && col <= b as f32, "pixel {c}: column {col} outside {a}..={b}");
                        let k = (col.floor() as usize).min(b - 1);
                        let at = right[k] + (col - k as f32) * (right[k + 1] - right[k]);
                        prop_assert!((at - phi).abs() < 1e-4, "pixel {c}: phase {at} at column {col}, wanted {phi}");
                    }
                    _ => ambiguous += 1,
                }
            }
            prop_assert_eq!((out.stats.matched, out.stats.ambiguous, out.stats.unmatched), (matched, ambiguous, unmatched));
        }

        /// The runs and the refused rising steps are those of the test applied
        /// one step at a time with `flanking_step`, on rows of every length
        /// (the end steps included) with holes, falls and jumps, enforced or not.
        #[test]
        fn monotone_runs_are_the_rising_continuous_steps_one_at_a_time(
            samples in prop::collection::vec((0u8..10, 0.0f32..1.0, 0.001f32..0.05), 0..40),
            enforced in any::<bool>(),
        ) {
            let mut row = Vec::new();
            let mut sigma = Vec::new();
            let mut phase = 0.0f32;
            for &(kind, size, s) in &samples {
                phase += match kind {
                    0 => -size,
                    1 => 3.0 + 5.0 * size,
                    _ => 0.2 + 0.05 * size,
                };
                row.push(if kind == 2 { f32::NAN } else { phase });
                sigma.push(s);
            }
            let continuity = if enforced { Continuity::default() } else { Continuity::plain() };
            let (mut runs, mut refused) = (Vec::new(), Vec::new());
            monotone_runs(&row, &sigma, &continuity, &mut runs, &mut refused);

            let mut expected_runs = Vec::new();
            let mut expected_refused = Vec::new();
            let mut start = None;
            for c in 0..row.len().saturating_sub(1) {
                let (a, b) = (row[c], row[c + 1]);
                let step_sigma = (sigma[c] * sigma[c] + sigma[c + 1] * sigma[c + 1]).sqrt();
                let rising = b > a && continuity.allows_flanked(b - a, flanking_step(&row, c), step_sigma);
                if b > a && !rising {
                    expected_refused.push((a, b));
                }
                match (rising, start) {
                    (true, None) => start = Some(c),
                    (false, Some(s)) => {
                        expected_runs.push((s, c));
                        start = None;
                    }
                    _ => {}
                }
            }
            if let Some(s) = start {
                expected_runs.push((s, row.len() - 1));
            }
            expected_runs.sort_by(|a, b| row[a.0].total_cmp(&row[b.0]));
            let found: Vec<(usize, usize)> = runs.iter().map(|r| (r.start, r.end)).collect();
            prop_assert_eq!(found, expected_runs);
            prop_assert_eq!(refused, expected_refused);
        }

        /// Walking on from any earlier bracket of the run finds the bracket
        /// that bisecting the whole run finds, near the hint or far past it.
        #[test]
        fn a_hinted_bracket_is_the_bisected_one(
            steps in prop::collection::vec(0.01f32..3.0, 1..200),
            at in 0.0f64..1.0,
            hint_at in 0.0f64..1.0,
        ) {
            let mut seg = vec![-1.0f32];
            for s in &steps {
                let next = seg[seg.len() - 1] + s;
                seg.push(next);
            }
            let (lo, hi) = (seg[0] - 0.5, seg[seg.len() - 1] + 0.5);
            let phi = lo + (hi - lo) * at as f32;
            let expected = seg.partition_point(|&v| v <= phi).saturating_sub(1).min(seg.len() - 2);
            prop_assert_eq!(bracket_start(&seg, phi, None), expected);
            let hint = ((seg.len() - 1) as f64 * hint_at) as usize;
            prop_assert_eq!(bracket_start(&seg, phi, Some(hint)), expected);
        }
    }
}
