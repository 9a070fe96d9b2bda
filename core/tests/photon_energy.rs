//! Photon emission conserves energy: the power of all emitted photons equals the lights' power, and Russian
//! roulette never raises a photon's power.

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, paths_per_light, trace_photons};
use std::path::Path;

fn scene(name: &str) -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name);
    Prepared::load(&path).unwrap()
}

#[test]
fn emitted_power_equals_light_power() {
    for name in ["cornell.toml", "cornell-point.toml", "caustic-point.toml"] {
        let prep = scene(name);
        let traced = trace_photons(&prep, 20_000, 0, PhotonKind::Global);
        let power = prep.lights.total_power();
        for (k, (e, p)) in traced.emitted.iter().zip(power.to_array()).enumerate() {
            let rel = (e - f64::from(p)).abs() / f64::from(p);
            assert!(rel < 1e-5, "{name} channel {k}: emitted {e} W, lights {p} W");
        }
        assert_eq!(traced.paths, 20_000);
    }
}

#[test]
fn paths_are_shared_by_power() {
    let mut prep = scene("cornell-point.toml");
    // Add a second point light with a third of the first one's power.
    let first = prep.lights.lights[0];
    let photon_core::light::Light::Point { p, intensity } = first else { panic!("expected a point light") };
    let second = photon_core::light::Light::Point { p: p + glam::Vec3A::X * 0.1, intensity: intensity / 3.0 };
    prep.lights = photon_core::light::LightSet::new(vec![first, second], None);
    assert_eq!(paths_per_light(&prep, 1000), vec![750, 250]);
    let traced = trace_photons(&prep, 1000, 0, PhotonKind::Global);
    let total = prep.lights.total_power();
    assert!((traced.emitted[0] - f64::from(total.x)).abs() / f64::from(total.x) < 1e-5);
}

#[test]
fn roulette_never_raises_a_photons_power() {
    // Lambert walls, a mirror and a glass sphere: every sampled weight is at most 1 per channel.
    for name in ["cornell.toml", "cornell-point.toml"] {
        let prep = scene(name);
        let n = 50_000u64;
        let emitted = prep.lights.lights[0].power() / n as f32;
        let max = emitted.max_element() * (1.0 + 1e-5);
        for kind in [PhotonKind::Global, PhotonKind::Caustic] {
            let traced = trace_photons(&prep, n, 0, kind);
            assert!(!traced.photons.is_empty());
            for ph in &traced.photons {
                let phi = ph.phi();
                assert!(phi.min_element() >= 0.0 && phi.max_element() <= max, "{name} {kind:?}: {phi} > {max}");
            }
        }
    }
}
