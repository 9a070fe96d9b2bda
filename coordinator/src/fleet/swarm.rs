//! Blobs passed among the workers (`--photon-maps peers`): the coordinator uploads a big blob to one worker at a
//! time, and every worker that holds it serves one other at a time (`FetchBlob` on the receiver, `GetBlob` on
//! the holder). The holders double with each round, so N workers hold a blob of B bytes after about
//! ⌈log₂(N+1)⌉ transfers of B bytes on separate links, instead of N transfers through the coordinator's link.
//!
//! A fetch that fails through the holder's fault (the worker answers `ABORTED`: the holder cannot be reached,
//! refuses, or sends bytes that do not hash to the id) drops that holder and the receiver takes the next source.
//! A fetch that fails through the receiver's fault (any other status, or no answer in time) keeps the holder and
//! the receiver gets the blob from the coordinator. The coordinator is always a source, so a blob reaches every
//! worker that can take it as long as the coordinator can upload it. Bytes are checked by their hash on arrival
//! whoever sent them. A transfer holds its source through a [`Lease`], released however the transfer ends.

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

/// How a transfer ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The receiver holds the blob now and serves it from now on.
    Delivered,
    /// The source failed (a peer that is gone, refuses or sends bad bytes): it is no longer offered.
    SourceFailed,
    /// The receiver failed, or the transfer was abandoned: the source is free again.
    ReceiverFailed,
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

/// A source held for one transfer of a blob to one receiver; dropping it unfinished frees the source as
/// [`Outcome::ReceiverFailed`] does (a session that is cancelled never leaves a source busy).
#[derive(Debug)]
pub struct Lease<'a> {
    swarm: &'a Swarm,
    id: String,
    receiver: String,
    source: Source,
    ended: bool,
}

impl Lease<'_> {
    /// Where the receiver gets the blob from.
    pub fn source(&self) -> &Source {
        &self.source
    }

    /// Ends the transfer.
    pub fn end(mut self, outcome: Outcome) {
        self.ended = true;
        self.swarm.release(&self.id, &self.source, &self.receiver, outcome);
    }
}

impl Drop for Lease<'_> {
    fn drop(&mut self) {
        if !self.ended {
            self.swarm.release(&self.id, &self.source, &self.receiver, Outcome::ReceiverFailed);
        }
    }
}

impl Swarm {
    /// A swarm whose workers speak TLS trusting `tls_ca` (plaintext when `None`).
    pub fn new(tls_ca: Option<Vec<u8>>) -> Self {
        Self { tls_ca, ..Self::default() }
    }

    /// Waits for a free source of blob `id` for the worker at `receiver`: a holder not sending (when `peers`),
    /// or else the coordinator when it is not uploading. The source is busy until the lease ends.
    pub async fn lease(&self, id: &str, receiver: &str, peers: bool) -> Lease<'_> {
        loop {
            let changed = self.changed.notified();
            tokio::pin!(changed);
            changed.as_mut().enable();
            if let Some(source) = self.try_source(id, receiver, peers) {
                return Lease { swarm: self, id: id.to_owned(), receiver: receiver.to_owned(), source, ended: false };
            }
            changed.await;
        }
    }

    fn try_source(&self, id: &str, receiver: &str, peers: bool) -> Option<Source> {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        if peers
            && let Some(holders) = state.holders.get_mut(id)
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

    fn release(&self, id: &str, source: &Source, receiver: &str, outcome: Outcome) {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let holders = state.holders.entry(id.to_owned()).or_default();
        match source {
            Source::Coordinator => {}
            Source::Peer(uri) if outcome == Outcome::SourceFailed => holders.retain(|(u, _)| u != uri),
            Source::Peer(uri) => holders.iter_mut().filter(|(u, _)| u == uri).for_each(|h| h.1 = false),
        }
        if outcome == Outcome::Delivered && !holders.iter().any(|(u, _)| u == receiver) {
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

    /// Takes a source now, or `None` when every source is busy.
    fn now<'a>(swarm: &'a Swarm, receiver: &str, peers: bool) -> Option<Lease<'a>> {
        let source = swarm.try_source("b", receiver, peers)?;
        Some(Lease { swarm, id: "b".into(), receiver: receiver.into(), source, ended: false })
    }

    /// Rounds of transfers until `n` receivers hold the blob, each transfer taking one round.
    fn rounds(n: usize) -> usize {
        let swarm = Swarm::new(None);
        let receivers: Vec<String> = (0..n).map(|i| format!("http://w{i}:1")).collect();
        let mut waiting: Vec<&String> = receivers.iter().collect();
        let mut round = 0;
        while !waiting.is_empty() {
            round += 1;
            let mut transfers = Vec::new();
            waiting.retain(|r| match now(&swarm, r, true) {
                Some(lease) => {
                    transfers.push(lease);
                    false
                }
                None => true,
            });
            transfers.into_iter().for_each(|lease| lease.end(Outcome::Delivered));
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
    fn a_failed_holder_is_dropped_a_failed_receiver_is_not_blamed_and_the_coordinator_remains() {
        let swarm = Swarm::new(None);
        let first = now(&swarm, "a", true).unwrap();
        assert_eq!(first.source(), &Source::Coordinator);
        first.end(Outcome::Delivered);
        // "a" serves "b"; the coordinator is free for a third.
        let from_a = now(&swarm, "b", true).unwrap();
        assert_eq!(from_a.source(), &Source::Peer("a".into()));
        let to_c = now(&swarm, "c", true).unwrap();
        assert_eq!(to_c.source(), &Source::Coordinator);
        // "b" fails by its own fault: "a" is free again, and "d" may take it.
        from_a.end(Outcome::ReceiverFailed);
        let for_d = now(&swarm, "d", true).unwrap();
        assert_eq!(for_d.source(), &Source::Peer("a".into()));
        // "a" fails as a source: it is no longer offered, and "b" waits for the coordinator.
        for_d.end(Outcome::SourceFailed);
        assert!(now(&swarm, "b", true).is_none());
        to_c.end(Outcome::Delivered);
        // Without peers (after its own failure), "b" takes the coordinator even though "c" is free.
        let b = now(&swarm, "b", false).unwrap();
        assert_eq!(b.source(), &Source::Coordinator);
        drop(b);
        assert_eq!(now(&swarm, "b", true).unwrap().source(), &Source::Peer("c".into()));
        // A worker is never its own source, and another blob has its own holders.
        assert_eq!(swarm.try_source("other", "c", true), Some(Source::Coordinator));
    }

    #[test]
    fn a_dropped_lease_frees_its_source() {
        let swarm = Swarm::new(None);
        let lease = now(&swarm, "a", true).unwrap();
        assert!(now(&swarm, "b", true).is_none());
        drop(lease);
        assert_eq!(now(&swarm, "b", true).unwrap().source(), &Source::Coordinator);
    }

    #[tokio::test]
    async fn a_waiting_receiver_wakes_when_a_source_frees() {
        let swarm = std::sync::Arc::new(Swarm::new(None));
        let first = swarm.lease("b", "a", true).await;
        assert_eq!(first.source(), &Source::Coordinator);
        let waiter = tokio::spawn({
            let swarm = swarm.clone();
            async move { swarm.lease("b", "b", true).await.source().clone() }
        });
        tokio::task::yield_now().await;
        assert!(!waiter.is_finished());
        first.end(Outcome::Delivered);
        let got = tokio::time::timeout(std::time::Duration::from_secs(5), waiter).await.unwrap().unwrap();
        assert_eq!(got, Source::Peer("a".into()));
    }
}
