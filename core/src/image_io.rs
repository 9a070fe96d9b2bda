//! Images: linear f32 RGB in memory; OpenEXR (linear, for analysis) or, tone-mapped, PNG, PPM (P6) and BMP
//! on disk. The format comes from the file extension.

use crate::math::fmath;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A linear RGB image, row-major, 3 floats per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `3 × width × height` floats.
    pub pixels: Vec<f32>,
}

/// Why an image could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The extension names no format we write.
    #[error("{path}: unknown image format: expected the extension .exr, .png, .ppm or .bmp")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The file system or the encoder failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// Image file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// OpenEXR, linear f32.
    Exr,
    /// PNG, 8-bit sRGB.
    Png,
    /// Binary PPM (P6), 8-bit sRGB.
    Ppm,
    /// BMP, 8-bit sRGB.
    Bmp,
}

impl Format {
    /// The format named by a path's extension.
    pub fn from_path(path: &Path) -> Result<Format, ImageError> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("exr") => Ok(Format::Exr),
            Some("png") => Ok(Format::Png),
            Some("ppm") => Ok(Format::Ppm),
            Some("bmp") => Ok(Format::Bmp),
            _ => Err(ImageError::UnknownFormat { path: path.into() }),
        }
    }
}

/// The sRGB transfer curve of a linear value in [0, 1].
#[inline]
pub fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * fmath::powf(x, 1.0 / 2.4) - 0.055 }
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, pixels: vec![0.0; 3 * width as usize * height as usize] }
    }

    /// 8-bit sRGB after scaling by 2^`exposure` and clamping to [0, 1].
    pub fn to_srgb8(&self, exposure: f32) -> Vec<u8> {
        let scale = exposure.exp2();
        self.pixels
            .iter()
            .map(|&v| {
                let v = if v.is_finite() { (v * scale).clamp(0.0, 1.0) } else { 0.0 };
                (srgb_encode(v) * 255.0 + 0.5) as u8
            })
            .collect()
    }

    /// Writes the image; the format comes from the extension, `exposure` (stops) applies to 8-bit formats.
    pub fn write(&self, path: &Path, exposure: f32) -> Result<(), ImageError> {
        let io = |e: &dyn std::fmt::Display| ImageError::Io { path: path.into(), message: e.to_string() };
        match Format::from_path(path)? {
            Format::Exr => {
                let img = image::Rgb32FImage::from_raw(self.width, self.height, self.pixels.clone())
                    .ok_or_else(|| io(&"pixel buffer does not match the size"))?;
                img.save_with_format(path, image::ImageFormat::OpenExr).map_err(|e| io(&e))
            }
            Format::Ppm => {
                let mut f = std::io::BufWriter::new(std::fs::File::create(path).map_err(|e| io(&e))?);
                write!(f, "P6\n{} {}\n255\n", self.width, self.height).map_err(|e| io(&e))?;
                f.write_all(&self.to_srgb8(exposure)).map_err(|e| io(&e))?;
                f.flush().map_err(|e| io(&e))
            }
            fmt => {
                let img = image::RgbImage::from_raw(self.width, self.height, self.to_srgb8(exposure))
                    .ok_or_else(|| io(&"pixel buffer does not match the size"))?;
                let f = if fmt == Format::Png { image::ImageFormat::Png } else { image::ImageFormat::Bmp };
                img.save_with_format(path, f).map_err(|e| io(&e))
            }
        }
    }

    /// Reads a linear image (EXR; 8-bit formats are decoded from sRGB).
    pub fn read(path: &Path) -> Result<Image, ImageError> {
        let img = image::open(path).map_err(|e| ImageError::Io { path: path.into(), message: e.to_string() })?;
        let rgb = img.into_rgb32f();
        Ok(Image { width: rgb.width(), height: rgb.height(), pixels: rgb.into_raw() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_format_round_trips() {
        let dir = std::env::temp_dir().join(format!("photon-image-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = Image::new(4, 3);
        for (i, v) in img.pixels.iter_mut().enumerate() {
            *v = i as f32 / 36.0;
        }
        let exr = dir.join("a.exr");
        img.write(&exr, 0.0).unwrap();
        assert_eq!(Image::read(&exr).unwrap(), img);
        for ext in ["png", "ppm", "bmp"] {
            let p = dir.join(format!("a.{ext}"));
            img.write(&p, 0.0).unwrap();
            let back = Image::read(&p).unwrap();
            assert_eq!((back.width, back.height), (4, 3));
            let raw = image::open(&p).unwrap().into_rgb8().into_raw();
            assert_eq!(raw, img.to_srgb8(0.0), "{ext}");
        }
        assert!(matches!(img.write(&dir.join("a.tiff"), 0.0), Err(ImageError::UnknownFormat { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn srgb_curve_endpoints() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_encode(0.5) - 0.735_357).abs() < 1e-4);
    }
}
