//! Self-intersection avoidance works 10,000 units from the origin: the same scene moved there gives the
//! analytic radiance of a point light over a Lambert plane, and a Cornell box there is as bright as at home
//! (surface acne would darken it).

#![allow(clippy::unwrap_used)]

use glam::{Vec3, Vec3A};
use photon_core::math::Ray;
use photon_core::math::fmath;
use photon_core::math::rng::Sampler;
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::{LightSpec, Object, Scene};
use std::path::Path;

const FAR: Vec3 = Vec3::new(10_000.0, -10_000.0, 10_000.0);

fn moved(mut scene: Scene, by: Vec3) -> Scene {
    scene.camera.eye += by;
    scene.camera.look_at += by;
    for o in &mut scene.objects {
        match o {
            Object::Sphere { center, .. } => *center += by,
            Object::Plane { point, .. } => *point += by,
            Object::Rect { center, corner, .. } => {
                if let Some(c) = center {
                    *c += by;
                }
                if let Some(c) = corner {
                    *c += by;
                }
            }
            Object::Triangle { vertices, .. } => vertices.iter_mut().for_each(|v| *v += by),
            Object::Mesh { transform, .. } => transform.translate += by,
        }
    }
    for l in &mut scene.lights {
        let LightSpec::Point { position, .. } = l;
        *position += by;
    }
    scene
}

#[test]
fn point_light_over_a_plane_far_away() {
    let text = r#"
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
width = 10.0
height = 10.0
material = "grey"
[[lights]]
type = "point"
position = [0.5, 2.0, 0.0]
intensity = [4.0, 4.0, 4.0]
"#;
    let path = Path::new("far.toml");
    let scene = moved(Scene::parse(text, path).unwrap(), FAR);
    let prep = Prepared::new(&scene, path).unwrap().with_photon_maps(path).unwrap();
    let far = Vec3A::from(FAR);
    let eye = Vec3A::new(0.0, 3.0, 3.0) + far;
    for (i, target) in [[0.0, 0.0, 0.0], [1.0, 0.0, -1.0], [-2.0, 0.0, 0.5]].iter().enumerate() {
        let p = Vec3A::from_array(*target) + far;
        let mut rays = 0;
        let l = photon_core::integrator::li(
            &prep,
            Ray::new(eye, fmath::normalize(p - eye)),
            &mut Sampler::for_pixel(1, i as u32, 0, 0),
            &mut rays,
        );
        let d = Vec3A::new(0.5, 2.0, 0.0) - Vec3A::from_array(*target);
        let expected = 0.5 / std::f32::consts::PI * 4.0 * (d.y / d.length()) / d.length_squared();
        // Positions carry about 1e-3 of rounding 10,000 units out: allow for that in the geometry, not more.
        assert!((l.x - expected).abs() / expected < 0.01, "{l} vs {expected}");
    }
}

#[test]
fn cornell_box_far_away_is_as_bright_as_at_home() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut home = Scene::load(&path).unwrap();
    home.camera.width = 48;
    home.camera.height = 48;
    home.render.spp = 16;
    let far = moved(home.clone(), FAR);
    let mean = |s: &Scene| {
        let prep = Prepared::new(s, &path).unwrap().with_photon_maps(&path).unwrap();
        let img = render_image(&prep, &|_| {});
        img.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / img.pixels.len() as f64
    };
    let (a, b) = (mean(&home), mean(&far));
    assert!((a - b).abs() / a < 0.03, "mean radiance {a} at home, {b} far away");
}
