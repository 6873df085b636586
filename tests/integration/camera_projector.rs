//! A camera–projector rig from the command line (issue 52): a capture laid
//! out like the real mug scan (two 3-step sets per axis whose wraps fall on
//! the Gray code's cell edges, OpenCV's Gray code with inverse frames,
//! white, black, one file per frame numbered in projection order) imports
//! with one command, `sheen check` decodes its code, and `sheen phase
//! --maps` writes the absolute projector coordinates, recovered against
//! the truth; frames out of order and missing frames are one line naming
//! the files.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use sheen::engine::gray_code::{bit_planes, pattern_is_bright};
use sheen::io::maps::read_f32_tiff;

const CAMERA: (usize, usize) = (160, 120);
const PROJECTOR: (usize, usize) = (640, 480);
const CELL_PX: usize = 32;
/// Two sets per axis: their beat (96 px) is what the 32 px code orders;
/// the 32 px set wraps on every cell edge, as the capture's 100 px set does.
const PERIODS: [f64; 2] = [32.0, 48.0];
/// A block of camera pixels the projector does not light.
const SHADOW: (std::ops::Range<usize>, std::ops::Range<usize>) = (100..140, 10..40);

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// The projector point each camera pixel sees (a tilted plane).
fn truth(col: usize, row: usize) -> (f64, f64) {
    (20.0 + 3.6 * col as f64 + 0.2 * row as f64, 15.0 + 3.5 * row as f64 + 0.1 * col as f64)
}

fn in_shadow(col: usize, row: usize) -> bool {
    SHADOW.0.contains(&col) && SHADOW.1.contains(&row)
}

/// Writes the 32 frames of the tilted-plane scene.
fn write_capture(dir: &Path) -> PathBuf {
    write_scene(dir, &|c, r| (!in_shadow(c, r)).then(|| truth(c, r)))
}

/// Writes the 32 frames as `pat00.png`..`pat31.png` of a scene whose camera
/// pixel sees projector point `seen(col, row)` (`None`: unlit), with 1 DN
/// of deterministic noise, and returns the folder.
fn write_scene(dir: &Path, seen: &(dyn Fn(usize, usize) -> Option<(f64, f64)> + Sync)) -> PathBuf {
    let (w, h) = CAMERA;
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut noise = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut frames: Vec<Box<dyn Fn(f64, f64) -> f64>> = Vec::new();
    for axis in 0..2 {
        for period in PERIODS {
            for k in 0..3 {
                let shift = TAU / 3.0 * (k as f64 - 1.0);
                frames.push(Box::new(move |x, y| {
                    let p = if axis == 0 { x } else { y };
                    100.0 + 60.0 * (TAU * p / period + shift).cos()
                }));
            }
        }
    }
    for (axis, extent) in [(0usize, PROJECTOR.0), (1, PROJECTOR.1)] {
        let cells = extent.div_ceil(CELL_PX);
        let planes = bit_planes(cells);
        for plane in 0..planes {
            for inverse in [false, true] {
                frames.push(Box::new(move |x, y| {
                    let cell = ((if axis == 0 { x } else { y }) / CELL_PX as f64).floor() as u32;
                    if pattern_is_bright(cell, planes, plane) != inverse { 180.0 } else { 30.0 }
                }));
            }
        }
    }
    frames.push(Box::new(|_, _| 200.0));
    frames.push(Box::new(|_, _| 20.0));
    assert_eq!(frames.len(), 32);
    for (i, frame) in frames.iter().enumerate() {
        let mut pixels = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let v = seen(c, r).map_or(20.0, |(x, y)| frame(x, y));
                pixels.push((v + noise()).round().clamp(0.0, 255.0) as u8);
            }
        }
        let image = image::GrayImage::from_raw(w as u32, h as u32, pixels).expect("frame size");
        image.save(dir.join(format!("pat{i:02}.png"))).expect("write a frame");
    }
    dir.to_path_buf()
}

/// The README's import command for such a capture.
fn import(dir: &Path) -> PathBuf {
    import_with(dir, &[])
}

fn import_with(dir: &Path, more: &[&str]) -> PathBuf {
    let mut args = vec![
        "import",
        dir.to_str().expect("utf8 path"),
        "--pattern",
        "pat{index:02}.png",
        "--periods",
        "32,48,32,48",
        "--axes",
        "x,x,y,y",
        "--shifts",
        "3",
        "--shift-offset=-2.0943951023931953",
        "--projector",
        "640x480",
        "--gray-code",
        "32",
        "-q",
    ];
    args.extend(more);
    let o = sheen(&args);
    assert!(o.status.success(), "{}", text(&o));
    dir.join("fringe-set.json")
}

#[test]
fn a_camera_projector_capture_imports_checks_and_gives_absolute_projector_coordinates() {
    let tmp = tempfile::tempdir().unwrap();
    let manifest = import(&write_capture(tmp.path()));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    assert_eq!(json["rig"], "camera-projector");
    assert_eq!(json["projector"]["width"], 640);
    assert_eq!(json["sets"][2]["axis"], "y");
    assert_eq!(json["gray_code"]["columns"]["camera"].as_array().expect("a list").len(), 10);
    assert_eq!(json["gray_code"]["rows"]["camera"][0], "pat22.png");
    assert_eq!(json["gray_code"]["white"]["camera"], "pat30.png");

    let o = sheen(&["check", manifest.to_str().expect("utf8 path"), "-q"]);
    assert!(o.status.success(), "{}", text(&o));
    let lit = CAMERA.0 * CAMERA.1 - SHADOW.0.len() * SHADOW.1.len();
    for axis in ["x (columns)", "y (rows)"] {
        let line = format!("camera Gray code {axis}: ");
        assert!(text(&o).contains(&line), "{}", text(&o));
    }

    let maps = tmp.path().join("maps");
    let o = sheen(&["phase", manifest.to_str().expect("utf8 path"), "--maps", maps.to_str().expect("utf8 path")]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("wraps inside the field"), "the code makes the phase absolute: {}", text(&o));
    for (axis, which) in [("x", 0usize), ("y", 1)] {
        let map = read_f32_tiff(&maps.join(format!("camera_projector_{axis}.tif"))).unwrap();
        let sigma = read_f32_tiff(&maps.join(format!("camera_projector_{axis}_sigma.tif"))).unwrap();
        let cells = read_f32_tiff(&maps.join(format!("camera_gray_code_{axis}.tif"))).unwrap();
        assert_eq!((map.width, map.height), CAMERA);
        let (mut measured, mut sum_sq, mut worst, mut sigma_sum) = (0usize, 0.0f64, 0.0f64, 0.0f64);
        for r in 0..CAMERA.1 {
            for c in 0..CAMERA.0 {
                let i = r * CAMERA.0 + c;
                let v = map.data[i];
                if in_shadow(c, r) {
                    assert!(v.is_nan() && cells.data[i].is_nan(), "{axis}: shadow pixel ({c}, {r}) measured");
                    continue;
                }
                if v.is_nan() {
                    continue;
                }
                let t = if which == 0 { truth(c, r).0 } else { truth(c, r).1 };
                let e = f64::from(v) - t;
                measured += 1;
                sum_sq += e * e;
                worst = worst.max(e.abs());
                sigma_sum += f64::from(sigma.data[i]);
            }
        }
        let rms = (sum_sq / measured as f64).sqrt();
        let share = measured as f64 / lit as f64;
        eprintln!("{axis}: {:.2} % of lit, RMS {rms:.3} px, worst {worst:.3} px", 100.0 * share);
        // Only pixels on a cell edge, where a bit's frames cross and the
        // code is undecided, may go without a coordinate.
        assert!(share > 0.97, "{axis}: {:.2} % of the lit pixels", 100.0 * share);
        // 1 DN of noise on 60 DN of modulation: a few hundredths of a pixel.
        assert!(rms < 0.1 && worst < 0.5, "{axis}: RMS {rms} px, worst {worst} px");
        let mean_sigma = sigma_sum / measured as f64;
        assert!(mean_sigma > 0.3 * rms && mean_sigma < 3.0 * rms, "{axis}: σ {mean_sigma} for RMS {rms}");
    }
}

/// Rows and the sets along y are optional (issue 52, item 1): the same
/// capture with only its sets along x, its column code, white and black
/// imports with `--gray-code-columns-only`, and `sheen phase --maps` writes
/// the projector x, on the truth, and no projector y.
#[test]
fn a_capture_with_a_column_code_only_gives_the_projector_x() {
    let tmp = tempfile::tempdir().unwrap();
    let full = tmp.path().join("full");
    std::fs::create_dir(&full).unwrap();
    write_capture(&full);
    let columns_only = tmp.path().join("columns");
    std::fs::create_dir(&columns_only).unwrap();
    // The x sets (pat00-05), the column planes (pat12-21), white, black.
    let kept: Vec<usize> = (0..6).chain(12..22).chain([30, 31]).collect();
    for (to, from) in kept.iter().enumerate() {
        std::fs::copy(full.join(format!("pat{from:02}.png")), columns_only.join(format!("pat{to:02}.png"))).unwrap();
    }
    let o = sheen(&[
        "import",
        columns_only.to_str().expect("utf8 path"),
        "--pattern",
        "pat{index:02}.png",
        "--periods",
        "32,48",
        "--axes",
        "x,x",
        "--shifts",
        "3",
        "--shift-offset=-2.0943951023931953",
        "--projector",
        "640x480",
        "--gray-code",
        "32",
        "--gray-code-columns-only",
        "-q",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let manifest = columns_only.join("fringe-set.json");
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    assert!(json["gray_code"].get("rows").is_none_or(serde_json::Value::is_null), "{}", json["gray_code"]);
    assert_eq!(json["gray_code"]["white"]["camera"], "pat16.png");
    let maps = tmp.path().join("maps");
    let o = sheen(&["phase", manifest.to_str().expect("utf8 path"), "--maps", maps.to_str().expect("utf8 path")]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(!maps.join("camera_projector_y.tif").exists(), "a projector y without rows");
    let map = read_f32_tiff(&maps.join("camera_projector_x.tif")).unwrap();
    let lit = CAMERA.0 * CAMERA.1 - SHADOW.0.len() * SHADOW.1.len();
    let mut measured = 0usize;
    for (i, v) in map.data.iter().enumerate().filter(|(_, v)| !v.is_nan()) {
        let (c, r) = (i % CAMERA.0, i / CAMERA.0);
        assert!(!in_shadow(c, r), "shadow pixel ({c}, {r}) measured");
        assert!((f64::from(*v) - truth(c, r).0).abs() < 0.5, "({c}, {r}): {v} for {}", truth(c, r).0);
        measured += 1;
    }
    assert!(measured as f64 > 0.97 * lit as f64, "{measured} of {lit}");
}

#[test]
fn gray_frames_out_of_order_or_missing_are_one_line_naming_the_files() {
    let tmp = tempfile::tempdir().unwrap();
    let manifest = import(&write_capture(tmp.path()));
    let original: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();

    // Plane 1's inverse listed before its pattern.
    let mut swapped = original.clone();
    let columns = swapped["gray_code"]["columns"]["camera"].as_array_mut().expect("a list");
    columns.swap(2, 3);
    std::fs::write(&manifest, serde_json::to_vec(&swapped).unwrap()).unwrap();
    for command in ["check", "phase"] {
        let maps = tmp.path().join("maps");
        let mut args = vec![command, manifest.to_str().expect("utf8 path")];
        if command == "phase" {
            args.extend(["--maps", maps.to_str().expect("utf8 path")]);
        }
        let o = sheen(&args);
        let out = text(&o);
        assert!(!o.status.success(), "{command}: {out}");
        assert!(
            out.contains("pat15.png (listed as the pattern) and pat14.png (as the inverse) look swapped"),
            "{command}: {out}"
        );
        assert!(!maps.join("camera_projector_x.tif").exists(), "{command}");
    }

    // A frame left out.
    let mut short = original.clone();
    short["gray_code"]["rows"]["camera"].as_array_mut().expect("a list").pop();
    std::fs::write(&manifest, serde_json::to_vec(&short).unwrap()).unwrap();
    let o = sheen(&["check", manifest.to_str().expect("utf8 path")]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("gray_code.rows camera 'camera' lists 7 frames, but a code of 15 cells of 32 px"),
        "{}",
        text(&o)
    );

    // White and black the other way round.
    let mut dark = original.clone();
    dark["gray_code"]["white"]["camera"] = "pat31.png".into();
    dark["gray_code"]["black"]["camera"] = "pat30.png".into();
    std::fs::write(&manifest, serde_json::to_vec(&dark).unwrap()).unwrap();
    let o = sheen(&["check", manifest.to_str().expect("utf8 path")]);
    assert!(!o.status.success());
    assert!(text(&o).contains("the white frame pat31.png is darker than the black frame pat30.png"), "{}", text(&o));

    // A set along y with its images in reverse order: `sheen check` checks
    // the sets along y too.
    let mut reversed = original.clone();
    reversed["sets"][3]["images"]["camera"].as_array_mut().expect("a list").reverse();
    std::fs::write(&manifest, serde_json::to_vec(&reversed).unwrap()).unwrap();
    let o = sheen(&["check", manifest.to_str().expect("utf8 path")]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    let row = text(&o).lines().find(|l| l.starts_with("camera       3")).map(str::to_string);
    assert!(row.as_deref().is_some_and(|r| !r.ends_with(" ok")), "{}", text(&o));
    let row2 = text(&o).lines().find(|l| l.starts_with("camera       2")).map(str::to_string);
    assert!(row2.as_deref().is_some_and(|r| r.ends_with(" ok")), "{}", text(&o));

    // Sets along y without a projector.
    let mut no_rig = original.clone();
    let object = no_rig.as_object_mut().expect("an object");
    object.remove("rig");
    object.remove("projector");
    object.remove("gray_code");
    std::fs::write(&manifest, serde_json::to_vec(&no_rig).unwrap()).unwrap();
    let o = sheen(&["check", manifest.to_str().expect("utf8 path")]);
    assert!(!o.status.success());
    assert!(text(&o).contains("runs along projector y, which only a camera–projector rig has"), "{}", text(&o));
}

/// The 3D of a camera–projector rig (issue 52, items 4 and 5), from the
/// files to the cloud: `sheen simulate --rig camera-projector` writes a
/// sphere seen by a pinhole camera 20° beside a pinhole projector (its
/// frames, manifest, calibration and truth), and `sheen reconstruct` puts
/// every lit pixel's point on the rendered surface to a few micrometres,
/// with a σ_z that says how well.
#[test]
fn a_simulated_camera_projector_rig_reconstructs_from_its_files_to_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sphere");
    let d = dir.to_str().expect("utf8 path");
    let o = sheen(&[
        "simulate",
        "--rig",
        "camera-projector",
        "--scene",
        "sphere",
        "--width",
        "320",
        "--height",
        "240",
        "--out",
        d,
        "-q",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let manifest = dir.join("fringe-set.json");
    let m = manifest.to_str().expect("utf8 path");
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    assert_eq!(json["rig"], "camera-projector");
    assert_eq!(json["gray_code"]["layout"], "opencv");
    let o = sheen(&["check", m, "-q"]);
    assert!(o.status.success(), "{}", text(&o));
    let cloud_path = tmp.path().join("cloud.ply");
    let cloud_arg = cloud_path.to_str().expect("utf8 path");
    let o = sheen(&["reconstruct", m, "--out", cloud_arg]);
    assert!(o.status.success(), "{}", text(&o));
    let cloud = sheen::io::ply::read_ply(&cloud_path).unwrap();
    let (u, v) = (cloud.scalar("u").expect("u"), cloud.scalar("v").expect("v"));
    let sigma = cloud.scalar("scalar_sigma_z_um").expect("sigma_z");
    let truth_z = read_f32_tiff(&dir.join("truth/camera_point_z_mm.tif")).unwrap();
    let lit = read_f32_tiff(&dir.join("truth/camera_projector_x_px.tif")).unwrap();
    let lit_count = lit.data.iter().filter(|x| !x.is_nan()).count();
    let (mut sum_sq, mut worst, mut sigma_sum) = (0.0f64, 0.0f64, 0.0f64);
    for (i, p) in cloud.xyz.iter().enumerate() {
        let pixel = v[i] as usize * 320 + u[i] as usize;
        assert!(!lit.data[pixel].is_nan(), "a point at the unlit pixel ({}, {})", u[i], v[i]);
        let e = p[2] - f64::from(truth_z.data[pixel]);
        sum_sq += e * e;
        worst = worst.max(e.abs());
        sigma_sum += sigma[i] / 1000.0;
    }
    let n = cloud.xyz.len();
    let (rms, mean_sigma) = ((sum_sq / n as f64).sqrt(), sigma_sum / n as f64);
    eprintln!(
        "{n} points of {lit_count} lit pixels; depth RMS {rms:.4} mm, worst {worst:.4} mm, mean σ_z {mean_sigma:.4} mm"
    );
    assert!(n as f64 > 0.98 * lit_count as f64, "{n} of {lit_count}");
    assert!(rms < 0.02 && worst < 0.1, "RMS {rms} mm, worst {worst} mm");
    assert!(mean_sigma > 0.3 * rms && mean_sigma < 3.0 * rms, "σ_z {mean_sigma} for RMS {rms}");

    // A stereo calibration where a camera–projector one belongs is refused.
    let calibration_path = dir.join("calibration.json");
    std::fs::write(&calibration_path, serde_json::json!({"model": "affine", "unit": "mm", "cameras": {}}).to_string())
        .unwrap();
    let o = sheen(&["reconstruct", m, "--out", cloud_arg]);
    assert!(!o.status.success());
    assert!(text(&o).contains("calibration.json: is a telecentric stereo (affine) calibration"), "{}", text(&o));
}

/// A polygon of the height map's frame.
type Polygon = Vec<[f64; 2]>;

/// A block of the step gauge: its reference strips, its top, its height (µm).
type Block = ([Polygon; 2], Polygon, f64);

/// The simulated step gauge through this rig (noise seed `seed`) written
/// as a PNG fringe set in `dir`, and its regions as polygons of the height
/// map's frame: world rectangles through the rig's true camera pose (the
/// cloud is seen from the camera: x right, y up the image, z towards the
/// camera). Returns the manifest, the base, and per block its reference
/// strips on both sides (the scene's landmark and its mirror, as ISO
/// 5436-1 places them), its top and its height (µm).
///
/// Both sides, not the landmark's one strip: the fringes leave an error
/// of about half a micrometre that is the same all along a fringe (8-bit
/// sampling of each fringe, under the noise), which tilts a plane fitted
/// to a strip 1.1 mm wide by about 0.05° and, carried 2.4 mm to the block's
/// centre, moves a step by 2-3 µm; two strips around the block leave 0.4 µm.
fn simulated_gauge(dir: &Path, seed: u64) -> (PathBuf, Polygon, Vec<Block>) {
    use sheen::engine::control::RunControl;
    use sheen::sim::camera_projector::{PinholeRigConfig, simulate_camera_projector};
    use sheen::sim::{Landmark, SceneKind};

    let config = PinholeRigConfig { seed, ..PinholeRigConfig::new(SceneKind::StepGauge) };
    let sim = simulate_camera_projector(&config, &RunControl::new()).expect("renders");
    let manifest =
        sheen::io::dataset::write_measurement_as(dir, &sim.measurement, sheen::io::dataset::ImageFileFormat::Png)
            .expect("writes");
    let pose = sim.truth.camera_from_world;
    let polygon = |r: &sheen::sim::scene_model::Region, z: f64| -> Polygon {
        [[r.x_min_mm, r.y_min_mm], [r.x_max_mm, r.y_min_mm], [r.x_max_mm, r.y_max_mm], [r.x_min_mm, r.y_max_mm]]
            .iter()
            .map(|&[x, y]| {
                let c = pose.apply([x, y, z]);
                [c[0], -c[1]]
            })
            .collect()
    };
    let (mut base, mut steps) = (Vec::new(), Vec::new());
    for landmark in &sheen::sim::scenes::build(SceneKind::StepGauge).landmarks {
        match landmark {
            Landmark::Land { name, region, height_mm } if name == "base" => base = polygon(region, *height_mm),
            Landmark::Step { reference, measured, height_mm, .. } => {
                let centre_x = 0.5 * (measured.x_min_mm + measured.x_max_mm);
                let mirror = sheen::sim::scene_model::Region {
                    x_min_mm: 2.0 * centre_x - reference.x_max_mm,
                    x_max_mm: 2.0 * centre_x - reference.x_min_mm,
                    ..*reference
                };
                let references = [polygon(reference, 0.0), polygon(&mirror, 0.0)];
                steps.push((references, polygon(measured, *height_mm), height_mm * 1e3));
            }
            _ => {}
        }
    }
    assert!(!base.is_empty() && steps.len() == 4, "the step gauge's landmarks");
    (manifest, base, steps)
}

/// `sheen analyze` on a camera–projector capture (issue 52, item 4): the
/// simulated step gauge, its regions placed from the scene's landmarks
/// through the rig's true camera pose, levelled on the base; every step
/// height within 1 µm of the gauge's, the part recorded.
#[test]
fn analyze_measures_a_camera_projector_step_gauge() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (manifest, base, steps) = simulated_gauge(&dir.path().join("gauge"), 1);
    let option = |p: &Polygon| -> String {
        let points: Vec<String> = p.iter().map(|[x, y]| format!("{x:.4},{y:.4}")).collect();
        format!("polygon:{}", points.join(","))
    };
    let mut args: Vec<String> = vec![
        "analyze".into(),
        manifest.to_string_lossy().into_owned(),
        "--out".into(),
        dir.path().join("qc").to_string_lossy().into_owned(),
        "-q".into(),
        "--region".into(),
        format!("base={}", option(&base)),
        "--level".into(),
        "base".into(),
    ];
    for (k, ([left, right], measured, height_um)) in steps.iter().enumerate() {
        args.extend([
            "--region".into(),
            format!("r{k}a={}", option(left)),
            "--region".into(),
            format!("r{k}b={}", option(right)),
            "--region".into(),
            format!("m{k}={}", option(measured)),
            "--step".into(),
            format!("s{k}=r{k}a,r{k}b:m{k}={height_um}±3"),
        ]);
    }
    // Kept in the records as a part of its recipe, as the line keeps it.
    let db = dir.path().join("records.sqlite").to_string_lossy().into_owned();
    args.extend(["--record", "--db", &db, "--recipe", "gauge-cp", "--part", "g1"].map(String::from));
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = sheen(&refs);
    assert!(o.status.success(), "{}", text(&o));
    let o = sheen(&["history", "--db", &db]);
    let history = text(&o);
    assert!(o.status.success() && history.contains("gauge-cp") && history.contains("pass"), "{history}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("qc/measurements.json")).expect("report")).expect("json");
    assert!(
        report["levelling"]["tilt_deg"].as_f64().is_some_and(|t| (t - 20.0).abs() < 0.05),
        "{}",
        report["levelling"]
    );
    let rows = report["measurements"].as_array().expect("measurements");
    assert_eq!(rows.len(), steps.len());
    for (row, (.., true_um)) in rows.iter().zip(&steps) {
        let value = row["value"].as_f64().expect("a value");
        println!(
            "camera–projector step gauge: {} = {value:.2} um (true {true_um} um, U {:.2} um)",
            row["name"], row["uncertainty"]["U"]
        );
        assert!((value - true_um).abs() < 1.0, "{}: {value} um, true {true_um} um", row["name"]);
    }
}

/// The line on a camera–projector rig (issue 52, item 4): a recipe made
/// from a reference step gauge through this rig, then `sheen watch` over an
/// inbox of two more captures of it and one missing a Gray code frame: the
/// two measured and recorded as passing with every step within 1 µm, the
/// third recorded as an error naming the missing file.
#[test]
fn the_line_measures_camera_projector_parts_and_records_a_broken_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (reference, base, steps) = simulated_gauge(&dir.path().join("reference"), 1);
    let region =
        |name: String, p: &Polygon| serde_json::json!({"name": name, "region": {"shape": "polygon", "vertices_mm": p}});
    let mut regions = vec![region("base".into(), &base)];
    let mut measurements = Vec::new();
    for (k, ([left, right], m, height_um)) in steps.iter().enumerate() {
        regions.push(region(format!("r{k}a"), left));
        regions.push(region(format!("r{k}b"), right));
        regions.push(region(format!("m{k}"), m));
        measurements.push(serde_json::json!({
            "name": format!("step {k}"),
            "measure": {"kind": "step_height", "reference": [format!("r{k}a"), format!("r{k}b")], "measured": [format!("m{k}")]},
            "nominal": height_um, "tolerance": {"lower": -3, "upper": 3}}));
    }
    let spec = serde_json::json!({"sheen_inspection": 1, "level_to": ["base"], "regions": regions, "measurements": measurements});
    let spec_path = dir.path().join("spec.json");
    std::fs::write(&spec_path, spec.to_string()).expect("spec");
    let recipe = dir.path().join("gauge.sheen-recipe.json");
    let p = |x: &Path| x.to_str().expect("utf8").to_string();
    let o = sheen(&["recipe", &p(&reference), "--spec", &p(&spec_path), "--out", &p(&recipe), "-q"]);
    assert!(o.status.success(), "recipe: {}", text(&o));

    let inbox = dir.path().join("inbox");
    for (name, seed) in [("part-a", 2), ("part-b", 3), ("part-c", 4)] {
        simulated_gauge(&inbox.join(name), seed);
    }
    // part-c lost its first Gray code frame.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(inbox.join("part-c/fringe-set.json")).expect("read"))
            .expect("json");
    let gray =
        manifest["gray_code"]["columns"].as_object().expect("columns per camera").values().next().expect("a camera");
    let lost = gray[0].as_str().expect("a file").to_string();
    std::fs::remove_file(inbox.join("part-c").join(&lost)).expect("remove a Gray code frame");

    let db = dir.path().join("records.sqlite");
    let o = sheen(&[
        "watch",
        &p(&inbox),
        "--recipe",
        &p(&recipe),
        "--db",
        &p(&db),
        "--out",
        &p(&dir.path().join("results")),
        "--json",
        "--settle-ms",
        "100",
        "--poll-ms",
        "20",
        "--once",
    ]);
    assert!(o.status.success(), "watch: {}", text(&o));
    let parts: Vec<serde_json::Value> =
        String::from_utf8_lossy(&o.stdout).lines().map(|l| serde_json::from_str(l).expect("json")).collect();
    assert_eq!(parts.len(), 3, "{}", text(&o));
    for v in &parts {
        let part = v["part"].as_str().expect("part");
        assert_eq!(v["recorded"].as_bool(), Some(true), "{part}: {v}");
        if part == "part-c" {
            assert_eq!(v["verdict"].as_str(), Some("error"), "{v}");
            let file = Path::new(&lost).file_name().expect("a name").to_string_lossy().into_owned();
            assert!(v["reason"].as_str().is_some_and(|r| r.contains(&file)), "{v}");
            continue;
        }
        assert_eq!(v["verdict"].as_str(), Some("pass"), "{part}: {v}");
        assert!(dir.path().join("results").join(part).join("measurements.json").is_file(), "{part}'s results");
        // The recipe placed the part (the alignment rows) before measuring it.
        let rows: Vec<&serde_json::Value> =
            v["measurements"].as_array().expect("measurements").iter().filter(|r| r["kind"] == "step_height").collect();
        assert_eq!(rows.len(), steps.len(), "{v}");
        for (row, (.., true_um)) in rows.iter().zip(&steps) {
            let value = row["value"].as_f64().expect("a value");
            println!("line, camera–projector {part}: {} = {value:.2} um (true {true_um} um)", row["name"]);
            assert!((value - true_um).abs() < 1.0, "{part} {}: {value} um, true {true_um} um", row["name"]);
        }
    }
    let location = sheen::records::DbLocation::Sqlite(db);
    let mut store = sheen::records::Store::open(&location).expect("open the records");
    let recorded = store.parts(&sheen::records::query::HistoryFilter::default()).expect("read the records");
    let verdicts: Vec<(&str, sheen::records::PartVerdict)> =
        recorded.iter().map(|p| (p.record.part_id.as_str(), p.record.verdict)).collect();
    use sheen::records::PartVerdict::{Error, Pass};
    assert_eq!(verdicts, [("part-a", Pass), ("part-b", Pass), ("part-c", Error)]);
}
