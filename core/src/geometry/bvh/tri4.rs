//! Triangles in blocks of four, stored as structure of arrays in leaf order and tested four at once, and the
//! tree over them ([`TriBvh`]).
//!
//! The block test is the watertight test of [`Triangle::intersect_prepared`] (Woop, Benthin and Wald 2013;
//! pbrt-v4 §6.5.3 and §6.8.7) with one triangle per SIMD lane: the same IEEE operations in the same order on the
//! same numbers, lane by lane (no fused multiply-add; maxima of finite values, which are exact), and the same
//! exact f64 decision of an edge function that rounds to zero. So a triangle gets the same answer, bit for bit,
//! alone or in a block, in any lane, on any architecture.
//!
//! Triangles that no test can hit (zero area, non-finite vertices) are left out of the blocks.

use super::build::Leaves;
use super::tree::{Tree, entry, split_entry};
use super::walk::{Count, RayBox, RayCost, better};
use crate::geometry::shapes::{Axes, Triangle, TriangleRay};
use crate::math::{Aabb, fmath, gamma, next_float_up};
use glam::Vec3A;
use rayon::prelude::*;
use wide::f32x4;

/// Triangles per block.
pub const LANES: usize = 4;

/// The SAH cost of testing one block, in node visits (each a test of a node's boxes): a block test does about
/// twice a node test's arithmetic.
pub const BLOCK_COST: f32 = 2.0;

/// Most blocks in a leaf of a [`TriBvh`]. The binary build makes leaves of one block; two sibling leaves of at most
/// eight triangles together whose parent would be a wide node of two slots become one leaf of two blocks instead,
/// tested one after the other: that saves the node's visit and its 224 bytes.
pub const MAX_LEAF_BLOCKS: usize = 2;

/// The leaves of a [`TriBvh`]: one block of four triangles from the build, up to [`MAX_LEAF_BLOCKS`] after the
/// collapse.
pub const TRIANGLE_LEAVES: Leaves =
    Leaves { max: LANES, group: LANES, group_cost: BLOCK_COST, merge: MAX_LEAF_BLOCKS * LANES };

/// Up to four triangles, structure of arrays: 160 bytes.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct Tri4 {
    /// `p[vertex][axis][lane]`; unused lanes hold NaN, which no test hits.
    p: [[[f32; LANES]; 3]; 3],
    /// Each lane's primitive index (the caller's); [`u32::MAX`] in unused lanes.
    id: [u32; LANES],
}

const _: () = assert!(std::mem::size_of::<Tri4>() == 160);

/// Equal bits: unused lanes hold NaN, which `==` on floats never finds equal.
impl PartialEq for Tri4 {
    fn eq(&self, other: &Self) -> bool {
        let bits = |b: &Tri4| b.p.map(|v| v.map(|a| a.map(f32::to_bits)));
        bits(self) == bits(other) && self.id == other.id
    }
}

/// The lanes of a block a ray hits: a bit mask, and each lane's distance and barycentrics `(b1, b2)`.
pub(crate) struct BlockHits {
    pub(crate) mask: u32,
    pub(crate) t: [f32; LANES],
    pub(crate) b1: [f32; LANES],
    pub(crate) b2: [f32; LANES],
}

impl BlockHits {
    const NONE: BlockHits = BlockHits { mask: 0, t: [0.0; LANES], b1: [0.0; LANES], b2: [0.0; LANES] };

    /// The lanes hit, in lane order.
    #[inline(always)]
    fn lanes(&self) -> impl Iterator<Item = usize> {
        let mut m = self.mask;
        std::iter::from_fn(move || {
            (m != 0).then(|| {
                let l = m.trailing_zeros() as usize;
                m &= m - 1;
                l
            })
        })
    }
}

/// A ray prepared for block tests: [`TriangleRay`]'s numbers in every lane, and its axis renaming as indices.
pub(crate) struct BlockRay {
    /// The renaming that makes z the dominant axis of the direction: the axes that become x, y and z.
    axes: [usize; 3],
    /// The origin's renamed coordinates.
    o: [f32x4; 3],
    sx: f32x4,
    sy: f32x4,
    sz: f32x4,
}

impl BlockRay {
    #[inline(always)]
    pub(crate) fn new(r: &TriangleRay) -> Self {
        let axes = match r.axes {
            Axes::X => [1, 2, 0],
            Axes::Y => [2, 0, 1],
            Axes::Z => [0, 1, 2],
        };
        let o = r.o.to_array();
        Self {
            axes,
            o: axes.map(|a| f32x4::splat(o[a])),
            sx: f32x4::splat(r.sx),
            sy: f32x4::splat(r.sy),
            sz: f32x4::splat(r.sz),
        }
    }
}

impl Tri4 {
    /// The lanes hit in `(0, tmax)`, as [`Triangle::intersect_prepared`] finds them one at a time.
    #[inline(always)]
    pub(crate) fn intersect(&self, r: &BlockRay, tmax: f32) -> BlockHits {
        let zero = f32x4::splat(0.0);
        let [ax, ay, az] = r.axes;
        let rel = |v: usize, a: usize, o: f32x4| f32x4::from(self.p[v][a]) - o;
        let (sx, sy, sz) = (r.sx, r.sy, r.sz);
        let z = [rel(0, az, r.o[2]), rel(1, az, r.o[2]), rel(2, az, r.o[2])];
        let x = [0, 1, 2].map(|v| rel(v, ax, r.o[0]) + sx * z[v]);
        let y = [0, 1, 2].map(|v| rel(v, ay, r.o[1]) + sy * z[v]);
        let mut e = [x[1] * y[2] - y[1] * x[2], x[2] * y[0] - y[2] * x[0], x[0] * y[1] - y[0] * x[1]];
        let on_edge = (e[0].simd_eq(zero) | e[1].simd_eq(zero) | e[2].simd_eq(zero)).to_bitmask();
        if on_edge != 0 {
            e = exact_edges(on_edge, x, y, e);
        }
        let neg = e[0].simd_lt(zero) | e[1].simd_lt(zero) | e[2].simd_lt(zero);
        let pos = e[0].simd_gt(zero) | e[1].simd_gt(zero) | e[2].simd_gt(zero);
        let det = e[0] + e[1] + e[2];
        // The lanes whose edge functions agree in sign with a finite, non-zero determinant; most blocks end here,
        // before the division.
        let inside = !(neg & pos) & det.simd_ne(zero) & det.is_finite();
        if inside.to_bitmask() == 0 {
            return BlockHits::NONE;
        }
        let z = z.map(|z| sz * z);
        let inv_det = f32x4::splat(1.0) / det;
        let t = (e[0] * z[0] + e[1] * z[1] + e[2] * z[2]) * inv_det;
        let mut mask = (inside & t.simd_gt(zero) & t.simd_lt(f32x4::splat(tmax))).to_bitmask();
        if mask == 0 {
            return BlockHits::NONE;
        }
        // The bound on t's rounding error, as the scalar test computes it; in the lanes still hit every value
        // is finite, so the maxima are exact whatever the instruction.
        let max3 = |v: [f32x4; 3]| v[0].abs().fast_max(v[1].abs()).fast_max(v[2].abs());
        let (max_x, max_y, max_z, max_e) = (max3(x), max3(y), max3(z), max3(e));
        let (g2, g3, g5) = (f32x4::splat(gamma(2)), f32x4::splat(gamma(3)), f32x4::splat(gamma(5)));
        let delta_x = g5 * (max_x + max_z);
        let delta_y = g5 * (max_y + max_z);
        let delta_z = g3 * max_z;
        let delta_e = f32x4::splat(2.0) * (g2 * max_x * max_y + delta_y * max_x + delta_x * max_y);
        let delta_t = f32x4::splat(3.0) * (g3 * max_e * max_z + delta_e * max_z + delta_z * max_e) * inv_det.abs();
        mask &= t.simd_gt(delta_t).to_bitmask();
        BlockHits { mask, t: t.to_array(), b1: (e[1] * inv_det).to_array(), b2: (e[2] * inv_det).to_array() }
    }
}

/// The edge functions of the lanes in `lanes` decided in f64, as the scalar test does when one rounds to zero:
/// products of f32 are exact there and the difference is rounded once.
#[cold]
fn exact_edges(lanes: u32, x: [f32x4; 3], y: [f32x4; 3], e: [f32x4; 3]) -> [f32x4; 3] {
    let (x, y) = (x.map(|v| v.to_array()), y.map(|v| v.to_array()));
    let mut e = e.map(|v| v.to_array());
    for l in 0..LANES {
        if lanes & (1 << l) == 0 {
            continue;
        }
        let edge = |i: usize, j: usize| {
            (f64::from(x[i][l]) * f64::from(y[j][l]) - f64::from(y[i][l]) * f64::from(x[j][l])) as f32
        };
        (e[0][l], e[1][l], e[2][l]) = (edge(1, 2), edge(2, 0), edge(0, 1));
    }
    e.map(f32x4::from)
}

/// The block of up to [`LANES`] triangles, each with its index, in lane order.
pub(crate) fn block(tris: impl IntoIterator<Item = (u32, Triangle)>) -> Tri4 {
    let mut b = Tri4 { p: [[[f32::NAN; LANES]; 3]; 3], id: [u32::MAX; LANES] };
    for (lane, (id, t)) in tris.into_iter().take(LANES).enumerate() {
        b.id[lane] = id;
        for (v, p) in t.p.iter().enumerate() {
            for a in 0..3 {
                b.p[v][a][lane] = p[a];
            }
        }
    }
    b
}

/// Whether some ray can hit `t`: finite vertices and an edge cross product that is not zero (the scalar test
/// rejects the others whatever the ray).
pub(crate) fn hittable(t: &Triangle) -> bool {
    let v0 = Vec3A::from(t.p[0]);
    t.p.iter().all(|p| p.is_finite()) && fmath::cross(Vec3A::from(t.p[1]) - v0, Vec3A::from(t.p[2]) - v0) != Vec3A::ZERO
}

/// A BVH over triangles whose leaves are blocks of four (`Tri4`) in leaf order; its queries name triangles by the
/// index given with each at the build.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriBvh {
    tree: Tree,
    blocks: Vec<Tri4>,
}

impl TriBvh {
    /// Builds the tree over `tris`, each with its index; deterministic for any number of rayon threads.
    ///
    /// # Panics
    /// With 2³² − 1 or more triangles.
    pub fn build(tris: &[(u32, Triangle)]) -> TriBvh {
        TriBvh::build_with(tris, TRIANGLE_LEAVES)
    }

    /// [`TriBvh::build`] with other leaves: `leaves.max` and `leaves.merge` at most [`MAX_LEAF_BLOCKS`] · [`LANES`].
    /// The queries' answers are the same for any leaves; the speed is not.
    ///
    /// # Panics
    /// With 2²⁸ or more triangles, or `leaves.max` or `leaves.merge` above [`MAX_LEAF_BLOCKS`] · [`LANES`].
    pub fn build_with(tris: &[(u32, Triangle)], leaves: Leaves) -> TriBvh {
        TriBvh::build_over(tris.len(), |k| Some(tris[k]), leaves)
    }

    /// The tree over the `count` triangles `tri(0)`, `tri(1)`, …, each with its index, leaving out those `tri`
    /// gives as `None`: what [`TriBvh::build`] builds, without a copy of the triangles. `tri` is called from
    /// rayon's threads.
    ///
    /// # Panics
    /// As [`TriBvh::build_with`].
    pub fn build_over(count: usize, tri: impl Fn(usize) -> Option<(u32, Triangle)> + Sync, leaves: Leaves) -> TriBvh {
        assert!(leaves.max.max(leaves.merge) <= MAX_LEAF_BLOCKS * LANES, "a leaf is at most {MAX_LEAF_BLOCKS} blocks");
        // The triangles a ray can hit, by position, and their boxes.
        let bound = |k| tri(k).and_then(|(_, t)| hittable(&t).then(|| t.bounds()));
        let (mut tree, order) = Tree::build(count, bound, leaves);
        // Each leaf becomes the next blocks, in node order, its triangles four a block; the blocks are filled in
        // parallel.
        let slots: Vec<(usize, usize)> = tree.leaf_slots().collect();
        let mut ranges: Vec<(usize, usize)> = Vec::with_capacity(slots.len());
        for (node, slot) in slots {
            let n = &mut tree.nodes[node];
            let (first, count) = split_entry(n.child[slot]);
            n.child[slot] = entry(ranges.len() as u32, count);
            let (first, count) = (first as usize, count as usize);
            ranges.extend((first..first + count).step_by(LANES).map(|f| (f, LANES.min(first + count - f))));
        }
        let blocks = ranges
            .par_iter()
            .map(|&(first, count)| block(order[first..first + count].iter().filter_map(|&k| tri(k as usize))))
            .collect();
        TriBvh { tree, blocks }
    }

    /// The closest triangle hit in `(0, tmax)` after `best` (a hit of another structure, or `None`): its index and
    /// distance, if closer than `best` or as close with a smaller index ([`super`]'s rule). `keep(index, b1, b2)`
    /// says whether a hit at barycentrics `(b1, b2)` counts (a cut-out's holes do not).
    #[inline]
    pub fn closest_hit(
        &self,
        tri: &TriangleRay,
        d: Vec3A,
        tmax: f32,
        best: Option<(u32, f32)>,
        keep: impl Fn(u32, f32, f32) -> bool,
    ) -> Option<(u32, f32)> {
        self.closest_prepared(tri, &RayBox::new(tri.o, d), tmax, best, keep, &mut ())
    }

    /// [`TriBvh::closest_hit`] that also counts its work into `cost`.
    pub fn closest_hit_counted(
        &self,
        tri: &TriangleRay,
        d: Vec3A,
        tmax: f32,
        cost: &mut RayCost,
    ) -> Option<(u32, f32)> {
        self.closest_prepared(tri, &RayBox::new(tri.o, d), tmax, None, |_, _, _| true, cost)
    }

    /// [`TriBvh::closest_hit`] for a ray already prepared for box tests, which several trees can share.
    #[inline(always)]
    pub(crate) fn closest_prepared(
        &self,
        tri: &TriangleRay,
        ray: &RayBox,
        tmax: f32,
        mut best: Option<(u32, f32)>,
        keep: impl Fn(u32, f32, f32) -> bool,
        cost: &mut impl Count,
    ) -> Option<(u32, f32)> {
        let mut tmax = best.map_or(tmax, |b| b.1);
        let block_ray = BlockRay::new(tri);
        let leaf = {
            #[inline(always)]
            |first: u32, count: u32, tmax: &mut f32| {
                for block in &self.blocks[first as usize..(first + count.div_ceil(LANES as u32)) as usize] {
                    // With a hit so far, a tie at its distance is still a candidate (`t ≤ tmax`).
                    let bound = if best.is_some() { next_float_up(*tmax) } else { *tmax };
                    let h = block.intersect(&block_ray, bound);
                    for l in h.lanes() {
                        let (t, id) = (h.t[l], block.id[l]);
                        if better(t, id, best) && keep(id, h.b1[l], h.b2[l]) {
                            *tmax = t;
                            best = Some((id, t));
                        }
                    }
                }
            }
        };
        self.tree.closest(ray, &mut tmax, cost, leaf);
        best
    }

    /// Whether a triangle that `keep` keeps is hit in `(0, tmax)`.
    #[inline]
    pub fn any_hit(&self, tri: &TriangleRay, d: Vec3A, tmax: f32, keep: impl Fn(u32, f32, f32) -> bool) -> bool {
        self.any_prepared(tri, &RayBox::new(tri.o, d), tmax, keep, &mut ())
    }

    /// [`TriBvh::any_hit`] that also counts its work into `cost`.
    pub fn any_hit_counted(&self, tri: &TriangleRay, d: Vec3A, tmax: f32, cost: &mut RayCost) -> bool {
        self.any_prepared(tri, &RayBox::new(tri.o, d), tmax, |_, _, _| true, cost)
    }

    /// [`TriBvh::any_hit`] for a ray already prepared for box tests.
    #[inline(always)]
    pub(crate) fn any_prepared(
        &self,
        tri: &TriangleRay,
        ray: &RayBox,
        tmax: f32,
        keep: impl Fn(u32, f32, f32) -> bool,
        cost: &mut impl Count,
    ) -> bool {
        let block_ray = BlockRay::new(tri);
        self.tree.any(ray, tmax, cost, |first, count| {
            self.blocks[first as usize..(first + count.div_ceil(LANES as u32)) as usize].iter().any(|block| {
                let h = block.intersect(&block_ray, tmax);
                h.lanes().any(|l| keep(block.id[l], h.b1[l], h.b2[l]))
            })
        })
    }

    /// Number of nodes (0 for an empty tree).
    pub fn node_count(&self) -> usize {
        self.tree.nodes.len()
    }

    /// Number of triangle blocks.
    pub fn block_count(&self) -> usize {
        self.blocks.len()
    }

    /// Where each triangle of the tree is: for each index `i < count` given at the build, `block · 4 + lane` of
    /// its block, or `None` where no block holds it (an index not given, or a triangle no ray can hit).
    pub(crate) fn locations(&self, count: usize) -> Vec<Option<u32>> {
        let mut out = vec![None; count];
        for (b, block) in self.blocks.iter().enumerate() {
            for (lane, &id) in block.id.iter().enumerate() {
                if let Some(slot) = out.get_mut(id as usize) {
                    *slot = Some((b * LANES + lane) as u32);
                }
            }
        }
        out
    }

    /// The vertices of the triangle at `location` ([`TriBvh::locations`]), as they were given.
    #[inline]
    pub(crate) fn vertices(&self, location: u32) -> Option<[glam::Vec3; 3]> {
        let (b, lane) = (location as usize / LANES, location as usize % LANES);
        let p = &self.blocks.get(b)?.p;
        Some(std::array::from_fn(|v| glam::Vec3::new(p[v][0][lane], p[v][1][lane], p[v][2][lane])))
    }

    /// Heap bytes: nodes and blocks.
    pub fn memory_bytes(&self) -> usize {
        self.tree.memory_bytes() + self.blocks.capacity() * std::mem::size_of::<Tri4>()
    }

    /// The box around every triangle in the tree (empty for an empty tree).
    pub fn bounds(&self) -> Aabb {
        self.tree.aabb()
    }

    /// Depth of the deepest leaf (the root's slots have depth 1).
    pub fn depth(&self) -> usize {
        self.tree.depth()
    }

    /// The SAH cost in node visits per ray that meets the root's box, a block test costing [`BLOCK_COST`].
    pub fn sah_cost(&self) -> f64 {
        self.tree.sah_cost(TRIANGLE_LEAVES)
    }

    /// A hash (FNV-1a, 64 bits) of the nodes and blocks: equal for equal trees.
    pub fn structure_hash(&self) -> u64 {
        let words = self
            .blocks
            .iter()
            .flat_map(|b| b.p.iter().flatten().flatten().map(|v| v.to_bits()).chain(b.id).collect::<Vec<_>>());
        self.tree.hash(words)
    }
}
