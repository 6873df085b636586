//! Map files: every per-camera intermediate of the method as a float32 TIFF
//! (the data) beside a colour-mapped PNG of the same stem (the look), a
//! contract shared by `sheen phase --maps` and `sheen reconstruct --maps`
//!. In a map folder, per camera:
//!
//! - `{camera}_fused_phase.tif`: absolute phase in radians of the densest
//!   period (Alg. 3), NaN where invalid;
//! - `{camera}_fused_sigma.tif`: its standard deviation (rad);
//! - `{camera}_source.tif`: the manifest set index that supplied each pixel,
//!   -1 for none, -2 where a fringe order failed its check;
//!
//! and per set, with the period written as an integer when it is one
//! (`912`, not `0912`; `22.5` stays `22.5`):
//!
//! - `{camera}_saturation_{period}.tif`: saturated samples per pixel (Alg. 1);
//! - `{camera}_wrapped_{period}.tif`: wrapped phase in [0, 2 pi) (Alg. 2), NaN invalid;
//! - `{camera}_modulation_{period}.tif`: fringe modulation `B` (DN);
//! - `{camera}_unwrapped_{period}.tif`: unwrapped phase (rad of that period),
//!   only for sets that took part in unwrapping;
//! - `{camera}_phase_sigma_{period}.tif`: wrapped-phase standard deviation (rad).
//!
//! A camera–projector rig with a Gray code adds, per axis (`x`, and `y`
//! where a row code and sets along y are given):
//!
//! - `{camera}_projector_{axis}.tif`: absolute projector coordinate in
//!   projector pixels (pixel centres at integers), NaN where refused;
//! - `{camera}_projector_{axis}_sigma.tif`: its standard deviation from the
//!   phase noise (projector pixels);
//! - `{camera}_gray_code_{axis}.tif`: the decoded code unit, NaN where the
//!   code has none (shadow, an undecided bit, beyond the projector).
//!
//! TIFFs are single-channel IEEE float32 (SampleFormat 3), uncompressed by
//! default: checked to open in tifffile and in Gwyddion 2.62
//! (`gwyddion-thumbnailer`, NaN shown as its invalid-data mask). Deflate is
//! available for size; tifffile reads it, but Gwyddion 2.62 does not.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype::Gray32Float};

use super::atomic::write_atomic;
use super::colormap::{ColorBar, Colormap, ValueRange, write_map_png};
use super::error::IoError;
use crate::engine::camera_projector::ProjectorMaps;
use crate::engine::pipeline::CameraPhase;

/// Compression of written TIFFs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TiffCompression {
    /// Largest files, readable everywhere (Gwyddion included).
    #[default]
    None,
    /// Lossless zlib/deflate (TIFF compression 8): much smaller maps where
    /// large areas are invalid or constant; Gwyddion 2.62 cannot open these.
    Deflate,
}

/// How [`write_camera_maps_with`] writes the maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MapWriteOptions {
    pub compression: TiffCompression,
    /// Also write a colour-mapped PNG beside each TIFF.
    pub previews: bool,
}

impl Default for MapWriteOptions {
    fn default() -> Self {
        Self { compression: TiffCompression::None, previews: true }
    }
}

/// A float32 map read back from a TIFF.
#[derive(Clone, Debug, PartialEq)]
pub struct FloatMap {
    pub width: usize,
    pub height: usize,
    /// Row-major samples.
    pub data: Vec<f32>,
}

fn invalid_input(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// Writes a row-major `width` x `height` float32 map as a single-channel
/// TIFF, atomically. NaN and every other value are kept bit for bit.
pub fn write_f32_tiff(
    path: &Path,
    width: usize,
    height: usize,
    data: &[f32],
    compression: TiffCompression,
) -> Result<(), IoError> {
    if data.len() != width * height || width == 0 || height == 0 {
        return Err(IoError::Write {
            path: path.to_path_buf(),
            source: invalid_input(format!("map of {} values is not {width}x{height} px", data.len())),
        });
    }
    let (w, h) = match (u32::try_from(width), u32::try_from(height)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => {
            return Err(IoError::Write {
                path: path.to_path_buf(),
                source: invalid_input(format!("{width}x{height} px is too large for TIFF")),
            });
        }
    };
    write_atomic(path, |writer| {
        let encoder = TiffEncoder::new(writer).map_err(std::io::Error::other)?;
        let mut encoder = match compression {
            TiffCompression::None => encoder,
            TiffCompression::Deflate => encoder.with_compression(Compression::Deflate(DeflateLevel::Balanced)),
        };
        encoder.write_image::<Gray32Float>(w, h, data).map_err(std::io::Error::other)
    })
}

/// Reads a single-channel float32 TIFF (what [`write_f32_tiff`] writes).
pub fn read_f32_tiff(path: &Path) -> Result<FloatMap, IoError> {
    let file = std::fs::File::open(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    let tiff_err = |e: tiff::TiffError| IoError::Tiff { path: path.to_path_buf(), message: e.to_string() };
    let mut decoder = tiff::decoder::Decoder::new(BufReader::new(file)).map_err(tiff_err)?;
    let (w, h) = decoder.dimensions().map_err(tiff_err)?;
    match decoder.read_image().map_err(tiff_err)? {
        tiff::decoder::DecodingResult::F32(data) if data.len() == w as usize * h as usize => {
            Ok(FloatMap { width: w as usize, height: h as usize, data })
        }
        _ => Err(IoError::Tiff {
            path: path.to_path_buf(),
            message: "is not a single-channel float32 image; Sheen's map files are float32 TIFF".into(),
        }),
    }
}

/// A period as it appears in file names: `912`, `22.5`.
pub fn period_label(period_px: f64) -> String {
    if period_px.fract() == 0.0 && period_px.abs() < 1e15 {
        format!("{}", period_px as i64)
    } else {
        format!("{period_px}")
    }
}

/// Writes every map of one camera into `dir` (uncompressed TIFFs with PNG
/// previews); returns the files written. `periods_px` are the manifest's
/// periods, one per entry of `camera.sets`.
pub fn write_camera_maps(dir: &Path, camera: &CameraPhase, periods_px: &[f64]) -> Result<Vec<PathBuf>, IoError> {
    write_camera_maps_with(dir, camera, periods_px, &MapWriteOptions::default())
}

/// One map to write: file stem, data, and how to preview it.
struct MapSpec<'a> {
    stem: String,
    data: std::borrow::Cow<'a, [f32]>,
    colormap: Colormap,
    range: ValueRange,
    bar: ColorBar,
}

/// [`write_camera_maps`] with a choice of compression and previews.
pub fn write_camera_maps_with(
    dir: &Path,
    camera: &CameraPhase,
    periods_px: &[f64],
    options: &MapWriteOptions,
) -> Result<Vec<PathBuf>, IoError> {
    let name = &camera.camera;
    let fault =
        |message: String| IoError::Write { path: dir.join(format!("{name}_*")), source: invalid_input(message) };
    if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
        return Err(fault(format!("camera name '{name}' cannot be part of a file name")));
    }
    if periods_px.len() != camera.sets.len() {
        return Err(fault(format!("{} periods given for {} sets", periods_px.len(), camera.sets.len())));
    }
    let (w, h) = (camera.width, camera.height);
    let sigma_range = |map: &[f32]| {
        ValueRange::quantiles(map, 0.0, 0.99).map_or(ValueRange::new(0.0, 1.0), |r| ValueRange::new(0.0, r.max))
    };
    let finite_range = |map: &[f32]| ValueRange::of_finite(map).unwrap_or(ValueRange::new(0.0, 1.0));
    let source_bar = ColorBar {
        unit: "set".into(),
        categories: periods_px
            .iter()
            .enumerate()
            .map(|(s, p)| (s as i32, format!("{} px", period_label(*p))))
            .collect(),
    };
    let mut maps = vec![
        MapSpec {
            stem: format!("{name}_fused_phase"),
            data: (&camera.fused.fused_phase_rad[..]).into(),
            colormap: Colormap::Turbo,
            range: finite_range(&camera.fused.fused_phase_rad),
            bar: ColorBar::unit("rad"),
        },
        MapSpec {
            stem: format!("{name}_fused_sigma"),
            data: (&camera.fused.fused_sigma_rad[..]).into(),
            colormap: Colormap::Viridis,
            range: sigma_range(&camera.fused.fused_sigma_rad),
            bar: ColorBar::unit("rad"),
        },
        MapSpec {
            stem: format!("{name}_source"),
            data: camera.fused.source_set.iter().map(|&s| f32::from(s)).collect::<Vec<_>>().into(),
            colormap: Colormap::SourceSet,
            range: ValueRange::new(0.0, periods_px.len().saturating_sub(1) as f32),
            bar: source_bar,
        },
        MapSpec {
            // How the fused pixel's fringe orders were decided :
            // 0 on its own samples, 1 confirmed by neighbours, 2 against the
            // sparser set averaged over its patch or neighbourhood; NaN invalid.
            stem: format!("{name}_order_evidence"),
            data: camera
                .fused
                .order_evidence
                .iter()
                .zip(&camera.fused.fused_phase_rad)
                .map(|(&e, phase)| if phase.is_nan() { f32::NAN } else { f32::from(e) })
                .collect::<Vec<_>>()
                .into(),
            colormap: Colormap::Viridis,
            range: ValueRange::new(0.0, 2.0),
            bar: ColorBar::unit("evidence"),
        },
    ];
    for (s, set) in camera.sets.iter().enumerate() {
        let p = period_label(periods_px[s]);
        maps.push(MapSpec {
            stem: format!("{name}_saturation_{p}"),
            data: set.saturation_count.iter().map(|&c| f32::from(c)).collect::<Vec<_>>().into(),
            colormap: Colormap::SaturationCount,
            range: ValueRange::new(0.0, set.shifts as f32),
            bar: ColorBar::unit("saturated"),
        });
        maps.push(MapSpec {
            stem: format!("{name}_wrapped_{p}"),
            data: (&set.wrapped_phase_rad[..]).into(),
            colormap: Colormap::Twilight,
            range: ValueRange::PHASE_RAD,
            bar: ColorBar::unit("rad"),
        });
        maps.push(MapSpec {
            stem: format!("{name}_modulation_{p}"),
            data: (&set.modulation_dn[..]).into(),
            colormap: Colormap::Viridis,
            range: sigma_range(&set.modulation_dn),
            bar: ColorBar::unit("DN"),
        });
        if let Some(unwrapped) = camera.unwrapped_phase(s) {
            maps.push(MapSpec {
                stem: format!("{name}_unwrapped_{p}"),
                data: unwrapped.into(),
                colormap: Colormap::Turbo,
                range: finite_range(unwrapped),
                bar: ColorBar::unit("rad"),
            });
        }
        maps.push(MapSpec {
            stem: format!("{name}_phase_sigma_{p}"),
            data: (&set.phase_sigma_rad[..]).into(),
            colormap: Colormap::Viridis,
            range: sigma_range(&set.phase_sigma_rad),
            bar: ColorBar::unit("rad"),
        });
    }
    write_map_specs(dir, w, h, maps, options)
}

/// Writes each map as TIFF (and its PNG preview where asked).
fn write_map_specs(
    dir: &Path,
    w: usize,
    h: usize,
    maps: Vec<MapSpec<'_>>,
    options: &MapWriteOptions,
) -> Result<Vec<PathBuf>, IoError> {
    let mut written = Vec::with_capacity(maps.len() * 2);
    for map in maps {
        let tif = dir.join(format!("{}.tif", map.stem));
        write_f32_tiff(&tif, w, h, &map.data, options.compression)?;
        written.push(tif);
        if options.previews {
            let png = dir.join(format!("{}.png", map.stem));
            write_map_png(&png, &map.data, w, h, map.colormap, map.range, &map.bar)?;
            written.push(png);
        }
    }
    Ok(written)
}

/// Writes a camera–projector rig's projector coordinate maps of one camera
/// (module docs); returns the files written.
pub fn write_projector_maps(
    dir: &Path,
    maps: &ProjectorMaps,
    options: &MapWriteOptions,
) -> Result<Vec<PathBuf>, IoError> {
    let name = &maps.camera;
    let mut specs = Vec::new();
    let mut size = None;
    for (axis, coordinate, code) in [("x", &maps.x, &maps.code_x), ("y", &maps.y, &maps.code_y)] {
        let (Some(coordinate), Some(code)) = (coordinate, code) else { continue };
        size = Some((coordinate.width, coordinate.height));
        specs.push(MapSpec {
            stem: format!("{name}_projector_{axis}"),
            data: (&coordinate.coordinate_px[..]).into(),
            colormap: Colormap::Turbo,
            range: ValueRange::of_finite(&coordinate.coordinate_px).unwrap_or(ValueRange::new(0.0, 1.0)),
            bar: ColorBar::unit("projector px"),
        });
        let sigma_max = ValueRange::quantiles(&coordinate.sigma_px, 0.0, 0.99).map_or(1.0, |r| r.max);
        specs.push(MapSpec {
            stem: format!("{name}_projector_{axis}_sigma"),
            data: (&coordinate.sigma_px[..]).into(),
            colormap: Colormap::Viridis,
            range: ValueRange::new(0.0, sigma_max),
            bar: ColorBar::unit("projector px"),
        });
        let cells: Vec<f32> = code.cells.iter().map(|c| c.map_or(f32::NAN, |c| c as f32)).collect();
        specs.push(MapSpec {
            stem: format!("{name}_gray_code_{axis}"),
            range: ValueRange::of_finite(&cells).unwrap_or(ValueRange::new(0.0, 1.0)),
            data: cells.into(),
            colormap: Colormap::Turbo,
            bar: ColorBar::unit("code unit"),
        });
    }
    let Some((w, h)) = size else { return Ok(Vec::new()) };
    write_map_specs(dir, w, h, specs, options)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::control::RunControl;
    use crate::engine::fringe::{CameraFringes, FringeSetInfo, FringeStack, Measurement, next_measurement_id};
    use crate::engine::pipeline::{Params, run_phase};

    #[test]
    fn float_tiff_round_trip_keeps_every_bit() {
        let dir = tempfile::tempdir().unwrap();
        let specials = [f32::NAN, -0.0, f32::INFINITY, f32::NEG_INFINITY, f32::MIN_POSITIVE / 8.0, f32::MAX, 1.0 / 3.0];
        let data: Vec<f32> = (0..7 * 5).map(|i| if i < 7 { specials[i] } else { (i as f32).sin() * 1e3 }).collect();
        for compression in [TiffCompression::None, TiffCompression::Deflate] {
            let path = dir.path().join(format!("{compression:?}.tif"));
            write_f32_tiff(&path, 7, 5, &data, compression).unwrap();
            let back = read_f32_tiff(&path).unwrap();
            assert_eq!((back.width, back.height), (7, 5));
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&back.data), bits(&data), "{compression:?}");
        }
        let err = write_f32_tiff(&dir.path().join("x.tif"), 3, 3, &data, TiffCompression::None).unwrap_err();
        assert!(err.to_string().contains("not 3x3 px"), "{err}");
    }

    #[test]
    fn reading_a_non_float_tiff_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gray8.tif");
        image::GrayImage::from_pixel(3, 2, image::Luma([7])).save(&path).unwrap();
        let err = read_f32_tiff(&path).unwrap_err().to_string();
        assert!(err.contains("gray8.tif") && err.contains("float32"), "{err}");
    }

    #[test]
    fn period_labels_are_plain_numbers() {
        assert_eq!(period_label(912.0), "912");
        assert_eq!(period_label(12.0), "12");
        assert_eq!(period_label(22.5), "22.5");
    }

    /// One camera, periods 64 and 8 px over a 32 x 6 field, 4 shifts, 8-bit;
    /// the right half is over-exposed so the saturation maps have content.
    fn camera_phase(enabled: Vec<bool>) -> CameraPhase {
        let (w, h, n) = (32usize, 6usize, 4usize);
        let periods = [64.0, 8.0];
        let stacks = periods
            .iter()
            .map(|&period| {
                let planes = (0..n)
                    .map(|k| {
                        (0..w * h)
                            .map(|i| {
                                let x = (i % w) as f64;
                                let b = if x < 16.0 { 90.0 } else { 200.0 };
                                let phase = std::f64::consts::TAU * (x / period + k as f64 / n as f64);
                                (120.0 + b * phase.cos()).round().clamp(0.0, 255.0) as u8
                            })
                            .collect()
                    })
                    .collect();
                FringeStack::from_planes_u8(w, h, planes)
            })
            .collect();
        let m = Measurement {
            bit_depth: 8,
            saturation_level: 255,
            sets: periods.iter().map(|&p| FringeSetInfo::uniform(p, n)).collect(),
            cameras: vec![CameraFringes { name: "left".into(), width: w, height: h, stacks }],
            calibration: None,
            label: "test".into(),
            projector: None,
            id: next_measurement_id(),
        };
        let params = Params { enabled_sets: enabled, ..Params::default() };
        let mut rec = run_phase(&m, &params, None, &RunControl::new()).unwrap();
        rec.cameras.remove(0)
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn camera_maps_follow_the_contract_and_hold_the_engine_values() {
        let dir = tempfile::tempdir().unwrap();
        let cam = camera_phase(Vec::new());
        let files = write_camera_maps(dir.path(), &cam, &[64.0, 8.0]).unwrap();
        let mut names: Vec<String> =
            files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
        names.sort();
        let mut expected: Vec<String> =
            ["fused_phase", "fused_sigma", "source", "order_evidence"].iter().map(|s| format!("left_{s}")).collect();
        for p in ["64", "8"] {
            for kind in ["saturation", "wrapped", "modulation", "unwrapped", "phase_sigma"] {
                expected.push(format!("left_{kind}_{p}"));
            }
        }
        let mut expected: Vec<String> =
            expected.iter().flat_map(|s| [format!("{s}.png"), format!("{s}.tif")]).collect();
        expected.sort();
        assert_eq!(names, expected);

        let read = |stem: &str| {
            let m = read_f32_tiff(&dir.path().join(format!("{stem}.tif"))).unwrap();
            assert_eq!((m.width, m.height), (32, 6), "{stem}");
            m.data
        };
        assert_eq!(bits(&read("left_fused_phase")), bits(&cam.fused.fused_phase_rad));
        assert_eq!(bits(&read("left_fused_sigma")), bits(&cam.fused.fused_sigma_rad));
        let source: Vec<f32> = cam.fused.source_set.iter().map(|&s| f32::from(s)).collect();
        assert_eq!(read("left_source"), source);
        assert!(source.contains(&1.0), "the densest set supplies pixels");
        // Order evidence where the fused phase is valid, NaN elsewhere.
        let evidence = read("left_order_evidence");
        for ((e, &code), phase) in evidence.iter().zip(&cam.fused.order_evidence).zip(&cam.fused.fused_phase_rad) {
            assert!(if phase.is_nan() { e.is_nan() } else { *e == f32::from(code) });
        }
        let sat: Vec<f32> = cam.sets[1].saturation_count.iter().map(|&c| f32::from(c)).collect();
        assert_eq!(read("left_saturation_8"), sat);
        assert!(sat.iter().any(|&c| c > 0.0), "the over-exposed half saturates");
        let wrapped = read("left_wrapped_8");
        assert_eq!(bits(&wrapped), bits(&cam.sets[1].wrapped_phase_rad));
        assert!(wrapped.iter().filter(|v| v.is_finite()).all(|&v| (0.0..std::f32::consts::TAU).contains(&v)));
        assert_eq!(bits(&read("left_modulation_64")), bits(&cam.sets[0].modulation_dn));
        assert_eq!(bits(&read("left_unwrapped_8")), bits(cam.unwrapped_phase(1).unwrap()));
        assert_eq!(bits(&read("left_phase_sigma_64")), bits(&cam.sets[0].phase_sigma_rad));
        // Previews: the map plus a colour bar, readable as PNG.
        let png = image::open(dir.path().join("left_wrapped_8.png")).unwrap();
        assert!(png.width() > 32 && png.height() >= 6);
    }

    #[test]
    fn disabled_sets_have_no_unwrapped_map_and_deflate_works() {
        let dir = tempfile::tempdir().unwrap();
        let cam = camera_phase(vec![true, false]);
        let options = MapWriteOptions { compression: TiffCompression::Deflate, previews: false };
        let files = write_camera_maps_with(dir.path(), &cam, &[64.0, 8.0], &options).unwrap();
        assert!(files.iter().all(|f| f.extension().unwrap() == "tif"));
        assert!(dir.path().join("left_unwrapped_64.tif").exists());
        assert!(!dir.path().join("left_unwrapped_8.tif").exists());
        assert!(dir.path().join("left_wrapped_8.tif").exists());
        assert_eq!(
            bits(&read_f32_tiff(&dir.path().join("left_wrapped_8.tif")).unwrap().data),
            bits(&cam.sets[1].wrapped_phase_rad)
        );
        let err = write_camera_maps(dir.path(), &cam, &[64.0]).unwrap_err().to_string();
        assert!(err.contains("1 periods given for 2 sets"), "{err}");
    }
}
