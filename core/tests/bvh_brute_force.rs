//! The BVHs find exactly what testing every triangle finds: the same closest triangle and distance for 100k random
//! rays per soup, the same any-hit answer, on random triangle soups salted with degenerate triangles (zero area,
//! collinear, repeated vertices) and exact duplicates, for every layout and thread count. And the build is
//! deterministic.

#![allow(clippy::unwrap_used)]

use glam::{Vec3, Vec3A};
use photon_core::geometry::bvh::{Bvh, Leaves, TriBvh};
use photon_core::geometry::shapes::{Shape, Triangle, TriangleRay};
use photon_core::geometry::{Geometry, NONE, Primitive};
use photon_core::math::fmath;
use photon_core::math::rng::mix64;

/// The test's own random stream (SplitMix64), so that the soups and rays, and the recorded tree below, do not
/// change when the renderer's sampler does.
struct Sampler(u64);

impl Sampler {
    fn new(seed: u64, stream: u64) -> Self {
        Sampler(mix64(seed ^ stream.rotate_left(32)))
    }

    fn next_u32(&mut self) -> u32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        (mix64(self.0) >> 32) as u32
    }

    fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    fn next_2d(&mut self) -> glam::Vec2 {
        let x = self.next_f32();
        glam::Vec2::new(x, self.next_f32())
    }
}
use photon_core::math::{Aabb, Ray};

fn v3(s: &mut Sampler) -> Vec3 {
    Vec3::new(s.next_f32(), s.next_f32(), s.next_f32())
}

/// A soup of `n` triangles in `[0, 10]³`: mostly small random triangles, some large ones, some axis-aligned
/// (flat bounds), plus degenerate ones and duplicates of earlier triangles.
fn soup(seed: u64, n: usize) -> Vec<Triangle> {
    let mut s = Sampler::new(seed, 1);
    let mut tris: Vec<Triangle> = Vec::with_capacity(n);
    while tris.len() < n {
        let kind = s.next_f32();
        let c = 10.0 * v3(&mut s);
        let size = if s.next_f32() < 0.05 { 4.0 } else { 0.6 };
        let pick = s.next_u32() as usize;
        let mut corner = || c + size * (v3(&mut s) - 0.5);
        let t = if kind < 0.60 {
            Triangle::new(corner(), corner(), corner())
        } else if kind < 0.70 {
            // One edge in an axis plane at the bottom of the bounds, so rays along that plane can hit the edge.
            let (mut a, mut b, mut d) = (corner(), corner(), corner());
            let k = pick % 3;
            a[k] = c[k];
            b[k] = c[k];
            d[k] = c[k] + 0.3;
            Triangle::new(a, b, d)
        } else if kind < 0.78 {
            // Axis-aligned: flat in z, so its bounds have zero thickness.
            let (a, b, d) = (corner(), corner(), corner());
            Triangle::new(a.with_z(c.z), b.with_z(c.z), d.with_z(c.z))
        } else if kind < 0.83 {
            // Zero area: all three vertices equal.
            let a = corner();
            Triangle::new(a, a, a)
        } else if kind < 0.88 {
            // Collinear vertices.
            let (a, b) = (corner(), corner());
            Triangle::new(a, b, a + 2.5 * (b - a))
        } else if kind < 0.93 {
            // Two repeated vertices.
            let (a, b) = (corner(), corner());
            Triangle::new(a, b, b)
        } else if let Some(&t) = tris.get(pick % tris.len().max(1)) {
            // An exact duplicate.
            t
        } else {
            Triangle::new(corner(), corner(), corner())
        };
        tris.push(t);
    }
    tris
}

/// Rays: origins in and around the soup, uniform directions. A fifth are axis-aligned (two zero direction
/// components) and run in the plane of an axis-aligned triangle edge that lies on the triangle's bounds, through
/// the edge's midpoint: they start exactly on slab planes of the boxes above that triangle, where `0·∞` gives
/// NaN slab distances, and still hit the triangle (on its edge, where the watertight test's edge function is
/// exactly 0).
fn rays(seed: u64, n: usize, tris: &[Triangle]) -> Vec<Ray> {
    let mut s = Sampler::new(seed, 2);
    (0..n)
        .map(|_| {
            let mut o = Vec3A::from(14.0 * v3(&mut s) - 2.0);
            if s.next_f32() < 0.2 {
                let t = tris[(s.next_u32() as usize) % tris.len()];
                let b = t.bounds();
                let edge = (0..3).flat_map(|i| (0..3).map(move |k| (i, k))).find(|&(i, k)| {
                    let (p, q) = (t.p[i], t.p[(i + 1) % 3]);
                    p != q && p[k] == q[k] && (p[k] == b.min[k] || p[k] == b.max[k])
                });
                let (k, mid) = match edge {
                    Some((i, k)) => (k, 0.5 * (t.p[i] + t.p[(i + 1) % 3])),
                    None => ((s.next_u32() % 3) as usize, b.min),
                };
                let axis = (k + 1 + (s.next_u32() % 2) as usize) % 3;
                let third = 3 - k - axis;
                o[k] = mid[k];
                o[third] = mid[third];
                let mut d = Vec3A::ZERO;
                d[axis] = if o[axis] < mid[axis] { 1.0 } else { -1.0 };
                return Ray::new(o, d);
            }
            let u = s.next_2d();
            let z = 1.0 - 2.0 * u.x;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * std::f32::consts::PI * u.y;
            Ray::new(o, Vec3A::new(r * fmath::cos(phi), r * fmath::sin(phi), z))
        })
        .collect()
}

/// Whether the hit at `t` lies in the triangle's bounding box, enlarged by a few ulps of the coordinates involved
/// (the hit point `o + t·d` is rounded). A triangle test that reports hits off its triangle, as Möller–Trumbore
/// does on nearly degenerate triangles, fails this.
fn on_triangle(tri: &Triangle, ray: &Ray, t: f32) -> bool {
    let b = tri.bounds();
    let p = ray.at(t);
    let scale = Vec3A::from(b.min).abs().max(Vec3A::from(b.max).abs()).max(ray.o.abs()).max_element();
    // Observed up to 2.2e-7·scale (about 2 ulps) on these soups.
    let eps = Vec3A::splat(1e-6 * scale.max(1.0));
    p.cmpge(Vec3A::from(b.min) - eps).all() && p.cmple(Vec3A::from(b.max) + eps).all()
}

/// The closest hit by testing every triangle: the smallest distance, then the smallest index (a later triangle
/// replaces the best only if strictly closer).
fn brute_closest(tris: &[Triangle], ray: &Ray, tmax: f32) -> Option<(u32, f32)> {
    let mut best = (None, tmax);
    for (i, tri) in tris.iter().enumerate() {
        if let Some(t) = hit(tri, ray, best.1) {
            best = (Some((i as u32, t)), t);
        }
    }
    best.0
}

/// `Triangle::intersect`, asserting that a hit lies on the triangle.
fn hit(tri: &Triangle, ray: &Ray, tmax: f32) -> Option<f32> {
    let t = tri.intersect(ray, tmax);
    if let Some(t) = t {
        assert!(on_triangle(tri, ray, t), "hit at t = {t} off {tri:?} along {ray:?}: {}", ray.at(t));
    }
    t
}

fn indexed(tris: &[Triangle]) -> Vec<(u32, Triangle)> {
    tris.iter().enumerate().map(|(i, &t)| (i as u32, t)).collect()
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

/// Every layout (the triangle tree with blocks of four and with one triangle a leaf, and the general tree that
/// tests one primitive at a time through a callback), built on 1, 2 and 3 threads, finds the same closest hit
/// as testing every triangle, index and distance bit for bit, and the same any-hit answer, on 100k rays per soup.
#[test]
fn closest_and_any_hit_match_brute_force() {
    for seed in [1u64, 2, 3] {
        let tris = soup(seed, 2000);
        let bounds: Vec<Aabb> = tris.iter().map(Triangle::bounds).collect();
        let threads = [1, 2, 3][seed as usize - 1];
        let (blocks, singles, general) = pool(threads).install(|| {
            (
                TriBvh::build(&indexed(&tris)),
                TriBvh::build_with(&indexed(&tris), Leaves { max: 1, group: 1, group_cost: 1.0, merge: 1 }),
                Bvh::build(&bounds),
            )
        });
        let (mut hits, mut limited, mut axial) = (0, 0, 0);
        for (k, ray) in rays(seed, 100_000, &tris).iter().enumerate() {
            // Every fourth ray has a finite tmax, to exercise the interval clipping.
            let tmax = if k % 4 == 0 { 6.0 } else { f32::INFINITY };
            let brute = brute_closest(&tris, ray, tmax);
            let bits = |h: Option<(u32, f32)>| h.map(|(i, t)| (i, t.to_bits()));
            let tri_ray = TriangleRay::new(ray);
            for (name, tree) in [("blocks", &blocks), ("singles", &singles)] {
                let got = tree.closest_hit(&tri_ray, ray.d, tmax, None, |_, _, _| true);
                assert_eq!(bits(got), bits(brute), "{name}: seed {seed} ray {k}: {ray:?}");
                let any = tree.any_hit(&tri_ray, ray.d, tmax, |_, _, _| true);
                assert_eq!(any, brute.is_some(), "{name}: seed {seed} ray {k}: any-hit");
            }
            let got = general.closest_hit(ray.o, ray.d, tmax, |i, t| hit(&tris[i as usize], ray, t));
            assert_eq!(bits(got), bits(brute), "general: seed {seed} ray {k}: {ray:?}");
            let any = general.any_hit(ray.o, ray.d, tmax, |i, t| hit(&tris[i as usize], ray, t).is_some());
            assert_eq!(any, brute.is_some(), "general: seed {seed} ray {k}: any-hit");
            if brute.is_some() {
                hits += 1;
                limited += usize::from(tmax.is_finite());
                axial += usize::from(ray.d.cmpeq(Vec3A::ZERO).any());
            }
        }
        // The test means something: plenty of hits and of misses, some of them cut by tmax, many axis-aligned.
        println!("seed {seed}: {hits} hits, {limited} with finite tmax, {axial} axis-aligned");
        assert!(hits > 20_000 && hits < 90_000 && limited > 1000 && axial > 5000);
    }
}

/// Every hit of every triangle lies on its triangle, however far along the ray: the tests above check only hits
/// closer than the best found so far.
#[test]
fn brute_force_hits_lie_on_their_triangles() {
    let tris = soup(4, 2000);
    let mut hits = 0;
    for ray in rays(4, 20_000, &tris) {
        hits += tris.iter().filter(|tri| hit(tri, &ray, f32::INFINITY).is_some()).count();
    }
    assert!(hits > 5000, "{hits}");
}

/// The geometry of `tris`, each primitive's `object` its index in `tris`.
fn geometry(tris: &[Triangle]) -> Geometry {
    let prims = tris
        .iter()
        .enumerate()
        .map(|(i, &t)| Primitive { shape: Shape::Triangle(t), material: 0, light: NONE, object: i as u32 })
        .collect();
    Geometry::new(prims, Vec::new(), Vec::new())
}

#[test]
fn geometry_queries_match_brute_force() {
    let tris = soup(9, 3000);
    let g = geometry(&tris);
    for ray in rays(9, 20_000, &tris) {
        let brute = brute_closest(&tris, &ray, f32::INFINITY);
        let hit = g.intersect(&ray, f32::INFINITY);
        // The same triangle (`object` carries its index) at the same distance.
        assert_eq!(hit.map(|h| (h.object, h.t.to_bits())), brute.map(|(i, t)| (i, t.to_bits())));
        assert_eq!(g.occluded(&ray, f32::INFINITY), brute.is_some());
    }
}

/// The trees build the same twice and on 1 and 4 threads (the same hash of every node and block), with enough
/// triangles that the top nodes bin in parallel chunks and the subtrees are rayon tasks.
#[test]
fn build_is_the_same_on_1_and_4_threads() {
    let tris = soup(6, 300_000);
    let bounds: Vec<Aabb> = tris.iter().map(Triangle::bounds).collect();
    assert!(bounds.len() > 4 * photon_core::geometry::bvh::CHUNK);
    let build = |threads: usize| pool(threads).install(|| (TriBvh::build(&indexed(&tris)), Bvh::build(&bounds)));
    let (one, four, again) = (build(1), build(4), build(4));
    println!("triangle tree {:016x}, general tree {:016x}", one.0.structure_hash(), one.1.structure_hash());
    for other in [&four, &again] {
        assert_eq!(one.0.structure_hash(), other.0.structure_hash());
        assert_eq!(one.0, other.0);
        assert_eq!(one.1.structure_hash(), other.1.structure_hash());
        assert_eq!(one.1, other.1);
    }
    assert!(one.0.node_count() > 5_000 && one.1.node_count() > 5_000);
}

/// The scene blob carries the primitives in the scene's order and no tree; decoding builds the trees again, and
/// they are the coordinator's, node for node.
#[test]
fn a_decoded_geometry_has_the_trees_it_was_encoded_with() {
    let tris = soup(8, 100_000);
    let g = geometry(&tris);
    let blob = photon_core::codec::encode(&g).unwrap();
    // The blob is the primitives, planes, meshes and cut-outs, and nothing else.
    let prims: Vec<Primitive> = g.prims().collect();
    assert_eq!(blob, photon_core::codec::encode(&(&prims, &g.planes, &g.meshes, &g.masks)).unwrap());
    let back: Geometry = photon_core::codec::decode(&blob, blob.len()).unwrap();
    assert_eq!(back.prims().collect::<Vec<_>>(), prims);
    assert_eq!(back.triangle_tree().structure_hash(), g.triangle_tree().structure_hash());
    assert_eq!(back.triangle_tree(), g.triangle_tree());
}

/// Packing a geometry (what a worker does on decoding it) keeps every primitive and every answer, bit for bit:
/// mesh faces in runs (with a skipped face, a change of material, lights carried in order and then not), bare
/// triangles, spheres and rectangles between them, and the soup's degenerate triangles, which no block holds.
/// A mesh's triangles then cost at most 64 bytes each, vertices included.
#[test]
fn a_packed_geometry_answers_as_the_listed_one() {
    use photon_core::geometry::shapes::{Rect, Sphere};
    let tris = soup(11, 20_000);
    let mut s = Sampler::new(11, 2);
    let mut prims = Vec::new();
    for (i, &t) in tris.iter().enumerate() {
        let i = i as u32;
        // Faces of mesh 0, one skipped every 1000; the material changes at 5000; faces 2000 to 2499 carry lights
        // 7, 8, …; one in 997 is a bare triangle; a sphere or a rectangle every 3001.
        let mesh = if i.is_multiple_of(997) { photon_core::geometry::shapes::NO_MESH } else { 0 };
        let face = i + i / 1000;
        let light = if (2000..2500).contains(&i) { 7 + i - 2000 } else { NONE };
        let material = u32::from(i >= 5000);
        prims.push(Primitive { shape: Shape::Triangle(Triangle { mesh, face, ..t }), material, light, object: 3 });
        if i.is_multiple_of(3001) {
            let c = 10.0 * v3(&mut s);
            let shape = if i.is_multiple_of(2) {
                Shape::Sphere(Sphere { center: c, radius: 0.3 })
            } else {
                Shape::Rect(Rect { corner: c, u: Vec3::X, v: Vec3::Z })
            };
            prims.push(Primitive { shape, material: 1, light: NONE, object: 4 });
        }
    }
    let listed = Geometry::new(prims.clone(), Vec::new(), Vec::new());
    let packed = listed.clone().packed();
    assert_eq!(packed.prim_count(), prims.len());
    assert_eq!(packed.prims().collect::<Vec<_>>(), prims);
    assert!(packed.prim(prims.len() as u32).is_none());
    // The blob lists them as before.
    assert_eq!(photon_core::codec::encode(&packed).unwrap(), photon_core::codec::encode(&listed).unwrap());
    let (mut hits, mut others) = (0, 0);
    for ray in rays(11, 20_000, &tris) {
        let (a, b) = (listed.intersect(&ray, f32::INFINITY), packed.intersect(&ray, f32::INFINITY));
        let key = |h: Option<photon_core::geometry::Hit>| {
            h.map(|h| (h.prim, h.t.to_bits(), h.p.to_array().map(f32::to_bits), h.material, h.light, h.object))
        };
        assert_eq!(key(a), key(b));
        hits += usize::from(a.is_some());
        others += usize::from(a.is_some_and(|h| h.object == 4));
        assert_eq!(listed.occluded(&ray, 5.0), packed.occluded(&ray, 5.0));
    }
    assert!(hits > 10_000 && others > 10, "{hits} hits, {others} on spheres and rectangles");
    // A packed geometry that is changed is listed again, with the change.
    let mut changed = packed.clone();
    changed.prims_mut()[5].material = 9;
    assert_eq!(changed.prim(5).map(|p| p.material), Some(9));
    assert_eq!(changed.prim(6), packed.prim(6));
    // The memory: the listed geometry holds each triangle twice (its primitive and the tree's block).
    let per_triangle = |g: &Geometry| g.memory_bytes() as f64 / prims.len() as f64;
    assert!(per_triangle(&packed) <= 64.0, "{} bytes a triangle packed", per_triangle(&packed));
    assert!(per_triangle(&listed) > 100.0, "{} bytes a triangle listed", per_triangle(&listed));
}
