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
    if settings.integrator == Integrator::Progressive {
        return render_strip_progressive(prep, rows, settings, progress);
    }
    let width = prep.camera.width;
    let done = std::sync::atomic::AtomicU32::new(0);
    let per_row: Vec<(Vec<f32>, u64)> = rows
        .clone()
        .into_par_iter()
        .map(|y| {
            let mut out = Vec::with_capacity(3 * width as usize);
            let mut rays = 0u64;
            for x in 0..width {
                let c = render_pixel(prep, settings, x, y, &mut rays);
                out.extend_from_slice(&[c.x, c.y, c.z]);
            }
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(n);
            (out, rays)
        })
        .collect();
    let rays = per_row.iter().map(|r| r.1).sum();
    let pixels = per_row.into_iter().flat_map(|r| r.0).collect();
    Strip { rows, pixels, rays }
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
    progress: &(dyn Fn(u32) + Sync),
) -> Strip {
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
        let traced = trace_photons(prep, u64::from(ph.pass_photons), u64::from(pass) + 2, PhotonKind::Indirect);
        // Traced photons lie on surfaces and are finite; a map that cannot be built contributes nothing.
        let map = PhotonMap::build(traced.photons).map_err(|e| tracing::warn!("pass {pass}: {e}")).ok();
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
        progress(((u64::from(pass) + 1) * rows_n / u64::from(passes)) as u32);
    }
    let inv_passes = 1.0 / passes as f32;
    let pixels = stats
        .iter()
        .flat_map(|st| {
            let c = st.ld * inv_passes + st.tau / (passes as f32 * std::f32::consts::PI * st.r2);
            c.to_array()
        })
        .collect();
    Strip { rows, pixels, rays }
}

fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() { c } else { Rgb::ZERO }
}
