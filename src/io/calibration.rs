//! The calibration contract: two telecentric cameras `left` (the
//! main camera) and `right`, each `(u, v)^T = P (X, Y, Z, 1)^T` with an
//! optional lens distortion, in a JSON file or inline in a manifest:
//!
//! ```json
//! {"model": "affine", "unit": "mm",
//!  "cameras": {"left":  {"width": 2048, "height": 1536, "P": [[p11, p12, p13, p14], [p21, p22, p23, p24]],
//!                        "distortion": {"center": [cx, cy], "scale_px": s, "k1": 0, "k2": 0, "p1": 0, "p2": 0},
//!                        "rms_reprojection_px": 0.02},
//!              "right": {...}}}
//! ```
//!
//! Reading validates everything a reconstruction relies on (shapes, finite
//! numbers, rank 2, non-parallel views via `StereoCalibration::validate`), so
//! a calibration that loads is one the stereo stage can use.

use crate::engine::warning::{Warning, WarningKind};
use std::path::{Path, PathBuf};

use serde_json::{Map, Value};

use super::atomic::write_atomic;
use super::error::IoError;
use super::json::{self, JsonFault, child};
use crate::engine::camera_model::{AffineCamera, CalibrationError, Distortion, ScaleUncertainty, StereoCalibration};
use crate::engine::length_unit::{LengthUnit, UnknownLengthUnit};

/// What is wrong with a calibration.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CalibrationFault {
    #[error(transparent)]
    Json(#[from] JsonFault),
    #[error(transparent)]
    UnknownUnit(#[from] UnknownLengthUnit),
    #[error("model '{found}' is not supported; Sheen reads \"model\": \"affine\" (telecentric cameras)")]
    UnknownModel { found: String },
    #[error("is a {found} calibration, but {expected}: use the calibration of this rig (\"model\": \"{model}\")")]
    OtherRigsModel { found: &'static str, expected: &'static str, model: &'static str },
    /// A camera–projector calibration's `key` (e.g. `camera.K`) and what is wrong with it.
    #[error("'{key}' {problem}")]
    Pinhole { key: String, problem: String },
    #[error("camera '{camera}': P must be 2 rows of 4 numbers, found {found}")]
    PShape { camera: String, found: String },
    #[error("camera '{camera}': '{key}' must be a positive whole number of pixels, found {found}")]
    BadSize { camera: String, key: &'static str, found: String },
    #[error("camera '{camera}': '{key}' must be 2 numbers, found {found}")]
    BadCenter { camera: String, key: String, found: String },
    #[error(
        "uncertainty: '{key}' = {found} is not a relative standard uncertainty; \"uncertainty\" holds \
         \"height_scale_relative\" and \"lateral_scale_relative\", each a number >= 0 (2e-4 for 0.02 %)"
    )]
    BadUncertainty { key: String, found: String },
    #[error("{0}; re-run the calibration or correct the file")]
    Unusable(#[from] CalibrationError),
    #[error(
        "camera '{camera}' is calibrated for {calibration_width}x{calibration_height} px images, but its image {} is \
         {image_width}x{image_height} px; use the calibration of this camera setup (or re-calibrate)",
        image.display()
    )]
    ImageSize {
        camera: String,
        calibration_width: usize,
        calibration_height: usize,
        image: PathBuf,
        image_width: usize,
        image_height: usize,
    },
}

const TOP_KEYS: [&str; 4] = ["model", "unit", "cameras", "uncertainty"];
const CAMERA_KEYS: [&str; 5] = ["width", "height", "P", "distortion", "rms_reprojection_px"];
const DISTORTION_KEYS: [&str; 6] = ["center", "scale_px", "k1", "k2", "p1", "p2"];

/// Reads and validates a calibration file; returns it with warnings (unknown
/// keys, a missing unit).
pub fn read_calibration(path: &Path) -> Result<(StereoCalibration, Vec<Warning>), IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    let fault = |fault| IoError::Calibration { path: path.to_path_buf(), inline: false, fault };
    let value = json::parse(&bytes).map_err(|e| fault(e.into()))?;
    let mut warnings = Vec::new();
    let calibration = parse_calibration(&value, &path.display().to_string(), &mut warnings).map_err(fault)?;
    Ok((calibration, warnings))
}

/// Parses and validates a calibration held in JSON, e.g. inline in the
/// manifest at `manifest_path` (named in errors and warnings).
pub fn calibration_from_value(
    value: &Value,
    manifest_path: &Path,
) -> Result<(StereoCalibration, Vec<Warning>), IoError> {
    let mut warnings = Vec::new();
    let origin = format!("inline calibration in {}", manifest_path.display());
    parse_calibration(value, &origin, &mut warnings).map(|c| (c, warnings)).map_err(|fault| IoError::Calibration {
        path: manifest_path.to_path_buf(),
        inline: true,
        fault,
    })
}

/// The contract's JSON for a calibration (numbers written exactly: serde_json
/// prints the shortest representation that reads back to the same `f64`).
pub fn calibration_to_value(c: &StereoCalibration) -> Value {
    // The calibration serialises itself (engine::camera_model); a number
    // that is not finite becomes null, which the reader then refuses.
    serde_json::to_value(c).unwrap_or(Value::Null)
}

/// Writes a calibration file atomically (pretty JSON).
pub fn write_calibration(path: &Path, c: &StereoCalibration) -> Result<(), IoError> {
    let value = calibration_to_value(c);
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &value).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
}

/// `"uncertainty": {"height_scale_relative": 2e-4, "lateral_scale_relative": 1e-4}`:
/// relative standard uncertainties, each optional, finite and >= 0.
fn parse_scale_uncertainty(value: &Value) -> Result<ScaleUncertainty, CalibrationFault> {
    let object = json::as_object(value, "uncertainty")?;
    let mut out = ScaleUncertainty::default();
    for (key, v) in object {
        let slot = match key.as_str() {
            "height_scale_relative" => &mut out.height_relative,
            "lateral_scale_relative" => &mut out.lateral_relative,
            _ => return Err(CalibrationFault::BadUncertainty { key: key.clone(), found: json::describe(v) }),
        };
        let x = json::number(v, &json::child("uncertainty", key))?;
        if !(x.is_finite() && x >= 0.0) {
            return Err(CalibrationFault::BadUncertainty { key: key.clone(), found: json::describe(v) });
        }
        *slot = Some(x);
    }
    Ok(out)
}

fn parse_calibration(
    value: &Value,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<StereoCalibration, CalibrationFault> {
    let top = json::as_object(value, "")?;
    json::warn_unknown_keys(top, "", &TOP_KEYS, origin, warnings);
    let model = json::string(json::require(top, "", "model", " (write \"model\": \"affine\")")?, "model")?;
    if model == super::pinhole_calibration::PINHOLE_MODEL {
        return Err(CalibrationFault::OtherRigsModel {
            found: "camera–projector (pinhole-camera-projector)",
            expected: "the manifest describes two telecentric cameras",
            model: "affine",
        });
    }
    if model != "affine" {
        return Err(CalibrationFault::UnknownModel { found: model.to_string() });
    }
    let unit = unit_or_mm(top, origin, warnings)?;
    let cameras = json::as_object(
        json::require(top, "", "cameras", " (an object with the cameras 'left' and 'right')")?,
        "cameras",
    )?;
    for name in cameras.keys().filter(|k| *k != "left" && *k != "right") {
        warnings.push(Warning::new(
            WarningKind::IgnoredInput,
            format!("{origin}: camera '{name}' ignored; the stereo rig uses 'left' and 'right'"),
        ));
    }
    let (left, left_rms) = parse_camera(cameras, "left", origin, warnings)?;
    let (right, right_rms) = parse_camera(cameras, "right", origin, warnings)?;
    let scale_uncertainty = top.get("uncertainty").map(parse_scale_uncertainty).transpose()?;
    let calibration = StereoCalibration {
        unit,
        left,
        right,
        rms_reprojection_px: left_rms.zip(right_rms).map(|(l, r)| [l, r]),
        scale_uncertainty,
    };
    calibration.validate()?;
    Ok(calibration)
}

/// A calibration's `unit`, or millimetres with a warning. Parsed here, once,
/// so that an unknown unit is refused naming the file instead of silently
/// disabling the conversions downstream.
pub(crate) fn unit_or_mm(
    top: &Map<String, Value>,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<LengthUnit, CalibrationFault> {
    Ok(match top.get("unit") {
        Some(v) => json::string(v, "unit")?.parse::<LengthUnit>()?,
        None => {
            warnings.push(Warning::new(
                WarningKind::UnitAssumed,
                format!("{origin}: no 'unit' given; assuming millimetres (\"unit\": \"mm\")"),
            ));
            LengthUnit::Mm
        }
    })
}

fn parse_camera(
    cameras: &Map<String, Value>,
    name: &str,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<(AffineCamera, Option<f64>), CalibrationFault> {
    let path = format!("cameras.{name}");
    let cam =
        json::as_object(json::require(cameras, "cameras", name, " (a stereo calibration needs both cameras)")?, &path)?;
    json::warn_unknown_keys(cam, &path, &CAMERA_KEYS, origin, warnings);
    let size = |key: &'static str| -> Result<usize, CalibrationFault> {
        let v = json::require(cam, &path, key, "")?;
        match json::integer(v, &child(&path, key), "a positive whole number") {
            Ok(n) if n > 0 && n <= 1 << 20 => Ok(n as usize),
            _ => Err(CalibrationFault::BadSize { camera: name.to_string(), key, found: json::describe(v) }),
        }
    };
    let (width, height) = (size("width")?, size("height")?);
    let p = parse_p(json::require(cam, &path, "P", " (the 2x4 projection matrix)")?, name)?;
    let distortion = match cam.get("distortion") {
        None | Some(Value::Null) => None,
        Some(v) => Some(parse_distortion(v, &child(&path, "distortion"), name, width, height, origin, warnings)?),
    };
    let rms = match cam.get("rms_reprojection_px") {
        None | Some(Value::Null) => None,
        Some(v) => Some(json::number(v, &child(&path, "rms_reprojection_px"))?),
    };
    Ok((AffineCamera { width, height, p, distortion }, rms))
}

fn parse_p(v: &Value, camera: &str) -> Result<[[f64; 4]; 2], CalibrationFault> {
    let shape_fault = |found: String| CalibrationFault::PShape { camera: camera.to_string(), found };
    let Some(rows) = v.as_array() else { return Err(shape_fault(json::describe(v))) };
    let lengths: Vec<Option<usize>> = rows.iter().map(|r| r.as_array().map(Vec::len)).collect();
    if rows.len() != 2 || lengths.iter().any(|l| *l != Some(4)) {
        let found = match lengths.first() {
            _ if lengths.iter().any(Option::is_none) => "a row that is not a list".to_string(),
            Some(first) if lengths.iter().all(|l| l == first) => format!("{}x{}", rows.len(), first.unwrap_or(0)),
            _ => format!(
                "rows of {} numbers",
                lengths.iter().map(|l| l.unwrap_or(0).to_string()).collect::<Vec<_>>().join(", ")
            ),
        };
        return Err(shape_fault(found));
    }
    let mut p = [[0.0; 4]; 2];
    for (i, row) in rows.iter().enumerate() {
        for (j, x) in row.as_array().into_iter().flatten().enumerate() {
            p[i][j] = json::number(x, &format!("cameras.{camera}.P[{i}][{j}]"))?;
        }
    }
    Ok(p)
}

fn parse_distortion(
    v: &Value,
    path: &str,
    camera: &str,
    width: usize,
    height: usize,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<Distortion, CalibrationFault> {
    let map = json::as_object(v, path)?;
    json::warn_unknown_keys(map, path, &DISTORTION_KEYS, origin, warnings);
    // Missing entries take the convention calibration writes (and no distortion).
    let mut d = Distortion::for_image(width, height);
    if let Some(c) = map.get("center") {
        let numbers: Option<Vec<f64>> =
            c.as_array().filter(|a| a.len() == 2).map(|a| a.iter().filter_map(|x| x.as_f64()).collect());
        match numbers {
            Some(n) if n.len() == 2 && n.iter().all(|x| x.is_finite()) => d.center_px = [n[0], n[1]],
            _ => {
                return Err(CalibrationFault::BadCenter {
                    camera: camera.to_string(),
                    key: child(path, "center"),
                    found: json::describe(c),
                });
            }
        }
    }
    for (key, slot) in
        [("scale_px", &mut d.scale_px), ("k1", &mut d.k1), ("k2", &mut d.k2), ("p1", &mut d.p1), ("p2", &mut d.p2)]
    {
        if let Some(x) = map.get(key) {
            *slot = json::number(x, &child(path, key))?;
        }
    }
    Ok(d)
}

/// Checks that a camera's images have the size its calibration was made for.
pub(crate) fn check_image_size(
    camera_name: &str,
    model: &AffineCamera,
    image: &Path,
    image_width: usize,
    image_height: usize,
) -> Result<(), CalibrationFault> {
    if model.width == image_width && model.height == image_height {
        return Ok(());
    }
    Err(CalibrationFault::ImageSize {
        camera: camera_name.to_string(),
        calibration_width: model.width,
        calibration_height: model.height,
        image: image.to_path_buf(),
        image_width,
        image_height,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use serde_json::json;

    /// A valid rig: left looks down -Z, right is tilted 20 degrees about the
    /// image rows, with an offset, so its view differs.
    pub(crate) fn rig() -> StereoCalibration {
        let (s, c) = 20f64.to_radians().sin_cos();
        StereoCalibration {
            unit: LengthUnit::Mm,
            left: AffineCamera {
                width: 64,
                height: 48,
                p: [[200.0, 0.0, 0.0, 31.5], [0.0, 200.0, 0.0, 23.5]],
                distortion: None,
            },
            right: AffineCamera {
                width: 64,
                height: 48,
                p: [[200.0 * c, 0.0, 200.0 * s, 30.25], [0.0, 200.0, 0.0, 22.75]],
                distortion: Some(Distortion { k1: 1.5e-3, p2: -2.0e-4, ..Distortion::for_image(64, 48) }),
            },
            rms_reprojection_px: Some([0.021, 0.019]),
            scale_uncertainty: None,
        }
    }

    fn parse_str(text: &str) -> Result<(StereoCalibration, Vec<Warning>), CalibrationFault> {
        let v = json::parse(text.as_bytes())?;
        let mut w = Vec::new();
        parse_calibration(&v, "c.json", &mut w).map(|c| (c, w))
    }

    #[test]
    fn write_read_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("calibration.json");
        let c = rig();
        write_calibration(&path, &c).unwrap();
        let (back, warnings) = read_calibration(&path).unwrap();
        assert_eq!(back, c);
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    #[test]
    fn every_length_unit_is_read_and_an_unknown_one_is_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rig_nm.json");
        use LengthUnit::{M, Mm, Nm, Um};
        for (written, kept) in [("mm", Mm), ("µm", Um), ("um", Um), ("nm", Nm), ("m", M)] {
            let mut v = calibration_to_value(&rig());
            v["unit"] = json!(written);
            std::fs::write(&path, v.to_string()).unwrap();
            let (c, _) = read_calibration(&path).unwrap();
            assert_eq!(c.unit, kept, "{written}");
        }
        let mut v = calibration_to_value(&rig());
        v["unit"] = json!("furlong");
        std::fs::write(&path, v.to_string()).unwrap();
        let err = read_calibration(&path).unwrap_err();
        assert!(
            matches!(&err, IoError::Calibration { fault: CalibrationFault::UnknownUnit(u), .. } if u.found == "furlong"),
            "{err:?}"
        );
        let message = format!("{err:#}");
        assert!(message.contains("rig_nm.json") && message.contains("furlong"), "{message}");
    }

    #[test]
    fn faults_name_the_file_and_what_is_wrong() {
        let good = calibration_to_value(&rig());
        let with = |edit: &dyn Fn(&mut Value)| {
            let mut v = good.clone();
            edit(&mut v);
            v.to_string()
        };
        let cases: Vec<(String, &[&str])> = vec![
            ("{\"model\": \"affine\",".to_string(), &["not valid JSON", "line 1"]),
            (with(&|v| v["model"] = json!("pinhole")), &["model 'pinhole'", "affine"]),
            (
                with(&|v| {
                    v.as_object_mut().unwrap().remove("model");
                }),
                &["lacks the key 'model'"],
            ),
            (
                with(&|v| {
                    v["cameras"].as_object_mut().unwrap().remove("right");
                }),
                &["lacks the key 'cameras.right'", "needs both cameras"],
            ),
            (
                with(&|v| v["cameras"]["left"]["P"] = json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])),
                &["camera 'left': P must be 2 rows of 4 numbers, found 3x4"],
            ),
            (
                with(&|v| v["cameras"]["right"]["P"] = json!([[1, 0, 0, 0], [0, 1, 0]])),
                &["camera 'right': P must be 2 rows of 4 numbers, found rows of 4, 3 numbers"],
            ),
            (with(&|v| v["cameras"]["left"]["P"][1][2] = json!("x")), &["'cameras.left.P[1][2]' must be a number"]),
            (with(&|v| v["cameras"]["left"]["width"] = json!(-3)), &["camera 'left'", "'width'", "positive"]),
            (
                with(&|v| v["cameras"]["right"]["P"] = json!([[1, 2, 3, 0], [2, 4, 6, 0]])),
                &["camera 'right'", "rank below 2"],
            ),
            (
                with(&|v| v["cameras"]["right"]["P"] = v["cameras"]["left"]["P"].clone()),
                &["viewing directions are parallel"],
            ),
            (
                with(&|v| v["cameras"]["left"]["distortion"] = json!({"center": [1.0]})),
                &["'cameras.left.distortion.center' must be 2 numbers"],
            ),
            (with(&|v| v["cameras"]["left"]["distortion"] = json!({"scale_px": 0})), &["distortion", "scale"]),
        ];
        for (text, expected) in cases {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("calib-under-test.json");
            std::fs::write(&path, &text).unwrap();
            let msg = read_calibration(&path).unwrap_err().to_string();
            assert!(msg.contains("calib-under-test.json"), "{msg}");
            for e in expected {
                assert!(msg.contains(e), "expected {e:?} in: {msg}");
            }
        }
    }

    #[test]
    fn numbers_too_large_for_f64_are_refused_not_infinite() {
        let mut v = calibration_to_value(&rig()).to_string();
        v = v.replacen("200.0", "1e999", 1);
        let fault = parse_str(&v).unwrap_err();
        assert!(matches!(fault, CalibrationFault::Json(JsonFault::Syntax { .. })), "{fault:?}");
        assert!(fault.to_string().contains("number out of range"), "{fault}");
    }

    #[test]
    fn unknown_keys_and_extra_cameras_warn_and_missing_unit_defaults_to_mm() {
        let mut v = calibration_to_value(&rig());
        v.as_object_mut().unwrap().remove("unit");
        v["cameras"]["left"]["skew"] = json!(0);
        v["cameras"]["aux"] = v["cameras"]["left"].clone();
        let (c, w) = parse_str(&v.to_string()).unwrap();
        assert_eq!(c.unit, LengthUnit::Mm);
        assert_eq!(w.len(), 3, "{w:?}"); // no unit, left's skew, aux ignored (and not parsed)
        let of = |kind| w.iter().filter(|m| m.kind == kind).map(|m| m.message.as_str()).collect::<Vec<_>>();
        assert_eq!(of(WarningKind::UnitAssumed).len(), 1, "{w:?}");
        let ignored = of(WarningKind::IgnoredInput);
        assert!(ignored.iter().any(|m| m.contains("'cameras.left.skew'")), "{w:?}");
        assert!(ignored.iter().any(|m| m.contains("camera 'aux' ignored")), "{w:?}");
    }

    #[test]
    fn inline_errors_name_the_manifest() {
        let err =
            calibration_from_value(&json!({"model": "affine"}), Path::new("/data/set/fringe-set.json")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("inline calibration in /data/set/fringe-set.json") && msg.contains("'cameras'"), "{msg}");
    }

    #[test]
    fn image_size_mismatch_names_both_files() {
        let err = IoError::Calibration {
            path: PathBuf::from("calibration.json"),
            inline: false,
            fault: check_image_size("left", &rig().left, Path::new("left/p0912_00.png"), 64, 47).unwrap_err(),
        };
        let msg = err.to_string();
        for part in ["calibration.json", "left/p0912_00.png", "64x48 px", "64x47 px", "camera 'left'"] {
            assert!(msg.contains(part), "{part:?} not in {msg}");
        }
    }

    /// Number literals as another tool might write them, including ones that
    /// overflow `f64`.
    fn number_text() -> impl proptest::strategy::Strategy<Value = String> {
        use proptest::prelude::*;
        prop_oneof![
            any::<f64>().prop_filter("finite", |x| x.is_finite()).prop_map(|x| format!("{x:e}")),
            (-400i32..400).prop_map(|e| format!("1.5e{e}")),
            "-?[0-9]{1,4}(\\.[0-9]{1,4})?",
            Just("1e999".to_string()),
            Just("-1e400".to_string()),
            Just("0".to_string()),
        ]
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 300, ..Default::default() })]

        #[test]
        fn parser_never_panics_on_bytes(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300)) {
            if let Ok(v) = json::parse(&bytes) {
                let _ = parse_calibration(&v, "fuzz", &mut Vec::new());
            }
        }
    }

    /// Numbers of a valid rig (left P, its distortion centre, scale, k1, k2;
    /// right P; right RMS), in the order of the template below.
    const RIG_NUMBERS: [f64; 22] = [
        200.0, 0.0, 0.0, 31.5, 0.0, 200.0, 0.0, 23.5, 31.5, 23.5, 32.0, 1e-3, 0.0, 187.9, 0.0, 68.4, 30.25, 0.0, 200.0,
        0.0, 22.75, 0.02,
    ];

    /// Whatever numbers a file holds, a parsed calibration is finite and
    /// valid. Most numbers are a valid rig's and some are wild, so that both
    /// accepted and refused files occur, and both are counted.
    #[test]
    fn parsed_calibrations_are_finite_and_valid() {
        let strategy = proptest::collection::vec((proptest::bool::weighted(0.92), number_text()), 22);
        let (accepted, refused) = json::count_outcomes(300, &strategy, |picks| {
            let numbers: Vec<String> = picks
                .iter()
                .zip(RIG_NUMBERS)
                .map(|((keep, wild), rig)| if *keep { format!("{rig:?}") } else { wild.clone() })
                .collect();
            let n = |i: usize| numbers[i].as_str();
            let text = format!(
                r#"{{"model": "affine", "unit": "mm", "cameras": {{
                        "left": {{"width": 64, "height": 48, "P": [[{}, {}, {}, {}], [{}, {}, {}, {}]],
                                  "distortion": {{"center": [{}, {}], "scale_px": {}, "k1": {}, "k2": {}}}}},
                        "right": {{"width": 64, "height": 48, "P": [[{}, {}, {}, {}], [{}, {}, {}, {}]],
                                   "rms_reprojection_px": {}}}}}}}"#,
                n(0),
                n(1),
                n(2),
                n(3),
                n(4),
                n(5),
                n(6),
                n(7),
                n(8),
                n(9),
                n(10),
                n(11),
                n(12),
                n(13),
                n(14),
                n(15),
                n(16),
                n(17),
                n(18),
                n(19),
                n(20),
                n(21)
            );
            match parse_str(&text) {
                Ok((c, _)) => {
                    for cam in [&c.left, &c.right] {
                        proptest::prop_assert!(cam.p.iter().flatten().all(|v| v.is_finite()));
                        if let Some(d) = &cam.distortion {
                            let all = [d.center_px[0], d.center_px[1], d.scale_px, d.k1, d.k2, d.p1, d.p2];
                            proptest::prop_assert!(all.iter().all(|v| v.is_finite()));
                        }
                    }
                    proptest::prop_assert!(c.validate().is_ok());
                    Ok(true)
                }
                Err(_) => Ok(false),
            }
        });
        eprintln!("calibrations: {accepted} accepted, {refused} refused");
        assert!(accepted >= 20 && refused >= 20, "{accepted} accepted, {refused} refused: both must be exercised");
    }

    /// The same, with a valid file's bytes mutated: most mutations still
    /// reach the calibration parser (counted), none may panic.
    #[test]
    fn parser_never_panics_on_mutated_files() {
        use proptest::prelude::*;
        let valid = calibration_to_value(&rig()).to_string().into_bytes();
        let strategy = proptest::collection::vec((0..valid.len(), any::<u8>()), 0..3);
        let (reached, _) = json::count_outcomes(300, &strategy, |edits| {
            let mut bytes = valid.clone();
            for (at, byte) in edits {
                bytes[at] = byte;
            }
            Ok(match json::parse(&bytes) {
                Ok(v) => {
                    let _ = parse_calibration(&v, "fuzz", &mut Vec::new());
                    true
                }
                Err(_) => false,
            })
        });
        eprintln!("mutated calibration files reaching the parser: {reached}");
        assert!(reached >= 60, "only {reached} of 300 mutated files were JSON");
    }
}
