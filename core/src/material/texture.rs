//! Textures: the colours of a material that vary over a surface, and the images that bump and normal maps
//! read.
//!
//! In the scene file a colour is one of
//! - a constant: a number (grey) or `[r, g, b]` (linear RGB);
//! - an image: `{ image = "wood.png", scale = 1, offset = [0, 0], wrap = "repeat", filter = "bilinear",
//!   colorspace = "srgb" }` (only `image` is required);
//! - a checkerboard: `{ checker = [A, B], scale = 8 }`, with A and B constants.
//!
//! ## Conventions
//! - Texture coordinates `(u, v)` follow OBJ's `vt`: `u` runs left to right across the image and `v` bottom to
//!   top, so `(0, 0)` is the image's bottom-left corner and `(0, 1)` its top-left. Every shape's coordinates
//!   (`crate::geometry`) keep an image upright and unmirrored when seen from the front.
//! - A lookup reads the image at `(u·scale_u + offset_u, v·scale_v + offset_v)`; `wrap = "repeat"` tiles it,
//!   `"clamp"` extends its edge texels. `filter = "nearest"` takes the texel under the point, `"bilinear"`
//!   interpolates the four texels around it (texel centres at `(i + ½)/width`).
//! - 8- and 16-bit images are sRGB-encoded unless `colorspace = "linear"`: each value is decoded with the
//!   sRGB curve (IEC 61966-2-1) to linear. Float images (OpenEXR) are linear. Bump and normal maps hold data,
//!   not colour: their default is `"linear"`.
//! - A checker's cell is `(⌊u·scale_u⌋ + ⌊v·scale_v⌋) mod 2`: even cells are A, odd cells B.
//!
//! The texels themselves live in [`TexelImage`]s, which travel to workers as their own content-addressed blobs
//! (`crate::prepare::textures`); a texture names its image by a slot in the prepared scene's list.

use crate::Rgb;
use crate::error::FieldError;
use crate::geometry::NONE;
use crate::input::InputError;
use crate::math::fmath;
use glam::{Vec2, Vec3A};
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::ser::{SerializeMap, SerializeSeq};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::path::{Path, PathBuf};

/// A colour that may vary over a surface (see the module docs for the scene-file forms).
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// The same colour everywhere.
    Constant(Rgb),
    /// A checkerboard of two colours.
    Checker {
        /// The colour of even cells.
        a: Rgb,
        /// The colour of odd cells.
        b: Rgb,
        /// Cells per unit of `u` and of `v`.
        scale: Vec2,
    },
    /// An image.
    Image(ImageRef),
}

/// How a lookup outside `[0, 1]` is folded back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wrap {
    /// Tile the image.
    #[default]
    Repeat,
    /// Extend the edge texels.
    Clamp,
}

/// How texels are reconstructed between their centres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Filter {
    /// The texel under the point.
    Nearest,
    /// The four texels around the point, weighted by distance.
    #[default]
    Bilinear,
}

/// How integer texel values map to linear values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ColorSpace {
    /// The sRGB transfer curve (IEC 61966-2-1), the default for colours.
    Srgb,
    /// Values are linear already: `v / max`, the default for bump and normal maps.
    Linear,
}

/// A reference to an image with the way to read it.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageRef {
    /// The file, as the scene writes it (relative to the scene's folder). Not part of the binary form: the
    /// image travels by `slot`.
    pub file: PathBuf,
    /// Index of the image in the prepared scene's texture list, or [`NONE`] before the scene is prepared.
    pub slot: u32,
    /// Multiplies `(u, v)` before the lookup.
    pub scale: Vec2,
    /// Added to `(u, v)·scale`.
    pub offset: Vec2,
    /// Folding outside `[0, 1]`.
    pub wrap: Wrap,
    /// Reconstruction.
    pub filter: Filter,
    /// Decoding of integer texels; `None` is the default of the image's role (sRGB for colours, linear for
    /// bump and normal maps).
    pub colorspace: Option<ColorSpace>,
}

impl ImageRef {
    /// The texel coordinates (continuous, in texel units with texel centres at `i + ½`) of `uv`, with `v` up.
    #[inline]
    fn texel_coords(&self, uv: Vec2, w: u32, h: u32) -> (f32, f32) {
        let s = uv.x * self.scale.x + self.offset.x;
        let t = uv.y * self.scale.y + self.offset.y;
        // A NaN coordinate (a degenerate hit) reads the corner, never out of bounds.
        let s = if s.is_finite() { s } else { 0.0 };
        let t = if t.is_finite() { t } else { 0.0 };
        (s * w as f32, (1.0 - t) * h as f32)
    }

    /// The linear value at `uv` in `image`, decoded with `space`.
    #[inline]
    pub fn lookup(&self, image: &TexelImage, uv: Vec2, space: ColorSpace) -> Rgb {
        let (w, h) = (image.width, image.height);
        let (x, y) = self.texel_coords(uv, w, h);
        match self.filter {
            Filter::Nearest => {
                let (i, j) = (self.fold(x.floor(), w), self.fold(y.floor(), h));
                image.texel(i, j, space)
            }
            Filter::Bilinear => {
                let (x, y) = (x - 0.5, y - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                let (i0, i1) = (self.fold(x0, w), self.fold(x0 + 1.0, w));
                let (j0, j1) = (self.fold(y0, h), self.fold(y0 + 1.0, h));
                // `a + (b − a)·f`: exactly `a` where neighbours are equal, so a flat image reads flat.
                let lerp = |a: Rgb, b: Rgb, f: f32| a + (b - a) * f;
                let top = lerp(image.texel(i0, j0, space), image.texel(i1, j0, space), fx);
                let bottom = lerp(image.texel(i0, j1, space), image.texel(i1, j1, space), fx);
                lerp(top, bottom, fy)
            }
        }
    }

    /// A texel index for the continuous index `x` (already floored) of an axis of `n` texels.
    #[inline]
    fn fold(&self, x: f32, n: u32) -> u32 {
        let n_f = n as f32;
        let i = match self.wrap {
            Wrap::Repeat => x - (x / n_f).floor() * n_f,
            Wrap::Clamp => x.clamp(0.0, n_f - 1.0),
        };
        // Float rounding can land `Repeat` on n itself; huge coordinates saturate in the cast.
        (i as u32).min(n - 1)
    }
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

impl Texture {
    /// A grey constant.
    pub const fn grey(v: f32) -> Self {
        Texture::Constant(Rgb::splat(v))
    }

    /// The colour at texture coordinates `uv` and point `p`, reading images from `images` (the prepared scene's
    /// texture list, which every slot indexes: see `crate::prepare::Prepared::textures`).
    #[inline]
    pub fn eval(&self, uv: Vec2, p: Vec3A, images: &[TexelImage]) -> Rgb {
        let _ = p;
        match self {
            Texture::Constant(c) => *c,
            Texture::Checker { a, b, scale } => {
                let cell = (uv.x * scale.x).floor() + (uv.y * scale.y).floor();
                // rem_euclid of a float keeps negative cells alternating across 0.
                if cell.rem_euclid(2.0) < 1.0 { *a } else { *b }
            }
            Texture::Image(r) => match images.get(r.slot as usize) {
                // Reflectances stay ≤ 1 whatever the texel (see `validate_reflectance`).
                Some(img) => r.lookup(img, uv, r.colorspace.unwrap_or(ColorSpace::Srgb)).min(Rgb::ONE),
                // Every slot is checked against the list when the scene is assembled.
                None => Rgb::ZERO,
            },
        }
    }

    /// The largest value of any channel anywhere, for constants and checkers; 1 for images (their texels are
    /// clamped to 1 when read as reflectances).
    pub fn max_value(&self) -> f32 {
        match self {
            Texture::Constant(c) => c.max_element(),
            Texture::Checker { a, b, .. } => a.max_element().max(b.max_element()),
            Texture::Image(_) => 1.0,
        }
    }

    /// The image this texture reads, if any.
    pub fn image(&self) -> Option<&ImageRef> {
        match self {
            Texture::Image(r) => Some(r),
            _ => None,
        }
    }

    /// The image this texture reads, if any, for assigning its slot.
    pub fn image_mut(&mut self) -> Option<&mut ImageRef> {
        match self {
            Texture::Image(r) => Some(r),
            _ => None,
        }
    }

    /// Whether the value depends on the texture coordinates (a shape must then provide them).
    pub fn needs_uv(&self) -> bool {
        !matches!(self, Texture::Constant(_))
    }

    /// Checks that the texture is a reflectance: every constant finite and in `[0, 1]`, scales and offsets
    /// finite. Image texels above 1 (float images) are clamped to 1 when read; the loader reports how many.
    /// The error names `field`.
    pub fn validate_reflectance(&self, field: &str) -> Result<(), FieldError> {
        let check = |c: &Rgb, field: &str| {
            if c.to_array().iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)) {
                Ok(())
            } else {
                Err(FieldError::new(field, format!("expected values in [0, 1], got [{}, {}, {}]", c.x, c.y, c.z)))
            }
        };
        match self {
            Texture::Constant(c) => check(c, field),
            Texture::Checker { a, b, scale } => {
                check(a, &format!("{field}.checker[0]"))?;
                check(b, &format!("{field}.checker[1]"))?;
                check_scale(*scale, &format!("{field}.scale"))
            }
            Texture::Image(r) => r.validate(field),
        }
    }
}

impl ImageRef {
    /// Checks the scale (finite, non-zero) and offset (finite) and that a file is named.
    pub fn validate(&self, field: &str) -> Result<(), FieldError> {
        if self.file.as_os_str().is_empty() {
            return Err(FieldError::new(format!("{field}.image"), "expected a file name, got an empty string"));
        }
        check_scale(self.scale, &format!("{field}.scale"))?;
        if !(self.offset.x.is_finite() && self.offset.y.is_finite()) {
            return Err(FieldError::new(
                format!("{field}.offset"),
                format!("expected finite numbers, got [{}, {}]", self.offset.x, self.offset.y),
            ));
        }
        Ok(())
    }
}

fn check_scale(s: Vec2, field: &str) -> Result<(), FieldError> {
    if s.x.is_finite() && s.y.is_finite() && s.x != 0.0 && s.y != 0.0 {
        Ok(())
    } else {
        Err(FieldError::new(field, format!("expected finite non-zero numbers, got [{}, {}]", s.x, s.y)))
    }
}

impl From<f32> for Texture {
    fn from(v: f32) -> Self {
        Texture::grey(v)
    }
}

impl From<[f32; 3]> for Texture {
    fn from(c: [f32; 3]) -> Self {
        Texture::Constant(Rgb::from_array(c))
    }
}

/// The default number of checker cells per unit of `u` and `v`.
pub const DEFAULT_CHECKER_SCALE: f32 = 8.0;

/// The table form of a texture, a bump map or a normal map, as the scene file writes it.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TextureTable {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<PathBuf>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checker: Option<[Texture; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<UvPair>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<[f32; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrap: Option<Wrap>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter: Option<Filter>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colorspace: Option<ColorSpace>,
    /// Bump maps only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strength: Option<f32>,
}

/// A number or a `[u, v]` pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UvPair(pub Vec2);

impl Serialize for UvPair {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.0.x == self.0.y { s.serialize_f32(self.0.x) } else { [self.0.x, self.0.y].serialize(s) }
    }
}

impl<'de> Deserialize<'de> for UvPair {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = UvPair;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or a [u, v] pair")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<UvPair, E> {
                Ok(UvPair(Vec2::splat(v as f32)))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<UvPair, E> {
                Ok(UvPair(Vec2::splat(v as f32)))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<UvPair, E> {
                Ok(UvPair(Vec2::splat(v as f32)))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<UvPair, A::Error> {
                let u: f32 = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(0, &self))?;
                let v: f32 = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(1, &self))?;
                if seq.next_element::<de::IgnoredAny>()?.is_some() {
                    return Err(de::Error::invalid_length(3, &self));
                }
                Ok(UvPair(Vec2::new(u, v)))
            }
        }
        d.deserialize_any(V)
    }
}

impl TextureTable {
    /// The image reference of a table that names an image (bump and normal maps, image textures).
    pub(crate) fn image_ref<E: de::Error>(&self, what: &str) -> Result<ImageRef, E> {
        let Some(file) = self.image.clone() else {
            return Err(E::custom(format!("{what} needs `image = \"FILE\"`")));
        };
        Ok(ImageRef {
            file,
            slot: NONE,
            scale: self.scale.map_or(Vec2::ONE, |s| s.0),
            offset: self.offset.map_or(Vec2::ZERO, Vec2::from_array),
            wrap: self.wrap.unwrap_or_default(),
            filter: self.filter.unwrap_or_default(),
            colorspace: self.colorspace,
        })
    }

    /// The table of an image reference.
    pub(crate) fn of_image(r: &ImageRef) -> Self {
        Self {
            image: Some(r.file.clone()),
            scale: (r.scale != Vec2::ONE).then_some(UvPair(r.scale)),
            offset: (r.offset != Vec2::ZERO).then_some(r.offset.to_array()),
            wrap: (r.wrap != Wrap::default()).then_some(r.wrap),
            filter: (r.filter != Filter::default()).then_some(r.filter),
            colorspace: r.colorspace,
            ..Self::default()
        }
    }
}

/// The binary form of an [`ImageRef`]: everything but the file name.
#[derive(Serialize, Deserialize)]
struct ImageRefBinary {
    slot: u32,
    scale: [f32; 2],
    offset: [f32; 2],
    wrap: Wrap,
    filter: Filter,
    colorspace: Option<ColorSpace>,
}

impl From<&ImageRef> for ImageRefBinary {
    fn from(r: &ImageRef) -> Self {
        Self {
            slot: r.slot,
            scale: r.scale.to_array(),
            offset: r.offset.to_array(),
            wrap: r.wrap,
            filter: r.filter,
            colorspace: r.colorspace,
        }
    }
}

impl From<ImageRefBinary> for ImageRef {
    fn from(b: ImageRefBinary) -> Self {
        Self {
            file: PathBuf::new(),
            slot: b.slot,
            scale: Vec2::from_array(b.scale),
            offset: Vec2::from_array(b.offset),
            wrap: b.wrap,
            filter: b.filter,
            colorspace: b.colorspace,
        }
    }
}

impl Serialize for ImageRef {
    /// Text formats: the scene-file table; binary formats: the slot and the lookup settings.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            TextureTable::of_image(self).serialize(s)
        } else {
            ImageRefBinary::from(self).serialize(s)
        }
    }
}

impl<'de> Deserialize<'de> for ImageRef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            let t = TextureTable::deserialize(d)?;
            if t.checker.is_some() || t.strength.is_some() {
                return Err(de::Error::custom("expected only image, scale, offset, wrap, filter and colorspace"));
            }
            t.image_ref("an image")
        } else {
            Ok(ImageRefBinary::deserialize(d)?.into())
        }
    }
}

/// The binary form of [`Texture`] (serde's default enum representation, which bincode can read).
#[derive(Serialize, Deserialize)]
enum TextureBinary {
    Constant([f32; 3]),
    Checker([f32; 3], [f32; 3], [f32; 2]),
    Image(ImageRefBinary),
}

impl Serialize for Texture {
    /// In text formats a grey constant as a number, any other constant as `[r, g, b]`, a checker or an image as
    /// its table; in binary formats a plain enum.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if !s.is_human_readable() {
            return match self {
                Texture::Constant(c) => TextureBinary::Constant(c.to_array()),
                Texture::Checker { a, b, scale } => {
                    TextureBinary::Checker(a.to_array(), b.to_array(), scale.to_array())
                }
                Texture::Image(r) => TextureBinary::Image(r.into()),
            }
            .serialize(s);
        }
        match self {
            Texture::Constant(c) if c.x == c.y && c.y == c.z => s.serialize_f32(c.x),
            Texture::Constant(c) => {
                let mut seq = s.serialize_seq(Some(3))?;
                for v in c.to_array() {
                    seq.serialize_element(&v)?;
                }
                seq.end()
            }
            Texture::Checker { a, b, scale } => {
                let mut m = s.serialize_map(Some(2))?;
                m.serialize_entry("checker", &[Texture::Constant(*a), Texture::Constant(*b)])?;
                m.serialize_entry("scale", &UvPair(*scale))?;
                m.end()
            }
            Texture::Image(r) => r.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for Texture {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            d.deserialize_any(TextureVisitor)
        } else {
            Ok(match TextureBinary::deserialize(d)? {
                TextureBinary::Constant(c) => Texture::from(c),
                TextureBinary::Checker(a, b, scale) => {
                    Texture::Checker { a: Rgb::from_array(a), b: Rgb::from_array(b), scale: Vec2::from_array(scale) }
                }
                TextureBinary::Image(r) => Texture::Image(r.into()),
            })
        }
    }
}

/// Reads a number, an `[r, g, b]` array, or an image or checker table.
struct TextureVisitor;

const EXPECTING: &str = "a number, an [r, g, b] array, { image = \"FILE\", … } or { checker = [A, B], … }";

impl<'de> Visitor<'de> for TextureVisitor {
    type Value = Texture;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(EXPECTING)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Texture, E> {
        Ok(Texture::grey(v as f32))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Texture, E> {
        Ok(Texture::grey(v as f32))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Texture, E> {
        Ok(Texture::grey(v as f32))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Texture, A::Error> {
        let mut c = [0.0f32; 3];
        for (i, v) in c.iter_mut().enumerate() {
            *v = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
        }
        let mut extra = 0;
        while seq.next_element::<de::IgnoredAny>()?.is_some() {
            extra += 1;
        }
        if extra > 0 {
            return Err(de::Error::invalid_length(3 + extra, &self));
        }
        Ok(Texture::from(c))
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Texture, A::Error> {
        let t = TextureTable::deserialize(de::value::MapAccessDeserializer::new(map))?;
        if t.strength.is_some() {
            return Err(de::Error::custom("`strength` belongs to a bump map (`bump = { image = …, strength = … }`)"));
        }
        match (&t.image, &t.checker) {
            (Some(_), None) => Ok(Texture::Image(t.image_ref("an image texture")?)),
            (None, Some([a, b])) => {
                if t.offset.is_some() || t.wrap.is_some() || t.filter.is_some() || t.colorspace.is_some() {
                    return Err(de::Error::custom("a checker takes only `checker = [A, B]` and `scale`"));
                }
                let (Texture::Constant(a), Texture::Constant(b)) = (a, b) else {
                    return Err(de::Error::custom("checker colours must be numbers or [r, g, b] arrays"));
                };
                let scale = t.scale.map_or(Vec2::splat(DEFAULT_CHECKER_SCALE), |s| s.0);
                Ok(Texture::Checker { a: *a, b: *b, scale })
            }
            (Some(_), Some(_)) => Err(de::Error::custom("a texture is either `image` or `checker`, not both")),
            (None, None) => Err(de::Error::custom(format!("expected {EXPECTING}"))),
        }
    }
}

/// A bump map: a grey height image displacing the surface along its shading normal by `strength · height`
/// scene units; only the shading normal changes (Blinn 1978; pbrt-v4 §10.5.1).
#[derive(Clone, Debug, PartialEq)]
pub struct BumpMap {
    /// The height image (its channels' mean is the height, in `[0, 1]` for integer images).
    pub image: ImageRef,
    /// Scene units of displacement per unit of height (may be negative: dents instead of bumps).
    pub strength: f32,
}

/// A tangent-space normal map: RGB `c` encodes the normal `2c − 1` in the frame (tangent along `∂p/∂u`,
/// bitangent along `∂p/∂v`, shading normal), OpenGL's convention (green points to +v).
#[derive(Clone, Debug, PartialEq)]
pub struct NormalMap {
    /// The image.
    pub image: ImageRef,
}

#[derive(Serialize, Deserialize)]
struct BumpBinary(ImageRefBinary, f32);

impl Serialize for BumpMap {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            TextureTable { strength: Some(self.strength), ..TextureTable::of_image(&self.image) }.serialize(s)
        } else {
            BumpBinary((&self.image).into(), self.strength).serialize(s)
        }
    }
}

impl<'de> Deserialize<'de> for BumpMap {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if !d.is_human_readable() {
            let BumpBinary(image, strength) = BumpBinary::deserialize(d)?;
            return Ok(Self { image: image.into(), strength });
        }
        let t = TextureTable::deserialize(d)?;
        if t.checker.is_some() {
            return Err(de::Error::custom("a bump map reads a height image: `image = \"FILE\"`, not `checker`"));
        }
        let Some(strength) = t.strength else {
            return Err(de::Error::custom("a bump map needs `strength` (scene units of displacement per unit height)"));
        };
        Ok(Self { image: t.image_ref("a bump map")?, strength })
    }
}

impl Serialize for NormalMap {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.image.serialize(s)
    }
}

impl<'de> Deserialize<'de> for NormalMap {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(Self { image: ImageRef::deserialize(d)? })
    }
}

impl BumpMap {
    /// The height `strength · h` at `uv` in scene units, `h` the mean of the channels.
    #[inline]
    fn height(&self, img: &TexelImage, uv: Vec2) -> f32 {
        let c = self.image.lookup(img, uv, self.image.colorspace.unwrap_or(ColorSpace::Linear));
        self.strength * ((c.x + c.y + c.z) / 3.0)
    }

    /// The bumped shading normal (unit, on the side of `ns`) at `uv`, from the surface's partial derivatives
    /// `dpdu`, `dpdv`. The height's derivatives are one-texel forward differences,
    /// `∂d/∂u ≈ (d(u + Δu, v) − d(u, v)) / Δu` with `Δu` one texel; then `∂p'/∂u = ∂p/∂u + ∂d/∂u · ns` (the
    /// term `d · ∂n/∂u` is dropped, as the displacement is small), likewise for `v`, and `n' = ∂p'/∂u × ∂p'/∂v`
    /// (pbrt-v4 §10.5.1, eq. 10.12). A height that does not change gives `ns` unchanged, bit for bit.
    pub fn perturb(&self, images: &[TexelImage], uv: Vec2, ns: Vec3A, dpdu: Vec3A, dpdv: Vec3A) -> Vec3A {
        let Some(img) = images.get(self.image.slot as usize) else { return ns };
        let du = 1.0 / (img.width as f32 * self.image.scale.x.abs());
        let dv = 1.0 / (img.height as f32 * self.image.scale.y.abs());
        let h = self.height(img, uv);
        let dddu = (self.height(img, uv + Vec2::new(du, 0.0)) - h) / du;
        let dddv = (self.height(img, uv + Vec2::new(0.0, dv)) - h) / dv;
        if dddu == 0.0 && dddv == 0.0 {
            return ns;
        }
        orient(fmath::cross(dpdu + dddu * ns, dpdv + dddv * ns), ns)
    }
}

impl NormalMap {
    /// The shading normal (unit, on the side of `ns`) that the map's texel at `uv` gives in the frame of
    /// `ns`, the tangent `dpdu` made perpendicular to `ns`, and the bitangent `ns × t` turned to the side of
    /// `dpdv` (so mirrored UVs keep green pointing to +v).
    pub fn perturb(&self, images: &[TexelImage], uv: Vec2, ns: Vec3A, dpdu: Vec3A, dpdv: Vec3A) -> Vec3A {
        let Some(img) = images.get(self.image.slot as usize) else { return ns };
        let c = self.image.lookup(img, uv, self.image.colorspace.unwrap_or(ColorSpace::Linear));
        let m = c * 2.0 - Rgb::ONE;
        let t = dpdu - ns * ns.dot(dpdu);
        let t = if t.length_squared() > 0.0 { fmath::normalize(t) } else { crate::math::Frame::from_normal(ns).s };
        let b = fmath::cross(ns, t);
        let b = if b.dot(dpdv) < 0.0 { -b } else { b };
        orient(m.x * t + m.y * b + m.z * ns, ns)
    }
}

/// `n` normalised and turned to the side of `side`; `side` itself when `n` is zero or not finite.
#[inline]
fn orient(n: Vec3A, side: Vec3A) -> Vec3A {
    let n = fmath::normalize(n);
    if !n.is_finite() || n == Vec3A::ZERO {
        side
    } else if n.dot(side) < 0.0 {
        -n
    } else {
        n
    }
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

/// Decodes image bytes (PNG, JPEG, OpenEXR, BMP or PNM, told by their content) into texels: grey images keep
/// one channel, others keep red, green and blue (alpha is dropped); 8- and 16-bit values stay integers (their
/// colour space is the texture's business), float values stay floats.
pub fn decode(bytes: &[u8], limit: u64) -> Result<TexelImage, TextureError> {
    if bytes.is_empty() {
        return Err(TextureError::Invalid("the file is empty (0 bytes)".into()));
    }
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| TextureError::Decode(e.to_string()))?;
    if reader.format().is_none() {
        return Err(TextureError::Decode("not a PNG, JPEG, OpenEXR, BMP or PNM image".into()));
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
