//! The command line: its arguments (here: one struct per command, the farm flags they share, and the parsers of
//! their values, with one error type, [`ValueError`]), the flags that override scene settings ([`overrides`])
//! and the commands that run them ([`commands`]).

mod auto;
pub mod commands;
pub mod overrides;
mod setup;

use crate::fleet;
use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use overrides::Setting;
use photon_core::method::Method;
use photon_core::metrics::Region;
use std::path::PathBuf;
use std::time::Duration;

/// A distributed photon-mapping renderer.
#[derive(Parser, Debug)]
#[command(name = "photon-coordinator", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand, Debug)]
pub(crate) enum Command {
    /// Render a scene file to an image.
    Render(RenderArgs),
    /// Measure an image's error against a reference (RMSE, relative MSE, relative error, bias).
    Compare(CompareArgs),
    /// Render a reference EXR: the path tracer at many samples, or progressive photon mapping at many passes
    /// when the scene has point-light caustics. Renders on workers like `render` (in-process by default).
    Reference(ReferenceArgs),
}

#[derive(clap::Args, Debug)]
pub(crate) struct RenderArgs {
    /// The scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Output image; the format comes from the extension: .png, .exr (linear), .ppm or .bmp.
    #[arg(short, long, default_value = "out.png")]
    pub(crate) output: PathBuf,
    /// Samples per pixel (overrides the scene's `render.spp`).
    #[arg(long)]
    pub(crate) spp: Option<u32>,
    /// Method (overrides `render.integrator`): `path` (path tracing, the reference), `direct` (direct light
    /// only), `photon-map` (the global map seen directly), `final-gather` (Jensen's two passes), `progressive`
    /// (progressive photon mapping, in passes), `vcm` (vertex connection and merging: bidirectional paths and
    /// photon merges weighted by MIS, in passes), `bdpt` (bidirectional path tracing: vcm without merging) or
    /// `lt` (light tracing: light subpaths connected to the camera only). `auto` chooses among path,
    /// progressive (at two radii), vcm and bdpt by a short pilot of each, for the budget of `--time` or
    /// `--target-error` (docs/USAGE.md).
    #[arg(long)]
    pub(crate) integrator: Option<IntegratorChoice>,
    /// Seed (overrides the scene's `render.seed`).
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// Image width and height in pixels, e.g. `256x256` (overrides the scene's camera).
    #[arg(long, value_parser = parse_size)]
    pub(crate) size: Option<(u32, u32)>,
    /// Photon paths per map, or per progressive pass (overrides `render.photons.global`, `.caustic` and
    /// `.pass_photons`).
    #[arg(long)]
    pub(crate) photons: Option<u32>,
    /// Passes of `progressive`, `vcm`, `bdpt` and `lt` (overrides `render.photons.passes`).
    #[arg(long)]
    pub(crate) passes: Option<u32>,
    /// Exposure in stops for 8-bit outputs (overrides the scene's `render.exposure`).
    #[arg(long)]
    pub(crate) exposure: Option<f32>,
    /// Override a scene setting, e.g. `--set render.photons.kernel=box` or `--set camera.fov=30`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub(crate) set: Vec<String>,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) farm: FarmArgs,
    /// Continue an interrupted render from the partial file it left (`OUTPUT.partial`).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["time", "target_error"])]
    pub(crate) resume: Option<PathBuf>,
    /// Write the finished strips (or pass blocks) to `OUTPUT.partial` this often while the render runs (e.g.
    /// `5s`), so that a coordinator killed at any moment can be resumed with `--resume OUTPUT.partial`. The
    /// interval grows to 50 times a checkpoint's write time, which keeps their cost under 2 %. Not for renders
    /// bounded by `--time` or `--target-error`, which cannot be resumed.
    #[arg(long, value_name = "TIME", value_parser = parse_time, default_value = "5s")]
    pub(crate) checkpoint_every: Duration,
    /// Write no checkpoints (`--checkpoint-every`); SIGINT and SIGTERM still leave the partial file.
    #[arg(long)]
    pub(crate) no_checkpoint: bool,
    /// Render in rounds until this much time has passed since the command started (e.g. `90s`, `1.5m`): passes
    /// for `progressive`, `vcm`, `bdpt` and `lt`, samples per pixel for the other methods, replacing `--spp` and
    /// `--passes`. The summary says how many were done; the image equals a render of that many.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub(crate) time: Option<Duration>,
    /// Render in rounds until the estimated relative MSE (no reference needed) is at most this, e.g. `0.01`:
    /// every method but `photon-map` and `final-gather` (the estimate of `progressive` and `vcm` includes the
    /// gather radius's bias). With `--time`, whichever comes first.
    #[arg(long, value_name = "RELMSE", value_parser = parse_target_error)]
    pub(crate) target_error: Option<f64>,
    /// Rows per strip (default: about 16 strips per worker, at most 64 rows); for `progressive`, `vcm`, `bdpt`
    /// and `lt`, passes per whole-image block (default: about 16 blocks per worker).
    #[arg(long, value_name = "N")]
    pub(crate) rows_per_strip: Option<u32>,
    /// Folder of prepared blobs reused by later renders of an unchanged scene (default: $PHOTON_CACHE_DIR, else
    /// $XDG_CACHE_HOME/photon, else ~/.cache/photon).
    #[arg(long, value_name = "DIR")]
    pub(crate) cache_dir: Option<PathBuf>,
    /// Size cap of the prepared-blob cache in MiB (oldest entries out first).
    #[arg(long, value_name = "MIB", default_value_t = 4096)]
    pub(crate) cache_mib: u64,
    /// Neither read nor write the prepared-blob cache.
    #[arg(long, conflicts_with = "cache_dir")]
    pub(crate) no_cache: bool,
    /// How workers get the photon maps of `photon-map` and `final-gather`: `ship` (traced here once, uploaded
    /// to each), `peers` (traced here once, uploaded to one worker at a time and passed on among the workers),
    /// `trace` (each worker traces them itself; the same bits), or `auto` (a cost model measured on this machine
    /// chooses per job; the summary line says which and what it modelled).
    #[arg(long, value_enum, default_value_t = crate::job::delivery::MapDelivery::Auto)]
    pub(crate) photon_maps: crate::job::delivery::MapDelivery,
    /// Serve a live web page of the render at ADDR while it runs (default 127.0.0.1:8080): the image as it fills
    /// in, the strips done and in flight, the workers, progress, the time left and the photon statistics;
    /// `/api/status` has the same as JSON. With a farm token, the page and the JSON want it
    /// (`Authorization: Bearer`).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = crate::out::live::DEFAULT_ADDR,
          value_parser = parse_serve_addr)]
    pub(crate) serve: Option<std::net::SocketAddr>,
    /// Keep the live page up after the render, showing the final state, until Ctrl-C.
    #[arg(long, requires = "serve")]
    pub(crate) serve_after: bool,
}

/// `--integrator`: a method, or `auto` (chosen by a pilot of each candidate: [`crate::auto`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntegratorChoice {
    /// This method.
    Method(Method),
    /// The method that a pilot predicts best for the budget.
    Auto,
}

impl IntegratorChoice {
    /// The method, unless `auto`.
    pub fn method(self) -> Option<Method> {
        match self {
            Self::Method(m) => Some(m),
            Self::Auto => None,
        }
    }
}

impl std::str::FromStr for IntegratorChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            _ => s.parse().map(Self::Method).map_err(|e: photon_core::method::UnknownMethod| format!("{e}, or auto")),
        }
    }
}

impl RenderArgs {
    /// The settings the flags override, checked as `--set` would not (a count of 0 names the flag).
    pub(crate) fn settings(&self) -> Result<Vec<Setting>> {
        let at_least_1 = |flag: &str, v: Option<u32>| match v {
            Some(0) => bail!("--{flag} must be at least 1"),
            _ => Ok(v),
        };
        let (spp, photons) = (at_least_1("spp", self.spp)?, at_least_1("photons", self.photons)?);
        let passes = at_least_1("passes", self.passes)?;
        let settings = [
            self.size.map(|(w, h)| Setting::Size(w, h)),
            spp.map(Setting::Spp),
            self.integrator.and_then(IntegratorChoice::method).map(Setting::Integrator),
            self.seed.map(Setting::Seed),
            self.exposure.map(Setting::Exposure),
            photons.map(Setting::Photons),
            passes.map(Setting::Passes),
        ];
        Ok(settings.into_iter().flatten().collect())
    }
}

/// Where to render: with none of `--hosts`, `--workers` or `--local`, on a worker inside this process.
#[derive(clap::Args, Debug, Clone)]
pub struct FarmArgs {
    /// Render on the workers of a host list (TOML: `[[worker]]` tables with `address` and an optional `name`).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["workers", "local"])]
    pub(crate) hosts: Option<PathBuf>,
    /// Render on these workers, e.g. `lab-01:7878,lab-02:7878`; `dns:NAME:PORT` is every address NAME resolves
    /// to (a Kubernetes headless Service: one per ready worker pod).
    #[arg(long, value_name = "HOST:PORT,...", conflicts_with = "local")]
    pub(crate) workers: Option<String>,
    /// Start N `photon-worker` processes on loopback (sharing this machine's cores) and render on them.
    #[arg(long, value_name = "N")]
    pub(crate) local: Option<usize>,
    /// A file holding the shared token the workers require.
    #[arg(long, value_name = "FILE")]
    pub(crate) token_file: Option<PathBuf>,
    /// Speak TLS to the workers, trusting only this PEM certificate authority (see deploy/tls/make-certs.sh).
    #[arg(long, value_name = "FILE")]
    pub(crate) tls_ca: Option<PathBuf>,
    /// Threads on this machine, for preparing and for in-process or --local workers (default: all cores).
    #[arg(long)]
    pub(crate) threads: Option<usize>,
    /// Block a worker after it failed this many units of the job, whatever the cause (a crash, a lost link, a
    /// corrupt result, a stall, a missed deadline): it gets no more units of the job, and the end table shows
    /// it `blocked` with the reason.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) block_after: u32,
}

/// What the farm flags resolve to.
pub struct Resolved {
    /// Where the workers are.
    pub spec: fleet::FleetSpec,
    /// The token to send them, if any.
    pub token: Option<String>,
    /// The PEM certificate authority to trust when speaking TLS to them.
    pub tls_ca: Option<Vec<u8>>,
    /// The scheduling policy (`--block-after`).
    pub policy: crate::farm::scheduler::Policy,
}

impl FarmArgs {
    /// Checks the flags, sizes the thread pool and says which workers to use, which token to send and which
    /// authority to trust.
    pub fn resolve(&self) -> Result<Resolved> {
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
                let h = fleet::read_hosts(path)?;
                (fleet::FleetSpec::Remote(h.workers), h.token_file, h.tls_ca)
            }
            (None, Some(list), _) => (fleet::FleetSpec::Remote(fleet::parse_workers(list)?), None, None),
            (None, None, Some(n)) => {
                let threads = self.threads.unwrap_or_else(rayon::current_num_threads);
                (fleet::FleetSpec::Local { n, threads, token_file: self.token_file.clone() }, None, None)
            }
            (None, None, None) => (fleet::FleetSpec::InProcess(self.threads), None, None),
        };
        let token_file = self.token_file.clone().or(hosts_token);
        let token = token_file.as_deref().map(photon_proto::read_token).transpose()?;
        let tls_ca = match self.tls_ca.clone().or(hosts_ca) {
            Some(p) => Some(std::fs::read(&p).with_context(|| format!("reading the TLS authority {}", p.display()))?),
            None => None,
        };
        let policy = crate::farm::scheduler::Policy { block_after: self.block_after, ..Default::default() };
        Ok(Resolved { spec, token, tls_ca, policy })
    }
}

#[derive(clap::Args, Debug)]
pub(crate) struct CompareArgs {
    /// The image to measure: EXR for linear values (8-bit formats are decoded from sRGB).
    pub(crate) image: PathBuf,
    /// The reference image, the same size.
    pub(crate) reference: PathBuf,
    /// Measure the bias over the pixels `X0,Y0,X1,Y1`, X1 and Y1 exclusive (default: the whole image).
    #[arg(long, value_parser = parse_region, value_name = "X0,Y0,X1,Y1")]
    pub(crate) region: Option<Region>,
    /// Write a false-colour map of per-pixel relative error (0 dark, 1 or more bright), e.g. `err.png`.
    #[arg(long, value_name = "FILE")]
    pub(crate) error_image: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
pub(crate) struct ReferenceArgs {
    /// The scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Output image; must be .exr (linear values, for `compare` and `photon-sweep`).
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Samples per pixel when the path tracer renders the reference.
    #[arg(long, default_value_t = 4096)]
    pub(crate) spp: u32,
    /// Passes when progressive photon mapping renders the reference.
    #[arg(long, default_value_t = 512)]
    pub(crate) passes: u32,
    /// Image width and height in pixels, e.g. `96x96` (overrides the scene's camera).
    #[arg(long, value_parser = parse_size)]
    pub(crate) size: Option<(u32, u32)>,
    /// Seed of the reference; keep it different from the seed of the images it measures (the scene's
    /// `render.seed`, 1 by default), or their noise is correlated and the error looks smaller than it is.
    #[arg(long, default_value_t = 0x5EED)]
    pub(crate) seed: u64,
    /// Override a scene setting, e.g. `--set render.photons.pass_photons=50000`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub(crate) set: Vec<String>,
    #[command(flatten)]
    pub(crate) farm: FarmArgs,
}

/// Why a value of `--region`, `--size`, `--serve`, `--time` or `--target-error` is not one.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum ValueError {
    /// Not four non-negative integers.
    #[error("expected X0,Y0,X1,Y1 (four non-negative integers, X1 and Y1 exclusive), found `{0}`")]
    RegionNumbers(String),
    /// An empty region.
    #[error("expected X0 < X1 and Y0 < Y1 (X1 and Y1 exclusive), found `{0}`")]
    RegionOrder(String),
    /// Not four numbers.
    #[error("expected four numbers X0,Y0,X1,Y1, found `{0}`")]
    RegionCount(String),
    /// Not `WIDTHxHEIGHT`.
    #[error("expected WIDTHxHEIGHT, found `{0}`")]
    SizeForm(String),
    /// A size of 0 or above 65536.
    #[error("expected WIDTHxHEIGHT with sizes in 1..=65536, found `{0}`")]
    SizeRange(String),
    /// Not an address to listen on.
    #[error("expected HOST:PORT to serve the live page on, e.g. 127.0.0.1:8080, found `{0}`")]
    ServeAddr(String),
    /// Not a positive time, or one above 10⁷ s.
    #[error("expected a positive time such as 90s, 1.5m or 500ms (at most 10⁷ s), found `{0}`")]
    Time(String),
    /// Not a relative MSE in (0, 10⁶).
    #[error("expected a relative MSE greater than 0, e.g. 0.01, found `{0}`")]
    TargetError(String),
}

/// A region `X0,Y0,X1,Y1` of `--region`.
pub fn parse_region(s: &str) -> Result<Region, ValueError> {
    let v: Vec<u32> = s
        .split(',')
        .map(|p| p.trim().parse::<u32>())
        .collect::<Result<_, _>>()
        .map_err(|_| ValueError::RegionNumbers(s.to_owned()))?;
    match v[..] {
        [x0, y0, x1, y1] if x0 < x1 && y0 < y1 => Ok(Region { x0, y0, x1, y1 }),
        [_, _, _, _] => Err(ValueError::RegionOrder(s.to_owned())),
        _ => Err(ValueError::RegionCount(s.to_owned())),
    }
}

/// A size `WIDTHxHEIGHT` of `--size`.
pub fn parse_size(s: &str) -> Result<(u32, u32), ValueError> {
    let (w, h) = s.split_once('x').ok_or_else(|| ValueError::SizeForm(s.to_owned()))?;
    let p = |v: &str| v.parse::<u32>().ok().filter(|&n| (1..=65_536).contains(&n));
    match (p(w), p(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(ValueError::SizeRange(s.to_owned())),
    }
}

/// The address `ADDR` of `--serve`: `IP:PORT`, or `NAME:PORT` resolved now (the first address it names).
pub fn parse_serve_addr(s: &str) -> Result<std::net::SocketAddr, ValueError> {
    use std::net::ToSocketAddrs;
    if let Ok(addr) = s.parse() {
        return Ok(addr);
    }
    s.to_socket_addrs().ok().and_then(|mut a| a.next()).ok_or_else(|| ValueError::ServeAddr(s.to_owned()))
}

/// Parses a `--time` value: a number with an optional unit `ms`, `s` (the default), `m` or `h`, e.g. `90s`,
/// `1.5m`, `500ms`.
pub fn parse_time(s: &str) -> Result<Duration, ValueError> {
    let t = s.trim();
    let (number, scale) = [("ms", 1e-3), ("s", 1.0), ("m", 60.0), ("h", 3600.0)]
        .iter()
        .find_map(|&(unit, scale)| t.strip_suffix(unit).map(|n| (n, scale)))
        .unwrap_or((t, 1.0));
    match number.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v * scale <= 1e7 => Ok(Duration::from_secs_f64(v * scale)),
        _ => Err(ValueError::Time(s.to_owned())),
    }
}

/// Parses a `--target-error` value: a relative MSE in (0, 1e6).
pub fn parse_target_error(s: &str) -> Result<f64, ValueError> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v < 1e6 => Ok(v),
        _ => Err(ValueError::TargetError(s.to_owned())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_values_parse_with_units_and_refuse_the_rest() {
        assert_eq!(parse_time("90s"), Ok(Duration::from_secs(90)));
        assert_eq!(parse_time("90"), Ok(Duration::from_secs(90)));
        assert_eq!(parse_time("1.5m"), Ok(Duration::from_secs(90)));
        assert_eq!(parse_time("500ms"), Ok(Duration::from_millis(500)));
        assert_eq!(parse_time("2h"), Ok(Duration::from_secs(7200)));
        for bad in ["", "0s", "-3s", "abc", "nan", "inf", "3 days"] {
            let e = parse_time(bad).unwrap_err();
            assert!(e.to_string().contains("expected a positive time"), "{bad}: {e}");
        }
        assert_eq!(parse_target_error("0.01"), Ok(0.01));
        for bad in ["0", "-1", "nan", "x"] {
            assert!(parse_target_error(bad).is_err(), "{bad}");
        }
    }
}
