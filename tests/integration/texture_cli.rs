//! Issue 20 through the binary: `sheen analyze --texture` and the S-filtered
//! `--flatness` on a cloud of known texture (a sine along X), checking rows,
//! units, limits, notes, exit codes and the errors of bad options.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use sheen::engine::point_cloud::PointCloud;
use sheen::io::ply::{PlyWriteOptions, write_ply};

/// Amplitude (µm) and wavelength (mm) of the sine; grid pitch (mm).
const A_UM: f64 = 0.4;
const LAMBDA_MM: f64 = 0.1;
const PITCH_MM: f64 = 0.0025;

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// z = 0.1 mm + 0.002 x + A sin(2π x / λ): 30 whole periods over 3 mm,
/// 0.1 mm across, tilted so the F-operator has something to remove; each
/// point's height sigma 0.01 µm.
fn sine_ply(dir: &Path) -> PathBuf {
    let (w, h) = (1200usize, 40usize);
    let mut cloud = PointCloud {
        unit: sheen::engine::length_unit::LengthUnit::Mm,
        grid_width: w,
        grid_height: h,
        ..PointCloud::default()
    };
    for r in 0..h {
        for c in 0..w {
            let (x, y) = (c as f64 * PITCH_MM, r as f64 * PITCH_MM);
            let z = 0.1 + 0.002 * x + A_UM / 1000.0 * (2.0 * std::f64::consts::PI * x / LAMBDA_MM).sin();
            cloud.xyz.push([x, y, z]);
            cloud.pixel_uv.push([c as f32, r as f32]);
            cloud.source_set.push(0);
            cloud.source_period_px.push(12.0);
            cloud.modulation_dn.push(100.0);
            cloud.sigma_z.push(0.00001);
            cloud.intensity_dn.push(128.0);
        }
    }
    let path = dir.join("sine.ply");
    write_ply(&path, &cloud, &PlyWriteOptions::default()).expect("write the PLY");
    path
}

fn analyze(ply: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["analyze", s(ply), "--out", s(out), "-q", "--pitch-mm", "0.0025"];
    args.extend(["--region", "face=rect:0,0,3,0.1"]);
    args.extend(extra);
    sheen(&args)
}

fn rows(out: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read(out.join("measurements.json")).expect("measurements.json");
    let json: serde_json::Value = serde_json::from_slice(&text).expect("JSON");
    json["measurements"].as_array().expect("rows").clone()
}

fn row<'a>(rows: &'a [serde_json::Value], name: &str) -> &'a serde_json::Value {
    rows.iter().find(|r| r["name"] == name).unwrap_or_else(|| panic!("no row '{name}' in {rows:?}"))
}

fn num(v: &serde_json::Value) -> f64 {
    v["value"].as_f64().unwrap_or_else(|| panic!("no value: {v}"))
}

/// The share of a sine of wavelength λ a Gaussian S-filter at λs keeps
/// (ISO 16610-21 Eq. 2).
fn s_kept(ls_mm: f64) -> f64 {
    let alpha = (std::f64::consts::LN_2 / std::f64::consts::PI).sqrt();
    (-std::f64::consts::PI * (alpha * ls_mm / LAMBDA_MM).powi(2)).exp()
}

#[test]
fn texture_rows_carry_parameter_unit_limits_and_verdict() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = sine_ply(dir.path());
    let out = dir.path().join("pass");
    let sa_nominal = format!("Sa={:.4}±0.01", 2.0 * A_UM / std::f64::consts::PI * s_kept(0.008));
    let texture = format!("seal=face,form=plane,ls=0.008,lc=0.5,Sq<=0.4,{sa_nominal}");
    let o = analyze(
        &ply,
        &out,
        &[
            "--texture",
            &texture,
            "--texture",
            "whole=all",
            "--flatness",
            "face,ls=0.025",
            "--flatness-rms",
            "face,ls=0.025",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = rows(&out);
    let sq = row(&rows, "seal Sq");
    assert_eq!((&sq["kind"], &sq["parameter"], &sq["unit"]), (&"texture".into(), &"Sq".into(), &"um".into()));
    let want_sq = A_UM / 2f64.sqrt() * s_kept(0.008);
    assert!((num(sq) - want_sq).abs() < 0.01 * want_sq, "Sq {} vs {want_sq}", num(sq));
    assert_eq!((&sq["upper_limit"], &sq["verdict"]), (&0.4.into(), &"pass".into()));
    assert_eq!(row(&rows, "seal Sa")["verdict"], "pass");
    assert!(row(&rows, "seal Sku")["verdict"].is_null());
    assert!((num(row(&rows, "seal Sku")) - 1.5).abs() < 0.015);
    assert!(num(row(&rows, "seal Ssk")).abs() < 0.01);
    // The lay runs along Y (Std 90°); the ACF of the sine decays to 0.2 at acos(0.2) / k.
    assert!((num(row(&rows, "seal Std")) - 90.0).abs() < 1.0, "{}", row(&rows, "seal Std"));
    let want_sal = 0.2f64.acos() / (2.0 * std::f64::consts::PI / LAMBDA_MM);
    assert!((num(row(&rows, "seal Sal")) - want_sal).abs() < 0.01 * want_sal, "{}", row(&rows, "seal Sal"));
    assert!(row(&rows, "seal Str")["note"].as_str().unwrap_or_default().contains("an upper bound"));
    for (p, unit) in [
        ("Sdr", "%"),
        ("Smr1", "%"),
        ("Ssk", "1"),
        ("Sdq", "1"),
        ("Vmc", "um"),
        ("Sz", "um"),
        ("Sal", "mm"),
        ("Str", "1"),
        ("Std", "deg"),
    ] {
        let r = row(&rows, &format!("seal {p}"));
        assert_eq!((&r["unit"], &r["parameter"]), (&unit.into(), &p.into()), "{r}");
    }
    // Sdq of a sine: A k / √2 (µm over µm), with the S-filter's share.
    let k = 2.0 * std::f64::consts::PI / (LAMBDA_MM * 1000.0);
    let want_sdq = A_UM * k / 2f64.sqrt() * s_kept(0.008);
    assert!((num(row(&rows, "seal Sdq")) - want_sdq).abs() < 0.01 * want_sdq);
    // With λs well above the pitch and Sq far above the 0.01 µm sigma, no caveat;
    // without an S-filter the note says the value is near the resolution limit.
    let note = |name: &str| row(&rows, name)["note"].as_str().unwrap_or_default().to_string();
    assert!(!note("seal Sq").contains("near the resolution limit"), "{}", note("seal Sq"));
    assert!(note("whole Sq").starts_with("near the resolution limit: no S-filter"), "{}", note("whole Sq"));
    assert!((num(row(&rows, "whole Sq")) - A_UM / 2f64.sqrt()).abs() < 0.01 * A_UM);
    // The S-filtered flatness: the sine's RMS times what the λs = 0.025 mm
    // filter keeps. The PV is an extreme and comes from the border, where the
    // renormalised kernel smooths less, so it lies between the interior's
    // filtered PV and the raw 2A.
    let flat = row(&rows, "flatness face");
    assert!(flat.get("parameter").is_none(), "other kinds carry no parameter: {flat}");
    let want_pv = 2.0 * A_UM * s_kept(0.025);
    assert!(num(flat) > 0.99 * want_pv && num(flat) < 2.0 * A_UM, "PV {} vs {want_pv}", num(flat));
    let want_rms = A_UM / 2f64.sqrt() * s_kept(0.025);
    let rms = num(row(&rows, "flatness rms face"));
    assert!((rms - want_rms).abs() < 0.01 * want_rms, "RMS {rms} vs {want_rms}");
    assert!(flat["note"].as_str().unwrap_or_default().contains("S-filter λs 0.025 mm"), "{flat}");
    let csv = std::fs::read_to_string(out.join("measurements.csv")).expect("csv");
    assert!(
        csv.contains(",note,parameter,u,U,")
            && csv
                .lines()
                .any(|l| l.starts_with("seal Sq,texture,") && l.contains(",Sq,") && l.contains(",monte-carlo,"))
    );
    // Every texture row states its uncertainty by Monte Carlo, with its trials.
    let sq = row(&rows, "seal Sq");
    assert_eq!(sq["uncertainty"]["method"], "monte-carlo", "{sq}");
    assert!(sq["uncertainty"]["trials"].as_u64().unwrap_or(0) >= 10, "{sq}");
    let u_sq = sq["uncertainty"]["U"].as_f64().expect("U");
    assert!(u_sq > 0.0 && u_sq < 0.1 * num(sq), "U(Sq) {u_sq} for Sq {}", num(sq));
    assert_eq!(flat["uncertainty"]["method"], "monte-carlo", "{flat}");
    assert!(flat["uncertainty"]["noise_floor"].as_f64().is_some(), "{flat}");
    // Extremes (Sz, Sp, Sv) state what noise alone would give on these nodes,
    // below the sine's own peak-to-valley; means (Sq) have no floor.
    let sz = row(&rows, "seal Sz");
    let floor = sz["uncertainty"]["noise_floor"].as_f64().expect("Sz's noise floor");
    assert!(floor > 0.0 && floor < num(sz), "floor {floor} for Sz {}", num(sz));
    assert!(sq["uncertainty"].get("noise_floor").is_none(), "{sq}");
}

#[test]
fn a_failed_texture_limit_exits_2_and_a_small_sq_is_flagged_against_the_cloud_sigma() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = sine_ply(dir.path());
    let out = dir.path().join("fail");
    // λc far below the sine's wavelength leaves almost nothing: Sq near the noise.
    let o =
        analyze(&ply, &out, &["--texture", "seal=face,ls=0.005,lc=0.02,Sa<=0.2", "--texture", "rough=face,Sa<=0.2"]);
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = rows(&out);
    assert_eq!(row(&rows, "rough Sa")["verdict"], "fail");
    assert_eq!(row(&rows, "seal Sa")["verdict"], "pass");
    let note = row(&rows, "seal Sq")["note"].as_str().unwrap_or_default().to_string();
    assert!(
        note.contains("within twice the height noise 0.0100 um (median height sigma of the cloud's points)"),
        "{note}"
    );
}

#[test]
fn bad_texture_options_fail_with_one_line_naming_the_option() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = sine_ply(dir.path());
    let out = dir.path().join("bad");
    for (value, expected) in [
        ("seal=face,Sx<=1", "unknown parameter or key 'Sx'"),
        ("seal=face,lc=-0.8", "not a positive cut-off"),
        ("seal=face,ls=0.8,lc=0.25", "must be shorter"),
        ("seal=nowhere,Sa<=1", "region 'nowhere', which is not defined"),
        ("seal=face,form=cylinder", "form=cylinder"),
    ] {
        let o = analyze(&ply, &out, &["--texture", value]);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(1), "{value}: {err}");
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{err}");
        assert!(lines[0].starts_with("error: --texture ") && lines[0].contains(expected), "{value}: {err}");
    }
}

#[test]
fn roughness_rows_of_a_section_profile_with_given_and_default_cutoffs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = sine_ply(dir.path());
    let out = dir.path().join("profile");
    let o = analyze(
        &ply,
        &out,
        &[
            "--hsection",
            "A=0.05",
            "--roughness",
            "A,lc=0.5,Ra<=0.3,Rz<=0.7",
            "--hsection",
            "B=0.06",
            "--roughness",
            "B",
        ],
    );
    // Rz = 2A = 0.8 um misses its 0.7 um limit: exit code 2.
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = rows(&out);
    let ra = row(&rows, "A Ra");
    assert_eq!((&ra["kind"], &ra["parameter"], &ra["unit"]), (&"profile_texture".into(), &"Ra".into(), &"um".into()));
    // λs defaults to 2.5 µm for λc 0.5 mm, which keeps 99.96 % of the sine.
    let want_ra = 2.0 * A_UM / std::f64::consts::PI * s_kept(0.0025);
    assert!((num(ra) - want_ra).abs() < 0.01 * want_ra, "Ra {} vs {want_ra}", num(ra));
    assert_eq!(ra["verdict"], "pass");
    assert_eq!(row(&rows, "A Rz")["verdict"], "fail");
    assert!((num(row(&rows, "A Rz")) - 2.0 * A_UM).abs() < 0.01 * 2.0 * A_UM);
    assert!((num(row(&rows, "A Rku")) - 1.5).abs() < 0.015);
    let rsm = row(&rows, "A RSm");
    assert_eq!(rsm["unit"], "mm");
    assert!((num(rsm) - LAMBDA_MM).abs() < 0.01 * LAMBDA_MM, "{rsm}");
    assert_eq!((&row(&rows, "A Rmr")["unit"], &row(&rows, "A Rsk")["unit"]), (&"%".into(), &"1".into()));
    assert!(row(&rows, "A Wq").is_object() && row(&rows, "A Pt").is_object());
    let note = ra["note"].as_str().unwrap_or_default();
    assert!(note.contains("λs 0.0025 mm is below twice the profile step (0.0025 mm)"), "{note}");
    assert!(note.contains("evaluation length 2.000 mm in 4 section(s)"), "{note}");
    // Without lc the cut-off comes from Ra (0.25 um: 0.8 mm).
    let b = row(&rows, "B Ra");
    assert!(b["note"].as_str().unwrap_or_default().contains("λc 0.8 mm (from Ra, ISO 21920-3)"), "{b}");
    assert!((num(b) - want_ra).abs() < 0.01 * want_ra, "{b}");

    let o = analyze(&ply, &dir.path().join("bad"), &["--roughness", "Z,Ra<=1"]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.starts_with("error: --roughness Z,Ra<=1: profile 'Z' is not defined") && err.lines().count() == 1,
        "{err}"
    );
}

// ---- Height maps of other instruments as input (issue 20 a) ----

fn map_input(map: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["analyze", s(map), "--out", s(out), "-q"];
    args.extend(extra);
    sheen(&args)
}

fn measurements(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("measurements.json")).expect("measurements.json")).expect("JSON")
}

#[test]
fn a_map_sheen_wrote_measures_the_same_texture_read_back_as_x3p_or_tiff() {
    let dir = tempfile::tempdir().unwrap();
    let ply = sine_ply(dir.path());
    let first = dir.path().join("first");
    let texture = ["--texture", "seal=face,form=plane,lc=0.5"];
    let o = analyze(&ply, &first, &texture);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let want = rows(&first);

    let region = ["--region", "face=rect:0,0,3,0.1"];
    let from_x3p = dir.path().join("x3p");
    let o = map_input(&first.join("height_map.x3p"), &from_x3p, &[&region[..], &texture[..]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let json = measurements(&from_x3p);
    assert_eq!(json["input"]["kind"], "height_map");
    assert_eq!(json["input"]["format"], "X3P");
    assert!(json["rasterization"].is_null());
    assert_eq!(json["height_map"]["pitch_mm"], 0.0025);

    let from_tiff = dir.path().join("tiff");
    let tiff_args = [&region[..], &texture[..], &["--pixel-mm", "0.0025"][..]].concat();
    let o = map_input(&first.join("height_map.tif"), &from_tiff, &tiff_args);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(measurements(&from_tiff)["input"]["format"], "TIFF");

    for out in [&from_x3p, &from_tiff] {
        let got = rows(out);
        for p in ["Sa", "Sq", "Sku", "Sz", "Sdq", "Sdr"] {
            let (w, g) = (num(row(&want, &format!("seal {p}"))), num(row(&got, &format!("seal {p}"))));
            // The X3P and the TIFF store f32 heights: a few ulps, nothing more.
            assert!((g - w).abs() <= 1e-5 * w.abs().max(1e-3), "{p} from {}: {g} vs {w}", out.display());
        }
    }
}

/// A 16 x 16 map whose north half (the TIFF's first rows) is 1000 nm
/// higher than its south half.
fn step_tiff_nm(dir: &Path) -> PathBuf {
    let (w, h) = (16usize, 16usize);
    let z: Vec<f32> = (0..w * h).map(|i| if i / w < h / 2 { 1000.0 } else { 0.0 }).collect();
    let path = dir.join("step.tif");
    sheen::io::maps::write_f32_tiff(&path, w, h, &z, sheen::io::maps::TiffCompression::None).expect("write TIFF");
    path
}

#[test]
fn a_float_tiff_reads_north_up_at_the_given_pixel_size_and_height_unit() {
    let dir = tempfile::tempdir().unwrap();
    let tiff = step_tiff_nm(dir.path());
    let out = dir.path().join("out");
    let o = map_input(
        &tiff,
        &out,
        &[
            "--pixel-mm",
            "0.01",
            "--z-unit",
            "nm",
            "--region",
            "south=rect:0,0,0.15,0.06",
            "--region",
            "north=rect:0,0.09,0.15,0.15",
            "--step",
            "rise=south:north",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let json = measurements(&out);
    assert_eq!((json["height_map"]["width"].as_u64(), json["height_map"]["pitch_mm"].as_f64()), (Some(16), Some(0.01)));
    let rise = json["measurements"].as_array().unwrap().iter().find(|r| r["kind"] == "step_height").cloned();
    let rise = rise.unwrap_or_else(|| panic!("no step row in {json}"));
    // North is up and 1000 nm is 1 µm.
    assert!((rise["value"].as_f64().unwrap() - 1.0).abs() < 1e-6, "{rise}");
    assert_eq!(rise["unit"], "um");
}

/// The sine of `sine_ply` as a text SDF in nm, `dy_um` apart along Y.
fn sine_sdf(dir: &Path, dy_um: f64) -> PathBuf {
    let (w, h) = (1201usize, (100.0 / dy_um) as usize + 1);
    let mut text = format!(
        "aISO-1.0\nManufacID = Probe\nCreateDate = 010120241200\nModDate = 010120241200\nNumPoints = {w}\n\
         NumProfiles = {h}\nXscale = 2.5e-6\nYscale = {}\nZscale = 1e-9\nZresolution = -1\nCompression = 0\n\
         DataType = 7\nCheckType = 0\n*\n",
        dy_um * 1e-6
    );
    for _ in 0..h {
        let profile: Vec<String> = (0..w)
            .map(|c| {
                let x = c as f64 * PITCH_MM;
                format!("{:.6}", A_UM * 1000.0 * (2.0 * std::f64::consts::PI * x / LAMBDA_MM).sin())
            })
            .collect();
        text.push_str(&profile.join(" "));
        text.push('\n');
    }
    text.push_str("*\n*\n");
    let path = dir.join("probe.sdf");
    std::fs::write(&path, text).expect("write the SDF");
    path
}

#[test]
fn an_sdf_with_unequal_increments_is_resampled_with_a_warning_and_keeps_its_texture() {
    let dir = tempfile::tempdir().unwrap();
    for (dy_um, resampled) in [(2.5, false), (5.0, true)] {
        let sdf = sine_sdf(dir.path(), dy_um);
        let out = dir.path().join(format!("out{dy_um}"));
        let o = map_input(&sdf, &out, &["--region", "face=rect:0,0,3,0.1", "--texture", "seal=face,form=none,lc=0.5"]);
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let json = measurements(&out);
        assert_eq!((&json["input"]["format"], json["height_map"]["pitch_mm"].as_f64()), (&"SDF".into(), Some(0.0025)));
        let warned = json["warnings"].as_array().unwrap().iter().any(|w| {
            w["kind"] == "height_map_resampled" && w["message"].as_str().unwrap_or_default().contains("resampled")
        });
        assert_eq!(warned, resampled, "{}", json["warnings"]);
        let rows = rows(&out);
        let sq = num(row(&rows, "seal Sq"));
        assert!((sq - A_UM / 2f64.sqrt()).abs() < 0.005 * A_UM, "Sq {sq} (dy {dy_um} um)");
    }
}

/// An X3P that MountainsMap wrote (X and Y increments that differ), with
/// the values another reader states for it; `tests/data/foreign/README.md`
/// says where the file and the values come from.
#[test]
fn an_x3p_mountainsmap_wrote_gives_the_values_its_other_reader_states() {
    let dir = tempfile::tempdir().unwrap();
    let x3p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/foreign/mountainsmap-650x650.x3p");
    let out = dir.path().join("out");
    let o = map_input(&x3p, &out, &["--texture", "t=all,form=none"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let json = measurements(&out);
    assert_eq!(json["input"]["format"], "X3P");
    let resampled = json["warnings"].as_array().unwrap().iter().any(|w| w["kind"] == "height_map_resampled");
    assert!(resampled, "{}", json["warnings"]);
    // 650 columns at the finer X increment; 650 rows of 0.31458 µm span
    // 1600 rows of 0.12766 µm.
    let map = &json["height_map"];
    assert_eq!((map["width"].as_u64(), map["height"].as_u64()), (Some(650), Some(1600)), "{map}");
    assert!((map["pitch_mm"].as_f64().unwrap() - 1.27656509837346e-4).abs() < 1e-12, "{map}");

    let rows = rows(&out);
    // Stated: Sq 7.728033e-8 m. The bilinear resampling onto the square grid
    // averages neighbouring rows and costs 0.22 % of it; more would be a
    // misread increment or unit.
    let sq_um = num(row(&rows, "t Sq"));
    assert!((sq_um / 0.07728033273597876 - 1.0).abs() < 0.003, "Sq {sq_um} um");
    // Stated: RMS gradient 0.062070 by forward differences; central
    // differences give 0.05957 on the file's own grid.
    let sdq = num(row(&rows, "t Sdq"));
    assert!((sdq / 0.05957141543221935 - 1.0).abs() < 0.005, "Sdq {sdq}");
    assert!((sdq / 0.062070073998443276 - 1.0).abs() < 0.05, "Sdq {sdq}");
}

#[test]
fn options_of_another_kind_of_input_are_refused_naming_the_option() {
    let dir = tempfile::tempdir().unwrap();
    let tiff = step_tiff_nm(dir.path());
    let sdf = sine_sdf(dir.path(), 2.5);
    let ply = sine_ply(dir.path());
    let cases: [(&Path, &[&str], &str); 5] = [
        (&tiff, &[], "--pixel-mm"),
        (&tiff, &["--pixel-mm", "0.01", "--ply"], "--ply"),
        (&tiff, &["--pixel-mm", "0.01", "--pitch-mm", "0.01"], "--pitch-mm"),
        (&sdf, &["--z-unit", "nm"], "--z-unit"),
        (&ply, &["--pixel-mm", "0.01"], "--pixel-mm"),
    ];
    for (i, (input, extra, option)) in cases.into_iter().enumerate() {
        let out = dir.path().join(format!("o{i}"));
        let o = map_input(input, &out, extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {err}");
        assert!(err.contains(option) && err.contains(s(input)), "{extra:?}: {err}");
    }
}

/// An area smaller than its filter, or with too few nodes for a height
/// distribution, gets no values and says why, as a profile shorter than its
/// cut-off does; a limit on it then fails the part (exit 2) instead of
/// passing on numbers of a few border nodes.
#[test]
fn an_area_too_small_for_its_filters_or_too_sparse_is_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let ply = sine_ply(dir.path());
    let out = dir.path().join("small");
    let o = analyze(
        &ply,
        &out,
        &[
            "--region",
            "tiny=rect:0,0,0.01,0.01",
            "--texture",
            "t=tiny,lc=0.8",
            "--texture",
            "wide=all,lc=100",
            "--texture",
            "ok=face,lc=0.5",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = rows(&out);
    for p in ["Sq", "Ssk", "Sku", "Sa"] {
        let tiny = row(&rows, &format!("t {p}"));
        assert!(tiny["value"].is_null(), "{tiny}");
        assert!(tiny["note"].as_str().unwrap_or_default().contains("at least 64 are needed"), "{tiny}");
        let wide = row(&rows, &format!("wide {p}"));
        assert!(wide["value"].is_null(), "{wide}");
        assert!(wide["note"].as_str().unwrap_or_default().contains("λc 100 mm exceeds the region's extent"), "{wide}");
        assert!(row(&rows, &format!("ok {p}"))["value"].is_number(), "a filter that fits still measures");
    }
    let limited = dir.path().join("limited");
    let o = analyze(&ply, &limited, &["--region", "tiny=rect:0,0,0.01,0.01", "--texture", "t=tiny,Sq<=1"]);
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
}
