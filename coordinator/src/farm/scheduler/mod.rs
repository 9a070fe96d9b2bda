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
//!   (the same input would fail anywhere) stops the render; a *counted* failure counts against the worker.
//!   Transport hiccups are retryable and not counted.
//! - **Stalls are re-issued before their deadline.** A busy worker silent (no progress, no result) past its
//!   silence limit, a few times its measured time per row, has stalled: each unit it holds is issued again to
//!   the others first, while its own copy keeps running (the first result wins, so a slow worker loses
//!   nothing), and it gets no new unit until it speaks or holds nothing. A cut link, a frozen process or a lost
//!   reply then costs the silence limit, not the deadline.
//! - **A blocklist.** A worker that fails [`Policy::block_after`] units of the job, whatever the cause (counted
//!   failures, units it stalled on, units it held when it was lost), is blocked: it gets no more units of this
//!   job, and is not called back. Each unit is charged once, however many ways it failed.
//! - **A result is accepted only from the assignment that is still current**: a late result from a worker that
//!   was declared lost, blocked or timed out is [`Completion::Unknown`] (or a duplicate, if the strip is done by
//!   then), never counted twice. The strip has already been given to someone else by then.

mod types;

pub use types::*;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::ops::Range;
use std::time::Duration;

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
    /// Its worker fell silent while it ran ([`Scheduler::check_stalls`]) and has not spoken since: the strip is
    /// open to other workers.
    stalled: bool,
    /// It was charged to its worker as a failed unit (once, whatever else befalls it).
    charged: bool,
}

#[derive(Clone, Debug)]
struct Worker {
    stats: WorkerStats,
    in_flight: BTreeSet<StripId>,
    /// Moving average of seconds per row, assignment to result.
    seconds_per_row: Option<f64>,
    /// When its in-flight set last became non-empty.
    busy_since: Option<Duration>,
    /// When it last showed a sign of life (progress or a result).
    heard: Option<Duration>,
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

    /// Appends `units` more rows (passes, for pass blocks) after the last strip, cut into strips of `per_strip`
    /// (0 is taken as 1), served after every strip already queued: the next round of a render bounded by time or
    /// error. Returns the ids of the new strips.
    pub fn extend(&mut self, units: u32, per_strip: u32) -> Range<u32> {
        let step = per_strip.max(1);
        let start = self.strips.last().map_or(0, |s| s.rows.end);
        let end = start.saturating_add(units);
        let first = self.strips.len() as u32;
        let mut y0 = start;
        while y0 < end {
            let y1 = y0.saturating_add(step).min(end);
            self.fresh.push_back(StripId(self.strips.len() as u32));
            self.strips.push(Strip { rows: y0..y1, state: StripState::Pending, issued: 0 });
            y0 = y1;
        }
        first..self.strips.len() as u32
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
            stalled: false,
            rejoins: 0,
        };
        let worker = Worker { stats, in_flight: BTreeSet::new(), seconds_per_row: None, busy_since: None, heard: None };
        self.workers.insert(id, worker);
        true
    }

    /// Takes back a lost worker that answers again (reconnected, and checked as at the start), with the `cores`
    /// it now announces: it is active again, keeps its numbers, and counts one more rejoin. Its speed is measured
    /// afresh (a restarted worker loads the scene again, and may be another machine at the same address).
    /// Returns `false` (and changes nothing) unless the worker is [`WorkerState::Lost`].
    pub fn rejoin(&mut self, id: WorkerId, cores: u32) -> bool {
        match self.workers.get_mut(&id) {
            Some(w) if w.stats.state == WorkerState::Lost => {
                w.stats.state = WorkerState::Active;
                w.stats.cores = cores;
                w.stats.stalled = false;
                w.stats.rejoins += 1;
                w.heard = None;
                w.seconds_per_row = None;
                true
            }
            _ => false,
        }
    }

    /// Records that `worker` showed a sign of life at `now` (progress or a result): it is not stalled, and its
    /// copies in flight count as running again (no more copies of them are issued for the stall).
    pub fn heard_from(&mut self, worker: WorkerId, now: Duration) {
        let Some(w) = self.workers.get_mut(&worker) else { return };
        w.heard = Some(now);
        w.stats.stalled = false;
        for strip in &w.in_flight {
            if let Some(f) = self.flights.get_mut(&(*strip, worker)) {
                f.stalled = false;
            }
        }
    }

    /// How long `worker` may stay silent while it holds strips before it counts as stalled: the deadline of a
    /// one-row strip at its measured speed (not below [`Policy::silence_floor`]), or [`Policy::first_deadline`]
    /// while it has measured nothing (its first strip may include loading the scene).
    pub fn silence_limit(&self, worker: WorkerId) -> Duration {
        match self.seconds_per_row(worker) {
            Some(spr) => Duration::try_from_secs_f64(self.policy.deadline_factor * spr)
                .unwrap_or(Duration::MAX)
                .max(self.policy.silence_floor),
            None => self.policy.first_deadline,
        }
    }

    /// Finds the active workers that hold strips and have said nothing (no progress, no result) for longer than
    /// their [`Scheduler::silence_limit`], counted from when they last spoke or, if later, from when they last
    /// became busy. Each unit such a worker holds is marked stalled, charged to it as a failed unit, and issued
    /// again to the next free worker ([`Scheduler::assign`]) while its copy keeps running; a worker charged
    /// [`Policy::block_after`] units is blocked. Returns them in id order. A worker stays `stalled` until it is
    /// heard from again ([`Scheduler::heard_from`]); a stalled worker that holds nothing more takes units again,
    /// and each is re-issued in turn if it stays silent.
    pub fn check_stalls(&mut self, now: Duration) -> Vec<Stall> {
        let limits: Vec<(WorkerId, Duration)> = self.workers.keys().map(|&id| (id, self.silence_limit(id))).collect();
        let mut stalls = Vec::new();
        for (id, limit) in limits {
            let Some(w) = self.workers.get(&id) else { continue };
            if w.stats.state != WorkerState::Active {
                continue;
            }
            let Some(busy) = w.busy_since else { continue };
            let since = w.heard.map_or(busy, |h| h.max(busy));
            if now.saturating_sub(since) <= limit {
                continue;
            }
            let fresh: Vec<StripId> = w
                .in_flight
                .iter()
                .copied()
                .filter(|&s| self.flights.get(&(s, id)).is_some_and(|f| !f.stalled))
                .collect();
            if fresh.is_empty() {
                continue;
            }
            let newly = !w.stats.stalled;
            let why = format!("stalled: no progress for {:.1} s", now.saturating_sub(since).as_secs_f64());
            let mut blocked = None;
            for &strip in &fresh {
                if let Some(f) = self.flights.get_mut(&(strip, id)) {
                    f.stalled = true;
                }
                blocked = blocked.or(self.charge(id, strip, &why, now));
            }
            if let Some(w) = self.workers.get_mut(&id) {
                w.stats.stalled = true;
            }
            stalls.push(Stall { worker: id, newly, strips: fresh, blocked });
        }
        stalls
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
        // A worker silent on the units it holds gets no more until it speaks.
        if w.in_flight.iter().any(|&s| self.flights.get(&(s, worker)).is_some_and(|f| f.stalled)) {
            return None;
        }
        let (strip, speculative) = match self.stalled_candidate(worker) {
            Some(strip) => (strip, false),
            None => match self.retry.pop_first().or_else(|| self.fresh.pop_front()) {
                Some(strip) => (strip, false),
                None => (self.speculation_candidate(worker)?, true),
            },
        };
        let s = &mut self.strips[strip.0 as usize];
        s.state = StripState::Running;
        s.issued += 1;
        let assignment = Assignment { strip, rows: s.rows.clone(), attempt: s.issued, speculative };
        self.flights.insert((strip, worker), Flight { attempt: s.issued, start: now, stalled: false, charged: false });
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

    /// The lowest running strip whose every copy in flight is stalled, if `worker` does not hold it: a stalled
    /// unit is issued again before anything else, since the image waits for it.
    fn stalled_candidate(&self, worker: WorkerId) -> Option<StripId> {
        let mut all_stalled: BTreeMap<StripId, bool> = BTreeMap::new();
        for (&(strip, w), flight) in &self.flights {
            let entry = all_stalled.entry(strip).or_insert(true);
            *entry &= flight.stalled && w != worker;
        }
        all_stalled
            .into_iter()
            .find(|&(strip, stalled)| stalled && self.strips[strip.0 as usize].state == StripState::Running)
            .map(|(strip, _)| strip)
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
        if self.strips[strip.0 as usize].state == StripState::Done {
            self.land(strip, worker, now);
            return FailureOutcome::Ignored;
        }
        let Some(w) = self.workers.get_mut(&worker) else {
            return FailureOutcome::Ignored;
        };
        w.stats.failures += 1;
        if !failure.retryable {
            self.land(strip, worker, now);
            if self.copies(strip).next().is_none() {
                self.strips[strip.0 as usize].state = StripState::Failed;
            }
            tracing::error!("{worker}: {strip}: {failure}");
            self.fatal.get_or_insert((strip, failure));
            return FailureOutcome::Fatal;
        }
        let blocked = if failure.counted { self.charge(worker, strip, &failure.reason, now) } else { None };
        self.land(strip, worker, now);
        self.requeue_front(&[strip]);
        match blocked {
            Some((reason, withdrawn)) => {
                let cancel = withdrawn.into_iter().filter(|&s| s != strip).collect();
                FailureOutcome::WorkerBlocked { reason, cancel }
            }
            None => FailureOutcome::Retrying,
        }
    }

    /// Charges `worker` with the failed unit `strip` (its copy in flight), once per copy, for `why`; blocks it
    /// when that makes [`Policy::block_after`] failed units. Returns the reason and the strips withdrawn from
    /// it when it was blocked, `strip` included (requeued at the front, as every withdrawn strip is).
    fn charge(&mut self, worker: WorkerId, strip: StripId, why: &str, now: Duration) -> Option<(String, Vec<StripId>)> {
        let flight = self.flights.get_mut(&(strip, worker))?;
        if std::mem::replace(&mut flight.charged, true) {
            return None;
        }
        let w = self.workers.get_mut(&worker)?;
        w.stats.counted_failures += 1;
        let (failed, limit) = (w.stats.counted_failures, self.policy.block_after);
        if failed < limit || w.stats.state != WorkerState::Active {
            return None;
        }
        let reason = format!("{failed} failed units (limit {limit}), the last on {strip}: {why}");
        tracing::warn!("blocking {worker}: {reason}");
        w.stats.state = WorkerState::Blocked(reason.clone());
        let withdrawn = self.withdraw_all(worker, now);
        self.requeue_front(&withdrawn);
        Some((reason, withdrawn))
    }

    /// Reports that `worker`'s connection is gone at time `now`: every strip it held is requeued at the front,
    /// and charged to it as a failed unit (it may be blocked then, instead of lost). Returns those strips. Its
    /// late results will not be accepted.
    pub fn worker_lost(&mut self, worker: WorkerId, now: Duration) -> Vec<StripId> {
        if !self.workers.get(&worker).is_some_and(|w| w.stats.state == WorkerState::Active) {
            return Vec::new();
        }
        let strips = self.in_flight(worker);
        for &strip in &strips {
            if self.strips[strip.0 as usize].state == StripState::Done {
                continue;
            }
            if let Some(w) = self.workers.get_mut(&worker) {
                w.stats.failures += 1;
            }
            if self.charge(worker, strip, "lost while rendering it", now).is_some() {
                return strips;
            }
        }
        if let Some(w) = self.workers.get_mut(&worker) {
            w.stats.state = WorkerState::Lost;
        }
        let strips = self.withdraw_all(worker, now);
        self.requeue_front(&strips);
        strips
    }

    /// Assignments past their deadline at `now`, in (strip, worker) order. The caller cancels each and reports it
    /// with [`Scheduler::failed`] (e.g. [`StripFailure::timed_out`]); until then it is listed again. If a report
    /// blocks the worker, its later entries are already withdrawn and report as [`FailureOutcome::Ignored`].
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

    /// Copies of each strip in flight, in strip order: 0 for a strip that is pending, done or failed, 2 or more
    /// for a strip whose tail copies are running beside the original (what a live view shows as duplicated).
    pub fn copies_in_flight(&self) -> Vec<usize> {
        let mut copies = vec![0; self.strips.len()];
        for &(strip, _) in self.flights.keys() {
            if let Some(c) = copies.get_mut(strip.0 as usize) {
                *c += 1;
            }
        }
        copies
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

    /// Whether no worker is active (none registered, or all lost or blocked): the caller should stop and say so.
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
mod tests;
