//! Who may call a worker, and how a session starts: the gRPC server with its token check ([`serve`]), and
//! `Hello`, where the coordinator and the worker agree on the protocol and the build. The cap on calls in
//! progress per peer is `peers.rs`.

use crate::config::memory_bytes;
use crate::service::Worker;
use photon_proto::pb::{self, render_server::RenderServer};
use photon_proto::{MAX_MESSAGE, quote};
use std::future::Future;
use tonic::{Request, Status};

/// Serves `worker` on `listener` until `shutdown` resolves; strips in progress are cancelled then. The
/// connections are guarded ([`crate::Config::handshake_timeout`], [`crate::Config::max_connections`]).
pub async fn serve(
    worker: Worker,
    listener: tokio::net::TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), tonic::transport::Error> {
    let token = worker.config.token.clone();
    let (handshake, max_connections) = (worker.config.handshake_timeout, worker.config.max_connections);
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
        .serve_with_incoming_shutdown(crate::listen::incoming(listener, handshake, max_connections), shutdown)
        .await
}

impl Worker {
    /// `Hello`: refuses another protocol version or build, starts a new session, and describes this worker.
    pub(crate) fn greet(&self, r: pb::HelloRequest) -> Result<pb::HelloReply, Status> {
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
        self.jobs.forget_unreported();
        Ok(pb::HelloReply {
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
        })
    }
}

/// This machine's name, empty where it cannot be read.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_owned())
        .unwrap_or_default()
}
