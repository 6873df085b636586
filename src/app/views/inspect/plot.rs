//! The profile plot: every section (distance in mm, height in µm), raw map
//! nodes beside the averaged profile on request, and two cursors A and B
//! (click to place, drag to move) reading dx, dz and the slope.

use eframe::egui::{self, Color32, RichText};
use egui_plot::{Legend, Line, LineStyle, MarkerShape, Plot, PlotPoints, Points, VLine};

use crate::analysis::inspection::{InspectionReport, ProfileTextureCurves};
use crate::analysis::profile::Profile;

use super::InspectRuntime;
use super::map::color32;
use super::plot_png::PlotSeries;
use super::state::{self, InspectDoc};

pub const CURSOR_COLORS: [Color32; 2] = [Color32::from_rgb(255, 80, 80), Color32::from_rgb(80, 170, 255)];
/// Raw points drawn per profile at most (every k-th beyond that).
const MAX_RAW_POINTS: usize = 20_000;
/// A press this close (screen points) to a cursor drags it.
const GRAB_PX: f32 = 10.0;

fn color_of(doc: &InspectDoc, name: &str) -> [u8; 3] {
    doc.profiles.iter().find(|p| p.spec.name == name).map_or([200, 200, 200], |p| p.color)
}

/// The plotted data of each profile (also what the PNG export draws).
pub fn series(doc: &InspectDoc, profiles: &[Profile]) -> Vec<PlotSeries> {
    profiles
        .iter()
        .map(|p| {
            let step = (p.raw.len() / MAX_RAW_POINTS).max(1);
            PlotSeries {
                name: p.name.clone(),
                color: color_of(doc, &p.name),
                points: p.samples.iter().map(|s| [s.distance_mm, s.z_um]).collect(),
                raw: if doc.show_raw {
                    p.raw.iter().step_by(step).map(|r| [r.distance_mm, r.z_um]).collect()
                } else {
                    Vec::new()
                },
            }
        })
        .collect()
}

/// A line the plot draws from a profile texture evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureLine {
    pub name: String,
    pub color: [u8; 3],
    pub points: Vec<[f64; 2]>,
    pub dashed: bool,
}

/// The lines of the profile texture evaluations: with `r_and_w`, each
/// evaluated profile's R (solid) and W (dashed) over its evaluation length,
/// about zero; else its mean line (form + W) over the measured heights
/// (dashed), as a profilometer draws it through the trace.
pub fn texture_lines(doc: &InspectDoc, textures: &[ProfileTextureCurves], r_and_w: bool) -> Vec<TextureLine> {
    let along = |t: &ProfileTextureCurves, v: &[f64], all: bool| -> Vec<[f64; 2]> {
        let range = if all { 0..v.len() } else { t.curves.evaluated.clone() };
        range.filter_map(|i| Some([*t.distance_mm.get(i)?, v[i]])).collect()
    };
    let mut lines = Vec::new();
    for t in textures {
        let color = color_of(doc, &t.profile);
        if r_and_w {
            lines.push(TextureLine {
                name: format!("{} R", t.profile),
                color,
                points: along(t, &t.curves.roughness_um, false),
                dashed: false,
            });
            lines.push(TextureLine {
                name: format!("{} W", t.profile),
                color: [color[0] / 2 + 100, color[1] / 2 + 100, color[2] / 2 + 100],
                points: along(t, &t.curves.waviness_um, false),
                dashed: true,
            });
        } else {
            lines.push(TextureLine {
                name: format!("{} mean line (λc {} mm)", t.profile, t.lc_mm),
                color: [color[0] / 2 + 100, color[1] / 2 + 100, color[2] / 2 + 100],
                points: along(t, &t.curves.mean_line_um(), true),
                dashed: true,
            });
        }
    }
    lines
}

/// "A-A: Ra 0.12 · Rz 0.9 · RSm 0.08 mm · Wa 0.3 µm" from the table rows of
/// each texture measurement, to read under the plot.
fn texture_summaries(report: &InspectionReport) -> Vec<String> {
    report
        .profile_textures
        .iter()
        .map(|t| {
            let value = |p: &str| {
                report
                    .table
                    .rows
                    .iter()
                    .find(|r| r.name == format!("{} {p}", t.measurement))
                    .and_then(|r| r.value)
                    .map_or_else(|| "–".to_string(), |v| format!("{v:.4}"))
            };
            format!(
                "{} (λc {} mm): Ra {} · Rq {} · Rz {} µm · RSm {} mm · Wa {} · Wt {} µm",
                t.profile,
                t.lc_mm,
                value("Ra"),
                value("Rq"),
                value("Rz"),
                value("RSm"),
                value("Wa"),
                value("Wt")
            )
        })
        .collect()
}

/// Runs of finite points (a gap in the data breaks the line).
fn runs(points: &[[f64; 2]]) -> Vec<Vec<[f64; 2]>> {
    let mut out = Vec::new();
    let mut current = Vec::new();
    for p in points {
        if p[1].is_finite() {
            current.push(*p);
        } else if !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

pub fn show(ui: &mut egui::Ui, rt: &mut InspectRuntime, height: f32) {
    let report = rt.analysis.value().and_then(|a| a.report.as_ref().ok());
    let profiles: &[Profile] = report.map_or(&[], |r| r.profiles.as_slice());
    let textures: &[ProfileTextureCurves] = report.map_or(&[], |r| r.profile_textures.as_slice());
    let summaries = report.map(texture_summaries).unwrap_or_default();
    let r_and_w = rt.doc.show_r_and_w && !textures.is_empty();
    let plotted = if r_and_w { Vec::new() } else { series(&rt.doc, profiles) };
    let texture = texture_lines(&rt.doc, textures, r_and_w);
    let readout_line_h = 18.0;
    ui.horizontal(|ui| {
        ui.strong("Profiles");
        ui.checkbox(&mut rt.doc.show_raw, "Raw points").on_hover_text(
            "Show the height-map nodes near each line (within half the averaging width) beside the averaged profile.",
        );
        ui.add_enabled(!textures.is_empty(), egui::Checkbox::new(&mut rt.doc.show_r_and_w, "R and W"))
            .on_hover_text(
                "Plot the roughness (R, solid) and waviness (W, dashed) profiles of the profiles that have a \
                 texture measurement, over their evaluation length, instead of the measured heights (which show \
                 the L-filter's mean line dashed).",
            )
            .on_disabled_hover_text("Add a texture measurement on a profile to see its R and W profiles.");
        if ui.button("Clear cursors").on_hover_text("Remove cursors A and B.").clicked() {
            rt.cursors = [None, None];
        }
        ui.add(
            egui::Label::new(
                RichText::new(
                    "Click the plot to place cursors A and B, drag them to move; scroll zooms, double-click resets.",
                )
                .weak(),
            )
            .truncate(),
        );
    });
    if plotted.is_empty() && texture.is_empty() {
        ui.add_space(24.0);
        ui.vertical_centered(|ui| {
            ui.add(
                egui::Label::new(
                    RichText::new(
                        "No profile yet: pick Line, Horizontal or Vertical section above and draw on the map.",
                    )
                    .weak(),
                )
                .wrap(),
            )
        });
        return;
    }
    let cursors = rt.cursors;
    let plot_h = (height - 30.0 - (2 + summaries.len()) as f32 * readout_line_h).max(60.0);
    let response = Plot::new("inspect profile plot")
        .height(plot_h)
        .legend(Legend::default())
        .x_axis_label("distance along the line (mm)")
        .y_axis_label(if r_and_w { "R, W (µm)" } else { "z (µm)" })
        .allow_drag(false)
        .show(ui, |pui| {
            for s in &plotted {
                let color = color32(s.color);
                if !s.raw.is_empty() {
                    pui.points(
                        Points::new(format!("{} raw", s.name), PlotPoints::new(s.raw.clone()))
                            .color(color.gamma_multiply(0.45))
                            .radius(1.2)
                            .shape(MarkerShape::Circle),
                    );
                }
                for (k, run) in runs(&s.points).into_iter().enumerate() {
                    pui.line(
                        Line::new(s.name.clone(), PlotPoints::new(run))
                            .id(("profile run", &s.name, k))
                            .color(color)
                            .width(2.0),
                    );
                }
            }
            for (k, line) in texture.iter().enumerate() {
                for (j, run) in runs(&line.points).into_iter().enumerate() {
                    let l = Line::new(line.name.clone(), PlotPoints::new(run))
                        .id(("texture run", k, j))
                        .color(color32(line.color))
                        .width(1.5);
                    pui.line(if line.dashed { l.style(LineStyle::dashed_dense()) } else { l });
                }
            }
            for (i, c) in cursors.iter().enumerate() {
                if let Some(x) = c {
                    pui.vline(VLine::new(if i == 0 { "A" } else { "B" }, *x).color(CURSOR_COLORS[i]).width(1.5));
                }
            }
        });
    let r = &response.response;
    r.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, "Profile plot"));
    let t = &response.transform;
    let nearest = |pos: egui::Pos2| -> Option<usize> {
        (0..2)
            .filter_map(|i| cursors[i].map(|x| (i, (t.position_from_point_x(x) - pos.x).abs())))
            .filter(|(_, d)| *d < GRAB_PX)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    };
    if r.drag_started_by(egui::PointerButton::Primary)
        && let Some(origin) = ui.input(|i| i.pointer.press_origin())
    {
        let grabbed = nearest(origin);
        ui.memory_mut(|m| m.data.insert_temp(egui::Id::unique("inspect cursor grab"), grabbed));
    }
    if r.dragged_by(egui::PointerButton::Primary)
        && let Some(pos) = r.interact_pointer_pos()
        && let Some(Some(i)) = ui.memory(|m| m.data.get_temp::<Option<usize>>(egui::Id::unique("inspect cursor grab")))
    {
        rt.cursors[i] = Some(t.value_from_position(pos).x);
    }
    if r.clicked()
        && let Some(pos) = r.interact_pointer_pos()
    {
        let x = t.value_from_position(pos).x;
        let slot = nearest(pos).unwrap_or(if cursors[0].is_none() {
            0
        } else if cursors[1].is_none() {
            1
        } else {
            // Both placed: move the nearer one.
            let d = |i: usize| cursors[i].map_or(f64::INFINITY, |c| (c - x).abs());
            if d(0) <= d(1) { 0 } else { 1 }
        });
        rt.cursors[slot] = Some(x);
    }
    // Read-outs on the selected profile (or the first).
    let which = match rt.selection {
        Some(super::Selection::Profile(i)) => rt.doc.profiles.get(i).map(|p| p.spec.name.clone()),
        _ => None,
    };
    let profiles: &[Profile] =
        rt.analysis.value().and_then(|a| a.report.as_ref().ok()).map_or(&[], |r| r.profiles.as_slice());
    let profile = which.and_then(|n| profiles.iter().find(|p| p.name == n)).or(profiles.first());
    if let Some(p) = profile {
        let text = match rt.cursors {
            [Some(a), Some(b)] => {
                let c = state::cursor_readout(p, a, b);
                format!(
                    "{}: A {:.3} mm {:.2} µm · B {:.3} mm {:.2} µm · dx {:.4} mm · dz {:.3} µm · slope {:.2} µm/mm \
                     ({:.3}°)",
                    p.name, c.a[0], c.a[1], c.b[0], c.b[1], c.dx_mm, c.dz_um, c.slope_um_per_mm, c.angle_deg
                )
            }
            [Some(a), None] | [None, Some(a)] => {
                format!(
                    "{}: cursor at {a:.4} mm, z {:.3} µm · click again for cursor B",
                    p.name,
                    state::profile_z_at(p, a)
                )
            }
            [None, None] => format!("{}: click the plot to place cursor A", p.name),
        };
        ui.add(egui::Label::new(egui::RichText::new(text).monospace()).wrap());
        ui.add(
            egui::Label::new(
                egui::RichText::new(format!(
                    "{}: step {:.4} mm, averaging width {:.4} mm ({} parallel lines); interpolation: {}",
                    p.name,
                    p.step_mm,
                    p.width_mm,
                    p.lines_across,
                    p.interpolation.describe()
                ))
                .small()
                .weak(),
            )
            .truncate(),
        );
    }
    for line in summaries {
        ui.add(egui::Label::new(egui::RichText::new(line).monospace().small()).truncate());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_break_the_line() {
        let pts = [[0.0, 1.0], [0.1, f64::NAN], [0.2, 2.0], [0.3, 3.0], [0.4, f64::NAN]];
        assert_eq!(runs(&pts), vec![vec![[0.0, 1.0]], vec![[0.2, 2.0], [0.3, 3.0]]]);
        assert!(runs(&[]).is_empty());
    }
}
