//! The scheduler's vocabulary: worker and strip ids, the policy's knobs, and what the state machine answers
//! (assignments, completions, failures and their outcomes, per-worker numbers).

use photon_core::render::sums::MAX_BLOCK_UNITS;
use std::fmt;
use std::ops::Range;
use std::time::Duration;

/// Identifies a worker; the caller chooses the numbers (a lost worker that reconnects gets a new id).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct WorkerId(pub u32);

impl fmt::Display for WorkerId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "worker {}", self.0)
    }
}

/// Identifies a strip: a dense index, strip 0 at the top of the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct StripId(pub u32);

impl fmt::Display for StripId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "strip {}", self.0)
    }
}

/// The knobs of the scheduling policy; [`Policy::default`] is what the command line uses.
#[derive(Clone, Debug, PartialEq)]
pub struct Policy {
    /// Strips a worker may hold at once (at least 1).
    pub max_in_flight: usize,
    /// Copies of one strip that may be in flight at once, the original included (1 disables speculation).
    pub max_copies: usize,
    /// Failed units after which a worker is blocked: it gets no more units of this job. Every failure counts
    /// but those that are nobody's fault (a cancelled copy, a busy worker) or the job's (the same input fails
    /// everywhere): a corrupt or impossible result, a missed deadline, a unit it stalled on, and each unit it
    /// held when its connection was lost (a crash, a cut link). Flamenco blocks a worker after 3 failures on a
    /// job for the same reason: one bad machine must not fail unit after unit.
    pub block_after: u32,
    /// A strip is overdue after this many times its expected latency.
    pub deadline_factor: f64,
    /// The shortest deadline, whatever the measured speed (absorbs jitter on tiny strips).
    pub deadline_floor: Duration,
    /// The deadline while no worker has completed a strip yet, so nothing is known of the speed.
    pub first_deadline: Duration,
    /// The shortest silence after which a busy worker counts as stalled ([`crate::farm::scheduler::Scheduler::silence_limit`]).
    pub silence_floor: Duration,
    /// Weight of the newest strip in the moving average of seconds per row, in (0, 1].
    pub speed_smoothing: f64,
}

impl Default for Policy {
    fn default() -> Self {
        Self {
            max_in_flight: 2,
            max_copies: 2,
            block_after: 3,
            deadline_factor: 4.0,
            deadline_floor: Duration::from_secs(10),
            first_deadline: Duration::from_secs(600),
            silence_floor: Duration::from_secs(2),
            speed_smoothing: 0.3,
        }
    }
}

/// Rows per strip for an image of `height` rows over `workers` workers: about 16 strips per worker, so that pulls
/// balance speeds and the tail is short, but never more than 64 rows nor fewer than 1.
pub fn rows_per_strip_for(height: u32, workers: u32) -> u32 {
    let target_strips = workers.max(1).saturating_mul(16);
    height.div_ceil(target_strips).clamp(1, 64)
}

/// Passes per block for progressive photon mapping over `workers` workers: about 16 blocks per worker, as for
/// strips, never more than [`MAX_BLOCK_UNITS`] nor fewer than 1. Each block renders the whole image and traces
/// its passes' photons once; the cut never changes a pixel (the sums are exact). Fewer blocks send fewer full
/// images back, more blocks shorten the tail: on the modelled 368-core lab (docs/RESULTS.md, "The modelled lab")
/// a 10-minute 1920×1080 job reaches 72 % efficiency with 4 blocks per worker (the last blocks of the slow
/// machines hold the end up), 88 % with 16, and 81 % with 32 (50 MB per block saturate the coordinator's link).
pub fn passes_per_block_for(passes: u32, workers: u32) -> u32 {
    passes.div_ceil(workers.max(1).saturating_mul(16)).clamp(1, MAX_BLOCK_UNITS)
}

/// One strip given to one worker.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Assignment {
    /// The strip.
    pub strip: StripId,
    /// The rows it covers, top to bottom.
    pub rows: Range<u32>,
    /// Which issue of the strip this is (1 for the first); the result must quote it.
    pub attempt: u32,
    /// Whether this is a speculative copy of a strip that is already running elsewhere.
    pub speculative: bool,
}

/// What became of a reported result.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Completion {
    /// The first valid result: keep the pixels. Cancel the other copies of the strip listed here.
    Accepted {
        /// Other workers still rendering the strip; their slots are already free.
        cancel: Vec<(WorkerId, StripId)>,
    },
    /// The strip was already done (a late or speculative copy): drop the pixels.
    Duplicate,
    /// No current assignment matches (unknown worker or strip, stale attempt, withdrawn assignment): drop it.
    Unknown,
}

/// Why a worker could not deliver a strip.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StripFailure {
    /// Another attempt could succeed (a network error, a crash); `false` means the render cannot finish.
    pub retryable: bool,
    /// The failure counts against the worker (it, not the network, misbehaved).
    pub counted: bool,
    /// What happened, for the log and the end-of-render table.
    pub reason: String,
}

impl StripFailure {
    /// A retryable failure that counts against the worker (it sent a bad strip, missed a deadline).
    pub fn counted(reason: impl Into<String>) -> Self {
        Self { retryable: true, counted: true, reason: reason.into() }
    }

    /// A retryable failure that is not the worker's fault (a dropped connection, a cancelled copy).
    pub fn transient(reason: impl Into<String>) -> Self {
        Self { retryable: true, counted: false, reason: reason.into() }
    }

    /// A failure no other attempt would avoid (the scene itself is broken): the render must stop.
    pub fn fatal(reason: impl Into<String>) -> Self {
        Self { retryable: false, counted: false, reason: reason.into() }
    }

    /// An assignment that missed its deadline: retryable, and counted (the worker stalled).
    pub fn timed_out(elapsed: Duration, deadline: Duration) -> Self {
        let (elapsed, deadline) = (elapsed.as_secs_f64(), deadline.as_secs_f64());
        Self::counted(format!("no result after {elapsed:.1} s (deadline {deadline:.1} s)"))
    }
}

impl fmt::Display for StripFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match (self.retryable, self.counted) {
            (false, _) => "fatal",
            (true, true) => "counted",
            (true, false) => "transient",
        };
        write!(f, "{kind} failure: {}", self.reason)
    }
}

impl std::error::Error for StripFailure {}

/// What became of a reported failure.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FailureOutcome {
    /// No current assignment matched (already withdrawn, or the strip is done): nothing changed.
    Ignored,
    /// The strip was requeued at the front (or another copy of it is still running).
    Retrying,
    /// The worker reached [`Policy::block_after`] failed units and was blocked; all its strips were requeued.
    WorkerBlocked {
        /// Why, for the log.
        reason: String,
        /// Its other strips still in flight: cancel them on the worker.
        cancel: Vec<StripId>,
    },
    /// A non-retryable failure: the render cannot finish (see [`crate::farm::scheduler::Scheduler::fatal`]).
    Fatal,
}

/// Where a worker stands.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WorkerState {
    /// Registered and taking strips.
    Active,
    /// Its connection was lost ([`crate::farm::scheduler::Scheduler::worker_lost`]); it may rejoin ([`crate::farm::scheduler::Scheduler::rejoin`]).
    Lost,
    /// Blocked after [`Policy::block_after`] failed units of this job, with the reason: it gets no more.
    Blocked(String),
}

/// Per-worker numbers for the end-of-render table.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkerStats {
    /// The cores it announced.
    pub cores: u32,
    /// Strips whose result was accepted.
    pub strips: u32,
    /// Rows in those strips.
    pub rows: u64,
    /// Time with at least one strip in flight (intervals still open are not included).
    pub busy: Duration,
    /// Failures reported, counted or not.
    pub failures: u32,
    /// Failed units that count towards its block ([`Policy::block_after`]): counted failures, units it
    /// stalled on, units it held when it was lost.
    pub counted_failures: u32,
    /// Results dropped as duplicates.
    pub duplicates: u32,
    /// Speculative copies it was given.
    pub speculative: u32,
    /// Whether it is still taking strips.
    pub state: WorkerState,
    /// It held strips and said nothing for longer than its silence limit (frozen, or its link is): those strips
    /// were issued again to others. Shown as `stalled` until it is heard from again.
    pub stalled: bool,
    /// Times it came back after it was lost.
    pub rejoins: u32,
}

/// A worker found stalled by [`crate::farm::scheduler::Scheduler::check_stalls`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stall {
    /// The worker.
    pub worker: WorkerId,
    /// It was not stalled before (the first stall since it was last heard from): tell the user.
    pub newly: bool,
    /// The units it stalled on, now open to the other workers (its copies keep running: the first result wins).
    pub strips: Vec<StripId>,
    /// The stall made it reach [`Policy::block_after`]: why, and the strips it held (cancel them on it).
    pub blocked: Option<(String, Vec<StripId>)>,
}
