//! Rough surfaces: the Trowbridge–Reitz (GGX) microfacet distribution with visible-normal sampling, and the
//! two lobes built on it, a rough conductor and a rough dielectric.
//!
//! Everything here works in the local shading frame (normal on +z, `cos θ = w.z`), with unit directions that
//! point away from the surface. The distribution is isotropic with width `α`; the scene files write the
//! perceptual roughness `r` of glTF and Disney's model, `α = r²`.
//!
//! Sources:
//! - the distribution, its Smith masking `Λ` and the height-correlated masking-shadowing `G`: Heitz 2014,
//!   "Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", eqs. 72 and 99; pbrt-v4 §9.6;
//! - sampling the normals visible from `wo`: Heitz 2018, "Sampling the GGX Distribution of Visible Normals";
//! - the conductor and dielectric BSDFs, reflection and transmission with their Jacobians: Walter et al. 2007,
//!   "Microfacet Models for Refraction through Rough Surfaces", eqs. 20, 21, 38 and 41; pbrt-v4 §9.6–9.7.
//!
//! Only single scattering between microfacets is modelled: a rough lobe loses the light that the real surface
//! would scatter more than once among its facets (at `r = 1` about a third of it at grazing view). The loss is
//! charted in docs/RESULTS.md (`cargo test -p photon-core --lib microfacet::tests::furnace -- --nocapture`).

use crate::Rgb;
use crate::math::fmath;
use glam::{Vec2, Vec3A};
use std::f32::consts::PI;

/// Below this `α` a lobe is a perfect mirror or smooth glass: the distribution is too narrow for `f32` (its
/// peak `1/(πα²)` overflows the sample weights' precision long before), and the delta lobes are exact there.
pub const SMOOTH_ALPHA: f32 = 1e-3;

/// The isotropic Trowbridge–Reitz (GGX) distribution of microfacet normals, of width `alpha` (> 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrowbridgeReitz {
    /// The width `α = r²` (`r` the perceptual roughness), at least [`SMOOTH_ALPHA`].
    pub alpha: f32,
}

impl TrowbridgeReitz {
    /// The distribution for perceptual roughness `roughness` in `[0, 1]`: `α = roughness²`.
    pub fn from_roughness(roughness: f32) -> Self {
        Self { alpha: (roughness * roughness).max(SMOOTH_ALPHA) }
    }

    /// The density of microfacet normals `D(m)` per unit solid angle, projected: `∫ D(m) cos θm dm = 1`.
    /// `D(m) = 1 / (π α² cos⁴θm (1 + tan²θm / α²)²)`, written as `α² / (π (sin²θm + α² cos²θm)²)` with
    /// `sin²θm = m.x² + m.y²`: no division by `cos θm`, and no cancellation in `1 − cos²θm`, which in `f32`
    /// would cost a narrow lobe (`α² ~ 1e-5`) a percent of its peak. Zero below the horizon.
    #[inline]
    pub fn d(&self, m: Vec3A) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let t = (m.x * m.x + m.y * m.y) + a2 * (m.z * m.z);
        a2 / (PI * t * t)
    }

    /// Smith's auxiliary function `Λ(w) = (−1 + √(1 + α² tan²θ)) / 2` (Heitz 2014, eq. 72); 0 at normal
    /// incidence, ∞ in the tangent plane.
    #[inline]
    pub fn lambda(&self, w: Vec3A) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 == 0.0 {
            return f32::INFINITY;
        }
        let tan2 = (w.x * w.x + w.y * w.y) / cos2;
        0.5 * ((1.0 + self.alpha * self.alpha * tan2).sqrt() - 1.0)
    }

    /// The masking function `G1(w) = 1 / (1 + Λ(w))`: the fraction of the facets facing `w` that `w` sees.
    #[inline]
    pub fn g1(&self, w: Vec3A) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// The height-correlated masking-shadowing function `G(wo, wi) = 1 / (1 + Λ(wo) + Λ(wi))` (Heitz 2014,
    /// eq. 99). Symmetric in its arguments.
    #[inline]
    pub fn g(&self, wo: Vec3A, wi: Vec3A) -> f32 {
        // `1 + (Λo + Λi)`: the same bits whichever direction is `wo`, so that a BSDF built on it is exactly
        // reciprocal.
        1.0 / (1.0 + (self.lambda(wo) + self.lambda(wi)))
    }

    /// The density of the normals visible from `w` (`w.z > 0`), per unit solid angle of `m`:
    /// `D_w(m) = G1(w) · max(0, w·m) · D(m) / cos θw` (Heitz 2018, eq. 1). It integrates to 1.
    #[inline]
    pub fn visible_d(&self, w: Vec3A, m: Vec3A) -> f32 {
        if w.z <= 0.0 {
            return 0.0;
        }
        self.g1(w) * w.dot(m).max(0.0) * self.d(m) / w.z
    }

    /// A microfacet normal drawn from [`TrowbridgeReitz::visible_d`] for `w` (`w.z > 0`): Heitz 2018, the
    /// hemisphere stretched to the unit configuration, a point on its projected disc, and back.
    pub fn sample_visible(&self, w: Vec3A, u: Vec2) -> Vec3A {
        let a = self.alpha;
        // The view direction in the configuration where the distribution is the uniform hemisphere.
        let vh = fmath::normalize(Vec3A::new(a * w.x, a * w.y, w.z));
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 { Vec3A::new(-vh.y, vh.x, 0.0) * (1.0 / len2.sqrt()) } else { Vec3A::X };
        let t2 = fmath::cross(vh, t1);
        // A uniform point on the disc, squeezed onto the part of it that `vh` sees.
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * fmath::cos(phi);
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * (r * fmath::sin(phi));
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        fmath::normalize(Vec3A::new(a * nh.x, a * nh.y, nh.z.max(1e-6)))
    }
}

/// How a conductor reflects, per colour channel, at the cosine `c` between the view and the facet normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConductorFresnel {
    /// The exact Fresnel reflectance of a conductor of complex index of refraction `eta + i·k` (relative to
    /// the outside medium), per channel.
    Complex {
        /// Real part of the index of refraction.
        eta: Rgb,
        /// Imaginary part (the absorption coefficient).
        k: Rgb,
    },
    /// Schlick's approximation `F0 + (1 − F0)(1 − c)⁵` with the reflectance `f0` at normal incidence: the glTF
    /// metallic model, whose base colour is `F0` (glTF 2.0 specification, appendix B.3.2).
    Schlick {
        /// Reflectance at normal incidence, in `[0, 1]`.
        f0: Rgb,
    },
}

impl ConductorFresnel {
    /// The reflectance at cosine `c` (its absolute value, clamped to 1), per channel.
    pub fn eval(&self, c: f32) -> Rgb {
        let c = c.abs().min(1.0);
        match *self {
            ConductorFresnel::Complex { eta, k } => {
                Rgb::new(fresnel_complex(c, eta.x, k.x), fresnel_complex(c, eta.y, k.y), fresnel_complex(c, eta.z, k.z))
            }
            ConductorFresnel::Schlick { f0 } => {
                let m = 1.0 - c;
                let m5 = (m * m) * (m * m) * m;
                f0 + (Rgb::ONE - f0) * m5
            }
        }
    }
}

/// The unpolarised Fresnel reflectance of a conductor of complex relative index `eta + i·k` at incident cosine
/// `cos_i` in `[0, 1]`, in real arithmetic and square roots only (so the same bits on every architecture):
/// pbrt-v3 §8.2.1's `FrConductor`, after Lazányi and Szirmay-Kalos 2005.
pub fn fresnel_complex(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let (eta2, k2) = (eta * eta, k * k);
    let t0 = eta2 - k2 - sin2;
    let a2_plus_b2 = (t0 * t0 + 4.0 * eta2 * k2).sqrt();
    let t1 = a2_plus_b2 + cos2;
    let a = (0.5 * (a2_plus_b2 + t0)).max(0.0).sqrt();
    let t2 = 2.0 * cos_i * a;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = cos2 * a2_plus_b2 + sin2 * sin2;
    let t4 = t2 * sin2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    let r = 0.5 * (rp + rs);
    if r.is_finite() { r.clamp(0.0, 1.0) } else { 1.0 }
}

/// A lobe sampled in the local frame: the direction, its BSDF value (no cosine), its solid-angle density, and
/// for a refraction the relative index of the side it enters over the side of `wo` (1 for a reflection).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalSample {
    /// The sampled direction, local frame.
    pub wi: Vec3A,
    /// The BSDF value at (`wo`, `wi`).
    pub f: Rgb,
    /// The solid-angle density of `wi`.
    pub pdf: f32,
    /// η of `wi`'s side over η of `wo`'s side; 1 for a reflection.
    pub eta: f32,
}

/// The rough conductor: `f = D(h) F(wo·h) G(wo, wi) / (4 |cos θo| |cos θi|)` with `h` the half vector
/// (Walter et al. 2007, eq. 20). It reflects on the side of the shading normal that `wo` lies on (both sides of
/// a two-sided surface) and is zero for a pair on opposite sides of it.
pub fn conductor_f(dist: &TrowbridgeReitz, fresnel: &ConductorFresnel, wo: Vec3A, wi: Vec3A) -> Rgb {
    let Some((wo, wi)) = upper(wo, wi) else { return Rgb::ZERO };
    let h = wo + wi;
    if h == Vec3A::ZERO {
        return Rgb::ZERO;
    }
    let h = fmath::normalize(h);
    // `wo·h = wi·h` for a reflection; their mean keeps the rounding the same both ways (exact reciprocity).
    fresnel.eval(0.5 * (wo.dot(h) + wi.dot(h))) * (dist.d(h) * dist.g(wo, wi) / (4.0 * wo.z * wi.z))
}

/// The density with which [`conductor_sample`] draws `wi`: `D_wo(h) / (4 |wo·h|)` (the visible normals, times
/// the Jacobian of reflection, Walter et al. 2007, eq. 14).
pub fn conductor_pdf(dist: &TrowbridgeReitz, wo: Vec3A, wi: Vec3A) -> f32 {
    let Some((wo, wi)) = upper(wo, wi) else { return 0.0 };
    let h = wo + wi;
    if h == Vec3A::ZERO {
        return 0.0;
    }
    let h = fmath::normalize(h);
    dist.visible_d(wo, h) / (4.0 * wo.dot(h))
}

/// Draws `wi` for `wo` by reflecting it about a visible microfacet normal. `None` when the reflection falls
/// below the horizon (the light the single-scattering model loses) or `wo` lies in the tangent plane.
pub fn conductor_sample(dist: &TrowbridgeReitz, fresnel: &ConductorFresnel, wo: Vec3A, u: Vec2) -> Option<LocalSample> {
    let flip = wo.z < 0.0;
    let wo_u = if flip { Vec3A::new(wo.x, wo.y, -wo.z) } else { wo };
    if wo_u.z == 0.0 {
        return None;
    }
    let h = dist.sample_visible(wo_u, u);
    let wi_u = crate::math::reflect(wo_u, h);
    if wi_u.z <= 0.0 {
        return None;
    }
    let pdf = dist.visible_d(wo_u, h) / (4.0 * wo_u.dot(h));
    let f = fresnel.eval(wo_u.dot(h)) * (dist.d(h) * dist.g(wo_u, wi_u) / (4.0 * wo_u.z * wi_u.z));
    let wi = if flip { Vec3A::new(wi_u.x, wi_u.y, -wi_u.z) } else { wi_u };
    (pdf > 0.0 && pdf.is_finite()).then_some(LocalSample { wi, f, pdf, eta: 1.0 })
}

/// `wo` and `wi` moved together to the upper hemisphere (both z negated when `wo.z < 0`), or `None` when they
/// lie on opposite sides of the shading plane or either lies in it.
#[inline]
fn upper(wo: Vec3A, wi: Vec3A) -> Option<(Vec3A, Vec3A)> {
    if wo.z * wi.z <= 0.0 {
        return None;
    }
    if wo.z < 0.0 { Some((Vec3A::new(wo.x, wo.y, -wo.z), Vec3A::new(wi.x, wi.y, -wi.z))) } else { Some((wo, wi)) }
}

/// The rough dielectric BSDF (Walter et al. 2007, eqs. 20–21; pbrt-v4 §9.7.2) for a boundary of relative index
/// `eta` (the side below the shading plane over the side above), with `h` the generalised half vector and
/// `etap` = η of `wi`'s side over η of `wo`'s:
/// - reflection: `D G F / (4 |cos θo cos θi|)`;
/// - refraction: `D G (1 − F) |wi·h| |wo·h| / (|cos θo cos θi| (wi·h + wo·h / etap)²)`, divided by `etap²`
///   for radiance transport (`radiance`), since radiance is compressed into a narrower cone on entering a
///   denser medium. Without that factor (importance: photons, light subpaths) it is the adjoint, and the pair
///   obeys `f_radiance(wo, wi) = f_importance(wi, wo)` (Veach 1997, §5.2).
pub fn dielectric_f(dist: &TrowbridgeReitz, eta: f32, wo: Vec3A, wi: Vec3A, radiance: bool) -> f32 {
    let Some((h, _, fr)) = dielectric_pair(eta, wo, wi) else { return 0.0 };
    if wo.z * wi.z > 0.0 {
        return dist.d(h) * dist.g(wo, wi) * fr / (4.0 * (wo.z * wi.z).abs());
    }
    // Refraction, written in the pair's own order, `a` outside and `b` inside, so that the value does not
    // depend on which of them is `wo`: every f32 operation is the same both ways and reciprocity is exact.
    // With `c = b·h + a·h/η`, `T = D·G·(1 − F)·|a·h·b·h| / |a.z·b.z·c²|`; from outside (`wo = a`, `etap = η`)
    // pbrt-v4's denominator is `c` and the value `T`, from inside (`etap = 1/η`) it is `η·c` and the value
    // `T/η²`; radiance divides either by `etap²`.
    let outside = wo.z > 0.0;
    let (a, b) = if outside { (wo, wi) } else { (wi, wo) };
    let c = b.dot(h) + a.dot(h) / eta;
    let t = dist.d(h) * dist.g(a, b) * (1.0 - fr) * (a.dot(h) * b.dot(h) / (a.z * b.z * c * c)).abs();
    // The 1/η² appears for radiance leaving through the outside and for importance leaving through the inside.
    if radiance == outside { t / (eta * eta) } else { t }
}

/// The density with which [`dielectric_sample`] draws `wi`: the visible-normal density of the half vector,
/// times the Jacobian of reflection or refraction (Walter et al. 2007, eqs. 14 and 17), times the Fresnel
/// probability of that event.
pub fn dielectric_pdf(dist: &TrowbridgeReitz, eta: f32, wo: Vec3A, wi: Vec3A) -> f32 {
    let Some((h, etap, fr)) = dielectric_pair(eta, wo, wi) else { return 0.0 };
    // The facet that faces wo is ±h; its visible density depends on |wo·h|, cos θh and |cos θo| only.
    let visible = dist.g1(wo) * wo.dot(h).abs() * dist.d(h) / wo.z.abs();
    if wo.z * wi.z > 0.0 {
        visible / (4.0 * wo.dot(h).abs()) * fr
    } else {
        let denom = wi.dot(h) + wo.dot(h) / etap;
        visible * (wi.dot(h).abs() / (denom * denom)) * (1.0 - fr)
    }
}

/// What a rough dielectric pair has in common for its value and density: the generalised half vector turned to
/// the upper hemisphere (Walter et al. 2007, eq. 16: `wo + etap·wi`), `etap` (1 for a reflection) and the
/// facet's Fresnel reflectance seen from `wo`. `None` for a direction in the shading plane, a vanishing half
/// vector, or a facet that would show its back to `wo` or `wi`: such pairs carry no light.
#[inline]
fn dielectric_pair(eta: f32, wo: Vec3A, wi: Vec3A) -> Option<(Vec3A, f32, f32)> {
    if wo.z == 0.0 || wi.z == 0.0 {
        return None;
    }
    let reflection = wo.z * wi.z > 0.0;
    let etap = if reflection {
        1.0
    } else if wo.z > 0.0 {
        eta
    } else {
        1.0 / eta
    };
    // A refraction's half vector and Fresnel term are computed from the outside direction `a` and the inside
    // one `b` (`a + η·b`, Fresnel seen from `a`), whichever is `wo`; a reflection's from `wo + wi` and the mean
    // of `wo·h` and `wi·h` (equal in exact arithmetic). So the same bits come out both ways: near total internal
    // reflection Fresnel's slope is unbounded, and the rounding of one cosine or the other would show.
    let (a, b, scale) = if reflection || wo.z > 0.0 { (wo, wi, etap) } else { (wi, wo, eta) };
    let h = a + scale * b;
    if h.length_squared() == 0.0 {
        return None;
    }
    let h = fmath::normalize(h);
    let h = if h.z < 0.0 { -h } else { h };
    if h.dot(wi) * wi.z < 0.0 || h.dot(wo) * wo.z < 0.0 {
        return None;
    }
    // Fresnel with the relative index of the facet's far side over `a`'s side.
    let eta_a = if a.z > 0.0 { eta } else { 1.0 / eta };
    let cos = if reflection { 0.5 * (a.dot(h) + b.dot(h)) } else { a.dot(h) };
    Some((h, etap, crate::math::fresnel_dielectric(cos, eta_a)))
}

/// Draws `wi` for `wo` at a rough dielectric: a visible facet normal, then reflection with the facet's Fresnel
/// probability or refraction through it. `u` chooses the event, `u2` the facet. `None` when the sampled
/// direction lands on the wrong side (the single-scattering loss) or `wo` lies in the tangent plane.
pub fn dielectric_sample(
    dist: &TrowbridgeReitz,
    eta: f32,
    wo: Vec3A,
    u: f32,
    u2: Vec2,
    radiance: bool,
) -> Option<LocalSample> {
    if wo.z == 0.0 {
        return None;
    }
    let flip = wo.z < 0.0;
    let wo_u = if flip { Vec3A::new(wo.x, wo.y, -wo.z) } else { wo };
    // The facet normal, drawn in the mirrored frame where wo is above, then taken back: it faces wo.
    let h_u = dist.sample_visible(wo_u, u2);
    let h = if flip { Vec3A::new(h_u.x, h_u.y, -h_u.z) } else { h_u };
    let eta_o = if flip { 1.0 / eta } else { eta };
    let c = wo.dot(h);
    let fr = crate::math::fresnel_dielectric(c, eta_o);
    let wi = if u < fr {
        let wi = crate::math::reflect(wo, h);
        if wi.z * wo.z <= 0.0 {
            return None;
        }
        wi
    } else {
        let wi = crate::math::refract(wo, h, eta_o)?;
        if wi.z * wo.z >= 0.0 {
            return None;
        }
        wi
    };
    let pdf = dielectric_pdf(dist, eta, wo, wi);
    let f = dielectric_f(dist, eta, wo, wi, radiance);
    let etap = if wi.z * wo.z > 0.0 { 1.0 } else { eta_o };
    (pdf > 0.0 && pdf.is_finite() && f > 0.0).then_some(LocalSample { wi, f: Rgb::splat(f), pdf, eta: etap })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::mix64;

    /// Independent uniform numbers from a counter hashed by SplitMix64.
    struct Uniform(u64);

    impl Uniform {
        fn next_f32(&mut self) -> f32 {
            self.0 += 1;
            (mix64(self.0) >> 40) as f32 * (1.0 / (1u32 << 24) as f32)
        }

        fn next_2d(&mut self) -> Vec2 {
            Vec2::new(self.next_f32(), self.next_f32())
        }
    }

    /// A unit direction at polar angle `theta` and azimuth `phi`.
    fn dir(theta: f32, phi: f32) -> Vec3A {
        Vec3A::new(fmath::sin(theta) * fmath::cos(phi), fmath::sin(theta) * fmath::sin(phi), fmath::cos(theta))
    }

    /// Visits quadrature points of the sphere with their solid angles: a midpoint rule in polar coordinates
    /// about `centre`, with polar angle `θ = π t²` for uniform `t`, so that the rings crowd near `centre`
    /// (where a narrow lobe peaks: the first ring is about 1e-6 rad wide) and are at most `2π/n` wide elsewhere;
    /// `2n` sectors. Only points that `keep` accepts are visited.
    fn quadrature(centre: Vec3A, n: usize, keep: impl Fn(Vec3A) -> bool, mut visit: impl FnMut(Vec3A, f64)) {
        let frame = crate::math::Frame::from_normal(centre);
        let dphi = std::f64::consts::TAU / (2 * n) as f64;
        for i in 0..n {
            let t = (i as f64 + 0.5) / n as f64;
            let theta = std::f64::consts::PI * t * t;
            let dtheta = std::f64::consts::TAU * t / n as f64;
            let ring = theta.sin() * dtheta * dphi;
            for j in 0..2 * n {
                let phi = (j as f64 + 0.5) * dphi;
                let local =
                    Vec3A::new((theta.sin() * phi.cos()) as f32, (theta.sin() * phi.sin()) as f32, theta.cos() as f32);
                let w = frame.to_world(local);
                if keep(w) {
                    visit(w, ring);
                }
            }
        }
    }

    /// `∫ g(w) dω` over the points of the sphere that `keep` accepts, by [`quadrature`] about `centre`, in f64.
    fn integrate(centre: Vec3A, keep: impl Fn(Vec3A) -> bool, mut g: impl FnMut(Vec3A) -> f32) -> f64 {
        let mut sum = 0.0;
        quadrature(centre, 600, keep, |w, dw| sum += f64::from(g(w)) * dw);
        sum
    }

    /// The peaks of a lobe seen from `wo`: the mirror direction, and for a dielectric of index `eta` the
    /// refracted one (or the mirror direction again under total internal reflection).
    fn peaks(wo: Vec3A, eta: f32) -> (Vec3A, Vec3A) {
        let mirror = Vec3A::new(-wo.x, -wo.y, wo.z);
        let n = if wo.z > 0.0 { Vec3A::Z } else { -Vec3A::Z };
        let eta_o = if wo.z > 0.0 { eta } else { 1.0 / eta };
        (mirror, crate::math::refract(wo, n, eta_o).unwrap_or(-mirror))
    }

    /// `∫ g dω` for a lobe that reflects (about the mirror direction) and may transmit: each hemisphere about
    /// its own peak.
    fn integrate_lobes(wo: Vec3A, eta: f32, g: impl Fn(Vec3A) -> f32) -> f64 {
        let (mirror, refracted) = peaks(wo, eta);
        integrate(mirror, |w| w.z * wo.z > 0.0, &g) + integrate(refracted, |w| w.z * wo.z < 0.0, &g)
    }

    fn sampler(seed: u64) -> Uniform {
        Uniform(seed << 40)
    }

    const ROUGHNESSES: [f32; 6] = [0.05, 0.1, 0.2, 0.4, 0.7, 1.0];

    #[test]
    fn the_distribution_and_its_visible_normals_are_normalised() {
        for r in [0.1f32, 0.3, 0.6, 1.0] {
            let dist = TrowbridgeReitz::from_roughness(r);
            // Narrow lobes need fine rings near the pole: integrate D cos θ in cos θ itself.
            let projected = integrate(Vec3A::Z, |_| true, |m| dist.d(m) * m.z.max(0.0));
            assert!((projected - 1.0).abs() < 2e-3, "r = {r}: ∫ D cos θ = {projected}");
            for theta in [0.0f32, 0.7, 1.3, 1.55] {
                let wo = dir(theta, 0.4);
                let visible = integrate(Vec3A::Z, |_| true, |m| dist.visible_d(wo, m));
                assert!((visible - 1.0).abs() < 3e-3, "r = {r}, θo = {theta}: ∫ D_wo = {visible}");
            }
        }
    }

    /// The conductor with F = 1 in a white furnace: the directional albedo `∫ f cos θi dωi` never exceeds 1,
    /// and what it loses is the single-scattering loss, which grows with roughness and at grazing view. The
    /// quadrature and the sampler's estimate `E[f cos/pdf]` agree, so sampling is unbiased. Prints the table
    /// that docs/RESULTS.md charts (`-- --nocapture`).
    #[test]
    fn furnace_conductor_loses_energy_only_to_single_scattering() {
        let white = ConductorFresnel::Schlick { f0: Rgb::ONE };
        let mut rng = sampler(1);
        println!("furnace: rough conductor, F = 1: albedo by roughness (rows) and cos θo (columns 1, 0.5, 0.1)");
        for r in ROUGHNESSES {
            let dist = TrowbridgeReitz::from_roughness(r);
            let mut row = Vec::new();
            for cos_o in [1.0f32, 0.5, 0.1] {
                let wo = Vec3A::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
                let quadrature = integrate_lobes(wo, 1.0, |wi| conductor_f(&dist, &white, wo, wi).x * wi.z.abs());
                let sampled = sampled_albedo(|| conductor_sample(&dist, &white, wo, rng.next_2d()));
                assert!(quadrature <= 1.0 + 3e-3, "r = {r}, cos θo = {cos_o}: albedo {quadrature} > 1");
                assert!((sampled - quadrature).abs() < 0.01, "r = {r}: sampled {sampled} vs {quadrature}");
                row.push(quadrature);
            }
            // Smooth lobes lose almost nothing; rough ones at grazing view lose the most.
            if r <= 0.1 {
                assert!(row[0] > 0.99 && row[1] > 0.99, "r = {r}: {row:?}");
            }
            println!("furnace r = {r:4}: {:.4} {:.4} {:.4}", row[0], row[1], row[2]);
        }
    }

    /// The mean of `f·|cos θi|/pdf` over 200 000 draws of `draw` (a `None` counts 0): the sampled albedo.
    fn sampled_albedo(mut draw: impl FnMut() -> Option<LocalSample>) -> f64 {
        let n = 200_000;
        (0..n).filter_map(|_| draw()).map(|s| f64::from(s.f.x * s.wi.z.abs() / s.pdf)).sum::<f64>() / n as f64
    }

    /// The rough dielectric conserves flux: reflected plus transmitted importance-mode albedo is at most 1, and
    /// close to 1 for smooth lobes, from outside and from inside; the sampler agrees with the quadrature.
    #[test]
    fn furnace_dielectric_reflects_and_transmits_at_most_what_arrives() {
        let mut rng = sampler(2);
        println!("furnace: rough dielectric η = 1.5, flux albedo by roughness (rows), cos θo 0.9 / 0.4, out / in");
        for r in ROUGHNESSES {
            let dist = TrowbridgeReitz::from_roughness(r);
            let mut row = Vec::new();
            for (cos_o, side) in [(0.9f32, 1.0f32), (0.4, 1.0), (0.9, -1.0), (0.4, -1.0)] {
                let wo = Vec3A::new((1.0 - cos_o * cos_o).sqrt(), 0.0, side * cos_o);
                let quadrature = integrate_lobes(wo, 1.5, |wi| dielectric_f(&dist, 1.5, wo, wi, false) * wi.z.abs());
                let sampled =
                    sampled_albedo(|| dielectric_sample(&dist, 1.5, wo, rng.next_f32(), rng.next_2d(), false));
                assert!(quadrature <= 1.0 + 5e-3, "r = {r}, {wo}: albedo {quadrature} > 1");
                assert!((sampled - quadrature).abs() < 0.015, "r = {r}, {wo}: sampled {sampled} vs {quadrature}");
                row.push(quadrature);
            }
            if r <= 0.1 {
                assert!(row.iter().all(|&a| a > 0.98), "r = {r}: {row:?}");
            }
            println!("furnace r = {r:4}: {:.4} {:.4} | {:.4} {:.4}", row[0], row[1], row[2], row[3]);
        }
    }

    /// Reciprocity: the conductor is symmetric, and the rough dielectric's radiance BSDF is the adjoint of its
    /// importance BSDF, `f_radiance(wo, wi) = f_importance(wi, wo)` (Veach 1997, §5.2), in reflection and in
    /// transmission, from both sides.
    #[test]
    fn the_lobes_are_reciprocal() {
        let mut rng = sampler(3);
        let fresnel = ConductorFresnel::Complex { eta: Rgb::new(0.14, 0.37, 1.44), k: Rgb::new(3.98, 2.39, 1.60) };
        let mut checked = 0;
        for _ in 0..2000 {
            let r = 0.05 + 0.95 * rng.next_f32();
            let dist = TrowbridgeReitz::from_roughness(r);
            let (a, b) = (rng.next_2d(), rng.next_2d());
            let wo = dir(fmath::acos(2.0 * a.x - 1.0), 2.0 * PI * a.y);
            let wi = dir(fmath::acos(2.0 * b.x - 1.0), 2.0 * PI * b.y);
            let (f1, f2) = (conductor_f(&dist, &fresnel, wo, wi), conductor_f(&dist, &fresnel, wi, wo));
            assert!((f1 - f2).abs().max_element() <= 1e-4 * f1.max_element().max(1.0), "{wo} {wi}: {f1} {f2}");
            let (g1, g2) = (dielectric_f(&dist, 1.5, wo, wi, true), dielectric_f(&dist, 1.5, wi, wo, false));
            assert!((g1 - g2).abs() <= 1e-4 * g1.max(1.0), "r = {r}, {wo} {wi}: {g1} vs {g2}");
            checked += usize::from(g1 > 0.0 && wo.z * wi.z < 0.0);
        }
        assert!(checked > 200, "only {checked} transmitted pairs checked");
    }

    /// The density each sampler reports integrates to the probability that it returns a direction, and that
    /// probability is what the samples show: `∫ pdf dω = P(Some)`, at most 1.
    #[test]
    fn each_pdf_integrates_to_the_share_of_samples_it_returns() {
        let white = ConductorFresnel::Schlick { f0: Rgb::ONE };
        let mut rng = sampler(4);
        for r in [0.1f32, 0.5, 1.0] {
            let dist = TrowbridgeReitz::from_roughness(r);
            for wo in [dir(0.2, 0.0), dir(1.2, 1.0), -dir(0.9, 2.0)] {
                let n = 100_000;
                let total_c = integrate_lobes(wo, 1.0, |wi| conductor_pdf(&dist, wo, wi));
                let some_c = (0..n).filter(|_| conductor_sample(&dist, &white, wo, rng.next_2d()).is_some()).count();
                let share_c = some_c as f64 / n as f64;
                assert!(total_c <= 1.0 + 3e-3 && (total_c - share_c).abs() < 6e-3, "r {r} {wo}: {total_c} {share_c}");
                let total_d = integrate_lobes(wo, 1.5, |wi| dielectric_pdf(&dist, 1.5, wo, wi));
                let some_d = (0..n)
                    .filter(|_| dielectric_sample(&dist, 1.5, wo, rng.next_f32(), rng.next_2d(), true).is_some())
                    .count();
                let share_d = some_d as f64 / n as f64;
                assert!(total_d <= 1.0 + 3e-3 && (total_d - share_d).abs() < 6e-3, "r {r} {wo}: {total_d} {share_d}");
            }
        }
    }

    /// Pearson's χ² of `n` samples of a lobe seen from `wo` (a dielectric's of index `eta`, 1 for a conductor)
    /// binned on the sphere against the expected counts from integrating `pdf` over each bin; bins expecting fewer than 5 samples are pooled. Returns (χ², degrees of freedom).
    fn chi_square(
        (wo, eta): (Vec3A, f32),
        n: usize,
        mut sample: impl FnMut() -> Option<Vec3A>,
        pdf: impl Fn(Vec3A) -> f32,
        (rings, sectors): (usize, usize),
    ) -> (f64, usize) {
        let bin = |w: Vec3A| {
            let i = (((w.z.clamp(-1.0, 1.0) + 1.0) * 0.5 * rings as f32) as usize).min(rings - 1);
            let phi = fmath::atan2(w.y, w.x).rem_euclid(2.0 * PI);
            let j = ((phi / (2.0 * PI) * sectors as f32) as usize).min(sectors - 1);
            i * sectors + j
        };
        let mut observed = vec![0f64; rings * sectors];
        for _ in 0..n {
            if let Some(w) = sample() {
                observed[bin(w)] += 1.0;
            }
        }
        // Expected counts: the quadrature about each of the lobe's peaks, point by point into the bins.
        let mut expected = vec![0f64; rings * sectors];
        let (mirror, refracted) = peaks(wo, eta);
        for (centre, side) in [(mirror, 1.0f32), (refracted, -1.0)] {
            quadrature(
                centre,
                600,
                |w| w.z * wo.z * side > 0.0,
                |w, dw| {
                    expected[bin(w)] += f64::from(pdf(w)) * dw * n as f64;
                },
            );
        }
        let (mut chi2, mut dof, mut pooled_o, mut pooled_e) = (0.0, 0usize, 0.0, 0.0);
        for (o, e) in observed.iter().zip(&expected) {
            if *e < 5.0 {
                pooled_o += o;
                pooled_e += e;
            } else {
                chi2 += (o - e) * (o - e) / e;
                dof += 1;
            }
        }
        if pooled_e >= 5.0 {
            chi2 += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e;
            dof += 1;
        }
        (chi2, dof.saturating_sub(1))
    }

    /// The upper-tail z-score of χ² with `dof` degrees of freedom (Wilson–Hilferty): a standard normal under
    /// the hypothesis that the samples follow the pdf.
    fn wilson_hilferty(chi2: f64, dof: usize) -> f64 {
        let k = dof as f64;
        ((chi2 / k).cbrt() - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt()
    }

    /// χ² goodness of fit of each sampler against its own pdf (the test of Mitsuba's and pbrt's BSDF suites),
    /// at a threshold of z = 4 (a false alarm once in 30 000 runs; the seeds are fixed, so a run is
    /// reproducible), for several roughnesses and view directions, from both sides of the dielectric.
    #[test]
    fn chi_square_each_sampler_follows_its_pdf() {
        let fresnel = ConductorFresnel::Complex { eta: Rgb::new(0.2, 0.9, 1.1), k: Rgb::new(3.9, 2.4, 2.1) };
        let mut rng = sampler(5);
        let mut report = Vec::new();
        for r in [0.15f32, 0.4, 0.8] {
            let dist = TrowbridgeReitz::from_roughness(r);
            for wo in [dir(0.3, 0.5), dir(1.3, 2.0), -dir(0.8, 4.0)] {
                let (chi2, dof) = chi_square(
                    (wo, 1.0),
                    300_000,
                    || conductor_sample(&dist, &fresnel, wo, rng.next_2d()).map(|s| s.wi),
                    |wi| conductor_pdf(&dist, wo, wi),
                    (30, 60),
                );
                let z = wilson_hilferty(chi2, dof);
                assert!(z < 4.0, "conductor r = {r}, {wo}: χ² = {chi2} with {dof} dof, z = {z}");
                report.push(format!("conductor r={r} cosθo={:.2}: χ²/dof = {:.3}", wo.z, chi2 / dof as f64));
                let (chi2, dof) = chi_square(
                    (wo, 1.5),
                    300_000,
                    || dielectric_sample(&dist, 1.5, wo, rng.next_f32(), rng.next_2d(), true).map(|s| s.wi),
                    |wi| dielectric_pdf(&dist, 1.5, wo, wi),
                    (30, 60),
                );
                let z = wilson_hilferty(chi2, dof);
                assert!(z < 4.0, "dielectric r = {r}, {wo}: χ² = {chi2} with {dof} dof, z = {z}");
                report.push(format!("dielectric r={r} cosθo={:.2}: χ²/dof = {:.3}", wo.z, chi2 / dof as f64));
            }
        }
        println!("chi-square:\n{}", report.join("\n"));
    }

    /// The complex Fresnel term: a conductor of `k = 0` is the dielectric of the same index; at normal
    /// incidence it is `((η−1)² + k²) / ((η+1)² + k²)`; at grazing incidence every conductor reflects all.
    #[test]
    fn complex_fresnel_matches_its_closed_forms() {
        for c in [1.0f32, 0.8, 0.4, 0.1] {
            let d = crate::math::fresnel_dielectric(c, 1.5);
            assert!((fresnel_complex(c, 1.5, 0.0) - d).abs() < 1e-5, "cos {c}");
        }
        let (eta, k) = (0.2f32, 3.9f32);
        let normal = ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k);
        assert!((fresnel_complex(1.0, eta, k) - normal).abs() < 1e-5);
        assert!(fresnel_complex(1e-4, eta, k) > 0.99);
        let schlick = ConductorFresnel::Schlick { f0: Rgb::new(1.0, 0.5, 0.0) };
        assert_eq!(schlick.eval(1.0), Rgb::new(1.0, 0.5, 0.0));
        assert_eq!(schlick.eval(0.0), Rgb::ONE);
    }
}
