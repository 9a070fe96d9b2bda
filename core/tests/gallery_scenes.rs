//! Every scene of the gallery still renders: each shipped scene (`scenes/*.toml`, `scenes/stress/*.toml` and `scenes/rooms/*.toml`), with
//! its own method at 16×16 and a tiny budget, gives a finite, non-negative image that is not black; and
//! docs/gallery/README.md, written by `python3 docs/gallery/make.py`, shows every one of them.

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The shipped scenes, as the gallery script lists them: the top-level folder, the stress folder, the rooms.
fn shipped_scenes() -> Vec<PathBuf> {
    let mut all = Vec::new();
    for dir in ["scenes", "scenes/stress", "scenes/rooms"] {
        let mut found: Vec<PathBuf> = std::fs::read_dir(repo().join(dir))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        found.sort();
        all.extend(found);
    }
    all
}

/// `scenes/stress/thin-wall.toml` → `stress-thin-wall`, the gallery's name for a scene's picture.
fn gallery_name(scene: &Path) -> String {
    let rel = scene.strip_prefix(repo().join("scenes")).unwrap().with_extension("");
    rel.iter().map(|p| p.to_string_lossy().into_owned()).collect::<Vec<_>>().join("-")
}

#[test]
fn every_shipped_scene_renders_tiny_with_its_own_method() {
    let scenes = shipped_scenes();
    assert!(scenes.len() >= 16, "{} scenes found", scenes.len());
    for path in &scenes {
        let mut scene = Scene::load(path).unwrap();
        let method = scene.render.integrator;
        scene.camera.width = 16;
        scene.camera.height = 16;
        let r = &mut scene.render;
        r.spp = r.spp.min(2);
        r.photons.passes = r.photons.passes.min(2);
        // Keep the stress scenes' own tiny photon counts; cap the others for speed.
        r.photons.global = r.photons.global.min(5_000);
        r.photons.caustic = r.photons.caustic.min(5_000);
        r.photons.pass_photons = r.photons.pass_photons.min(5_000);
        r.photons.final_gather_rays = r.photons.final_gather_rays.min(4);
        let prep = Prepared::new(&scene, path).unwrap().with_photon_maps(path).unwrap();
        let img = render_image(&prep, &|_| {});
        assert_eq!(img.pixels.len(), 16 * 16 * 3, "{}", path.display());
        let bad = img.pixels.iter().filter(|v| !v.is_finite() || **v < 0.0).count();
        assert_eq!(bad, 0, "{} ({method}): {bad} NaN, infinite or negative values", path.display());
        let lit = img.pixels.chunks(3).filter(|p| p.iter().any(|&v| v > 0.0)).count();
        assert!(lit > 0, "{} ({method}): black image", path.display());
    }
}

#[test]
fn the_gallery_shows_every_shipped_scene() {
    let gallery = repo().join("docs/gallery");
    let page = std::fs::read_to_string(gallery.join("README.md")).unwrap();
    for path in shipped_scenes() {
        let rel = path.strip_prefix(repo()).unwrap().to_string_lossy().into_owned();
        let png = format!("{}.png", gallery_name(&path));
        assert!(page.contains(&format!("`{rel}`")), "docs/gallery/README.md does not list {rel}");
        assert!(page.contains(&format!("]({png})")), "docs/gallery/README.md does not show {png}");
        assert!(gallery.join(&png).is_file(), "docs/gallery/{png} is missing: run python3 docs/gallery/make.py");
    }
}
