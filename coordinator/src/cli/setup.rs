//! What `render` sets up and finishes, whichever way the method is chosen (named, or `auto`): the runtime, the
//! scene with its overrides, the memory check, the prepared-blob cache, the live page, the output file.

use crate::cli::RenderArgs;
use crate::cli::overrides::{self, Setting};
use crate::fleet::interrupt::Interrupts;
use crate::job::Job;
use crate::job::partial_path;
use crate::job::prepared_cache::PreparedCache;
use crate::out::live::{self, Board, LiveServer};
use anyhow::{Context, Result, bail};
use photon_core::image_io::Image;
use photon_core::method::Method;
use photon_core::prepare::gltf::direct::load_scene;
use photon_core::scene::Scene;
use std::sync::Arc;
use std::time::Instant;

/// The async runtime of the farm: two threads are plenty for the network; rendering runs on rayon.
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// Shapes a prepared job for how it renders: whole-image blocks of passes or samples, in rounds, when `bounded`
/// by time or error; a swarm when the photon maps pass among `peers` (with the farm's TLS authority).
pub(crate) fn shape_job(job: &mut Job, bounded: bool, peers: bool, tls_ca: &Option<Vec<u8>>) {
    if bounded {
        job.passes = Some(crate::farm::bounded::MAX_PASSES);
    }
    if peers {
        job.swarm = Some(std::sync::Arc::new(crate::fleet::swarm::Swarm::new(tls_ca.clone())));
    }
}

/// The prepared-blob cache of `render`, unless `--no-cache` or no folder for it.
pub(crate) fn open_cache(args: &RenderArgs) -> Result<Option<PreparedCache>> {
    Ok(match (args.no_cache, args.cache_dir.clone().or_else(PreparedCache::default_dir)) {
        (false, Some(dir)) => Some(PreparedCache::open(dir, args.cache_mib << 20)?),
        _ => None,
    })
}

/// Writes the finished image, and removes the output's partial file when this render wrote checkpoints there
/// or was resumed from it; the seconds it took.
pub(crate) fn write_output(args: &RenderArgs, image: &Image, exposure: f32, checkpointed: bool) -> Result<f64> {
    let t = Instant::now();
    image.write(&args.output, exposure)?;
    let partial = partial_path(&args.output);
    if checkpointed || args.resume.as_deref() == Some(partial.as_path()) {
        let _ = std::fs::remove_file(&partial);
    }
    Ok(t.elapsed().as_secs_f64())
}

/// Serves the live page on `addr` (`render --serve`), warning when anyone who reaches it may look.
pub(crate) fn serve_live(
    rt: &tokio::runtime::Runtime,
    addr: std::net::SocketAddr,
    exposure: f32,
    token: Option<&str>,
) -> Result<(Arc<Board>, LiveServer)> {
    let board = Arc::new(Board::new(exposure));
    let server = rt.block_on(live::serve(addr, board.clone(), token))?;
    eprintln!("live page: http://{}/", server.addr());
    if !server.addr().ip().is_loopback() && token.is_none() {
        eprintln!(
            "warning: the live page is served on {} without a farm token: anyone who can reach it sees the \
             image and the workers (give --token-file to require one)",
            server.addr()
        );
    }
    Ok((board, server))
}

/// Stops the live page once the render is over; with `--serve-after`, first serves its final state until a
/// signal.
pub(crate) async fn stop_live(server: LiveServer, serve_after: bool, interrupts: &mut Interrupts) {
    if serve_after {
        eprintln!("live page: the render is over; serving its final state at http://{}/ until Ctrl-C", server.addr());
        crate::fleet::interrupt::interrupted(Some(interrupts)).await;
    }
    server.stop().await;
}

/// Refuses a job whose image, photon maps and strips would not fit this machine's memory, before any of it is
/// allocated; the error names the setting and what would fit. The strips count as rendered here, by the
/// in-process workers of a render without hosts (the most a render allocates on this machine).
pub(crate) fn fits_in_memory(scene: &Scene, rows_per_strip: Option<u32>, bounded: bool) -> Result<()> {
    let Some(budget) = photon_core::prepare::budget::machine_memory() else { return Ok(()) };
    let (c, r) = (&scene.camera, &scene.render);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    // The methods that render in passes (progressive, vcm, bdpt, lt) render whole-image pass blocks;
    // `--rows-per-strip` is then passes per block. So does a render bounded by time or error, in blocks of samples.
    let rows = if bounded || r.integrator.renders_passes() {
        c.height
    } else {
        rows_per_strip.unwrap_or_else(|| crate::farm::scheduler::rows_per_strip_for(c.height, 1))
    };
    let estimate = photon_core::prepare::budget::MemoryEstimate::job(c.width, c.height, rows, r, threads);
    tracing::info!(bytes = estimate.total(), budget, "memory estimate");
    estimate.check(budget, c.width, c.height, r).context("the job does not fit this machine's memory")?;
    Ok(())
}

/// The scene of `render`: the file, its `--set` pairs, then the flags that override settings as more pairs.
/// For `auto`, the method is set to `path` until the pilot chooses (the file may say `"auto"`, which names no
/// method).
pub(crate) fn render_scene(args: &RenderArgs, auto: bool) -> Result<Scene> {
    let mut settings = args.settings()?;
    if auto {
        settings.push(Setting::Integrator(Method::Path));
    }
    Ok(load_scene(&args.scene, &overrides::pairs(&args.set, &settings))?)
}

/// The bound of `--time` and `--target-error`, if either is given, with the scene set up for it: its samples per
/// pixel (or passes, for progressive, vcm, bdpt and lt) become the most a bounded render takes, the range its
/// blocks are numbered in.
/// Refuses `--target-error` for the methods whose error no number of samples lowers, and `--spp`/`--passes`.
pub(crate) fn bound(args: &RenderArgs, scene: &mut Scene, t0: Instant) -> Result<Option<crate::farm::bounded::Bound>> {
    if args.time.is_none() && args.target_error.is_none() {
        return Ok(None);
    }
    let r = &mut scene.render;
    let in_passes = r.integrator.renders_passes();
    if args.spp.is_some() || args.passes.is_some() {
        bail!("--spp and --passes fix the samples; --time and --target-error choose them: give one or the other");
    }
    if args.target_error.is_some() && !r.integrator.error_falls_with_units() {
        bail!(
            "--target-error needs an error that more samples lower; `{}` keeps the bias of its photon maps \
             (their count is fixed before the render): use `progressive`, `vcm` or `path`, or bound it with --time",
            r.integrator
        );
    }
    if in_passes {
        r.photons.passes = crate::farm::bounded::MAX_PASSES;
    } else {
        r.spp = crate::farm::bounded::MAX_PASSES;
    }
    Ok(Some(crate::farm::bounded::Bound {
        deadline: args.time.map(|t| t0 + t),
        target_error: args.target_error,
        // The gather (merge) radius of progressive photon mapping and vcm shrinks with α; bdpt and lt are unbiased.
        bias_alpha: r.integrator.bias_alpha(r.photons.alpha),
        passes: None,
        // The methods whose error more samples lower estimate it after every round, for the summary and the
        // live page, whether or not a target stops them.
        estimate: r.integrator.error_falls_with_units(),
    }))
}
