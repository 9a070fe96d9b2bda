//! Self-intersection avoidance works at any place and scale (issue 16): the same scene moved 10⁴ units from
//! the origin gives the analytic radiance of a point light over a Lambert plane, and the Cornell box moved 10⁴
//! or 10⁵ units away, or scaled by 10⁻³ or 10³ (lights kept as bright), renders the mean of the original within
//! 1 % (surface acne would darken it, rays escaping through offsets too large for the scene would change it).
//! The box's coordinates are first rounded to multiples of 1/128 (lengths to 1/64), so that moved 10⁵ away (where f32 spacing is
//! 1/128) it is the same geometry to the bit; unrounded, its 5 mm light gap and 0.5-wide light land on that grid
//! and its mean changes by 2 % for that reason alone. The renders share their random streams, so what differs
//! is the arithmetic of intersection and offsets, not the samples.

#![allow(clippy::unwrap_used)]

use glam::{Vec3, Vec3A};
use photon_core::math::Ray;
use photon_core::math::fmath;
use photon_core::math::rng::Sampler;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::prepare::tracer::Tracer;
use photon_core::render::render_image;
use photon_core::scene::{LightSpec, Object, Scene};
use std::path::Path;

const FAR: Vec3 = Vec3::new(10_000.0, -10_000.0, 10_000.0);

fn moved(scene: Scene, by: Vec3) -> Scene {
    placed(scene, 1.0, by)
}

/// The scene with every point `p` at `s·p + by` and every length scaled by `s`; point lights' intensity by `s²`,
/// so that the radiance of every surface stays the same.
fn placed(scene: Scene, s: f32, by: Vec3) -> Scene {
    mapped(scene, |p| s * p + by, |x| s * x, s * s)
}

/// The scene with every coordinate rounded to a multiple of 1/128 and every length to 1/64: then every
/// coordinate of it moved 10⁵ away (where f32 spacing is 1/128), rectangle corners included, is exact, and the
/// scene there is the same geometry, to the bit.
fn snapped(scene: Scene) -> Scene {
    let snap = |k: f32| move |x: f32| (x * k).round() / k;
    mapped(scene, |p| p.map(snap(128.0)), snap(64.0), 1.0)
}

/// The scene with points mapped by `at`, lengths (and edge vectors, per axis) by `len`, and point lights'
/// intensity multiplied by `light`. Meshes only move (a mesh's scale is not a length here).
fn mapped(mut scene: Scene, at: impl Fn(Vec3) -> Vec3, len: impl Fn(f32) -> f32, light: f32) -> Scene {
    let at = |p: &mut Vec3| *p = at(*p);
    at(&mut scene.camera.eye);
    at(&mut scene.camera.look_at);
    scene.camera.focus_distance = scene.camera.focus_distance.map(&len);
    scene.camera.aperture = len(scene.camera.aperture);
    for o in &mut scene.objects {
        match o {
            Object::Sphere { center, radius, .. } => {
                at(center);
                *radius = len(*radius);
            }
            Object::Plane { point, .. } => at(point),
            Object::Rect { center, corner, width, height, u, v, .. } => {
                center.iter_mut().chain(corner.iter_mut()).for_each(at);
                width.iter_mut().chain(height.iter_mut()).for_each(|x| *x = len(*x));
                u.iter_mut().chain(v.iter_mut()).for_each(|e| *e = e.map(&len));
            }
            Object::Triangle { vertices, .. } => vertices.iter_mut().for_each(at),
            Object::Mesh { transform, .. } | Object::Gltf { transform, .. } => {
                let mut o = Vec3::ZERO;
                at(&mut o);
                transform.translate += o;
            }
        }
    }
    for l in &mut scene.lights {
        let LightSpec::Point { position, intensity, power } = l else { panic!("the scenes here have point lights") };
        at(position);
        intensity.iter_mut().chain(power.iter_mut()).for_each(|i| *i *= light);
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
        let mut tracer = Tracer::new(&prep, Sampler::for_pixel(1, i as u32, 0, 0));
        let l = photon_core::integrator::li(&mut tracer, Ray::new(eye, fmath::normalize(p - eye)));
        let d = Vec3A::new(0.5, 2.0, 0.0) - Vec3A::from_array(*target);
        let expected = 0.5 / std::f32::consts::PI * 4.0 * (d.y / d.length()) / d.length_squared();
        // Positions carry about 1e-3 of rounding 10,000 units out: allow for that in the geometry, not more.
        assert!((l.x - expected).abs() / expected < 0.01, "{l} vs {expected}");
    }
}

#[test]
fn cornell_box_far_away_and_scaled_is_as_bright_as_at_home() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut home = Scene::load(&path).unwrap();
    home.camera.width = 48;
    home.camera.height = 48;
    home.render.spp = 16;
    let mean = |s: &Scene| {
        let prep = Prepared::new(s, &path).unwrap().with_photon_maps(&path).unwrap();
        let img = render_image(&prep, &|_| {});
        img.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / img.pixels.len() as f64
    };
    let mut home = snapped(home);
    for integrator in [Method::Path, Method::Direct] {
        home.render.integrator = integrator;
        let a = mean(&home);
        for (s, by) in [(1.0, FAR), (1.0, 10.0 * FAR), (1e-3, Vec3::ZERO), (1e3, Vec3::ZERO)] {
            let b = mean(&placed(home.clone(), s, by));
            eprintln!("{integrator}: mean {a:.5} at home, {b:.5} scaled by {s:e} and moved by {by}");
            assert!((a - b).abs() / a < 0.01, "{integrator}: mean {a} at home, {b} scaled by {s} and moved by {by}");
        }
    }
}
