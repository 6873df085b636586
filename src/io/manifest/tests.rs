//! Tests of the manifest contract: every fault class of the contract (manifest,
//! images, calibration) on small generated data sets, exact round trips of
//! manifests and samples in every supported format, and parsers that never
//! panic on arbitrary input.

use crate::engine::warning::{Warning, WarningKind};
use std::path::{Path, PathBuf};

use proptest::prelude::*;
use serde_json::{Value, json};

use super::*;
use crate::engine::control::RunControl;
use crate::io::calibration::{calibration_to_value, tests::rig, write_calibration};
use crate::io::images::tests::{write_gray8, write_gray16, write_pgm16};

/// What a generated data set looks like.
#[derive(Clone)]
struct Spec {
    bit_depth: u32,
    ext: &'static str,
    cameras: Vec<&'static str>,
    periods: Vec<f64>,
    shifts: usize,
    width: usize,
    height: usize,
    /// Write 16-bit data as PGM with this maximum value instead of `ext`.
    pgm_maxval: Option<u16>,
}

impl Default for Spec {
    fn default() -> Self {
        Self {
            bit_depth: 8,
            ext: "png",
            cameras: vec!["left", "right"],
            periods: vec![96.0, 24.0, 12.0],
            shifts: 4,
            width: 6,
            height: 5,
            pgm_maxval: None,
        }
    }
}

struct Fixture {
    dir: tempfile::TempDir,
    path: PathBuf,
    manifest: Manifest,
}

impl Fixture {
    fn file(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    fn image(&self, set: usize, camera: &str, k: usize) -> String {
        self.manifest.sets[set].images[camera][k].clone()
    }

    fn json(&self) -> Value {
        manifest_to_json(&self.manifest)
    }
}

/// Sample of camera `c`, set `s`, image `k`, pixel `p`: distinct along every
/// index, and reaching the container's top code for 12-bit data.
fn sample(bit_depth: u32, c: usize, s: usize, k: usize, p: usize) -> u16 {
    if bit_depth == 8 {
        ((c * 31 + s * 17 + k * 7 + p * 3) % 256) as u16
    } else if (c, s, k, p) == (0, 0, 0, 1) {
        4095
    } else {
        ((c * 331 + s * 177 + k * 71 + p * 37) % 4096) as u16
    }
}

fn build(spec: &Spec) -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let mut sets = Vec::new();
    for (s, &period) in spec.periods.iter().enumerate() {
        let mut images = BTreeMap::new();
        for (c, cam) in spec.cameras.iter().enumerate() {
            std::fs::create_dir_all(dir.path().join(cam)).unwrap();
            let mut list = Vec::new();
            for k in 0..spec.shifts {
                let ext = if spec.pgm_maxval.is_some() { "pgm" } else { spec.ext };
                let rel = format!("{cam}/p{:04}_{k:02}.{ext}", period as u32);
                let path = dir.path().join(&rel);
                let n = spec.width * spec.height;
                let values: Vec<u16> = (0..n).map(|p| sample(spec.bit_depth, c, s, k, p)).collect();
                let (w, h) = (spec.width as u32, spec.height as u32);
                match (spec.bit_depth, spec.pgm_maxval) {
                    (8, _) => write_gray8(&path, w, h, &values.iter().map(|&v| v as u8).collect::<Vec<_>>()),
                    (_, Some(maxval)) => write_pgm16(&path, spec.width, spec.height, maxval, &values),
                    _ => write_gray16(&path, w, h, &values),
                }
                list.push(rel);
            }
            images.insert(cam.to_string(), list);
        }
        sets.push(ManifestSet {
            period_px: period,
            shifts: spec.shifts,
            phase_shifts_rad: None,
            axis: Default::default(),
            images,
        });
    }
    let manifest = Manifest {
        bit_depth: spec.bit_depth,
        saturation_level: None,
        calibration: None,
        sets,
        projector: None,
        gray_code: None,
        warnings: Vec::new(),
    };
    let path = dir.path().join("fringe-set.json");
    write_manifest(&path, &manifest).unwrap();
    Fixture { dir, path, manifest }
}

fn load(path: &Path) -> Result<Loaded, IoError> {
    load_measurement(path, &RunControl::new())
}

fn assert_samples(loaded: &Loaded, spec: &Spec, names: &[&str]) {
    let m = &loaded.measurement;
    let order: Vec<&str> = m.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(order, names);
    for cam in &m.cameras {
        let c = spec.cameras.iter().position(|n| *n == cam.name).unwrap();
        assert_eq!((cam.width, cam.height), (spec.width, spec.height));
        for (s, stack) in cam.stacks.iter().enumerate() {
            assert_eq!(stack.shifts, spec.shifts);
            assert_eq!(matches!(stack.samples, Samples::U8(_)), spec.bit_depth == 8);
            for k in 0..spec.shifts {
                for p in 0..spec.width * spec.height {
                    assert_eq!(
                        stack.sample(k, p),
                        sample(spec.bit_depth, c, s, k, p),
                        "{} set {s} image {k} px {p}",
                        cam.name
                    );
                }
            }
        }
    }
}

#[test]
fn eight_bit_sets_in_every_format_load_exactly() {
    for ext in ["png", "tif", "bmp", "pgm"] {
        let spec = Spec { ext, ..Spec::default() };
        let fx = build(&spec);
        let loaded = load(&fx.path).unwrap_or_else(|e| panic!("{ext}: {e}"));
        assert_samples(&loaded, &spec, &["left", "right"]);
        assert!(loaded.warnings.is_empty(), "{ext}: {:?}", loaded.warnings);
        let m = &loaded.measurement;
        assert_eq!((m.bit_depth, m.saturation_level), (8, 255));
        assert_eq!(m.periods_px(), vec![96.0, 24.0, 12.0]);
        assert_eq!(m.sets[1].phase_shifts_rad, crate::engine::fringe::uniform_shifts_rad(4));
        assert_eq!(m.label, fx.path.display().to_string());
        assert!(m.calibration.is_none());
    }
}

#[test]
fn twelve_bit_data_in_sixteen_bit_files_loads_exactly() {
    for (ext, maxval) in [("png", None), ("tif", None), ("pgm", None), ("pgm", Some(4095))] {
        let spec = Spec { bit_depth: 12, ext, pgm_maxval: maxval, ..Spec::default() };
        let fx = build(&spec);
        let loaded = load(&fx.path).unwrap_or_else(|e| panic!("{ext}: {e}"));
        assert_samples(&loaded, &spec, &["left", "right"]);
        assert_eq!(loaded.measurement.saturation_level, 4095);
        assert!(loaded.warnings.is_empty(), "{ext}: {:?}", loaded.warnings);
    }
}

#[test]
fn camera_order_is_left_right_then_sorted_and_one_camera_is_allowed() {
    let spec = Spec { cameras: vec!["zeta", "right", "aux", "left"], periods: vec![50.0, 10.0], ..Spec::default() };
    let loaded = load(&build(&spec).path).unwrap();
    assert_samples(&loaded, &spec, &["left", "right", "aux", "zeta"]);
    let spec = Spec { cameras: vec!["cam0"], ..Spec::default() };
    let loaded = load(&build(&spec).path).unwrap();
    assert_samples(&loaded, &spec, &["cam0"]);
}

#[test]
fn ids_are_fresh_progress_completes_and_cancel_stops() {
    let fx = build(&Spec::default());
    let control = RunControl::new();
    let a = load_measurement(&fx.path, &control).unwrap();
    assert_eq!(control.progress(), ("load images".to_string(), 1.0));
    let b = load(&fx.path).unwrap();
    assert_ne!(a.measurement.id, b.measurement.id);
    let control = RunControl::new();
    control.cancel();
    assert!(matches!(load_measurement(&fx.path, &control), Err(IoError::Cancelled(_))));
}

#[test]
fn explicit_shifts_saturation_level_and_calibration_file_are_applied() {
    let fx = build(&Spec::default());
    write_calibration(&fx.file("calibration.json"), &calibration_for(6, 5)).unwrap();
    let mut v = fx.json();
    v["saturation_level"] = json!(250);
    v["calibration"] = json!("calibration.json");
    v["sets"][2]["phase_shifts_rad"] = json!([0.0, -1.5, -3.0, -4.5]);
    std::fs::write(&fx.path, v.to_string()).unwrap();
    let m = load(&fx.path).unwrap().measurement;
    assert_eq!(m.saturation_level, 250);
    assert_eq!(m.sets[2].phase_shifts_rad, vec![0.0, -1.5, -3.0, -4.5]);
    assert_eq!(m.calibration, Some(calibration_for(6, 5)));
    // Inline calibration gives the same.
    v["calibration"] = calibration_to_value(&calibration_for(6, 5));
    std::fs::write(&fx.path, v.to_string()).unwrap();
    assert_eq!(load(&fx.path).unwrap().measurement.calibration, Some(calibration_for(6, 5)));
}

fn calibration_for(width: usize, height: usize) -> crate::engine::camera_model::StereoCalibration {
    let mut c = rig();
    for cam in [&mut c.left, &mut c.right] {
        cam.width = width;
        cam.height = height;
    }
    c.right.distortion = None;
    c
}

#[test]
fn write_read_round_trip_is_equal() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.json");
    let mut images = BTreeMap::new();
    images.insert("left".to_string(), vec!["l/a0.tif".to_string(), "l/a1.tif".into(), "l/a2.tif".into()]);
    images.insert("right".to_string(), vec!["r/a0.tif".to_string(), "r/a1.tif".into(), "r/a2.tif".into()]);
    let mut images2 = images.clone();
    images2.values_mut().flatten().for_each(|p| *p = p.replace('a', "b"));
    let m = Manifest {
        bit_depth: 12,
        saturation_level: Some(4000),
        calibration: Some(CalibrationSource::Inline(calibration_to_value(&rig()))),
        sets: vec![
            ManifestSet { period_px: 912.0, shifts: 3, phase_shifts_rad: None, axis: Default::default(), images },
            ManifestSet {
                period_px: 22.5,
                shifts: 3,
                phase_shifts_rad: Some(vec![0.1, 2.2, 4.300_000_000_000_001]),
                axis: Default::default(),
                images: images2,
            },
        ],
        projector: None,
        gray_code: None,
        warnings: Vec::new(),
    };
    write_manifest(&path, &m).unwrap();
    let back = read_manifest(&path).unwrap();
    assert_eq!(back, m);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.trim_start().starts_with("{\n  \"sheen_fringe_set\": 1"), "{text}");
    assert!(text.contains("\"period\": 912,"), "{text}");
    // File calibration round-trips too.
    let m2 = Manifest { calibration: Some(CalibrationSource::File("calibration.json".into())), ..m };
    write_manifest(&path, &m2).unwrap();
    assert_eq!(read_manifest(&path).unwrap(), m2);
}

#[test]
fn write_makes_paths_inside_the_folder_relative_and_refuses_others() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.json");
    let abs = |rel: &str| dir.path().join(rel).display().to_string();
    let mut images = BTreeMap::new();
    images.insert("left".to_string(), vec![abs("left/0.png"), abs("left/1.png"), "left/2.png".into()]);
    let mut m = Manifest {
        bit_depth: 8,
        saturation_level: None,
        calibration: None,
        sets: vec![ManifestSet {
            period_px: 100.0,
            shifts: 3,
            phase_shifts_rad: None,
            axis: Default::default(),
            images,
        }],
        projector: None,
        gray_code: None,
        warnings: Vec::new(),
    };
    write_manifest(&path, &m).unwrap();
    let back = read_manifest(&path).unwrap();
    assert_eq!(back.sets[0].images["left"], ["left/0.png", "left/1.png", "left/2.png"]);
    m.sets[0].images.get_mut("left").unwrap()[0] = "/elsewhere/0.png".into();
    let err = write_manifest(&path, &m).unwrap_err().to_string();
    assert!(err.contains("'/elsewhere/0.png' is absolute"), "{err}");
    // The refused write left the earlier manifest in place.
    assert_eq!(read_manifest(&path).unwrap(), back);
}

#[test]
fn in_memory_manifests_load_and_are_checked_like_files() {
    let fx = build(&Spec { cameras: vec!["left"], ..Spec::default() });
    let elsewhere = fx.file("not-yet-written.json");
    let loaded = load_manifest_measurement(&fx.manifest, &elsewhere, &RunControl::new()).unwrap();
    assert_eq!(loaded.measurement.label, elsewhere.display().to_string());
    let mut bad = fx.manifest.clone();
    bad.sets.swap(0, 1);
    let err = load_manifest_measurement(&bad, &elsewhere, &RunControl::new()).unwrap_err().to_string();
    assert!(err.contains("not-yet-written.json") && err.contains("does not follow set 0"), "{err}");
}

#[test]
fn exports_cannot_overwrite_inputs() {
    let fx = build(&Spec::default());
    let inputs = fx.manifest.input_paths(&fx.path);
    assert_eq!(inputs.len(), 1 + 2 * 3 * 4);
    let image = fx.file(&fx.image(1, "right", 2));
    let err = crate::io::atomic::refuse_overwriting_inputs(&image, &inputs).unwrap_err();
    assert!(err.to_string().contains("is an input"), "{err}");
    crate::io::atomic::refuse_overwriting_inputs(&fx.path, &inputs).unwrap_err();
    crate::io::atomic::refuse_overwriting_inputs(&fx.file("cloud.ply"), &inputs).unwrap();
}

/// The messages of the warnings of one kind, one per line.
fn of_kind(warnings: &[Warning], kind: WarningKind) -> String {
    warnings.iter().filter(|w| w.kind == kind).map(|w| w.message.as_str()).collect::<Vec<_>>().join("\n")
}

#[test]
fn warnings_for_unknown_keys_colour_images_repeats_and_unused_bits() {
    let fx = build(&Spec::default());
    let mut v = fx.json();
    v["exposure_ms"] = json!(3);
    v["sets"][1]["perod"] = json!(24);
    // A colour image replaces one grey one: converted to luma with a warning.
    let rel = fx.image(2, "left", 1);
    let rgb: image::RgbImage =
        image::ImageBuffer::from_fn(6, 5, |x, y| image::Rgb([(x * 40) as u8, (y * 50) as u8, 7]));
    rgb.save(fx.file(&rel)).unwrap();
    std::fs::write(&fx.path, v.to_string()).unwrap();
    let loaded = load(&fx.path).unwrap();
    let w = of_kind(&loaded.warnings, WarningKind::IgnoredInput);
    assert!(w.contains("unknown key 'exposure_ms'") && w.contains("unknown key 'sets[1].perod'"), "{w}");
    let w = of_kind(&loaded.warnings, WarningKind::ImageConverted);
    assert!(w.contains(&format!("camera 'left' set 2 image 1 {rel} is a colour image")), "{w}");
    let stack = &loaded.measurement.cameras[0].stacks[2];
    let luma = |x: u32, y: u32| (0.2126 * f64::from(x * 40) + 0.7152 * f64::from(y * 50) + 0.0722 * 7.0).round() as u16;
    assert_eq!(stack.sample(1, 6 + 2), luma(2, 1));
    // A repeated image is suspicious but loadable.
    let mut v = fx.json();
    v["sets"][1]["images"]["right"][3] = json!(fx.image(0, "right", 0));
    std::fs::write(&fx.path, v.to_string()).unwrap();
    let w = of_kind(&load(&fx.path).unwrap().warnings, WarningKind::RepeatedImage);
    assert!(w.contains("set 1 camera 'right' image 3 repeats right/p0096_00.png, already set 0"), "{w}");
    // 12-bit data declared as 16-bit: saturation would never be detected.
    let fx = build(&Spec { bit_depth: 12, ..Spec::default() });
    let mut v = fx.json();
    v["bit_depth"] = json!(16);
    std::fs::write(&fx.path, v.to_string()).unwrap();
    let w = of_kind(&load(&fx.path).unwrap().warnings, WarningKind::BitDepthUnreached);
    assert!(w.contains("largest sample is 4095 but bit_depth is 16") && w.contains("12-bit"), "{w}");
}

/// A fault: how to break the fixture, and what the message must say.
struct Case {
    name: &'static str,
    spec: Spec,
    /// Edits the manifest JSON and/or files; `Some(text)` replaces the manifest text.
    breaks: fn(&Fixture, &mut Value) -> Option<String>,
    expect: &'static [&'static str],
}

fn case(
    name: &'static str,
    breaks: fn(&Fixture, &mut Value) -> Option<String>,
    expect: &'static [&'static str],
) -> Case {
    Case { name, spec: Spec::default(), breaks, expect }
}

fn remove(v: &mut Value, key: &str) {
    v.as_object_mut().expect("an object").remove(key);
}

#[test]
fn every_bad_input_gives_an_error_naming_the_file_and_the_fault() {
    let sixteen = Spec { bit_depth: 12, ..Spec::default() };
    let cases = vec![
        case(
            "invalid json",
            |_, _| Some("{\"sheen_fringe_set\": 1,\n  \"bit_depth\": 8,,\n}".into()),
            &["fringe-set.json", "not valid JSON at line 2, column 18"],
        ),
        case(
            "not an object",
            |_, _| Some("[1, 2]".into()),
            &["fringe-set.json", "must be a JSON object", "found a list of 2 item(s)"],
        ),
        case(
            "unknown version",
            |_, v| {
                v["sheen_fringe_set"] = json!(2);
                None
            },
            &["declares sheen_fringe_set 2;", "reads version 1"],
        ),
        case(
            "missing version",
            |_, v| {
                remove(v, "sheen_fringe_set");
                None
            },
            &["lacks the key 'sheen_fringe_set'"],
        ),
        case(
            "missing bit depth",
            |_, v| {
                remove(v, "bit_depth");
                None
            },
            &["lacks the key 'bit_depth'"],
        ),
        case(
            "bad bit depth",
            |_, v| {
                v["bit_depth"] = json!(7);
                None
            },
            &["bit_depth must be 8", "found the number 7"],
        ),
        case(
            "bad saturation level",
            |_, v| {
                v["saturation_level"] = json!(256);
                None
            },
            &["saturation_level must be 1 to 255", "found the number 256"],
        ),
        case(
            "missing sets",
            |_, v| {
                remove(v, "sets");
                None
            },
            &["lacks the key 'sets'"],
        ),
        case(
            "no sets",
            |_, v| {
                v["sets"] = json!([]);
                None
            },
            &["lists no fringe set"],
        ),
        case(
            "missing period",
            |_, v| {
                remove(&mut v["sets"][1], "period");
                None
            },
            &["lacks the key 'sets[1].period'"],
        ),
        case(
            "missing images",
            |_, v| {
                remove(&mut v["sets"][2], "images");
                None
            },
            &["lacks the key 'sets[2].images'"],
        ),
        case(
            "periods out of order",
            |_, v| {
                v["sets"][1]["period"] = json!(120);
                None
            },
            &["set 1 (period 120 px) does not follow set 0 (period 96 px)", "largest period to the smallest"],
        ),
        case(
            "equal periods",
            |_, v| {
                v["sets"][2]["period"] = json!(24);
                None
            },
            &["set 2 (period 24 px) does not follow set 1 (period 24 px)"],
        ),
        case(
            "negative period",
            |_, v| {
                v["sets"][2]["period"] = json!(-12);
                None
            },
            &["set 2: period must be a positive number", "found the number -12"],
        ),
        case(
            "period as text",
            |_, v| {
                v["sets"][0]["period"] = json!("96");
                None
            },
            &["set 0: period must be a positive number", "found the text \"96\""],
        ),
        case(
            "too few shifts",
            |_, v| {
                v["sets"][1]["shifts"] = json!(2);
                None
            },
            &["set 1 (period 24 px): shifts must be 3 to 32, found the number 2"],
        ),
        case(
            "shifts not matching images",
            |_, v| {
                v["sets"][1]["shifts"] = json!(5);
                None
            },
            &["set 1 (period 24 px) camera 'left' lists 4 images but shifts is 5"],
        ),
        case(
            "image list too short",
            |_, v| {
                v["sets"][2]["images"]["right"].as_array_mut().expect("a list").pop();
                None
            },
            &["set 2 (period 12 px) camera 'right' lists 3 images but shifts is 4"],
        ),
        case(
            "shift list length",
            |_, v| {
                v["sets"][0]["phase_shifts_rad"] = json!([0, 1, 2]);
                None
            },
            &["set 0 (period 96 px): phase_shifts_rad lists 3 shifts but shifts is 4"],
        ),
        case(
            "degenerate shift list",
            |_, v| {
                v["sets"][0]["phase_shifts_rad"] = json!([0.5, 0.5, 0.5, 0.5]);
                None
            },
            &["set 0 (period 96 px): phase_shifts_rad do not determine a phase"],
        ),
        case(
            "camera missing in a set",
            |_, v| {
                remove(&mut v["sets"][1]["images"], "right");
                None
            },
            &["set 1 (period 24 px) has cameras [left] but set 0 has [left, right]"],
        ),
        case(
            "camera renamed in a set",
            |_, v| {
                let right = v["sets"][2]["images"]["right"].take();
                remove(&mut v["sets"][2]["images"], "right");
                v["sets"][2]["images"]["Right"] = right;
                None
            },
            &["set 2 (period 12 px) has cameras [Right, left] but set 0 has [left, right]"],
        ),
        case(
            "no cameras",
            |_, v| {
                v["sets"][0]["images"] = json!({});
                None
            },
            &["set 0 (period 96 px) lists no camera"],
        ),
        case(
            "path escaping with ..",
            |_, v| {
                v["sets"][0]["images"]["left"][2] = json!("../x.png");
                None
            },
            &["set 0 camera 'left' image 2 path '../x.png' leaves the manifest's folder"],
        ),
        case(
            "path escaping through a subfolder",
            |_, v| {
                v["sets"][1]["images"]["right"][0] = json!("right/../../x.png");
                None
            },
            &["set 1 camera 'right' image 0 path 'right/../../x.png' leaves the manifest's folder"],
        ),
        case(
            "absolute path",
            |_, v| {
                v["sets"][2]["images"]["left"][3] = json!("/etc/passwd");
                None
            },
            &["set 2 camera 'left' image 3 path '/etc/passwd' is absolute"],
        ),
        case(
            "calibration path escaping",
            |_, v| {
                v["calibration"] = json!("../calibration.json");
                None
            },
            &["calibration path '../calibration.json' leaves the manifest's folder"],
        ),
        case(
            "missing image",
            |fx, _| {
                std::fs::remove_file(fx.file(&fx.image(1, "right", 3))).unwrap();
                None
            },
            &["camera 'right' set 1 image 3 right/p0024_03.png does not exist"],
        ),
        case(
            "unreadable image",
            |fx, _| {
                let p = fx.file(&fx.image(2, "left", 0));
                std::fs::remove_file(&p).unwrap();
                std::fs::create_dir(&p).unwrap();
                None
            },
            &["camera 'left' set 2 image 0 left/p0012_00.png cannot be read"],
        ),
        case(
            "truncated image",
            |fx, _| {
                let p = fx.file(&fx.image(1, "left", 2));
                let bytes = std::fs::read(&p).unwrap();
                std::fs::write(&p, &bytes[..bytes.len() * 2 / 3]).unwrap();
                None
            },
            &["camera 'left' set 1 image 2 left/p0024_02.png cannot be decoded", "truncated or corrupt"],
        ),
        case(
            "corrupt image",
            |fx, _| {
                let p = fx.file(&fx.image(2, "right", 1));
                let mut bytes = std::fs::read(&p).unwrap();
                let n = bytes.len();
                bytes[n / 2..n - 12].iter_mut().for_each(|b| *b ^= 0x5A);
                std::fs::write(&p, &bytes).unwrap();
                None
            },
            &["camera 'right' set 2 image 1 right/p0012_01.png cannot be decoded"],
        ),
        case(
            "first image corrupt",
            |fx, _| {
                std::fs::write(fx.file(&fx.image(0, "left", 0)), b"\x89PNG\r\n\x1a\n").unwrap();
                None
            },
            &["camera 'left' set 0 image 0 left/p0096_00.png cannot be decoded"],
        ),
        case(
            "different sizes",
            |fx, _| {
                write_gray8(&fx.file(&fx.image(1, "left", 2)), 6, 4, &[9; 24]);
                None
            },
            &["camera 'left' set 1 image 2 left/p0024_02.png is 6x4 px, expected 6x5 px like left/p0096_00.png"],
        ),
        case(
            "different bit depths",
            |fx, _| {
                write_gray16(&fx.file(&fx.image(2, "right", 3)), 6, 5, &[300; 30]);
                None
            },
            &["camera 'right' set 2 image 3 right/p0012_03.png is a 16-bit file but the manifest declares bit_depth 8"],
        ),
        Case {
            name: "8-bit file in a 12-bit set",
            spec: sixteen.clone(),
            breaks: |fx, _| {
                write_gray8(&fx.file(&fx.image(0, "left", 1)), 6, 5, &[9; 30]);
                None
            },
            expect: &[
                "camera 'left' set 0 image 1 left/p0096_01.png is an 8-bit file but the manifest declares bit_depth 12",
            ],
        },
        Case {
            name: "bit depth inconsistent with the data",
            spec: sixteen.clone(),
            breaks: |_, v| {
                v["bit_depth"] = json!(10);
                None
            },
            expect: &["camera 'left' set 0 image 0 left/p0096_00.png holds values up to 4095", "set bit_depth to 12"],
        },
        case(
            "calibration file missing",
            |_, v| {
                v["calibration"] = json!("calibration.json");
                None
            },
            &["cannot read", "calibration.json", "check that the path exists"],
        ),
        case(
            "calibration with wrong P shape",
            |fx, v| {
                let mut c = calibration_to_value(&calibration_for(6, 5));
                c["cameras"]["left"]["P"] = json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]);
                std::fs::write(fx.file("calibration.json"), c.to_string()).unwrap();
                v["calibration"] = json!("calibration.json");
                None
            },
            &["calibration.json", "camera 'left': P must be 2 rows of 4 numbers, found 3x4"],
        ),
        case(
            "calibration with parallel views",
            |fx, v| {
                let mut c = calibration_for(6, 5);
                c.right.p = c.left.p;
                write_calibration(&fx.file("calibration.json"), &c).unwrap();
                v["calibration"] = json!("calibration.json");
                None
            },
            &["calibration.json", "viewing directions are parallel"],
        ),
        case(
            "inline calibration rank deficient",
            |_, v| {
                let mut c = calibration_for(6, 5);
                c.left.p = [[1.0, 2.0, 3.0, 0.0], [2.0, 4.0, 6.0, 0.0]];
                v["calibration"] = calibration_to_value(&c);
                None
            },
            &["inline calibration in", "fringe-set.json", "camera 'left'", "rank below 2"],
        ),
        case(
            "calibration for another image size",
            |fx, v| {
                write_calibration(&fx.file("calibration.json"), &calibration_for(6, 6)).unwrap();
                v["calibration"] = json!("calibration.json");
                None
            },
            &[
                "calibration",
                "calibration.json",
                "camera 'left' is calibrated for 6x6 px images",
                "left/p0096_00.png is 6x5 px",
            ],
        ),
        case(
            "calibration of wrong type",
            |_, v| {
                v["calibration"] = json!(3);
                None
            },
            &["'calibration' must be a file name or a calibration object"],
        ),
        case(
            "camera name that is a path",
            |_, v| {
                for s in 0..3 {
                    let left = v["sets"][s]["images"]["left"].take();
                    remove(&mut v["sets"][s]["images"], "left");
                    v["sets"][s]["images"]["../left"] = left;
                }
                None
            },
            &["camera name '../left' is not usable"],
        ),
    ];
    for c in cases {
        let fx = build(&c.spec);
        let mut v = fx.json();
        if let Some(text) = (c.breaks)(&fx, &mut v) {
            std::fs::write(&fx.path, text).unwrap();
        } else {
            std::fs::write(&fx.path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
        }
        let msg = match load(&fx.path) {
            Ok(_) => panic!("case '{}' loaded without error", c.name),
            Err(e) => e.to_string(),
        };
        let names_file = msg.contains("fringe-set.json") || msg.contains(".png") || msg.contains("calibration.json");
        assert!(names_file, "case '{}' names no file: {msg}", c.name);
        for e in c.expect {
            assert!(msg.contains(e), "case '{}': expected {e:?} in:\n{msg}", c.name);
        }
    }
}

#[test]
fn image_errors_name_the_manifest_relative_path_and_location() {
    let fx = build(&Spec::default());
    std::fs::remove_file(fx.file(&fx.image(2, "left", 1))).unwrap();
    let err = load(&fx.path).unwrap_err();
    let IoError::Image { path, location: Some(loc), fault } = &err else { panic!("{err:?}") };
    assert_eq!(path, &fx.file("left/p0012_01.png"));
    assert_eq!((loc.camera.as_str(), loc.set, loc.image), ("left", 2, 1));
    assert_eq!(fault, &images::ImageFault::Missing);
}

#[test]
fn impossible_allocations_are_refused_not_aborted() {
    assert!(alloc::<u16>(usize::MAX / 2).is_none());
    assert!(available_memory_bytes().is_some_and(|a| a > 0));
    let msg = IoError::OutOfMemory { path: "/d/m.json".into(), bytes: 3 << 30, available: Some(1 << 30) }.to_string();
    assert!(
        msg.contains("/d/m.json") && msg.contains("need 3.0 GiB") && msg.contains("only 1.0 GiB is available"),
        "{msg}"
    );
    assert_eq!(alloc::<u8>(3), Some(vec![0, 0, 0]));
}

/// Arbitrary JSON values, nested a few levels.
fn arb_json() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(|i| json!(i)),
        any::<f64>().prop_filter("finite", |x| x.is_finite()).prop_map(|x| json!(x)),
        "[a-z/._]{0,12}".prop_map(Value::String),
    ];
    leaf.prop_recursive(4, 48, 6, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
            prop::collection::btree_map("[a-z_]{1,18}", inner, 0..6)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn manifest_parser_never_panics_on_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = parse_manifest_bytes(&bytes, Path::new("fuzz.json"));
    }

    #[test]
    fn manifest_parser_never_panics_on_json(v in arb_json()) {
        let _ = parse_manifest_bytes(v.to_string().as_bytes(), Path::new("fuzz.json"));
    }
}

/// A valid manifest with one value replaced anywhere by arbitrary JSON:
/// an error or a manifest that passes its own checks. Both outcomes are
/// counted, so the check on accepted manifests cannot pass by never running.
#[test]
fn mutated_manifests_error_or_validate() {
    let text = r#"{"sheen_fringe_set": 1, "bit_depth": 8, "saturation_level": 250,
        "sets": [{"period": 96, "shifts": 3, "phase_shifts_rad": [0, 2, 4],
                  "images": {"left": ["l/0.png", "l/1.png", "l/2.png"], "right": ["r/0.png", "r/1.png", "r/2.png"]}},
                 {"period": 12, "shifts": 3,
                  "images": {"left": ["l/3.png", "l/4.png", "l/5.png"], "right": ["r/3.png", "r/4.png", "r/5.png"]}}]}"#;
    // Arbitrary JSON is nearly always refused; values of the kinds a
    // manifest holds make accepted manifests common enough to check.
    let plausible = prop_oneof![
        (1u64..300).prop_map(|n| json!(n)),
        (0.0f64..7.0).prop_map(|x| json!(x)),
        "[lr]/[0-9]\\.png".prop_map(Value::String),
    ];
    let replacement = prop_oneof![arb_json(), plausible];
    let (accepted, refused) =
        crate::io::json::count_outcomes(400, &(replacement, 0usize..64), |(replacement, pick)| {
            let mut v: Value = serde_json::from_str(text).unwrap();
            let mut slots = Vec::new();
            collect_pointers(&v, String::new(), &mut slots);
            let target = slots[pick % slots.len()].clone();
            if let Some(slot) = v.pointer_mut(&target) {
                *slot = replacement;
            }
            match parse_manifest_bytes(v.to_string().as_bytes(), Path::new("fuzz.json")) {
                Ok(m) => {
                    prop_assert!(m.validate(Path::new("fuzz.json")).is_ok());
                    prop_assert!(m.sets.windows(2).all(|w| w[0].period_px > w[1].period_px));
                    Ok(true)
                }
                Err(_) => Ok(false),
            }
        });
    eprintln!("mutated manifests: {accepted} accepted, {refused} refused");
    assert!(accepted >= 20 && refused >= 20, "{accepted} accepted, {refused} refused: both must be exercised");
}

fn collect_pointers(v: &Value, at: String, out: &mut Vec<String>) {
    out.push(at.clone());
    match v {
        Value::Array(a) => a.iter().enumerate().for_each(|(i, x)| collect_pointers(x, format!("{at}/{i}"), out)),
        Value::Object(m) => m.iter().for_each(|(k, x)| collect_pointers(x, format!("{at}/{k}"), out)),
        _ => {}
    }
}

#[test]
fn sample_buffers_come_zeroed_at_their_length_and_a_reused_block_is_zeroed_again() {
    // The first buffer is written all over and freed, so the allocator may
    // hand its block to the next: zeroed memory must then be zeroed anew.
    let mut first = alloc::<u16>(1 << 20).expect("4 MiB");
    first.iter_mut().for_each(|v| *v = 0xABCD);
    drop(first);
    for len in [0usize, 1, 4095, 1 << 20, 3 << 20] {
        let eight = alloc::<u8>(len).expect("memory");
        let sixteen = alloc::<u16>(len).expect("memory");
        assert_eq!((eight.len(), sixteen.len()), (len, len));
        assert!(eight.iter().all(|&v| v == 0) && sixteen.iter().all(|&v| v == 0), "len {len}");
    }
    assert!(alloc::<u16>(usize::MAX / 2).is_none(), "an impossible size is refused, not a panic");
}

/// A camera–projector manifest as issue 52 writes it: two sets per axis,
/// the 20 x 11 cell code of 100 px over a 1920 x 1080 projector.
fn camera_projector_json() -> Value {
    let frames = |first: usize, n: usize| (first..first + n).map(|i| format!("pat{i:02}.png")).collect::<Vec<_>>();
    let set = |period: f64, axis: &str, first: usize| json!({"period": period, "shifts": 3, "axis": axis, "images": {"cam": frames(first, 3)}});
    json!({"sheen_fringe_set": 1, "bit_depth": 8, "rig": "camera-projector",
           "projector": {"width": 1920, "height": 1080},
           "sets": [set(100.0, "x", 3), set(66.666667, "x", 0), set(100.0, "y", 9), set(66.666667, "y", 6)],
           "gray_code": {"layout": "opencv", "cell_px": 100, "columns": {"cam": frames(12, 10)},
                         "rows": {"cam": frames(22, 8)}, "white": {"cam": "pat30.png"}, "black": {"cam": "pat31.png"}}})
}

fn parse_value(v: &Value) -> Result<Manifest, ManifestFault> {
    match parse_manifest_bytes(v.to_string().as_bytes(), Path::new("m.json")) {
        Ok(m) => Ok(m),
        Err(IoError::Manifest { fault, .. }) => Err(fault),
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn a_camera_projector_manifest_reads_and_round_trips() {
    let m = parse_value(&camera_projector_json()).unwrap();
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    assert_eq!(m.projector, Some(ProjectorSize { width_px: 1920, height_px: 1080 }));
    let axes: Vec<ProjectorAxis> = m.sets.iter().map(|s| s.axis).collect();
    assert_eq!(axes, [ProjectorAxis::X, ProjectorAxis::X, ProjectorAxis::Y, ProjectorAxis::Y]);
    let code = m.gray_code.as_ref().unwrap();
    assert_eq!((code.cell_px, code.frames_needed(1920), code.frames_needed(1080)), (100, 10, 8));
    assert_eq!(m.set_infos(ProjectorAxis::X).len(), 2);
    assert_eq!(m.set_infos(ProjectorAxis::Y)[0].period_px, 100.0);
    // Every frame is an input exports must not overwrite.
    assert_eq!(m.input_paths(Path::new("m.json")).len(), 1 + 12 + 20);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.json");
    write_manifest(&path, &m).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"rig\": \"camera-projector\"") && text.contains("\"axis\": \"y\""), "{text}");
    assert_eq!(read_manifest(&path).unwrap(), m);
    // A telecentric pair's manifest is written as before: no axis.
    let plain = Manifest { projector: None, gray_code: None, sets: m.sets[..2].to_vec(), ..m.clone() };
    write_manifest(&path, &plain).unwrap();
    assert!(!std::fs::read_to_string(&path).unwrap().contains("axis"));
}

#[test]
fn a_camera_projector_manifest_that_does_not_add_up_is_one_fault_naming_what() {
    let base = camera_projector_json();
    let with = |edit: &dyn Fn(&mut Value)| {
        let mut v = base.clone();
        edit(&mut v);
        parse_value(&v).unwrap_err()
    };
    let no_rig = with(&|v| {
        let o = v.as_object_mut().expect("an object");
        o.remove("rig");
        o.remove("projector");
        o.remove("gray_code");
    });
    assert_eq!(no_rig, ManifestFault::AxisWithoutProjector { set: 2, period: 100.0 });
    assert_eq!(
        with(&|v| v.as_object_mut().expect("an object").remove("projector").map(drop).unwrap()),
        ManifestFault::NoProjector
    );
    assert_eq!(
        with(&|v| v.as_object_mut().expect("an object").remove("rig").map(drop).unwrap()),
        ManifestFault::ProjectorWithoutRig
    );
    assert!(matches!(with(&|v| v["rig"] = json!("stereo-pair")), ManifestFault::BadRig { .. }));
    assert!(matches!(with(&|v| v["projector"]["width"] = json!(0)), ManifestFault::BadProjector { key: "width", .. }));
    assert!(matches!(with(&|v| v["sets"][1]["axis"] = json!("z")), ManifestFault::BadAxis { set: 1, .. }));
    assert!(matches!(with(&|v| v["gray_code"]["layout"] = json!("sls")), ManifestFault::BadGrayLayout { .. }));
    assert!(matches!(with(&|v| v["gray_code"]["cell_px"] = json!(0)), ManifestFault::BadCellSize { .. }));
    // Periods decrease within each axis, not across them.
    let order = with(&|v| v["sets"].as_array_mut().expect("a list").swap(2, 3));
    assert_eq!(order, ManifestFault::PeriodOrder { set: 3, period: 100.0, previous_set: 2, previous: 66.666667 });
    let only_y = with(&|v| {
        v["sets"][0]["axis"] = json!("y");
        v["sets"][1]["axis"] = json!("y");
        v["sets"].as_array_mut().expect("a list").truncate(2);
    });
    assert_eq!(only_y, ManifestFault::NoSetAlongX);
    // A frame missing, and a code for a projector twice as wide.
    let missing = with(&|v| drop(v["gray_code"]["columns"]["cam"].as_array_mut().expect("a list").pop()));
    assert_eq!(
        missing,
        ManifestFault::GrayFrameCount {
            list: "columns",
            camera: "cam".into(),
            found: 9,
            expected: 10,
            cell_px: 100,
            extent_px: 1920
        }
    );
    let wider = with(&|v| v["projector"]["width"] = json!(3840));
    assert!(matches!(wider, ManifestFault::GrayFrameCount { expected: 12, found: 10, .. }), "{wider:?}");
    assert!(wider.to_string().contains("a frame is missing or extra, or cell_px or the projector size is wrong"));
    let cameras = with(&|v| v["gray_code"]["white"] = json!({"other": "pat30.png"}));
    assert!(matches!(cameras, ManifestFault::GrayCodeCameras { list: "white", .. }), "{cameras:?}");
    let outside = with(&|v| v["gray_code"]["black"]["cam"] = json!("../pat31.png"));
    assert!(matches!(outside, ManifestFault::BadGrayPath { list: "black", .. }), "{outside:?}");
    let no_code_rig = with(&|v| {
        let o = v.as_object_mut().expect("an object");
        o.remove("rig");
        o.remove("projector");
        for s in o["sets"].as_array_mut().expect("a list") {
            s["axis"] = json!("x");
        }
        o["sets"].as_array_mut().expect("a list").truncate(2);
    });
    assert_eq!(no_code_rig, ManifestFault::GrayCodeWithoutProjector);
}
