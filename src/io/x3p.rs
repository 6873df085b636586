//! X3P (ISO 25178-72, the openGPS ISO5436_2 XML format) for height maps, as
//! Gwyddion, MountainsMap and the openGPS tools read it.
//!
//! The container is a zip archive holding
//! - `main.xml`: the `ISO5436_2` document (namespace
//!   `http://www.opengps.eu/2008/ISO5436_2`, child elements unqualified):
//!   Record1 = revision, feature type `SUR`, axes CX and CY incremental with
//!   their increment and offset in metres, CZ absolute with data type `F`
//!   (float32) or `D` (float64); Record2 = date, creator, instrument, calibration
//!   date, probing system, comment; Record3 = matrix dimension and the
//!   `DataLink` to `bindata/data.bin` with its MD5; Record4 = the name of the
//!   checksum file;
//! - `bindata/data.bin`: Z in metres, little-endian, X fastest then Y, NaN
//!   for invalid points (no valid-points file is needed for float data);
//! - `md5checksum.hex`: the MD5 of `main.xml` as `md5sum` prints it.
//!
//! Rows are stored north first, as the TIFF and PNG maps are: readers that
//! draw row 0 at the top (Gwyddion, MountainsMap) show the part as the app
//! does. The file's Y therefore grows with the row, southward: file Y is
//! minus the map's Y, and CY/Offset is minus the Y of the map's northmost row
//! (a comment inside `<CY>` says so). Sheen up to 0.1.0 stored row 0 at the
//! smallest Y; the reader recognises those files by their Record2 (instrument
//! "Sheen", version exactly "0.1.0", what [`X3pMetadata::sheen`] wrote then)
//! and reads them the old way, so they still come back right side up.
//!
//! The writer takes `impl Write + Seek` (zip needs to seek back to patch
//! sizes); the caller writes to a temporary file and renames it. The reader
//! validates the structure and the data checksum and reads what the writer
//! writes bit for bit for `D` data (float32 `F` data to 1 ulp: mm -> m is not
//! a power of two). It also reads int16/int32 Z (`I`, `L`) with increment and
//! offset and an optional valid-points file, since other instruments write them.

use crate::engine::warning::{Warning, WarningKind};
use std::collections::HashMap;
use std::io::{self, Read, Seek, Write};

use md5::{Digest, Md5};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

use crate::analysis::height_map::HeightMap;

pub const MAIN_XML: &str = "main.xml";
pub const DATA_BIN: &str = "bindata/data.bin";
pub const CHECKSUM_FILE: &str = "md5checksum.hex";
pub const NAMESPACE: &str = "http://www.opengps.eu/2008/ISO5436_2";

/// Record2/Instrument/Version that Sheen wrote while its X3P rows were south
/// first; no file written since carries it (see [`X3pMetadata::sheen`]).
pub const SOUTH_FIRST_SHEEN_VERSION: &str = "0.1.0";
/// Record2/Instrument/Manufacturer of Sheen's files.
pub const SHEEN_MANUFACTURER: &str = "Sheen";

/// Storage type of Z (`CZ/DataType`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum X3pDataType {
    /// "F": float32 metres, half the size, 1 ulp of rounding (7 digits).
    Float32,
    /// "D": float64 metres, lossless for Sheen's f32 millimetres.
    #[default]
    Float64,
}

impl X3pDataType {
    pub fn code(self) -> &'static str {
        match self {
            X3pDataType::Float32 => "F",
            X3pDataType::Float64 => "D",
        }
    }
}

/// Record2: who, when and with what. `date` and `calibration_date` are
/// `xsd:dateTime` text such as `2025-03-01T14:05:00Z` ([`xsd_date_time_utc`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct X3pMetadata {
    pub date: String,
    pub creator: Option<String>,
    pub manufacturer: String,
    pub model: String,
    pub serial: String,
    pub version: String,
    /// The schema requires a calibration date; when unknown the file date is
    /// written instead and the comment says so.
    pub calibration_date: Option<String>,
    /// Probe identification (lens, projector...).
    pub probe: String,
    pub comment: Option<String>,
}

impl X3pMetadata {
    /// Sheen's defaults for a map measured now (`date` from [`xsd_date_time_utc`]).
    pub fn sheen(date: impl Into<String>) -> Self {
        Self {
            date: date.into(),
            creator: None,
            manufacturer: SHEEN_MANUFACTURER.into(),
            model: "dual-telecentric fringe projection".into(),
            serial: "unknown".into(),
            // The row order in the version keeps these files apart from those
            // of 0.1.0, which carried the bare package version and south-first
            // rows, even before the package version moves on.
            version: concat!(env!("CARGO_PKG_VERSION"), " (X3P rows north first)").into(),
            calibration_date: None,
            probe: "multi-frequency phase shifting, telecentric stereo".into(),
            comment: None,
        }
    }
}

/// What can go wrong writing or reading an X3P container. The caller adds
/// the file path (io wraps this error with it).
#[derive(Debug, thiserror::Error)]
pub enum X3pError {
    #[error("reading or writing the X3P data failed: {0}")]
    Io(#[from] io::Error),
    #[error("the X3P zip container is damaged or not a zip archive: {0}")]
    Zip(#[from] zip::result::ZipError),
    #[error("the X3P container has no '{name}' (it holds: {found}); it is incomplete or not an ISO 25178-72 file")]
    MissingEntry { name: String, found: String },
    #[error("main.xml is not well-formed XML: {reason}")]
    Xml { reason: String },
    #[error("main.xml lacks the element {element}, which ISO 25178-72 requires")]
    MissingElement { element: String },
    #[error("main.xml: {element} is '{value}', expected {expected}")]
    BadValue { element: String, value: String, expected: String },
    #[error("this X3P file uses {what}, which Sheen does not read")]
    Unsupported { what: String },
    #[error("'{entry}' holds {found} bytes, expected {expected} from the matrix size and data type in main.xml")]
    DataSize { entry: String, expected: u64, found: u64 },
    #[error(
        "'{entry}' is corrupt: its MD5 is {computed} but main.xml declares {declared}; the file was damaged after \
         writing"
    )]
    DataChecksum { entry: String, declared: String, computed: String },
    #[error("the height map is empty ({width}x{height}); there is nothing to export")]
    EmptyMap { width: usize, height: usize },
}

impl X3pMetadata {
    /// Whether a file with this Record2 was written by Sheen 0.1.0, whose
    /// rows run south first with CY/Offset the Y of row 0.
    pub fn rows_south_first(&self) -> bool {
        self.manufacturer == SHEEN_MANUFACTURER && self.version == SOUTH_FIRST_SHEEN_VERSION
    }
}

/// A height map read from an X3P file.
#[derive(Clone, Debug, PartialEq)]
pub struct X3pFile {
    pub map: HeightMap,
    /// Record2 as found (missing text fields are empty).
    pub metadata: X3pMetadata,
    pub data_type_code: String,
    /// Problems that do not stop reading (main.xml checksum file missing or
    /// not matching, as some writers leave it).
    pub warnings: Vec<Warning>,
}

/// Lowercase hex MD5.
fn md5_hex(bytes: &[u8]) -> String {
    Md5::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

fn xml_text(s: &str) -> String {
    quick_xml::escape::escape(s).into_owned()
}

/// Writes `map` as an X3P container into `writer` and returns it.
pub fn write_x3p<W: Write + Seek>(
    writer: W,
    map: &HeightMap,
    meta: &X3pMetadata,
    data_type: X3pDataType,
) -> Result<W, X3pError> {
    if map.width == 0 || map.height == 0 {
        return Err(X3pError::EmptyMap { width: map.width, height: map.height });
    }
    let m_per_unit = map.unit.mm_per_unit() * 1e-3;
    let value_bytes = match data_type {
        X3pDataType::Float32 => 4,
        X3pDataType::Float64 => 8,
    };
    let mut data = vec![0u8; map.z.len() * value_bytes];
    data.par_chunks_mut(map.width * value_bytes).zip(map.z.par_chunks_exact(map.width).rev()).for_each(|(out, row)| {
        for (bytes, &z) in out.chunks_exact_mut(value_bytes).zip(row) {
            let metres = f64::from(z) * m_per_unit;
            match data_type {
                X3pDataType::Float32 => bytes.copy_from_slice(&(metres as f32).to_le_bytes()),
                X3pDataType::Float64 => bytes.copy_from_slice(&metres.to_le_bytes()),
            }
        }
    });

    let time = zip_time(&meta.date);
    // Deflate's fastest level: float heights compress to 59 % there against
    // 54 % at the default level 6, in a third of the time (a full-size map's
    // 25 MB took about 0.4 s at level 6, and the line writes one per part
    // for the results and one for the records).
    let options = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Deflated)
        .compression_level(Some(1))
        .last_modified_time(time);
    // main.xml comes first and holds the data's MD5, but the data need not
    // wait for it: the data is deflated into an archive of its own while the
    // MD5 is computed, and its compressed entry copied in after main.xml (at
    // full size the MD5 is a quarter of the file's time).
    let deflate_data = || -> Result<Vec<u8>, X3pError> {
        let mut part = ZipWriter::new(io::Cursor::new(Vec::new()));
        part.add_directory("bindata/", options)?;
        part.start_file(DATA_BIN, options)?;
        part.write_all(&data)?;
        Ok(part.finish()?.into_inner())
    };
    let (deflated, data_md5) = rayon::join(deflate_data, || md5_hex(&data));
    let xml = main_xml(map, meta, data_type, m_per_unit, &data_md5);
    let checksum = format!("{} *{MAIN_XML}\n", md5_hex(xml.as_bytes()));
    let mut zip = ZipWriter::new(writer);
    zip.start_file(MAIN_XML, options)?;
    zip.write_all(xml.as_bytes())?;
    zip.merge_archive(ZipArchive::new(io::Cursor::new(deflated?))?)?;
    zip.start_file(CHECKSUM_FILE, options)?;
    zip.write_all(checksum.as_bytes())?;
    Ok(zip.finish()?)
}

fn main_xml(map: &HeightMap, meta: &X3pMetadata, data_type: X3pDataType, m_per_unit: f64, data_md5: &str) -> String {
    let inc = map.pitch_mm * m_per_unit;
    // Row 0 is the northmost, and file Y grows southward (module docs).
    let north_y = map.y_mm(map.height - 1);
    let (ox, oy) = (map.origin_x_mm * m_per_unit, -north_y * m_per_unit);
    let mut comment = meta.comment.clone().unwrap_or_default();
    let calibration_date = match &meta.calibration_date {
        Some(d) => d.clone(),
        None => {
            if !comment.is_empty() {
                comment.push_str("; ");
            }
            comment.push_str("calibration date not recorded: CalibrationDate repeats the file date");
            meta.date.clone()
        }
    };
    let creator =
        meta.creator.as_deref().map_or(String::new(), |c| format!("    <Creator>{}</Creator>\n", xml_text(c)));
    let comment =
        if comment.is_empty() { String::new() } else { format!("    <Comment>{}</Comment>\n", xml_text(&comment)) };
    format!(
        r#"<?xml version="1.0" encoding="UTF-8" standalone="no" ?>
<p:ISO5436_2 xmlns:p="{NAMESPACE}" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="{NAMESPACE} http://www.opengps.eu/2008/ISO5436_2/ISO5436_2.xsd">
  <Record1>
    <Revision>ISO5436 - 2000</Revision>
    <FeatureType>SUR</FeatureType>
    <Axes>
      <CX>
        <AxisType>I</AxisType>
        <DataType>D</DataType>
        <Increment>{inc:e}</Increment>
        <Offset>{ox:e}</Offset>
      </CX>
      <CY>
        <!-- Y grows with the row, southward: row 0 is the north edge, as in Sheen's TIFF and PNG maps; Y here is minus Sheen's Y -->
        <AxisType>I</AxisType>
        <DataType>D</DataType>
        <Increment>{inc:e}</Increment>
        <Offset>{oy:e}</Offset>
      </CY>
      <CZ>
        <AxisType>A</AxisType>
        <DataType>{dt}</DataType>
        <Increment>1</Increment>
        <Offset>0</Offset>
      </CZ>
    </Axes>
  </Record1>
  <Record2>
    <Date>{date}</Date>
{creator}    <Instrument>
      <Manufacturer>{manufacturer}</Manufacturer>
      <Model>{model}</Model>
      <Serial>{serial}</Serial>
      <Version>{version}</Version>
    </Instrument>
    <CalibrationDate>{calibration_date}</CalibrationDate>
    <ProbingSystem>
      <Type>NonContacting</Type>
      <Identification>{probe}</Identification>
    </ProbingSystem>
{comment}  </Record2>
  <Record3>
    <MatrixDimension>
      <SizeX>{w}</SizeX>
      <SizeY>{h}</SizeY>
      <SizeZ>1</SizeZ>
    </MatrixDimension>
    <DataLink>
      <PointDataLink>{DATA_BIN}</PointDataLink>
      <MD5ChecksumPointData>{data_md5}</MD5ChecksumPointData>
    </DataLink>
  </Record3>
  <Record4>
    <ChecksumFile>{CHECKSUM_FILE}</ChecksumFile>
  </Record4>
</p:ISO5436_2>
"#,
        dt = data_type.code(),
        date = xml_text(&meta.date),
        manufacturer = xml_text(&meta.manufacturer),
        model = xml_text(&meta.model),
        serial = xml_text(&meta.serial),
        version = xml_text(&meta.version),
        calibration_date = xml_text(&calibration_date),
        probe = xml_text(&meta.probe),
        w = map.width,
        h = map.height,
    )
}

/// Zip entry time from the leading `YYYY-MM-DDTHH:MM:SS` of an xsd:dateTime
/// (1980-01-01 when it does not parse: zip cannot store earlier dates).
fn zip_time(date: &str) -> zip::DateTime {
    let num = |r: std::ops::Range<usize>| date.get(r).and_then(|s| s.parse::<u16>().ok());
    let parts = (num(0..4), num(5..7), num(8..10), num(11..13), num(14..16), num(17..19));
    if let (Some(y), Some(mo), Some(d), Some(h), Some(mi), Some(s)) = parts
        && let Ok(t) = zip::DateTime::from_date_and_time(y, mo as u8, d as u8, h as u8, mi as u8, s as u8)
    {
        return t;
    }
    zip::DateTime::default()
}

/// `xsd:dateTime` in UTC (`2025-03-01T14:05:00Z`) of a system time.
pub fn xsd_date_time_utc(time: std::time::SystemTime) -> String {
    let secs = match time.duration_since(std::time::UNIX_EPOCH) {
        Ok(d) => d.as_secs() as i64,
        Err(e) => -(e.duration().as_secs() as i64),
    };
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (H. Hinnant, "chrono-Compatible
    // Low-Level Date Algorithms", civil_from_days).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem / 60 % 60, rem % 60)
}

/// Element texts of main.xml by path of local names (namespace prefixes
/// dropped, `ISO5436_2/Record1/FeatureType`), first occurrence kept.
fn parse_xml(text: &str) -> Result<HashMap<String, String>, X3pError> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(text);
    let mut path: Vec<String> = Vec::new();
    let mut texts: Vec<String> = Vec::new();
    let mut out = HashMap::new();
    let xml_err = |e: &dyn std::fmt::Display| X3pError::Xml { reason: e.to_string() };
    loop {
        match reader.read_event().map_err(|e| xml_err(&e))? {
            Event::Start(e) => {
                path.push(String::from_utf8_lossy(e.local_name().as_ref()).into_owned());
                texts.push(String::new());
            }
            Event::Empty(e) => {
                let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
                let key = path.iter().chain(std::iter::once(&name)).cloned().collect::<Vec<_>>().join("/");
                out.entry(key).or_insert_with(String::new);
            }
            Event::End(_) => {
                let raw = texts.pop().unwrap_or_default();
                let value = quick_xml::escape::unescape(&raw).map_err(|e| xml_err(&e))?.trim().to_string();
                out.entry(path.join("/")).or_insert(value);
                path.pop();
            }
            Event::Text(t) => {
                if let Some(buf) = texts.last_mut() {
                    buf.push_str(&t.decode().map_err(|e| xml_err(&e))?);
                }
            }
            Event::GeneralRef(r) => {
                if let Some(buf) = texts.last_mut() {
                    buf.push('&');
                    buf.push_str(&r.decode().map_err(|e| xml_err(&e))?);
                    buf.push(';');
                }
            }
            Event::CData(c) => {
                if let Some(buf) = texts.last_mut() {
                    // Escape so the final unescape leaves CDATA text as it was.
                    buf.push_str(&quick_xml::escape::escape(c.decode().map_err(|e| xml_err(&e))?.as_ref()));
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !path.is_empty() {
        return Err(X3pError::Xml { reason: format!("element <{}> is not closed", path.join("/")) });
    }
    Ok(out)
}

struct Doc(HashMap<String, String>);

impl Doc {
    fn get(&self, p: &str) -> Option<&str> {
        self.0.get(&format!("ISO5436_2/{p}")).map(String::as_str)
    }
    fn req(&self, p: &str) -> Result<&str, X3pError> {
        self.get(p).ok_or_else(|| X3pError::MissingElement { element: p.to_string() })
    }
    fn num<T: std::str::FromStr>(&self, p: &str, expected: &str) -> Result<T, X3pError> {
        let v = self.req(p)?;
        v.parse().map_err(|_| X3pError::BadValue { element: p.into(), value: v.into(), expected: expected.into() })
    }
    fn text(&self, p: &str) -> String {
        self.get(p).unwrap_or_default().to_string()
    }
}

/// Largest main.xml or checksum file read (the real ones are a few kB).
const MAX_TEXT_ENTRY: u64 = 16 << 20;

/// Reads a zip entry of at most `max_bytes` (more is refused before it is
/// all decompressed, so a damaged or hostile archive cannot exhaust memory).
fn read_entry<R: Read + Seek>(
    zip: &mut ZipArchive<R>,
    name: &str,
    names: &[String],
    max_bytes: u64,
) -> Result<Vec<u8>, X3pError> {
    let file = match zip.by_name(name) {
        Ok(f) => f,
        Err(zip::result::ZipError::FileNotFound) => {
            return Err(X3pError::MissingEntry { name: name.into(), found: names.join(", ") });
        }
        Err(e) => return Err(e.into()),
    };
    let declared = file.size();
    let mut bytes = Vec::with_capacity(declared.min(max_bytes.saturating_add(1)).min(1 << 30) as usize);
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        let found = declared.max(bytes.len() as u64);
        return Err(X3pError::DataSize { entry: name.into(), expected: max_bytes, found });
    }
    Ok(bytes)
}

/// Reads and validates an X3P container (module docs).
pub fn read_x3p<R: Read + Seek>(reader: R) -> Result<X3pFile, X3pError> {
    let mut zip = ZipArchive::new(reader)?;
    let names: Vec<String> = zip.file_names().filter_map(|n| n.ok().map(|n| n.into_owned())).collect();
    let xml_bytes = read_entry(&mut zip, MAIN_XML, &names, MAX_TEXT_ENTRY)?;
    let xml = String::from_utf8(xml_bytes.clone())
        .map_err(|_| X3pError::Xml { reason: "main.xml is not UTF-8 text".into() })?;
    let doc = Doc(parse_xml(&xml)?);
    if !doc.0.keys().any(|k| k == "ISO5436_2") {
        return Err(X3pError::MissingElement { element: "ISO5436_2 (the root)".into() });
    }

    let feature = doc.req("Record1/FeatureType")?;
    if feature != "SUR" {
        return Err(X3pError::Unsupported { what: format!("feature type '{feature}' (Sheen reads surfaces, SUR)") });
    }
    let mut axis_inc = [0.0f64; 2];
    let mut axis_off = [0.0f64; 2];
    for (k, axis) in ["CX", "CY"].iter().enumerate() {
        let kind = doc.req(&format!("Record1/Axes/{axis}/AxisType"))?;
        if kind != "I" {
            return Err(X3pError::Unsupported { what: format!("{axis} axis type '{kind}' (only incremental, I)") });
        }
        let inc: f64 = doc.num(&format!("Record1/Axes/{axis}/Increment"), "a positive length in metres")?;
        if !(inc.is_finite() && inc > 0.0) {
            return Err(X3pError::BadValue {
                element: format!("Record1/Axes/{axis}/Increment"),
                value: inc.to_string(),
                expected: "a positive length in metres".into(),
            });
        }
        axis_inc[k] = inc;
        axis_off[k] = match doc.get(&format!("Record1/Axes/{axis}/Offset")) {
            Some(_) => doc.num(&format!("Record1/Axes/{axis}/Offset"), "a length in metres")?,
            None => 0.0,
        };
    }
    let z_kind = doc.req("Record1/Axes/CZ/AxisType")?;
    if z_kind != "A" {
        return Err(X3pError::BadValue {
            element: "Record1/Axes/CZ/AxisType".into(),
            value: z_kind.into(),
            expected: "A (the Z axis must be absolute)".into(),
        });
    }
    let code = doc.req("Record1/Axes/CZ/DataType")?.to_string();
    let bytes_per: usize = match code.as_str() {
        "I" => 2,
        "L" | "F" => 4,
        "D" => 8,
        other => {
            return Err(X3pError::BadValue {
                element: "Record1/Axes/CZ/DataType".into(),
                value: other.into(),
                expected: "I, L, F or D".into(),
            });
        }
    };
    let z_inc: f64 = if doc.get("Record1/Axes/CZ/Increment").is_some() {
        doc.num("Record1/Axes/CZ/Increment", "a number")?
    } else {
        1.0
    };
    let z_off: f64 =
        if doc.get("Record1/Axes/CZ/Offset").is_some() { doc.num("Record1/Axes/CZ/Offset", "a number")? } else { 0.0 };

    if doc.get("Record3/ListDimension").is_some() {
        return Err(X3pError::Unsupported { what: "an unordered point list (ListDimension)".into() });
    }
    if doc.get("Record3/DataList").is_some() {
        return Err(X3pError::Unsupported { what: "points inline in main.xml (DataList)".into() });
    }
    let width: u64 = doc.num("Record3/MatrixDimension/SizeX", "a positive integer")?;
    let height: u64 = doc.num("Record3/MatrixDimension/SizeY", "a positive integer")?;
    let layers: u64 = doc.num("Record3/MatrixDimension/SizeZ", "a positive integer")?;
    if layers != 1 {
        return Err(X3pError::Unsupported { what: format!("{layers} layers in Z (SizeZ); Sheen reads one") });
    }
    let link = doc.req("Record3/DataLink/PointDataLink")?.to_string();
    // The schema makes the data's MD5 optional; check it where a writer gave one.
    let declared = doc.get("Record3/DataLink/MD5ChecksumPointData").map(str::to_ascii_lowercase);
    let expected = width.checked_mul(height).and_then(|n| n.checked_mul(bytes_per as u64)).unwrap_or(u64::MAX);
    let data = read_entry(&mut zip, &link, &names, expected)?;
    if data.len() as u64 != expected {
        return Err(X3pError::DataSize { entry: link, expected, found: data.len() as u64 });
    }
    let computed = md5_hex(&data);
    if let Some(declared) = &declared
        && computed != *declared
    {
        return Err(X3pError::DataChecksum { entry: link, declared: declared.clone(), computed });
    }
    let (w, h) = (width as usize, height as usize);
    let valid = match doc.get("Record3/DataLink/ValidPointsLink") {
        Some(vlink) => {
            let vlink = vlink.to_string();
            let need = (w * h).div_ceil(8) as u64;
            let bits = read_entry(&mut zip, &vlink, &names, need)?;
            if (bits.len() as u64) < need {
                return Err(X3pError::DataSize { entry: vlink, expected: need, found: bits.len() as u64 });
            }
            if let Some(d) = doc.get("Record3/DataLink/MD5ChecksumValidPoints") {
                let (d, c) = (d.to_ascii_lowercase(), md5_hex(&bits));
                if d != c {
                    return Err(X3pError::DataChecksum { entry: vlink, declared: d, computed: c });
                }
            }
            Some(bits)
        }
        None => None,
    };

    // Heights in metres -> mm. Float data: the value plus Z offset; integer
    // data: offset + value x increment (the schema's Xreal = Xoffset + Xint Xinc).
    let mut z = Vec::with_capacity(w * h);
    for (i, chunk) in data.chunks_exact(bytes_per).enumerate() {
        let metres = match bytes_per {
            2 => z_off + f64::from(i16::from_le_bytes([chunk[0], chunk[1]])) * z_inc,
            4 if code == "L" => z_off + f64::from(i32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]])) * z_inc,
            4 => z_off + f64::from(f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]])),
            _ => {
                let mut b = [0u8; 8];
                b.copy_from_slice(chunk);
                z_off + f64::from_le_bytes(b)
            }
        };
        let is_valid = valid.as_ref().is_none_or(|bits| bits[i / 8] & (1 << (i % 8)) != 0);
        z.push(if is_valid { (metres * 1e3) as f32 } else { f32::NAN });
    }
    let optional = |p: &str| doc.get(p).filter(|s| !s.is_empty()).map(str::to_string);
    let metadata = X3pMetadata {
        date: doc.text("Record2/Date"),
        creator: optional("Record2/Creator"),
        manufacturer: doc.text("Record2/Instrument/Manufacturer"),
        model: doc.text("Record2/Instrument/Model"),
        serial: doc.text("Record2/Instrument/Serial"),
        version: doc.text("Record2/Instrument/Version"),
        calibration_date: optional("Record2/CalibrationDate"),
        probe: doc.text("Record2/ProbingSystem/Identification"),
        comment: optional("Record2/Comment"),
    };
    let [dx_mm, dy_mm] = [axis_inc[0] * 1e3, axis_inc[1] * 1e3];
    let origin_y_mm = if metadata.rows_south_first() {
        axis_off[1] * 1e3
    } else {
        // Rows north first, file Y = minus map Y: row 0 is the map's last.
        z = z.chunks_exact(w.max(1)).rev().flatten().copied().collect();
        -(axis_off[1] * 1e3) - h.saturating_sub(1) as f64 * dy_mm
    };
    let (map, resampled) = HeightMap::from_rectangular_grid(w, h, axis_off[0] * 1e3, origin_y_mm, [dx_mm, dy_mm], z)
        .map_err(|e| X3pError::BadValue {
            element: "Record3/MatrixDimension".into(),
            value: e.to_string(),
            expected: "a map".into(),
        })?;

    let mut warnings: Vec<Warning> = resampled.into_iter().collect();
    if declared.is_none() {
        warnings.push(Warning::new(
            WarningKind::ChecksumUnverified,
            format!("main.xml declares no MD5 for '{link}': its data could not be checked"),
        ));
    }
    let checksum_name = doc.get("Record4/ChecksumFile").unwrap_or(CHECKSUM_FILE).to_string();
    match read_entry(&mut zip, &checksum_name, &names, MAX_TEXT_ENTRY) {
        Ok(bytes) => {
            let text = String::from_utf8_lossy(&bytes);
            let listed = text.split_whitespace().next().unwrap_or("").to_ascii_lowercase();
            let actual = md5_hex(&xml_bytes);
            if listed != actual {
                warnings.push(Warning::new(
                    WarningKind::ChecksumMismatch,
                    format!(
                        "{checksum_name} lists MD5 '{listed}' but main.xml's is {actual}: the metadata may have \
                         been edited after writing"
                    ),
                ));
            }
        }
        Err(X3pError::MissingEntry { .. }) => {
            warnings.push(Warning::new(
                WarningKind::ChecksumUnverified,
                format!("the checksum file '{checksum_name}' is missing; main.xml was not verified"),
            ));
        }
        Err(e) => return Err(e),
    }
    Ok(X3pFile { map, metadata, data_type_code: code, warnings })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn sample_map() -> HeightMap {
        let (w, h) = (37, 23);
        let z = (0..w * h)
            .map(|i| {
                let (c, r) = ((i % w) as f32, (i / w) as f32);
                if (c - 10.0).hypot(r - 12.0) < 3.0 { f32::NAN } else { 0.25 + 0.001 * c - 0.0007 * r + 1e-5 * c * r }
            })
            .collect();
        HeightMap::new(w, h, 12.3456, -7.5, 0.0117, z).unwrap()
    }

    fn meta() -> X3pMetadata {
        X3pMetadata {
            creator: Some("QC <line 3> & co".into()),
            comment: Some("watch plate 42".into()),
            ..X3pMetadata::sheen("2025-03-01T14:05:06Z")
        }
    }

    fn write(map: &HeightMap, dt: X3pDataType) -> Vec<u8> {
        write_x3p(Cursor::new(Vec::new()), map, &meta(), dt).unwrap().into_inner()
    }

    fn rezip(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
        let mut zip = ZipWriter::new(Cursor::new(Vec::new()));
        for (name, bytes) in entries {
            zip.start_file(*name, SimpleFileOptions::default()).unwrap();
            zip.write_all(bytes).unwrap();
        }
        zip.finish().unwrap().into_inner()
    }

    fn entries(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
        let mut zip = ZipArchive::new(Cursor::new(bytes)).unwrap();
        (0..zip.len())
            .map(|i| {
                let mut f = zip.by_index(i).unwrap();
                let mut v = Vec::new();
                f.read_to_end(&mut v).unwrap();
                (f.name().unwrap().into_owned(), v)
            })
            .collect()
    }

    #[test]
    fn float64_round_trip_is_bit_exact() {
        let map = sample_map();
        let back = read_x3p(Cursor::new(write(&map, X3pDataType::Float64))).unwrap();
        assert!(back.warnings.is_empty(), "{:?}", back.warnings);
        assert_eq!(back.data_type_code, "D");
        assert_eq!((back.map.width, back.map.height), (map.width, map.height));
        for (a, b) in map.z.iter().zip(&back.map.z) {
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "{a} vs {b}");
        }
        assert!((back.map.pitch_mm - map.pitch_mm).abs() <= 2.0 * f64::EPSILON * map.pitch_mm);
        assert!((back.map.origin_x_mm - map.origin_x_mm).abs() <= 4.0 * f64::EPSILON * map.origin_x_mm.abs());
        // Y goes through minus the north row's Y and back: a few ulps of it.
        let north_y = map.y_mm(map.height - 1).abs();
        assert!(
            (back.map.origin_y_mm - map.origin_y_mm).abs() <= 8.0 * f64::EPSILON * north_y.max(map.origin_y_mm.abs())
        );
        assert_eq!(back.map.unit, crate::engine::length_unit::LengthUnit::Mm);
        assert_eq!(back.metadata.creator.as_deref(), Some("QC <line 3> & co"));
        assert_eq!(back.metadata.date, "2025-03-01T14:05:06Z");
        assert_eq!(back.metadata.calibration_date.as_deref(), Some("2025-03-01T14:05:06Z"));
        assert!(back.metadata.comment.unwrap().starts_with("watch plate 42; calibration date not recorded"));
    }

    #[test]
    fn float32_round_trip_is_within_one_ulp() {
        let map = sample_map();
        let back = read_x3p(Cursor::new(write(&map, X3pDataType::Float32))).unwrap();
        assert_eq!(back.data_type_code, "F");
        for (a, b) in map.z.iter().zip(&back.map.z) {
            if a.is_nan() {
                assert!(b.is_nan());
            } else {
                assert!((a - b).abs() <= a.abs() * f32::EPSILON, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn container_structure_and_checksums_follow_the_standard() {
        let map = sample_map();
        let bytes = write(&map, X3pDataType::Float64);
        let files = entries(&bytes);
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["main.xml", "bindata/", "bindata/data.bin", "md5checksum.hex"]);
        let get = |n: &str| files.iter().find(|(m, _)| m == n).map(|(_, b)| b.clone()).unwrap();
        let xml = String::from_utf8(get("main.xml")).unwrap();
        let data = get("bindata/data.bin");
        // data.bin: little-endian float64 metres, X fastest, rows north
        // first (stored row 0 = the map's last row), NaN kept.
        assert_eq!(data.len(), map.z.len() * 8);
        let first = f64::from_le_bytes(data[..8].try_into().unwrap());
        assert_eq!(first, f64::from(map.z[(map.height - 1) * map.width]) * 1e-3);
        let hole = (map.height - 1 - 12) * map.width + 10;
        assert!(f64::from_le_bytes(data[hole * 8..hole * 8 + 8].try_into().unwrap()).is_nan());
        // The declared data MD5 and the checksum file as md5sum writes them.
        assert!(xml.contains(&format!("<MD5ChecksumPointData>{}</MD5ChecksumPointData>", md5_hex(&data))));
        assert_eq!(
            String::from_utf8(get("md5checksum.hex")).unwrap(),
            format!("{} *main.xml\n", md5_hex(xml.as_bytes()))
        );
        // Root qualified, records in schema order, metres, SUR, absolute Z.
        assert!(xml.contains(r#"<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2""#));
        let order = [
            "<Record1>",
            "<Revision>",
            "<FeatureType>SUR<",
            "<CX>",
            "<CY>",
            "<CZ>",
            "<Record2>",
            "<Date>",
            "<Creator>",
            "<Instrument>",
            "<CalibrationDate>",
            "<ProbingSystem>",
            "<Comment>",
            "<Record3>",
            "<SizeX>37<",
            "<SizeY>23<",
            "<SizeZ>1<",
            "<PointDataLink>bindata/data.bin<",
            "<MD5ChecksumPointData>",
            "<Record4>",
            "<ChecksumFile>md5checksum.hex<",
        ];
        let mut at = 0;
        for tag in order {
            let pos = xml[at..].find(tag).unwrap_or_else(|| panic!("{tag} missing or out of order"));
            at += pos;
        }
        assert!(xml.contains("<Increment>1.17e-5</Increment>"), "{xml}");
        assert!(xml.contains("<AxisType>A</AxisType>\n        <DataType>D</DataType>"));
        assert!(xml.contains("QC &lt;line 3&gt; &amp; co"));
        let doc = parse_xml(&xml).unwrap();
        assert_eq!(doc["ISO5436_2/Record1/Axes/CX/Offset"].parse::<f64>().unwrap(), 12.3456e-3);
        // CY: the north row's Y, negated, and the axis says which way it runs.
        let cy = doc["ISO5436_2/Record1/Axes/CY/Offset"].parse::<f64>().unwrap();
        assert!((cy + map.y_mm(map.height - 1) * 1e-3).abs() < 1e-15, "{cy}");
        let cy_xml = &xml[xml.find("<CY>").unwrap()..xml.find("</CY>").unwrap()];
        assert!(cy_xml.contains("Y grows with the row, southward"), "{cy_xml}");
        assert_eq!(doc["ISO5436_2/Record2/Instrument/Version"], "0.1.0 (X3P rows north first)");
    }

    /// A map whose north edge (largest Y, last rows) carries a ridge and whose
    /// south-west corner a hole, so that a flip in either axis shows.
    fn north_ridge_map() -> HeightMap {
        let (w, h) = (9, 12);
        let z = (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                if r >= h - 2 {
                    1.0 + 0.01 * c as f32
                } else if r == 0 && c == 0 {
                    f32::NAN
                } else {
                    0.001 * (r * w + c) as f32
                }
            })
            .collect();
        HeightMap::new(w, h, -0.4, 2.25, 0.05, z).unwrap()
    }

    fn stored_rows(bytes: &[u8], width: usize) -> Vec<Vec<f64>> {
        let files = entries(bytes);
        let data = &files.iter().find(|(n, _)| n == DATA_BIN).unwrap().1;
        let values: Vec<f64> = data.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap())).collect();
        values.chunks_exact(width).map(<[f64]>::to_vec).collect()
    }

    #[test]
    fn rows_are_stored_north_first_like_the_tiff() {
        let map = north_ridge_map();
        let rows = stored_rows(&write(&map, X3pDataType::Float64), map.width);
        // The ridge (>= 1 mm, rising eastward) fills the first two stored rows
        // and no other; the south-west hole is the first node of the last row.
        for (r, row) in rows.iter().enumerate() {
            let ridge = row.iter().all(|&z| z >= 1e-3);
            assert_eq!(ridge, r < 2, "stored row {r}: {row:?}");
        }
        assert!(rows[0][1] > rows[0][0], "west stays west");
        assert!(rows[map.height - 1][0].is_nan() && !rows[0][0].is_nan());
        // Exactly the order of the north-up TIFF/PNG data.
        let north_up = crate::analysis::height_map::rows_north_up(&map.z, map.width);
        for (stored, z) in rows.iter().flatten().zip(north_up) {
            assert!(stored.to_bits() == (f64::from(z) * 1e-3).to_bits() || (stored.is_nan() && z.is_nan()));
        }
    }

    #[test]
    fn round_trip_of_the_north_first_layout_is_exact() {
        let map = north_ridge_map();
        let back = read_x3p(Cursor::new(write(&map, X3pDataType::Float64))).unwrap();
        assert!(!back.metadata.rows_south_first());
        assert_eq!((back.map.width, back.map.height), (map.width, map.height));
        for (a, b) in map.z.iter().zip(&back.map.z) {
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "{a} vs {b}");
        }
        for row in [0, map.height - 1] {
            assert!((back.map.y_mm(row) - map.y_mm(row)).abs() < 1e-12, "row {row}");
        }
        assert!((back.map.x_mm(0) - map.x_mm(0)).abs() < 1e-15);
    }

    /// The X3P as Sheen 0.1.0 wrote it: rows south first (row 0 = smallest
    /// Y), CY/Offset the Y of row 0, Record2 version "0.1.0", no CY comment.
    fn south_first_x3p(map: &HeightMap) -> Vec<u8> {
        let meta = X3pMetadata { version: SOUTH_FIRST_SHEEN_VERSION.into(), ..meta() };
        let new = entries(&write_x3p(Cursor::new(Vec::new()), map, &meta, X3pDataType::Float64).unwrap().into_inner());
        let data: Vec<u8> = map.z.iter().flat_map(|&z| (f64::from(z) * 1e-3).to_le_bytes()).collect();
        let xml = String::from_utf8(new[0].1.clone()).unwrap();
        let (start, end) = (xml.find("<CY>").unwrap(), xml.find("</CY>").unwrap());
        let old_cy = format!(
            "<CY>\n        <AxisType>I</AxisType>\n        <DataType>D</DataType>\n        <Increment>{:e}</Increment>\n        <Offset>{:e}</Offset>\n      ",
            map.pitch_mm * 1e-3,
            map.origin_y_mm * 1e-3
        );
        let new_md5 = new.iter().find(|(n, _)| n == DATA_BIN).map(|(_, d)| md5_hex(d)).unwrap();
        let xml = format!("{}{}{}", &xml[..start], old_cy, &xml[end..]).replace(&new_md5, &md5_hex(&data));
        let checksum = format!("{} *{MAIN_XML}\n", md5_hex(xml.as_bytes()));
        rezip(&[(MAIN_XML, xml.into_bytes()), (DATA_BIN, data), (CHECKSUM_FILE, checksum.into_bytes())])
    }

    #[test]
    fn files_of_sheen_0_1_0_still_read_right_side_up() {
        let map = north_ridge_map();
        let old = south_first_x3p(&map);
        // The constructed file really is the old layout: the ridge is last.
        let rows = stored_rows(&old, map.width);
        assert!(rows[map.height - 1].iter().all(|&z| z >= 1e-3) && rows[0][0].is_nan());
        let back = read_x3p(Cursor::new(old)).unwrap();
        assert!(back.warnings.is_empty(), "{:?}", back.warnings);
        assert!(back.metadata.rows_south_first());
        for (a, b) in map.z.iter().zip(&back.map.z) {
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "{a} vs {b}");
        }
        assert!((back.map.origin_y_mm - map.origin_y_mm).abs() < 1e-12);
        // Another instrument's "0.1.0" is not Sheen's: read north first.
        let other = X3pMetadata { manufacturer: "Acme".into(), version: SOUTH_FIRST_SHEEN_VERSION.into(), ..meta() };
        assert!(!other.rows_south_first());
    }

    #[test]
    fn damage_is_detected_and_explained() {
        let map = sample_map();
        let files = entries(&write(&map, X3pDataType::Float64));
        let get = |n: &str| files.iter().find(|(m, _)| m == n).map(|(_, b)| b.clone()).unwrap();
        // A flipped data byte fails the data checksum.
        let mut data = get("bindata/data.bin");
        data[100] ^= 0x40;
        let bad = rezip(&[
            ("main.xml", get("main.xml")),
            ("bindata/data.bin", data),
            ("md5checksum.hex", get("md5checksum.hex")),
        ]);
        let e = read_x3p(Cursor::new(bad)).unwrap_err();
        assert!(matches!(e, X3pError::DataChecksum { .. }), "{e}");
        // Truncated data: size mismatch with the expected count.
        let short = get("bindata/data.bin")[..80].to_vec();
        let bad = rezip(&[("main.xml", get("main.xml")), ("bindata/data.bin", short)]);
        let e = read_x3p(Cursor::new(bad)).unwrap_err();
        assert!(matches!(e, X3pError::DataSize { expected, found: 80, .. } if expected == 37 * 23 * 8), "{e}");
        // Too much data is refused before it is all read.
        let mut long = get("bindata/data.bin");
        long.extend_from_slice(&[0; 16]);
        let bad = rezip(&[("main.xml", get("main.xml")), ("bindata/data.bin", long)]);
        let e = read_x3p(Cursor::new(bad)).unwrap_err();
        assert!(matches!(e, X3pError::DataSize { found, .. } if found == 37 * 23 * 8 + 16), "{e}");
        // Edited metadata: read, with a warning about the main.xml checksum.
        let edited = String::from_utf8(get("main.xml")).unwrap().replace("watch plate 42", "watch plate 43");
        let ok = rezip(&[
            ("main.xml", edited.into_bytes()),
            ("bindata/data.bin", get("bindata/data.bin")),
            ("md5checksum.hex", get("md5checksum.hex")),
        ]);
        let back = read_x3p(Cursor::new(ok)).unwrap();
        assert_eq!(back.warnings.len(), 1, "{:?}", back.warnings);
        // No main.xml at all.
        let e = read_x3p(Cursor::new(rezip(&[("data.bin", vec![0; 8])]))).unwrap_err();
        assert!(e.to_string().contains("no 'main.xml'") && e.to_string().contains("data.bin"), "{e}");
        // Not a zip.
        assert!(matches!(read_x3p(Cursor::new(b"ISO5436_2".to_vec())), Err(X3pError::Zip(_))));
    }

    #[test]
    fn foreign_int16_files_with_a_valid_points_mask_are_read() {
        // 3x2 int16 heights, increment 1 nm, offset 1 um, point (1,0) invalid.
        let values: [i16; 6] = [0, 5, -3, 1000, 7, -32768];
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let valid = vec![0b0001_1101u8];
        let xml = format!(
            r#"<?xml version="1.0"?><ISO5436_2 xmlns="{NAMESPACE}"><Record1><Revision>ISO5436 - 2000</Revision>
<FeatureType>SUR</FeatureType><Axes><CX><AxisType>I</AxisType><Increment>2e-6</Increment></CX>
<CY><AxisType>I</AxisType><Increment>2e-6</Increment><Offset>1e-3</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>I</DataType><Increment>1e-9</Increment><Offset>1e-6</Offset></CZ></Axes></Record1>
<Record3><MatrixDimension><SizeX>3</SizeX><SizeY>2</SizeY><SizeZ>1</SizeZ></MatrixDimension><DataLink>
<PointDataLink>bindata/data.bin</PointDataLink><MD5ChecksumPointData>{}</MD5ChecksumPointData>
<ValidPointsLink>bindata/valid.bin</ValidPointsLink><MD5ChecksumValidPoints>{}</MD5ChecksumValidPoints>
</DataLink></Record3><Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4></ISO5436_2>"#,
            md5_hex(&data).to_uppercase(),
            md5_hex(&valid)
        );
        let bytes = rezip(&[("main.xml", xml.into_bytes()), ("bindata/data.bin", data), ("bindata/valid.bin", valid)]);
        let f = read_x3p(Cursor::new(bytes)).unwrap();
        assert_eq!(f.warnings.len(), 1, "missing checksum file is a warning");
        // Row 0 is north, file Y southward: the map's rows reversed, its Y
        // minus the file's (north row at -1 mm, the other at -1.002 mm).
        assert!((f.map.pitch_mm - 0.002).abs() < 1e-15 && (f.map.origin_y_mm + 1.002).abs() < 1e-12);
        let expect_um = [2.0, 1.007, f64::NAN, 1.0, f64::NAN, 0.997];
        for (z, e) in f.map.z.iter().zip(expect_um) {
            if e.is_nan() {
                assert!(z.is_nan());
            } else {
                assert!((f64::from(*z) * 1e3 - e).abs() < 1e-6, "{z} vs {e}");
            }
        }
    }

    #[test]
    fn dates_are_utc_xsd_date_times() {
        use std::time::{Duration, UNIX_EPOCH};
        assert_eq!(xsd_date_time_utc(UNIX_EPOCH), "1970-01-01T00:00:00Z");
        // 2024-02-29T23:59:59Z (leap day) = 1709251199 s.
        assert_eq!(xsd_date_time_utc(UNIX_EPOCH + Duration::from_secs(1_709_251_199)), "2024-02-29T23:59:59Z");
        assert_eq!(xsd_date_time_utc(UNIX_EPOCH + Duration::from_secs(951_782_400)), "2000-02-29T00:00:00Z");
        let t = zip_time("2024-02-29T23:59:59Z");
        assert_eq!((t.year(), t.month(), t.day(), t.hour(), t.minute()), (2024, 2, 29, 23, 59));
    }
}
