//! `path` and `direct`: the unbiased path tracer that serves as the reference for every accuracy comparison,
//! and direct lighting with specular recursion.
//!
//! Both follow mirror and glass (delta lobes) from the camera. At each non-delta vertex the path tracer
//! estimates direct light by sampling one light (chosen by power) and by sampling the BSDF, weighting the two
//! with the power heuristic (Veach 1997, §9.2); the BSDF sample then continues the path, ended by Russian
//! roulette once its throughput, without the η² of refraction, falls below 1. The direct integrator stops after
//! that first BSDF sample. That bounce (`PathState::bounce`) is the volumetric path tracer's too
//! ([`super::volume::path_li`]).

use super::direct::{emission, escaped, sample_one_light};
use crate::Rgb;
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::prepare::tracer::Tracer;
use glam::Vec3A;

/// Bounces before Russian roulette may end a path.
const RR_START: u32 = 3;

/// Radiance arriving along `ray` by path tracing with at most `max_depth` bounces; with `direct_only`, the
/// path ends after the first non-delta BSDF sample (direct light, through mirror and glass).
pub fn li(tracer: &mut Tracer, max_depth: u32, mut ray: Ray, direct_only: bool) -> Rgb {
    let prep = tracer.prep;
    let mut l = Rgb::ZERO;
    let mut path = PathState::new();
    for depth in 0..=max_depth {
        let Some(hit) = tracer.intersect(&ray, f32::INFINITY) else {
            let (le, w) = escaped(prep, &ray, path.prev_delta, path.prev_pdf);
            if le != Rgb::ZERO {
                l += path.beta * le * w;
            }
            break;
        };
        let wo = -ray.d;
        let (le, w) = emission(prep, &hit, &ray, path.prev_delta, path.prev_pdf);
        if le != Rgb::ZERO {
            l += path.beta * le * w;
        }
        if path.finishing || depth == max_depth {
            break;
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        let bsdf = material.bsdf(&hit, &prep.textures);
        if bsdf.black_from(wo) {
            break;
        }
        if bsdf.has_non_delta() {
            l += path.beta * sample_one_light(tracer, &hit, &bsdf, wo, None, true);
        }
        let Some(wi) = path.bounce(tracer, &bsdf, wo, depth, direct_only) else { break };
        ray = hit.spawn_ray(wi);
    }
    l
}

/// What a camera path of the path tracers (this one and [`super::volume::path_li`]) carries from vertex to
/// vertex besides its radiance.
#[derive(Clone, Copy, Debug)]
pub(super) struct PathState {
    /// Throughput.
    pub beta: Rgb,
    /// The last bounce was a delta lobe (or the camera): emission is counted in full, not by MIS.
    pub prev_delta: bool,
    /// The solid-angle density of the last bounce's direction (BSDF or phase function), for MIS.
    pub prev_pdf: f32,
    /// Direct light only: the path has taken its one non-delta BSDF sample and ends at the next hit.
    pub finishing: bool,
    /// Product of η² over the refractions so far: `beta · eta_scale` is the throughput without the 1/η²
    /// scaling of radiance across glass, which Russian roulette must not mistake for absorption.
    pub eta_scale: f32,
}

impl PathState {
    /// A path leaving the camera.
    pub fn new() -> Self {
        Self { beta: Rgb::ONE, prev_delta: true, prev_pdf: 0.0, finishing: false, eta_scale: 1.0 }
    }

    /// The surface bounce of bounce `depth` at a surface with `bsdf`, reached from `wo`: a BSDF sample
    /// ([`Tracer::sample_bsdf`]), the throughput times `f·|wi·ns|/pdf`, and then either the end of a direct-only
    /// path at its first non-delta sample (`finishing`) or the η² bookkeeping and Russian roulette
    /// ([`roulette`]). The direction the path continues in, or `None` where it ends.
    // Always inlined, as the two loops held this code before they shared it (as a call of its own it added
    // about 0.9 % instructions to a path-traced render).
    #[inline(always)]
    pub fn bounce(
        &mut self,
        tracer: &mut Tracer,
        bsdf: &Bsdf,
        wo: Vec3A,
        depth: u32,
        direct_only: bool,
    ) -> Option<Vec3A> {
        let bs = tracer.sample_bsdf(bsdf, wo, TransportMode::Radiance)?;
        self.beta *= bsdf.sample_weight(wo, &bs, bs.pdf, TransportMode::Radiance);
        self.prev_delta = bs.delta;
        self.prev_pdf = bs.pdf;
        if direct_only && !bs.delta {
            self.finishing = true;
        } else {
            self.eta_scale *= bs.eta * bs.eta;
            if !roulette(&mut self.beta, self.eta_scale, depth, &mut tracer.sampler) {
                return None;
            }
        }
        self.beta.is_finite().then_some(bs.wi)
    }
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
