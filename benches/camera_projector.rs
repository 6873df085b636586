//! Camera–projector decoding (issue 52) on the real mug capture
//! (`../shared/data/real-mugs-3step-graycode`, 32 frames of 1936x1216 8-bit):
//! reading the frames, decoding both axes' Gray code, the four 3-step
//! wrapped phases, the absolute projector x and y, and the 3D point of
//! every pixel with a stand-in pinhole calibration (none ships with the
//! capture; the triangulation costs the same). The capture lives
//! beside the repository; without it the bench says so and measures nothing.
//! `SHEEN_REAL_DATA` points at another `data` folder.

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use sheen::engine::control::RunControl;
use sheen::engine::fringe::{FringeSetInfo, FringeStack};
use sheen::engine::gray_code::{GrayDecodeParams, bit_planes, decode_axis};
use sheen::engine::length_unit::LengthUnit;
use sheen::engine::phase_shift::{PhaseParams, SampleSelection, WrappedPhase, wrapped_phase};
use sheen::engine::pinhole::{CameraProjectorCalibration, PinholeDevice, reconstruct};
use sheen::engine::projector_coordinate::{AbsoluteParams, ProjectorCoordinate, SetPhase, absolute_coordinate};

/// As the `sheen` binary (`main.rs`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn capture() -> Option<PathBuf> {
    let dir = std::env::var_os("SHEEN_REAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"))
        .join("real-mugs-3step-graycode/images");
    dir.join("pat31.png").exists().then_some(dir)
}

struct Frames {
    width: usize,
    height: usize,
    frames: Vec<Vec<u8>>,
}

fn read(dir: &std::path::Path) -> Frames {
    use rayon::prelude::*;
    let frames: Vec<(Vec<u8>, usize, usize)> = (0..32)
        .into_par_iter()
        .map(|i| {
            let image = image::open(dir.join(format!("pat{i:02}.png"))).expect("a frame").to_luma8();
            let (w, h) = image.dimensions();
            (image.into_raw(), w as usize, h as usize)
        })
        .collect();
    let (width, height) = (frames[0].1, frames[0].2);
    Frames { width, height, frames: frames.into_iter().map(|f| f.0).collect() }
}

/// Both axes' projector coordinates from the frames in memory.
fn decode(f: &Frames) -> [ProjectorCoordinate; 2] {
    let grey = |i: usize| f.frames[i].iter().map(|&v| f32::from(v)).collect::<Vec<f32>>();
    let (white, black) = (grey(30), grey(31));
    let shifts = vec![-std::f64::consts::TAU / 3.0, 0.0, std::f64::consts::TAU / 3.0];
    let params =
        PhaseParams { saturation_threshold: 255, min_modulation_dn: 4.0, selection: SampleSelection::Unsaturated };
    let phase = |first: usize, period_px: f64| -> WrappedPhase {
        let stack = FringeStack::from_planes_u8(f.width, f.height, f.frames[first..first + 3].to_vec());
        let set = FringeSetInfo { period_px, phase_shifts_rad: shifts.clone() };
        wrapped_phase(&stack, &set, &params, false, &RunControl::new()).expect("not cancelled")
    };
    [([0usize, 3], 12usize, 20usize), ([6, 9], 22, 11)].map(|(sets, gray_first, cells)| {
        let frames: Vec<Vec<f32>> = (gray_first..gray_first + 2 * bit_planes(cells)).map(grey).collect();
        let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
        let code =
            decode_axis(&refs, &white, &black, f.width, f.height, cells, &GrayDecodeParams::default()).expect("code");
        let (short, long) = (phase(sets[0], 200.0 / 3.0), phase(sets[1], 100.0));
        let set_phases = [SetPhase::of(&short), SetPhase::of(&long)];
        absolute_coordinate(&code, 100.0, &set_phases, &AbsoluteParams::default()).expect("coordinates")
    })
}

/// A plausible calibration of the capture's rig (1936x1216 camera with
/// radial distortion, 1920x1080 projector 150 mm aside, turned 15°).
fn stand_in_calibration() -> CameraProjectorCalibration {
    let device =
        |width, height, f: f64, cx, cy, distortion| PinholeDevice { width, height, fx: f, fy: f, cx, cy, distortion };
    let (s, c) = 15f64.to_radians().sin_cos();
    CameraProjectorCalibration {
        unit: LengthUnit::Mm,
        camera: device(1936, 1216, 2400.0, 967.5, 607.5, [-0.1, 0.05, 0.0, 0.0, 0.0]),
        projector: device(1920, 1080, 2200.0, 959.5, 1079.5, [0.0; 5]),
        r: [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        t: [-150.0, 0.0, 20.0],
    }
}

fn bench(c: &mut Criterion) {
    let Some(dir) = capture() else {
        eprintln!("the real mug capture is not beside the repository: nothing measured");
        return;
    };
    let mut group = c.benchmark_group("camera-projector-1936x1216");
    group.sample_size(10);
    group.bench_function("read 32 PNG frames", |b| b.iter(|| read(&dir)));
    let frames = read(&dir);
    group.bench_function("Gray code + phases + projector x and y", |b| b.iter(|| decode(&frames)));
    group.bench_function("all of it, from the files", |b| b.iter(|| decode(&read(&dir))));
    let calibration = stand_in_calibration();
    group.bench_function("all of it and the 3D cloud, from the files", |b| {
        b.iter(|| {
            let [x, y] = decode(&read(&dir));
            reconstruct(&calibration, &x, Some(&y), None)
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
