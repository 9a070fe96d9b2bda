//! White furnace: inside a closed sphere of albedo ρ whose surface emits Le everywhere, the radiance in every
//! direction is Le·(1 + ρ + ρ² + …) = Le/(1 − ρ). The path tracer (NEE, MIS and Russian roulette included)
//! must find it within 2%.

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::Path;

fn furnace(albedo: f32) -> f64 {
    let text = format!(
        r#"
[camera]
eye = [0.0, 0.0, 0.0]
look_at = [0.0, 0.0, -1.0]
fov = 90.0
width = 16
height = 16

[render]
spp = 64
max_depth = 1000
integrator = "path"

[materials.grey]
type = "lambert"
albedo = {albedo}

[[objects]]
type = "sphere"
center = [0.1, -0.2, 0.05]
radius = 2.0
material = "grey"
emission = {{ radiance = [1.0, 1.0, 1.0], two_sided = true }}
"#
    );
    let scene = Scene::parse(&text, Path::new("furnace.toml")).unwrap();
    let prep =
        Prepared::new(&scene, Path::new("furnace.toml")).unwrap().with_photon_maps(Path::new("furnace.toml")).unwrap();
    let strip = render_image(&prep, &|_| {});
    assert!(strip.pixels.iter().all(|v| v.is_finite() && *v >= 0.0));
    strip.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / strip.pixels.len() as f64
}

#[test]
fn path_tracer_converges_to_le_over_one_minus_albedo() {
    for albedo in [0.5f32, 0.8] {
        let mean = furnace(albedo);
        let expected = 1.0 / (1.0 - f64::from(albedo));
        let rel = (mean - expected).abs() / expected;
        eprintln!("furnace albedo {albedo}: {mean:.4} (expected {expected:.4})");
        assert!(rel < 0.02, "albedo {albedo}: mean {mean} vs {expected} ({:.2}%)", rel * 100.0);
    }
}
