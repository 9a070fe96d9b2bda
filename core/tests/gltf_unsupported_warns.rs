//! Claim: what a glTF uses and photon does not support is named once per file, however often the file uses
//! it (an unknown extension in `extensionsUsed`, a POINTS primitive on two nodes, an orthographic camera on two
//! nodes), nothing supported is warned about, and the file still renders: pixel for pixel what the same
//! triangle, material and `KHR_lights_punctual` point light give when the scene file writes them itself.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder};
use photon_core::prepare::Prepared;
use photon_core::prepare::gltf::import;
use photon_core::render::render_image;
use photon_core::scene::Scene;

/// A floor triangle (y = 0, facing +y) and a POINTS primitive, on two nodes each, a point light of 5 W/sr at
/// (0, 1, 0), two orthographic cameras, and an unknown extension.
fn file(dir: &std::path::Path) -> std::path::PathBuf {
    let mut b = Builder::default();
    let p = b.vec3(&[[-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 0.0, -1.0]]);
    let i = b.indices(&[0, 1, 2]);
    let dots = b.vec3(&[[0.0, 0.5, 0.0]]);
    b.member(&format!(
        r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i},"material":0}},
            {{"attributes":{{"POSITION":{dots}}},"mode":0}}]}}]"#
    ));
    b.member(
        r#""materials":[{"pbrMetallicRoughness":{"baseColorFactor":[0.8,0.6,0.4,1],"metallicFactor":0.25,
            "roughnessFactor":0.5}}]"#,
    );
    b.member(r#""cameras":[{"type":"orthographic","orthographic":{"xmag":1,"ymag":1,"znear":0.1,"zfar":10}}]"#);
    b.member(
        r#""nodes":[{"mesh":0},{"mesh":0,"camera":0,"children":[2]},{"camera":0},
            {"translation":[0,1,0],"extensions":{"KHR_lights_punctual":{"light":0}}}]"#,
    );
    b.member(r#""extensions":{"KHR_lights_punctual":{"lights":[{"type":"point","color":[1,1,1],"intensity":5}]}}"#);
    b.member(r#""extensionsUsed":["EXT_made_up_extension","KHR_lights_punctual"]"#);
    b.member(r#""scenes":[{"nodes":[0,1,3]}]"#);
    let path = dir.join("unsupported.gltf");
    b.write_gltf(&path);
    path
}

#[test]
fn each_unsupported_feature_is_named_once() {
    let dir = folder("warn-once");
    let imported = import(&file(&dir), &glam::Affine3A::IDENTITY, u64::MAX, u64::MAX).unwrap();
    let w = &imported.warnings;
    let count = |needle: &str| w.iter().filter(|s| s.contains(needle)).count();
    assert_eq!(count("EXT_made_up_extension"), 1, "{w:?}");
    assert_eq!(count("Points"), 1, "{w:?}");
    assert_eq!(count("orthographic"), 1, "{w:?}");
    assert_eq!(w.len(), 3, "nothing else: {w:?}");
    assert_eq!(count("KHR_lights_punctual"), 0, "{w:?}");
    // Both floor nodes, the light; no camera (orthographic only).
    assert_eq!(imported.meshes.len(), 2);
    assert_eq!(imported.lights.len(), 1);
    assert!(imported.camera.is_none());
    let _ = std::fs::remove_dir_all(&dir);
}

const CAMERA: &str = "[camera]\neye = [0, 2, 3]\nlook_at = [0, 0, 0]\nwidth = 12\nheight = 12\n[render]\nspp = 4\n";

#[test]
fn the_file_renders_as_the_same_scene_written_by_hand() {
    let dir = folder("renders");
    file(&dir);
    let gltf = dir.join("gltf.toml");
    std::fs::write(&gltf, format!("{CAMERA}[[objects]]\ntype = \"gltf\"\nfile = \"unsupported.gltf\"\n")).unwrap();
    // The floor once: the glTF's two floor nodes put the same triangle in the same place, which a ray sees as
    // one surface either way.
    let by_hand = dir.join("hand.toml");
    std::fs::write(
        &by_hand,
        format!(
            "{CAMERA}[materials.m]\ntype = \"metallic_roughness\"\nbase_color = [0.8, 0.6, 0.4]\nmetallic = 0.25\n\
             roughness = 0.5\n[[objects]]\ntype = \"triangle\"\nvertices = [[-1, 0, 1], [1, 0, 1], [0, 0, -1]]\n\
             material = \"m\"\n[[objects]]\ntype = \"triangle\"\nvertices = [[-1, 0, 1], [1, 0, 1], [0, 0, -1]]\n\
             material = \"m\"\n[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = [5, 5, 5]\n"
        ),
    )
    .unwrap();
    let render = |path: &std::path::Path| {
        let scene = Scene::load(path).unwrap();
        render_image(&Prepared::new(&scene, path).unwrap(), &|_| {}).pixels
    };
    let (a, b) = (render(&gltf), render(&by_hand));
    assert!(a.iter().all(|p| p.is_finite()));
    let lit = a.chunks(3).filter(|p| p.iter().any(|c| *c > 0.0)).count();
    assert!(lit > a.len() / 12, "only {lit} of {} pixels lit", a.len() / 3);
    assert_eq!(a, b, "the glTF scene and the scene written by hand differ");
    let _ = std::fs::remove_dir_all(&dir);
}
