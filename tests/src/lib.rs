//! Helpers shared by photon's end-to-end tests, which run the binaries as a user runs them.
//!
//! `photon-coordinator`, `photon-worker` and `photon-sweep` are other packages' binaries, so Cargo does not build
//! them for these tests and `CARGO_BIN_EXE_…` is not set. [`coordinator`] runs `cargo build --workspace --bins
//! --examples --features photon-worker/fault-injection` once per test process (a no-op when the binaries are
//! fresh, as they are after `cargo test --workspace`; it builds them when missing or stale) in the profile and
//! target folder of the running test executable, then returns `<target>/<profile>/photon-coordinator`, found from
//! `std::env::current_exe()` (`<target>/<profile>/deps/<test>-…`). The worker gets the feature `fault-injection`
//! for the tests' `--test-…` fault flags, as this package's dev-dependency on it does.
//!
//! The build selects what `cargo test --workspace` selects, so that Cargo unifies the same features and the
//! binaries reuse every library the tests compiled: the whole workspace, with its dev-dependencies (which
//! `--examples` brings in, building only `coordinator/examples/` and `tests/examples/`, which `cargo test` builds
//! too). A build of the
//! binaries' packages alone would see other features: criterion, photon-core's dev-dependency, turns on
//! `either`'s `use_std` and more of `regex-automata`, which rayon and tracing-subscriber share with the binaries,
//! so the four photon libraries and 17 crates under them (rayon, kiddo, tracing-subscriber, prost, tonic-prost,
//! …) would be compiled twice. After `cargo test -p photon-tests` alone (no criterion) it is this build that
//! compiles them a second time.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod netns;

use std::io::BufRead;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::sync::mpsc::{self, Receiver};
use std::time::{Duration, Instant};

/// The coordinator binary, built on first use (with the worker). Panics (failing the test) when it cannot be built.
pub fn coordinator() -> &'static Path {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        let exe = std::env::current_exe().unwrap_or_else(|e| panic!("cannot locate the test executable: {e}"));
        // <target>/<profile>/deps/<test>-HASH
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .unwrap_or_else(|| panic!("{} is not in <target>/<profile>/deps", exe.display()))
            .to_path_buf();
        let target_dir =
            profile_dir.parent().unwrap_or_else(|| panic!("{} has no parent folder", profile_dir.display()));
        let profile = profile_dir.file_name().map(|p| p.to_string_lossy().into_owned()).unwrap_or_default();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.toml");
        let mut build = Command::new(cargo);
        // The selection of `cargo test --workspace`, dev-dependencies included (module documentation), with the
        // tests' fault flags (photon-worker's hidden --test-…).
        build.args(["build", "--quiet", "--workspace", "--bins", "--examples"]);
        build.args(["--features", "photon-worker/fault-injection", "--manifest-path"]);
        build.arg(&manifest);
        build.arg("--target-dir").arg(target_dir);
        match profile.as_str() {
            // `cargo test` builds in the test profile, whose output folder is `debug`: building the binaries in
            // that profile too reuses every dependency the tests compiled (the dev profile would compile them all
            // again, minutes in CI) and makes the binaries as fast as the tests.
            "debug" => {
                build.args(["--profile", "test"]);
            }
            "release" => {
                build.arg("--release");
            }
            other => {
                build.args(["--profile", other]);
            }
        }
        let status = build.status().unwrap_or_else(|e| panic!("cannot run cargo: {e}"));
        assert!(status.success(), "`cargo build --workspace --bins --examples` failed: {status}");
        let bin = profile_dir.join(format!("photon-coordinator{}", std::env::consts::EXE_SUFFIX));
        assert!(bin.is_file(), "{} missing after the build", bin.display());
        bin
    })
}

/// A fresh, empty folder `photon-<suite>-<pid>-<test>` in the system's temporary folder.
pub fn temp_dir(suite: &str, test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-{suite}-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
    dir
}

/// The workspace's `scenes` folder.
pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// Runs `photon-coordinator render SCENE -q --no-cache ARGS…` in `dir` and waits for it.
pub fn render_in(dir: &Path, scene: &Path, args: &[&str]) -> std::process::Output {
    Command::new(coordinator())
        .current_dir(dir)
        .arg("render")
        .arg(scene)
        .args(["-q", "--no-cache"])
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", coordinator().display()))
}

/// The standard output of a run that succeeded; panics with both of its streams otherwise.
pub fn success_stdout(out: &std::process::Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "stdout: {stdout}\nstderr: {}", String::from_utf8_lossy(&out.stderr));
    stdout
}

/// The worker binary, built with the coordinator.
pub fn worker() -> PathBuf {
    coordinator().with_file_name(format!("photon-worker{}", std::env::consts::EXE_SUFFIX))
}

/// The sweep's binary (`photon-sweep`, in `tools/sweep/`), built with the coordinator.
pub fn sweep() -> PathBuf {
    coordinator().with_file_name(format!("photon-sweep{}", std::env::consts::EXE_SUFFIX))
}

/// A `photon-worker` process on a free loopback port, killed (SIGKILL) when dropped.
pub struct WorkerProcess {
    child: Child,
    /// `127.0.0.1:PORT`.
    pub addr: String,
    /// Lines of its standard error (its log), as they arrive.
    pub log: Receiver<String>,
}

impl WorkerProcess {
    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Starts a worker on a free loopback port with extra arguments; panics if it does not report its address
    /// within 20 s.
    pub fn start(args: &[&str]) -> Self {
        Self::start_on("127.0.0.1:0", args)
    }

    /// Starts a worker listening on `listen`.
    pub fn start_on(listen: &str, args: &[&str]) -> Self {
        Self::start_command(Command::new(worker()), listen, args)
    }

    /// Starts a worker with `command` (the worker binary, or an emulator with the binary as its first
    /// argument), listening on `listen`.
    pub fn start_command(mut command: Command, listen: &str, args: &[&str]) -> Self {
        let mut child = command
            .args(["--listen", listen])
            .args(args)
            .env("RUST_LOG", "info")
            .env("NO_COLOR", "1")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start photon-worker: {e}"));
        let (tx, rx) = mpsc::channel();
        if let Some(out) = child.stdout.take() {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(out).lines().map_while(Result::ok) {
                    let _ = tx.send(line);
                }
            });
        }
        let (log_tx, log) = mpsc::channel();
        if let Some(err) = child.stderr.take() {
            std::thread::spawn(move || {
                for line in BufReader::new(err).lines().map_while(Result::ok) {
                    let _ = log_tx.send(line);
                }
            });
        }
        let line = rx.recv_timeout(Duration::from_secs(20)).unwrap_or_else(|e| {
            let _ = child.kill();
            panic!("photon-worker did not report its address: {e}")
        });
        let addr = line
            .strip_prefix("photon-worker listening on ")
            .unwrap_or_else(|| panic!("unexpected first line from photon-worker: {line}"))
            .to_owned();
        Self { child, addr, log }
    }

    /// Waits until the worker's log has shown `n` lines containing `needle` (panics after `timeout`).
    pub fn wait_for_log(&self, needle: &str, n: usize, timeout: Duration) {
        wait_for_lines(&self.log, needle, n, timeout, "the worker's log");
    }

    /// Kills the process at once (SIGKILL on Unix), as a crash would.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Asks the process to stop (SIGTERM) and waits up to `timeout` for it; returns its exit status.
    pub fn terminate(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let pid = self.child.id().to_string();
        let _ = Command::new("kill").args(["-TERM", &pid]).status();
        wait_with_timeout(&mut self.child, timeout)
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Reads `lines` until `n` of them contained `needle`; panics after `timeout` or when the lines end, naming
/// `source`.
fn wait_for_lines(lines: &Receiver<String>, needle: &str, n: usize, timeout: Duration, source: &str) {
    if let Err(e) = seek_lines(lines, needle, n, timeout) {
        panic!("{e} in {source}");
    }
}

/// Reads `lines` until `n` of them contained `needle`; after `timeout`, or when the lines end, says how many
/// did.
fn seek_lines(lines: &Receiver<String>, needle: &str, n: usize, timeout: Duration) -> Result<(), String> {
    let end = Instant::now() + timeout;
    let mut seen = 0;
    while seen < n {
        let left = end.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if line.contains(needle) => seen += 1,
            Ok(_) => {}
            Err(e) => return Err(format!("saw `{needle}` {seen} of {n} times: {e}")),
        }
    }
    Ok(())
}

/// Waits for a child up to `timeout`; kills it and returns `None` if it is still running then.
pub fn wait_with_timeout(child: &mut Child, timeout: Duration) -> Option<std::process::ExitStatus> {
    let end = Instant::now() + timeout;
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        if Instant::now() >= end {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Output of a command run to completion within `timeout` (panics if it runs longer).
pub fn run_with_timeout(cmd: &mut Command, timeout: Duration) -> std::process::Output {
    Running::start(cmd).finish(timeout)
}

/// A command running in the background, its standard error readable line by line as it comes (to act on what
/// it says) while both outputs are kept for the end.
pub struct Running {
    child: Child,
    description: String,
    stdout: std::thread::JoinHandle<Vec<u8>>,
    stderr: std::thread::JoinHandle<Vec<u8>>,
    lines: Receiver<String>,
}

impl Running {
    /// Starts `cmd` with piped outputs (panics if it cannot start).
    pub fn start(cmd: &mut Command) -> Self {
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
        // Drain the pipes on threads so a chatty child cannot block on a full pipe.
        let out = child.stdout.take();
        let stdout = std::thread::spawn(move || {
            let mut buf = Vec::new();
            if let Some(mut r) = out {
                let _ = std::io::Read::read_to_end(&mut r, &mut buf);
            }
            buf
        });
        let err = child.stderr.take();
        let (tx, lines) = mpsc::channel();
        let stderr = std::thread::spawn(move || {
            let mut buf = Vec::new();
            if let Some(r) = err {
                let mut r = BufReader::new(r);
                let mut line = Vec::new();
                while matches!(r.read_until(b'\n', &mut line), Ok(n) if n > 0) {
                    let _ = tx.send(String::from_utf8_lossy(&line).into_owned());
                    buf.append(&mut line);
                }
            }
            buf
        });
        Self { child, description: format!("{cmd:?}"), stdout, stderr, lines }
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends it a signal by name (`INT`, `TERM`, `STOP`, …) with `kill`; returns whether it was delivered
    /// (`false` once the process has ended).
    pub fn signal(&self, name: &str) -> bool {
        let status = Command::new("kill").arg(format!("-{name}")).arg(self.pid().to_string()).status();
        status.is_ok_and(|s| s.success())
    }

    /// Waits until its standard error has shown `n` lines containing `needle` (panics after `timeout`, or if it
    /// ends first).
    pub fn wait_for_line(&self, needle: &str, n: usize, timeout: Duration) {
        wait_for_lines(&self.lines, needle, n, timeout, &format!("{}'s standard error", self.description));
    }

    /// Like [`Running::wait_for_line`], but answers whether the lines came instead of panicking (the caller can
    /// then [`Running::finish`] and show the whole output).
    pub fn saw_line(&self, needle: &str, n: usize, timeout: Duration) -> bool {
        seek_lines(&self.lines, needle, n, timeout).is_ok()
    }

    /// Waits for it to end within `timeout` (panics if it runs longer) and returns its outputs.
    pub fn finish(mut self, timeout: Duration) -> std::process::Output {
        let status = wait_with_timeout(&mut self.child, timeout)
            .unwrap_or_else(|| panic!("{} ran longer than {timeout:?} and was killed", self.description));
        let stdout = self.stdout.join().unwrap_or_default();
        let stderr = self.stderr.join().unwrap_or_default();
        std::process::Output { status, stdout, stderr }
    }
}

/// A worker's row of the coordinator's end table (printed after a render on workers): worker, platform (2
/// words), threads, units, busy s, Mpx/s, shipped (2 words), from peers (2 words), ship s, load s, photon paths,
/// photon s, spec/dup, failures, then the state (the rest of the line). One parser, so a new column moves every
/// test's reading at once.
#[derive(Clone, Debug)]
pub struct WorkerRow {
    /// The whole line.
    pub line: String,
    /// Strips or pass blocks accepted from it.
    pub units: u64,
    /// Blob bytes shipped to it from the coordinator, as printed (`1.7 MiB`).
    pub shipped: String,
    /// Blob bytes it fetched from peers, as printed.
    pub from_peers: String,
    /// Photon paths it traced.
    pub photon_paths: u64,
    /// Speculative copies it was given.
    pub speculative: u32,
    /// Its state column (`ok`, `stalled`, `lost: …`).
    pub state: String,
}

impl WorkerRow {
    /// The row of the worker at `addr` in a coordinator's standard output, or `None` when it has none or it does
    /// not have the table's columns.
    pub fn find(stdout: &str, addr: &str) -> Option<Self> {
        let line = stdout.lines().find(|l| l.starts_with(addr))?;
        let w: Vec<&str> = line.split_whitespace().collect();
        // The platform is two words ("x86_64 linux"), or "-" for a worker never greeted: the threads column is
        // the first number after the name.
        let t = 1 + w.get(1..)?.iter().position(|c| c.parse::<u32>().is_ok())?;
        Some(Self {
            line: line.to_owned(),
            units: w.get(t + 1)?.parse().ok()?,
            shipped: format!("{} {}", w.get(t + 4)?, w.get(t + 5)?),
            from_peers: format!("{} {}", w.get(t + 6)?, w.get(t + 7)?),
            photon_paths: w.get(t + 10)?.parse().ok()?,
            speculative: w.get(t + 12)?.split('/').next()?.parse().ok()?,
            state: w.get(t + 14..)?.join(" "),
        })
    }
}
