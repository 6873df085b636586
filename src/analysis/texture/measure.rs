//! A texture measurement on a region of a height map: the region's nodes
//! (everything else a hole), the F-operator, the S-filter at λs and the
//! L-filter at λc (ISO 25178-3 §3: the S-F or S-L surface), then the areal
//! parameters of ISO 25178-2, each with the unit it is reported in and a note
//! where the value is near what the measurement can resolve.
//!
//! Also the S-filtered flatness of ISO 12781-2 §4 (the Gaussian filter of
//! ISO 16610-61 before the least-squares reference plane), so a flatness is
//! the surface's and not the noise's peak-to-valley.

use crate::engine::control::RunControl;
use serde::{Deserialize, Serialize};

use super::areal::{ArealParameters, MaterialRatioPoints, areal_parameters};
use super::filter::{
    FilterReport, FormRemoval, gaussian_areal_mean_surface, gaussian_areal_mean_surface_with_coverage, remove_form,
};
use super::spatial::{SpatialParameters, spatial_parameters};
use crate::analysis::error::AnalysisError;
use crate::analysis::height_map::HeightMap;

/// The areal parameters a texture measurement reports, in the order of
/// ISO 25178-2 (height, hybrid, material ratio, volume).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum ArealParameter {
    Sq,
    Ssk,
    Sku,
    Sp,
    Sv,
    Sz,
    Sa,
    Sdq,
    Sdr,
    Smr,
    Smc,
    Sk,
    Spk,
    Svk,
    Smr1,
    Smr2,
    Vmp,
    Vmc,
    Vvc,
    Vvv,
    Sal,
    Str,
    Std,
}

impl ArealParameter {
    pub const ALL: [Self; 23] = [
        Self::Sq,
        Self::Ssk,
        Self::Sku,
        Self::Sp,
        Self::Sv,
        Self::Sz,
        Self::Sa,
        Self::Sdq,
        Self::Sdr,
        Self::Smr,
        Self::Smc,
        Self::Sk,
        Self::Spk,
        Self::Svk,
        Self::Smr1,
        Self::Smr2,
        Self::Vmp,
        Self::Vmc,
        Self::Vvc,
        Self::Vvv,
        Self::Sal,
        Self::Str,
        Self::Std,
    ];

    /// The ISO 25178-2 symbol.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sq => "Sq",
            Self::Ssk => "Ssk",
            Self::Sku => "Sku",
            Self::Sp => "Sp",
            Self::Sv => "Sv",
            Self::Sz => "Sz",
            Self::Sa => "Sa",
            Self::Sdq => "Sdq",
            Self::Sdr => "Sdr",
            Self::Smr => "Smr",
            Self::Smc => "Smc",
            Self::Sk => "Sk",
            Self::Spk => "Spk",
            Self::Svk => "Svk",
            Self::Smr1 => "Smr1",
            Self::Smr2 => "Smr2",
            Self::Vmp => "Vmp",
            Self::Vmc => "Vmc",
            Self::Vvc => "Vvc",
            Self::Vvv => "Vvv",
            Self::Sal => "Sal",
            Self::Str => "Str",
            Self::Std => "Std",
        }
    }

    /// The symbol, matched without regard to case (`sa` is Sa).
    pub fn from_name(text: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name().eq_ignore_ascii_case(text.trim()))
    }

    /// The symbols, comma-separated, for messages.
    pub fn names() -> String {
        Self::ALL.map(Self::name).join(", ")
    }

    /// Whether the parameter is an extreme (a highest peak, a deepest
    /// valley, their sum): noise alone raises it, so its value is stated
    /// with the noise floor beside it.
    pub fn is_extreme(self) -> bool {
        matches!(self, Self::Sp | Self::Sv | Self::Sz)
    }

    /// Unit of the reported value: heights and volumes per area (µm³/µm²)
    /// in `um`, Sdr and material ratios in `%`, the shape parameters and Str
    /// `1`, Sal `mm`, Std `deg`.
    pub fn unit(self) -> &'static str {
        match self {
            Self::Ssk | Self::Sku | Self::Sdq | Self::Str => "1",
            Self::Sal => "mm",
            Self::Std => "deg",
            Self::Sdr | Self::Smr | Self::Smr1 | Self::Smr2 => "%",
            _ => "um",
        }
    }

    /// Whether a plain value of this parameter can be negative, so a one-sided
    /// `<= X` limit has no natural lower bound (0) and needs a nominal.
    pub fn can_be_negative(self) -> bool {
        matches!(self, Self::Ssk | Self::Smc)
    }

    pub fn value(self, r: &TextureResult) -> f64 {
        self.value_of(&r.parameters, r.spatial)
    }

    /// The parameter from the height parameters and, for Sal, Str and Std,
    /// the spatial ones (NaN without them).
    pub fn value_of(self, p: &super::areal::ArealParameters, s: Option<SpatialParameters>) -> f64 {
        match self {
            Self::Sal => s.map_or(f64::NAN, |s| s.sal_mm),
            Self::Str => s.map_or(f64::NAN, |s| s.str_ratio),
            Self::Std => s.map_or(f64::NAN, |s| s.std_deg),
            Self::Sq => p.sq_um,
            Self::Ssk => p.ssk,
            Self::Sku => p.sku,
            Self::Sp => p.sp_um,
            Self::Sv => p.sv_um,
            Self::Sz => p.sz_um,
            Self::Sa => p.sa_um,
            Self::Sdq => p.sdq,
            Self::Sdr => p.sdr_percent,
            Self::Smr => p.smr_percent,
            Self::Smc => p.smc_um,
            Self::Sk => p.core.sk_um,
            Self::Spk => p.core.spk_um,
            Self::Svk => p.core.svk_um,
            Self::Smr1 => p.core.smr1_percent,
            Self::Smr2 => p.core.smr2_percent,
            Self::Vmp => p.vmp_um,
            Self::Vmc => p.vmc_um,
            Self::Vvc => p.vvc_um,
            Self::Vvv => p.vvv_um,
        }
    }
}

/// The operators that make the scale-limited surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureSettings {
    pub form: FormRemoval,
    /// S-filter nesting index λs (mm); `None` = no S-filter.
    pub ls_mm: Option<f64>,
    /// L-filter nesting index λc (mm); `None` = the S-F surface.
    pub lc_mm: Option<f64>,
    pub points: MaterialRatioPoints,
}

/// The height noise a texture value is compared with, and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightNoise {
    pub sigma_um: f64,
    pub source: String,
}

/// A rectangular piece of a map, heights in µm, nodes outside the selection NaN.
#[derive(Clone, Debug, PartialEq)]
pub struct Crop {
    pub z_um: Vec<f64>,
    pub width: usize,
    pub height: usize,
    pub pitch_mm: f64,
    /// The map node (column, row) of the crop's first node.
    pub origin: [usize; 2],
}

/// The bounding box of the selected nodes of `map` (`mask` as from
/// [`crate::analysis::region::region_mask`]); unselected nodes become holes.
/// `None` when nothing is selected.
pub fn crop(map: &HeightMap, mask: &[bool]) -> Option<Crop> {
    let scale = map.unit.um_per_unit();
    let (mut c0, mut c1, mut r0, mut r1) = (usize::MAX, 0, usize::MAX, 0);
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        let (c, r) = (i % map.width, i / map.width);
        (c0, c1, r0, r1) = (c0.min(c), c1.max(c), r0.min(r), r1.max(r));
    }
    if c0 > c1 {
        return None;
    }
    let (width, height) = (c1 - c0 + 1, r1 - r0 + 1);
    let mut z_um = Vec::with_capacity(width * height);
    for r in r0..=r1 {
        for c in c0..=c1 {
            let i = r * map.width + c;
            z_um.push(if mask[i] { f64::from(map.z[i]) * scale } else { f64::NAN });
        }
    }
    Some(Crop { z_um, width, height, pitch_mm: map.pitch_mm, origin: [c0, r0] })
}

/// The scale-limited surface and what its filters saw.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleLimited {
    pub z_um: Vec<f64>,
    pub s_filter: Option<FilterReport>,
    pub l_filter: Option<FilterReport>,
}

/// F-operator, then S-filter, then L-filter (ISO 25178-3 §3.1, Fig. 1). The
/// F-operator comes first so the Gaussian filters see no tilt: at a border,
/// where the kernel is renormalised (ISO 16610-28 zero-order correction), a
/// tilt would bend the mean surface. `label` names the selection in errors.
pub fn scale_limited_surface(
    crop: &Crop,
    settings: &TextureSettings,
    label: &str,
) -> Result<ScaleLimited, AnalysisError> {
    let valid = crop.z_um.iter().filter(|v| v.is_finite()).count();
    let needed = match settings.form {
        FormRemoval::None => 2,
        FormRemoval::Plane => 3,
        FormRemoval::Polynomial(n) => (n as usize + 1) * (n as usize + 2) / 2,
    }
    .max(2);
    let too_few = || AnalysisError::TooFewSamples { region: label.to_string(), found: valid, needed };
    if valid < needed {
        return Err(too_few());
    }
    let mut z = remove_form(&crop.z_um, crop.width, crop.height, settings.form).ok_or_else(too_few)?;
    let mut s_filter = None;
    if let Some(ls) = settings.ls_mm {
        let (mean, report) = gaussian_areal_mean_surface(&z, crop.width, crop.height, crop.pitch_mm, ls);
        z = mean;
        s_filter = Some(report);
    }
    let mut l_filter = None;
    if let Some(lc) = settings.lc_mm {
        let (mean, report) = gaussian_areal_mean_surface(&z, crop.width, crop.height, crop.pitch_mm, lc);
        z.iter_mut().zip(&mean).for_each(|(v, m)| *v -= m);
        l_filter = Some(report);
    }
    Ok(ScaleLimited { z_um: z, s_filter, l_filter })
}

/// Height noise estimated from the map itself: for white noise of σ the
/// second difference `z[i-1] - 2 z[i] + z[i+1]` along a row has a standard
/// deviation of √6 σ, while a smooth surface sampled finely contributes
/// almost nothing; the median absolute value (× 1.4826) keeps edges and
/// outliers out. Interpolation in the height map correlates neighbouring
/// nodes, so this is a lower estimate of the instrument's noise.
pub fn height_noise_from_map_um(crop: &Crop) -> Option<f64> {
    let mut d: Vec<f64> = crop
        .z_um
        .chunks_exact(crop.width)
        .flat_map(|row| row.windows(3).map(|w| (w[0] - 2.0 * w[1] + w[2]).abs()))
        .filter(|v| v.is_finite())
        .collect();
    if d.len() < 16 {
        return None;
    }
    let mid = d.len() / 2;
    let (_, median, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    Some(1.4826 * *median / 6f64.sqrt())
}

/// The parameters of one texture measurement and its notes.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureResult {
    pub parameters: ArealParameters,
    /// Sal, Str, Std (`None` on a surface smaller than 4 × 4 nodes).
    pub spatial: Option<SpatialParameters>,
    /// What the surface is (operators, nodes, partial kernels).
    pub description: String,
    /// Why the values are near the resolution limit; empty when they are not.
    pub resolution_notes: Vec<String>,
}

/// Runs the measurement on `crop`. `noise` is the measured height noise when
/// the data carry one; otherwise it is estimated from the map and the note
/// says so.
/// The fewest measured nodes an areal texture is evaluated on: 8 x 8, so the
/// height distribution's moments (Ssk, Sku) rest on more than a handful.
pub const MIN_TEXTURE_NODES: usize = 64;

pub fn measure_texture(
    crop: &Crop,
    settings: &TextureSettings,
    noise: Option<&HeightNoise>,
    label: &str,
    control: &RunControl,
) -> Result<TextureResult, AnalysisError> {
    // As a profile shorter than its cut-off is refused, so is an area: its
    // heights would all be border values of a partial kernel, and a few nodes
    // give no statistic (Sq, Ssk, Sku of 4 nodes are no surface's).
    let measured = crop.z_um.iter().filter(|v| v.is_finite()).count();
    if measured < MIN_TEXTURE_NODES {
        return Err(AnalysisError::TooFewSamples {
            region: label.to_string(),
            found: measured,
            needed: MIN_TEXTURE_NODES,
        });
    }
    // The longer side: a seal strip narrower than λc is still filtered along
    // its length, which is what such a strip is specified by.
    let extent_mm = crop.width.max(crop.height).saturating_sub(1) as f64 * crop.pitch_mm;
    if let Some(lc) = settings.lc_mm
        && lc > extent_mm
    {
        return Err(AnalysisError::CutoffBeyondRegion { region: label.to_string(), cutoff_mm: lc, extent_mm });
    }
    control.check()?;
    let surface = scale_limited_surface(crop, settings, label)?;
    control.check()?;
    let valid = surface.z_um.iter().filter(|v| v.is_finite()).count();
    let parameters = areal_parameters(&surface.z_um, crop.width, crop.height, crop.pitch_mm, settings.points)
        .ok_or(AnalysisError::TooFewSamples { region: label.to_string(), found: valid, needed: 2 })?;
    let noise = noise.cloned().or_else(|| {
        height_noise_from_map_um(crop).map(|sigma_um| HeightNoise {
            sigma_um,
            source: "estimated from the map's second differences; the map carries no noise estimate".into(),
        })
    });
    let resolution_notes = resolution_notes(crop.pitch_mm, settings.ls_mm, parameters.sq_um, noise.as_ref());
    control.check()?;
    let spatial = spatial_parameters(&surface.z_um, crop.width, crop.height, crop.pitch_mm);
    Ok(TextureResult {
        parameters,
        spatial,
        description: describe(settings, &surface, parameters.nodes),
        resolution_notes,
    })
}

fn form_name(form: FormRemoval) -> String {
    match form {
        FormRemoval::None => "none".into(),
        FormRemoval::Plane => "plane".into(),
        FormRemoval::Polynomial(n) => format!("polynomial of order {n}"),
    }
}

fn describe(settings: &TextureSettings, surface: &ScaleLimited, nodes: usize) -> String {
    let mut parts = vec![
        format!("{} surface", if settings.lc_mm.is_some() { "S-L" } else { "S-F" }),
        format!("F-operator {}", form_name(settings.form)),
    ];
    match settings.ls_mm {
        Some(ls) => parts.push(format!("λs {ls} mm")),
        None => parts.push("no S-filter".into()),
    }
    if let Some(lc) = settings.lc_mm {
        parts.push(format!("λc {lc} mm"));
    }
    parts.push(format!("{nodes} nodes"));
    // ISO 16610-28: the border is kept with the renormalised kernel; say how
    // much of the surface rests on it.
    let partial = [surface.s_filter, surface.l_filter].into_iter().flatten().map(|r| r.incomplete_percent());
    if let Some(p) = partial.reduce(f64::max) {
        parts.push(format!("{p:.1} % on a partial filter kernel (border or holes, renormalised)"));
    }
    parts.join("; ")
}

/// ISO 25178-3 asks λs to be well above the sampling (twice the pitch at
/// least, Nyquist) and a height parameter to be well above the noise; say
/// where either does not hold.
pub fn resolution_notes(pitch_mm: f64, ls_mm: Option<f64>, sq_um: f64, noise: Option<&HeightNoise>) -> Vec<String> {
    [s_filter_note("map pitch", pitch_mm, ls_mm), noise_note("Sq", sq_um, noise)].into_iter().flatten().collect()
}

/// Where λs does not lie above twice the sampling `spacing` (the map pitch,
/// a profile's step), or there is no S-filter at all.
pub fn s_filter_note(spacing: &str, spacing_mm: f64, ls_mm: Option<f64>) -> Option<String> {
    match ls_mm {
        None => Some(format!(
            "no S-filter: the surface keeps everything down to the {spacing} ({spacing_mm} mm), noise included"
        )),
        Some(ls) if ls < 2.0 * spacing_mm => Some(format!(
            "λs {ls} mm is below twice the {spacing} ({spacing_mm} mm), so the S-filter removes little the grid holds"
        )),
        Some(_) => None,
    }
}

/// Where the RMS height `parameter` (Sq, Rq) is within twice the height noise.
pub fn noise_note(parameter: &str, q_um: f64, noise: Option<&HeightNoise>) -> Option<String> {
    noise.filter(|n| q_um <= 2.0 * n.sigma_um).map(|n| {
        format!("{parameter} {q_um:.4} um is within twice the height noise {:.4} um ({})", n.sigma_um, n.source)
    })
}

/// An S-filtered flatness (ISO 12781-2 §4): PV and RMS, µm, of the region's
/// heights about their least-squares plane after a Gaussian S-filter at λs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilteredFlatness {
    pub peak_to_valley_um: f64,
    pub rms_um: f64,
    /// Nodes PV and RMS are taken over.
    pub nodes: usize,
    /// Valid nodes left out: their kernel lay for more than
    /// `1 - MIN_KERNEL_COVERAGE` outside the data (the region's edge, a hole).
    pub edge_nodes: usize,
    /// True when too few nodes had full enough kernels and all were used.
    pub edge_kept: bool,
    pub filter: FilterReport,
}

/// The share of its weighting function a filtered node must have on data to
/// count in an S-filtered flatness. At the edge of the data the
/// renormalised Gaussian (ISO 16610-28's end-effect correction) averages
/// over one side only, so those heights are noisier and biased by the
/// curvature beside them, and a PV would pick them. A Gaussian of cut-off
/// λs has sigma 0.187 λs; 90 % coverage leaves out a band of about λs / 4
/// along edges and around holes.
pub const MIN_KERNEL_COVERAGE: f32 = 0.9;

/// The plane is removed before filtering (so the renormalised border kernel
/// sees no tilt) and fitted again after it over the nodes whose kernel lies
/// on data ([`MIN_KERNEL_COVERAGE`]; all of them when fewer than 3 do);
/// residuals are scaled by `cos_tilt` of the region's plane so they are
/// measured along its normal, as the unfiltered flatness is.
pub fn filtered_flatness(
    crop: &Crop,
    ls_mm: f64,
    cos_tilt: f64,
    label: &str,
) -> Result<FilteredFlatness, AnalysisError> {
    let valid = crop.z_um.iter().filter(|v| v.is_finite()).count();
    let too_few = || AnalysisError::TooFewSamples { region: label.to_string(), found: valid, needed: 3 };
    let flat = remove_form(&crop.z_um, crop.width, crop.height, FormRemoval::Plane).ok_or_else(too_few)?;
    let (filtered, coverage, filter) =
        gaussian_areal_mean_surface_with_coverage(&flat, crop.width, crop.height, crop.pitch_mm, ls_mm);
    let covered = coverage.iter().filter(|c| **c >= MIN_KERNEL_COVERAGE).count();
    let edge_kept = covered < 3;
    let inner: Vec<f64> = if edge_kept {
        filtered
    } else {
        filtered.iter().zip(&coverage).map(|(v, c)| if *c >= MIN_KERNEL_COVERAGE { *v } else { f64::NAN }).collect()
    };
    let residual = remove_form(&inner, crop.width, crop.height, FormRemoval::Plane).ok_or_else(too_few)?;
    let (mut lo, mut hi, mut sum2, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
    for v in residual.iter().filter(|v| v.is_finite()) {
        let r = v * cos_tilt;
        lo = lo.min(r);
        hi = hi.max(r);
        sum2 += r * r;
        n += 1;
    }
    if n < 3 {
        return Err(too_few());
    }
    Ok(FilteredFlatness {
        peak_to_valley_um: hi - lo,
        rms_um: (sum2 / n as f64).sqrt(),
        nodes: n,
        edge_nodes: valid - n,
        edge_kept,
        filter,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn map(w: usize, h: usize, pitch_mm: f64, f: impl Fn(f64, f64) -> f64) -> HeightMap {
        let z = (0..w * h).map(|i| f((i % w) as f64 * pitch_mm, (i / w) as f64 * pitch_mm) as f32).collect();
        HeightMap::new(w, h, 0.0, 0.0, pitch_mm, z).unwrap()
    }

    fn settings(form: FormRemoval, ls_mm: Option<f64>, lc_mm: Option<f64>) -> TextureSettings {
        TextureSettings { form, ls_mm, lc_mm, points: MaterialRatioPoints::default() }
    }

    #[test]
    fn a_tilted_sine_gives_the_analytic_sa_after_plane_removal() {
        // z = tilt + A sin(kx) (mm); 8 whole periods of 0.1 mm at 0.002 mm pitch.
        let (a_um, lambda) = (0.5, 0.1);
        let k = 2.0 * PI / lambda;
        let m = map(400, 60, 0.002, |x, y| 0.01 * x + 0.004 * y + a_um / 1000.0 * (k * x).sin());
        let c = crop(&m, &vec![true; m.z.len()]).unwrap();
        let r =
            measure_texture(&c, &settings(FormRemoval::Plane, None, None), None, "all", &RunControl::new()).unwrap();
        let p = r.parameters;
        // f32 storage of heights of 0.01 mm limits the agreement to ~1e-4 µm.
        assert!((p.sa_um - 2.0 * a_um / PI).abs() < 0.01 * 2.0 * a_um / PI, "Sa {}", p.sa_um);
        assert!((p.sq_um - a_um / 2f64.sqrt()).abs() < 0.01 * a_um, "Sq {}", p.sq_um);
        assert!(r.description.contains("S-F surface") && r.description.contains("plane"));
        // No S-filter: the note says so.
        assert!(r.resolution_notes.iter().any(|n| n.contains("no S-filter")), "{:?}", r.resolution_notes);
    }

    #[test]
    fn the_l_filter_removes_the_waviness_and_the_s_filter_the_fine_ripple() {
        // Waviness at 10 λc, roughness at λc/3.2, ripple at λs/4 on a 0.001 mm grid.
        let (lc, ls) = (0.16, 0.008);
        let (w_len, r_len, n_len) = (1.6, 0.05, 0.002);
        let f = |x: f64| {
            0.002 * (2.0 * PI * x / w_len).sin()
                + 0.0004 * (2.0 * PI * x / r_len).sin()
                + 0.0002 * (2.0 * PI * x / n_len).sin()
        };
        let m = map(3200, 20, 0.001, |x, _| f(x));
        let c = crop(&m, &vec![true; m.z.len()]).unwrap();
        let r = measure_texture(&c, &settings(FormRemoval::None, Some(ls), Some(lc)), None, "all", &RunControl::new())
            .unwrap();
        // Only the roughness sine is left in the interior: Sq ≈ 0.4/√2 µm.
        // The border where the λc kernel is partial keeps some waviness, so
        // judge the interior directly.
        let s = scale_limited_surface(&c, &settings(FormRemoval::None, Some(ls), Some(lc)), "all").unwrap();
        let interior: Vec<f64> = (200..3000).map(|i| s.z_um[10 * 3200 + i]).collect();
        let rq = (interior.iter().map(|v| v * v).sum::<f64>() / interior.len() as f64).sqrt();
        let want = 0.4 / 2f64.sqrt();
        // The S-filter keeps exp(-π (α λs/λ)²) of the roughness (98.2 % here),
        // the L-filter 1 - exp(-π (α λc/λ)²) (99.9 %), ISO 16610-21 Eq. (2).
        let t = |cut: f64| (-PI * (super::super::filter::gaussian_alpha() * cut / r_len).powi(2)).exp();
        let kept = t(ls) * (1.0 - t(lc));
        assert!((rq - want * kept).abs() < 0.01 * want, "Rq {rq}, want {}", want * kept);
        assert!(r.description.contains("S-L surface") && r.description.contains("partial filter kernel"));
        assert!(r.resolution_notes.iter().all(|n| !n.contains("S-filter")), "{:?}", r.resolution_notes);
    }

    #[test]
    fn noise_is_estimated_from_the_map_and_flagged_when_sq_is_near_it() {
        // Pseudo-random ±e heights: white noise of σ = e / √3 (uniform).
        let e = 0.0002;
        let m = map(200, 200, 0.005, |x, y| {
            let h = (((x * 1e4) as u64 * 2654435761) ^ ((y * 1e4) as u64 * 40503)) % 1000;
            e * (h as f64 / 500.0 - 1.0)
        });
        let c = crop(&m, &vec![true; m.z.len()]).unwrap();
        let sigma = height_noise_from_map_um(&c).unwrap();
        let truth = 1000.0 * e / 3f64.sqrt();
        assert!(sigma > 0.5 * truth && sigma < 1.5 * truth, "σ {sigma} vs {truth}");
        let r = measure_texture(&c, &settings(FormRemoval::Plane, Some(0.02), None), None, "all", &RunControl::new())
            .unwrap();
        assert!(
            r.resolution_notes.iter().any(|n| n.contains("height noise") && n.contains("no noise estimate")),
            "{:?}",
            r.resolution_notes
        );
        let given = HeightNoise { sigma_um: 0.0001, source: "the cloud".into() };
        let r = measure_texture(
            &c,
            &settings(FormRemoval::Plane, Some(0.02), None),
            Some(&given),
            "all",
            &RunControl::new(),
        )
        .unwrap();
        assert!(r.resolution_notes.is_empty(), "{:?}", r.resolution_notes);
        let fine = resolution_notes(0.005, Some(0.008), 1.0, None);
        assert!(fine[0].contains("below twice the map pitch"), "{fine:?}");
    }

    #[test]
    fn a_region_is_cropped_with_holes_outside_it() {
        let m = map(10, 8, 0.01, |x, _| x);
        let mut mask = vec![false; 80];
        for i in [12, 13, 23, 33] {
            mask[i] = true;
        }
        let c = crop(&m, &mask).unwrap();
        assert_eq!((c.width, c.height), (2, 3));
        assert_eq!(c.z_um.iter().filter(|v| v.is_finite()).count(), 4);
        assert!((c.z_um[0] - 20.0).abs() < 1e-3);
        assert!(crop(&m, &[false; 80]).is_none());
        let e = scale_limited_surface(&c, &settings(FormRemoval::Polynomial(3), None, None), "r").unwrap_err();
        assert!(e.to_string().contains("covers 4 valid"), "{e}");
    }

    #[test]
    fn an_s_filter_takes_the_noise_out_of_a_flatness() {
        // A flat plate with ±1 µm pseudo-random noise on a 0.01 mm grid.
        let m = map(150, 150, 0.01, |x, y| {
            let h = ((x * 1e3).round() as u64 * 7919 + (y * 1e3).round() as u64 * 104729) % 997;
            0.001 * (h as f64 / 498.5 - 1.0)
        });
        let c = crop(&m, &vec![true; m.z.len()]).unwrap();
        let f = filtered_flatness(&c, 0.25, 1.0, "plate").unwrap();
        assert!(f.peak_to_valley_um < 0.2, "filtered PV {}", f.peak_to_valley_um);
        assert!(f.nodes + f.edge_nodes == 150 * 150 && f.filter.incomplete_nodes > 0 && !f.edge_kept);
    }

    /// The edge of the data: there the renormalised kernel averages one side
    /// only, so the filtered noise is larger and a PV would be an edge value.
    /// Left out are the nodes within about λs/4 of the edge (a band of
    /// 0.24 λs = 6 nodes here), and the PV is the interior's.
    #[test]
    fn an_s_filtered_flatness_leaves_the_filter_edge_out() {
        let (n, pitch, ls) = (160, 0.01, 0.25);
        let noise = |x: f64, y: f64| {
            let mut h = ((x / pitch).round() as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ ((y / pitch).round() as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            h ^= h >> 29;
            h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
            h ^= h >> 32;
            0.001 * ((h % 2001) as f64 / 1000.0 - 1.0)
        };
        let c = crop(&map(n, n, pitch, noise), &vec![true; n * n]).unwrap();
        let f = filtered_flatness(&c, ls, 1.0, "plate").unwrap();
        // The band: nodes whose distance to the nearest edge is under 1.28 sigma.
        let band = (1.28 * 0.187 * ls / pitch) as usize + 1;
        let inner = (n - 2 * band) * (n - 2 * band);
        assert!(f.nodes.abs_diff(inner) <= 4 * n, "{} nodes kept, about {inner} expected", f.nodes);
        // Every node, edges included, as before: the edge band's filtered
        // noise is larger (one-sided averages), and the PV was taken there.
        let flat = remove_form(&c.z_um, n, n, FormRemoval::Plane).unwrap();
        let (all, _) = gaussian_areal_mean_surface(&flat, n, n, pitch, ls);
        let all = remove_form(&all, n, n, FormRemoval::Plane).unwrap();
        let on_edge = |i: usize| (i % n).min(n - 1 - i % n).min((i / n).min(n - 1 - i / n)) < band;
        let rms = |edge: bool| {
            let v: Vec<f64> = (0..n * n).filter(|&i| on_edge(i) == edge).map(|i| all[i]).collect();
            (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
        };
        assert!(rms(true) > 1.2 * rms(false), "edge noise {} against {} inside", rms(true), rms(false));
        let extreme = (0..n * n).max_by(|&a, &b| all[a].abs().total_cmp(&all[b].abs())).unwrap();
        assert!(on_edge(extreme), "the largest deviation of the unrestricted surface lies on its edge");
        let pv_all =
            all.iter().fold(f64::NEG_INFINITY, |a, v| a.max(*v)) - all.iter().fold(f64::INFINITY, |a, v| a.min(*v));
        assert!(f.peak_to_valley_um < pv_all, "interior PV {} against {pv_all} with the edges", f.peak_to_valley_um);
        // A region narrower than the band keeps every node, and says so.
        let narrow = crop(&map(4, 40, pitch, noise), &[true; 160]).unwrap();
        let f = filtered_flatness(&narrow, ls, 1.0, "strip").unwrap();
        assert!(f.edge_kept && f.nodes == 160 && f.edge_nodes == 0, "{f:?}");
    }

    #[test]
    fn parameter_names_round_trip_and_units_follow_the_standard() {
        for p in ArealParameter::ALL {
            assert_eq!(ArealParameter::from_name(&p.name().to_lowercase()), Some(p));
        }
        assert_eq!(ArealParameter::Sdr.unit(), "%");
        assert_eq!(ArealParameter::Vmc.unit(), "um");
        assert_eq!(ArealParameter::Sku.unit(), "1");
        assert!(ArealParameter::from_name("Sx").is_none());
        assert_eq!(serde_json::to_string(&ArealParameter::Smr1).unwrap(), "\"Smr1\"");
    }
}
