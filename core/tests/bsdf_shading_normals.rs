//! Claim: with a shading normal tilted away from the geometric normal, no light leaks: a reflective BSDF never
//! sends light to the other side of the geometric surface, a transmitted direction always crosses it, and no
//! sample carries more than the flux that arrived (the sample weights stay within `albedo()`).
//!
//! Shading normals tilted by 25° to 51° from the geometric normal, `wo` uniform over the sphere, 20 000
//! samples per case. The weight `f·|cos θi|/pdf` of a sample is at most `albedo()` for Lambert, mirror and glass
//! and at most 1 for Mix (it picks a component by its share of the weights, so a sample carries their sum);
//! Phong's mixture weight is bounded by its albedo only on average (`bsdf_albedo.rs`). These bounds hold per
//! sample, up to f32 rounding: no statistics are involved.

mod common;

use common::{every_kind, sampler, transmits};
use glam::Vec3A;
use photon_core::material::bsdf::{Bsdf, Bxdf, TransportMode};
use photon_core::math::fmath;
use photon_core::math::uniform_sphere;

#[test]
fn tilted_shading_normals_leak_no_light() {
    let ng = fmath::normalize(Vec3A::new(0.2, 0.3, -0.93));
    let tilts = [Vec3A::new(0.5, 0.0, -0.87), Vec3A::new(-0.86, 0.1, -0.5), Vec3A::new(0.0, 0.7, -0.7)];
    for (k, (name, bxdf)) in every_kind().into_iter().enumerate() {
        for (j, ns) in tilts.into_iter().enumerate() {
            let b = Bsdf::new(fmath::normalize(ns), ng, bxdf);
            let mut rng = sampler(7, (k * 10 + j) as u64);
            let (mut some, mut crossed) = (0usize, 0usize);
            for _ in 0..20_000 {
                let wo = uniform_sphere(rng.next_2d());
                let albedo = b.albedo(wo);
                let Some(s) = b.sample(wo, rng.next_f32(), rng.next_2d(), TransportMode::Importance) else {
                    continue;
                };
                some += 1;
                let at = format!("{name}, ns = {ns}, wo = {wo}: {s:?}");
                let same_side = wo.dot(ng) * s.wi.dot(ng) > 0.0;
                if !same_side {
                    crossed += 1;
                    assert!(s.delta && transmits(&bxdf), "{at}: light through an opaque surface");
                }
                let weight = s.f * s.wi.dot(b.frame.n).abs() / s.pdf;
                let bound = match bxdf {
                    Bxdf::Phong { .. } => Vec3A::INFINITY,
                    // Mix picks a component by its share of the weights: a sample carries their sum (≤ 1).
                    Bxdf::Mix { .. } => Vec3A::splat(1.0 + 1e-5),
                    Bxdf::Lambert { .. } | Bxdf::Mirror { .. } | Bxdf::Dielectric { .. } => albedo * (1.0 + 1e-5),
                };
                assert!(
                    weight.cmple(bound).all() && weight.min_element() >= 0.0 && weight.is_finite(),
                    "{at}: {weight}"
                );
            }
            assert!(some > 2_000, "{name}: only {some} samples");
            assert_eq!(crossed > 0, transmits(&bxdf), "{name}: {crossed} samples crossed the surface");
        }
    }
}
