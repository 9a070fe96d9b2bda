//! `progressive`: stochastic progressive photon mapping (Hachisuka & Jensen 2009; pbrt-v3's SPPM). A pass
//! traces fresh photons and takes one camera sample per pixel; each pixel keeps its statistics (photon count,
//! shrinking radius, accumulated flux) across passes, so this method renders whole strips, not single rays.
//! It lives here, beside the strip loop it replaces, and reads the per-ray building blocks of
//! [`crate::integrator`].

use super::{Strip, camera_sample, pixel_rotation};
use crate::Rgb;
use crate::integrator::{sample_one_light, visible_point};
use crate::photon::{Estimator, Gather, Kernel, PhotonMap, photon_flux};
use crate::prepare::Prepared;
use crate::prepare::photons::{PhotonKind, trace_photons};
use crate::scene::{Integrator, RenderSettings};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

/// The photon maps of progressive photon mapping's passes, traced once per job and shared by all the strips a
/// process renders of it, as far as a memory budget allows: passes whose maps no longer fit are traced again by
/// every strip. A pass's map depends only on the prepared scene, the settings and the pass index, so sharing it
/// changes no pixel.
pub struct PassMaps {
    /// One slot per pass (none when the method is not progressive); a slot stays empty for a pass whose map
    /// did not fit the budget.
    maps: Vec<OnceLock<Arc<PhotonMap>>>,
    budget: u64,
    used: AtomicU64,
}

impl PassMaps {
    /// Shares the passes of `settings` (when the method is progressive) while their maps take at most `budget`
    /// bytes in all; `budget` 0 never shares.
    pub fn new(settings: &RenderSettings, budget: u64) -> Self {
        let n = if settings.integrator == Integrator::Progressive { settings.photons.passes as usize } else { 0 };
        Self { maps: (0..n).map(|_| OnceLock::new()).collect(), budget, used: AtomicU64::new(0) }
    }

    /// Bytes of the maps kept so far.
    pub fn kept_bytes(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }

    /// Passes whose maps are kept for the next strip.
    pub fn kept_passes(&self) -> usize {
        self.maps.iter().filter(|m| m.get().is_some()).count()
    }

    /// The photon map of `pass`: the kept one, or traced now (and kept if it fits). `None` when it cannot be
    /// built (no photon was stored).
    fn get(&self, prep: &Prepared, pass: u32) -> Option<Arc<PhotonMap>> {
        let slot = self.maps.get(pass as usize);
        if let Some(map) = slot.and_then(OnceLock::get) {
            return Some(map.clone());
        }
        let n = u64::from(prep.settings.photons.pass_photons);
        let traced = trace_photons(prep, n, u64::from(pass) + 2, PhotonKind::Indirect);
        // Traced photons lie on surfaces and are finite; a map that cannot be built contributes nothing.
        let map = Arc::new(PhotonMap::build(traced.photons).map_err(|e| tracing::warn!("pass {pass}: {e}")).ok()?);
        let bytes = map.memory_bytes() as u64;
        if let Some(slot) = slot
            && self.used.load(Ordering::Relaxed) + bytes <= self.budget
            && slot.set(map.clone()).is_ok()
        {
            self.used.fetch_add(bytes, Ordering::Relaxed);
        }
        Some(map)
    }
}

/// Per-pixel state of progressive photon mapping (Hachisuka & Jensen 2009, §4; pbrt-v3's SPPM).
#[derive(Clone, Copy)]
struct PixelStats {
    /// Accumulated photon count N.
    n: f32,
    /// Squared gather radius R².
    r2: f32,
    /// Accumulated, radius-scaled flux τ.
    tau: Rgb,
    /// Sum of directly estimated radiance (emission seen and light sampling) over passes.
    ld: Rgb,
}

/// Stochastic progressive photon mapping over rows `rows`. Pass `k` traces its own photons from the streams
/// `(seed, k + 2, i)` (0 and 1 belong to the static global and caustic maps) and takes camera sample `k` of each
/// pixel, so a pixel's value depends only on the scene, the seed and the pass count, never on strips.
/// Direct light comes from light sampling at the visible point; photons carry indirect light only
/// (light → anything⁺ → diffuse), so each light path is counted once.
pub(super) fn render_strip(
    prep: &Prepared,
    rows: Range<u32>,
    pass_maps: &PassMaps,
    progress: &(dyn Fn(u32) -> bool + Sync),
) -> Option<Strip> {
    let settings = &prep.settings;
    let ph = &settings.photons;
    let width = prep.camera.width as usize;
    let passes = ph.passes.max(1);
    let r0 = prep.photon_radius();
    let est = Estimator {
        gather: Gather::Radius { radius: r0 },
        kernel: Kernel::Box,
        disc: ph.disc,
        same_object: ph.same_object,
    };
    let mut stats = vec![PixelStats { n: 0.0, r2: r0 * r0, tau: Rgb::ZERO, ld: Rgb::ZERO }; width * rows.len()];
    let mut rays = 0u64;
    let rows_n = rows.len() as u64;
    for pass in 0..passes {
        let map = pass_maps.get(prep, pass);
        let pass_rays: u64 = stats
            .par_chunks_mut(width)
            .zip(rows.clone().into_par_iter())
            .map(|(row, y)| {
                let mut rays = 0u64;
                for (x, st) in row.iter_mut().enumerate() {
                    let x = x as u32;
                    let (ray, mut s) =
                        camera_sample(prep, settings.seed, x, y, pass, passes, pixel_rotation(settings.seed, x, y));
                    let vp = visible_point(prep, settings.max_depth, ray, &mut s, &mut rays);
                    let mut ld = vp.le;
                    let Some((beta, hit, bsdf, wo)) = vp.vertex else {
                        st.ld += finite_or_zero(ld);
                        continue;
                    };
                    ld += beta * sample_one_light(prep, &hit, &bsdf, wo, &mut s, &mut rays, false);
                    st.ld += finite_or_zero(ld);
                    let radius = st.r2.sqrt();
                    let est = Estimator { gather: Gather::Radius { radius }, ..est };
                    // The box-kernel estimate is Σ f·Φ / (π r²): undo the normalisation to get Σ f·Φ and M.
                    let Some(map) = &map else { continue };
                    let (phi, m) = photon_flux(map, &est, &hit, &bsdf, wo);
                    // st.n + m > 0 as m > 0; a radius that shrank to nothing (r² ≤ 0) stops shrinking, so
                    // the ratio r2_new / r2 below never divides by zero.
                    if m > 0 && st.r2 > 0.0 {
                        let m = m as f32;
                        let n_new = st.n + ph.alpha * m;
                        let r2_new = st.r2 * n_new / (st.n + m);
                        if r2_new > 0.0 {
                            st.tau = (st.tau + beta * finite_or_zero(phi)) * (r2_new / st.r2);
                            st.n = n_new;
                            st.r2 = r2_new;
                        }
                    }
                }
                rays
            })
            .sum();
        rays += pass_rays;
        if !progress(((u64::from(pass) + 1) * rows_n / u64::from(passes)) as u32) {
            return None;
        }
    }
    let inv_passes = 1.0 / passes as f32;
    let pixels = stats
        .iter()
        .flat_map(|st| {
            // τ is only ever scaled when r² > 0; a pixel whose radius is zero gathered nothing.
            let area = passes as f32 * std::f32::consts::PI * st.r2;
            let indirect = if area > 0.0 { st.tau / area } else { Rgb::ZERO };
            let c = st.ld * inv_passes + finite_or_zero(indirect);
            debug_assert!(c.is_finite(), "progressive: non-finite pixel {c:?} (r² = {}, τ = {:?})", st.r2, st.tau);
            c.to_array()
        })
        .collect();
    Some(Strip { rows, pixels, rays })
}

fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() { c } else { Rgb::ZERO }
}
