//! `photon-coordinator`: the photon command line.
#![forbid(unsafe_code)]

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use photon_core::image_io::{Format, Image};
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
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Exposure in stops for 8-bit outputs (overrides the scene's `render.exposure`).
    #[arg(long)]
    exposure: Option<f32>,
    /// Override a scene setting, e.g. `--set render.photons.kernel=box` or `--set camera.fov=30`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
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
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render(args),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn render(args: RenderArgs) -> Result<()> {
    Format::from_path(&args.output)?;
    if let Some(t) = args.threads {
        if t == 0 {
            bail!("--threads must be at least 1");
        }
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().context("starting the thread pool")?;
    }
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
    let prep = Prepared::new(&scene, &args.scene)?;
    let prepare_s = t0.elapsed().as_secs_f64();
    tracing::info!(primitives = prep.geometry.prims.len(), lights = prep.lights.lights.len(), prepare_s, "prepared");
    let (width, height) = (prep.camera.width, prep.camera.height);
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(u64::from(height)) };
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} rows ({eta} left)")
            .context("progress bar template")?,
    );
    let t1 = Instant::now();
    let settings = prep.settings.clone();
    let strip = photon_core::render::render_image(&prep, &settings, &|n| bar.set_position(u64::from(n)));
    bar.finish_and_clear();
    let render_s = t1.elapsed().as_secs_f64();
    let image = Image { width, height, pixels: strip.pixels };
    image.write(&args.output, settings.exposure)?;
    println!(
        "{}: {width}x{height}, {} spp, {}, {:.2} s render (+{:.2} s prepare), {:.2} Mrays/s",
        args.output.display(),
        settings.spp,
        settings.integrator,
        render_s,
        prepare_s,
        strip.rays as f64 / render_s / 1e6
    );
    Ok(())
}
