//! A huge sphere used as a floor (issue 16): a sphere of radius R centred R below the origin must light like
//! the plane y = 0 it approximates. A ball of radius 0.5 stands on it, lit by a point light at (1, 3, 1).
//! Self-intersection of shadow rays (acne) made the floor 30 % too dark at R = 1000.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::Path;

/// The image, as (width, height, luminance-free red channel), of the scene with the floor `floor` (a TOML
/// object) seen from `eye` towards `look_at`.
fn render(floor: &str, integrator: Method, eye: [f32; 3], look_at: [f32; 3], fov: f32) -> (usize, Vec<f32>) {
    let width = 32usize;
    let text = format!(
        r#"
[camera]
eye = {eye:?}
look_at = {look_at:?}
fov = {fov}
width = {width}
height = {width}

[render]
spp = 8
max_depth = 5
integrator = "{integrator}"

[materials.white]
type = "lambert"
albedo = 0.8

[[objects]]
{floor}
material = "white"

[[objects]]
type = "sphere"
center = [0.0, 0.5, 0.0]
radius = 0.5
material = "white"

[[lights]]
type = "point"
position = [1.0, 3.0, 1.0]
intensity = [10.0, 10.0, 10.0]
"#
    );
    let scene = Scene::parse(&text, Path::new("floor.toml")).unwrap();
    let prep = Prepared::new(&scene, Path::new("floor.toml")).unwrap();
    let img = render_image(&prep, &|_| {});
    (width, img.pixels.chunks_exact(3).map(|p| p[0]).collect())
}

fn plane() -> String {
    "type = \"plane\"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 1.0, 0.0]".into()
}

/// The floor sphere of radius `r` touching y = 0 at (x, 0, z).
fn sphere_at(r: f64, x: f64, z: f64) -> String {
    format!("type = \"sphere\"\ncenter = [{x:?}, {:?}, {z:?}]\nradius = {r:?}", -r)
}

fn sphere(r: f64) -> String {
    sphere_at(r, 0.0, 0.0)
}

fn mean(v: &[f32]) -> f64 {
    v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64
}

#[test]
fn oblique_view_of_the_floor_matches_the_plane() {
    // The bottom eight rows: floor only, in front of the ball, partly in its shadow.
    for integrator in [Method::Direct, Method::Path] {
        let view = |floor: &str| render(floor, integrator, [0.0, 1.0, 4.0], [0.0, 0.3, 0.0], 45.0);
        let (w, p) = view(&plane());
        let reference = mean(&p[p.len() - 8 * w..]);
        for r in [1e3, 1e4, 1e5, 1e6] {
            let (w, s) = view(&sphere(r));
            let m = mean(&s[s.len() - 8 * w..]);
            eprintln!("{integrator} R = {r:e}: floor {m:.4}, plane {reference:.4}");
            assert!((m / reference - 1.0).abs() < 0.01, "{integrator} R = {r:e}: {m} vs plane {reference}");
        }
    }
}

#[test]
fn floor_under_the_light_matches_the_plane_for_every_radius() {
    // Looking straight down at a patch 0.1 wide under the light, at the top of the floor sphere (centred under
    // it), where even R = 10 is flat to 0.1 %.
    for integrator in [Method::Direct, Method::Path] {
        let view = |floor: &str| render(floor, integrator, [1.0, 1.0, 1.0], [1.0, 0.0, 1.001], 5.7);
        let reference = mean(&view(&plane()).1);
        for r in [10.0, 1e2, 1e3, 1e4, 1e5, 1e6] {
            let m = mean(&view(&sphere_at(r, 1.0, 1.0)).1);
            eprintln!("{integrator} R = {r:e}: patch {m:.5}, plane {reference:.5}");
            assert!((m / reference - 1.0).abs() < 0.01, "{integrator} R = {r:e}: {m} vs plane {reference}");
        }
    }
}
