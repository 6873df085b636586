//! Grey-level images for target detection and the few image operations the
//! detectors share: Otsu's threshold, connected components, Gaussian blur.
//!
//! Grey levels are `f32` in the image's own units (DN), whatever the bit depth
//! of the file: detection only compares levels within one image.

use rayon::prelude::*;

/// One camera image of the target, row-major, `(0, 0)` the centre of the
/// top-left pixel (the calibration contract's pixel convention).
#[derive(Clone, Debug, PartialEq)]
pub struct GrayImage {
    pub width: usize,
    pub height: usize,
    pub pixels_dn: Vec<f32>,
}

impl GrayImage {
    /// An image from its pixels; `None` when the pixel count is not `width * height`.
    pub fn new(width: usize, height: usize, pixels_dn: Vec<f32>) -> Option<Self> {
        (pixels_dn.len() == width * height).then_some(Self { width, height, pixels_dn })
    }

    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Self {
        let mut pixels_dn = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                pixels_dn.push(f(x, y));
            }
        }
        Self { width, height, pixels_dn }
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.pixels_dn[y * self.width + x]
    }

    /// Lowest and highest grey level.
    pub fn range_dn(&self) -> (f32, f32) {
        self.pixels_dn.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)))
    }
}

/// Otsu's threshold: the level that maximises the between-class variance of
/// the grey-level histogram (256 bins over the image's range). `None` for a
/// flat image.
pub fn otsu_threshold_dn(image: &GrayImage) -> Option<f32> {
    const BINS: usize = 256;
    let (lo, hi) = image.range_dn();
    if !(hi > lo) || !lo.is_finite() || !hi.is_finite() {
        return None;
    }
    let scale = (BINS as f64 - 1.0) / f64::from(hi - lo);
    let mut histogram = [0u64; BINS];
    for &v in &image.pixels_dn {
        let bin = ((f64::from(v - lo)) * scale).round() as usize;
        histogram[bin.min(BINS - 1)] += 1;
    }
    let total = image.pixels_dn.len() as f64;
    let sum_all: f64 = histogram.iter().enumerate().map(|(b, &n)| b as f64 * n as f64).sum();
    let (mut weight_below, mut sum_below) = (0.0f64, 0.0f64);
    let (mut best, mut best_bin) = (-1.0f64, 0usize);
    for (b, &n) in histogram.iter().enumerate() {
        weight_below += n as f64;
        sum_below += b as f64 * n as f64;
        let weight_above = total - weight_below;
        if weight_below == 0.0 || weight_above == 0.0 {
            continue;
        }
        let mean_below = sum_below / weight_below;
        let mean_above = (sum_all - sum_below) / weight_above;
        let between = weight_below * weight_above * (mean_below - mean_above).powi(2);
        if between > best {
            best = between;
            best_bin = b;
        }
    }
    // Pixels in bins <= best_bin form the lower class; the threshold sits
    // half a bin above it.
    Some(lo + ((best_bin as f64 + 0.5) / scale) as f32)
}

/// A connected set of foreground pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// Label in the label image (1-based).
    pub label: u32,
    pub area_px: usize,
    /// Inclusive bounding box: x_min, y_min, x_max, y_max.
    pub bbox: [usize; 4],
}

/// 8-connected components of `mask`; returns the label image (0 = background)
/// and the components in label order.
pub fn connected_components(mask: &[bool], width: usize, height: usize) -> (Vec<u32>, Vec<Component>) {
    let mut labels = vec![0u32; width * height];
    let mut components = Vec::new();
    let mut stack = Vec::new();
    for start in 0..mask.len() {
        if !mask[start] || labels[start] != 0 {
            continue;
        }
        let label = components.len() as u32 + 1;
        labels[start] = label;
        stack.push(start);
        let mut area = 0usize;
        let mut bbox = [usize::MAX, usize::MAX, 0, 0];
        while let Some(i) = stack.pop() {
            let (x, y) = (i % width, i / width);
            area += 1;
            bbox = [bbox[0].min(x), bbox[1].min(y), bbox[2].max(x), bbox[3].max(y)];
            for (dx, dy) in [(-1i64, -1i64), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || ny < 0 || nx >= width as i64 || ny >= height as i64 {
                    continue;
                }
                let j = ny as usize * width + nx as usize;
                if mask[j] && labels[j] == 0 {
                    labels[j] = label;
                    stack.push(j);
                }
            }
        }
        components.push(Component { label, area_px: area, bbox });
    }
    (labels, components)
}

/// Separable Gaussian blur with standard deviation `sigma_px`, edges clamped.
pub fn gaussian_blur(image: &GrayImage, sigma_px: f64) -> GrayImage {
    let radius = (3.0 * sigma_px).ceil().max(1.0) as usize;
    let kernel: Vec<f64> = (0..=2 * radius)
        .map(|k| {
            let d = k as f64 - radius as f64;
            (-0.5 * d * d / (sigma_px * sigma_px)).exp()
        })
        .collect();
    let norm: f64 = kernel.iter().sum();
    let (w, h) = (image.width, image.height);
    let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
    let mut tmp = vec![0f32; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (k, &g) in kernel.iter().enumerate() {
                let xx = clamp(x as i64 + k as i64 - radius as i64, w);
                acc += g * f64::from(image.pixels_dn[y * w + xx]);
            }
            *out = (acc / norm) as f32;
        }
    });
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, value) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (k, &g) in kernel.iter().enumerate() {
                let yy = clamp(y as i64 + k as i64 - radius as i64, h);
                acc += g * f64::from(tmp[yy * w + x]);
            }
            *value = (acc / norm) as f32;
        }
    });
    GrayImage { width: w, height: h, pixels_dn: out }
}

/// Median of a non-empty list (sorted in place).
pub(crate) fn median_f32(values: &mut [f32]) -> Option<f32> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f32::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 { values[n / 2] } else { 0.5 * (values[n / 2 - 1] + values[n / 2]) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn otsu_splits_two_levels() {
        let img = GrayImage::from_fn(20, 10, |x, _| if x < 7 { 30.0 } else { 200.0 });
        let t = otsu_threshold_dn(&img).expect("threshold");
        assert!(t > 30.0 && t < 200.0, "{t}");
        assert!(otsu_threshold_dn(&GrayImage::from_fn(4, 4, |_, _| 9.0)).is_none());
    }

    #[test]
    fn components_are_eight_connected() {
        // Two diagonal pixels touch (8-connectivity); the third is apart.
        let (w, h) = (5, 4);
        let mut mask = vec![false; w * h];
        for (x, y) in [(0, 0), (1, 1), (4, 3)] {
            mask[y * w + x] = true;
        }
        let (labels, comps) = connected_components(&mask, w, h);
        assert_eq!(comps.len(), 2);
        assert_eq!(comps[0].area_px, 2);
        assert_eq!(comps[0].bbox, [0, 0, 1, 1]);
        assert_eq!(labels[3 * w + 4], 2);
    }

    #[test]
    fn blur_keeps_the_mean_and_smooths_a_step() {
        let img = GrayImage::from_fn(16, 8, |x, _| if x < 8 { 0.0 } else { 100.0 });
        let b = gaussian_blur(&img, 1.5);
        let mean_in: f64 = img.pixels_dn.iter().map(|&v| f64::from(v)).sum();
        let mean_out: f64 = b.pixels_dn.iter().map(|&v| f64::from(v)).sum();
        assert!((mean_in - mean_out).abs() < 1e-2 * mean_in);
        assert!((b.get(7, 4) - 50.0).abs() < 20.0 && b.get(7, 4) > 10.0);
        assert!(b.get(0, 0) < 1e-3 && (b.get(15, 0) - 100.0).abs() < 1e-3);
    }
}
