//! Grey-level images as the pipeline sees them: one `f32` per pixel, row-major, and loading from
//! files or raw buffers with the checks a user's input needs.
//!
//! Pixel `(x, y)` (integers) has its centre at image coordinate `(x, y)`; see the crate docs.

use std::path::Path;

/// Largest image accepted, in pixels (width × height). 400 megapixels is far beyond any camera the
/// method targets and keeps a single `f32` copy under 1.6 GB.
pub const MAX_PIXELS: u64 = 400_000_000;

/// What can go wrong when an image is built or read.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be opened or read.
    #[error("cannot read {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// The bytes are not an image in a supported format, or are corrupt.
    #[error("cannot decode {path}: {message}")]
    Decode { path: String, message: String },
    /// Zero width or height.
    #[error("image is empty ({width}×{height})")]
    Empty { width: usize, height: usize },
    /// More than [`MAX_PIXELS`] pixels.
    #[error("image is too large ({width}×{height} > {MAX_PIXELS} pixels)")]
    TooLarge { width: usize, height: usize },
    /// The buffer length does not match width × height.
    #[error("buffer holds {len} values, expected {expected} for {width}×{height}")]
    BadBuffer {
        len: usize,
        expected: usize,
        width: usize,
        height: usize,
    },
}

/// A single-channel image with `f32` intensities, stored row-major (`data[y * width + x]`).
///
/// Intensities keep the scale of the source (0–255 for 8-bit input, 0–65535 for 16-bit, whatever a
/// float buffer holds): every stage of the pipeline is invariant to an affine change of intensity.
#[derive(Clone, Debug, PartialEq)]
pub struct GrayImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

fn check_size(width: usize, height: usize) -> Result<(), ImageError> {
    if width == 0 || height == 0 {
        return Err(ImageError::Empty { width, height });
    }
    if (width as u64) * (height as u64) > MAX_PIXELS {
        return Err(ImageError::TooLarge { width, height });
    }
    Ok(())
}

impl GrayImage {
    /// Wraps a row-major `f32` buffer of `width × height` values.
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Result<Self, ImageError> {
        check_size(width, height)?;
        let expected = width * height;
        if data.len() != expected {
            return Err(ImageError::BadBuffer {
                len: data.len(),
                expected,
                width,
                height,
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Builds an image from any row-major buffer of values convertible to `f32` (u8, u16, f32 …).
    pub fn from_slice<T: Copy + Into<f32>>(
        width: usize,
        height: usize,
        data: &[T],
    ) -> Result<Self, ImageError> {
        check_size(width, height)?;
        let expected = width * height;
        if data.len() != expected {
            return Err(ImageError::BadBuffer {
                len: data.len(),
                expected,
                width,
                height,
            });
        }
        Ok(Self {
            width,
            height,
            data: data.iter().map(|&v| v.into()).collect(),
        })
    }

    /// An image of the given size filled with `value`.
    pub fn filled(width: usize, height: usize, value: f32) -> Result<Self, ImageError> {
        check_size(width, height)?;
        Ok(Self {
            width,
            height,
            data: vec![value; width * height],
        })
    }

    /// Converts a decoded image: 8- and 16-bit grey or colour, or float; colour is converted to
    /// luma (Rec. 709 weights, as the `image` crate does), alpha is dropped.
    pub fn from_dynamic(img: &image::DynamicImage) -> Result<Self, ImageError> {
        use image::DynamicImage as D;
        let (w, h) = (img.width() as usize, img.height() as usize);
        check_size(w, h)?;
        match img {
            D::ImageLuma8(b) => Self::from_slice(w, h, b.as_raw()),
            D::ImageLuma16(b) => Self::from_slice(w, h, b.as_raw()),
            D::ImageRgb8(b) => Self::from_rgb8::<3>(w, h, b.as_raw(), img),
            D::ImageRgba8(b) => Self::from_rgb8::<4>(w, h, b.as_raw(), img),
            D::ImageLumaA8(_) => Self::from_slice(w, h, img.to_luma8().as_raw()),
            D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
                Self::from_slice(w, h, img.to_luma16().as_raw())
            }
            _ => Self::from_vec(w, h, img.to_luma32f().into_raw()),
        }
    }

    /// The 8-bit luma of `CH`-channel RGB(A) pixels `raw` (alpha ignored), bit-identical to the
    /// `image` crate's `to_luma8` of `img` (which holds the same pixels), and twice as fast as it
    /// followed by the conversion to `f32` (17 against 35 ms on the 9-megapixel `curve_6.jpg`):
    /// `round(255 · (k_r r + k_g g + k_b b))` with each channel scaled to [0, 1], the weights `k`
    /// of the image's colour space and the same `f32` operations in the same order. The crate
    /// rounds through `roundf`, a library call per pixel on baseline x86-64; here the rounding
    /// is a few comparisons, which vectorize. Bit-identical matters: on real photos some corners
    /// sit where a one-level change of a few pixels switches how they are refined
    /// (`BENCHMARKS.md`, "grey conversion").
    fn from_rgb8<const CH: usize>(
        width: usize,
        height: usize,
        raw: &[u8],
        img: &image::DynamicImage,
    ) -> Result<Self, ImageError> {
        let Some(k) = luma_weights(img.color_space()) else {
            return Self::from_slice(width, height, img.to_luma8().as_raw());
        };
        let mut data = vec![0.0f32; width * height];
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 support was just checked at run time.
            unsafe { luma_rgb8_avx2::<CH>(raw, k, &mut data) };
            return Self::from_vec(width, height, data);
        }
        luma_rgb8::<CH>(raw, k, &mut data);
        Self::from_vec(width, height, data)
    }

    /// Reads and decodes an image file (any format the `image` crate was built with: PNG, JPEG,
    /// TIFF, BMP, PNM, WebP, GIF), checking its size before the pixels are decoded.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, ImageError> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let reader = image::ImageReader::open(path)
            .map_err(|source| ImageError::Io {
                path: name.clone(),
                source,
            })?
            .with_guessed_format()
            .map_err(|source| ImageError::Io {
                path: name.clone(),
                source,
            })?;
        let decode_err = |e: image::ImageError| ImageError::Decode {
            path: name.clone(),
            message: e.to_string(),
        };
        let (w, h) = reader.into_dimensions().map_err(decode_err)?;
        check_size(w as usize, h as usize)?;
        let reader = image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|source| ImageError::Io {
                path: name.clone(),
                source,
            })?;
        let mut reader = reader;
        reader.no_limits();
        let img = reader.decode().map_err(decode_err)?;
        Self::from_dynamic(&img)
    }

    /// Width in pixels.
    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }

    /// The row-major pixel buffer.
    #[inline]
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Mutable access to the row-major pixel buffer.
    #[inline]
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// Row `y` as a slice.
    #[inline]
    pub fn row(&self, y: usize) -> &[f32] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Intensity of pixel `(x, y)`. Panics when out of bounds, like slice indexing.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Intensity of pixel `(x, y)`, or `None` outside the image.
    #[inline]
    pub fn get_checked(&self, x: isize, y: isize) -> Option<f32> {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            None
        } else {
            Some(self.data[y as usize * self.width + x as usize])
        }
    }

    /// Bilinear interpolation at image coordinate `(x, y)` (pixel centres at integers), or `None`
    /// when the four neighbouring pixel centres are not all inside the image.
    #[inline]
    pub fn bilinear(&self, x: f32, y: f32) -> Option<f32> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            // Exactly on the last row or column is still inside.
            if x0 < self.width && y0 < self.height && x == x0 as f32 && y == y0 as f32 {
                return Some(self.get(x0, y0));
            }
            return None;
        }
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let i = y0 * self.width + x0;
        let (a, b) = (self.data[i], self.data[i + 1]);
        let (c, d) = (self.data[i + self.width], self.data[i + self.width + 1]);
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        Some(top + (bottom - top) * fy)
    }

    /// Minimum and maximum intensity.
    pub fn min_max(&self) -> (f32, f32) {
        self.data
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    }

    /// Converts to an 8-bit image, mapping `lo..=hi` to `0..=255` with rounding and clamping.
    pub fn to_luma8(&self, lo: f32, hi: f32) -> image::GrayImage {
        let scale = 255.0 / (hi - lo).max(f32::MIN_POSITIVE);
        let buf = self
            .data
            .iter()
            .map(|&v| ((v - lo) * scale).round().clamp(0.0, 255.0) as u8)
            .collect();
        image::GrayImage::from_raw(self.width as u32, self.height as u32, buf)
            .expect("buffer size matches")
    }
}

/// The luma weights `[k_r, k_g, k_b]` that the `image` crate uses for the colour space `cicp`,
/// read back exactly from its own conversion of three unit pixels in `f32` (one multiply-add by
/// 1 each, so exact); `None` if the crate refuses that colour space for an RGB image.
fn luma_weights(cicp: image::metadata::Cicp) -> Option<[f32; 3]> {
    let mut k = [0.0; 3];
    for (c, kc) in k.iter_mut().enumerate() {
        let mut px = vec![0.0f32; 3];
        px[c] = 1.0;
        let mut probe = image::DynamicImage::ImageRgb32F(image::ImageBuffer::from_raw(1, 1, px)?);
        probe.set_color_space(cicp).ok()?;
        *kc = probe.to_luma32f().as_raw()[0];
    }
    Some(k)
}

/// The body of [`GrayImage::from_rgb8`]: the luma of each `CH`-channel pixel of `raw` with the
/// weights `k`, written to `out`.
#[inline(always)]
fn luma_rgb8<const CH: usize>(raw: &[u8], k: [f32; 3], out: &mut [f32]) {
    let luma = |px: &[u8]| {
        const SCALE: f32 = 1.0 / 255.0;
        let [r, g, b] = [px[0], px[1], px[2]].map(|c| f32::from(c) * SCALE);
        let y = 255.0 * mul_acc(mul_acc(mul_acc(0.0, r, k[0]), g, k[1]), b, k[2]);
        // `f32::round` (half away from zero) without its library call, for 0 ≤ y < 2²²: adding
        // and removing 2²³ rounds to an integer (to even), a correction makes it the floor, and
        // the fraction, exact, decides.
        const MAGIC: f32 = 8_388_608.0;
        let f = (y + MAGIC) - MAGIC;
        let f = if f > y { f - 1.0 } else { f };
        let t = if y - f >= 0.5 { f + 1.0 } else { f };
        t.clamp(0.0, 255.0)
    };
    for (px, v) in raw.chunks_exact(CH).zip(out) {
        *v = luma(px);
    }
}

/// [`luma_rgb8`] compiled for AVX2 (eight lanes instead of SSE2's four). Its multiply-adds are
/// fused only if [`mul_acc`] says so, as in the baseline build, so the two give the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn luma_rgb8_avx2<const CH: usize>(raw: &[u8], k: [f32; 3], out: &mut [f32]) {
    luma_rgb8::<CH>(raw, k, out)
}

/// `acc + a · b` exactly as the `image` crate computes it: fused where the build target has FMA
/// (its `multiply_accumulate` decides at compile time, on the same target features).
#[inline(always)]
fn mul_acc(acc: f32, a: f32, b: f32) -> f32 {
    if cfg!(any(
        all(
            any(target_arch = "x86", target_arch = "x86_64"),
            target_feature = "fma"
        ),
        all(target_arch = "aarch64", target_feature = "neon")
    )) {
        a.mul_add(b, acc)
    } else {
        acc + a * b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_empty_and_mismatched_buffers() {
        assert!(matches!(
            GrayImage::from_vec(0, 5, vec![]),
            Err(ImageError::Empty { .. })
        ));
        assert!(matches!(
            GrayImage::from_slice(3, 3, &[0u8; 8]),
            Err(ImageError::BadBuffer { .. })
        ));
        assert!(matches!(
            GrayImage::filled(100_000, 100_000, 0.0),
            Err(ImageError::TooLarge { .. })
        ));
    }

    /// Every 8-bit RGB triple (and RGBA, with varying alpha) gives the same grey level as the
    /// `image` crate's own conversion.
    #[test]
    fn colour_conversion_matches_the_image_crate_on_every_rgb_value() {
        // The fast path is taken (not the fallback to the crate's own conversion).
        let k = luma_weights(image::metadata::Cicp::SRGB).unwrap();
        assert!((k[0] - 0.2126).abs() < 1e-4 && (k[1] - 0.7152).abs() < 1e-4);
        let rgb: Vec<u8> = (0..1u32 << 24)
            .flat_map(|v| [(v >> 16) as u8, (v >> 8) as u8, v as u8])
            .collect();
        let img = image::DynamicImage::ImageRgb8(
            image::RgbImage::from_raw(4096, 4096, rgb.clone()).unwrap(),
        );
        let ours = GrayImage::from_dynamic(&img).unwrap();
        let theirs = img.to_luma8();
        let differ = ours
            .data()
            .iter()
            .zip(theirs.as_raw())
            .filter(|(a, b)| **a != f32::from(**b))
            .count();
        assert_eq!(differ, 0);
        // The baseline build's loop too, when the run-time dispatch took the AVX2 one.
        let mut baseline = vec![0.0; 1 << 24];
        luma_rgb8::<3>(&rgb, k, &mut baseline);
        assert!(baseline == ours.data());
        let rgba: Vec<u8> = rgb
            .chunks_exact(3)
            .step_by(7)
            .enumerate()
            .flat_map(|(i, p)| [p[0], p[1], p[2], (i * 37) as u8])
            .collect();
        let n = rgba.len() as u32 / 4;
        let img = image::DynamicImage::ImageRgba8(image::RgbaImage::from_raw(n, 1, rgba).unwrap());
        let ours = GrayImage::from_dynamic(&img).unwrap();
        let theirs = img.to_luma8();
        assert!(ours
            .data()
            .iter()
            .zip(theirs.as_raw())
            .all(|(a, b)| *a == f32::from(*b)));
    }

    #[test]
    fn bilinear_uses_pixel_centre_convention() {
        let img = GrayImage::from_vec(2, 2, vec![0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(img.bilinear(0.0, 0.0), Some(0.0));
        assert_eq!(img.bilinear(0.5, 0.0), Some(0.5));
        assert_eq!(img.bilinear(0.5, 0.5), Some(1.5));
        assert_eq!(img.bilinear(1.0, 1.0), Some(3.0));
        assert_eq!(img.bilinear(1.01, 0.0), None);
        assert_eq!(img.bilinear(-0.01, 0.0), None);
        assert_eq!(img.bilinear(f32::NAN, 0.0), None);
    }

    #[test]
    fn missing_file_is_an_io_error() {
        let err = GrayImage::open("/nonexistent/x.png").unwrap_err();
        assert!(matches!(err, ImageError::Io { .. }));
        assert!(err.to_string().contains("/nonexistent/x.png"));
    }
}
