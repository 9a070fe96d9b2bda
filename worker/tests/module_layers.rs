//! No file of the worker names a file that names it back, through any chain of files: the shared state and the
//! `Render` trait sit in `service.rs`, and the files of each concern (`server.rs`, `blobs.rs`, `strip.rs`) name
//! it, never the other way (docs/ARCHITECTURE.md, "The worker's modules"). The graph is core's
//! (`core/tests/layers/mod.rs`), over every file under `worker/src`; `python3 tools/structure.py --why` draws the
//! same.

#![allow(clippy::unwrap_used)]

#[path = "../../core/tests/layers/mod.rs"]
mod layers;

use std::path::Path;

#[test]
fn no_file_of_the_worker_names_a_file_that_names_it_back() {
    let cycles = layers::crate_cycles(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    assert!(
        cycles.is_empty(),
        "import cycles between the worker's files (python3 tools/structure.py --why shows them too):\n{}",
        cycles.join("\n")
    );
}
