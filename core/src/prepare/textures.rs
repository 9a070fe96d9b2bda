//! The images a scene's materials read: each distinct file decoded once into a [`TexelImage`], given a slot in
//! the prepared scene's texture list, and shipped to workers as its own content-addressed blob (so that a
//! second render with another image on one object ships only that image; the scene blob holds slots, not
//! texels).
//!
//! Slots follow the materials in name order and, within a material, its colours in declaration order, then
//! its bump or normal map, then the environment's image; a file read twice (the same path) has one slot. The
//! order depends only on the scene text, so a scene blob from the cache and freshly decoded images always agree.
//! The images of glTF objects ([`super::gltf`]) follow, object by object, in the order their materials read
//! them, after the scene's own materials and then each glTF object's materials.

use crate::material::Material;
use crate::material::texture::{TexelImage, decode_file};
use crate::scene::{LightSpec, Scene, SceneError};
use std::path::{Path, PathBuf};

/// The distinct image files of `scene`'s materials and environment in slot order, each with the field that
/// first names it (`materials.wood.albedo`, `lights[2]`) for error messages.
pub fn files(scene: &Scene) -> Vec<(PathBuf, String)> {
    let mut out: Vec<(PathBuf, String)> = Vec::new();
    let mut add = |path: PathBuf, field: String| {
        if !out.iter().any(|(p, _)| *p == path) {
            out.push((path, field));
        }
    };
    for (name, m) in &scene.materials {
        for (field, r) in m.images() {
            add(scene.base_dir.join(&r.file), format!("materials.{name}.{field}"));
        }
    }
    if let Some((i, file)) = environment_image(scene) {
        add(scene.base_dir.join(file), format!("lights[{i}]"));
    }
    out
}

/// The environment's image file as the scene names it, with the environment's index among the lights.
pub fn environment_image(scene: &Scene) -> Option<(usize, &Path)> {
    scene.lights.iter().enumerate().find_map(|(i, l)| match l {
        LightSpec::Environment { image: Some(file), .. } => Some((i, file.as_path())),
        _ => None,
    })
}

/// The texture slot of the environment's image among `files` ([`files`]), or [`crate::geometry::NONE`].
pub fn environment_slot(scene: &Scene, files: &[(PathBuf, String)]) -> u32 {
    environment_image(scene)
        .and_then(|(_, file)| files.iter().position(|(p, _)| *p == scene.base_dir.join(file)))
        .map_or(crate::geometry::NONE, |i| i as u32)
}

/// The materials of `scene` in name order with every image's slot set, the decoded images by slot, and the
/// environment image's slot ([`crate::geometry::NONE`] without one).
///
/// # Errors
/// [`SceneError::Texture`] naming the scene, the material's field and the file: the file cannot be read or
/// decoded, is empty, has a side of 0 or over [`crate::material::texture::MAX_TEXTURE_SIDE`], or decodes to
/// more than `limits.texture_mib`; float texels that are negative or not finite.
pub fn load(scene: &Scene, scene_path: &Path) -> Result<(Vec<Material>, Vec<TexelImage>, u32), SceneError> {
    load_with(scene, scene_path, &mut super::gltf::import_all(scene, scene_path)?)
}

/// [`load`] with the scene's glTF objects already imported: their materials follow the scene's, their image
/// slots moved past the images before them, and their images (taken out of `imported`) follow the scene's.
///
/// # Errors
/// As [`load`].
pub fn load_with(
    scene: &Scene,
    scene_path: &Path,
    imported: &mut [Option<super::gltf::Imported>],
) -> Result<(Vec<Material>, Vec<TexelImage>, u32), SceneError> {
    let (mut materials, mut images, env_slot) = load_scene_images(scene, scene_path)?;
    for imp in imported.iter_mut().flatten() {
        let offset = images.len() as u32;
        for m in &imp.materials {
            let mut m = m.clone();
            for (_, r) in m.images_mut() {
                r.slot = r.slot.saturating_add(offset);
            }
            materials.push(m);
        }
        for mesh in &mut imp.meshes {
            if let Some(e) = &mut mesh.emission_image {
                e.slot = e.slot.saturating_add(offset);
            }
        }
        images.append(&mut imp.images);
    }
    Ok((materials, images, env_slot))
}

/// The scene's own materials (name order) with their slots set, their images and the environment's, and the
/// environment image's slot.
fn load_scene_images(scene: &Scene, scene_path: &Path) -> Result<(Vec<Material>, Vec<TexelImage>, u32), SceneError> {
    let files = files(scene);
    let limit = scene.limits.texture_mib.saturating_mul(1 << 20);
    let mut images = Vec::with_capacity(files.len());
    for (path, field) in &files {
        let img = decode_file(path, limit).map_err(|source| SceneError::Texture {
            path: scene_path.into(),
            field: format!("{field}.image"),
            file: path.clone(),
            source,
        })?;
        images.push(img);
    }
    let mut materials: Vec<Material> = scene.materials.values().cloned().collect();
    for (m, name) in materials.iter_mut().zip(scene.materials.keys()) {
        for (field, r) in m.images_mut() {
            let path = scene.base_dir.join(&r.file);
            // `files` listed every path, so the position exists.
            r.slot = files.iter().position(|(p, _)| *p == path).map_or(crate::geometry::NONE, |i| i as u32);
            let is_colour = field != "bump" && field != "normal_map";
            if let Some((over, max)) = images.get(r.slot as usize).and_then(TexelImage::above_one)
                && is_colour
            {
                tracing::warn!(
                    "{}: materials.{name}.{field}: {} has {over} texel values above 1 (largest {max}); a \
                     reflectance reads them as 1",
                    scene_path.display(),
                    path.display()
                );
            }
        }
    }
    let env_slot = environment_slot(scene, &files);
    Ok((materials, images, env_slot))
}
