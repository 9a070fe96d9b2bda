//! The state of one render and its handlers. Each event the loop receives (a worker ready or refused, a strip's
//! progress or result, the timer, a signal) is one method call that updates the scheduler, the workers and the
//! image. What must then happen outside the state is queued as [`Action`]s: call a worker for a strip, cancel a
//! call, tell the user, call a lost worker back, publish an error estimate. The loop ([`super::render`]) takes
//! them after each step and performs them. Nothing here spawns a task, prints or touches the network, so a test
//! can feed events and read the actions and the image.

use super::bounded::{Rounds, StopReason};
use super::scheduler::{
    Assignment, Completion, FailureOutcome, Scheduler, StripFailure, StripId, WorkerId, WorkerState,
};
use super::types::{FarmError, Options};
use crate::fleet::interrupt::Interrupt;
use crate::fleet::session::{Delivered, StripError, StripResult, WorkerAddr};
use crate::job::Job;
use crate::out::report::Warning;
use photon_core::render::sums::SumAccumulator;
use photon_proto::pb;
use std::collections::BTreeMap;
use std::time::Duration;

/// What a handler decided that the loop must do outside the state, in the order it was decided.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Action {
    /// Call the worker for the strip (or pass block) of the assignment, through its session's client.
    Spawn(WorkerId, Assignment),
    /// Drop the worker's call of the strip if it is still in flight (the worker then stops rendering it).
    Cancel(WorkerId, StripId),
    /// Tell the user, now.
    Warn(Warning),
    /// Call the lost worker back with backoff; it reports ready or refused again.
    CallBack(WorkerId),
    /// A bounded render's round estimated the relative MSE of the image, `elapsed_s` into the render (for the
    /// live page).
    Estimate {
        /// Seconds since the render started.
        elapsed_s: f64,
        /// The estimate.
        rel_mse: f64,
    },
}

/// Why the loop stopped before the image was complete.
#[derive(Debug, PartialEq)]
pub(super) enum Stop {
    /// A failure no retry can fix: the strip and why.
    Fatal(String),
    /// No worker is left, none is still connecting, and none came back within the patience.
    NoWorkers,
    /// A signal asked to stop.
    Interrupted(Interrupt),
}

/// A worker as the loop knows it.
pub(super) struct Member {
    pub(super) addr: WorkerAddr,
    /// Its session is open (it said hello and holds the blobs): it takes strips through the loop's client.
    pub(super) ready: bool,
    pub(super) hello: Option<pb::HelloReply>,
    /// Blob bytes it received, from the coordinator and from other workers.
    pub(super) received: Delivered,
    pub(super) ship_s: f64,
    /// Why it is out, if it is (refused, lost, blocked).
    pub(super) out: Option<String>,
    /// Rows (passes, for pass blocks) finished in strips still in flight (for the progress bar's rate).
    pub(super) rows_live: u64,
    /// Photon paths its accepted results traced, and the seconds it spent tracing them and building their maps.
    pub(super) photon_paths: u64,
    pub(super) photon_s: f64,
    /// Seconds it spent decoding the job's blobs.
    pub(super) load_s: f64,
    /// It was lost and a task is calling it back.
    pub(super) rejoining: bool,
}

impl Member {
    fn new(addr: WorkerAddr) -> Self {
        Self {
            addr,
            ready: false,
            hello: None,
            received: Delivered::default(),
            ship_s: 0.0,
            out: None,
            rows_live: 0,
            photon_paths: 0,
            photon_s: 0.0,
            load_s: 0.0,
            rejoining: false,
        }
    }
}

/// The state of one render, owned by its event loop: the scheduler, the workers and the image so far. Times are
/// durations since the render started, given by the caller.
pub(super) struct Farm<'a> {
    pub(super) job: &'a Job,
    /// Rows per strip, or passes per block.
    pub(super) rows_per_strip: u32,
    pub(super) sched: Scheduler,
    pub(super) members: Vec<Member>,
    /// The fixed-point sums of the units accepted so far (3 per pixel, row-major, of the whole image).
    pub(super) image: SumAccumulator,
    /// Rows of finished strips, or units of finished blocks (first → end), for the partial file.
    pub(super) done_rows: BTreeMap<u32, u32>,
    pub(super) rays: u64,
    pub(super) photon_paths: u64,
    /// When the first worker was ready.
    pub(super) first_ready: Option<Duration>,
    /// Workers whose session has not reported yet.
    pub(super) unresolved: usize,
    pub(super) resumed: usize,
    mixed_math_warned: bool,
    rejoin_patience: Duration,
    /// Since when no worker has been active, while that lasts.
    none_active_since: Option<Duration>,
    /// The signal that asked to stop, once one has.
    interrupted: Option<Interrupt>,
    /// A render bounded by time or error: its rounds (the round in flight's sums join `image` when it is
    /// complete) and why it stopped.
    pub(super) rounds: Option<Rounds>,
    /// What the loop must do, in order, since it last took them.
    actions: Vec<Action>,
}

impl<'a> Farm<'a> {
    /// The state before any worker answered, with the units of `options.resume` done.
    pub(super) fn new(job: &'a Job, workers: &[WorkerAddr], options: &Options) -> Result<Self, FarmError> {
        let n = workers.len() as u32;
        let pixels = 3 * job.width as usize * job.height as usize;
        // A bounded render starts with its first round; the others with the whole job.
        let mut rounds = options.bound.clone().map(|b| Rounds::new(b, pixels));
        let first = rounds.as_mut().map(|r| r.first(workers.len()));
        let rows_per_strip = match (&options.resume, options.rows_per_strip, job.passes, first) {
            (_, _, _, Some(plan)) => plan.per_block,
            (Some(p), _, _, _) => p.rows_per_strip,
            (None, Some(r), _, _) => r,
            (None, None, Some(passes), _) => super::scheduler::passes_per_block_for(passes, n),
            (None, None, None, _) => super::scheduler::rows_per_strip_for(job.height, n),
        };
        // The scheduler cuts one axis: the units of whole-image blocks (the methods that render in passes, and a
        // bounded render), or the rows of strips that each take every unit of the job.
        let (axis, image) = match (job.passes, first) {
            (Some(_), Some(plan)) => (plan.passes, SumAccumulator::new(pixels, 1)),
            (Some(p), None) => (p, SumAccumulator::new(pixels, p)),
            (None, _) => (job.height, SumAccumulator::new(pixels, job.units)),
        };
        let mut farm = Self {
            job,
            rows_per_strip,
            sched: Scheduler::with_policy(axis, rows_per_strip, options.policy.clone()),
            members: workers.iter().cloned().map(Member::new).collect(),
            image,
            done_rows: BTreeMap::new(),
            rays: 0,
            photon_paths: 0,
            first_ready: None,
            unresolved: workers.len(),
            resumed: 0,
            mixed_math_warned: false,
            rejoin_patience: options.rejoin_patience,
            none_active_since: None,
            interrupted: None,
            rounds,
            actions: Vec::new(),
        };
        if let Some(p) = &options.resume {
            farm.resume(p)?;
        }
        Ok(farm)
    }

    /// Goes on from an earlier bounded render of this job ([`Options::continuation`], taken out of the options by
    /// `render`, so that its image is moved, not copied) under `bound`: its
    /// rounds' blocks are cut again as they were (each keeps its index, and with it its half of the error
    /// estimate) and marked done, its sums are the image, and the next round is queued after them.
    pub(super) fn continue_from(
        &mut self,
        c: super::bounded::Continuation,
        bound: crate::farm::bounded::Bound,
        policy: &super::scheduler::Policy,
        workers: usize,
    ) -> Result<(), FarmError> {
        let super::bounded::Continuation { mut rounds, image } = c;
        let plans = rounds.plans().to_vec();
        let fits = image.sums().len() == self.image.sums().len() && self.job.passes.is_some();
        let Some((first, rest)) = plans.split_first().filter(|_| fits) else {
            return Err(FarmError::Resume("the render to continue has no completed round of this job".into()));
        };
        let mut sched = Scheduler::with_policy(first.passes, first.per_block, policy.clone());
        for plan in rest {
            sched.extend(plan.passes, plan.per_block);
        }
        for id in 0..sched.strip_count() as u32 {
            sched.mark_done(super::scheduler::StripId(id));
        }
        rounds.continue_with(bound);
        if let Ok(plan) = rounds.next(workers) {
            sched.extend(plan.passes, plan.per_block);
        }
        self.rows_per_strip = first.per_block;
        self.sched = sched;
        self.image = image;
        self.rounds = Some(rounds);
        Ok(())
    }

    /// The actions decided since the last call, in order.
    pub(super) fn take_actions(&mut self) -> Vec<Action> {
        std::mem::take(&mut self.actions)
    }

    /// How the render ended at `now`, once it has.
    pub(super) fn end(&mut self, now: Duration) -> Option<Result<(), Stop>> {
        if self.sched.is_done() {
            // A continued render may find no round to start (its deadline passed during the pilots).
            return match self.rounds.as_ref().map(Rounds::is_stopped) {
                Some(false) => self.next_round(now),
                Some(true) | None => Some(Ok(())),
            };
        }
        if let Some((strip, failure)) = self.sched.fatal() {
            return Some(Err(Stop::Fatal(format!("{strip}: {}", failure.reason))));
        }
        // A bounded render well past its deadline stops with its finished rounds; the round in flight is dropped.
        if let Some(rounds) = self.rounds.as_mut().filter(|r| r.completed() > 0 && r.overdue()) {
            rounds.stop(StopReason::Time);
            return Some(Ok(()));
        }
        if let Some(signal) = self.interrupted {
            return Some(self.keep_rounds(StopReason::Interrupted, Stop::Interrupted(signal)));
        }
        if !(self.unresolved == 0 && self.sched.all_workers_gone()) {
            self.none_active_since = None;
            return None;
        }
        let since = *self.none_active_since.get_or_insert(now);
        let waiting = self.members.iter().any(|m| m.rejoining);
        (!waiting || now.saturating_sub(since) >= self.rejoin_patience)
            .then(|| self.keep_rounds(StopReason::NoWorkers, Stop::NoWorkers))
    }

    /// A bounded render whose round is complete: its sums join the image, and the next round is queued, or the
    /// render ends.
    fn next_round(&mut self, now: Duration) -> Option<Result<(), Stop>> {
        let Some(rounds) = self.rounds.as_mut() else { return Some(Ok(())) };
        let estimate = rounds.end_round(&mut self.image);
        tracing::info!(passes = rounds.passes(), rounds = rounds.completed(), ?estimate, "round complete");
        if let Some(rel_mse) = estimate {
            self.actions.push(Action::Estimate { elapsed_s: now.as_secs_f64(), rel_mse });
        }
        let active = self.sched.workers().filter(|(_, s)| s.state == WorkerState::Active).count();
        match rounds.next(active) {
            Ok(plan) => {
                self.sched.extend(plan.passes, plan.per_block);
                None
            }
            Err(_) => Some(Ok(())),
        }
    }

    /// How a render that must stop for `reason` ends: a bounded one with a complete round keeps its rounds;
    /// the others fail with `stop`.
    fn keep_rounds(&mut self, reason: StopReason, stop: Stop) -> Result<(), Stop> {
        match self.rounds.as_mut().filter(|r| r.completed() > 0) {
            Some(rounds) => {
                rounds.stop(reason);
                Ok(())
            }
            None => Err(stop),
        }
    }

    /// A signal asked the render to stop.
    pub(super) fn interrupt(&mut self, signal: Interrupt) {
        self.interrupted = Some(signal);
    }

    /// The session of `worker` is open: it said `hello` and received `delivered` in `ship_s` seconds.
    pub(super) fn on_ready(
        &mut self,
        worker: WorkerId,
        hello: pb::HelloReply,
        delivered: Delivered,
        ship_s: f64,
        now: Duration,
    ) {
        if std::mem::take(&mut self.members[worker.0 as usize].rejoining) {
            return self.on_rejoined(worker, hello, delivered);
        }
        self.unresolved -= 1;
        if self.first_ready.is_none() {
            self.first_ready = Some(now);
            // A bounded render's first round is timed from here, not from the connections and uploads.
            if let Some(rounds) = &mut self.rounds {
                rounds.restart_round_clock();
            }
        }
        let other_mode = self.members.iter().find_map(|o| {
            o.hello.as_ref().filter(|h| h.math_mode != hello.math_mode).map(|h| (&o.addr.name, &h.math_mode))
        });
        if let (Some((other, other_mode)), false) = (other_mode, self.mixed_math_warned) {
            self.actions.push(Action::Warn(Warning::MixedMath {
                worker: self.members[worker.0 as usize].addr.name.clone(),
                mode: hello.math_mode.clone(),
                other: other.clone(),
                other_mode: other_mode.clone(),
            }));
            self.mixed_math_warned = true;
        }
        let m = &mut self.members[worker.0 as usize];
        tracing::info!(
            worker = %m.addr.name, arch = %hello.arch, math = %hello.math_mode, threads = hello.threads,
            shipped = delivered.shipped, fetched = delivered.fetched, ship_s, "ready"
        );
        self.sched.add_worker(worker, hello.threads);
        (m.ready, m.hello, m.received, m.ship_s) = (true, Some(hello), delivered, ship_s);
    }

    /// A lost worker that answered again, with the same build: it takes strips again.
    fn on_rejoined(&mut self, worker: WorkerId, hello: pb::HelloReply, delivered: Delivered) {
        let m = &mut self.members[worker.0 as usize];
        tracing::info!(worker = %m.addr.name, threads = hello.threads, ?delivered, "rejoined");
        if self.sched.rejoin(worker, hello.threads) {
            let shipped = delivered.shipped + delivered.fetched;
            self.actions.push(Action::Warn(Warning::Rejoined { worker: m.addr.name.clone(), shipped }));
            m.received += delivered;
            (m.ready, m.hello, m.out) = (true, Some(hello), None);
        }
    }

    /// The session of `worker` failed (at the start, or when it was called back): it is out for `reason`.
    pub(super) fn on_refused(&mut self, worker: WorkerId, reason: String) {
        let m = &mut self.members[worker.0 as usize];
        if std::mem::take(&mut m.rejoining) {
            let reason = format!("lost, then refused: {reason}");
            self.actions.push(Action::Warn(Warning::Refused { worker: m.addr.name.clone(), reason: reason.clone() }));
            m.out = Some(reason);
            return;
        }
        self.unresolved -= 1;
        self.actions.push(Action::Warn(Warning::Refused { worker: m.addr.name.clone(), reason: reason.clone() }));
        m.out = Some(reason);
    }

    /// `worker` finished `rows` rows (or passes) of a strip still in flight.
    pub(super) fn on_progress(&mut self, worker: WorkerId, rows: u32, now: Duration) {
        self.sched.heard_from(worker, now);
        self.members[worker.0 as usize].rows_live = u64::from(rows);
    }

    /// The call of `strip` (its issue `attempt`) on `worker` ended with `result`.
    pub(super) fn on_strip(
        &mut self,
        worker: WorkerId,
        strip: StripId,
        attempt: u32,
        result: Result<StripResult, StripError>,
        now: Duration,
    ) {
        self.members[worker.0 as usize].rows_live = 0;
        if !result.as_ref().is_err_and(StripError::lost) {
            self.sched.heard_from(worker, now);
        }
        match result {
            Ok(result) => self.on_result(worker, strip, attempt, result, now),
            Err(e) if e.lost() => self.on_lost(worker, e.to_string(), now),
            Err(e) => {
                let failure = e.failure();
                tracing::warn!("{}: {strip}: {failure}", self.members[worker.0 as usize].addr.name);
                self.on_failure(worker, strip, failure, now);
            }
        }
    }

    /// A valid strip or pass block: the first copy wins and the others are cancelled.
    fn on_result(&mut self, worker: WorkerId, strip: StripId, attempt: u32, result: StripResult, now: Duration) {
        let StripResult { sums, summary } = result;
        // Maps a worker traced for itself count whichever copy of a strip reports them (the worker traced them
        // once, for the job); a pass block's photons count only when the block is accepted, so that their total
        // is the job's.
        let completion = self.sched.complete(worker, strip, attempt, now);
        let accepted = matches!(completion, Completion::Accepted { .. });
        let m = &mut self.members[worker.0 as usize];
        m.load_s += summary.load_seconds;
        if self.job.trace_photons || accepted {
            m.photon_paths += summary.photon_paths;
            m.photon_s += summary.photon_seconds;
            self.photon_paths += summary.photon_paths;
        }
        if let Completion::Accepted { cancel } = completion {
            tracing::info!(worker = %m.addr.name, %strip, "accepted");
            if let (Some(rounds), Some(range)) = (self.rounds.as_mut(), self.sched.strip_rows(strip)) {
                rounds.add_block_time(range.len() as u32, summary.render_seconds);
            }
            self.accept(strip, sums, summary.rays, cancel);
        }
    }

    /// Adds the sums of an accepted strip or block (which traced `rays`) to the image, and cancels its other
    /// copies. A strip's sums land at its first row; a whole-image block's at the first pixel, or in its round.
    fn accept(&mut self, strip: StripId, sums: Vec<i64>, rays: u64, cancel: Vec<(WorkerId, StripId)>) {
        if let Some(range) = self.sched.strip_rows(strip) {
            match (&mut self.rounds, self.job.passes) {
                (Some(rounds), _) => rounds.add_block(strip.0, range.len() as u32, &sums),
                (None, Some(_)) => self.image.add(&sums),
                (None, None) => self.image.add_at(3 * self.job.width as usize * range.start as usize, &sums),
            }
            self.done_rows.insert(range.start, range.end);
        }
        self.rays += rays;
        self.cancel(cancel);
    }

    /// A worker that cannot be reached: its strips go to the others, and it is called back with backoff, unless
    /// the units it lost blocked it.
    fn on_lost(&mut self, worker: WorkerId, reason: String, now: Duration) {
        if self.sched.worker_stats(worker).is_some_and(|s| s.state == WorkerState::Active) {
            let name = self.members[worker.0 as usize].addr.name.clone();
            self.actions.push(Action::Warn(Warning::Lost { worker: name, reason: reason.clone() }));
        }
        let strips = self.sched.worker_lost(worker, now);
        self.cancel(strips.into_iter().map(|s| (worker, s)));
        if let Some(WorkerState::Blocked(why)) = self.sched.worker_stats(worker).map(|s| s.state.clone()) {
            self.blocked(worker, why);
            self.members[worker.0 as usize].ready = false;
            return;
        }
        let m = &mut self.members[worker.0 as usize];
        m.out.get_or_insert(format!("lost: {reason}"));
        m.ready = false;
        let lost = self.sched.worker_stats(worker).is_some_and(|s| s.state == WorkerState::Lost);
        if lost && !m.rejoining {
            m.rejoining = true;
            self.actions.push(Action::CallBack(worker));
        }
    }

    /// Reports a failed strip to the scheduler, and blocks the worker when that was one failed unit too many.
    fn on_failure(&mut self, worker: WorkerId, strip: StripId, failure: StripFailure, now: Duration) {
        if let FailureOutcome::WorkerBlocked { reason, cancel } = self.sched.failed(worker, strip, failure, now) {
            self.cancel(cancel.into_iter().map(|s| (worker, s)));
            self.blocked(worker, reason);
        }
    }

    /// Tells the user that `worker` is blocked for `reason` (the scheduler blocked it), and keeps it out.
    fn blocked(&mut self, worker: WorkerId, reason: String) {
        let m = &mut self.members[worker.0 as usize];
        self.actions.push(Action::Warn(Warning::Blocked { worker: m.addr.name.clone(), reason: reason.clone() }));
        m.out = Some(format!("blocked: {reason}"));
    }

    /// Issues again the units of the workers that fell silent (their copies keep running) and withdraws the
    /// strips past their deadline, as failures of their workers.
    pub(super) fn on_tick(&mut self, now: Duration) {
        for stall in self.sched.check_stalls(now) {
            let worker = stall.worker;
            let silence = self.sched.silence_limit(worker);
            let name = self.members[worker.0 as usize].addr.name.clone();
            tracing::info!(worker = %name, strips = ?stall.strips, "stalled: issuing its units again");
            if stall.newly {
                self.actions.push(Action::Warn(Warning::Stalled { worker: name, silence }));
            }
            if let Some((reason, cancel)) = stall.blocked {
                self.cancel(cancel.into_iter().map(|s| (worker, s)));
                self.blocked(worker, reason);
            }
        }
        for (worker, strip) in self.sched.expired(now) {
            self.cancel([(worker, strip)]);
            let deadline = self.sched.deadline(worker, strip).unwrap_or_default();
            self.on_failure(worker, strip, StripFailure::timed_out(now, deadline), now);
        }
    }

    /// Cancels strip calls in flight.
    fn cancel(&mut self, calls: impl IntoIterator<Item = (WorkerId, StripId)>) {
        self.actions.extend(calls.into_iter().map(|(worker, strip)| Action::Cancel(worker, strip)));
    }

    /// Gives every ready worker strips until its slots are full.
    pub(super) fn fill_slots(&mut self, now: Duration) {
        for (i, m) in self.members.iter().enumerate() {
            let worker = WorkerId(i as u32);
            if !m.ready {
                continue;
            }
            while let Some(a) = self.sched.assign(worker, now) {
                self.actions.push(Action::Spawn(worker, a));
            }
        }
    }
}
