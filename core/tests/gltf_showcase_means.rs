//! The shipped glTF scene (`scenes/gltf-showcase.toml`: the glTF file's rough gold, rough glass and smooth glass
//! on a textured floor, its spot and point lights, under the HDR sky) through the unbiased and consistent
//! methods: the image means of vcm and progressive agree with bdpt's within 0.5 %. The path tracer's is lower by
//! the caustics the delta lights cast through the smooth glass, which no camera path can complete (0.6 %).

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
fn vcm_agrees_with_bdpt_and_the_path_tracer_lacks_only_the_point_caustics() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/gltf-showcase.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 48;
    scene.camera.height = 32;
    let reference = mean(&scene, &path, Method::Bdpt, 2048);
    for (integrator, budget) in [(Method::Vcm, 2048), (Method::Progressive, 1024)] {
        let m = mean(&scene, &path, integrator, budget);
        let rel = m / reference - 1.0;
        eprintln!("glTF showcase, {integrator}: {m:.5} against bdpt {reference:.5} ({:+.2} %)", 100.0 * rel);
        assert!(rel.abs() < 0.005, "{integrator}: mean {m} against bdpt's {reference} ({:+.2} %)", 100.0 * rel);
    }
    // The spot and point lights' caustics through the smooth glass sphere are paths a camera path can only end
    // by hitting a point: the path tracer converges to the image without them, a little darker.
    let m = mean(&scene, &path, Method::Path, 8192);
    let rel = m / reference - 1.0;
    eprintln!("glTF showcase, path: {m:.5} against bdpt {reference:.5} ({:+.2} %)", 100.0 * rel);
    assert!((-0.015..0.0).contains(&rel), "path: mean {m} against bdpt's {reference} ({:+.2} %)", 100.0 * rel);
}
