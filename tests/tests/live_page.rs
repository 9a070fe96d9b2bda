//! The live page of a farm render (`render --serve`), in a real headless browser.
//!
//! Two slowed-down workers on loopback render a job while the coordinator serves its page; Debian's Chromium
//! (driven by its command line: `--dump-dom`, `--screenshot`) loads the page, which polls `/api/status` and
//! `/preview.png` and records what it did in the DOM (`data-frames` and `data-done` on the image, one row per
//! worker with `data-address` and `data-state`). One worker is killed halfway: the page must show it `lost`
//! while the image goes on filling in. The test keeps a screenshot in its temporary folder and prints its path.
//!
//! Without a Chromium on PATH (`chromium`, `chromium-headless-shell`, or `PHOTON_CHROMIUM` naming one) the test
//! says so and passes, unless `PHOTON_REQUIRE_BROWSER` is set, as `.ci/run` sets it: then it fails.

#![allow(clippy::unwrap_used)]

use photon_tests::{Running, WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const LIMIT: Duration = Duration::from_secs(240);

/// The browser to drive, or `None` (the test is skipped) when there is none and `PHOTON_REQUIRE_BROWSER` is not
/// set.
fn browser() -> Option<PathBuf> {
    let named = std::env::var_os("PHOTON_CHROMIUM").map(PathBuf::from);
    let on_path = || {
        let path = std::env::var_os("PATH").unwrap_or_default();
        ["chromium", "chromium-headless-shell", "chromium-browser"]
            .iter()
            .flat_map(|name| std::env::split_paths(&path).map(move |dir| dir.join(name)))
            .find(|p| p.is_file())
    };
    match named.filter(|p| p.is_file()).or_else(on_path) {
        Some(bin) => Some(bin),
        None if std::env::var_os("PHOTON_REQUIRE_BROWSER").is_some() => {
            panic!("PHOTON_REQUIRE_BROWSER is set but no chromium is on PATH (Debian's package chromium)")
        }
        None => {
            eprintln!("skipped: no chromium on PATH (apt-get install chromium); set PHOTON_REQUIRE_BROWSER=1 to fail");
            None
        }
    }
}

/// Chromium, headless, with its profile and HOME in `dir` and none of its background connections (the machine's
/// network is closed).
fn chromium(bin: &Path, dir: &Path) -> Command {
    let mut cmd = Command::new(bin);
    cmd.env("HOME", dir).args([
        "--headless",
        "--disable-gpu",
        "--no-sandbox",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--virtual-time-budget=3000",
    ]);
    cmd.arg(format!("--user-data-dir={}", dir.join("profile").display()));
    cmd
}

/// The page's DOM after about 3 s of its scripts running.
fn dump_dom(bin: &Path, dir: &Path, url: &str) -> String {
    let o = run_with_timeout(chromium(bin, dir).args(["--dump-dom", url]), Duration::from_secs(90));
    assert!(o.status.success(), "chromium --dump-dom failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The value of attribute `name` in the first tag of `dom` that contains `marker`.
fn attr(dom: &str, marker: &str, name: &str) -> Option<String> {
    let at = dom.find(marker)?;
    let start = dom[..at].rfind('<')?;
    let tag = &dom[start..start + dom[start..].find('>')?];
    let key = format!("{name}=\"");
    let v = &tag[tag.find(&key)? + key.len()..];
    Some(v[..v.find('"')?].to_owned())
}

fn attr_u64(dom: &str, marker: &str, name: &str) -> u64 {
    attr(dom, marker, name).and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("no {name} at {marker} in\n{dom}"))
}

/// GET `path` from `addr` over HTTP/1.1: the status code and the body.
fn http_get(addr: &str, path: &str) -> Option<(u16, String)> {
    let mut s = TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(10))).ok()?;
    write!(s, "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").ok()?;
    let mut bytes = Vec::new();
    s.read_to_end(&mut bytes).ok()?;
    // A PNG body is not text; its head is, and the status only needs the head.
    let text = String::from_utf8_lossy(&bytes);
    let code = text.split_whitespace().nth(1)?.parse().ok()?;
    Some((code, text.split_once("\r\n\r\n")?.1.to_owned()))
}

/// `/api/status` as JSON, once the page answers.
fn status(addr: &str) -> Option<serde_json::Value> {
    match http_get(addr, "/api/status")? {
        (200, body) => serde_json::from_str(&body).ok(),
        _ => None,
    }
}

/// Polls `/api/status` until `ok` holds of it (panics after `LIMIT`); returns that status.
fn wait_for_status(addr: &str, what: &str, ok: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let end = Instant::now() + LIMIT;
    loop {
        let s = status(addr);
        if let Some(s) = s.filter(|s| ok(s)) {
            return s;
        }
        assert!(Instant::now() < end, "the live status never showed {what}: {:?}", status(addr));
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The state of the worker at `worker` in a status.
fn worker_state(s: &serde_json::Value, worker: &str) -> Option<String> {
    s["workers"].as_array()?.iter().find(|w| w["address"] == worker).and_then(|w| w["state"].as_str()).map(Into::into)
}

fn done(s: &serde_json::Value) -> u64 {
    s["done"].as_u64().unwrap_or(0)
}

#[test]
fn the_live_page_shows_the_image_filling_in_and_a_killed_worker_lost() {
    let Some(bin) = browser() else { return };
    let dir = temp_dir("live", "page");
    // 200 ms a strip on one thread each: 96 one-row strips last long enough to look twice and kill a worker.
    let a = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "200"]);
    let mut b = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "200"]);
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let page = format!("127.0.0.1:{port}");
    let url = format!("http://{page}/");
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(dir.join("out.png")).arg("-q");
    cmd.args(["--size", "128x96", "--spp", "8", "--integrator", "path", "--rows-per-strip", "1"]);
    cmd.args(["--workers", &format!("{},{}", a.addr, b.addr), "--serve", &page]);
    let render = Running::start(&mut cmd);
    render.wait_for_line(&format!("live page: {url}"), 1, LIMIT);

    // Both workers listed and ready, and a few strips in the image.
    let both_ok = |s: &serde_json::Value| {
        [&a.addr, &b.addr].iter().all(|w| worker_state(s, w).as_deref() == Some("ok")) && done(s) >= 3
    };
    wait_for_status(&page, "both workers ok and 3 strips done", both_ok);
    let first = dump_dom(&bin, &dir, &url);
    assert!(attr_u64(&first, "id=\"preview\"", "data-frames") >= 1, "no preview was shown:\n{first}");
    let first_done = attr_u64(&first, "id=\"preview\"", "data-done");
    assert!(first_done >= 3, "the preview shows {first_done} strips:\n{first}");
    for w in [&a.addr, &b.addr] {
        let row = format!("data-address=\"{w}\"");
        assert_eq!(attr(&first, &row, "data-state").as_deref(), Some("ok"), "{w}'s row:\n{first}");
    }

    b.kill();
    let lost =
        wait_for_status(&page, "the killed worker lost", |s| worker_state(s, &b.addr).as_deref() == Some("lost"));
    // The image goes on filling in on the other worker: look again once it has.
    let more = done(&lost).max(first_done) + 2;
    wait_for_status(&page, "more strips done", |s| done(s) >= more);
    let second = dump_dom(&bin, &dir, &url);
    assert!(attr_u64(&second, "id=\"preview\"", "data-frames") >= 1, "no preview was shown:\n{second}");
    let second_done = attr_u64(&second, "id=\"preview\"", "data-done");
    assert!(second_done > first_done, "the preview did not fill in: {first_done} then {second_done} strips");
    let row = |w: &str| attr(&second, &format!("data-address=\"{w}\""), "data-state");
    assert_eq!(row(&b.addr).as_deref(), Some("lost"), "the killed worker's row:\n{second}");
    assert_eq!(row(&a.addr).as_deref(), Some("ok"), "the other worker's row:\n{second}");

    let shot = dir.join("live-page.png");
    let o = run_with_timeout(
        chromium(&bin, &dir).arg("--window-size=1200,900").arg(format!("--screenshot={}", shot.display())).arg(&url),
        Duration::from_secs(90),
    );
    assert!(o.status.success(), "chromium --screenshot failed: {}", String::from_utf8_lossy(&o.stderr));
    let png = std::fs::read(&shot).unwrap();
    assert!(png.starts_with(b"\x89PNG"), "{} is not a PNG", shot.display());
    println!("live page screenshot: {}", shot.display());

    // The render finishes on the worker left; without --serve-after the page goes with it.
    let o = render.finish(LIMIT);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "stdout:\n{stdout}\nstderr:\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(WorkerRow::find(&stdout, &b.addr).unwrap().state.starts_with("lost"), "{stdout}");
    assert!(WorkerRow::find(&stdout, &a.addr).unwrap().units > 0, "{stdout}");
    assert!(http_get(&page, "/api/status").is_none(), "the page is still up after the render");
}

/// `--serve` with the default in-process render, and `--serve-after`: the page shows the finished render until
/// SIGINT, and the process then ends as a successful render does.
#[test]
fn serve_after_keeps_the_final_state_up_until_ctrl_c() {
    let dir = temp_dir("live", "after");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let page = format!("127.0.0.1:{port}");
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(dir.join("out.png")).arg("-q");
    cmd.args(["--size", "32x24", "--spp", "2", "--integrator", "path", "--serve", &page, "--serve-after"]);
    let render = Running::start(&mut cmd);
    render.wait_for_line("until Ctrl-C", 1, LIMIT);
    let s = wait_for_status(&page, "the render finished", |s| s["finished"] == true);
    let preview = http_get(&page, "/preview.png").map(|r| r.0);
    // Stopped before anything is asserted, so that a failed check leaves no process behind.
    assert!(render.signal("INT"));
    let o = render.finish(LIMIT);
    assert_eq!(s["done"], s["total"], "{s}");
    assert_eq!(s["eta_s"].as_f64(), Some(0.0));
    assert_eq!(preview, Some(200));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("out.png").is_file());
}

/// A page that cannot be served stops the render before it starts, naming the address.
#[test]
fn a_port_in_use_or_a_bad_address_is_refused_at_once() {
    let dir = temp_dir("live", "refused");
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    for (serve, wanted) in [
        (addr.as_str(), format!("cannot serve the live page on {addr}: ")),
        ("nowhere", "expected HOST:PORT to serve the live page on".to_owned()),
    ] {
        let mut cmd = Command::new(coordinator());
        cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(dir.join("out.png"));
        cmd.args(["--size", "16x16", "--spp", "1", "--serve", serve]);
        let o = run_with_timeout(&mut cmd, LIMIT);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.contains(&wanted), "--serve {serve}: {stderr}");
        assert!(!dir.join("out.png").exists());
    }
}
