//! Parts as a Q-DAS AQDEF transfer file (`.dfq`), the ASCII format that
//! qs-STAT, O-QIS, procella and most CAQ systems read.
//!
//! Layout, as Q-DAS software writes it (the files in `tests/data/aqdef/`):
//! `K0100` (characteristics in the file) first; then one block per part
//! number and set of characteristic definitions: the part lines `K1001/p`
//! (part number: the recipe), `K1002/p` (description), `K1086/p`
//! (operation), its characteristics `K2001/i` (number), `K2002/i`
//! (description), `K2004/i` (0: variable), `K2022/i` (decimal places),
//! `K2101/i` (nominal), `K2110/i` / `K2111/i` (lower / upper limit, each
//! only where set), `K2142/i` (unit), and after them one value record per
//! part and characteristic: `K0001/i` (value), `K0002/i` (attribute),
//! `K0004/i` (date/time, `dd.MM.yyyy/HH:mm:ss`, local time), `K0006/i` and
//! `K0014/i` (the part's serial), `K0008/i` (operator), `K0009/i` (text:
//! the expanded uncertainty, the decision rule and a verdict Q-DAS cannot
//! hold), `K0010/i` (station), `K0012/i` (gauge: Sheen and the rig's
//! calibration). The index `i` numbers characteristics across the file.
//!
//! A history whose tolerances changed gets a new block for the values judged
//! against the new limits, so every value keeps the limits it was judged
//! against. A value that could not be measured (a part in error) is written
//! as Q-DAS marks an invalid value: `K0001 0` with attribute `K0002 255`,
//! and the reason in `K0009`. A part with no characteristic at all (an
//! error before any part of its recipe was measured) gets one
//! characteristic, "not measured", so it is in the file.
//!
//! Encoding: ISO 8859-1 (Latin-1, what Q-DAS reads without a byte-order
//! mark), CRLF line ends. Text fields lose what the format cannot hold:
//! control characters (the format's field separators 0x0F and 0x14, line
//! breaks) become spaces, characters outside Latin-1 become `?`, and each
//! field is cut to its K-field's length (K1001 40, K2001 20, K2002 80,
//! K0006 and K0014 40, K0008 and K0010 40, K0012 80, K0009 255
//! characters). Units are written in ASCII as Sheen names them (`um`,
//! `mm`, `deg`), so a reader that guesses the encoding (Python's chardet
//! does) cannot misread a `µ`.
//!
//! The expanded uncertainty has no K-field of its own: it is written as
//! text in `K0009` (`U=0.12 um k=2`), not as a number Q-DAS computes with.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use chrono::Local;

use crate::analysis::measurement_record::MeasurementRecord;
use crate::analysis::measurement_table::Verdict;

use super::IoError;
use super::exchange::{ExchangePart, characteristic_description, write_exchange_file};

/// The attribute Q-DAS gives an invalid value (`K0002`).
pub const INVALID_VALUE_ATTRIBUTE: u32 = 255;

/// The description of the one characteristic a part without any gets.
pub const NOT_MEASURED: &str = "not measured";

/// Writes `parts` as one `.dfq` file, atomically.
pub fn write_dfq(path: &Path, parts: &[ExchangePart]) -> Result<(), IoError> {
    write_exchange_file(path, &dfq_bytes(parts))
}

/// The `.dfq` file of `parts` (Latin-1 bytes, CRLF line ends).
pub fn dfq_bytes(parts: &[ExchangePart]) -> Vec<u8> {
    let blocks = blocks_of(parts);
    let characteristics: usize = blocks.iter().map(|b| b.characteristics().len()).sum();
    let mut text = String::with_capacity(256 + parts.len() * 64 * 8);
    line(&mut text, "K0100", None, &characteristics.to_string());
    let mut first_index = 1;
    for (p, block) in blocks.iter().enumerate() {
        write_block(&mut text, p + 1, first_index, block);
        first_index += block.characteristics().len();
    }
    latin1(&text)
}

/// Parts of one part number measured against the same characteristic
/// definitions (the same names, units, nominals and limits, in order).
/// Each part with its values; the first part's describe the block (the
/// others' share their definitions).
struct Block<'a> {
    parts: Vec<(&'a ExchangePart, Vec<&'a MeasurementRecord>)>,
}

impl<'a> Block<'a> {
    fn first(&self) -> &'a ExchangePart {
        self.parts[0].0
    }

    fn characteristics(&self) -> &[&'a MeasurementRecord] {
        &self.parts[0].1
    }
}

/// The placeholder characteristic of a part that has none.
fn not_measured_record() -> &'static MeasurementRecord {
    static RECORD: std::sync::OnceLock<MeasurementRecord> = std::sync::OnceLock::new();
    RECORD.get_or_init(|| MeasurementRecord::unmeasured(NOT_MEASURED, "", ""))
}

fn characteristics_of(part: &ExchangePart) -> Vec<&MeasurementRecord> {
    if part.measurements.is_empty() { vec![not_measured_record()] } else { part.measurements.iter().collect() }
}

type Definition = (String, String, u64, u64, u64);

fn definition(m: &MeasurementRecord) -> Definition {
    let bits = |v: Option<f64>| v.map_or(u64::MAX, f64::to_bits);
    (characteristic_description(m), m.unit.clone(), bits(m.nominal), bits(m.lower_limit), bits(m.upper_limit))
}

/// Groups parts into blocks in the order their first part appears.
fn blocks_of(parts: &[ExchangePart]) -> Vec<Block<'_>> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut by_key: HashMap<(String, Vec<Definition>), usize> = HashMap::new();
    for part in parts {
        let values = characteristics_of(part);
        let key = (part.part_number.clone(), values.iter().map(|m| definition(m)).collect());
        let index = *by_key.entry(key).or_insert_with(|| {
            blocks.push(Block { parts: Vec::new() });
            blocks.len() - 1
        });
        blocks[index].parts.push((part, values));
    }
    blocks
}

fn write_block(text: &mut String, p: usize, first_index: usize, block: &Block) {
    let part = block.first();
    line(text, "K1001", Some(p), &field(&part.part_number, 40));
    if let Some(d) = &part.description {
        line(text, "K1002", Some(p), &field(d, 80));
    }
    if let Some(op) = &part.operation {
        line(text, "K1086", Some(p), &field(op, 40));
    }
    for (offset, m) in block.characteristics().iter().enumerate() {
        let i = first_index + offset;
        let decimals = decimal_places(&m.unit);
        line(text, "K2001", Some(i), &(offset + 1).to_string());
        line(text, "K2002", Some(i), &field(&characteristic_description(m), 80));
        line(text, "K2004", Some(i), "0");
        line(text, "K2022", Some(i), &decimals.to_string());
        if let Some(nominal) = m.nominal {
            line(text, "K2101", Some(i), &number(nominal, decimals));
        }
        if let Some(lower) = m.lower_limit {
            line(text, "K2110", Some(i), &number(lower, decimals));
        }
        if let Some(upper) = m.upper_limit {
            line(text, "K2111", Some(i), &number(upper, decimals));
        }
        if !m.unit.is_empty() {
            line(text, "K2142", Some(i), &field(&m.unit, 20));
        }
    }
    for (part, values) in &block.parts {
        let time = part.time_utc.with_timezone(&Local).format("%d.%m.%Y/%H:%M:%S").to_string();
        for (offset, m) in values.iter().enumerate() {
            let i = first_index + offset;
            let decimals = decimal_places(&m.unit);
            match m.value {
                Some(v) => {
                    line(text, "K0001", Some(i), &number(v, decimals));
                    line(text, "K0002", Some(i), "0");
                }
                None => {
                    line(text, "K0001", Some(i), "0");
                    line(text, "K0002", Some(i), &INVALID_VALUE_ATTRIBUTE.to_string());
                }
            }
            line(text, "K0004", Some(i), &time);
            line(text, "K0006", Some(i), &field(&part.part_id, 40));
            if let Some(operator) = &part.operator {
                line(text, "K0008", Some(i), &field(operator, 40));
            }
            let note = value_text(part, m);
            if !note.is_empty() {
                line(text, "K0009", Some(i), &field(&note, 255));
            }
            if let Some(station) = &part.station {
                line(text, "K0010", Some(i), &field(station, 40));
            }
            line(text, "K0012", Some(i), &field(&part.gauge, 80));
            line(text, "K0014", Some(i), &field(&part.part_id, 40));
        }
    }
}

/// `K0009`: what Q-DAS has no field for. An invalid value says why; a value
/// states its expanded uncertainty, the rule it was judged by, and a verdict
/// the limits alone do not give (inconclusive).
fn value_text(part: &ExchangePart, m: &MeasurementRecord) -> String {
    if m.value.is_none() {
        let why = m.note.as_deref().or(part.reason.as_deref()).unwrap_or("not measured");
        return format!("not measured: {why}");
    }
    let mut text = String::new();
    if let Some(u) = &m.uncertainty {
        let _ = write!(text, "U={} {} k={}", significant(u.expanded), m.unit, u.k);
    }
    if let Some(rule) = &m.decision_rule {
        let _ = write!(text, "{}rule {}", if text.is_empty() { "" } else { "; " }, rule.name());
    }
    if m.verdict == Some(Verdict::Inconclusive) {
        let _ = write!(text, "{}inconclusive", if text.is_empty() { "" } else { "; " });
    }
    text
}

/// Two significant digits, as an uncertainty is stated (GUM 7.2.6).
fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{}", v.abs());
    }
    let decimals = (1 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.decimals$}")
}

/// `K2022`: decimal places shown, by unit, so a history keeps one setting.
pub fn decimal_places(unit: &str) -> usize {
    match unit {
        "mm" => 4,
        "um" => 3,
        "nm" => 1,
        "deg" => 4,
        "%" => 2,
        _ => 4,
    }
}

/// A number with three digits more than the characteristic shows, so a
/// value read back is the value measured to well below its resolution.
fn number(v: f64, decimals: usize) -> String {
    let digits = decimals + 3;
    let text = format!("{v:.digits$}");
    // "-0.000000" is zero.
    if text.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') { format!("{:.digits$}", 0.0) } else { text }
}

/// A text field as the format can hold it (see the module's notes).
pub fn field(text: &str, max_chars: usize) -> String {
    let cleaned: String = text
        .chars()
        .map(|c| match c {
            c if c.is_control() => ' ',
            c if (c as u32) > 0xFF => '?',
            c => c,
        })
        .collect();
    cleaned.trim().chars().take(max_chars).collect::<String>().trim_end().to_string()
}

fn line(text: &mut String, key: &str, index: Option<usize>, value: &str) {
    text.push_str(key);
    if let Some(i) = index {
        let _ = write!(text, "/{i}");
    }
    text.push(' ');
    text.push_str(value);
    text.push_str("\r\n");
}

/// Latin-1 bytes of text [`field`] has already limited to Latin-1.
fn latin1(text: &str) -> Vec<u8> {
    text.chars().map(|c| u8::try_from(c as u32).unwrap_or(b'?')).collect()
}

#[cfg(test)]
mod tests;
