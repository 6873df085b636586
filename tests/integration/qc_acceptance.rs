//! Issue 7's acceptance: `sheen analyze` on simulated artefacts with known
//! truth, through files and the binary as a production line runs it, plus
//! the X3P contract and the command's errors and exit codes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use sheen::analysis::height_map::{HeightMap, RasterParams, height_map_from_cloud};
use sheen::analysis::inspection::{Measure, MeasurementSpec};
use sheen::analysis::measurement_table::Tolerance;
use sheen::analysis::region::{NamedRegion, Region};
use sheen::analysis::session::Session;
use sheen::engine::control::RunControl;
use sheen::engine::pipeline::{Method, Params, run};
use sheen::engine::point_cloud::PointCloud;
use sheen::io::ply::{PlyWriteOptions, write_ply};
use sheen::io::x3p::{X3pMetadata, read_x3p};
use sheen::sim::{Landmark, SceneKind, SimConfig, Simulation, simulate};

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn sim(scene: SceneKind, w: usize, h: usize, bits: u32, noise_dn: f64) -> Simulation {
    let mut c = SimConfig::new(scene, w, h);
    c.bits = bits;
    c.noise_sigma_dn = noise_dn;
    simulate(&c, &RunControl::new()).expect("simulate")
}

/// The simulation as a fringe set on disk; returns the manifest path.
fn write_set(sim: &Simulation, dir: &Path) -> PathBuf {
    sheen::io::dataset::write_measurement(&dir.join("set"), &sim.measurement).expect("write the fringe set")
}

/// The engine's cloud of a simulation, written as Sheen's PLY.
fn write_cloud(sim: &Simulation, path: &Path) -> PointCloud {
    let rec = run(&sim.measurement, &Params { method: Method::Hdr, ..Params::default() }, None, &RunControl::new())
        .expect("reconstruct");
    let cloud = rec.stereo.expect("stereo ran").cloud;
    write_ply(path, &cloud, &PlyWriteOptions::default()).expect("write the PLY");
    cloud
}

fn measurements(dir: &Path) -> serde_json::Value {
    let text = std::fs::read(dir.join("measurements.json")).expect("measurements.json");
    serde_json::from_slice(&text).expect("measurements.json is JSON")
}

fn row<'a>(json: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    json["measurements"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["name"] == name)
        .unwrap_or_else(|| panic!("no row '{name}' in {json}"))
}

fn value(json: &serde_json::Value, name: &str) -> f64 {
    row(json, name)["value"].as_f64().unwrap_or_else(|| panic!("'{name}' has no value: {}", row(json, name)))
}

fn rect_arg(name: &str, r: &sheen::sim::scene_model::Region) -> String {
    format!("{name}=rect:{},{},{},{}", r.x_min_mm, r.y_min_mm, r.x_max_mm, r.y_max_mm)
}

#[test]
fn a_tilted_flat_levels_to_under_a_tenth_of_a_micrometre_through_the_whole_pipeline() {
    // Noise-free 16-bit images of the lapped flat (tilted 1.5 and -1 mrad),
    // simulated -> fringe set on disk -> engine -> height map -> levelling.
    let dir = tempfile::tempdir().expect("tempdir");
    let flat = sim(SceneKind::Flat, 512, 384, 16, 0.0);
    let manifest = write_set(&flat, dir.path());
    let out = dir.path().join("qc");
    let o = sheen(&[
        "analyze",
        s(&manifest),
        "--out",
        s(&out),
        "--region",
        "flat=rect:-9,-6,9,6",
        "--level",
        "flat",
        "--flatness-rms",
        "flat<=0.1",
        "--flatness",
        "flat",
        "-q",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let json = measurements(&out);
    let rms = value(&json, "flatness rms flat");
    let pv = value(&json, "flatness flat");
    eprintln!("flat: residual RMS {rms:.4} um, PV {pv:.4} um");
    // Noise-free 16-bit data of a plane leave only the quantisation of the
    // fringes and rounding: about 0.001 um RMS and 0.013 um PV here.
    assert!(rms < 0.1, "levelled residual RMS {rms} um");
    assert_eq!(row(&json, "flatness rms flat")["verdict"], "pass");
    // The levelling plane is the scene's tilt.
    let lev = &json["levelling"];
    let (sx, sy) = (lev["slope_x"].as_f64().expect("slope"), lev["slope_y"].as_f64().expect("slope"));
    assert!((sx - 0.0015).abs() < 2e-6 && (sy + 0.001).abs() < 2e-6, "slopes {sx} {sy}");
    // The levelled map (float32 micrometres) lies on zero: its median height
    // is far below the 0.1 um bound, where the map as measured spans ~40 um.
    let lev_map = sheen::io::maps::read_f32_tiff(&out.join("height_map_levelled.tif")).expect("levelled TIFF");
    let mut z: Vec<f32> = lev_map.data.iter().copied().filter(|z| z.is_finite()).collect();
    z.sort_by(f32::total_cmp);
    assert!(z.len() > 100_000 && z[z.len() / 2].abs() < 0.05, "{} nodes, median {}", z.len(), z[z.len() / 2]);
    for f in ["height_map.x3p", "height_map.png", "height_map_levelled.x3p", "measurements.csv", "inspection.json"] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
}

#[test]
fn step_gauge_heights_are_recovered_to_half_a_micrometre_inline_and_from_a_session() {
    let dir = tempfile::tempdir().expect("tempdir");
    // 12-bit images with 2 DN of read noise, an industrial camera: the steps
    // come out within 0.06 um. (Noise-free 8-bit images are not enough for
    // 0.5 um: their quantisation error follows the phase, so it does not
    // average out over a region and leaves up to ~1 um; 1 DN of noise
    // dithers it to ~0.4 um.)
    let gauge = sim(SceneKind::StepGauge, 512, 384, 12, 2.0);
    let manifest = write_set(&gauge, dir.path());
    // Regions and truth from the scene's landmarks: the base beside each
    // block (clear of the wall and its occlusion) and the block's top.
    let mut args: Vec<String> = Vec::new();
    let mut truth = Vec::new();
    for (i, lm) in gauge.truth.scene.landmarks.iter().enumerate() {
        if let Landmark::Step { reference, measured, height_mm, .. } = lm {
            args.extend(["--region".into(), rect_arg(&format!("base {i}"), reference)]);
            args.extend(["--region".into(), rect_arg(&format!("block {i}"), measured)]);
            let nominal = height_mm * 1e3;
            args.extend(["--step".into(), format!("step {i}=base {i}:block {i}={nominal}±0.5")]);
            truth.push((format!("step {i}"), nominal));
        }
    }
    assert_eq!(truth.len(), 4);
    let out = dir.path().join("inline");
    let mut cmd = vec!["analyze".to_string(), s(&manifest).into(), "--out".into(), s(&out).into(), "-q".into()];
    cmd.extend(args);
    let o = sheen(&cmd.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let json = measurements(&out);
    assert_eq!(json["overall_verdict"], "pass");
    for (name, nominal) in &truth {
        let v = value(&json, name);
        eprintln!("{name}: {v:.4} um (true {nominal} um)");
        assert!((v - nominal).abs() < 0.5, "{name}: {v} um, true {nominal} um");
    }

    // The same inspection as an app session (manifest relative to the
    // session file, engine parameters, regions, tolerances) reruns identically.
    let spec: sheen::analysis::inspection::InspectionSpec =
        serde_json::from_slice(&std::fs::read(out.join("inspection.json")).expect("inspection.json"))
            .expect("the written inspection reads back");
    let mut session = Session::new("set/fringe-set.json", Params::default());
    assert!(manifest.ends_with("set/fringe-set.json"), "{}", manifest.display());
    session.inspection = spec;
    let session_path = dir.path().join("gauge.sheen-session.json");
    std::fs::write(&session_path, session.to_json()).expect("write the session");
    let out2 = dir.path().join("from-session");
    let o = sheen(&["analyze", "--session", s(&session_path), "--out", s(&out2), "-q"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let again = measurements(&out2);
    for (name, _) in &truth {
        assert_eq!(value(&again, name), value(&json, name), "{name} differs between inline and session runs");
    }
}

#[test]
fn a_section_across_the_gasket_indentation_matches_the_true_section() {
    let dir = tempfile::tempdir().expect("tempdir");
    let gaskets = sim(SceneKind::Gaskets, 512, 384, 8, 0.0);
    let ply = dir.path().join("gaskets.ply");
    write_cloud(&gaskets, &ply);
    let out = dir.path().join("qc");
    // Radially across the ring dent of the loaded gasket (centre (0, -4.3)
    // mm, radius 2.2 mm, 25 um deep, Gaussian sigma 0.18 mm), averaged over
    // 0.2 mm along the ring, where its depth changes by under 0.1 um: the
    // average bridges the narrow holes that over-saturated streaks of the
    // brushed steel leave (the engine refuses those pixels).
    let o = sheen(&[
        "analyze",
        s(&ply),
        "--out",
        s(&out),
        "--profile",
        "dent=-3.4,-4.3,-1.0,-4.3@0.2",
        "--profile-step",
        "0.01",
        "-q",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(out.join("profile_dent.csv")).expect("profile CSV");
    assert!(text.contains("# start_mm: -3.400000, -4.300000") && text.contains("# interpolation: bilinear"));
    assert!(text.contains("# averaging_width_mm: 0.200000 (7 parallel lines)"), "{text}");
    // The true section, averaged over the same 7 parallel lines.
    let scene = &gaskets.truth.scene;
    let truth_um = |x: f64, y: f64| -> f64 {
        (0..7).map(|j| scene.height_mm(x, y + (j as f64 - 3.0) / 3.0 * 0.1)).sum::<f64>() / 7.0 * 1e3
    };
    let (mut all, mut full, mut stations) = (Vec::new(), Vec::new(), 0);
    let (mut deepest, mut deepest_x, mut true_deepest) = (f64::INFINITY, f64::NAN, f64::INFINITY);
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        stations += 1;
        let (x, y): (f64, f64) = (f[1].parse().expect("x"), f[2].parse().expect("y"));
        let t = truth_um(x, y);
        true_deepest = true_deepest.min(t);
        if f[3].is_empty() {
            continue;
        }
        let z: f64 = f[3].parse().expect("z");
        all.push(z - t);
        if f[4] == "7" {
            full.push(z - t);
        }
        if z < deepest {
            (deepest, deepest_x) = (z, x);
        }
    }
    let rms = |e: &[f64]| (e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt();
    let max = |e: &[f64]| e.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    eprintln!(
        "gasket section: {} of {stations} stations with data ({} fully), error rms {:.3} um (full {:.3}), max {:.3} \
         um (full {:.3}), deepest {deepest:.3} um at x {deepest_x:.3}, true {true_deepest:.3} um",
        all.len(),
        full.len(),
        rms(&all),
        rms(&full),
        max(&all),
        max(&full)
    );
    assert!(all.len() as f64 > 0.9 * stations as f64, "only {} of {stations} stations have data", all.len());
    assert!(full.len() as f64 > 0.6 * stations as f64, "only {} stations fully averaged", full.len());
    // Where all 7 lines have data the section follows the truth to the
    // resampling error of the dent's curvature (25 um / (0.18 mm)^2: about
    // 0.2 um per linear-interpolation stage at the 47 um pitch, two stages:
    // stereo resampling and the height map), so 0.75 um at the dent's bottom.
    assert!(rms(&full) < 0.3 && max(&full) < 0.75, "fully averaged stations: rms {} max {}", rms(&full), max(&full));
    // Stations next to a refused streak average fewer, noisier points at its
    // edge (up to ~3 um off); they stay rare enough for 1 um RMS overall.
    assert!(rms(&all) < 1.0, "section error rms {} um", rms(&all));
    // The dent: its deepest point on the ring within a pitch, its depth to 0.75 um.
    assert!((deepest_x + 2.2).abs() < 0.05, "deepest at x = {deepest_x}");
    assert!((deepest - true_deepest).abs() < 0.75, "deepest {deepest} um, true {true_deepest} um");
}

/// A synthetic organized cloud: a plate z = 0.1 + 0.001 x with a 20 um boss
/// of radius 0.25 mm at (1.0, 0.6), on an 80 x 60 grid of 0.02 mm.
fn plate_cloud() -> PointCloud {
    let (w, h, pitch) = (80usize, 60usize, 0.02);
    let mut cloud = PointCloud {
        unit: sheen::engine::length_unit::LengthUnit::Mm,
        grid_width: w,
        grid_height: h,
        ..PointCloud::default()
    };
    for r in 0..h {
        for c in 0..w {
            let (x, y) = (c as f64 * pitch, r as f64 * pitch);
            let boss = if (x - 1.0).hypot(y - 0.6) < 0.25 { 0.020 } else { 0.0 };
            cloud.xyz.push([x, y, 0.1 + 0.001 * x + boss]);
            cloud.pixel_uv.push([c as f32, r as f32]);
            cloud.source_set.push(3);
            cloud.source_period_px.push(12.0);
            cloud.modulation_dn.push(100.0);
            cloud.sigma_z.push(0.0001);
            cloud.intensity_dn.push(128.0);
        }
    }
    cloud
}

fn plate_ply(dir: &Path) -> PathBuf {
    let path = dir.join("plate.ply");
    write_ply(&path, &plate_cloud(), &PlyWriteOptions::default()).expect("write the plate");
    path
}

const PLATE_REGIONS: [&str; 4] = ["--region", "base=rect:0.05,0.05,0.6,1.1", "--region", "boss=circle:1.0,0.6,0.2"];

#[test]
fn x3p_written_by_analyze_reads_back_identically_with_the_standard_structure() {
    use std::io::Read;
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = plate_ply(dir.path());
    let out = dir.path().join("qc");
    let mut args = vec!["analyze", s(&ply), "--out", s(&out), "-q", "--pitch-mm", "0.02"];
    args.extend(PLATE_REGIONS);
    let o = sheen(&args);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // Data: the map the library makes of the same cloud, bit for bit.
    let expected = height_map_from_cloud(&plate_cloud(), &RasterParams { pitch_mm: Some(0.02), ..Default::default() })
        .expect("rasterize")
        .map;
    let path = out.join("height_map.x3p");
    let back = read_x3p(std::fs::File::open(&path).expect("open")).expect("read the X3P back");
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    assert_same_map(&back.map, &expected);
    assert_eq!(back.metadata.manufacturer, "Sheen");
    assert!(back.metadata.comment.as_deref().unwrap_or("").contains("plate.ply"), "{:?}", back.metadata.comment);
    // The TIFF holds the same map in micrometres, north up like the app's
    // exports: its first row is the map's last (largest Y).
    let tif = sheen::io::maps::read_f32_tiff(&out.join("height_map.tif")).expect("TIFF");
    assert_eq!((tif.width, tif.height), (expected.width, expected.height));
    for r in [0, expected.height / 2, expected.height - 1] {
        let tif_row = &tif.data[r * expected.width..(r + 1) * expected.width];
        let map_row = &expected.z[(expected.height - 1 - r) * expected.width..(expected.height - r) * expected.width];
        for (t, z) in tif_row.iter().zip(map_row) {
            let z_um = (f64::from(*z) * 1e3) as f32;
            assert!(t.to_bits() == z_um.to_bits() || (t.is_nan() && z.is_nan()), "row {r}: {t} vs {z_um}");
        }
    }

    // Structure, as Gwyddion and the openGPS tools expect it.
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&path).expect("open")).expect("a zip archive");
    let mut entry = |name: &str| {
        let mut v = Vec::new();
        zip.by_name(name).unwrap_or_else(|_| panic!("no {name}")).read_to_end(&mut v).expect("read entry");
        v
    };
    let xml = String::from_utf8(entry("main.xml")).expect("utf-8");
    let data = entry("bindata/data.bin");
    let checksum = String::from_utf8(entry("md5checksum.hex")).expect("utf-8");
    let md5 = |b: &[u8]| -> String {
        use md5::Digest;
        md5::Md5::digest(b).iter().map(|x| format!("{x:02x}")).collect()
    };
    assert!(xml.contains(r#"<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2""#), "{xml}");
    let mut at = 0;
    for tag in ["<Record1>", "<FeatureType>SUR</FeatureType>", "<Record2>", "<Record3>", "<Record4>"] {
        at += xml[at..].find(tag).unwrap_or_else(|| panic!("{tag} missing or out of order"));
    }
    assert!(xml.contains("<PointDataLink>bindata/data.bin</PointDataLink>"));
    assert!(xml.contains(&format!("<MD5ChecksumPointData>{}</MD5ChecksumPointData>", md5(&data))));
    assert!(xml.contains(&format!("<SizeX>{}</SizeX>", expected.width)));
    assert!(xml.contains("<ChecksumFile>md5checksum.hex</ChecksumFile>"));
    assert_eq!(checksum, format!("{} *main.xml\n", md5(xml.as_bytes())));
    assert_eq!(data.len(), expected.z.len() * 8, "float64 metres, one per node");

    // Metadata: everything written comes back (the library path with a full record).
    let meta = X3pMetadata {
        creator: Some("line 3".into()),
        calibration_date: Some("2026-01-02T03:04:05Z".into()),
        comment: Some("lot 42".into()),
        ..X3pMetadata::sheen("2026-11-23T10:00:00Z")
    };
    let path2 = dir.path().join("again.x3p");
    sheen::cli::analyze::write_height_map_x3p(&path2, &expected, &meta).expect("write");
    let back = read_x3p(std::fs::File::open(&path2).expect("open")).expect("read");
    assert_eq!(back.metadata, meta);
    assert_same_map(&back.map, &expected);
}

fn assert_same_map(a: &HeightMap, b: &HeightMap) {
    assert_eq!((a.width, a.height, a.unit.as_str()), (b.width, b.height, b.unit.as_str()));
    assert!(a.z.iter().zip(&b.z).all(|(x, y)| x.to_bits() == y.to_bits()), "heights differ");
    let close = |x: f64, y: f64| (x - y).abs() <= 4.0 * f64::EPSILON * x.abs().max(y.abs()).max(1e-3);
    assert!(
        close(a.pitch_mm, b.pitch_mm) && close(a.origin_x_mm, b.origin_x_mm) && close(a.origin_y_mm, b.origin_y_mm)
    );
}

#[test]
fn plate_measurements_pass_or_exit_2_with_the_table_and_profiles() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = plate_ply(dir.path());
    let run = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec!["analyze", s(&ply), "--out", s(&out)];
        args.extend(PLATE_REGIONS);
        args.extend(extra);
        (sheen(&args), out)
    };
    let (o, out) = run(
        "pass",
        &["--level", "base", "--step", "boss=base:boss=20±0.1", "--hsection", "A=0.6@0.04", "--vsection", "1.0"],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("boss") && stdout.contains("pass") && stdout.contains("overall: PASS"), "{stdout}");
    let json = measurements(&out);
    assert!((value(&json, "boss") - 20.0).abs() < 1e-3);
    assert_eq!(json["units"]["heights"], "um");
    let csv = std::fs::read_to_string(out.join("measurements.csv")).expect("csv");
    assert!(csv.contains("# overall verdict: pass") && csv.contains("boss,step_height,20.0"), "{csv}");
    // Levelled profile through the boss: base at 0, boss top at 20 um.
    let a = std::fs::read_to_string(out.join("profile_A.csv")).expect("profile A");
    assert!(a.contains("# averaging_width_mm: 0.040000") && a.contains("distance_mm,x_mm,y_mm,z_um,n"));
    let z_at = |x: f64| -> f64 {
        a.lines()
            .filter(|l| !l.starts_with('#'))
            .skip(1)
            .map(|l| l.split(',').map(|f| f.parse::<f64>().unwrap_or(f64::NAN)).collect::<Vec<_>>())
            .min_by(|p, q| (p[1] - x).abs().total_cmp(&(q[1] - x).abs()))
            .expect("rows")[3]
    };
    assert!(z_at(0.3).abs() < 1e-3 && (z_at(1.0) - 20.0).abs() < 1e-3, "{} {}", z_at(0.3), z_at(1.0));
    assert!(out.join("profile_V_X_1.0.csv").is_file(), "vertical section file");

    // A tolerance the part misses: exit code 2, the table still written.
    let (o, out) = run("fail", &["--step", "boss=base:boss=25±0.5", "--flatness", "base<=1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let json = measurements(&out);
    assert_eq!(json["overall_verdict"], "fail");
    assert_eq!(row(&json, "boss")["verdict"], "fail");
    assert_eq!(row(&json, "flatness base")["verdict"], "pass");
}

#[test]
fn an_unorganized_cloud_is_binned_and_measured() {
    // x y z only, as another program would export the plate.
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = plate_cloud();
    let mut text = format!(
        "ply\nformat ascii 1.0\ncomment unit mm\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nend_header\n",
        cloud.len()
    );
    for p in &cloud.xyz {
        text.push_str(&format!("{} {} {}\n", p[0], p[1], p[2]));
    }
    let ply = dir.path().join("xyz.ply");
    std::fs::write(&ply, text).expect("write");
    let out = dir.path().join("qc");
    let mut args = vec!["analyze", s(&ply), "--out", s(&out), "-q", "--step", "boss=base:boss=20±0.1"];
    args.extend(PLATE_REGIONS);
    let o = sheen(&args);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let json = measurements(&out);
    assert!((value(&json, "boss") - 20.0).abs() < 1e-3);
    assert!((json["height_map"]["pitch_mm"].as_f64().expect("pitch") - 0.02).abs() < 1e-9);
    let binned = json["warnings"].as_array().expect("warnings").iter().any(|w| {
        w["kind"] == "cloud_fields_missing" && w["message"].as_str().unwrap_or_default().contains("binning X-Y")
    });
    assert!(binned, "{}", json["warnings"]);
}

/// One `error:` line naming what is wrong, exit code 1.
fn assert_one_line_error(o: &Output, expected: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    for e in expected {
        assert!(lines[0].contains(e), "expected '{e}' in: {err}");
    }
}

#[test]
fn bad_inspections_and_inputs_fail_with_one_line_naming_the_option_or_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = plate_ply(dir.path());
    let out = dir.path().join("qc");
    let analyze = |extra: &[&str]| {
        let mut args = vec!["analyze", s(&ply), "--out", s(&out), "-q"];
        args.extend(extra);
        sheen(&args)
    };
    assert_one_line_error(&analyze(&["--region", "base=rect:0,0,1"]), &["--region base=rect:0,0,1", "4 numbers"]);
    assert_one_line_error(&analyze(&["--region", "base=hexagon:0,0,1"]), &["--region base=hexagon:0,0,1", "hexagon"]);
    assert_one_line_error(
        &analyze(&["--region", "far=rect:10,10,11,11", "--flatness", "far"]),
        &["--region far=rect:10,10,11,11", "outside the height map"],
    );
    assert_one_line_error(
        &analyze(&["--region", "base=rect:0,0,0.5,0.5", "--step", "h=base:bos"]),
        &["--step h=base:bos", "'bos'", "not defined", "'base'"],
    );
    assert_one_line_error(&analyze(&["--step", "h=base:boss=20±x"]), &["--step h=base:boss=20±x", "'x'"]);
    assert_one_line_error(&analyze(&["--level", "nowhere"]), &["--level nowhere", "'nowhere'"]);
    assert_one_line_error(&analyze(&["--hsection", "5"]), &["--hsection 5", "outside the height map"]);

    let not_ply = dir.path().join("scan.ply");
    std::fs::write(&not_ply, b"this is a text file, not a point cloud\n").expect("write");
    let o = sheen(&["analyze", s(&not_ply), "--out", s(&out), "-q"]);
    assert_one_line_error(&o, &["scan.ply", "not a PLY"]);
    let o = sheen(&["analyze", "/nonexistent/part.ply", "--out", s(&out), "-q"]);
    assert_one_line_error(&o, &["/nonexistent/part.ply"]);

    let session = dir.path().join("part.session.json");
    std::fs::write(&session, Session::new("plate.ply", Params::default()).to_json()).expect("write");
    let o = sheen(&["analyze", s(&session), "--out", s(&out), "-q"]);
    assert_one_line_error(&o, &["part.session.json", "--session"]);

    let spec = dir.path().join("spec.json");
    std::fs::write(&spec, r#"{"sheen_inspection": 1, "regions": [], "measurments": []}"#).expect("write");
    let o = sheen(&["analyze", s(&ply), "--spec", s(&spec), "--out", s(&out), "-q"]);
    assert_one_line_error(&o, &["spec.json", "measurments"]);
}

#[test]
fn outputs_never_overwrite_the_inputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = plate_ply(dir.path());
    // The cloud is named as the one output (--ply) would be.
    let cloud = dir.path().join("cloud.ply");
    std::fs::rename(&ply, &cloud).expect("rename");
    let before = std::fs::read(&cloud).expect("read");
    let o = sheen(&["analyze", s(&cloud), "--out", s(dir.path()), "--ply", "-q"]);
    assert_one_line_error(&o, &["cloud.ply", "input"]);
    assert_eq!(std::fs::read(&cloud).expect("read"), before);
    assert!(!dir.path().join("measurements.csv").exists(), "nothing written before the refusal");
    // A spec named like an output is an input too.
    let spec = dir.path().join("inspection.json");
    std::fs::write(&spec, r#"{"sheen_inspection": 1}"#).expect("write");
    let o = sheen(&["analyze", s(&cloud), "--spec", s(&spec), "--out", s(dir.path()), "-q"]);
    assert_one_line_error(&o, &["inspection.json", "input"]);
}

#[test]
fn a_session_with_a_spec_level_measurement_is_read() {
    // The session format's measurement list as the app writes it, on the PLY.
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = plate_ply(dir.path());
    let mut session = Session::new("plate.ply", Params::default());
    session.inspection.regions = vec![
        NamedRegion::new("base", Region::Rectangle { x_mm: [0.05, 0.6], y_mm: [0.05, 1.1] }),
        NamedRegion::new("boss", Region::Circle { centre_mm: [1.0, 0.6], radius_mm: 0.2 }),
    ];
    session.inspection.measurements = vec![MeasurementSpec {
        name: "boss height".into(),
        measure: Measure::StepHeight { reference: vec!["base".into()], measured: vec!["boss".into()] },
        nominal: Some(20.0),
        tolerance: Some(Tolerance::symmetric(0.1)),
    }];
    session.view = serde_json::json!({ "profile_colours": {} });
    let path = dir.path().join("plate.session.json");
    std::fs::write(&path, session.to_json()).expect("write");
    let out = dir.path().join("qc");
    let o = sheen(&["analyze", "--session", s(&path), "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!((value(&measurements(&out), "boss height") - 20.0).abs() < 1e-3);
    assert!(ply.is_file());
    // An inline option overrides the session's tolerance: now it fails.
    let o =
        sheen(&["analyze", "--session", s(&path), "--out", s(&out), "-q", "--step", "boss height=base:boss=21±0.1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

/// Where Gwyddion is installed (Debian: `apt-get install gwyddion`), its
/// thumbnailer must open the X3P and the TIFF `analyze` writes: it exits
/// non-zero on a file no Gwyddion module can load. Skipped without it.
#[test]
fn gwyddion_opens_the_height_maps_when_installed() {
    let probe = Command::new("gwyddion-thumbnailer").arg("--version").output();
    if probe.is_err() {
        eprintln!("gwyddion-thumbnailer not installed: skipped");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = plate_ply(dir.path());
    let out = dir.path().join("qc");
    let o = sheen(&["analyze", s(&ply), "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for file in ["height_map.x3p", "height_map.tif"] {
        let thumb = dir.path().join(format!("{file}.png"));
        let t = Command::new("gwyddion-thumbnailer")
            .args(["gnome2", "128", s(&out.join(file)), s(&thumb)])
            .output()
            .expect("run gwyddion-thumbnailer");
        assert!(t.status.success(), "Gwyddion cannot open {file}: {}", stderr(&t));
        assert!(std::fs::metadata(&thumb).map(|m| m.len() > 0).unwrap_or(false), "no thumbnail of {file}");
    }
}

#[test]
fn a_toleranced_measurement_on_a_hole_is_not_passed() {
    // The plate with a hole of radius 0.12 mm where nothing was measured.
    let dir = tempfile::tempdir().expect("tempdir");
    let full = plate_cloud();
    let keep: Vec<usize> =
        (0..full.len()).filter(|&i| (full.xyz[i][0] - 0.3).hypot(full.xyz[i][1] - 0.9) > 0.12).collect();
    let pick = |v: &[f32]| keep.iter().map(|&i| v[i]).collect::<Vec<f32>>();
    let cloud = PointCloud {
        xyz: keep.iter().map(|&i| full.xyz[i]).collect(),
        pixel_uv: keep.iter().map(|&i| full.pixel_uv[i]).collect(),
        source_set: keep.iter().map(|&i| full.source_set[i]).collect(),
        source_period_px: pick(&full.source_period_px),
        modulation_dn: pick(&full.modulation_dn),
        sigma_z: pick(&full.sigma_z),
        intensity_dn: pick(&full.intensity_dn),
        order_evidence: keep.iter().filter_map(|&i| full.order_evidence.get(i).copied()).collect(),
        ..full.clone()
    };
    let ply = dir.path().join("holed.ply");
    write_ply(&ply, &cloud, &PlyWriteOptions::default()).expect("write");
    let out = dir.path().join("qc");
    let o =
        sheen(&["analyze", s(&ply), "--out", s(&out), "--region", "pit=circle:0.3,0.9,0.08", "--flatness", "pit<=5"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let json = measurements(&out);
    let r = row(&json, "flatness pit");
    assert!(r["value"].is_null() && r["verdict"] == "fail", "{r}");
    assert!(r["note"].as_str().unwrap_or("").contains("valid height-map samples"), "{r}");
    assert!(stderr(&o).contains("warning: 'flatness pit' was not measured"), "{}", stderr(&o));
}
