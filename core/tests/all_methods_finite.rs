//! Every method on every shipped scene, the stress scenes of `scenes/stress/` included, gives a finite,
//! non-negative image.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::Path;

#[test]
fn no_nan_inf_or_negative_pixel() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut scenes: Vec<_> = [dir.clone(), dir.join("stress")]
        .iter()
        .flat_map(|d| std::fs::read_dir(d).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    scenes.sort();
    assert!(scenes.iter().filter(|p| p.parent().is_some_and(|d| d.ends_with("stress"))).count() >= 12);
    assert!(scenes.len() >= 16);
    for path in &scenes {
        for integrator in Method::ALL {
            let mut scene = Scene::load(path).unwrap();
            scene.camera.width = 12;
            scene.camera.height = 10;
            let r = &mut scene.render;
            r.integrator = integrator;
            r.spp = 2;
            // Keep the stress scenes' own tiny photon counts; cap the others for speed.
            r.photons.global = r.photons.global.min(5_000);
            r.photons.caustic = r.photons.caustic.min(5_000);
            r.photons.pass_photons = r.photons.pass_photons.min(5_000);
            r.photons.passes = 2;
            r.photons.final_gather_rays = 4;
            let prep = Prepared::new(&scene, path).unwrap().with_photon_maps(path).unwrap();
            let img = render_image(&prep, &|_| {});
            let bad = img.pixels.iter().filter(|v| !v.is_finite() || **v < 0.0).count();
            assert_eq!(bad, 0, "{}: {integrator}: {bad} bad values", path.display());
            // A point light inside a glass sphere reaches the room only through refraction: camera paths never
            // find it (a delta light behind a delta surface), so direct lighting and the path tracer see black
            // there; the photon methods see it (the stress suite's point).
            let camera_only = matches!(integrator, Method::Direct | Method::Path);
            // A gather radius of 0.0005 in a map of 5 000 photons finds none from 240 samples: the photon map
            // seen directly is rightly black at this size (the stress suite renders it at full size).
            let no_gather = integrator == Method::PhotonMap && path.ends_with("small-radius.toml");
            let unlit = (camera_only && path.ends_with("light-in-glass.toml")) || no_gather;
            if !unlit {
                assert!(img.pixels.iter().any(|&v| v > 0.0), "{}: {integrator}: black image", path.display());
            }
        }
    }
}
