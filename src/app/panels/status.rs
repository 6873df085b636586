//! The error banner (latest error, with the file it concerns) and the status
//! bar (what is loading or running, with progress and Cancel).

use eframe::egui::{self, RichText};

use crate::app::commands::Command;
use crate::app::palette;

use super::parameters::EngineStatus;

/// A message that stays on screen until dismissed.
#[derive(Clone, Debug, PartialEq)]
pub struct Banner {
    pub text: String,
    /// Errors are red; notices (e.g. "no file dialog available") are amber.
    pub is_error: bool,
}

pub fn banner(ui: &mut egui::Ui, banner: &Banner, commands: &mut Vec<Command>) {
    let color = if banner.is_error { palette::error_text(ui.visuals()) } else { palette::warning_text(ui.visuals()) };
    egui::Frame::new().fill(color.gamma_multiply(0.18)).stroke((1.0, color)).inner_margin(6.0).corner_radius(4.0).show(
        ui,
        |ui| {
            ui.horizontal(|ui| {
                let kind = if banner.is_error { "Error" } else { "Note" };
                ui.label(RichText::new(kind).color(color).strong());
                if ui.button("Dismiss").on_hover_text("Hide this message (it stays in the log).").clicked() {
                    commands.push(Command::DismissBanner);
                }
                ui.add(egui::Label::new(RichText::new(&banner.text).color(color)).wrap());
            });
        },
    );
}

/// Progress of a load: (what, stage, fraction).
pub type LoadProgress = (String, String, f32);

pub fn status_bar(
    ui: &mut egui::Ui,
    load: Option<&LoadProgress>,
    engine: &EngineStatus,
    compare: Option<&(String, f32)>,
    summary: &str,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        if let Some((what, stage, fraction)) = load {
            ui.label(format!("Loading {what}"));
            ui.add(egui::ProgressBar::new(*fraction).text(stage.clone()).desired_width(220.0));
            if ui.button("Cancel loading").on_hover_text("Stop loading; the current data stays (Esc).").clicked() {
                commands.push(Command::CancelLoad);
            }
            ui.separator();
        }
        if engine.running {
            ui.label("Engine:");
            ui.add(egui::ProgressBar::new(engine.fraction).text(engine.stage.clone()).desired_width(220.0));
            ui.separator();
        }
        if let Some((stage, fraction)) = compare {
            ui.label("Comparison:");
            ui.add(egui::ProgressBar::new(*fraction).text(stage.clone()).desired_width(160.0));
            ui.separator();
        }
        ui.label(summary);
    });
}
