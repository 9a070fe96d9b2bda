//! What importing a glTF makes ([`Imported`]), its error ([`ImportError`]), and the state of one import that
//! the readers of buffers, materials and nodes share.

use crate::Rgb;
use crate::geometry::mask::AlphaMask;
use crate::geometry::mesh::{MeshData, MeshError};
use crate::light::EmissionImage;
use crate::material::texture::TextureError;
use crate::material::{Material, TexelImage};
use crate::scene::{LightSpec, SceneError};
use glam::Affine3A;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// One primitive of one mesh node, in world space.
#[derive(Clone, Debug, Default)]
pub struct ImportedMesh {
    /// Triangles and their normals and UVs (flipped to photon's `v`-up: `v' = 1 − v`).
    pub mesh: MeshData,
    /// Index into [`Imported::materials`].
    pub material: u32,
    /// Emitted radiance of each triangle (`emissiveFactor × KHR_materials_emissive_strength`), times
    /// `emission_image` at each point when there is one; empty when the material emits nothing.
    pub emission: Vec<Rgb>,
    /// The material's `emissiveTexture` (its slot indexes [`Imported::images`]), read at each point of the
    /// surface by the area lights.
    pub emission_image: Option<EmissionImage>,
    /// Whether the emission leaves both sides (the material's `doubleSided`).
    pub two_sided_emission: bool,
}

/// A perspective camera found in the file: its node's world transform and its projection.
#[derive(Clone, Copy, Debug)]
pub struct ImportedCamera {
    /// `world_from_camera`: the camera looks down its −z axis with +y up.
    pub world_from_camera: Affine3A,
    /// Vertical field of view in radians.
    pub yfov: f32,
    /// Width over height, when the file gives it.
    pub aspect: Option<f32>,
}

/// Everything a glTF object adds to a prepared scene.
#[derive(Clone, Debug, Default)]
pub struct Imported {
    /// The primitives, in node order (depth first from the scene's roots) and primitive order.
    pub meshes: Vec<ImportedMesh>,
    /// The materials, by the file's material index, then glTF's default material (the last one).
    pub materials: Vec<Material>,
    /// The decoded images; the materials' image slots index this list.
    pub images: Vec<TexelImage>,
    /// The cut-outs (`alphaMode` MASK with a textured alpha); the meshes' `shading.mask` indexes this list.
    pub masks: Vec<AlphaMask>,
    /// The `KHR_lights_punctual` lights, in world space.
    pub lights: Vec<LightSpec>,
    /// The first perspective camera in node order.
    pub camera: Option<ImportedCamera>,
    /// What the file uses that is not supported, each named once.
    pub warnings: Vec<String>,
}

/// Why a glTF object cannot be imported.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file or a buffer cannot be read, or the file is not a valid glTF.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// An image cannot be decoded.
    #[error("{file}: {field}: {source}")]
    Texture {
        /// The image: its file, or the glTF with `#images[i]`.
        file: PathBuf,
        /// The glTF field, `images[i]`.
        field: String,
        /// The cause.
        source: TextureError,
    },
}

impl ImportError {
    /// The error as a scene error of object `i` of the scene at `scene_path`.
    pub fn in_scene(self, scene_path: &Path, i: usize) -> SceneError {
        match self {
            ImportError::Mesh(source) => {
                SceneError::Mesh { path: scene_path.into(), field: format!("objects[{i}].file"), source }
            }
            ImportError::Texture { file, field, source } => SceneError::Texture {
                path: scene_path.into(),
                field: format!("objects[{i}].file: {field}"),
                file,
                source,
            },
        }
    }
}

/// What the importer is working on: the file, its document and its buffers, and the warnings so far.
pub(crate) struct Import<'a> {
    pub(super) file: &'a Path,
    pub(super) doc: &'a gltf::Document,
    pub(super) buffers: Vec<Vec<u8>>,
    pub(super) warned: BTreeSet<String>,
    /// The emissive texture of each material, by material index (the default material last); filled by
    /// `materials::load`.
    pub(super) material_emission: Vec<Option<EmissionImage>>,
    /// The index into [`Imported::masks`] of each material's cut-out, by material index (the default material
    /// last); filled by `materials::load`.
    pub(super) material_masks: Vec<Option<u32>>,
}

impl Import<'_> {
    /// Notes something unsupported; each text is kept once.
    pub(super) fn warn(&mut self, what: impl Into<String>) {
        self.warned.insert(what.into());
    }
}

/// A [`MeshError::MalformedGltf`] for `file`.
pub(crate) fn malformed(file: &Path, message: impl Into<String>) -> MeshError {
    MeshError::MalformedGltf { file: file.into(), message: message.into() }
}
