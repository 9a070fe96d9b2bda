//! Photon maps are bit-identical whatever the thread count: photon i draws from the stream (seed, pass, i) and
//! chunks are concatenated in order.

#![allow(clippy::unwrap_used)]

use photon_core::codec;
use photon_core::photon::PhotonMap;
use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use std::path::Path;

#[test]
fn maps_are_identical_with_one_and_four_threads() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let prep = Prepared::load(&path).unwrap();
    let build = |threads: usize, kind: PhotonKind| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let traced = trace_photons(&prep, 30_000, 0, kind);
            codec::encode(&PhotonMap::build(traced.photons).unwrap()).unwrap()
        })
    };
    for kind in [PhotonKind::Global, PhotonKind::Caustic] {
        let one = build(1, kind);
        let four = build(4, kind);
        assert!(one.len() > 1000, "{kind:?}: too few photons");
        assert!(one == four, "{kind:?}: maps differ between 1 and 4 threads");
    }
}
