//! When two neighbouring phase samples belong to one continuous surface.
//!
//! Absolute phase grows steadily across a continuous surface; at a step or an
//! occlusion it jumps. A fixed jump limit cannot tell them apart, because the
//! phase step between neighbours depends on the fringe density in the image
//! (about 0.2 rad per pixel at the paper's resolution, over 1.4 rad per pixel at
//! an eighth of it) while an occlusion can hide just a pixel's worth of surface.
//! The yardstick is therefore local: a step between two neighbours is
//! continuous when it differs from the step that flanks it on the same line by
//! at most `factor - 1` of that step (plus a noise allowance). Signs count:
//! across the fringes steps keep the direction of the flanks, along them they
//! are near zero, so a step edge running along the fringes shows even when its
//! phase jump is small. A surface kink changes the step by a factor of about
//! `1 + slope tan(theta)`, which a factor of 1.35 tolerates up to a slope of
//! about 1 (45 degrees) at the paper's 15 degrees; an occlusion changes it by far
//! more at full resolution.

/// sqrt(3), the ratio of a second difference's sigma to a first difference's.
const SQRT_3: f32 = 1.732_050_8;

/// The tolerance of the continuity test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Continuity {
    /// Largest ratio of a step to its flanking step on a continuous surface.
    pub factor: f32,
    /// Noise allowance in standard deviations of the step.
    pub noise_sigmas: f32,
    /// Smallest noise allowance (rad): quantisation and model error.
    pub min_slack_rad: f32,
    /// False: every step between valid neighbours counts as continuous (plain
    /// matching as the paper's Eq. 7, for comparison).
    pub enforced: bool,
}

impl Default for Continuity {
    fn default() -> Self {
        Self { factor: 1.35, noise_sigmas: 4.0, min_slack_rad: 0.03, enforced: true }
    }
}

impl Continuity {
    /// No continuity test: valid neighbours are always continuous.
    pub fn plain() -> Self {
        Self { enforced: false, ..Self::default() }
    }

    /// [`Continuity::allows`] with the flank as found: a step without a valid
    /// flank is continuous only when the test is not enforced.
    #[inline]
    pub fn allows_flanked(&self, step: f32, flank: Option<f32>, step_sigma: f32) -> bool {
        !self.enforced || flank.is_some_and(|f| self.allows(step, f, step_sigma))
    }

    /// Whether a signed `step` (radians) between neighbours whose difference
    /// has standard deviation `step_sigma` is continuous, given the signed
    /// `flank` step beside it on the same line.
    #[inline]
    pub fn allows(&self, step: f32, flank: f32, step_sigma: f32) -> bool {
        !self.enforced || self.within_tolerance(step, flank, step_sigma)
    }

    /// The test of [`Continuity::allows`] whether or not it is enforced; false
    /// for a NaN flank. Branch-free, so loops over many pairs vectorise.
    #[inline(always)]
    pub fn within_tolerance(&self, step: f32, flank: f32, step_sigma: f32) -> bool {
        // `step - flank` is a second difference over three samples
        // (`v2 - 2 v1 + v0`): its sigma is sqrt(3) times a step's.
        let slack = (self.noise_sigmas * SQRT_3 * step_sigma).max(self.min_slack_rad);
        (step - flank).abs() <= (self.factor - 1.0) * flank.abs() + slack
    }
}

/// Of the signed steps flanking the pair `(c, c + 1)` in a row, `(c - 1, c)`
/// and `(c + 1, c + 2)`, the one of smaller magnitude; `None` when neither is
/// valid. The smaller one is the yardstick so that a jump next to another jump
/// (a hidden strip one pixel wide) is still seen as a jump.
#[inline]
pub fn flanking_step(row: &[f32], c: usize) -> Option<f32> {
    flanking_step_by(|i| usize::try_from(i).ok().and_then(|i| row.get(i).copied()), c as isize)
}

/// [`flanking_step`] over any line of samples, `value(i)` being sample i
/// (`None` outside): rows and columns of a map alike.
#[inline]
pub fn flanking_step_by(value: impl Fn(isize) -> Option<f32>, c: isize) -> Option<f32> {
    let step = |a: isize, b: isize| {
        let d = value(b)? - value(a)?;
        d.is_finite().then_some(d)
    };
    // Branches, not the selects of `nearer_flank`: one pixel at a time, on
    // matching's per-pixel path, they were 6 ms faster per run.
    match (step(c - 1, c), step(c + 1, c + 2)) {
        (Some(a), Some(b)) => Some(if a.abs() <= b.abs() { a } else { b }),
        (a, b) => a.or(b),
    }
}

/// The step from `a` to `b`, NaN when either is missing (NaN) or it is not finite.
#[inline(always)]
fn finite_step(a: f32, b: f32) -> f32 {
    let d = b - a;
    if d.is_finite() { d } else { f32::NAN }
}

/// Of the steps before and after a pair (NaN: missing), the one of smaller
/// magnitude (ties: the one before), or the one there is; NaN when neither
/// is: [`flanking_step_by`]'s rule as selects, not branches, so loops over
/// many pairs vectorise (the tests of rectification's flags and matching's
/// runs compare the two).
#[inline(always)]
fn nearer_flank(before: f32, after: f32) -> f32 {
    if before.is_nan() || !after.is_nan() && after.abs() < before.abs() { after } else { before }
}

/// Whether the pair `(line[1], line[2])` of four consecutive samples on a line
/// is continuous: [`Continuity::allows_flanked`] with the nearer of its
/// flanking steps ([`flanking_step_by`]), `step_sigma` the sigma of the pair's
/// step. NaN stands for a missing sample, so there is no branch and loops
/// over a row's pairs vectorise; the caller handles pairs at the ends of a
/// line, whose flanks lie outside it.
#[inline(always)]
pub fn continuous_pair(continuity: &Continuity, line: [f32; 4], step_sigma: f32) -> bool {
    let flank = nearer_flank(finite_step(line[0], line[1]), finite_step(line[2], line[3]));
    let valid = !line[1].is_nan() && !line[2].is_nan();
    // A NaN flank fails the comparison: no flank, no continuity.
    valid & (!continuity.enforced | continuity.within_tolerance(line[2] - line[1], flank, step_sigma))
}
