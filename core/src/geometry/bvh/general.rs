//! [`Bvh`]: the tree over primitives given by their boxes, tested one at a time through a callback.

use super::build::Leaves;
use super::tree::Tree;
use super::walk::{self, Count, RayBox};
use crate::math::Aabb;
use glam::Vec3A;

/// A bounding volume hierarchy over primitives given by their boxes; its queries name primitives by their index
/// in the boxes it was built from.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    tree: Tree,
    /// The primitive indices in leaf order: a leaf is a range of this table.
    pub(super) items: Vec<u32>,
}

impl Bvh {
    /// Deterministic binned-SAH build over primitive bounds with the leaves of [`Leaves::GENERAL`], on the current
    /// rayon pool; the same bounds give the same BVH for any number of threads.
    ///
    /// # Panics
    /// With [`super::MAX_INDEX`] or more primitives.
    pub fn build(bounds: &[Aabb]) -> Bvh {
        Bvh::build_with(bounds, Leaves::GENERAL)
    }

    /// [`Bvh::build`] with the leaves `leaves` allows.
    pub fn build_with(bounds: &[Aabb], leaves: Leaves) -> Bvh {
        let (tree, items) = Tree::build(bounds.len(), |i| Some(bounds[i]), leaves);
        Bvh { tree, items }
    }

    /// [`Bvh::build`] over a subset of the caller's primitives: `bounds[k]` is the box of primitive `ids[k]`, and
    /// the queries name primitives by those ids. The ids must increase with `k`, so that the smallest-index rule
    /// for ties means the same in both numberings.
    ///
    /// # Panics
    /// If `ids` and `bounds` differ in length.
    pub fn build_for(bounds: &[Aabb], ids: &[u32]) -> Bvh {
        assert_eq!(bounds.len(), ids.len(), "one id per box");
        let mut bvh = Bvh::build(bounds);
        bvh.items.iter_mut().for_each(|k| *k = ids[*k as usize]);
        bvh
    }

    /// Closest hit: `hit(prim, bound)` returns the distance `t < bound` at which primitive `prim` (an index into
    /// the bounds the BVH was built from) is hit, if it is. Returns the primitive and distance of the closest hit
    /// in `(0, tmax)`; of hits at exactly the same distance, the smallest primitive index, whatever the tree.
    pub fn closest_hit(
        &self,
        o: Vec3A,
        d: Vec3A,
        tmax: f32,
        hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<(u32, f32)> {
        self.closest_prepared(&RayBox::new(o, d), tmax, None, hit, &mut ())
    }

    /// [`Bvh::closest_hit`] for a ray already prepared for box tests, which several trees can share, going on from
    /// the hit `best` of another structure (planes, another tree): a hit here replaces it only if it is closer, or
    /// as close with a smaller index. `cost` counts the walk's work.
    #[inline(always)]
    pub(crate) fn closest_prepared(
        &self,
        ray: &RayBox,
        tmax: f32,
        mut best: Option<(u32, f32)>,
        mut hit: impl FnMut(u32, f32) -> Option<f32>,
        cost: &mut impl Count,
    ) -> Option<(u32, f32)> {
        let mut tmax = best.map_or(tmax, |b| b.1);
        self.tree.closest(ray, &mut tmax, cost, |first, count, tmax| {
            for &p in &self.items[first as usize..(first + count) as usize] {
                // With a hit so far, a tie at its distance is still a candidate (`t ≤ tmax`).
                let bound = if best.is_some() { crate::math::next_float_up(*tmax) } else { *tmax };
                if let Some(t) = hit(p, bound)
                    && walk::better(t, p, best)
                {
                    *tmax = t;
                    best = Some((p, t));
                }
            }
        });
        best
    }

    /// Any hit in `(0, tmax)`: stops at the first primitive for which `hit(prim, tmax)` is true.
    pub fn any_hit(&self, o: Vec3A, d: Vec3A, tmax: f32, hit: impl FnMut(u32, f32) -> bool) -> bool {
        self.any_prepared(&RayBox::new(o, d), tmax, hit)
    }

    /// [`Bvh::any_hit`] for a ray already prepared for box tests.
    #[inline(always)]
    pub(crate) fn any_prepared(&self, ray: &RayBox, tmax: f32, mut hit: impl FnMut(u32, f32) -> bool) -> bool {
        self.tree.any(ray, tmax, &mut (), |first, count| {
            self.items[first as usize..(first + count) as usize].iter().any(|&p| hit(p, tmax))
        })
    }

    /// Number of nodes of the traversed tree (0 for an empty BVH).
    pub fn node_count(&self) -> usize {
        self.tree.nodes.len()
    }

    /// Heap bytes of the BVH itself (nodes and index table).
    pub fn memory_bytes(&self) -> usize {
        self.tree.memory_bytes() + self.items.capacity() * std::mem::size_of::<u32>()
    }

    /// The box around everything (empty for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        self.tree.aabb()
    }

    /// Depth of the deepest leaf of the traversed tree (the root's slots have depth 1); 0 for an empty BVH.
    pub fn depth(&self) -> usize {
        self.tree.depth()
    }

    /// The SAH cost in node visits per ray that meets the root's box, with one-at-a-time leaves.
    pub fn sah_cost(&self) -> f64 {
        self.tree.sah_cost(Leaves::GENERAL)
    }

    /// A hash (FNV-1a, 64 bits) of every node's bytes and the index table: equal for equal trees.
    pub fn structure_hash(&self) -> u64 {
        self.tree.hash(self.items.iter().copied())
    }
}
