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

use crate::material::Material;
use glam::Vec3;
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
    /// Point lights (area lights are objects with `emission`).
    #[serde(default)]
    pub lights: Vec<LightSpec>,
    /// The folder that relative paths resolve against (the scene file's folder); not part of the file.
    #[serde(skip)]
    pub base_dir: PathBuf,
}

fn default_up() -> Vec3 {
    Vec3::Y
}
fn default_fov() -> f32 {
    40.0
}
fn default_width() -> u32 {
    512
}
fn default_height() -> u32 {
    512
}

/// A pinhole or thin-lens camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Position of the eye (required).
    pub eye: Vec3,
    /// The point looked at (required).
    pub look_at: Vec3,
    /// Up direction; default `[0, 1, 0]`.
    #[serde(default = "default_up")]
    pub up: Vec3,
    /// Vertical field of view in degrees, in (0, 180); default 40.
    #[serde(default = "default_fov")]
    pub fov: f32,
    /// Image width in pixels; default 512.
    #[serde(default = "default_width")]
    pub width: u32,
    /// Image height in pixels; default 512.
    #[serde(default = "default_height")]
    pub height: u32,
    /// Lens radius for depth of field; default 0 (a pinhole).
    #[serde(default)]
    pub aperture: f32,
    /// Distance of the plane in focus; default the distance from `eye` to `look_at`.
    #[serde(default)]
    pub focus_distance: Option<f32>,
}

/// How pixels are computed: the method, in the scene file (`render.integrator`) and on the command line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Unbiased path tracing with next-event estimation, MIS and Russian roulette (the reference).
    #[default]
    Path,
    /// Direct lighting at the first non-specular hit, following mirror and glass.
    Direct,
    /// Direct visualisation of the global photon map at the first non-specular hit (what the origin did).
    PhotonMap,
    /// Jensen's two passes: direct light by shadow rays, caustics from the caustic map, indirect light from
    /// the global map through final gathering.
    FinalGather,
    /// Stochastic progressive photon mapping (Hachisuka & Jensen 2009): passes of fresh photons with a
    /// shrinking per-pixel radius; consistent, it converges to the path tracer's answer.
    Progressive,
}

impl Integrator {
    /// Every integrator, in the order the documentation lists them.
    pub const ALL: [Integrator; 5] =
        [Integrator::Path, Integrator::Direct, Integrator::PhotonMap, Integrator::FinalGather, Integrator::Progressive];

    /// The name used in scene files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Path => "path",
            Integrator::Direct => "direct",
            Integrator::PhotonMap => "photon-map",
            Integrator::FinalGather => "final-gather",
            Integrator::Progressive => "progressive",
        }
    }

    /// Whether this method needs photon maps built before rendering.
    pub fn needs_photon_maps(self) -> bool {
        matches!(self, Integrator::PhotonMap | Integrator::FinalGather)
    }
}

impl std::fmt::Display for Integrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Integrator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|i| i.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|i| i.name()).collect();
            format!("unknown integrator `{s}`: expected one of {}", names.join(", "))
        })
    }
}

/// How photons are gathered for a radiance estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GatherMode {
    /// The `k` nearest photons, within `radius`.
    #[default]
    KNearest,
    /// Every photon within `radius`.
    Radius,
}

fn default_global() -> u32 {
    200_000
}
fn default_caustic() -> u32 {
    200_000
}
fn default_k() -> u32 {
    100
}
fn default_kernel() -> crate::photon_map::Kernel {
    crate::photon_map::Kernel::Epanechnikov
}
fn default_final_gather_rays() -> u32 {
    32
}
fn default_passes() -> u32 {
    32
}
fn default_pass_photons() -> u32 {
    100_000
}
fn default_alpha() -> f32 {
    2.0 / 3.0
}

/// Photon-mapping settings: the `[render.photons]` table. Only the photon methods read it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotonSettings {
    /// Photon paths emitted for the global map; default 200,000.
    #[serde(default = "default_global")]
    pub global: u32,
    /// Photon paths emitted for the caustic map (built only for `final-gather` on scenes with mirror or
    /// glass); default 200,000.
    #[serde(default = "default_caustic")]
    pub caustic: u32,
    /// `k-nearest` (default) or `radius`.
    #[serde(default)]
    pub gather: GatherMode,
    /// Photons per k-nearest estimate (≥ 2); default 100.
    #[serde(default = "default_k")]
    pub k: u32,
    /// Fixed gather radius, and the largest k-nearest radius, in scene units; default 2% of the diagonal of
    /// the scene's bounding box. Progressive photon mapping starts from it.
    #[serde(default)]
    pub radius: Option<f32>,
    /// Density-estimation kernel: `box`, `cone`, `epanechnikov` (default), `gaussian`, `linear`, `quadratic`.
    #[serde(default = "default_kernel")]
    pub kernel: crate::photon_map::Kernel,
    /// Disc filter: ignore photons farther from the tangent plane than this fraction of the radius (against
    /// light leaking round corners and through thin walls); default off.
    #[serde(default)]
    pub disc: Option<f32>,
    /// Use only photons stored on the object that was hit (the origin's filter); default false.
    #[serde(default)]
    pub same_object: bool,
    /// Final-gather rays per camera hit (`final-gather`); default 32.
    #[serde(default = "default_final_gather_rays")]
    pub final_gather_rays: u32,
    /// Passes of progressive photon mapping; default 32.
    #[serde(default = "default_passes")]
    pub passes: u32,
    /// Photon paths per progressive pass; default 100,000.
    #[serde(default = "default_pass_photons")]
    pub pass_photons: u32,
    /// Progressive radius reduction α in (0, 1); default 2/3.
    #[serde(default = "default_alpha")]
    pub alpha: f32,
}

impl Default for PhotonSettings {
    fn default() -> Self {
        Self {
            global: default_global(),
            caustic: default_caustic(),
            gather: GatherMode::KNearest,
            k: default_k(),
            radius: None,
            kernel: default_kernel(),
            disc: None,
            same_object: false,
            final_gather_rays: default_final_gather_rays(),
            passes: default_passes(),
            pass_photons: default_pass_photons(),
            alpha: default_alpha(),
        }
    }
}

fn default_spp() -> u32 {
    16
}
fn default_seed() -> u64 {
    1
}
fn default_max_depth() -> u32 {
    16
}

/// Render settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Samples per pixel (≥ 1); default 16.
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Seed of every random stream; default 1.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Longest path in bounces (≥ 1); default 16. Russian roulette ends most paths sooner.
    #[serde(default = "default_max_depth")]
    pub max_depth: u32,
    /// The integrator; default `"path"`.
    #[serde(default)]
    pub integrator: Integrator,
    /// Exposure in stops applied before tone mapping to 8-bit images; default 0.
    #[serde(default)]
    pub exposure: f32,
    /// Photon-mapping settings.
    #[serde(default)]
    pub photons: PhotonSettings,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            spp: default_spp(),
            seed: default_seed(),
            max_depth: default_max_depth(),
            integrator: Integrator::Path,
            exposure: 0.0,
            photons: PhotonSettings::default(),
        }
    }
}

/// Scale of a mesh: one factor or one per axis. In the scene file: a number or `[x, y, z]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Scale {
    /// The same factor on every axis.
    Uniform(f32),
    /// One factor per axis.
    PerAxis(Vec3),
}

impl Default for Scale {
    fn default() -> Self {
        Scale::Uniform(1.0)
    }
}

// By hand rather than `#[serde(untagged)]`, whose error ("data did not match any variant") says nothing of
// what was expected.
impl<'de> Deserialize<'de> for Scale {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ScaleVisitor)
    }
}

/// Reads a number or an `[x, y, z]` array.
struct ScaleVisitor;

impl<'de> serde::de::Visitor<'de> for ScaleVisitor {
    type Value = Scale;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a number or an [x, y, z] array")
    }

    fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Scale, E> {
        Ok(Scale::Uniform(v as f32))
    }

    fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Scale, E> {
        Ok(Scale::Uniform(v as f32))
    }

    fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Scale, E> {
        Ok(Scale::Uniform(v as f32))
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Scale, A::Error> {
        let mut v = [0.0f32; 3];
        for (i, x) in v.iter_mut().enumerate() {
            *x = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
        }
        if seq.next_element::<serde::de::IgnoredAny>()?.is_some() {
            return Err(serde::de::Error::invalid_length(4, &self));
        }
        Ok(Scale::PerAxis(Vec3::from_array(v)))
    }
}

impl Scale {
    /// Per-axis factors.
    pub fn to_vec3(self) -> Vec3 {
        match self {
            Scale::Uniform(s) => Vec3::splat(s),
            Scale::PerAxis(v) => v,
        }
    }
}

/// Object-to-world transform of a mesh: scale, then rotate (degrees about x, then y, then z), then translate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    /// Translation; default 0.
    #[serde(default)]
    pub translate: Vec3,
    /// Rotation in degrees about x, y and z, applied in that order; default 0.
    #[serde(default)]
    pub rotate: Vec3,
    /// Scale; default 1.
    #[serde(default)]
    pub scale: Scale,
}

impl Transform {
    /// The matrix `world_from_object`.
    pub fn matrix(&self) -> glam::Affine3A {
        let r = self.rotate * (std::f32::consts::PI / 180.0);
        let rot = glam::Quat::from_euler(glam::EulerRot::ZYX, r.z, r.y, r.x);
        glam::Affine3A::from_scale_rotation_translation(self.scale.to_vec3(), rot, self.translate)
    }
}

/// Emission that turns a surface into a diffuse area light.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Emission {
    /// Emitted radiance (W·sr⁻¹·m⁻²) per channel.
    pub radiance: Vec3,
    /// Emit from both sides; default false (only towards the surface normal).
    #[serde(default)]
    pub two_sided: bool,
}

/// A surface in the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Object {
    /// A sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius (> 0).
        radius: f32,
        /// Material name.
        material: String,
        /// Area light emission, if any.
        #[serde(default)]
        emission: Option<Emission>,
    },
    /// An infinite plane through `point` facing `normal`.
    Plane {
        /// A point on the plane.
        point: Vec3,
        /// Normal (need not be unit length).
        normal: Vec3,
        /// Material name.
        material: String,
    },
    /// A rectangle: either `center`, `normal`, `tangent`, `width`, `height` (the width runs along the tangent),
    /// or `corner` with edges `u` and `v` (a parallelogram whose normal is `u × v`).
    Rect {
        /// Centre (with `normal`, `tangent`, `width`, `height`).
        #[serde(default)]
        center: Option<Vec3>,
        /// Facing direction.
        #[serde(default)]
        normal: Option<Vec3>,
        /// Direction of the width; default: any direction perpendicular to the normal.
        #[serde(default)]
        tangent: Option<Vec3>,
        /// Extent along the tangent.
        #[serde(default)]
        width: Option<f32>,
        /// Extent along `normal × tangent`.
        #[serde(default)]
        height: Option<f32>,
        /// A corner (with `u` and `v`).
        #[serde(default)]
        corner: Option<Vec3>,
        /// First edge from the corner.
        #[serde(default)]
        u: Option<Vec3>,
        /// Second edge from the corner.
        #[serde(default)]
        v: Option<Vec3>,
        /// Material name.
        material: String,
        /// Area light emission, if any.
        #[serde(default)]
        emission: Option<Emission>,
    },
    /// A triangle; its normal is `(p1 − p0) × (p2 − p0)`.
    Triangle {
        /// The three vertices.
        vertices: [Vec3; 3],
        /// Material name.
        material: String,
        /// Area light emission, if any.
        #[serde(default)]
        emission: Option<Emission>,
    },
    /// A Wavefront OBJ mesh.
    Mesh {
        /// Path of the .obj file, relative to the scene file.
        file: PathBuf,
        /// Placement in the world.
        #[serde(default)]
        transform: Transform,
        /// Material name (the OBJ's own materials are ignored).
        material: String,
        /// Area light emission, if any.
        #[serde(default)]
        emission: Option<Emission>,
    },
}

impl Object {
    /// The material name.
    pub fn material(&self) -> &str {
        match self {
            Object::Sphere { material, .. }
            | Object::Plane { material, .. }
            | Object::Rect { material, .. }
            | Object::Triangle { material, .. }
            | Object::Mesh { material, .. } => material,
        }
    }
}

/// A point light, given by its radiant intensity or its total power.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum LightSpec {
    /// An isotropic point light. Give exactly one of `intensity` (W/sr) and `power` (W, = 4π·intensity).
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity per channel (W/sr).
        #[serde(default)]
        intensity: Option<Vec3>,
        /// Total emitted power per channel (W).
        #[serde(default)]
        power: Option<Vec3>,
    },
}

/// Why a scene could not be loaded. Every variant names the file, and the line or the field.
///
/// The message of every variant is complete: it includes its cause (the I/O error, the mesh's `file:line`), so
/// `source()` is `None` and a chain printer (`anyhow`'s `{:#}`) does not repeat the cause.
#[derive(Debug)]
pub enum SceneError {
    /// The file could not be read.
    Io {
        /// The scene file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
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
        /// The field, e.g. `objects[3].radius`.
        field: String,
        /// What was expected.
        message: String,
    },
    /// A mesh could not be loaded.
    Mesh {
        /// The scene file.
        path: PathBuf,
        /// The field that names the mesh.
        field: String,
        /// The cause.
        source: crate::mesh::MeshError,
    },
}

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SceneError::Io { path, source } => {
                write!(f, "{}: cannot read the scene file: {source}", path.display())
            }
            SceneError::Parse { path, message } => write!(f, "{}: {}", path.display(), message.trim_end()),
            SceneError::Invalid { path, field, message } => write!(f, "{}: {field}: {message}", path.display()),
            SceneError::Mesh { path, field, source } => write!(f, "{}: {field}: {source}", path.display()),
        }
    }
}

impl std::error::Error for SceneError {}

impl Scene {
    /// Reads, parses and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io { path: path.into(), source })?;
        Self::parse(&text, path)
    }

    /// Parses and validates scene text; `path` names the file in errors and gives the base folder.
    pub fn parse(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let mut scene: Scene =
            toml::from_str(text).map_err(|e| SceneError::Parse { path: path.into(), message: e.to_string() })?;
        scene.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        scene.validate().map_err(|(field, message)| SceneError::Invalid { path: path.into(), field, message })?;
        Ok(scene)
    }

    /// Reads a scene file and applies overrides `KEY=VALUE` before validation, where `KEY` is a dotted path
    /// into the file's tables (`render.spp`, `render.photons.kernel`, `camera.width`) and `VALUE` is a TOML
    /// value (`64`, `"box"`, `true`, `[1.0, 0.0, 0.0]`); a bare word is taken as a string.
    pub fn load_with(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        if overrides.is_empty() {
            return Self::load(path);
        }
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io { path: path.into(), source })?;
        let parse_err = |message: String| SceneError::Parse { path: path.into(), message };
        let mut table: toml::Table = toml::from_str(&text).map_err(|e| parse_err(e.to_string()))?;
        for o in overrides {
            let invalid = |message: String| SceneError::Invalid { path: path.into(), field: o.clone(), message };
            let (key, value) =
                o.split_once('=').ok_or_else(|| invalid("expected KEY=VALUE, e.g. render.spp=64".into()))?;
            let value = value.trim();
            let value = toml::from_str::<toml::Table>(&format!("v = {value}"))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .unwrap_or_else(|| toml::Value::String(value.to_string()));
            let keys: Vec<&str> = key.trim().split('.').collect();
            let (last, parents) = keys.split_last().ok_or_else(|| invalid("empty key".into()))?;
            let mut t = &mut table;
            for k in parents {
                let entry = t.entry(k.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
                t = entry.as_table_mut().ok_or_else(|| invalid(format!("`{k}` is not a table")))?;
            }
            t.insert(last.to_string(), value);
        }
        let mut scene: Scene = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| parse_err(format!("after --set: {}", e.message())))?;
        scene.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        scene.validate().map_err(|(field, message)| SceneError::Invalid { path: path.into(), field, message })?;
        Ok(scene)
    }

    /// Checks every value the types cannot: ranges, finiteness, names that must exist.
    fn validate(&self) -> Result<(), (String, String)> {
        let c = &self.camera;
        finite3("camera.eye", c.eye)?;
        finite3("camera.look_at", c.look_at)?;
        nonzero3("camera.up", c.up)?;
        let view = c.look_at - c.eye;
        if !view.is_finite() || view.length() == 0.0 {
            return Err(("camera.look_at".into(), "must differ from camera.eye".into()));
        }
        // Relative, so that a nearly parallel `up` is caught whatever the scene's scale.
        if c.up.cross(view).length() <= 1e-6 * c.up.length() * view.length() {
            return Err(("camera.up".into(), "must not be parallel to the viewing direction".into()));
        }
        if !(c.fov > 0.0 && c.fov < 180.0) {
            return Err(("camera.fov".into(), format!("expected degrees in (0, 180), found {}", c.fov)));
        }
        for (name, v) in [("camera.width", c.width), ("camera.height", c.height)] {
            if v == 0 || v > 65_536 {
                return Err((name.into(), format!("expected a pixel count in 1..=65536, found {v}")));
            }
        }
        positive_or_zero("camera.aperture", c.aperture)?;
        if let Some(f) = c.focus_distance {
            positive("camera.focus_distance", f)?;
        }
        let r = &self.render;
        if r.spp == 0 {
            return Err(("render.spp".into(), "expected at least 1 sample per pixel".into()));
        }
        if r.max_depth == 0 {
            return Err(("render.max_depth".into(), "expected at least 1 bounce".into()));
        }
        let ph = &r.photons;
        let pf = |s: &str| format!("render.photons.{s}");
        if ph.global == 0 {
            return Err((pf("global"), "expected at least 1 photon path".into()));
        }
        if ph.k < 2 {
            return Err((pf("k"), format!("expected at least 2 photons, found {}", ph.k)));
        }
        if let Some(radius) = ph.radius {
            positive(&pf("radius"), radius)?;
        }
        if let Some(disc) = ph.disc {
            positive(&pf("disc"), disc)?;
        }
        if !(ph.alpha > 0.0 && ph.alpha < 1.0) {
            return Err((pf("alpha"), format!("expected a number in (0, 1), found {}", ph.alpha)));
        }
        for (name, v) in
            [("passes", ph.passes), ("pass_photons", ph.pass_photons), ("final_gather_rays", ph.final_gather_rays)]
        {
            if v == 0 {
                return Err((pf(name), "expected at least 1".into()));
            }
        }
        if !r.exposure.is_finite() {
            return Err(("render.exposure".into(), "expected a finite number of stops".into()));
        }
        for (name, m) in &self.materials {
            m.validate().map_err(|msg| (format!("materials.{name}"), msg))?;
        }
        for (i, o) in self.objects.iter().enumerate() {
            let f = |s: &str| format!("objects[{i}].{s}");
            if !self.materials.contains_key(o.material()) {
                let known: Vec<&str> = self.materials.keys().map(String::as_str).collect();
                return Err((
                    f("material"),
                    format!("no material named `{}` (defined: {})", o.material(), known.join(", ")),
                ));
            }
            let emission = match o {
                Object::Sphere { center, radius, emission, .. } => {
                    finite3(&f("center"), *center)?;
                    positive(&f("radius"), *radius)?;
                    emission
                }
                Object::Plane { point, normal, .. } => {
                    finite3(&f("point"), *point)?;
                    nonzero3(&f("normal"), *normal)?;
                    &None
                }
                Object::Rect { emission, .. } => {
                    o.rect().map_err(|(field, msg)| (f(&field), msg))?;
                    emission
                }
                Object::Triangle { vertices, emission, .. } => {
                    for (k, v) in vertices.iter().enumerate() {
                        finite3(&f(&format!("vertices[{k}]")), *v)?;
                    }
                    // A triangle without area can never be hit: as a light it would silently emit nothing.
                    let [p0, p1, p2] = *vertices;
                    if (p1 - p0).cross(p2 - p0).length() == 0.0 {
                        return Err((f("vertices"), "the vertices are collinear: the triangle has no area".into()));
                    }
                    emission
                }
                Object::Mesh { transform, emission, .. } => {
                    finite3(&f("transform.translate"), transform.translate)?;
                    finite3(&f("transform.rotate"), transform.rotate)?;
                    let s = transform.scale.to_vec3();
                    if !s.is_finite() || s.x == 0.0 || s.y == 0.0 || s.z == 0.0 {
                        return Err((f("transform.scale"), format!("expected finite non-zero factors, found {s}")));
                    }
                    emission
                }
            };
            if let Some(e) = emission {
                let v = e.radiance;
                if !v.is_finite() || v.min_element() < 0.0 {
                    return Err((f("emission.radiance"), format!("expected finite non-negative radiance, found {v}")));
                }
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            let f = |s: &str| format!("lights[{i}].{s}");
            match l {
                LightSpec::Point { position, intensity, power } => {
                    finite3(&f("position"), *position)?;
                    let (name, v) = match (intensity, power) {
                        (Some(i), None) => ("intensity", *i),
                        (None, Some(p)) => ("power", *p),
                        _ => return Err((f("intensity"), "give exactly one of `intensity` and `power`".into())),
                    };
                    if !v.is_finite() || v.min_element() < 0.0 {
                        return Err((f(name), format!("expected finite non-negative values, found {v}")));
                    }
                }
            }
        }
        Ok(())
    }
}

impl Object {
    /// The rectangle this object describes, from either of its two forms; errors name the field.
    pub fn rect(&self) -> Result<crate::shapes::Rect, (String, String)> {
        let Object::Rect { center, normal, tangent, width, height, corner, u, v, .. } = self else {
            return Err(("type".into(), "not a rectangle".into()));
        };
        match (center, corner) {
            (Some(c), None) => {
                if u.is_some() || v.is_some() {
                    let field = if u.is_some() { "u" } else { "v" };
                    return Err((field.into(), "`u` and `v` go with `corner`, not with `center`".into()));
                }
                finite3("center", *c)?;
                let n = normal.ok_or(("normal".into(), "a rectangle with `center` needs `normal`".to_string()))?;
                nonzero3("normal", n)?;
                let t = match tangent {
                    Some(t) => {
                        nonzero3("tangent", *t)?;
                        if t.cross(n).length() <= 1e-6 * t.length() * n.length() {
                            return Err(("tangent".into(), "must not be parallel to the normal".into()));
                        }
                        *t
                    }
                    None => crate::math::Frame::from_normal(glam::Vec3A::from(n.normalize())).s.into(),
                };
                let w = width.ok_or(("width".into(), "a rectangle with `center` needs `width`".to_string()))?;
                let h = height.ok_or(("height".into(), "a rectangle with `center` needs `height`".to_string()))?;
                positive("width", w)?;
                positive("height", h)?;
                Ok(crate::shapes::Rect::from_center(*c, n, t, w, h))
            }
            (None, Some(c)) => {
                if normal.is_some() || tangent.is_some() || width.is_some() || height.is_some() {
                    return Err((
                        "corner".into(),
                        "use either `corner`, `u`, `v` or `center`, `normal`, `tangent`, `width`, `height`".into(),
                    ));
                }
                finite3("corner", *c)?;
                let u = u.ok_or(("u".into(), "a rectangle with `corner` needs edges `u` and `v`".to_string()))?;
                let v = v.ok_or(("v".into(), "a rectangle with `corner` needs edges `u` and `v`".to_string()))?;
                finite3("u", u)?;
                finite3("v", v)?;
                if u.cross(v).length() == 0.0 {
                    return Err(("v".into(), "the edges `u` and `v` must not be parallel or zero".into()));
                }
                Ok(crate::shapes::Rect { corner: *c, u, v })
            }
            (Some(_), Some(_)) => Err(("corner".into(), "give `center` or `corner`, not both".into())),
            (None, None) => Err(("center".into(), "a rectangle needs `center` (or `corner`)".into())),
        }
    }
}

fn finite3(field: &str, v: Vec3) -> Result<(), (String, String)> {
    if v.is_finite() { Ok(()) } else { Err((field.into(), format!("expected finite numbers, found {v}"))) }
}

fn nonzero3(field: &str, v: Vec3) -> Result<(), (String, String)> {
    finite3(field, v)?;
    if v.length() > 0.0 { Ok(()) } else { Err((field.into(), "expected a non-zero vector".into())) }
}

fn positive(field: &str, x: f32) -> Result<(), (String, String)> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err((field.into(), format!("expected a positive number, found {x}")))
    }
}

fn positive_or_zero(field: &str, x: f32) -> Result<(), (String, String)> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err((field.into(), format!("expected a non-negative number, found {x}")))
    }
}
