//! The prepared scene as blobs for the wire and the disk caches, all through [`crate::codec`]: the scene blob
//! (geometry, materials, lights, media: what stays the same from frame to frame), the photons blob, and
//! the small frame blob (camera and render settings) that travels with every strip request.

use super::Prepared;
use crate::camera::Camera;
use crate::codec::{self, CodecError};
use crate::error::FieldError;
use crate::geometry::shapes::{NO_MESH, Shape};
use crate::geometry::{Geometry, MeshShading, NONE};
use crate::light::{Light, LightSet};
use crate::material::{Material, TexelImage};
use crate::medium::Media;
use crate::scene::RenderSettings;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The scene blob, written from borrowed parts and read into owned ones (the same encoding).
#[derive(Serialize)]
struct SceneRef<'a> {
    geometry: &'a Geometry,
    materials: &'a [Material],
    lights: &'a LightSet,
    media: &'a Option<Media>,
}

#[derive(Deserialize)]
struct SceneOwned {
    geometry: Geometry,
    materials: Vec<Material>,
    lights: LightSet,
    media: Option<Media>,
}

impl SceneOwned {
    /// Decodes a scene blob of at most `limit` bytes and checks every index in it
    /// ([`SceneOwned::check_indices`]) and its media's coefficients.
    fn decode(scene: &[u8], limit: usize) -> Result<Self, FrameError> {
        let mut s: SceneOwned = codec::decode(scene, limit)?;
        s.check_indices()?;
        // Whether shadow rays look past `interface` surfaces follows from the materials, not from the blob.
        let interfaces = s.materials.iter().any(Material::is_interface);
        match &mut s.media {
            Some(m) => {
                m.check()?;
                m.interfaces = interfaces;
            }
            None if interfaces => {
                return Err(
                    FieldError::new("media", "the materials include an interface but the scene has no media").into()
                );
            }
            None => {}
        }
        Ok(s)
    }

    /// Checks every index the scene blob holds against the table it points into, once, so that rendering a
    /// scene that passed indexes nothing out of range (a prepared scene passes; a forged or corrupted blob with
    /// a correct hash may not):
    /// - meshes: each normal and UV index of each face corner below the mesh's normal and UV count, and its
    ///   `normal_indices` and `uv_indices` (each empty or one entry per face) of the same length;
    /// - primitives and planes: the material below the material count; the object below the media's boundary
    ///   count (objects index nothing else); a mesh triangle's mesh below the mesh count and its face below
    ///   that mesh's face count (when the mesh has per-face data);
    /// - lights: a primitive's light below the light count, and that light an area light on this primitive;
    ///   each area light's primitive below the primitive count, and that primitive carrying this light; the
    ///   light choice tables and the media's light list as long as the light list.
    ///
    /// Triangles carry their vertices, not indices; the BVH is not in the blob (decoding builds it); texture
    /// slots are checked against the texture blobs (`check_slots`).
    fn check_indices(&self) -> Result<(), FrameError> {
        let g = &self.geometry;
        g.meshes.iter().enumerate().try_for_each(|(m, mesh)| check_mesh(m, mesh, g.masks.len()))?;
        for (k, mask) in g.masks.iter().enumerate() {
            mask.check().map_err(|message| bad_table(format!("masks[{k}]"), message))?;
        }
        check_lights(&self.lights, g, self.media.as_ref())?;
        let objects = self.media.as_ref().map(|m| m.boundaries.len());
        check_surfaces(g, self.materials.len(), &self.lights.lights, objects)
    }
}

/// Each area light's primitive, carrying that light; the choice tables and the media's light list as long as
/// the light list.
fn check_lights(lights: &LightSet, g: &Geometry, media: Option<&Media>) -> Result<(), FrameError> {
    for (l, light) in lights.lights.iter().enumerate() {
        if let Light::Area { prim, .. } = *light {
            within(prim, g.prim_count(), || format!("lights[{l}].prim"), || "prims".into())?;
            let carried = g.prim(prim).map_or(NONE, |p| p.light);
            if carried as usize != l {
                return Err(bad_table(
                    format!("lights[{l}].prim"),
                    format!("is {prim}, but prims[{prim}].light is {carried}"),
                ));
            }
        }
    }
    let n = lights.lights.len();
    // The environment, if any, is the last light ([`LightSet::environment`]), and has a distribution exactly
    // when it has an image.
    let env = lights.lights.iter().position(|l| matches!(l, Light::Environment { .. }));
    if let Some(e) = env.filter(|&e| e + 1 != n) {
        return Err(bad_table(format!("lights[{e}]"), format!("is an environment, but only the last of {n} may be")));
    }
    let image = lights.environment().and_then(|(_, l)| match *l {
        Light::Environment { image, .. } if image != NONE => Some(image),
        _ => None,
    });
    if image.is_some() != lights.sky.is_some() {
        return Err(bad_table("lights.sky".into(), "is present exactly when the environment has an image".into()));
    }
    let (cdf, pmf) = lights.table_lens();
    let media_lights = media.map(|m| ("media.lights", m.lights.len()));
    for (table, len) in [("lights.cdf", cdf), ("lights.pmf", pmf)].into_iter().chain(media_lights) {
        if len != n {
            return Err(bad_table(table.into(), format!("has {len} entries, but there are {n} lights")));
        }
    }
    Ok(())
}

/// The primitives' and planes' materials, objects (when there are media: `objects` boundaries), lights (an area
/// light on the primitive) and mesh triangles' meshes and faces.
fn check_surfaces(g: &Geometry, materials: usize, lights: &[Light], objects: Option<usize>) -> Result<(), FrameError> {
    for (i, p) in g.prims().enumerate() {
        let field = |f: &str| format!("prims[{i}].{f}");
        within(p.material, materials, || field("material"), || "materials".into())?;
        if let Some(n) = objects {
            within(p.object, n, || field("object"), || "media.boundaries".into())?;
        }
        if p.light != NONE {
            within(p.light, lights.len(), || field("light"), || "lights".into())?;
            if !matches!(lights.get(p.light as usize), Some(Light::Area { prim, .. }) if *prim as usize == i) {
                return Err(bad_table(
                    field("light"),
                    format!("is {}, but lights[{}] is not an area light on prims[{i}]", p.light, p.light),
                ));
            }
        }
        if let Shape::Triangle(t) = p.shape
            && t.mesh != NO_MESH
        {
            within(t.mesh, g.meshes.len(), || field("shape.mesh"), || "meshes".into())?;
            if let Some(mesh) = g.meshes.get(t.mesh as usize) {
                let (faces, table) = face_table(mesh);
                if faces > 0 {
                    within(t.face, faces, || field("shape.face"), || format!("meshes[{}].{table}", t.mesh))?;
                }
            }
        }
    }
    for (i, p) in g.planes.iter().enumerate() {
        within(p.material, materials, || format!("planes[{i}].material"), || "materials".into())?;
        if let Some(n) = objects {
            within(p.object, n, || format!("planes[{i}].object"), || "media.boundaries".into())?;
        }
    }
    Ok(())
}

/// A mesh's face count as its per-face tables give it, and the table that gives it (0 when it has neither).
fn face_table(mesh: &MeshShading) -> (usize, &'static str) {
    if mesh.normal_indices.is_empty() {
        (mesh.uv_indices.len(), "uv_indices")
    } else {
        (mesh.normal_indices.len(), "normal_indices")
    }
}

/// Mesh `m`'s normal and UV indices against its normals and UVs, its two per-face tables against each other,
/// its tangents against its normals, and its mask against the `masks` cut-outs.
fn check_mesh(m: usize, mesh: &MeshShading, masks: usize) -> Result<(), FrameError> {
    let (n, uv) = (mesh.normal_indices.len(), mesh.uv_indices.len());
    if n != 0 && uv != 0 && n != uv {
        return Err(bad_table(
            format!("meshes[{m}].uv_indices"),
            format!("has {uv} faces, but meshes[{m}].normal_indices has {n}"),
        ));
    }
    let (t, normals) = (mesh.tangents.len(), mesh.normals.len());
    if t != 0 && t != normals {
        return Err(bad_table(
            format!("meshes[{m}].tangents"),
            format!("has {t} tangents, but meshes[{m}].normals has {normals}: one tangent a normal"),
        ));
    }
    if let Some(k) = mesh.mask {
        within(k, masks, || format!("meshes[{m}].mask"), || "masks".into())?;
    }
    for (ixs, name, len, table) in [
        (&mesh.normal_indices, "normal_indices", mesh.normals.len(), "normals"),
        (&mesh.uv_indices, "uv_indices", mesh.uvs.len(), "uvs"),
    ] {
        for (f, ix) in ixs.iter().enumerate() {
            for (k, &i) in ix.iter().enumerate() {
                within(i, len, || format!("meshes[{m}].{name}[{f}][{k}]"), || format!("meshes[{m}].{table}"))?;
            }
        }
    }
    Ok(())
}

/// `Ok` when `index` is below `len`, else [`FrameError::BadIndex`] (its names made only then).
fn within(
    index: u32,
    len: usize,
    field: impl FnOnce() -> String,
    table: impl FnOnce() -> String,
) -> Result<(), FrameError> {
    if (index as usize) < len {
        Ok(())
    } else {
        Err(FrameError::BadIndex { field: field(), index, table: table(), len })
    }
}

/// [`FrameError::BadTable`].
fn bad_table(table: String, message: String) -> FrameError {
    FrameError::BadTable { table, message }
}

/// The frame blob, borrowed and owned.
#[derive(Serialize)]
struct FrameRef<'a> {
    camera: &'a Camera,
    settings: &'a RenderSettings,
}

/// A decoded frame blob: the camera and the render settings of a job.
#[derive(Clone, Debug, Deserialize)]
pub struct Frame {
    /// The camera.
    pub camera: Camera,
    /// The render settings.
    pub settings: RenderSettings,
}

/// Why a frame blob cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The bytes are not a frame.
    #[error("the frame does not decode: {0}")]
    Codec(#[from] CodecError),
    /// A value the scene's validation would have refused (a frame made by hand, or corrupted).
    #[error("the frame's {0}")]
    Invalid(#[from] FieldError),
    /// A texture blob that does not decode or check, or a material whose image slot has no texture blob.
    #[error("textures: {0}")]
    Textures(String),
    /// An index in a scene blob at or past the end of the table it points into (a forged or corrupted blob).
    #[error("scene blob: {field} = {index}, but {table} has {len} entries")]
    BadIndex {
        /// Where the index is, e.g. `meshes[2].normal_indices[17][1]` or `prims[40].material`.
        field: String,
        /// The index found.
        index: u32,
        /// The table it points into, e.g. `meshes[2].normals` or `materials`.
        table: String,
        /// That table's length.
        len: usize,
    },
    /// A table of a scene blob that disagrees with another: a choice table shorter than the light list, a
    /// mesh's UV faces not matching its normal faces, a primitive's light that is not an area light on it.
    #[error("scene blob: {table} {message}")]
    BadTable {
        /// The field or table, e.g. `lights.pmf` or `prims[3].light`.
        table: String,
        /// What it holds and what it disagrees with.
        message: String,
    },
}

impl Frame {
    /// Decodes a frame blob of at most `limit` bytes and checks it with the scene's rules: image sizes within
    /// [`crate::scene::MAX_IMAGE_SIDE`], finite camera, render settings in range. What arrives from the wire
    /// passes here before anything is allocated from its sizes.
    pub fn decode(frame: &[u8], limit: usize) -> Result<Self, FrameError> {
        let f: Frame = codec::decode(frame, limit)?;
        f.camera.check()?;
        f.settings.check()?;
        Ok(f)
    }
}

impl Prepared {
    /// The scene blob: geometry with its BVH, materials and lights (what stays the same from frame to frame).
    pub fn encode_scene(&self) -> Result<Vec<u8>, CodecError> {
        codec::encode(&SceneRef {
            geometry: &self.geometry,
            materials: &self.materials,
            lights: &self.lights,
            media: &self.media,
        })
    }

    /// The photons blob, when there are photon maps.
    pub fn encode_photons(&self) -> Result<Option<Vec<u8>>, CodecError> {
        self.photons.as_ref().map(codec::encode).transpose()
    }

    /// The frame blob: camera and render settings (small; it travels with every strip request).
    pub fn encode_frame(&self) -> Result<Vec<u8>, CodecError> {
        Self::encode_frame_of(&self.camera, &self.settings)
    }

    /// The frame blob of a camera and settings.
    pub fn encode_frame_of(camera: &Camera, settings: &RenderSettings) -> Result<Vec<u8>, CodecError> {
        codec::encode(&FrameRef { camera, settings })
    }

    /// The texture blobs, one per image slot ([`encode_textures`]).
    pub fn encode_textures(&self) -> Result<Vec<Vec<u8>>, CodecError> {
        encode_textures(&self.textures)
    }

    /// A prepared scene from its scene blob, its decoded texture images, a camera and settings, without photon
    /// maps.
    pub fn from_scene_blob(
        scene: &[u8],
        textures: Arc<Vec<TexelImage>>,
        camera: Camera,
        settings: RenderSettings,
        limit: usize,
    ) -> Result<Self, FrameError> {
        let s = SceneOwned::decode(scene, limit)?;
        check_slots(&s.materials, textures.len())?;
        check_light_textures(&s.lights, &textures)?;
        let (geometry, materials, lights, media) = (s.geometry, s.materials, s.lights, s.media);
        Ok(Self { camera, geometry, materials, lights, settings, photons: None, media, textures })
    }

    /// Reassembles a prepared scene from its blobs, refusing any blob longer than `limit` bytes, a frame that
    /// [`Frame::decode`] refuses, a texture blob that does not check ([`TexelImage::check`]) and a material whose
    /// image slot has no texture.
    pub fn from_blobs(
        scene: &[u8],
        photons: Option<&[u8]>,
        frame: &[u8],
        textures: &[&[u8]],
        limit: usize,
    ) -> Result<Self, FrameError> {
        let s = SceneOwned::decode(scene, limit)?;
        let f = Frame::decode(frame, limit)?;
        let photons = photons.map(|p| codec::decode(p, limit)).transpose()?;
        let textures = decode_textures(textures, limit)?;
        check_slots(&s.materials, textures.len())?;
        check_light_textures(&s.lights, &textures)?;
        Ok(Self {
            camera: f.camera,
            geometry: s.geometry,
            materials: s.materials,
            lights: s.lights,
            settings: f.settings,
            photons,
            media: s.media,
            textures: Arc::new(textures),
        })
    }
}

/// The texture blobs of `images`, one per slot: each image's texels, decoded once from its file.
pub fn encode_textures(images: &[TexelImage]) -> Result<Vec<Vec<u8>>, CodecError> {
    images.iter().map(codec::encode).collect()
}

/// Decodes and checks texture blobs, each of at most `limit` bytes.
pub fn decode_textures(blobs: &[&[u8]], limit: usize) -> Result<Vec<TexelImage>, FrameError> {
    blobs
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let img: TexelImage =
                codec::decode(b, limit).map_err(|e| FrameError::Textures(format!("texture {i}: {e}")))?;
            img.check().map_err(|e| FrameError::Textures(format!("texture {i}: {e}")))?;
            Ok(img)
        })
        .collect()
}

/// Refuses a material whose image slot is not below `n`.
fn check_slots(materials: &[Material], n: usize) -> Result<(), FrameError> {
    for (i, m) in materials.iter().enumerate() {
        for (field, r) in m.images() {
            if r.slot as usize >= n {
                return Err(FrameError::Textures(format!("material {i}'s {field} reads texture {} of {n}", r.slot)));
            }
        }
    }
    Ok(())
}

/// Each textured area light's image slot and the environment's below the texture count, and the
/// environment's distribution made for that image's size.
fn check_light_textures(lights: &LightSet, textures: &[TexelImage]) -> Result<(), FrameError> {
    for (l, light) in lights.lights.iter().enumerate() {
        if let Light::Area { image: Some(e), .. } = light
            && e.slot as usize >= textures.len()
        {
            return Err(FrameError::Textures(format!("light {l} reads texture {} of {}", e.slot, textures.len())));
        }
    }
    let Some((_, &Light::Environment { image, .. })) = lights.environment() else { return Ok(()) };
    if image == NONE {
        return Ok(());
    }
    let n = textures.len();
    let Some(img) = textures.get(image as usize) else {
        return Err(FrameError::Textures(format!("the environment reads texture {image} of {n}")));
    };
    match &lights.sky {
        Some(sky) if sky.fits(img.width, img.height) => Ok(()),
        _ => Err(bad_table(
            "lights.sky".into(),
            format!("does not fit the environment's {}×{} image", img.width, img.height),
        )),
    }
}
