//! The coordinator's disk cache of prepared blobs: rendering an unchanged scene again skips loading meshes,
//! building the BVH and tracing photons.
//!
//! Two keys, so that changing only what photons depend on keeps the geometry:
//! - the **scene key** hashes the build id, the scene's materials, objects and lights as parsed (after `--set`),
//!   and the path and bytes of every file they reference (meshes; glTF files with their buffers and images);
//! - the **photons key** hashes the scene key, the render settings except those that cannot change a photon
//!   (samples per pixel, exposure), and the path and bytes of every texture image (photons bounce off textured
//!   surfaces; the scene blob names images by slot, so it does not depend on them).
//!
//! The camera is in neither: it travels in the frame. What the camera decides of the scene blob, the error
//! bound of each simplified mesh ([`photon_core::prepare::lod::plan`], quantised to quarter octaves so that a
//! small move of the camera keeps it), is in the scene key: a mesh simplified for another view is never reused,
//! and an unchanged bound finds the mesh that bound builds. A changed input changes a key, and another build has
//! another build id, so a stale entry is never read; it just ages out. Each file holds the BLAKE3 hash of its
//! payload before the payload, and a file that does not match is deleted and rebuilt. The folder is a
//! [`DiskStore`]: files are written under a temporary name and renamed, and the folder is trimmed to its cap,
//! least recently used first.

use photon_core::codec::CodecError;
use photon_core::scene::{Object, Scene};
use photon_worker::disk_store::{DiskStore, DiskStoreError, Integrity};
use std::path::{Path, PathBuf};

/// Which cache entries a render used.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Hits {
    /// The scene blob came from the cache.
    pub scene: bool,
    /// The photons blob came from the cache.
    pub photons: bool,
}

/// Why the cache cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PreparedCacheError {
    /// Its folder cannot be created.
    #[error(transparent)]
    Store(#[from] DiskStoreError),
    /// A part of the scene cannot be encoded for hashing.
    #[error("hashing the scene's {what}: {cause}")]
    Hash {
        /// Which part.
        what: &'static str,
        /// The encoder's error.
        cause: CodecError,
    },
}

/// A folder of prepared blobs.
pub struct PreparedCache {
    store: DiskStore,
}

/// The cache keys of a scene.
pub struct Keys {
    /// Key of the scene blob.
    pub scene: String,
    /// Key of the photons blob.
    pub photons: String,
}

impl PreparedCache {
    /// The cache in `dir`, created if missing, trimmed to `cap` bytes.
    pub fn open(dir: PathBuf, cap: u64) -> Result<Self, PreparedCacheError> {
        Ok(Self { store: DiskStore::open(dir, cap, &["scene", "photons"], Integrity::ChecksumHeader)? })
    }

    /// The default folder: `$PHOTON_CACHE_DIR`, else `$XDG_CACHE_HOME/photon`, else `$HOME/.cache/photon`.
    pub fn default_dir() -> Option<PathBuf> {
        let env = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
        env("PHOTON_CACHE_DIR")
            .or_else(|| env("XDG_CACHE_HOME").map(|d| d.join("photon")))
            .or_else(|| env("HOME").map(|d| d.join(".cache/photon")))
    }

    /// The keys of `scene`, reading every file it references.
    pub fn keys(scene: &Scene) -> Result<Keys, PreparedCacheError> {
        let enc = |what: &'static str, r: Result<Vec<u8>, CodecError>| {
            r.map_err(|cause| PreparedCacheError::Hash { what, cause })
        };
        let mut h = photon_proto::Hasher::new();
        h.update(photon_proto::BUILD_ID.as_bytes());
        h.update(&enc("materials", photon_core::codec::encode(&scene.materials))?);
        h.update(&enc("objects", photon_core::codec::encode(&scene.objects))?);
        h.update(&enc("lights", photon_core::codec::encode(&scene.lights))?);
        let mesh_limit = (scene.limits.mesh_mib.saturating_mul(1 << 20), "limits.mesh_mib");
        let texture_limit = (scene.limits.texture_mib.saturating_mul(1 << 20), "limits.texture_mib");
        for o in &scene.objects {
            if let Object::Mesh { file, .. } = o {
                hash_file(&mut h, &scene.base_dir.join(file), mesh_limit);
            }
        }
        // glTF objects: the file and the buffers and images beside it (its embedded images too: the scene key
        // covers the photons key).
        for path in photon_core::prepare::gltf::files(scene) {
            hash_file(&mut h, &path, mesh_limit);
        }
        // The environment's image decides the scene blob's distribution over it and its power.
        let env_image = photon_core::prepare::textures::environment_image(scene).map(|(_, f)| scene.base_dir.join(f));
        if let Some(path) = &env_image {
            hash_file(&mut h, path, texture_limit);
        }
        // The level of detail of each mesh: kept whole (0), or simplified with this bound (its bits).
        for lod in photon_core::prepare::lod::plan(scene) {
            let bound = match lod {
                Some(photon_core::prepare::lod::MeshLod::Simplify { bound }) => bound.to_bits(),
                _ => 0,
            };
            h.update(&bound.to_le_bytes());
        }
        let scene_key = h.finalize().to_hex().to_string();
        let mut settings = scene.render.clone();
        settings.spp = 0;
        settings.exposure = 0.0;
        let mut h = photon_proto::Hasher::new();
        h.update(scene_key.as_bytes());
        h.update(&enc("settings", photon_core::codec::encode(&settings))?);
        // Photons bounce off textured surfaces: their images' bytes decide the maps (not the scene blob, which
        // names images by slot). The environment's image is in the scene key already.
        for (path, _) in photon_core::prepare::textures::files(scene) {
            if env_image.as_ref() != Some(&path) {
                hash_file(&mut h, &path, texture_limit);
            }
        }
        Ok(Keys { scene: scene_key, photons: h.finalize().to_hex().to_string() })
    }

    fn name(key: &str, kind: &str) -> String {
        format!("{key}.{kind}")
    }

    /// The cached payload, if present and intact.
    pub fn load(&self, key: &str, kind: &str) -> Option<Vec<u8>> {
        let name = Self::name(key, kind);
        match self.store.read(&name) {
            Ok(bytes) => {
                // Mark it used, so trimming removes the least recently used first.
                self.store.touch(&name);
                bytes
            }
            Err(_) => {
                tracing::warn!("{} is damaged; rebuilding it", self.store.path(&name).display());
                None
            }
        }
    }

    /// Stores a payload; a failure only costs the next render a rebuild, so it is logged, not returned.
    pub fn store(&self, key: &str, kind: &str, payload: &[u8]) {
        if let Err(e) = self.store.write(&Self::name(key, kind), payload) {
            tracing::warn!("cannot write the prepared cache in {}: {e}", self.store.dir().display());
        }
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        self.store.dir()
    }
}

/// Adds file `path` to `h`: its path, its length and its bytes, read within `limit` (bytes, and the setting that
/// sets them). A file that cannot be read (or is not a regular file, or is over the limit: `/dev/zero` would
/// never end) adds its path and length 0, and is left to the loader, which reports it with the scene's context.
fn hash_file(h: &mut photon_proto::Hasher, path: &std::path::Path, (limit, setting): (u64, &'static str)) {
    let bytes = photon_core::input::read_regular(path, limit, setting).unwrap_or_default();
    h.update(path.to_string_lossy().as_bytes());
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(&bytes);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(dir: &Path, photons: u32, spp: u32) -> Scene {
        scene_from(dir, photons, spp, 5.0)
    }

    fn scene_from(dir: &Path, photons: u32, spp: u32, eye_z: f32) -> Scene {
        let text = format!(
            "[camera]\neye = [0, 0, {eye_z}]\nlook_at = [0, 0, 0]\nwidth = 8\nheight = 8\n\
             [render]\nspp = {spp}\n[render.photons]\nglobal = {photons}\n\
             [materials.white]\ntype = \"lambert\"\nalbedo = [0.5, 0.5, 0.5]\n\
             [[objects]]\ntype = \"mesh\"\nfile = \"m.obj\"\nmaterial = \"white\"\n"
        );
        std::fs::write(dir.join("s.toml"), text).unwrap();
        Scene::load(&dir.join("s.toml")).unwrap()
    }

    #[test]
    fn keys_follow_the_inputs() {
        let dir = std::env::temp_dir().join(format!("photon-prepared-keys-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let base = PreparedCache::keys(&scene(&dir, 1000, 4)).unwrap();
        // Samples per pixel change neither key.
        let spp = PreparedCache::keys(&scene(&dir, 1000, 64)).unwrap();
        assert_eq!((&base.scene, &base.photons), (&spp.scene, &spp.photons));
        // Photon settings change the photons key only.
        let more = PreparedCache::keys(&scene(&dir, 2000, 4)).unwrap();
        assert_eq!(base.scene, more.scene);
        assert_ne!(base.photons, more.photons);
        // A changed mesh file changes both.
        std::fs::write(dir.join("m.obj"), "v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let mesh = PreparedCache::keys(&scene(&dir, 1000, 4)).unwrap();
        assert_ne!(base.scene, mesh.scene);
        assert_ne!(base.photons, mesh.photons);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_changed_texture_image_changes_the_photons_key_only() {
        let dir = std::env::temp_dir().join(format!("photon-prepared-texture-keys-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a.png"), b"first image bytes").unwrap();
        let text = "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n\
                    [materials.wood]\ntype = \"lambert\"\nalbedo = { image = \"a.png\" }\n\
                    [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"wood\"\n";
        std::fs::write(dir.join("s.toml"), text).unwrap();
        let keys = || PreparedCache::keys(&Scene::load(&dir.join("s.toml")).unwrap()).unwrap();
        let before = keys();
        std::fs::write(dir.join("a.png"), b"other image bytes").unwrap();
        let after = keys();
        // The scene blob names images by slot: it does not change; photons bounce off the new texels.
        assert_eq!(before.scene, after.scene);
        assert_ne!(before.photons, after.photons);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_scene_key_follows_the_level_of_detail() {
        let dir = std::env::temp_dir().join(format!("photon-prepared-lod-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        // The mesh's nearest point is 10 units away: a slightly moved camera keeps the quantised bound and the key.
        let base = PreparedCache::keys(&scene_from(&dir, 1000, 4, 10.0)).unwrap();
        let nudged = PreparedCache::keys(&scene_from(&dir, 1000, 4, 10.01)).unwrap();
        assert_eq!(base.scene, nudged.scene);
        // Twice as far, the bound doubles: another mesh, another key.
        let far = PreparedCache::keys(&scene_from(&dir, 1000, 4, 20.0)).unwrap();
        assert_ne!(base.scene, far.scene);
        assert_ne!(base.photons, far.photons);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn damaged_files_are_not_read() {
        let dir = std::env::temp_dir().join(format!("photon-prepared-cache-{}", std::process::id()));
        let cache = PreparedCache::open(dir.clone(), 1 << 20).unwrap();
        cache.store("k", "scene", b"payload");
        assert_eq!(cache.load("k", "scene").unwrap(), b"payload");
        let mut bytes = std::fs::read(dir.join("k.scene")).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(dir.join("k.scene"), bytes).unwrap();
        assert!(cache.load("k", "scene").is_none());
        assert!(!dir.join("k.scene").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
