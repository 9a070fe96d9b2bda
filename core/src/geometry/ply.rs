//! PLY meshes (Turk's polygon file format), read with `ply-rs-bw`: ASCII, binary little-endian and binary
//! big-endian.
//!
//! ```toml
//! [[objects]]
//! type = "mesh"
//! file = "meshes/torus.ply"          # relative to the scene file; `.ply` in any case
//! material = "gold"
//! transform = { translate = [0.0, 0.5, 0.0], scale = 0.75 }
//! ```
//! The `vertex` element gives the positions (`x`, `y`, `z`), and when the file has them the normals (`nx`, `ny`,
//! `nz`) and texture coordinates (the first pair present of `u`/`v`, `s`/`t` and `texture_u`/`texture_v`); each
//! may be of any scalar type (an integer, `float` or `double`) and is rounded to `f32`. The `face` element's list
//! `vertex_indices` (or `vertex_index`), of any integer type, gives each polygon's vertices, counted from 0;
//! polygons are ear-clipped as OBJ's are ([`crate::geometry::mesh`]). Every other element and property (colours,
//! edges, materials) is read past and ignored. Normals follow [`Normals`] as for OBJ: the file's when it has them,
//! else smooth normals within the crease angle.
//!
//! Errors never panic: a header that is not PLY (or of another format than the three), a `vertex` element without
//! `x`, `y` or `z`, a face of fewer than three vertices or with an index out of range, a non-finite number, a
//! truncated binary body, or a file without faces is a [`MeshError::MalformedPly`] that names the file, the line
//! (in the header and in an ASCII body) and the element and its index (in any body).

use crate::geometry::MeshShading;
use crate::geometry::mesh::{MeshData, MeshError, Normals};
use crate::geometry::mesh::{push_crease_normals, triangulate, warn_if_not_plain, winding, world_normals};
use crate::input::excerpt;
use crate::math::Aabb;
use glam::{Affine3A, Vec3};
use ply_rs_bw::parser::{ParseError, Parser, Reader};
use ply_rs_bw::ply::{ElementDef, Encoding, Header, Property, PropertyAccess, PropertyAccessResult, PropertyType};
use std::io::{BufRead, Cursor, ErrorKind};
use std::path::Path;

/// The texture-coordinate property pairs looked for, in this order.
const UV_NAMES: [[&str; 2]; 3] = [["u", "v"], ["s", "t"], ["texture_u", "texture_v"]];

/// The names of the face element's vertex-index list, in the order looked for.
const INDEX_NAMES: [&str; 2] = ["vertex_indices", "vertex_index"];

/// Parses the bytes of a PLY file and places its mesh in the world with `world_from_object`; `file` names it in
/// errors and warnings. [`crate::geometry::mesh_file::load_mesh`] reads the file.
pub fn parse_ply(
    bytes: &[u8],
    file: &Path,
    world_from_object: &Affine3A,
    normals: Normals,
) -> Result<MeshData, MeshError> {
    let ply = read(bytes, file, true)?;
    Ok(assemble(&ply, file, world_from_object, normals))
}

/// The world-space bounding box of a PLY file's vertices, read from its bytes (the body is read only as far as
/// the `vertex` element).
pub fn ply_bounds(bytes: &[u8], file: &Path, world_from_object: &Affine3A) -> Result<Aabb, MeshError> {
    let ply = read(bytes, file, false)?;
    Ok(ply.positions.iter().fold(Aabb::EMPTY, |b, &p| {
        let w = world_from_object.transform_point3(p);
        b.union(Aabb { min: w, max: w })
    }))
}

/// A PLY file's mesh as the file gives it, in object space, every index checked.
#[derive(Debug, Default)]
struct PlyMesh {
    positions: Vec<Vec3>,
    /// One per position, when the file has normals.
    normals: Option<Vec<Vec3>>,
    /// One per position, when the file has texture coordinates.
    uvs: Option<Vec<[f32; 2]>>,
    /// The polygons' vertex indices, one polygon after another.
    indices: Vec<u32>,
    /// The number of vertices of each polygon (at least three).
    arities: Vec<u32>,
}

/// Where the properties photon reads sit in a `vertex` row: the slots of [`VertexRow`].
#[derive(Clone, Copy, Debug)]
struct VertexLayout {
    /// Whether the file has `nx`, `ny` and `nz`.
    normals: bool,
    /// The texture-coordinate pair the file has ([`UV_NAMES`]), if any.
    uv: Option<usize>,
}

/// The slot of each vertex property photon reads: x y z, nx ny nz, then each pair of [`UV_NAMES`].
fn vertex_slot(name: &str) -> Option<usize> {
    const NAMES: [&str; 6] = ["x", "y", "z", "nx", "ny", "nz"];
    NAMES
        .iter()
        .position(|&n| n == name)
        .or_else(|| UV_NAMES.iter().flatten().position(|&n| n == name).map(|k| NAMES.len() + k))
}

/// The number of slots of [`vertex_slot`].
const VERTEX_SLOTS: usize = 6 + 2 * UV_NAMES.len();

/// One `vertex` row: the value of each property of [`vertex_slot`], rounded to `f32` (the header's checks make
/// sure that each slot read is there).
struct VertexRow([f32; VERTEX_SLOTS]);

impl PropertyAccess for VertexRow {
    fn new() -> Self {
        VertexRow([0.0; VERTEX_SLOTS])
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let Some(slot) = vertex_slot(name) else { return PropertyAccessResult::Ignored };
        // A list where a number belongs was refused with the header; here it is only ignored.
        match property.to_f32_lossy() {
            Some(v) => {
                self.0[slot] = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

/// One `face` row: the vertex-index list under each name of [`INDEX_NAMES`], widened to `i64` (so a negative
/// `int` stays negative and is refused by its value).
#[derive(Default)]
struct FaceRow([Vec<i64>; INDEX_NAMES.len()]);

impl PropertyAccess for FaceRow {
    fn new() -> Self {
        FaceRow::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let Some(slot) = INDEX_NAMES.iter().position(|&n| n == name) else { return PropertyAccessResult::Ignored };
        let widened: Vec<i64> = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            // Scalars and lists of floats were refused with the header.
            _ => return PropertyAccessResult::Ignored,
        };
        self.0[slot] = widened;
        PropertyAccessResult::Set
    }
}

/// A row of an element photon does not read.
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

/// Reads the header and the body's `vertex` and `face` elements (or, unless `faces`, only as far as the
/// vertices), checking every value photon uses.
fn read(bytes: &[u8], file: &Path, faces: bool) -> Result<PlyMesh, MeshError> {
    let malformed = |line: Option<usize>, message: String| MeshError::MalformedPly { file: file.into(), line, message };
    let mut reader = Reader::new(Cursor::new(bytes));
    let header = Parser::<Skip>::new().read_header(&mut reader).map_err(|e| {
        let line = e.line();
        malformed(line, header_message(&e, line.and_then(|l| nth_line(bytes, l))))
    })?;
    // The line of the first body row, in an ASCII file (each row is one line).
    let mut line = (header.encoding == Encoding::Ascii).then(|| reader.line());
    let mut body = reader.into_inner();
    let (layout, index_slot) = check_header(&header).map_err(|m| malformed(None, m))?;
    let mut out = PlyMesh::default();
    let mut faces_line = None;
    let mut rows: Vec<FaceRow> = Vec::new();
    // The line of row `i` of an element whose first row is on `line`.
    let at = |line: Option<usize>, i: usize| line.map(|l| l + i);
    for def in header.elements.values() {
        match def.name.as_str() {
            "vertex" => {
                let read = read_rows::<VertexRow>(&mut body, header.encoding, def, true)
                    .map_err(|(i, m)| malformed(at(line, i), m))?;
                out = vertices(&read, layout).map_err(|(i, m)| malformed(at(line, i), m))?;
                if !faces {
                    return Ok(out);
                }
            }
            "face" => {
                faces_line = line;
                rows = read_rows::<FaceRow>(&mut body, header.encoding, def, true)
                    .map_err(|(i, m)| malformed(at(line, i), m))?;
            }
            _ => {
                read_rows::<Skip>(&mut body, header.encoding, def, false)
                    .map_err(|(i, m)| malformed(at(line, i), m))?;
            }
        }
        line = line.map(|l| l + def.count);
    }
    let count = out.positions.len();
    for (i, row) in rows.iter().enumerate() {
        let polygon = &row.0[index_slot];
        let place = |message: String| malformed(faces_line.map(|l| l + i), format!("`face` {i}: {message}"));
        if polygon.len() < 3 {
            return Err(place(format!("a face needs at least three vertices, found {}", polygon.len())));
        }
        for &ix in polygon {
            match u32::try_from(ix) {
                Ok(v) if (v as usize) < count => out.indices.push(v),
                _ if count == 0 => return Err(place(format!("vertex index {ix}, but the file has no vertices"))),
                _ => return Err(place(format!("vertex index {ix} is out of range (0 to {})", count - 1))),
            }
        }
        out.arities.push(polygon.len() as u32);
    }
    if out.arities.is_empty() {
        return Err(malformed(None, "no faces: the `face` element is missing or empty".into()));
    }
    Ok(out)
}

/// What photon reads of the header, or what is wrong with it: the vertex layout and which name of
/// [`INDEX_NAMES`] the face's index list has (the slot of [`FaceRow`] to read).
fn check_header(header: &Header) -> Result<(VertexLayout, usize), String> {
    let vertex = header.elements.get("vertex").ok_or("no `vertex` element")?;
    let scalar = |name: &str| -> Result<bool, String> {
        match vertex.properties.get(name).map(|p| &p.data_type) {
            None => Ok(false),
            Some(PropertyType::Scalar(_)) => Ok(true),
            Some(PropertyType::List(..)) => Err(format!("the `vertex` property `{name}` is a list, not a number")),
        }
    };
    for name in ["x", "y", "z"] {
        if !scalar(name)? {
            return Err(format!("the `vertex` element has no `{name}` property (positions need `x`, `y` and `z`)"));
        }
    }
    let normals = scalar("nx")? && scalar("ny")? && scalar("nz")?;
    let mut uv = None;
    for (k, [u, v]) in UV_NAMES.iter().enumerate() {
        if scalar(u)? && scalar(v)? && uv.is_none() {
            uv = Some(k);
        }
    }
    let face = header.elements.get("face").ok_or("no faces: the file has no `face` element")?;
    let (slot, indices) = INDEX_NAMES
        .iter()
        .enumerate()
        .find_map(|(slot, &n)| face.properties.get(n).map(|p| (slot, p)))
        .ok_or("the `face` element has no `vertex_indices` (or `vertex_index`) property")?;
    match &indices.data_type {
        PropertyType::List(_, t) if is_integer(t) => Ok((VertexLayout { normals, uv }, slot)),
        other => Err(format!("the `face` property `{}` must be a list of integers, not {other:?}", indices.name)),
    }
}

/// Whether a PLY scalar type is an integer.
fn is_integer(t: &ply_rs_bw::ply::ScalarType) -> bool {
    use ply_rs_bw::ply::ScalarType as S;
    matches!(t, S::Char | S::UChar | S::Short | S::UShort | S::Int | S::UInt)
}

/// The rows of the element `def`, read from `body` in `encoding` (and kept when `keep`); a failure gives the
/// row's index and what is wrong.
fn read_rows<E: PropertyAccess>(
    body: &mut Cursor<&[u8]>,
    encoding: Encoding,
    def: &ElementDef,
    keep: bool,
) -> Result<Vec<E>, (usize, String)> {
    let parser = Parser::<E>::new();
    // A header's count reserves no more than this up front: it may promise more rows than the file holds.
    let mut rows = Vec::with_capacity(if keep { def.count.min(1 << 16) } else { 0 });
    if encoding != Encoding::Ascii && def.properties.is_empty() {
        // A binary row of no properties takes no bytes: there is nothing to read, however many the header says.
        return Ok(rows);
    }
    let name = &def.name;
    let mut text = Vec::new();
    for i in 0..def.count {
        let row = match encoding {
            Encoding::Ascii => {
                text.clear();
                let read = body.read_until(b'\n', &mut text).map_err(|e| (i, e.to_string()))?;
                if read == 0 {
                    return Err((i, format!("the file ends before `{name}` {i} of {}", def.count)));
                }
                let line = std::str::from_utf8(&text).map_err(|_| (i, format!("`{name}` {i}: not ASCII text")))?;
                parser
                    .read_ascii_element(line, def)
                    .map_err(|e| (i, format!("`{name}` {i}: `{}`: {}", excerpt(line.trim_end()), crate_message(&e))))?
            }
            Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
                let read = if encoding == Encoding::BinaryLittleEndian {
                    parser.read_little_endian_element(body, def)
                } else {
                    parser.read_big_endian_element(body, def)
                };
                read.map_err(|e| match e.kind() {
                    ErrorKind::UnexpectedEof => {
                        (i, format!("the file ends inside `{name}` {i} of {} (a truncated binary body)", def.count))
                    }
                    _ => (i, format!("`{name}` {i}: {}", crate_message(&e))),
                })?
            }
        };
        if keep {
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The positions, normals and texture coordinates of the `vertex` rows, each checked to be finite; a failure
/// gives the row's index and what is wrong.
fn vertices(rows: &[VertexRow], layout: VertexLayout) -> Result<PlyMesh, (usize, String)> {
    let mut out = PlyMesh { positions: Vec::with_capacity(rows.len()), ..PlyMesh::default() };
    let mut normals = Vec::with_capacity(if layout.normals { rows.len() } else { 0 });
    let mut uvs = Vec::with_capacity(if layout.uv.is_some() { rows.len() } else { 0 });
    for (i, VertexRow(s)) in rows.iter().enumerate() {
        let finite = |slots: std::ops::Range<usize>, what: &str| {
            let values = &s[slots];
            if values.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err((i, format!("`vertex` {i}: its {what} {values:?} is not finite (as f32)")))
            }
        };
        finite(0..3, "position")?;
        out.positions.push(Vec3::new(s[0], s[1], s[2]));
        if layout.normals {
            finite(3..6, "normal")?;
            normals.push(Vec3::new(s[3], s[4], s[5]));
        }
        if let Some(k) = layout.uv {
            let at = 6 + 2 * k;
            finite(at..at + 2, "texture coordinate")?;
            uvs.push([s[at], s[at + 1]]);
        }
    }
    out.normals = layout.normals.then_some(normals);
    out.uvs = layout.uv.map(|_| uvs);
    Ok(out)
}

/// The mesh of a checked PLY in the world, shaded as `normals` says: every polygon ear-clipped, the winding kept
/// outside under a mirroring transform; the file's normals and texture coordinates shared by the corners of a
/// vertex, or smooth normals computed three per face, as for OBJ.
fn assemble(ply: &PlyMesh, file: &Path, world_from_object: &Affine3A, normals: Normals) -> MeshData {
    let world: Vec<Vec3> = ply.positions.iter().map(|&p| world_from_object.transform_point3(p)).collect();
    let order = winding(world_from_object);
    // Each triangle as three vertex indices.
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(ply.indices.len().saturating_sub(2 * ply.arities.len()));
    let mut start = 0usize;
    for (f, &arity) in ply.arities.iter().enumerate() {
        let corners = &ply.indices[start..start + arity as usize];
        start += arity as usize;
        let polygon: Vec<Vec3> = corners.iter().map(|&v| ply.positions[v as usize]).collect();
        let clipped = triangulate(&polygon);
        warn_if_not_plain(&clipped, corners.len(), || format!("{}: face {f}", file.display()));
        tris.extend(clipped.triangles.iter().map(|t| order.map(|k| corners[t[k]])));
    }
    let triangles: Vec<[Vec3; 3]> = tris.iter().map(|t| t.map(|v| world[v as usize])).collect();
    let mut sh = MeshShading::default();
    match (normals, &ply.normals) {
        (Normals::Flat, _) => {}
        (Normals::Smooth { .. }, Some(file_normals)) => {
            sh.normals.extend(world_normals(file_normals.iter().copied(), world_from_object));
            sh.normal_indices.clone_from(&tris);
        }
        (Normals::Smooth { crease_angle }, None) => {
            push_crease_normals(&mut sh, &triangles, &tris, world.len(), crease_angle);
        }
    }
    if let Some(uvs) = &ply.uvs {
        sh.uvs.clone_from(uvs);
        sh.uv_indices.clone_from(&tris);
    }
    MeshData { triangles, shading: sh }
}

/// A header error's message: what the parser says (its first line, without the line number it adds), with the
/// offending header line `text` quoted when known, or for a `format` line, the three formats it may name.
fn header_message(e: &ParseError, text: Option<String>) -> String {
    let said = crate_message(e);
    match text {
        Some(t) if t.starts_with("format") => format!(
            "unknown format `{}`: expected `format ascii 1.0`, `format binary_little_endian 1.0` or \
             `format binary_big_endian 1.0`",
            excerpt(&t)
        ),
        Some(t) if e.line() == Some(1) => format!("not a PLY file: it starts with `{}`, not `ply`", excerpt(&t)),
        Some(t) => format!("header line `{}`: {said}", excerpt(&t)),
        None => format!("header: {said}"),
    }
}

/// The parser's message on one line: without its `Line N: ` prefix and the input it quotes (photon quotes the
/// line itself, cut to an excerpt), its other detail lines joined by `; `.
fn crate_message(e: &ParseError) -> String {
    let text = e.to_string();
    let text = match e.line() {
        Some(l) => text.strip_prefix(&format!("Line {l}: ")).unwrap_or(&text).to_owned(),
        None => text,
    };
    let parts: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with("String:")).collect();
    excerpt(&parts.join("; "))
}

/// Line `n` (1-based) of `bytes`, without its line break, read lossily.
fn nth_line(bytes: &[u8], n: usize) -> Option<String> {
    let line = bytes.split(|&b| b == b'\n').nth(n.checked_sub(1)?)?;
    Some(String::from_utf8_lossy(line).trim_end().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<MeshData, MeshError> {
        parse_ply(text.as_bytes(), Path::new("t.ply"), &Affine3A::IDENTITY, Normals::default())
    }

    const QUAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                        property float z\nproperty float s\nproperty float t\nelement face 1\n\
                        property list uchar int vertex_indices\nend_header\n\
                        0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";

    #[test]
    fn a_quad_is_two_triangles_with_its_uvs_and_computed_normals() {
        let m = parse(QUAD).unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.shading.uvs, vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        assert_eq!(m.shading.uv_indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.shading.normal_indices.len(), 2);
        for n in &m.shading.normals {
            assert_eq!(*n, [0.0, 0.0, 1.0]);
        }
    }

    #[test]
    fn integer_and_double_properties_are_read() {
        let text = QUAD
            .replace("property float x", "property uchar x")
            .replace("property float y", "property short y")
            .replace("property float z", "property double z")
            .replace("uchar int vertex_indices", "uint16 uint32 vertex_index");
        let m = parse(&text).unwrap();
        assert_eq!(m.triangles[0], [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]);
    }

    #[test]
    fn bounds_are_those_of_the_placed_vertices() {
        let xf = Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0));
        let b = ply_bounds(QUAD.as_bytes(), Path::new("t.ply"), &xf).unwrap();
        assert_eq!((b.min, b.max), (Vec3::new(0.0, 0.0, 5.0), Vec3::new(1.0, 1.0, 5.0)));
    }

    #[test]
    fn ascii_errors_name_their_line() {
        // The header has 11 lines: the vertices are lines 12 to 15, the face line 16.
        let e = parse(&QUAD.replace("4 0 1 2 3", "4 0 1 2 7")).unwrap_err().to_string();
        assert!(e.starts_with("t.ply:16: malformed PLY: `face` 0: vertex index 7 is out of range (0 to 3)"), "{e}");
        let e = parse(&QUAD.replace("1 1 0 1 1", "1 x 0 1 1")).unwrap_err().to_string();
        assert!(e.starts_with("t.ply:14: malformed PLY: `vertex` 2: `1 x 0 1 1`"), "{e}");
    }
}
