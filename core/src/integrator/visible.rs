//! The walk of a camera path through mirror and glass (and across media) to its first non-delta vertex, which
//! the photon methods estimate at.

use super::direct::{emission, escaped, sample_one_light};
use crate::Rgb;
use crate::geometry::{Hit, NONE};
use crate::material::bsdf::{Bsdf, TransportMode};
use crate::math::Ray;
use crate::medium::Medium;
use crate::prepare::tracer::Tracer;
use glam::Vec3A;

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

/// A stretch of a ray inside one medium: from the ray's origin to the next surface, at `t_max` along it.
#[derive(Clone, Copy, Debug)]
pub struct Segment<'a> {
    /// The ray (unit direction).
    pub ray: &'a Ray,
    /// The medium it crosses (not vacuum).
    pub medium: &'a Medium,
    /// The distance to the surface in scene units, ∞ when there is none.
    pub t_max: f32,
}

/// What a walk through a medium adds along one segment: given the path's tracer and the segment, the radiance
/// scattered towards the ray's origin along the segment, not yet weighted by the path's throughput.
pub type VolumeEstimate<'a> = dyn FnMut(&mut Tracer, &Segment) -> Rgb + 'a;

/// Follows `ray` through mirror and glass to the first surface with a non-delta component rough enough to store
/// photons ([`Bsdf::stores_photons`]); through a glossier lobe it walks on by sampling it, after sampling one
/// light there (joined by MIS to the emission the walk then finds; without it, a point, spot or directional
/// light's highlight on a glossy surface, or its light through rough glass, is lost). At a surface with
/// both (the mixture), the path continues only if the delta lobe is sampled, and that surface is the vertex.
/// In a scene without media.
pub fn visible_point(tracer: &mut Tracer, max_depth: u32, ray: Ray) -> VisiblePoint {
    visible_point_in(tracer, max_depth, ray, None, &mut |_, _| Rgb::ZERO)
}

/// [`visible_point`] from a ray that starts in `medium`: along every segment in a medium the walk adds
/// `volume`'s estimate and carries on to the surface with the segment's transmittance (no free flight: every
/// walk reaches its surface, so photon methods estimate both the volume and the surface behind it).
pub fn visible_point_in(
    tracer: &mut Tracer,
    max_depth: u32,
    mut ray: Ray,
    mut medium: Option<Medium>,
    volume: &mut VolumeEstimate,
) -> VisiblePoint {
    let prep = tracer.prep;
    let mut beta = Rgb::ONE;
    let mut le = Rgb::ZERO;
    let mut in_volume = Rgb::ZERO;
    // Crossings of `interface` surfaces are not bounces.
    let (mut bounces, mut crossings) = (0u32, 0u32);
    // The last bounce was a delta lobe (or the camera), and the density of its direction: emission found next
    // is weighted against light sampling at the glossy vertex it left (`emission`). In a scene with media the
    // walk samples no light at glossy vertices and counts emission in full.
    let (mut prev_delta, mut prev_pdf) = (true, 0.0f32);
    let nee_off = prep.media.is_some();
    while bounces <= max_depth {
        let found = tracer.intersect(&ray, f32::INFINITY);
        if let Some(m) = medium.filter(|m| !m.is_vacuum()) {
            let t_max = found.as_ref().map_or(f32::INFINITY, |h| h.t);
            in_volume += beta * volume(tracer, &Segment { ray: &ray, medium: &m, t_max });
            beta *= m.transmittance(&ray, t_max);
            if beta == Rgb::ZERO {
                break;
            }
        }
        let Some(hit) = found else {
            let (e, w) = escaped(prep, &ray, prev_delta || nee_off, prev_pdf);
            if e != Rgb::ZERO {
                le += beta * e * w;
            }
            break;
        };
        let wo = -ray.d;
        if hit.light != NONE {
            let (e, w) = emission(prep, &hit, &ray, prev_delta || nee_off, prev_pdf);
            if e != Rgb::ZERO {
                le += beta * e * w;
            }
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
        if bsdf.stores_photons(prep.settings.photons.min_roughness) {
            return VisiblePoint { le, volume: in_volume, vertex: Some((beta, hit, bsdf, wo)), medium };
        }
        // Light reflected here straight from a light: sampled on the light (a delta light can be found no other
        // way) and joined by MIS to the emission the BSDF sample below finds.
        if !nee_off && bsdf.has_non_delta() {
            le += beta * sample_one_light(tracer, &hit, &bsdf, wo, medium, true);
        }
        // A zero BSDF value, which `sample_bsdf` refuses, would have ended the walk at the test below.
        let Some(bs) = tracer.sample_bsdf(&bsdf, wo, TransportMode::Radiance) else { break };
        (prev_delta, prev_pdf) = (bs.delta, bs.pdf);
        beta *= bsdf.sample_weight(wo, &bs, bs.pdf, TransportMode::Radiance);
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
