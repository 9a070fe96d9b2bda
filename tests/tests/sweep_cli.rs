//! `photon-coordinator reference` and `photon-sweep` end to end on a 12×12 Cornell box: the reference is a
//! path-traced EXR; the sweep, on two loopback worker processes, writes one CSV row per method and budget with finite
//! values, each method's error falls at every step of a 4× budget, both charts are written, and report.html
//! shows the summaries as tables and the reference and each method's image over its error map, PNGs of the
//! sweep's size.
#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::{coordinator, scenes_dir, sweep, temp_dir};
use std::path::Path;
use std::process::{Command, Output};

/// Runs `bin` (the coordinator or the sweep) in `dir`; panics, with its output, unless it succeeds.
fn run(bin: &Path, dir: &Path, args: &[&str]) -> Output {
    let out = Command::new(bin).current_dir(dir).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?} failed\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn reference_then_sweep_writes_a_falling_csv_and_charts() {
    let dir = temp_dir("sweep-cli", "cornell");
    let scene = scenes_dir().join("cornell.toml");
    let scene = scene.to_str().unwrap();

    // Diffuse spheres: with the glass one, the path tracer's caustic fireflies make its relative MSE over 144
    // pixels jump (measured: 2.57, 0.024, 0.23 at budgets 1, 4, 16), which says nothing about the sweep.
    let diffuse = [
        "--set",
        "materials.glass={type=\"lambert\",albedo=0.5}",
        "--set",
        "materials.mirror={type=\"lambert\",albedo=0.5}",
    ];
    let reference = ["reference", scene, "-o", "ref.exr", "--spp", "512", "--size", "12x12"];
    let out = run(coordinator(), &dir, &[&reference[..], &diffuse[..]].concat());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("reference method: path"), "{stdout}");
    assert!(dir.join("ref.exr").is_file());

    // Fewer photons per progressive pass keep the test short; the budget still grows the passes.
    let args = [scene, "--reference", "ref.exr", "--methods", "path,progressive", "--budget", "1,4,16"];
    let more = ["--size", "12x12", "--out", "out", "--set", "render.photons.pass_photons=20000", "--local", "2"];
    let out = run(&sweep(), &dir, &[&args[..], &more[..], &diffuse[..]].concat());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("equal time") && stdout.contains("equal error"), "{stdout}");
    assert!(stdout.contains("on local-0, local-1"), "the sweep should render on the two local workers: {stdout}");

    let csv = std::fs::read_to_string(dir.join("out/sweep.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("method,budget,parameter,value,seconds,rmse,rel_mse,estimated_rel_mse"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 6, "{csv}");
    for r in &rows {
        assert_eq!(r.len(), 8, "{r:?}");
        // Both methods estimate their own error without the reference.
        for v in &r[4..] {
            let x: f64 = v.parse().unwrap();
            assert!(x.is_finite() && x >= 0.0, "{r:?}");
        }
    }
    for method in ["path", "progressive"] {
        let rel: Vec<(u32, f64)> =
            rows.iter().filter(|r| r[0] == method).map(|r| (r[1].parse().unwrap(), r[6].parse().unwrap())).collect();
        assert_eq!(rel.iter().map(|r| r.0).collect::<Vec<_>>(), [1, 4, 16], "{method}: {rel:?}");
        // Each 4× budget must lower the error: a curve that rises anywhere is a bug, not noise, at these ratios.
        assert!(rel[1].1 < rel[0].1 && rel[2].1 < rel[1].1, "{method}: relMSE did not fall at every step: {rel:?}");
        let estimated: Vec<f64> = rows.iter().filter(|r| r[0] == method).map(|r| r[7].parse().unwrap()).collect();
        assert!(estimated[2] < estimated[0], "{method}: the estimate did not fall from budget 1 to 16: {estimated:?}");
    }
    for chart in ["sweep.svg", "sweep.png"] {
        let len = std::fs::metadata(dir.join("out").join(chart)).unwrap().len();
        assert!(len > 0, "{chart} is empty");
    }
    let svg = std::fs::read_to_string(dir.join("out/sweep.svg")).unwrap();
    assert!(svg.contains("progressive") && svg.contains("relative MSE"), "the SVG lacks its legend or labels");

    let report = Path::new("out").join("report.html");
    assert_eq!(stdout.lines().last(), Some(format!("report: {}", report.display()).as_str()), "{stdout}");
    let html = std::fs::read_to_string(dir.join(&report)).unwrap();
    // One HTML table per printed table; a summary without columns prints its reason, and the page says it too.
    let printed = stdout.lines().filter(|l| l.starts_with("| method |")).count();
    assert_eq!(html.matches("<table>").count(), printed, "{html}");
    assert_eq!(printed + html.matches("<p class=\"note\">").count(), 2, "{html}");
    assert!(html.contains("<img src=\"sweep.png\"") && html.contains("href=\"sweep.svg\""), "{html}");
    for name in ["reference.png", "path.png", "path-error.png", "progressive.png", "progressive-error.png"] {
        assert!(html.contains(&format!("<img src=\"{name}\"")), "{name} is not shown: {html}");
        let path = dir.join("out").join(name);
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "{name} is not a PNG");
        let image = Image::read(&path).unwrap();
        assert_eq!((image.width, image.height), (12, 12), "{name}");
    }
    assert!(html.contains("progressive, budget 16 (passes 64)"), "{html}");
}

#[test]
fn reference_must_be_exr_and_sweep_size_must_match() {
    let dir = temp_dir("sweep-cli", "errors");
    let scene = scenes_dir().join("cornell.toml");
    let scene = scene.to_str().unwrap();
    let out = Command::new(coordinator()).current_dir(&dir).args(["reference", scene, "-o", "ref.png"]).output();
    let out = out.unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains(".exr"));

    run(coordinator(), &dir, &["reference", scene, "-o", "ref.exr", "--spp", "4", "--size", "8x8"]);
    let out = Command::new(sweep())
        .current_dir(&dir)
        .args([scene, "--reference", "ref.exr", "--methods", "path", "--budget", "1", "--size", "9x9"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("differs from the reference"));
}
