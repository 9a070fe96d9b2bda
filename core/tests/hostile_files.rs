//! Files a careless user names as a mesh or a scene: OBJ materials we ignore, Latin-1 bytes, a folder, a FIFO,
//! `/dev/zero`, a file over the cap, megabyte-long lines, a scene that is not UTF-8. Each loads, or fails at
//! once with an error that names the file and the line or the setting, and quotes little of the input.

#![allow(clippy::unwrap_used)]

use glam::Affine3A;
use photon_core::geometry::mesh::{MeshError, Normals, load_obj};
use photon_core::prepare::Prepared;
use photon_core::scene::{Scene, SceneError};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-hostile-files-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn load(path: &Path, limit: u64) -> Result<usize, MeshError> {
    load_obj(path, &Affine3A::IDENTITY, Normals::default(), limit).map(|m| m.triangles.len())
}

const TRIANGLE: &[u8] = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

#[test]
fn obj_materials_and_latin1_bytes_are_read() {
    let dir = temp_dir("materials");
    // A material library whose only material has an empty name, which tobj refuses: never read.
    std::fs::write(dir.join("m.mtl"), "newmtl \n").unwrap();
    let obj = dir.join("with-mtl.obj");
    std::fs::write(&obj, [b"mtllib m.mtl\nusemtl red\n".as_slice(), TRIANGLE].concat()).unwrap();
    assert_eq!(load(&obj, 1 << 20).unwrap(), 1);
    // A Latin-1 é in a comment and in a group name.
    let latin1 = dir.join("latin1.obj");
    std::fs::write(&latin1, [b"# caf\xe9\ng caf\xe9\n".as_slice(), TRIANGLE].concat()).unwrap();
    assert_eq!(load(&latin1, 1 << 20).unwrap(), 1);
    // In a number it is an error of that line.
    let bad = dir.join("bad.obj");
    std::fs::write(&bad, b"v 0 0 0\nv 1 0 \xe9\nv 0 1 0\nf 1 2 3\n").unwrap();
    let e = load(&bad, 1 << 20).unwrap_err().to_string();
    assert!(e.contains("bad.obj:2:"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn only_regular_files_under_the_cap_are_read_and_nothing_hangs() {
    let dir = temp_dir("special");
    let fifo = dir.join("fifo.obj");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    let t0 = Instant::now();
    let mut cases = vec![(dir.clone(), "a folder"), (PathBuf::from("/dev/zero"), "a device")];
    if made {
        cases.push((fifo, "a FIFO"));
    }
    for (path, kind) in cases {
        let e = load(&path, 1 << 30).unwrap_err().to_string();
        assert!(e.contains(&format!("not a regular file but {kind}")), "{}: {e}", path.display());
    }
    assert!(t0.elapsed() < Duration::from_secs(2), "took {:?}", t0.elapsed());
    let big = dir.join("big.obj");
    std::fs::write(&big, TRIANGLE.repeat(100)).unwrap();
    let e = load(&big, 1000).unwrap_err().to_string();
    assert!(e.contains("big.obj") && e.contains("limits.mesh_mib"), "{e}");
    // A megabyte-long line is quoted in at most a few hundred characters.
    let long = dir.join("long.obj");
    std::fs::write(&long, format!("v 0 0 {}\n", "9".repeat(1 << 20))).unwrap();
    let e = load(&long, 1 << 30).unwrap_err().to_string();
    assert!(e.contains("long.obj:1:") && e.len() < 600, "{} bytes: {}", e.len(), &e[..e.len().min(600)]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_scene_naming_dev_zero_as_its_mesh_fails_with_the_field() {
    let dir = temp_dir("scene-mesh");
    let scene = dir.join("zero.toml");
    let text = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\n\n[materials.white]\ntype = \
                \"lambert\"\n\n[[objects]]\ntype = \"mesh\"\nfile = \"/dev/zero\"\nmaterial = \"white\"\n";
    std::fs::write(&scene, text).unwrap();
    let s = Scene::load(&scene).unwrap();
    let e = Prepared::new(&s, &scene).unwrap_err().to_string();
    assert!(e.contains("objects[0].file") && e.contains("not a regular file"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn scene_files_name_encoding_errors_and_are_read_only_when_regular() {
    let dir = temp_dir("scene");
    let path = dir.join("latin1.toml");
    std::fs::write(&path, b"[camera]\neye = [0.0, 1.0, 3.0] # caf\xe9\nlook_at = [0.0, 1.0, 0.0]\n").unwrap();
    let e = Scene::load(&path).unwrap_err();
    assert!(matches!(&e, SceneError::Encoding { at, .. } if at.line == 2 && at.offset == 36), "{e:?}");
    assert!(e.to_string().contains("latin1.toml:2: the scene is not UTF-8 text (byte offset 36)"), "{e}");
    let e = Scene::load(&dir).unwrap_err().to_string();
    assert!(e.contains("not a regular file but a folder"), "{e}");
    // A ten-megabyte string is quoted in a few hundred characters.
    let long = dir.join("long.toml");
    let text =
        format!("[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nfov = \"{}\"\n", "x".repeat(10 << 20));
    std::fs::write(&long, text).unwrap();
    let e = Scene::load(&long).unwrap_err().to_string();
    assert!(e.len() < 2000 && e.contains("line 4"), "{} bytes: {}", e.len(), &e[..e.len().min(2000)]);
    std::fs::remove_dir_all(&dir).unwrap();
}
