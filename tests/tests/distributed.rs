//! Distributed rendering over loopback: worker processes on port 0, the coordinator as a user runs it.
//!
//! Every image is compared bit for bit with the in-process render of the same job: the farm may move strips
//! around, retry them and race copies of them, but it may not change a pixel, lose a strip or count one twice.

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::{WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::Duration;

/// A quick job with photon maps (so a photons blob is shipped too).
const QUICK: &[&str] = &["--size", "64x48", "--spp", "4", "--integrator", "photon-map", "--photons", "20000"];
/// A slower job cut into many strips, for killing a worker in the middle of it.
const SLOW: &[&str] = &["--size", "128x96", "--spp", "48", "--integrator", "path", "--rows-per-strip", "3"];

const LIMIT: Duration = Duration::from_secs(240);

fn render(out: &Path, job: &[&str], extra: &[&str]) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(out).arg("-q").args(job).args(extra);
    run_with_timeout(&mut cmd, LIMIT)
}

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn bits(path: &Path) -> Vec<u32> {
    Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// The in-process render of a job (made once per test process).
fn reference(job: &'static [&'static str]) -> Vec<u32> {
    static QUICK_REF: OnceLock<Vec<u32>> = OnceLock::new();
    static SLOW_REF: OnceLock<Vec<u32>> = OnceLock::new();
    // By content: a constant's address is not unique (each use may be its own copy), so a pointer comparison
    // could file one job's reference under the other's.
    let quick = job == QUICK;
    let cell = if quick { &QUICK_REF } else { &SLOW_REF };
    cell.get_or_init(|| {
        let dir = temp_dir("distributed", if quick { "ref-quick" } else { "ref-slow" });
        let out = dir.join("ref.exr");
        let o = render(&out, job, &[]);
        assert!(o.status.success(), "{}", text(&o));
        let b = bits(&out);
        assert!(b.iter().any(|&v| f32::from_bits(v) > 0.0));
        b
    })
    .clone()
}

fn workers_arg(ws: &[&WorkerProcess]) -> String {
    ws.iter().map(|w| w.addr.as_str()).collect::<Vec<_>>().join(",")
}

/// The summary line's count of blob bytes shipped.
fn shipped(o: &Output) -> u64 {
    let out = String::from_utf8_lossy(&o.stdout);
    let words: Vec<&str> = out.split_whitespace().collect();
    let i = words
        .windows(4)
        .position(|w| w[1..] == ["blob", "bytes", "shipped"] || w[1..] == ["blob", "bytes", "shipped,"]);
    words[i.unwrap_or_else(|| panic!("no shipped count in {out}"))].parse().unwrap()
}

#[test]
fn one_and_two_workers_give_the_in_process_bytes() {
    let want = reference(QUICK);
    let dir = temp_dir("distributed", "match");
    let (a, b) = (WorkerProcess::start(&["--threads", "1"]), WorkerProcess::start(&["--threads", "1"]));
    for (name, ws) in [("one", vec![&a]), ("two", vec![&a, &b])] {
        let out = dir.join(format!("{name}.exr"));
        let o = render(&out, QUICK, &["--workers", &workers_arg(&ws)]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(bits(&out) == want, "{name} worker(s) changed pixels");
    }
    // --local starts its own worker processes.
    let out = dir.join("local.exr");
    let o = render(&out, QUICK, &["--local", "2"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(bits(&out) == want, "--local 2 changed pixels");
}

#[test]
fn a_killed_worker_loses_no_strip() {
    let want = reference(SLOW);
    let dir = temp_dir("distributed", "kill");
    let mut victim = WorkerProcess::start(&["--threads", "1"]);
    let survivor = WorkerProcess::start(&["--threads", "1"]);
    let out = dir.join("out.exr");
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(&out).arg("-q").args(SLOW);
    cmd.args(["--workers", &workers_arg(&[&victim, &survivor])]);
    let handle = std::thread::spawn(move || run_with_timeout(&mut cmd, LIMIT));
    // Kill it while it holds strips: after it has started its second one.
    victim.wait_for_log("rendering strip", 2, LIMIT);
    victim.kill();
    let o = handle.join().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let row = stdout.lines().find(|l| l.starts_with(&victim.addr)).unwrap_or_else(|| panic!("{}", text(&o)));
    assert!(row.contains("lost"), "the killed worker should be reported lost: {}", text(&o));
    assert!(bits(&out) == want, "the image changed after a worker was killed");
    drop(survivor);
}

#[test]
fn corrupted_pixels_are_caught_and_rendered_again() {
    let want = reference(QUICK);
    let dir = temp_dir("distributed", "corrupt");
    let faulty = WorkerProcess::start(&["--threads", "1", "--test-corrupt-strips", "2"]);
    let out = dir.join("out.exr");
    let o = render(&out, QUICK, &["--workers", &faulty.addr]);
    assert!(o.status.success(), "{}", text(&o));
    let all = text(&o);
    assert_eq!(all.matches("checksum mismatch").count(), 2, "{all}");
    assert!(bits(&out) == want, "a corrupted strip reached the image");
    // A worker that keeps corrupting is blocked after 3 bad strips, with the reason; a good one finishes.
    let hopeless = WorkerProcess::start(&["--threads", "1", "--test-corrupt-strips", "1000"]);
    let good = WorkerProcess::start(&["--threads", "1"]);
    let o = render(&out, QUICK, &["--workers", &workers_arg(&[&hopeless, &good])]);
    assert!(o.status.success(), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains(&format!("worker {} blocked: 3 failed units (limit 3)", hopeless.addr)), "{}", text(&o));
    assert!(bits(&out) == want, "a corrupted strip reached the image");
}

/// A strip whose sums match the worker's checksum but hold a value no block of its units can add up to (the
/// fault flag writes -1) was computed so by the renderer: every worker of this build would do the same. The render stops at once, the worker is not blamed, and the error says it is
/// a bug with the pixel and the method instead of suggesting `--resume`.
#[test]
fn a_non_finite_strip_is_reported_as_a_bug_not_a_faulty_worker() {
    let dir = temp_dir("distributed", "nan");
    let buggy = WorkerProcess::start(&["--threads", "1", "--test-nan-strips"]);
    let out = dir.join("out.exr");
    let o = render(&out, QUICK, &["--workers", &buggy.addr]);
    assert!(!o.status.success(), "{}", text(&o));
    let all = text(&o);
    assert!(all.contains("holds the sum -1: not the sum of"), "{all}");
    assert!(all.contains("bug in photon") && all.contains("method `photon-map`"), "{all}");
    assert!(!all.contains("--resume") && !all.contains("blocked"), "{all}");
    assert!(!dir.join("out.exr.partial").exists());
}

#[test]
fn refused_workers_are_skipped_with_their_reason() {
    let want = reference(QUICK);
    let dir = temp_dir("distributed", "refused");
    let token = dir.join("token");
    std::fs::write(&token, "right-token\n").unwrap();
    let wrong = dir.join("wrong");
    std::fs::write(&wrong, "wrong-token").unwrap();
    let other_build = WorkerProcess::start(&["--test-build-id", "0123456789abcdef"]);
    let other_token = WorkerProcess::start(&["--token-file", wrong.to_str().unwrap()]);
    let good = WorkerProcess::start(&["--token-file", token.to_str().unwrap()]);
    let out = dir.join("out.exr");
    let ws = workers_arg(&[&other_build, &other_token, &good]);
    let o = render(&out, QUICK, &["--workers", &ws, "--token-file", token.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("is not this worker's build 0123456789abcdef"), "{}", text(&o));
    assert!(stderr.contains("wrong token"), "{}", text(&o));
    assert!(bits(&out) == want);
    // Without a token, the worker that wants one refuses too.
    let o = render(&dir.join("none.exr"), QUICK, &["--workers", &good.addr]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("requires a token"), "{}", text(&o));
}

#[test]
fn with_no_worker_left_the_render_stops_and_resumes() {
    let want = reference(SLOW);
    let dir = temp_dir("distributed", "resume");
    let out = dir.join("out.exr");
    let mut only = WorkerProcess::start(&["--threads", "1"]);
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(&out).arg("-q").args(SLOW);
    cmd.args(["--workers", &only.addr]);
    let handle = std::thread::spawn(move || run_with_timeout(&mut cmd, LIMIT));
    only.wait_for_log("rendering strip", 4, LIMIT);
    only.kill();
    let o = handle.join().unwrap();
    assert!(!o.status.success(), "{}", text(&o));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("no worker left"), "{}", text(&o));
    let partial: PathBuf = dir.join("out.exr.partial");
    assert!(partial.is_file(), "{}", text(&o));
    assert!(!out.exists());
    // Resume on a fresh worker: only the missing strips are rendered, and the image is the same.
    let fresh = WorkerProcess::start(&[]);
    let o = render(&out, SLOW, &["--workers", &fresh.addr, "--resume", partial.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let resumed: u32 = stdout
        .split(", ")
        .find_map(|p| p.strip_suffix(" strips resumed").or_else(|| p.trim().strip_suffix(" strips resumed")))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("{}", text(&o)));
    assert!((1..32).contains(&resumed), "{resumed} strips resumed of 32");
    assert!(bits(&out) == want, "the resumed image differs");
    assert!(!partial.exists(), "the partial file is removed once the image is complete");
    // A partial file of another job is refused.
    std::fs::write(&partial, photon_core::codec::encode(&("not", "a partial")).unwrap()).unwrap();
    let o = render(&dir.join("x.exr"), QUICK, &["--workers", &fresh.addr, "--resume", partial.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a partial render"), "{}", text(&o));
}

#[test]
fn a_second_render_ships_no_blob() {
    let dir = temp_dir("distributed", "ship");
    let w = WorkerProcess::start(&[]);
    // Shipped photon maps (the worker could trace them itself: tests/tests/map_delivery.rs).
    let ship = ["--workers", &w.addr, "--photon-maps", "ship"];
    let first = render(&dir.join("a.exr"), QUICK, &ship);
    assert!(first.status.success(), "{}", text(&first));
    let second = render(&dir.join("b.exr"), QUICK, &ship);
    assert!(second.status.success(), "{}", text(&second));
    assert!(shipped(&first) > 100_000, "the photon map alone is larger: {}", text(&first));
    assert_eq!(shipped(&second), 0, "{}", text(&second));
    // Another exposure is another frame, not another scene nor other photons: still nothing to ship.
    let third = render(&dir.join("c.exr"), QUICK, &[&ship[..], &["--exposure", "1"]].concat());
    assert_eq!(shipped(&third), 0, "{}", text(&third));
}

#[test]
fn a_slow_worker_takes_fewer_strips_and_the_tail_does_not_wait_for_it() {
    let want = reference(QUICK);
    let dir = temp_dir("distributed", "slow");
    let fast = WorkerProcess::start(&["--threads", "1"]);
    let slow = WorkerProcess::start(&["--threads", "1", "--test-delay-ms", "400"]);
    let out = dir.join("out.exr");
    let o = render(&out, QUICK, &["--workers", &workers_arg(&[&fast, &slow]), "--rows-per-strip", "2"]);
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let strips = |addr: &str| WorkerRow::find(&stdout, addr).unwrap_or_else(|| panic!("{}", text(&o))).units;
    let (f, s) = (strips(&fast.addr), strips(&slow.addr));
    assert_eq!(f + s, 24, "every strip accepted once: {}", text(&o));
    assert!(f >= 4 * s, "the fast worker should take most strips ({f} against {s}): {}", text(&o));
    assert!(bits(&out) == want);
}

#[test]
fn sigterm_stops_a_worker_cleanly() {
    let mut w = WorkerProcess::start(&[]);
    let status = w.terminate(Duration::from_secs(20)).expect("the worker did not stop within 20 s of SIGTERM");
    assert!(status.success(), "{status}");
}

/// A copy of `scenes/textured.toml` with its images and mesh in a folder of its own, so that a test may change
/// an image.
fn textured_copy(dir: &Path) -> PathBuf {
    let src = scenes_dir();
    for sub in ["textures", "meshes"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    for f in
        ["textured.toml", "textures/wood.png", "textures/bricks.png", "textures/ridges-normal.png", "meshes/torus.obj"]
    {
        std::fs::copy(src.join(f), dir.join(f)).unwrap();
    }
    dir.join("textured.toml")
}

/// Every texture kind (checker, image, bump map, normal map) renders through the farm with the in-process
/// bytes, and a second render after one image changed ships that image alone: textures are their own blobs.
#[test]
fn a_textured_scene_renders_through_the_farm_and_a_changed_image_ships_alone() {
    let dir = temp_dir("distributed", "textured");
    let scene = textured_copy(&dir);
    let job = ["--size", "48x48", "--spp", "4", "-q"];
    let run = |out: &Path, extra: &[&str]| {
        let mut cmd = Command::new(coordinator());
        cmd.arg("render").arg(&scene).arg("-o").arg(out).args(job).args(extra);
        run_with_timeout(&mut cmd, LIMIT)
    };
    let o = run(&dir.join("ref.exr"), &[]);
    assert!(o.status.success(), "{}", text(&o));
    let want = bits(&dir.join("ref.exr"));
    let (a, b) = (WorkerProcess::start(&["--threads", "1"]), WorkerProcess::start(&["--threads", "1"]));
    let o = run(&dir.join("two.exr"), &["--workers", &workers_arg(&[&a, &b])]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(bits(&dir.join("two.exr")) == want, "two workers changed the textured image");
    let first = shipped(&o);
    // Another wood image, same size: only its blob travels (to each of the two workers).
    let wood = dir.join("textures/wood.png");
    let img = image::open(&wood).unwrap().into_rgb8();
    let (w, h) = img.dimensions();
    let inverted: Vec<u8> = img.into_raw().iter().map(|v| 255 - v).collect();
    image::RgbImage::from_raw(w, h, inverted).unwrap().save(&wood).unwrap();
    let o = run(&dir.join("again.exr"), &["--workers", &workers_arg(&[&a, &b])]);
    assert!(o.status.success(), "{}", text(&o));
    let texels = u64::from(w * h * 3);
    let again = shipped(&o);
    assert!(
        (2 * texels..2 * texels + 256).contains(&again),
        "shipped {again} B, expected two wood blobs of ~{texels} B"
    );
    assert!(first > again + 100_000, "the first render ships the scene too: {first} B");
    assert!(bits(&dir.join("again.exr")) != want, "the changed image did not change the render");
}

/// Both scenes with participating media, by every method, through two workers: the in-process bytes (each
/// pass of progressive photon mapping traced once in the farm, its volume photons with it).
#[test]
fn media_scenes_render_through_the_farm_with_every_method() {
    let dir = temp_dir("distributed", "media");
    let (a, b) = (WorkerProcess::start(&["--threads", "1"]), WorkerProcess::start(&["--threads", "1"]));
    let farm = workers_arg(&[&a, &b]);
    for scene in ["fog.toml", "volume-caustic.toml"] {
        for method in ["path", "direct", "photon-map", "final-gather", "progressive", "vcm", "bdpt", "lt"] {
            let job = [
                "--size",
                "24x20",
                "--spp",
                "2",
                "--passes",
                "3",
                "--photons",
                "8000",
                "--integrator",
                method,
                "--rows-per-strip",
                "4",
                "--set",
                "render.photons.final_gather_rays=2",
            ];
            let run = |out: &Path, extra: &[&str]| {
                let mut cmd = Command::new(coordinator());
                cmd.arg("render").arg(scenes_dir().join(scene)).arg("-o").arg(out).arg("-q").args(job).args(extra);
                let o = run_with_timeout(&mut cmd, LIMIT);
                assert!(o.status.success(), "{scene} {method}: {}", text(&o));
            };
            let (here, there) = (dir.join("here.exr"), dir.join("farm.exr"));
            run(&here, &[]);
            run(&there, &["--workers", &farm]);
            let want = bits(&here);
            assert!(want.iter().any(|&v| f32::from_bits(v) > 0.0), "{scene} {method}: black image");
            assert!(bits(&there) == want, "{scene} {method}: the farm changed pixels");
        }
    }
}

/// `vcm` renders every shipped scene (`scenes/*.toml`, `scenes/stress/*.toml`, `scenes/rooms/*.toml`) through
/// two workers, each pass's light subpaths traced once in the farm: the in-process bytes.
#[test]
fn vcm_renders_every_shipped_scene_through_the_farm() {
    let dir = temp_dir("distributed", "vcm-scenes");
    let (a, b) = (WorkerProcess::start(&["--threads", "1"]), WorkerProcess::start(&["--threads", "1"]));
    let farm = workers_arg(&[&a, &b]);
    let mut scenes = Vec::new();
    for sub in ["", "stress", "rooms"] {
        let folder = scenes_dir().join(sub);
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                scenes.push(path);
            }
        }
    }
    scenes.sort();
    assert!(scenes.len() >= 16, "{} scenes found", scenes.len());
    let mut lit = 0;
    for scene in &scenes {
        let job = ["--size", "20x16", "--passes", "2", "--integrator", "vcm", "--rows-per-strip", "4"];
        let run = |out: &Path, extra: &[&str]| {
            let mut cmd = Command::new(coordinator());
            cmd.arg("render").arg(scene).arg("-o").arg(out).arg("-q").args(job).args(extra);
            let o = run_with_timeout(&mut cmd, LIMIT);
            assert!(o.status.success(), "{}: {}", scene.display(), text(&o));
        };
        let (here, there) = (dir.join("here.exr"), dir.join("farm.exr"));
        run(&here, &[]);
        run(&there, &["--workers", &farm]);
        let want = bits(&here);
        assert!(want.iter().all(|&v| f32::from_bits(v).is_finite()), "{}: a pixel is not finite", scene.display());
        lit += usize::from(want.iter().any(|&v| f32::from_bits(v) > 0.0));
        assert!(bits(&there) == want, "{}: the farm changed pixels", scene.display());
    }
    assert_eq!(lit, scenes.len(), "some scenes rendered black");
}
