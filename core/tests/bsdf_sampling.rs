//! Claim: `Bsdf::sample` draws directions with the density `Bsdf::pdf` says, and reports that density.
//!
//! Pearson's chi-square test (as in pbrt's `chi2test`): 200 000 samples binned into 10 × 20 cells in (θ, φ) over
//! the whole sphere, against expected counts from integrating `pdf` over each cell numerically. Only the
//! non-delta samples are binned, and the expected counts are scaled to their number: this tests the shape of
//! the distribution; how much probability the non-delta lobes get is `bsdf_pdf_normalisation.rs`'s claim
//! (the quadrature error of 1 − ∫pdf would swamp the few `None` samples of a narrow lobe). Cells expecting
//! fewer than 5 samples are pooled. Lambert and Phong (several exponents), the diffuse part of Mix, and rough
//! metal and glass (both sides, so refraction into and out of the denser side), at several `wo`. The narrower
//! microfacet lobes are tested on a grid about their peak in `microfacet.rs`'s own tests.
//! Each test rejects at significance 1 − (1 − 0.01)^(1/cases) (Šidák), so that the whole file wrongly fails
//! once in a hundred seeds; the seeds are fixed, so the outcome is reproducible.

mod common;

use common::{chi2_p_value, chi2_test, dir, flat, integrate_sphere, sampler};
use glam::Vec3A;
use photon_core::Rgb;
use photon_core::material::bsdf::{Bsdf, Bxdf, TransportMode};
use std::f64::consts::{PI, TAU};

const SAMPLES: usize = 200_000;
const THETA_BINS: usize = 10;
const PHI_BINS: usize = 20;
/// Sub-grid per cell for the expected counts: fine enough for the narrowest lobe tested (n = 500, about
/// 1/√n ≈ 0.045 rad wide) at 0.31/48 ≈ 0.0065 rad per step.
const SUB: usize = 48;

fn cell_of(w: Vec3A) -> usize {
    let theta = f64::from(w.z.clamp(-1.0, 1.0)).acos();
    let mut phi = f64::from(w.y).atan2(f64::from(w.x));
    if phi < 0.0 {
        phi += TAU;
    }
    let t = ((theta / PI * THETA_BINS as f64) as usize).min(THETA_BINS - 1);
    let p = ((phi / TAU * PHI_BINS as f64) as usize).min(PHI_BINS - 1);
    t * PHI_BINS + p
}

/// Runs the chi-square test of one (BSDF, wo) pair and returns its p-value.
fn chi2_of(b: &Bsdf, wo: Vec3A, case: u64) -> f64 {
    let cells = THETA_BINS * PHI_BINS;
    let mut observed = vec![0.0f64; cells];
    let mut rng = sampler(2, case);
    for _ in 0..SAMPLES {
        let (u, u2) = (rng.next_f32(), rng.next_2d());
        match b.sample(wo, u, u2, TransportMode::Radiance) {
            Some(s) if !s.delta => observed[cell_of(s.wi)] += 1.0,
            _ => {}
        }
    }
    let mut expected = vec![0.0f64; cells];
    let (dt, dp) = (PI / THETA_BINS as f64, TAU / PHI_BINS as f64);
    for t in 0..THETA_BINS {
        for p in 0..PHI_BINS {
            let mass = integrate_sphere(
                (t as f64 * dt, (t + 1) as f64 * dt),
                (p as f64 * dp, (p + 1) as f64 * dp),
                (SUB, SUB),
                |wi| Rgb::splat(b.pdf(wo, wi)),
            )[0];
            expected[t * PHI_BINS + p] = mass;
        }
    }
    let scale = observed.iter().sum::<f64>() / expected.iter().sum::<f64>();
    expected.iter_mut().for_each(|e| *e *= scale);
    chi2_test(&observed, &expected).2
}

fn cases() -> Vec<(String, Bsdf, Vec3A)> {
    let mut out = Vec::new();
    let wos = [dir(0.05, 0.3), dir(0.8, 2.0), dir(1.4, 4.0), -dir(0.6, 1.0)];
    let mut bxdfs = vec![("lambert".to_string(), Bxdf::Lambert { r: Rgb::splat(0.7) })];
    for n in [1.0, 5.0, 30.0, 500.0] {
        bxdfs.push((
            format!("phong n={n}"),
            Bxdf::Phong { kd: Rgb::new(0.3, 0.2, 0.1), ks: Rgb::new(0.5, 0.6, 0.4), exponent: n },
        ));
    }
    bxdfs.push(("phong glossy only".into(), Bxdf::Phong { kd: Rgb::ZERO, ks: Rgb::splat(0.9), exponent: 10.0 }));
    bxdfs.push((
        "mix".into(),
        Bxdf::Mix { color: Rgb::splat(0.5), diffuse: 0.4, specular: 0.2, transmission: 0.3, eta: 1.5 },
    ));
    for r in [0.3f32, 0.6] {
        let alpha = r * r;
        bxdfs.push((format!("gold r={r}"), Bxdf::Conductor { fresnel: common::gold(), alpha }));
        bxdfs.push((format!("rough glass r={r}"), Bxdf::RoughDielectric { eta: 1.5, tint: Rgb::ONE, alpha }));
    }
    bxdfs.push((
        "rough glass 1/1.5 r=0.5".into(),
        Bxdf::RoughDielectric { eta: 1.0 / 1.5, tint: Rgb::ONE, alpha: 0.25 },
    ));
    for (name, bxdf) in bxdfs {
        for wo in wos {
            out.push((name.clone(), flat(bxdf), wo));
        }
    }
    out
}

#[test]
fn chi2_p_values_match_tables() {
    // Critical values from standard tables: P(X ≥ x) for the given degrees of freedom.
    for (x, dof, p) in [(3.841, 1, 0.05), (6.635, 1, 0.01), (18.307, 10, 0.05), (124.342, 100, 0.05), (0.0, 5, 1.0)] {
        let got = chi2_p_value(x, dof);
        assert!((got - p).abs() < 2e-4, "chi2 {x} dof {dof}: {got} vs {p}");
    }
}

#[test]
fn sampled_directions_follow_pdf() {
    let cases = cases();
    let alpha = 1.0 - (1.0f64 - 0.01).powf(1.0 / cases.len() as f64);
    for (i, (name, b, wo)) in cases.iter().enumerate() {
        let p = chi2_of(b, *wo, i as u64);
        eprintln!("{name:>18}, wo = {wo:.3}: p = {p:.3}");
        assert!(p >= alpha, "{name}, wo = {wo}: chi-square p-value {p:.3e} < {alpha:.3e}");
    }
}

#[test]
fn samples_report_pdf_and_f() {
    for (i, (name, b, wo)) in cases().iter().enumerate() {
        let mut rng = sampler(3, i as u64);
        for _ in 0..20_000 {
            let (u, u2) = (rng.next_f32(), rng.next_2d());
            let Some(s) = b.sample(*wo, u, u2, TransportMode::Radiance) else { continue };
            if s.delta {
                continue;
            }
            let pdf = b.pdf(*wo, s.wi);
            assert!((s.pdf - pdf).abs() <= 1e-4 * pdf, "{name}: sample pdf {} vs pdf() {pdf}", s.pdf);
            let f = b.f(*wo, s.wi, TransportMode::Radiance);
            assert!((s.f - f).abs().max_element() <= 1e-4 * f.max_element(), "{name}: sample f {} vs f() {f}", s.f);
            assert!((s.wi.length() - 1.0).abs() < 1e-4, "{name}: |wi| = {}", s.wi.length());
        }
    }
}
