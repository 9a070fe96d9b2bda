//! `--integrator auto`: the method, and progressive photon mapping's radius, chosen for a budget by measured
//! efficiency rather than by the user.
//!
//! # The pilot
//! Each [`Candidate`] that suits the scene ([`candidates`]) renders a short bounded render of its own: whole-image
//! blocks in two rounds, [`PILOT_PASSES`] passes (or samples per pixel) in all, on the same workers as the
//! render, stopped early if it takes more than [`PILOT_SHARE`] of the budget. Its rounds give the two things a
//! choice needs: the rate (passes a second, from the rounds' own time) and the error estimate of
//! [`crate::farm::bounded`] in its two parts, variance and squared bias, with no reference.
//!
//! # The error of a pilot
//! After a few passes a pixel's smaller half-mean, the stand-in for the true value in the bounded render's
//! relative error, is often near 0 where the image is noisy, which inflates the noisiest methods' estimates
//! most (the path tracer's by 15× on the diffuse room). Each pilot's variance is therefore taken relative to the
//! mean of every pilot's image, which holds about five times the samples of any one
//! ([`crate::farm::bounded::ErrorEstimate::parts_against`]).
//!
//! # The bias of a radius
//! A pilot of a few passes cannot see the kernel bias by itself: its time split ([`crate::farm::bounded`])
//! compares radii that hardly differ, and the estimate of its squared bias is noise. Progressive photon mapping
//! is therefore piloted at two first radii, `r₀` and `r₀/2` ([`PROGRESSIVE_SCALES`]), with the
//! same passes and seeds, and [`radius_pair_bias2`] estimates the bias from their difference, less their noise,
//! value by value. Where the radiance is smooth the bias grows as `r²` (Hachisuka, Ogaki & Jensen 2008, §4.3);
//! on the rooms the edges dominate (corners, shadows' borders, caustics' rims: halving the radius cut
//! progressive's error at 142 passes on the diffuse room from 1.28e-3 to 8.4e-4). An edge biases the values
//! within one radius of it, each by the jump times the share of the kernel across it ([`EdgeShare`]; the flat
//! kernel progressive photon mapping gathers with, vcm's own), so its squared bias summed over the image grows
//! with the band's width, `r`, and after `N` passes it is the band of their radii ([`edge_band`]). The same
//! model gives the ratio of `r₀`'s squared bias to the squared difference of the pair (4.4 for the 4 passes of
//! a pilot at α = 2/3 and the flat kernel; 4.7 for Epanechnikov's), and `r₀/2`'s squared bias is half of
//! `r₀`'s. (The first model took the bias at every value to grow as `r`: a quarter for `r₀/2`, falling as the
//! squared mean radius. On the diffuse room in 20 s it predicted progressive at `r₀/2` at 3.4e-4, against
//! 7.4e-4 measured; this one predicts 5.5e-4, against 6.7e-4.)
//!
//! # The prediction
//! Each candidate's error at the end of the budget is predicted from how its error falls with its units
//! ([`predict`]): an unbiased method's variance as `1/N`; for progressive photon mapping and vcm, whose radius
//! shrinks as `r_i² = r_0² Π (k + α)/(k + 1)` (Knaus & Zwicker 2011, eq. 15), the variance of the mean of `N`
//! passes as `Σ r_i⁻² / N²` (each pass's density estimate has a variance `∝ 1/r_i²`) and the squared bias as
//! the edges' band (see above), each scaled from the pilot's own estimate, at the pilot's rate
//! ([`Pilot::rate`]). With `--time` the candidate of the least predicted error wins; with `--target-error`, the
//! one predicted to reach it soonest.
//!
//! # Going on
//! The winner goes on from its pilot ([`crate::farm::Options::continuation`]): its pilot's blocks stay in the
//! image, so its share of the pilot is not lost, and the image is bit for bit that of `--integrator M
//! --passes N` (or `--spp N`) with the same settings, which the summary prints.

use crate::farm::bounded::{ErrorParts, MAX_PASSES};
use photon_core::method::{Bias, Method};
use photon_core::photon::Kernel;
use photon_core::render::radius::{radius_power_sum, radius_ratios2};

/// Passes (or samples per pixel) in a candidate's pilot: two rounds of one whole-image block each, the fewest
/// that give an error estimate (each block holds an even number of passes, and each half of the estimate at
/// least one block; the bias model of a shrinking radius needs two rounds).
pub const PILOT_PASSES: u32 = 4;

/// The most a candidate's pilot may take, as a share of a `--time` budget: a candidate slower than that gives
/// no estimate and is not chosen.
pub const PILOT_SHARE: f64 = 0.15;

/// With `--target-error` alone, the most a candidate's pilot may take, in seconds.
pub const TARGET_PILOT_S: f64 = 5.0;

/// Progressive photon mapping's first radius in the pilot, as multiples of the scene's own
/// (`render.photons.radius`, 2 % of the scene's diagonal by default): a measured remedy for a default radius
/// that is too large for caustics (docs/RESULTS.md, "Choosing the method by measured efficiency").
pub const PROGRESSIVE_SCALES: [f32; 2] = [1.0, 0.5];

/// One method to pilot, with its radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// The method.
    pub method: Method,
    /// Progressive photon mapping's first gather radius as a multiple of the scene's; 1 for the others.
    pub radius_scale: f32,
}

impl Candidate {
    /// The candidate's name in the summary: `progressive ×0.5` for a scaled radius.
    pub fn label(&self) -> String {
        if self.radius_scale == 1.0 {
            self.method.name().to_owned()
        } else {
            format!("{} (radius ×{})", self.method, self.radius_scale)
        }
    }
}

/// What the candidates depend on in a scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneFacts {
    /// The scene has participating media: vcm and bdpt have no volumetric version there (their passes fall
    /// back to the path tracer's samples), so they are left out.
    pub media: bool,
    /// The scene has a point, spot or directional light and a mirror or glass material: the caustics it casts
    /// are paths a path tracer never completes ([`crate::measure::choose_reference`]), so it is left out.
    pub delta_caustics: bool,
}

/// The candidates for a scene: the path tracer, progressive photon mapping at each of
/// [`PROGRESSIVE_SCALES`], vcm and bdpt, less those that do not suit it ([`SceneFacts`]). `photon-map` and
/// `final-gather` are not candidates (their error stops falling at the size of their maps), nor is `lt` (it
/// sees no light through mirror or glass in front of the camera), nor `direct` (it has no indirect light).
pub fn candidates(facts: SceneFacts) -> Vec<Candidate> {
    let one = |method| Candidate { method, radius_scale: 1.0 };
    let mut out = Vec::new();
    if !facts.delta_caustics {
        out.push(one(Method::Path));
    }
    out.extend(PROGRESSIVE_SCALES.map(|radius_scale| Candidate { method: Method::Progressive, radius_scale }));
    if !facts.media {
        out.push(one(Method::Vcm));
        out.push(one(Method::Bdpt));
    }
    out
}

/// What a candidate's pilot measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pilot {
    /// Passes (or samples per pixel) rendered.
    pub passes: u32,
    /// Seconds its rounds took (from the first worker's readiness to the last block).
    pub seconds: f64,
    /// Passes a second of the farm: one worker's passes a second over the pilot's blocks (the seconds its
    /// worker spent rendering each) times the workers. A pilot's rounds are short, and their round trips would
    /// make the rate of a fast method seem half of what the long rounds of the render reach.
    pub rate: f64,
    /// Its error estimate's parts after the last round.
    pub parts: ErrorParts,
}

impl Pilot {
    /// Passes a second.
    pub fn rate(&self) -> f64 {
        self.rate.max(1e-9)
    }

    /// Passes in all after `seconds` more of rendering at the pilot's rate, at most [`MAX_PASSES`].
    pub fn passes_after(&self, seconds: f64) -> u32 {
        let more = (self.rate() * seconds.max(0.0)).min(f64::from(MAX_PASSES));
        (f64::from(self.passes) + more).min(f64::from(MAX_PASSES)) as u32
    }
}

/// The relative MSE of `method` predicted after `passes` passes in all, from its pilot's estimate at
/// `pilot.passes` (see the module documentation); `alpha` is the radius sequence's α
/// (`render.photons.alpha`).
pub fn predict(method: Method, alpha: f32, share: &EdgeShare, pilot: &Pilot, passes: u32) -> f64 {
    let (k, n) = (f64::from(pilot.passes.max(1)), f64::from(passes.max(1)));
    match method.bias() {
        Bias::None | Bias::Fixed => pilot.parts.variance * k / n,
        Bias::Shrinking => {
            let (pk, pn) = (pilot.passes.max(1), passes.max(1));
            // Variance of the mean: Σ r_i⁻² / N²; squared bias: the edges' band ([`edge_band`]).
            let var = |p: u32, n: f64| radius_power_sum(alpha, 0..p, -2.0) / (n * n);
            let w = |u| share.at(u);
            let bias2 = edge_band(alpha, pn, w) / edge_band(alpha, pk, w);
            pilot.parts.variance * var(pn, n) / var(pk, k) + pilot.parts.bias2.max(0.0) * bias2
        }
    }
}

/// Points of [`EdgeShare`]'s table over `u ∈ [0, 1]`.
const SHARE_POINTS: usize = 1024;

/// The share of a kernel's weight that lies beyond a straight line `u` radii from its centre, `∫∫_{x > u}
/// K(√(x² + y²)) dx dy` over the unit disc: ½ at the centre and 0 from one radius on (for the flat kernel
/// `(acos u − u√(1 − u²))/π`, for Epanechnikov's `½ − (u(5 − 2u²)√(1 − u²) + 3 asin u)/3π`). Where the radiance
/// jumps at an edge (a corner, a shadow's border, a caustic's rim) by `J`, a density estimate `u` radii from it
/// is off by `J` times this share. Tabulated by quadrature of the kernel's own weights ([`Kernel::weight`]), so
/// that it is the kernel the method gathers with: progressive photon mapping's flat one
/// ([`Method::kernel`]), vcm's `render.photons.kernel`.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeShare {
    /// The share at `u = j / SHARE_POINTS`.
    table: Vec<f64>,
}

impl EdgeShare {
    /// The table of `kernel`: the weight across each chord by the midpoint rule, summed from the disc's rim
    /// inwards, normalised so that the share at the centre is ½.
    pub fn new(kernel: Kernel) -> Self {
        const CHORD_POINTS: usize = 64;
        let chord = |x: f64| {
            let h = (1.0 - x * x).max(0.0).sqrt();
            let dy = 2.0 * h / CHORD_POINTS as f64;
            (0..CHORD_POINTS)
                .map(|k| {
                    let y = -h + (k as f64 + 0.5) * dy;
                    f64::from(kernel.weight((x * x + y * y) as f32))
                })
                .sum::<f64>()
                * dy
        };
        let mut table = vec![0.0; SHARE_POINTS + 1];
        let mut beyond = 0.0;
        for j in (0..SHARE_POINTS).rev() {
            beyond += chord((j as f64 + 0.5) / SHARE_POINTS as f64) / SHARE_POINTS as f64;
            table[j] = beyond;
        }
        let half = table[0];
        table.iter_mut().for_each(|v| *v *= 0.5 / half);
        Self { table }
    }

    /// The share at `u` (linear between the table's points; 0 from one radius on, ½ for `u ≤ 0`).
    pub fn at(&self, u: f64) -> f64 {
        if u.is_nan() || u >= 1.0 {
            return 0.0;
        }
        let x = u.max(0.0) * SHARE_POINTS as f64;
        let j = (x as usize).min(SHARE_POINTS - 1);
        let f = x - j as f64;
        self.table[j] * (1.0 - f) + self.table[j + 1] * f
    }
}

/// Quadrature points across an edge's band.
const BAND_POINTS: usize = 128;
/// Passes sampled at most along a radius sequence in [`edge_band`] (more are strided: the radius changes
/// slowly late in the sequence).
const BAND_PASSES: u32 = 2048;

/// `∫₀¹ ((1/N) Σᵢ w(x/ρᵢ))² dx` over the first `passes` passes of the radius sequence of `alpha`, with `ρᵢ` the
/// ratio of pass `i`'s radius to the first: the squared error, summed across one unit of an edge's length
/// (in first radii), of the mean of `N` passes whose estimate at distance `x` from the edge is off by `w(x/rᵢ)`
/// (times the jump). With `w` = [`EdgeShare::at`] it is the squared bias an edge leaves in the image, up to a
/// factor (the jump squared, the edges' length over the image's area, the first radius) that cancels in every
/// ratio of it: between pass counts, and between the bias and the difference of two radii.
pub fn edge_band(alpha: f32, passes: u32, w: impl Fn(f64) -> f64) -> f64 {
    let n = passes.max(1);
    let stride = n.div_ceil(BAND_PASSES).max(1);
    let mut sums = [0.0f64; BAND_POINTS];
    let mut weight = 0.0f64;
    for (i, ratio2) in (0..n).zip(radius_ratios2(alpha)).step_by(stride as usize) {
        let w_i = f64::from(stride.min(n - i));
        let rho = ratio2.sqrt();
        for (j, s) in sums.iter_mut().enumerate() {
            let x = (j as f64 + 0.5) / BAND_POINTS as f64;
            *s += w_i * w(x / rho);
        }
        weight += w_i;
    }
    sums.iter().map(|s| (s / weight) * (s / weight)).sum::<f64>() / BAND_POINTS as f64
}

/// The fewest passes in all at which `method` is predicted to reach `target`, or `None` beyond
/// [`MAX_PASSES`].
pub fn passes_to_reach(method: Method, alpha: f32, share: &EdgeShare, pilot: &Pilot, target: f64) -> Option<u32> {
    // The prediction falls with the passes: double until it is reached, then bisect (each prediction walks the
    // radius sequence, so the search costs O(N log N) for an answer of N).
    let reached = |n: u32| predict(method, alpha, share, pilot, n) <= target;
    let mut hi = pilot.passes.max(1);
    while !reached(hi) {
        if hi >= MAX_PASSES {
            return None;
        }
        hi = hi.saturating_mul(2).min(MAX_PASSES);
    }
    let mut lo = (hi / 2).max(pilot.passes.max(1));
    if reached(lo) {
        return Some(lo);
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if reached(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

/// Two half-images of one pilot: radiance sums per pixel value and the passes in each
/// ([`crate::farm::bounded::ErrorEstimate::halves`]).
pub type Halves<'a> = ([&'a [f64]; 2], [u64; 2]);

/// The relative squared bias of the larger radius's image (first radius `r₀`, `alpha` its sequence's α), from
/// its halves `large` and those of the image of the same passes and seeds at first radius `r₀/2`, `small`,
/// relative to `reference`, the best estimate of the image at hand (the pooled pilots): the difference image
/// `L − S` and its noise come from the halves' differences (the two pilots trace the same photons, so their
/// noises are correlated and do not add), and `mean over values of (d² − var d) / (reference² + ε)`, at least 0,
/// is the difference's squared error. Under the edges' model ([`edge_band`]), an edge leaves `L` the squared
/// error `edge_band(share)` and the difference `edge_band(w)` with `w(u) = share(u) − share(2u)`, `share` the
/// kernel's ([`EdgeShare`]); their ratio (4.4 for 4 passes at α = 2/3 and the flat kernel progressive photon
/// mapping gathers with) turns the one into the other, and the smaller radius's band is
/// half as wide, so its squared bias is half of `L`'s. Per value, not over tiles: at an edge the bias has
/// opposite signs on its two sides, and an average over a tile cancels it. 0 when the halves do not match.
pub fn radius_pair_bias2(
    large: Halves<'_>,
    small: Halves<'_>,
    reference: &[f32],
    alpha: f32,
    share: &EdgeShare,
) -> f64 {
    let n = reference.len();
    let ([la, lb], passes) = large;
    let ([sa, sb], small_passes) = small;
    if n == 0 || passes != small_passes || [la.len(), lb.len(), sa.len(), sb.len()].iter().any(|&m| m != n) {
        return 0.0;
    }
    let (na, nb) = (passes[0] as f64, passes[1] as f64);
    if na == 0.0 || nb == 0.0 {
        return 0.0;
    }
    let sum: f64 = (0..n)
        .map(|i| {
            let (da, db) = ((la[i] - sa[i]) / na, (lb[i] - sb[i]) / nb);
            let d = (la[i] + lb[i] - sa[i] - sb[i]) / (na + nb);
            // The variance of the difference's mean, as the bounded render's estimate takes a pass's variance
            // from its two halves.
            let var = (da - db) * (da - db) / (1.0 / na + 1.0 / nb) / (na + nb);
            let r = f64::from(reference[i]).max(0.0);
            (d * d - var) / (r * r + photon_core::metrics::EPSILON)
        })
        .sum();
    let k = (passes[0] + passes[1]).min(u64::from(u32::MAX)) as u32;
    let difference = edge_band(alpha, k, |u| share.at(u) - share.at(2.0 * u));
    (edge_band(alpha, k, |u| share.at(u)) / difference * sum / n as f64).max(0.0)
}

/// A candidate's pilot with what it predicts.
#[derive(Clone, Debug, PartialEq)]
pub struct Judged {
    /// The candidate.
    pub candidate: Candidate,
    /// Its pilot; `None` when the pilot gave no estimate (too few rounds).
    pub pilot: Option<Pilot>,
    /// The predicted relative MSE at the deadline (`--time`), or the predicted seconds to the target
    /// (`--target-error`); `f64::INFINITY` when there is no prediction.
    pub score: f64,
}

/// What `auto` is asked to reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Goal {
    /// The least error after this many more seconds of rendering.
    Time(f64),
    /// A relative MSE, as soon as possible.
    Error(f64),
}

/// Scores a candidate's pilot for `goal` (lower is better): the predicted relative MSE once the candidate has
/// gone on for the goal's seconds, or the seconds it is predicted to need for the goal's error.
pub fn score(candidate: Candidate, alpha: f32, share: &EdgeShare, pilot: Option<&Pilot>, goal: Goal) -> f64 {
    let Some(p) = pilot else { return f64::INFINITY };
    let method = candidate.method;
    match goal {
        Goal::Time(seconds) => predict(method, alpha, share, p, p.passes_after(seconds)),
        Goal::Error(target) => passes_to_reach(method, alpha, share, p, target)
            .map_or(f64::INFINITY, |n| f64::from(n.saturating_sub(p.passes)) / p.rate()),
    }
}

/// The index of the winner among `judged`: the least score; on a tie (or no score at all), the first.
pub fn winner(judged: &[Judged]) -> usize {
    judged.iter().enumerate().min_by(|a, b| a.1.score.total_cmp(&b.1.score).then(a.0.cmp(&b.0))).map_or(0, |(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photon_core::render::radius::pass_radius2;

    fn pilot(passes: u32, seconds: f64, variance: f64, bias2: f64) -> Pilot {
        Pilot { passes, seconds, rate: f64::from(passes) / seconds, parts: ErrorParts { variance, bias2 } }
    }

    #[test]
    fn candidates_suit_the_scene() {
        let names = |f| candidates(f).iter().map(Candidate::label).collect::<Vec<_>>().join(", ");
        let plain = SceneFacts { media: false, delta_caustics: false };
        assert_eq!(names(plain), "path, progressive, progressive (radius ×0.5), vcm, bdpt");
        assert_eq!(names(SceneFacts { media: true, ..plain }), "path, progressive, progressive (radius ×0.5)");
        let both = SceneFacts { media: true, delta_caustics: true };
        assert_eq!(names(both), "progressive, progressive (radius ×0.5)");
    }

    #[test]
    fn an_unbiased_error_falls_as_one_over_n() {
        let p = pilot(16, 1.0, 0.04, 0.0);
        assert!((predict(Method::Path, 2.0 / 3.0, &EdgeShare::new(Kernel::Box), &p, 64) - 0.01).abs() < 1e-12);
        // 3 more seconds at 16 passes a second: 64 in all.
        assert_eq!(p.passes_after(3.0), 64);
        assert!(
            (score(
                Candidate { method: Method::Bdpt, radius_scale: 1.0 },
                0.5,
                &EdgeShare::new(Kernel::Box),
                Some(&p),
                Goal::Time(3.0)
            ) - 0.01)
                .abs()
                < 1e-12
        );
        // To reach 0.01: 64 passes, 48 more, 3 s.
        assert_eq!(passes_to_reach(Method::Path, 0.5, &EdgeShare::new(Kernel::Box), &p, 0.01), Some(64));
        let t = score(
            Candidate { method: Method::Path, radius_scale: 1.0 },
            0.5,
            &EdgeShare::new(Kernel::Box),
            Some(&p),
            Goal::Error(0.01),
        );
        assert!((t - 3.0).abs() < 1e-9, "{t}");
    }

    #[test]
    fn a_shrinking_radius_trades_bias_for_variance_at_the_rate_alpha_implies() {
        let alpha = 2.0 / 3.0;
        // Variance alone: it falls more slowly than 1/N (the radius shrinks, so each pass is noisier), near
        // N^-α for many passes.
        let p = pilot(100, 1.0, 1e-2, 0.0);
        let share = EdgeShare::new(Kernel::Box);
        let v = predict(Method::Progressive, alpha, &share, &p, 10_000);
        let expected = 1e-2 * (100f64 / 10_000.0).powf(f64::from(alpha));
        assert!((v / expected - 1.0).abs() < 0.05, "{v} against {expected}");
        assert!(v > 1e-2 * 100.0 / 10_000.0);
        // Squared bias alone (edges') falls as their band narrows.
        let p = pilot(100, 1.0, 0.0, 1e-2);
        let b = predict(Method::Vcm, alpha, &share, &p, 10_000);
        let w = |u| share.at(u);
        let expected = 1e-2 * edge_band(alpha, 10_000, w) / edge_band(alpha, 100, w);
        assert!((b / expected - 1.0).abs() < 1e-9, "{b} against {expected}");
        assert!(b < 1e-2);
        // A negative squared bias (noise) adds nothing.
        assert_eq!(predict(Method::Progressive, alpha, &share, &pilot(100, 1.0, 0.0, -1e-3), 400), 0.0);
        // Unreachable within MAX_PASSES.
        assert_eq!(passes_to_reach(Method::Progressive, alpha, &share, &pilot(10, 1.0, 1.0, 1.0), 1e-12), None);
    }

    #[test]
    fn the_edge_share_is_the_kernel_weight_beyond_a_line() {
        // Every kernel against a direct quadrature of its weight over the unit disc beyond x = u.
        let beyond = |kernel: Kernel, u: f64| {
            let m = 400;
            let (mut inside, mut total) = (0.0, 0.0);
            for i in 0..m {
                for j in 0..m {
                    let (x, y) = (-1.0 + (i as f64 + 0.5) * 2.0 / m as f64, -1.0 + (j as f64 + 0.5) * 2.0 / m as f64);
                    if x * x + y * y > 1.0 {
                        continue;
                    }
                    let k = f64::from(kernel.weight((x * x + y * y) as f32));
                    total += k;
                    if x > u {
                        inside += k;
                    }
                }
            }
            inside / total
        };
        for kernel in Kernel::ALL {
            let share = EdgeShare::new(kernel);
            for u in [0.0, 0.1, 0.3, 0.5, 0.8, 0.95] {
                let (f, q) = (share.at(u), beyond(kernel, u));
                assert!((f - q).abs() < 3e-3, "{kernel:?} at u {u}: {f} against {q}");
            }
            assert_eq!(share.at(1.0), 0.0);
            assert_eq!(share.at(3.0), 0.0);
            assert_eq!(share.at(f64::NAN), 0.0);
            assert!((share.at(0.0) - 0.5).abs() < 1e-12);
            assert!((share.at(-1.0) - 0.5).abs() < 1e-12);
        }
        // The closed forms of the flat kernel and Epanechnikov's.
        let flat = |u: f64| (u.acos() - u * (1.0 - u * u).sqrt()) / std::f64::consts::PI;
        let epanechnikov = |u: f64| {
            0.5 - (u * (5.0 - 2.0 * u * u) * (1.0 - u * u).sqrt() + 3.0 * u.asin()) / (3.0 * std::f64::consts::PI)
        };
        let (b, e) = (EdgeShare::new(Kernel::Box), EdgeShare::new(Kernel::Epanechnikov));
        for i in 0..100 {
            let u = (i as f64 + 0.5) / 100.0;
            assert!((b.at(u) - flat(u)).abs() < 1e-3, "flat at {u}: {} against {}", b.at(u), flat(u));
            assert!((e.at(u) - epanechnikov(u)).abs() < 1e-3, "at {u}: {} against {}", e.at(u), epanechnikov(u));
        }
        // The pair's factor for a 4-pass pilot at α = 2/3: the flat kernel's and Epanechnikov's.
        let factor = |share: &EdgeShare| {
            edge_band(2.0 / 3.0, 4, |u| share.at(u)) / edge_band(2.0 / 3.0, 4, |u| share.at(u) - share.at(2.0 * u))
        };
        let (fb, fe) = (factor(&b), factor(&e));
        eprintln!("the pair's factor: flat {fb:.3}, Epanechnikov {fe:.3}");
        assert!((fb - 4.37).abs() < 0.02 && (fe - 4.66).abs() < 0.02, "{fb} {fe}");
    }

    #[test]
    fn an_edges_band_narrows_with_the_radius() {
        // A fixed radius (α = 1): the same band whatever the passes, ∫₀¹ f(x)² dx.
        let share = EdgeShare::new(Kernel::Box);
        let w = |u| share.at(u);
        let direct = (0..100_000).map(|i| w((i as f64 + 0.5) / 1e5).powi(2)).sum::<f64>() / 1e5;
        for n in [1, 10, 1000] {
            let b = edge_band(1.0, n, w);
            assert!((b / direct - 1.0).abs() < 1e-3, "{n} passes: {b} against {direct}");
        }
        // A shrinking radius: the squared bias falls with the passes, more slowly than the squared mean radius
        // (the old model) and about as the mean radius (the band's width).
        let alpha = 2.0 / 3.0;
        let (b1, b2) = (edge_band(alpha, 100, w), edge_band(alpha, 10_000, w));
        let mean_r = |n: u32| radius_power_sum(alpha, 0..n, 1.0) / f64::from(n);
        let r = mean_r(10_000) / mean_r(100);
        eprintln!("squared bias 100 → 10 000 passes: ×{:.4}; mean radius ×{r:.4}", b2 / b1);
        assert!(b2 / b1 > r * r * 1.2 && b2 / b1 < r * 1.1, "{} against r {r}", b2 / b1);
    }

    #[test]
    fn two_radii_give_the_bias_of_each() {
        // An edge at x = 0 between radiance 1 and 1.2, seen by the density estimates of 4 passes (two halves of
        // 2) at first radius 1 and ½: a value x away is off by the jump times the kernel's share across the
        // edge, averaged over the passes' radii. The pair's estimate of the larger radius's squared bias is its
        // true mean over the values.
        let (alpha, jump, n) = (2.0f32 / 3.0, 0.2f64, 4000);
        let flat = EdgeShare::new(Kernel::Box);
        let x = |i: usize| -2.0 + 4.0 * (i as f64 + 0.5) / n as f64;
        let truth = |i: usize| if x(i) < 0.0 { 1.0 } else { 1.0 + jump };
        let radii: Vec<f64> = (0..4).map(|p| f64::from(pass_radius2(1.0, alpha, p)).sqrt()).collect();
        let bias = |i: usize, r0: f64| {
            let share = radii.iter().map(|r| flat.at(x(i).abs() / (r0 * r))).sum::<f64>() / 4.0;
            if x(i) < 0.0 { jump * share } else { -jump * share }
        };
        let sums = |r0: f64| (0..n).map(|i| 2.0 * (truth(i) + bias(i, r0))).collect::<Vec<f64>>();
        let reference: Vec<f32> = (0..n).map(|i| truth(i) as f32).collect();
        let (la, lb, sa, sb) = (sums(1.0), sums(1.0), sums(0.5), sums(0.5));
        let b = radius_pair_bias2(([&la, &lb], [2, 2]), ([&sa, &sb], [2, 2]), &reference, alpha, &flat);
        let expected =
            (0..n).map(|i| bias(i, 1.0).powi(2) / (truth(i).powi(2) + photon_core::metrics::EPSILON)).sum::<f64>()
                / n as f64;
        assert!((b / expected - 1.0).abs() < 0.03, "{b} against {expected}");
        // Noise in the difference (its halves disagree) is taken off; noise both share is not noise of the
        // difference; mismatched halves give none.
        let noisy: Vec<f64> = la.iter().enumerate().map(|(i, v)| v + if i % 2 == 0 { 0.1 } else { -0.1 }).collect();
        let with_noise = radius_pair_bias2(([&noisy, &lb], [2, 2]), ([&sa, &sb], [2, 2]), &reference, alpha, &flat);
        assert!((with_noise / b - 1.0).abs() < 0.1, "{with_noise} against {b}");
        let shared = radius_pair_bias2(([&noisy, &lb], [2, 2]), ([&noisy, &sb], [2, 2]), &reference, alpha, &flat);
        assert!(shared < 0.05 * b, "{shared}");
        assert_eq!(radius_pair_bias2(([&la, &lb], [2, 2]), ([&sa, &sb], [2, 4]), &reference, alpha, &flat), 0.0);
    }

    #[test]
    fn the_least_predicted_error_wins() {
        let judged =
            |score| Judged { candidate: Candidate { method: Method::Path, radius_scale: 1.0 }, pilot: None, score };
        assert_eq!(winner(&[judged(2.0), judged(1.0), judged(1.0), judged(f64::INFINITY)]), 1);
        assert_eq!(winner(&[judged(f64::INFINITY), judged(f64::INFINITY)]), 0);
        // A fast, noisy method beats a slow, quiet one when its error falls below the other's by the deadline:
        // 0.1 at 10 passes a second against 0.2 at 1 pass a second, 9 s more: 0.1·10/100 = 0.01 < 0.2·1/10.
        let path = Candidate { method: Method::Path, radius_scale: 1.0 };
        let fast = score(path, 0.5, &EdgeShare::new(Kernel::Box), Some(&pilot(10, 1.0, 0.1, 0.0)), Goal::Time(9.0));
        let slow = score(path, 0.5, &EdgeShare::new(Kernel::Box), Some(&pilot(1, 1.0, 0.2, 0.0)), Goal::Time(9.0));
        assert!(fast < slow, "{fast} {slow}");
    }
}
