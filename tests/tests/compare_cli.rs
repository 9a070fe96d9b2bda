//! `photon-coordinator compare` end to end: two tiny renders of the Cornell box with different seeds differ by
//! finite, non-zero metrics; an image against itself has zero error; a size mismatch or a missing file fails
//! with status 1 and a message naming the files and the sizes.
#![allow(clippy::unwrap_used)]

use photon_tests::{coordinator, scenes_dir, temp_dir};
use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Output};

/// Renders the Cornell box to `dir/name` (EXR) at `size` with the path tracer at 4 spp and `seed`.
fn render(dir: &Path, name: &str, size: &str, seed: u64) {
    let scene = scenes_dir().join("cornell.toml");
    let out = Command::new(coordinator())
        .current_dir(dir)
        .arg("render")
        .arg(&scene)
        .args(["-o", name, "--size", size, "--integrator", "path", "--spp", "4", "--seed", &seed.to_string()])
        .args(["-q", "--threads", "1"])
        .output()
        .unwrap();
    assert!(out.status.success(), "render failed: {}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join(name).is_file());
}

/// Runs `photon-coordinator compare ARGS…` in `dir`.
fn compare(dir: &Path, args: &[&str]) -> Output {
    Command::new(coordinator()).current_dir(dir).arg("compare").args(args).output().unwrap()
}

/// The `key=value` line of a successful compare, parsed; asserts success and a single such line.
fn key_values(out: &Output) -> HashMap<String, String> {
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "stdout: {stdout}\nstderr: {}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<&str> = stdout.lines().filter(|l| l.starts_with("rmse=")).collect();
    assert_eq!(lines.len(), 1, "one machine-readable line expected in: {stdout}");
    lines[0]
        .split_whitespace()
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap();
            (k.to_owned(), v.to_owned())
        })
        .collect()
}

fn number(kv: &HashMap<String, String>, key: &str) -> f64 {
    kv.get(key).unwrap_or_else(|| panic!("`{key}` missing from {kv:?}")).parse().unwrap()
}

#[test]
fn two_seeds_differ_and_an_image_matches_itself() {
    let dir = temp_dir("compare-cli", "seeds");
    render(&dir, "a.exr", "16x16", 1);
    render(&dir, "b.exr", "16x16", 2);

    let out = compare(&dir, &["a.exr", "b.exr", "--error-image", "err.png"]);
    let kv = key_values(&out);
    for key in ["rmse", "rel_mse", "mare", "bias", "rel_bias"] {
        assert!(number(&kv, key).is_finite(), "{key} = {}", kv[key]);
    }
    for key in ["rmse", "rel_mse", "mare", "max_abs", "differing"] {
        assert!(number(&kv, key) > 0.0, "different seeds gave {key} = 0");
    }
    assert_eq!(kv["region"], "0,0,16,16");
    let stdout = String::from_utf8_lossy(&out.stdout);
    for label in ["RMSE", "relative MSE", "mean abs. relative error", "bias over", "largest difference"] {
        assert!(stdout.contains(label), "`{label}` missing from: {stdout}");
    }
    let err = photon_core::image_io::Image::read(&dir.join("err.png")).unwrap();
    assert_eq!((err.width, err.height), (16, 16));

    let same = key_values(&compare(&dir, &["a.exr", "a.exr", "--region", "2,3,10,12"]));
    for key in ["rmse", "rel_mse", "mare", "bias", "rel_bias", "max_abs", "differing"] {
        assert_eq!(number(&same, key), 0.0, "{key} of an image against itself");
    }
    assert_eq!(same["region"], "2,3,10,12");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Asserts status 1, no panic, and every one of `parts` in stderr.
fn assert_clean_failure(out: &Output, parts: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
    for p in parts {
        assert!(stderr.contains(p), "`{p}` missing from stderr: {stderr}");
    }
}

#[test]
fn size_mismatch_and_missing_files_fail_clearly() {
    let dir = temp_dir("compare-cli", "errors");
    render(&dir, "big.exr", "16x16", 1);
    render(&dir, "small.exr", "8x16", 1);
    let out = compare(&dir, &["small.exr", "big.exr", "--error-image", "err.png"]);
    assert_clean_failure(&out, &["small.exr", "big.exr", "8x16", "16x16"]);
    assert!(!dir.join("err.png").exists(), "an error image was written despite the error");
    let out = compare(&dir, &["big.exr", "no-such.exr"]);
    assert_clean_failure(&out, &["no-such.exr"]);
    let out = compare(&dir, &["big.exr", "big.exr", "--region", "0,0,17,4"]);
    assert_clean_failure(&out, &["0,0,17,4", "16x16"]);
    let _ = std::fs::remove_dir_all(&dir);
}
