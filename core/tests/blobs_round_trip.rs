//! A prepared scene sent as blobs (scene, photons, frame) renders the same bytes as the original, for a method
//! with photon maps and for progressive photon mapping, cut into strips anywhere; a cancelled render stops.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::render::sums::MAX_BLOCK_UNITS;
use photon_core::render::{Block, job_units, render_block, render_rows};
use photon_core::run::{Cancel, Guard, RunError};
use photon_core::scene::Scene;
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

fn cornell(integrator: Method) -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 24;
    scene.camera.height = 18;
    scene.render.spp = 2;
    scene.render.integrator = integrator;
    scene.render.photons.global = 5_000;
    scene.render.photons.pass_photons = 2_000;
    scene.render.photons.passes = 3;
    Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn blobs_render_the_same_bytes() {
    for integrator in [Method::FinalGather, Method::Progressive] {
        let prep = cornell(integrator);
        let scene = prep.encode_scene().unwrap();
        let photons = prep.encode_photons().unwrap();
        let frame = prep.encode_frame().unwrap();
        assert_eq!(photons.is_some(), integrator == Method::FinalGather);
        let back = Prepared::from_blobs(&scene, photons.as_deref(), &frame, &[], usize::MAX).unwrap();
        let h = prep.camera.height;
        let a = render_rows(&prep, 0..h, &|_| {});
        // Strips cut anywhere give the same bytes as the whole image.
        let mut b = Vec::new();
        for rows in [0..7, 7..h] {
            b.extend(render_rows(&back, rows, &|_| {}).pixels);
        }
        assert_eq!(bits(&a.pixels), bits(&b), "{integrator}");
        assert!(a.pixels.iter().any(|&v| v > 0.0));
    }
}

#[test]
fn a_cancelled_render_stops_early() {
    for integrator in [Method::Path, Method::Progressive, Method::Vcm] {
        let prep = cornell(integrator);
        let calls = AtomicU32::new(0);
        let stop = Cancel::new();
        let progress = |_| {
            calls.fetch_add(1, Ordering::Relaxed);
            stop.cancel();
        };
        let block = Block { rows: 0..prep.camera.height, units: 0..job_units(&prep) };
        let out = render_block(&prep, &block, &progress, &Guard { cancel: &stop, storage_bytes: u64::MAX });
        assert_eq!(out.err(), Some(RunError::Cancelled), "{integrator}");
        // No pixel starts once the flag is set: only rows that finished at that moment report (one per thread).
        let started = calls.load(Ordering::Relaxed);
        assert!(started <= rayon::current_num_threads() as u32 + 1, "{integrator}: {started} rows after cancel");
    }
}

/// A block that would take minutes stops within a second or two of its flag being set, from another thread:
/// the flag is read before every sample of a pixel, every pixel, photon path and light subpath. (A loose bound
/// on a loaded machine: the point is that a cancelled block does not run to its end.)
#[test]
fn a_long_block_stops_soon_after_it_is_cancelled() {
    for integrator in [Method::Path, Method::Progressive, Method::Vcm] {
        let mut prep = cornell(integrator);
        prep.settings.photons.pass_photons = 2_000_000;
        prep.settings.spp = MAX_BLOCK_UNITS;
        prep.settings.photons.passes = MAX_BLOCK_UNITS;
        // One row of many samples: before, cancellation was read only when a row finished.
        let block = Block { rows: 0..1, units: 0..MAX_BLOCK_UNITS };
        let stop = Cancel::new();
        let guard = Guard { cancel: &stop, storage_bytes: u64::MAX };
        let t0 = Instant::now();
        let out = std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(Duration::from_millis(200));
                stop.cancel();
            });
            render_block(&prep, &block, &|_| {}, &guard)
        });
        let took = t0.elapsed();
        assert_eq!(out.err(), Some(RunError::Cancelled), "{integrator}");
        assert!(
            took < Duration::from_secs(3),
            "{integrator}: stopped {took:?} after the start, 200 ms after which it was cancelled"
        );
    }
}
