//! The log panel: every info, warning and error of the session, newest at the
//! bottom, filterable by level.

use eframe::egui::{self, RichText};

use crate::app::commands::Command;
use crate::app::log::{Level, LogBook};
use crate::app::palette;

/// Which levels the panel lists (persisted with the layout).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LogFilter {
    pub info: bool,
    pub warnings: bool,
    pub errors: bool,
}

impl Default for LogFilter {
    fn default() -> Self {
        Self { info: true, warnings: true, errors: true }
    }
}

impl LogFilter {
    fn shows(&self, level: Level) -> bool {
        match level {
            Level::Info => self.info,
            Level::Warning => self.warnings,
            Level::Error => self.errors,
        }
    }
}

pub fn show(ui: &mut egui::Ui, log: &LogBook, filter: &mut LogFilter, commands: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        ui.label(RichText::new("Log").strong());
        ui.checkbox(&mut filter.errors, format!("errors ({})", log.count(Level::Error))).on_hover_text("List errors.");
        ui.checkbox(&mut filter.warnings, format!("warnings ({})", log.count(Level::Warning)))
            .on_hover_text("List warnings.");
        ui.checkbox(&mut filter.info, format!("info ({})", log.count(Level::Info))).on_hover_text("List information.");
        if ui.small_button("Clear log").on_hover_text("Remove all entries.").clicked() {
            commands.push(Command::ClearLog);
        }
    });
    egui::ScrollArea::vertical().id_salt("log").stick_to_bottom(true).auto_shrink([false, false]).show(ui, |ui| {
        for e in log.entries().iter().filter(|e| filter.shows(e.level)) {
            let color = match e.level {
                Level::Info => ui.visuals().text_color(),
                Level::Warning => palette::warning_text(ui.visuals()),
                Level::Error => palette::error_text(ui.visuals()),
            };
            ui.horizontal_wrapped(|ui| {
                ui.label(RichText::new(&e.time).monospace().weak());
                ui.label(RichText::new(e.level.name()).monospace().color(color));
                ui.label(RichText::new(&e.text).color(color));
            });
        }
    });
}
