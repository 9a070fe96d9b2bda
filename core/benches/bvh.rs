//! BVH build time (on 1 and 2 threads), size and single-threaded closest-hit and any-hit throughput on procedural
//! meshes of 100k and 1M triangles (a displaced UV sphere: smooth bumps over the whole surface, degenerate
//! slivers at the poles).
//!
//! Run with `cargo bench -p photon-core --bench bvh`. Coherent rays come from a pinhole camera looking at the
//! mesh; incoherent rays start at random points in the mesh's bounds and go in uniformly random directions.
//! Any-hit rays are the same rays with an infinite `tmax`. Bytes per triangle count the BVH alone and the BVH
//! plus the primitive array traversal reads.

#[allow(dead_code)]
mod shared {
    pub mod meshes;
}

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use photon_core::geometry::bvh::Bvh;
use photon_core::geometry::shapes::{Shape, Triangle, TriangleRay};
use photon_core::geometry::{Geometry, NONE, Primitive};
use photon_core::math::fmath;
use photon_core::math::{Aabb, Ray};
use shared::meshes::{camera_rays, random_rays};
use std::hint::black_box;
use std::time::Duration;

/// A UV sphere of radius about 1 with `rows × cols` quads (two triangles each), displaced along the normal.
fn displaced_sphere(rows: usize, cols: usize) -> Vec<Triangle> {
    let vertex = |i: usize, j: usize| {
        let theta = std::f32::consts::PI * i as f32 / rows as f32;
        let phi = 2.0 * std::f32::consts::PI * j as f32 / cols as f32;
        let r = 1.0
            + 0.08 * fmath::sin(7.0 * theta) * fmath::sin(9.0 * phi)
            + 0.02 * fmath::sin(41.0 * theta) * fmath::cos(37.0 * phi);
        r * Vec3::new(fmath::sin(theta) * fmath::cos(phi), fmath::cos(theta), fmath::sin(theta) * fmath::sin(phi))
    };
    let mut tris = Vec::with_capacity(2 * rows * cols);
    for i in 0..rows {
        for j in 0..cols {
            let (a, b, c, d) = (vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1), vertex(i, j + 1));
            tris.push(Triangle::new(a, b, c));
            tris.push(Triangle::new(a, c, d));
        }
    }
    tris
}

fn geometry(tris: &[Triangle]) -> Geometry {
    let prims =
        tris.iter().map(|&t| Primitive { shape: Shape::Triangle(t), material: 0, light: NONE, object: 0 }).collect();
    Geometry::new(prims, Vec::new(), Vec::new())
}

/// Traces every ray to its closest hit through the BVH; returns the number of hits.
fn trace(g: &Geometry, rays: &[Ray]) -> usize {
    rays.iter()
        .filter(|ray| {
            let tri = TriangleRay::new(ray);
            g.bvh
                .closest_hit(ray.o, ray.d, f32::INFINITY, |i, tmax| {
                    g.prims[i as usize].shape.intersect_prepared(ray, &tri, tmax)
                })
                .is_some()
        })
        .count()
}

/// Traces every ray to any hit through the BVH; returns the number of occluded rays.
fn occluded(g: &Geometry, rays: &[Ray]) -> usize {
    rays.iter().filter(|ray| g.occluded(ray, f32::INFINITY)).count()
}

fn bench(c: &mut Criterion) {
    for (label, rows, cols) in [("100k", 224, 224), ("1M", 708, 708)] {
        let tris = displaced_sphere(rows, cols);
        let bounds: Vec<Aabb> = tris.iter().map(Triangle::bounds).collect();
        let g = geometry(&tris);
        let bytes = g.bvh.memory_bytes();
        let prim_bytes = g.prims.len() * std::mem::size_of::<Primitive>();
        println!(
            "bvh {label}: {} triangles, {} nodes, depth {}, {} bytes = {:.1} bytes/triangle ({:.1} with primitives)",
            tris.len(),
            g.bvh.node_count(),
            g.bvh.depth(),
            bytes,
            bytes as f64 / tris.len() as f64,
            (bytes + prim_bytes) as f64 / tris.len() as f64
        );
        let mut group = c.benchmark_group(format!("bvh_{label}"));
        group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
        group.throughput(Throughput::Elements(tris.len() as u64));
        for threads in [1, 2] {
            let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(threads).build() else { continue };
            group.bench_function(format!("build_{threads}t"), |b| {
                b.iter(|| pool.install(|| Bvh::build(black_box(&bounds))))
            });
        }

        let coherent = camera_rays(256, 256);
        let incoherent = random_rays(65_536, g.bounds());
        println!(
            "bvh {label}: coherent hits {}/{} (occluded {}), incoherent hits {}/{} (occluded {})",
            trace(&g, &coherent),
            coherent.len(),
            occluded(&g, &coherent),
            trace(&g, &incoherent),
            incoherent.len(),
            occluded(&g, &incoherent)
        );
        group.throughput(Throughput::Elements(coherent.len() as u64));
        group.bench_function("closest_coherent", |b| b.iter(|| trace(&g, black_box(&coherent))));
        group.throughput(Throughput::Elements(incoherent.len() as u64));
        group.bench_function("closest_incoherent", |b| b.iter(|| trace(&g, black_box(&incoherent))));
        group.bench_function("any_incoherent", |b| b.iter(|| occluded(&g, black_box(&incoherent))));
        group.throughput(Throughput::Elements(coherent.len() as u64));
        group.bench_function("any_coherent", |b| b.iter(|| occluded(&g, black_box(&coherent))));
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
