//! Decoding grayscale fringe images (PNG, TIFF, BMP, PGM/PNM; 8- or 16-bit
//! containers) straight into a measurement's sample buffers.
//!
//! What the data must satisfy is checked here, per file, because a wrong
//! bit depth or size silently produces wrong phases downstream: the container
//! must match the manifest's bit depth (8-bit files for `bit_depth` 8, 16-bit
//! files for 9..=16), no sample may exceed `2^bit_depth - 1` (12-bit data
//! declared as 10-bit), and all images of a camera share one size. Colour
//! images are converted to luma, with a warning naming the file.
//!
//! PGM files with a maximum value other than 255 or 65535 (e.g. 4095 for
//! 12-bit data) hold the camera's raw values; the `image` crate stretches
//! them to the full container range, which is undone here so the samples
//! stay the acquired grey levels.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use image::{ColorType, ImageDecoder, ImageFormat, ImageReader};

use super::error::IoError;

/// What is wrong with one image file.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ImageFault {
    #[error("does not exist; check the path in the manifest and that the image was copied")]
    Missing,
    #[error("cannot be read: {message}")]
    Unreadable { message: String },
    #[error("is a {format} file; fringe images must be PNG, TIFF, BMP or PGM")]
    UnsupportedFormat { format: String },
    #[error("cannot be decoded ({message}); the file is truncated or corrupt: copy or export it again")]
    Corrupt { message: String },
    #[error("holds {found} samples; fringe images must be 8- or 16-bit integer grayscale")]
    UnsupportedSamples { found: String },
    #[error(
        "is a 16-bit file but the manifest declares bit_depth 8; set bit_depth to the camera's bit depth \
         (10, 12, 14 or 16)"
    )]
    SixteenBitIn8BitSet,
    #[error(
        "is an 8-bit file but the manifest declares bit_depth {bit_depth}; set bit_depth to 8 or export the \
         images with 16-bit samples"
    )]
    EightBitInHighBitSet { bit_depth: u32 },
    #[error(
        "holds values up to {max_value_dn}, above {limit} = 2^{bit_depth} - 1 allowed by bit_depth {bit_depth}; \
         the data is {needed}-bit: set bit_depth to {needed}"
    )]
    ValueTooLarge { max_value_dn: u16, limit: u32, bit_depth: u32, needed: u32 },
    #[error("is {width}x{height} px, expected {expected_width}x{expected_height} px like {}", reference.display())]
    SizeMismatch { width: usize, height: usize, expected_width: usize, expected_height: usize, reference: PathBuf },
}

/// Where an image sits in a manifest, for messages.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageLocation {
    pub camera: String,
    pub set: usize,
    /// A Gray code frame rather than a set's: which list (`columns`,
    /// `rows`, `white`, `black`); `set` is then unused.
    pub gray_code: Option<&'static str>,
    pub image: usize,
    /// The path as the manifest writes it.
    pub listed_as: String,
}

impl std::fmt::Display for ImageLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.gray_code {
            Some(list) => {
                write!(f, "camera '{}' gray_code {list} image {} {}", self.camera, self.image, self.listed_as)
            }
            None => write!(f, "camera '{}' set {} image {} {}", self.camera, self.set, self.image, self.listed_as),
        }
    }
}

/// Size and sample width of an image file, from its header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageHeader {
    pub width: usize,
    pub height: usize,
    /// 8 or 16: bits per sample of the file.
    pub container_bits: u32,
}

/// Samples of a grayscale image, in the type of its container.
#[derive(Clone, Debug, PartialEq)]
pub enum GrayPixels {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

/// A decoded grayscale image (row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct GrayImage {
    pub width: usize,
    pub height: usize,
    pub container_bits: u32,
    /// Largest sample: tells 12-bit data in 16-bit files from true 16-bit data.
    pub max_value_dn: u16,
    pub pixels: GrayPixels,
    /// Set when the file was converted (colour to luma, alpha dropped).
    pub warning: Option<String>,
}

/// Smallest bit depth (at least 8) that holds `max_value_dn`.
pub fn bits_for_value(max_value_dn: u16) -> u32 {
    (16 - max_value_dn.leading_zeros()).max(8)
}

/// Reads the header of an image file (no pixel decoding).
pub fn read_image_header(path: &Path) -> Result<ImageHeader, IoError> {
    probe(path).map_err(|fault| IoError::Image { path: path.to_path_buf(), location: None, fault })
}

/// Decodes a whole grayscale image (colour is converted to luma with a warning).
pub fn read_gray_image(path: &Path) -> Result<GrayImage, IoError> {
    let err = |fault| IoError::Image { path: path.to_path_buf(), location: None, fault };
    let header = probe(path).map_err(err)?;
    let n = header.width * header.height;
    let name = path.display().to_string();
    let (pixels, decoded) = if header.container_bits == 8 {
        let mut v = vec![0u8; n];
        let d = decode_into(path, &name, PlaneMut::U8(&mut v), header.width, header.height, path, 8).map_err(err)?;
        (GrayPixels::U8(v), d)
    } else {
        let mut v = vec![0u16; n];
        let d = decode_into(path, &name, PlaneMut::U16(&mut v), header.width, header.height, path, 16).map_err(err)?;
        (GrayPixels::U16(v), d)
    };
    Ok(GrayImage {
        width: header.width,
        height: header.height,
        container_bits: header.container_bits,
        max_value_dn: decoded.max_value_dn,
        pixels,
        warning: decoded.warning,
    })
}

/// A plane of a stack to decode into.
pub(crate) enum PlaneMut<'a> {
    U8(&'a mut [u8]),
    U16(&'a mut [u16]),
}

/// What decoding one file found.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Decoded {
    pub max_value_dn: u16,
    pub warning: Option<String>,
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, ImageFault> {
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => ImageFault::Missing,
        _ => ImageFault::Unreadable { message: super::error::os_cause(&e) },
    })
}

fn corrupt(e: image::ImageError) -> ImageFault {
    match e {
        image::ImageError::Unsupported(u) => ImageFault::UnsupportedSamples { found: u.to_string() },
        e => ImageFault::Corrupt { message: e.to_string() },
    }
}

/// A decoder for the file's content (the magic bytes decide; the extension
/// only when they are not recognised), and for PGM the maximum sample value.
fn open_decoder<'a>(path: &Path, bytes: &'a [u8]) -> Result<(Box<dyn ImageDecoder + 'a>, Option<u32>), ImageFault> {
    let format = match image::guess_format(bytes) {
        Ok(f) => f,
        Err(_) => ImageFormat::from_path(path)
            .map_err(|_| ImageFault::Corrupt { message: "not a recognisable PNG, TIFF, BMP or PGM file".into() })?,
    };
    match format {
        ImageFormat::Pnm => {
            let d = image::codecs::pnm::PnmDecoder::new(Cursor::new(bytes)).map_err(corrupt)?;
            let maxval = d.header().maximal_sample();
            Ok((Box::new(d), Some(maxval)))
        }
        ImageFormat::Png | ImageFormat::Tiff | ImageFormat::Bmp => {
            let d = ImageReader::with_format(Cursor::new(bytes), format).into_decoder().map_err(corrupt)?;
            Ok((Box::new(d), None))
        }
        other => Err(ImageFault::UnsupportedFormat { format: format!("{other:?}").to_uppercase() }),
    }
}

fn container_bits(color: ColorType) -> Result<u32, ImageFault> {
    match color {
        ColorType::L8 | ColorType::La8 | ColorType::Rgb8 | ColorType::Rgba8 => Ok(8),
        ColorType::L16 | ColorType::La16 | ColorType::Rgb16 | ColorType::Rgba16 => Ok(16),
        other => Err(ImageFault::UnsupportedSamples { found: format!("{other:?}") }),
    }
}

/// Header facts of an image file.
pub(crate) fn probe(path: &Path) -> Result<ImageHeader, ImageFault> {
    let bytes = read_bytes(path)?;
    let (decoder, _) = open_decoder(path, &bytes)?;
    let (w, h) = decoder.dimensions();
    Ok(ImageHeader { width: w as usize, height: h as usize, container_bits: container_bits(decoder.color_type())? })
}

/// Decodes `path` into `plane` (`width * height` samples), checking its size
/// against `width` x `height` (as found in `reference`), its container
/// against `bit_depth` (the plane's type follows it), and its values against
/// `2^bit_depth - 1`. `name` is how warnings refer to the file.
pub(crate) fn decode_into(
    path: &Path,
    name: &str,
    plane: PlaneMut<'_>,
    width: usize,
    height: usize,
    reference: &Path,
    bit_depth: u32,
) -> Result<Decoded, ImageFault> {
    let mut plane = plane;
    if let Some(max_value_dn) = read_plain_tiff(path, &mut plane, width, height) {
        return checked_max(max_value_dn, bit_depth).map(|max_value_dn| Decoded { max_value_dn, warning: None });
    }
    let bytes = read_bytes(path)?;
    let (decoder, pnm_maxval) = open_decoder(path, &bytes)?;
    let (w, h) = decoder.dimensions();
    let (w, h) = (w as usize, h as usize);
    if (w, h) != (width, height) {
        return Err(ImageFault::SizeMismatch {
            width: w,
            height: h,
            expected_width: width,
            expected_height: height,
            reference: reference.to_path_buf(),
        });
    }
    let color = decoder.color_type();
    let bits = container_bits(color)?;
    match (&plane, bits) {
        (PlaneMut::U8(_), 16) => return Err(ImageFault::SixteenBitIn8BitSet),
        (PlaneMut::U16(_), 8) => return Err(ImageFault::EightBitInHighBitSet { bit_depth }),
        _ => {}
    }
    let total = decoder.total_bytes();
    let mut warning = None;
    let max_value_dn = match plane {
        PlaneMut::U8(out) => {
            if color == ColorType::L8 {
                read_exact(decoder, out, total)?;
            } else {
                let mut buf = vec![0u8; usize::try_from(total).unwrap_or(usize::MAX).min(out.len() * 4)];
                read_exact(decoder, &mut buf, total)?;
                warning = to_luma(&buf, color, out, name);
            }
            if let Some(maxval) = pnm_maxval {
                unstretch(out.iter_mut(), maxval, 255);
            }
            out.iter().copied().max().map_or(0, u16::from)
        }
        PlaneMut::U16(out) => {
            if color == ColorType::L16 {
                read_exact(decoder, bytemuck::cast_slice_mut(out), total)?;
            } else {
                let mut buf = vec![0u16; usize::try_from(total / 2).unwrap_or(usize::MAX).min(out.len() * 4)];
                read_exact(decoder, bytemuck::cast_slice_mut(&mut buf), total)?;
                warning = to_luma(&buf, color, out, name);
            }
            if let Some(maxval) = pnm_maxval {
                unstretch(out.iter_mut(), maxval, 65535);
            }
            out.iter().copied().max().unwrap_or(0)
        }
    };
    checked_max(max_value_dn, bit_depth).map(|max_value_dn| Decoded { max_value_dn, warning })
}

#[cfg(not(unix))]
fn read_plain_tiff(_: &Path, _: &mut PlaneMut<'_>, _: usize, _: usize) -> Option<u16> {
    None
}

/// The largest sample, refused when it does not fit `bit_depth` bits.
fn checked_max(max_value_dn: u16, bit_depth: u32) -> Result<u16, ImageFault> {
    let limit = (1u32 << bit_depth.min(16)) - 1;
    if u32::from(max_value_dn) > limit {
        return Err(ImageFault::ValueTooLarge { max_value_dn, limit, bit_depth, needed: bits_for_value(max_value_dn) });
    }
    Ok(max_value_dn)
}

/// An uncompressed, single-channel, black-is-zero TIFF of the plane's size
/// and sample width, its strips read from the file straight into the plane
/// (a rig's usual file: the general decoder would read the whole file, then
/// copy the samples twice); returns the largest sample. `None` for any other
/// file, or any doubt: the general decoder then reads it, and names what is
/// wrong with it.
#[cfg(unix)]
fn read_plain_tiff(path: &Path, plane: &mut PlaneMut<'_>, width: usize, height: usize) -> Option<u16> {
    use std::os::unix::fs::FileExt as _;
    use tiff::decoder::{Decoder, ifd::Value};
    use tiff::tags::Tag;

    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff")) {
        return None;
    }
    let file = std::fs::File::open(path).ok()?;
    let mut decoder = Decoder::new(std::io::BufReader::with_capacity(4096, &file)).ok()?;
    let (w, h) = decoder.dimensions().ok()?;
    if (w as usize, h as usize) != (width, height) {
        return None;
    }
    let bits = match decoder.colortype().ok()? {
        tiff::ColorType::Gray(bits) => bits,
        _ => return None,
    };
    let mut number = |tag: Tag, absent: u64| -> Option<u64> {
        match decoder.find_tag(tag).ok()? {
            None => Some(absent),
            Some(v) => v.into_u64().ok(),
        }
    };
    // No compression, black is zero, one plane, no predictor, unsigned
    // samples, strips not tiles.
    let plain = number(Tag::Compression, 1)? == 1
        && number(Tag::PhotometricInterpretation, u64::MAX)? == 1
        && number(Tag::SamplesPerPixel, 1)? == 1
        && number(Tag::PlanarConfiguration, 1)? == 1
        && number(Tag::Predictor, 1)? == 1
        && number(Tag::SampleFormat, 1)? == 1
        && number(Tag::TileWidth, 0)? == 0;
    let rows_per_strip = number(Tag::RowsPerStrip, u64::from(h))?.clamp(1, u64::from(h).max(1)) as usize;
    if !plain {
        return None;
    }
    let offsets = decoder.get_tag(Tag::StripOffsets).ok().and_then(|v: Value| v.into_u64_vec().ok())?;
    let counts = decoder.get_tag(Tag::StripByteCounts).ok().and_then(|v: Value| v.into_u64_vec().ok())?;
    let big_endian = decoder.byte_order() == tiff::tags::ByteOrder::BigEndian;
    let (bytes, sample_bytes): (&mut [u8], usize) = match (&mut *plane, bits) {
        (PlaneMut::U8(out), 8) => (&mut **out, 1),
        (PlaneMut::U16(out), 16) => (bytemuck::cast_slice_mut(out), 2),
        _ => return None,
    };
    let row_bytes = width * sample_bytes;
    let strips = height.div_ceil(rows_per_strip);
    if bytes.len() != row_bytes * height || offsets.len() != strips || counts.len() != strips {
        return None;
    }
    for (i, (&offset, &count)) in offsets.iter().zip(&counts).enumerate() {
        let start = i * rows_per_strip * row_bytes;
        let end = ((i + 1) * rows_per_strip).min(height) * row_bytes;
        if count < (end - start) as u64 {
            return None;
        }
        file.read_exact_at(&mut bytes[start..end], offset).ok()?;
    }
    match plane {
        PlaneMut::U8(out) => out.iter().copied().max().map(u16::from),
        PlaneMut::U16(out) => {
            for v in out.iter_mut() {
                *v = if big_endian { u16::from_be(*v) } else { u16::from_le(*v) };
            }
            out.iter().copied().max()
        }
    }
}

/// Reads the decoder's pixels into `buf`, which must hold exactly `total`
/// bytes (the decoder would panic otherwise).
fn read_exact(decoder: Box<dyn ImageDecoder + '_>, buf: &mut [u8], total: u64) -> Result<(), ImageFault> {
    if buf.len() as u64 != total {
        return Err(ImageFault::Corrupt {
            message: format!("the header announces {total} bytes of pixels for its size, expected {}", buf.len()),
        });
    }
    decoder.read_image_boxed(buf).map_err(corrupt)
}

/// Undoes the PGM decoder's stretch of `maxval` to `full` (`v' = round(v full
/// / maxval)`); exact because the stretch factor is at least 1.
fn unstretch<'a, T>(samples: impl Iterator<Item = &'a mut T>, maxval: u32, full: u32)
where
    T: Copy + Into<u32> + TryFrom<u32> + 'a,
{
    if maxval == 0 || maxval >= full {
        return;
    }
    let factor = f64::from(maxval) / f64::from(full);
    for v in samples {
        let raw = (f64::from((*v).into()) * factor).round() as u32;
        if let Ok(x) = T::try_from(raw) {
            *v = x;
        }
    }
}

/// Converts interleaved samples to one grey level per pixel: equal colour
/// channels (grey stored as RGB, e.g. palette BMPs) are taken exactly, others
/// as Rec. 709 luma. Returns a warning when colour or alpha was dropped.
fn to_luma<T>(buf: &[T], color: ColorType, out: &mut [T], name: &str) -> Option<String>
where
    T: Copy + PartialEq + Into<f64> + TryFrom<u32> + Bounded,
{
    let (channels, has_colour, has_alpha) = match color {
        ColorType::La8 | ColorType::La16 => (2, false, true),
        ColorType::Rgb8 | ColorType::Rgb16 => (3, true, false),
        ColorType::Rgba8 | ColorType::Rgba16 => (4, true, true),
        _ => (1, false, false),
    };
    let mut coloured = false;
    let mut translucent = false;
    for (px, o) in buf.chunks_exact(channels).zip(out.iter_mut()) {
        if has_colour && (px[0] != px[1] || px[1] != px[2]) {
            coloured = true;
            let y = 0.2126 * px[0].into() + 0.7152 * px[1].into() + 0.0722 * px[2].into();
            *o = T::try_from(y.round() as u32).unwrap_or(T::MAX);
        } else {
            *o = px[0];
        }
        if has_alpha && px[channels - 1] != T::MAX {
            translucent = true;
        }
    }
    match (coloured, translucent) {
        (false, false) => None,
        (true, _) => Some(format!(
            "{name} is a colour image; converted to luma Y = 0.2126 R + 0.7152 G + 0.0722 B (use grayscale images \
             for the camera's own grey levels)"
        )),
        (false, true) => Some(format!("{name} has a transparency channel; it was ignored")),
    }
}

/// The largest value of a sample type (alpha "opaque").
pub(crate) trait Bounded {
    const MAX: Self;
}
impl Bounded for u8 {
    const MAX: Self = u8::MAX;
}
impl Bounded for u16 {
    const MAX: Self = u16::MAX;
}

/// Writes a grayscale image as PNG (8-bit samples as an 8-bit PNG, 16-bit as
/// 16-bit), atomically. Fast compression: fringe images are large and written
/// by the dozen (the simulator, the importer's fixtures).
pub fn write_gray_png(path: &Path, width: usize, height: usize, pixels: &GrayPixels) -> Result<(), IoError> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let (bytes, color): (Vec<u8>, image::ExtendedColorType) = match pixels {
        GrayPixels::U8(v) => (v.clone(), image::ExtendedColorType::L8),
        // PNG stores 16-bit samples big-endian; the encoder takes native order.
        GrayPixels::U16(v) => (bytemuck::cast_slice(v).to_vec(), image::ExtendedColorType::L16),
    };
    let (w, h) = (u32::try_from(width), u32::try_from(height));
    let (Ok(w), Ok(h)) = (w, h) else {
        return Err(IoError::Write {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "image larger than PNG allows"),
        });
    };
    super::atomic::write_atomic(path, |out| {
        PngEncoder::new_with_quality(out, CompressionType::Fast, FilterType::Sub)
            .write_image(&bytes, w, h, color)
            .map_err(std::io::Error::other)
    })
}

/// Writes a grayscale image as an uncompressed TIFF, atomically: the format
/// many industrial cameras' software saves, and the fastest to read back.
pub fn write_gray_tiff(path: &Path, width: usize, height: usize, pixels: &GrayPixels) -> Result<(), IoError> {
    use tiff::encoder::{TiffEncoder, colortype};
    let (Ok(w), Ok(h)) = (u32::try_from(width), u32::try_from(height)) else {
        return Err(IoError::Write {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "image larger than TIFF allows"),
        });
    };
    super::atomic::write_atomic(path, |out| {
        let mut encoder = TiffEncoder::new(out).map_err(std::io::Error::other)?;
        match pixels {
            GrayPixels::U8(v) => encoder.write_image::<colortype::Gray8>(w, h, v),
            GrayPixels::U16(v) => encoder.write_image::<colortype::Gray16>(w, h, v),
        }
        .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use image::{ImageBuffer, Luma, Rgb};

    /// Writes `samples` as a grayscale image in `format` (8-bit for u8 data).
    pub(crate) fn write_gray8(path: &Path, w: u32, h: u32, samples: &[u8]) {
        let img: ImageBuffer<Luma<u8>, Vec<u8>> = ImageBuffer::from_raw(w, h, samples.to_vec()).unwrap();
        img.save(path).unwrap();
    }

    pub(crate) fn write_gray16(path: &Path, w: u32, h: u32, samples: &[u16]) {
        let img: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_raw(w, h, samples.to_vec()).unwrap();
        img.save(path).unwrap();
    }

    /// A binary PGM with an explicit maximum value (as 12-bit cameras write).
    pub(crate) fn write_pgm16(path: &Path, w: usize, h: usize, maxval: u16, samples: &[u16]) {
        let mut bytes = format!("P5\n{w} {h}\n{maxval}\n").into_bytes();
        for s in samples {
            bytes.extend_from_slice(&s.to_be_bytes());
        }
        std::fs::write(path, bytes).unwrap();
    }

    fn pattern8(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 37 % 256) as u8).collect()
    }

    /// 12-bit samples reaching the top code 4095.
    fn pattern12(n: usize) -> Vec<u16> {
        (0..n).map(|i| if i == 1 { 4095 } else { (i * 977 % 4096) as u16 }).collect()
    }

    #[test]
    fn eight_bit_formats_decode_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (13u32, 7u32);
        let samples = pattern8((w * h) as usize);
        for ext in ["png", "tif", "bmp", "pgm"] {
            let path = dir.path().join(format!("f.{ext}"));
            write_gray8(&path, w, h, &samples);
            let img = read_gray_image(&path).unwrap();
            assert_eq!(img.pixels, GrayPixels::U8(samples.clone()), "{ext}");
            assert_eq!((img.width, img.height, img.container_bits), (13, 7, 8), "{ext}");
            assert_eq!(img.max_value_dn, 255, "{ext}");
            assert_eq!(img.warning, None, "{ext}");
        }
    }

    #[test]
    fn twelve_bit_data_in_sixteen_bit_files_decodes_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (11usize, 5usize);
        let samples = pattern12(w * h);
        for ext in ["png", "tif", "pgm"] {
            let path = dir.path().join(format!("f.{ext}"));
            write_gray16(&path, w as u32, h as u32, &samples);
            let img = read_gray_image(&path).unwrap();
            assert_eq!(img.pixels, GrayPixels::U16(samples.clone()), "{ext}");
            assert_eq!(img.max_value_dn, 4095, "{ext}");
            assert_eq!(bits_for_value(img.max_value_dn), 12);
        }
        // maxval 4095 PGM: the decoder's stretch to 65535 is undone.
        let path = dir.path().join("raw12.pgm");
        write_pgm16(&path, w, h, 4095, &samples);
        let img = read_gray_image(&path).unwrap();
        assert_eq!(img.pixels, GrayPixels::U16(samples));
    }

    #[test]
    fn colour_images_become_luma_with_a_warning_and_grey_rgb_stays_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("colour.png");
        let img: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_raw(2, 1, vec![200, 100, 50, 90, 90, 90]).unwrap();
        img.save(&path).unwrap();
        let g = read_gray_image(&path).unwrap();
        let y = (0.2126f64 * 200.0 + 0.7152 * 100.0 + 0.0722 * 50.0).round() as u8;
        assert_eq!(g.pixels, GrayPixels::U8(vec![y, 90]));
        let w = g.warning.unwrap();
        assert!(w.contains("colour.png") && w.contains("luma"), "{w}");
        // Grey stored as RGB (what palette BMPs decode to) is not colour.
        let path = dir.path().join("grey_rgb.bmp");
        let img: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_raw(2, 1, vec![7, 7, 7, 250, 250, 250]).unwrap();
        img.save(&path).unwrap();
        let g = read_gray_image(&path).unwrap();
        assert_eq!(g.pixels, GrayPixels::U8(vec![7, 250]));
        assert_eq!(g.warning, None);
    }

    /// What the general decoder makes of a file (the reference for the
    /// direct strip reading).
    fn general_u16(path: &Path) -> Vec<u16> {
        let bytes = std::fs::read(path).unwrap();
        let (decoder, _) = open_decoder(path, &bytes).unwrap();
        let mut out = vec![0u16; usize::try_from(decoder.total_bytes()).unwrap() / 2];
        decoder.read_image_boxed(bytemuck::cast_slice_mut(&mut out)).unwrap();
        out
    }

    /// A big-endian ("MM") uncompressed 16-bit TIFF of one strip per two rows,
    /// written by hand: the tiff crate writes only its own byte order.
    fn write_big_endian_tiff16(path: &Path, w: usize, h: usize, samples: &[u16]) {
        let rows_per_strip = 2;
        let strips = h.div_ceil(rows_per_strip);
        let entries: u16 = 9;
        let ifd_len = 2 + 12 * usize::from(entries) + 4;
        let (offsets_at, counts_at) = (8 + ifd_len, 8 + ifd_len + 4 * strips);
        let data_at = counts_at + 4 * strips;
        let mut f = b"MM\0\x2a".to_vec();
        f.extend_from_slice(&8u32.to_be_bytes());
        f.extend_from_slice(&entries.to_be_bytes());
        let mut entry = |tag: u16, kind: u16, count: u32, value: u32| {
            f.extend_from_slice(&tag.to_be_bytes());
            f.extend_from_slice(&kind.to_be_bytes());
            f.extend_from_slice(&count.to_be_bytes());
            // A SHORT value sits in the first two bytes of the field.
            let field = if kind == 3 && count == 1 { value << 16 } else { value };
            f.extend_from_slice(&field.to_be_bytes());
        };
        let (short, long) = (3, 4);
        entry(256, long, 1, w as u32);
        entry(257, long, 1, h as u32);
        entry(258, short, 1, 16);
        entry(259, short, 1, 1);
        entry(262, short, 1, 1);
        entry(273, long, strips as u32, offsets_at as u32);
        entry(277, short, 1, 1);
        entry(278, long, 1, rows_per_strip as u32);
        entry(279, long, strips as u32, counts_at as u32);
        f.extend_from_slice(&0u32.to_be_bytes());
        for s in 0..strips {
            f.extend_from_slice(&((data_at + s * rows_per_strip * w * 2) as u32).to_be_bytes());
        }
        for s in 0..strips {
            let rows = rows_per_strip.min(h - s * rows_per_strip);
            f.extend_from_slice(&((rows * w * 2) as u32).to_be_bytes());
        }
        for v in samples {
            f.extend_from_slice(&v.to_be_bytes());
        }
        std::fs::write(path, f).unwrap();
    }

    /// Uncompressed grey TIFFs of several strips, 8- and 16-bit and either
    /// byte order, are read straight into the plane with the samples the
    /// general decoder gives; a compressed one goes to the general decoder
    /// and decodes the same; a truncated one is refused as corrupt.
    #[test]
    fn plain_tiffs_are_read_into_the_plane_as_the_decoder_reads_them() {
        use tiff::encoder::{Compression, TiffEncoder, colortype};
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (300usize, 97usize);
        let samples8 = pattern8(w * h);
        let samples12 = pattern12(w * h);

        // Strips of five rows, the last one shorter.
        let path8 = dir.path().join("plain8.tif");
        let mut encoder = TiffEncoder::new(std::fs::File::create(&path8).unwrap()).unwrap();
        let mut image = encoder.new_image::<colortype::Gray8>(w as u32, h as u32).unwrap();
        image.rows_per_strip(5).unwrap();
        image.write_data(&samples8).unwrap();
        let mut plane = vec![0u8; w * h];
        assert_eq!(read_plain_tiff(&path8, &mut PlaneMut::U8(&mut plane), w, h), Some(255));
        assert_eq!(plane, samples8);

        let path16 = dir.path().join("plain16.tif");
        let mut encoder = TiffEncoder::new(std::fs::File::create(&path16).unwrap()).unwrap();
        let mut image = encoder.new_image::<colortype::Gray16>(w as u32, h as u32).unwrap();
        image.rows_per_strip(5).unwrap();
        image.write_data(&samples12).unwrap();
        let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(&path16).unwrap()).unwrap();
        let strips = decoder.get_tag_u64_vec(tiff::tags::Tag::StripOffsets).unwrap().len();
        assert!(strips > 1, "several strips ({strips})");
        let mut plane = vec![0u16; w * h];
        assert_eq!(read_plain_tiff(&path16, &mut PlaneMut::U16(&mut plane), w, h), Some(4095));
        assert_eq!(plane, samples12);

        let big = dir.path().join("big-endian.tif");
        write_big_endian_tiff16(&big, w, h, &samples12);
        assert_eq!(general_u16(&big), samples12, "the general decoder reads the hand-made file");
        let mut plane = vec![0u16; w * h];
        assert_eq!(read_plain_tiff(&big, &mut PlaneMut::U16(&mut plane), w, h), Some(4095));
        assert_eq!(plane, samples12);

        let lzw = dir.path().join("lzw.tif");
        let file = std::fs::File::create(&lzw).unwrap();
        let mut encoder = TiffEncoder::new(file).unwrap().with_compression(Compression::Lzw);
        encoder.write_image::<colortype::Gray16>(w as u32, h as u32, &samples12).unwrap();
        let mut plane = vec![0u16; w * h];
        assert_eq!(read_plain_tiff(&lzw, &mut PlaneMut::U16(&mut plane), w, h), None, "compressed: not read directly");
        let d = decode_into(&lzw, "x", PlaneMut::U16(&mut plane), w, h, &lzw, 12).unwrap();
        assert_eq!((plane.as_slice(), d.max_value_dn), (samples12.as_slice(), 4095));

        let bytes = std::fs::read(&path16).unwrap();
        let cut = dir.path().join("cut.tif");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let mut plane = vec![0u16; w * h];
        assert_eq!(read_plain_tiff(&cut, &mut PlaneMut::U16(&mut plane), w, h), None);
        let fault = decode_into(&cut, "x", PlaneMut::U16(&mut plane), w, h, &cut, 12).unwrap_err();
        assert!(matches!(fault, ImageFault::Corrupt { .. }), "{fault:?}");
    }

    fn decode8(path: &Path, w: usize, h: usize, bit_depth: u32) -> Result<Decoded, ImageFault> {
        let mut plane = vec![0u8; w * h];
        decode_into(path, "x", PlaneMut::U8(&mut plane), w, h, Path::new("left/ref.png"), bit_depth)
    }

    fn decode16(path: &Path, w: usize, h: usize, bit_depth: u32) -> Result<Decoded, ImageFault> {
        let mut plane = vec![0u16; w * h];
        decode_into(path, "x", PlaneMut::U16(&mut plane), w, h, Path::new("left/ref.png"), bit_depth)
    }

    #[test]
    fn faults_are_classified() {
        let dir = tempfile::tempdir().unwrap();
        let p8 = dir.path().join("a.png");
        write_gray8(&p8, 4, 3, &pattern8(12));
        let p16 = dir.path().join("b.png");
        write_gray16(&p16, 4, 3, &pattern12(12));
        assert_eq!(decode8(&dir.path().join("none.png"), 4, 3, 8), Err(ImageFault::Missing));
        assert_eq!(decode8(&p16, 4, 3, 8), Err(ImageFault::SixteenBitIn8BitSet));
        assert_eq!(decode16(&p8, 4, 3, 12), Err(ImageFault::EightBitInHighBitSet { bit_depth: 12 }));
        assert_eq!(
            decode16(&p16, 4, 3, 10),
            Err(ImageFault::ValueTooLarge { max_value_dn: 4095, limit: 1023, bit_depth: 10, needed: 12 })
        );
        assert!(decode16(&p16, 4, 3, 12).is_ok());
        let Err(ImageFault::SizeMismatch { width: 4, height: 3, expected_width: 4, expected_height: 4, .. }) =
            decode8(&p8, 4, 4, 8)
        else {
            panic!("size mismatch not reported")
        };
        // Truncated: the first half of a valid PNG.
        let bytes = std::fs::read(&p8).unwrap();
        let cut = dir.path().join("cut.png");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        assert!(matches!(decode8(&cut, 4, 3, 8), Err(ImageFault::Corrupt { .. })));
        // Not an image at all.
        let junk = dir.path().join("junk.png");
        std::fs::write(&junk, b"this is not an image").unwrap();
        assert!(matches!(decode8(&junk, 4, 3, 8), Err(ImageFault::Corrupt { .. })));
        // A JPEG by its magic bytes.
        let jpeg = dir.path().join("photo.png");
        std::fs::write(&jpeg, [0xFF, 0xD8, 0xFF, 0xE0, 0, 16, b'J', b'F', b'I', b'F', 0]).unwrap();
        assert!(matches!(decode8(&jpeg, 4, 3, 8), Err(ImageFault::UnsupportedFormat { .. })));
    }

    #[test]
    fn errors_name_the_file() {
        let err = read_gray_image(Path::new("/no/such/left/p0912_00.png")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("/no/such/left/p0912_00.png") && msg.contains("does not exist"), "{msg}");
    }
}
