//! PLY meshes (issue 33, item 2): the shipped torus and icosphere written as ASCII, binary little-endian and
//! binary big-endian PLY load to the same bits, and to the bits of the OBJ they were converted from; a scene
//! renders to the same bytes with either file; every malformed PLY fails with its file (and its line, in the
//! header and in an ASCII body) and what was expected, and a mesh file of another extension fails with the
//! scene's field and the two extensions it may have.

#![allow(clippy::unwrap_used)]

use glam::{Affine3A, Vec3};
use photon_core::geometry::mesh::{MeshData, MeshError, Normals, load_obj};
use photon_core::geometry::mesh_file::load_mesh;
use photon_core::geometry::ply::parse_ply;
use photon_core::prepare::Prepared;
use photon_core::prepare::lod::{MeshLod, plan};
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::{Path, PathBuf};

fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-ply-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn meshes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/meshes")
}

/// A mesh whose positions, normals and UVs share one index per corner, as OBJ text and PLY both can hold it.
#[derive(Default)]
struct Shared {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    polygons: Vec<Vec<u32>>,
}

/// The mesh of an OBJ whose face corners name one index (`f 1 2 3` or `f 1/1/1 …`), each number read as f32 as
/// the OBJ reader reads it.
fn from_obj(text: &str) -> Shared {
    let mut m = Shared::default();
    let floats = |rest: &[&str]| rest.iter().map(|w| w.parse::<f32>().unwrap()).collect::<Vec<f32>>();
    for line in text.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.first() {
            Some(&"v") => m.positions.push(floats(&words[1..4]).try_into().unwrap()),
            Some(&"vn") => m.normals.push(floats(&words[1..4]).try_into().unwrap()),
            Some(&"vt") => m.uvs.push(floats(&words[1..3]).try_into().unwrap()),
            Some(&"f") => m.polygons.push(
                words[1..]
                    .iter()
                    .map(|w| {
                        let parts: Vec<&str> = w.split('/').collect();
                        assert!(parts.iter().all(|p| *p == parts[0]), "{w}: not one index per corner");
                        parts[0].parse::<u32>().unwrap() - 1
                    })
                    .collect(),
            ),
            _ => {}
        }
    }
    m
}

#[derive(Clone, Copy, Debug)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

/// The mesh as a PLY file: positions as `double` (any scalar type is read), normals and UVs (`u`/`v`) as `float`
/// when the mesh has them, faces as `list uchar uint vertex_indices`, and a colour property and an edge element
/// that the reader passes over.
fn to_ply(m: &Shared, encoding: Encoding) -> Vec<u8> {
    let format = match encoding {
        Encoding::Ascii => "ascii",
        Encoding::Little => "binary_little_endian",
        Encoding::Big => "binary_big_endian",
    };
    let mut header = format!("ply\nformat {format} 1.0\ncomment written by core/tests/ply_meshes.rs\n");
    header += &format!("element vertex {}\n", m.positions.len());
    header += "property double x\nproperty double y\nproperty double z\nproperty uchar red\n";
    if !m.normals.is_empty() {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if !m.uvs.is_empty() {
        header += "property float u\nproperty float v\n";
    }
    header += &format!("element face {}\nproperty list uchar uint vertex_indices\n", m.polygons.len());
    header += "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
    let mut out = header.into_bytes();
    let mut ascii = String::new();
    let mut put = |out: &mut Vec<u8>, value: Value| match encoding {
        Encoding::Ascii => {
            let word = match value {
                Value::F64(v) => format!("{v}"),
                Value::F32(v) => format!("{v}"),
                Value::U8(v) => format!("{v}"),
                Value::U32(v) => format!("{v}"),
                Value::I32(v) => format!("{v}"),
                Value::End => {
                    ascii.pop();
                    out.extend_from_slice(ascii.as_bytes());
                    out.push(b'\n');
                    ascii.clear();
                    return;
                }
            };
            ascii += &word;
            ascii.push(' ');
        }
        Encoding::Little | Encoding::Big => {
            let big = matches!(encoding, Encoding::Big);
            let bytes: Vec<u8> = match value {
                Value::F64(v) if big => v.to_be_bytes().to_vec(),
                Value::F64(v) => v.to_le_bytes().to_vec(),
                Value::F32(v) if big => v.to_be_bytes().to_vec(),
                Value::F32(v) => v.to_le_bytes().to_vec(),
                Value::U8(v) => vec![v],
                Value::U32(v) if big => v.to_be_bytes().to_vec(),
                Value::U32(v) => v.to_le_bytes().to_vec(),
                Value::I32(v) if big => v.to_be_bytes().to_vec(),
                Value::I32(v) => v.to_le_bytes().to_vec(),
                Value::End => vec![],
            };
            out.extend_from_slice(&bytes);
        }
    };
    for (i, p) in m.positions.iter().enumerate() {
        p.iter().for_each(|&c| put(&mut out, Value::F64(f64::from(c))));
        put(&mut out, Value::U8(200));
        if let Some(n) = m.normals.get(i) {
            n.iter().for_each(|&c| put(&mut out, Value::F32(c)));
        }
        if let Some(uv) = m.uvs.get(i) {
            uv.iter().for_each(|&c| put(&mut out, Value::F32(c)));
        }
        put(&mut out, Value::End);
    }
    for polygon in &m.polygons {
        put(&mut out, Value::U8(polygon.len() as u8));
        polygon.iter().for_each(|&v| put(&mut out, Value::U32(v)));
        put(&mut out, Value::End);
    }
    put(&mut out, Value::I32(0));
    put(&mut out, Value::I32(1));
    put(&mut out, Value::End);
    out
}

/// One number of a PLY body, or the end of its row.
#[derive(Clone, Copy)]
enum Value {
    F64(f64),
    F32(f32),
    U8(u8),
    U32(u32),
    I32(i32),
    End,
}

/// The bits of a mesh's positions, normals, normal indices, UVs and UV indices.
type MeshBits = (Vec<u32>, Vec<u32>, Vec<[u32; 3]>, Vec<u32>, Vec<[u32; 3]>);

/// Every bit of a mesh as it is stored: positions, then the shading data with its indices.
fn bits(m: &MeshData) -> MeshBits {
    let sh = &m.shading;
    (
        float_bits(m.triangles.iter().flat_map(|t| t.iter().flat_map(|p| p.to_array()))),
        float_bits(sh.normals.iter().flatten().copied()),
        sh.normal_indices.clone(),
        float_bits(sh.uvs.iter().flatten().copied()),
        sh.uv_indices.clone(),
    )
}

/// The bits of what each face corner gets: its position, normal and UV, whatever order the arrays hold them in
/// (the OBJ reader keeps its own).
fn corner_bits(m: &MeshData) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let sh = &m.shading;
    let at = |table: &[[u32; 3]], f: usize| table.get(f).copied().into_iter().flatten();
    let normals = (0..m.triangles.len()).flat_map(|f| at(&sh.normal_indices, f).flat_map(|i| sh.normals[i as usize]));
    let uvs = (0..m.triangles.len()).flat_map(|f| at(&sh.uv_indices, f).flat_map(|i| sh.uvs[i as usize]));
    (
        float_bits(m.triangles.iter().flat_map(|t| t.iter().flat_map(|p| p.to_array()))),
        float_bits(normals),
        float_bits(uvs),
    )
}

fn float_bits(v: impl Iterator<Item = f32>) -> Vec<u32> {
    v.map(f32::to_bits).collect()
}

/// A transform that scales unevenly, mirrors, rotates and moves: normals and the winding must follow it.
fn placement() -> Affine3A {
    Affine3A::from_scale_rotation_translation(
        Vec3::new(0.7, -1.3, 0.9),
        glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.4),
        Vec3::new(0.5, 1.0, -2.0),
    )
}

#[test]
fn every_encoding_loads_to_the_bits_of_the_obj() {
    let dir = temp_dir("encodings");
    for (name, with_normals_and_uvs) in [("torus", true), ("icosphere", false)] {
        let obj_path = meshes().join(format!("{name}.obj"));
        let shared = from_obj(&std::fs::read_to_string(&obj_path).unwrap());
        assert_eq!((!shared.normals.is_empty(), !shared.uvs.is_empty()), (with_normals_and_uvs, with_normals_and_uvs));
        for normals in [Normals::default(), Normals::Smooth { crease_angle: 5.0 }, Normals::Flat] {
            let obj = load_obj(&obj_path, &placement(), normals, 1 << 30).unwrap();
            assert!(obj.triangles.len() >= 800, "{name}: {} triangles", obj.triangles.len());
            let mut loaded = Vec::new();
            for encoding in [Encoding::Ascii, Encoding::Little, Encoding::Big] {
                let path = dir.join(format!("{name}-{encoding:?}.ply"));
                std::fs::write(&path, to_ply(&shared, encoding)).unwrap();
                loaded.push((encoding, load_mesh(&path, &placement(), normals, 1 << 30).unwrap()));
            }
            let (_, ascii) = &loaded[0];
            for (encoding, ply) in &loaded {
                assert!(bits(ply) == bits(ascii), "{name}, {normals:?}: {encoding:?} differs from ASCII");
                assert!(
                    corner_bits(ply) == corner_bits(&obj),
                    "{name}, {normals:?}: {encoding:?} differs from the OBJ"
                );
            }
            let has = |m: &MeshData| (m.shading.normal_indices.len(), m.shading.uv_indices.len());
            let faces = obj.triangles.len();
            let expected =
                (if normals == Normals::Flat { 0 } else { faces }, if with_normals_and_uvs { faces } else { 0 });
            assert_eq!(has(ascii), expected, "{name}, {normals:?}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The shipped PLY scene with its two tori read from `file`, at 24×24 pixels and 4 spp: small enough that level of
/// detail simplifies both (their bounds come from the file's vertices).
fn scene(dir: &Path, file: &str) -> PathBuf {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/ply-mesh.toml");
    let text = std::fs::read_to_string(shipped).unwrap();
    assert_eq!(text.matches("\"meshes/torus.ply\"").count(), 2);
    let path = dir.join(format!("{file}.toml"));
    std::fs::write(&path, text.replace("meshes/torus.ply", file)).unwrap();
    path
}

/// The scene's level-of-detail plan, and the bits of its image.
fn render(path: &Path) -> (Vec<Option<MeshLod>>, Vec<u32>) {
    let mut s = Scene::load(path).unwrap();
    (s.camera.width, s.camera.height, s.render.spp) = (24, 24, 4);
    let prep = Prepared::new(&s, path).unwrap();
    (plan(&s), render_image(&prep, &|_| {}).pixels.iter().map(|v| v.to_bits()).collect())
}

#[test]
fn a_ply_and_the_obj_it_came_from_render_the_same_bytes() {
    let dir = temp_dir("render");
    let obj = std::fs::read_to_string(meshes().join("torus.obj")).unwrap();
    std::fs::write(dir.join("torus.obj"), &obj).unwrap();
    std::fs::write(dir.join("torus.PLY"), to_ply(&from_obj(&obj), Encoding::Little)).unwrap();
    let (lod, from_obj) = render(&scene(&dir, "torus.obj"));
    let (ply_lod, from_ply) = render(&scene(&dir, "torus.PLY"));
    // The level of detail reads the PLY's bounds as the OBJ's, and simplifies both alike.
    assert_eq!(lod.iter().filter(|l| matches!(l, Some(MeshLod::Simplify { .. }))).count(), 2, "{lod:?}");
    assert_eq!(ply_lod, lod);
    assert!(from_obj == from_ply, "the PLY renders other pixels than the OBJ");
    let lit = from_obj.chunks(3).filter(|p| p.iter().any(|&b| f32::from_bits(b) > 0.0)).count();
    assert!(lit > from_obj.len() / 6, "{lit} lit pixels");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A one-triangle PLY of the given format line (positions as `float`), then the body.
fn triangle(format: &str, body: &str) -> String {
    format!(
        "ply\n{format}\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n\
         property list uchar int vertex_indices\nend_header\n{body}"
    )
}

fn load(dir: &Path, name: &str, bytes: &[u8]) -> Result<MeshData, MeshError> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    load_mesh(&path, &Affine3A::IDENTITY, Normals::default(), 1 << 20)
}

/// The little-endian bytes of a binary triangle body: three vertices of three floats, one face.
fn binary_triangle() -> Vec<u8> {
    let mut b = Vec::new();
    for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        p.iter().for_each(|c| b.extend_from_slice(&c.to_le_bytes()));
    }
    b.push(3);
    [0i32, 1, 2].iter().for_each(|i| b.extend_from_slice(&i.to_le_bytes()));
    b
}

#[test]
fn every_malformed_ply_names_its_file_and_what_was_expected() {
    let dir = temp_dir("errors");
    // The header is lines 1 to 9, the vertices lines 10 to 12, the face line 13.
    let good = triangle("format ascii 1.0", "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    assert_eq!(load(&dir, "good.ply", good.as_bytes()).unwrap().triangles.len(), 1);
    let binary = |body: &[u8]| [triangle("format binary_little_endian 1.0", "").as_bytes(), body].concat();
    let whole = binary_triangle();
    assert_eq!(load(&dir, "good-binary.ply", &binary(&whole)).unwrap().triangles.len(), 1);
    // The good ASCII triangle with `from` replaced by `to`.
    let edit = |from: &str, to: &str| good.replacen(from, to, 1).into_bytes();
    let no_face_element = edit("element face 1\nproperty list uchar int vertex_indices\n", "");
    // (file name, its bytes, the line its message names, words the message must hold)
    let cases: Vec<(&str, Vec<u8>, Option<usize>, &str)> = vec![
        (
            "format.ply",
            edit("ascii", "binary_middle_endian"),
            Some(2),
            "unknown format `format binary_middle_endian 1.0`",
        ),
        ("not-ply.ply", b"v 0 0 0\nv 1 0 0\n".to_vec(), Some(1), "not a PLY file"),
        ("no-y.ply", edit("property float y\n", ""), None, "the `vertex` element has no `y` property"),
        ("index.ply", edit("3 0 1 2", "3 0 1 3"), Some(13), "`face` 0: vertex index 3 is out of range (0 to 2)"),
        ("negative.ply", edit("3 0 1 2", "3 0 -1 2"), Some(13), "vertex index -1 is out of range"),
        ("line.ply", edit("3 0 1 2", "2 0 1"), Some(13), "`face` 0: a face needs at least three vertices, found 2"),
        ("nan.ply", edit("1 0 0\n", "1 1e99 0\n"), Some(11), "`vertex` 1: its position [1.0, inf, 0.0] is not finite"),
        ("short-row.ply", edit("1 0 0\n", "1 0\n"), Some(11), "`vertex` 1: `1 0`"),
        ("no-faces.ply", edit("element face 1", "element face 0"), None, "no faces"),
        ("no-face-element.ply", no_face_element, None, "no faces"),
        ("truncated.ply", binary(&whole[..whole.len() - 3]), None, "the file ends inside `face` 0 of 1 (a truncated"),
        ("truncated-vertex.ply", binary(&whole[..20]), None, "the file ends inside `vertex` 1 of 3"),
        ("empty.ply", Vec::new(), None, "header"),
    ];
    for (name, bytes, line, expected) in &cases {
        let e = load(&dir, name, bytes).unwrap_err();
        let message = e.to_string();
        assert!(matches!(e, MeshError::MalformedPly { .. }), "{name}: {e:?}");
        let place = line.map_or(format!("{name}: "), |l| format!("{name}:{l}: "));
        let tail = message.strip_prefix(&format!("{}/{place}malformed PLY: ", dir.display()));
        assert!(tail.is_some_and(|t| t.contains(expected)), "{name}: `{message}` lacks `{place}…{expected}`");
        assert!(message.len() < 600, "{name}: {} bytes", message.len());
    }
    // The size limit holds for PLY as for OBJ.
    let path = dir.join("big.ply");
    std::fs::write(&path, &good).unwrap();
    let e = load_mesh(&path, &Affine3A::IDENTITY, Normals::default(), 100).unwrap_err().to_string();
    assert!(e.contains("big.ply") && e.contains("limits.mesh_mib"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every prefix of the shipped binary torus, the same file with any one header byte changed, and headers that
/// promise billions of rows: each loads or fails with a [`MeshError`], never a panic, and quickly.
#[test]
fn no_cut_or_corrupted_ply_panics() {
    let file = Path::new("torus.ply");
    let bytes = std::fs::read(meshes().join("torus.ply")).unwrap();
    let parse = |b: &[u8]| parse_ply(b, file, &Affine3A::IDENTITY, Normals::default());
    assert_eq!(parse(&bytes).unwrap().triangles.len(), 2 * 24 * 12);
    let t0 = std::time::Instant::now();
    let body = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    for cut in (0..body).chain((body..bytes.len()).step_by(7)) {
        assert!(parse(&bytes[..cut]).is_err(), "{cut} of {} bytes loaded", bytes.len());
    }
    for at in 0..body {
        for b in [b'0', b'9', b' ', b'\n', 0xFF] {
            let mut changed = bytes.clone();
            changed[at] = b;
            let _ = parse(&changed);
        }
    }
    let huge = String::from_utf8_lossy(&bytes[..body]).replace("element vertex 325", "element vertex 4000000000");
    let e = parse(&[huge.as_bytes(), &bytes[body..]].concat()).unwrap_err().to_string();
    assert!(e.contains("the file ends inside `vertex`"), "{e}");
    let empty_rows =
        triangle("format binary_little_endian 1.0", "").replace("end_header", "element nothing 4000000000\nend_header");
    assert!(parse(&[empty_rows.as_bytes(), &binary_triangle()].concat()).is_ok());
    assert!(t0.elapsed() < std::time::Duration::from_secs(20), "{:?}", t0.elapsed());
}

#[test]
fn a_mesh_file_of_another_extension_is_refused_with_its_field() {
    let dir = temp_dir("extension");
    std::fs::write(dir.join("torus.stl"), b"solid torus\nendsolid torus\n").unwrap();
    let path = scene(&dir, "torus.stl");
    let s = Scene::load(&path).unwrap();
    let e = Prepared::new(&s, &path).unwrap_err().to_string();
    assert!(
        e.contains("objects[6].file")
            && e.contains("torus.stl: unknown mesh format")
            && e.contains("`.obj`")
            && e.contains("`.ply`"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
