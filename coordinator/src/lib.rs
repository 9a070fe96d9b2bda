//! `photon-coordinator` as a library: the command line's commands, and the parts worth testing on their own.
//!
//! The folders follow a render from the command line to the image:
//!
//! - [`cli`]: the arguments, the flags that override scene settings as `--set` pairs ([`cli::overrides`]), and
//!   the commands that run them ([`cli::commands`]).
//! - [`job`]: what a render ships, the blobs and frame of a prepared scene, and what an interrupted render
//!   leaves for `--resume`; whether the photon maps are shipped, passed among the workers or traced by each
//!   ([`job::delivery`]); the disk cache of prepared blobs ([`job::prepared_cache`]).
//! - [`fleet`]: the workers. Where they come from: a host list, an address list, worker processes on loopback,
//!   or a worker server inside this process (the default, so a render on one machine takes the same path as one
//!   on many). One worker's side of the wire, with the classification of a failed strip ([`fleet::session`]);
//!   blobs passed among them ([`fleet::swarm`]); lost workers called back with backoff ([`fleet::rejoin`]);
//!   SIGINT and SIGTERM turned into a render that stops keeping what is finished ([`fleet::interrupt`]).
//! - [`farm`]: the render. Its event loop validates strips and assembles the image; the scheduler decides which
//!   worker renders which strip ([`farm::scheduler`], a pure state machine with no clock, network or async, so
//!   every policy decision can be replayed in a unit test); a render bounded by time or estimated error runs in
//!   rounds and estimates that error without a reference ([`farm::bounded`]).
//! - [`out`]: what the user reads: warnings during the render, the worker table and the summary line
//!   ([`out::report`]), and a web page of the render while it runs ([`out::live`]).
//!
//! Beside them: [`measure`] chooses a reference's method and times a render on the workers (for `reference`, and
//! for the sweep of error against time, a tool of its own in `tools/sweep/`, `photon-sweep`, so that its charts
//! and fonts are not part of the renderer's build); [`model`] is a discrete-event model of a lab farm that drives
//! the real scheduler with a simulated clock and network.
//!
//! The user's manual is the repository's `README.md`; `docs/ARCHITECTURE.md` the design, `docs/RESULTS.md` the
//! measurements.
//!
//! ## Example
//!
//! The farm model: a job of 400 rows costing one core-second each, on one 4-core worker and on two, with the
//! real scheduler and a 1 Gbit/s network. Two identical workers take about half the time.
//!
//! ```
//! use photon_coordinator::model::{Network, SimJob, SimWorker, simulate};
//! use photon_coordinator::farm::scheduler::Policy;
//!
//! let job = SimJob {
//!     units: 400,
//!     units_per_strip: 4,
//!     core_s_per_unit: 1.0,
//!     result_bytes_fixed: 0.0,
//!     result_bytes_per_unit: 12_000.0,
//!     blob_bytes: 1e6,
//!     prepare_s: 0.0,
//!     load_core_s: 0.0,
//!     thread_efficiency: 1.0,
//!     relay: false,
//! };
//! let worker = SimWorker { cores: 4, core_speed: 1.0, dies_at: None };
//! let one = simulate(&job, &[worker.clone()], &Network::gigabit(), Policy::default());
//! let two = simulate(&job, &[worker.clone(), worker], &Network::gigabit(), Policy::default());
//! assert!((one.makespan_s - 100.0).abs() < 1.0); // 400 core-s on 4 cores
//! assert!((two.makespan_s / one.makespan_s - 0.5).abs() < 0.05);
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod auto;
pub mod cli;
pub mod farm;
pub mod fleet;
pub mod job;
pub mod measure;
pub mod model;
pub mod out;
