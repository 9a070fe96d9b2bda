//! The strip renderer: rows of pixels in parallel with rayon.
//!
//! Each pixel sample draws from its own stream identified by `(seed, x, y, sample)`, so a pixel's value does not
//! depend on strips, threads or workers. The samples of a pixel are the points of one padded, scrambled
//! Sobol sequence ([`Sampler`]): their first draw places them in the pixel (a box filter), and every aligned
//! block of 2^m samples has one sample in each elementary interval of area 2^−m, in the pixel and in every
//! later 2D draw (lens, light, BSDF). Each point is uniformly distributed, so the estimate is unbiased. No sample
//! depends on how many there will be, so the first `K` samples are the same points whether `K` was fixed ahead
//! (`--spp`) or reached by a time or error bound.
//!
//! A pixel's samples are summed as fixed-point integers ([`progressive::to_fixed`]) and divided once
//! ([`progressive::fixed_mean`]): the sum is exact in any order, so `K` samples rendered as a strip and the same
//! `K` samples rendered as sample blocks on many workers ([`progressive::render_passes`]) give the same bits.

pub mod progressive;
pub mod vcm;

use crate::Rgb;
use crate::integrator::li;
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::prepare::Prepared;
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
    if prep.settings.integrator.renders_passes() {
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

/// The mean radiance of pixel `(x, y)` over `render.spp` samples, summed in fixed point (see the module
/// documentation). A non-finite sample channel (which a correct integrator never makes) counts as zero rather
/// than poisoning the image.
pub fn render_pixel(prep: &Prepared, x: u32, y: u32, rays: &mut u64) -> Rgb {
    let settings = &prep.settings;
    let spp = settings.spp.max(1);
    let mut sum = [0i128; 3];
    for i in 0..spp {
        let c = pixel_sample(prep, x, y, i, rays);
        for (s, v) in sum.iter_mut().zip(c.to_array()) {
            *s += i128::from(progressive::to_fixed(v));
        }
    }
    Rgb::from_array(sum.map(|s| progressive::fixed_mean(s, spp)))
}

/// Samples `samples` of every pixel of rows `rows` (any method but progressive photon mapping): each pixel
/// channel's sum of their fixed-point values, as [`progressive::render_passes`] returns for a block of passes.
/// `progress` gets the samples finished so far (rows done scaled to samples) and returns `false` to cancel (then
/// `None`).
pub(crate) fn render_sample_block(
    prep: &Prepared,
    rows: Range<u32>,
    samples: Range<u32>,
    progress: &(dyn Fn(u32) -> bool + Sync),
) -> Option<progressive::PassSums> {
    let width = prep.camera.width as usize;
    let (n, rows_n) = (u64::from(samples.end.saturating_sub(samples.start)), rows.len().max(1) as u64);
    let done = AtomicU32::new(0);
    let cancelled = AtomicBool::new(false);
    let mut sums = vec![0i64; 3 * width * rows.len()];
    let rays = sums
        .par_chunks_mut(3 * width)
        .zip(rows.clone().into_par_iter())
        .map(|(row, y)| {
            if cancelled.load(Ordering::Relaxed) {
                return 0;
            }
            let mut rays = 0u64;
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                let x = x as u32;
                for i in samples.clone() {
                    let c = pixel_sample(prep, x, y, i, &mut rays);
                    for (s, v) in px.iter_mut().zip(c.to_array()) {
                        *s = s.saturating_add(progressive::to_fixed(v));
                    }
                }
            }
            let d = u64::from(done.fetch_add(1, Ordering::Relaxed) + 1);
            if !progress((d * n / rows_n) as u32) {
                cancelled.store(true, Ordering::Relaxed);
            }
            rays
        })
        .sum();
    if cancelled.load(Ordering::Relaxed) {
        return None;
    }
    Some(progressive::PassSums { rows, passes: samples, sums, rays, photon_paths: 0, photon_seconds: 0.0 })
}

/// Sample `i` of pixel `(x, y)`: the radiance the method's estimator ([`li`]) returns along its camera ray.
fn pixel_sample(prep: &Prepared, x: u32, y: u32, i: u32, rays: &mut u64) -> Rgb {
    let (ray, mut s) = camera_sample(prep, prep.settings.seed, x, y, i);
    li(prep, ray, &mut s, rays)
}

/// Camera ray and sample stream of sample `i` in pixel `(x, y)`. The stream's first draw places the sample in
/// the pixel (a box filter), its second on the lens; the samples of a pixel are one Sobol sequence, so both
/// are stratified over `i` (see [`Sampler`]).
fn camera_sample(prep: &Prepared, seed: u64, x: u32, y: u32, i: u32) -> (Ray, Sampler) {
    let mut s = Sampler::for_pixel(seed, x, y, i);
    let film = Vec2::new(x as f32, y as f32) + s.next_2d();
    let ray = prep.camera.ray(film, s.next_2d());
    (ray, s)
}

/// Renders the whole image on this machine.
pub fn render_image(prep: &Prepared, progress: &(dyn Fn(u32) + Sync)) -> Strip {
    render_strip(prep, 0..prep.camera.height, progress)
}
