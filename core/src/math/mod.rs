//! Small geometric helpers: rays and boxes, orthonormal frames, floating-point error bounds and robust ray
//! offsets, sampling warps,
//! reflection, refraction and the Fresnel equations; the portable float functions ([`fmath`]) and the
//! deterministic random streams ([`rng`]).

pub mod fmath;
mod ray;
pub mod rng;

use glam::{Vec2, Vec3A};
pub use ray::{Aabb, Ray};
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// An orthonormal frame whose `n` axis is local +z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Local +x.
    pub s: Vec3A,
    /// Local +y.
    pub t: Vec3A,
    /// Local +z (the normal).
    pub n: Vec3A,
}

impl Frame {
    /// A frame around the unit vector `n` (Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 2017).
    pub fn from_normal(n: Vec3A) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3A::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }

    /// World to local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3A) -> Vec3A {
        Vec3A::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local to world coordinates.
    #[inline]
    pub fn to_world(&self, v: Vec3A) -> Vec3A {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// γ(n) = n·u / (1 − n·u), with u = 2⁻²⁴ the unit roundoff of f32: a bound on the relative error of `n`
/// successive rounded operations (Higham, "Accuracy and Stability of Numerical Algorithms", §3.1; pbrt-v4
/// §6.8.1).
pub const fn gamma(n: u8) -> f32 {
    let nu = n as f32 * (f32::EPSILON * 0.5);
    nu / (1.0 - nu)
}

/// The next `f32` towards +∞ (`x` itself for +∞ and NaN).
#[inline]
pub fn next_float_up(x: f32) -> f32 {
    if x.is_infinite() && x > 0.0 || x.is_nan() {
        return x;
    }
    let x = if x == 0.0 { 0.0 } else { x };
    let bits = x.to_bits();
    f32::from_bits(if x >= 0.0 { bits + 1 } else { bits - 1 })
}

/// The next `f32` towards −∞.
#[inline]
pub fn next_float_down(x: f32) -> f32 {
    -next_float_up(-x)
}

/// The origin of a ray leaving a surface point `p` towards `w`, moved off the surface far enough that the ray
/// cannot hit the surface it leaves (pbrt-v4 §6.8.6).
///
/// `p_error` bounds, per coordinate, how far the computed `p` may lie from the true surface point; `n` is the
/// geometric normal. The origin moves along `±n`, to `w`'s side, by `|n|·p_error`: the farthest the error box
/// around `p` reaches along the normal. The sum is then rounded outward (each moved coordinate one `f32`
/// further), so the rounding of the addition cannot bring it back inside the box. The offset is as small as the
/// computation of `p` allows: zero for a point computed exactly, a few ulps of the coordinates otherwise.
#[inline]
pub fn offset_ray_origin_by_error(p: Vec3A, p_error: Vec3A, n: Vec3A, w: Vec3A) -> Vec3A {
    let d = n.abs().dot(p_error);
    let offset = if w.dot(n) < 0.0 { -d * n } else { d * n };
    let po = (p + offset).to_array();
    let off = offset.to_array();
    Vec3A::from_array(std::array::from_fn(|i| {
        if off[i] > 0.0 {
            next_float_up(po[i])
        } else if off[i] < 0.0 {
            next_float_down(po[i])
        } else {
            po[i]
        }
    }))
}

/// Cosine-weighted direction on the local +z hemisphere (Malley's method); pdf = cos θ / π.
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3A {
    let d = concentric_disk(u);
    let z = (1.0 - d.x * d.x - d.y * d.y).max(0.0).sqrt();
    Vec3A::new(d.x, d.y, z)
}

/// Uniform direction on the unit sphere; pdf = 1 / (4π).
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3A {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3A::new(r * fmath::cos(phi), r * fmath::sin(phi), z)
}

/// Shirley–Chiu concentric map of the unit square onto the unit disc (area preserving).
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) =
        if o.x.abs() > o.y.abs() { (o.x, FRAC_PI_4 * (o.y / o.x)) } else { (o.y, FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y)) };
    r * Vec2::new(fmath::cos(theta), fmath::sin(theta))
}

/// Uniform point on a triangle as barycentrics (b1, b2) (Heitz's low-distortion map is not needed here).
#[inline]
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

/// Mirror reflection of `wo` about `n` (both pointing away from the surface).
#[inline]
pub fn reflect(wo: Vec3A, n: Vec3A) -> Vec3A {
    2.0 * wo.dot(n) * n - wo
}

/// Refraction of `wo` (pointing away from the surface, on the side of `n`) through a boundary with relative
/// index `eta` = η_transmitted / η_incident. Returns the transmitted direction (pointing away from the surface
/// on the other side), or `None` on total internal reflection.
#[inline]
pub fn refract(wo: Vec3A, n: Vec3A, eta: f32) -> Option<Vec3A> {
    let cos_i = wo.dot(n);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(-wo / eta + (cos_i / eta - cos_t) * n)
}

/// Fresnel reflectance of a dielectric boundary for unpolarised light: the mean of the exact s- and
/// p-polarised reflectances. `cos_i` is the cosine of the incident angle on the side of the surface the light
/// comes from (taken as its absolute value), and `eta` = η_transmitted / η_incident. Returns 1 under total
/// internal reflection.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.abs().min(1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (r_s * r_s + r_p * r_p)
}

/// Balance... the power heuristic with β = 2 (Veach, 1997) for two strategies with `nf` and `ng` samples.
#[inline]
pub fn power_heuristic(pdf_f: f32, pdf_g: f32) -> f32 {
    let f = pdf_f * pdf_f;
    let g = pdf_g * pdf_g;
    if f + g == 0.0 { 0.0 } else { f / (f + g) }
}

/// Luminance of a linear sRGB/Rec.709 colour.
#[inline]
pub fn luminance(c: crate::Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3A::Z, -Vec3A::Z, Vec3A::X, fmath::normalize(Vec3A::new(0.3, -0.5, 0.81))] {
            let f = Frame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-6 && f.s.dot(f.n).abs() < 1e-6 && f.t.dot(f.n).abs() < 1e-6);
            assert!((f.s.length() - 1.0).abs() < 1e-6 && (f.t.length() - 1.0).abs() < 1e-6);
            let v = Vec3A::new(0.2, 0.4, -0.7);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-6);
        }
    }

    #[test]
    fn fresnel_normal_incidence_and_total_internal_reflection() {
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        // Leaving glass: critical angle asin(1/1.5) ≈ 41.8°.
        let critical = fmath::asin(1.0f32 / 1.5);
        assert_eq!(fresnel_dielectric(fmath::cos(critical + 0.01), 1.0 / 1.5), 1.0);
        assert!(fresnel_dielectric(fmath::cos(critical - 0.01), 1.0 / 1.5) < 1.0);
        assert!(
            refract(Vec3A::new(fmath::sin(critical + 0.01), 0.0, fmath::cos(critical + 0.01)), Vec3A::Z, 1.0 / 1.5)
                .is_none()
        );
    }

    #[test]
    fn refraction_obeys_snell() {
        let theta_i = 0.6f32;
        let wo = Vec3A::new(fmath::sin(theta_i), 0.0, fmath::cos(theta_i));
        let wt = refract(wo, Vec3A::Z, 1.5).unwrap();
        assert!((wt.length() - 1.0).abs() < 1e-5);
        assert!(wt.z < 0.0);
        let sin_t = (wt.x * wt.x + wt.y * wt.y).sqrt();
        assert!((fmath::sin(theta_i) - 1.5 * sin_t).abs() < 1e-5);
    }

    #[test]
    fn error_offset_leaves_the_error_box_on_the_side_of_w() {
        let p = Vec3A::new(10_000.0, -3.0, 0.25);
        let err = Vec3A::new(1e-3, 2e-7, 1e-8);
        let n = fmath::normalize(Vec3A::new(0.1, 1.0, -0.2));
        for w in [n, -n] {
            let q = offset_ray_origin_by_error(p, err, n, w);
            // The whole error box around p lies behind the plane through q with normal n (on w's side).
            let reach = n.abs().dot(err);
            assert!((q - p).dot(n) * w.dot(n).signum() > reach * (1.0 - 1e-6), "{q} from {p}");
        }
        // An exact point is not moved.
        assert_eq!(offset_ray_origin_by_error(p, Vec3A::ZERO, n, n), p);
        assert_eq!(next_float_up(-0.0), f32::from_bits(1));
        assert_eq!(next_float_down(1.0), 1.0 - f32::EPSILON / 2.0);
        assert_eq!(next_float_up(-1.0), -1.0 + f32::EPSILON / 2.0);
    }
}
