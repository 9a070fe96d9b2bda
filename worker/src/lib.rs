//! photon-worker: a gRPC server that renders strips of prepared scenes on all its cores.
//!
//! The coordinator introduces itself ([`Hello`](photon_proto::pb::HelloRequest): the protocol version and build
//! id must equal this worker's), uploads the blobs the worker lacks, then asks for strips. Blobs live in a
//! bounded, content-addressed cache ([`cache`]) in memory and optionally on disk, so a second render of the same
//! scene ships nothing. A strip renders on the worker's rayon pool, one strip at a time, off the async runtime;
//! a few more may wait ([`Config::max_queue`]), beyond that a request is refused as `RESOURCE_EXHAUSTED`.
//!
//! Everything a peer sends is checked before it is used, and a bad request gets a gRPC status that says what
//! was wrong; the worker keeps serving: another protocol or build (`FAILED_PRECONDITION`), a wrong or missing
//! token (`UNAUTHENTICATED`), a blob larger than [`Config::max_blob_bytes`] (`RESOURCE_EXHAUSTED`), a truncated
//! or overlong upload (`INVALID_ARGUMENT`), bytes that do not hash to their id (`DATA_LOSS`), an upload that
//! stalls or crawls (`DEADLINE_EXCEEDED`, [`Config::upload_idle`], [`Config::upload_min_rate`]), an unknown
//! blob (`NOT_FOUND`), rows outside the image (`OUT_OF_RANGE`), a frame whose sizes or settings are out of range
//! or whose method lacks its photons blob (`INVALID_ARGUMENT`, naming the field: [`check_strip_request`]), a
//! strip that would not fit the worker's memory (`RESOURCE_EXHAUSTED`), blobs that do not decode
//! (`INVALID_ARGUMENT`). A status echoes at most a short, escaped prefix of a received value
//! ([`photon_proto::quote`]). A panic while rendering (a bug) fails that strip with `INTERNAL`, not the worker.
//! A worker serves the blobs it holds to its peers (`GetBlob`) and, asked by the coordinator, fetches a blob
//! from a peer (`FetchBlob`) with its own token, checking the size and hash like an upload's.
//! One peer (a remote IP address) may have [`Config::max_calls_per_peer`] calls in progress over all its
//! connections; beyond that a call is refused with `RESOURCE_EXHAUSTED`, naming the cap.
//!
//! The command-line options are in the repository's `README.md` (photon-worker `--help` lists them);
//! `docs/ARCHITECTURE.md` places the worker in the design.
//!
//! ## Example
//!
//! A worker with one render thread, served on a loopback port until the shutdown future resolves (here at once):
//!
//! ```
//! use photon_worker::{Config, Worker, serve};
//!
//! let worker = Worker::new(Config { threads: Some(1), ..Config::default() })?;
//! assert_eq!(worker.threads(), 1);
//! let rt = tokio::runtime::Runtime::new()?;
//! rt.block_on(async {
//!     let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
//!     println!("serving on {}", listener.local_addr()?);
//!     serve(worker, listener, async {}).await?;
//!     Ok::<(), Box<dyn std::error::Error>>(())
//! })?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cache;
pub mod disk_store;

use cache::BlobCache;
use photon_core::method::Unit;
use photon_core::prepare::Prepared;
use photon_core::prepare::blobs::Frame;
use photon_core::prepare::budget::MemoryEstimate;
use photon_core::render::sums::MAX_BLOCK_UNITS;
use photon_core::render::{Block, render_block};
use photon_core::scene::RenderSettings;
use photon_proto::pb::render_server::{Render, RenderServer};
use photon_proto::pb::{self, strip_event::Event};
use photon_proto::transport::SERVED_AT_ONCE;
use photon_proto::{MAX_CHUNK, MAX_MESSAGE, quote};
use std::collections::HashMap;
use std::future::Future;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{Semaphore, mpsc};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

/// A worker's settings.
#[derive(Clone, Debug)]
pub struct Config {
    /// Render threads (`None`: all logical cores).
    pub threads: Option<usize>,
    /// The shared token every call must carry, when set.
    pub token: Option<String>,
    /// TLS: the PEM certificate chain and private key this worker presents (plaintext when `None`).
    pub tls: Option<(Vec<u8>, Vec<u8>)>,
    /// Bytes of blobs kept in memory.
    pub memory_cache_bytes: u64,
    /// A folder that keeps blobs across restarts, and its size cap in bytes.
    pub disk_cache: Option<(PathBuf, u64)>,
    /// The largest blob accepted, in bytes.
    pub max_blob_bytes: u64,
    /// Bytes that uploads in progress may hold in memory together; an upload's chunks count as they arrive,
    /// so a slow client holds only what it has sent.
    pub upload_budget_bytes: u64,
    /// The longest wait for an upload's next chunk.
    pub upload_idle: Duration,
    /// The slowest upload accepted, in bytes per second: a blob of `size` bytes must arrive within
    /// `upload_idle + size / upload_min_rate`.
    pub upload_min_rate: u64,
    /// Memory one strip's buffers may take, in bytes (default: half the machine's memory); a larger strip is
    /// refused before it allocates ([`MemoryEstimate::strip`]).
    pub strip_memory_bytes: u64,
    /// Strip requests that may wait behind the one rendering.
    pub max_queue: usize,
    /// Calls one remote IP address may have in progress at once, over all its connections.
    pub max_calls_per_peer: usize,
    /// The build id this worker claims (the real one unless a test pretends otherwise).
    pub build_id: String,
    /// The math mode this worker claims (the real one, [`photon_core::math::fmath::MODE`], unless a test pretends
    /// otherwise).
    pub math_mode: String,
    /// Test-only fault injection.
    pub fault: Fault,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            threads: None,
            token: None,
            tls: None,
            memory_cache_bytes: 4 << 30,
            disk_cache: None,
            max_blob_bytes: 4 << 30,
            upload_budget_bytes: 8 << 30,
            upload_idle: Duration::from_secs(30),
            upload_min_rate: 256 << 10,
            strip_memory_bytes: if memory_bytes() == 0 { u64::MAX } else { memory_bytes() / 2 },
            max_queue: 4,
            max_calls_per_peer: photon_proto::transport::CALLS_PER_PEER,
            build_id: photon_proto::BUILD_ID.to_owned(),
            math_mode: photon_core::math::fmath::MODE.to_owned(),
            fault: Fault::None,
        }
    }
}

/// Faults a test can make a worker commit, to prove the coordinator catches them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fault {
    /// Behave.
    #[default]
    None,
    /// Change one pixel of each of the first `n` strips after computing their checksum, as a bit flip in
    /// memory or on the wire would.
    CorruptPixels(u32),
    /// Wait this many milliseconds before each strip, as a much slower machine would take longer.
    Delay(u64),
    /// Render a NaN into the first pixel of every strip before computing the checksum, as a bug in an
    /// integrator would.
    NanPixels,
    /// Panic while rendering the first `n` strips, as a bug would.
    Panic(u32),
    /// Serve blobs to peers (`GetBlob`) with the first byte changed, as a bit flip would.
    CorruptBlobs,
}

/// The decoded scene of one job.
struct Job {
    key: [String; 4],
    prep: Prepared,
    /// What making the job cost and no finished strip has reported yet: the strip that made it may be
    /// cancelled (a tail copy that lost), and its cost then goes with the next strip of the job.
    unreported: Mutex<Load>,
}

/// What making a job cost this worker: decoding its blobs, and tracing its photon maps when it traced them.
#[derive(Clone, Copy, Debug, Default)]
struct Load {
    /// Seconds spent decoding the blobs (and rebuilding received photon maps' trees).
    seconds: f64,
    /// Photon paths traced for the job's maps (0 when they were received).
    photon_paths: u64,
    /// Seconds spent tracing those paths and building their maps.
    photon_seconds: f64,
}

/// The render service.
pub struct Worker {
    config: Config,
    pool: Arc<rayon::ThreadPool>,
    blobs: Arc<BlobCache>,
    /// The most recently used decoded jobs (at most [`Worker::JOBS_KEPT`]).
    jobs: Arc<Mutex<Vec<Arc<Job>>>>,
    /// One strip renders at a time: it has all the cores.
    render_slot: Arc<Semaphore>,
    /// Bytes that uploads in progress hold ([`Config::upload_budget_bytes`]).
    upload_bytes: Arc<Semaphore>,
    /// Blobs served to peers at once ([`photon_proto::transport::SERVED_AT_ONCE`]).
    serving: Arc<Semaphore>,
    waiting: Arc<AtomicUsize>,
    /// Strips left to corrupt ([`Fault::CorruptPixels`]) or to panic in ([`Fault::Panic`]).
    corrupt_left: Arc<AtomicU32>,
    /// Calls in progress per peer ([`Config::max_calls_per_peer`]).
    peers: Arc<PeerCalls>,
}

/// Calls in progress per remote IP address, capped.
#[derive(Debug)]
struct PeerCalls {
    cap: usize,
    calls: Mutex<HashMap<IpAddr, usize>>,
}

/// One admitted call; its peer's count goes down when it drops.
struct PeerCall {
    peers: Arc<PeerCalls>,
    ip: Option<IpAddr>,
}

impl PeerCalls {
    /// Admits a call from `peer`, or refuses it when the peer has `cap` calls in progress already. A call whose
    /// peer is unknown (not over TCP) is not counted.
    fn admit(self: &Arc<Self>, peer: Option<SocketAddr>) -> Result<PeerCall, Status> {
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

/// Why a worker cannot start.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    /// The render thread pool cannot be built.
    #[error("cannot start the render threads: {0}")]
    Threads(rayon::ThreadPoolBuildError),
    /// The blob cache cannot be opened.
    #[error(transparent)]
    Cache(#[from] disk_store::DiskStoreError),
}

impl Worker {
    const JOBS_KEPT: usize = 2;

    /// A worker with `config`; starts its thread pool and opens its disk cache.
    pub fn new(config: Config) -> Result<Self, WorkerError> {
        let mut pool = rayon::ThreadPoolBuilder::new().thread_name(|i| format!("photon-render-{i}"));
        if let Some(n) = config.threads {
            pool = pool.num_threads(n);
        }
        let pool = pool.build().map_err(WorkerError::Threads)?;
        let blobs = BlobCache::new(config.memory_cache_bytes, config.disk_cache.clone())?;
        let corrupt = match config.fault {
            Fault::CorruptPixels(n) | Fault::Panic(n) => n,
            Fault::None | Fault::Delay(_) | Fault::NanPixels | Fault::CorruptBlobs => 0,
        };
        let upload_budget =
            usize::try_from(config.upload_budget_bytes).unwrap_or(usize::MAX).min(Semaphore::MAX_PERMITS);
        Ok(Self {
            pool: Arc::new(pool),
            blobs: Arc::new(blobs),
            jobs: Arc::new(Mutex::new(Vec::new())),
            render_slot: Arc::new(Semaphore::new(1)),
            upload_bytes: Arc::new(Semaphore::new(upload_budget)),
            serving: Arc::new(Semaphore::new(SERVED_AT_ONCE)),
            waiting: Arc::new(AtomicUsize::new(0)),
            corrupt_left: Arc::new(AtomicU32::new(corrupt)),
            peers: Arc::new(PeerCalls { cap: config.max_calls_per_peer.max(1), calls: Mutex::new(HashMap::new()) }),
            config,
        })
    }

    /// Threads the worker renders with.
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }
}

/// Serves `worker` on `listener` until `shutdown` resolves; strips in progress are cancelled then.
pub async fn serve(
    worker: Worker,
    listener: tokio::net::TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), tonic::transport::Error> {
    let token = worker.config.token.clone();
    let builder = match &worker.config.tls {
        Some((cert, key)) => photon_proto::transport::tls_server(cert, key)?,
        None => photon_proto::transport::server(),
    };
    let (health, health_service) = tonic_health::server::health_reporter();
    health.set_serving::<RenderServer<Worker>>().await;
    let service =
        RenderServer::new(worker).max_decoding_message_size(MAX_MESSAGE).max_encoding_message_size(MAX_MESSAGE);
    let check = move |req: Request<()>| -> Result<Request<()>, Status> {
        let Some(expected) = &token else { return Ok(req) };
        let given = req.metadata().get(photon_proto::TOKEN_KEY).and_then(|v| v.to_str().ok());
        match given.and_then(|v| v.strip_prefix("Bearer ")) {
            Some(t) if photon_proto::tokens_match(t, expected) => Ok(req),
            Some(_) => Err(Status::unauthenticated("wrong token: this worker's --token-file holds another one")),
            None => Err(Status::unauthenticated("this worker requires a token (coordinator: --token-file)")),
        }
    };
    let mut builder = builder;
    builder
        .add_service(health_service)
        .add_service(tonic::service::interceptor::InterceptedService::new(service, check))
        .serve_with_incoming_shutdown(photon_proto::transport::incoming(listener), shutdown)
        .await
}

/// Physical memory in bytes, 0 where it is not known.
fn memory_bytes() -> u64 {
    photon_core::prepare::budget::machine_memory().unwrap_or(0)
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_owned())
        .unwrap_or_default()
}

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

/// What a strip request is checked against.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Bytes one strip's buffers may take ([`Config::strip_memory_bytes`]).
    pub strip_memory_bytes: u64,
    /// The worker's render threads (each keeps its own k-nearest buffer).
    pub threads: usize,
}

/// The most texture images one request may name.
pub const MAX_TEXTURES: usize = 4096;

/// The longest frame blob accepted (a camera and render settings take a few hundred bytes).
pub const MAX_FRAME_BYTES: usize = 64 << 10;

/// Checks a strip request before anything is looked up or allocated from it: blob ids, the frame (decoded and
/// checked as the scene's validation checks a scene: sizes, finite camera, settings in range), the rows against
/// the frame's image, the method against the blobs present, and the strip's memory against `limits`. Returns the
/// decoded frame. A refusal names the field and quotes at most a short prefix of a received value.
pub fn check_strip_request(r: &pb::StripRequest, limits: &Limits) -> Result<Frame, Status> {
    if !photon_proto::is_blob_id(&r.scene_blob) {
        return Err(Status::invalid_argument(format!(
            "scene_blob: {} is not a blob id (64 lowercase hex digits)",
            quote(&r.scene_blob)
        )));
    }
    if !r.photons_blob.is_empty() && !photon_proto::is_blob_id(&r.photons_blob) {
        return Err(Status::invalid_argument(format!(
            "photons_blob: {} is not a blob id (64 lowercase hex digits, or empty)",
            quote(&r.photons_blob)
        )));
    }
    if r.texture_blobs.len() > MAX_TEXTURES {
        return Err(Status::invalid_argument(format!(
            "texture_blobs: {} ids, at most {MAX_TEXTURES} expected",
            r.texture_blobs.len()
        )));
    }
    if let Some((i, id)) = r.texture_blobs.iter().enumerate().find(|(_, id)| !photon_proto::is_blob_id(id)) {
        return Err(Status::invalid_argument(format!(
            "texture_blobs[{i}]: {} is not a blob id (64 lowercase hex digits)",
            quote(id)
        )));
    }
    if r.row_start >= r.row_end {
        return Err(Status::out_of_range(format!("empty or reversed rows {}..{}", r.row_start, r.row_end)));
    }
    let frame = Frame::decode(&r.frame, MAX_FRAME_BYTES).map_err(|e| Status::invalid_argument(e.to_string()))?;
    let (width, height) = (frame.camera.width, frame.camera.height);
    if r.row_end > height {
        return Err(Status::out_of_range(format!(
            "rows {}..{} are outside the image's {height} rows",
            r.row_start, r.row_end
        )));
    }
    let method = frame.settings.integrator;
    if r.trace_photons && !r.photons_blob.is_empty() {
        return Err(Status::invalid_argument(
            "trace_photons: the worker is asked to trace the photon maps and is sent them too; expected one or the \
             other",
        ));
    }
    let maps_given = !r.photons_blob.is_empty() || r.trace_photons;
    if method.needs_photon_maps() != maps_given {
        let (needs, sent) = if maps_given {
            ("needs no", "a photons blob or trace_photons was sent")
        } else {
            ("needs", "neither a photons blob nor trace_photons was sent")
        };
        return Err(Status::invalid_argument(format!(
            "photons_blob: the frame's method `{method}` {needs} photon maps, and {sent}"
        )));
    }
    check_units(r, &frame.settings)?;
    let mut estimate = MemoryEstimate::strip(width, r.row_end - r.row_start, &frame.settings, limits.threads);
    // A pass of vcm, bdpt or lt traces the light subpaths of the whole image, whatever rows it renders.
    estimate.light_paths = MemoryEstimate::light_paths(width, height, &frame.settings);
    if r.trace_photons {
        // Maps traced here are held here (received ones were bounded by the blob size limit on upload).
        estimate.photon_maps = MemoryEstimate::photon_maps(&frame.settings);
    }
    estimate
        .check(limits.strip_memory_bytes, width, r.row_end - r.row_start, &frame.settings)
        .map_err(|e| Status::resource_exhausted(format!("this worker cannot render the strip: {e}")))?;
    Ok(frame)
}

impl Worker {
    /// What this worker checks strip requests against.
    pub fn limits(&self) -> Limits {
        Limits { strip_memory_bytes: self.config.strip_memory_bytes, threads: self.threads() }
    }

    /// The longest a blob of `bytes` may take to arrive or to be read: the idle time plus its size over the
    /// minimum rate ([`Config::upload_idle`], [`Config::upload_min_rate`]).
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
    async fn receive_blob(
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
}

#[tonic::async_trait]
impl Render for Worker {
    async fn hello(&self, request: Request<pb::HelloRequest>) -> Result<Response<pb::HelloReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        let r = request.into_inner();
        if r.protocol_version != photon_proto::PROTOCOL_VERSION {
            return Err(Status::failed_precondition(format!(
                "protocol version {} is not this worker's {}: build coordinator and workers from the same code",
                r.protocol_version,
                photon_proto::PROTOCOL_VERSION
            )));
        }
        if r.build_id != self.config.build_id {
            return Err(Status::failed_precondition(format!(
                "build {} (photon {}) is not this worker's build {} (photon {}): build coordinator and workers \
                 from the same code",
                quote(&r.build_id),
                quote(&r.crate_version),
                self.config.build_id,
                photon_proto::CRATE_VERSION
            )));
        }
        // A new session: what making a job cost and no strip of an earlier session reported stays with that
        // session (its report is complete without it), so the next strip does not report work it did not cause.
        for job in self.jobs.lock().unwrap_or_else(std::sync::PoisonError::into_inner).iter() {
            *job.unreported.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Load::default();
        }
        Ok(Response::new(pb::HelloReply {
            protocol_version: photon_proto::PROTOCOL_VERSION,
            build_id: self.config.build_id.clone(),
            crate_version: photon_proto::CRATE_VERSION.to_owned(),
            arch: std::env::consts::ARCH.to_owned(),
            os: std::env::consts::OS.to_owned(),
            threads: self.threads() as u32,
            logical_cores: std::thread::available_parallelism().map_or(1, |n| n.get() as u32),
            memory_bytes: memory_bytes(),
            max_blob_bytes: self.config.max_blob_bytes,
            hostname: hostname(),
            math_mode: self.config.math_mode.clone(),
        }))
    }

    async fn missing_blobs(
        &self,
        request: Request<pb::MissingBlobsRequest>,
    ) -> Result<Response<pb::MissingBlobsReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        let ids = request.into_inner().ids;
        if ids.len() > 1024 {
            return Err(Status::invalid_argument(format!("{} blob ids in one request; at most 1024", ids.len())));
        }
        let mut missing = Vec::new();
        for id in ids {
            check_blob_id(&id)?;
            if !self.blobs.contains(&id) {
                missing.push(id);
            }
        }
        Ok(Response::new(pb::MissingBlobsReply { missing }))
    }

    async fn put_blob(&self, request: Request<Streaming<pb::BlobChunk>>) -> Result<Response<pb::PutBlobReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        let stored = self.receive_blob(&mut request.into_inner(), None).await?;
        Ok(Response::new(pb::PutBlobReply { stored }))
    }

    async fn fetch_blob(&self, request: Request<pb::FetchBlobRequest>) -> Result<Response<pb::PutBlobReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        let r = request.into_inner();
        let Some(blob) = r.blob else {
            return Err(Status::invalid_argument("a fetch must name the blob: its id and size"));
        };
        self.check_blob_header(&blob)?;
        if self.blobs.contains(&blob.id) {
            return Ok(Response::new(pb::PutBlobReply { stored: 0 }));
        }
        if self.config.tls.is_some() && r.tls_ca.is_empty() {
            return Err(Status::failed_precondition(
                "this worker speaks TLS and fetches from peers over TLS only: the fetch must carry the farm's CA",
            ));
        }
        let mut stream = self.open_peer_blob(&r.peer, &r.tls_ca, &blob.id).await?;
        let stored = self.receive_blob(&mut stream, Some(&blob)).await.map_err(|s| {
            // Out of upload memory is this worker's state; anything else went wrong with the peer or its bytes.
            let code = if s.code() == tonic::Code::ResourceExhausted { s.code() } else { tonic::Code::Aborted };
            Status::new(code, format!("fetching blob {} from {}: {}", blob.id, quote(&r.peer), s.message()))
        })?;
        Ok(Response::new(pb::PutBlobReply { stored }))
    }

    type GetBlobStream = ReceiverStream<Result<pb::BlobChunk, Status>>;

    async fn get_blob(&self, request: Request<pb::GetBlobRequest>) -> Result<Response<Self::GetBlobStream>, Status> {
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
        let corrupt = self.config.fault == Fault::CorruptBlobs;
        let (tx, rx) = mpsc::channel(3);
        tokio::spawn(async move {
            let _held = (call, serving);
            for (i, mut chunk) in photon_proto::blob_chunks(header, blob).enumerate() {
                if corrupt && i == 0 && !chunk.data.is_empty() {
                    chunk.data[0] ^= 1;
                }
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
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    type RenderStripStream = ReceiverStream<Result<pb::StripEvent, Status>>;

    async fn render_strip(
        &self,
        request: Request<pb::StripRequest>,
    ) -> Result<Response<Self::RenderStripStream>, Status> {
        // Held until the strip's last event is sent (or it is cancelled).
        let call = self.peers.admit(request.remote_addr())?;
        let r = request.into_inner();
        for id in [&r.scene_blob, &r.photons_blob].into_iter().chain(&r.texture_blobs) {
            if photon_proto::is_blob_id(id) && !self.blobs.contains(id) {
                return Err(Status::not_found(format!("blob {id} is unknown here: upload it with PutBlob first")));
            }
        }
        check_strip_request(&r, &self.limits())?;
        if self.waiting.load(Ordering::Relaxed) >= self.config.max_queue {
            return Err(Status::resource_exhausted(format!(
                "{} strips already queued here; send fewer at once",
                self.config.max_queue
            )));
        }
        self.waiting.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = mpsc::channel(32);
        let ctx = StripContext {
            pool: self.pool.clone(),
            blobs: self.blobs.clone(),
            jobs: self.jobs.clone(),
            corrupt_left: self.corrupt_left.clone(),
            delay: match self.config.fault {
                Fault::Delay(ms) => std::time::Duration::from_millis(ms),
                _ => std::time::Duration::ZERO,
            },
            nan_pixels: matches!(self.config.fault, Fault::NanPixels),
            panic: matches!(self.config.fault, Fault::Panic(_)),
        };
        let slot = self.render_slot.clone();
        let waiting = self.waiting.clone();
        tokio::spawn(async move {
            let _call = call;
            let permit = slot.acquire_owned().await;
            waiting.fetch_sub(1, Ordering::Relaxed);
            let Ok(_permit) = permit else { return };
            if tx.is_closed() {
                return;
            }
            let render_tx = tx.clone();
            let outcome = tokio::task::spawn_blocking(move || ctx.render_guarded(&r, &render_tx)).await;
            let events = match outcome {
                Ok(Ok(events)) => events,
                Ok(Err(status)) => vec![Err(status)],
                Err(e) => vec![Err(Status::internal(format!("the render failed: {e}")))],
            };
            for e in events {
                if tx.send(e).await.is_err() {
                    break;
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }
}

/// What a strip's blocking render needs from the worker.
struct StripContext {
    pool: Arc<rayon::ThreadPool>,
    blobs: Arc<BlobCache>,
    jobs: Arc<Mutex<Vec<Arc<Job>>>>,
    corrupt_left: Arc<AtomicU32>,
    delay: std::time::Duration,
    /// Test only: a NaN in every strip ([`Fault::NanPixels`]).
    nan_pixels: bool,
    /// Test only: panic in the first strips ([`Fault::Panic`], counted by `corrupt_left`).
    panic: bool,
}

type Event_ = Result<pb::StripEvent, Status>;

impl StripContext {
    /// The job of a request: from the cache, or decoded from its blobs (with its photon maps traced here when
    /// the request says so), on this worker's threads; what that cost is kept in [`Job::unreported`].
    fn job(&self, r: &pb::StripRequest) -> Result<Arc<Job>, Status> {
        // A traced map and a received one are the same bits, but keep the jobs apart all the same.
        let photons = if r.trace_photons { "traced".to_owned() } else { r.photons_blob.clone() };
        let key = [r.scene_blob.clone(), photons, photon_proto::blob_id(&r.frame), r.texture_blobs.join(",")];
        // A panic while the lock was held (a bug, caught by `render_guarded`) leaves a list of whole jobs.
        let mut jobs = self.jobs.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(i) = jobs.iter().position(|j| j.key == key) {
            let job = jobs.remove(i);
            jobs.push(job.clone());
            return Ok(job);
        }
        let t0 = Instant::now();
        let blob = |id: &str| {
            self.blobs.get(id).ok_or_else(|| Status::not_found(format!("blob {id} was evicted; upload it again")))
        };
        let scene = blob(&r.scene_blob)?;
        let photons = if r.photons_blob.is_empty() { None } else { Some(blob(&r.photons_blob)?) };
        let photons = photons.as_deref().map(Vec::as_slice);
        let textures = r.texture_blobs.iter().map(|id| blob(id)).collect::<Result<Vec<_>, _>>()?;
        let textures: Vec<&[u8]> = textures.iter().map(|b| b.as_slice()).collect();
        let mut prep = self
            .pool
            .install(|| Prepared::from_blobs(&scene, photons, &r.frame, &textures, usize::MAX))
            .map_err(|e| Status::invalid_argument(format!("the job's blobs do not decode: {e}")))?;
        let mut load = Load { seconds: t0.elapsed().as_secs_f64(), ..Load::default() };
        if r.trace_photons {
            let t1 = Instant::now();
            // Deterministic streams: the same maps as the coordinator would have traced and shipped.
            let maps = self
                .pool
                .install(|| prep.build_photon_maps())
                .map_err(|e| Status::invalid_argument(format!("the job's photon maps cannot be built: {e}")))?;
            load.photon_paths = prep.photon_map_paths();
            load.photon_seconds = t1.elapsed().as_secs_f64();
            prep.photons = Some(maps);
        }
        if prep.settings.integrator.needs_photon_maps() && prep.photons.is_none() {
            return Err(Status::invalid_argument(format!(
                "the method `{}` needs photon maps and the photons blob holds none",
                prep.settings.integrator
            )));
        }
        let job = Arc::new(Job { key, prep, unreported: Mutex::new(load) });
        jobs.push(job.clone());
        if jobs.len() > Worker::JOBS_KEPT {
            jobs.remove(0);
        }
        Ok(job)
    }

    /// [`StripContext::render`], with a panic (a bug: every request was checked before) turned into an
    /// `INTERNAL` status for this strip, so the worker keeps serving the others.
    fn render_guarded(&self, r: &pb::StripRequest, tx: &mpsc::Sender<Event_>) -> Result<Vec<Event_>, Status> {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.render(r, tx))).unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            tracing::error!(strip = r.strip, "the render panicked: {what}");
            Err(Status::internal(format!(
                "strip {} (rows {}..{}) panicked on this worker: {}; this is a bug in photon",
                r.strip,
                r.row_start,
                r.row_end,
                quote(&what)
            )))
        })
    }

    /// Renders the strip, sending progress on `tx` as it goes; returns the pixel and summary events.
    fn render(&self, r: &pb::StripRequest, tx: &mpsc::Sender<Event_>) -> Result<Vec<Event_>, Status> {
        // The rows and passes were checked against this frame by `check_strip_request` before the call started.
        let job = self.job(r)?;
        let width = job.prep.camera.width;
        tracing::info!(strip = r.strip, attempt = r.attempt, rows = ?(r.row_start..r.row_end), "rendering strip");
        if self.panic
            && self.corrupt_left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1)).is_ok()
        {
            panic!("fault injection: a panic while rendering strip {}", r.strip);
        }
        if !self.delay.is_zero() {
            // Test-only slowness, in small steps so a cancelled strip stops waiting.
            let end = Instant::now() + self.delay;
            while Instant::now() < end {
                if tx.is_closed() {
                    return Err(Status::cancelled("the coordinator cancelled the strip"));
                }
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
        }
        let t0 = Instant::now();
        let progress = |units: u32| {
            // A full channel only delays a progress report; a closed one means the coordinator left: stop.
            let _ = tx.try_send(Ok(pb::StripEvent { event: Some(Event::UnitsDone(units)) }));
            !tx.is_closed()
        };
        let prep = &job.prep;
        let block = Block { rows: r.row_start..r.row_end, units: r.unit_start..r.unit_end };
        let block = self.pool.install(|| render_block(prep, &block, &progress));
        let block = block.ok_or_else(|| Status::cancelled("the coordinator cancelled the strip"))?;
        let mut sums = block.sums;
        if self.nan_pixels
            && let Some(v) = sums.first_mut()
        {
            tracing::warn!(strip = r.strip, "fault injection: an impossible sum before the checksum");
            *v = -1;
        }
        let mut bytes = photon_proto::sums_to_bytes(&sums);
        let mut summary = pb::StripSummary {
            rays: block.rays,
            photon_paths: block.photon_paths,
            photon_seconds: block.photon_seconds,
            ..Default::default()
        };
        summary.render_seconds = t0.elapsed().as_secs_f64();
        let load = std::mem::take(&mut *job.unreported.lock().unwrap_or_else(std::sync::PoisonError::into_inner));
        summary.load_seconds = load.seconds;
        summary.photon_paths += load.photon_paths;
        summary.photon_seconds += load.photon_seconds;
        let checksum = photon_proto::checksum(&bytes).to_vec();
        let corrupt = if self.panic {
            Err(0)
        } else {
            self.corrupt_left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1))
        };
        if corrupt.is_ok() && bytes.len() >= 4 {
            tracing::warn!(strip = r.strip, "fault injection: corrupting a pixel after the checksum");
            bytes[0] ^= 0x40;
        }
        summary.checksum = checksum;
        let row_bytes = 3 * 8 * width as usize;
        let rows_per_chunk = (MAX_CHUNK / row_bytes.max(1)).max(1);
        let mut events: Vec<Event_> = bytes
            .chunks(rows_per_chunk * row_bytes)
            .enumerate()
            .map(|(i, c)| {
                let first_row = r.row_start + (i * rows_per_chunk) as u32;
                let rows = pb::PixelRows { first_row, data: c.to_vec() };
                Ok(pb::StripEvent { event: Some(Event::Sums(rows)) })
            })
            .collect();
        events.push(Ok(pb::StripEvent { event: Some(Event::Done(summary)) }));
        Ok(events)
    }
}

/// Checks a request's units against its frame: a non-empty block of at most [`MAX_BLOCK_UNITS`] within the
/// job's units ([`RenderSettings::units`]: samples per pixel, or passes).
fn check_units(r: &pb::StripRequest, settings: &RenderSettings) -> Result<(), Status> {
    let (start, end, total) = (r.unit_start, r.unit_end, settings.units());
    let what = match settings.integrator.unit() {
        Unit::Samples => "samples per pixel",
        Unit::Passes => "passes",
    };
    if start >= end || end > total {
        return Err(Status::out_of_range(format!(
            "unit_start/unit_end {start}..{end}: expected a non-empty block within the job's {total} {what}"
        )));
    }
    if end - start > MAX_BLOCK_UNITS {
        return Err(Status::invalid_argument(format!(
            "unit_start/unit_end {start}..{end}: expected at most {MAX_BLOCK_UNITS} units in one block"
        )));
    }
    Ok(())
}
