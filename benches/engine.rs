//! Engine benchmarks (issue 8): each stage and the whole method on the
//! simulator's watch-plate scene, generated in process, at the paper's full
//! resolution (2 cameras x 4 sets x 12 shifts of 2048x1536 8-bit images) and
//! at a quick size, with a straightforward implementation of the per-camera
//! stages as the baseline so the speed-up is measured in the same run.
//!
//! `cargo bench --bench engine` runs both sizes; `SHEEN_BENCH_SIZE=quick`
//! (or `full`) runs one. Results are dropped outside the timed region
//! (`iter_with_large_drop`): freeing them is measured on its own
//! (`free_result`), as it happens when the next result replaces one.

mod baseline;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use sheen::engine::control::RunControl;
use sheen::engine::fringe::Measurement;
use sheen::engine::fusion::fuse;
use sheen::engine::phase_shift::{WrappedPhase, wrapped_phase};
use sheen::engine::pipeline::{self, Method, Params};
use sheen::engine::stereo::{LeftAttributes, PhaseMapView, reconstruct};
use sheen::engine::unwrap::{OrderCheck, unwrap_hierarchical};
use sheen::sim::{SceneKind, SimConfig, simulate};

/// As the `sheen` binary (`main.rs`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

struct Size {
    name: &'static str,
    width: usize,
    height: usize,
}

const SIZES: [Size; 2] = [
    Size { name: "quick-512x384", width: 512, height: 384 },
    Size { name: "full-2048x1536", width: 2048, height: 1536 },
];

fn sizes() -> Vec<&'static Size> {
    match std::env::var("SHEEN_BENCH_SIZE").as_deref() {
        Ok("quick") => vec![&SIZES[0]],
        Ok("full") => vec![&SIZES[1]],
        _ => SIZES.iter().collect(),
    }
}

fn watch_plate(size: &Size) -> Measurement {
    let mut config = SimConfig::new(SceneKind::WatchPlate, size.width, size.height);
    config.bits = 8;
    config.noise_sigma_dn = 1.0;
    simulate(&config, &RunControl::new()).expect("simulate the watch plate").measurement
}

fn benches(c: &mut Criterion) {
    // As the `sheen` binary does at start, and for the app: its runs reuse
    // the pages of the runs before (the warm engine is the app's engine).
    sheen::cli::keep_memory_as_the_app_does();
    for size in sizes() {
        let m = watch_plate(size);
        let params = Params { method: Method::Hdr, ..Params::default() };
        let control = RunControl::new();
        let threshold = params.threshold_for(&m);
        let mut group = c.benchmark_group(format!("engine/{}", size.name));
        group.sample_size(10);

        // Stage: Alg. 1 + 2 on one stack (the densest set of the left camera).
        let phase_params = sheen::engine::phase_shift::PhaseParams {
            saturation_threshold: threshold,
            min_modulation_dn: params.min_modulation_dn,
            selection: Method::Hdr.selection(),
        };
        let dense = m.sets.len() - 1;
        group.bench_function("phase_one_stack", |b| {
            b.iter_with_large_drop(|| {
                wrapped_phase(&m.cameras[0].stacks[dense], &m.sets[dense], &phase_params, false, &control)
            })
        });

        // Stage: Alg. 3 unwrapping and fusion of one camera.
        let rec = pipeline::run(&m, &params, None, &control).expect("engine run");
        let cam = &rec.cameras[0];
        let chain: Vec<&WrappedPhase> = cam.enabled.iter().map(|&s| cam.sets[s].as_ref()).collect();
        group.bench_function("unwrap_fuse_one_camera", |b| {
            b.iter_with_large_drop(|| {
                let unwrapped = unwrap_hierarchical(&chain, OrderCheck::default(), &control).expect("unwrap");
                fuse(&chain, &unwrapped, &cam.enabled, Method::Hdr.fusion_rule(), false)
            })
        });

        // Stage: rectification, matching and triangulation.
        if let (Some(calib), Some(right)) = (m.calibration.as_ref(), rec.cameras.get(1)) {
            let periods = m.periods_px();
            let attributes = LeftAttributes {
                source_set: &cam.fused.source_set,
                periods_px: &periods,
                modulation_dn: cam.sets.iter().map(|s| s.modulation_dn.as_slice()).collect(),
                texture_dn: &cam.texture_dn,
                order_evidence: &cam.fused.order_evidence,
            };
            group.bench_function("stereo", |b| {
                b.iter_with_large_drop(|| {
                    reconstruct(
                        calib,
                        &view(cam),
                        &view(right),
                        &attributes,
                        f64::INFINITY,
                        sheen::engine::continuity::Continuity::default(),
                        &control,
                    )
                    .expect("stereo")
                })
            });
        }

        // End to end with the images in memory.
        group.bench_function("end_to_end", |b| {
            b.iter_with_large_drop(|| pipeline::run(&m, &params, None, &control).expect("run"))
        });

        // Freeing a full result (about 0.75 GB of maps and cloud): paid when
        // a new result replaces it, outside the latency above, measured apart.
        group.bench_function("free_result", |b| {
            b.iter_batched(
                || pipeline::run(&m, &params, None, &control).expect("run"),
                drop,
                criterion::BatchSize::PerIteration,
            )
        });

        // Re-run after a threshold change, reusing nothing from before (the
        // threshold invalidates every per-set phase) and after a set toggle,
        // which reuses them.
        let mut lower = params.clone();
        lower.saturation_threshold = Some(threshold - 5);
        group.bench_function("rerun_threshold_change", |b| {
            b.iter_with_large_drop(|| pipeline::run(&m, &lower, Some(&rec), &control).expect("run"))
        });
        let mut toggled = params.clone();
        toggled.enabled_sets = (0..m.sets.len()).map(|s| s != 1).collect();
        group.bench_function("rerun_set_toggle", |b| {
            b.iter_with_large_drop(|| pipeline::run(&m, &toggled, Some(&rec), &control).expect("run"))
        });

        // The baseline: the same per-camera stages, straightforwardly. First
        // check it computes the same thing, so the comparison is fair.
        let base = baseline::baseline_camera(&m.cameras[0], &m.sets, threshold, f64::from(params.min_modulation_dn));
        let (mut both, mut agree) = (0usize, 0usize);
        for (b, e) in base.fused_phase_rad.iter().zip(&cam.fused.fused_phase_rad) {
            if b.is_finite() && e.is_finite() {
                both += 1;
                agree += usize::from((b - f64::from(*e)).abs() < 0.01);
            }
        }
        let sources_agree = base.source_set.iter().zip(&cam.fused.source_set).filter(|(b, e)| b == e).count();
        eprintln!(
            "{}: baseline and engine phases agree at {:.2} % of the pixels both recover; sources at {:.2} %",
            size.name,
            100.0 * agree as f64 / both.max(1) as f64,
            100.0 * sources_agree as f64 / base.source_set.len().max(1) as f64
        );
        assert!(agree as f64 > 0.99 * both as f64, "the baseline computes something else");
        group.bench_with_input(BenchmarkId::new("baseline_per_camera_stages", "both cameras"), &m, |b, m| {
            b.iter_with_large_drop(|| {
                m.cameras
                    .iter()
                    .map(|cam| baseline::baseline_camera(cam, &m.sets, threshold, f64::from(params.min_modulation_dn)))
                    .collect::<Vec<_>>()
            })
        });
        group.bench_function("engine_per_camera_stages", |b| {
            b.iter_with_large_drop(|| pipeline::run_phase(&m, &params, None, &control).expect("run"))
        });
        group.finish();
    }
}

fn view(c: &sheen::engine::pipeline::CameraPhase) -> PhaseMapView<'_> {
    PhaseMapView {
        width: c.width,
        height: c.height,
        phase_rad: &c.fused.fused_phase_rad,
        sigma_rad: &c.fused.fused_sigma_rad,
    }
}

/// Loading a fringe set from disk: the 96 PNG images of the full-size
/// measurement (2 cameras x 4 sets x 12 shifts), decoded in parallel.
fn loading(c: &mut Criterion) {
    for size in sizes() {
        let m = watch_plate(size);
        let dir = tempfile::tempdir().expect("temporary folder");
        let manifest = sheen::io::dataset::write_measurement(dir.path(), &m).expect("write the fringe set");
        drop(m);
        let mut group = c.benchmark_group(format!("io/{}", size.name));
        group.sample_size(10);
        group.bench_function("load_png_fringe_set", |b| {
            b.iter(|| sheen::io::manifest::load_measurement(&manifest, &RunControl::new()).expect("load"))
        });
        group.finish();
    }
}

criterion_group!(engine, benches, loading);
criterion_main!(engine);
