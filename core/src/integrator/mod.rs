//! Integrators: how the radiance arriving along one camera ray is estimated. One file per method:
//!
//! | method (`render.integrator`) | file | what it computes |
//! |---|---|---|
//! | `path`, `direct` | [`path`] | unbiased path tracing with next-event estimation and MIS; direct light only |
//! | `photon-map` | [`photon_map`] | the global photon map seen at the first non-delta surface |
//! | `final-gather` | [`final_gather`] | shadow rays + caustic map + final gathering of the global map |
//! | `progressive` | `render::progressive` | per-pixel statistics over passes: a strip-level method, not per ray |
//!
//! This module holds what they share: the dispatch ([`li`]), light sampling ([`sample_one_light`]), shadow rays
//! ([`unoccluded`]) and the walk through mirror and glass to the first non-delta surface ([`visible_point`]).
//! A new per-ray method is a file here, a variant of `scene::Integrator` and an arm of [`li`]; a method that
//! keeps state across samples of a pixel (like progressive photon mapping) goes next to the strip loop in
//! `render`.

pub mod final_gather;
pub mod path;
pub mod photon_map;

use crate::Rgb;
use crate::geometry::{Hit, NONE};
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::rng::Sampler;
use crate::math::{Ray, power_heuristic};
use crate::prepare::Prepared;
use crate::scene::Integrator;
use glam::Vec3A;

/// Radiance arriving along `ray`, by the integrator of the prepared job's settings. Counts every traced ray in
/// `rays`. Progressive photon mapping is not a per-ray method: `render::progressive` runs its passes and calls
/// [`visible_point`] instead; here it gives direct light only.
pub fn li(prep: &Prepared, ray: Ray, s: &mut Sampler, rays: &mut u64) -> Rgb {
    let settings = &prep.settings;
    match settings.integrator {
        Integrator::Path => path::li(prep, settings.max_depth, ray, s, rays, false),
        Integrator::Direct | Integrator::Progressive => path::li(prep, settings.max_depth, ray, s, rays, true),
        Integrator::PhotonMap | Integrator::FinalGather => match &prep.photons {
            Some(maps) => photon_map::li(prep, maps, ray, s, rays),
            None => path::li(prep, settings.max_depth, ray, s, rays, true),
        },
    }
}

/// Whether the segment from `hit` (leaving towards `wi`) to `target` is free. `target` has been moved off its
/// own surface, so the segment ends just short of it at any scale; the last 1e-5 of its length is not tested
/// either.
pub fn unoccluded(prep: &Prepared, hit: &Hit, wi: Vec3A, target: Vec3A) -> bool {
    let ray = hit.spawn_ray(wi);
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
    // Written so that a NaN pdf also returns: every division below is by a positive pdf or pmf.
    if f == Rgb::ZERO || !(ls.pdf > 0.0 && pmf > 0.0 && pmf * ls.pdf > 0.0) {
        return Rgb::ZERO;
    }
    *rays += 1;
    if !unoccluded(prep, hit, ls.wi, ls.p) {
        return Rgb::ZERO;
    }
    // The BSDF's shading normal: a bump or normal map bends it away from `hit.ns`.
    let cos = ls.wi.dot(bsdf.frame.n).abs();
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
        let bsdf = material.bsdf(&hit, &prep.textures);
        if bsdf.has_non_delta() {
            return VisiblePoint { le, vertex: Some((beta, hit, bsdf, wo)) };
        }
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if bs.pdf.is_nan() || bs.pdf <= 0.0 {
            break;
        }
        beta *= bs.f * (bs.wi.dot(bsdf.frame.n).abs() / bs.pdf);
        if !beta.is_finite() || beta == Rgb::ZERO {
            break;
        }
        ray = hit.spawn_ray(bs.wi);
    }
    VisiblePoint { le, vertex: None }
}
