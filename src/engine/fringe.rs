//! In-memory fringe images of one measurement: per camera, one phase-shifted
//! stack per fringe period (the paper's `I^m_set`, Table 1).
//!
//! Samples stay in their acquired integer type (8-bit data as `u8`, 10-16-bit
//! data as `u16`) so the full-resolution workload (302 million samples) costs
//! its raw size in memory and the phase kernels read each sample once.

use std::f64::consts::TAU;

/// Raw samples of one stack, shift-major: plane `k` holds image `k`.
#[derive(Clone, Debug, PartialEq)]
pub enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

impl Samples {
    pub fn len(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    pub fn get(&self, index: usize) -> u16 {
        match self {
            Samples::U8(v) => u16::from(v[index]),
            Samples::U16(v) => v[index],
        }
    }

    pub fn byte_size(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len() * 2,
        }
    }
}

/// The N phase-shifted images of one camera for one fringe period.
#[derive(Clone, Debug, PartialEq)]
pub struct FringeStack {
    pub width: usize,
    pub height: usize,
    pub shifts: usize,
    pub samples: Samples,
}

impl FringeStack {
    /// Builds a stack from its planes; all planes must have `width * height` samples.
    pub fn from_planes_u8(width: usize, height: usize, planes: Vec<Vec<u8>>) -> Self {
        let shifts = planes.len();
        let mut samples = Vec::with_capacity(width * height * shifts);
        for plane in planes {
            assert_eq!(plane.len(), width * height, "plane size");
            samples.extend_from_slice(&plane);
        }
        Self { width, height, shifts, samples: Samples::U8(samples) }
    }

    pub fn from_planes_u16(width: usize, height: usize, planes: Vec<Vec<u16>>) -> Self {
        let shifts = planes.len();
        let mut samples = Vec::with_capacity(width * height * shifts);
        for plane in planes {
            assert_eq!(plane.len(), width * height, "plane size");
            samples.extend_from_slice(&plane);
        }
        Self { width, height, shifts, samples: Samples::U16(samples) }
    }

    pub fn pixel_count(&self) -> usize {
        self.width * self.height
    }

    /// Sample of image `shift` at linear pixel index `pixel`.
    #[inline]
    pub fn sample(&self, shift: usize, pixel: usize) -> u16 {
        self.samples.get(shift * self.pixel_count() + pixel)
    }

    /// All N samples of one pixel, in shift order.
    pub fn pixel_samples(&self, pixel: usize) -> Vec<u16> {
        (0..self.shifts).map(|k| self.sample(k, pixel)).collect()
    }
}

/// One fringe set of the manifest: its period and the phase shift of each image.
#[derive(Clone, Debug, PartialEq)]
pub struct FringeSetInfo {
    /// Fringe period in projector pixels (`per^m`).
    pub period_px: f64,
    /// Phase shift `delta_k` of image k in the model `I_k = A + B cos(Phi + delta_k)`.
    pub phase_shifts_rad: Vec<f64>,
}

impl FringeSetInfo {
    /// A set with the standard shifts `delta_k = 2 pi k / N`.
    pub fn uniform(period_px: f64, shifts: usize) -> Self {
        Self { period_px, phase_shifts_rad: uniform_shifts_rad(shifts) }
    }

    pub fn shifts(&self) -> usize {
        self.phase_shifts_rad.len()
    }
}

/// `delta_k = 2 pi k / N`, the manifest's default convention.
pub fn uniform_shifts_rad(shifts: usize) -> Vec<f64> {
    (0..shifts).map(|k| TAU * k as f64 / shifts as f64).collect()
}

/// The images of one camera, one stack per fringe set, in manifest order.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraFringes {
    pub name: String,
    pub width: usize,
    pub height: usize,
    pub stacks: Vec<FringeStack>,
}

/// A complete measurement held in memory: what a manifest describes, decoded.
#[derive(Clone, Debug)]
pub struct Measurement {
    pub bit_depth: u32,
    /// Largest value the camera can report; samples at or above the operator's
    /// threshold (default: this level) count as saturated (Alg. 1).
    pub saturation_level: u16,
    /// Sets from the sparsest (largest period) to the densest.
    pub sets: Vec<FringeSetInfo>,
    /// Cameras; with two, the first is the main (left) camera.
    pub cameras: Vec<CameraFringes>,
    pub calibration: Option<crate::engine::camera_model::StereoCalibration>,
    /// A camera–projector rig's other patterns (sets along y, Gray code,
    /// white and black); `None` for the telecentric pair and phase-only sets.
    pub projector: Option<crate::engine::camera_projector::ProjectorPatterns>,
    /// Where the data came from, for reports and window titles.
    pub label: String,
    /// Unique per loaded measurement (see [`next_measurement_id`]): results
    /// computed from one measurement are reused only for the same id.
    pub id: u64,
}

/// A fresh id for a newly built [`Measurement`].
pub fn next_measurement_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl Measurement {
    pub fn camera(&self, name: &str) -> Option<&CameraFringes> {
        self.cameras.iter().find(|c| c.name == name)
    }

    pub fn sample_bytes(&self) -> usize {
        self.cameras.iter().flat_map(|c| c.stacks.iter()).map(|s| s.samples.byte_size()).sum()
    }

    pub fn periods_px(&self) -> Vec<f64> {
        self.sets.iter().map(|s| s.period_px).collect()
    }
}
