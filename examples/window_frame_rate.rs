//! Frames per second of the real application window while the engine runs
//! (issue 8: the GUI keeps 60 frames per second during a run). Unlike
//! `ui_frame_times.rs` this opens the app through eframe exactly as `sheen`
//! does (wgpu surface, presentation, no read-back), repaints continuously
//! with vsync off, starts engine runs back to back, and reports the interval
//! between frames: the whole frame, UI thread and rendering, as a user sees it.
//! On a machine without a GPU, wgpu renders with Mesa's lavapipe on the same
//! cores as the engine, which makes this an upper bound for any graphics card.
//! With `paced` the window repaints only when the app asks (during a run its
//! animated progress bar keeps it drawing), which gives the time from Run to
//! result as an operator sees it. `below-ui` runs the jobs below the UI thread's
//! priority even with a CPU renderer, where the app would not (`app::jobs`).
//! `empty` instead of a view measures an empty egui window of the same size:
//! the floor that the windowing system and renderer set for any egui app.
//! With `PROBE_CAUSES=1` each frame during a run prints what asked egui for
//! it (`Context::repaint_causes`): where the frames of a run come from.
//!
//! ```sh
//! sheen simulate --scene watch-plate --out wp --noise 1
//! xvfb-run -a -s "-screen 0 1600x1000x24" \
//!     cargo run --release --example window_frame_rate -- wp/fringe-set.json [raw|height|cloud|empty] [RUNS] [paced] [below-ui]
//! ```

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use eframe::egui;
use sheen::app::commands::Command;
use sheen::app::views::ViewKind;
use sheen::app::{AppOptions, SheenApp, Startup};

/// As the `sheen` binary: large buffers on transparent huge pages.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Frame intervals in ms (idle, during runs), handed out when the window closes.
type Report = Arc<Mutex<Option<(Vec<f64>, Vec<f64>)>>>;

struct Probe {
    app: SheenApp,
    view: ViewKind,
    runs_wanted: u64,
    /// Engine runs started before measuring (the one that loads the data).
    runs_before: u64,
    last_frame: Option<Instant>,
    /// Frame intervals in ms, split by whether the engine ran during the frame.
    idle_ms: Vec<f64>,
    busy_ms: Vec<f64>,
    /// Idle frames since the last run ended; the next run starts after 30.
    idle_streak: usize,
    ready: bool,
    started: Instant,
    /// Repaint every frame (frame rate), or only when the app asks to
    /// (`paced`: how long runs take with the app's own repaints).
    continuous: bool,
    /// When the last Run was asked for, and the run count before it.
    run_requested: Option<(Instant, u64)>,
    run_s: Vec<f64>,
    out: Report,
}

impl eframe::App for Probe {
    fn logic(&mut self, ctx: &egui::Context, frame: &mut eframe::Frame) {
        self.app.logic(ctx, frame);
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let now = Instant::now();
        let runs = self.app.engine_runs_started();
        if let Some((asked, _)) = self.run_requested.filter(|&(_, before)| runs > before && !self.app.is_busy()) {
            self.run_s.push((now - asked).as_secs_f64());
            self.run_requested = None;
        }
        // A requested run counts from the frame that asks for it.
        let busy = self.app.is_busy() || self.run_requested.is_some();
        if busy && std::env::var_os("PROBE_CAUSES").is_some() {
            eprintln!("CAUSE {:.3} {:?}", self.started.elapsed().as_secs_f64(), ui.ctx().repaint_causes());
        }
        if self.ready {
            if let Some(last) = self.last_frame {
                let ms = (now - last).as_secs_f64() * 1e3;
                if busy {
                    self.busy_ms.push(ms);
                    self.idle_streak = 0;
                } else {
                    self.idle_ms.push(ms);
                    self.idle_streak += 1;
                }
            }
        } else if self.app.result().is_some() && !busy {
            // The first result is in: show the view under test, then measure.
            self.app.state.views.active = self.view;
            self.ready = true;
            self.runs_before = self.app.engine_runs_started();
        }
        self.last_frame = Some(now);
        self.app.ui(ui, frame);
        if self.ready && self.idle_streak >= 30 {
            self.idle_streak = 0;
            if self.app.engine_runs_started() - self.runs_before >= self.runs_wanted {
                ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
            } else {
                self.app.push_command(Command::Run);
                self.run_requested = Some((Instant::now(), self.app.engine_runs_started()));
            }
        }
        assert!(self.started.elapsed().as_secs() < 600, "the probe did not finish within 10 minutes");
        if self.continuous {
            ui.ctx().request_repaint();
        } else if !busy {
            // Enough frames to start the next run; during one the app paces itself.
            ui.ctx().request_repaint_after(std::time::Duration::from_millis(20));
        }
    }

    /// Hands the measurements to `main` when eframe closes the window.
    fn on_exit(&mut self) {
        if !self.run_s.is_empty() {
            let mut run_s = self.run_s.clone();
            run_s.sort_by(f64::total_cmp);
            let list: Vec<String> = run_s.iter().map(|s| format!("{s:.2}")).collect();
            println!("engine runs, Run to result on screen: {} s", list.join(", "));
            // In run order too: whether later runs drift from the first ones.
            let in_order: Vec<String> = self.run_s.iter().map(|s| format!("{s:.2}")).collect();
            println!("the same in run order: {} s", in_order.join(", "));
        }
        let idle = std::mem::take(&mut self.idle_ms);
        let busy = std::mem::take(&mut self.busy_ms);
        *self.out.lock().expect("report lock") = Some((idle, busy));
    }
}

fn summary(mut ms: Vec<f64>) -> String {
    if ms.is_empty() {
        return "no frames".into();
    }
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    format!(
        "{} frames, {:.0} fps on average, median {:.1} ms, 95th percentile {:.1} ms, worst {:.1} ms",
        ms.len(),
        1e3 / mean,
        at(0.5),
        at(0.95),
        at(1.0)
    )
}

fn main() -> eframe::Result {
    // A run reuses the pages of the run before.
    sheen::cli::keep_memory_as_the_app_does();
    let mut args = std::env::args().skip(1);
    let manifest = PathBuf::from(args.next().expect("usage: window_frame_rate MANIFEST [raw|height|cloud] [RUNS]"));
    let view = match args.next().as_deref() {
        None | Some("raw") => Some(ViewKind::Raw),
        Some("height") => Some(ViewKind::Height),
        Some("cloud") => Some(ViewKind::Cloud),
        Some("empty") => None,
        Some(other) => panic!("unknown view {other:?}: raw, height, cloud or empty"),
    };
    let runs_wanted = args.next().map_or(3, |n| n.parse().expect("RUNS is a count"));
    let flags: Vec<String> = args.collect();
    let continuous = !flags.iter().any(|f| f == "paced");
    let force_below_ui = flags.iter().any(|f| f == "below-ui");
    let mut options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_title("Sheen frame rate").with_inner_size([1400.0, 880.0]),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    // Vsync off: the interval between frames is then what a frame costs.
    options.wgpu_options.surface.present_mode = eframe::wgpu::PresentMode::AutoNoVsync;
    let report: Report = Arc::new(Mutex::new(None));
    let out = report.clone();
    eframe::run_native(
        "sheen-frame-rate",
        options,
        Box::new(move |cc| {
            let info = cc.wgpu_render_state.as_ref().map(|s| s.adapter.get_info());
            if let Some(info) = info {
                println!("adapter: {} ({:?}, driver {})", info.name, info.device_type, info.driver_info);
            }
            let Some(view) = view else {
                return Ok(Box::new(EmptyWindow { last_frame: None, frame_ms: Vec::new(), out }));
            };
            let options =
                AppOptions { startup: Startup::Manifest(manifest), restore_state: false, ..AppOptions::default() };
            let app = SheenApp::new(cc, options);
            if force_below_ui {
                sheen::app::jobs::set_jobs_below_ui_thread(true);
            }
            println!("jobs below the UI thread: {}", sheen::app::jobs::jobs_below_ui_thread());
            Ok(Box::new(Probe {
                app,
                view,
                runs_wanted,
                runs_before: 0,
                last_frame: None,
                idle_ms: Vec::new(),
                busy_ms: Vec::new(),
                idle_streak: 0,
                ready: false,
                started: Instant::now(),
                continuous,
                run_requested: None,
                run_s: Vec::new(),
                out,
            }))
        }),
    )?;
    if let Some((idle, busy)) = report.lock().expect("report lock").take() {
        println!("view {}", view.map_or("empty window".to_owned(), |v| format!("{v:?}")));
        println!("idle: {}", summary(idle));
        println!("while the engine runs: {}", summary(busy));
    }
    Ok(())
}

/// An egui window with nothing in it, repainted continuously: what a frame
/// costs before the app draws anything.
struct EmptyWindow {
    last_frame: Option<Instant>,
    frame_ms: Vec<f64>,
    out: Report,
}

impl eframe::App for EmptyWindow {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let now = Instant::now();
        if let Some(last) = self.last_frame.replace(now) {
            self.frame_ms.push((now - last).as_secs_f64() * 1e3);
        }
        egui::CentralPanel::default().show(ui, |_| {});
        if self.frame_ms.len() == 120 {
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
        }
        ui.ctx().request_repaint();
    }

    fn on_exit(&mut self) {
        *self.out.lock().expect("report lock") = Some((std::mem::take(&mut self.frame_ms), Vec::new()));
    }
}
