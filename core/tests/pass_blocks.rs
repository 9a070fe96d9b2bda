//! Every method's units are independent: progressive photon mapping's passes: blocks of passes rendered in any cut and added in
//! any order give the image of the whole render, bit for bit, and each pass traces `pass_photons` paths once.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::render::sums::{SumAccumulator, check_sums};
use photon_core::render::{Block, BlockSums, render_block, render_image};
use photon_core::run::{Cancel, Guard, RunError};
use photon_core::scene::Scene;
use std::ops::Range;
use std::path::Path;

fn cornell(passes: u32) -> Prepared {
    cornell_with(Method::Progressive, passes)
}

fn cornell_with(integrator: Method, passes: u32) -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 20;
    scene.camera.height = 16;
    scene.render.integrator = integrator;
    scene.render.photons.passes = passes;
    scene.render.photons.pass_photons = 3_000;
    Prepared::new(&scene, &path).unwrap()
}

/// Units `units` over rows `rows`.
fn blocks(prep: &Prepared, rows: Range<u32>, units: Range<u32>) -> BlockSums {
    render_block(prep, &Block { rows, units }, &|_| {}, &Guard::unbounded()).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn any_cut_into_blocks_in_any_order_gives_the_same_image() {
    let passes = 7;
    let prep = cornell(passes);
    let (w, h) = (prep.camera.width, prep.camera.height);
    let whole = render_image(&prep, &|_| {});
    assert_eq!(whole.photon_paths, u64::from(passes) * 3_000);
    assert!(whole.pixels.iter().any(|&v| v > 0.0));
    let cuts: [&[Range<u32>]; 3] = [&[0..4, 4..7], &[0..1, 1..4, 4..7], &[5..7, 0..2, 3..5, 2..3]];
    for cut in cuts {
        let mut acc = SumAccumulator::new(3 * (w * h) as usize, passes);
        let mut paths = 0;
        for block in cut {
            let sums = blocks(&prep, 0..h, block.clone());
            check_sums(&sums.sums, block.len() as u32).unwrap();
            paths += sums.photon_paths;
            acc.add(&sums.sums);
        }
        assert_eq!(bits(&acc.image()), bits(&whole.pixels), "blocks {cut:?}");
        assert_eq!(paths, whole.photon_paths, "blocks {cut:?}");
    }
}

/// vcm's iterations too: light subpaths, connections, merges and light-tracing splats, whatever the cut, and
/// each iteration traces one light subpath per pixel once.
#[test]
fn vcm_iterations_in_any_cut_give_the_same_image() {
    let passes = 5;
    let prep = cornell_with(Method::Vcm, passes);
    let (w, h) = (prep.camera.width, prep.camera.height);
    let whole = render_image(&prep, &|_| {});
    assert_eq!(whole.photon_paths, u64::from(passes * w * h));
    assert!(whole.pixels.iter().any(|&v| v > 0.0));
    for cut in [&[0..2, 2..5][..], &[4..5, 0..1, 1..4]] {
        let mut acc = SumAccumulator::new(3 * (w * h) as usize, passes);
        for block in cut {
            let sums = blocks(&prep, 0..h, block.clone());
            check_sums(&sums.sums, block.len() as u32).unwrap();
            acc.add(&sums.sums);
        }
        assert_eq!(bits(&acc.image()), bits(&whole.pixels), "blocks {cut:?}");
    }
    // Rows: splats from light subpaths land on any row, and a block over some rows keeps those that land there.
    let all = blocks(&prep, 0..h, 0..2);
    let part = blocks(&prep, 5..9, 0..2);
    assert_eq!(part.sums[..], all.sums[3 * w as usize * 5..3 * w as usize * 9]);
}

#[test]
fn a_block_over_some_rows_gives_those_rows_of_the_whole_block() {
    let prep = cornell(3);
    let (w, h) = (prep.camera.width as usize, prep.camera.height);
    let all = blocks(&prep, 0..h, 0..3);
    let part = blocks(&prep, 5..9, 0..3);
    assert_eq!(part.sums[..], all.sums[3 * w * 5..3 * w * 9]);
}

#[test]
fn a_cancelled_block_stops_after_the_pass_that_asked() {
    let prep = cornell(5);
    let calls = std::sync::atomic::AtomicU32::new(0);
    let stop = Cancel::new();
    let progress = |_| {
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        stop.cancel();
    };
    let guard = Guard { cancel: &stop, storage_bytes: u64::MAX };
    let out = render_block(&prep, &Block { rows: 0..prep.camera.height, units: 0..5 }, &progress, &guard);
    assert_eq!(out.err(), Some(RunError::Cancelled));
    assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 1);
}
