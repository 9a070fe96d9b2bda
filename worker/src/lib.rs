//! photon-worker: a gRPC server that renders strips of prepared scenes on all its cores.
//!
//! The coordinator introduces itself ([`Hello`](photon_proto::pb::HelloRequest): the protocol version and build
//! id must equal this worker's), uploads the blobs the worker lacks, then asks for strips. Blobs live in a
//! bounded, content-addressed cache ([`cache`]) in memory and optionally on disk, so a second render of the same
//! scene ships nothing. A strip renders on the worker's rayon pool, one strip at a time, off the async runtime;
//! a few more may wait ([`Config::max_queue`]), beyond that a request is refused as `RESOURCE_EXHAUSTED`.
//! A worker serves the blobs it holds to its peers (`GetBlob`) and, asked by the coordinator, fetches a blob
//! from a peer (`FetchBlob`) with its own token, checking the size and hash like an upload's.
//!
//! The crate by concern: the [`Worker`] and its `Render` trait (`service.rs`); [`Config`] and [`Limits`]
//! (`config.rs`); who may call and `Hello` ([`serve`], `server.rs`, `peers.rs`, `listen.rs`); blobs in and out
//! (`blobs.rs`); a strip's checked request ([`check_strip_request`], [`StripOrder`], `order.rs`), its decoded
//! job (`jobs.rs`) and its render and events (`strip.rs`); the blob cache ([`cache`], [`disk_store`]). The files
//! of each concern name `service.rs`, never the other way: no file names a file that names it back
//! (`tests/module_layers.rs`).
//!
//! ## Refusals
//!
//! Everything a peer sends is checked before it is used, and a bad request gets a gRPC status that says what
//! was wrong; the worker keeps serving. A status echoes at most a short, escaped prefix of a received value
//! ([`photon_proto::quote`]).
//!
//! | Status code | When |
//! |---|---|
//! | `FAILED_PRECONDITION` | another protocol version or build (`Hello`) |
//! | `FAILED_PRECONDITION` | a fetch without the farm's CA, on a worker that speaks TLS |
//! | `UNAUTHENTICATED` | a wrong or missing token |
//! | `RESOURCE_EXHAUSTED` | a blob larger than [`Config::max_blob_bytes`] |
//! | `RESOURCE_EXHAUSTED` | uploads in progress hold the upload memory ([`Config::upload_budget_bytes`]) |
//! | `RESOURCE_EXHAUSTED` | a strip that would not fit the worker's memory ([`Config::strip_memory_bytes`]) |
//! | `FAILED_PRECONDITION` | a strip whose photons or light vertices, traced, pass that memory ([`photon_core::run::StorageError`]) |
//! | `RESOURCE_EXHAUSTED` | [`Config::max_queue`] strips wait already |
//! | `RESOURCE_EXHAUSTED` | a peer (a remote IP address) has [`Config::max_calls_per_peer`] calls in progress |
//! | `RESOURCE_EXHAUSTED` | the most blobs served to peers at once ([`photon_proto::transport::SERVED_AT_ONCE`]) |
//! | `INVALID_ARGUMENT` | an id that is not a blob id, more ids in one request than accepted, or a texture named twice |
//! | `INVALID_ARGUMENT` | a strip of more work than [`Config::max_strip_work`] (pixels × units × `max_depth`) |
//! | `INVALID_ARGUMENT` | a truncated or overlong upload |
//! | `INVALID_ARGUMENT` | a frame whose sizes or settings are out of range, or whose method lacks its photons blob |
//! | `INVALID_ARGUMENT` | blobs that do not decode |
//! | `DATA_LOSS` | bytes that do not hash to their id |
//! | `DEADLINE_EXCEEDED` | an upload that stalls or crawls ([`Config::upload_idle`], [`Config::upload_min_rate`]) |
//! | `DEADLINE_EXCEEDED` | a blob served to a peer that is not read within the same allowance |
//! | `NOT_FOUND` | an unknown blob |
//! | `OUT_OF_RANGE` | empty rows or rows outside the image; units outside the job's |
//! | `ABORTED` | a fetch that fails through the peer: unreachable, refusing, or sending other bytes |
//! | `CANCELLED` | a strip whose call ended (cancelled, dropped, past its deadline) while it rendered; its slot is free within a second, and one that waited gives up its queue place at once |
//! | `INTERNAL` | a panic while rendering (a bug): that strip fails, not the worker |
//!
//! A strip request's refusals name the field ([`check_strip_request`]); a per-peer refusal names the cap.
//!
//! Below gRPC, a connection that does not send its first bytes within [`Config::handshake_timeout`] is closed,
//! and at most [`Config::max_connections`] are open at once; at the cap the oldest connection still in its
//! handshake makes way for the new one (`listen.rs`).
//!
//! ## Fault injection
//!
//! With the cargo feature `fault-injection` (off by default) a worker can commit chosen faults (`Fault`: corrupt
//! or impossible sums, panics, delays, corrupt blobs served to peers; the hidden `--test-…` flags of
//! photon-worker), so the end-to-end tests in `tests/` can prove that the coordinator catches them; they build
//! the worker with the feature. Release binaries (`cargo build --release -p photon-worker`) are built without
//! it: they have neither the fault code nor its flags.
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

mod blobs;
pub mod cache;
mod config;
pub mod disk_store;
#[cfg(feature = "fault-injection")]
mod fault;
mod jobs;
mod listen;
mod order;
mod peers;
mod server;
mod service;
mod strip;

pub use config::{Config, DEFAULT_MAX_STRIP_WORK, Limits};
#[cfg(feature = "fault-injection")]
pub use fault::Fault;
pub use order::{MAX_FRAME_BYTES, MAX_TEXTURES, StripOrder, check_strip_request};
pub use server::serve;
pub use service::{Worker, WorkerError};
