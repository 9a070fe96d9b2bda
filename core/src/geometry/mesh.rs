//! Wavefront OBJ meshes, read with `tobj`, and what every mesh format loads to ([`MeshData`], [`MeshError`],
//! [`Normals`]); PLY files are read by [`crate::geometry::ply`], and [`crate::geometry::mesh_file`] picks the reader
//! by the file's extension.
//!
//! ```toml
//! [[objects]]
//! type = "mesh"
//! file = "meshes/bunny.obj"          # relative to the scene file
//! material = "gold"
//! transform = { translate = [0.0, 0.0, 0.0], rotate = [0.0, 45.0, 0.0], scale = 0.5 }
//! ```
//! Polygons are triangulated by ear clipping in their plane, so concave faces keep their shape; a polygon whose
//! vertices leave its plane is warned about with its file and line. A `#` starts a comment on any line. Normals
//! and UVs are kept when the file has them, and smooth (area-weighted) vertex normals are computed when it does
//! not. The OBJ's own materials are ignored (`mtllib` and `usemtl` lines are skipped, the `.mtl` is never
//! read). Bytes that are not UTF-8 (a Latin-1 comment or group name) are read as U+FFFD. Only a regular file is
//! read, of at most `[limits] mesh_mib`. Every parse error names its line and quotes at most
//! [`crate::input::EXCERPT_CHARS`] characters of it.

use crate::geometry::MeshShading;
use crate::input::excerpt;
use crate::math::fmath;
use glam::{Affine3A, Vec3, Vec3A};
use std::path::{Path, PathBuf};

/// Why a mesh could not be loaded; names the file and, where known, the line.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be opened or read, is not a regular file, or is too large.
    #[error("{file}: cannot read the mesh: {source}")]
    Io {
        /// The mesh file.
        file: PathBuf,
        /// The cause.
        source: crate::input::InputError,
    },
    /// The file is not a valid OBJ.
    #[error("{file}{}: malformed OBJ: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Malformed {
        /// The mesh file.
        file: PathBuf,
        /// The first offending line (1-based), where it could be found.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// The file is not a valid PLY, or not a mesh (no faces, no positions).
    #[error("{file}{}: malformed PLY: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    MalformedPly {
        /// The mesh file.
        file: PathBuf,
        /// The offending line (1-based) of the header or of an ASCII body; `None` in a binary body, where the
        /// message names the element instead.
        line: Option<usize>,
        /// What is wrong, and where in the body: the element and its index (from 0, as faces count vertices).
        message: String,
    },
    /// The file is not a valid glTF 2.0 file, or its data are not what its accessors promise.
    #[error("{file}: malformed glTF: {message}")]
    MalformedGltf {
        /// The glTF file.
        file: PathBuf,
        /// What is wrong, naming the glTF field (`meshes[0].primitives[1].indices`) where there is one.
        message: String,
    },
    /// The file name ends in neither `.obj` nor `.ply`, so its format is not known.
    #[error("{file}: unknown mesh format: the file name must end in `.obj` (Wavefront OBJ) or `.ply` (PLY)")]
    UnknownFormat {
        /// The mesh file.
        file: PathBuf,
    },
}

/// A loaded mesh in world space.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    /// Triangles as world-space vertex triples.
    pub triangles: Vec<[Vec3; 3]>,
    /// Shading data (normals, UVs) per face corner.
    pub shading: MeshShading,
}

/// How a mesh's shading normals are made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Normals {
    /// The file's normals when it has them; otherwise smooth normals, averaged (area-weighted) only over the
    /// faces around a vertex whose normals are within `crease_angle` degrees of the face's own, so that a
    /// sharp edge stays sharp.
    Smooth {
        /// Largest angle between two faces' normals, in degrees, across which shading is smoothed.
        crease_angle: f32,
    },
    /// No shading normals: every face shades with its geometric normal, even when the file has normals.
    Flat,
}

impl Normals {
    /// The default crease angle, in degrees.
    pub const DEFAULT_CREASE_ANGLE: f32 = 30.0;
}

impl Default for Normals {
    fn default() -> Self {
        Normals::Smooth { crease_angle: Self::DEFAULT_CREASE_ANGLE }
    }
}

/// Loads an OBJ file of at most `limit` bytes and places it in the world with `world_from_object`.
pub fn load_obj(
    file: &Path,
    world_from_object: &Affine3A,
    normals: Normals,
    limit: u64,
) -> Result<MeshData, MeshError> {
    parse_obj_bytes(&read_mesh(file, limit)?, file, world_from_object, normals)
}

/// The bytes of the mesh file `file`: a regular file of at most `limit` bytes (`[limits] mesh_mib`).
pub(crate) fn read_mesh(file: &Path, limit: u64) -> Result<Vec<u8>, MeshError> {
    crate::input::read_regular(file, limit, "limits.mesh_mib in the scene")
        .map_err(|source| MeshError::Io { file: file.into(), source })
}

/// Parses the bytes of an OBJ file; `file` names it in errors and warnings.
pub(crate) fn parse_obj_bytes(
    bytes: &[u8],
    file: &Path,
    world_from_object: &Affine3A,
    normals: Normals,
) -> Result<MeshData, MeshError> {
    // Lossy: a byte that is not UTF-8 sits in a comment or a name, both unused; in a number it fails that
    // line's check below, with its line.
    parse_obj(&String::from_utf8_lossy(bytes), file, world_from_object, normals)
}

/// Parses OBJ text; `file` names it in errors and warnings.
pub fn parse_obj(
    text: &str,
    file: &Path,
    world_from_object: &Affine3A,
    normals: Normals,
) -> Result<MeshData, MeshError> {
    let malformed = |line: Option<usize>, message: String| MeshError::Malformed { file: file.into(), line, message };
    // A `#` starts a comment on any line (tobj accepts one only where a statement ignores extra words). Stripping
    // keeps every line in its place, so line numbers stay those of the file.
    let text = strip_comments(text);
    let text = text.as_str();
    // tobj names no line in its errors: find the first bad statement ourselves, before tobj sees it.
    if let Some((line, message)) = first_bad_line(text) {
        return Err(malformed(Some(line), message));
    }
    // Polygons are kept whole (tobj's triangulation is a fan, right only for convex faces) and ear-clipped below.
    let options =
        tobj::LoadOptions { triangulate: false, single_index: false, ignore_points: true, ignore_lines: true };
    let mut reader = std::io::BufReader::new(text.as_bytes());
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| malformed(None, e.to_string()))?;
    if models.iter().all(|m| m.mesh.indices.is_empty()) {
        return Err(malformed(None, "no faces".into()));
    }
    // The line of each face, in file order (tobj's models and their faces keep that order).
    let face_lines: Vec<usize> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| l.split_whitespace().next() == Some("f"))
        .map(|(i, _)| i + 1)
        .collect();
    let mut face_number = 0usize;
    let mut out = MeshData::default();
    let sh = &mut out.shading;
    for model in &models {
        let m = &model.mesh;
        let base_pos = out.triangles.len();
        let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(malformed(nth_line_starting(text, "v", i), format!("vertex {} is not finite", i + 1)));
        }
        let world: Vec<Vec3> = positions.iter().map(|&p| world_from_object.transform_point3(p)).collect();
        // Each triangle as three positions in `m.indices` (which also index the normal and UV indices).
        let tris = model_triangles(m, &positions, file, &face_lines, &mut face_number)?;
        let order = winding(world_from_object);
        let tris: Vec<[usize; 3]> = tris.iter().map(|t| order.map(|k| t[k])).collect();
        for t in &tris {
            out.triangles.push(t.map(|c| world[m.indices[c] as usize]));
        }
        // Normals: none when flat, else the file's, else smooth within the crease angle.
        let normal_base = sh.normals.len() as u32;
        match normals {
            Normals::Flat => {}
            Normals::Smooth { .. } if !m.normals.is_empty() && m.normal_indices.len() == m.indices.len() => {
                let file_normals = m.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2]));
                sh.normals.extend(world_normals(file_normals, world_from_object));
                for t in &tris {
                    sh.normal_indices.push(t.map(|c| normal_base + m.normal_indices[c]));
                }
            }
            Normals::Smooth { crease_angle } => {
                let corner_positions: Vec<[u32; 3]> = tris.iter().map(|t| t.map(|c| m.indices[c])).collect();
                push_crease_normals(sh, &out.triangles[base_pos..], &corner_positions, world.len(), crease_angle);
            }
        }
        if !m.texcoords.is_empty() && m.texcoord_indices.len() == m.indices.len() {
            let uv_base = sh.uvs.len() as u32;
            sh.uvs.extend(m.texcoords.chunks_exact(2).map(|t| [t[0], t[1]]));
            for t in &tris {
                sh.uv_indices.push(t.map(|c| uv_base + m.texcoord_indices[c]));
            }
        }
    }
    if !sh.uv_indices.is_empty() && sh.uv_indices.len() != out.triangles.len() {
        // Some parts of the mesh have UVs and others do not: give the others zeros so indices stay aligned.
        let missing = out.triangles.len() - sh.uv_indices.len();
        let zero = sh.uvs.len() as u32;
        sh.uvs.push([0.0, 0.0]);
        sh.uv_indices.splice(0..0, std::iter::repeat_n([zero; 3], missing));
    }
    Ok(out)
}

/// The triangles of one tobj model's faces, each as three corners of `m.indices` (which also index the normal
/// and UV indices), every polygon ear-clipped in its mean plane. `face_lines` holds each face's line in the file;
/// `face_number` counts the faces of the models before this one and moves past this one's. Warns, naming the
/// line, of non-planar and non-simple polygons.
fn model_triangles(
    m: &tobj::Mesh,
    positions: &[Vec3],
    file: &Path,
    face_lines: &[usize],
    face_number: &mut usize,
) -> Result<Vec<[usize; 3]>, MeshError> {
    let malformed = |line: Option<usize>, message: String| MeshError::Malformed { file: file.into(), line, message };
    let mut tris: Vec<[usize; 3]> = Vec::new();
    let arities: Vec<usize> = if m.face_arities.is_empty() {
        vec![3; m.indices.len() / 3]
    } else {
        m.face_arities.iter().map(|&a| a as usize).collect()
    };
    let mut start = 0usize;
    for arity in arities {
        let line = face_lines.get(*face_number).copied();
        *face_number += 1;
        let corners = start..start + arity;
        start += arity;
        let mut polygon = Vec::with_capacity(arity);
        for c in corners.clone() {
            let ix = m.indices.get(c).copied().unwrap_or(u32::MAX) as usize;
            let p = positions.get(ix).ok_or_else(|| malformed(line, "face index out of bounds".into()))?;
            polygon.push(*p);
        }
        let clipped = triangulate(&polygon);
        warn_if_not_plain(&clipped, arity, || format!("{}:{}", file.display(), line.unwrap_or(0)));
        tris.extend(clipped.triangles.iter().map(|t| t.map(|k| corners.start + k)));
    }
    Ok(tris)
}

/// Warns, naming the polygon with `place` (`file:line`, or `file: face N`), when its triangulation `clipped` had to
/// flatten a non-planar polygon of `arity` vertices or fan a polygon that is not simple.
pub(crate) fn warn_if_not_plain(clipped: &Triangulation, arity: usize, place: impl Fn() -> String) {
    if clipped.non_planarity > NON_PLANAR_TOLERANCE {
        tracing::warn!(
            "{}: non-planar polygon of {arity} vertices (a vertex is {:.1e} of the polygon's size off its plane): \
             its triangles follow the ear clipping in its mean plane",
            place(),
            clipped.non_planarity
        );
    }
    if !clipped.simple {
        tracing::warn!(
            "{}: polygon of {arity} vertices is not simple (it self-intersects or is degenerate): part of it is \
             triangulated as a fan",
            place()
        );
    }
}

/// The corner order that keeps a face's outside outside under `world_from_object`: a mirroring transform
/// (negative determinant) reverses the winding, and swapping two corners restores it (the winding decides the
/// computed normals, and which way emission faces).
pub(crate) fn winding(world_from_object: &Affine3A) -> [usize; 3] {
    if world_from_object.matrix3.determinant() < 0.0 { [0, 2, 1] } else { [0, 1, 2] }
}

/// A file's object-space normals as world-space unit normals (by the inverse transpose of the transform; a zero
/// normal stays zero).
pub(crate) fn world_normals(
    normals: impl Iterator<Item = Vec3>,
    world_from_object: &Affine3A,
) -> impl Iterator<Item = [f32; 3]> {
    let normal_from_object = world_from_object.matrix3.inverse().transpose();
    normals.map(move |n| (normal_from_object * Vec3A::from(n)).normalize_or_zero().to_array())
}

/// Appends to `sh` the smooth normals of [`crease_normals`], three per face of `faces` (one per corner), with
/// their indices.
pub(crate) fn push_crease_normals(
    sh: &mut MeshShading,
    faces: &[[Vec3; 3]],
    corners: &[[u32; 3]],
    positions: usize,
    crease_angle: f32,
) {
    let base = sh.normals.len() as u32;
    for (f, corner_normals) in crease_normals(faces, corners, positions, crease_angle).iter().enumerate() {
        sh.normals.extend(corner_normals.iter().map(|n| n.to_array()));
        let first = base + 3 * f as u32;
        sh.normal_indices.push([first, first + 1, first + 2]);
    }
}

/// Smooth normals at the corners of `faces` (world space; `corners` gives each corner's position index, of
/// `positions` in all): at each corner, the area-weighted sum of the normals of the faces around that position
/// that lie within `crease_angle` degrees of this face (the face itself always counts). Across a sharper edge
/// each side keeps its own normal: averaging across a cube's 90° edges tilts the shading normal 35° off the
/// geometric one, and refraction with it loses energy (issue 16's black glass cube).
fn crease_normals(faces: &[[Vec3; 3]], corners: &[[u32; 3]], positions: usize, crease_angle: f32) -> Vec<[Vec3A; 3]> {
    // Twice the area times the unit normal, and the unit normal (zero for a face without area).
    let weighted: Vec<Vec3A> =
        faces.iter().map(|t| fmath::cross(Vec3A::from(t[1] - t[0]), Vec3A::from(t[2] - t[0]))).collect();
    let unit: Vec<Vec3A> =
        weighted.iter().map(|&n| if n.length_squared() > 0.0 { fmath::normalize(n) } else { Vec3A::ZERO }).collect();
    let cos_crease = fmath::cos(crease_angle.to_radians());
    // The faces around each position, in face order (so the sums below add in a fixed order).
    let mut start = vec![0u32; positions + 1];
    for c in corners.iter().flatten() {
        start[*c as usize + 1] += 1;
    }
    for i in 0..positions {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut around = vec![0u32; corners.len() * 3];
    for (f, t) in corners.iter().enumerate() {
        for &c in t {
            around[fill[c as usize] as usize] = f as u32;
            fill[c as usize] += 1;
        }
    }
    corners
        .iter()
        .enumerate()
        .map(|(f, t)| {
            t.map(|c| {
                let faces_here = &around[start[c as usize] as usize..start[c as usize + 1] as usize];
                let sum = faces_here
                    .iter()
                    .map(|&g| g as usize)
                    .filter(|&g| g == f || unit[g].dot(unit[f]) >= cos_crease)
                    .fold(Vec3A::ZERO, |acc, g| acc + weighted[g]);
                if sum.length_squared() > 0.0 { fmath::normalize(sum) } else { unit[f] }
            })
        })
        .collect()
}

/// The text with everything from a `#` to the end of its line removed, and the material statements (`mtllib`,
/// `usemtl`: OBJ materials are not used) blanked; the lines stay where they were.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let code = line.split('#').next().unwrap_or("");
        if !matches!(code.split_whitespace().next(), Some("mtllib" | "usemtl")) {
            out.push_str(code);
        }
        out.push('\n');
    }
    out
}

/// Largest distance of a polygon's vertex from its mean plane, as a fraction of its size, below which it counts
/// as planar (f32 positions written with six or seven digits stay well below it).
const NON_PLANAR_TOLERANCE: f64 = 1e-3;

/// The triangles of one polygon.
#[derive(Debug, PartialEq)]
pub(crate) struct Triangulation {
    /// Corner triples, as indices into the polygon, each with the polygon's winding.
    pub triangles: Vec<[usize; 3]>,
    /// Largest distance of a vertex from the mean plane, over the polygon's size (its bounding-box diagonal).
    pub non_planarity: f64,
    /// False when ear clipping ran out of ears (a self-intersecting or degenerate polygon), and the rest was
    /// triangulated as a fan.
    pub simple: bool,
}

/// Triangulates a polygon by ear clipping (Meisters 1975; Eberly, "Triangulation by ear clipping") in its
/// plane: the plane of Newell's normal, projected along its dominant axis. Works in f64, so it decides the
/// same on every platform and rounds less. A triangle is emitted as it stands; a vertex that is collinear with
/// its neighbours is never an ear, so no zero-area triangle comes out of a simple polygon. A convex polygon
/// gives the fan from its first vertex.
pub(crate) fn triangulate(polygon: &[Vec3]) -> Triangulation {
    let n = polygon.len();
    let p: Vec<[f64; 3]> = polygon.iter().map(|v| [f64::from(v.x), f64::from(v.y), f64::from(v.z)]).collect();
    // Newell's normal: twice the vector area, robust for concave and slightly non-planar polygons.
    let mut normal = [0.0f64; 3];
    for i in 0..n {
        let (a, b) = (p[i], p[(i + 1) % n]);
        normal[0] += (a[1] - b[1]) * (a[2] + b[2]);
        normal[1] += (a[2] - b[2]) * (a[0] + b[0]);
        normal[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    let non_planarity = non_planarity(&p, normal);
    if n == 3 {
        return Triangulation { triangles: vec![[0, 1, 2]], non_planarity, simple: true };
    }
    // Project along the dominant axis, keeping the other two in cyclic order: the polygon then winds
    // counter-clockwise in 2D exactly when the normal's dominant component is positive.
    let axis = if normal[0].abs() > normal[1].abs() && normal[0].abs() > normal[2].abs() {
        0
    } else if normal[1].abs() > normal[2].abs() {
        1
    } else {
        2
    };
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let sign = if normal[axis] < 0.0 { -1.0 } else { 1.0 };
    let q: Vec<[f64; 2]> = p.iter().map(|c| [c[u], c[v]]).collect();
    // Twice the signed area of (a, b, c), positive when it turns the polygon's way.
    let turn = |a: usize, b: usize, c: usize| {
        let (a, b, c) = (q[a], q[b], q[c]);
        sign * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    };
    let mut left: Vec<usize> = (0..n).collect();
    let mut triangles = Vec::with_capacity(n - 2);
    let mut simple = true;
    while left.len() > 3 {
        let k = left.len();
        // Starting at the second vertex makes a convex polygon come out as the fan from its first vertex, the
        // triangulation tobj (and so earlier versions of this loader) gave it.
        let ear = (1..k).chain(0..1).find(|&i| {
            let (a, b, c) = (left[(i + k - 1) % k], left[i], left[(i + 1) % k]);
            // Convex corner, and no other remaining vertex inside or on the triangle (a vertex at one of its
            // corners, a duplicate, does not block it).
            turn(a, b, c) > 0.0
                && left.iter().all(|&r| {
                    r == a
                        || r == b
                        || r == c
                        || q[r] == q[a]
                        || q[r] == q[b]
                        || q[r] == q[c]
                        || !(turn(a, b, r) >= 0.0 && turn(b, c, r) >= 0.0 && turn(c, a, r) >= 0.0)
                })
        });
        let Some(i) = ear else {
            // No ear: the polygon is not simple. Fan the rest, which at least covers it.
            simple = false;
            for j in 1..k - 1 {
                triangles.push([left[0], left[j], left[j + 1]]);
            }
            return Triangulation { triangles, non_planarity, simple };
        };
        triangles.push([left[(i + k - 1) % k], left[i], left[(i + 1) % k]]);
        left.remove(i);
    }
    triangles.push([left[0], left[1], left[2]]);
    Triangulation { triangles, non_planarity, simple }
}

/// Largest distance of a point from the plane through the centroid with normal `normal`, over the diagonal of
/// the points' bounding box; 0 for a degenerate polygon (no normal or no extent).
fn non_planarity(p: &[[f64; 3]], normal: [f64; 3]) -> f64 {
    let len = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
    let count = p.len() as f64;
    let centroid = [0, 1, 2].map(|k| p.iter().map(|c| c[k]).sum::<f64>() / count);
    let lo = [0, 1, 2].map(|k| p.iter().map(|c| c[k]).fold(f64::INFINITY, f64::min));
    let hi = [0, 1, 2].map(|k| p.iter().map(|c| c[k]).fold(f64::NEG_INFINITY, f64::max));
    let size = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    if len == 0.0 || size == 0.0 || !len.is_finite() || !size.is_finite() {
        return 0.0;
    }
    let off = p
        .iter()
        .map(|c| {
            ((c[0] - centroid[0]) * normal[0] + (c[1] - centroid[1]) * normal[1] + (c[2] - centroid[2]) * normal[2])
                .abs()
        })
        .fold(0.0, f64::max);
    off / len / size
}

/// The line of the `n`-th (0-based) statement that starts with `prefix`.
fn nth_line_starting(text: &str, tag: &str, n: usize) -> Option<usize> {
    text.lines().enumerate().filter(|(_, l)| l.split_whitespace().next() == Some(tag)).nth(n).map(|(i, _)| i + 1)
}

/// The first line that tobj would reject (1-based), and what is wrong with it, by checking each statement's
/// shape: `v`/`vn` need three numbers (`v` may add a weight or a colour), `vt` one to three, `f` at least three
/// references within the counts seen so far. `text` has no comments left.
fn first_bad_line(text: &str) -> Option<(usize, String)> {
    let (mut nv, mut nt, mut nn) = (0i64, 0i64, 0i64);
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let numbers = |min: usize, max: usize, what: &str| {
            if rest.len() < min || rest.len() > max || rest.iter().any(|w| w.parse::<f32>().is_err()) {
                let count = if min == max { format!("{min}") } else { format!("{min} to {max}") };
                Some(format!("`{tag}` needs {count} numbers ({what}), found `{}`", excerpt(&rest.join(" "))))
            } else {
                // `nan` and `inf` parse as numbers: name them here, where the line is known.
                let not_finite = rest.iter().find(|w| !w.parse::<f32>().is_ok_and(f32::is_finite));
                not_finite.map(|w| format!("`{tag}`: `{}` is not finite", excerpt(w)))
            }
        };
        let error = match tag {
            "v" => {
                nv += 1;
                numbers(3, 7, "a position, then an optional weight or colour")
            }
            "vt" => {
                nt += 1;
                numbers(1, 3, "a texture coordinate")
            }
            "vn" => {
                nn += 1;
                numbers(3, 3, "a normal")
            }
            "f" => {
                if rest.len() < 3 {
                    Some(format!("a face needs at least three vertices, found {}", rest.len()))
                } else {
                    rest.iter().find_map(|w| face_vertex_error(w, [nv, nt, nn]))
                }
            }
            _ => None,
        };
        if let Some(message) = error {
            return Some((i + 1, message));
        }
    }
    None
}

/// What is wrong with one `f` reference `v`, `v/vt`, `v//vn` or `v/vt/vn`, given how many positions, texture
/// coordinates and normals precede it; `None` if it is fine.
fn face_vertex_error(word: &str, counts: [i64; 3]) -> Option<String> {
    const KINDS: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    let parts: Vec<&str> = word.split('/').collect();
    let shown = excerpt(word);
    if parts.len() > 3 {
        return Some(format!("face vertex `{shown}` has more than three parts"));
    }
    for (k, part) in parts.iter().enumerate() {
        if part.is_empty() {
            if k == 0 {
                return Some(format!("face vertex `{shown}` has no position index"));
            }
            continue;
        }
        match part.parse::<i64>() {
            Ok(ix) if ix != 0 && ix.abs() <= counts[k] => {}
            Ok(ix) => {
                let (kind, count) = (KINDS[k], counts[k]);
                return Some(format!(
                    "face vertex `{shown}`: {kind} index {ix} is out of bounds (1 to {count}, or -1 to -{count})"
                ));
            }
            Err(_) => return Some(format!("face vertex `{shown}`: `{}` is not an index", excerpt(part))),
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";

    #[test]
    fn quad_is_triangulated_with_smooth_normals_and_uvs() {
        let m = parse_obj(QUAD, Path::new("quad.obj"), &Affine3A::IDENTITY, Normals::default()).unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.shading.uv_indices.len(), 2);
        for n in &m.shading.normals {
            assert!((Vec3::from(*n) - Vec3::Z).length() < 1e-6);
        }
    }

    #[test]
    fn transform_moves_vertices_and_normals() {
        let xf = Affine3A::from_scale_rotation_translation(
            Vec3::splat(2.0),
            glam::Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
            Vec3::new(0.0, 1.0, 0.0),
        );
        let m = parse_obj(QUAD, Path::new("quad.obj"), &xf, Normals::default()).unwrap();
        let t = m.triangles[0];
        assert!((t[1] - Vec3::new(2.0, 1.0, 0.0)).length() < 1e-5);
        // +z rotated by −90° about x becomes +y.
        assert!((Vec3::from(m.shading.normals[0]) - Vec3::Y).length() < 1e-5);
    }

    #[test]
    fn mirroring_keeps_the_outside_outside() {
        // The quad faces +z; mirrored in z it must face −z, with the computed normals agreeing.
        let xf = Affine3A::from_scale(Vec3::new(1.0, 1.0, -1.0));
        let m = parse_obj(QUAD, Path::new("quad.obj"), &xf, Normals::default()).unwrap();
        let t = m.triangles[0];
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        assert!((n - Vec3::NEG_Z).length() < 1e-6, "{n}");
        for sn in &m.shading.normals {
            assert!((Vec3::from(*sn) - Vec3::NEG_Z).length() < 1e-6);
        }
    }

    #[test]
    fn malformed_obj_names_the_line() {
        let bad = "v 0 0 0\nv 1 0 0\nv 1 x 0\nf 1 2 3\n";
        let e = parse_obj(bad, Path::new("bad.obj"), &Affine3A::IDENTITY, Normals::default()).unwrap_err().to_string();
        assert!(e.contains("bad.obj:3"), "{e}");
        let oob = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n";
        let e = parse_obj(oob, Path::new("oob.obj"), &Affine3A::IDENTITY, Normals::default()).unwrap_err().to_string();
        assert!(e.contains("oob.obj:4"), "{e}");
    }

    fn parse(text: &str) -> Result<MeshData, MeshError> {
        parse_obj(text, Path::new("t.obj"), &Affine3A::IDENTITY, Normals::default())
    }

    fn area(t: &[Vec3; 3]) -> f64 {
        f64::from((t[1] - t[0]).cross(t[2] - t[0]).length()) / 2.0
    }

    #[test]
    fn comments_are_stripped_from_every_kind_of_line() {
        let plain = "mtllib a.mtl\no quad\ng side\ns 1\nusemtl m\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                     vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\nl 1 2\np 1\n";
        let commented: String = plain.lines().map(|l| format!("{l} # note: 1 2 x / #\n")).collect();
        let commented = format!("# header\n{commented}#\n");
        let (a, b) = (parse(plain).unwrap(), parse(&commented).unwrap());
        assert_eq!(a.triangles, b.triangles);
        assert_eq!(a.shading.normals, b.shading.normals);
        assert_eq!(a.shading.uvs, b.shading.uvs);
        assert_eq!(b.triangles.len(), 2);
        // A comment with no space before it.
        let tight = "v 0 0 0#a\nv 1 0 0#b\nv 0 1 0#c\nf 1 2 3#d\n";
        assert_eq!(parse(tight).unwrap().triangles.len(), 1);
    }

    #[test]
    fn every_parse_error_names_its_line() {
        let good: String = (0..13).map(|i| format!("v {i} 0 0\nv {i} 1 0\nv {i} 0 1 # vertex\n")).collect();
        assert_eq!(good.lines().count(), 39);
        for bad in [
            "v 1 2",
            "v 1 x 3",
            "v 1 nan 3",
            "vn inf 0 1",
            "vn 0 1",
            "vt",
            "f 1 2",
            "f 1 2 x",
            "f 1 2 99",
            "f 1 2 0",
            "f 1/1 2 3",
            "f 1//5 2 3",
            "f 1/2/3/4 2 3",
        ] {
            let text = format!("{good}{bad} # a comment\nf 1 2 3\n");
            let e = parse(&text).unwrap_err();
            assert!(matches!(e, MeshError::Malformed { line: Some(40), .. }), "`{bad}`: {e}");
            assert!(e.to_string().starts_with("t.obj:40: "), "`{bad}`: {e}");
        }
    }

    /// The L shape of the issue: (1,0) (1,1) (0,1) (0,2) (−1,2) (−1,0), area 3, concave at (0,1).
    const L_SHAPE: [[f32; 2]; 6] = [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 2.0], [-1.0, 2.0], [-1.0, 0.0]];

    fn check_covers(polygon: &[Vec3], area_expected: f64) {
        let t = triangulate(polygon);
        assert!(t.simple);
        assert_eq!(t.triangles.len(), polygon.len() - 2);
        let tris: Vec<[Vec3; 3]> = t.triangles.iter().map(|c| c.map(|k| polygon[k])).collect();
        let total: f64 = tris.iter().map(area).sum();
        assert!((total - area_expected).abs() < 1e-6, "{total} vs {area_expected}");
        // Every triangle winds as the polygon does (so none folds over another), hence they tile it.
        let n = polygon_normal(polygon);
        for tri in &tris {
            assert!((tri[1] - tri[0]).cross(tri[2] - tri[0]).dot(n) > 0.0, "{tri:?}");
        }
    }

    fn polygon_normal(polygon: &[Vec3]) -> Vec3 {
        (0..polygon.len()).map(|i| polygon[i].cross(polygon[(i + 1) % polygon.len()])).sum()
    }

    #[test]
    fn concave_polygons_are_ear_clipped() {
        let l: Vec<Vec3> = L_SHAPE.iter().map(|p| Vec3::new(p[0], p[1], 0.0)).collect();
        check_covers(&l, 3.0);
        // No triangle reaches into the notch x ∈ (0, 1), y ∈ (1, 2).
        for t in triangulate(&l).triangles {
            let c = t.iter().map(|&k| l[k]).sum::<Vec3>() / 3.0;
            assert!(!(c.x > 0.0 && c.y > 1.0), "{c}");
        }
        // Reversed winding, other planes, and every starting vertex.
        for start in 0..6 {
            let mut r = l.clone();
            r.rotate_left(start);
            check_covers(&r, 3.0);
            r.reverse();
            check_covers(&r, 3.0);
            let yz: Vec<Vec3> = r.iter().map(|p| Vec3::new(5.0, p.x, p.y)).collect();
            check_covers(&yz, 3.0);
        }
        let star = star(5, 1.0, 0.4);
        // Ten triangles (centre, outer k, inner k) of area ½·1·0.4·sin 36° each.
        let expected = 10.0 * 0.5 * 0.4 * (36f64.to_radians()).sin();
        check_covers(&star, expected);
    }

    /// A star with `points` points of outer radius `r_out` and inner radius `r_in`, in z = 0.
    fn star(points: usize, r_out: f32, r_in: f32) -> Vec<Vec3> {
        (0..2 * points)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / points as f64;
                let r = if i % 2 == 0 { r_out } else { r_in };
                Vec3::new(r * a.cos() as f32, r * a.sin() as f32, 0.0)
            })
            .collect()
    }

    #[test]
    fn convex_polygons_keep_the_fan() {
        let hexagon: Vec<Vec3> = star(3, 1.0, 1.0);
        assert_eq!(triangulate(&hexagon).triangles, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]);
    }

    #[test]
    fn non_planar_polygons_are_measured() {
        let flat = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        assert!(triangulate(&flat).non_planarity < 1e-9);
        let bent = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.5), Vec3::Y];
        assert!(triangulate(&bent).non_planarity > NON_PLANAR_TOLERANCE);
    }

    /// A unit cube without normals, six quads facing out.
    const CUBE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
                        f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

    fn shading_normals(text: &str, normals: Normals) -> Vec<(Vec3, [Vec3; 3])> {
        let m = parse_obj(text, Path::new("t.obj"), &Affine3A::IDENTITY, normals).unwrap();
        let sh = &m.shading;
        m.triangles
            .iter()
            .zip(&sh.normal_indices)
            .map(|(t, ix)| {
                ((t[1] - t[0]).cross(t[2] - t[0]).normalize(), ix.map(|i| Vec3::from(sh.normals[i as usize])))
            })
            .collect()
    }

    #[test]
    fn crease_angle_keeps_sharp_edges_sharp() {
        // 90° edges: every corner's normal is its face's normal.
        for (n, corners) in shading_normals(CUBE, Normals::default()) {
            for c in corners {
                assert!((c - n).length() < 1e-6, "{c} vs {n}");
            }
        }
        // Smoothed across every edge (area-weighted over the triangles at the corner), a corner leans off its face.
        for (n, corners) in shading_normals(CUBE, Normals::Smooth { crease_angle: 180.0 }) {
            for c in corners {
                assert!(c.dot(n) > 0.4 && c.dot(n) < 0.9, "{c} vs {n}");
            }
        }
        // Flat: no shading normals at all.
        let m = parse_obj(CUBE, Path::new("t.obj"), &Affine3A::IDENTITY, Normals::Flat).unwrap();
        assert!(m.shading.normal_indices.is_empty());
    }

    #[test]
    fn crease_angle_smooths_shallow_edges() {
        // Two faces folded by 20° along x = 0: within 30° their shared corners share the mean normal.
        let a = 10f32.to_radians();
        let text = format!(
            "v 0 0 0\nv 0 1 0\nv 1 0 {z}\nv 1 1 {z}\nv -1 0 {z}\nv -1 1 {z}\nf 1 3 4 2\nf 5 1 2 6\n",
            z = fmath::tan(a)
        );
        let normals = shading_normals(&text, Normals::default());
        let mut at_edge = Vec::new();
        for (n, corners) in &normals {
            for c in corners {
                let angle = fmath::acos(c.dot(*n).clamp(-1.0, 1.0)).to_degrees();
                // The outer corners keep the face normal; those on the fold lean towards the other face.
                assert!(angle < 0.1 || (angle > 1.0 && angle < 19.0), "{angle}");
                if angle > 1.0 {
                    at_edge.push(*c);
                }
            }
        }
        // Each fold vertex has one normal, on its three corners in both faces: shading is continuous across it.
        assert_eq!(at_edge.len(), 6);
        for c in &at_edge {
            assert_eq!(at_edge.iter().filter(|d| (**d - *c).length() < 1e-6).count(), 3, "{at_edge:?}");
        }
        // Smooth shading does not cross a 20° fold with a 10° crease angle.
        for (n, corners) in shading_normals(&text, Normals::Smooth { crease_angle: 10.0 }) {
            for c in corners {
                assert!((c - n).length() < 1e-6);
            }
        }
    }
}
