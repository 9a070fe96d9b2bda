//! `photon-coordinator`: the photon command line. The commands live in the library ([`photon_coordinator::cli::commands`]).
#![forbid(unsafe_code)]

use clap::Parser;
use photon_coordinator::cli::{Cli, commands};

fn main() {
    commands::init_logging();
    // `photon-coordinator … | head` closes the pipe early: end quietly, as a SIGPIPE would, not with a panic.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg = payload.downcast_ref::<String>().map(String::as_str).or(payload.downcast_ref::<&str>().copied());
        if msg.is_some_and(|m| m.starts_with("failed printing to stdout")) {
            std::process::exit(141);
        }
        default_hook(info);
    }));
    if let Err(e) = commands::run(Cli::parse()) {
        eprintln!("error: {e:#}");
        // A render stopped by a signal ends as the signal would have ended it (130, 143).
        let code = e.downcast_ref::<commands::Interrupted>().map_or(1, |i| i.exit_code);
        std::process::exit(code);
    }
}
