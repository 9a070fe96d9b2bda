//! Progressive photon mapping over the farm: whole-image pass blocks, each pass traced once in the whole farm,
//! and an image that depends only on (scene, seed, passes), bit for bit, whatever the workers do.

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::{WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::Duration;

const PASSES: u64 = 24;
const PASS_PHOTONS: u64 = 4000;
/// A progressive job of 24 passes; `--rows-per-strip 2` cuts it into 12 blocks of 2 passes.
const JOB: &[&str] = &["--size", "40x30", "--integrator", "progressive", "--passes", "24", "--photons", "4000"];

const LIMIT: Duration = Duration::from_secs(240);

fn render(out: &Path, extra: &[&str]) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(out).arg("-q").args(JOB).args(extra);
    run_with_timeout(&mut cmd, LIMIT)
}

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn bits(path: &Path) -> Vec<u32> {
    Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// The in-process render, with its default cut (made once per test process).
fn reference() -> Vec<u32> {
    static REF: OnceLock<Vec<u32>> = OnceLock::new();
    REF.get_or_init(|| {
        let out = temp_dir("farm-passes", "ref").join("ref.exr");
        let o = render(&out, &[]);
        assert!(o.status.success(), "{}", text(&o));
        assert_eq!(paths_in_summary(&o), PASSES * PASS_PHOTONS, "{}", text(&o));
        let b = bits(&out);
        assert!(b.iter().any(|&v| f32::from_bits(v) > 0.0));
        b
    })
    .clone()
}

/// The summary line's count of photon paths traced on the workers.
fn paths_in_summary(o: &Output) -> u64 {
    let out = String::from_utf8_lossy(&o.stdout);
    let at = out.find(" paths traced on the workers").unwrap_or_else(|| panic!("no path count in {}", text(o)));
    out[..at].rsplit('(').next().and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("{}", text(o)))
}

/// A worker's row of the end table: (units accepted, photon paths).
fn row(o: &Output, addr: &str) -> (u64, u64) {
    let row = WorkerRow::find(&String::from_utf8_lossy(&o.stdout), addr).unwrap_or_else(|| panic!("{}", text(o)));
    (row.units, row.photon_paths)
}

fn workers_arg(ws: &[&WorkerProcess]) -> String {
    ws.iter().map(|w| w.addr.as_str()).collect::<Vec<_>>().join(",")
}

#[test]
fn one_and_three_workers_give_the_in_process_bytes_and_trace_each_pass_once() {
    let want = reference();
    let dir = temp_dir("farm-passes", "match");
    let ws: Vec<WorkerProcess> = (0..3).map(|_| WorkerProcess::start(&["--threads", "1"])).collect();
    for (name, n) in [("one", 1), ("three", 3)] {
        let out = dir.join(format!("{name}.exr"));
        let farm: Vec<&WorkerProcess> = ws.iter().take(n).collect();
        let o = render(&out, &["--workers", &workers_arg(&farm), "--rows-per-strip", "2"]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(bits(&out) == want, "{name} worker(s) changed pixels");
        // Every pass traced exactly once in the whole farm: the workers' paths add up to passes × pass_photons.
        assert_eq!(paths_in_summary(&o), PASSES * PASS_PHOTONS, "{}", text(&o));
        let rows: Vec<(u64, u64)> = farm.iter().map(|w| row(&o, &w.addr)).collect();
        assert_eq!(rows.iter().map(|r| r.0).sum::<u64>(), 12, "12 blocks of 2 passes: {}", text(&o));
        assert_eq!(rows.iter().map(|r| r.1).sum::<u64>(), PASSES * PASS_PHOTONS, "{}", text(&o));
    }
}

#[test]
fn a_worker_killed_in_the_middle_of_a_pass_block_changes_nothing() {
    let want = reference();
    let dir = temp_dir("farm-passes", "kill");
    // Both take at least 0.1 s a block, so the victim holds blocks when it dies.
    let mut victim = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "100"]);
    let survivor = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "100"]);
    let out = dir.join("out.exr");
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(&out).arg("-q").args(JOB);
    cmd.args(["--workers", &workers_arg(&[&victim, &survivor]), "--rows-per-strip", "1"]);
    let handle = std::thread::spawn(move || run_with_timeout(&mut cmd, LIMIT));
    victim.wait_for_log("rendering strip", 2, LIMIT);
    victim.kill();
    let o = handle.join().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(row_line(&o, &victim.addr).contains("lost"), "{}", text(&o));
    assert!(bits(&out) == want, "the image changed after a worker was killed");
    assert_eq!(paths_in_summary(&o), PASSES * PASS_PHOTONS, "{}", text(&o));
}

fn row_line(o: &Output, addr: &str) -> String {
    let stdout = String::from_utf8_lossy(&o.stdout);
    stdout.lines().find(|l| l.starts_with(addr)).unwrap_or_else(|| panic!("{}", text(o))).to_owned()
}

#[test]
fn corrupted_sums_are_caught_and_impossible_sums_are_reported_as_a_bug() {
    let want = reference();
    let dir = temp_dir("farm-passes", "corrupt");
    let faulty = WorkerProcess::start(&["--threads", "1", "--test-corrupt-strips", "2"]);
    let out = dir.join("out.exr");
    let o = render(&out, &["--workers", &faulty.addr, "--rows-per-strip", "4"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(text(&o).matches("checksum mismatch").count(), 2, "{}", text(&o));
    assert!(bits(&out) == want, "a corrupted block reached the image");
    let buggy = WorkerProcess::start(&["--threads", "1", "--test-nan-strips"]);
    let o = render(&dir.join("bug.exr"), &["--workers", &buggy.addr]);
    assert!(!o.status.success(), "{}", text(&o));
    let all = text(&o);
    assert!(all.contains("not the sum of") && all.contains("method `progressive`"), "{all}");
}

#[test]
fn an_interrupted_progressive_render_resumes_to_the_same_bytes() {
    let want = reference();
    let dir = temp_dir("farm-passes", "resume");
    let out = dir.join("out.exr");
    let mut only = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "200"]);
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(&out).arg("-q").args(JOB);
    cmd.args(["--workers", &only.addr, "--rows-per-strip", "2"]);
    let handle = std::thread::spawn(move || run_with_timeout(&mut cmd, LIMIT));
    only.wait_for_log("rendering strip", 4, LIMIT);
    only.kill();
    let o = handle.join().unwrap();
    assert!(!o.status.success(), "{}", text(&o));
    let partial = dir.join("out.exr.partial");
    assert!(partial.is_file(), "{}", text(&o));
    let fresh = WorkerProcess::start(&[]);
    let o = render(&out, &["--workers", &fresh.addr, "--resume", partial.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let resumed = String::from_utf8_lossy(&o.stdout).contains("pass blocks resumed");
    assert!(resumed, "{}", text(&o));
    assert!(bits(&out) == want, "the resumed image differs");
    // Only the missing blocks were traced again.
    assert!(paths_in_summary(&o) < PASSES * PASS_PHOTONS, "{}", text(&o));
}
