//! `photon-sweep`: error against time for several methods. The sweep lives in the library
//! ([`photon_sweep::cli::run`]).
#![forbid(unsafe_code)]

use clap::Parser;
use photon_sweep::cli::{SweepArgs, run};

fn main() {
    photon_coordinator::cli::commands::init_logging();
    if let Err(e) = run(SweepArgs::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
