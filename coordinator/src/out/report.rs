//! What a render tells the user: the warnings printed while it runs ([`Warning`]), and at the end one line per
//! worker ([`WorkerReport`], printed by [`print_workers`]) and the summary line of `render` ([`Summary`]) of
//! the finished render ([`Outcome`]).

use crate::farm::bounded::BoundedReport;
use crate::job::delivery::MapDelivery;
use crate::job::prepared_cache::Hits;
use photon_core::method::{PassStorage, StaticMaps};
use photon_core::scene::RenderSettings;
use std::fmt;
use std::path::Path;

/// Four significant digits, in scientific notation outside [0.001, 10 000): the numbers of `compare` and of the
/// sweep's tables.
pub fn sig(x: f64) -> String {
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

/// One worker's line in the final report.
#[derive(Clone, Debug)]
pub struct WorkerReport {
    /// Its name.
    pub name: String,
    /// Architecture and OS (`x86_64 linux`), empty if it never answered.
    pub platform: String,
    /// Render threads.
    pub threads: u32,
    /// Strips accepted from it.
    pub strips: u32,
    /// Seconds with a strip in flight.
    pub busy_s: f64,
    /// Megapixels accepted per busy second.
    pub mpix_per_s: f64,
    /// Blob bytes shipped to it from the coordinator.
    pub shipped_bytes: u64,
    /// Blob bytes it fetched from other workers (`--photon-maps peers`).
    pub fetched_bytes: u64,
    /// Seconds spent shipping to it.
    pub ship_s: f64,
    /// Speculative copies it was given (tail duplicates of strips running elsewhere).
    pub speculative: u32,
    /// Its results dropped because another copy won.
    pub duplicates: u32,
    /// Failures it had, and why it stopped, if it did.
    pub failures: u32,
    /// Photon paths traced by its accepted results (progressive passes).
    pub photon_paths: u64,
    /// Seconds it spent tracing those photons and building their maps (partly beside its gathering).
    pub photon_s: f64,
    /// Seconds it spent decoding the job's blobs (the scene, and photon maps when shipped).
    pub load_s: f64,
    /// `ok` (with the times it rejoined after it was lost), `stalled`, or why it was refused, lost or dropped.
    pub state: String,
}

/// A finished render ([`crate::farm::render`]): the image and what the report says of it.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Linear RGB, row-major.
    pub pixels: Vec<f32>,
    /// Rays traced (by accepted strips).
    pub rays: u64,
    /// Photon paths traced by accepted strips (progressive passes; the other methods trace theirs when the job
    /// is prepared).
    pub photon_paths: u64,
    /// One line per worker.
    pub workers: Vec<WorkerReport>,
    /// Seconds from the start until the first worker was ready (connection, hello and shipping).
    pub ship_s: f64,
    /// Seconds from the first worker ready to the last strip.
    pub render_s: f64,
    /// Strips resumed from a partial file.
    pub resumed: usize,
    /// What a render bounded by time or error did: passes (samples) in the image, rounds, why it stopped.
    pub bounded: Option<BoundedReport>,
    /// A bounded render's rounds and image sums, for a render that goes on from them
    /// ([`crate::farm::Options::continuation`]).
    pub continuation: Option<Box<crate::farm::bounded::Continuation>>,
}

/// The per-worker table.
pub fn print_workers(workers: &[WorkerReport]) {
    println!(
        "{:<16} {:<14} {:>7} {:>6} {:>8} {:>8} {:>10} {:>10} {:>7} {:>7} {:>12} {:>8} {:>8} {:>8}  state",
        "worker",
        "platform",
        "threads",
        "units",
        "busy s",
        "Mpx/s",
        "shipped",
        "from peers",
        "ship s",
        "load s",
        "photon paths",
        "photon s",
        "spec/dup",
        "failures"
    );
    for w in workers {
        println!(
            "{:<16} {:<14} {:>7} {:>6} {:>8.2} {:>8.3} {:>10} {:>10} {:>7.2} {:>7.2} {:>12} {:>8.2} {:>8} {:>8}  {}",
            w.name,
            w.platform,
            w.threads,
            w.strips,
            w.busy_s,
            w.mpix_per_s,
            human_bytes(w.shipped_bytes),
            human_bytes(w.fetched_bytes),
            w.ship_s,
            w.load_s,
            w.photon_paths,
            w.photon_s,
            format!("{}/{}", w.speculative, w.duplicates),
            w.failures,
            w.state
        );
    }
}

/// A byte count for people: B, KiB or MiB with one decimal.
pub fn human_bytes(b: u64) -> String {
    match b {
        0..1024 => format!("{b} B"),
        1024..1_048_576 => format!("{:.1} KiB", b as f64 / 1024.0),
        _ => format!("{:.1} MiB", b as f64 / 1_048_576.0),
    }
}

/// What the summary line of a finished render says besides the [`Outcome`].
pub struct Summary<'a> {
    /// The image written.
    pub output: &'a Path,
    /// Its size in pixels.
    pub size: (u32, u32),
    /// The settings it was rendered with.
    pub settings: &'a RenderSettings,
    /// Seconds spent preparing the scene.
    pub prepare_s: f64,
    /// Seconds spent writing the image.
    pub assemble_s: f64,
    /// Which prepared blobs came from the cache, when there is one.
    pub hits: Option<Hits>,
    /// How the workers got the photon maps, for the methods that read them.
    pub delivery: Option<crate::job::delivery::Decision>,
}

impl Summary<'_> {
    /// The line: size, budget, method, times, ray rate, bytes shipped, and what was resumed or cached.
    pub fn line(&self, outcome: &Outcome) -> String {
        let settings = self.settings;
        let (width, height) = self.size;
        // The methods that render in passes (progressive, vcm, bdpt, lt) take one camera sample per pass; the
        // others take `spp`. A bounded render took as many as its completed rounds hold.
        let ph = &settings.photons;
        let (spp, passes) = outcome.bounded.as_ref().map_or((settings.spp, ph.passes), |b| (b.passes, b.passes));
        let method = settings.integrator;
        let units = if method.renders_passes() { passes } else { spp };
        // One light subpath per pixel and pass; in a scene with media a subpath method's passes are the
        // volumetric path tracer's samples, and no light path is traced.
        let media = outcome.photon_paths == 0 && passes > 0;
        let mut samples = method.work_words(units, u64::from(width) * u64::from(height), ph.pass_photons, media);
        match (method.pass_storage(), method.static_maps(), self.delivery) {
            (PassStorage::PhotonMap, _, _) => {
                samples.push_str(&format!(" ({} paths traced on the workers)", outcome.photon_paths));
            }
            (_, StaticMaps::None, _) => {}
            (_, _, Some(d)) if d.mode == MapDelivery::Trace => {
                samples.push_str(&format!(", photon maps {d}: {} paths traced on the workers", outcome.photon_paths));
            }
            (_, _, Some(d)) => samples.push_str(&format!(", photon maps of {} paths {d}", ph.global)),
            (_, _, None) => samples.push_str(&format!(", photon maps of {} paths traced here", ph.global)),
        }
        if let Some(b) = &outcome.bounded {
            samples.push_str(&format!(" in {} rounds, stopped {}", b.rounds, b.reason));
            if let Some(e) = b.rel_mse_estimate {
                samples.push_str(&format!(" (estimated relMSE {e:.3e})"));
            }
        }
        let units = if settings.integrator.renders_passes() { "pass blocks" } else { "strips" };
        let mut extras =
            if outcome.resumed > 0 { format!(", {} {units} resumed", outcome.resumed) } else { String::new() };
        if let Some(h) = self.hits {
            let word = |hit: bool| if hit { "cached" } else { "built" };
            extras.push_str(&format!(", scene {}", word(h.scene)));
            if settings.integrator.needs_photon_maps() && self.delivery.is_none_or(|d| d.mode.ships()) {
                extras.push_str(&format!(", photons {}", word(h.photons)));
            }
        }
        let fetched = outcome.workers.iter().map(|w| w.fetched_bytes).sum::<u64>();
        let peers = if fetched > 0 { format!(" (+{fetched} passed between workers)") } else { String::new() };
        format!(
            "{}: {width}x{height}, {samples}, {}, {:.2} s render (+{:.2} s prepare, {:.2} s ship, {:.2} s assemble), \
             {:.2} Mrays/s, {} blob bytes shipped{peers}{extras}",
            self.output.display(),
            settings.integrator,
            outcome.render_s,
            self.prepare_s,
            outcome.ship_s,
            self.assemble_s,
            outcome.rays as f64 / outcome.render_s.max(1e-9) / 1e6,
            outcome.workers.iter().map(|w| w.shipped_bytes).sum::<u64>()
        )
    }
}

/// Something the user should hear about while the render goes on; the loop prints each as it happens.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Warning {
    /// Two workers compute with different math modes.
    MixedMath {
        /// The worker that just became ready, and its mode.
        worker: String,
        /// Its math mode.
        mode: String,
        /// A worker already ready with another mode.
        other: String,
        /// That worker's mode.
        other_mode: String,
    },
    /// A worker could not be connected to, or refused the job.
    Refused {
        /// The worker.
        worker: String,
        /// Why.
        reason: String,
    },
    /// An active worker's connection was lost.
    Lost {
        /// The worker.
        worker: String,
        /// Why.
        reason: String,
    },
    /// A worker was blocked after too many failed units of the job: it gets no more.
    Blocked {
        /// The worker.
        worker: String,
        /// Why.
        reason: String,
    },
    /// A lost worker answered again and takes strips again.
    Rejoined {
        /// The worker.
        worker: String,
        /// Blob bytes shipped to it again.
        shipped: u64,
    },
    /// A worker holds strips and has said nothing for longer than its silence limit.
    Stalled {
        /// The worker.
        worker: String,
        /// The limit.
        silence: std::time::Duration,
    },
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MixedMath { worker, mode, other, other_mode } => write!(
                f,
                "workers compute with different math modes ({mode} on {worker}, {other_mode} on {other}): their \
                 strips may differ in the last bits, and the image depends on which worker rendered what"
            ),
            Self::Refused { worker, reason } => write!(f, "worker {worker}: {reason}"),
            Self::Lost { worker, reason } => {
                write!(f, "worker {worker} lost ({reason}); its strips go to the others while it is called back")
            }
            Self::Blocked { worker, reason } => write!(f, "worker {worker} blocked: {reason}"),
            Self::Rejoined { worker, shipped } => {
                write!(f, "worker {worker} rejoined ({} shipped again); it takes strips again", human_bytes(*shipped))
            }
            Self::Stalled { worker, silence } => write!(
                f,
                "worker {worker} stalled: no progress for over {:.1} s; its strips are issued again to the others",
                silence.as_secs_f64()
            ),
        }
    }
}

/// The progress bar of a render (hidden unless `show`), counting `units` (strips, pass blocks) from those resumed.
pub fn progress_bar(show: bool, strips: usize, resumed: usize, units: &str) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(strips as u64);
    let template =
        format!("{{spinner}} [{{elapsed_precise}}] {{bar:32}} {{pos}}/{{len}} {units}, ~{{eta}} left {{msg}}");
    if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar.set_position(resumed as u64);
    bar
}
