//! Wavefront OBJ meshes, read with `tobj`.
//!
//! ```toml
//! [[objects]]
//! type = "mesh"
//! file = "meshes/bunny.obj"          # relative to the scene file
//! material = "gold"
//! transform = { translate = [0.0, 0.0, 0.0], rotate = [0.0, 45.0, 0.0], scale = 0.5 }
//! ```
//! Polygons are triangulated; normals and UVs are kept when the file has them, and smooth (area-weighted)
//! vertex normals are computed when it does not. The OBJ's own materials are ignored.

use crate::geometry::MeshShading;
use glam::{Affine3A, Vec3, Vec3A};
use std::path::{Path, PathBuf};

/// Why a mesh could not be loaded; names the file and, where known, the line.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be opened or read.
    #[error("{file}: cannot read the mesh: {source}")]
    Io {
        /// The mesh file.
        file: PathBuf,
        /// The cause.
        source: std::io::Error,
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
}

/// A loaded mesh in world space.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    /// Triangles as world-space vertex triples.
    pub triangles: Vec<[Vec3; 3]>,
    /// Shading data (normals, UVs) per face corner.
    pub shading: MeshShading,
}

/// Loads an OBJ file and places it in the world with `world_from_object`.
pub fn load_obj(file: &Path, world_from_object: &Affine3A) -> Result<MeshData, MeshError> {
    let text = std::fs::read_to_string(file).map_err(|source| MeshError::Io { file: file.into(), source })?;
    parse_obj(&text, file, world_from_object)
}

/// Parses OBJ text; `file` names it in errors.
pub fn parse_obj(text: &str, file: &Path, world_from_object: &Affine3A) -> Result<MeshData, MeshError> {
    let malformed = |line: Option<usize>, message: String| MeshError::Malformed { file: file.into(), line, message };
    let options = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    let mut reader = std::io::BufReader::new(text.as_bytes());
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| malformed(first_bad_line(text), e.to_string()))?;
    if models.iter().all(|m| m.mesh.indices.is_empty()) {
        return Err(malformed(None, "no faces".into()));
    }
    let normal_from_object = world_from_object.matrix3.inverse().transpose();
    let mut out = MeshData::default();
    let sh = &mut out.shading;
    for model in &models {
        let m = &model.mesh;
        let base_pos = out.triangles.len();
        let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(malformed(nth_line_starting(text, "v ", i), format!("vertex {} is not finite", i + 1)));
        }
        let world: Vec<Vec3> = positions.iter().map(|&p| world_from_object.transform_point3(p)).collect();
        let tri_count = m.indices.len() / 3;
        // A mirroring transform (negative determinant) reverses the winding; swapping two corners keeps the
        // outside outside (it decides the normals computed below, and which way emission faces).
        let corners: [usize; 3] = if world_from_object.matrix3.determinant() < 0.0 { [0, 2, 1] } else { [0, 1, 2] };
        for f in 0..tri_count {
            let ix = corners.map(|k| m.indices[3 * f + k]);
            let mut tri = [Vec3::ZERO; 3];
            for k in 0..3 {
                tri[k] = *world
                    .get(ix[k] as usize)
                    .ok_or_else(|| malformed(None, format!("face {} index out of range", f + 1)))?;
            }
            out.triangles.push(tri);
        }
        // Normals: the file's, else area-weighted smooth normals over shared positions.
        let normal_base = sh.normals.len() as u32;
        if !m.normals.is_empty() && m.normal_indices.len() == m.indices.len() {
            for n in m.normals.chunks_exact(3) {
                let wn = (normal_from_object * Vec3A::new(n[0], n[1], n[2])).normalize_or_zero();
                sh.normals.push(wn.to_array());
            }
            for f in 0..tri_count {
                sh.normal_indices.push(corners.map(|k| normal_base + m.normal_indices[3 * f + k]));
            }
        } else {
            let mut acc = vec![Vec3A::ZERO; world.len()];
            for f in 0..tri_count {
                let t = &out.triangles[base_pos + f];
                // The cross product's length is twice the area: area weighting for free.
                let n = Vec3A::from((t[1] - t[0]).cross(t[2] - t[0]));
                for k in 0..3 {
                    acc[m.indices[3 * f + k] as usize] += n;
                }
            }
            sh.normals.extend(acc.iter().map(|n| n.normalize_or_zero().to_array()));
            for f in 0..tri_count {
                sh.normal_indices.push(corners.map(|k| normal_base + m.indices[3 * f + k]));
            }
        }
        if !m.texcoords.is_empty() && m.texcoord_indices.len() == m.indices.len() {
            let uv_base = sh.uvs.len() as u32;
            sh.uvs.extend(m.texcoords.chunks_exact(2).map(|t| [t[0], t[1]]));
            for f in 0..tri_count {
                sh.uv_indices.push(corners.map(|k| uv_base + m.texcoord_indices[3 * f + k]));
            }
        }
    }
    if !sh.uv_indices.is_empty() && sh.uv_indices.len() != sh.normal_indices.len() {
        // Some parts of the mesh have UVs and others do not: give the others zeros so indices stay aligned.
        let missing = sh.normal_indices.len() - sh.uv_indices.len();
        let zero = sh.uvs.len() as u32;
        sh.uvs.push([0.0, 0.0]);
        sh.uv_indices.splice(0..0, std::iter::repeat_n([zero; 3], missing));
    }
    Ok(out)
}

/// The line of the `n`-th (0-based) statement that starts with `prefix`.
fn nth_line_starting(text: &str, prefix: &str, n: usize) -> Option<usize> {
    text.lines().enumerate().filter(|(_, l)| l.trim_start().starts_with(prefix)).nth(n).map(|(i, _)| i + 1)
}

/// Finds the first line that tobj would reject, by checking each statement's shape: `v`/`vn` need three
/// numbers, `vt` one to three, `f` at least three references within the counts seen so far.
fn first_bad_line(text: &str) -> Option<usize> {
    let (mut nv, mut nt, mut nn) = (0i64, 0i64, 0i64);
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let numbers_ok = |min: usize, max: usize| {
            rest.len() >= min && rest.len() <= max && rest.iter().all(|w| w.parse::<f32>().is_ok())
        };
        let ok = match tag {
            "v" => {
                nv += 1;
                numbers_ok(3, 7)
            }
            "vt" => {
                nt += 1;
                numbers_ok(1, 3)
            }
            "vn" => {
                nn += 1;
                numbers_ok(3, 3)
            }
            "f" => {
                rest.len() >= 3
                    && rest.iter().all(|w| {
                        let parts: Vec<&str> = w.split('/').collect();
                        let counts = [nv, nt, nn];
                        !parts.is_empty()
                            && parts.len() <= 3
                            && parts.iter().enumerate().all(|(k, p)| {
                                if p.is_empty() {
                                    return k > 0;
                                }
                                match p.parse::<i64>() {
                                    Ok(ix) => ix != 0 && ix.abs() <= counts[k],
                                    Err(_) => false,
                                }
                            })
                    })
            }
            _ => true,
        };
        if !ok {
            return Some(i + 1);
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
        let m = parse_obj(QUAD, Path::new("quad.obj"), &Affine3A::IDENTITY).unwrap();
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
        let m = parse_obj(QUAD, Path::new("quad.obj"), &xf).unwrap();
        let t = m.triangles[0];
        assert!((t[1] - Vec3::new(2.0, 1.0, 0.0)).length() < 1e-5);
        // +z rotated by −90° about x becomes +y.
        assert!((Vec3::from(m.shading.normals[0]) - Vec3::Y).length() < 1e-5);
    }

    #[test]
    fn mirroring_keeps_the_outside_outside() {
        // The quad faces +z; mirrored in z it must face −z, with the computed normals agreeing.
        let xf = Affine3A::from_scale(Vec3::new(1.0, 1.0, -1.0));
        let m = parse_obj(QUAD, Path::new("quad.obj"), &xf).unwrap();
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
        let e = parse_obj(bad, Path::new("bad.obj"), &Affine3A::IDENTITY).unwrap_err().to_string();
        assert!(e.contains("bad.obj:3"), "{e}");
        let oob = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n";
        let e = parse_obj(oob, Path::new("oob.obj"), &Affine3A::IDENTITY).unwrap_err().to_string();
        assert!(e.contains("oob.obj:4"), "{e}");
    }
}
