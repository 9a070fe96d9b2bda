//! Workers that come back: a worker lost during a render is called again with exponential backoff
//! ([`Backoff`]) until it answers, and rejoins after the same hello and build-id check as at the start, with the
//! job's blobs shipped again where it lacks them (a restarted worker has an empty cache).

use crate::fleet::session::{self, Ready, SessionError, WorkerAddr};
use crate::job::Job;
use std::time::Duration;

/// The first wait before a lost worker is called again.
pub const FIRST_RETRY: Duration = Duration::from_millis(250);

/// The longest wait between two calls of a lost worker.
pub const MAX_RETRY: Duration = Duration::from_secs(5);

/// Exponential backoff: [`FIRST_RETRY`], doubling each time, capped at [`MAX_RETRY`].
#[derive(Clone, Debug)]
pub struct Backoff {
    next: Duration,
}

impl Backoff {
    /// A schedule that starts at [`FIRST_RETRY`].
    pub fn new() -> Self {
        Self { next: FIRST_RETRY }
    }

    /// The next wait.
    pub fn next_wait(&mut self) -> Duration {
        let wait = self.next;
        self.next = (wait * 2).min(MAX_RETRY);
        wait
    }
}

impl Default for Backoff {
    fn default() -> Self {
        Self::new()
    }
}

impl Iterator for Backoff {
    type Item = Duration;

    /// The next wait; the schedule never ends.
    fn next(&mut self) -> Option<Duration> {
        Some(self.next_wait())
    }
}

/// Whether a failed call of a lost worker is worth repeating: `false` when the worker answered and said no
/// (another build or protocol, a wrong token, a blob it cannot take) or the address itself is wrong, `true`
/// when it did not answer (not listening yet, no hello, a broken upload).
pub fn worth_retrying(e: &SessionError) -> bool {
    match e {
        SessionError::BadToken
        | SessionError::BadAddress { .. }
        | SessionError::UnknownBlob(_)
        | SessionError::BlobTooLarge { .. } => false,
        SessionError::Refused { code, .. } => session::unanswered(*code),
        SessionError::Connect { .. }
        | SessionError::HelloTimeout
        | SessionError::BlobListTimeout
        | SessionError::BlobList(_)
        | SessionError::ShipTimeout { .. }
        | SessionError::Ship { .. } => true,
    }
}

/// Calls the lost worker at `addr` with backoff until it is ready again (`Ok`) or answers with a refusal that
/// another call would not change (`Err`). Each call tries to connect once.
pub async fn call_back(
    addr: &WorkerAddr,
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
    job: &Job,
) -> Result<Ready, SessionError> {
    let mut backoff = Backoff::new();
    loop {
        tokio::time::sleep(backoff.next_wait()).await;
        match session::open_with_patience(addr, token, tls_ca, job, Duration::ZERO).await {
            Ok(ready) => return Ok(ready),
            Err(e) if worth_retrying(&e) => tracing::debug!(worker = %addr.name, "not back yet: {e}"),
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backoff_doubles_from_a_quarter_second_to_five_seconds() {
        let waits: Vec<f64> = Backoff::new().take(8).map(|d| d.as_secs_f64()).collect();
        assert_eq!(waits, [0.25, 0.5, 1.0, 2.0, 4.0, 5.0, 5.0, 5.0]);
        // A worker back after a minute is called within MAX_RETRY of its return.
        let mut t = 0.0;
        let calls: Vec<f64> = Backoff::new()
            .map(|d| {
                t += d.as_secs_f64();
                t
            })
            .take_while(|&t| t < 70.0)
            .collect();
        let first_after = calls.iter().find(|&&c| c >= 60.0).copied().unwrap_or(f64::INFINITY);
        assert!(first_after - 60.0 <= MAX_RETRY.as_secs_f64(), "{calls:?}");
    }

    #[test]
    fn only_a_silent_worker_is_called_again() {
        let connect = SessionError::Connect { uri: "http://a:1".into(), chain: "refused".into(), hint: "" };
        assert!(worth_retrying(&connect));
        assert!(worth_retrying(&SessionError::HelloTimeout));
        let build = SessionError::Refused {
            status: "build abc is not this worker's build def".into(),
            code: tonic::Code::FailedPrecondition,
            hint: "",
        };
        assert!(!worth_retrying(&build));
        let gone = SessionError::Refused { status: "transport".into(), code: tonic::Code::Unavailable, hint: "" };
        assert!(worth_retrying(&gone));
        assert!(!worth_retrying(&SessionError::BlobTooLarge { size: 10, limit: 1 }));
    }
}
