//! Sub-pixel detection of a grid of filled circles (dots).
//!
//! Otsu's threshold separates dots from the plate; each 8-connected blob that
//! does not touch the image border is measured by grey-level-weighted moments:
//! with the plate level `b` (median of a ring around the blob) and the dot
//! level `f` (median of its eroded interior), the weight of a pixel near the
//! blob is its dot coverage `w = clamp((I - b) / (f - b), 0, 1)`, and the
//! centre is `sum(w p) / sum(w)`. For an anti-aliased dot this is the centroid
//! of the dot's area, and under an affine (telecentric) projection the centroid
//! of the imaged ellipse is exactly the image of the circle's centre, unlike
//! with pinhole cameras. The second moments give the ellipse, whose area-to-
//! moment ratio rejects blobs that are not ellipses; since an affine camera
//! images every dot as the same ellipse, blobs whose area differs from the
//! main group are clutter or partly hidden dots. The rest is ordered by
//! [`super::grid::order_grid`].

use super::detect::{DetectionError, TargetDetection};
use super::gray_image::{GrayImage, connected_components, median_f32, otsu_threshold_dn};
use super::grid::order_grid;
use super::target::Target;

/// Tuning of the dot detector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CircleDetectionParams {
    /// Blobs smaller than this are noise.
    pub min_area_px: usize,
    /// Pixels up to this far (chessboard distance) outside the thresholded
    /// blob carry partial coverage and take part in the moments.
    pub margin_px: usize,
    /// Width of the ring beyond the margin that gives the plate level.
    pub ring_px: usize,
    /// Dot-to-plate contrast below this share of the image's grey range is no dot.
    pub min_contrast_fraction: f32,
    /// Accepted ratio of a blob's area to the area of the ellipse of its moments.
    pub ellipse_fill: (f64, f64),
    /// Dots whose area differs from the median dot by more than this share are left out.
    pub area_tolerance: f64,
}

impl Default for CircleDetectionParams {
    fn default() -> Self {
        Self {
            min_area_px: 9,
            margin_px: 2,
            ring_px: 2,
            min_contrast_fraction: 0.1,
            ellipse_fill: (0.8, 1.2),
            area_tolerance: 0.25,
        }
    }
}

/// One measured blob.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dot {
    pub center_px: [f64; 2],
    /// Coverage-weighted area.
    pub area_px: f64,
    /// Semi-axes of the moment ellipse, major first.
    pub semi_axes_px: [f64; 2],
}

/// Detects and orders the dots of a circles target.
pub fn detect_circles(
    image: &GrayImage,
    target: &Target,
    params: &CircleDetectionParams,
) -> Result<TargetDetection, DetectionError> {
    let (dots, border_blobs) = find_dots(image, target.dark_on_light, params)?;
    let centers: Vec<[f64; 2]> = dots.iter().map(|d| d.center_px).collect();
    let order = order_grid(&centers, target.rows, target.cols, "dots").map_err(|grid| {
        if border_blobs > 0 { DetectionError::AtBorder { border_blobs, grid } } else { DetectionError::Grid(grid) }
    })?;
    let points_px: Vec<[f64; 2]> = order.iter().map(|&k| dots[k].center_px).collect();
    let mut areas: Vec<f32> = order.iter().map(|&k| dots[k].area_px as f32).collect();
    let median_area = f64::from(median_f32(&mut areas).unwrap_or(0.0));
    let feature_size_px = 2.0 * (median_area / std::f64::consts::PI).sqrt();
    Ok(TargetDetection { points_px, feature_size_px, candidates: dots.len() })
}

/// All dot-like blobs of the image (clutter of another size removed), and
/// how many blobs touched the border.
pub fn find_dots(
    image: &GrayImage,
    dark_on_light: bool,
    params: &CircleDetectionParams,
) -> Result<(Vec<Dot>, usize), DetectionError> {
    let (w, h) = (image.width, image.height);
    let threshold = otsu_threshold_dn(image).ok_or(DetectionError::NoContrast)?;
    // "Ink": how much of a dot a grey level is, so bright dots on a dark
    // plate are handled by the same code.
    let sign = if dark_on_light { -1.0f32 } else { 1.0 };
    let ink: Vec<f32> = image.pixels_dn.iter().map(|&v| sign * v).collect();
    let ink_threshold = sign * threshold;
    let mask: Vec<bool> = ink.iter().map(|&v| v > ink_threshold).collect();
    let (labels, components) = connected_components(&mask, w, h);
    let (lo, hi) = image.range_dn();
    let min_contrast = params.min_contrast_fraction * (hi - lo);
    let max_area = w * h / 16;
    let mut dots = Vec::new();
    let mut border_blobs = 0;
    for comp in &components {
        if comp.area_px < params.min_area_px || comp.area_px > max_area {
            continue;
        }
        let [x0, y0, x1, y1] = comp.bbox;
        if x0 == 0 || y0 == 0 || x1 + 1 == w || y1 + 1 == h {
            border_blobs += 1;
            continue;
        }
        if let Some(dot) = measure_blob(&ink, w, h, &labels, comp.label, comp.bbox, min_contrast, params) {
            let fill = dot.area_px / (std::f64::consts::PI * dot.semi_axes_px[0] * dot.semi_axes_px[1]);
            if fill >= params.ellipse_fill.0 && fill <= params.ellipse_fill.1 {
                dots.push(dot);
            }
        }
    }
    Ok((keep_main_size_group(dots, params.area_tolerance), border_blobs))
}

/// Keeps the blobs of the most common size: an affine camera images every
/// dot of the plate as the same ellipse.
fn keep_main_size_group(dots: Vec<Dot>, tolerance: f64) -> Vec<Dot> {
    let similar = |a: f64, b: f64| (a - b).abs() <= tolerance * b;
    let Some(anchor) = dots
        .iter()
        .map(|d| (d.area_px, dots.iter().filter(|e| similar(e.area_px, d.area_px)).count()))
        .max_by(|a, b| a.1.cmp(&b.1).then(a.0.total_cmp(&b.0)))
        .map(|(area, _)| area)
    else {
        return dots;
    };
    let mut group: Vec<f32> = dots.iter().filter(|d| similar(d.area_px, anchor)).map(|d| d.area_px as f32).collect();
    let median = f64::from(median_f32(&mut group).unwrap_or(anchor as f32));
    dots.into_iter().filter(|d| similar(d.area_px, median)).collect()
}

/// Grey-level-weighted moments of one blob (see the module doc).
#[allow(clippy::too_many_arguments)]
fn measure_blob(
    ink: &[f32],
    w: usize,
    h: usize,
    labels: &[u32],
    label: u32,
    bbox: [usize; 4],
    min_contrast: f32,
    params: &CircleDetectionParams,
) -> Option<Dot> {
    let reach = params.margin_px + params.ring_px;
    let x0 = bbox[0].saturating_sub(reach);
    let y0 = bbox[1].saturating_sub(reach);
    let x1 = (bbox[2] + reach).min(w - 1);
    let y1 = (bbox[3] + reach).min(h - 1);
    let (lw, lh) = (x1 - x0 + 1, y1 - y0 + 1);
    let global = |lx: usize, ly: usize| (y0 + ly) * w + x0 + lx;
    // Chessboard distance to the blob, up to `reach`, by repeated dilation.
    const FAR: usize = usize::MAX;
    let mut distance = vec![FAR; lw * lh];
    for ly in 0..lh {
        for lx in 0..lw {
            if labels[global(lx, ly)] == label {
                distance[ly * lw + lx] = 0;
            }
        }
    }
    let neighbours = |lx: usize, ly: usize| {
        let xs = lx.saturating_sub(1)..=(lx + 1).min(lw - 1);
        let ys = ly.saturating_sub(1)..=(ly + 1).min(lh - 1);
        ys.flat_map(move |y| xs.clone().map(move |x| (x, y)))
    };
    for step in 1..=reach {
        let previous = distance.clone();
        for ly in 0..lh {
            for lx in 0..lw {
                if previous[ly * lw + lx] == FAR && neighbours(lx, ly).any(|(x, y)| previous[y * lw + x] == step - 1) {
                    distance[ly * lw + lx] = step;
                }
            }
        }
    }
    // Pixels of, or next to, another blob would bias both levels and moments.
    let near_other = |lx: usize, ly: usize| {
        neighbours(lx, ly).any(|(x, y)| {
            let l = labels[global(x, y)];
            l != 0 && l != label
        })
    };
    let mut ring = Vec::new();
    let mut core = Vec::new();
    for ly in 0..lh {
        for lx in 0..lw {
            let d = distance[ly * lw + lx];
            let v = ink[global(lx, ly)];
            if d == 0 {
                // Interior: the blob's pixels whose 8 neighbours are all in it.
                if neighbours(lx, ly).all(|(x, y)| distance[y * lw + x] == 0) {
                    core.push(v);
                }
            } else if d > params.margin_px && d != FAR && !near_other(lx, ly) {
                ring.push(v);
            }
        }
    }
    let plate = median_f32(&mut ring)?;
    let dot_level = match median_f32(&mut core) {
        Some(level) => level,
        // A dot too small for an interior: its darkest pixel.
        None => {
            (0..lw * lh).filter(|&i| distance[i] == 0).map(|i| ink[global(i % lw, i / lw)]).fold(f32::MIN, f32::max)
        }
    };
    let contrast = dot_level - plate;
    if !(contrast > min_contrast) {
        return None;
    }
    let (mut s, mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
    for ly in 0..lh {
        for lx in 0..lw {
            if distance[ly * lw + lx] > params.margin_px || near_other(lx, ly) {
                continue;
            }
            let weight = f64::from(((ink[global(lx, ly)] - plate) / contrast).clamp(0.0, 1.0));
            let (x, y) = ((x0 + lx) as f64, (y0 + ly) as f64);
            s += weight;
            sx += weight * x;
            sy += weight * y;
            sxx += weight * x * x;
            sxy += weight * x * y;
            syy += weight * y * y;
        }
    }
    if !(s > 0.0) {
        return None;
    }
    let (cx, cy) = (sx / s, sy / s);
    let (vxx, vxy, vyy) = (sxx / s - cx * cx, sxy / s - cx * cy, syy / s - cy * cy);
    // A uniform ellipse with semi-axes a, b has moment eigenvalues a^2/4, b^2/4.
    let mean = 0.5 * (vxx + vyy);
    let spread = (0.25 * (vxx - vyy).powi(2) + vxy * vxy).sqrt();
    let (l1, l2) = (mean + spread, (mean - spread).max(0.0));
    Some(Dot { center_px: [cx, cy], area_px: s, semi_axes_px: [2.0 * l1.sqrt(), 2.0 * l2.sqrt()] })
}
