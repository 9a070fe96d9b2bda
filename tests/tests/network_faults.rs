//! The farm on a network: the coordinator and each worker on hosts of their own (network namespaces joined by
//! a bridge, `photon_tests::netns`), and their links cut, restored, flapped or slowed while a render runs. Each
//! fault must lose nothing and count nothing twice: the image is byte for byte the uninterrupted in-process
//! render, and the end table's units add up to the job's, each accepted once.
//!
//! The tests need root and network namespaces; where they cannot run they say so and pass, unless
//! `PHOTON_REQUIRE_NETNS` is set (as `.ci/run` sets it). They act on what the processes log (a unit started, a
//! unit rendered, a stall noticed) and on the hosts' byte counters, never on guessed sleeps alone. Each prints
//! the time from its fault to the unit being issued again (docs/RESULTS.md, "The farm on a network").

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::netns::Lab;
use photon_tests::{Running, WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir, worker};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A path-traced job of 32 strips of 3 rows.
const PATH_JOB: &[&str] = &["--size", "128x96", "--spp", "48", "--integrator", "path", "--rows-per-strip", "3"];
/// A progressive job of 24 whole-image pass blocks of 2 passes, each block's sums 160 × 120 × 24 bytes (450 KiB):
/// enough blocks that the other worker is still busy with fresh ones when a silence is noticed, so the tail's
/// speculative copies do not hide it.
const PASS_JOB: &[&str] = &[
    "--size",
    "160x120",
    "--integrator",
    "progressive",
    "--passes",
    "48",
    "--photons",
    "2000",
    "--rows-per-strip",
    "2",
];
/// The photon-map method with 100k-photon maps shipped from the coordinator (a blob of megabytes to cut).
const SHIP_JOB: &[&str] = &[
    "--size",
    "64x48",
    "--spp",
    "4",
    "--integrator",
    "photon-map",
    "--photons",
    "100000",
    "--photon-maps",
    "ship",
    "--rows-per-strip",
    "2",
];

/// The photon-map method with 200k-path maps (about 12 MB), 12 strips of 6 rows, the delivery left to the test.
const MAPS_JOB: &[&str] =
    &["--size", "96x72", "--spp", "4", "--integrator", "photon-map", "--photons", "200000", "--rows-per-strip", "6"];

const LIMIT: Duration = Duration::from_secs(240);
/// What the coordinator logs when it issues a silent worker's units again.
const STALL_LINE: &str = "stalled: issuing its units again";

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn bits(path: &Path) -> Vec<u32> {
    Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// The render command of `job` writing `out`, on `cmd` (the coordinator, here or on a host of a lab).
fn render_command(mut cmd: Command, out: &Path, job: &[&str], extra: &[&str]) -> Command {
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(out).arg("-q").args(job).args(extra);
    cmd.args(["--no-cache"]).env("RUST_LOG", "photon_coordinator=info").env("NO_COLOR", "1");
    cmd
}

/// The uninterrupted in-process render of a job, once per test process and job.
fn reference(job: &'static [&'static str]) -> Vec<u32> {
    static REFS: [OnceLock<Vec<u32>>; 4] = [OnceLock::new(), OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let i = [PATH_JOB, PASS_JOB, SHIP_JOB, MAPS_JOB].iter().position(|j| *j == job).unwrap();
    REFS[i]
        .get_or_init(|| {
            let out = temp_dir("netfaults", &format!("ref-{i}")).join("ref.exr");
            let o = run_with_timeout(&mut render_command(Command::new(coordinator()), &out, job, &[]), LIMIT);
            assert!(o.status.success(), "{}", text(&o));
            let b = bits(&out);
            assert!(b.iter().any(|&v| f32::from_bits(v) > 0.0));
            b
        })
        .clone()
}

/// A lab of a coordinator (host 0) and `n` workers (hosts 1..=n), each worker started with `args`.
struct Farm {
    workers: Vec<WorkerProcess>,
    lab: Lab,
}

impl Farm {
    fn start(n: usize, args: &[&str]) -> Option<Self> {
        let lab = Lab::new(n + 1)?;
        let workers = (1..=n)
            .map(|i| {
                let listen = format!("{}:7878", lab.addr(i));
                WorkerProcess::start_command(lab.command(i, &worker()), &listen, args)
            })
            .collect();
        Some(Self { workers, lab })
    }

    fn worker_list(&self) -> String {
        self.workers.iter().map(|w| w.addr.as_str()).collect::<Vec<_>>().join(",")
    }

    /// Starts the coordinator on host 0, rendering `job` to `out` on every worker.
    fn render(&self, out: &Path, job: &[&str], extra: &[&str]) -> Running {
        let list = self.worker_list();
        let mut cmd =
            render_command(self.lab.command(0, coordinator()), out, job, &[&["--workers", &list], extra].concat());
        Running::start(&mut cmd)
    }
}

/// Checks a finished render of `job`: it succeeded, its image is the uninterrupted one, and the units in the
/// end table add up to `units` (each unit accepted once). Returns the rows of the workers, in order.
fn check(o: &Output, out: &Path, job: &'static [&'static str], units: u64, farm: &Farm) -> Vec<WorkerRow> {
    assert!(o.status.success(), "{}", text(o));
    assert!(bits(out) == reference(job), "the image differs from the uninterrupted render: {}", text(o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let rows: Vec<WorkerRow> = farm
        .workers
        .iter()
        .map(|w| WorkerRow::find(&stdout, &w.addr).unwrap_or_else(|| panic!("no row for {}: {}", w.addr, text(o))))
        .collect();
    assert_eq!(rows.iter().map(|r| r.units).sum::<u64>(), units, "each unit accepted once: {}", text(o));
    rows
}

/// Waits for the coordinator to issue the units of a silent worker again, and prints how long that took after
/// the fault at `fault`.
fn await_reissue(render: Running, fault: Instant, what: &str) -> (Running, Duration) {
    if !render.saw_line(STALL_LINE, 1, LIMIT) {
        panic!("the units were not issued again: {}", text(&render.finish(LIMIT)));
    }
    let took = fault.elapsed();
    eprintln!("fault to re-issue, {what}: {:.2} s", took.as_secs_f64());
    (render, took)
}

/// On a farm of 2 workers rendering the path job, cuts the first worker's link once it has started its third
/// strip (its first result measured its speed), and waits until its units are issued again. Returns the farm,
/// the render, its output and the time from the cut to the re-issue; `None` where namespaces cannot be used.
fn cut_during_a_unit(test: &str, what: &str) -> Option<(Farm, Running, PathBuf, Duration)> {
    let farm = Farm::start(2, &["--threads", "1", "--test-delay-ms", "150"])?;
    let out = temp_dir("netfaults", test).join("out.exr");
    let render = farm.render(&out, PATH_JOB, &[]);
    farm.workers[0].wait_for_log("rendering strip", 3, LIMIT);
    let fault = Instant::now();
    farm.lab.cut(1);
    let (render, took) = await_reissue(render, fault, what);
    Some((farm, render, out, took))
}

/// A worker's link is cut while it renders a unit, after its speed is known, then restored: the coordinator
/// notices the silence within the worker's silence limit (well before the unit's deadline), issues its units to
/// the other worker, and the worker takes part again once its link is back.
#[test]
fn a_link_cut_during_a_unit_then_restored_loses_nothing() {
    let Some((farm, render, out, took)) = cut_during_a_unit("cut-unit", "link cut during a unit") else { return };
    std::thread::sleep(Duration::from_millis(500));
    farm.lab.restore(1);
    let o = render.finish(LIMIT);
    check(&o, &out, PATH_JOB, 32, &farm);
    assert!(took < Duration::from_secs(10), "re-issued {took:?} after the cut, not before the 10 s deadline floor");
}

/// A worker cut off for good: its units go to the other, and the render finishes without it.
#[test]
fn a_worker_cut_off_for_good_loses_nothing() {
    let Some((farm, render, out, _)) = cut_during_a_unit("cut-for-good", "worker cut off for good") else { return };
    let o = render.finish(LIMIT);
    let rows = check(&o, &out, PATH_JOB, 32, &farm);
    let state = &rows[0].state;
    assert!(state == "stalled" || state.starts_with("blocked") || state.starts_with("lost"), "{}", text(&o));
    assert_eq!(rows[1].state, "ok", "{}", text(&o));
}

/// A link that goes down for 2.5 s and up for 1 s, again and again, for the whole render.
#[test]
fn a_flapping_link_loses_nothing() {
    let Some(farm) = Farm::start(2, &["--threads", "1", "--test-delay-ms", "150"]) else { return };
    let out = temp_dir("netfaults", "flapping").join("out.exr");
    let render = farm.render(&out, PATH_JOB, &[]);
    farm.workers[0].wait_for_log("rendering strip", 2, LIMIT);
    let stop = AtomicBool::new(false);
    let (o, flaps) = std::thread::scope(|s| {
        let flapper = s.spawn(|| {
            let mut flaps = 0;
            while !stop.load(Ordering::Relaxed) {
                farm.lab.cut(1);
                std::thread::sleep(Duration::from_millis(2500));
                farm.lab.restore(1);
                flaps += 1;
                std::thread::sleep(Duration::from_millis(1000));
            }
            flaps
        });
        let o = render.finish(LIMIT);
        stop.store(true, Ordering::Relaxed);
        (o, flapper.join().unwrap())
    });
    check(&o, &out, PATH_JOB, 32, &farm);
    assert!(flaps >= 1, "the link never flapped during the render: {}", text(&o));
    eprintln!("flapping link: {flaps} cuts of 2.5 s during the render");
}

/// A worker finishes a pass block and starts sending its 450 KiB of sums over a 4 Mbit/s link (about a
/// second); the link is cut at once, so the reply is lost on the way. The coordinator hears nothing more, issues
/// the block to the other worker, and when the link comes back the late reply (TCP delivers it, or the call was
/// cancelled) does not join the image a second time.
#[test]
fn a_reply_lost_after_the_unit_finished_is_counted_once() {
    let Some(farm) = Farm::start(2, &["--threads", "1", "--test-delay-ms", "200"]) else { return };
    farm.lab.shape(1, 4);
    let out = temp_dir("netfaults", "lost-reply").join("out.exr");
    let render = farm.render(&out, PASS_JOB, &[]);
    // Once a first result of it was accepted (its speed is measured), the next block it finishes: what it
    // logged before is passed over.
    render.wait_for_line(&format!("accepted worker={}", farm.workers[0].addr), 1, LIMIT);
    while farm.workers[0].log.try_recv().is_ok() {}
    farm.workers[0].wait_for_log("strip rendered, sending it", 1, LIMIT);
    let fault = Instant::now();
    farm.lab.cut(1);
    let (render, _) = await_reissue(render, fault, "reply lost after the unit finished");
    std::thread::sleep(Duration::from_millis(500));
    farm.lab.restore(1);
    let o = render.finish(LIMIT);
    check(&o, &out, PASS_JOB, 24, &farm);
}

/// A worker's link is cut for 3 s in the middle of the upload of a photon map of megabytes (at 20 Mbit/s), then
/// restored: the upload resumes within its time limit and the worker renders with the same bits.
#[test]
fn a_link_cut_during_a_blob_upload_then_restored_loses_nothing() {
    // 400 ms a strip: the other worker alone would take about 10 s, longer than the upload and its cut.
    let Some(farm) = Farm::start(2, &["--threads", "1", "--test-delay-ms", "400"]) else { return };
    farm.lab.shape(1, 20);
    let out = temp_dir("netfaults", "cut-upload").join("out.exr");
    let before = farm.lab.rx_bytes(1);
    let render = farm.render(&out, SHIP_JOB, &[]);
    // A megabyte of the upload has arrived: cut it there.
    let end = Instant::now() + LIMIT;
    while farm.lab.rx_bytes(1) < before + (1 << 20) {
        assert!(Instant::now() < end, "the upload never reached a megabyte");
        std::thread::sleep(Duration::from_millis(20));
    }
    farm.lab.cut(1);
    std::thread::sleep(Duration::from_secs(3));
    farm.lab.restore(1);
    let o = render.finish(LIMIT);
    let rows = check(&o, &out, SHIP_JOB, 24, &farm);
    assert!(!rows[0].state.starts_with("refused"), "the upload did not survive the cut: {}", text(&o));
    assert!(rows[0].shipped.ends_with("MiB"), "the map was shipped to it: {}", rows[0].line);
}

/// The delivery a render's summary line names (`--photon-maps` forced or chosen).
fn delivery_of(o: &Output) -> &'static str {
    let all = text(o);
    [("traced by each worker", "trace"), ("passed among the workers", "peers"), ("traced here and shipped", "ship")]
        .into_iter()
        .find(|(words, _)| all.contains(words))
        .map(|(_, mode)| mode)
        .unwrap_or_else(|| panic!("the summary names no photon-map delivery: {all}"))
}

/// The coordinator's link at 100 Mbit/s and four workers: each delivery of a 12 MB photon map is timed on fresh
/// workers (nothing cached), then `auto` must choose one the measured times favour (within 20 % of the fastest:
/// the runs are noisy on a shared machine), having measured the link near its 12.5 MB/s, and render the same
/// bits.
#[test]
fn behind_a_100_mbit_link_auto_chooses_the_delivery_the_measured_times_favour() {
    let mut times = Vec::new();
    for mode in ["ship", "peers", "trace", "auto"] {
        let Some(farm) = Farm::start(4, &["--threads", "1"]) else { return };
        farm.lab.shape(0, 100);
        let out = temp_dir("netfaults", &format!("delivery-{mode}")).join("out.exr");
        let t = Instant::now();
        let o = farm.render(&out, MAPS_JOB, &["--photon-maps", mode]).finish(LIMIT);
        let secs = t.elapsed().as_secs_f64();
        check(&o, &out, MAPS_JOB, 12, &farm);
        eprintln!("100 Mbit/s coordinator link, 4 workers, --photon-maps {mode}: {secs:.2} s");
        if mode != "auto" {
            assert_eq!(delivery_of(&o), mode, "{}", text(&o));
            times.push((mode, secs));
            continue;
        }
        let chosen = delivery_of(&o);
        let all = text(&o);
        let measured: f64 = all
            .split("link measured at ")
            .nth(1)
            .and_then(|rest| rest.split(' ').next())
            .and_then(|mb| mb.parse().ok())
            .unwrap_or_else(|| panic!("auto did not measure the link: {all}"));
        assert!((7.5..=13.0).contains(&measured), "a 100 Mbit/s link measured at {measured} MB/s: {all}");
        let best = times.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
        let of_chosen = times.iter().find(|t| t.0 == chosen).map(|t| t.1).unwrap();
        assert!(of_chosen <= 1.2 * best, "auto chose {chosen} ({of_chosen:.2} s) where {times:?} were measured: {all}");
        eprintln!("auto chose {chosen}, the link measured at {measured} MB/s; measured {times:?}");
    }
}
