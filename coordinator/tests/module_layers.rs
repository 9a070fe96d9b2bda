//! No file of the coordinator names a file that names it back, through any chain of files: the coordinator's
//! modules form layers too (docs/ARCHITECTURE.md, "The coordinator's modules"). The graph is core's
//! (`core/tests/layers/mod.rs`: `use` items and paths in code, resolved to files; test modules and comments not
//! counted), over every file under `coordinator/src`; `python3 tools/structure.py --why` draws the same.

#![allow(clippy::unwrap_used)]

#[path = "../../core/tests/layers/mod.rs"]
mod layers;

use std::path::Path;

#[test]
fn no_file_of_the_coordinator_names_a_file_that_names_it_back() {
    let cycles = layers::crate_cycles(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    assert!(
        cycles.is_empty(),
        "import cycles between the coordinator's files (python3 tools/structure.py --why shows them too):\n{}",
        cycles.join("\n")
    );
}
