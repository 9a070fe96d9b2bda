//! Ray casting throughput of photon's BVH on the meshes and rays that `docs/figures/embree/embree_rays.c` times
//! with Embree, so the two can be compared in one run (`docs/figures/embree/run.sh`).
//!
//! `cargo run --release -p photon-core --example raycast -- write DIR` writes, for bumpy icospheres of 5 120,
//! 81 920 and 1 310 720 triangles (`DIR/ico{4,6,8}.mesh`: vertex count u32, triangle count u32, vertices as
//! 3 × f32, triangles as 3 × u32, little-endian) and two ray sets for each (`DIR/ico{4,6,8}.{coherent,incoherent}.rays`:
//! ray count u32, then origin and direction as 6 × f32): 65 536 rays of a 256×256 pinhole camera looking at the
//! mesh, and 65 536 rays from uniform points in the mesh's bounds in uniform directions.
//!
//! `... --example raycast -- time DIR NAME THREADS` builds the BVH of `DIR/NAME.mesh` and times closest-hit and
//! any-hit queries (single rays, `tmax` = ∞) of both ray sets on `THREADS` threads, printing one line per
//! measurement in the harness's format: `photon NAME THREADS build_s bytes_per_triangle` and
//! `photon NAME THREADS {closest,any} {coherent,incoherent} Mrays_per_s hits`. Each rate is the median of 5
//! passes over the rays; the build time is the median of 3 builds, each timed as `embree_rays` times Embree's:
//! the input ready before the clock starts, the previous build released before it. `... build DIR NAME THREADS`
//! prints the build line alone.
//!
//! `... cost DIR NAME` prints the tree's measures, which timings on a shared machine cannot move: node and block
//! counts, depth, the SAH cost, and per ray of each set and query the nodes visited, the leaves tested and the
//! triangles in them. `... one DIR NAME QUERY KIND` runs one pass of one query in a function of its own, for
//! `valgrind --tool=callgrind --toggle-collect=raycast::one_pass` to count its instructions.
//! `... obj FILE LEVELS` writes the bumpy icosphere of `20·4^LEVELS` triangles as OBJ, for whole renders.

#[path = "../benches/shared/meshes.rs"]
mod meshes;

use glam::{Vec3, Vec3A};
use meshes::{bumpy_icosphere, camera_rays, random_rays};
use photon_core::geometry::bvh::RayCost;
use photon_core::geometry::shapes::{Shape, Triangle};
use photon_core::geometry::{Geometry, NONE, Primitive};
use photon_core::math::{Aabb, Ray};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

fn put(out: &mut Vec<u8>, x: u32) {
    out.extend_from_slice(&x.to_le_bytes());
}

fn write(dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for levels in [4, 6, 8] {
        let name = format!("ico{levels}");
        let (v, f) = bumpy_icosphere(levels);
        let mut out = Vec::new();
        put(&mut out, v.len() as u32);
        put(&mut out, f.len() as u32);
        v.iter().flatten().for_each(|c| put(&mut out, c.to_bits()));
        f.iter().flatten().for_each(|&i| put(&mut out, i));
        std::fs::write(dir.join(format!("{name}.mesh")), out)?;
        let bounds = v.iter().fold(Aabb::EMPTY, |b, p| b.grow(Vec3::from_array(*p)));
        for (kind, rays) in [("coherent", camera_rays(256, 256)), ("incoherent", random_rays(65_536, bounds))] {
            let mut out = Vec::new();
            put(&mut out, rays.len() as u32);
            for r in &rays {
                for c in [r.o.x, r.o.y, r.o.z, r.d.x, r.d.y, r.d.z] {
                    put(&mut out, c.to_bits());
                }
            }
            std::fs::write(dir.join(format!("{name}.{kind}.rays")), out)?;
        }
        println!("wrote {name}: {} vertices, {} triangles", v.len(), f.len());
    }
    Ok(())
}

/// Writes the bumpy icosphere of `20·4^levels` triangles as OBJ text (for whole renders of a large mesh).
fn write_obj(path: &Path, levels: u32) -> std::io::Result<()> {
    use std::io::Write;
    let (v, f) = bumpy_icosphere(levels);
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    for p in &v {
        writeln!(out, "v {} {} {}", p[0], p[1], p[2])?;
    }
    for t in &f {
        writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
    }
    out.flush()?;
    println!("wrote {}: {} vertices, {} triangles", path.display(), v.len(), f.len());
    Ok(())
}

fn words(bytes: &[u8]) -> Vec<u32> {
    bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

fn read_mesh(path: &Path) -> std::io::Result<Vec<Triangle>> {
    let w = words(&std::fs::read(path)?);
    let bad = || std::io::Error::new(std::io::ErrorKind::InvalidData, format!("{}: truncated mesh", path.display()));
    let (nv, nf) = (*w.first().ok_or_else(bad)? as usize, *w.get(1).ok_or_else(bad)? as usize);
    let vs = w.get(2..2 + 3 * nv).ok_or_else(bad)?;
    let fs = w.get(2 + 3 * nv..2 + 3 * nv + 3 * nf).ok_or_else(bad)?;
    let vertex = |i: u32| -> std::io::Result<Vec3> {
        let k = 3 * i as usize;
        let c = vs.get(k..k + 3).ok_or_else(bad)?;
        Ok(Vec3::new(f32::from_bits(c[0]), f32::from_bits(c[1]), f32::from_bits(c[2])))
    };
    fs.chunks_exact(3).map(|f| Ok(Triangle::new(vertex(f[0])?, vertex(f[1])?, vertex(f[2])?))).collect()
}

fn read_rays(path: &Path) -> std::io::Result<Vec<Ray>> {
    let w = words(&std::fs::read(path)?);
    let f: Vec<f32> = w.iter().skip(1).map(|&b| f32::from_bits(b)).collect();
    Ok(f.chunks_exact(6).map(|c| Ray::new(Vec3A::new(c[0], c[1], c[2]), Vec3A::new(c[3], c[4], c[5]))).collect())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time(dir: &Path, name: &str, threads: usize, build_only: bool) -> Result<(), Box<dyn std::error::Error>> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let tris = read_mesh(&dir.join(format!("{name}.mesh")))?;
    let prims: Vec<Primitive> =
        tris.iter().map(|&t| Primitive { shape: Shape::Triangle(t), material: 0, light: NONE, object: 0 }).collect();
    // The build as a worker runs it on decoding a scene: the trees over the primitives, and the primitives packed
    // against them (`Geometry::packed`). As embree_rays does, the input is ready before the clock starts and the
    // previous build is released before it, not within it.
    let mut secs = Vec::new();
    let mut last = None;
    for _ in 0..3 {
        drop(last.take());
        let input = prims.clone();
        let t0 = Instant::now();
        last = Some(pool.install(|| Geometry::new(black_box(input), Vec::new(), Vec::new()).packed()));
        secs.push(t0.elapsed().as_secs_f64());
    }
    let g = last.ok_or("no build")?;
    let bytes = g.memory_bytes();
    println!(
        "photon {name} {threads} build {:.4} {:.1} {:016x}",
        median(secs),
        bytes as f64 / tris.len() as f64,
        g.triangle_tree().structure_hash()
    );
    if build_only {
        return Ok(());
    }
    for kind in ["coherent", "incoherent"] {
        let rays = read_rays(&dir.join(format!("{name}.{kind}.rays")))?;
        // The queries as `Geometry::intersect` and `Geometry::occluded` make them, without the hit's shading data
        // (normals, UVs), which Embree's queries do not compute either.
        let closest = |r: &Ray| g.closest_bounded(r, f32::INFINITY).is_some();
        let any = |r: &Ray| g.occluded(r, f32::INFINITY);
        for (query, f) in [("closest", &closest as &(dyn Fn(&Ray) -> bool + Sync)), ("any", &any)] {
            let run =
                || pool.install(|| rays.par_chunks(256).map(|c| c.iter().filter(|r| f(r)).count()).sum::<usize>());
            let hits = run();
            let mut rates = Vec::new();
            for _ in 0..5 {
                let t0 = Instant::now();
                black_box(run());
                rates.push(rays.len() as f64 / t0.elapsed().as_secs_f64() / 1e6);
            }
            println!("photon {name} {threads} {query} {kind} {:.3} {hits}", median(rates));
        }
    }
    Ok(())
}

/// The tree's measures, deterministic where timings are not: its SAH cost, and per ray of each set the nodes
/// visited, the leaves (triangle blocks) tested and the triangles in them, for closest and any hit.
fn cost(dir: &Path, name: &str) -> Result<(), Box<dyn std::error::Error>> {
    let tris = read_mesh(&dir.join(format!("{name}.mesh")))?;
    let prims: Vec<Primitive> =
        tris.iter().map(|&t| Primitive { shape: Shape::Triangle(t), material: 0, light: NONE, object: 0 }).collect();
    let g = Geometry::new(prims, Vec::new(), Vec::new());
    let t = g.triangle_tree();
    println!(
        "{name}: {} triangles, {} nodes, {} blocks ({:.2} triangles a block), depth {}, SAH cost {:.2}",
        tris.len(),
        t.node_count(),
        t.block_count(),
        tris.len() as f64 / t.block_count() as f64,
        t.depth(),
        t.sah_cost()
    );
    for kind in ["coherent", "incoherent"] {
        let rays = read_rays(&dir.join(format!("{name}.{kind}.rays")))?;
        let n = rays.len() as f64;
        let (mut closest, mut any) = (RayCost::default(), RayCost::default());
        for r in &rays {
            g.closest_triangle_counted(r, f32::INFINITY, &mut closest);
            g.triangle_occluded_counted(r, f32::INFINITY, &mut any);
        }
        for (query, c) in [("closest", closest), ("any", any)] {
            println!(
                "  {query} {kind}: per ray {:.2} nodes, {:.2} leaves, {:.2} triangles",
                c.nodes as f64 / n,
                c.leaves as f64 / n,
                c.prims as f64 / n
            );
        }
    }
    Ok(())
}

/// One pass of one query over one ray set, alone in its function so that `valgrind --tool=callgrind
/// --toggle-collect=raycast::one_pass` counts its instructions: a measure of the walk that this shared machine's
/// load cannot move.
#[inline(never)]
fn one_pass(g: &Geometry, rays: &[Ray], closest: bool) -> usize {
    if closest {
        rays.iter().filter(|r| g.closest_bounded(r, f32::INFINITY).is_some()).count()
    } else {
        rays.iter().filter(|r| g.occluded(r, f32::INFINITY)).count()
    }
}

fn one(dir: &Path, name: &str, query: &str, kind: &str) -> Result<(), Box<dyn std::error::Error>> {
    let tris = read_mesh(&dir.join(format!("{name}.mesh")))?;
    let prims: Vec<Primitive> =
        tris.iter().map(|&t| Primitive { shape: Shape::Triangle(t), material: 0, light: NONE, object: 0 }).collect();
    let g = Geometry::new(prims, Vec::new(), Vec::new()).packed();
    let rays = read_rays(&dir.join(format!("{name}.{kind}.rays")))?;
    let hits = one_pass(&g, &rays, query == "closest");
    println!("{name} {query} {kind}: {} rays, {hits} hits", rays.len());
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>().as_slice() {
        ["write", dir] => write(Path::new(dir))?,
        ["time", dir, name, threads] => time(Path::new(dir), name, threads.parse()?, false)?,
        ["build", dir, name, threads] => time(Path::new(dir), name, threads.parse()?, true)?,
        ["cost", dir, name] => cost(Path::new(dir), name)?,
        ["one", dir, name, query, kind] => one(Path::new(dir), name, query, kind)?,
        ["obj", file, levels] => write_obj(Path::new(file), levels.parse()?)?,
        _ => {
            return Err(
                "usage: raycast write DIR | raycast {time,build} DIR NAME THREADS | raycast cost DIR NAME | raycast one DIR \
             NAME {closest,any} {coherent,incoherent} | raycast obj FILE LEVELS".into()
            );
        }
    }
    Ok(())
}
