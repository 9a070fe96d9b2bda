//! `progressive`: probabilistic progressive photon mapping (Knaus & Zwicker 2011, "Progressive Photon Mapping:
//! A Probabilistic Approach", ACM TOG 30(3)).
//!
//! Pass `p` (0-based, numbered over the whole render) traces its own photons from the streams `(seed, p + 2, i)`
//! (0 and 1 belong to the static global and caustic maps), takes camera sample `p` of each pixel, and estimates
//! that pixel's radiance with a box kernel of a radius that depends only on the pass index:
//!
//! `r_{i+1}² = r_i² · (i + α) / (i + 1)` (1-based `i`; Knaus & Zwicker, eq. 15), `r_1 = render.photons.radius`.
//!
//! The passes are independent estimates, and averaging them makes both the variance (`O(1/N^α)`) and the bias
//! (`O(1/N^(1−α))`) vanish (their §4), so the method is consistent. No state is carried from pass to pass, so
//! passes can be rendered anywhere: the farm hands out whole-image **pass blocks**, and each pass is traced
//! exactly once in the whole farm.
//!
//! Direct light comes from light sampling at the visible point; photons carry indirect light only
//! (light → anything⁺ → diffuse), so each light path is counted once.
//!
//! # Exact sums, so the farm's cut never changes a pixel
//! A pass's estimate of each pixel channel is rounded to a fixed-point integer with [`SUM_FRACTION_BITS`]
//! fraction bits (a quantum of 6·10⁻⁸; values are clamped to `[0, MAX_PASS_RADIANCE]`) and the passes are
//! added as integers. Integer addition is exact and associative, so the image is the same whatever the blocks,
//! their order of arrival, the workers and the threads: it depends only on (scene, seed, passes). A block of at
//! most [`MAX_BLOCK_PASSES`] passes fits `i64`; the whole render is summed in `i128` ([`PassAccumulator`]).

use super::{Strip, camera_sample};
use crate::Rgb;
use crate::integrator::volume::{Strategy, in_scattering, segment_point};
use crate::integrator::{sample_one_light, visible_point, visible_point_in};
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::medium::Medium;
use crate::photon::{Estimator, Gather, Kernel, PhotonMap, photon_flux, volume_radiance};
use crate::prepare::Prepared;
use crate::prepare::budget::passes_at_once;
use crate::prepare::photons::{PhotonKind, trace_photons, volume_map};
use rayon::prelude::*;
use std::ops::Range;
use std::time::Instant;

/// Fraction bits of the fixed-point pass sums: one unit is 2⁻²⁴ W·sr⁻¹·m⁻².
pub const SUM_FRACTION_BITS: u32 = 24;

/// The largest radiance one pass may add to a pixel channel (2²⁴ W·sr⁻¹·m⁻²); a larger estimate (a firefly of a
/// vanishing radius, or an emitter brighter than this seen directly) is clamped to it.
pub const MAX_PASS_RADIANCE: f32 = 16_777_216.0;

/// The most passes one block may hold: `MAX_BLOCK_PASSES × 2⁴⁸` (the largest fixed-point value of one pass) stays
/// below `i64::MAX = 2⁶³ − 1`.
pub const MAX_BLOCK_PASSES: u32 = (1 << 15) - 1;

/// The largest fixed-point value one pass adds to one channel.
pub const MAX_PASS_SUM: i64 = (MAX_PASS_RADIANCE as i64) << SUM_FRACTION_BITS;

/// The squared gather radius of pass `pass` (0-based): `r0² · Π_{i=1}^{pass} (i + α) / (i + 1)` (Knaus &
/// Zwicker 2011, eq. 15), computed in f64 in a fixed order.
pub fn pass_radius2(r0: f32, alpha: f32, pass: u32) -> f32 {
    RadiusSequence::at(r0, alpha, pass).r2()
}

/// The radius sequence walked pass by pass: the product of [`pass_radius2`] kept from one pass to the next, so a
/// block pays for the passes before it once, not once per pass. Each step multiplies in the same order as the
/// whole product, so every value is bit for bit [`pass_radius2`]'s.
#[derive(Clone, Copy, Debug)]
pub(super) struct RadiusSequence {
    r0: f64,
    alpha: f64,
    pass: u32,
    /// `Π_{i=1}^{pass} (i + α) / (i + 1)`, multiplied left to right.
    ratio: f64,
}

impl RadiusSequence {
    pub(super) fn at(r0: f32, alpha: f32, pass: u32) -> Self {
        let start = Self { r0: f64::from(r0), alpha: f64::from(alpha), pass: 0, ratio: 1.0 };
        (0..pass).fold(start, |s, _| s.next())
    }

    pub(super) fn next(self) -> Self {
        let i = f64::from(self.pass + 1);
        Self { pass: self.pass + 1, ratio: self.ratio * ((i + self.alpha) / (i + 1.0)), ..self }
    }

    pub(super) fn r2(&self) -> f32 {
        (self.r0 * self.r0 * self.ratio) as f32
    }
}

/// The fixed-point value of one pass's estimate of one channel: `round(v · 2²⁴)`, with `v` clamped to
/// `[0, MAX_PASS_RADIANCE]` and a non-finite `v` taken as 0.
#[inline]
pub fn to_fixed(v: f32) -> i64 {
    if !v.is_finite() {
        return 0;
    }
    (f64::from(v.clamp(0.0, MAX_PASS_RADIANCE)) * f64::from(1u32 << SUM_FRACTION_BITS)).round() as i64
}

/// The mean of `n` fixed-point estimates whose sum is `sum`: `sum / (2²⁴ · n)`, divided in f64 then rounded to
/// f32 (the one division of every pixel of a strip and of a pass accumulator, so both give the same bits).
#[inline]
pub fn fixed_mean(sum: i128, n: u32) -> f32 {
    let scale = f64::from(1u32 << SUM_FRACTION_BITS) * f64::from(n.max(1));
    (sum as f64 / scale) as f32
}

/// `Σ_{p ∈ passes} (r_p / r_0)^power`: the gather radii of passes `passes` relative to the first one's, raised to
/// `power`. The kernel bias of a density estimate grows as `r²` where the density is smooth (Hachisuka, Ogaki &
/// Jensen 2008, §4.3) and as `r` at its edges, so this sum is the factor by which the passes' mean bias differs
/// from the first pass's. Walks the sequence once, `O(passes.end)`.
pub fn radius_power_sum(alpha: f32, passes: Range<u32>, power: f64) -> f64 {
    let mut r = RadiusSequence::at(1.0, alpha, 0);
    let mut sum = 0.0;
    while r.pass < passes.end {
        if r.pass >= passes.start {
            sum += r.ratio.powf(power / 2.0);
        }
        r = r.next();
    }
    sum
}

/// The pixel sums of a block of passes over some rows.
#[derive(Clone, Debug, PartialEq)]
pub struct PassSums {
    /// The rows rendered.
    pub rows: Range<u32>,
    /// The passes rendered.
    pub passes: Range<u32>,
    /// Per pixel channel (3 per pixel, row-major), the sum over the passes of [`to_fixed`] of its estimate.
    pub sums: Vec<i64>,
    /// Rays traced.
    pub rays: u64,
    /// Photon paths traced.
    pub photon_paths: u64,
    /// Seconds spent tracing photons and building their maps (wall clock).
    pub photon_seconds: f64,
}

/// Why a block's sums cannot be valid.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PassSumsError {
    /// A sum lies outside `[0, passes × MAX_PASS_SUM]`.
    #[error("value {index} of a block of {passes} passes is {value}, outside [0, {max}]")]
    OutOfRange {
        /// Index of the value (3 per pixel).
        index: usize,
        /// The value.
        value: i64,
        /// Passes in the block.
        passes: u32,
        /// The largest valid value.
        max: i64,
    },
}

/// Checks that every sum of a block of `passes` passes could have come from [`render_passes`].
pub fn check_sums(sums: &[i64], passes: u32) -> Result<(), PassSumsError> {
    let max = MAX_PASS_SUM.saturating_mul(i64::from(passes));
    match sums.iter().position(|&v| !(0..=max).contains(&v)) {
        Some(index) => Err(PassSumsError::OutOfRange { index, value: sums[index], passes, max }),
        None => Ok(()),
    }
}

/// Renders passes `passes` over rows `rows`: each pixel channel's sum over those passes of its fixed-point
/// estimate. At most [`MAX_BLOCK_PASSES`] passes (more are cut off, as a caller that checked its input never asks
/// for). `progress` gets the passes finished so far and returns `false` to cancel (then `None`).
///
/// For progressive photon mapping a pass is one photon pass ([`PassSums`]); several passes trace their photons
/// and build their maps side by side (as many as the threads, within a memory bound), and each pass's gather
/// then runs over the rows in parallel. For the other methods a pass is one camera sample of every pixel, the
/// sample of that index, summed in fixed point as the strip renderer sums a pixel's samples: blocks of samples
/// are how a render bounded by time or error is cut, and `K` samples in any blocks give the bits of a strip
/// rendered at `K` samples per pixel.
pub fn render_passes(
    prep: &Prepared,
    rows: Range<u32>,
    passes: Range<u32>,
    progress: &(dyn Fn(u32) -> bool + Sync),
) -> Option<PassSums> {
    let passes = passes.start..passes.end.min(passes.start.saturating_add(MAX_BLOCK_PASSES));
    if let Some(techniques) = super::vcm::Techniques::of(prep.settings.integrator)
        && prep.media.is_none()
    {
        return super::vcm::render_passes(prep, techniques, rows, passes, progress);
    }
    if prep.settings.integrator != crate::scene::Integrator::Progressive {
        return super::render_sample_block(prep, rows, passes, progress);
    }
    let ph = &prep.settings.photons;
    let width = prep.camera.width as usize;
    let mut sums = vec![0i64; 3 * width * rows.len()];
    let (mut rays, mut photon_paths, mut photon_seconds) = (0u64, 0u64, 0.0f64);
    // How many passes trace side by side changes the speed and the memory, never a pixel.
    let group = passes_at_once(ph.pass_photons, rayon::current_num_threads());
    let mut done = 0u32;
    let mut radius = RadiusSequence::at(prep.photon_radius(), ph.alpha, passes.start);
    let mut start = passes.start;
    while start < passes.end {
        let end = start.saturating_add(group).min(passes.end);
        let t0 = Instant::now();
        let maps: Vec<PassMaps> = (start..end).into_par_iter().map(|p| pass_map(prep, p)).collect();
        photon_seconds += t0.elapsed().as_secs_f64();
        for (pass, maps) in (start..end).zip(maps) {
            photon_paths += maps.paths;
            debug_assert_eq!(radius.pass, pass);
            rays += render_pass(prep, &rows, pass, radius.r2(), &maps, &mut sums);
            radius = radius.next();
            done += 1;
            if !progress(done) {
                return None;
            }
        }
        start = end;
    }
    Some(PassSums { rows, passes, sums, rays, photon_paths, photon_seconds })
}

/// The photon maps of one pass: surfaces, and media in a scene that has them.
struct PassMaps {
    surface: Option<PhotonMap>,
    volume: Option<PhotonMap>,
    paths: u64,
}

/// The photon maps of pass `pass` and the paths traced for it. A map that cannot be built (no photon was
/// stored) contributes nothing.
fn pass_map(prep: &Prepared, pass: u32) -> PassMaps {
    let n = u64::from(prep.settings.photons.pass_photons);
    let traced = trace_photons(prep, n, u64::from(pass) + 2, PhotonKind::Indirect);
    let surface = PhotonMap::build(traced.photons).map_err(|e| tracing::warn!("pass {pass}: {e}")).ok();
    let volume = volume_map(traced.volume).map_err(|e| tracing::warn!("pass {pass}, volume: {e}")).ok().flatten();
    PassMaps { surface, volume, paths: traced.paths }
}

/// Adds pass `pass`'s fixed-point estimates of rows `rows`, gathered at squared radius `r2`, to `sums`; returns
/// the rays traced.
fn render_pass(prep: &Prepared, rows: &Range<u32>, pass: u32, r2: f32, maps: &PassMaps, sums: &mut [i64]) -> u64 {
    let ph = &prep.settings.photons;
    let est = Estimator {
        gather: Gather::Radius { radius: r2.sqrt() },
        kernel: Kernel::Box,
        disc: ph.disc,
        same_object: ph.same_object,
    };
    // The volume radius shrinks so that r³ follows the sequence r² follows (the variance of a 3D estimate grows
    // as 1/r³ where a surface's grows as 1/r²; Knaus & Zwicker 2011, §4.3, with dimension 3).
    let r0 = prep.photon_radius();
    let ratio = if r0 > 0.0 { r2 / (r0 * r0) } else { 1.0 };
    let volume = maps.volume.as_ref().map(|v| (v, prep.volume_radius() * crate::math::fmath::cbrt(ratio)));
    let width = prep.camera.width as usize;
    sums.par_chunks_mut(3 * width)
        .zip(rows.clone().into_par_iter())
        .map(|(row, y)| {
            let mut rays = 0u64;
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                let c = pixel_estimate(prep, maps.surface.as_ref(), volume, &est, r2, (x as u32, y), pass, &mut rays);
                for (s, v) in px.iter_mut().zip(c.to_array()) {
                    *s = s.saturating_add(to_fixed(v));
                }
            }
            rays
        })
        .sum()
}

/// Pass `pass`'s radiance estimate at pixel `xy`: emission and light sampling at the visible point, plus the
/// box-kernel photon estimate `β · Σ f·Φ / (π r²)` there (Knaus & Zwicker 2011, eq. 4). In a scene with media,
/// each medium segment of the camera walk adds single scattering ([`in_scattering`]) and the volume map's box
/// estimate at radius `volume.1` at one point of the segment ([`segment_point`]). Non-finite parts count as zero.
#[allow(clippy::too_many_arguments)]
fn pixel_estimate(
    prep: &Prepared,
    map: Option<&PhotonMap>,
    volume: Option<(&PhotonMap, f32)>,
    est: &Estimator,
    r2: f32,
    (x, y): (u32, u32),
    pass: u32,
    rays: &mut u64,
) -> Rgb {
    let settings = &prep.settings;
    let seed = settings.seed;
    let (ray, mut s) = camera_sample(prep, seed, x, y, pass);
    let vp = match &prep.media {
        None => visible_point(prep, settings.max_depth, ray, &mut s, rays),
        Some(media) => {
            let mut along = |r: &Ray, m: &Medium, t_max: f32, s: &mut Sampler, rays: &mut u64| -> Rgb {
                let Some((t, pdf, w)) = segment_point(m, t_max, s) else { return Rgb::ZERO };
                let mass = m.segment_mass(t_max);
                let density = |x: f32| m.distance_pdf(x) / mass;
                let direct = in_scattering(prep, m, r, t_max, Some((t, pdf)), &density, Strategy::Mis, false, s, rays);
                let indirect = match volume {
                    Some((v, radius)) => w * volume_radiance(v, r.at(t), r.d, m.g, Gather::Radius { radius }),
                    None => Rgb::ZERO,
                };
                finite_or_zero(direct) + finite_or_zero(indirect)
            };
            visible_point_in(prep, settings.max_depth, ray, media.camera, &mut s, rays, &mut along)
        }
    };
    let Some((beta, hit, bsdf, wo)) = vp.vertex else { return finite_or_zero(vp.le) + finite_or_zero(vp.volume) };
    let ld = vp.le + beta * sample_one_light(prep, &hit, &bsdf, wo, vp.medium, &mut s, rays, false);
    let ld = finite_or_zero(ld) + finite_or_zero(vp.volume);
    let Some(map) = map else { return finite_or_zero(ld) };
    let (phi, m) = photon_flux(map, est, &hit, &bsdf, wo);
    let area = std::f32::consts::PI * r2;
    let indirect = if m > 0 && area > 0.0 { beta * phi / area } else { Rgb::ZERO };
    finite_or_zero(ld) + finite_or_zero(indirect)
}

/// The fixed-point sums of a whole render, added block by block in any order; gives the image, the mean over
/// all passes.
#[derive(Clone, Debug, PartialEq)]
pub struct PassAccumulator {
    passes: u32,
    sums: Vec<i128>,
}

impl PassAccumulator {
    /// An accumulator of `len` values (3 per pixel) for a render of `passes` passes in all.
    pub fn new(len: usize, passes: u32) -> Self {
        Self { passes: passes.max(1), sums: vec![0; len] }
    }

    /// Adds a block's sums (as many as [`PassAccumulator::new`] was given; extra values are ignored).
    pub fn add(&mut self, sums: &[i64]) {
        for (s, &v) in self.sums.iter_mut().zip(sums) {
            *s += i128::from(v);
        }
    }

    /// Adds `other`'s sums (as many as both hold) and zeroes `other`: a finished round joins the image.
    pub fn absorb(&mut self, other: &mut Self) {
        for (s, o) in self.sums.iter_mut().zip(other.sums.iter_mut()) {
            *s += std::mem::take(o);
        }
    }

    /// The sums so far (for a partial file).
    pub fn sums(&self) -> &[i128] {
        &self.sums
    }

    /// Restores sums saved by [`PassAccumulator::sums`]; `false` (and no change) when the length differs.
    pub fn restore(&mut self, sums: &[i128]) -> bool {
        if sums.len() != self.sums.len() {
            return false;
        }
        self.sums.copy_from_slice(sums);
        true
    }

    /// The image: linear RGB radiance, each value the sum divided by `2²⁴ × passes` ([`fixed_mean`]).
    pub fn image(&self) -> Vec<f32> {
        self.sums.iter().map(|&s| fixed_mean(s, self.passes)).collect()
    }

    /// The image over `passes` passes in all (the passes added so far, when a render stops at a bound rather
    /// than at the count it was created with).
    pub fn image_of(&self, passes: u32) -> Vec<f32> {
        self.sums.iter().map(|&s| fixed_mean(s, passes.max(1))).collect()
    }
}

/// Every pass over rows `rows`, in blocks of at most [`MAX_BLOCK_PASSES`]: the same pixels as a farm render,
/// whatever its blocks. `progress` gets rows-equivalent done so far (`rows.len()` at the end).
pub(super) fn render_strip(
    prep: &Prepared,
    rows: Range<u32>,
    progress: &(dyn Fn(u32) -> bool + Sync),
) -> Option<Strip> {
    let total = prep.settings.photons.passes.max(1);
    let width = prep.camera.width as usize;
    let mut acc = PassAccumulator::new(3 * width * rows.len(), total);
    let (mut rays, mut photon_paths) = (0, 0);
    let rows_n = rows.len() as u64;
    let mut start = 0;
    while start < total {
        let end = start.saturating_add(MAX_BLOCK_PASSES).min(total);
        let block_progress = |n: u32| progress(((u64::from(start + n)) * rows_n / u64::from(total)) as u32);
        let block = render_passes(prep, rows.clone(), start..end, &block_progress)?;
        rays += block.rays;
        photon_paths += block.photon_paths;
        acc.add(&block.sums);
        start = end;
    }
    Some(Strip { rows, pixels: acc.image(), rays, photon_paths })
}

/// `c`, or zero when a channel is not finite (an estimate that must not poison a fixed-point sum).
pub(super) fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() { c } else { Rgb::ZERO }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_radius_sequence_follows_its_recurrence() {
        let (r0, alpha) = (0.1f32, 2.0 / 3.0);
        assert_eq!(pass_radius2(r0, alpha, 0), r0 * r0);
        for i in 1..200u32 {
            let expected =
                f64::from(pass_radius2(r0, alpha, i - 1)) * (f64::from(i) + f64::from(alpha)) / (f64::from(i) + 1.0);
            assert!((f64::from(pass_radius2(r0, alpha, i)) - expected).abs() <= 1e-6 * expected);
        }
        // Walking the sequence gives the same bits as the whole product computed from scratch for each pass.
        let mut walk = RadiusSequence::at(r0, alpha, 0);
        for i in 0..300u32 {
            let a = f64::from(alpha);
            let ratio: f64 = (1..=i).map(|k| (f64::from(k) + a) / (f64::from(k) + 1.0)).product();
            let scratch = (f64::from(r0) * f64::from(r0) * ratio) as f32;
            assert_eq!(walk.r2().to_bits(), scratch.to_bits(), "pass {i}");
            assert_eq!(RadiusSequence::at(r0, alpha, i).r2().to_bits(), scratch.to_bits(), "pass {i}");
            walk = walk.next();
        }
        // r_i² ~ i^(α−1): the ratio of radii 1000 passes apart follows the power law within a percent.
        let ratio = f64::from(pass_radius2(r0, alpha, 1999) / pass_radius2(r0, alpha, 999));
        assert!((ratio / 2f64.powf(f64::from(alpha) - 1.0) - 1.0).abs() < 0.01, "{ratio}");
    }

    #[test]
    fn fixed_point_keeps_radiance_to_its_quantum_and_refuses_nothing_finite() {
        let quantum = 1.0 / f64::from(1u32 << SUM_FRACTION_BITS);
        for v in [0.0f32, 1e-9, 0.3, 1.0, 123.456, 1e6] {
            let back = to_fixed(v) as f64 * quantum;
            assert!((back - f64::from(v)).abs() <= 0.5 * quantum + f64::from(v) * 1e-15, "{v}: {back}");
        }
        assert_eq!(to_fixed(f32::NAN), 0);
        assert_eq!(to_fixed(f32::INFINITY), 0);
        assert_eq!(to_fixed(-1.0), 0);
        assert_eq!(to_fixed(1e30), MAX_PASS_SUM);
        // A full block at the clamp fits i64.
        assert!(MAX_PASS_SUM.checked_mul(i64::from(MAX_BLOCK_PASSES)).is_some());
    }

    #[test]
    fn sums_are_checked_against_the_block_length() {
        assert_eq!(check_sums(&[0, 5, MAX_PASS_SUM * 2], 2), Ok(()));
        assert!(matches!(check_sums(&[0, -1], 2), Err(PassSumsError::OutOfRange { index: 1, .. })));
        assert!(matches!(check_sums(&[MAX_PASS_SUM * 2 + 1], 2), Err(PassSumsError::OutOfRange { index: 0, .. })));
    }

    #[test]
    fn the_accumulator_is_exact_whatever_the_order_of_blocks() {
        let blocks: Vec<Vec<i64>> = (0..7)
            .map(|i| vec![to_fixed(0.1 * i as f32 + 1e-7), to_fixed(3.3 / (i + 1) as f32), i64::MAX / 8])
            .collect();
        let mut in_order = PassAccumulator::new(3, 7);
        for b in &blocks {
            in_order.add(b);
        }
        let mut shuffled = PassAccumulator::new(3, 7);
        for i in [3, 1, 6, 4, 0, 5, 2] {
            shuffled.add(&blocks[i]);
        }
        assert_eq!(in_order, shuffled);
        assert_eq!(in_order.image(), shuffled.image());
        let mean = (0..7).map(|i| 0.1 * f64::from(i) + 1e-7).sum::<f64>() / 7.0;
        assert!((f64::from(in_order.image()[0]) - mean).abs() < 1e-6);
    }
}
