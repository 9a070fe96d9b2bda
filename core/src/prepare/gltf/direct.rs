//! A glTF file rendered directly (`photon-coordinator render model.glb -o out.png`): the scene made for it is
//! one `gltf` object, the file's first perspective camera (or a framing of its bounds), and default render
//! settings. `--set` and the shorthand flags apply to that scene as to a scene file.
//!
//! Without a camera the view looks at the centre of the bounding box from the front (`+z`, glTF's front) and a
//! little above, far enough for the bounding sphere to fit a 40° field of view. A file with neither lights nor
//! emissive materials is lit by a point light at the eye whose irradiance at the centre is 1 W/m² (a warning
//! says so), so that the render is not black.

use super::{ImportError, Imported, import, is_gltf};
use crate::scene::{Scene, SceneError};
use glam::Vec3;
use std::path::Path;

/// The image height of a direct render; the width follows the camera's aspect ratio (square without one).
pub const HEIGHT: u32 = 512;

/// Loads a scene file with overrides, or, for a `.gltf`/`.glb`, the scene [`scene_text`] makes for it.
///
/// # Errors
/// As [`Scene::load_with`]; a glTF that cannot be imported names the file and what was expected.
pub fn load_scene(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
    if !is_gltf(path) {
        return Scene::load_with(path, overrides);
    }
    let text = scene_text(path)?;
    Scene::parse_with(&text, path, overrides)
}

/// The scene text (TOML) that renders the glTF at `path` directly.
///
/// # Errors
/// The file cannot be imported (as `objects[0].file` of the made scene).
pub fn scene_text(path: &Path) -> Result<String, SceneError> {
    let limits = crate::scene::Limits::default();
    let imported = import(path, &glam::Affine3A::IDENTITY, limits.mesh_mib << 20, limits.texture_mib << 20)
        .map_err(|e: ImportError| e.in_scene(path, 0))?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let (mut text, eye, distance) = camera(&imported);
    text.push_str(&format!("\n[[objects]]\ntype = \"gltf\"\nfile = {}\n", toml::Value::String(name)));
    let emits = imported.meshes.iter().any(|m| !m.emission.is_empty());
    if imported.lights.is_empty() && !emits {
        tracing::warn!(
            "{}: the file has no lights and no emissive material: lit by a point light at the camera",
            path.display()
        );
        let i = distance * distance;
        text.push_str(&format!(
            "\n[[lights]]\ntype = \"point\"\nposition = {}\nintensity = {}\n",
            v3(eye),
            v3(Vec3::splat(i))
        ));
    }
    Ok(text)
}

/// The `[camera]` table, the eye, and the distance from the eye to the centre of the bounds.
fn camera(imported: &Imported) -> (String, Vec3, f32) {
    let (lo, hi) = bounds(imported);
    let centre = (lo + hi) * 0.5;
    if let Some(c) = imported.camera {
        let eye = Vec3::from(c.world_from_camera.translation);
        let forward = c.world_from_camera.transform_vector3(Vec3::NEG_Z).normalize_or(Vec3::NEG_Z);
        let up = c.world_from_camera.transform_vector3(Vec3::Y).normalize_or(Vec3::Y);
        let fov = c.yfov.to_degrees().clamp(1e-3, 179.0);
        let width = c
            .aspect
            .filter(|a| a.is_finite() && *a > 0.0)
            .map_or(HEIGHT, |a| ((HEIGHT as f32 * a).round() as u32).clamp(1, crate::scene::MAX_IMAGE_SIDE));
        let text = format!(
            "[camera]\neye = {}\nlook_at = {}\nup = {}\nfov = {fov:?}\nwidth = {width}\nheight = {HEIGHT}\n",
            v3(eye),
            v3(eye + forward),
            v3(up)
        );
        return (text, eye, (centre - eye).length().max(1e-3));
    }
    let radius = (0.5 * (hi - lo).length()).max(1e-3);
    let fov = 40.0f32;
    let distance = 1.1 * radius / crate::math::fmath::sin(0.5 * fov.to_radians());
    let eye = centre + Vec3::new(0.0, 0.35, 1.0).normalize() * distance;
    let text = format!(
        "[camera]\neye = {}\nlook_at = {}\nfov = {fov:?}\nwidth = {HEIGHT}\nheight = {HEIGHT}\n",
        v3(eye),
        v3(centre)
    );
    (text, eye, distance)
}

/// The bounding box of every triangle, or the unit cube around the origin for a file without any.
fn bounds(imported: &Imported) -> (Vec3, Vec3) {
    let points = imported.meshes.iter().flat_map(|m| m.mesh.triangles.iter().flatten());
    let (lo, hi) = points.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    if lo.is_finite() && hi.is_finite() { (lo, hi) } else { (Vec3::splat(-0.5), Vec3::splat(0.5)) }
}

/// `[x, y, z]` in TOML, every digit kept (`{:?}` of an `f32` reads back to the same bits).
fn v3(v: Vec3) -> String {
    format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z)
}
