//! `photon-coordinator render model.glb` renders a glTF directly: the shipped showcase at a size given on the
//! command line, with its own camera and lights, each warning about what it does not support printed once; and
//! the shipped glTF and PLY scenes through two `--local` workers give the in-process bits, by every method.
#![allow(clippy::unwrap_used)]

use photon_tests::{coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::process::Command;
use std::time::Duration;

#[test]
fn a_glb_renders_directly() {
    let dir = temp_dir("gltf-render", "direct");
    let out = dir.join("showcase.png");
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("gltf/showcase.glb")).arg("-o").arg(&out);
    cmd.args(["--size", "48x32", "--spp", "4", "--threads", "2"]);
    let o = run_with_timeout(&mut cmd, Duration::from_secs(120));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (48, 32));
    let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 8)).count();
    assert!(lit > 48 * 32 / 4, "only {lit} pixels lit");
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("WARN") && l.contains("showcase.glb")).collect();
    for w in &warnings {
        let text = w.split("showcase.glb: ").nth(1).unwrap_or(w);
        assert_eq!(warnings.iter().filter(|x| x.ends_with(text)).count(), 1, "printed more than once: {w}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The pixels of an EXR, as bits.
fn bits(path: &std::path::Path) -> Vec<u32> {
    photon_core::image_io::Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// The shipped glTF scene and the PLY mesh scene, by every method, through two `--local` workers: the
/// in-process bits.
#[test]
fn the_gltf_and_ply_scenes_render_the_same_bits_through_two_local_workers_with_every_method() {
    let dir = temp_dir("gltf-render", "farm");
    for scene in ["gltf-showcase.toml", "ply-mesh.toml"] {
        for method in ["path", "direct", "photon-map", "final-gather", "progressive", "vcm", "bdpt", "lt"] {
            let render = |name: &str, extra: &[&str]| {
                let out = dir.join(format!("{method}-{name}.exr"));
                let mut cmd = Command::new(coordinator());
                cmd.arg("render").arg(scenes_dir().join(scene)).arg("-o").arg(&out).arg("-q");
                cmd.args(["--size", "24x16", "--spp", "2", "--passes", "2", "--photons", "8000"]);
                cmd.args(["--integrator", method, "--set", "render.photons.final_gather_rays=2", "--no-cache"]);
                let o = run_with_timeout(cmd.args(extra), Duration::from_secs(240));
                assert!(o.status.success(), "{scene} {method} {name}: {}", String::from_utf8_lossy(&o.stderr));
                bits(&out)
            };
            let in_process = render("in-process", &[]);
            assert!(in_process.iter().any(|&v| f32::from_bits(v) > 0.0), "{scene} {method}: black");
            assert!(render("local", &["--local", "2"]) == in_process, "{scene} {method}: --local 2 changed pixels");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
