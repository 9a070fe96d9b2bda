//! A bounding volume hierarchy over primitive bounds: a binned-SAH binary build (parallel and deterministic),
//! collapsed into a 4-wide tree traversed with SIMD box tests; closest-hit and any-hit queries.
//!
//! The BVH knows only boxes. [`Bvh::build`] returns a permutation of the primitives; the caller stores them in
//! that order, so every leaf is a contiguous range of the caller's array and traversal needs no index table.
//! Primitive tests are callbacks, so one BVH serves every shape without trait objects.
//!
//! Build: binned surface area heuristic (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
//! 2007; pbrt-v4 §7.3.2) with [`BINS`] bins over the centroid bounds on all three axes. Large nodes bin their
//! primitives in fixed chunks of [`CHUNK`] on rayon and merge the chunks in order, and large subtrees are rayon
//! tasks; every split is a function of the node's primitives alone, so any number of threads builds the same
//! tree.
//!
//! Layout: the binary tree is collapsed into nodes of up to [`WIDTH`] children (Wald, Benthin and Boulos,
//! "Getting rid of packets", 2008; Embree's BVH4): a node repeatedly opens its child of largest surface area
//! until it has four. A node stores its children's boxes as structure of arrays, so one SIMD test per axis
//! tests all four; leaves live in their parent's slots (a primitive range), so there are no leaf nodes.
//!
//! Traversal gives exactly the binary tree's results, bit for bit and on every architecture:
//! - The box test is the binary tree's slab test, lane by lane: the same products and differences (never a
//!   fused multiply-add), and the running near and far distances are updated by comparisons, `t0 = near if
//!   near > t0`, which are false for NaN on every target; no `min`/`max` instruction, whose NaN rules differ
//!   between x86 (`minps` returns its second operand) and NEON (`fmin` returns NaN).
//! - Children are visited in the order the binary tree would visit the leaves below them: every node keeps,
//!   for each of the 8 octants of ray direction signs, the order a depth-first walk of its collapsed binary
//!   nodes gives (near child first along each split axis).
//! - A child's near distance `t0` goes on the stack with it and is compared with the current `tmax` when it is
//!   popped: `t0 <= min(tmax, far)` is the binary test of that box with the `tmax` the binary walk would use.
//!   A box inside another gives a `t0` no smaller and a far distance no larger (rounding is monotonic), so a
//!   subtree the wide walk skips holds no leaf the binary walk visits. Both walks therefore call the primitive
//!   test on the same primitives in the same order with the same `tmax`, and ties between equal distances go to
//!   the primitive tested first, as before.
//!
//! The binary tree's depth is capped at [`MAX_DEPTH`], so traversal uses a fixed stack and never allocates.
//!
//! | file | what it holds |
//! |---|---|
//! | this one | the 4-wide tree, its collapse from the binary tree, and the walks |
//! | [`build`] | the binned-SAH binary build |

pub mod build;

pub use build::{BINS, CHUNK, MAX_DEPTH, MAX_LEAF};

use crate::math::Aabb;
use build::{Node, build_binary};
use glam::{Vec3, Vec3A};
use serde::{Deserialize, Serialize};
use wide::f32x4;

/// Children per node of the traversed tree.
pub const WIDTH: usize = 4;

/// Traversal stack entries: each node on the path leaves at most `WIDTH − 1` siblings behind.
const STACK: usize = (WIDTH - 1) * MAX_DEPTH + 1;

/// pbrt's γ(3) = 3ε/(1 − 3ε) with ε = 2⁻²⁴: scaling the far slab distance by 1 + 2γ(3) makes the box test
/// conservative under rounding (pbrt-v4 §6.8.2).
const FAR_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// per 256 bytes of cache.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[repr(C, align(64))]
struct Node4 {
    /// `lo[axis][slot]`: the children's box minima; unused slots hold an empty box.
    lo: [[f32; WIDTH]; 3],
    /// `hi[axis][slot]`: the children's box maxima.
    hi: [[f32; WIDTH]; 3],
    /// Interior child: its node index. Leaf child: its first primitive.
    child: [u32; WIDTH],
    /// Leaf child: its number of primitives (1..=[`MAX_LEAF`]); interior child: 0.
    count: [u8; WIDTH],
    /// For each octant (bit `a` set when the ray's direction is negative on axis `a`), the slots in visiting
    /// order, two bits each from the lowest.
    order: [u8; 8],
    /// Number of used slots (1..=[`WIDTH`]).
    n: u8,
}

const _: () = assert!(std::mem::size_of::<Node4>() == 128);

/// A bounding volume hierarchy; leaves refer to ranges of primitives in the order [`Bvh::build`] returned.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Bvh {
    /// Depth-first; node 0 is the root.
    nodes: Vec<Node4>,
    /// The box around everything, `[min, max]`.
    bounds: [[f32; 3]; 2],
}

/// A box held in SIMD registers during the build. `union` takes each coordinate by comparison and select, so a NaN
#[derive(Clone, Copy)]
struct Entry {
    child: u32,
    count: u32,
    t0: f32,
}

impl Entry {
    const ZERO: Entry = Entry { child: 0, count: 0, t0: 0.0 };
}

thread_local! {
    /// Each thread's traversal stack.
    static STACKS: std::cell::RefCell<[Entry; STACK]> = const { std::cell::RefCell::new([Entry::ZERO; STACK]) };
}

/// A ray prepared for box tests.
struct RayBox {
    o: [f32x4; 3],
    inv: [f32x4; 3],
    /// Whether the direction is negative on each axis: that axis enters a box through its max plane.
    neg: [bool; 3],
    /// The octant: bit `a` is `neg[a]`.
    octant: usize,
}

impl RayBox {
    #[inline]
    fn new(o: Vec3A, d: Vec3A) -> Self {
        // 1/±0 = ±∞; the sign comes from the inverse so that −0 counts as negative consistently.
        let inv = d.recip();
        let neg = [inv.x < 0.0, inv.y < 0.0, inv.z < 0.0];
        let octant = usize::from(neg[0]) | usize::from(neg[1]) << 1 | usize::from(neg[2]) << 2;
        Self {
            o: [f32x4::splat(o.x), f32x4::splat(o.y), f32x4::splat(o.z)],
            inv: [f32x4::splat(inv.x), f32x4::splat(inv.y), f32x4::splat(inv.z)],
            neg,
            octant,
        }
    }

    /// The four child boxes of `node` against `[0, tmax]`: a bit mask of the slots hit and their near distances.
    /// Lane by lane this is the scalar slab test `near = (b_near − o)·inv`, `far = (b_far − o)·inv·(1 + 2γ(3))`,
    /// `t0 = max(0, near…)`, `t1 = min(tmax, far…)`, hit when `t0 ≤ t1`. A NaN slab distance (0·∞, a ray on a
    /// slab plane and parallel to it) fails both comparisons and so leaves the interval unchanged: no false
    /// misses.
    #[inline(always)]
    fn hits(&self, node: &Node4, tmax: f32) -> (u32, [f32; WIDTH]) {
        let mut t0 = f32x4::splat(0.0);
        let mut t1 = f32x4::splat(tmax);
        let scale = f32x4::splat(FAR_SCALE);
        for a in 0..3 {
            let (bn, bf) = if self.neg[a] { (node.hi[a], node.lo[a]) } else { (node.lo[a], node.hi[a]) };
            let near = (f32x4::from(bn) - self.o[a]) * self.inv[a];
            let far = (f32x4::from(bf) - self.o[a]) * self.inv[a] * scale;
            t0 = near.simd_gt(t0).bitselect(near, t0);
            t1 = far.simd_lt(t1).bitselect(far, t1);
        }
        let used = (1u32 << node.n) - 1;
        (t0.simd_le(t1).to_bitmask() & used, t0.to_array())
    }
}

impl Bvh {
    /// Deterministic binned-SAH build over primitive bounds, on the current rayon pool; the same bounds give
    /// the same BVH for any number of threads. Returns the BVH and `order`: the caller reorders its primitives as
    /// `new[i] = old[order[i]]`, and the leaves refer to contiguous ranges of that new array. Built again over
    /// the bounds in that new order, it gives the same BVH and the identity order: a worker rebuilds the tree
    /// from primitives shipped in leaf order and gets the coordinator's tree.
    ///
    /// # Panics
    /// With 2³² − 1 or more primitives, which `u32` indices cannot address.
    pub fn build(bounds: &[Aabb]) -> (Bvh, Vec<u32>) {
        if bounds.is_empty() {
            return (Bvh::default(), Vec::new());
        }
        assert!(bounds.len() < u32::MAX as usize, "a BVH holds fewer than 2^32 primitives");
        let (binary, order) = build_binary(bounds);
        let mut nodes = collapse(&binary);
        nodes.shrink_to_fit();
        (Bvh { nodes, bounds: binary[0].b }, order)
    }

    /// Closest hit: `hit(prim, current_tmax)` returns a `t < current_tmax` if primitive `prim` (in the new order)
    /// is hit closer. Returns the primitive and distance of the closest hit in `(0, tmax)`; of hits at equal
    /// distance, the first tested (the binary tree's near-first order).
    pub fn closest_hit(
        &self,
        o: Vec3A,
        d: Vec3A,
        tmax: f32,
        mut hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<(u32, f32)> {
        let mut tmax = tmax;
        let mut best = None;
        self.walk(o, d, &mut tmax, |first, count, tmax| {
            for p in first..first + count {
                if let Some(t) = hit(p, *tmax)
                    && t < *tmax
                {
                    *tmax = t;
                    best = Some((p, t));
                }
            }
            false
        });
        best
    }

    /// Any hit in `(0, tmax)`: stops at the first primitive for which `hit(prim, tmax)` is true.
    pub fn any_hit(&self, o: Vec3A, d: Vec3A, tmax: f32, mut hit: impl FnMut(u32, f32) -> bool) -> bool {
        let mut tmax = tmax;
        self.walk(o, d, &mut tmax, |first, count, tmax| (first..first + count).any(|p| hit(p, *tmax)))
    }

    /// Visits the leaves whose boxes the ray meets within `[0, tmax]`, in the binary tree's near-first order,
    /// testing each leaf's box with `tmax` as `leaf(first, count, tmax)` left it; stops when `leaf` returns true
    /// and returns whether it did.
    #[inline(always)]
    fn walk(&self, o: Vec3A, d: Vec3A, tmax: &mut f32, leaf: impl FnMut(u32, u32, &mut f32) -> bool) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        // The stack is the thread's, so no ray pays for clearing 2 kB (it was a tenth of the traversal time); a
        // walk started from inside another's leaf callback gets a fresh one.
        STACKS.with(|stack| match stack.try_borrow_mut() {
            Ok(mut stack) => self.walk_with(&mut stack, o, d, tmax, leaf),
            Err(_) => self.walk_with(&mut [Entry::ZERO; STACK], o, d, tmax, leaf),
        })
    }

    /// [`Bvh::walk`] on a given stack.
    #[inline(always)]
    fn walk_with(
        &self,
        stack: &mut [Entry; STACK],
        o: Vec3A,
        d: Vec3A,
        tmax: &mut f32,
        mut leaf: impl FnMut(u32, u32, &mut f32) -> bool,
    ) -> bool {
        let ray = RayBox::new(o, d);
        let mut sp = 0;
        let mut e = Entry::ZERO;
        loop {
            if e.t0 <= *tmax {
                if e.count == 0 {
                    let node = &self.nodes[e.child as usize];
                    let (mask, t0) = ray.hits(node, *tmax);
                    if mask != 0 {
                        let order = node.order[ray.octant];
                        // Push the hit children in reverse visiting order, then take the first off again: the
                        // loop goes on with it at once (its t0 passed with this tmax).
                        for k in (0..u32::from(node.n)).rev() {
                            let slot = usize::from((order >> (2 * k)) & 3);
                            if mask & (1 << slot) != 0 {
                                stack[sp] =
                                    Entry { child: node.child[slot], count: u32::from(node.count[slot]), t0: t0[slot] };
                                sp += 1;
                            }
                        }
                        sp -= 1;
                        e = stack[sp];
                        continue;
                    }
                } else if leaf(e.child, e.count, tmax) {
                    return true;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            e = stack[sp];
        }
    }

    /// Number of nodes of the traversed tree (0 for an empty BVH).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Heap bytes of the BVH itself.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node4>()
    }

    /// The box around everything (empty for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        if self.nodes.is_empty() {
            Aabb::EMPTY
        } else {
            Aabb { min: Vec3::from_array(self.bounds[0]), max: Vec3::from_array(self.bounds[1]) }
        }
    }

    /// Depth of the deepest leaf of the traversed tree (the root's slots have depth 1); 0 for an empty BVH.
    pub fn depth(&self) -> usize {
        fn rec(nodes: &[Node4], i: usize) -> usize {
            let n = &nodes[i];
            1 + (0..usize::from(n.n))
                .filter(|&k| n.count[k] == 0)
                .map(|k| rec(nodes, n.child[k] as usize))
                .max()
                .unwrap_or(0)
        }
        if self.nodes.is_empty() { 0 } else { rec(&self.nodes, 0) }
    }

    /// A hash (FNV-1a, 64 bits) of every node's bytes: equal for equal trees, for comparing builds.
    pub fn structure_hash(&self) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |x: u32| {
            for byte in x.to_le_bytes() {
                h = (h ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3);
            }
        };
        for n in &self.nodes {
            n.lo.iter().chain(&n.hi).flatten().for_each(|v| eat(v.to_bits()));
            n.child.iter().for_each(|&c| eat(c));
            eat(u32::from_le_bytes(n.count));
            n.order.chunks(4).for_each(|c| eat(c.iter().fold(0, |a, &b| a << 8 | u32::from(b))));
            eat(u32::from(n.n));
        }
        self.bounds.iter().flatten().for_each(|v| eat(v.to_bits()));
        h
    }
}

/// Collapses the binary tree (root at 0) into [`Node4`]s, depth-first.
fn collapse(binary: &[Node]) -> Vec<Node4> {
    let mut out = Vec::with_capacity(binary.len() / 3 + 1);
    if binary[0].count > 0 {
        // A root leaf: one node with one slot.
        let mut node = empty_node4();
        set_slot(&mut node, 0, &binary[0]);
        node.child[0] = binary[0].offset;
        node.n = 1;
        out.push(node);
    } else {
        collapse_node(binary, 0, &mut out);
    }
    out
}

fn empty_node4() -> Node4 {
    let e = Aabb::EMPTY;
    Node4 {
        lo: [[e.min.x; WIDTH], [e.min.y; WIDTH], [e.min.z; WIDTH]],
        hi: [[e.max.x; WIDTH], [e.max.y; WIDTH], [e.max.z; WIDTH]],
        child: [0; WIDTH],
        count: [0; WIDTH],
        order: [0; 8],
        n: 0,
    }
}

/// Copies binary node `b`'s box and leaf count into slot `k`.
fn set_slot(node: &mut Node4, k: usize, b: &Node) {
    for a in 0..3 {
        node.lo[a][k] = b.b[0][a];
        node.hi[a][k] = b.b[1][a];
    }
    node.count[k] = b.count as u8;
}

/// Appends the [`Node4`] for interior binary node `b` and those below it; returns its index.
fn collapse_node(binary: &[Node], b: usize, out: &mut Vec<Node4>) -> u32 {
    let half_area = |i: usize| {
        let n = &binary[i];
        Aabb { min: Vec3::from_array(n.b[0]), max: Vec3::from_array(n.b[1]) }.half_area()
    };
    // Slots in the binary tree's first-then-second order; open the interior slot of largest area (the first
    // on ties) until there are WIDTH.
    let mut slots = [0usize; WIDTH];
    slots[0] = b + 1;
    slots[1] = binary[b].offset as usize;
    let mut n = 2;
    while n < WIDTH {
        let mut pick: Option<(usize, f32)> = None;
        for (k, &s) in slots[..n].iter().enumerate() {
            if binary[s].count == 0 && pick.is_none_or(|(_, a)| half_area(s) > a) {
                pick = Some((k, half_area(s)));
            }
        }
        let Some((k, _)) = pick else { break };
        let s = slots[k];
        slots.copy_within(k + 1..n, k + 2);
        slots[k] = s + 1;
        slots[k + 1] = binary[s].offset as usize;
        n += 1;
    }
    let index = out.len();
    out.push(empty_node4());
    let mut node = empty_node4();
    node.n = n as u8;
    for (octant, order) in node.order.iter_mut().enumerate() {
        let mut k = 0;
        visit_order(binary, b, &slots[..n], octant, order, &mut k);
    }
    for (k, &s) in slots[..n].iter().enumerate() {
        set_slot(&mut node, k, &binary[s]);
        node.child[k] = if binary[s].count > 0 { binary[s].offset } else { collapse_node(binary, s, out) };
    }
    out[index] = node;
    index as u32
}

/// Appends to `order` (two bits per slot, from bit `2k`) the slots below binary node `b` in the order the binary
/// traversal visits them for rays in `octant`: the second child first when the direction is negative along the
/// split axis.
fn visit_order(binary: &[Node], b: usize, slots: &[usize], octant: usize, order: &mut u8, k: &mut u32) {
    if let Some(slot) = slots.iter().position(|&s| s == b) {
        *order |= (slot as u8) << (2 * *k);
        *k += 1;
        return;
    }
    let (first, second) = (b + 1, binary[b].offset as usize);
    let (near, far) = if (octant >> binary[b].axis) & 1 == 1 { (second, first) } else { (first, second) };
    visit_order(binary, near, slots, octant, order, k);
    visit_order(binary, far, slots, octant, order, k);
}

/// How to split a node's primitives.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes::Triangle;
    use crate::math::{Ray, fmath};

    fn cube(c: Vec3, h: f32) -> Aabb {
        Aabb { min: c - Vec3::splat(h), max: c + Vec3::splat(h) }
    }

    /// Ray-box test as the primitive: exact slab test of the primitive's own box.
    fn box_hit(b: &Aabb, o: Vec3A, d: Vec3A, tmax: f32) -> Option<f32> {
        let inv = d.recip();
        let mut t0 = 0.0f32;
        let mut t1 = tmax;
        for a in 0..3 {
            let n = (b.min[a] - o[a]) * inv[a];
            let f = (b.max[a] - o[a]) * inv[a];
            // A NaN (0·∞: the origin on a slab plane, parallel to it) is ignored by `max`/`min`.
            let (n, f) = if f < n { (f, n) } else { (n, f) };
            t0 = t0.max(n);
            t1 = t1.min(f);
        }
        (t0 <= t1 && t0 > 0.0 && t0 < tmax).then_some(t0)
    }

    #[test]
    fn empty_bvh_misses() {
        let (bvh, order) = Bvh::build(&[]);
        assert!(order.is_empty());
        assert_eq!(bvh.node_count(), 0);
        assert_eq!(bvh.depth(), 0);
        assert!(bvh.bounds().is_empty());
        assert!(bvh.closest_hit(Vec3A::ZERO, Vec3A::X, f32::INFINITY, |_, _| Some(1.0)).is_none());
        assert!(!bvh.any_hit(Vec3A::ZERO, Vec3A::X, f32::INFINITY, |_, _| true));
    }

    #[test]
    fn one_primitive() {
        let b = [cube(Vec3::new(0.0, 0.0, 5.0), 1.0)];
        let (bvh, order) = Bvh::build(&b);
        assert_eq!(order, vec![0]);
        assert_eq!(bvh.node_count(), 1);
        let hit = |p: u32, t: f32| box_hit(&b[p as usize], Vec3A::ZERO, Vec3A::Z, t);
        let h = bvh.closest_hit(Vec3A::ZERO, Vec3A::Z, f32::INFINITY, hit).unwrap();
        assert_eq!(h.0, 0);
        assert!((h.1 - 4.0).abs() < 1e-6);
        assert!(bvh.closest_hit(Vec3A::ZERO, Vec3A::Z, 3.0, hit).is_none());
        assert!(bvh.closest_hit(Vec3A::ZERO, Vec3A::NEG_Z, f32::INFINITY, hit).is_none());
        assert!(bvh.any_hit(Vec3A::ZERO, Vec3A::Z, 10.0, |p, t| hit(p, t).is_some()));
    }

    #[test]
    fn many_identical_bounds() {
        let n = 1000;
        let b = vec![cube(Vec3::ONE, 0.5); n];
        let (bvh, order) = Bvh::build(&b);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>());
        assert!(bvh.depth() <= 10, "median splits keep identical boxes balanced: depth {}", bvh.depth());
        // Every primitive is reached exactly once by a ray through the box.
        let mut seen = vec![0u32; n];
        bvh.closest_hit(Vec3A::ZERO, fmath::normalize(Vec3A::ONE), f32::INFINITY, |p, _| {
            seen[p as usize] += 1;
            None
        });
        assert!(seen.iter().all(|&s| s == 1));
        // Points (zero-size boxes) at one place also build.
        let (bvh, _) = Bvh::build(&vec![cube(Vec3::ONE, 0.0); n]);
        assert!(bvh.node_count() > 1);
    }

    #[test]
    fn ray_parallel_to_slabs() {
        // Flat boxes in the z = 0 plane; rays lie in that plane or on a box's face, parallel to the slabs.
        let b: Vec<Aabb> = (0..64)
            .map(|i| {
                let c = Vec3::new((i % 8) as f32, (i / 8) as f32, 0.0);
                Aabb { min: c, max: c + Vec3::new(0.5, 0.5, 0.0) }
            })
            .collect();
        let (bvh, order) = Bvh::build(&b);
        let b: Vec<Aabb> = order.iter().map(|&i| b[i as usize]).collect();
        let count = |o: Vec3A, d: Vec3A| {
            let mut n = 0;
            bvh.closest_hit(o, d, f32::INFINITY, |p, _| {
                n += u32::from(box_hit(&b[p as usize], o, d, f32::INFINITY).is_some());
                None
            });
            n
        };
        // Along +x at y = 0.25, in the z = 0 plane (d.y = d.z = 0, o.z on both z slabs): 8 boxes.
        assert_eq!(count(Vec3A::new(-1.0, 0.25, 0.0), Vec3A::X), 8);
        // The same with negative zeros.
        assert_eq!(count(Vec3A::new(-1.0, 0.25, 0.0), Vec3A::new(1.0, -0.0, -0.0)), 8);
        // Exactly along the boxes' y = 0 face.
        assert_eq!(count(Vec3A::new(-1.0, 0.0, 0.0), Vec3A::X), 8);
        // Along −y on the x = 3.5 face.
        assert_eq!(count(Vec3A::new(3.5, 10.0, 0.0), Vec3A::NEG_Y), 8);
        // Parallel but outside: nothing.
        assert_eq!(count(Vec3A::new(-1.0, 0.25, 0.1), Vec3A::X), 0);
        assert_eq!(count(Vec3A::new(-1.0, 0.75, 0.0), Vec3A::X), 0);
    }

    /// `n` random cubes in `[0, 10]³` (sides up to 0.2), their BVH, the cubes in its leaf order, and `rays` random
    /// rays (origins in `[−1, 11]³`, uniform directions), from `seed`.
    #[allow(clippy::type_complexity)]
    fn boxes_and_rays(seed: u64, n: usize, rays: usize) -> (Bvh, Vec<Aabb>, Vec<(Vec3A, Vec3A)>) {
        let mut s = crate::math::rng::Sampler::new(seed, crate::math::rng::Domain::Photon, 0, 0, 0);
        let mut v = || Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
        let b: Vec<Aabb> = (0..n).map(|_| cube(10.0 * v(), 0.2 * v().x)).collect();
        let rays =
            (0..rays).map(|_| (Vec3A::from(12.0 * v() - 1.0), fmath::normalize(Vec3A::from(v() - 0.5)))).collect();
        let (bvh, order) = Bvh::build(&b);
        let b = order.iter().map(|&i| b[i as usize]).collect();
        (bvh, b, rays)
    }

    #[test]
    fn closest_and_any_hit_agree_with_brute_force_on_boxes() {
        let (bvh, b, rays) = boxes_and_rays(3, 500, 2000);
        for (o, d) in rays {
            let brute = b.iter().filter_map(|x| box_hit(x, o, d, f32::INFINITY)).fold(f32::INFINITY, f32::min);
            let h = bvh.closest_hit(o, d, f32::INFINITY, |p, t| box_hit(&b[p as usize], o, d, t));
            assert_eq!(h.map_or(f32::INFINITY, |h| h.1), brute);
            assert_eq!(
                bvh.any_hit(o, d, f32::INFINITY, |p, t| box_hit(&b[p as usize], o, d, t).is_some()),
                h.is_some()
            );
        }
    }

    /// A walk started inside another walk's leaf callback (which then holds the thread's stack) gets a stack of
    /// its own and the same answers, and leaves the outer walk's stack intact.
    #[test]
    fn a_walk_inside_a_walk_has_its_own_stack() {
        let (bvh, b, rays) = boxes_and_rays(5, 2000, 500);
        for &(o, d) in &rays {
            let plain = bvh.closest_hit(o, d, f32::INFINITY, |p, t| box_hit(&b[p as usize], o, d, t));
            let mut inner = Vec::new();
            let nested = bvh.closest_hit(o, d, f32::INFINITY, |p, t| {
                // Another walk, along the reversed ray, from inside this one.
                inner.push(bvh.any_hit(o, -d, f32::INFINITY, |q, t| box_hit(&b[q as usize], o, -d, t).is_some()));
                box_hit(&b[p as usize], o, d, t)
            });
            assert_eq!(nested, plain);
            let reversed = bvh.any_hit(o, -d, f32::INFINITY, |q, t| box_hit(&b[q as usize], o, -d, t).is_some());
            assert!(inner.iter().all(|&h| h == reversed));
        }
    }

    /// The binary tree's traversal, as it was before the collapse: the scalar slab test and a near-first walk.
    /// Returns what `leaf` returned true for, or the end of the walk.
    fn binary_walk(nodes: &[Node], o: Vec3A, d: Vec3A, tmax: &mut f32, mut leaf: impl FnMut(u32, &mut f32) -> bool) {
        let inv = d.recip();
        let neg = [usize::from(inv.x < 0.0), usize::from(inv.y < 0.0), usize::from(inv.z < 0.0)];
        let hits = |b: &[[f32; 3]; 2], tmax: f32| {
            let (mut t0, mut t1) = (0.0f32, tmax);
            for a in 0..3 {
                let near = (b[neg[a]][a] - o[a]) * inv[a];
                let far = (b[1 - neg[a]][a] - o[a]) * inv[a] * FAR_SCALE;
                if near > t0 {
                    t0 = near;
                }
                if far < t1 {
                    t1 = far;
                }
            }
            t0 <= t1
        };
        let mut stack = Vec::new();
        let mut i = 0usize;
        loop {
            let node = &nodes[i];
            if hits(&node.b, *tmax) {
                if node.count == 0 {
                    let (near, far) = if neg[node.axis as usize] == 1 {
                        (node.offset, i as u32 + 1)
                    } else {
                        (i as u32 + 1, node.offset)
                    };
                    stack.push(far);
                    i = near as usize;
                    continue;
                }
                for p in node.offset..node.offset + u32::from(node.count) {
                    if leaf(p, tmax) {
                        return;
                    }
                }
            }
            match stack.pop() {
                Some(next) => i = next as usize,
                None => return,
            }
        }
    }

    /// Triangles with many exact ties: a soup with duplicates and degenerate triangles, and a grid of unit
    /// squares (two triangles each) in the plane z = 2 whose shared edges and vertices rays hit exactly.
    fn tie_scene(s: &mut crate::math::rng::Sampler) -> Vec<Triangle> {
        let mut v = || Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
        let mut tris: Vec<Triangle> = Vec::new();
        for k in 0..3000 {
            let c = 8.0 * v();
            let t = match k % 10 {
                0 => Triangle::new(c, c, c),
                1 => Triangle::new(c, c + Vec3::X, c + 2.0 * Vec3::X),
                2 | 3 if !tris.is_empty() => tris[(8.0 * c.x) as usize % tris.len()],
                _ => Triangle::new(c, c + 0.7 * (v() - 0.5), c + 0.7 * (v() - 0.5)),
            };
            tris.push(t);
        }
        for y in 0..8 {
            for x in 0..8 {
                let p = |dx: i32, dy: i32| Vec3::new((x + dx) as f32, (y + dy) as f32, 2.0);
                tris.push(Triangle::new(p(0, 0), p(1, 0), p(1, 1)));
                tris.push(Triangle::new(p(0, 0), p(1, 1), p(0, 1)));
            }
        }
        tris
    }

    #[test]
    fn wide_traversal_tests_the_same_primitives_as_the_binary_tree() {
        let mut s = crate::math::rng::Sampler::new(5, crate::math::rng::Domain::Photon, 0, 0, 0);
        let tris = tie_scene(&mut s);
        let bounds: Vec<Aabb> = tris.iter().map(Triangle::bounds).collect();
        let (bvh, order) = Bvh::build(&bounds);
        let (binary, binary_order) = build_binary(&bounds);
        assert_eq!(order, binary_order);
        let tris: Vec<Triangle> = order.iter().map(|&i| tris[i as usize]).collect();
        let mut rays: Vec<Ray> = Vec::new();
        for k in 0..40_000 {
            let (o, d) = match k % 4 {
                // Straight down through grid vertices and edge midpoints: ties between the triangles sharing them.
                0 => (Vec3A::new((k % 17) as f32 * 0.5, (k % 13) as f32 * 0.5, 5.0), Vec3A::NEG_Z),
                // In the grid's plane, along an axis: on slab planes, with NaN slab distances.
                1 => (Vec3A::new(-1.0, (k % 9) as f32, 2.0), Vec3A::X),
                _ => (
                    Vec3A::new(10.0 * s.next_f32() - 1.0, 10.0 * s.next_f32() - 1.0, 10.0 * s.next_f32() - 1.0),
                    crate::math::uniform_sphere(s.next_2d()),
                ),
            };
            rays.push(Ray::new(o, d));
        }
        let mut ties = 0;
        for (k, ray) in rays.iter().enumerate() {
            let tmax = if k % 5 == 0 { 4.0 } else { f32::INFINITY };
            // Every call of the primitive test, with the tmax it was given, in order.
            let mut wide_calls = Vec::new();
            let wide = bvh.closest_hit(ray.o, ray.d, tmax, |p, t| {
                wide_calls.push((p, t.to_bits()));
                tris[p as usize].intersect(ray, t)
            });
            let mut binary_calls = Vec::new();
            let mut best = None;
            binary_walk(&binary, ray.o, ray.d, &mut tmax.clone(), |p, t| {
                binary_calls.push((p, t.to_bits()));
                if let Some(h) = tris[p as usize].intersect(ray, *t)
                    && h < *t
                {
                    *t = h;
                    best = Some((p, h));
                }
                false
            });
            assert_eq!(wide_calls, binary_calls, "ray {k}: {ray:?}");
            assert_eq!(wide.map(|(p, t)| (p, t.to_bits())), best.map(|(p, t)| (p, t.to_bits())), "ray {k}");
            if let Some((_, t)) = wide {
                ties += usize::from(tris.iter().filter(|tri| tri.intersect(ray, f32::INFINITY) == Some(t)).count() > 1);
            }
            let mut wide_calls = Vec::new();
            let wide_any = bvh.any_hit(ray.o, ray.d, tmax, |p, t| {
                wide_calls.push(p);
                tris[p as usize].intersect(ray, t).is_some()
            });
            let mut binary_calls = Vec::new();
            let mut binary_any = false;
            binary_walk(&binary, ray.o, ray.d, &mut tmax.clone(), |p, t| {
                binary_calls.push(p);
                binary_any = tris[p as usize].intersect(ray, *t).is_some();
                binary_any
            });
            assert_eq!(wide_calls, binary_calls, "ray {k}: any hit");
            assert_eq!(wide_any, binary_any);
        }
        // The ties were there to break: closest hits shared by two or more triangles at the same distance.
        assert!(ties > 1000, "{ties} ties");
    }

    #[test]
    fn geometric_centroids_stay_within_depth_cap() {
        // Centroids at 2^-k make every SAH split peel off one primitive.
        let b: Vec<Aabb> = (0..200).map(|k| cube(Vec3::splat((-(k as f32)).exp2()), 0.0)).collect();
        let (bvh, _) = Bvh::build(&b);
        assert!(bvh.depth() <= MAX_DEPTH);
    }

    /// Building over the bounds in the order a build returned gives the same tree and the identity order (what
    /// a worker's rebuild relies on), with SAH splits, duplicates, empty boxes and the median splits of a
    /// degenerate distribution.
    #[test]
    fn a_build_over_its_own_order_gives_the_same_tree() {
        let mut s = crate::math::rng::Sampler::new(3, crate::math::rng::Domain::Photon, 0, 0, 0);
        let mut soup: Vec<Aabb> = (0..20_000)
            .map(|_| cube(10.0 * Vec3::new(s.next_f32(), s.next_f32(), s.next_f32()), 0.3 * s.next_f32()))
            .collect();
        soup.extend_from_within(..500);
        soup.extend([Aabb::EMPTY; 5]);
        soup.push(cube(Vec3::new(-0.0, 0.0, -0.0), 0.0));
        let geometric: Vec<Aabb> = (0..200).map(|k| cube(Vec3::splat((-(k as f32)).exp2()), 0.0)).collect();
        for bounds in [soup, geometric] {
            let (bvh, order) = Bvh::build(&bounds);
            let sorted: Vec<Aabb> = order.iter().map(|&i| bounds[i as usize]).collect();
            let (again, order_again) = Bvh::build(&sorted);
            assert!(order_again.iter().enumerate().all(|(i, &o)| o == i as u32));
            assert_eq!(again.structure_hash(), bvh.structure_hash());
            assert_eq!(again, bvh);
        }
    }

    #[test]
    fn empty_boxes_build() {
        let mut b = vec![Aabb::EMPTY; 10];
        b.push(cube(Vec3::ZERO, 1.0));
        let (bvh, order) = Bvh::build(&b);
        assert_eq!(order.len(), 11);
        let k = order.iter().position(|&i| i == 10).unwrap() as u32;
        let h = bvh.closest_hit(Vec3A::new(0.0, 0.0, -5.0), Vec3A::Z, f32::INFINITY, |p, t| {
            (p == k).then_some(4.0).filter(|&x| x < t)
        });
        assert_eq!(h, Some((k, 4.0)));
    }
}
