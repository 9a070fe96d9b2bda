//! Renders that are measured: the method a reference is rendered with ([`choose_reference`]), and a render on the
//! workers timed, with the error it estimates of itself ([`render_timed`]). `reference` uses both; the sweep
//! (`photon-sweep`, in `tools/sweep/`) times each of its renders with [`render_timed`].

use anyhow::Result;
use photon_core::image_io::Image;
use photon_core::light::Light;
use photon_core::material::Material;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::scene::Scene;
use std::path::Path;
use std::time::Instant;

/// The method a reference is rendered with, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReferenceChoice {
    /// `path` or `progressive`.
    pub integrator: Method,
    /// One sentence for the user.
    pub reason: String,
}

/// The path tracer, unless the scene has a delta light (point, spot or directional) and a mirror or glass
/// material: light from a point through a delta surface onto a diffuse one (a point-light caustic) is a path
/// that a camera path can only complete by hitting the point, which has probability zero, so the path tracer
/// converges to an image without the caustic. Progressive photon mapping is consistent for those paths.
pub fn choose_reference(prep: &Prepared) -> ReferenceChoice {
    if has_delta_caustics(prep) {
        ReferenceChoice {
            integrator: Method::Progressive,
            reason: "the scene has a point, spot or directional light and a mirror or glass material: the caustics it casts are paths \
                     a path tracer can never complete, so progressive photon mapping (consistent) renders the \
                     reference"
                .into(),
        }
    } else {
        let point = prep.lights.lights.iter().any(Light::is_delta);
        let why = if point { "no mirror or glass material" } else { "no point, spot or directional light" };
        ReferenceChoice {
            integrator: Method::Path,
            reason: format!(
                "{why}: every light path can be found from the camera, so the unbiased path tracer renders the reference"
            ),
        }
    }
}

/// Whether the scene has a point, spot or directional light and a mirror or glass material: the caustics that
/// light casts through them are paths a camera path completes only by hitting the point, with probability zero
/// (so the path tracer never renders them).
pub fn has_delta_caustics(prep: &Prepared) -> bool {
    prep.lights.lights.iter().any(Light::is_delta) && prep.materials.iter().any(Material::has_specular)
}

/// An image and the wall time it took.
#[derive(Clone, Debug)]
pub struct Timed {
    /// The linear image.
    pub image: Image,
    /// Seconds to prepare (meshes, BVH, photon maps).
    pub prepare_s: f64,
    /// Seconds to render the pixels.
    pub render_s: f64,
    /// The relative MSE the render estimated of itself without a reference ([`crate::farm::bounded`]): every method
    /// but `photon-map` and `final-gather`.
    pub estimated_rel_mse: Option<f64>,
}

/// Prepares `scene` here (no prepared-blob cache: its time is part of the method's cost) and renders it on the
/// workers at `addrs`, as `render` does. The render time runs from the first connection to the last strip, so it
/// includes shipping the blobs (workers that already hold them are sent nothing).
///
/// Every method but `photon-map` and `final-gather` renders its samples (passes) in rounds of whole-image blocks
/// that estimate their own error ([`crate::farm::bounded`]); the image is the same, bit for bit, as in strips.
pub async fn render_timed(
    scene: &Scene,
    scene_path: &Path,
    addrs: &[crate::fleet::session::WorkerAddr],
    mut options: crate::farm::Options,
) -> Result<Timed> {
    let t0 = Instant::now();
    let prep = Prepared::new(scene, scene_path)?.with_photon_maps(scene_path)?;
    let (width, height) = (prep.camera.width, prep.camera.height);
    let (scene_blob, photons, frame) = (prep.encode_scene()?, prep.encode_photons()?, prep.encode_frame()?);
    let textures = prep.encode_textures()?;
    let mut job = crate::job::Job::new(scene_blob, photons, textures, frame, (width, height), &prep.settings);
    let r = &prep.settings;
    // The methods whose error more units lower estimate it; vcm's merge radius shrinks with α as progressive
    // photon mapping's gather radius does (both biased), bdpt, lt and the path tracer are unbiased.
    let estimated =
        r.integrator.error_falls_with_units().then(|| (r.units(), r.integrator.bias_alpha(r.photons.alpha)));
    if let Some((passes, bias_alpha)) = estimated {
        job.passes = Some(passes.max(1));
        let passes = Some(passes.max(1));
        options.bound = Some(crate::farm::bounded::Bound {
            deadline: None,
            target_error: None,
            bias_alpha,
            passes,
            estimate: true,
        });
    }
    drop(prep);
    let prepare_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let outcome = crate::farm::render(&job, addrs, options).await?;
    let render_s = t1.elapsed().as_secs_f64();
    // A render in rounds that stopped short (no worker left, a signal) must not pass for its budget.
    if let (Some(b), Some((passes, _))) = (&outcome.bounded, estimated)
        && (b.reason != crate::farm::bounded::StopReason::Cap || b.passes != passes.max(1))
    {
        anyhow::bail!("the render stopped {} after {} of its {} passes (samples)", b.reason, b.passes, passes.max(1));
    }
    let estimated_rel_mse = outcome.bounded.and_then(|b| b.rel_mse_estimate);
    Ok(Timed { image: Image { width, height, pixels: outcome.pixels }, prepare_s, render_s, estimated_rel_mse })
}
