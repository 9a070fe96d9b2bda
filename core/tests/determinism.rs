//! The image does not depend on threads or strips: 1 thread × 1 strip and 4 threads × 7 strips give the same
//! bytes.

use photon_core::prepare::Prepared;
use photon_core::render::render_strip;
use photon_core::scene::Scene;
use std::path::Path;

fn cornell() -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 40;
    scene.camera.height = 30;
    scene.render.spp = 4;
    Prepared::new(&scene, &path).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn threads_and_strips_do_not_change_a_pixel() {
    let prep = cornell();
    let h = prep.camera.height;
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let whole = one.install(|| render_strip(&prep, 0..h, &prep.settings, &|_| {}));
    let four = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
    let bounds = [0, 3, 4, 11, 17, 18, 26, h];
    let mut stitched = Vec::new();
    for w in bounds.windows(2) {
        let strip = four.install(|| render_strip(&prep, w[0]..w[1], &prep.settings, &|_| {}));
        assert_eq!(strip.rows, w[0]..w[1]);
        stitched.extend(strip.pixels);
    }
    assert_eq!(bits(&whole.pixels), bits(&stitched));
    assert!(whole.pixels.iter().any(|&v| v > 0.0));
}
