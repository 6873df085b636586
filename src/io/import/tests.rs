//! Unit tests of the folder import: natural order, globs, patterns, the three namings, errors.

use super::*;

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn spec(periods: &[f64], shifts: &[usize], pattern: Option<&str>) -> ImportSpec {
    ImportSpec {
        periods_px: periods.to_vec(),
        shifts: shifts.to_vec(),
        pattern: pattern.map(str::to_string),
        ..ImportSpec::default()
    }
}

#[test]
fn natural_order_reads_numbers_as_numbers() {
    let mut v = names(&["10.bmp", "2.bmp", "1.bmp", "img_20.png", "img_3.png", "Img_4.png"]);
    v.sort_by(|a, b| natural_cmp(a, b));
    assert_eq!(v, names(&["1.bmp", "2.bmp", "10.bmp", "img_3.png", "Img_4.png", "img_20.png"]));
    assert_eq!(natural_cmp("a01", "a1"), Ordering::Greater, "ties are broken, never equal for different names");
}

#[test]
fn globs_match_names_and_paths() {
    let g = |text: &str| SkipGlob::new(text).expect("a glob");
    assert!(g("gray_*").matches("gray_07.bmp"));
    assert!(g("*/gray_??.bmp").matches("left/gray_07.bmp"));
    assert!(!g("gray_?.bmp").matches("gray_07.bmp"));
    assert!(g("gray_*").matches("left/gray_07.bmp"), "a glob without '/' matches the file name");
    assert!(!g("gray_*").matches("left/fringe_07.bmp"));
    // Character classes, as a shell writes them.
    let class = g("pat0[6-9].png");
    assert!(class.matches("pat06.png") && class.matches("pat09.png") && !class.matches("pat05.png"));
    assert!(g("pat0[!0-5].png").matches("pat07.png") && !g("pat0[!0-5].png").matches("pat03.png"));
    match SkipGlob::new("pat0[6-9.png") {
        Err(ImportFault::BadSkip { glob, .. }) => assert_eq!(glob, "pat0[6-9.png"),
        other => panic!("an unclosed class is refused: {other:?}"),
    }
}

/// The real capture in shared/data holds its denser set first (pat00-02
/// period 66.67, pat03-05 period 100) and Gray-code images after.
#[test]
fn periods_in_the_files_order_are_sorted_sparsest_first_and_class_skips_work() {
    let files: Vec<String> = (0..10).map(|i| format!("pat{i:02}.png")).collect();
    let mut s = spec(&[66.6667, 100.0], &[3], Some("pat{index:02}.png"));
    s.skip = names(&["pat0[6-9].png"]);
    let a = assign(&files, &s).expect("assignment");
    assert_eq!(a.sets.iter().map(|s| s.period_px).collect::<Vec<_>>(), vec![100.0, 66.6667]);
    let cam = DEFAULT_CAMERA;
    assert_eq!(a.sets[0].files[cam], names(&["pat03.png", "pat04.png", "pat05.png"]), "period 100 is pat03-05");
    assert_eq!(a.sets[1].files[cam], names(&["pat00.png", "pat01.png", "pat02.png"]), "period 66.67 is pat00-02");
    assert_eq!(a.skipped.len(), 4);
    assert!(a.notes.iter().any(|n| n.contains("sparsest first")), "{:?}", a.notes);
    // Repeated periods are still refused; a glob that leaves nothing out is told.
    let e = assign(&files, &spec(&[100.0, 100.0], &[3], Some("pat{index:02}.png"))).expect_err("repeat");
    assert!(matches!(e, ImportFault::PeriodOrder { .. }), "{e}");
    s.skip = names(&["pat0[6-9].png", "gray_*"]);
    let a = assign(&files, &s).expect("assignment");
    assert!(a.notes.iter().any(|n| n.contains("--skip 'gray_*' matches no image file")), "{:?}", a.notes);
    // Sets already sparsest first are left alone, without a note.
    let mut s = spec(&[100.0, 66.6667], &[3], Some("pat{index:02}.png"));
    s.skip = names(&["pat0[6-9].png"]);
    let a = assign(&files, &s).expect("assignment");
    assert!(a.notes.iter().all(|n| !n.contains("sparsest first")), "{:?}", a.notes);
}

#[test]
fn patterns_are_checked_when_parsed() {
    for (bad, says) in [
        ("{camera}_{idx}.bmp", "unknown placeholder"),
        ("{camera}_{shift}.bmp", "needs {index}"),
        ("{camera}_{index}_{shift}.bmp", "either with {index}"),
        ("{camera}{index}.bmp", "two placeholders touch"),
        ("{camera_{index}.bmp", "unknown placeholder"),
        ("{index}_{index}.bmp", "appears twice"),
    ] {
        let e = Pattern::parse(bad).expect_err(bad).to_string();
        assert!(e.contains(says), "{bad}: {e}");
    }
    Pattern::parse("{camera}/p{period}_{shift:02}.png").expect("good pattern");
    Pattern::parse("cam{camera}_{index}.bmp").expect("good pattern");
}

#[test]
fn index_numbering_counts_through_the_sets_sparsest_first() {
    // Two cameras, numbered 1..9 without padding, sets of 3 + 3 + 3.
    let mut files = Vec::new();
    for cam in ["L", "R"] {
        for i in 1..=9 {
            files.push(format!("cam{cam}_{i}.bmp"));
        }
    }
    files.push("camL_gray_1.bmp".into());
    files.push("notes.txt".into());
    let mut s = spec(&[100.0, 20.0, 5.0], &[3], Some("cam{camera}_{index}.bmp"));
    s.cameras = parse_cameras("left=L,right=R").expect("cameras");
    let a = assign(&names(&files.iter().map(String::as_str).collect::<Vec<_>>()), &s).expect("assignment");
    assert_eq!(a.cameras, names(&["left", "right"]));
    assert_eq!(a.sets[0].files["left"], names(&["camL_1.bmp", "camL_2.bmp", "camL_3.bmp"]));
    assert_eq!(a.sets[2].files["right"], names(&["camR_7.bmp", "camR_8.bmp", "camR_9.bmp"]), "9 after 7, not 10");
    assert_eq!(a.ignored.len(), 1, "the Gray-code image does not match: {:?}", a.ignored);
    assert_eq!(a.rows().len(), 18);
    assert_eq!(
        a.rows()[4],
        AssignmentRow { camera: "left".into(), set: 1, period_px: 20.0, shift: 1, file: "camL_5.bmp".into() }
    );
}

#[test]
fn period_and_shift_placeholders_infer_periods_and_counts() {
    let mut files = Vec::new();
    for cam in ["left", "right"] {
        for (p, n) in [(912, 4), (144, 4), (12, 3)] {
            for k in 0..n {
                files.push(format!("{cam}/p{p:04}_{k:02}.png"));
            }
        }
    }
    let s = spec(&[], &[], Some("{camera}/p{period}_{shift:02}.png"));
    let a = assign(&files, &s).expect("assignment");
    assert_eq!(a.sets.iter().map(|s| s.period_px).collect::<Vec<_>>(), vec![912.0, 144.0, 12.0]);
    assert_eq!(a.sets.iter().map(|s| s.shifts).collect::<Vec<_>>(), vec![4, 4, 3]);
    assert_eq!(a.sets[1].files["right"][3], "right/p0144_03.png");
    // Declared counts are enforced.
    let s = spec(&[912.0, 144.0, 12.0], &[4], Some("{camera}/p{period}_{shift:02}.png"));
    let e = assign(&files, &s).expect_err("set 2 has 3").to_string();
    assert!(e.contains("camera 'left' set 2 (period 12 px) has 3 images but the sets need 4"), "{e}");
}

#[test]
fn folders_are_cameras_in_natural_order_and_skips_apply() {
    let mut files = Vec::new();
    for cam in ["left", "right"] {
        for i in 1..=8 {
            files.push(format!("{cam}/{i}.bmp"));
        }
        files.push(format!("{cam}/gray_1.bmp"));
    }
    files.push("fringe-set.json".into());
    let mut s = spec(&[50.0, 10.0], &[4], None);
    let e = assign(&files, &s).expect_err("gray images counted").to_string();
    assert!(e.contains("camera 'left' (folder left/) has 9 images but the sets need 8 (4+4)"), "{e}");
    assert!(e.contains("--skip"), "{e}");
    s.skip = names(&["gray_*"]);
    let a = assign(&files, &s).expect("assignment");
    assert_eq!(a.skipped.len(), 2);
    assert_eq!(a.sets[1].files["left"], names(&["left/5.bmp", "left/6.bmp", "left/7.bmp", "left/8.bmp"]));
    // One camera: images in the folder itself.
    let one: Vec<String> = (1..=6).map(|i| format!("{i}.tif")).collect();
    let a = assign(&one, &spec(&[30.0, 6.0], &[3], None)).expect("one camera");
    assert_eq!(a.cameras, names(&[DEFAULT_CAMERA]));
}

#[test]
fn gaps_and_repeats_are_named() {
    let files = names(&["a_0.png", "a_1.png", "a_3.png", "a_4.png"]);
    let e = assign(&files, &spec(&[10.0], &[4], Some("a_{index}.png"))).expect_err("gap").to_string();
    assert!(e.contains("image number 2 is missing") && e.contains("after a_1.png"), "{e}");
    let files = names(&["a_1.png", "a_01.png", "a_2.png"]);
    let e = assign(&files, &spec(&[10.0], &[3], Some("a_{index}.png"))).expect_err("repeat").to_string();
    assert!(e.contains("a_01.png and a_1.png both give 1") || e.contains("a_1.png and a_01.png both give 1"), "{e}");
}

#[test]
fn shift_sign_and_offset_write_the_list() {
    let s = ImportSpec { shift_sign: -1.0, shift_offset_rad: std::f64::consts::FRAC_PI_2, ..ImportSpec::default() };
    let list = s.phase_shifts_rad(4).expect("a list");
    let expected = [0.5, 0.0, -0.5, -1.0].map(|x| x * std::f64::consts::PI);
    for (a, b) in list.iter().zip(expected) {
        assert!((a - b).abs() < 1e-12, "{list:?}");
    }
    assert_eq!(ImportSpec::default().phase_shifts_rad(4), None);
}
