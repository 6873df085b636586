//! The AQDEF writer read back by a test reader that also reads Q-DAS's own
//! files (tests/data/aqdef): layout, index, limits, invalid values, text.

use std::collections::BTreeMap;

use chrono::{DateTime, Local, Utc};

use super::*;
use crate::analysis::measurement_table::{DecisionRule, PartVerdict};
use crate::analysis::uncertainty::{Contribution, Uncertainty, UncertaintyMethod};

type Fields = BTreeMap<String, String>;

/// A DFQ file as its K-fields say, read the way the format's users write
/// it: coded `Kxxxx/i` lines and Q-DAS's own value lines (fields separated
/// by 0x14, characteristics by 0x0F).
#[derive(Debug, Default)]
struct Dfq {
    count: Option<usize>,
    parts: BTreeMap<usize, Fields>,
    characteristics: BTreeMap<usize, Characteristic>,
}

#[derive(Debug, Default)]
struct Characteristic {
    part: usize,
    fields: Fields,
    values: Vec<Fields>,
}

fn read_dfq(bytes: &[u8]) -> Dfq {
    let text: String = bytes.iter().map(|&b| b as char).collect();
    assert!(text.ends_with("\r\n"), "the file ends with CRLF");
    let mut dfq = Dfq::default();
    let mut part = 0;
    for line in text.split_terminator("\r\n") {
        assert!(!line.contains('\n') && !line.contains('\r'), "a bare line break in {line:?}");
        if line.is_empty() {
            continue;
        }
        if !line.starts_with('K') {
            // Q-DAS's value line: one group per characteristic of the part.
            let first = dfq.characteristics.iter().find(|(_, c)| c.part == part).map_or(1, |(i, _)| *i);
            for (offset, group) in line.split('\u{0f}').enumerate() {
                let f: Vec<&str> = group.split('\u{14}').collect();
                let mut value = Fields::new();
                value.insert("K0001".into(), f[0].trim().into());
                value.insert("K0002".into(), f.get(1).unwrap_or(&"0").trim().into());
                value.insert("K0004".into(), f.get(2).unwrap_or(&"").trim().into());
                dfq.characteristics.entry(first + offset).or_default().values.push(value);
            }
            continue;
        }
        let (code, value) = line.split_once(' ').unwrap_or((line, ""));
        let (key, index) = match code.split_once('/') {
            Some((k, i)) => (k, Some(i.parse::<usize>().expect("a numeric index"))),
            None => (code, None),
        };
        assert_eq!(key.len(), 5, "K-field {key}");
        match (&key[..2], index) {
            ("K0", None) if key == "K0100" => dfq.count = Some(value.parse().unwrap()),
            ("K0", None) => {}
            ("K1", Some(p)) => {
                part = p;
                dfq.parts.entry(p).or_default().insert(key.into(), value.into());
            }
            ("K2", Some(i)) => {
                let c = dfq.characteristics.entry(i).or_default();
                c.part = part;
                c.fields.insert(key.into(), value.into());
            }
            ("K0", Some(i)) => {
                let c = dfq
                    .characteristics
                    .get_mut(&i)
                    .unwrap_or_else(|| panic!("a value of undefined characteristic {i}"));
                if key == "K0001" {
                    c.values.push(Fields::new());
                }
                c.values.last_mut().expect("K0001 first").insert(key.into(), value.into());
            }
            _ => {}
        }
    }
    dfq
}

fn time(text: &str) -> DateTime<Utc> {
    DateTime::parse_from_rfc3339(text).unwrap().with_timezone(&Utc)
}

fn step(value: Option<f64>, limits: (f64, f64)) -> MeasurementRecord {
    let mut m = MeasurementRecord::bare("step A–B", "step_height", value.unwrap_or(0.0), "um");
    m.value = value;
    m.nominal = Some(12.0);
    (m.lower_limit, m.upper_limit) = (Some(limits.0), Some(limits.1));
    m.verdict = value.map(|_| Verdict::Pass);
    m.decision_rule = Some(DecisionRule::Iso14253);
    m.uncertainty =
        Some(Uncertainty::from_budget(UncertaintyMethod::Propagation, vec![Contribution::new("noise", 0.0617)]));
    m
}

fn flatness(value: f64) -> MeasurementRecord {
    let mut m = MeasurementRecord::bare("plate", "flatness_peak_to_valley", value, "um");
    m.upper_limit = Some(5.0);
    m.verdict = Some(Verdict::Inconclusive);
    m
}

fn part(id: &str, at: &str, measurements: Vec<MeasurementRecord>) -> ExchangePart {
    ExchangePart {
        part_id: id.into(),
        part_number: "watch plate".into(),
        description: Some("Sheen recipe watch plate".into()),
        operation: Some("OP 40".into()),
        time_utc: time(at),
        station: Some("line 3".into()),
        operator: Some("Zoë\u{14}Ng 張".into()),
        gauge: ExchangePart::gauge_name("1.2.0", Some("rig-7.json")),
        verdict: PartVerdict::Pass,
        reason: None,
        measurements,
    }
}

#[test]
fn a_history_writes_each_value_under_the_limits_it_was_judged_against() {
    let parts = vec![
        part("p1", "2026-12-17T08:00:00Z", vec![step(Some(12.03), (11.5, 12.5)), flatness(4.2)]),
        part("p2", "2026-12-17T08:00:02Z", vec![step(Some(11.97), (11.5, 12.5)), flatness(3.1)]),
        // The recipe's tolerance tightened: a new block.
        part("p3", "2026-12-17T09:00:00Z", vec![step(Some(12.01), (11.8, 12.2)), flatness(2.0)]),
    ];
    let bytes = dfq_bytes(&parts);
    let dfq = read_dfq(&bytes);
    assert_eq!(dfq.count, Some(4), "K0100 counts the characteristics of the file");
    assert_eq!(dfq.characteristics.keys().copied().collect::<Vec<_>>(), vec![1, 2, 3, 4], "one index across the file");
    assert_eq!(dfq.parts.len(), 2);
    assert_eq!(dfq.parts[&1]["K1001"], "watch plate");
    assert_eq!(dfq.parts[&1]["K1086"], "OP 40");

    let old = &dfq.characteristics[&1];
    assert_eq!((old.part, old.fields["K2110"].as_str(), old.fields["K2111"].as_str()), (1, "11.500000", "12.500000"));
    assert_eq!(old.fields["K2101"], "12.000000");
    assert_eq!(old.fields["K2002"], "step A?B", "a character Latin-1 cannot hold is replaced");
    assert_eq!(old.fields["K2142"], "um");
    assert_eq!((old.fields["K2004"].as_str(), old.fields["K2022"].as_str()), ("0", "3"), "variable, 3 decimals in um");
    assert_eq!(old.values.iter().map(|v| v["K0001"].as_str()).collect::<Vec<_>>(), ["12.030000", "11.970000"]);
    let new = &dfq.characteristics[&3];
    assert_eq!((new.part, new.fields["K2110"].as_str(), new.fields["K2111"].as_str()), (2, "11.800000", "12.200000"));
    assert_eq!(new.values.len(), 1);
    assert_eq!(new.values[0]["K0014"], "p3");
    assert_eq!(new.values[0]["K0006"], "p3");

    let flat = &dfq.characteristics[&2];
    assert!(!flat.fields.contains_key("K2110"), "a <= limit has no lower limit");
    assert_eq!(flat.fields["K2111"], "5.000000");
    assert_eq!(flat.values[0]["K0009"], "inconclusive");

    let v = &old.values[0];
    let local = time("2026-12-17T08:00:00Z").with_timezone(&Local).format("%d.%m.%Y/%H:%M:%S").to_string();
    assert_eq!(v["K0004"], local);
    assert_eq!(v["K0002"], "0");
    assert_eq!(v["K0008"], "Zoë Ng ?", "the field separator and a non-Latin-1 character are replaced");
    assert_eq!(v["K0010"], "line 3");
    assert_eq!(v["K0012"], "Sheen 1.2.0 / rig-7.json");
    assert_eq!(v["K0009"], "U=0.12 um k=2; rule iso-14253-1");
    // Latin-1: the operator's ë is one byte.
    assert!(bytes.windows(3).any(|w| w == b"Zo\xeb"));
}

#[test]
fn a_part_in_error_is_written_as_invalid_values() {
    let mut error = part("p9", "2026-12-17T10:00:00Z", Vec::new());
    error.verdict = PartVerdict::Error;
    error.reason = Some("image pat03.png is truncated".into());
    let template = [step(Some(12.0), (11.5, 12.5))];
    let mut with_template = error.clone();
    with_template.not_measured_like(&template);
    let measured = part("p8", "2026-12-17T09:59:58Z", template.to_vec());

    let dfq = read_dfq(&dfq_bytes(&[measured, with_template]));
    assert_eq!(dfq.count, Some(1), "the error part joins its recipe's block");
    let values = &dfq.characteristics[&1].values;
    assert_eq!(values.len(), 2);
    assert_eq!(values[1]["K0002"], INVALID_VALUE_ATTRIBUTE.to_string());
    assert_eq!(values[1]["K0014"], "p9");
    assert_eq!(values[1]["K0009"], "not measured: image pat03.png is truncated");

    // Nothing of its recipe was ever measured: one placeholder characteristic.
    let alone = read_dfq(&dfq_bytes(&[error]));
    assert_eq!(alone.count, Some(1));
    assert_eq!(alone.characteristics[&1].fields["K2002"], NOT_MEASURED);
    assert_eq!(alone.characteristics[&1].values[0]["K0002"], "255");
}

#[test]
fn a_part_without_tolerances_still_exports_its_values() {
    let mut m = MeasurementRecord::bare("plate", "flatness_rms", 0.8123, "um");
    m.note = Some("rms".into());
    let dfq = read_dfq(&dfq_bytes(&[part("p1", "2026-12-17T08:00:00Z", vec![m])]));
    let c = &dfq.characteristics[&1];
    assert!(!c.fields.contains_key("K2110") && !c.fields.contains_key("K2111") && !c.fields.contains_key("K2101"));
    assert_eq!(c.values[0]["K0001"], "0.812300");
}

#[test]
fn text_fields_are_cut_to_their_k_field() {
    let long = "x".repeat(100);
    assert_eq!(field(&long, 40).len(), 40);
    assert_eq!(field(" a\r\nb\u{0f}c ", 40), "a  b c");
}

/// Q-DAS's own files (tests/data/aqdef, written by Q-DAS software) parse
/// with the reader the tests above use: the layout Sheen writes is the
/// layout the format's users write.
#[test]
fn real_qdas_files_read_with_the_same_reader() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/aqdef");
    let type1 = read_dfq(&std::fs::read(dir.join("BOSCH_BOOKLET10_TYPE_1.dfq")).unwrap());
    assert_eq!(type1.count, Some(1));
    let c = &type1.characteristics[&1];
    assert_eq!(
        (c.fields["K2101"].as_str(), c.fields["K2110"].as_str(), c.fields["K2111"].as_str()),
        ("6.000", "5.97000", "6.03000")
    );
    assert_eq!(c.fields["K2142"], "mm");
    assert_eq!(c.values.len(), 50);
    let first: f64 = c.values[0]["K0001"].parse().unwrap();
    assert!((5.97..=6.03).contains(&first));
    assert!(c.values.iter().all(|v| v["K0004"].len() == "06.09.2002/12:51:30".len()));
    assert!(c.values.iter().all(|v| v.contains_key("K0097")), "each value's GUID line follows it");

    let rr = read_dfq(&std::fs::read(dir.join("GC_AIAG.DFQ")).unwrap());
    let c = &rr.characteristics[&1];
    assert_eq!((c.fields["K2110"].as_str(), c.fields["K2111"].as_str()), ("0.60", "1.00"));
    assert_eq!(c.values.len(), 60, "10 parts x 3 appraisers x 2 trials");
}

#[test]
fn numbers_are_plain_decimals_with_three_digits_below_the_shown_ones() {
    assert_eq!(number(12.0, 3), "12.000000");
    assert_eq!(number(-0.0000001, 3), "0.000000");
    assert_eq!(number(-1.5, 4), "-1.5000000");
    assert_eq!(significant(0.01234), "0.012");
    assert_eq!(significant(1.234), "1.2");
    assert_eq!(significant(123.4), "123");
}
