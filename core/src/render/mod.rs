//! The strip renderer: rows of pixels in parallel with rayon.
//!
//! Each pixel sample draws from its own stream seeded by `(seed, x, y, sample)`, so a pixel's value does not
//! depend on strips, threads or workers. Sample positions in the pixel (a box filter) are stratified: sample `i`
//! of `n` lies in column `i/n` and in the van der Corput row of `i`, the whole pattern rotated by a per-pixel
//! random offset (Cranley–Patterson), which keeps every sample uniformly distributed and the estimate unbiased.

pub mod progressive;

use crate::Rgb;
use crate::integrator::li;
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::prepare::Prepared;
use crate::scene::Integrator;
use glam::Vec2;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// A rendered strip: linear RGB radiance of rows `rows`, row-major, 3 floats per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Strip {
    /// The rows rendered.
    pub rows: Range<u32>,
    /// `3 × width × rows.len()` floats.
    pub pixels: Vec<f32>,
    /// Rays traced.
    pub rays: u64,
    /// Photon paths traced while rendering the strip (progressive photon mapping's passes; 0 for the other
    /// methods, whose maps are traced once when the job is prepared).
    pub photon_paths: u64,
}

/// Renders rows `rows` of the image. `progress` is called with the number of rows finished so far.
pub fn render_strip(prep: &Prepared, rows: Range<u32>, progress: &(dyn Fn(u32) + Sync)) -> Strip {
    let never_cancel = |n| {
        progress(n);
        true
    };
    let Some(strip) = render_strip_with(prep, rows, &never_cancel) else {
        unreachable!("a render whose progress callback never cancels always finishes")
    };
    strip
}

/// Renders rows `rows` of the image (for progressive photon mapping, every pass). `progress` is called with the
/// number of rows finished so far and returns `false` to cancel; a cancelled render returns `None` soon after
/// (rows already started finish first).
pub fn render_strip_with(prep: &Prepared, rows: Range<u32>, progress: &(dyn Fn(u32) -> bool + Sync)) -> Option<Strip> {
    if prep.settings.integrator == Integrator::Progressive {
        return progressive::render_strip(prep, rows, progress);
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
                let c = render_pixel(prep, x, y, &mut rays);
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
    Some(Strip { rows, pixels, rays, photon_paths: 0 })
}

/// The mean radiance of pixel `(x, y)` over `render.spp` samples. Non-finite samples (which a correct
/// integrator never makes) are dropped rather than poisoning the image.
pub fn render_pixel(prep: &Prepared, x: u32, y: u32, rays: &mut u64) -> Rgb {
    let settings = &prep.settings;
    let spp = settings.spp.max(1);
    let offset = pixel_rotation(settings.seed, x, y);
    let mut sum = Rgb::ZERO;
    for i in 0..spp {
        let (ray, mut s) = camera_sample(prep, settings.seed, x, y, i, spp, offset);
        let c = li(prep, ray, &mut s, rays);
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
fn camera_sample(prep: &Prepared, seed: u64, x: u32, y: u32, i: u32, n: u32, rotation: Vec2) -> (Ray, Sampler) {
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
pub fn render_image(prep: &Prepared, progress: &(dyn Fn(u32) + Sync)) -> Strip {
    render_strip(prep, 0..prep.camera.height, progress)
}
