//! Issue 50, item 5: `sheen gauge` from a CSV and from the records, checked
//! against AIAG MSA's published Gage R&R example and a Type-1 hand
//! computation; bad studies refused with one line, nothing written.

use std::path::Path;
use std::process::{Command, Output};

use sheen::records::{DbLocation, MeasurementRecord, PartRecord, PartVerdict, Store};

use super::records::utc;

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run sheen")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// AIAG MSA 4th edition's example: appraisers A, B, C; trials; parts 1-10.
const MSA: [(&str, [[f64; 10]; 3]); 3] = [
    (
        "A",
        [
            [0.29, -0.56, 1.34, 0.47, -0.80, 0.02, 0.59, -0.31, 2.26, -1.36],
            [0.41, -0.68, 1.17, 0.50, -0.92, -0.11, 0.75, -0.20, 1.99, -1.25],
            [0.64, -0.58, 1.27, 0.64, -0.84, -0.21, 0.66, -0.17, 2.01, -1.31],
        ],
    ),
    (
        "B",
        [
            [0.08, -0.47, 1.19, 0.01, -0.56, -0.20, 0.47, -0.63, 1.80, -1.68],
            [0.25, -1.22, 0.94, 1.03, -1.20, 0.22, 0.55, 0.08, 2.12, -1.62],
            [0.07, -0.68, 1.34, 0.20, -1.28, 0.06, 0.83, -0.34, 2.19, -1.50],
        ],
    ),
    (
        "C",
        [
            [0.04, -1.38, 0.88, 0.14, -1.46, -0.29, 0.02, -0.46, 1.77, -1.49],
            [-0.11, -1.13, 1.09, 0.20, -1.07, -0.67, 0.01, -0.56, 1.45, -1.77],
            [-0.15, -0.96, 0.67, 0.11, -1.45, -0.49, 0.21, -0.49, 1.87, -2.16],
        ],
    ),
];

fn msa_csv() -> String {
    let mut text = String::from("part,operator,trial,value\n");
    for (operator, trials) in MSA {
        for (t, trial) in trials.iter().enumerate() {
            for (p, v) in trial.iter().enumerate() {
                text.push_str(&format!("{},{operator},{},{v}\n", p + 1, t + 1));
            }
        }
    }
    text
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("json written")).expect("json")
}

#[test]
fn gage_rr_from_a_csv_gives_the_msa_manuals_figures_both_ways() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("msa.csv");
    std::fs::write(&csv, msa_csv()).expect("csv");
    let out = dir.path().join("range.json");
    let html = dir.path().join("range.html");
    let pdf = dir.path().join("range.pdf");
    let o =
        sheen(&["gauge", "rr", s(&csv), "--method", "range", "--json", s(&out), "--html", s(&html), "--pdf", s(&pdf)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The page for the lab file: the verdict, the figures, every value.
    let page = std::fs::read_to_string(&html).expect("the HTML page");
    assert!(page.contains("CONDITIONALLY ACCEPTABLE · %GRR 26.7 % · ndc 5"), "{page}");
    assert!(page.contains("Gage R&amp;R (average and range)") && page.contains("Data (90 values)"));
    assert_eq!(page.matches("<tr><td class=\"num\">").count(), 90, "one row per value");
    assert!(page.contains("<td>C</td><td class=\"num\">-2.16</td>"), "the last value, appraiser C");
    // The same page as a PDF, read back by poppler where it is installed.
    let bytes = std::fs::read(&pdf).expect("the PDF");
    assert!(bytes.starts_with(b"%PDF-"));
    if let Ok(o) = std::process::Command::new("pdftotext").args(["-layout", s(&pdf), "-"]).output() {
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains("CONDITIONALLY ACCEPTABLE") && text.contains("Data (90 values)"), "{text}");
        assert!(text.contains("-2.16") && text.contains("ndc"), "{text}");
    } else {
        assert!(std::env::var("SHEEN_REQUIRE_POPPLER_TESTS").is_err(), "pdftotext is missing");
    }
    let v = json(&out);
    for (key, want) in [("ev", 0.20188), ("av", 0.22963), ("grr", 0.30575), ("pv", 1.10456), ("tv", 1.14610)] {
        let got = v[key].as_f64().expect(key);
        assert!((got - want).abs() < 6e-5, "{key}: {got} against the manual's {want}");
    }
    assert!((v["percent_grr"].as_f64().expect("%GRR") - 26.68).abs() < 0.006);
    assert_eq!(v["ndc"], 5);
    assert!(v["percent_tolerance"].is_null(), "no tolerance given");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("conditionally acceptable") && text.contains("ndc 5"), "{text}");

    let out = dir.path().join("anova.json");
    let o = sheen(&["gauge", "rr", s(&csv), "--tolerance", "6", "--json", s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&out);
    assert_eq!(v["method"], "anova");
    assert_eq!(v["anova"]["interaction_pooled"], true);
    assert_eq!(v["ndc"], 4);
    let grr = v["grr"].as_f64().expect("grr");
    assert!((v["percent_tolerance"].as_f64().expect("%T") - 100.0 * grr).abs() < 1e-9, "6 GRR / 6");
}

#[test]
fn a_type1_study_from_the_records_of_one_part() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = dir.path().join("records.sqlite");
    let mut store = Store::open(&DbLocation::Sqlite(db.clone())).expect("store");
    // 30 repeats of the reference step (xm = 250 um): 250.2 +- 0.3.
    let values: Vec<f64> = (0..30).map(|i| 250.2 + 0.3 * ((i * 7 % 11) as f64 - 5.0) / 5.0).collect();
    for (i, v) in values.iter().enumerate() {
        let mut r = PartRecord {
            part_id: "gauge-block".into(),
            recipe: "step-gauge".into(),
            time_utc: utc(&format!("2026-12-07T08:{:02}:00Z", i)),
            station: None,
            operator: Some("ana".into()),
            input_path: "in.json".into(),
            input_hash: None,
            sheen_version: "0.1.0".into(),
            engine_parameters: None,
            inspection: None,
            verdict: PartVerdict::Pass,
            reason: None,
            height_map_path: None,
            height_map_hash: None,
            decision_rule: None,
            exports: Vec::new(),
            measurements: Vec::new(),
        };
        r.measurements.push(MeasurementRecord {
            name: "step 250".into(),
            kind: "step_height".into(),
            parameter: None,
            value: Some(*v),
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
        });
        store.insert(&r).expect("record");
    }
    drop(store);
    let out = dir.path().join("type1.json");
    let o = sheen(&[
        "gauge",
        "type1",
        "--db",
        s(&db),
        "--recipe",
        "step-gauge",
        "--measurement",
        "step 250",
        "--reference",
        "250",
        "--tolerance",
        "20",
        "--json",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&out);
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let sd = (values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert_eq!(v["n"], 30);
    for (key, want) in [
        ("mean", mean),
        ("s", sd),
        ("bias", mean - 250.0),
        ("cg", 0.2 * 20.0 / (6.0 * sd)),
        ("cgk", (0.1 * 20.0 - (mean - 250.0).abs()) / (3.0 * sd)),
    ] {
        assert!((v[key].as_f64().expect(key) - want).abs() < 1e-9, "{key}: {} against {want}", v[key]);
    }
    assert_eq!(v["capable"], (0.2 * 20.0 / (6.0 * sd) >= 1.33 && (2.0 - (mean - 250.0).abs()) / (3.0 * sd) >= 1.33));
}

#[test]
fn bad_studies_are_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out.json");
    let few = dir.path().join("few.csv");
    std::fs::write(&few, "value\n1\n2\n3\n").expect("csv");
    let text = dir.path().join("text.csv");
    std::fs::write(&text, "part,operator,trial,value\n1,A,1,0.5\n1,A,2,abc\n").expect("csv");
    let unbalanced = dir.path().join("unbalanced.csv");
    let mut lines: Vec<&str> = Vec::new();
    let full = msa_csv();
    lines.extend(full.lines().take(full.lines().count() - 1));
    std::fs::write(&unbalanced, lines.join("\n")).expect("csv");
    for (args, expected) in [
        (vec!["type1", s(&few), "--reference", "2", "--tolerance", "1"], "at least 25 repeats"),
        (vec!["rr", s(&text)], "line 3: value 'abc' is not a number"),
        (vec!["rr", s(&unbalanced)], "unbalanced"),
        (
            vec!["rr", "--recipe", "r", "--measurement", "m", "--db", s(&dir.path().join("none.sqlite"))],
            "no records database",
        ),
    ] {
        let mut argv = vec!["gauge"];
        argv.extend(args.iter().copied());
        argv.extend(["--json", s(&out)]);
        let o = sheen(&argv);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{argv:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(expected), "{argv:?}: {err}");
        assert!(!out.exists(), "nothing written");
    }
}
