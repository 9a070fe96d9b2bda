//! The cap on calls in progress per peer ([`PeerCalls`], [`crate::Config::max_calls_per_peer`]).

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};
use tonic::Status;

/// Calls in progress per remote IP address, capped.
#[derive(Debug)]
pub(crate) struct PeerCalls {
    cap: usize,
    calls: Mutex<HashMap<IpAddr, usize>>,
}

/// One admitted call; its peer's count goes down when it drops.
pub(crate) struct PeerCall {
    peers: Arc<PeerCalls>,
    ip: Option<IpAddr>,
}

impl PeerCalls {
    /// At most `cap` calls per peer (at least one).
    pub(crate) fn new(cap: usize) -> Self {
        Self { cap: cap.max(1), calls: Mutex::new(HashMap::new()) }
    }

    /// Admits a call from `peer`, or refuses it when the peer has `cap` calls in progress already. A call whose
    /// peer is unknown (not over TCP) is not counted.
    pub(crate) fn admit(self: &Arc<Self>, peer: Option<SocketAddr>) -> Result<PeerCall, Status> {
        let ip = peer.map(|p| p.ip());
        if let Some(ip) = ip {
            let mut calls = self.calls.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            let n = calls.entry(ip).or_insert(0);
            if *n >= self.cap {
                return Err(Status::resource_exhausted(format!(
                    "{ip} already has {} calls in progress here, the most one peer may have \
                     (photon-worker --max-calls-per-peer)",
                    self.cap
                )));
            }
            *n += 1;
        }
        Ok(PeerCall { peers: self.clone(), ip })
    }
}

impl Drop for PeerCall {
    fn drop(&mut self) {
        let Some(ip) = self.ip else { return };
        let mut calls = self.peers.calls.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(n) = calls.get_mut(&ip) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                calls.remove(&ip);
            }
        }
    }
}
