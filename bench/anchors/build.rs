//! Compiles src/tinybvh_shim.cpp against the C++ header that tinybvh-rs bundles (tinybvh 1.6.8). The shim has no
//! `TINYBVH_IMPLEMENTATION`: its calls resolve to the tinybvh that tinybvh-rs's own build script compiled (with
//! -march=native), so the anchor times that crate's tinybvh. The header is looked up in cargo's registry sources
//! (`$CARGO_HOME/registry/src/*/tinybvh-rs-0.1.0-beta.3`, the exact version Cargo.toml pins), or in
//! `$TINYBVH_RS_DIR` where set (a vendored copy, say).

use std::path::PathBuf;

const CRATE_DIR: &str = "tinybvh-rs-0.1.0-beta.3";
const HEADER: &str = "ffi/tinybvh/tiny_bvh.h";

fn tinybvh_rs_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("TINYBVH_RS_DIR") {
        return dir.into();
    }
    let home = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")))
        .expect("neither CARGO_HOME nor HOME is set");
    let src = home.join("registry").join("src");
    let found = std::fs::read_dir(&src)
        .unwrap_or_else(|e| panic!("{}: {e}", src.display()))
        .filter_map(|d| d.ok())
        .map(|d| d.path().join(CRATE_DIR))
        .find(|d| d.join(HEADER).is_file());
    found.unwrap_or_else(|| panic!("{CRATE_DIR} not found under {}; set TINYBVH_RS_DIR", src.display()))
}

fn main() {
    let dir = tinybvh_rs_dir();
    cc::Build::new()
        .cpp(true)
        .std("c++20")
        // As tinybvh-rs compiles tinybvh (its build.rs): the header's inline code must match the library's.
        .flag("-march=native")
        // The header warns (#pragma GCC warning) about nothing we need; keep the build output quiet.
        .flag_if_supported("-Wno-unused-parameter")
        .include(dir.join("ffi/tinybvh"))
        .file("src/tinybvh_shim.cpp")
        .compile("anchors_tinybvh_shim");
    println!("cargo:rerun-if-changed=src/tinybvh_shim.cpp");
    println!("cargo:rerun-if-env-changed=TINYBVH_RS_DIR");
}
