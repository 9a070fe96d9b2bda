//! Light transport in participating media: the volumetric path tracer (`path` and `direct` in a scene with
//! media), the estimate of single scattering along a ray segment that it shares with progressive photon
//! mapping, and the volume photon estimates of the photon methods.
//!
//! # The path tracer
//! Along each segment in a medium the path samples a free flight (closed-form distance sampling,
//! [`Medium::sample_distance`]). Single scattering from the lights along the segment is estimated by
//! [`in_scattering`]: one light point, and two candidate distances combined by multiple importance sampling with
//! the power heuristic, one sampled **equiangularly** towards the light point and one the free flight itself
//! (Kulla & Fajardo 2012, §4.2). Equiangular sampling cancels the `1/r²` of a light near the ray, where distance
//! sampling in thin fog almost never lands; distance sampling wins far from the light in thick media. A flight
//! that scatters continues along a Henyey–Greenstein direction (its weight `p/pdf` is 1); emission that such a
//! direction finds on an area light is a third strategy for single scattering, and the three share the power
//! heuristic over densities on (distance, point on the light): phase sampling wins where an area light is near
//! and large, where sampling it by area gives `1/r²` spikes. Shadow rays carry the transmittance of their medium; surfaces in between
//! block them, as in a scene without media.
//!
//! # The photon methods
//! A camera walk ([`super::visible::visible_point_in`]) crosses each medium segment to its surface and estimates the
//! radiance scattered towards the camera at one point of the segment, sampled from the truncated free-flight
//! density ([`Medium::sample_segment`]): a ray march with one stochastic step, whose value is the volume photon
//! estimate there ([`crate::photon::volume_radiance`], a 3D box kernel, Jensen & Christensen 1998, §3.3).
//! `photon-map` and `final-gather` read the global volume map (direct light included); progressive photon
//! mapping estimates single scattering by [`in_scattering`] at the same point and reads its pass's volume map of
//! photons that have bounced at least once.

use super::direct::{emission, sample_one_light, shadow_transmittance};
use super::path::{PathState, roulette};
use super::visible::Segment;
use crate::Rgb;
use crate::geometry::NONE;
use crate::light::Light;
use crate::material::Material;
use crate::math::rng::Sampler;
use crate::math::{Ray, offset_ray_origin_by_error};
use crate::medium::{Equiangular, FreeFlight, HenyeyGreenstein, MAX_CROSSINGS, Media, Medium};
use crate::prepare::Prepared;
use crate::prepare::tracer::Tracer;
use glam::Vec3A;

/// Which candidate distances [`in_scattering`] uses: both with MIS (what the renderer does), or one alone
/// (for the tests that compare their variance).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Equiangular and free-flight distances, weighted by the power heuristic.
    Mis,
    /// The equiangular distance only.
    Equiangular,
    /// The free-flight distance only.
    Distance,
}

/// A point chosen on a light for one segment's single-scattering estimate.
#[derive(Clone, Copy, Debug)]
enum LightPoint {
    /// A point or spot light: its position and the light (for its intensity towards the medium point).
    Point { p: Vec3A, light: Light },
    /// A point on an area light: position, its error bound, the surface normal, radiance, sidedness, and the
    /// light's area (the point was chosen uniformly by area).
    Area { p: Vec3A, p_error: Vec3A, n: Vec3A, le: Rgb, two_sided: bool, area: f32 },
}

impl LightPoint {
    /// A light chosen by power (`u`) and a point on it (`u2`), with the light's choice probability.
    fn sample(prep: &Prepared, u: f32, u2: glam::Vec2) -> Option<(Self, f32)> {
        let (i, pmf) = prep.lights.choose(u)?;
        let lp = match prep.lights.lights[i] {
            l @ (Light::Point { p, .. } | Light::Spot { p, .. }) => LightPoint::Point { p, light: l },
            l @ Light::Area { prim, two_sided, area, .. } => {
                let (p, p_error, n) = prep.geometry.with_prim(prim, |p| p.shape.sample_area_with_error(u2))?;
                let le = l.le_at(&prep.light_scene(), p);
                LightPoint::Area { p, p_error, n, le, two_sided, area }
            }
            // Refused in scenes with media (`Scene::check`).
            Light::Directional { .. } | Light::Environment { .. } => return None,
        };
        (pmf > 0.0).then_some((lp, pmf))
    }

    fn position(&self) -> Vec3A {
        match *self {
            LightPoint::Point { p, .. } | LightPoint::Area { p, .. } => p,
        }
    }

    /// The light's area (0 for a point light).
    fn area(&self) -> f32 {
        match *self {
            LightPoint::Point { .. } => 0.0,
            LightPoint::Area { area, .. } => area,
        }
    }

    /// The light arriving at `x` in medium `m` from this point, divided by the pdf of the point on the light:
    /// `I/r²` for a point light, `L·|cos θl|·A/r²` for an area light; with its direction from `x`, the
    /// transmittance and visibility of the segment, and for an area light `|cos θl|/r²` (the factor that turns
    /// a solid-angle pdf at `x` into an area pdf on the light). Counts the shadow ray.
    fn incident(&self, tracer: &mut Tracer, x: Vec3A, m: &Medium) -> Option<(Vec3A, Rgb, f32)> {
        let (target, li, geometric) = match *self {
            LightPoint::Point { p, light } => {
                let d2 = (x - p).length_squared();
                (p, light.intensity((x - p) / d2.sqrt()) / d2, 0.0)
            }
            LightPoint::Area { p, p_error, n, le, two_sided, area } => {
                let d = p - x;
                let d2 = d.length_squared();
                let cos_l = -d.dot(n) / d2.sqrt();
                if !(two_sided || cos_l > 0.0) || cos_l == 0.0 {
                    return None;
                }
                let towards = if cos_l > 0.0 { n } else { -n };
                let g = cos_l.abs() / d2;
                (offset_ray_origin_by_error(p, p_error, n, towards), le * (g * area), g)
            }
        };
        let d = target - x;
        let dist = d.length();
        if !(dist > 0.0 && li.is_finite()) {
            return None;
        }
        let wi = d / dist;
        let tr = match &tracer.prep.media {
            Some(media) => shadow_transmittance(tracer, media, x, target, Some(*m)),
            None => Rgb::ZERO,
        };
        (tr != Rgb::ZERO).then_some((wi, li * tr, geometric))
    }
}

/// The three ways the path tracer finds light scattered once at distance `t` of a segment from a point `y` on
/// an area light, as densities over (t, y): equiangular distance and `y` by area, free-flight distance and `y`
/// by area, free-flight distance and a phase-sampled direction that hits `y`. Their power-heuristic weights
/// ([`mis_weight`]) sum to 1 (Veach 1997, §9.2.4; the three-strategy form of Kulla & Fajardo 2012, §4.2).
#[derive(Clone, Copy, Debug)]
struct Densities {
    equiangular: f32,
    distance: f32,
    phase: f32,
}

/// The power-heuristic weight of the strategy whose density is `own` among `d`, computed on the densities
/// divided by the largest, so that squares of large densities (a tiny light, g near ±1) do not overflow.
fn mis_weight(own: f32, d: Densities) -> f32 {
    let max = d.equiangular.max(d.distance).max(d.phase);
    if !(max > 0.0 && max.is_finite()) {
        return 0.0;
    }
    let (o, e, f, p) = (own / max, d.equiangular / max, d.distance / max, d.phase / max);
    o * o / (e * e + f * f + p * p)
}

/// Single scattering towards the ray's origin along `segment` (the stretch `[0, t_max)` of its ray in its
/// medium): `∫ T(t)·σs·p(ray.d, ωl)·L_light(x(t), ωl) dt`, estimated with one light point (chosen by power,
/// uniformly by area) and the candidate distances of `strategy`: an equiangular one towards the light point
/// (Kulla & Fajardo 2012, eq. 9) and `flight`, a distance the caller sampled with density `flight.1` (the path
/// tracer's free flight, when it scattered in the segment); `distance_pdf(t)` is that density at any `t` (per
/// scene unit), for the MIS weights (the power heuristic, Veach 1997 §9.2.4). With `phase_hits`, the caller
/// also counts emission that a phase-sampled direction from the free-flight point finds (the path tracer), and
/// area-light samples share the weight with that strategy (`emission_from_medium`). Draws the light, the
/// point on it and the equiangular distance from the tracer's stream, and counts its shadow rays. The result
/// (W·sr⁻¹·m⁻²) is not weighted by the path's throughput.
pub fn in_scattering(
    tracer: &mut Tracer,
    segment: &Segment,
    flight: Option<(f32, f32)>,
    distance_pdf: &dyn Fn(f32) -> f32,
    strategy: Strategy,
    phase_hits: bool,
) -> Rgb {
    let Segment { ray, medium: m, t_max } = *segment;
    let s = &mut tracer.sampler;
    let (u, u2, ue) = (s.next_f32(), s.next_2d(), s.next_f32());
    if !m.scatters() {
        return Rgb::ZERO;
    }
    let Some((light, pmf)) = LightPoint::sample(tracer.prep, u, u2) else { return Rgb::ZERO };
    let phase = HenyeyGreenstein { g: m.g };
    let eq = Equiangular::new(ray, t_max, light.position());
    // Per unit of length along the ray and of area on the light (a point light: per unit of length).
    let by_area = if light.area() > 0.0 { pmf / light.area() } else { pmf };
    // The integrand at distance t (divided by the light point's pdf) and the three densities there.
    let at = |t: f32, tracer: &mut Tracer| -> Option<(Rgb, Densities)> {
        let x = ray.at(t);
        let (wi, li, geometric) = light.incident(tracer, x, m)?;
        let p = phase.eval(ray.d, wi);
        let d_t = distance_pdf(t);
        let densities = Densities {
            equiangular: eq.as_ref().map_or(0.0, |e| e.pdf(t)) * by_area,
            distance: d_t * by_area,
            phase: if phase_hits { d_t * p * geometric } else { 0.0 },
        };
        Some((m.transmittance(ray, t) * m.sigma_s * li * p, densities))
    };
    let mut sum = Rgb::ZERO;
    if strategy != Strategy::Distance
        && let Some(eq) = &eq
    {
        let (t, pdf_e) = eq.sample(ue);
        if t < t_max
            && pdf_e > 0.0
            && pdf_e.is_finite()
            && let Some((f, d)) = at(t, tracer)
        {
            let w = if strategy == Strategy::Mis { mis_weight(d.equiangular, d) } else { 1.0 };
            sum += f * (w / pdf_e);
        }
    }
    if strategy != Strategy::Equiangular
        && let Some((t, pdf_d)) = flight
        && t < t_max
        && pdf_d > 0.0
        && let Some((f, d)) = at(t, tracer)
    {
        let w = if strategy == Strategy::Mis { mis_weight(d.distance, d) } else { 1.0 };
        sum += f * (w / pdf_d);
    }
    let l = sum / pmf;
    if l.is_finite() { l } else { Rgb::ZERO }
}

/// Where a path last scattered in a medium: the segment it scattered on, the distance and its free-flight
/// density, and the phase pdf of the direction it left in.
#[derive(Clone, Copy, Debug)]
struct Scattering {
    ray: Ray,
    t_max: f32,
    t: f32,
    distance_pdf: f32,
    phase_pdf: f32,
}

/// Emission at `hit` (at distance `hit.t` from the medium vertex `v`, along the phase-sampled `ray`), and its
/// weight against the segment's light samples ([`in_scattering`]).
fn emission_from_medium(prep: &Prepared, v: &Scattering, hit: &crate::geometry::Hit, ray: &Ray) -> (Rgb, f32) {
    if hit.light == NONE {
        return (Rgb::ZERO, 0.0);
    }
    let light = hit.light as usize;
    let Some(l @ &Light::Area { area, .. }) = prep.lights.lights.get(light) else { return (Rgb::ZERO, 0.0) };
    let le = l.le(&prep.light_scene(), hit, -ray.d);
    if le == Rgb::ZERO {
        return (le, 0.0);
    }
    let by_area = prep.lights.pmf(light) / area;
    let geometric = ray.d.dot(hit.n).abs() / (hit.t * hit.t);
    let eq = Equiangular::new(&v.ray, v.t_max, hit.p).map_or(0.0, |e| e.pdf(v.t));
    let densities = Densities {
        equiangular: eq * by_area,
        distance: v.distance_pdf * by_area,
        phase: v.distance_pdf * v.phase_pdf * geometric,
    };
    (le, mis_weight(densities.phase, densities))
}

/// Volumetric path tracing (`path`), or direct light with specular recursion (`direct_only`): see the module
/// documentation. Without media it would equal [`super::path::li`]; scenes without media never come here.
pub fn path_li(tracer: &mut Tracer, media: &Media, max_depth: u32, mut ray: Ray, direct_only: bool) -> Rgb {
    let prep = tracer.prep;
    let mut l = Rgb::ZERO;
    let mut path = PathState::new();
    // The last vertex was in a medium: emission found next shares its weight with the segment's light samples.
    let mut prev_medium: Option<Scattering> = None;
    let mut medium = media.camera;
    let mut depth = 0u32;
    // `interface` surfaces crossed since the last vertex, and the distance from that vertex to the ray's origin.
    let (mut crossings, mut travelled) = (0u32, 0.0f32);
    while depth <= max_depth {
        let found = tracer.intersect(&ray, f32::INFINITY);
        if let Some(m) = medium.filter(|m| !m.is_vacuum()) {
            let segment = Segment { ray: &ray, medium: &m, t_max: found.as_ref().map_or(f32::INFINITY, |h| h.t) };
            let flight = m.sample_distance(&ray, segment.t_max, &mut tracer.sampler);
            // Light scattered once at a point of this segment: like light sampling at a surface, only below the
            // last bounce; the phase-sampled strategy exists only where the path goes on from a scattering.
            if !path.finishing && depth < max_depth {
                l += path.beta * single_scattering(tracer, &segment, &flight, !direct_only);
            }
            path.beta *= flight.weight;
            if !path.beta.is_finite() || path.beta == Rgb::ZERO {
                break;
            }
            if flight.scattered {
                if path.finishing || direct_only || depth == max_depth {
                    break;
                }
                let Some((next, vertex)) = scatter(tracer, &segment, &flight, &mut path, depth) else { break };
                prev_medium = Some(vertex);
                ray = next;
                depth += 1;
                (crossings, travelled) = (0, 0.0);
                continue;
            }
        }
        let Some(mut hit) = found else { break };
        if prep.materials.get(hit.material as usize).is_some_and(Material::is_interface) {
            // Not a vertex: the ray goes on in the medium on the other side.
            crossings += 1;
            if crossings > MAX_CROSSINGS {
                break;
            }
            medium = media.after(&hit, ray.d, medium);
            travelled += hit.t;
            ray = hit.spawn_ray(ray.d);
            continue;
        }
        // Distances from the last vertex, for the MIS densities of emission found here.
        hit.t += travelled;
        let wo = -ray.d;
        let (le, w) = match &prev_medium {
            Some(v) => emission_from_medium(prep, v, &hit, &ray),
            None => emission(prep, &hit, &ray, path.prev_delta, path.prev_pdf),
        };
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
            l += path.beta * sample_one_light(tracer, &hit, &bsdf, wo, medium, true);
        }
        let Some(wi) = path.bounce(tracer, &bsdf, wo, depth, direct_only) else { break };
        prev_medium = None;
        medium = media.after(&hit, wi, medium);
        ray = hit.spawn_ray(wi);
        depth += 1;
        (crossings, travelled) = (0, 0.0);
    }
    l
}

/// The path tracer's single scattering along `segment` ([`in_scattering`] with both distances), the free
/// flight's distance as the second candidate where it scattered; `phase_hits` as there.
fn single_scattering(tracer: &mut Tracer, segment: &Segment, flight: &FreeFlight, phase_hits: bool) -> Rgb {
    let at = flight.scattered.then_some((flight.t, flight.pdf));
    let (ray, m) = (segment.ray, segment.medium);
    let pdf = |t: f32| m.distance_pdf(ray, t);
    in_scattering(tracer, segment, at, &pdf, Strategy::Mis, phase_hits)
}

/// The path tracer's scattering in a medium at the end of `flight` along `segment`, at bounce `depth`: a
/// Henyey–Greenstein direction (its weight `p/pdf` is 1), then Russian roulette as at a surface. The ray that
/// leaves and the vertex (for the MIS weight of emission found next), or `None` where the path ends.
fn scatter(
    tracer: &mut Tracer,
    segment: &Segment,
    flight: &FreeFlight,
    path: &mut PathState,
    depth: u32,
) -> Option<(Ray, Scattering)> {
    let ray = *segment.ray;
    let ps = HenyeyGreenstein { g: segment.medium.g }.sample(ray.d, tracer.sampler.next_2d());
    path.prev_delta = false;
    path.prev_pdf = ps.pdf;
    if !roulette(&mut path.beta, path.eta_scale, depth, &mut tracer.sampler) {
        return None;
    }
    let vertex = Scattering { ray, t_max: segment.t_max, t: flight.t, distance_pdf: flight.pdf, phase_pdf: ps.pdf };
    Some((Ray::new(ray.at(flight.t), ps.wi), vertex))
}

/// A distance in `segment` sampled from the truncated free-flight density ([`Medium::sample_segment`], two
/// samples from `s`), its density (per scene unit), and the weight `T(t)/p(t)` that turns a volume estimate
/// there into the segment's integral; `None` when the medium does not scatter.
pub fn segment_point(segment: &Segment, s: &mut Sampler) -> Option<(f32, f32, Rgb)> {
    let Segment { ray, medium: m, t_max } = *segment;
    let (t, pdf) = m.sample_segment(ray, t_max, s)?;
    Some((t, pdf, m.transmittance(ray, t) / pdf))
}

/// The photon methods' volume estimate along `segment` from a volume photon map (`photon-map`,
/// `final-gather`): at one point sampled by [`segment_point`], `T(t)/p(t) · Σ p(ωp, ωo)·Φp / V`.
pub fn map_volume_estimate(
    map: &crate::photon::PhotonMap,
    gather: crate::photon::Gather,
    segment: &Segment,
    s: &mut Sampler,
) -> Rgb {
    let Some((t, _, w)) = segment_point(segment, s) else { return Rgb::ZERO };
    let ray = segment.ray;
    let l = w * crate::photon::volume_radiance(map, ray.at(t), ray.d, segment.medium.g, gather);
    if l.is_finite() { l } else { Rgb::ZERO }
}
