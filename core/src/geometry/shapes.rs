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
//! and, for that hit only, the surface data (`local_hit`): the point, with a bound on its rounding error, which
//! is what a ray leaving it is offset by (pbrt-v4 §6.8). No shape is hit by a ray whose origin lies within the
//! rounding error of its surface, so a ray offset by that bound never finds the surface it leaves.

use crate::math::fmath;
use crate::math::{Aabb, Ray, gamma};
use glam::{Vec2, Vec3, Vec3A, Vec3Swizzles};
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

/// Which axis of a ray's direction is the largest in magnitude: the watertight triangle test renames the axes
/// cyclically so that it becomes z (a cyclic renaming keeps the triangle's orientation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axes {
    /// x dominates: (x, y, z) become (y, z, x).
    X,
    /// y dominates: (x, y, z) become (z, x, y).
    Y,
    /// z dominates: no renaming.
    Z,
}

/// The part of the watertight ray–triangle test (Woop, Benthin and Wald 2013; pbrt-v4 §6.5.3) that depends on the
/// ray alone, done once per ray instead of once per triangle tested: the axis renaming and the shear that takes
/// the direction to +z.
#[derive(Clone, Copy, Debug)]
pub struct TriangleRay {
    /// Ray origin.
    pub o: Vec3A,
    /// The renaming that makes z the dominant axis of the direction.
    pub axes: Axes,
    /// `−d.x / d.z` after renaming (as `−d.x · (1/d.z)`).
    pub sx: f32,
    /// `−d.y / d.z` after renaming.
    pub sy: f32,
    /// `1 / d.z` after renaming.
    pub sz: f32,
}

impl TriangleRay {
    /// Prepares `ray`.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let ad = ray.d.abs();
        let (axes, d) = if ad.x > ad.y && ad.x > ad.z {
            (Axes::X, ray.d.yzx())
        } else if ad.y > ad.z {
            (Axes::Y, ray.d.zxy())
        } else {
            (Axes::Z, ray.d)
        };
        let sz = 1.0 / d.z;
        Self { o: ray.o, axes, sx: -d.x * sz, sy: -d.y * sz, sz }
    }
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
    /// A bound on the distance of each coordinate of `p` from the true surface point (absolute, per axis).
    pub p_error: Vec3A,
    /// Geometric unit normal, as defined by the shape (not flipped towards the ray).
    pub n: Vec3A,
    /// Surface parameters: `(u, v)` on rectangles, spheres and planes, barycentrics `(b1, b2)` on triangles.
    pub uv: Vec2,
    /// `∂p/∂u`: how the point moves per unit of `u` (scene units).
    pub dpdu: Vec3A,
    /// `∂p/∂v`.
    pub dpdv: Vec3A,
}

impl Sphere {
    /// Distance along `ray` to the closest hit in `(0, tmax)`.
    ///
    /// The numerically stable form of Haines et al. ("Precision Improvements for Ray/Sphere Intersection",
    /// Ray Tracing Gems, ch. 7), evaluated in f64. In f32 the term `|o − c|² − r²` loses everything when the
    /// origin lies on a large sphere: for a floor of radius 1000 it is a difference of two numbers near 10⁶
    /// whose f32 spacing is 0.06, so a shadow ray leaving the floor 10⁻⁶ above it found the floor again
    /// (acne, 30 % too dark). In f64 the differences of f32 inputs are exact and the products carry 29 more bits:
    /// the sign of `|o − c|² − r²` is right for an origin 10⁻⁶ off a sphere of radius 10⁶. f64 arithmetic is
    /// IEEE on every target, so every architecture gives the same `t`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let o = ray.o.to_array().map(f64::from);
        let d = ray.d.to_array().map(f64::from);
        let c = self.center.to_array().map(f64::from);
        let r = f64::from(self.radius);
        let f = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let a = dot(d, d);
        let b = -dot(f, d);
        // l: from the centre to the point of the line closest to it; r² − |l|² is the discriminant over a.
        let s = b / a;
        let l = [f[0] + s * d[0], f[1] + s * d[1], f[2] + s * d[2]];
        let disc = r * r - dot(l, l);
        if disc < 0.0 {
            return None;
        }
        let c_term = dot(f, f) - r * r;
        let q = b + b.signum() * (a * disc).sqrt();
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c_term / q, q / a) };
        let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        let tmax = f64::from(tmax);
        // A root that rounds to 0 in f32 is no hit: the ray starts on the surface.
        let hit = |t: f64| t > 0.0 && t < tmax && (t as f32) > 0.0;
        if hit(t0) {
            Some(t0 as f32)
        } else if hit(t1) {
            Some(t1 as f32)
        } else {
            None
        }
    }

    /// The hit of `ray` at distance `t`, projected onto the sphere in f64 so that its f32 coordinates are the
    /// surface point rounded once: within half an ulp of each coordinate of the true surface (`p_error`: that
    /// half ulp, γ(1)·|p|, plus the f64 rounding of `c + n·r`, a few 2⁻⁵³ of |c| + r). Projecting as `c + n·r`
    /// in f32 instead puts the point up to an ulp of |c| + r off the surface: 0.06 for a floor of radius 10⁶.
    fn local_hit(&self, ray: &Ray, t: f32) -> LocalHit {
        let o = ray.o.to_array().map(f64::from);
        let d = ray.d.to_array().map(f64::from);
        let c = self.center.to_array().map(f64::from);
        let t = f64::from(t);
        let v = [o[0] + t * d[0] - c[0], o[1] + t * d[1] - c[1], o[2] + t * d[2] - c[2]];
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        // A hit has |v| ≈ r > 0; the guard keeps a degenerate ray from dividing by zero.
        let unit = if len > 0.0 { v.map(|x| x / len) } else { [0.0, 1.0, 0.0] };
        let (p, p_error, n) = self.point_at(unit);
        let (uv, dpdu, dpdv) = self.uv_at(n);
        LocalHit { p, p_error, n, uv, dpdu, dpdv }
    }

    /// Longitude-latitude coordinates of the point with unit normal `n` and the partial derivatives of the
    /// point: `u = ½ − φ/2π` with `φ = atan2(n_z, n_x)`, `v = 1 − θ/π` with `θ = acos(n_y)`, so `v` runs from the
    /// south pole (−y, 0) to the north pole (+y, 1) and, seen from outside with +y up, `u` increases to the right
    /// (an image is upright and not mirrored). With `p = c + r(sin θ cos φ, cos θ, sin θ sin φ)`:
    /// `∂p/∂u = 2πr(n_z, 0, −n_x)` and `∂p/∂v = πr(−cos θ cos φ, sin θ, −cos θ sin φ)`, whose cross product points
    /// outwards (pbrt-v4 §6.2.2 with y as the polar axis).
    fn uv_at(&self, n: Vec3A) -> (Vec2, Vec3A, Vec3A) {
        use std::f32::consts::PI;
        let u = 0.5 - fmath::atan2(n.z, n.x) / (2.0 * PI);
        let v = 1.0 - fmath::acos(n.y.clamp(-1.0, 1.0)) / PI;
        let r = self.radius;
        let dpdu = Vec3A::new(n.z, 0.0, -n.x) * (2.0 * PI * r);
        let sin_theta = (n.x * n.x + n.z * n.z).sqrt();
        let dpdv = if sin_theta > 0.0 {
            let k = n.y / sin_theta;
            Vec3A::new(-k * n.x, sin_theta, -k * n.z) * (PI * r)
        } else {
            // At a pole any direction in the tangent plane will do.
            Vec3A::new(PI * r, 0.0, 0.0)
        };
        (Vec2::new(u, v), dpdu, dpdv)
    }

    /// The point `c + unit·r` of the sphere for an f64 unit vector, rounded once to f32, with its error bound
    /// and the normal.
    fn point_at(&self, unit: [f64; 3]) -> (Vec3A, Vec3A, Vec3A) {
        let c = self.center.to_array().map(f64::from);
        let r = f64::from(self.radius);
        let p = Vec3A::new((c[0] + unit[0] * r) as f32, (c[1] + unit[1] * r) as f32, (c[2] + unit[2] * r) as f32);
        let n = Vec3A::new(unit[0] as f32, unit[1] as f32, unit[2] as f32);
        // 2⁻⁵⁰ covers the f64 rounding of the unit vector (relative) and of c + unit·r, with room to spare.
        let f64_error = (Vec3A::from(self.center).abs() + Vec3A::splat(self.radius)) * (1.0 / 1_125_899_906_842_624.0);
        (p, gamma(1) * p.abs() + f64_error, n)
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
        fmath::normalize(Vec3A::from(self.u.cross(self.v)))
    }

    /// Area.
    pub fn area(&self) -> f32 {
        self.u.cross(self.v).length()
    }

    /// Distance along `ray` to the hit in `(0, tmax)`. A ray whose origin lies within the rounding error of the
    /// rectangle's plane does not hit it (see `plane_distance`).
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let u = Vec3A::from(self.u);
        let v = Vec3A::from(self.v);
        let nn = fmath::cross(u, v);
        // Bounds |nn| per axis whatever the cancellation in the cross product: |u|×|v| with plus signs.
        let (au, av) = (u.abs(), v.abs());
        let nn_abs = au.yzx() * av.zxy() + au.zxy() * av.yzx();
        let t = plane_distance(ray, Vec3A::from(self.corner), nn, nn_abs)?;
        if t >= tmax {
            return None;
        }
        let d = offset_from(ray, t, Vec3A::from(self.corner));
        let a = d.dot(u) / u.length_squared();
        let b = d.dot(v) / v.length_squared();
        ((0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b)).then_some(t)
    }

    fn local_hit(&self, ray: &Ray, t: f32) -> LocalHit {
        let u = Vec3A::from(self.u);
        let v = Vec3A::from(self.v);
        let c = Vec3A::from(self.corner);
        let d = offset_from(ray, t, c);
        let a = d.dot(u) / u.length_squared();
        let b = d.dot(v) / v.length_squared();
        // The error of `a` and `b` only slides the point within the plane.
        let (p, p_error) = self.point_at(a, b);
        LocalHit { p, p_error, n: self.normal(), uv: Vec2::new(a, b), dpdu: u, dpdv: v }
    }

    /// The point `corner + a·u + b·v` and its error bound: on the plane up to the rounding of two products and
    /// two sums.
    fn point_at(&self, a: f32, b: f32) -> (Vec3A, Vec3A) {
        let c = Vec3A::from(self.corner);
        let (au, bv) = (a * Vec3A::from(self.u), b * Vec3A::from(self.v));
        (c + au + bv, gamma(3) * (c.abs() + au.abs() + bv.abs()))
    }
}

/// The hit point of `ray` at distance `t` relative to the point `q` of a flat shape, as `(o − q) + t·d`: the
/// difference of two nearby points is exact (Sterbenz) or nearly, and the rest is small, so the result keeps
/// the precision of the shape's own size. Computing `o + t·d` first rounds it to the spacing of the
/// coordinates, 1/128 at 10⁵, which made the edges of a 0.5-wide light fuzzy by 1.5 % there.
#[inline]
fn offset_from(ray: &Ray, t: f32, q: Vec3A) -> Vec3A {
    (ray.o - q) + t * ray.d
}

/// The distance along `ray` to the plane through `q` with (not necessarily unit) normal `nn`, if it lies in
/// `(0, ∞)` and the origin is farther from the plane than the rounding error of the computation can explain.
///
/// `nn_abs` bounds `|nn|` per axis together with its own rounding (for a computed cross product). The
/// numerator `nn·(q − o)` is the origin's signed distance times `|nn|`; its rounding error is at most
/// γ(6)·(nn_abs·|q − o|) (the subtraction, the products, the sum, and the rounding of `nn`). When the
/// numerator is no larger than that, the origin may lie on the plane, and it is the surface the ray leaves
/// (pbrt-v4 §6.8.7 asks the same of triangles): no hit. A ray spawned off the plane by its hit's error bound
/// starts strictly on the side it leaves towards, so its numerator either has the true sign (the plane is
/// behind it) or lies within that bound (no hit): it never finds the plane again.
#[inline]
fn plane_distance(ray: &Ray, q: Vec3A, nn: Vec3A, nn_abs: Vec3A) -> Option<f32> {
    let denom = nn.dot(ray.d);
    if denom == 0.0 {
        return None;
    }
    let diff = q - ray.o;
    let num = nn.dot(diff);
    let t = num / denom;
    (t > 0.0 && num.abs() > gamma(6) * nn_abs.dot(diff.abs())).then_some(t)
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
        fmath::cross(e1, e2).normalize_or_zero()
    }

    /// Area.
    pub fn area(&self) -> f32 {
        0.5 * (self.p[1] - self.p[0]).cross(self.p[2] - self.p[0]).length()
    }

    /// Distance and barycentrics `(b1, b2)` of the hit in `(0, tmax)`, where the hit point is
    /// `(1 − b1 − b2)·p0 + b1·p1 + b2·p2`; either side of the triangle is hit.
    ///
    /// Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection" (JCGT 2(1), 2013), in the form of pbrt-v4
    /// (§6.5.3 and §6.8.7). The vertices move to a frame where the ray starts at the origin and runs along +z;
    /// there the test is the signs of three 2D edge functions. Triangles that share an edge compute that edge's
    /// function from the same rounded coordinates, so they get the same value with opposite signs: a ray through
    /// a shared edge or vertex hits at least one of them (watertight), and a triangle is hit only where the ray
    /// passes through it, up to rounding of its vertices, never far off it as Möller–Trumbore does with a tiny
    /// determinant. Zero-area triangles, non-finite vertices and hits within rounding error of the ray's origin
    /// are never hit.
    #[inline]
    pub fn intersect_bary(&self, ray: &Ray, tmax: f32) -> Option<(f32, f32, f32)> {
        self.intersect_prepared(&TriangleRay::new(ray), tmax)
    }

    /// [`Triangle::intersect_bary`] with the ray's part of the work done once by [`TriangleRay::new`]: the same
    /// operations on the same numbers, so the same result, bit for bit.
    #[inline]
    pub fn intersect_prepared(&self, ray: &TriangleRay, tmax: f32) -> Option<(f32, f32, f32)> {
        // Vertices relative to the ray origin, one vector per axis: lane i holds vertex i.
        let [p0, p1, p2] = self.p;
        let xs = Vec3A::new(p0.x, p1.x, p2.x) - ray.o.x;
        let ys = Vec3A::new(p0.y, p1.y, p2.y) - ray.o.y;
        let zs = Vec3A::new(p0.z, p1.z, p2.z) - ray.o.z;
        let (x, y, z) = match ray.axes {
            Axes::X => (ys, zs, xs),
            Axes::Y => (zs, xs, ys),
            Axes::Z => (xs, ys, zs),
        };
        // Shear so the ray runs along +z: x' = x − (dx/dz)·z, y' = y − (dy/dz)·z; z is scaled by 1/dz only for
        // a hit. A vertex shared by two triangles gets the same x', y' in both.
        let sz = ray.sz;
        let x = x + ray.sx * z;
        let y = y + ray.sy * z;

        // Edge functions: twice the signed area of the 2D triangle of the ray (the origin) and one edge; lane i
        // is for the edge opposite vertex i, e.g. `e.x = x1·y2 − y1·x2`. Plain products, not fused: then the
        // same edge in the other direction rounds to exactly the negation, which is what makes shared edges agree.
        let mut e = x.yzx() * y.zxy() - y.yzx() * x.zxy();
        if e.cmpeq(Vec3A::ZERO).any() {
            // Through an edge or vertex, or cancellation: decide in f64, where products of f32 are exact and the
            // difference is rounded once, so the sign is exact (unless it flushes to 0 in f32, below 1e-45).
            let edge =
                |i: usize, j: usize| (f64::from(x[i]) * f64::from(y[j]) - f64::from(y[i]) * f64::from(x[j])) as f32;
            e = Vec3A::new(edge(1, 2), edge(2, 0), edge(0, 1));
        }
        // The ray misses if the edge functions disagree in sign; zero (on an edge) agrees with either.
        if e.cmplt(Vec3A::ZERO).any() && e.cmpgt(Vec3A::ZERO).any() {
            return None;
        }
        // The determinant is twice the projected area. A finite one also means every coordinate above is finite.
        let det = e.x + e.y + e.z;
        if det == 0.0 || !det.is_finite() {
            return None;
        }

        // t = Σ ei·zi / det, with z scaled by 1/dz. Written so that NaN fails.
        let z = sz * z;
        let inv_det = 1.0 / det;
        let t = (e.x * z.x + e.y * z.y + e.z * z.z) * inv_det;
        if !(t > 0.0 && t < tmax) {
            return None;
        }

        // pbrt-v4 §6.8.7: bound the rounding error of t (γn bounds n rounded operations) and require t to exceed
        // it, so a surface at the ray's origin (the one the ray leaves) is not hit by rounding alone.
        let (max_x, max_y) = (x.abs().max_element(), y.abs().max_element());
        let (max_z, max_e) = (z.abs().max_element(), e.abs().max_element());
        let delta_x = gamma(5) * (max_x + max_z);
        let delta_y = gamma(5) * (max_y + max_z);
        let delta_z = gamma(3) * max_z;
        let delta_e = 2.0 * (gamma(2) * max_x * max_y + delta_y * max_x + delta_x * max_y);
        let delta_t = 3.0 * (gamma(3) * max_e * max_z + delta_e * max_z + delta_z * max_e) * inv_det.abs();
        if t <= delta_t {
            return None;
        }

        // A zero-area triangle can still get a tiny non-zero determinant from the rounding of the translation and
        // shear. Checked last, as few tests get this far.
        let v0 = Vec3A::from(p0);
        if fmath::cross(Vec3A::from(p1) - v0, Vec3A::from(p2) - v0) == Vec3A::ZERO {
            return None;
        }
        Some((t, e.y * inv_det, e.z * inv_det))
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
        let (p, p_error) = self.point_at(b1, b2);
        let p0 = Vec3A::from(self.p[0]);
        let (dpdu, dpdv) = (Vec3A::from(self.p[1]) - p0, Vec3A::from(self.p[2]) - p0);
        LocalHit { p, p_error, n: self.normal(), uv: Vec2::new(b1, b2), dpdu, dpdv }
    }

    /// The point at barycentrics `(b1, b2)` and its error bound.
    fn point_at(&self, b1: f32, b2: f32) -> (Vec3A, Vec3A) {
        let b0 = 1.0 - b1 - b2;
        let [t0, t1, t2] = [b0 * Vec3A::from(self.p[0]), b1 * Vec3A::from(self.p[1]), b2 * Vec3A::from(self.p[2])];
        // The interpolation rounds three products and two sums (pbrt-v4's γ(7)·Σ|bi·pi| covers them and the
        // barycentrics' own error); b0 = 1 − b1 − b2 in f32 makes the weights sum to 1 only within γ(2)·3, which
        // moves the point by that fraction of its distance from the origin: γ(6)·max|pi|.
        let max_p = Vec3A::from(self.p[0].abs().max(self.p[1].abs()).max(self.p[2].abs()));
        (t0 + t1 + t2, gamma(7) * (t0.abs() + t1.abs() + t2.abs()) + gamma(6) * max_p)
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
    /// Distance along `ray` to the hit in `(0, tmax)`. A ray whose origin lies within the rounding error of the
    /// plane does not hit it (see `plane_distance`).
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let n = Vec3A::from(self.normal);
        plane_distance(ray, Vec3A::from(self.point), n, n.abs()).filter(|&t| t < tmax)
    }

    /// Surface data of the hit of `ray` at distance `t`; `uv` are coordinates in a tangent frame of the plane.
    pub fn local_hit(&self, ray: &Ray, t: f32) -> LocalHit {
        let n = Vec3A::from(self.normal);
        let f = crate::math::Frame::from_normal(n);
        let q = Vec3A::from(self.point);
        let d = offset_from(ray, t, q);
        let (a, b) = (d.dot(f.s), d.dot(f.t));
        // The point of the plane at (a, b) in its frame: on the plane up to the rounding of two products and two
        // sums, and of the frame's tangents, which are perpendicular to n within a few ulps (γ(4) of a and b).
        let (sa, tb) = (a * f.s, b * f.t);
        let p = q + sa + tb;
        let p_error = gamma(3) * (q.abs() + sa.abs() + tb.abs()) + gamma(4) * (a.abs() + b.abs()) * n.abs();
        LocalHit { p, p_error, n, uv: Vec2::new(a, b), dpdu: f.s, dpdv: f.t }
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
        self.intersect_prepared(ray, &TriangleRay::new(ray), tmax)
    }

    /// [`Shape::intersect`] with `tri`, which is `TriangleRay::new(ray)`, prepared once for all the shapes a ray
    /// is tested against.
    #[inline]
    pub fn intersect_prepared(&self, ray: &Ray, tri: &TriangleRay, tmax: f32) -> Option<f32> {
        match self {
            Shape::Sphere(s) => s.intersect(ray, tmax),
            Shape::Rect(r) => r.intersect(ray, tmax),
            Shape::Triangle(t) => t.intersect_prepared(tri, tmax).map(|h| h.0),
        }
    }

    /// Surface data of the hit at distance `t` (found by [`Shape::intersect`] with the same `ray`).
    pub fn local_hit(&self, ray: &Ray, t: f32) -> LocalHit {
        match self {
            Shape::Sphere(s) => s.local_hit(ray, t),
            Shape::Rect(r) => r.local_hit(ray, t),
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
        let (p, _, n) = self.sample_area_with_error(u);
        (p, n)
    }

    /// A point uniformly distributed by area, the bound on its error (as [`LocalHit::p_error`]) and its
    /// geometric normal: what a ray leaving the point is offset by.
    pub fn sample_area_with_error(&self, u: Vec2) -> (Vec3A, Vec3A, Vec3A) {
        match self {
            Shape::Sphere(s) => {
                let d = crate::math::uniform_sphere(u).to_array().map(f64::from);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                s.point_at(d.map(|x| x / len))
            }
            Shape::Rect(r) => {
                let (p, e) = r.point_at(u.x, u.y);
                (p, e, r.normal())
            }
            Shape::Triangle(t) => {
                let (b1, b2) = crate::math::uniform_triangle(u);
                let (p, e) = t.point_at(b1, b2);
                (p, e, t.normal())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: [f32; 3], d: [f32; 3]) -> Ray {
        Ray::new(Vec3A::from_array(o), fmath::normalize(Vec3A::from_array(d)))
    }

    /// Closest hit of the line `o + t·d` with the sphere, from the textbook quadratic in f64 on the same f32
    /// inputs: far more precise than f32 for the cases below (its cancellation costs at most 10⁻⁸ relative).
    fn reference_t(s: &Sphere, r: &Ray) -> Option<f64> {
        let (o, d, c) = (r.o.as_dvec3(), r.d.as_dvec3(), Vec3A::from(s.center).as_dvec3());
        let f = o - c;
        let a = d.length_squared();
        let b = f.dot(d);
        let disc = b * b - a * (f.length_squared() - f64::from(s.radius).powi(2));
        (disc >= 0.0).then(|| (-b - disc.sqrt()) / a).filter(|&t| t > 0.0)
    }

    #[test]
    fn sphere_closest_hit_matches_f64_for_rays_from_far_away() {
        let mut rng = crate::math::rng::Sampler::new(7, crate::math::rng::Domain::Photon, 0, 0, 0);
        for radius in [1e-3f32, 1e-1, 1.0, 10.0, 1e3, 1e6] {
            for far in [2.0f32, 1e2, 1e4] {
                for k in 0..200 {
                    let center = Vec3::new(0.3, -radius, 0.7) * if k % 2 == 0 { 1.0 } else { 10.0 };
                    let s = Sphere { center, radius };
                    // From a point `far` radii away, towards a random point of the sphere's front half.
                    let dir = crate::math::uniform_sphere(rng.next_2d());
                    let o = Vec3A::from(center) + dir * (far * radius);
                    let target = Vec3A::from(center) + radius * crate::math::uniform_sphere(rng.next_2d());
                    let r = Ray::new(o, fmath::normalize(target - o));
                    let (Some(t), Some(t_ref)) = (s.intersect(&r, f32::INFINITY), reference_t(&s, &r)) else {
                        continue;
                    };
                    // The f32 result is the f64 root rounded once (half an ulp), plus the reference's own error.
                    let rel = (f64::from(t) - t_ref).abs() / t_ref;
                    assert!(rel < 1e-7, "r = {radius}, {far} radii away: t = {t}, reference {t_ref}, rel {rel:e}");
                    // The hit point lies on the sphere to within the rounding of its coordinates.
                    let hit = s.local_hit(&r, t);
                    let p = hit.p.as_dvec3();
                    let off = (p - Vec3A::from(center).as_dvec3()).length() - f64::from(radius);
                    let ulp = f64::from(p.abs().max_element() as f32) * f64::from(f32::EPSILON);
                    assert!(off.abs() <= 2.0 * ulp, "r = {radius}: {off:e} off the surface, ulp {ulp:e}");
                    // ... and within the error bound that spawned rays are offset by.
                    let bound = f64::from(hit.n.abs().dot(hit.p_error));
                    assert!(off.abs() <= bound, "r = {radius}: {off:e} off the surface, bound {bound:e}");
                }
            }
        }
    }

    #[test]
    fn ray_leaving_a_large_sphere_does_not_hit_it_again() {
        // A floor sphere of radius R under the origin; rays leave points of it upwards (the shadow rays of
        // issue 16) and must miss it.
        let mut rng = crate::math::rng::Sampler::new(9, crate::math::rng::Domain::Photon, 0, 0, 0);
        for radius in [10.0f32, 1e3, 1e4, 1e6] {
            let s = Sphere { center: Vec3::new(0.0, -radius, 0.0), radius };
            for _ in 0..1000 {
                let u = rng.next_2d();
                let down = Ray::new(Vec3A::new(4.0 * u.x - 2.0, 1.0, 4.0 * u.y - 2.0), Vec3A::NEG_Y);
                let t = s.intersect(&down, f32::INFINITY).unwrap();
                let hit = s.local_hit(&down, t);
                let w = crate::math::uniform_sphere(rng.next_2d());
                let w = if w.dot(hit.n) < 0.0 { -w } else { w };
                let o = crate::math::offset_ray_origin_by_error(hit.p, hit.p_error, hit.n, w);
                let up = Ray::new(o, w);
                assert_eq!(s.intersect(&up, f32::INFINITY), None, "R = {radius}: from {o} along {w}");
            }
        }
    }

    /// Rectangles, planes and triangles, at home, 10⁴ and 10⁵ units away and scaled by 10⁻³ and 10³: a hit point
    /// lies within its error bound of the exact surface (measured in f64), and a ray spawned from it by that
    /// bound, in any direction on either side, never hits the surface again.
    #[test]
    fn spawned_rays_never_hit_the_flat_surface_they_leave() {
        use crate::math::rng::{Domain, Sampler};
        use crate::math::{offset_ray_origin_by_error, uniform_sphere};
        let mut rng = Sampler::new(11, Domain::Photon, 0, 0, 0);
        let places = [
            (1.0f32, Vec3::ZERO),
            (1.0, Vec3::new(1e4, -1e4, 3e3)),
            (1.0, Vec3::splat(-1e5)),
            (1e-3, Vec3::ZERO),
            (1e3, Vec3::ZERO),
        ];
        for (scale, by) in places {
            let at = |p: Vec3| scale * p + by;
            let (a, b, c) =
                (at(Vec3::new(-1.0, 0.2, -0.7)), at(Vec3::new(1.3, -0.4, 0.1)), at(Vec3::new(-0.2, 0.9, 1.1)));
            let rect = Shape::Rect(Rect { corner: a, u: b - a, v: c - a });
            let tri = Shape::Triangle(Triangle::new(a, b, c));
            let plane = Plane { point: a, normal: (b - a).cross(c - a).normalize() };
            // The exact plane of the three points, in f64: unit normal and offset.
            let n64 = (b.as_dvec3() - a.as_dvec3()).cross(c.as_dvec3() - a.as_dvec3()).normalize();
            let plane_n = Vec3A::from(plane.normal).as_dvec3();
            let centre = Vec3A::from(at(Vec3::new(0.0, 0.3, 0.2)));
            let mut tested = 0;
            for _ in 0..3000 {
                let o = centre + 3.0 * scale * uniform_sphere(rng.next_2d());
                let target =
                    Vec3A::from(a) + rng.next_f32() * Vec3A::from(b - a) + rng.next_f32() * 0.9 * Vec3A::from(c - a);
                let ray = Ray::new(o, fmath::normalize(target - o));
                let w = uniform_sphere(rng.next_2d());
                for (name, hit, again, exact) in [
                    (
                        "rect",
                        rect.intersect(&ray, f32::INFINITY).map(|t| rect.local_hit(&ray, t)),
                        Box::new(|r: &Ray| rect.intersect(r, f32::INFINITY)) as Box<dyn Fn(&Ray) -> Option<f32>>,
                        n64,
                    ),
                    (
                        "triangle",
                        tri.intersect(&ray, f32::INFINITY).map(|t| tri.local_hit(&ray, t)),
                        Box::new(|r: &Ray| tri.intersect(r, f32::INFINITY)),
                        n64,
                    ),
                    (
                        "plane",
                        plane.intersect(&ray, f32::INFINITY).map(|t| plane.local_hit(&ray, t)),
                        Box::new(|r: &Ray| plane.intersect(r, f32::INFINITY)),
                        plane_n,
                    ),
                ] {
                    let Some(hit) = hit else { continue };
                    tested += 1;
                    let off = (hit.p.as_dvec3() - Vec3A::from(a).as_dvec3()).dot(exact);
                    let bound = f64::from(hit.n.abs().dot(hit.p_error));
                    assert!(off.abs() <= bound, "{name} ×{scale} at {by}: {off:e} off the plane, bound {bound:e}");
                    let spawned = Ray::new(offset_ray_origin_by_error(hit.p, hit.p_error, hit.n, w), w);
                    assert_eq!(again(&spawned), None, "{name} ×{scale} at {by}: {spawned:?} from {:?}", hit.p);
                }
            }
            assert!(tested > 6000, "{tested}");
        }
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

    #[test]
    fn triangle_hit_from_either_side_within_open_interval() {
        let t = Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y);
        let below = ray([0.25, 0.5, -2.0], [0.0, 0.0, 1.0]);
        assert_eq!(t.intersect_bary(&below, f32::INFINITY), Some((2.0, 0.25, 0.5)));
        // tmax is exclusive, and a triangle behind the origin is not hit.
        assert!(t.intersect(&below, 2.0).is_none());
        assert!(t.intersect(&ray([0.25, 0.5, 2.0], [0.0, 0.0, 1.0]), f32::INFINITY).is_none());
        // Barycentrics of a tilted triangle seen along an oblique ray interpolate the hit point.
        let t = Triangle::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, -1.0, 2.5), Vec3::new(-2.0, 0.5, 7.0));
        let p = 0.2 * Vec3A::from(t.p[0]) + 0.5 * Vec3A::from(t.p[1]) + 0.3 * Vec3A::from(t.p[2]);
        let o = Vec3A::new(-3.0, 5.0, 1.0);
        let (tt, b1, b2) = t.intersect_bary(&Ray::new(o, p - o), f32::INFINITY).unwrap();
        assert!((tt - 1.0).abs() < 1e-5 && (b1 - 0.5).abs() < 1e-5 && (b2 - 0.3).abs() < 1e-5);
    }

    /// Watertightness: a fan of six triangles around a shared vertex, tilted so no edge lies in an axis plane.
    /// Rays aimed at points of the shared edges, and at the shared vertex itself, all hit the fan, unless the
    /// surface folds over there as seen from the ray (the triangles at the target face opposite ways), where a
    /// ray can graze it.
    #[test]
    fn triangle_fan_has_no_cracks() {
        use crate::math::rng::{Domain, Sampler};
        let c = Vec3::new(0.3, -0.2, 0.1);
        let ring: Vec<Vec3> = (0..6)
            .map(|i| {
                let a = i as f32 * std::f32::consts::FRAC_PI_3 + 0.1;
                c + Vec3::new(fmath::cos(a), fmath::sin(a), 0.4 * fmath::sin(2.0 * a))
            })
            .collect();
        let fan: Vec<Triangle> = (0..6).map(|i| Triangle::new(c, ring[i], ring[(i + 1) % 6])).collect();
        let mut s = Sampler::new(1, Domain::Photon, 0, 0, 0);
        let mut tested = 0;
        for k in 0..60_000 {
            let (target, sharing) = if k % 10 == 0 {
                (c, &fan[..])
            } else {
                let e = k % 6;
                (c + (0.05 + 0.9 * s.next_f32()) * (ring[e] - c), &[fan[(e + 5) % 6], fan[e]][..])
            };
            let o = Vec3A::from(target) + 3.0 * crate::math::uniform_sphere(s.next_2d());
            let r = Ray::new(o, Vec3A::from(target) - o);
            let facing = sharing.iter().map(|t| t.normal().dot(r.d) > 0.0);
            if facing.clone().any(|f| f) && facing.clone().any(|f| !f) {
                continue;
            }
            tested += 1;
            assert!(fan.iter().any(|t| t.intersect(&r, f32::INFINITY).is_some()), "ray {k} slips through: {r:?}");
        }
        assert!(tested > 40_000, "{tested}");
    }

    #[test]
    fn zero_area_and_non_finite_triangles_are_never_hit() {
        use crate::math::rng::{Domain, Sampler};
        let (a, b) = (Vec3::new(0.1, 0.7, -0.3), Vec3::new(2.3, -1.1, 0.9));
        let mut tris = vec![
            Triangle::new(a, a, a),
            Triangle::new(a, b, b),
            Triangle::new(a, b, a),
            Triangle::new(b, a, a),
            // Exactly collinear, and exactly so in f32 too.
            Triangle::new(Vec3::new(0.5, 0.0, 1.0), Vec3::new(1.5, 2.0, 4.0), Vec3::new(2.5, 4.0, 7.0)),
        ];
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for i in 0..3 {
                for k in 0..3 {
                    let mut t = Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y);
                    t.p[i][k] = bad;
                    tris.push(t);
                }
            }
        }
        let mut s = Sampler::new(2, Domain::Photon, 0, 0, 0);
        for t in &tris {
            // Aim at points of the triangle's vertices' convex hull, where it has finite vertices.
            let finite: Vec<Vec3A> = t.p.iter().filter(|p| p.is_finite()).map(|&p| Vec3A::from(p)).collect();
            for _ in 0..2000 {
                let u = s.next_f32();
                let target = (1.0 - u) * finite[0] + u * finite[finite.len() - 1];
                let o = target + 3.0 * crate::math::uniform_sphere(s.next_2d());
                let r = Ray::new(o, target - o);
                assert!(t.intersect(&r, f32::INFINITY).is_none(), "{t:?} hit by {r:?}");
            }
        }
    }

    /// A ray that starts exactly on a triangle's plane (in exact arithmetic) never hits that triangle, though
    /// translating the vertices to its origin rounds: the conservative distance bound rejects such hits.
    #[test]
    fn triangle_is_not_hit_from_its_own_plane() {
        use crate::math::rng::{Domain, Sampler};
        // The plane z = x + y.
        let t = Triangle::new(Vec3::new(-1.0, -1.0, -2.0), Vec3::new(3.0, 0.0, 3.0), Vec3::new(0.0, 3.0, 3.0));
        let mut s = Sampler::new(3, Domain::Photon, 0, 0, 0);
        let mut tested = 0;
        while tested < 50_000 {
            let (x, y) = (s.next_f32(), s.next_f32());
            let z = x + y;
            if f64::from(x) + f64::from(y) != f64::from(z) {
                continue;
            }
            tested += 1;
            let r = Ray::new(Vec3A::new(x, y, z), crate::math::uniform_sphere(s.next_2d()));
            assert!(t.intersect(&r, f32::INFINITY).is_none(), "{r:?}");
        }
    }
}
