//! The photon maps of one job, and the estimates that read them through a BSDF at a hit.

use super::kernel::Estimator;
use super::map::{Photon, PhotonMap};
use crate::Rgb;
use crate::geometry::Hit;
use crate::material::bsdf::{Bsdf, TransportMode};
use glam::Vec3A;

/// The photon maps a photon method reads, and how it gathers.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PhotonMaps {
    /// Every photon at a non-delta surface.
    pub global: PhotonMap,
    /// Light → specular⁺ → diffuse photons (for `final-gather`, on scenes with mirror or glass).
    pub caustic: Option<PhotonMap>,
    /// The radiance estimate's settings, with the radius resolved to scene units.
    pub estimator: Estimator,
    /// Irradiance precomputed at every fourth global photon (Christensen 1999), for `final-gather`: each
    /// entry's `power` holds the irradiance E (W/m²) at its position.
    pub irradiance: Option<PhotonMap>,
}

/// Precomputes irradiance at every `stride`-th photon of `global` (in parallel, in a fixed order).
pub fn precompute_irradiance(global: &PhotonMap, est: &Estimator, stride: usize) -> Vec<Photon> {
    use rayon::prelude::*;
    let picked: Vec<&Photon> = global.photons().iter().step_by(stride.max(1)).collect();
    picked
        .par_iter()
        .map(|ph| {
            let n = ph.normal();
            let e = with_scratch(|scratch| global.estimate(est, ph.position(), n, ph.object, |_| Rgb::ONE, scratch));
            Photon::new(ph.position(), n, n, e, ph.object)
        })
        .collect()
}

thread_local! {
    /// Gather scratch of each rendering thread: no allocation per estimate.
    static SCRATCH: std::cell::RefCell<Vec<(u32, f32)>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Runs `f` with this thread's gather scratch (found photons as `(index, squared distance)`).
pub fn with_scratch<R>(f: impl FnOnce(&mut Vec<(u32, f32)>) -> R) -> R {
    SCRATCH.with_borrow_mut(f)
}

/// Reflected radiance at `hit` towards `wo` from a photon map, through the non-delta part of `bsdf`.
pub fn photon_radiance(map: &PhotonMap, est: &Estimator, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> Rgb {
    let n = hit.normal_towards(wo);
    with_scratch(|scratch| {
        map.estimate(est, hit.p, n, hit.object, |wi| bsdf.f(wo, wi, TransportMode::Radiance), scratch)
    })
}

/// Progressive photon mapping's gather at `hit`: flux `Σ f·Φ` of the accepted photons and their count.
pub fn photon_flux(map: &PhotonMap, est: &Estimator, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> (Rgb, usize) {
    let n = hit.normal_towards(wo);
    with_scratch(|scratch| {
        map.gather_flux(est, hit.p, n, hit.object, |wi| bsdf.f(wo, wi, TransportMode::Radiance), scratch)
    })
}
