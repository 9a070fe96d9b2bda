//! What a render is asked for ([`Options`]) and how it can fail ([`FarmError`]): the farm's types, apart from
//! its loop and its state so that neither names the other.

use super::scheduler::Policy;
use crate::fleet::interrupt::{Interrupt, Interrupts};
use crate::fleet::session::Greeting;
use crate::job::Partial;
use crate::out::report::WorkerReport;
use std::path::PathBuf;
use std::time::Duration;

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
    /// blocks ([`crate::job::Job::passes`]).
    pub bound: Option<crate::farm::bounded::Bound>,
    /// Where the render's state is published for the live page (`render --serve`), if anywhere.
    pub live: Option<std::sync::Arc<crate::out::live::Board>>,
    /// The workers greeted earlier in this render ([`crate::fleet::greet`]), by their index in the workers
    /// rendered on: their sessions go on from the greeting, without a second hello. The others (all of them
    /// when this is empty) are greeted by their sessions.
    pub greetings: Vec<Option<Greeting>>,
    /// Where and how often the finished units are written while the render runs, so that a coordinator killed
    /// at any moment (SIGKILL, the OOM killer, a power cut) can be resumed from its last checkpoint; `None`: no
    /// checkpoints (a render bounded by time or error, which cannot be resumed).
    pub checkpoint: Option<Checkpoint>,
    /// A bounded render that goes on from where an earlier one of the same job stopped (`--integrator auto`
    /// continues its pilot): its rounds and image are kept, under [`Options::bound`].
    pub continuation: Option<crate::farm::bounded::Continuation>,
}

/// Checkpoints of a render's finished units ([`Options::checkpoint`]).
#[derive(Clone, Debug)]
pub struct Checkpoint {
    /// The partial file (`OUTPUT.partial`, which `--resume` reads).
    pub path: PathBuf,
    /// The least time between two checkpoints. It grows to 50 times the last write's duration, so that writing
    /// checkpoints takes at most 2 % of the render's time whatever the image's size and the disk.
    pub every: Duration,
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
            greetings: Vec::new(),
            checkpoint: None,
            continuation: None,
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
