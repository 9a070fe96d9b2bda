//! The value types of a scene file: camera, render settings (method, photons), objects, lights, transforms.
//! Every field has a documented default; unknown fields are errors.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

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

pub use crate::method::{Method, UnknownMethod};

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
fn default_kernel() -> crate::photon::Kernel {
    crate::photon::Kernel::Epanechnikov
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
    /// Gather radius in participating media (scene units); default twice `radius`. Progressive photon mapping
    /// shrinks it pass by pass so that the volume `r³` follows the same sequence as the surfaces' `r²`.
    #[serde(default)]
    pub volume_radius: Option<f32>,
    /// First merging radius of `vcm` (scene units); default the width of one pixel at the focus distance
    /// (`Prepared::merge_radius`). It shrinks with `alpha` as progressive's radius does.
    #[serde(default)]
    pub merge_radius: Option<f32>,
    /// Density-estimation kernel: `box`, `cone`, `epanechnikov` (default), `gaussian`, `linear`, `quadratic`.
    #[serde(default = "default_kernel")]
    pub kernel: crate::photon::Kernel,
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
    /// The smoothest surface, as a perceptual roughness in [0, 1], on which the photon methods (`photon-map`,
    /// `final-gather`, `progressive`) store photons and estimate density; default 0.3. On a glossier lobe
    /// (a conductor or a Phong lobe without diffuse part whose width, as a Trowbridge–Reitz `α`, is below
    /// `min_roughness²`) a density estimate needs too many photons, so camera paths walk on through it by
    /// sampling it, as through a mirror, and photons that leave through it are caustic ones. Transmitting
    /// rough glass never stores photons. `vcm` merges at every non-delta vertex: its MIS weighs merging there.
    #[serde(default = "default_min_roughness")]
    pub min_roughness: f32,
}

fn default_min_roughness() -> f32 {
    0.3
}

impl Default for PhotonSettings {
    fn default() -> Self {
        Self {
            global: default_global(),
            caustic: default_caustic(),
            gather: GatherMode::KNearest,
            k: default_k(),
            radius: None,
            volume_radius: None,
            merge_radius: None,
            kernel: default_kernel(),
            disc: None,
            same_object: false,
            final_gather_rays: default_final_gather_rays(),
            passes: default_passes(),
            pass_photons: default_pass_photons(),
            alpha: default_alpha(),
            min_roughness: default_min_roughness(),
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
    pub integrator: Method,
    /// Exposure in stops applied before tone mapping to 8-bit images; default 0.
    #[serde(default)]
    pub exposure: f32,
    /// Photon-mapping settings.
    #[serde(default)]
    pub photons: PhotonSettings,
}

impl RenderSettings {
    /// The units of the whole job, at least 1: `spp` camera samples of each pixel, or `photons.passes` passes,
    /// as the method's unit says ([`Method::unit`]).
    pub fn units(&self) -> u32 {
        match self.integrator.unit() {
            crate::method::Unit::Samples => self.spp.max(1),
            crate::method::Unit::Passes => self.photons.passes.max(1),
        }
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            spp: default_spp(),
            seed: default_seed(),
            max_depth: default_max_depth(),
            integrator: Method::Path,
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
        /// The participating medium inside the sphere; default none (vacuum inside).
        #[serde(default)]
        interior: Option<MediumSpec>,
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
        /// Texture coordinates of the three vertices; default `[[0, 0], [1, 0], [0, 1]]`.
        #[serde(default)]
        uv: Option<[[f32; 2]; 3]>,
        /// Material name.
        material: String,
        /// Area light emission, if any.
        #[serde(default)]
        emission: Option<Emission>,
    },
    /// A Wavefront OBJ mesh.
    Mesh {
        /// Path of the mesh file (`.obj` or `.ply`), relative to the scene file.
        file: PathBuf,
        /// Placement in the world.
        #[serde(default)]
        transform: Transform,
        /// Material name (the OBJ's own materials are ignored).
        material: String,
        /// Area light emission, if any.
        #[serde(default)]
        emission: Option<Emission>,
        /// Smooth shading (default `true`): the file's normals, or normals computed within `crease_angle`;
        /// `false` shades every face with its geometric normal.
        #[serde(default = "default_smooth")]
        smooth: bool,
        /// Largest angle in degrees between two faces' normals across which computed normals are smoothed, in
        /// [0, 180]; default 30. Unused when the file has normals.
        #[serde(default = "default_crease_angle")]
        crease_angle: f32,
        /// Level of detail, in pixels (finite, ≥ 0); default 0.25: the mesh is simplified so that its surface moves
        /// by at most about `lod` times the width of one pixel's footprint at the mesh's nearest distance to the
        /// camera. `0` keeps every triangle. Off for emitting meshes and in scenes with mirror or glass
        /// materials ([`crate::prepare::lod`]).
        #[serde(default = "default_lod")]
        lod: f32,
        /// The participating medium inside the mesh, which must then be closed (every edge shared by exactly
        /// two faces); default none. A closed mesh without one is vacuum inside; an open mesh separates no
        /// media.
        #[serde(default)]
        interior: Option<MediumSpec>,
    },
    /// A glTF 2.0 file (`.gltf` with its buffers and images, or `.glb`): its default scene's meshes with their
    /// own materials, and its `KHR_lights_punctual` lights, placed by `transform` (after the file's node
    /// transforms). Its cameras are used only when the file is rendered directly. See
    /// [`crate::prepare::gltf`].
    Gltf {
        /// Path of the glTF file, relative to the scene file.
        file: PathBuf,
        /// Placement in the world, applied after the file's node hierarchy.
        #[serde(default)]
        transform: Transform,
    },
}

fn default_smooth() -> bool {
    true
}

fn default_lod() -> f32 {
    crate::geometry::lod::DEFAULT_LOD
}

fn default_crease_angle() -> f32 {
    crate::geometry::mesh::Normals::DEFAULT_CREASE_ANGLE
}

impl Object {
    /// The material name; `None` for a glTF object, whose materials come from its file.
    pub fn material(&self) -> Option<&str> {
        match self {
            Object::Sphere { material, .. }
            | Object::Plane { material, .. }
            | Object::Rect { material, .. }
            | Object::Triangle { material, .. }
            | Object::Mesh { material, .. } => Some(material),
            Object::Gltf { .. } => None,
        }
    }
}

/// A light that is not a surface: a point, spot or directional light, or the environment (area lights are
/// objects with `emission`).
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
    /// A spot light at `position` shining along `direction`: radiant intensity `intensity` (W/sr) within
    /// `inner_angle` of the axis, falling off smoothly (a smoothstep in the cosine, pbrt-v4 §12.1.1) to 0 at
    /// `outer_angle`. Give exactly one of `intensity` and `power` (W, = 2π·I·(1 − (cos inner + cos outer)/2)).
    Spot {
        /// Position.
        position: Vec3,
        /// The axis of the cone (need not be unit length).
        direction: Vec3,
        /// Radiant intensity on the axis per channel (W/sr).
        #[serde(default)]
        intensity: Option<Vec3>,
        /// Total emitted power per channel (W).
        #[serde(default)]
        power: Option<Vec3>,
        /// Half-angle in degrees within which the intensity is full, in [0, `outer_angle`]; default 0.
        #[serde(default)]
        inner_angle: f32,
        /// Half-angle in degrees of the cone outside which nothing is emitted, in (0, 90]; default 45.
        #[serde(default = "default_outer_angle")]
        outer_angle: f32,
    },
    /// A directional light (the sun seen as a delta direction): light travelling along `direction`, giving
    /// irradiance `irradiance` (W/m²) on a surface facing it.
    Directional {
        /// The direction the light travels (need not be unit length).
        direction: Vec3,
        /// Irradiance per channel on a surface perpendicular to the light (W/m²).
        irradiance: Vec3,
    },
    /// Light arriving from infinitely far in every direction: a constant `radiance`, or an equirectangular
    /// `image` (EXR, HDR, PNG, ...) times `scale`. Image column `u` and row `v` (from the top) are the direction
    /// at polar angle `θ = π·v` from +y and azimuth `φ = π·(2u − 1)` from −z towards +x, turned by `rotate`
    /// degrees about +y. At most one per scene; not in scenes with participating media.
    Environment {
        /// Constant radiance per channel (W·sr⁻¹·m⁻²), without `image`.
        #[serde(default)]
        radiance: Option<Vec3>,
        /// An equirectangular image, relative to the scene file, without `radiance`.
        #[serde(default)]
        image: Option<PathBuf>,
        /// Multiplies the image's values (finite, ≥ 0); default 1.
        #[serde(default = "default_env_scale")]
        scale: f32,
        /// Rotation about +y in degrees; default 0.
        #[serde(default)]
        rotate: f32,
    },
}

fn default_outer_angle() -> f32 {
    45.0
}

fn default_env_scale() -> f32 {
    1.0
}

/// A homogeneous participating medium as a scene writes it: the global `[medium]` table or an object's
/// `interior`. Give the coefficients (`sigma_a`, `sigma_s`, each a number or `[r, g, b]` in 1/scene-unit,
/// default 0) or `density` (σt, 1/scene-unit) with `albedo` (σs/σt, default 1), not both; `g` is the
/// Henyey–Greenstein asymmetry in (−1, 1), default 0 (isotropic).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MediumSpec {
    /// Absorption coefficient σa per channel (1/scene-unit).
    #[serde(default)]
    pub sigma_a: Option<Scale>,
    /// Scattering coefficient σs per channel (1/scene-unit).
    #[serde(default)]
    pub sigma_s: Option<Scale>,
    /// Extinction σt (1/scene-unit), with `albedo`.
    #[serde(default)]
    pub density: Option<f32>,
    /// Single-scattering albedo σs/σt per channel in [0, 1], with `density`; default 1.
    #[serde(default)]
    pub albedo: Option<Scale>,
    /// Henyey–Greenstein asymmetry; default 0.
    #[serde(default)]
    pub g: f32,
}

impl MediumSpec {
    /// The medium's coefficients. Call after [`MediumSpec::check`].
    pub fn medium(&self) -> crate::medium::Medium {
        let v = |s: &Option<Scale>, d: f32| s.map_or(Vec3::splat(d), Scale::to_vec3);
        let (sigma_a, sigma_s) = match self.density {
            Some(density) => {
                let albedo = v(&self.albedo, 1.0);
                (density * (Vec3::ONE - albedo), density * albedo)
            }
            None => (v(&self.sigma_a, 0.0), v(&self.sigma_s, 0.0)),
        };
        crate::medium::Medium { sigma_a: sigma_a.into(), sigma_s: sigma_s.into(), g: self.g }
    }

    /// Checks the ranges; errors name the field relative to the table (`sigma_a`, `g`, ...).
    pub fn check(&self) -> Result<(), crate::error::FieldError> {
        use crate::error::FieldError;
        let coefficients = |name: &str, s: &Option<Scale>, max: f32, range: &str| -> Result<(), FieldError> {
            let Some(s) = s else { return Ok(()) };
            let v = s.to_vec3();
            if !(v.is_finite() && v.min_element() >= 0.0 && v.max_element() <= max) {
                return Err(FieldError::new(name, format!("expected {range} per channel, found {v}")));
            }
            Ok(())
        };
        use crate::medium::MAX_SIGMA;
        let sigma = "finite numbers ≥ 0 (1/scene-unit, at most 1e30)";
        coefficients("sigma_a", &self.sigma_a, MAX_SIGMA, sigma)?;
        coefficients("sigma_s", &self.sigma_s, MAX_SIGMA, sigma)?;
        coefficients("albedo", &self.albedo, 1.0, "numbers in [0, 1]")?;
        if let Some(d) = self.density {
            if !(d.is_finite() && (0.0..=MAX_SIGMA).contains(&d)) {
                return Err(FieldError::new("density", format!("expected a number in [0, {MAX_SIGMA:e}], found {d}")));
            }
            if self.sigma_a.is_some() || self.sigma_s.is_some() {
                return Err(FieldError::new(
                    "density",
                    "give either `density` (with `albedo`) or `sigma_a`/`sigma_s`, not both",
                ));
            }
        } else if self.albedo.is_some() {
            return Err(FieldError::new(
                "albedo",
                "`albedo` goes with `density`; with `sigma_a`/`sigma_s` leave it out",
            ));
        }
        if !(self.g.is_finite() && self.g > -1.0 && self.g < 1.0) {
            return Err(FieldError::new("g", format!("expected a number in (−1, 1), found {}", self.g)));
        }
        Ok(())
    }
}
