//! `photon-coordinator`: the photon command line.
#![forbid(unsafe_code)]

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use photon_coordinator::prepared_cache::{self, PreparedCache};
use photon_coordinator::sweep::{self, sig};
use photon_coordinator::{farm, fleet};
use photon_core::image_io::{Format, Image};
use photon_core::metrics::{self, Metrics, Region};
use photon_core::prepare::Prepared;
use photon_core::scene::{Integrator, Scene};
use std::path::PathBuf;
use std::time::Instant;

/// A distributed photon-mapping renderer.
#[derive(Parser, Debug)]
#[command(name = "photon-coordinator", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene file to an image.
    Render(RenderArgs),
    /// Measure an image's error against a reference (RMSE, relative MSE, relative error, bias).
    Compare(CompareArgs),
    /// Render a reference EXR: the path tracer at many samples, or progressive photon mapping at many passes
    /// when the scene has point-light caustics. Renders on workers like `render` (in-process by default).
    Reference(ReferenceArgs),
    /// Render with several methods at growing budgets, measure each image against a reference, and write
    /// sweep.csv, sweep.svg and sweep.png with equal-time and equal-error tables. Renders run one after another
    /// on workers like `render` (in-process by default; `--workers`, `--hosts` or `--local` for others).
    Sweep(SweepArgs),
}

#[derive(clap::Args, Debug)]
struct RenderArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// Output image; the format comes from the extension: .png, .exr (linear), .ppm or .bmp.
    #[arg(short, long, default_value = "out.png")]
    output: PathBuf,
    /// Samples per pixel (overrides the scene's `render.spp`).
    #[arg(long)]
    spp: Option<u32>,
    /// Method: `path`, `direct`, `photon-map`, `final-gather` or `progressive` (overrides `render.integrator`).
    #[arg(long)]
    integrator: Option<Integrator>,
    /// Seed (overrides the scene's `render.seed`).
    #[arg(long)]
    seed: Option<u64>,
    /// Image width and height in pixels, e.g. `256x256` (overrides the scene's camera).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Photon paths per map, or per progressive pass (overrides `render.photons.global`, `.caustic` and
    /// `.pass_photons`).
    #[arg(long)]
    photons: Option<u32>,
    /// Progressive photon-mapping passes (overrides `render.photons.passes`).
    #[arg(long)]
    passes: Option<u32>,
    /// Exposure in stops for 8-bit outputs (overrides the scene's `render.exposure`).
    #[arg(long)]
    exposure: Option<f32>,
    /// Override a scene setting, e.g. `--set render.photons.kernel=box` or `--set camera.fov=30`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
    #[command(flatten)]
    farm: FarmArgs,
    /// Continue an interrupted render from the partial file it left (`OUTPUT.partial`).
    #[arg(long, value_name = "FILE")]
    resume: Option<PathBuf>,
    /// Rows per strip (default: about 16 strips per worker, at most 64 rows).
    #[arg(long, value_name = "N")]
    rows_per_strip: Option<u32>,
    /// Folder of prepared blobs reused by later renders of an unchanged scene (default: $PHOTON_CACHE_DIR, else
    /// $XDG_CACHE_HOME/photon, else ~/.cache/photon).
    #[arg(long, value_name = "DIR")]
    cache_dir: Option<PathBuf>,
    /// Size cap of the prepared-blob cache in MiB (oldest entries out first).
    #[arg(long, value_name = "MIB", default_value_t = 4096)]
    cache_mib: u64,
    /// Neither read nor write the prepared-blob cache.
    #[arg(long, conflicts_with = "cache_dir")]
    no_cache: bool,
}

/// Where to render: with none of `--hosts`, `--workers` or `--local`, on a worker inside this process.
#[derive(clap::Args, Debug, Clone)]
struct FarmArgs {
    /// Render on the workers of a host list (TOML: `[[worker]]` tables with `address` and an optional `name`).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["workers", "local"])]
    hosts: Option<PathBuf>,
    /// Render on these workers, e.g. `lab-01:7878,lab-02:7878`; `dns:NAME:PORT` is every address NAME resolves
    /// to (a Kubernetes headless Service: one per ready worker pod).
    #[arg(long, value_name = "HOST:PORT,...", conflicts_with = "local")]
    workers: Option<String>,
    /// Start N `photon-worker` processes on loopback (sharing this machine's cores) and render on them.
    #[arg(long, value_name = "N")]
    local: Option<usize>,
    /// A file holding the shared token the workers require.
    #[arg(long, value_name = "FILE")]
    token_file: Option<PathBuf>,
    /// Speak TLS to the workers, trusting only this PEM certificate authority (see deploy/tls/make-certs.sh).
    #[arg(long, value_name = "FILE")]
    tls_ca: Option<PathBuf>,
    /// Threads on this machine, for preparing and for in-process or --local workers (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

/// What the farm flags resolve to.
struct Resolved {
    spec: fleet::FleetSpec,
    token: Option<String>,
    tls_ca: Option<Vec<u8>>,
}

impl FarmArgs {
    /// Checks the flags, sizes the thread pool and says which workers to use, which token to send and which
    /// authority to trust.
    fn resolve(&self) -> Result<Resolved> {
        if let Some(t) = self.threads {
            if t == 0 {
                bail!("--threads must be at least 1");
            }
            rayon::ThreadPoolBuilder::new().num_threads(t).build_global().context("starting the thread pool")?;
        }
        if self.local == Some(0) {
            bail!("--local must be at least 1");
        }
        let (spec, hosts_token, hosts_ca) = match (&self.hosts, &self.workers, self.local) {
            (Some(path), _, _) => {
                let h = fleet::read_hosts(path).map_err(anyhow::Error::msg)?;
                (fleet::FleetSpec::Remote(h.workers), h.token_file, h.tls_ca)
            }
            (None, Some(list), _) => {
                (fleet::FleetSpec::Remote(fleet::parse_workers(list).map_err(anyhow::Error::msg)?), None, None)
            }
            (None, None, Some(n)) => {
                let threads = self.threads.unwrap_or_else(rayon::current_num_threads);
                (fleet::FleetSpec::Local { n, threads, token_file: self.token_file.clone() }, None, None)
            }
            (None, None, None) => (fleet::FleetSpec::InProcess(self.threads), None, None),
        };
        let token_file = self.token_file.clone().or(hosts_token);
        let token = token_file.as_deref().map(photon_proto::read_token).transpose().map_err(anyhow::Error::msg)?;
        let tls_ca = match self.tls_ca.clone().or(hosts_ca) {
            Some(p) => Some(std::fs::read(&p).with_context(|| format!("reading the TLS authority {}", p.display()))?),
            None => None,
        };
        Ok(Resolved { spec, token, tls_ca })
    }
}

/// The async runtime of the farm: two threads are plenty for the network; rendering runs on rayon.
fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
}

#[derive(clap::Args, Debug)]
struct CompareArgs {
    /// The image to measure: EXR for linear values (8-bit formats are decoded from sRGB).
    image: PathBuf,
    /// The reference image, the same size.
    reference: PathBuf,
    /// Measure the bias over the pixels `X0,Y0,X1,Y1`, X1 and Y1 exclusive (default: the whole image).
    #[arg(long, value_parser = parse_region, value_name = "X0,Y0,X1,Y1")]
    region: Option<Region>,
    /// Write a false-colour map of per-pixel relative error (0 dark, 1 or more bright), e.g. `err.png`.
    #[arg(long, value_name = "FILE")]
    error_image: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct ReferenceArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// Output image; must be .exr (linear values, for `compare` and `sweep`).
    #[arg(short, long)]
    output: PathBuf,
    /// Samples per pixel when the path tracer renders the reference.
    #[arg(long, default_value_t = 4096)]
    spp: u32,
    /// Passes when progressive photon mapping renders the reference.
    #[arg(long, default_value_t = 512)]
    passes: u32,
    /// Image width and height in pixels, e.g. `96x96` (overrides the scene's camera).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Seed of the reference; keep it different from the seed of the images it measures (the scene's
    /// `render.seed`, 1 by default), or their noise is correlated and the error looks smaller than it is.
    #[arg(long, default_value_t = 0x5EED)]
    seed: u64,
    /// Override a scene setting, e.g. `--set render.photons.pass_photons=50000`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    farm: FarmArgs,
}

#[derive(clap::Args, Debug)]
struct SweepArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// The reference image (EXR), e.g. from `photon-coordinator reference`.
    #[arg(long)]
    reference: PathBuf,
    /// Methods, comma-separated: `path`, `direct`, `photon-map`, `final-gather`, `progressive`.
    #[arg(long, value_delimiter = ',', default_value = "path,photon-map,final-gather,progressive")]
    methods: Vec<Integrator>,
    /// Budget multipliers b, comma-separated: path/direct render 4·b spp; photon-map traces 25 000·b global
    /// photons (k fixed, 2 spp); final-gather 25 000·b global and caustic photons (2 spp); progressive 4·b passes.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    budget: Vec<u32>,
    /// Image width and height, e.g. `96x96`; must match the reference (default: the reference's size).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Folder for sweep.csv, sweep.svg and sweep.png (created when missing).
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Override a scene setting for every render, e.g. `--set render.photons.pass_photons=20000`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    farm: FarmArgs,
}

fn parse_region(s: &str) -> Result<Region, String> {
    let v: Vec<u32> =
        s.split(',').map(|p| p.trim().parse::<u32>()).collect::<Result<_, _>>().map_err(|_| {
            format!("expected X0,Y0,X1,Y1 (four non-negative integers, X1 and Y1 exclusive), found `{s}`")
        })?;
    match v[..] {
        [x0, y0, x1, y1] if x0 < x1 && y0 < y1 => Ok(Region { x0, y0, x1, y1 }),
        [_, _, _, _] => Err(format!("expected X0 < X1 and Y0 < Y1 (X1 and Y1 exclusive), found `{s}`")),
        _ => Err(format!("expected four numbers X0,Y0,X1,Y1, found `{s}`")),
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once('x').ok_or_else(|| format!("expected WIDTHxHEIGHT, found `{s}`"))?;
    let p = |v: &str| v.parse::<u32>().ok().filter(|&n| (1..=65_536).contains(&n));
    match (p(w), p(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("expected WIDTHxHEIGHT with sizes in 1..=65536, found `{s}`")),
    }
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    // `photon-coordinator … | head` closes the pipe early: end quietly, as a SIGPIPE would, not with a panic.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg = payload.downcast_ref::<String>().map(String::as_str).or(payload.downcast_ref::<&str>().copied());
        if msg.is_some_and(|m| m.starts_with("failed printing to stdout")) {
            std::process::exit(141);
        }
        default_hook(info);
    }));
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render(args),
        Command::Compare(args) => compare(args),
        Command::Reference(args) => reference(args),
        Command::Sweep(args) => sweep(args),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn render(args: RenderArgs) -> Result<()> {
    Format::from_path(&args.output)?;
    if args.rows_per_strip == Some(0) {
        bail!("--rows-per-strip must be at least 1");
    }
    let Resolved { spec, token, tls_ca } = args.farm.resolve()?;
    let t0 = Instant::now();
    let mut scene = Scene::load_with(&args.scene, &args.set)?;
    if let Some((w, h)) = args.size {
        scene.camera.width = w;
        scene.camera.height = h;
    }
    let s = &mut scene.render;
    if let Some(spp) = args.spp {
        if spp == 0 {
            bail!("--spp must be at least 1");
        }
        s.spp = spp;
    }
    if let Some(i) = args.integrator {
        s.integrator = i;
    }
    if let Some(seed) = args.seed {
        s.seed = seed;
    }
    if let Some(e) = args.exposure {
        s.exposure = e;
    }
    if let Some(n) = args.photons {
        if n == 0 {
            bail!("--photons must be at least 1");
        }
        s.photons.global = n;
        s.photons.caustic = n;
        s.photons.pass_photons = n;
    }
    if let Some(p) = args.passes {
        if p == 0 {
            bail!("--passes must be at least 1");
        }
        s.photons.passes = p;
    }
    let resume = match &args.resume {
        Some(path) => {
            let bytes = std::fs::read(path).with_context(|| format!("reading the partial file {}", path.display()))?;
            let p: farm::Partial = photon_core::codec::decode(&bytes, bytes.len())
                .with_context(|| format!("{} is not a partial render", path.display()))?;
            Some(p)
        }
        None => None,
    };

    let cache = match (args.no_cache, args.cache_dir.clone().or_else(PreparedCache::default_dir)) {
        (false, Some(dir)) => Some(PreparedCache::open(dir, args.cache_mib << 20).map_err(anyhow::Error::msg)?),
        _ => None,
    };
    let (job, hits) = prepare_job(&scene, &args.scene, cache.as_ref())?;
    let (width, height) = (job.width, job.height);
    let settings = scene.render.clone();
    let prepare_s = t0.elapsed().as_secs_f64();
    tracing::info!(blob_bytes = job.blob_bytes(), prepare_s, "prepared");

    let options = farm::Options {
        token,
        tls_ca,
        rows_per_strip: args.rows_per_strip,
        policy: Default::default(),
        resume,
        progress: !args.quiet,
    };
    let outcome = runtime()?.block_on(async {
        let fleet = fleet::Fleet::start(&spec).await.map_err(anyhow::Error::msg)?;
        let outcome = farm::render(&job, &fleet.addrs, options).await;
        let in_process = fleet.is_in_process();
        fleet.stop().await;
        anyhow::Ok((outcome, in_process))
    })?;
    let (outcome, in_process) = outcome;
    let outcome = match outcome {
        Ok(o) => o,
        Err(e) => {
            if let Some(partial) = e.partial() {
                let path = partial_path(&args.output);
                let done = partial.strips.len();
                let bytes = photon_core::codec::encode(partial).context("encoding the partial render")?;
                std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
                if let farm::FarmError::NoWorkers { workers, .. } | farm::FarmError::Fatal { workers, .. } = &e {
                    print_workers(workers);
                }
                bail!(
                    "{e}\n{done} finished strips are in {}; continue with the same command and `--resume {}`",
                    path.display(),
                    path.display()
                );
            }
            return Err(e.into());
        }
    };
    let t_assemble = Instant::now();
    let image = Image { width, height, pixels: outcome.pixels };
    image.write(&args.output, settings.exposure)?;
    if let Some(p) = &args.resume
        && *p == partial_path(&args.output)
    {
        let _ = std::fs::remove_file(p);
    }
    let assemble_s = t_assemble.elapsed().as_secs_f64();
    if !in_process {
        print_workers(&outcome.workers);
    }
    // Progressive photon mapping takes one camera sample per pass; the others take `spp`.
    let samples = if settings.integrator == Integrator::Progressive {
        format!("{} passes of {} photon paths", settings.photons.passes, settings.photons.pass_photons)
    } else {
        format!("{} spp", settings.spp)
    };
    let mut extras = if outcome.resumed > 0 { format!(", {} strips resumed", outcome.resumed) } else { String::new() };
    if let Some(h) = hits {
        let word = |hit: bool| if hit { "cached" } else { "built" };
        extras.push_str(&format!(", scene {}", word(h.scene)));
        if settings.integrator.needs_photon_maps() {
            extras.push_str(&format!(", photons {}", word(h.photons)));
        }
    }
    println!(
        "{}: {width}x{height}, {samples}, {}, {:.2} s render (+{:.2} s prepare, {:.2} s ship, {:.2} s assemble), \
         {:.2} Mrays/s, {} blob bytes shipped{extras}",
        args.output.display(),
        settings.integrator,
        outcome.render_s,
        prepare_s,
        outcome.ship_s,
        assemble_s,
        outcome.rays as f64 / outcome.render_s.max(1e-9) / 1e6,
        outcome.workers.iter().map(|w| w.shipped_bytes).sum::<u64>()
    );
    Ok(())
}

/// Prepares a scene into a job, through the prepared-blob cache when there is one: the scene blob (meshes, BVH,
/// materials, lights) and the photons blob are each read from the cache or built and stored.
fn prepare_job(
    scene: &Scene,
    scene_path: &std::path::Path,
    cache: Option<&PreparedCache>,
) -> Result<(farm::Job, Option<prepared_cache::Hits>)> {
    let camera = photon_core::camera::Camera::new(&scene.camera);
    let settings = scene.render.clone();
    let frame = Prepared::encode_frame_of(&camera, &settings).context("encoding the frame")?;
    let (width, height) = (camera.width, camera.height);
    let Some(cache) = cache else {
        let prep = Prepared::new(scene, scene_path)?.with_photon_maps(scene_path)?;
        let scene_blob = prep.encode_scene().context("encoding the scene")?;
        let photons = prep.encode_photons().context("encoding the photon maps")?;
        return Ok((farm::Job::new(scene_blob, photons, frame, (width, height), &settings), None));
    };
    let keys = PreparedCache::keys(scene).map_err(anyhow::Error::msg)?;
    let needs_photons = settings.integrator.needs_photon_maps();
    let cached_scene = cache.load(&keys.scene, "scene");
    let cached_photons = if needs_photons { cache.load(&keys.photons, "photons") } else { None };
    let hits = prepared_cache::Hits { scene: cached_scene.is_some(), photons: cached_photons.is_some() };
    // Build what is missing; decode the cached scene only when photons must be traced in it.
    let (scene_blob, prep) = match cached_scene {
        Some(bytes) => (bytes, None),
        None => {
            let prep = Prepared::new(scene, scene_path)?;
            let bytes = prep.encode_scene().context("encoding the scene")?;
            cache.store(&keys.scene, "scene", &bytes);
            (bytes, Some(prep))
        }
    };
    let photons = match (needs_photons, cached_photons) {
        (false, _) => None,
        (true, Some(bytes)) => Some(bytes),
        (true, None) => {
            let prep = match prep {
                Some(p) => p,
                None => Prepared::from_scene_blob(&scene_blob, camera, settings.clone(), usize::MAX)
                    .with_context(|| format!("decoding the cached scene in {}", cache.dir().display()))?,
            };
            let prep = prep.with_photon_maps(scene_path)?;
            let bytes = prep.encode_photons().context("encoding the photon maps")?;
            if let Some(b) = &bytes {
                cache.store(&keys.photons, "photons", b);
            }
            bytes
        }
    };
    Ok((farm::Job::new(scene_blob, photons, frame, (width, height), &settings), Some(hits)))
}

/// Where an interrupted render keeps its finished strips.
fn partial_path(output: &std::path::Path) -> PathBuf {
    let mut p = output.as_os_str().to_owned();
    p.push(".partial");
    PathBuf::from(p)
}

/// The per-worker table.
fn print_workers(workers: &[farm::WorkerReport]) {
    println!(
        "{:<16} {:<14} {:>7} {:>6} {:>8} {:>8} {:>10} {:>7} {:>8} {:>8}  state",
        "worker", "platform", "threads", "strips", "busy s", "Mpx/s", "shipped", "ship s", "spec/dup", "failures"
    );
    for w in workers {
        println!(
            "{:<16} {:<14} {:>7} {:>6} {:>8.2} {:>8.3} {:>10} {:>7.2} {:>8} {:>8}  {}",
            w.name,
            w.platform,
            w.threads,
            w.strips,
            w.busy_s,
            w.mpix_per_s,
            human_bytes(w.shipped_bytes),
            w.ship_s,
            format!("{}/{}", w.speculative, w.duplicates),
            w.failures,
            w.state
        );
    }
}

fn human_bytes(b: u64) -> String {
    match b {
        0..1024 => format!("{b} B"),
        1024..1_048_576 => format!("{:.1} KiB", b as f64 / 1024.0),
        _ => format!("{:.1} MiB", b as f64 / 1_048_576.0),
    }
}

fn compare(args: CompareArgs) -> Result<()> {
    if let Some(path) = &args.error_image {
        Format::from_path(path)?;
    }
    let image = Image::read(&args.image)?;
    let reference = Image::read(&args.reference)?;
    let what = || format!("comparing {} with the reference {}", args.image.display(), args.reference.display());
    let m = metrics::compare(&image, &reference, args.region).with_context(what)?;
    println!("{} against {} ({}x{})", args.image.display(), args.reference.display(), image.width, image.height);
    print_metrics(&m);
    if let Some(path) = &args.error_image {
        metrics::error_image(&image, &reference).with_context(what)?.write(path, 0.0)?;
        println!("  {:<26}{}", "error image", path.display());
    }
    println!("{}", m.key_values());
    Ok(())
}

fn reference(args: ReferenceArgs) -> Result<()> {
    if Format::from_path(&args.output)? != Format::Exr {
        bail!("the reference must be an .exr image (linear values), not {}", args.output.display());
    }
    if args.spp == 0 || args.passes == 0 {
        bail!("--spp and --passes must be at least 1");
    }
    let mut scene = Scene::load_with(&args.scene, &args.set)?;
    if let Some((w, h)) = args.size {
        scene.camera.width = w;
        scene.camera.height = h;
    }
    if args.seed == scene.render.seed {
        eprintln!("warning: the reference seed equals the scene's render.seed: its noise will correlate with renders");
    }
    // Decide on the scene as it stands (lights and materials do not depend on the method).
    let choice = sweep::choose_reference(&Prepared::new(&scene, &args.scene)?);
    let s = &mut scene.render;
    s.integrator = choice.integrator;
    s.seed = args.seed;
    let budget = match choice.integrator {
        Integrator::Progressive => {
            s.photons.passes = args.passes;
            format!("{} passes of {} photon paths", args.passes, s.photons.pass_photons)
        }
        _ => {
            s.spp = args.spp;
            format!("{} spp", args.spp)
        }
    };
    println!("reference method: {} ({budget}), because {}", choice.integrator, choice.reason);
    let Resolved { spec, token, tls_ca } = args.farm.resolve()?;
    let t = runtime()?.block_on(async {
        let fleet = fleet::Fleet::start(&spec).await.map_err(anyhow::Error::msg)?;
        let options = farm::Options { token, tls_ca, ..farm::Options::default() };
        let t = sweep::render_timed(&scene, &args.scene, &fleet.addrs, options).await;
        fleet.stop().await;
        t
    })?;
    t.image.write(&args.output, 0.0)?;
    println!(
        "{}: {}x{}, {}, {:.2} s render (+{:.2} s prepare)",
        args.output.display(),
        t.image.width,
        t.image.height,
        choice.integrator,
        t.render_s,
        t.prepare_s
    );
    Ok(())
}

fn sweep(args: SweepArgs) -> Result<()> {
    if args.methods.is_empty() || args.budget.is_empty() {
        bail!("--methods and --budget need at least one value each");
    }
    if args.budget.contains(&0) {
        bail!("budget multipliers must be at least 1");
    }
    let reference = Image::read(&args.reference).with_context(|| format!("reading {}", args.reference.display()))?;
    let (width, height) = args.size.unwrap_or((reference.width, reference.height));
    if (width, height) != (reference.width, reference.height) {
        bail!(
            "--size {width}x{height} differs from the reference {} ({}x{})",
            args.reference.display(),
            reference.width,
            reference.height
        );
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut base = Scene::load_with(&args.scene, &args.set)?;
    base.camera.width = width;
    base.camera.height = height;
    let Resolved { spec, token, tls_ca } = args.farm.resolve()?;
    let rows = runtime()?.block_on(async {
        // One set of workers for the whole sweep: they keep the blobs of repeated scenes and photon maps.
        let fleet = fleet::Fleet::start(&spec).await.map_err(anyhow::Error::msg)?;
        let names: Vec<&str> = fleet.addrs.iter().map(|a| a.name.as_str()).collect();
        println!(
            "sweep of {} at {width}x{height} against {}: on {} ({} threads here)",
            args.scene.display(),
            args.reference.display(),
            names.join(", "),
            rayon::current_num_threads()
        );
        let options = farm::Options { token, tls_ca, ..farm::Options::default() };
        let rows = sweep_rows(&args, &base, &reference, &fleet.addrs, options).await;
        fleet.stop().await;
        rows
    })?;
    let csv_path = args.out.join("sweep.csv");
    std::fs::write(&csv_path, sweep::csv(&rows)).with_context(|| format!("writing {}", csv_path.display()))?;
    let curves = sweep::curves(&rows);
    let name = args.scene.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let title = format!("{name} {width}x{height}: relative MSE against wall time");
    let (svg, png) = (args.out.join("sweep.svg"), args.out.join("sweep.png"));
    sweep::draw_charts(&curves, &title, &svg, &png)?;
    println!("\nequal time (relMSE, log-log interpolation):\n{}", sweep::equal_time_table(&curves));
    println!("equal error (seconds, log-log interpolation; — out of the measured range):");
    println!("{}", sweep::equal_error_table(&curves));
    println!("wrote {}, {} and {} (the PNG has no text)", csv_path.display(), svg.display(), png.display());
    Ok(())
}

/// Renders every (method, budget) of a sweep on the workers at `addrs` and measures it.
async fn sweep_rows(
    args: &SweepArgs,
    base: &Scene,
    reference: &Image,
    addrs: &[farm::WorkerAddr],
    options: farm::Options,
) -> Result<Vec<sweep::Row>> {
    let mut rows = Vec::new();
    for &method in &args.methods {
        for &b in &args.budget {
            let mut scene = base.clone();
            let setting = sweep::apply_budget(&mut scene.render, method, b)?;
            let t = sweep::render_timed(&scene, &args.scene, addrs, options.clone())
                .await
                .with_context(|| format!("rendering {method} at budget {b}"))?;
            let m = metrics::compare(&t.image, reference, None)
                .with_context(|| format!("measuring {method} at budget {b} against {}", args.reference.display()))?;
            let row = sweep::Row {
                method,
                budget: b,
                setting,
                seconds: t.prepare_s + t.render_s,
                rmse: m.rmse,
                rel_mse: m.rel_mse,
            };
            println!(
                "  {:<13} b={:<4} {:<16} {:>8.3} s  rmse {:<10} relMSE {}",
                method.name(),
                b,
                format!("{}={}", row.setting.parameter, row.setting.value),
                row.seconds,
                sig(row.rmse),
                sig(row.rel_mse)
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The readable block of `compare`: one metric a line, labels in a column.
fn print_metrics(m: &Metrics) {
    let rel = m.rel_bias.map_or_else(|| "undefined: black reference".to_owned(), |b| format!("{:+.3} %", 100.0 * b));
    let rows = [
        ("RMSE".to_owned(), sig(m.rmse)),
        (format!("relative MSE (eps {})", metrics::EPSILON), sig(m.rel_mse)),
        ("mean abs. relative error".to_owned(), sig(m.mare)),
        (format!("bias over {}", m.region), format!("{} ({rel})", sig(m.bias))),
        ("largest difference".to_owned(), format!("{} ({} values differ)", sig(m.max_abs), m.differing)),
    ];
    for (label, value) in rows {
        println!("  {label:<26}{value}");
    }
}
