//! [`Tracer`]: what every traced path carries with it — the prepared job it runs in, its stream of samples and
//! the count of the rays it traces — and the one surface-bounce step that the path tracers, photon tracing and
//! the vcm subpaths share ([`Tracer::sample_bsdf`] with [`crate::material::bsdf::Bsdf::sample_weight`]).
//!
//! A tracer is made where a stream begins (a camera sample, a photon path, a light subpath) and lent as
//! `&mut Tracer` to every function that follows the path; its ray count is added to the caller's total when
//! the path ends. It holds one reference and two plain values, so lending it costs what lending the three did.

use super::Prepared;
use crate::Rgb;
use crate::geometry::Hit;
use crate::material::bsdf::{Bsdf, BsdfSample, TransportMode};
use crate::math::Ray;
use crate::math::rng::Sampler;
use glam::Vec3A;

/// The context of one traced path: the prepared job, the path's sample stream and the rays it has traced.
#[derive(Clone, Debug)]
pub struct Tracer<'a> {
    /// The job the path is traced in.
    pub prep: &'a Prepared,
    /// The path's stream of uniform samples (one per camera sample, photon path or light subpath).
    pub sampler: Sampler,
    /// Rays traced so far: closest-hit and shadow rays. Photon tracing reports its cost in paths, not rays,
    /// and leaves this at 0.
    pub rays: u64,
}

impl<'a> Tracer<'a> {
    /// A tracer of a path in `prep` drawing from `sampler`, with no ray traced yet.
    #[inline]
    pub fn new(prep: &'a Prepared, sampler: Sampler) -> Self {
        Self { prep, sampler, rays: 0 }
    }

    /// The closest surface hit along `ray` before `t_max` (scene units along the unit direction), counting one
    /// ray.
    #[inline]
    pub fn intersect(&mut self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.rays += 1;
        self.prep.geometry.intersect(ray, t_max)
    }

    /// The surface-bounce step's sample: draws `u` and `u2` from the stream and samples `bsdf` from `wo` in
    /// `mode` ([`Bsdf::sample`]). `None` where the path ends at this surface: nothing sampled, a pdf that is
    /// not positive (or NaN), or a zero BSDF value. The throughput factor of the sample is
    /// [`Bsdf::sample_weight`].
    // Always inlined: each caller then holds its `Bsdf::sample` call as it did before this step was shared
    // (measured: as a call of its own it added about 0.5 % instructions to a vcm render).
    #[inline(always)]
    pub fn sample_bsdf(&mut self, bsdf: &Bsdf, wo: Vec3A, mode: TransportMode) -> Option<BsdfSample> {
        let (u, u2) = (self.sampler.next_f32(), self.sampler.next_2d());
        let bs = bsdf.sample(wo, u, u2, mode)?;
        // Written so that a NaN pdf is refused too.
        (bs.pdf > 0.0 && bs.f != Rgb::ZERO).then_some(bs)
    }
}
