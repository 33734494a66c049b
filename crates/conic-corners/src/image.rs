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
            D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => {
                Self::from_slice(w, h, img.to_luma8().as_raw())
            }
            D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
                Self::from_slice(w, h, img.to_luma16().as_raw())
            }
            _ => Self::from_vec(w, h, img.to_luma32f().into_raw()),
        }
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
