//! `photon-map` (the global map seen directly at the first non-delta surface, the origin's method) and the
//! camera-path walk that `final-gather` shares with it.

use super::volume::map_volume_estimate;
use super::{VisiblePoint, final_gather, sample_one_light, visible_point_in};
use crate::Rgb;
use crate::material::bsdf::TransportMode;
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::medium::Medium;
use crate::photon::{PhotonMaps, photon_radiance};
use crate::prepare::Prepared;
use crate::scene::Integrator;

/// The photon methods `photon-map` and `final-gather` along one camera ray: the estimate at the first non-delta
/// surface, and on through the delta lobe of a mixture surface.
pub fn li(prep: &Prepared, maps: &PhotonMaps, ray: Ray, s: &mut Sampler, rays: &mut u64) -> Rgb {
    let settings = &prep.settings;
    let mut l = Rgb::ZERO;
    let mut ray = ray;
    let mut beta = Rgb::ONE;
    let mut medium = prep.media.as_ref().and_then(|m| m.camera);
    // A mixture surface may send the path on through its delta lobe: follow a few such continuations.
    for _ in 0..=settings.max_depth {
        let vp = walk(prep, maps, ray, medium, s, rays);
        l += beta * (vp.le + vp.volume);
        let Some((b, hit, bsdf, wo)) = vp.vertex else { break };
        beta *= b;
        match settings.integrator {
            Integrator::FinalGather => {
                l += beta * sample_one_light(prep, &hit, &bsdf, wo, vp.medium, s, rays, false);
                if let Some(caustic) = &maps.caustic {
                    l += beta * photon_radiance(caustic, &maps.estimator, &hit, &bsdf, wo);
                }
                l += beta * final_gather::indirect(prep, maps, &hit, &bsdf, wo, vp.medium, s, rays);
            }
            _ => l += beta * photon_radiance(&maps.global, &maps.estimator, &hit, &bsdf, wo),
        }
        // Continue only through a delta lobe: the non-delta part is what the estimate above counted.
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { break };
        if !bs.delta || bs.pdf.is_nan() || bs.pdf <= 0.0 {
            break;
        }
        beta *= bs.f * (bs.wi.dot(bsdf.frame.n).abs() / bs.pdf);
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
pub fn walk(
    prep: &Prepared,
    maps: &PhotonMaps,
    ray: Ray,
    medium: Option<Medium>,
    s: &mut Sampler,
    rays: &mut u64,
) -> VisiblePoint {
    let depth = prep.settings.max_depth;
    match &maps.volume {
        Some(v) => visible_point_in(prep, depth, ray, medium, s, rays, &mut |r, m, t_max, s, _| {
            map_volume_estimate(v, maps.volume_gather, r, m, t_max, s)
        }),
        None => visible_point_in(prep, depth, ray, medium, s, rays, &mut |_, _, _, _, _| Rgb::ZERO),
    }
}
