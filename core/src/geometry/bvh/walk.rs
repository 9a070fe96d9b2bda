//! The walk of the wide tree ([`super`]): the ray's SIMD box test, and one walk, specialised per octant of the
//! ray's direction, that visits the children a ray meets nearest first, prunes the stack by the best hit so far
//! (closest hit) or stops at the first hit (any hit).
//!
//! The walks know only leaves; what a leaf holds, and the rule that picks the closest hit, are the callers'
//! ([`super::Bvh`], [`super::TriBvh`]).

use super::build::MAX_DEPTH;
use super::tree::{Node, Tree, WIDTH, split_entry};
use glam::Vec3A;
use wide::f32x4;

/// The SIMD vector of half a node's slots: the box test runs on each half in turn, so the ray's six vectors
/// and both running distances stay in SSE2's or NEON's registers.
type Half = f32x4;
const _: () = assert!(WIDTH.is_multiple_of(4));

/// Traversal stack entries: each node on the path leaves at most `WIDTH − 1` siblings behind.
const STACK: usize = (WIDTH - 1) * MAX_DEPTH + 1;

/// The far distance's factor, `1 + 2γ(5)` with pbrt's `γ(n) = nε/(1 − nε)`, ε = 2⁻²⁴ (pbrt-v4 §6.8.2 uses
/// `1 + 2γ(3)` for its three roundings). The scaled far distance carries four roundings (the subtraction, the
/// reciprocal, the product, the scaling) and a near distance three, so a scaled far is never below a computed
/// near that does not exceed it exactly: no box a ray meets is missed.
const FAR_SCALE: f32 = 1.0 + 2.0 * (5.0 * f32::EPSILON * 0.5) / (1.0 - 5.0 * f32::EPSILON * 0.5);

/// How far (relative) a box's near distance may exceed the best hit so far and the box still be entered: the
/// closest-hit walk prunes with `t0 ≤ tmax · (1 + CULL_MARGIN)`. A primitive's computed hit lies before its
/// boxes' computed near distances by rounding only (a few ulps), far less than 2⁻¹⁰, so a primitive that ties
/// the best hit is always tested, whichever box holds it: which of two tied primitives wins then depends on
/// their indices alone, not on the tree.
pub const CULL_MARGIN: f32 = 1.0 / 1024.0;

/// Work counted by a walk, for measuring a tree ([`super::TriBvh::closest_hit_counted`]): deterministic, unlike
/// timings, so two trees can be compared exactly on the same rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCost {
    /// Interior nodes whose boxes were tested.
    pub nodes: u64,
    /// Leaves tested (a range of primitives, or one or two triangle blocks).
    pub leaves: u64,
    /// Primitives in the leaves tested.
    pub prims: u64,
}

/// What a walk counts: nothing for the queries that render ([`()`]), [`RayCost`] for the measures.
pub(crate) trait Count {
    fn node(&mut self);
    fn leaf(&mut self, prims: u32);
}

impl Count for () {
    #[inline(always)]
    fn node(&mut self) {}
    #[inline(always)]
    fn leaf(&mut self, _: u32) {}
}

impl Count for RayCost {
    #[inline(always)]
    fn node(&mut self) {
        self.nodes += 1;
    }
    #[inline(always)]
    fn leaf(&mut self, prims: u32) {
        self.leaves += 1;
        self.prims += u64::from(prims);
    }
}

/// Whether a hit at `t` on primitive `p` replaces `best`: it is closer, or as close with a smaller index. The
/// order is total on `(t, p)`, so the closest hit does not depend on the order primitives are tested in.
#[inline(always)]
pub(crate) fn better(t: f32, p: u32, best: Option<(u32, f32)>) -> bool {
    match best {
        None => true,
        Some((bp, bt)) => t < bt || (t == bt && p < bp),
    }
}

/// A traversal stack entry: a slot's entry ([`Node`]'s `child`) and its near distance.
#[derive(Clone, Copy)]
struct Entry {
    child: u32,
    t0: f32,
}

impl Entry {
    const ZERO: Entry = Entry { child: 0, t0: 0.0 };
}

thread_local! {
    /// Each thread's traversal stack.
    static STACKS: std::cell::RefCell<[Entry; STACK]> = const { std::cell::RefCell::new([Entry::ZERO; STACK]) };
}

/// Runs `f` on the thread's stack, so no ray pays for clearing 2 kB (it was a tenth of the traversal time); a
/// walk started from inside another's leaf callback gets a fresh one.
#[inline(always)]
fn with_stack<R>(f: impl FnOnce(&mut [Entry; STACK]) -> R) -> R {
    STACKS.with(|stack| match stack.try_borrow_mut() {
        Ok(mut stack) => f(&mut stack),
        Err(_) => f(&mut [Entry::ZERO; STACK]),
    })
}

/// A ray prepared for box tests.
pub(crate) struct RayBox {
    o: [Half; 3],
    /// `1/d` per axis (±∞ for a zero component).
    inv: [Half; 3],
    /// The octant: bit `a` is set when the direction is negative on axis `a` (from the sign of `1/d`, so that −0
    /// counts as negative consistently); such an axis enters a box through its max plane.
    octant: usize,
}

/// `a > b ? a : b` lane by lane: `b` where `a` is NaN. On x86 this is exactly `maxps a, b`; elsewhere a compare
/// and a select (NEON's `fmax` would return the NaN).
#[inline(always)]
fn max_or_second(a: Half, b: Half) -> Half {
    #[cfg(target_arch = "x86_64")]
    {
        a.fast_max(b)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        a.simd_gt(b).bitselect(a, b)
    }
}

/// `a < b ? a : b` lane by lane: `b` where `a` is NaN (`minps a, b` on x86).
#[inline(always)]
fn min_or_second(a: Half, b: Half) -> Half {
    #[cfg(target_arch = "x86_64")]
    {
        a.fast_min(b)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        a.simd_lt(b).bitselect(a, b)
    }
}

impl RayBox {
    #[inline]
    pub(crate) fn new(o: Vec3A, d: Vec3A) -> Self {
        // 1/±0 = ±∞; the sign comes from the inverse so that −0 counts as negative consistently.
        let inv = d.recip();
        let octant = usize::from(inv.x < 0.0) | usize::from(inv.y < 0.0) << 1 | usize::from(inv.z < 0.0) << 2;
        Self {
            o: [Half::splat(o.x), Half::splat(o.y), Half::splat(o.z)],
            inv: [Half::splat(inv.x), Half::splat(inv.y), Half::splat(inv.z)],
            octant,
        }
    }

    /// The child boxes of `node` against `[0, tmax]` for a ray in octant `OCT`: a bit mask of the slots hit and
    /// their near distances. Per axis `near = (b_near − o)·(1/d)` and `far = (b_far − o)·(1/d)`; `t0 = max(0,
    /// near…)`, `t1 = min(tmax, far…)·FAR_SCALE`, hit when `t0 ≤ t1`. A NaN slab distance (0·∞: a ray on a slab
    /// plane and parallel to it) leaves the interval unchanged ([`max_or_second`]), so there are no false misses.
    /// Unused slots hold an empty box (min +∞, max −∞), which no ray meets. The slots are tested four at a time
    /// ([`Half`]), each lane as it would be alone.
    ///
    /// The box test decides only which leaves are visited, never which hit is found, as long as it never misses
    /// a box the ray meets ([`FAR_SCALE`]).
    #[inline(always)]
    fn hits<const OCT: usize>(&self, node: &Node, tmax: f32) -> (u32, [f32; WIDTH]) {
        let mut mask = 0;
        let mut near = [0.0; WIDTH];
        for h in 0..WIDTH / 4 {
            let plane = |p: &[[f32; WIDTH]; 3], a: usize| {
                let s = &p[a];
                Half::from([s[4 * h], s[4 * h + 1], s[4 * h + 2], s[4 * h + 3]])
            };
            let mut t0 = Half::splat(0.0);
            let mut t1 = Half::splat(tmax);
            for a in 0..3 {
                let (bn, bf) = if (OCT >> a) & 1 == 1 { (&node.hi, &node.lo) } else { (&node.lo, &node.hi) };
                let n = (plane(bn, a) - self.o[a]) * self.inv[a];
                let f = (plane(bf, a) - self.o[a]) * self.inv[a];
                t0 = max_or_second(n, t0);
                t1 = min_or_second(f, t1);
            }
            mask |= t0.simd_le(t1 * Half::splat(FAR_SCALE)).to_bitmask() << (4 * h);
            near[4 * h..4 * h + 4].copy_from_slice(&t0.to_array());
        }
        (mask, near)
    }
}

/// Calls `$f::<OCT>` with the ray's octant as a constant, so that each walk is compiled once per octant and
/// chooses each axis's near and far planes at compile time.
macro_rules! by_octant {
    ($octant:expr, $f:ident, $($arg:expr),*) => {
        match $octant {
            0 => $f::<0>($($arg),*),
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            5 => $f::<5>($($arg),*),
            6 => $f::<6>($($arg),*),
            _ => $f::<7>($($arg),*),
        }
    };
}

impl Tree {
    /// The closest-hit walk: calls `leaf(child, count, tmax)` for the leaves whose boxes the ray meets within the
    /// pruning bound of `tmax` ([`CULL_MARGIN`]), the children of each node nearest first; `leaf` lowers `tmax`
    /// as it finds hits.
    #[inline(always)]
    pub(crate) fn closest(
        &self,
        ray: &RayBox,
        tmax: &mut f32,
        cost: &mut impl Count,
        mut leaf: impl FnMut(u32, u32, &mut f32),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let leaf = {
            #[inline(always)]
            |child, count, tmax: &mut f32| {
                leaf(child, count, tmax);
                false
            }
        };
        by_octant!(ray.octant, walk, self, ray, tmax, cost, leaf);
    }

    /// The any-hit walk: calls `leaf(child, count)` for the leaves whose boxes the ray meets within `[0, tmax]`,
    /// the children of each node nearest first, until one returns true; returns whether one did.
    #[inline(always)]
    pub(crate) fn any(
        &self,
        ray: &RayBox,
        mut tmax: f32,
        cost: &mut impl Count,
        mut leaf: impl FnMut(u32, u32) -> bool,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        by_octant!(ray.octant, walk, self, ray, &mut tmax, cost, |child, count, _: &mut f32| leaf(child, count))
    }
}

/// The walk of both queries for rays in octant `OCT`: visits the leaves whose boxes the ray meets within the
/// pruning bound of `tmax` ([`CULL_MARGIN`]), the children of each node nearest first, calling
/// `leaf(child, count, tmax)`, which may lower `tmax` (closest hit) or return true to stop the walk (any hit);
/// returns whether one did.
#[inline(always)]
fn walk<const OCT: usize>(
    tree: &Tree,
    ray: &RayBox,
    tmax: &mut f32,
    cost: &mut impl Count,
    mut leaf: impl FnMut(u32, u32, &mut f32) -> bool,
) -> bool {
    let bound = |tmax: f32| tmax + tmax * CULL_MARGIN;
    with_stack(|stack| {
        let mut sp = 0;
        // The entry being visited: the root first.
        let mut cur = Entry::ZERO;
        'walk: loop {
            let (child, count) = split_entry(cur.child);
            if count == 0 {
                let n = &tree.nodes[child as usize];
                cost.node();
                let (mask, t0) = ray.hits::<OCT>(n, bound(*tmax));
                if mask != 0 {
                    let slot = |s: u32| Entry { child: n.child[s as usize], t0: t0[s as usize] };
                    let first = slot(mask.trailing_zeros());
                    let rest = mask & (mask - 1);
                    if rest == 0 {
                        cur = first;
                        continue 'walk;
                    }
                    let second = slot(rest.trailing_zeros());
                    if rest & (rest - 1) == 0 {
                        let (near, far) = if second.t0 < first.t0 { (second, first) } else { (first, second) };
                        stack[sp] = far;
                        sp += 1;
                        cur = near;
                        continue 'walk;
                    }
                    // Three or more: by near distance (insertion sort); the farther ones go on the stack,
                    // farthest first, and the walk goes on with the nearest.
                    let mut e = [Entry::ZERO; WIDTH];
                    e[0] = first;
                    let (mut k, mut m) = (1, rest);
                    while m != 0 {
                        e[k] = slot(m.trailing_zeros());
                        m &= m - 1;
                        let mut j = k;
                        while j > 0 && e[j - 1].t0 > e[j].t0 {
                            e.swap(j - 1, j);
                            j -= 1;
                        }
                        k += 1;
                    }
                    for i in (1..k).rev() {
                        stack[sp] = e[i];
                        sp += 1;
                    }
                    cur = e[0];
                    continue 'walk;
                }
            } else {
                cost.leaf(count);
                if leaf(child, count, tmax) {
                    return true;
                }
            }
            // Pop the nearest entry not pruned by the best hit so far.
            while sp > 0 {
                sp -= 1;
                if stack[sp].t0 <= bound(*tmax) {
                    cur = stack[sp];
                    continue 'walk;
                }
            }
            return false;
        }
    })
}
