//! ISO 21920-2 profile parameters of a section profile: the primary (P),
//! roughness (R) and waviness (W) profiles and their height, spacing, hybrid
//! and material-ratio parameters.
//!
//! The profile is first freed of its form (F-operator: the least-squares
//! line), then S-filtered at λs (the Gaussian mean line of ISO 16610-21) into
//! the primary profile P. The L-filter at λc splits P into the waviness W
//! (its mean line) and the roughness R = P - W. Holes stay holes at every
//! stage (normalised convolution). End effects: the first and last λc of
//! the traverse, where the ±λc kernel is incomplete, are run-in and run-out
//! and are not evaluated (ISO 16610-28 allows excluding the affected border;
//! the λc/2 of ISO 4288 leaves 0.8 % of a sine at λc/10 leaking into W).
//! P, R and W are evaluated on the same length so they can be compared.
//!
//! Section parameters (Xp, Xv, Xz) are means over sections of length λc for
//! R (ISO 21920-3: the number of sections is the evaluation length over λc,
//! 5 by default) and over the whole evaluation length for P and W; Xt is
//! over the evaluation length. Default cut-offs come from the measured Ra by
//! the table of ISO 21920-3 (as ISO 4288 Table 1), iterated until the table
//! gives back the cut-off it was measured with.

use crate::engine::length_unit::LengthUnit;
use serde::{Deserialize, Serialize};

use super::areal::HeightMoments;
use super::filter::gaussian_profile_mean_line;
use super::material_ratio::MaterialRatioCurve;

/// Which profile a parameter describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ProfileFamily {
    Primary,
    Roughness,
    Waviness,
}

impl ProfileFamily {
    pub const ALL: [Self; 3] = [Self::Roughness, Self::Waviness, Self::Primary];

    fn letter(self) -> char {
        match self {
            Self::Primary => 'P',
            Self::Roughness => 'R',
            Self::Waviness => 'W',
        }
    }
}

/// The ISO 21920-2 parameter, whatever the profile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ProfileMeasure {
    A,
    Q,
    Sk,
    Ku,
    P,
    V,
    Z,
    T,
    Sm,
    Dq,
    Mr,
    Dc,
}

impl ProfileMeasure {
    pub const ALL: [Self; 12] = [
        Self::A,
        Self::Q,
        Self::Sk,
        Self::Ku,
        Self::P,
        Self::V,
        Self::Z,
        Self::T,
        Self::Sm,
        Self::Dq,
        Self::Mr,
        Self::Dc,
    ];

    fn suffix(self) -> &'static str {
        match self {
            Self::A => "a",
            Self::Q => "q",
            Self::Sk => "sk",
            Self::Ku => "ku",
            Self::P => "p",
            Self::V => "v",
            Self::Z => "z",
            Self::T => "t",
            Self::Sm => "Sm",
            Self::Dq => "dq",
            Self::Mr => "mr",
            Self::Dc => "dc",
        }
    }
}

/// A profile parameter such as Ra, RSm or Wt.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ProfileParameter {
    pub family: ProfileFamily,
    pub measure: ProfileMeasure,
}

impl ProfileParameter {
    /// Every parameter: R first, then W, then P.
    pub fn all() -> Vec<Self> {
        ProfileFamily::ALL
            .into_iter()
            .flat_map(|family| ProfileMeasure::ALL.map(|measure| Self { family, measure }))
            .collect()
    }

    pub fn name(self) -> String {
        format!("{}{}", self.family.letter(), self.measure.suffix())
    }

    /// Whether the parameter is an extreme (Rp, Rv, Rz, Rt and their W and
    /// P): noise alone raises it, so it is stated with its noise floor.
    pub fn is_extreme(self) -> bool {
        matches!(self.measure, ProfileMeasure::P | ProfileMeasure::V | ProfileMeasure::Z | ProfileMeasure::T)
    }

    /// The symbol, matched without regard to case (`rsm` is RSm).
    pub fn from_name(text: &str) -> Option<Self> {
        Self::all().into_iter().find(|p| p.name().eq_ignore_ascii_case(text.trim()))
    }

    /// The symbols of the R profile and the rule for the others, for messages.
    pub fn names() -> String {
        let r: Vec<String> =
            ProfileMeasure::ALL.map(|measure| Self { family: ProfileFamily::Roughness, measure }.name()).to_vec();
        format!("{} and the same with P or W", r.join(", "))
    }

    /// Heights in `um`, RSm in `mm`, Rmr in `%`, shape parameters `1`.
    pub fn unit(self) -> &'static str {
        match self.measure {
            ProfileMeasure::Sk | ProfileMeasure::Ku | ProfileMeasure::Dq => "1",
            ProfileMeasure::Sm => "mm",
            ProfileMeasure::Mr => "%",
            _ => "um",
        }
    }

    /// Whether a value can be negative (skewness), so `<= X` has no lower bound.
    pub fn can_be_negative(self) -> bool {
        self.measure == ProfileMeasure::Sk
    }

    pub fn value(self, p: &ProfileParameters) -> f64 {
        let f = match self.family {
            ProfileFamily::Primary => &p.primary,
            ProfileFamily::Roughness => &p.roughness,
            ProfileFamily::Waviness => &p.waviness,
        };
        match self.measure {
            ProfileMeasure::A => f.a_um,
            ProfileMeasure::Q => f.q_um,
            ProfileMeasure::Sk => f.sk,
            ProfileMeasure::Ku => f.ku,
            ProfileMeasure::P => f.p_um,
            ProfileMeasure::V => f.v_um,
            ProfileMeasure::Z => f.z_um,
            ProfileMeasure::T => f.t_um,
            ProfileMeasure::Sm => f.sm_mm,
            ProfileMeasure::Dq => f.dq,
            ProfileMeasure::Mr => f.mr_percent,
            ProfileMeasure::Dc => f.dc_um,
        }
    }
}

impl Serialize for ProfileParameter {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

impl<'de> Deserialize<'de> for ProfileParameter {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Self::from_name(&text).ok_or_else(|| {
            serde::de::Error::custom(format!("unknown profile parameter '{text}'; known: {}", Self::names()))
        })
    }
}

/// The parameters of one of the P, R, W profiles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FamilyParameters {
    pub a_um: f64,
    pub q_um: f64,
    pub sk: f64,
    pub ku: f64,
    /// Mean over sections of the highest peak.
    pub p_um: f64,
    /// Mean over sections of the deepest valley (positive).
    pub v_um: f64,
    /// Mean over sections of the peak-to-valley height.
    pub z_um: f64,
    /// Peak-to-valley height over the evaluation length.
    pub t_um: f64,
    /// Mean width of the profile elements.
    pub sm_mm: f64,
    /// Root mean square slope.
    pub dq: f64,
    /// Material ratio at `c` above the mean line.
    pub mr_percent: f64,
    /// Height difference between the material ratios of [`RDC_RATIOS_PERCENT`].
    pub dc_um: f64,
}

/// Material ratios of Rdc (%): ISO 21920-2 leaves them to the specification;
/// 20 % and 80 % keep the highest peaks and deepest valleys out.
pub const RDC_RATIOS_PERCENT: (f64, f64) = (20.0, 80.0);

/// The parameters of the three profiles and how they were obtained.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileParameters {
    pub primary: FamilyParameters,
    pub roughness: FamilyParameters,
    pub waviness: FamilyParameters,
    pub ls_mm: Option<f64>,
    pub lc_mm: f64,
    /// Whether λc came from the table (not given).
    pub lc_from_table: bool,
    /// Whether that table was the periodic profiles' (by RSm), not Ra's.
    pub periodic: bool,
    pub evaluation_length_mm: f64,
    /// Sections of the R profile.
    pub sections: usize,
    /// Valid samples evaluated.
    pub samples: usize,
    /// The profiles evaluated, for plotting.
    pub curves: ProfileCurves,
}

/// The profiles of an evaluation, sample by sample as given (NaN where the
/// input had a hole), in µm.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProfileCurves {
    /// The least-squares line the F-operator removed.
    pub form_um: Vec<f64>,
    /// P: the S-filtered profile about that line.
    pub primary_um: Vec<f64>,
    /// W: the L-filter's mean line of P.
    pub waviness_um: Vec<f64>,
    /// R = P - W.
    pub roughness_um: Vec<f64>,
    /// The samples inside the evaluation length (λc run-in and run-out left out).
    pub evaluated: std::ops::Range<usize>,
}

impl ProfileCurves {
    /// The mean line on the measured profile's own heights: form plus W
    /// (what a profilometer draws through the trace).
    pub fn mean_line_um(&self) -> Vec<f64> {
        self.form_um.iter().zip(&self.waviness_um).map(|(f, w)| f + w).collect()
    }
}

/// Why a profile cannot be evaluated.
#[derive(Clone, Debug, PartialEq)]
pub enum ProfileTextureError {
    /// The profile is shorter than it must be for λc (run-in, run-out and one section).
    TooShort {
        length_mm: f64,
        lc_mm: f64,
    },
    TooFewSamples {
        found: usize,
    },
}

impl std::fmt::Display for ProfileTextureError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TooShort { length_mm, lc_mm } => write!(
                f,
                "the profile is {length_mm:.3} mm long, but λc {lc_mm} mm needs at least {:.3} mm (run-in, one \
                 section, run-out); give a smaller lc or a longer profile",
                3.0 * lc_mm
            ),
            Self::TooFewSamples { found } => {
                write!(f, "the profile has {found} valid samples in its evaluation length, at least 8 are needed")
            }
        }
    }
}

impl std::error::Error for ProfileTextureError {}

/// The standard cut-off wavelengths λc (ISO 21920-3), shortest first.
const CUTOFFS_MM: [f64; 5] = [0.08, 0.25, 0.8, 2.5, 8.0];

/// λc from Ra (ISO 21920-3 / ISO 4288 Table 1, non-periodic profiles).
pub fn cutoff_for_ra_mm(ra_um: f64) -> f64 {
    // The upper Ra of each cut-off's row; above the last, the longest.
    const RA_UPPER_UM: [f64; 4] = [0.02, 0.1, 2.0, 10.0];
    CUTOFFS_MM[RA_UPPER_UM.iter().take_while(|upper| ra_um > **upper).count()]
}

/// λc from RSm (ISO 21920-3 / ISO 4288 Table 3, periodic profiles); `None`
/// for an RSm outside the table (no elements, or wider than 4 mm).
pub fn cutoff_for_rsm_mm(rsm_mm: f64) -> Option<f64> {
    match rsm_mm {
        r if !r.is_finite() || r > 4.0 => None,
        // The upper RSm of each cut-off's row; up to 4 mm, the longest.
        r => Some(CUTOFFS_MM[[0.04, 0.13, 0.4, 1.3].iter().take_while(|upper| r > **upper).count()]),
    }
}

/// The default λs for a λc (ISO 21920-3, ISO 3274 Table 1).
pub fn default_ls_mm(lc_mm: f64) -> f64 {
    if lc_mm <= 0.8 + 1e-9 {
        0.0025
    } else if lc_mm <= 2.5 + 1e-9 {
        0.008
    } else {
        0.025
    }
}

/// Least-squares line removed from the valid samples (the F-operator of a
/// nominally straight profile).
fn remove_line(z: &[f64]) -> Vec<f64> {
    let (mut n, mut sx, mut sz, mut sxx, mut sxz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, v) in z.iter().enumerate().filter(|(_, v)| v.is_finite()) {
        let x = i as f64;
        n += 1.0;
        sx += x;
        sz += v;
        sxx += x * x;
        sxz += x * v;
    }
    let det = n * sxx - sx * sx;
    let (b, a) = if det.abs() > 0.0 { ((n * sxz - sx * sz) / det, (sz * sxx - sx * sxz) / det) } else { (0.0, sz / n) };
    z.iter().enumerate().map(|(i, v)| v - a - b * i as f64).collect()
}

/// Parameters of one profile `z` (µm, about its mean line) over `sections`
/// equal sections, sample spacing `step_mm`.
fn family(z: &[f64], step_mm: f64, sections: usize, c_um: f64) -> Option<FamilyParameters> {
    let valid: Vec<f64> = z.iter().copied().filter(|v| v.is_finite()).collect();
    if valid.len() < 8 {
        return None;
    }
    let m = HeightMoments::of(&valid);
    let d: Vec<f64> = z.iter().map(|v| v - m.mean).collect();
    let extremes = |s: &[f64]| {
        s.iter()
            .filter(|v| v.is_finite())
            .fold((f64::NEG_INFINITY, f64::INFINITY), |(hi, lo), v| (hi.max(*v), lo.min(*v)))
    };
    let (hi, lo) = extremes(&d);
    let len = d.len() / sections.max(1);
    let (mut sp, mut sv, mut count) = (0.0, 0.0, 0);
    for s in d.chunks_exact(len.max(1)).take(sections.max(1)) {
        let (h, l) = extremes(s);
        if h.is_finite() && l.is_finite() {
            sp += h;
            sv -= l;
            count += 1;
        }
    }
    let (p, v) = if count > 0 { (sp / count as f64, sv / count as f64) } else { (f64::NAN, f64::NAN) };
    // Rdq: central differences where both neighbours are valid.
    let (mut g2, mut gn) = (0.0, 0usize);
    for w in d.windows(3) {
        if w[0].is_finite() && w[2].is_finite() {
            let g = (w[2] - w[0]) / (2.0 * step_mm * LengthUnit::Mm.um_per_unit());
            g2 += g * g;
            gn += 1;
        }
    }
    let curve = MaterialRatioCurve::new(&d)?;
    let (mr1, mr2) = RDC_RATIOS_PERCENT;
    Some(FamilyParameters {
        a_um: m.mean_abs,
        q_um: m.rms,
        sk: m.skewness,
        ku: m.kurtosis,
        p_um: p,
        v_um: v,
        z_um: p + v,
        t_um: hi - lo,
        sm_mm: mean_element_width_mm(&d, step_mm, 0.1 * (p + v)),
        dq: if gn > 0 { (g2 / gn as f64).sqrt() } else { f64::NAN },
        mr_percent: curve.material_ratio_percent(c_um),
        dc_um: curve.height_at_ratio_um(mr1) - curve.height_at_ratio_um(mr2),
    })
}

/// RSm (ISO 21920-2 §4.4.1): the mean width of the profile elements, an
/// element being a peak above `+hd` and the valley below `-hd` that follows
/// it (height discrimination `hd` = 10 % of Rz, the standard's default).
/// Element borders are the mean-line crossings where the profile starts
/// rising towards a counted peak; a hole ends the current element.
fn mean_element_width_mm(d: &[f64], step_mm: f64, hd: f64) -> f64 {
    #[derive(PartialEq)]
    enum State {
        Unknown,
        Peak,
        Valley,
    }
    let mut state = State::Unknown;
    let mut last_up: Option<f64> = None; // position (samples) of the last upward crossing
    let mut candidate: Option<f64> = None; // upward crossing since the last valley
    let mut widths = Vec::new();
    for i in 0..d.len() {
        let v = d[i];
        if !v.is_finite() {
            state = State::Unknown;
            last_up = None;
            candidate = None;
            continue;
        }
        if i > 0 && d[i - 1].is_finite() && d[i - 1] < 0.0 && v >= 0.0 {
            candidate = Some(i as f64 - 1.0 + d[i - 1] / (d[i - 1] - v));
        }
        if v > hd && state != State::Peak {
            if state == State::Valley
                && let Some(up) = candidate
            {
                if let Some(prev) = last_up {
                    widths.push((up - prev) * step_mm);
                }
                last_up = Some(up);
            }
            state = State::Peak;
        } else if v < -hd && state != State::Valley {
            state = State::Valley;
            candidate = None;
        }
    }
    if widths.is_empty() { f64::NAN } else { widths.iter().sum::<f64>() / widths.len() as f64 }
}

/// The S-filter of a profile evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SFilter {
    /// None: the primary profile is the form-free trace (analytic checks).
    Off,
    /// ISO 21920-3's λs for the λc used ([`default_ls_mm`]).
    Default,
    /// This λs (mm).
    Cutoff(f64),
}

impl SFilter {
    /// `ls_mm` as a spec gives it: absent means the standard's default.
    pub fn from_spec(ls_mm: Option<f64>) -> Self {
        ls_mm.map_or(SFilter::Default, SFilter::Cutoff)
    }

    /// λs in mm for cut-off `lc_mm`, `None` without S-filter.
    pub fn cutoff_mm(self, lc_mm: f64) -> Option<f64> {
        match self {
            SFilter::Off => None,
            SFilter::Default => Some(default_ls_mm(lc_mm)),
            SFilter::Cutoff(ls) => Some(ls),
        }
    }
}

/// Settings of a profile evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProfileSettings {
    pub s_filter: SFilter,
    /// λc (mm); `None` = from the measured Ra (or RSm when `periodic`).
    pub lc_mm: Option<f64>,
    /// A periodic profile: λc, when not given, from RSm rather than Ra.
    pub periodic: bool,
    /// Height c of Rmr(c) above the mean line (µm).
    pub c_um: f64,
}

/// Evaluates `z_um` (samples `step_mm` apart, NaN = hole).
pub fn profile_parameters(
    z_um: &[f64],
    step_mm: f64,
    settings: &ProfileSettings,
) -> Result<ProfileParameters, ProfileTextureError> {
    let length_mm = step_mm * z_um.len().saturating_sub(1) as f64;
    let evaluate = |lc_mm: f64| -> Result<ProfileParameters, ProfileTextureError> {
        if length_mm < 3.0 * lc_mm - 1e-9 {
            return Err(ProfileTextureError::TooShort { length_mm, lc_mm });
        }
        let ls_mm = settings.s_filter.cutoff_mm(lc_mm);
        let form_free = remove_line(z_um);
        let form_um: Vec<f64> = z_um.iter().zip(&form_free).map(|(z, p)| z - p).collect();
        let primary = match ls_mm {
            Some(ls) => gaussian_profile_mean_line(&form_free, step_mm, ls).0,
            None => form_free,
        };
        let (waviness, _) = gaussian_profile_mean_line(&primary, step_mm, lc_mm);
        let roughness: Vec<f64> = primary.iter().zip(&waviness).map(|(p, w)| p - w).collect();
        // Run-in and run-out of λc each; sections of λc in between.
        let skip = (lc_mm / step_mm).ceil() as usize;
        let eval = skip..z_um.len() - skip;
        let evaluation_length_mm = step_mm * eval.len() as f64;
        let sections = ((evaluation_length_mm / lc_mm) + 1e-6).floor().max(1.0) as usize;
        let samples = primary[eval.clone()].iter().filter(|v| v.is_finite()).count();
        let too_few = ProfileTextureError::TooFewSamples { found: samples };
        let c = settings.c_um;
        Ok(ProfileParameters {
            primary: family(&primary[eval.clone()], step_mm, 1, c).ok_or(too_few.clone())?,
            roughness: family(&roughness[eval.clone()], step_mm, sections, c).ok_or(too_few.clone())?,
            waviness: family(&waviness[eval.clone()], step_mm, 1, c).ok_or(too_few)?,
            curves: ProfileCurves {
                form_um,
                primary_um: primary,
                waviness_um: waviness,
                roughness_um: roughness,
                evaluated: eval,
            },
            ls_mm,
            lc_mm,
            lc_from_table: settings.lc_mm.is_none(),
            periodic: settings.periodic,
            evaluation_length_mm,
            sections,
            samples,
        })
    };
    if let Some(lc) = settings.lc_mm {
        return evaluate(lc);
    }
    // ISO 21920-3 / ISO 4288 §7: measure with a cut-off, look Ra (RSm for a
    // periodic profile) up, and measure again until the table returns the
    // cut-off used. Start at 0.8 mm (the table's middle) or the longest the
    // profile allows.
    let longest = CUTOFFS_MM.iter().rev().copied().find(|lc| length_mm >= 3.0 * lc - 1e-9);
    let Some(longest) = longest else {
        return Err(ProfileTextureError::TooShort { length_mm, lc_mm: 0.08 });
    };
    let mut lc = longest.min(0.8);
    let mut tried = Vec::new();
    loop {
        let result = evaluate(lc)?;
        let looked_up = if settings.periodic {
            // No profile elements (a flat trace): Ra's table decides instead.
            cutoff_for_rsm_mm(result.roughness.sm_mm).unwrap_or_else(|| cutoff_for_ra_mm(result.roughness.a_um))
        } else {
            cutoff_for_ra_mm(result.roughness.a_um)
        };
        let next = looked_up.min(longest);
        if next == lc || tried.contains(&next) {
            return Ok(result);
        }
        tried.push(lc);
        lc = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn close(got: f64, want: f64, what: &str) {
        assert!((got - want).abs() <= 0.01 * want.abs().max(1e-3), "{what}: {got}, expected {want}");
    }

    /// z = A sin(2π x / λ) over `length_mm` at `step_mm`.
    fn sine(a_um: f64, lambda_mm: f64, length_mm: f64, step_mm: f64) -> Vec<f64> {
        let n = (length_mm / step_mm).round() as usize + 1;
        (0..n).map(|i| a_um * (2.0 * PI * i as f64 * step_mm / lambda_mm).sin()).collect()
    }

    fn fixed(lc_mm: f64) -> ProfileSettings {
        ProfileSettings { s_filter: SFilter::Off, lc_mm: Some(lc_mm), periodic: false, c_um: 0.0 }
    }

    #[test]
    fn a_sine_over_whole_periods_gives_the_analytic_roughness() {
        // λ = λc/10: the L-filter leaves it whole; the evaluation length
        // 5.6 - 2 x 0.8 = 4.0 mm holds 50 periods in 5 sections.
        let (a, lambda, step) = (0.7, 0.08, 0.0005);
        let p = profile_parameters(&sine(a, lambda, 5.6, step), step, &fixed(0.8)).unwrap();
        let r = p.roughness;
        close(r.a_um, 2.0 * a / PI, "Ra");
        close(r.q_um, a / 2f64.sqrt(), "Rq");
        assert!(r.sk.abs() < 0.01, "Rsk {}", r.sk);
        close(r.ku, 1.5, "Rku");
        close(r.p_um, a, "Rp");
        close(r.v_um, a, "Rv");
        close(r.z_um, 2.0 * a, "Rz");
        close(r.t_um, 2.0 * a, "Rt");
        close(r.sm_mm, lambda, "RSm");
        close(r.dq, a * (2.0 * PI / (lambda * 1000.0)) / 2f64.sqrt(), "Rdq");
        close(r.mr_percent, 50.0, "Rmr(0)");
        close(r.dc_um, 2.0 * a * (0.2 * PI).cos(), "Rdc(20 %, 80 %)");
        assert_eq!((p.sections, p.lc_from_table), (5, false));
        close(p.evaluation_length_mm, 4.0, "evaluation length");
        // The L-filter passes none of a sine at λc/10 into W; what W holds is
        // the F-operator's line: over whole periods on [0, L] the least-squares
        // line of A sin(kx) has slope -12 A / (k L²), so removing it leaves a
        // ramp of that slope, whose RMS over the evaluation length E is s E/√12.
        let (k, length, e) = (2.0 * PI / lambda, 5.6, 4.0);
        close(p.waviness.q_um, 12.0 * a / (k * length * length) * e / 12f64.sqrt(), "Wq (the form line's ramp)");
        close(p.primary.q_um, a / 2f64.sqrt(), "Pq");
    }

    #[test]
    fn the_gaussian_split_keeps_half_at_the_cutoff_and_99_percent_at_a_third() {
        let (a, lc, step) = (1.0, 0.8, 0.001);
        // At λc: W and R each keep half the amplitude. 8 λc long, 6 evaluated.
        let p = profile_parameters(&sine(a, lc, 8.0 * lc, step), step, &fixed(lc)).unwrap();
        close(p.waviness.q_um, 0.5 * a / 2f64.sqrt(), "Wq at λc");
        close(p.roughness.q_um, 0.5 * a / 2f64.sqrt(), "Rq at λc");
        // At λc/3 the roughness keeps over 99 %.
        let p = profile_parameters(&sine(a, lc / 3.0, 5.0 * lc, step), step, &fixed(lc)).unwrap();
        assert!(p.roughness.q_um > 0.99 * a / 2f64.sqrt(), "Rq at λc/3: {}", p.roughness.q_um);
    }

    #[test]
    fn default_cutoffs_follow_the_measured_roughness() {
        let auto = ProfileSettings { s_filter: SFilter::Default, lc_mm: None, periodic: false, c_um: 0.0 };
        // Ra = 0.64 µm: 0.8 mm.
        let p = profile_parameters(&sine(1.0, 0.1, 6.0, 0.0005), 0.0005, &auto).unwrap();
        assert_eq!((p.lc_mm, p.ls_mm, p.lc_from_table), (0.8, Some(0.0025), true));
        // Ra = 0.032 µm at a 0.05 mm wavelength: 0.25 mm, found from the 0.8 mm start.
        let p = profile_parameters(&sine(0.05, 0.05, 6.0, 0.0005), 0.0005, &auto).unwrap();
        assert_eq!(p.lc_mm, 0.25);
        // Ra = 4.5 µm of a 0.4 mm wave on a 20 mm traverse (4.2 µm at the 0.8 mm start): 2.5 mm, λs 8 µm.
        let p = profile_parameters(&sine(7.0, 0.4, 20.0, 0.002), 0.002, &auto).unwrap();
        assert_eq!((p.lc_mm, p.ls_mm), (2.5, Some(0.008)));
        assert_eq!(cutoff_for_ra_mm(0.01), 0.08);
        assert_eq!(cutoff_for_ra_mm(20.0), 8.0);
        let e = profile_parameters(&sine(1.0, 0.1, 1.0, 0.001), 0.001, &fixed(0.8)).unwrap_err();
        assert!(e.to_string().contains("needs at least 2.400 mm"), "{e}");
    }

    /// ISO 21920-3's second route: a periodic profile's λc comes from RSm.
    /// A 0.1 mm sine of 1 µm has Ra 0.64 µm (0.8 mm by Ra's table) but RSm
    /// 0.1 mm (0.25 mm by RSm's); a 0.3 mm sine gives 0.8 mm either way.
    /// Each row's edges of ISO 4288 Tables 1 and 3: an upper bound belongs
    /// to its row, anything above it to the next.
    #[test]
    fn the_cutoff_tables_change_rows_just_above_each_upper_bound() {
        let ra = [(0.02, 0.08), (0.0201, 0.25), (0.1, 0.25), (0.1001, 0.8), (2.0, 0.8), (2.001, 2.5)];
        for (ra_um, lc) in ra.into_iter().chain([(10.0, 2.5), (10.01, 8.0)]) {
            assert_eq!(cutoff_for_ra_mm(ra_um), lc, "Ra {ra_um}");
        }
        let rsm = [(0.04, 0.08), (0.0401, 0.25), (0.13, 0.25), (0.1301, 0.8), (0.4, 0.8), (0.4001, 2.5)];
        for (rsm_mm, lc) in rsm.into_iter().chain([(1.3, 2.5), (1.3001, 8.0), (4.0, 8.0)]) {
            assert_eq!(cutoff_for_rsm_mm(rsm_mm), Some(lc), "RSm {rsm_mm}");
        }
    }

    #[test]
    fn a_periodic_profile_takes_its_cutoff_from_rsm() {
        let periodic = ProfileSettings { s_filter: SFilter::Default, lc_mm: None, periodic: true, c_um: 0.0 };
        let auto = ProfileSettings { periodic: false, ..periodic };
        let z = sine(1.0, 0.1, 6.0, 0.0005);
        let by_ra = profile_parameters(&z, 0.0005, &auto).unwrap();
        let by_rsm = profile_parameters(&z, 0.0005, &periodic).unwrap();
        assert_eq!((by_ra.lc_mm, by_rsm.lc_mm), (0.8, 0.25));
        assert!(by_rsm.periodic && by_rsm.lc_from_table && !by_ra.periodic);
        close(by_rsm.roughness.sm_mm, 0.1, "RSm at λc 0.25 mm");
        let z = sine(1.0, 0.3, 6.0, 0.0005);
        assert_eq!(profile_parameters(&z, 0.0005, &periodic).unwrap().lc_mm, 0.8);
        assert_eq!(cutoff_for_rsm_mm(0.02), Some(0.08));
        assert_eq!(cutoff_for_rsm_mm(1.0), Some(2.5));
        assert_eq!(cutoff_for_rsm_mm(f64::NAN), None);
        assert_eq!(cutoff_for_rsm_mm(5.0), None);
    }

    #[test]
    fn holes_and_names() {
        let (a, lambda, step) = (0.5, 0.08, 0.0005);
        let mut z = sine(a, lambda, 4.8, step);
        for v in z.iter_mut().skip(3000).take(40) {
            *v = f64::NAN;
        }
        let p = profile_parameters(&z, step, &fixed(0.8)).unwrap();
        assert!((p.roughness.q_um - a / 2f64.sqrt()).abs() < 0.01 * a, "Rq with a hole {}", p.roughness.q_um);
        for name in ["Ra", "RSm", "rsm", "Wt", "Pdq", "Rmr", "Rdc"] {
            assert!(ProfileParameter::from_name(name).is_some(), "{name}");
        }
        let rsm = ProfileParameter::from_name("rsm").unwrap();
        assert_eq!((rsm.name(), rsm.unit()), ("RSm".to_string(), "mm"));
        assert_eq!(ProfileParameter::from_name("Rku").unwrap().unit(), "1");
        assert!(ProfileParameter::from_name("Rx").is_none());
        assert_eq!(ProfileParameter::all().len(), 36);
        let json = serde_json::to_string(&rsm).unwrap();
        assert_eq!(json, "\"RSm\"");
        assert_eq!(serde_json::from_str::<ProfileParameter>(&json).unwrap(), rsm);
    }
}
