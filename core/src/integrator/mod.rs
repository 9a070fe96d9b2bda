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
//! Every estimator follows its path with the path's [`Tracer`] (the prepared job, the sample stream, the ray
//! count), lent as `&mut Tracer`; the surface-bounce step they share is [`Tracer::sample_bsdf`] with
//! [`crate::material::bsdf::Bsdf::sample_weight`], and the path tracers' η² bookkeeping and Russian roulette
//! are `path`'s `PathState::bounce`, which [`volume`] uses too.
//!
//! This module holds the one dispatch ([`estimate`]); what the estimators share lives in files of its own, so
//! that no file names one that names it back: light sampling and shadow rays ([`direct`]), and the walk through
//! mirror and glass to the first non-delta surface ([`visible`]). A new per-ray estimator is a file here, a
//! variant of `method::CameraEstimator` and an arm of [`estimate`].

pub mod direct;
pub mod path;
pub mod photon_map;
pub mod visible;
pub mod volume;

pub use direct::{photon_vertex_direct, reaches, sample_one_light, shadow_transmittance, unoccluded};
pub use visible::{Segment, VisiblePoint, VolumeEstimate, visible_point, visible_point_in};

use crate::Rgb;
use crate::math::Ray;
use crate::method::{CameraEstimator, Technique};
use crate::prepare::tracer::Tracer;

/// Radiance arriving along `ray` (W·sr⁻¹·m⁻²), by the camera estimator of the tracer's job's method
/// ([`crate::method::Method::technique`]). Draws from the tracer's stream and counts every traced ray in it. Progressive photon mapping, `vcm`, `bdpt` and
/// `lt` are not per-ray methods: their pass renderers (`render::progressive`, `render::vcm`) trace their own
/// light paths; here progressive gives direct light (what its passes add photons to) and the subpath methods
/// trace full paths (what their passes fall back to in a scene with media).
pub fn li(tracer: &mut Tracer, ray: Ray) -> Rgb {
    let prep = tracer.prep;
    let estimator = match prep.settings.integrator.technique(prep.media.is_some(), prep.photons.is_some()) {
        Technique::Samples(e) => e,
        Technique::PhotonPasses => CameraEstimator::Direct,
        Technique::Subpaths(_) => CameraEstimator::Path,
    };
    estimate(tracer, estimator, ray)
}

/// Radiance arriving along `ray` by `estimator`: the one dispatch of the per-ray methods, in scenes with and
/// without media. A photon-map estimator without the job's maps gives direct light.
pub fn estimate(tracer: &mut Tracer, estimator: CameraEstimator, ray: Ray) -> Rgb {
    let prep = tracer.prep;
    let depth = prep.settings.max_depth;
    let path = |tracer: &mut Tracer, direct: bool| match &prep.media {
        None => path::li(tracer, depth, ray, direct),
        Some(media) => volume::path_li(tracer, media, depth, ray, direct),
    };
    match (estimator, &prep.photons) {
        (CameraEstimator::Path, _) => path(tracer, false),
        (CameraEstimator::Direct, _) | (CameraEstimator::PhotonMap | CameraEstimator::FinalGather, None) => {
            path(tracer, true)
        }
        (CameraEstimator::PhotonMap, Some(maps)) => photon_map::li(tracer, maps, false, ray),
        (CameraEstimator::FinalGather, Some(maps)) => photon_map::li(tracer, maps, true, ray),
    }
}
