//! Spot, directional and environment lights against closed-form answers, through every method:
//! - a constant environment of radiance L around a white Lambert sphere: every pixel is L (the sphere is convex,
//!   so it sees only the environment: `Lo = ρ/π · πL`);
//! - an environment image bright (L) over one half of the upper hemisphere and black elsewhere, over a Lambert
//!   plane of albedo ρ: `E = πL/2`, so `Lo = ρL/2`;
//! - a spot light and a directional light over a Lambert plane: `E = I·s(cos α)·cos θ/r² + E⊥·cos θ_d`, with
//!   `s` the smoothstep falloff, checked ray by ray for the per-ray methods and as image means for all.

#![allow(clippy::unwrap_used)]

use glam::{Vec2, Vec3A};
use photon_core::image_io::Image;
use photon_core::math::fmath;
use photon_core::math::rng::Sampler;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::prepare::tracer::Tracer;
use photon_core::scene::Scene;
use std::f32::consts::PI;
use std::path::Path;

mod common;

use common::render_method as render;

/// The mean over pixels `xs × ys` of every channel.
fn mean_over(image: &Image, xs: std::ops::Range<u32>, ys: std::ops::Range<u32>) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in ys {
        for x in xs.clone() {
            for c in 0..3 {
                sum += f64::from(image.pixels[3 * (y * image.width + x) as usize + c]);
                n += 1;
            }
        }
    }
    sum / n as f64
}

/// Every method, with a budget that brings it within the tolerances below on these small images, and its
/// tolerance: the unbiased methods 1 %, the photon methods (biased by their radius and, for photon-map, by
/// the density estimate at the first bounce) 2–4 %.
const METHODS: [(Method, u32, f64); 8] = [
    (Method::Path, 64, 0.01),
    (Method::Direct, 64, 0.01),
    (Method::Bdpt, 64, 0.01),
    (Method::Vcm, 64, 0.01),
    (Method::Lt, 64, 0.015),
    (Method::PhotonMap, 16, 0.04),
    (Method::FinalGather, 16, 0.02),
    (Method::Progressive, 32, 0.02),
];

const SPHERE: &str = r#"
[camera]
eye = [0.0, 0.0, 3.0]
look_at = [0.0, 0.0, 0.0]
fov = 40.0
width = 16
height = 16

[render]
max_depth = 16

[render.photons]
global = 200000
caustic = 0
pass_photons = 50000

[materials.white]
type = "lambert"
albedo = 1.0

[[objects]]
type = "sphere"
center = [0.0, 0.0, 0.0]
radius = 0.9
material = "white"

[[lights]]
type = "environment"
radiance = [0.5, 0.5, 0.5]
"#;

#[test]
fn a_constant_environment_around_a_white_sphere_is_its_radiance_in_every_pixel() {
    let path = Path::new("env-sphere.toml");
    let scene = Scene::parse(SPHERE, path).unwrap();
    for (integrator, budget, tolerance) in METHODS {
        let image = render(&scene, path, integrator, budget);
        // The sphere covers the central 8 × 8 pixels; the corners see the environment itself.
        let sphere = mean_over(&image, 4..12, 4..12);
        let corner = mean_over(&image, 0..2, 0..2);
        eprintln!("constant environment, {integrator}: sphere {sphere:.4}, corner {corner:.4} (expected 0.5)");
        assert!((corner - 0.5).abs() < 1e-6, "{integrator}: the environment seen directly is {corner}");
        assert!((sphere / 0.5 - 1.0).abs() < tolerance, "{integrator}: sphere {sphere}, expected 0.5 ± {tolerance}");
    }
}

/// An equirectangular PNG of `w × h` white texels where `bright(u, v)` and black elsewhere, in a fresh
/// directory.
fn sky_png(name: &str, w: u32, h: u32, bright: impl Fn(f32, f32) -> bool) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-lights-analytic-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let img = image::RgbImage::from_fn(w, h, |i, j| {
        let (u, v) = ((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32);
        if bright(u, v) { image::Rgb([255, 255, 255]) } else { image::Rgb([0, 0, 0]) }
    });
    img.save(dir.join("sky.png")).unwrap();
    dir
}

fn plane_scene(lights: &str) -> String {
    format!(
        r#"
[camera]
eye = [0.0, 3.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, -1.0]
fov = 40.0
width = 16
height = 16

[render]
max_depth = 8

[render.photons]
global = 400000
caustic = 0
pass_photons = 100000

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "rect"
center = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
width = 12.0
height = 12.0
material = "grey"
{lights}
"#
    )
}

#[test]
fn half_a_bright_upper_hemisphere_gives_half_the_irradiance_of_a_whole_one() {
    // Bright over the upper hemisphere (v < ½) where the azimuth is negative (u < ½): radiance 2 there.
    let dir = sky_png("half", 64, 32, |u, v| u < 0.5 && v < 0.5);
    for rotate in [0.0, 137.0] {
        let text = plane_scene(&format!(
            "[[lights]]\ntype = \"environment\"\nimage = \"sky.png\"\nscale = 2.0\nrotate = {rotate}\n"
        ));
        let path = dir.join("half-sky.toml");
        let scene = Scene::parse(&text, &path).unwrap();
        // ρ/π · πL/2 = 0.5 · 2 / 2.
        let expected = 0.5;
        for (integrator, budget, tolerance) in METHODS {
            let image = render(&scene, &path, integrator, budget);
            let m = mean_over(&image, 0..16, 0..16);
            eprintln!("half-bright sky, rotated {rotate}°, {integrator}: {m:.4} (expected {expected})");
            assert!((m / expected - 1.0).abs() < tolerance, "{integrator}, rotated {rotate}°: {m} vs {expected}");
        }
    }
}

const SPOT: [f32; 3] = [0.4, 2.0, -0.3];
const SPOT_AXIS: [f32; 3] = [0.2, -1.0, 0.1];
const SUN: [f32; 3] = [0.5, -1.0, 0.3];

const SPOT_LIGHT: &str = r#"
[[lights]]
type = "spot"
position = [0.4, 2.0, -0.3]
direction = [0.2, -1.0, 0.1]
intensity = [6.0, 4.0, 2.0]
inner_angle = 15.0
outer_angle = 35.0
"#;

const SUN_LIGHT: &str = r#"
[[lights]]
type = "directional"
direction = [0.5, -1.0, 0.3]
irradiance = [0.03, 0.05, 0.07]
"#;

fn spot_and_sun() -> String {
    plane_scene(&format!("{SPOT_LIGHT}{SUN_LIGHT}"))
}

/// The radiance leaving the plane's point `p` towards the camera from the spot light: ρ/π times its
/// irradiance there.
fn spot_radiance(p: Vec3A) -> Vec3A {
    let light = Vec3A::from(SPOT);
    let d = light - p;
    let r2 = d.length_squared();
    let w = fmath::normalize(d);
    let cos_axis = (-w).dot(fmath::normalize(Vec3A::from(SPOT_AXIS)));
    let (cos_outer, cos_inner) = (fmath::cos(35.0f32.to_radians()), fmath::cos(15.0f32.to_radians()));
    let t = ((cos_axis - cos_outer) / (cos_inner - cos_outer)).clamp(0.0, 1.0);
    let falloff = t * t * (3.0 - 2.0 * t);
    0.5 / PI * Vec3A::new(6.0, 4.0, 2.0) * falloff * w.y / r2
}

/// The same for the directional light (the same everywhere).
fn sun_radiance() -> Vec3A {
    0.5 / PI * Vec3A::new(0.03, 0.05, 0.07) * (-fmath::normalize(Vec3A::from(SUN))).y
}

#[test]
fn a_spot_and_a_directional_light_give_their_analytic_radiance_ray_by_ray() {
    let eye = Vec3A::new(0.0, 3.0, 0.0);
    // Inside the full cone, in the falloff (twice), outside the cone.
    let targets = [[0.8, 0.0, -0.1], [0.4, 0.0, 0.6], [1.3, 0.0, -0.8], [-1.5, 0.0, 0.2], [0.0, 0.0, -1.6]];
    let full = spot_radiance(Vec3A::new(0.8, 0.0, -0.1)).x;
    let in_falloff =
        targets.iter().filter(|t| (0.01 * full..0.9 * full).contains(&spot_radiance(Vec3A::from_array(**t)).x));
    assert!(in_falloff.count() >= 2, "the targets miss the falloff");
    assert_eq!(spot_radiance(Vec3A::new(-1.5, 0.0, 0.2)), Vec3A::ZERO, "a target lies outside the cone");
    for (lights, name) in [(SPOT_LIGHT, "spot"), (SUN_LIGHT, "directional")] {
        let path = Path::new("one-light.toml");
        let scene = Scene::parse(&plane_scene(lights), path).unwrap();
        let prep = Prepared::new(&scene, path).unwrap();
        for integrator in [Method::Direct, Method::Path] {
            let mut prep = prep.clone();
            prep.settings.integrator = integrator;
            for (i, target) in targets.iter().enumerate() {
                let p = Vec3A::from_array(*target);
                let ray = photon_core::math::Ray::new(eye, fmath::normalize(p - eye));
                let mut tracer = Tracer::new(&prep, Sampler::for_pixel(1, i as u32, 0, 0));
                let l = photon_core::integrator::li(&mut tracer, ray);
                let expected = if name == "spot" { spot_radiance(p) } else { sun_radiance() };
                let err = (l - expected).abs().max_element();
                assert!(err <= 1e-4 * expected.max_element(), "{name}, {integrator:?} at {p}: {l} vs {expected}");
            }
        }
    }
}

/// Both lights together at `p`.
fn analytic(p: Vec3A) -> Vec3A {
    spot_radiance(p) + sun_radiance()
}

#[test]
fn every_method_gives_the_analytic_image_of_a_spot_and_a_directional_light() {
    let path = Path::new("spot.toml");
    let scene = Scene::parse(&spot_and_sun(), path).unwrap();
    let prep = Prepared::new(&scene, path).unwrap();
    // The analytic image at the pixels' centres (the plane is smooth enough that a pixel's mean is its
    // centre's value to well under the tolerances).
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut expected = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let ray = prep.camera.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), Vec2::splat(0.5));
            let p = ray.at(-ray.o.y / ray.d.y);
            expected += analytic(p).to_array().iter().map(|&c| f64::from(c)).sum::<f64>();
        }
    }
    expected /= f64::from(3 * w * h);
    // More budget: the spot, a fifth of the power, is chosen for a fifth of the light samples and light
    // subpaths (by power), and the sun's light subpaths leave a disc 50 times the view's area (light tracing
    // sees the plane only through them).
    for (integrator, budget, tolerance) in METHODS {
        let more = if integrator == Method::Lt { 16 } else { 4 };
        let m = mean_over(&render(&scene, path, integrator, more * budget), 0..w, 0..h);
        eprintln!("spot and sun, {integrator}: {m:.5} (expected {expected:.5})");
        assert!((m / expected - 1.0).abs() < tolerance, "{integrator}: {m} vs {expected}");
    }
}
