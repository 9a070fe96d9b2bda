//! Claim: the non-delta lobes are reciprocal, f(wo, wi) = f(wi, wo) (Helmholtz), for every kind and with a
//! shading normal that differs from the geometric one; and the transport mode does not change them (only
//! refraction, a delta lobe, depends on it).
//!
//! 20 000 random direction pairs per BSDF, uniform over the sphere so that both sides and grazing angles occur;
//! pairs on opposite sides must give 0 both ways. Tolerance: 1e-6 relative (the formulas are symmetric in
//! exact arithmetic; f32 rounding is the only difference).

mod common;

use common::{every_kind, sampler};
use glam::Vec3A;
use photon_core::material::bsdf::{Bsdf, TransportMode};
use photon_core::math::fmath;
use photon_core::math::uniform_sphere;

#[test]
fn non_delta_lobes_are_reciprocal() {
    let normals = [
        (Vec3A::Z, Vec3A::Z),
        (fmath::normalize(Vec3A::new(0.3, -0.2, 0.9)), Vec3A::Z),
        (fmath::normalize(Vec3A::new(-0.1, 0.8, 0.2)), Vec3A::new(0.0, 0.6, 0.8)),
    ];
    for (k, (name, bxdf)) in every_kind().into_iter().enumerate() {
        for (j, (ns, ng)) in normals.into_iter().enumerate() {
            let b = Bsdf::new(ns, ng, bxdf);
            let mut rng = sampler(6, (k * 10 + j) as u64);
            let mut nonzero = 0;
            for _ in 0..20_000 {
                let (wo, wi) = (uniform_sphere(rng.next_2d()), uniform_sphere(rng.next_2d()));
                let forward = b.f(wo, wi, TransportMode::Radiance);
                let backward = b.f(wi, wo, TransportMode::Radiance);
                let tol = 1e-6 * forward.max_element().max(backward.max_element());
                let at = format!("{name}, ns = {ns}, ng = {ng}, wo = {wo}, wi = {wi}");
                assert!((forward - backward).abs().max_element() <= tol, "{at}: {forward} vs {backward}");
                assert_eq!(forward, b.f(wo, wi, TransportMode::Importance), "{at}: depends on the mode");
                assert!(forward.min_element() >= 0.0 && forward.is_finite(), "{at}: {forward}");
                if wo.dot(ng) * wi.dot(ng) <= 0.0 {
                    assert_eq!(forward, glam::Vec3A::ZERO, "{at}: light through an opaque surface");
                }
                nonzero += usize::from(forward.max_element() > 0.0);
            }
            // Not vacuous: a BSDF with a non-delta lobe is non-zero for a good share of the pairs.
            assert_eq!(nonzero > 4_000, b.has_non_delta(), "{name}: {nonzero} non-zero pairs");
        }
    }
}
