//! Direct light at a surface: one light chosen by power and sampled on the light ([`sample_one_light`]), the
//! shadow ray that tests it ([`unoccluded`]), and in a scene with media the transmittance along it
//! ([`shadow_transmittance`]). Shared by every method's camera paths.

use crate::Rgb;
use crate::geometry::{Hit, NONE};
use crate::light::LightSample;
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

/// Whether light sample `ls` reaches `hit`: the segment to its point is free ([`unoccluded`]), or for an
/// infinitely distant light, the ray towards it escapes.
pub fn reaches(prep: &Prepared, hit: &Hit, ls: &LightSample) -> bool {
    if ls.infinite() {
        !prep.geometry.occluded(&hit.spawn_ray(ls.wi), f32::INFINITY)
    } else {
        unoccluded(prep, hit, ls.wi, ls.p)
    }
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
    let Some(ls) = light.sample_li(&prep.light_scene(), hit.p, u2) else { return Rgb::ZERO };
    let f = bsdf.f(wo, ls.wi, TransportMode::Radiance);
    // Written so that a NaN pdf also returns: every division below is by a positive pdf or pmf.
    if f == Rgb::ZERO || !(ls.pdf > 0.0 && pmf > 0.0 && pmf * ls.pdf > 0.0) {
        return Rgb::ZERO;
    }
    let f = match &prep.media {
        None => {
            tracer.rays += 1;
            if !reaches(prep, hit, &ls) {
                return Rgb::ZERO;
            }
            f
        }
        // Infinitely distant lights are refused in scenes with media (`Scene::check`).
        Some(_) if ls.infinite() => return Rgb::ZERO,
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

/// Direct light at the vertex where `final-gather` and `progressive` estimate density: light sampling alone
/// ([`sample_one_light`] without MIS) at a surface whose lobes are diffuse, and at a glossy one (a metal rough
/// enough to hold photons, a Phong lobe without diffuse part; [`crate::material::bsdf::Bxdf::photon_alpha`]
/// finite) one light sample and one BSDF sample joined by the power heuristic (Veach 1997, §9.2): there light
/// sampling alone sends rare, bright samples into the narrow lobe. The BSDF sample counts only the emission it hits first; light that reaches it through
/// mirror or glass is the caustic estimate's. In a scene with media, light sampling alone everywhere.
pub fn photon_vertex_direct(tracer: &mut Tracer, hit: &Hit, bsdf: &Bsdf, wo: Vec3A, medium: Option<Medium>) -> Rgb {
    let prep = tracer.prep;
    if prep.media.is_some() || !bsdf.bxdf.photon_alpha().is_finite() {
        return sample_one_light(tracer, hit, bsdf, wo, medium, false);
    }
    let mut l = sample_one_light(tracer, hit, bsdf, wo, medium, true);
    let Some(bs) = tracer.sample_bsdf(bsdf, wo, TransportMode::Radiance) else { return l };
    if bs.delta {
        return l;
    }
    let ray = hit.spawn_ray(bs.wi);
    let (le, w) = match tracer.intersect(&ray, f32::INFINITY) {
        Some(h) => emission(prep, &h, &ray, false, bs.pdf),
        None => escaped(prep, &ray, false, bs.pdf),
    };
    if le != Rgb::ZERO {
        l += bsdf.sample_weight(wo, &bs, bs.pdf, TransportMode::Radiance) * le * w;
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
    let le = light.le(&prep.light_scene(), hit, -ray.d);
    if le == Rgb::ZERO || prev_delta {
        return (le, 1.0);
    }
    let light_pdf = prep.lights.pmf(hit.light as usize) * light.pdf_li(ray, hit);
    (le, power_heuristic(prev_pdf, light_pdf))
}

/// The environment's radiance along `ray`, which escaped the scene from a surface vertex (or the camera), and
/// its MIS weight as [`emission`]'s: 1 after a delta lobe or the camera, else the power heuristic against light
/// sampling's density of the direction. Zero without an environment.
pub(super) fn escaped(prep: &Prepared, ray: &Ray, prev_delta: bool, prev_pdf: f32) -> (Rgb, f32) {
    let Some((i, env)) = prep.lights.environment() else { return (Rgb::ZERO, 0.0) };
    let scene = prep.light_scene();
    let le = env.le_escaped(&scene, ray.d);
    if le == Rgb::ZERO || prev_delta {
        return (le, 1.0);
    }
    let light_pdf = prep.lights.pmf(i) * env.pdf_escaped(&scene, ray.d);
    (le, power_heuristic(prev_pdf, light_pdf))
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
