//! A bounding volume hierarchy over primitive bounds: binned-SAH build, flat depth-first nodes, closest-hit and
//! any-hit traversal.
//!
//! The BVH knows only boxes. [`Bvh::build`] returns a permutation of the primitives; the caller stores them in
//! that order, so every leaf is a contiguous range of the caller's array and traversal needs no index table.
//! Primitive tests are callbacks, so one BVH serves every shape without trait objects.
//!
//! Build: binned surface area heuristic (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
//! 2007; pbrt-v4 §7.3.2) with [`BINS`] bins over the centroid bounds on all three axes. The build is sequential
//! and uses only deterministic operations, so the same bounds always give the same nodes.
//!
//! Layout: 32-byte nodes in depth-first order; an interior node's first child follows it, the second child's
//! index is stored (pbrt's `LinearBVHNode`). The tree depth is capped at [`MAX_DEPTH`], so traversal uses a
//! fixed stack and never allocates.

use crate::math::Aabb;
use glam::{Vec3, Vec3A};
use serde::{Deserialize, Serialize};

/// Number of SAH bins per axis.
pub const BINS: usize = 16;

/// Most primitives in a leaf; the SAH may stop earlier.
pub const MAX_LEAF: usize = 8;

/// Below this depth splits are chosen by the SAH; deeper nodes (only reached by pathological inputs, such as
/// centroids spaced geometrically) are split at the centroid median, which halves the count at each level.
const SAH_DEPTH: u32 = 32;

/// Bound on the depth of any leaf, and the size of the traversal stack: 32 SAH levels (`SAH_DEPTH`), then at most
/// 29 median levels take fewer than 2³² primitives down to [`MAX_LEAF`] = 2³.
pub const MAX_DEPTH: usize = 64;

/// Cost of one node visit relative to one primitive test, for the SAH.
const TRAVERSAL_COST: f32 = 1.0;

/// pbrt's γ(3) = 3ε/(1 − 3ε) with ε = 2⁻²⁴: scaling the far slab distance by 1 + 2γ(3) makes the box test
/// conservative under rounding (pbrt-v4 §6.8.2).
const FAR_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// One node: its box and either a leaf range or the second child's index.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct Node {
    /// `[min, max]` of the box.
    b: [[f32; 3]; 2],
    /// Leaf: index of the first primitive. Interior: index of the second child (the first is the next node).
    offset: u32,
    /// Number of primitives; 0 marks an interior node.
    count: u16,
    /// Split axis of an interior node.
    axis: u8,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

impl Node {
    fn new(bounds: Aabb) -> Self {
        Self { b: [bounds.min.to_array(), bounds.max.to_array()], offset: 0, count: 0, axis: 0 }
    }
}

/// A bounding volume hierarchy; leaves refer to ranges of primitives in the order [`Bvh::build`] returned.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Bvh {
    nodes: Vec<Node>,
}

/// A primitive during the build.
#[derive(Clone, Copy)]
struct Ref {
    bounds: Aabb,
    /// Centroid, with non-finite components (empty or infinite boxes) replaced by 0 so binning stays defined.
    c: Vec3,
    index: u32,
}

/// A ray prepared for box tests.
struct RayBox {
    o: [f32; 3],
    inv: [f32; 3],
    /// 1 where the direction is negative: that axis enters the box through its max plane.
    neg: [usize; 3],
}

impl RayBox {
    #[inline]
    fn new(o: Vec3A, d: Vec3A) -> Self {
        // 1/±0 = ±∞; the sign comes from the inverse so that −0 counts as negative consistently.
        let inv = d.recip();
        let neg = [usize::from(inv.x < 0.0), usize::from(inv.y < 0.0), usize::from(inv.z < 0.0)];
        Self { o: o.to_array(), inv: inv.to_array(), neg }
    }

    /// Whether the ray meets the box in `[0, tmax]`. A NaN slab distance (0·∞, a ray on a slab plane and
    /// parallel to it) fails both comparisons and so leaves the interval unchanged: no false misses.
    #[inline(always)]
    fn hits(&self, b: &[[f32; 3]; 2], tmax: f32) -> bool {
        let mut t0 = 0.0f32;
        let mut t1 = tmax;
        for a in 0..3 {
            let near = (b[self.neg[a]][a] - self.o[a]) * self.inv[a];
            let far = (b[1 - self.neg[a]][a] - self.o[a]) * self.inv[a] * FAR_SCALE;
            if near > t0 {
                t0 = near;
            }
            if far < t1 {
                t1 = far;
            }
        }
        t0 <= t1
    }
}

impl Bvh {
    /// Deterministic binned-SAH build over primitive bounds. Returns the BVH and `order`: the caller reorders its
    /// primitives as `new[i] = old[order[i]]`, and the leaves refer to contiguous ranges of that new array.
    ///
    /// # Panics
    /// With 2³² − 1 or more primitives, which `u32` indices cannot address.
    pub fn build(bounds: &[Aabb]) -> (Bvh, Vec<u32>) {
        if bounds.is_empty() {
            return (Bvh::default(), Vec::new());
        }
        assert!(bounds.len() < u32::MAX as usize, "a BVH holds fewer than 2^32 primitives");
        let mut refs: Vec<Ref> = bounds
            .iter()
            .enumerate()
            .map(|(i, &b)| {
                let c = b.center();
                let c = Vec3::select(c.is_finite_mask(), c, Vec3::ZERO);
                Ref { bounds: b, c, index: i as u32 }
            })
            .collect();
        let mut nodes = Vec::with_capacity(bounds.len().div_ceil(2).max(1));
        build_node(&mut refs, 0, 0, &mut nodes);
        nodes.shrink_to_fit();
        (Bvh { nodes }, refs.iter().map(|r| r.index).collect())
    }

    /// Closest hit: `hit(prim, current_tmax)` returns a `t < current_tmax` if primitive `prim` (in the new order)
    /// is hit closer. Returns the primitive and distance of the closest hit in `(0, tmax)`.
    pub fn closest_hit(
        &self,
        o: Vec3A,
        d: Vec3A,
        tmax: f32,
        mut hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<(u32, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let ray = RayBox::new(o, d);
        let mut tmax = tmax;
        let mut best = None;
        let mut stack = [0u32; MAX_DEPTH];
        let mut sp = 0;
        let mut i = 0usize;
        loop {
            let node = &self.nodes[i];
            if ray.hits(&node.b, tmax) {
                if node.count == 0 {
                    // Visit the child on the ray's near side of the split plane first.
                    let (near, far) = if ray.neg[node.axis as usize] == 1 {
                        (node.offset, i as u32 + 1)
                    } else {
                        (i as u32 + 1, node.offset)
                    };
                    stack[sp] = far;
                    sp += 1;
                    i = near as usize;
                    continue;
                }
                for p in node.offset..node.offset + u32::from(node.count) {
                    if let Some(t) = hit(p, tmax)
                        && t < tmax
                    {
                        tmax = t;
                        best = Some((p, t));
                    }
                }
            }
            if sp == 0 {
                return best;
            }
            sp -= 1;
            i = stack[sp] as usize;
        }
    }

    /// Any hit in `(0, tmax)`: stops at the first primitive for which `hit(prim, tmax)` is true.
    pub fn any_hit(&self, o: Vec3A, d: Vec3A, tmax: f32, mut hit: impl FnMut(u32, f32) -> bool) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let ray = RayBox::new(o, d);
        let mut stack = [0u32; MAX_DEPTH];
        let mut sp = 0;
        let mut i = 0usize;
        loop {
            let node = &self.nodes[i];
            if ray.hits(&node.b, tmax) {
                if node.count == 0 {
                    let (near, far) = if ray.neg[node.axis as usize] == 1 {
                        (node.offset, i as u32 + 1)
                    } else {
                        (i as u32 + 1, node.offset)
                    };
                    stack[sp] = far;
                    sp += 1;
                    i = near as usize;
                    continue;
                }
                if (node.offset..node.offset + u32::from(node.count)).any(|p| hit(p, tmax)) {
                    return true;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            i = stack[sp] as usize;
        }
    }

    /// Number of nodes (0 for an empty BVH).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Heap bytes of the BVH itself.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node>()
    }

    /// The box around everything (empty for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        self.nodes
            .first()
            .map_or(Aabb::EMPTY, |n| Aabb { min: Vec3::from_array(n.b[0]), max: Vec3::from_array(n.b[1]) })
    }

    /// Depth of the deepest leaf (the root has depth 0); 0 for an empty BVH.
    pub fn depth(&self) -> usize {
        fn rec(nodes: &[Node], i: usize) -> usize {
            let n = &nodes[i];
            if n.count > 0 { 0 } else { 1 + rec(nodes, i + 1).max(rec(nodes, n.offset as usize)) }
        }
        if self.nodes.is_empty() { 0 } else { rec(&self.nodes, 0) }
    }
}

/// How to split a node's primitives.
enum Split {
    /// Make a leaf.
    Leaf,
    /// Left child gets centroids in bins `0..=bin` along `axis`.
    Bin { axis: usize, bin: usize },
    /// Split at the centroid median along the widest centroid axis.
    Median,
}

/// Builds the subtree over `refs` (which start at primitive `first`), appending its nodes depth-first.
fn build_node(refs: &mut [Ref], first: u32, depth: u32, nodes: &mut Vec<Node>) {
    let bounds = refs.iter().fold(Aabb::EMPTY, |b, r| b.union(r.bounds));
    let cbounds = refs.iter().fold(Aabb::EMPTY, |b, r| b.grow(r.c));
    let index = nodes.len();
    nodes.push(Node::new(bounds));
    let n = refs.len();
    let split = if n == 1 {
        Split::Leaf
    } else if depth >= SAH_DEPTH {
        if n <= MAX_LEAF { Split::Leaf } else { Split::Median }
    } else {
        sah_split(refs, &bounds, &cbounds)
    };
    let (mid, axis) = match split {
        Split::Leaf => {
            nodes[index].offset = first;
            nodes[index].count = n as u16;
            return;
        }
        Split::Bin { axis, bin } => {
            let (lo, scale) = bin_params(&cbounds, axis);
            (partition(refs, |r| bin_of(r.c[axis], lo, scale) <= bin), axis)
        }
        Split::Median => {
            let ext = cbounds.max - cbounds.min;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = n / 2;
            refs.select_nth_unstable_by(mid, |a, b| a.c[axis].total_cmp(&b.c[axis]).then(a.index.cmp(&b.index)));
            (mid, axis)
        }
    };
    let (left, right) = refs.split_at_mut(mid);
    build_node(left, first, depth + 1, nodes);
    let second = nodes.len() as u32;
    build_node(right, first + mid as u32, depth + 1, nodes);
    nodes[index].offset = second;
    nodes[index].axis = axis as u8;
}

/// Lower centroid bound and bins-per-unit scale along `axis`; the scale is 0 for a flat or non-finite extent,
/// which puts every centroid in bin 0.
#[inline]
fn bin_params(cbounds: &Aabb, axis: usize) -> (f32, f32) {
    let lo = cbounds.min[axis];
    let ext = cbounds.max[axis] - lo;
    let scale = if ext > 0.0 && ext.is_finite() { BINS as f32 / ext } else { 0.0 };
    (lo, scale)
}

#[inline]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    // `as` saturates (NaN → 0), and the top edge maps to BINS, hence the min.
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Chooses the cheapest binned split over all axes, or a leaf when that is cheaper and small enough.
fn sah_split(refs: &[Ref], bounds: &Aabb, cbounds: &Aabb) -> Split {
    let n = refs.len();
    let params = [bin_params(cbounds, 0), bin_params(cbounds, 1), bin_params(cbounds, 2)];
    let mut bins = [[(Aabb::EMPTY, 0u32); BINS]; 3];
    for r in refs {
        for (axis, &(lo, scale)) in params.iter().enumerate() {
            let b = &mut bins[axis][bin_of(r.c[axis], lo, scale)];
            b.0 = b.0.union(r.bounds);
            b.1 += 1;
        }
    }
    // Cost in units of one primitive test times the parent's half area: (A_l·N_l + A_r·N_r).
    let mut best: Option<(f32, usize, usize)> = None;
    for (axis, bins) in bins.iter().enumerate() {
        if params[axis].1 == 0.0 {
            continue;
        }
        let mut right_cost = [0.0f32; BINS];
        let (mut rb, mut rn) = (Aabb::EMPTY, 0u32);
        for k in (1..BINS).rev() {
            rb = rb.union(bins[k].0);
            rn += bins[k].1;
            right_cost[k] = rb.half_area() * rn as f32;
        }
        let (mut lb, mut ln) = (Aabb::EMPTY, 0u32);
        for k in 0..BINS - 1 {
            lb = lb.union(bins[k].0);
            ln += bins[k].1;
            // Both sides must be non-empty (so the right side's cost was set).
            if ln == 0 || ln as usize == n {
                continue;
            }
            let cost = lb.half_area() * ln as f32 + right_cost[k + 1];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    let leaf_cost = n as f32 * bounds.half_area();
    match best {
        Some((cost, axis, bin)) => {
            let split_cost = TRAVERSAL_COST * bounds.half_area() + cost;
            if n <= MAX_LEAF && leaf_cost <= split_cost { Split::Leaf } else { Split::Bin { axis, bin } }
        }
        None if n <= MAX_LEAF => Split::Leaf,
        None => Split::Median,
    }
}

/// Moves the elements satisfying `left` to the front (a deterministic in-place partition); returns their count.
fn partition(refs: &mut [Ref], left: impl Fn(&Ref) -> bool) -> usize {
    let mut i = 0;
    let mut j = refs.len();
    loop {
        while i < j && left(&refs[i]) {
            i += 1;
        }
        while i < j && !left(&refs[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        refs.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fmath;

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

    #[test]
    fn closest_and_any_hit_agree_with_brute_force_on_boxes() {
        let mut s = crate::math::rng::Sampler::new(3, crate::math::rng::Domain::Photon, 0, 0, 0);
        let mut v = || Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
        let b: Vec<Aabb> = (0..500).map(|_| cube(10.0 * v(), 0.2 * v().x)).collect();
        let rays: Vec<(Vec3A, Vec3A)> =
            (0..2000).map(|_| (Vec3A::from(12.0 * v() - 1.0), fmath::normalize(Vec3A::from(v() - 0.5)))).collect();
        let (bvh, order) = Bvh::build(&b);
        let b: Vec<Aabb> = order.iter().map(|&i| b[i as usize]).collect();
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

    #[test]
    fn geometric_centroids_stay_within_depth_cap() {
        // Centroids at 2^-k make every SAH split peel off one primitive.
        let b: Vec<Aabb> = (0..200).map(|k| cube(Vec3::splat((-(k as f32)).exp2()), 0.0)).collect();
        let (bvh, _) = Bvh::build(&b);
        assert!(bvh.depth() <= MAX_DEPTH);
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
