//! Homogeneous participating media: transmittance, free-flight distance sampling, the Henyey–Greenstein phase
//! function, equiangular sampling, and which medium fills which part of the scene.
//!
//! A medium has absorption and scattering coefficients `σa`, `σs` (1/scene-unit, per RGB channel) and an HG
//! asymmetry `g`; its extinction is `σt = σa + σs` and its transmittance over a distance `d` is `T = e^(−σt·d)`
//! (Beer–Lambert; pbrt-v4 §11.2). The global medium (`[medium]`) fills the space outside all closed objects;
//! a closed object (a sphere, a closed mesh) holds its `interior` medium, or vacuum, and its outside is the
//! inside of the closed object around it, or the global medium (objects nest; they must not overlap partly);
//! open surfaces (planes, rectangles, triangles, open meshes) separate nothing, and a ray crossing one stays in
//! its medium ([`Media::after`]). The camera and each point light are in the medium of the innermost closed
//! object that contains them, or in the global one ([`Media::at`]).
//!
//! The integrators and photon tracing ask a medium only along a ray: [`Medium::transmittance`],
//! [`Medium::sample_distance`], [`Medium::sample_segment`], [`Medium::distance_pdf`] and
//! [`Medium::segment_mass`] take the ray (unit direction) and distances along it, and the sampling calls the
//! path's sampler, from which they draw. A homogeneous medium needs only the distances (closed forms); a medium
//! that varies in space would answer the same calls by tracking along the ray (pbrt-v4 §14.2).
//!
//! Directions follow light's flow: the phase function is evaluated at `cos θ = d_in · d_out`, the cosine
//! between the direction light travelled before the scattering and after it, so `g > 0` scatters forwards.
//! Seen from a camera path that arrived along `ray.d` and leaves along `wi`, light travels along `−wi` then
//! `−ray.d`, and `cos θ = wi · ray.d`: the same formula, so one [`HenyeyGreenstein`] serves both directions.

use crate::Rgb;
use crate::geometry::shapes::Shape;
use crate::geometry::{Geometry, Hit};
use crate::math::fmath;
use crate::math::rng::Sampler;
use crate::math::{Frame, Ray};
use glam::{Vec2, Vec3A};
use serde::{Deserialize, Serialize};

/// The most `interface` surfaces a ray may cross between two vertices (a guard against a ray caught between
/// coincident boundaries; a real scene crosses a few).
pub const MAX_CROSSINGS: u32 = 64;

/// The largest coefficient (σa, σs, density) a medium may have, in 1/scene-unit: beyond it σt·d overflows f32
/// for ordinary distances, and a transmittance of exactly 0 is what such a medium gives anyway.
pub const MAX_SIGMA: f32 = 1e30;

/// A homogeneous medium.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Medium {
    /// Absorption coefficient σa (1/scene-unit) per channel.
    pub sigma_a: Rgb,
    /// Scattering coefficient σs (1/scene-unit) per channel.
    pub sigma_s: Rgb,
    /// Henyey–Greenstein asymmetry in (−1, 1).
    pub g: f32,
}

/// Where a free flight ended (see [`Medium::sample_distance`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FreeFlight {
    /// Distance along the ray: of the scattering event, or `t_max` when the flight reached the surface.
    pub t: f32,
    /// The flight ended in the medium (a scattering event) rather than at `t_max`.
    pub scattered: bool,
    /// Throughput weight: `σs·T(t) / p(t)` for a scattering event, `T(t_max) / P(t ≥ t_max)` otherwise.
    pub weight: Rgb,
    /// The density `p(t)` of the event (0 when the flight reached the surface).
    pub pdf: f32,
}

impl Medium {
    /// Extinction σt = σa + σs.
    #[inline]
    pub fn sigma_t(&self) -> Rgb {
        self.sigma_a + self.sigma_s
    }

    /// Whether the medium scatters at all (σs > 0 in some channel).
    #[inline]
    pub fn scatters(&self) -> bool {
        self.sigma_s.max_element() > 0.0
    }

    /// Whether the medium changes anything (σt > 0 in some channel).
    #[inline]
    pub fn is_vacuum(&self) -> bool {
        self.sigma_t().max_element() <= 0.0
    }

    /// Transmittance along `ray` (unit direction) from its origin to distance `t ≥ 0`, which may be infinite:
    /// here `e^(−σt·t)` (Beer–Lambert; pbrt-v4 §11.2), 0 where σt > 0 and 1 where σt = 0 over an infinite
    /// distance. The ray is what a medium that varies in space integrates σt along; it would estimate the
    /// integral by ratio tracking (pbrt-v4 §14.2.2) from a stream of its own, hashed from the ray, so the
    /// path's sample streams keep their dimensions.
    #[inline]
    pub fn transmittance(&self, ray: &Ray, t: f32) -> Rgb {
        let _ = ray;
        self.transmittance_over(t)
    }

    /// `e^(−σt·d)` over distance `d`: the homogeneous closed form.
    #[inline]
    fn transmittance_over(&self, d: f32) -> Rgb {
        let st = self.sigma_t();
        Rgb::new(tr(st.x, d), tr(st.y, d), tr(st.z, d))
    }

    /// The density (per scene unit) of a free flight along `ray` sampled by [`Medium::sample_distance`] ending
    /// at `t`: `p(t) = (1/3)·Σ_c σt_c·e^(−σt_c·t)` (one channel chosen uniformly, its exponential sampled;
    /// single-sample spectral MIS, pbrt-v3 §15.2.2).
    #[inline]
    pub fn distance_pdf(&self, ray: &Ray, t: f32) -> f32 {
        let _ = ray;
        self.distance_pdf_at(t)
    }

    /// [`Medium::distance_pdf`] at distance `t` of the homogeneous medium.
    #[inline]
    fn distance_pdf_at(&self, t: f32) -> f32 {
        let st = self.sigma_t();
        let tr = self.transmittance_over(t);
        (st * tr).element_sum() / 3.0
    }

    /// The probability that a free flight passes `t`: `(1/3)·Σ_c e^(−σt_c·t)`.
    #[inline]
    fn pass_probability(&self, t: f32) -> f32 {
        self.transmittance_over(t).element_sum() / 3.0
    }

    /// Samples the distance to the next interaction along `ray` (unit direction), whose surface hit is at
    /// `t_max` (∞ when none), drawing two samples from `s` (both, always: a channel, then the distance): a
    /// channel `c` chosen uniformly, then `t = −ln(1 − u)/σt_c` (pbrt-v4 §11.2.2). A medium that does not
    /// scatter is never sampled: the flight reaches `t_max` with weight `T(t_max)`, so an absorbing slab costs
    /// no noise. The weight keeps the estimate unbiased in every channel. A medium that varies in space would
    /// sample the same flight by delta tracking along `ray` (pbrt-v4 §14.2.1).
    pub fn sample_distance(&self, ray: &Ray, t_max: f32, s: &mut Sampler) -> FreeFlight {
        let _ = ray;
        let (u_channel, u) = (s.next_f32(), s.next_f32());
        if !self.scatters() {
            return FreeFlight { t: t_max, scattered: false, weight: self.transmittance_over(t_max), pdf: 0.0 };
        }
        let st = self.sigma_t();
        let c = ((u_channel * 3.0) as usize).min(2);
        let sc = st[c];
        let t = if sc > 0.0 { -fmath::ln_1p(-u) / sc } else { f32::INFINITY };
        if t < t_max {
            let pdf = self.distance_pdf_at(t);
            let weight = self.sigma_s * self.transmittance_over(t) / pdf;
            if pdf > 0.0 && weight.is_finite() {
                return FreeFlight { t, scattered: true, weight, pdf };
            }
        }
        let p_pass = self.pass_probability(t_max);
        let weight = if p_pass > 0.0 { self.transmittance_over(t_max) / p_pass } else { Rgb::ZERO };
        FreeFlight { t: t_max, scattered: false, weight, pdf: 0.0 }
    }

    /// The probability that a free flight along `ray` ([`Medium::sample_distance`]) ends before `t_max`:
    /// `(1/3)·Σ_c (1 − e^(−σt_c·t_max))`, each term without the cancellation of a thin segment.
    pub fn segment_mass(&self, ray: &Ray, t_max: f32) -> f32 {
        let _ = ray;
        self.channel_masses(t_max).iter().sum::<f32>() / 3.0
    }

    /// Per channel, `1 − e^(−σt_c·t_max)` (0 where σt_c = 0).
    fn channel_masses(&self, t_max: f32) -> [f32; 3] {
        self.sigma_t().to_array().map(|s| if s > 0.0 { -expm1(-s * t_max) } else { 0.0 })
    }

    /// Samples a distance in `[0, t_max)` of `ray` from the free-flight density restricted to the segment,
    /// `p(t) / m` with `m` = [`Medium::segment_mass`], drawing two samples from `s` (both, always): a channel
    /// chosen with probability proportional to its mass on the segment, then its exponential inverted on the
    /// interval. The point where a photon method estimates in-scattered radiance along a segment. Returns
    /// `(t, density)`, the density per scene unit, or `None` when the medium does not scatter or the segment
    /// holds no mass.
    pub fn sample_segment(&self, ray: &Ray, t_max: f32, s: &mut Sampler) -> Option<(f32, f32)> {
        let _ = ray;
        let (u_channel, u) = (s.next_f32(), s.next_f32());
        if !self.scatters() || t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        let masses = self.channel_masses(t_max);
        let total: f32 = masses.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        // The channel whose share of the total mass holds `u_channel` (never one without mass).
        let x = u_channel * total;
        let (mut c, mut acc) = (0, 0.0);
        for (i, &m) in masses.iter().enumerate() {
            if m > 0.0 {
                (c, acc) = (i, acc + m);
                if x < acc {
                    break;
                }
            }
        }
        let sc = self.sigma_t()[c];
        let t = (-fmath::ln_1p(-u * masses[c]) / sc).min(t_max.next_down_f32());
        let pdf = self.distance_pdf_at(t) / (total / 3.0);
        (pdf > 0.0 && pdf.is_finite() && t.is_finite()).then_some((t, pdf))
    }
}

/// `e^(−σ·d)`, 1 where σ = 0 (also for an infinite `d`).
#[inline]
fn tr(sigma: f32, d: f32) -> f32 {
    if sigma <= 0.0 { 1.0 } else { fmath::exp(-sigma * d) }
}

/// `e^x − 1` without the cancellation of small `x`.
#[inline]
fn expm1(x: f32) -> f32 {
    if x.abs() < 1e-4 { x + 0.5 * x * x } else { fmath::exp(x) - 1.0 }
}

/// `x.next_down()` for the f32s this module handles (finite, positive); the largest f32 below `x`.
trait NextDown {
    fn next_down_f32(self) -> f32;
}

impl NextDown for f32 {
    #[inline]
    fn next_down_f32(self) -> f32 {
        if self.is_finite() && self > 0.0 { f32::from_bits(self.to_bits() - 1) } else { self }
    }
}

/// The Henyey–Greenstein phase function (Henyey & Greenstein 1941; pbrt-v4 §11.3.1):
/// `p(cos θ) = (1 − g²) / (4π·(1 + g² − 2g·cos θ)^{3/2})` (sr⁻¹), normalised over the sphere, isotropic (1/4π)
/// at `g = 0`. `cos θ` is between the direction light travelled and the one it leaves in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HenyeyGreenstein {
    /// Asymmetry in (−1, 1).
    pub g: f32,
}

/// A sampled phase-function direction.
#[derive(Clone, Copy, Debug)]
pub struct PhaseSample {
    /// The new unit direction.
    pub wi: Vec3A,
    /// Its solid-angle pdf, which equals the phase function's value (exact importance sampling).
    pub pdf: f32,
}

impl HenyeyGreenstein {
    /// The phase function's value at `cos θ` (sr⁻¹).
    #[inline]
    pub fn eval_cos(&self, cos: f32) -> f32 {
        let g = self.g;
        let denom = 1.0 + g * g - 2.0 * g * cos.clamp(-1.0, 1.0);
        let denom = denom.max(1e-12);
        (1.0 - g * g) / (4.0 * std::f32::consts::PI * denom * denom.sqrt())
    }

    /// The phase function between unit directions `d_in` and `d_out` (`cos θ = d_in · d_out`).
    #[inline]
    pub fn eval(&self, d_in: Vec3A, d_out: Vec3A) -> f32 {
        self.eval_cos(d_in.dot(d_out))
    }

    /// Samples `cos θ` by inverting the CDF: `cos θ = (1 + g² − ((1 − g²)/(1 − g + 2g·u))²) / (2g)`, and
    /// `1 − 2u` when `|g| < 10⁻³` (pbrt-v4 §11.3.1).
    #[inline]
    pub fn sample_cos(&self, u: f32) -> f32 {
        let g = self.g;
        if g.abs() < 1e-3 {
            return (1.0 - 2.0 * u).clamp(-1.0, 1.0);
        }
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
        ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
    }

    /// Samples a direction around `axis` (a unit vector): `cos θ` by [`HenyeyGreenstein::sample_cos`] with
    /// `u.x`, the azimuth `2π·u.y`.
    pub fn sample(&self, axis: Vec3A, u: Vec2) -> PhaseSample {
        let cos = self.sample_cos(u.x);
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * std::f32::consts::PI * u.y;
        let local = Vec3A::new(sin * fmath::cos(phi), sin * fmath::sin(phi), cos);
        let wi = fmath::normalize(Frame::from_normal(axis).to_world(local));
        PhaseSample { wi, pdf: self.eval_cos(cos) }
    }
}

/// Equiangular sampling of a point along a ray segment towards a point light (Kulla & Fajardo 2012, "Importance
/// Sampling Techniques for Path Tracing in Participating Media", EGSR, §4.1): `t` is chosen uniformly in the
/// angle it subtends at the light, so its density is `D / ((θb − θa)·(D² + (t − Δ)²))`, which cancels the
/// `1/r²` of the light's falloff.
#[derive(Clone, Copy, Debug)]
pub struct Equiangular {
    /// Distance along the ray to the point nearest the light.
    delta: f32,
    /// Distance from the light to the ray's line.
    dist: f32,
    /// Angles of the segment's ends, seen from the light.
    theta_a: f32,
    theta_b: f32,
}

impl Equiangular {
    /// The sampler for the segment `[0, t_max)` of `ray` (unit direction) towards `light`; `None` when the
    /// light lies on the ray's line (the density would be a delta) or the segment is empty.
    pub fn new(ray: &Ray, t_max: f32, light: Vec3A) -> Option<Self> {
        let delta = (light - ray.o).dot(ray.d);
        let dist = (ray.o + delta * ray.d - light).length();
        if !(dist > 0.0 && dist.is_finite() && t_max > 0.0) {
            return None;
        }
        let theta_a = fmath::atan2(-delta, dist);
        let theta_b = fmath::atan2(t_max - delta, dist);
        (theta_b > theta_a).then_some(Self { delta, dist, theta_a, theta_b })
    }

    /// A distance in `[0, t_max)` and its density.
    pub fn sample(&self, u: f32) -> (f32, f32) {
        let theta = self.theta_a + u * (self.theta_b - self.theta_a);
        let t = (self.delta + self.dist * fmath::tan(theta)).max(0.0);
        (t, self.pdf(t))
    }

    /// The density of [`Equiangular::sample`] at `t` in the segment.
    #[inline]
    pub fn pdf(&self, t: f32) -> f32 {
        let x = t - self.delta;
        self.dist / ((self.theta_b - self.theta_a) * (self.dist * self.dist + x * x))
    }
}

/// What a closed object holds inside, as far as media go.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Boundary {
    /// An open surface, or an object that separates nothing: a ray crossing it keeps its medium.
    Open,
    /// A closed surface: inside is `interior` (vacuum when `None`), outside `exterior` (the medium of the
    /// closed object around it, or the global one). `inward` is set when the surface's geometric normals point
    /// inwards (a mesh wound clockwise).
    Closed {
        /// The medium inside.
        interior: Option<Medium>,
        /// The medium outside.
        exterior: Option<Medium>,
        /// The geometric normals point inwards.
        inward: bool,
    },
}

/// The media of a scene: present only when it has a global medium or an interior one, so a scene without
/// media runs none of this code.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Media {
    /// The medium outside all closed objects (vacuum when `None`).
    pub global: Option<Medium>,
    /// Per scene object (by `Hit::object`), what it separates.
    pub boundaries: Vec<Boundary>,
    /// The medium the camera is in.
    pub camera: Option<Medium>,
    /// The medium each light is in, by light index (for a point light's photons; area lights' photons leave
    /// through their surface, [`Media::leaving`]).
    pub lights: Vec<Option<Medium>>,
    /// Some material is an `interface`: shadow rays must look past such surfaces (closest hits, not any hit).
    pub interfaces: bool,
}

impl Medium {
    /// Checks what a scene's validation checks, for a medium that arrived in a blob: coefficients finite and
    /// ≥ 0, `g` in (−1, 1).
    pub fn check(&self) -> Result<(), crate::error::FieldError> {
        for (name, v) in [("sigma_a", self.sigma_a), ("sigma_s", self.sigma_s)] {
            if !(v.is_finite() && v.min_element() >= 0.0 && v.max_element() <= MAX_SIGMA) {
                return Err(crate::error::FieldError::new(
                    name,
                    format!("expected finite numbers ≥ 0 (at most {MAX_SIGMA:e}), found {v}"),
                ));
            }
        }
        if !(self.g > -1.0 && self.g < 1.0) {
            return Err(crate::error::FieldError::new("g", format!("expected a number in (−1, 1), found {}", self.g)));
        }
        Ok(())
    }
}

impl Media {
    /// Checks every medium ([`Medium::check`]); the error names it (`media.global.g`, `media.boundaries[3].sigma_s`).
    pub fn check(&self) -> Result<(), crate::error::FieldError> {
        let all = [("media.global".to_string(), self.global), ("media.camera".to_string(), self.camera)]
            .into_iter()
            .chain(self.lights.iter().enumerate().map(|(i, m)| (format!("media.lights[{i}]"), *m)))
            .chain(self.boundaries.iter().enumerate().flat_map(|(i, b)| match b {
                Boundary::Closed { interior, exterior, .. } => vec![
                    (format!("media.boundaries[{i}].interior"), *interior),
                    (format!("media.boundaries[{i}].exterior"), *exterior),
                ],
                Boundary::Open => Vec::new(),
            }));
        for (name, m) in all {
            if let Some(m) = m {
                m.check().map_err(|e| e.within(&name))?;
            }
        }
        Ok(())
    }

    /// The medium a ray is in after leaving (or passing) the surface of `hit` in direction `wi`, having been in
    /// `current` before it.
    #[inline]
    pub fn after(&self, hit: &Hit, wi: Vec3A, current: Option<Medium>) -> Option<Medium> {
        self.leaving(hit.object, hit.n, wi, current)
    }

    /// [`Media::after`] for a surface of object `object` with geometric normal `n`.
    #[inline]
    pub fn leaving(&self, object: u32, n: Vec3A, wi: Vec3A, current: Option<Medium>) -> Option<Medium> {
        match self.boundaries.get(object as usize) {
            Some(Boundary::Closed { interior, exterior, inward }) => {
                if (wi.dot(n) < 0.0) != *inward {
                    *interior
                } else {
                    *exterior
                }
            }
            _ => current,
        }
    }

    /// The medium at point `p`: the interior of the innermost closed object that contains it (of those that
    /// contain it, the one with the smallest bounding box: objects may nest but not overlap), else the global
    /// medium. Containment is the parity of crossings along a fixed ray through each closed object's
    /// primitives, all counted in one pass over the primitives; object `skip` is left out (an object's own
    /// exterior is the medium around it). For the camera, the lights and each closed object, once per scene.
    pub fn at(&self, geometry: &Geometry, p: Vec3A, skip: Option<u32>) -> Option<Medium> {
        // A direction unlikely to graze an edge of an axis-aligned model.
        let d = fmath::normalize(Vec3A::new(0.5773, 0.5802, 0.5745));
        let ray = Ray::new(p, d);
        let n = self.boundaries.len();
        let (mut count, mut bounds) = (vec![0u32; n], vec![crate::math::Aabb::EMPTY; n]);
        for pr in geometry.prims() {
            let o = pr.object as usize;
            if Some(pr.object) == skip || !matches!(self.boundaries.get(o), Some(Boundary::Closed { .. })) {
                continue;
            }
            count[o] += crossings(&pr.shape, &ray);
            bounds[o] = bounds[o].union(pr.shape.bounds());
        }
        let size = |b: &crate::math::Aabb| (b.max - b.min).length();
        let inner =
            (0..n).filter(|&o| count[o] % 2 == 1).min_by(|&a, &b| size(&bounds[a]).total_cmp(&size(&bounds[b])));
        match inner.and_then(|o| self.boundaries.get(o)) {
            Some(Boundary::Closed { interior, .. }) => *interior,
            _ => self.global,
        }
    }
}

/// How many times the ray from `ray.o` crosses `shape`, counted so that its parity says whether `ray.o` is
/// inside a closed surface: a sphere by the distance to its centre, a triangle by one intersection test.
fn crossings(shape: &Shape, ray: &Ray) -> u32 {
    match shape {
        Shape::Sphere(s) => u32::from((ray.o - Vec3A::from(s.center)).length() < s.radius),
        _ => u32::from(shape.intersect(ray, f32::INFINITY).is_some()),
    }
}

/// Whether a triangle mesh is closed and how it is wound: `Some(inward)` when every edge is shared by exactly
/// two faces that run along it in opposite directions (vertices welded by exact position), with `inward` set
/// when the enclosed signed volume is negative (normals `(p1 − p0) × (p2 − p0)` pointing in); `None` for an open
/// or inconsistently wound mesh.
pub fn closed_mesh_orientation(triangles: &[[glam::Vec3; 3]]) -> Option<bool> {
    use std::collections::HashMap;
    if triangles.is_empty() {
        return None;
    }
    let key = |v: glam::Vec3| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    let mut volume = 0.0f64;
    for t in triangles {
        let mut idx = [0u32; 3];
        for (k, v) in t.iter().enumerate() {
            let n = ids.len() as u32;
            idx[k] = *ids.entry(key(*v)).or_insert(n);
        }
        for k in 0..3 {
            *edges.entry((idx[k], idx[(k + 1) % 3])).or_insert(0) += 1;
        }
        let [a, b, c] = t.map(|v| v.as_dvec3());
        volume += a.dot(b.cross(c));
    }
    let closed = edges.iter().all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1));
    (closed && volume != 0.0).then_some(volume < 0.0)
}
