//! `render --integrator auto` (or `integrator = "auto"` in the scene file): a pilot of each candidate method on
//! the workers, a prediction of each one's error at the end of the budget, and the winner's render, which goes
//! on from its pilot ([`crate::auto`] has the model).

use super::setup::{
    bound, fits_in_memory, open_cache, render_scene, runtime, serve_live, shape_job, stop_live, write_output,
};
use crate::auto::{self, Candidate, Goal, Judged, Pilot, SceneFacts};
use crate::cli::{IntegratorChoice, RenderArgs};
use crate::farm::bounded::{Bound, StopReason};
use crate::farm::{self, bounded::Continuation};
use crate::fleet;
use crate::job::delivery::{self, MapDelivery};
use crate::job::{Job, prepare_job};
use crate::out::live::LiveCandidate;
use crate::out::report::{Summary, print_workers};
use anyhow::{Context, Result, bail};
use photon_core::image_io::{Format, Image};
use photon_core::method::RadiusSetting;
use photon_core::prepare::Prepared;
use photon_core::scene::Scene;
use std::path::Path;
use std::time::{Duration, Instant};

/// Whether `render` is asked to choose its method: `--integrator auto`, or, with no `--integrator`, the scene
/// file's `integrator = "auto"`.
pub(super) fn asked(args: &RenderArgs) -> bool {
    match args.integrator {
        Some(choice) => choice == IntegratorChoice::Auto,
        None => scene_asks_auto(&args.scene),
    }
}

/// Whether the scene file at `path` asks for `integrator = "auto"` in its `[render]` table. A file that cannot
/// be read or parsed says no: loading it reports why.
fn scene_asks_auto(path: &Path) -> bool {
    let is_toml = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    let Some(text) = is_toml.then(|| std::fs::read_to_string(path).ok()).flatten() else { return false };
    let Ok(table) = text.parse::<toml::Table>() else { return false };
    table.get("render").and_then(|r| r.get("integrator")).and_then(|i| i.as_str()) == Some("auto")
}

/// One candidate's pilot: its scene, its job, what it measured, and where it stopped.
struct Piloted {
    judged: Judged,
    scene: Scene,
    job: Job,
    /// The render this pilot begins, bounded by the command's time or error.
    bound: Bound,
    continuation: Option<Box<Continuation>>,
    /// The pilot's image (pixel values, 3 per pixel).
    pixels: Vec<f32>,
}

/// Re-estimates each pilot's error relative to the mean of every pilot's image (about five times the samples of
/// any one), in place of its own halves' smaller mean ([`crate::farm::bounded::ErrorEstimate::parts_against`]);
/// returns that mean.
fn against_the_pooled_pilots(piloted: &mut [Piloted]) -> Vec<f32> {
    let with_images: Vec<&Piloted> = piloted.iter().filter(|p| p.judged.pilot.is_some()).collect();
    let Some(len) = with_images.first().map(|p| p.pixels.len()) else { return Vec::new() };
    let mut pooled = vec![0.0f64; len];
    for p in with_images.iter().filter(|p| p.pixels.len() == len) {
        for (s, &v) in pooled.iter_mut().zip(&p.pixels) {
            *s += f64::from(v);
        }
    }
    let n = with_images.iter().filter(|p| p.pixels.len() == len).count().max(1) as f64;
    let pooled: Vec<f32> = pooled.iter().map(|&s| (s / n) as f32).collect();
    for p in piloted.iter_mut() {
        let parts = p.continuation.as_ref().and_then(|c| c.rounds.estimate().parts_against(&pooled));
        if let (Some(pilot), Some(parts)) = (p.judged.pilot.as_mut(), parts) {
            pilot.parts = parts;
        }
    }
    pooled
}

/// Gives progressive photon mapping's pilots at the scene's radius and at half of it the squared bias their
/// difference shows ([`auto::radius_pair_bias2`], relative to `pooled`), where it exceeds their own estimates.
fn bias_from_the_radius_pair(piloted: &mut [Piloted], pooled: &[f32]) {
    // The pair: the candidates of a gathering radius at the two scales.
    let find = |p: &[Piloted], scale: f32| {
        let c = |p: &Piloted| p.judged.candidate;
        p.iter().position(|p| c(p).method.radius() == RadiusSetting::Photon && c(p).radius_scale == scale)
    };
    let [large, small] = auto::PROGRESSIVE_SCALES;
    let (Some(l), Some(s)) = (find(piloted, large), find(piloted, small)) else { return };
    fn halves(p: &Piloted) -> Option<auto::Halves<'_>> {
        p.continuation.as_ref().and_then(|c| c.rounds.estimate().halves())
    }
    let alpha = piloted[l].scene.render.photons.alpha;
    let (Some(hl), Some(hs)) = (halves(&piloted[l]), halves(&piloted[s])) else { return };
    let photons = &piloted[l].scene.render.photons;
    let share = auto::EdgeShare::new(piloted[l].judged.candidate.method.kernel(photons.kernel));
    let b = auto::radius_pair_bias2(hl, hs, pooled, alpha, &share);
    // The band of an edge narrows with the radius (see `auto::edge_band`).
    let ratio = f64::from(small / large);
    for (i, b) in [(l, b), (s, b * ratio)] {
        if let Some(p) = piloted[i].judged.pilot.as_mut() {
            p.parts.bias2 = p.parts.bias2.max(b);
        }
    }
}

/// Refuses what `auto` cannot choose for; the goal's kind (the seconds are set once the pilots are done).
fn check(args: &RenderArgs) -> Result<()> {
    Format::from_path(&args.output)?;
    if args.spp.is_some() || args.passes.is_some() {
        bail!(
            "--integrator auto chooses the method for a budget of time or error: --spp and --passes fix the \
             samples, so there is nothing to choose for (give --time or --target-error, or a method)"
        );
    }
    if args.time.is_none() && args.target_error.is_none() {
        bail!(
            "--integrator auto (or integrator = \"auto\" in the scene) needs a budget to choose for: give --time \
             (e.g. --time 20s) or --target-error (e.g. --target-error 0.01), or name a method with --integrator"
        );
    }
    if args.resume.is_some() {
        bail!("--integrator auto renders bounded by time or error, which cannot be resumed: drop --resume");
    }
    Ok(())
}

/// The scene's facts that decide the candidates, and its gather radius.
fn facts(scene: &Scene, path: &Path) -> Result<(SceneFacts, f32)> {
    let prep = Prepared::new(scene, path).context("preparing the scene for the pilots")?;
    let facts = SceneFacts { media: prep.media.is_some(), delta_caustics: crate::measure::has_delta_caustics(&prep) };
    Ok((facts, prep.photon_radius()))
}

/// What every pilot shares: the command and when it started, the scene, its radius, the time a pilot may take,
/// the farm.
struct PilotRun<'a> {
    t0: Instant,
    args: &'a RenderArgs,
    scene: &'a Scene,
    radius: f32,
    pilot: Duration,
    options: &'a farm::Options,
    addrs: &'a [fleet::session::WorkerAddr],
    cache: Option<&'a crate::job::prepared_cache::PreparedCache>,
}

/// What the pilots decided: every candidate judged, the winner's index and pilot, and the goal.
struct Choice {
    judged: Vec<Judged>,
    win: usize,
    chosen: Piloted,
    goal: Goal,
}

/// Pilots every candidate, predicts each one's error for the budget left after them and picks the winner.
async fn choose(run: &PilotRun<'_>, candidates: &[Candidate]) -> Result<Choice> {
    let mut piloted = Vec::new();
    for &candidate in candidates {
        piloted.push(run_pilot(run, candidate).await?);
    }
    let pooled = against_the_pooled_pilots(&mut piloted);
    bias_from_the_radius_pair(&mut piloted, &pooled);
    let goal = match (run.args.time, run.args.target_error) {
        (Some(t), _) => Goal::Time((run.t0 + t).saturating_duration_since(Instant::now()).as_secs_f64()),
        (None, e) => Goal::Error(e.unwrap_or(f64::INFINITY)),
    };
    for p in &mut piloted {
        let photons = &p.scene.render.photons;
        let share = auto::EdgeShare::new(p.judged.candidate.method.kernel(photons.kernel));
        p.judged.score = auto::score(p.judged.candidate, photons.alpha, &share, p.judged.pilot.as_ref(), goal);
    }
    let judged: Vec<Judged> = piloted.iter().map(|p| p.judged.clone()).collect();
    let win = auto::winner(&judged);
    if judged.iter().all(|j| !j.score.is_finite()) {
        eprintln!(
            "warning: --integrator auto: no pilot gave an estimate within {:.2} s; going on with {}",
            run.pilot.as_secs_f64(),
            judged[win].candidate.label()
        );
    }
    let chosen = piloted.swap_remove(win);
    Ok(Choice { judged, win, chosen, goal })
}

/// Renders with the method a pilot chooses (see the module documentation).
pub(super) fn render(args: RenderArgs) -> Result<()> {
    let t0 = Instant::now();
    check(&args)?;
    let crate::cli::Resolved { spec, token, tls_ca, policy } = args.farm.resolve()?;
    let scene = render_scene(&args, true)?;
    let (facts, radius) = facts(&scene, &args.scene)?;
    let candidates = auto::candidates(facts);
    if candidates.iter().all(|c| c.method == candidates[0].method) {
        eprintln!(
            "warning: --integrator auto: only {} suits this scene (it has participating media and point-light \
             caustics); the pilot chooses its radius",
            candidates[0].method
        );
    }
    let cache = open_cache(&args)?;
    let rt = runtime()?;
    let live = args.serve.map(|addr| serve_live(&rt, addr, scene.render.exposure, token.as_deref())).transpose()?;
    let fleet = rt.block_on(fleet::Fleet::start(&spec))?;
    let mut interrupts = rt.block_on(async { crate::fleet::interrupt::watch_signals() });
    let options =
        farm::Options { token, tls_ca, interrupt: Some(interrupts.clone()), policy, ..farm::Options::default() };
    let pilot = Duration::from_secs_f64(match args.time {
        Some(t) => auto::PILOT_SHARE * t.as_secs_f64(),
        None => auto::TARGET_PILOT_S,
    });
    let addrs = fleet.addrs.clone();
    let run = PilotRun {
        t0,
        args: &args,
        scene: &scene,
        radius,
        pilot,
        options: &options,
        addrs: &addrs,
        cache: cache.as_ref(),
    };
    let result = rt.block_on(async {
        let mut choice = choose(&run, &candidates).await?;
        if let Some((board, _)) = &live {
            board.set_candidates(live_candidates(&choice.judged, choice.win, choice.goal));
        }
        let chosen = &mut choice.chosen;
        let options = farm::Options {
            bound: Some(chosen.bound.clone()),
            continuation: chosen.continuation.take().map(|c| *c),
            progress: !args.quiet,
            live: live.as_ref().map(|(board, _)| board.clone()),
            ..options.clone()
        };
        let outcome = farm::render(&chosen.job, &addrs, options).await;
        let in_process = fleet.is_in_process();
        fleet.stop().await;
        anyhow::Ok((choice, outcome, in_process))
    });
    let (choice, outcome, in_process) = result?;
    if let Some((board, _)) = &live {
        board.finish();
    }
    let outcome = outcome.map_err(|e| {
        anyhow::anyhow!("{e}\nthe render was bounded by time or error: no image and no partial file were written")
    })?;
    finish(&args, &choice, outcome, in_process)?;
    if let Some((_, server)) = live {
        rt.block_on(stop_live(server, args.serve_after, &mut interrupts));
    }
    Ok(())
}

/// Writes the chosen render's image and prints the choice, the flags that reproduce it and the summary line.
fn finish(
    args: &RenderArgs,
    choice: &Choice,
    mut outcome: crate::out::report::Outcome,
    in_process: bool,
) -> Result<()> {
    if let Some(b) = outcome.bounded.as_ref().filter(|b| b.reason == StopReason::Interrupted) {
        bail!("interrupted after {} passes: no image was written", b.passes);
    }
    let (scene, job) = (&choice.chosen.scene, &choice.chosen.job);
    let image = Image { width: job.width, height: job.height, pixels: std::mem::take(&mut outcome.pixels) };
    let assemble_s = write_output(args, &image, scene.render.exposure, false)?;
    print_choice(&choice.judged, choice.win, choice.goal);
    if !in_process {
        print_workers(&outcome.workers);
    }
    let passes = outcome.bounded.as_ref().map_or(0, |b| b.passes);
    println!("{}", reproduce(&choice.judged[choice.win].candidate, scene, passes));
    let summary = Summary {
        output: &args.output,
        size: (job.width, job.height),
        settings: &scene.render,
        prepare_s: 0.0,
        assemble_s,
        hits: None,
        delivery: None,
    };
    println!("{}", summary.line(&outcome));
    Ok(())
}

/// Renders `candidate`'s pilot: the scene with its method (and radius: `radius_scale` times the scene's own),
/// [`auto::PILOT_PASSES`] passes in two rounds that estimate their error, stopped at `run.pilot` from now if it
/// is slower.
async fn run_pilot(run: &PilotRun<'_>, candidate: Candidate) -> Result<Piloted> {
    let PilotRun { t0, args, scene, radius, pilot, options, addrs, cache } = *run;
    let mut scene = scene.clone();
    let r = &mut scene.render;
    r.integrator = candidate.method;
    if candidate.radius_scale != 1.0 {
        r.photons.radius = Some(radius * candidate.radius_scale);
    }
    // The candidate's own render, of which the pilot is the first rounds.
    let bound = bound(args, &mut scene, t0)?.context("auto has a budget (checked)")?;
    fits_in_memory(&scene, None, true)?;
    let decide = |prep: &Prepared| delivery::choose(MapDelivery::Trace, prep, &delivery::Farm::default());
    let (mut job, _, _) = prepare_job(&scene, &args.scene, cache, decide)?;
    shape_job(&mut job, true, false, &options.tls_ca);
    let pilot_bound = Bound {
        deadline: Some(Instant::now() + pilot),
        target_error: None,
        passes: Some(auto::PILOT_PASSES),
        ..bound.clone()
    };
    let options = farm::Options { bound: Some(pilot_bound), ..options.clone() };
    let outcome =
        farm::render(&job, addrs, options).await.with_context(|| format!("the pilot of {}", candidate.label()))?;
    let report = outcome.bounded.context("a pilot renders in rounds")?;
    if report.reason == StopReason::Interrupted {
        bail!("interrupted during the pilot of {}: no image was written", candidate.label());
    }
    let workers = outcome.workers.iter().filter(|w| w.threads > 0).count().max(1) as f64;
    let pilot = match (report.error_parts, report.block_rate) {
        (Some(parts), Some(rate)) if report.passes > 0 => {
            Some(Pilot { passes: report.passes, seconds: report.round_seconds, rate: rate * workers, parts })
        }
        _ => None,
    };
    let judged = Judged { candidate, pilot, score: f64::INFINITY };
    Ok(Piloted { judged, scene, job, bound, continuation: outcome.continuation, pixels: outcome.pixels })
}

/// The candidates as the live page shows them.
fn live_candidates(judged: &[Judged], win: usize, goal: Goal) -> Vec<LiveCandidate> {
    judged
        .iter()
        .enumerate()
        .map(|(i, j)| LiveCandidate {
            method: j.candidate.label(),
            passes: j.pilot.map_or(0, |p| p.passes),
            pilot_s: j.pilot.map_or(0.0, |p| p.seconds),
            rel_mse: j.pilot.map(|p| p.parts.rel_mse()),
            predicted: j.score.is_finite().then_some(j.score),
            predicted_seconds: matches!(goal, Goal::Error(_)),
            chosen: i == win,
        })
        .collect()
}

/// Prints each candidate's pilot, its prediction and the choice.
fn print_choice(judged: &[Judged], win: usize, goal: Goal) {
    let (what, unit) = match goal {
        Goal::Time(s) => (format!("relMSE predicted {s:.1} s on"), ""),
        Goal::Error(e) => (format!("seconds predicted to relMSE {e:.2e}"), " s"),
    };
    println!("auto: {:<28} {:>8} {:>8} {:>11} {:>11}  {what}", "candidate", "passes", "pilot s", "variance", "bias²");
    for (i, j) in judged.iter().enumerate() {
        let mark = if i == win { "  <- chosen" } else { "" };
        match &j.pilot {
            Some(p) => println!(
                "auto: {:<28} {:>8} {:>8.2} {:>11.3e} {:>11.3e}  {:.3e}{unit}{mark}",
                j.candidate.label(),
                p.passes,
                p.seconds,
                p.parts.variance,
                p.parts.bias2.max(0.0),
                j.score
            ),
            None => println!("auto: {:<28} no estimate (the pilot ended before two rounds){mark}", j.candidate.label()),
        }
    }
}

/// The flags that render the same image bit for bit with the chosen method: `--integrator M --passes N` (or
/// `--spp N`), with the radius the pilot chose.
fn reproduce(candidate: &Candidate, scene: &Scene, passes: u32) -> String {
    let method = candidate.method;
    let budget = if method.renders_passes() { "--passes" } else { "--spp" };
    let mut line = format!("auto: the same image: --integrator {method} {budget} {passes}");
    if candidate.radius_scale != 1.0
        && let Some(r) = scene.render.photons.radius
    {
        line.push_str(&format!(" --set render.photons.radius={r}"));
    }
    line.push_str(" (with this command's other settings)");
    line
}
