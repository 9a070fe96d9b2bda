//! Blobs in and out of a worker: uploads received (`PutBlob`), blobs fetched from a peer (`FetchBlob`) and served
//! to peers (`GetBlob`), and which of a list are missing (`MissingBlobs`). Every transfer is checked as it
//! arrives: the announced id and size, each chunk against the upload budget, the whole blob against a minimum
//! rate, and the bytes against their id.

use crate::service::Worker;
use photon_proto::pb;
use photon_proto::transport::SERVED_AT_ONCE;
use photon_proto::{MAX_CHUNK, MAX_MESSAGE, quote};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Status, Streaming};

/// The most ids one `MissingBlobs` request may list.
const MAX_LISTED: usize = 1024;

/// Refuses what is not a blob id (64 lowercase hex digits), quoting it.
fn check_blob_id(id: &str) -> Result<(), Status> {
    if photon_proto::is_blob_id(id) {
        Ok(())
    } else {
        Err(Status::invalid_argument(format!("{} is not a blob id (64 lowercase hex digits)", quote(id))))
    }
}

/// The next chunk of an upload, waiting at most `idle` for it and never past `deadline`.
async fn next_chunk(
    stream: &mut Streaming<pb::BlobChunk>,
    deadline: Instant,
    idle: Duration,
) -> Result<Option<pb::BlobChunk>, Status> {
    let now = Instant::now();
    let wait = idle.min(deadline.saturating_duration_since(now));
    match tokio::time::timeout(wait, stream.message()).await {
        Ok(Ok(chunk)) => Ok(chunk),
        // The sender's own words (a peer's, when fetching), quoted like every received value.
        Ok(Err(s)) => Err(Status::new(s.code(), format!("the sender's stream failed: {}", quote(s.message())))),
        Err(_) if wait < idle => Err(Status::deadline_exceeded(
            "the upload is too slow: a blob must arrive within the idle time plus its size over the minimum rate \
             (photon-worker --upload-idle-s, --upload-min-kib-s)",
        )),
        Err(_) => Err(Status::deadline_exceeded(format!(
            "no chunk of the upload for {} s (photon-worker --upload-idle-s)",
            idle.as_secs_f64()
        ))),
    }
}

impl Worker {
    /// The longest a blob of `bytes` may take to arrive or to be read: the idle time plus its size over the
    /// minimum rate ([`crate::Config::upload_idle`], [`crate::Config::upload_min_rate`]).
    fn transfer_allowance(&self, bytes: u64) -> Duration {
        self.config.upload_idle + Duration::from_secs_f64(bytes as f64 / self.config.upload_min_rate.max(1) as f64)
    }

    /// Checks a blob's announced id and size.
    fn check_blob_header(&self, header: &pb::BlobHeader) -> Result<(), Status> {
        check_blob_id(&header.id)?;
        if header.size > self.config.max_blob_bytes {
            return Err(Status::resource_exhausted(format!(
                "blob {} of {} bytes exceeds this worker's limit of {} bytes (photon-worker --max-blob-mib)",
                header.id, header.size, self.config.max_blob_bytes
            )));
        }
        Ok(())
    }

    /// Receives a blob's stream (an upload, or a peer's answer to `GetBlob`) and stores it; returns the bytes
    /// stored (0 when the blob was held already). The stream must announce `expected` when given. Every chunk is
    /// reserved from the upload budget as it arrives and the whole blob must come within the idle time plus its
    /// size over the minimum rate; the bytes must hash to the id.
    pub(crate) async fn receive_blob(
        &self,
        stream: &mut Streaming<pb::BlobChunk>,
        expected: Option<&pb::BlobHeader>,
    ) -> Result<u64, Status> {
        let idle = self.config.upload_idle;
        let Some(first) = next_chunk(stream, Instant::now() + idle, idle).await? else {
            return Err(Status::invalid_argument("empty upload: the first chunk must carry the blob's header"));
        };
        let Some(header) = first.header else {
            return Err(Status::invalid_argument("the first chunk of an upload must carry the blob's header"));
        };
        if let Some(asked) = expected
            && *asked != header
        {
            return Err(Status::data_loss(format!(
                "the peer sent blob {} of {} bytes, not the one asked for",
                quote(&header.id),
                header.size
            )));
        }
        self.check_blob_header(&header)?;
        if self.blobs.contains(&header.id) {
            return Ok(0);
        }
        // The whole upload must keep a minimum rate, so a client that sends a byte now and then (never idle
        // long enough for the idle timeout) cannot keep its bytes reserved for ever.
        let deadline = Instant::now() + self.transfer_allowance(header.size);
        let size = header.size as usize;
        // Grow with what arrives rather than trusting the announced size with one allocation; every chunk's bytes
        // are reserved from the upload budget as they arrive, and nothing is held while waiting for the network
        // but the bytes already received.
        let mut bytes: Vec<u8> = Vec::new();
        let mut reserved: Option<tokio::sync::OwnedSemaphorePermit> = None;
        let mut hasher = photon_proto::Hasher::new();
        let mut chunk = first.data;
        loop {
            if chunk.len() > MAX_CHUNK {
                return Err(Status::invalid_argument(format!(
                    "a chunk of {} bytes; chunks are at most {MAX_CHUNK} bytes",
                    chunk.len()
                )));
            }
            if bytes.len() + chunk.len() > size {
                return Err(Status::invalid_argument(format!(
                    "blob {} announced {size} bytes and sent more",
                    header.id
                )));
            }
            self.reserve_upload(&mut reserved, chunk.len())?;
            hasher.update(&chunk);
            bytes.extend_from_slice(&chunk);
            match next_chunk(stream, deadline, idle).await? {
                Some(next) if next.header.is_some() => {
                    return Err(Status::invalid_argument("only the first chunk of an upload carries a header"));
                }
                Some(next) => chunk = next.data,
                None => break,
            }
        }
        if bytes.len() != size {
            return Err(Status::invalid_argument(format!(
                "blob {} truncated: {} of the announced {size} bytes arrived",
                header.id,
                bytes.len()
            )));
        }
        let hash = hasher.finalize().to_hex().to_string();
        if hash != header.id {
            return Err(Status::data_loss(format!("blob {} arrived with bytes that hash to {hash}", header.id)));
        }
        let stored = bytes.len() as u64;
        self.blobs.insert(header.id, Arc::new(bytes));
        Ok(stored)
    }

    /// Calls `GetBlob` for `id` on the peer at `peer` (`host:port` or a URI), with this worker's token, over TLS
    /// trusting `tls_ca` when it is not empty.
    async fn open_peer_blob(&self, peer: &str, tls_ca: &[u8], id: &str) -> Result<Streaming<pb::BlobChunk>, Status> {
        const MAX_PEER_URI: usize = 512;
        const MAX_CA_BYTES: usize = 64 << 10;
        if peer.len() > MAX_PEER_URI || tls_ca.len() > MAX_CA_BYTES {
            return Err(Status::invalid_argument(format!(
                "a peer address of at most {MAX_PEER_URI} bytes and a CA certificate of at most {MAX_CA_BYTES} bytes"
            )));
        }
        let tls_ca = (!tls_ca.is_empty()).then_some(tls_ca);
        let uri = photon_proto::transport::worker_uri(peer, tls_ca.is_some());
        if !(uri.starts_with("http://") || uri.starts_with("https://")) {
            return Err(Status::invalid_argument(format!(
                "a peer is `host:port` or an http(s) URI, not {}",
                quote(peer)
            )));
        }
        let endpoint = photon_proto::transport::client_endpoint(&uri, tls_ca)
            .map_err(|e| Status::invalid_argument(format!("bad peer address {}: {e}", quote(peer))))?;
        let channel =
            endpoint.connect().await.map_err(|e| Status::aborted(format!("cannot reach peer {}: {e}", quote(peer))))?;
        let mut client = pb::render_client::RenderClient::new(channel)
            .max_decoding_message_size(MAX_MESSAGE)
            .max_encoding_message_size(MAX_MESSAGE);
        let mut request = Request::new(pb::GetBlobRequest { id: id.to_owned() });
        if let Some(token) = &self.config.token {
            let value = tonic::metadata::MetadataValue::try_from(photon_proto::bearer(token))
                .map_err(|_| Status::internal("this worker's token cannot travel in a header"))?;
            request.metadata_mut().insert(photon_proto::TOKEN_KEY, value);
        }
        let answer = tokio::time::timeout(self.config.upload_idle, client.get_blob(request))
            .await
            .map_err(|_| Status::aborted(format!("peer {} did not answer", quote(peer))))?
            .map_err(|s| {
                Status::aborted(format!("peer {} refused ({:?}): {}", quote(peer), s.code(), quote(s.message())))
            })?;
        Ok(answer.into_inner())
    }

    /// Adds `n` bytes to an upload's reservation from the upload budget.
    fn reserve_upload(&self, reserved: &mut Option<tokio::sync::OwnedSemaphorePermit>, n: usize) -> Result<(), Status> {
        let Ok(n) = u32::try_from(n) else {
            return Err(Status::invalid_argument("a chunk larger than 4 GiB"));
        };
        if n == 0 {
            return Ok(());
        }
        let permit = self.upload_bytes.clone().try_acquire_many_owned(n).map_err(|_| {
            Status::resource_exhausted(format!(
                "uploads in progress hold this worker's upload memory ({} bytes); try again when they finish",
                self.config.upload_budget_bytes
            ))
        })?;
        match reserved {
            Some(r) => r.merge(permit),
            None => *reserved = Some(permit),
        }
        Ok(())
    }

    /// `MissingBlobs`: which of the listed blobs this worker lacks.
    pub(crate) fn missing(&self, ids: Vec<String>) -> Result<pb::MissingBlobsReply, Status> {
        if ids.len() > MAX_LISTED {
            return Err(Status::invalid_argument(format!(
                "{} blob ids in one request; at most {MAX_LISTED}",
                ids.len()
            )));
        }
        let mut missing = Vec::new();
        for id in ids {
            check_blob_id(&id)?;
            if !self.blobs.contains(&id) {
                missing.push(id);
            }
        }
        Ok(pb::MissingBlobsReply { missing })
    }

    /// `FetchBlob`: fetches a blob from the peer the coordinator names, unless it is held here already; returns
    /// the bytes stored.
    pub(crate) async fn fetch(&self, r: pb::FetchBlobRequest) -> Result<u64, Status> {
        let Some(blob) = r.blob else {
            return Err(Status::invalid_argument("a fetch must name the blob: its id and size"));
        };
        self.check_blob_header(&blob)?;
        if self.blobs.contains(&blob.id) {
            return Ok(0);
        }
        if self.config.tls.is_some() && r.tls_ca.is_empty() {
            return Err(Status::failed_precondition(
                "this worker speaks TLS and fetches from peers over TLS only: the fetch must carry the farm's CA",
            ));
        }
        let mut stream = self.open_peer_blob(&r.peer, &r.tls_ca, &blob.id).await?;
        self.receive_blob(&mut stream, Some(&blob)).await.map_err(|s| {
            // Out of upload memory is this worker's state; anything else went wrong with the peer or its bytes.
            let code = if s.code() == tonic::Code::ResourceExhausted { s.code() } else { tonic::Code::Aborted };
            Status::new(code, format!("fetching blob {} from {}: {}", blob.id, quote(&r.peer), s.message()))
        })
    }

    /// `GetBlob`: streams a held blob to a peer, at most [`SERVED_AT_ONCE`] at a time, within the transfer
    /// allowance of its size.
    pub(crate) fn serve_blob(
        &self,
        request: Request<pb::GetBlobRequest>,
    ) -> Result<ReceiverStream<Result<pb::BlobChunk, Status>>, Status> {
        let call = self.peers.admit(request.remote_addr())?;
        let id = request.into_inner().id;
        check_blob_id(&id)?;
        let Ok(serving) = self.serving.clone().try_acquire_owned() else {
            return Err(Status::resource_exhausted(format!(
                "this worker already serves {SERVED_AT_ONCE} blobs to peers; try another source"
            )));
        };
        let Some(blob) = self.blobs.get(&id) else {
            return Err(Status::not_found(format!("blob {id} is not held here")));
        };
        // A reader that stops reading must not hold the blob and the call for ever: the whole blob goes within
        // the same allowance as an upload (idle time plus its size over the minimum rate), or the call ends.
        let deadline = tokio::time::Instant::now() + self.transfer_allowance(blob.len() as u64);
        let header = pb::BlobHeader { id, size: blob.len() as u64 };
        let chunks = photon_proto::blob_chunks(header, blob);
        #[cfg(feature = "fault-injection")]
        let chunks = self.faults.served_chunks(chunks);
        let (tx, rx) = mpsc::channel(3);
        tokio::spawn(async move {
            let _held = (call, serving);
            for chunk in chunks {
                // A chunk goes only when two places are free, so one is always left for the error.
                let Ok(Ok(mut places)) = tokio::time::timeout_at(deadline, tx.reserve_many(2)).await else {
                    let late = Status::deadline_exceeded("the blob was not read within its allowance");
                    let _ = tx.try_send(Err(late));
                    return;
                };
                if let Some(place) = places.next() {
                    place.send(Ok(chunk));
                }
            }
        });
        Ok(ReceiverStream::new(rx))
    }
}
