//! How each worker gets a job's photon maps: **shipped** from the coordinator (which traces them once, builds
//! them and uploads the blob to every worker), passed among **peers** (the coordinator uploads the blob to one
//! worker at a time and every worker holding it sends it on to another, [`crate::fleet::swarm`]), or **traced** by
//! every worker itself from the deterministic photon streams (only the scene blob travels). All give the same
//! maps, bit for bit, so the image does not depend on the choice; only the time does.
//!
//! [`choose`] decides per job from a cost model calibrated on this machine: it traces a sample of the job's
//! photon paths here, builds, encodes and decodes their map, and scales the measured costs to the job
//! ([`Calibration`]). For each mode the model gives the mean time until a worker holds its maps
//! ([`Estimate`]):
//!
//! - ship: `(P·t_path + build(n)) / T_c + encode(B) + N · B/link + mean_w (decode(B) + build(n)) / T_w`,
//!   the N uploads running at once and sharing the coordinator's link fairly, so every worker waits for N blob
//!   times (measured on namespaced hosts: docs/RESULTS.md, "The farm on a network");
//! - peers: the same with `mean_i (⌊log₂ i⌋ + 1) · B/link` for the upload, the i-th worker receiving in round
//!   ⌊log₂ i⌋ + 1 over links of its own (the holders double each round); workers on this machine share one
//!   link, and then peers cost what shipping does;
//! - trace: `mean_w (P·t_path + build(n)) / T_w`,
//!
//! with `P` photon paths of `n` photons in a blob of `B` bytes, `T_c` threads here, `N` workers of `T_w`
//! threads, and `build(n) ∝ n log n` (sorting and the kd-tree). Tracing and building are taken to scale
//! linearly with threads, which favours neither mode. The link is loopback for in-process and `--local`
//! workers (300 MB/s, measured in docs/RESULTS.md "Shipping photon maps"); for remote ones it is measured before
//! the job is prepared ([`crate::fleet::measure_link`]: the median over the workers of a padded hello's bytes
//! per second), and taken as 1 Gbit/s (125 MB/s) where no probe could be timed. The peers' links are taken to
//! be as fast as the coordinator's; where the coordinator's alone is slow, peers are underestimated.

use photon_core::codec;
use photon_core::photon::{PhotonMap, PhotonMaps};
use photon_core::prepare::Prepared;
use photon_core::prepare::photons::{PhotonKind, trace_photons};
use std::fmt;
use std::time::Instant;

/// How workers get the photon maps (`--photon-maps`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MapDelivery {
    /// Chosen per job by the cost model.
    Auto,
    /// Traced here once and shipped to every worker.
    Ship,
    /// Traced here once, uploaded to one worker at a time and passed on among the workers.
    Peers,
    /// Traced by every worker itself.
    Trace,
}

impl MapDelivery {
    /// Whether the coordinator traces the maps and the job carries them as a blob.
    pub fn ships(self) -> bool {
        matches!(self, Self::Ship | Self::Peers)
    }
}

/// Bytes per second of a loopback upload (docs/RESULTS.md, "Shipping photon maps": 300–334 MB/s).
pub const LOOPBACK_BYTES_PER_S: f64 = 300e6;

/// Bytes per second of a lab's link: 1 Gbit/s.
pub const LINK_BYTES_PER_S: f64 = 125e6;

/// The most photon paths traced to calibrate the model (an eighth of the job's when that is fewer).
pub const SAMPLE_PATHS: u64 = 40_000;

/// Costs measured on this machine from a sample of the job's photon paths, per unit and per thread.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Seconds of one thread per photon path traced.
    pub trace_s_per_path: f64,
    /// Photons stored per path.
    pub photons_per_path: f64,
    /// Seconds of one thread per `n log₂ n` to sort `n` photons and build their kd-tree.
    pub build_s_per_nlogn: f64,
    /// Blob bytes per photon.
    pub bytes_per_photon: f64,
    /// Seconds per blob byte to encode.
    pub encode_s_per_byte: f64,
    /// Seconds per blob byte to decode (the photons only; the tree's rebuild is `build`).
    pub decode_s_per_byte: f64,
}

/// The workers as the model sees them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Farm {
    /// Threads of each worker.
    pub worker_threads: Vec<u32>,
    /// Threads of this machine, which traces and builds the maps it ships.
    pub coordinator_threads: u32,
    /// Bytes per second of the coordinator's link, which the uploads share, and of each worker's.
    pub link_bytes_per_s: f64,
    /// The workers run on this machine and share its one link (loopback).
    pub shared_link: bool,
    /// Whether `link_bytes_per_s` was measured before the job was prepared (rather than assumed).
    pub link_measured: bool,
}

/// The model's mean seconds until a worker holds the maps, for each mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// The link's bytes per second, when it was measured ([`Farm::link_measured`]).
    pub measured_link: Option<f64>,
    /// Shipped from here.
    pub ship_s: f64,
    /// Traced by each worker.
    pub trace_s: f64,
    /// Passed among the workers.
    pub peers_s: f64,
}

/// What was chosen, and why.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// [`MapDelivery::Ship`], [`MapDelivery::Peers`] or [`MapDelivery::Trace`].
    pub mode: MapDelivery,
    /// Whether `--photon-maps` forced it.
    pub forced: bool,
    /// The model's estimate (none when forced).
    pub estimate: Option<Estimate>,
}

impl Calibration {
    /// Measures the costs by tracing a sample of the job's `paths` (an eighth, between 1000 and
    /// [`SAMPLE_PATHS`]) global photon paths of `prep` on the current
    /// rayon pool, building their map, and encoding and decoding it. `None` when the sample stores no photon
    /// (a scene whose light reaches no surface: either mode is then free).
    pub fn measure(prep: &Prepared, paths: u64) -> Option<Self> {
        // An eighth of the job at most, so that measuring costs little beside the work it decides.
        let sample = (paths / 8).clamp(1000, SAMPLE_PATHS).min(paths.max(1));
        let threads = rayon::current_num_threads() as f64;
        let t = Instant::now();
        // Stream index 7 keeps the sample apart from the real maps' streams (only its costs are used).
        let traced = trace_photons(prep, sample, 7, PhotonKind::Global);
        let trace_s = t.elapsed().as_secs_f64() * threads;
        let n = traced.photons.len();
        if n < 2 {
            return None;
        }
        let t = Instant::now();
        let map = PhotonMap::build(traced.photons).ok()?;
        let build_s = t.elapsed().as_secs_f64() * threads;
        let maps = PhotonMaps {
            global: map,
            caustic: None,
            estimator: prep.estimator(),
            irradiance: None,
            volume: None,
            volume_gather: prep.volume_gather(),
        };
        let t = Instant::now();
        let blob = codec::encode(&maps).ok()?;
        let encode_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        codec::decode::<PhotonMaps>(&blob, blob.len()).ok()?;
        // The decode rebuilds the (already sorted) tree on the whole pool: count that part as build.
        let decode_s = (t.elapsed().as_secs_f64() - build_s / threads).max(0.0);
        let nf = n as f64;
        Some(Self {
            trace_s_per_path: trace_s / sample as f64,
            photons_per_path: nf / sample as f64,
            build_s_per_nlogn: build_s / (nf * nf.log2()),
            bytes_per_photon: blob.len() as f64 / nf,
            encode_s_per_byte: encode_s / blob.len() as f64,
            decode_s_per_byte: decode_s / blob.len() as f64,
        })
    }

    /// The model's estimate for `paths` photon paths on `farm` (formulas in the module documentation).
    pub fn estimate(&self, paths: u64, farm: &Farm) -> Estimate {
        let p = paths as f64;
        let n = (p * self.photons_per_path).max(2.0);
        let bytes = n * self.bytes_per_photon;
        let trace = p * self.trace_s_per_path;
        let build = self.build_s_per_nlogn * n * n.log2();
        let threads_c = f64::from(farm.coordinator_threads.max(1));
        let workers = farm.worker_threads.len().max(1) as f64;
        let mean_over_workers = |f: &dyn Fn(f64) -> f64| {
            let sum: f64 = farm.worker_threads.iter().map(|&t| f(f64::from(t.max(1)))).sum();
            sum / workers
        };
        let prepare = (trace + build) / threads_c + self.encode_s_per_byte * bytes;
        let upload = workers * bytes / farm.link_bytes_per_s;
        let load = mean_over_workers(&|t| self.decode_s_per_byte * bytes + build / t);
        let n = farm.worker_threads.len().max(1);
        let rounds = (1..=n).map(|i| f64::from(i.ilog2() + 1)).sum::<f64>() / n as f64;
        let relay = if farm.shared_link { upload } else { rounds * bytes / farm.link_bytes_per_s };
        Estimate {
            measured_link: farm.link_measured.then_some(farm.link_bytes_per_s),
            ship_s: prepare + upload + load,
            trace_s: mean_over_workers(&|t| (trace + build) / t),
            peers_s: prepare + relay + load,
        }
    }
}

/// Decides how the workers of `farm` get the maps of `prep` (whose settings say how many paths), measuring
/// the costs here when `requested` is [`MapDelivery::Auto`].
pub fn choose(requested: MapDelivery, prep: &Prepared, farm: &Farm) -> Decision {
    if requested != MapDelivery::Auto {
        return Decision { mode: requested, forced: true, estimate: None };
    }
    let paths = prep.photon_map_paths();
    let Some(calibration) = Calibration::measure(prep, paths) else {
        return Decision { mode: MapDelivery::Trace, forced: false, estimate: None };
    };
    let estimate = calibration.estimate(paths, farm);
    tracing::info!(?calibration, ?estimate, "photon-map delivery model");
    // The cheapest; on a tie the one that moves fewer bytes, then the one with fewer moving parts.
    let mode = [
        (estimate.trace_s, MapDelivery::Trace),
        (estimate.ship_s, MapDelivery::Ship),
        (estimate.peers_s, MapDelivery::Peers),
    ]
    .into_iter()
    .reduce(|best, next| if next.0 < best.0 { next } else { best })
    .map_or(MapDelivery::Trace, |(_, mode)| mode);
    Decision { mode, forced: false, estimate: Some(estimate) }
}

impl fmt::Display for Decision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match self.mode {
            MapDelivery::Trace => "traced by each worker",
            MapDelivery::Peers => "traced here and passed among the workers",
            _ => "traced here and shipped",
        };
        match (self.forced, self.estimate) {
            (true, _) => write!(f, "{what} (--photon-maps)"),
            (false, Some(e)) => {
                write!(
                    f,
                    "{what} (modelled {:.2} s traced, {:.2} s shipped, {:.2} s among peers",
                    e.trace_s, e.ship_s, e.peers_s
                )?;
                match e.measured_link {
                    Some(bps) => write!(f, "; link measured at {:.1} MB/s)", bps / 1e6),
                    None => write!(f, ")"),
                }
            }
            (false, None) => write!(f, "{what}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn calibration() -> Calibration {
        // Roughly this machine's costs (docs/RESULTS.md, "Photon maps without a serial bottleneck").
        Calibration {
            trace_s_per_path: 1.5e-6,
            photons_per_path: 1.67,
            build_s_per_nlogn: 2.0e-8,
            bytes_per_photon: 36.0,
            encode_s_per_byte: 2.5e-9,
            decode_s_per_byte: 5e-9,
        }
    }

    fn farm(workers: &[u32], coordinator: u32, link: f64) -> Farm {
        Farm {
            worker_threads: workers.to_vec(),
            coordinator_threads: coordinator,
            link_bytes_per_s: link,
            shared_link: link == LOOPBACK_BYTES_PER_S,
            link_measured: false,
        }
    }

    #[test]
    fn one_worker_as_strong_as_the_coordinator_traces_for_itself() {
        // The same work either way, but shipping adds encoding, the upload and decoding.
        let e = calibration().estimate(1_000_000, &farm(&[8], 8, LOOPBACK_BYTES_PER_S));
        assert!(e.trace_s < e.ship_s, "{e:?}");
    }

    #[test]
    fn weak_workers_get_costly_maps_shipped() {
        // Sixteen one-thread workers beside a 16-thread coordinator, on a scene whose paths cost ten times the
        // Cornell box's for the photons they store (long paths through glass): each worker would trace every
        // path on one thread, while the coordinator traces them once on sixteen.
        let costly = Calibration { trace_s_per_path: 1.5e-5, ..calibration() };
        let e = costly.estimate(4_000_000, &farm(&[1; 16], 16, LOOPBACK_BYTES_PER_S));
        assert!(e.ship_s < e.trace_s, "{e:?}");
        // With the Cornell box's cost per path, shipping 16 blobs through one loopback link costs more.
        let e = calibration().estimate(4_000_000, &farm(&[1; 16], 16, LOOPBACK_BYTES_PER_S));
        assert!(e.trace_s < e.ship_s, "{e:?}");
    }

    #[test]
    fn a_lab_behind_one_link_traces() {
        // 52 machines of 4–96 threads behind 1 Gbit/s: 52 uploads of a big map cost more than tracing it.
        let mut lab = vec![6; 20];
        lab.extend([4; 30]);
        lab.extend([32, 96]);
        let e = calibration().estimate(4_000_000, &farm(&lab, 6, LINK_BYTES_PER_S));
        assert!(e.trace_s < e.ship_s, "{e:?}");
        // Shipping grows with the number of workers, tracing does not.
        let two = calibration().estimate(4_000_000, &farm(&[6, 6], 6, LINK_BYTES_PER_S));
        assert!(e.ship_s > 5.0 * two.ship_s && (e.trace_s - two.trace_s).abs() < two.trace_s, "{e:?} {two:?}");
    }

    #[test]
    fn peers_win_where_shipping_would_and_the_link_is_the_cost() {
        // The costly scene of weak_workers_get_costly_maps_shipped, on 52 one-thread machines behind 1 Gbit/s:
        // 52 uploads sharing one link cost more than tracing, and passing the blob on among the workers beats
        // both.
        let costly = Calibration { trace_s_per_path: 1.5e-5, ..calibration() };
        let lab = farm(&[1; 52], 16, LINK_BYTES_PER_S);
        let e = costly.estimate(4_000_000, &lab);
        assert!(e.peers_s < e.trace_s && e.trace_s < e.ship_s, "{e:?}");
        // The i-th worker receives in round ⌊log₂ i⌋ + 1: 52 workers wait 4.90 blob times on average, not the 52
        // of uploads sharing one link.
        let bytes = 4e6 * 1.67 * 36.0;
        let saved = e.ship_s - e.peers_s;
        assert!((saved - (52.0 - 255.0 / 52.0) * bytes / LINK_BYTES_PER_S).abs() < 1e-6 * saved, "{e:?}");
        // One worker: one upload either way.
        let one = costly.estimate(4_000_000, &farm(&[1], 16, LINK_BYTES_PER_S));
        assert!((one.peers_s - one.ship_s).abs() < 1e-9, "{one:?}");
        // Workers on this machine share its link: passing the blob on saves nothing.
        let local = costly.estimate(4_000_000, &farm(&[1; 16], 16, LOOPBACK_BYTES_PER_S));
        assert_eq!(local.peers_s, local.ship_s);
    }

    #[test]
    fn the_link_decides_between_passing_the_maps_on_and_tracing_them() {
        // The costly scene on eight two-thread workers beside a 16-thread coordinator: over 1 Gbit/s the blob is
        // best passed among peers; over the 100 Mbit/s that fleet::measure_link would find on a slower lab,
        // each worker tracing the paths itself is cheaper than 2.6 blob times at a tenth of the speed.
        let costly = Calibration { trace_s_per_path: 1.5e-5, ..calibration() };
        let mut lab = farm(&[2; 8], 16, LINK_BYTES_PER_S);
        let gigabit = costly.estimate(4_000_000, &lab);
        assert!(gigabit.peers_s < gigabit.trace_s && gigabit.peers_s < gigabit.ship_s, "{gigabit:?}");
        lab.link_bytes_per_s = 12.5e6;
        lab.link_measured = true;
        let slow = costly.estimate(4_000_000, &lab);
        assert!(slow.trace_s < slow.peers_s && slow.peers_s < slow.ship_s, "{slow:?}");
        // Tracing does not depend on the link; the uploads scale with its time per byte.
        assert_eq!(slow.trace_s, gigabit.trace_s);
        let decision = Decision { mode: MapDelivery::Trace, forced: false, estimate: Some(slow) };
        assert!(decision.to_string().ends_with("; link measured at 12.5 MB/s)"), "{decision}");
    }

    #[test]
    fn the_calibration_measures_the_scene() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
        let scene = photon_core::scene::Scene::load(&path).unwrap();
        let prep = Prepared::new(&scene, &path).unwrap();
        let c = Calibration::measure(&prep, 10_000).unwrap();
        // Every photon of a map is 36 bytes; the closed Cornell box stores more than one photon per path.
        assert!((c.bytes_per_photon - 36.0).abs() < 0.5, "{c:?}");
        assert!(c.photons_per_path > 1.0 && c.photons_per_path < 10.0, "{c:?}");
        assert!(c.trace_s_per_path > 0.0 && c.build_s_per_nlogn > 0.0 && c.encode_s_per_byte > 0.0, "{c:?}");
        let forced = choose(MapDelivery::Ship, &prep, &farm(&[1], 1, LINK_BYTES_PER_S));
        assert_eq!((forced.mode, forced.forced, forced.estimate), (MapDelivery::Ship, true, None));
    }
}
