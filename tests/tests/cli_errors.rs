//! The command line on malformed scenes: exit status 1 (not a panic's 101), and a message on stderr that names
//! the file and the field or line. The binary is built and found by [`photon_tests::coordinator`].
#![allow(clippy::unwrap_used)]

use photon_tests::coordinator;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh folder for one test.
fn temp_dir(test: &str) -> PathBuf {
    photon_tests::temp_dir("cli-errors", test)
}

/// Runs `photon-coordinator render SCENE -o DIR/out.png` in `dir`, with the scene named relative to `dir`.
fn render(dir: &Path, scene: &str) -> Output {
    Command::new(coordinator())
        .current_dir(dir)
        .args(["render", scene, "-o", "out.png", "--quiet", "--threads", "1"])
        .output()
        .unwrap()
}

/// Asserts a clean failure: status 1, no panic, no image, and stderr containing every one of `parts`; returns
/// stderr.
fn assert_clean_failure(dir: &Path, out: &Output, parts: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
    assert!(!dir.join("out.png").exists(), "an image was written despite the error");
    for p in parts {
        assert!(stderr.contains(p), "`{p}` missing from stderr: {stderr}");
    }
    stderr
}

const CAMERA: &str = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nwidth = 8\nheight = 8\n";
const WHITE: &str = "[materials.white]\ntype = \"lambert\"\n";

#[test]
fn valid_scene_renders() {
    let dir = temp_dir("valid");
    let light = "[[lights]]\ntype = \"point\"\nposition = [0.0, 2.0, 0.0]\npower = [10.0, 10.0, 10.0]\n";
    let sphere = "[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 1.0, 0.0]\nradius = 0.5\nmaterial = \"white\"\n";
    std::fs::write(dir.join("ok.toml"), format!("{CAMERA}[render]\nspp = 1\n{WHITE}{sphere}{light}")).unwrap();
    let out = render(&dir, "ok.toml");
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("out.png").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn invalid_value_names_the_file_and_the_field() {
    let dir = temp_dir("nan-radius");
    let sphere = "[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 1.0, 0.0]\nradius = nan\nmaterial = \"white\"\n";
    std::fs::write(dir.join("bad-radius.toml"), format!("{CAMERA}{WHITE}{sphere}")).unwrap();
    let out = render(&dir, "bad-radius.toml");
    assert_clean_failure(&dir, &out, &["bad-radius.toml", "objects[0].radius", "positive"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn parse_errors_name_the_file_and_the_line() {
    let dir = temp_dir("parse");
    std::fs::write(dir.join("negative-width.toml"), CAMERA.replace("width = 8", "width = -5")).unwrap();
    let out = render(&dir, "negative-width.toml");
    assert_clean_failure(&dir, &out, &["negative-width.toml", "line 4", "expected u32"]);
    std::fs::write(dir.join("unknown-field.toml"), format!("{CAMERA}zoom = 2.0\n")).unwrap();
    let out = render(&dir, "unknown-field.toml");
    assert_clean_failure(&dir, &out, &["unknown-field.toml", "line 6", "unknown field `zoom`"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_mesh_names_the_scene_the_field_and_the_obj_line() {
    let dir = temp_dir("mesh");
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::write(dir.join("meshes/bad.obj"), "v 0 0 0\nv 1 0 0\nv 1 zz 0\nf 1 2 3\n").unwrap();
    let mesh = "[[objects]]\ntype = \"mesh\"\nfile = \"meshes/bad.obj\"\nmaterial = \"white\"\n";
    std::fs::write(dir.join("bad-mesh.toml"), format!("{CAMERA}{WHITE}{mesh}")).unwrap();
    let out = render(&dir, "bad-mesh.toml");
    let stderr = assert_clean_failure(&dir, &out, &["bad-mesh.toml", "objects[0].file", "bad.obj:3"]);
    assert_eq!(stderr.matches("bad.obj:3").count(), 1, "the cause is repeated: {stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_scene_file_is_named() {
    let dir = temp_dir("missing");
    let out = render(&dir, "no-such-scene.toml");
    assert_clean_failure(&dir, &out, &["no-such-scene.toml", "cannot read the scene file"]);
    let _ = std::fs::remove_dir_all(&dir);
}
