//! A prepared scene sent as blobs (scene, photons, frame) renders the same bytes as the original, for a method
//! with photon maps and for progressive photon mapping, cut into strips anywhere; a cancelled render stops.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::render::{Block, job_units, render_block, render_rows};
use photon_core::scene::Scene;
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};

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
    for integrator in [Method::Path, Method::Progressive] {
        let prep = cornell(integrator);
        let calls = AtomicU32::new(0);
        let cancel = |_| {
            calls.fetch_add(1, Ordering::Relaxed);
            false
        };
        let block = Block { rows: 0..prep.camera.height, units: 0..job_units(&prep) };
        let out = render_block(&prep, &block, &cancel);
        assert!(out.is_none(), "{integrator}");
        // Rows already started finish; no new row starts once the first one has asked to stop (one per thread).
        let started = calls.load(Ordering::Relaxed);
        assert!(started <= rayon::current_num_threads() as u32 + 1, "{integrator}: {started} rows after cancel");
    }
}
