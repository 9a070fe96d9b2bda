//! `vcm`, `bdpt` and `lt`: vertex connection and merging (Georgiev, Křivánek, Davidovič & Slusallek 2012,
//! "Light Transport Simulation with Vertex Connection and Merging", ACM TOG 31(6); the same method as
//! Hachisuka, Pantaleoni & Jensen 2012, "A Path Space Extension for Robust Light Transport Simulation"), and
//! the two methods that are settings of it: bidirectional path tracing (connections only; Veach 1997, ch. 10)
//! and light tracing (light subpaths connected to the camera only).
//!
//! # An iteration
//! Iteration (pass) `p` is numbered over the whole render, like a progressive photon-mapping pass, and is
//! traced exactly once in the whole farm:
//! 1. `N = width × height` light subpaths, subpath `j` from the stream `(seed, LightSubpath, p, j)`: a light
//!    chosen by power, a point and direction on it, then BSDF sampling with Russian roulette. Every vertex with a
//!    non-delta lobe is stored and connected to the camera (light tracing); the connection lands on any pixel.
//! 2. The stored vertices are indexed by a kd-tree for merging.
//! 3. Camera subpath of pixel `(x, y)` is its camera sample `p` (the stream of every other method). At each
//!    vertex with a non-delta lobe it adds: next-event estimation (a light chosen by power, a point on it),
//!    connections to every vertex of light subpath `j = y·width + x`, and merges with every stored light vertex
//!    within the radius `r_p`; emission found by the camera subpath is added too.
//!
//! Each path so found is weighted by the power heuristic over every technique that could have sampled it —
//! each split of it into a light and a camera subpath, joined by a connection or by a merge — using
//! Georgiev's recursive quantities `dVCM`, `dVC`, `dVM` carried along each subpath ("Implementing Vertex
//! Connection and Merging", technical report, Saarland University 2012, eqs. 31–55; we follow its numbering in
//! the comments; the quantities and the weights are in the file `vcm/mis.rs`: [`Iteration`], [`MisState`],
//! [`weights`]). A merge is the photon-map estimate with the photon maps' kernel (`render.photons.kernel`)
//! at radius `r_p`, with acceptance probability `π r² p_A` in the weights (the report's `η_VCM = π r² N`).
//!
//! The radius shrinks as progressive photon mapping's (Knaus & Zwicker 2011, eq. 15): `r_p² = r_0² ·
//! Π (i + α)/(i + 1)`, `r_0` = [`Prepared::merge_radius`] (`render.photons.merge_radius`, by default one pixel's width at the focus
//! distance), `α = render.photons.alpha`, so merging's bias vanishes
//! and the method is consistent; `bdpt` and `lt` are unbiased.
//!
//! Russian roulette at a vertex continues with probability `q = min(1, max albedo)`, a property of the vertex
//! (our BSDFs' albedos do not depend on direction), so the same `q` enters the forward and reverse densities
//! and the weights stay exact. Area conversions of densities use the geometric normal; throughputs the shading
//! cosine and, on light subpaths, the adjoint BSDF (Veach 1997, §5.3).
//!
//! # Exact sums
//! Every pixel's estimate of a pass is one fixed-point value, as for progressive photon mapping: the camera
//! subpath's radiance rounded once, plus each light-tracing contribution that landed there rounded once, added
//! as integers (so in any order), clamped to `[0, MAX_UNIT_SUM]`. The image therefore depends only on (scene,
//! seed, passes), never on the farm's cut, the workers or the threads.
//!
//! # What it does not do
//! Scenes with participating media (or an `interface` material) are rendered by the volumetric path tracer,
//! one camera sample per pass: the subpaths here do not cross media. Light tracing (`lt`) sees nothing through
//! mirror or glass directly in front of the camera, as no light subpath can connect there.

mod join;
mod mis;
mod splats;

pub use mis::{Iteration, MisState, weights};

use super::radius::RadiusSequence;
use super::samples::{camera_sample, for_each_pixel};
use super::sums::{BlockSums, MAX_UNIT_SUM, finite_or_zero, to_fixed};
use crate::Rgb;
use crate::geometry::{Hit, NONE};
use crate::integrator::{reaches, unoccluded};
use crate::light::Light;
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::rng::{Domain, Sampler};
use crate::math::{Ray, offset_ray_origin_by_error};
use crate::method::Techniques;
use crate::prepare::Prepared;
use crate::prepare::budget::{LIGHT_VERTEX_BYTES, MERGE_TREE_BYTES_PER_VERTEX, SPLAT_BYTES};
use crate::prepare::tracer::Tracer;
use crate::run::{Guard, RunError};
use glam::Vec3A;
use join::join;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use splats::{Bands, ChunkSplats, Splat, Splats};
use std::f32::consts::{FRAC_1_PI, PI};
use std::ops::Range;
use std::time::Instant;

/// Light subpaths traced per parallel chunk (fixed, so the vertex order does not depend on the thread pool).
const CHUNK: usize = 1024;

/// A stored light-subpath vertex.
#[derive(Clone, Copy, Debug)]
pub struct LightVertex {
    /// The surface point and a bound on its rounding error.
    pub p: Vec3A,
    p_error: Vec3A,
    /// The BSDF there.
    pub bsdf: Bsdf,
    /// Unit direction towards the previous vertex (where the light came from).
    pub wo: Vec3A,
    /// Throughput from the light (flux-like: emitted radiance over the densities, not divided by `N`).
    pub beta: Rgb,
    /// Russian roulette's continuation probability at this vertex.
    q: f32,
    /// The MIS quantities.
    pub mis: MisState,
}

/// Russian roulette's continuation probability at a vertex: the largest channel of the albedo, at most 1.
#[inline]
pub fn continuation(bsdf: &Bsdf, wo: Vec3A) -> f32 {
    let q = bsdf.albedo(wo).max_element();
    if q.is_finite() { q.clamp(0.0, 1.0) } else { 0.0 }
}

/// The vertices, subpath ends, splats and rays of one parallel chunk of light subpaths.
type LightChunk = (Vec<LightVertex>, Vec<u32>, ChunkSplats, u64);

/// The light subpaths of one iteration.
pub struct LightPaths {
    /// Every stored vertex, subpath after subpath.
    pub vertices: Vec<LightVertex>,
    /// `ends[j]`: one past the last vertex of subpath `j`.
    pub ends: Vec<u32>,
    /// Light-tracing contributions, by band of rows.
    pub splats: Splats,
    /// Rays traced.
    pub rays: u64,
}

impl LightPaths {
    /// The vertices of subpath `j`.
    pub fn of(&self, j: usize) -> &[LightVertex] {
        let end = self.ends.get(j).copied().unwrap_or(0) as usize;
        let start = if j == 0 { 0 } else { self.ends.get(j - 1).copied().unwrap_or(0) as usize };
        self.vertices.get(start..end).unwrap_or(&[])
    }
}

/// Traces the `N` light subpaths of iteration `pass` (in parallel, in fixed chunks, concatenated in order),
/// stopping when `guard.cancel` is set (checked before every subpath) or when what they store (each vertex
/// and splat twice, in its chunk and joined, and each vertex's share of the merge index) passes
/// `guard.storage_bytes` (one count over all subpaths, so the outcome does not depend on the threads).
/// Returns them with their merge index when `it` merges ([`merge_tree`]; `None` otherwise or when they
/// cannot be indexed).
pub fn trace_light_paths(
    prep: &Prepared,
    it: &Iteration,
    pass: u32,
    guard: &Guard,
) -> Result<(LightPaths, Option<Tree>), RunError> {
    // The count itself, not `it.light_paths` (an f32, inexact above 2²⁴ pixels).
    let n = prep.camera.width as usize * prep.camera.height as usize;
    let meter = guard.meter("light vertex", "camera.width × camera.height", prep.settings.max_depth);
    let bands = Bands::new(prep.camera.width, prep.camera.height);
    let chunks: Vec<LightChunk> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let (mut vertices, mut ends, mut splats, mut rays) = (Vec::new(), Vec::new(), Vec::new(), 0u64);
            for j in c * CHUNK..((c + 1) * CHUNK).min(n) {
                guard.cancel.check()?;
                meter.check()?;
                let (v0, s0) = (vertices.len(), splats.len());
                let s = Sampler::new(prep.settings.seed, Domain::LightSubpath, u64::from(pass), 0, j as u64);
                let mut tracer = Tracer::new(prep, s);
                light_subpath(&mut tracer, it, &mut vertices, &mut splats);
                rays += tracer.rays;
                ends.push(vertices.len() as u32);
                let (dv, ds) = ((vertices.len() - v0) as u64, (splats.len() - s0) as u64);
                meter.add(stored_bytes(it, 1, dv, ds))?;
            }
            Ok((vertices, ends, ChunkSplats::new(&splats, &bands), rays))
        })
        .collect::<Result<_, RunError>>()?;
    // The chunks joined in order, each array gathered in parallel: a serial join (a copy of every vertex into
    // fresh memory) kept one core busy and the other idle for a tenth of an iteration.
    let (vertices, firsts) = join(&chunks.iter().map(|c| c.0.as_slice()).collect::<Vec<_>>());
    // The merge index is built beside the other joins: the first partitions of its build are serial.
    let (tree, (splats, ends)) = rayon::join(
        || if it.techniques.merge { merge_tree(&vertices) } else { None },
        || {
            let splats = Splats::join(&chunks.iter().map(|c| &c.2).collect::<Vec<_>>(), bands);
            let ends = (0..n).into_par_iter().map(|j| chunks[j / CHUNK].1[j % CHUNK] + firsts[j / CHUNK] as u32);
            (splats, ends.collect())
        },
    );
    let rays = chunks.iter().map(|c| c.3).sum();
    Ok((LightPaths { vertices, ends, splats, rays }, tree))
}

/// Bytes that `subpaths` light subpaths with `vertices` vertices and `splats` splats in all store: each vertex
/// and splat twice (in its chunk and joined), each vertex's share of the merge index when `it` merges, and
/// each subpath's end.
fn stored_bytes(it: &Iteration, subpaths: u64, vertices: u64, splats: u64) -> u64 {
    let tree = if it.techniques.merge { MERGE_TREE_BYTES_PER_VERTEX } else { 0 };
    vertices * (2 * LIGHT_VERTEX_BYTES + tree) + splats * 2 * SPLAT_BYTES + subpaths * 8
}

/// Emission of a light subpath: the first ray, the throughput and MIS quantities before the first hit (eqs.
/// 31–33, with delta lights as eqs. 48–50), and whether the light is infinitely far (its densities are per
/// solid angle at the first hit, not per area: the report's §5.1).
fn emit(tracer: &mut Tracer, it: &Iteration) -> Option<(Ray, Subpath, bool)> {
    let prep = tracer.prep;
    let (i, pick) = prep.lights.choose(tracer.sampler.next_f32())?;
    let e = prep.lights.lights.get(i)?.sample_le(&prep.light_scene(), pick, &mut tracer.sampler)?;
    if !(e.pdf_w > 0.0 && e.beta.is_finite()) {
        return None;
    }
    let mis = MisState::emitted(it, e.pdf_a, e.pdf_w, e.cos, e.delta);
    Some((e.ray, Subpath { beta: e.beta, mis }, e.infinite))
}

/// A subpath after its last vertex: its throughput and its MIS quantities.
#[derive(Clone, Copy, Debug)]
struct Subpath {
    /// Throughput from the subpath's origin (on a light subpath flux-like: emitted radiance over the densities).
    beta: Rgb,
    /// The MIS quantities.
    mis: MisState,
}

/// Traces one light subpath: stores its vertices (when connecting or merging) and connects each to the camera
/// (when connecting, or light tracing).
fn light_subpath(tracer: &mut Tracer, it: &Iteration, vertices: &mut Vec<LightVertex>, splats: &mut Vec<Splat>) {
    let prep = tracer.prep;
    let Some((mut ray, mut path, infinite)) = emit(tracer, it) else { return };
    let tech = it.techniques;
    while let Some(hit) = tracer.intersect(&ray, f32::INFINITY) {
        let wo = -ray.d;
        // From an infinitely distant light the first segment's length is not part of the densities (§5.1).
        let dist = if infinite && path.mis.len == 1 { 1.0 } else { hit.t };
        path.mis.arrive(dist, wo.dot(hit.n).abs());
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit, &prep.textures);
        if bsdf.black_from(wo) {
            break;
        }
        let q = continuation(&bsdf, wo);
        if bsdf.has_non_delta() {
            let v = LightVertex { p: hit.p, p_error: hit.p_error, bsdf, wo, beta: path.beta, q, mis: path.mis };
            if tech.connect || tech.merge {
                vertices.push(v);
            }
            if (tech.connect || tech.light_tracing_only) && path.mis.len < it.max_len {
                connect_to_camera(tracer, it, &hit, &v, splats);
            }
        }
        if path.mis.len + 2 > it.max_len {
            break;
        }
        let Some(wi) = continue_subpath(tracer, it, &bsdf, wo, q, TransportMode::Importance, &mut path) else {
            break;
        };
        ray = hit.spawn_ray(wi);
    }
}

/// One step of a subpath (SmallVCM's `SampleScattering`): the surface-bounce step at a vertex reached from
/// `wo` in `mode` (light subpaths carry importance, camera subpaths radiance; [`Tracer::sample_bsdf`]), Russian
/// roulette with continuation probability `q`, and the update of the MIS quantities and of the throughput by
/// `f·|wi·ns| / (pdf·q)` (on a light subpath with the adjoint BSDF's shading-normal factor,
/// [`Bsdf::sample_weight`]). The new direction, or `None` when the subpath ends.
fn continue_subpath(
    tracer: &mut Tracer,
    it: &Iteration,
    bsdf: &Bsdf,
    wo: Vec3A,
    q: f32,
    mode: TransportMode,
    path: &mut Subpath,
) -> Option<Vec3A> {
    let bs = tracer.sample_bsdf(bsdf, wo, mode)?;
    if tracer.sampler.next_f32() >= q {
        return None;
    }
    let pdf_rev = if bs.delta { bs.pdf } else { bsdf.pdf(bs.wi, wo) };
    path.mis.scatter(it, bs.wi.dot(bsdf.ng).abs(), bs.pdf * q, pdf_rev * q, bs.delta);
    path.beta *= bsdf.sample_weight(wo, &bs, bs.pdf * q, mode);
    (path.beta.is_finite() && path.beta != Rgb::ZERO).then_some(bs.wi)
}

/// Light tracing: connects light vertex `v` (at `hit`) to a point on the lens and adds its contribution to the
/// pixel it lands on (SmallVCM's `ConnectToCamera`; the report's eqs. 46–47). The contribution is
/// `w · β · f · |cos_x| · W_e / (d² N)`, with `W_e` the camera's importance per pixel
/// ([`crate::camera::Camera::pixel_direction_pdf`]).
fn connect_to_camera(tracer: &mut Tracer, it: &Iteration, hit: &Hit, v: &LightVertex, splats: &mut Vec<Splat>) {
    let prep = tracer.prep;
    let camera = &prep.camera;
    let lens = camera.lens_point(tracer.sampler.next_2d());
    let to_lens = lens - v.p;
    let dist2 = to_lens.length_squared();
    if dist2.is_nan() || dist2 <= 0.0 {
        return;
    }
    let dist = dist2.sqrt();
    let w = to_lens / dist;
    let Some((film, cos_camera)) = camera.film_position(lens, -w) else { return };
    let f = v.bsdf.f(v.wo, w, TransportMode::Importance) * v.bsdf.adjoint_correction(v.wo, w);
    if f == Rgb::ZERO {
        return;
    }
    let camera_pdf_w = camera.pixel_direction_pdf(cos_camera);
    // The density of this vertex sampled from the camera, in area measure.
    let camera_pdf_a = camera_pdf_w * w.dot(v.bsdf.ng).abs() / dist2;
    let weight = weights::light_trace(it, &v.mis, camera_pdf_a, v.bsdf.pdf(w, v.wo) * v.q);
    let c = v.beta * f * (weight * w.dot(v.bsdf.frame.n).abs() * camera_pdf_w / (dist2 * it.light_paths));
    if !c.is_finite() || c == Rgb::ZERO {
        return;
    }
    tracer.rays += 1;
    if !unoccluded(prep, hit, w, lens) {
        return;
    }
    let (x, y) = ((film.x as u32).min(camera.width - 1), (film.y as u32).min(camera.height - 1));
    splats.push((y * camera.width + x, c));
}

/// A kd-tree over the light vertices' positions (items are vertex indices), for merging.
type Tree = ImmutableKdTree<f32, 3>;

/// The merging index of an iteration's light vertices; `None` when there are none.
pub fn merge_tree(vertices: &[LightVertex]) -> Option<Tree> {
    if vertices.is_empty() || u32::try_from(vertices.len()).is_err() {
        return None;
    }
    let positions: Vec<[f32; 3]> = vertices.par_iter().map(|v| v.p.to_array()).collect();
    if positions.iter().flatten().any(|c| !c.is_finite()) {
        return None;
    }
    Tree::new_from_source_parallel(&positions, |p, dim| p[dim], |i, _| i as u32).ok()
}

/// What a camera subpath sees of one iteration's light subpaths.
pub struct LightSide<'a> {
    /// The light subpaths.
    pub paths: &'a LightPaths,
    /// Their merging index (with merging only).
    pub tree: Option<&'a Tree>,
}

/// The camera subpath of sample `pass` of pixel `(x, y)`: the radiance it gathers by every technique of `it`
/// (SmallVCM's camera loop). Non-finite contributions count as zero. Adds the rays it traces to `rays`.
pub fn camera_subpath(
    prep: &Prepared,
    it: &Iteration,
    light: &LightSide,
    (x, y): (u32, u32),
    pass: u32,
    rays: &mut u64,
) -> Rgb {
    let (ray, s) = camera_sample(prep, prep.settings.seed, x, y, pass);
    let mut tracer = Tracer::new(prep, s);
    let l = camera_walk(&mut tracer, it, light, ray, (y * prep.camera.width + x) as usize);
    *rays += tracer.rays;
    l
}

/// [`camera_subpath`] from its camera ray `ray`, in pixel `index` (`y·width + x`, the index of the light subpath
/// it connects to).
fn camera_walk(tracer: &mut Tracer, it: &Iteration, light: &LightSide, mut ray: Ray, index: usize) -> Rgb {
    let prep = tracer.prep;
    let camera = &prep.camera;
    let tech = it.techniques;
    let cos_camera = ray.d.dot(camera.forward());
    if cos_camera.is_nan() || cos_camera <= 0.0 {
        return Rgb::ZERO;
    }
    let camera_pdf_w = camera.pixel_direction_pdf(cos_camera);
    let mut path = Subpath { beta: Rgb::ONE, mis: MisState::from_camera(it, camera_pdf_w) };
    let mut l = Rgb::ZERO;
    let own_path = light.paths.of(index);
    loop {
        let Some(hit) = tracer.intersect(&ray, f32::INFINITY) else {
            l += finite_or_zero(path.beta * escaped(prep, it, ray.d, &path.mis));
            break;
        };
        let wo = -ray.d;
        path.mis.arrive(hit.t, wo.dot(hit.n).abs());
        if hit.light != NONE {
            let le = emission(prep, it, &hit, wo, &path.mis);
            l += finite_or_zero(path.beta * le);
        }
        if tech.light_tracing_only || path.mis.len >= it.max_len {
            break;
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit, &prep.textures);
        if bsdf.black_from(wo) {
            break;
        }
        let q = continuation(&bsdf, wo);
        let vertex = CameraVertex { hit: &hit, bsdf: &bsdf, wo, q, mis: path.mis };
        if bsdf.has_non_delta() {
            if tech.connect {
                l += finite_or_zero(path.beta * direct_light(tracer, it, &vertex));
                for v in own_path {
                    if v.mis.len + 1 + path.mis.len > it.max_len {
                        break;
                    }
                    l += finite_or_zero(path.beta * connect(tracer, it, &vertex, v));
                }
            }
            if let (true, Some(tree)) = (tech.merge, light.tree) {
                l += finite_or_zero(path.beta * merge(it, &vertex, &light.paths.vertices, tree));
            }
        }
        let Some(wi) = continue_subpath(tracer, it, &bsdf, wo, q, TransportMode::Radiance, &mut path) else {
            break;
        };
        ray = hit.spawn_ray(wi);
    }
    l
}

/// A camera-subpath vertex with a non-delta lobe.
struct CameraVertex<'a> {
    hit: &'a Hit,
    bsdf: &'a Bsdf,
    wo: Vec3A,
    q: f32,
    mis: MisState,
}

/// Emission at `hit` on an area light, found by a camera subpath in `state`, weighted against the techniques
/// that end the path on the light by sampling it (eqs. 42–43); in full when the camera sees the light directly.
fn emission(prep: &Prepared, it: &Iteration, hit: &Hit, wo: Vec3A, state: &MisState) -> Rgb {
    let Some(light) = prep.lights.lights.get(hit.light as usize) else { return Rgb::ZERO };
    let le = light.le(&prep.light_scene(), hit, wo);
    if le == Rgb::ZERO || state.len == 1 {
        return le;
    }
    if it.techniques.light_tracing_only {
        return Rgb::ZERO;
    }
    // A point light has no surface to be found on: its `le` is zero, returned above.
    let (direct_pdf_a, emission_pdf_w) = light.pdf_le(prep.lights.pmf(hit.light as usize), wo.dot(hit.n).abs());
    le * weights::emission(state, direct_pdf_a, emission_pdf_w)
}

/// The environment's radiance along a camera subpath in `state` that escaped in direction `d`, weighted as
/// [`emission`] weighs an area light's (SmallVCM's background light: densities per solid angle, §5.1).
fn escaped(prep: &Prepared, it: &Iteration, d: Vec3A, state: &MisState) -> Rgb {
    let Some((i, env)) = prep.lights.environment() else { return Rgb::ZERO };
    let scene = prep.light_scene();
    let le = env.le_escaped(&scene, d);
    if le == Rgb::ZERO || state.len == 1 {
        return le;
    }
    if it.techniques.light_tracing_only {
        return Rgb::ZERO;
    }
    let (direct_pdf, emission_pdf_w) = env.pdf_le_escaped(&scene, prep.lights.pmf(i), d);
    le * weights::emission(state, direct_pdf, emission_pdf_w)
}

/// Next-event estimation at a camera vertex: a light chosen by power, a point on it (SmallVCM's
/// `DirectIllumination`; eqs. 44–45).
fn direct_light(tracer: &mut Tracer, it: &Iteration, c: &CameraVertex) -> Rgb {
    let prep = tracer.prep;
    let (u, u2) = (tracer.sampler.next_f32(), tracer.sampler.next_2d());
    let Some((i, pick)) = prep.lights.choose(u) else { return Rgb::ZERO };
    let Some(light) = prep.lights.lights.get(i) else { return Rgb::ZERO };
    let Some(ls) = light.sample_li(&prep.light_scene(), c.hit.p, u2) else { return Rgb::ZERO };
    // Radiance (or intensity, or irradiance), the solid-angle density of the sample at the vertex (for a point
    // or spot light, the squared distance that turns its intensity into irradiance; 1 for a directional
    // light), the emission density of the opposite direction, and the cosine at the light (SmallVCM's
    // `Illuminate` of each light).
    let (radiance, direct_pdf_w, emission_pdf_w, cos_light) = match *light {
        Light::Point { intensity, .. } => (intensity, ls.dist * ls.dist, 1.0 / (4.0 * PI), 1.0),
        Light::Spot { .. } => (light.intensity(-ls.wi), ls.dist * ls.dist, light.direction_pdf(), 1.0),
        Light::Area { area, two_sided, .. } => {
            let cos_light = ls.dist * ls.dist / (ls.pdf * area);
            let sides = if two_sided { 0.5 } else { 1.0 };
            (ls.li, ls.pdf, cos_light * FRAC_1_PI * sides / area, cos_light)
        }
        Light::Directional { bounds, .. } => (ls.li, 1.0, bounds.disc_pdf(), 1.0),
        Light::Environment { bounds, .. } => (ls.li, ls.pdf, ls.pdf * bounds.disc_pdf(), 1.0),
    };
    let f = c.bsdf.f(c.wo, ls.wi, TransportMode::Radiance);
    if f == Rgb::ZERO || !(direct_pdf_w > 0.0 && pick > 0.0 && cos_light > 0.0) {
        return Rgb::ZERO;
    }
    let bsdf_pdf = if ls.delta { 0.0 } else { c.bsdf.pdf(c.wo, ls.wi) * c.q };
    let bsdf_pdf_rev = c.bsdf.pdf(ls.wi, c.wo) * c.q;
    let emission_ratio = emission_pdf_w * ls.wi.dot(c.bsdf.ng).abs() / (direct_pdf_w * cos_light);
    let weight = weights::direct(it, &c.mis, bsdf_pdf, bsdf_pdf_rev, pick * direct_pdf_w, emission_ratio);
    let contribution = radiance * f * (weight * ls.wi.dot(c.bsdf.frame.n).abs() / (pick * direct_pdf_w));
    tracer.rays += 1;
    if !reaches(prep, c.hit, &ls) {
        return Rgb::ZERO;
    }
    contribution
}

/// Connects camera vertex `c` to light vertex `v` (SmallVCM's `ConnectVertices`; eqs. 40–41).
fn connect(tracer: &mut Tracer, it: &Iteration, c: &CameraVertex, v: &LightVertex) -> Rgb {
    let d = v.p - c.hit.p;
    let dist2 = d.length_squared();
    if dist2.is_nan() || dist2 <= 0.0 {
        return Rgb::ZERO;
    }
    let w = d / dist2.sqrt();
    let f_camera = c.bsdf.f(c.wo, w, TransportMode::Radiance);
    if f_camera == Rgb::ZERO {
        return Rgb::ZERO;
    }
    let f_light = v.bsdf.f(v.wo, -w, TransportMode::Importance) * v.bsdf.adjoint_correction(v.wo, -w);
    if f_light == Rgb::ZERO {
        return Rgb::ZERO;
    }
    let g = w.dot(c.bsdf.frame.n).abs() * w.dot(v.bsdf.frame.n).abs() / dist2;
    // Densities of each end sampling the other, in area measure.
    let camera_pdf_a = c.bsdf.pdf(c.wo, w) * c.q * w.dot(v.bsdf.ng).abs() / dist2;
    let light_pdf_a = v.bsdf.pdf(v.wo, -w) * v.q * w.dot(c.bsdf.ng).abs() / dist2;
    let camera_pdf_rev = c.bsdf.pdf(w, c.wo) * c.q;
    let light_pdf_rev = v.bsdf.pdf(-w, v.wo) * v.q;
    let weight = weights::connect(it, &c.mis, &v.mis, camera_pdf_a, camera_pdf_rev, light_pdf_a, light_pdf_rev);
    let contribution = f_camera * f_light * v.beta * (weight * g);
    if contribution == Rgb::ZERO || !contribution.is_finite() {
        return Rgb::ZERO;
    }
    tracer.rays += 1;
    let target = offset_ray_origin_by_error(v.p, v.p_error, v.bsdf.ng, -w);
    if !unoccluded(tracer.prep, c.hit, w, target) {
        return Rgb::ZERO;
    }
    contribution
}

/// Merges camera vertex `c` with the light vertices within the radius (SmallVCM's `RangeQuery`; eqs. 38–39):
/// `Σ w · f · β · K(d/r) / (r² N)`, skipping vertices as the photon maps do (arriving from behind, or stored
/// on a surface facing away).
fn merge(it: &Iteration, c: &CameraVertex, vertices: &[LightVertex], tree: &Tree) -> Rgb {
    crate::photon::with_scratch(|scratch| merge_in(it, c, vertices, tree, scratch))
}

/// [`merge`] with the gather's storage (the photon estimates' per-thread buffer).
fn merge_in(
    it: &Iteration,
    c: &CameraVertex,
    vertices: &[LightVertex],
    tree: &Tree,
    scratch: &mut Vec<(u32, f32)>,
) -> Rgb {
    scratch.clear();
    let q: [f32; 3] = c.hit.p.to_array();
    tree.query(&q).within::<SquaredEuclidean<f32>>(it.r2).unsorted().visit(|r| scratch.push((r.item, r.distance)));
    let n = c.hit.normal_towards(c.wo);
    let inv_r2 = 1.0 / it.r2;
    let mut sum = Rgb::ZERO;
    for &(index, d2) in scratch.iter() {
        let Some(v) = vertices.get(index as usize) else { continue };
        if v.mis.len + c.mis.len > it.max_len {
            continue;
        }
        let wi = v.wo;
        let n_light = if wi.dot(v.bsdf.ng) >= 0.0 { v.bsdf.ng } else { -v.bsdf.ng };
        if wi.dot(n) <= 0.0 || n_light.dot(n) <= 0.0 {
            continue;
        }
        let f = c.bsdf.f(c.wo, wi, TransportMode::Radiance) * c.bsdf.arrival_correction(wi);
        if f == Rgb::ZERO {
            continue;
        }
        // The forward density continues the camera subpath (its vertex's roulette); the reverse one stands for
        // the light subpath continuing from its own vertex, so it takes that vertex's roulette (SmallVCM does
        // the same): the two vertices differ, and so may their albedos.
        let camera_pdf = c.bsdf.pdf(c.wo, wi) * c.q;
        let camera_pdf_rev = c.bsdf.pdf(wi, c.wo) * v.q;
        let weight = weights::merge(it, &c.mis, &v.mis, camera_pdf, camera_pdf_rev);
        // A weight made non-finite by a degenerate vertex (a grazing arrival) drops that vertex, not the others.
        if !weight.is_finite() {
            continue;
        }
        sum += f * v.beta * (weight * it.kernel.weight(d2 * inv_r2));
    }
    sum * it.vm_normalization
}

/// Renders vcm's (or bdpt's, or lt's) iterations `passes` over rows `rows`: each pixel channel's sum over those
/// iterations of its fixed-point estimate (see the module docs). Every iteration traces all `N` light
/// subpaths, whatever the rows. `progress` gets the iterations finished so far; `guard` stops the render
/// (before every light subpath and pixel) and bounds what one iteration's light subpaths store.
///
/// The light subpaths of the next iteration are traced while the camera subpaths of this one run, so that the
/// tail of either keeps no core idle. The two together stay within the storage bound: the next iteration is
/// traced ahead within what this one leaves, and when it does not fit there it is traced again, alone, once
/// this one is done. So an iteration fails on its storage only when it alone passes the bound, and its bits do
/// not depend on which way it was traced.
pub(super) fn render_passes(
    prep: &Prepared,
    techniques: Techniques,
    rows: Range<u32>,
    passes: Range<u32>,
    progress: &(dyn Fn(u32) + Sync),
    guard: &Guard,
) -> Result<BlockSums, RunError> {
    let ph = &prep.settings.photons;
    let camera = &prep.camera;
    let light_paths = (camera.width as usize * camera.height as usize) as f32;
    let mut sums = vec![0i64; 3 * camera.width as usize * rows.len()];
    let mut pass_sums = vec![0i64; sums.len()];
    let (mut rays, mut photon_seconds) = (0u64, 0.0f64);
    let mut radius = RadiusSequence::at(prep.merge_radius(), ph.alpha, passes.start);
    let mut iteration = || {
        let it = Iteration::new(techniques, light_paths, radius.r2(), ph.kernel, prep.settings.max_depth);
        radius = radius.next();
        it
    };
    let mut it = iteration();
    let mut ahead: Option<Result<TracedIteration, RunError>> = None;
    for (done, pass) in passes.clone().enumerate() {
        let traced = match ahead.take() {
            Some(Ok(traced)) => traced,
            // It did not fit beside the last iteration: alone it has the whole bound.
            None | Some(Err(RunError::Storage(_))) => trace_iteration(prep, &it, pass, guard)?,
            Some(Err(e)) => return Err(e),
        };
        photon_seconds += traced.seconds;
        rays += traced.paths.rays;
        let next = (pass + 1 < passes.end).then(&mut iteration);
        let beside = Guard { cancel: guard.cancel, storage_bytes: guard.storage_bytes.saturating_sub(traced.bytes) };
        let (camera_rays, traced_ahead) = rayon::join(
            || camera_pass(prep, &it, &traced, &rows, pass, &mut pass_sums, guard),
            || next.as_ref().map(|next| trace_iteration(prep, next, pass + 1, &beside)),
        );
        rays += camera_rays?;
        sums.par_iter_mut().zip(&pass_sums).with_min_len(1 << 14).for_each(|(s, p)| {
            *s = s.saturating_add((*p).clamp(0, MAX_UNIT_SUM));
        });
        progress(done as u32 + 1);
        ahead = traced_ahead;
        if let Some(next) = next {
            it = next;
        }
    }
    let photon_paths = u64::from(camera.width) * u64::from(camera.height) * u64::from(passes.end - passes.start);
    Ok(BlockSums { rows, units: passes, sums, rays, photon_paths, photon_seconds })
}

/// One iteration's light subpaths, their merge index, the bytes they store (as [`trace_light_paths`] counts
/// them) and the seconds they took.
struct TracedIteration {
    paths: LightPaths,
    tree: Option<Tree>,
    bytes: u64,
    seconds: f64,
}

/// Traces iteration `pass`'s light subpaths and their merge index within `guard` ([`trace_light_paths`]).
fn trace_iteration(prep: &Prepared, it: &Iteration, pass: u32, guard: &Guard) -> Result<TracedIteration, RunError> {
    let t0 = Instant::now();
    let (paths, tree) = trace_light_paths(prep, it, pass, guard)?;
    if it.techniques.merge && tree.is_none() && !paths.vertices.is_empty() {
        tracing::warn!("pass {pass}: the light vertices could not be indexed; this pass merges nothing");
    }
    let bytes = stored_bytes(it, paths.ends.len() as u64, paths.vertices.len() as u64, paths.splats.len() as u64);
    Ok(TracedIteration { paths, tree, bytes, seconds: t0.elapsed().as_secs_f64() })
}

/// Writes iteration `pass`'s fixed-point estimate of every pixel of rows `rows` into `pass_sums`: each camera
/// subpath's value, plus the light-tracing splats that land in those rows. Returns the rays the camera
/// subpaths traced; stops when `guard.cancel` is set.
fn camera_pass(
    prep: &Prepared,
    it: &Iteration,
    traced: &TracedIteration,
    rows: &Range<u32>,
    pass: u32,
    pass_sums: &mut [i64],
    guard: &Guard,
) -> Result<u64, RunError> {
    let width = prep.camera.width;
    let light = LightSide { paths: &traced.paths, tree: traced.tree.as_ref() };
    let pixel = |x, y, px: &mut [i64], rays: &mut u64| {
        let c = camera_subpath(prep, it, &light, (x, y), pass, rays);
        for (s, v) in px.iter_mut().zip(c.to_array()) {
            *s = to_fixed(v);
        }
    };
    let rays = for_each_pixel(width as usize, rows, pass_sums, guard.cancel, pixel)?;
    traced.paths.splats.add_to(rows, pass_sums);
    Ok(rays)
}
