//! The small references in `scenes/references/` (made by `photon-coordinator reference`, see the README there)
//! are what the renderer converges to: for every shipped scene, the reference's own method with another seed has
//! an error that falls as its budget grows 4×, and a mean brightness within 2 % of the reference's.
//!
//! A change that makes a method converge to another image (darker, brighter, a lost light path) fails here.

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_core::method::Method;
use photon_core::metrics::compare;
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::Path;

/// Renders `scene` at the reference's size with `integrator` at budget `b` (spp or passes).
fn render(name: &str, integrator: Method, b: u32) -> Image {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let path = dir.join(format!("{name}.toml"));
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 32;
    scene.camera.height = 32;
    scene.render.seed = 77; // not the reference's seed (0x5EED) nor the scenes' (1)
    scene.render.integrator = integrator;
    scene.render.spp = b;
    scene.render.photons.passes = b;
    scene.render.photons.pass_photons = 25_000;
    let prep = Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap();
    Image { width: 32, height: 32, pixels: render_image(&prep, &|_| {}).pixels }
}

fn check(name: &str, integrator: Method, budgets: [u32; 2]) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/references");
    let reference = Image::read(&dir.join(format!("{name}-32.exr"))).unwrap();
    let [lo, hi] = budgets.map(|b| compare(&render(name, integrator, b), &reference, None).unwrap());
    eprintln!(
        "{name} {integrator}: relMSE {:.5} -> {:.5}, rel. bias {:+.4} -> {:+.4}",
        lo.rel_mse,
        hi.rel_mse,
        lo.rel_bias.unwrap(),
        hi.rel_bias.unwrap()
    );
    assert!(hi.rel_mse < lo.rel_mse, "{name} {integrator}: error did not fall: {} -> {}", lo.rel_mse, hi.rel_mse);
    let bias = hi.rel_bias.unwrap();
    assert!(bias.abs() < 0.02, "{name} {integrator}: mean {:+.2} % off the reference", 100.0 * bias);
}

#[test]
fn path_traced_references() {
    check("cornell", Method::Path, [64, 256]);
    check("mesh", Method::Path, [64, 256]);
}

#[test]
fn progressive_references_of_point_light_caustics() {
    check("cornell-point", Method::Progressive, [8, 32]);
    check("caustic-point", Method::Progressive, [8, 32]);
}

/// Textures, a bump map and a normal map: the path tracer converges to the reference, and progressive photon
/// mapping (photons bouncing off the textured, bumped and normal-mapped surfaces, with the adjoint BSDF) converges
/// to the path tracer's image.
#[test]
fn textured_reference() {
    check("textured", Method::Path, [64, 256]);
    check("textured", Method::Progressive, [8, 32]);
}
