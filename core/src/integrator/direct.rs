//! Direct light at a surface: one light chosen by power and sampled on the light ([`sample_one_light`]), the
//! shadow ray that tests it ([`unoccluded`]), and in a scene with media the transmittance along it
//! ([`shadow_transmittance`]). Shared by every method's camera paths.

use crate::Rgb;
use crate::geometry::Hit;
use crate::material::Material;
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::{Ray, power_heuristic};
use crate::medium::{MAX_CROSSINGS, Media, Medium};
use crate::prepare::Prepared;
use crate::prepare::tracer::Tracer;
use glam::Vec3A;

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
pub fn sample_one_light(
    tracer: &mut Tracer,
    hit: &Hit,
    bsdf: &Bsdf,
    wo: Vec3A,
    medium: Option<Medium>,
    mis: bool,
) -> Rgb {
    let prep = tracer.prep;
    let (u, u2) = (tracer.sampler.next_f32(), tracer.sampler.next_2d());
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
            tracer.rays += 1;
            if !unoccluded(prep, hit, ls.wi, ls.p) {
                return Rgb::ZERO;
            }
            f
        }
        Some(media) => {
            let origin = hit.spawn_ray(ls.wi).o;
            let tr = shadow_transmittance(tracer, media, origin, ls.p, media.after(hit, ls.wi, medium));
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

/// The transmittance from `origin`, in `medium`, to `target`: 0 when a surface is in the way, else the product
/// of each medium's `e^(−σt·d)` over the pieces between `interface` surfaces, whose crossing changes the medium
/// ([`Media::after`]). The last 10⁻⁵ of the distance is not tested (the target has been moved off its surface).
/// Counts the rays it traces.
pub fn shadow_transmittance(
    tracer: &mut Tracer,
    media: &Media,
    origin: Vec3A,
    target: Vec3A,
    mut medium: Option<Medium>,
) -> Rgb {
    let prep = tracer.prep;
    let mut o = origin;
    let mut tr = Rgb::ONE;
    for _ in 0..=MAX_CROSSINGS {
        let d = target - o;
        let dist = d.length();
        if dist.is_nan() || dist <= 0.0 {
            return tr;
        }
        let ray = Ray::new(o, d / dist);
        let reach = dist * (1.0 - 1e-5);
        if !media.interfaces {
            tracer.rays += 1;
            if prep.geometry.occluded(&ray, reach) {
                return Rgb::ZERO;
            }
            return medium.map_or(tr, |m| tr * m.transmittance(&ray, dist));
        }
        let Some(hit) = tracer.intersect(&ray, reach) else {
            return medium.map_or(tr, |m| tr * m.transmittance(&ray, dist));
        };
        if !prep.materials.get(hit.material as usize).is_some_and(Material::is_interface) {
            return Rgb::ZERO;
        }
        if let Some(m) = medium {
            tr *= m.transmittance(&ray, hit.t);
        }
        medium = media.after(&hit, ray.d, medium);
        o = hit.spawn_ray(ray.d).o;
    }
    Rgb::ZERO
}
