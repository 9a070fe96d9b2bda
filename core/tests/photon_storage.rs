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

/// The smallest storage bound under which `block` renders.
fn least_bound(prep: &Prepared, block: &Block) -> u64 {
    let (mut fails, mut fits) = (0u64, 1u64 << 32);
    assert!(render_block(prep, block, &|_| {}, &guard(fits)).is_ok());
    while fits - fails > 1 {
        let mid = fails + (fits - fails) / 2;
        match render_block(prep, block, &|_| {}, &guard(mid)) {
            Ok(_) => fits = mid,
            Err(RunError::Storage(_)) => fails = mid,
            Err(e) => panic!("{e}"),
        }
    }
    fits
}

#[test]
fn a_block_fits_the_bound_its_largest_pass_fits_whatever_the_threads() {
    // Passes are traced side by side and ahead of the gather; a block must still render under the bound that
    // its largest pass alone needs, with the bits of an unbounded render, and fail one byte below it.
    for integrator in [Method::Progressive, Method::Vcm] {
        let prep = room(integrator);
        let rows = 0..prep.camera.height;
        let alone: Vec<u64> =
            (0..3).map(|p| least_bound(&prep, &Block { rows: rows.clone(), units: p..p + 1 })).collect();
        let largest = *alone.iter().max().unwrap();
        let block = Block { rows: rows.clone(), units: 0..3 };
        let unbounded = render_block(&prep, &block, &|_| {}, &Guard::unbounded()).unwrap();
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let fits = pool.install(|| render_block(&prep, &block, &|_| {}, &guard(largest)));
            let fits = fits.unwrap_or_else(|e| panic!("{integrator}, {threads} threads, {alone:?}: {e}"));
            assert_eq!(fits.sums, unbounded.sums, "{integrator}, {threads} threads");
            let over = pool.install(|| render_block(&prep, &block, &|_| {}, &guard(largest - 1)));
            assert!(matches!(over, Err(RunError::Storage(_))), "{integrator}, {threads} threads");
        }
        // Two passes side by side would not fit: the bound is below the sum of any two.
        assert!(alone.iter().all(|&b| b + alone.iter().min().unwrap() > largest), "{alone:?}");
    }
}
