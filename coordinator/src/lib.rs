//! `photon-coordinator` as a library: the parts of the command line that are worth testing on their own.
//!
//! [`scheduler`] decides which worker renders which strip of rows. It is a pure state machine (no clock, no
//! network, no async): the caller feeds it events with the time they happened and acts on what it returns, so
//! every policy decision can be replayed in a unit test.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod scheduler;
pub mod sweep;
