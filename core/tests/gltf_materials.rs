//! Claim: glTF materials become the BSDFs the glTF 2.0 specification's appendix B describes, with the values
//! the file gives:
//! - metallic 1 over a white base is the Schlick conductor of F0 = 1 at α = roughness²: the same `f` for every
//!   pair, and the same white-furnace albedo (5 standard errors of 100 000 samples);
//! - metallic 0 is the F0 = 0.04 layer over the diffuse base, and scatters at most what it receives;
//! - `KHR_materials_transmission` with `KHR_materials_ior` is rough glass of that index and roughness, tinted
//!   by the base colour;
//! - the metallic-roughness texture is read texel by texel (blue: metalness, green: roughness), not averaged;
//! - a base colour factor multiplies its texture (sRGB texels decoded, then scaled);
//! - the emission is `emissiveFactor × KHR_materials_emissive_strength`.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder};
use common::{Mean, dir, flat, sampler};
use glam::{Vec2, Vec3A};
use photon_core::Rgb;
use photon_core::geometry::{Hit, NONE, PrimRef};
use photon_core::material::Material;
use photon_core::material::bsdf::{Bsdf, Bxdf, TransportMode};
use photon_core::material::microfacet::ConductorFresnel;
use photon_core::prepare::gltf::{Imported, import};

/// A PNG of `w × h` RGB texels.
fn png(w: u32, h: u32, texels: &[[u8; 3]]) -> Vec<u8> {
    let img = image::RgbImage::from_raw(w, h, texels.iter().flatten().copied().collect()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// Seven materials on seven triangles (see the module docs); the images are embedded in the buffer.
fn imported() -> Imported {
    let mut b = Builder::default();
    let p = b.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let uv = b.vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
    // Texel 0: metal 1, roughness 0; texel 1: metal 0, roughness 1.
    let mr = b.bytes(&png(2, 1, &[[0, 0, 255], [0, 255, 0]]));
    let grey = b.bytes(&png(1, 1, &[[188, 188, 188]]));
    let prims: Vec<String> =
        (0..6).map(|m| format!(r#"{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{uv}}},"material":{m}}}"#)).collect();
    b.member(&format!(r#""meshes":[{{"primitives":[{}]}}]"#, prims.join(",")));
    b.member(&format!(
        r#""images":[{{"bufferView":{mr},"mimeType":"image/png"}},{{"bufferView":{grey},"mimeType":"image/png"}}]"#
    ));
    b.member(r#""samplers":[{"magFilter":9728,"minFilter":9728}],"textures":[{"source":0,"sampler":0},{"source":1}]"#);
    b.member(
        r#""materials":[
        {"pbrMetallicRoughness":{"metallicFactor":1,"roughnessFactor":0.5}},
        {"pbrMetallicRoughness":{"baseColorFactor":[0.5,0.5,0.5,1],"metallicFactor":0,"roughnessFactor":0.3}},
        {"pbrMetallicRoughness":{"baseColorFactor":[0.9,0.8,0.7,1],"metallicFactor":0,"roughnessFactor":0.2},
         "extensions":{"KHR_materials_transmission":{"transmissionFactor":1},"KHR_materials_ior":{"ior":1.33}}},
        {"pbrMetallicRoughness":{"metallicRoughnessTexture":{"index":0},"metallicFactor":1,"roughnessFactor":0.8}},
        {"pbrMetallicRoughness":{"baseColorTexture":{"index":1},"baseColorFactor":[0.5,1,1,1]}},
        {"emissiveFactor":[1,0.5,0.25],"extensions":{"KHR_materials_emissive_strength":{"emissiveStrength":4}}}
    ]"#,
    );
    b.member(r#""nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]"#);
    b.member(
        r#""extensionsUsed":["KHR_materials_transmission","KHR_materials_ior","KHR_materials_emissive_strength"]"#,
    );
    // One folder per call: the tests run in parallel and each makes the file.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let dir = folder(&format!("materials-{}", CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed)));
    let path = dir.join("materials.glb");
    std::fs::write(&path, b.glb()).unwrap();
    let out = import(&path, &glam::Affine3A::IDENTITY, u64::MAX, u64::MAX).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    out
}

/// A hit on the plane z = 0 at texture coordinates `uv` (photon's v-up convention).
fn hit(uv: Vec2) -> Hit {
    Hit {
        t: 1.0,
        p: Vec3A::ZERO,
        p_error: Vec3A::ZERO,
        n: Vec3A::Z,
        ns: Vec3A::Z,
        uv,
        dpdu: Vec3A::X,
        dpdv: Vec3A::Y,
        material: 0,
        light: NONE,
        object: 0,
        prim: PrimRef::Plane(0),
    }
}

fn bsdf(imp: &Imported, m: usize, uv: Vec2) -> Bsdf {
    imp.materials[m].bsdf(&hit(uv), &imp.images)
}

/// The sampled white-furnace albedo of `b` seen from `wo`.
fn albedo(b: &Bsdf, wo: Vec3A, case: u64) -> Mean {
    let mut rng = sampler(77, case);
    let mut m = Mean::default();
    for _ in 0..100_000 {
        let w = match b.sample(wo, rng.next_f32(), rng.next_2d(), TransportMode::Importance) {
            Some(s) => s.f * s.wi.dot(b.frame.n).abs() / s.pdf,
            None => Rgb::ZERO,
        };
        m.add(w);
    }
    m
}

#[test]
fn metallic_one_is_the_conductor() {
    let imp = imported();
    let b = bsdf(&imp, 0, Vec2::ZERO);
    assert_eq!(b.bxdf, Bxdf::MetallicRoughness { base: Rgb::ONE, metallic: 1.0, alpha: 0.25 });
    let metal = flat(Bxdf::Conductor { fresnel: ConductorFresnel::Schlick { f0: Rgb::ONE }, alpha: 0.25 });
    for (k, theta) in [0.1f32, 0.6, 1.2, 1.5].into_iter().enumerate() {
        let wo = dir(theta, 0.3);
        for j in 0..50 {
            let wi = dir(1.5 * j as f32 / 50.0, 2.0 + 0.1 * j as f32);
            let (a, c) = (b.f(wo, wi, TransportMode::Radiance), metal.f(wo, wi, TransportMode::Radiance));
            assert!((a - c).abs().max_element() <= 1e-5 * c.max_element().max(1.0), "{a} vs {c}");
        }
        let (a, c) = (albedo(&b, wo, k as u64), albedo(&metal, wo, k as u64 + 100));
        for ch in 0..3 {
            let se = (a.std_error()[ch].powi(2) + c.std_error()[ch].powi(2)).sqrt();
            assert!(
                (a.mean()[ch] - c.mean()[ch]).abs() <= 5.0 * se + 1e-6,
                "θ {theta}: {:?} vs {:?}",
                a.mean(),
                c.mean()
            );
            assert!(a.mean()[ch] <= 1.0 + 5.0 * a.std_error()[ch]);
        }
    }
}

#[test]
fn metallic_zero_is_the_coated_diffuse_base() {
    let imp = imported();
    let b = bsdf(&imp, 1, Vec2::ZERO);
    assert_eq!(b.bxdf, Bxdf::MetallicRoughness { base: Rgb::splat(0.5), metallic: 0.0, alpha: 0.3 * 0.3 });
    use photon_core::material::metallic_roughness::{DIELECTRIC_F0, diffuse_f};
    use photon_core::material::microfacet::{TrowbridgeReitz, conductor_f};
    let layer = ConductorFresnel::Schlick { f0: Rgb::splat(DIELECTRIC_F0) };
    let (wo, wi) = (dir(0.7, 0.2), dir(0.4, 2.9));
    let want = conductor_f(&TrowbridgeReitz { alpha: 0.09 }, &layer, wo, wi) + diffuse_f(Rgb::splat(0.5), 0.0, wo, wi);
    assert!((b.f(wo, wi, TransportMode::Radiance) - want).abs().max_element() < 1e-6);
    for (k, theta) in [0.0f32, 0.8, 1.4].into_iter().enumerate() {
        let a = albedo(&b, dir(theta, 0.0), 10 + k as u64);
        for ch in 0..3 {
            assert!(a.mean()[ch] <= 1.0 + 5.0 * a.std_error()[ch], "θ {theta}: {:?}", a.mean());
            // The base's albedo under the layer, (1 − F(cos θo))·0.5, and a little specular on top.
            assert!(a.mean()[ch] > 0.4, "θ {theta}: {:?}", a.mean());
        }
    }
}

#[test]
fn transmission_is_rough_glass_of_the_ior() {
    let imp = imported();
    match &imp.materials[2] {
        Material::Dielectric { eta, roughness, .. } => assert_eq!((*eta, *roughness), (1.33, 0.2)),
        m => panic!("{m:?}"),
    }
    assert_eq!(
        bsdf(&imp, 2, Vec2::ZERO).bxdf,
        Bxdf::RoughDielectric { eta: 1.33, tint: Rgb::new(0.9, 0.8, 0.7), alpha: 0.2 * 0.2 }
    );
}

#[test]
fn the_metallic_roughness_texture_is_read_texel_by_texel() {
    let imp = imported();
    // glTF's u across the 2 × 1 image: texel 0 at u = 0.25, texel 1 at u = 0.75.
    let metal = bsdf(&imp, 3, Vec2::new(0.25, 0.5)).bxdf;
    let rough = bsdf(&imp, 3, Vec2::new(0.75, 0.5)).bxdf;
    assert_eq!(metal, Bxdf::MetallicRoughness { base: Rgb::ONE, metallic: 1.0, alpha: 0.0 });
    assert_eq!(rough, Bxdf::MetallicRoughness { base: Rgb::ONE, metallic: 0.0, alpha: 0.8 * 0.8 });
}

#[test]
fn the_base_colour_factor_multiplies_the_texture() {
    let imp = imported();
    let Bxdf::MetallicRoughness { base, .. } = bsdf(&imp, 4, Vec2::splat(0.5)).bxdf else { panic!() };
    let texel = photon_core::material::texture::srgb_decode(188.0 / 255.0);
    assert!((base - Rgb::new(0.5 * texel, texel, texel)).abs().max_element() < 1e-6, "{base}");
}

#[test]
fn emission_is_the_factor_times_the_strength() {
    let imp = imported();
    let emitting: Vec<_> = imp.meshes.iter().filter(|m| !m.emission.is_empty()).collect();
    assert_eq!(emitting.len(), 1);
    assert_eq!(emitting[0].material, 5);
    assert_eq!(emitting[0].emission, vec![Rgb::new(4.0, 2.0, 1.0)]);
}
