//! Several hosts on one machine, for the tests of what crosses a network: each host is a Linux network
//! namespace of its own with one interface, `eth0`, joined by a veth pair to a bridge that lives in a namespace of
//! its own, so nothing of it touches this machine's own network. Addresses come from the benchmarking range
//! 198.18.0.0/15 (RFC 2544): host `i` is `198.18.0.{i+1}`. Each host's link can be shaped with `tbf` (a rate,
//! both ways), cut (its bridge port set down: packets are lost, connections are not reset, as when a cable or a
//! switch port fails) and restored.
//!
//! What it cannot model: delay, jitter, loss rates and reordering need `netem`, which this kernel does not have
//! (`tc qdisc add … netem` answers "Specified qdisc kind is unknown"); a cut is all or nothing, both ways at once,
//! and the links share one bridge (no routed hops, no MTU changes).
//!
//! It needs root (or `CAP_NET_ADMIN` and `CAP_SYS_ADMIN`) and `ip` and `tc` from iproute2. Where it cannot run,
//! [`Lab::new`] says why and returns `None`, and the test passes having checked nothing, unless
//! `PHOTON_REQUIRE_NETNS` is set (as `.ci/run` sets it), when it fails. A lab removes its namespaces when it is
//! dropped, pass or fail, and [`Lab::new`] first removes those left by test processes that died.

use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};

/// Names of this crate's namespaces start with this, then the test process's id.
const PREFIX: &str = "photon-net-";

/// A bridge and its hosts, each in a network namespace (see the module documentation).
pub struct Lab {
    /// `photon-net-<pid>-<n>`: the namespaces are `<stem>-br` and `<stem>-h<i>`.
    stem: String,
    hosts: usize,
}

impl Lab {
    /// A lab of `hosts` hosts on one bridge, their links unshaped. `None` (after saying why on standard error)
    /// where namespaces cannot be made, unless `PHOTON_REQUIRE_NETNS` is set: then it panics.
    pub fn new(hosts: usize) -> Option<Self> {
        static USABLE: OnceLock<Result<(), String>> = OnceLock::new();
        if let Err(why) = USABLE.get_or_init(Self::usable) {
            assert!(
                std::env::var_os("PHOTON_REQUIRE_NETNS").is_none(),
                "PHOTON_REQUIRE_NETNS is set but network namespaces cannot be used: {why}"
            );
            eprintln!("skipping: network namespaces cannot be used here ({why}); set PHOTON_REQUIRE_NETNS to fail");
            return None;
        }
        remove_stale();
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let stem = format!("{PREFIX}{}-{}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed));
        let lab = Self { stem, hosts };
        let br = lab.bridge_ns();
        ip(&["netns", "add", &br]);
        ip(&["-n", &br, "link", "add", "br0", "type", "bridge"]);
        ip(&["-n", &br, "link", "set", "br0", "up"]);
        for i in 0..hosts {
            let (ns, port) = (lab.ns(i), format!("p{i}"));
            ip(&["netns", "add", &ns]);
            ip(&["-n", &br, "link", "add", &port, "type", "veth", "peer", "name", "eth0", "netns", &ns]);
            ip(&["-n", &br, "link", "set", &port, "master", "br0", "up"]);
            ip(&["-n", &ns, "addr", "add", &format!("{}/24", lab.addr(i)), "dev", "eth0"]);
            ip(&["-n", &ns, "link", "set", "eth0", "up"]);
            ip(&["-n", &ns, "link", "set", "lo", "up"]);
        }
        Some(lab)
    }

    /// Whether this process may make namespaces and has `ip` and `tc` (asked once per process: parallel tests
    /// would race on the probe's name).
    fn usable() -> Result<(), String> {
        for tool in ["ip", "tc"] {
            let found = Command::new(tool).arg("-V").output().is_ok_and(|o| o.status.success());
            if !found {
                return Err(format!("`{tool}` (iproute2) is not installed"));
            }
        }
        let probe = format!("{PREFIX}{}-probe", std::process::id());
        let made = Command::new("ip").args(["netns", "add", &probe]).output();
        let _ = Command::new("ip").args(["netns", "del", &probe]).output();
        match made {
            Ok(o) if o.status.success() => Ok(()),
            Ok(o) => Err(format!("`ip netns add` failed: {}", String::from_utf8_lossy(&o.stderr).trim())),
            Err(e) => Err(format!("cannot run `ip`: {e}")),
        }
    }

    /// Host `i`'s namespace.
    pub fn ns(&self, i: usize) -> String {
        assert!(i < self.hosts, "host {i} of {}", self.hosts);
        format!("{}-h{i}", self.stem)
    }

    fn bridge_ns(&self) -> String {
        format!("{}-br", self.stem)
    }

    /// Host `i`'s address, `198.18.0.{i+1}`.
    pub fn addr(&self, i: usize) -> String {
        format!("198.18.0.{}", i + 1)
    }

    /// A command that runs `program` on host `i` (in its namespace, through `ip netns exec`, which execs it:
    /// the child's process id is the program's).
    pub fn command(&self, i: usize, program: &Path) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.ns(i)]).arg(program);
        c
    }

    /// Shapes host `i`'s link to `mbit_per_s` megabits per second both ways, with a token bucket (`tbf`) on each
    /// end of its veth pair. The bucket holds 256 KiB, or 10 ms of traffic where that is more (a bucket smaller
    /// than a timer tick's traffic caps the rate below the one asked for).
    pub fn shape(&self, i: usize, mbit_per_s: u32) {
        let rate = format!("{mbit_per_s}mbit");
        let burst = format!("{}kb", (u64::from(mbit_per_s) * 1_000_000 / 8 / 100 / 1024).max(256));
        let tbf = ["root", "tbf", "rate", &rate, "burst", &burst, "latency", "200ms"];
        let ns = self.ns(i);
        tc(&[&["-n", &ns, "qdisc", "replace", "dev", "eth0"][..], &tbf].concat());
        let (br, port) = (self.bridge_ns(), format!("p{i}"));
        tc(&[&["-n", &br, "qdisc", "replace", "dev", &port][..], &tbf].concat());
    }

    /// Cuts host `i`'s link: its bridge port goes down, and every packet to or from it is lost until
    /// [`Lab::restore`]. Its connections are not reset.
    pub fn cut(&self, i: usize) {
        ip(&["-n", &self.bridge_ns(), "link", "set", &format!("p{i}"), "down"]);
    }

    /// Restores host `i`'s link after [`Lab::cut`].
    pub fn restore(&self, i: usize) {
        ip(&["-n", &self.bridge_ns(), "link", "set", &format!("p{i}"), "up"]);
    }

    /// Bytes host `i` has received on its link (its `eth0` counter).
    pub fn rx_bytes(&self, i: usize) -> u64 {
        let o = Command::new("ip")
            .args(["netns", "exec", &self.ns(i), "cat", "/sys/class/net/eth0/statistics/rx_bytes"])
            .output()
            .unwrap_or_else(|e| panic!("cannot read host {i}'s counters: {e}"));
        String::from_utf8_lossy(&o.stdout).trim().parse().unwrap_or_else(|e| panic!("host {i}'s rx_bytes: {e}"))
    }
}

impl Drop for Lab {
    fn drop(&mut self) {
        for i in 0..self.hosts {
            let _ = Command::new("ip").args(["netns", "del", &self.ns(i)]).output();
        }
        let _ = Command::new("ip").args(["netns", "del", &self.bridge_ns()]).output();
    }
}

/// Removes the namespaces of this crate whose test process is gone (killed before its labs were dropped).
fn remove_stale() {
    let Ok(o) = Command::new("ip").args(["netns", "list"]).output() else { return };
    for line in String::from_utf8_lossy(&o.stdout).lines() {
        let Some(name) = line.split_whitespace().next() else { continue };
        let Some(pid) = name.strip_prefix(PREFIX).and_then(|r| r.split('-').next()) else { continue };
        if !Path::new("/proc").join(pid).exists() {
            let _ = Command::new("ip").args(["netns", "del", name]).output();
        }
    }
}

fn ip(args: &[&str]) {
    run("ip", args);
}

fn tc(args: &[&str]) {
    run("tc", args);
}

/// Runs a setup command; panics naming it and its error when it fails.
fn run(tool: &str, args: &[&str]) {
    let o = Command::new(tool).args(args).output().unwrap_or_else(|e| panic!("cannot run {tool}: {e}"));
    assert!(o.status.success(), "`{tool} {}` failed: {}", args.join(" "), String::from_utf8_lossy(&o.stderr).trim());
}
