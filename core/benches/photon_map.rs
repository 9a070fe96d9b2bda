//! Photon-map benchmarks (being written).
fn main() {}
