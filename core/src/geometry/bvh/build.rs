//! The binary tree of the BVH ([`super`]): a binned surface-area-heuristic build over primitive bounds (Wald,
//! "On fast Construction of SAH-based Bounding Volume Hierarchies", 2007; pbrt-v4 §7.3.2), parallel and
//! deterministic. Large nodes bin their primitives in fixed chunks of [`CHUNK`] on rayon and merge the chunks
//! in order, and large subtrees are rayon tasks; every split is a function of the node's primitives alone, so
//! any number of threads builds the same tree. Deeper than `SAH_DEPTH` nodes split at the centroid median, so no
//! leaf is deeper than [`MAX_DEPTH`].

use crate::math::Aabb;
use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;
use wide::f32x4;

/// Number of SAH bins per axis of nodes of more than [`SMALL_NODE`] primitives.
pub const BINS: usize = 16;

/// Number of SAH bins per axis of smaller nodes: most nodes are small, and for them the bins' fixed cost (clearing
/// and sweeping them) outweighs the binning; eight bins choose nearly as well.
pub const SMALL_BINS: usize = 8;

/// Nodes of at most this many primitives are binned into [`SMALL_BINS`].
pub const SMALL_NODE: usize = 64;

/// Most primitives in a leaf of the general tree ([`Leaves::GENERAL`]); the SAH may stop earlier.
pub const MAX_LEAF: usize = 8;

/// What a leaf may hold and what testing it costs, for the SAH: a leaf of `n` primitives costs
/// `⌈n / group⌉ · group_cost` node visits, and holds at most `max`. Triangle blocks are tested four at once, so a
/// leaf of 1 to 4 triangles costs one block test (the leaf cost of tinybvh's 4-wide layouts, Bikker 2024).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leaves {
    /// Most primitives in a leaf, 1 to [`MAX_LEAF`] (median splits then stay within [`MAX_DEPTH`]).
    pub max: usize,
    /// Primitives tested together: a power of two.
    pub group: usize,
    /// Cost of testing one group, in node visits.
    pub group_cost: f32,
    /// Most primitives in a leaf made, when the binary tree is collapsed, of two sibling leaves whose parent would
    /// otherwise be a wide node of two slots (at most [`MAX_LEAF`]).
    pub merge: usize,
}

impl Leaves {
    /// Spheres, rectangles and other shapes tested one at a time: a leaf holds one, or two that would otherwise
    /// make a node of two slots. A shape's test costs about what a node's does, and the wide nodes sort out which
    /// of their children a ray meets: the walls of a room, each a leaf, are tested only where the ray crosses them,
    /// where one leaf of all of them (what the SAH prefers, their boxes overlapping the room's) tests every wall
    /// for every ray.
    pub const GENERAL: Leaves = Leaves { max: 1, group: 1, group_cost: 1.0, merge: 2 };

    /// The SAH cost of a leaf of `n` primitives, in node visits.
    #[inline]
    pub fn cost(self, n: u32) -> f32 {
        // A shift, not a division: this runs for every bin of every node.
        ((n + self.group as u32 - 1) >> self.group.trailing_zeros()) as f32 * self.group_cost
    }
}

/// Below this depth splits are chosen by the SAH; deeper nodes (only reached by pathological inputs, such as
/// centroids spaced geometrically) are split at the centroid median, which halves the count at each level.
const SAH_DEPTH: u32 = 32;

/// Bound on the depth of any leaf, and of the traversal stack: 32 SAH levels (`SAH_DEPTH`), then at most 28 median
/// levels take fewer than 2²⁸ primitives ([`super::MAX_INDEX`]) down to one.
pub const MAX_DEPTH: usize = 64;

/// Cost of one node visit relative to one primitive test, for the SAH.
const TRAVERSAL_COST: f32 = 1.0;

/// Nodes with more primitives than this bin them in parallel, in chunks of [`CHUNK`].
const PARALLEL_BINNING: usize = 1 << 16;

/// Primitives per binning chunk; fixed, so the merge order does not depend on the thread count.
pub const CHUNK: usize = 1 << 14;

/// Subtrees with more primitives than this are built as rayon tasks.
const PARALLEL_SUBTREE: usize = 1 << 14;

/// A node of the binary build tree: its box and either a leaf range or the second child's index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct BinaryNode {
    /// `[min, max]` of the box.
    pub(super) b: [[f32; 3]; 2],
    /// Leaf: index of the first primitive. Interior: index of the second child (the first is the next node).
    pub(super) offset: u32,
    /// Number of primitives; 0 marks an interior node.
    pub(super) count: u16,
    /// Split axis of an interior node.
    pub(super) axis: u8,
}

impl BinaryNode {
    fn new(bounds: Aabb) -> Self {
        // `+ 0` turns −0 into +0: which of the two a union keeps depends on the order it met them in, and the box
        // test cannot tell them apart, so the stored box does not depend on the primitives' order.
        let zero = |v: Vec3| (v + Vec3::ZERO).to_array();
        Self { b: [zero(bounds.min), zero(bounds.max)], offset: 0, count: 0, axis: 0 }
    }
}

/// A box held in SIMD registers during the build. `union` takes each coordinate as `o < self ? o : self` (and
/// `>` for the maxima), so a NaN coordinate of the box added is ignored, as `f32::min` and `f32::max` ignore it,
/// on every target: `minps`/`maxps` on x86 are exactly that; elsewhere a compare and a select.
#[derive(Clone, Copy)]
struct Box3 {
    min: Vec3A,
    max: Vec3A,
}

impl Box3 {
    const EMPTY: Box3 = Box3 { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };

    #[inline(always)]
    fn union(self, o: Box3) -> Box3 {
        #[cfg(target_arch = "x86_64")]
        {
            // glam's `min`/`max` on SSE2 are `minps`/`maxps` with `o` first: `o < self ? o : self`.
            Box3 { min: o.min.min(self.min), max: o.max.max(self.max) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            Box3 {
                min: Vec3A::select(o.min.cmplt(self.min), o.min, self.min),
                max: Vec3A::select(o.max.cmpgt(self.max), o.max, self.max),
            }
        }
    }

    #[inline(always)]
    fn grow(self, p: Vec3A) -> Box3 {
        self.union(Box3 { min: p, max: p })
    }

    /// Half the surface area, as [`Aabb::half_area`] computes it (the same operations, so the same bits).
    #[inline(always)]
    fn half_area(self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    fn aabb(self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }
}

/// A primitive during the build: its box, with its index in the spare lane of the minimum (32 bytes, so a cache
/// line holds two). Binning uses `min + max`, twice the centroid, which saves the halving.
#[derive(Clone, Copy)]
struct Ref {
    /// `x, y, z`: the box's minimum; `w`: the primitive's index, as bits.
    min: Vec4,
    max: Vec4,
}

impl Ref {
    #[inline(always)]
    fn index(&self) -> u32 {
        self.min.w.to_bits()
    }

    #[inline(always)]
    fn b(&self) -> Box3 {
        Box3 { min: Vec3A::from_vec4(self.min), max: Vec3A::from_vec4(self.max) }
    }

    /// Twice the centroid, with non-finite components (empty or infinite boxes) replaced by 0 so that binning
    /// stays defined.
    #[inline(always)]
    fn c(&self) -> Vec3A {
        let c = Vec3A::from_vec4(self.min) + Vec3A::from_vec4(self.max);
        Vec3A::select(c.is_finite_mask(), c, Vec3A::ZERO)
    }
}

/// The binary SAH tree over the boxes `bound(0)`, `bound(1)`, … `bound(count − 1)` that are not `None` (root at
/// 0, depth-first) and the primitive order: the `i` of each box, in leaf order. `None` when every box is.
pub(super) fn build_binary(
    count: usize,
    bound: impl Fn(usize) -> Option<Aabb> + Sync,
    leaves: Leaves,
) -> Option<(Vec<BinaryNode>, Vec<u32>)> {
    // A box left out is marked by a maximum's `w` of 1 (an exact-size parallel map, then one pass to drop them).
    let mut refs: Vec<Ref> = (0..count)
        .into_par_iter()
        .map(|i| {
            let (b, out) = bound(i).map_or((Aabb::EMPTY, 1.0), |b| (b, 0.0));
            Ref { min: b.min.extend(f32::from_bits(i as u32)), max: b.max.extend(out) }
        })
        .collect();
    refs.retain(|r| r.max.w == 0.0);
    if refs.is_empty() {
        return None;
    }
    let mut binary = Vec::with_capacity(refs.len() + refs.len() / 4);
    build_node(&mut refs, 0, 0, &mut binary, None, leaves);
    Some((binary, refs.iter().map(Ref::index).collect()))
}

enum Split {
    /// Make a leaf.
    Leaf,
    /// Left child gets centroids in bins `0..=bin` of `bins` along `axis`; `left` and `right` are the children's
    /// boxes.
    Bin { axis: usize, bin: usize, bins: usize, left: Box3, right: Box3 },
    /// Split at the centroid median along the widest centroid axis.
    Median,
}

/// Applies `f` to `refs`, in chunks of [`CHUNK`] on rayon when there are more than [`PARALLEL_BINNING`], and
/// merges the chunks' results in order.
fn chunked<T: Send>(refs: &[Ref], f: impl Fn(&[Ref]) -> T + Sync + Send, merge: impl Fn(T, T) -> T) -> T {
    if refs.len() <= PARALLEL_BINNING {
        return f(refs);
    }
    let parts: Vec<T> = refs.par_chunks(CHUNK).map(&f).collect();
    let mut parts = parts.into_iter();
    // There is at least one chunk, since refs is longer than PARALLEL_BINNING.
    let first = parts.next().unwrap_or_else(|| f(&[]));
    parts.fold(first, merge)
}

/// Builds the subtree over `refs` (which start at primitive `first`), appending its nodes depth-first.
///
/// `extent` is the box and centroid box of `refs` when the parent's split already found them.
fn build_node(
    refs: &mut [Ref],
    first: u32,
    depth: u32,
    nodes: &mut Vec<BinaryNode>,
    extent: Option<Extent>,
    leaves: Leaves,
) {
    let (bounds, cbounds) = extent.unwrap_or_else(|| {
        chunked(
            refs,
            |rs| rs.iter().fold((Box3::EMPTY, Box3::EMPTY), |(b, c), r| (b.union(r.b()), c.grow(r.c()))),
            |(b0, c0), (b1, c1)| (b0.union(b1), c0.union(c1)),
        )
    });
    let (bounds, cbounds) = (bounds.aabb(), cbounds.aabb());
    let index = nodes.len();
    nodes.push(BinaryNode::new(bounds));
    let n = refs.len();
    // A node that one group of primitives holds is a leaf: splitting it would cost a second group test for the
    // same primitives.
    let split = if n <= leaves.group.min(leaves.max) {
        Split::Leaf
    } else if depth >= SAH_DEPTH {
        if n <= leaves.max { Split::Leaf } else { Split::Median }
    } else if n > SMALL_NODE {
        sah_split::<BINS>(refs, &bounds, &cbounds, leaves)
    } else {
        sah_split::<SMALL_BINS>(refs, &bounds, &cbounds, leaves)
    };
    let (mid, axis, extents) = match split {
        Split::Leaf => {
            nodes[index].offset = first;
            nodes[index].count = n as u16;
            return;
        }
        Split::Bin { axis, bin, bins, left, right } => {
            let (lo, scale) = bin_params(&cbounds, axis, bins);
            // The bin of centroid c is ⌊f⌋ for f = (c − lo)·scale ≥ 0 ([`Bins::add`]), and ⌊f⌋ ≤ bin ⟺ f < bin + 1
            // (bin + 1 < bins, so the clamp to the last bin never matters): no conversion.
            let limit = (bin + 1) as f32;
            let (mid, left_c, right_c) = partition(refs, |r| (r.c()[axis] - lo) * scale < limit);
            (mid, axis, [Some((left, left_c)), Some((right, right_c))])
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
            let cmp = |a: &Ref, b: &Ref| a.c()[axis].total_cmp(&b.c()[axis]).then(a.index().cmp(&b.index()));
            // Left as it is when already split: the selection is skipped.
            let (l, r) = refs.split_at(mid);
            let split = match (l.iter().max_by(|a, b| cmp(a, b)), r.iter().min_by(|a, b| cmp(a, b))) {
                (Some(a), Some(b)) => cmp(a, b).is_lt(),
                _ => true,
            };
            if !split {
                refs.select_nth_unstable_by(mid, cmp);
            }
            (mid, axis, [None, None])
        }
    };
    let [left_extent, right_extent] = extents;
    let (left, right) = refs.split_at_mut(mid);
    // The tree does not depend on which branch runs; one thread gains nothing from the copies of the first.
    if n > PARALLEL_SUBTREE && rayon::current_num_threads() > 1 {
        // Both halves as tasks into their own arrays, then appended: the node indices they hold are relative to
        // their own start until shifted.
        let build = |refs: &mut [Ref], first: u32, extent: Option<Extent>| {
            // About 1.1 nodes per primitive with leaves of up to MAX_LEAF.
            let mut v = Vec::with_capacity(refs.len() + refs.len() / 4);
            build_node(refs, first, depth + 1, &mut v, extent, leaves);
            v
        };
        let (l, r) = rayon::join(|| build(left, first, left_extent), || build(right, first + mid as u32, right_extent));
        append_shifted(nodes, l);
        let second = nodes.len() as u32;
        append_shifted(nodes, r);
        nodes[index].offset = second;
    } else {
        build_node(left, first, depth + 1, nodes, left_extent, leaves);
        let second = nodes.len() as u32;
        build_node(right, first + mid as u32, depth + 1, nodes, right_extent, leaves);
        nodes[index].offset = second;
    }
    nodes[index].axis = axis as u8;
}

/// Appends a subtree built with indices from 0, shifting its interior nodes' child indices to where it lands.
fn append_shifted(nodes: &mut Vec<BinaryNode>, sub: Vec<BinaryNode>) {
    let base = nodes.len() as u32;
    nodes.extend(sub.into_iter().map(|mut n| {
        if n.count == 0 {
            n.offset += base;
        }
        n
    }));
}

/// Lower centroid bound and bins-per-unit scale along `axis`, for `bins` bins; the scale is 0 for a flat or
/// non-finite extent, which puts every centroid in bin 0.
#[inline]
fn bin_params(cbounds: &Aabb, axis: usize, bins: usize) -> (f32, f32) {
    let lo = cbounds.min[axis];
    let ext = cbounds.max[axis] - lo;
    let scale = if ext > 0.0 && ext.is_finite() { bins as f32 / ext } else { 0.0 };
    (lo, scale)
}

/// A node's box and the box of its primitives' centroids.
type Extent = (Box3, Box3);

/// Per axis and bin: the union of the boxes and the count of the primitives whose centroids fall in it.
#[derive(Clone, Copy)]
struct Bins<const B: usize> {
    boxes: [[Box3; B]; 3],
    counts: [[u32; B]; 3],
}

impl<const B: usize> Bins<B> {
    const EMPTY: Self = Bins { boxes: [[Box3::EMPTY; B]; 3], counts: [[0; B]; 3] };

    /// Adds `refs`, binned by `(c − lo)·scale` per axis.
    ///
    /// Neighbouring references often fall in the same bin, and each update of a bin waits for the previous one
    /// to be stored: above [`SMALL_NODE`] references, the even and the odd ones go to two sets of bins, merged at
    /// the end, which halves the chain.
    #[inline(always)]
    fn add(&mut self, refs: &[Ref], lo: Vec3A, scale: Vec3A) {
        if refs.len() <= SMALL_NODE {
            // Too few for the second set's clearing and merging to pay.
            refs.iter().for_each(|r| self.add_one(r, lo, scale));
            return;
        }
        let mut odd = Self::EMPTY;
        let mut pairs = refs.chunks_exact(2);
        for pair in &mut pairs {
            self.add_one(&pair[0], lo, scale);
            odd.add_one(&pair[1], lo, scale);
        }
        for r in pairs.remainder() {
            self.add_one(r, lo, scale);
        }
        *self = self.merge(odd);
    }

    /// Adds one reference.
    #[inline(always)]
    fn add_one(&mut self, r: &Ref, lo: Vec3A, scale: Vec3A) {
        let top = Vec3A::splat((B - 1) as f32);
        // The bin on the three axes at once: ⌊(c − lo)·scale⌋, which is in [0, B] (the centroid is finite and
        // not below `lo`; the top edge maps to B, hence the min), so one truncating conversion of the three
        // lanes gives it.
        let f = ((r.c() - lo) * scale).min(top);
        let k = f32x4::from(Vec4::from((f, 0.0)).to_array()).fast_trunc_int().to_array();
        let b = r.b();
        for axis in 0..3 {
            let k = (k[axis] as usize).min(B - 1);
            self.boxes[axis][k] = self.boxes[axis][k].union(b);
            self.counts[axis][k] += 1;
        }
    }

    fn merge(mut self, o: Self) -> Self {
        for axis in 0..3 {
            for k in 0..B {
                self.boxes[axis][k] = self.boxes[axis][k].union(o.boxes[axis][k]);
                self.counts[axis][k] += o.counts[axis][k];
            }
        }
        self
    }
}

/// Chooses the cheapest split into `B` bins over all axes, or a leaf when that is cheaper and small enough.
fn sah_split<const B: usize>(refs: &[Ref], bounds: &Aabb, cbounds: &Aabb, leaves: Leaves) -> Split {
    let n = refs.len();
    let params = [bin_params(cbounds, 0, B), bin_params(cbounds, 1, B), bin_params(cbounds, 2, B)];
    let lo = Vec3A::new(params[0].0, params[1].0, params[2].0);
    let scale = Vec3A::new(params[0].1, params[1].1, params[2].1);
    let bin = |rs: &[Ref]| {
        let mut bins = Bins::EMPTY;
        bins.add(rs, lo, scale);
        bins
    };
    let bins: Bins<B> = chunked(refs, bin, Bins::merge);
    // Cost in node visits times the parent's half area: A_l·C(N_l) + A_r·C(N_r), C the leaf cost.
    let mut best: Option<(f32, usize, usize)> = None;
    for (axis, (boxes, counts)) in bins.boxes.iter().zip(&bins.counts).enumerate() {
        if params[axis].1 == 0.0 {
            continue;
        }
        // Small nodes leave most bins empty, and an empty bin changes neither side's box nor count: its right
        // cost is the next bin's, and its split costs exactly what the split before it costs, which the strict
        // `<` below never prefers. Skipping them gives the same choice at a fraction of the work.
        let mut right_cost = [0.0f32; B];
        let (mut rb, mut rn, mut cost) = (Box3::EMPTY, 0u32, 0.0f32);
        for k in (1..B).rev() {
            if counts[k] > 0 {
                rb = rb.union(boxes[k]);
                rn += counts[k];
                cost = rb.half_area() * leaves.cost(rn);
            }
            right_cost[k] = cost;
        }
        let (mut lb, mut ln) = (Box3::EMPTY, 0u32);
        for k in 0..B - 1 {
            if counts[k] == 0 {
                continue;
            }
            lb = lb.union(boxes[k]);
            ln += counts[k];
            // Both sides must be non-empty (so the right side's cost was set).
            if ln as usize == n {
                continue;
            }
            let cost = lb.half_area() * leaves.cost(ln) + right_cost[k + 1];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    let leaf_cost = leaves.cost(n as u32) * bounds.half_area();
    match best {
        Some((cost, axis, bin)) => {
            let split_cost = TRAVERSAL_COST * bounds.half_area() + cost;
            if n <= leaves.max && leaf_cost <= split_cost {
                Split::Leaf
            } else {
                let (l, r) = bins.boxes[axis].split_at(bin + 1);
                let union = |boxes: &[Box3]| boxes.iter().fold(Box3::EMPTY, |a, &b| a.union(b));
                Split::Bin { axis, bin, bins: B, left: union(l), right: union(r) }
            }
        }
        None if n <= leaves.max => Split::Leaf,
        None => Split::Median,
    }
}

/// Moves the elements satisfying `left` to the front (a deterministic in-place partition); returns their count
/// and the boxes of the two sides' centroids (each element is classified once, and added to its side's box then).
///
/// Branch-free Lomuto: every element is swapped to the boundary and the boundary moves on when it belongs to the
/// left, so a side that is hard to predict costs no mispredicted branches. The left side keeps its order; the
/// right side's is rotated.
fn partition(refs: &mut [Ref], left: impl Fn(&Ref) -> bool) -> (usize, Box3, Box3) {
    let (mut lc, mut rc) = (Box3::EMPTY, Box3::EMPTY);
    let nan = Vec3A::splat(f32::NAN);
    let mut l = 0;
    for i in 0..refs.len() {
        let r = refs[i];
        let (c, is_left) = (r.c(), left(&r));
        let m = glam::BVec3A::splat(is_left);
        // A NaN coordinate leaves a box as it is ([`Box3::union`]).
        lc = lc.grow(Vec3A::select(m, c, nan));
        rc = rc.grow(Vec3A::select(m, nan, c));
        refs.swap(l, i);
        l += usize::from(is_left);
    }
    (l, lc, rc)
}
