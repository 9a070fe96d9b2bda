//! Tests of the BVHs: the walks against brute force, nested walks, degenerate builds, and the four-at-once
//! triangle test against the one-at-a-time test.

use super::*;
use crate::geometry::shapes::{Triangle, TriangleRay};
use crate::math::Aabb;
use crate::math::{Ray, fmath};
use glam::{Vec3, Vec3A};

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
    let bvh = Bvh::build(&[]);
    assert_eq!(bvh.node_count(), 0);
    assert_eq!(bvh.depth(), 0);
    assert!(bvh.bounds().is_empty());
    assert!(bvh.closest_hit(Vec3A::ZERO, Vec3A::X, f32::INFINITY, |_, _| Some(1.0)).is_none());
    assert!(!bvh.any_hit(Vec3A::ZERO, Vec3A::X, f32::INFINITY, |_, _| true));
}

#[test]
fn one_primitive() {
    let b = [cube(Vec3::new(0.0, 0.0, 5.0), 1.0)];
    let bvh = Bvh::build(&b);
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
    let bvh = Bvh::build(&b);
    let mut sorted = bvh.items.clone();
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
    let bvh = Bvh::build(&vec![cube(Vec3::ONE, 0.0); n]);
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
    let bvh = Bvh::build(&b);
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

/// `n` random cubes in `[0, 10]³` (sides up to 0.2), their BVH, and `rays` random
/// rays (origins in `[−1, 11]³`, uniform directions), from `seed`.
#[allow(clippy::type_complexity)]
fn boxes_and_rays(seed: u64, n: usize, rays: usize) -> (Bvh, Vec<Aabb>, Vec<(Vec3A, Vec3A)>) {
    let mut s = crate::math::rng::Sampler::new(seed, crate::math::rng::Domain::Photon, 0, 0, 0);
    let mut v = || Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
    let b: Vec<Aabb> = (0..n).map(|_| cube(10.0 * v(), 0.2 * v().x)).collect();
    let rays = (0..rays).map(|_| (Vec3A::from(12.0 * v() - 1.0), fmath::normalize(Vec3A::from(v() - 0.5)))).collect();
    let bvh = Bvh::build(&b);
    (bvh, b, rays)
}

#[test]
fn closest_and_any_hit_agree_with_brute_force_on_boxes() {
    let (bvh, b, rays) = boxes_and_rays(3, 500, 2000);
    for (o, d) in rays {
        let brute = b.iter().filter_map(|x| box_hit(x, o, d, f32::INFINITY)).fold(f32::INFINITY, f32::min);
        let h = bvh.closest_hit(o, d, f32::INFINITY, |p, t| box_hit(&b[p as usize], o, d, t));
        assert_eq!(h.map_or(f32::INFINITY, |h| h.1), brute);
        assert_eq!(bvh.any_hit(o, d, f32::INFINITY, |p, t| box_hit(&b[p as usize], o, d, t).is_some()), h.is_some());
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

#[test]
fn geometric_centroids_stay_within_depth_cap() {
    // Centroids at 2^-k make every SAH split peel off one primitive.
    let b: Vec<Aabb> = (0..200).map(|k| cube(Vec3::splat((-(k as f32)).exp2()), 0.0)).collect();
    let bvh = Bvh::build(&b);
    assert!(bvh.depth() <= MAX_DEPTH);
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
fn empty_boxes_build() {
    let mut b = vec![Aabb::EMPTY; 10];
    b.push(cube(Vec3::ZERO, 1.0));
    let bvh = Bvh::build(&b);
    let k = 10;
    let h = bvh.closest_hit(Vec3A::new(0.0, 0.0, -5.0), Vec3A::Z, f32::INFINITY, |p, t| {
        (p == k).then_some(4.0).filter(|&x| x < t)
    });
    assert_eq!(h, Some((k, 4.0)));
}

/// Rays through `tie_scene`: straight down through the grid's vertices and edge midpoints (ties between the
/// triangles that share them), in the grid's plane along an axis (on slab planes, NaN slab distances), and random.
fn tie_rays(s: &mut crate::math::rng::Sampler, n: usize) -> Vec<Ray> {
    (0..n)
        .map(|k| {
            let (o, d) = match k % 4 {
                0 => (Vec3A::new((k % 17) as f32 * 0.5, (k % 13) as f32 * 0.5, 5.0), Vec3A::NEG_Z),
                1 => (Vec3A::new(-1.0, (k % 9) as f32, 2.0), Vec3A::X),
                _ => (
                    Vec3A::new(10.0 * s.next_f32() - 1.0, 10.0 * s.next_f32() - 1.0, 10.0 * s.next_f32() - 1.0),
                    crate::math::uniform_sphere(s.next_2d()),
                ),
            };
            Ray::new(o, d)
        })
        .collect()
}

/// The closest hit by testing every triangle: the smallest distance, then the smallest index.
fn brute_closest(tris: &[Triangle], ray: &Ray, tmax: f32) -> Option<(u32, f32)> {
    let mut best: Option<(u32, f32)> = None;
    for (i, t) in tris.iter().enumerate() {
        if let Some(h) = t.intersect(ray, tmax)
            && walk::better(h, i as u32, best)
        {
            best = Some((i as u32, h));
        }
    }
    best
}

/// A block tests each of its triangles with the same bits as the one-at-a-time test, in whichever lane, for
/// rays through shared edges and vertices (where the edge functions are decided in f64) and random rays.
#[test]
fn four_at_once_gives_the_one_at_a_time_bits() {
    let mut s = crate::math::rng::Sampler::new(11, crate::math::rng::Domain::Photon, 0, 0, 0);
    let tris: Vec<Triangle> = tie_scene(&mut s).into_iter().filter(tri4::hittable).collect();
    let rays = tie_rays(&mut s, 4000);
    let (mut hits, mut on_edge) = (0, 0);
    for (k, ray) in rays.iter().enumerate() {
        let tri_ray = TriangleRay::new(ray);
        let tmax = if k % 3 == 0 { 4.0 } else { f32::INFINITY };
        // Blocks of four consecutive triangles, starting at a different offset for each ray so that each
        // triangle meets every lane.
        for first in (k % 4..tris.len().saturating_sub(4)).step_by(4) {
            let four: Vec<(u32, Triangle)> = (0..4).map(|l| (l as u32, tris[first + l])).collect();
            let block = tri4::block(four.iter().copied());
            let h = block.intersect(&tri4::BlockRay::new(&tri_ray), tmax);
            for (l, (_, t)) in four.iter().enumerate() {
                let one = t.intersect_prepared(&tri_ray, tmax);
                let four = (h.mask & (1 << l) != 0).then(|| (h.t[l], h.b1[l], h.b2[l]));
                let bits = |h: Option<(f32, f32, f32)>| h.map(|(a, b, c)| (a.to_bits(), b.to_bits(), c.to_bits()));
                assert_eq!(bits(four), bits(one), "ray {k} {ray:?}, triangle {t:?} in lane {l}");
                hits += usize::from(one.is_some());
                on_edge += usize::from(one.is_some_and(|(_, b1, b2)| b1 == 0.0 || b2 == 0.0 || b1 + b2 == 1.0));
            }
        }
    }
    assert!(hits > 3000 && on_edge > 1000, "{hits} hits, {on_edge} on an edge");
}

/// Two triangle trees with different leaves, the general tree testing one triangle at a time, and testing every
/// triangle all give the same closest hit, index and distance bit for bit, on 100k rays with over a thousand
/// exact ties; and the same any-hit answer.
#[test]
fn hits_do_not_depend_on_the_tree() {
    let mut s = crate::math::rng::Sampler::new(5, crate::math::rng::Domain::Photon, 0, 0, 0);
    let tris = tie_scene(&mut s);
    let indexed: Vec<(u32, Triangle)> = tris.iter().enumerate().map(|(i, &t)| (i as u32, t)).collect();
    let blocks = TriBvh::build(&indexed);
    let singles = TriBvh::build_with(&indexed, Leaves { max: 1, group: 1, group_cost: 1.0, merge: 1 });
    let general = Bvh::build(&tris.iter().map(Triangle::bounds).collect::<Vec<_>>());
    assert_ne!(blocks.structure_hash(), singles.structure_hash());
    let mut ties = 0;
    for (k, ray) in tie_rays(&mut s, 100_000).iter().enumerate() {
        let tmax = if k % 5 == 0 { 4.0 } else { f32::INFINITY };
        let tri_ray = TriangleRay::new(ray);
        let want = brute_closest(&tris, ray, tmax);
        let bits = |h: Option<(u32, f32)>| h.map(|(i, t)| (i, t.to_bits()));
        let a = blocks.closest_hit(&tri_ray, ray.d, tmax, None, |_, _, _| true);
        let b = singles.closest_hit(&tri_ray, ray.d, tmax, None, |_, _, _| true);
        let c = general
            .closest_hit(ray.o, ray.d, tmax, |p, t| tris[p as usize].intersect_prepared(&tri_ray, t).map(|h| h.0));
        assert_eq!(bits(a), bits(want), "ray {k}: {ray:?}");
        assert_eq!(bits(b), bits(want), "ray {k}: {ray:?}");
        assert_eq!(bits(c), bits(want), "ray {k}: {ray:?}");
        let any = want.is_some();
        assert_eq!(blocks.any_hit(&tri_ray, ray.d, tmax, |_, _, _| true), any, "ray {k}");
        assert_eq!(singles.any_hit(&tri_ray, ray.d, tmax, |_, _, _| true), any, "ray {k}");
        assert_eq!(general.any_hit(ray.o, ray.d, tmax, |p, t| tris[p as usize].intersect(ray, t).is_some()), any);
        if let Some((_, t)) = want {
            ties += usize::from(tris.iter().filter(|tri| tri.intersect(ray, tmax) == Some(t)).count() > 1);
        }
    }
    assert!(ties > 1000, "{ties} ties");
}

/// The triangle tree builds the same on 1 and 4 threads, and `keep` removes hits.
#[test]
fn the_triangle_tree_is_the_same_on_any_thread_count_and_keep_filters() {
    let mut s = crate::math::rng::Sampler::new(7, crate::math::rng::Domain::Photon, 0, 0, 0);
    let tris: Vec<(u32, Triangle)> = (0..40_000u32)
        .map(|i| {
            let c = 10.0 * Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
            let mut v = || c + 0.3 * Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
            (i, Triangle::new(v(), v(), v()))
        })
        .collect();
    let build = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| TriBvh::build(&tris))
    };
    let (one, four) = (build(1), build(4));
    assert_eq!(one.structure_hash(), four.structure_hash());
    assert_eq!(one, four);
    let ray = Ray::new(Vec3A::new(5.0, 5.0, -1.0), Vec3A::Z);
    let tri_ray = TriangleRay::new(&ray);
    let first = one.closest_hit(&tri_ray, ray.d, f32::INFINITY, None, |_, _, _| true);
    let (i, _) = first.expect("the ray meets the soup");
    let second = one.closest_hit(&tri_ray, ray.d, f32::INFINITY, None, |j, _, _| j != i);
    assert!(second.is_some_and(|(j, t)| j != i && t >= first.unwrap().1));
}
