//! The strip renderer: rows of pixels in parallel with rayon.
//!
//! Each pixel sample draws from its own stream seeded by `(seed, x, y, sample)`, so a pixel's value does not
//! depend on strips, threads or workers. Sample positions in the pixel (a box filter) follow the (0,2)-sequence:
//! sample `i` lies at (second Sobol dimension of `i`, van der Corput radical inverse of `i`) (Kollig & Keller
//! 2002, "Efficient Multidimensional Sampling", §2.2), whose every prefix of 2^m samples has one sample in each
//! elementary interval of area 2^−m; the whole pattern is rotated by a per-pixel random offset
//! (Cranley–Patterson), which keeps every sample uniformly distributed and the estimate unbiased. No sample
//! depends on how many there will be, so the first `K` samples are the same points whether `K` was fixed ahead
//! (`--spp`) or reached by a time or error bound.
//!
//! A pixel's samples are summed as fixed-point integers ([`progressive::to_fixed`]) and divided once
//! ([`progressive::fixed_mean`]): the sum is exact in any order, so `K` samples rendered as a strip and the same
//! `K` samples rendered as sample blocks on many workers ([`progressive::render_passes`]) give the same bits.

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

/// The mean radiance of pixel `(x, y)` over `render.spp` samples, summed in fixed point (see the module
/// documentation). A non-finite sample channel (which a correct integrator never makes) counts as zero rather
/// than poisoning the image.
pub fn render_pixel(prep: &Prepared, x: u32, y: u32, rays: &mut u64) -> Rgb {
    let settings = &prep.settings;
    let spp = settings.spp.max(1);
    let offset = pixel_rotation(settings.seed, x, y);
    let mut sum = [0i128; 3];
    for i in 0..spp {
        let c = pixel_sample(prep, x, y, i, offset, rays);
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
                let offset = pixel_rotation(prep.settings.seed, x, y);
                for i in samples.clone() {
                    let c = pixel_sample(prep, x, y, i, offset, &mut rays);
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

/// Sample `i` of pixel `(x, y)` (whose pattern is rotated by `offset`, [`pixel_rotation`]): the radiance the
/// method's estimator ([`li`]) returns along its camera ray.
fn pixel_sample(prep: &Prepared, x: u32, y: u32, i: u32, offset: Vec2, rays: &mut u64) -> Rgb {
    let (ray, mut s) = camera_sample(prep, prep.settings.seed, x, y, i, offset);
    li(prep, ray, &mut s, rays)
}

/// The per-pixel Cranley–Patterson rotation of the sample pattern.
fn pixel_rotation(seed: u64, x: u32, y: u32) -> Vec2 {
    Sampler::for_pixel(seed, x, y, u32::MAX).next_2d()
}

/// Camera ray and random stream of sample `i` in pixel `(x, y)`.
fn camera_sample(prep: &Prepared, seed: u64, x: u32, y: u32, i: u32, rotation: Vec2) -> (Ray, Sampler) {
    let mut s = Sampler::for_pixel(seed, x, y, i);
    let strat = Vec2::new(sobol_2(i), radical_inverse_2(i));
    let film = Vec2::new(x as f32, y as f32) + (strat + rotation).fract();
    let ray = prep.camera.ray(film, s.next_2d());
    (ray, s)
}

/// The base-2 radical inverse (van der Corput sequence) of `i`.
#[inline]
fn radical_inverse_2(i: u32) -> f32 {
    (i.reverse_bits() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// The second dimension of the Sobol sequence at index `i` (generator matrix: Pascal's triangle mod 2), in
/// `[0, 1)` with 24 bits: with [`radical_inverse_2`] it makes the (0,2)-sequence (Kollig & Keller 2002, §2.2).
#[inline]
fn sobol_2(i: u32) -> f32 {
    let (mut bits, mut v, mut n) = (0u32, 1u32 << 31, i);
    while n != 0 {
        if n & 1 != 0 {
            bits ^= v;
        }
        n >>= 1;
        v ^= v >> 1;
    }
    (bits >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Renders the whole image on this machine.
pub fn render_image(prep: &Prepared, progress: &(dyn Fn(u32) + Sync)) -> Strip {
    render_strip(prep, 0..prep.camera.height, progress)
}
