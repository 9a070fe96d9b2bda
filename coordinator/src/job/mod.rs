//! A render job and what survives an interrupted one: the blobs and frame of a prepared scene ([`Job`],
//! built by [`prepare_job`], through the prepared-blob cache when there is one), and the strips finished so far
//! ([`Partial`]), kept in a partial file beside the output for `--resume`. Preparing one also decides how the
//! workers get its photon maps ([`delivery`]) and keeps the prepared blobs on disk for the next render of an
//! unchanged scene ([`prepared_cache`]).

pub mod delivery;
pub mod prepared_cache;

use delivery::Decision;
use photon_core::codec::CodecError;
use photon_core::prepare::Prepared;
use photon_core::scene::{Scene, SceneError};
use prepared_cache::{PreparedCache, PreparedCacheError};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Why a job cannot be prepared, or a partial file read or written. The messages without a cause in them are
/// context: the cause is the error's source, so `{:#}` prints both.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// The scene cannot be prepared (meshes, photon maps).
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The cache keys cannot be computed.
    #[error(transparent)]
    Cache(#[from] PreparedCacheError),
    /// A blob cannot be encoded.
    #[error("encoding the {0}")]
    Encode(&'static str, #[source] CodecError),
    /// The cached scene blob does not decode.
    #[error("decoding the cached scene in {}", dir.display())]
    DecodeCached {
        /// The cache's folder.
        dir: PathBuf,
        /// The decoder's error.
        #[source]
        cause: photon_core::prepare::blobs::FrameError,
    },
    /// The partial file cannot be read.
    #[error("reading the partial file {}", path.display())]
    ReadPartial {
        /// The file.
        path: PathBuf,
        /// The reason.
        #[source]
        cause: std::io::Error,
    },
    /// The file is not a partial render.
    #[error("{} is not a partial render", path.display())]
    NotPartial {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        cause: CodecError,
    },
    /// The partial file cannot be written.
    #[error("writing {}", path.display())]
    WritePartial {
        /// The file.
        path: PathBuf,
        /// The reason.
        #[source]
        cause: std::io::Error,
    },
}

/// A job: the blobs of a prepared scene and the frame to render.
#[derive(Clone, Debug)]
pub struct Job {
    /// Blob id of the scene (geometry in BVH leaf order, materials, lights; the tree is built again on decoding).
    pub scene_blob: String,
    /// Blob id of the photon maps, if the method has any.
    pub photons_blob: Option<String>,
    /// Blob ids of the texture images, by slot.
    pub texture_blobs: Vec<String>,
    /// Every blob by id, shared with the shipping tasks.
    pub blobs: BTreeMap<String, Arc<Vec<u8>>>,
    /// The encoded frame (camera and settings).
    pub frame: Vec<u8>,
    /// Image size in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The method reads photon maps and the job carries none: every worker traces them itself from the
    /// deterministic photon streams ([`crate::job::delivery`]).
    pub trace_photons: bool,
    /// The pass count when the method renders in passes (progressive, vcm, bdpt, lt: see
    /// [`photon_core::method::Method::renders_passes`]): the farm then hands out whole-image pass
    /// blocks ([`crate::farm::scheduler::passes_per_block_for`]) instead of strips of rows.
    pub passes: Option<u32>,
    /// The units of the whole job ([`photon_core::scene::RenderSettings::units`]): what each strip of rows
    /// renders when the farm cuts rows.
    pub units: u32,
    /// The workers pass big blobs among themselves (`--photon-maps peers`) instead of each receiving them
    /// from the coordinator.
    pub swarm: Option<Arc<crate::fleet::swarm::Swarm>>,
}

impl Job {
    /// A job from the encoded parts of a prepared scene, rendered with `settings`.
    pub fn new(
        scene: Vec<u8>,
        photons: Option<Vec<u8>>,
        textures: Vec<Vec<u8>>,
        frame: Vec<u8>,
        (width, height): (u32, u32),
        settings: &photon_core::scene::RenderSettings,
    ) -> Self {
        let mut blobs = BTreeMap::new();
        // Files a blob under its content id and returns the id.
        let mut add = |bytes: Vec<u8>| {
            let id = photon_proto::blob_id(&bytes);
            blobs.insert(id.clone(), Arc::new(bytes));
            id
        };
        let scene_blob = add(scene);
        let photons_blob = photons.map(&mut add);
        let texture_blobs = textures.into_iter().map(&mut add).collect();
        let passes = settings.integrator.renders_passes().then_some(settings.photons.passes.max(1));
        let trace_photons = settings.integrator.needs_photon_maps() && photons_blob.is_none();
        Self {
            scene_blob,
            photons_blob,
            texture_blobs,
            blobs,
            frame,
            width,
            height,
            passes,
            units: settings.units(),
            trace_photons,
            swarm: None,
        }
    }

    /// A fingerprint of everything that decides the pixels: the scene blob, the textures, the frame and the size. A partial
    /// file is resumed only by the job with the same fingerprint. The photons blob is left out: the scene and
    /// the frame decide its bytes, and a job whose workers trace the maps renders the same image.
    pub fn fingerprint(&self) -> String {
        let mut h = photon_proto::Hasher::new();
        h.update(self.scene_blob.as_bytes());
        for t in &self.texture_blobs {
            h.update(t.as_bytes());
        }
        h.update(&self.frame);
        h.update(&self.width.to_le_bytes());
        h.update(&self.height.to_le_bytes());
        h.finalize().to_hex().to_string()
    }

    /// Bytes of all blobs.
    pub fn blob_bytes(&self) -> u64 {
        self.blobs.values().map(|b| b.len() as u64).sum()
    }
}

/// Strips or pass blocks finished so far: what an interrupted render leaves for `--resume`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Partial {
    /// [`Job::fingerprint`] of the job.
    pub fingerprint: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The strip height the render used, or the units per block for a cut of whole-image blocks (a resumed
    /// render cuts the work the same way).
    pub rows_per_strip: u32,
    /// The first row of each finished strip, or the first unit of each finished block.
    pub done: Vec<u32>,
    /// The fixed-point sums of the finished units (3 per pixel, row-major, of the whole image).
    pub sums: Vec<i128>,
}

/// Prepares a scene into a job, through the prepared-blob cache when there is one: the scene blob (meshes in BVH
/// leaf order, materials, lights) and the photons blob are each read from the cache or built and stored. For a method with
/// photon maps, `delivery` decides from the prepared scene whether the maps are traced here and shipped or
/// traced by the workers ([`crate::job::delivery`]); the job then carries no photons blob and the workers trace.
pub fn prepare_job(
    scene: &Scene,
    scene_path: &Path,
    cache: Option<&PreparedCache>,
    delivery: impl FnOnce(&Prepared) -> Decision,
) -> Result<(Job, Option<prepared_cache::Hits>, Option<Decision>), JobError> {
    let camera = photon_core::camera::Camera::new(&scene.camera);
    let settings = scene.render.clone();
    let frame = Prepared::encode_frame_of(&camera, &settings).map_err(|e| JobError::Encode("frame", e))?;
    let (width, height) = (camera.width, camera.height);
    let needs_photons = settings.integrator.needs_photon_maps();
    let job = |scene_blob, photons, textures| {
        Job::new(scene_blob, photons, textures, frame.clone(), (width, height), &settings)
    };
    let Some(cache) = cache else {
        let prep = Prepared::new(scene, scene_path)?;
        let scene_blob = prep.encode_scene().map_err(|e| JobError::Encode("scene", e))?;
        let textures = prep.encode_textures().map_err(|e| JobError::Encode("textures", e))?;
        let decision = needs_photons.then(|| delivery(&prep));
        let photons = match decision {
            Some(d) if d.mode.ships() => {
                let prep = prep.with_photon_maps(scene_path)?;
                prep.encode_photons().map_err(|e| JobError::Encode("photon maps", e))?
            }
            _ => None,
        };
        return Ok((job(scene_blob, photons, textures), None, decision));
    };
    let keys = PreparedCache::keys(scene)?;
    let cached_scene = cache.load(&keys.scene, "scene");
    let scene_hit = cached_scene.is_some();
    // Build what is missing; decode the cached scene only when photons are involved.
    let (scene_blob, prep, images) = match cached_scene {
        Some(bytes) => {
            // Texture images are not cached: they are read and decoded from their files.
            let (_, images, _) = photon_core::prepare::textures::load(scene, scene_path)?;
            (bytes, None, Arc::new(images))
        }
        None => {
            let prep = Prepared::new(scene, scene_path)?;
            let bytes = prep.encode_scene().map_err(|e| JobError::Encode("scene", e))?;
            cache.store(&keys.scene, "scene", &bytes);
            let images = prep.textures.clone();
            (bytes, Some(prep), images)
        }
    };
    let textures =
        photon_core::prepare::blobs::encode_textures(&images).map_err(|e| JobError::Encode("textures", e))?;
    if !needs_photons {
        let hits = prepared_cache::Hits { scene: scene_hit, photons: false };
        return Ok((job(scene_blob, None, textures), Some(hits), None));
    }
    let prep = match prep {
        Some(p) => p,
        None => Prepared::from_scene_blob(&scene_blob, images, camera, settings.clone(), usize::MAX)
            .map_err(|cause| JobError::DecodeCached { dir: cache.dir().into(), cause })?,
    };
    let decision = delivery(&prep);
    if !decision.mode.ships() {
        let hits = prepared_cache::Hits { scene: scene_hit, photons: false };
        return Ok((job(scene_blob, None, textures), Some(hits), Some(decision)));
    }
    let cached_photons = cache.load(&keys.photons, "photons");
    let hits = prepared_cache::Hits { scene: scene_hit, photons: cached_photons.is_some() };
    let photons = match cached_photons {
        Some(bytes) => Some(bytes),
        None => {
            let prep = prep.with_photon_maps(scene_path)?;
            let bytes = prep.encode_photons().map_err(|e| JobError::Encode("photon maps", e))?;
            if let Some(b) = &bytes {
                cache.store(&keys.photons, "photons", b);
            }
            bytes
        }
    };
    Ok((job(scene_blob, photons, textures), Some(hits), Some(decision)))
}

/// Where an interrupted render keeps its finished strips.
pub fn partial_path(output: &Path) -> PathBuf {
    let mut p = output.as_os_str().to_owned();
    p.push(".partial");
    PathBuf::from(p)
}

impl Partial {
    /// Reads a partial file left by an interrupted render.
    pub fn read(path: &Path) -> Result<Self, JobError> {
        let bytes = std::fs::read(path).map_err(|cause| JobError::ReadPartial { path: path.into(), cause })?;
        photon_core::codec::decode(&bytes, bytes.len())
            .map_err(|cause| JobError::NotPartial { path: path.into(), cause })
    }

    /// Writes the partial file so that a crash at any moment leaves either the file that was there or this
    /// one, whole ([`write_atomically`]).
    pub fn write(&self, path: &Path) -> Result<(), JobError> {
        write_atomically(path, &self.encode()?)
    }

    /// The partial file's bytes.
    pub fn encode(&self) -> Result<Vec<u8>, JobError> {
        photon_core::codec::encode(self).map_err(|e| JobError::Encode("partial render", e))
    }
}

/// Writes `bytes` to `path` so that a crash at any moment leaves either the file that was there or this one,
/// whole: into `PATH.tmp` beside it, flushed to the disk (`fsync`), then renamed over `path`, and the folder
/// flushed so that the rename itself survives a power cut.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), JobError> {
    use std::io::Write;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let written = std::fs::File::create(&tmp).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    written.and_then(|()| std::fs::rename(&tmp, path)).map_err(|cause| {
        let _ = std::fs::remove_file(&tmp);
        JobError::WritePartial { path: path.into(), cause }
    })?;
    // Flushing the folder is best effort: some file systems do not open folders for it.
    let folder = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Ok(d) = std::fs::File::open(folder) {
        let _ = d.sync_all();
    }
    Ok(())
}
