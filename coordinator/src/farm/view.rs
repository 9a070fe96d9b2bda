//! What the state of a render shows: how it ended ([`Outcome`] or [`FarmError`]), one line per worker, the
//! progress bar's rates and the live page's snapshot.

use super::scheduler::{WorkerId, WorkerState};
use super::state::{Farm, Stop};
use super::types::FarmError;
use crate::out::live::{self, LiveStatus, LiveWorker, Preview};
use crate::out::report::{Outcome, WorkerReport};
use std::time::Duration;

impl Farm<'_> {
    /// What the scheduler hands out: "pass blocks" or "strips".
    pub(super) fn units_word(&self) -> &'static str {
        if self.job.passes.is_some() { "pass blocks" } else { "strips" }
    }

    /// How the render went, once the loop stopped with `result` at `now`.
    pub(super) fn finish(self, result: Result<(), Stop>, now: Duration) -> Result<Outcome, FarmError> {
        let render_s = self.first_ready.map_or(0.0, |t| now.saturating_sub(t).as_secs_f64());
        let ship_s = self.first_ready.unwrap_or(now).as_secs_f64();
        let workers = self.reports();
        let stop = match result {
            Ok(()) => {
                let bounded = self.rounds.as_ref().map(super::bounded::Rounds::report);
                let pixels = match &bounded {
                    Some(b) => self.image.image_of(b.passes),
                    None => self.image.image(),
                };
                let (rays, photon_paths, resumed) = (self.rays, self.photon_paths, self.resumed);
                let image = self.image;
                let continuation = self.rounds.map(|rounds| Box::new(super::bounded::Continuation { rounds, image }));
                return Ok(Outcome {
                    pixels,
                    rays,
                    photon_paths,
                    workers,
                    ship_s,
                    render_s,
                    resumed,
                    bounded,
                    continuation,
                });
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

    /// Per-worker rates for the progress bar: megapixels (or passes) per busy second so far.
    pub(super) fn rates(&self) -> String {
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
    pub(super) fn reports(&self) -> Vec<WorkerReport> {
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
                        WorkerState::Blocked(why) => format!("blocked: {why}"),
                        WorkerState::Lost => "lost".into(),
                        WorkerState::Active if s.stalled => "stalled".into(),
                        WorkerState::Active if s.rejoins == 1 => "ok (rejoined once)".into(),
                        WorkerState::Active if s.rejoins > 1 => format!("ok (rejoined {} times)", s.rejoins),
                        WorkerState::Active => "ok".into(),
                    },
                    // Never added to the scheduler: still being greeted or supplied when the last unit came in.
                    (None, None) => "not ready (the render ended first)".into(),
                };
                WorkerReport {
                    name: m.addr.name.clone(),
                    platform: m.hello.as_ref().map_or_else(|| "-".into(), |h| format!("{} {}", h.arch, h.os)),
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

    /// The render's state at `now` for the live page, with the image so far when `wants_preview` says so for the
    /// units done.
    pub(super) fn live_view(
        &self,
        now: Duration,
        wants_preview: impl FnOnce(usize) -> bool,
    ) -> (LiveStatus, Option<Preview>) {
        let (done, total) = self.sched.progress();
        let (job, passes_done) = (self.job, self.done_rows.iter().map(|(a, b)| b - a).sum::<u32>());
        let preview = wants_preview(done).then(|| {
            let (pixels, gain) = match (job.passes, &self.rounds) {
                // A bounded render's image holds its completed rounds.
                (_, Some(rounds)) => (self.image.image_of(rounds.passes()), 1.0),
                (Some(all), None) => (self.image.image(), all as f32 / passes_done.max(1) as f32),
                (None, None) => (self.image.image(), 1.0),
            };
            Preview { image: photon_core::image_io::Image { width: job.width, height: job.height, pixels }, gain }
        });
        let render_s = self.first_ready.map_or(0.0, |t| now.saturating_sub(t).as_secs_f64());
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
            elapsed_s: now.as_secs_f64(),
            // A bounded render's end is its deadline (its units grow round by round).
            eta_s: match &self.rounds {
                Some(rounds) => rounds.remaining().map(|d| d.as_secs_f64()),
                None => live::eta_s(render_s, done - self.resumed.min(done), total - done),
            },
            units: self.units_word().into(),
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
        (status, preview)
    }
}
