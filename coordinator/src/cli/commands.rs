//! The commands of the command line: `render`, `compare` and `reference`, each from its parsed
//! arguments ([`crate::cli`]) to its output files and the lines it prints.

pub use super::setup::runtime;
use super::setup::{bound, fits_in_memory, open_cache, render_scene, serve_live, shape_job, stop_live, write_output};
use crate::cli::overrides::{self, Setting};
use crate::cli::{Cli, Command, CompareArgs, ReferenceArgs, RenderArgs, Resolved};
use crate::farm::{self, FarmError};
use crate::fleet::{self, session::Greeting};
use crate::job::delivery::{self, MapDelivery};
use crate::job::{Partial, partial_path, prepare_job};
use crate::measure;
use crate::out::report::{Summary, print_workers, sig};
use anyhow::{Context, Result, bail};
use photon_core::image_io::{Format, Image};
use photon_core::method::Method;
use photon_core::metrics::{self, Metrics};
use photon_core::prepare::Prepared;
// A scene file, or a glTF rendered directly.
use photon_core::prepare::gltf::direct::load_scene;
use std::path::Path;
use std::time::{Duration, Instant};

/// Runs a parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(args) if super::auto::asked(&args) => super::auto::render(args),
        Command::Render(args) => render(args),
        Command::Compare(args) => compare(args),
        Command::Reference(args) => reference(args),
    }
}

/// Logs to standard error, at `warn` unless `RUST_LOG` says otherwise: the log of `photon-coordinator` and of
/// the tools built on this library (`photon-sweep`).
pub fn init_logging() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
}

fn render(args: RenderArgs) -> Result<()> {
    Format::from_path(&args.output)?;
    if args.rows_per_strip == Some(0) {
        bail!("--rows-per-strip must be at least 1");
    }
    let Resolved { spec, token, tls_ca, policy } = args.farm.resolve()?;
    let t0 = Instant::now();
    let mut scene = render_scene(&args, false)?;
    let bound = bound(&args, &mut scene, t0)?;
    fits_in_memory(&scene, args.rows_per_strip, bound.is_some())?;
    let resume = args.resume.as_deref().map(Partial::read).transpose()?;
    let cache = open_cache(&args)?;
    // The runtime outlives the render, so that its signal watch still ends the process at a second signal while
    // the partial file is written. The workers start (and remote ones are asked their threads) before
    // preparing: how they get the photon maps depends on them.
    let rt = runtime()?;
    // The page is up before the workers start, so that an address in use fails at once.
    let live = args.serve.map(|addr| serve_live(&rt, addr, scene.render.exposure, token.as_deref())).transpose()?;
    let fleet = rt.block_on(fleet::Fleet::start(&spec))?;
    // The model's view of the workers is needed only when it chooses (a forced mode ignores it).
    let (model_farm, greetings) =
        if scene.render.integrator.needs_photon_maps() && args.photon_maps == MapDelivery::Auto {
            rt.block_on(model_farm(&spec, &fleet, token.as_deref(), tls_ca.as_deref()))
        } else {
            (delivery::Farm::default(), Vec::new())
        };
    let decide = |prep: &Prepared| delivery::choose(args.photon_maps, prep, &model_farm);
    let (mut job, hits, delivery) = prepare_job(&scene, &args.scene, cache.as_ref(), decide)?;
    let peers = delivery.is_some_and(|d| d.mode == MapDelivery::Peers);
    shape_job(&mut job, bound.is_some(), peers, &tls_ca);
    let (width, height) = (job.width, job.height);
    let settings = scene.render.clone();
    let prepare_s = t0.elapsed().as_secs_f64();
    tracing::info!(blob_bytes = job.blob_bytes(), prepare_s, "prepared");

    let mut interrupts = rt.block_on(async { crate::fleet::interrupt::watch_signals() });
    let checkpoint = checkpoint(&args, bound.is_some());
    let checkpointed = checkpoint.is_some();
    let options = farm::Options {
        token,
        tls_ca,
        rows_per_strip: args.rows_per_strip,
        resume,
        progress: !args.quiet,
        interrupt: Some(interrupts.clone()),
        bound: bound.clone(),
        live: live.as_ref().map(|(board, _)| board.clone()),
        greetings,
        checkpoint,
        policy,
        ..farm::Options::default()
    };
    let (outcome, in_process) = rt.block_on(async {
        let outcome = farm::render(&job, &fleet.addrs, options).await;
        let in_process = fleet.is_in_process();
        fleet.stop().await;
        anyhow::Ok((outcome, in_process))
    })?;
    if let Some((board, _)) = &live {
        board.finish();
    }
    let mut outcome = match outcome {
        Ok(o) => o,
        Err(e) if bound.is_some() => {
            bail!("{e}\nthe render was bounded by time or error: no image and no partial file were written")
        }
        Err(e) => return fail_keeping_partial(&args.output, e, settings.integrator),
    };
    let image = Image { width, height, pixels: std::mem::take(&mut outcome.pixels) };
    let assemble_s = write_output(&args, &image, settings.exposure, checkpointed)?;
    if !in_process {
        print_workers(&outcome.workers);
    }
    let summary = Summary {
        output: &args.output,
        size: (width, height),
        settings: &settings,
        prepare_s,
        assemble_s,
        hits,
        delivery,
    };
    println!("{}", summary.line(&outcome));
    if let Some((_, server)) = live {
        rt.block_on(stop_live(server, args.serve_after, &mut interrupts));
    }
    Ok(())
}

/// The render's checkpoints (`--checkpoint-every`), into the output's partial file; none with
/// `--no-checkpoint` or for a render `bounded` by time or error. Warns when that file exists and is not the one
/// resumed from: the first checkpoint replaces it.
fn checkpoint(args: &RenderArgs, bounded: bool) -> Option<farm::Checkpoint> {
    if args.no_checkpoint || bounded {
        return None;
    }
    let path = partial_path(&args.output);
    if path.exists() && args.resume.as_deref() != Some(path.as_path()) {
        eprintln!(
            "warning: {} exists and is not resumed (--resume): this render's first checkpoint replaces it",
            path.display()
        );
    }
    Some(farm::Checkpoint { path, every: args.checkpoint_every })
}

/// The workers as the photon-map delivery model sees them: their threads, this machine's threads, and the link
/// between them. Remote workers are greeted for their threads and their link is measured
/// ([`fleet::measure_link`]); the greetings are returned for the render's sessions, which then say no second
/// hello.
async fn model_farm(
    spec: &fleet::FleetSpec,
    fleet: &fleet::Fleet,
    token: Option<&str>,
    tls_ca: Option<&[u8]>,
) -> (delivery::Farm, Vec<Option<Greeting>>) {
    let mut greetings = Vec::new();
    let here = rayon::current_num_threads() as u32;
    let (worker_threads, link_bytes_per_s) = match spec {
        fleet::FleetSpec::InProcess(threads) => {
            (vec![threads.map_or(here, |t| t as u32)], delivery::LOOPBACK_BYTES_PER_S)
        }
        fleet::FleetSpec::Local { n, threads, .. } => {
            (vec![(threads / n.max(&1)).max(1) as u32; *n], delivery::LOOPBACK_BYTES_PER_S)
        }
        fleet::FleetSpec::Remote(_) => {
            greetings = fleet::greet(&fleet.addrs, token, tls_ca, Duration::from_secs(5)).await;
            (fleet::threads(&greetings), delivery::LINK_BYTES_PER_S)
        }
    };
    // Workers on this machine share its one link, whether started here or listed by a loopback address.
    let shared_link = !matches!(spec, fleet::FleetSpec::Remote(_)) || fleet.addrs.iter().all(|a| a.is_loopback());
    // A remote farm's link is measured: a lab's may be 100 Mbit/s or 10 Gbit/s, and the choice turns on it.
    let measured = if shared_link { None } else { fleet::measure_link(&mut greetings).await };
    let link_bytes_per_s = measured.unwrap_or(link_bytes_per_s);
    let link_measured = measured.is_some();
    let farm =
        delivery::Farm { worker_threads, coordinator_threads: here, link_bytes_per_s, shared_link, link_measured };
    (farm, greetings)
}

/// A render stopped by a signal: the error `main` reports, with the exit status it ends with.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct Interrupted {
    /// The process's exit status (130 for SIGINT, 143 for SIGTERM).
    pub exit_code: i32,
    /// What happened and how to resume.
    message: String,
}

/// Keeps the finished strips of a failed or interrupted render in the partial file beside the output, and prints
/// the command that resumes it. A fatal failure is not resumable: no worker of this build can render that strip,
/// so it is reported with no partial file and no `--resume` hint: as the limit it names (a worker's memory,
/// with the settings to change), or else as a bug of `method`.
fn fail_keeping_partial(output: &Path, e: FarmError, method: Method) -> Result<()> {
    if let FarmError::Fatal { workers, reason } = &e {
        print_workers(workers);
        if reason.contains(photon_core::run::STORAGE_CAPPED) {
            bail!("{e}\nresuming would fail the same way: change the settings the message names");
        }
        bail!(
            "{e}\nno worker of this build can render it with the method `{method}` (resuming would fail the same \
             way): this is a bug in photon; please report it with the scene and the command"
        );
    }
    let Some(partial) = e.partial() else {
        return Err(e.into());
    };
    let path = partial_path(output);
    let done = partial.done.len();
    let units = if method.renders_passes() { "pass blocks" } else { "strips or sample blocks" };
    partial.write(&path)?;
    if let FarmError::NoWorkers { workers, .. } | FarmError::Interrupted { workers, .. } = &e {
        print_workers(workers);
    }
    let message = format!(
        "{e}\n{done} finished {units} are in {}; continue with:\n  {}",
        path.display(),
        resume_command(std::env::args_os(), &path)
    );
    match e {
        FarmError::Interrupted { signal, .. } => Err(Interrupted { exit_code: signal.exit_code(), message }.into()),
        _ => Err(anyhow::Error::msg(message)),
    }
}

/// The command line `args` (this process's, program first) with its `--resume` replaced by `--resume partial`,
/// quoted for a POSIX shell.
fn resume_command(args: impl IntoIterator<Item = std::ffi::OsString>, partial: &Path) -> String {
    let mut out = Vec::new();
    let mut args = args.into_iter();
    while let Some(arg) = args.next() {
        let text = arg.to_string_lossy();
        if text == "--resume" {
            args.next();
        } else if !text.starts_with("--resume=") {
            out.push(shell_quote(&text));
        }
    }
    out.push("--resume".into());
    out.push(shell_quote(&partial.to_string_lossy()));
    out.join(" ")
}

/// `word` as a POSIX shell reads it back: as it is when it holds only safe characters, else in single quotes.
fn shell_quote(word: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "-_./:=,@%+".contains(c);
    if !word.is_empty() && word.chars().all(safe) {
        word.to_owned()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
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
    let size: Vec<Setting> = args.size.map(|(w, h)| Setting::Size(w, h)).into_iter().collect();
    let scene = load_scene(&args.scene, &overrides::pairs(&args.set, &size))?;
    if args.seed == scene.render.seed {
        eprintln!("warning: the reference seed equals the scene's render.seed: its noise will correlate with renders");
    }
    // Decide on the scene as it stands (lights and materials do not depend on the method).
    let choice = measure::choose_reference(&Prepared::new(&scene, &args.scene)?);
    let budget = if choice.integrator.renders_passes() { Setting::Passes(args.passes) } else { Setting::Spp(args.spp) };
    let settings = [size.as_slice(), &[Setting::Integrator(choice.integrator), Setting::Seed(args.seed), budget]];
    let scene = load_scene(&args.scene, &overrides::pairs(&args.set, &settings.concat()))?;
    let (w, h) = (scene.camera.width, scene.camera.height);
    let units = scene.render.units();
    let budget =
        choice.integrator.work_words(units, u64::from(w) * u64::from(h), scene.render.photons.pass_photons, false);
    fits_in_memory(&scene, None, false)?;
    println!("reference method: {} ({budget}), because {}", choice.integrator, choice.reason);
    let Resolved { spec, token, tls_ca, policy } = args.farm.resolve()?;
    let t = runtime()?.block_on(async {
        let fleet = fleet::Fleet::start(&spec).await?;
        let options = farm::Options { token, tls_ca, policy, ..farm::Options::default() };
        let t = measure::render_timed(&scene, &args.scene, &fleet.addrs, options).await;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::IntegratorChoice;
    use photon_core::scene::Scene;

    #[test]
    fn the_resume_command_replaces_an_earlier_resume_and_quotes_for_the_shell() {
        let args = ["photon-coordinator", "render", "my scene.toml", "-o", "out.exr", "--resume", "old.partial", "-q"];
        let line = resume_command(args.map(Into::into), Path::new("out.exr.partial"));
        assert_eq!(line, "photon-coordinator render 'my scene.toml' -o out.exr -q --resume out.exr.partial");
        let args = ["p", "--resume=x", "it's"];
        assert_eq!(resume_command(args.map(Into::into), Path::new("o")), "p 'it'\\''s' --resume o");
    }

    #[test]
    fn the_methods_in_passes_parse_and_bound_their_passes() {
        use clap::Parser as _;
        let text = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nwidth = 8\nheight = 8\n";
        let methods = [("progressive", true), ("vcm", true), ("bdpt", false), ("lt", false), ("path", false)];
        for (method, biased) in methods {
            let render = ["photon-coordinator", "render", "s.toml", "--integrator", method, "--time", "10s"];
            let Command::Render(args) = Cli::try_parse_from(render).unwrap().command else { unreachable!("a render") };
            let mut scene = Scene::parse(text, Path::new("s.toml")).unwrap();
            scene.render.integrator = args.integrator.and_then(IntegratorChoice::method).unwrap();
            let (spp, passes) = (scene.render.spp, scene.render.photons.passes);
            let b = bound(&args, &mut scene, Instant::now()).unwrap().unwrap();
            let in_passes = scene.render.integrator.renders_passes();
            let max = crate::farm::bounded::MAX_PASSES;
            assert_eq!(
                (scene.render.spp, scene.render.photons.passes),
                if in_passes { (spp, max) } else { (max, passes) },
                "{method}"
            );
            assert_eq!(b.bias_alpha.is_some(), biased, "{method}");
            assert!(b.estimate, "{method}");
        }
    }
}
