//! `photon-coordinator`: the photon command line.
#![forbid(unsafe_code)]

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
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
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render(args),
        Command::Compare(args) => compare(args),
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

/// The readable block of `compare`: one metric a line, labels in a column.
fn print_metrics(m: &Metrics) {
    let rel = m.rel_bias.map_or_else(|| "undefined: black reference".to_owned(), |b| format!("{:+.3} %", 100.0 * b));
    let rows = [
        ("RMSE".to_owned(), sig(m.rmse)),
        (format!("relative MSE (eps {})", metrics::EPSILON), sig(m.rel_mse)),
        ("mean abs. relative error".to_owned(), sig(m.mare)),
        (format!("bias over {}", m.region), format!("{} ({rel})", sig(m.bias))),
    ];
    for (label, value) in rows {
        println!("  {label:<26}{value}");
    }
}

/// Four significant digits, in scientific notation outside [0.001, 10 000).
fn sig(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() {
        format!("{x}")
    } else if (1e-3..1e4).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.3e}")
    }
}
