//! A small synthetic stereo measurement with known content for the GUI tests:
//! a tilted plane seen by two telecentric cameras at +-15 degrees, lit by a
//! telecentric projector with three fringe sets (periods 500, 100, 20
//! projector pixels, 12 shifts each), and a shiny disc where the dense
//! fringes are fully blown out while the sparser ones keep 4 or more
//! unsaturated samples (the paper's Fig. 2 situation in miniature).

use sheen::app::loading::DemoData;
use sheen::engine::camera_model::{AffineCamera, StereoCalibration};
use sheen::engine::control::RunControl;
use sheen::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Measurement, next_measurement_id};

pub const WIDTH: usize = 160;
pub const HEIGHT: usize = 120;
pub const PERIODS_PX: [f64; 3] = [500.0, 100.0, 20.0];
pub const SHIFTS: usize = 12;
/// Camera pixel pitch on the object (mm).
pub const PITCH_MM: f64 = 0.01;
/// Projector pixel pitch on the object (mm); the field spans ~420 projector px.
const PROJECTOR_PITCH_MM: f64 = 0.004;
pub const THETA_DEG: f64 = 15.0;
/// The plane z = a x + b y (mm).
const SLOPE: [f64; 2] = [0.05, 0.03];
/// The shiny disc: centre (mm) and radius (mm).
pub const DISC_CENTER_MM: [f64; 2] = [0.25, 0.1];
pub const DISC_RADIUS_MM: f64 = 0.22;

/// (A, B) of the fringes per set outside and inside the disc, in grey levels.
/// Dense fringes are blurred more (lower B), as with the projector's shallow depth of field.
const MATTE: [(f64, f64); 3] = [(128.0, 100.0), (128.0, 80.0), (128.0, 60.0)];
const SHINY: [(f64, f64); 3] = [(300.0, 130.0), (300.0, 100.0), (320.0, 40.0)];

pub fn camera(sign: f64) -> AffineCamera {
    let t = THETA_DEG.to_radians();
    let (c, s) = (t.cos() / PITCH_MM, sign * t.sin() / PITCH_MM);
    AffineCamera {
        width: WIDTH,
        height: HEIGHT,
        p: [[c, 0.0, s, (WIDTH as f64 - 1.0) / 2.0], [0.0, -1.0 / PITCH_MM, 0.0, (HEIGHT as f64 - 1.0) / 2.0]],
        distortion: None,
    }
}

/// World point of the plane seen at pixel (u, v) of `cam`.
pub fn surface_point(cam: &AffineCamera, u: f64, v: f64) -> [f64; 3] {
    let p = &cam.p;
    let a = nalgebra::Matrix3::new(p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], -SLOPE[0], -SLOPE[1], 1.0);
    let b = nalgebra::Vector3::new(u - p[0][3], v - p[1][3], 0.0);
    let x = a.lu().solve(&b).expect("the plane is seen by the camera");
    [x[0], x[1], x[2]]
}

/// True if the pixel of the left camera lies on the shiny disc.
pub fn on_disc(point: [f64; 3]) -> bool {
    (point[0] - DISC_CENTER_MM[0]).hypot(point[1] - DISC_CENTER_MM[1]) < DISC_RADIUS_MM
}

pub fn left_camera() -> AffineCamera {
    camera(1.0)
}

fn render(cam: &AffineCamera, sets: &[FringeSetInfo]) -> Vec<FringeStack> {
    sets.iter()
        .enumerate()
        .map(|(s, set)| {
            let planes = set
                .phase_shifts_rad
                .iter()
                .map(|delta| {
                    (0..WIDTH * HEIGHT)
                        .map(|i| {
                            let x = surface_point(cam, (i % WIDTH) as f64, (i / WIDTH) as f64);
                            let projector_px = (x[0] + 1.0) / PROJECTOR_PITCH_MM;
                            let phase = std::f64::consts::TAU * projector_px / set.period_px;
                            let (a, b) = if on_disc(x) { SHINY[s] } else { MATTE[s] };
                            (a + b * (phase + delta).cos()).round().clamp(0.0, 255.0) as u8
                        })
                        .collect()
                })
                .collect();
            FringeStack::from_planes_u8(WIDTH, HEIGHT, planes)
        })
        .collect()
}

pub fn measurement() -> Measurement {
    let sets: Vec<FringeSetInfo> = PERIODS_PX.iter().map(|&p| FringeSetInfo::uniform(p, SHIFTS)).collect();
    let (left, right) = (camera(1.0), camera(-1.0));
    let cameras = vec![
        CameraFringes { name: "left".into(), width: WIDTH, height: HEIGHT, stacks: render(&left, &sets) },
        CameraFringes { name: "right".into(), width: WIDTH, height: HEIGHT, stacks: render(&right, &sets) },
    ];
    Measurement {
        bit_depth: 8,
        saturation_level: 255,
        sets,
        cameras,
        calibration: Some(StereoCalibration {
            unit: sheen::engine::length_unit::LengthUnit::Mm,
            left,
            right,
            rms_reprojection_px: None,
            scale_uncertainty: None,
        }),
        label: "synthetic tilted plane".into(),
        projector: None,
        id: next_measurement_id(),
    }
}

/// A [`sheen::app::loading::DemoFn`] giving this measurement (size ignored: fixed 160x120).
pub fn demo(_width: usize, _height: usize, control: &RunControl) -> anyhow::Result<DemoData> {
    control.check()?;
    Ok(DemoData { measurement: measurement(), description: "synthetic tilted plane, 160x120 px".into() })
}

/// A demo that never finishes unless cancelled: for testing the load's Cancel.
pub fn endless_demo(_width: usize, _height: usize, control: &RunControl) -> anyhow::Result<DemoData> {
    control.begin_stage("waiting to be cancelled");
    loop {
        if control.is_cancelled() {
            anyhow::bail!("cancelled");
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
}

/// Writes `m` as a manifest with 8-bit PNG images and an inline calibration
/// into `dir`, the way an acquisition program would; returns the manifest path.
pub fn write_manifest(dir: &std::path::Path, m: &Measurement) -> std::path::PathBuf {
    use sheen::engine::fringe::Samples;
    use sheen::io::manifest::{CalibrationSource, Manifest, ManifestSet, write_manifest};
    let mut sets = Vec::new();
    for (s, info) in m.sets.iter().enumerate() {
        let mut images = std::collections::BTreeMap::new();
        for cam in &m.cameras {
            std::fs::create_dir_all(dir.join(&cam.name)).expect("camera folder");
            let stack = &cam.stacks[s];
            let Samples::U8(samples) = &stack.samples else { panic!("8-bit data expected") };
            let plane_len = stack.width * stack.height;
            let names: Vec<String> = (0..stack.shifts)
                .map(|k| {
                    let name = format!("{}/p{}_{k:02}.png", cam.name, info.period_px);
                    let plane = samples[k * plane_len..(k + 1) * plane_len].to_vec();
                    let img =
                        image::GrayImage::from_raw(stack.width as u32, stack.height as u32, plane).expect("plane");
                    img.save(dir.join(&name)).expect("write png");
                    name
                })
                .collect();
            images.insert(cam.name.clone(), names);
        }
        sets.push(ManifestSet {
            period_px: info.period_px,
            shifts: info.shifts(),
            phase_shifts_rad: None,
            axis: Default::default(),
            images,
        });
    }
    let calibration =
        m.calibration.as_ref().map(|c| CalibrationSource::Inline(sheen::io::calibration::calibration_to_value(c)));
    let manifest = Manifest {
        bit_depth: m.bit_depth,
        saturation_level: Some(m.saturation_level),
        calibration,
        sets,
        projector: None,
        gray_code: None,
        warnings: Vec::new(),
    };
    let path = dir.join("manifest.json");
    write_manifest(&path, &manifest).expect("write manifest");
    path
}

/// A measurement whose stacks hold fewer samples than their shape says (what
/// a faulty importer could build): reading it by shape would index past the end.
pub fn truncated_demo(_width: usize, _height: usize, _control: &RunControl) -> anyhow::Result<DemoData> {
    let mut m = measurement();
    for cam in &mut m.cameras {
        for stack in &mut cam.stacks {
            stack.samples = sheen::engine::fringe::Samples::U8(vec![100; 10]);
        }
    }
    Ok(DemoData { measurement: m, description: "truncated synthetic data".into() })
}
