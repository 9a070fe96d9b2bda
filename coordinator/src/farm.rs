//! Rendering a prepared job on workers over gRPC: connect, check versions, ship blobs, schedule strips, validate
//! and assemble them, survive workers that fail.
//!
//! One task per worker connects, says hello and ships the blobs the worker lacks; one task per strip in flight
//! asks for it and checks what comes back. They report to a single loop that owns the [`Scheduler`] (a pure state
//! machine) through a channel, so every decision is made in one place, in the order events arrive. The loop
//! also wakes on a timer to withdraw strips past their deadline.
//!
//! A result is accepted only if it covers exactly the strip's rows in order, has the right number of floats,
//! every value finite and non-negative, and hashes to the checksum the worker computed before sending. A copy
//! that loses the race, or a worker's strips when it is declared lost or dropped, are cancelled by dropping
//! their calls (the worker then stops rendering them).

use crate::scheduler::{Completion, FailureOutcome, Policy, Scheduler, StripFailure, StripId, WorkerId, WorkerState};
use photon_proto::pb::render_client::RenderClient;
use photon_proto::pb::{self, strip_event::Event as WireEvent};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio::task::AbortHandle;
use tonic::Code;
use tonic::metadata::{AsciiMetadataValue, MetadataValue};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;

/// A job: the blobs of a prepared scene and the frame to render.
#[derive(Clone, Debug)]
pub struct Job {
    /// Blob id of the scene (geometry, BVH, materials, lights).
    pub scene_blob: String,
    /// Blob id of the photon maps, if the method has any.
    pub photons_blob: Option<String>,
    /// Every blob by id, shared with the shipping tasks.
    pub blobs: BTreeMap<String, Arc<Vec<u8>>>,
    /// The encoded frame (camera and settings).
    pub frame: Vec<u8>,
    /// Image size in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Whether the method is progressive photon mapping, whose strips each need every pass's photons: it gets
    /// fewer, taller strips ([`crate::scheduler::rows_per_strip_progressive`]).
    pub progressive: bool,
}

impl Job {
    /// A job from the encoded parts of a prepared scene, rendered with `settings`.
    pub fn new(
        scene: Vec<u8>,
        photons: Option<Vec<u8>>,
        frame: Vec<u8>,
        (width, height): (u32, u32),
        settings: &photon_core::scene::RenderSettings,
    ) -> Self {
        let mut blobs = BTreeMap::new();
        let scene_blob = photon_proto::blob_id(&scene);
        blobs.insert(scene_blob.clone(), Arc::new(scene));
        let photons_blob = photons.map(|p| {
            let id = photon_proto::blob_id(&p);
            blobs.insert(id.clone(), Arc::new(p));
            id
        });
        let progressive = settings.integrator == photon_core::scene::Integrator::Progressive;
        Self { scene_blob, photons_blob, blobs, frame, width, height, progressive }
    }

    /// A fingerprint of everything that decides the pixels: the blobs, the frame and the size. A partial file
    /// is resumed only by the job with the same fingerprint.
    pub fn fingerprint(&self) -> String {
        let mut h = photon_proto::Hasher::new();
        h.update(self.scene_blob.as_bytes());
        h.update(self.photons_blob.as_deref().unwrap_or("").as_bytes());
        h.update(&self.frame);
        h.update(&self.width.to_le_bytes());
        h.update(&self.height.to_le_bytes());
        h.finalize().to_hex().to_string()
    }

    /// Bytes of all blobs.
    pub fn blob_bytes(&self) -> u64 {
        self.blobs.values().map(|b| b.len() as u64).sum()
    }
}

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

/// How to render.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// The shared token, sent with every call.
    pub token: Option<String>,
    /// TLS: the PEM certificate authority that signed the workers' certificates (plaintext when `None`).
    pub tls_ca: Option<Vec<u8>>,
    /// Rows per strip (default: [`crate::scheduler::rows_per_strip_for`], or
    /// [`crate::scheduler::rows_per_strip_progressive`] for progressive photon mapping).
    pub rows_per_strip: Option<u32>,
    /// The scheduling policy.
    pub policy: Policy,
    /// Strips finished by an earlier, interrupted render of the same job.
    pub resume: Option<Partial>,
    /// Show a progress bar.
    pub progress: bool,
}

/// Strips finished so far: what an interrupted render leaves for `--resume`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Partial {
    /// [`Job::fingerprint`] of the job.
    pub fingerprint: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The strip height the render used (a resumed render cuts the image the same way).
    pub rows_per_strip: u32,
    /// Finished strips: (first row, pixels of whole rows).
    pub strips: Vec<(u32, Vec<f32>)>,
}

/// One worker's line in the final report.
#[derive(Clone, Debug)]
pub struct WorkerReport {
    /// Its name.
    pub name: String,
    /// Architecture and OS (`x86_64 linux`), empty if it never answered.
    pub platform: String,
    /// Render threads.
    pub threads: u32,
    /// Strips accepted from it.
    pub strips: u32,
    /// Seconds with a strip in flight.
    pub busy_s: f64,
    /// Megapixels accepted per busy second.
    pub mpix_per_s: f64,
    /// Blob bytes shipped to it.
    pub shipped_bytes: u64,
    /// Seconds spent shipping to it.
    pub ship_s: f64,
    /// Speculative copies it was given (tail duplicates of strips running elsewhere).
    pub speculative: u32,
    /// Its results dropped because another copy won.
    pub duplicates: u32,
    /// Failures it had, and why it stopped, if it did.
    pub failures: u32,
    /// `active`, or why it was refused, lost or dropped.
    pub state: String,
}

/// A finished render.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Linear RGB, row-major.
    pub pixels: Vec<f32>,
    /// Rays traced (by accepted strips).
    pub rays: u64,
    /// One line per worker.
    pub workers: Vec<WorkerReport>,
    /// Seconds from the start until the first worker was ready (connection, hello and shipping).
    pub ship_s: f64,
    /// Seconds from the first worker ready to the last strip.
    pub render_s: f64,
    /// Strips resumed from a partial file.
    pub resumed: usize,
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
        partial: Partial,
        /// Per-worker lines.
        workers: Vec<WorkerReport>,
    },
    /// A failure that no retry can fix (the job itself cannot render).
    #[error("the render cannot finish: {reason}")]
    Fatal {
        /// Why.
        reason: String,
        /// What was finished.
        partial: Partial,
        /// Per-worker lines.
        workers: Vec<WorkerReport>,
    },
    /// The job does not fit the partial file given to resume.
    #[error("{0}")]
    Resume(String),
}

impl FarmError {
    /// The finished strips, when there are any worth keeping.
    pub fn partial(&self) -> Option<&Partial> {
        match self {
            Self::NoWorkers { partial, .. } | Self::Fatal { partial, .. } => Some(partial),
            Self::Resume(_) => None,
        }
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
enum StripError {
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
async fn fetch_strip(
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

/// What the tasks tell the loop.
enum Event {
    Ready { worker: WorkerId, client: Box<Client>, hello: pb::HelloReply, shipped: u64, ship_s: f64 },
    Refused { worker: WorkerId, reason: String },
    Progress { worker: WorkerId, rows: u32 },
    Strip { worker: WorkerId, strip: StripId, attempt: u32, result: Result<(Vec<f32>, u64), StripError> },
}

/// A worker as the loop knows it.
struct Member {
    addr: WorkerAddr,
    client: Option<Client>,
    hello: Option<pb::HelloReply>,
    shipped: u64,
    ship_s: f64,
    /// Why it is out, if it is (refused, lost, dropped).
    out: Option<String>,
    /// Rows finished in strips still in flight (for the progress bar's rate).
    rows_live: u64,
}

/// Renders `job` on `workers`.
pub async fn render(job: &Job, workers: &[WorkerAddr], options: Options) -> Result<Outcome, FarmError> {
    let t0 = Instant::now();
    let width = job.width;
    let n = workers.len() as u32;
    let rows_per_strip = match (&options.resume, options.rows_per_strip) {
        (Some(p), _) => p.rows_per_strip,
        (None, Some(r)) => r,
        (None, None) if job.progressive => crate::scheduler::rows_per_strip_progressive(job.height, n),
        (None, None) => crate::scheduler::rows_per_strip_for(job.height, n),
    };
    let mut sched = Scheduler::with_policy(job.height, rows_per_strip, options.policy.clone());
    let mut image = vec![0.0f32; 3 * width as usize * job.height as usize];
    let mut done_rows: BTreeMap<u32, u32> = BTreeMap::new();
    let mut resumed = 0;
    if let Some(p) = &options.resume {
        if p.fingerprint != job.fingerprint() || (p.width, p.height) != (job.width, job.height) {
            return Err(FarmError::Resume(
                "the partial file was made by another scene, other settings or another build: render without --resume"
                    .into(),
            ));
        }
        for (first_row, pixels) in &p.strips {
            let id = StripId(first_row / rows_per_strip.max(1));
            let Some(rows) = sched.strip_rows(id) else { continue };
            let len = 3 * width as usize * rows.len();
            if rows.start != *first_row || pixels.len() != len {
                continue;
            }
            let at = 3 * width as usize * rows.start as usize;
            image[at..at + len].copy_from_slice(pixels);
            if sched.mark_done(id) {
                done_rows.insert(rows.start, rows.end);
                resumed += 1;
            }
        }
    }
    let (tx, mut rx) = mpsc::unbounded_channel::<Event>();
    let mut members: Vec<Member> = workers
        .iter()
        .map(|a| Member {
            addr: a.clone(),
            client: None,
            hello: None,
            shipped: 0,
            ship_s: 0.0,
            out: None,
            rows_live: 0,
        })
        .collect();
    let mut sessions = Vec::new();
    for (i, addr) in workers.iter().enumerate() {
        let (tx, job, addr, token) = (tx.clone(), job.clone(), addr.clone(), options.token.clone());
        let tls_ca = options.tls_ca.clone();
        let worker = WorkerId(i as u32);
        sessions.push(tokio::spawn(async move {
            let started = Instant::now();
            let event = match connect(&addr.uri, token.as_deref(), tls_ca.as_deref(), Duration::from_secs(3)).await {
                Err(reason) => Event::Refused { worker, reason },
                Ok(mut client) => match introduce(&mut client, &job).await {
                    Ok((hello, shipped)) => Event::Ready {
                        worker,
                        client: Box::new(client),
                        hello,
                        shipped,
                        ship_s: started.elapsed().as_secs_f64(),
                    },
                    Err(reason) => Event::Refused { worker, reason },
                },
            };
            let _ = tx.send(event);
        }));
    }
    let mut unresolved = workers.len();
    let mut tasks: BTreeMap<(WorkerId, StripId), AbortHandle> = BTreeMap::new();
    let mut rays = 0u64;
    let mut first_ready: Option<Instant> = None;
    let bar = progress_bar(options.progress, sched.strip_count(), resumed);
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    let mut mixed_math_warned = false;
    let result = loop {
        if sched.is_done() {
            break Ok(());
        }
        if let Some((strip, failure)) = sched.fatal() {
            break Err(format!("{strip}: {}", failure.reason));
        }
        if unresolved == 0 && sched.all_workers_gone() {
            break Err(String::new());
        }
        let now = t0.elapsed();
        tokio::select! {
            Some(event) = rx.recv() => match event {
                Event::Ready { worker, client, hello, shipped, ship_s } => {
                    unresolved -= 1;
                    first_ready.get_or_insert_with(Instant::now);
                    let other_mode = members.iter().find_map(|o| {
                        o.hello.as_ref().filter(|h| h.math_mode != hello.math_mode).map(|h| (&o.addr.name, &h.math_mode))
                    });
                    if let (Some((other, mode)), false) = (other_mode, mixed_math_warned) {
                        eprintln!(
                            "warning: workers compute with different math modes ({} on {}, {} on {other}): their \
                             strips may differ in the last bits, and the image depends on which worker rendered what",
                            hello.math_mode, members[worker.0 as usize].addr.name, mode
                        );
                        mixed_math_warned = true;
                    }
                    let m = &mut members[worker.0 as usize];
                    tracing::info!(
                        worker = %m.addr.name, arch = %hello.arch, math = %hello.math_mode, threads = hello.threads,
                        shipped, ship_s, "ready"
                    );
                    sched.add_worker(worker, hello.threads);
                    (m.client, m.hello, m.shipped, m.ship_s) = (Some(*client), Some(hello), shipped, ship_s);
                }
                Event::Refused { worker, reason } => {
                    unresolved -= 1;
                    let m = &mut members[worker.0 as usize];
                    eprintln!("warning: worker {}: {reason}", m.addr.name);
                    m.out = Some(reason);
                }
                Event::Progress { worker, rows } => {
                    members[worker.0 as usize].rows_live = u64::from(rows);
                }
                Event::Strip { worker, strip, attempt, result } => {
                    tasks.remove(&(worker, strip));
                    members[worker.0 as usize].rows_live = 0;
                    match result {
                        Ok((pixels, strip_rays)) => match sched.complete(worker, strip, attempt, now) {
                            Completion::Accepted { cancel } => {
                                if let Some(rows) = sched.strip_rows(strip) {
                                    let at = 3 * width as usize * rows.start as usize;
                                    image[at..at + pixels.len()].copy_from_slice(&pixels);
                                    done_rows.insert(rows.start, rows.end);
                                }
                                rays += strip_rays;
                                for key in cancel {
                                    if let Some(h) = tasks.remove(&key) {
                                        h.abort();
                                    }
                                }
                                bar.inc(1);
                            }
                            Completion::Duplicate | Completion::Unknown => {}
                        },
                        Err(StripError::Lost(reason)) => {
                            let name = &members[worker.0 as usize].addr.name;
                            if sched.worker_stats(worker).is_some_and(|s| s.state == WorkerState::Active) {
                                eprintln!("warning: worker {name} lost ({reason}); its strips go to the others");
                            }
                            for s in sched.worker_lost(worker, now) {
                                if let Some(h) = tasks.remove(&(worker, s)) {
                                    h.abort();
                                }
                            }
                            members[worker.0 as usize].out.get_or_insert(format!("lost: {reason}"));
                        }
                        Err(StripError::Failed(failure)) => {
                            let name = members[worker.0 as usize].addr.name.clone();
                            tracing::warn!("{name}: {strip}: {failure}");
                            if let FailureOutcome::WorkerDropped { reason, cancel } =
                                sched.failed(worker, strip, failure, now)
                            {
                                eprintln!("warning: worker {name} dropped: {reason}");
                                for s in cancel {
                                    if let Some(h) = tasks.remove(&(worker, s)) {
                                        h.abort();
                                    }
                                }
                                members[worker.0 as usize].out = Some(format!("dropped: {reason}"));
                            }
                        }
                    }
                }
            },
            _ = tick.tick() => {
                for (worker, strip) in sched.expired(now) {
                    if let Some(h) = tasks.remove(&(worker, strip)) {
                        h.abort();
                    }
                    let (elapsed, deadline) = (now, sched.deadline(worker, strip).unwrap_or_default());
                    let name = members[worker.0 as usize].addr.name.clone();
                    if let FailureOutcome::WorkerDropped { reason, cancel } =
                        sched.failed(worker, strip, StripFailure::timed_out(elapsed, deadline), now)
                    {
                        eprintln!("warning: worker {name} dropped: {reason}");
                        for s in cancel {
                            if let Some(h) = tasks.remove(&(worker, s)) {
                                h.abort();
                            }
                        }
                        members[worker.0 as usize].out = Some(format!("dropped: {reason}"));
                    }
                }
                bar.set_message(rates(&sched, &members, width));
            }
        }
        // Fill every free slot.
        let now = t0.elapsed();
        for (i, m) in members.iter().enumerate() {
            let worker = WorkerId(i as u32);
            let Some(client) = &m.client else { continue };
            while let Some(a) = sched.assign(worker, now) {
                let request = pb::StripRequest {
                    scene_blob: job.scene_blob.clone(),
                    photons_blob: job.photons_blob.clone().unwrap_or_default(),
                    frame: job.frame.clone(),
                    row_start: a.rows.start,
                    row_end: a.rows.end,
                    strip: a.strip.0,
                    attempt: a.attempt,
                };
                let (tx, client) = (tx.clone(), client.clone());
                let (strip, attempt) = (a.strip, a.attempt);
                let progress_tx = tx.clone();
                let handle = tokio::spawn(async move {
                    let progress = |rows| {
                        let _ = progress_tx.send(Event::Progress { worker, rows });
                    };
                    let result = fetch_strip(client, request, width, progress).await;
                    let _ = tx.send(Event::Strip { worker, strip, attempt, result });
                });
                tasks.insert((worker, strip), handle.abort_handle());
            }
        }
    };
    bar.finish_and_clear();
    for h in tasks.values() {
        h.abort();
    }
    for s in sessions {
        s.abort();
    }
    let render_s = first_ready.map_or(0.0, |t| t.elapsed().as_secs_f64());
    let ship_s = first_ready.map_or(t0.elapsed().as_secs_f64(), |t| (t - t0).as_secs_f64());
    let reports = reports(&sched, &members, width);
    match result {
        Ok(()) => Ok(Outcome { pixels: image, rays, workers: reports, ship_s, render_s, resumed }),
        Err(reason) => {
            let strips = done_rows
                .iter()
                .map(|(&start, &end)| {
                    let (lo, hi) = (3 * width as usize * start as usize, 3 * width as usize * end as usize);
                    (start, image[lo..hi].to_vec())
                })
                .collect();
            let partial = Partial { fingerprint: job.fingerprint(), width, height: job.height, rows_per_strip, strips };
            if reason.is_empty() {
                let reasons = members
                    .iter()
                    .map(|m| format!("{}: {}", m.addr.name, m.out.as_deref().unwrap_or("gone")))
                    .collect::<Vec<_>>()
                    .join("; ");
                let reasons = if reasons.is_empty() { "no workers were given".to_owned() } else { reasons };
                Err(FarmError::NoWorkers { reasons, partial, workers: reports })
            } else {
                Err(FarmError::Fatal { reason, partial, workers: reports })
            }
        }
    }
}

fn progress_bar(show: bool, strips: usize, resumed: usize) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(strips as u64);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:32} {pos}/{len} strips {msg}")
    {
        bar.set_style(style);
    }
    bar.set_position(resumed as u64);
    bar
}

/// Per-worker rates for the progress bar: megapixels per busy second so far.
fn rates(sched: &Scheduler, members: &[Member], width: u32) -> String {
    sched
        .workers()
        .filter(|(_, s)| s.state == WorkerState::Active)
        .map(|(id, s)| {
            let m = &members[id.0 as usize];
            let busy = s.busy.as_secs_f64().max(1e-3);
            let mpix = (s.rows + m.rows_live) as f64 * f64::from(width) / 1e6;
            format!("{} {:.2} Mpx/s", m.addr.name, mpix / busy)
        })
        .collect::<Vec<_>>()
        .join(" · ")
}

fn reports(sched: &Scheduler, members: &[Member], width: u32) -> Vec<WorkerReport> {
    members
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let stats = sched.worker_stats(WorkerId(i as u32));
            let (speculative, duplicates) = stats.map_or((0, 0), |s| (s.speculative, s.duplicates));
            let (strips, busy_s, rows, failures) =
                stats.map_or((0, 0.0, 0, 0), |s| (s.strips, s.busy.as_secs_f64(), s.rows, s.failures));
            let state = match (&m.out, stats.map(|s| &s.state)) {
                (Some(why), _) => why.clone(),
                (None, Some(WorkerState::Dropped(why))) => format!("dropped: {why}"),
                (None, Some(WorkerState::Lost)) => "lost".into(),
                (None, _) => "ok".into(),
            };
            WorkerReport {
                name: m.addr.name.clone(),
                platform: m.hello.as_ref().map(|h| format!("{} {}", h.arch, h.os)).unwrap_or_default(),
                threads: m.hello.as_ref().map_or(0, |h| h.threads),
                strips,
                busy_s,
                mpix_per_s: if busy_s > 0.0 { rows as f64 * f64::from(width) / 1e6 / busy_s } else { 0.0 },
                shipped_bytes: m.shipped,
                ship_s: m.ship_s,
                speculative,
                duplicates,
                failures,
                state,
            }
        })
        .collect()
}
