//! The whole method for one measurement: per camera the phase stage (Algs.
//! 1-2), unwrapping and fusion (Alg. 3), then stereo (section 2.3).
//!
//! Every intermediate stays in the result because the GUI shows them all.
//! Per-set phases are shared (`Arc`) and reused from a previous run when only
//! parameters downstream of them changed (enabled sets, the fusion rule), so
//! toggling a set or switching between `hdr` and `generalized` re-runs only
//! the cheap stages.

use super::camera_projector::{ProjectorMaps, ProjectorMapsError, projector_maps};
use std::sync::Arc;
use std::time::Instant;

use super::control::{Cancelled, RunControl};
use super::fringe::{FringeStack, Measurement};
use super::fusion::{Fused, FusionRule, fuse};
use super::phase_shift::{
    MAX_SHIFTS, NoiseSource, PhaseParams, SampleSelection, WrappedPhase, cross_set_noise, wrapped_phase,
};
use super::stereo::{self, LeftAttributes, PhaseMapView, StereoError, StereoResult};
use super::stereo_match::StereoContinuity;
use super::unwrap::{MAX_SETS, OrderCheck, ROOT_WRAP_WARNING_FRACTION, Unwrapped, unwrap_hierarchical};
use super::warning::{Warning, WarningKind};

/// The four ways to compute the final phase, selectable everywhere; comparing
/// them is the paper's Fig. 5.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The paper's scheme: generalized phase shifting on unsaturated samples,
    /// and where the densest set is over-saturated, the densest usable sparser set.
    #[default]
    Hdr,
    /// The N-step formula on all samples, saturated or not.
    Standard,
    /// The N-step formula; pixels with any saturated sample are dropped.
    Masked,
    /// Generalized phase shifting on unsaturated samples, densest set only.
    Generalized,
}

impl Method {
    pub const ALL: [Method; 4] = [Method::Hdr, Method::Standard, Method::Masked, Method::Generalized];

    pub fn name(self) -> &'static str {
        match self {
            Method::Hdr => "hdr",
            Method::Standard => "standard",
            Method::Masked => "masked",
            Method::Generalized => "generalized",
        }
    }

    pub fn selection(self) -> SampleSelection {
        match self {
            Method::Hdr | Method::Generalized => SampleSelection::Unsaturated,
            Method::Standard => SampleSelection::All,
            Method::Masked => SampleSelection::RejectSaturated,
        }
    }

    pub fn fusion_rule(self) -> FusionRule {
        match self {
            Method::Hdr => FusionRule::DensestUsable,
            _ => FusionRule::DensestOnly,
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown method '{s}': expected hdr, standard, masked or generalized"))
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Operator parameters of a run.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Params {
    pub method: Method,
    /// Samples at or above are saturated; `None` = the measurement's saturation level.
    pub saturation_threshold: Option<u16>,
    /// Pixels with fringe modulation below this (grey levels) are invalid.
    pub min_modulation_dn: f32,
    /// Per manifest set: take part in unwrapping and fusion. Empty = all.
    pub enabled_sets: Vec<bool>,
    /// Points whose height standard deviation, propagated from the phase
    /// noise, exceeds this (micrometres) are left out of the cloud: a fill
    /// from a sparse set at noise-level modulation locates nothing. `None`:
    /// keep every point.
    #[serde(default = "default_max_sigma_z_um")]
    pub max_sigma_z_um: Option<f32>,
    /// How fringe orders are accepted; sessions saved before the
    /// setting existed load with the default.
    #[serde(default)]
    pub order_check: OrderCheck,
    /// Leave out pixels whose orders were accepted on their neighbours' or
    /// their patch's evidence rather than on their own samples.
    #[serde(default)]
    pub own_orders_only: bool,
    /// Stereo keeps to continuous surfaces, or matches plainly along the row.
    #[serde(default)]
    pub stereo_continuity: StereoContinuity,
}

/// The default height-uncertainty limit: keeps fills from sparser sets at
/// ordinary modulation (10 to 50 um on the paper's rig), drops matches located
/// by noise-level fringes (hundreds of micrometres).
pub const DEFAULT_MAX_SIGMA_Z_UM: f32 = 100.0;

fn default_max_sigma_z_um() -> Option<f32> {
    Some(DEFAULT_MAX_SIGMA_Z_UM)
}

impl Default for Params {
    fn default() -> Self {
        Self {
            method: Method::Hdr,
            saturation_threshold: None,
            min_modulation_dn: 4.0,
            enabled_sets: Vec::new(),
            max_sigma_z_um: default_max_sigma_z_um(),
            order_check: OrderCheck::default(),
            own_orders_only: false,
            stereo_continuity: StereoContinuity::default(),
        }
    }
}

impl Params {
    pub fn threshold_for(&self, m: &Measurement) -> u16 {
        self.saturation_threshold.unwrap_or(m.saturation_level)
    }

    pub fn set_enabled(&self, set: usize) -> bool {
        self.enabled_sets.get(set).copied().unwrap_or(true)
    }

    pub fn phase_params(&self, m: &Measurement) -> PhaseParams {
        PhaseParams {
            saturation_threshold: self.threshold_for(m),
            min_modulation_dn: self.min_modulation_dn,
            selection: self.method.selection(),
        }
    }
}

/// Everything computed for one camera.
#[derive(Clone, Debug)]
pub struct CameraPhase {
    pub camera: String,
    pub width: usize,
    pub height: usize,
    /// One per manifest set (disabled sets too: their maps are still shown).
    pub sets: Vec<Arc<WrappedPhase>>,
    /// Manifest indices of the sets that took part in unwrapping and fusion.
    pub enabled: Vec<usize>,
    /// Indexed like `enabled`.
    pub unwrapped: Unwrapped,
    pub fused: Fused,
    /// Mean intensity of the sparsest set: the texture of the cloud and of views.
    pub texture_dn: Arc<Vec<f32>>,
    /// Share of rows in which the root set wraps (phase ambiguity).
    pub root_wrap_fraction: f64,
}

impl CameraPhase {
    /// Unwrapped phase of manifest set `set`, if it took part.
    pub fn unwrapped_phase(&self, set: usize) -> Option<&[f32]> {
        let k = self.enabled.iter().position(|&s| s == set)?;
        Some(&self.unwrapped.unwrapped_phase_rad[k])
    }

    /// Valid-phase mask of the fused map.
    pub fn valid_mask(&self) -> Vec<bool> {
        self.fused.fused_phase_rad.iter().map(|p| !p.is_nan()).collect()
    }

    /// Frees the per-set maps that stereo and the point cloud do not read
    /// (wrapped phases, their uncertainty, saturation counts, unwrapped
    /// phases; the modulation stays where `keep_modulation`: the main camera's
    /// is a point attribute), keeping every statistic. For batch runs that
    /// write no maps; a set shared with another result is left alone.
    fn release_per_set_maps(&mut self, keep_modulation: bool) {
        for set in &mut self.sets {
            if let Some(set) = Arc::get_mut(set) {
                set.wrapped_phase_rad = Vec::new();
                set.phase_sigma_rad = Vec::new();
                set.saturation_count = Vec::new();
                if !keep_modulation {
                    set.modulation_dn = Vec::new();
                }
            }
        }
        self.unwrapped.unwrapped_phase_rad = Vec::new();
        self.unwrapped.order_flags = Vec::new();
    }
}

/// Result of a run.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    pub measurement_id: u64,
    pub params: Params,
    pub saturation_threshold: u16,
    pub cameras: Vec<CameraPhase>,
    pub stereo: Option<StereoResult>,
    /// Why there is no stereo result, when there is none.
    pub stereo_skipped: Option<String>,
    pub warnings: Vec<Warning>,
    /// Wall time per stage, in order.
    pub timings: Vec<(String, f64)>,
    /// A camera–projector rig with a Gray code: each camera's absolute
    /// projector coordinates, or why they could not be had (frames out of
    /// order, white and black swapped). `None` for other rigs.
    pub projector: Option<Result<Arc<Vec<ProjectorMaps>>, Arc<ProjectorMapsError>>>,
    /// A calibrated camera–projector rig's cloud, seen from the camera
    /// ([`crate::engine::camera_projector::rig_cloud_seen_from_camera`]); the
    /// telecentric pair's is `stereo`'s.
    pub rig_cloud: Option<Arc<super::point_cloud::PointCloud>>,
}

/// The timing that holds the whole stereo half; the stereo stages it holds
/// are listed before it, named with [`stereo::STAGE_PREFIX`].
const STEREO_TOTAL: &str = "stereo total";

impl Reconstruction {
    /// The run's engine time: every stage once. `timings` lists the stereo
    /// stages and then their total, so a plain sum counted them twice.
    pub fn total_seconds(&self) -> f64 {
        self.timings.iter().filter(|(stage, _)| !stage.starts_with(stereo::STAGE_PREFIX)).map(|(_, t)| t).sum()
    }

    /// The run's 3D points: the stereo pair's or the camera–projector rig's.
    pub fn cloud(&self) -> Option<&super::point_cloud::PointCloud> {
        self.stereo.as_ref().map(|s| &s.cloud).or(self.rig_cloud.as_deref())
    }

    pub fn camera(&self, name: &str) -> Option<&CameraPhase> {
        self.cameras.iter().find(|c| c.camera == name)
    }

    /// Per camera: the share of its pixels measured. A camera–projector
    /// rig measures its projector coordinates, not the x sets' fused phase
    /// (no Gray code in it): its share is the pixels with a projector x.
    pub fn completeness(&self) -> Vec<f64> {
        let share = |n: usize, pixels: usize| n as f64 / pixels.max(1) as f64;
        match &self.projector {
            Some(Ok(maps)) => maps
                .iter()
                .map(|c| c.x.as_ref().map_or(0.0, |x| share(x.lit_and_measured().1, x.coordinate_px.len())))
                .collect(),
            _ => self.cameras.iter().map(|c| share(c.fused.valid_count(), c.width * c.height)).collect(),
        }
    }

    pub fn point_count(&self) -> usize {
        self.cloud().map_or(0, super::point_cloud::PointCloud::len)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    #[error("no fringe set is enabled: enable at least the sparsest set")]
    NoEnabledSet,
    #[error("{sets} fringe sets given; at most {max} are supported")]
    TooManySets { sets: usize, max: usize },
    #[error("set {set} (period {period_px} px) has {shifts} shifts; supported are 3 to {max}")]
    BadShiftCount { set: usize, period_px: f64, shifts: usize, max: usize },
    #[error(
        "camera '{camera}' set {set}: stack is {got_w}x{got_h} px with {got_n} images, expected {want_w}x{want_h} px with {want_n}"
    )]
    StackShape {
        camera: String,
        set: usize,
        got_w: usize,
        got_h: usize,
        got_n: usize,
        want_w: usize,
        want_h: usize,
        want_n: usize,
    },
    #[error("the measurement has no camera")]
    NoCamera,
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

fn check_shapes(m: &Measurement) -> Result<(), EngineError> {
    if m.cameras.is_empty() {
        return Err(EngineError::NoCamera);
    }
    if m.sets.is_empty() {
        return Err(EngineError::NoEnabledSet);
    }
    if m.sets.len() > MAX_SETS {
        return Err(EngineError::TooManySets { sets: m.sets.len(), max: MAX_SETS });
    }
    for (s, set) in m.sets.iter().enumerate() {
        if !(3..=MAX_SHIFTS).contains(&set.shifts()) {
            return Err(EngineError::BadShiftCount {
                set: s,
                period_px: set.period_px,
                shifts: set.shifts(),
                max: MAX_SHIFTS,
            });
        }
    }
    for cam in &m.cameras {
        for (s, stack) in cam.stacks.iter().enumerate() {
            let want_n = m.sets[s].shifts();
            if stack.width != cam.width || stack.height != cam.height || stack.shifts != want_n {
                return Err(EngineError::StackShape {
                    camera: cam.name.clone(),
                    set: s,
                    got_w: stack.width,
                    got_h: stack.height,
                    got_n: stack.shifts,
                    want_w: cam.width,
                    want_h: cam.height,
                    want_n,
                });
            }
        }
        if cam.stacks.len() != m.sets.len() {
            return Err(EngineError::StackShape {
                camera: cam.name.clone(),
                set: cam.stacks.len(),
                got_w: 0,
                got_h: 0,
                got_n: 0,
                want_w: cam.width,
                want_h: cam.height,
                want_n: 0,
            });
        }
    }
    Ok(())
}

/// Per-camera stages only (phase, unwrapping, fusion): what `sheen phase` runs
/// and what works with one camera and no calibration.
pub fn run_phase(
    m: &Measurement,
    params: &Params,
    previous: Option<&Reconstruction>,
    control: &RunControl,
) -> Result<Reconstruction, EngineError> {
    check_shapes(m)?;
    let mut rec = phase_stages(m, params, previous, control, Samples::Borrowed)?;
    // The projector coordinates of a camera–projector rig, from the same
    // phase parameters (issue 52).
    if m.projector.as_ref().is_some_and(|p| p.gray_code.is_some()) {
        let t0 = Instant::now();
        rec.projector = match projector_maps(m, &params.phase_params(m), control) {
            Ok(maps) => Some(Ok(Arc::new(maps))),
            Err(ProjectorMapsError::Cancelled(c)) => return Err(c.into()),
            Err(e) => Some(Err(Arc::new(e))),
        };
        rec.timings.push(("projector coordinates".into(), t0.elapsed().as_secs_f64()));
        if let Some(Ok(maps)) = &rec.projector {
            rec.warnings.extend(maps.iter().flat_map(|c| c.warnings.iter().cloned()));
        }
    }
    Ok(rec)
}

/// [`run_phase`] for a batch caller that needs the images no more: each
/// camera's raw samples are freed as soon as its phases are computed, so the
/// second camera's maps never coexist with the first camera's samples; with
/// [`PerSetMaps::Release`] each camera's per-set maps go too once its phase is
/// fused ([`CameraPhase::release_per_set_maps`]), so they never coexist
/// with the next camera's either. The measurement keeps its sets, cameras'
/// names and sizes and calibration, which is all [`run_stereo`] reads.
pub fn run_phase_releasing_samples(
    m: &mut Measurement,
    params: &Params,
    per_set_maps: PerSetMaps,
    control: &RunControl,
) -> Result<Reconstruction, EngineError> {
    check_shapes(m)?;
    let mut stacks: Vec<Vec<FringeStack>> = m.cameras.iter_mut().map(|c| std::mem::take(&mut c.stacks)).collect();
    phase_stages(m, params, None, control, Samples::Owned { stacks: &mut stacks, per_set_maps })
}

/// Whether a batch run keeps each camera's per-set maps (to write them) or
/// frees them once the camera's phase is fused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PerSetMaps {
    Keep,
    Release,
}

/// Where the per-camera stages find each camera's image stacks.
enum Samples<'a> {
    /// In the measurement, kept.
    Borrowed,
    /// Taken out of the measurement, one list per camera, released camera by
    /// camera, with the per-set maps unless they are to be kept.
    Owned { stacks: &'a mut Vec<Vec<FringeStack>>, per_set_maps: PerSetMaps },
}

fn phase_stages(
    m: &Measurement,
    params: &Params,
    previous: Option<&Reconstruction>,
    control: &RunControl,
    mut samples: Samples<'_>,
) -> Result<Reconstruction, EngineError> {
    let enabled: Vec<usize> = (0..m.sets.len()).filter(|&s| params.set_enabled(s)).collect();
    if enabled.is_empty() {
        return Err(EngineError::NoEnabledSet);
    }
    let phase_params = params.phase_params(m);
    // Per-set phases depend only on the threshold, the sample selection and
    // the modulation floor; reuse them when those are unchanged.
    let reusable = previous.filter(|p| {
        p.measurement_id == m.id
            && p.saturation_threshold == phase_params.saturation_threshold
            && p.params.method.selection() == phase_params.selection
            && p.params.min_modulation_dn == phase_params.min_modulation_dn
    });
    let mut timings = Vec::new();
    let mut warnings = Vec::new();
    let mut cameras = Vec::with_capacity(m.cameras.len());
    for (ci, cam) in m.cameras.iter().enumerate() {
        let t0 = Instant::now();
        let mut sets = Vec::with_capacity(m.sets.len());
        let mut texture = None;
        // Taken out of the measurement, a stack is dropped as soon as no
        // later step of this camera can want its samples: once any set's
        // noise is measured, the 3-step noise estimate from the stacks
        // (`measure_unmeasured_noise`) is not needed, so each set's samples
        // go right after its phase. A full-size one-shot run's peak falls
        // from 662 to 584 MB, and it faults in that many fewer fresh pages
        // (docs/benchmarks-history.md).
        let mut owned: Option<Vec<Option<FringeStack>>> = match &mut samples {
            Samples::Borrowed => None,
            Samples::Owned { stacks, .. } => Some(std::mem::take(&mut stacks[ci]).into_iter().map(Some).collect()),
        };
        if let Some(prev) = reusable.and_then(|p| p.cameras.get(ci)) {
            sets.extend(prev.sets.iter().map(Arc::clone));
            texture = Some(Arc::clone(&prev.texture_dn));
        } else {
            let mut fresh: Vec<WrappedPhase> = Vec::with_capacity(m.sets.len());
            let mut any_measured = false;
            for (s, set) in m.sets.iter().enumerate() {
                control.begin_stage(&format!("phase {} period {}", cam.name, set.period_px));
                let stack = match &owned {
                    None => &cam.stacks[s],
                    Some(stacks) => stacks[s].as_ref().expect("a set's samples are dropped only after its phase"),
                };
                let mut wp = wrapped_phase(stack, set, &phase_params, s == 0, control)?;
                if let Some(offset) = wp.offset_dn.take() {
                    texture = Some(Arc::new(offset));
                }
                any_measured |= wp.noise.measured;
                fresh.push(wp);
                if let Some(stacks) = &mut owned
                    && any_measured
                {
                    stacks[..=s].iter_mut().for_each(|stack| drop(stack.take()));
                }
            }
            // The stacks are read only when no set measured its noise, and
            // then none was dropped.
            let kept: Vec<FringeStack> = match &mut owned {
                Some(stacks) if !any_measured => stacks.iter_mut().filter_map(Option::take).collect(),
                _ => Vec::new(),
            };
            let stacks: &[FringeStack] = if owned.is_some() { &kept } else { &cam.stacks };
            measure_unmeasured_noise(&mut fresh, stacks, m, &phase_params);
            sets.extend(fresh.into_iter().map(Arc::new));
        }
        timings.push((format!("phase {}", cam.name), t0.elapsed().as_secs_f64()));
        drop(owned);
        let t1 = Instant::now();
        control.begin_stage(&format!("unwrap {}", cam.name));
        let chain: Vec<&WrappedPhase> = enabled.iter().map(|&s| sets[s].as_ref()).collect();
        let unwrapped = unwrap_hierarchical(&chain, params.order_check, control)?;
        let fused = fuse(&chain, &unwrapped, &enabled, params.method.fusion_rule(), params.own_orders_only);
        let root_wraps = unwrapped.root_wrap_fraction;
        timings.push((format!("unwrap+fuse {}", cam.name), t1.elapsed().as_secs_f64()));
        camera_warnings(m, cam.name.as_str(), &sets, &enabled, &fused, root_wraps, params.order_check, &mut warnings);
        cameras.push(CameraPhase {
            camera: cam.name.clone(),
            width: cam.width,
            height: cam.height,
            sets,
            enabled: enabled.clone(),
            unwrapped,
            fused,
            texture_dn: texture.unwrap_or_else(|| Arc::new(vec![0.0; cam.width * cam.height])),
            root_wrap_fraction: root_wraps,
        });
        if let (Samples::Owned { per_set_maps: PerSetMaps::Release, .. }, Some(camera)) = (&samples, cameras.last_mut())
        {
            camera.release_per_set_maps(ci == 0);
        }
        control.check()?;
    }
    Ok(Reconstruction {
        measurement_id: m.id,
        params: params.clone(),
        saturation_threshold: phase_params.saturation_threshold,
        cameras,
        stereo: None,
        stereo_skipped: Some("phase stages only".into()),
        warnings,
        timings,
        projector: None,
        rig_cloud: None,
    })
}

/// Sets whose fit leaves no residual (3 shifts) get the camera's noise from
/// its other sets' residuals or, failing those, from the offsets' spread
/// between sets, so that their phase sigma (and every fringe-order decision
/// made with it) rests on a measurement, not on an assumed grey level.
fn measure_unmeasured_noise(sets: &mut [WrappedPhase], stacks: &[FringeStack], m: &Measurement, params: &PhaseParams) {
    if sets.iter().all(|s| s.noise.measured) {
        return;
    }
    let mut measured: Vec<(f32, usize)> =
        sets.iter().filter(|s| s.noise.measured).map(|s| (s.noise.sigma_dn, s.noise.pixels)).collect();
    let camera_noise = if measured.is_empty() {
        let stack_refs: Vec<&FringeStack> = stacks.iter().collect();
        let shifts: Vec<&[f64]> = m.sets.iter().map(|s| s.phase_shifts_rad.as_slice()).collect();
        cross_set_noise(&stack_refs, &shifts, params).map(|(sigma, n)| (sigma, n, NoiseSource::CrossSetOffsets))
    } else {
        measured.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (sigma, n) = measured[measured.len() / 2];
        Some((sigma, n, NoiseSource::OtherSets))
    };
    if let Some((sigma, n, source)) = camera_noise {
        for set in sets.iter_mut().filter(|s| !s.noise.measured) {
            set.rescale_noise(sigma, n, source);
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn camera_warnings(
    m: &Measurement,
    camera: &str,
    sets: &[Arc<WrappedPhase>],
    enabled: &[usize],
    fused: &Fused,
    root_wraps: f64,
    order_check: OrderCheck,
    warnings: &mut Vec<Warning>,
) {
    for (s, wp) in sets.iter().enumerate() {
        if wp.stats.valid == 0 {
            let (kind, why) = if wp.stats.over_saturated == wp.stats.pixels {
                (
                    WarningKind::SetAllSaturated,
                    "every pixel has fewer than 3 unsaturated samples (all saturated: lower the exposure or raise the \
                     threshold)",
                )
            } else {
                (
                    WarningKind::SetTooDark,
                    "no pixel reaches the minimum modulation (dark or defocused: check the exposure and the modulation \
                     floor)",
                )
            };
            let message = format!("camera '{camera}', set {s} (period {} px): no usable pixel; {why}", wp.period_px);
            warnings.push(Warning::new(kind, message));
        }
    }
    // A camera–projector rig's Gray code makes its phase absolute instead
    // (the projector coordinate maps): the wrap is its design, not a fault.
    let gray_code = m.projector.as_ref().is_some_and(|p| p.gray_code.is_some());
    if root_wraps > ROOT_WRAP_WARNING_FRACTION && !gray_code {
        let root = enabled[0];
        warnings.push(Warning::new(WarningKind::SparsestSetWraps, format!(
            "camera '{camera}': the sparsest enabled set (period {} px) wraps inside the field in {:.0} % of rows, so its \
             phase is not absolute and every unwrapped phase is ambiguous; enable a set whose period covers the projector",
            m.sets[root].period_px,
            root_wraps * 100.0
        )));
    }
    for pair in enabled.windows(2) {
        let (a, b) = (&sets[pair[0]], &sets[pair[1]]);
        let (sa, sb) = (median_finite(&a.phase_sigma_rad), median_finite(&b.phase_sigma_rad));
        if let (Some(sa), Some(sb)) = (sa, sb) {
            let ratio = a.period_px / b.period_px;
            let predicted = ((ratio * sa).powi(2) + sb * sb).sqrt();
            // Warned where the typical pixel's order is beyond what the
            // order check can decide (for `evidence`: a wrong order more
            // likely than 5 % even before neighbours are asked).
            let limit = order_check.warning_sigma_rad();
            if predicted > limit {
                let p_wrong = super::unwrap::wrong_order_probability(predicted);
                warnings.push(Warning::new(WarningKind::PeriodRatioTooLarge, format!(
                    "camera '{camera}': period ratio {ratio:.1} from {} px to {} px is too large for reliable unwrapping at \
                     the measured phase noise (predicted order error {predicted:.2} rad > {limit:.2} rad, a wrong order \
                     with probability {:.0} % per pixel); add an intermediate period or more shifts",
                    a.period_px,
                    b.period_px,
                    p_wrong * 100.0
                )));
            }
        }
    }
    if fused.valid_count() == 0 {
        warnings.push(Warning::new(
            WarningKind::NoAbsolutePhase,
            format!("camera '{camera}': no pixel has a valid absolute phase"),
        ));
    }
}

/// Median of the finite values of a map, from a subsample.
pub fn median_finite(map: &[f32]) -> Option<f64> {
    let step = (map.len() / 20_000).max(1);
    let mut v: Vec<f32> = map.iter().step_by(step).copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    Some(f64::from(*m))
}

/// The whole method: per-camera stages, then stereo when the measurement has
/// two cameras and a calibration (otherwise `stereo_skipped` says why).
pub fn run(
    m: &Measurement,
    params: &Params,
    previous: Option<&Reconstruction>,
    control: &RunControl,
) -> Result<Reconstruction, EngineError> {
    let mut rec = run_phase(m, params, previous, control)?;
    run_stereo(m, params, &mut rec, control)?;
    Ok(rec)
}

/// The stereo half of [`run`] on a finished [`run_phase`]: it reads only the
/// measurement's calibration and set periods, never its images, so a batch
/// caller may release the raw samples in between to lower its peak memory.
pub fn run_stereo(
    m: &Measurement,
    params: &Params,
    rec: &mut Reconstruction,
    control: &RunControl,
) -> Result<(), EngineError> {
    rec.stereo_skipped = None;
    rec.rig_cloud = None;
    if let Some(patterns) = m.projector.as_ref() {
        // A camera–projector rig: its 3D comes from the projector coordinates.
        rec.stereo_skipped = match (&rec.projector, &patterns.calibration) {
            (_, None) => Some(
                "3D needs the rig's calibration (a pinhole-camera-projector file named by the manifest); the \
                 projector coordinates only"
                    .into(),
            ),
            (Some(Ok(maps)), Some(_)) => {
                let t0 = Instant::now();
                rec.rig_cloud = super::camera_projector::rig_cloud_seen_from_camera(m, maps).map(Arc::new);
                rec.timings.push(("camera–projector 3D".into(), t0.elapsed().as_secs_f64()));
                rec.rig_cloud.is_none().then(|| "no projector x was decoded".into())
            }
            (Some(Err(e)), Some(_)) => Some(format!("no projector coordinates: {e}")),
            (None, Some(_)) => Some("no Gray code: no absolute projector coordinate".into()),
        };
        control.check()?;
        return Ok(());
    }
    let Some(calib) = m.calibration.as_ref() else {
        rec.stereo_skipped = Some(if m.cameras.len() < 2 {
            "3D needs a second camera and a calibration; this measurement has one camera and no calibration \
             (phase maps only)"
                .into()
        } else {
            "3D needs a calibration; the manifest has none (phase maps only)".into()
        });
        return Ok(());
    };
    if m.cameras.len() < 2 {
        rec.stereo_skipped = Some("3D needs a second camera; the manifest has one (phase maps only)".into());
        return Ok(());
    }
    if let Err(e) = calib.validate() {
        rec.stereo_skipped = Some(format!("calibration unusable: {e}"));
        rec.warnings.push(Warning::new(WarningKind::CalibrationUnusable, format!("no 3D: calibration unusable: {e}")));
        return Ok(());
    }
    for (cam, model) in rec.cameras.iter().zip([&calib.left, &calib.right]) {
        if cam.width != model.width || cam.height != model.height {
            let msg = format!(
                "calibration is for {}x{} px images but camera '{}' images are {}x{} px",
                model.width, model.height, cam.camera, cam.width, cam.height
            );
            rec.warnings.push(Warning::new(WarningKind::CalibrationSizeMismatch, format!("no 3D: {msg}")));
            rec.stereo_skipped = Some(msg);
            return Ok(());
        }
    }
    let t0 = Instant::now();
    let (left, right) = (&rec.cameras[0], &rec.cameras[1]);
    fn view(c: &CameraPhase) -> PhaseMapView<'_> {
        PhaseMapView {
            width: c.width,
            height: c.height,
            phase_rad: &c.fused.fused_phase_rad,
            sigma_rad: &c.fused.fused_sigma_rad,
        }
    }
    let periods = m.periods_px();
    let attributes = LeftAttributes {
        source_set: &left.fused.source_set,
        periods_px: &periods,
        modulation_dn: left.sets.iter().map(|s| s.modulation_dn.as_slice()).collect(),
        texture_dn: &left.texture_dn,
        order_evidence: &left.fused.order_evidence,
    };
    // The limit in calibration units.
    let max_sigma_z = params.max_sigma_z_um.map_or(f64::INFINITY, |limit| f64::from(limit) / calib.unit.um_per_unit());
    let continuity = params.stereo_continuity.continuity();
    match super::stereo::reconstruct(calib, &view(left), &view(right), &attributes, max_sigma_z, continuity, control) {
        Ok(result) => {
            rec.timings.extend(result.timings.iter().cloned());
            if result.cloud.is_empty() {
                rec.warnings.push(Warning::new(WarningKind::NoStereoMatch, format!(
                    "no 3D point: {} left pixels had a phase, none matched in the right camera ({} unmatched, {} ambiguous); \
                     do the cameras share a field of view?",
                    result.match_stats.candidates, result.match_stats.unmatched, result.match_stats.ambiguous
                )));
            }
            rec.stereo = Some(result);
        }
        Err(StereoError::Cancelled(c)) => return Err(c.into()),
        Err(e) => {
            rec.warnings.push(Warning::new(WarningKind::StereoFailed, format!("no 3D: {e}")));
            rec.stereo_skipped = Some(e.to_string());
        }
    }
    rec.timings.push((STEREO_TOTAL.into(), t0.elapsed().as_secs_f64()));
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn parameters_saved_before_issue_18_load_with_its_defaults() {
        let mut json = serde_json::to_value(super::Params::default()).expect("serialise");
        let map = json.as_object_mut().expect("object");
        for key in ["order_check", "own_orders_only", "stereo_continuity"] {
            assert!(map.remove(key).is_some(), "{key} is saved");
        }
        let params: super::Params = serde_json::from_value(json).expect("an older session's parameters load");
        assert_eq!(params.order_check, super::OrderCheck::Evidence);
        assert!(!params.own_orders_only);
        assert_eq!(params.stereo_continuity, super::StereoContinuity::Strict);
    }
}
