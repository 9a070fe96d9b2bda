//! One worker's session over gRPC: connect (plaintext or TLS, with the shared token), say hello, ship the blobs
//! it lacks in chunks, and fetch a strip, checking what comes back. A failed strip is classified here: a worker
//! that cannot be reached is lost; one that answered with a failure gets a [`StripFailure`] whose flags say
//! whether to retry and whether it counts against the worker.

use crate::job::Job;
use crate::scheduler::StripFailure;
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
    /// A worker at `address` (`host:port`, or a URI with a scheme), named `name` or after its address.
    pub fn new(address: &str, name: Option<&str>) -> Self {
        let address = address.trim();
        let uri = if address.contains("://") { address.to_owned() } else { format!("http://{address}") };
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
) -> Result<Client, String> {
    let auth = match token {
        Some(t) => Some(
            MetadataValue::try_from(photon_proto::bearer(t))
                .map_err(|_| "the token must be printable ASCII".to_owned())?,
        ),
        None => None,
    };
    let uri = if tls_ca.is_some() { uri.replacen("http://", "https://", 1) } else { uri.to_owned() };
    let endpoint = match tls_ca {
        Some(ca) => photon_proto::transport::tls_endpoint(&uri, ca),
        None => photon_proto::transport::endpoint(&uri),
    }
    .map_err(|e| format!("bad worker address {uri}: {e}"))?;
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
                return Err(format!("cannot connect to {uri}: {chain}{hint}"));
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
    /// Blob bytes shipped to it.
    pub shipped: u64,
    /// Seconds from the start of the session until it was ready.
    pub ship_s: f64,
}

/// Connects to the worker at `addr`, says hello and ships the blobs it lacks.
pub async fn open(addr: &WorkerAddr, token: Option<&str>, tls_ca: Option<&[u8]>, job: &Job) -> Result<Ready, String> {
    let started = Instant::now();
    let mut client = connect(&addr.uri, token, tls_ca, Duration::from_secs(3)).await?;
    let (hello, shipped) = introduce(&mut client, job).await?;
    Ok(Ready { client, hello, shipped, ship_s: started.elapsed().as_secs_f64() })
}

/// Says hello and ships the blobs the worker lacks; returns its reply, the bytes shipped and the seconds taken.
pub async fn introduce(client: &mut Client, job: &Job) -> Result<(pb::HelloReply, u64), String> {
    let request = pb::HelloRequest {
        protocol_version: photon_proto::PROTOCOL_VERSION,
        build_id: photon_proto::BUILD_ID.to_owned(),
        crate_version: photon_proto::CRATE_VERSION.to_owned(),
    };
    // A peer that accepts the connection and never answers must not hang the render.
    let silent = || format!("no answer to hello within {} s", ANSWER_TIMEOUT.as_secs());
    let hello = tokio::time::timeout(ANSWER_TIMEOUT, client.hello(request))
        .await
        .map_err(|_| silent())?
        .map_err(|s| {
            // A plaintext client talking to a TLS worker sees the connection die without an HTTP/2 answer.
            let hint = match s.code() {
                Code::Unavailable | Code::Unknown | Code::Internal => {
                    " (if the worker was started with --tls-cert, give the coordinator --tls-ca)"
                }
                _ => "",
            };
            format!("refused: {}{hint}", status_line(&s))
        })?
        .into_inner();
    let ids: Vec<String> = job.blobs.keys().cloned().collect();
    let missing = tokio::time::timeout(ANSWER_TIMEOUT, client.missing_blobs(pb::MissingBlobsRequest { ids }))
        .await
        .map_err(|_| format!("no answer to the blob list within {} s", ANSWER_TIMEOUT.as_secs()))?
        .map_err(|s| format!("listing blobs: {}", status_line(&s)))?
        .into_inner()
        .missing;
    let mut shipped = 0;
    for id in missing {
        let Some(blob) = job.blobs.get(&id) else {
            return Err(format!("asked for blob {id}, which this job does not have"));
        };
        if blob.len() as u64 > hello.max_blob_bytes {
            return Err(format!(
                "blob of {} MiB exceeds the worker's limit of {} MiB",
                blob.len() >> 20,
                hello.max_blob_bytes >> 20
            ));
        }
        shipped += put_blob(client, &id, blob.clone()).await?;
    }
    Ok((hello, shipped))
}

/// Uploads one blob in chunks of at most [`photon_proto::MAX_CHUNK`] bytes, copied one at a time as the stream
/// is sent. Allowed [`ANSWER_TIMEOUT`] plus a second per MiB (1 MiB/s is a very slow link).
pub async fn put_blob(client: &mut Client, id: &str, blob: Arc<Vec<u8>>) -> Result<u64, String> {
    let header = pb::BlobHeader { id: id.to_owned(), size: blob.len() as u64 };
    let limit = ANSWER_TIMEOUT + Duration::from_secs(blob.len() as u64 >> 20);
    let reply = tokio::time::timeout(limit, client.put_blob(tokio_stream::iter(chunk_messages(header, blob))))
        .await
        .map_err(|_| format!("shipping blob {id} took longer than {} s", limit.as_secs()))?
        .map_err(|s| format!("shipping blob {id}: {}", status_line(&s)))?;
    Ok(reply.into_inner().stored)
}

/// How long a worker may take to answer a short call (hello, the blob list).
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(30);

/// The upload messages of a blob, made lazily: the header rides with the first chunk.
pub fn chunk_messages(header: pb::BlobHeader, blob: Arc<Vec<u8>>) -> impl Iterator<Item = pb::BlobChunk> {
    let n = blob.len().div_ceil(photon_proto::MAX_CHUNK).max(1);
    let mut header = Some(header);
    (0..n).map(move |i| {
        let lo = i * photon_proto::MAX_CHUNK;
        let hi = (lo + photon_proto::MAX_CHUNK).min(blob.len());
        pb::BlobChunk { header: header.take(), data: blob[lo..hi].to_vec() }
    })
}

/// What a strip task reports.
pub enum StripError {
    /// The worker cannot be reached: it is lost.
    Lost(String),
    /// The worker answered, and the answer was a failure.
    Failed(StripFailure),
}

/// Classifies a status returned by a strip call.
fn classify(s: &tonic::Status) -> StripError {
    let line = status_line(s);
    match s.code() {
        // The connection is gone (or never came back): the worker is lost.
        Code::Unavailable | Code::Unknown | Code::Aborted => StripError::Lost(line),
        // The job itself cannot render: another worker would fail the same way.
        Code::InvalidArgument | Code::OutOfRange => StripError::Failed(StripFailure::fatal(line)),
        // Busy, or cancelled: try again elsewhere, not the worker's fault.
        Code::ResourceExhausted | Code::Cancelled | Code::DeadlineExceeded => {
            StripError::Failed(StripFailure::transient(line))
        }
        _ => StripError::Failed(StripFailure::counted(line)),
    }
}

/// Asks `client` for the rows of one strip and validates what comes back.
pub async fn fetch_strip(
    mut client: Client,
    request: pb::StripRequest,
    width: u32,
    progress: impl Fn(u32),
) -> Result<(Vec<f32>, u64), StripError> {
    let (row_start, row_end) = (request.row_start, request.row_end);
    let mut stream = client.render_strip(request).await.map_err(|s| classify(&s))?.into_inner();
    let row_bytes = 12 * width as usize;
    let expected = row_bytes * (row_end - row_start) as usize;
    let mut bytes: Vec<u8> = Vec::with_capacity(expected);
    let bad = |why: String| StripError::Failed(StripFailure::counted(why));
    loop {
        let event = match stream.message().await {
            Ok(Some(e)) => e,
            Ok(None) => return Err(StripError::Lost("the strip's stream ended before its summary".into())),
            Err(s) => return Err(classify(&s)),
        };
        match event.event {
            Some(WireEvent::RowsDone(n)) => progress(n),
            Some(WireEvent::Rows(rows)) => {
                let next_row = row_start + (bytes.len() / row_bytes.max(1)) as u32;
                if rows.first_row != next_row || rows.data.len() % row_bytes.max(1) != 0 {
                    return Err(bad(format!(
                        "pixel rows out of order: got {} bytes from row {}, expected whole rows from row {next_row}",
                        rows.data.len(),
                        rows.first_row
                    )));
                }
                if bytes.len() + rows.data.len() > expected {
                    return Err(bad(format!("more pixels than rows {row_start}..{row_end} hold")));
                }
                bytes.extend_from_slice(&rows.data);
            }
            Some(WireEvent::Done(summary)) => {
                if bytes.len() != expected {
                    return Err(bad(format!("{} of {expected} pixel bytes before the summary", bytes.len())));
                }
                if summary.checksum != photon_proto::checksum(&bytes) {
                    return Err(bad("checksum mismatch: the pixels changed after the worker hashed them".into()));
                }
                let pixels = photon_proto::bytes_to_pixels(&bytes).unwrap_or_default();
                if let Some(i) = pixels.iter().position(|v| !v.is_finite() || *v < 0.0) {
                    let (x, y) = ((i / 3) as u32 % width.max(1), row_start + (i / 3) as u32 / width.max(1));
                    return Err(bad(format!("pixel ({x}, {y}) holds {}: not a radiance", pixels[i])));
                }
                return Ok((pixels, summary.rays));
            }
            None => return Err(bad("an empty event".into())),
        }
    }
}
