//! What a render keeps across an interruption: the finished units of a partial file taken back in
//! (`--resume`), and the partial file a stopped render leaves.

use super::scheduler::StripId;
use super::state::Farm;
use super::types::FarmError;
use crate::job::Partial;
use std::ops::Range;

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
