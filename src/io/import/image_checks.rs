//! What the assigned images hold (size, sample type, bit depth), checked
//! per camera before anything is written, and thumbnails for the dialog.

use super::*;

/// What the image files hold, per camera.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageFacts {
    /// Per camera (assignment order): width, height, bits per sample of the files.
    pub cameras: Vec<CameraFacts>,
    /// Largest sample over all images, when samples were read (16-bit files).
    pub max_value_dn: Option<u16>,
    /// The bit depth for the manifest: given, 8 for 8-bit files, or the
    /// smallest usual camera depth (10, 12, 14, 16) that holds the largest value.
    pub bit_depth: u32,
    pub notes: Vec<String>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CameraFacts {
    pub name: String,
    pub width: usize,
    pub height: usize,
    pub container_bits: u32,
}

/// Size and sample type of an image from its header alone where the format
/// allows (PNG, BMP, PGM, TIFF read only what they need), else a full probe.
pub fn read_header(path: &Path) -> Result<images::ImageHeader, IoError> {
    let quick = || -> Option<images::ImageHeader> {
        use image::ImageDecoder as _;
        let decoder = image::ImageReader::open(path).ok()?.with_guessed_format().ok()?.into_decoder().ok()?;
        let (w, h) = decoder.dimensions();
        let bits = match decoder.color_type() {
            image::ColorType::L8 | image::ColorType::La8 | image::ColorType::Rgb8 | image::ColorType::Rgba8 => 8,
            image::ColorType::L16 | image::ColorType::La16 | image::ColorType::Rgb16 | image::ColorType::Rgba16 => 16,
            _ => return None,
        };
        Some(images::ImageHeader { width: w as usize, height: h as usize, container_bits: bits })
    };
    match quick() {
        Some(h) => Ok(h),
        None => images::read_image_header(path),
    }
}

/// Reads the headers of every assigned image (in parallel) and checks one
/// size and one sample type per camera; with `measure_bit_depth`, decodes
/// the 16-bit images to find the largest value (12-bit data in 16-bit files).
pub fn inspect_images(
    folder: &Path,
    assignment: &Assignment,
    spec: &ImportSpec,
    measure_bit_depth: bool,
    control: &RunControl,
) -> Result<ImageFacts, ImportError> {
    let at = ImportError::at(folder);
    control.begin_stage("reading image headers");
    let mut cameras = Vec::new();
    for camera in &assignment.cameras {
        let files: Vec<&String> = assignment.sets.iter().flat_map(|s| s.files[camera].iter()).collect();
        let headers: Vec<Result<images::ImageHeader, IoError>> =
            files.par_iter().map(|f| read_header(&folder.join(f))).collect();
        control.check().map_err(IoError::from)?;
        let mut reference: Option<(&String, images::ImageHeader)> = None;
        for (file, header) in files.iter().zip(headers) {
            let header = header?;
            match &reference {
                None => reference = Some((file, header)),
                Some((rf, rh)) => {
                    if (header.width, header.height) != (rh.width, rh.height) {
                        return Err(at(ImportFault::SizeMismatch {
                            file: (*file).clone(),
                            width: header.width,
                            height: header.height,
                            reference: (*rf).clone(),
                            ref_width: rh.width,
                            ref_height: rh.height,
                        }));
                    }
                    if header.container_bits != rh.container_bits {
                        return Err(at(ImportFault::MixedContainers {
                            file: (*file).clone(),
                            bits: header.container_bits,
                            reference: (*rf).clone(),
                            ref_bits: rh.container_bits,
                        }));
                    }
                }
            }
        }
        if let Some((_, h)) = reference {
            cameras.push(CameraFacts {
                name: camera.clone(),
                width: h.width,
                height: h.height,
                container_bits: h.container_bits,
            });
        }
    }
    let mut notes = Vec::new();
    let sixteen = cameras.iter().any(|c| c.container_bits == 16);
    if sixteen && let Some(c) = cameras.iter().find(|c| c.container_bits == 8) {
        let first = assignment.sets[0].files[&c.name][0].clone();
        return Err(at(ImportFault::MixedContainers {
            file: first,
            bits: 8,
            reference: format!("camera '{}'", cameras.iter().find(|c| c.container_bits == 16).map_or("", |c| &c.name)),
            ref_bits: 16,
        }));
    }
    let mut max_value_dn = None;
    let mut max_file = String::new();
    if sixteen && (measure_bit_depth || spec.bit_depth.is_some()) {
        control.begin_stage("reading the largest sample value");
        let files: Vec<&String> = assignment.sets.iter().flat_map(|s| s.files.values().flatten()).collect();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let maxima: Vec<Result<u16, IoError>> = files
            .par_iter()
            .map(|f| {
                control.check()?;
                let image = images::read_gray_image(&folder.join(f))?;
                let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                control.set_fraction(n as f32 / files.len() as f32);
                Ok(image.max_value_dn)
            })
            .collect();
        let mut best = 0u16;
        for (f, m) in files.iter().zip(maxima) {
            let m = m?;
            if m > best || max_file.is_empty() {
                best = best.max(m);
                max_file = (*f).clone();
            }
        }
        max_value_dn = Some(best);
    }
    let bit_depth = match spec.bit_depth {
        Some(b) => {
            let first = assignment.sets[0].files[&assignment.cameras[0]][0].clone();
            if !(8..=16).contains(&b) {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: first,
                    problem: "the bit depth must be 8 to 16".into(),
                }));
            }
            if b == 8 && sixteen {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: first,
                    problem: "it is a 16-bit file; give the camera's bit depth (10, 12, 14 or 16)".into(),
                }));
            }
            if b > 8 && !sixteen {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: first,
                    problem: "it is an 8-bit file; use --bit-depth 8 or leave it out".into(),
                }));
            }
            if let Some(m) = max_value_dn
                && u32::from(m) > (1u32 << b) - 1
            {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: max_file,
                    problem: format!(
                        "it holds values up to {m}, above 2^{b} - 1 = {}; the data is {}-bit",
                        (1u32 << b) - 1,
                        images::bits_for_value(m)
                    ),
                }));
            }
            b
        }
        None if !sixteen => 8,
        None => match max_value_dn {
            Some(m) => {
                let needed = images::bits_for_value(m).max(9);
                let depth = [10, 12, 14, 16].into_iter().find(|&d| d >= needed).unwrap_or(16);
                notes.push(format!(
                    "bit depth {depth}: 16-bit files whose largest value is {m} (in {max_file}); give --bit-depth if \
                     the camera has more bits"
                ));
                depth
            }
            None => 16,
        },
    };
    Ok(ImageFacts { cameras, max_value_dn, bit_depth, notes })
}

// ---------------------------------------------------------------- manifest

/// A small 8-bit preview of an image (for the import dialog).
#[derive(Clone, Debug, PartialEq)]
pub struct Thumbnail {
    pub width: usize,
    pub height: usize,
    pub luma: Vec<u8>,
}

/// Decodes `path` and scales it (box average) to at most `max_side` pixels,
/// stretched to its own largest value so 12-bit data in 16-bit files shows.
pub fn thumbnail(path: &Path, max_side: usize) -> Result<Thumbnail, IoError> {
    let image = images::read_gray_image(path)?;
    let (w, h) = (image.width, image.height);
    let step = w.max(h).div_ceil(max_side.max(1)).max(1);
    let (tw, th) = (w.div_ceil(step).max(1), h.div_ceil(step).max(1));
    let sample = |i: usize| -> f32 {
        match &image.pixels {
            GrayPixels::U8(v) => f32::from(v[i]),
            GrayPixels::U16(v) => f32::from(v[i]),
        }
    };
    let scale = 255.0 / f32::from(image.max_value_dn.max(1));
    let mut luma = vec![0u8; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let (mut sum, mut n) = (0.0f32, 0u32);
            for y in ty * step..((ty + 1) * step).min(h) {
                for x in tx * step..((tx + 1) * step).min(w) {
                    sum += sample(y * w + x);
                    n += 1;
                }
            }
            luma[ty * tw + tx] = (sum / n.max(1) as f32 * scale).round().clamp(0.0, 255.0) as u8;
        }
    }
    Ok(Thumbnail { width: tw, height: th, luma })
}
