//! `photon-worker`: serves strips to a photon coordinator.
#![forbid(unsafe_code)]

use anyhow::{Context, Result, bail};
use clap::Parser;
use photon_worker::{Config, Worker};
use std::io::Write;
use std::path::PathBuf;

#[cfg(feature = "fault-injection")]
use photon_worker::Fault;

/// A photon render worker: renders strips of prepared scenes for a coordinator, over gRPC.
#[derive(Parser, Debug)]
#[command(name = "photon-worker", version, about)]
struct Cli {
    /// Address to listen on, e.g. `0.0.0.0:7878` for a lab network or `127.0.0.1:0` for a free loopback port.
    /// The address bound is printed on the first line of standard output.
    #[arg(long, default_value = "127.0.0.1:7878")]
    listen: String,
    /// Render threads (default: all logical cores).
    #[arg(long)]
    threads: Option<usize>,
    /// A file holding the shared token every coordinator call must carry.
    #[arg(long)]
    token_file: Option<PathBuf>,
    /// Speak TLS with this PEM certificate (chain); needs --tls-key. See deploy/tls/make-certs.sh.
    #[arg(long, requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// The PEM private key of --tls-cert.
    #[arg(long, requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// A folder that keeps received blobs across restarts.
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// Size cap of --cache-dir in MiB.
    #[arg(long, default_value_t = 8192)]
    cache_dir_mib: u64,
    /// Memory for blobs in MiB (least recently used out first).
    #[arg(long, default_value_t = 4096)]
    cache_mib: u64,
    /// The largest blob accepted, in MiB.
    #[arg(long, default_value_t = 4096)]
    max_blob_mib: u64,
    /// The longest wait for the next chunk of an upload, in seconds.
    #[arg(long, default_value_t = 30.0)]
    upload_idle_s: f64,
    /// The slowest upload accepted, in KiB per second: a blob must arrive within --upload-idle-s plus its size
    /// at this rate.
    #[arg(long, default_value_t = 256)]
    upload_min_kib_s: u64,
    /// Calls one remote IP address may have in progress at once, over all its connections; more are refused.
    #[arg(long, default_value_t = photon_proto::transport::CALLS_PER_PEER)]
    max_calls_per_peer: usize,
    /// Memory one strip may take, in MiB: its buffers (a larger strip is refused before it starts) and the
    /// photons or light vertices it traces (tracing past it stops with an error). Default: half the machine's
    /// memory.
    #[arg(long)]
    strip_memory_mib: Option<u64>,
    /// The most work one strip may ask for, in path vertices (pixels × samples or passes × render.max_depth).
    #[arg(long, default_value_t = photon_worker::DEFAULT_MAX_STRIP_WORK)]
    max_strip_work: u64,
    /// Seconds a new connection may take to send its first bytes (the HTTP/2 preface, or the start of a TLS
    /// handshake) before it is closed.
    #[arg(long, default_value_t = 10.0)]
    handshake_timeout_s: f64,
    /// Connections open at once (keep it below the open-file limit, `ulimit -n`); at the cap the oldest one
    /// still in its handshake is closed for the new one.
    #[arg(long, default_value_t = 512)]
    max_connections: usize,
    /// Test only: claim this build id instead of the real one.
    #[arg(long, hide = true)]
    test_build_id: Option<String>,
    /// Test only: claim this math mode instead of the real one.
    #[arg(long, hide = true)]
    test_math_mode: Option<String>,
    // Test only: the faults to commit, with the cargo feature `fault-injection` (release binaries have none).
    #[cfg(feature = "fault-injection")]
    #[command(flatten)]
    faults: FaultFlags,
}

/// The hidden flags of the faults a test makes a worker commit ([`Fault`]); when several are given, the last
/// in this list wins.
#[cfg(feature = "fault-injection")]
#[derive(clap::Args, Debug)]
struct FaultFlags {
    /// Test only: corrupt one pixel of each of the first N strips after computing their checksum.
    #[arg(long, hide = true, value_name = "N")]
    test_corrupt_strips: Option<u32>,
    /// Test only: render a NaN into every strip before its checksum, as a bug in an integrator would.
    #[arg(long, hide = true)]
    test_nan_strips: bool,
    /// Test only: panic while rendering each of the first N strips, as a bug would.
    #[arg(long, hide = true, value_name = "N")]
    test_panic_strips: Option<u32>,
    /// Test only: wait MS milliseconds before each strip, like a much slower machine.
    #[arg(long, hide = true, value_name = "MS")]
    test_delay_ms: Option<u64>,
    /// Test only: serve blobs to peers with a byte changed, as a bit flip in memory or on the wire would.
    #[arg(long, hide = true)]
    test_corrupt_blobs: bool,
}

#[cfg(feature = "fault-injection")]
impl FaultFlags {
    /// The fault the flags ask for.
    fn fault(&self) -> Fault {
        let mut fault = Fault::None;
        if let Some(n) = self.test_corrupt_strips {
            fault = Fault::CorruptPixels(n);
        }
        if self.test_nan_strips {
            fault = Fault::NanPixels;
        }
        if let Some(n) = self.test_panic_strips {
            fault = Fault::Panic(n);
        }
        if let Some(ms) = self.test_delay_ms {
            fault = Fault::Delay(ms);
        }
        if self.test_corrupt_blobs {
            fault = Fault::CorruptBlobs;
        }
        fault
    }
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// Refuses option values out of their range, naming the option.
fn check_options(cli: &Cli) -> Result<()> {
    if cli.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    if !(cli.upload_idle_s.is_finite() && cli.upload_idle_s > 0.0 && cli.upload_idle_s <= 86_400.0) {
        bail!("--upload-idle-s must be a number of seconds in (0, 86400], found {}", cli.upload_idle_s);
    }
    if cli.max_calls_per_peer == 0 {
        bail!("--max-calls-per-peer must be at least 1");
    }
    if cli.upload_min_kib_s == 0 {
        bail!("--upload-min-kib-s must be at least 1");
    }
    if !(cli.handshake_timeout_s.is_finite() && cli.handshake_timeout_s > 0.0 && cli.handshake_timeout_s <= 3600.0) {
        bail!("--handshake-timeout-s must be a number of seconds in (0, 3600], found {}", cli.handshake_timeout_s);
    }
    if cli.max_connections == 0 {
        bail!("--max-connections must be at least 1");
    }
    if cli.strip_memory_mib == Some(0) || cli.max_strip_work == 0 {
        bail!("--strip-memory-mib and --max-strip-work must be at least 1");
    }
    Ok(())
}

/// The worker's configuration from the options: the token file and TLS files read, sizes in bytes.
fn config(cli: &Cli) -> Result<Config> {
    let token = cli.token_file.as_deref().map(photon_proto::read_token).transpose()?;
    let read =
        |p: &PathBuf, what: &str| std::fs::read(p).with_context(|| format!("reading the {what} {}", p.display()));
    let tls = match (&cli.tls_cert, &cli.tls_key) {
        (Some(c), Some(k)) => Some((read(c, "TLS certificate")?, read(k, "TLS key")?)),
        _ => None,
    };
    let mut config = Config {
        threads: cli.threads,
        token,
        tls,
        memory_cache_bytes: cli.cache_mib << 20,
        disk_cache: cli.cache_dir.clone().map(|d| (d, cli.cache_dir_mib << 20)),
        max_blob_bytes: cli.max_blob_mib << 20,
        upload_budget_bytes: (2 * cli.max_blob_mib) << 20,
        upload_idle: std::time::Duration::from_secs_f64(cli.upload_idle_s),
        upload_min_rate: cli.upload_min_kib_s << 10,
        max_calls_per_peer: cli.max_calls_per_peer,
        max_strip_work: cli.max_strip_work,
        handshake_timeout: std::time::Duration::from_secs_f64(cli.handshake_timeout_s),
        max_connections: cli.max_connections,
        ..Config::default()
    };
    if let Some(mib) = cli.strip_memory_mib {
        config.strip_memory_bytes = mib.saturating_mul(1 << 20);
    }
    if let Some(id) = &cli.test_build_id {
        config.build_id = id.clone();
    }
    if let Some(mode) = &cli.test_math_mode {
        config.math_mode = mode.clone();
    }
    #[cfg(feature = "fault-injection")]
    {
        config.fault = cli.faults.fault();
    }
    Ok(config)
}

fn run(cli: Cli) -> Result<()> {
    check_options(&cli)?;
    let config = config(&cli)?;
    let config_tls_off = config.tls.is_none();
    let worker = Worker::new(config)?;
    let threads = worker.threads();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(&cli.listen)
            .await
            .with_context(|| format!("cannot listen on {}", cli.listen))?;
        let addr = listener.local_addr().context("reading the bound address")?;
        if !addr.ip().is_loopback() && config_tls_off {
            tracing::warn!(
                %addr,
                "listening beyond loopback without TLS: anyone who can reach this port can read the scenes and \
                 images; use --tls-cert/--tls-key (and --token-file) on a shared network"
            );
            eprintln!("warning: {addr} is not a loopback address and TLS is off (see --tls-cert)");
        }
        // Watch the signals before saying where we listen: a SIGTERM sent as soon as the address is known (a
        // script, a test, Slurm ending the job) must stop the worker cleanly, not kill it.
        let shutdown = shutdown_signal();
        // The first line of standard output names the address: scripts and tests that asked for port 0 read it.
        println!("photon-worker listening on {addr}");
        std::io::stdout().flush().context("writing to standard output")?;
        tracing::info!(
            %addr, threads, build = photon_proto::BUILD_ID, version = photon_proto::CRATE_VERSION, "serving"
        );
        photon_worker::serve(worker, listener, shutdown).await.context("serving")?;
        tracing::info!("stopped");
        Ok(())
    })
}

/// A future that resolves on SIGTERM or Ctrl-C. The SIGTERM handler is installed when this is called, not when
/// the future is first polled, so a SIGTERM that arrives after the call is never missed.
fn shutdown_signal() -> impl std::future::Future<Output = ()> {
    #[cfg(unix)]
    let term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .map_err(|e| tracing::warn!("cannot watch SIGTERM: {e}"))
        .ok();
    async move {
        let ctrl_c = async {
            let _ = tokio::signal::ctrl_c().await;
        };
        #[cfg(unix)]
        let term = async move {
            match term {
                Some(mut s) => {
                    s.recv().await;
                }
                None => std::future::pending::<()>().await,
            }
        };
        #[cfg(not(unix))]
        let term = std::future::pending::<()>();
        tokio::select! {
            () = ctrl_c => {}
            () = term => {}
        }
        tracing::info!("shutting down");
    }
}
