//! Claim: photons see smooth shading normals as the path tracer does (Veach 1997, §5.3). In
//! `scenes/regressions/smooth-cube-photons.toml` a point light of
//! intensity I shines on a Lambert cube (albedo ρ) whose normals are averaged across its 90° edges (corner
//! normals 35° to 55° off the faces), inside a black sphere that absorbs what the cube reflects.
//!
//! With shading normals the cube reflects towards the camera `L = ρ/π · I·|wl·ns|/d²` at a point at distance d
//! from the light, so the flux it scatters is `ρ·∫ I·|wl·ns|/d² dA = ρ·I·∫ |w·ns|/|w·ng| dω` over the directions
//! from the light that hit the cube. The photons stored on the cube (first hits) must carry `I·∫|w·ns|/|w·ng| dω`
//! (the arrival correction) and those stored on the black sphere after one bounce `ρ` times that (the adjoint
//! BSDF). Without the corrections they are `I·Ω` and `ρ·I·Ω`, Ω the solid angle of the cube: 7 % lower here,
//! outside the tolerances (checked below).
//!
//! The reference integral is a Monte Carlo estimate over 4 000 000 uniform directions from the light through the
//! scene's own hit records (normals, not the BSDF); the photon sums come from 4 000 000 paths. Each path adds at
//! most one photon to each sum, so the sums are means of independent terms: tolerance 5 combined standard
//! errors.

#![allow(clippy::unwrap_used)]

mod common;

use common::sampler;
use glam::Vec3A;
use photon_core::light::Light;
use photon_core::math::{Ray, uniform_sphere};
use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use photon_core::scene::Scene;
use std::path::PathBuf;

/// The cube's object index: the black sphere is object 0.
const CUBE: u32 = 1;

/// The scene, its light's position and intensity (red).
fn scene() -> (Prepared, Vec3A, f32) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/regressions/smooth-cube-photons.toml");
    let prep = Prepared::new(&Scene::load(&path).unwrap(), &path).unwrap();
    let Light::Point { p, intensity } = prep.lights.lights[0] else { panic!("expected a point light") };
    (prep, p, intensity.x)
}

/// Mean and standard error of `n` terms given their sum and sum of squares (terms not listed are 0).
fn mean_se(sum: f64, sum2: f64, n: f64) -> (f64, f64) {
    let mean = sum / n;
    (mean, ((sum2 / n - mean * mean) / (n - 1.0)).max(0.0).sqrt())
}

/// Σ of the red power of `photons` (each from a different path) on `object`, over `paths` paths, as the mean
/// per path times `paths` with its standard error.
fn photon_sum(photons: &[photon_core::photon::Photon], object: Option<u32>, paths: u64) -> (f64, f64) {
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for ph in photons.iter().filter(|ph| object.is_none_or(|o| ph.object == o)) {
        let x = f64::from(ph.phi().x);
        s += x;
        s2 += x * x;
    }
    let (m, se) = mean_se(s, s2, paths as f64);
    (m * paths as f64, se * paths as f64)
}

#[test]
fn photons_on_a_smooth_shaded_cube_carry_what_the_path_tracer_sees() {
    let (prep, light, intensity) = scene();

    // Reference: I·∫|w·ns|/|w·ng| dω and I·Ω over the directions from the light that hit the cube.
    let m = 4_000_000u32;
    let mut rng = sampler(21, 0);
    let (mut s, mut s2, mut omega, mut rho) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for _ in 0..m {
        let w = uniform_sphere(rng.next_2d());
        let Some(hit) = prep.geometry.intersect(&Ray::new(light, w), f32::INFINITY) else { continue };
        if hit.object != CUBE {
            continue;
        }
        let i4pi = 4.0 * std::f64::consts::PI * f64::from(intensity);
        let x = i4pi * f64::from(w.dot(hit.ns).abs() / w.dot(hit.n).abs());
        s += x;
        s2 += x * x;
        omega += i4pi;
        rho = f64::from(prep.materials[hit.material as usize].bsdf(&hit, &prep.textures).albedo(-w).x);
    }
    let (expected, expected_se) = mean_se(s, s2, f64::from(m));
    let uncorrected = omega / f64::from(m);

    let n = 4_000_000u64;
    let first = trace_photons(&prep, n, 0, PhotonKind::Global);
    let (on_cube, on_cube_se) = photon_sum(&first.photons, Some(CUBE), n);
    let bounced = trace_photons(&prep, n, 1, PhotonKind::Indirect);
    let (scattered, scattered_se) = photon_sum(&bounced.photons, None, n);
    eprintln!(
        "arriving: photons {on_cube:.4} ± {on_cube_se:.4}, path tracer {expected:.4} ± {expected_se:.4}, \
         without correction {uncorrected:.4}; scattered: photons {scattered:.4} ± {scattered_se:.4}, path tracer {:.4}",
        rho * expected
    );

    let tol = 5.0 * on_cube_se.hypot(expected_se);
    assert!((on_cube - expected).abs() < tol, "arriving flux {on_cube} vs {expected} ± {tol}");
    let tol_s = 5.0 * scattered_se.hypot(rho * expected_se);
    assert!((scattered - rho * expected).abs() < tol_s, "scattered flux {scattered} vs {} ± {tol_s}", rho * expected);
    // Not vacuous: without the corrections both sums would fall outside their tolerances.
    assert!((uncorrected - expected).abs() > tol, "correction {} within noise {tol}", uncorrected - expected);
    let d = rho * (uncorrected - expected);
    assert!(d.abs() > tol_s, "scattered: correction {d} within noise {tol_s}");
}
