//! Gray-code decoding for camera–projector rigs (issue 52, first stage):
//! the projector cell each camera pixel sees, from complementary Gray code
//! frames in OpenCV's `GrayCodePattern` layout.
//!
//! The layout: per axis, `ceil(log2(cells))` bit planes, most significant
//! first, each pattern followed by its inverse; the pattern is bright where
//! that bit of the cell's Gray code `c ^ (c >> 1)` is set. Comparing a
//! pattern with its own inverse decides a bit without a global threshold
//! (Scharstein & Szeliski 2003), so a dark, glossy or unevenly lit pixel
//! decodes as well as a bright one; a bit whose two frames differ by less
//! than a stated contrast is a decoding error, not a guess. White and black
//! frames give the shadow mask: a pixel the projector does not light, or
//! lights too weakly, has no code.

/// Bit planes of a Gray code over `cells` cells (`ceil(log2(cells))`, 0 for
/// one cell).
pub fn bit_planes(cells: usize) -> usize {
    (usize::BITS - cells.saturating_sub(1).leading_zeros()) as usize
}

/// The Gray code of `value`.
pub fn to_gray(value: u32) -> u32 {
    value ^ (value >> 1)
}

/// The value whose Gray code is `gray`.
pub fn from_gray(gray: u32) -> u32 {
    let mut value = gray;
    let mut shift = gray >> 1;
    while shift != 0 {
        value ^= shift;
        shift >>= 1;
    }
    value
}

/// Whether the pattern of bit plane `plane` (0 = most significant) of a
/// code with `planes` planes is bright at cell `cell`.
pub fn pattern_is_bright(cell: u32, planes: usize, plane: usize) -> bool {
    (to_gray(cell) >> (planes - 1 - plane)) & 1 == 1
}

/// How confident a decoded bit and a lit pixel must be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrayDecodeParams {
    /// White minus black at least this (grey levels): the pixel is lit.
    pub min_lit_dn: f32,
    /// |pattern - inverse| at least this (grey levels) for every bit.
    pub min_bit_contrast_dn: f32,
}

impl Default for GrayDecodeParams {
    /// For 8-bit frames. Lit means lit enough to measure: a projector's
    /// gamma makes its fringes dimmer than its white, and on the real
    /// capture (kamino410's mugs, 0.7 DN of noise per frame measured from
    /// each Gray pattern and inverse against white and black) the pixels
    /// lit 10-20 DN over black carry fringes of a median modulation under
    /// 2 DN (0.7 DN at 10-15 DN), 88 % of them under the phase's 4 DN
    /// floor: a grazing wall, not a surface to measure. 20 DN keeps 68.6 %
    /// of that image lit, as the capture's own reference decode does (about
    /// 68 %). A bit needs 3 DN between its frames (3σ of their difference).
    fn default() -> Self {
        Self { min_lit_dn: 20.0, min_bit_contrast_dn: 3.0 }
    }
}

/// Why a pixel has no code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrayRefusal {
    /// White minus black below `min_lit_dn`: in the projector's shadow.
    Shadow,
    /// A bit's pattern and inverse closer than `min_bit_contrast_dn`;
    /// `plane` is the first such plane (0 = most significant).
    AmbiguousBit { plane: u8 },
    /// The bits decode to a cell beyond the code's `cells`.
    OutOfRange,
    /// One bit undecided, and its two readings are neighbouring cells: the
    /// pixel lies on the edge between `lower_cell` and the next one (a
    /// position, for the phase to order; no cell of its own).
    AtCellEdge { lower_cell: u32 },
}

/// One axis decoded over an image.
#[derive(Clone, Debug, PartialEq)]
pub struct GrayDecode {
    pub width: usize,
    pub height: usize,
    /// The projector cell of each pixel, or why it has none.
    pub cells: Vec<Result<u32, GrayRefusal>>,
}

impl GrayDecode {
    /// Pixels the white/black mask keeps (lit), and of those how many decoded.
    pub fn lit_and_decoded(&self) -> (usize, usize) {
        let lit = self.cells.iter().filter(|c| !matches!(c, Err(GrayRefusal::Shadow))).count();
        let decoded = self.cells.iter().filter(|c| c.is_ok()).count();
        (lit, decoded)
    }
}

/// Errors in the frames given, before any pixel is decoded.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GrayCodeError {
    #[error("a Gray code over {cells} cells needs {expected} frames (pattern and inverse per bit plane), got {found}")]
    FrameCount { cells: usize, expected: usize, found: usize },
    #[error("frame {index} has {found} pixels where the image has {expected}")]
    FrameSize { index: usize, expected: usize, found: usize },
    #[error("the {which} frame has {found} pixels where the image has {expected}")]
    ReferenceSize { which: &'static str, expected: usize, found: usize },
    #[error(
        "the white frame is darker than the black one at {share_percent:.0} % of the pixels: are they given the \
         other way round?"
    )]
    WhiteDarkerThanBlack { share_percent: f64 },
    #[error(
        "bit plane {plane} reads flipped at most pixels: its frames {pattern} and {inverse} look swapped (the \
         inverse before the pattern)"
    )]
    SwappedPlane { plane: usize, pattern: usize, inverse: usize },
}

/// Decodes one axis: `frames` in OpenCV order (plane 0 pattern, plane 0
/// inverse, plane 1 pattern, ...) over `cells` cells, with the `white` and
/// `black` frames, every frame `width` x `height` row-major grey levels (in
/// the camera's own sample type: a capture is not copied to decode it).
pub fn decode_axis<T: Copy + Into<f32> + Sync>(
    frames: &[&[T]],
    white: &[T],
    black: &[T],
    width: usize,
    height: usize,
    cells: usize,
    params: &GrayDecodeParams,
) -> Result<GrayDecode, GrayCodeError> {
    use rayon::prelude::*;
    let planes = bit_planes(cells);
    if frames.len() != 2 * planes {
        return Err(GrayCodeError::FrameCount { cells, expected: 2 * planes, found: frames.len() });
    }
    let pixels = width * height;
    if let Some((index, f)) = frames.iter().enumerate().find(|(_, f)| f.len() != pixels) {
        return Err(GrayCodeError::FrameSize { index, expected: pixels, found: f.len() });
    }
    if let Some((which, f)) = [("white", white), ("black", black)].into_iter().find(|(_, f)| f.len() != pixels) {
        return Err(GrayCodeError::ReferenceSize { which, expected: pixels, found: f.len() });
    }
    // White and black given the other way round: most pixels darker lit.
    let darker = white.par_iter().zip(black).filter(|&(&w, &b)| w.into() + params.min_lit_dn < b.into()).count();
    if darker * 2 > pixels {
        return Err(GrayCodeError::WhiteDarkerThanBlack { share_percent: 100.0 * darker as f64 / pixels as f64 });
    }
    // Per pixel: its cell or why not, and its raw Gray code (every bit read,
    // however faint; None in the shadow) for the frame-order check.
    let (cells_decoded, raw): (Vec<Result<u32, GrayRefusal>>, Vec<Option<u32>>) = (0..pixels)
        .into_par_iter()
        .map(|i| {
            if white[i].into() - black[i].into() < params.min_lit_dn {
                return (Err(GrayRefusal::Shadow), None);
            }
            let mut gray = 0u32;
            let (mut undecided, mut first_undecided) = (0usize, 0usize);
            for plane in 0..planes {
                let difference = frames[2 * plane][i].into() - frames[2 * plane + 1][i].into();
                if difference.abs() < params.min_bit_contrast_dn {
                    if undecided == 0 {
                        first_undecided = plane;
                    }
                    undecided += 1;
                }
                gray = (gray << 1) | u32::from(difference > 0.0);
            }
            let cell = match undecided {
                0 => {
                    let cell = from_gray(gray);
                    if cell as usize >= cells { Err(GrayRefusal::OutOfRange) } else { Ok(cell) }
                }
                // A bit's two frames cross where its stripe changes, and in
                // a Gray code neighbouring cells differ in that one bit: if
                // its two readings are neighbouring cells, the pixel lies on
                // their common edge. Any other pair is no reading at all.
                1 => {
                    let flipped = gray ^ (1 << (planes - 1 - first_undecided));
                    let (a, b) = (from_gray(gray), from_gray(flipped));
                    let lower = a.min(b);
                    if a.abs_diff(b) == 1 && (lower as usize + 1) < cells {
                        Err(GrayRefusal::AtCellEdge { lower_cell: lower })
                    } else {
                        Err(GrayRefusal::AmbiguousBit { plane: first_undecided as u8 })
                    }
                }
                _ => Err(GrayRefusal::AmbiguousBit { plane: first_undecided as u8 }),
            };
            (cell, Some(gray))
        })
        .unzip();
    if let Some(plane) = swapped_plane(&raw, width, height, cells) {
        return Err(GrayCodeError::SwappedPlane { plane, pattern: 2 * plane, inverse: 2 * plane + 1 });
    }
    Ok(GrayDecode { width, height, cells: cells_decoded })
}

/// The bit plane whose pattern and inverse were given the other way round,
/// where one is: its bit is then flipped at every pixel. Flipping a Gray
/// code's bit mirrors blocks of cells, so the decoded cells jump by more
/// than one between neighbours at the blocks' edges (half the cell edges
/// for the last plane), or, for the first plane, land beyond the code. A
/// plane is named when flipping it back leaves under half the jumps and
/// codes beyond the cells, and the decode had many (a tenth of the cell
/// changes between neighbours, or a twentieth of the lit pixels); a
/// surface's own outlines make far fewer.
fn swapped_plane(gray: &[Option<u32>], width: usize, height: usize, cells: usize) -> Option<usize> {
    use rayon::prelude::*;
    let planes = bit_planes(cells);
    let score = |flip: u32| -> (usize, usize) {
        let cell = |i: usize| gray[i].map(|g| from_gray(g ^ flip)).filter(|&c| (c as usize) < cells);
        // Per row: (codes beyond the cells, cell changes to the right and
        // below, of which jumps).
        let (beyond, changes, jumps) = (0..height)
            .into_par_iter()
            .map(|r| {
                let (mut beyond, mut changes, mut jumps) = (0usize, 0usize, 0usize);
                for c in 0..width {
                    let i = r * width + c;
                    beyond += usize::from(gray[i].is_some_and(|g| from_gray(g ^ flip) as usize >= cells));
                    let Some(a) = cell(i) else { continue };
                    for j in [(c + 1 < width).then(|| i + 1), (r + 1 < height).then(|| i + width)].into_iter().flatten()
                    {
                        if let Some(b) = cell(j).filter(|&b| b != a) {
                            changes += 1;
                            jumps += usize::from(a.abs_diff(b) > 1);
                        }
                    }
                }
                (beyond, changes, jumps)
            })
            .reduce(|| (0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
        (jumps + beyond, changes + gray.iter().flatten().count() / 20)
    };
    let (bad, scale) = score(0);
    if bad * 10 < scale {
        return None;
    }
    (0..planes)
        .map(|p| (p, score(1 << (planes - 1 - p)).0))
        .min_by_key(|&(_, b)| b)
        .filter(|&(_, b)| b * 2 < bad)
        .map(|(p, _)| p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OpenCV's frames of a code over `cells` cells, each cell `cell_px`
    /// projector pixels, seen 1:1 by a camera of `cells * cell_px` x 1 px,
    /// 200 DN bright and 20 DN dark.
    fn frames(cells: usize, cell_px: usize) -> Vec<Vec<f32>> {
        let planes = bit_planes(cells);
        let width = cells * cell_px;
        (0..planes)
            .flat_map(|plane| {
                let pattern: Vec<f32> = (0..width)
                    .map(|x| if pattern_is_bright((x / cell_px) as u32, planes, plane) { 200.0 } else { 20.0 })
                    .collect();
                let inverse = pattern.iter().map(|v| 220.0 - v).collect();
                [pattern, inverse]
            })
            .collect()
    }

    #[test]
    fn gray_codes_round_trip_and_neighbours_differ_in_one_bit() {
        for v in 0..5000u32 {
            assert_eq!(from_gray(to_gray(v)), v);
            assert_eq!((to_gray(v) ^ to_gray(v + 1)).count_ones(), 1);
        }
        assert_eq!(
            [bit_planes(1), bit_planes(2), bit_planes(20), bit_planes(1024), bit_planes(1920)],
            [0, 1, 5, 10, 11]
        );
    }

    #[test]
    fn a_full_opencv_code_decodes_to_every_cell() {
        // The real capture's column code: 20 cells of 100 px (5 planes,
        // 10 frames), and a code with a cell per projector column (1920).
        for (cells, cell_px) in [(20, 100), (1920, 1)] {
            let f = frames(cells, cell_px);
            assert_eq!(f.len(), 2 * bit_planes(cells));
            let width = cells * cell_px;
            let refs: Vec<&[f32]> = f.iter().map(Vec::as_slice).collect();
            let (white, black) = (vec![200.0; width], vec![20.0; width]);
            let d = decode_axis(&refs, &white, &black, width, 1, cells, &GrayDecodeParams::default()).expect("decode");
            for (x, cell) in d.cells.iter().enumerate() {
                assert_eq!(*cell, Ok((x / cell_px) as u32), "pixel {x}");
            }
            assert_eq!(d.lit_and_decoded(), (width, width));
        }
    }

    #[test]
    fn shadows_ambiguous_bits_and_swapped_frames_are_refused_not_guessed() {
        let cells = 20;
        let mut f = frames(cells, 10);
        let width = 200;
        let (white, mut black) = (vec![200.0; width], vec![20.0; width]);
        black[5] = 195.0; // in the shadow
        f[4][50] = 110.0;
        f[5][50] = 111.0; // plane 2 undecidable at pixel 50
        let refs: Vec<&[f32]> = f.iter().map(Vec::as_slice).collect();
        let d = decode_axis(&refs, &white, &black, width, 1, cells, &GrayDecodeParams::default()).expect("decode");
        assert_eq!(d.cells[5], Err(GrayRefusal::Shadow));
        assert_eq!(d.cells[50], Err(GrayRefusal::AmbiguousBit { plane: 2 }));
        assert_eq!(d.lit_and_decoded(), (width - 1, width - 2));
        // A plane's inverse given before its pattern: named, not decoded
        // into wrong cells (the first plane mirrors the code beyond its 20
        // cells, the others mirror blocks of cells).
        for plane in 0..bit_planes(cells) {
            let mut swapped = frames(cells, 10);
            swapped.swap(2 * plane, 2 * plane + 1);
            let refs: Vec<&[f32]> = swapped.iter().map(Vec::as_slice).collect();
            let e = decode_axis(&refs, &white, &vec![20.0; width], width, 1, cells, &GrayDecodeParams::default())
                .unwrap_err();
            assert_eq!(e, GrayCodeError::SwappedPlane { plane, pattern: 2 * plane, inverse: 2 * plane + 1 });
            assert!(e.to_string().contains("look swapped"), "{e}");
        }
        // White and black the other way round.
        let refs: Vec<&[f32]> = f.iter().map(Vec::as_slice).collect();
        let e =
            decode_axis(&refs, &vec![20.0; width], &white, width, 1, cells, &GrayDecodeParams::default()).unwrap_err();
        assert!(matches!(e, GrayCodeError::WhiteDarkerThanBlack { .. }), "{e}");
    }

    #[test]
    fn missing_or_mismatched_frames_are_named() {
        let f = frames(20, 10);
        let refs: Vec<&[f32]> = f.iter().take(9).map(Vec::as_slice).collect();
        let (white, black) = (vec![200.0; 200], vec![20.0; 200]);
        let e = decode_axis(&refs, &white, &black, 200, 1, 20, &GrayDecodeParams::default()).unwrap_err();
        assert_eq!(e, GrayCodeError::FrameCount { cells: 20, expected: 10, found: 9 });
        assert!(e.to_string().contains("needs 10 frames"));
        let short = vec![0.0; 100];
        let mut refs: Vec<&[f32]> = f.iter().map(Vec::as_slice).collect();
        refs[3] = &short;
        let e = decode_axis(&refs, &white, &black, 200, 1, 20, &GrayDecodeParams::default()).unwrap_err();
        assert_eq!(e, GrayCodeError::FrameSize { index: 3, expected: 200, found: 100 });
    }
}
