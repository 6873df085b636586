//! How long the app's UI thread spends per frame while the engine runs
//! (issue 8: the GUI keeps 60 frames per second during a run). Opens a
//! manifest in the real app under egui_kittest, then times `step()` (the egui
//! frame: polling jobs, drawing every panel, no GPU work) for a stretch of
//! idle frames and for every frame of one engine run. With `--render` each
//! frame is also rendered through wgpu and read back (timed apart: on a
//! machine without a GPU that is Mesa's software rasterizer, not a graphics
//! card), which the 3D view (`--view cloud`) needs to upload its points.
//!
//! ```sh
//! sheen simulate --scene watch-plate --out wp --noise 1
//! xvfb-run -a cargo run --release --example ui_frame_times -- wp/fringe-set.json [--render] [--view raw|height|cloud] [--threshold DN] [--paced]
//! ```

use std::path::PathBuf;
use std::time::{Duration, Instant};

use egui_kittest::Harness;
use sheen::app::commands::Command;
use sheen::app::views::ViewKind;
use sheen::app::{AppOptions, SheenApp, Startup};

/// As the `sheen` binary: large buffers on transparent huge pages.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    // A run reuses the pages of the run before.
    sheen::cli::keep_memory_as_the_app_does();
    let mut args = std::env::args().skip(1);
    let manifest = PathBuf::from(
        args.next()
            .expect("usage: ui_frame_times MANIFEST [--render] [--view raw|height|cloud] [--threshold DN] [--paced]"),
    );
    let rest: Vec<String> = args.collect();
    let render = rest.iter().any(|a| a == "--render");
    // Frames 5 ms apart during the run instead of back to back: the app
    // itself draws a run's progress a few times a second, so a UI thread
    // spinning on frames would take a core from the engine that it does not
    // take in use. Gives the time from Run to the result in the UI without
    // any renderer, the floor of what a graphics card can show.
    let paced = rest.iter().any(|a| a == "--paced");
    let view = match rest.iter().position(|a| a == "--view").and_then(|i| rest.get(i + 1)).map(String::as_str) {
        None | Some("raw") => ViewKind::Raw,
        Some("height") => ViewKind::Height,
        Some("cloud") => ViewKind::Cloud,
        Some(other) => panic!("unknown view {other:?}: raw, height or cloud"),
    };
    // The run after a new saturation threshold, as an operator types one.
    let threshold: Option<u16> = rest
        .iter()
        .position(|a| a == "--threshold")
        .map(|i| rest.get(i + 1).and_then(|t| t.parse().ok()).expect("--threshold takes grey levels, e.g. 200"));
    let options = AppOptions { startup: Startup::Manifest(manifest), restore_state: false, ..AppOptions::default() };
    let mut builder = Harness::builder().with_size(eframe::egui::vec2(1400.0, 900.0)).with_max_steps(1_000_000);
    if render {
        builder = builder.wgpu();
    }
    let mut h = builder.build_eframe(move |cc| SheenApp::new(cc, options));
    let start = Instant::now();
    while h.state().result().is_none() || h.state().is_busy() {
        h.step();
        std::thread::sleep(Duration::from_millis(5));
        assert!(start.elapsed() < Duration::from_secs(300), "no result within 5 minutes");
    }
    h.state_mut().state.views.active = view;
    // The UI thread's frame, and the rendering apart (empty without --render).
    let mut render_ms = Vec::new();
    let mut frame = |h: &mut Harness<'_, SheenApp>| {
        let t = Instant::now();
        h.step();
        let ui_ms = t.elapsed().as_secs_f64() * 1e3;
        if render {
            let t = Instant::now();
            let _image = h.render();
            render_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        ui_ms
    };
    let idle: Vec<f64> = (0..60).map(|_| frame(&mut h)).collect();
    let runs = h.state().engine_runs_started();
    if let Some(t) = threshold {
        h.state_mut().state.params.saturation_threshold = Some(t);
    }
    h.state_mut().push_command(Command::Run);
    let run_start = Instant::now();
    let mut busy = Vec::new();
    while h.state().engine_runs_started() == runs || h.state().is_busy() {
        busy.push(frame(&mut h));
        if paced {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(run_start.elapsed() < Duration::from_secs(300), "the run did not finish");
    }
    let run_s = run_start.elapsed().as_secs_f64();
    println!("view {view:?}, the UI thread's frame:");
    println!("idle: {}", summary(idle));
    println!("during a {run_s:.2} s engine run: {}", summary(busy));
    if render {
        println!("rendering and read-back, every frame: {}", summary(render_ms));
    }
}

fn summary(mut ms: Vec<f64>) -> String {
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    format!(
        "{} frames, median {:.2} ms, 95th percentile {:.2} ms, worst {:.2} ms",
        ms.len(),
        at(0.5),
        at(0.95),
        at(1.0)
    )
}
