//! What a render keeps across an interruption: the finished units of a partial file taken back in
//! (`--resume`), and the partial file a stopped render leaves.

use super::scheduler::StripId;
use super::state::Farm;
use super::types::{Checkpoint, FarmError};
use crate::job::{JobError, Partial, write_atomically};
use std::ops::Range;
use std::time::{Duration, Instant};

impl Farm<'_> {
    /// Takes the strips of a partial file that fit this job's cut.
    pub(super) fn resume(&mut self, p: &Partial) -> Result<(), FarmError> {
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

    /// The finished units and their sums, for `--resume`.
    pub(super) fn partial(&self) -> Partial {
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
}

/// A running render's checkpoints ([`Checkpoint`]): when the last one was started, how many units it held, what
/// it cost the loop, and the write in flight. The loop only takes the snapshot (a copy of the sums); a thread of
/// its own encodes it and writes it, so a slow disk delays the next checkpoint, never the render.
pub(super) struct Checkpoints {
    checkpoint: Option<Checkpoint>,
    /// When the last one was started (the render's time; its start before the first).
    last: Duration,
    /// The finished units it held (those resumed count as held: they are in the file resumed from).
    units: usize,
    /// The processor time the last one took: its snapshot here and its encoding on the writer (not the time
    /// waiting for the disk, which renders on).
    cost: Duration,
    /// The write in flight: its units, and the thread that answers its encoding time.
    writing: Option<(usize, std::thread::JoinHandle<Result<Duration, JobError>>)>,
    /// Whether a failed write was reported (once per render).
    warned: bool,
}

impl Checkpoints {
    /// The checkpoints of `farm`'s render, none when `checkpoint` is `None`.
    pub(super) fn new(checkpoint: Option<Checkpoint>, farm: &Farm) -> Self {
        let units = farm.done_rows.len();
        Self { checkpoint, last: Duration::ZERO, units, cost: Duration::ZERO, writing: None, warned: false }
    }

    /// At `now`, starts writing the finished units when some finished since the last checkpoint, its interval
    /// has passed (the interval, or 50 times the last one's processor time if that is longer) and no write is in
    /// flight. A write that fails is reported once, and tried again at the next interval: the render goes on.
    pub(super) fn at(&mut self, farm: &Farm, now: Duration) {
        if self.writing.as_ref().is_some_and(|(_, w)| !w.is_finished()) {
            return;
        }
        self.collect();
        let Some(c) = &self.checkpoint else { return };
        let done = farm.done_rows.len();
        if done == self.units || now.saturating_sub(self.last) < c.every.max(self.cost * 50) {
            return;
        }
        let t = Instant::now();
        let (partial, path) = (farm.partial(), c.path.clone());
        let snapshot = t.elapsed();
        let writer = std::thread::Builder::new().name("checkpoint".into()).spawn(move || {
            let t = Instant::now();
            let bytes = partial.encode()?;
            let encode = t.elapsed();
            write_atomically(&path, &bytes)?;
            Ok(encode)
        });
        match writer {
            Ok(w) => self.writing = Some((done, w)),
            Err(e) => self.warn(&e.to_string()),
        }
        (self.last, self.units, self.cost) = (now, done, snapshot);
    }

    /// Waits for the write in flight, if any: the render ends only once its last checkpoint is whole (a
    /// failed render then writes its partial file over it, a finished one removes it).
    pub(super) fn finish(&mut self) {
        self.collect();
    }

    /// Takes the answer of the write in flight (waiting for it), and reports it.
    fn collect(&mut self) {
        let Some((units, writer)) = self.writing.take() else { return };
        let path = self.checkpoint.as_ref().map(|c| c.path.display().to_string()).unwrap_or_default();
        match writer.join() {
            Ok(Ok(encode)) => {
                self.cost += encode;
                tracing::info!("checkpoint: {units} units in {path} ({:.1} ms of processor time)", ms(self.cost));
            }
            Ok(Err(e)) => self.warn(&e.to_string()),
            Err(_) => self.warn("its writer panicked"),
        }
    }

    fn warn(&mut self, why: &str) {
        if !self.warned {
            self.warned = true;
            eprintln!("warning: checkpoint: {why}; the render goes on, and a kill would lose its finished units");
        }
    }
}

/// A duration in milliseconds.
fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
