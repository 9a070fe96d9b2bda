//! `path` and `direct`: the unbiased path tracer that serves as the reference for every accuracy comparison,
//! and direct lighting with specular recursion.
//!
//! Both follow mirror and glass (delta lobes) from the camera. At each non-delta vertex the path tracer
//! estimates direct light by sampling one light (chosen by power) and by sampling the BSDF, weighting the two
//! with the power heuristic (Veach 1997, §9.2); the BSDF sample then continues the path, ended by Russian
//! roulette once its throughput, without the η² of refraction, falls below 1. The direct integrator stops after that first BSDF sample.

use super::direct::sample_one_light;
use crate::Rgb;
use crate::geometry::{Hit, NONE};
use crate::material::bsdf::TransportMode;
use crate::math::rng::Sampler;
use crate::math::{Ray, power_heuristic};
use crate::prepare::Prepared;

/// Bounces before Russian roulette may end a path.
const RR_START: u32 = 3;

/// Radiance arriving along `ray` by path tracing with at most `max_depth` bounces; with `direct_only`, the
/// path ends after the first non-delta BSDF sample (direct light, through mirror and glass).
pub fn li(prep: &Prepared, max_depth: u32, mut ray: Ray, s: &mut Sampler, rays: &mut u64, direct_only: bool) -> Rgb {
    let mut l = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    // The last bounce was a delta lobe (or the camera): emission is counted in full, not by MIS.
    let mut prev_delta = true;
    let mut prev_pdf = 0.0f32;
    let mut finishing = false;
    // Product of η² over the refractions so far: `beta · eta_scale` is the throughput without the 1/η² scaling
    // of radiance across glass, which Russian roulette must not mistake for absorption.
    let mut eta_scale = 1.0f32;
    for depth in 0..=max_depth {
        *rays += 1;
        let Some(hit) = prep.geometry.intersect(&ray, f32::INFINITY) else { break };
        let wo = -ray.d;
        let (le, w) = emission(prep, &hit, &ray, prev_delta, prev_pdf);
        if le != Rgb::ZERO {
            l += beta * le * w;
        }
        if finishing || depth == max_depth {
            break;
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit, &prep.textures);
        if bsdf.black_from(wo) {
            break;
        }
        if bsdf.has_non_delta() {
            l += beta * sample_one_light(prep, &hit, &bsdf, wo, None, s, rays, true);
        }
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if bs.pdf.is_nan() || bs.pdf <= 0.0 || bs.f == Rgb::ZERO {
            break;
        }
        beta *= bs.f * (bs.wi.dot(bsdf.frame.n).abs() / bs.pdf);
        prev_delta = bs.delta;
        prev_pdf = bs.pdf;
        if direct_only && !bs.delta {
            finishing = true;
        } else {
            eta_scale *= bs.eta * bs.eta;
            if !roulette(&mut beta, eta_scale, depth, s) {
                break;
            }
        }
        if !beta.is_finite() {
            break;
        }
        ray = hit.spawn_ray(bs.wi);
    }
    l
}

/// Emission at `hit`, reached along `ray` from a surface vertex (or the camera), and its MIS weight: 1 after a
/// delta lobe or the camera (`prev_delta`), else the power heuristic of the BSDF sample's pdf `prev_pdf` against
/// light sampling's.
pub(super) fn emission(prep: &Prepared, hit: &Hit, ray: &Ray, prev_delta: bool, prev_pdf: f32) -> (Rgb, f32) {
    if hit.light == NONE {
        return (Rgb::ZERO, 0.0);
    }
    let Some(light) = prep.lights.lights.get(hit.light as usize) else { return (Rgb::ZERO, 0.0) };
    let le = light.le(hit, -ray.d);
    if le == Rgb::ZERO || prev_delta {
        return (le, 1.0);
    }
    let light_pdf = prep.lights.pmf(hit.light as usize) * light.pdf_li(ray, hit);
    (le, power_heuristic(prev_pdf, light_pdf))
}

/// Russian roulette: past [`RR_START`] bounces, a path whose throughput (η² scaling undone: `eta_scale` is the
/// product of η² over its refractions) has fallen below 1 survives with that probability and is divided by it
/// (pbrt-v4). A path through lossless glass keeps throughput 1 and is never ended at random, so a glass object
/// in a white furnace is 1 in every sample, not only on average. Returns whether the path survives.
pub(super) fn roulette(beta: &mut Rgb, eta_scale: f32, depth: u32, s: &mut Sampler) -> bool {
    let rr_beta = beta.max_element() * eta_scale;
    if depth + 1 >= RR_START && rr_beta < 1.0 {
        if s.next_f32() >= rr_beta {
            return false;
        }
        *beta /= rr_beta;
    }
    true
}
