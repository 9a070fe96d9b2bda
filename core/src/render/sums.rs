//! The fixed-point contract of every unit of work: a block of units (camera samples or whole-image passes) over
//! some rows is summed per pixel channel as integers, so that the image depends only on (scene, seed, units),
//! never on the farm's cut, the order in which blocks arrive, the workers or the threads.
//!
//! A unit's estimate of a pixel channel is rounded to a fixed-point integer with [`SUM_FRACTION_BITS`] fraction
//! bits (a quantum of 6·10⁻⁸ W·sr⁻¹·m⁻²; values are clamped to `[0, MAX_UNIT_RADIANCE]`) and units are added as
//! integers. Integer addition is exact and associative. A block of at most [`MAX_BLOCK_UNITS`] units fits
//! `i64` ([`BlockSums`]); the whole render is summed in `i128` ([`SumAccumulator`]) and divided once
//! ([`fixed_mean`]).

use crate::Rgb;
use std::ops::Range;

/// Fraction bits of the fixed-point sums: one unit is 2⁻²⁴ W·sr⁻¹·m⁻².
pub const SUM_FRACTION_BITS: u32 = 24;

/// The largest radiance one unit may add to a pixel channel (2²⁴ W·sr⁻¹·m⁻²); a larger estimate (a firefly of a
/// vanishing radius, or an emitter brighter than this seen directly) is clamped to it.
pub const MAX_UNIT_RADIANCE: f32 = 16_777_216.0;

/// The most units one block may hold: `MAX_BLOCK_UNITS × 2⁴⁸` (the largest fixed-point value of one unit) stays
/// below `i64::MAX = 2⁶³ − 1`.
pub const MAX_BLOCK_UNITS: u32 = (1 << 15) - 1;

/// The largest fixed-point value one unit adds to one channel.
pub const MAX_UNIT_SUM: i64 = (MAX_UNIT_RADIANCE as i64) << SUM_FRACTION_BITS;

/// The fixed-point value of one unit's estimate of one channel: `round(v · 2²⁴)`, with `v` clamped to
/// `[0, MAX_UNIT_RADIANCE]` and a non-finite `v` taken as 0.
#[inline]
pub fn to_fixed(v: f32) -> i64 {
    if !v.is_finite() {
        return 0;
    }
    (f64::from(v.clamp(0.0, MAX_UNIT_RADIANCE)) * f64::from(1u32 << SUM_FRACTION_BITS)).round() as i64
}

/// The mean of `n` fixed-point estimates whose sum is `sum`: `sum / (2²⁴ · n)`, divided in f64 then rounded to
/// f32: the one division of every pixel of an image.
#[inline]
pub fn fixed_mean(sum: i128, n: u32) -> f32 {
    let scale = f64::from(1u32 << SUM_FRACTION_BITS) * f64::from(n.max(1));
    (sum as f64 / scale) as f32
}

/// Adds the fixed-point value of each channel of `c` to a pixel's three sums.
#[inline]
pub fn add_fixed(px: &mut [i64], c: Rgb) {
    for (s, v) in px.iter_mut().zip(c.to_array()) {
        *s = s.saturating_add(to_fixed(v));
    }
}

/// `c`, or black when any channel is not finite.
pub fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() { c } else { Rgb::ZERO }
}

/// A unit of work: units `units` (camera samples of each pixel, or whole-image passes, as the method's
/// [`crate::method::Unit`] says) over rows `rows` of the image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// The rows rendered.
    pub rows: Range<u32>,
    /// The units rendered, numbered over the whole render (at most [`MAX_BLOCK_UNITS`] of them).
    pub units: Range<u32>,
}

/// The pixel sums of a block.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockSums {
    /// The rows rendered.
    pub rows: Range<u32>,
    /// The units rendered.
    pub units: Range<u32>,
    /// Per pixel channel (3 per pixel, row-major), the sum over the units of [`to_fixed`] of its estimate.
    pub sums: Vec<i64>,
    /// Rays traced.
    pub rays: u64,
    /// Photon paths (or light subpaths) traced for the block.
    pub photon_paths: u64,
    /// Seconds spent tracing photons (or light subpaths) and building their maps (wall clock; the passes traced
    /// ahead overlap the gathering of the passes before them, so this may exceed the share of the block's time).
    pub photon_seconds: f64,
}

/// Why a block's sums cannot be valid.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BlockSumsError {
    /// A sum lies outside `[0, units × MAX_UNIT_SUM]`.
    #[error("value {index} of a block of {units} units is {value}, outside [0, {max}]")]
    OutOfRange {
        /// Index of the value (3 per pixel).
        index: usize,
        /// The value.
        value: i64,
        /// Units in the block.
        units: u32,
        /// The largest valid value.
        max: i64,
    },
}

/// Checks that every sum of a block of `units` units could have come from [`super::render_block`].
pub fn check_sums(sums: &[i64], units: u32) -> Result<(), BlockSumsError> {
    let max = MAX_UNIT_SUM.saturating_mul(i64::from(units));
    match sums.iter().position(|&v| !(0..=max).contains(&v)) {
        Some(index) => Err(BlockSumsError::OutOfRange { index, value: sums[index], units, max }),
        None => Ok(()),
    }
}

/// The fixed-point sums of a whole render, added block by block in any order; gives the image, the mean over
/// all units.
#[derive(Clone, Debug, PartialEq)]
pub struct SumAccumulator {
    units: u32,
    sums: Vec<i128>,
}

impl SumAccumulator {
    /// An accumulator of `len` values (3 per pixel) for a render of `units` units per pixel in all.
    pub fn new(len: usize, units: u32) -> Self {
        Self { units: units.max(1), sums: vec![0; len] }
    }

    /// Adds a block's sums at value `offset` (3 per pixel: `3 × width × first row` for a block of rows; extra
    /// values are ignored).
    pub fn add_at(&mut self, offset: usize, sums: &[i64]) {
        let tail = self.sums.get_mut(offset..).unwrap_or_default();
        for (s, &v) in tail.iter_mut().zip(sums) {
            *s += i128::from(v);
        }
    }

    /// Adds a block's sums from the first value.
    pub fn add(&mut self, sums: &[i64]) {
        self.add_at(0, sums);
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

    /// Restores sums saved by [`SumAccumulator::sums`]; `false` (and no change) when the length differs.
    pub fn restore(&mut self, sums: &[i128]) -> bool {
        if sums.len() != self.sums.len() {
            return false;
        }
        self.sums.copy_from_slice(sums);
        true
    }

    /// The image: linear RGB radiance, each value the sum divided by `2²⁴ × units` ([`fixed_mean`]).
    pub fn image(&self) -> Vec<f32> {
        self.image_of(self.units)
    }

    /// The image over `units` units in all (the units added so far, when a render stops at a bound rather than
    /// at the count it was created with).
    pub fn image_of(&self, units: u32) -> Vec<f32> {
        self.sums.iter().map(|&s| fixed_mean(s, units.max(1))).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert_eq!(to_fixed(1e30), MAX_UNIT_SUM);
        // A full block at the clamp fits i64.
        assert!(MAX_UNIT_SUM.checked_mul(i64::from(MAX_BLOCK_UNITS)).is_some());
    }

    #[test]
    fn sums_are_checked_against_the_block_length() {
        assert_eq!(check_sums(&[0, 5, MAX_UNIT_SUM * 2], 2), Ok(()));
        assert!(matches!(check_sums(&[0, -1], 2), Err(BlockSumsError::OutOfRange { index: 1, .. })));
        assert!(matches!(check_sums(&[MAX_UNIT_SUM * 2 + 1], 2), Err(BlockSumsError::OutOfRange { index: 0, .. })));
    }

    #[test]
    fn the_accumulator_is_exact_whatever_the_order_of_blocks() {
        let blocks: Vec<Vec<i64>> = (0..7)
            .map(|i| vec![to_fixed(0.1 * i as f32 + 1e-7), to_fixed(3.3 / (i + 1) as f32), i64::MAX / 8])
            .collect();
        let mut in_order = SumAccumulator::new(3, 7);
        for b in &blocks {
            in_order.add(b);
        }
        let mut shuffled = SumAccumulator::new(3, 7);
        for i in [3, 1, 6, 4, 0, 5, 2] {
            shuffled.add(&blocks[i]);
        }
        assert_eq!(in_order, shuffled);
        assert_eq!(in_order.image(), shuffled.image());
        let mean = (0..7).map(|i| 0.1 * f64::from(i) + 1e-7).sum::<f64>() / 7.0;
        assert!((f64::from(in_order.image()[0]) - mean).abs() < 1e-6);
    }

    #[test]
    fn blocks_of_rows_land_at_their_offset() {
        let mut acc = SumAccumulator::new(6, 1);
        acc.add_at(3, &[to_fixed(1.0), to_fixed(2.0), to_fixed(3.0)]);
        acc.add_at(9, &[1]);
        assert_eq!(acc.image(), [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
    }
}
