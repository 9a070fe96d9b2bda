//! The coordinator's prepared-blob cache: an unchanged scene is not prepared again, the cached render has the
//! same bytes, and a changed mesh file or photon setting is never served from a stale entry.

#![allow(clippy::unwrap_used)]

use photon_tests::{coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

fn render(scene: &Path, cache: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scene).arg("-o").arg(out).arg("-q").arg("--cache-dir").arg(cache);
    // Shipped maps: the coordinator traces them, so they go through its cache (traced ones never do).
    cmd.args(["--size", "32x24", "--spp", "2", "--integrator", "photon-map", "--photons", "5000"]);
    if !extra.contains(&"--photon-maps") {
        cmd.args(["--photon-maps", "ship"]);
    }
    cmd.args(extra);
    let o = run_with_timeout(&mut cmd, Duration::from_secs(120));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

fn summary(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).lines().last().unwrap_or_default().to_owned()
}

#[test]
fn unchanged_scenes_come_from_the_cache_and_changed_ones_do_not() {
    let dir = temp_dir("prepared-cache", "keys");
    // A copy of the mesh scene, so its OBJ file can be changed.
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::copy(scenes_dir().join("mesh.toml"), dir.join("mesh.toml")).unwrap();
    for f in ["torus.obj", "icosphere.obj"] {
        std::fs::copy(scenes_dir().join("meshes").join(f), dir.join("meshes").join(f)).unwrap();
    }
    let (scene, cache) = (dir.join("mesh.toml"), dir.join("cache"));
    let first = render(&scene, &cache, &dir.join("a.exr"), &[]);
    assert!(summary(&first).ends_with("scene built, photons built"), "{}", summary(&first));
    let second = render(&scene, &cache, &dir.join("b.exr"), &[]);
    assert!(summary(&second).ends_with("scene cached, photons cached"), "{}", summary(&second));
    assert_eq!(std::fs::read(dir.join("a.exr")).unwrap(), std::fs::read(dir.join("b.exr")).unwrap());
    // Other photon settings: the scene is reused, the photons are traced again.
    let third = render(&scene, &cache, &dir.join("c.exr"), &["--seed", "9"]);
    assert!(summary(&third).ends_with("scene cached, photons built"), "{}", summary(&third));
    // A changed mesh file (even by a comment: the bytes are hashed): nothing is reused.
    let obj = dir.join("meshes/torus.obj");
    let text = std::fs::read_to_string(&obj).unwrap();
    std::fs::write(&obj, text + "\n# changed\n").unwrap();
    let fourth = render(&scene, &cache, &dir.join("d.exr"), &[]);
    assert!(summary(&fourth).ends_with("scene built, photons built"), "{}", summary(&fourth));
    // Maps the workers trace are neither read from the cache nor stored in it; the image is the same.
    let traced = render(&scene, &cache, &dir.join("t.exr"), &["--photon-maps", "trace"]);
    assert!(summary(&traced).ends_with("scene cached"), "{}", summary(&traced));
    assert_eq!(std::fs::read(dir.join("d.exr")).unwrap(), std::fs::read(dir.join("t.exr")).unwrap());
    // --no-cache says nothing of the cache.
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(&scene).arg("-o").arg(dir.join("e.exr")).args(["-q", "--no-cache", "--size", "8x8"]);
    let o = run_with_timeout(&mut cmd, Duration::from_secs(120));
    assert!(o.status.success());
    assert!(!summary(&o).contains("cached") && !summary(&o).contains("built"), "{}", summary(&o));
}
