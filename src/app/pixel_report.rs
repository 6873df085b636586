//! Everything the method did at one pixel, for the pixel inspector: per set
//! the N recorded samples, which are saturated, the sinusoid fitted to the
//! unsaturated ones (`phase_shift::fit_pixel`, Eqs. 2-4), the maps' values,
//! and in plain words why the pixel has no final phase or no 3D point.
//!
//! Pure data (no egui): built from the measurement and the result, tested here.

use crate::engine::fringe::Measurement;
use crate::engine::fusion::{SOURCE_NONE, SOURCE_ORDER_FAILED};
use crate::engine::phase_shift::{PixelFit, SampleSelection, fit_pixel};
use crate::engine::pipeline::{Method, Reconstruction};
use crate::engine::unwrap::{EVIDENCE_NEIGHBOURS, EVIDENCE_OWN, EVIDENCE_PATCH};

use super::commands::PixelRef;
use super::run_data::Derived;

/// Why a set gave no usable phase at the pixel (or that it did).
#[derive(Clone, Debug, PartialEq)]
pub enum SetStatus {
    /// Wrapped and (if enabled) unwrapped phase available.
    Valid,
    /// Fewer than 3 unsaturated samples.
    OverSaturated { usable: usize },
    /// The masked method drops pixels with any saturated sample.
    RejectedSaturated { saturated: usize },
    /// Fitted modulation below the operator's minimum.
    LowModulation { modulation_dn: f32, min_dn: f32 },
    /// Wrapped phase fine, but its fringe order failed the check.
    OrderFailed,
    /// Wrapped phase fine and a sparser set usable, but the order was left
    /// undecided: its predicted error too large, or ambiguous and confirmed
    /// by nothing (a sparser set fills in).
    OrderUndecided,
    /// Ambiguous, and the continuous neighbours or the patch imply another
    /// order (a sparser set fills in).
    OrderContradicted,
    /// Wrapped phase fine, but no reference set was usable here to unwrap it.
    NotUnwrapped,
    /// The operator disabled the set.
    Disabled,
}

impl SetStatus {
    pub fn describe(&self) -> String {
        match self {
            SetStatus::Valid => "valid".into(),
            SetStatus::OverSaturated { usable } => {
                format!("over-saturated: {usable} unsaturated sample(s), 3 needed")
            }
            SetStatus::RejectedSaturated { saturated } => {
                format!("rejected: {saturated} saturated sample(s) and the masked method drops such pixels")
            }
            SetStatus::LowModulation { modulation_dn, min_dn } => {
                format!("low modulation: B = {modulation_dn:.2} dn < {min_dn} dn")
            }
            SetStatus::OrderFailed => "fringe order failed its check (disagrees with the sparser set)".into(),
            SetStatus::OrderUndecided => "fringe order undecided: ambiguous from the sparser set (its predicted \
                                          error too large) and confirmed by no neighbour, patch or smoothed sparser \
                                          phase; a sparser set fills in"
                .into(),
            SetStatus::OrderContradicted => "fringe order contradicted: ambiguous from the sparser set, and its \
                                             continuous neighbours (or its patch) imply another order; a sparser set \
                                             fills in"
                .into(),
            SetStatus::NotUnwrapped => "not unwrapped: no sparser set usable here as a reference".into(),
            SetStatus::Disabled => "disabled".into(),
        }
    }
}

/// One set at the pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct SetSamples {
    pub set: usize,
    pub period_px: f64,
    pub shifts_rad: Vec<f64>,
    pub samples_dn: Vec<u16>,
    pub saturated: Vec<bool>,
    /// Fit on the unsaturated samples (what hdr/generalized use).
    pub fit: Option<PixelFit>,
    pub wrapped_phase_rad: Option<f32>,
    pub modulation_dn: Option<f32>,
    pub phase_sigma_rad: Option<f32>,
    pub unwrapped_phase_rad: Option<f32>,
    pub status: SetStatus,
    /// How the fringe orders behind the unwrapped phase were decided
    /// (`unwrap::EVIDENCE_*`; own pixel where not unwrapped).
    pub order_evidence: u8,
}

/// The evidence behind a fringe order, in words (`None`: the pixel's own samples).
pub fn order_evidence_text(evidence: u8) -> Option<&'static str> {
    match evidence {
        EVIDENCE_NEIGHBOURS => Some("order confirmed by its neighbours on the same surface"),
        EVIDENCE_PATCH => {
            Some("order confirmed against the sparser set's phase averaged over its patch or neighbourhood")
        }
        _ => None,
    }
}

impl SetSamples {
    pub fn saturated_count(&self) -> usize {
        self.saturated.iter().filter(|&&s| s).count()
    }
}

/// The inspector's content for one pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct PixelReport {
    pub pixel: PixelRef,
    pub camera_name: String,
    pub threshold_dn: u16,
    pub method: Option<Method>,
    pub sets: Vec<SetSamples>,
    pub fused_phase_rad: Option<f32>,
    pub source: Option<i8>,
    /// Height of the pixel's 3D point, with its unit.
    pub height: Option<(f32, String)>,
    /// The verdict in one sentence, then the per-set reasons when it failed.
    pub verdict: String,
    pub reasons: Vec<String>,
    /// A camera–projector rig's absolute projector x and y at the pixel, or
    /// why each was refused.
    pub projector: Vec<String>,
}

/// Builds the report of `pixel`. `threshold_dn` applies when there is no result
/// yet; with a result, its own threshold is used so the plot matches the maps.
pub fn build(
    m: &Measurement,
    pixel: PixelRef,
    threshold_dn: u16,
    result: Option<(&Reconstruction, &Derived)>,
) -> Option<PixelReport> {
    let cam = m.cameras.get(pixel.camera)?;
    if pixel.u >= cam.width || pixel.v >= cam.height {
        return None;
    }
    let index = pixel.v * cam.width + pixel.u;
    let threshold = result.map_or(threshold_dn, |(r, _)| r.saturation_threshold);
    let phase = result.and_then(|(r, _)| r.cameras.get(pixel.camera));
    let method = result.map(|(r, _)| r.params.method);
    let selection = method.map(Method::selection);
    let min_modulation = result.map(|(r, _)| r.params.min_modulation_dn);

    let mut sets = Vec::with_capacity(m.sets.len());
    for (s, (info, stack)) in m.sets.iter().zip(&cam.stacks).enumerate() {
        let samples_dn = stack.pixel_samples(index);
        let saturated: Vec<bool> = samples_dn.iter().map(|&v| v >= threshold).collect();
        let as_f64: Vec<f64> = samples_dn.iter().map(|&v| f64::from(v)).collect();
        let used: Vec<bool> = saturated.iter().map(|s| !s).collect();
        let fit = fit_pixel(&as_f64, &info.phase_shifts_rad, &used);
        let wp = phase.and_then(|p| p.sets.get(s));
        let finite = |v: f32| v.is_finite().then_some(v);
        let wrapped = wp.and_then(|w| finite(w.wrapped_phase_rad[index]));
        let modulation = wp.map(|w| w.modulation_dn[index]);
        let sigma = wp.and_then(|w| finite(w.phase_sigma_rad[index]));
        let enabled_pos = phase.and_then(|p| p.enabled.iter().position(|&e| e == s));
        let unwrapped = phase.and_then(|p| p.unwrapped_phase(s)).map(|u| u[index]).filter(|v| v.is_finite());
        let n_sat = saturated.iter().filter(|&&x| x).count();
        let usable = samples_dn.len() - n_sat;
        let status = if phase.is_some() && enabled_pos.is_none() {
            SetStatus::Disabled
        } else if selection == Some(SampleSelection::RejectSaturated) && n_sat > 0 {
            SetStatus::RejectedSaturated { saturated: n_sat }
        } else if selection != Some(SampleSelection::All) && usable < 3 {
            SetStatus::OverSaturated { usable }
        } else if let (Some(b), Some(min)) = (modulation, min_modulation)
            && wrapped.is_none()
            && !(b >= min && b > 0.0)
        {
            SetStatus::LowModulation { modulation_dn: b, min_dn: min }
        } else if let (Some(p), Some(k)) = (phase, enabled_pos)
            && wrapped.is_some()
            && unwrapped.is_none()
        {
            let sparser_usable =
                (0..k).any(|j| p.unwrapped.unwrapped_phase_rad.get(j).is_some_and(|u| u[index].is_finite()));
            if p.unwrapped.order_flags[index] & (1 << k) != 0 {
                SetStatus::OrderFailed
            } else if p.unwrapped.order_contradicted.get(index).is_some_and(|bits| bits & (1 << k) != 0) {
                SetStatus::OrderContradicted
            } else if sparser_usable {
                SetStatus::OrderUndecided
            } else {
                SetStatus::NotUnwrapped
            }
        } else {
            SetStatus::Valid
        };
        sets.push(SetSamples {
            set: s,
            period_px: info.period_px,
            shifts_rad: info.phase_shifts_rad.clone(),
            samples_dn,
            saturated,
            fit,
            wrapped_phase_rad: wrapped,
            modulation_dn: modulation,
            phase_sigma_rad: sigma,
            unwrapped_phase_rad: unwrapped,
            status,
            order_evidence: match (phase, enabled_pos, unwrapped) {
                (Some(p), Some(k), Some(_)) => p.unwrapped.evidence(k, index),
                _ => EVIDENCE_OWN,
            },
        });
    }

    let fused = phase.map(|p| p.fused.fused_phase_rad[index]).filter(|v| v.is_finite());
    let source = phase.map(|p| p.fused.source_set[index]);
    let height = result.and_then(|(_, d)| {
        let z = d.height.as_ref()?.get(index).copied().filter(|z| z.is_finite())?;
        (pixel.camera == 0).then(|| (z, d.height_unit.clone()))
    });
    let (verdict, reasons) = verdict(m, pixel.camera, result.map(|(r, _)| r), &sets, fused, source, height.is_some());
    let projector = match result.and_then(|(r, _)| r.projector.as_ref()) {
        Some(Ok(maps)) => maps.get(pixel.camera).map_or_else(Vec::new, |cam| {
            [("x", &cam.x, &cam.code_x), ("y", &cam.y, &cam.code_y)]
                .into_iter()
                .filter_map(|(axis, coordinate, code)| {
                    let (coordinate, code) = (coordinate.as_ref()?, code.as_ref()?);
                    Some(format!("projector {axis}: {}", coordinate.explain_pixel(code, axis, index)))
                })
                .collect()
        }),
        Some(Err(e)) => vec![format!("no projector coordinates: {e}")],
        None => Vec::new(),
    };
    Some(PixelReport {
        pixel,
        camera_name: cam.name.clone(),
        threshold_dn: threshold,
        method,
        sets,
        fused_phase_rad: fused,
        source,
        height,
        verdict,
        reasons,
        projector,
    })
}

fn verdict(
    m: &Measurement,
    camera: usize,
    result: Option<&Reconstruction>,
    sets: &[SetSamples],
    fused: Option<f32>,
    source: Option<i8>,
    has_point: bool,
) -> (String, Vec<String>) {
    let Some(rec) = result else {
        return ("No result yet: run the engine to see what it makes of this pixel.".into(), Vec::new());
    };
    let set_reasons = |filter: &dyn Fn(&SetSamples) -> bool| -> Vec<String> {
        sets.iter()
            .rev()
            .filter(|s| s.status != SetStatus::Disabled && filter(s))
            .map(|s| format!("set {} ({} px): {}", s.set, s.period_px, s.status.describe()))
            .collect()
    };
    match (fused, source) {
        (Some(_), Some(src)) if src >= 0 => {
            let period = m.sets.get(src as usize).map_or(f64::NAN, |s| s.period_px);
            let mut verdict = format!("Valid: phase from set {src} ({period} px)");
            if let Some(why) = sets.get(src as usize).and_then(|s| order_evidence_text(s.order_evidence)) {
                verdict.push_str(&format!(" ({why})"));
            }
            let densest = rec.cameras.get(camera).and_then(|c| c.enabled.last().copied());
            let mut reasons = Vec::new();
            if densest.is_some_and(|d| d != src as usize) {
                verdict.push_str(", filled in by HDR fusion because denser sets failed here");
                reasons = set_reasons(&|s: &SetSamples| s.set > src as usize && s.status != SetStatus::Valid);
            }
            if camera == 0 && rec.stereo.is_some() {
                if has_point {
                    verdict.push_str("; it has a 3D point.");
                } else {
                    verdict.push_str(
                        "; but no 3D point: no match in the right camera (occluded, outside its view, or ambiguous).",
                    );
                }
            } else {
                verdict.push('.');
            }
            (verdict, reasons)
        }
        (_, Some(SOURCE_ORDER_FAILED)) => (
            "Invalid: the fringe-order check failed, two sets disagree at this pixel.".into(),
            set_reasons(&|s: &SetSamples| s.status == SetStatus::OrderFailed),
        ),
        (_, Some(SOURCE_NONE)) | (_, Some(_)) | (_, None) => {
            let reasons = set_reasons(&|s: &SetSamples| s.status != SetStatus::Valid);
            let verdict = if reasons.is_empty() {
                "Invalid: no set supplied a phase (the method uses the densest set only).".into()
            } else {
                "Invalid: no set could recover this pixel.".into()
            };
            (verdict, reasons)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::control::RunControl;
    use crate::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, next_measurement_id};
    use crate::engine::pipeline::{Params, run_phase};

    /// One camera of `w` x `h` px, 8-bit, with the sets given; `sample(set,
    /// shift index, shift, pixel)` is each sample's value before rounding.
    fn one_camera(
        (w, h): (usize, usize),
        sets: Vec<FringeSetInfo>,
        sample: impl Fn(usize, usize, f64, usize) -> f64,
    ) -> Measurement {
        let stacks = sets
            .iter()
            .enumerate()
            .map(|(s, set)| {
                let planes = (set.phase_shifts_rad.iter().enumerate())
                    .map(|(k, &d)| (0..w * h).map(|p| sample(s, k, d, p).round().clamp(0.0, 255.0) as u8).collect())
                    .collect();
                FringeStack::from_planes_u8(w, h, planes)
            })
            .collect();
        Measurement {
            bit_depth: 8,
            saturation_level: 255,
            sets,
            cameras: vec![CameraFringes { name: "left".into(), width: w, height: h, stacks }],
            calibration: None,
            label: "test".into(),
            projector: None,
            id: next_measurement_id(),
        }
    }

    /// One camera, 2 sets (period 64 covering the 48 px wide field, then 8),
    /// 8 shifts, a plane phase; pixel column 0..4 is blown out in the dense set only.
    fn measurement() -> Measurement {
        let w = 48;
        let periods = [64.0, 8.0];
        one_camera((w, 8), periods.iter().map(|&p| FringeSetInfo::uniform(p, 8)).collect(), |s, _, d, p| {
            let u = (p % w) as f64;
            let phi = std::f64::consts::TAU * (u + 4.0) / periods[s];
            let (a, b) = if s == 1 && u < 4.0 { (400.0, 40.0) } else { (120.0, 80.0) };
            a + b * (phi + d).cos()
        })
    }

    fn report(m: &Measurement, params: &Params, u: usize) -> PixelReport {
        let rec = run_phase(m, params, None, &RunControl::new()).expect("engine");
        let derived = Derived::compute(&rec);
        build(m, PixelRef { camera: 0, u, v: 3 }, 255, Some((&rec, &derived))).expect("report")
    }

    #[test]
    fn samples_saturation_and_fit_match_the_data() {
        let m = measurement();
        let r = report(&m, &Params::default(), 20);
        assert_eq!(r.sets.len(), 2);
        let s = &r.sets[1];
        assert_eq!(s.samples_dn, m.cameras[0].stacks[1].pixel_samples(3 * 48 + 20));
        assert!(s.saturated.iter().all(|&x| !x));
        let fit = s.fit.expect("fit");
        assert!((fit.modulation - 80.0).abs() < 1.0, "{}", fit.modulation);
        assert!((fit.offset - 120.0).abs() < 1.0, "{}", fit.offset);
        let expected = (std::f64::consts::TAU * 24.0 / 8.0).rem_euclid(std::f64::consts::TAU);
        let d = (fit.phase_rad - expected).abs();
        assert!(d.min(std::f64::consts::TAU - d) < 0.02, "phase {} vs {expected}", fit.phase_rad);
        assert!(r.verdict.starts_with("Valid: phase from set 1"), "{}", r.verdict);
    }

    #[test]
    fn an_over_saturated_dense_pixel_is_filled_from_the_sparse_set_and_says_why() {
        let m = measurement();
        let r = report(&m, &Params::default(), 2);
        let dense = &r.sets[1];
        assert_eq!(dense.saturated_count(), 8);
        assert_eq!(dense.status, SetStatus::OverSaturated { usable: 0 });
        assert_eq!(r.source, Some(0));
        assert!(r.verdict.contains("filled in by HDR fusion"), "{}", r.verdict);
        assert_eq!(r.reasons.len(), 1);
        assert!(r.reasons[0].contains("over-saturated"), "{:?}", r.reasons);
    }

    #[test]
    fn the_traditional_method_leaves_the_pixel_invalid_with_the_reason() {
        let m = measurement();
        let params = Params { method: Method::Generalized, ..Params::default() };
        let r = report(&m, &params, 2);
        assert_eq!(r.fused_phase_rad, None);
        assert!(r.verdict.starts_with("Invalid"), "{}", r.verdict);
        assert!(r.reasons.iter().any(|x| x.contains("set 1") && x.contains("over-saturated")), "{:?}", r.reasons);
    }

    #[test]
    fn masked_and_low_modulation_reasons() {
        let m = measurement();
        let masked = report(&m, &Params { method: Method::Masked, ..Params::default() }, 2);
        assert!(matches!(masked.sets[1].status, SetStatus::RejectedSaturated { saturated: 8 }));
        let strict = report(&m, &Params { min_modulation_dn: 200.0, ..Params::default() }, 20);
        assert!(matches!(strict.sets[0].status, SetStatus::LowModulation { .. }), "{:?}", strict.sets[0].status);
    }

    /// Through the whole engine: one pixel whose sparse set is dim (11 DN of
    /// modulation against 80, in 1.7 DN of noise) and off by 0.55 rad, which
    /// at a period ratio of 10 rounds the dense set to the next order. Its
    /// order is ambiguous and its decided neighbours imply another one: the
    /// inspector must say "contradicted", not "undecided" or "failed".
    #[test]
    fn an_order_its_neighbours_contradict_is_reported_as_contradicted() {
        let (w, h, bad) = (64usize, 16usize, (30usize, 8usize));
        // Uniform noise of +-3 DN (sigma 1.7 DN), the same on every run.
        let noise = |p: usize, s: usize, k: usize| {
            let mut x = (p as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ ((s * 16 + k) as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x ^= x >> 31;
            x = x.wrapping_mul(0x94D0_49BB_1331_11EB);
            x ^= x >> 29;
            (x % 7) as f64 - 3.0
        };
        let periods = [160.0, 16.0];
        let sets = periods.iter().map(|&p| FringeSetInfo::uniform(p, 8)).collect();
        let m = one_camera((w, h), sets, |s, k, d, p| {
            let at_bad = s == 0 && p == bad.1 * w + bad.0;
            let phi = std::f64::consts::TAU * ((p % w) as f64 + 5.0) / periods[s] + if at_bad { 0.55 } else { 0.0 };
            let b = if at_bad { 11.0 } else { 80.0 };
            120.0 + b * (phi + d).cos() + noise(p, s, k)
        });
        let rec = run_phase(&m, &Params::default(), None, &RunControl::new()).expect("engine");
        let derived = Derived::compute(&rec);
        let at = |u, v| build(&m, PixelRef { camera: 0, u, v }, 255, Some((&rec, &derived))).expect("report");
        let r = at(bad.0, bad.1);
        assert_eq!(r.sets[1].status, SetStatus::OrderContradicted, "{:?} {:?}", r.sets[0], r.sets[1]);
        assert_eq!(r.source, Some(0), "the sparse set fills in");
        assert!(r.reasons.iter().any(|x| x.contains("contradicted")), "{:?}", r.reasons);
        // Its neighbours are measured by the dense set.
        let n = at(bad.0 + 2, bad.1);
        assert_eq!((n.sets[1].status.clone(), n.source), (SetStatus::Valid, Some(1)));
    }

    #[test]
    fn pixels_outside_the_image_have_no_report() {
        let m = measurement();
        assert!(build(&m, PixelRef { camera: 0, u: 48, v: 0 }, 255, None).is_none());
        assert!(build(&m, PixelRef { camera: 1, u: 0, v: 0 }, 255, None).is_none());
    }
}
