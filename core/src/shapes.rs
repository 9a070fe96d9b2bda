//! Shapes and their exact ray tests.
//!
//! ```toml
//! [[objects]]
//! type = "sphere"
//! center = [0.0, 1.0, 0.0]
//! radius = 0.5
//! material = "glass"
//! ```
//! Spheres, rectangles (parallelograms) and triangles are bounded and live in the BVH; infinite planes are
//! tested separately (see [`crate::geometry`]). Each shape answers the distance of the closest hit (`intersect`)
//! and, for that hit only, the surface data (`surface`).

use crate::geometry::{Aabb, Ray};
use glam::{Vec2, Vec3, Vec3A};
use serde::{Deserialize, Serialize};

/// A sphere.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3,
    /// Radius (> 0).
    pub radius: f32,
}

/// A parallelogram with corner `corner` and edges `u`, `v`; its normal is `normalize(u × v)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    /// One corner.
    pub corner: Vec3,
    /// First edge (width direction).
    pub u: Vec3,
    /// Second edge (height direction).
    pub v: Vec3,
}

/// A triangle. `mesh` and `face` point at shading data (normals, UVs) in the prepared meshes, or are
/// [`NO_MESH`] for a bare triangle, whose normal is `normalize((p1 − p0) × (p2 − p0))`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Triangle {
    /// Vertices.
    pub p: [Vec3; 3],
    /// Mesh index, or [`NO_MESH`].
    pub mesh: u32,
    /// Face index within the mesh.
    pub face: u32,
}

/// Marks a triangle without mesh shading data.
pub const NO_MESH: u32 = u32::MAX;

/// An infinite plane through `point` with unit normal `normal`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plane {
    /// A point on the plane.
    pub point: Vec3,
    /// Unit normal.
    pub normal: Vec3,
}

/// A bounded shape.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Shape {
    /// A sphere.
    Sphere(Sphere),
    /// A parallelogram.
    Rect(Rect),
    /// A triangle.
    Triangle(Triangle),
}

/// Geometric data of a hit point before shading normals and textures are applied.
#[derive(Clone, Copy, Debug)]
pub struct LocalHit {
    /// The point, refined to lie on the surface.
    pub p: Vec3A,
    /// Geometric unit normal, as defined by the shape (not flipped towards the ray).
    pub n: Vec3A,
    /// Surface parameters: `(u, v)` on rectangles and spheres, barycentrics `(b1, b2)` on triangles.
    pub uv: Vec2,
}

impl Sphere {
    /// Distance along `ray` to the closest hit in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        // Numerically stable form (Haines et al., "Precision Improvements for Ray/Sphere Intersection", RTG ch. 7).
        let c = Vec3A::from(self.center);
        let f = ray.o - c;
        let a = ray.d.length_squared();
        let b = -f.dot(ray.d);
        let l = f + (b / a) * ray.d;
        let disc = self.radius * self.radius - l.length_squared();
        if disc < 0.0 {
            return None;
        }
        let c_term = f.length_squared() - self.radius * self.radius;
        let q = b + b.signum() * (a * disc).sqrt();
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c_term / q, q / a) };
        let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        if t0 > 0.0 && t0 < tmax {
            Some(t0)
        } else if t1 > 0.0 && t1 < tmax {
            Some(t1)
        } else {
            None
        }
    }

    fn local_hit(&self, p: Vec3A) -> LocalHit {
        let c = Vec3A::from(self.center);
        let n = (p - c).normalize();
        // Re-project onto the surface so the offset origin of the next ray is reliable.
        let p = c + n * self.radius;
        let u = 0.5 + n.z.atan2(n.x) / (2.0 * std::f32::consts::PI);
        let v = n.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
        LocalHit { p, n, uv: Vec2::new(u, v) }
    }
}

impl Rect {
    /// Builds the rectangle of the origin's convention: centre, unit normal, tangent (the width direction,
    /// projected to be perpendicular to the normal), width and height.
    pub fn from_center(center: Vec3, normal: Vec3, tangent: Vec3, width: f32, height: f32) -> Self {
        let n = normal.normalize();
        let t = (tangent - n * tangent.dot(n)).normalize();
        let b = n.cross(t);
        // u × v = t × b = n, so the rectangle faces along `normal`.
        let u = t * width;
        let v = b * height;
        Self { corner: center - 0.5 * u - 0.5 * v, u, v }
    }

    /// Unit normal.
    pub fn normal(&self) -> Vec3A {
        Vec3A::from(self.u.cross(self.v)).normalize()
    }

    /// Area.
    pub fn area(&self) -> f32 {
        self.u.cross(self.v).length()
    }

    /// Distance along `ray` to the hit in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let u = Vec3A::from(self.u);
        let v = Vec3A::from(self.v);
        let nn = u.cross(v);
        let denom = nn.dot(ray.d);
        if denom == 0.0 {
            return None;
        }
        let t = nn.dot(Vec3A::from(self.corner) - ray.o) / denom;
        if !(t > 0.0 && t < tmax) {
            return None;
        }
        let d = ray.o + t * ray.d - Vec3A::from(self.corner);
        let a = d.dot(u) / u.length_squared();
        let b = d.dot(v) / v.length_squared();
        ((0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b)).then_some(t)
    }

    fn local_hit(&self, p: Vec3A) -> LocalHit {
        let u = Vec3A::from(self.u);
        let v = Vec3A::from(self.v);
        let d = p - Vec3A::from(self.corner);
        let a = d.dot(u) / u.length_squared();
        let b = d.dot(v) / v.length_squared();
        LocalHit { p, n: self.normal(), uv: Vec2::new(a, b) }
    }
}

impl Triangle {
    /// A bare triangle.
    pub fn new(p0: Vec3, p1: Vec3, p2: Vec3) -> Self {
        Self { p: [p0, p1, p2], mesh: NO_MESH, face: 0 }
    }

    /// Geometric unit normal (zero for a degenerate triangle).
    pub fn normal(&self) -> Vec3A {
        let e1 = Vec3A::from(self.p[1] - self.p[0]);
        let e2 = Vec3A::from(self.p[2] - self.p[0]);
        e1.cross(e2).normalize_or_zero()
    }

    /// Area.
    pub fn area(&self) -> f32 {
        0.5 * (self.p[1] - self.p[0]).cross(self.p[2] - self.p[0]).length()
    }

    /// Möller–Trumbore: distance and barycentrics `(b1, b2)` of the hit in `(0, tmax)`. Degenerate triangles
    /// are never hit.
    #[inline]
    pub fn intersect_bary(&self, ray: &Ray, tmax: f32) -> Option<(f32, f32, f32)> {
        let p0 = Vec3A::from(self.p[0]);
        let e1 = Vec3A::from(self.p[1]) - p0;
        let e2 = Vec3A::from(self.p[2]) - p0;
        let pv = ray.d.cross(e2);
        let det = e1.dot(pv);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let tv = ray.o - p0;
        let b1 = tv.dot(pv) * inv;
        if !(0.0..=1.0).contains(&b1) {
            return None;
        }
        let qv = tv.cross(e1);
        let b2 = ray.d.dot(qv) * inv;
        if b2 < 0.0 || b1 + b2 > 1.0 {
            return None;
        }
        let t = e2.dot(qv) * inv;
        (t > 0.0 && t < tmax).then_some((t, b1, b2))
    }

    /// Distance to the hit in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        self.intersect_bary(ray, tmax).map(|h| h.0)
    }

    /// Bounding box.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.p)
    }

    fn local_hit(&self, ray: &Ray, tmax: f32, t: f32) -> LocalHit {
        // Recompute the barycentrics; the point is then interpolated, which keeps it on the triangle.
        let (b1, b2) = self.intersect_bary(ray, tmax.max(t * 1.0001 + f32::MIN_POSITIVE)).map_or_else(
            || {
                // The hit was found by this same test; fall back to projecting the point.
                let p = ray.at(t);
                let (b1, b2) = self.barycentrics(p);
                (b1, b2)
            },
            |h| (h.1, h.2),
        );
        let p = (1.0 - b1 - b2) * Vec3A::from(self.p[0]) + b1 * Vec3A::from(self.p[1]) + b2 * Vec3A::from(self.p[2]);
        LocalHit { p, n: self.normal(), uv: Vec2::new(b1, b2) }
    }

    /// Barycentrics `(b1, b2)` of a point in the triangle's plane.
    pub fn barycentrics(&self, p: Vec3A) -> (f32, f32) {
        let p0 = Vec3A::from(self.p[0]);
        let e1 = Vec3A::from(self.p[1]) - p0;
        let e2 = Vec3A::from(self.p[2]) - p0;
        let d = p - p0;
        let d11 = e1.dot(e1);
        let d12 = e1.dot(e2);
        let d22 = e2.dot(e2);
        let dp1 = d.dot(e1);
        let dp2 = d.dot(e2);
        let den = d11 * d22 - d12 * d12;
        if den == 0.0 {
            return (0.0, 0.0);
        }
        ((d22 * dp1 - d12 * dp2) / den, (d11 * dp2 - d12 * dp1) / den)
    }
}

impl Plane {
    /// Distance along `ray` to the hit in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let n = Vec3A::from(self.normal);
        let denom = n.dot(ray.d);
        if denom == 0.0 {
            return None;
        }
        let t = n.dot(Vec3A::from(self.point) - ray.o) / denom;
        (t > 0.0 && t < tmax).then_some(t)
    }

    /// Surface data at the hit; `uv` are coordinates in a tangent frame of the plane.
    pub fn local_hit(&self, p: Vec3A) -> LocalHit {
        let n = Vec3A::from(self.normal);
        let f = crate::math::Frame::from_normal(n);
        let d = p - Vec3A::from(self.point);
        // Project onto the plane: the point is then exactly on it, up to rounding.
        let p = p - n * d.dot(n);
        LocalHit { p, n, uv: Vec2::new(d.dot(f.s), d.dot(f.t)) }
    }
}

impl Shape {
    /// Bounding box.
    pub fn bounds(&self) -> Aabb {
        match self {
            Shape::Sphere(s) => {
                let r = Vec3::splat(s.radius);
                Aabb { min: s.center - r, max: s.center + r }
            }
            Shape::Rect(r) => Aabb::from_points(&[r.corner, r.corner + r.u, r.corner + r.v, r.corner + r.u + r.v]),
            Shape::Triangle(t) => t.bounds(),
        }
    }

    /// Distance along `ray` to the closest hit in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        match self {
            Shape::Sphere(s) => s.intersect(ray, tmax),
            Shape::Rect(r) => r.intersect(ray, tmax),
            Shape::Triangle(t) => t.intersect(ray, tmax),
        }
    }

    /// Surface data of the hit at distance `t` (found by [`Shape::intersect`] with the same `ray`).
    pub fn local_hit(&self, ray: &Ray, t: f32) -> LocalHit {
        let p = ray.at(t);
        match self {
            Shape::Sphere(s) => s.local_hit(p),
            Shape::Rect(r) => r.local_hit(p),
            Shape::Triangle(tri) => tri.local_hit(ray, f32::INFINITY, t),
        }
    }

    /// Surface area.
    pub fn area(&self) -> f32 {
        match self {
            Shape::Sphere(s) => 4.0 * std::f32::consts::PI * s.radius * s.radius,
            Shape::Rect(r) => r.area(),
            Shape::Triangle(t) => t.area(),
        }
    }

    /// A point uniformly distributed by area and its geometric normal.
    pub fn sample_area(&self, u: Vec2) -> (Vec3A, Vec3A) {
        match self {
            Shape::Sphere(s) => {
                let n = crate::math::uniform_sphere(u);
                (Vec3A::from(s.center) + n * s.radius, n)
            }
            Shape::Rect(r) => (Vec3A::from(r.corner) + u.x * Vec3A::from(r.u) + u.y * Vec3A::from(r.v), r.normal()),
            Shape::Triangle(t) => {
                let (b1, b2) = crate::math::uniform_triangle(u);
                let p = (1.0 - b1 - b2) * Vec3A::from(t.p[0]) + b1 * Vec3A::from(t.p[1]) + b2 * Vec3A::from(t.p[2]);
                (p, t.normal())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: [f32; 3], d: [f32; 3]) -> Ray {
        Ray::new(Vec3A::from_array(o), Vec3A::from_array(d).normalize())
    }

    #[test]
    fn sphere_hits_front_then_back() {
        let s = Sphere { center: Vec3::new(0.0, 0.0, 5.0), radius: 1.0 };
        let r = ray([0.0; 3], [0.0, 0.0, 1.0]);
        assert!((s.intersect(&r, f32::INFINITY).unwrap() - 4.0).abs() < 1e-5);
        let inside = ray([0.0, 0.0, 5.0], [0.0, 0.0, 1.0]);
        assert!((s.intersect(&inside, f32::INFINITY).unwrap() - 1.0).abs() < 1e-5);
        assert!(s.intersect(&ray([0.0, 2.0, 0.0], [0.0, 0.0, 1.0]), f32::INFINITY).is_none());
    }

    #[test]
    fn rect_from_center_faces_its_normal() {
        let r = Rect::from_center(Vec3::new(0.0, 2.0, 0.0), Vec3::NEG_Y, Vec3::X, 2.0, 1.0);
        assert!((r.normal() - Vec3A::NEG_Y).length() < 1e-6);
        assert!((r.area() - 2.0).abs() < 1e-6);
        assert!(r.intersect(&ray([0.9, 0.0, 0.4], [0.0, 1.0, 0.0]), f32::INFINITY).is_some());
        assert!(r.intersect(&ray([1.1, 0.0, 0.0], [0.0, 1.0, 0.0]), f32::INFINITY).is_none());
        assert!(r.intersect(&ray([0.0, 0.0, 0.6], [0.0, 1.0, 0.0]), f32::INFINITY).is_none());
    }

    #[test]
    fn triangle_hit_and_degenerate_miss() {
        let t = Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y);
        let h = t.intersect_bary(&ray([0.25, 0.25, 1.0], [0.0, 0.0, -1.0]), f32::INFINITY).unwrap();
        assert!((h.0 - 1.0).abs() < 1e-6 && (h.1 - 0.25).abs() < 1e-6 && (h.2 - 0.25).abs() < 1e-6);
        let d = Triangle::new(Vec3::ZERO, Vec3::X, 2.0 * Vec3::X);
        assert!(d.intersect(&ray([0.5, 0.0, 1.0], [0.0, 0.0, -1.0]), f32::INFINITY).is_none());
    }
}
