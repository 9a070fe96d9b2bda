//! The scene file: TOML, read with serde, every unknown field an error, every field with a documented default.
//! `docs/SCENE.md` is the manual; this module is its source of truth.
//!
//! ```toml
//! [camera]
//! eye = [0.0, 1.0, 3.4]
//! look_at = [0.0, 1.0, 0.0]
//! fov = 40.0
//! width = 512
//! height = 512
//!
//! [render]
//! spp = 64
//! integrator = "path"
//!
//! [materials.white]
//! type = "lambert"
//! albedo = 0.73
//!
//! [[objects]]
//! type = "rect"
//! center = [0.0, 1.99, 0.0]
//! normal = [0.0, -1.0, 0.0]
//! tangent = [1.0, 0.0, 0.0]
//! width = 0.5
//! height = 0.4
//! material = "white"
//! emission = { radiance = [17.0, 12.0, 4.0] }
//! ```
//! Paths (meshes) resolve relative to the scene file's folder.
//!
//! The parts: the value types of the file ([`types`]), `--set` overrides applied before validation
//! (`overrides`), validation of what the types cannot express (`validate`), and the line of a field in the
//! file for errors (`source`). A new object kind is a variant of [`Object`] with its checks in `validate`.

mod limits;
mod overrides;
mod source;
pub mod types;
mod validate;

pub(crate) use limits::image_side;
pub use limits::{MAX_CAMERA_COORDINATE, MAX_IMAGE_SIDE, MAX_K, MAX_PASSES};
pub use types::*;

use crate::material::Material;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A scene as written in its file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// The camera.
    pub camera: CameraSpec,
    /// Render settings.
    #[serde(default)]
    pub render: RenderSettings,
    /// Named materials.
    #[serde(default)]
    pub materials: BTreeMap<String, Material>,
    /// Surfaces.
    #[serde(default)]
    pub objects: Vec<Object>,
    /// Point, spot and directional lights and the environment (area lights are objects with `emission`).
    #[serde(default)]
    pub lights: Vec<LightSpec>,
    /// Limits on the files the scene reads.
    #[serde(default)]
    pub limits: Limits,
    /// The participating medium filling the space outside all closed objects (`[medium]`); default none.
    #[serde(default)]
    pub medium: Option<MediumSpec>,
    /// The folder that relative paths resolve against (the scene file's folder); not part of the file.
    #[serde(skip)]
    pub base_dir: PathBuf,
}

/// Limits on what a scene reads: the `[limits]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// The largest mesh file read, in MiB; default 2048.
    #[serde(default = "default_mesh_mib")]
    pub mesh_mib: u64,
    /// The largest texture image read, in MiB, both as a file and decoded; default 1024.
    #[serde(default = "default_texture_mib")]
    pub texture_mib: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self { mesh_mib: default_mesh_mib(), texture_mib: default_texture_mib() }
    }
}

fn default_texture_mib() -> u64 {
    crate::input::DEFAULT_TEXTURE_MIB
}

fn default_mesh_mib() -> u64 {
    crate::input::DEFAULT_MESH_MIB
}

/// Why a scene could not be loaded. Every variant names the file, and the line or the field.
///
/// The message of every variant is complete: it includes its cause (the I/O error, the mesh's `file:line`), so
/// `source()` is `None` and a chain printer (`anyhow`'s `{:#}`) does not repeat the cause.
#[derive(Debug)]
pub enum SceneError {
    /// The file could not be read, is not a regular file, or is larger than [`crate::input::MAX_SCENE_BYTES`].
    Io {
        /// The scene file.
        path: PathBuf,
        /// The cause.
        source: crate::input::InputError,
    },
    /// The file is not UTF-8 text.
    Encoding {
        /// The scene file.
        path: PathBuf,
        /// Where the first byte that is not UTF-8 is.
        at: crate::input::EncodingError,
    },
    /// TOML syntax or a field of the wrong name or type (the message gives line and column).
    Parse {
        /// The scene file.
        path: PathBuf,
        /// The parser's message, with line and column.
        message: String,
    },
    /// A field whose value is not allowed.
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// The line of the field (or of what encloses it) in the file, when the file writes it.
        line: Option<usize>,
        /// The field, e.g. `objects[3].radius`.
        field: String,
        /// What was expected.
        message: String,
    },
    /// A `--set KEY=VALUE` override that is malformed, of the wrong type, or gives a value not allowed.
    Override {
        /// The scene file.
        path: PathBuf,
        /// The scene field, e.g. `render.photons.k`.
        field: String,
        /// The override as given, `KEY=VALUE`.
        setting: String,
        /// What was expected.
        message: String,
    },
    /// A photon map could not be built from the photons the scene's lights emitted.
    Photons {
        /// The scene file.
        path: PathBuf,
        /// The cause.
        source: crate::photon::PhotonMapError,
    },
    /// A texture image could not be loaded.
    Texture {
        /// The scene file.
        path: PathBuf,
        /// The field that names the image, e.g. `materials.wood.albedo.image`.
        field: String,
        /// The image file.
        file: PathBuf,
        /// The cause.
        source: crate::material::texture::TextureError,
    },
    /// A mesh could not be loaded.
    Mesh {
        /// The scene file.
        path: PathBuf,
        /// The field that names the mesh.
        field: String,
        /// The cause.
        source: crate::geometry::mesh::MeshError,
    },
}

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SceneError::Io { path, source } => {
                write!(f, "{}: cannot read the scene file: {source}", path.display())
            }
            SceneError::Encoding { path, at } => {
                write!(f, "{}:{}: the scene is not UTF-8 text (byte offset {})", path.display(), at.line, at.offset)
            }
            SceneError::Parse { path, message } => write!(f, "{}: {}", path.display(), message.trim_end()),
            SceneError::Invalid { path, line: Some(line), field, message } => {
                write!(f, "{}:{line}: {field}: {message}", path.display())
            }
            SceneError::Invalid { path, line: None, field, message } => {
                write!(f, "{}: {field}: {message}", path.display())
            }
            SceneError::Override { path, field, setting, message } => {
                write!(f, "{}: {field}: {message} (from --set {setting})", path.display())
            }
            SceneError::Photons { path, source } => write!(f, "{}: render.photons: {source}", path.display()),
            SceneError::Mesh { path, field, source } => write!(f, "{}: {field}: {source}", path.display()),
            SceneError::Texture { path, field, file, source } => {
                write!(f, "{}: {field}: {}: {source}", path.display(), file.display())
            }
        }
    }
}

impl std::error::Error for SceneError {}

impl Scene {
    /// Reads, parses and validates a scene file.
    ///
    /// # Errors
    /// [`SceneError`]: the file cannot be read, is not valid TOML or not a scene (with line and column), or a
    /// value is not allowed (with the line of its field).
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = read(path)?;
        Self::parse(&text, path)
    }

    /// Parses and validates scene text; `path` names the file in errors and gives the base folder.
    pub fn parse(text: &str, path: &Path) -> Result<Scene, SceneError> {
        // The parser's message quotes the offending line: a megabyte-long one is cut.
        let mut scene: Scene = toml::from_str(text).map_err(|e| SceneError::Parse {
            path: path.into(),
            message: crate::input::excerpt_lines(&e.to_string()),
        })?;
        scene.base_dir = base_dir(path);
        scene.validate(text, path)?;
        Ok(scene)
    }

    /// Checks every value the types cannot; an error names the field and its line in `text`.
    pub fn validate(&self, text: &str, path: &Path) -> Result<(), SceneError> {
        self.check().map_err(|e| SceneError::Invalid {
            path: path.into(),
            line: source::line_of(text, &e.field),
            field: e.field,
            message: e.message,
        })
    }
}

/// The scene file's text: a regular file of at most [`crate::input::MAX_SCENE_BYTES`], in UTF-8.
fn read(path: &Path) -> Result<String, SceneError> {
    let bytes = crate::input::read_regular(path, crate::input::MAX_SCENE_BYTES, "scenes are at most 16 MiB")
        .map_err(|source| SceneError::Io { path: path.into(), source })?;
    let text = crate::input::utf8(&bytes).map_err(|at| SceneError::Encoding { path: path.into(), at })?;
    Ok(text.to_owned())
}

/// The folder that a scene file's relative paths resolve against.
fn base_dir(path: &Path) -> PathBuf {
    path.parent().map(Path::to_path_buf).unwrap_or_default()
}
