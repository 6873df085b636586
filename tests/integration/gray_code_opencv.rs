//! Issue 52: Sheen's Gray decoding is OpenCV's on a full code. The frames
//! in `tests/data/opencv-gray-code` are OpenCV's own `GrayCodePattern` of a
//! 1920 x 1080 projector with a code per column and row (44 frames, its
//! order), seen by a 320 x 240 camera through a perspective warp with blur,
//! gain and black level; `opencv_x.png` / `opencv_y.png` are what OpenCV's
//! own decoder found in every camera pixel (`make_fixture.py` beside them).

use std::path::{Path, PathBuf};

use sheen::engine::gray_code::{GrayDecodeParams, GrayRefusal, bit_planes, decode_axis};

const WIDTH: usize = 320;
const HEIGHT: usize = 240;
/// OpenCV's decoder found no code here.
const NONE: u16 = u16::MAX;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/opencv-gray-code")
}

fn grey(path: &Path) -> Vec<f32> {
    let image = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
    assert_eq!(image.dimensions(), (WIDTH as u32, HEIGHT as u32), "{}", path.display());
    image.into_raw().into_iter().map(f32::from).collect()
}

/// The projector pixel (x, y) a camera pixel's centre sees.
fn truth() -> impl Fn(usize) -> [f64; 2] {
    let path = fixture().join("camera_to_projector.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let json: serde_json::Value = serde_json::from_str(&text).expect("json");
    let m: Vec<Vec<f64>> = serde_json::from_value(json["camera_to_projector"].clone()).expect("3 x 3");
    move |i| {
        let (u, v) = ((i % WIDTH) as f64, (i / WIDTH) as f64);
        let w = m[2][0] * u + m[2][1] * v + m[2][2];
        [(m[0][0] * u + m[0][1] * v + m[0][2]) / w, (m[1][0] * u + m[1][1] * v + m[1][2]) / w]
    }
}

fn opencv(axis: &str) -> Vec<u16> {
    let path = fixture().join(format!("opencv_{axis}.png"));
    let image = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma16();
    image.into_raw()
}

#[test]
fn a_full_opencv_gray_code_decodes_to_the_projector_column_and_row_opencv_finds() {
    let dir = fixture();
    let white = grey(&dir.join("white.png"));
    let black = grey(&dir.join("black.png"));
    // OpenCV's order: the column planes (pattern, inverse), then the rows'.
    let frames: Vec<Vec<f32>> = (0..44).map(|i| grey(&dir.join(format!("cap{i:02}.png")))).collect();
    let seen = truth();
    let columns = bit_planes(1920);
    assert_eq!(2 * (columns + bit_planes(1080)), frames.len());
    for (k, axis, cells, range) in [(0, "x", 1920, 0..2 * columns), (1, "y", 1080, 2 * columns..frames.len())] {
        let refs: Vec<&[f32]> = frames[range].iter().map(Vec::as_slice).collect();
        let ours = decode_axis(&refs, &white, &black, WIDTH, HEIGHT, cells, &GrayDecodeParams::default())
            .unwrap_or_else(|e| panic!("{axis}: {e}"));
        let theirs = opencv(axis);
        let (mut both, mut only_opencv, mut only_sheen, mut at_edge) = (0usize, 0usize, 0usize, 0usize);
        for (i, (mine, &found)) in ours.cells.iter().zip(&theirs).enumerate() {
            match (mine, found) {
                // OpenCV reads both axes at once and gives up on a pixel
                // whose other axis has an undecided bit (or a bit within
                // its 5 DN where Sheen's 3 DN decides).
                (Ok(c), NONE) => {
                    let t = seen(i)[k];
                    assert!((f64::from(*c) - t).abs() <= 0.5 + 1e-6, "{axis}: pixel {i} decoded to {c}, seeing {t:.2}");
                    only_sheen += 1;
                }
                (Ok(c), found) => {
                    assert_eq!(*c, u32::from(found), "{axis}: pixel ({}, {})", i % WIDTH, i / WIDTH);
                    both += 1;
                }
                // One bit between its frames: a position on the edge of two
                // neighbouring columns, one of which OpenCV picked.
                (Err(GrayRefusal::AtCellEdge { lower_cell }), found) if found != NONE => {
                    assert!(
                        [*lower_cell, lower_cell + 1].contains(&u32::from(found)),
                        "{axis}: pixel {i} on the edge above {lower_cell}, OpenCV {found}"
                    );
                    at_edge += 1;
                }
                (Err(_), NONE) => {}
                (Err(_), _) => only_opencv += 1,
            }
        }
        let opencv_decoded = theirs.iter().filter(|&&v| v != NONE).count();
        eprintln!(
            "{axis}: OpenCV decoded {opencv_decoded} of {} pixels; Sheen the same column in {both}, \
             on the edge of its column in {at_edge}, refused {only_opencv}; Sheen alone {only_sheen}",
            WIDTH * HEIGHT
        );
        // Sheen finds OpenCV's column wherever OpenCV found one (a pixel
        // the blur leaves between a bit's two frames may be refused, or
        // placed on the edge, where OpenCV's threshold picks a side).
        assert!(opencv_decoded > WIDTH * HEIGHT * 9 / 10, "{axis}: {opencv_decoded}");
        assert!(both as f64 > 0.99 * opencv_decoded as f64, "{axis}: {both} of {opencv_decoded}");
        let distinct: std::collections::BTreeSet<u32> = ours.cells.iter().flatten().copied().collect();
        let expected_span = if axis == "x" { 150 } else { 110 };
        assert!(distinct.len() >= expected_span, "{axis}: {} distinct columns", distinct.len());
    }
}
