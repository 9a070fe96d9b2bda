//! Rendering a prepared job on workers over gRPC: schedule strips, validate and assemble them, survive workers
//! that fail.
//!
//! Every unit of work is a block of units (samples or passes) over rows, and comes back as fixed-point sums
//! ([`photon_core::render::sums`]). The farm cuts one axis: strips of rows that each take every unit of the job
//! (the methods whose unit is a sample), or whole-image blocks of units (the methods that render in passes,
//! and every render bounded by time or error), whose passes are traced once in the whole farm. The sums are
//! added exactly, in any order ([`SumAccumulator`]), so the image does not depend on the cut, the workers or
//! their speed.
//!
//! One task per worker opens a [`session`] (connect, hello, ship the blobs it lacks); one task per
//! strip in flight asks for it and checks what comes back. They report to a single loop that owns the `Farm`
//! state, with the [`Scheduler`] (a pure state machine) inside, through a channel, so every decision is made in
//! one place, in the order events arrive. The loop also wakes on a timer to withdraw strips past their deadline.
//! What the user should hear about during the render ([`Warning`]) is collected by the handlers and printed by
//! the loop.
//!
//! A worker whose connection is lost is called again with backoff ([`crate::fleet::rejoin`]) while the render goes on;
//! when it answers it rejoins after the same hello and build-id check as at the start, with the blobs it lacks
//! shipped again. A worker that holds strips and says nothing past its silence limit is shown as `stalled`. When
//! no worker is left the render waits [`Options::rejoin_patience`] for one to come back before it gives up.
//! SIGINT or SIGTERM ([`crate::fleet::interrupt`]) stops the render as a failure does: the strips in flight are
//! cancelled and the finished ones kept for `--resume` ([`FarmError::Interrupted`]).
//!
//! A result is accepted only if it covers exactly the strip's rows in order, has the right number of floats,
//! every value finite and non-negative, and hashes to the checksum the worker computed before sending. A copy
//! that loses the race, or a worker's strips when it is declared lost or dropped, are cancelled by dropping
//! their calls (the worker then stops rendering them).

pub mod bounded;
pub mod scheduler;

use crate::fleet::interrupt::{Interrupt, Interrupts, interrupted};
use crate::fleet::session::{
    self, Client, Delivered, Ready, SessionError, StripError, StripResult, WorkerAddr, fetch_strip,
};
use crate::job::{Job, Partial};
use crate::out::report::{Outcome, Warning, WorkerReport, progress_bar};
use photon_core::render::sums::SumAccumulator;
use photon_proto::pb;
use scheduler::{
    Assignment, Completion, FailureOutcome, Policy, Scheduler, StripFailure, StripId, WorkerId, WorkerState,
};
use std::collections::BTreeMap;
use std::ops::Range;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::{self, UnboundedSender};
use tokio::task::{AbortHandle, JoinHandle};

/// How to render.
#[derive(Clone, Debug)]
pub struct Options {
    /// The shared token, sent with every call.
    pub token: Option<String>,
    /// TLS: the PEM certificate authority that signed the workers' certificates (plaintext when `None`).
    pub tls_ca: Option<Vec<u8>>,
    /// Rows per strip (default: [`crate::farm::scheduler::rows_per_strip_for`]); for progressive photon mapping, passes
    /// per block (default: [`crate::farm::scheduler::passes_per_block_for`]).
    pub rows_per_strip: Option<u32>,
    /// The scheduling policy.
    pub policy: Policy,
    /// Strips finished by an earlier, interrupted render of the same job.
    pub resume: Option<Partial>,
    /// Show a progress bar.
    pub progress: bool,
    /// Signals that stop the render, keeping the finished strips ([`crate::fleet::interrupt::watch_signals`]).
    pub interrupt: Option<Interrupts>,
    /// How long the render waits, once no worker is left, for a lost one to come back before it gives up.
    pub rejoin_patience: Duration,
    /// Render in rounds until a time or an estimated error ([`crate::farm::bounded`]); the job must then hand out pass
    /// blocks ([`Job::passes`]).
    pub bound: Option<crate::farm::bounded::Bound>,
    /// Where the render's state is published for the live page (`render --serve`), if anywhere.
    pub live: Option<std::sync::Arc<crate::out::live::Board>>,
}

/// The default [`Options::rejoin_patience`]: three calls at the longest backoff.
pub const REJOIN_PATIENCE: Duration = Duration::from_secs(15);

impl Default for Options {
    fn default() -> Self {
        Self {
            token: None,
            tls_ca: None,
            rows_per_strip: None,
            policy: Policy::default(),
            resume: None,
            progress: false,
            interrupt: None,
            rejoin_patience: REJOIN_PATIENCE,
            bound: None,
            live: None,
        }
    }
}

/// Why a render stopped before the image was complete.
#[derive(Debug, thiserror::Error)]
pub enum FarmError {
    /// No worker is left (none connected, all refused, lost or dropped).
    #[error("no worker left to render on: {reasons}")]
    NoWorkers {
        /// Each worker's reason.
        reasons: String,
        /// What was finished.
        partial: Box<Partial>,
        /// Per-worker lines.
        workers: Vec<WorkerReport>,
    },
    /// A failure that no retry can fix (the job itself cannot render): no partial file is kept, since resuming
    /// would fail the same way.
    #[error("the render cannot finish: {reason}")]
    Fatal {
        /// Why.
        reason: String,
        /// Per-worker lines.
        workers: Vec<WorkerReport>,
    },
    /// The job does not fit the partial file given to resume.
    #[error("{0}")]
    Resume(String),
    /// A signal stopped the render.
    #[error("interrupted by {signal}")]
    Interrupted {
        /// Which.
        signal: Interrupt,
        /// What was finished.
        partial: Box<Partial>,
        /// Per-worker lines.
        workers: Vec<WorkerReport>,
    },
}

impl FarmError {
    /// The finished strips, when there are any worth keeping.
    pub fn partial(&self) -> Option<&Partial> {
        match self {
            Self::NoWorkers { partial, .. } | Self::Interrupted { partial, .. } => Some(partial),
            Self::Fatal { .. } | Self::Resume(_) => None,
        }
    }
}

/// Renders `job` on `workers`.
pub async fn render(job: &Job, workers: &[WorkerAddr], mut options: Options) -> Result<Outcome, FarmError> {
    let (tx, mut rx) = mpsc::unbounded_channel::<Event>();
    let mut interrupt = options.interrupt.take();
    let mut farm = Farm::new(job, workers, &options, tx.clone())?;
    let sessions = start_sessions(job, workers, &options, &tx);
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    let result = loop {
        let now = farm.t0.elapsed();
        if let Some(end) = farm.end(now) {
            break end;
        }
        tokio::select! {
            Some(event) = rx.recv() => farm.on_event(event, now),
            _ = tick.tick() => farm.on_tick(now),
            signal = interrupted(interrupt.as_mut()) => farm.interrupted = Some(signal),
        }
        farm.print_warnings();
        farm.fill_slots();
        farm.publish(false);
    };
    farm.finish(result, sessions)
}

/// One task per worker: connect, say hello, ship blobs, and report the worker ready or refused.
fn start_sessions(
    job: &Job,
    workers: &[WorkerAddr],
    options: &Options,
    tx: &UnboundedSender<Event>,
) -> Vec<JoinHandle<()>> {
    let mut sessions = Vec::new();
    for (i, addr) in workers.iter().enumerate() {
        let (tx, job, addr, token) = (tx.clone(), job.clone(), addr.clone(), options.token.clone());
        let tls_ca = options.tls_ca.clone();
        let worker = WorkerId(i as u32);
        sessions.push(tokio::spawn(async move {
            let event = match session::open(&addr, token.as_deref(), tls_ca.as_deref(), &job).await {
                Ok(ready) => Event::Ready { worker, ready: Box::new(ready) },
                Err(reason) => Event::Refused { worker, reason },
            };
            let _ = tx.send(event);
        }));
    }
    sessions
}

/// What the tasks tell the loop.
enum Event {
    Ready { worker: WorkerId, ready: Box<Ready> },
    Refused { worker: WorkerId, reason: SessionError },
    Progress { worker: WorkerId, rows: u32 },
    Strip { worker: WorkerId, strip: StripId, attempt: u32, result: Result<StripResult, StripError> },
}

/// Why the loop stopped before the image was complete.
enum Stop {
    /// A failure no retry can fix: the strip and why.
    Fatal(String),
    /// No worker is left, none is still connecting, and none came back within the patience.
    NoWorkers,
    /// A signal asked to stop.
    Interrupted(Interrupt),
}

/// A worker as the loop knows it.
struct Member {
    addr: WorkerAddr,
    client: Option<Client>,
    hello: Option<pb::HelloReply>,
    /// Blob bytes it received, from the coordinator and from other workers.
    received: Delivered,
    ship_s: f64,
    /// Why it is out, if it is (refused, lost, dropped).
    out: Option<String>,
    /// Rows (passes, for pass blocks) finished in strips still in flight (for the progress bar's rate).
    rows_live: u64,
    /// Photon paths its accepted results traced, and the seconds it spent tracing them and building their maps.
    photon_paths: u64,
    photon_s: f64,
    /// Seconds it spent decoding the job's blobs.
    load_s: f64,
    /// The task calling it back after it was lost, while it runs.
    rejoining: Option<AbortHandle>,
}

/// The state of one render, owned by its event loop: the scheduler, the workers, the image so far and the
/// strip calls in flight. Each event is one method call.
struct Farm<'a> {
    job: &'a Job,
    t0: Instant,
    /// Rows per strip, or passes per block.
    rows_per_strip: u32,
    sched: Scheduler,
    members: Vec<Member>,
    /// The fixed-point sums of the units accepted so far (3 per pixel, row-major, of the whole image).
    image: SumAccumulator,
    /// Rows of finished strips, or units of finished blocks (first → end), for the partial file.
    done_rows: BTreeMap<u32, u32>,
    /// Strip calls in flight; aborting one cancels the strip on its worker.
    tasks: BTreeMap<(WorkerId, StripId), AbortHandle>,
    rays: u64,
    photon_paths: u64,
    first_ready: Option<Instant>,
    /// Workers whose session has not reported yet.
    unresolved: usize,
    resumed: usize,
    mixed_math_warned: bool,
    warnings: Vec<Warning>,
    bar: indicatif::ProgressBar,
    /// Where the tasks report.
    tx: UnboundedSender<Event>,
    /// The shared token and TLS authority, to call lost workers back.
    token: Option<String>,
    tls_ca: Option<Vec<u8>>,
    rejoin_patience: Duration,
    /// Since when no worker has been active, while that lasts.
    none_active_since: Option<Duration>,
    /// The signal that asked to stop, once one has.
    interrupted: Option<Interrupt>,
    /// A render bounded by time or error: its rounds (the round in flight's sums join `passes` when it is
    /// complete) and why it stopped.
    rounds: Option<crate::farm::bounded::Rounds>,
    /// The live page's board ([`Options::live`]).
    live: Option<std::sync::Arc<crate::out::live::Board>>,
}

impl<'a> Farm<'a> {
    fn new(
        job: &'a Job,
        workers: &[WorkerAddr],
        options: &Options,
        tx: UnboundedSender<Event>,
    ) -> Result<Self, FarmError> {
        let t0 = Instant::now();
        let n = workers.len() as u32;
        let pixels = 3 * job.width as usize * job.height as usize;
        // A bounded render starts with its first round; the others with the whole job.
        let mut rounds = options.bound.clone().map(|b| crate::farm::bounded::Rounds::new(b, pixels));
        let first = rounds.as_mut().map(|r| r.first(workers.len()));
        let rows_per_strip = match (&options.resume, options.rows_per_strip, job.passes, first) {
            (_, _, _, Some(plan)) => plan.per_block,
            (Some(p), _, _, _) => p.rows_per_strip,
            (None, Some(r), _, _) => r,
            (None, None, Some(passes), _) => crate::farm::scheduler::passes_per_block_for(passes, n),
            (None, None, None, _) => crate::farm::scheduler::rows_per_strip_for(job.height, n),
        };
        // The scheduler cuts one axis: the units of whole-image blocks (the methods that render in passes, and a
        // bounded render), or the rows of strips that each take every unit of the job.
        let (axis, image) = match (job.passes, first) {
            (Some(_), Some(plan)) => (plan.passes, SumAccumulator::new(pixels, 1)),
            (Some(p), None) => (p, SumAccumulator::new(pixels, p)),
            (None, _) => (job.height, SumAccumulator::new(pixels, job.units)),
        };
        let members = workers
            .iter()
            .map(|a| Member {
                addr: a.clone(),
                client: None,
                hello: None,
                received: Delivered::default(),
                ship_s: 0.0,
                out: None,
                rows_live: 0,
                photon_paths: 0,
                photon_s: 0.0,
                load_s: 0.0,
                rejoining: None,
            })
            .collect();
        let mut farm = Self {
            job,
            t0,
            rows_per_strip,
            sched: Scheduler::with_policy(axis, rows_per_strip, options.policy.clone()),
            members,
            image,
            done_rows: BTreeMap::new(),
            tasks: BTreeMap::new(),
            rays: 0,
            photon_paths: 0,
            first_ready: None,
            unresolved: workers.len(),
            resumed: 0,
            mixed_math_warned: false,
            warnings: Vec::new(),
            bar: indicatif::ProgressBar::hidden(),
            tx,
            token: options.token.clone(),
            tls_ca: options.tls_ca.clone(),
            rejoin_patience: options.rejoin_patience,
            none_active_since: None,
            interrupted: None,
            rounds,
            live: options.live.clone(),
        };
        if let Some(p) = &options.resume {
            farm.resume(p)?;
        }
        let unit = if job.passes.is_some() { "pass blocks" } else { "strips" };
        farm.bar = progress_bar(options.progress, farm.sched.strip_count(), farm.resumed, unit);
        Ok(farm)
    }

    /// Takes the strips of a partial file that fit this job's cut.
    fn resume(&mut self, p: &Partial) -> Result<(), FarmError> {
        let job = self.job;
        if p.fingerprint != job.fingerprint() || (p.width, p.height) != (job.width, job.height) {
            return Err(FarmError::Resume(
                "the partial file was made by another scene, other settings or another build: render without --resume"
                    .into(),
            ));
        }
        // Every unit must fit this render's cut: their sums cannot be taken apart.
        let units: Option<Vec<(StripId, Range<u32>)>> =
            p.done.iter().map(|&first| self.unit_starting_at(first)).collect();
        let Some(units) = units.filter(|_| self.image.restore(&p.sums)) else {
            return Err(FarmError::Resume(
                "the partial file's finished units do not fit this render: render without --resume".into(),
            ));
        };
        for (id, range) in units {
            if self.sched.mark_done(id) {
                self.done_rows.insert(range.start, range.end);
                self.resumed += 1;
            }
        }
        Ok(())
    }

    /// The strip (or pass block) of this render's cut that starts at row (or pass) `first`, with its range.
    fn unit_starting_at(&self, first: u32) -> Option<(StripId, Range<u32>)> {
        let id = StripId(first / self.rows_per_strip.max(1));
        self.sched.strip_rows(id).filter(|r| r.start == first).map(|r| (id, r))
    }

    /// How the render ended at `now`, once it has.
    fn end(&mut self, now: Duration) -> Option<Result<(), Stop>> {
        if self.sched.is_done() {
            return match self.rounds.is_some() {
                true => self.next_round(),
                false => Some(Ok(())),
            };
        }
        if let Some((strip, failure)) = self.sched.fatal() {
            return Some(Err(Stop::Fatal(format!("{strip}: {}", failure.reason))));
        }
        // A bounded render well past its deadline stops with its finished rounds; the round in flight is dropped.
        if let Some(rounds) = self.rounds.as_mut().filter(|r| r.completed() > 0 && r.overdue()) {
            rounds.stop(crate::farm::bounded::StopReason::Time);
            return Some(Ok(()));
        }
        if let Some(signal) = self.interrupted {
            return Some(self.keep_rounds(crate::farm::bounded::StopReason::Interrupted, Stop::Interrupted(signal)));
        }
        if !(self.unresolved == 0 && self.sched.all_workers_gone()) {
            self.none_active_since = None;
            return None;
        }
        let since = *self.none_active_since.get_or_insert(now);
        let waiting = self.members.iter().any(|m| m.rejoining.is_some());
        (!waiting || now.saturating_sub(since) >= self.rejoin_patience)
            .then(|| self.keep_rounds(crate::farm::bounded::StopReason::NoWorkers, Stop::NoWorkers))
    }

    /// A bounded render whose round is complete: its sums join the image, and the next round is queued, or the
    /// render ends.
    fn next_round(&mut self) -> Option<Result<(), Stop>> {
        let Some(rounds) = self.rounds.as_mut() else { return Some(Ok(())) };
        let estimate = rounds.end_round(&mut self.image);
        tracing::info!(passes = rounds.passes(), rounds = rounds.completed(), ?estimate, "round complete");
        if let (Some(board), Some(e)) = (&self.live, estimate) {
            board.push_error(self.t0.elapsed().as_secs_f64(), e);
        }
        let active = self.sched.workers().filter(|(_, s)| s.state == WorkerState::Active).count();
        match rounds.next(active) {
            Ok(plan) => {
                self.sched.extend(plan.passes, plan.per_block);
                self.bar.set_length(self.sched.strip_count() as u64);
                None
            }
            Err(_) => Some(Ok(())),
        }
    }

    /// How a render that must stop for `reason` ends: a bounded one with a complete round keeps its rounds;
    /// the others fail with `stop`.
    fn keep_rounds(&mut self, reason: crate::farm::bounded::StopReason, stop: Stop) -> Result<(), Stop> {
        match self.rounds.as_mut().filter(|r| r.completed() > 0) {
            Some(rounds) => {
                rounds.stop(reason);
                Ok(())
            }
            None => Err(stop),
        }
    }

    fn on_event(&mut self, event: Event, now: Duration) {
        match event {
            Event::Ready { worker, ready } => self.on_ready(worker, *ready),
            Event::Refused { worker, reason } => self.on_refused(worker, reason.to_string()),
            Event::Progress { worker, rows } => {
                self.sched.heard_from(worker, now);
                self.members[worker.0 as usize].rows_live = u64::from(rows);
            }
            Event::Strip { worker, strip, attempt, result } => self.on_strip(worker, strip, attempt, result, now),
        }
    }

    fn on_ready(&mut self, worker: WorkerId, ready: Ready) {
        if self.members[worker.0 as usize].rejoining.take().is_some() {
            return self.on_rejoined(worker, ready);
        }
        self.unresolved -= 1;
        if self.first_ready.is_none() {
            self.first_ready = Some(Instant::now());
            // A bounded render's first round is timed from here, not from the connections and uploads.
            if let Some(rounds) = &mut self.rounds {
                rounds.restart_round_clock();
            }
        }
        let Ready { client, hello, delivered, ship_s } = ready;
        let other_mode = self.members.iter().find_map(|o| {
            o.hello.as_ref().filter(|h| h.math_mode != hello.math_mode).map(|h| (&o.addr.name, &h.math_mode))
        });
        if let (Some((other, other_mode)), false) = (other_mode, self.mixed_math_warned) {
            self.warnings.push(Warning::MixedMath {
                worker: self.members[worker.0 as usize].addr.name.clone(),
                mode: hello.math_mode.clone(),
                other: other.clone(),
                other_mode: other_mode.clone(),
            });
            self.mixed_math_warned = true;
        }
        let m = &mut self.members[worker.0 as usize];
        tracing::info!(
            worker = %m.addr.name, arch = %hello.arch, math = %hello.math_mode, threads = hello.threads,
            shipped = delivered.shipped, fetched = delivered.fetched, ship_s, "ready"
        );
        self.sched.add_worker(worker, hello.threads);
        (m.client, m.hello, m.received, m.ship_s) = (Some(client), Some(hello), delivered, ship_s);
    }

    /// A lost worker that answered again, with the same build: it takes strips again.
    fn on_rejoined(&mut self, worker: WorkerId, ready: Ready) {
        let Ready { client, hello, delivered, .. } = ready;
        let m = &mut self.members[worker.0 as usize];
        tracing::info!(worker = %m.addr.name, threads = hello.threads, ?delivered, "rejoined");
        if self.sched.rejoin(worker, hello.threads) {
            let shipped = delivered.shipped + delivered.fetched;
            self.warnings.push(Warning::Rejoined { worker: m.addr.name.clone(), shipped });
            m.received += delivered;
            (m.client, m.hello, m.out) = (Some(client), Some(hello), None);
        }
    }

    fn on_refused(&mut self, worker: WorkerId, reason: String) {
        let m = &mut self.members[worker.0 as usize];
        if m.rejoining.take().is_some() {
            let reason = format!("lost, then refused: {reason}");
            self.warnings.push(Warning::Refused { worker: m.addr.name.clone(), reason: reason.clone() });
            m.out = Some(reason);
            return;
        }
        self.unresolved -= 1;
        self.warnings.push(Warning::Refused { worker: m.addr.name.clone(), reason: reason.clone() });
        m.out = Some(reason);
    }

    fn on_strip(
        &mut self,
        worker: WorkerId,
        strip: StripId,
        attempt: u32,
        result: Result<StripResult, StripError>,
        now: Duration,
    ) {
        self.tasks.remove(&(worker, strip));
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
        self.bar.inc(1);
    }

    /// A worker that cannot be reached: its strips go to the others, and it is called back with backoff.
    fn on_lost(&mut self, worker: WorkerId, reason: String, now: Duration) {
        if self.sched.worker_stats(worker).is_some_and(|s| s.state == WorkerState::Active) {
            let name = self.members[worker.0 as usize].addr.name.clone();
            self.warnings.push(Warning::Lost { worker: name, reason: reason.clone() });
        }
        let strips = self.sched.worker_lost(worker, now);
        self.cancel(strips.into_iter().map(|s| (worker, s)));
        let m = &mut self.members[worker.0 as usize];
        m.out.get_or_insert(format!("lost: {reason}"));
        m.client = None;
        let lost = self.sched.worker_stats(worker).is_some_and(|s| s.state == WorkerState::Lost);
        if lost && m.rejoining.is_none() {
            let (tx, job, addr) = (self.tx.clone(), self.job.clone(), m.addr.clone());
            let (token, tls_ca) = (self.token.clone(), self.tls_ca.clone());
            let task = tokio::spawn(async move {
                let event =
                    match crate::fleet::rejoin::call_back(&addr, token.as_deref(), tls_ca.as_deref(), &job).await {
                        Ok(ready) => Event::Ready { worker, ready: Box::new(ready) },
                        Err(reason) => Event::Refused { worker, reason },
                    };
                let _ = tx.send(event);
            });
            m.rejoining = Some(task.abort_handle());
        }
    }

    /// Reports a failed strip to the scheduler, and drops the worker when that was one failure too many.
    fn on_failure(&mut self, worker: WorkerId, strip: StripId, failure: StripFailure, now: Duration) {
        if let FailureOutcome::WorkerDropped { reason, cancel } = self.sched.failed(worker, strip, failure, now) {
            let name = self.members[worker.0 as usize].addr.name.clone();
            self.warnings.push(Warning::Dropped { worker: name, reason: reason.clone() });
            self.cancel(cancel.into_iter().map(|s| (worker, s)));
            self.members[worker.0 as usize].out = Some(format!("dropped: {reason}"));
        }
    }

    /// Withdraws the strips past their deadline, as failures of their workers, and notes the workers that fell
    /// silent.
    fn on_tick(&mut self, now: Duration) {
        for worker in self.sched.check_stalls(now) {
            let silence = self.sched.silence_limit(worker);
            let name = self.members[worker.0 as usize].addr.name.clone();
            self.warnings.push(Warning::Stalled { worker: name, silence });
        }
        for (worker, strip) in self.sched.expired(now) {
            self.cancel([(worker, strip)]);
            let deadline = self.sched.deadline(worker, strip).unwrap_or_default();
            self.on_failure(worker, strip, StripFailure::timed_out(now, deadline), now);
        }
        self.bar.set_message(self.rates());
    }

    /// Cancels strip calls in flight by dropping them (the worker then stops rendering them).
    fn cancel(&mut self, calls: impl IntoIterator<Item = (WorkerId, StripId)>) {
        for key in calls {
            if let Some(h) = self.tasks.remove(&key) {
                h.abort();
            }
        }
    }

    /// Prints the warnings gathered since the last call.
    fn print_warnings(&mut self) {
        for w in self.warnings.drain(..) {
            eprintln!("warning: {w}");
        }
    }

    /// Gives every ready worker strips until its slots are full.
    fn fill_slots(&mut self) {
        let now = self.t0.elapsed();
        for (i, m) in self.members.iter().enumerate() {
            let worker = WorkerId(i as u32);
            let Some(client) = &m.client else { continue };
            while let Some(a) = self.sched.assign(worker, now) {
                let strip = a.strip;
                let handle = spawn_strip(self.job, worker, a, client.clone(), self.tx.clone());
                self.tasks.insert((worker, strip), handle);
            }
        }
    }

    /// Stops what is still running and says how the render went.
    fn finish(mut self, result: Result<(), Stop>, sessions: Vec<JoinHandle<()>>) -> Result<Outcome, FarmError> {
        self.bar.finish_and_clear();
        self.cancel(self.tasks.keys().copied().collect::<Vec<_>>());
        self.publish(true);
        for s in sessions {
            s.abort();
        }
        for m in &mut self.members {
            if let Some(task) = m.rejoining.take() {
                task.abort();
            }
        }
        let (t0, first_ready) = (self.t0, self.first_ready);
        let render_s = first_ready.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let ship_s = first_ready.map_or(t0.elapsed().as_secs_f64(), |t| (t - t0).as_secs_f64());
        let workers = self.reports();
        let stop = match result {
            Ok(()) => {
                let bounded = self.rounds.as_ref().map(crate::farm::bounded::Rounds::report);
                let pixels = match &bounded {
                    Some(b) => self.image.image_of(b.passes),
                    None => self.image.image(),
                };
                let (rays, photon_paths, resumed) = (self.rays, self.photon_paths, self.resumed);
                return Ok(Outcome { pixels, rays, photon_paths, workers, ship_s, render_s, resumed, bounded });
            }
            Err(stop) => stop,
        };
        match stop {
            Stop::NoWorkers => {
                let reasons = self
                    .members
                    .iter()
                    .map(|m| format!("{}: {}", m.addr.name, m.out.as_deref().unwrap_or("gone")))
                    .collect::<Vec<_>>()
                    .join("; ");
                let reasons = if reasons.is_empty() { "no workers were given".to_owned() } else { reasons };
                Err(FarmError::NoWorkers { reasons, partial: Box::new(self.partial()), workers })
            }
            Stop::Fatal(reason) => Err(FarmError::Fatal { reason, workers }),
            Stop::Interrupted(signal) => {
                Err(FarmError::Interrupted { signal, partial: Box::new(self.partial()), workers })
            }
        }
    }

    /// The finished units and their sums, for `--resume`.
    fn partial(&self) -> Partial {
        let job = self.job;
        Partial {
            fingerprint: job.fingerprint(),
            width: job.width,
            height: job.height,
            rows_per_strip: self.rows_per_strip,
            done: self.done_rows.keys().copied().collect(),
            sums: self.image.sums().to_vec(),
        }
    }

    /// Per-worker rates for the progress bar: megapixels (or passes) per busy second so far.
    fn rates(&self) -> String {
        self.sched
            .workers()
            .filter(|(_, s)| s.state == WorkerState::Active)
            .map(|(id, s)| {
                let m = &self.members[id.0 as usize];
                if s.stalled {
                    return format!("{} stalled", m.addr.name);
                }
                let busy = s.busy.as_secs_f64().max(1e-3);
                let done = (s.rows + m.rows_live) as f64;
                match self.job.passes {
                    Some(_) => format!("{} {:.2} passes/s", m.addr.name, done / busy),
                    None => format!("{} {:.2} Mpx/s", m.addr.name, done * f64::from(self.job.width) / 1e6 / busy),
                }
            })
            .collect::<Vec<_>>()
            .join(" · ")
    }

    /// One line per worker for the final table.
    fn reports(&self) -> Vec<WorkerReport> {
        let width = self.job.width;
        self.members
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let stats = self.sched.worker_stats(WorkerId(i as u32));
                let (speculative, duplicates) = stats.map_or((0, 0), |s| (s.speculative, s.duplicates));
                let (strips, busy_s, rows, failures) =
                    stats.map_or((0, 0.0, 0, 0), |s| (s.strips, s.busy.as_secs_f64(), s.rows, s.failures));
                // A pass block covers every row of the image once per pass.
                let rows = if self.job.passes.is_some() { rows * u64::from(self.job.height) } else { rows };
                let state = match (&m.out, stats) {
                    (Some(why), _) => why.clone(),
                    (None, Some(s)) => match &s.state {
                        WorkerState::Dropped(why) => format!("dropped: {why}"),
                        WorkerState::Lost => "lost".into(),
                        WorkerState::Active if s.stalled => "stalled".into(),
                        WorkerState::Active if s.rejoins == 1 => "ok (rejoined once)".into(),
                        WorkerState::Active if s.rejoins > 1 => format!("ok (rejoined {} times)", s.rejoins),
                        WorkerState::Active => "ok".into(),
                    },
                    (None, None) => "ok".into(),
                };
                WorkerReport {
                    name: m.addr.name.clone(),
                    platform: m.hello.as_ref().map(|h| format!("{} {}", h.arch, h.os)).unwrap_or_default(),
                    threads: m.hello.as_ref().map_or(0, |h| h.threads),
                    strips,
                    busy_s,
                    mpix_per_s: if busy_s > 0.0 { rows as f64 * f64::from(width) / 1e6 / busy_s } else { 0.0 },
                    shipped_bytes: m.received.shipped,
                    fetched_bytes: m.received.fetched,
                    ship_s: m.ship_s,
                    speculative,
                    duplicates,
                    failures,
                    photon_paths: m.photon_paths,
                    photon_s: m.photon_s,
                    load_s: m.load_s,
                    state,
                }
            })
            .collect()
    }

    /// Publishes the render's state to the live page, if there is one: at most every
    /// [`crate::out::live::PUBLISH_EVERY`] unless `force`, with the image when a unit was finished since and someone
    /// looks (or it is the final state).
    fn publish(&mut self, force: bool) {
        use crate::out::live::{self, LiveStatus, LiveWorker, Preview};
        let Some(board) = self.live.as_deref().filter(|b| b.due(force)) else { return };
        let (done, total) = self.sched.progress();
        let (job, passes_done) = (self.job, self.done_rows.iter().map(|(a, b)| b - a).sum::<u32>());
        let preview = board.wants_preview(done, force).then(|| {
            let (pixels, gain) = match (job.passes, &self.rounds) {
                // A bounded render's image holds its completed rounds.
                (_, Some(rounds)) => (self.image.image_of(rounds.passes()), 1.0),
                (Some(all), None) => (self.image.image(), all as f32 / passes_done.max(1) as f32),
                (None, None) => (self.image.image(), 1.0),
            };
            Preview { image: photon_core::image_io::Image { width: job.width, height: job.height, pixels }, gain }
        });
        let render_s = self.first_ready.map_or(0.0, |t| t.elapsed().as_secs_f64());
        // Pixels of one scheduler "row": a row of the image, or a pass over all of it.
        let px = f64::from(job.width) * if job.passes.is_some() { f64::from(job.height) } else { 1.0 };
        let workers = (self.reports().into_iter().zip(&self.members).enumerate())
            .map(|(i, (r, m))| LiveWorker {
                state: live::worker_state(m.out.as_deref(), self.sched.worker_stats(WorkerId(i as u32))),
                in_flight: self.sched.in_flight(WorkerId(i as u32)).len(),
                mpix_per_s: self.sched.worker_stats(WorkerId(i as u32)).map_or(0.0, |s| s.rows as f64 * px / 1e6)
                    / render_s.max(1e-3),
                address: r.name,
                platform: r.platform,
                threads: r.threads,
                strips: r.strips,
                shipped_bytes: r.shipped_bytes,
                fetched_bytes: r.fetched_bytes,
            })
            .collect();
        let status = LiveStatus {
            elapsed_s: self.t0.elapsed().as_secs_f64(),
            // A bounded render's end is its deadline (its units grow round by round).
            eta_s: match &self.rounds {
                Some(rounds) => rounds.remaining().map(|d| d.as_secs_f64()),
                None => live::eta_s(render_s, done - self.resumed.min(done), total - done),
            },
            units: if job.passes.is_some() { "pass blocks" } else { "strips" }.into(),
            done,
            total,
            unit_states: live::unit_states(&self.sched),
            workers,
            photon_paths: self.photon_paths,
            photon_blob_bytes: job.photons_blob.as_ref().and_then(|id| job.blobs.get(id)).map_or(0, |b| b.len() as u64),
            width: job.width,
            height: job.height,
            ..LiveStatus::default()
        };
        board.publish(status, preview);
    }
}

/// Starts the call of one assigned strip; its result comes back as an [`Event::Strip`].
fn spawn_strip(job: &Job, worker: WorkerId, a: Assignment, client: Client, tx: UnboundedSender<Event>) -> AbortHandle {
    // A block covers the whole image and the scheduler cuts its units; a strip takes every unit of its rows.
    let (rows, units) = match job.passes {
        Some(_) => (0..job.height, a.rows.clone()),
        None => (a.rows.clone(), 0..job.units),
    };
    let request = pb::StripRequest {
        scene_blob: job.scene_blob.clone(),
        photons_blob: job.photons_blob.clone().unwrap_or_default(),
        frame: job.frame.clone(),
        row_start: rows.start,
        row_end: rows.end,
        strip: a.strip.0,
        attempt: a.attempt,
        unit_start: units.start,
        unit_end: units.end,
        trace_photons: job.trace_photons,
        texture_blobs: job.texture_blobs.clone(),
    };
    let (strip, attempt, width, job_by_rows) = (a.strip, a.attempt, job.width, job.passes.is_none());
    let progress_tx = tx.clone();
    let handle = tokio::spawn(async move {
        // The worker counts units done; a strip's progress is counted in its rows.
        let (strip_rows, block_units) = (rows.len() as u64, u64::from(units.len() as u32).max(1));
        let by_rows = job_by_rows;
        let progress = |units_done: u32| {
            let rows = if by_rows { (u64::from(units_done) * strip_rows / block_units) as u32 } else { units_done };
            let _ = progress_tx.send(Event::Progress { worker, rows });
        };
        let result = fetch_strip(client, request, width, progress).await;
        let _ = tx.send(Event::Strip { worker, strip, attempt, result });
    });
    handle.abort_handle()
}
