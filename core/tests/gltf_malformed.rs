//! Claim: a malformed glTF is an error that names the file and what was expected, never a panic: every cut of
//! a GLB, a missing buffer file, a buffer shorter than its `byteLength`, an index past the vertices, an
//! accessor of the wrong type, text that is not JSON; through a scene file the error also names the scene and
//! `objects[i].file`.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder};
use photon_core::prepare::Prepared;
use photon_core::prepare::gltf::import;
use photon_core::scene::Scene;
use std::path::Path;

/// One triangle with these indices; with `vec2_normals`, NORMAL of two components.
fn triangle(indices: &[u16], vec2_normals: bool) -> Builder {
    let mut b = Builder::default();
    let p = b.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let normals = if vec2_normals {
        format!(r#","NORMAL":{}"#, b.vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]))
    } else {
        String::new()
    };
    let i = b.indices(indices);
    b.member(&format!(r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}{normals}}},"indices":{i}}}]}}]"#));
    b.member(r#""nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]"#);
    b
}

fn error(path: &Path) -> String {
    match import(path, &glam::Affine3A::IDENTITY, 1 << 30, 1 << 30) {
        Ok(_) => panic!("{} imported", path.display()),
        Err(e) => e.to_string(),
    }
}

fn assert_names(e: &str, parts: &[&str]) {
    for p in parts {
        assert!(e.contains(p), "`{p}` missing from: {e}");
    }
}

#[test]
fn every_cut_of_a_glb_fails_cleanly() {
    let dir = folder("cut-glb");
    let glb = triangle(&[0, 1, 2], false).glb();
    let path = dir.join("cut.glb");
    std::fs::write(&path, &glb).unwrap();
    import(&path, &glam::Affine3A::IDENTITY, 1 << 30, 1 << 30).unwrap();
    for len in 0..glb.len() {
        std::fs::write(&path, &glb[..len]).unwrap();
        let e = error(&path);
        assert_names(&e, &["cut.glb"]);
        assert!(e.contains("malformed glTF") || e.contains("cannot read"), "{len}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn each_malformed_file_says_what_was_expected() {
    let dir = folder("malformed");
    // A buffer file that is not there.
    let missing = dir.join("missing.gltf");
    triangle(&[0, 1, 2], false).write_gltf_with_bin(&missing, "gone.bin");
    std::fs::remove_file(dir.join("gone.bin")).unwrap();
    assert_names(&error(&missing), &["gone.bin", "cannot read"]);
    // A buffer file shorter than its byteLength.
    let short = dir.join("short.gltf");
    triangle(&[0, 1, 2], false).write_gltf_with_bin(&short, "short.bin");
    std::fs::write(dir.join("short.bin"), [0u8; 10]).unwrap();
    assert_names(&error(&short), &["short.gltf", "buffers[0] holds 10 bytes", "byteLength"]);
    // An index past the three vertices.
    let index = dir.join("index.gltf");
    triangle(&[0, 1, 5], false).write_gltf(&index);
    assert_names(
        &error(&index),
        &["index.gltf", "meshes[0].primitives[0].indices[2] is 5, out of range", "3 vertices"],
    );
    // Normals of two components.
    let vec2 = dir.join("vec2.gltf");
    triangle(&[0, 1, 2], true).write_gltf(&vec2);
    assert_names(&error(&vec2), &["vec2.gltf", "NORMAL (accessors[1]) is Vec2", "expected Vec3"]);
    // Not JSON, and JSON that is not glTF (an accessor index out of range).
    let text = dir.join("text.gltf");
    std::fs::write(&text, "this is not json").unwrap();
    assert_names(&error(&text), &["text.gltf", "not valid glTF JSON"]);
    let dangling = dir.join("dangling.gltf");
    let json = triangle(&[0, 1, 2], false).json(Some("x.bin")).replace(r#""POSITION":0"#, r#""POSITION":9"#);
    std::fs::write(&dangling, json).unwrap();
    assert_names(&error(&dangling), &["dangling.gltf", "invalid glTF", "POSITION"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_scene_names_itself_the_object_and_the_file() {
    let dir = folder("scene-error");
    triangle(&[0, 1, 7], false).write_gltf(&dir.join("bad.gltf"));
    let scene = dir.join("scene.toml");
    std::fs::write(
        &scene,
        "[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\n[[objects]]\ntype = \"gltf\"\nfile = \"bad.gltf\"\n",
    )
    .unwrap();
    let e = Prepared::new(&Scene::load(&scene).unwrap(), &scene).unwrap_err().to_string();
    assert_names(&e, &["scene.toml", "objects[0].file", "bad.gltf", "out of range"]);
    let _ = std::fs::remove_dir_all(&dir);
}
