//! # photon-core
//!
//! Everything about light and geometry for the photon renderer: the scene description, shapes and the BVH,
//! materials and their BSDFs, lights, the camera, the integrators, the strip renderer and image output.
//! It knows nothing of networks or async runtimes; everything a worker needs to render is one serialisable
//! [`prepare::Prepared`] value.
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
pub mod metrics;
pub mod photon;
pub mod prepare;
pub mod render;
pub mod scene;

/// Linear RGB radiance, power or reflectance.
pub type Rgb = glam::Vec3A;
