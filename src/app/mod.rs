//! The egui/eframe inspection application over the engine: load a
//! measurement, tune the method's parameters, and see every stage of it.
//!
//! Layout of this module (one file per panel or view; state apart from drawing):
//! - `sheen_app.rs`: [`SheenApp`], the frame loop: poll jobs, draw, run commands.
//! - `state.rs`: the persisted [`AppState`]; `session.rs`: runtime data (measurement, results).
//! - `commands.rs`: what panels and views ask for; `jobs.rs`, `runner.rs`, `loading.rs`: work off the UI thread.
//! - `panels/`: menu bar, parameters, inspector, statistics, log, status; `views/`: the maps.
//! - `widgets/`: zoomable map and legends; `palette.rs`, `textures.rs`: colours and the texture cache.
//! - `pixel_report.rs`: the inspector's per-pixel analysis (no GUI types).
//!
//! Architecture invariant: the UI thread never waits on the engine or on disk;
//! every long operation is a [`jobs::Job`] polled once per frame.

pub mod calibration;
pub mod commands;
pub mod exports;
pub mod import_dialog;
pub mod jobs;
pub mod loading;
pub mod log;
pub mod palette;
pub mod panels;
pub mod pixel_report;
pub mod record_settings;
pub mod run_data;
pub mod runner;
mod sheen_app;
pub mod state;
pub mod textures;
pub mod views;
pub mod widgets;

use std::path::PathBuf;

use eframe::egui;

pub use sheen_app::{AppOptions, PROGRESS_REPAINT, PROGRESS_REPAINT_ON_CPU, SheenApp, Startup};
pub use state::AppState;

/// Opens the application window: on `manifest` if given, else on the simulated demo.
pub fn run(manifest: Option<PathBuf>) -> anyhow::Result<()> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("Sheen")
            .with_app_id("sheen")
            .with_inner_size([1400.0, 880.0])
            .with_min_inner_size([800.0, 500.0])
            .with_drag_and_drop(true),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    let startup = manifest.map_or(Startup::Demo, Startup::Manifest);
    eframe::run_native(
        "sheen",
        options,
        Box::new(move |cc| Ok(Box::new(SheenApp::new(cc, AppOptions { startup, ..AppOptions::default() })))),
    )
    .map_err(|e| anyhow::anyhow!("the application window could not be opened: {e}"))
}

#[cfg(test)]
mod tests {
    use eframe::egui;

    /// Every non-ASCII character in the app's sources (labels use µ, σ, φ, ·, ...)
    /// must exist in egui's built-in proportional font: a missing glyph draws
    /// as a box for operators and panics under egui_kittest.
    #[test]
    fn every_symbol_the_app_writes_has_a_glyph() {
        fn sources(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
            for entry in std::fs::read_dir(dir).expect("read src/app").flatten() {
                let path = entry.path();
                if path.is_dir() {
                    sources(&path, out);
                } else if path.extension().is_some_and(|e| e == "rs") {
                    out.push(path);
                }
            }
        }
        let mut files = Vec::new();
        sources(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/app"), &mut files);
        assert!(files.len() > 20, "found only {} files", files.len());
        let ctx = egui::Context::default();
        ctx.begin_pass(Default::default());
        let font = egui::FontId::proportional(12.0);
        let mut missing = Vec::new();
        for file in &files {
            let text = std::fs::read_to_string(file).expect("read source");
            for c in text.chars().filter(|c| !c.is_ascii()) {
                if !ctx.fonts_mut(|f| f.has_glyph(&font, c)) {
                    missing.push(format!("{c:?} in {}", file.display()));
                }
            }
        }
        missing.dedup();
        assert!(missing.is_empty(), "characters without a glyph: {missing:?}");
    }
}
