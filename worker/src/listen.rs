//! The connections a worker accepts, guarded: a new connection must send its first [`HANDSHAKE_BYTES`] (the
//! HTTP/2 client preface, or the start of a TLS handshake) within the handshake timeout or it is closed, and at
//! most [`crate::Config::max_connections`] are open at once. At the cap, a new connection closes the oldest one
//! that has not finished its handshake (an idle socket that never spoke), so a coordinator still gets in while
//! thousands of idle sockets are opened; only when every open connection has finished its handshake is the new
//! one refused. A failed `accept` (out of file descriptors) waits a moment and frees the oldest idle socket
//! instead of spinning.
//!
//! What it cannot see: a client that completes the preface and then idles is left to HTTP/2's keep-alive pings
//! ([`photon_proto::transport::KEEPALIVE_TIMEOUT`]) and the per-peer call cap; one that drips a TLS handshake
//! after its first bytes, to the TLS handshake timeout of the server builder.

use std::collections::VecDeque;
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, oneshot};
use tokio_stream::wrappers::ReceiverStream;
use tonic::transport::server::{Connected, TcpConnectInfo};

/// Bytes a new connection must send within the handshake timeout: the HTTP/2 client preface
/// (`PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n`, RFC 9113 §3.4); a TLS ClientHello is longer.
pub const HANDSHAKE_BYTES: usize = 24;

/// How long a failed `accept` waits before the next (the error is usually "too many open files").
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// Open connections, and the ones still in their handshake, oldest first.
#[derive(Default)]
struct Registry {
    open: usize,
    /// Dropping a sender closes its connection (the connection's read sees it).
    in_handshake: VecDeque<oneshot::Sender<()>>,
}

impl Registry {
    /// Closes the oldest connection still in its handshake (skipping those that finished it); whether there
    /// was one.
    fn evict_oldest(&mut self) -> bool {
        while let Some(evict) = self.in_handshake.pop_front() {
            if !evict.is_closed() {
                return true;
            }
        }
        false
    }
}

/// The connections accepted on `listener`, guarded as the module says, for the server to serve.
pub(crate) fn incoming(
    listener: TcpListener,
    handshake_timeout: Duration,
    max_connections: usize,
) -> ReceiverStream<io::Result<Guarded>> {
    let (tx, rx) = mpsc::channel(16);
    let registry = Arc::new(Mutex::new(Registry::default()));
    tokio::spawn(async move {
        loop {
            let accepted = tokio::select! {
                a = listener.accept() => a,
                // The server stopped: release the port.
                () = tx.closed() => return,
            };
            let stream = match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    tracing::warn!("accepting a connection failed: {e}; closing the oldest idle one");
                    lock(&registry).evict_oldest();
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                    continue;
                }
            };
            // Without it every small message waits for a delayed ACK (~40 ms).
            let _ = stream.set_nodelay(true);
            let closed = {
                let mut r = lock(&registry);
                // Forget the connections that finished their handshake, so the list stays as short as the cap.
                r.in_handshake.retain(|s| !s.is_closed());
                if r.open >= max_connections.max(1) && !r.evict_oldest() {
                    tracing::warn!(max_connections, "refusing a connection: all open ones are in use");
                    continue;
                }
                r.open += 1;
                let (evict, closed) = oneshot::channel();
                r.in_handshake.push_back(evict);
                closed
            };
            let conn = Guarded {
                inner: stream,
                handshake: Some(Handshake {
                    left: HANDSHAKE_BYTES,
                    deadline: Box::pin(tokio::time::sleep(handshake_timeout)),
                    closed,
                }),
                _open: Open(registry.clone()),
            };
            if tx.send(Ok(conn)).await.is_err() {
                return;
            }
        }
    });
    ReceiverStream::new(rx)
}

fn lock(r: &Mutex<Registry>) -> std::sync::MutexGuard<'_, Registry> {
    r.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A connection's place in the count of open ones, given back when it closes.
struct Open(Arc<Mutex<Registry>>);

impl Drop for Open {
    fn drop(&mut self) {
        let mut r = lock(&self.0);
        r.open = r.open.saturating_sub(1);
    }
}

/// A connection in its handshake: the bytes it must still send, by when, and its eviction.
struct Handshake {
    left: usize,
    deadline: Pin<Box<tokio::time::Sleep>>,
    /// Resolves when the registry evicts the connection.
    closed: oneshot::Receiver<()>,
}

/// An accepted connection, closed when its handshake is late or it is evicted.
pub(crate) struct Guarded {
    inner: TcpStream,
    handshake: Option<Handshake>,
    _open: Open,
}

impl AsyncRead for Guarded {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        let before = buf.filled().len();
        let read = Pin::new(&mut this.inner).poll_read(cx, buf);
        let Some(h) = &mut this.handshake else { return read };
        if let Poll::Ready(Ok(())) = read {
            let n = buf.filled().len() - before;
            // End of stream (0 bytes) goes up as it is; the handshake is over once its bytes arrived.
            h.left = h.left.saturating_sub(n);
            if h.left == 0 || n == 0 {
                this.handshake = None;
            }
            return read;
        }
        if read.is_ready() {
            return read;
        }
        if h.deadline.as_mut().poll(cx).is_ready() {
            return Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "no handshake within the timeout (photon-worker --handshake-timeout-s)",
            )));
        }
        if Pin::new(&mut h.closed).poll(cx).is_ready() {
            return Poll::Ready(Err(io::Error::new(
                io::ErrorKind::ConnectionAborted,
                "closed for a newer connection: the most connections are open (photon-worker --max-connections)",
            )));
        }
        Poll::Pending
    }
}

impl AsyncWrite for Guarded {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}

impl Connected for Guarded {
    type ConnectInfo = TcpConnectInfo;

    fn connect_info(&self) -> TcpConnectInfo {
        self.inner.connect_info()
    }
}
