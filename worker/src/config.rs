//! A worker's settings ([`Config`], with the defaults the command line starts from) and what a strip request is
//! checked against ([`Limits`]).

use std::path::PathBuf;
use std::time::Duration;

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
    /// refused before it allocates ([`photon_core::prepare::budget::MemoryEstimate::strip`]), and a run that
    /// stores more photons or light vertices than this stops with `FAILED_PRECONDITION`
    /// ([`photon_core::run::Guard::storage_bytes`]).
    pub strip_memory_bytes: u64,
    /// The most work one strip may ask for, in path vertices (pixels × units × `render.max_depth`); more is
    /// refused as `INVALID_ARGUMENT` (photon-worker `--max-strip-work`).
    pub max_strip_work: u64,
    /// How long a new connection may take to send its first bytes (the HTTP/2 preface, or a TLS handshake's
    /// first record) before it is closed (photon-worker `--handshake-timeout-s`).
    pub handshake_timeout: Duration,
    /// Connections open at once; at the cap a new connection closes the oldest one that has not finished its
    /// handshake, or is itself refused when all have (photon-worker `--max-connections`).
    pub max_connections: usize,
    /// Strip requests that may wait behind the one rendering.
    pub max_queue: usize,
    /// Calls one remote IP address may have in progress at once, over all its connections.
    pub max_calls_per_peer: usize,
    /// The build id this worker claims (the real one unless a test pretends otherwise).
    pub build_id: String,
    /// The math mode this worker claims (the real one, [`photon_core::math::fmath::MODE`], unless a test pretends
    /// otherwise).
    pub math_mode: String,
    /// Test-only fault injection (the cargo feature `fault-injection`).
    #[cfg(feature = "fault-injection")]
    pub fault: crate::fault::Fault,
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
            strip_memory_bytes: photon_core::run::half_the_memory(),
            max_strip_work: DEFAULT_MAX_STRIP_WORK,
            handshake_timeout: Duration::from_secs(10),
            max_connections: 512,
            max_queue: 4,
            max_calls_per_peer: photon_proto::transport::CALLS_PER_PEER,
            build_id: photon_proto::BUILD_ID.to_owned(),
            math_mode: photon_core::math::fmath::MODE.to_owned(),
            #[cfg(feature = "fault-injection")]
            fault: crate::fault::Fault::None,
        }
    }
}

/// The default of [`Config::max_strip_work`]: 2⁴⁸ path vertices, about a 1920 × 1080 image at 8192 samples
/// per pixel and 16 bounces, or hours of one 16-core machine's work. The farm's blocks stay far below it.
pub const DEFAULT_MAX_STRIP_WORK: u64 = 1 << 48;

/// What a strip request is checked against.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Bytes one strip's buffers may take ([`Config::strip_memory_bytes`]).
    pub strip_memory_bytes: u64,
    /// The worker's render threads (each keeps its own k-nearest buffer).
    pub threads: usize,
    /// Bytes of the texture images the request names: their blobs' sizes (0 when it names none; a request that
    /// names one twice is refused before its memory is checked).
    pub texture_bytes: u64,
    /// The most path vertices one strip may ask for ([`Config::max_strip_work`]).
    pub max_strip_work: u64,
}

/// Physical memory in bytes, 0 where it is not known.
pub(crate) fn memory_bytes() -> u64 {
    photon_core::prepare::budget::machine_memory().unwrap_or(0)
}
