//! Blobs passed among the workers (`--photon-maps peers`): the coordinator uploads a big blob to one worker at a
//! time, and every worker that holds it serves one other at a time (`FetchBlob` on the receiver, `GetBlob` on
//! the holder). The holders double with each round, so N workers hold a blob of B bytes after about
//! ⌈log₂(N+1)⌉ transfers of B bytes on separate links, instead of N transfers through the coordinator's link.
//!
//! A fetch that fails (the holder is gone, or refuses) drops that holder and the receiver takes the next source;
//! the coordinator is always one, so a blob reaches every worker that can take it as long as the coordinator
//! can upload it. Bytes are checked by their hash on arrival whoever sent them.

use std::collections::BTreeMap;
use std::sync::{Mutex, PoisonError};
use tokio::sync::Notify;

/// Blobs smaller than this travel from the coordinator as usual: a peer's connection costs more than they do.
pub const MIN_PEER_BYTES: usize = photon_proto::MAX_CHUNK;

/// Uploads the coordinator runs at once for blobs passed among workers: one, so that the first holder is ready
/// as soon as possible and the coordinator's link is not split.
const COORDINATOR_UPLOADS: usize = 1;

/// Where a worker gets a blob from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// Uploaded by the coordinator.
    Coordinator,
    /// Fetched from the worker at this URI.
    Peer(String),
}

/// Who holds which blob, and who is busy sending.
#[derive(Debug, Default)]
pub struct Swarm {
    state: Mutex<State>,
    changed: Notify,
    /// The CA the workers verify each other with (the coordinator's `--tls-ca`); `None` for plaintext.
    pub tls_ca: Option<Vec<u8>>,
}

#[derive(Debug, Default)]
struct State {
    /// Per blob id: the workers holding it, and whether each is sending it now.
    holders: BTreeMap<String, Vec<(String, bool)>>,
    uploads: usize,
}

impl Swarm {
    /// A swarm whose workers speak TLS trusting `tls_ca` (plaintext when `None`).
    pub fn new(tls_ca: Option<Vec<u8>>) -> Self {
        Self { tls_ca, ..Self::default() }
    }

    /// Waits for a free source of blob `id` for the worker at `receiver`: a holder not sending, or else the
    /// coordinator when it is not uploading. The source is busy until [`Swarm::done`].
    pub async fn source(&self, id: &str, receiver: &str) -> Source {
        loop {
            let changed = self.changed.notified();
            tokio::pin!(changed);
            changed.as_mut().enable();
            if let Some(source) = self.try_source(id, receiver) {
                return source;
            }
            changed.await;
        }
    }

    fn try_source(&self, id: &str, receiver: &str) -> Option<Source> {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(holders) = state.holders.get_mut(id)
            && let Some((uri, busy)) = holders.iter_mut().find(|(uri, busy)| !*busy && uri != receiver)
        {
            *busy = true;
            return Some(Source::Peer(uri.clone()));
        }
        if state.uploads < COORDINATOR_UPLOADS {
            state.uploads += 1;
            return Some(Source::Coordinator);
        }
        None
    }

    /// Ends a transfer of blob `id` from `source` to `receiver`: the source is free again (a peer that failed
    /// is dropped as a holder) and, when `delivered`, the receiver holds the blob and serves it from now on.
    pub fn done(&self, id: &str, source: &Source, receiver: &str, delivered: bool) {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let holders = state.holders.entry(id.to_owned()).or_default();
        match source {
            Source::Coordinator => {}
            Source::Peer(uri) if delivered => holders.iter_mut().filter(|(u, _)| u == uri).for_each(|h| h.1 = false),
            Source::Peer(uri) => holders.retain(|(u, _)| u != uri),
        }
        if delivered && !holders.iter().any(|(u, _)| u == receiver) {
            holders.push((receiver.to_owned(), false));
        }
        if *source == Source::Coordinator {
            state.uploads -= 1;
        }
        drop(state);
        self.changed.notify_waiters();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rounds of transfers until `n` receivers hold the blob, each transfer taking one round.
    fn rounds(n: usize) -> usize {
        let swarm = Swarm::new(None);
        let receivers: Vec<String> = (0..n).map(|i| format!("http://w{i}:1")).collect();
        let mut waiting: Vec<&String> = receivers.iter().collect();
        let mut round = 0;
        while !waiting.is_empty() {
            round += 1;
            let mut transfers = Vec::new();
            waiting.retain(|r| match swarm.try_source("b", r) {
                Some(s) => {
                    transfers.push((s, *r));
                    false
                }
                None => true,
            });
            for (s, r) in transfers {
                swarm.done("b", &s, r, true);
            }
        }
        round
    }

    #[test]
    fn holders_double_every_round() {
        // One upload from the coordinator, then every holder sends to one more worker per round.
        assert_eq!(rounds(1), 1);
        assert_eq!(rounds(3), 2);
        assert_eq!(rounds(7), 3);
        assert_eq!(rounds(8), 4);
        assert_eq!(rounds(52), 6);
    }

    #[test]
    fn a_failed_holder_is_dropped_and_the_coordinator_remains() {
        let swarm = Swarm::new(None);
        assert_eq!(swarm.try_source("b", "a"), Some(Source::Coordinator));
        swarm.done("b", &Source::Coordinator, "a", true);
        // "a" serves "b"; the coordinator is free for a third.
        let from_a = Source::Peer("a".into());
        assert_eq!(swarm.try_source("b", "b"), Some(from_a.clone()));
        assert_eq!(swarm.try_source("b", "c"), Some(Source::Coordinator));
        // "a" fails: it is no longer offered, and "b" falls back to the coordinator once it is free.
        swarm.done("b", &from_a, "b", false);
        assert_eq!(swarm.try_source("b", "b"), None);
        swarm.done("b", &Source::Coordinator, "c", true);
        assert_eq!(swarm.try_source("b", "b"), Some(Source::Peer("c".into())));
        // A worker is never its own source, and another blob has its own holders.
        assert_eq!(swarm.try_source("other", "c"), Some(Source::Coordinator));
    }

    #[tokio::test]
    async fn a_waiting_receiver_wakes_when_a_source_frees() {
        let swarm = std::sync::Arc::new(Swarm::new(None));
        assert_eq!(swarm.source("b", "a").await, Source::Coordinator);
        let waiter = tokio::spawn({
            let swarm = swarm.clone();
            async move { swarm.source("b", "b").await }
        });
        tokio::task::yield_now().await;
        assert!(!waiter.is_finished());
        swarm.done("b", &Source::Coordinator, "a", true);
        let got = tokio::time::timeout(std::time::Duration::from_secs(5), waiter).await.unwrap().unwrap();
        assert_eq!(got, Source::Peer("a".into()));
    }
}
