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
//! | file | what it holds |
//! |---|---|
//! | this one | textures, image references and their lookups, bump and normal maps |
//! | [`texels`] | decoded images (`TexelImage`), colour spaces and the decoder of image files |
//! | `forms` | the scene-file and binary forms of textures and maps (their serde impls) |

mod forms;
pub mod texels;

pub use texels::{
    ColorSpace, MAX_TEXTURE_SIDE, TexelImage, TexelImageError, Texels, TextureError, decode, decode_alpha, decode_file,
    srgb_decode,
};

use crate::Rgb;
use crate::error::FieldError;
use crate::math::fmath;
use glam::{Vec2, Vec3A};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

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

/// A reference to an image with the way to read it.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageRef {
    /// The file, as the scene writes it (relative to the scene's folder). Not part of the binary form: the
    /// image travels by `slot`.
    pub file: PathBuf,
    /// Index of the image in the prepared scene's texture list, or [`NONE`](crate::geometry::NONE) before the scene is prepared.
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
