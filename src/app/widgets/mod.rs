//! Widgets shared by the views and dialogs: the zoomable map, its colour
//! legend, and the line that says what is running.

pub mod legend;
pub mod map_view;

use eframe::egui;

/// A spinner and what it waits for, on one line.
pub fn busy_line(ui: &mut egui::Ui, text: impl Into<egui::WidgetText>) {
    ui.horizontal(|ui| {
        ui.spinner();
        ui.label(text);
    });
}
