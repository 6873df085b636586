//! The menu bar (open, recent files, demo, theme, panels, shortcuts) and the
//! line saying what data is on screen, with a clear mark when it is simulated.

use std::path::PathBuf;

use eframe::egui::{self, RichText};

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::run_data::DataSource;
use crate::app::state::{AppState, Theme};

/// Keyboard shortcuts, for the Help menu.
pub const SHORTCUTS: [(&str, &str); 7] = [
    ("Ctrl+O", "open a manifest"),
    ("F5 / Ctrl+R", "run the engine"),
    ("Esc", "cancel the run or the load"),
    ("PageUp / [", "previous fringe set"),
    ("PageDown / ]", "next fringe set"),
    ("Left / Right", "previous / next phase shift"),
    ("Double-click a map", "fit it to the view"),
];

/// The "Open path" box of the File menu (for systems without a file dialog).
#[derive(Default)]
pub struct OpenPathBox {
    pub text: String,
}

pub fn show(
    ui: &mut egui::Ui,
    state: &mut AppState,
    source: Option<&DataSource>,
    open_path: &mut OpenPathBox,
    commands: &mut Vec<Command>,
) {
    egui::MenuBar::new().ui(ui, |ui| {
        ui.menu_button("File", |ui| {
            if ui.button("Open manifest… (Ctrl+O)").clicked() {
                commands.push(Command::OpenDialog);
                ui.close();
            }
            ui.horizontal(|ui| {
                let edit = ui.add(
                    egui::TextEdit::singleline(&mut open_path.text)
                        .hint_text("/path/to/manifest.json or a height map (.x3p, .sdf, .tif)")
                        .desired_width(260.0),
                );
                edit.widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Manifest path"));
                let edit = edit.on_hover_text(
                    "A manifest opens the measurement; an X3P, SDF or float TIFF height map opens in the Inspect view.",
                );
                let enter = edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
                if (ui.button("Open path").clicked() || enter) && !open_path.text.trim().is_empty() {
                    commands.push(Command::Open(PathBuf::from(open_path.text.trim())));
                    ui.close();
                }
            });
            ui.horizontal(|ui| {
                ui.label("Height-map TIFF:").on_hover_text(
                    "X3P and SDF height maps carry their scales; a float TIFF does not. Opening one (by path, from \
                     Recent files or by dropping it) uses this pixel size and height unit.",
                );
                let inspect = &mut state.views.inspect;
                ui.add(
                    egui::DragValue::new(&mut inspect.tiff_pixel_mm)
                        .range(0.0..=100.0)
                        .speed(0.0001)
                        .max_decimals(6)
                        .suffix(" mm/px"),
                );
                use crate::engine::length_unit::LengthUnit;
                egui::ComboBox::from_id_salt("tiff z unit").selected_text(inspect.tiff_z_unit.as_str()).show_ui(
                    ui,
                    |ui| {
                        for unit in [LengthUnit::Nm, LengthUnit::Um, LengthUnit::Mm, LengthUnit::M] {
                            ui.selectable_value(&mut inspect.tiff_z_unit, unit, unit.as_str());
                        }
                    },
                );
            });
            ui.menu_button("Recent files", |ui| {
                if state.recent_files.is_empty() {
                    ui.weak("none yet");
                }
                // No existence check here: a stat on a slow network drive would
                // stall the UI; a missing file simply fails to load with a banner.
                for path in &state.recent_files {
                    ui.horizontal(|ui| {
                        if ui
                            .small_button("Forget")
                            .on_hover_text("Remove this file from the list (the file is not touched).")
                            .clicked()
                        {
                            commands.push(Command::ForgetRecent(path.clone()));
                        }
                        if ui.button(path.display().to_string()).clicked() {
                            commands.push(Command::Open(path.clone()));
                            ui.close();
                        }
                    });
                }
            });
            if ui
                .button("Import a folder of images…")
                .on_hover_text("Write a manifest for another rig's images: pattern, periods, shifts, shift check.")
                .clicked()
            {
                commands.push(Command::OpenImport);
                ui.close();
            }
            ui.separator();
            if ui.button("Open the simulated demo").clicked() {
                commands.push(Command::OpenDemo);
                ui.close();
            }
            ui.separator();
            if ui
                .button("Save session…")
                .on_hover_text("Manifest, parameters and the Inspect view's inspection, as JSON.")
                .clicked()
            {
                commands.push(Command::SaveSession(None));
                ui.close();
            }
            if ui
                .button("Save as recipe…")
                .on_hover_text(
                    "The session and this part's height map as a line's recipe (sheen watch, the Line view).",
                )
                .clicked()
            {
                commands.push(Command::SaveRecipe(None));
                ui.close();
            }
            if ui.button("Follow recipe…").on_hover_text(crate::app::views::inspect::FOLLOW_RECIPE_TIP).clicked() {
                commands.push(Command::FollowRecipe(None));
                ui.close();
            }
            if ui
                .button("Open session…")
                .on_hover_text("Reopen a saved session: data, parameters and inspection.")
                .clicked()
            {
                commands.push(Command::OpenSession(None));
                ui.close();
            }
        });
        ui.menu_button("View", |ui| {
            ui.label("Theme");
            for theme in Theme::ALL {
                ui.radio_value(&mut state.theme, theme, theme.name());
            }
            ui.separator();
            ui.checkbox(&mut state.layout.show_side_panel, "Inspector and statistics panel");
            ui.checkbox(&mut state.layout.show_log, "Log panel");
        });
        if ui.button("Calibration").on_hover_text("Calibrate the stereo rig from target images.").clicked() {
            commands.push(Command::OpenCalibration);
        }
        ui.menu_button("Help", |ui| {
            ui.label(RichText::new("Keyboard shortcuts").strong());
            egui::Grid::new("shortcuts").num_columns(2).show(ui, |ui| {
                for (keys, action) in SHORTCUTS {
                    ui.monospace(keys);
                    ui.label(action);
                    ui.end_row();
                }
            });
        });
        ui.separator();
        match source {
            Some(DataSource::Simulated { description }) => {
                ui.label(
                    RichText::new(format!("SIMULATED DATA · {description} · not a measurement"))
                        .color(palette::warning_text(ui.visuals()))
                        .strong(),
                )
                .on_hover_text(
                    "Built-in demo from the simulator. Open a manifest (Ctrl+O) or drop one here to measure.",
                );
            }
            Some(DataSource::File(path)) => {
                ui.label(RichText::new(path.display().to_string()).strong());
            }
            None => {
                ui.weak("No measurement loaded");
            }
        }
    });
}
