//! Density-estimation kernels and the settings of a radiance estimate: how photons are gathered around a point
//! ([`Gather`]), how they are weighted by distance ([`Kernel`]), and which are skipped ([`Estimator`]).
//! The estimate itself is [`super::PhotonMap::estimate`]; the module documentation of [`super::map`] derives
//! the normalisation.

use crate::math::fmath;
use serde::{Deserialize, Serialize};

/// Density-estimation kernels over the gather disc, as functions of `t = d / r ∈ [0, 1]`, each normalised
/// so that `∫₀¹ K(t) 2πt dt = 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// `K = 1/π`: the classic `Σ Φ / (π r²)`.
    Box,
    /// Jensen's cone filter with slope k = 1: `K = 3/π · (1 − t)` (`∫(1−t)2πt dt = π/3`).
    Cone,
    /// `K = 2/π · (1 − t²)` (`∫(1−t²)2πt dt = π/2`).
    Epanechnikov,
    /// The Gaussian of Pavicic as used by Jensen, `g(t) = 1 − (1 − e^(−β t²/2)) / (1 − e^(−β))` with β = 1.953,
    /// normalised: `K = g(t) / I` with
    /// `I = ∫₀¹ g(t) 2πt dt = π [(1 − c) + 2c (1 − e^(−β/2)) / β]`, `c = 1 / (1 − e^(−β))`,
    /// so `I = 1.81773` and `1/I = 0.550138` (in Jensen's form `α/π · g`, α = 1.72831; his published
    /// α = 0.918 integrates to 0.531 and so halves the radiance). `g(1) = 0.274`: it does not reach zero.
    Gaussian,
    /// The origin's "linear distance" weight `1/(1 + d)`, with `d` in units of the gather radius so it does
    /// not depend on scene scale: `K = 1/(2π(1 − ln 2)) · 1/(1 + t)` (`∫ 2πt/(1+t) dt = 2π(1 − ln 2)`);
    /// the weight halves from centre to edge.
    Linear,
    /// The origin's "quadratic distance" weight `1/(1 + d)²`, `d` in units of the gather radius:
    /// `K = 1/(2π(ln 2 − ½)) · 1/(1 + t)²` (`∫ 2πt/(1+t)² dt = 2π(ln 2 − ½)`); a quarter at the edge.
    Quadratic,
}

/// Gaussian β (Pavicic / Jensen).
const GAUSS_HALF_BETA: f32 = 1.953 / 2.0;
/// `c = 1 / (1 − e^(−β))`.
const GAUSS_C: f32 = 1.165_294_6;
/// `1 / I`, see [`Kernel::Gaussian`].
const GAUSS_NORM: f32 = 0.550_137_9;
/// `1 / (2π(1 − ln 2))`.
const LINEAR_NORM: f32 = 0.518_668_7;
/// `1 / (2π(ln 2 − ½))`.
const QUADRATIC_NORM: f32 = 0.824_008_6;

impl Kernel {
    /// Every kernel.
    pub const ALL: [Kernel; 6] =
        [Kernel::Box, Kernel::Cone, Kernel::Epanechnikov, Kernel::Gaussian, Kernel::Linear, Kernel::Quadratic];

    /// The normalised kernel `K(t)` at `t² = (d / r)²` (clamped to 1); the estimate divides by `r²`.
    #[inline]
    pub fn weight(self, t2: f32) -> f32 {
        use std::f32::consts::FRAC_1_PI;
        let t2 = t2.clamp(0.0, 1.0);
        match self {
            Kernel::Box => FRAC_1_PI,
            Kernel::Cone => 3.0 * FRAC_1_PI * (1.0 - t2.sqrt()),
            Kernel::Epanechnikov => 2.0 * FRAC_1_PI * (1.0 - t2),
            Kernel::Gaussian => GAUSS_NORM * (1.0 - GAUSS_C * (1.0 - fmath::exp(-GAUSS_HALF_BETA * t2))),
            Kernel::Linear => LINEAR_NORM / (1.0 + t2.sqrt()),
            Kernel::Quadratic => {
                let s = 1.0 + t2.sqrt();
                QUADRATIC_NORM / (s * s)
            }
        }
    }
}

/// How photons are gathered around a point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Gather {
    /// The `k` nearest photons within `max_radius`; the radius is the k-th photon's distance (k ≥ 2).
    KNearest {
        /// Number of photons.
        k: u32,
        /// Largest gather radius (world units).
        max_radius: f32,
    },
    /// Every photon within a fixed radius.
    Radius {
        /// Gather radius (world units).
        radius: f32,
    },
}

/// A radiance estimate's settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Estimator {
    /// How photons are gathered.
    pub gather: Gather,
    /// Kernel weighting them by distance.
    pub kernel: Kernel,
    /// Largest |distance to the tangent plane| of a photon, as a fraction of the gather radius; `None` keeps
    /// every photon in the sphere.
    pub disc: Option<f32>,
    /// Only photons stored on the object that was hit (the origin's filter).
    pub same_object: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_constants_follow_from_their_formulas() {
        use std::f64::consts::{LN_2, PI};
        let beta = 1.953f64;
        let c = 1.0 / (1.0 - (-beta).exp());
        let i = PI * ((1.0 - c) + 2.0 * c * (1.0 - (-beta / 2.0).exp()) / beta);
        let close = |a: f32, b: f64| (f64::from(a) - b).abs() < 1e-6 * b;
        assert!(close(GAUSS_C, c));
        assert!(close(GAUSS_NORM, 1.0 / i));
        assert!(close(LINEAR_NORM, 1.0 / (2.0 * PI * (1.0 - LN_2))));
        assert!(close(QUADRATIC_NORM, 1.0 / (2.0 * PI * (LN_2 - 0.5))));
    }
}
