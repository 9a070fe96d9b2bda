//! Renders bounded by time (`--time`) or by estimated error (`--target-error`): the image is rendered in
//! **rounds** of whole-image blocks (photon passes for progressive photon mapping, camera samples per pixel for
//! the other methods), and after each round the render goes on or stops.
//!
//! A block's fixed-point sums add exactly in any order, so the image after `K` passes (or samples) is the same
//! bits however the rounds were cut and whichever workers rendered them: a bounded render that stopped after `K`
//! samples equals `render --spp K`, and one that stopped after `K` passes equals `render --passes K`. Only `K`
//! depends on the machines' speed.
//!
//! # Sizing the rounds
//! The first round is two passes per block, two blocks per worker (at least two blocks, so that the error
//! estimate has both halves); every later block holds an even number of passes (see the error estimate). Each
//! later round aims at half the time spent so far, between [`MIN_ROUND`] and
//! [`MAX_ROUND`], at the rate the last round measured: rounds grow geometrically, so their count (and the
//! image-sized blocks sent back) grows with the logarithm of the time. With `--time` a round is cut to 90 % of
//! what fits before the deadline at the last round's rate, no round starts when fewer than two passes (or half a
//! pass per block) fit, and a round still in flight a tenth of the time limit past the deadline is dropped: the
//! render ends with its finished rounds. The first round is timed from the first worker's readiness, not from the connections and uploads. With `--target-error` a
//! round is also cut to the passes the error's `1/K` fall predicts are still needed (plus 10 %), and to at most
//! the passes done (so `K` at most doubles between two estimates): the render stops soon after it crosses the
//! target, with an error no less than about half of it.
//!
//! # Estimating the error without a reference
//! Variance: the blocks are split into two interleaved half-images `A` and `B` by the parity of their index
//! (`half_of`; interleaved blocks rather than interleaved samples: a block is the unit a worker returns, and
//! both halves then span the whole render, so they carry the same bias). Blocks hold an even number of passes
//! starting at an even pass (but for an odd budget's last): samples `2k` and `2k + 1` of a pixel's Sobol sequence lie
//! in opposite halves of the pixel, so a block of such pairs covers the whole pixel, and the halves' difference
//! is noise rather than the pixel's sub-pixel detail. With `nA`, `nB` passes and per-pass variance σ²,
//! `E[(Ā − B̄)²] = σ²(1/nA + 1/nB)`, so the variance of the full mean is estimated per pixel value as
//! `(Ā − B̄)² / ((1/nA + 1/nB)(nA + nB))`. The Sobol sequence stratifies the samples of the whole render better
//! than two independent halves, so this estimate errs high.
//!
//! Bias (progressive photon mapping only; the path tracer and direct lighting are unbiased): the kernel bias of a
//! pass of squared radius `r_i²` is `c·r_i²` for a smooth radiance (Hachisuka, Ogaki & Jensen 2008, §4.3), with
//! a per-pixel `c`. The render is also split in time at the round end nearest `K/2`: the first part's mean minus
//! the second's is `D = c(m₁ − m₂) + noise`, where `m₁`, `m₂` are the parts' mean `r²/r₀²`
//! ([`photon_core::render::radius::radius_power_sum`]); the whole render's bias is `c·m`, so its square is
//! estimated as `(m / (m₁ − m₂))² (D² − Var D)`, with `Var D` from σ² above. This is a two-level extrapolation
//! (Richardson) of the bias model, not the Laplacian estimate of Hachisuka, Jarosz & Jensen 2010; at edges and
//! caustic boundaries, where the bias grows as `r` rather than `r²`, it errs low (measured in docs/RESULTS.md).
//!
//! The estimate keeps two f64 images (the halves) and, for progressive photon mapping, one f32 image a round
//! (rounds grow geometrically, so about 10 to 20 of them): 25 MB and 3 MB a round for a 1024×1024 image.
//!
//! The estimate of the relative MSE is the mean over pixel values of `(variance + bias²) / (min(Ā, B̄)² + ε)` with
//! the `ε` of [`photon_core::metrics::EPSILON`], the definition `compare` measures against a reference with the
//! smaller half's value in place of the reference's: a rare large sample (a firefly) in one half would inflate
//! the mean, and with it the denominator that should show that very error (with the mean, the Cornell box's path
//! tracer stopped at a fifth of the samples its target needed). The bias term is summed over the image before it
//! is clamped at 0.

use photon_core::render::radius::radius_power_sum;
use photon_core::render::sums::{SUM_FRACTION_BITS, SumAccumulator};
use std::ops::Range;
use std::time::{Duration, Instant};

/// The most passes (or samples per pixel) a bounded render takes: the scene format's limit on passes.
pub const MAX_PASSES: u32 = photon_core::scene::MAX_PASSES;

/// The shortest round aimed at.
pub const MIN_ROUND: Duration = Duration::from_secs(1);

/// The longest round aimed at.
pub const MAX_ROUND: Duration = Duration::from_secs(60);

/// What bounds a render.
#[derive(Clone, Debug)]
pub struct Bound {
    /// Start no round that cannot finish before this instant.
    pub deadline: Option<Instant>,
    /// Stop once the estimated relative MSE is at most this.
    pub target_error: Option<f64>,
    /// Progressive photon mapping's α (the radius sequence): the error estimate then includes the kernel bias.
    /// `None` for the unbiased methods.
    pub bias_alpha: Option<f32>,
    /// Stop after exactly this many passes (at most [`MAX_PASSES`]): a render of a fixed budget in rounds, for
    /// its error estimate (`photon-sweep`).
    pub passes: Option<u32>,
    /// Estimate the error after each round (implied by `target_error`). Rounds then at most double the passes,
    /// so that the estimates come at a steady pace.
    pub estimate: bool,
}

impl Bound {
    /// Whether the render estimates its error.
    fn estimates(&self) -> bool {
        self.estimate || self.target_error.is_some()
    }
}

/// Why a bounded render stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// The time ran out.
    Time,
    /// The estimated error reached the target.
    Error,
    /// [`MAX_PASSES`] (or [`Bound::passes`]) were rendered.
    Cap,
    /// A signal asked to stop; the finished rounds are kept.
    Interrupted,
    /// No worker was left; the finished rounds are kept.
    NoWorkers,
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Time => "at the time limit",
            Self::Error => "at the target error",
            Self::Cap => "at its passes",
            Self::Interrupted => "by a signal",
            Self::NoWorkers => "with no worker left",
        })
    }
}

/// What a bounded render did, for the summary.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundedReport {
    /// Passes (or samples per pixel) in the image: those of the completed rounds.
    pub passes: u32,
    /// Rounds completed.
    pub rounds: u32,
    /// Why it stopped.
    pub reason: StopReason,
    /// The last estimate of the relative MSE, when one was made.
    pub rel_mse_estimate: Option<f64>,
    /// The last estimate's parts: variance and squared bias.
    pub error_parts: Option<ErrorParts>,
    /// Seconds the completed rounds took, each from its start to its last block (the first from the first
    /// worker's readiness): the render's own time, without connections and uploads.
    pub round_seconds: f64,
    /// Passes a second of one worker, over the accepted blocks: their passes over the seconds their workers
    /// spent rendering them (without the rounds' round trips, which a short round is mostly made of).
    pub block_rate: Option<f64>,
}

/// An estimate of the relative MSE in its two parts (see the module documentation), each averaged over the
/// image's pixel values: `rel_mse = variance + max(bias2, 0)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorParts {
    /// The relative variance of the image's mean.
    pub variance: f64,
    /// The relative squared bias (the bias model's, for progressive photon mapping and vcm; 0 for the
    /// unbiased methods). It may be negative: the model subtracts the noise it expects, and the sum is
    /// clamped only in [`ErrorParts::rel_mse`].
    pub bias2: f64,
}

impl ErrorParts {
    /// The estimated relative MSE.
    pub fn rel_mse(self) -> f64 {
        self.variance + self.bias2.max(0.0)
    }
}

/// Where a bounded render stopped: its completed rounds and the sums of its image
/// ([`crate::out::report::Outcome::continuation`]; [`crate::farm::Options::continuation`] goes on from it).
#[derive(Clone, Debug)]
pub struct Continuation {
    /// The completed rounds, with their rate and error estimate.
    pub rounds: Rounds,
    /// The image's fixed-point sums (those of the completed rounds).
    pub image: SumAccumulator,
}

/// The next round: `passes` passes in blocks of `per_block`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RoundPlan {
    /// Passes in the round.
    pub passes: u32,
    /// Passes per block.
    pub per_block: u32,
}

/// The rounds of one bounded render: when each ended, how fast it went, the sums of the round in flight (they
/// join the image only when the round is complete, so the image holds whole rounds), the error estimate, and
/// why the render stopped.
#[derive(Clone, Debug)]
pub struct Rounds {
    bound: Bound,
    started: Instant,
    round_started: Instant,
    /// The plan of each completed round: how its passes were cut into blocks (a continued render cuts its
    /// scheduler's first units the same way, so that each block keeps its index and its half).
    plans: Vec<RoundPlan>,
    /// Passes of the completed rounds.
    done: u32,
    /// The round in flight (0 passes when none).
    current: RoundPlan,
    /// Seconds and passes of the last completed round.
    last: Option<(f64, u32)>,
    /// Fixed-point sums of the blocks of the round in flight.
    sums: SumAccumulator,
    estimate: ErrorEstimate,
    last_estimate: Option<ErrorParts>,
    /// Seconds of the completed rounds.
    round_seconds: f64,
    /// Seconds the workers spent rendering the accepted blocks, and their passes.
    block_time: (f64, u64),
    stopped: Option<StopReason>,
}

impl Rounds {
    /// Rounds of a render of `values` pixel values (3 per pixel) bounded by `bound`, starting now.
    pub fn new(bound: Bound, values: usize) -> Self {
        let now = Instant::now();
        let estimate = ErrorEstimate::new(values, bound.estimates(), bound.bias_alpha);
        Self {
            bound,
            started: now,
            round_started: now,
            plans: Vec::new(),
            done: 0,
            current: NO_ROUND,
            last: None,
            sums: SumAccumulator::new(values, 1),
            estimate,
            last_estimate: None,
            round_seconds: 0.0,
            block_time: (0.0, 0),
            stopped: None,
        }
    }

    /// The first round for `workers` workers.
    pub fn first(&mut self, workers: usize) -> RoundPlan {
        let cap = self.bound.passes.unwrap_or(MAX_PASSES).clamp(1, MAX_PASSES);
        // An estimating render of a fixed budget leaves at least half of it to a second round: the bias model
        // needs two.
        let cap = if self.bound.estimates() && self.bound.passes.is_some() { cap.div_ceil(2) } else { cap };
        let passes = (2 * blocks_per_round(workers)).min(cap);
        self.current = RoundPlan { passes, per_block: 2 };
        self.round_started = Instant::now();
        self.current
    }

    /// The error estimate of the completed rounds.
    pub fn estimate(&self) -> &ErrorEstimate {
        &self.estimate
    }

    /// The completed rounds' plans, in order.
    pub fn plans(&self) -> &[RoundPlan] {
        &self.plans
    }

    /// Goes on with these rounds under a new `bound` (a later deadline or another target; the pilot of
    /// `--integrator auto` continued by the render it chose): the completed rounds, their rate and the error
    /// estimate are kept, and the round in flight, if any, is forgotten.
    pub fn continue_with(&mut self, bound: Bound) {
        self.bound = Bound { bias_alpha: self.bound.bias_alpha, ..bound };
        self.stopped = None;
        self.current = NO_ROUND;
        self.sums = SumAccumulator::new(self.sums.sums().len(), 1);
    }

    /// Whether the render has stopped ([`Rounds::stop`], or [`Rounds::next`] found no round to start).
    pub fn is_stopped(&self) -> bool {
        self.stopped.is_some()
    }

    /// Times the round in flight from now: the first round's clock starts when the first worker is ready, so
    /// that its rate is the render's, not the connections' and uploads'.
    pub fn restart_round_clock(&mut self) {
        self.round_started = Instant::now();
    }

    /// Whether the round in flight is so late that it should be dropped: past the deadline by more than a tenth
    /// of the time the render had (a round that ends a little late is kept; one that a lost worker or a slow
    /// round holds up is not).
    pub fn overdue(&self) -> bool {
        self.bound.deadline.is_some_and(|d| {
            let grace = d.saturating_duration_since(self.started) / 10;
            Instant::now() > d + grace
        })
    }

    /// Time left before the deadline, if there is one.
    pub fn remaining(&self) -> Option<Duration> {
        self.bound.deadline.map(|d| d.saturating_duration_since(Instant::now()))
    }

    /// Passes of the completed rounds.
    pub fn passes(&self) -> u32 {
        self.done
    }

    /// Rounds completed.
    pub fn completed(&self) -> u32 {
        self.plans.len() as u32
    }

    /// Adds an accepted block of the round in flight: its index (for the interleaved halves), its passes and
    /// its fixed-point sums.
    pub fn add_block(&mut self, index: u32, passes: u32, sums: &[i64]) {
        self.sums.add(sums);
        self.estimate.add_block(index, passes, sums);
    }

    /// Counts an accepted block of `passes` passes that its worker rendered in `seconds`.
    pub fn add_block_time(&mut self, passes: u32, seconds: f64) {
        if seconds.is_finite() && seconds > 0.0 {
            self.block_time.0 += seconds;
            self.block_time.1 += u64::from(passes);
        }
    }

    /// Ends the round in flight: its sums join `image`. Returns the new error estimate when the render
    /// estimates one.
    pub fn end_round(&mut self, image: &mut SumAccumulator) -> Option<f64> {
        image.absorb(&mut self.sums);
        self.done += self.current.passes;
        self.plans.push(self.current);
        let seconds = self.round_started.elapsed().as_secs_f64();
        self.round_seconds += seconds;
        self.last = Some((seconds, self.current.passes));
        self.estimate.end_round();
        self.last_estimate = if self.bound.estimates() { self.estimate.parts() } else { None };
        self.last_estimate.map(ErrorParts::rel_mse)
    }

    /// Records why the render stops (the round in flight, if any, is dropped with its sums).
    pub fn stop(&mut self, reason: StopReason) {
        self.stopped = Some(reason);
    }

    /// What the render did: the passes and rounds in the image, why it stopped, the last estimate.
    pub fn report(&self) -> BoundedReport {
        BoundedReport {
            passes: self.passes(),
            rounds: self.completed(),
            reason: self.stopped.unwrap_or(StopReason::Cap),
            rel_mse_estimate: self.last_estimate.map(ErrorParts::rel_mse),
            error_parts: self.last_estimate,
            round_seconds: self.round_seconds,
            block_rate: (self.block_time.0 > 0.0).then(|| self.block_time.1 as f64 / self.block_time.0),
        }
    }

    /// The next round for `workers` workers, or why the render stops (recorded as by [`Rounds::stop`]).
    pub fn next(&mut self, workers: usize) -> Result<RoundPlan, StopReason> {
        let now = Instant::now();
        let plan = plan_round(&RoundState {
            done: self.passes(),
            elapsed: now.duration_since(self.started),
            remaining: self.bound.deadline.map(|d| d.saturating_duration_since(now)),
            last: self.last,
            estimate: self.last_estimate.map(ErrorParts::rel_mse),
            target: self.bound.target_error,
            estimating: self.bound.estimates(),
            cap: self.bound.passes.unwrap_or(MAX_PASSES).min(MAX_PASSES),
            workers,
        })
        .inspect_err(|&reason| self.stop(reason))?;
        self.current = plan;
        self.round_started = now;
        Ok(plan)
    }
}

/// The plan of no round: before the first, and after a continued render forgot the round in flight.
const NO_ROUND: RoundPlan = RoundPlan { passes: 0, per_block: 1 };

/// Blocks in a round for `workers` workers: two each, and at least two (one per half of the error estimate).
fn blocks_per_round(workers: usize) -> u32 {
    (2 * workers.max(1)).min(1024) as u32
}

/// What [`plan_round`] decides from.
#[derive(Clone, Copy, Debug)]
struct RoundState {
    /// Passes done.
    done: u32,
    /// Time since the render started.
    elapsed: Duration,
    /// Time left before the deadline, if there is one.
    remaining: Option<Duration>,
    /// Seconds and passes of the last round.
    last: Option<(f64, u32)>,
    /// The last error estimate.
    estimate: Option<f64>,
    /// The target error.
    target: Option<f64>,
    /// Whether each round ends with an estimate.
    estimating: bool,
    /// The most passes in all.
    cap: u32,
    /// Workers active.
    workers: usize,
}

/// The next round, or why the render stops (see the module documentation).
fn plan_round(s: &RoundState) -> Result<RoundPlan, StopReason> {
    if let (Some(e), Some(t)) = (s.estimate, s.target)
        && e <= t
    {
        return Err(StopReason::Error);
    }
    let left = s.cap.saturating_sub(s.done);
    if left == 0 {
        return Err(StopReason::Cap);
    }
    let blocks = blocks_per_round(s.workers);
    // Passes per second the last round measured (its first round: one pass per block).
    let rate = s.last.map_or(0.0, |(secs, passes)| f64::from(passes) / secs.max(1e-3));
    let aim = (s.elapsed / 2).clamp(MIN_ROUND, MAX_ROUND);
    let mut passes = (rate * aim.as_secs_f64()).max(f64::from(blocks));
    if let Some(remaining) = s.remaining {
        // 10 % spare: the last round's rate is a measurement, and a slower round must still end in time.
        let fits = 0.9 * rate * remaining.as_secs_f64();
        if remaining.is_zero() || fits < (0.5 * f64::from(blocks)).max(2.0) {
            return Err(StopReason::Time);
        }
        passes = passes.min(fits);
    }
    if s.estimating {
        // At most as many as are done, so that K at most doubles between two estimates; and the error falls as
        // 1/K (variance) or slower, so K·(e/t) passes in all is the fewest that can reach the target.
        let needed = match (s.estimate, s.target) {
            (Some(e), Some(t)) => f64::from(s.done) * (e / t - 1.0) * 1.1,
            _ => f64::INFINITY,
        };
        passes = passes.min(needed.min(f64::from(s.done)).max(f64::from(blocks)));
    }
    // Even counts, so that every block starts at an even pass and holds whole pairs (see `half_of`).
    let passes = ((passes.round() as u32).max(2) & !1).min(left);
    let per_block =
        passes.div_ceil(blocks).next_multiple_of(2).clamp(2, photon_core::render::sums::MAX_BLOCK_UNITS - 1);
    Ok(RoundPlan { passes, per_block })
}

/// The error estimate of a bounded render (see the module documentation): two interleaved half-images by block
/// parity, and, for the bias of progressive photon mapping, the sums of each round.
#[derive(Clone, Debug, Default)]
pub struct ErrorEstimate {
    /// Radiance sums (W·sr⁻¹·m⁻² × passes) of the even and odd blocks, and their passes. Empty when the render
    /// estimates no error.
    halves: [Vec<f64>; 2],
    half_passes: [u64; 2],
    /// Progressive photon mapping: the radiance sums and passes of each completed round, and of the one in flight.
    rounds: Vec<(Vec<f32>, u32)>,
    current: Vec<f64>,
    current_passes: u32,
    alpha: Option<f32>,
}

/// The half-image block `index` belongs to: the blocks alternate (A B A B …), so each round, and with it each
/// stretch of the radius sequence, is split between the halves.
fn half_of(index: u32) -> usize {
    (index % 2) as usize
}

/// One fixed-point unit in radiance.
const UNIT: f64 = 1.0 / (1u64 << SUM_FRACTION_BITS) as f64;

impl ErrorEstimate {
    /// An estimate over `values` pixel values; nothing is kept unless `enabled`. `alpha`: the bias model's α.
    pub fn new(values: usize, enabled: bool, alpha: Option<f32>) -> Self {
        if !enabled {
            return Self::default();
        }
        let current = if alpha.is_some() { vec![0.0; values] } else { Vec::new() };
        Self { halves: [vec![0.0; values], vec![0.0; values]], current, alpha, ..Self::default() }
    }

    /// Adds block `index` of `passes` passes with fixed-point sums `sums`.
    pub fn add_block(&mut self, index: u32, passes: u32, sums: &[i64]) {
        let half = half_of(index);
        if self.halves[half].is_empty() {
            return;
        }
        for (h, &s) in self.halves[half].iter_mut().zip(sums) {
            *h += s as f64 * UNIT;
        }
        self.half_passes[half] += u64::from(passes);
        if self.alpha.is_some() {
            for (c, &s) in self.current.iter_mut().zip(sums) {
                *c += s as f64 * UNIT;
            }
            self.current_passes += passes;
        }
    }

    /// Closes the round in flight (its sums become one round of the time split).
    pub fn end_round(&mut self) {
        if self.alpha.is_some() && self.current_passes > 0 {
            let sums = self.current.iter().map(|&v| v as f32).collect();
            self.rounds.push((sums, self.current_passes));
            self.current.iter_mut().for_each(|v| *v = 0.0);
            self.current_passes = 0;
        }
    }

    /// The estimated relative MSE of the mean of every block added so far, or `None` before both halves have a
    /// block (and, with the bias model, before two rounds are complete).
    pub fn rel_mse(&self) -> Option<f64> {
        self.parts().map(ErrorParts::rel_mse)
    }

    /// [`ErrorEstimate::rel_mse`] in its parts, variance and squared bias.
    pub fn parts(&self) -> Option<ErrorParts> {
        self.parts_with(None)
    }

    /// [`ErrorEstimate::parts`] relative to `reference` (pixel values, as the image's), an estimate of the true
    /// image better than this render's own halves, in place of the smaller half's mean: after a few passes that
    /// mean is often near 0 where the image is noisy, which inflates the relative error of the noisiest methods
    /// most (`--integrator auto` pools its candidates' pilots into one: [`crate::auto`]).
    pub fn parts_against(&self, reference: &[f32]) -> Option<ErrorParts> {
        (reference.len() == self.halves[0].len()).then(|| self.parts_with(Some(reference))).flatten()
    }

    /// The two half-images: their radiance sums per pixel value (W·sr⁻¹·m⁻² × passes) and their passes; `None`
    /// before both halves have a block.
    pub fn halves(&self) -> Option<([&[f64]; 2], [u64; 2])> {
        let [na, nb] = self.half_passes;
        (na > 0 && nb > 0).then(|| ([self.halves[0].as_slice(), self.halves[1].as_slice()], self.half_passes))
    }

    fn parts_with(&self, reference: Option<&[f32]>) -> Option<ErrorParts> {
        let [na, nb] = self.half_passes.map(|n| n as f64);
        if na == 0.0 || nb == 0.0 {
            return None;
        }
        let n = na + nb;
        // Before two rounds the bias cannot be told from noise: no estimate. When the two parts' radii hardly
        // differ (α near 1), the bias model has nothing to extrapolate from: variance only.
        if self.alpha.is_some() && self.rounds.len() < 2 {
            return None;
        }
        let split = self.alpha.and_then(|alpha| self.time_split(alpha));
        let (mut var_sum, mut bias_sum) = (0.0, 0.0);
        for i in 0..self.halves[0].len() {
            let (a, b) = (self.halves[0][i], self.halves[1][i]);
            let d = a / na - b / nb;
            // σ²: the variance of one pass.
            let sigma2 = d * d / (1.0 / na + 1.0 / nb);
            // The reference's value is unknown: the smaller half's mean stands in for it, which a rare large
            // sample (a firefly) in one half does not inflate (the full mean would, hiding that very error).
            let low = match reference {
                Some(r) => f64::from(r[i]).max(0.0),
                None => (a / na).min(b / nb).max(0.0),
            };
            let den = low * low + photon_core::metrics::EPSILON;
            var_sum += sigma2 / n / den;
            if let Some(split) = &split {
                let dt = split.first[i] / split.p1 - split.second[i] / split.p2;
                let var_d = sigma2 * (1.0 / split.p1 + 1.0 / split.p2);
                bias_sum += split.gain * split.gain * (dt * dt - var_d) / den;
            }
        }
        let values = self.halves[0].len().max(1) as f64;
        Some(ErrorParts { variance: var_sum / values, bias2: bias_sum / values })
    }

    /// The split of the completed rounds at the round end nearest half the passes, with the bias model's gain
    /// `m / (m₁ − m₂)`; `None` before two rounds or when the two parts' radii hardly differ.
    fn time_split(&self, alpha: f32) -> Option<TimeSplit> {
        if self.rounds.len() < 2 {
            return None;
        }
        let total: u32 = self.rounds.iter().map(|r| r.1).sum();
        let mut ends = self.rounds.iter().scan(0u32, |acc, r| {
            *acc += r.1;
            Some(*acc)
        });
        let (j, p) = ends
            .by_ref()
            .take(self.rounds.len() - 1)
            .enumerate()
            .min_by_key(|&(_, p)| (i64::from(p) - i64::from(total) / 2).abs())?;
        let (p1, p2) = (f64::from(p), f64::from(total - p));
        let m1 = radius_power_sum(alpha, 0..p, 2.0) / p1;
        let m2 = radius_power_sum(alpha, p..total, 2.0) / p2;
        let m = radius_power_sum(alpha, 0..total, 2.0) / f64::from(total);
        if m1 - m2 <= 1e-6 * m {
            return None;
        }
        let sum_of = |rounds: &[(Vec<f32>, u32)]| {
            let mut s = vec![0.0f64; self.halves[0].len()];
            for (r, _) in rounds {
                for (a, &v) in s.iter_mut().zip(r) {
                    *a += f64::from(v);
                }
            }
            s
        };
        Some(TimeSplit {
            first: sum_of(&self.rounds[..=j]),
            second: sum_of(&self.rounds[j + 1..]),
            p1,
            p2,
            gain: m / (m1 - m2),
        })
    }
}

/// The completed rounds split in two parts in time.
struct TimeSplit {
    /// Radiance sums of the first and second parts, and their passes.
    first: Vec<f64>,
    second: Vec<f64>,
    p1: f64,
    p2: f64,
    /// `m / (m₁ − m₂)`: the whole render's bias over the expected difference of the parts' means.
    gain: f64,
}

/// The passes of a round, `start..start + plan.passes`.
pub fn round_range(start: u32, plan: RoundPlan) -> Range<u32> {
    start..start.saturating_add(plan.passes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator of uniform numbers in [0, 1) (xorshift64*).
    struct Rng(u64);

    impl Rng {
        fn seed_from_u64(seed: u64) -> Self {
            Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }

        fn random(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Fixed-point sums of `passes` draws of `value + noise` per pixel value.
    fn block(rng: &mut Rng, values: &[f64], passes: u32, sigma: f64, bias: impl Fn(u32) -> f64) -> Vec<i64> {
        values
            .iter()
            .map(|&v| {
                (0..passes)
                    .map(|p| {
                        let x = v + bias(p) + sigma * (rng.random() - 0.5) * 12f64.sqrt();
                        (x.max(0.0) / UNIT).round() as i64
                    })
                    .sum()
            })
            .collect()
    }

    #[test]
    fn the_variance_estimate_matches_the_true_error_of_noisy_pixels() {
        // 2000 values of mean 1 with per-pass noise σ = 0.2: after n passes the relative MSE is σ²/n / (1 + ε).
        let mut rng = Rng::seed_from_u64(7);
        let values = vec![1.0; 2000];
        let mut est = ErrorEstimate::new(values.len(), true, None);
        for i in 0..8 {
            est.add_block(i, 4, &block(&mut rng, &values, 4, 0.2, |_| 0.0));
        }
        let truth = 0.04 / 32.0 / (1.0 + photon_core::metrics::EPSILON);
        let e = est.rel_mse().unwrap();
        // The smaller half stands in for the reference: a few per cent high at this noise.
        assert!((e / truth - 1.0).abs() < 0.15, "estimate {e}, truth {truth}");
    }

    #[test]
    fn a_firefly_in_one_half_counts_against_the_other_halfs_value() {
        // Four values of 0.5 a pass, two passes a half; one pass of the first value is a firefly of 1000. That
        // value's mean is 250.4, 249.9 off, a relative squared error of 249.9² / (0.5² + ε) = 240 000, or 60 000
        // over the 4 values. Dividing by the full mean's square would give about 0.25; the smaller half (0.5)
        // keeps the estimate of the right order.
        let fixed = |v: f64| (v / UNIT).round() as i64;
        let mut est = ErrorEstimate::new(4, true, None);
        est.add_block(0, 2, &[fixed(1000.5), fixed(1.0), fixed(1.0), fixed(1.0)]);
        est.add_block(1, 2, &[fixed(1.0), fixed(1.0), fixed(1.0), fixed(1.0)]);
        let e = est.rel_mse().unwrap();
        assert!(e > 10_000.0, "{e}");
    }

    #[test]
    fn no_estimate_before_both_halves_have_a_block() {
        let mut est = ErrorEstimate::new(3, true, None);
        assert_eq!(est.rel_mse(), None);
        est.add_block(0, 1, &[1 << 24, 1 << 24, 1 << 24]);
        est.add_block(2, 1, &[1 << 24, 1 << 24, 1 << 24]);
        assert_eq!(est.rel_mse(), None, "blocks 0 and 2 are both in the first half");
        est.add_block(1, 1, &[1 << 24, 1 << 24, 1 << 24]);
        assert_eq!(est.rel_mse(), Some(0.0));
        // Disabled: nothing kept, nothing estimated.
        let mut off = ErrorEstimate::new(3, false, None);
        off.add_block(0, 1, &[1, 1, 1]);
        off.add_block(2, 1, &[1, 1, 1]);
        assert_eq!(off.rel_mse(), None);
    }

    #[test]
    fn the_bias_model_recovers_a_bias_proportional_to_the_squared_radius() {
        // Pass p estimates 1 + c·r_p²/r_0² with c = 0.2 and small noise: the estimate is dominated by the bias
        // of the mean, c·mean(r²/r₀²), which a variance-only estimate would miss.
        let (alpha, c) = (0.7f32, 0.2);
        let mut rng = Rng::seed_from_u64(11);
        let values = vec![1.0; 500];
        let ratio = |p: u32| radius_power_sum(alpha, p..p + 1, 2.0);
        let mut est = ErrorEstimate::new(values.len(), true, Some(alpha));
        let (mut start, mut index) = (0u32, 0u32);
        for round in [4u32, 8, 16, 32] {
            for _ in 0..2 {
                let passes = round / 2;
                let s = start;
                est.add_block(index, passes, &block(&mut rng, &values, passes, 0.01, |p| c * ratio(s + p)));
                start += passes;
                index += 1;
            }
            est.end_round();
        }
        let bias = c * radius_power_sum(alpha, 0..start, 2.0) / f64::from(start);
        let mean = 1.0 + bias;
        let truth = bias * bias / (mean * mean + photon_core::metrics::EPSILON);
        let e = est.rel_mse().unwrap();
        assert!((e / truth - 1.0).abs() < 0.2, "estimate {e}, truth {truth}");
        let variance_only = {
            let mut v = ErrorEstimate::new(values.len(), true, None);
            let mut rng = Rng::seed_from_u64(11);
            for i in 0..8 {
                v.add_block(i, 8, &block(&mut rng, &values, 8, 0.01, |_| 0.0));
            }
            v.rel_mse().unwrap()
        };
        assert!(variance_only < truth / 10.0, "{variance_only} vs {truth}");
    }

    fn state(done: u32, elapsed: f64, remaining: Option<f64>, last: Option<(f64, u32)>) -> RoundState {
        RoundState {
            done,
            elapsed: Duration::from_secs_f64(elapsed),
            remaining: remaining.map(Duration::from_secs_f64),
            last,
            estimate: None,
            target: None,
            estimating: false,
            cap: MAX_PASSES,
            workers: 2,
        }
    }

    #[test]
    fn rounds_grow_with_the_time_spent_and_fit_the_deadline() {
        // 10 passes/s; 8 s spent: aim at 4 s = 40 passes in 4 blocks of 10.
        let plan = plan_round(&state(20, 8.0, None, Some((2.0, 20)))).unwrap();
        assert_eq!(plan, RoundPlan { passes: 40, per_block: 10 });
        // Early on the round is at least MIN_ROUND long: 1 s = 10 passes.
        assert_eq!(plan_round(&state(4, 0.5, None, Some((0.4, 4)))).unwrap().passes, 10);
        // 1.5 s left: 15 passes, less 10 %.
        assert_eq!(plan_round(&state(20, 8.0, Some(1.5), Some((2.0, 20)))).unwrap().passes, 14);
        // 0.15 s left fits 1.35 passes, under half a pass per block: stop.
        assert_eq!(plan_round(&state(20, 8.0, Some(0.15), Some((2.0, 20)))), Err(StopReason::Time));
        assert_eq!(plan_round(&state(20, 8.0, Some(0.0), Some((2.0, 20)))), Err(StopReason::Time));
        // The cap.
        assert_eq!(plan_round(&state(MAX_PASSES, 8.0, None, Some((2.0, 20)))), Err(StopReason::Cap));
        let near = plan_round(&state(MAX_PASSES - 3, 8.0, None, Some((2.0, 20)))).unwrap();
        assert_eq!(near.passes, 3);
        // A budget of 25 passes: 5 left.
        let budget = RoundState { cap: 25, ..state(20, 8.0, None, Some((2.0, 20))) };
        assert_eq!(plan_round(&budget).unwrap().passes, 5);
        assert_eq!(plan_round(&RoundState { cap: 20, ..budget }), Err(StopReason::Cap));
    }

    #[test]
    fn a_target_stops_the_render_and_cuts_the_last_rounds() {
        let mut s = state(100, 20.0, None, Some((5.0, 100)));
        (s.target, s.estimating) = (Some(0.01), true);
        // 1.5 times the target: at most 100·(1.5 − 1)·1.1 = 55 more passes (54: an even count), not the 200 the
        // time aim allows.
        s.estimate = Some(0.015);
        assert_eq!(plan_round(&s).unwrap().passes, 54);
        // Far above it: at most the 100 done, so K at most doubles.
        s.estimate = Some(1.0);
        assert_eq!(plan_round(&s).unwrap().passes, 100);
        s.estimate = Some(0.0099);
        assert_eq!(plan_round(&s), Err(StopReason::Error));
    }
}
