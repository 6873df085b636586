//! The pixel inspector: for the selected pixel, per set a plot of its N
//! samples against the phase shift (saturated samples marked), the
//! threshold, and the sinusoid fitted to the unsaturated samples (Eqs. 2-4),
//! with the maps' values and, in words, why the pixel failed.

use std::f64::consts::TAU;

use eframe::egui::{self, Color32, RichText};
use egui_plot::{HLine, Legend, Line, MarkerShape, Plot, PlotPoints, Points};

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
    let verdict_color = if r.verdict.starts_with("Valid") { ui.visuals().text_color() } else { palette::ERROR };
    ui.colored_label(verdict_color, &r.verdict);
    for reason in &r.reasons {
        ui.label(format!("• {reason}"));
    }
    if let Some(phase) = r.fused_phase_rad {
        ui.label(format!("Fused phase Φ = {}", format_value(phase, "rad")));
    }
    if let Some((z, unit)) = &r.height {
        ui.label(format!("Height Z = {}", format_value(*z, unit)));
    }
    ui.add_space(4.0);
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
    let status_color = if s.status == SetStatus::Valid { ui.visuals().weak_text_color() } else { palette::WARNING };
    ui.colored_label(status_color, s.status.describe());
    let mut values = Vec::new();
    if let Some(p) = s.wrapped_phase_rad {
        values.push(format!("φ {}", format_value(p, "rad")));
    }
    if let Some(b) = s.modulation_dn {
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
        .legend(Legend::default())
        .allow_scroll(false)
        .allow_zoom(false)
        .allow_drag(false)
        .include_y(0.0)
        .include_y(threshold * 1.05)
        .x_axis_label("phase shift δ (rad)")
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
