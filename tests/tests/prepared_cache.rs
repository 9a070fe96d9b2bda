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

/// A torus of `scenes/meshes` (Lambert: level of detail applies) seen from `z` units along +z.
fn lod_scene(dir: &Path, z: f32) -> std::path::PathBuf {
    let text = format!(
        "[camera]\neye = [0.0, 0.5, {z}]\nlook_at = [0.0, 0.0, 0.0]\n\
         [materials.white]\ntype = \"lambert\"\nalbedo = 0.7\n\
         [[objects]]\ntype = \"plane\"\npoint = [0.0, -1.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\nmaterial = \"white\"\n\
         [[objects]]\ntype = \"mesh\"\nfile = \"{}\"\nmaterial = \"white\"\n\
         [[lights]]\ntype = \"point\"\nposition = [2.0, 4.0, 3.0]\npower = [300.0, 300.0, 300.0]\n",
        scenes_dir().join("meshes/torus.obj").display()
    );
    let path = dir.join(format!("torus-{z}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// Renders `scene` with the path tracer (no photons: only the scene blob goes through the cache); the summary.
fn render_path(scene: &Path, cache: &Path, out: &Path) -> String {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scene).arg("-o").arg(out).arg("-q").arg("--cache-dir").arg(cache);
    cmd.args(["--size", "32x24", "--spp", "1", "--integrator", "path"]);
    let o = run_with_timeout(&mut cmd, Duration::from_secs(120));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    summary(&o)
}

#[test]
fn a_mesh_simplified_for_another_view_is_not_reused() {
    let dir = temp_dir("prepared-cache", "lod");
    let cache = dir.join("cache");
    let near = render_path(&lod_scene(&dir, 3.0), &cache, &dir.join("near.exr"));
    assert!(near.ends_with("scene built"), "{near}");
    // Ten times farther: the bound grows tenfold, and the torus is simplified anew.
    let far = render_path(&lod_scene(&dir, 30.0), &cache, &dir.join("far.exr"));
    assert!(far.ends_with("scene built"), "{far}");
    // A camera moved by 0.1 %: the same quantised bound, the same mesh, from the cache.
    let nudged = render_path(&lod_scene(&dir, 30.03), &cache, &dir.join("nudged.exr"));
    assert!(nudged.ends_with("scene cached"), "{nudged}");
    // The log says what level of detail did.
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(lod_scene(&dir, 30.0)).arg("-o").arg(dir.join("log.exr")).args(["-q", "--no-cache"]);
    cmd.args(["--size", "32x24", "--spp", "1"]).env("RUST_LOG", "photon_core=info");
    let o = run_with_timeout(&mut cmd, Duration::from_secs(120));
    assert!(o.status.success());
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("torus.obj: ") && log.contains(" triangles → ") && log.contains("(lod 0.25, error "), "{log}");
}
