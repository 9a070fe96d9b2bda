//! glTF materials as photon materials, and the images they read.
//!
//! - `pbrMetallicRoughness` → [`Material::MetallicRoughness`]: base colour factor × texture (sRGB), metallic
//!   and roughness factors × the metallic-roughness texture's blue and green channels (linear, texel by texel
//!   in the BSDF), the normal texture with its `scale`.
//! - `KHR_materials_transmission` with a factor above 0 → [`Material::Dielectric`] of index
//!   `KHR_materials_ior` (default 1.5), tinted by the base colour, as rough as the roughness factor.
//! - A factor that multiplies a texture (base colour, normal scale) is baked into the texels: the image is
//!   stored as linear floats times the factor, so that the texture lookup stays a lookup.
//! - `alphaMode` MASK with a base colour texture whose image has alpha → an [`AlphaMask`] of that alpha and the
//!   factor's; the geometry cuts the faces away where their product is below the cutoff
//!   (`crate::geometry::mask`). A factor alone below the cutoff drops the primitive (`super::nodes`).
//!
//! Image slots index [`super::Imported::images`]; preparing the scene offsets them into its texture list.

use super::buffers;
use super::types::{Import, ImportError, Imported};
use crate::Rgb;
use crate::geometry::mask::AlphaMask;
use crate::light::EmissionImage;
use crate::material::texture::{ColorSpace, Filter, ImageRef, NormalMap, Texels, Wrap, decode, decode_alpha};
use crate::material::{Material, TexelImage, Texture};
use glam::Vec2;
use std::collections::BTreeMap;

/// How an image is read: as a colour (sRGB) or as data (linear), and what factor is baked into it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Use {
    /// The texels as they are, read in this colour space.
    Plain(bool),
    /// Linear floats: the sRGB colour times the factor's bits.
    Scaled([u32; 3]),
    /// A normal map whose x and y are scaled by the factor's bits (glTF's `normalTexture.scale`).
    Normal(u32),
}

/// The decoded images and the slots of the forms the materials read.
struct Images {
    decoded: BTreeMap<usize, TexelImage>,
    slots: BTreeMap<(usize, Use), u32>,
    out: Vec<TexelImage>,
    limit: u64,
}

impl Images {
    /// The slot of glTF image `index` read as `how`, decoding it on first use.
    fn slot(&mut self, im: &Import<'_>, index: usize, how: Use) -> Result<u32, ImportError> {
        if let Some(&s) = self.slots.get(&(index, how)) {
            return Ok(s);
        }
        if !self.decoded.contains_key(&index) {
            let image = im.doc.images().nth(index).ok_or_else(|| {
                ImportError::Mesh(super::types::malformed(im.file, format!("images[{index}] does not exist")))
            })?;
            let (bytes, name) = buffers::image_bytes(im, &image, self.limit)?;
            let field = format!("images[{index}]");
            let img =
                decode(&bytes, self.limit).map_err(|source| ImportError::Texture { file: name, field, source })?;
            self.decoded.insert(index, img);
        }
        let Some(img) = self.decoded.get(&index) else { return Ok(crate::geometry::NONE) };
        let form = match how {
            Use::Plain(_) => img.clone(),
            Use::Scaled(bits) => scaled(img, Rgb::from_array(bits.map(f32::from_bits))),
            Use::Normal(bits) => scaled_normals(img, f32::from_bits(bits)),
        };
        let slot = self.out.len() as u32;
        self.out.push(form);
        self.slots.insert((index, how), slot);
        Ok(slot)
    }
}

/// `img` as linear floats (sRGB integer texels decoded) times `factor`.
fn scaled(img: &TexelImage, factor: Rgb) -> TexelImage {
    let mut v = Vec::with_capacity(img.width as usize * img.height as usize * 3);
    for j in 0..img.height {
        for i in 0..img.width {
            v.extend_from_slice(&(img.texel(i, j, ColorSpace::Srgb) * factor).to_array());
        }
    }
    TexelImage { width: img.width, height: img.height, channels: 3, texels: Texels::F32(v) }
}

/// A normal map with glTF's `scale`: each texel's normal `2c − 1` has x and y times `scale`, is normalised,
/// and is stored again as `(n + 1)/2` in linear floats.
fn scaled_normals(img: &TexelImage, scale: f32) -> TexelImage {
    let mut v = Vec::with_capacity(img.width as usize * img.height as usize * 3);
    for j in 0..img.height {
        for i in 0..img.width {
            let c = img.texel(i, j, ColorSpace::Linear);
            let n = glam::Vec3::new((2.0 * c.x - 1.0) * scale, (2.0 * c.y - 1.0) * scale, 2.0 * c.z - 1.0);
            let n = n.normalize_or(glam::Vec3::Z);
            v.extend_from_slice(&((n + glam::Vec3::ONE) * 0.5).to_array());
        }
    }
    TexelImage { width: img.width, height: img.height, channels: 3, texels: Texels::F32(v) }
}

/// An import holding the file's materials by index, then glTF's default material, the images they read, and
/// their cut-outs (`im.material_masks` says which material has which); its other parts are empty.
pub(super) fn load(im: &mut Import<'_>, texture_limit: u64) -> Result<Imported, ImportError> {
    let mut images = Images { decoded: BTreeMap::new(), slots: BTreeMap::new(), out: Vec::new(), limit: texture_limit };
    let mut out = Vec::new();
    let mut masks = Vec::new();
    let doc = im.doc;
    for m in doc.materials() {
        out.push(material(im, &m, &mut images)?);
        let emission = emission_image(im, &m, &mut images)?;
        im.material_emission.push(emission);
        let mask = alpha_mask(im, &m, texture_limit)?;
        im.material_masks.push(mask.map(|k| {
            masks.push(k);
            masks.len() as u32 - 1
        }));
    }
    // glTF's default material (specification §3.9.6: metallic and roughness 1, white), which the document's
    // list does not hold.
    out.push(Material::MetallicRoughness {
        base_color: Texture::grey(1.0),
        metallic: 1.0,
        roughness: 1.0,
        metallic_roughness: None,
        bump: None,
        normal_map: None,
        two_sided: true,
    });
    im.material_masks.push(None);
    im.material_emission.push(None);
    Ok(Imported { materials: out, images: images.out, masks, ..Imported::default() })
}

/// The cut-out of material `m`: its base colour texture's alpha when `alphaMode` is MASK and the image has an
/// alpha channel. The surface is present where `factor_alpha · texture_alpha ≥ alphaCutoff` (specification
/// §3.9.4). `None` when nothing can be cut: another mode, no texture, an image without alpha, a cutoff ≤ 0, or a
/// factor below the cutoff (the primitive is dropped); and for an emissive material, whose faces are kept whole
/// (with a warning) because light sampling and photon emission pick points over the whole face.
fn alpha_mask(im: &mut Import<'_>, m: &gltf::Material<'_>, limit: u64) -> Result<Option<AlphaMask>, ImportError> {
    let pbr = m.pbr_metallic_roughness();
    let (cutoff, factor) = (m.alpha_cutoff().unwrap_or(0.5), pbr.base_color_factor()[3]);
    let Some(info) = pbr.base_color_texture() else { return Ok(None) };
    if m.alpha_mode() != gltf::material::AlphaMode::Mask || cutoff <= 0.0 || factor < cutoff {
        return Ok(None);
    }
    let tex = info.texture();
    let (bytes, name) = buffers::image_bytes(im, &tex.source(), limit)?;
    let field = format!("images[{}]", tex.source().index());
    let Some(alpha) =
        decode_alpha(&bytes, limit).map_err(|source| ImportError::Texture { file: name, field, source })?
    else {
        return Ok(None);
    };
    if m.emissive_factor() != [0.0; 3] {
        im.warn(
            "an emissive material with alphaMode MASK is drawn without its texture's cut-out: light sampling and \
             photon emission pick points over whole faces, so every method sees the whole face",
        );
        return Ok(None);
    }
    let r = image_ref(im, &tex, 0, None);
    let values = match alpha.texels {
        Texels::U8(v) => v.into_iter().map(|a| u16::from(a) * 257).collect(),
        Texels::U16(v) => v,
        Texels::F32(v) => v.into_iter().map(|a| (a.clamp(0.0, 1.0) * 65535.0).round() as u16).collect(),
    };
    Ok(Some(AlphaMask {
        width: alpha.width,
        height: alpha.height,
        alpha: values,
        repeat: r.wrap == Wrap::Repeat,
        bilinear: r.filter == Filter::Bilinear,
        factor,
        cutoff,
    }))
}

/// An image reference to slot `slot` with the sampler of `texture`.
fn image_ref(im: &mut Import<'_>, texture: &gltf::Texture<'_>, slot: u32, colorspace: Option<ColorSpace>) -> ImageRef {
    let sampler = texture.sampler();
    let wrap = |w: gltf::texture::WrappingMode| match w {
        gltf::texture::WrappingMode::ClampToEdge => Wrap::Clamp,
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::Repeat,
    };
    let (s, t) = (sampler.wrap_s(), sampler.wrap_t());
    if s == gltf::texture::WrappingMode::MirroredRepeat || t == gltf::texture::WrappingMode::MirroredRepeat {
        im.warn("the MIRRORED_REPEAT wrap mode is not supported: those textures repeat");
    }
    if s != t {
        im.warn("samplers with different wrap modes in s and t are not supported: the s mode is used for both");
    }
    let filter = match sampler.mag_filter() {
        Some(gltf::texture::MagFilter::Nearest) => Filter::Nearest,
        _ => Filter::Bilinear,
    };
    ImageRef {
        file: format!("{}#images[{}]", im.file.display(), texture.source().index()).into(),
        slot,
        scale: Vec2::ONE,
        offset: Vec2::ZERO,
        wrap: wrap(s),
        filter,
        colorspace,
    }
}

/// Warns when a texture reads a texture-coordinate set other than 0.
fn check_tex_coord(im: &mut Import<'_>, set: u32) {
    if set != 0 {
        im.warn(format!("texCoord {set} is not supported: textures read TEXCOORD_0"));
    }
}

/// The base colour: the factor's RGB, times the texture when there is one.
fn base_color(im: &mut Import<'_>, m: &gltf::Material<'_>, images: &mut Images) -> Result<Texture, ImportError> {
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, _] = pbr.base_color_factor();
    let factor = Rgb::new(r, g, b).clamp(Rgb::ZERO, Rgb::ONE);
    let Some(info) = pbr.base_color_texture() else { return Ok(Texture::Constant(factor)) };
    check_tex_coord(im, info.tex_coord());
    let tex = info.texture();
    let (how, space) = if factor == Rgb::ONE {
        (Use::Plain(true), Some(ColorSpace::Srgb))
    } else {
        (Use::Scaled(factor.to_array().map(f32::to_bits)), Some(ColorSpace::Linear))
    };
    let slot = images.slot(im, tex.source().index(), how)?;
    Ok(Texture::Image(image_ref(im, &tex, slot, space)))
}

/// One glTF material.
fn material(im: &mut Import<'_>, m: &gltf::Material<'_>, images: &mut Images) -> Result<Material, ImportError> {
    let pbr = m.pbr_metallic_roughness();
    let base_color = base_color(im, m, images)?;
    let normal_map = match m.normal_texture() {
        Some(n) => {
            check_tex_coord(im, n.tex_coord());
            let tex = n.texture();
            let how = if n.scale() == 1.0 { Use::Plain(false) } else { Use::Normal(n.scale().to_bits()) };
            let slot = images.slot(im, tex.source().index(), how)?;
            Some(NormalMap { image: image_ref(im, &tex, slot, Some(ColorSpace::Linear)) })
        }
        None => None,
    };
    if m.occlusion_texture().is_some() {
        tracing::info!("{}: occlusionTexture is not read: the renderer traces occlusion", im.file.display());
    }
    if m.alpha_mode() == gltf::material::AlphaMode::Blend {
        im.warn("alphaMode BLEND is not supported: those materials are opaque");
    }
    let roughness = pbr.roughness_factor().clamp(0.0, 1.0);
    if let Some(t) = m.transmission()
        && t.transmission_factor() > 0.0
    {
        if t.transmission_factor() < 1.0 || t.transmission_texture().is_some() || pbr.metallic_factor() > 0.0 {
            im.warn(
                "KHR_materials_transmission with a factor below 1, a transmission texture or metalness is rendered \
                 as fully transmitting glass",
            );
        }
        let tint = match base_color {
            Texture::Image(_) => {
                im.warn("a transmitting material's base colour texture is not read: its factor tints the glass");
                let [r, g, b, _] = pbr.base_color_factor();
                Texture::Constant(Rgb::new(r, g, b).clamp(Rgb::ZERO, Rgb::ONE))
            }
            t => t,
        };
        let eta = m.ior().filter(|e| e.is_finite() && *e > 0.0).unwrap_or(1.5);
        return Ok(Material::Dielectric { eta, tint, roughness, bump: None, normal_map });
    }
    if m.ior().is_some_and(|e| e != 1.5) {
        im.warn("KHR_materials_ior changes only transmitting materials: an opaque base keeps F0 = 0.04");
    }
    let metallic_roughness = match pbr.metallic_roughness_texture() {
        Some(info) => {
            check_tex_coord(im, info.tex_coord());
            let tex = info.texture();
            let slot = images.slot(im, tex.source().index(), Use::Plain(false))?;
            Some(Texture::Image(image_ref(im, &tex, slot, Some(ColorSpace::Linear))))
        }
        None => None,
    };
    Ok(Material::MetallicRoughness {
        base_color,
        metallic: pbr.metallic_factor().clamp(0.0, 1.0),
        roughness,
        metallic_roughness,
        bump: None,
        normal_map,
        two_sided: true,
    })
}

/// The emitted radiance of material `m` before its texture: `emissiveFactor × emissive_strength`, at least 0.
pub(super) fn emission_scale(m: &gltf::Material<'_>) -> Rgb {
    let f = m.emissive_factor();
    let e = Rgb::new(f[0], f[1], f[2]) * m.emissive_strength().unwrap_or(1.0);
    if e.is_finite() { e.max(Rgb::ZERO) } else { Rgb::ZERO }
}

/// Material `m`'s emissive texture as the area lights read it (sRGB, in the texture list, with its sampler and
/// the mean of its texels), when it has one and a factor that is not black.
fn emission_image(
    im: &mut Import<'_>,
    m: &gltf::Material<'_>,
    images: &mut Images,
) -> Result<Option<EmissionImage>, ImportError> {
    let Some(info) = m.emissive_texture() else { return Ok(None) };
    if emission_scale(m) == Rgb::ZERO {
        return Ok(None);
    }
    check_tex_coord(im, info.tex_coord());
    let tex = info.texture();
    let slot = images.slot(im, tex.source().index(), Use::Plain(true))?;
    let Some(img) = images.out.get(slot as usize) else { return Ok(None) };
    let mut sum = [0.0f64; 3];
    for j in 0..img.height {
        for i in 0..img.width {
            let c = img.texel(i, j, ColorSpace::Srgb);
            sum = [sum[0] + f64::from(c.x), sum[1] + f64::from(c.y), sum[2] + f64::from(c.z)];
        }
    }
    let n = f64::from(img.width) * f64::from(img.height);
    let mean = Rgb::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
    let r = image_ref(im, &tex, slot, Some(ColorSpace::Srgb));
    Ok(Some(EmissionImage { slot, wrap: r.wrap, filter: r.filter, mean }))
}
