//! The glTF 2.0 metallic–roughness model in the local shading frame (`cos θ = w.z`), as the glTF 2.0
//! specification's appendix B describes it (B.3.1–B.3.5):
//!
//! ```text
//! metal      = conductor_fresnel(f0 = base, specular_brdf(α))
//! dielectric = fresnel_mix(ior = 1.5, base = diffuse_brdf(base), layer = specular_brdf(α))
//! material   = mix(dielectric, metal, metallic)
//! ```
//!
//! `specular_brdf` is the Trowbridge–Reitz lobe of width `α = roughness²` ([`super::microfacet`]), and both
//! Fresnel terms are Schlick's with `VdotH`: the metal's with `F0 = base`, the dielectric layer's with
//! `F0 = 0.04` (`ior` 1.5). Schlick's form is affine in `F0`, so the two specular lobes add up to one lobe with
//! `F0 = mix(0.04, base, metallic)` (appendix B.3.5 writes it so too).
//!
//! One departure, for energy: appendix B weighs the diffuse base by `1 − F_0.04(VdotH)`, which scatters more
//! than it receives at grazing angles (3.3 % too much at θo = 80° for a base of 0.8 and roughness 0.3, in
//! `core/tests/bsdf_albedo.rs`'s furnace), because the half vector of most pairs is nearer to `wo` than the
//! normal is. Here the base keeps what the layer lets through on the way in and on the way out,
//! `(1 − metallic)·base/π·(1 − F(cos θo))·(1 − F(cos θi)) / (1 − F̄)`, with `F̄ = 0.04 + 0.96/21` the
//! cosine-weighted mean of `F_0.04` (Ashikhmin and Shirley 2000 couple a diffuse base to a specular layer the
//! same way): reciprocal, and the base's albedo is exactly `(1 − metallic)·(1 − F(cos θo))·base`, so with the
//! lobe's single-scattering albedo (at most its Fresnel reflectance at the view angle) the sum stays ≤ 1.
//!
//! Below [`SMOOTH_ALPHA`](super::microfacet::SMOOTH_ALPHA) the specular lobe is a delta mirror with the
//! Fresnel reflectance at the view angle, over the same diffuse base.

use super::microfacet::{self, ConductorFresnel, TrowbridgeReitz};
use crate::Rgb;
use crate::math::luminance;
use glam::Vec3A;
use std::f32::consts::FRAC_1_PI;

/// The reflectance at normal incidence of glTF's dielectric base (`ior` 1.5: `((1.5 − 1)/(1.5 + 1))² = 0.04`).
pub const DIELECTRIC_F0: f32 = 0.04;

/// The specular lobes' Fresnel: Schlick's with `F0 = mix(0.04, base, metallic)`.
#[inline]
pub fn fresnel(base: Rgb, metallic: f32) -> ConductorFresnel {
    let f0 = Rgb::splat(DIELECTRIC_F0) * (1.0 - metallic) + base * metallic;
    ConductorFresnel::Schlick { f0 }
}

/// Schlick's reflectance of the dielectric layer (`F0` = 0.04) at cosine `c`.
#[inline]
fn dielectric_schlick(c: f32) -> f32 {
    let m = 1.0 - c.abs().min(1.0);
    let m5 = (m * m) * (m * m) * m;
    DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * m5
}

/// The cosine-weighted mean of the dielectric layer's reflectance over the hemisphere,
/// `2∫ F_0.04(c)·c dc = 0.04 + 0.96·2·B(2, 6) = 0.04 + 0.96/21`.
const MEAN_DIELECTRIC_F: f32 = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) / 21.0;

/// The diffuse base, `(1 − metallic)·base/π·(1 − F(cos θo))·(1 − F(cos θi)) / (1 − F̄)` (see the module docs).
#[inline]
pub fn diffuse_f(base: Rgb, metallic: f32, wo: Vec3A, wi: Vec3A) -> Rgb {
    if metallic >= 1.0 {
        return Rgb::ZERO;
    }
    let through = (1.0 - dielectric_schlick(wo.z)) * (1.0 - dielectric_schlick(wi.z));
    base * ((1.0 - metallic) * through / (1.0 - MEAN_DIELECTRIC_F) * FRAC_1_PI)
}

/// The non-delta part of the BSDF for a pair on one geometric side: the diffuse base, and the specular lobe
/// when it is rough (`alpha` ≥ [`SMOOTH_ALPHA`](super::microfacet::SMOOTH_ALPHA)).
#[inline]
pub fn f(base: Rgb, metallic: f32, alpha: f32, wo: Vec3A, wi: Vec3A) -> Rgb {
    let diffuse = diffuse_f(base, metallic, wo, wi);
    if alpha < microfacet::SMOOTH_ALPHA {
        return diffuse;
    }
    diffuse + microfacet::conductor_f(&TrowbridgeReitz { alpha }, &fresnel(base, metallic), wo, wi)
}

/// The probability of sampling the specular lobe for `wo` (local): its Fresnel reflectance at the view angle
/// against the diffuse base's weight, by luminance. It depends on `wo` only, so the mixture's density is
/// well defined.
#[inline]
pub fn specular_probability(base: Rgb, metallic: f32, wo: Vec3A) -> f32 {
    let spec = luminance(fresnel(base, metallic).eval(wo.z));
    let diffuse = (1.0 - metallic) * (1.0 - dielectric_schlick(wo.z)) * luminance(base);
    if spec + diffuse > 0.0 { spec / (spec + diffuse) } else { 1.0 }
}

/// The solid-angle density of the sampler's non-delta lobes: `p·D_wo(h)/(4|wo·h|) + (1 − p)·|cos θi|/π` with
/// `p` the [`specular_probability`]; the specular term only for a rough lobe.
#[inline]
pub fn pdf(base: Rgb, metallic: f32, alpha: f32, wo: Vec3A, wi: Vec3A) -> f32 {
    let p = specular_probability(base, metallic, wo);
    let diffuse = (1.0 - p) * wi.z.abs() * FRAC_1_PI;
    if alpha < microfacet::SMOOTH_ALPHA {
        return diffuse;
    }
    diffuse + p * microfacet::conductor_pdf(&TrowbridgeReitz { alpha }, wo, wi)
}

/// The flux scattered from `wo`, for Russian roulette: the diffuse base's albedo (exact) plus the specular
/// Fresnel reflectance at the view angle (exact for the smooth lobe, a bound for a rough one), at most 1.
#[inline]
pub fn albedo(base: Rgb, metallic: f32, wo: Vec3A) -> Rgb {
    let spec = fresnel(base, metallic).eval(wo.z);
    (spec + base * ((1.0 - metallic) * (1.0 - dielectric_schlick(wo.z)))).min(Rgb::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fmath;

    #[test]
    fn metal_and_dielectric_ends() {
        let base = Rgb::new(0.9, 0.5, 0.2);
        let (wo, wi) = (fmath::normalize(Vec3A::new(0.3, 0.1, 0.9)), fmath::normalize(Vec3A::new(-0.2, 0.4, 0.8)));
        // metallic 1: no diffuse, the conductor with Schlick's F0 = base.
        assert_eq!(diffuse_f(base, 1.0, wo, wi), Rgb::ZERO);
        let metal =
            microfacet::conductor_f(&TrowbridgeReitz { alpha: 0.25 }, &ConductorFresnel::Schlick { f0: base }, wo, wi);
        assert!((f(base, 1.0, 0.25, wo, wi) - metal).abs().max_element() < 1e-6);
        // metallic 0: the F0 = 0.04 layer over a Lambert base.
        let layer = microfacet::conductor_f(
            &TrowbridgeReitz { alpha: 0.25 },
            &ConductorFresnel::Schlick { f0: Rgb::splat(DIELECTRIC_F0) },
            wo,
            wi,
        );
        let through = (1.0 - dielectric_schlick(wo.z)) * (1.0 - dielectric_schlick(wi.z));
        let lambert = base * (through / (1.0 - MEAN_DIELECTRIC_F) * FRAC_1_PI);
        assert!((f(base, 0.0, 0.25, wo, wi) - layer - lambert).abs().max_element() < 1e-6);
    }
}
