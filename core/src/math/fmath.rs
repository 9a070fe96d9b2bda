//! The transcendental functions of rendering, the same to the bit on every machine.
//!
//! A strip must not depend on the worker that rendered it. `+ − × ÷` and `sqrt` are exact IEEE operations
//! everywhere, but `f32::tan`, `atan2` and `ln_1p` call the platform's C library, and aarch64 glibc's
//! versions round differently from x86-64's on a fraction of inputs (they use fused multiply-adds); other
//! C libraries, or other versions of one, may differ again. Everything a worker computes therefore goes
//! through these wrappers, which call the pure-Rust `libm` crate: one implementation, compiled from the same
//! source, without contraction into fused multiply-adds, on every target.
//!
//! The other half is glam's `Vec3A`, which is SSE2 on x86-64 and NEON on aarch64. Lane-wise arithmetic, `dot`,
//! `length`, `min`, `max` and `normalize_or_zero` compute the same operations in the same order on both, but
//! `normalize` divides by the length on SSE2 and multiplies by its reciprocal on NEON, and NEON's `cross`,
//! `lerp` and `mul_add` fuse a multiply with an add. [`normalize`] and [`cross`] below replace the first two
//! (`clippy.toml` forbids glam's), and nothing calls the others. glam's `scalar-math` feature would do the same
//! for every method, but costs 6–24 % of render speed on x86-64 (`docs/RESULTS.md`, "Cross-architecture
//! agreement"); the cost of these two is within noise.
//!
//! Built with fused multiply-adds enabled (`-C target-cpu=native` on most x86-64 machines), glam's SSE2 code
//! fuses too; [`MODE`] says so, and a coordinator warns when the workers of a render report different modes.

use glam::Vec3A;

/// The math mode of this build, reported by workers in `Hello`: strips agree to the bit across architectures
/// when the workers' modes are equal (and their build ids, which the coordinator checks first).
pub const MODE: &str = if cfg!(target_feature = "fma") { "portable libm, fused glam" } else { "portable" };

/// `x.sin()`.
#[inline]
pub fn sin(x: f32) -> f32 {
    libm::sinf(x)
}

/// `x.cos()`.
#[inline]
pub fn cos(x: f32) -> f32 {
    libm::cosf(x)
}

/// `x.tan()`.
#[inline]
pub fn tan(x: f32) -> f32 {
    libm::tanf(x)
}

/// `x.asin()`.
#[inline]
pub fn asin(x: f32) -> f32 {
    libm::asinf(x)
}

/// `x.acos()`.
#[inline]
pub fn acos(x: f32) -> f32 {
    libm::acosf(x)
}

/// `y.atan2(x)`.
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}

/// `x.exp()`.
#[inline]
pub fn exp(x: f32) -> f32 {
    libm::expf(x)
}

/// `x.ln_1p()`.
#[inline]
pub fn ln_1p(x: f32) -> f32 {
    libm::log1pf(x)
}

/// `x.cbrt()`.
#[inline]
pub fn cbrt(x: f32) -> f32 {
    libm::cbrtf(x)
}

/// `x.powf(y)`.
#[inline]
pub fn powf(x: f32, y: f32) -> f32 {
    libm::powf(x, y)
}

/// `v` scaled to unit length, as `v · (1 / |v|)` on every architecture (glam's SSE2 `normalize` divides by
/// `|v|` instead, which rounds differently).
#[inline]
pub fn normalize(v: Vec3A) -> Vec3A {
    v * (1.0 / v.length())
}

/// The cross product `a × b`, each component a difference of two rounded products (glam's NEON `cross` fuses the
/// second product into the subtraction).
#[inline]
pub fn cross(a: Vec3A, b: Vec3A) -> Vec3A {
    Vec3A::new(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // compares with the platform's versions
mod tests {
    use super::*;

    /// The wrappers are the functions they name, to within an ulp or two of the platform's (they are not
    /// meant to be more or less accurate, only the same everywhere).
    #[test]
    fn wrappers_agree_with_std_to_a_few_ulps() {
        let close = |a: f32, b: f32| (a - b).abs() <= 4.0 * f32::EPSILON * a.abs().max(b.abs()).max(1e-30);
        for i in 0..2000 {
            let x = i as f32 * 0.000_75 - 0.75; // [-0.75, 0.75)
            assert!(close(sin(x * 4.0), (x * 4.0).sin()), "sin {x}");
            assert!(close(cos(x * 4.0), (x * 4.0).cos()), "cos {x}");
            assert!(close(tan(x * 2.0), (x * 2.0).tan()), "tan {x}");
            assert!(close(asin(x), x.asin()), "asin {x}");
            assert!(close(acos(x), x.acos()), "acos {x}");
            assert!(close(atan2(x, 0.3 - x), x.atan2(0.3 - x)), "atan2 {x}");
            assert!(close(exp(x * 20.0), (x * 20.0).exp()), "exp {x}");
            assert!(close(ln_1p(x), x.ln_1p()), "ln_1p {x}");
            assert!(close(powf(x.abs() + 0.01, 37.5), (x.abs() + 0.01).powf(37.5)), "powf {x}");
        }
    }

    /// `normalize` gives unit vectors and `cross` the right-handed perpendicular, to rounding.
    #[test]
    fn normalize_and_cross_are_the_vector_operations() {
        let (a, b) = (Vec3A::new(0.3, -1.7, 2.2), Vec3A::new(-4.0, 0.5, 0.25));
        assert!((normalize(a).length() - 1.0).abs() < 2.0 * f32::EPSILON);
        assert!((normalize(a) - a / a.length()).abs().max_element() < 2.0 * f32::EPSILON);
        let c = cross(a, b);
        assert!(c.dot(a).abs() < 1e-5 && c.dot(b).abs() < 1e-5);
        assert_eq!(cross(Vec3A::X, Vec3A::Y), Vec3A::Z);
        assert!(
            (c.length() - a.length() * b.length() * (1.0 - (a.dot(b) / (a.length() * b.length())).powi(2)).sqrt())
                .abs()
                < 1e-5
        );
    }
}
