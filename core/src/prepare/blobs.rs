//! The prepared scene as blobs for the wire and the disk caches, all through [`crate::codec`]: the scene blob
//! (geometry, materials, lights, media: what stays the same from frame to frame), the photons blob, and
//! the small frame blob (camera and render settings) that travels with every strip request.

use super::Prepared;
use crate::camera::Camera;
use crate::codec::{self, CodecError};
use crate::error::FieldError;
use crate::geometry::Geometry;
use crate::light::LightSet;
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
    /// Decodes a scene blob of at most `limit` bytes and checks its media's coefficients.
    fn decode(scene: &[u8], limit: usize) -> Result<Self, FrameError> {
        let mut s: SceneOwned = codec::decode(scene, limit)?;
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
