//! The workers of a render. Here: where they come from (a host list file, an address list, worker processes
//! started on loopback, or one worker server inside this process, the default). Below: one worker's side of the
//! wire ([`session`]: connect, hello, blob upload, strip fetch), blobs passed among the workers ([`swarm`]),
//! lost workers called back ([`rejoin`]), and the signals that stop a render ([`interrupt`]).

pub mod interrupt;
pub mod rejoin;
pub mod session;
pub mod swarm;

use session::{Greeting, WorkerAddr};
use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::io::AsyncBufReadExt;

/// Why the workers cannot be found or started. Each message is the one the user reads.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// The host list cannot be read.
    #[error("cannot read the host list {}: {cause}", path.display())]
    ReadHosts {
        /// The file.
        path: PathBuf,
        /// The reason.
        cause: std::io::Error,
    },
    /// The host list is not valid TOML of the expected shape.
    #[error("{}: {cause}", path.display())]
    ParseHosts {
        /// The file.
        path: PathBuf,
        /// The parser's message.
        cause: toml::de::Error,
    },
    /// The host list names no worker.
    #[error("{}: no [[worker]] entries (each needs an `address = \"host:port\"`)", path.display())]
    NoHosts {
        /// The file.
        path: PathBuf,
    },
    /// An entry of the host list has a bad address.
    #[error("{}: worker[{index}].address: {cause}", path.display())]
    HostAddress {
        /// The file.
        path: PathBuf,
        /// The entry.
        index: usize,
        /// What is wrong with it.
        cause: AddressError,
    },
    /// An entry of `--workers` has a bad address.
    #[error("--workers: {0}")]
    WorkerAddress(AddressError),
    /// `--workers` names no worker.
    #[error("--workers needs at least one HOST:PORT")]
    NoWorkers,
    /// A `dns:` name resolved to nothing within the patience.
    #[error("--workers {name}: {host_port} resolves to no address")]
    DnsEmpty {
        /// The entry.
        name: String,
        /// The name and port looked up.
        host_port: String,
    },
    /// A `dns:` name did not resolve within the patience.
    #[error("--workers {name}: {host_port} does not resolve: {cause}")]
    DnsFailed {
        /// The entry.
        name: String,
        /// The name and port looked up.
        host_port: String,
        /// The resolver's error.
        cause: std::io::Error,
    },
    /// This executable's path is unknown, so the worker binary beside it cannot be found.
    #[error("cannot locate this executable: {0}")]
    CurrentExe(std::io::Error),
    /// The worker binary is not beside this executable.
    #[error(
        "{} is missing: --local starts worker processes from it (build it with `cargo build --release -p \
         photon-worker`)",
        bin.display()
    )]
    MissingWorkerBinary {
        /// Where it was looked for.
        bin: PathBuf,
    },
    /// A local worker process cannot be started.
    #[error("cannot start {}: {cause}", bin.display())]
    Spawn {
        /// The binary.
        bin: PathBuf,
        /// The reason.
        cause: std::io::Error,
    },
    /// A local worker process has no standard output to read its address from.
    #[error("no standard output from the worker")]
    NoStdout,
    /// A local worker did not print its address in time.
    #[error("local worker {0} did not report its address within 10 s")]
    AddressTimeout(usize),
    /// A local worker's output cannot be read.
    #[error("reading local worker {index}'s address: {cause}")]
    ReadAddress {
        /// The worker.
        index: usize,
        /// The reason.
        cause: std::io::Error,
    },
    /// A local worker printed something else than its address.
    #[error("local worker {index} said `{line}` instead of its address")]
    UnexpectedLine {
        /// The worker.
        index: usize,
        /// What it said.
        line: String,
    },
    /// The in-process worker cannot start.
    #[error(transparent)]
    Worker(#[from] photon_worker::WorkerError),
    /// No loopback port for the in-process worker.
    #[error("cannot open a loopback port for the in-process worker: {0}")]
    Loopback(std::io::Error),
    /// The loopback port's address cannot be read.
    #[error("{0}")]
    LocalAddr(std::io::Error),
}

/// A worker address that is not `HOST:PORT` with a numeric port.
#[derive(Debug, thiserror::Error)]
#[error("`{0}` is not HOST:PORT")]
pub struct AddressError(String);

/// Which workers a command renders on.
#[derive(Clone, Debug)]
pub enum FleetSpec {
    /// One worker server inside this process, with this many threads (`None`: all cores).
    InProcess(Option<usize>),
    /// `n` worker processes on loopback sharing `threads` threads, with an optional token file.
    Local {
        /// Processes.
        n: usize,
        /// Threads shared between them.
        threads: usize,
        /// The token file they are started with.
        token_file: Option<PathBuf>,
    },
    /// Workers elsewhere.
    Remote(Vec<WorkerAddr>),
}

/// Running workers: their addresses, and whatever must be stopped at the end.
pub struct Fleet {
    /// Where they listen.
    pub addrs: Vec<WorkerAddr>,
    in_process: Option<InProcess>,
    local: Option<LocalWorkers>,
}

impl Fleet {
    /// Starts the workers of `spec` (remote ones are only listed: the render connects to them).
    pub async fn start(spec: &FleetSpec) -> Result<Self, FleetError> {
        Ok(match spec {
            FleetSpec::InProcess(threads) => {
                let w = InProcess::start(*threads).await?;
                Self { addrs: vec![w.addr.clone()], in_process: Some(w), local: None }
            }
            FleetSpec::Local { n, threads, token_file } => {
                let l = LocalWorkers::start(*n, *threads, token_file.as_deref()).await?;
                Self { addrs: l.addrs.clone(), in_process: None, local: Some(l) }
            }
            FleetSpec::Remote(addrs) => Self { addrs: resolve_dns(addrs).await?, in_process: None, local: None },
        })
    }

    /// Stops what was started here.
    pub async fn stop(self) {
        drop(self.in_process);
        if let Some(l) = self.local {
            l.stop().await;
        }
    }

    /// Whether the workers run in this process (the default, single-machine case).
    pub fn is_in_process(&self) -> bool {
        self.in_process.is_some()
    }
}

/// Greets each worker at `addrs` (one connection attempt and a hello, within `patience`), in order: `None` for
/// one that did not answer in time or refused. The model of a remote farm reads their threads ([`threads`]); the
/// render's sessions go on from these greetings ([`crate::farm::Options::greetings`]), and a worker left out is
/// tried again by its session and reported as usual.
pub async fn greet(
    addrs: &[WorkerAddr],
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
    patience: Duration,
) -> Vec<Option<Greeting>> {
    let mut hellos = tokio::task::JoinSet::new();
    for (i, a) in addrs.iter().enumerate() {
        let (uri, token, tls_ca) = (a.uri.clone(), token.map(str::to_owned), tls_ca.map(<[u8]>::to_vec));
        hellos.spawn(async move {
            let greeting = session::greet(&uri, token.as_deref(), tls_ca.as_deref(), Duration::ZERO);
            (i, tokio::time::timeout(patience, greeting).await.ok().and_then(Result::ok))
        });
    }
    let mut greetings = vec![None; addrs.len()];
    while let Some(Ok((i, greeting))) = hellos.join_next().await {
        greetings[i] = greeting;
    }
    greetings
}

/// The thread count of each worker that answered its greeting (the model's view of a remote farm).
pub fn threads(greetings: &[Option<Greeting>]) -> Vec<u32> {
    greetings.iter().flatten().map(|g| g.hello.threads).collect()
}

/// Bytes per second of the coordinator's link to the greeted workers: the median of each worker's
/// [`session::probe_link`], measured one worker at a time so that each probe has this machine's link to itself
/// (as the uploads of a shipped map share it). Each of a worker's two probes carries 512 KiB, less on a farm of
/// more than 16 workers (8 MiB a round in all, 64 KiB at least), within 5 s a worker (a slower one is left out).
/// `None` when no probe could be timed.
pub async fn measure_link(greetings: &mut [Option<Greeting>]) -> Option<f64> {
    let n = greetings.iter().flatten().count().max(1);
    let bytes = ((8usize << 20) / n).clamp(64 << 10, 512 << 10);
    let mut rates = Vec::new();
    for g in greetings.iter_mut().flatten() {
        let probe = session::probe_link(&mut g.client, bytes);
        match tokio::time::timeout(Duration::from_secs(5), probe).await {
            Ok(Ok(Some(rate))) => rates.push(rate),
            Ok(Ok(None)) => {}
            Ok(Err(e)) => tracing::warn!(host = %g.hello.hostname, "probing the link failed: {e}"),
            Err(_) => tracing::warn!(host = %g.hello.hostname, "probing the link took too long"),
        }
    }
    rates.sort_by(f64::total_cmp);
    rates.get(rates.len() / 2).copied()
}

/// A host list file:
///
/// ```toml
/// # token_file = "farm.token"   # optional: the shared token, relative to this file
/// # tls_ca = "ca.pem"           # optional: speak TLS, trusting this authority (relative to this file)
/// [[worker]]
/// address = "lab-01.example.edu:7878"
/// name = "lab-01"               # optional: the name in reports
/// ```
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct HostsFile {
    #[serde(default)]
    token_file: Option<PathBuf>,
    #[serde(default)]
    tls_ca: Option<PathBuf>,
    #[serde(default)]
    worker: Vec<HostEntry>,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct HostEntry {
    address: String,
    #[serde(default)]
    name: Option<String>,
}

/// What a host list gives: its workers, and the token file and TLS authority it names (resolved against the
/// list's folder).
#[derive(Debug)]
pub struct Hosts {
    /// The workers.
    pub workers: Vec<WorkerAddr>,
    /// The shared token's file.
    pub token_file: Option<PathBuf>,
    /// The certificate authority of the workers' TLS certificates.
    pub tls_ca: Option<PathBuf>,
}

/// Reads a host list.
pub fn read_hosts(path: &Path) -> Result<Hosts, FleetError> {
    let text = std::fs::read_to_string(path).map_err(|cause| FleetError::ReadHosts { path: path.into(), cause })?;
    let hosts: HostsFile =
        toml::from_str(&text).map_err(|cause| FleetError::ParseHosts { path: path.into(), cause })?;
    if hosts.worker.is_empty() {
        return Err(FleetError::NoHosts { path: path.into() });
    }
    let mut workers = Vec::new();
    for (i, w) in hosts.worker.iter().enumerate() {
        let worker = worker_entry(&w.address, w.name.as_deref()).map_err(|cause| FleetError::HostAddress {
            path: path.into(),
            index: i,
            cause,
        })?;
        workers.push(worker);
    }
    let base = path.parent().unwrap_or(Path::new("."));
    Ok(Hosts {
        workers,
        token_file: hosts.token_file.map(|t| base.join(t)),
        tls_ca: hosts.tls_ca.map(|t| base.join(t)),
    })
}

/// The prefix of a worker entry that stands for every address its name resolves to.
const DNS_PREFIX: &str = "dns:";

/// How long a `dns:` name may resolve to nothing before the render gives up (the workers' pods may still be
/// starting when the coordinator's does).
const DNS_PATIENCE: Duration = Duration::from_secs(120);

/// Workers from `a:port,b:port`. An entry `dns:NAME:PORT` is every address `NAME` resolves to (a Kubernetes
/// headless Service lists one per ready worker pod); it is resolved when the fleet starts.
pub fn parse_workers(list: &str) -> Result<Vec<WorkerAddr>, FleetError> {
    let mut out = Vec::new();
    for a in list.split(',').map(str::trim).filter(|a| !a.is_empty()) {
        out.push(worker_entry(a, None).map_err(FleetError::WorkerAddress)?);
    }
    if out.is_empty() {
        return Err(FleetError::NoWorkers);
    }
    Ok(out)
}

/// One worker entry of `--workers` or a host list: `HOST:PORT`, a URI, or `dns:NAME:PORT`.
fn worker_entry(address: &str, name: Option<&str>) -> Result<WorkerAddr, AddressError> {
    let address = address.trim();
    match address.strip_prefix(DNS_PREFIX) {
        Some(host_port) => {
            check_address(host_port)?;
            Ok(WorkerAddr { name: name.unwrap_or(address).to_owned(), uri: address.to_owned() })
        }
        None => {
            check_address(address)?;
            Ok(WorkerAddr::new(address, name))
        }
    }
}

/// Replaces each `dns:NAME:PORT` entry by one worker per distinct address of `NAME`, waiting up to
/// [`DNS_PATIENCE`] for the name to resolve to something.
async fn resolve_dns(addrs: &[WorkerAddr]) -> Result<Vec<WorkerAddr>, FleetError> {
    let mut out = Vec::new();
    for w in addrs {
        let Some(host_port) = w.uri.strip_prefix(DNS_PREFIX) else {
            out.push(w.clone());
            continue;
        };
        let deadline = tokio::time::Instant::now() + DNS_PATIENCE;
        let found = loop {
            let result = tokio::net::lookup_host(host_port).await.map(|a| a.collect::<BTreeSet<SocketAddr>>());
            match result {
                Ok(found) if !found.is_empty() => break found,
                _ if tokio::time::Instant::now() < deadline => tokio::time::sleep(Duration::from_secs(1)).await,
                Ok(_) => {
                    return Err(FleetError::DnsEmpty { name: w.name.clone(), host_port: host_port.to_owned() });
                }
                Err(cause) => {
                    let (name, host_port) = (w.name.clone(), host_port.to_owned());
                    return Err(FleetError::DnsFailed { name, host_port, cause });
                }
            }
        };
        tracing::info!(name = %host_port, workers = found.len(), "resolved");
        out.extend(found.iter().map(|a| WorkerAddr::new(&a.to_string(), None)));
    }
    Ok(out)
}

/// An address must be `host:port` (optionally with an `http://` or `https://` scheme) with a numeric port.
fn check_address(a: &str) -> Result<(), AddressError> {
    let rest = a.split_once("://").map_or(a, |(_, r)| r).trim_end_matches('/');
    match rest.rsplit_once(':') {
        Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => Ok(()),
        _ => Err(AddressError(a.to_owned())),
    }
}

/// Worker processes on loopback, killed when this value drops.
pub struct LocalWorkers {
    children: Vec<tokio::process::Child>,
    /// Their addresses.
    pub addrs: Vec<WorkerAddr>,
}

impl LocalWorkers {
    /// Starts `n` `photon-worker` processes on free loopback ports, sharing the machine's cores between them.
    pub async fn start(n: usize, threads_total: usize, token_file: Option<&Path>) -> Result<Self, FleetError> {
        let bin = worker_binary()?;
        let threads = (threads_total / n.max(1)).max(1);
        let mut children = Vec::new();
        let mut addrs = Vec::new();
        for i in 0..n {
            let mut cmd = tokio::process::Command::new(&bin);
            cmd.args(["--listen", "127.0.0.1:0", "--threads", &threads.to_string()])
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::null())
                .kill_on_drop(true);
            if let Some(t) = token_file {
                cmd.arg("--token-file").arg(t);
            }
            let mut child = cmd.spawn().map_err(|cause| FleetError::Spawn { bin: bin.clone(), cause })?;
            let stdout = child.stdout.take().ok_or(FleetError::NoStdout)?;
            let mut lines = tokio::io::BufReader::new(stdout).lines();
            let line = tokio::time::timeout(Duration::from_secs(10), lines.next_line())
                .await
                .map_err(|_| FleetError::AddressTimeout(i))?
                .map_err(|cause| FleetError::ReadAddress { index: i, cause })?
                .unwrap_or_default();
            let addr = line
                .strip_prefix("photon-worker listening on ")
                .ok_or_else(|| FleetError::UnexpectedLine { index: i, line: line.clone() })?;
            addrs.push(WorkerAddr::new(addr, Some(&format!("local-{i}"))));
            children.push(child);
        }
        Ok(Self { children, addrs })
    }

    /// Stops the processes.
    pub async fn stop(mut self) {
        for c in &mut self.children {
            let _ = c.kill().await;
        }
    }
}

/// `photon-worker` next to this executable (or one folder up, for Cargo's examples and benches).
fn worker_binary() -> Result<PathBuf, FleetError> {
    let exe = std::env::current_exe().map_err(FleetError::CurrentExe)?;
    let name = format!("photon-worker{}", std::env::consts::EXE_SUFFIX);
    let bin = exe.with_file_name(&name);
    let up = exe.parent().and_then(Path::parent).map(|d| d.join(&name));
    if bin.is_file() {
        Ok(bin)
    } else if let Some(up) = up.filter(|p| p.is_file()) {
        Ok(up)
    } else {
        Err(FleetError::MissingWorkerBinary { bin })
    }
}

/// A worker server inside this process, on a free loopback port; stops when dropped.
pub struct InProcess {
    /// Its address.
    pub addr: WorkerAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl InProcess {
    /// Starts it with `threads` render threads (`None`: all cores).
    pub async fn start(threads: Option<usize>) -> Result<Self, FleetError> {
        let config = photon_worker::Config { threads, ..photon_worker::Config::default() };
        let worker = photon_worker::Worker::new(config)?;
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.map_err(FleetError::Loopback)?;
        let addr = listener.local_addr().map_err(FleetError::LocalAddr)?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        tokio::spawn(async move {
            let shutdown = async {
                let _ = stopped.await;
            };
            if let Err(e) = photon_worker::serve(worker, listener, shutdown).await {
                tracing::error!("in-process worker: {e}");
            }
        });
        Ok(Self { addr: WorkerAddr::new(&addr.to_string(), Some("in-process")), stop: Some(stop) })
    }
}

impl Drop for InProcess {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses() {
        assert!(check_address("lab-01:7878").is_ok());
        assert!(check_address("http://10.0.0.2:7878").is_ok());
        assert!(check_address("[::1]:7878").is_ok());
        assert!(check_address("lab-01").is_err());
        assert!(check_address(":7878").is_err());
        assert!(check_address("lab-01:http").is_err());
        let w = parse_workers("a:1, b:2").unwrap();
        assert_eq!(w.iter().map(|w| w.uri.as_str()).collect::<Vec<_>>(), ["http://a:1", "http://b:2"]);
        assert!(parse_workers(" , ").is_err());
        assert!(parse_workers("dns:photon-worker").is_err());
    }

    /// A `dns:` entry becomes one worker per address of the name (here the loopback name, whose addresses
    /// depend on the machine: 127.0.0.1 and perhaps ::1).
    #[tokio::test]
    async fn a_dns_entry_stands_for_every_address_of_its_name() {
        let w = parse_workers("dns:localhost:7878,b:2").unwrap();
        let addrs = resolve_dns(&w).await.unwrap();
        let uris: Vec<&str> = addrs.iter().map(|a| a.uri.as_str()).collect();
        assert!(uris.contains(&"http://127.0.0.1:7878"), "{uris:?}");
        assert_eq!(uris.last(), Some(&"http://b:2"));
        assert!(uris.len() >= 2 && uris.iter().all(|u| u.ends_with(":7878") || *u == "http://b:2"), "{uris:?}");
    }

    #[test]
    fn host_list_errors_name_the_file_and_field() {
        let dir = std::env::temp_dir().join(format!("photon-hosts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("hosts.toml");
        std::fs::write(&p, "[[worker]]\naddress = \"a:1\"\nname = \"A\"\n[[worker]]\naddress = \"b\"\n").unwrap();
        let e = read_hosts(&p).unwrap_err().to_string();
        assert!(e.contains("hosts.toml") && e.contains("worker[1].address"), "{e}");
        std::fs::write(&p, "token_file = \"t\"\n[[worker]]\naddress = \"a:1\"\nname = \"A\"\n").unwrap();
        let hosts = read_hosts(&p).unwrap();
        assert_eq!(hosts.workers[0].name, "A");
        assert_eq!(hosts.token_file.unwrap(), dir.join("t"));
        std::fs::write(&p, "[[worker]]\nadress = \"a:1\"\n").unwrap();
        let e = read_hosts(&p).unwrap_err().to_string();
        assert!(e.contains("adress"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A worker server in this process whose hellos are counted.
    async fn counting_worker() -> (WorkerAddr, std::sync::Arc<std::sync::atomic::AtomicUsize>) {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let hellos = std::sync::Arc::new(AtomicUsize::new(0));
        let counted = hellos.clone();
        let count = tower::util::MapRequestLayer::new(move |req: tonic::codegen::http::Request<tonic::body::Body>| {
            if req.uri().path().ends_with("/Hello") {
                counted.fetch_add(1, Ordering::SeqCst);
            }
            req
        });
        let worker = photon_worker::Worker::new(photon_worker::Config::default()).unwrap();
        let service = photon_proto::pb::render_server::RenderServer::new(worker)
            .max_decoding_message_size(photon_proto::MAX_MESSAGE)
            .max_encoding_message_size(photon_proto::MAX_MESSAGE);
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = WorkerAddr::new(&listener.local_addr().unwrap().to_string(), None);
        let incoming = tokio_stream::wrappers::TcpListenerStream::new(listener);
        let server = tonic::transport::Server::builder().layer(count).add_service(service);
        tokio::spawn(server.serve_with_incoming(incoming));
        (addr, hellos)
    }

    /// A job of the Cornell box at 8×8 pixels, one path-traced sample per pixel.
    fn small_job() -> crate::job::Job {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
        let mut scene = photon_core::scene::Scene::load(&path).unwrap();
        (scene.camera.width, scene.camera.height) = (8, 8);
        (scene.render.integrator, scene.render.spp) = (photon_core::method::Method::Path, 1);
        let prep = photon_core::prepare::Prepared::new(&scene, &path).unwrap();
        let (size, frame) = ((prep.camera.width, prep.camera.height), prep.encode_frame().unwrap());
        let (blob, textures) = (prep.encode_scene().unwrap(), prep.encode_textures().unwrap());
        crate::job::Job::new(blob, prep.encode_photons().unwrap(), textures, frame, size, &prep.settings)
    }

    /// The model's greeting is the render's: a worker greeted for its threads hears no second hello, and renders
    /// the same image as one its session greets.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_worker_greeted_for_the_model_hears_one_hello_per_render() {
        use std::sync::atomic::Ordering;
        let (addr, hellos) = counting_worker().await;
        let (job, addrs) = (small_job(), vec![addr]);
        let greetings = greet(&addrs, None, None, Duration::from_secs(5)).await;
        assert_eq!(threads(&greetings).len(), 1);
        let options = crate::farm::Options { greetings, ..crate::farm::Options::default() };
        let greeted = crate::farm::render(&job, &addrs, options).await.unwrap();
        assert_eq!(hellos.load(Ordering::SeqCst), 1);
        let plain = crate::farm::render(&job, &addrs, crate::farm::Options::default()).await.unwrap();
        assert_eq!(hellos.load(Ordering::SeqCst), 2);
        let bits = |p: &[f32]| p.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
        assert_eq!(bits(&greeted.pixels), bits(&plain.pixels));
    }
}
