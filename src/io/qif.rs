//! A part as a QIF 3.0 Results document (ISO 23952, the Quality Information
//! Framework), valid against the official schema (`tests/data/qif-3.0/`,
//! checked by `xmllint` in the tests).
//!
//! What goes where:
//! - `Header/Application`: Sheen and its version; `Version/TimeCreated`.
//! - `FileUnits`: millimetres and degrees; heights in micrometres keep their
//!   unit (`linearUnit="um"`, declared under `OtherUnits`).
//! - `MeasurementResources`: one device, the gauge (Sheen and the rig's
//!   calibration).
//! - `Characteristics`: per measurement a definition (its tolerance), a
//!   nominal and an item (the row's name), chained by id. A step height is
//!   a `HeightCharacteristic`; a peak-to-valley flatness with a limit a
//!   `FlatnessCharacteristic` (its `ToleranceValue` the limit); Sa or Ra
//!   with an upper limit a `SurfaceTextureCharacteristic` (QIF's only
//!   texture parameter, `RoughnessAverage`); any other length a
//!   `UserDefinedLinearCharacteristic`, an angle a
//!   `UserDefinedAngularCharacteristic`, a toleranced value of another
//!   unit a `UserDefinedUnitCharacteristic`. QIF's user-defined-unit
//!   characteristic must have limits, so an untoleranced value of another
//!   unit (Ssk, Sku, a match score) is written as an `AttributeD1` of the
//!   results (`name` the measurement and its unit) instead.
//! - `Results/MeasurementResultsSet/MeasurementResults`: every
//!   characteristic's measured value with its standard uncertainty
//!   (`combinedUncertainty`, the value's unit), the expanded uncertainty,
//!   coverage factor and decision rule as attributes of the measurement, and
//!   its status: pass `PASS`, fail `FAIL`, inconclusive (ISO 14253-1:
//!   within U of a limit) `INDETERMINATE`, untoleranced `NOT_ANALYZED`, not
//!   measured `SYSERROR` without a value. The part's status: `PASS`,
//!   `FAIL`, inconclusive `UNKNOWN` (QIF has no inconclusive inspection; the
//!   results' attribute `sheen_verdict` says `inconclusive`), error
//!   `SYSERROR`. The part's serial is the actual component's
//!   `SerialNumber`; operator and time are the results'
//!   `InspectionTraceability`, the station an attribute of the results.
//!
//! Text: XML-escaped; characters XML 1.0 cannot hold (control characters
//! other than tab and line breaks) become `?`.

use std::fmt::Write as _;
use std::path::Path;

use crate::analysis::measurement_record::MeasurementRecord;
use crate::analysis::measurement_table::{PartVerdict, Verdict};

use super::IoError;
use super::exchange::{ExchangePart, characteristic_description, write_exchange_file};

/// QIF's schema version this writer follows.
pub const QIF_VERSION: &str = "3.0.0";

/// Writes `part` as a QIF 3.0 Results document, atomically.
pub fn write_qif(path: &Path, part: &ExchangePart, sheen_version: &str) -> Result<(), IoError> {
    write_exchange_file(path, qif_document(part, sheen_version).as_bytes())
}

/// How QIF types a measurement (see the module's notes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QifKind {
    Height,
    Flatness,
    SurfaceTexture,
    UserDefinedLinear,
    UserDefinedAngular,
    UserDefinedUnit,
    /// Not a characteristic: an attribute of the results.
    ResultAttribute,
}

impl QifKind {
    pub fn of(m: &MeasurementRecord) -> Self {
        let length = matches!(m.unit.as_str(), "mm" | "um");
        let parameter = m.parameter.as_deref().unwrap_or("");
        match m.kind.as_str() {
            "step_height" if length => QifKind::Height,
            "flatness_peak_to_valley" if length && m.upper_limit.is_some() => QifKind::Flatness,
            "texture" | "profile_texture"
                if length && matches!(parameter, "Sa" | "Ra") && m.upper_limit.is_some() && m.lower_limit.is_none() =>
            {
                QifKind::SurfaceTexture
            }
            _ if length => QifKind::UserDefinedLinear,
            _ if m.unit == "deg" => QifKind::UserDefinedAngular,
            _ if m.upper_limit.is_some() || m.lower_limit.is_some() => QifKind::UserDefinedUnit,
            _ => QifKind::ResultAttribute,
        }
    }

    /// The element names' stem (`{stem}CharacteristicDefinition`, ...).
    pub fn stem(self) -> &'static str {
        match self {
            QifKind::Height => "Height",
            QifKind::Flatness => "Flatness",
            QifKind::SurfaceTexture => "SurfaceTexture",
            QifKind::UserDefinedLinear => "UserDefinedLinear",
            QifKind::UserDefinedAngular => "UserDefinedAngular",
            QifKind::UserDefinedUnit | QifKind::ResultAttribute => "UserDefinedUnit",
        }
    }
}

/// The status QIF gives a characteristic's measurement.
pub fn characteristic_status(m: &MeasurementRecord) -> &'static str {
    match (m.verdict, m.value) {
        (Some(Verdict::Pass), _) => "PASS",
        (Some(Verdict::Fail), _) => "FAIL",
        (Some(Verdict::Inconclusive), _) => "INDETERMINATE",
        (None, None) => "SYSERROR",
        (None, Some(_)) => "NOT_ANALYZED",
    }
}

/// The status QIF gives the part.
pub fn inspection_status(verdict: PartVerdict) -> &'static str {
    match verdict {
        PartVerdict::Pass => "PASS",
        PartVerdict::Fail => "FAIL",
        PartVerdict::Inconclusive => "UNKNOWN",
        PartVerdict::Error => "SYSERROR",
    }
}

/// The QIF document of one part.
pub fn qif_document(part: &ExchangePart, sheen_version: &str) -> String {
    let mut ids = Ids(0);
    let mut x = String::with_capacity(4096 + part.measurements.len() * 1500);
    let standard = ids.next();
    let device = ids.next();
    let characteristics: Vec<(&MeasurementRecord, QifKind, Chain)> = part
        .measurements
        .iter()
        .map(|m| (m, QifKind::of(m)))
        .filter(|(_, kind)| *kind != QifKind::ResultAttribute)
        .map(|(m, kind)| {
            let chain =
                Chain { definition: ids.next(), nominal: ids.next(), item: ids.next(), measurement: ids.next() };
            (m, kind, chain)
        })
        .collect();
    let results = ids.next();
    let component = ids.next();

    let digest = part.digest();
    x.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        x,
        "<QIFDocument xmlns=\"http://qifstandards.org/xsd/qif3\" \
         xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" \
         xsi:schemaLocation=\"http://qifstandards.org/xsd/qif3 ../QIFApplications/QIFDocument.xsd\" \
         versionQIF=\"{QIF_VERSION}\" idMax=\"{}\">",
        ids.0
    );
    let _ = writeln!(x, "  <QPId>{}</QPId>", qpid(&digest, 0));
    let created = xml_time(part.time_utc);
    let _ = writeln!(x, "  <Version><TimeCreated>{created}</TimeCreated></Version>");
    let _ = writeln!(
        x,
        "  <Header><Application><Name>Sheen</Name><Organization>Sheen {}</Organization></Application>\
         <Description>{}</Description></Header>",
        text(sheen_version),
        text(&format!("Inspection results of part {} ({})", part.part_id, part.part_number))
    );
    let _ = writeln!(
        x,
        "  <StandardsDefinitions n=\"1\"><Standard id=\"{standard}\"><Organization>\
         <StandardsOrganizationEnum>ISO</StandardsOrganizationEnum></Organization>\
         <Designator>1101</Designator><Year>2017</Year></Standard></StandardsDefinitions>"
    );
    x.push_str(
        "  <FileUnits><PrimaryUnits>\
         <AngularUnit><SIUnitName>radian</SIUnitName><UnitName>degree</UnitName>\
         <UnitConversion><Factor>0.0174532925199433</Factor></UnitConversion></AngularUnit>\
         <LinearUnit><SIUnitName>meter</SIUnitName><UnitName>mm</UnitName>\
         <UnitConversion><Factor>0.001</Factor></UnitConversion></LinearUnit></PrimaryUnits>\
         <OtherUnits n=\"1\"><LinearUnit><SIUnitName>meter</SIUnitName><UnitName>um</UnitName>\
         <UnitConversion><Factor>0.000001</Factor></UnitConversion></LinearUnit></OtherUnits>",
    );
    // QIF checks every user-defined unit a value names against this list.
    let mut user_units: Vec<String> = characteristics
        .iter()
        .filter(|(_, k, _)| *k == QifKind::UserDefinedUnit)
        .map(|(m, _, _)| unit_name(&m.unit))
        .collect();
    user_units.sort();
    user_units.dedup();
    if !user_units.is_empty() {
        let _ = write!(x, "<UserDefinedUnits n=\"{}\">", user_units.len());
        for unit in &user_units {
            let _ = write!(
                x,
                "<UserDefinedUnit><WhatIsMeasured>{}</WhatIsMeasured><UnitName>{unit}</UnitName></UserDefinedUnit>",
                if unit == "1" { "a quantity of dimension one" } else { "a quantity in this unit" }
            );
        }
        x.push_str("</UserDefinedUnits>");
    }
    x.push_str("</FileUnits>\n");
    let _ = writeln!(
        x,
        "  <MeasurementResources><MeasurementDevices n=\"1\"><MeasurementDevice id=\"{device}\">\
         <Name>{}</Name></MeasurementDevice></MeasurementDevices></MeasurementResources>",
        text(&part.gauge)
    );

    if !characteristics.is_empty() {
        write_characteristics(&mut x, standard, device, &characteristics);
    }

    x.push_str("  <Results>\n    <MeasurementResultsSet n=\"1\">\n");
    let _ = writeln!(x, "      <MeasurementResults id=\"{results}\">");
    write_result_attributes(&mut x, part);
    x.push_str("        <InspectionTraceability>");
    let _ = write!(x, "<ReportNumber>{}</ReportNumber>", text(&part.part_id));
    let _ = write!(x, "<InspectionStart>{created}</InspectionStart>");
    if let Some(operator) = &part.operator {
        let _ = write!(x, "<InspectionOperator><Name>{}</Name></InspectionOperator>", token(operator));
    }
    x.push_str("</InspectionTraceability>\n");
    let _ = writeln!(x, "        <ThisResultsInstanceQPId>{}</ThisResultsInstanceQPId>", qpid(&digest, 1));
    if !characteristics.is_empty() {
        let _ = writeln!(
            x,
            "        <MeasuredCharacteristics><CharacteristicMeasurements n=\"{}\">",
            characteristics.len()
        );
        for (m, kind, chain) in &characteristics {
            write_measurement(&mut x, m, *kind, chain, device, &created);
        }
        x.push_str("        </CharacteristicMeasurements></MeasuredCharacteristics>\n");
    }
    let status = inspection_status(part.verdict);
    let _ = writeln!(
        x,
        "        <InspectionStatus><InspectionStatusEnum>{status}</InspectionStatusEnum></InspectionStatus>"
    );
    let _ = writeln!(x, "        <ActualComponentIds n=\"1\"><Id>{component}</Id></ActualComponentIds>");
    x.push_str("      </MeasurementResults>\n    </MeasurementResultsSet>\n");
    let _ = writeln!(
        x,
        "    <ActualComponentSets n=\"1\"><ActualComponentSet n=\"1\"><ActualComponent id=\"{component}\">\
         <SerialNumber>{}</SerialNumber><Status><InspectionStatusEnum>{status}</InspectionStatusEnum></Status>\
         </ActualComponent></ActualComponentSet></ActualComponentSets>",
        text(&part.part_id)
    );
    x.push_str("  </Results>\n</QIFDocument>\n");
    x
}

/// The ids of one characteristic's chain, definition to measurement.
#[derive(Clone, Copy, Debug)]
struct Chain {
    definition: u64,
    nominal: u64,
    item: u64,
    measurement: u64,
}

struct Ids(u64);

impl Ids {
    fn next(&mut self) -> u64 {
        self.0 += 1;
        self.0
    }
}

fn write_characteristics(x: &mut String, standard: u64, device: u64, list: &[(&MeasurementRecord, QifKind, Chain)]) {
    let n = list.len();
    let _ = writeln!(x, "  <Characteristics>\n    <FormalStandardId>{standard}</FormalStandardId>");
    let _ = writeln!(x, "    <CharacteristicDefinitions n=\"{n}\">");
    for (m, kind, chain) in list {
        let stem = kind.stem();
        let _ = write!(x, "      <{stem}CharacteristicDefinition id=\"{}\">", chain.definition);
        let _ = write!(x, "<Description>{}</Description>", text(&characteristic_description(m)));
        match kind {
            QifKind::Height | QifKind::UserDefinedLinear => {
                write_tolerance(x, m, &value_attribute("linearUnit", &m.unit));
                if *kind == QifKind::UserDefinedLinear {
                    let _ = write!(x, "<WhatToMeasure>{}</WhatToMeasure>", text(&what_to_measure(m)));
                }
            }
            QifKind::UserDefinedAngular => {
                write_tolerance(x, m, "");
                let _ = write!(x, "<WhatToMeasure>{}</WhatToMeasure>", text(&what_to_measure(m)));
            }
            QifKind::Flatness => {
                let limit = m.upper_limit.unwrap_or_default();
                let _ = write!(
                    x,
                    "<ToleranceValue{}>{}</ToleranceValue>",
                    value_attribute("linearUnit", &m.unit),
                    decimal(limit)
                );
            }
            QifKind::SurfaceTexture => {
                let limit = m.upper_limit.unwrap_or_default();
                let _ = write!(
                    x,
                    "<RoughnessAverage{}>{}</RoughnessAverage>",
                    value_attribute("linearUnit", &m.unit),
                    decimal(limit)
                );
            }
            QifKind::UserDefinedUnit | QifKind::ResultAttribute => {}
        }
        let _ = writeln!(x, "</{stem}CharacteristicDefinition>");
    }
    x.push_str("    </CharacteristicDefinitions>\n");
    let _ = writeln!(x, "    <CharacteristicNominals n=\"{n}\">");
    for (m, kind, chain) in list {
        let stem = kind.stem();
        let _ = write!(x, "      <{stem}CharacteristicNominal id=\"{}\">", chain.nominal);
        let _ = write!(x, "<CharacteristicDefinitionId>{}</CharacteristicDefinitionId>", chain.definition);
        match kind {
            QifKind::Height | QifKind::UserDefinedLinear => {
                if let Some(nominal) = m.nominal {
                    let _ = write!(
                        x,
                        "<TargetValue{}>{}</TargetValue>",
                        value_attribute("linearUnit", &m.unit),
                        decimal(nominal)
                    );
                }
            }
            QifKind::UserDefinedAngular => {
                if let Some(nominal) = m.nominal {
                    let _ = write!(x, "<TargetValue>{}</TargetValue>", decimal(nominal));
                }
            }
            QifKind::UserDefinedUnit => write_unit_nominal(x, m),
            QifKind::Flatness | QifKind::SurfaceTexture | QifKind::ResultAttribute => {}
        }
        let _ = writeln!(x, "</{stem}CharacteristicNominal>");
    }
    x.push_str("    </CharacteristicNominals>\n");
    let _ = writeln!(x, "    <CharacteristicItems n=\"{n}\">");
    for (m, kind, chain) in list {
        let stem = kind.stem();
        let _ = writeln!(
            x,
            "      <{stem}CharacteristicItem id=\"{}\"><Name>{}</Name>\
             <MeasurementDeviceIds n=\"1\"><Id>{device}</Id></MeasurementDeviceIds>\
             <CharacteristicNominalId>{}</CharacteristicNominalId></{stem}CharacteristicItem>",
            chain.item,
            token(&characteristic_description(m)),
            chain.nominal
        );
    }
    x.push_str("    </CharacteristicItems>\n  </Characteristics>\n");
}

/// A linear or angular definition's limits (absolute: `DefinedAsLimit`),
/// or `NonTolerance MEASURED` where there are none.
fn write_tolerance(x: &mut String, m: &MeasurementRecord, unit_attribute: &str) {
    match (m.upper_limit, m.lower_limit) {
        (None, None) => x.push_str("<NonTolerance>MEASURED</NonTolerance>"),
        (upper, lower) => {
            x.push_str("<Tolerance>");
            if let Some(u) = upper {
                let _ = write!(x, "<MaxValue{unit_attribute}>{}</MaxValue>", decimal(u));
            }
            if let Some(l) = lower {
                let _ = write!(x, "<MinValue{unit_attribute}>{}</MinValue>", decimal(l));
            }
            x.push_str("<DefinedAsLimit>true</DefinedAsLimit></Tolerance>");
        }
    }
}

/// QIF's user-defined-unit nominal needs a target and a limit: the target is
/// the nominal where one is given, else the middle of the limits, else the
/// one limit.
fn write_unit_nominal(x: &mut String, m: &MeasurementRecord) {
    let unit = unit_name(&m.unit);
    let target = m.nominal.unwrap_or(match (m.lower_limit, m.upper_limit) {
        (Some(l), Some(u)) => 0.5 * (l + u),
        (Some(l), None) => l,
        (None, Some(u)) => u,
        (None, None) => 0.0,
    });
    let _ = write!(x, "<TargetValue unitName=\"{unit}\">{}</TargetValue>", decimal(target));
    if let Some(u) = m.upper_limit {
        let _ = write!(x, "<MaxValue unitName=\"{unit}\">{}</MaxValue>", decimal(u));
    }
    if let Some(l) = m.lower_limit {
        let _ = write!(x, "<MinValue unitName=\"{unit}\">{}</MinValue>", decimal(l));
    }
    x.push_str("<DefinedAsLimit>true</DefinedAsLimit>");
}

fn write_measurement(x: &mut String, m: &MeasurementRecord, kind: QifKind, chain: &Chain, device: u64, time: &str) {
    let stem = kind.stem();
    let _ = write!(x, "          <{stem}CharacteristicMeasurement id=\"{}\">", chain.measurement);
    let mut attributes = Vec::new();
    if let Some(u) = &m.uncertainty {
        attributes.push(format!("<AttributeD1 name=\"expanded_uncertainty\" value=\"{}\"/>", u.expanded));
        attributes.push(format!("<AttributeD1 name=\"coverage_factor\" value=\"{}\"/>", u.k));
    }
    if let Some(rule) = &m.decision_rule {
        attributes.push(format!("<AttributeStr name=\"decision_rule\" value=\"{}\"/>", attribute_text(&rule.name())));
    }
    if let Some(note) = &m.note {
        attributes.push(format!("<AttributeStr name=\"note\" value=\"{}\"/>", attribute_text(note)));
    }
    if !attributes.is_empty() {
        let _ = write!(x, "<Attributes n=\"{}\">{}</Attributes>", attributes.len(), attributes.concat());
    }
    let _ = write!(
        x,
        "<Status><CharacteristicStatusEnum>{}</CharacteristicStatusEnum></Status>\
         <CharacteristicItemId>{}</CharacteristicItemId><TimeStamp>{time}</TimeStamp>\
         <MeasurementDeviceIds n=\"1\"><Id>{device}</Id></MeasurementDeviceIds>",
        characteristic_status(m),
        chain.item
    );
    if let Some(v) = m.value {
        let uncertainty = m
            .uncertainty
            .as_ref()
            .map_or(String::new(), |u| format!(" combinedUncertainty=\"{}\"", decimal(u.u.abs())));
        let (element, unit) = match kind {
            QifKind::SurfaceTexture => ("RoughnessAverageValue", value_attribute("linearUnit", &m.unit)),
            QifKind::UserDefinedUnit => ("Value", format!(" unitName=\"{}\"", unit_name(&m.unit))),
            QifKind::UserDefinedAngular => ("Value", String::new()),
            _ => ("Value", value_attribute("linearUnit", &m.unit)),
        };
        let _ = write!(x, "<{element}{unit}{uncertainty}>{}</{element}>", decimal(v));
    }
    let _ = writeln!(x, "</{stem}CharacteristicMeasurement>");
}

/// The results' attributes: Sheen's own verdict (QIF has no inconclusive
/// inspection), why the part failed or was not measured, and the values
/// QIF has no characteristic for.
fn write_result_attributes(x: &mut String, part: &ExchangePart) {
    let mut attributes = vec![format!("<AttributeStr name=\"sheen_verdict\" value=\"{}\"/>", part.verdict.name())];
    if let Some(station) = &part.station {
        attributes.push(format!("<AttributeStr name=\"station\" value=\"{}\"/>", attribute_text(station)));
    }
    if let Some(reason) = &part.reason {
        attributes.push(format!("<AttributeStr name=\"reason\" value=\"{}\"/>", attribute_text(reason)));
    }
    for m in part.measurements.iter().filter(|m| QifKind::of(m) == QifKind::ResultAttribute) {
        let name = match m.unit.as_str() {
            "" => characteristic_description(m),
            unit => format!("{} [{unit}]", characteristic_description(m)),
        };
        match m.value {
            Some(v) => attributes.push(format!("<AttributeD1 name=\"{}\" value=\"{v}\"/>", attribute_text(&name))),
            None => {
                attributes.push(format!("<AttributeStr name=\"{}\" value=\"not measured\"/>", attribute_text(&name)))
            }
        }
    }
    let _ = writeln!(x, "        <Attributes n=\"{}\">{}</Attributes>", attributes.len(), attributes.concat());
}

fn what_to_measure(m: &MeasurementRecord) -> String {
    match &m.parameter {
        Some(p) => format!("{} {p}", m.kind),
        None => m.kind.replace('_', " "),
    }
}

/// A length's unit attribute: millimetres are the file's primary unit.
fn value_attribute(name: &str, unit: &str) -> String {
    match unit {
        "um" => format!(" {name}=\"um\""),
        _ => String::new(),
    }
}

/// A user-defined unit's name (an `xs:token`; a unitless value is "1").
fn unit_name(unit: &str) -> String {
    let unit = attribute_text(unit.trim());
    if unit.is_empty() { "1".into() } else { unit.split_whitespace().collect::<Vec<_>>().join("_") }
}

/// An `xs:decimal`: plain digits, never exponent notation (Rust's `Display`
/// of `f64` never uses it, and prints the shortest text that reads back as
/// the same number).
fn decimal(v: f64) -> String {
    if v == 0.0 { "0".into() } else { format!("{v}") }
}

/// `xs:dateTime` in UTC.
fn xml_time(t: chrono::DateTime<chrono::Utc>) -> String {
    t.format("%Y-%m-%dT%H:%M:%S%.6fZ").to_string()
}

/// A QPId (a UUID, RFC 4122 layout, version 5-like: name-based) from the
/// part's digest, so one part's file names the same document each time.
fn qpid(digest: &[u8; 32], salt: u8) -> String {
    let mut b = [0u8; 16];
    b.copy_from_slice(&digest[..16]);
    b[15] ^= salt;
    b[6] = (b[6] & 0x0f) | 0x50;
    b[8] = (b[8] & 0x3f) | 0x80;
    let hex: String = b.iter().map(|v| format!("{v:02x}")).collect();
    format!("{}-{}-{}-{}-{}", &hex[..8], &hex[8..12], &hex[12..16], &hex[16..20], &hex[20..])
}

/// Text XML 1.0 can hold: its control characters other than tab and line
/// breaks become `?`.
fn xml_chars(s: &str) -> String {
    s.chars()
        .map(|c| match c {
            '\t' | '\n' | '\r' => c,
            c if (c as u32) < 0x20 || c == '\u{fffe}' || c == '\u{ffff}' => '?',
            c => c,
        })
        .collect()
}

fn text(s: &str) -> String {
    quick_xml::escape::escape(xml_chars(s).as_str()).into_owned()
}

fn attribute_text(s: &str) -> String {
    // Line breaks in an attribute would be normalised to spaces by a reader.
    text(&s.replace(['\n', '\r', '\t'], " "))
}

/// An `xs:token`: no line breaks, tabs or runs of spaces.
fn token(s: &str) -> String {
    text(&s.split_whitespace().collect::<Vec<_>>().join(" "))
}

#[cfg(test)]
mod tests;
