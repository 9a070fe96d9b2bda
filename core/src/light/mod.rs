//! Lights: isotropic point lights, spot lights, diffuse area lights on any bounded surface, directional
//! lights and the environment.
//!
//! ```toml
//! [[lights]]
//! type = "point"
//! position = [0.0, 1.9, 0.0]
//! intensity = [10.0, 10.0, 10.0]    # W/sr; or power = [...] in W (= 4π·intensity)
//!
//! [[lights]]
//! type = "spot"
//! position = [0.0, 1.9, 0.0]
//! direction = [0.0, -1.0, 0.0]
//! intensity = [10.0, 10.0, 10.0]    # W/sr on the axis; or power
//! inner_angle = 20.0                # degrees: full intensity within (default 0)
//! outer_angle = 30.0                # degrees: nothing outside (default 45)
//!
//! [[lights]]
//! type = "directional"
//! direction = [0.3, -1.0, 0.2]      # the way the light travels
//! irradiance = [3.0, 3.0, 3.0]      # W/m² on a surface facing it
//!
//! [[lights]]
//! type = "environment"              # at most one; see [`environment`] for the image's mapping
//! radiance = [0.4, 0.5, 0.7]        # or image = "sky.exr" with scale and rotate
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
//!
//! Directional lights and the environment are infinitely far: no ray hits them, a ray that escapes the scene
//! sees the environment, and their photons and light subpaths leave a disc of the radius of the scene's
//! bounding sphere (bounded primitives; planes are not counted), perpendicular to their direction, from outside
//! the sphere (pbrt-v4 §12.5; Georgiev et al. 2012, §5.1, for their densities in vcm). Their power is what
//! crosses that disc.

pub mod environment;

pub use environment::SkyDistribution;

use crate::Rgb;
use crate::geometry::{Geometry, Hit, NONE};
use crate::material::texture::TexelImage;
use crate::math::rng::Sampler;
use crate::math::{
    Frame, Ray, concentric_disk, cosine_hemisphere, fmath, luminance, offset_ray_origin_by_error, uniform_sphere,
};
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
    /// A spot light: radiant intensity `intensity` (W/sr) within `cos_inner` of the axis, a smoothstep in the
    /// cosine down to 0 at `cos_outer` (pbrt-v4 §12.1.1).
    Spot {
        /// Position.
        p: Vec3A,
        /// Radiant intensity on the axis.
        intensity: Rgb,
        /// Unit axis of the cone.
        axis: Vec3A,
        /// Cosine of the cone's half-angle (> 0: the cone is at most a hemisphere).
        cos_outer: f32,
        /// Cosine of the half-angle of full intensity, ≥ `cos_outer`.
        cos_inner: f32,
    },
    /// A diffuse emitter on bounded primitive `prim` of the geometry.
    Area {
        /// Index of the primitive ([`Geometry::prim`]).
        prim: u32,
        /// Emitted radiance; with `image`, its scale.
        le: Rgb,
        /// Emits from both sides.
        two_sided: bool,
        /// Surface area.
        area: f32,
        /// An image whose texels multiply `le` at each point's texture coordinates (glTF's
        /// `emissiveTexture`), or `None` for a constant emitter.
        image: Option<EmissionImage>,
    },
    /// Light from infinitely far along one direction.
    Directional {
        /// Unit direction the light travels.
        d: Vec3A,
        /// Irradiance on a surface facing the light (W/m²).
        irradiance: Rgb,
        /// The scene's bounding sphere, from which photons leave.
        bounds: BoundingSphere,
    },
    /// Light from infinitely far in every direction: the constant `radiance`, or `radiance` times the values of
    /// texture slot `image` laid out as [`environment`] says.
    Environment {
        /// The radiance, or the image's scale.
        radiance: Rgb,
        /// The image's texture slot, or [`NONE`] for a constant environment.
        image: u32,
        /// `(cos, sin)` of the rotation about +y.
        turn: Vec2,
        /// The mean radiance over the sphere, `∫L dω / 4π` (its power over the disc).
        mean: Rgb,
        /// The scene's bounding sphere, from which photons leave.
        bounds: BoundingSphere,
    },
}

/// The image of a textured area light: a texture slot read in sRGB at a point's texture coordinates, and the
/// image's mean, which stands for the texels in the light's power (its share of light choices and photons; the
/// samples themselves carry the texels they read, so any positive mean leaves the estimates unbiased).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EmissionImage {
    /// The texture slot.
    pub slot: u32,
    /// Folding outside `[0, 1]`.
    pub wrap: crate::material::texture::Wrap,
    /// Reconstruction between texel centres.
    pub filter: crate::material::texture::Filter,
    /// The mean of the image's texels (linear).
    pub mean: Rgb,
}

impl EmissionImage {
    /// The image's linear value at texture coordinates `uv`; zero when the slot is missing.
    #[inline]
    pub fn at(&self, textures: &[TexelImage], uv: Vec2) -> Rgb {
        let Some(img) = textures.get(self.slot as usize) else { return Rgb::ZERO };
        let r = crate::material::texture::ImageRef {
            file: std::path::PathBuf::new(),
            slot: self.slot,
            scale: Vec2::ONE,
            offset: Vec2::ZERO,
            wrap: self.wrap,
            filter: self.filter,
            colorspace: None,
        };
        r.lookup(img, uv, crate::material::texture::ColorSpace::Srgb)
    }
}

/// A bounding sphere of the scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoundingSphere {
    /// Centre.
    pub center: Vec3A,
    /// Radius (> 0).
    pub radius: f32,
}

impl BoundingSphere {
    /// The density of a point on the sphere's cross-section disc, `1/(πR²)`.
    #[inline]
    pub fn disc_pdf(&self) -> f32 {
        1.0 / (PI * self.radius * self.radius)
    }

    /// A ray travelling along unit `d` from a point uniform on the disc of the sphere's radius perpendicular to
    /// `d`, placed just outside the sphere on the side the light comes from.
    fn ray_in(&self, d: Vec3A, u: Vec2) -> Ray {
        let frame = Frame::from_normal(d);
        let xy = concentric_disk(u) * self.radius;
        let o = self.center + frame.to_world(Vec3A::new(xy.x, xy.y, -self.radius * 1.001));
        Ray::new(o, d)
    }
}

/// What lights read beside themselves: the surfaces of area lights, the texture images (an environment's) and
/// the environment's sampling distribution.
#[derive(Clone, Copy)]
pub struct LightScene<'a> {
    /// The surfaces.
    pub geometry: &'a Geometry,
    /// The texture images by slot.
    pub textures: &'a [TexelImage],
    /// The environment image's distribution, when the scene has one.
    pub sky: Option<&'a SkyDistribution>,
}

/// A sampled light: direction, distance and incident radiance at the shaded point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shaded point towards the light.
    pub wi: Vec3A,
    /// Distance to the sampled point (∞ for a directional light or the environment).
    pub dist: f32,
    /// Incident radiance (for a point or spot light: intensity / dist²; for a directional light: the
    /// irradiance; both to be used without a pdf).
    pub li: Rgb,
    /// Solid-angle pdf of `wi` (1 for delta lights).
    pub pdf: f32,
    /// Whether the light is a delta (point, spot or directional) light.
    pub delta: bool,
    /// The sampled point, moved off an area light's surface towards the shaded point (so a shadow ray that ends
    /// there does not hit the light itself, whatever the scale of the coordinates); unused when `dist` is ∞.
    pub p: Vec3A,
}

impl LightSample {
    /// Whether the light is infinitely far (its shadow ray has no end).
    #[inline]
    pub fn infinite(&self) -> bool {
        self.dist == f32::INFINITY
    }
}

/// A ray leaving a light, sampled in proportion to its emission ([`Light::sample_le`]).
#[derive(Clone, Copy, Debug)]
pub struct LeSample {
    /// The ray: from the light's position, from the sampled surface point moved off the surface along the
    /// ray, or from the disc outside the scene's bounding sphere.
    pub ray: Ray,
    /// The ray's throughput: emitted radiance × cos / (pick × point density × direction density), W·m⁻²·sr⁻¹
    /// over the densities; for a point light, intensity / (pick × 1/4π).
    pub beta: Rgb,
    /// The density of this point and direction together (area × solid angle, the light choice `pick`
    /// included): Georgiev et al. 2012's emission pdf.
    pub pdf_w: f32,
    /// The density of the point alone, as next-event estimation picks it (pick / area; `pick` for a point,
    /// spot or directional light; for the environment, pick × the direction's solid-angle density, Georgiev et
    /// al.'s §5.1).
    pub pdf_a: f32,
    /// The cosine at the light between the ray and the emitting side's normal (1 for a light without a
    /// surface).
    pub cos: f32,
    /// Whether the light is a delta (point, spot or directional) light.
    pub delta: bool,
    /// Whether the light is infinitely far: the first segment's length is not part of the densities.
    pub infinite: bool,
    /// The surface the ray leaves: the primitive's object and its geometric normal (`None` for a light without
    /// a surface).
    pub surface: Option<(u32, Vec3A)>,
}

/// `smoothstep(a, b, x)`: 0 below `a`, 1 above `b`, `t²(3 − 2t)` between; a step at `a` when `a = b`.
#[inline]
fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    if a >= b {
        return if x >= a { 1.0 } else { 0.0 };
    }
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Light {
    /// Total emitted power (W) per channel: through the bounding disc for the infinitely distant lights.
    pub fn power(&self) -> Rgb {
        match *self {
            Light::Point { intensity, .. } => 4.0 * PI * intensity,
            // 2π ∫ falloff d(cos θ): 1 − cos_inner at full intensity, and half the smoothstep's interval.
            Light::Spot { intensity, cos_outer, cos_inner, .. } => {
                2.0 * PI * (1.0 - 0.5 * (cos_inner + cos_outer)) * intensity
            }
            Light::Area { le, two_sided, area, image, .. } => {
                let texels = image.map_or(Rgb::ONE, |i| i.mean);
                (if two_sided { 2.0 } else { 1.0 }) * PI * area * le * texels
            }
            Light::Directional { irradiance, bounds, .. } => irradiance / bounds.disc_pdf(),
            Light::Environment { mean, bounds, .. } => 4.0 * PI * mean / bounds.disc_pdf(),
        }
    }

    /// Whether [`Light::sample_le`] samples rays exactly in proportion to their emission, so that every
    /// sample's weight `beta` is the light's power (with `pick` = 1): true of point, area and directional lights
    /// and a constant environment, not of a spot light's falloff, a textured area light's or an environment
    /// image's colours.
    pub fn emits_as_sampled(&self) -> bool {
        match *self {
            Light::Spot { .. } => false,
            Light::Area { image, .. } => image.is_none(),
            Light::Environment { image, .. } => image == NONE,
            _ => true,
        }
    }

    /// Whether the light is a delta light (a point, spot or directional light), which no ray can hit.
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. } | Light::Directional { .. })
    }

    /// A point or spot light's radiant intensity (W/sr) in unit direction `w` from it; zero for other lights.
    #[inline]
    pub fn intensity(&self, w: Vec3A) -> Rgb {
        match *self {
            Light::Point { intensity, .. } => intensity,
            Light::Spot { intensity, axis, cos_outer, cos_inner, .. } => {
                intensity * smoothstep(cos_outer, cos_inner, w.dot(axis))
            }
            _ => Rgb::ZERO,
        }
    }

    /// The solid-angle density with which a spot light emits (uniform within its cone) or a point light
    /// (uniform over the sphere).
    #[inline]
    pub fn direction_pdf(&self) -> f32 {
        match *self {
            Light::Spot { cos_outer, .. } => 1.0 / (2.0 * PI * (1.0 - cos_outer)),
            _ => 1.0 / (4.0 * PI),
        }
    }

    /// Emitted radiance leaving an area light's surface at `hit` towards `wo`.
    #[inline]
    pub fn le(&self, scene: &LightScene, hit: &Hit, wo: Vec3A) -> Rgb {
        match *self {
            Light::Area { le, two_sided, image, .. } if two_sided || wo.dot(hit.n) > 0.0 => match image {
                None => le,
                Some(i) => le * i.at(scene.textures, hit.uv),
            },
            _ => Rgb::ZERO,
        }
    }

    /// An area light's emitted radiance at point `p` of its surface (on its emitting side): `le`, times the
    /// image at `p`'s texture coordinates for a textured light; zero for other lights.
    #[inline]
    pub fn le_at(&self, scene: &LightScene, p: Vec3A) -> Rgb {
        match *self {
            Light::Area { le, image: None, .. } => le,
            Light::Area { prim, le, image: Some(i), .. } => le * i.at(scene.textures, scene.geometry.uv_at(prim, p)),
            _ => Rgb::ZERO,
        }
    }

    /// The environment's radiance arriving from unit direction `d` (along a ray leaving in direction `d` that
    /// escapes the scene); zero for other lights.
    #[inline]
    pub fn le_escaped(&self, scene: &LightScene, d: Vec3A) -> Rgb {
        let Light::Environment { radiance, image, turn, .. } = *self else { return Rgb::ZERO };
        if image == NONE {
            return radiance;
        }
        let Some(img) = scene.textures.get(image as usize) else { return Rgb::ZERO };
        radiance * environment::radiance(img, environment::image_point(from_world(turn, d)).0)
    }

    /// The solid-angle density with which [`Light::sample_li`] picks unit direction `d` towards the
    /// environment; zero for other lights.
    pub fn pdf_escaped(&self, scene: &LightScene, d: Vec3A) -> f32 {
        let Light::Environment { image, turn, .. } = *self else { return 0.0 };
        if image == NONE {
            return 1.0 / (4.0 * PI);
        }
        let Some(sky) = scene.sky else { return 0.0 };
        let (uv, sin_theta) = environment::image_point(from_world(turn, d));
        if sin_theta <= 0.0 { 0.0 } else { sky.pdf(uv) / (2.0 * PI * PI * sin_theta) }
    }

    /// A direction towards the environment for uniform `u2`, its radiance and its solid-angle density.
    fn sample_environment(&self, scene: &LightScene, u2: Vec2) -> Option<(Vec3A, Rgb, f32)> {
        let Light::Environment { radiance, image, turn, .. } = *self else { return None };
        if image == NONE {
            return Some((uniform_sphere(u2), radiance, 1.0 / (4.0 * PI)));
        }
        let (img, sky) = (scene.textures.get(image as usize)?, scene.sky?);
        let (uv, pdf_uv) = sky.sample(u2);
        let sin_theta = fmath::sin(PI * uv.y);
        if !(pdf_uv > 0.0 && sin_theta > 0.0) {
            return None;
        }
        let wi = to_world(turn, environment::direction(uv));
        Some((wi, radiance * environment::radiance(img, uv), pdf_uv / (2.0 * PI * PI * sin_theta)))
    }

    /// Samples incident light at `p` (uniform by area on area lights, by the image's distribution towards the
    /// environment). `None` when the sample carries nothing.
    pub fn sample_li(&self, scene: &LightScene, p: Vec3A, u2: Vec2) -> Option<LightSample> {
        match *self {
            Light::Point { p: lp, .. } | Light::Spot { p: lp, .. } => {
                let d = lp - p;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let intensity = self.intensity(-wi);
                if intensity == Rgb::ZERO {
                    return None;
                }
                Some(LightSample { wi, dist, li: intensity / dist2, pdf: 1.0, delta: true, p: lp })
            }
            Light::Area { prim, two_sided, area, .. } => {
                let (lp, lp_error, ln) = scene.geometry.with_prim(prim, |p| p.shape.sample_area_with_error(u2))?;
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
                let li = self.le_at(scene, lp);
                (li != Rgb::ZERO).then_some(LightSample { wi, dist, li, pdf, delta: false, p })
            }
            Light::Directional { d, irradiance, .. } => {
                Some(LightSample { wi: -d, dist: f32::INFINITY, li: irradiance, pdf: 1.0, delta: true, p })
            }
            Light::Environment { .. } => {
                let (wi, li, pdf) = self.sample_environment(scene, u2)?;
                Some(LightSample { wi, dist: f32::INFINITY, li, pdf, delta: false, p })
            }
        }
    }

    /// Samples a ray leaving the light in proportion to its emission (Veach 1997, §10.2.2; pbrt-v4's
    /// `SampleLe`): a point light emits uniformly over the sphere, a spot light uniformly within its cone; an
    /// area light from a point uniform by area, in a cosine-distributed direction on its emitting side (either
    /// side, with equal probability, when two-sided); a directional light and the environment from a point
    /// uniform on the disc of the scene's bounding sphere facing the direction (the environment's sampled as
    /// [`Light::sample_li`] samples it). `pick` is the probability with which the light was chosen (its
    /// densities include it). Draws two 2D samples, then one more for the side of a two-sided light. `None`
    /// for a light whose primitive or image is missing, or a sample that carries nothing.
    pub fn sample_le(&self, scene: &LightScene, pick: f32, s: &mut Sampler) -> Option<LeSample> {
        let (u, u2) = (s.next_2d(), s.next_2d());
        let at_light = |ray: Ray, beta: Rgb, pdf_w: f32, pdf_a: f32, delta: bool, infinite: bool| LeSample {
            ray,
            beta,
            pdf_w,
            pdf_a,
            cos: 1.0,
            delta,
            infinite,
            surface: None,
        };
        match *self {
            Light::Point { p, intensity } => {
                let pdf = pick / (4.0 * PI);
                Some(at_light(Ray::new(p, uniform_sphere(u)), intensity / pdf, pdf, pick, true, false))
            }
            Light::Spot { p, axis, cos_outer, .. } => {
                // Uniform in the cone: cos θ uniform in [cos_outer, 1].
                let cos = 1.0 - u.x * (1.0 - cos_outer);
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                let local = Vec3A::new(sin * fmath::cos(phi), sin * fmath::sin(phi), cos);
                let d = Frame::from_normal(axis).to_world(local);
                let pdf = pick * self.direction_pdf();
                let beta = self.intensity(d) / pdf;
                (beta != Rgb::ZERO).then(|| at_light(Ray::new(p, d), beta, pdf, pick, true, false))
            }
            Light::Area { prim, two_sided, .. } => {
                let ((p, p_error, n), object) =
                    scene.geometry.with_prim(prim, |pr| (pr.shape.sample_area_with_error(u), pr.object))?;
                let le = self.le_at(scene, p);
                let side = if two_sided && s.next_f32() < 0.5 { -n } else { n };
                let local = cosine_hemisphere(u2);
                let d = Frame::from_normal(side).to_world(local);
                let cos = local.z;
                let (pdf_a, pdf_w) = self.pdf_le(pick, cos);
                let ray = Ray::new(offset_ray_origin_by_error(p, p_error, side, d), d);
                let beta = le * (cos / pdf_w);
                let surface = Some((object, n));
                Some(LeSample { ray, beta, pdf_w, pdf_a, cos, delta: false, infinite: false, surface })
            }
            Light::Directional { d, irradiance, bounds } => {
                let pdf = pick * bounds.disc_pdf();
                Some(at_light(bounds.ray_in(d, u2), irradiance / pdf, pdf, pick, true, true))
            }
            Light::Environment { bounds, .. } => {
                let (wi, li, pdf_dir) = self.sample_environment(scene, u)?;
                let pdf_w = pick * pdf_dir * bounds.disc_pdf();
                let beta = li / pdf_w;
                let ray = bounds.ray_in(-wi, u2);
                (beta != Rgb::ZERO).then(|| at_light(ray, beta, pdf_w, pick * pdf_dir, false, true))
            }
        }
    }

    /// The densities with which [`Light::sample_le`] emits from a point of this light in a direction at cosine
    /// `cos` to the emitting side's normal, the light chosen with probability `pick`: (point density, point and
    /// direction density) = `(pick/A, pick/A · cos/π · ½ if two-sided)` for an area light; `(pick, pick ×
    /// direction density)` for a point or spot light; `(pick, pick/(πR²))` for a directional light. Not for the
    /// environment ([`Light::pdf_le_escaped`]).
    pub fn pdf_le(&self, pick: f32, cos: f32) -> (f32, f32) {
        match *self {
            Light::Area { two_sided, area, .. } => {
                let pdf_a = pick / area;
                (pdf_a, pdf_a * cos * FRAC_1_PI * if two_sided { 0.5 } else { 1.0 })
            }
            Light::Directional { bounds, .. } | Light::Environment { bounds, .. } => (pick, pick * bounds.disc_pdf()),
            _ => (pick, pick * self.direction_pdf()),
        }
    }

    /// The environment's densities for a ray escaping in unit direction `d`, the light chosen with
    /// probability `pick`: (direction density as next-event estimation samples it, emission density of the
    /// opposite ray from the disc), both with `pick` (Georgiev et al. 2012, §5.1).
    pub fn pdf_le_escaped(&self, scene: &LightScene, pick: f32, d: Vec3A) -> (f32, f32) {
        let Light::Environment { bounds, .. } = *self else { return (0.0, 0.0) };
        let pdf_dir = pick * self.pdf_escaped(scene, d);
        (pdf_dir, pdf_dir * bounds.disc_pdf())
    }

    /// Solid-angle pdf with which [`Light::sample_li`] picks the point `hit` on this area light, seen from a
    /// point at distance `hit.t` along `ray`.
    pub fn pdf_li(&self, ray: &Ray, hit: &Hit) -> f32 {
        match *self {
            Light::Area { area, .. } => {
                let cos_l = ray.d.dot(hit.n).abs();
                if cos_l == 0.0 { 0.0 } else { hit.t * hit.t / (cos_l * area) }
            }
            _ => 0.0,
        }
    }
}

/// `d` turned by the environment's rotation `turn = (cos, sin)` about +y.
#[inline]
fn to_world(turn: Vec2, d: Vec3A) -> Vec3A {
    Vec3A::new(turn.x * d.x + turn.y * d.z, d.y, -turn.y * d.x + turn.x * d.z)
}

/// World direction `d` in the environment's own frame (the inverse of [`to_world`]).
#[inline]
fn from_world(turn: Vec2, d: Vec3A) -> Vec3A {
    Vec3A::new(turn.x * d.x - turn.y * d.z, d.y, turn.y * d.x + turn.x * d.z)
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
    /// The sampling distribution of the environment's image, when the environment has one.
    pub sky: Option<SkyDistribution>,
}

impl LightSet {
    /// Lights chosen in proportion to the luminance of their power (uniformly if all are dark), with the
    /// distribution of the environment's image. An environment comes last ([`LightSet::environment`]).
    pub fn new(lights: Vec<Light>, sky: Option<SkyDistribution>) -> Self {
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
        Self { lights, cdf, pmf, sky }
    }

    /// The environment and its index: the last light, when it is one.
    #[inline]
    pub fn environment(&self) -> Option<(usize, &Light)> {
        let i = self.lights.len().checked_sub(1)?;
        self.lights.get(i).filter(|l| matches!(l, Light::Environment { .. })).map(|l| (i, l))
    }

    /// What the lights read beside themselves, over `geometry` and the texture images `textures`.
    pub fn scene<'a>(&'a self, geometry: &'a Geometry, textures: &'a [TexelImage]) -> LightScene<'a> {
        LightScene { geometry, textures, sky: self.sky.as_ref() }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::texture::Texels;

    /// An environment of one bright texel (the image's centre column, on the horizon row) turned by `degrees`.
    fn one_texel(degrees: f32) -> (Light, Vec<TexelImage>, SkyDistribution) {
        let (w, h) = (8u32, 4u32);
        let texels = (0..h * w).flat_map(|k| if k == 2 * w + 4 { [5.0f32; 3] } else { [0.0; 3] }).collect();
        let img = TexelImage { width: w, height: h, channels: 3, texels: Texels::F32(texels) };
        let turn = Vec2::new(fmath::cos(degrees.to_radians()), fmath::sin(degrees.to_radians()));
        let bounds = BoundingSphere { center: Vec3A::ZERO, radius: 1.0 };
        let sky = SkyDistribution::new(&img);
        let light = Light::Environment { radiance: Rgb::ONE, image: 0, turn, mean: Rgb::ZERO, bounds };
        (light, vec![img], sky)
    }

    #[test]
    fn a_rotation_turns_the_image_about_plus_y_by_the_right_hand_rule() {
        let geometry = Geometry::default();
        for (degrees, towards) in [(0.0, Vec3A::NEG_Z), (90.0, Vec3A::NEG_X), (180.0, Vec3A::Z), (-90.0, Vec3A::X)] {
            let (light, textures, sky) = one_texel(degrees);
            let scene = LightScene { geometry: &geometry, textures: &textures, sky: Some(&sky) };
            // Texel (4, 2) spans azimuths [0, π/4) from the view axis and polar angles [π/2, 3π/4): its centre
            // is a little right of and below the axis.
            let (u, v) = (4.5f32 / 8.0, 2.5f32 / 4.0);
            let centre = to_world(
                Vec2::new(fmath::cos(degrees.to_radians()), fmath::sin(degrees.to_radians())),
                environment::direction(Vec2::new(u, v)),
            );
            assert!(centre.dot(towards) > 0.8, "{degrees}°: {centre} is not near {towards}");
            assert_eq!(light.le_escaped(&scene, centre), Rgb::splat(5.0));
            assert_eq!(light.le_escaped(&scene, -centre), Rgb::ZERO);
            // Every sample lands in the bright texel, with the density pdf_escaped gives it.
            for k in 0..16 {
                let u2 = Vec2::new((k as f32 + 0.5) / 16.0, 0.37);
                let ls = light.sample_li(&scene, Vec3A::ZERO, u2).unwrap();
                assert_eq!(ls.li, Rgb::splat(5.0));
                assert!((ls.pdf / light.pdf_escaped(&scene, ls.wi) - 1.0).abs() < 1e-4);
                assert!(ls.wi.dot(towards) > 0.6 && ls.infinite());
            }
        }
    }
}
