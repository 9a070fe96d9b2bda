//! Interruption and workers that come back, with the binaries as a user runs them.
//!
//! SIGINT or SIGTERM in the middle of a render keeps every finished strip (or pass block) in `OUT.partial`,
//! prints the command that resumes it and exits as the signal would (130, 143); that command finishes the image
//! with the bytes of an uninterrupted render. A worker killed and started again on its port rejoins the render
//! and takes strips again; a frozen one is reported `stalled` and its units go to the others. The tests act on what the processes log (a strip
//! accepted, a worker rejoined), never on guessed sleeps.

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::{Running, WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::Duration;

/// A path-traced job of 32 strips.
const PATH_JOB: &[&str] = &["--size", "128x96", "--spp", "48", "--integrator", "path", "--rows-per-strip", "3"];
/// A progressive job of 12 pass blocks.
const PASS_JOB: &[&str] =
    &["--size", "40x30", "--integrator", "progressive", "--passes", "24", "--photons", "4000", "--rows-per-strip", "2"];

const LIMIT: Duration = Duration::from_secs(240);

fn command(out: &Path, job: &[&str], extra: &[&str]) -> Command {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(out).arg("-q").args(job).args(extra);
    // The farm logs each accepted strip and each rejoin at this level: the tests wait for those lines.
    cmd.env("RUST_LOG", "photon_coordinator=info").env("NO_COLOR", "1");
    cmd
}

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn bits(path: &Path) -> Vec<u32> {
    Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// The uninterrupted in-process render of a job (made once per test process and job).
fn reference(job: &'static [&'static str]) -> Vec<u32> {
    static PATH_REF: OnceLock<Vec<u32>> = OnceLock::new();
    static PASS_REF: OnceLock<Vec<u32>> = OnceLock::new();
    let path = job == PATH_JOB;
    let cell = if path { &PATH_REF } else { &PASS_REF };
    cell.get_or_init(|| {
        let out = temp_dir("interrupt", if path { "ref-path" } else { "ref-pass" }).join("ref.exr");
        let o = run_with_timeout(&mut command(&out, job, &[]), LIMIT);
        assert!(o.status.success(), "{}", text(&o));
        let b = bits(&out);
        assert!(b.iter().any(|&v| f32::from_bits(v) > 0.0));
        b
    })
    .clone()
}

/// The number before ` {units} resumed` in the summary line.
fn resumed(o: &Output, units: &str) -> u32 {
    let out = String::from_utf8_lossy(&o.stdout);
    let suffix = format!(" {units} resumed");
    out.split(", ").find_map(|p| p.trim().strip_suffix(&suffix)).and_then(|n| n.parse().ok()).unwrap_or_else(|| {
        panic!("no `{units} resumed` in {}", text(o));
    })
}

/// A worker's row of the end table.
fn row(o: &Output, addr: &str) -> WorkerRow {
    WorkerRow::find(&String::from_utf8_lossy(&o.stdout), addr)
        .unwrap_or_else(|| panic!("no row for {addr}: {}", text(o)))
}

/// Interrupts a render of `job` on one slow worker with `signal` after `accepted` units were accepted, checks
/// the exit status, the partial file and the printed command, then runs that command and compares the image
/// with the uninterrupted render.
fn interrupt_and_resume(job: &'static [&'static str], signal: &str, code: i32, accepted: usize, units: &str) {
    let want = reference(job);
    let dir = temp_dir("interrupt", &format!("{signal}-{units}").replace(' ', "-"));
    let out = dir.join("out.exr");
    let partial = dir.join("out.exr.partial");
    // 300 ms a unit: the signal lands long before the remaining units could finish.
    let worker = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "300"]);
    let render = Running::start(&mut command(&out, job, &["--workers", &worker.addr]));
    render.wait_for_line("accepted", accepted, LIMIT);
    assert!(render.signal(signal), "the render ended before the signal");
    let o = render.finish(LIMIT);
    assert_eq!(o.status.code(), Some(code), "{}", text(&o));
    assert!(partial.is_file(), "{}", text(&o));
    assert!(!out.exists(), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains(&format!("interrupted by SIG{signal}")), "{}", text(&o));
    // The printed command is this one with `--resume` added; run it as printed.
    let wanted = format!("--resume {}", partial.display());
    let line = stderr.lines().find(|l| l.contains(&wanted)).unwrap_or_else(|| panic!("{}", text(&o)));
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(words[0], coordinator().to_str().unwrap(), "{line}");
    assert!(words.contains(&"--workers") && words.contains(&worker.addr.as_str()), "{line}");
    let o = run_with_timeout(Command::new(words[0]).args(&words[1..]), LIMIT);
    assert!(o.status.success(), "{}", text(&o));
    assert!(resumed(&o, units) >= accepted as u32, "{}", text(&o));
    assert!(bits(&out) == want, "the resumed image differs from the uninterrupted one");
    assert!(!partial.exists(), "the partial file is removed once the image is complete");
}

/// SIGKILL gives the coordinator no chance to write anything: what survives is its last checkpoint. Resumed
/// from it, the render finishes with the bytes of an uninterrupted one, and removes the file.
#[test]
fn a_coordinator_killed_by_sigkill_resumes_from_its_last_checkpoint_to_the_same_bytes() {
    let want = reference(PATH_JOB);
    let dir = temp_dir("interrupt", "sigkill");
    let out = dir.join("out.exr");
    let partial = dir.join("out.exr.partial");
    // 300 ms a unit and a checkpoint at most every 100 ms: each checkpoint holds the units finished by then.
    let worker = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "300"]);
    let job = ["--workers", worker.addr.as_str(), "--checkpoint-every", "100ms"];
    let render = Running::start(&mut command(&out, PATH_JOB, &job));
    render.wait_for_line("checkpoint: ", 3, LIMIT);
    assert!(render.signal("KILL"), "the render ended before the signal");
    let o = render.finish(LIMIT);
    assert_eq!(o.status.code(), None, "killed by a signal: {}", text(&o));
    assert!(partial.is_file() && !out.exists(), "{}", text(&o));
    let held = String::from_utf8_lossy(&o.stderr)
        .lines()
        .filter_map(|l| l.split("checkpoint: ").nth(1)?.split(' ').next()?.parse::<u32>().ok())
        .max()
        .unwrap_or_else(|| panic!("no checkpoint count: {}", text(&o)));
    assert!(held >= 3, "{}", text(&o));
    let o = run_with_timeout(
        &mut command(&out, PATH_JOB, &[&job[..], &["--resume", partial.to_str().unwrap()]].concat()),
        LIMIT,
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(resumed(&o, "strips") >= held, "{}", text(&o));
    assert!(bits(&out) == want, "the resumed image differs from the uninterrupted one");
    assert!(!partial.exists(), "the partial file is removed once the image is complete");
}

#[test]
fn sigint_keeps_the_finished_strips_and_the_printed_command_resumes_to_the_same_bytes() {
    interrupt_and_resume(PATH_JOB, "INT", 130, 3, "strips");
}

#[test]
fn sigterm_keeps_the_finished_pass_blocks_and_the_printed_command_resumes_to_the_same_bytes() {
    interrupt_and_resume(PASS_JOB, "TERM", 143, 2, "pass blocks");
}

/// A second SIGINT while the first one's stop is under way ends the process at once; whichever comes first,
/// the exit status is SIGINT's and no image is written.
#[test]
fn a_second_signal_ends_the_render_at_once() {
    let dir = temp_dir("interrupt", "twice");
    let out = dir.join("out.exr");
    let worker = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "300"]);
    let render = Running::start(&mut command(&out, PATH_JOB, &["--workers", &worker.addr]));
    render.wait_for_line("accepted", 1, LIMIT);
    assert!(render.signal("INT"), "the render ended before the signal");
    render.wait_for_line("SIGINT: stopping", 1, LIMIT);
    // The orderly stop may already be over (it takes milliseconds): then the second signal finds no process.
    let second = render.signal("INT");
    let o = render.finish(LIMIT);
    // Either way the process ends as SIGINT ends it, and never writes the image.
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    assert!(!out.exists(), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    let orderly = stderr.contains("--resume") && dir.join("out.exr.partial").is_file();
    assert!(orderly || (second && stderr.contains("SIGINT again: stopping at once")), "{}", text(&o));
}

#[test]
fn a_worker_restarted_on_its_port_rejoins_and_takes_strips_again() {
    let want = reference(PATH_JOB);
    let dir = temp_dir("rejoin", "restart");
    let out = dir.join("out.exr");
    // The only worker: while it is down no strip is rendered, so the one started again on its port renders
    // every strip that was not finished (the render waits for it).
    let mut first = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "100"]);
    let addr = first.addr.clone();
    let render = Running::start(&mut command(&out, PATH_JOB, &["--workers", &addr]));
    first.wait_for_log("rendering strip", 3, LIMIT);
    first.kill();
    render.wait_for_line("lost", 1, LIMIT);
    let again = WorkerProcess::start_on(&addr, &["--threads", "1"]);
    render.wait_for_line("rejoined", 1, LIMIT);
    let o = render.finish(LIMIT);
    assert!(o.status.success(), "{}", text(&o));
    assert!(bits(&out) == want, "the image changed after a worker left and came back");
    // The restarted process rendered strips, was shipped the job again (its cache was empty), and the table
    // says it rejoined.
    again.wait_for_log("rendering strip", 1, LIMIT);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains(&format!("worker {addr} rejoined")), "{}", text(&o));
    assert!(!stderr.contains("rejoined (0 B shipped again)"), "{}", text(&o));
    let row = row(&o, &addr);
    assert!(row.units > 0 && row.state == "ok (rejoined once)", "{}", row.line);
}

#[cfg(unix)]
#[test]
fn a_frozen_worker_is_reported_stalled_not_ok() {
    let want = reference(PATH_JOB);
    let dir = temp_dir("rejoin", "frozen");
    let out = dir.join("out.exr");
    let frozen = WorkerProcess::start(&["--threads", "1"]);
    // 200 ms a strip: the render outlasts the frozen worker's silence limit (2 s) by several seconds.
    let steady = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "200"]);
    let workers = format!("{},{}", frozen.addr, steady.addr);
    let render = Running::start(&mut command(&out, PATH_JOB, &["--workers", &workers]));
    // Its third strip is asked for after its first result: its speed is measured, so its silence limit is short.
    frozen.wait_for_log("rendering strip", 3, LIMIT);
    let stop = Command::new("kill").args(["-STOP", &frozen.pid().to_string()]).status().unwrap();
    assert!(stop.success());
    render.wait_for_line("stalled", 1, LIMIT);
    let o = render.finish(LIMIT);
    assert!(o.status.success(), "{}", text(&o));
    assert!(bits(&out) == want, "the image changed with a frozen worker");
    // Frozen for less than the keep-alive's 30 s, so not lost: stalled, its units issued again to the other
    // worker; blocked if it stalled on 3 units in all (it takes new units whenever it holds none).
    let state = row(&o, &frozen.addr).state;
    let blocked_for_stalls = state.starts_with("blocked: 3 failed units") && state.contains("stalled");
    assert!(state == "stalled" || blocked_for_stalls, "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("its strips are issued again to the others"), "{}", text(&o));
    assert_eq!(row(&o, &steady.addr).state, "ok", "{}", text(&o));
}
