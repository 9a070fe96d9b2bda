//! Claim: glTF's `alphaMode` MASK cuts a face away where its base colour texture's alpha (times the factor's) is
//! below `alphaCutoff`, for every kind of ray, and the TANGENT attribute sets the frame of normal maps.
//! - Ray by ray: a checker of transparent and opaque texels on a quad lets a ray through exactly where its
//!   texel is transparent, closest hit and shadow query alike; the factor's alpha multiplies the texture's.
//! - Light: the sun straight down through a checker of half transparent cells lights half a Lambert floor, so
//!   the floor's mean radiance seen from below the quad is `½ · ρ/π · E`, in every method (photons and light
//!   subpaths pass the holes as camera rays and shadow rays do).
//! - A TANGENT attribute turns `∂p/∂u` to the tangent and `∂p/∂v` to `w · (n × t)`, at the lengths the UVs give,
//!   and a mirroring node transform turns the bitangent around with the surface.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder};
use glam::Vec3A;
use photon_core::math::Ray;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::scene::Scene;

/// An RGBA PNG of `n × n` texels, `rgba(x, y)` with `y` from the top row.
fn rgba_png(n: u32, rgba: impl Fn(u32, u32) -> [u8; 4]) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(n, n, |x, y| image::Rgba(rgba(x, y)));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// A GLB of the square `[−h, h]²` in y = `height`, facing down (−y) and both ways (`doubleSided`), with UVs over
/// the whole texture `png`, an `alphaMode` MASK material of cutoff 0.5 whose base colour factor is
/// `factor` (RGBA), and a nearest-texel sampler; `extra` adds members to the material (`,"emissiveFactor":...`).
fn masked_square_with(h: f32, height: f32, png: &[u8], factor: [f32; 4], extra: &str) -> Vec<u8> {
    let mut b = Builder::default();
    let p = b.vec3(&[[-h, height, -h], [h, height, -h], [h, height, h], [-h, height, h]]);
    // glTF's v runs down the image: (0, 0) is its top-left texel, at (−h, −h).
    let uv = b.vec2(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
    let i = b.indices(&[0, 1, 2, 0, 2, 3]);
    let image = b.bytes(png);
    b.member(&format!(
        r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{uv}}},"indices":{i},"material":0}}]}}]"#
    ));
    b.member(&format!(r#""images":[{{"bufferView":{image},"mimeType":"image/png"}}]"#));
    b.member(r#""samplers":[{"magFilter":9728,"minFilter":9728,"wrapS":33071,"wrapT":33071}]"#);
    b.member(r#""textures":[{"source":0,"sampler":0}]"#);
    b.member(&format!(
        r#""materials":[{{"alphaMode":"MASK","alphaCutoff":0.5,"doubleSided":true,
            "pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}},"baseColorFactor":{factor:?},
            "metallicFactor":1,"roughnessFactor":0.5}}{extra}}}]"#
    ));
    b.member(r#""nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]"#);
    b.glb()
}

/// [`masked_square_with`] without more material members.
fn masked_square(h: f32, height: f32, png: &[u8], factor: [f32; 4]) -> Vec<u8> {
    masked_square_with(h, height, png, factor, "")
}

/// The prepared scene of `toml` with `glb` written beside it as `square.glb`.
fn prepared(test: &str, toml: &str, glb: &[u8]) -> (Scene, std::path::PathBuf, Prepared) {
    let dir = folder(test);
    std::fs::write(dir.join("square.glb"), glb).unwrap();
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    let scene = Scene::load(&path).unwrap();
    let prep = Prepared::new(&scene, &path).unwrap();
    (scene, path, prep)
}

const RAYS_SCENE: &str = r#"
[camera]
eye = [0.0, 3.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, -1.0]

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "gltf"
file = "square.glb"

[[objects]]
type = "plane"
point = [0.0, -1.0, 0.0]
normal = [0.0, 1.0, 0.0]
material = "grey"

[[lights]]
type = "point"
position = [0.0, 5.0, 0.0]
intensity = [1.0, 1.0, 1.0]
"#;

#[test]
fn rays_pass_a_cut_out_exactly_where_its_texels_are_transparent() {
    // 8 × 8 texels over [−1, 1]²: alpha 0 (transparent) on even cells, 255 on odd ones.
    let png = rgba_png(8, |x, y| [90, 90, 90, if (x + y) % 2 == 0 { 0 } else { 255 }]);
    let (_, _, prep) = prepared("cutout-rays", RAYS_SCENE, &masked_square(1.0, 0.0, &png, [1.0; 4]));
    assert_eq!(prep.geometry.masks.len(), 1);
    let mut sampler = common::sampler(71, 0);
    let (mut through, mut n) = (0, 0);
    for _ in 0..4000 {
        let (x, z) = (2.0 * sampler.next_f32() - 1.0, 2.0 * sampler.next_f32() - 1.0);
        // Texel (column, row from the top): x from −1 is u; the top row is at z = −1 (glTF's v = 0).
        let (i, j) = (((x + 1.0) * 4.0).floor() as u32, ((z + 1.0) * 4.0).floor() as u32);
        let transparent = (i + j).is_multiple_of(2);
        let ray = Ray::new(Vec3A::new(x, 2.0, z), Vec3A::NEG_Y);
        let hit = prep.geometry.intersect(&ray, f32::INFINITY).unwrap();
        let expected_t = if transparent { 3.0 } else { 2.0 };
        assert!((hit.t - expected_t).abs() < 1e-4, "({x}, {z}): texel ({i}, {j}) hit at t = {}", hit.t);
        assert_eq!(prep.geometry.occluded(&ray, 2.5), !transparent, "({x}, {z}): the shadow query disagrees");
        through += usize::from(transparent);
        n += 1;
    }
    let fraction = through as f64 / n as f64;
    assert!((fraction - 0.5).abs() < 0.03, "{fraction} of the rays passed, for half the area open");
}

#[test]
fn the_base_colour_factors_alpha_multiplies_the_textures() {
    // Left half alpha 0.5, right half 0.75 (texels 128 and 191); the factor's alpha 0.8 makes them 0.4 and 0.6,
    // so against the cutoff 0.5 only the right half remains. Without the factor both would remain.
    let png = rgba_png(2, |x, _| [200, 200, 200, if x == 0 { 128 } else { 191 }]);
    for (factor, left_there) in [(0.8, false), (1.0, true)] {
        let glb = masked_square(1.0, 0.0, &png, [1.0, 1.0, 1.0, factor]);
        let (_, _, prep) = prepared(&format!("cutout-factor-{factor}"), RAYS_SCENE, &glb);
        let hit_at =
            |x: f32| prep.geometry.intersect(&Ray::new(Vec3A::new(x, 2.0, 0.1), Vec3A::NEG_Y), 10.0).unwrap().t;
        assert!((hit_at(0.5) - 2.0).abs() < 1e-4, "factor {factor}: the right half is cut");
        assert_eq!((hit_at(-0.5) - 2.0).abs() < 1e-4, left_there, "factor {factor}: the left half");
    }
}

#[test]
fn an_emissive_cut_out_keeps_its_faces_whole_and_says_so() {
    // Light sampling and photon emission pick points over whole faces: cutting only the hit queries would make
    // the methods disagree, so the faces stay whole.
    let png = rgba_png(2, |x, _| [255, 255, 255, if x == 0 { 0 } else { 255 }]);
    let glb = masked_square_with(1.0, 0.0, &png, [1.0; 4], r#","emissiveFactor":[1,1,1]"#);
    let (_, path, prep) = prepared("cutout-emissive", RAYS_SCENE, &glb);
    assert!(prep.geometry.masks.is_empty());
    let hit = prep.geometry.intersect(&Ray::new(Vec3A::new(-0.5, 2.0, 0.1), Vec3A::NEG_Y), 10.0).unwrap();
    assert!((hit.t - 2.0).abs() < 1e-4, "the transparent half was cut");
    let file = path.with_file_name("square.glb");
    let imported = photon_core::prepare::gltf::import(&file, &glam::Affine3A::IDENTITY, u64::MAX, u64::MAX).unwrap();
    assert!(imported.warnings.iter().any(|w| w.contains("emissive") && w.contains("MASK")), "{:?}", imported.warnings);
}

#[test]
fn an_image_without_alpha_cuts_nothing() {
    let img = image::RgbImage::from_pixel(2, 2, image::Rgb([10, 10, 10]));
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png).unwrap();
    let (_, _, prep) = prepared("cutout-rgb", RAYS_SCENE, &masked_square(1.0, 0.0, &png.into_inner(), [1.0; 4]));
    assert!(prep.geometry.masks.is_empty());
    let hit = prep.geometry.intersect(&Ray::new(Vec3A::new(0.3, 2.0, -0.6), Vec3A::NEG_Y), 10.0).unwrap();
    assert!((hit.t - 2.0).abs() < 1e-4);
}

/// A floor of albedo 0.5 at y = 0, the masked square 4 × 4 at y = 1 above it, the sun straight down with
/// irradiance 1, and a camera at y = 0.5 looking straight down with a field of view of 2·atan 2: it sees the
/// floor's `[−1, 1]²` (a pinhole facing a plane gives every pixel the same area of it) and nothing of the square,
/// which is behind it.
const SHADOW_SCENE: &str = r#"
[camera]
eye = [0.0, 0.5, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, -1.0]
fov = 126.8699
width = 16
height = 16

[render]
max_depth = 6

[render.photons]
global = 400000
caustic = 0
pass_photons = 50000
gather = "radius"
radius = 0.1

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "gltf"
file = "square.glb"

[[objects]]
type = "rect"
center = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
width = 8.0
height = 8.0
material = "grey"

[[lights]]
type = "directional"
direction = [0.0, -1.0, 0.0]
irradiance = [1.0, 1.0, 1.0]
"#;

#[test]
fn the_sun_through_a_half_open_cut_out_lights_half_the_floor_in_every_method() {
    // 4 × 4 black texels (metallic 1 over black: only Schlick's grazing reflection, which adds 0.15 % through the
    // floor's light it returns) over [−2, 2]²: cells of 1, alternately open and opaque. The camera's view
    // [−1, 1]² holds 4 whole cells, 2 of them open. photon-map gathers within a fixed radius: its blur across a
    // shadow's edge then moves as much light out of the lit cells as into the dark ones, where k-nearest
    // gathering (which widens its radius only in the dark) adds 5 % here.
    let png = rgba_png(4, |x, y| [0, 0, 0, if (x + y) % 2 == 0 { 0 } else { 255 }]);
    let (scene, path, _) = prepared("cutout-shadow", SHADOW_SCENE, &masked_square(2.0, 1.0, &png, [1.0; 4]));
    let expected = 0.5 * 0.5 / std::f64::consts::PI;
    for (method, budget, tolerance) in [
        // Direct light only: exact but for the float sums.
        (Method::Direct, 64, 1e-4),
        // The grazing reflection adds 0.15 %; the rest is noise (lt's most: 1.1 % at 64 passes).
        (Method::Path, 64, 0.005),
        (Method::Bdpt, 64, 0.005),
        (Method::Vcm, 64, 0.005),
        (Method::Progressive, 16, 0.005),
        (Method::FinalGather, 4, 0.01),
        (Method::PhotonMap, 1, 0.01),
        (Method::Lt, 64, 0.02),
    ] {
        let mean = common::image_mean(&common::render_method(&scene, &path, method, budget));
        let rel = mean / expected - 1.0;
        eprintln!("{method}: {mean:.5} against {expected:.5} ({:+.2} %)", 100.0 * rel);
        assert!(rel.abs() < tolerance, "{method}: floor radiance {mean} against {expected} ({:+.2} %)", 100.0 * rel);
    }
}

/// A GLB of the unit square in z = 0 facing +z with UVs `u = x`, `v = −y` (so photon's `v' = 1 − v` runs along
/// +y and `∂p/∂u = +x`), normals +z, and, when `tangent` is given, that TANGENT at every vertex; its node scaled by
/// `scale`.
fn tangent_square(tangent: Option<[f32; 4]>, scale: [f32; 3]) -> Vec<u8> {
    let mut b = Builder::default();
    let p = b.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]);
    let n = b.vec3(&[[0.0, 0.0, 1.0]; 4]);
    let uv = b.vec2(&[[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]);
    let i = b.indices(&[0, 1, 2, 0, 2, 3]);
    let t = tangent.map(|t| format!(r#","TANGENT":{}"#, b.vec4(&[t; 4]))).unwrap_or_default();
    b.member(&format!(
        r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TEXCOORD_0":{uv}{t}}},"indices":{i}}}]}}]"#
    ));
    b.member(&format!(r#""nodes":[{{"mesh":0,"scale":{scale:?}}}],"scenes":[{{"nodes":[0]}}]"#));
    b.glb()
}

/// `∂p/∂u` and `∂p/∂v` where a ray from +z meets the square of `glb` at (x, y) = (0.3, 0.6) of its object space.
fn frame(test: &str, glb: &[u8], x: f32) -> (Vec3A, Vec3A, Vec3A) {
    let (_, _, prep) = prepared(test, RAYS_SCENE, glb);
    let ray = Ray::new(Vec3A::new(x, 0.6, 2.0), Vec3A::NEG_Z);
    let hit = prep.geometry.intersect(&ray, 10.0).unwrap();
    (hit.ns, hit.dpdu, hit.dpdv)
}

#[test]
fn a_tangent_attribute_sets_the_normal_map_frame() {
    let close = |a: Vec3A, b: Vec3A| (a - b).length() < 1e-5;
    // Without tangents: the UVs' derivatives, +x and +y.
    let (_, dpdu, dpdv) = frame("tangent-none", &tangent_square(None, [1.0; 3]), 0.3);
    assert!(close(dpdu, Vec3A::X) && close(dpdv, Vec3A::Y), "{dpdu} {dpdv}");
    // A tangent along +y with w = +1: the bitangent is n × t = z × y = −x.
    let (ns, dpdu, dpdv) = frame("tangent-y", &tangent_square(Some([0.0, 1.0, 0.0, 1.0]), [1.0; 3]), 0.3);
    assert!(close(ns, Vec3A::Z));
    assert!(close(dpdu, Vec3A::Y) && close(dpdv, Vec3A::NEG_X), "{dpdu} {dpdv}");
    // w = −1 turns the bitangent around.
    let (_, dpdu, dpdv) = frame("tangent-y-minus", &tangent_square(Some([0.0, 1.0, 0.0, -1.0]), [1.0; 3]), 0.3);
    assert!(close(dpdu, Vec3A::Y) && close(dpdv, Vec3A::X), "{dpdu} {dpdv}");
    // A tangent along +x agrees with the UVs; scaled by 2 in x, the lengths stay the UVs' (2 and 1).
    let (_, dpdu, dpdv) = frame("tangent-x-scaled", &tangent_square(Some([1.0, 0.0, 0.0, 1.0]), [2.0, 1.0, 1.0]), 0.6);
    assert!(close(dpdu, 2.0 * Vec3A::X) && close(dpdv, Vec3A::Y), "{dpdu} {dpdv}");
    // Mirrored in x: the surface's +u now runs along −x and its +v along +y, and the tangent frame follows it
    // (t = −x, b = w' · (n × t) = +y with w' = −w), as the UVs' derivatives do.
    let mirrored = tangent_square(Some([1.0, 0.0, 0.0, 1.0]), [-1.0, 1.0, 1.0]);
    let (_, uv_dpdu, uv_dpdv) = frame("tangent-mirror-uv", &tangent_square(None, [-1.0, 1.0, 1.0]), -0.3);
    let (_, dpdu, dpdv) = frame("tangent-mirror", &mirrored, -0.3);
    assert!(close(dpdu, uv_dpdu) && close(dpdv, uv_dpdv), "tangents {dpdu} {dpdv}, UVs {uv_dpdu} {uv_dpdv}");
    assert!(close(dpdu, Vec3A::NEG_X) && close(dpdv, Vec3A::Y), "{dpdu} {dpdv}");
}

#[test]
fn a_tangent_attribute_of_the_wrong_length_is_an_error_naming_it() {
    let mut b = Builder::default();
    let p = b.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let n = b.vec3(&[[0.0, 0.0, 1.0]; 3]);
    let t = b.vec4(&[[1.0, 0.0, 0.0, 1.0]; 2]);
    b.member(&format!(
        r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TANGENT":{t}}}}}]}}]"#
    ));
    b.member(r#""nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]"#);
    let dir = folder("tangent-count");
    let file = dir.join("short.glb");
    std::fs::write(&file, b.glb()).unwrap();
    let e = photon_core::prepare::gltf::import(&file, &glam::Affine3A::IDENTITY, u64::MAX, u64::MAX).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("short.glb") && text.contains("TANGENT has 2 values") && text.contains("3 vertices"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
