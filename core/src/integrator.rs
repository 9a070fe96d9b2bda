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
use crate::prepare::Prepared;
use crate::rng::Sampler;
use crate::scene::{Integrator, RenderSettings};
use glam::Vec3A;

/// Bounces before Russian roulette may end a path.
const RR_START: u32 = 3;

/// Radiance arriving along `ray`, by the integrator of `settings`. Counts every traced ray in `rays`.
pub fn li(prep: &Prepared, settings: &RenderSettings, ray: Ray, s: &mut Sampler, rays: &mut u64) -> Rgb {
    match settings.integrator {
        Integrator::Path => trace(prep, settings.max_depth, ray, s, rays, false),
        Integrator::Direct => trace(prep, settings.max_depth, ray, s, rays, true),
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
        if hit.light != NONE {
            if let Some(light) = prep.lights.lights.get(hit.light as usize) {
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
        }
        if finishing || depth == max_depth {
            break;
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit);
        if bsdf.has_non_delta() {
            l += beta * sample_one_light(prep, &hit, &bsdf, wo, s, rays);
        }
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if !(bs.pdf > 0.0) || bs.f == Rgb::ZERO {
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

/// Direct light at `hit` from one light chosen by power, sampled on the light and weighted by MIS against BSDF
/// sampling (point lights take the full weight).
pub fn sample_one_light(prep: &Prepared, hit: &Hit, bsdf: &Bsdf, wo: Vec3A, s: &mut Sampler, rays: &mut u64) -> Rgb {
    let (u, u2) = (s.next_f32(), s.next_2d());
    let Some((i, pmf)) = prep.lights.choose(u) else { return Rgb::ZERO };
    let light = &prep.lights.lights[i];
    let Some(ls) = light.sample_li(&prep.geometry, hit.p, u2) else { return Rgb::ZERO };
    let f = bsdf.f(wo, ls.wi, TransportMode::Radiance);
    if f == Rgb::ZERO || ls.pdf <= 0.0 {
        return Rgb::ZERO;
    }
    *rays += 1;
    // Stop short of the light's own surface; the margin is relative, so it holds at any scale.
    if prep.geometry.occluded(&spawn(hit, ls.wi), ls.dist * (1.0 - 1e-4)) {
        return Rgb::ZERO;
    }
    let cos = ls.wi.dot(hit.ns).abs();
    if ls.delta {
        f * ls.li * (cos / pmf)
    } else {
        let light_pdf = pmf * ls.pdf;
        let w = power_heuristic(light_pdf, bsdf.pdf(wo, ls.wi));
        f * ls.li * (cos * w / light_pdf)
    }
}
