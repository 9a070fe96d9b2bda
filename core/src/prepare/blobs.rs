//! The prepared scene as blobs for the wire and the disk caches, all through [`crate::codec`]: the scene blob
//! (geometry with its BVH, materials, lights: what stays the same from frame to frame), the photons blob, and
//! the small frame blob (camera and render settings) that travels with every strip request.

use super::Prepared;
use crate::camera::Camera;
use crate::codec::{self, CodecError};
use crate::geometry::Geometry;
use crate::light::LightSet;
use crate::material::Material;
use crate::scene::RenderSettings;
use serde::{Deserialize, Serialize};

/// The scene blob, written from borrowed parts and read into owned ones (the same encoding).
#[derive(Serialize)]
struct SceneRef<'a> {
    geometry: &'a Geometry,
    materials: &'a [Material],
    lights: &'a LightSet,
}

#[derive(Deserialize)]
struct SceneOwned {
    geometry: Geometry,
    materials: Vec<Material>,
    lights: LightSet,
}

/// The frame blob, borrowed and owned.
#[derive(Serialize)]
struct FrameRef<'a> {
    camera: &'a Camera,
    settings: &'a RenderSettings,
}

#[derive(Deserialize)]
struct FrameOwned {
    camera: Camera,
    settings: RenderSettings,
}

impl Prepared {
    /// The scene blob: geometry with its BVH, materials and lights (what stays the same from frame to frame).
    pub fn encode_scene(&self) -> Result<Vec<u8>, CodecError> {
        codec::encode(&SceneRef { geometry: &self.geometry, materials: &self.materials, lights: &self.lights })
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

    /// A prepared scene from its scene blob, a camera and settings, without photon maps.
    pub fn from_scene_blob(
        scene: &[u8],
        camera: Camera,
        settings: RenderSettings,
        limit: usize,
    ) -> Result<Self, CodecError> {
        let s: SceneOwned = codec::decode(scene, limit)?;
        let (geometry, materials, lights) = (s.geometry, s.materials, s.lights);
        Ok(Self { camera, geometry, materials, lights, settings, photons: None })
    }

    /// Reassembles a prepared scene from its blobs, refusing any blob longer than `limit` bytes.
    pub fn from_blobs(scene: &[u8], photons: Option<&[u8]>, frame: &[u8], limit: usize) -> Result<Self, CodecError> {
        let s: SceneOwned = codec::decode(scene, limit)?;
        let f: FrameOwned = codec::decode(frame, limit)?;
        let photons = photons.map(|p| codec::decode(p, limit)).transpose()?;
        Ok(Self {
            camera: f.camera,
            geometry: s.geometry,
            materials: s.materials,
            lights: s.lights,
            settings: f.settings,
            photons,
        })
    }
}
