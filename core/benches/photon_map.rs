//! Photon-map benchmarks: kd-tree build, k-nearest gathers and radiance estimates on 1M and 10M photons.
//!
//! The photons lie on the five walls of a unit Cornell box, so, as in real maps, many of them share a
//! coordinate (every photon on a wall has the same x, y or z). Run with
//! `cargo bench -p photon-core --bench photon_map`; it also prints the map's bytes per photon.
#![allow(clippy::unwrap_used, reason = "a benchmark whose setup fails should stop at once, like a test")]

use photon_core::math::fmath;
use std::hint::black_box;
use std::time::Duration;

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3A;
use photon_core::Rgb;
use photon_core::math::rng::{Domain, Sampler};
use photon_core::photon::{Estimator, Gather, Kernel, Photon, PhotonMap};

const SIZES: [usize; 2] = [1_000_000, 10_000_000];
const QUERIES: usize = 1000;

/// A uniform point on one of the five walls (floor, ceiling, back, left, right) of the unit box, with the
/// wall's inward normal.
fn wall_point(s: &mut Sampler) -> (Vec3A, Vec3A) {
    let wall = (s.next_f32() * 5.0) as u32;
    let u = s.next_2d();
    match wall {
        0 => (Vec3A::new(u.x, 0.0, u.y), Vec3A::Y),
        1 => (Vec3A::new(u.x, 1.0, u.y), -Vec3A::Y),
        2 => (Vec3A::new(u.x, u.y, 1.0), -Vec3A::Z),
        3 => (Vec3A::new(0.0, u.x, u.y), Vec3A::X),
        _ => (Vec3A::new(1.0, u.x, u.y), -Vec3A::X),
    }
}

fn cornell_photons(count: usize) -> Vec<Photon> {
    let mut s = Sampler::new(1, Domain::Photon, count as u64, 0, 0);
    let phi = Rgb::splat(1.0 / count as f32);
    (0..count)
        .map(|i| {
            let (p, n) = wall_point(&mut s);
            let wi = fmath::normalize(n + photon_core::math::uniform_sphere(s.next_2d()) * 0.9);
            Photon::new(p, wi, n, phi, (i % 5) as u32)
        })
        .collect()
}

fn queries() -> Vec<(Vec3A, Vec3A)> {
    let mut s = Sampler::new(2, Domain::Photon, 0, 0, 0);
    (0..QUERIES).map(|_| wall_point(&mut s)).collect()
}

fn build(c: &mut Criterion) {
    let mut group = c.benchmark_group("photon_map_build");
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(5));
    for n in SIZES {
        let photons = cornell_photons(n);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter_batched(|| photons.clone(), |p| PhotonMap::build(p).unwrap(), BatchSize::PerIteration)
        });
    }
    group.finish();
}

fn gather(c: &mut Criterion) {
    let queries = queries();
    let mut group = c.benchmark_group("photon_map_gather");
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Elements(QUERIES as u64));
    for n in SIZES {
        let map = PhotonMap::build(cornell_photons(n)).unwrap();
        eprintln!(
            "{n} photons: {:.1} bytes per photon ({} for the photon, {:.1} for the kd-tree)",
            map.memory_bytes() as f64 / n as f64,
            size_of::<Photon>(),
            (map.memory_bytes() - n * size_of::<Photon>()) as f64 / n as f64,
        );
        let mut scratch = Vec::with_capacity(256);
        for k in [50, 200] {
            group.bench_function(BenchmarkId::new(format!("k_nearest_{k}"), n), |b| {
                b.iter(|| {
                    for &(p, _) in &queries {
                        map.k_nearest(p, k, 0.01, &mut scratch);
                        black_box(&scratch);
                    }
                })
            });
        }
        // Radius gathers holding the same numbers of photons on average (area 5): kiddo's k-nearest search
        // costs several times a radius search over as many photons.
        for k in [50.0f32, 200.0] {
            let r2 = k * 5.0 / (std::f32::consts::PI * n as f32);
            group.bench_function(BenchmarkId::new(format!("within_mean_{k}"), n), |b| {
                b.iter(|| {
                    for &(p, _) in &queries {
                        map.within(p, r2, &mut scratch);
                        black_box(&scratch);
                    }
                })
            });
        }
        let est = Estimator {
            gather: Gather::KNearest { k: 50, max_radius: 0.1 },
            kernel: Kernel::Epanechnikov,
            disc: Some(0.25),
            same_object: false,
        };
        group.bench_function(BenchmarkId::new("estimate_k50_epanechnikov", n), |b| {
            b.iter(|| {
                for &(p, n) in &queries {
                    black_box(map.estimate(&est, p, n, 0, |_| Rgb::splat(0.25), &mut scratch));
                }
            })
        });
    }
    group.finish();
}

fn codec(c: &mut Criterion) {
    let map = PhotonMap::build(cornell_photons(SIZES[0])).unwrap();
    let bytes = photon_core::codec::encode(&map).unwrap();
    eprintln!("encoded 1M-photon map: {} bytes", bytes.len());
    let mut group = c.benchmark_group("photon_map_codec");
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(5));
    group.throughput(Throughput::Elements(map.len() as u64));
    group.bench_function("encode_1000000", |b| b.iter(|| photon_core::codec::encode(&map).unwrap()));
    group.bench_function("decode_and_rebuild_1000000", |b| {
        b.iter(|| photon_core::codec::decode::<PhotonMap>(&bytes, bytes.len()).unwrap())
    });
    group.finish();
}

criterion_group!(benches, build, gather, codec);
criterion_main!(benches);
