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
//! - `mix`: the original renderer's material, `diffuse·lambert(color) + specular·mirror + transmission·glass(eta)`.
//!   `color` tints the diffuse part only (default 0.8); the weights `diffuse`, `specular` and `transmission`
//!   (each ≥ 0, default 0, so a mix names the parts it has) sum to at most 1, and the rest is absorbed;
//!   `eta` as for `dielectric` (default 1.5).
//!
//! Unknown fields are errors. [`Material::validate`] checks the ranges; the scene loader reports its message
//! under the material's path.

use crate::Rgb;
pub mod bsdf;

use crate::error::FieldError;
use crate::geometry::Hit;
use bsdf::{Bsdf, Bxdf};
use glam::{Vec2, Vec3A};
use serde::de::{self, SeqAccess, Visitor};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// A colour that may vary over a surface. In the scene file: a number (grey) or `[r, g, b]`.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// The same colour everywhere.
    Constant(Rgb),
}

impl Texture {
    /// A grey constant.
    pub const fn grey(v: f32) -> Self {
        Texture::Constant(Rgb::splat(v))
    }

    /// The colour at texture coordinates `uv` and point `p`.
    #[inline]
    pub fn eval(&self, uv: Vec2, p: Vec3A) -> Rgb {
        let _ = (uv, p);
        match self {
            Texture::Constant(c) => *c,
        }
    }

    /// The largest value of any channel anywhere.
    pub fn max_value(&self) -> f32 {
        match self {
            Texture::Constant(c) => c.max_element(),
        }
    }

    /// Checks that the texture is a reflectance: every value finite and in `[0, 1]`. The error names `field`.
    pub fn validate_reflectance(&self, field: &str) -> Result<(), FieldError> {
        match self {
            Texture::Constant(c) => {
                if c.to_array().iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)) {
                    Ok(())
                } else {
                    Err(FieldError::new(field, format!("expected values in [0, 1], got [{}, {}, {}]", c.x, c.y, c.z)))
                }
            }
        }
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

/// The binary form of [`Texture`] (serde's default enum representation, which bincode can read).
#[derive(Serialize, Deserialize)]
enum TextureBinary {
    Constant([f32; 3]),
}

impl Serialize for Texture {
    /// In text formats a grey constant as a number, any other constant as `[r, g, b]`; in binary formats a
    /// plain enum.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Texture::Constant(c) if !s.is_human_readable() => TextureBinary::Constant(c.to_array()).serialize(s),
            Texture::Constant(c) if c.x == c.y && c.y == c.z => s.serialize_f32(c.x),
            Texture::Constant(c) => {
                let mut seq = s.serialize_seq(Some(3))?;
                for v in c.to_array() {
                    seq.serialize_element(&v)?;
                }
                seq.end()
            }
        }
    }
}

impl<'de> Deserialize<'de> for Texture {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            d.deserialize_any(TextureVisitor)
        } else {
            match TextureBinary::deserialize(d)? {
                TextureBinary::Constant(c) => Ok(Texture::from(c)),
            }
        }
    }
}

/// Reads a number or an `[r, g, b]` array.
struct TextureVisitor;

impl<'de> Visitor<'de> for TextureVisitor {
    type Value = Texture;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or an [r, g, b] array")
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
}

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
    },
    /// A perfect mirror.
    Mirror {
        /// Reflectance (default 1).
        #[serde(default = "default_one")]
        reflectance: Texture,
    },
    /// Smooth glass.
    Dielectric {
        /// Index of refraction, inside over outside (default 1.5).
        #[serde(default = "default_eta")]
        eta: f32,
        /// Multiplies reflected and transmitted light (default 1).
        #[serde(default = "default_one")]
        tint: Texture,
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
    },
}

/// The binary form of [`Material`]: the same fields in declaration order, in serde's default (externally
/// tagged) enum representation.
#[derive(Serialize, Deserialize)]
enum MaterialBinary {
    Lambert(Texture),
    Phong(Texture, Texture, f32),
    Mirror(Texture),
    Dielectric(f32, Texture),
    Mix(Texture, f32, f32, f32, f32),
}

impl Serialize for Material {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            // The derived scene-file form (`remote = "Self"` makes it an inherent function).
            return Material::serialize(self, s);
        }
        match self.clone() {
            Material::Lambert { albedo } => MaterialBinary::Lambert(albedo),
            Material::Phong { diffuse, specular, exponent } => MaterialBinary::Phong(diffuse, specular, exponent),
            Material::Mirror { reflectance } => MaterialBinary::Mirror(reflectance),
            Material::Dielectric { eta, tint } => MaterialBinary::Dielectric(eta, tint),
            Material::Mix { color, diffuse, specular, transmission, eta } => {
                MaterialBinary::Mix(color, diffuse, specular, transmission, eta)
            }
        }
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for Material {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            return Material::deserialize(d);
        }
        Ok(match MaterialBinary::deserialize(d)? {
            MaterialBinary::Lambert(albedo) => Material::Lambert { albedo },
            MaterialBinary::Phong(diffuse, specular, exponent) => Material::Phong { diffuse, specular, exponent },
            MaterialBinary::Mirror(reflectance) => Material::Mirror { reflectance },
            MaterialBinary::Dielectric(eta, tint) => Material::Dielectric { eta, tint },
            MaterialBinary::Mix(color, diffuse, specular, transmission, eta) => {
                Material::Mix { color, diffuse, specular, transmission, eta }
            }
        })
    }
}

fn default_albedo() -> Texture {
    Texture::grey(0.8)
}

fn default_one() -> Texture {
    Texture::grey(1.0)
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
        Material::Lambert { albedo: default_albedo() }
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
        match self {
            Material::Lambert { albedo } => albedo.validate_reflectance("albedo"),
            Material::Phong { diffuse, specular, exponent } => {
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
                match (diffuse, specular) {
                    (Texture::Constant(kd), Texture::Constant(ks)) => {
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
                }
                Ok(())
            }
            Material::Mirror { reflectance } => reflectance.validate_reflectance("reflectance"),
            Material::Dielectric { eta, tint } => {
                validate_eta(*eta)?;
                tint.validate_reflectance("tint")
            }
            Material::Mix { color, diffuse, specular, transmission, eta } => {
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
        }
    }

    /// The BSDF at a hit: textures evaluated at `hit.uv`, `hit.p`; shading frame from `hit.ns`; `hit.n` kept to
    /// tell the inside of glass from the outside.
    pub fn bsdf(&self, hit: &Hit) -> Bsdf {
        let (uv, p) = (hit.uv, hit.p);
        let bxdf = match self {
            Material::Lambert { albedo } => Bxdf::Lambert { r: albedo.eval(uv, p) },
            Material::Phong { diffuse, specular, exponent } => {
                Bxdf::Phong { kd: diffuse.eval(uv, p), ks: specular.eval(uv, p), exponent: *exponent }
            }
            Material::Mirror { reflectance } => Bxdf::Mirror { r: reflectance.eval(uv, p) },
            Material::Dielectric { eta, tint } => Bxdf::Dielectric { eta: *eta, tint: tint.eval(uv, p) },
            Material::Mix { color, diffuse, specular, transmission, eta } => Bxdf::Mix {
                color: color.eval(uv, p),
                diffuse: *diffuse,
                specular: *specular,
                transmission: *transmission,
                eta: *eta,
            },
        };
        Bsdf::new(hit.ns, hit.n, bxdf)
    }

    /// Whether the material has a delta (perfectly specular: mirror or glass) component, so that caustic paths
    /// (light → specular → … → diffuse) exist and a caustic photon map is worth building.
    pub fn has_specular(&self) -> bool {
        match self {
            Material::Lambert { .. } | Material::Phong { .. } => false,
            Material::Mirror { .. } | Material::Dielectric { .. } => true,
            Material::Mix { specular, transmission, .. } => *specular > 0.0 || *transmission > 0.0,
        }
    }

    /// Whether the material has a non-delta (diffuse or glossy) component: photons are stored on it and direct
    /// light is sampled there.
    pub fn has_non_delta(&self) -> bool {
        match self {
            Material::Lambert { .. } | Material::Phong { .. } => true,
            Material::Mirror { .. } | Material::Dielectric { .. } => false,
            Material::Mix { diffuse, .. } => *diffuse > 0.0,
        }
    }

    /// Whether light can pass through the surface (glass, or a mix with transmission).
    pub fn is_transmissive(&self) -> bool {
        match self {
            Material::Lambert { .. } | Material::Phong { .. } | Material::Mirror { .. } => false,
            Material::Dielectric { .. } => true,
            Material::Mix { transmission, .. } => *transmission > 0.0,
        }
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
    use crate::math::fmath;
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
        assert_eq!(m.len(), 5);
        for mat in m.values() {
            mat.validate().unwrap();
        }
        assert_eq!(m["red"], Material::Lambert { albedo: Texture::from([0.63, 0.065, 0.05]) });
        assert_eq!(m["glass"], Material::Dielectric { eta: 1.5, tint: Texture::grey(1.0) });
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
            Material::Phong { diffuse: Texture::grey(0.5), specular: Texture::grey(0.3), exponent: 20.0 }
        );
        assert_eq!(m["c"], Material::Mirror { reflectance: Texture::grey(1.0) });
        assert_eq!(m["d"], Material::Dielectric { eta: 1.5, tint: Texture::grey(1.0) });
        assert_eq!(
            m["e"],
            Material::Mix { color: Texture::grey(0.8), diffuse: 0.0, specular: 0.0, transmission: 0.0, eta: 1.5 }
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
            Material::Phong { diffuse: Texture::grey(0.0), specular: Texture::from([1.0, 0.0, 0.0]), exponent: 100.0 }
        );
    }

    #[test]
    fn bad_textures_say_what_was_expected() {
        for bad in ["\"red\"", "[0.1, 0.2]", "[0.1, 0.2, 0.3, 0.4]", "{ r = 1 }"] {
            let e = parse(&format!("[materials.a]\ntype = \"lambert\"\nalbedo = {bad}\n")).unwrap_err();
            assert!(e.contains("expected a number or an [r, g, b] array"), "{bad}: {e}");
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
                ("a".into(), Material::Lambert { albedo: Texture::from([0.63, 0.065, 0.05]) }),
                ("b".into(), Material::Phong { diffuse: 0.2.into(), specular: 0.7.into(), exponent: 8.0 }),
                (
                    "c".into(),
                    Material::Mix { color: 0.5.into(), diffuse: 0.1, specular: 0.2, transmission: 0.3, eta: 1.3 },
                ),
            ]),
        };
        // Through a TOML value: the crate reads TOML but does not need to write it as text.
        let v = toml::Value::try_from(&f).unwrap();
        assert_eq!(v["materials"]["a"]["albedo"].as_array().map(Vec::len), Some(3));
        assert!(v["materials"]["b"]["diffuse"].is_float());
        assert_eq!(v.try_into::<File>().unwrap(), f);
    }

    #[test]
    fn binary_round_trip() {
        // Prepared scenes travel to workers through bincode, which cannot read the scene file's internal tag.
        let all = vec![
            Material::Lambert { albedo: Texture::from([0.63, 0.065, 0.05]) },
            Material::Phong { diffuse: 0.2.into(), specular: 0.7.into(), exponent: 8.0 },
            Material::Mirror { reflectance: 0.9.into() },
            Material::Dielectric { eta: 1.33, tint: [1.0, 0.9, 0.8].into() },
            Material::Mix { color: 0.5.into(), diffuse: 0.1, specular: 0.2, transmission: 0.3, eta: 1.3 },
        ];
        let bytes = crate::codec::encode(&all).unwrap();
        assert_eq!(crate::codec::decode::<Vec<Material>>(&bytes, bytes.len()).unwrap(), all);
    }

    #[test]
    fn validation_names_the_field() {
        let cases = [
            (Material::Lambert { albedo: 1.2.into() }, "albedo"),
            (Material::Lambert { albedo: f32::NAN.into() }, "albedo"),
            (
                Material::Phong { diffuse: 0.6.into(), specular: [0.5, 0.3, 0.3].into(), exponent: 10.0 },
                "diffuse + specular",
            ),
            (Material::Phong { diffuse: 0.5.into(), specular: 0.3.into(), exponent: -1.0 }, "exponent"),
            (Material::Phong { diffuse: 0.5.into(), specular: 0.3.into(), exponent: 1e30 }, "exponent"),
            (Material::Mirror { reflectance: (-0.1).into() }, "reflectance"),
            (Material::Dielectric { eta: 0.0, tint: 1.0.into() }, "eta"),
            (Material::Dielectric { eta: 1.5, tint: f32::INFINITY.into() }, "tint"),
            (Material::Mix { color: 0.5.into(), diffuse: 0.5, specular: 0.4, transmission: 0.3, eta: 1.5 }, "= 1.2"),
            (Material::Mix { color: 0.5.into(), diffuse: -0.1, specular: 0.4, transmission: 0.3, eta: 1.5 }, "diffuse"),
        ];
        for (m, needle) in cases {
            let e = m.validate().unwrap_err();
            assert!(e.to_string().contains(needle), "{m:?}: {e}");
        }
        let ok = Material::Mix { color: 0.5.into(), diffuse: 0.1, specular: 0.2, transmission: 0.7, eta: 1.5 };
        ok.validate().unwrap();
    }

    #[test]
    fn bsdf_evaluates_textures_and_keeps_both_normals() {
        use crate::geometry::{NONE, PrimRef};
        use crate::material::bsdf::TransportMode;
        let ns = fmath::normalize(Vec3A::new(0.1, 0.0, 1.0));
        let hit = Hit {
            t: 1.0,
            p: Vec3A::new(1.0, 2.0, 3.0),
            p_error: Vec3A::ZERO,
            n: Vec3A::Z,
            ns,
            uv: Vec2::new(0.25, 0.5),
            material: 0,
            light: NONE,
            object: 0,
            prim: PrimRef::Plane(0),
        };
        let b = Material::Lambert { albedo: Texture::from([0.1, 0.2, 0.3]) }.bsdf(&hit);
        assert_eq!(b.bxdf, Bxdf::Lambert { r: Rgb::new(0.1, 0.2, 0.3) });
        assert_eq!((b.frame.n, b.ng), (ns, Vec3A::Z));
        // Glass seen from below the geometric normal is seen from inside: leaving into air refracts away from
        // the normal, so a ray at 30° inside leaves at asin(1.5·sin 30°) ≈ 48.6°.
        let glass = Material::Dielectric { eta: 1.5, tint: 1.0.into() }.bsdf(&Hit { ns: Vec3A::Z, ..hit });
        let wo = -Vec3A::new(0.5, 0.0, 0.75f32.sqrt());
        let s = glass.sample(wo, 0.999, Vec2::ZERO, TransportMode::Importance).unwrap();
        assert!(s.wi.z > 0.0 && (s.wi.x.abs() - 0.75).abs() < 1e-5, "{s:?}");
    }

    #[test]
    fn component_queries() {
        let glass = Material::Dielectric { eta: 1.5, tint: 1.0.into() };
        assert!(glass.has_specular() && !glass.has_non_delta() && glass.is_transmissive());
        let lambert = Material::default();
        assert!(!lambert.has_specular() && lambert.has_non_delta() && !lambert.is_transmissive());
        let mix = Material::Mix { color: 0.5.into(), diffuse: 0.5, specular: 0.2, transmission: 0.0, eta: 1.5 };
        assert!(mix.has_specular() && mix.has_non_delta() && !mix.is_transmissive());
    }
}
