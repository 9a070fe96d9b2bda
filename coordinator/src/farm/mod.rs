//! Rendering a prepared job on workers over gRPC: schedule strips, validate and assemble them, survive workers
//! that fail.
//!
//! Every unit of work is a block of units (samples or passes) over rows, and comes back as fixed-point sums
//! ([`photon_core::render::sums`]). The farm cuts one axis: strips of rows that each take every unit of the job
//! (the methods whose unit is a sample), or whole-image blocks of units (the methods that render in passes,
//! and every render bounded by time or error), whose passes are traced once in the whole farm. The sums are
//! added exactly, in any order ([`photon_core::render::sums::SumAccumulator`]), so the image does not depend on the cut, the workers or
//! their speed.
//!
//! One task per worker opens a [`session`] (connect, hello, ship the blobs it lacks); one task per
//! strip in flight asks for it and checks what comes back. They report through a channel to a single loop
//! ([`render`]), so every decision is made in one place, in the order events arrive; the loop also wakes on a
//! timer to withdraw strips past their deadline. The decisions are the state's (`state::Farm`, with the
//! [`scheduler::Scheduler`], a pure state machine, inside): each event is one method call, which queues what
//! must happen outside it (call a worker for a strip, cancel a call, warn the user, call a lost worker back) as
//! actions that the loop performs. The state spawns nothing and prints nothing, so its unit tests feed it events
//! and read its actions and its image.
//!
//! A worker whose connection is lost is called again with backoff ([`crate::fleet::rejoin`]) while the render goes on;
//! when it answers it rejoins after the same hello and build-id check as at the start, with the blobs it lacks
//! shipped again. A worker that holds strips and says nothing past its silence limit is shown as `stalled`. When
//! no worker is left the render waits [`Options::rejoin_patience`] for one to come back before it gives up.
//! SIGINT or SIGTERM ([`crate::fleet::interrupt`]) stops the render as a failure does: the strips in flight are
//! cancelled and the finished ones kept for `--resume` ([`FarmError::Interrupted`]). While it runs, the finished
//! units are also written every few seconds ([`Options::checkpoint`]), so that a coordinator killed without a
//! word (SIGKILL, the OOM killer, a power cut) loses at most the units of the last interval.
//!
//! A result is accepted only if it covers exactly the strip's rows in order, has the right number of sums, each
//! one the block's units can add up to, and hashes to the checksum the worker computed before sending. A copy
//! that loses the race, or a worker's strips when it is declared lost or dropped, are cancelled by dropping
//! their calls (the worker then stops rendering them).

pub mod bounded;
mod partial;
pub mod scheduler;
mod state;
#[cfg(test)]
mod tests;
mod types;
mod view;

use crate::fleet::interrupt::interrupted;
use crate::fleet::session::{self, Client, Ready, SessionError, StripError, StripResult, WorkerAddr, fetch_strip};
use crate::job::Job;
use crate::out::live::Board;
use crate::out::report::{Outcome, progress_bar};
use photon_proto::pb;
use scheduler::{Assignment, StripId, WorkerId};
use state::{Action, Farm};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::{self, UnboundedSender};
use tokio::task::{AbortHandle, JoinHandle};
pub use types::{Checkpoint, FarmError, Options, REJOIN_PATIENCE};

/// Renders `job` on `workers`.
pub async fn render(job: &Job, workers: &[WorkerAddr], mut options: Options) -> Result<Outcome, FarmError> {
    let t0 = Instant::now();
    let (tx, mut rx) = mpsc::unbounded_channel::<Event>();
    let mut interrupt = options.interrupt.take();
    let continuation = options.continuation.take();
    let mut farm = Farm::new(job, workers, &options)?;
    if let (Some(c), Some(bound)) = (continuation, &options.bound) {
        farm.continue_from(c, bound.clone(), &options.policy, workers.len())?;
    }
    let mut effects = Effects::new(job, workers, &options, tx, &farm);
    let sessions = start_sessions(job, workers, &options, &effects.tx);
    let mut checkpoints = partial::Checkpoints::new(options.checkpoint.take(), &farm);
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    let result = loop {
        let end = farm.end(t0.elapsed());
        effects.perform(farm.take_actions());
        if let Some(end) = end {
            break end;
        }
        // A bounded render's next round was queued by `end`: hand it out now, not at the next event or tick
        // (up to 250 ms later, which was most of a short round's time).
        farm.fill_slots(t0.elapsed());
        effects.perform(farm.take_actions());
        tokio::select! {
            Some(event) = rx.recv() => effects.deliver(&mut farm, event, t0.elapsed()),
            _ = tick.tick() => {
                farm.on_tick(t0.elapsed());
                effects.bar.set_message(farm.rates());
            }
            signal = interrupted(interrupt.as_mut()) => farm.interrupt(signal),
        }
        farm.fill_slots(t0.elapsed());
        effects.perform(farm.take_actions());
        effects.show(&farm, t0.elapsed());
        checkpoints.at(&farm, t0.elapsed());
    };
    checkpoints.finish();
    effects.stop(&farm, t0.elapsed(), sessions);
    farm.finish(result, t0.elapsed())
}

/// One task per worker: connect and say hello (unless it was greeted already), ship blobs, and report the worker
/// ready or refused.
fn start_sessions(
    job: &Job,
    workers: &[WorkerAddr],
    options: &Options,
    tx: &UnboundedSender<Event>,
) -> Vec<JoinHandle<()>> {
    let mut sessions = Vec::new();
    for (i, addr) in workers.iter().enumerate() {
        let (tx, job, addr, token) = (tx.clone(), job.clone(), addr.clone(), options.token.clone());
        let (tls_ca, greeting) = (options.tls_ca.clone(), options.greetings.get(i).cloned().flatten());
        let worker = WorkerId(i as u32);
        sessions.push(tokio::spawn(async move {
            let opened = match greeting {
                Some(greeting) => session::open_greeted(greeting, &addr, &job).await,
                None => session::open(&addr, token.as_deref(), tls_ca.as_deref(), &job).await,
            };
            let event = match opened {
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

/// What the loop does outside the [`Farm`] state: the workers' clients, the strip calls in flight, the tasks
/// calling lost workers back, the progress bar and the live page.
struct Effects<'a> {
    job: &'a Job,
    workers: &'a [WorkerAddr],
    /// The shared token and TLS authority, to call lost workers back.
    token: Option<String>,
    tls_ca: Option<Vec<u8>>,
    /// Where the tasks report.
    tx: UnboundedSender<Event>,
    /// Each worker's client, from its last session.
    clients: Vec<Option<Client>>,
    /// Strip calls in flight; aborting one cancels the strip on its worker.
    tasks: BTreeMap<(WorkerId, StripId), AbortHandle>,
    /// The task calling each lost worker back, while it runs.
    rejoins: Vec<Option<AbortHandle>>,
    bar: indicatif::ProgressBar,
    /// The live page's board ([`Options::live`]).
    live: Option<Arc<Board>>,
}

impl<'a> Effects<'a> {
    fn new(
        job: &'a Job,
        workers: &'a [WorkerAddr],
        options: &Options,
        tx: UnboundedSender<Event>,
        farm: &Farm,
    ) -> Self {
        let bar = progress_bar(options.progress, farm.sched.strip_count(), farm.resumed, farm.units_word());
        Self {
            job,
            workers,
            token: options.token.clone(),
            tls_ca: options.tls_ca.clone(),
            tx,
            clients: vec![None; workers.len()],
            tasks: BTreeMap::new(),
            rejoins: vec![None; workers.len()],
            bar,
            live: options.live.clone(),
        }
    }

    /// Hands `event` to the state; a ready worker's client stays here, for its strip calls.
    fn deliver(&mut self, farm: &mut Farm, event: Event, now: Duration) {
        match event {
            Event::Ready { worker, ready } => {
                let Ready { client, hello, delivered, ship_s } = *ready;
                self.clients[worker.0 as usize] = Some(client);
                farm.on_ready(worker, hello, delivered, ship_s, now);
            }
            Event::Refused { worker, reason } => farm.on_refused(worker, reason.to_string()),
            Event::Progress { worker, rows } => farm.on_progress(worker, rows, now),
            Event::Strip { worker, strip, attempt, result } => {
                self.tasks.remove(&(worker, strip));
                farm.on_strip(worker, strip, attempt, result, now);
            }
        }
    }

    /// Performs the state's actions, in order.
    fn perform(&mut self, actions: Vec<Action>) {
        for action in actions {
            match action {
                Action::Spawn(worker, a) => self.spawn(worker, a),
                Action::Cancel(worker, strip) => {
                    if let Some(h) = self.tasks.remove(&(worker, strip)) {
                        h.abort();
                    }
                }
                Action::Warn(w) => eprintln!("warning: {w}"),
                Action::CallBack(worker) => self.call_back(worker),
                Action::Estimate { elapsed_s, rel_mse } => {
                    if let Some(board) = &self.live {
                        board.push_error(elapsed_s, rel_mse);
                    }
                }
            }
        }
    }

    /// Starts the call of an assigned strip on `worker`.
    fn spawn(&mut self, worker: WorkerId, a: Assignment) {
        // The state assigns strips only to a worker whose session reported ready, whose client is kept here.
        let Some(client) = self.clients[worker.0 as usize].clone() else {
            tracing::error!("{worker} has no client: {} waits for its deadline", a.strip);
            return;
        };
        let strip = a.strip;
        let handle = spawn_strip(self.job, worker, a, client, self.tx.clone());
        self.tasks.insert((worker, strip), handle);
    }

    /// Calls a lost worker back with backoff ([`crate::fleet::rejoin`]); it reports ready or refused.
    fn call_back(&mut self, worker: WorkerId) {
        let i = worker.0 as usize;
        self.clients[i] = None;
        let (tx, job, addr) = (self.tx.clone(), self.job.clone(), self.workers[i].clone());
        let (token, tls_ca) = (self.token.clone(), self.tls_ca.clone());
        let task = tokio::spawn(async move {
            let event = match crate::fleet::rejoin::call_back(&addr, token.as_deref(), tls_ca.as_deref(), &job).await {
                Ok(ready) => Event::Ready { worker, ready: Box::new(ready) },
                Err(reason) => Event::Refused { worker, reason },
            };
            let _ = tx.send(event);
        });
        self.rejoins[i] = Some(task.abort_handle());
    }

    /// Shows the state at `now`: on the progress bar, and on the live page.
    fn show(&self, farm: &Farm, now: Duration) {
        let (done, total) = farm.sched.progress();
        self.bar.set_length(total as u64);
        self.bar.set_position(done as u64);
        self.publish(farm, now, false);
    }

    /// Publishes the state at `now` to the live page, if there is one: at most every
    /// [`crate::out::live::PUBLISH_EVERY`] unless `force`, with the image when a unit was finished since and
    /// someone looks (or it is the final state).
    fn publish(&self, farm: &Farm, now: Duration, force: bool) {
        let Some(board) = self.live.as_deref().filter(|b| b.due(force)) else { return };
        let (status, preview) = farm.live_view(now, |done| board.wants_preview(done, force));
        board.publish(status, preview);
    }

    /// Stops what is still running at the end of the render, and shows its final state.
    fn stop(&mut self, farm: &Farm, now: Duration, sessions: Vec<JoinHandle<()>>) {
        self.bar.finish_and_clear();
        for (_, h) in std::mem::take(&mut self.tasks) {
            h.abort();
        }
        self.publish(farm, now, true);
        for s in sessions {
            s.abort();
        }
        for task in self.rejoins.iter_mut().filter_map(Option::take) {
            task.abort();
        }
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
    let (strip, attempt, width, by_rows) = (a.strip, a.attempt, job.width, job.passes.is_none());
    let progress_tx = tx.clone();
    let handle = tokio::spawn(async move {
        // The worker counts units done; a strip's progress is counted in its rows.
        let (strip_rows, block_units) = (rows.len() as u64, u64::from(units.len() as u32).max(1));
        let progress = |units_done: u32| {
            let rows = if by_rows { (u64::from(units_done) * strip_rows / block_units) as u32 } else { units_done };
            let _ = progress_tx.send(Event::Progress { worker, rows });
        };
        let result = fetch_strip(client, request, width, progress).await;
        let _ = tx.send(Event::Strip { worker, strip, attempt, result });
    });
    handle.abort_handle()
}
