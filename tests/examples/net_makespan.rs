//! Makespans on a network, measured and modelled (docs/RESULTS.md, "The farm on a network"): a photon-map job
//! rendered with each photon-map delivery (`ship`, `peers`, `trace`) by 2, 4 and 8 one-thread workers, each
//! worker and the coordinator on a host of its own ([`photon_tests::netns`]) with every link shaped to 1 Gbit/s
//! and then 100 Mbit/s; beside each measured makespan, the farm model's prediction for the same settings
//! ([`photon_coordinator::model::simulate`]), fed with costs measured here on one thread before the runs.
//!
//! The hosts share this machine's cores, and the model is told so: each of `n` one-thread workers renders at
//! `min(1, cores / n)` of a core. Fresh workers for every run, so nothing is cached between them; the makespan
//! is the wall time of the whole `photon-coordinator render` command (preparing included), the median of
//! `--runs` (3).
//!
//! As root: `cargo run --release -p photon-tests --example net_makespan [-- --runs N]`.

#![allow(clippy::expect_used, clippy::unwrap_used)] // a benchmark: a failure should stop it loudly

use photon_coordinator::farm::scheduler::Policy;
use photon_coordinator::job::Job;
use photon_coordinator::model::{Network, SimJob, SimWorker, simulate};
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::run::Guard;
use photon_core::scene::Scene;
use photon_tests::netns::Lab;
use photon_tests::{WorkerProcess, coordinator, run_with_timeout, scenes_dir, temp_dir, worker};
use std::time::{Duration, Instant};

const WIDTH: u32 = 128;
const HEIGHT: u32 = 96;
const SPP: u32 = 8;
const PATHS: u32 = 200_000;
const ROWS_PER_STRIP: u32 = 4;

fn job_args() -> Vec<String> {
    let size = format!("{WIDTH}x{HEIGHT}");
    let (spp, paths, rows) = (SPP.to_string(), PATHS.to_string(), ROWS_PER_STRIP.to_string());
    let args = ["--size", &size, "--spp", &spp, "--integrator", "photon-map", "--photons", &paths];
    args.iter().map(|s| s.to_string()).chain(["--rows-per-strip".into(), rows]).collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn one_thread<R: Send>(f: impl FnOnce() -> R + Send) -> (f64, R) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("one-thread pool");
    let t = Instant::now();
    let r = pool.install(f);
    (t.elapsed().as_secs_f64(), r)
}

/// What the model needs of one delivery: blob bytes to each worker, the coordinator's preparing, and a worker's
/// loading in one-core seconds.
struct Costs {
    blob_bytes: f64,
    prepare_s: f64,
    load_core_s: f64,
}

/// The job's costs, measured here: (seconds of one core per row, the shipped delivery, the traced one).
fn calibrate() -> (f64, Costs, Costs) {
    let path = scenes_dir().join("cornell.toml");
    let mut scene = Scene::load(&path).expect("cornell.toml");
    (scene.camera.width, scene.camera.height, scene.render.spp) = (WIDTH, HEIGHT, SPP);
    scene.render.integrator = Method::PhotonMap;
    scene.render.photons.global = PATHS;
    // The coordinator prepares on all its threads, as the render does.
    let t = Instant::now();
    let scene_only = Prepared::new(&scene, &path).expect("prepare");
    let scene_prepare_s = t.elapsed().as_secs_f64();
    let prep = scene_only.with_photon_maps(&path).expect("photon maps");
    let job = Job::new(
        prep.encode_scene().expect("scene"),
        prep.encode_photons().expect("photons"),
        prep.encode_textures().expect("textures"),
        prep.encode_frame().expect("frame"),
        (WIDTH, HEIGHT),
        &prep.settings,
    );
    let prepare_s = t.elapsed().as_secs_f64();
    let photons = job.photons_blob.as_ref().and_then(|id| job.blobs.get(id)).map(|b| b.as_slice());
    let decode = |photons| {
        let textures: Vec<&[u8]> = job.texture_blobs.iter().map(|id| job.blobs[id].as_slice()).collect();
        Prepared::from_blobs(&job.blobs[&job.scene_blob], photons, &job.frame, &textures, usize::MAX).expect("decode")
    };
    let (shipped_load_s, _) = one_thread(|| decode(photons));
    let (traced_load_s, _) = one_thread(|| decode(None).build_photon_maps(&Guard::unbounded()).expect("maps"));
    let rows = 16;
    let (t, _) = one_thread(|| photon_core::render::render_rows(&prep, 0..rows, &|_| {}));
    let shipped = Costs { blob_bytes: job.blob_bytes() as f64, prepare_s, load_core_s: shipped_load_s };
    let scene_bytes = job.blobs[&job.scene_blob].len() as f64;
    let traced = Costs { blob_bytes: scene_bytes, prepare_s: scene_prepare_s, load_core_s: traced_load_s };
    (t / f64::from(rows), shipped, traced)
}

/// One render of the job on `n` fresh one-thread workers, every link at `mbit` Mbit/s: the wall seconds.
fn measure(n: usize, mbit: u32, mode: &str) -> f64 {
    let lab = Lab::new(n + 1).expect("network namespaces (run as root)");
    for i in 0..=n {
        lab.shape(i, mbit);
    }
    let workers: Vec<WorkerProcess> = (1..=n)
        .map(|i| {
            let listen = format!("{}:7878", lab.addr(i));
            WorkerProcess::start_command(lab.command(i, &worker()), &listen, &["--threads", "1"])
        })
        .collect();
    let list = workers.iter().map(|w| w.addr.as_str()).collect::<Vec<_>>().join(",");
    let out = temp_dir("net-makespan", &format!("{n}-{mbit}-{mode}")).join("out.exr");
    let mut cmd = lab.command(0, coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(&out).args(["-q", "--no-cache"]);
    cmd.args(job_args()).args(["--workers", &list, "--photon-maps", mode]);
    let t = Instant::now();
    let o = run_with_timeout(&mut cmd, Duration::from_secs(300));
    let secs = t.elapsed().as_secs_f64();
    assert!(o.status.success(), "{mode} on {n} workers at {mbit} Mbit/s: {}", String::from_utf8_lossy(&o.stderr));
    secs
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: usize = args
        .iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1))
        .map_or(3, |n| n.parse().expect("--runs N"));
    // Build the binaries first (photon_tests::coordinator), so that no run pays for it.
    let _ = coordinator();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let (core_s_per_row, shipped, traced) = calibrate();
    println!(
        "net_makespan: Cornell {WIDTH}x{HEIGHT}, photon-map, {SPP} spp, {PATHS} paths, {} strips; {cores} cores; \
         one core: {:.1} ms a row; shipped: {:.1} MB, prepare {:.2} s, load {:.2} core-s; traced: {:.2} MB, \
         prepare {:.2} s, load (tracing the maps) {:.2} core-s; median of {runs}",
        HEIGHT.div_ceil(ROWS_PER_STRIP),
        1e3 * core_s_per_row,
        shipped.blob_bytes / 1e6,
        shipped.prepare_s,
        shipped.load_core_s,
        traced.blob_bytes / 1e6,
        traced.prepare_s,
        traced.load_core_s,
    );
    println!(
        "| links | workers | ship: measured s | modelled s | peers: measured s | modelled s | trace: measured s | modelled s |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for mbit in [1000u32, 100] {
        for n in [2usize, 4, 8] {
            let mut cells = Vec::new();
            for mode in ["ship", "peers", "trace"] {
                let measured = median((0..runs).map(|_| measure(n, mbit, mode)).collect());
                let costs = if mode == "trace" { &traced } else { &shipped };
                let job = SimJob {
                    units: HEIGHT,
                    units_per_strip: ROWS_PER_STRIP,
                    core_s_per_unit: core_s_per_row,
                    result_bytes_fixed: 0.0,
                    // A strip's sums: 3 × i64 per pixel.
                    result_bytes_per_unit: 24.0 * f64::from(WIDTH),
                    blob_bytes: costs.blob_bytes,
                    prepare_s: costs.prepare_s,
                    load_core_s: costs.load_core_s,
                    thread_efficiency: 1.0,
                    relay: mode == "peers",
                };
                let speed = (cores / n as f64).min(1.0);
                let workers = vec![SimWorker { cores: 1, core_speed: speed, dies_at: None }; n];
                let bps = f64::from(mbit) * 1e6 / 8.0;
                let net = Network { coordinator_bps: bps, worker_bps: bps, rtt_s: 2e-4, detect_s: 1.0 };
                let modelled = simulate(&job, &workers, &net, Policy::default());
                assert!(modelled.complete, "the model did not finish");
                cells.push(format!("{measured:.2} | {:.2}", modelled.makespan_s));
            }
            let links = if mbit >= 1000 { format!("{} Gbit/s", mbit / 1000) } else { format!("{mbit} Mbit/s") };
            println!("| {links} | {n} | {} |", cells.join(" | "));
        }
    }
}
