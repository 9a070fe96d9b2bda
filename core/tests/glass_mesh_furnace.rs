//! White furnace with closed glass meshes (issue 16): a closed dielectric (η = 1.5) inside a sphere that emits
//! radiance 1 on both sides and reflects nothing. Glass absorbs nothing, so every camera path leaves the mesh
//! with its throughput intact and every pixel is 1. A cube from an OBJ without normals, with the default crease
//! angle (its 90° edges stay sharp) and flat: every pixel 1 within 1 %. (Normals averaged across the cube's
//! edges, as before the crease angle, gave a mean of 0.882 here, with pixels at 0.)

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::{Path, PathBuf};

/// An 8-vertex cube `v ±1 ±1 ±1` with six outward quads and no normals.
const CUBE: &str = "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
                    f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("photon-glass-furnace-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Every pixel of the furnace around the mesh `obj` (a path), with the mesh's extra fields `extra`.
fn furnace(name: &str, obj: &Path, extra: &str, transform: &str) -> Vec<f32> {
    let text = format!(
        r#"
[camera]
eye = [0.3, 0.4, 4.0]
look_at = [0.0, 0.0, 0.0]
fov = 40.0
width = 24
height = 24

[render]
spp = 16
max_depth = 200
integrator = "path"

[materials.glass]
type = "dielectric"
eta = 1.5

[materials.black]
type = "lambert"
albedo = 0.0

[[objects]]
type = "sphere"
center = [0.0, 0.0, 0.0]
radius = 10.0
material = "black"
emission = {{ radiance = [1.0, 1.0, 1.0], two_sided = true }}

[[objects]]
type = "mesh"
file = "{}"
material = "glass"
{transform}
{extra}
"#,
        obj.display()
    );
    let path = dir().join(format!("{name}.toml"));
    std::fs::write(&path, &text).unwrap();
    let scene = Scene::load(&path).unwrap();
    let prep = Prepared::new(&scene, &path).unwrap();
    render_image(&prep, &|_| {}).pixels
}

fn check(name: &str, pixels: &[f32]) {
    let mean = pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / pixels.len() as f64;
    let worst = pixels.iter().map(|&v| (f64::from(v) - 1.0).abs()).fold(0.0, f64::max);
    eprintln!("{name}: mean {mean:.5}, largest |pixel − 1| {worst:.5}");
    assert!(worst < 0.01, "{name}: a pixel is {worst} away from 1 (mean {mean})");
}

fn cube_file() -> PathBuf {
    let p = dir().join("cube.obj");
    std::fs::write(&p, CUBE).unwrap();
    p
}

#[test]
fn glass_cube_without_normals_default_crease() {
    check("cube, crease 30°", &furnace("cube-crease", &cube_file(), "", ""));
}

#[test]
fn glass_cube_without_normals_flat() {
    check("cube, flat", &furnace("cube-flat", &cube_file(), "smooth = false", ""));
}
