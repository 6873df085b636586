//! The Inspect view's computations, off the UI thread and memoised: the
//! height map is rasterized once per result (and raster parameters), the
//! analysis (levelling, measurements, profiles, display heights) once per
//! change of the inspection. Each runs as a [`Job`]; a newer request cancels
//! the older one (latest wins), and the last finished value stays on screen
//! until the new one arrives.

use crate::engine::warning::{Warning, WarningKind};
use std::sync::Arc;

use crate::analysis::AnalysisError;
use crate::analysis::height_map::{
    DisplayFill, DisplayFillParams, HeightMap, RasterParams, Rasterized, camera_pitch_mm, fill_holes_for_display,
    height_map_from_cloud,
};
use crate::analysis::inspection::{
    InspectionReport, InspectionSpec, MeasurementContext, run_inspection_controlled, texture_surface_on_map,
};
use crate::analysis::plane_fit::{PlaneFit, level};
use crate::analysis::region::NamedRegion;
use crate::analysis::uncertainty::ScaleUncertainty;
use crate::app::jobs::{Job, JobOutcome};
use crate::engine::camera_model::StereoCalibration;
use crate::engine::control::RunControl;
use crate::engine::pipeline::Reconstruction;

/// A computation as a job runs it.
type Work<T> = Box<dyn FnOnce(&RunControl) -> anyhow::Result<T> + Send>;

/// Work queued behind the running job: its key, label, wake-up and closure.
type Pending<T> = (u64, String, Box<dyn Fn() + Send>, Work<T>);

/// The latest value of a keyed computation on a worker thread. At most one
/// job runs: a request made meanwhile waits, and a newer request replaces
/// the waiting one, so dragging a slider queues no pile of jobs. Work that
/// checks its [`RunControl`] often ([`Latest::interruptible`]) is cancelled
/// instead, and the newer request starts at once.
pub struct Latest<T> {
    wanted: Option<u64>,
    running: Option<(u64, Job<anyhow::Result<T>>)>,
    pending: Option<Pending<T>>,
    done: Option<(u64, anyhow::Result<T>)>,
    interruptible: bool,
}

impl<T> Default for Latest<T> {
    fn default() -> Self {
        Self { wanted: None, running: None, pending: None, done: None, interruptible: false }
    }
}

impl<T> Latest<T> {
    /// For work that stops soon after its control is cancelled.
    pub fn interruptible() -> Self {
        Self { interruptible: true, ..Self::default() }
    }
}

impl<T: Send + 'static> Latest<T> {
    /// Computes `work` for `key` unless that key is already wanted (running,
    /// waiting or done): now if nothing runs, else after the running job.
    pub fn request(
        &mut self,
        key: u64,
        label: &str,
        repaint: impl Fn() + Send + 'static,
        work: impl FnOnce(&RunControl) -> anyhow::Result<T> + Send + 'static,
    ) {
        if self.wanted == Some(key) {
            return;
        }
        self.wanted = Some(key);
        if self.interruptible
            && let Some((_, job)) = self.running.take()
        {
            job.cancel();
        }
        if self.running.is_some() {
            self.pending = Some((key, label.to_owned(), Box::new(repaint), Box::new(work)));
        } else {
            self.spawn(key, label, Box::new(repaint), Box::new(work));
        }
    }

    fn spawn(&mut self, key: u64, label: &str, repaint: Box<dyn Fn() + Send>, work: Work<T>) {
        let job = Job::spawn(label, repaint, move |control| {
            let out = work(control);
            control.check()?;
            Ok(out)
        });
        self.running = Some((key, job));
    }

    /// Collects a finished job and starts the waiting one; true when a new
    /// value (or error) arrived.
    pub fn poll(&mut self) -> bool {
        let Some((key, job)) = &self.running else { return false };
        let Some(outcome) = job.poll() else { return false };
        let key = *key;
        self.running = None;
        let arrived = match outcome {
            JobOutcome::Done(v) => Some(v),
            JobOutcome::Failed(e) => Some(Err(e)),
            JobOutcome::Panicked(e) => Some(Err(anyhow::anyhow!("the computation crashed: {e}"))),
            JobOutcome::Cancelled => None,
        };
        if let Some(v) = arrived {
            self.done = Some((key, v));
        }
        if let Some((key, label, repaint, work)) = self.pending.take() {
            self.spawn(key, &label, repaint, work);
        } else if arrived_none_for_wanted(self.wanted, key, self.done.as_ref().map(|d| d.0)) {
            self.wanted = None;
        }
        true
    }

    /// The last finished value (possibly for an older key).
    pub fn value(&self) -> Option<&T> {
        self.done.as_ref().and_then(|(_, v)| v.as_ref().ok())
    }

    /// The key the last finished value was computed for.
    pub fn value_key(&self) -> Option<u64> {
        self.done.as_ref().map(|(k, _)| *k)
    }

    /// The last finished result, value or error.
    pub fn result(&self) -> Option<&anyhow::Result<T>> {
        self.done.as_ref().map(|(_, v)| v)
    }

    /// True when the last finished value is for the key last requested.
    pub fn is_current(&self) -> bool {
        self.wanted.is_some() && self.done.as_ref().map(|(k, _)| *k) == self.wanted
    }

    pub fn is_running(&self) -> bool {
        self.running.is_some()
    }

    /// Stops the running job and forgets the wish for its key; the last
    /// finished value stays. The key it ran for, if one ran.
    pub fn cancel(&mut self) -> Option<u64> {
        let (key, job) = self.running.take()?;
        job.cancel();
        self.pending = None;
        self.wanted = None;
        Some(key)
    }

    /// Forgets everything (new measurement).
    pub fn clear(&mut self) {
        if let Some((_, job)) = self.running.take() {
            job.cancel();
        }
        self.pending = None;
        self.wanted = None;
        self.done = None;
    }
}

/// A cancelled job for the wanted key leaves nothing done for it: forget
/// the wish so the next request starts it again.
fn arrived_none_for_wanted(wanted: Option<u64>, finished: u64, done: Option<u64>) -> bool {
    wanted == Some(finished) && done != Some(finished)
}

/// The raster parameters with the pitch chosen: the operator's, else the
/// left camera's pixel pitch on the object (the finest grid the data
/// supports), else the cloud's own neighbour spacing.
pub fn raster_params(params: &RasterParams, calibration: Option<&StereoCalibration>) -> RasterParams {
    let pitch_mm = params.pitch_mm.or_else(|| calibration.and_then(|c| camera_pitch_mm(&c.left, c.unit).ok()));
    RasterParams { pitch_mm, ..params.clone() }
}

/// Rasterizes the result's point cloud (worker side).
pub fn rasterize(rec: &Reconstruction, params: &RasterParams, control: &RunControl) -> anyhow::Result<Rasterized> {
    control.begin_stage("height map: rasterizing the point cloud");
    let cloud = rec.cloud().ok_or_else(|| {
        anyhow::anyhow!("no 3D points: {}", rec.stereo_skipped.as_deref().unwrap_or("no stereo result"))
    })?;
    Ok(height_map_from_cloud(cloud, params)?)
}

/// Everything the view draws from one inspection on one map.
pub struct Analysis {
    /// The map as displayed and profiled: levelled when levelling worked.
    pub map: Arc<HeightMap>,
    pub levelling: Option<PlaneFit>,
    /// Measurements and profiles; `Err` when the inspection cannot run.
    pub report: Result<InspectionReport, AnalysisError>,
    pub warnings: Vec<Warning>,
    /// Display heights in um, row-major as the map (row 0 = lowest Y); filled
    /// nodes only when hole filling is on.
    pub display_um: Vec<f32>,
    /// Nodes holding a filled (not measured) value.
    pub filled: Option<Vec<bool>>,
    pub holes_filled: usize,
    /// Robust (1-99 %) range of the display heights, um.
    pub range_um: Option<(f32, f32)>,
    /// What the display holds: the heights, a texture measurement's
    /// scale-limited surface, or the part less its aligned reference.
    pub shown: MapShows,
}

/// What the Inspect map shows.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub enum MapShows {
    #[default]
    Heights,
    /// A texture measurement's scale-limited surface (S-F or S-L), on its region.
    Surface(String),
    /// The part less its aligned reference (a followed recipe).
    DifferenceToReference,
}

/// Levels, measures and prepares the display (worker side).
pub fn analyse(
    map: &HeightMap,
    spec: &InspectionSpec,
    calibration: Option<ScaleUncertainty>,
    fill: Option<DisplayFillParams>,
    surface: Option<&str>,
    control: &RunControl,
) -> Analysis {
    let mut warnings = Vec::new();
    let mut spec = spec.clone();
    let (display_map, levelling) = if spec.level_to.is_empty() {
        (Arc::new(map.clone()), None)
    } else {
        let reference: Vec<NamedRegion> =
            spec.regions.iter().filter(|r| spec.level_to.contains(&r.name)).cloned().collect();
        match level(map, &reference) {
            Ok(l) => (Arc::new(l.map), Some(l.reference)),
            Err(e) => {
                warnings.push(Warning::new(WarningKind::NotLevelled, format!("not levelled: {e}")));
                spec.level_to.clear();
                (Arc::new(map.clone()), None)
            }
        }
    };
    let report = run_inspection_controlled(map, &spec, &MeasurementContext { noise: None, calibration }, control);
    if let Ok(r) = &report {
        warnings.extend(r.warnings.iter().cloned());
    }
    let (z_mm, filled, holes_filled): (Vec<f32>, Option<Vec<bool>>, usize) = match fill {
        Some(params) => {
            let DisplayFill { z_mm, filled, holes_filled, .. } = fill_holes_for_display(&display_map, &params);
            (z_mm, Some(filled), holes_filled)
        }
        None => (display_map.z.clone(), None, 0),
    };
    // The display map's unit (mm unless a calibration says otherwise).
    let um_per_unit = display_map.unit.um_per_unit() as f32;
    let mut display_um: Vec<f32> = z_mm.iter().map(|z| z * um_per_unit).collect();
    let mut shown = MapShows::Heights;
    if let Some(name) = surface {
        match texture_surface_on_map(&display_map, &spec, name) {
            Ok(z_um) => {
                display_um = z_um;
                shown = MapShows::Surface(name.to_string());
            }
            Err(e) => warnings.push(Warning::new(
                WarningKind::NotMeasured,
                format!("the surface of '{name}' cannot be shown: {e}; the heights are"),
            )),
        }
    }
    let range_um = crate::app::views::robust_range(&display_um, 0.01, 0.99);
    let filled = if shown == MapShows::Heights { filled } else { None };
    Analysis { map: display_map, levelling, report, warnings, display_um, filled, holes_filled, range_um, shown }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::inspection::{Measure, MeasurementSpec};
    use crate::analysis::region::Region;
    use crate::analysis::testing::node_map;

    /// A calibration that states its scales exactly (no warning about it).
    const KNOWN: Option<ScaleUncertainty> =
        Some(ScaleUncertainty { height_relative: Some(0.0), lateral_relative: Some(0.0) });

    #[test]
    fn one_job_runs_and_the_newest_request_waits() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let runs = Arc::new(AtomicUsize::new(0));
        let mut latest: Latest<u64> = Latest::default();
        for key in 1..=5u64 {
            let runs = Arc::clone(&runs);
            latest.request(
                key,
                "test",
                || {},
                move |_| {
                    runs.fetch_add(1, Ordering::SeqCst);
                    std::thread::sleep(std::time::Duration::from_millis(30));
                    Ok(key * 10)
                },
            );
        }
        latest.request(5, "test", || {}, |_| Ok(0));
        for _ in 0..500 {
            latest.poll();
            if latest.is_current() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        assert!(latest.is_current() && !latest.is_running());
        assert_eq!(latest.value(), Some(&50), "the newest request wins");
        assert_eq!(latest.value_key(), Some(5));
        assert_eq!(runs.load(Ordering::SeqCst), 2, "the first job and the newest, not all five");
    }

    /// Interruptible work is cancelled by a newer request, which starts at
    /// once; a cancel by the operator forgets the wish and keeps the last value.
    #[test]
    fn a_newer_request_cancels_interruptible_work_and_the_operator_can_too() {
        let wait = |latest: &mut Latest<u64>, until: &dyn Fn(&Latest<u64>) -> bool| {
            for _ in 0..2000 {
                latest.poll();
                if until(latest) {
                    return;
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            panic!("timed out");
        };
        // Work that runs until it is cancelled.
        let endless = |control: &RunControl| {
            while !control.is_cancelled() {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            Ok(0)
        };
        let mut latest: Latest<u64> = Latest::interruptible();
        latest.request(1, "test", || {}, endless);
        latest.request(2, "test", || {}, |_| Ok(20));
        wait(&mut latest, &|l| l.is_current());
        assert_eq!((latest.value(), latest.value_key()), (Some(&20), Some(2)), "the newer one ran at once");
        latest.request(3, "test", || {}, endless);
        assert!(latest.is_running());
        assert_eq!(latest.cancel(), Some(3));
        assert!(!latest.is_running() && !latest.is_current());
        assert_eq!(latest.value(), Some(&20), "the last finished value stays");
    }

    #[test]
    fn a_cancelled_inspection_stops_with_cancelled() {
        let map = node_map(64, 64, [0.0, 0.0], 0.01, |x, _| Some(0.001 * x));
        let spec = InspectionSpec {
            regions: vec![NamedRegion::new("all", Region::Rectangle { x_mm: [0.0, 1.0], y_mm: [0.0, 1.0] })],
            measurements: vec![MeasurementSpec {
                name: "t".into(),
                measure: Measure::Texture {
                    region: "all".into(),
                    form: crate::analysis::texture::filter::FormRemoval::Plane,
                    ls_mm: None,
                    lc_mm: None,
                    smr_c_um: None,
                    smc_mr_percent: None,
                    limits: Default::default(),
                },
                nominal: None,
                tolerance: None,
            }],
            ..InspectionSpec::default()
        };
        let control = RunControl::new();
        control.cancel();
        let a = analyse(&map, &spec, KNOWN, None, None, &control);
        assert!(matches!(a.report, Err(AnalysisError::Cancelled(_))), "{:?}", a.report.map(|r| r.table));
        assert!(analyse(&map, &spec, KNOWN, None, None, &RunControl::new()).report.is_ok());
    }

    #[test]
    fn levelling_flattens_the_display_and_measures_the_step() {
        // A plane tilted 1 mrad in X with a 20 um step for y > 0.5 mm.
        let map = node_map(101, 101, [0.0, 0.0], 0.01, |x, y| Some(0.001 * x + if y > 0.5 { 0.02 } else { 0.0 }));
        let spec = InspectionSpec {
            level_to: vec!["base".into()],
            regions: vec![
                NamedRegion::new("base", Region::Rectangle { x_mm: [0.0, 1.0], y_mm: [0.0, 0.4] }),
                NamedRegion::new("top", Region::Rectangle { x_mm: [0.0, 1.0], y_mm: [0.6, 1.0] }),
            ],
            measurements: vec![MeasurementSpec {
                name: "step".into(),
                measure: Measure::StepHeight { reference: vec!["base".into()], measured: vec!["top".into()] },
                nominal: None,
                tolerance: None,
            }],
            ..InspectionSpec::default()
        };
        let a = analyse(&map, &spec, KNOWN, None, None, &RunControl::new());
        assert!(a.warnings.is_empty(), "{:?}", a.warnings);
        let step = a.report.as_ref().unwrap().table.rows[0].value.unwrap();
        assert!((step - 20.0).abs() < 1e-3, "{step}");
        // Display in um, levelled: the base at 0, the top at 20.
        assert!(a.display_um[0].abs() < 1e-3 && (a.display_um[100].abs()) < 1e-3, "tilt removed");
        assert!((a.display_um[100 * 101 + 50] - 20.0).abs() < 1e-3);
        let (lo, hi) = a.range_um.unwrap();
        assert!(lo.abs() < 1e-2 && (hi - 20.0).abs() < 1e-2, "{lo} {hi}");

        // A reference on a hole: shown unlevelled with a warning, not an error.
        let holey = node_map(101, 101, [0.0, 0.0], 0.01, |_, y| (y > 0.45).then_some(0.0));
        let a = analyse(&holey, &spec, KNOWN, None, None, &RunControl::new());
        assert!(a.levelling.is_none());
        assert!(a.warnings.iter().any(|w| w.kind == WarningKind::NotLevelled), "{:?}", a.warnings);
        assert!(a.report.is_ok());
    }

    #[test]
    fn hole_filling_is_for_display_and_marked() {
        let map = node_map(20, 20, [0.0, 0.0], 0.01, |x, y| {
            ((x - 0.1).abs() > 0.015 || (y - 0.1).abs() > 0.015).then_some(0.001)
        });
        let holes = map.z.iter().filter(|z| z.is_nan()).count();
        assert!(holes > 0);
        let a = analyse(
            &map,
            &InspectionSpec::default(),
            KNOWN,
            Some(DisplayFillParams::default()),
            None,
            &RunControl::new(),
        );
        let filled = a.filled.as_ref().unwrap();
        assert_eq!(filled.iter().filter(|f| **f).count(), holes);
        assert!(a.display_um.iter().all(|z| (z - 1.0).abs() < 1e-4));
        assert_eq!(a.map.z.iter().filter(|z| z.is_nan()).count(), holes, "the measured map keeps its holes");
    }
}
