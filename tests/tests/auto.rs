//! `--integrator auto` end to end: it pilots the candidates that suit the scene, prints each one's estimate and
//! prediction and the choice, and its image is, bit for bit, the render the printed flags give; in-process and
//! through two loopback workers; it refuses what has no budget to choose for.
#![allow(clippy::unwrap_used)]

use photon_tests::{render_in, scenes_dir, success_stdout, temp_dir};
use std::path::Path;

/// The flags of the `auto: the same image:` line, up to its parenthesis.
fn reproducing_flags(stdout: &str) -> Vec<String> {
    let line =
        stdout.lines().find_map(|l| l.strip_prefix("auto: the same image: ")).unwrap_or_else(|| panic!("{stdout}"));
    let flags = line.split(" (").next().unwrap();
    flags.split_whitespace().map(str::to_owned).collect()
}

/// Renders `scene` with `auto` and `extra` flags, then with the flags it printed, and asserts equal bytes;
/// returns the auto render's standard output.
fn auto_then_reproduce(dir: &Path, scene: &Path, extra: &[&str]) -> String {
    let base = ["--size", "32x32", "--set", "render.photons.pass_photons=5000"];
    let auto = [&base[..], &["-o", "auto.exr", "--integrator", "auto", "--time", "4s"], extra].concat();
    let out = success_stdout(&render_in(dir, scene, &auto));
    let flags = reproducing_flags(&out);
    let flags: Vec<&str> = flags.iter().map(String::as_str).collect();
    let fixed = [&base[..], &["-o", "fixed.exr"], &flags[..]].concat();
    success_stdout(&render_in(dir, scene, &fixed));
    let (a, b) = (std::fs::read(dir.join("auto.exr")).unwrap(), std::fs::read(dir.join("fixed.exr")).unwrap());
    assert!(a == b, "auto gave other bits than {flags:?}:\n{out}");
    out
}

#[test]
fn auto_pilots_the_candidates_and_its_image_is_the_printed_render() {
    let dir = temp_dir("auto", "cornell");
    let out = auto_then_reproduce(&dir, &scenes_dir().join("cornell.toml"), &[]);
    // Every candidate of a scene without media or point lights was piloted, and one was chosen.
    for candidate in ["path ", "progressive ", "progressive (radius ×0.5)", "vcm ", "bdpt "] {
        assert!(out.lines().any(|l| l.starts_with(&format!("auto: {candidate}"))), "{candidate}:\n{out}");
    }
    assert_eq!(out.matches("<- chosen").count(), 1, "{out}");
    assert!(out.contains("stopped at the time limit"), "{out}");
}

#[test]
fn auto_on_two_workers_gives_the_printed_render_in_process() {
    let dir = temp_dir("auto", "two-workers");
    auto_then_reproduce(&dir, &scenes_dir().join("cornell.toml"), &["--local", "2", "--threads", "2"]);
}

#[test]
fn auto_leaves_out_the_path_tracer_where_it_cannot_see_point_light_caustics() {
    // A point light and glass: a path tracer never completes the caustic's paths.
    let dir = temp_dir("auto", "caustic-point");
    let out = auto_then_reproduce(&dir, &scenes_dir().join("caustic-point.toml"), &[]);
    assert!(!out.lines().any(|l| l.starts_with("auto: path ")), "{out}");
    assert!(out.lines().any(|l| l.starts_with("auto: vcm ")), "{out}");
}

#[test]
fn auto_in_the_scene_file_and_its_refusals() {
    let dir = temp_dir("auto", "refusals");
    let text = std::fs::read_to_string(scenes_dir().join("cornell.toml")).unwrap();
    let (before, after) = text.split_once("integrator = \"progressive\"").unwrap();
    let scene = dir.join("auto.toml");
    std::fs::write(&scene, format!("{before}integrator = \"auto\"{after}")).unwrap();
    let fails = |scene: &Path, args: &[&str], expected: &str| {
        let out = render_in(&dir, scene, &[&["-o", "x.png", "--size", "8x8"], args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    };
    let cornell = scenes_dir().join("cornell.toml");
    fails(&cornell, &["--integrator", "auto"], "needs a budget to choose for");
    fails(&cornell, &["--integrator", "auto", "--time", "2s", "--spp", "4"], "nothing to choose for");
    fails(&cornell, &["--integrator", "auto", "--time", "2s", "--passes", "4"], "nothing to choose for");
    fails(&cornell, &["--integrator", "automatic"], "or auto");
    fails(&scene, &[], "needs a budget to choose for");
    // The file's `auto` with a budget chooses; a method on the command line overrides it.
    let out = success_stdout(&render_in(&dir, &scene, &["-o", "a.png", "--size", "8x8", "--time", "3s"]));
    assert!(out.contains("<- chosen"), "{out}");
    let out = success_stdout(&render_in(
        &dir,
        &scene,
        &["-o", "b.png", "--size", "8x8", "--integrator", "path", "--spp", "2"],
    ));
    assert!(!out.contains("auto:") && out.contains("2 spp"), "{out}");
}
