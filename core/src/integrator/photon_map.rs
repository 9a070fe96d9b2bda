//! The photon-map methods that read maps traced before rendering:
//! - `photon-map`: the global map seen directly at the first non-delta surface (the origin's method);
//! - `final-gather`: Jensen's two passes. Direct light by shadow rays, caustics from the caustic map, and
//!   indirect light by final gathering: BSDF-sampled rays to the next non-delta surface, where the global map
//!   (through its precomputed irradiance, Christensen 1999) gives the radiance coming back.
//!
//! Both share the camera-path walk ([`walk`]).

use super::direct::photon_vertex_direct;
use super::visible::{VisiblePoint, visible_point, visible_point_in};
use super::volume::map_volume_estimate;
use crate::Rgb;
use crate::geometry::Hit;
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::Ray;
use crate::medium::Medium;
use crate::photon::{Gather, PhotonMaps, photon_radiance, with_scratch};
use crate::prepare::tracer::Tracer;
use glam::Vec3A;

/// The photon methods `photon-map` and `final-gather` along one camera ray: the estimate at the first non-delta
/// surface, and on through the delta lobe of a mixture surface. `final_gather` chooses Jensen's two passes (shadow
/// rays, the caustic map and final gathering) over the global map seen directly.
pub fn li(tracer: &mut Tracer, maps: &PhotonMaps, final_gather: bool, ray: Ray) -> Rgb {
    let prep = tracer.prep;
    let settings = &prep.settings;
    let mut l = Rgb::ZERO;
    let mut ray = ray;
    let mut beta = Rgb::ONE;
    let mut medium = prep.media.as_ref().and_then(|m| m.camera);
    // A mixture surface may send the path on through its delta lobe: follow a few such continuations.
    for _ in 0..=settings.max_depth {
        let vp = walk(tracer, maps, ray, medium);
        l += beta * (vp.le + vp.volume);
        let Some((b, hit, bsdf, wo)) = vp.vertex else { break };
        beta *= b;
        if final_gather {
            l += beta * photon_vertex_direct(tracer, &hit, &bsdf, wo, vp.medium);
            if let Some(caustic) = &maps.caustic {
                l += beta * photon_radiance(caustic, &maps.estimator, &hit, &bsdf, wo);
            }
            l += beta * gather_indirect(tracer, maps, &hit, &bsdf, wo, vp.medium);
        } else {
            l += beta * photon_radiance(&maps.global, &maps.estimator, &hit, &bsdf, wo);
        }
        // Continue only through a delta lobe: the non-delta part is what the estimate above counted. A zero
        // BSDF value, which `sample_bsdf` refuses, would have ended the path at the test below.
        let Some(bs) = tracer.sample_bsdf(&bsdf, wo, TransportMode::Radiance) else { break };
        if !bs.delta {
            break;
        }
        beta *= bsdf.sample_weight(wo, &bs, bs.pdf, TransportMode::Radiance);
        if !beta.is_finite() || beta == Rgb::ZERO {
            break;
        }
        medium = prep.media.as_ref().and_then(|m| m.after(&hit, bs.wi, vp.medium));
        ray = hit.spawn_ray(bs.wi);
    }
    l
}

/// The photon methods' walk to the first non-delta surface ([`visible_point_in`]) from a ray in `medium`,
/// estimating the volume along the way from the global volume map when there is one.
pub fn walk(tracer: &mut Tracer, maps: &PhotonMaps, ray: Ray, medium: Option<Medium>) -> VisiblePoint {
    let depth = tracer.prep.settings.max_depth;
    match &maps.volume {
        Some(v) => visible_point_in(tracer, depth, ray, medium, &mut |tracer, segment| {
            map_volume_estimate(v, maps.volume_gather, segment, &mut tracer.sampler)
        }),
        None => visible_point_in(tracer, depth, ray, medium, &mut |_, _| Rgb::ZERO),
    }
}

/// Indirect light at `hit` by final gathering: BSDF-sampled rays (non-delta lobes) to the next non-delta
/// surface, through mirror and glass, where the global map gives the radiance coming back. Emission found by
/// these rays is not counted: direct light and caustics have their own estimates. In a scene with media the
/// gather rays leave into the medium on their side of `hit` (`medium` is the one on `wo`'s side) and add the
/// global volume map's estimate along the way ([`walk`]).
fn gather_indirect(
    tracer: &mut Tracer,
    maps: &PhotonMaps,
    hit: &Hit,
    bsdf: &Bsdf,
    wo: Vec3A,
    medium: Option<Medium>,
) -> Rgb {
    let prep = tracer.prep;
    let settings = &prep.settings;
    let n = settings.photons.final_gather_rays.max(1);
    let mut sum = Rgb::ZERO;
    for _ in 0..n {
        // Not `Tracer::sample_bsdf`: a gather ray with a zero BSDF value still walks (and draws samples), so
        // refusing it would change the samples of the rays after it.
        let (u, u2) = (tracer.sampler.next_f32(), tracer.sampler.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { continue };
        if bs.delta || bs.pdf.is_nan() || bs.pdf <= 0.0 {
            continue;
        }
        let w = bsdf.sample_weight(wo, &bs, bs.pdf, TransportMode::Radiance);
        let ray = hit.spawn_ray(bs.wi);
        let vp = match &prep.media {
            None => visible_point(tracer, settings.max_depth, ray),
            Some(media) => {
                let vp = walk(tracer, maps, ray, media.after(hit, bs.wi, medium));
                sum += w * vp.volume;
                vp
            }
        };
        if let Some((b, h2, bsdf2, wo2)) = vp.vertex {
            sum += w * b * gathered_radiance(maps, &h2, &bsdf2, wo2);
        }
    }
    sum / n as f32
}

/// Radiance leaving a final-gather hit: the precomputed irradiance of the nearest entry facing the same way,
/// reflected as by a diffuse surface, `L = f(wo, n)·E` (exact for Lambert and the mixture's diffuse part; an
/// approximation for glossy surfaces, which final gathering blurs anyway). Falls back on the full estimate.
fn gathered_radiance(maps: &PhotonMaps, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> Rgb {
    let Some(irr) = &maps.irradiance else { return photon_radiance(&maps.global, &maps.estimator, hit, bsdf, wo) };
    let n = hit.normal_towards(wo);
    let radius = match maps.estimator.gather {
        Gather::KNearest { max_radius, .. } => max_radius,
        Gather::Radius { radius } => radius,
    };
    let found = with_scratch(|scratch| {
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
