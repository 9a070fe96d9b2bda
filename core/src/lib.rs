//! # photon-core
//!
//! Everything about light and geometry for the photon renderer: the scene description, shapes and the BVH,
//! materials and their BSDFs, lights, the camera, the integrators, the strip renderer and image output.
//! It knows nothing of networks or async runtimes; everything a worker needs to render is one serialisable
//! [`prepare::Prepared`] value.
//!
//! In the repository, `docs/SCENE.md` is the scene manual, `docs/ARCHITECTURE.md` the design, and
//! `docs/RESULTS.md` every measured number with the command that reproduces it.
//!
//! ## Example
//!
//! A point light of intensity 1 W/sr one metre above a Lambert plane of albedo 0.5, seen from straight above
//! through one pixel: the reflected radiance is `albedo / π · I / d²` (Pharr, Jakob & Humphreys, *Physically
//! Based Rendering*, 4th ed., §4.5 and §9.2).
//!
//! ```
//! use photon_core::prepare::Prepared;
//! use photon_core::scene::Scene;
//!
//! let toml = r#"
//! [camera]
//! eye = [0.0, 2.0, 0.0]
//! look_at = [0.0, 0.0, 0.0]
//! up = [0.0, 0.0, -1.0]
//! fov = 0.5
//! width = 1
//! height = 1
//!
//! [render]
//! integrator = "direct"
//! spp = 1
//!
//! [materials.grey]
//! type = "lambert"
//! albedo = 0.5
//!
//! [[objects]]
//! type = "plane"
//! point = [0.0, 0.0, 0.0]
//! normal = [0.0, 1.0, 0.0]
//! material = "grey"
//!
//! [[lights]]
//! type = "point"
//! position = [0.0, 1.0, 0.0]
//! intensity = [1.0, 1.0, 1.0]
//! "#;
//! let path = std::path::Path::new("example.toml"); // names the scene in errors; nothing is read
//! let scene = Scene::parse(toml, path)?;
//! let prep = Prepared::new(&scene, path)?;
//! let image = photon_core::render::render_image(&prep, &|_rows| {});
//! let radiance = image.pixels[0]; // W sr⁻¹ m⁻², red channel
//! assert!((radiance - 0.5 / std::f32::consts::PI).abs() < 1e-3 * radiance);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Vocabulary
//! - `wo`, `wi`: unit directions that point *away* from the surface (towards the viewer, towards the light).
//! - `n`: geometric normal; `ns`: shading normal. `p`: a point.
//! - `u`, `u2`: uniform samples in `[0, 1)` (a scalar, a pair).
//! - `beta`: path throughput; `phi`: flux in watts; `le`, `li`, `ld`: emitted, incident, direct radiance.
//! - `eta`: relative index of refraction (inside over outside).
//! - Colours are linear RGB in [`Rgb`] (a `Vec3A`); bulk storage uses `[f32; 3]`.
//! - Local shading frames have the normal on +z, so `cos θ = w.z`.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

// Layered in the order of the data flow; docs/ARCHITECTURE.md lists the layers (core/tests/module_layers.rs).
pub mod camera;
pub mod codec;
pub mod error;
pub mod geometry;
pub mod image_io;
pub mod input;
pub mod integrator;
pub mod light;
pub mod material;
pub mod math;
pub mod medium;
pub mod method;
pub mod metrics;
pub mod photon;
pub mod prepare;
pub mod render;
pub mod run;
pub mod scene;

/// Linear RGB radiance, power or reflectance.
pub type Rgb = glam::Vec3A;
