//! Which meshes of a scene are simplified, and with which error bound ([`plan`]); the simplification itself is
//! [`crate::geometry::lod`].
//!
//! A mesh's `lod` (pixels, default 1) lets its surface move by up to `lod` × the smallest pixel footprint at
//! the nearest point of its bounding box to the camera ([`View::error_bound`]). A mesh keeps every triangle
//! when:
//! - its `lod` is 0;
//! - it emits light: its area is its light's power, and the light it throws on nearby surfaces is not bounded by
//!   the pixel footprint where the camera sees the mesh;
//! - any material of the scene has a mirror or glass component ([`Material::has_specular`]): a curved mirror or
//!   a lens can show the mesh magnified, where one pixel covers less than the camera's footprint;
//! - the camera is inside its bounding box or so near it that the bound is negligible
//!   ([`crate::geometry::lod::MIN_RELATIVE_BOUND`]);
//! - its file cannot be read (the loader then reports why).
//!
//! The plan depends on the camera, which the coordinator's prepared cache keeps out of its scene key: the cache
//! adds the bounds of the plan to the key, so that a mesh simplified for another view is never reused.

use crate::geometry::lod::View;
use crate::material::Material;
use crate::scene::{Object, Scene};

/// Why a mesh keeps every triangle.
#[derive(Clone, Debug, PartialEq)]
pub enum Full {
    /// Its `lod` is 0.
    Off,
    /// It emits light.
    Emitter,
    /// It holds an interior medium, whose boundary must stay closed.
    Interior,
    /// The scene has a mirror or glass material, named here.
    Specular(String),
    /// The camera is inside or very near its bounding box.
    NearCamera,
    /// Its file cannot be read (the loader reports it).
    Unreadable,
}

impl std::fmt::Display for Full {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Full::Off => f.write_str("lod = 0"),
            Full::Emitter => f.write_str("it emits light"),
            Full::Interior => f.write_str("it holds a medium, whose boundary must stay closed"),
            Full::Specular(m) => write!(
                f,
                "material `{}` is specular (mirror or glass), in which the mesh may be seen magnified",
                crate::input::excerpt(m)
            ),
            Full::NearCamera => f.write_str("the camera is inside or very near its bounding box"),
            Full::Unreadable => f.write_str("its file cannot be read"),
        }
    }
}

/// What level of detail does to one mesh.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshLod {
    /// Simplified until the next collapse would move the surface by more than `bound` (scene units).
    Simplify {
        /// The error bound in scene units, quantised ([`crate::geometry::lod::quantise_down`]).
        bound: f32,
    },
    /// Kept whole, for this reason.
    Full(Full),
}

/// The view the scene's camera gives level of detail (its eye, field of view and image size).
pub fn view(scene: &Scene) -> View {
    let c = &scene.camera;
    View::pinhole(c.eye, c.fov, c.width, c.height)
}

/// The level of detail of every object of a validated `scene`, in object order: `None` for an object that is
/// not a mesh. Reads each mesh file (at most `[limits] mesh_mib`) for the bounding box of its vertices after its
/// transform ([`crate::geometry::mesh_file::mesh_bounds`]); the same scene and files give the same plan.
pub fn plan(scene: &Scene) -> Vec<Option<MeshLod>> {
    let specular = scene.materials.iter().find(|(_, m)| Material::has_specular(m)).map(|(name, _)| name.clone());
    let view = view(scene);
    let limit = scene.limits.mesh_mib.saturating_mul(1 << 20);
    scene
        .objects
        .iter()
        .map(|o| {
            let Object::Mesh { file, transform, emission, lod, interior, .. } = o else { return None };
            let full = |why| Some(MeshLod::Full(why));
            if *lod <= 0.0 {
                return full(Full::Off);
            }
            if emission.is_some_and(|e| e.radiance.max_element() > 0.0) {
                return full(Full::Emitter);
            }
            if interior.is_some() {
                return full(Full::Interior);
            }
            if let Some(m) = &specular {
                return full(Full::Specular(m.clone()));
            }
            let path = scene.base_dir.join(file);
            let Ok(bounds) = crate::geometry::mesh_file::mesh_bounds(&path, &transform.matrix(), limit) else {
                return full(Full::Unreadable);
            };
            match view.error_bound(bounds, *lod) {
                Some(bound) => Some(MeshLod::Simplify { bound }),
                None => full(Full::NearCamera),
            }
        })
        .collect()
}
