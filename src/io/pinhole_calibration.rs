//! The camera–projector calibration contract (issue 52), OpenCV's
//! conventions: x right, y down, z forward, pixel centres at integer
//! coordinates, distortion `k1, k2, p1, p2[, k3]`, and `X_p = R X_c + t`
//! from the camera's frame to the projector's:
//!
//! ```json
//! {"model": "pinhole-camera-projector", "unit": "mm",
//!  "camera":    {"width": 640, "height": 480, "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "distortion": [k1, k2, p1, p2, k3]},
//!  "projector": {"width": 800, "height": 600, "K": [[...]], "distortion": [...]},
//!  "R": [[...], [...], [...]], "t": [tx, ty, tz]}
//! ```
//!
//! What OpenCV's `stereoCalibrate` gives (camera first, projector second)
//! goes in as it is.

use std::path::Path;

use serde_json::{Map, Value};

use super::calibration::CalibrationFault;
use super::error::IoError;
use super::json;
use crate::engine::pinhole::{CameraProjectorCalibration, PinholeDevice};
use crate::engine::warning::Warning;

/// The `model` of a camera–projector calibration.
pub const PINHOLE_MODEL: &str = "pinhole-camera-projector";

const TOP_KEYS: [&str; 6] = ["model", "unit", "camera", "projector", "R", "t"];
const DEVICE_KEYS: [&str; 5] = ["width", "height", "K", "distortion", "rms_reprojection_px"];

fn fault(key: &str, problem: impl Into<String>) -> CalibrationFault {
    CalibrationFault::Pinhole { key: key.to_string(), problem: problem.into() }
}

fn numbers(v: &Value, key: &str, len: usize) -> Result<Vec<f64>, CalibrationFault> {
    let list = v.as_array().ok_or_else(|| fault(key, format!("must be a list of {len} numbers")))?;
    let out: Vec<f64> = list.iter().filter_map(Value::as_f64).filter(|x| x.is_finite()).collect();
    if out.len() != list.len() || out.len() != len {
        return Err(fault(key, format!("must be a list of {len} finite numbers, found {}", json::describe(v))));
    }
    Ok(out)
}

fn matrix3(v: &Value, key: &str) -> Result<[[f64; 3]; 3], CalibrationFault> {
    let rows = v.as_array().filter(|r| r.len() == 3).ok_or_else(|| fault(key, "must be 3 rows of 3 numbers"))?;
    let mut m = [[0.0; 3]; 3];
    for (i, row) in rows.iter().enumerate() {
        let r = numbers(row, &format!("{key}[{i}]"), 3)?;
        m[i] = [r[0], r[1], r[2]];
    }
    Ok(m)
}

fn device(
    top: &Map<String, Value>,
    name: &str,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<PinholeDevice, CalibrationFault> {
    let object = json::as_object(json::require(top, "", name, " (its size, K and distortion)")?, name)?;
    json::warn_unknown_keys(object, name, &DEVICE_KEYS, origin, warnings);
    let side = |key: &str| {
        let k = format!("{name}.{key}");
        let v = json::require(object, name, key, " (pixels)")?;
        match v.as_u64() {
            Some(n) if n >= 1 => Ok(n as usize),
            _ => Err(fault(&k, format!("must be a positive whole number of pixels, found {}", json::describe(v)))),
        }
    };
    let (width, height) = (side("width")?, side("height")?);
    let k_key = format!("{name}.K");
    let k = matrix3(json::require(object, name, "K", " ([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])")?, &k_key)?;
    if k[0][1] != 0.0 || k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
        return Err(fault(&k_key, "must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)"));
    }
    if !(k[0][0] > 0.0 && k[1][1] > 0.0) {
        return Err(fault(&k_key, "needs positive focal lengths fx and fy (pixels)"));
    }
    let mut distortion = [0.0; 5];
    if let Some(v) = object.get("distortion").filter(|v| !v.is_null()) {
        let d_key = format!("{name}.distortion");
        let len = v.as_array().map_or(0, Vec::len);
        if !(len == 4 || len == 5) {
            return Err(fault(
                &d_key,
                format!("must be [k1, k2, p1, p2] or [k1, k2, p1, p2, k3], found {}", json::describe(v)),
            ));
        }
        distortion[..len].copy_from_slice(&numbers(v, &d_key, len)?);
    }
    Ok(PinholeDevice { width, height, fx: k[0][0], fy: k[1][1], cx: k[0][2], cy: k[1][2], distortion })
}

fn parse(
    value: &Value,
    origin: &str,
    warnings: &mut Vec<Warning>,
) -> Result<CameraProjectorCalibration, CalibrationFault> {
    let top = json::as_object(value, "")?;
    json::warn_unknown_keys(top, "", &TOP_KEYS, origin, warnings);
    let model =
        json::string(json::require(top, "", "model", " (write \"model\": \"pinhole-camera-projector\")")?, "model")?;
    if model == "affine" {
        return Err(CalibrationFault::OtherRigsModel {
            found: "telecentric stereo (affine)",
            expected: "the manifest describes a camera–projector rig",
            model: PINHOLE_MODEL,
        });
    }
    if model != PINHOLE_MODEL {
        return Err(fault("model", format!("must be \"{PINHOLE_MODEL}\" for a camera–projector rig, found '{model}'")));
    }
    let unit = super::calibration::unit_or_mm(top, origin, warnings)?;
    let camera = device(top, "camera", origin, warnings)?;
    let projector = device(top, "projector", origin, warnings)?;
    let r = matrix3(json::require(top, "", "R", " (the rotation from the camera's frame to the projector's)")?, "R")?;
    // A rotation: RᵀR = I and det R = +1, to the digits a calibration keeps.
    let orthogonality = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| ((0..3).map(|k| r[k][i] * r[k][j]).sum::<f64>() - f64::from(u8::from(i == j))).abs())
        .fold(0.0, f64::max);
    let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
    if orthogonality > 1e-6 || det < 0.0 {
        return Err(fault("R", format!("is not a rotation (|RᵀR - I| = {orthogonality:.1e}, det {det:.6})")));
    }
    let t = numbers(json::require(top, "", "t", " (the camera-to-projector translation)")?, "t", 3)?;
    let t = [t[0], t[1], t[2]];
    if t.iter().map(|x| x * x).sum::<f64>() == 0.0 {
        return Err(fault("t", "is zero: a camera and a projector at one point see no depth"));
    }
    Ok(CameraProjectorCalibration { unit, camera, projector, r, t })
}

/// Reads and checks a camera–projector calibration file.
pub fn read_camera_projector_calibration(path: &Path) -> Result<(CameraProjectorCalibration, Vec<Warning>), IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Read { path: path.to_path_buf(), source })?;
    let to_error = |fault| IoError::Calibration { path: path.to_path_buf(), inline: false, fault };
    let value = json::parse(&bytes).map_err(|e| to_error(e.into()))?;
    camera_projector_calibration_from_value(&value, &path.display().to_string()).map_err(to_error)
}

/// Parses a camera–projector calibration held in JSON (`origin` names it).
pub fn camera_projector_calibration_from_value(
    value: &Value,
    origin: &str,
) -> Result<(CameraProjectorCalibration, Vec<Warning>), CalibrationFault> {
    let mut warnings = Vec::new();
    parse(value, origin, &mut warnings).map(|c| (c, warnings))
}

/// Writes a camera–projector calibration file (atomically).
pub fn write_camera_projector_calibration(path: &Path, c: &CameraProjectorCalibration) -> Result<(), IoError> {
    let value = camera_projector_calibration_to_value(c);
    super::atomic::write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &value).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
}

/// The contract's JSON for a calibration (what the reader reads back).
pub fn camera_projector_calibration_to_value(c: &CameraProjectorCalibration) -> Value {
    let device = |d: &PinholeDevice| {
        serde_json::json!({"width": d.width, "height": d.height,
            "K": [[d.fx, 0.0, d.cx], [0.0, d.fy, d.cy], [0.0, 0.0, 1.0]], "distortion": d.distortion})
    };
    serde_json::json!({"model": PINHOLE_MODEL, "unit": c.unit.as_str(), "camera": device(&c.camera),
        "projector": device(&c.projector), "R": c.r, "t": c.t})
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Value {
        serde_json::json!({"model": "pinhole-camera-projector", "unit": "mm",
            "camera": {"width": 640, "height": 480, "K": [[800.0, 0, 319.5], [0, 805.0, 239.5], [0, 0, 1]],
                       "distortion": [-0.2, 0.08, 0.001, -0.002, 0.01]},
            "projector": {"width": 800, "height": 600, "K": [[1200.0, 0, 399.5], [0, 1200.0, 299.5], [0, 0, 1]],
                          "distortion": [0.05, 0.0, 0.0, 0.0]},
            "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [-120.0, 5.0, 30.0]})
    }

    #[test]
    fn a_camera_projector_calibration_reads_and_round_trips() {
        let (c, warnings) = camera_projector_calibration_from_value(&example(), "c.json").unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!((c.camera.fx, c.camera.cy, c.projector.width), (800.0, 239.5, 800));
        assert_eq!(c.projector.distortion, [0.05, 0.0, 0.0, 0.0, 0.0]);
        let back = camera_projector_calibration_from_value(&camera_projector_calibration_to_value(&c), "c.json");
        assert_eq!(back.unwrap().0, c);
    }

    #[test]
    fn a_calibration_that_cannot_be_used_is_one_line_saying_why() {
        let with = |edit: &dyn Fn(&mut Value)| {
            let mut v = example();
            edit(&mut v);
            camera_projector_calibration_from_value(&v, "c.json").unwrap_err().to_string()
        };
        let affine = with(&|v| v["model"] = "affine".into());
        assert!(
            affine.contains(
                "is a telecentric stereo (affine) calibration, but the manifest describes a camera–projector rig"
            ),
            "{affine}"
        );
        assert!(with(&|v| v["R"][0][0] = 2.0.into()).contains("'R' is not a rotation"));
        assert!(with(&|v| v["camera"]["K"][0][1] = 3.0.into()).contains("'camera.K' must be [[fx, 0, cx]"));
        assert!(
            with(&|v| v["projector"]["distortion"] = serde_json::json!([0.1, 0.2]))
                .contains("'projector.distortion' must be")
        );
        assert!(with(&|v| v["t"] = serde_json::json!([0, 0, 0])).contains("'t' is zero"));
        assert!(with(&|v| v["camera"]["width"] = 0.into()).contains("'camera.width' must be a positive whole number"));
        // The stereo reader says the same the other way round.
        let err =
            crate::io::calibration::calibration_from_value(&example(), Path::new("m.json")).unwrap_err().to_string();
        assert!(err.contains("is a camera–projector (pinhole-camera-projector) calibration, but the manifest describes two telecentric cameras"), "{err}");
    }
}
