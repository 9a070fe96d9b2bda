//! The binary tree of the BVH ([`super`]): a binned surface-area-heuristic build over primitive bounds (Wald,
//! "On fast Construction of SAH-based Bounding Volume Hierarchies", 2007; pbrt-v4 §7.3.2), parallel and
//! deterministic. Large nodes bin their primitives in fixed chunks of [`CHUNK`] on rayon and merge the chunks
//! in order, and large subtrees are rayon tasks; every split is a function of the node's primitives alone, so
//! any number of threads builds the same tree. Deeper than `SAH_DEPTH` nodes split at the centroid median, so no
//! leaf is deeper than [`MAX_DEPTH`].

use crate::math::Aabb;
use glam::{Vec3, Vec3A};
use rayon::prelude::*;

/// Number of SAH bins per axis.
pub const BINS: usize = 16;

/// Most primitives in a leaf; the SAH may stop earlier.
pub const MAX_LEAF: usize = 8;

/// Below this depth splits are chosen by the SAH; deeper nodes (only reached by pathological inputs, such as
/// centroids spaced geometrically) are split at the centroid median, which halves the count at each level.
const SAH_DEPTH: u32 = 32;

/// Bound on the depth of any leaf, and of the traversal stack: 32 SAH levels (`SAH_DEPTH`), then at most 29 median
/// levels take fewer than 2³² primitives down to [`MAX_LEAF`] = 2³.
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
pub(super) struct Node {
    /// `[min, max]` of the box.
    pub(super) b: [[f32; 3]; 2],
    /// Leaf: index of the first primitive. Interior: index of the second child (the first is the next node).
    pub(super) offset: u32,
    /// Number of primitives; 0 marks an interior node.
    pub(super) count: u16,
    /// Split axis of an interior node.
    pub(super) axis: u8,
}

impl Node {
    fn new(bounds: Aabb) -> Self {
        // `+ 0` turns −0 into +0: which of the two a union keeps depends on the order it met them in, and the box
        // test cannot tell them apart, so the stored box does not depend on the primitives' order.
        let zero = |v: Vec3| (v + Vec3::ZERO).to_array();
        Self { b: [zero(bounds.min), zero(bounds.max)], offset: 0, count: 0, axis: 0 }
    }
}

/// A node of the traversed tree: up to [`WIDTH`] children, their boxes as structure of arrays. 128 bytes, two
/// coordinate of the box added is ignored, as `f32::min` and `f32::max` ignore it, on every target.
#[derive(Clone, Copy)]
struct Box3 {
    min: Vec3A,
    max: Vec3A,
}

impl Box3 {
    const EMPTY: Box3 = Box3 { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };

    #[inline(always)]
    fn union(self, o: Box3) -> Box3 {
        Box3 {
            min: Vec3A::select(o.min.cmplt(self.min), o.min, self.min),
            max: Vec3A::select(o.max.cmpgt(self.max), o.max, self.max),
        }
    }

    #[inline(always)]
    fn grow(self, p: Vec3A) -> Box3 {
        self.union(Box3 { min: p, max: p })
    }

    fn aabb(self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }
}

/// A primitive during the build (48 bytes).
#[derive(Clone, Copy)]
struct Ref {
    b: Box3,
    /// Centroid, with non-finite components (empty or infinite boxes) replaced by 0 so binning stays defined.
    c: Vec3,
    index: u32,
}

/// A traversal stack entry: a child slot's content and its near distance.
/// The binary SAH tree over non-empty `bounds` (root at 0, depth-first) and the primitive order.
pub(super) fn build_binary(bounds: &[Aabb]) -> (Vec<Node>, Vec<u32>) {
    let mut refs: Vec<Ref> = bounds
        .par_iter()
        .enumerate()
        .map(|(i, &b)| {
            let c = b.center();
            let c = Vec3::select(c.is_finite_mask(), c, Vec3::ZERO);
            Ref { b: Box3 { min: b.min.into(), max: b.max.into() }, c, index: i as u32 }
        })
        .collect();
    let mut binary = Vec::with_capacity(bounds.len() + bounds.len() / 4);
    build_node(&mut refs, 0, 0, &mut binary, None);
    (binary, refs.iter().map(|r| r.index).collect())
}

enum Split {
    /// Make a leaf.
    Leaf,
    /// Left child gets centroids in bins `0..=bin` along `axis`; `left` and `right` are the children's boxes.
    Bin { axis: usize, bin: usize, left: Box3, right: Box3 },
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
fn build_node(refs: &mut [Ref], first: u32, depth: u32, nodes: &mut Vec<Node>, extent: Option<Extent>) {
    let (bounds, cbounds) = extent.unwrap_or_else(|| {
        chunked(
            refs,
            |rs| rs.iter().fold((Box3::EMPTY, Box3::EMPTY), |(b, c), r| (b.union(r.b), c.grow(r.c.into()))),
            |(b0, c0), (b1, c1)| (b0.union(b1), c0.union(c1)),
        )
    });
    let (bounds, cbounds) = (bounds.aabb(), cbounds.aabb());
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
    let (mid, axis, extents) = match split {
        Split::Leaf => {
            nodes[index].offset = first;
            nodes[index].count = n as u16;
            return;
        }
        Split::Bin { axis, bin, left, right } => {
            let (lo, scale) = bin_params(&cbounds, axis);
            let (mid, left_c, right_c) = partition(refs, |r| bin_of(r.c[axis], lo, scale) <= bin);
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
            let cmp = |a: &Ref, b: &Ref| a.c[axis].total_cmp(&b.c[axis]).then(a.index.cmp(&b.index));
            // Left as it is when already split (as the partition leaves split input alone), so that a build
            // over primitives in a tree's order gives that tree and that order again.
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
            build_node(refs, first, depth + 1, &mut v, extent);
            v
        };
        let (l, r) = rayon::join(|| build(left, first, left_extent), || build(right, first + mid as u32, right_extent));
        append_shifted(nodes, l);
        let second = nodes.len() as u32;
        append_shifted(nodes, r);
        nodes[index].offset = second;
    } else {
        build_node(left, first, depth + 1, nodes, left_extent);
        let second = nodes.len() as u32;
        build_node(right, first + mid as u32, depth + 1, nodes, right_extent);
        nodes[index].offset = second;
    }
    nodes[index].axis = axis as u8;
}

/// Appends a subtree built with indices from 0, shifting its interior nodes' child indices to where it lands.
fn append_shifted(nodes: &mut Vec<Node>, sub: Vec<Node>) {
    let base = nodes.len() as u32;
    nodes.extend(sub.into_iter().map(|mut n| {
        if n.count == 0 {
            n.offset += base;
        }
        n
    }));
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

/// A node's box and the box of its primitives' centroids.
type Extent = (Box3, Box3);

/// Per axis and bin: the union of the boxes and the count of the primitives whose centroids fall in it.
type Bins = [[(Box3, u32); BINS]; 3];

/// Chooses the cheapest binned split over all axes, or a leaf when that is cheaper and small enough.
fn sah_split(refs: &[Ref], bounds: &Aabb, cbounds: &Aabb) -> Split {
    let n = refs.len();
    let params = [bin_params(cbounds, 0), bin_params(cbounds, 1), bin_params(cbounds, 2)];
    let lo = Vec3A::new(params[0].0, params[1].0, params[2].0);
    let scale = Vec3A::new(params[0].1, params[1].1, params[2].1);
    let bins: Bins = chunked(
        refs,
        |rs| {
            let mut bins = [[(Box3::EMPTY, 0u32); BINS]; 3];
            for r in rs {
                // `bin_of` on the three axes at once: the same subtraction and product in each lane.
                let f = (Vec3A::from(r.c) - lo) * scale;
                for (axis, bins) in bins.iter_mut().enumerate() {
                    // `as` saturates (NaN → 0), and the top edge maps to BINS, hence the min.
                    let b = &mut bins[(f[axis] as usize).min(BINS - 1)];
                    b.0 = b.0.union(r.b);
                    b.1 += 1;
                }
            }
            bins
        },
        |mut a, b| {
            for (a, b) in a.iter_mut().flatten().zip(b.iter().flatten()) {
                *a = (a.0.union(b.0), a.1 + b.1);
            }
            a
        },
    );
    // Cost in units of one primitive test times the parent's half area: (A_l·N_l + A_r·N_r).
    let mut best: Option<(f32, usize, usize)> = None;
    for (axis, bins) in bins.iter().enumerate() {
        if params[axis].1 == 0.0 {
            continue;
        }
        // Small nodes leave most bins empty, and an empty bin changes neither side's box nor count: its right
        // cost is the next bin's, and its split costs exactly what the split before it costs, which the strict
        // `<` below never prefers. Skipping them gives the same choice at a fraction of the work.
        let mut right_cost = [0.0f32; BINS];
        let (mut rb, mut rn, mut cost) = (Box3::EMPTY, 0u32, 0.0f32);
        for k in (1..BINS).rev() {
            if bins[k].1 > 0 {
                rb = rb.union(bins[k].0);
                rn += bins[k].1;
                cost = rb.aabb().half_area() * rn as f32;
            }
            right_cost[k] = cost;
        }
        let (mut lb, mut ln) = (Box3::EMPTY, 0u32);
        for k in 0..BINS - 1 {
            if bins[k].1 == 0 {
                continue;
            }
            lb = lb.union(bins[k].0);
            ln += bins[k].1;
            // Both sides must be non-empty (so the right side's cost was set).
            if ln == 0 || ln as usize == n {
                continue;
            }
            let cost = lb.aabb().half_area() * ln as f32 + right_cost[k + 1];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    let leaf_cost = n as f32 * bounds.half_area();
    match best {
        Some((cost, axis, bin)) => {
            let split_cost = TRAVERSAL_COST * bounds.half_area() + cost;
            if n <= MAX_LEAF && leaf_cost <= split_cost {
                Split::Leaf
            } else {
                let (l, r) = bins[axis].split_at(bin + 1);
                let union = |bins: &[(Box3, u32)]| bins.iter().fold(Box3::EMPTY, |b, bin| b.union(bin.0));
                Split::Bin { axis, bin, left: union(l), right: union(r) }
            }
        }
        None if n <= MAX_LEAF => Split::Leaf,
        None => Split::Median,
    }
}

/// Moves the elements satisfying `left` to the front (a deterministic in-place partition); returns their count
/// and the boxes of the two sides' centroids (each element is classified once, and added to its side's box then).
fn partition(refs: &mut [Ref], left: impl Fn(&Ref) -> bool) -> (usize, Box3, Box3) {
    let (mut lc, mut rc) = (Box3::EMPTY, Box3::EMPTY);
    let mut i = 0;
    let mut j = refs.len();
    loop {
        while i < j && left(&refs[i]) {
            lc = lc.grow(refs[i].c.into());
            i += 1;
        }
        while i < j && !left(&refs[j - 1]) {
            rc = rc.grow(refs[j - 1].c.into());
            j -= 1;
        }
        if i >= j {
            return (i, lc, rc);
        }
        refs.swap(i, j - 1);
        lc = lc.grow(refs[i].c.into());
        rc = rc.grow(refs[j - 1].c.into());
        i += 1;
        j -= 1;
    }
}
