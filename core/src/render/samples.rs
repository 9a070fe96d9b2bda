//! The sample driver: camera samples of every pixel of some rows through a per-ray estimator, and the one rows ×
//! pixels loop that every method's block renderer runs its pixels through.
//!
//! Each pixel sample draws from its own stream identified by `(seed, x, y, sample)`, so a pixel's value does not
//! depend on blocks, threads or workers. The samples of a pixel are the points of one padded, scrambled
//! Sobol sequence ([`Sampler`]): their first draw places them in the pixel (a box filter), and every aligned
//! block of 2^m samples has one sample in each elementary interval of area 2^−m, in the pixel and in every
//! later 2D draw (lens, light, BSDF). Each point is uniformly distributed, so the estimate is unbiased. No sample
//! depends on how many there will be, so the first `K` samples are the same points whether `K` was fixed ahead
//! (`--spp`) or reached by a time or error bound.

use super::sums::{BlockSums, add_fixed};
use crate::Rgb;
use crate::integrator::estimate;
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::method::CameraEstimator;
use crate::prepare::Prepared;
use crate::prepare::tracer::Tracer;
use crate::run::{Cancel, RunError};
use glam::Vec2;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicU32, Ordering};

/// Runs `pixel(x, y, sums, rays)` on every pixel of rows `rows`, in parallel over rows: `sums` holds 3 values
/// per pixel, row-major, and `pixel` adds (or writes) its pixel's three.
/// `cancel` is checked before every pixel (and `pixel` may check it more often); once it is set the pixels not
/// yet started are skipped and the result is [`RunError::Cancelled`]. Returns the rays the pixels counted.
pub(super) fn for_each_pixel<F>(
    width: usize,
    rows: &Range<u32>,
    sums: &mut [i64],
    cancel: &Cancel,
    pixel: F,
) -> Result<u64, RunError>
where
    F: Fn(u32, u32, &mut [i64], &mut u64) + Sync,
{
    for_each_pixel_row(width, rows, sums, cancel, &|| (), pixel)
}

/// [`for_each_pixel`], calling `row_done` after each row.
fn for_each_pixel_row<F>(
    width: usize,
    rows: &Range<u32>,
    sums: &mut [i64],
    cancel: &Cancel,
    row_done: &(dyn Fn() + Sync),
    pixel: F,
) -> Result<u64, RunError>
where
    F: Fn(u32, u32, &mut [i64], &mut u64) + Sync,
{
    let rays = sums
        .par_chunks_mut(3 * width)
        .zip(rows.clone().into_par_iter())
        .map(|(row, y)| {
            let mut rays = 0u64;
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                if cancel.is_cancelled() {
                    return 0;
                }
                pixel(x as u32, y, px, &mut rays);
            }
            row_done();
            rays
        })
        .sum();
    cancel.check()?;
    Ok(rays)
}

/// Samples `samples` of every pixel of rows `rows` by `estimator`: each pixel channel's sum of their fixed-point
/// values. `progress` gets the samples finished so far (rows done scaled to samples); `cancel` is checked
/// before every sample.
pub(super) fn render(
    prep: &Prepared,
    estimator: CameraEstimator,
    rows: Range<u32>,
    samples: Range<u32>,
    progress: &(dyn Fn(u32) + Sync),
    cancel: &Cancel,
) -> Result<BlockSums, RunError> {
    let width = prep.camera.width as usize;
    let (n, rows_n) = (u64::from(samples.end.saturating_sub(samples.start)), rows.len().max(1) as u64);
    let done = AtomicU32::new(0);
    let row_done = || {
        let d = u64::from(done.fetch_add(1, Ordering::Relaxed) + 1);
        progress((d * n / rows_n) as u32);
    };
    let mut sums = vec![0i64; 3 * width * rows.len()];
    let rays = for_each_pixel_row(width, &rows, &mut sums, cancel, &row_done, |x, y, px, rays| {
        for i in samples.clone() {
            if cancel.is_cancelled() {
                return;
            }
            add_fixed(px, pixel_sample(prep, estimator, x, y, i, rays));
        }
    })?;
    Ok(BlockSums { rows, units: samples, sums, rays, photon_paths: 0, photon_seconds: 0.0 })
}

/// Sample `i` of pixel `(x, y)`: the radiance `estimator` returns along its camera ray.
fn pixel_sample(prep: &Prepared, estimator: CameraEstimator, x: u32, y: u32, i: u32, rays: &mut u64) -> Rgb {
    let (ray, s) = camera_sample(prep, prep.settings.seed, x, y, i);
    let mut tracer = Tracer::new(prep, s);
    let l = estimate(&mut tracer, estimator, ray);
    *rays += tracer.rays;
    l
}

/// Camera ray and sample stream of sample `i` in pixel `(x, y)`. The stream's first draw places the sample in
/// the pixel (a box filter), its second on the lens; the samples of a pixel are one Sobol sequence, so both
/// are stratified over `i` (see [`Sampler`]).
pub(super) fn camera_sample(prep: &Prepared, seed: u64, x: u32, y: u32, i: u32) -> (Ray, Sampler) {
    let mut s = Sampler::for_pixel(seed, x, y, i);
    let film = Vec2::new(x as f32, y as f32) + s.next_2d();
    let ray = prep.camera.ray(film, s.next_2d());
    (ray, s)
}
