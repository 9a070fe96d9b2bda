//! Lights: isotropic point lights and diffuse area lights on any bounded surface.
//!
//! ```toml
//! [[lights]]
//! type = "point"
//! position = [0.0, 1.9, 0.0]
//! intensity = [10.0, 10.0, 10.0]    # W/sr; or power = [...] in W (= 4π·intensity)
//!
//! [[objects]]                       # any rect, triangle, sphere or mesh becomes an area light
//! type = "rect"
//! center = [0.0, 1.99, 0.0]
//! normal = [0.0, -1.0, 0.0]
//! width = 0.5
//! height = 0.4
//! material = "white"
//! emission = { radiance = [17.0, 12.0, 4.0], two_sided = false }
//! ```
//! Area lights emit `radiance` with a cosine law from the side the surface normal points to (both sides when
//! `two_sided`); their power is Φ = π·L·A per side. Lights are chosen for next-event estimation in proportion
//! to their power.

use crate::Rgb;
use crate::geometry::{Geometry, Hit};
use crate::math::rng::Sampler;
use crate::math::{Frame, Ray, cosine_hemisphere, luminance, offset_ray_origin_by_error, uniform_sphere};
use glam::{Vec2, Vec3A};
use serde::{Deserialize, Serialize};
use std::f32::consts::{FRAC_1_PI, PI};

/// A light.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Light {
    /// An isotropic point light with radiant intensity `intensity` (W/sr).
    Point {
        /// Position.
        p: Vec3A,
        /// Radiant intensity.
        intensity: Rgb,
    },
    /// A diffuse emitter on bounded primitive `prim` of the geometry.
    Area {
        /// Index into [`Geometry::prims`].
        prim: u32,
        /// Emitted radiance.
        le: Rgb,
        /// Emits from both sides.
        two_sided: bool,
        /// Surface area.
        area: f32,
    },
}

/// A sampled light: direction, distance and incident radiance at the shaded point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shaded point towards the light.
    pub wi: Vec3A,
    /// Distance to the sampled point.
    pub dist: f32,
    /// Incident radiance (for a point light: intensity / dist², to be used without a pdf).
    pub li: Rgb,
    /// Solid-angle pdf of `wi` (1 for point lights, whose sample is a delta).
    pub pdf: f32,
    /// Whether the light is a delta (point) light.
    pub delta: bool,
    /// The sampled point, moved off an area light's surface towards the shaded point (so a shadow ray that ends
    /// there does not hit the light itself, whatever the scale of the coordinates).
    pub p: Vec3A,
}

/// A ray leaving a light, sampled in proportion to its emission ([`Light::sample_le`]).
#[derive(Clone, Copy, Debug)]
pub struct LeSample {
    /// The ray: from the light's position, or from the sampled surface point moved off the surface along the
    /// ray, in a cosine-distributed direction on the emitting side.
    pub ray: Ray,
    /// The ray's throughput: emitted radiance × cos / (pick × point density × direction density), W·m⁻²·sr⁻¹
    /// over the densities; for a point light, intensity / (pick × 1/4π).
    pub beta: Rgb,
    /// The density of this point and direction together (area × solid angle, the light choice `pick`
    /// included): Georgiev et al. 2012's emission pdf.
    pub pdf_w: f32,
    /// The density of the point alone, as next-event estimation picks it (pick / area; `pick` for a point
    /// light).
    pub pdf_a: f32,
    /// The cosine at the light between the ray and the emitting side's normal (1 for a point light).
    pub cos: f32,
    /// Whether the light is a delta (point) light.
    pub delta: bool,
    /// The surface the ray leaves: the primitive's object and its geometric normal (`None` for a point light).
    pub surface: Option<(u32, Vec3A)>,
}

impl Light {
    /// Total emitted power (W) per channel.
    pub fn power(&self) -> Rgb {
        match *self {
            Light::Point { intensity, .. } => 4.0 * std::f32::consts::PI * intensity,
            Light::Area { le, two_sided, area, .. } => {
                (if two_sided { 2.0 } else { 1.0 }) * std::f32::consts::PI * area * le
            }
        }
    }

    /// Emitted radiance leaving an area light's surface at `hit` towards `wo`.
    #[inline]
    pub fn le(&self, hit: &Hit, wo: Vec3A) -> Rgb {
        match *self {
            Light::Area { le, two_sided, .. } if two_sided || wo.dot(hit.n) > 0.0 => le,
            _ => Rgb::ZERO,
        }
    }

    /// Samples incident light at `p` (uniform by area on area lights).
    pub fn sample_li(&self, geometry: &Geometry, p: Vec3A, u2: Vec2) -> Option<LightSample> {
        match *self {
            Light::Point { p: lp, intensity } => {
                let d = lp - p;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                Some(LightSample { wi: d / dist, dist, li: intensity / dist2, pdf: 1.0, delta: true, p: lp })
            }
            Light::Area { prim, le, two_sided, area } => {
                let (lp, lp_error, ln) = geometry.prims.get(prim as usize)?.shape.sample_area_with_error(u2);
                let d = lp - p;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = -wi.dot(ln);
                if !(two_sided || cos_l > 0.0) || cos_l == 0.0 {
                    return None;
                }
                let pdf = dist2 / (cos_l.abs() * area);
                let towards = if cos_l > 0.0 { ln } else { -ln };
                // Off the light by its sampled point's error bound (pbrt-v4 §6.8.6), towards the shaded point.
                let p = crate::math::offset_ray_origin_by_error(lp, lp_error, ln, towards);
                Some(LightSample { wi, dist, li: le, pdf, delta: false, p })
            }
        }
    }

    /// Samples a ray leaving the light in proportion to its emission (Veach 1997, §10.2.2; pbrt-v4's
    /// `SampleLe`): a point light emits uniformly over the sphere; an area light from a point uniform by area,
    /// in a cosine-distributed direction on its emitting side (either side, with equal probability, when
    /// two-sided). `pick` is the probability with which the light was chosen (its densities include it).
    /// Draws two 2D samples, then one more for the side of a two-sided light. `None` for a light whose
    /// primitive is missing.
    pub fn sample_le(&self, geometry: &Geometry, pick: f32, s: &mut Sampler) -> Option<LeSample> {
        let (u, u2) = (s.next_2d(), s.next_2d());
        match *self {
            Light::Point { p, intensity } => {
                let pdf = pick / (4.0 * PI);
                let ray = Ray::new(p, uniform_sphere(u));
                Some(LeSample {
                    ray,
                    beta: intensity / pdf,
                    pdf_w: pdf,
                    pdf_a: pick,
                    cos: 1.0,
                    delta: true,
                    surface: None,
                })
            }
            Light::Area { prim, le, two_sided, .. } => {
                let pr = geometry.prims.get(prim as usize)?;
                let (p, p_error, n) = pr.shape.sample_area_with_error(u);
                let side = if two_sided && s.next_f32() < 0.5 { -n } else { n };
                let local = cosine_hemisphere(u2);
                let d = Frame::from_normal(side).to_world(local);
                let cos = local.z;
                let (pdf_a, pdf_w) = self.pdf_le(pick, cos);
                let ray = Ray::new(offset_ray_origin_by_error(p, p_error, side, d), d);
                let beta = le * (cos / pdf_w);
                Some(LeSample { ray, beta, pdf_w, pdf_a, cos, delta: false, surface: Some((pr.object, n)) })
            }
        }
    }

    /// The densities with which [`Light::sample_le`] emits from a point of this light in a direction at cosine
    /// `cos` to the emitting side's normal, the light chosen with probability `pick`: (point density, point and
    /// direction density) = `(pick/A, pick/A · cos/π · ½ if two-sided)`; `(pick, pick/4π)` for a point light.
    pub fn pdf_le(&self, pick: f32, cos: f32) -> (f32, f32) {
        match *self {
            Light::Point { .. } => (pick, pick / (4.0 * PI)),
            Light::Area { two_sided, area, .. } => {
                let pdf_a = pick / area;
                (pdf_a, pdf_a * cos * FRAC_1_PI * if two_sided { 0.5 } else { 1.0 })
            }
        }
    }

    /// Solid-angle pdf with which [`Light::sample_li`] picks the point `hit` on this area light, seen from a
    /// point at distance `hit.t` along `ray`.
    pub fn pdf_li(&self, ray: &Ray, hit: &Hit) -> f32 {
        match *self {
            Light::Point { .. } => 0.0,
            Light::Area { area, .. } => {
                let cos_l = ray.d.dot(hit.n).abs();
                if cos_l == 0.0 { 0.0 } else { hit.t * hit.t / (cos_l * area) }
            }
        }
    }
}

/// The lights of a scene with a power-proportional choice among them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LightSet {
    /// The lights.
    pub lights: Vec<Light>,
    /// Cumulative choice probabilities (last = 1).
    cdf: Vec<f32>,
    /// Choice probability of each light.
    pmf: Vec<f32>,
}

impl LightSet {
    /// Lights chosen in proportion to the luminance of their power (uniformly if all are dark).
    pub fn new(lights: Vec<Light>) -> Self {
        let weights: Vec<f64> = lights.iter().map(|l| f64::from(luminance(l.power()).max(0.0))).collect();
        let total: f64 = weights.iter().sum();
        let n = lights.len().max(1) as f64;
        let pmf: Vec<f32> =
            weights.iter().map(|&w| if total > 0.0 { (w / total) as f32 } else { (1.0 / n) as f32 }).collect();
        let mut acc = 0.0f64;
        let mut cdf: Vec<f32> = weights
            .iter()
            .map(|&w| {
                acc += if total > 0.0 { w / total } else { 1.0 / n };
                acc as f32
            })
            .collect();
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Self { lights, cdf, pmf }
    }

    /// Picks a light: its index and choice probability.
    #[inline]
    pub fn choose(&self, u: f32) -> Option<(usize, f32)> {
        if self.lights.is_empty() {
            return None;
        }
        // `pmf` is as long as `lights` ([`LightSet::new`]; a scene blob's is checked on decode).
        let i = self.cdf.partition_point(|&c| c <= u).min(self.lights.len() - 1);
        Some((i, self.pmf[i]))
    }

    /// Choice probability of light `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf.get(i).copied().unwrap_or(0.0)
    }

    /// The lengths of the choice tables (cumulative, per light): each is the number of lights in a set that
    /// [`LightSet::new`] made; a scene blob's are checked against it.
    pub fn table_lens(&self) -> (usize, usize) {
        (self.cdf.len(), self.pmf.len())
    }

    /// Total power of all lights (W) per channel.
    pub fn total_power(&self) -> Rgb {
        self.lights.iter().fold(Rgb::ZERO, |a, l| a + l.power())
    }
}
