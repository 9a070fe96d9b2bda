//! The strip renderer: rows of pixels in parallel with rayon.
//!
//! Each pixel sample draws from its own stream seeded by `(seed, x, y, sample)`, so a pixel's value does not
//! depend on strips, threads or workers. Sample positions in the pixel (a box filter) are stratified: sample `i`
//! of `n` lies in column `i/n` and in the van der Corput row of `i`, the whole pattern rotated by a per-pixel
//! random offset (Cranley–Patterson), which keeps every sample uniformly distributed and the estimate unbiased.

use crate::Rgb;
use crate::integrator::li;
use crate::prepare::Prepared;
use crate::rng::Sampler;
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
    let mut rot = Sampler::for_pixel(settings.seed, x, y, u32::MAX);
    let offset = rot.next_2d();
    let mut sum = Rgb::ZERO;
    for i in 0..spp {
        let mut s = Sampler::for_pixel(settings.seed, x, y, i);
        let strat = Vec2::new((i as f32 + 0.5) / spp as f32, radical_inverse_2(i));
        let jitter = (strat + offset).fract();
        let film = Vec2::new(x as f32, y as f32) + jitter;
        let ray = prep.camera.ray(film, s.next_2d());
        let c = li(prep, settings, ray, &mut s, rays);
        if c.is_finite() {
            sum += c;
        }
    }
    sum / spp as f32
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
