//! Claim: a glTF's triangles land where its node hierarchy says, to 1e-5: translation, rotation (a unit
//! quaternion) and scale composed as T·R·S, a node given by a matrix, children after their parents, a
//! mirroring node whose triangles keep their front (winding reversed), indexed and non-indexed primitives,
//! and the scene object's own `transform` applied after the file's. The same triangles reach the prepared
//! scene's primitives through a scene file, from a `.gltf` with a `data:` buffer, one with a buffer file
//! beside it, and a `.glb`.
//!
//! The expected positions are computed here with glam's `Mat4` (not the importer's `Affine3A` path through the
//! `gltf` crate), and for one node by hand.

#![allow(clippy::unwrap_used)]

mod common;

use common::gltf::{Builder, folder, unit_triangle_meshes};
use glam::{Mat4, Quat, Vec3};
use photon_core::geometry::shapes::Shape;
use photon_core::prepare::Prepared;
use photon_core::prepare::gltf::import;
use photon_core::scene::Scene;

const TRI: [Vec3; 3] = [Vec3::ZERO, Vec3::X, Vec3::Y];

/// Node 0: T (1, 2, 3), R 90° about y, S 2, children 1 and 2. Node 1: a matrix (scale x by 0.5, translate
/// (0, 1, 0)), mesh 0, child 3. Node 2: mesh 1 (not indexed). Node 3: T (0, 0, −1), S (−1, 1, 1) (a mirror),
/// mesh 0.
fn builder() -> Builder {
    let mut b = Builder::default();
    let meshes = unit_triangle_meshes(&mut b);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    b.member(&meshes);
    b.member(&format!(
        r#""nodes":[
            {{"translation":[1,2,3],"rotation":[0,{h},0,{h}],"scale":[2,2,2],"children":[1,2]}},
            {{"matrix":[0.5,0,0,0, 0,1,0,0, 0,0,1,0, 0,1,0,1],"mesh":0,"children":[3]}},
            {{"mesh":1}},
            {{"translation":[0,0,-1],"scale":[-1,1,1],"mesh":0}}
        ]"#
    ));
    b.member(r#""scenes":[{"nodes":[0]}],"scene":0"#);
    b
}

/// The scene object's transform: rotate 90° about z, then translate (10, 0, 0).
fn object() -> Mat4 {
    Mat4::from_translation(Vec3::new(10.0, 0.0, 0.0)) * Mat4::from_rotation_z(90f32.to_radians())
}

/// The expected triangles, in the importer's order (depth first, children in order), with the mirrored one's
/// winding reversed.
fn expected() -> Vec<[Vec3; 3]> {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let n0 = Mat4::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::from_xyzw(0.0, h, 0.0, h),
        Vec3::new(1.0, 2.0, 3.0),
    );
    let n1 = n0 * Mat4::from_cols_array(&[0.5, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 1., 0., 1.]);
    let n2 = n0;
    let n3 = n1
        * Mat4::from_scale_rotation_translation(Vec3::new(-1.0, 1.0, 1.0), Quat::IDENTITY, Vec3::new(0.0, 0.0, -1.0));
    let place = |m: Mat4| TRI.map(|p| (object() * m).transform_point3(p));
    let mirrored = place(n3);
    vec![place(n1), [mirrored[0], mirrored[2], mirrored[1]], place(n2)]
}

fn assert_close(got: &[[Vec3; 3]], want: &[[Vec3; 3]], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?}");
    for (g, w) in got.iter().zip(want) {
        for (a, b) in g.iter().zip(w) {
            assert!((*a - *b).abs().max_element() <= 1e-5, "{what}: {g:?} vs {w:?}");
        }
    }
}

#[test]
fn triangles_land_where_the_hierarchy_says() {
    let dir = folder("nodes");
    let path = dir.join("nodes.gltf");
    builder().write_gltf(&path);
    let affine = glam::Affine3A::from_mat4(object());
    let imported = import(&path, &affine, u64::MAX, u64::MAX).unwrap();
    let got: Vec<[Vec3; 3]> = imported.meshes.iter().flat_map(|m| m.mesh.triangles.clone()).collect();
    let want = expected();
    assert_close(&got, &want, "import");
    // Node 2 by hand: S 2, then 90° about y ((x, y, z) → (z, y, −x)), then T (1, 2, 3); then the object's 90°
    // about z ((x, y) → (−y, x)) and (10, 0, 0).
    let by_hand = [Vec3::new(8.0, 1.0, 3.0), Vec3::new(8.0, 1.0, 1.0), Vec3::new(6.0, 1.0, 3.0)];
    assert_close(&got[2..], &[by_hand], "node 2 by hand");
    // The mirrored triangle's geometric normal is the mirror image of its parent's, not its negative.
    let normal = |t: &[Vec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]).normalize();
    let (n1, n3) = (normal(&got[0]), normal(&got[1]));
    assert!((n1 - n3).length() < 1e-5, "parent {n1}, mirrored child {n3}");
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The prepared scene's triangles (as vertex triples, sorted: the BVH reorders primitives).
fn prepared_triangles(scene_path: &std::path::Path) -> Vec<[Vec3; 3]> {
    let scene = Scene::load(scene_path).unwrap();
    let prep = Prepared::new(&scene, scene_path).unwrap();
    let mut out: Vec<[Vec3; 3]> = prep
        .geometry
        .prims()
        .filter_map(|p| match &p.shape {
            Shape::Triangle(t) => Some(t.p),
            _ => None,
        })
        .collect();
    out.sort_by(|a, b| a[0].to_array().partial_cmp(&b[0].to_array()).unwrap());
    out
}

#[test]
fn every_container_reaches_the_prepared_scene() {
    let dir = folder("containers");
    let b = builder();
    b.write_gltf(&dir.join("inline.gltf"));
    b.write_gltf_with_bin(&dir.join("external.gltf"), "external data.bin");
    std::fs::write(dir.join("binary.glb"), b.glb()).unwrap();
    let mut want = expected();
    want.sort_by(|a, b| a[0].to_array().partial_cmp(&b[0].to_array()).unwrap());
    for file in ["inline.gltf", "external.gltf", "binary.glb"] {
        let scene = format!(
            "[camera]\neye = [0, 0, 30]\nlook_at = [0, 0, 0]\nwidth = 4\nheight = 4\n\
             [[objects]]\ntype = \"gltf\"\nfile = \"{file}\"\ntransform = {{ rotate = [0, 0, 90], translate = [10, 0, 0] }}\n"
        );
        let path = dir.join("scene.toml");
        std::fs::write(&path, scene).unwrap();
        assert_close(&prepared_triangles(&path), &want, file);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
