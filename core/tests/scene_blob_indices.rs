//! Every index in a scene blob is checked once, when it is decoded: a blob with one index corrupted (a light's
//! primitive, a light choice table shorter than the light list, a material, an object, a mesh's normal or UV
//! index, a triangle's mesh or face, ...) is refused with an error naming that table, the unmodified blob
//! still decodes and renders the same bytes, and a few hundred random corruptions of index fields either fail
//! to decode or render without a panic.
//!
//! The blob is taken apart into a copy of its layout made here from the crate's public types, changed, and
//! encoded again through [`photon_core::codec`]; that the copy is faithful is checked by encoding it unchanged,
//! which gives the same bytes.

#![allow(clippy::unwrap_used)]

use photon_core::codec;
use photon_core::geometry::shapes::{NO_MESH, Shape};
use photon_core::geometry::{MeshShading, NONE, PlanePrimitive, Primitive};
use photon_core::light::{BoundingSphere, Light, SkyDistribution};
use photon_core::material::Material;
use photon_core::medium::Media;
use photon_core::prepare::Prepared;
use photon_core::prepare::blobs::FrameError;
use photon_core::render::render_rows;
use photon_core::scene::Scene;
use serde::{Deserialize, Serialize};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

/// The scene blob's layout (`prepare::blobs`' `SceneRef`): geometry, materials, lights, media.
#[derive(Clone, Serialize, Deserialize)]
struct Blob {
    geometry: Geom,
    materials: Vec<Material>,
    lights: Lights,
    media: Option<Media>,
}

/// `Geometry`'s serde form: the primitives in leaf order, the planes, the meshes' shading data and the
/// cut-outs (no BVH).
#[derive(Clone, Serialize, Deserialize)]
struct Geom {
    prims: Vec<Primitive>,
    planes: Vec<PlanePrimitive>,
    meshes: Vec<MeshShading>,
    masks: Vec<photon_core::geometry::mask::AlphaMask>,
}

/// `LightSet`'s serde form: the lights, their choice tables and the environment image's distribution.
#[derive(Clone, Serialize, Deserialize)]
struct Lights {
    lights: Vec<Light>,
    cdf: Vec<f32>,
    pmf: Vec<f32>,
    sky: Option<SkyDistribution>,
}

/// The test scene; `MEDIUM` is replaced by the fog's table or nothing.
const SCENE: &str = r#"
[camera]
eye = [0.0, 1.0, 3.9]
look_at = [0.0, 1.0, 0.0]
fov = 37.0
width = 8
height = 6

[render]
spp = 1
seed = 7
max_depth = 5
integrator = "path"

MEDIUM
[materials.white]
type = "lambert"
albedo = 0.73

[materials.red]
type = "lambert"
albedo = [0.63, 0.065, 0.05]

[materials.glossy]
type = "phong"
diffuse = [0.25, 0.35, 0.55]
specular = 0.35
exponent = 60.0

[materials.mirror]
type = "mirror"

[[objects]]
type = "plane"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
material = "white"

[[objects]]
type = "rect"
center = [0.0, 1.0, -1.0]
normal = [0.0, 0.0, 1.0]
tangent = [1.0, 0.0, 0.0]
width = 2.0
height = 2.0
material = "red"

[[objects]]
type = "rect"
center = [0.0, 1.99, 0.0]
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
width = 0.5
height = 0.4
material = "white"
emission = { radiance = [17.0, 12.0, 4.0] }

[[objects]]
type = "sphere"
center = [0.6, 1.5, -0.3]
radius = 0.1
material = "white"
emission = { radiance = [2.0, 2.0, 2.0] }

[[objects]]
type = "triangle"
vertices = [[-0.9, 0.2, -0.9], [-0.2, 0.2, -0.9], [-0.9, 1.2, -0.9]]
uv = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
material = "mirror"

[[objects]]
type = "mesh"
file = "meshes/torus.obj"
material = "glossy"
lod = 0.0
transform = { translate = [0.4, 0.3, 0.25], rotate = [70.0, 0.0, 0.0], scale = 0.7 }

[[objects]]
type = "mesh"
file = "meshes/cube.obj"
material = "white"
smooth = false
lod = 0.0
transform = { translate = [-0.5, 0.2, -0.3], scale = 0.4 }

[[objects]]
type = "mesh"
file = "meshes/icosphere.obj"
material = "red"
lod = 0.0
transform = { translate = [-0.4, 1.2, 0.0], scale = 0.2 }

[[lights]]
type = "point"
position = [0.0, 1.8, 0.5]
intensity = [1.0, 1.0, 1.0]
"#;

/// A small box with every kind of index: a plane, rectangles, an emitting rectangle and sphere, a triangle with
/// texture coordinates (a one-face mesh of UVs only), a smooth torus with normals and UVs, a flat cube (a mesh
/// without per-face data), a smooth icosphere (normals only), a point light; in fog when `fog`, so that the
/// blob has media (each object's boundary, each light's medium).
fn prepared(fog: bool) -> (Prepared, Vec<u8>, Vec<u8>) {
    let medium = if fog { "[medium]\nsigma_s = 0.05\nsigma_a = 0.01\ng = 0.2\n" } else { "" };
    let text = SCENE.replace("MEDIUM", medium);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/scene-blob-indices.toml");
    let scene = Scene::parse(&text, &path).unwrap();
    let prep = Prepared::new(&scene, &path).unwrap();
    let (blob, frame) = (prep.encode_scene().unwrap(), prep.encode_frame().unwrap());
    (prep, blob, frame)
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn decode(blob: &Blob, frame: &[u8]) -> Result<Prepared, FrameError> {
    Prepared::from_blobs(&codec::encode(blob).unwrap(), None, frame, &[], usize::MAX)
}

fn render(prep: &Prepared) -> Vec<f32> {
    render_rows(prep, 0..prep.camera.height, &|_| {}).pixels
}

/// The table an error names: `BadIndex`'s table, or `BadTable`'s.
fn table_of(e: &FrameError) -> Option<String> {
    match e {
        FrameError::BadIndex { table, .. } | FrameError::BadTable { table, .. } => Some(table.clone()),
        _ => None,
    }
}

/// Indices of things the corruptions need: the torus (the mesh with normals and UVs), a prim on it, a prim
/// that carries no light, an area light and the point light.
struct Landmarks {
    torus: usize,
    torus_prim: usize,
    uv_triangle: usize,
    dark_prim: usize,
    area_light: usize,
    point_light: usize,
}

fn landmarks(b: &Blob) -> Landmarks {
    let meshes = &b.geometry.meshes;
    let torus = meshes.iter().position(|m| !m.normal_indices.is_empty() && !m.uv_indices.is_empty()).unwrap();
    let on_mesh = |want: usize| {
        b.geometry.prims.iter().position(|p| matches!(p.shape, Shape::Triangle(t) if t.mesh as usize == want))
    };
    let uv_mesh = meshes.iter().position(|m| m.normal_indices.is_empty() && m.uv_indices.len() == 1).unwrap();
    let lights = &b.lights.lights;
    Landmarks {
        torus,
        torus_prim: on_mesh(torus).unwrap(),
        uv_triangle: on_mesh(uv_mesh).unwrap(),
        dark_prim: b.geometry.prims.iter().position(|p| p.light == NONE).unwrap(),
        area_light: lights.iter().position(|l| matches!(l, Light::Area { .. })).unwrap(),
        point_light: lights.iter().position(|l| matches!(l, Light::Point { .. })).unwrap(),
    }
}

#[test]
fn the_unmodified_blob_decodes_and_renders_the_same_bytes() {
    for fog in [false, true] {
        let (prep, blob, frame) = prepared(fog);
        let parts: Blob = codec::decode(&blob, usize::MAX).unwrap();
        assert_eq!(parts.media.is_some(), fog);
        // The copy of the layout is faithful: encoded unchanged, it gives the same bytes.
        assert_eq!(codec::encode(&parts).unwrap(), blob);
        let back = decode(&parts, &frame).unwrap();
        let (a, b) = (render(&prep), render(&back));
        assert_eq!(bits(&a), bits(&b), "fog {fog}");
        assert!(a.iter().any(|&v| v > 0.0));
    }
}

#[test]
fn every_shipped_scene_blob_passes_the_check() {
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut n = 0;
    for dir in ["", "stress", "regressions", "rooms"] {
        let Ok(entries) = std::fs::read_dir(scenes.join(dir)) else { continue };
        for path in entries.map(|e| e.unwrap().path()).filter(|p| p.extension().is_some_and(|e| e == "toml")) {
            // Some regression scenes are refused on purpose (a gather radius below the scene's floor).
            let Ok(prep) = Prepared::new(&Scene::load(&path).unwrap(), &path) else { continue };
            let (blob, frame) = (prep.encode_scene().unwrap(), prep.encode_frame().unwrap());
            let textures = prep.encode_textures().unwrap();
            let textures: Vec<&[u8]> = textures.iter().map(Vec::as_slice).collect();
            if let Err(e) = Prepared::from_blobs(&blob, None, &frame, &textures, usize::MAX) {
                panic!("{}: {e}", path.display());
            }
            n += 1;
        }
    }
    assert!(n >= 20, "{n} scenes");
}

/// A 2 × 2 cut-out of `values` values in all and `cutoff`.
fn mask(values: usize, cutoff: f32) -> photon_core::geometry::mask::AlphaMask {
    let alpha = vec![32768; values];
    photon_core::geometry::mask::AlphaMask {
        width: 2,
        height: 2,
        alpha,
        repeat: true,
        bilinear: false,
        factor: 1.0,
        cutoff,
    }
}

/// One corruption: what it changes, and the table (or field) its error must name.
type Case = (&'static str, Box<dyn Fn(&mut Blob)>, String);

fn cases(b: &Blob, fog: bool) -> Vec<Case> {
    let l = landmarks(b);
    let (prims, lights, materials) = (b.geometry.prims.len(), b.lights.lights.len(), b.materials.len());
    let torus = &b.geometry.meshes[l.torus];
    let (normals, uvs, faces) = (torus.normals.len(), torus.uvs.len(), torus.normal_indices.len());
    let (m, tp, dp, al, pl, ut) = (l.torus, l.torus_prim, l.dark_prim, l.area_light, l.point_light, l.uv_triangle);
    let mesh_of = |b: &mut Blob, i: usize, f: &dyn Fn(&mut u32, &mut u32)| {
        if let Shape::Triangle(t) = &mut b.geometry.prims[i].shape {
            f(&mut t.mesh, &mut t.face);
        }
    };
    let mut out: Vec<Case> = vec![
        (
            "a light's primitive past the primitives",
            Box::new(move |b| {
                if let Light::Area { prim, .. } = &mut b.lights.lights[al] {
                    *prim = prims as u32 + 3;
                }
            }),
            "prims".into(),
        ),
        (
            "a light's primitive on another primitive",
            Box::new(move |b| {
                if let Light::Area { prim, .. } = &mut b.lights.lights[al] {
                    *prim = dp as u32;
                }
            }),
            format!("lights[{al}].prim"),
        ),
        (
            "the light choice table short",
            Box::new(|b| {
                b.lights.pmf.pop();
            }),
            "lights.pmf".into(),
        ),
        (
            "the cumulative light table short",
            Box::new(|b| {
                b.lights.cdf.pop();
            }),
            "lights.cdf".into(),
        ),
        (
            "an environment before the last light",
            Box::new(|b| {
                let bounds = BoundingSphere { center: glam::Vec3A::ZERO, radius: 1.0 };
                let env = Light::Environment {
                    radiance: photon_core::Rgb::ONE,
                    image: NONE,
                    turn: glam::Vec2::X,
                    mean: photon_core::Rgb::ONE,
                    bounds,
                };
                let point = Light::Point { p: glam::Vec3A::Y, intensity: photon_core::Rgb::ONE };
                b.lights.lights.extend([env, point]);
                b.lights.cdf.extend([1.0, 1.0]);
                b.lights.pmf.extend([0.0, 0.0]);
            }),
            format!("lights[{lights}]"),
        ),
        (
            "a primitive's light past the lights",
            Box::new(move |b| b.geometry.prims[dp].light = lights as u32),
            "lights".into(),
        ),
        (
            "a primitive's light on a point light",
            Box::new(move |b| b.geometry.prims[dp].light = pl as u32),
            format!("prims[{dp}].light"),
        ),
        (
            "a primitive's material",
            Box::new(move |b| b.geometry.prims[tp].material = materials as u32),
            "materials".into(),
        ),
        ("a plane's material", Box::new(move |b| b.geometry.planes[0].material = u32::MAX), "materials".into()),
        (
            "a mesh's normal index",
            Box::new(move |b| b.geometry.meshes[m].normal_indices[17][1] = normals as u32),
            format!("meshes[{m}].normals"),
        ),
        (
            "a mesh's UV index",
            Box::new(move |b| b.geometry.meshes[m].uv_indices[faces - 1][2] = uvs as u32 + 100),
            format!("meshes[{m}].uvs"),
        ),
        (
            "a mesh's UV faces fewer than its normal faces",
            Box::new(move |b| {
                b.geometry.meshes[m].uv_indices.pop();
            }),
            format!("meshes[{m}].uv_indices"),
        ),
        ("a triangle's mesh", Box::new(move |b| mesh_of(b, tp, &|mesh, _| *mesh = NO_MESH - 1)), "meshes".into()),
        (
            "a triangle's face",
            Box::new(move |b| mesh_of(b, tp, &|_, face| *face = faces as u32)),
            format!("meshes[{m}].normal_indices"),
        ),
        ("a UV-only triangle's face", Box::new(move |b| mesh_of(b, ut, &|_, face| *face = 1)), "uv_indices".into()),
        ("a mesh's cut-out past the cut-outs", Box::new(move |b| b.geometry.meshes[m].mask = Some(0)), "masks".into()),
        ("a cut-out's texels short", Box::new(|b| b.geometry.masks.push(mask(3, 0.5))), "masks[0]".into()),
        ("a cut-out's texels too many", Box::new(|b| b.geometry.masks.push(mask(12, 0.5))), "masks[0]".into()),
        ("a cut-out's cutoff not finite", Box::new(|b| b.geometry.masks.push(mask(4, f32::NAN))), "masks[0]".into()),
        (
            "a mesh's tangents fewer than its normals",
            Box::new(move |b| b.geometry.meshes[m].tangents = vec![[1.0, 0.0, 0.0, 1.0]; normals - 1]),
            format!("meshes[{m}].tangents"),
        ),
    ];
    if fog {
        let objects = b.media.as_ref().unwrap().boundaries.len() as u32;
        let fogged: Vec<Case> = vec![
            (
                "a primitive's object",
                Box::new(move |b| b.geometry.prims[tp].object = objects),
                "media.boundaries".into(),
            ),
            (
                "a plane's object",
                Box::new(move |b| b.geometry.planes[0].object = objects + 9),
                "media.boundaries".into(),
            ),
            (
                "the lights' media short",
                Box::new(|b| {
                    b.media.as_mut().unwrap().lights.pop();
                }),
                "media.lights".into(),
            ),
        ];
        out.extend(fogged);
    }
    out
}

#[test]
fn each_corrupted_index_is_refused_naming_its_table() {
    for fog in [false, true] {
        let (_, blob, frame) = prepared(fog);
        let parts: Blob = codec::decode(&blob, usize::MAX).unwrap();
        for (what, corrupt, table) in cases(&parts, fog) {
            let mut bad = parts.clone();
            corrupt(&mut bad);
            let e = match decode(&bad, &frame) {
                Ok(_) => panic!("fog {fog}: {what}: decoded"),
                Err(e) => e,
            };
            let named = table_of(&e);
            assert!(named.as_deref().is_some_and(|t| t.ends_with(&table)), "fog {fog}: {what}: {e} (want {table})");
            assert!(e.to_string().starts_with("scene blob: "), "{e}");
        }
    }
}

#[test]
fn the_error_names_field_index_and_table() {
    let (_, blob, frame) = prepared(false);
    let mut parts: Blob = codec::decode(&blob, usize::MAX).unwrap();
    let m = landmarks(&parts).torus;
    let normals = parts.geometry.meshes[m].normals.len();
    parts.geometry.meshes[m].normal_indices[17][1] = 900_000;
    let e = decode(&parts, &frame).err().unwrap().to_string();
    assert_eq!(
        e,
        format!(
            "scene blob: meshes[{m}].normal_indices[17][1] = 900000, but meshes[{m}].normals has {normals} entries"
        )
    );
}

/// SplitMix64: a small deterministic stream for the fuzz.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// A value for an index into a table of `len`: half the time within the table, a quarter just past its end, a
/// quarter anything.
fn value(rng: &mut Rng, len: usize) -> u32 {
    match rng.below(4) {
        0 | 1 => rng.below(len) as u32,
        2 => (len + rng.below(3)) as u32,
        _ => rng.next() as u32,
    }
}

/// Sets one index field chosen by `rng` to `value(len)`, where `len` is the length of the table it points
/// into; returns the field's name.
fn mutate(b: &mut Blob, rng: &mut Rng) -> String {
    let (prims, lights, materials, meshes) =
        (b.geometry.prims.len(), b.lights.lights.len(), b.materials.len(), b.geometry.meshes.len());
    let objects = b.media.as_ref().map_or(12, |m| m.boundaries.len());
    match rng.below(9) {
        0 => {
            let i = rng.below(prims);
            b.geometry.prims[i].material = value(rng, materials);
            format!("prims[{i}].material")
        }
        1 => {
            let i = rng.below(prims);
            b.geometry.prims[i].light = if rng.below(4) == 0 { NONE } else { value(rng, lights) };
            format!("prims[{i}].light")
        }
        2 => {
            let i = rng.below(prims);
            b.geometry.prims[i].object = value(rng, objects);
            format!("prims[{i}].object")
        }
        3 => {
            let i = rng.below(prims);
            let (v, w) = (value(rng, meshes), value(rng, 1300));
            if let Shape::Triangle(t) = &mut b.geometry.prims[i].shape {
                if rng.below(2) == 0 { t.mesh = v } else { t.face = w }
            }
            format!("prims[{i}].shape")
        }
        4 => {
            let i = rng.below(lights);
            let v = value(rng, prims);
            if let Light::Area { prim, .. } = &mut b.lights.lights[i] {
                *prim = v;
            }
            format!("lights[{i}].prim")
        }
        5 => {
            let i = rng.below(b.geometry.planes.len());
            let (v, w) = (value(rng, materials), value(rng, objects));
            let p = &mut b.geometry.planes[i];
            if rng.below(2) == 0 {
                p.material = v
            } else {
                p.object = w
            }
            format!("planes[{i}]")
        }
        6 | 7 => {
            let m = rng.below(meshes);
            let mesh = &mut b.geometry.meshes[m];
            let normals = rng.below(2) == 0;
            let (ix, len) = if normals {
                (&mut mesh.normal_indices, mesh.normals.len())
            } else {
                (&mut mesh.uv_indices, mesh.uvs.len())
            };
            if ix.is_empty() {
                return format!("meshes[{m}] (no indices)");
            }
            let (f, k) = (rng.below(ix.len()), rng.below(3));
            ix[f][k] = value(rng, len);
            format!("meshes[{m}] normals {normals} [{f}][{k}]")
        }
        _ => {
            // A table shortened or lengthened.
            match rng.below(3) {
                0 => {
                    b.lights.pmf.pop();
                }
                1 => b.lights.cdf.push(1.0),
                _ => {
                    let m = rng.below(meshes);
                    b.geometry.meshes[m].uv_indices.truncate(rng.below(3));
                }
            }
            "a table's length".into()
        }
    }
}

#[test]
fn random_corruptions_are_refused_or_render_without_a_panic() {
    let (mut refused, mut rendered) = (0, 0);
    for fog in [false, true] {
        let (_, blob, frame) = prepared(fog);
        let parts: Blob = codec::decode(&blob, usize::MAX).unwrap();
        for seed in 0..200u64 {
            let mut rng = Rng(seed ^ (u64::from(fog) << 32));
            let mut bad = parts.clone();
            let what = mutate(&mut bad, &mut rng);
            let bytes = codec::encode(&bad).unwrap();
            let outcome = catch_unwind(AssertUnwindSafe(|| {
                Prepared::from_blobs(&bytes, None, &frame, &[], usize::MAX).map(|p| render(&p))
            }));
            match outcome {
                Err(_) => panic!("fog {fog}, seed {seed}: {what}: panicked"),
                Ok(Err(_)) => refused += 1,
                Ok(Ok(pixels)) => {
                    assert_eq!(pixels.len(), 3 * 8 * 6);
                    rendered += 1;
                }
            }
        }
    }
    // Both outcomes occur: the fuzz reaches the renderer as well as the check.
    assert!(refused > 50 && rendered > 50, "refused {refused}, rendered {rendered}");
}
