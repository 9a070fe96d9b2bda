//! Benchmarks of the distributed path on one machine (docs/RESULTS.md, "Distributed rendering"):
//!
//! 1. the same render direct (core's strip renderer, no scheduler, no wire), through the in-process worker
//!    (the default), and on two loopback worker processes: medians of interleaved runs, overhead in %;
//! 2. shipping photon maps: blob bytes and seconds per million photons on loopback, and whether LZ4 would pay
//!    on loopback and on a 1 Gbit/s link;
//! 3. strips per second: the scheduler state machine alone, and the whole farm with trivial strips.
//!
//! `-- --scaling [--max-workers N]` instead measures scaling (docs/RESULTS.md, "Scaling"): each method's job
//! rendered in-process on every core, then on 1, 2, 4, …, N one-thread loopback worker processes (N: the
//! cores); time (median of 3), speed-up over one worker, parallel efficiency, and every image checked bit for
//! bit against the in-process one.
//!
//! `-- --model` runs the discrete-event model of the origin's lab ([`photon_coordinator::model`]): per-row and
//! per-pass costs measured here on one thread for a 1920×1080 Cornell box, jobs sized to about 10 minutes on the
//! lab, with and without two machines dying (docs/RESULTS.md, "The modelled lab").
//!
//! `cargo build --release -p photon-worker && cargo run --release -p photon-coordinator --example farm_bench`
//! (the worker binary is needed for the loopback processes). `-- --quick` runs fewer, smaller cases.

#![allow(clippy::expect_used)] // a benchmark: a failure should stop it loudly

use photon_coordinator::farm::scheduler::{Policy, Scheduler, WorkerId};
use photon_coordinator::farm::{self, Options};
use photon_coordinator::fleet::session;
use photon_coordinator::fleet::{InProcess, LocalWorkers};
use photon_coordinator::job::Job;
use photon_coordinator::model::{Network, SimJob, SimWorker, simulate};
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::scene::Scene;
use std::path::Path;
use std::time::{Duration, Instant};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn job_of(prep: &Prepared) -> Job {
    Job::new(
        prep.encode_scene().expect("scene"),
        prep.encode_photons().expect("photons"),
        prep.encode_textures().expect("textures"),
        prep.encode_frame().expect("frame"),
        (prep.camera.width, prep.camera.height),
        &prep.settings,
    )
}

fn cornell(size: u32, spp: u32, integrator: Method, photons: u32) -> (Scene, std::path::PathBuf) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).expect("cornell.toml");
    scene.camera.width = size;
    scene.camera.height = size;
    scene.render.spp = spp;
    scene.render.integrator = integrator;
    scene.render.photons.global = photons;
    (scene, path)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let cores = rayon::current_num_threads();
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime");
    println!("farm_bench: {cores} threads, {}", if quick { "quick" } else { "full" });
    if args.iter().any(|a| a == "--model") {
        model();
        return;
    }
    if args.iter().any(|a| a == "--scaling") {
        let max = args
            .iter()
            .position(|a| a == "--max-workers")
            .and_then(|i| args.get(i + 1))
            .map_or(cores, |n| n.parse().expect("--max-workers N"));
        scaling(&rt, quick, cores, max);
        return;
    }

    // 1. Overhead of the farm against the direct render.
    let (size, spp, runs) = if quick { (96, 8, 3) } else { (256, 32, 5) };
    let (scene, path) = cornell(size, spp, Method::Path, 0);
    let prep = Prepared::new(&scene, &path).and_then(|p| p.with_photon_maps(&path)).expect("prepare");
    let job = job_of(&prep);
    let (mut direct, mut inproc, mut two) = (Vec::new(), Vec::new(), Vec::new());
    let local = rt.block_on(LocalWorkers::start(2, cores, None)).expect("start two loopback workers");
    for _ in 0..runs {
        let t = Instant::now();
        let strip = photon_core::render::render_image(&prep, &|_| {});
        direct.push(t.elapsed().as_secs_f64());
        let want: Vec<u32> = strip.pixels.iter().map(|v| v.to_bits()).collect();

        let t = Instant::now();
        let out = rt.block_on(async {
            let w = InProcess::start(None).await.expect("in-process worker");
            farm::render(&job, std::slice::from_ref(&w.addr), Options::default()).await
        });
        inproc.push(t.elapsed().as_secs_f64());
        let got: Vec<u32> = out.expect("in-process render").pixels.iter().map(|v| v.to_bits()).collect();
        assert!(got == want, "the in-process farm changed pixels");

        let t = Instant::now();
        let out = rt.block_on(farm::render(&job, &local.addrs, Options::default()));
        two.push(t.elapsed().as_secs_f64());
        let got: Vec<u32> = out.expect("two-worker render").pixels.iter().map(|v| v.to_bits()).collect();
        assert!(got == want, "two workers changed pixels");
    }
    rt.block_on(local.stop());
    let d = median(direct);
    println!("\n## Overhead: Cornell {size}x{size}, {spp} spp, path, medians of {runs} interleaved runs");
    println!("| how | median s | vs direct |");
    println!("|---|---|---|");
    println!("| direct (core renderer, no farm) | {d:.3} | — |");
    for (name, v) in [("in-process worker (default)", inproc), ("2 loopback worker processes", two)] {
        let m = median(v);
        println!("| {name} | {m:.3} | {:+.1} % |", 100.0 * (m / d - 1.0));
    }

    // 2. Shipping photon maps.
    println!("\n## Shipping photon maps to a fresh loopback worker (photon-map method, Cornell)");
    println!("| photon paths | stored photons | blob MiB | B/photon | ship s | s per million photons | MB/s |");
    println!("|---|---|---|---|---|---|---|");
    let counts: &[u32] = if quick { &[100_000] } else { &[250_000, 1_000_000] };
    let mut last_blob = Vec::new();
    for &n in counts {
        let (scene, path) = cornell(8, 1, Method::PhotonMap, n);
        let prep = Prepared::new(&scene, &path).and_then(|p| p.with_photon_maps(&path)).expect("prepare");
        let stored = prep.photons.as_ref().map_or(0, |p| p.global.len());
        let job = job_of(&prep);
        let bytes = job.blob_bytes();
        let mut times = Vec::new();
        for _ in 0..3 {
            let secs = rt.block_on(async {
                let w = InProcess::start(Some(1)).await.expect("worker");
                let mut c = session::connect(&w.addr.uri, None, None, Duration::from_secs(3)).await.expect("connect");
                let t = Instant::now();
                let (_, delivered) = session::introduce(&mut c, &job, &w.addr.uri).await.expect("ship");
                assert_eq!(delivered.shipped, bytes);
                t.elapsed().as_secs_f64()
            });
            times.push(secs);
        }
        let s = median(times);
        println!(
            "| {n} | {stored} | {:.1} | {:.1} | {s:.3} | {:.3} | {:.0} |",
            bytes as f64 / 1048576.0,
            bytes as f64 / stored.max(1) as f64,
            s / (stored as f64 / 1e6),
            bytes as f64 / s / 1e6
        );
        last_blob = job.blobs.values().max_by_key(|b| b.len()).map(|b| b.to_vec()).unwrap_or_default();
    }
    compression(&last_blob);

    // 3. Strips per second.
    let n = if quick { 20_000 } else { 200_000 };
    let mut sched = Scheduler::new(n, 1);
    for w in 0..8 {
        sched.add_worker(WorkerId(w), 4);
    }
    let t = Instant::now();
    let mut now = Duration::ZERO;
    while !sched.is_done() {
        for w in 0..8 {
            now += Duration::from_micros(1);
            if let Some(a) = sched.assign(WorkerId(w), now) {
                sched.complete(WorkerId(w), a.strip, a.attempt, now);
            }
        }
    }
    let pure = f64::from(n) / t.elapsed().as_secs_f64();
    let rows = if quick { 500 } else { 2000 };
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    let mut scene = Scene::load(&path).expect("cornell");
    scene.camera.width = 1;
    scene.camera.height = rows;
    scene.render.spp = 1;
    scene.render.integrator = Method::Path;
    let prep = Prepared::new(&scene, &path).and_then(|p| p.with_photon_maps(&path)).expect("prepare");
    let job = job_of(&prep);
    let mut rates = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        rt.block_on(async {
            let w = InProcess::start(None).await.expect("worker");
            let opts = Options { rows_per_strip: Some(1), ..Options::default() };
            farm::render(&job, std::slice::from_ref(&w.addr), opts).await.expect("render")
        });
        rates.push(f64::from(rows) / t.elapsed().as_secs_f64());
    }
    println!("\n## Strips per second");
    println!("| what | strips/s |");
    println!("|---|---|");
    println!("| scheduler state machine alone (8 workers, {n} strips, assign + complete) | {pure:.0} |");
    println!(
        "| whole farm, in-process worker, {rows} one-pixel strips (gRPC, validation, assembly), median of 3 | {:.0} |",
        median(rates)
    );
}

/// Would LZ4 pay? Compress and decompress the blob, and compare shipping times on loopback (measured rate) and
/// on a 1 Gbit/s link (125 MB/s) with and without it.
fn compression(blob: &[u8]) {
    if blob.is_empty() {
        return;
    }
    let t = Instant::now();
    let packed = lz4_flex::compress_prepend_size(blob);
    let c = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let back = lz4_flex::decompress_size_prepended(&packed).expect("lz4 round trip");
    let d = t.elapsed().as_secs_f64();
    assert_eq!(back, blob);
    let ratio = blob.len() as f64 / packed.len() as f64;
    let link = 125e6;
    let raw = blob.len() as f64 / link;
    let with = c + packed.len() as f64 / link + d;
    println!(
        "\nLZ4 on the largest blob ({:.1} MiB): ratio {ratio:.2}, compress {:.0} MB/s, decompress {:.0} MB/s; \
         at 1 Gbit/s: {raw:.3} s raw vs {with:.3} s compressed ({:+.0} %)",
        blob.len() as f64 / 1048576.0,
        blob.len() as f64 / c / 1e6,
        blob.len() as f64 / d / 1e6,
        100.0 * (with / raw - 1.0)
    );
}

/// The scaling table: per method, in-process on all cores, then 1, 2, 4, …, `max` one-thread loopback workers.
fn scaling(rt: &tokio::runtime::Runtime, quick: bool, cores: usize, max: usize) {
    let size = if quick { 64 } else { 128 };
    let jobs: [(Method, u32, u32, u32); 4] = [
        (Method::Path, 16, 0, 1),
        (Method::PhotonMap, 8, 200_000, 1),
        (Method::FinalGather, 2, 50_000, 1),
        (Method::Progressive, 1, 20_000, 64),
    ];
    let mut counts = vec![1usize];
    while counts.last().is_some_and(|&n| n * 2 <= max) {
        counts.push(counts.last().map_or(1, |n| n * 2));
    }
    if counts.last() != Some(&max) {
        counts.push(max);
    }
    println!(
        "\n## Scaling: Cornell {size}x{size}, medians of 3; workers of 1 thread each; in-process on {cores} threads"
    );
    println!("| method | farm | s | speed-up over 1 worker | efficiency |");
    println!("|---|---|---:|---:|---:|");
    for (integrator, spp, photons, passes) in jobs {
        let (mut scene, path) = cornell(size, spp, integrator, photons);
        scene.render.photons.pass_photons = photons;
        scene.render.photons.passes = passes;
        let t = Instant::now();
        let prep = Prepared::new(&scene, &path).and_then(|p| p.with_photon_maps(&path)).expect("prepare");
        let prepare_s = t.elapsed().as_secs_f64();
        let job = job_of(&prep);
        let time = |addrs: &[session::WorkerAddr]| -> (f64, Vec<u32>) {
            let mut times = Vec::new();
            let mut bits = Vec::new();
            for _ in 0..3 {
                let t = Instant::now();
                let out = rt.block_on(farm::render(&job, addrs, Options::default())).expect("render");
                times.push(t.elapsed().as_secs_f64());
                bits = out.pixels.iter().map(|v| v.to_bits()).collect();
            }
            (median(times), bits)
        };
        let inproc = rt.block_on(InProcess::start(None)).expect("in-process worker");
        let (t_in, want) = time(std::slice::from_ref(&inproc.addr));
        drop(inproc);
        println!("| {integrator} | in-process, {cores} threads (prepare {prepare_s:.2} s) | {t_in:.3} | | |");
        let mut t1 = None;
        for &n in &counts {
            let local = rt.block_on(LocalWorkers::start(n, n, None)).expect("loopback workers");
            let (t, got) = time(&local.addrs);
            rt.block_on(local.stop());
            assert!(got == want, "{integrator}: {n} workers changed pixels");
            let base = *t1.get_or_insert(t);
            let speedup = base / t;
            println!(
                "| {integrator} | {n} worker{} | {t:.3} | {speedup:.2} | {:.0} % |",
                if n == 1 { "" } else { "s" },
                100.0 * speedup / n as f64
            );
        }
    }
}

/// The origin's lab: 20 six-core and 30 four-core x86-64 machines, one 32-core and one 96-core ARM machine
/// (368 cores). Core speeds relative to this machine's core are assumptions, stated in RESULTS.
fn lab() -> Vec<SimWorker> {
    let mut ws = Vec::new();
    ws.extend((0..20).map(|_| SimWorker { cores: 6, core_speed: 1.0, dies_at: None }));
    ws.extend((0..30).map(|_| SimWorker { cores: 4, core_speed: 0.8, dies_at: None }));
    ws.push(SimWorker { cores: 32, core_speed: 1.0, dies_at: None });
    ws.push(SimWorker { cores: 96, core_speed: 0.6, dies_at: None });
    ws
}

/// Seconds of `f` on one thread.
fn one_thread<R: Send>(f: impl FnOnce() -> R + Send) -> (f64, R) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("one-thread pool");
    let t = Instant::now();
    let r = pool.install(f);
    (t.elapsed().as_secs_f64(), r)
}

/// The lab model: costs measured here, jobs of about 10 minutes on the lab, each method with and without deaths.
fn model() {
    let (width, height) = (1920u32, 1080u32);
    let lab = lab();
    let lab_speed: f64 = lab.iter().map(|w| f64::from(w.cores) * w.core_speed).sum();
    let target_s = 600.0;
    let net = Network::gigabit();
    println!(
        "\n## The modelled lab: {} machines, {} cores, 1 Gbit/s links; Cornell {width}x{height}",
        lab.len(),
        lab.iter().map(|w| w.cores).sum::<u32>()
    );
    println!(
        "| method | job | units | per unit | strips | makespan s | ideal s | efficiency | prepare s | ship s | tail s | speculative | with 2 deaths: makespan s, efficiency |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    let methods: [(Method, u32); 4] = [
        (Method::Path, 0),
        (Method::PhotonMap, 1_000_000),
        (Method::FinalGather, 200_000),
        (Method::Progressive, 100_000),
    ];
    for (integrator, photons) in methods {
        let (mut scene, path) = cornell(width, 1, integrator, photons.max(1));
        scene.camera.height = height;
        scene.render.photons.pass_photons = photons.max(1);
        scene.render.photons.passes = 2;
        let t = Instant::now();
        let scene_only = Prepared::new(&scene, &path).expect("prepare");
        let scene_prepare_s = t.elapsed().as_secs_f64();
        let prep = scene_only.clone().with_photon_maps(&path).expect("photon maps");
        let prepare_s = t.elapsed().as_secs_f64();
        let job = job_of(&prep);
        let photons_blob = job.photons_blob.as_ref().and_then(|id| job.blobs.get(id)).map(|b| b.as_slice());
        let decode = |photons| {
            let textures: Vec<&[u8]> = job.texture_blobs.iter().map(|id| job.blobs[id].as_slice()).collect();
            Prepared::from_blobs(&job.blobs[&job.scene_blob], photons, &job.frame, &textures, usize::MAX)
                .expect("decode")
        };
        let (load_core_s, _) = one_thread(|| decode(photons_blob));
        // How the workers get the maps: shipped (the coordinator traces them while preparing), passed on among
        // the workers (`--photon-maps peers`), or traced by each worker while loading (only the scene blob ships;
        // `--photon-maps trace`).
        let mut deliveries = vec![("", job.blob_bytes() as f64, prepare_s, load_core_s, false)];
        if integrator.needs_photon_maps() {
            let (traced_load_s, _) =
                one_thread(|| decode(None).build_photon_maps(&photon_core::run::Guard::unbounded()).expect("maps"));
            let scene_bytes = job.blobs[&job.scene_blob].len() as f64;
            deliveries[0].0 = ", maps shipped";
            deliveries.push((", maps among peers", job.blob_bytes() as f64, prepare_s, load_core_s, true));
            deliveries.push((", maps traced by workers", scene_bytes, scene_prepare_s, traced_load_s, false));
        }
        let rows = 8u32;
        let (units, core_s_per_unit, fixed, per_unit, label) = if integrator.renders_passes() {
            // Two passes over 8 rows: the photon (light path) part is per pass, the gather part per row.
            let (t, block) = one_thread(|| {
                let block = photon_core::render::Block { rows: 0..rows, units: 0..2 };
                photon_core::render::render_block(&prep, &block, &|_| {}, &photon_core::run::Guard::unbounded())
                    .expect("passes")
            });
            let photon_part = block.photon_seconds / 2.0;
            let per_pass = photon_part + (t - block.photon_seconds) / 2.0 / f64::from(rows) * f64::from(height);
            let passes = (target_s * lab_speed / per_pass).round() as u32;
            let label = if integrator == Method::Progressive {
                format!("{passes} passes of {photons} paths")
            } else {
                format!("{passes} passes")
            };
            (passes, per_pass, 24.0 * f64::from(width) * f64::from(height), 0.0, label)
        } else {
            let (t, _) = one_thread(|| photon_core::render::render_rows(&prep, 0..rows, &|_| {}));
            let per_row_spp = t / f64::from(rows);
            let spp = (target_s * lab_speed / (per_row_spp * f64::from(height))).round().max(1.0);
            // A strip's sums: 3 × i64 per pixel.
            (height, per_row_spp * spp, 0.0, 24.0 * f64::from(width), format!("{spp} spp"))
        };
        let cuts: Vec<u32> = if integrator.renders_passes() {
            let default = photon_coordinator::farm::scheduler::passes_per_block_for(units, lab.len() as u32);
            // The default, and other cuts for comparison (more blocks: a shorter tail, more bytes to send back).
            let per_worker = |k: u32| units.div_ceil(lab.len() as u32 * k);
            vec![default, per_worker(4), per_worker(8), per_worker(32)]
        } else {
            vec![photon_coordinator::farm::scheduler::rows_per_strip_for(height, lab.len() as u32)]
        };
        let runs = cuts.iter().flat_map(|&c| deliveries.iter().map(move |&d| (c, d)));
        for (per_strip, (delivery, blob_bytes, prepare_s, load_core_s, relay)) in runs {
            let sim = SimJob {
                units,
                units_per_strip: per_strip,
                core_s_per_unit,
                result_bytes_fixed: fixed,
                result_bytes_per_unit: per_unit,
                blob_bytes,
                prepare_s,
                load_core_s,
                thread_efficiency: 1.0,
                relay,
            };
            let r = simulate(&sim, &lab, &net, Policy::default());
            let mut dying = lab.clone();
            dying[0].dies_at = Some(0.3 * r.makespan_s);
            dying[51].dies_at = Some(0.5 * r.makespan_s);
            let d = simulate(&sim, &dying, &net, Policy::default());
            assert!(r.complete && d.complete, "{integrator}: the model did not finish");
            println!(
                "| {integrator}{delivery} | {label} | {units} | {core_s_per_unit:.3} core-s | {} | {:.1} | {:.1} | {:.1} % | {:.2} | {:.2} | {:.1} | {} | {:.1}, {:.1} % |",
                units.div_ceil(per_strip),
                r.makespan_s,
                r.ideal_s,
                100.0 * r.efficiency,
                r.prepare_s,
                r.ship_s,
                r.tail_s,
                r.speculative,
                d.makespan_s,
                100.0 * d.efficiency
            );
        }
    }
}
