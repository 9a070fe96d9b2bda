//! The render service: the [`Worker`] with its shared state, and the gRPC `Render` trait, each call admitted by
//! its peer's count and handed to the file of its concern (`server.rs`: `Hello`; `blobs.rs`: blobs in and out;
//! `strip.rs`: strips).

use crate::cache::BlobCache;
use crate::config::{Config, Limits};
use crate::jobs::JobCache;
use crate::peers::PeerCalls;
use photon_proto::pb::{self, render_server::Render};
use photon_proto::transport::SERVED_AT_ONCE;
use std::sync::Arc;
use std::sync::atomic::AtomicUsize;
use tokio::sync::Semaphore;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

/// One message of a strip's response stream: an event, or the status that ends the stream.
pub(crate) type EventOrStatus = Result<pb::StripEvent, Status>;

/// The render service.
pub struct Worker {
    pub(crate) config: Config,
    pub(crate) pool: Arc<rayon::ThreadPool>,
    pub(crate) blobs: Arc<BlobCache>,
    /// The most recently used decoded jobs.
    pub(crate) jobs: Arc<JobCache>,
    /// One strip renders at a time: it has all the cores.
    pub(crate) render_slot: Arc<Semaphore>,
    /// Bytes that uploads in progress hold ([`Config::upload_budget_bytes`]).
    pub(crate) upload_bytes: Arc<Semaphore>,
    /// Blobs served to peers at once ([`photon_proto::transport::SERVED_AT_ONCE`]).
    pub(crate) serving: Arc<Semaphore>,
    /// Strip requests waiting for the render slot ([`Config::max_queue`]).
    pub(crate) waiting: Arc<AtomicUsize>,
    /// The fault this worker commits, and the strips it has left to commit it in.
    #[cfg(feature = "fault-injection")]
    pub(crate) faults: Arc<crate::fault::Injector>,
    /// Calls in progress per peer ([`Config::max_calls_per_peer`]).
    pub(crate) peers: Arc<PeerCalls>,
}

/// Why a worker cannot start.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    /// The render thread pool cannot be built.
    #[error("cannot start the render threads: {0}")]
    Threads(rayon::ThreadPoolBuildError),
    /// The blob cache cannot be opened.
    #[error(transparent)]
    Cache(#[from] crate::disk_store::DiskStoreError),
}

impl Worker {
    /// A worker with `config`; starts its thread pool and opens its disk cache.
    pub fn new(config: Config) -> Result<Self, WorkerError> {
        let mut pool = rayon::ThreadPoolBuilder::new().thread_name(|i| format!("photon-render-{i}"));
        if let Some(n) = config.threads {
            pool = pool.num_threads(n);
        }
        let pool = pool.build().map_err(WorkerError::Threads)?;
        let blobs = BlobCache::new(config.memory_cache_bytes, config.disk_cache.clone())?;
        let upload_budget =
            usize::try_from(config.upload_budget_bytes).unwrap_or(usize::MAX).min(Semaphore::MAX_PERMITS);
        Ok(Self {
            pool: Arc::new(pool),
            blobs: Arc::new(blobs),
            jobs: Arc::new(JobCache::default()),
            render_slot: Arc::new(Semaphore::new(1)),
            upload_bytes: Arc::new(Semaphore::new(upload_budget)),
            serving: Arc::new(Semaphore::new(SERVED_AT_ONCE)),
            waiting: Arc::new(AtomicUsize::new(0)),
            #[cfg(feature = "fault-injection")]
            faults: Arc::new(crate::fault::Injector::new(config.fault)),
            peers: Arc::new(PeerCalls::new(config.max_calls_per_peer)),
            config,
        })
    }

    /// Threads the worker renders with.
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// What this worker checks strip requests against (with no texture images: a request adds its own).
    pub fn limits(&self) -> Limits {
        Limits {
            strip_memory_bytes: self.config.strip_memory_bytes,
            threads: self.threads(),
            texture_bytes: 0,
            max_strip_work: self.config.max_strip_work,
        }
    }
}

/// Every call is admitted by its peer's count of calls in progress ([`Config::max_calls_per_peer`]) and held
/// for as long as it runs, then handled by the module of its concern.
#[tonic::async_trait]
impl Render for Worker {
    async fn hello(&self, request: Request<pb::HelloRequest>) -> Result<Response<pb::HelloReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        self.greet(request.into_inner()).map(Response::new)
    }

    async fn missing_blobs(
        &self,
        request: Request<pb::MissingBlobsRequest>,
    ) -> Result<Response<pb::MissingBlobsReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        self.missing(request.into_inner().ids).map(Response::new)
    }

    async fn put_blob(&self, request: Request<Streaming<pb::BlobChunk>>) -> Result<Response<pb::PutBlobReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        let stored = self.receive_blob(&mut request.into_inner(), None).await?;
        Ok(Response::new(pb::PutBlobReply { stored }))
    }

    async fn fetch_blob(&self, request: Request<pb::FetchBlobRequest>) -> Result<Response<pb::PutBlobReply>, Status> {
        let _call = self.peers.admit(request.remote_addr())?;
        let stored = self.fetch(request.into_inner()).await?;
        Ok(Response::new(pb::PutBlobReply { stored }))
    }

    type GetBlobStream = ReceiverStream<Result<pb::BlobChunk, Status>>;

    async fn get_blob(&self, request: Request<pb::GetBlobRequest>) -> Result<Response<Self::GetBlobStream>, Status> {
        // The call is held by the stream's task until the blob is sent.
        self.serve_blob(request).map(Response::new)
    }

    type RenderStripStream = ReceiverStream<EventOrStatus>;

    async fn render_strip(
        &self,
        request: Request<pb::StripRequest>,
    ) -> Result<Response<Self::RenderStripStream>, Status> {
        // The call is held by the strip's task until its last event is sent (or it is cancelled).
        self.start_strip(request).await
    }
}
