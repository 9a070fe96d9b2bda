//! The photon maps of one job, and the estimates that read them through a BSDF at a hit.

use super::kernel::{Estimator, Gather};
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
    /// Photons scattered in participating media (scenes with media only): each holds the power it scattered,
    /// `σs·T/p` times the power that arrived ([`crate::prepare::photons`]).
    pub volume: Option<PhotonMap>,
    /// How the volume map is gathered: the k nearest within the volume radius, or every photon within it.
    pub volume_gather: Gather,
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

/// Radiance scattered towards the origin of a ray with direction `ray_d` at point `x` of a medium with HG
/// asymmetry `g`, from a volume photon map: `Σ p(−ωp·…)·Φp / (4/3·π·r³)` over the photons of the gather, where
/// `r` is the fixed radius or the distance to the k-th nearest photon (a box kernel in 3D; Jensen & Christensen
/// 1998, "Efficient Simulation of Light Transport in Scenes with Participating Media using Photon Maps", eq. 9).
/// The stored power already carries σs, so this is `σs·L_i` (W·m⁻³·sr⁻¹).
pub fn volume_radiance(map: &PhotonMap, x: Vec3A, ray_d: Vec3A, g: f32, gather: Gather) -> Rgb {
    let phase = crate::medium::HenyeyGreenstein { g };
    with_scratch(|scratch| {
        let r2 = match gather {
            Gather::KNearest { k, max_radius } => {
                let max_r2 = max_radius * max_radius;
                map.k_nearest(x, k as usize, max_r2, scratch);
                if scratch.len() == k as usize { scratch.last().map_or(max_r2, |&(_, d2)| d2) } else { max_r2 }
            }
            Gather::Radius { radius } => {
                map.within(x, radius * radius, scratch);
                radius * radius
            }
        };
        if scratch.is_empty() || r2.is_nan() || r2 <= 0.0 {
            return Rgb::ZERO;
        }
        let volume = 4.0 / 3.0 * std::f32::consts::PI * r2 * r2.sqrt();
        let photons = map.photons();
        let sum = scratch.iter().fold(Rgb::ZERO, |acc, &(i, _)| {
            let ph = &photons[i as usize];
            // The photon travelled along −wi; light leaves towards the ray's origin, along −ray_d.
            acc + ph.phi() * phase.eval(ph.wi(), ray_d)
        });
        sum / volume
    })
}

/// Progressive photon mapping's gather at `hit`: flux `Σ f·Φ` of the accepted photons and their count.
pub fn photon_flux(map: &PhotonMap, est: &Estimator, hit: &Hit, bsdf: &Bsdf, wo: Vec3A) -> (Rgb, usize) {
    let n = hit.normal_towards(wo);
    with_scratch(|scratch| {
        map.gather_flux(est, hit.p, n, hit.object, |wi| bsdf.f(wo, wi, TransportMode::Radiance), scratch)
    })
}
