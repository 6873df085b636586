//! SDF (ISO 25178-71, the Surfstand "surface data file") height maps as
//! other instruments and programs write them (Gwyddion, MountainsMap,
//! surfalize, profilometer software), so their maps can be inspected like
//! Sheen's own.
//!
//! Two encodings share one header:
//! - text: a magic line (`aISO-1.0`, `aISO-2.0`, `aBCR-1.0`...), `Key = Value`
//!   lines (ManufacID, CreateDate, ModDate, NumPoints, NumProfiles, Xscale,
//!   Yscale, Zscale, Zresolution, Compression, DataType, CheckType), `*`, the
//!   values separated by white space (`BAD` for a point not measured), `*`,
//!   an optional trailer of `Key = Value` lines and a last `*`;
//! - binary: the magic (`bISO-1.0`, `bISO-2.0`, `bBCR-1.0`), ManufacID (10
//!   bytes), CreateDate and ModDate (12 each), NumPoints and NumProfiles
//!   (u16, u32 in ISO-2.0), Xscale, Yscale, Zscale, Zresolution (f64),
//!   Compression, DataType, CheckType (u8), all little-endian, then the
//!   values; a point not measured holds its type's minimum value.
//!
//! Scales are metres per unit (heights are value x Zscale). Values run
//! profile by profile, NumPoints to a profile (X fastest). Profile 0 is read
//! as the map's north edge, as Gwyddion and MountainsMap draw it at the top
//! and as Sheen's X3P stores it, so a map looks the same in every program.

use crate::engine::warning::Warning;
use std::io::Read;

use crate::analysis::height_map::{HeightMap, MAX_MAP_NODES};

/// What an SDF file could not be read for.
#[derive(Debug, thiserror::Error)]
pub enum SdfError {
    #[error("cannot read it: {0}")]
    Io(#[from] std::io::Error),
    #[error("is not an SDF file: it starts with {found:?}, not a magic such as \"aISO-1.0\" or \"bISO-1.0\"")]
    NotSdf { found: String },
    #[error("header: {reason}")]
    Header { reason: String },
    #[error("{what} is not supported")]
    Unsupported { what: String },
    #[error("holds {found} values, but its header declares {expected} ({width} points x {height} profiles)")]
    DataSize { expected: usize, found: usize, width: usize, height: usize },
    #[error("value {index} ('{token}') is not a number")]
    BadNumber { index: usize, token: String },
}

/// A height map read from an SDF file.
#[derive(Clone, Debug, PartialEq)]
pub struct SdfFile {
    pub map: HeightMap,
    /// The header's ManufacID, trimmed.
    pub manufacturer: String,
    /// Problems that do not stop reading (a grid resampled to one pitch).
    pub warnings: Vec<Warning>,
}

/// The header fields a map needs.
struct Header {
    manufacturer: String,
    width: usize,
    height: usize,
    x_scale_m: f64,
    y_scale_m: f64,
    z_scale_m: f64,
    data_type: u8,
}

/// Bytes per value of each DataType (0..=2 unsigned, which older writers
/// use, 3 float32, 4..=6 signed, 7 float64).
fn value_size(data_type: u8) -> Option<usize> {
    [1, 2, 4, 4, 1, 2, 4, 8].get(usize::from(data_type)).copied()
}

/// Reads an SDF file, text or binary (module docs).
pub fn read_sdf<R: Read>(mut reader: R) -> Result<SdfFile, SdfError> {
    let mut bytes = Vec::new();
    reader.read_to_end(&mut bytes)?;
    let magic = String::from_utf8_lossy(&bytes[..bytes.len().min(8)]).into_owned();
    let known = ["ISO-1.0", "ISO-2.0", "BCR-1.0", "BCR-0.0"];
    let dialect = magic.get(1..).filter(|d| known.contains(d));
    let (header, z) = match (magic.as_bytes().first(), dialect) {
        (Some(b'a'), Some(_)) => read_text(&bytes[8..])?,
        (Some(b'b'), Some(d)) => read_binary(&bytes[8..], d == "ISO-2.0")?,
        _ => return Err(SdfError::NotSdf { found: magic }),
    };
    let [dx_mm, dy_mm] = [header.x_scale_m * 1e3, header.y_scale_m * 1e3];
    // Profile 0 is north: the map's rows run south first.
    let z_mm: Vec<f32> =
        z.chunks_exact(header.width).rev().flatten().map(|&v| (v * header.z_scale_m * 1e3) as f32).collect();
    let (map, resampled) =
        HeightMap::from_rectangular_grid(header.width, header.height, 0.0, 0.0, [dx_mm, dy_mm], z_mm)
            .map_err(|e| SdfError::Header { reason: e.to_string() })?;
    Ok(SdfFile { map, manufacturer: header.manufacturer, warnings: resampled.into_iter().collect() })
}

fn header_error(reason: impl Into<String>) -> SdfError {
    SdfError::Header { reason: reason.into() }
}

/// Checks what every header must hold, whichever encoding it came in.
fn check_header(h: &Header) -> Result<(), SdfError> {
    if h.width == 0 || h.height == 0 {
        return Err(header_error(format!("NumPoints {} x NumProfiles {} is an empty map", h.width, h.height)));
    }
    if h.width.saturating_mul(h.height) > MAX_MAP_NODES {
        return Err(header_error(format!(
            "{} x {} points is more than the {MAX_MAP_NODES} nodes Sheen reads",
            h.width, h.height
        )));
    }
    for (name, v) in [("Xscale", h.x_scale_m), ("Yscale", h.y_scale_m)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(header_error(format!("{name} {v} is not a positive length in metres")));
        }
    }
    if !(h.z_scale_m.is_finite() && h.z_scale_m != 0.0) {
        return Err(header_error(format!("Zscale {} is not a finite, non-zero scale in metres", h.z_scale_m)));
    }
    if value_size(h.data_type).is_none() {
        return Err(SdfError::Unsupported { what: format!("DataType {}", h.data_type) });
    }
    Ok(())
}

fn read_text(body: &[u8]) -> Result<(Header, Vec<f64>), SdfError> {
    let text = std::str::from_utf8(body).map_err(|_| header_error("a text SDF must be ASCII"))?;
    let mut records = text.splitn(3, '*');
    let (Some(head), Some(data)) = (records.next(), records.next()) else {
        return Err(header_error("no '*' ends the header and starts the data"));
    };
    let mut fields = std::collections::HashMap::new();
    for line in head.lines().map(str::trim).filter(|l| !l.is_empty()) {
        let Some((k, v)) = line.split_once('=') else {
            return Err(header_error(format!("line '{line}' is not 'Key = Value'")));
        };
        fields.insert(k.trim().to_string(), v.trim().to_string());
    }
    let get = |k: &str| fields.get(k).ok_or_else(|| header_error(format!("no {k}")));
    let int = |k: &str| -> Result<u64, SdfError> {
        let v = get(k)?;
        v.parse().map_err(|_| header_error(format!("{k} '{v}' is not a whole number")))
    };
    let real = |k: &str| -> Result<f64, SdfError> {
        let v = get(k)?;
        v.parse().map_err(|_| header_error(format!("{k} '{v}' is not a number")))
    };
    let flag = |k: &str| fields.get(k).map_or(Ok(0), |_| int(k));
    let header = Header {
        manufacturer: fields.get("ManufacID").cloned().unwrap_or_default(),
        width: int("NumPoints")? as usize,
        height: int("NumProfiles")? as usize,
        x_scale_m: real("Xscale")?,
        y_scale_m: real("Yscale")?,
        z_scale_m: real("Zscale")?,
        data_type: u8::try_from(flag("DataType")?).unwrap_or(u8::MAX),
    };
    check_flags(flag("Compression")?, flag("CheckType")?)?;
    check_header(&header)?;
    let n = header.width * header.height;
    let mut z = Vec::with_capacity(n);
    for (index, token) in data.split_whitespace().enumerate() {
        let v = if token.eq_ignore_ascii_case("BAD") {
            f64::NAN
        } else {
            token.parse::<f64>().map_err(|_| SdfError::BadNumber { index, token: token.to_string() })?
        };
        z.push(v);
    }
    if z.len() != n {
        return Err(SdfError::DataSize { expected: n, found: z.len(), width: header.width, height: header.height });
    }
    Ok((header, z))
}

fn check_flags(compression: u64, check_type: u64) -> Result<(), SdfError> {
    if compression != 0 {
        return Err(SdfError::Unsupported { what: format!("Compression {compression}") });
    }
    if check_type != 0 {
        return Err(SdfError::Unsupported { what: format!("CheckType {check_type}") });
    }
    Ok(())
}

fn read_binary(body: &[u8], wide_dimensions: bool) -> Result<(Header, Vec<f64>), SdfError> {
    let dims = if wide_dimensions { 8 } else { 4 };
    let header_len = 10 + 12 + 12 + dims + 4 * 8 + 3;
    if body.len() < header_len {
        return Err(header_error(format!(
            "the binary header needs {} bytes, the file has {}",
            header_len + 8,
            body.len() + 8
        )));
    }
    let f64_at = |o: usize| f64::from_le_bytes(body[o..o + 8].try_into().unwrap_or_default());
    let manufacturer =
        String::from_utf8_lossy(body[..10].split(|&b| b == 0).next().unwrap_or_default()).trim().to_string();
    let mut o = 34;
    let (width, height) = if wide_dimensions {
        let w = u32::from_le_bytes(body[o..o + 4].try_into().unwrap_or_default());
        let h = u32::from_le_bytes(body[o + 4..o + 8].try_into().unwrap_or_default());
        (w as usize, h as usize)
    } else {
        let w = u16::from_le_bytes([body[o], body[o + 1]]);
        let h = u16::from_le_bytes([body[o + 2], body[o + 3]]);
        (usize::from(w), usize::from(h))
    };
    o += dims;
    let header = Header {
        manufacturer,
        width,
        height,
        x_scale_m: f64_at(o),
        y_scale_m: f64_at(o + 8),
        z_scale_m: f64_at(o + 16),
        data_type: body[o + 33],
    };
    check_flags(u64::from(body[o + 32]), u64::from(body[o + 34]))?;
    check_header(&header)?;
    let size = value_size(header.data_type).unwrap_or(8);
    let n = header.width * header.height;
    let data = &body[header_len..];
    if data.len() < n * size {
        return Err(SdfError::DataSize { expected: n, found: data.len() / size, width, height });
    }
    let t = header.data_type;
    let z = data[..n * size]
        .chunks_exact(size)
        .map(|b| {
            // A point not measured holds its type's minimum (ISO 25178-71).
            let (v, missing) = match t {
                0 => (f64::from(b[0]), false),
                1 => (f64::from(u16::from_le_bytes([b[0], b[1]])), false),
                2 => (f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])), false),
                3 => {
                    let v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                    (f64::from(v), v == f32::MIN)
                }
                4 => (f64::from(b[0] as i8), b[0] as i8 == i8::MIN),
                5 => {
                    let v = i16::from_le_bytes([b[0], b[1]]);
                    (f64::from(v), v == i16::MIN)
                }
                6 => {
                    let v = i32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                    (f64::from(v), v == i32::MIN)
                }
                _ => {
                    let v = f64::from_le_bytes(b.try_into().unwrap_or_default());
                    (v, v == f64::MIN)
                }
            };
            if missing { f64::NAN } else { v }
        })
        .collect();
    Ok((header, z))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 3 points x 2 profiles, 2 um by 1 um, heights in nm; profile 0 (north)
    /// = 10, BAD, 30; profile 1 = 40, 50, 60.
    const TEXT: &str = "aISO-1.0\r\nManufacID = Test\r\nCreateDate = 010120241200\r\nModDate = 010120241200\r\n\
        NumPoints = 3\r\nNumProfiles = 2\r\nXscale = 2e-6\r\nYscale = 1e-6\r\nZscale = 1e-9\r\nZresolution = -1\r\n\
        Compression = 0\r\nDataType = 7\r\nCheckType = 0\r\n*\r\n10 BAD 30\r\n40 50 60\r\n*\r\nOperator = Jo\r\n*\r\n";

    #[test]
    fn a_text_sdf_reads_north_first_in_millimetres_and_resamples_to_one_pitch() {
        let f = read_sdf(TEXT.as_bytes()).unwrap();
        assert_eq!(f.manufacturer, "Test");
        // Resampled at the finer 1 um: 5 columns, 2 rows; map row 0 is the south profile.
        assert_eq!((f.map.width, f.map.height, f.map.pitch_mm), (5, 2, 0.001));
        let south: Vec<f32> = f.map.z[..5].to_vec();
        let expect = [40e-6, 45e-6, 50e-6, 55e-6, 60e-6];
        for (z, e) in south.iter().zip(expect) {
            // f32 heights: 1e-11 mm is a few ulps at 60 nm.
            assert!((f64::from(*z) - e).abs() < 1e-11, "{z} vs {e}");
        }
        // North profile: the BAD point is never bridged.
        assert!((f64::from(f.map.z[5]) - 10e-6).abs() < 1e-11);
        assert!(f.map.z[6..9].iter().all(|z| z.is_nan()));
        assert!((f64::from(f.map.z[9]) - 30e-6).abs() < 1e-11);
        assert_eq!(f.warnings.len(), 1);
    }

    fn binary(magic: &[u8; 8], w: u32, h: u32, data_type: u8, values: &[u8]) -> Vec<u8> {
        let mut b = magic.to_vec();
        b.extend_from_slice(b"Mountains\0");
        b.extend_from_slice(b"010120241200010120241200");
        if magic.starts_with(b"bISO-2.0") {
            b.extend_from_slice(&w.to_le_bytes());
            b.extend_from_slice(&h.to_le_bytes());
        } else {
            b.extend_from_slice(&(w as u16).to_le_bytes());
            b.extend_from_slice(&(h as u16).to_le_bytes());
        }
        for v in [1e-6f64, 1e-6, 1e-9, -1.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&[0, data_type, 0]);
        b.extend_from_slice(values);
        b
    }

    #[test]
    fn binary_sdf_of_each_dialect_and_type_with_missing_points() {
        let i16s: Vec<u8> = [1i16, i16::MIN, 3, 4].iter().flat_map(|v| v.to_le_bytes()).collect();
        let f = read_sdf(&binary(b"bISO-1.0", 2, 2, 5, &i16s)[..]).unwrap();
        assert_eq!((f.map.width, f.map.height, f.map.pitch_mm, f.manufacturer.as_str()), (2, 2, 0.001, "Mountains"));
        // North profile (1, missing) becomes map row 1.
        let nm: Vec<f64> = f.map.z.iter().map(|&z| f64::from(z) * 1e6).collect();
        assert!((nm[0] - 3.0).abs() < 1e-4 && (nm[1] - 4.0).abs() < 1e-4 && (nm[2] - 1.0).abs() < 1e-4, "{nm:?}");
        assert!(nm[3].is_nan());
        let f64s: Vec<u8> = [1.0f64, 2.0, f64::MIN, 4.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let f = read_sdf(&binary(b"bISO-2.0", 2, 2, 7, &f64s)[..]).unwrap();
        // The south profile (missing, 4) is map row 0.
        assert!(
            f.map.z[0].is_nan()
                && (f64::from(f.map.z[1]) - 4e-6).abs() < 1e-12
                && f.map.z[2..].iter().all(|z| z.is_finite())
        );
        assert_eq!(f.map.z.iter().filter(|z| z.is_nan()).count(), 1);
    }

    #[test]
    fn faults_name_what_is_wrong() {
        let e = read_sdf(&b"PK\x03\x04 not an sdf"[..]).unwrap_err();
        assert!(matches!(e, SdfError::NotSdf { .. }), "{e}");
        let short = TEXT.replace("40 50 60", "40 50");
        let e = read_sdf(short.as_bytes()).unwrap_err();
        assert!(matches!(e, SdfError::DataSize { expected: 6, found: 5, .. }), "{e}");
        let e = read_sdf(TEXT.replace("Compression = 0", "Compression = 1").as_bytes()).unwrap_err();
        assert!(matches!(&e, SdfError::Unsupported { what } if what == "Compression 1"), "{e}");
        let e = read_sdf(TEXT.replace("Xscale = 2e-6", "Xscale = 0").as_bytes()).unwrap_err();
        assert!(e.to_string().contains("Xscale 0"), "{e}");
        let e = read_sdf(TEXT.replace("30", "3O").as_bytes()).unwrap_err();
        assert!(matches!(&e, SdfError::BadNumber { index: 2, token } if token == "3O"), "{e}");
        let e = read_sdf(&binary(b"bISO-1.0", 2, 2, 5, &[0; 6])[..]).unwrap_err();
        assert!(matches!(e, SdfError::DataSize { expected: 4, found: 3, .. }), "{e}");
        let e = read_sdf(&binary(b"bISO-1.0", 2, 2, 9, &[0; 8])[..]).unwrap_err();
        assert!(matches!(&e, SdfError::Unsupported { what } if what == "DataType 9"), "{e}");
    }
}
