//! `photon-sweep`: speed against accuracy. Renders a scene with each method at growing budgets on photon's
//! workers, measures every image against a reference, and summarises the curves of relative MSE against wall time
//! in a CSV, two charts, equal-time and equal-error tables and one HTML page.
//!
//! A tool apart from `photon-coordinator`, so that the renderer's build has no charts or fonts: it renders
//! through the coordinator's library, as `render` does ([`photon_coordinator::measure::render_timed`]).
//!
//! - [`cli`]: the command line and the sweep it runs;
//! - [`budget`]: how a budget multiplier becomes a method's setting, and the CSV's rows;
//! - [`curve`]: each method's curve and log-log interpolation along it;
//! - [`table`]: the equal-time and equal-error tables;
//! - [`chart`]: the chart, as SVG and PNG;
//! - [`report`]: each method's image and error map, and `report.html`.
//!
//! `cargo run --release -p photon-sweep -- SCENE --reference REF.exr` (docs/USAGE.md, "Measuring error").
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod budget;
pub mod chart;
pub mod cli;
pub mod curve;
#[cfg(test)]
mod fixtures;
pub mod report;
pub mod table;
