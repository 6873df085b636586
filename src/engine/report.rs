//! The numbers an operator checks after a run, as one serialisable summary
//! (the report JSON of `sheen reconstruct`/`sheen phase` and the app's
//! statistics panel read the same struct).

use serde::Serialize;

use super::fusion::{SOURCE_NONE, SOURCE_ORDER_FAILED};
use super::pipeline::Reconstruction;

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub method: String,
    /// How fringe orders were accepted: strict, evidence or off.
    pub order_check: String,
    /// Stereo continuity rule: strict or plain.
    pub stereo_continuity: String,
    pub saturation_threshold: u16,
    pub min_modulation_dn: f32,
    pub cameras: Vec<CameraReport>,
    /// Points in the cloud (0 without stereo).
    pub point_count: usize,
    pub stereo: Option<StereoReport>,
    /// Why there is no 3D result, when there is none.
    pub stereo_skipped: Option<String>,
    /// Each with its `kind` (snake case) and `message`.
    pub warnings: Vec<super::warning::Warning>,
    /// Wall time per stage in seconds, in order.
    pub timings_s: Vec<StageTime>,
    /// The instruction set the per-pixel kernels ran on (`avx512`, `avx2` or
    /// `baseline`, `SHEEN_SIMD`'s words): the timings of two PCs compare only
    /// where it is the same. The results are the same bits on each.
    pub kernels: &'static str,
    /// Where a command-line run's wall time went (absent in the app's report).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub process_s: Option<ProcessTimes>,
}

/// A command-line run's wall time in seconds, from the command's start: a
/// line sees whether a slow part went to reading, computing or writing.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct ProcessTimes {
    /// From the process's start: start-up, reading the manifest and decoding
    /// every image.
    pub load: f64,
    /// The engine: phases, unwrapping, fusion and stereo.
    pub compute: f64,
    /// Writing the cloud and the maps (the report itself comes last, after
    /// this was measured).
    pub write: f64,
    /// From the process's start to the report.
    pub total: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct CameraReport {
    pub camera: String,
    pub width: usize,
    pub height: usize,
    pub pixels: usize,
    pub sets: Vec<SetReport>,
    /// Share of pixels supplied by each set (and by none), in manifest order.
    pub source_histogram: Vec<SourceShare>,
    /// Pixels with a valid fused phase.
    pub valid_pixels: usize,
    pub valid_percent: f64,
    pub order_failed_pixels: usize,
    /// Valid pixels whose fringe orders were confirmed by their neighbours
    /// (or by their patch's mean residual), not by their own samples alone.
    pub confirmed_by_neighbours_pixels: usize,
    pub confirmed_by_patch_pixels: usize,
    /// Pixels left out because they needed such evidence (`--own-orders-only`).
    pub excluded_confirmed_pixels: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct SetReport {
    pub set: usize,
    pub period_px: f64,
    pub shifts: usize,
    pub enabled: bool,
    /// Pixels with at least one saturated sample.
    pub saturated_pixels: usize,
    /// Pixels with fewer than 3 unsaturated samples.
    pub over_saturated_pixels: usize,
    pub low_modulation_pixels: usize,
    pub valid_pixels: usize,
    pub saturated_percent: f64,
    pub over_saturated_percent: f64,
    /// Camera noise estimated from the fit residuals (grey levels), if measurable.
    pub noise_sigma_dn: Option<f32>,
    /// Where `noise_sigma_dn` comes from: `fit_residual` (the set's own
    /// samples), `other_sets` (a 3-step set: the camera's sets with more
    /// shifts), `cross_set_offsets` (no set has a residual: the offsets'
    /// spread between sets) or `assumed` (one grey level).
    pub noise_source: crate::engine::phase_shift::NoiseSource,
    /// RMS of the fringe's harmonics (projector gamma) relative to its
    /// modulation, in per cent, estimated apart from the random noise;
    /// absent where `harmonics` says why.
    pub harmonic_percent: Option<f32>,
    /// Why there is no harmonic share: `not separable` (the modulation varies
    /// too little to tell harmonics from noise, so `noise_sigma_dn` holds
    /// both) or `no residual` (3 shifts fit exactly; the noise is borrowed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub harmonics: Option<&'static str>,
    pub fringe_order_failures: usize,
    /// Pixels whose own order was confirmed by neighbours, by the patch, or
    /// could not be decided (the set is not used there).
    pub orders_confirmed_by_neighbours: usize,
    pub orders_confirmed_by_patch: usize,
    pub orders_undecided: usize,
    /// Ambiguous orders that continuity contradicted (a sparser set filled in).
    pub orders_contradicted: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct SourceShare {
    /// "set 2 (period 24 px)", "none" or "order check failed".
    pub source: String,
    /// Manifest set index, or -1 (none) / -2 (order check failed).
    pub code: i8,
    pub pixels: usize,
    pub percent: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct StereoReport {
    pub rectified_rows: usize,
    pub left_candidates: usize,
    pub matched: usize,
    pub unmatched: usize,
    /// Unmatched left pixels whose phase falls in a right-row step the
    /// continuity rule refused (the rest: outside the right view, occluded
    /// or invalid there).
    pub unmatched_at_discontinuity: usize,
    pub ambiguous: usize,
    /// Of `matched`: left pixels matched by extending a right run up to a
    /// pixel towards the edge where its surface stops (strict continuity).
    pub extended_to_edge: usize,
    /// Matches dropped for a height sigma above the limit.
    pub too_uncertain: usize,
}

fn percent(part: usize, whole: usize) -> f64 {
    if whole == 0 { 0.0 } else { 100.0 * part as f64 / whole as f64 }
}

impl Report {
    pub fn new(rec: &Reconstruction) -> Self {
        let cameras = rec
            .cameras
            .iter()
            .map(|cam| {
                let pixels = cam.width * cam.height;
                let sets = cam
                    .sets
                    .iter()
                    .enumerate()
                    .map(|(s, wp)| {
                        let position = cam.enabled.iter().position(|&e| e == s);
                        SetReport {
                            set: s,
                            period_px: wp.period_px,
                            shifts: wp.shifts,
                            enabled: position.is_some(),
                            saturated_pixels: wp.stats.partially_saturated,
                            over_saturated_pixels: wp.stats.over_saturated,
                            low_modulation_pixels: wp.stats.low_modulation,
                            valid_pixels: wp.stats.valid,
                            saturated_percent: percent(wp.stats.partially_saturated, pixels),
                            over_saturated_percent: percent(wp.stats.over_saturated, pixels),
                            noise_sigma_dn: wp.noise.measured.then_some(wp.noise.sigma_dn),
                            noise_source: wp.noise.source,
                            harmonic_percent: wp.noise.harmonic_percent,
                            harmonics: harmonics_note(&wp.noise),
                            fringe_order_failures: position.map_or(0, |k| cam.unwrapped.order_failures[k]),
                            orders_confirmed_by_neighbours: position
                                .map_or(0, |k| cam.unwrapped.confirmed_by_neighbours[k]),
                            orders_confirmed_by_patch: position.map_or(0, |k| cam.unwrapped.confirmed_by_patch[k]),
                            orders_undecided: position.map_or(0, |k| cam.unwrapped.undecided[k]),
                            orders_contradicted: position.map_or(0, |k| cam.unwrapped.contradicted[k]),
                        }
                    })
                    .collect();
                let mut source_histogram: Vec<SourceShare> = cam
                    .enabled
                    .iter()
                    .zip(&cam.fused.source_counts)
                    .map(|(&s, &count)| SourceShare {
                        source: format!("set {s} (period {} px)", cam.sets[s].period_px),
                        code: s as i8,
                        pixels: count,
                        percent: percent(count, pixels),
                    })
                    .collect();
                source_histogram.push(SourceShare {
                    source: "none".into(),
                    code: SOURCE_NONE,
                    pixels: cam.fused.none_count,
                    percent: percent(cam.fused.none_count, pixels),
                });
                source_histogram.push(SourceShare {
                    source: "order check failed".into(),
                    code: SOURCE_ORDER_FAILED,
                    pixels: cam.fused.order_failed_count,
                    percent: percent(cam.fused.order_failed_count, pixels),
                });
                let valid = cam.fused.valid_count();
                CameraReport {
                    camera: cam.camera.clone(),
                    width: cam.width,
                    height: cam.height,
                    pixels,
                    sets,
                    source_histogram,
                    valid_pixels: valid,
                    valid_percent: percent(valid, pixels),
                    order_failed_pixels: cam.fused.order_failed_count,
                    confirmed_by_neighbours_pixels: cam.fused.confirmed_counts[0],
                    confirmed_by_patch_pixels: cam.fused.confirmed_counts[1],
                    excluded_confirmed_pixels: cam.fused.excluded_confirmed,
                }
            })
            .collect();
        Report {
            method: rec.params.method.to_string(),
            order_check: rec.params.order_check.to_string(),
            stereo_continuity: rec.params.stereo_continuity.to_string(),
            saturation_threshold: rec.saturation_threshold,
            min_modulation_dn: rec.params.min_modulation_dn,
            cameras,
            point_count: rec.point_count(),
            stereo: rec.stereo.as_ref().map(|s| StereoReport {
                rectified_rows: s.rectification.rows,
                left_candidates: s.match_stats.candidates,
                matched: s.match_stats.matched,
                unmatched: s.match_stats.unmatched,
                unmatched_at_discontinuity: s.match_stats.unmatched_at_discontinuity,
                ambiguous: s.match_stats.ambiguous,
                extended_to_edge: s.match_stats.extended_to_edge,
                too_uncertain: s.too_uncertain,
            }),
            stereo_skipped: rec.stereo_skipped.clone(),
            warnings: rec.warnings.clone(),
            timings_s: rec
                .timings
                .iter()
                .map(|(stage, seconds)| StageTime { stage: stage.clone(), seconds: *seconds })
                .collect(),
            kernels: super::simd::level().name(),
            process_s: None,
        }
    }
}
/// Why a set's report has no harmonic share, if it has none.
fn harmonics_note(noise: &crate::engine::phase_shift::NoiseEstimate) -> Option<&'static str> {
    use crate::engine::phase_shift::NoiseSource;
    match (noise.harmonic_percent, noise.source) {
        (Some(_), _) => None,
        (None, NoiseSource::FitResidual) => Some("not separable"),
        (None, _) => Some("no residual"),
    }
}
