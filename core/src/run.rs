//! What bounds one run besides its settings: a stop flag that someone outside the run sets ([`Cancel`]), and
//! the bytes that the photons, light vertices and light-tracing splats one tracing run stores may take
//! ([`Guard::storage_bytes`], counted by a [`Meter`]).
//!
//! Both are checked at a fine grain, so a run stops soon after either trips: the cancel flag before every
//! photon path, light subpath and camera sample, the storage after every path. What a path stores is added
//! to one shared count, so a run fails on its storage exactly when the whole run would store more than its
//! bound, whatever the threads: a run's outcome never depends on the machine's parallelism.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// A stop flag: set once from outside a run ([`Cancel::cancel`]), read by the run's loops.
#[derive(Debug, Default)]
pub struct Cancel(AtomicBool);

impl Cancel {
    /// A flag not set.
    pub const fn new() -> Self {
        Self(AtomicBool::new(false))
    }

    /// Asks the run to stop; it returns [`RunError::Cancelled`] soon after.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether [`Cancel::cancel`] was called.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// `Err(Cancelled)` once the flag is set.
    pub fn check(&self) -> Result<(), RunError> {
        if self.is_cancelled() { Err(RunError::Cancelled) } else { Ok(()) }
    }
}

/// A flag that nobody sets: for runs that are never cancelled (tests, benchmarks, examples).
pub static NEVER: Cancel = Cancel::new();

/// What a run checks besides its settings.
#[derive(Clone, Copy, Debug)]
pub struct Guard<'a> {
    /// The run's stop flag.
    pub cancel: &'a Cancel,
    /// Bytes that what one tracing run stores (photons, light vertices, splats) may take; the machine's memory
    /// budget ([`Guard::machine`] on the coordinator, `photon-worker --strip-memory-mib` on a worker).
    pub storage_bytes: u64,
}

impl Guard<'static> {
    /// Never cancelled, with no storage bound: tests, benchmarks and examples of known size.
    pub fn unbounded() -> Self {
        Self { cancel: &NEVER, storage_bytes: u64::MAX }
    }
}

impl<'a> Guard<'a> {
    /// The guard of a run on this machine: storage up to half its physical memory (all of it where the
    /// memory cannot be read), as a worker's default strip budget.
    pub fn machine(cancel: &'a Cancel) -> Self {
        Self { cancel, storage_bytes: half_the_memory() }
    }

    /// A meter for one tracing run of `what` (its storage, for messages), bounded by [`Guard::storage_bytes`].
    pub fn meter(&self, what: &'static str, setting: &'static str, max_depth: u32) -> Meter {
        Meter { used: AtomicU64::new(0), bound: self.storage_bytes, what, setting, max_depth }
    }
}

/// The bytes one tracing run has stored, against its bound.
#[derive(Debug)]
pub struct Meter {
    used: AtomicU64,
    bound: u64,
    what: &'static str,
    setting: &'static str,
    max_depth: u32,
}

impl Meter {
    /// Adds `bytes` that a path stored; [`RunError::Storage`] when the run's total passes the bound.
    pub fn add(&self, bytes: u64) -> Result<(), RunError> {
        let before = self.used.fetch_add(bytes, Ordering::Relaxed);
        if before.saturating_add(bytes) > self.bound { Err(self.error()) } else { Ok(()) }
    }

    /// [`RunError::Storage`] once the run has passed its bound (another thread's path did), so the others
    /// stop too.
    pub fn check(&self) -> Result<(), RunError> {
        if self.used.load(Ordering::Relaxed) > self.bound { Err(self.error()) } else { Ok(()) }
    }

    /// The error of a run over its bound.
    pub fn error(&self) -> RunError {
        RunError::Storage(StorageError {
            what: self.what,
            setting: self.setting,
            bound: self.bound,
            max_depth: self.max_depth,
        })
    }
}

/// The words every [`StorageError`] message holds, by which a caller that has only the message (a status from
/// a worker) knows it.
pub const STORAGE_CAPPED: &str = "storage capped at";

/// Why a run stopped before its end.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RunError {
    /// Its [`Cancel`] flag was set.
    #[error("cancelled")]
    Cancelled,
    /// It would have stored more than its memory allows.
    #[error(transparent)]
    Storage(#[from] StorageError),
}

/// A tracing run that would store more than its memory allows: in a closed room of albedo near 1 Russian
/// roulette seldom ends a path, so paths run to `render.max_depth` and store a photon (or vertex) at every bounce,
/// several times the usual few per path that the memory estimate assumes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "{what} {capped} {}: the paths store more (they may bounce up to render.max_depth = {max_depth} \
     times); lower render.max_depth or {setting}, or give the run more memory (photon-worker --strip-memory-mib)",
    gib(*bound),
    capped = STORAGE_CAPPED
)]
pub struct StorageError {
    /// What is stored, e.g. `photon`.
    pub what: &'static str,
    /// The setting that decides how many paths are traced.
    pub setting: &'static str,
    /// Bytes the run may store.
    pub bound: u64,
    /// The scene's `render.max_depth`.
    pub max_depth: u32,
}

/// `bytes` in GiB or MiB, for messages.
pub fn gib(bytes: u64) -> String {
    if bytes >= 1 << 30 {
        format!("{:.1} GiB", bytes as f64 / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
    }
}

/// Half this machine's physical memory in bytes (`u64::MAX` where it cannot be read): the memory one run, or
/// one strip on a worker, may take by default.
pub fn half_the_memory() -> u64 {
    machine_memory().map_or(u64::MAX, |m| if m == 0 { u64::MAX } else { m / 2 })
}

/// The machine's physical memory in bytes, from `/proc/meminfo` (`MemTotal`); `None` where it cannot be read.
pub fn machine_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map(|kib| kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn a_meter_fails_exactly_when_the_total_passes_its_bound_whatever_the_order() {
        let cancel = Cancel::new();
        let guard = Guard { cancel: &cancel, storage_bytes: 1000 };
        let within = guard.meter("photon", "render.photons.global", 16);
        assert!((0..100u64).into_par_iter().all(|_| within.add(10).is_ok()));
        assert_eq!(within.check(), Ok(()));
        let over = guard.meter("photon", "render.photons.global", 16);
        let failed = (0..101u64).into_par_iter().filter(|_| over.add(10).is_err()).count();
        assert_eq!(failed, 1, "exactly the addition that passes the bound fails");
        assert_eq!(over.check(), Err(over.error()));
        let msg = over.error().to_string();
        assert!(msg.contains("render.max_depth = 16") && msg.contains("render.photons.global"), "{msg}");
    }

    #[test]
    fn cancel_is_seen() {
        let cancel = Cancel::new();
        assert_eq!(cancel.check(), Ok(()));
        cancel.cancel();
        assert_eq!(cancel.check(), Err(RunError::Cancelled));
        assert!(!NEVER.is_cancelled());
    }
}
