//! The wide tree both hierarchies walk ([`super`]): its nodes, the collapse of the binary build tree into them,
//! and the measures of a tree (depth, SAH cost, a hash of its bytes).

use super::build::{BinaryNode, Leaves, build_binary};
use crate::math::Aabb;
use glam::Vec3;

/// Children per node of the traversed tree.
pub const WIDTH: usize = 8;

/// Bits of a slot's entry ([`Node::child`]) that hold a leaf's primitive count; the others hold an index.
const COUNT_BITS: u32 = 4;

/// Indices (of nodes, blocks or index-table entries) are below this: `2^(32 − COUNT_BITS)`.
pub const MAX_INDEX: usize = 1 << (32 - COUNT_BITS);

/// A node of the traversed tree: up to [`WIDTH`] children, their boxes as structure of arrays (28 bytes a slot).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub(crate) struct Node {
    /// `lo[axis][slot]`: the children's box minima; unused slots hold an empty box.
    pub(super) lo: [[f32; WIDTH]; 3],
    /// `hi[axis][slot]`: the children's box maxima.
    pub(super) hi: [[f32; WIDTH]; 3],
    /// Each slot: an interior child's node index, or a leaf's entry (what the tree's leaves index: [`super::Bvh`],
    /// its first entry of the index table; [`super::TriBvh`], its first block) with its primitive count in the
    /// top [`COUNT_BITS`] bits, which are 0 for an interior child.
    pub(super) child: [u32; WIDTH],
}

const _: () = assert!(std::mem::size_of::<Node>() == 28 * WIDTH || std::mem::size_of::<Node>() == 32 * WIDTH);

/// A slot's entry: `index` with `count` primitives (0 for an interior child).
#[inline(always)]
pub(crate) fn entry(index: u32, count: u32) -> u32 {
    index | count << (32 - COUNT_BITS)
}

/// The index and the primitive count of a slot's entry.
#[inline(always)]
pub(crate) fn split_entry(e: u32) -> (u32, u32) {
    (e & (MAX_INDEX as u32 - 1), e >> (32 - COUNT_BITS))
}

impl Node {
    /// Number of used slots: they come first, and an unused one holds the empty box (min above max).
    pub(super) fn n(&self) -> usize {
        (0..WIDTH).take_while(|&k| self.lo[0][k] <= self.hi[0][k]).count()
    }
}

/// The collapsed tree that both hierarchies walk.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Tree {
    /// Depth-first; node 0 is the root.
    pub(super) nodes: Vec<Node>,
    /// The box around everything, `[min, max]`.
    pub(super) bounds: [[f32; 3]; 2],
}

impl Tree {
    /// The binary SAH tree over the `count` boxes `bound(i)`, collapsed, and the primitive order its leaves'
    /// ranges refer to: the `i` of each box, in leaf order. A `bound(i)` of `None` leaves primitive `i` out.
    ///
    /// # Panics
    /// With [`MAX_INDEX`] or more boxes.
    pub(super) fn build(
        count: usize,
        bound: impl Fn(usize) -> Option<Aabb> + Sync,
        leaves: Leaves,
    ) -> (Tree, Vec<u32>) {
        assert!(count < MAX_INDEX, "a BVH holds fewer than 2^28 primitives");
        let Some((binary, order)) = build_binary(count, bound, leaves) else {
            return (Tree::default(), Vec::new());
        };
        let mut nodes = collapse(&binary, leaves.merge);
        nodes.shrink_to_fit();
        (Tree { nodes, bounds: binary[0].b }, order)
    }

    /// The leaf slots as `(node, slot)`, in node order (depth-first, parents before children).
    pub(super) fn leaf_slots(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.nodes
            .iter()
            .enumerate()
            .flat_map(|(i, n)| (0..n.n()).filter(|&k| split_entry(n.child[k]).1 > 0).map(move |k| (i, k)))
    }

    pub(super) fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node>()
    }

    pub(super) fn depth(&self) -> usize {
        fn rec(nodes: &[Node], i: usize) -> usize {
            let n = &nodes[i];
            1 + (0..n.n())
                .map(|k| split_entry(n.child[k]))
                .filter(|&(_, count)| count == 0)
                .map(|(child, _)| rec(nodes, child as usize))
                .max()
                .unwrap_or(0)
        }
        if self.nodes.is_empty() { 0 } else { rec(&self.nodes, 0) }
    }

    pub(super) fn aabb(&self) -> Aabb {
        if self.nodes.is_empty() {
            Aabb::EMPTY
        } else {
            Aabb { min: Vec3::from_array(self.bounds[0]), max: Vec3::from_array(self.bounds[1]) }
        }
    }

    /// The SAH cost of the tree in node visits per ray that meets its box (MacDonald and Booth 1990; pbrt-v4
    /// §7.3.2): `Σ_nodes A(n)/A(root) + Σ_leaves A(l)/A(root) · C(l)`, with `C` the leaf cost of `leaves`.
    pub(super) fn sah_cost(&self, leaves: Leaves) -> f64 {
        let area = |n: &Node, k: usize| {
            let b = Aabb {
                min: Vec3::new(n.lo[0][k], n.lo[1][k], n.lo[2][k]),
                max: Vec3::new(n.hi[0][k], n.hi[1][k], n.hi[2][k]),
            };
            f64::from(b.half_area())
        };
        let root = f64::from(self.aabb().half_area());
        if self.nodes.is_empty() || root <= 0.0 {
            return 0.0;
        }
        // The root is visited by every ray; each slot's box is tested with its parent, and an interior slot's
        // node is visited when its box is hit.
        let mut cost = 1.0;
        for n in &self.nodes {
            for k in 0..n.n() {
                let count = split_entry(n.child[k]).1;
                let c = if count == 0 { 1.0 } else { f64::from(leaves.cost(count)) };
                cost += area(n, k) / root * c;
            }
        }
        cost
    }

    /// A hash (FNV-1a, 64 bits) of every node's bytes and of `extra`: equal for equal trees, for comparing builds.
    pub(super) fn hash(&self, extra: impl IntoIterator<Item = u32>) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |x: u32| {
            for byte in x.to_le_bytes() {
                h = (h ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3);
            }
        };
        for n in &self.nodes {
            n.lo.iter().chain(&n.hi).flatten().for_each(|v| eat(v.to_bits()));
            n.child.iter().for_each(|&c| eat(c));
        }
        self.bounds.iter().flatten().for_each(|v| eat(v.to_bits()));
        extra.into_iter().for_each(eat);
        h
    }
}

/// Collapses the binary tree (root at 0) into [`Node`]s, depth-first; sibling leaves of at most `merge` primitives
/// together that would make a node of two slots become one leaf (their ranges are adjacent).
fn collapse(binary: &[BinaryNode], merge: usize) -> Vec<Node> {
    // The binary tree has one interior node fewer than leaves, and each wide node takes the place of at least one
    // of them.
    let mut out = Vec::with_capacity(binary.len() / 2 + 1);
    if binary[0].count > 0 {
        // A root leaf: one node with one slot.
        let mut node = empty_node();
        set_slot(&mut node, 0, &binary[0]);
        node.child[0] = entry(binary[0].offset, u32::from(binary[0].count));
        out.push(node);
    } else {
        collapse_node(binary, 0, merge, &mut out);
    }
    out
}

fn empty_node() -> Node {
    let e = Aabb::EMPTY;
    Node {
        lo: [[e.min.x; WIDTH], [e.min.y; WIDTH], [e.min.z; WIDTH]],
        hi: [[e.max.x; WIDTH], [e.max.y; WIDTH], [e.max.z; WIDTH]],
        child: [0; WIDTH],
    }
}

/// Copies binary node `b`'s box into slot `k`.
fn set_slot(node: &mut Node, k: usize, b: &BinaryNode) {
    for a in 0..3 {
        node.lo[a][k] = b.b[0][a];
        node.hi[a][k] = b.b[1][a];
    }
}

/// Appends the [`Node`] for interior binary node `b` and those below it; returns its index.
fn collapse_node(binary: &[BinaryNode], b: usize, merge: usize, out: &mut Vec<Node>) -> u32 {
    // An interior slot's area, for choosing the slot to open; a leaf's is -1, so it is never chosen.
    let area = |i: usize| {
        let n = &binary[i];
        if n.count > 0 {
            -1.0
        } else {
            Aabb { min: Vec3::from_array(n.b[0]), max: Vec3::from_array(n.b[1]) }.half_area()
        }
    };
    // Slots in the binary tree's first-then-second order, with their areas; open the interior slot of largest
    // area (the first on ties) until there are WIDTH.
    let mut slots = [(0usize, 0f32); WIDTH];
    slots[0] = (b + 1, area(b + 1));
    slots[1] = (binary[b].offset as usize, area(binary[b].offset as usize));
    let mut n = 2;
    while n < WIDTH {
        let mut pick: Option<(usize, f32)> = None;
        for (k, &(_, a)) in slots[..n].iter().enumerate() {
            if a >= 0.0 && pick.is_none_or(|(_, best)| a > best) {
                pick = Some((k, a));
            }
        }
        let Some((k, _)) = pick else { break };
        let s = slots[k].0;
        slots.copy_within(k + 1..n, k + 2);
        let (first, second) = (s + 1, binary[s].offset as usize);
        slots[k] = (first, area(first));
        slots[k + 1] = (second, area(second));
        n += 1;
    }
    let slots = slots.map(|(s, _)| s);
    let index = out.len();
    out.push(empty_node());
    let mut node = empty_node();
    for (k, &s) in slots[..n].iter().enumerate() {
        set_slot(&mut node, k, &binary[s]);
        let count = u32::from(binary[s].count);
        node.child[k] = if count > 0 {
            entry(binary[s].offset, count)
        } else {
            let (first, second) = (&binary[s + 1], &binary[binary[s].offset as usize]);
            if first.count > 0 && second.count > 0 && usize::from(first.count + second.count) <= merge {
                // Two leaves: the second's range follows the first's.
                entry(first.offset, u32::from(first.count + second.count))
            } else {
                entry(collapse_node(binary, s, merge, out), 0)
            }
        };
    }
    out[index] = node;
    index as u32
}
