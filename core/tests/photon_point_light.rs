//! A point light over a Lambert plane, estimated from photons: L = ρ/π · I·cos θ / r². With 4× the photons the
//! error is smaller, for every kernel, gathering by k nearest (k ∝ √N) and by radius (r ∝ N^(−1/4)): both
//! shrink the variance and the bias together, as a consistent estimator must.

#![allow(clippy::unwrap_used)]

use glam::Vec3A;
use photon_core::photon::{Estimator, Gather, Kernel, PhotonMap};
use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use photon_core::scene::Scene;
use std::path::Path;

const SCENE: &str = r#"
[camera]
eye = [0.0, 3.0, 3.0]
look_at = [0.0, 0.0, 0.0]

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "rect"
center = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
width = 20.0
height = 20.0
material = "grey"

[[lights]]
type = "point"
position = [0.0, 1.0, 0.0]
intensity = [2.0, 2.0, 2.0]
"#;

const RHO: f32 = 0.5;

/// RMS relative error of the estimate over a grid of points on the plane.
fn rms_error(map: &PhotonMap, est: &Estimator) -> f64 {
    let mut scratch = Vec::new();
    let mut sum = 0.0f64;
    let mut count = 0;
    for i in 0..10 {
        for j in 0..10 {
            let p = Vec3A::new(-0.6 + 1.2 * i as f32 / 9.0, 0.0, -0.6 + 1.2 * j as f32 / 9.0);
            let r2 = p.x * p.x + p.z * p.z + 1.0;
            let expected = RHO / std::f32::consts::PI * 2.0 * (1.0 / r2.sqrt()) / r2;
            let l = map.estimate(est, p, Vec3A::Y, 0, |_| Vec3A::splat(RHO / std::f32::consts::PI), &mut scratch);
            let rel = f64::from((l.y - expected) / expected);
            sum += rel * rel;
            count += 1;
        }
    }
    (sum / f64::from(count)).sqrt()
}

#[test]
fn estimate_converges_as_photons_grow() {
    let path = Path::new("point-over-plane.toml");
    let prep = Prepared::new(&Scene::parse(SCENE, path).unwrap(), path).unwrap();
    let n = 40_000u64;
    let small = PhotonMap::build(trace_photons(&prep, n, 0, PhotonKind::Global).photons).unwrap();
    let large = PhotonMap::build(trace_photons(&prep, 4 * n, 1, PhotonKind::Global).photons).unwrap();
    for kernel in Kernel::ALL {
        let est = |gather| Estimator { gather, kernel, disc: None, same_object: false };
        let cases = [
            ("k-nearest", Gather::KNearest { k: 100, max_radius: 1.0 }, Gather::KNearest { k: 200, max_radius: 1.0 }),
            ("radius", Gather::Radius { radius: 0.15 }, Gather::Radius { radius: 0.15 / 2f32.sqrt() }),
        ];
        for (name, g1, g4) in cases {
            let e1 = rms_error(&small, &est(g1));
            let e4 = rms_error(&large, &est(g4));
            eprintln!("{kernel:?} {name}: rms relative error {e1:.4} with N, {e4:.4} with 4N");
            assert!(e4 < e1, "{kernel:?} {name}: error did not shrink ({e1} → {e4})");
            assert!(e4 < 0.1, "{kernel:?} {name}: error {e4} with 4N photons is not small");
        }
    }
}
