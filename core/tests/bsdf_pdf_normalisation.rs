//! Claim: `Bsdf::pdf` integrates over the sphere to the probability that `Bsdf::sample` returns a non-delta
//! direction: 1 for Lambert, 1 for Phong less what its glossy lobe puts below the horizon (nothing at normal
//! incidence), `diffuse / (diffuse + specular + transmission)` for Mix, 0 for mirrors and glass (smooth metal
//! too), and for rough metal and glass 1 less what their visible facets reflect below the horizon; for glTF's
//! metallic–roughness model with a smooth lobe, its diffuse base's share (1 − the mirror's probability).
//!
//! The integral is a midpoint quadrature over (θ, φ) whose error is bounded by the change on halving the grid;
//! the probability is the fraction of 200 000 samples, within 5 binomial standard errors.

mod common;

use common::{dir, every_kind, flat, integrate_whole_sphere, sampler};
use photon_core::Rgb;
use photon_core::material::bsdf::{Bxdf, TransportMode};
use photon_core::material::metallic_roughness;

const SAMPLES: usize = 200_000;

#[test]
fn pdf_integrates_to_the_non_delta_share() {
    let mut case = 0;
    for (name, bxdf) in every_kind() {
        let b = flat(bxdf);
        for (j, theta) in [0.0f32, 0.5, 1.0, 1.4].into_iter().enumerate() {
            for side in [1.0f32, -1.0] {
                case += 1;
                let wo = side * dir(theta, 1.3 * j as f32);
                let g = |wi| Rgb::splat(b.pdf(wo, wi));
                let fine = integrate_whole_sphere(512, g)[0];
                let quadrature_error = (fine - integrate_whole_sphere(256, g)[0]).abs() + 1e-6;

                let mut rng = sampler(4, case);
                let mut hits = 0usize;
                for _ in 0..SAMPLES {
                    if let Some(s) = b.sample(wo, rng.next_f32(), rng.next_2d(), TransportMode::Radiance) {
                        hits += usize::from(!s.delta);
                    }
                }
                let share = hits as f64 / SAMPLES as f64;
                let se = (share * (1.0 - share) / SAMPLES as f64).sqrt();
                let at = format!("{name}, θo = {theta}, side {side}: ∫pdf = {fine} ± {quadrature_error}");
                assert!(fine <= 1.0 + quadrature_error, "{at}");
                assert!((fine - share).abs() <= 5.0 * se + quadrature_error, "{at}, sampled share {share} ± {se}");

                let exact = match bxdf {
                    Bxdf::Lambert { .. } => Some(1.0),
                    Bxdf::Phong { .. } if theta == 0.0 => Some(1.0),
                    Bxdf::Phong { .. } => None,
                    Bxdf::Mirror { .. } | Bxdf::Dielectric { .. } => Some(0.0),
                    Bxdf::Conductor { alpha: 0.0, .. } => Some(0.0),
                    // Visible normals reflect below the horizon now and then: the share is below 1.
                    Bxdf::Conductor { .. } | Bxdf::RoughDielectric { .. } => None,
                    // The smooth glTF model: its diffuse base's share, 1 − the mirror's probability.
                    Bxdf::MetallicRoughness { base, metallic, alpha: 0.0 } => {
                        Some(f64::from(1.0 - metallic_roughness::specular_probability(base, metallic, wo)))
                    }
                    Bxdf::MetallicRoughness { .. } => None,
                    Bxdf::Mix { diffuse, specular, transmission, .. } => {
                        Some(f64::from(diffuse / (diffuse + specular + transmission)))
                    }
                };
                if let Some(exact) = exact {
                    assert!((fine - exact).abs() <= quadrature_error, "{at}, expected {exact}");
                }
            }
        }
    }
}
