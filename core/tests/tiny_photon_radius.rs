//! A vanishing gather radius never gives NaN or Inf: below the floor (a millionth of the scene's size) it is
//! an error naming `render.photons.radius` (`render.photons.merge_radius` for vcm); at the floor, and even when the floor is bypassed, every photon
//! method renders a finite image.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::prepare::{MIN_RELATIVE_PHOTON_RADIUS, Prepared};
use photon_core::render::render_image;
use photon_core::scene::{Scene, SceneError};
use std::path::{Path, PathBuf};

/// The methods that gather photons, and `vcm`, which merges light vertices within `merge_radius`.
const PHOTON_METHODS: [Method; 4] = [Method::PhotonMap, Method::FinalGather, Method::Progressive, Method::Vcm];

fn cornell(integrator: Method, radius: f32) -> (Scene, PathBuf) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 8;
    scene.camera.height = 8;
    let r = &mut scene.render;
    r.integrator = integrator;
    r.spp = 1;
    r.photons.global = 2000;
    r.photons.caustic = 2000;
    r.photons.pass_photons = 2000;
    r.photons.passes = 4;
    r.photons.final_gather_rays = 2;
    r.photons.radius = Some(radius);
    r.photons.merge_radius = Some(radius);
    (scene, path)
}

fn assert_finite(scene: &Scene, prep: &Prepared, what: &str) {
    let img = render_image(prep, &|_| {});
    assert_eq!(img.pixels.len(), (scene.camera.width * scene.camera.height * 3) as usize);
    let bad = img.pixels.iter().filter(|v| !v.is_finite() || **v < 0.0).count();
    assert_eq!(bad, 0, "{what}: {bad} non-finite or negative values");
}

#[test]
fn radius_below_the_floor_is_an_error_naming_the_field() {
    for integrator in PHOTON_METHODS {
        for radius in [1e-25, 1e-30, 0.0] {
            let (scene, path) = cornell(integrator, radius);
            let e = Prepared::new(&scene, &path).unwrap_err();
            let name = if integrator == Method::Vcm { "render.photons.merge_radius" } else { "render.photons.radius" };
            assert!(matches!(&e, SceneError::Invalid { field, .. } if field == name), "{integrator} {radius:e}: {e}");
            assert!(e.to_string().contains(name), "{e}");
        }
    }
}

#[test]
fn radius_is_not_checked_for_methods_that_do_not_gather() {
    for integrator in [Method::Path, Method::Direct, Method::Bdpt, Method::Lt] {
        let (scene, path) = cornell(integrator, 1e-30);
        assert!(Prepared::new(&scene, &path).is_ok(), "{integrator}");
    }
}

#[test]
fn radius_at_the_floor_gives_a_finite_image() {
    // The Cornell box's bounded primitives span [-1, 1] × [0, 2] × [-1, 1]: diagonal 2√3.
    let floor = MIN_RELATIVE_PHOTON_RADIUS * 2.0 * 3f32.sqrt();
    for integrator in PHOTON_METHODS {
        let (scene, path) = cornell(integrator, floor * 1.01);
        let prep = Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap();
        assert_finite(&scene, &prep, &format!("{integrator} at the floor"));
    }
}

#[test]
fn estimators_stay_finite_when_the_floor_is_bypassed() {
    // The guards in the estimators themselves: a radius whose square underflows to 0 in f32.
    for integrator in PHOTON_METHODS {
        for radius in [1e-25, 1e-30] {
            let (scene, path) = cornell(integrator, 1.0);
            let mut prep = Prepared::new(&scene, &path).unwrap();
            prep.settings.photons.radius = Some(radius);
            prep.settings.photons.merge_radius = Some(radius);
            let prep = prep.with_photon_maps(&path).unwrap();
            assert_finite(&scene, &prep, &format!("{integrator} {radius:e}"));
        }
    }
}
