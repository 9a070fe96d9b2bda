//! Renders bounded by time (`--time`) or by estimated error (`--target-error`), end to end: a time-bounded render
//! stops near its deadline and its image is, bit for bit, the render of the samples (or passes) it reports; on
//! two loopback workers too; an error-bounded render stops with a true error (against the shipped 32×32
//! references) within a factor 2 of its target; the flags refuse what they cannot honour.
#![allow(clippy::unwrap_used)]

use photon_tests::{coordinator, render_in, scenes_dir, success_stdout, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// Runs `photon-coordinator render SCENE ARGS…` in `dir`, the scene from the workspace's `scenes` folder.
fn render(dir: &Path, scene: &str, args: &[&str]) -> Output {
    render_in(dir, &scenes_dir().join(scene), args)
}

/// The summary line of a successful render.
fn summary(out: &Output) -> String {
    success_stdout(out).lines().last().unwrap_or_default().to_owned()
}

/// The number before `word` in `line` (e.g. `448 spp` → 448).
fn count_before(line: &str, word: &str) -> u32 {
    let words: Vec<&str> = line.split_whitespace().collect();
    let i =
        words.iter().position(|w| w.trim_end_matches(',') == word).unwrap_or_else(|| panic!("no `{word}` in {line}"));
    words[i - 1].parse().unwrap_or_else(|_| panic!("no count before `{word}` in {line}"))
}

/// The seconds of `N s render` in a summary line.
fn render_seconds(line: &str) -> f64 {
    let words: Vec<&str> = line.split_whitespace().collect();
    let i = words.windows(2).position(|w| w == ["s", "render"]).unwrap_or_else(|| panic!("no render time in {line}"));
    words[i - 1].parse().unwrap()
}

/// The relative MSE of `image` against `reference`, as `compare` measures it.
fn rel_mse(dir: &Path, image: &str, reference: &str) -> f64 {
    let out = Command::new(coordinator())
        .current_dir(dir)
        .arg("compare")
        .arg(image)
        .arg(scenes_dir().join("references").join(reference))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let kv = stdout.split_whitespace().find_map(|kv| kv.strip_prefix("rel_mse=")).unwrap();
    kv.parse().unwrap()
}

#[test]
fn a_time_bound_stops_near_its_deadline_with_the_image_of_the_samples_it_reports() {
    let dir = temp_dir("bounded", "time-path");
    coordinator(); // built before the clock starts
    let t0 = Instant::now();
    let line = summary(&render(
        &dir,
        "cornell.toml",
        &["-o", "timed.exr", "--size", "32x32", "--integrator", "path", "--time", "3s"],
    ));
    let wall = t0.elapsed();
    assert!(line.contains("stopped at the time limit"), "{line}");
    // A round aims at half the time spent (1.5 s at most here), and none starts that cannot end by the deadline:
    // the render ends within 3 s and one round, with room for a loaded machine.
    let render_s = render_seconds(&line);
    assert!(render_s < 3.0 + 3.0, "{line}");
    assert!(wall < Duration::from_secs(20), "{wall:?}");
    let spp = count_before(&line, "spp");
    let rounds = count_before(&line, "rounds");
    assert!(spp >= 2 && rounds >= 1, "{line}");
    // The image equals, bit for bit, a render fixed at that many samples per pixel.
    let fixed = summary(&render(
        &dir,
        "cornell.toml",
        &["-o", "fixed.exr", "--size", "32x32", "--integrator", "path", "--spp", &spp.to_string()],
    ));
    assert!(fixed.contains(&format!("{spp} spp")), "{fixed}");
    let (a, b) = (std::fs::read(dir.join("timed.exr")).unwrap(), std::fs::read(dir.join("fixed.exr")).unwrap());
    assert!(a == b, "--time stopped at {spp} spp, and --spp {spp} gave other bits");
    let image = photon_core::image_io::Image::read(&dir.join("timed.exr")).unwrap();
    assert_eq!((image.width, image.height), (32, 32));
    assert!(image.pixels.iter().all(|v| v.is_finite() && *v >= 0.0));
}

#[test]
fn progressive_passes_bounded_by_time_on_two_workers_equal_the_same_passes_fixed() {
    let dir = temp_dir("bounded", "time-progressive");
    let args = ["--size", "32x32", "--integrator", "progressive", "--set", "render.photons.pass_photons=20000"];
    let timed = [&args[..], &["-o", "timed.exr", "--time", "2s", "--local", "2", "--threads", "2"]].concat();
    let line = summary(&render(&dir, "caustic-point.toml", &timed));
    let passes = count_before(&line, "passes");
    assert!(line.contains("stopped at the time limit") && passes >= 2, "{line}");
    let passes_arg = passes.to_string();
    let fixed = [&args[..], &["-o", "fixed.exr", "--passes", &passes_arg]].concat();
    summary(&render(&dir, "caustic-point.toml", &fixed));
    let (a, b) = (std::fs::read(dir.join("timed.exr")).unwrap(), std::fs::read(dir.join("fixed.exr")).unwrap());
    assert!(a == b, "two workers stopped at {passes} passes, and --passes {passes} here gave other bits");
}

#[test]
fn an_error_bound_stops_within_a_factor_two_of_its_target() {
    // The path tracer on the Cornell box, and progressive photon mapping on the caustic a path tracer cannot
    // render; each true relative MSE against the scene's 32×32 reference.
    let dir = temp_dir("bounded", "target-error");
    for (scene, reference, method, target) in [
        ("cornell.toml", "cornell-32.exr", "path", 0.02),
        ("caustic-point.toml", "caustic-point-32.exr", "progressive", 0.01),
    ] {
        let out = format!("{method}.exr");
        let args = ["-o", &out, "--size", "32x32", "--integrator", method, "--target-error", &target.to_string()];
        let line = summary(&render(&dir, scene, &args));
        assert!(line.contains("stopped at the target error"), "{line}");
        let truth = rel_mse(&dir, &out, reference);
        assert!(
            (0.5..=2.0).contains(&(truth / target)),
            "{scene} {method}: true relMSE {truth} for target {target}: {line}"
        );
    }
}

#[test]
fn the_bounds_refuse_what_they_cannot_honour() {
    let dir = temp_dir("bounded", "refusals");
    let fails = |args: &[&str], expected: &str| {
        let out = render(&dir, "cornell.toml", &[&["-o", "x.png", "--size", "8x8"], args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    };
    fails(&["--time", "0s"], "expected a positive time");
    fails(&["--time", "soon"], "expected a positive time");
    fails(&["--target-error=-1"], "expected a relative MSE greater than 0");
    fails(&["--target-error", "0.01", "--integrator", "photon-map"], "keeps the bias of its photon maps");
    fails(&["--time", "2s", "--spp", "4"], "give one or the other");
    fails(&["--time", "2s", "--resume", "x.png.partial"], "cannot be used with");
}
