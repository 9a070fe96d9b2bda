//! `final-gather`: Jensen's two passes. Direct light by shadow rays, caustics from the caustic map, and
//! indirect light by final gathering: BSDF-sampled rays to the next non-delta surface, where the global map
//! (through its precomputed irradiance, Christensen 1999) gives the radiance coming back.

use super::visible_point;
use crate::Rgb;
use crate::geometry::Hit;
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::rng::Sampler;
use crate::medium::Medium;
use crate::photon::{Gather, PhotonMaps, photon_radiance, with_scratch};
use crate::prepare::Prepared;
use glam::Vec3A;

/// Indirect light at `hit` by final gathering: BSDF-sampled rays (non-delta lobes) to the next non-delta
/// surface, through mirror and glass, where the global map gives the radiance coming back. Emission found by
/// these rays is not counted: direct light and caustics have their own estimates. In a scene with media the
/// gather rays leave into the medium on their side of `hit` (`medium` is the one on `wo`'s side) and add the
/// global volume map's estimate along the way ([`super::photon_map::walk`]).
#[allow(clippy::too_many_arguments)]
pub fn indirect(
    prep: &Prepared,
    maps: &PhotonMaps,
    hit: &Hit,
    bsdf: &Bsdf,
    wo: Vec3A,
    medium: Option<Medium>,
    s: &mut Sampler,
    rays: &mut u64,
) -> Rgb {
    let settings = &prep.settings;
    let n = settings.photons.final_gather_rays.max(1);
    let mut sum = Rgb::ZERO;
    for _ in 0..n {
        let (u, u2) = (s.next_f32(), s.next_2d());
        let Some(bs) = bsdf.sample(wo, u, u2, TransportMode::Radiance) else { continue };
        if bs.delta || bs.pdf.is_nan() || bs.pdf <= 0.0 {
            continue;
        }
        let w = bs.f * (bs.wi.dot(bsdf.frame.n).abs() / bs.pdf);
        let ray = hit.spawn_ray(bs.wi);
        let vp = match &prep.media {
            None => visible_point(prep, settings.max_depth, ray, s, rays),
            Some(media) => {
                let vp = super::photon_map::walk(prep, maps, ray, media.after(hit, bs.wi, medium), s, rays);
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
