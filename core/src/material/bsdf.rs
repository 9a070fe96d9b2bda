//! Scattering at a surface point: a [`Bxdf`] (the lobes, with textures already evaluated) in a shading frame.
//!
//! A [`crate::material::Material`] evaluates its textures at a hit and returns a [`Bsdf`] by value; integrators
//! only talk to the `Bsdf`, always with world-space unit directions `wo`, `wi` that point away from the surface.
//! The lobes themselves work in the local shading frame, where the shading normal is +z and `cos θ = w.z`.
//!
//! ## Conventions
//! - [`Bsdf::f`] and [`Bsdf::pdf`] cover the non-delta lobes only (Lambert, Phong, rough metal and glass);
//!   mirror, smooth metal and glass are zero there. [`Bsdf::sample`] draws from every lobe.
//! - An integrator updates its throughput with `beta *= s.f * |wi·ns| / s.pdf` for every sample `s`. For a delta
//!   lobe we follow pbrt: `f = (reflectance or transmittance) / |cos θi|` and `pdf` is the discrete probability
//!   of choosing that lobe, so the same formula gives `beta *= reflectance / probability`.
//! - Shading normals (Veach 1997, §5.3): the geometric normal `ng` alone decides between reflection and
//!   transmission, the shading normal only shapes the lobe. A reflective lobe scatters exactly when `wo` and
//!   `wi` lie on the same side of `ng`, whatever their sides of the shading normal: anything else would leak
//!   light through the surface (light-leak rule), and zeroing pairs that a tilted shading normal separates
//!   would draw black fringes where the shading and geometric horizons disagree (black-fringe rule). The
//!   cosine is the shading one, `|wi·ns|`. The diffuse lobes sample `|wi·ns|/π` over `wo`'s geometric
//!   hemisphere, which reaches all of it and integrates to 1 for any tilt; a sampled direction on the other
//!   geometric side (from the Phong lobe) is returned as `None`, and [`Bsdf::pdf`] is 0 there, so it is the
//!   density of the samples actually returned. A transmitted direction must cross the geometric surface.
//! - Light paths with shading normals are not the mirror image of camera paths: the BSDF with the shading
//!   cosine is not symmetric with respect to the geometric measure, so photons scatter with its adjoint,
//!   [`Bsdf::adjoint_correction`] (Veach 1997, eq. 5.17).
//! - Glass: `wo` on the side the geometric normal points to means the path is outside, so light is entering
//!   and the relative index is `eta`; on the other side it is `1/eta`. In [`TransportMode::Radiance`] a
//!   transmitted sample is scaled by `1/η'²` (η' = η_transmitted / η_incident as seen from `wo`), because
//!   radiance, unlike flux, is compressed into a narrower cone on entering a denser medium (Veach 1997, §5.2;
//!   pbrt-v4 §9.5.2). Photons carry flux and use [`TransportMode::Importance`], without that factor.
//! - Lambert, Phong and the conductor are reciprocal, `f(wo, wi) = f(wi, wo)`; the transport mode does not
//!   change them.
//! - Rough glass ([`Bxdf::RoughDielectric`], [`super::microfacet`]) reflects and refracts through non-delta
//!   lobes. Its refracted value carries the `1/η'²` of radiance mode like smooth glass, so it is reciprocal in
//!   the adjoint sense, `f_radiance(wo, wi) = f_importance(wi, wo)`. A pair must lie on the same sides of the
//!   geometric and the shading normal to scatter (a reflection on one side of both, a refraction across both):
//!   a rough lobe has no symmetric way to reach the pairs they disagree on, so those carry no light.

use super::metallic_roughness as mr;
use super::microfacet::{self, ConductorFresnel, SMOOTH_ALPHA, TrowbridgeReitz};
use crate::Rgb;
use crate::math::fmath;
use crate::math::{Frame, cosine_hemisphere, fresnel_dielectric, luminance, refract};
use glam::{Vec2, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI};

/// The largest `f32` below 1, for remapping a used-up uniform sample back into `[0, 1)`.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// What a path carries, which decides whether refraction scales it by `1/η'²`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    /// Camera paths carry radiance: transmission scales by `1/η'²`.
    Radiance,
    /// Light paths (photons) carry flux, or importance: no `1/η'²` factor.
    Importance,
}

/// The scattering lobes at one point, with every texture evaluated. Colours are reflectances in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bxdf {
    /// Ideal diffuse reflection, `f = r/π`.
    Lambert {
        /// Reflectance (the albedo).
        r: Rgb,
    },
    /// Modified Phong (Lafortune & Willems 1994): `f = kd/π + ks·(n+2)/(2π)·cos^n α`, with α the angle between
    /// `wi` and the mirror direction of `wo`. Energy conserving when `kd + ks ≤ 1` per channel.
    Phong {
        /// Diffuse reflectance.
        kd: Rgb,
        /// Glossy reflectance (at normal incidence).
        ks: Rgb,
        /// Phong exponent `n ≥ 0`.
        exponent: f32,
    },
    /// A perfect mirror.
    Mirror {
        /// Reflectance.
        r: Rgb,
    },
    /// A smooth dielectric boundary (glass): exact unpolarised Fresnel reflection and refraction.
    Dielectric {
        /// Index of refraction of the inside (the side opposite the geometric normal) over the outside.
        eta: f32,
        /// Multiplies both the reflected and the transmitted light.
        tint: Rgb,
    },
    /// A conductor (metal): a Trowbridge–Reitz microfacet lobe with conductor Fresnel (Walter et al. 2007), or
    /// for `alpha` below [`SMOOTH_ALPHA`] a perfect mirror with that Fresnel reflectance. Reflects on both sides.
    Conductor {
        /// The Fresnel reflectance: a complex index of refraction, or glTF's Schlick form with a base colour.
        fresnel: ConductorFresnel,
        /// The distribution's width `α = roughness²`.
        alpha: f32,
    },
    /// A rough dielectric boundary: Trowbridge–Reitz facets that reflect and refract (Walter et al. 2007).
    RoughDielectric {
        /// Index of refraction of the inside (the side opposite the geometric normal) over the outside.
        eta: f32,
        /// Multiplies both the reflected and the transmitted light.
        tint: Rgb,
        /// The distribution's width `α = roughness²`, at least [`SMOOTH_ALPHA`] (smooth glass is
        /// [`Bxdf::Dielectric`]).
        alpha: f32,
    },
    /// The glTF 2.0 metallic–roughness model (specification appendix B, [`super::metallic_roughness`]): a
    /// Trowbridge–Reitz lobe with Schlick's Fresnel of `F0 = mix(0.04, base, metallic)` over a diffuse base
    /// `(1 − metallic)·(1 − F_0.04(wo·h))·base/π`; for `alpha` below [`SMOOTH_ALPHA`] the lobe is a delta mirror.
    /// Reflects on both sides.
    MetallicRoughness {
        /// Base colour: the metal's `F0` and the diffuse base's reflectance.
        base: Rgb,
        /// Metalness in `[0, 1]`.
        metallic: f32,
        /// The distribution's width `α = roughness²`.
        alpha: f32,
    },
    /// The origin's mixture `diffuse·Lambert(color) + specular·mirror + transmission·glass(eta)`; the weights
    /// sum to at most 1, the rest is absorbed.
    Mix {
        /// Reflectance of the diffuse component (only the diffuse component is coloured).
        color: Rgb,
        /// Weight of the diffuse component.
        diffuse: f32,
        /// Weight of the perfect (white) mirror.
        specular: f32,
        /// Weight of the (untinted) smooth dielectric.
        transmission: f32,
        /// Relative index of refraction of the dielectric component.
        eta: f32,
    },
}

/// One direction drawn by [`Bsdf::sample`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// The sampled world-space direction (away from the surface).
    pub wi: Vec3A,
    /// BSDF value for `wi` (for a delta lobe, `reflectance / |cos θi|` times the lobe's weight).
    pub f: Rgb,
    /// Solid-angle density of `wi`, or for a delta lobe the discrete probability of having chosen it.
    pub pdf: f32,
    /// Whether `wi` came from a delta lobe (mirror or glass).
    pub delta: bool,
    /// For a refracted `wi`, the relative index η of the side `wi` points into over the side of `wo`; 1 for a
    /// reflection. Radiance crossing the surface is scaled by 1/η², which is not a loss of energy: Russian
    /// roulette undoes it (pbrt-v4's `etaScale`).
    pub eta: f32,
}

/// A [`Bxdf`] placed at a surface point: the shading frame (normal on local +z) and the geometric normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    /// The shading frame; `frame.n` is the shading normal, on the same side as `ng`.
    pub frame: Frame,
    /// The geometric unit normal, as the shape defines it (not flipped towards the viewer).
    pub ng: Vec3A,
    /// The lobes.
    pub bxdf: Bxdf,
    /// Whether the surface is black seen from behind (`wo·ng ≤ 0`): there `f`, `pdf` and `albedo` are 0 and
    /// `sample` returns nothing. See [`Bsdf::black_from`].
    pub one_sided: bool,
}

impl Bsdf {
    /// A BSDF with shading normal `ns` and geometric normal `ng` (both unit). A shading normal on the wrong
    /// side of `ng` is flipped.
    pub fn new(ns: Vec3A, ng: Vec3A, bxdf: Bxdf) -> Self {
        let ns = if ns.dot(ng) < 0.0 { -ns } else { ns };
        Self { frame: Frame::from_normal(ns), ng, bxdf, one_sided: false }
    }

    /// The same BSDF, one-sided when `one_sided` (black seen from behind) or two-sided.
    #[must_use]
    pub fn one_sided(mut self, one_sided: bool) -> Self {
        self.one_sided = one_sided;
        self
    }

    /// Whether the surface scatters nothing towards or from `wo`: a one-sided surface seen from behind, the side
    /// its geometric normal points away from. Integrators end a path there (the light is absorbed), and photons
    /// arriving there are absorbed without being stored, so a density estimate never counts them.
    #[inline]
    pub fn black_from(&self, wo: Vec3A) -> bool {
        self.one_sided && wo.dot(self.ng) <= 0.0
    }

    /// The BSDF of the non-delta lobes for the pair (`wo`, `wi`), without the cosine factor. Zero for mirrors
    /// and smooth glass, and, except for rough glass (which refracts), whenever `wo` and `wi` are not on the same
    /// side of the geometric normal; their sides of the shading normal do not matter (the black-fringe rule, see
    /// the module docs).
    pub fn f(&self, wo: Vec3A, wi: Vec3A, mode: TransportMode) -> Rgb {
        if self.black_from(wo) {
            return Rgb::ZERO;
        }
        if let Bxdf::RoughDielectric { eta, tint, alpha } = self.bxdf {
            let (wo_l, wi_l) = (self.frame.to_local(wo), self.frame.to_local(wi));
            if !self.crosses_consistently(wo, wi, wo_l, wi_l) {
                return Rgb::ZERO;
            }
            let dist = TrowbridgeReitz { alpha };
            return tint * microfacet::dielectric_f(&dist, eta, wo_l, wi_l, mode == TransportMode::Radiance);
        }
        // Every other non-delta lobe is reflective and reciprocal: the transport mode does not change it.
        if wo.dot(self.ng) * wi.dot(self.ng) <= 0.0 {
            return Rgb::ZERO;
        }
        self.f_local(self.frame.to_local(wo), self.frame.to_local(wi))
    }

    /// Whether a pair of a lobe that both reflects and transmits is on sides that agree: a reflection about the
    /// shading normal (`wo_l`, `wi_l` on one side of it) stays on one side of the geometric surface, and a
    /// refraction crosses both. A pair the shading and geometric normals disagree on carries no light (the
    /// light-leak rule; unlike the diffuse lobes, a rough dielectric has no symmetric way to reach it).
    #[inline]
    fn crosses_consistently(&self, wo: Vec3A, wi: Vec3A, wo_l: Vec3A, wi_l: Vec3A) -> bool {
        let geometric = wo.dot(self.ng) * wi.dot(self.ng);
        let shading = wo_l.z * wi_l.z;
        geometric != 0.0 && (geometric > 0.0) == (shading > 0.0)
    }

    /// The factor that turns the sample weight `f·|wi·ns|/pdf` of a camera path into that of a light path
    /// (a photon arriving from `wo` and leaving along `wi`): `|wo·ns|·|wi·ng| / (|wo·ng|·|wi·ns|)`.
    ///
    /// With shading normals the scattering kernel is `f(wo, wi)·|wi·ns|`, taken against the geometric
    /// projected solid angle `|wi·ng| dω`: the BSDF as the geometry sees it is `f·|wi·ns|/|wi·ng|`, which is not
    /// symmetric. Radiance (camera paths) uses it as it is; flux (photons) must use its adjoint, with the roles
    /// of `wo` and `wi` exchanged (Veach 1997, eq. 5.17; pbrt-v3's `CorrectShadingNormal`). Without it photon
    /// maps and the path tracer disagree on every smooth-shaded surface. 1 where the shading normal is the
    /// geometric one; 0 for a direction in the geometric tangent plane (no flux crosses it).
    #[inline]
    pub fn adjoint_correction(&self, wo: Vec3A, wi: Vec3A) -> f32 {
        if self.frame.n == self.ng {
            return 1.0;
        }
        let num = wo.dot(self.frame.n).abs() * wi.dot(self.ng).abs();
        let den = wo.dot(self.ng).abs() * wi.dot(self.frame.n).abs();
        if den > 0.0 { num / den } else { 0.0 }
    }

    /// The factor that turns the flux `Φ` of a photon arriving from `wo` into what a density estimate with this
    /// BSDF needs: `|wo·ns| / |wo·ng|`. A photon's flux crossed the geometric surface, `Φ = L·|wo·ng| dA dω`,
    /// while the reflected radiance weighs incident radiance with the shading cosine, `L·|wo·ns|`; so
    /// `Σ f·Φ·|wo·ns|/|wo·ng| / A` estimates it (the last vertex of a light path in Veach 1997, §5.3). 1 where
    /// the normals agree, 0 for a photon grazing the geometric surface.
    #[inline]
    pub fn arrival_correction(&self, wo: Vec3A) -> f32 {
        if self.frame.n == self.ng {
            return 1.0;
        }
        let den = wo.dot(self.ng).abs();
        if den > 0.0 { wo.dot(self.frame.n).abs() / den } else { 0.0 }
    }

    /// The factor by which a path that sampled `bs` from `wo` multiplies its throughput: `f·|wi·ns| / pdf`,
    /// with the shading normal's cosine (the estimator of pbrt-v4 §13.1, written with shading normals), and for
    /// a path that carries importance (photons, light subpaths) times [`Bsdf::adjoint_correction`] (Veach 1997,
    /// eq. 5.17). `pdf` is the density the direction was drawn with: `bs.pdf`, or `bs.pdf` times a Russian
    /// roulette probability that the caller folds into the sample (vcm's subpaths). Unitless, per channel.
    #[inline]
    pub fn sample_weight(&self, wo: Vec3A, bs: &BsdfSample, pdf: f32, mode: TransportMode) -> Rgb {
        let w = bs.wi.dot(self.frame.n).abs() / pdf;
        match mode {
            TransportMode::Radiance => bs.f * w,
            TransportMode::Importance => bs.f * (w * self.adjoint_correction(wo, bs.wi)),
        }
    }

    /// The solid-angle density with which [`Bsdf::sample`] draws `wi` from its non-delta lobes, lobe selection
    /// probabilities included. Zero when the BSDF has no non-delta lobe.
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A) -> f32 {
        if self.black_from(wo) {
            return 0.0;
        }
        if let Bxdf::RoughDielectric { eta, alpha, .. } = self.bxdf {
            let (wo_l, wi_l) = (self.frame.to_local(wo), self.frame.to_local(wi));
            if !self.crosses_consistently(wo, wi, wo_l, wi_l) {
                return 0.0;
            }
            return microfacet::dielectric_pdf(&TrowbridgeReitz { alpha }, eta, wo_l, wi_l);
        }
        let side = wo.dot(self.ng);
        if side * wi.dot(self.ng) <= 0.0 {
            return 0.0;
        }
        let (wo, wi) = (self.frame.to_local(wo), self.frame.to_local(wi));
        // `|wi·ns|/π` over wo's geometric hemisphere, which integrates to 1 for any shading normal (see
        // `sample_shading_cosine`).
        let cosine = wi.z.abs() * FRAC_1_PI;
        match self.bxdf {
            Bxdf::Lambert { .. } => cosine,
            Bxdf::Phong { kd, ks, exponent } => {
                let p_glossy = phong_glossy_probability(kd, ks);
                (1.0 - p_glossy) * cosine + p_glossy * phong_lobe_pdf(wo, wi, exponent)
            }
            Bxdf::Mirror { .. } | Bxdf::Dielectric { .. } => 0.0,
            Bxdf::Conductor { alpha, .. } if alpha < SMOOTH_ALPHA => 0.0,
            Bxdf::Conductor { alpha, .. } => microfacet::conductor_pdf(&TrowbridgeReitz { alpha }, wo, wi),
            Bxdf::MetallicRoughness { base, metallic, alpha } => mr::pdf(base, metallic, alpha, wo, wi),
            // Handled above.
            Bxdf::RoughDielectric { .. } => 0.0,
            Bxdf::Mix { diffuse, specular, transmission, .. } => {
                let sum = diffuse + specular + transmission;
                if sum > 0.0 { diffuse / sum * cosine } else { 0.0 }
            }
        }
    }

    /// Draws `wi` for a given `wo`: `u` chooses the lobe (and between reflection and refraction for glass), `u2`
    /// the direction in a non-delta lobe. `None` when the sampled direction carries no light (absorbed, or it
    /// would cross the surface the wrong way, see the module docs).
    ///
    /// For a non-delta sample, `f` and `pdf` equal [`Bsdf::f`] and [`Bsdf::pdf`] at (`wo`, `wi`). The Mix
    /// material chooses its component with probability `weight / (sum of weights)`, so it never absorbs here:
    /// its absorption shows in the sample weight `f·|cos|/pdf` (and in [`Bsdf::albedo`], for Russian roulette).
    pub fn sample(&self, wo: Vec3A, u: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if self.black_from(wo) {
            return None;
        }
        let wo_l = self.frame.to_local(wo);
        // The hemisphere of the shading normal on wo's geometric side (see the module docs).
        let up = wo.dot(self.ng);
        match self.bxdf {
            Bxdf::Lambert { .. } => self.sample_non_delta(wo, self.sample_shading_cosine(u2, up)),
            Bxdf::Phong { kd, ks, exponent } => {
                // The lobe around the mirror direction may dip below the horizon: `sample_non_delta` returns
                // nothing there.
                let wi_l = if u < phong_glossy_probability(kd, ks) {
                    sample_phong_lobe(wo_l, exponent, u2)
                } else {
                    self.sample_shading_cosine(u2, up)
                };
                self.sample_non_delta(wo, wi_l)
            }
            Bxdf::Mirror { r } => self.sample_mirror(wo, wo_l, r, 1.0),
            Bxdf::Dielectric { eta, tint } => self.sample_dielectric(wo, wo_l, eta, tint, u, mode),
            Bxdf::Conductor { fresnel, alpha } if alpha < SMOOTH_ALPHA => {
                self.sample_mirror(wo, wo_l, fresnel.eval(wo_l.z), 1.0)
            }
            Bxdf::Conductor { fresnel, alpha } => {
                let s = microfacet::conductor_sample(&TrowbridgeReitz { alpha }, &fresnel, wo_l, u2)?;
                let wi = self.frame.to_world(s.wi);
                // A reflection about the shading frame that crosses the geometric surface would leak light.
                (wo.dot(self.ng) * wi.dot(self.ng) > 0.0).then_some(BsdfSample {
                    wi,
                    f: s.f,
                    pdf: s.pdf,
                    delta: false,
                    eta: 1.0,
                })
            }
            Bxdf::MetallicRoughness { base, metallic, alpha } => {
                let p_spec = mr::specular_probability(base, metallic, wo_l);
                if u >= p_spec {
                    return self.sample_non_delta(wo, self.sample_shading_cosine(u2, up));
                }
                let fresnel = mr::fresnel(base, metallic);
                if alpha < SMOOTH_ALPHA {
                    return self.sample_mirror(wo, wo_l, fresnel.eval(wo_l.z), p_spec);
                }
                // The lobe's direction; its value and density are the whole mixture's.
                let s = microfacet::conductor_sample(&TrowbridgeReitz { alpha }, &fresnel, wo_l, u2)?;
                self.sample_non_delta(wo, s.wi)
            }
            Bxdf::RoughDielectric { eta, tint, alpha } => {
                let radiance = mode == TransportMode::Radiance;
                let s = microfacet::dielectric_sample(&TrowbridgeReitz { alpha }, eta, wo_l, u, u2, radiance)?;
                let wi = self.frame.to_world(s.wi);
                self.crosses_consistently(wo, wi, wo_l, s.wi).then_some(BsdfSample {
                    wi,
                    f: tint * s.f.x,
                    pdf: s.pdf,
                    delta: false,
                    eta: s.eta,
                })
            }
            Bxdf::Mix { diffuse, specular, transmission, eta, .. } => {
                let sum = diffuse + specular + transmission;
                if sum <= 0.0 {
                    return None;
                }
                let x = u * sum;
                if x < diffuse || (specular <= 0.0 && transmission <= 0.0) {
                    self.sample_non_delta(wo, self.sample_shading_cosine(u2, up))
                } else if x < diffuse + specular || transmission <= 0.0 {
                    self.sample_mirror(wo, wo_l, Rgb::splat(specular), specular / sum)
                } else {
                    let u = ((x - diffuse - specular) / transmission).clamp(0.0, ONE_MINUS_EPSILON);
                    let mut s = self.sample_dielectric(wo, wo_l, eta, Rgb::ONE, u, mode)?;
                    s.f *= transmission;
                    s.pdf *= transmission / sum;
                    Some(s)
                }
            }
        }
    }

    /// The fraction of the flux arriving from `wo` that the surface scatters (reflected plus transmitted;
    /// directional-hemispherical reflectance), per channel and at most 1. It is what Russian roulette keeps.
    ///
    /// Exact for Lambert (`r`), mirror (`r`), glass (`tint`: Fresnel splits the flux, it does not absorb any)
    /// and Mix (`diffuse·color + specular + transmission`), up to light lost to shading-normal clipping. For
    /// Phong it is the upper bound `kd + ks` (the glossy lobe reflects exactly `ks` only at normal incidence and
    /// loses what its lobe puts below the horizon elsewhere). This is the flux (importance-mode) value: the
    /// `1/η'²` of radiance transport moves no energy.
    pub fn albedo(&self, wo: Vec3A) -> Rgb {
        if self.black_from(wo) {
            return Rgb::ZERO;
        }
        match self.bxdf {
            Bxdf::Lambert { r } | Bxdf::Mirror { r } => r,
            Bxdf::Phong { kd, ks, .. } => (kd + ks).min(Rgb::ONE),
            Bxdf::Dielectric { tint, .. } | Bxdf::RoughDielectric { tint, .. } => tint,
            // The Fresnel reflectance at the view angle: exact for the mirror, an upper bound for a rough
            // lobe, which loses what its facets shadow and what falls below the horizon.
            Bxdf::Conductor { fresnel, .. } => fresnel.eval(self.frame.to_local(wo).z),
            Bxdf::MetallicRoughness { base, metallic, .. } => mr::albedo(base, metallic, self.frame.to_local(wo)),
            Bxdf::Mix { color, diffuse, specular, transmission, .. } => {
                (diffuse * color + Rgb::splat(specular + transmission)).min(Rgb::ONE)
            }
        }
    }

    /// Whether every lobe is a delta lobe (mirror, glass, or a Mix without diffuse weight).
    pub fn is_delta(&self) -> bool {
        !self.has_non_delta()
    }

    /// Whether some lobe is not a delta lobe (Lambert, Phong, rough conductors and glass, the diffuse part of
    /// Mix): direct light is worth sampling here.
    pub fn has_non_delta(&self) -> bool {
        self.bxdf.has_non_delta()
    }

    /// Whether the photon methods store photons and estimate density here: a non-delta lobe at least
    /// `min_roughness` rough (perceptual roughness, `α = r²`; see [`Bxdf::photon_alpha`]). Elsewhere their
    /// paths walk on through the surface as through a mirror.
    #[inline]
    pub fn stores_photons(&self, min_roughness: f32) -> bool {
        // `photon_alpha` is 0 without a non-delta lobe and for a transmitting one, which never stores photons,
        // even at `min_roughness` 0.
        let alpha = self.bxdf.photon_alpha();
        alpha > 0.0 && alpha >= min_roughness * min_roughness
    }

    /// The non-delta part in the local frame, for directions on the same geometric side (checked by the
    /// caller): no test of the shading hemisphere here, which is the black-fringe rule.
    fn f_local(&self, wo: Vec3A, wi: Vec3A) -> Rgb {
        match self.bxdf {
            Bxdf::Lambert { r } => r * FRAC_1_PI,
            Bxdf::Phong { kd, ks, exponent } => {
                kd * FRAC_1_PI + ks * ((exponent + 2.0) * (0.5 * FRAC_1_PI) * phong_cos_pow(wo, wi, exponent))
            }
            Bxdf::Mirror { .. } | Bxdf::Dielectric { .. } => Rgb::ZERO,
            Bxdf::Conductor { alpha, .. } if alpha < SMOOTH_ALPHA => Rgb::ZERO,
            Bxdf::Conductor { fresnel, alpha } => microfacet::conductor_f(&TrowbridgeReitz { alpha }, &fresnel, wo, wi),
            Bxdf::MetallicRoughness { base, metallic, alpha } => mr::f(base, metallic, alpha, wo, wi),
            // Evaluated by `f` itself: it both reflects and transmits.
            Bxdf::RoughDielectric { .. } => Rgb::ZERO,
            Bxdf::Mix { color, diffuse, .. } => color * (diffuse * FRAC_1_PI),
        }
    }

    /// A local direction with density `|wi·ns|/π` over the geometric hemisphere on the side of `side` (`wo·ng`).
    ///
    /// The cosine-weighted hemisphere of the shading normal on that side sticks out beyond the geometric horizon
    /// where the normals differ; the part that does, reflected through the origin (`wi → −wi`), is exactly the
    /// part of the geometric hemisphere below the shading horizon, with the same `|wi·ns|`. So every direction
    /// on the geometric side is reachable (the BSDF is not zero there: the black-fringe rule), the density is
    /// `|wi·ns|/π` everywhere on it, and it integrates to 1: `∫ |wi·ns| dωi = π` over any hemisphere, whatever
    /// its tilt against `ns`. A Lambert sample then carries exactly its albedo.
    fn sample_shading_cosine(&self, u2: Vec2, side: f32) -> Vec3A {
        let w = flip_to(cosine_hemisphere(u2), side);
        if self.frame.to_world(w).dot(self.ng) * side < 0.0 { -w } else { w }
    }

    /// A sample of the non-delta lobes at the local direction `wi_l`: `f` and `pdf` from `f` and `pdf`, so that
    /// a lobe mixture gets the density of the mixture.
    fn sample_non_delta(&self, wo: Vec3A, wi_l: Vec3A) -> Option<BsdfSample> {
        let wi = self.frame.to_world(wi_l);
        if wo.dot(self.ng) * wi.dot(self.ng) <= 0.0 {
            return None;
        }
        let wo_l = self.frame.to_local(wo);
        let pdf = self.pdf(wo, wi);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample { wi, f: self.f_local(wo_l, wi_l), pdf, delta: false, eta: 1.0 })
    }

    /// Mirror reflection about the shading normal with reflectance `r`, chosen with probability `prob`.
    fn sample_mirror(&self, wo: Vec3A, wo_l: Vec3A, r: Rgb, prob: f32) -> Option<BsdfSample> {
        let wi = self.frame.to_world(Vec3A::new(-wo_l.x, -wo_l.y, wo_l.z));
        let wi = self.onto_side(wi, wo.dot(self.ng))?;
        let cos_i = wi.dot(self.frame.n).abs();
        (cos_i > 0.0).then(|| BsdfSample { wi, f: r / cos_i, pdf: prob, delta: true, eta: 1.0 })
    }

    /// Fresnel reflection (probability F) or refraction (1 − F) with index `eta` (inside over outside).
    fn sample_dielectric(
        &self,
        wo: Vec3A,
        wo_l: Vec3A,
        eta: f32,
        tint: Rgb,
        u: f32,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let side = wo.dot(self.ng);
        if side == 0.0 {
            return None;
        }
        let entering = side > 0.0;
        // Relative index as seen from wo, and the shading normal turned to wo's side.
        let (etap, n_l) = if entering { (eta, Vec3A::Z) } else { (1.0 / eta, -Vec3A::Z) };
        let cos_o = wo_l.dot(n_l);
        if cos_o <= 0.0 {
            // `wo` lies below the shading normal's horizon on its own geometric side: the shading frame has no
            // answer, so this sample uses the geometric normal instead of dropping the path.
            if self.frame.n == self.ng {
                return None;
            }
            // Its `f` is rescaled so that the weight `f·|wi·ns|/pdf`, taken by callers with this shading normal,
            // is the one the geometric frame gives.
            let geometric = Bsdf::new(self.ng, self.ng, self.bxdf);
            let mut bs = geometric.sample_dielectric(wo, geometric.frame.to_local(wo), eta, tint, u, mode)?;
            let cos_s = bs.wi.dot(self.frame.n).abs();
            if cos_s <= 0.0 {
                return None;
            }
            bs.f *= bs.wi.dot(self.ng).abs() / cos_s;
            return Some(bs);
        }
        let fr = fresnel_dielectric(cos_o, etap);
        if u < fr {
            let wi = self.frame.to_world(Vec3A::new(-wo_l.x, -wo_l.y, wo_l.z));
            let wi = self.onto_side(wi, side)?;
            let cos_i = wi.dot(self.frame.n).abs();
            return (cos_i > 0.0).then(|| BsdfSample { wi, f: tint * (fr / cos_i), pdf: fr, delta: true, eta: 1.0 });
        }
        let wi = self.frame.to_world(refract(wo_l, n_l, etap)?);
        let wi = self.onto_side(wi, -side)?;
        let cos_i = wi.dot(self.frame.n).abs();
        let tr = 1.0 - fr;
        let scale = match mode {
            TransportMode::Radiance => 1.0 / (etap * etap),
            TransportMode::Importance => 1.0,
        };
        (cos_i > 0.0).then(|| BsdfSample { wi, f: tint * (tr * scale / cos_i), pdf: tr, delta: true, eta: etap })
    }

    /// `wi`, mirrored across the geometric tangent plane if it lies on the wrong side of it (the side of
    /// `side`'s sign is wanted). Refraction or reflection about a shading normal can point a delta sample to the
    /// wrong side of the true surface; returning no sample there (pbrt's choice) drops its energy, and a closed
    /// glass mesh with smooth normals then darkens in a white furnace. Mirroring keeps the sample's weight
    /// `f·|cos θi|/pdf` (the caller's cosine is taken with the mirrored direction) and sends it where the event
    /// it stands for goes. `None` only for a direction in the tangent plane.
    fn onto_side(&self, wi: Vec3A, side: f32) -> Option<Vec3A> {
        let c = wi.dot(self.ng);
        if c == 0.0 {
            None
        } else if c * side > 0.0 {
            Some(wi)
        } else {
            Some(wi - (2.0 * c) * self.ng)
        }
    }
}

impl Bxdf {
    /// Whether some lobe is not a delta lobe.
    pub fn has_non_delta(&self) -> bool {
        match *self {
            Bxdf::Lambert { .. } | Bxdf::Phong { .. } | Bxdf::RoughDielectric { .. } => true,
            Bxdf::Mirror { .. } | Bxdf::Dielectric { .. } => false,
            Bxdf::Conductor { alpha, .. } => alpha >= SMOOTH_ALPHA,
            Bxdf::MetallicRoughness { metallic, alpha, .. } => metallic < 1.0 || alpha >= SMOOTH_ALPHA,
            Bxdf::Mix { diffuse, .. } => diffuse > 0.0,
        }
    }

    /// The width of the narrowest non-delta lobe as a Trowbridge–Reitz `α`: the photon methods store photons
    /// and estimate density only where it is at least their threshold (see [`crate::scene`]'s
    /// `photons.min_roughness`), and walk on through narrower lobes. Infinite for diffuse lobes (Lambert, the
    /// mixture); for a Phong lobe of exponent n the `α` of equal width, `√(2/(n+2))` (Walter et al. 2007, eq. 33,
    /// which gives the Beckmann width; GGX's is close enough for a threshold); 0 for a lobe that transmits,
    /// whose density estimate would mix the light of its two sides. 0 when there is no non-delta lobe.
    pub fn photon_alpha(&self) -> f32 {
        match *self {
            Bxdf::Lambert { .. } => f32::INFINITY,
            Bxdf::Mix { diffuse, .. } if diffuse > 0.0 => f32::INFINITY,
            Bxdf::Phong { kd, exponent, .. } if luminance(kd) > 0.0 || exponent <= 0.0 => f32::INFINITY,
            Bxdf::Phong { exponent, .. } => (2.0 / (exponent + 2.0)).sqrt(),
            Bxdf::Conductor { alpha, .. } if alpha >= SMOOTH_ALPHA => alpha,
            // The diffuse base is there unless the surface is all metal.
            Bxdf::MetallicRoughness { metallic, .. } if metallic < 1.0 => f32::INFINITY,
            Bxdf::MetallicRoughness { alpha, .. } if alpha >= SMOOTH_ALPHA => alpha,
            _ => 0.0,
        }
    }

    /// Whether some lobe is a delta lobe (mirror or glass).
    pub fn has_delta(&self) -> bool {
        match *self {
            Bxdf::Lambert { .. } | Bxdf::Phong { .. } | Bxdf::RoughDielectric { .. } => false,
            Bxdf::Mirror { .. } | Bxdf::Dielectric { .. } => true,
            Bxdf::Conductor { alpha, .. } | Bxdf::MetallicRoughness { alpha, .. } => alpha < SMOOTH_ALPHA,
            Bxdf::Mix { specular, transmission, .. } => specular > 0.0 || transmission > 0.0,
        }
    }
}

/// `w` (on local +z) moved to local −z when `side` is negative: the shading hemisphere on the geometric side
/// of `wo` when `side = wo·ng` (the shading normal lies on `ng`'s side).
#[inline]
fn flip_to(w: Vec3A, side: f32) -> Vec3A {
    if side < 0.0 { Vec3A::new(w.x, w.y, -w.z) } else { w }
}

/// `cos^n α` for the angle α between `wi` and the mirror direction of `wo` (local frame), and 0 where cos α ≤ 0
/// (also for n = 0).
///
/// With d = wi − reflect(wo), cos α = 1 − |d|²/2 for unit vectors, so cos^n α = exp(n·ln(1 − |d|²/2)). Unlike
/// `powf` of a dot product this keeps its precision at the peak for large n, and it is insensitive to first
/// order to the f32 rounding of |wo| and |wi| (a dot product scales cos α by |wo||wi|, which would bias the
/// lobe's integral by n·(|wo||wi| − 1)). It is exactly symmetric in `wo` and `wi`.
#[inline]
fn phong_cos_pow(wo: Vec3A, wi: Vec3A, n: f32) -> f32 {
    let d2 = Vec3A::new(wi.x + wo.x, wi.y + wo.y, wi.z - wo.z).length_squared();
    if d2 >= 2.0 { 0.0 } else { fmath::exp(n * fmath::ln_1p(-0.5 * d2)) }
}

/// Probability of sampling the glossy Phong lobe: its share of the luminance of `kd + ks`.
#[inline]
fn phong_glossy_probability(kd: Rgb, ks: Rgb) -> f32 {
    let (d, s) = (luminance(kd), luminance(ks));
    if s <= 0.0 { 0.0 } else { s / (d + s) }
}

/// Density of the glossy lobe sampling: `(n+1)/(2π)·cos^n α` over the sphere of directions.
#[inline]
fn phong_lobe_pdf(wo: Vec3A, wi: Vec3A, n: f32) -> f32 {
    (n + 1.0) * (0.5 * FRAC_1_PI) * phong_cos_pow(wo, wi, n)
}

/// A direction around the mirror direction of `wo` with density `(n+1)/(2π)·cos^n α` (cos α = u^(1/(n+1))).
#[inline]
fn sample_phong_lobe(wo: Vec3A, n: f32, u2: Vec2) -> Vec3A {
    let r = Vec3A::new(-wo.x, -wo.y, wo.z);
    let cos_a = fmath::powf(u2.x, 1.0 / (n + 1.0));
    let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
    let phi = 2.0 * PI * u2.y;
    Frame::from_normal(r).to_world(Vec3A::new(sin_a * fmath::cos(phi), sin_a * fmath::sin(phi), cos_a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(theta: f32, phi: f32) -> Vec3A {
        Vec3A::new(fmath::sin(theta) * fmath::cos(phi), fmath::sin(theta) * fmath::sin(phi), fmath::cos(theta))
    }

    #[test]
    fn lambert_sample_matches_f_and_pdf() {
        let b = Bsdf::new(Vec3A::Z, Vec3A::Z, Bxdf::Lambert { r: Rgb::splat(0.5) });
        let wo = dir(0.4, 1.0);
        let s = b.sample(wo, 0.3, Vec2::new(0.2, 0.7), TransportMode::Radiance).unwrap();
        assert!(!s.delta);
        assert!((s.pdf - s.wi.z / PI).abs() < 1e-6);
        assert_eq!(s.f, b.f(wo, s.wi, TransportMode::Radiance));
        assert!((b.albedo(wo) - Rgb::splat(0.5)).length() < 1e-6);
    }

    #[test]
    fn two_sided_lambert_reflects_on_the_back() {
        let b = Bsdf::new(Vec3A::Z, Vec3A::Z, Bxdf::Lambert { r: Rgb::ONE });
        let wo = -dir(0.3, 0.0);
        let s = b.sample(wo, 0.5, Vec2::new(0.5, 0.5), TransportMode::Radiance).unwrap();
        assert!(s.wi.z < 0.0);
        assert_eq!(b.f(wo, dir(0.5, 1.0), TransportMode::Radiance), Rgb::ZERO);
    }

    #[test]
    fn mirror_reflects_about_the_shading_normal() {
        let b = Bsdf::new(Vec3A::Z, Vec3A::Z, Bxdf::Mirror { r: Rgb::splat(0.9) });
        let wo = dir(0.6, 0.3);
        let s = b.sample(wo, 0.5, Vec2::ZERO, TransportMode::Radiance).unwrap();
        assert!(s.delta && s.pdf == 1.0);
        assert!((s.wi - Vec3A::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
        assert!((s.f * s.wi.z / s.pdf - Rgb::splat(0.9)).length() < 1e-5);
        assert_eq!(b.pdf(wo, s.wi), 0.0);
        assert!(b.is_delta());
    }
}
