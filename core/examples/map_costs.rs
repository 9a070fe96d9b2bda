//! The costs of getting a photon map onto a worker, measured on this machine: tracing the paths, building the
//! kd-tree, encoding the blob, and decoding it back (which rebuilds the tree), each on one thread and on all.
//! Run with `cargo run --release -p photon-core --example map_costs -- [SCENE] [PATHS]`; prints the median of
//! three runs of each step.
#![allow(clippy::unwrap_used, clippy::print_stdout, reason = "a measuring tool: a failed setup should stop at once")]

use photon_core::codec;
use photon_core::photon::{PhotonMap, PhotonMaps};
use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time<R>(f: impl Fn() -> R) -> (f64, R) {
    let mut out = None;
    let mut times = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        out = Some(f());
        times.push(t.elapsed().as_secs_f64());
    }
    (median(times), out.unwrap())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = args.get(1).map_or("scenes/cornell.toml", String::as_str);
    let paths: u64 = args.get(2).map_or(4_000_000, |s| s.parse().unwrap());
    let mut prep = Prepared::new(&photon_core::scene::Scene::load(scene.as_ref()).unwrap(), scene.as_ref()).unwrap();
    prep.settings.integrator = photon_core::method::Method::PhotonMap;
    let threads = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    println!("{scene}, {paths} global photon paths, {threads} threads; median of 3 (seconds)");
    println!("step | 1 thread | {threads} threads");
    let (t1, _) = time(|| one.install(|| trace_photons(&prep, paths, 0, PhotonKind::Global).photons.len()));
    let (tn, traced) = time(|| trace_photons(&prep, paths, 0, PhotonKind::Global));
    println!("trace | {t1:.3} | {tn:.3}   ({} photons)", traced.photons.len());
    let (b1, _) = time(|| one.install(|| PhotonMap::build(traced.photons.clone()).unwrap().len()));
    let (bn, map) = time(|| PhotonMap::build(traced.photons.clone()).unwrap());
    println!("build | {b1:.3} | {bn:.3}");
    let (r1, _) = time(|| one.install(|| PhotonMap::build(map.photons().to_vec()).unwrap().len()));
    let (rn, _) = time(|| PhotonMap::build(map.photons().to_vec()).unwrap().len());
    println!("rebuild from sorted photons | {r1:.3} | {rn:.3}");
    let maps = PhotonMaps {
        global: map,
        caustic: None,
        estimator: prep.estimator(),
        irradiance: None,
        volume: None,
        volume_gather: prep.volume_gather(),
    };
    let (e1, _) = time(|| one.install(|| codec::encode(&maps).unwrap().len()));
    let (en, blob) = time(|| codec::encode(&maps).unwrap());
    println!("encode | {e1:.3} | {en:.3}   ({:.1} MB)", blob.len() as f64 / 1e6);
    let (d1, _) = time(|| one.install(|| codec::decode::<PhotonMaps>(&blob, usize::MAX).unwrap().global.len()));
    let (dn, _) = time(|| codec::decode::<PhotonMaps>(&blob, usize::MAX).unwrap().global.len());
    println!("decode + build | {d1:.3} | {dn:.3}");
}
