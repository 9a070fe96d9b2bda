//! The k-nearest gather returns exactly the k nearest photons (ties by index) whatever radius its previous
//! query left as the guess: the guess changes the work, never the result.

#![allow(clippy::unwrap_used)]

use glam::Vec3A;
use photon_core::math::rng::{Domain, Sampler};
use photon_core::photon::{Photon, PhotonMap};

fn brute(photons: &[Photon], p: Vec3A, k: usize, max_r2: f32) -> Vec<(u32, f32)> {
    let mut all: Vec<(u32, f32)> = photons
        .iter()
        .enumerate()
        .map(|(i, ph)| (i as u32, (ph.position() - p).length_squared()))
        .filter(|&(_, d2)| d2 <= max_r2)
        .collect();
    all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    all.truncate(k);
    all
}

#[test]
fn result_does_not_depend_on_the_previous_query() {
    let mut s = Sampler::new(3, Domain::Photon, 0, 0, 0);
    // Dense on a small patch, sparse elsewhere, with duplicated positions to create exact ties.
    let mut photons = Vec::new();
    for i in 0..20_000 {
        let scale = if i % 4 == 0 { 10.0 } else { 0.5 };
        let p = Vec3A::new(s.next_f32() * scale, 0.0, s.next_f32() * scale);
        photons.push(Photon::new(p, Vec3A::Y, Vec3A::Y, Vec3A::ONE, 0));
        if i % 50 == 0 {
            photons.push(Photon::new(p, Vec3A::Y, Vec3A::Y, Vec3A::ONE, 1));
        }
    }
    let map = PhotonMap::build(photons.clone()).unwrap();
    let mut out = Vec::new();
    for (k, max_r2) in [(50usize, 4.0f32), (200, 0.5), (20, 100.0)] {
        for q in 0..200 {
            let p = Vec3A::new(s.next_f32() * 10.0, 0.0, s.next_f32() * 10.0);
            // Prime the guess with a query in the dense patch, then in the sparse area.
            for prime in [Vec3A::new(0.25, 0.0, 0.25), Vec3A::new(9.0, 0.0, 9.0)] {
                map.k_nearest(prime, k, max_r2, &mut out);
                map.k_nearest(p, k, max_r2, &mut out);
                // Results index the map's photons (which `build` reordered along a Morton curve).
                assert_eq!(out, brute(map.photons(), p, k, max_r2), "query {q}, k {k}, primed at {prime}");
            }
        }
    }
}
