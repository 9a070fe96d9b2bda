//! Generates the gRPC code from render.proto with protox (pure Rust: no protoc), and computes the build id.

use std::path::{Path, PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=render.proto");
    let fds = protox::compile(["render.proto"], ["."])?;
    tonic_prost_build::configure().compile_fds(fds)?;

    // The build id: a hash of every file that decides what a worker renders or how it speaks (core, proto,
    // worker and the locked dependency versions). Two binaries with the same id render the same pixels from the
    // same blobs; a coordinator and a worker with different ids refuse to work together. The coordinator's own
    // command-line code is left out, so changing it does not force redeploying workers.
    // Read when the script runs, not when it is compiled: a script compiled for one checkout and reused by
    // another (worktrees sharing a target folder) must hash the files of the checkout it builds.
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").ok_or("CARGO_MANIFEST_DIR is not set")?).join("..");
    let mut files = Vec::new();
    for dir in ["core/src", "proto/src", "worker/src"] {
        collect(&root.join(dir), &mut files)?;
        println!("cargo:rerun-if-changed={}", root.join(dir).display());
    }
    for file in ["core/Cargo.toml", "proto/Cargo.toml", "proto/render.proto", "worker/Cargo.toml", "Cargo.lock"] {
        let path = root.join(file);
        if path.is_file() {
            println!("cargo:rerun-if-changed={}", path.display());
            files.push(path);
        }
    }
    files.sort();
    // FNV-1a, 64 bits, over (relative path, length, bytes) of each file: stable across machines and architectures.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for path in &files {
        let rel = path.strip_prefix(&root).unwrap_or(path).to_string_lossy().replace('\\', "/");
        let bytes = std::fs::read(path)?;
        feed(rel.as_bytes());
        feed(&(bytes.len() as u64).to_le_bytes());
        feed(&bytes);
    }
    println!("cargo:rustc-env=PHOTON_BUILD_ID={h:016x}");
    Ok(())
}

fn collect(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            collect(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    Ok(())
}
