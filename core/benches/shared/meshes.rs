//! Meshes and rays shared by the BVH benchmark, the `raycast` example (photon against Embree) and the
//! mixed-architecture test; included with `#[path]` where needed.

use glam::{Vec3, Vec3A};
use photon_core::math::rng::{Domain, Sampler};
use photon_core::math::{Aabb, Ray, fmath};
use std::collections::HashMap;

/// A unit icosphere subdivided `levels` times (20·4^levels triangles), its vertices displaced along the normal
/// by a smooth bump of ±6 %: every triangle is distinct and the BVH's boxes overlap as on a scanned surface.
pub fn bumpy_icosphere(levels: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut faces: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid = HashMap::new();
        let mut split = |a: usize, b: usize, v: &mut Vec<[f64; 3]>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push([0, 1, 2].map(|k| 0.5 * (v[a][k] + v[b][k])));
                v.len() - 1
            })
        };
        faces = faces
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (split(a, b, &mut v), split(b, c, &mut v), split(c, a, &mut v));
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    let vertices = v
        .iter()
        .map(|p| {
            let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let q = p.map(|c| c / len);
            let bump = 1.0 + 0.06 * (9.0 * q[0]).sin() * (7.0 * q[1]).sin() * (11.0 * q[2]).sin();
            q.map(|c| (bump * c) as f32)
        })
        .collect();
    let faces = faces.iter().map(|f| f.map(|i| i as u32)).collect();
    (vertices, faces)
}

/// Rays of a `w × h` pinhole camera at `(0, 0.3, 3)` looking at the origin with a 45° vertical field of view.
pub fn camera_rays(w: usize, h: usize) -> Vec<Ray> {
    let o = Vec3A::new(0.0, 0.3, 3.0);
    let fwd = fmath::normalize(-o);
    let right = fmath::normalize(fmath::cross(fwd, Vec3A::Y));
    let up = fmath::cross(right, fwd);
    let tan = fmath::tan((22.5f32).to_radians());
    let mut rays = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let sx = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * tan * w as f32 / h as f32;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * tan;
            rays.push(Ray::new(o, fmath::normalize(fwd + sx * right + sy * up)));
        }
    }
    rays
}

/// `n` rays from uniform points in `bounds` in uniform directions.
pub fn random_rays(n: usize, bounds: Aabb) -> Vec<Ray> {
    let mut s = Sampler::new(7, Domain::Photon, 0, 0, 0);
    (0..n)
        .map(|_| {
            let u = Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
            let o = bounds.min + u * (bounds.max - bounds.min);
            let d = photon_core::math::uniform_sphere(s.next_2d());
            Ray::new(Vec3A::from(o), d)
        })
        .collect()
}
