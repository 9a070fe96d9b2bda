//! Materials: what a `[materials.NAME]` table of the scene file declares.
//!
//! ```toml
//! [materials.red]
//! type = "lambert"
//! albedo = [0.63, 0.065, 0.05]
//!
//! [materials.plastic]
//! type = "phong"
//! diffuse = [0.5, 0.1, 0.1]
//! specular = 0.3
//! exponent = 50.0
//!
//! [materials.silver]
//! type = "mirror"
//! reflectance = 0.95
//!
//! [materials.glass]
//! type = "dielectric"
//! eta = 1.5
//!
//! [materials.frosted_glass]
//! type = "dielectric"
//! eta = 1.5
//! roughness = 0.4
//!
//! [materials.gold]
//! type = "conductor"
//! eta = [0.143, 0.374, 1.442]
//! k = [3.983, 2.385, 1.603]
//! roughness = 0.25
//!
//! [materials.brushed]
//! type = "conductor"
//! color = [0.95, 0.64, 0.54]
//! roughness = 0.5
//!
//! [materials.boundary]
//! type = "interface"
//!
//! [materials.frosted]
//! type = "mix"
//! color = 0.9
//! diffuse = 0.2
//! specular = 0.1
//! transmission = 0.6
//! eta = 1.5
//! ```
//!
//! A colour (a [`Texture`]) is written as one number (grey) or as `[r, g, b]` (linear RGB); reflectances must
//! lie in `[0, 1]`. The types, their fields and defaults:
//!
//! - `lambert`: ideal diffuse. `albedo` (default 0.8).
//! - `phong`: modified Phong (Lafortune & Willems 1994), `f = kd/π + ks·(n+2)/(2π)·cos^n α` with α the angle
//!   between the incident direction and the mirror direction. `diffuse` = kd (default 0.5), `specular` = ks
//!   (default 0.3), `exponent` = n from 0 to 10,000 (default 20; [`MAX_PHONG_EXPONENT`]). Energy conserving, so
//!   `diffuse + specular ≤ 1` per channel.
//! - `mirror`: perfect specular reflection. `reflectance` (default 1).
//! - `dielectric`: smooth glass with exact unpolarised Fresnel reflection, refraction and total internal
//!   reflection. `eta`: index of refraction of the inside (the side the surface normal points away from) over
//!   the outside (default 1.5, > 0); `tint` multiplies reflected and transmitted light (default 1).
//!   `roughness` (default 0, from 0 to 1) makes it rough glass: Trowbridge–Reitz facets of width `α = r²`
//!   that reflect and refract (Walter et al. 2007), sampled by their visible normals (Heitz 2018). Below
//!   `r ≈ 0.032` (`α <` [`SMOOTH_ALPHA`]) it is the smooth glass.
//! - `conductor`: a metal, Trowbridge–Reitz facets with a conductor's Fresnel reflectance. Either a complex
//!   index of refraction, `eta` and `k` together (per channel, `eta > 0`, `k ≥ 0`, constants; exact Fresnel,
//!   pbrt-v3 §8.2.1), or `color`, the reflectance at normal incidence with Schlick's approximation (the glTF
//!   metal); with neither it is white. `roughness` (default 0.3, from 0 to 1), `α = r²`; below `r ≈ 0.032` a
//!   perfect mirror with that Fresnel reflectance. Single scattering: a rough metal loses the light its facets
//!   shadow (under 1 % to `r = 0.2`, a third at `r = 1` and normal incidence; docs/RESULTS.md).
//! - `interface`: no surface at all, only the boundary of a medium (pbrt-v4's `interface` material): light
//!   passes it unchanged in direction and power, shadow rays pass it, and it is never a path vertex. A closed
//!   object of this material holds its `interior` medium (a cloud box) or vacuum (a region the global fog
//!   does not fill). No fields.
//! - `mix`: the original renderer's material, `diffuse·lambert(color) + specular·mirror + transmission·glass(eta)`.
//!   `color` tints the diffuse part only (default 0.8); the weights `diffuse`, `specular` and `transmission`
//!   (each ≥ 0, default 0, so a mix names the parts it has) sum to at most 1, and the rest is absorbed;
//!   `eta` as for `dielectric` (default 1.5).
//!
//! `lambert`, `phong`, `mirror` and `conductor` take `two_sided` (default `true`): a one-sided surface (`false`) reflects only
//! on its front, the side its geometric normal points to, and is black from behind, where it absorbs the light
//! and the photons that arrive (Mitsuba 3's rule for its BSDFs). The default follows pbrt-v4, Cycles and
//! LuxCore, whose diffuse and glossy surfaces reflect on both sides: meshes from the field are often wound
//! inconsistently, and one-sided faces would show them as black holes.
//!
//! Unknown fields are errors. [`Material::validate`] checks the ranges; the scene loader reports its message
//! under the material's path.

pub mod bsdf;
pub mod metallic_roughness;
pub mod microfacet;
pub mod texture;

use crate::error::FieldError;
use crate::geometry::Hit;
use bsdf::{Bsdf, Bxdf};
use microfacet::{ConductorFresnel, SMOOTH_ALPHA};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
pub use texture::{BumpMap, ImageRef, NormalMap, TexelImage, Texture};

/// A surface material, exactly as a `[materials.NAME]` table declares it (see the module docs).
///
/// Serde: text formats (TOML) use the scene-file form, internally tagged by `type`; binary formats (bincode,
/// which cannot read an internal tag) use a plain enum, so that [`crate::prepare::Prepared`] can carry
/// materials to workers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self", tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Material {
    /// Ideal diffuse reflection.
    Lambert {
        /// Reflectance (default 0.8).
        #[serde(default = "default_albedo")]
        albedo: Texture,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
        /// Whether the surface reflects on both sides (default true); a one-sided surface is black seen from
        /// behind (the side its geometric normal points away from) and absorbs the light that arrives there.
        #[serde(default = "default_true", skip_serializing_if = "is_true")]
        two_sided: bool,
    },
    /// Modified Phong: a diffuse and an energy-conserving glossy lobe.
    Phong {
        /// Diffuse reflectance kd (default 0.5).
        #[serde(default = "default_phong_diffuse")]
        diffuse: Texture,
        /// Glossy reflectance ks (default 0.3); `diffuse + specular ≤ 1` per channel.
        #[serde(default = "default_phong_specular")]
        specular: Texture,
        /// Phong exponent n ≥ 0 (default 20): larger is shinier.
        #[serde(default = "default_phong_exponent")]
        exponent: f32,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
        /// Whether the surface reflects on both sides (default true); a one-sided surface is black seen from
        /// behind (the side its geometric normal points away from) and absorbs the light that arrives there.
        #[serde(default = "default_true", skip_serializing_if = "is_true")]
        two_sided: bool,
    },
    /// A perfect mirror.
    Mirror {
        /// Reflectance (default 1).
        #[serde(default = "default_one")]
        reflectance: Texture,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
        /// Whether the surface reflects on both sides (default true); a one-sided surface is black seen from
        /// behind (the side its geometric normal points away from) and absorbs the light that arrives there.
        #[serde(default = "default_true", skip_serializing_if = "is_true")]
        two_sided: bool,
    },
    /// Smooth glass.
    Dielectric {
        /// Index of refraction, inside over outside (default 1.5).
        #[serde(default = "default_eta")]
        eta: f32,
        /// Multiplies reflected and transmitted light (default 1).
        #[serde(default = "default_one")]
        tint: Texture,
        /// Perceptual roughness `r` in [0, 1] (default 0, smooth glass): a Trowbridge–Reitz lobe of width
        /// `α = r²` that reflects and refracts (Walter et al. 2007).
        #[serde(default, skip_serializing_if = "is_zero")]
        roughness: f32,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
    },
    /// A metal: Trowbridge–Reitz facets with a conductor's Fresnel reflectance.
    Conductor {
        /// Real part of the complex index of refraction per channel (with `k`; default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        eta: Option<Texture>,
        /// Imaginary part of the complex index of refraction per channel (with `eta`; default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        k: Option<Texture>,
        /// Reflectance at normal incidence with Schlick's Fresnel, glTF's metal (default 1 when neither `eta`
        /// nor `color` is given).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        color: Option<Texture>,
        /// Perceptual roughness `r` in [0, 1] (default 0.3); `α = r²`, and below `r ≈ 0.032` a perfect mirror.
        #[serde(default = "default_conductor_roughness")]
        roughness: f32,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
        /// Whether the surface reflects on both sides (default true); a one-sided surface is black seen from
        /// behind (the side its geometric normal points away from) and absorbs the light that arrives there.
        #[serde(default = "default_true", skip_serializing_if = "is_true")]
        two_sided: bool,
    },
    /// glTF's metallic–roughness model ([`metallic_roughness`]): a metal and a dielectric-coated diffuse base,
    /// mixed by metalness.
    MetallicRoughness {
        /// Base colour (default 1): the metal's reflectance at normal incidence, the base's diffuse colour.
        #[serde(default = "default_one")]
        base_color: Texture,
        /// Metalness factor in [0, 1] (default 1, glTF's default).
        #[serde(default = "default_one_f32")]
        metallic: f32,
        /// Perceptual roughness factor in [0, 1] (default 1, glTF's default); `α = r²`.
        #[serde(default = "default_one_f32")]
        roughness: f32,
        /// glTF's metallic-roughness image (default none): its blue channel multiplies `metallic`, its green
        /// channel `roughness`, texel by texel; integer texels are linear unless `colorspace` says otherwise.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        metallic_roughness: Option<Texture>,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
        /// Whether the surface reflects on both sides (default true); a one-sided surface is black seen from
        /// behind (the side its geometric normal points away from) and absorbs the light that arrives there.
        #[serde(default = "default_true", skip_serializing_if = "is_true")]
        two_sided: bool,
    },
    /// The original renderer's mixture of diffuse, mirror and glass; the rest of the weight is absorbed.
    Mix {
        /// Colour of the diffuse part (default 0.8).
        #[serde(default = "default_albedo")]
        color: Texture,
        /// Weight of the diffuse part (default 0).
        #[serde(default)]
        diffuse: f32,
        /// Weight of the perfect mirror (default 0).
        #[serde(default)]
        specular: f32,
        /// Weight of the glass (default 0).
        #[serde(default)]
        transmission: f32,
        /// Index of refraction of the glass, inside over outside (default 1.5).
        #[serde(default = "default_eta")]
        eta: f32,
        /// Bump map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        bump: Option<BumpMap>,
        /// Tangent-space normal map (default none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normal_map: Option<NormalMap>,
    },
    /// No surface: the boundary of a medium, which light crosses unchanged.
    Interface {},
}

/// The binary form of [`Material`]: the lobes' fields in declaration order, in serde's default (externally
/// tagged) enum representation, then the bump and normal maps.
#[derive(Serialize, Deserialize)]
enum LobesBinary {
    Lambert(Texture),
    Phong(Texture, Texture, f32),
    Mirror(Texture),
    Dielectric(f32, Texture, f32),
    Conductor(Option<Texture>, Option<Texture>, Option<Texture>, f32),
    MetallicRoughness(Texture, f32, f32, Option<Texture>),
    Mix(Texture, f32, f32, f32, f32),
    Interface,
}

#[derive(Serialize, Deserialize)]
struct MaterialBinary(LobesBinary, Option<BumpMap>, Option<NormalMap>, bool);

impl Serialize for Material {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            // The derived scene-file form (`remote = "Self"` makes it an inherent function).
            return Material::serialize(self, s);
        }
        let (bump, normal_map) = (self.bump().cloned(), self.normal_map().cloned());
        let lobes = match self.clone() {
            Material::Lambert { albedo, .. } => LobesBinary::Lambert(albedo),
            Material::Phong { diffuse, specular, exponent, .. } => LobesBinary::Phong(diffuse, specular, exponent),
            Material::Mirror { reflectance, .. } => LobesBinary::Mirror(reflectance),
            Material::Dielectric { eta, tint, roughness, .. } => LobesBinary::Dielectric(eta, tint, roughness),
            Material::Conductor { eta, k, color, roughness, .. } => LobesBinary::Conductor(eta, k, color, roughness),
            Material::MetallicRoughness { base_color, metallic, roughness, metallic_roughness, .. } => {
                LobesBinary::MetallicRoughness(base_color, metallic, roughness, metallic_roughness)
            }
            Material::Mix { color, diffuse, specular, transmission, eta, .. } => {
                LobesBinary::Mix(color, diffuse, specular, transmission, eta)
            }
            Material::Interface {} => LobesBinary::Interface,
        };
        MaterialBinary(lobes, bump, normal_map, self.two_sided()).serialize(s)
    }
}

impl<'de> Deserialize<'de> for Material {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            return Material::deserialize(d);
        }
        let MaterialBinary(lobes, bump, normal_map, two_sided) = MaterialBinary::deserialize(d)?;
        Ok(match lobes {
            LobesBinary::Lambert(albedo) => Material::Lambert { albedo, bump, normal_map, two_sided },
            LobesBinary::Phong(diffuse, specular, exponent) => {
                Material::Phong { diffuse, specular, exponent, bump, normal_map, two_sided }
            }
            LobesBinary::Mirror(reflectance) => Material::Mirror { reflectance, bump, normal_map, two_sided },
            LobesBinary::Dielectric(eta, tint, roughness) => {
                Material::Dielectric { eta, tint, roughness, bump, normal_map }
            }
            LobesBinary::Conductor(eta, k, color, roughness) => {
                Material::Conductor { eta, k, color, roughness, bump, normal_map, two_sided }
            }
            LobesBinary::MetallicRoughness(base_color, metallic, roughness, metallic_roughness) => {
                Material::MetallicRoughness {
                    base_color,
                    metallic,
                    roughness,
                    metallic_roughness,
                    bump,
                    normal_map,
                    two_sided,
                }
            }
            LobesBinary::Mix(color, diffuse, specular, transmission, eta) => {
                Material::Mix { color, diffuse, specular, transmission, eta, bump, normal_map }
            }
            LobesBinary::Interface => Material::Interface {},
        })
    }
}

fn default_albedo() -> Texture {
    Texture::grey(0.8)
}

fn default_true() -> bool {
    true
}

fn is_true(b: &bool) -> bool {
    *b
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

fn default_conductor_roughness() -> f32 {
    0.3
}

fn default_one() -> Texture {
    Texture::grey(1.0)
}

fn default_one_f32() -> f32 {
    1.0
}

fn default_phong_diffuse() -> Texture {
    Texture::grey(0.5)
}

fn default_phong_specular() -> Texture {
    Texture::grey(0.3)
}

fn default_phong_exponent() -> f32 {
    20.0
}

fn default_eta() -> f32 {
    1.5
}

impl Default for Material {
    /// Grey Lambert with albedo 0.8.
    fn default() -> Self {
        Material::Lambert { albedo: default_albedo(), bump: None, normal_map: None, two_sided: true }
    }
}

/// The largest Phong exponent. Its lobe is already under a degree wide (cosⁿα = ½ at α ≈ √(2 ln 2 / n) ≈ 0.7°);
/// far beyond it the f32 cosine near 1 is too coarse for the lobe, whose peak `(n+2)/(2π)` then turns a few
/// rays into huge pixel values instead of a reflection.
pub const MAX_PHONG_EXPONENT: f32 = 10_000.0;

impl Material {
    /// Checks every parameter's range. The error names the parameter (`albedo`); the scene loader places it
    /// under the material's path.
    pub fn validate(&self) -> Result<(), FieldError> {
        if let Some(b) = self.bump() {
            b.image.validate("bump")?;
            if !b.strength.is_finite() {
                return Err(FieldError::new("bump.strength", format!("expected a finite number, got {}", b.strength)));
            }
        }
        if let Some(n) = self.normal_map() {
            n.image.validate("normal_map")?;
        }
        if self.bump().is_some() && self.normal_map().is_some() {
            return Err(FieldError::new("normal_map", "a material takes a bump map or a normal map, not both"));
        }
        match self {
            Material::Lambert { albedo, .. } => albedo.validate_reflectance("albedo"),
            Material::Phong { diffuse, specular, exponent, .. } => {
                diffuse.validate_reflectance("diffuse")?;
                specular.validate_reflectance("specular")?;
                if !(exponent.is_finite() && (0.0..=MAX_PHONG_EXPONENT).contains(exponent)) {
                    return Err(FieldError::new(
                        "exponent",
                        format!(
                            "expected a number from 0 to {MAX_PHONG_EXPONENT}, got {exponent} (a sharper lobe is a \
                             mirror: use type = \"mirror\", or a mix)"
                        ),
                    ));
                }
                // Where either varies, the glossy part is cut to `1 − kd` per point (see `bsdf`).
                if let (Texture::Constant(kd), Texture::Constant(ks)) = (diffuse, specular) {
                    let sum = *kd + *ks;
                    if sum.max_element() > 1.0 {
                        return Err(FieldError::new(
                            "specular",
                            format!(
                                "diffuse + specular = [{}, {}, {}] exceeds 1: the material would create energy",
                                sum.x, sum.y, sum.z
                            ),
                        ));
                    }
                }
                Ok(())
            }
            Material::Mirror { reflectance, .. } => reflectance.validate_reflectance("reflectance"),
            Material::Dielectric { eta, tint, roughness, .. } => {
                validate_eta(*eta)?;
                validate_roughness(*roughness)?;
                tint.validate_reflectance("tint")
            }
            Material::Conductor { eta, k, color, roughness, .. } => {
                validate_roughness(*roughness)?;
                validate_conductor_fresnel(eta.as_ref(), k.as_ref(), color.as_ref())
            }
            Material::MetallicRoughness { base_color, metallic, roughness, metallic_roughness, .. } => {
                base_color.validate_reflectance("base_color")?;
                validate_roughness(*roughness)?;
                if !(metallic.is_finite() && (0.0..=1.0).contains(metallic)) {
                    return Err(FieldError::new("metallic", format!("expected a number from 0 to 1, got {metallic}")));
                }
                metallic_roughness.as_ref().map_or(Ok(()), |t| t.validate_reflectance("metallic_roughness"))
            }
            Material::Mix { color, diffuse, specular, transmission, eta, .. } => {
                color.validate_reflectance("color")?;
                for (name, w) in [("diffuse", diffuse), ("specular", specular), ("transmission", transmission)] {
                    if !(w.is_finite() && *w >= 0.0) {
                        return Err(FieldError::new(name, format!("expected a weight ≥ 0, got {w}")));
                    }
                }
                let sum = diffuse + specular + transmission;
                // A little slack for decimal weights such as 0.1 + 0.2 + 0.7 that round above 1 in f32.
                if sum > 1.0 + 1e-6 {
                    return Err(FieldError::new(
                        "transmission",
                        format!(
                            "diffuse + specular + transmission = {sum} exceeds 1: the material would create energy"
                        ),
                    ));
                }
                validate_eta(*eta)
            }
            Material::Interface {} => Ok(()),
        }
    }

    /// The bump map, if any.
    pub fn bump(&self) -> Option<&BumpMap> {
        match self {
            Material::Lambert { bump, .. }
            | Material::Phong { bump, .. }
            | Material::Mirror { bump, .. }
            | Material::Dielectric { bump, .. }
            | Material::Conductor { bump, .. }
            | Material::MetallicRoughness { bump, .. }
            | Material::Mix { bump, .. } => bump.as_ref(),
            Material::Interface {} => None,
        }
    }

    /// The normal map, if any.
    pub fn normal_map(&self) -> Option<&NormalMap> {
        match self {
            Material::Lambert { normal_map, .. }
            | Material::Phong { normal_map, .. }
            | Material::Mirror { normal_map, .. }
            | Material::Dielectric { normal_map, .. }
            | Material::Conductor { normal_map, .. }
            | Material::MetallicRoughness { normal_map, .. }
            | Material::Mix { normal_map, .. } => normal_map.as_ref(),
            Material::Interface {} => None,
        }
    }

    /// Every colour of the material with its field name, in declaration order.
    pub fn colors(&self) -> Vec<(&'static str, &Texture)> {
        match self {
            Material::Lambert { albedo, .. } => vec![("albedo", albedo)],
            Material::Phong { diffuse, specular, .. } => vec![("diffuse", diffuse), ("specular", specular)],
            Material::Mirror { reflectance, .. } => vec![("reflectance", reflectance)],
            Material::Dielectric { tint, .. } => vec![("tint", tint)],
            Material::Conductor { eta, k, color, .. } => [("eta", eta), ("k", k), ("color", color)]
                .into_iter()
                .filter_map(|(n, t)| Some((n, t.as_ref()?)))
                .collect(),
            Material::MetallicRoughness { base_color, metallic_roughness, .. } => {
                let mut out = vec![("base_color", base_color)];
                out.extend(metallic_roughness.as_ref().map(|t| ("metallic_roughness", t)));
                out
            }
            Material::Mix { color, .. } => vec![("color", color)],
            Material::Interface {} => Vec::new(),
        }
    }

    /// Every image the material reads, with its field (`albedo`, `bump`, `normal_map`), in a fixed order:
    /// colours in declaration order, then the bump or normal map.
    pub fn images(&self) -> Vec<(&'static str, &ImageRef)> {
        let mut out: Vec<(&'static str, &ImageRef)> =
            self.colors().into_iter().filter_map(|(n, t)| t.image().map(|r| (n, r))).collect();
        out.extend(self.bump().map(|b| ("bump", &b.image)));
        out.extend(self.normal_map().map(|n| ("normal_map", &n.image)));
        out
    }

    /// [`Material::images`], mutable, so that preparing the scene can set each image's slot.
    pub fn images_mut(&mut self) -> Vec<(&'static str, &mut ImageRef)> {
        let (colors, bump, normal_map): (Vec<(&'static str, &mut Texture)>, _, _) = match self {
            Material::Lambert { albedo, bump, normal_map, .. } => (vec![("albedo", albedo)], bump, normal_map),
            Material::Phong { diffuse, specular, bump, normal_map, .. } => {
                (vec![("diffuse", diffuse), ("specular", specular)], bump, normal_map)
            }
            Material::Mirror { reflectance, bump, normal_map, .. } => {
                (vec![("reflectance", reflectance)], bump, normal_map)
            }
            Material::Dielectric { tint, bump, normal_map, .. } => (vec![("tint", tint)], bump, normal_map),
            Material::Conductor { eta, k, color, bump, normal_map, .. } => {
                let colors = [("eta", eta), ("k", k), ("color", color)];
                (colors.into_iter().filter_map(|(n, t)| Some((n, t.as_mut()?))).collect(), bump, normal_map)
            }
            Material::MetallicRoughness { base_color, metallic_roughness, bump, normal_map, .. } => {
                let mut colors = vec![("base_color", base_color)];
                colors.extend(metallic_roughness.as_mut().map(|t| ("metallic_roughness", t)));
                (colors, bump, normal_map)
            }
            Material::Mix { color, bump, normal_map, .. } => (vec![("color", color)], bump, normal_map),
            Material::Interface {} => return Vec::new(),
        };
        let mut out: Vec<(&'static str, &mut ImageRef)> =
            colors.into_iter().filter_map(|(n, t)| t.image_mut().map(|r| (n, r))).collect();
        if let Some(b) = bump {
            out.push(("bump", &mut b.image));
        }
        if let Some(n) = normal_map {
            out.push(("normal_map", &mut n.image));
        }
        out
    }

    /// Whether the material reads texture coordinates (an image or checker colour, a bump or normal map).
    pub fn needs_uv(&self) -> bool {
        self.colors().iter().any(|(_, t)| t.needs_uv()) || self.bump().is_some() || self.normal_map().is_some()
    }

    /// The shading normal at a hit: `hit.ns`, bent by the bump or normal map when there is one.
    #[inline]
    pub fn shading_normal(&self, hit: &Hit, images: &[TexelImage]) -> glam::Vec3A {
        if let Some(b) = self.bump() {
            b.perturb(images, hit.uv, hit.ns, hit.dpdu, hit.dpdv)
        } else if let Some(n) = self.normal_map() {
            n.perturb(images, hit.uv, hit.ns, hit.dpdu, hit.dpdv)
        } else {
            hit.ns
        }
    }

    /// The BSDF at a hit: textures evaluated at `hit.uv`, `hit.p` from `images` (the prepared scene's texture
    /// list); shading frame from `hit.ns`, bent by a bump or normal map; `hit.n` kept to tell the inside of
    /// glass from the outside and to keep light from leaking through the surface (see [`bsdf`]).
    pub fn bsdf(&self, hit: &Hit, images: &[TexelImage]) -> Bsdf {
        let (uv, p) = (hit.uv, hit.p);
        let eval = |t: &Texture| t.eval(uv, p, images);
        let bxdf = match self {
            Material::Lambert { albedo, .. } => Bxdf::Lambert { r: eval(albedo) },
            Material::Phong { diffuse, specular, exponent, .. } => {
                let kd = eval(diffuse);
                // Textured lobes may sum above 1 at a point: the glossy part gives way (energy conservation).
                let ks = eval(specular).min(crate::Rgb::ONE - kd);
                Bxdf::Phong { kd, ks, exponent: *exponent }
            }
            Material::Mirror { reflectance, .. } => Bxdf::Mirror { r: eval(reflectance) },
            Material::Dielectric { eta, tint, roughness, .. } => {
                let alpha = roughness * roughness;
                if alpha < SMOOTH_ALPHA {
                    Bxdf::Dielectric { eta: *eta, tint: eval(tint) }
                } else {
                    Bxdf::RoughDielectric { eta: *eta, tint: eval(tint), alpha }
                }
            }
            Material::Conductor { eta, k, color, roughness, .. } => {
                let fresnel = match (eta, k, color) {
                    (Some(eta), Some(k), _) => ConductorFresnel::Complex { eta: eval(eta), k: eval(k) },
                    (_, _, Some(color)) => ConductorFresnel::Schlick { f0: eval(color) },
                    // Validation refuses half an index; a conductor with none is white.
                    _ => ConductorFresnel::Schlick { f0: crate::Rgb::ONE },
                };
                Bxdf::Conductor { fresnel, alpha: roughness * roughness }
            }
            Material::MetallicRoughness { base_color, metallic, roughness, metallic_roughness, .. } => {
                // Blue is metalness and green roughness (glTF 2.0, `metallicRoughnessTexture`), linear values.
                let map = metallic_roughness.as_ref().map_or(crate::Rgb::ONE, |t| eval_linear(t, uv, p, images));
                let roughness = roughness * map.y;
                Bxdf::MetallicRoughness {
                    base: eval(base_color),
                    metallic: (metallic * map.z).clamp(0.0, 1.0),
                    alpha: roughness * roughness,
                }
            }
            Material::Mix { color, diffuse, specular, transmission, eta, .. } => Bxdf::Mix {
                color: eval(color),
                diffuse: *diffuse,
                specular: *specular,
                transmission: *transmission,
                eta: *eta,
            },
            // Never shaded (the integrators pass it by); as a surface it is glass of index 1, which lets light
            // through unchanged.
            Material::Interface {} => Bxdf::Dielectric { eta: 1.0, tint: crate::Rgb::ONE },
        };
        Bsdf::new(self.shading_normal(hit, images), hit.n, bxdf).one_sided(!self.two_sided())
    }

    /// Whether the surface reflects on both sides: the `two_sided` field of lambert, phong and mirror; glass,
    /// mix and interface act on both sides by nature.
    pub fn two_sided(&self) -> bool {
        match self {
            Material::Lambert { two_sided, .. }
            | Material::Phong { two_sided, .. }
            | Material::Mirror { two_sided, .. }
            | Material::Conductor { two_sided, .. }
            | Material::MetallicRoughness { two_sided, .. } => *two_sided,
            Material::Dielectric { .. } | Material::Mix { .. } | Material::Interface {} => true,
        }
    }

    /// Whether the material has a delta (perfectly specular: mirror or glass) component, so that caustic paths
    /// (light → specular → … → diffuse) exist and a caustic photon map is worth building.
    pub fn has_specular(&self) -> bool {
        match self {
            Material::Lambert { .. } | Material::Phong { .. } | Material::Interface {} => false,
            // Rough conductors and glass too: the photon methods walk through their narrower lobes as through a
            // mirror (`photons.min_roughness`), so light that reaches a diffuse surface through them is caustic.
            Material::Mirror { .. } | Material::Dielectric { .. } | Material::Conductor { .. } => true,
            // Its specular lobe, however rough, is walked through where it is narrower than the threshold.
            Material::MetallicRoughness { .. } => true,
            Material::Mix { specular, transmission, .. } => *specular > 0.0 || *transmission > 0.0,
        }
    }

    /// Whether the material is an `interface`: the boundary of a medium, no surface.
    #[inline]
    pub fn is_interface(&self) -> bool {
        matches!(self, Material::Interface {})
    }

    /// Whether the material has a non-delta (diffuse or glossy) component: photons are stored on it and direct
    /// light is sampled there.
    pub fn has_non_delta(&self) -> bool {
        match self {
            Material::Lambert { .. } | Material::Phong { .. } => true,
            Material::Dielectric { roughness, .. } | Material::Conductor { roughness, .. } => {
                roughness * roughness >= SMOOTH_ALPHA
            }
            Material::Mirror { .. } | Material::Interface {} => false,
            // The diffuse base, unless the metalness is 1 everywhere, or the rough lobe.
            Material::MetallicRoughness { metallic, roughness, metallic_roughness, .. } => {
                *metallic < 1.0 || metallic_roughness.is_some() || roughness * roughness >= SMOOTH_ALPHA
            }
            Material::Mix { diffuse, .. } => *diffuse > 0.0,
        }
    }

    /// Whether light can pass through the surface (glass, or a mix with transmission).
    pub fn is_transmissive(&self) -> bool {
        match self {
            Material::Lambert { .. }
            | Material::Phong { .. }
            | Material::Mirror { .. }
            | Material::Conductor { .. }
            | Material::MetallicRoughness { .. } => false,
            Material::Dielectric { .. } | Material::Interface {} => true,
            Material::Mix { transmission, .. } => *transmission > 0.0,
        }
    }
}

/// `t` at `uv`, its integer image texels read as linear values unless its `colorspace` says otherwise (data,
/// not colour: glTF's metallic-roughness image).
fn eval_linear(t: &Texture, uv: glam::Vec2, p: glam::Vec3A, images: &[TexelImage]) -> crate::Rgb {
    match t {
        Texture::Image(r) => match images.get(r.slot as usize) {
            Some(img) => r.lookup(img, uv, r.colorspace.unwrap_or(texture::ColorSpace::Linear)).min(crate::Rgb::ONE),
            None => crate::Rgb::ZERO,
        },
        t => t.eval(uv, p, images),
    }
}

/// A conductor's Fresnel inputs: a complex index (`eta` > 0 and `k` ≥ 0, constants), or a `color`, or neither.
fn validate_conductor_fresnel(
    eta: Option<&Texture>,
    k: Option<&Texture>,
    color: Option<&Texture>,
) -> Result<(), FieldError> {
    match (eta, k, color) {
        (Some(eta), Some(k), None) => {
            validate_constant(eta, "eta", |c| c > 0.0, "a finite number > 0")?;
            validate_constant(k, "k", |c| c >= 0.0, "a finite number ≥ 0")
        }
        (None, None, Some(color)) => color.validate_reflectance("color"),
        (None, None, None) => Ok(()),
        (Some(_), None, _) => Err(FieldError::new("k", "eta needs k, the imaginary part of the index")),
        (None, Some(_), _) => Err(FieldError::new("eta", "k needs eta, the real part of the index")),
        (Some(_), Some(_), Some(_)) => Err(FieldError::new(
            "color",
            "a conductor takes a complex index (eta and k) or a color (Schlick's F0), not both",
        )),
    }
}

fn validate_roughness(r: f32) -> Result<(), FieldError> {
    if r.is_finite() && (0.0..=1.0).contains(&r) {
        Ok(())
    } else {
        Err(FieldError::new("roughness", format!("expected a number from 0 to 1, got {r}")))
    }
}

/// Checks that `t` is a constant (one number or `[r, g, b]`) whose every channel is finite and passes `ok`.
fn validate_constant(t: &Texture, field: &str, ok: impl Fn(f32) -> bool, expected: &str) -> Result<(), FieldError> {
    let Texture::Constant(c) = t else {
        return Err(FieldError::new(field, format!("expected {expected} or [r, g, b] of them, not a texture")));
    };
    match c.to_array().into_iter().find(|&x| !(x.is_finite() && ok(x))) {
        Some(x) => Err(FieldError::new(field, format!("expected {expected} in every channel, got {x}"))),
        None => Ok(()),
    }
}

fn validate_eta(eta: f32) -> Result<(), FieldError> {
    if eta.is_finite() && eta > 0.0 {
        Ok(())
    } else {
        Err(FieldError::new("eta", format!("expected a finite number > 0, got {eta}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Rgb;
    use crate::math::fmath;
    use glam::{Vec2, Vec3A};
    use std::collections::BTreeMap;

    #[derive(Debug, Deserialize, Serialize, PartialEq)]
    struct File {
        materials: BTreeMap<String, Material>,
    }

    fn parse(s: &str) -> Result<BTreeMap<String, Material>, String> {
        toml::from_str::<File>(s).map(|f| f.materials).map_err(|e| e.to_string())
    }

    #[test]
    fn module_doc_snippet_parses_and_validates() {
        let doc = include_str!("mod.rs");
        let start = doc.find("//! ```toml").unwrap();
        let snippet: String = doc[start..]
            .lines()
            .skip(1)
            .take_while(|l| !l.starts_with("//! ```"))
            .map(|l| format!("{}\n", l.trim_start_matches("//!").trim_start()))
            .collect();
        let m = parse(&snippet).unwrap();
        assert_eq!(m.len(), 9);
        assert_eq!(m["boundary"], Material::Interface {});
        for mat in m.values() {
            mat.validate().unwrap();
        }
        assert_eq!(
            m["red"],
            Material::Lambert {
                albedo: Texture::from([0.63, 0.065, 0.05]),
                bump: None,
                normal_map: None,
                two_sided: true
            }
        );
        assert_eq!(
            m["glass"],
            Material::Dielectric { eta: 1.5, tint: Texture::grey(1.0), roughness: 0.0, bump: None, normal_map: None }
        );
    }

    #[test]
    fn defaults() {
        let m = parse(
            "[materials.a]\ntype = \"lambert\"\n[materials.b]\ntype = \"phong\"\n[materials.c]\ntype = \"mirror\"\n\
             [materials.d]\ntype = \"dielectric\"\n[materials.e]\ntype = \"mix\"\n",
        )
        .unwrap();
        assert_eq!(m["a"], Material::default());
        assert_eq!(
            m["b"],
            Material::Phong {
                diffuse: Texture::grey(0.5),
                specular: Texture::grey(0.3),
                exponent: 20.0,
                bump: None,
                normal_map: None,
                two_sided: true,
            }
        );
        assert_eq!(
            m["c"],
            Material::Mirror { reflectance: Texture::grey(1.0), bump: None, normal_map: None, two_sided: true }
        );
        assert_eq!(
            m["d"],
            Material::Dielectric { eta: 1.5, tint: Texture::grey(1.0), roughness: 0.0, bump: None, normal_map: None }
        );
        assert_eq!(
            m["e"],
            Material::Mix {
                color: Texture::grey(0.8),
                diffuse: 0.0,
                specular: 0.0,
                transmission: 0.0,
                eta: 1.5,
                bump: None,
                normal_map: None
            }
        );
        for mat in m.values() {
            mat.validate().unwrap();
        }
    }

    #[test]
    fn integers_are_numbers() {
        let m = parse("[materials.a]\ntype = \"phong\"\ndiffuse = 0\nspecular = [1, 0, 0]\nexponent = 100\n").unwrap();
        assert_eq!(
            m["a"],
            Material::Phong {
                diffuse: Texture::grey(0.0),
                specular: Texture::from([1.0, 0.0, 0.0]),
                exponent: 100.0,
                bump: None,
                normal_map: None,
                two_sided: true,
            }
        );
    }

    #[test]
    fn bad_textures_say_what_was_expected() {
        for bad in ["\"red\"", "[0.1, 0.2]", "[0.1, 0.2, 0.3, 0.4]"] {
            let e = parse(&format!("[materials.a]\ntype = \"lambert\"\nalbedo = {bad}\n")).unwrap_err();
            assert!(e.contains("expected a number, an [r, g, b] array"), "{bad}: {e}");
        }
        for (bad, needle) in [("{ r = 1 }", "unknown field `r`"), ("{}", "expected a number, an [r, g, b] array")] {
            let e = parse(&format!("[materials.a]\ntype = \"lambert\"\nalbedo = {bad}\n")).unwrap_err();
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }

    #[test]
    fn unknown_fields_and_types_are_errors() {
        let e = parse("[materials.a]\ntype = \"lambert\"\nalbdo = 0.5\n").unwrap_err();
        assert!(e.contains("albdo"), "{e}");
        let e = parse("[materials.a]\ntype = \"mirror\"\neta = 1.5\n").unwrap_err();
        assert!(e.contains("eta"), "{e}");
        let e = parse("[materials.a]\ntype = \"metal\"\n").unwrap_err();
        assert!(e.contains("metal"), "{e}");
        let e = parse("[materials.a]\nalbedo = 0.5\n").unwrap_err();
        assert!(e.contains("type"), "{e}");
    }

    #[test]
    fn round_trip() {
        let f = File {
            materials: BTreeMap::from([
                (
                    "a".into(),
                    Material::Lambert {
                        albedo: Texture::from([0.63, 0.065, 0.05]),
                        bump: None,
                        normal_map: None,
                        two_sided: true,
                    },
                ),
                ("b".into(), phong(true)),
                ("c".into(), mix()),
                ("d".into(), textured("wood.png", crate::geometry::NONE)),
            ]),
        };
        // Through a TOML value: the crate reads TOML but does not need to write it as text.
        let v = toml::Value::try_from(&f).unwrap();
        assert_eq!(v["materials"]["a"]["albedo"].as_array().map(Vec::len), Some(3));
        assert!(v["materials"]["b"]["diffuse"].is_float());
        assert_eq!(v.try_into::<File>().unwrap(), f);
    }

    fn mix() -> Material {
        Material::Mix {
            color: 0.5.into(),
            diffuse: 0.1,
            specular: 0.2,
            transmission: 0.3,
            eta: 1.3,
            bump: None,
            normal_map: None,
        }
    }

    /// A Phong material with a checker, an image and a bump map. The scene file names images by file, the
    /// binary form by slot.
    fn textured(file: &str, slot: u32) -> Material {
        let image = ImageRef {
            file: file.into(),
            slot,
            scale: glam::Vec2::new(2.0, 0.5),
            offset: glam::Vec2::new(0.1, 0.0),
            wrap: texture::Wrap::Clamp,
            filter: texture::Filter::Nearest,
            colorspace: Some(texture::ColorSpace::Linear),
        };
        Material::Phong {
            diffuse: Texture::Checker { a: Rgb::splat(0.1), b: Rgb::new(0.5, 0.4, 0.3), scale: glam::Vec2::splat(4.0) },
            specular: Texture::Image(image.clone()),
            exponent: 30.0,
            bump: Some(BumpMap { image, strength: -0.02 }),
            normal_map: None,
            two_sided: false,
        }
    }

    fn phong(two_sided: bool) -> Material {
        Material::Phong {
            diffuse: 0.2.into(),
            specular: 0.7.into(),
            exponent: 8.0,
            bump: None,
            normal_map: None,
            two_sided,
        }
    }

    #[test]
    fn binary_round_trip() {
        // Prepared scenes travel to workers through bincode, which cannot read the scene file's internal tag.
        let all = vec![
            Material::Lambert {
                albedo: Texture::from([0.63, 0.065, 0.05]),
                bump: None,
                normal_map: None,
                two_sided: true,
            },
            // One-sided: the binary form carries the flag.
            phong(false),
            Material::Mirror { reflectance: 0.9.into(), bump: None, normal_map: None, two_sided: true },
            Material::Dielectric {
                eta: 1.33,
                tint: [1.0, 0.9, 0.8].into(),
                roughness: 0.0,
                bump: None,
                normal_map: None,
            },
            mix(),
            // The binary form carries an image's slot, not its file name.
            textured("", 3),
        ];
        let bytes = crate::codec::encode(&all).unwrap();
        assert_eq!(crate::codec::decode::<Vec<Material>>(&bytes, bytes.len()).unwrap(), all);
    }

    #[test]
    fn validation_names_the_field() {
        let cases = [
            (Material::Lambert { albedo: 1.2.into(), bump: None, normal_map: None, two_sided: true }, "albedo"),
            (Material::Lambert { albedo: f32::NAN.into(), bump: None, normal_map: None, two_sided: true }, "albedo"),
            (
                Material::Phong {
                    diffuse: 0.6.into(),
                    specular: [0.5, 0.3, 0.3].into(),
                    exponent: 10.0,
                    bump: None,
                    normal_map: None,
                    two_sided: true,
                },
                "diffuse + specular",
            ),
            (
                Material::Phong {
                    diffuse: 0.5.into(),
                    specular: 0.3.into(),
                    exponent: -1.0,
                    bump: None,
                    normal_map: None,
                    two_sided: true,
                },
                "exponent",
            ),
            (
                Material::Phong {
                    diffuse: 0.5.into(),
                    specular: 0.3.into(),
                    exponent: 1e30,
                    bump: None,
                    normal_map: None,
                    two_sided: true,
                },
                "exponent",
            ),
            (
                Material::Mirror { reflectance: (-0.1).into(), bump: None, normal_map: None, two_sided: true },
                "reflectance",
            ),
            (Material::Dielectric { eta: 0.0, tint: 1.0.into(), roughness: 0.0, bump: None, normal_map: None }, "eta"),
            (
                Material::Dielectric {
                    eta: 1.5,
                    tint: f32::INFINITY.into(),
                    roughness: 0.0,
                    bump: None,
                    normal_map: None,
                },
                "tint",
            ),
            (
                Material::Mix {
                    color: 0.5.into(),
                    diffuse: 0.5,
                    specular: 0.4,
                    transmission: 0.3,
                    eta: 1.5,
                    bump: None,
                    normal_map: None,
                },
                "= 1.2",
            ),
            (
                Material::Mix {
                    color: 0.5.into(),
                    diffuse: -0.1,
                    specular: 0.4,
                    transmission: 0.3,
                    eta: 1.5,
                    bump: None,
                    normal_map: None,
                },
                "diffuse",
            ),
        ];
        for (m, needle) in cases {
            let e = m.validate().unwrap_err();
            assert!(e.to_string().contains(needle), "{m:?}: {e}");
        }
        let ok = Material::Mix {
            color: 0.5.into(),
            diffuse: 0.1,
            specular: 0.2,
            transmission: 0.7,
            eta: 1.5,
            bump: None,
            normal_map: None,
        };
        ok.validate().unwrap();
    }

    /// A hit at the origin of the plane z = 0, normals +z, tangents along x and y.
    fn plane_hit() -> Hit {
        use crate::geometry::{NONE, PrimRef};
        Hit {
            t: 1.0,
            p: Vec3A::ZERO,
            p_error: Vec3A::ZERO,
            n: Vec3A::Z,
            ns: Vec3A::Z,
            uv: Vec2::ZERO,
            dpdu: Vec3A::X,
            dpdv: Vec3A::Y,
            material: 0,
            light: NONE,
            object: 0,
            prim: PrimRef::Plane(0),
        }
    }

    #[test]
    fn bsdf_evaluates_textures_and_keeps_both_normals() {
        use crate::material::bsdf::TransportMode;
        let ns = fmath::normalize(Vec3A::new(0.1, 0.0, 1.0));
        let hit = Hit { p: Vec3A::new(1.0, 2.0, 3.0), ns, uv: Vec2::new(0.25, 0.5), ..plane_hit() };
        let b =
            Material::Lambert { albedo: Texture::from([0.1, 0.2, 0.3]), bump: None, normal_map: None, two_sided: true }
                .bsdf(&hit, &[]);
        assert_eq!(b.bxdf, Bxdf::Lambert { r: Rgb::new(0.1, 0.2, 0.3) });
        assert_eq!((b.frame.n, b.ng), (ns, Vec3A::Z));
        // Glass seen from below the geometric normal is seen from inside: leaving into air refracts away from
        // the normal, so a ray at 30° inside leaves at asin(1.5·sin 30°) ≈ 48.6°.
        let glass = Material::Dielectric { eta: 1.5, tint: 1.0.into(), roughness: 0.0, bump: None, normal_map: None }
            .bsdf(&Hit { ns: Vec3A::Z, ..hit }, &[]);
        let wo = -Vec3A::new(0.5, 0.0, 0.75f32.sqrt());
        let s = glass.sample(wo, 0.999, Vec2::ZERO, TransportMode::Importance).unwrap();
        assert!(s.wi.z > 0.0 && (s.wi.x.abs() - 0.75).abs() < 1e-5, "{s:?}");
    }

    #[test]
    fn component_queries() {
        let glass = Material::Dielectric { eta: 1.5, tint: 1.0.into(), roughness: 0.0, bump: None, normal_map: None };
        assert!(glass.has_specular() && !glass.has_non_delta() && glass.is_transmissive());
        let lambert = Material::default();
        assert!(!lambert.has_specular() && lambert.has_non_delta() && !lambert.is_transmissive());
        let mix = Material::Mix {
            color: 0.5.into(),
            diffuse: 0.5,
            specular: 0.2,
            transmission: 0.0,
            eta: 1.5,
            bump: None,
            normal_map: None,
        };
        assert!(mix.has_specular() && mix.has_non_delta() && !mix.is_transmissive());
    }

    /// Roughness 0 is the existing delta mirror and glass: the same samples, no non-delta lobe; a rough one is a
    /// microfacet lobe that the photon methods store photons on only from `min_roughness` on.
    #[test]
    fn roughness_zero_falls_back_to_the_delta_lobes() {
        use crate::material::bsdf::TransportMode;
        let hit = plane_hit();
        let m = parse(
            r#"
            [materials.smooth_glass]
            type = "dielectric"
            eta = 1.5
            [materials.rough_glass]
            type = "dielectric"
            eta = 1.5
            roughness = 0.5
            [materials.smooth_metal]
            type = "conductor"
            color = [0.9, 0.6, 0.3]
            roughness = 0.0
            [materials.metal]
            type = "conductor"
            eta = [0.2, 0.4, 1.4]
            k = [4.0, 2.4, 1.6]
            "#,
        )
        .unwrap();
        let (smooth_glass, rough_glass) = (m["smooth_glass"].bsdf(&hit, &[]), m["rough_glass"].bsdf(&hit, &[]));
        assert_eq!(smooth_glass.bxdf, Bxdf::Dielectric { eta: 1.5, tint: Rgb::ONE });
        assert_eq!(rough_glass.bxdf, Bxdf::RoughDielectric { eta: 1.5, tint: Rgb::ONE, alpha: 0.25 });
        let wo = fmath::normalize(Vec3A::new(0.3, 0.2, 0.9));
        let mirror = Material::Mirror { reflectance: 1.0.into(), bump: None, normal_map: None, two_sided: true };
        let (smooth_metal, mirror) = (m["smooth_metal"].bsdf(&hit, &[]), mirror.bsdf(&hit, &[]));
        assert!(smooth_metal.is_delta() && !m["smooth_metal"].has_non_delta());
        let s = smooth_metal.sample(wo, 0.5, Vec2::splat(0.5), TransportMode::Radiance).unwrap();
        let r = mirror.sample(wo, 0.5, Vec2::splat(0.5), TransportMode::Radiance).unwrap();
        assert!(s.delta && s.wi == r.wi && s.pdf == r.pdf, "{s:?} vs {r:?}");
        // The mirror's f is its reflectance over |cos θi|; the metal's carries Schlick's F at the view angle.
        let schlick = Rgb::new(0.9, 0.6, 0.3) + (Rgb::ONE - Rgb::new(0.9, 0.6, 0.3)) * (1.0 - wo.z).powi(5);
        assert!((s.f - r.f * schlick).abs().max_element() < 1e-5, "{} vs {}", s.f, r.f * schlick);
        // The default roughness 0.3 is just rough enough for photons at the default threshold 0.3.
        let metal = m["metal"].bsdf(&hit, &[]);
        assert!(metal.has_non_delta() && metal.stores_photons(0.3) && !metal.stores_photons(0.31));
        assert!(!rough_glass.stores_photons(0.0), "transmitting glass stores no photons");
        assert!(!smooth_metal.stores_photons(0.0));
        assert!(parse("[materials.a]\ntype = \"conductor\"\neta = 0.2\n").unwrap()["a"].validate().is_err());
        assert!(parse("[materials.a]\ntype = \"dielectric\"\nroughness = 1.5\n").unwrap()["a"].validate().is_err());
    }
}
