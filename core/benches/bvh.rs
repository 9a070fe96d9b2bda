//! The BVH on the mesh sizes: bumpy icospheres of 5 120, 81 920 and 1 310 720 triangles
//! (`shared/meshes.rs`, the meshes `docs/figures/embree/run.sh` also gives Embree). For each: the build on 1 thread
//! and on all, its size, and closest-hit and any-hit throughput of coherent and incoherent rays on 1 thread and on
//! all.
//!
//! Run with `cargo bench -p photon-core --bench bvh`. Coherent rays come from a 256×256 pinhole camera looking at
//! the mesh; incoherent rays start at uniform points in the mesh's bounds and go in uniform directions; both have
//! an infinite `tmax`. Rays are split over the threads in chunks of 256. Bytes per triangle count the BVH alone
//! (nodes and triangle blocks, which hold the vertices) and with the scene's primitive array.

#[allow(dead_code)]
mod shared {
    pub mod meshes;
}

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use photon_core::geometry::bvh::TriBvh;
use photon_core::geometry::shapes::{Shape, Triangle};
use photon_core::geometry::{Geometry, NONE, Primitive};
use photon_core::math::Ray;
use rayon::prelude::*;
use shared::meshes::{bumpy_icosphere, camera_rays, random_rays};
use std::hint::black_box;
use std::time::Duration;

fn geometry(tris: &[Triangle]) -> Geometry {
    let prims =
        tris.iter().map(|&t| Primitive { shape: Shape::Triangle(t), material: 0, light: NONE, object: 0 }).collect();
    // Packed, as a worker holds it.
    Geometry::new(prims, Vec::new(), Vec::new()).packed()
}

/// Traces every ray to its closest hit through the BVH (`Geometry::closest_bounded`, what `Geometry::intersect`
/// does before it computes the hit's shading data); returns the number of hits.
fn trace(g: &Geometry, rays: &[Ray]) -> usize {
    rays.par_chunks(256)
        .map(|rays| rays.iter().filter(|ray| g.closest_bounded(ray, f32::INFINITY).is_some()).count())
        .sum()
}

/// Traces every ray to any hit through the BVH; returns the number of occluded rays.
fn occluded(g: &Geometry, rays: &[Ray]) -> usize {
    rays.par_chunks(256).map(|rays| rays.iter().filter(|ray| g.occluded(ray, f32::INFINITY)).count()).sum()
}

fn bench(c: &mut Criterion) {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pools: Vec<(usize, rayon::ThreadPool)> = [1, all]
        .into_iter()
        .filter_map(|t| rayon::ThreadPoolBuilder::new().num_threads(t).build().ok().map(|p| (t, p)))
        .collect();
    for (label, levels) in [("5k", 4), ("82k", 6), ("1.3M", 8)] {
        let (vertices, faces) = bumpy_icosphere(levels);
        let vertex = |i: u32| Vec3::from_array(vertices[i as usize]);
        let tris: Vec<Triangle> =
            faces.iter().map(|f| Triangle::new(vertex(f[0]), vertex(f[1]), vertex(f[2]))).collect();
        let indexed: Vec<(u32, Triangle)> = tris.iter().enumerate().map(|(i, &t)| (i as u32, t)).collect();
        let g = geometry(&tris);
        let bytes = g.bvh_bytes();
        println!(
            "bvh {label}: {} triangles, {} nodes, {} blocks, depth {}, SAH cost {:.2}, {} bytes = {:.1} bytes/triangle \
             ({:.1} with the packed primitives)",
            tris.len(),
            g.triangle_tree().node_count(),
            g.triangle_tree().block_count(),
            g.triangle_tree().depth(),
            g.triangle_tree().sah_cost(),
            bytes,
            bytes as f64 / tris.len() as f64,
            g.memory_bytes() as f64 / tris.len() as f64
        );
        let coherent = camera_rays(256, 256);
        let incoherent = random_rays(65_536, g.bounds());
        let mut group = c.benchmark_group(format!("bvh_{label}"));
        group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
        for (threads, pool) in &pools {
            group.throughput(Throughput::Elements(tris.len() as u64));
            group.bench_function(format!("build_{threads}t"), |b| {
                b.iter(|| pool.install(|| TriBvh::build(black_box(&indexed))))
            });
            for (kind, rays) in [("coherent", &coherent), ("incoherent", &incoherent)] {
                group.throughput(Throughput::Elements(rays.len() as u64));
                group.bench_function(format!("closest_{kind}_{threads}t"), |b| {
                    b.iter(|| pool.install(|| trace(&g, black_box(rays))))
                });
                group.bench_function(format!("any_{kind}_{threads}t"), |b| {
                    b.iter(|| pool.install(|| occluded(&g, black_box(rays))))
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
