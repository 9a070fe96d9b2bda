//! Claim: no BSDF scatters more flux than it receives, and `Bsdf::albedo` is the scattered fraction.
//!
//! The directional albedo ρ(wo) = ∫ f(wo, wi)·|cos θi| dωi (plus the delta lobes) is estimated with the BSDF's
//! own sampling, as an integrator does: the mean of `f·|cos θi|/pdf` over samples, delta lobes included, in
//! `Importance` mode (flux). It must not exceed 1 per channel; it must equal `albedo()` for the kinds where
//! that is exact (Phong at normal incidence too), and stay below it for Phong elsewhere and for the microfacet
//! lobes (rough metal and glass), where `albedo()` is an upper bound. The non-delta part is
//! checked once more against an independent quadrature of `f·|cos θi|` over the sphere, which does not use
//! `pdf` or `sample` at all. Tolerances: 5 standard errors of the Monte Carlo mean, plus the quadrature's own
//! error estimated by halving its grid, plus 1e-5 for f32 rounding.

mod common;

use common::{Mean, dir, every_kind, flat, integrate_whole_sphere, is_microfacet, sampler};
use photon_core::material::bsdf::{Bsdf, TransportMode};

const SAMPLES: usize = 200_000;
const Z: f64 = 5.0;
const THETAS: [f32; 6] = [0.0, 0.3, 0.7, 1.1, 1.4, 1.55];

/// Monte Carlo estimates of the whole albedo and of its non-delta part.
fn estimate(b: &Bsdf, wo: glam::Vec3A, case: u64) -> (Mean, Mean) {
    let mut rng = sampler(1, case);
    let (mut all, mut non_delta) = (Mean::default(), Mean::default());
    for _ in 0..SAMPLES {
        let (u, u2) = (rng.next_f32(), rng.next_2d());
        let w = match b.sample(wo, u, u2, TransportMode::Importance) {
            Some(s) => {
                assert!(s.pdf > 0.0 && s.f.is_finite() && s.f.min_element() >= 0.0, "{s:?}");
                (s.f * s.wi.dot(b.frame.n).abs() / s.pdf, s.delta)
            }
            None => (photon_core::Rgb::ZERO, false),
        };
        all.add(w.0);
        non_delta.add(if w.1 { photon_core::Rgb::ZERO } else { w.0 });
    }
    (all, non_delta)
}

#[test]
fn scattered_flux_is_at_most_the_incident_flux_and_is_the_albedo() {
    let mut case = 0;
    for (name, bxdf) in every_kind() {
        let b = flat(bxdf);
        for (j, &theta) in THETAS.iter().enumerate() {
            // Phong's albedo() = kd + ks is exact at normal incidence, where its lobe lies wholly above the
            // surface: ∫ (n+2)/(2π)·cos^n θ·cos θ dω = 1. That pins the lobe's normalisation.
            // A microfacet lobe's albedo() is a bound: single scattering loses what its facets shadow and what
            // falls below the horizon (the furnace tables in microfacet.rs's tests).
            let exact = (!name.starts_with("phong") || theta == 0.0) && !is_microfacet(&bxdf);
            for side in [1.0f32, -1.0] {
                case += 1;
                let wo = side * dir(theta, 0.4 * j as f32);
                let (all, _) = estimate(&b, wo, case);
                let albedo = b.albedo(wo).to_array();
                let (m, se) = (all.mean(), all.std_error());
                for c in 0..3 {
                    let tol = Z * se[c] + 1e-5;
                    let at = format!("{name}, θo = {theta}, side {side}, channel {c}: {} ± {}", m[c], se[c]);
                    assert!(m[c] <= 1.0 + tol, "energy gain: {at}");
                    assert!(albedo[c] <= 1.0, "albedo() above 1: {at}");
                    if exact {
                        assert!((m[c] - f64::from(albedo[c])).abs() <= tol, "albedo() = {}: {at}", albedo[c]);
                    } else {
                        assert!(m[c] <= f64::from(albedo[c]) + tol, "albedo() = {} is no bound: {at}", albedo[c]);
                    }
                }
            }
        }
    }
}

#[test]
fn sampled_non_delta_albedo_matches_a_quadrature_of_f_cos() {
    let mut case = 1000;
    for (name, bxdf) in every_kind() {
        let b = flat(bxdf);
        if !b.has_non_delta() {
            continue;
        }
        for (j, &theta) in THETAS.iter().enumerate() {
            case += 1;
            let wo = dir(theta, 0.4 * j as f32);
            let (_, non_delta) = estimate(&b, wo, case);
            let (m, se) = (non_delta.mean(), non_delta.std_error());
            let g = |wi: glam::Vec3A| b.f(wo, wi, TransportMode::Importance) * wi.z.abs();
            let fine = integrate_whole_sphere(512, g);
            let coarse = integrate_whole_sphere(256, g);
            for c in 0..3 {
                let tol = Z * se[c] + (fine[c] - coarse[c]).abs() + 1e-5;
                assert!(
                    (m[c] - fine[c]).abs() <= tol,
                    "{name}, θo = {theta}, channel {c}: sampled {} ± {}, quadrature {} (coarse {})",
                    m[c],
                    se[c],
                    fine[c],
                    coarse[c]
                );
            }
        }
    }
}
