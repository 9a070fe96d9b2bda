//! The shipped glTF scene (`scenes/gltf-showcase.toml`: the glTF file's rough gold, rough glass and smooth glass
//! on a normal-mapped textured floor, a cut-out lattice, its spot light, under the HDR sky) through the unbiased
//! and consistent methods: the image means of path, vcm and progressive agree with bdpt's within 0.5 %. The spot's
//! cone leaves the smooth glass out: a point-like light's caustic through smooth glass is a path no camera path
//! can complete, which made the path tracer 0.6 % dark on the scene's first version.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::scene::Scene;
use std::path::PathBuf;

mod common;

/// The image mean of `scene` by `integrator` at `budget` ([`common::render_method`]).
fn mean(scene: &Scene, path: &std::path::Path, integrator: Method, budget: u32) -> f64 {
    common::image_mean(&common::render_method(scene, path, integrator, budget))
}

#[test]
fn path_vcm_and_progressive_agree_with_bdpt() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/gltf-showcase.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 48;
    scene.camera.height = 32;
    let reference = mean(&scene, &path, Method::Bdpt, 2048);
    for (integrator, budget) in [(Method::Path, 8192), (Method::Vcm, 2048), (Method::Progressive, 1024)] {
        let m = mean(&scene, &path, integrator, budget);
        let rel = m / reference - 1.0;
        eprintln!("glTF showcase, {integrator}: {m:.5} against bdpt {reference:.5} ({:+.2} %)", 100.0 * rel);
        assert!(rel.abs() < 0.005, "{integrator}: mean {m} against bdpt's {reference} ({:+.2} %)", 100.0 * rel);
    }
}
