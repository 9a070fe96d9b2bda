//! The scene-file (text) and blob (binary) forms of textures, image references, bump and normal maps: in text a
//! texture is a number, an `[r, g, b]` array or a table; in binary formats each is a plain struct or enum that
//! bincode reads. Nothing here is read while rendering.

use super::texels::ColorSpace;
use super::{BumpMap, DEFAULT_CHECKER_SCALE, Filter, ImageRef, NormalMap, Texture, Wrap};
use crate::Rgb;
use crate::geometry::NONE;
use glam::Vec2;
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::ser::{SerializeMap, SerializeSeq};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::path::PathBuf;

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
