//! One-sided and two-sided surfaces: a point light over a Lambert plane, with the plane's normal towards the
//! light or away from it. Seen from the light's side, the radiance is ρ/π · I·cos θ / r² when the plane faces
//! the light or is two-sided, and exactly 0 when a one-sided plane turns its back (Mitsuba 3's rule); no photon
//! is stored on that back.

#![allow(clippy::unwrap_used)]

use glam::Vec3A;
use photon_core::Rgb;
use photon_core::math::Ray;
use photon_core::math::fmath;
use photon_core::math::rng::Sampler;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::prepare::tracer::Tracer;
use photon_core::scene::Scene;
use std::path::Path;

const LIGHT: [f32; 3] = [0.3, 2.0, -0.4];
const INTENSITY: [f32; 3] = [10.0, 5.0, 2.5];
const EYE: [f32; 3] = [0.0, 3.0, 3.0];

fn prepared(normal_y: f32, two_sided: bool) -> Prepared {
    let text = format!(
        r#"
[camera]
eye = {EYE:?}
look_at = [0.0, 0.0, 0.0]

[render]
spp = 1
integrator = "photon-map"

[render.photons]
global = 50000
k = 50

[materials.grey]
type = "lambert"
albedo = 0.5
two_sided = {two_sided}

[[objects]]
type = "rect"
center = [0.0, 0.0, 0.0]
normal = [0.0, {normal_y:?}, 0.0]
width = 12.0
height = 12.0
material = "grey"

[[lights]]
type = "point"
position = {LIGHT:?}
intensity = {INTENSITY:?}
"#
    );
    let path = Path::new("one-sided.toml");
    let scene = Scene::parse(&text, path).unwrap();
    Prepared::new(&scene, path).unwrap().with_photon_maps(path).unwrap()
}

/// The radiance each method returns towards the eye from a few points of the plane, with the analytic value.
fn radiance(prep: &Prepared, integrator: Method) -> Vec<(Rgb, Rgb)> {
    let (light, eye) = (Vec3A::from_array(LIGHT), Vec3A::from_array(EYE));
    let mut prep = prep.clone();
    prep.settings.integrator = integrator;
    [[0.0, 0.0, 0.0], [1.5, 0.0, -2.0], [-2.0, 0.0, 1.0], [0.3, 0.0, -0.4]]
        .iter()
        .enumerate()
        .map(|(i, target)| {
            let p = Vec3A::from_array(*target);
            let ray = Ray::new(eye, fmath::normalize(p - eye));
            // The mean of a few samples: the photon methods' gather is deterministic, the others are exact.
            let n = 16;
            let mut sum = Rgb::ZERO;
            for k in 0..n {
                let mut tracer = Tracer::new(&prep, Sampler::for_pixel(1, i as u32, 0, k));
                sum += photon_core::integrator::li(&mut tracer, ray);
            }
            let d = light - p;
            let expected =
                0.5 / std::f32::consts::PI * Vec3A::from_array(INTENSITY) * fmath::normalize(d).y / d.length_squared();
            (sum / n as f32, expected)
        })
        .collect()
}

const METHODS: [Method; 4] = [Method::Direct, Method::Path, Method::PhotonMap, Method::FinalGather];

#[test]
fn a_one_sided_plane_facing_the_light_reflects_as_a_two_sided_one() {
    for two_sided in [true, false] {
        let prep = prepared(1.0, two_sided);
        for integrator in METHODS {
            // The photon methods estimate a density: a few per cent of kernel bias and noise at 50 000 photons.
            let tol = if matches!(integrator, Method::Direct | Method::Path) { 0.01 } else { 0.08 };
            for (l, expected) in radiance(&prep, integrator) {
                let rel = ((l - expected) / expected).abs().max_element();
                assert!(rel < tol, "two_sided = {two_sided}, {integrator:?}: {l} vs {expected} ({rel})");
            }
        }
    }
}

#[test]
fn a_two_sided_plane_reflects_on_its_back() {
    let prep = prepared(-1.0, true);
    for integrator in [Method::Direct, Method::Path] {
        for (l, expected) in radiance(&prep, integrator) {
            let rel = ((l - expected) / expected).abs().max_element();
            assert!(rel < 0.01, "{integrator:?}: {l} vs {expected} ({rel})");
        }
    }
    assert!(!prep.photons.as_ref().unwrap().global.is_empty());
}

#[test]
fn a_one_sided_plane_is_black_from_behind_and_stores_no_photon_there() {
    let prep = prepared(-1.0, false);
    for integrator in METHODS {
        for (l, _) in radiance(&prep, integrator) {
            assert_eq!(l, Rgb::ZERO, "{integrator:?}");
        }
    }
    assert!(prep.photons.as_ref().unwrap().global.is_empty(), "photons stored on the back of a one-sided plane");
}

#[test]
fn two_sided_defaults_to_true_and_survives_the_blob() {
    let text = "[materials.a]\ntype = \"lambert\"\n[materials.b]\ntype = \"phong\"\ntwo_sided = false\n\
                [materials.c]\ntype = \"mirror\"\ntwo_sided = false\n";
    #[derive(serde::Deserialize)]
    struct File {
        materials: std::collections::BTreeMap<String, photon_core::material::Material>,
    }
    let f: File = toml::from_str(text).unwrap();
    assert!(f.materials["a"].two_sided());
    assert!(!f.materials["b"].two_sided());
    assert!(!f.materials["c"].two_sided());
    let prep = prepared(1.0, false);
    let blob = photon_core::codec::encode(&prep.materials).unwrap();
    let back: Vec<photon_core::material::Material> = photon_core::codec::decode(&blob, 1 << 20).unwrap();
    assert_eq!(back, prep.materials);
    assert!(!back[0].two_sided());
}
