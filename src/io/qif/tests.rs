//! The QIF writer checked by xmllint against the QIF 3.0 schemas and read
//! back with quick-xml, for every kind of measurement and every verdict.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use chrono::{DateTime, Utc};
use quick_xml::events::Event;

use super::*;
use crate::analysis::measurement_table::DecisionRule;
use crate::analysis::uncertainty::{Contribution, Uncertainty, UncertaintyMethod};

/// The QIF 3.0 schemas, laid out for validation without a network.
pub(crate) fn schema() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/qif-3.0/QIFApplications/QIFDocument.xsd")
}

/// `xmllint --noout --nonet --schema` on a document; `None` where xmllint
/// is missing (a bare machine; CI sets SHEEN_REQUIRE_XMLLINT_TESTS and
/// installs it, so there it must run).
pub(crate) fn validate(document: &str) -> Option<Result<(), String>> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("part.qif");
    std::fs::write(&path, document).unwrap();
    let output = match std::process::Command::new("xmllint")
        .args(["--noout", "--nonet", "--schema"])
        .arg(schema())
        .arg(&path)
        .output()
    {
        Ok(o) => o,
        Err(_) => {
            assert!(
                std::env::var("SHEEN_REQUIRE_XMLLINT_TESTS").is_err(),
                "SHEEN_REQUIRE_XMLLINT_TESTS is set but xmllint is missing (apt-get install libxml2-utils)"
            );
            eprintln!("xmllint not found: QIF schema validation skipped");
            return None;
        }
    };
    Some(if output.status.success() { Ok(()) } else { Err(String::from_utf8_lossy(&output.stderr).into_owned()) })
}

fn uncertain(u: f64) -> Option<Uncertainty> {
    Some(Uncertainty::from_budget(UncertaintyMethod::Propagation, vec![Contribution::new("noise", u)]))
}

fn row(name: &str, kind: &str, parameter: Option<&str>, value: f64, unit: &str) -> MeasurementRecord {
    let mut m = MeasurementRecord::bare(name, kind, value, unit);
    m.parameter = parameter.map(Into::into);
    m.uncertainty = uncertain(value.abs() * 0.01 + 0.001);
    m
}

fn judged(mut m: MeasurementRecord, lower: Option<f64>, upper: Option<f64>, verdict: Verdict) -> MeasurementRecord {
    (m.lower_limit, m.upper_limit, m.verdict) = (lower, upper, Some(verdict));
    m.decision_rule = Some(DecisionRule::Iso14253);
    m
}

/// A part with every kind of measurement Sheen makes.
pub(crate) fn every_kind() -> ExchangePart {
    let mut step =
        judged(row("step A<B & \"C\"", "step_height", None, 12.034, "um"), Some(11.5), Some(12.5), Verdict::Pass);
    step.nominal = Some(12.0);
    let measurements = vec![
        step,
        judged(row("plate PV", "flatness_peak_to_valley", None, 4.9, "um"), None, Some(5.0), Verdict::Inconclusive),
        row("plate RMS", "flatness_rms", None, 0.8, "um"),
        judged(row("lands", "coplanarity", None, 0.0123, "mm"), None, Some(0.02), Verdict::Pass),
        row("land 1", "land_deviation", None, 0.004, "mm"),
        judged(row("plate tilt", "plane_tilt", None, 0.25, "deg"), Some(-1.0), Some(1.0), Verdict::Pass),
        judged(row("dial Sa", "texture", Some("Sa"), 0.41, "um"), None, Some(0.8), Verdict::Pass),
        row("dial Sq", "texture", Some("Sq"), 0.52, "um"),
        row("dial Ssk", "texture", Some("Ssk"), -0.3, ""),
        judged(row("dial Sdr", "texture", Some("Sdr"), 3.1, "%"), None, Some(5.0), Verdict::Fail),
        judged(row("section 1 Ra", "profile_texture", Some("Ra"), 0.35, "um"), None, Some(0.4), Verdict::Pass),
        row("alignment score", "alignment", None, 0.97, ""),
    ];
    ExchangePart {
        part_id: "W-0042\u{1}".into(),
        part_number: "watch plate".into(),
        description: None,
        operation: None,
        time_utc: DateTime::parse_from_rfc3339("2026-12-17T08:00:00.250Z").unwrap().with_timezone(&Utc),
        station: Some("line 3".into()),
        operator: Some("A. N. Operator".into()),
        gauge: ExchangePart::gauge_name("1.2.0", Some("rig.json")),
        verdict: PartVerdict::Fail,
        reason: Some("out of tolerance: dial Sdr".into()),
        measurements,
    }
}

/// What an XML reader finds: each element's text and attributes by path.
#[derive(Debug, Default)]
pub(crate) struct Read {
    pub elements: Vec<(String, BTreeMap<String, String>, String)>,
}

impl Read {
    pub fn all<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a (String, BTreeMap<String, String>, String)> {
        self.elements.iter().filter(move |(path, _, _)| path.ends_with(&format!("/{name}")))
    }
}

pub(crate) fn read(document: &str) -> Read {
    let mut reader = quick_xml::Reader::from_str(document);
    let mut path: Vec<String> = Vec::new();
    let mut out = Read::default();
    let mut open: Vec<usize> = Vec::new();
    loop {
        let event = reader.read_event().expect("well-formed XML");
        let (start, empty) = match &event {
            Event::Start(e) => (Some(e.clone()), false),
            Event::Empty(e) => (Some(e.clone()), true),
            _ => (None, false),
        };
        if let Some(e) = start {
            let name = String::from_utf8(e.name().as_ref().to_vec()).unwrap();
            let attributes = e
                .attributes()
                .map(|a| {
                    let a = a.unwrap();
                    let raw = String::from_utf8_lossy(&a.value).into_owned();
                    (
                        String::from_utf8(a.key.as_ref().to_vec()).unwrap(),
                        quick_xml::escape::unescape(&raw).unwrap().into_owned(),
                    )
                })
                .collect();
            path.push(name);
            out.elements.push((format!("/{}", path.join("/")), attributes, String::new()));
            if empty {
                path.pop();
            } else {
                open.push(out.elements.len() - 1);
            }
            continue;
        }
        match event {
            Event::Text(t) => {
                if let Some(&i) = open.last() {
                    out.elements[i].2.push_str(&t.decode().unwrap());
                }
            }
            Event::GeneralRef(r) => {
                if let Some(&i) = open.last() {
                    out.elements[i].2.push_str(&format!("&{};", r.decode().unwrap()));
                }
            }
            Event::End(_) => {
                path.pop();
                if let Some(i) = open.pop() {
                    out.elements[i].2 = quick_xml::escape::unescape(&out.elements[i].2).unwrap().into_owned();
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    out
}

fn check(document: &str) {
    if let Some(result) = validate(document) {
        result.unwrap_or_else(|e| panic!("schema-invalid QIF:\n{e}\n{document}"));
    }
}

#[test]
fn a_part_with_every_kind_of_measurement_is_valid_qif_and_reads_back() {
    let part = every_kind();
    let document = qif_document(&part, "1.2.0");
    check(&document);
    let r = read(&document);
    let root = &r.elements[0];
    assert_eq!((root.0.as_str(), root.1["versionQIF"].as_str()), ("/QIFDocument", "3.0.0"));
    assert_eq!(r.all("Application").count(), 1);
    assert_eq!(r.elements.iter().find(|(p, _, _)| p.ends_with("Application/Name")).expect("name").2, "Sheen");
    assert_eq!(
        r.elements.iter().find(|(p, _, _)| p.ends_with("Application/Organization")).expect("version").2,
        "Sheen 1.2.0"
    );
    let linear = r.elements.iter().find(|(p, _, _)| p.ends_with("PrimaryUnits/LinearUnit/UnitName")).expect("unit");
    assert_eq!(linear.2, "mm", "FileUnits in mm");
    // idMax is the largest id.
    let max_id = r.elements.iter().filter_map(|(_, a, _)| a.get("id")?.parse::<u64>().ok()).max().unwrap();
    assert_eq!(root.1["idMax"], max_id.to_string());
    // Every n= counts its children.
    for (i, (path, attributes, _)) in r.elements.iter().enumerate() {
        if let Some(n) = attributes.get("n") {
            let depth = path.matches('/').count();
            let children = r.elements[i + 1..]
                .iter()
                .take_while(|(p, _, _)| p.starts_with(&format!("{path}/")))
                .filter(|(p, _, _)| p.matches('/').count() == depth + 1)
                .count();
            assert_eq!(n, &children.to_string(), "{path}");
        }
    }
    let measured: Vec<&(String, BTreeMap<String, String>, String)> =
        r.elements.iter().filter(|(p, _, _)| p.ends_with("CharacteristicMeasurement")).collect();
    let names: Vec<&str> = measured.iter().map(|(p, _, _)| p.rsplit('/').next().unwrap()).collect();
    assert_eq!(
        names,
        [
            "HeightCharacteristicMeasurement",
            "FlatnessCharacteristicMeasurement",
            "UserDefinedLinearCharacteristicMeasurement",
            "UserDefinedLinearCharacteristicMeasurement",
            "UserDefinedLinearCharacteristicMeasurement",
            "UserDefinedAngularCharacteristicMeasurement",
            "SurfaceTextureCharacteristicMeasurement",
            "UserDefinedLinearCharacteristicMeasurement",
            "UserDefinedUnitCharacteristicMeasurement",
            "SurfaceTextureCharacteristicMeasurement",
        ]
    );
    // Values, uncertainties and units as measured.
    let values: Vec<(f64, Option<&String>, Option<&String>)> = r
        .elements
        .iter()
        .filter(|(p, _, _)| p.ends_with("CharacteristicMeasurement/Value") || p.ends_with("/RoughnessAverageValue"))
        .map(|(_, a, t)| (t.parse().unwrap(), a.get("linearUnit"), a.get("combinedUncertainty")))
        .collect();
    let expected: Vec<&MeasurementRecord> =
        part.measurements.iter().filter(|m| QifKind::of(m) != QifKind::ResultAttribute).collect();
    assert_eq!(values.len(), expected.len());
    for ((v, unit, u), m) in values.iter().zip(&expected) {
        assert_eq!(*v, m.value.unwrap(), "{}", m.name);
        assert_eq!(unit.map(String::as_str), (m.unit == "um").then_some("um"), "{}", m.name);
        let u: f64 = u.unwrap().parse().unwrap();
        assert_eq!(u, m.uncertainty.as_ref().unwrap().u, "{}", m.name);
    }
    let statuses: Vec<&str> = r.all("CharacteristicStatusEnum").map(|(_, _, t)| t.as_str()).collect();
    assert_eq!(
        statuses,
        [
            "PASS",
            "INDETERMINATE",
            "NOT_ANALYZED",
            "PASS",
            "NOT_ANALYZED",
            "PASS",
            "PASS",
            "NOT_ANALYZED",
            "FAIL",
            "PASS"
        ]
    );
    // The limits: the step's absolute, the flatness's tolerance zone.
    let step_def = r.elements.iter().position(|(p, _, _)| p.ends_with("HeightCharacteristicDefinition")).unwrap();
    let max = r.elements[step_def..].iter().find(|(p, _, _)| p.ends_with("Tolerance/MaxValue")).unwrap();
    let min = r.elements[step_def..].iter().find(|(p, _, _)| p.ends_with("Tolerance/MinValue")).unwrap();
    assert_eq!((max.2.as_str(), min.2.as_str()), ("12.5", "11.5"));
    assert_eq!(r.all("TargetValue").next().unwrap().2, "12");
    assert_eq!(r.all("ToleranceValue").next().unwrap().2, "5");
    assert_eq!(r.all("RoughnessAverage").next().unwrap().2, "0.8");
    // The untoleranced unitless values are results' attributes.
    let attributes: BTreeMap<&str, &str> = r
        .elements
        .iter()
        .filter(|(p, _, _)| p.starts_with("/QIFDocument/Results/MeasurementResultsSet/MeasurementResults/Attributes/"))
        .map(|(_, a, _)| (a["name"].as_str(), a["value"].as_str()))
        .collect();
    assert_eq!(attributes["dial Ssk"], "-0.3");
    assert_eq!(attributes["alignment score"], "0.97");
    assert_eq!(attributes["sheen_verdict"], "fail");
    // The part: serial (a control character replaced), status, operator.
    assert_eq!(r.all("SerialNumber").next().unwrap().2, "W-0042?");
    assert_eq!(r.all("InspectionStatusEnum").next().unwrap().2, "FAIL");
    assert_eq!(r.all("InspectionOperator").count(), 1);
    assert_eq!(r.all("Description").find(|(_, _, t)| t.starts_with("step")).unwrap().2, "step A<B & \"C\"");
}

#[test]
fn passed_inconclusive_and_unmeasured_parts_are_valid_qif() {
    let mut part = every_kind();
    for verdict in [PartVerdict::Pass, PartVerdict::Inconclusive] {
        part.verdict = verdict;
        let document = qif_document(&part, "1.2.0");
        check(&document);
        let expected = if verdict == PartVerdict::Pass { "PASS" } else { "UNKNOWN" };
        assert_eq!(read(&document).all("InspectionStatusEnum").next().unwrap().2, expected);
    }
    // A part in error, its recipe's characteristics without values.
    let template = part.measurements.clone();
    let mut error = every_kind();
    error.verdict = PartVerdict::Error;
    error.reason = Some("image pat03.png is truncated".into());
    error.measurements.clear();
    error.not_measured_like(&template);
    let document = qif_document(&error, "1.2.0");
    check(&document);
    let r = read(&document);
    assert!(r.all("CharacteristicStatusEnum").all(|(_, _, t)| t == "SYSERROR"));
    assert_eq!(r.all("Value").count() + r.all("RoughnessAverageValue").count(), 0);
    assert_eq!(r.all("InspectionStatusEnum").next().unwrap().2, "SYSERROR");
    // And one with no characteristic at all.
    error.measurements.clear();
    let document = qif_document(&error, "1.2.0");
    check(&document);
    assert_eq!(read(&document).all("Characteristics").count(), 0);
}

#[test]
fn a_dangling_reference_is_refused_by_the_schema_check() {
    // The check the tests rely on does refuse a broken chain.
    let document =
        qif_document(&every_kind(), "1.2.0").replacen("<CharacteristicItemId>", "<CharacteristicItemId>9", 1);
    if let Some(result) = validate(&document) {
        assert!(result.is_err(), "xmllint accepted a measurement of a missing item");
    }
}

#[test]
fn qpids_are_uuids_and_follow_the_part() {
    let a = qpid(&every_kind().digest(), 0);
    assert_eq!(a.len(), 36);
    assert_eq!(&a[14..15], "5");
    assert_ne!(a, qpid(&every_kind().digest(), 1));
}
