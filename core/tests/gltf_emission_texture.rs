//! Claim: a glTF `emissiveTexture` is read point by point by the area lights, in every method: a 2 × 2 square
//! emitting through a 4 × 1 texture whose first texel alone is white lights a floor exactly as a rectangle light
//! over the first quarter of the square does (image means within the methods' noise). Reading the texture at
//! each triangle's centroid, as photon did before, would leave the square dark: both centroids fall on black
//! texels.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder};
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::scene::Scene;

/// A PNG of `w × 1` RGB texels.
fn png_row(texels: &[[u8; 3]]) -> Vec<u8> {
    let img = image::RgbImage::from_raw(texels.len() as u32, 1, texels.iter().flatten().copied().collect()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// The square `[−1, 1]²` at y = 1 facing down, black (a metal of base colour 0), emitting `emissiveFactor` 1 ×
/// strength 4 through a nearest-texel 4 × 1 texture, white on `u < ¼` (x < −0.5) and black elsewhere.
fn emissive_square() -> Vec<u8> {
    let mut b = Builder::default();
    let p = b.vec3(&[[-1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]]);
    let uv = b.vec2(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
    let i = b.indices(&[0, 1, 2, 0, 2, 3]);
    let image = b.bytes(&png_row(&[[255; 3], [0; 3], [0; 3], [0; 3]]));
    b.member(&format!(
        r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{uv}}},"indices":{i},"material":0}}]}}]"#
    ));
    b.member(&format!(r#""images":[{{"bufferView":{image},"mimeType":"image/png"}}]"#));
    b.member(r#""samplers":[{"magFilter":9728,"minFilter":9728,"wrapS":33071,"wrapT":33071}]"#);
    b.member(r#""textures":[{"source":0,"sampler":0}]"#);
    b.member(
        r#""materials":[{"emissiveFactor":[1,1,1],"emissiveTexture":{"index":0},
            "extensions":{"KHR_materials_emissive_strength":{"emissiveStrength":4}},
            "pbrMetallicRoughness":{"baseColorFactor":[0,0,0,1],"metallicFactor":1,"roughnessFactor":0.5}}]"#,
    );
    b.member(r#""nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]"#);
    b.member(r#""extensionsUsed":["KHR_materials_emissive_strength"]"#);
    b.glb()
}

/// A Lambert floor (albedo 0.5) at y = 0 and a camera at y = 0.5 looking straight down; `light` adds the
/// emitter.
fn scene_text(light: &str) -> String {
    format!(
        r#"
[camera]
eye = [0.0, 0.5, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, -1.0]
fov = 120.0
width = 16
height = 16

[render]
max_depth = 6

[render.photons]
global = 200000
caustic = 0
pass_photons = 50000

[materials.grey]
type = "lambert"
albedo = 0.5

[materials.black]
type = "conductor"
color = [0.0, 0.0, 0.0]
roughness = 0.5

[[objects]]
type = "rect"
center = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
width = 8.0
height = 8.0
material = "grey"
{light}"#
    )
}

/// The same square as two rectangles of the same black metal (glTF's metallic 1 over base colour 0 is the
/// Schlick conductor of F0 = 0): one over its white quarter, x in [−1, −0.5], emitting radiance 4, and the
/// rest.
const RECT_LIGHT: &str = r#"
[[objects]]
type = "rect"
center = [-0.75, 1.0, 0.0]
normal = [0.0, -1.0, 0.0]
width = 0.5
height = 2.0
material = "black"
emission = { radiance = [4.0, 4.0, 4.0] }

[[objects]]
type = "rect"
center = [0.25, 1.0, 0.0]
normal = [0.0, -1.0, 0.0]
width = 1.5
height = 2.0
material = "black"
"#;

const GLTF_LIGHT: &str = r#"
[[objects]]
type = "gltf"
file = "square.glb"
"#;

#[test]
fn a_textured_emitter_lights_the_floor_as_its_bright_texels_would_alone() {
    let dir = folder("emission-texture");
    std::fs::write(dir.join("square.glb"), emissive_square()).unwrap();
    let load = |name: &str, light: &str| {
        let path = dir.join(name);
        std::fs::write(&path, scene_text(light)).unwrap();
        (Scene::load(&path).unwrap(), path)
    };
    let (textured, textured_path) = load("textured.toml", GLTF_LIGHT);
    let (rect, rect_path) = load("rect.toml", RECT_LIGHT);
    let prep = Prepared::new(&textured, &textured_path).unwrap();
    assert_eq!(prep.lights.lights.len(), 2, "one area light a triangle");
    for (method, budget, tolerance) in [
        // Budgets for the textured light's noise: sampled uniformly by area, three quarters of its points are
        // black (importance sampling the texels is not done).
        (Method::Direct, 1024, 0.005),
        (Method::Path, 1024, 0.005),
        (Method::Bdpt, 4096, 0.005),
        (Method::Vcm, 4096, 0.005),
        (Method::Lt, 2048, 0.01),
        (Method::PhotonMap, 256, 0.01),
        (Method::FinalGather, 256, 0.01),
        (Method::Progressive, 256, 0.01),
    ] {
        let a = common::image_mean(&common::render_method(&textured, &textured_path, method, budget));
        let b = common::image_mean(&common::render_method(&rect, &rect_path, method, budget));
        let rel = a / b - 1.0;
        eprintln!("{method}: textured {a:.5}, rectangle {b:.5} ({:+.2} %)", 100.0 * rel);
        assert!(b > 0.01, "{method}: the rectangle lights nothing ({b})");
        assert!(rel.abs() < tolerance, "{method}: textured {a} against the rectangle's {b} ({:+.2} %)", 100.0 * rel);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
