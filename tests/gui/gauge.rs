//! Issue 50, item 5 in the app: the History view's Gauge study computes a
//! Type-1 study of the selected measurement's records, and says why a Gage
//! R&R cannot be made of them.

use egui_kittest::kittest::Queryable as _;
use sheen::records::{DbLocation, MeasurementRecord, PartRecord, PartVerdict, Store};

use super::{shows, started, step_until};

fn record(i: usize, value: f64) -> PartRecord {
    PartRecord {
        part_id: "gauge-block".into(),
        recipe: "step-gauge".into(),
        time_utc: chrono::DateTime::parse_from_rfc3339(&format!("2026-12-07T08:{i:02}:00Z")).expect("time").to_utc(),
        station: None,
        operator: Some("ana".into()),
        input_path: "in.json".into(),
        input_hash: None,
        sheen_version: "0.1.0".into(),
        engine_parameters: None,
        inspection: None,
        decision_rule: None,
        exports: Vec::new(),
        verdict: PartVerdict::Pass,
        reason: None,
        height_map_path: None,
        height_map_hash: None,
        measurements: vec![MeasurementRecord {
            name: "step 250".into(),
            kind: "step_height".into(),
            parameter: None,
            value: Some(value),
            unit: "um".into(),
            nominal: None,
            lower_limit: None,
            upper_limit: None,
            verdict: None,
            note: None,
            uncertainty: None,
            decision_rule: None,
            acceptance_lower: None,
            acceptance_upper: None,
        }],
    }
}

#[test]
fn the_history_views_gauge_study_gives_cg_and_cgk_of_the_records() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = dir.path().join("records.sqlite");
    let values: Vec<f64> = (0..30).map(|i| 250.2 + 0.3 * ((i * 7 % 11) as f64 - 5.0) / 5.0).collect();
    let mut store = Store::open(&DbLocation::Sqlite(db.clone())).expect("store");
    for (i, v) in values.iter().enumerate() {
        store.insert(&record(i, *v)).expect("record");
    }
    drop(store);
    let expected = sheen::analysis::gauge::type1(&values, 250.0, 20.0).expect("study");

    let mut h = started();
    h.state_mut().state.views.inspect.record.db = db.display().to_string();
    h.run_steps(1);
    h.get_by_label("History").click();
    step_until(&mut h, "the records", |app| app.history().parts().is_some_and(|p| p.len() == 30));
    h.get_by_label("Gauge study").click();
    h.run_steps(2);
    assert!(shows(&h, "30 recorded value(s) of 'step 250'"));
    assert!(shows(&h, "Type the reference part's calibrated value"), "asks for xm and T first");
    h.state_mut().state.views.history.gauge.reference = "250".into();
    h.state_mut().state.views.history.gauge.tolerance = "20".into();
    h.run_steps(2);
    let headline = format!("Cg {:.2}  Cgk {:.2}", expected.cg, expected.cgk);
    assert!(shows(&h, &headline), "the figures of analysis::gauge on screen: {headline}");
    // The study saved for the lab file, as HTML and PDF, with every value.
    h.state_mut().state.views.history.gauge.export_folder = dir.path().display().to_string();
    h.run_steps(1);
    for (button, file) in [("Save study HTML", "type-1_step_250.html"), ("Save study PDF", "type-1_step_250.pdf")] {
        h.get_by_label(button).click();
        step_until(&mut h, "the study saved", |app| !app.history().study_exports.is_running());
        h.run_steps(1);
        let status = h.state().history().study_exports.status.clone().expect("a status");
        assert!(!status.1 && status.0.contains(file), "{status:?}");
    }
    let page = std::fs::read_to_string(dir.path().join("type-1_step_250.html")).expect("the HTML page");
    assert!(page.contains("CAPABLE") && page.contains("Data (30 values)"), "{page}");
    assert_eq!(page.matches("<tr><td class=\"num\">").count(), 30);
    let pdf = std::fs::read(dir.path().join("type-1_step_250.pdf")).expect("the PDF");
    assert!(pdf.starts_with(b"%PDF-"));
    h.get_by_label("Gage R&R").click();
    h.run_steps(2);
    assert!(shows(&h, "needs at least 2 parts; 1 given"), "one part by one operator is no R&R study");
}
