//! Photon tracing throughput on the Cornell scene: photon paths traced and photons stored per second on one
//! core (a one-thread rayon pool), for the global and the caustic map.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use std::path::Path;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let Ok(prep) = Prepared::load(&path) else { panic!("cannot load {}", path.display()) };
    let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(1).build() else { panic!("no thread pool") };
    let paths = 100_000u64;
    let mut g = c.benchmark_group("photon_tracing_one_core");
    g.sample_size(10).measurement_time(Duration::from_secs(5)).throughput(Throughput::Elements(paths));
    for (name, kind) in [("global", PhotonKind::Global), ("caustic", PhotonKind::Caustic)] {
        let stored = pool.install(|| trace_photons(&prep, paths, 0, kind)).photons.len();
        eprintln!(
            "cornell {name}: {paths} paths store {stored} photons ({:.2} per path)",
            stored as f64 / paths as f64
        );
        g.bench_function(name, |b| b.iter(|| pool.install(|| trace_photons(&prep, paths, 0, kind)).photons.len()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
