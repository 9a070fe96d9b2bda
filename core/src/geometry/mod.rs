//! The scene geometry: every bounded primitive under one BVH, infinite planes beside it, with closest-hit and
//! any-hit queries, and the hit record shading reads.
//!
//! A new shape goes in [`shapes`] (its intersection, bounds, area sampling) as a variant of [`Shape`], and in
//! the scene's `Object` list (`scene::types`) with its validation (`scene::validate`).

pub mod bvh;
pub mod lod;
pub mod mask;
pub mod mesh;
pub mod mesh_file;
pub mod ply;
pub mod shapes;

use crate::math::{Aabb, Ray, offset_ray_origin_by_error};
use bvh::walk::RayBox;
use bvh::{Bvh, RayCost, TriBvh, tri4};
use glam::{Vec2, Vec3A};
use mask::AlphaMask;
use serde::{Deserialize, Serialize};
use shapes::{LocalHit, Plane, Shape, TriangleRay};

/// Marks "no light" / "no index".
pub const NONE: u32 = u32::MAX;

/// A bounded primitive: a shape with its material, the area light it carries (or [`NONE`]) and the scene object
/// it belongs to (objects group the triangles of a mesh).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Primitive {
    /// The shape.
    pub shape: Shape,
    /// Material index.
    pub material: u32,
    /// Area light index, or [`NONE`].
    pub light: u32,
    /// Scene object index.
    pub object: u32,
}

/// An infinite plane primitive.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanePrimitive {
    /// The plane.
    pub plane: Plane,
    /// Material index.
    pub material: u32,
    /// Scene object index.
    pub object: u32,
}

/// Per-vertex shading data of one mesh: normals, tangents and UVs indexed per face corner, and the cut-out
/// its faces have.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshShading {
    /// World-space unit normals.
    pub normals: Vec<[f32; 3]>,
    /// World-space unit tangents `(x, y, z)` with the bitangent's sign `w` (±1), one per normal and indexed by
    /// `normal_indices`: the bitangent is `w · (n × t)` (glTF's TANGENT attribute, specification §3.7.2.1).
    /// Empty when the mesh has none: normal maps then use `∂p/∂u`.
    pub tangents: Vec<[f32; 4]>,
    /// Texture coordinates (may be empty).
    pub uvs: Vec<[f32; 2]>,
    /// For each face, the normal index of each corner.
    pub normal_indices: Vec<[u32; 3]>,
    /// For each face, the UV index of each corner (empty when the mesh has no UVs).
    pub uv_indices: Vec<[u32; 3]>,
    /// Index into [`Geometry::masks`] of the cut-out the faces have, read at their UVs; `None`: opaque.
    pub mask: Option<u32>,
}

/// Which primitive a hit is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrimRef {
    /// Index into [`Geometry::prims`].
    Bounded(u32),
    /// Index into [`Geometry::planes`].
    Plane(u32),
}

/// A ray's closest hit with everything shading needs.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Point on the surface.
    pub p: Vec3A,
    /// A bound on the rounding error of each coordinate of `p` (absolute): how far the true surface point may be.
    pub p_error: Vec3A,
    /// Geometric unit normal as the shape defines it.
    pub n: Vec3A,
    /// Shading unit normal (interpolated on meshes), on the same side as `n`.
    pub ns: Vec3A,
    /// Texture coordinates (see `crate::material::texture` for each shape's convention).
    pub uv: Vec2,
    /// `∂p/∂u`: how the point moves per unit of `u` (scene units); with `dpdv`, the tangent frame of bump and
    /// normal maps.
    pub dpdu: Vec3A,
    /// `∂p/∂v`.
    pub dpdv: Vec3A,
    /// Material index.
    pub material: u32,
    /// Area light index, or [`NONE`].
    pub light: u32,
    /// Scene object index.
    pub object: u32,
    /// The primitive.
    pub prim: PrimRef,
}

impl Hit {
    /// The geometric normal turned to the side of `w` (towards `w` when `w · n = 0`).
    #[inline]
    pub fn normal_towards(&self, w: Vec3A) -> Vec3A {
        if w.dot(self.n) >= 0.0 { self.n } else { -self.n }
    }

    /// A ray leaving the hit point in direction `wi`, its origin offset along the geometric normal to the side
    /// `wi` goes to by the error bound of `p` (pbrt-v4 §6.8.6), so that it does not hit this surface again: no
    /// fixed epsilon, so it works for a sphere of radius 10⁻³ as for a floor of radius 10⁶ or a scene 10⁵ units
    /// from the origin.
    #[inline]
    pub fn spawn_ray(&self, wi: Vec3A) -> Ray {
        Ray::new(offset_ray_origin_by_error(self.p, self.p_error, self.n, wi), wi)
    }
}

/// All the surfaces of a scene.
///
/// Triangles are under one BVH of four-triangle blocks ([`TriBvh`]), the other bounded shapes under a BVH of
/// their own ([`Bvh`]), so they cost mesh triangles nothing; infinite planes are tested beside both. The closest
/// hit is the smallest distance, then the smallest primitive index ([`Geometry::prim`]; planes first): no tree
/// decides it.
///
/// The trees are built on the first query, or by [`Geometry::build_trees`]: a coordinator that only ships the
/// scene to its workers never builds them, and its workers build theirs at once, in parallel with each other.
/// Its serialised form (what the scene blob carries) has no trees and lists every primitive: deserialising builds
/// the trees again, which gives the same trees ([`Bvh::build`]), and packs the primitives against them
/// ([`Geometry::packed`]), so that a worker holds a mesh's vertices once, in the triangle tree. Shipping the trees
/// would cost the coordinator's link about 50 bytes per triangle for every worker; building them costs each
/// worker, in parallel, under half a microsecond per triangle on one thread (docs/RESULTS.md, "Rays at Embree's
/// rate"), and a tree that was never on the wire cannot be a malformed one.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(from = "GeometryParts")]
pub struct Geometry {
    /// Bounded primitives, in the order the scene gave them; hits and lights name them by their index here
    /// ([`Geometry::prim`]).
    prims: PrimStore,
    /// Infinite planes.
    pub planes: Vec<PlanePrimitive>,
    /// Shading data of meshes.
    pub meshes: Vec<MeshShading>,
    /// The cut-outs that meshes' `mask` index.
    pub masks: Vec<AlphaMask>,
    /// The BVHs over `prims`, once built. The shapes in `prims` must not change after that.
    #[serde(skip)]
    trees: std::sync::OnceLock<Trees>,
}

/// Where a [`Geometry`] keeps its bounded primitives.
#[derive(Clone, Debug)]
enum PrimStore {
    /// One [`Primitive`] each (60 bytes), as given: what a scene is prepared and shipped as.
    Listed(Vec<Primitive>),
    /// After [`Geometry::packed`]: a triangle's vertices are read from the blocks of the triangle tree, which
    /// holds them anyway, and its other fields from the run of faces it is in.
    Packed(Packed),
}

impl Default for PrimStore {
    fn default() -> Self {
        PrimStore::Listed(Vec::new())
    }
}

/// [`Geometry::packed`] packs geometries whose triangle tree has room for at least this many triangles.
pub const PACK_FROM: usize = 4096;

/// Marks an entry of [`Packed::at`] that indexes [`Packed::rest`].
const IN_REST: u32 = 1 << 31;

/// Bounded primitives packed against the triangle tree: 4 bytes a triangle beside the tree's blocks, and a few
/// bytes a run.
#[derive(Clone, Debug, Default)]
struct Packed {
    /// Per primitive: where its triangle is in the blocks ([`TriBvh::locations`]), or [`IN_REST`] plus its index
    /// in `rest`.
    at: Vec<u32>,
    /// Runs of triangles in the blocks, by their first primitive.
    runs: Vec<Run>,
    /// The primitives no block holds (spheres, rectangles, triangles no ray can hit), in order.
    rest: Vec<Primitive>,
}

/// Consecutive triangle primitives, `first + k` being face `face + k` of mesh `mesh` (face `face` for triangles of
/// no mesh, [`shapes::NO_MESH`]), of one material and object, carrying light `light + k` (none when `light` is
/// [`NONE`]). Sums wrap, as they do when a run is formed, so every field comes back with the bits it had.
#[derive(Clone, Copy, Debug)]
struct Run {
    first: u32,
    mesh: u32,
    face: u32,
    material: u32,
    light: u32,
    object: u32,
}

impl Run {
    fn start(i: u32, p: &Primitive, t: &shapes::Triangle) -> Run {
        Run { first: i, mesh: t.mesh, face: t.face, material: p.material, light: p.light, object: p.object }
    }

    /// Primitive `first + k`'s face and light.
    #[inline]
    fn nth(&self, k: u32) -> (u32, u32) {
        let face = if self.mesh == shapes::NO_MESH { self.face } else { self.face.wrapping_add(k) };
        (face, if self.light == NONE { NONE } else { self.light.wrapping_add(k) })
    }

    /// Whether primitive `i`, triangle `t`, follows the run.
    fn continues(&self, i: u32, p: &Primitive, t: &shapes::Triangle) -> bool {
        let (face, light) = self.nth(i.wrapping_sub(self.first));
        (t.mesh, t.face, p.material, p.light, p.object) == (self.mesh, face, self.material, light, self.object)
    }
}

impl Packed {
    /// Packs `list`, whose triangles the blocks of `tree` hold.
    fn new(list: &[Primitive], tree: &TriBvh) -> Packed {
        let mut packed = Packed { at: Vec::with_capacity(list.len()), ..Packed::default() };
        for (i, (p, at)) in list.iter().zip(tree.locations(list.len())).enumerate() {
            let i = i as u32;
            match (p.shape, at) {
                (Shape::Triangle(t), Some(at)) => {
                    if !packed.runs.last().is_some_and(|r| r.continues(i, p, &t)) {
                        packed.runs.push(Run::start(i, p, &t));
                    }
                    packed.at.push(at);
                }
                _ => {
                    packed.at.push(IN_REST | packed.rest.len() as u32);
                    packed.rest.push(*p);
                }
            }
        }
        packed.runs.shrink_to_fit();
        packed.rest.shrink_to_fit();
        packed
    }

    /// Primitive `i` where it is kept whole: in `rest` (every primitive but the blocks' triangles, so every one
    /// the tree of other shapes holds).
    #[inline(always)]
    fn whole(&self, i: u32) -> Option<&Primitive> {
        let at = *self.at.get(i as usize)?;
        if at & IN_REST != 0 { self.rest.get((at & !IN_REST) as usize) } else { None }
    }

    fn bytes(&self) -> usize {
        self.at.capacity() * 4
            + self.runs.capacity() * std::mem::size_of::<Run>()
            + self.rest.capacity() * std::mem::size_of::<Primitive>()
    }
}

/// The BVHs of a [`Geometry`].
#[derive(Clone, Debug, Default)]
struct Trees {
    /// Over the triangles of `prims`.
    triangles: TriBvh,
    /// Over the other bounded shapes of `prims` (spheres, rectangles).
    others: Bvh,
}

impl Trees {
    fn build(prims: &[Primitive]) -> Trees {
        let (mut bounds, mut ids) = (Vec::new(), Vec::new());
        for (i, p) in prims.iter().enumerate() {
            if !matches!(p.shape, Shape::Triangle(_)) {
                bounds.push(p.shape.bounds());
                ids.push(i as u32);
            }
        }
        let triangle = |i: usize| match prims[i].shape {
            Shape::Triangle(t) => Some((i as u32, t)),
            _ => None,
        };
        let (triangles, others) = rayon::join(
            || TriBvh::build_over(prims.len(), triangle, bvh::tri4::TRIANGLE_LEAVES),
            || Bvh::build_for(&bounds, &ids),
        );
        Trees { triangles, others }
    }
}

/// [`Geometry`] as it is deserialised: the same fields but the trees.
#[derive(Deserialize)]
struct GeometryParts {
    prims: Vec<Primitive>,
    planes: Vec<PlanePrimitive>,
    meshes: Vec<MeshShading>,
    masks: Vec<AlphaMask>,
}

impl From<GeometryParts> for Geometry {
    /// A decoded geometry is a worker's, about to render: its trees are built now, and its primitives packed
    /// against them.
    fn from(p: GeometryParts) -> Self {
        Geometry::new(p.prims, p.planes, p.meshes).with_masks(p.masks).packed()
    }
}

/// The scene blob's form of a geometry: its primitives listed, its planes, meshes and cut-outs, no trees (what
/// `GeometryParts` reads back).
impl Serialize for Geometry {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        struct Listed<'a>(&'a Geometry);
        impl Serialize for Listed<'_> {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                serializer.collect_seq(self.0.prims())
            }
        }
        let mut s = serializer.serialize_struct("Geometry", 4)?;
        s.serialize_field("prims", &Listed(self))?;
        s.serialize_field("planes", &self.planes)?;
        s.serialize_field("meshes", &self.meshes)?;
        s.serialize_field("masks", &self.masks)?;
        s.end()
    }
}

impl Geometry {
    /// The geometry of `prims` (which keep their order), `planes` and `meshes`; its trees are built when first
    /// needed.
    pub fn new(prims: Vec<Primitive>, planes: Vec<PlanePrimitive>, meshes: Vec<MeshShading>) -> Self {
        Self { prims: PrimStore::Listed(prims), planes, meshes, masks: Vec::new(), trees: std::sync::OnceLock::new() }
    }

    /// The geometry with its trees built and its primitives packed against them: a triangle's vertices are read
    /// from the triangle tree's blocks, which hold them anyway, and its mesh, face, material, light and object
    /// from the run of faces it is in, so a mesh's triangles cost about 4 bytes each beside the tree instead of a
    /// 60-byte [`Primitive`] (docs/RESULTS.md, "Rays at Embree's rate"). Every query and [`Geometry::prim`]
    /// answers as before, bit for bit. What a worker holds. A geometry of fewer triangles than [`PACK_FROM`] stays
    /// as it is.
    pub fn packed(mut self) -> Self {
        if let PrimStore::Listed(list) = &self.prims {
            let tree = &self.trees().triangles;
            // A few thousand triangles hold too little to pack (56 bytes each); a listed primitive is one load
            // away, a packed one two, which costs scenes of spheres and rectangles several percent.
            if tree.block_count() * tri4::LANES >= PACK_FROM {
                let packed = Packed::new(list, tree);
                self.prims = PrimStore::Packed(packed);
            }
        }
        self
    }

    /// Builds the trees now, if they are not built yet (on the current rayon pool, deterministically for any
    /// number of threads).
    pub fn build_trees(&self) {
        self.trees();
    }

    #[inline]
    fn trees(&self) -> &Trees {
        self.trees.get_or_init(|| match &self.prims {
            PrimStore::Listed(list) => Trees::build(list),
            // Packing builds the trees first, and nothing unsets them.
            PrimStore::Packed(_) => Trees::default(),
        })
    }

    /// The number of bounded primitives.
    pub fn prim_count(&self) -> usize {
        match &self.prims {
            PrimStore::Listed(list) => list.len(),
            PrimStore::Packed(p) => p.at.len(),
        }
    }

    /// Bounded primitive `i`, or `None` past the last.
    #[inline]
    pub fn prim(&self, i: u32) -> Option<Primitive> {
        self.with_prim(i, |p| *p)
    }

    /// `f` of bounded primitive `i`, or `None` past the last: [`Geometry::prim`] without a copy where the
    /// primitive is kept whole (what the hot paths use: a hit's surface data, a point sampled on a light).
    #[inline(always)]
    pub fn with_prim<R>(&self, i: u32, f: impl FnOnce(&Primitive) -> R) -> Option<R> {
        let built;
        let p = match &self.prims {
            PrimStore::Listed(list) => list.get(i as usize)?,
            PrimStore::Packed(p) => match p.whole(i) {
                Some(p) => p,
                None => {
                    built = self.triangle(p, i, *p.at.get(i as usize)?)?;
                    &built
                }
            },
        };
        // One call, so that `f` is inlined here.
        Some(f(p))
    }

    /// Packed primitive `i`, the triangle at `at` in the blocks, from its run.
    fn triangle(&self, p: &Packed, i: u32, at: u32) -> Option<Primitive> {
        let run = p.runs.get(p.runs.partition_point(|r| r.first <= i).checked_sub(1)?)?;
        let (face, light) = run.nth(i - run.first);
        let vertices = self.trees().triangles.vertices(at)?;
        let shape = Shape::Triangle(shapes::Triangle { p: vertices, mesh: run.mesh, face });
        Some(Primitive { shape, material: run.material, light, object: run.object })
    }

    /// The bounded primitives, in order.
    pub fn prims(&self) -> impl ExactSizeIterator<Item = Primitive> + '_ {
        let n = self.prim_count() as u32;
        // Every index below the count has its primitive: `Packed::new` gives each one an entry.
        (0..n).map(move |i| self.prim(i).unwrap_or_else(|| unreachable!("primitive {i} of {n} is missing")))
    }

    /// The bounded primitives, to change their materials, lights, objects or meshes' faces (a packed geometry is
    /// listed again); their shapes' vertices must not change once the trees are built.
    pub fn prims_mut(&mut self) -> &mut [Primitive] {
        if let PrimStore::Packed(_) = self.prims {
            self.prims = PrimStore::Listed(self.prims().collect());
        }
        match &mut self.prims {
            PrimStore::Listed(list) => list,
            PrimStore::Packed(_) => &mut [],
        }
    }

    /// Heap bytes of the geometry: its trees, its primitives, planes and meshes' shading tables (not the cut-outs'
    /// images).
    pub fn memory_bytes(&self) -> usize {
        let prims = match &self.prims {
            PrimStore::Listed(list) => list.capacity() * std::mem::size_of::<Primitive>(),
            PrimStore::Packed(p) => p.bytes(),
        };
        let shading: usize = self
            .meshes
            .iter()
            .map(|m| {
                m.normals.capacity() * 12
                    + m.tangents.capacity() * 16
                    + m.uvs.capacity() * 8
                    + (m.normal_indices.capacity() + m.uv_indices.capacity()) * 12
            })
            .sum();
        self.bvh_bytes() + prims + shading + self.planes.capacity() * std::mem::size_of::<PlanePrimitive>()
    }

    /// The BVH over the triangles.
    pub fn triangle_tree(&self) -> &TriBvh {
        &self.trees().triangles
    }

    /// The geometry with the cut-outs `masks`, which the meshes' `mask` fields index.
    pub fn with_masks(mut self, masks: Vec<AlphaMask>) -> Self {
        self.masks = masks;
        self
    }

    /// The bounding box of all bounded primitives.
    pub fn bounds(&self) -> Aabb {
        self.prims().fold(Aabb::EMPTY, |b, p| b.union(p.shape.bounds()))
    }

    /// Heap bytes of the two BVHs (nodes, triangle blocks, index table), without `prims`.
    pub fn bvh_bytes(&self) -> usize {
        let t = self.trees();
        t.triangles.memory_bytes() + t.others.memory_bytes()
    }

    /// The closest hit in `(0, tmax)`.
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<Hit> {
        let mut best: Option<(PrimRef, f32)> = None;
        let mut tmax = tmax;
        for (i, pl) in self.planes.iter().enumerate() {
            if let Some(t) = pl.plane.intersect(ray, tmax) {
                tmax = t;
                best = Some((PrimRef::Plane(i as u32), t));
            }
        }
        if let Some((i, t)) = self.closest_bounded(ray, tmax) {
            best = Some((PrimRef::Bounded(i), t));
        }
        let (prim, t) = best?;
        self.hit_data(ray, prim, t)
    }

    /// The closest hit in `(0, tmax)` among the bounded primitives (the BVHs'), without planes and without the
    /// hit's surface data: the index into `prims` and the distance. What [`Geometry::intersect`] does before
    /// shading, and what the ray casting benchmarks time.
    pub fn closest_bounded(&self, ray: &Ray, tmax: f32) -> Option<(u32, f32)> {
        let trees = self.trees();
        let tri = TriangleRay::new(ray);
        // One preparation of the ray for the box tests of both trees.
        let boxes = RayBox::new(ray.o, ray.d);
        let best = if self.masks.is_empty() {
            trees.triangles.closest_prepared(&tri, &boxes, tmax, None, |_, _, _| true, &mut ())
        } else {
            let covers = |i, b1, b2| self.covers(i, Vec2::new(b1, b2));
            trees.triangles.closest_prepared(&tri, &boxes, tmax, None, covers, &mut ())
        };
        let hit = |p: &Primitive, tmax| p.shape.intersect_prepared(ray, &tri, tmax);
        // Per store, so that a listed geometry's leaf test is the one load it always was.
        match &self.prims {
            PrimStore::Listed(list) => {
                trees.others.closest_prepared(&boxes, tmax, best, |i, tmax| hit(list.get(i as usize)?, tmax), &mut ())
            }
            PrimStore::Packed(p) => {
                trees.others.closest_prepared(&boxes, tmax, best, |i, tmax| hit(p.whole(i)?, tmax), &mut ())
            }
        }
    }

    /// [`Geometry::closest_bounded`] over the triangles alone, counting the work of the walk into `cost`: what
    /// the ray casting benchmark reports beside its rates.
    pub fn closest_triangle_counted(&self, ray: &Ray, tmax: f32, cost: &mut RayCost) -> Option<(u32, f32)> {
        self.trees().triangles.closest_hit_counted(&TriangleRay::new(ray), ray.d, tmax, cost)
    }

    /// [`Geometry::occluded`] over the triangles alone, counting the work of the walk into `cost`.
    pub fn triangle_occluded_counted(&self, ray: &Ray, tmax: f32, cost: &mut RayCost) -> bool {
        self.trees().triangles.any_hit_counted(&TriangleRay::new(ray), ray.d, tmax, cost)
    }

    /// The texture coordinates of point `p` on bounded primitive `prim`: a mesh triangle's UVs interpolated at
    /// `p`'s barycentrics; zero for other shapes and meshes without UVs (what a textured area light reads,
    /// [`crate::light::Light::le_at`]).
    pub fn uv_at(&self, prim: u32, p: Vec3A) -> Vec2 {
        let Some(Shape::Triangle(tri)) = self.with_prim(prim, |pr| pr.shape) else { return Vec2::ZERO };
        let Some(m) = self.meshes.get(tri.mesh as usize) else { return Vec2::ZERO };
        let Some(ix) = m.uv_indices.get(tri.face as usize) else { return Vec2::ZERO };
        let (b1, b2) = tri.barycentrics(p);
        let w = [1.0 - b1 - b2, b1, b2];
        (0..3).fold(Vec2::ZERO, |acc, k| acc + w[k] * Vec2::from_array(m.uvs[ix[k] as usize]))
    }

    /// Whether primitive `i` is present at barycentrics `b`: it is not a mesh face, or its mesh has no cut-out
    /// or no UVs, or its mask covers the UVs interpolated there.
    fn covers(&self, i: u32, b: Vec2) -> bool {
        let Some(Shape::Triangle(tri)) = self.with_prim(i, |p| p.shape) else { return true };
        let Some(m) = self.meshes.get(tri.mesh as usize) else { return true };
        let (Some(mask), Some(ix)) =
            (m.mask.and_then(|k| self.masks.get(k as usize)), m.uv_indices.get(tri.face as usize))
        else {
            return true;
        };
        let w = [1.0 - b.x - b.y, b.x, b.y];
        let uv = (0..3).fold(Vec2::ZERO, |acc, k| acc + w[k] * Vec2::from_array(m.uvs[ix[k] as usize]));
        mask.covers(uv)
    }

    /// Whether anything blocks `ray` in `(0, tmax)`.
    pub fn occluded(&self, ray: &Ray, tmax: f32) -> bool {
        if self.planes.iter().any(|pl| pl.plane.intersect(ray, tmax).is_some()) {
            return true;
        }
        let trees = self.trees();
        let tri = TriangleRay::new(ray);
        let boxes = RayBox::new(ray.o, ray.d);
        let blocked = if self.masks.is_empty() {
            trees.triangles.any_prepared(&tri, &boxes, tmax, |_, _, _| true, &mut ())
        } else {
            trees.triangles.any_prepared(&tri, &boxes, tmax, |i, b1, b2| self.covers(i, Vec2::new(b1, b2)), &mut ())
        };
        let hit =
            |p: Option<&Primitive>, tmax| p.is_some_and(|p| p.shape.intersect_prepared(ray, &tri, tmax).is_some());
        blocked
            || match &self.prims {
                PrimStore::Listed(list) => {
                    trees.others.any_prepared(&boxes, tmax, |i, tmax| hit(list.get(i as usize), tmax))
                }
                PrimStore::Packed(p) => trees.others.any_prepared(&boxes, tmax, |i, tmax| hit(p.whole(i), tmax)),
            }
    }

    fn hit_data(&self, ray: &Ray, prim: PrimRef, t: f32) -> Option<Hit> {
        Some(match prim {
            PrimRef::Plane(i) => {
                let pl = &self.planes[i as usize];
                let LocalHit { p, p_error, n, uv, dpdu, dpdv } = pl.plane.local_hit(ray, t);
                let (material, light, object) = (pl.material, NONE, pl.object);
                Hit { t, p, p_error, n, ns: n, uv, dpdu, dpdv, material, light, object, prim }
            }
            PrimRef::Bounded(i) => self.with_prim(i, |pr| {
                let LocalHit { p, p_error, n, uv, dpdu, dpdv } = pr.shape.local_hit(ray, t);
                let (n, ns, uv, dpdu, dpdv) = match pr.shape {
                    Shape::Triangle(tri) if tri.mesh != shapes::NO_MESH => {
                        let (n, ns, uv_mesh) = self.mesh_shading(&tri, uv, n);
                        let (uv, dpdu, dpdv) = uv_mesh.unwrap_or((uv, dpdu, dpdv));
                        (n, ns, uv, dpdu, dpdv)
                    }
                    _ => (n, n, uv, dpdu, dpdv),
                };
                let (material, light, object) = (pr.material, pr.light, pr.object);
                Hit { t, p, p_error, n, ns, uv, dpdu, dpdv, material, light, object, prim }
            })?,
        })
    }

    /// Geometric normal, interpolated shading normal, and the texture coordinates with `∂p/∂u`, `∂p/∂v` when the
    /// mesh has them, at barycentrics `b` of a mesh face. The mesh's normals say which side is outside: the
    /// geometric normal is flipped to their side, so a mesh whose winding disagrees with its normals still has a
    /// consistent outside (which glass needs).
    #[allow(clippy::type_complexity)]
    fn mesh_shading(&self, tri: &shapes::Triangle, b: Vec2, n: Vec3A) -> (Vec3A, Vec3A, Option<(Vec2, Vec3A, Vec3A)>) {
        // Normal and UV indices are below their tables: the prepared scene makes them so, and decoding a scene
        // blob checks them (`prepare::blobs`).
        let face = tri.face;
        let Some(m) = self.meshes.get(tri.mesh as usize) else { return (n, n, None) };
        let w = [1.0 - b.x - b.y, b.x, b.y];
        let (n, ns) = match m.normal_indices.get(face as usize) {
            Some(ix) => {
                let s = (0..3).fold(Vec3A::ZERO, |acc, k| acc + w[k] * Vec3A::from_array(m.normals[ix[k] as usize]));
                let s = s.normalize_or_zero();
                if s == Vec3A::ZERO {
                    (n, n)
                } else if s.dot(n) < 0.0 {
                    (-n, s)
                } else {
                    (n, s)
                }
            }
            None => (n, n),
        };
        let tangent = match (m.tangents.is_empty(), m.normal_indices.get(face as usize)) {
            (false, Some(ix)) => {
                let c = ix.map(|k| m.tangents[k as usize]);
                let t = (0..3).fold(Vec3A::ZERO, |acc, k| acc + w[k] * Vec3A::new(c[k][0], c[k][1], c[k][2]));
                Some((t, if c[0][3] < 0.0 { -1.0 } else { 1.0 }))
            }
            _ => None,
        };
        let uv = m.uv_indices.get(face as usize).map(|ix| {
            let c = ix.map(|k| Vec2::from_array(m.uvs[k as usize]));
            let uv = (0..3).fold(Vec2::ZERO, |acc, k| acc + w[k] * c[k]);
            let (dpdu, dpdv) = uv_derivatives(&tri.p, &c);
            match tangent {
                Some((t, sign)) => {
                    let (dpdu, dpdv) = tangent_frame(ns, t, sign, dpdu, dpdv);
                    (uv, dpdu, dpdv)
                }
                None => (uv, dpdu, dpdv),
            }
        });
        (n, ns, uv)
    }
}

/// `∂p/∂u` and `∂p/∂v` turned to a mesh's tangent frame: along the interpolated tangent `t` made perpendicular
/// to the shading normal `ns`, and along the bitangent `sign · (ns × t)` (glTF specification §3.7.2.1), each as
/// long as the UVs' derivative it replaces (what a bump map's heights are measured against). A tangent that
/// vanishes against `ns` keeps the UVs' derivatives.
fn tangent_frame(ns: Vec3A, t: Vec3A, sign: f32, dpdu: Vec3A, dpdv: Vec3A) -> (Vec3A, Vec3A) {
    let t = (t - ns * ns.dot(t)).normalize_or_zero();
    if t == Vec3A::ZERO {
        return (dpdu, dpdv);
    }
    let b = sign * crate::math::fmath::cross(ns, t);
    let length = |v: Vec3A| if v.length() > 0.0 { v.length() } else { 1.0 };
    (t * length(dpdu), b * length(dpdv))
}

/// `∂p/∂u` and `∂p/∂v` of a triangle with corners `p` and texture coordinates `uv`, from
/// `p_i − p_2 = (u_i − u_2)·∂p/∂u + (v_i − v_2)·∂p/∂v` for i = 0, 1 (pbrt-v4 §6.5.3, eq. 6.7). Degenerate
/// coordinates (all on a line) give the triangle's edges instead.
fn uv_derivatives(p: &[glam::Vec3; 3], uv: &[Vec2; 3]) -> (Vec3A, Vec3A) {
    let [p0, p1, p2] = p.map(Vec3A::from);
    let (d02, d12) = (uv[0] - uv[2], uv[1] - uv[2]);
    let (dp02, dp12) = (p0 - p2, p1 - p2);
    let det = d02.x * d12.y - d02.y * d12.x;
    if det.abs() < 1e-12 || !det.is_finite() {
        return (p1 - p0, p2 - p0);
    }
    let inv = 1.0 / det;
    ((d12.y * dp02 - d02.y * dp12) * inv, (d02.x * dp12 - d12.x * dp02) * inv)
}
