//! Physics claim: on a flat Lambertian surface lit by photons of uniform density, the photon-map estimate
//! returns the analytic reflected radiance L = ρ/π · E (E = density · Φ) with every kernel, gathering by
//! radius or by the k nearest, with or without the filters; and the k-nearest estimate is unbiased only
//! because the k-th photon, which sets the radius, is left out of the sum.
//!
//! Statistics. Photon positions are independent and uniform over the unit square (a binomial process: given
//! the k-th nearest distance, the nearer photons are uniform in its disc, exactly as for a Poisson process).
//! Every gather radius is capped (k-nearest: `max_radius`), queries sit on a grid whose spacing is twice the
//! cap, at least the cap away from the square's edges, so their discs are disjoint and their estimates
//! independent. With 2^20 photons per set and about 400 counted photons per disc, each estimate has a
//! relative standard deviation of about √(V/400) with V = E[K²]/E[K]² between 1 (box) and 1.5 (cone),
//! i.e. 5–6%; averaged over ~1400 queries the standard error of the mean is ≈ 0.15%. The 2% tolerance is
//! then more than 10 standard errors: a correct estimator essentially never fails it, and a 2% bias never
//! passes. Each case also asserts that its measured standard error is below 0.5% (so the tolerance means
//! something) and that the mean is within 4.5 standard errors of L.

use glam::Vec3A;
use photon_core::Rgb;
use photon_core::math::cosine_hemisphere;
use photon_core::math::rng::{Domain, Sampler};
use photon_core::photon::{Estimator, Gather, Kernel, Photon, PhotonMap};

const SEED: u64 = 0x5EED_F00D;
/// Reflectance of the Lambertian surface.
const RHO: f32 = 0.8;
/// Irradiance carried by each set of photons, W/m² per channel (the square has unit area).
const E: [f32; 3] = [1.0, 0.5, 0.25];

/// `count` photons uniform over the unit square at z = 0 carrying `E` in total (so `Φ = E / count`), arriving
/// from cosine-distributed directions on the side `side` (+1: above, −1: below) of the plane.
fn plane_photons(count: usize, set: u64, side: f32, object: u32) -> Vec<Photon> {
    let phi = Rgb::from(E) / count as f32;
    let n = Vec3A::Z * side;
    (0..count)
        .map(|i| {
            let mut s = Sampler::new(SEED, Domain::Photon, set, i as u64, 0);
            let xy = s.next_2d();
            let wi = cosine_hemisphere(s.next_2d()) * Vec3A::new(1.0, 1.0, side);
            Photon::new(Vec3A::new(xy.x, xy.y, 0.0), wi, n, phi, object)
        })
        .collect()
}

/// Query points on a grid of the given spacing, at least `margin` from the square's edges.
fn query_grid(spacing: f32, margin: f32) -> Vec<Vec3A> {
    let per_axis = ((1.0 - 2.0 * margin) / spacing).floor() as usize + 1;
    let offset = (1.0 - (per_axis - 1) as f32 * spacing) / 2.0;
    (0..per_axis * per_axis)
        .map(|i| Vec3A::new(offset + (i % per_axis) as f32 * spacing, offset + (i / per_axis) as f32 * spacing, 0.0))
        .collect()
}

struct Stats {
    mean: f64,
    std_error: f64,
    queries: usize,
}

fn stats(values: impl Iterator<Item = f64>) -> Stats {
    let v: Vec<f64> = values.collect();
    let q = v.len() as f64;
    let mean = v.iter().sum::<f64>() / q;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (q - 1.0);
    Stats { mean, std_error: (var / q).sqrt(), queries: v.len() }
}

/// Asserts the estimate, averaged over the queries, is L = ρ/π·E in every channel (checked on the ratio to L,
/// which is the same random variable for all three channels since every photon carries the same colour).
fn check(map: &PhotonMap, est: &Estimator, queries: &[Vec3A], label: &str) {
    let l = Rgb::from(E) * (RHO / std::f32::consts::PI);
    let f = |_wi: Vec3A| Rgb::splat(RHO / std::f32::consts::PI);
    let mut scratch = Vec::new();
    let mut ratios = [Vec::new(), Vec::new(), Vec::new()];
    for &p in queries {
        let estimate = map.estimate(est, p, Vec3A::Z, 0, f, &mut scratch);
        for (c, r) in ratios.iter_mut().enumerate() {
            r.push(f64::from(estimate[c]) / f64::from(l[c]));
        }
    }
    for (c, r) in ratios.into_iter().enumerate() {
        let s = stats(r.into_iter());
        if c == 0 {
            println!("{label:<64} mean/L = {:.4} ± {:.4} over {} queries", s.mean, s.std_error, s.queries);
        }
        assert!(s.std_error < 0.005, "{label}: standard error {} too large for a 2% test", s.std_error);
        assert!((s.mean - 1.0).abs() < 0.02, "{label}: mean/L = {} ± {}", s.mean, s.std_error);
        assert!((s.mean - 1.0).abs() < 4.5 * s.std_error, "{label}: mean/L = {} ± {}", s.mean, s.std_error);
    }
}

/// Expected gather radius holding `m` photons at density `density`.
fn radius_for(m: f32, density: f32) -> f32 {
    (m / (std::f32::consts::PI * density)).sqrt()
}

/// The k-nearest radius cap, relative to the radius holding k photons on average: π·density·(1.15 r)² holds
/// 1.32 k photons on average, 6σ above k for k = 400, so the cap practically never binds (and when it does,
/// the estimate is a radius estimate, unbiased as well).
const CAP: f32 = 1.15;

#[test]
fn every_kernel_recovers_the_radiance_of_a_uniform_density() {
    let count = 1 << 20;
    let map = PhotonMap::build(plane_photons(count, 0, 1.0, 0)).unwrap();
    let r = radius_for(400.0, count as f32);
    let queries = query_grid(2.0 * CAP * r, CAP * r);
    assert!(queries.len() > 1000, "{} queries", queries.len());
    for kernel in Kernel::ALL {
        for (gather, disc) in [
            (Gather::Radius { radius: r }, None),
            (Gather::KNearest { k: 401, max_radius: CAP * r }, None),
            (Gather::KNearest { k: 401, max_radius: CAP * r }, Some(0.1)),
        ] {
            let est = Estimator { gather, kernel, disc, same_object: false };
            check(&map, &est, &queries, &format!("{kernel:?} {gather:?} disc {disc:?}"));
        }
    }
}

/// Photons of another object on the same plane and photons stored on its back face (arriving from below)
/// are rejected by the filters; with a k-nearest gather they still take part in choosing the radius, and the
/// estimate stays unbiased.
#[test]
fn filters_reject_other_objects_and_the_back_face_without_bias() {
    let count = 1 << 20;
    let mut photons = plane_photons(count, 1, 1.0, 0);
    photons.extend(plane_photons(count, 2, -1.0, 0));
    photons.extend(plane_photons(count, 3, 1.0, 1));
    let map = PhotonMap::build(photons).unwrap();
    // 400 counted photons per disc: 1200 gathered across the three sets.
    let r = radius_for(400.0, count as f32);
    let queries = query_grid(2.0 * CAP * r, CAP * r);
    assert!(queries.len() > 1000, "{} queries", queries.len());
    for kernel in Kernel::ALL {
        for gather in [Gather::Radius { radius: r }, Gather::KNearest { k: 1201, max_radius: CAP * r }] {
            let est = Estimator { gather, kernel, disc: Some(0.05), same_object: true };
            check(&map, &est, &queries, &format!("filtered {kernel:?} {gather:?}"));
        }
    }
}

/// With few photons the k-th photon's place on the boundary matters: counting it overestimates the density
/// by k/(k−1) (here 8/7, +14%); the estimate leaves it out and is unbiased.
#[test]
fn k_nearest_leaves_the_boundary_photon_out() {
    let count = 1 << 20;
    let map = PhotonMap::build(plane_photons(count, 4, 1.0, 0)).unwrap();
    let k = 8;
    // Relative std of (k−1)/(π d_k²) is 1/√(k−2) = 41% per query; 25,000 disjoint queries bring the
    // standard error to 0.26%, and 2% is 7 of them. The cap of 2 radii holds 32 photons on average, where
    // k = 8 are needed: it binds with probability ~1e-8.
    let r = radius_for(k as f32, count as f32);
    let queries = query_grid(4.0 * r, 2.0 * r);
    assert!(queries.len() > 25_000, "{} queries", queries.len());
    let est = Estimator {
        gather: Gather::KNearest { k, max_radius: 2.0 * r },
        kernel: Kernel::Box,
        disc: None,
        same_object: false,
    };
    check(&map, &est, &queries, "box, k = 8");

    // The naive box estimate over all k photons, from the same gathers.
    let phi = E[0] / count as f32;
    let mut scratch = Vec::new();
    let naive = stats(queries.iter().map(|&p| {
        map.k_nearest(p, k as usize, 4.0 * r * r, &mut scratch);
        let d2_k = scratch.last().map_or(4.0 * r * r, |&(_, d2)| d2);
        f64::from(scratch.len() as f32 * phi / (std::f32::consts::PI * d2_k)) / f64::from(E[0])
    }));
    println!("naive box, k = 8: mean/E = {:.4} ± {:.4}", naive.mean, naive.std_error);
    let expected = f64::from(k) / f64::from(k - 1);
    assert!((naive.mean - expected).abs() < 4.5 * naive.std_error, "naive {} vs k/(k-1) = {expected}", naive.mean);
}
