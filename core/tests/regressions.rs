//! The regression scenes of `scenes/regressions/` (issue 16), each at a small size, with the value it must give.
//! `cargo test -p photon-core --test regressions -- --nocapture` prints the values listed in docs/RESULTS.md.

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::{Scene, SceneError};
use std::path::PathBuf;

fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/regressions").join(name)
}

/// The red channel of `name` rendered at `size`×`size` with `spp` samples.
fn render(name: &str, size: u32, spp: u32) -> Vec<f32> {
    let path = path(name);
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = size;
    scene.camera.height = size;
    scene.render.spp = spp;
    let prep = Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap();
    render_image(&prep, &|_| {}).pixels.chunks_exact(3).map(|p| p[0]).collect()
}

fn mean(v: &[f32]) -> f64 {
    v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64
}

#[test]
fn glass_cube_in_a_furnace_is_one_everywhere() {
    let px = render("glass-cube-furnace.toml", 24, 16);
    let worst = px.iter().map(|&v| (f64::from(v) - 1.0).abs()).fold(0.0, f64::max);
    eprintln!("glass-cube-furnace: mean {:.5}, largest |pixel - 1| {worst:.5}", mean(&px));
    assert!(worst < 0.01, "a pixel is {worst} away from 1");
}

#[test]
fn sphere_floor_matches_the_plane() {
    let size = 32;
    let rows = 8 * size as usize;
    let sphere = render("sphere-floor.toml", size, 8);
    let plane = render("plane-floor.toml", size, 8);
    let (s, p) = (mean(&sphere[sphere.len() - rows..]), mean(&plane[plane.len() - rows..]));
    eprintln!("sphere-floor: bottom rows {s:.4}, plane-floor {p:.4}");
    assert!((s / p - 1.0).abs() < 0.01, "sphere floor {s} vs plane {p}");
}

#[test]
fn concave_face_renders_as_its_triangles() {
    let face = render("l-face.toml", 32, 2);
    let tris = render("l-triangles.toml", 32, 2);
    let differ = face.iter().zip(&tris).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
    eprintln!("l-face: {differ} pixels differ from l-triangles, mean {:.4}", mean(&face));
    assert_eq!(differ, 0);
    assert!(mean(&face) > 0.0);
}

#[test]
fn tiny_progressive_radius_is_refused_by_name() {
    let path = path("tiny-radius.toml");
    let scene = Scene::load(&path).unwrap();
    let e = Prepared::new(&scene, &path).unwrap_err();
    eprintln!("tiny-radius: {e}");
    assert!(matches!(&e, SceneError::Invalid { field, .. } if field == "render.photons.radius"), "{e}");
}
