//! Two more anchors for photon's ray casting (docs/figures/embree/run.sh): tinybvh and obvhs, timed exactly as
//! `docs/figures/embree/embree_rays.c` times Embree, on the files photon's `raycast write DIR` example writes.
//!
//! Usage: `anchors TOOL DIR NAME THREADS`, TOOL `tinybvh` or `obvhs`. Reads `DIR/NAME.mesh` (vertex count u32,
//! triangle count u32, vertices as 3 × f32, triangles as 3 × u32, little-endian) and
//! `DIR/NAME.{coherent,incoherent}.rays` (ray count u32, then origin and direction as 6 × f32), builds the tool's
//! BVH (the median of 3 builds; the last is kept) and times single-ray closest-hit and any-hit queries (tmin 0,
//! tmax infinity) of both ray sets: one warm-up pass that counts the hits, then the median rate of 5 passes, the
//! rays in chunks of 256 (on THREADS rayon threads; on the calling thread alone when THREADS is 1). Prints lines
//! in embree_rays' format, the tool's name first:
//!   TOOL NAME THREADS build SECONDS BYTES_PER_TRIANGLE
//!   TOOL NAME THREADS {closest,any} {coherent,incoherent} MRAYS_PER_S HITS
//! and, on stderr, how the bytes split (not parsed by run.sh).
//!
//! - tinybvh 1.6.8 (bundled by tinybvh-rs 0.1.0-beta.3): the BVH8_CPU layout, the fastest CPU layout for single
//!   rays in tinybvh's own comparisons and the fastest tinybvh-rs exposes (its others: the binary "Wald" BVH,
//!   MBVH<8>, an intermediate with no traversal, and CWBVH, a GPU layout without a CPU traversal in the crate);
//!   8-wide AVX2 nodes, leaves of 4 triangles. Built by BVH8_CPU::Build, closest hit by Intersect, any hit by
//!   IsOccluded, through src/tinybvh_shim.cpp (see there why not the crate's Rust API). Its build makes its own
//!   threads above 50 000 triangles (as many as the machine has CPUs); THREADS is honoured by holding the build to
//!   THREADS CPUs (src/tinybvh.rs, `pin`).
//! - obvhs 0.4.0: its CWBVH (compressed 8-wide nodes of 80 bytes) built as its docs' example and README build it,
//!   `build_cwbvh_from_tris` with `BvhBuildParams::medium_build()` (PLOC, reinsertion; "around the same build time
//!   as embree but with faster traversal"), on a rayon pool of THREADS threads; the triangles copied in the BVH's
//!   order as `RtTriangle` ("optimized for CPU ray intersection", as its cornell_box_cwbvh example lays them out),
//!   which is part of the timed build; closest hit by `CwBvh::ray_traverse`, any hit by `CwBvh::ray_traverse_miss`
//!   (it stops at the first hit), both on its SSE node test.

mod tinybvh;

use glam::Vec3A;
use obvhs::{
    BvhBuildParams,
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris, node::CwBvhNode},
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    triangle::Triangle,
};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

type Error = Box<dyn std::error::Error>;

/// Rays per work item: embree_rays' OpenMP chunks and photon's rayon chunks.
const CHUNK: usize = 256;

struct Mesh {
    vertices: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl Mesh {
    fn corners(&self) -> impl Iterator<Item = [[f32; 3]; 3]> + '_ {
        self.triangles.iter().map(|t| t.map(|i| self.vertices[i as usize]))
    }
}

fn words(path: &Path) -> Result<Vec<u32>, Error> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}

fn read_mesh(path: &Path) -> Result<Mesh, Error> {
    let w = words(path)?;
    let bad = || format!("{}: truncated mesh", path.display());
    let (nv, nf) = (*w.first().ok_or_else(bad)? as usize, *w.get(1).ok_or_else(bad)? as usize);
    let vs = w.get(2..2 + 3 * nv).ok_or_else(bad)?;
    let fs = w.get(2 + 3 * nv..2 + 3 * nv + 3 * nf).ok_or_else(bad)?;
    let vertices: Vec<[f32; 3]> = vs.chunks_exact(3).map(|c| [0, 1, 2].map(|k| f32::from_bits(c[k]))).collect();
    let triangles: Vec<[u32; 3]> = fs.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    if triangles.iter().flatten().any(|&i| i as usize >= nv) {
        return Err(format!("{}: a vertex index past the {nv} vertices", path.display()).into());
    }
    Ok(Mesh { vertices, triangles })
}

fn read_rays(path: &Path) -> Result<Vec<[f32; 6]>, Error> {
    let w = words(path)?;
    let n = *w.first().ok_or_else(|| format!("{}: empty", path.display()))? as usize;
    let rays: Vec<[f32; 6]> = w[1..].chunks_exact(6).map(|c| std::array::from_fn(|k| f32::from_bits(c[k]))).collect();
    if rays.len() != n {
        return Err(format!("{}: {} rays where the header says {n}", path.display(), rays.len()).into());
    }
    Ok(rays)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median seconds of 3 builds, and the last one built. The one before is dropped before each build, as
/// embree_rays releases its scene.
fn time_build<T>(build: impl Fn() -> T) -> (f64, T) {
    let mut secs = Vec::new();
    let mut last = None;
    for _ in 0..3 {
        drop(last.take());
        let t0 = Instant::now();
        last = Some(black_box(build()));
        secs.push(t0.elapsed().as_secs_f64());
    }
    (median(secs), last.expect("three builds"))
}

/// A query over a chunk of rays, giving the number that hit.
type Query<'a> = &'a (dyn Fn(&[[f32; 6]]) -> usize + Sync);

fn cast(pool: Option<&rayon::ThreadPool>, rays: &[[f32; 6]], query: Query) -> usize {
    match pool {
        None => rays.chunks(CHUNK).map(query).sum(),
        Some(pool) => pool.install(|| rays.par_chunks(CHUNK).map(query).sum()),
    }
}

/// Times `closest` and `any` on both ray sets and prints their lines.
fn time_queries(
    tool: &str,
    dir: &Path,
    name: &str,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
    closest: Query,
    any: Query,
) -> Result<(), Error> {
    for kind in ["coherent", "incoherent"] {
        let rays = read_rays(&dir.join(format!("{name}.{kind}.rays")))?;
        for (query, f) in [("closest", closest), ("any", any)] {
            let hits = cast(pool, &rays, f);
            let mut rates = Vec::new();
            for _ in 0..5 {
                let t0 = Instant::now();
                black_box(cast(pool, &rays, f));
                rates.push(rays.len() as f64 / t0.elapsed().as_secs_f64() / 1e6);
            }
            println!("{tool} {name} {threads} {query} {kind} {:.3} {hits}", median(rates));
        }
    }
    Ok(())
}

fn run_tinybvh(
    mesh: &Mesh,
    dir: &Path,
    name: &str,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
) -> Result<(), Error> {
    // tinybvh's plain input, as its header's usage notes give it: 3 vertices of 4 floats per triangle (it also takes
    // an index list, but its leaves copy the triangles either way). Made once, outside the timed builds, as
    // embree_rays hands Embree its buffers.
    let vertices: Vec<tinybvh::Vec4> =
        mesh.corners().flatten().map(|[x, y, z]| tinybvh::Vec4([x, y, z, 0.0])).collect();
    let (secs, bvh) = {
        let _pinned = tinybvh::pin(threads);
        time_build(|| tinybvh::Bvh8::build(&vertices))
    };
    // Bytes: every buffer the BVH8_CPU holds after its build, as allocated, which is what the process holds for it,
    // as embree_rays counts what Embree's device holds: its traversal data (nodes and leaves, with its own copy of
    // the triangles; the buffer is sized for every MBVH<8> node as an interior node plus every leaf, about 2.5
    // times what it fills), and the binary BVH, its build fragments and the MBVH<8> it keeps from the build and
    // has no call to release. Not the input vertices, which its queries never read. stderr also gives the
    // traversal data in use, what a leaner tinybvh would keep.
    let (held, traversal) = bvh.bytes();
    let nf = mesh.triangles.len() as f64;
    println!("tinybvh {name} {threads} build {secs:.4} {:.1}", held as f64 / nf);
    eprintln!(
        "tinybvh {name}: {:.1} bytes/triangle held, {:.1} the traversal data in use (nodes and leaves with their \
         triangle copies)",
        held as f64 / nf,
        traversal as f64 / nf
    );
    time_queries("tinybvh", dir, name, threads, pool, &|c| bvh.cast(c, false), &|c| bvh.cast(c, true))
}

/// obvhs's CWBVH and its triangles in the BVH's order.
struct Obvhs {
    bvh: CwBvh,
    tris: Vec<RtTriangle>,
}

fn run_obvhs(
    mesh: &Mesh,
    dir: &Path,
    name: &str,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
) -> Result<(), Error> {
    // Its input type, made once outside the timed builds (the BVH keeps no reference to it).
    let input: Vec<Triangle> = mesh
        .corners()
        .map(|[a, b, c]| Triangle { v0: Vec3A::from(a), v1: Vec3A::from(b), v2: Vec3A::from(c) })
        .collect();
    let build = || {
        let bvh = build_cwbvh_from_tris(&input, BvhBuildParams::medium_build(), &mut Duration::default());
        let tris = bvh.primitive_indices.iter().map(|&i| RtTriangle::from(&input[i as usize])).collect();
        Obvhs { bvh, tris }
    };
    // On a pool of THREADS threads, one of its own when THREADS is 1 (rayon's global pool would take every CPU).
    let own;
    let build_pool = match pool {
        Some(pool) => pool,
        None => {
            own = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
            &own
        }
    };
    let (secs, o) = time_build(|| build_pool.install(build));
    // Bytes: the nodes, the primitive index map (to the input's triangle numbers, which a renderer needs for its
    // shading data) and the RtTriangle copy the queries read (v0, two edges and the normal: 64 bytes), as allocated,
    // which is what the process holds for them after the build, as embree_rays counts what Embree's device holds.
    // (obvhs sizes the node Vec for the worst case; stderr also gives the part in use, which `shrink_to_fit` would
    // leave.) The PLOC BVH2 it was built through is dropped inside build_cwbvh_from_tris.
    let (b, tris) = (&o.bvh, &o.tris);
    let aabb = size_of::<obvhs::aabb::Aabb>();
    let held = b.nodes.capacity() * size_of::<CwBvhNode>()
        + b.primitive_indices.capacity() * size_of::<u32>()
        + tris.capacity() * size_of::<RtTriangle>()
        + b.exact_node_aabbs.as_ref().map_or(0, |a| a.capacity() * aabb);
    let used = b.nodes.len() * size_of::<CwBvhNode>()
        + b.primitive_indices.len() * size_of::<u32>()
        + tris.len() * size_of::<RtTriangle>()
        + b.exact_node_aabbs.as_ref().map_or(0, |a| a.len() * aabb);
    let nf = mesh.triangles.len() as f64;
    println!("obvhs {name} {threads} build {secs:.4} {:.1}", held as f64 / nf);
    eprintln!(
        "obvhs {name}: {:.1} bytes/triangle held, {:.1} in use ({} nodes of {} allocated, {} primitive indices, \
         {} RtTriangles)",
        held as f64 / nf,
        used as f64 / nf,
        b.nodes.len(),
        b.nodes.capacity(),
        b.primitive_indices.len(),
        tris.len()
    );
    let ray = |r: &[f32; 6]| Ray::new_inf(Vec3A::new(r[0], r[1], r[2]), Vec3A::new(r[3], r[4], r[5]));
    let closest = |c: &[[f32; 6]]| {
        c.iter()
            .filter(|r| o.bvh.ray_traverse(ray(r), &mut RayHit::none(), |ray, id| o.tris[id].intersect(ray)))
            .count()
    };
    let any = |c: &[[f32; 6]]| {
        c.iter().filter(|r| !o.bvh.ray_traverse_miss(ray(r), |ray, id| o.tris[id].intersect(ray))).count()
    };
    time_queries("obvhs", dir, name, threads, pool, &closest, &any)
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [tool, dir, name, threads] = args.as_slice() else {
        return Err("usage: anchors TOOL DIR NAME THREADS   (TOOL: tinybvh or obvhs)".into());
    };
    let (dir, threads): (&Path, usize) = (Path::new(dir), threads.parse()?);
    if threads == 0 {
        return Err("THREADS must be at least 1".into());
    }
    let mesh = read_mesh(&dir.join(format!("{name}.mesh")))?;
    // Single-threaded casting on the calling thread when THREADS is 1, as embree_rays' OpenMP loop of one thread.
    let pool = if threads > 1 { Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?) } else { None };
    match tool.as_str() {
        "tinybvh" => run_tinybvh(&mesh, dir, name, threads, pool.as_ref()),
        "obvhs" => run_obvhs(&mesh, dir, name, threads, pool.as_ref()),
        _ => Err(format!("unknown tool {tool}: tinybvh or obvhs").into()),
    }
}
