//! Claim: the non-delta lobes are reciprocal, for every kind and with a shading normal that differs from the
//! geometric one. A reflecting lobe is symmetric, f(wo, wi) = f(wi, wo) (Helmholtz), and the transport mode does
//! not change it. Rough glass refracts, and radiance crossing it scales by 1/η² (Veach 1997, §5.2): there the
//! claim is the adjoint one, f_radiance(wo, wi) = f_importance(wi, wo), with which the photon methods and the
//! camera paths agree.
//!
//! 20 000 random direction pairs per BSDF, uniform over the sphere so that both sides and grazing angles occur;
//! pairs on opposite sides must give 0 both ways for a BSDF that does not transmit. Tolerance: 1e-6 relative
//! (the formulas are symmetric in exact arithmetic; f32 rounding is the only difference). The microfacet lobes
//! compute their half vector, masking and Fresnel terms in an order that does not depend on which direction is
//! `wo`: near total internal reflection, Fresnel's unbounded slope would turn the rounding of `wo·h` against
//! `wi·h` into errors of 1e-3.

mod common;

use common::{every_kind, sampler, transmits};
use glam::Vec3A;
use photon_core::material::bsdf::{Bsdf, Bxdf, TransportMode};
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
            let (mut nonzero, mut crossed) = (0, 0);
            for _ in 0..20_000 {
                let (wo, wi) = (uniform_sphere(rng.next_2d()), uniform_sphere(rng.next_2d()));
                let forward = b.f(wo, wi, TransportMode::Radiance);
                let backward = b.f(wi, wo, TransportMode::Importance);
                let tol = 1e-6 * forward.max_element().max(backward.max_element());
                let at = format!("{name}, ns = {ns}, ng = {ng}, wo = {wo}, wi = {wi}");
                assert!((forward - backward).abs().max_element() <= tol, "{at}: {forward} vs {backward}");
                assert!(forward.min_element() >= 0.0 && forward.is_finite(), "{at}: {forward}");
                if wo.dot(ng) * wi.dot(ng) > 0.0 {
                    // A reflection: symmetric in either mode.
                    assert_eq!(forward, b.f(wo, wi, TransportMode::Importance), "{at}: depends on the mode");
                    let swapped = b.f(wi, wo, TransportMode::Radiance);
                    assert!((forward - swapped).abs().max_element() <= tol, "{at}: {forward} vs {swapped}");
                } else if !transmits(&bxdf) {
                    assert_eq!(forward, glam::Vec3A::ZERO, "{at}: light through an opaque surface");
                } else {
                    crossed += usize::from(forward.max_element() > 0.0);
                }
                nonzero += usize::from(forward.max_element() > 0.0);
            }
            // Rough glass is checked on refracted pairs too, not only on reflected ones.
            assert_eq!(crossed > 1_000, matches!(bxdf, Bxdf::RoughDielectric { .. }), "{name}: {crossed} refracted");
            // Not vacuous: a BSDF with a non-delta lobe is non-zero for a good share of the pairs.
            assert_eq!(nonzero > 4_000, b.has_non_delta(), "{name}: {nonzero} non-zero pairs");
        }
    }
}
