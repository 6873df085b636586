//! The statistics panel: per camera and set the saturated, over-saturated,
//! low-modulation and valid shares, the unwrapping figures, the fusion's
//! source shares and completeness, the 3D point count and matching figures,
//! and the wall time of every stage.

use eframe::egui::{self, RichText};

use crate::app::run_data::ResultSet;
use crate::app::views::{format_period, percent};
use crate::engine::fringe::Measurement;

pub fn show(ui: &mut egui::Ui, measurement: Option<&Measurement>, result: Option<&ResultSet>) {
    ui.heading("Statistics");
    let (Some(m), Some(r)) = (measurement, result) else {
        ui.label("No result yet.");
        return;
    };
    let rec = &r.reconstruction;
    ui.label(format!(
        "Result #{} · method {} · threshold {} dn · min. modulation {} dn",
        r.generation, rec.params.method, rec.saturation_threshold, rec.params.min_modulation_dn
    ));
    egui::ScrollArea::vertical().id_salt("statistics").show(ui, |ui| {
        for (ci, cp) in rec.cameras.iter().enumerate() {
            let pixels = cp.width * cp.height;
            ui.add_space(6.0);
            ui.label(RichText::new(format!("Camera {} ({}x{} px)", cp.camera, cp.width, cp.height)).strong());
            egui::Grid::new(("set stats", ci)).striped(true).num_columns(6).show(ui, |ui| {
                for h in ["set", "saturated", "over-sat.", "low mod.", "valid", "unwrapped"] {
                    ui.label(RichText::new(h).weak());
                }
                ui.end_row();
                for (s, wp) in cp.sets.iter().enumerate() {
                    let period = m.sets.get(s).map_or(f64::NAN, |set| set.period_px);
                    ui.label(format!("{s} · {} px", format_period(period)));
                    ui.label(percent(wp.stats.partially_saturated, wp.stats.pixels));
                    ui.label(percent(wp.stats.over_saturated, wp.stats.pixels));
                    ui.label(percent(wp.stats.low_modulation, wp.stats.pixels));
                    ui.label(percent(wp.stats.valid, wp.stats.pixels));
                    match cp.enabled.iter().position(|&e| e == s) {
                        Some(k) => ui.label(percent(cp.unwrapped.unwrapped_count[k], pixels)),
                        None => ui.weak("disabled"),
                    };
                    ui.end_row();
                }
            });
            ui.add_space(4.0);
            let completeness = percent(cp.fused.valid_count(), pixels);
            ui.label(format!("Completeness (valid final phase): {completeness}"));
            let mut shares: Vec<String> = cp
                .enabled
                .iter()
                .zip(&cp.fused.source_counts)
                .map(|(&s, &n)| format!("set {s}: {}", percent(n, pixels)))
                .collect();
            shares.push(format!("none: {}", percent(cp.fused.none_count, pixels)));
            shares.push(format!("order failed: {}", percent(cp.fused.order_failed_count, pixels)));
            ui.label(format!("Sources: {}", shares.join(" · ")));
            let u = &cp.unwrapped;
            let total = |v: &[usize]| v.iter().sum::<usize>();
            ui.label(format!(
                "Fringe orders ({}): confirmed by neighbours {} · by patch {} · undecided {} · contradicted {}",
                u.check,
                percent(total(&u.confirmed_by_neighbours), pixels),
                percent(total(&u.confirmed_by_patch), pixels),
                percent(total(&u.undecided), pixels),
                percent(total(&u.contradicted), pixels)
            ))
            .on_hover_text(
                "Summed over the sets. Confirmed: ambiguous on the pixel's own samples, accepted because its \
                 neighbours on the same surface or its patch's mean residual against the sparser set agree. \
                 Undecided or contradicted: the set is not used there and a sparser set fills in.",
            );
            let [by_neighbours, by_patch] = cp.fused.confirmed_counts;
            ui.label(format!(
                "Final phase resting on confirmed orders: {} (neighbours {}, patch {}){}",
                percent(by_neighbours + by_patch, pixels),
                percent(by_neighbours, pixels),
                percent(by_patch, pixels),
                if cp.fused.excluded_confirmed > 0 {
                    format!(" · left out (own orders only) {}", percent(cp.fused.excluded_confirmed, pixels))
                } else {
                    String::new()
                }
            ));
            if cp.root_wrap_fraction > 0.0 {
                ui.label(format!("Root set wraps in {:.1} % of rows", cp.root_wrap_fraction * 100.0));
            }
        }
        ui.add_space(8.0);
        ui.label(RichText::new("3D").strong());
        match &rec.stereo {
            Some(st) => {
                let left_pixels = rec.cameras.first().map_or(0, |c| c.width * c.height);
                ui.label(format!(
                    "Points: {} ({} of the left pixels)",
                    st.cloud.len(),
                    percent(st.cloud.len(), left_pixels)
                ));
                let ms = &st.match_stats;
                ui.label(format!(
                    "Matching: {} candidates, {} matched ({} extended to an edge), {} unmatched ({} at a refused discontinuity), {} ambiguous",
                    ms.candidates,
                    ms.matched,
                    ms.extended_to_edge,
                    ms.unmatched,
                    ms.unmatched_at_discontinuity,
                    ms.ambiguous
                ));
            }
            None => match rec.rig_cloud.as_deref() {
                Some(cloud) => {
                    let pixels = rec.cameras.first().map_or(0, |c| c.width * c.height);
                    ui.label(format!(
                        "Points: {} ({} of the camera's pixels), from the projector coordinates",
                        cloud.len(),
                        percent(cloud.len(), pixels)
                    ));
                }
                None => {
                    ui.label(format!("No 3D: {}", rec.stereo_skipped.as_deref().unwrap_or("no stereo result")));
                }
            },
        }
        ui.add_space(8.0);
        ui.label(RichText::new("Timings").strong());
        egui::Grid::new("timings").striped(true).num_columns(2).show(ui, |ui| {
            for (stage, seconds) in &rec.timings {
                ui.label(stage);
                ui.label(format!("{:.1} ms", seconds * 1e3));
                ui.end_row();
            }
            let total = rec.total_seconds();
            ui.label(RichText::new("total").strong());
            ui.label(RichText::new(format!("{:.1} ms", total * 1e3)).strong());
            ui.end_row();
        });
    });
}
