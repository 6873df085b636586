//! Height maps from other instruments (a confocal microscope, an
//! interferometer, a profilometer, another program) as input, so the same
//! inspection runs on them as on Sheen's own maps: ISO 25178-72
//! X3P, ISO 25178-71 SDF and single-channel float TIFF.
//!
//! X3P and SDF carry their scales; a TIFF carries none, so its pixel size
//! and height unit come from the caller, and its rows are read north up
//! (first row = largest Y), as Sheen writes its TIFF maps. Every format
//! comes back in the map's own layout: row 0 at the smallest Y, mm.

use crate::engine::warning::Warning;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use crate::analysis::error::AnalysisError;
use crate::analysis::height_map::{HeightMap, rows_north_up};
use crate::engine::length_unit::LengthUnit;
use crate::io::IoError;
use crate::io::sdf::{SdfError, read_sdf};
use crate::io::x3p::{X3pError, read_x3p};

/// The file formats a height map is read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeightMapFormat {
    X3p,
    Sdf,
    Tiff,
}

impl HeightMapFormat {
    pub fn name(self) -> &'static str {
        match self {
            Self::X3p => "X3P",
            Self::Sdf => "SDF",
            Self::Tiff => "TIFF",
        }
    }

    /// The format of `path` by its extension, else by its first bytes
    /// (zip, an SDF magic, a TIFF byte order mark); `None` when it is none of them.
    pub fn of(path: &Path) -> Option<Self> {
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("x3p") => return Some(Self::X3p),
            Some("sdf") => return Some(Self::Sdf),
            Some("tif" | "tiff") => return Some(Self::Tiff),
            _ => {}
        }
        let mut head = [0u8; 8];
        let n = std::fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut head)).ok()?;
        match &head[..n] {
            [b'P', b'K', 3, 4, ..] => Some(Self::X3p),
            [b'a' | b'b', b'I', b'S', b'O', ..] | [b'a' | b'b', b'B', b'C', b'R', ..] => Some(Self::Sdf),
            [b'I', b'I', 42, 0, ..] | [b'M', b'M', 0, 42, ..] => Some(Self::Tiff),
            _ => None,
        }
    }
}

/// What a TIFF height map does not say about itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TiffMapScale {
    /// The pixel size in mm (square pixels); required for a TIFF.
    pub pixel_mm: Option<f64>,
    /// The unit of its values; micrometres, as Sheen writes them, by default.
    pub z_unit: LengthUnit,
}

impl Default for TiffMapScale {
    fn default() -> Self {
        Self { pixel_mm: None, z_unit: LengthUnit::Um }
    }
}

/// Why a height-map file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum HeightMapFault {
    #[error("X3P: {0}")]
    X3p(#[from] X3pError),
    #[error("SDF: {0}")]
    Sdf(#[from] SdfError),
    #[error("TIFF: {0}")]
    Tiff(#[from] TiffFault),
    #[error("a TIFF says nothing of its pixel size; give it (--pixel-mm in `sheen analyze`)")]
    NoPixelSize,
    #[error("pixel size {0} mm is not a positive length")]
    BadPixelSize(f64),
    #[error("is neither an X3P, an SDF nor a TIFF height map")]
    UnknownFormat,
    #[error("holds no valid height ({width}x{height} nodes, all holes)")]
    NoData { width: usize, height: usize },
}

/// What is wrong with a float TIFF height map.
#[derive(Debug, thiserror::Error)]
pub enum TiffFault {
    #[error("{0}")]
    Open(#[source] std::io::Error),
    #[error("{0}")]
    Decode(#[from] tiff::TiffError),
    #[error("holds integer samples; a height map TIFF holds float32 or float64 heights")]
    IntegerSamples,
    #[error("holds {values} values for {width}x{height} pixels")]
    ValueCount { values: usize, width: usize, height: usize },
    #[error("{0}")]
    Map(#[from] AnalysisError),
}

/// A height map read from a file, with what it is and what was adjusted.
#[derive(Clone, Debug)]
pub struct ForeignHeightMap {
    pub map: HeightMap,
    pub format: HeightMapFormat,
    /// Who wrote it, where the file says (X3P Record2, SDF ManufacID).
    pub writer: Option<String>,
    /// Problems that did not stop reading: resampling, unchecked data.
    pub warnings: Vec<Warning>,
}

/// Reads the height map at `path` (module docs); `tiff` scales a TIFF and is
/// ignored for the formats that carry their scales.
pub fn read_height_map_file(path: &Path, tiff: &TiffMapScale) -> Result<ForeignHeightMap, IoError> {
    let fault = |fault: HeightMapFault| IoError::HeightMap { path: path.to_path_buf(), fault };
    let format = HeightMapFormat::of(path).ok_or_else(|| fault(HeightMapFault::UnknownFormat))?;
    let open = || {
        std::fs::File::open(path)
            .map(BufReader::new)
            .map_err(|source| IoError::Read { path: PathBuf::from(path), source })
    };
    let read = match format {
        HeightMapFormat::X3p => {
            let f = read_x3p(open()?).map_err(|e| fault(e.into()))?;
            let m = &f.metadata;
            let writer = [m.manufacturer.as_str(), m.model.as_str(), m.version.as_str()]
                .iter()
                .filter(|s| !s.is_empty())
                .copied()
                .collect::<Vec<_>>()
                .join(" ");
            ForeignHeightMap {
                map: f.map,
                format,
                writer: (!writer.is_empty()).then_some(writer),
                warnings: f.warnings,
            }
        }
        HeightMapFormat::Sdf => {
            let f = read_sdf(open()?).map_err(|e| fault(e.into()))?;
            let writer = (!f.manufacturer.is_empty()).then_some(f.manufacturer);
            ForeignHeightMap { map: f.map, format, writer, warnings: f.warnings }
        }
        HeightMapFormat::Tiff => read_tiff(path, tiff).map_err(fault)?,
    };
    if read.map.valid_count() == 0 {
        return Err(fault(HeightMapFault::NoData { width: read.map.width, height: read.map.height }));
    }
    Ok(read)
}

fn read_tiff(path: &Path, scale: &TiffMapScale) -> Result<ForeignHeightMap, HeightMapFault> {
    let pixel_mm = scale.pixel_mm.ok_or(HeightMapFault::NoPixelSize)?;
    if !(pixel_mm.is_finite() && pixel_mm > 0.0) {
        return Err(HeightMapFault::BadPixelSize(pixel_mm));
    }
    let file = std::fs::File::open(path).map_err(TiffFault::Open)?;
    let mut decoder = tiff::decoder::Decoder::new(BufReader::new(file)).map_err(TiffFault::from)?;
    let (w, h) = decoder.dimensions().map_err(TiffFault::from)?;
    let (w, h) = (w as usize, h as usize);
    let scale_to_mm = scale.z_unit.mm_per_unit();
    let values: Vec<f32> = match decoder.read_image().map_err(TiffFault::from)? {
        tiff::decoder::DecodingResult::F32(d) => d.iter().map(|&v| (f64::from(v) * scale_to_mm) as f32).collect(),
        tiff::decoder::DecodingResult::F64(d) => d.iter().map(|&v| (v * scale_to_mm) as f32).collect(),
        _ => {
            return Err(TiffFault::IntegerSamples.into());
        }
    };
    if values.len() != w * h {
        return Err(TiffFault::ValueCount { values: values.len(), width: w, height: h }.into());
    }
    // Infinities are no height either.
    let values: Vec<f32> = values.into_iter().map(|v| if v.is_finite() { v } else { f32::NAN }).collect();
    let map = HeightMap::new(w, h, 0.0, 0.0, pixel_mm, rows_north_up(&values, w)).map_err(TiffFault::from)?;
    Ok(ForeignHeightMap { map, format: HeightMapFormat::Tiff, writer: None, warnings: Vec::new() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::maps::{TiffCompression, write_f32_tiff};

    #[test]
    fn a_float_tiff_reads_north_up_with_the_given_pixel_and_unit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("confocal.tif");
        // First row (north) 1, 2, 3 nm; second 4, NaN, 6 nm.
        write_f32_tiff(&path, 3, 2, &[1.0, 2.0, 3.0, 4.0, f32::NAN, 6.0], TiffCompression::None).unwrap();
        let scale = TiffMapScale { pixel_mm: Some(0.0005), z_unit: LengthUnit::Nm };
        let f = read_height_map_file(&path, &scale).unwrap();
        assert_eq!((f.format, f.map.width, f.map.height, f.map.pitch_mm), (HeightMapFormat::Tiff, 3, 2, 0.0005));
        // Map row 0 is the south (second) row of the image.
        let nm: Vec<f64> = f.map.z.iter().map(|&z| f64::from(z) * 1e6).collect();
        assert!((nm[0] - 4.0).abs() < 1e-4 && nm[1].is_nan() && (nm[3] - 1.0).abs() < 1e-4, "{nm:?}");
        let e = read_height_map_file(&path, &TiffMapScale::default()).unwrap_err();
        assert!(matches!(e, IoError::HeightMap { fault: HeightMapFault::NoPixelSize, .. }), "{e}");
        assert!(e.to_string().contains("confocal.tif") && e.to_string().contains("--pixel-mm"), "{e}");
    }

    #[test]
    fn formats_are_known_by_extension_and_by_content() {
        let dir = tempfile::tempdir().unwrap();
        let sdf = dir.path().join("scan.dat");
        std::fs::write(&sdf, b"aISO-1.0\n").unwrap();
        assert_eq!(HeightMapFormat::of(&sdf), Some(HeightMapFormat::Sdf));
        let text = dir.path().join("notes.dat");
        std::fs::write(&text, b"hello world").unwrap();
        assert_eq!(HeightMapFormat::of(&text), None);
        let e = read_height_map_file(&text, &TiffMapScale::default()).unwrap_err();
        assert!(matches!(e, IoError::HeightMap { fault: HeightMapFault::UnknownFormat, .. }), "{e}");
        let holes = dir.path().join("holes.tif");
        write_f32_tiff(&holes, 2, 1, &[f32::NAN, f32::INFINITY], TiffCompression::None).unwrap();
        let e = read_height_map_file(&holes, &TiffMapScale { pixel_mm: Some(0.01), ..Default::default() }).unwrap_err();
        assert!(matches!(e, IoError::HeightMap { fault: HeightMapFault::NoData { .. }, .. }), "{e}");
    }
}
