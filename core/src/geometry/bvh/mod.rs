//! Bounding volume hierarchies: a binned-SAH binary build (parallel and deterministic), collapsed into 8-wide
//! trees traversed with SIMD box tests; closest-hit and any-hit queries whose answers do not depend on the tree.
//!
//! Two trees share the build and the walk:
//! - [`Bvh`] over any primitives given by their boxes: leaves are ranges of an index table, and the primitive
//!   test is a callback, so one tree serves spheres, rectangles and the tests' boxes without trait objects.
//! - [`TriBvh`] over triangles: leaves are one or two blocks of up to four triangles stored as structure of arrays
//!   in leaf order and tested four at once ([`tri4`]), with no table, enum or callback on the hot path.
//!
//! Build: binned surface area heuristic (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
//! 2007; pbrt-v4 §7.3.2) with [`BINS`] bins (8 below 64 primitives) over the centroid bounds on all three axes;
//! the leaf cost counts triangles in groups of four ([`Leaves`], as tinybvh's builds for its 4- and 8-wide
//! layouts do). Large nodes bin their primitives in fixed chunks of [`CHUNK`] on rayon and merge the chunks in
//! order, and large subtrees are rayon tasks; every split is a function of the node's primitives alone, so any
//! number of threads builds the same tree.
//!
//! Layout: the binary tree is collapsed into nodes of up to [`WIDTH`] children (Wald, Benthin and Boulos,
//! "Getting rid of packets", 2008; Embree's BVH8): a node repeatedly opens its child of largest surface area
//! until it has eight. A node stores its children's boxes as structure of arrays, so one SIMD test per axis
//! tests all eight (two SSE or NEON instructions, one AVX); leaves live in their parent's slots, so there are no
//! leaf nodes. Eight children measured faster than four on x86-64 with SSE2 (docs/RESULTS.md, "Rays at Embree's
//! rate"), and fewer nodes hold the same leaves.
//!
//! **Hits do not depend on the tree.** The closest hit is the one of smallest distance and, of hits at exactly
//! the same distance, the one of smallest primitive index (the caller's order, which no tree changes). Every
//! primitive test computes the same IEEE operations however it is reached (the four-at-once triangle test is
//! the one-at-a-time test lane by lane, [`tri4`]). So the answer is the same for any tree shape, width, leaf
//! size, visiting order, thread count or architecture, and the walk is free to visit children nearest first.
//! The walk prunes a box whose near distance exceeds the best hit so far by more than [`CULL_MARGIN`]
//! (relative): a hit found in a box is never before that box's computed entry by more than rounding, so a box
//! holding a primitive that ties the best hit is still entered. The box test's far distance is made
//! conservative as pbrt-v4 §6.8.2 does, with a larger factor ([`walk`]), so no box a ray meets is missed.
//!
//! The binary tree's depth is capped at [`MAX_DEPTH`], so traversal uses a fixed stack and never allocates.
//!
//! | file | what it holds |
//! |---|---|
//! | [`build`] | the binned-SAH binary build |
//! | [`tree`] | the wide nodes, the collapse of the binary tree into them, the tree's measures |
//! | [`walk`] | the ray's box test and the walk of both queries |
//! | `general` | [`Bvh`], over boxes, tested through a callback |
//! | [`tri4`] | triangle blocks, their four-at-once test, and [`TriBvh`] |

pub mod build;
mod general;
pub mod tree;
pub mod tri4;
pub mod walk;

pub use build::{BINS, CHUNK, Leaves, MAX_DEPTH, MAX_LEAF};
pub use general::Bvh;
pub use tree::{MAX_INDEX, WIDTH};
pub use tri4::TriBvh;
pub use walk::{CULL_MARGIN, RayCost};

#[cfg(test)]
mod tests;
