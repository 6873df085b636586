//! The pixel inspector: for the selected pixel, per set a plot of its N
//! samples against the phase shift (saturated samples marked), the
//! threshold, and the sinusoid fitted to the unsaturated samples (Eqs. 2-4),
//! with the maps' values and, in words, why the pixel failed.

use std::f64::consts::TAU;

use eframe::egui::{self, Color32, RichText};
use egui_plot::{Axis, AxisHints, GridInput, GridMark, HLine, Line, MarkerShape, Plot, PlotPoints, Points};

use crate::app::commands::Command;
use crate::app::palette;
use crate::app::pixel_report::{PixelReport, SetSamples, SetStatus};
use crate::app::views::{format_period, format_value};

const SAMPLE_COLOR: Color32 = Color32::from_rgb(90, 170, 255);
const FIT_COLOR: Color32 = Color32::from_rgb(120, 220, 120);
const THRESHOLD_COLOR: Color32 = Color32::from_rgb(255, 170, 40);

pub fn show(ui: &mut egui::Ui, report: Option<&PixelReport>, commands: &mut Vec<Command>) {
    let Some(r) = report else {
        ui.heading("Pixel inspector");
        ui.label("Click a pixel in any map to see its samples, the fitted sinusoid and why it failed.");
        return;
    };
    ui.horizontal(|ui| {
        ui.heading("Pixel inspector");
        if ui.small_button("Clear").on_hover_text("Deselect the pixel.").clicked() {
            commands.push(Command::ClearSelection);
        }
    });
    ui.label(RichText::new(format!("{} camera · u {}, v {}", r.camera_name, r.pixel.u, r.pixel.v)).strong());
    let verdict_color =
        if r.verdict.starts_with("Valid") { ui.visuals().text_color() } else { palette::error_text(ui.visuals()) };
    ui.colored_label(verdict_color, &r.verdict);
    for reason in &r.reasons {
        ui.label(format!("• {reason}"));
    }
    for line in &r.projector {
        let color = if line.contains("refused") || line.starts_with("no projector") {
            palette::warning_text(ui.visuals())
        } else {
            ui.visuals().text_color()
        };
        ui.colored_label(color, line);
    }
    if let Some(phase) = r.fused_phase_rad {
        ui.label(format!("Fused phase Φ = {}", format_value(phase, "rad")));
    }
    if let Some((z, unit)) = &r.height {
        ui.label(format!("Height Z = {}", format_value(*z, unit)));
    }
    ui.add_space(4.0);
    // One key for all plots instead of a legend over each plot's data.
    ui.horizontal_wrapped(|ui| {
        ui.spacing_mut().item_spacing.x = 4.0;
        ui.colored_label(SAMPLE_COLOR, "• samples");
        ui.colored_label(palette::SATURATED, "× saturated");
        ui.colored_label(FIT_COLOR, "— fit to unsaturated");
        ui.colored_label(palette::warning_text(ui.visuals()), "— threshold");
    });
    egui::ScrollArea::vertical().id_salt("inspector sets").show(ui, |ui| {
        for s in r.sets.iter().rev() {
            set_section(ui, r, s);
            ui.add_space(6.0);
        }
    });
}

/// Heading line of one set: the text tests and operators read.
pub fn set_summary(s: &SetSamples) -> String {
    format!(
        "set {} · {} px: {} samples, {} saturated",
        s.set,
        format_period(s.period_px),
        s.samples_dn.len(),
        s.saturated_count()
    )
}

fn set_section(ui: &mut egui::Ui, r: &PixelReport, s: &SetSamples) {
    ui.label(RichText::new(set_summary(s)).strong());
    let status_color =
        if s.status == SetStatus::Valid { ui.visuals().weak_text_color() } else { palette::warning_text(ui.visuals()) };
    ui.colored_label(status_color, s.status.describe());
    if let Some(why) = crate::app::pixel_report::order_evidence_text(s.order_evidence) {
        ui.weak(why);
    }
    let mut values = Vec::new();
    if let Some(p) = s.wrapped_phase_rad {
        values.push(format!("φ {}", format_value(p, "rad")));
    }
    if let Some(b) = s.modulation_dn.filter(|_| !matches!(s.status, SetStatus::OverSaturated { .. })) {
        values.push(format!("B {}", format_value(b, "dn")));
    }
    if let Some(sig) = s.phase_sigma_rad {
        values.push(format!("σφ {}", format_value(sig, "rad")));
    }
    if let Some(u) = s.unwrapped_phase_rad {
        values.push(format!("Φ {}", format_value(u, "rad")));
    }
    if !values.is_empty() {
        ui.weak(values.join(" · "));
    }

    let unsaturated: Vec<[f64; 2]> = s
        .shifts_rad
        .iter()
        .zip(&s.samples_dn)
        .zip(&s.saturated)
        .filter(|(_, sat)| !**sat)
        .map(|((&d, &v), _)| [d, f64::from(v)])
        .collect();
    let saturated: Vec<[f64; 2]> = s
        .shifts_rad
        .iter()
        .zip(&s.samples_dn)
        .zip(&s.saturated)
        .filter(|(_, sat)| **sat)
        .map(|((&d, &v), _)| [d, f64::from(v)])
        .collect();
    let (d_lo, d_hi) =
        s.shifts_rad.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let (d_lo, d_hi) = if d_lo.is_finite() && d_hi > d_lo { (d_lo.min(0.0), d_hi.max(TAU)) } else { (0.0, TAU) };
    let threshold = f64::from(r.threshold_dn);
    let fit = s.fit;
    Plot::new(("samples", s.set))
        .height(130.0)
        .allow_scroll(false)
        .allow_zoom(false)
        .allow_drag(false)
        .include_x(d_lo)
        .include_x(d_hi)
        .include_y(0.0)
        .include_y(threshold * 1.05)
        .x_grid_spacer(quarter_turns)
        // Quarter-turn labels are short: let them sit closer than egui_plot's default 60 px.
        .custom_x_axes(vec![
            AxisHints::new(Axis::X)
                .label("phase shift δ")
                .formatter(|mark, _| format_quarter_turn(mark.value))
                .label_spacing(24.0..=36.0),
        ])
        .y_axis_label("I (dn)")
        .show(ui, |plot| {
            if let Some(f) = fit {
                let curve: PlotPoints = (0..=120)
                    .map(|i| {
                        let d = d_lo + (d_hi - d_lo) * f64::from(i) / 120.0;
                        [d, f.offset + f.modulation * (f.phase_rad + d).cos()]
                    })
                    .collect();
                plot.line(Line::new("fit (unsaturated)", curve).color(FIT_COLOR).width(1.5));
            }
            plot.hline(HLine::new(format!("threshold {} dn", r.threshold_dn), threshold).color(THRESHOLD_COLOR));
            plot.points(
                Points::new("samples", unsaturated)
                    .color(SAMPLE_COLOR)
                    .radius(3.5)
                    .shape(MarkerShape::Circle)
                    .filled(true),
            );
            if !saturated.is_empty() {
                plot.points(
                    Points::new("saturated", saturated).color(palette::SATURATED).radius(5.0).shape(MarkerShape::Cross),
                );
            }
        });
    if let Some(f) = fit {
        ui.weak(format!(
            "fit on {} of {} samples: A {:.1} dn, B {:.1} dn, φ {:.4} rad, residual {:.2} dn rms",
            f.used,
            s.samples_dn.len(),
            f.offset,
            f.modulation,
            f.phase_rad,
            f.residual_rms
        ));
    } else {
        ui.weak("no fit: fewer than 3 unsaturated samples");
    }
}

/// Grid marks at multiples of pi/2 (labelled) over the visible phase-shift range.
fn quarter_turns(input: GridInput) -> Vec<GridMark> {
    let step = std::f64::consts::FRAC_PI_2;
    let (lo, hi) = input.bounds;
    let (first, last) = ((lo / step).ceil() as i64, (hi / step).floor() as i64);
    if last - first > 64 {
        return Vec::new();
    }
    (first..=last).map(|k| GridMark { value: k as f64 * step, step_size: step }).collect()
}

/// "0", "π/2", "π", "3π/2", "2π", ... for multiples of pi/2.
fn format_quarter_turn(value: f64) -> String {
    let k = (value / std::f64::consts::FRAC_PI_2).round() as i64;
    match k {
        0 => "0".into(),
        2 => "π".into(),
        -2 => "-π".into(),
        k if k % 2 == 0 => format!("{}π", k / 2),
        1 => "π/2".into(),
        -1 => "-π/2".into(),
        k => format!("{k}π/2"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_shift_ticks_are_quarter_turns() {
        let q = std::f64::consts::FRAC_PI_2;
        let labels: Vec<String> = [0.0, q, 2.0 * q, 3.0 * q, 4.0 * q, -q].map(format_quarter_turn).to_vec();
        assert_eq!(labels, ["0", "π/2", "π", "3π/2", "2π", "-π/2"]);
    }
}
