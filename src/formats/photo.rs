//! Photo files: the sRGB transfer curve, decoding, and writing 16-bit linear PNG, 8-bit sRGB JPEG
//! (with EXIF) and 8-bit greyscale images — atomically. EXIF and the exposure convention are in
//! `crate::formats::exif`.

use crate::error::{Error, Result};
pub use crate::formats::exif::{relative_exposure, ExifInfo};
use crate::formats::output::write_atomic;
use image::codecs::jpeg::JpegEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use std::path::Path;

/// sRGB encoding of a linear value in [0, 1].
pub(crate) fn srgb_encode(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The 8-bit sRGB code of a linear value, `(srgb_encode(x)·255 + 0.5)` truncated, to the bit,
/// without a power: the code is the number of the 255 thresholds — the smallest linear values
/// reaching each code, found once by bisection over the values' bit patterns (ordered like the
/// values for x ≥ 0) — at or below x. Equal because the encoding never decreases. In [0, 1) the
/// count starts from its value at the start of x's bucket ([`SRGB_BUCKETS`] of them) and steps
/// to the thresholds either side (at most a few near 0, where the codes are densest), instead of
/// a binary search, whose dependent steps were a tenth of a 640×480 detection's time (drawing
/// its overlays).
pub(crate) fn srgb_u8(x: f64) -> u8 {
    let t = srgb_u8_thresholds();
    if !(0.0..1.0).contains(&x) {
        return t.partition_point(|&v| v <= x) as u8;
    }
    let bucket = ((x * SRGB_BUCKETS as f64) as usize).min(SRGB_BUCKETS - 1);
    let mut k = srgb_u8_bucket_starts()[bucket] as usize;
    while k < t.len() && t[k] <= x {
        k += 1;
    }
    while k > 0 && t[k - 1] > x {
        k -= 1;
    }
    k as u8
}

/// Buckets of [0, 1) for [`srgb_u8`]'s starting counts.
const SRGB_BUCKETS: usize = 4096;

/// Per bucket of [`srgb_u8`], the number of thresholds at or below its lower end.
fn srgb_u8_bucket_starts() -> &'static [u8] {
    static STARTS: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    STARTS.get_or_init(|| {
        let t = srgb_u8_thresholds();
        (0..SRGB_BUCKETS)
            .map(|i| t.partition_point(|&v| v <= i as f64 / SRGB_BUCKETS as f64) as u8)
            .collect()
    })
}

/// The thresholds of [`srgb_u8`]: for k = 1 … 255, the smallest linear value whose code is k.
fn srgb_u8_thresholds() -> &'static [f64] {
    static THRESHOLDS: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    let code = |x: f64| (srgb_encode(x) * 255.0 + 0.5) as u8;
    THRESHOLDS.get_or_init(|| {
        (1..=255u8)
            .map(|k| {
                let (mut lo, mut hi) = (0f64.to_bits(), 1f64.to_bits());
                while hi - lo > 1 {
                    let mid = lo + (hi - lo) / 2;
                    if code(f64::from_bits(mid)) >= k {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                f64::from_bits(hi)
            })
            .collect()
    })
}

/// Linear value of an sRGB-encoded value in [0, 1].
pub fn srgb_decode(y: f64) -> f64 {
    let y = y.clamp(0.0, 1.0);
    if y <= 0.040_45 {
        y / 12.92
    } else {
        ((y + 0.055) / 1.055).powf(2.4)
    }
}

/// Diagonal of a 36×24 mm frame, which "35 mm equivalent" focal lengths refer to.
pub(crate) const FULL_FRAME_DIAGONAL_MM: f64 = 43.266_615;

/// The 35 mm equivalent focal length of a lens on a sensor `sensor_width_mm` wide imaging
/// `size` pixels (square pixels), by the diagonal.
pub(crate) fn focal_35mm_equivalent(focal_mm: f64, sensor_width_mm: f64, size: [u32; 2]) -> f64 {
    let diag_px = (size[0] as f64).hypot(size[1] as f64);
    let sensor_diag_mm = sensor_width_mm * diag_px / size[0] as f64;
    focal_mm * FULL_FRAME_DIAGONAL_MM / sensor_diag_mm
}

/// The focal length in pixels that a 35 mm equivalent focal length implies for an image size.
pub(crate) fn fx_from_35mm(f35_mm: f64, size: [u32; 2]) -> f64 {
    f35_mm * (size[0] as f64).hypot(size[1] as f64) / FULL_FRAME_DIAGONAL_MM
}

fn image_err(path: &Path, e: image::ImageError) -> Error {
    Error::Image {
        path: path.to_path_buf(),
        err: e,
    }
}

/// Write interleaved RGB 16-bit samples as a PNG.
pub fn write_png16_rgb(path: &Path, width: u32, height: u32, rgb: &[u16]) -> Result<()> {
    let bytes: Vec<u8> = rgb.iter().flat_map(|v| v.to_ne_bytes()).collect();
    let mut err = None;
    write_atomic(path, |w| {
        PngEncoder::new_with_quality(w, CompressionType::Fast, FilterType::Adaptive)
            .write_image(&bytes, width, height, ExtendedColorType::Rgb16)
            .map_err(|e| {
                err = Some(e);
                std::io::Error::other("PNG encoding failed")
            })
    })
    .map_err(|e| err.map(|ie| image_err(path, ie)).unwrap_or(e))
}

/// Write 8-bit samples (`channels` = 1 grey or 3 RGB) as PNG or JPEG by extension; a JPEG gets
/// the EXIF block when given.
pub fn write_8bit(
    path: &Path,
    width: u32,
    height: u32,
    channels: u8,
    data: &[u8],
    quality: u8,
    exif: Option<&ExifInfo>,
) -> Result<()> {
    let color = if channels == 1 {
        ExtendedColorType::L8
    } else {
        ExtendedColorType::Rgb8
    };
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let tiff = exif.map(|e| e.to_tiff()).transpose()?;
    let mut err = None;
    write_atomic(path, |w| {
        let res = match ext.as_str() {
            "jpg" | "jpeg" => {
                let mut enc = JpegEncoder::new_with_quality(w, quality);
                match tiff {
                    Some(t) => match enc.set_exif_metadata(t) {
                        Ok(()) => enc.write_image(data, width, height, color),
                        Err(e) => Err(image::ImageError::Unsupported(e)),
                    },
                    None => enc.write_image(data, width, height, color),
                }
            }
            _ => PngEncoder::new(w).write_image(data, width, height, color),
        };
        res.map_err(|e| {
            err = Some(e);
            std::io::Error::other("image encoding failed")
        })
    })
    .map_err(|e| err.map(|ie| image_err(path, ie)).unwrap_or(e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tabulated 8-bit code equals the encoding's, at a million points, on both sides of every
    /// threshold (each code's first value and the value below it) and of every bucket's start,
    /// and outside [0, 1].
    #[test]
    fn srgb_u8_equals_the_encoding() {
        let direct = |x: f64| (srgb_encode(x) * 255.0 + 0.5) as u8;
        for i in 0..=1_000_000 {
            let x = i as f64 / 1e6;
            assert_eq!(srgb_u8(x), direct(x), "{x}");
        }
        for i in 1..SRGB_BUCKETS {
            let start = i as f64 / SRGB_BUCKETS as f64;
            for x in [start, f64::from_bits(start.to_bits() - 1)] {
                assert_eq!(srgb_u8(x), direct(x), "{x}");
            }
        }
        for (k, &t) in (1..=255u8).zip(srgb_u8_thresholds()) {
            let below = f64::from_bits(t.to_bits() - 1);
            assert_eq!((srgb_u8(t), direct(t)), (k, k), "{t}");
            assert_eq!((srgb_u8(below), direct(below)), (k - 1, k - 1), "{below}");
        }
        for x in [-1.0, 0.0, 1.0, 2.0, f64::NAN] {
            assert_eq!(srgb_u8(x), direct(x), "{x}");
        }
    }

    #[test]
    fn srgb_round_trip() {
        for i in 0..=1000 {
            let x = i as f64 / 1000.0;
            assert!((srgb_decode(srgb_encode(x)) - x).abs() < 1e-12);
        }
    }
}

/// A single-channel image of any pixel type, row-major: the one grid the stages share (8-bit grey
/// for the calibration, luminance for the detector). A photo in colour is [`LinearRgb`] (its
/// clipped pixels flagged), a render `render::raster::Image` (its coverage kept).
#[derive(Clone, Debug, PartialEq)]
pub struct Raster<T> {
    pub width: u32,
    pub height: u32,
    pub data: Vec<T>,
}

impl<T: Copy> Raster<T> {
    pub fn at(&self, x: u32, y: u32) -> T {
        self.data[y as usize * self.width as usize + x as usize]
    }
}

/// An 8-bit greyscale image.
pub type Gray8 = Raster<u8>;

/// Decode any supported image (JPEG, PNG, TIFF; 8 or 16 bit) to 8-bit grey, with its EXIF
/// orientation applied.
pub fn load_gray8(path: &Path) -> Result<Gray8> {
    let g = decode_oriented(path)?.to_luma8();
    Ok(Gray8 {
        width: g.width(),
        height: g.height(),
        data: g.into_raw(),
    })
}

/// The largest photo read (pixels): 64 MP, above any sensor in common use for this work; a
/// larger image is refused before decoding (it would need more than 64 · 10⁶ · 12 bytes of
/// linear RGB).
pub(crate) const MAX_PIXELS: u64 = 64_000_000;
/// The smallest photo side that can hold a sphere worth fitting (pixels).
pub(crate) const MIN_SIDE: u32 = 32;

/// Refuse images too large to decode or too small to hold a sphere.
pub(crate) fn check_size(path: &Path, width: u32, height: u32) -> Result<()> {
    match size_problem(width, height) {
        Some(why) => Err(Error::invalid(path, why)),
        None => Ok(()),
    }
}

/// What is wrong with an image of `width`×`height` for workbench's readers, if anything: the
/// bounds every photo read must meet, and every photo `synth` writes (so that what one command
/// makes, the next can read).
pub(crate) fn size_problem(width: u32, height: u32) -> Option<String> {
    let n = width as u64 * height as u64;
    if n > MAX_PIXELS {
        return Some(format!(
            "image is {width}×{height} ({:.1} MP), more than the {} MP workbench reads: downsample it",
            n as f64 / 1e6,
            MAX_PIXELS / 1_000_000
        ));
    }
    if width < MIN_SIDE || height < MIN_SIDE {
        return Some(format!(
            "image is {width}×{height}: too small to hold a sphere (at least {MIN_SIDE}×{MIN_SIDE})"
        ));
    }
    None
}

/// A JPEG cut short decodes without complaint (the missing rows grey): refuse one whose last scan
/// (the last SOS marker, after any EXIF thumbnail's) has no end-of-image marker after it.
fn check_jpeg_end(path: &Path, b: &[u8]) -> Result<()> {
    let last = |m: u8| b.windows(2).rposition(|w| w[0] == 0xFF && w[1] == m);
    match (last(0xDA), last(0xD9)) {
        (Some(sos), Some(eoi)) if eoi > sos => Ok(()),
        _ => Err(Error::invalid(
            path,
            "truncated JPEG: no end-of-image marker after the last scan",
        )),
    }
}

/// Decode a JPEG, PNG or TIFF file with its EXIF orientation applied.
fn decode_oriented(path: &Path) -> Result<image::DynamicImage> {
    use image::ImageDecoder;
    // Read once: the JPEG end check and the decoder share the bytes.
    crate::formats::input::regular_file(path)?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let reader = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?;
    if reader.format().is_none() {
        return Err(Error::invalid(path, "not a JPEG, PNG or TIFF image"));
    }
    if reader.format() == Some(image::ImageFormat::Jpeg) {
        check_jpeg_end(path, &bytes)?;
    }
    let mut dec = reader.into_decoder().map_err(|e| image_err(path, e))?;
    let (w, h) = dec.dimensions();
    if w as u64 * h as u64 > MAX_PIXELS {
        // Only the upper limit here: small calibration views are judged by their corners.
        check_size(path, w, h)?;
    }
    let orientation = dec.orientation().map_err(|e| image_err(path, e))?;
    let mut img = image::DynamicImage::from_decoder(dec).map_err(|e| image_err(path, e))?;
    img.apply_orientation(orientation);
    Ok(img)
}

/// A linear RGB image (full scale 1), with which pixels were clipped at full scale.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearRgb {
    pub width: u32,
    pub height: u32,
    /// Interleaved RGB, row-major.
    pub data: Vec<f32>,
    /// One flag a pixel: any channel at the top code value (saturated).
    pub saturated: Vec<bool>,
    pub bits: u8,
}

impl LinearRgb {
    /// Rec. 709 luminance of a pixel.
    pub fn luminance(&self, x: u32, y: u32) -> f32 {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        0.2126 * self.data[i] + 0.7152 * self.data[i + 1] + 0.0722 * self.data[i + 2]
    }
}

/// Photos decoded once, to be shared by the stages that read their pixels (detection, then the
/// fit's samples), and the wall time the decoding took (the baseline `fit.json` times against).
pub struct Decoded {
    pub images: Vec<LinearRgb>,
    pub seconds: f64,
}

/// Decode photos in parallel ([`load_linear_rgb`]; each path with its `linear` flag).
pub fn decode_all(photos: &[(&Path, Option<bool>)]) -> Result<Decoded> {
    use rayon::prelude::*;
    let t = std::time::Instant::now();
    let images = photos
        .par_iter()
        .map(|&(path, linear)| load_linear_rgb(path, linear))
        .collect::<Result<_>>()?;
    Ok(Decoded {
        images,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Decode a photo to linear RGB: 16-bit (and float) values are taken as linear, 8-bit values as
/// sRGB unless `linear` says otherwise. EXIF orientation is applied.
pub fn load_linear_rgb(path: &Path, linear: Option<bool>) -> Result<LinearRgb> {
    let img = decode_oriented(path)?;
    let bits = img.color().bytes_per_pixel() / img.color().channel_count() * 8;
    let (width, height) = (img.width(), img.height());
    let (data, saturated) = if bits == 8 {
        let lin = linear.unwrap_or(false);
        let table: Vec<f32> = (0..256)
            .map(|v| {
                if lin {
                    v as f32 / 255.0
                } else {
                    srgb_decode(v as f64 / 255.0) as f32
                }
            })
            .collect();
        let rgb = img.to_rgb8();
        let sat = rgb.pixels().map(|p| p.0.contains(&255)).collect();
        (
            rgb.into_raw()
                .into_iter()
                .map(|v| table[v as usize])
                .collect(),
            sat,
        )
    } else if bits == 16 {
        let rgb = img.to_rgb16();
        let sat = rgb.pixels().map(|p| p.0.contains(&65535)).collect();
        let dec = |v: u16| {
            let x = v as f64 / 65535.0;
            (if linear == Some(false) {
                srgb_decode(x)
            } else {
                x
            }) as f32
        };
        (rgb.into_raw().into_iter().map(dec).collect(), sat)
    } else {
        let rgb = img.to_rgb32f();
        let sat = vec![false; (width * height) as usize];
        (rgb.into_raw(), sat)
    };
    Ok(LinearRgb {
        width,
        height,
        data,
        saturated,
        bits,
    })
}
