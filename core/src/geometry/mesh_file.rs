//! Which reader a mesh file takes, by the extension of its name (in any case): `.obj` is a Wavefront OBJ
//! ([`crate::geometry::mesh`]), `.ply` a PLY ([`crate::geometry::ply`]); any other name is an error that says
//! which two it may end in. Every place that reads a mesh file comes through here.
//!
//! ```toml
//! [[objects]]
//! type = "mesh"
//! file = "meshes/torus.ply"          # or "meshes/torus.obj"
//! material = "white"
//! ```

use crate::geometry::mesh::{MeshData, MeshError, Normals, parse_obj_bytes, read_mesh};
use crate::geometry::{lod, ply};
use crate::math::Aabb;
use glam::Affine3A;
use std::path::Path;

/// A mesh file's format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// PLY, ASCII or binary (`.ply`).
    Ply,
}

impl MeshFormat {
    /// The format the extension of `file` names.
    ///
    /// # Errors
    /// [`MeshError::UnknownFormat`] when the name ends in neither `.obj` nor `.ply`.
    pub fn of(file: &Path) -> Result<MeshFormat, MeshError> {
        match file.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).as_deref() {
            Some("obj") => Ok(MeshFormat::Obj),
            Some("ply") => Ok(MeshFormat::Ply),
            _ => Err(MeshError::UnknownFormat { file: file.into() }),
        }
    }
}

/// Loads the mesh file `file` (at most `limit` bytes) in the format its name gives and places it in the world
/// with `world_from_object`. The file is read first, so a missing file, a folder or a device is reported as such
/// whatever its name.
///
/// # Errors
/// [`MeshError`]: the file cannot be read, its name gives no format, or it is not a valid mesh of its format.
pub fn load_mesh(
    file: &Path,
    world_from_object: &Affine3A,
    normals: Normals,
    limit: u64,
) -> Result<MeshData, MeshError> {
    let bytes = read_mesh(file, limit)?;
    match MeshFormat::of(file)? {
        MeshFormat::Obj => parse_obj_bytes(&bytes, file, world_from_object, normals),
        MeshFormat::Ply => ply::parse_ply(&bytes, file, world_from_object, normals),
    }
}

/// The world-space bounding box of the vertices of the mesh file `file` (at most `limit` bytes) placed with
/// `world_from_object`, for the level of detail. An OBJ's unreadable vertex lines are passed over
/// ([`lod::obj_bounds`]); a PLY must be valid as far as its vertices.
///
/// # Errors
/// [`MeshError`]: the file cannot be read, its name gives no format, or (a PLY) its header or vertices are not
/// valid.
pub fn mesh_bounds(file: &Path, world_from_object: &Affine3A, limit: u64) -> Result<Aabb, MeshError> {
    let bytes = read_mesh(file, limit)?;
    match MeshFormat::of(file)? {
        MeshFormat::Obj => Ok(lod::obj_bounds(&String::from_utf8_lossy(&bytes), world_from_object)),
        MeshFormat::Ply => ply::ply_bounds(&bytes, file, world_from_object),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_extension_names_the_format_in_any_case() {
        assert_eq!(MeshFormat::of(Path::new("a/b.obj")).unwrap(), MeshFormat::Obj);
        assert_eq!(MeshFormat::of(Path::new("B.OBJ")).unwrap(), MeshFormat::Obj);
        assert_eq!(MeshFormat::of(Path::new("x.Ply")).unwrap(), MeshFormat::Ply);
        for name in ["bunny.stl", "bunny", "bunny.obj.gz", ".ply"] {
            let e = MeshFormat::of(Path::new(name)).unwrap_err().to_string();
            assert!(e.starts_with(&format!("{name}: unknown mesh format")) && e.contains("`.obj`"), "{e}");
        }
    }
}
