//! Claim: `KHR_lights_punctual` lights land where their nodes put them, pointing down the node's −z axis, with
//! `color × intensity` read as W/sr (point, spot) and W/m² (directional) and the cone angles in degrees, and a
//! file lit by them renders bit for bit as the same lights written in the scene file.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder};
use glam::Vec3;
use photon_core::math::fmath;
use photon_core::prepare::Prepared;
use photon_core::prepare::gltf::import;
use photon_core::render::render_image;
use photon_core::scene::{LightSpec, Scene};

/// A floor triangle lit by a spot light 2 above it turned to look straight down (−90° about x), a
/// directional light travelling down and towards +x at 45° (−90° about x, then 45° about z), and a point light.
fn file(dir: &std::path::Path) -> std::path::PathBuf {
    let mut b = Builder::default();
    let p = b.vec3(&[[-2.0, 0.0, 2.0], [2.0, 0.0, 2.0], [0.0, 0.0, -2.0]]);
    b.member(&format!(r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}]"#));
    let h = std::f32::consts::FRAC_1_SQRT_2;
    // The sun's node: −z turned by −90° about x points down (−y); then 45° about z tilts it towards −x.
    let (s, c) = (fmath::sin(std::f32::consts::PI / 8.0), fmath::cos(std::f32::consts::PI / 8.0));
    let sun = glam::Quat::from_xyzw(0.0, 0.0, s, c) * glam::Quat::from_xyzw(-h, 0.0, 0.0, h);
    b.member(&format!(
        r#""nodes":[{{"mesh":0}},
            {{"translation":[0.5,2,0],"rotation":[{},0,0,{h}],"extensions":{{"KHR_lights_punctual":{{"light":0}}}}}},
            {{"rotation":[{},{},{},{}],"extensions":{{"KHR_lights_punctual":{{"light":1}}}}}},
            {{"translation":[-1,1,1],"extensions":{{"KHR_lights_punctual":{{"light":2}}}}}}]"#,
        -h, sun.x, sun.y, sun.z, sun.w
    ));
    b.member(
        r#""extensions":{"KHR_lights_punctual":{"lights":[
            {"type":"spot","color":[1,0.5,0.25],"intensity":8,"spot":{"innerConeAngle":0.2,"outerConeAngle":0.5}},
            {"type":"directional","color":[0.5,0.5,1],"intensity":2},
            {"type":"point","color":[1,1,1],"intensity":0.5}]}}"#,
    );
    b.member(r#""extensionsUsed":["KHR_lights_punctual"],"scenes":[{"nodes":[0,1,2,3]}]"#);
    let path = dir.join("lights.gltf");
    b.write_gltf(&path);
    path
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() <= 1e-5
}

#[test]
fn lights_land_where_their_nodes_say() {
    let dir = folder("lights");
    let imported = import(&file(&dir), &glam::Affine3A::IDENTITY, u64::MAX, u64::MAX).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let [spot, sun, point] = imported.lights.as_slice() else { panic!("{:?}", imported.lights) };
    let LightSpec::Spot { position, direction, intensity, power, inner_angle, outer_angle } = spot else { panic!() };
    assert!(close(*position, Vec3::new(0.5, 2.0, 0.0)) && close(*direction, Vec3::NEG_Y), "{spot:?}");
    assert!(close(intensity.unwrap(), Vec3::new(8.0, 4.0, 2.0)) && power.is_none());
    assert!((inner_angle - 0.2f32.to_degrees()).abs() < 1e-4 && (outer_angle - 0.5f32.to_degrees()).abs() < 1e-4);
    let LightSpec::Directional { direction, irradiance } = sun else { panic!() };
    let h = std::f32::consts::FRAC_1_SQRT_2;
    // Down (−y), turned 45° about +z: half towards +x.
    assert!(close(*direction, Vec3::new(h, -h, 0.0)), "{sun:?}");
    assert!(close(*irradiance, Vec3::new(1.0, 1.0, 2.0)));
    let LightSpec::Point { position, intensity, .. } = point else { panic!() };
    assert!(close(*position, Vec3::new(-1.0, 1.0, 1.0)) && close(intensity.unwrap(), Vec3::splat(0.5)));
    let _ = std::fs::remove_dir_all(&dir);
}

const CAMERA: &str = "[camera]\neye = [0, 3, 4]\nlook_at = [0, 0, 0]\nwidth = 12\nheight = 12\n[render]\nspp = 4\n";

#[test]
fn the_lights_render_as_the_same_lights_written_by_hand() {
    let dir = folder("lights-render");
    file(&dir);
    let gltf = dir.join("gltf.toml");
    std::fs::write(&gltf, format!("{CAMERA}[[objects]]\ntype = \"gltf\"\nfile = \"lights.gltf\"\n")).unwrap();
    let imported = import(&dir.join("lights.gltf"), &glam::Affine3A::IDENTITY, u64::MAX, u64::MAX).unwrap();
    // The same lights as TOML, every digit kept; glTF's default material written out.
    let lights: String = imported
        .lights
        .iter()
        .map(|l| format!("[[lights]]\n{}", toml::to_string(l).unwrap()))
        .collect::<Vec<_>>()
        .join("\n");
    let by_hand = dir.join("hand.toml");
    std::fs::write(
        &by_hand,
        format!(
            "{CAMERA}[materials.m]\ntype = \"metallic_roughness\"\n[[objects]]\ntype = \"triangle\"\n\
             vertices = [[-2, 0, 2], [2, 0, 2], [0, 0, -2]]\nmaterial = \"m\"\n{lights}"
        ),
    )
    .unwrap();
    let render = |path: &std::path::Path| {
        let scene = Scene::load(path).unwrap();
        render_image(&Prepared::new(&scene, path).unwrap(), &|_| {}).pixels
    };
    let (a, b) = (render(&gltf), render(&by_hand));
    assert!(a.iter().all(|p| p.is_finite()) && a.iter().any(|p| *p > 0.0));
    assert_eq!(a, b, "the glTF's lights and the same lights written by hand differ");
    let _ = std::fs::remove_dir_all(&dir);
}
