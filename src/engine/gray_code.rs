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
    /// For 8-bit frames of a projector whose black is the camera's dark
    /// level: the real capture's dark frames sit near 19 DN with 5-10 DN of
    /// noise, so a lit pixel shows 10 DN over black and a bit 3 DN between
    /// its frames.
    fn default() -> Self {
        Self { min_lit_dn: 10.0, min_bit_contrast_dn: 3.0 }
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
}

/// Decodes one axis: `frames` in OpenCV order (plane 0 pattern, plane 0
/// inverse, plane 1 pattern, ...) over `cells` cells, with the `white` and
/// `black` frames, every frame `width` x `height` row-major grey levels.
pub fn decode_axis(
    frames: &[&[f32]],
    white: &[f32],
    black: &[f32],
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
    let cells_decoded = (0..pixels)
        .into_par_iter()
        .map(|i| {
            if white[i] - black[i] < params.min_lit_dn {
                return Err(GrayRefusal::Shadow);
            }
            let mut gray = 0u32;
            let mut undecided: Option<usize> = None;
            for plane in 0..planes {
                let difference = frames[2 * plane][i] - frames[2 * plane + 1][i];
                if difference.abs() < params.min_bit_contrast_dn {
                    if undecided.is_some() {
                        return Err(GrayRefusal::AmbiguousBit { plane: plane as u8 });
                    }
                    undecided = Some(plane);
                }
                gray = (gray << 1) | u32::from(difference > 0.0);
            }
            match undecided {
                None => {
                    let cell = from_gray(gray);
                    if cell as usize >= cells { Err(GrayRefusal::OutOfRange) } else { Ok(cell) }
                }
                // A bit's two frames cross where its stripe changes, and in
                // a Gray code neighbouring cells differ in that one bit: if
                // its two readings are neighbouring cells, the pixel lies on
                // their common edge. Any other pair is no reading at all.
                Some(plane) => {
                    let flipped = gray ^ (1 << (planes - 1 - plane));
                    let (a, b) = (from_gray(gray), from_gray(flipped));
                    let lower = a.min(b);
                    if a.abs_diff(b) == 1 && (lower as usize + 1) < cells {
                        Err(GrayRefusal::AtCellEdge { lower_cell: lower })
                    } else {
                        Err(GrayRefusal::AmbiguousBit { plane: plane as u8 })
                    }
                }
            }
        })
        .collect();
    Ok(GrayDecode { width, height, cells: cells_decoded })
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
        // The most significant plane's inverse given before its pattern:
        // every cell reads as another cell or beyond the code, never as itself.
        let mut swapped = frames(cells, 10);
        swapped.swap(0, 1);
        let refs: Vec<&[f32]> = swapped.iter().map(Vec::as_slice).collect();
        let d = decode_axis(&refs, &white, &vec![20.0; width], width, 1, cells, &GrayDecodeParams::default())
            .expect("decode");
        assert!(d.cells.iter().enumerate().all(|(x, c)| *c != Ok((x / 10) as u32)));
        assert!(d.cells.contains(&Err(GrayRefusal::OutOfRange)), "a 5-bit code over 20 cells has 12 spare");
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
