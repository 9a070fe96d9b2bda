//! Integrators: how the radiance arriving along one camera ray is estimated, for the methods whose unit is a
//! camera sample ([`crate::method::CameraEstimator`]), and the pieces every method's camera paths share.
//!
//! | estimator | file | what it computes |
//! |---|---|---|
//! | `Path`, `Direct` | [`path`] | unbiased path tracing with next-event estimation and MIS; direct light only |
//! | `PhotonMap`, `FinalGather` | [`photon_map`] | the global map seen at the first non-delta surface; shadow rays + caustic map + final gathering |
//!
//! The pass methods live in `render`: `render::progressive` (photon passes) and `render::vcm` (light and camera
//! subpaths). A scene with participating media (or an `interface` material) takes [`volume`]'s paths instead:
//! the volumetric path tracer for `Path` and `Direct`, and the media-aware walk ([`visible_point_in`]) for the
//! photon methods; a scene without media never runs medium code.
//!
//! This module holds what they share: the one dispatch ([`estimate`]), light sampling ([`sample_one_light`]),
//! shadow rays ([`unoccluded`]) and the walk through mirror and glass to the first non-delta surface
//! ([`visible_point`]). A new per-ray estimator is a file here, a variant of `method::CameraEstimator` and an
//! arm of [`estimate`].

pub mod path;
pub mod photon_map;
pub mod volume;

use crate::Rgb;
use crate::geometry::{Hit, NONE};
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::rng::Sampler;
use crate::math::{Ray, power_heuristic};
use crate::medium::Medium;
use crate::method::{CameraEstimator, Technique};
use crate::prepare::Prepared;
use glam::Vec3A;

/// Radiance arriving along `ray`, by the camera estimator of the prepared job's method
/// ([`Method::technique`]). Counts every traced ray in `rays`. Progressive photon mapping, `vcm`, `bdpt` and
/// `lt` are not per-ray methods: their pass renderers (`render::progressive`, `render::vcm`) trace their own
/// light paths; here progressive gives direct light (what its passes add photons to) and the subpath methods
/// trace full paths (what their passes fall back to in a scene with media).
pub fn li(prep: &Prepared, ray: Ray, s: &mut Sampler, rays: &mut u64) -> Rgb {
    let estimator = match prep.settings.integrator.technique(prep.media.is_some(), prep.photons.is_some()) {
        Technique::Samples(e) => e,
        Technique::PhotonPasses => CameraEstimator::Direct,
        Technique::Subpaths(_) => CameraEstimator::Path,
    };
    estimate(prep, estimator, ray, s, rays)
}

/// Radiance arriving along `ray` by `estimator`: the one dispatch of the per-ray methods, in scenes with and
/// without media. A photon-map estimator without the job's maps gives direct light.
pub fn estimate(prep: &Prepared, estimator: CameraEstimator, ray: Ray, s: &mut Sampler, rays: &mut u64) -> Rgb {
    let depth = prep.settings.max_depth;
    let path = |direct: bool, s: &mut Sampler, rays: &mut u64| match &prep.media {
        None => path::li(prep, depth, ray, s, rays, direct),
        Some(media) => volume::path_li(prep, media, depth, ray, s, rays, direct),
    };
    match (estimator, &prep.photons) {
        (CameraEstimator::Path, _) => path(false, s, rays),
        (CameraEstimator::Direct, _) | (CameraEstimator::PhotonMap | CameraEstimator::FinalGather, None) => {
            path(true, s, rays)
        }
        (CameraEstimator::PhotonMap, Some(maps)) => photon_map::li(prep, maps, false, ray, s, rays),
        (CameraEstimator::FinalGather, Some(maps)) => photon_map::li(prep, maps, true, ray, s, rays),
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
/// the complementary weight); without, light sampling carries the full estimate. `medium` is the medium on
/// the side the path arrived from; in a scene with media the shadow ray carries the transmittance of the
/// medium it leaves into ([`crate::medium::Media::after`]).
#[allow(clippy::too_many_arguments)]
pub fn sample_one_light(
    prep: &Prepared,
    hit: &Hit,
    bsdf: &Bsdf,
    wo: Vec3A,
    medium: Option<Medium>,
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
    let f = match &prep.media {
        None => {
            *rays += 1;
            if !unoccluded(prep, hit, ls.wi, ls.p) {
                return Rgb::ZERO;
            }
            f
        }
        Some(media) => {
            let origin = hit.spawn_ray(ls.wi).o;
            let tr = volume::shadow_transmittance(prep, media, origin, ls.p, media.after(hit, ls.wi, medium), rays);
            if tr == Rgb::ZERO {
                return Rgb::ZERO;
            }
            f * tr
        }
    };
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
    /// In a scene with media, the radiance the walk's volume estimate gave along the way (already weighted).
    pub volume: Rgb,
    /// Throughput to the vertex, the vertex, its BSDF and the direction back along the path.
    pub vertex: Option<(Rgb, Hit, Bsdf, Vec3A)>,
    /// The medium on the path's side of the vertex (`None` in vacuum and in scenes without media).
    pub medium: Option<Medium>,
}

/// What a walk through a medium adds along one segment: given the ray, the medium (not vacuum), the distance
/// to the surface (∞ when none), the sampler and the ray count, the radiance scattered towards the ray's
/// origin along the segment, not yet weighted by the path's throughput.
pub type VolumeEstimate<'a> = dyn FnMut(&Ray, &Medium, f32, &mut Sampler, &mut u64) -> Rgb + 'a;

/// Follows `ray` through mirror and glass to the first surface with a non-delta component. At a surface with
/// both (the mixture), the path continues only if the delta lobe is sampled, and that surface is the vertex.
/// In a scene without media.
pub fn visible_point(prep: &Prepared, max_depth: u32, ray: Ray, s: &mut Sampler, rays: &mut u64) -> VisiblePoint {
    visible_point_in(prep, max_depth, ray, None, s, rays, &mut |_, _, _, _, _| Rgb::ZERO)
}

/// [`visible_point`] from a ray that starts in `medium`: along every segment in a medium the walk adds
/// `volume`'s estimate and carries on to the surface with the segment's transmittance (no free flight: every
/// walk reaches its surface, so photon methods estimate both the volume and the surface behind it).
pub fn visible_point_in(
    prep: &Prepared,
    max_depth: u32,
    mut ray: Ray,
    mut medium: Option<Medium>,
    s: &mut Sampler,
    rays: &mut u64,
    volume: &mut VolumeEstimate,
) -> VisiblePoint {
    let mut beta = Rgb::ONE;
    let mut le = Rgb::ZERO;
    let mut in_volume = Rgb::ZERO;
    // Crossings of `interface` surfaces are not bounces.
    let (mut bounces, mut crossings) = (0u32, 0u32);
    while bounces <= max_depth {
        *rays += 1;
        let found = prep.geometry.intersect(&ray, f32::INFINITY);
        if let Some(m) = medium.filter(|m| !m.is_vacuum()) {
            let t_max = found.as_ref().map_or(f32::INFINITY, |h| h.t);
            in_volume += beta * volume(&ray, &m, t_max, s, rays);
            beta *= m.transmittance(t_max);
            if beta == Rgb::ZERO {
                break;
            }
        }
        let Some(hit) = found else { break };
        let wo = -ray.d;
        if hit.light != NONE
            && let Some(light) = prep.lights.lights.get(hit.light as usize)
        {
            le += beta * light.le(&hit, wo);
        }
        let Some(material) = prep.materials.get(hit.material as usize) else { break };
        if let Some(media) = &prep.media
            && material.is_interface()
        {
            // Not a vertex: the walk goes on in the medium on the other side.
            crossings += 1;
            if crossings > crate::medium::MAX_CROSSINGS {
                break;
            }
            medium = media.after(&hit, ray.d, medium);
            ray = hit.spawn_ray(ray.d);
            continue;
        }
        let bsdf = material.bsdf(&hit, &prep.textures);
        if bsdf.black_from(wo) {
            break;
        }
        if bsdf.has_non_delta() {
            return VisiblePoint { le, volume: in_volume, vertex: Some((beta, hit, bsdf, wo)), medium };
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
        if let Some(media) = &prep.media {
            medium = media.after(&hit, bs.wi, medium);
        }
        ray = hit.spawn_ray(bs.wi);
        (bounces, crossings) = (bounces + 1, 0);
    }
    VisiblePoint { le, volume: in_volume, vertex: None, medium }
}
