//! The profile plot: every section (distance in mm, height in µm), raw map
//! nodes beside the averaged profile on request, and two cursors A and B
//! (click to place, drag to move) reading dx, dz and the slope.

use eframe::egui::{self, Color32, RichText};
use egui_plot::{Legend, Line, MarkerShape, Plot, PlotPoints, Points, VLine};

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
    let profiles: &[Profile] =
        rt.analysis.value().and_then(|a| a.report.as_ref().ok()).map_or(&[], |r| r.profiles.as_slice());
    let plotted = series(&rt.doc, profiles);
    let readout_line_h = 18.0;
    ui.horizontal(|ui| {
        ui.strong("Profiles");
        ui.checkbox(&mut rt.doc.show_raw, "Raw points").on_hover_text(
            "Show the height-map nodes near each line (within half the averaging width) beside the averaged profile.",
        );
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
    if plotted.is_empty() {
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
    let plot_h = (height - 30.0 - 2.0 * readout_line_h).max(60.0);
    let response = Plot::new("inspect profile plot")
        .height(plot_h)
        .legend(Legend::default())
        .x_axis_label("distance along the line (mm)")
        .y_axis_label("z (µm)")
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
