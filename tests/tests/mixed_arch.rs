//! An x86-64 worker and an aarch64 worker (run under `qemu-aarch64`) on one render, over loopback.
//!
//! The aarch64 worker is the one `deploy/aarch64/build.sh` builds (`PHOTON_AARCH64_WORKER` names another).
//! Without it or without `qemu-aarch64` these tests say so and pass, unless `PHOTON_REQUIRE_AARCH64` is set, as
//! `.ci/run` sets it: then a missing binary fails them.
//!
//! Strips rendered on the two architectures must agree to the bit (`photon_core::math::fmath`), so the image of a
//! mixed farm is the image of an x86 farm, whoever rendered which strip.

#![allow(clippy::unwrap_used)]

#[allow(dead_code)]
#[path = "../../core/benches/shared/meshes.rs"]
mod meshes;

use photon_core::image_io::Image;
use photon_core::metrics::compare;
use photon_tests::{WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(600);

/// The aarch64 worker and the emulator to run it with, or why they are missing.
fn aarch64_worker() -> Result<(PathBuf, PathBuf), String> {
    let bin = std::env::var_os("PHOTON_AARCH64_WORKER").map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../target/aarch64/aarch64-unknown-linux-gnu/release/photon-worker")
        },
        PathBuf::from,
    );
    if !bin.is_file() {
        return Err(format!("no aarch64 worker at {} (build it with deploy/aarch64/build.sh)", bin.display()));
    }
    let qemu = std::env::var_os("PATH")
        .and_then(|path| std::env::split_paths(&path).map(|d| d.join("qemu-aarch64")).find(|p| p.is_file()))
        .ok_or("no qemu-aarch64 on PATH (Debian's qemu-user)")?;
    Ok((qemu, bin))
}

/// Starts the aarch64 worker under emulation, or returns `None` (the test is skipped) when it cannot run here
/// and `PHOTON_REQUIRE_AARCH64` is not set.
fn start_aarch64(args: &[&str]) -> Option<WorkerProcess> {
    match aarch64_worker() {
        Ok((qemu, bin)) => {
            let mut cmd = Command::new(qemu);
            cmd.arg(bin);
            Some(WorkerProcess::start_command(cmd, "127.0.0.1:0", args))
        }
        Err(why) if std::env::var_os("PHOTON_REQUIRE_AARCH64").is_some() => {
            panic!("PHOTON_REQUIRE_AARCH64 is set but {why}")
        }
        Err(why) => {
            eprintln!("skipped: {why}");
            None
        }
    }
}

fn render(scene: &str, out: &Path, job: &[&str], workers: &str) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join(scene)).arg("-o").arg(out).args(job).args(["--workers", workers]);
    let o = run_with_timeout(&mut cmd, LIMIT);
    if String::from_utf8_lossy(&o.stderr).contains("is not this worker's build") {
        panic!(
            "a worker was built from other code: rebuild the aarch64 worker (deploy/aarch64/build.sh)\n{}",
            text(&o)
        );
    }
    assert!(o.status.success(), "{}", text(&o));
    o
}

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Values of the two images whose bits differ, and the largest absolute difference (`photon-coordinator compare`).
fn difference(a: &Path, b: &Path) -> (u64, f64) {
    let m = compare(&Image::read(a).unwrap(), &Image::read(b).unwrap(), None).unwrap();
    (m.differing, m.max_abs)
}

/// The strips and speculative copies column of a worker's row in the coordinator's table.
fn strips_and_speculative(o: &Output, addr: &str) -> (u32, u32) {
    let row = WorkerRow::find(&String::from_utf8_lossy(&o.stdout), addr)
        .unwrap_or_else(|| panic!("no row for {addr}: {}", text(o)));
    (row.units as u32, row.speculative)
}

/// A bumpy icosphere of 20·4⁵ = 20480 triangles of about unit radius, as OBJ text: deep enough BVHs (two of
/// them in a scene) for the wide traversal's ordering, ties on shared edges and SIMD box tests to matter.
fn bumpy_icosphere_obj() -> String {
    let (vertices, faces) = meshes::bumpy_icosphere(5);
    let mut obj = String::new();
    for p in &vertices {
        obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for f in &faces {
        obj += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    obj
}

/// Every code path a worker runs: the camera, spheres (their UVs), rectangles, meshes with interpolated normals,
/// Lambert, mirror, glass and Phong lobes, textures, bump and normal maps, photon gathering, photon tracing itself
/// (progressive passes are traced on the workers), and a scene of two 20k-triangle meshes. Each job is rendered
/// by the x86-64 worker alone and the aarch64 worker alone.
#[test]
fn aarch64_and_x86_64_workers_render_identical_strips() {
    let Some(arm) = start_aarch64(&["--threads", "2"]) else { return };
    let x86 = WorkerProcess::start(&["--threads", "2"]);
    let dir = temp_dir("mixed-arch", "agree");
    // mesh.toml with its torus (glossy) and icosphere (glass) both replaced by the bumpy icosphere; the glass
    // keeps level of detail off, so both meshes keep all their triangles.
    std::fs::write(dir.join("bumpy.obj"), bumpy_icosphere_obj()).unwrap();
    let scene = std::fs::read_to_string(scenes_dir().join("mesh.toml")).unwrap();
    let scene = scene.replace("meshes/torus.obj", "bumpy.obj").replace("meshes/icosphere.obj", "bumpy.obj");
    let big = dir.join("big-mesh.toml");
    std::fs::write(&big, scene).unwrap();
    let big = big.to_string_lossy().into_owned();
    let jobs: [(&str, &[&str]); 19] = [
        ("cornell.toml", &["--size", "48x36", "--spp", "2", "--integrator", "photon-map", "--photons", "20000"]),
        ("mesh.toml", &["--size", "40x40", "--spp", "2", "--integrator", "path"]),
        ("caustic-point.toml", &["--size", "40x30", "--integrator", "progressive", "--passes", "3"]),
        // Checker, image (sRGB table), bump and normal maps: lookups, finite differences and tangent frames.
        ("textured.toml", &["--size", "40x40", "--spp", "2", "--integrator", "path"]),
        ("textured.toml", &["--size", "32x32", "--integrator", "progressive", "--passes", "2"]),
        // Vertex connection and merging: light subpaths, connections, merges and light-tracing splats.
        ("cornell.toml", &["--size", "32x24", "--integrator", "vcm", "--passes", "3"]),
        ("rooms/cornell-spheres.toml", &["--size", "32x32", "--integrator", "vcm", "--passes", "2"]),
        // `join` keeps an absolute path as it is.
        (&big, &["--size", "40x40", "--spp", "2", "--integrator", "path"]),
        // Media: free flights, equiangular sampling, HG directions, transmittance (exp, log1p, atan2, tan),
        // interface crossings and volume photon maps.
        ("fog.toml", &["--size", "32x32", "--spp", "2", "--integrator", "path"]),
        ("fog.toml", &["--size", "32x32", "--integrator", "progressive", "--passes", "2", "--photons", "20000"]),
        ("volume-caustic.toml", &["--size", "32x24", "--spp", "1", "--integrator", "photon-map", "--photons", "20000"]),
        // Rough metal and glass: visible-normal sampling, masking, Fresnel terms and their MIS with the lights;
        // photons stored on the metal and walked through the glass.
        ("rough-spheres.toml", &["--size", "32x32", "--spp", "2", "--integrator", "path"]),
        ("rough-spheres.toml", &["--size", "32x32", "--integrator", "vcm", "--passes", "2"]),
        (
            "rough-spheres.toml",
            &["--size", "32x32", "--integrator", "progressive", "--passes", "2", "--photons", "20000"],
        ),
        // An HDR environment (its image lookups, sampled directions and disc emission) and a spot light.
        ("sky.toml", &["--size", "32x20", "--spp", "2", "--integrator", "path"]),
        ("sky.toml", &["--size", "32x20", "--integrator", "vcm", "--passes", "2"]),
        ("sky.toml", &["--size", "32x20", "--integrator", "progressive", "--passes", "2", "--photons", "20000"]),
        // A glTF file: its node transforms, metallic–roughness materials, embedded textures, a normal map in the
        // frame of TANGENT attributes, a cut-out (alphaMode MASK) and a punctual spot light.
        ("gltf-showcase.toml", &["--size", "32x20", "--spp", "2", "--integrator", "path"]),
        ("gltf-showcase.toml", &["--size", "32x20", "--integrator", "vcm", "--passes", "2"]),
    ];
    for (scene, job) in jobs {
        let (a, b) = (dir.join("x86.exr"), dir.join("arm.exr"));
        render(scene, &a, job, &x86.addr);
        let o = render(scene, &b, job, &arm.addr);
        assert!(String::from_utf8_lossy(&o.stdout).contains("aarch64"), "not rendered on aarch64: {}", text(&o));
        let x = Image::read(&a).unwrap().pixels;
        assert!(x.iter().any(|&v| v > 0.0), "{scene}: black image");
        let (differing, largest) = difference(&a, &b);
        eprintln!("{scene}: {differing} of {} values differ, largest difference {largest:e}", x.len());
        assert_eq!(differing, 0, "{scene}: aarch64 and x86-64 disagree (largest difference {largest:e})");
    }
}

/// The emulated worker is many times slower: it gets a few strips, the fast one the rest and the copies of the
/// slow one's last strips (the tail does not wait for it), and the image is the x86-64 image to the bit.
#[test]
fn a_mixed_farm_gives_the_slow_worker_fewer_strips_and_the_same_image() {
    let Some(arm) = start_aarch64(&["--threads", "1"]) else { return };
    let x86 = WorkerProcess::start(&["--threads", "1"]);
    let dir = temp_dir("mixed-arch", "farm");
    let job = ["--size", "96x96", "--spp", "96", "--integrator", "photon-map", "--photons", "20000"];
    let job = [&job[..], &["--rows-per-strip", "2"]].concat();
    let (alone, mixed) = (dir.join("x86.exr"), dir.join("mixed.exr"));
    render("cornell.toml", &alone, &job, &x86.addr);
    let o = render("cornell.toml", &mixed, &job, &format!("{},{}", x86.addr, arm.addr));
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    let (x_strips, x_spec) = strips_and_speculative(&o, &x86.addr);
    let (a_strips, _) = strips_and_speculative(&o, &arm.addr);
    eprintln!("strips: x86-64 {x_strips} (speculative copies {x_spec}), aarch64 {a_strips}");
    assert_eq!(x_strips + a_strips, 48, "every strip accepted once: {}", text(&o));
    assert!(a_strips >= 1, "the aarch64 worker should finish a strip in a 48-strip render: {}", text(&o));
    assert!(x_strips > 2 * a_strips, "the emulated worker should take far fewer strips: {}", text(&o));
    assert!(x_spec >= 1, "the fast worker should copy the slow one's tail strips: {}", text(&o));
    assert!(!text(&o).contains("different math modes"), "both builds are portable: {}", text(&o));
    let (differing, largest) = difference(&alone, &mixed);
    assert_eq!(differing, 0, "the mixed farm changed pixels (largest difference {largest:e})");
}

/// A worker whose math mode differs is used, and the render says its strips may differ.
#[test]
fn a_render_that_mixes_math_modes_says_so() {
    let a = WorkerProcess::start(&["--threads", "1"]);
    let b = WorkerProcess::start(&["--threads", "1", "--test-math-mode", "native: platform libm, SIMD glam"]);
    let dir = temp_dir("mixed-arch", "modes");
    let o = render(
        "cornell.toml",
        &dir.join("out.exr"),
        &["--size", "32x24", "--integrator", "path", "--spp", "1"],
        &format!("{},{}", a.addr, b.addr),
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("different math modes"), "{}", text(&o));
    assert!(stderr.contains("native: platform libm, SIMD glam"), "{}", text(&o));
}
