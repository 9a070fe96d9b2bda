//! Claim: with a shading normal tilted away from the geometric normal, no light leaks: a reflective BSDF never
//! sends light to the other side of the geometric surface, a transmitted direction always crosses it, and no
//! sample carries more than the flux that arrived (the sample weights stay within `albedo()`).
//!
//! Shading normals tilted by 25° to 51° from the geometric normal, `wo` uniform over the sphere, 20 000
//! samples per case. The weight `f·|cos θi|/pdf` of a sample is at most `albedo()` for Lambert, mirror and glass
//! (rough glass too: `(1 − F)·G2/G1` or `F·G2/G1` times its tint), at most 1 for a metal (its facet's Fresnel
//! factor times G2/G1) and at most 1 for Mix (it picks a component by its share of the weights, so a sample carries their sum);
//! Phong's and glTF's metallic–roughness mixture weights are bounded by their albedo only on average
//! (`bsdf_albedo.rs`). These bounds hold per
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
                    assert!(transmits(&bxdf), "{at}: light through an opaque surface");
                }
                let weight = s.f * s.wi.dot(b.frame.n).abs() / s.pdf;
                let bound = match bxdf {
                    // Mixtures sampled by a luminance share: bounded on average only (`bsdf_albedo.rs`).
                    Bxdf::Phong { .. } | Bxdf::MetallicRoughness { .. } => Vec3A::INFINITY,
                    // Mix picks a component by its share of the weights: a sample carries their sum (≤ 1).
                    Bxdf::Mix { .. } => Vec3A::splat(1.0 + 1e-5),
                    // A facet's Fresnel factor at `wo·h`, not at `wo·n` as albedo() takes it, times G2/G1 ≤ 1.
                    Bxdf::Conductor { .. } => Vec3A::splat(1.0 + 1e-5),
                    Bxdf::Lambert { .. }
                    | Bxdf::Mirror { .. }
                    | Bxdf::Dielectric { .. }
                    | Bxdf::RoughDielectric { .. } => albedo * (1.0 + 1e-5),
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

/// Claim: a tilted shading normal draws no black fringe: for Lambert, `f = r/π` for every pair on the same side
/// of the geometric normal, also where the shading normal puts `wo` and `wi` on opposite sides of its horizon;
/// and a sample's weight `f·|wi·ns|/pdf` is exactly the albedo there too (no energy lost to the shading frame).
/// For a photon the adjoint weight averages `r·|wo·ns|/|wo·ng|` (Veach 1997, eq. 5.17: the flux the shading
/// cosine lets in), and its outgoing flux is cosine-distributed about the geometric normal, so the mean of
/// `weight·|wi·ng|` is 2/3 of that: 5 standard errors over 100 000 samples.
#[test]
fn lambert_with_a_tilted_shading_normal_has_no_black_fringe() {
    let ng = Vec3A::Z;
    let ns = fmath::normalize(Vec3A::new(0.8, 0.0, 0.6));
    let r = photon_core::Rgb::splat(0.7);
    let b = Bsdf::new(ns, ng, Bxdf::Lambert { r });
    // Above the geometric horizon on both sides, on opposite sides of the shading one.
    let (wo, wi) = (fmath::normalize(Vec3A::new(-0.9, 0.0, 0.2)), fmath::normalize(Vec3A::new(0.3, 0.4, 0.8)));
    assert!(wo.dot(ns) < 0.0 && wi.dot(ns) > 0.0);
    assert_eq!(b.f(wo, wi, TransportMode::Radiance), r * std::f32::consts::FRAC_1_PI);
    assert_eq!(b.f(wo, -wi, TransportMode::Radiance), photon_core::Rgb::ZERO);

    for (case, wo) in [wo, fmath::normalize(Vec3A::new(0.5, -0.5, 0.3)), Vec3A::Z].into_iter().enumerate() {
        let mut rng = sampler(8, case as u64);
        let (mut mean, mut cos_mean) = (common::Mean::default(), common::Mean::default());
        for _ in 0..100_000 {
            let s = b.sample(wo, rng.next_f32(), rng.next_2d(), TransportMode::Importance);
            let w = s.map_or(photon_core::Rgb::ZERO, |s| {
                let w = s.f * s.wi.dot(ns).abs() / s.pdf;
                assert!((w - r).abs().max_element() < 1e-5, "wo = {wo}: {s:?}");
                w * b.adjoint_correction(wo, s.wi)
            });
            mean.add(w);
            cos_mean.add(w * s.map_or(0.0, |s| s.wi.dot(ng).abs()));
        }
        let expected = f64::from(r.x * wo.dot(ns).abs() / wo.dot(ng).abs());
        let (m, se) = (mean.mean()[0], mean.std_error()[0]);
        assert!((m - expected).abs() < 5.0 * se + 1e-6, "wo = {wo}: mean adjoint weight {m} ± {se}, not {expected}");
        let (c, cse) = (cos_mean.mean()[0], cos_mean.std_error()[0]);
        let expected_c = 2.0 / 3.0 * expected;
        assert!((c - expected_c).abs() < 5.0 * cse + 1e-6, "wo = {wo}: ⟨weight·cos⟩ {c} ± {cse}, not {expected_c}");
    }
}
