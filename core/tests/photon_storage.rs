//! A valid scene whose photon paths never end by roulette (a closed room of albedo 1,
//! `scenes/stress/white-room.toml`) stores a photon at every bounce up to `render.max_depth`: many times the
//! few per path that the memory estimate assumes. Tracing then stops at its storage bound with an error that
//! names the settings to change, for the static maps, progressive's passes and vcm's light subpaths alike;
//! and the bound trips exactly when the whole run would pass it, whatever the threads.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::photon::PhotonMapError;
use photon_core::prepare::Prepared;
use photon_core::prepare::budget::{BYTES_PER_PHOTON, PHOTONS_PER_PATH};
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use photon_core::render::{Block, render_block};
use photon_core::run::{Guard, NEVER, RunError};
use photon_core::scene::Scene;
use std::path::Path;

fn room(integrator: Method) -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/stress/white-room.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.render.integrator = integrator;
    scene.render.photons.global = 4_000;
    scene.render.photons.pass_photons = 4_000;
    scene.camera.width = 16;
    scene.camera.height = 16;
    Prepared::new(&scene, &path).unwrap()
}

fn guard(bytes: u64) -> Guard<'static> {
    Guard { cancel: &NEVER, storage_bytes: bytes }
}

#[test]
fn the_white_room_stores_a_photon_at_every_bounce() {
    let prep = room(Method::PhotonMap);
    let traced = trace_photons(&prep, 4_000, 0, PhotonKind::Global);
    let per_path = traced.photons.len() as f64 / traced.paths as f64;
    // Every path runs to max_depth = 64 and stores at each of its bounces.
    assert!(per_path > 60.0, "{per_path} photons per path");
    assert!(per_path > 10.0 * PHOTONS_PER_PATH as f64, "{per_path} photons per path");
}

#[test]
fn static_maps_stop_at_their_bound_exactly_and_whatever_the_threads() {
    let prep = room(Method::PhotonMap);
    let stored = trace_photons(&prep, 4_000, 0, PhotonKind::Global).photons.len() as u64;
    let exact = stored * BYTES_PER_PHOTON;
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let fits = pool.install(|| prep.build_photon_maps(&guard(exact)));
        assert!(fits.is_ok(), "{threads} threads: {:?}", fits.err());
        let over = pool.install(|| prep.build_photon_maps(&guard(exact - 1)));
        let Err(PhotonMapError::Run(RunError::Storage(e))) = over else { panic!("{threads} threads: {over:?}") };
        let msg = e.to_string();
        assert!(msg.contains("render.max_depth = 64") && msg.contains("render.photons.global"), "{msg}");
    }
}

#[test]
fn passes_and_light_subpaths_stop_at_their_bound() {
    // The estimate's bound for one pass (4 photons per path) is far below what a pass of this room stores.
    for (integrator, setting) in
        [(Method::Progressive, "render.photons.pass_photons"), (Method::Vcm, "camera.width × camera.height")]
    {
        let prep = room(integrator);
        let block = Block { rows: 0..prep.camera.height, units: 0..2 };
        let bound = 4_000 * PHOTONS_PER_PATH * BYTES_PER_PHOTON;
        let out = render_block(&prep, &block, &|_| {}, &guard(bound));
        let Err(RunError::Storage(e)) = out else { panic!("{integrator}: {:?}", out.map(|b| b.rays)) };
        assert!(e.to_string().contains(setting), "{integrator}: {e}");
        // With room enough, the same block renders.
        assert!(render_block(&prep, &block, &|_| {}, &Guard::unbounded()).is_ok(), "{integrator}");
    }
}
