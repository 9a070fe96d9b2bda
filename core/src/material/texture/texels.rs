//! Decoded texture images: texels of 8 or 16 bits or floats ([`TexelImage`]), their colour spaces, and the
//! decoder of image files (PNG, JPEG, OpenEXR, BMP, PNM) through the `image` crate.

use crate::Rgb;
use crate::input::InputError;
use crate::math::fmath;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How integer texel values map to linear values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ColorSpace {
    /// The sRGB transfer curve (IEC 61966-2-1), the default for colours.
    Srgb,
    /// Values are linear already: `v / max`, the default for bump and normal maps.
    Linear,
}

/// Texel storage of one image: integer or float channels, row-major from the top row, `channels` per texel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Texels {
    /// 8-bit values.
    U8(Vec<u8>),
    /// 16-bit values.
    U16(Vec<u16>),
    /// Linear float values.
    F32(Vec<f32>),
}

/// The decoded texels of one image file: what travels to workers as a texture blob.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TexelImage {
    /// Width in texels (> 0).
    pub width: u32,
    /// Height in texels (> 0).
    pub height: u32,
    /// 1 (grey) or 3 (RGB) values per texel.
    pub channels: u8,
    /// The values, `width · height · channels` of them.
    pub texels: Texels,
}

/// Why a [`TexelImage`] is not usable.
#[derive(Debug, thiserror::Error)]
#[error("texture image of {width}×{height}×{channels} texels holding {len} values: {why}")]
pub struct TexelImageError {
    width: u32,
    height: u32,
    channels: u8,
    len: usize,
    why: &'static str,
}

impl TexelImage {
    /// Checks the sizes: both sides > 0, 1 or 3 channels, and exactly `width · height · channels` values; float
    /// values finite and ≥ 0.
    pub fn check(&self) -> Result<(), TexelImageError> {
        let len = match &self.texels {
            Texels::U8(v) => v.len(),
            Texels::U16(v) => v.len(),
            Texels::F32(v) => v.len(),
        };
        let err =
            |why| Err(TexelImageError { width: self.width, height: self.height, channels: self.channels, len, why });
        if self.width == 0 || self.height == 0 {
            return err("an image needs at least one texel");
        }
        if self.channels != 1 && self.channels != 3 {
            return err("expected 1 or 3 channels");
        }
        let want = u64::from(self.width) * u64::from(self.height) * u64::from(self.channels);
        if len as u64 != want {
            return err("the number of values does not match the size");
        }
        if let Texels::F32(v) = &self.texels
            && v.iter().any(|x| !(x.is_finite() && *x >= 0.0))
        {
            return err("float texels must be finite and ≥ 0");
        }
        Ok(())
    }

    /// The linear value of texel `(i, j)` (column, row from the top), integer values decoded with `space`.
    /// Indices must be in range (the lookups fold them first).
    #[inline]
    pub fn texel(&self, i: u32, j: u32, space: ColorSpace) -> Rgb {
        let c = usize::from(self.channels);
        let at = (j as usize * self.width as usize + i as usize) * c;
        // One match per texel, not per channel; indices past the end (impossible after `check`) read 0.
        let [r, g, b] = match &self.texels {
            Texels::U8(v) => {
                let raw = read3(v, at, c);
                match space {
                    ColorSpace::Linear => raw.map(|x| f32::from(x) / 255.0),
                    ColorSpace::Srgb => {
                        let table = srgb_table();
                        raw.map(|x| table[usize::from(x)])
                    }
                }
            }
            Texels::U16(v) => read3(v, at, c).map(|x| decode_unit(f32::from(x) / 65535.0, space)),
            Texels::F32(v) => read3(v, at, c),
        };
        Rgb::new(r, g, b)
    }

    /// Bytes of texel storage.
    pub fn texel_bytes(&self) -> usize {
        match &self.texels {
            Texels::U8(v) => v.len(),
            Texels::U16(v) => 2 * v.len(),
            Texels::F32(v) => 4 * v.len(),
        }
    }

    /// How many values exceed 1, and the largest, when any does. Only float texels can: integer ones decode
    /// into `[0, 1]` in either colour space, so they are not scanned.
    pub fn above_one(&self) -> Option<(usize, f32)> {
        let Texels::F32(v) = &self.texels else { return None };
        let over = v.iter().filter(|&&x| x > 1.0).count();
        (over > 0).then(|| (over, v.iter().copied().fold(0.0, f32::max)))
    }
}

/// The values of one texel at `at`: three channels, or one repeated; 0 past the end.
#[inline]
fn read3<T: Copy + Default>(v: &[T], at: usize, channels: usize) -> [T; 3] {
    if channels == 1 {
        [v.get(at).copied().unwrap_or_default(); 3]
    } else {
        match v.get(at..at + 3) {
            Some(&[r, g, b]) => [r, g, b],
            _ => [T::default(); 3],
        }
    }
}

/// The sRGB decodings of the 8-bit values, built once with the portable `powf` (the same bits on every
/// architecture).
fn srgb_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| srgb_decode(i as f32 / 255.0)))
}

/// A value in `[0, 1]` decoded with `space`.
#[inline]
fn decode_unit(x: f32, space: ColorSpace) -> f32 {
    match space {
        ColorSpace::Linear => x,
        ColorSpace::Srgb => srgb_decode(x),
    }
}

/// The sRGB transfer curve, encoded value to linear (IEC 61966-2-1): `x/12.92` up to 0.04045, else
/// `((x + 0.055)/1.055)^2.4`.
pub fn srgb_decode(x: f32) -> f32 {
    if x <= 0.040_45 { x / 12.92 } else { fmath::powf((x + 0.055) / 1.055, 2.4) }
}

/// The largest side of a texture image, in texels.
pub const MAX_TEXTURE_SIDE: u32 = 32_768;

/// Why an image file cannot be a texture.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    /// The file cannot be read (or is too large, or not a regular file).
    #[error("cannot read the image: {0}")]
    Read(#[from] InputError),
    /// The bytes are not an image this build decodes (PNG, JPEG, OpenEXR, BMP, PNM).
    #[error("cannot decode the image: {0}")]
    Decode(String),
    /// The decoded image is unusable.
    #[error("{0}")]
    Invalid(String),
}

/// Decodes one image file of at most `limit` bytes (both the file and its decoded texels).
pub fn decode_file(path: &Path, limit: u64) -> Result<TexelImage, TextureError> {
    let bytes = crate::input::read_regular(path, limit, "limits.texture_mib")?;
    decode(&bytes, limit)
}

/// Decodes image bytes (PNG, JPEG, OpenEXR, Radiance HDR, BMP or PNM, told by their content) into texels: grey images keep
/// one channel, others keep red, green and blue (alpha is dropped); 8- and 16-bit values stay integers (their
/// colour space is the texture's business), float values stay floats.
pub fn decode(bytes: &[u8], limit: u64) -> Result<TexelImage, TextureError> {
    let img = decode_dynamic(bytes, limit)?;
    let (width, height) = (img.width(), img.height());
    use image::DynamicImage as D;
    let (channels, texels) = match img {
        D::ImageLuma8(i) => (1, Texels::U8(i.into_raw())),
        D::ImageLumaA8(_) => (1, Texels::U8(img.to_luma8().into_raw())),
        D::ImageRgb8(i) => (3, Texels::U8(i.into_raw())),
        D::ImageLuma16(i) => (1, Texels::U16(i.into_raw())),
        D::ImageLumaA16(_) => (1, Texels::U16(img.to_luma16().into_raw())),
        D::ImageRgb16(i) => (3, Texels::U16(i.into_raw())),
        D::ImageRgba16(_) => (3, Texels::U16(img.to_rgb16().into_raw())),
        D::ImageRgb32F(i) => (3, Texels::F32(i.into_raw())),
        D::ImageRgba32F(_) => (3, Texels::F32(img.to_rgb32f().into_raw())),
        // RGBA8 and any layout added later.
        other => (3, Texels::U8(other.to_rgb8().into_raw())),
    };
    let image = TexelImage { width, height, channels, texels };
    image.check().map_err(|e| TextureError::Invalid(e.to_string()))?;
    Ok(image)
}

/// The alpha channel of image bytes (as [`decode`] reads them), as a one-channel image of linear values (alpha is
/// never sRGB-encoded): 8- and 16-bit values stay integers, float values floats. `None` when the image has no
/// alpha channel, so is opaque everywhere.
pub fn decode_alpha(bytes: &[u8], limit: u64) -> Result<Option<TexelImage>, TextureError> {
    let img = decode_dynamic(bytes, limit)?;
    if !img.color().has_alpha() {
        return Ok(None);
    }
    let (width, height) = (img.width(), img.height());
    let texels = match img.color().bytes_per_pixel() / img.color().channel_count() {
        1 => Texels::U8(img.to_rgba8().pixels().map(|p| p.0[3]).collect()),
        2 => Texels::U16(img.to_rgba16().pixels().map(|p| p.0[3]).collect()),
        _ => Texels::F32(img.to_rgba32f().pixels().map(|p| p.0[3]).collect()),
    };
    let image = TexelImage { width, height, channels: 1, texels };
    image.check().map_err(|e| TextureError::Invalid(e.to_string()))?;
    Ok(Some(image))
}

/// The `image` crate's decoding of `bytes`, within [`MAX_TEXTURE_SIDE`] a side and `limit` bytes.
fn decode_dynamic(bytes: &[u8], limit: u64) -> Result<image::DynamicImage, TextureError> {
    if bytes.is_empty() {
        return Err(TextureError::Invalid("the file is empty (0 bytes)".into()));
    }
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| TextureError::Decode(e.to_string()))?;
    if reader.format().is_none() {
        return Err(TextureError::Decode("not a PNG, JPEG, OpenEXR, Radiance HDR, BMP or PNM image".into()));
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    limits.max_alloc = Some(limit);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| match e {
        image::ImageError::Limits(l) => TextureError::Invalid(format!(
            "the image is larger than allowed ({l}): at most {MAX_TEXTURE_SIDE} texels a side and \
             limits.texture_mib decoded"
        )),
        e => TextureError::Decode(e.to_string()),
    })?;
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Err(TextureError::Invalid(format!("the image is {width}×{height}: it needs at least one texel")));
    }
    Ok(img)
}
