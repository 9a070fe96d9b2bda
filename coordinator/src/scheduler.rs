//! The strip scheduler: which worker renders which rows, as a pure state machine.
//!
//! The image is cut along Y into strips of a few rows; strip ids are dense indices from the top. The caller owns
//! the network and the clock and feeds events in with the time they happened (a [`Duration`] since the render
//! started); the scheduler only keeps books. Nothing here reads the clock, spawns a task or iterates a hash map,
//! so the same events always give the same decisions, and the tests drive it with a fake clock.
//!
//! # Policy, and why
//! - **Pull, not push.** A worker asks for work ([`Scheduler::assign`]) whenever it has a free slot. Faster
//!   machines come back sooner and so take more strips, with no up-front partition to get wrong (the static
//!   partition of the original Bash layer left the fast machines idle while the slow ones finished).
//! - **A few strips in flight per worker** ([`Policy::max_in_flight`], 2 by default): while a worker renders one
//!   strip the next is already on its way, so the network overlaps compute; a larger number would only hoard
//!   strips that a faster worker could have taken at the end.
//! - **Pending strips in order; requeue at the front.** A failed, lost or timed-out strip goes back to the head of
//!   the queue (requeued strips among themselves top of the image first): it has waited longest and the image
//!   cannot be finished without it, so putting it last would only lengthen the tail. The queue never holds a strip
//!   twice, nor one that is done or still running.
//! - **Speculation at the tail.** When the queue is empty a free slot takes a copy of the oldest outstanding strip
//!   (one the worker does not already hold, at most [`Policy::max_copies`] copies in flight). The first valid
//!   result wins ([`Completion::Accepted`] lists the other copies to cancel); a later one is a
//!   [`Completion::Duplicate`] and is dropped. One slow or stalled machine then cannot hold the whole render up.
//! - **Deadlines from measured speed.** Each worker's seconds per row is an exponential moving average over the
//!   strips it completed, measured from assignment to result (so it includes the wait behind its other in-flight
//!   strip and the network, exactly the latency a deadline must allow for). A strip is overdue after
//!   `max(deadline_factor × rows × seconds_per_row, deadline_floor)`; before a worker has finished anything it
//!   borrows the fleet's speed scaled by its cores, and before anyone has, [`Policy::first_deadline`] applies.
//!   [`Scheduler::expired`] lists overdue assignments; the caller cancels them and reports them as failures.
//! - **Failures carry flags** ([`StripFailure`]): a retryable failure requeues the strip; a non-retryable one
//!   (the same input would fail anywhere) stops the render; a *counted* failure counts against the worker, which
//!   is dropped after [`Policy::max_counted_failures`] of them. Transport hiccups are retryable and not counted.
//! - **A result is accepted only from the assignment that is still current**: a late result from a worker that
//!   was declared lost, dropped or timed out is [`Completion::Unknown`] (or a duplicate, if the strip is done by
//!   then), never counted twice. The strip has already been given to someone else by then.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
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
    /// Counted failures after which a worker is dropped.
    pub max_counted_failures: u32,
    /// A strip is overdue after this many times its expected latency.
    pub deadline_factor: f64,
    /// The shortest deadline, whatever the measured speed (absorbs jitter on tiny strips).
    pub deadline_floor: Duration,
    /// The deadline while no worker has completed a strip yet, so nothing is known of the speed.
    pub first_deadline: Duration,
    /// Weight of the newest strip in the moving average of seconds per row, in (0, 1].
    pub speed_smoothing: f64,
}

impl Default for Policy {
    fn default() -> Self {
        Self {
            max_in_flight: 2,
            max_copies: 2,
            max_counted_failures: 3,
            deadline_factor: 4.0,
            deadline_floor: Duration::from_secs(10),
            first_deadline: Duration::from_secs(600),
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

/// Rows per strip for progressive photon mapping: about 4 strips per worker. Every strip needs the photon maps of
/// every pass; a worker keeps them for its next strip only as far as its memory allows, and traces them again
/// beyond that, so fewer, taller strips bound the repeated tracing (measured: 512 passes of 100 000 photons on a
/// 32×32 image took 451 s in 16 strips on one worker that kept no maps, and 39 s in 4 strips that kept them).
pub fn rows_per_strip_progressive(height: u32, workers: u32) -> u32 {
    height.div_ceil(workers.max(1).saturating_mul(4)).max(1)
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
    /// A retryable failure that counts against the worker (it crashed, sent a bad strip).
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
    /// The worker reached the counted-failure limit and was dropped; all its strips were requeued.
    WorkerDropped {
        /// Why, for the log.
        reason: String,
        /// Its other strips still in flight: cancel them on the worker.
        cancel: Vec<StripId>,
    },
    /// A non-retryable failure: the render cannot finish (see [`Scheduler::fatal`]).
    Fatal,
}

/// Where a worker stands.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WorkerState {
    /// Registered and taking strips.
    Active,
    /// Its connection was lost ([`Scheduler::worker_lost`]).
    Lost,
    /// Dropped after too many counted failures, with the reason.
    Dropped(String),
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
    /// Failures that counted against it.
    pub counted_failures: u32,
    /// Results dropped as duplicates.
    pub duplicates: u32,
    /// Speculative copies it was given.
    pub speculative: u32,
    /// Whether it is still taking strips.
    pub state: WorkerState,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StripState {
    /// In the queue.
    Pending,
    /// At least one copy in flight.
    Running,
    /// A result was accepted (or preloaded by `mark_done`).
    Done,
    /// A non-retryable failure: never issued again.
    Failed,
}

#[derive(Clone, Debug)]
struct Strip {
    rows: Range<u32>,
    state: StripState,
    /// Times the strip was issued; the attempt number of the latest issue.
    issued: u32,
}

#[derive(Clone, Copy, Debug)]
struct Flight {
    attempt: u32,
    start: Duration,
}

#[derive(Clone, Debug)]
struct Worker {
    stats: WorkerStats,
    in_flight: BTreeSet<StripId>,
    /// Moving average of seconds per row, assignment to result.
    seconds_per_row: Option<f64>,
    /// When its in-flight set last became non-empty.
    busy_since: Option<Duration>,
}

/// The strip scheduler (see the module documentation for the policy).
#[derive(Clone, Debug)]
pub struct Scheduler {
    policy: Policy,
    strips: Vec<Strip>,
    /// Requeued strips, served before `fresh`, top of the image first.
    retry: BTreeSet<StripId>,
    /// Strips never issued, in order. Each strip in `retry` or `fresh` is in state `Pending`, and in one of them once.
    fresh: VecDeque<StripId>,
    /// Every copy in flight, keyed by (strip, worker) so a strip's copies are one range.
    flights: BTreeMap<(StripId, WorkerId), Flight>,
    workers: BTreeMap<WorkerId, Worker>,
    done: usize,
    fatal: Option<(StripId, StripFailure)>,
}

impl Scheduler {
    /// A scheduler for `height` rows cut into strips of `rows_per_strip` rows (0 is taken as 1), default policy.
    pub fn new(height: u32, rows_per_strip: u32) -> Self {
        Self::with_policy(height, rows_per_strip, Policy::default())
    }

    /// A scheduler for `height` rows cut into strips of `rows_per_strip` rows (0 is taken as 1).
    pub fn with_policy(height: u32, rows_per_strip: u32, policy: Policy) -> Self {
        let step = rows_per_strip.max(1);
        let strips: Vec<Strip> = (0..height.div_ceil(step))
            .map(|i| {
                let y0 = i * step;
                Strip { rows: y0..(y0 + step).min(height), state: StripState::Pending, issued: 0 }
            })
            .collect();
        let fresh = (0..strips.len() as u32).map(StripId).collect();
        let policy =
            Policy { max_in_flight: policy.max_in_flight.max(1), max_copies: policy.max_copies.max(1), ..policy };
        let (flights, workers) = (BTreeMap::new(), BTreeMap::new());
        Self { policy, strips, retry: BTreeSet::new(), fresh, flights, workers, done: 0, fatal: None }
    }

    /// The policy in force.
    pub fn policy(&self) -> &Policy {
        &self.policy
    }

    /// Number of strips.
    pub fn strip_count(&self) -> usize {
        self.strips.len()
    }

    /// The rows a strip covers, or `None` for an id out of range.
    pub fn strip_rows(&self, strip: StripId) -> Option<Range<u32>> {
        self.strips.get(strip.0 as usize).map(|s| s.rows.clone())
    }

    /// Registers a worker with `cores` cores. Returns `false` (and changes nothing) if the id was ever used.
    pub fn add_worker(&mut self, id: WorkerId, cores: u32) -> bool {
        if self.workers.contains_key(&id) {
            return false;
        }
        let stats = WorkerStats {
            cores,
            strips: 0,
            rows: 0,
            busy: Duration::ZERO,
            failures: 0,
            counted_failures: 0,
            duplicates: 0,
            speculative: 0,
            state: WorkerState::Active,
        };
        let worker = Worker { stats, in_flight: BTreeSet::new(), seconds_per_row: None, busy_since: None };
        self.workers.insert(id, worker);
        true
    }

    /// Gives `worker` its next strip at time `now`, if it is active, has a free slot and there is work: the first
    /// pending strip, or else a speculative copy of the oldest outstanding one. Nothing after a fatal failure.
    pub fn assign(&mut self, worker: WorkerId, now: Duration) -> Option<Assignment> {
        if self.fatal.is_some() {
            return None;
        }
        let w = self.workers.get(&worker)?;
        if w.stats.state != WorkerState::Active || w.in_flight.len() >= self.policy.max_in_flight {
            return None;
        }
        let (strip, speculative) = match self.retry.pop_first().or_else(|| self.fresh.pop_front()) {
            Some(strip) => (strip, false),
            None => (self.speculation_candidate(worker)?, true),
        };
        let s = &mut self.strips[strip.0 as usize];
        s.state = StripState::Running;
        s.issued += 1;
        let assignment = Assignment { strip, rows: s.rows.clone(), attempt: s.issued, speculative };
        self.flights.insert((strip, worker), Flight { attempt: s.issued, start: now });
        if let Some(w) = self.workers.get_mut(&worker) {
            if w.in_flight.is_empty() {
                w.busy_since = Some(now);
            }
            w.in_flight.insert(strip);
            if speculative {
                w.stats.speculative += 1;
            }
        }
        Some(assignment)
    }

    /// The running strip whose earliest copy started first, among those `worker` does not hold and that have
    /// fewer than `max_copies` copies in flight; ties go to the lower strip id.
    fn speculation_candidate(&self, worker: WorkerId) -> Option<StripId> {
        // Per running strip: (earliest start, copies in flight, held by `worker`).
        let mut running: BTreeMap<StripId, (Duration, usize, bool)> = BTreeMap::new();
        for (&(strip, w), flight) in &self.flights {
            let entry = running.entry(strip).or_insert((flight.start, 0, false));
            entry.0 = entry.0.min(flight.start);
            entry.1 += 1;
            entry.2 |= w == worker;
        }
        running
            .into_iter()
            .filter(|&(strip, (_, copies, held))| {
                !held && copies < self.policy.max_copies && self.strips[strip.0 as usize].state == StripState::Running
            })
            .min_by_key(|&(strip, (start, _, _))| (start, strip))
            .map(|(strip, _)| strip)
    }

    /// Reports the result of `strip`, attempt `attempt`, from `worker` at time `now`.
    pub fn complete(&mut self, worker: WorkerId, strip: StripId, attempt: u32, now: Duration) -> Completion {
        let Some(state) = self.strips.get(strip.0 as usize).map(|s| s.state) else {
            return Completion::Unknown;
        };
        if state == StripState::Done {
            // A copy preloaded by `mark_done` while running may still be in flight: free its slot.
            if self.flights.get(&(strip, worker)).is_some_and(|f| f.attempt == attempt) {
                self.land(strip, worker, now);
            }
            if let Some(w) = self.workers.get_mut(&worker) {
                w.stats.duplicates += 1;
            }
            return Completion::Duplicate;
        }
        if self.flights.get(&(strip, worker)).is_none_or(|f| f.attempt != attempt) {
            return Completion::Unknown;
        }
        let Some(flight) = self.land(strip, worker, now) else {
            return Completion::Unknown;
        };
        let s = &mut self.strips[strip.0 as usize];
        s.state = StripState::Done;
        self.done += 1;
        let rows = s.rows.len() as u32;
        let smoothing = self.policy.speed_smoothing.clamp(f64::MIN_POSITIVE, 1.0);
        if let Some(w) = self.workers.get_mut(&worker) {
            w.stats.strips += 1;
            w.stats.rows += u64::from(rows);
            let sample = now.saturating_sub(flight.start).as_secs_f64() / f64::from(rows.max(1));
            w.seconds_per_row = Some(match w.seconds_per_row {
                Some(avg) => avg + smoothing * (sample - avg),
                None => sample,
            });
        }
        let others: Vec<WorkerId> = self.copies(strip).map(|(w, _)| w).collect();
        let cancel = others
            .into_iter()
            .map(|w| {
                self.land(strip, w, now);
                (w, strip)
            })
            .collect();
        Completion::Accepted { cancel }
    }

    /// Reports that `worker` could not deliver `strip` at time `now` (the caller has cancelled the work on it).
    pub fn failed(&mut self, worker: WorkerId, strip: StripId, failure: StripFailure, now: Duration) -> FailureOutcome {
        if !self.flights.contains_key(&(strip, worker)) {
            return FailureOutcome::Ignored;
        }
        self.land(strip, worker, now);
        if self.strips[strip.0 as usize].state == StripState::Done {
            return FailureOutcome::Ignored;
        }
        let Some(w) = self.workers.get_mut(&worker) else {
            return FailureOutcome::Ignored;
        };
        w.stats.failures += 1;
        if failure.counted {
            w.stats.counted_failures += 1;
        }
        let counted_failures = w.stats.counted_failures;
        if !failure.retryable {
            if self.copies(strip).next().is_none() {
                self.strips[strip.0 as usize].state = StripState::Failed;
            }
            tracing::error!("{worker}: {strip}: {failure}");
            self.fatal.get_or_insert((strip, failure));
            return FailureOutcome::Fatal;
        }
        let limit = self.policy.max_counted_failures;
        if failure.counted && counted_failures >= limit {
            let reason =
                format!("{counted_failures} counted failures (limit {limit}), the last on {strip}: {}", failure.reason);
            tracing::warn!("dropping {worker}: {reason}");
            if let Some(w) = self.workers.get_mut(&worker) {
                w.stats.state = WorkerState::Dropped(reason.clone());
            }
            let cancel = self.withdraw_all(worker, now);
            self.requeue_front(&cancel);
            self.requeue_front(&[strip]);
            return FailureOutcome::WorkerDropped { reason, cancel };
        }
        self.requeue_front(&[strip]);
        FailureOutcome::Retrying
    }

    /// Reports that `worker`'s connection is gone at time `now`: every strip it held is requeued at the front.
    /// Returns those strips. Its late results will not be accepted.
    pub fn worker_lost(&mut self, worker: WorkerId, now: Duration) -> Vec<StripId> {
        match self.workers.get_mut(&worker) {
            Some(w) if w.stats.state == WorkerState::Active => w.stats.state = WorkerState::Lost,
            _ => return Vec::new(),
        }
        let strips = self.withdraw_all(worker, now);
        self.requeue_front(&strips);
        strips
    }

    /// Assignments past their deadline at `now`, in (strip, worker) order. The caller cancels each and reports it
    /// with [`Scheduler::failed`] (e.g. [`StripFailure::timed_out`]); until then it is listed again. If a report
    /// drops the worker, its later entries are already withdrawn and report as [`FailureOutcome::Ignored`].
    pub fn expired(&self, now: Duration) -> Vec<(WorkerId, StripId)> {
        self.flights
            .iter()
            .filter(|&(&(strip, worker), flight)| now > self.deadline_of(strip, worker, flight))
            .map(|(&(strip, worker), _)| (worker, strip))
            .collect()
    }

    /// The deadline of `worker`'s copy of `strip`, if it holds one.
    pub fn deadline(&self, worker: WorkerId, strip: StripId) -> Option<Duration> {
        self.flights.get(&(strip, worker)).map(|f| self.deadline_of(strip, worker, f))
    }

    /// The earliest deadline of anything in flight: when the caller should next call [`Scheduler::expired`].
    pub fn next_deadline(&self) -> Option<Duration> {
        self.flights.iter().map(|(&(strip, worker), f)| self.deadline_of(strip, worker, f)).min()
    }

    /// Whether every strip is done.
    pub fn is_done(&self) -> bool {
        self.done == self.strips.len()
    }

    /// (strips done, strips in total).
    pub fn progress(&self) -> (usize, usize) {
        (self.done, self.strips.len())
    }

    /// The strips done so far, in order: what a resumable partial file records.
    pub fn done_strips(&self) -> Vec<StripId> {
        self.strips_in(StripState::Done)
    }

    /// The strips waiting in the queue, in the order they will be served.
    pub fn pending_strips(&self) -> Vec<StripId> {
        self.retry.iter().chain(&self.fresh).copied().collect()
    }

    /// Marks a strip finished earlier (`--resume`), so it is never assigned. Returns `false` if the id is out of
    /// range or the strip was already done. A copy still in flight will report as a duplicate.
    pub fn mark_done(&mut self, strip: StripId) -> bool {
        let Some(s) = self.strips.get_mut(strip.0 as usize) else {
            return false;
        };
        if s.state == StripState::Done {
            return false;
        }
        if s.state == StripState::Pending {
            self.retry.remove(&strip);
            self.fresh.retain(|&p| p != strip);
        }
        s.state = StripState::Done;
        self.done += 1;
        true
    }

    /// Whether no worker is active (none registered, or all lost or dropped): the caller should stop and say so.
    /// Strips not done stay pending.
    pub fn all_workers_gone(&self) -> bool {
        !self.workers.values().any(|w| w.stats.state == WorkerState::Active)
    }

    /// The first non-retryable failure, if any: the render cannot finish.
    pub fn fatal(&self) -> Option<&(StripId, StripFailure)> {
        self.fatal.as_ref()
    }

    /// One worker's numbers.
    pub fn worker_stats(&self, worker: WorkerId) -> Option<&WorkerStats> {
        self.workers.get(&worker).map(|w| &w.stats)
    }

    /// Every worker's numbers, in id order.
    pub fn workers(&self) -> impl Iterator<Item = (WorkerId, &WorkerStats)> {
        self.workers.iter().map(|(&id, w)| (id, &w.stats))
    }

    /// The strips a worker holds, in order.
    pub fn in_flight(&self, worker: WorkerId) -> Vec<StripId> {
        self.workers.get(&worker).map(|w| w.in_flight.iter().copied().collect()).unwrap_or_default()
    }

    /// A worker's measured seconds per row (assignment to result), once it has completed a strip.
    pub fn seconds_per_row(&self, worker: WorkerId) -> Option<f64> {
        self.workers.get(&worker).and_then(|w| w.seconds_per_row)
    }

    fn strips_in(&self, state: StripState) -> Vec<StripId> {
        (0..self.strips.len() as u32).map(StripId).filter(|s| self.strips[s.0 as usize].state == state).collect()
    }

    /// The copies of `strip` in flight, as (worker, flight).
    fn copies(&self, strip: StripId) -> impl Iterator<Item = (WorkerId, &Flight)> {
        self.flights.range((strip, WorkerId(0))..=(strip, WorkerId(u32::MAX))).map(|(&(_, w), f)| (w, f))
    }

    /// Removes one copy from flight and frees the worker's slot, closing its busy interval if it is now idle.
    fn land(&mut self, strip: StripId, worker: WorkerId, now: Duration) -> Option<Flight> {
        let flight = self.flights.remove(&(strip, worker))?;
        if let Some(w) = self.workers.get_mut(&worker) {
            w.in_flight.remove(&strip);
            if w.in_flight.is_empty()
                && let Some(since) = w.busy_since.take()
            {
                w.stats.busy += now.saturating_sub(since);
            }
        }
        Some(flight)
    }

    /// Lands every copy `worker` holds; returns those strips in order.
    fn withdraw_all(&mut self, worker: WorkerId, now: Duration) -> Vec<StripId> {
        let strips = self.in_flight(worker);
        for &strip in &strips {
            self.land(strip, worker, now);
        }
        strips
    }

    /// Puts back at the front of the queue those strips that are running with no copy left.
    fn requeue_front(&mut self, strips: &[StripId]) {
        for &strip in strips {
            if self.strips[strip.0 as usize].state == StripState::Running && self.copies(strip).next().is_none() {
                self.strips[strip.0 as usize].state = StripState::Pending;
                self.retry.insert(strip);
            }
        }
    }

    /// Expected latency of the copy from the worker's measured speed, else the fleet's scaled by cores.
    fn deadline_of(&self, strip: StripId, worker: WorkerId, flight: &Flight) -> Duration {
        let rows = self.strips[strip.0 as usize].rows.len() as f64;
        let allowance = match self.expected_seconds_per_row(worker) {
            Some(spr) => Duration::try_from_secs_f64(self.policy.deadline_factor * rows * spr)
                .unwrap_or(Duration::MAX)
                .max(self.policy.deadline_floor),
            None => self.policy.first_deadline,
        };
        flight.start.saturating_add(allowance)
    }

    fn expected_seconds_per_row(&self, worker: WorkerId) -> Option<f64> {
        let w = self.workers.get(&worker)?;
        if w.seconds_per_row.is_some() {
            return w.seconds_per_row;
        }
        // Core-seconds per row, averaged over the workers that have measured theirs.
        let (sum, n) = self
            .workers
            .values()
            .filter_map(|o| o.seconds_per_row.map(|spr| spr * f64::from(o.stats.cores.max(1))))
            .fold((0.0, 0u32), |(sum, n), cs| (sum + cs, n + 1));
        (n > 0).then(|| sum / f64::from(n) / f64::from(w.stats.cores.max(1)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const W0: WorkerId = WorkerId(0);
    const W1: WorkerId = WorkerId(1);
    const W2: WorkerId = WorkerId(2);

    fn secs(s: f64) -> Duration {
        Duration::from_secs_f64(s)
    }

    fn is_accepted(c: &Completion) -> bool {
        matches!(c, Completion::Accepted { .. })
    }

    /// A tiny portable generator (splitmix64) so the random tests replay exactly.
    struct SplitMix64(u64);

    impl SplitMix64 {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    #[test]
    fn strips_cover_every_row_once() {
        let s = Scheduler::new(10, 4);
        let rows: Vec<_> = (0..3).map(|i| s.strip_rows(StripId(i)).unwrap()).collect();
        assert_eq!(rows, vec![0..4, 4..8, 8..10]);
        assert_eq!(s.strip_rows(StripId(3)), None);
        assert_eq!(Scheduler::new(5, 0).strip_count(), 5);
        let empty = Scheduler::new(0, 8);
        assert!(empty.is_done());
        assert_eq!(empty.progress(), (0, 0));
    }

    #[test]
    fn rows_per_strip_gives_many_more_strips_than_workers() {
        for (height, workers) in [(1080, 1), (1080, 8), (2160, 52), (100, 4), (7, 3)] {
            let rows = rows_per_strip_for(height, workers);
            assert!((1..=64).contains(&rows));
            let strips = height.div_ceil(rows);
            assert!(strips >= (8 * workers).min(height), "{height} rows over {workers} workers: {strips} strips");
        }
        assert_eq!(rows_per_strip_for(1080, 0), rows_per_strip_for(1080, 1));
    }

    #[test]
    fn pulls_serve_pending_strips_in_order_up_to_the_in_flight_limit() {
        let mut s = Scheduler::new(40, 4);
        assert!(s.add_worker(W0, 8));
        assert!(s.add_worker(W1, 8));
        assert!(!s.add_worker(W1, 4), "an id is registered once");
        let t = Duration::ZERO;
        let a = s.assign(W0, t).unwrap();
        assert_eq!((a.strip, a.rows.clone(), a.attempt, a.speculative), (StripId(0), 0..4, 1, false));
        assert_eq!(s.assign(W1, t).unwrap().strip, StripId(1));
        assert_eq!(s.assign(W0, t).unwrap().strip, StripId(2));
        assert_eq!(s.assign(W0, t), None, "two in flight is the limit");
        assert_eq!(s.assign(WorkerId(9), t), None, "unknown worker");
        assert!(is_accepted(&s.complete(W0, StripId(0), 1, secs(1.0))));
        assert_eq!(s.assign(W0, secs(1.0)).unwrap().strip, StripId(3), "a freed slot pulls the next strip");
        assert_eq!(s.in_flight(W0), vec![StripId(2), StripId(3)]);
    }

    /// A discrete-event simulation: each worker renders its strips one after the other at `seconds_per_row`,
    /// results arrive at their finish times on a fake clock, and every free slot pulls after every event.
    struct Sim {
        sched: Scheduler,
        clock: Duration,
        speed: BTreeMap<WorkerId, f64>,
        free_at: BTreeMap<WorkerId, Duration>,
        events: BTreeMap<(Duration, u64), (WorkerId, Assignment)>,
        seq: u64,
        accepted: Vec<u32>,
        duplicates: u32,
    }

    impl Sim {
        fn new(sched: Scheduler, workers: &[(WorkerId, u32, f64)]) -> Self {
            let mut sim = Sim {
                accepted: vec![0; sched.strip_count()],
                sched,
                clock: Duration::ZERO,
                speed: BTreeMap::new(),
                free_at: BTreeMap::new(),
                events: BTreeMap::new(),
                seq: 0,
                duplicates: 0,
            };
            for &(id, cores, seconds_per_row) in workers {
                assert!(sim.sched.add_worker(id, cores));
                sim.speed.insert(id, seconds_per_row);
                sim.free_at.insert(id, Duration::ZERO);
            }
            sim
        }

        fn fill(&mut self) {
            let ids: Vec<WorkerId> = self.speed.keys().copied().collect();
            for w in ids {
                while let Some(a) = self.sched.assign(w, self.clock) {
                    let start = self.free_at[&w].max(self.clock);
                    let finish = start + secs(self.speed[&w] * a.rows.len() as f64);
                    self.free_at.insert(w, finish);
                    self.events.insert((finish, self.seq), (w, a));
                    self.seq += 1;
                }
            }
        }

        fn run(&mut self) {
            self.fill();
            while let Some(((t, _), (w, a))) = self.events.pop_first() {
                self.clock = t;
                assert!(self.sched.expired(t).is_empty(), "no deadline should pass in a healthy run");
                match self.sched.complete(w, a.strip, a.attempt, t) {
                    Completion::Accepted { .. } => self.accepted[a.strip.0 as usize] += 1,
                    Completion::Duplicate => self.duplicates += 1,
                    Completion::Unknown => panic!("{w} {a:?}: no assignment was withdrawn"),
                }
                self.fill();
            }
        }
    }

    #[test]
    fn simulated_workers_complete_every_strip_once_and_faster_ones_take_more() {
        // Worker 0 is 4× faster than worker 1; worker 2 sits in between.
        let workers = [(W0, 16, 0.025), (W1, 4, 0.1), (W2, 8, 0.05)];
        let mut sim = Sim::new(Scheduler::new(480, 4), &workers);
        sim.run();
        assert!(sim.sched.is_done());
        assert_eq!(sim.sched.progress(), (120, 120));
        assert!(sim.accepted.iter().all(|&n| n == 1), "{:?}", sim.accepted);
        assert_eq!(sim.sched.done_strips().len(), 120);
        let strips = |w| sim.sched.worker_stats(w).unwrap().strips;
        let (fast, mid, slow) = (strips(W0), strips(W2), strips(W1));
        assert_eq!(fast + mid + slow, 120);
        assert!(fast >= 3 * slow, "fast {fast}, slow {slow}");
        assert!(fast > mid && mid > slow, "{fast} {mid} {slow}");
        eprintln!("strips taken: 4x {fast}, 2x {mid}, 1x {slow}; {} duplicates", sim.duplicates);
        let stats = sim.sched.worker_stats(W0).unwrap();
        assert_eq!(stats.rows, u64::from(fast) * 4);
        assert!(stats.busy > Duration::ZERO && stats.busy <= sim.clock);
        // The measured latency per row includes the wait behind the other in-flight strip: about 2× the speed.
        let spr = sim.sched.seconds_per_row(W0).unwrap();
        assert!((0.025..=0.06).contains(&spr), "{spr}");
    }

    #[test]
    fn a_single_worker_sees_no_speculation_and_no_duplicates() {
        let mut sim = Sim::new(Scheduler::new(64, 4), &[(W0, 4, 0.1)]);
        sim.run();
        assert_eq!(sim.duplicates, 0);
        assert_eq!(sim.sched.worker_stats(W0).unwrap().speculative, 0);
        assert_eq!(sim.sched.worker_stats(W0).unwrap().strips, 16);
        assert!(sim.accepted.iter().all(|&n| n == 1));
    }

    #[test]
    fn a_lost_workers_strips_requeue_at_the_front_and_complete_elsewhere() {
        let mut s = Scheduler::new(40, 4);
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        let t0 = Duration::ZERO;
        let a0 = s.assign(W0, t0).unwrap();
        let a1 = s.assign(W0, t0).unwrap();
        let b0 = s.assign(W1, t0).unwrap();
        assert_eq!((a0.strip, a1.strip, b0.strip), (StripId(0), StripId(1), StripId(2)));
        assert_eq!(s.worker_lost(W0, secs(2.0)), vec![StripId(0), StripId(1)]);
        assert_eq!(s.worker_lost(W0, secs(2.0)), vec![], "lost once");
        assert_eq!(s.pending_strips()[..3], [StripId(0), StripId(1), StripId(3)]);
        assert_eq!(s.assign(W0, secs(2.0)), None, "a lost worker takes nothing");
        assert_eq!(s.worker_stats(W0).unwrap().state, WorkerState::Lost);
        assert_eq!(s.worker_stats(W0).unwrap().busy, secs(2.0));
        assert!(is_accepted(&s.complete(W1, b0.strip, b0.attempt, secs(3.0))));
        let r = s.assign(W1, secs(3.0)).unwrap();
        assert_eq!((r.strip, r.attempt), (StripId(0), 2), "the requeued strip comes first, as a new attempt");
        // The lost worker's late result is not accepted while the re-issue runs...
        assert_eq!(s.complete(W0, a0.strip, a0.attempt, secs(3.5)), Completion::Unknown);
        assert!(is_accepted(&s.complete(W1, r.strip, r.attempt, secs(4.0))));
        // ...and is a duplicate once the strip is done.
        assert_eq!(s.complete(W0, a0.strip, a0.attempt, secs(4.5)), Completion::Duplicate);
        let mut t = 5.0;
        while let Some(a) = s.assign(W1, secs(t)) {
            assert!(is_accepted(&s.complete(W1, a.strip, a.attempt, secs(t + 0.5))));
            t += 1.0;
        }
        assert!(s.is_done());
        assert_eq!(s.worker_stats(W1).unwrap().strips, 10);
        assert_eq!(s.worker_stats(W0).unwrap().strips, 0);
        assert_eq!(s.worker_stats(W0).unwrap().duplicates, 1);
    }

    #[test]
    fn late_results_after_a_timeout_are_never_counted_twice() {
        let mut s = Scheduler::new(8, 4);
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        let a = s.assign(W0, Duration::ZERO).unwrap();
        let f = StripFailure::timed_out(secs(700.0), secs(600.0));
        assert_eq!(s.failed(W0, a.strip, f.clone(), secs(700.0)), FailureOutcome::Retrying);
        assert_eq!(s.failed(W0, a.strip, f, secs(700.0)), FailureOutcome::Ignored, "reported once");
        // The same worker may pull the strip again: the old attempt still does not match.
        let again = s.assign(W0, secs(700.0)).unwrap();
        assert_eq!((again.strip, again.attempt), (a.strip, 2));
        assert_eq!(s.complete(W0, a.strip, a.attempt, secs(701.0)), Completion::Unknown);
        assert!(is_accepted(&s.complete(W0, again.strip, again.attempt, secs(702.0))));
        assert_eq!(s.complete(W0, again.strip, again.attempt, secs(703.0)), Completion::Duplicate);
        assert_eq!(s.complete(W0, StripId(99), 1, secs(703.0)), Completion::Unknown);
        assert_eq!(s.progress(), (1, 2));
        assert_eq!(s.worker_stats(W0).unwrap().strips, 1);
    }

    #[test]
    fn tail_speculation_copies_the_oldest_strip_and_the_first_result_wins() {
        let mut s = Scheduler::new(12, 4);
        for w in [W0, W1, W2] {
            s.add_worker(w, 4);
        }
        let a0 = s.assign(W0, secs(0.0)).unwrap();
        let a1 = s.assign(W0, secs(1.0)).unwrap();
        let b = s.assign(W1, secs(2.0)).unwrap();
        assert!(!a0.speculative && !a1.speculative && !b.speculative);
        // The queue is empty: W1's free slot takes a copy of the oldest outstanding strip it does not hold.
        let spec = s.assign(W1, secs(3.0)).unwrap();
        assert_eq!((spec.strip, spec.attempt, spec.speculative), (StripId(0), 2, true));
        // W2 cannot take strip 0 (two copies in flight): it gets the next oldest, strip 1.
        let spec2 = s.assign(W2, secs(3.0)).unwrap();
        assert_eq!(spec2.strip, StripId(1));
        let spec3 = s.assign(W2, secs(3.0)).unwrap();
        assert_eq!(spec3.strip, StripId(2), "strip 2 has one copy, on W1");
        assert_eq!(s.assign(WorkerId(7), secs(3.0)), None);
        // The copy finishes first and wins; the original is cancelled and its late result is a duplicate.
        assert_eq!(
            s.complete(W1, spec.strip, spec.attempt, secs(4.0)),
            Completion::Accepted { cancel: vec![(W0, StripId(0))] }
        );
        assert_eq!(s.in_flight(W0), vec![StripId(1)]);
        assert_eq!(s.complete(W0, a0.strip, a0.attempt, secs(5.0)), Completion::Duplicate);
        assert!(is_accepted(&s.complete(W0, a1.strip, a1.attempt, secs(5.0))));
        assert_eq!(s.complete(W2, spec2.strip, spec2.attempt, secs(6.0)), Completion::Duplicate);
        assert!(is_accepted(&s.complete(W1, b.strip, b.attempt, secs(6.0))));
        assert_eq!(s.complete(W2, spec3.strip, spec3.attempt, secs(6.0)), Completion::Duplicate);
        assert!(s.is_done());
        assert_eq!(s.assign(W0, secs(7.0)), None, "nothing left to copy");
        let total: u32 = s.workers().map(|(_, st)| st.strips).sum();
        assert_eq!(total, 3);
        assert_eq!(s.worker_stats(W2).unwrap().speculative, 2);
        assert_eq!(s.worker_stats(W2).unwrap().duplicates, 2);
    }

    #[test]
    fn speculation_can_be_disabled() {
        let policy = Policy { max_copies: 1, ..Policy::default() };
        let mut s = Scheduler::with_policy(4, 4, policy);
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        assert!(s.assign(W0, Duration::ZERO).is_some());
        assert_eq!(s.assign(W1, Duration::ZERO), None);
    }

    #[test]
    fn a_failed_copy_leaves_the_other_copy_running_without_requeueing() {
        let mut s = Scheduler::new(4, 4);
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        let a = s.assign(W0, secs(0.0)).unwrap();
        let b = s.assign(W1, secs(1.0)).unwrap();
        assert!(b.speculative);
        assert_eq!(s.failed(W1, b.strip, StripFailure::transient("reset"), secs(2.0)), FailureOutcome::Retrying);
        assert!(s.pending_strips().is_empty(), "the original still runs");
        assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(3.0))));
        assert!(s.is_done());
    }

    #[test]
    fn repeated_counted_failures_drop_the_worker_and_requeue_its_strips() {
        let mut s = Scheduler::new(40, 4);
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        let mut t = 0.0;
        for n in 1..=2 {
            let a = s.assign(W0, secs(t)).unwrap();
            let out = s.failed(W0, a.strip, StripFailure::counted(format!("crash {n}")), secs(t + 1.0));
            assert_eq!(out, FailureOutcome::Retrying);
            assert_eq!(s.pending_strips()[0], a.strip, "requeued at the front");
            t += 2.0;
        }
        let a = s.assign(W0, secs(t)).unwrap();
        let other = s.assign(W0, secs(t)).unwrap();
        assert_eq!((a.strip, a.attempt, other.strip), (StripId(0), 3, StripId(1)));
        match s.failed(W0, a.strip, StripFailure::counted("crash 3"), secs(t + 1.0)) {
            FailureOutcome::WorkerDropped { reason, cancel } => {
                assert!(reason.contains("3 counted failures") && reason.contains("crash 3"), "{reason}");
                assert_eq!(cancel, vec![StripId(1)]);
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(s.worker_stats(W0).unwrap().state, WorkerState::Dropped(_)));
        assert_eq!(s.worker_stats(W0).unwrap().counted_failures, 3);
        assert_eq!(s.pending_strips()[..3], [StripId(0), StripId(1), StripId(2)]);
        assert_eq!(s.assign(W0, secs(t + 1.0)), None);
        assert_eq!(s.complete(W0, other.strip, other.attempt, secs(t + 2.0)), Completion::Unknown);
        assert!(!s.all_workers_gone());
        let mut now = t + 2.0;
        while let Some(a) = s.assign(W1, secs(now)) {
            assert!(is_accepted(&s.complete(W1, a.strip, a.attempt, secs(now + 0.5))));
            now += 1.0;
        }
        assert!(s.is_done());
    }

    #[test]
    fn uncounted_failures_do_not_count_toward_the_limit() {
        let mut s = Scheduler::new(8, 4);
        s.add_worker(W0, 4);
        for i in 0..10 {
            let a = s.assign(W0, secs(f64::from(i))).unwrap();
            let out = s.failed(W0, a.strip, StripFailure::transient("connection reset"), secs(f64::from(i) + 0.5));
            assert_eq!(out, FailureOutcome::Retrying);
        }
        let stats = s.worker_stats(W0).unwrap();
        assert_eq!((stats.failures, stats.counted_failures, stats.state.clone()), (10, 0, WorkerState::Active));
        let a = s.assign(W0, secs(20.0)).unwrap();
        assert_eq!(a.attempt, 11);
        assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(21.0))));
    }

    #[test]
    fn a_fatal_failure_stops_the_render() {
        let mut s = Scheduler::new(8, 4);
        s.add_worker(W0, 4);
        let a = s.assign(W0, Duration::ZERO).unwrap();
        assert_eq!(s.failed(W0, a.strip, StripFailure::fatal("bad scene"), secs(1.0)), FailureOutcome::Fatal);
        assert_eq!(s.fatal().map(|(strip, f)| (*strip, f.reason.as_str())), Some((StripId(0), "bad scene")));
        assert_eq!(s.assign(W0, secs(1.0)), None);
        assert!(!s.is_done());
    }

    #[test]
    fn when_all_workers_are_gone_the_remaining_strips_stay_pending() {
        let mut s = Scheduler::new(20, 4);
        assert!(s.all_workers_gone(), "no worker yet");
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        let a = s.assign(W0, Duration::ZERO).unwrap();
        s.assign(W1, Duration::ZERO).unwrap();
        assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(1.0))));
        s.worker_lost(W0, secs(2.0));
        assert!(!s.all_workers_gone());
        s.worker_lost(W1, secs(2.0));
        assert!(s.all_workers_gone());
        assert_eq!(s.done_strips(), vec![StripId(0)]);
        assert_eq!(s.pending_strips(), (1..5).map(StripId).collect::<Vec<_>>());
        assert_eq!(s.progress(), (1, 5));
    }

    #[test]
    fn a_stalled_worker_is_reported_past_its_deadline() {
        let policy = Policy { deadline_floor: secs(1.0), first_deadline: secs(100.0), ..Policy::default() };
        let mut s = Scheduler::with_policy(40, 4, policy);
        s.add_worker(W0, 4);
        s.add_worker(W1, 8);
        // Nothing measured yet: the first deadline applies.
        let a = s.assign(W0, Duration::ZERO).unwrap();
        assert_eq!(s.deadline(W0, a.strip), Some(secs(100.0)));
        assert!(s.expired(secs(100.0)).is_empty());
        assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(2.0))));
        // W0 measured 0.5 s per row: a 4-row strip is due after max(4 × 2 s, 1 s) = 8 s.
        assert_eq!(s.seconds_per_row(W0), Some(0.5));
        let b = s.assign(W0, secs(10.0)).unwrap();
        assert_eq!(s.deadline(W0, b.strip), Some(secs(18.0)));
        // W1 has measured nothing: it borrows W0's core-seconds per row, halved for its 8 cores.
        let c = s.assign(W1, secs(10.0)).unwrap();
        assert_eq!(s.deadline(W1, c.strip), Some(secs(14.0)));
        assert_eq!(s.next_deadline(), Some(secs(14.0)));
        assert!(s.expired(secs(14.0)).is_empty());
        assert_eq!(s.expired(secs(15.0)), vec![(W1, c.strip)]);
        assert_eq!(s.expired(secs(19.0)), vec![(W0, b.strip), (W1, c.strip)]);
        // The caller cancels and reports: the strips requeue at the front in order.
        for (w, strip) in s.expired(secs(19.0)) {
            let f = StripFailure::timed_out(secs(9.0), secs(8.0));
            assert_eq!(s.failed(w, strip, f, secs(19.0)), FailureOutcome::Retrying);
        }
        assert!(s.expired(secs(1000.0)).is_empty());
        assert_eq!(s.pending_strips()[..2], [b.strip, c.strip]);
        assert_eq!(s.worker_stats(W1).unwrap().counted_failures, 1);
    }

    #[test]
    fn the_speed_estimate_is_a_moving_average() {
        let policy = Policy { speed_smoothing: 0.5, ..Policy::default() };
        let mut s = Scheduler::with_policy(8, 4, policy);
        s.add_worker(W0, 4);
        let a = s.assign(W0, secs(0.0)).unwrap();
        s.complete(W0, a.strip, a.attempt, secs(4.0));
        let b = s.assign(W0, secs(4.0)).unwrap();
        s.complete(W0, b.strip, b.attempt, secs(12.0));
        assert_eq!(s.seconds_per_row(W0), Some(1.5));
        assert_eq!(s.worker_stats(W0).unwrap().busy, secs(12.0));
    }

    #[test]
    fn strips_marked_done_are_never_assigned() {
        let mut s = Scheduler::new(40, 4);
        for i in [0, 3, 4, 9] {
            assert!(s.mark_done(StripId(i)));
        }
        assert!(!s.mark_done(StripId(3)), "already done");
        assert!(!s.mark_done(StripId(10)), "out of range");
        assert_eq!(s.progress(), (4, 10));
        s.add_worker(W0, 4);
        s.add_worker(W1, 4);
        let mut seen = Vec::new();
        let mut t = 0.0;
        loop {
            let mut any = false;
            for w in [W0, W1] {
                if let Some(a) = s.assign(w, secs(t)) {
                    seen.push(a.strip.0);
                    assert!(is_accepted(&s.complete(w, a.strip, a.attempt, secs(t + 1.0))));
                    any = true;
                }
            }
            t += 1.0;
            if !any {
                break;
            }
        }
        assert_eq!(seen, vec![1, 2, 5, 6, 7, 8]);
        assert!(s.is_done());
        assert_eq!(s.done_strips().len(), 10);
    }

    #[test]
    fn marking_a_running_strip_done_turns_its_result_into_a_duplicate() {
        let mut s = Scheduler::new(8, 4);
        s.add_worker(W0, 4);
        let a = s.assign(W0, Duration::ZERO).unwrap();
        assert!(s.mark_done(a.strip));
        assert_eq!(s.complete(W0, a.strip, a.attempt, secs(1.0)), Completion::Duplicate);
        assert!(s.in_flight(W0).is_empty());
        assert_eq!(s.progress(), (1, 2));
    }

    /// Checks that the scheduler's books agree with what the test knows is on the wire, and that no strip is lost.
    fn check_books(s: &Scheduler, outstanding: &[(WorkerId, Assignment)], accepted: &[u32]) {
        let done = accepted.iter().filter(|&&n| n == 1).count();
        assert!(accepted.iter().all(|&n| n <= 1), "a strip was accepted twice");
        assert_eq!(s.progress(), (done, accepted.len()));
        let mut by_worker: BTreeMap<WorkerId, Vec<StripId>> = BTreeMap::new();
        for (w, a) in outstanding {
            by_worker.entry(*w).or_default().push(a.strip);
        }
        for (id, stats) in s.workers() {
            let mut expect = by_worker.remove(&id).unwrap_or_default();
            expect.sort_unstable();
            assert_eq!(s.in_flight(id), expect, "{id}");
            assert!(expect.len() <= s.policy().max_in_flight);
            if stats.state != WorkerState::Active {
                assert!(expect.is_empty());
            }
        }
        assert!(by_worker.is_empty());
        let pending = s.pending_strips();
        for strip in 0..accepted.len() as u32 {
            let strip = StripId(strip);
            let queued = pending.iter().filter(|&&p| p == strip).count();
            let copies = outstanding.iter().filter(|(_, a)| a.strip == strip).count();
            assert!(copies <= s.policy().max_copies);
            if accepted[strip.0 as usize] == 1 {
                assert_eq!((queued, copies), (0, 0), "{strip} is done");
            } else {
                assert!((queued == 1) != (copies > 0), "{strip}: queued {queued} times, {copies} copies in flight");
            }
        }
    }

    #[test]
    fn random_event_orders_accept_every_strip_exactly_once() {
        // How often the interesting paths were taken over all seeds, to show the test reaches them.
        let (mut drops, mut losses, mut expiries, mut late, mut speculative) = (0, 0, 0, 0, 0);
        for seed in 0..200u64 {
            let mut rng = SplitMix64(seed);
            let height = 1 + rng.below(60) as u32;
            let rows = 1 + rng.below(6) as u32;
            let policy = Policy {
                max_in_flight: 1 + rng.below(3),
                max_copies: 1 + rng.below(3),
                max_counted_failures: 1 + rng.below(4) as u32,
                deadline_floor: secs(1.0),
                first_deadline: secs(20.0),
                ..Policy::default()
            };
            let mut s = Scheduler::with_policy(height, rows, policy);
            let mut accepted = vec![0u32; s.strip_count()];
            // What is on the wire, and results that are no longer current (for late replays).
            let mut outstanding: Vec<(WorkerId, Assignment)> = Vec::new();
            let mut stale: Vec<(WorkerId, Assignment)> = Vec::new();
            let mut next_worker = 0u32;
            let mut now = Duration::ZERO;
            let accept = |strip: StripId, accepted: &mut Vec<u32>| {
                accepted[strip.0 as usize] += 1;
                assert_eq!(accepted[strip.0 as usize], 1, "seed {seed}: {strip} accepted twice");
            };
            for _ in 0..400 {
                now += secs(rng.below(1000) as f64 / 1000.0);
                match rng.below(10) {
                    0 if next_worker < 6 => {
                        assert!(s.add_worker(WorkerId(next_worker), 1 + rng.below(16) as u32));
                        next_worker += 1;
                    }
                    1 | 2 => {
                        let w = WorkerId(rng.below(next_worker as usize + 1) as u32);
                        if let Some(a) = s.assign(w, now) {
                            speculative += u32::from(a.speculative);
                            outstanding.push((w, a));
                        }
                    }
                    3 | 4 if !outstanding.is_empty() => {
                        let (w, a) = outstanding.swap_remove(rng.below(outstanding.len()));
                        match s.complete(w, a.strip, a.attempt, now) {
                            Completion::Accepted { cancel } => {
                                accept(a.strip, &mut accepted);
                                for c in cancel {
                                    let i = outstanding.iter().position(|(w, a)| (*w, a.strip) == c).unwrap();
                                    stale.push(outstanding.swap_remove(i));
                                }
                            }
                            other => panic!("seed {seed}: a current assignment was {other:?}"),
                        }
                        stale.push((w, a));
                    }
                    5 if !stale.is_empty() => {
                        let (w, a) = stale[rng.below(stale.len())].clone();
                        let c = s.complete(w, a.strip, a.attempt, now);
                        late += 1;
                        assert!(!is_accepted(&c), "seed {seed}: a stale result {a:?} from {w} was accepted");
                    }
                    6 if !outstanding.is_empty() => {
                        let (w, a) = outstanding.swap_remove(rng.below(outstanding.len()));
                        let failure = if rng.below(2) == 0 {
                            StripFailure::counted("crash")
                        } else {
                            StripFailure::transient("reset")
                        };
                        match s.failed(w, a.strip, failure, now) {
                            FailureOutcome::Retrying => {}
                            FailureOutcome::WorkerDropped { mut cancel, .. } => {
                                drops += 1;
                                let mut theirs: Vec<StripId> =
                                    outstanding.iter().filter(|(o, _)| *o == w).map(|(_, a)| a.strip).collect();
                                theirs.sort_unstable();
                                cancel.sort_unstable();
                                assert_eq!(cancel, theirs, "seed {seed}");
                                stale.extend(outstanding.iter().filter(|(o, _)| *o == w).cloned());
                                outstanding.retain(|(o, _)| *o != w);
                            }
                            other => panic!("seed {seed}: {other:?}"),
                        }
                        stale.push((w, a));
                    }
                    7 if next_worker > 0 && rng.below(4) == 0 => {
                        let w = WorkerId(rng.below(next_worker as usize) as u32);
                        let mut lost = s.worker_lost(w, now);
                        losses += 1;
                        let mut theirs: Vec<StripId> =
                            outstanding.iter().filter(|(o, _)| *o == w).map(|(_, a)| a.strip).collect();
                        theirs.sort_unstable();
                        lost.sort_unstable();
                        assert_eq!(lost, theirs, "seed {seed}");
                        stale.extend(outstanding.iter().filter(|(o, _)| *o == w).cloned());
                        outstanding.retain(|(o, _)| *o != w);
                    }
                    8 => {
                        for (w, strip) in s.expired(now) {
                            let Some(i) = outstanding.iter().position(|(o, a)| (*o, a.strip) == (w, strip)) else {
                                let f = StripFailure::timed_out(now, now);
                                assert_eq!(s.failed(w, strip, f, now), FailureOutcome::Ignored, "seed {seed}");
                                continue;
                            };
                            let (w, a) = outstanding.swap_remove(i);
                            expiries += 1;
                            match s.failed(w, strip, StripFailure::timed_out(now, now), now) {
                                FailureOutcome::Retrying => {}
                                FailureOutcome::WorkerDropped { .. } => {
                                    stale.extend(outstanding.iter().filter(|(o, _)| *o == w).cloned());
                                    outstanding.retain(|(o, _)| *o != w);
                                }
                                other => panic!("seed {seed}: {other:?}"),
                            }
                            stale.push((w, a));
                        }
                    }
                    _ => {}
                }
                check_books(&s, &outstanding, &accepted);
            }
            // Drain: a reliable worker joins and every result is delivered, oldest first.
            assert!(s.add_worker(WorkerId(100), 8));
            let ids: Vec<WorkerId> = s.workers().map(|(id, _)| id).collect();
            while !s.is_done() {
                for &w in &ids {
                    while let Some(a) = s.assign(w, now) {
                        outstanding.push((w, a));
                    }
                }
                assert!(!outstanding.is_empty(), "seed {seed}: strips left but nothing to run");
                now += secs(1.0);
                while !outstanding.is_empty() {
                    let (w, a) = outstanding.remove(0);
                    match s.complete(w, a.strip, a.attempt, now) {
                        Completion::Accepted { cancel } => {
                            accept(a.strip, &mut accepted);
                            outstanding.retain(|(o, b)| !cancel.contains(&(*o, b.strip)));
                        }
                        other => panic!("seed {seed}: {other:?}"),
                    }
                }
                check_books(&s, &outstanding, &accepted);
            }
            assert!(accepted.iter().all(|&n| n == 1), "seed {seed}: {accepted:?}");
            let total: u32 = s.workers().map(|(_, st)| st.strips).sum();
            assert_eq!(total as usize, accepted.len(), "seed {seed}: per-worker counts add up");
            for (w, a) in &stale {
                assert_eq!(s.complete(*w, a.strip, a.attempt, now), Completion::Duplicate, "seed {seed}");
            }
        }
        let counts = [drops, losses, expiries, late, speculative];
        assert!(
            counts.iter().all(|&n| n >= 20),
            "drops, losses, expiries, late results, speculative copies: {counts:?}"
        );
    }
}
