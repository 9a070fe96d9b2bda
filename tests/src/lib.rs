//! Helpers shared by photon's end-to-end tests, which run the binaries as a user runs them.
//!
//! `photon-coordinator` is another package's binary, so Cargo does not build it for these tests and
//! `CARGO_BIN_EXE_…` is not set. [`coordinator`] runs `cargo build -p photon-coordinator` once per test process
//! (a no-op when the binary is fresh; it builds it when missing or stale) in the profile and target folder of the
//! running test executable, then returns `<target>/<profile>/photon-coordinator`, found from
//! `std::env::current_exe()` (`<target>/<profile>/deps/<test>-…`).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The coordinator binary, built on first use. Panics (failing the test) when it cannot be built.
pub fn coordinator() -> &'static Path {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        let exe = std::env::current_exe().unwrap_or_else(|e| panic!("cannot locate the test executable: {e}"));
        // <target>/<profile>/deps/<test>-HASH
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .unwrap_or_else(|| panic!("{} is not in <target>/<profile>/deps", exe.display()))
            .to_path_buf();
        let target_dir =
            profile_dir.parent().unwrap_or_else(|| panic!("{} has no parent folder", profile_dir.display()));
        let profile = profile_dir.file_name().map(|p| p.to_string_lossy().into_owned()).unwrap_or_default();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.toml");
        let mut build = Command::new(cargo);
        build.args(["build", "--quiet", "-p", "photon-coordinator", "--manifest-path"]).arg(&manifest);
        build.arg("--target-dir").arg(target_dir);
        match profile.as_str() {
            "debug" => {}
            "release" => {
                build.arg("--release");
            }
            other => {
                build.args(["--profile", other]);
            }
        }
        let status = build.status().unwrap_or_else(|e| panic!("cannot run cargo: {e}"));
        assert!(status.success(), "`cargo build -p photon-coordinator` failed: {status}");
        let bin = profile_dir.join(format!("photon-coordinator{}", std::env::consts::EXE_SUFFIX));
        assert!(bin.is_file(), "{} missing after the build", bin.display());
        bin
    })
}

/// A fresh, empty folder `photon-<suite>-<pid>-<test>` in the system's temporary folder.
pub fn temp_dir(suite: &str, test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-{suite}-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
    dir
}

/// The workspace's `scenes` folder.
pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}
