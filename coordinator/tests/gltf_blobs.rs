//! Claim: a glTF's textures ship once over the farm: two jobs of the shipped glTF scene that differ only in the
//! camera (through a scene file, and rendered directly with `--set camera.eye=…`) have the same scene blob and
//! the same texture blobs (the floor's embedded checker among them), so the second ships only its frame.

#![allow(clippy::unwrap_used)]

use photon_coordinator::job::delivery::Decision;
use photon_coordinator::job::{Job, prepare_job};
use photon_core::prepare::Prepared;
use photon_core::prepare::gltf::direct::load_scene;
use std::path::{Path, PathBuf};

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

fn job(path: &Path, overrides: &[&str]) -> Job {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let scene = load_scene(path, &overrides).unwrap();
    let no_photons = |_: &Prepared| -> Decision { unreachable!("the path tracer has no photon maps") };
    prepare_job(&scene, path, None, no_photons).unwrap().0
}

#[test]
fn a_new_camera_ships_no_new_blob() {
    for (path, base) in [
        (scenes().join("gltf-showcase.toml"), vec!["camera.width=16", "camera.height=16"]),
        (scenes().join("gltf/showcase.glb"), vec!["camera.width=16", "camera.height=16"]),
    ] {
        let a = job(&path, &base);
        let moved: Vec<&str> = base.iter().copied().chain(["camera.eye=[1.0, 3.0, 5.0]"]).collect();
        let b = job(&path, &moved);
        assert_ne!(a.frame, b.frame, "{}: the camera did not change", path.display());
        assert_eq!(a.scene_blob, b.scene_blob, "{}", path.display());
        assert!(!a.texture_blobs.is_empty(), "{}: no texture blob", path.display());
        assert_eq!(a.texture_blobs, b.texture_blobs, "{}", path.display());
        let new: Vec<&String> = b.blobs.keys().filter(|k| !a.blobs.contains_key(*k)).collect();
        assert!(new.is_empty(), "{}: new blobs {new:?}", path.display());
    }
}
