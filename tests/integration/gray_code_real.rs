//! Issue 52's first stage on the real camera–projector capture
//! (`../shared/data/real-mugs-3step-graycode`, kamino410/phase-shifting,
//! MIT): its Gray code frames in OpenCV's layout decode to the projector
//! cell of most lit pixels. The capture is 24 MB and lives beside the
//! repository, not in it: the test says so and passes where it is absent,
//! unless SHEEN_REQUIRE_REAL_DATA is set.

use std::path::PathBuf;

use sheen::engine::gray_code::{GrayDecodeParams, GrayRefusal, decode_axis};

fn capture() -> Option<PathBuf> {
    let dir = std::env::var_os("SHEEN_REAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"))
        .join("real-mugs-3step-graycode/images");
    if dir.join("pat31.png").exists() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("SHEEN_REQUIRE_REAL_DATA").is_none(),
        "SHEEN_REQUIRE_REAL_DATA is set but {} has no capture",
        dir.display()
    );
    eprintln!("{} not found: the real capture's Gray code is not decoded", dir.display());
    None
}

fn grey(dir: &std::path::Path, index: usize) -> (Vec<f32>, usize, usize) {
    let path = dir.join(format!("pat{index:02}.png"));
    let image = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
    let (w, h) = image.dimensions();
    (image.into_raw().into_iter().map(f32::from).collect(), w as usize, h as usize)
}

#[test]
fn the_real_captures_gray_code_decodes_most_lit_pixels_without_jumps() {
    let Some(dir) = capture() else { return };
    let (white, width, height) = grey(&dir, 30);
    let (black, ..) = grey(&dir, 31);
    // Columns: 20 cells of 100 projector px (pat12-pat21); rows: 11 cells
    // (pat22-pat29); README of the capture.
    for (first, cells, axis) in [(12usize, 20usize, "x"), (22, 11, "y")] {
        let frames: Vec<Vec<f32>> =
            (first..first + 2 * sheen::engine::gray_code::bit_planes(cells)).map(|i| grey(&dir, i).0).collect();
        let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
        let d = decode_axis(&refs, &white, &black, width, height, cells, &GrayDecodeParams::default()).expect("decode");
        let (lit, decoded) = d.lit_and_decoded();
        let share = decoded as f64 / lit as f64;
        let out_of_range = d.cells.iter().filter(|c| **c == Err(GrayRefusal::OutOfRange)).count();
        eprintln!(
            "{axis}: {lit} lit pixels ({:.1} % of the image), {decoded} decoded ({:.1} %), {out_of_range} beyond the code",
            100.0 * lit as f64 / (width * height) as f64,
            100.0 * share
        );
        assert!(share >= 0.85, "{axis}: {:.1} % of the lit pixels decoded", 100.0 * share);
        assert!((out_of_range as f64) < 0.005 * lit as f64, "{axis}: {out_of_range} pixels beyond the code");
        // A decoding error flips a bit and lands many cells away; the
        // surface moves the cell by at most one between neighbouring pixels
        // (a 100 px cell spans about 100 camera px) except across the mugs'
        // outlines. So nearly every pair of decoded neighbours along the
        // axis differs by at most one cell, and the cells span the code.
        let step = if axis == "x" { 1 } else { width };
        let (mut pairs, mut smooth) = (0usize, 0usize);
        for i in 0..width * height - step {
            if axis == "x" && (i + 1) % width == 0 {
                continue;
            }
            if let (Ok(a), Ok(b)) = (d.cells[i], d.cells[i + step]) {
                pairs += 1;
                smooth += usize::from(a.abs_diff(b) <= 1);
            }
        }
        let smooth_share = smooth as f64 / pairs as f64;
        eprintln!("{axis}: {:.3} % of {pairs} decoded neighbour pairs within one cell", 100.0 * smooth_share);
        assert!(smooth_share > 0.995, "{axis}: {:.3} % of neighbours within one cell", 100.0 * smooth_share);
        let (lo, hi) = d.cells.iter().flatten().fold((u32::MAX, 0), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        assert!(hi - lo + 1 >= cells as u32 * 2 / 3, "{axis}: cells {lo}..={hi} of {cells}");
        // The same frames with one plane's inverse before its pattern are
        // named as such, on real data too.
        let mut swapped = refs.clone();
        swapped.swap(4, 5);
        let e = decode_axis(&swapped, &white, &black, width, height, cells, &GrayDecodeParams::default()).unwrap_err();
        assert_eq!(e, sheen::engine::gray_code::GrayCodeError::SwappedPlane { plane: 2, pattern: 4, inverse: 5 });
    }
}

/// The modulation floor the README's command gives `sheen phase` for this
/// capture: five times its camera's noise (0.7 DN per frame, measured from
/// each Gray pattern and inverse against white and black). Sheen's default
/// floor, 4 DN, leaves 84.6 % (x) and 87.0 % (y).
const CAPTURE_FLOOR_DN: f32 = 3.5;

/// The scanner's own result (`vizualized.png`, written by kamino410's
/// decoder: blue = projector x, green = projector y, both modulo 256; red
/// 128 where it decoded). Per axis: how many of `coordinate_px` it also
/// decoded, their median difference (px), and how many differ by more than
/// 25 px (a period of either set is 67 or 100 px, a beat 200 px).
fn against_the_scanner(dir: &std::path::Path, coordinate_px: &[f32], axis: &str) -> (usize, f32, usize) {
    let path = dir.join("vizualized.png");
    let viz = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgb8();
    let channel = if axis == "x" { 2 } else { 1 };
    let mut differences: Vec<f32> = coordinate_px
        .iter()
        .zip(viz.pixels())
        .filter(|(x, p)| !x.is_nan() && p[0] == 128)
        .map(|(x, p)| (x - f32::from(p[channel]) + 128.0).rem_euclid(256.0) - 128.0)
        .collect();
    differences.sort_by(f32::total_cmp);
    let far = differences.iter().filter(|d| d.abs() > 25.0).count();
    (differences.len(), differences[differences.len() / 2], far)
}

/// The absolute projector x and y of the real capture (issue 52): the Gray
/// code orders the beat of the 200/3 px and 100 px sets (200 px), the beat
/// orders each set. At least 85 % of the pixels the white/black mask keeps
/// get a coordinate, and none is a whole period off: where its 24
/// neighbours in 5 x 5 lie on a smooth surface (within 40 projector px of
/// each other: a surface moves the coordinate by about a pixel per camera
/// pixel), the pixel does not stand out from their median by a third of
/// the short period or more; and against the scanner's own result, which
/// a region a period off would contradict however smooth it is inside.
#[test]
fn the_real_captures_projector_coordinates_are_absolute_and_complete() {
    use sheen::engine::control::RunControl;
    use sheen::engine::fringe::{FringeSetInfo, FringeStack};
    use sheen::engine::phase_shift::{PhaseParams, SampleSelection, wrapped_phase};
    use sheen::engine::projector_coordinate::{AbsoluteParams, SetPhase, absolute_coordinate};
    let Some(dir) = capture() else { return };
    let (white, width, height) = grey(&dir, 30);
    let (black, ..) = grey(&dir, 31);
    let shifts = vec![-std::f64::consts::TAU / 3.0, 0.0, std::f64::consts::TAU / 3.0];
    let phase = |first: usize, period_px: f64, floor_dn: f32| {
        let params = PhaseParams {
            saturation_threshold: 255,
            min_modulation_dn: floor_dn,
            selection: SampleSelection::Unsaturated,
        };
        let planes: Vec<Vec<u8>> = (first..first + 3)
            .map(|i| {
                let path = dir.join(format!("pat{i:02}.png"));
                image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8().into_raw()
            })
            .collect();
        let stack = FringeStack::from_planes_u8(width, height, planes);
        let set = FringeSetInfo { period_px, phase_shifts_rad: shifts.clone() };
        wrapped_phase(&stack, &set, &params, false, &RunControl::new()).expect("not cancelled")
    };
    // (sets' first frames, Gray frames' first, cells, axis)
    for (sets, gray_first, cells, axis) in [([0usize, 3], 12usize, 20usize, "x"), ([6, 9], 22, 11, "y")] {
        let frames: Vec<Vec<f32>> = (gray_first..gray_first + 2 * sheen::engine::gray_code::bit_planes(cells))
            .map(|i| grey(&dir, i).0)
            .collect();
        let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
        let code =
            decode_axis(&refs, &white, &black, width, height, cells, &GrayDecodeParams::default()).expect("code");
        // Sheen's default floor: what the README says it leaves (84.6 %, 87.0 %).
        let default_floor = sheen::engine::pipeline::Params::default().min_modulation_dn;
        let (short, long) = (phase(sets[0], 200.0 / 3.0, default_floor), phase(sets[1], 100.0, default_floor));
        let set_phases = [SetPhase::of(&short), SetPhase::of(&long)];
        let p = absolute_coordinate(&code, 100.0, &set_phases, &AbsoluteParams::default()).expect("coordinates");
        let (lit, measured) = p.lit_and_measured();
        let at_default = measured as f64 / lit as f64;
        eprintln!("{axis}: {:.1} % of the lit pixels at the default {default_floor} DN floor", 100.0 * at_default);
        assert!(at_default >= if axis == "x" { 0.845 } else { 0.865 }, "{axis}: {at_default}");
        let (short, long) = (phase(sets[0], 200.0 / 3.0, CAPTURE_FLOOR_DN), phase(sets[1], 100.0, CAPTURE_FLOOR_DN));
        let set_phases = [SetPhase::of(&short), SetPhase::of(&long)];
        let p = absolute_coordinate(&code, 100.0, &set_phases, &AbsoluteParams::default()).expect("coordinates");
        let (lit, measured) = p.lit_and_measured();
        let share = measured as f64 / lit as f64;
        eprintln!(
            "{axis}: {measured} of {lit} lit pixels have a coordinate ({:.1} %); refused: {:?}",
            100.0 * share,
            p.refusal_counts()
        );
        // Issue 52 asks for 85 %: 85.6 % (x) and 88.6 % (y). What is left
        // is mostly the grazing side wall, whose fringes are too faint.
        assert!(share >= 0.85, "{axis}: {:.1} % of the lit pixels", 100.0 * share);
        // The scanner decoded without any check; where both decoded, Sheen
        // agrees with it to a fraction of a pixel, and where they differ
        // by a period (0.14 % of x, 0.03 % of y) the scanner's neighbours
        // side with Sheen about as often as with the scanner. A region a
        // period off (a cell margin of 30 px lets one through on the wall:
        // 0.37 %) fails here.
        let (compared, median, far) = against_the_scanner(&dir, &p.coordinate_px, axis);
        eprintln!("{axis}: against the scanner's result: {compared} pixels, median {median:.2} px, {far} beyond 25 px");
        assert!(compared as f64 > 0.95 * measured as f64, "{axis}: {compared} of {measured} compared");
        assert!(median.abs() < 1.0, "{axis}: median difference {median} px");
        assert!((far as f64) < 0.002 * compared as f64, "{axis}: {far} of {compared} differ by more than 25 px");
        // The capture's projector gamma was not fully corrected (its
        // README): the two 3-step sets disagree by about 5 px RMS, far
        // beyond their noise. Sheen fits their harmonic ripple from that
        // disagreement, takes it out (they then agree to 1.4 px RMS against
        // 0.8 px of noise) and says so.
        let agreement = p.set_agreement.expect("two sets");
        let ripple = p.ripple.expect("a ripple fitted");
        eprintln!("{axis}: {agreement:?}, peak {:.2} px", ripple.peak_px());
        assert!(ripple.rms_before_px > 4.0, "{ripple:?}");
        assert!(agreement.rms_px < 1.6 && agreement.rms_px < 2.0 * agreement.expected_rms_px, "{agreement:?}");
        let warnings = p.ripple_warnings(axis);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        eprintln!("{axis}: {}", warnings[0]);
        assert!(warnings[0].message.contains("was taken out"), "{}", warnings[0]);
        let (mut checked, mut off) = (0usize, 0usize);
        for r in 2..height - 2 {
            for c in 2..width - 2 {
                let x = p.coordinate_px[r * width + c];
                if x.is_nan() {
                    continue;
                }
                let mut around: Vec<f32> = (0..25)
                    .filter(|&k| k != 12)
                    .map(|k| p.coordinate_px[(r + k / 5 - 2) * width + c + k % 5 - 2])
                    .filter(|v| !v.is_nan())
                    .collect();
                around.sort_by(f32::total_cmp);
                // A smooth surface around it (not a mug's outline, where the
                // background lies hundreds of projector pixels away).
                if around.len() < 24 || around[23] - around[0] > 40.0 {
                    continue;
                }
                checked += 1;
                let median = 0.5 * (around[11] + around[12]);
                if (x - median).abs() >= 200.0 / 9.0 {
                    off += 1;
                    eprintln!(
                        "{axis}: ({c}, {r}) at {x:.1} px, its neighbours {median:.1} ({:.1}..{:.1})",
                        around[0], around[23]
                    );
                }
            }
        }
        eprintln!("{axis}: {off} of {checked} pixels on a smooth surface stand out by 22 px or more");
        assert!(checked as f64 > 0.5 * measured as f64, "{axis}: {checked} checked of {measured}");
        assert_eq!(off, 0, "{axis}: pixels a period off");
        // The coordinates span the projector's code.
        let (lo, hi) =
            p.coordinate_px.iter().filter(|v| !v.is_nan()).fold((f32::MAX, f32::MIN), |a, &v| (a.0.min(v), a.1.max(v)));
        eprintln!("{axis}: {lo:.0}..{hi:.0} projector px");
        assert!(f64::from(hi - lo) > 100.0 * cells as f64 * 2.0 / 3.0);
    }
}

/// The real capture imports with the README's one command (on a copy: the
/// manifest is written beside the images) and `sheen phase --maps` writes
/// its projector x and y maps, as complete as the engine gives them, with
/// the ripple of its uncorrected gamma reported.
#[test]
fn the_real_capture_imports_with_one_command_and_phase_writes_its_projector_maps() {
    let Some(dir) = capture() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let images = tmp.path().join("images");
    std::fs::create_dir(&images).unwrap();
    for i in 0..32 {
        let name = format!("pat{i:02}.png");
        std::fs::copy(dir.join(&name), images.join(&name)).unwrap();
    }
    let run = |args: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_sheen")).args(args).output().expect("run sheen");
        let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "{args:?}: {text}");
        text
    };
    // As README.md "Camera–projector rigs" writes it.
    run(&[
        "import",
        images.to_str().expect("utf8 path"),
        "--pattern",
        "pat{index:02}.png",
        "--periods",
        "66.666667,100,66.666667,100",
        "--axes",
        "x,x,y,y",
        "--shifts",
        "3",
        "--shift-offset=-2.0943951023931953",
        "--projector",
        "1920x1080",
        "--gray-code",
        "100",
    ]);
    let manifest = images.join("fringe-set.json");
    let checked = run(&["check", manifest.to_str().expect("utf8 path"), "-q"]);
    assert!(checked.contains("camera Gray code x (columns): 1487208 of 1615291 lit pixels decoded"), "{checked}");
    let maps = tmp.path().join("maps");
    let floor = CAPTURE_FLOOR_DN.to_string();
    let out = run(&[
        "phase",
        manifest.to_str().expect("utf8 path"),
        "--maps",
        maps.to_str().expect("utf8 path"),
        "--min-modulation",
        &floor,
    ]);
    assert!(out.contains("projector x: the phase sets rippled by up to") && out.contains("was taken out"), "{out}");
    // The summary gives what this rig measures, not its x sets' fused phase.
    assert!(out.contains("phase maps of 1 camera(s) (camera projector x 85.6 %, y 88.6 % of the lit pixels;"), "{out}");
    for (axis, at_least) in [("x", 0.85), ("y", 0.85)] {
        let map = sheen::io::maps::read_f32_tiff(&maps.join(format!("camera_projector_{axis}.tif"))).unwrap();
        let cells = sheen::io::maps::read_f32_tiff(&maps.join(format!("camera_gray_code_{axis}.tif"))).unwrap();
        let measured = map.data.iter().filter(|v| !v.is_nan()).count();
        // Every coordinate lies in (or within the margin of) its cell.
        let decoded_with_coordinate = map
            .data
            .iter()
            .zip(&cells.data)
            .filter(|(v, c)| !v.is_nan() && !c.is_nan())
            .filter(|(v, c)| (-0.2..1.2).contains(&(**v / 100.0 - **c)))
            .count();
        assert!(decoded_with_coordinate as f64 > 0.99 * measured as f64, "{axis}");
        let line = out.lines().find(|l| l.starts_with(&format!("sheen: camera projector {axis}:"))).expect("a line");
        eprintln!("{line}");
        let lit: f64 = line.split(" of ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
        assert!(measured as f64 >= at_least * lit, "{axis}: {measured} of {lit}");
    }
}
