//! The image does not depend on threads or strips: 1 thread × 1 strip and 4 threads × 7 strips give the same
//! bytes.

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::render::render_rows;
use photon_core::scene::Scene;
use std::path::Path;

fn cornell() -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 40;
    scene.camera.height = 30;
    scene.render.spp = 4;
    scene.render.integrator = photon_core::method::Method::Path;
    Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn threads_and_strips_do_not_change_a_pixel() {
    let prep = cornell();
    let h = prep.camera.height;
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let whole = one.install(|| render_rows(&prep, 0..h, &|_| {}));
    let four = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
    let bounds = [0, 3, 4, 11, 17, 18, 26, h];
    let mut stitched = Vec::new();
    for w in bounds.windows(2) {
        let strip = four.install(|| render_rows(&prep, w[0]..w[1], &|_| {}));
        assert_eq!(strip.rows, w[0]..w[1]);
        stitched.extend(strip.pixels);
    }
    assert_eq!(bits(&whole.pixels), bits(&stitched));
    assert!(whole.pixels.iter().any(|&v| v > 0.0));
}

#[test]
fn photon_methods_do_not_depend_on_strips_either() {
    use photon_core::method::Method;
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    for integrator in [Method::Progressive, Method::PhotonMap, Method::Vcm, Method::Bdpt, Method::Lt] {
        let mut scene = Scene::load(&path).unwrap();
        scene.camera.width = 16;
        scene.camera.height = 12;
        scene.render.integrator = integrator;
        scene.render.spp = 2;
        scene.render.photons.global = 5_000;
        scene.render.photons.pass_photons = 5_000;
        scene.render.photons.passes = 3;
        let prep = Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let whole = one.install(|| render_rows(&prep, 0..12, &|_| {}));
        let three = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let mut stitched = Vec::new();
        for rows in [0..5, 5..6, 6..12] {
            stitched.extend(three.install(|| render_rows(&prep, rows, &|_| {})).pixels);
        }
        assert_eq!(bits(&whole.pixels), bits(&stitched), "{integrator}");
    }
}
