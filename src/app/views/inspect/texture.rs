//! The settings of a texture measurement in the Inspect panel:
//! form removal (F-operator), the S- and L-filter nesting indices and the
//! accepted range of each parameter the operator limits. The parameters
//! themselves are rows of the measurement table, like every measurement.

use std::collections::BTreeMap;

use eframe::egui;

use crate::analysis::inspection::{Measure, ParameterLimit};
use crate::analysis::measurement_table::Tolerance;
use crate::analysis::texture::filter::FormRemoval;
use crate::analysis::texture::measure::ArealParameter;
use crate::analysis::texture::profile_params::ProfileParameter;

/// Whether the measurement's limits are per parameter (set here) rather than
/// one range for the measurement.
pub fn is_texture(m: &Measure) -> bool {
    matches!(m, Measure::Texture { .. } | Measure::ProfileTexture { .. })
}

/// Draws the settings of a texture measurement `name` (nothing for others).
pub fn settings(ui: &mut egui::Ui, name: &str, m: &mut Measure) {
    match m {
        Measure::Texture { form, ls_mm, lc_mm, limits, .. } => {
            ui.horizontal_wrapped(|ui| {
                ui.add_space(24.0);
                form_edit(ui, name, form);
                cutoff_edit(ui, name, "λs", ls_mm, 0.0025, "S-filter (ISO 16610-61): removes wavelengths below λs.");
                cutoff_edit(ui, name, "λc", lc_mm, 0.8, "L-filter (ISO 16610-61): removes wavelengths above λc.");
            });
            limits_edit(ui, name, limits, &ArealParameter::ALL, |p| p.name().to_string(), |p| p.can_be_negative());
        }
        Measure::ProfileTexture { ls_mm, lc_mm, periodic, limits, .. } => {
            ui.horizontal_wrapped(|ui| {
                ui.add_space(24.0);
                cutoff_edit(ui, name, "λs", ls_mm, 0.0025, "S-filter (ISO 16610-21); off: the ISO 21920-3 default.");
                cutoff_edit(
                    ui,
                    name,
                    "λc",
                    lc_mm,
                    0.8,
                    "Roughness / waviness cut-off (ISO 16610-21); off: chosen from the measured roughness as ISO \
                     21920-3 prescribes.",
                );
                if lc_mm.is_none() {
                    ui.checkbox(periodic, "periodic").on_hover_text(
                        "A periodic profile (turned, ground with a feed): λc from the measured RSm, ISO 21920-3's \
                         table for periodic profiles, instead of from Ra.",
                    );
                }
            });
            limits_edit(ui, name, limits, &ProfileParameter::all(), |p| p.name(), |p| p.can_be_negative());
        }
        _ => {}
    }
}

fn form_edit(ui: &mut egui::Ui, name: &str, form: &mut FormRemoval) {
    let text = |f: FormRemoval| match f {
        FormRemoval::None => "no form removal".to_string(),
        FormRemoval::Plane => "plane removed".to_string(),
        FormRemoval::Polynomial(n) => format!("polynomial {n} removed"),
    };
    egui::ComboBox::from_id_salt(("texture form", name))
        .selected_text(text(*form))
        .show_ui(ui, |ui| {
            for f in [FormRemoval::None, FormRemoval::Plane, FormRemoval::Polynomial(2), FormRemoval::Polynomial(3)] {
                ui.selectable_value(form, f, text(f));
            }
        })
        .response
        .on_hover_text("F-operator: the least-squares form taken off before the parameters.")
        .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, format!("Form of {name}")));
}

/// An optional nesting index in mm: a checkbox turns it on with `default`.
fn cutoff_edit(ui: &mut egui::Ui, name: &str, label: &str, value: &mut Option<f64>, default: f64, tip: &str) {
    let mut on = value.is_some();
    if ui.checkbox(&mut on, label).on_hover_text(tip).changed() {
        *value = on.then_some(default);
    }
    if let Some(v) = value.as_mut() {
        ui.add(egui::DragValue::new(v).range(0.0001..=100.0).speed(0.001).max_decimals(4).suffix(" mm"))
            .on_hover_text(tip)
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("{label} of {name}")));
    }
}

/// The accepted range per limited parameter, and a picker to limit another.
fn limits_edit<P: Ord + Copy>(
    ui: &mut egui::Ui,
    name: &str,
    limits: &mut BTreeMap<P, ParameterLimit>,
    all: &[P],
    label: impl Fn(P) -> String,
    can_be_negative: impl Fn(P) -> bool,
) {
    let mut remove = None;
    for (p, limit) in limits.iter_mut() {
        let what = label(*p);
        ui.horizontal(|ui| {
            ui.add_space(24.0);
            ui.label(&what);
            let nominal = limit.nominal.unwrap_or(0.0);
            let (mut lo, mut hi) = (nominal + limit.tolerance.lower, nominal + limit.tolerance.upper);
            let a = ui.add(egui::DragValue::new(&mut lo).speed(0.001).max_decimals(4)).on_hover_text("Minimum.");
            a.widget_info(|| {
                egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("Minimum of {name} {what}"))
            });
            ui.label("…");
            let b = ui.add(egui::DragValue::new(&mut hi).speed(0.001).max_decimals(4)).on_hover_text("Maximum.");
            b.widget_info(|| {
                egui::WidgetInfo::labeled(egui::Role::SpinButton, true, format!("Maximum of {name} {what}"))
            });
            if a.changed() || b.changed() {
                *limit =
                    ParameterLimit { nominal: None, tolerance: Tolerance { lower: lo.min(hi), upper: lo.max(hi) } };
            }
            if ui.small_button("×").on_hover_text(format!("No limit on {what}")).clicked() {
                remove = Some(*p);
            }
        });
    }
    if let Some(p) = remove {
        limits.remove(&p);
    }
    ui.horizontal(|ui| {
        ui.add_space(24.0);
        let mut picked = None;
        egui::ComboBox::from_id_salt(("texture limit", name))
            .selected_text("limit a parameter…")
            .show_ui(ui, |ui| {
                for &p in all.iter().filter(|p| !limits.contains_key(p)) {
                    if ui.selectable_label(false, label(p)).clicked() {
                        picked = Some(p);
                    }
                }
            })
            .response
            .on_hover_text("Give a parameter an accepted range: its row in the table then says PASS or FAIL.")
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::ComboBox, true, format!("Limit of {name}")));
        if let Some(p) = picked {
            // A quantity that cannot be negative starts at 0 .. 1; others -1 .. 1.
            let lower = if can_be_negative(p) { -1.0 } else { 0.0 };
            limits.insert(p, ParameterLimit { nominal: None, tolerance: Tolerance { lower, upper: 1.0 } });
        }
    });
}
