//! Integrators: direct lighting with specular recursion, and the unbiased path tracer that serves as the
//! reference for every accuracy comparison.
//!
//! Both follow mirror and glass (delta lobes) from the camera. At each non-delta vertex the path tracer
//! estimates direct light by sampling one light (chosen by power) and by sampling the BSDF, weighting the two
//! with the power heuristic (Veach 1997, §9.2); the BSDF sample then continues the path, ended by Russian
//! roulette on the throughput. The direct integrator stops after that first BSDF sample.

use crate::Rgb;
use crate::bsdf::{Bsdf, TransportMode};
use crate::geometry::{Hit, NONE, Ray};
use crate::math::{offset_ray_origin, power_heuristic};
use crate::photon_map::{Estimator, Photon, PhotonMap};
use crate::prepare::Prepared;
use crate::rng::Sampler;
use crate::scene::{Integrator, RenderSettings};
use glam::Vec3A;

/// Bounces before Russian roulette may end a path.
const RR_START: u32 = 3;

/// Radiance arriving along `ray`, by the integrator of `settings`. Counts every traced ray in `rays`.
/// Progressive photon mapping is not a per-ray method: [`crate::render`] runs its passes and calls
/// [`visible_point`] instead.
pub fn li(prep: &Prepared, settings: &RenderSettings, ray: Ray, s: &mut Sampler, rays: &mut u64) -> Rgb {
    match settings.integrator {
        Integrator::Path => trace(prep, settings.max_depth, ray, s, rays, false),
        Integrator::Direct | Integrator::Progressive => trace(prep, settings.max_depth, ray, s, rays, true),
        Integrator::PhotonMap | Integrator::FinalGather => match &prep.photons {
            Some(maps) => photon_li(prep, maps, settings, ray, s, rays),
            None => trace(prep, settings.max_depth, ray, s, rays, true),
        },
    }
}

/// A ray leaving `hit` in direction `wi`, offset to the side `wi` goes to.
#[inline]
pub fn spawn(hit: &Hit, wi: Vec3A) -> Ray {
    let n = if wi.dot(hit.n) > 0.0 { hit.n } else { -hit.n };
    Ray::new(offset_ray_origin(hit.p, n), wi)
}

fn trace(prep: &Prepared, max_depth: u32, mut ray: Ray, s: &mut Sampler, rays: &mut u64, direct_only: bool) -> Rgb {
    let mut l = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    // The last bounce was a delta lobe (or the camera): emission is counted in full, not by MIS.
    let mut prev_delta = true;
    let mut prev_pdf = 0.0f32;
    let mut finishing = false;
    for depth in 0..=max_depth {
        *rays += 1;
        let Some(hit) = prep.geometry.intersect(&ray, f32::INFINITY) else { break };
        let wo = -ray.d;
        if hit.light != NONE
            && let Some(light) = prep.lights.lights.get(hit.light as usize)
        {
            let le = light.le(&hit, wo);
            if le != Rgb::ZERO {
                if prev_delta {
                    l += beta * le;
                } else {
                    let light_pdf = prep.lights.pmf(hit.light as usize) * light.pdf_li(&ray, &hit);
                    l += beta * le * power_heuristic(prev_pdf, light_pdf);
                }
            }
        }
        if finishing || depth == max_depth {
            break;
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit);
        if bsdf.has_non_delta() {
            l += beta * sample_one_light(prep, &hit, &bsdf, wo, s, rays, true);
        }
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if bs.pdf.is_nan() || bs.pdf <= 0.0 || bs.f == Rgb::ZERO {
            break;
        }
        beta *= bs.f * (bs.wi.dot(hit.ns).abs() / bs.pdf);
        prev_delta = bs.delta;
        prev_pdf = bs.pdf;
        if direct_only && !bs.delta {
            finishing = true;
        } else if depth + 1 >= RR_START {
            let q = beta.max_element().min(0.95);
            if s.next_f32() >= q {
                break;
            }
            beta /= q;
        }
        if !beta.is_finite() {
            break;
        }
        ray = spawn(&hit, bs.wi);
    }
    l
}

/// Whether the segment from `hit` (leaving towards `wi`) to `target` is free. `target` has been moved off its
/// own surface, so the segment ends just short of it at any scale; the last 1e-5 of its length is not tested
/// either.
pub fn unoccluded(prep: &Prepared, hit: &Hit, wi: Vec3A, target: Vec3A) -> bool {
    let ray = spawn(hit, wi);
    let dist = (target - ray.o).length();
    !prep.geometry.occluded(&Ray::new(ray.o, (target - ray.o) / dist), dist * (1.0 - 1e-5))
}

/// Direct light at `hit` from one light chosen by power, sampled on the light. With `mis`, area-light samples
/// are weighted by the power heuristic against BSDF sampling (the caller then adds BSDF-sampled emission with
/// the complementary weight); without, light sampling carries the full estimate.
pub fn sample_one_light(
    prep: &Prepared,
    hit: &Hit,
    bsdf: &Bsdf,
    wo: Vec3A,
    s: &mut Sampler,
    rays: &mut u64,
    mis: bool,
) -> Rgb {
    let (u, u2) = (s.next_f32(), s.next_2d());
    let Some((i, pmf)) = prep.lights.choose(u) else { return Rgb::ZERO };
    let light = &prep.lights.lights[i];
    let Some(ls) = light.sample_li(&prep.geometry, hit.p, u2) else { return Rgb::ZERO };
    let f = bsdf.f(wo, ls.wi, TransportMode::Radiance);
    if f == Rgb::ZERO || ls.pdf <= 0.0 {
        return Rgb::ZERO;
    }
    *rays += 1;
    if !unoccluded(prep, hit, ls.wi, ls.p) {
        return Rgb::ZERO;
    }
    let cos = ls.wi.dot(hit.ns).abs();
    if ls.delta {
        f * ls.li * (cos / pmf)
    } else if !mis {
        f * ls.li * (cos / (pmf * ls.pdf))
    } else {
        let light_pdf = pmf * ls.pdf;
        let w = power_heuristic(light_pdf, bsdf.pdf(wo, ls.wi));
        f * ls.li * (cos * w / light_pdf)
    }
}

/// The photon maps a photon method reads, and how it gathers.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PhotonMaps {
    /// Every photon at a non-delta surface.
    pub global: PhotonMap,
    /// Light → specular⁺ → diffuse photons (for `final-gather`, on scenes with mirror or glass).
    pub caustic: Option<PhotonMap>,
    /// The radiance estimate's settings, with the radius resolved to scene units.
    pub estimator: Estimator,
    /// Irradiance precomputed at every fourth global photon (Christensen 1999), for `final-gather`: each
    /// entry's `power` holds the irradiance E (W/m²) at its position.
    pub irradiance: Option<PhotonMap>,
}

/// Precomputes irradiance at every `stride`-th photon of `global` (in parallel, in a fixed order).
pub fn precompute_irradiance(global: &PhotonMap, est: &Estimator, stride: usize) -> Vec<Photon> {
    use rayon::prelude::*;
    let picked: Vec<&Photon> = global.photons().iter().step_by(stride.max(1)).collect();
    picked
        .par_iter()
        .map(|ph| {
            let n = ph.normal();
            let e = SCRATCH
                .with_borrow_mut(|scratch| global.estimate(est, ph.position(), n, ph.object, |_| Rgb::ONE, scratch));
            Photon::new(ph.position(), n, n, e, ph.object)
        })
        .collect()
}

/// Radiance leaving a final-gather hit: the precomputed irradiance of the nearest entry facing the same way,
/// reflected as by a diffuse surface, `L = f(wo, n)·E` (exact for Lambert and the mixture's diffuse part; an
/// approximation for glossy surfaces, which final gathering blurs anyway). Falls back on the full estimate.
fn gathered_radiance(maps: &PhotonMaps, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> Rgb {
    let Some(irr) = &maps.irradiance else { return photon_radiance(&maps.global, &maps.estimator, hit, bsdf, wo) };
    let n = hit.normal_towards(wo);
    let radius = match maps.estimator.gather {
        crate::photon_map::Gather::KNearest { max_radius, .. } => max_radius,
        crate::photon_map::Gather::Radius { radius } => radius,
    };
    let found = SCRATCH.with_borrow_mut(|scratch| {
        irr.k_nearest(hit.p, 8, radius * radius, scratch);
        scratch
            .iter()
            .map(|&(i, _)| irr.photons()[i as usize])
            .find(|e| e.normal().dot(n) > 0.9 && (!maps.estimator.same_object || e.object == hit.object))
    });
    match found {
        Some(e) => bsdf.f(wo, n, TransportMode::Radiance) * e.phi(),
        None => photon_radiance(&maps.global, &maps.estimator, hit, bsdf, wo),
    }
}

thread_local! {
    /// Gather scratch of each rendering thread: no allocation per estimate.
    static SCRATCH: std::cell::RefCell<Vec<(u32, f32)>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Reflected radiance at `hit` towards `wo` from a photon map, through the non-delta part of `bsdf`.
pub fn photon_radiance(map: &PhotonMap, est: &Estimator, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> Rgb {
    let n = hit.normal_towards(wo);
    SCRATCH.with_borrow_mut(|scratch| {
        map.estimate(est, hit.p, n, hit.object, |wi| bsdf.f(wo, wi, TransportMode::Radiance), scratch)
    })
}

/// Progressive photon mapping's gather at `hit`: flux `Σ f·Φ` of the accepted photons and their count.
pub fn photon_flux(map: &PhotonMap, est: &Estimator, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> (Rgb, usize) {
    let n = hit.normal_towards(wo);
    SCRATCH.with_borrow_mut(|scratch| {
        map.gather_flux(est, hit.p, n, hit.object, |wi| bsdf.f(wo, wi, TransportMode::Radiance), scratch)
    })
}

/// A camera path followed through delta lobes to its first non-delta vertex: the emission it saw on the way,
/// and, if it found one, the vertex.
pub struct VisiblePoint {
    /// Emission seen through delta lobes (already weighted).
    pub le: Rgb,
    /// Throughput to the vertex, the vertex, its BSDF and the direction back along the path.
    pub vertex: Option<(Rgb, Hit, Bsdf, Vec3A)>,
}

/// Follows `ray` through mirror and glass to the first surface with a non-delta component. At a surface with
/// both (the mixture), the path continues only if the delta lobe is sampled, and that surface is the vertex.
pub fn visible_point(prep: &Prepared, max_depth: u32, mut ray: Ray, s: &mut Sampler, rays: &mut u64) -> VisiblePoint {
    let mut beta = Rgb::ONE;
    let mut le = Rgb::ZERO;
    for _ in 0..=max_depth {
        *rays += 1;
        let Some(hit) = prep.geometry.intersect(&ray, f32::INFINITY) else { break };
        let wo = -ray.d;
        if hit.light != NONE
            && let Some(light) = prep.lights.lights.get(hit.light as usize)
        {
            le += beta * light.le(&hit, wo);
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit);
        if bsdf.has_non_delta() {
            return VisiblePoint { le, vertex: Some((beta, hit, bsdf, wo)) };
        }
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if bs.pdf.is_nan() || bs.pdf <= 0.0 {
            break;
        }
        beta *= bs.f * (bs.wi.dot(hit.ns).abs() / bs.pdf);
        if !beta.is_finite() || beta == Rgb::ZERO {
            break;
        }
        ray = spawn(&hit, bs.wi);
    }
    VisiblePoint { le, vertex: None }
}

/// The photon methods `photon-map` and `final-gather` along one camera ray.
fn photon_li(
    prep: &Prepared,
    maps: &PhotonMaps,
    settings: &RenderSettings,
    ray: Ray,
    s: &mut Sampler,
    rays: &mut u64,
) -> Rgb {
    let mut l = Rgb::ZERO;
    let mut ray = ray;
    let mut beta = Rgb::ONE;
    // A mixture surface may send the path on through its delta lobe: follow a few such continuations.
    for _ in 0..=settings.max_depth {
        let vp = visible_point(prep, settings.max_depth, ray, s, rays);
        l += beta * vp.le;
        let Some((b, hit, bsdf, wo)) = vp.vertex else { break };
        beta *= b;
        match settings.integrator {
            Integrator::FinalGather => {
                l += beta * sample_one_light(prep, &hit, &bsdf, wo, s, rays, false);
                if let Some(caustic) = &maps.caustic {
                    l += beta * photon_radiance(caustic, &maps.estimator, &hit, &bsdf, wo);
                }
                l += beta * final_gather(prep, maps, settings, &hit, &bsdf, wo, s, rays);
            }
            _ => l += beta * photon_radiance(&maps.global, &maps.estimator, &hit, &bsdf, wo),
        }
        // Continue only through a delta lobe: the non-delta part is what the estimate above counted.
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if !bs.delta || bs.pdf.is_nan() || bs.pdf <= 0.0 {
            break;
        }
        beta *= bs.f * (bs.wi.dot(hit.ns).abs() / bs.pdf);
        if !beta.is_finite() || beta == Rgb::ZERO {
            break;
        }
        ray = spawn(&hit, bs.wi);
    }
    l
}

/// Indirect light at `hit` by final gathering: BSDF-sampled rays (non-delta lobes) to the next non-delta
/// surface, through mirror and glass, where the global map gives the radiance coming back. Emission found by
/// these rays is not counted: direct light and caustics have their own estimates.
#[allow(clippy::too_many_arguments)]
fn final_gather(
    prep: &Prepared,
    maps: &PhotonMaps,
    settings: &RenderSettings,
    hit: &Hit,
    bsdf: &Bsdf,
    wo: Vec3A,
    s: &mut Sampler,
    rays: &mut u64,
) -> Rgb {
    let n = settings.photons.final_gather_rays.max(1);
    let mut sum = Rgb::ZERO;
    for _ in 0..n {
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { continue };
        if bs.delta || bs.pdf.is_nan() || bs.pdf <= 0.0 {
            continue;
        }
        let w = bs.f * (bs.wi.dot(hit.ns).abs() / bs.pdf);
        let vp = visible_point(prep, settings.max_depth, spawn(hit, bs.wi), s, rays);
        if let Some((b, h2, bsdf2, wo2)) = vp.vertex {
            sum += w * b * gathered_radiance(maps, &h2, &bsdf2, wo2);
        }
    }
    sum / n as f32
}
