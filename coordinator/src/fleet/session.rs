//! One worker's session over gRPC: connect (plaintext or TLS, with the shared token), say hello, ship the blobs
//! it lacks in chunks, and fetch a strip, checking what comes back. A failed strip is classified here: a worker
//! that cannot be reached is lost; one that answered with a failure gets a [`StripFailure`] whose flags say
//! whether to retry and whether it counts against the worker.

use crate::farm::scheduler::StripFailure;
use crate::job::Job;
use photon_core::render::sums::{BlockSumsError, check_sums};
use photon_proto::pb::render_client::RenderClient;
use photon_proto::pb::{self, strip_event::Event as WireEvent};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tonic::Code;
use tonic::metadata::{AsciiMetadataValue, MetadataValue};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;

/// Where a worker is.
#[derive(Clone, Debug)]
pub struct WorkerAddr {
    /// A name for reports (the host list's, or the address).
    pub name: String,
    /// `http://host:port`.
    pub uri: String,
}

impl WorkerAddr {
    /// Whether the worker is on this machine: its host is `localhost` or a loopback address.
    pub fn is_loopback(&self) -> bool {
        let Ok(uri) = self.uri.parse::<tonic::codegen::http::Uri>() else { return false };
        let host = uri.host().unwrap_or_default().trim_start_matches('[').trim_end_matches(']');
        host == "localhost" || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
    }

    /// A worker at `address` (`host:port`, or a URI with a scheme), named `name` or after its address.
    pub fn new(address: &str, name: Option<&str>) -> Self {
        let address = address.trim();
        let uri = photon_proto::transport::worker_uri(address, false);
        Self { name: name.map_or_else(|| address.to_owned(), str::to_owned), uri }
    }
}

/// Adds the shared token to every call.
#[derive(Clone)]
pub struct Auth(Option<AsciiMetadataValue>);

impl tonic::service::Interceptor for Auth {
    fn call(&mut self, mut req: tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(v) = &self.0 {
            req.metadata_mut().insert(photon_proto::TOKEN_KEY, v.clone());
        }
        Ok(req)
    }
}

/// Why a session with a worker failed: it is refused for this render. Each message is the one the user reads.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The token cannot travel in an HTTP/2 header.
    #[error("the token must be printable ASCII")]
    BadToken,
    /// The address is not a URI.
    #[error("bad worker address {uri}: {cause}")]
    BadAddress {
        /// The worker's URI.
        uri: String,
        /// The reason.
        cause: tonic::transport::Error,
    },
    /// No connection within the patience.
    #[error("cannot connect to {uri}: {chain}{hint}")]
    Connect {
        /// The worker's URI.
        uri: String,
        /// The connection error with its sources, on one line.
        chain: String,
        /// A hint when TLS is the likely cause, else empty.
        hint: &'static str,
    },
    /// The worker accepted the connection and said nothing.
    #[error("no answer to hello within {} s", ANSWER_TIMEOUT.as_secs())]
    HelloTimeout,
    /// The worker refused the hello (another protocol or build, a wrong token, or not gRPC at all).
    #[error("refused: {status}{hint}")]
    Refused {
        /// The status, on one line.
        status: String,
        /// Its code: [`unanswered`] tells a refusal from a call that never got an answer.
        code: Code,
        /// A hint when TLS is the likely cause, else empty.
        hint: &'static str,
    },
    /// The worker did not list its missing blobs in time.
    #[error("no answer to the blob list within {} s", ANSWER_TIMEOUT.as_secs())]
    BlobListTimeout,
    /// The worker failed to list its missing blobs.
    #[error("listing blobs: {0}")]
    BlobList(String),
    /// The worker asked for a blob that is not part of the job.
    #[error("asked for blob {0}, which this job does not have")]
    UnknownBlob(String),
    /// A blob is larger than the worker accepts.
    #[error("blob of {} MiB exceeds the worker's limit of {} MiB", .size >> 20, .limit >> 20)]
    BlobTooLarge {
        /// The blob's bytes.
        size: u64,
        /// The worker's limit in bytes.
        limit: u64,
    },
    /// An upload took longer than its allowance.
    #[error("shipping blob {id} took longer than {} s", .limit.as_secs())]
    ShipTimeout {
        /// The blob.
        id: String,
        /// The allowance.
        limit: Duration,
    },
    /// An upload failed.
    #[error("shipping blob {id}: {status}")]
    Ship {
        /// The blob.
        id: String,
        /// The status, on one line.
        status: String,
    },
}

/// A client of one worker.
pub type Client = RenderClient<InterceptedService<Channel, Auth>>;

/// Connects to a worker, retrying refused connections for `patience` (a worker that was just started may not
/// listen yet). With `tls_ca`, the connection is TLS and the worker's certificate must be signed by that
/// authority and name the worker's host.
pub async fn connect(
    uri: &str,
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
    patience: Duration,
) -> Result<Client, SessionError> {
    let auth = match token {
        Some(t) => Some(MetadataValue::try_from(photon_proto::bearer(t)).map_err(|_| SessionError::BadToken)?),
        None => None,
    };
    let uri = photon_proto::transport::worker_uri(uri, tls_ca.is_some());
    let endpoint = photon_proto::transport::client_endpoint(&uri, tls_ca)
        .map_err(|cause| SessionError::BadAddress { uri: uri.clone(), cause })?;
    let start = Instant::now();
    let channel = loop {
        match endpoint.connect().await {
            Ok(c) => break c,
            Err(e) if start.elapsed() < patience => {
                tracing::debug!(uri, "connect: {e}; retrying");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            Err(e) => {
                let chain = error_chain(&e);
                // A TLS client talking to a plaintext worker sees its handshake answered with HTTP/2 bytes.
                let hint = if tls_ca.is_some() && !chain.contains("certificate") && !chain.contains("refused") {
                    " (if the worker runs without --tls-cert, drop --tls-ca)"
                } else {
                    ""
                };
                return Err(SessionError::Connect { uri, chain, hint });
            }
        }
    };
    Ok(RenderClient::with_interceptor(channel, Auth(auth))
        .max_decoding_message_size(photon_proto::MAX_MESSAGE)
        .max_encoding_message_size(photon_proto::MAX_MESSAGE))
}

/// An error with its sources, on one line.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(inner) = source {
        let part = inner.to_string();
        // Layers often repeat their inner error's words; say each once.
        if !s.ends_with(&part) {
            s.push_str(": ");
            s.push_str(&part);
        }
        source = inner.source();
    }
    s
}

/// A status as one readable line.
fn status_line(s: &tonic::Status) -> String {
    let code = format!("{:?}", s.code());
    if s.message().is_empty() { code } else { format!("{} ({code})", s.message()) }
}

/// A worker that said hello and holds every blob of the job.
pub struct Ready {
    /// Its client.
    pub client: Client,
    /// Its hello.
    pub hello: pb::HelloReply,
    /// Blob bytes it received, from the coordinator and from other workers ([`crate::fleet::swarm`]).
    pub delivered: Delivered,
    /// Seconds from the start of the session until it was ready.
    pub ship_s: f64,
}

/// Connects to the worker at `addr`, says hello and ships the blobs it lacks.
pub async fn open(
    addr: &WorkerAddr,
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
    job: &Job,
) -> Result<Ready, SessionError> {
    open_with_patience(addr, token, tls_ca, job, Duration::from_secs(3)).await
}

/// [`open`], retrying refused connections for `patience` (zero: one attempt).
pub async fn open_with_patience(
    addr: &WorkerAddr,
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
    job: &Job,
    patience: Duration,
) -> Result<Ready, SessionError> {
    let started = Instant::now();
    let greeting = greet(&addr.uri, token, tls_ca, patience).await?;
    supply_greeted(greeting, addr, job, started).await
}

/// The session of a worker greeted earlier in this render ([`crate::fleet::greet`]): ships the blobs it lacks
/// over the greeting's connection, without a second hello.
pub async fn open_greeted(greeting: Greeting, addr: &WorkerAddr, job: &Job) -> Result<Ready, SessionError> {
    supply_greeted(greeting, addr, job, Instant::now()).await
}

/// Gets a greeted worker the blobs of `job`; the session counts as started at `started`.
async fn supply_greeted(
    greeting: Greeting,
    addr: &WorkerAddr,
    job: &Job,
    started: Instant,
) -> Result<Ready, SessionError> {
    let Greeting { mut client, hello } = greeting;
    let delivered = supply(&mut client, &hello, job, &addr.uri).await?;
    Ok(Ready { client, hello, delivered, ship_s: started.elapsed().as_secs_f64() })
}

/// A worker that answered hello: its client, on the same connection, and its reply. The model of the farm greets
/// remote workers before the job is prepared (it needs their threads); the render's sessions go on from these
/// greetings, so that each worker hears one hello per render.
#[derive(Clone)]
pub struct Greeting {
    /// Its client.
    pub client: Client,
    /// Its answer.
    pub hello: pb::HelloReply,
}

impl std::fmt::Debug for Greeting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Greeting").field("hello", &self.hello).finish_non_exhaustive()
    }
}

/// Connects to the worker at `uri` ([`connect`], retrying refused connections for `patience`) and says hello.
pub async fn greet(
    uri: &str,
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
    patience: Duration,
) -> Result<Greeting, SessionError> {
    let mut client = connect(uri, token, tls_ca, patience).await?;
    let hello = hello(&mut client).await?;
    Ok(Greeting { client, hello })
}

/// Whether a hello that failed with `code` got no answer from a worker (the connection died: a worker going
/// down or restarting, or a plaintext call to a TLS worker) rather than a refusal.
pub fn unanswered(code: Code) -> bool {
    matches!(code, Code::Unavailable | Code::Unknown | Code::Internal | Code::Cancelled)
}

/// Blob bytes a worker received for a job.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Delivered {
    /// From the coordinator.
    pub shipped: u64,
    /// From other workers.
    pub fetched: u64,
}

impl std::ops::AddAssign for Delivered {
    fn add_assign(&mut self, other: Self) {
        self.shipped += other.shipped;
        self.fetched += other.fetched;
    }
}

/// Says hello and gets the worker the blobs it lacks ([`supply`]). Returns its reply and the bytes it received.
pub async fn introduce(client: &mut Client, job: &Job, uri: &str) -> Result<(pb::HelloReply, Delivered), SessionError> {
    let hello = hello(client).await?;
    let delivered = supply(client, &hello, job, uri).await?;
    Ok((hello, delivered))
}

/// Gets a worker that answered `hello` the blobs it lacks: uploaded from here, or, for the big blobs of a job
/// with a [`Swarm`](crate::fleet::swarm::Swarm), fetched from another worker when one is free to send. `uri` is
/// the worker's address as the other workers reach it. Returns the bytes it received.
pub async fn supply(
    client: &mut Client,
    hello: &pb::HelloReply,
    job: &Job,
    uri: &str,
) -> Result<Delivered, SessionError> {
    let ids: Vec<String> = job.blobs.keys().cloned().collect();
    let missing = tokio::time::timeout(ANSWER_TIMEOUT, client.missing_blobs(pb::MissingBlobsRequest { ids }))
        .await
        .map_err(|_| SessionError::BlobListTimeout)?
        .map_err(|s| SessionError::BlobList(status_line(&s)))?
        .into_inner()
        .missing;
    let mut delivered = Delivered::default();
    for id in missing {
        let Some(blob) = job.blobs.get(&id) else {
            return Err(SessionError::UnknownBlob(id));
        };
        if blob.len() as u64 > hello.max_blob_bytes {
            return Err(SessionError::BlobTooLarge { size: blob.len() as u64, limit: hello.max_blob_bytes });
        }
        match &job.swarm {
            Some(swarm) if blob.len() >= crate::fleet::swarm::MIN_PEER_BYTES => {
                delivered += through_swarm(client, swarm, &id, blob, uri).await?;
            }
            _ => delivered.shipped += put_blob(client, &id, blob.clone()).await?,
        }
    }
    Ok(delivered)
}

/// Gets blob `id` to the worker at `uri` from the first free source: a peer holding it or the coordinator. A
/// fetch the peer failed (`ABORTED`) tries the next source; one the receiver failed gets the blob from here.
async fn through_swarm(
    client: &mut Client,
    swarm: &crate::fleet::swarm::Swarm,
    id: &str,
    blob: &Arc<Vec<u8>>,
    uri: &str,
) -> Result<Delivered, SessionError> {
    use crate::fleet::swarm::{Outcome, Source};
    let mut peers = true;
    loop {
        let lease = swarm.lease(id, uri, peers).await;
        let Source::Peer(peer) = lease.source().clone() else {
            let shipped = put_blob(client, id, blob.clone()).await;
            lease.end(if shipped.is_ok() { Outcome::Delivered } else { Outcome::ReceiverFailed });
            return Ok(Delivered { shipped: shipped?, fetched: 0 });
        };
        let request = pb::FetchBlobRequest {
            blob: Some(pb::BlobHeader { id: id.to_owned(), size: blob.len() as u64 }),
            peer: peer.clone(),
            tls_ca: swarm.tls_ca.clone().unwrap_or_default(),
        };
        let limit = ANSWER_TIMEOUT + Duration::from_secs(blob.len() as u64 >> 20);
        match tokio::time::timeout(limit, client.fetch_blob(request)).await {
            Ok(Ok(reply)) => {
                lease.end(Outcome::Delivered);
                return Ok(Delivered { shipped: 0, fetched: reply.into_inner().stored });
            }
            Ok(Err(status)) if status.code() == Code::Aborted => {
                tracing::warn!(
                    "{uri}: fetch from peer {peer} failed ({}); trying the next source",
                    status_line(&status)
                );
                lease.end(Outcome::SourceFailed);
            }
            answer => {
                let why = match answer {
                    Ok(Err(status)) => status_line(&status),
                    _ => format!("no answer in {} s", limit.as_secs()),
                };
                tracing::warn!("{uri}: could not fetch from peer {peer} ({why}); uploading from here");
                lease.end(Outcome::ReceiverFailed);
                peers = false;
            }
        }
    }
}

/// Says hello: the worker answers with what it is, or refuses another protocol or build (or a wrong token).
pub async fn hello(client: &mut Client) -> Result<pb::HelloReply, SessionError> {
    hello_carrying(client, Vec::new()).await
}

/// Measures the link to a worker that answered a hello, in bytes per second: `bytes` of padding
/// ([`pb::HelloRequest::probe`]) over the time a hello carrying them takes beyond an empty one (the round trip
/// and the worker's answer). The faster of two tries; `None` when the difference is too small to time (a link
/// much faster than the probe needs). `bytes` is at most [`photon_proto::MAX_CHUNK`].
pub async fn probe_link(client: &mut Client, bytes: usize) -> Result<Option<f64>, SessionError> {
    let bytes = bytes.min(photon_proto::MAX_CHUNK);
    let t = std::time::Instant::now();
    hello_carrying(client, Vec::new()).await?;
    let empty = t.elapsed().as_secs_f64();
    let mut best = f64::INFINITY;
    for _ in 0..2 {
        let t = std::time::Instant::now();
        hello_carrying(client, vec![0; bytes]).await?;
        best = best.min(t.elapsed().as_secs_f64());
    }
    let extra = best - empty;
    // Under 100 µs the timer and the scheduler's noise are the measurement.
    Ok((extra > 1e-4).then(|| bytes as f64 / extra))
}

async fn hello_carrying(client: &mut Client, probe: Vec<u8>) -> Result<pb::HelloReply, SessionError> {
    let request = pb::HelloRequest {
        protocol_version: photon_proto::PROTOCOL_VERSION,
        build_id: photon_proto::BUILD_ID.to_owned(),
        crate_version: photon_proto::CRATE_VERSION.to_owned(),
        probe,
    };
    // A peer that accepts the connection and never answers must not hang the render.
    tokio::time::timeout(ANSWER_TIMEOUT, client.hello(request))
        .await
        .map_err(|_| SessionError::HelloTimeout)?
        .map(tonic::Response::into_inner)
        .map_err(|s| {
            // A plaintext client talking to a TLS worker sees the connection die without an HTTP/2 answer: as
            // a transport error, or, when the close comes while the call waits (hyper), as a cancelled call,
            // which the coordinator never makes of a hello itself.
            let hint = if unanswered(s.code()) {
                " (if the worker was started with --tls-cert, give the coordinator --tls-ca)"
            } else {
                ""
            };
            SessionError::Refused { status: status_line(&s), code: s.code(), hint }
        })
}

/// Uploads one blob in chunks of at most [`photon_proto::MAX_CHUNK`] bytes, copied one at a time as the stream
/// is sent. Allowed [`ANSWER_TIMEOUT`] plus a second per MiB (1 MiB/s is a very slow link).
pub async fn put_blob(client: &mut Client, id: &str, blob: Arc<Vec<u8>>) -> Result<u64, SessionError> {
    let header = pb::BlobHeader { id: id.to_owned(), size: blob.len() as u64 };
    let limit = ANSWER_TIMEOUT + Duration::from_secs(blob.len() as u64 >> 20);
    let reply =
        tokio::time::timeout(limit, client.put_blob(tokio_stream::iter(photon_proto::blob_chunks(header, blob))))
            .await
            .map_err(|_| SessionError::ShipTimeout { id: id.to_owned(), limit })?
            .map_err(|s| SessionError::Ship { id: id.to_owned(), status: status_line(&s) })?;
    Ok(reply.into_inner().stored)
}

/// How long a worker may take to answer a short call (hello, the blob list).
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(30);

/// Why a strip call brought back no valid strip. Each message is the one the log and the worker table show.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StripError {
    /// The call ended with a status.
    #[error("{line}")]
    Status {
        /// Its code, which decides what the failure means.
        code: Code,
        /// The status, on one line.
        line: String,
    },
    /// The stream ended without a summary.
    #[error("the strip's stream ended before its summary")]
    StreamEnded,
    /// Pixel rows came out of order or not as whole rows.
    #[error("pixel rows out of order: got {bytes} bytes from row {first_row}, expected whole rows from row {next_row}")]
    RowsOutOfOrder {
        /// Bytes in the message.
        bytes: usize,
        /// The row they claimed to start at.
        first_row: u32,
        /// The row expected next.
        next_row: u32,
    },
    /// More pixels than the strip holds.
    #[error("more pixels than rows {row_start}..{row_end} hold")]
    TooManyPixels {
        /// The strip's first row.
        row_start: u32,
        /// The row after its last.
        row_end: u32,
    },
    /// The summary came before all pixels.
    #[error("{got} of {expected} pixel bytes before the summary")]
    ShortStrip {
        /// Bytes received.
        got: usize,
        /// Bytes the strip holds.
        expected: usize,
    },
    /// The pixels do not hash to the worker's checksum.
    #[error("checksum mismatch: the pixels changed after the worker hashed them")]
    ChecksumMismatch,
    /// A sum that no block of this many units can add up to, in values that hash to the worker's checksum:
    /// the worker's renderer computed it, and every worker of this build would compute it again.
    #[error("pixel ({x}, {y}) holds the sum {value}: not the sum of {units} units")]
    NotASum {
        /// Column.
        x: u32,
        /// Row.
        y: u32,
        /// The sum.
        value: i64,
        /// Units in the block.
        units: u32,
    },
    /// A message with no event.
    #[error("an empty event")]
    EmptyEvent,
}

impl StripError {
    /// The worker cannot be reached (the connection is gone, or never came back): it is lost, and its strips go
    /// to the others; the failure is not reported against the strip.
    pub fn lost(&self) -> bool {
        match self {
            Self::Status { code, .. } => matches!(code, Code::Unavailable | Code::Unknown | Code::Aborted),
            Self::StreamEnded => true,
            _ => false,
        }
    }

    /// Another attempt could succeed; `false` when the job itself cannot render (another worker would fail the
    /// same way).
    pub fn retryable(&self) -> bool {
        // FAILED_PRECONDITION: the strip's photons or light vertices pass the worker's memory (the same strip
        // fails the same way there, and on every worker of no more memory).
        !matches!(
            self,
            Self::Status { code: Code::InvalidArgument | Code::OutOfRange | Code::FailedPrecondition, .. }
                | Self::NotASum { .. }
        )
    }

    /// The failure counts against the worker: it misbehaved, rather than being busy or cancelled, or the job
    /// being broken.
    pub fn counted(&self) -> bool {
        match self {
            Self::Status { code, .. } => !matches!(
                code,
                Code::Unavailable
                    | Code::Unknown
                    | Code::Aborted
                    | Code::InvalidArgument
                    | Code::OutOfRange
                    | Code::FailedPrecondition
                    | Code::ResourceExhausted
                    | Code::Cancelled
                    | Code::DeadlineExceeded
            ),
            // Not the worker's fault: the same build renders the same pixel the same way everywhere.
            Self::StreamEnded | Self::NotASum { .. } => false,
            _ => true,
        }
    }

    /// The failure as the scheduler takes it.
    pub fn failure(&self) -> StripFailure {
        StripFailure { retryable: self.retryable(), counted: self.counted(), reason: self.to_string() }
    }
}

impl From<tonic::Status> for StripError {
    fn from(s: tonic::Status) -> Self {
        Self::Status { code: s.code(), line: status_line(&s) }
    }
}

/// What a worker sent back for one strip: its block sums and the worker's summary.
#[derive(Clone, Debug)]
pub struct StripResult {
    /// Per pixel channel of the strip's rows (3 per pixel, row-major), the sum over the block's units of the
    /// fixed-point estimate ([`photon_core::render::sums`]).
    pub sums: Vec<i64>,
    /// Rays, photon paths and seconds, as the worker reported them (the checksum already checked).
    pub summary: pb::StripSummary,
}

/// Asks `client` for one block (units over rows) and validates what comes back: whole rows in order, the right
/// length, the checksum, and sums that the block's units can add up to.
pub async fn fetch_strip(
    mut client: Client,
    request: pb::StripRequest,
    width: u32,
    progress: impl Fn(u32),
) -> Result<StripResult, StripError> {
    let (row_start, row_end) = (request.row_start, request.row_end);
    let units = request.unit_end.saturating_sub(request.unit_start);
    let mut stream = client.render_strip(request).await?.into_inner();
    let row_bytes = 3 * 8 * width as usize;
    let expected = row_bytes * (row_end - row_start) as usize;
    let mut bytes: Vec<u8> = Vec::with_capacity(expected);
    loop {
        let event = match stream.message().await {
            Ok(Some(e)) => e,
            Ok(None) => return Err(StripError::StreamEnded),
            Err(s) => return Err(s.into()),
        };
        let rows = match event.event {
            Some(WireEvent::UnitsDone(n)) => {
                progress(n);
                continue;
            }
            Some(WireEvent::Sums(rows)) => rows,
            Some(WireEvent::Done(summary)) => {
                if bytes.len() != expected {
                    return Err(StripError::ShortStrip { got: bytes.len(), expected });
                }
                if summary.checksum != photon_proto::checksum(&bytes) {
                    return Err(StripError::ChecksumMismatch);
                }
                let sums = sums_of(&bytes, units, width, row_start)?;
                return Ok(StripResult { sums, summary });
            }
            None => return Err(StripError::EmptyEvent),
        };
        let next_row = row_start + (bytes.len() / row_bytes.max(1)) as u32;
        if rows.first_row != next_row || rows.data.len() % row_bytes.max(1) != 0 {
            return Err(StripError::RowsOutOfOrder { bytes: rows.data.len(), first_row: rows.first_row, next_row });
        }
        if bytes.len() + rows.data.len() > expected {
            return Err(StripError::TooManyPixels { row_start, row_end });
        }
        bytes.extend_from_slice(&rows.data);
    }
}

/// The pixel of value `i` (3 per pixel) of rows from `row_start`.
fn pixel_of(i: usize, width: u32, row_start: u32) -> (u32, u32) {
    ((i / 3) as u32 % width.max(1), row_start + (i / 3) as u32 / width.max(1))
}

/// Block sums from checked bytes: every value within what `units` units can add.
fn sums_of(bytes: &[u8], units: u32, width: u32, row_start: u32) -> Result<Vec<i64>, StripError> {
    let sums = photon_proto::bytes_to_sums(bytes).unwrap_or_default();
    if let Err(BlockSumsError::OutOfRange { index, value, .. }) = check_sums(&sums, units) {
        let (x, y) = pixel_of(index, width, row_start);
        return Err(StripError::NotASum { x, y, value, units });
    }
    Ok(sums)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_workers_are_told_from_remote_ones() {
        for (address, local) in [
            ("127.0.0.1:7878", true),
            ("localhost:7878", true),
            ("http://[::1]:7878", true),
            ("https://127.0.0.2:1", true),
            ("node07:7878", false),
            ("10.0.0.5:7878", false),
            ("http://[2001:db8::1]:7878", false),
        ] {
            assert_eq!(WorkerAddr::new(address, None).is_loopback(), local, "{address}");
        }
    }

    #[test]
    fn strip_errors_keep_the_flags_of_their_kind() {
        let status = |code| StripError::from(tonic::Status::new(code, "why"));
        // (lost, retryable, counted)
        let cases = [
            (Code::Unavailable, (true, true, false)),
            (Code::Aborted, (true, true, false)),
            (Code::InvalidArgument, (false, false, false)),
            (Code::OutOfRange, (false, false, false)),
            (Code::FailedPrecondition, (false, false, false)),
            (Code::ResourceExhausted, (false, true, false)),
            (Code::Cancelled, (false, true, false)),
            (Code::DeadlineExceeded, (false, true, false)),
            (Code::Internal, (false, true, true)),
            (Code::NotFound, (false, true, true)),
        ];
        for (code, flags) in cases {
            let e = status(code);
            assert_eq!((e.lost(), e.retryable(), e.counted()), flags, "{code:?}");
        }
        assert_eq!(status(Code::Internal).to_string(), "why (Internal)");
        assert!(StripError::StreamEnded.lost());
        let bad = StripError::NotASum { x: 1, y: 2, value: -5, units: 3 };
        assert_eq!(bad.failure(), StripFailure::fatal("pixel (1, 2) holds the sum -5: not the sum of 3 units"));
        assert!(StripError::ChecksumMismatch.failure().counted);
    }
}
