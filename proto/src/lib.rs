//! photon-proto: the wire protocol between coordinator and workers.
//!
//! `render.proto` (in this crate's folder) is the contract; [`pb`] is the code tonic and prost generate from it
//! at build time (with protox, so no `protoc` is needed). Around it this crate keeps what both ends must agree
//! on: the protocol version and the build id, blob ids, the strip checksum, the pixel encoding, the token
//! header, and the transport settings, each in one place. The protocol's walk-through is the comment at the top
//! of `render.proto`; the repository's `docs/ARCHITECTURE.md` places it in the design.
//!
//! ## Example
//!
//! Blobs are content-addressed: their id is the hash of their bytes, so a worker holding an id holds exactly
//! those bytes, and a blob travels as chunks of at most [`MAX_CHUNK`] bytes, the first carrying the header.
//!
//! ```
//! use std::sync::Arc;
//!
//! let scene = Arc::new(vec![7u8; 3 * photon_proto::MAX_CHUNK + 5]);
//! let id = photon_proto::blob_id(&scene);
//! assert!(photon_proto::is_blob_id(&id));
//! let header = photon_proto::pb::BlobHeader { id, size: scene.len() as u64 };
//! let chunks: Vec<_> = photon_proto::blob_chunks(header, scene.clone()).collect();
//! assert_eq!(chunks.len(), 4);
//! assert!(chunks[0].header.is_some() && chunks[1..].iter().all(|c| c.header.is_none()));
//! assert_eq!(chunks.iter().map(|c| c.data.len()).sum::<usize>(), scene.len());
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

use std::time::Duration;

/// The generated messages, client and server.
#[allow(missing_docs, clippy::all, clippy::pedantic)]
pub mod pb {
    tonic::include_proto!("photon.v1");
}

/// Version of the protocol; raise it with every incompatible change of `render.proto` or of its meaning.
pub const PROTOCOL_VERSION: u32 = 7;

/// A hash of the code that decides what a worker renders and how it speaks (core, proto, worker and the locked
/// dependencies): coordinator and workers must have the same one.
pub const BUILD_ID: &str = env!("PHOTON_BUILD_ID");

/// The crate version, for people reading reports.
pub const CRATE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// The largest chunk of a `PutBlob` stream and of a strip's pixel rows, in bytes.
pub const MAX_CHUNK: usize = 1 << 20;

/// The largest gRPC message either end decodes: a chunk plus the message's own fields.
pub const MAX_MESSAGE: usize = MAX_CHUNK + (64 << 10);

/// The metadata key of the shared token: `authorization: Bearer <token>`.
pub const TOKEN_KEY: &str = "authorization";

/// The id of a blob: the lowercase hex BLAKE3 hash of its bytes (64 characters).
pub fn blob_id(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// The messages of a blob's stream (a `PutBlob` upload or a `GetBlob` answer), made lazily: the header rides
/// with the first chunk, and each chunk of at most [`MAX_CHUNK`] bytes is copied only as the stream is sent.
pub fn blob_chunks(header: pb::BlobHeader, blob: std::sync::Arc<Vec<u8>>) -> impl Iterator<Item = pb::BlobChunk> {
    let n = blob.len().div_ceil(MAX_CHUNK).max(1);
    let mut header = Some(header);
    (0..n).map(move |i| {
        let lo = i * MAX_CHUNK;
        let hi = (lo + MAX_CHUNK).min(blob.len());
        pb::BlobChunk { header: header.take(), data: blob[lo..hi].to_vec() }
    })
}

/// Whether `id` has the form of a blob id (64 lowercase hex digits).
pub fn is_blob_id(id: &str) -> bool {
    id.len() == 64 && id.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// An incremental hash, for blobs that arrive in chunks and for strip checksums.
pub type Hasher = blake3::Hasher;

/// The checksum of a strip: BLAKE3 of its pixel bytes in order.
pub fn checksum(bytes: &[u8]) -> [u8; 32] {
    *blake3::hash(bytes).as_bytes()
}

/// Fixed-point block sums as little-endian bytes, 8 per value.
pub fn sums_to_bytes(sums: &[i64]) -> Vec<u8> {
    sums.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Little-endian bytes back to block sums; `None` when the length is not a multiple of 8.
pub fn bytes_to_sums(bytes: &[u8]) -> Option<Vec<i64>> {
    let chunks = bytes.chunks_exact(8);
    if !chunks.remainder().is_empty() {
        return None;
    }
    Some(chunks.map(|c| i64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])).collect())
}

/// The value of the token metadata for `token`.
pub fn bearer(token: &str) -> String {
    format!("Bearer {token}")
}

/// Why a token file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    /// The file cannot be read.
    #[error("cannot read the token file {}: {cause}", path.display())]
    Read {
        /// The file.
        path: std::path::PathBuf,
        /// The reason.
        cause: std::io::Error,
    },
    /// The file holds only white space.
    #[error("the token file {} is empty", path.display())]
    Empty {
        /// The file.
        path: std::path::PathBuf,
    },
    /// The token has a space or a character outside printable ASCII.
    #[error("the token in {} must be printable ASCII without spaces", path.display())]
    NotPrintable {
        /// The file.
        path: std::path::PathBuf,
    },
}

/// Reads a shared token from a file: its content without surrounding white space; it must not be empty and must
/// be printable ASCII (it travels in an HTTP/2 header).
pub fn read_token(path: &std::path::Path) -> Result<String, TokenError> {
    let text = std::fs::read_to_string(path).map_err(|cause| TokenError::Read { path: path.into(), cause })?;
    let token = text.trim();
    if token.is_empty() {
        return Err(TokenError::Empty { path: path.into() });
    }
    if !token.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(TokenError::NotPrintable { path: path.into() });
    }
    Ok(token.to_owned())
}

/// At most [`QUOTE_CHARS`] characters of a received value, escaped (control characters and quotes as Rust
/// escapes) and in backquotes, with the length of the rest: what a status or an error may echo of what a peer
/// sent, so that a megabyte-long value cannot blow the 16 KiB limit of gRPC's metadata, nor a log line.
pub fn quote(value: &str) -> String {
    let mut out = String::from("`");
    let mut chars = value.chars();
    for c in chars.by_ref().take(QUOTE_CHARS) {
        out.extend(c.escape_debug());
    }
    out.push('`');
    let rest = chars.as_str().len();
    if rest > 0 {
        out.push_str(&format!("… ({rest} more bytes)"));
    }
    out
}

/// How many characters of a received value [`quote`] shows.
pub const QUOTE_CHARS: usize = 64;

/// Compares two tokens in time that does not depend on where they differ.
pub fn tokens_match(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Transport settings, all in one place: HTTP/2 keep-alive pings find a dead peer whose connection the kernel
/// still believes open (a machine that lost power), and TCP_NODELAY keeps small strip requests from waiting.
pub mod transport {
    use super::*;

    /// How often an idle connection is pinged.
    pub const KEEPALIVE_INTERVAL: Duration = Duration::from_secs(10);
    /// How long a ping may go unanswered before the connection is declared dead.
    pub const KEEPALIVE_TIMEOUT: Duration = Duration::from_secs(20);
    /// How long a server waits for a client's TLS handshake.
    pub const TLS_HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
    /// How long the coordinator waits for a worker's TCP connection.
    pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

    /// A client endpoint for a worker at `uri` (`http://host:port`).
    pub fn endpoint(uri: &str) -> Result<tonic::transport::Endpoint, tonic::transport::Error> {
        Ok(tonic::transport::Endpoint::from_shared(uri.to_owned())?
            .connect_timeout(CONNECT_TIMEOUT)
            .tcp_nodelay(true)
            .http2_keep_alive_interval(KEEPALIVE_INTERVAL)
            .keep_alive_timeout(KEEPALIVE_TIMEOUT)
            .keep_alive_while_idle(true))
    }

    /// A client endpoint that speaks TLS to a worker at `uri` (`https://host:port`), trusting only the
    /// certificate authority in `ca_pem`; the worker's certificate must name the host of `uri`.
    pub fn tls_endpoint(uri: &str, ca_pem: &[u8]) -> Result<tonic::transport::Endpoint, tonic::transport::Error> {
        let tls =
            tonic::transport::ClientTlsConfig::new().ca_certificate(tonic::transport::Certificate::from_pem(ca_pem));
        endpoint(uri)?.tls_config(tls)
    }

    /// The URI of a worker at `address` (`host:port`, or a URI with a scheme): `http://` unless the address names
    /// a scheme, and `https://` in place of `http://` when `tls`.
    pub fn worker_uri(address: &str, tls: bool) -> String {
        let uri = if address.contains("://") { address.to_owned() } else { format!("http://{address}") };
        if tls { uri.replacen("http://", "https://", 1) } else { uri }
    }

    /// A client endpoint for the worker at `uri` ([`worker_uri`]), speaking TLS and trusting only the authority
    /// in `tls_ca` when one is given.
    pub fn client_endpoint(
        uri: &str,
        tls_ca: Option<&[u8]>,
    ) -> Result<tonic::transport::Endpoint, tonic::transport::Error> {
        match tls_ca {
            Some(ca) => tls_endpoint(uri, ca),
            None => endpoint(uri),
        }
    }

    /// A server builder that speaks TLS with the certificate chain and key in `cert_pem` and `key_pem`.
    pub fn tls_server(cert_pem: &[u8], key_pem: &[u8]) -> Result<tonic::transport::Server, tonic::transport::Error> {
        let identity = tonic::transport::Identity::from_pem(cert_pem, key_pem);
        server().tls_config(tonic::transport::ServerTlsConfig::new().identity(identity).timeout(TLS_HANDSHAKE_TIMEOUT))
    }

    /// The connections a server accepts on `listener`, with TCP_NODELAY (a server given its own listener does not
    /// apply the builder's setting, and without it every small message waits for a delayed ACK, ~40 ms).
    pub fn incoming(listener: tokio::net::TcpListener) -> tonic::transport::server::TcpIncoming {
        tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true))
    }

    /// Calls one connection may have in progress at once; more wait. A coordinator needs a few strips, an upload
    /// and a heartbeat at a time: the cap keeps one peer from opening thousands of calls.
    pub const CALLS_PER_CONNECTION: usize = 32;

    /// Calls one peer (one remote IP address, over all its connections) may have in progress at once by default;
    /// a worker refuses more with `RESOURCE_EXHAUSTED` (photon-worker `--max-calls-per-peer`). Opening many
    /// connections then gains a peer nothing over [`CALLS_PER_CONNECTION`] each.
    pub const CALLS_PER_PEER: usize = 64;

    /// Blobs a worker serves to peers at once (`GetBlob`); a farm passing blobs on asks each holder for one at a
    /// time, so more is a misbehaving caller, refused with `RESOURCE_EXHAUSTED`.
    pub const SERVED_AT_ONCE: usize = 4;

    /// A server builder with the same settings.
    pub fn server() -> tonic::transport::Server {
        tonic::transport::Server::builder()
            .concurrency_limit_per_connection(CALLS_PER_CONNECTION)
            .max_concurrent_streams(Some(2 * CALLS_PER_CONNECTION as u32))
            .tcp_nodelay(true)
            .http2_keepalive_interval(Some(KEEPALIVE_INTERVAL))
            .http2_keepalive_timeout(Some(KEEPALIVE_TIMEOUT))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quotes_are_short_and_escaped() {
        assert_eq!(quote("abc"), "`abc`");
        assert_eq!(quote("a\nb\"\u{7}"), "`a\\nb\\\"\\u{7}`");
        let long = "x".repeat(1 << 20);
        let q = quote(&long);
        assert!(q.len() < 100 && q.ends_with(&format!("({} more bytes)", (1 << 20) - QUOTE_CHARS)), "{q}");
    }

    #[test]
    fn blob_ids_are_hex_blake3() {
        let id = blob_id(b"photon");
        assert!(is_blob_id(&id), "{id}");
        assert_ne!(id, blob_id(b"photon "));
        assert!(!is_blob_id("ABC"));
        assert!(!is_blob_id(&id.to_uppercase()));
        let mut h = Hasher::new();
        h.update(b"pho");
        h.update(b"ton");
        assert_eq!(h.finalize().to_hex().as_str(), id);
    }

    #[test]
    fn sums_round_trip() {
        let s = [0i64, -1, i64::MAX, 1 << 40];
        assert_eq!(bytes_to_sums(&sums_to_bytes(&s)).unwrap(), s);
        assert!(bytes_to_sums(&[0; 12]).is_none());
    }

    #[test]
    fn tokens() {
        assert!(tokens_match("s3cret", "s3cret"));
        assert!(!tokens_match("s3cret", "s3cres"));
        assert!(!tokens_match("s3cret", "s3cret!"));
    }

    #[test]
    fn token_files_are_checked() {
        let dir = std::env::temp_dir().join(format!("photon-token-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("token");
        std::fs::write(&p, "  s3cret\n").unwrap();
        assert_eq!(read_token(&p).unwrap(), "s3cret");
        std::fs::write(&p, " \n").unwrap();
        assert!(matches!(read_token(&p), Err(TokenError::Empty { .. })));
        std::fs::write(&p, "s3 cret").unwrap();
        let e = read_token(&p).unwrap_err();
        assert!(e.to_string().contains("must be printable ASCII without spaces"), "{e}");
        assert!(matches!(read_token(&dir.join("missing")), Err(TokenError::Read { .. })));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn build_id_is_set() {
        assert_eq!(BUILD_ID.len(), 16);
    }
}
