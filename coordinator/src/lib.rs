//! `photon-coordinator` as a library: the command line's commands, and the parts worth testing on their own.
//!
//! [`scheduler`] decides which worker renders which strip of rows. It is a pure state machine (no clock, no
//! network, no async): the caller feeds it events with the time they happened and acts on what it returns, so
//! every policy decision can be replayed in a unit test. [`farm`] is that caller: its event loop owns the
//! scheduler, validates strips and assembles the image. [`session`] is one worker's side of the wire: connect,
//! hello, blob upload in chunks, strip fetch, and the classification of a failed strip. [`job`] is what a render
//! ships (the blobs and frame of a prepared scene, prepared through the cache) and what an interrupted one
//! leaves for `--resume`. [`delivery`] decides whether a job's photon maps are shipped to the workers, passed
//! among them ([`swarm`]) or traced by each of them. [`fleet`] finds the workers: a host list, an address list,
//! worker processes on loopback, or a worker server inside this process (the default, so a render on one machine
//! takes the same path as one on many). [`prepared_cache`] keeps prepared blobs on disk for the next render of
//! an unchanged scene. [`rejoin`] calls lost workers back with backoff, and [`interrupt`] turns SIGINT and
//! SIGTERM into a render that stops keeping what is finished. [`report`] is what the user reads: warnings during
//! the render, the worker table and the summary line; [`live`] serves a web page of the render while it runs.
//! [`sweep`] charts error against time. [`bounded`] sizes the rounds of a render bounded by time or estimated
//! error and estimates that error without a reference. [`model`] is a discrete-event model of a lab farm that
//! drives the real scheduler with a simulated clock and network.
//! [`overrides`] turns the flags that override scene settings, and the sweep's budgets, into the `KEY=VALUE`
//! pairs of `--set`. [`cli`] holds the command line's arguments and [`commands`] runs them.
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
//! use photon_coordinator::scheduler::Policy;
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

pub mod bounded;
pub mod cli;
pub mod commands;
pub mod delivery;
pub mod farm;
pub mod fleet;
pub mod interrupt;
pub mod job;
pub mod live;
pub mod model;
pub mod overrides;
pub mod prepared_cache;
pub mod rejoin;
pub mod report;
pub mod scheduler;
pub mod session;
pub mod swarm;
pub mod sweep;
