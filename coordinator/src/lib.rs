//! `photon-coordinator` as a library: the parts of the command line that are worth testing on their own.
//!
//! [`scheduler`] decides which worker renders which strip of rows. It is a pure state machine (no clock, no
//! network, no async): the caller feeds it events with the time they happened and acts on what it returns, so
//! every policy decision can be replayed in a unit test. [`farm`] is that caller: it talks to the workers over
//! gRPC, ships blobs, validates strips and assembles the image. [`fleet`] finds the workers: a host list, an
//! address list, worker processes on loopback, or a worker server inside this process (the default, so a
//! render on one machine takes the same path as one on many). [`prepared_cache`] keeps prepared blobs on disk
//! for the next render of an unchanged scene. [`sweep`] charts error against time.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod farm;
pub mod fleet;
pub mod prepared_cache;
pub mod scheduler;
pub mod sweep;
