//! glTF 2.0 import through the `gltf` crate: a `.gltf` (with its buffers and images beside it or in `data:`
//! URIs) or a `.glb`, placed in a scene like a mesh, with its own materials.
//!
//! ```toml
//! [[objects]]
//! type = "gltf"
//! file = "gltf/showcase.glb"         # relative to the scene file
//! transform = { translate = [0.0, 0.0, 0.0], rotate = [0.0, 30.0, 0.0], scale = 1.0 }
//! ```
//!
//! Preparing the scene expands the object into triangle meshes (module `nodes`), one per primitive of every mesh
//! node of the file's default scene, placed by the node hierarchy (matrix or TRS, parent → child) and then by
//! the object's `transform`; its materials become [`crate::material::Material::MetallicRoughness`] or, with
//! `KHR_materials_transmission`, [`crate::material::Material::Dielectric`] (module `materials`); its images are decoded by the
//! texture loader into the prepared scene's texture list, so they travel as content-addressed blobs like any
//! texture; its `KHR_lights_punctual` lights join the scene's lights. `photon-coordinator render model.glb`
//! renders a file directly through a scene made for it ([`direct`]).
//!
//! What the file uses and photon does not support is named once per file in a warning (and kept in
//! [`Imported::warnings`]); nothing is dropped silently. A malformed file is a [`MeshError::MalformedGltf`]
//! naming the file and what was expected. docs/SCENE.md lists every feature.

mod buffers;
pub mod direct;
mod materials;
mod nodes;
mod types;

pub use types::{ImportError, Imported, ImportedCamera, ImportedMesh};

use crate::geometry::mesh::MeshError;
use crate::scene::{Object, Scene, SceneError};
use glam::Affine3A;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use types::{Import, malformed};

/// The extensions this importer reads; any other in `extensionsUsed` is warned about.
pub const SUPPORTED_EXTENSIONS: [&str; 4] =
    ["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_materials_ior", "KHR_materials_transmission"];

/// Reads and parses a glTF or GLB file of at most `limit` bytes (buffers and images each within it too).
fn read(file: &Path, limit: u64) -> Result<gltf::Gltf, MeshError> {
    let bytes = crate::geometry::mesh::read_mesh(file, limit)?;
    // gltf-json 1.4's validator indexes the accessors of a primitive's attributes before checking the index
    // (it panics in `mesh.rs`): those are checked first, and any other panic of the validator is a malformed
    // file too, not a crash.
    if let Ok(unchecked) = gltf::Gltf::from_slice_without_validation(&bytes)
        && let Some(why) = dangling_accessor(unchecked.document.as_json())
    {
        return Err(malformed(file, format!("invalid glTF: {why}")));
    }
    let parsed = std::panic::catch_unwind(|| gltf::Gltf::from_slice(&bytes)).map_err(|panic| {
        let why = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("a panic");
        malformed(file, format!("invalid glTF: an index is out of range ({why}, in the gltf crate's validator)"))
    })?;
    parsed.map_err(|e| malformed(file, describe(&e)))
}

/// The first primitive attribute or index list that names an accessor past the accessor list.
fn dangling_accessor(root: &gltf::json::Root) -> Option<String> {
    let n = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let at = format!("meshes[{m}].primitives[{p}]");
            let attributes = prim.attributes.iter().map(|(s, a)| {
                let name = match s {
                    gltf::json::validation::Checked::Valid(s) => s.to_string(),
                    gltf::json::validation::Checked::Invalid => "(unknown)".to_string(),
                };
                (format!("attributes.{name}"), a.value())
            });
            for (field, a) in attributes.chain(prim.indices.iter().map(|i| ("indices".to_string(), i.value()))) {
                if a >= n {
                    return Some(format!("{at}.{field}: accessors[{a}] does not exist (the file has {n})"));
                }
            }
        }
    }
    None
}

/// The `gltf` crate's error in words that say what was expected.
fn describe(e: &gltf::Error) -> String {
    match e {
        gltf::Error::Validation(v) => {
            let list: Vec<String> = v.iter().take(5).map(|(path, err)| format!("{path}: {err}")).collect();
            format!("invalid glTF: {}", list.join("; "))
        }
        gltf::Error::Binary(b) => format!("not a valid GLB (binary glTF): {b:?}"),
        gltf::Error::Deserialize(d) => format!("not valid glTF JSON: {d}"),
        other => other.to_string(),
    }
}

/// Imports `file` placed by `world_from_object`, reading at most `limit` bytes of each file and decoding at most
/// `texture_limit` bytes of each image. The warnings are logged once each and returned in
/// [`Imported::warnings`].
///
/// # Errors
/// [`ImportError`]: a file cannot be read, the document is not valid glTF 2.0, a buffer is shorter than it says,
/// an accessor is of the wrong type or reaches past its data, an index is out of range, an image cannot be
/// decoded.
pub fn import(
    file: &Path,
    world_from_object: &Affine3A,
    limit: u64,
    texture_limit: u64,
) -> Result<Imported, ImportError> {
    let out = import_unlogged(file, world_from_object, limit, texture_limit)?;
    for w in &out.warnings {
        tracing::warn!("{}: {w}", file.display());
    }
    Ok(out)
}

/// [`import`] without logging the warnings (a direct render reads the file once to make its scene, then
/// prepares that scene, which logs them).
pub(crate) fn import_unlogged(
    file: &Path,
    world_from_object: &Affine3A,
    limit: u64,
    texture_limit: u64,
) -> Result<Imported, ImportError> {
    let gltf = read(file, limit)?;
    let buffers = buffers::load(&gltf, file, limit)?;
    let mut im = Import {
        file,
        doc: &gltf.document,
        buffers,
        warned: BTreeSet::new(),
        material_emission: Vec::new(),
        material_masks: Vec::new(),
    };
    unsupported_document_features(&mut im);
    let mut out = materials::load(&mut im, texture_limit)?;
    nodes::walk(&mut im, world_from_object, &mut out)?;
    out.warnings = im.warned.into_iter().collect();
    Ok(out)
}

/// The features of the whole document that are not supported: extensions outside [`SUPPORTED_EXTENSIONS`],
/// skins, animations, and scenes other than the default one.
fn unsupported_document_features(im: &mut Import<'_>) {
    for ext in im.doc.extensions_used() {
        if !SUPPORTED_EXTENSIONS.contains(&ext) {
            im.warn(format!("extension {ext} is not supported: it is ignored"));
        }
    }
    let skins = im.doc.skins().len();
    if skins > 0 {
        im.warn(format!(
            "skins are not supported: {skins} skin(s) ignored, meshes are posed as their nodes place them"
        ));
    }
    let animations = im.doc.animations().len();
    if animations > 0 {
        im.warn(format!(
            "animations are not supported: {animations} animation(s) ignored, the file's rest pose is rendered"
        ));
    }
    let scenes = im.doc.scenes().len();
    if scenes > 1 {
        im.warn(format!("the file has {scenes} scenes: only the default one is rendered"));
    }
}

/// The glTF file of each glTF object of `scene`, its external buffers and images, in object order: what a
/// cache key of the prepared scene must hash. A file that cannot be read or parsed is listed alone (the
/// loader reports it).
pub fn files(scene: &Scene) -> Vec<PathBuf> {
    let limit = scene.limits.mesh_mib.saturating_mul(1 << 20);
    let mut out = Vec::new();
    for o in &scene.objects {
        let Object::Gltf { file, .. } = o else { continue };
        let path = scene.base_dir.join(file);
        let external = read(&path, limit).map(|g| buffers::external_files(&g.document, &path)).unwrap_or_default();
        out.push(path);
        out.extend(external);
    }
    out
}

/// Whether `path` names a glTF file (`.gltf` or `.glb`, in any case).
pub fn is_gltf(path: &Path) -> bool {
    matches!(path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).as_deref(), Some("gltf" | "glb"))
}

/// Imports every glTF object of `scene`, by object index (`None` for other objects).
///
/// # Errors
/// The first object's [`ImportError`], as a [`SceneError`] naming `objects[i].file`.
pub fn import_all(scene: &Scene, scene_path: &Path) -> Result<Vec<Option<Imported>>, SceneError> {
    let limit = scene.limits.mesh_mib.saturating_mul(1 << 20);
    let texture_limit = scene.limits.texture_mib.saturating_mul(1 << 20);
    scene
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| match o {
            Object::Gltf { file, transform } => {
                import(&scene.base_dir.join(file), &transform.matrix(), limit, texture_limit)
                    .map(Some)
                    .map_err(|e| e.in_scene(scene_path, i))
            }
            _ => Ok(None),
        })
        .collect()
}
