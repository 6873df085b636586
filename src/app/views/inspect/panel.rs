//! The Inspect view's controls: the toolbar above the map, and the side
//! panel listing regions, profiles and measurements (rename, colour, role,
//! delete, tolerances), the measurement table, exports and sessions.

use eframe::egui::{self, Color32, RichText};

use crate::analysis::inspection::MeasurementSpec;
use crate::analysis::measurement_table::{DecisionRule, Verdict};
use crate::analysis::region::Region;
use crate::app::commands::Command;
use crate::app::palette;
use crate::app::widgets::busy_line;

use super::files::ExportKind;
use super::record::RecordSettings;
use super::state::{self, RegionRole, Tool};
use super::texture;
use super::{InspectRuntime, InspectView, MapShows, Notice, Selection};
use crate::app::views::colormap_picker;

/// A name being edited in the panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NameRef {
    Region(usize),
    Profile(usize),
    Measurement(usize),
}

const PASS: Color32 = Color32::from_rgb(60, 190, 90);
const INCONCLUSIVE: Color32 = Color32::from_rgb(210, 170, 30);

/// What Follow recipe does (the panel's button and the File menu's entry).
pub const FOLLOW_RECIPE_TIP: &str = "Open a line's recipe: each part is found on the recipe's reference part and the \
                                     recipe's regions, sections and measurements move with it, as sheen watch does.";

/// What the map shows: the heights, a texture measurement's scale-limited
/// surface (S-F or S-L, what its parameters describe), or, with a recipe
/// followed, the part less its aligned reference.
fn surface_picker(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    let textures: Vec<String> =
        rt.doc.measurements.iter().filter(|m| m.measure.texture_settings().is_some()).map(|m| m.name.clone()).collect();
    let following = rt.followed_recipe().is_some();
    let available = match &rt.map_shows {
        MapShows::Heights => true,
        MapShows::Surface(name) => textures.contains(name),
        MapShows::DifferenceToReference => following,
    };
    if !available {
        rt.map_shows = MapShows::Heights;
    }
    if textures.is_empty() && !following {
        return;
    }
    let label = |shows: &MapShows| match shows {
        MapShows::Heights => "heights".to_string(),
        MapShows::Surface(name) => format!("surface of {name}"),
        MapShows::DifferenceToReference => "difference to reference".to_string(),
    };
    let mut choices = vec![MapShows::Heights];
    choices.extend(textures.into_iter().map(MapShows::Surface));
    if following {
        choices.push(MapShows::DifferenceToReference);
    }
    egui::ComboBox::from_id_salt("inspect shown surface")
        .selected_text(label(&rt.map_shows))
        .show_ui(ui, |ui| {
            for choice in choices {
                let text = label(&choice);
                ui.selectable_value(&mut rt.map_shows, choice, text);
            }
        })
        .response
        .on_hover_text(
            "Show the measured heights, the scale-limited surface (form removed, S- and L-filtered) a texture \
             measurement evaluates, on its region, or, with a recipe followed, the part less its reference where \
             the alignment puts it (near zero where the part matches).",
        )
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, "Map shows"));
}

/// The recipe followed, and the button that stops following it.
fn followed_recipe(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    let Some((name, path)) = rt.followed_recipe() else { return };
    let path = path.display().to_string();
    ui.label(format!("Recipe: {name}")).on_hover_text(format!(
        "{path}: each part is found on the recipe's reference and its regions and sections move with it."
    ));
    if ui.button("Stop following").on_hover_text("Measure the inspection as it is, without the recipe.").clicked() {
        rt.stop_following_recipe();
    }
}

/// Tools, colour settings, levelling and hole filling.
pub fn toolbar(ui: &mut egui::Ui, settings: &mut InspectView, rt: &mut InspectRuntime) {
    ui.horizontal_wrapped(|ui| {
        for tool in Tool::ALL {
            if ui.selectable_label(rt.tool == tool, tool.name()).on_hover_text(tool.tooltip()).clicked() {
                rt.tool = tool;
                rt.drawing = None;
            }
        }
    });
    ui.horizontal_wrapped(|ui| {
        surface_picker(ui, rt);
        followed_recipe(ui, rt);
        colormap_picker(ui, "inspect colormap", &mut settings.colormap);
        let auto = rt.analysis.value().and_then(|a| a.range_um);
        settings.range.ui(ui, "µm", auto);
        ui.separator();
        ui.checkbox(&mut rt.doc.level, "Level to references").on_hover_text(
            "Level the map and the profiles to the plane fitted to the regions with the role 'reference'. Step \
             heights, flatness and coplanarity are defined on fitted planes and do not change.",
        );
        ui.checkbox(&mut settings.fill_holes, "Fill holes (display only)").on_hover_text(
            "Fill small holes on the map by interpolation from their rim, for display only: filled nodes are \
             patterned, and no measurement, profile or export uses them.",
        );
        if rt.is_busy() {
            ui.spinner();
        }
        if rt.analysis.is_running()
            && ui
                .button("Cancel measuring")
                .on_hover_text("Stop measuring; the last finished results stay shown.")
                .clicked()
        {
            rt.cancel_measuring();
        }
        if rt.measuring_cancelled()
            && !rt.analysis.is_running()
            && ui.button("Measure").on_hover_text("Measure the inspection on screen after all.").clicked()
        {
            rt.measure_again();
        }
    });
    if let Some(sel) = rt.selection
        && !ui.ctx().egui_wants_keyboard_input()
        && ui.input(|i| i.key_pressed(egui::Key::Delete))
    {
        delete(rt, sel);
    }
}

fn delete(rt: &mut InspectRuntime, sel: Selection) {
    match sel {
        Selection::Region(i) => {
            let dropped = rt.doc.delete_region(i);
            if !dropped.is_empty() {
                rt.status = Some(Notice {
                    text: format!("Removed the measurements that needed the region: {}", dropped.join(", ")),
                    is_error: false,
                });
            }
        }
        Selection::Profile(i) => rt.doc.delete_profile(i),
    }
    rt.selection = None;
    rt.editing = None;
}

/// A name field that commits on Enter or when it loses focus.
fn name_edit(ui: &mut egui::Ui, rt: &mut InspectRuntime, me: NameRef, current: &str, label: &str) -> Option<String> {
    let mut text = match &rt.editing {
        Some((r, t)) if *r == me => t.clone(),
        _ => current.to_owned(),
    };
    let response = ui.add(egui::TextEdit::singleline(&mut text).desired_width(110.0));
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, label));
    if response.has_focus() || response.changed() {
        rt.editing = Some((me, text.clone()));
    }
    if response.lost_focus() {
        rt.editing = None;
        if text != current {
            return Some(text);
        }
    }
    None
}

fn shape_text(r: &Region) -> String {
    match r {
        Region::Rectangle { x_mm, y_mm } => {
            format!("rect {:.3}×{:.3} mm", (x_mm[1] - x_mm[0]).abs(), (y_mm[1] - y_mm[0]).abs())
        }
        Region::Polygon { vertices_mm } => format!("polygon, {} vertices, {:.4} mm²", vertices_mm.len(), r.area_mm2()),
        Region::Circle { radius_mm, .. } => format!("circle r {radius_mm:.3} mm"),
    }
}

fn set_error(rt: &mut InspectRuntime, e: String) {
    rt.status = Some(Notice { text: e, is_error: true });
}

pub fn show(ui: &mut egui::Ui, rt: &mut InspectRuntime, record: &mut RecordSettings, commands: &mut Vec<Command>) {
    raster(ui, rt);
    ui.separator();
    regions(ui, rt);
    ui.separator();
    profiles(ui, rt);
    ui.separator();
    measurements(ui, rt);
    ui.separator();
    results(ui, rt);
    ui.separator();
    record_form(ui, rt, record, commands);
    ui.separator();
    files(ui, rt, commands);
}

/// A labelled one-line text field that accessibility (and the tests) find by its label.
fn text_field(ui: &mut egui::Ui, label: &str, text: &mut String, hint: &str, tip: &str) {
    ui.horizontal(|ui| {
        ui.add_sized([62.0, 18.0], egui::Label::new(label));
        let edit = ui.add(egui::TextEdit::singleline(text).hint_text(hint).desired_width(230.0));
        let label = label.to_string();
        edit.on_hover_text(tip).widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, &label));
    });
}

/// Inspect > Record: the part's identity, the database, the
/// Record button and "always record".
fn record_form(ui: &mut egui::Ui, rt: &mut InspectRuntime, record: &mut RecordSettings, commands: &mut Vec<Command>) {
    ui.strong("Inspection record");
    text_field(ui, "Part ID", &mut rt.part_id, "manifest folder name", "The part's ID in the records.");
    text_field(
        ui,
        "Recipe",
        &mut rt.recipe,
        "session name",
        "The recipe the part is recorded under (the opened session's name by default).",
    );
    text_field(ui, "Station", &mut record.station, "—", "The measuring station recorded with each part.");
    text_field(ui, "Operator", &mut record.operator, "—", "Who measured, recorded with each part.");
    let default_db = crate::records::DbLocation::from_option(None).map_or_else(|e| e.to_string(), |l| l.display());
    text_field(
        ui,
        "Database",
        &mut record.db,
        &default_db,
        "A SQLite file, or postgres://user@host/db for a store several stations share (password from PGPASSWORD or ~/.pgpass). Empty: the default SQLite file.",
    );
    ui.horizontal(|ui| {
        let busy = rt.record_job_running();
        let ready = rt.can_record();
        let button = ui.add_enabled(!busy && ready.is_ok(), egui::Button::new("Record"));
        let button = match &ready {
            Ok(()) => button.on_hover_text("Keep this part, its measurements and height map in the records database."),
            Err(why) => button.on_disabled_hover_text(format!("Not now: {why}.")),
        };
        if button.clicked() {
            commands.push(Command::InspectRecord);
        }
        ui.checkbox(&mut record.always, "Always record")
            .on_hover_text("Record each new result of a measurement (not the simulated demo) once it is measured.");
        if busy {
            ui.spinner();
        }
    });
}

/// The height map's parameters (applied with a button: each change re-rasterizes) and what rasterizing did.
fn raster(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    let map = rt.analysis.value().map(|a| (a.map.width, a.map.height, a.map.pitch_mm));
    let header = match map {
        Some((w, h, p)) => format!("Height map: {w}×{h} nodes at {p:.4} mm"),
        None => "Height map".to_owned(),
    };
    egui::CollapsingHeader::new(RichText::new(header).strong()).id_salt("inspect raster").show(ui, |ui| {
        if let Some(s) = rt.raster_stats() {
            ui.label(
                RichText::new(format!(
                    "{} points, {} triangles; cut {} at height jumps and {} at long edges (holes stay holes)",
                    s.points, s.triangles, s.cut_jump, s.cut_long_edge
                ))
                .small(),
            );
        }
        let edit = rt.raster_edit.get_or_insert_with(|| rt.doc.raster.clone());
        ui.horizontal(|ui| {
            let mut auto = edit.pitch_mm.is_none();
            if ui.checkbox(&mut auto, "camera pitch").on_hover_text("Grid pitch = the left camera's pixel pitch on the object.").changed() {
                edit.pitch_mm = if auto { None } else { Some(map.map_or(0.01, |m| m.2)) };
            }
            if let Some(p) = edit.pitch_mm.as_mut() {
                ui.add(egui::DragValue::new(p).range(0.0001..=10.0).speed(0.0005).max_decimals(5).suffix(" mm"))
                    .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Height map pitch"));
            }
        });
        ui.horizontal(|ui| {
            ui.label("jump ratio");
            ui.add(egui::DragValue::new(&mut edit.max_jump_ratio).range(1.0..=1000.0).speed(0.1))
                .on_hover_text("A triangle edge whose height change exceeds this multiple of what its neighbours show is a step seen without points: cut.")
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Jump ratio"));
            ui.label("noise floor");
            ui.add(egui::DragValue::new(&mut edit.z_noise_floor_um).range(0.0..=1000.0).speed(0.1).suffix(" µm"))
                .on_hover_text("Height changes below the jump ratio times this are never cut: set it near the height noise.")
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Noise floor"));
        });
        ui.horizontal(|ui| {
            ui.label("longest edge");
            ui.add(egui::DragValue::new(&mut edit.max_edge_pitches).range(1.0..=100.0).speed(0.1).suffix(" pitches"))
                .on_hover_text("Triangle edges longer than this bridge a gap, not the surface: cut.")
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, "Longest edge"));
            let changed = *edit != rt.doc.raster;
            if ui.add_enabled(changed, egui::Button::new("Apply")).on_hover_text("Rasterize again with these settings.").clicked() {
                rt.doc.raster = edit.clone();
            }
        });
    });
}

fn regions(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    ui.strong(format!("Regions ({})", rt.doc.regions.len()));
    if rt.doc.regions.is_empty() {
        ui.weak("Draw rectangles, polygons or circles on the map (tools above).");
    }
    let mut action: Option<RegionAction> = None;
    for i in 0..rt.doc.regions.len() {
        let selected = rt.selection == Some(Selection::Region(i));
        let name = rt.doc.regions[i].region.name.clone();
        ui.horizontal(|ui| {
            egui::color_picker::color_edit_button_srgb(ui, &mut rt.doc.regions[i].color)
                .on_hover_text("Colour on the map.");
            if let Some(new) = name_edit(ui, rt, NameRef::Region(i), &name, &format!("Name of region {name}"))
                && let Err(e) = rt.doc.rename_region(i, &new)
            {
                set_error(rt, format!("Cannot rename {name}: {e}."));
            }
            let role = &mut rt.doc.regions[i].role;
            egui::ComboBox::from_id_salt(("region role", i))
                .selected_text(role.name())
                .width(80.0)
                .show_ui(ui, |ui| {
                    for r in RegionRole::ALL {
                        ui.selectable_value(role, r, r.name()).on_hover_text(r.tooltip());
                    }
                })
                .response
                .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, format!("Role of {name}")));
            if ui.small_button("×").on_hover_text(format!("Delete {name} (Del)")).clicked() {
                action = Some(RegionAction::Delete(i));
            }
        });
        ui.horizontal(|ui| {
            ui.add_space(24.0);
            let text = RichText::new(shape_text(&rt.doc.regions[i].region.region)).small();
            if ui.selectable_label(selected, text).on_hover_text("Select (highlight on the map).").clicked() {
                rt.selection = Some(Selection::Region(i));
            }
            if ui
                .small_button("Flatness")
                .on_hover_text(format!("Measure the flatness of {name} (PV and RMS)."))
                .clicked()
            {
                action = Some(RegionAction::Flatness(i));
            }
            if ui
                .small_button("Tilt")
                .on_hover_text(format!("Measure the tilt of the plane fitted to {name}."))
                .clicked()
            {
                action = Some(RegionAction::Tilt(i));
            }
            if ui
                .small_button("Texture")
                .on_hover_text(format!(
                    "The ISO 25178-2 areal parameters of {name} (Sa, Sq, Sz, Sdr, Sk, volumes, ...); choose the \
                     form removal and the S- and L-filters in the measurement list."
                ))
                .clicked()
            {
                action = Some(RegionAction::Texture(i));
            }
        });
    }
    let added = match action {
        None => Ok(()),
        Some(RegionAction::Delete(i)) => {
            delete(rt, Selection::Region(i));
            Ok(())
        }
        Some(RegionAction::Flatness(i)) => rt.doc.add_flatness(i).map(|_| ()),
        Some(RegionAction::Tilt(i)) => rt.doc.add_tilt(i).map(|_| ()),
        Some(RegionAction::Texture(i)) => rt.doc.add_texture(i).map(|_| ()),
    };
    if let Err(e) = added {
        set_error(rt, e.to_string());
    }
}

/// What a button of the region list asked for (run after the list is drawn).
enum RegionAction {
    Delete(usize),
    Flatness(usize),
    Tilt(usize),
    Texture(usize),
}

fn profiles(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    ui.strong(format!("Profiles ({})", rt.doc.profiles.len()));
    if rt.doc.profiles.is_empty() {
        ui.weak("Draw a line section, or click a point with the horizontal or vertical section tool.");
    }
    let mut delete_at = None;
    let mut roughness_of = None;
    for i in 0..rt.doc.profiles.len() {
        let name = rt.doc.profiles[i].spec.name.clone();
        ui.horizontal(|ui| {
            egui::color_picker::color_edit_button_srgb(ui, &mut rt.doc.profiles[i].color)
                .on_hover_text("Colour on the map and in the plot.");
            if let Some(new) = name_edit(ui, rt, NameRef::Profile(i), &name, &format!("Name of profile {name}"))
                && let Err(e) = rt.doc.rename_profile(i, &new)
            {
                set_error(rt, format!("Cannot rename {name}: {e}."));
            }
            let selected = rt.selection == Some(Selection::Profile(i));
            if ui.selectable_label(selected, "select").on_hover_text("Select: the cursors read this profile.").clicked()
            {
                rt.selection = Some(Selection::Profile(i));
            }
            if ui.small_button("×").on_hover_text(format!("Delete {name} (Del)")).clicked() {
                delete_at = Some(i);
            }
        });
        ui.horizontal(|ui| {
            ui.add_space(24.0);
            if ui
                .small_button("Roughness")
                .on_hover_text(format!("The ISO 21920-2 parameters (Ra, Rq, Rz, RSm, ..., W and P too) of {name}."))
                .clicked()
            {
                roughness_of = Some(i);
            }
            let spec = &mut rt.doc.profiles[i].spec;
            ui.label("width");
            ui.add(
                egui::DragValue::new(&mut spec.width_mm).range(0.0..=10.0).speed(0.001).max_decimals(4).suffix(" mm"),
            )
            .on_hover_text("Averaging width across the line (0 = the line alone).")
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("Width of {name}")));
            let mut auto = spec.step_mm.is_none();
            if ui.checkbox(&mut auto, "step = pitch").on_hover_text("Sample at the height-map pitch.").changed() {
                spec.step_mm = if auto { None } else { Some(0.01) };
            }
            if let Some(step) = spec.step_mm.as_mut() {
                ui.add(egui::DragValue::new(step).range(0.0001..=10.0).speed(0.0005).max_decimals(4).suffix(" mm"))
                    .on_hover_text("Distance between stations along the line.")
                    .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("Step of {name}")));
            }
        });
    }
    if let Some(i) = roughness_of
        && let Err(e) = rt.doc.add_roughness(i)
    {
        set_error(rt, e.to_string());
    }
    if let Some(i) = delete_at {
        delete(rt, Selection::Profile(i));
    }
}

fn measurements(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    ui.strong(format!("Measurements ({})", rt.doc.measurements.len()));
    ui.horizontal_wrapped(|ui| {
        if ui
            .button("Step height")
            .on_hover_text("Step height of the 'measured' regions (together) over the 'reference' regions.")
            .clicked()
            && let Err(e) = rt.doc.add_step_height()
        {
            set_error(rt, format!("Cannot add a step height: {e}."));
        }
        if ui
            .button("Step per region")
            .on_hover_text("One step height per 'measured' region over the 'reference' regions.")
            .clicked()
            && let Err(e) = rt.doc.add_step_heights_each()
        {
            set_error(rt, format!("Cannot add step heights: {e}."));
        }
        if ui.button("Coplanarity").on_hover_text("Coplanarity of all regions with the role 'land'.").clicked()
            && let Err(e) = rt.doc.add_coplanarity()
        {
            set_error(rt, format!("Cannot add a coplanarity: {e}."));
        }
    });
    let mut delete_at = None;
    for i in 0..rt.doc.measurements.len() {
        let name = rt.doc.measurements[i].name.clone();
        ui.horizontal(|ui| {
            if let Some(new) = name_edit(ui, rt, NameRef::Measurement(i), &name, &format!("Name of measurement {name}"))
                && let Err(e) = rt.doc.rename_measurement(i, &new)
            {
                set_error(rt, format!("Cannot rename {name}: {e}."));
            }
            if !texture::is_texture(&rt.doc.measurements[i].measure) {
                tolerance_edit(ui, &mut rt.doc.measurements[i]);
            }
            if ui.small_button("×").on_hover_text(format!("Delete {name}")).clicked() {
                delete_at = Some(i);
            }
        });
        ui.horizontal(|ui| {
            ui.add_space(24.0);
            ui.label(RichText::new(state::describe_measure(&rt.doc.measurements[i].measure)).small().weak());
        });
        texture::settings(ui, &name, &mut rt.doc.measurements[i].measure);
    }
    if let Some(i) = delete_at {
        rt.doc.delete_measurement(i);
        rt.editing = None;
    }
}

fn tolerance_edit(ui: &mut egui::Ui, m: &mut MeasurementSpec) {
    let unit = if matches!(m.measure, crate::analysis::inspection::Measure::Tilt { .. }) { "°" } else { " µm" };
    let mut on = m.tolerance.is_some();
    let name = m.name.clone();
    let toggled = ui
        .checkbox(&mut on, "limits")
        .on_hover_text("Give the accepted range (min and max): the table shows pass or fail.")
        .changed();
    if toggled {
        state::set_limits(m, on.then_some((0.0, 1.0)));
    }
    if let Some((mut lo, mut hi)) = state::limits(m) {
        let a = ui
            .add(egui::DragValue::new(&mut lo).speed(0.01).max_decimals(4).suffix(unit))
            .on_hover_text("Minimum accepted value.");
        a.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("Minimum of {name}")));
        let b = ui
            .add(egui::DragValue::new(&mut hi).speed(0.01).max_decimals(4).suffix(unit))
            .on_hover_text("Maximum accepted value.");
        b.widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("Maximum of {name}")));
        if a.changed() || b.changed() {
            state::set_limits(m, Some((lo, hi)));
        }
    }
}

fn unit_text(unit: &str) -> &str {
    if unit == "um" {
        "µm"
    } else if unit == "deg" {
        "°"
    } else {
        unit
    }
}

fn results(ui: &mut egui::Ui, rt: &mut InspectRuntime) {
    ui.strong("Results");
    let Some(analysis) = rt.analysis.value() else {
        ui.weak("Computing…");
        return;
    };
    if let Some(fit) = &analysis.levelling {
        ui.label(
            RichText::new(format!(
                "Levelled to {}: tilt {:.4}°, residual RMS {:.3} µm over {} nodes",
                fit.region,
                fit.plane.tilt_deg(),
                fit.rms_um,
                fit.samples
            ))
            .small(),
        );
    }
    for w in &analysis.warnings {
        ui.label(RichText::new(&w.message).small().color(palette::warning_text(ui.visuals())));
    }
    let report = match &analysis.report {
        Ok(r) => r,
        Err(e) => {
            ui.colored_label(palette::error_text(ui.visuals()), format!("The inspection cannot run: {e}"));
            return;
        }
    };
    if report.table.rows.is_empty() {
        ui.weak("No measurement yet: give regions roles and add measurements above.");
        return;
    }
    decision_rule_picker(ui, &mut rt.doc.decision_rule);
    egui::Grid::new("inspect results").striped(true).num_columns(4).show(ui, |ui| {
        ui.strong("measurement");
        ui.strong("value ± U");
        // The verdict before the limits: with U the value is wider, and a
        // narrow panel should clip the limits, not the verdict.
        ui.strong("verdict");
        ui.strong("limits");
        ui.end_row();
        for row in &report.table.rows {
            let unit = unit_text(&row.unit);
            let name = ui.label(&row.name);
            if let Some(note) = &row.note {
                name.on_hover_text(note);
            }
            match (row.value, &row.uncertainty) {
                (Some(v), Some(u)) => ui.monospace(format!("{v:.3} ± {:.3} {unit}", u.expanded)).on_hover_text(budget_text(u)),
                (Some(v), None) => ui.monospace(format!("{v:.3} {unit}")),
                (None, _) => ui.colored_label(palette::error_text(ui.visuals()), "not measured"),
            };
            match row.verdict() {
                Some(Verdict::Pass) => ui.colored_label(PASS, RichText::new("PASS").strong()),
                Some(Verdict::Fail) => {
                    ui.colored_label(palette::error_text(ui.visuals()), RichText::new("FAIL").strong())
                }
                Some(Verdict::Inconclusive) => ui
                    .colored_label(INCONCLUSIVE, RichText::new("INCONCLUSIVE").strong())
                    .on_hover_text("Within the expanded uncertainty U of a limit: by ISO 14253-1 neither conformity nor non-conformity is proven."),
                None => ui.weak("—"),
            };
            match row.limits() {
                Some((lo, hi)) => ui.monospace(format!("{lo:.3} … {hi:.3}")),
                None => ui.weak("—"),
            };
            ui.end_row();
        }
    });
    match report.table.overall_verdict() {
        Some(Verdict::Pass) => ui.colored_label(PASS, RichText::new("Overall: PASS").strong()),
        Some(Verdict::Fail) => {
            ui.colored_label(palette::error_text(ui.visuals()), RichText::new("Overall: FAIL").strong())
        }
        Some(Verdict::Inconclusive) => ui.colored_label(INCONCLUSIVE, RichText::new("Overall: INCONCLUSIVE").strong()),
        None => ui.weak("No limits given: no verdict."),
    };
}

/// The expanded uncertainty's budget, for a value's tooltip.
fn budget_text(u: &crate::analysis::uncertainty::Uncertainty) -> String {
    let mut text = format!(
        "U = {:.4} (k = {}, u = {:.4}) by {}{}",
        u.expanded,
        u.k,
        u.u,
        u.method.name(),
        u.trials.map_or(String::new(), |t| format!(", {t} trials"))
    );
    for c in &u.budget {
        text.push_str(&format!("\n• {}: u = {:.4}", c.source, c.u));
    }
    if let Some(floor) = u.noise_floor {
        text.push_str(&format!("\nNoise alone would give {floor:.4} on these nodes."));
    }
    text
}

/// How the toleranced rows are judged against U; a change measures again.
fn decision_rule_picker(ui: &mut egui::Ui, rule: &mut DecisionRule) {
    ui.horizontal(|ui| {
        let mut fraction = match rule {
            DecisionRule::GuardBand { fraction } => *fraction,
            _ => 0.5,
        };
        egui::ComboBox::from_label("Decision rule")
            .selected_text(match rule {
                DecisionRule::Iso14253 => "ISO 14253-1".to_string(),
                DecisionRule::Simple => "Simple acceptance".to_string(),
                DecisionRule::GuardBand { fraction } => format!("Guard band {:.0} % of U", *fraction * 100.0),
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(rule, DecisionRule::Iso14253, "ISO 14253-1").on_hover_text(
                    "Pass only inside the limits shrunk by U, fail only outside them widened by U; between, \
                     INCONCLUSIVE.",
                );
                ui.selectable_value(rule, DecisionRule::Simple, "Simple acceptance")
                    .on_hover_text("ILAC-G8 simple acceptance: inside the limits passes; U is not used.");
                ui.selectable_value(rule, DecisionRule::GuardBand { fraction }, "Guard band")
                    .on_hover_text("ILAC-G8 guarded acceptance: pass inside the limits shrunk by a fraction of U.");
            });
        if let DecisionRule::GuardBand { fraction: f } = rule
            && ui.add(egui::DragValue::new(&mut fraction).range(0.0..=1.0).speed(0.05).prefix("× U ")).changed()
        {
            *f = fraction;
        }
    })
    .response
    .on_hover_text("The rule every toleranced row's verdict is taken by; it is kept in the session and the records.");
}

fn files(ui: &mut egui::Ui, rt: &mut InspectRuntime, commands: &mut Vec<Command>) {
    ui.strong("Export");
    ui.horizontal(|ui| {
        ui.label("Folder");
        let edit =
            ui.add(egui::TextEdit::singleline(&mut rt.export_folder).hint_text("current folder").desired_width(220.0));
        edit.on_hover_text("Where the save dialogs start, and where files go when no dialog can be shown.")
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::TextInput, true, "Export folder"));
    });
    let busy = rt.file_job_running();
    ui.add_enabled_ui(!busy, |ui| {
        ui.horizontal_wrapped(|ui| {
            for kind in ExportKind::ALL {
                if ui.button(kind.label()).on_hover_text(kind.tooltip()).clicked() {
                    commands.push(Command::InspectExport(kind));
                }
            }
        });
        ui.horizontal(|ui| {
            if ui.button("Save session…").on_hover_text(ExportKind::Session.tooltip()).clicked() {
                commands.push(Command::SaveSession(None));
            }
            if ui.button("Save as recipe…").on_hover_text(ExportKind::Recipe.tooltip()).clicked() {
                commands.push(Command::SaveRecipe(None));
            }
            if ui.button("Follow recipe…").on_hover_text(FOLLOW_RECIPE_TIP).clicked() {
                commands.push(Command::FollowRecipe(None));
            }
            if ui
                .button("Open session…")
                .on_hover_text("Reopen a saved session: data, parameters and inspection.")
                .clicked()
            {
                commands.push(Command::OpenSession(None));
            }
        });
    });
    if busy {
        busy_line(ui, "Writing…");
    }
}
