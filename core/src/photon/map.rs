//! Photon maps and the reflected-radiance estimate.
//!
//! A [`PhotonMap`] owns its photons (the truth) and a static kd-tree over their positions (an index that is
//! rebuilt, never trusted from the wire). [`PhotonMap::estimate`] turns the photons near a point into
//! reflected radiance with a normalised kernel, so every kernel gives the same answer on a uniform density.
//!
//! An [`Estimator`] as it appears in a TOML scene:
//! ```toml
//! gather = { k_nearest = { k = 100, max_radius = 0.25 } }   # or { radius = { radius = 0.05 } }
//! kernel = "epanechnikov"   # box | cone | epanechnikov | gaussian | linear | quadratic
//! disc = 0.25               # optional: max |distance to the tangent plane| / gather radius
//! same_object = false       # only photons stored on the object that was hit
//! ```
//!
//! ## The estimate
//! Reflected radiance at `p` towards `wo` (Jensen, *Realistic Image Synthesis Using Photon Mapping*, 2001,
//! with a kernel in place of the box):
//!
//! `L(p, wo) ≈ Σ_p f_r(p, wo, wi_p) · Φ_p · K(d_p / r) / r²`
//!
//! where `d_p` is the photon's distance from `p`, `r` the gather radius, and every kernel is normalised over
//! the unit disc, `∫₀¹ K(t) 2πt dt = 1`, so that `Σ Φ_p K(d_p/r)/r²` is an unbiased estimate of the irradiance
//! `E` when the photons on a flat surface have uniform density (Campbell's theorem: its mean is
//! `λ Φ ∫_disc K(d/r)/r² dA = λ Φ`).
//!
//! With a k-nearest gather the radius is the distance to the k-th photon, which sits on the boundary by
//! construction; counting it too biases the estimate high by `k/(k−1)` (for the box kernel, or any kernel with
//! `K(1) ≠ 0`). We use the k-th photon's distance as `r` and sum only the `k − 1` photons inside. Given the
//! k-th distance, those `k − 1` are uniform in the disc, and `(k−1)/(π d_k²)` is an unbiased density estimate
//! for uniformly scattered photons, so the estimate is unbiased for every kernel. When fewer than `k` photons
//! lie within `max_radius`, `r = max_radius` and every photon found counts (a plain radius estimate). A
//! k-nearest gather therefore needs `k ≥ 2`; with `k = 1` it sees no photon inside the radius.
//!
//! Photons are skipped when
//! - they arrive from behind the surface (`wi · n ≤ 0`) or were stored on a surface facing away
//!   (`n_photon · n ≤ 0`, which also drops photons on a perpendicular wall at a corner);
//! - `disc` is set and they lie farther than `disc · r` from the tangent plane (`|(p_photon − p) · n|`),
//!   which keeps photons on nearby parallel surfaces (thin walls, steps, the far side of a corner) out;
//! - `same_object` is set and they were stored on another object (the origin's filter).
//!
//! A skipped photon still counts towards `k`, and the radius stays what the gather found: the density is
//! per unit area of the disc around `p`, and skipped photons simply belong to some other surface.

use std::num::NonZeroUsize;
use std::sync::Arc;

use glam::Vec3A;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::{Deserialize, Serialize};

use super::kernel::{Estimator, Gather};
use crate::Rgb;
use crate::math::fmath;

/// A photon stored at a diffuse hit. 36 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Photon {
    /// Position (world space).
    pub p: [f32; 3],
    /// Unit direction towards where the photon came from ([`pack_unit`]); `wi · n > 0`.
    pub wi: u32,
    /// Geometric normal of the surface it was stored on, facing the side it arrived from ([`pack_unit`]).
    pub n: u32,
    /// Flux in watts, per colour channel.
    pub power: [f32; 3],
    /// Id of the object it was stored on.
    pub object: u32,
}

impl Photon {
    /// A photon at `p` that arrived from direction `wi` onto a surface with normal `n`.
    pub fn new(p: Vec3A, wi: Vec3A, n: Vec3A, phi: Rgb, object: u32) -> Self {
        Self { p: p.into(), wi: pack_unit(wi), n: pack_unit(n), power: phi.into(), object }
    }

    /// Position.
    #[inline]
    pub fn position(&self) -> Vec3A {
        Vec3A::from(self.p)
    }

    /// Unit direction towards where the photon came from.
    #[inline]
    pub fn wi(&self) -> Vec3A {
        unpack_unit(self.wi)
    }

    /// Unit normal of the surface it was stored on.
    #[inline]
    pub fn normal(&self) -> Vec3A {
        unpack_unit(self.n)
    }

    /// Flux in watts.
    #[inline]
    pub fn phi(&self) -> Rgb {
        Rgb::from(self.power)
    }
}

/// Reorders photons along a Morton (Z-order) curve over their bounding box, 21 bits per axis, ties by their
/// previous index: deterministic, and the identity on photons already in that order (checked in O(n) before
/// sorting, so a map read back from a blob is not sorted twice).
///
/// Why: the kd-tree's construction partitions an index array while reading the photon of each index; on
/// photons in tracing order those reads miss the cache (a map of 6.7 M photons took 7.9 s to build on one
/// core, 2.6 s once sorted, sort included; `cargo run --release -p photon-core --example map_costs`, numbers in
/// docs/RESULTS.md). Gathers read photons that
/// lie near each other too, which this puts near each other in memory.
pub fn sort_spatially(photons: &mut Vec<Photon>) {
    use rayon::prelude::*;
    if photons.len() < 2 {
        return;
    }
    let (lo, hi) = photons
        .par_iter()
        .fold(
            || ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
            |(lo, hi), ph| (std::array::from_fn(|d| lo[d].min(ph.p[d])), std::array::from_fn(|d| hi[d].max(ph.p[d]))),
        )
        .reduce(
            || ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
            |(a, b), (c, d)| (std::array::from_fn(|i| a[i].min(c[i])), std::array::from_fn(|i| b[i].max(d[i]))),
        );
    const LEVELS: f32 = ((1u32 << 21) - 1) as f32;
    let scale: [f32; 3] = std::array::from_fn(|d| if hi[d] > lo[d] { LEVELS / (hi[d] - lo[d]) } else { 0.0 });
    let code = |ph: &Photon| {
        // The cast saturates: a coordinate at the top of the box rounds to at most LEVELS.
        let q = |d: usize| spread_bits(((ph.p[d] - lo[d]) * scale[d]).min(LEVELS) as u64);
        q(0) | q(1) << 1 | q(2) << 2
    };
    // (code, previous index): unique keys, so an unstable sort is deterministic. The length was checked to fit
    // u32 by the caller.
    let mut keys: Vec<(u64, u32)> = photons.par_iter().enumerate().map(|(i, ph)| (code(ph), i as u32)).collect();
    if keys.par_windows(2).all(|w| w[0].0 <= w[1].0) {
        return;
    }
    keys.par_sort_unstable();
    let sorted: Vec<Photon> = keys.par_iter().map(|&(_, i)| photons[i as usize]).collect();
    *photons = sorted;
}

/// The low 21 bits of `x`, two zero bits after each: one axis of a 63-bit Morton code.
fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    (x | x << 2) & 0x1249_2492_4924_9249
}

/// Octahedral encoding of a unit vector in 16 + 16 bits (Cigolle et al., "A Survey of Efficient
/// Representations for Independent Unit Vectors", JCGT 2014). Angular error at most √18/65534 = 6.5·10⁻⁵ rad;
/// the axes are exact.
/// `v` need not be normalised but must be non-zero and finite.
pub fn pack_unit(v: Vec3A) -> u32 {
    let v = v / (v.x.abs() + v.y.abs() + v.z.abs());
    let (x, y) = if v.z >= 0.0 {
        (v.x, v.y)
    } else {
        ((1.0 - v.y.abs()) * sign_not_zero(v.x), (1.0 - v.x.abs()) * sign_not_zero(v.y))
    };
    // Map [-1, 1] to [0, 65534] (an odd number of levels, so 0 and the axes are exact: normals of
    // axis-aligned walls survive unchanged). The float-to-int cast saturates, so rounding cannot wrap.
    let quantise = |c: f32| ((c.clamp(-1.0, 1.0) + 1.0) * 32767.0).round() as u32;
    quantise(x) | (quantise(y) << 16)
}

/// Inverse of [`pack_unit`]: a unit vector.
pub fn unpack_unit(u: u32) -> Vec3A {
    let dequantise = |b: u32| (f32::from((b & 0xFFFF) as u16) / 32767.0 - 1.0).min(1.0);
    let (x, y) = (dequantise(u), dequantise(u >> 16));
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    fmath::normalize(Vec3A::new(x - t * sign_not_zero(x), y - t * sign_not_zero(y), z))
}

#[inline]
fn sign_not_zero(x: f32) -> f32 {
    if x >= 0.0 { 1.0 } else { -1.0 }
}

/// Why a photon map could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhotonMapError {
    /// More photons than a `u32` index can address.
    #[error("{0} photons: a photon map holds at most 2^32 - 1")]
    TooMany(usize),
    /// A photon position is NaN, infinite or ±`f32::MAX` (which the kd-tree reserves).
    #[error("photon {index} has a non-finite position {p:?}")]
    BadPosition {
        /// Index of the photon.
        index: usize,
        /// Its position.
        p: [f32; 3],
    },
    /// The kd-tree refused the photons.
    #[error("kd-tree construction failed: {0}")]
    Tree(String),
    /// The tracing was cancelled, or its photons passed its storage bound.
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
}

thread_local! {
    /// Squared distance of the k-th photon of this thread's last full k-nearest query: the next query's guess.
    static LAST_KTH_R2: std::cell::Cell<f32> = const { std::cell::Cell::new(0.0) };
}

/// kiddo's recommended immutable layout: `u32` items (photon indices), buckets of 32, Eytzinger stems.
/// The immutable tree copes with many photons sharing a coordinate (axis-aligned walls).
type Tree = ImmutableKdTree<f32, 3>;
type Metric = SquaredEuclidean<f32>;

/// Photons plus a kd-tree over their positions.
///
/// Serialised as its photons alone; deserialising rebuilds the tree, which is deterministic, so a map read
/// back answers every query exactly as the original. The tree is never read from bytes: kiddo's layout
/// carries unchecked offsets, and a photon array cannot be malformed in a way that is unsafe to query.
#[derive(Clone, Debug, Deserialize)]
#[serde(try_from = "PhotonMapData")]
pub struct PhotonMap {
    photons: Vec<Photon>,
    /// Shared so a clone costs only its photons (kiddo's immutable tree is not `Clone`).
    tree: Arc<Tree>,
}

/// The serialised form of a [`PhotonMap`].
#[derive(Deserialize)]
#[serde(rename = "PhotonMap", deny_unknown_fields)]
struct PhotonMapData {
    photons: Vec<Photon>,
}

#[derive(Serialize)]
#[serde(rename = "PhotonMap")]
struct PhotonMapRef<'a> {
    photons: &'a [Photon],
}

impl TryFrom<PhotonMapData> for PhotonMap {
    type Error = PhotonMapError;

    fn try_from(data: PhotonMapData) -> Result<Self, Self::Error> {
        Self::build(data.photons)
    }
}

impl Serialize for PhotonMap {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        PhotonMapRef { photons: &self.photons }.serialize(serializer)
    }
}

impl PhotonMap {
    /// Reorders `photons` along a Morton curve ([`sort_spatially`]) and builds the kd-tree over them, on the
    /// current rayon pool. Deterministic: equal photons give equal maps, whatever the pool's size, and a map
    /// built from another map's photons equals it.
    pub fn build(mut photons: Vec<Photon>) -> Result<Self, PhotonMapError> {
        if u32::try_from(photons.len()).is_err() {
            return Err(PhotonMapError::TooMany(photons.len()));
        }
        let bad = |c: &f32| !c.is_finite() || c.abs() == f32::MAX;
        if let Some(index) = photons.iter().position(|ph| ph.p.iter().any(bad)) {
            return Err(PhotonMapError::BadPosition { index, p: photons[index].p });
        }
        sort_spatially(&mut photons);
        photons.shrink_to_fit();
        // Items are indices into `photons`; the length check above keeps them within u32. The parallel
        // construction splits the same partitions over the current rayon pool: the tree is the serial one (a
        // unit test compares them).
        let positions: Vec<[f32; 3]> = {
            use rayon::prelude::*;
            photons.par_iter().map(|ph| ph.p).collect()
        };
        let tree = Tree::new_from_source_parallel(&positions, |p, dim| p[dim], |i, _| i as u32)
            .map_err(|e| PhotonMapError::Tree(e.to_string()))?;
        Ok(Self { photons, tree: Arc::new(tree) })
    }

    /// Number of photons.
    pub fn len(&self) -> usize {
        self.photons.len()
    }

    /// Whether the map holds no photon.
    pub fn is_empty(&self) -> bool {
        self.photons.is_empty()
    }

    /// The photons, in the Morton order [`build`](Self::build) gave them; query results index this slice.
    pub fn photons(&self) -> &[Photon] {
        &self.photons
    }

    /// Heap bytes held by the photons and the tree.
    ///
    /// kiddo does not report its heap size, so the tree's part follows its 6.3 layout: each leaf arena holds
    /// 3 × f32 + u32 per photon plus up to 7 alignment bytes per leaf (reserved for a power-of-two leaf
    /// count), each leaf an `(offset, len)` extent, and the stems one f32 per node of the complete binary tree
    /// above the leaves. A unit test checks it against the tree's serialised size.
    pub fn memory_bytes(&self) -> usize {
        let n = self.tree.size();
        let leaves = self.tree.leaf_count();
        let leaf_slots = leaves.next_power_of_two();
        let arena = n * (3 * size_of::<f32>() + size_of::<u32>()) + leaf_slots * 7;
        let extents = leaves * size_of::<(usize, usize)>();
        let stems = leaf_slots.div_ceil(8) * 8 * size_of::<f32>();
        self.photons.capacity() * size_of::<Photon>() + arena + extents + stems
    }

    /// The at most `k` photons nearest to `p` within squared distance `max_r2` (inclusive), nearest first (ties
    /// by photon index), as `(photon index, squared distance)` in `out` (cleared first).
    ///
    /// Radius first: kiddo's k-nearest search costs about three times a radius search that returns as many
    /// photons, so this gathers within a guessed radius — 1.5× the squared radius of this thread's previous
    /// query, which neighbouring pixels make a good guess — and keeps the `k` nearest. When the guess holds
    /// fewer than `k`, kiddo's k-nearest search finds the k-th distance and a radius search to it collects the
    /// ties, so the result never depends on the guess (only the work does) and no query scans more than the
    /// k-th photon's disc.
    pub fn k_nearest(&self, p: Vec3A, k: usize, max_r2: f32, out: &mut Vec<(u32, f32)>) {
        out.clear();
        let Some(k_nz) = NonZeroUsize::new(k) else { return };
        if self.photons.is_empty() {
            return;
        }
        let guess = LAST_KTH_R2.get() * 1.5;
        if guess > 0.0 && guess < max_r2 {
            self.within(p, guess, out);
        }
        if out.len() < k {
            let q: [f32; 3] = p.into();
            let found = self.tree.query(&q).nearest_n::<Metric>(k_nz).within(max_r2).execute();
            match found.last() {
                Some(kth) if found.len() == k => self.within(p, kth.distance, out),
                // Fewer than k within max_r2: that is all of them.
                _ => {
                    out.clear();
                    out.extend(found.iter().map(|r| (r.item, r.distance)));
                }
            }
        }
        let order = |a: &(u32, f32), b: &(u32, f32)| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0));
        if out.len() > k {
            out.select_nth_unstable_by(k - 1, order);
            out.truncate(k);
        }
        out.sort_unstable_by(order);
        if out.len() == k
            && let Some(&(_, d2)) = out.last()
        {
            LAST_KTH_R2.set(d2);
        }
    }

    /// Every photon within squared distance `r2` of `p` (inclusive), in an unspecified but deterministic order,
    /// as `(photon index, squared distance)` in `out` (cleared first).
    pub fn within(&self, p: Vec3A, r2: f32, out: &mut Vec<(u32, f32)>) {
        out.clear();
        if self.photons.is_empty() {
            return;
        }
        let q: [f32; 3] = p.into();
        self.tree.query(&q).within::<Metric>(r2).unsorted().visit(|r| out.push((r.item, r.distance)));
    }

    /// Reflected radiance at `p` (unit geometric normal `n`, on object `object`) from these photons; see the
    /// module documentation for the estimate and its filters. `f` is the BSDF for an incident direction `wi`
    /// (towards the light, world space) at the fixed outgoing direction, without the cosine. `scratch` is
    /// reused storage for the gather.
    pub fn estimate(
        &self,
        est: &Estimator,
        p: Vec3A,
        n: Vec3A,
        object: u32,
        f: impl Fn(Vec3A) -> Rgb,
        scratch: &mut Vec<(u32, f32)>,
    ) -> Rgb {
        let (r2, inside) = match est.gather {
            Gather::KNearest { k, max_radius } => {
                let k = k as usize;
                self.k_nearest(p, k, max_radius * max_radius, scratch);
                match scratch.last() {
                    // The k-th photon sets the radius and is not counted (see the module docs).
                    Some(&(_, d2_k)) if scratch.len() == k => (d2_k, k - 1),
                    _ => (max_radius * max_radius, scratch.len()),
                }
            }
            Gather::Radius { radius } => {
                self.within(p, radius * radius, scratch);
                (radius * radius, scratch.len())
            }
        };
        if r2 <= 0.0 || !r2.is_finite() {
            return Rgb::ZERO;
        }
        let max_plane_distance = est.disc.map(|disc| disc * r2.sqrt());
        let inv_r2 = 1.0 / r2;
        let mut l = Rgb::ZERO;
        for &(index, d2) in &scratch[..inside] {
            let ph = &self.photons[index as usize];
            if let Some(wi) = accept(est, ph, p, n, object, max_plane_distance) {
                l += f(wi) * ph.phi() * est.kernel.weight(d2 * inv_r2);
            }
        }
        let l = l * inv_r2;
        debug_assert!(l.is_finite(), "photon estimate {l:?} at {p} with r² = {r2}");
        l
    }

    /// Progressive photon mapping's gather: the flux `Σ f(wi)·Φ` of the photons within `radius` of `p` that the
    /// estimator's filters accept, and their count `M` (no kernel, no division by the area).
    pub fn gather_flux(
        &self,
        est: &Estimator,
        p: Vec3A,
        n: Vec3A,
        object: u32,
        f: impl Fn(Vec3A) -> Rgb,
        scratch: &mut Vec<(u32, f32)>,
    ) -> (Rgb, usize) {
        let radius = match est.gather {
            Gather::Radius { radius } => radius,
            Gather::KNearest { max_radius, .. } => max_radius,
        };
        self.within(p, radius * radius, scratch);
        let max_plane_distance = est.disc.map(|d| d * radius);
        let mut flux = Rgb::ZERO;
        let mut m = 0;
        for &(index, _) in scratch.iter() {
            let ph = &self.photons[index as usize];
            if let Some(wi) = accept(est, ph, p, n, object, max_plane_distance) {
                flux += f(wi) * ph.phi();
                m += 1;
            }
        }
        (flux, m)
    }
}

/// The photon's direction `wi` if the estimator's filters (module docs) accept it at `p` (normal `n`, object
/// `object`), given the largest distance from the tangent plane.
#[inline]
fn accept(
    est: &Estimator,
    ph: &Photon,
    p: Vec3A,
    n: Vec3A,
    object: u32,
    max_plane_distance: Option<f32>,
) -> Option<Vec3A> {
    if est.same_object && ph.object != object {
        return None;
    }
    if let Some(max_plane_distance) = max_plane_distance
        && (ph.position() - p).dot(n).abs() > max_plane_distance
    {
        return None;
    }
    let wi = ph.wi();
    (wi.dot(n) > 0.0 && ph.normal().dot(n) > 0.0).then_some(wi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::{Domain, Sampler};
    use crate::photon::Kernel;

    fn random_unit(s: &mut Sampler) -> Vec3A {
        crate::math::uniform_sphere(s.next_2d())
    }

    fn random_map(count: usize, seed: u64) -> PhotonMap {
        PhotonMap::build(random_map_photons(count, seed)).unwrap()
    }

    fn random_map_photons(count: usize, seed: u64) -> Vec<Photon> {
        let mut s = Sampler::new(seed, Domain::Photon, 0, 0, 0);
        (0..count)
            .map(|i| {
                // A box of walls: many photons share a coordinate, as on axis-aligned walls.
                let u = s.next_2d();
                let p = match i % 3 {
                    0 => Vec3A::new(u.x, u.y, 0.0),
                    1 => Vec3A::new(0.0, u.x, u.y),
                    _ => Vec3A::new(u.x, 1.0, u.y),
                };
                Photon::new(p, Vec3A::Z, Vec3A::Z, Rgb::splat(1.0), (i % 5) as u32)
            })
            .collect()
    }

    #[test]
    fn parallel_construction_gives_the_serial_tree_and_sorting_is_a_permutation() {
        // Above kiddo's parallel threshold (262 144 items).
        let map = random_map(300_000, 11);
        let serial = Tree::new_from_source(map.photons(), |ph, dim| ph.p[dim], |i, _| i as u32).unwrap();
        // kiddo's trees have no `PartialEq`: compare their serialised forms.
        let bytes = |t: &Tree| crate::codec::encode(t).unwrap();
        assert!(bytes(&map.tree) == bytes(&serial), "the parallel tree differs from the serial one");
        // Rebuilt from its own photons on another pool size: the same map (no second reordering).
        let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let again = pool.install(|| PhotonMap::build(map.photons().to_vec())).unwrap();
        assert_eq!(again.photons(), map.photons());
        assert!(bytes(&again.tree) == bytes(&map.tree));
        // The sort permutes: the same photons, in a different order.
        let input = random_map_photons(300_000, 11);
        assert_ne!(input, map.photons());
        let key = |ph: &Photon| (ph.p.map(f32::to_bits), ph.object);
        let mut a: Vec<_> = input.iter().map(key).collect();
        let mut b: Vec<_> = map.photons().iter().map(key).collect();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b);
    }

    fn random_query(s: &mut Sampler) -> Vec3A {
        Vec3A::new(s.next_f32() * 1.2 - 0.1, s.next_f32() * 1.2 - 0.1, s.next_f32() * 1.2 - 0.1)
    }

    fn brute_force(map: &PhotonMap, p: Vec3A, r2: f32) -> Vec<(u32, f32)> {
        let mut v: Vec<(u32, f32)> = map
            .photons()
            .iter()
            .enumerate()
            .map(|(i, ph)| {
                let d = Vec3A::from(ph.p) - p;
                // Same arithmetic order as kiddo's squared Euclidean metric.
                (i as u32, d.x * d.x + d.y * d.y + d.z * d.z)
            })
            .filter(|&(_, d2)| d2 <= r2)
            .collect();
        v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        v
    }

    #[test]
    fn pack_unpack_round_trip() {
        let mut s = Sampler::new(1, Domain::Photon, 1, 0, 0);
        let mut worst = 0.0f32;
        let axes = [Vec3A::X, Vec3A::Y, Vec3A::Z, -Vec3A::X, -Vec3A::Y, -Vec3A::Z];
        for v in (0..100_000).map(|_| random_unit(&mut s)).chain(axes) {
            let back = unpack_unit(pack_unit(v));
            assert!((back.length() - 1.0).abs() < 1e-6);
            // The angle from the cross product's length is accurate for tiny angles, unlike acos.
            worst = worst.max(fmath::atan2(fmath::cross(v, back).length(), v.dot(back)));
        }
        // Rounding moves each octahedral coordinate by at most e = 1/65534 (half a step over [-1, 1]). The
        // point q = (x, y, 1 - |x| - |y|) then moves by at most √6·e, and q/|q| by at most that over
        // |q| ≥ 1/√3 (a face centre): √18·e = 6.5e-5 rad.
        let bound = 18f32.sqrt() / 65534.0;
        assert!(worst <= bound * 1.01, "worst angular error {worst}, bound {bound}");
        for v in axes {
            assert_eq!(unpack_unit(pack_unit(v)), v, "axes are exact");
            assert_eq!(pack_unit(v), pack_unit(v * 7.5), "scale invariance");
        }
    }

    #[test]
    fn k_nearest_is_capped_sorted_and_matches_brute_force() {
        let map = random_map(20_000, 2);
        let mut s = Sampler::new(3, Domain::Photon, 0, 0, 0);
        let mut out = Vec::new();
        for _ in 0..200 {
            let p = random_query(&mut s);
            for (k, max_r2) in [(1, 1.0), (10, 0.01), (50, 0.002), (200, 4.0)] {
                map.k_nearest(p, k, max_r2, &mut out);
                let brute = brute_force(&map, p, max_r2);
                assert_eq!(out.len(), k.min(brute.len()));
                assert!(out.windows(2).all(|w| w[0].1 <= w[1].1), "sorted");
                // Distances equal the brute force's k smallest; indices too up to ties at equal distance.
                for (a, b) in out.iter().zip(&brute) {
                    assert_eq!(a.1.to_bits(), b.1.to_bits());
                    let ph = map.photons()[a.0 as usize].p;
                    let d = Vec3A::from(ph) - p;
                    assert_eq!((d.x * d.x + d.y * d.y + d.z * d.z).to_bits(), a.1.to_bits());
                }
            }
        }
        map.k_nearest(Vec3A::ZERO, 0, 1.0, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn within_matches_brute_force() {
        let map = random_map(20_000, 4);
        let mut s = Sampler::new(5, Domain::Photon, 0, 0, 0);
        let mut out = Vec::new();
        for _ in 0..200 {
            let p = random_query(&mut s);
            for r2 in [0.0, 1e-4, 3e-3, 0.05] {
                map.within(p, r2, &mut out);
                out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                assert_eq!(out, brute_force(&map, p, r2));
            }
        }
    }

    #[test]
    fn empty_map_answers_nothing() {
        let map = PhotonMap::build(Vec::new()).unwrap();
        assert!(map.is_empty());
        let mut out = vec![(1, 1.0)];
        map.k_nearest(Vec3A::ZERO, 10, 1.0, &mut out);
        assert!(out.is_empty());
        map.within(Vec3A::ZERO, 1.0, &mut out);
        assert!(out.is_empty());
        let est =
            Estimator { gather: Gather::Radius { radius: 1.0 }, kernel: Kernel::Box, disc: None, same_object: false };
        assert_eq!(map.estimate(&est, Vec3A::ZERO, Vec3A::Z, 0, |_| Rgb::ONE, &mut out), Rgb::ZERO);
    }

    #[test]
    fn rejects_bad_positions() {
        let good = Photon::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Z, Rgb::ONE, 0);
        for bad in [f32::NAN, f32::INFINITY, f32::MAX, f32::MIN] {
            let mut photons = vec![good; 3];
            photons[2].p[1] = bad;
            assert!(matches!(PhotonMap::build(photons), Err(PhotonMapError::BadPosition { index: 2, .. })));
        }
    }

    #[test]
    fn serialised_map_answers_queries_identically() {
        let map = random_map(50_000, 6);
        let bytes = crate::codec::encode(&map).unwrap();
        // Photons alone: 36 bytes each plus the header and the length.
        assert_eq!(bytes.len(), 8 + 8 + 36 * map.len());
        let back: PhotonMap = crate::codec::decode(&bytes, bytes.len()).unwrap();
        assert_eq!(back.photons(), map.photons());
        let mut s = Sampler::new(7, Domain::Photon, 0, 0, 0);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let bits = |v: &[(u32, f32)]| v.iter().map(|&(i, d)| (i, d.to_bits())).collect::<Vec<_>>();
        for _ in 0..1000 {
            let p = random_query(&mut s);
            map.k_nearest(p, 50, 0.01, &mut a);
            back.k_nearest(p, 50, 0.01, &mut b);
            assert_eq!(bits(&a), bits(&b));
            map.within(p, 2e-3, &mut a);
            back.within(p, 2e-3, &mut b);
            assert_eq!(bits(&a), bits(&b), "same order too");
        }
    }

    #[test]
    fn deserialising_rejects_bad_photons() {
        let mut photons = vec![Photon::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Z, Rgb::ONE, 0); 4];
        photons[3].p[0] = f32::NAN;
        // Serialise the raw photons in the map's format, bypassing build().
        let bytes = crate::codec::encode(&PhotonMapRef { photons: &photons }).unwrap();
        assert!(crate::codec::decode::<PhotonMap>(&bytes, bytes.len()).is_err());
    }

    #[test]
    fn memory_estimate_matches_the_tree() {
        for count in [1, 31, 1000, 100_000] {
            let map = random_map(count, 8);
            // The tree serialised with fixed-width integers: its Vecs' contents plus 8-byte length prefixes.
            let tree_bytes = crate::codec::encode(&*map.tree).unwrap().len();
            let estimate = map.memory_bytes() - count * size_of::<Photon>();
            let slack = 8 * map.tree.leaf_count().next_power_of_two() + 128;
            assert!(
                estimate + 64 >= tree_bytes && estimate <= tree_bytes + slack,
                "{count}: {estimate} vs {tree_bytes}"
            );
        }
    }

    #[test]
    fn kernels_are_normalised() {
        // ∫₀¹ K(t) 2πt dt by the midpoint rule in f64 over f32 kernel values.
        for kernel in Kernel::ALL {
            let steps = 100_000;
            let integral: f64 = (0..steps)
                .map(|i| {
                    let t = (f64::from(i) + 0.5) / f64::from(steps);
                    f64::from(kernel.weight((t * t) as f32)) * 2.0 * std::f64::consts::PI * t / f64::from(steps)
                })
                .sum();
            assert!((integral - 1.0).abs() < 2e-6, "{kernel:?}: {integral}");
            assert!(kernel.weight(1.0) >= 0.0 && kernel.weight(0.0) >= kernel.weight(0.5));
        }
    }

    /// Photons placed by hand around the origin: the estimate sums exactly the photons the filters admit.
    #[test]
    fn estimate_applies_its_filters() {
        let n = Vec3A::Z;
        let phi = Rgb::new(1.0, 2.0, 3.0);
        let at = |x: f32, y: f32, z: f32| Vec3A::new(x, y, z);
        let photons = vec![
            Photon::new(at(0.1, 0.0, 0.0), Vec3A::Z, n, phi, 7), // counted
            Photon::new(at(0.0, 0.2, 0.0), Vec3A::new(0.0, 0.6, 0.8), n, phi, 7), // counted
            Photon::new(at(-0.3, 0.0, 0.0), Vec3A::Z, n, phi, 8), // other object
            Photon::new(at(0.0, -0.1, 0.0), -Vec3A::Z, -n, phi, 7), // from behind
            Photon::new(at(0.0, 0.0, 0.3), Vec3A::Z, n, phi, 7), // off the plane
            Photon::new(at(0.2, 0.2, 0.0), Vec3A::Z, Vec3A::X, phi, 7), // on a perpendicular wall
            Photon::new(at(2.0, 0.0, 0.0), Vec3A::Z, n, phi, 7), // outside the radius
        ];
        let map = PhotonMap::build(photons).unwrap();
        let f = |wi: Vec3A| Rgb::splat(0.5 + wi.y); // depends on wi, so a wrong direction shows
        // The slanted photon's f, from its stored (quantised) direction.
        // (`build` reorders photons: find it by its position.)
        let slanted = map.photons().iter().find(|ph| ph.p == [0.0, 0.2, 0.0]).unwrap();
        let f_slanted = 0.5 + slanted.wi().y;
        assert!((f_slanted - 1.1).abs() < 1e-4);
        let est = Estimator {
            gather: Gather::Radius { radius: 0.5 },
            kernel: Kernel::Box,
            disc: Some(0.2),
            same_object: true,
        };
        let mut scratch = Vec::new();
        let l = map.estimate(&est, Vec3A::ZERO, n, 7, f, &mut scratch);
        let expected = (phi * 0.5 + phi * f_slanted) / (std::f32::consts::PI * 0.25);
        assert!((l - expected).abs().max_element() < 1e-5 * expected.max_element(), "{l} vs {expected}");

        // Progressive photon mapping's gather applies the same filters, without kernel or area.
        let (flux, m) = map.gather_flux(&est, Vec3A::ZERO, n, 7, f, &mut scratch);
        assert_eq!(m, 2);
        assert!((flux - phi * (0.5 + f_slanted)).abs().max_element() < 1e-5 * flux.max_element(), "{flux}");

        // Without the object and disc filters, the other object's photon and the off-plane one count too.
        let loose = Estimator { disc: None, same_object: false, ..est };
        let l = map.estimate(&loose, Vec3A::ZERO, n, 7, f, &mut scratch);
        let expected = (phi * 0.5 * 3.0 + phi * f_slanted) / (std::f32::consts::PI * 0.25);
        assert!((l - expected).abs().max_element() < 1e-5 * expected.max_element(), "{l} vs {expected}");

        // k nearest, k = 3: the photons at 0.1, 0.1 (behind, skipped) and 0.2; the last sets r and is left out.
        let knn = Estimator { gather: Gather::KNearest { k: 3, max_radius: 1.0 }, ..loose };
        let l = map.estimate(&knn, Vec3A::ZERO, n, 7, f, &mut scratch);
        let expected = phi * 0.5 / (std::f32::consts::PI * 0.04);
        assert!((l - expected).abs().max_element() < 1e-5 * expected.max_element(), "{l} vs {expected}");

        // Fewer than k photons within max_radius: r = max_radius and all found count.
        let sparse = Estimator { gather: Gather::KNearest { k: 50, max_radius: 0.15 }, ..loose };
        let l = map.estimate(&sparse, Vec3A::ZERO, n, 7, f, &mut scratch);
        let expected = phi * 0.5 / (std::f32::consts::PI * 0.0225);
        assert!((l - expected).abs().max_element() < 1e-5 * expected.max_element(), "{l} vs {expected}");
    }

    #[test]
    fn estimator_reads_from_toml() {
        let snippet = r#"
            gather = { k_nearest = { k = 100, max_radius = 0.25 } }
            kernel = "epanechnikov"
            disc = 0.25
            same_object = false
        "#;
        let est: Estimator = toml::from_str(snippet).unwrap();
        assert_eq!(
            est,
            Estimator {
                gather: Gather::KNearest { k: 100, max_radius: 0.25 },
                kernel: Kernel::Epanechnikov,
                disc: Some(0.25),
                same_object: false
            }
        );
        assert!(
            toml::from_str::<Estimator>(
                "gather = { radius = { radius = 1.0 } }\nkernel = \"box\"\nsame_object = true\nextra = 1\n"
            )
            .is_err()
        );
    }
}
