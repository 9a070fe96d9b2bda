//! The shrinking radius of the consistent density estimators (progressive photon mapping's gathers and vcm's
//! merges): a function of the pass index alone, so that a pass renders alike wherever the farm sends it.
//!
//! `r_{i+1}² = r_i² · (i + α) / (i + 1)` (1-based `i`; Knaus & Zwicker 2011, "Progressive Photon Mapping: A
//! Probabilistic Approach", eq. 15), `r_1` the method's first radius ([`crate::method::Method::radius`]).

use std::ops::Range;

/// The squared radius of pass `pass` (0-based): `r0² · Π_{i=1}^{pass} (i + α) / (i + 1)` (Knaus & Zwicker 2011,
/// eq. 15), computed in f64 in a fixed order.
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
    /// The pass this value is for (0-based).
    pub(super) pass: u32,
    /// `Π_{i=1}^{pass} (i + α) / (i + 1)`, multiplied left to right.
    ratio: f64,
}

impl RadiusSequence {
    /// The sequence from `r0` at pass `pass`.
    pub(super) fn at(r0: f32, alpha: f32, pass: u32) -> Self {
        let start = Self { r0: f64::from(r0), alpha: f64::from(alpha), pass: 0, ratio: 1.0 };
        (0..pass).fold(start, |s, _| s.next())
    }

    /// The next pass's value.
    pub(super) fn next(self) -> Self {
        let i = f64::from(self.pass + 1);
        Self { pass: self.pass + 1, ratio: self.ratio * ((i + self.alpha) / (i + 1.0)), ..self }
    }

    /// The squared radius.
    pub(super) fn r2(&self) -> f32 {
        (self.r0 * self.r0 * self.ratio) as f32
    }
}

/// The passes' squared radii relative to the first one's, `(r_p / r_0)²` for `p = 0, 1, 2, …`: the sequence's
/// product walked once, each value bit for bit the ratio [`pass_radius2`] multiplies `r0²` by.
pub fn radius_ratios2(alpha: f32) -> impl Iterator<Item = f64> {
    std::iter::successors(Some(RadiusSequence::at(1.0, alpha, 0)), |r| Some(r.next())).map(|r| r.ratio)
}

/// `Σ_{p ∈ passes} (r_p / r_0)^power`: the radii of passes `passes` relative to the first one's, raised to
/// `power`. The kernel bias of a density estimate grows as `r²` where the density is smooth (Hachisuka, Ogaki &
/// Jensen 2008, §4.3) and as `r` at its edges, so this sum is the factor by which the passes' mean bias differs
/// from the first pass's. Walks the sequence once, `O(passes.end)`.
pub fn radius_power_sum(alpha: f32, passes: Range<u32>, power: f64) -> f64 {
    radius_ratios2(alpha)
        .take(passes.end as usize)
        .skip(passes.start as usize)
        .fold(0.0, |sum, ratio| sum + ratio.powf(power / 2.0))
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
}
