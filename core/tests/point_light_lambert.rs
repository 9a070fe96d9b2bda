//! A point light above a Lambert plane: the radiance leaving the plane is ρ/π · I·cos θ / r², exactly, for
//! both integrators (the only light path is light → plane → eye).

#![allow(clippy::unwrap_used)]

use glam::Vec3A;
use photon_core::math::Ray;
use photon_core::math::fmath;
use photon_core::math::rng::Sampler;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::prepare::tracer::Tracer;
use photon_core::scene::Scene;
use std::path::Path;

const SCENE: &str = r#"
[camera]
eye = [0.0, 3.0, 3.0]
look_at = [0.0, 0.0, 0.0]

[render]
spp = 1

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "plane"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
material = "grey"

[[lights]]
type = "point"
position = [0.3, 2.0, -0.4]
intensity = [10.0, 5.0, 2.5]
"#;

#[test]
fn radiance_matches_the_analytic_value() {
    let scene = Scene::parse(SCENE, Path::new("point-light.toml")).unwrap();
    let prep = Prepared::new(&scene, Path::new("point-light.toml"))
        .unwrap()
        .with_photon_maps(Path::new("point-light.toml"))
        .unwrap();
    let light = Vec3A::new(0.3, 2.0, -0.4);
    let intensity = Vec3A::new(10.0, 5.0, 2.5);
    let eye = Vec3A::new(0.0, 3.0, 3.0);
    for integrator in [Method::Direct, Method::Path] {
        let mut prep = prep.clone();
        prep.settings.integrator = integrator;
        for (i, target) in [[0.0, 0.0, 0.0], [1.5, 0.0, -2.0], [-2.0, 0.0, 1.0], [0.3, 0.0, -0.4]].iter().enumerate() {
            let p = Vec3A::from_array(*target);
            let ray = Ray::new(eye, fmath::normalize(p - eye));
            let mut tracer = Tracer::new(&prep, Sampler::for_pixel(1, i as u32, 0, 0));
            let l = photon_core::integrator::li(&mut tracer, ray);
            let d = light - p;
            let r2 = d.length_squared();
            let cos = fmath::normalize(d).y;
            let expected = 0.5 / std::f32::consts::PI * intensity * cos / r2;
            let rel = ((l - expected) / expected).abs().max_element();
            assert!(rel < 0.01, "{integrator:?} at {p}: {l} vs {expected} ({rel})");
        }
    }
}
