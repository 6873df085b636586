//! The Line view runs the same watch as `sheen watch` and shows each part
//! as it arrives.

use std::path::Path;
use std::process::Command;

use egui_kittest::kittest::Queryable as _;
use sheen::records::PartVerdict;

use super::{shows, started, step_until};

fn sheen(args: &[&str]) {
    let o = Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run sheen");
    assert!(o.status.success(), "sheen {args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

fn simulate(out: &Path, scene: &str, seed: u64, place: &str) {
    let out = out.to_str().expect("utf8");
    let seed = seed.to_string();
    let args =
        ["simulate", "--scene", scene, "--out", out, "-q", "--width", "256", "--height", "192", "--noise", "0.5"];
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["--seed", &seed, "--place", place]);
    sheen(&all);
}

const SPEC: &str = r#"{"sheen_inspection": 1,
 "regions": [
  {"name": "ref200", "region": {"shape": "rectangle", "x_mm": [-0.2, 0.7], "y_mm": [-5, 5]}},
  {"name": "top200", "region": {"shape": "rectangle", "x_mm": [1.9, 4.1], "y_mm": [-5, 5]}}
 ],
 "measurements": [
  {"name": "step 200", "measure": {"kind": "step_height", "reference": ["ref200"], "measured": ["top200"]},
   "nominal": 200, "tolerance": {"lower": -5, "upper": 5}}
 ]}"#;

#[test]
fn the_line_view_runs_the_watch_and_shows_each_part_as_it_arrives() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    simulate(&d.join("reference"), "step-gauge", 1, "0,0,0");
    std::fs::write(d.join("spec.json"), SPEC).expect("spec");
    let recipe = d.join("gauge.sheen-recipe.json");
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    sheen(&[
        "recipe",
        &p(&d.join("reference/fringe-set.json")),
        "--spec",
        &p(&d.join("spec.json")),
        "--out",
        &p(&recipe),
        "-q",
    ]);
    let inbox = d.join("inbox");
    simulate(&inbox.join("part-01"), "step-gauge", 2, "1,0.5,3");
    simulate(&inbox.join("part-02"), "watch-plate", 3, "0,0,0");

    let mut h = started();
    h.get_by_label("Line").click();
    h.run_steps(2);
    assert!(shows(&h, "No parts yet"));
    {
        let app = h.state_mut();
        app.state.views.line.inbox = p(&inbox);
        app.state.views.line.recipe = p(&recipe);
        app.state.views.line.dfq_dir = p(&d.join("spc"));
        app.state.views.inspect.record.db = p(&d.join("records.sqlite"));
        app.state.views.inspect.record.station = "line 4".into();
        app.line_mut().program = env!("CARGO_BIN_EXE_sheen").into();
    }
    h.run_steps(1);
    h.get_by_label("Start").click();
    step_until(&mut h, "two parts", |app| app.line().parts().len() >= 2);
    let parts = h.state().line().parts().clone();
    assert_eq!(parts[0].part, "part-01");
    assert_eq!(parts[0].verdict(), Some(PartVerdict::Pass), "{:?}", parts[0]);
    assert_eq!(parts[1].verdict(), Some(PartVerdict::Error));
    let reason = parts[1].measured().and_then(|m| m.reason.as_deref());
    assert!(reason.is_some_and(|r| r.contains("part not found")), "{:?}", parts[1]);
    assert_eq!(h.state().line().map_part(), Some("part-01"), "the last measured part's map is shown");
    assert!(shows(&h, "ERROR") && shows(&h, "part not found") && shows(&h, "Last 2 parts"));

    // A part dropped in while the watch runs appears too.
    simulate(&d.join("staging"), "step-gauge", 4, "-1,-0.5,-4");
    std::fs::rename(d.join("staging"), inbox.join("part-03")).expect("drop the part");
    step_until(&mut h, "the third part", |app| app.line().parts().len() >= 3);
    let third = h.state().line().parts()[2].clone();
    assert_eq!((third.part.as_str(), third.verdict()), ("part-03", Some(PartVerdict::Pass)), "{third:?}");
    let step =
        third.measured().expect("measured").measurements.iter().find(|m| m.name == "step 200").expect("the step");
    assert!((step.value.expect("value") - 200.0).abs() < 5.0, "{step:?}");
    // The watch's line carries the step's U, and the table prints it.
    let u = step.expanded_uncertainty.expect("the step's U reaches the Line view");
    assert!(u > 0.0 && u < 1.0, "{step:?}");
    assert!(shows(&h, &format!("{:.3} ± {u:.3} um", step.value.expect("value"))), "value ± U in the table");
    assert_eq!(h.state().line().map_part(), Some("part-03"));
    assert!(shows(&h, "PASS") && shows(&h, "Trends"));
    assert_eq!(h.state().line().difference_part(), Some("part-03"));
    h.get_by_label("Difference to the reference").click();
    h.run_steps(2);
    assert!(h.state().state.views.line.show_difference);
    assert!(shows(&h, "part-03 less the aligned reference"));

    h.get_by_label("Stop").click();
    step_until(&mut h, "the watch to stop", |app| !app.line().is_running());
    assert_eq!(h.state().line().status().map(|s| s.1), Some(false), "{:?}", h.state().line().status());
    let location = sheen::records::DbLocation::Sqlite(d.join("records.sqlite"));
    let parts = sheen::records::Store::open(&location)
        .expect("open")
        .parts(&sheen::records::HistoryFilter::default())
        .expect("read");
    let ids: Vec<&str> = parts.iter().map(|p| p.record.part_id.as_str()).collect();
    assert_eq!(ids, ["part-01", "part-02", "part-03"]);
    // Each part's AQDEF file went to the folder the view names.
    let dfqs = std::fs::read_dir(d.join("spc")).expect("the AQDEF folder").count();
    assert_eq!(dfqs, 3, "one .dfq per part");
    assert!(parts.iter().all(|p| p.record.exports.len() == 1));
    assert!(parts.iter().all(|p| p.record.station.as_deref() == Some("line 4")));
}
