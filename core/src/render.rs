//! The strip renderer: rows of pixels in parallel with rayon.
//!
//! Each pixel sample draws from its own stream seeded by `(seed, x, y, sample)`, so a pixel's value does not
//! depend on strips, threads or workers. Sample positions in the pixel (a box filter) are stratified: sample `i`
//! of `n` lies in column `i/n` and in the van der Corput row of `i`, the whole pattern rotated by a per-pixel
//! random offset (Cranley–Patterson), which keeps every sample uniformly distributed and the estimate unbiased.

use crate::Rgb;
use crate::integrator::{li, sample_one_light, visible_point};
use crate::photon::{PhotonKind, trace_photons};
use crate::photon_map::{Estimator, Gather, Kernel, PhotonMap};
use crate::prepare::Prepared;
use crate::rng::Sampler;
use crate::scene::Integrator;
use crate::scene::RenderSettings;
use glam::Vec2;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

/// A rendered strip: linear RGB radiance of rows `rows`, row-major, 3 floats per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Strip {
    /// The rows rendered.
    pub rows: Range<u32>,
    /// `3 × width × rows.len()` floats.
    pub pixels: Vec<f32>,
    /// Rays traced.
    pub rays: u64,
}

/// Renders rows `rows` of the image. `progress` is called with the number of rows finished so far.
pub fn render_strip(
    prep: &Prepared,
    rows: Range<u32>,
    settings: &RenderSettings,
    progress: &(dyn Fn(u32) + Sync),
) -> Strip {
    let passes = PassMaps::new(settings, 0);
    let never_cancel = |n| {
        progress(n);
        true
    };
    let Some(strip) = render_strip_with(prep, rows, settings, &passes, &never_cancel) else {
        unreachable!("a render whose progress callback never cancels always finishes")
    };
    strip
}

/// Renders rows `rows` of the image, sharing progressive photon passes through `passes`. `progress` is called
/// with the number of rows finished so far and returns `false` to cancel; a cancelled render returns `None`
/// soon after (rows already started finish first).
pub fn render_strip_with(
    prep: &Prepared,
    rows: Range<u32>,
    settings: &RenderSettings,
    passes: &PassMaps,
    progress: &(dyn Fn(u32) -> bool + Sync),
) -> Option<Strip> {
    if settings.integrator == Integrator::Progressive {
        return render_strip_progressive(prep, rows, settings, passes, progress);
    }
    let width = prep.camera.width;
    let done = AtomicU32::new(0);
    let cancelled = AtomicBool::new(false);
    let per_row: Vec<(Vec<f32>, u64)> = rows
        .clone()
        .into_par_iter()
        .map(|y| {
            if cancelled.load(Ordering::Relaxed) {
                return (Vec::new(), 0);
            }
            let mut out = Vec::with_capacity(3 * width as usize);
            let mut rays = 0u64;
            for x in 0..width {
                let c = render_pixel(prep, settings, x, y, &mut rays);
                out.extend_from_slice(&[c.x, c.y, c.z]);
            }
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            if !progress(n) {
                cancelled.store(true, Ordering::Relaxed);
            }
            (out, rays)
        })
        .collect();
    if cancelled.load(Ordering::Relaxed) {
        return None;
    }
    let rays = per_row.iter().map(|r| r.1).sum();
    let pixels = per_row.into_iter().flat_map(|r| r.0).collect();
    Some(Strip { rows, pixels, rays })
}

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
    fn get(&self, prep: &Prepared, settings: &RenderSettings, pass: u32) -> Option<Arc<PhotonMap>> {
        let slot = self.maps.get(pass as usize);
        if let Some(map) = slot.and_then(OnceLock::get) {
            return Some(map.clone());
        }
        let n = u64::from(settings.photons.pass_photons);
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

/// The mean radiance of pixel `(x, y)` over `settings.spp` samples. Non-finite samples (which a correct
/// integrator never makes) are dropped rather than poisoning the image.
pub fn render_pixel(prep: &Prepared, settings: &RenderSettings, x: u32, y: u32, rays: &mut u64) -> Rgb {
    let spp = settings.spp.max(1);
    let offset = pixel_rotation(settings.seed, x, y);
    let mut sum = Rgb::ZERO;
    for i in 0..spp {
        let (ray, mut s) = camera_sample(prep, settings.seed, x, y, i, spp, offset);
        let c = li(prep, settings, ray, &mut s, rays);
        if c.is_finite() {
            sum += c;
        }
    }
    sum / spp as f32
}

/// The per-pixel Cranley–Patterson rotation of the sample pattern.
fn pixel_rotation(seed: u64, x: u32, y: u32) -> Vec2 {
    Sampler::for_pixel(seed, x, y, u32::MAX).next_2d()
}

/// Camera ray and random stream of sample `i` of `n` in pixel `(x, y)`.
fn camera_sample(
    prep: &Prepared,
    seed: u64,
    x: u32,
    y: u32,
    i: u32,
    n: u32,
    rotation: Vec2,
) -> (crate::geometry::Ray, Sampler) {
    let mut s = Sampler::for_pixel(seed, x, y, i);
    let strat = Vec2::new((i as f32 + 0.5) / n as f32, radical_inverse_2(i));
    let film = Vec2::new(x as f32, y as f32) + (strat + rotation).fract();
    let ray = prep.camera.ray(film, s.next_2d());
    (ray, s)
}

/// The base-2 radical inverse (van der Corput sequence) of `i`.
#[inline]
fn radical_inverse_2(i: u32) -> f32 {
    (i.reverse_bits() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Renders the whole image on this machine.
pub fn render_image(prep: &Prepared, settings: &RenderSettings, progress: &(dyn Fn(u32) + Sync)) -> Strip {
    render_strip(prep, 0..prep.camera.height, settings, progress)
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
fn render_strip_progressive(
    prep: &Prepared,
    rows: Range<u32>,
    settings: &RenderSettings,
    pass_maps: &PassMaps,
    progress: &(dyn Fn(u32) -> bool + Sync),
) -> Option<Strip> {
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
        let map = pass_maps.get(prep, settings, pass);
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
                    let (phi, m) = crate::integrator::photon_flux(map, &est, &hit, &bsdf, wo);
                    if m > 0 {
                        let m = m as f32;
                        let n_new = st.n + ph.alpha * m;
                        let r2_new = st.r2 * n_new / (st.n + m);
                        st.tau = (st.tau + beta * finite_or_zero(phi)) * (r2_new / st.r2);
                        st.n = n_new;
                        st.r2 = r2_new;
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
            let c = st.ld * inv_passes + st.tau / (passes as f32 * std::f32::consts::PI * st.r2);
            c.to_array()
        })
        .collect();
    Some(Strip { rows, pixels, rays })
}

fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() { c } else { Rgb::ZERO }
}
