//! Bringing another rig's images in (issue 13): `sheen import` on vendor-like
//! namings reconstructs the same cloud as the original fringe set, phase-shift
//! conventions give the same phase once the manifest says so, `sheen check`
//! catches a wrong one, and a one-camera import runs `sheen phase`.

use std::collections::HashMap;
use std::f64::consts::{FRAC_PI_2, TAU};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use sheen::engine::control::RunControl;
use sheen::engine::fringe::{FringeSetInfo, Measurement};
use sheen::engine::pipeline::{Params, run, run_phase};
use sheen::engine::point_cloud::PointCloud;
use sheen::io::dataset::write_measurement;
use sheen::io::manifest::{load_measurement, read_manifest};
use sheen::sim::{SceneKind, SimConfig, simulate};

use crate::util::{phase_diff, sinusoid, stack_from_fn};

fn sheen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run the sheen binary")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf8 path")
}

const SHIFTS: [usize; 4] = [8, 8, 8, 4];

/// The simulated watch plate, 320x240, sets of 8, 8, 8 and 4 shifts, on disk.
fn original(dir: &Path) -> (PathBuf, Measurement) {
    let mut c = SimConfig::new(SceneKind::WatchPlate, 320, 240);
    c.shifts = SHIFTS.to_vec();
    c.noise_sigma_dn = 1.0;
    let sim = simulate(&c, &RunControl::new()).expect("simulate");
    let manifest = write_measurement(&dir.join("original"), &sim.measurement).expect("write");
    (manifest, sim.measurement)
}

fn cloud_of(manifest: &Path) -> PointCloud {
    let loaded = load_measurement(manifest, &RunControl::new()).expect("load");
    let rec = run(&loaded.measurement, &Params::default(), None, &RunControl::new()).expect("run");
    rec.stereo.expect("stereo").cloud
}

/// The original's images as `(camera, set, shift) -> file`, relative to its folder.
fn original_files(manifest: &Path) -> HashMap<(String, usize, usize), PathBuf> {
    let m = read_manifest(manifest).expect("manifest");
    let dir = manifest.parent().expect("folder");
    let mut out = HashMap::new();
    for (si, set) in m.sets.iter().enumerate() {
        for (cam, files) in &set.images {
            for (k, f) in files.iter().enumerate() {
                out.insert((cam.clone(), si, k), dir.join(f));
            }
        }
    }
    out
}

fn copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to.parent().expect("parent")).expect("mkdir");
    std::fs::copy(from, to).expect("copy");
}

fn assert_same_cloud(a: &PointCloud, b: &PointCloud, tolerance_mm: f64, what: &str) {
    if tolerance_mm == 0.0 {
        assert_eq!(a.len(), b.len(), "{what}: point count");
        assert_eq!(a.pixel_uv, b.pixel_uv, "{what}: pixels");
        assert_eq!(a.xyz, b.xyz, "{what}: points must be identical");
        return;
    }
    let index: HashMap<[u32; 2], usize> =
        b.pixel_uv.iter().enumerate().map(|(i, uv)| ([uv[0].to_bits(), uv[1].to_bits()], i)).collect();
    let mut common = 0;
    let mut worst = 0.0f64;
    for (i, uv) in a.pixel_uv.iter().enumerate() {
        if let Some(&j) = index.get(&[uv[0].to_bits(), uv[1].to_bits()]) {
            common += 1;
            for c in 0..3 {
                worst = worst.max((a.xyz[i][c] - b.xyz[j][c]).abs());
            }
        }
    }
    assert!(a.len() > 10_000, "{what}: {} points", a.len());
    assert!(
        common as f64 >= 0.999 * a.len().max(b.len()) as f64,
        "{what}: {common} common of {} / {}",
        a.len(),
        b.len()
    );
    assert!(worst <= tolerance_mm, "{what}: points differ by up to {worst:e} mm");
}

#[test]
fn three_vendor_namings_import_to_the_same_cloud() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (manifest, m) = original(dir.path());
    let reference = cloud_of(&manifest);
    let files = original_files(&manifest);
    let calibration = manifest.parent().expect("folder").join("calibration.json");
    let (w, h) = (m.cameras[0].width as u32, m.cameras[0].height as u32);

    // A: one flat folder, `cam{camera}_{index}.bmp`, numbered 1..28 without
    // padding (natural order: 9 before 10), Gray-code images beside them.
    let a = dir.path().join("vendor_a");
    std::fs::create_dir_all(&a).expect("mkdir");
    for (cam, key) in [("left", "L"), ("right", "R")] {
        let mut index = 1;
        for (si, &n) in SHIFTS.iter().enumerate() {
            for k in 0..n {
                let gray = image::open(&files[&(cam.to_string(), si, k)]).expect("decode").into_luma8();
                gray.save(a.join(format!("cam{key}_{index}.bmp"))).expect("bmp");
                index += 1;
            }
        }
        for g in 0..3 {
            image::GrayImage::from_pixel(w, h, image::Luma([(g * 80) as u8]))
                .save(a.join(format!("cam{key}_gray_{g}.bmp")))
                .expect("gray code");
        }
    }
    copy(&calibration, &a.join("rig.json"));
    let out_a = a.join("fringe-set.json");
    let o = sheen(&[
        "import",
        s(&a),
        "--out",
        s(&out_a),
        "--pattern",
        "cam{camera}_{index}.bmp",
        "--cameras",
        "left=L,right=R",
        "--periods",
        "912,144,24,12",
        "--shifts",
        "8,8,8,4",
        "--skip",
        "cam?_gray_*",
        "--calibration",
        s(&a.join("rig.json")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let table = text(&o);
    let row = |cam: &str, set: usize, shift: usize, file: &str| {
        table.lines().any(|l| {
            l.split_whitespace().collect::<Vec<_>>() == [cam, &set.to_string(), "144", &shift.to_string(), file]
        })
    };
    assert!(row("left", 1, 0, "camL_9.bmp") && row("right", 1, 7, "camR_16.bmp"), "one row per image:\n{table}");
    let ma = read_manifest(&out_a).expect("manifest A");
    assert_eq!(ma.sets[1].images["left"][0], "camL_9.bmp", "natural order: 9 follows 8");
    assert_eq!(ma.sets[3].images["right"], ["camR_25.bmp", "camR_26.bmp", "camR_27.bmp", "camR_28.bmp"]);
    assert_same_cloud(&reference, &cloud_of(&out_a), 0.0, "scheme A");

    // B: `{camera}/f{period}/img{shift:02}.png` in camera folders cam0/cam1;
    // periods and shift counts read from the names.
    let b = dir.path().join("vendor_b");
    for (cam, key) in [("left", "cam0"), ("right", "cam1")] {
        for (si, set) in m.sets.iter().enumerate() {
            for k in 0..set.shifts() {
                copy(&files[&(cam.to_string(), si, k)], &b.join(format!("{key}/f{}/img{k:02}.png", set.period_px)));
            }
        }
    }
    copy(&calibration, &b.join("calib/rig.json"));
    let out_b = b.join("fringe-set.json");
    let o = sheen(&[
        "import",
        s(&b),
        "--pattern",
        "{camera}/f{period}/img{shift:02}.png",
        "--cameras",
        "left=cam0,right=cam1",
        "--calibration",
        s(&b.join("calib/rig.json")),
        "-q",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let mb = read_manifest(&out_b).expect("manifest B (the default path)");
    assert_eq!(mb.sets.iter().map(|s| s.shifts).collect::<Vec<_>>(), SHIFTS);
    assert_eq!(mb.sets[2].period_px, 24.0);
    assert_same_cloud(&reference, &cloud_of(&out_b), 0.0, "scheme B");

    // C: camera folders Left/Right, files 1..28 in natural order, but each set
    // recorded with the shift running the other way; a dark frame to skip.
    // The manifest goes above the folder.
    let c = dir.path().join("vendor_c");
    for (cam, key) in [("left", "Left"), ("right", "Right")] {
        let mut index = 1;
        for (si, &n) in SHIFTS.iter().enumerate() {
            for j in 0..n {
                let k = (n - j) % n;
                copy(&files[&(cam.to_string(), si, k)], &c.join(format!("{key}/{index}.png")));
                index += 1;
            }
        }
        image::GrayImage::new(w, h).save(c.join(format!("{key}/dark.png"))).expect("dark");
    }
    copy(&calibration, &c.join("calibration.json"));
    let out_c = dir.path().join("vendor_c.json");
    let import_c = |sign: &str| {
        sheen(&[
            "import",
            s(&c),
            "--out",
            s(&out_c),
            "--cameras",
            "left=Left,right=Right",
            "--periods",
            "912,144,24,12",
            "--shifts",
            "8,8,8,4",
            "--skip",
            "dark.png",
            "--shift-sign",
            sign,
            "--calibration",
            s(&c.join("calibration.json")),
        ])
    };
    let o = import_c("-1");
    assert!(o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("REVERSED") && !text(&o).contains("MISMATCH"), "{}", text(&o));
    let mc = read_manifest(&out_c).expect("manifest C");
    assert_eq!(mc.sets[0].images["left"][1], "vendor_c/Left/2.png");
    let shifts = mc.sets[3].phase_shifts_rad.as_ref().expect("the manifest states the reversed shifts");
    assert!((shifts[1] + TAU / 4.0).abs() < 1e-12, "{shifts:?}");
    // The phase kernel sums the samples in file order in f32, so the
    // reversed listing rounds differently: equal to f32 precision (about
    // 1e-6 of the field), far below the method's noise.
    assert_same_cloud(&reference, &cloud_of(&out_c), 2e-5, "scheme C");
}

/// A one-camera measurement, 16-bit samples of `A + B cos(Phi + delta_k)`
/// with Phi growing along u, per set `shifts(set)`.
fn synthetic(shifts: impl Fn(usize, usize) -> Vec<f64>) -> Measurement {
    let (w, h) = (160usize, 96usize);
    let periods = [480.0, 96.0, 24.0];
    let ns = [8, 8, 4];
    let x_p = |i: usize| 20.0 + 2.5 * (i % w) as f64 + 0.4 * (i / w) as f64;
    let sets: Vec<FringeSetInfo> = periods
        .iter()
        .zip(ns)
        .enumerate()
        .map(|(s, (&p, n))| FringeSetInfo { period_px: p, phase_shifts_rad: shifts(s, n) })
        .collect();
    let stacks = sets
        .iter()
        .map(|set| {
            stack_from_fn(w, h, set.shifts(), 65535, |i, k| {
                sinusoid(30000.0, 20000.0, TAU * x_p(i) / set.period_px, set.phase_shifts_rad[k])
            })
        })
        .collect();
    Measurement {
        bit_depth: 16,
        saturation_level: 65535,
        sets,
        cameras: vec![sheen::engine::fringe::CameraFringes { name: "left".into(), width: w, height: h, stacks }],
        calibration: None,
        label: "synthetic".into(),
        projector: None,
        id: sheen::engine::fringe::next_measurement_id(),
    }
}

fn plain(_: usize, n: usize) -> Vec<f64> {
    (0..n).map(|k| TAU * k as f64 / n as f64).collect()
}

fn reversed_from_half_pi(_: usize, n: usize) -> Vec<f64> {
    (0..n).map(|k| FRAC_PI_2 - TAU * k as f64 / n as f64).collect()
}

#[test]
fn a_reversed_convention_gives_the_same_phase_once_the_manifest_says_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plain_m = synthetic(plain);
    let reversed = synthetic(reversed_from_half_pi);
    let path = write_measurement(&dir.path().join("reversed"), &reversed).expect("write");
    let listed = read_manifest(&path).expect("manifest");
    assert!(listed.sets.iter().all(|s| s.phase_shifts_rad.is_some()), "the manifest carries the convention");
    let loaded = load_measurement(&path, &RunControl::new()).expect("load").measurement;
    let params = Params::default();
    let a = run_phase(&plain_m, &params, None, &RunControl::new()).expect("plain");
    let b = run_phase(&loaded, &params, None, &RunControl::new()).expect("reversed");
    for (sa, sb) in a.cameras[0].sets.iter().zip(&b.cameras[0].sets) {
        let worst = sa
            .wrapped_phase_rad
            .iter()
            .zip(&sb.wrapped_phase_rad)
            .map(|(x, y)| phase_diff(f64::from(*x), f64::from(*y)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-3, "period {}: wrapped phases differ by {worst} rad", sa.period_px);
    }
    let (fa, fb) = (&a.cameras[0].fused.fused_phase_rad, &b.cameras[0].fused.fused_phase_rad);
    let valid = fa.iter().filter(|x| x.is_finite()).count();
    assert!(valid > fa.len() * 95 / 100, "{valid} of {}", fa.len());
    let worst = fa.iter().zip(fb).filter(|(x, _)| x.is_finite()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-2, "fused phases differ by {worst} rad");
    // Read as the plain convention, the same images give another phase.
    let mut wrong = loaded.clone();
    wrong.sets = plain_m.sets.clone();
    let c = run_phase(&wrong, &params, None, &RunControl::new()).expect("wrong manifest");
    let off = c.cameras[0].sets[2]
        .wrapped_phase_rad
        .iter()
        .zip(&a.cameras[0].sets[2].wrapped_phase_rad)
        .filter(|(x, y)| phase_diff(f64::from(**x), f64::from(**y)).abs() > 0.5)
        .count();
    assert!(off > fa.len() / 2, "a wrong convention must change the phase ({off} pixels)");
}

#[test]
fn check_warns_when_the_manifest_has_the_wrong_convention() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The rig's densest set runs the other way from a start of pi/2 (as in
    // the example), the others are plain.
    let mixed = |s: usize, n: usize| if s == 2 { reversed_from_half_pi(s, n) } else { plain(s, n) };
    let good = write_measurement(&dir.path().join("good"), &synthetic(mixed)).expect("write");
    let o = sheen(&["check", s(&good), "-q"]);
    assert!(o.status.success(), "the right manifest passes:\n{}", text(&o));
    assert!(text(&o).matches(" ok").count() >= 3, "{}", text(&o));

    // The same images with a manifest that claims the plain convention.
    let mut wrong_m = synthetic(mixed);
    wrong_m.sets = synthetic(plain).sets;
    let wrong = write_measurement(&dir.path().join("wrong"), &wrong_m).expect("write");
    let o = sheen(&["check", s(&wrong), "-q"]);
    assert_eq!(o.status.code(), Some(3), "a wrong manifest fails with the disagreement code:\n{}", text(&o));
    let out = text(&o);
    assert!(out.contains("REVERSED"), "{out}");
    assert!(out.contains("left set 2 (period 24 px)") && out.contains("reverse shift order"), "{out}");
    assert_eq!(out.lines().filter(|l| l.starts_with("error:")).count(), 1, "{out}");

    // All sets reversed with a plain manifest: the images alone cannot tell,
    // knowing where the phase grows in the image can.
    let mut all = synthetic(reversed_from_half_pi);
    all.sets = synthetic(plain).sets;
    let all = write_measurement(&dir.path().join("all"), &all).expect("write");
    let o = sheen(&["check", s(&all), "-q", "--phase-grows", "right"]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).matches("REVERSED").count() >= 3, "{}", text(&o));
    // A manifest that cannot be read is an input error, not a disagreement.
    let o = sheen(&["check", s(&dir.path().join("no-such-manifest.json")), "-q"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let o = sheen(&["check", s(&good), "-q", "--phase-grows", "right"]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn a_one_camera_folder_imports_and_runs_phase_but_not_reconstruct() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = synthetic(plain);
    let written = write_measurement(&dir.path().join("orig"), &m).expect("write");
    let files = original_files(&written);
    // One folder, 16-bit TIFF-like numbering 0..19 with 12-bit data.
    let folder = dir.path().join("rig");
    std::fs::create_dir_all(&folder).expect("mkdir");
    let mut index = 0;
    for (si, set) in m.sets.iter().enumerate() {
        for k in 0..set.shifts() {
            let img = image::open(&files[&("left".to_string(), si, k)]).expect("decode").into_luma16();
            let scaled = image::ImageBuffer::from_fn(img.width(), img.height(), |x, y| {
                image::Luma([img.get_pixel(x, y)[0] / 16])
            });
            let img: image::ImageBuffer<image::Luma<u16>, Vec<u16>> = scaled;
            img.save(folder.join(format!("frame{index}.png"))).expect("png");
            index += 1;
        }
    }
    let o = sheen(&["import", s(&folder), "--periods", "480,96,24", "--shifts", "8,8,4", "--cameras", "left"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("bit depth 12"), "12-bit data in 16-bit files is recognised:\n{}", text(&o));
    let manifest = folder.join("fringe-set.json");
    let listed = read_manifest(&manifest).expect("manifest");
    assert_eq!(listed.bit_depth, 12);
    assert!(listed.calibration.is_none());
    assert_eq!(listed.sets[0].images["left"][2], "frame2.png");
    assert_eq!(listed.sets[1].images["left"][0], "frame8.png", "natural order: frame8 before frame10");

    let maps = dir.path().join("maps");
    let o = sheen(&["phase", s(&manifest), "--maps", s(&maps), "-q"]);
    assert!(o.status.success(), "{}", text(&o));
    let mut names = vec!["left_fused_phase".to_string(), "left_source".to_string()];
    for p in ["480", "96", "24"] {
        for kind in ["saturation", "wrapped", "modulation"] {
            names.push(format!("left_{kind}_{p}"));
        }
    }
    for n in &names {
        assert!(maps.join(format!("{n}.tif")).is_file(), "missing {n}.tif");
        assert!(maps.join(format!("{n}.png")).is_file(), "missing {n}.png");
    }
    let wrapped = sheen::io::maps::read_f32_tiff(&maps.join("left_wrapped_24.tif")).expect("tiff");
    assert!(wrapped.data.iter().filter(|x| x.is_finite()).all(|&x| (0.0..TAU as f32).contains(&x)));
    let source = sheen::io::maps::read_f32_tiff(&maps.join("left_source.tif")).expect("tiff");
    assert!(source.data.iter().all(|&x| (-2.0..=2.0).contains(&x) && x.fract() == 0.0));

    let cloud = dir.path().join("cloud.ply");
    let o = sheen(&["reconstruct", s(&manifest), "--out", s(&cloud)]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(err.lines().count(), 1, "one line:\n{err}");
    assert!(err.contains("two cameras and a calibration") && err.contains("sheen phase"), "{err}");
    assert!(!cloud.exists());
}

#[test]
fn import_errors_name_the_folder_and_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let folder = dir.path().join("rig");
    std::fs::create_dir_all(&folder).expect("mkdir");
    for i in 0..7 {
        image::GrayImage::from_pixel(16, 8, image::Luma([i * 20])).save(folder.join(format!("{i}.png"))).expect("png");
    }
    image::GrayImage::new(20, 8).save(folder.join("7.png")).expect("png");
    let o = sheen(&["import", s(&folder), "--periods", "100,10", "--shifts", "3"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(err.contains(s(&folder)) && err.contains("has 8 images but the sets need 6 (3+3)"), "{err}");
    let o = sheen(&["import", s(&folder), "--periods", "100,10", "--shifts", "4"]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(err.contains("7.png is 20x8 px, but 0.png is 16x8 px"), "{err}");
    assert!(!folder.join("fringe-set.json").exists(), "nothing is written on an error");
}

/// The fast kernel on every convention a manifest can state: either sign, any
/// start, uniform (the standard formula) or uneven (least squares), with and
/// without saturated samples (least squares on the rest).
#[test]
fn the_phase_kernel_honours_every_shift_convention() {
    use sheen::engine::phase_shift::{PhaseParams, SampleSelection, wrapped_phase};
    let (w, h) = (64usize, 8usize);
    let phi = |i: usize| TAU * (i % w) as f64 / w as f64 * 3.0 + 0.1 * (i / w) as f64;
    let mut lists: Vec<Vec<f64>> = Vec::new();
    for n in [3usize, 4, 7, 12] {
        for sign in [1.0, -1.0] {
            for start in [0.0, FRAC_PI_2, -1.0] {
                lists.push((0..n).map(|k| start + sign * TAU * k as f64 / n as f64).collect());
            }
        }
    }
    lists.push(vec![0.0, 1.1, 2.0, 3.6, 4.4, 5.5]);
    lists.push(vec![0.3, -0.9, -2.2, -3.0, -4.1]);
    for shifts in &lists {
        let n = shifts.len();
        for (amplitude, threshold) in [(20000.0, 65535u16), (30000.0, 60000u16)] {
            let stack = stack_from_fn(w, h, n, 65535, |i, k| sinusoid(35000.0, amplitude, phi(i), shifts[k]));
            let set = FringeSetInfo { period_px: 24.0, phase_shifts_rad: shifts.clone() };
            let params = PhaseParams {
                saturation_threshold: threshold,
                min_modulation_dn: 4.0,
                selection: SampleSelection::Unsaturated,
            };
            let out = wrapped_phase(&stack, &set, &params, false, &RunControl::new()).expect("phase");
            let mut checked = 0;
            for (i, &p) in out.wrapped_phase_rad.iter().enumerate() {
                if p.is_finite() {
                    checked += 1;
                    let d = phase_diff(f64::from(p), phi(i).rem_euclid(TAU)).abs();
                    assert!(d < 2e-3, "shifts {shifts:?}, threshold {threshold}: pixel {i} off by {d} rad");
                }
            }
            let saturating = threshold < 65535;
            assert!(
                checked > w * h * 3 / 4 || (saturating && n <= 4),
                "shifts {shifts:?}: only {checked} valid pixels"
            );
        }
    }
}

/// Issue 18: a rough camera-projector capture (gamma 2.2 corrected for 1.8,
/// dark exposure with a black level, 1024/256/64 x 8, the sparsest set one
/// fringe across the projector) passes `sheen check` in every set, though
/// the harmonics bias the sparsest set's estimated steps; two swapped images
/// fail it, and so does a sequence reversed in every set once the direction
/// the phase grows is given.
#[test]
fn check_passes_a_rough_capture_and_catches_swapped_and_reversed_images() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("rough");
    let sim = sheen(&[
        "simulate",
        "--scene",
        "dim-part",
        "--rig",
        "rough-scanner",
        "--width",
        "320",
        "--height",
        "240",
        "--out",
        out.to_str().expect("utf-8"),
        "-q",
    ]);
    assert!(sim.status.success(), "{}", String::from_utf8_lossy(&sim.stderr));
    let manifest = out.join("fringe-set.json");
    let check = |path: &std::path::Path, extra: &[&str]| {
        let mut args = vec!["check", "-q", path.to_str().expect("utf-8")];
        args.extend_from_slice(extra);
        sheen(&args)
    };
    let ok = check(&manifest, &["--phase-grows", "right"]);
    let table = String::from_utf8_lossy(&ok.stdout).to_string();
    assert_eq!(ok.status.code(), Some(0), "{table}{}", String::from_utf8_lossy(&ok.stderr));
    assert_eq!(table.matches(" ok\n").count(), 3, "{table}");

    let text = std::fs::read_to_string(&manifest).expect("manifest");
    let mut json: serde_json::Value = serde_json::from_str(&text).expect("json");
    let edit = |json: &serde_json::Value, name: &str, f: &dyn Fn(&mut Vec<serde_json::Value>)| {
        let mut json = json.clone();
        for set in json["sets"].as_array_mut().expect("sets") {
            f(set["images"]["left"].as_array_mut().expect("left images"));
        }
        let path = out.join(name);
        std::fs::write(&path, serde_json::to_string(&json).expect("json")).expect("write");
        path
    };
    let swapped = edit(&json, "swapped.json", &|images| images.swap(2, 3));
    let run = check(&swapped, &[]);
    assert_eq!(run.status.code(), Some(3), "{}", String::from_utf8_lossy(&run.stdout));
    assert_eq!(String::from_utf8_lossy(&run.stdout).matches("MISMATCH").count(), 3);
    let reversed = edit(&json, "reversed.json", &|images| images.reverse());
    assert_eq!(check(&reversed, &[]).status.code(), Some(0), "without a direction the common sign is free");
    let run = check(&reversed, &["--phase-grows", "right"]);
    assert_eq!(run.status.code(), Some(3), "{}", String::from_utf8_lossy(&run.stdout));
    assert_eq!(String::from_utf8_lossy(&run.stdout).matches("REVERSED").count(), 3);
    json["sets"][0]["images"]["left"].as_array_mut().expect("images").swap(5, 6);
    let one = edit(&json, "one-set.json", &|_| {});
    let run = check(&one, &[]);
    assert_eq!(run.status.code(), Some(3), "{}", String::from_utf8_lossy(&run.stdout));
    assert_eq!(String::from_utf8_lossy(&run.stdout).matches("MISMATCH").count(), 1, "only the sparsest set");
}
