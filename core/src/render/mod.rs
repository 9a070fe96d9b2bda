//! Rendering: every unit of work, for every method, is a [`Block`] of units (camera samples or whole-image
//! passes, as the method's [`Unit`](crate::method::Unit) says) over some rows, and its result is the block's fixed-point pixel sums
//! ([`BlockSums`]). [`render_block`] is the one entry; the farm, the bounded renders and [`render_image`] all go
//! through it, and an image is its sums divided once ([`sums::SumAccumulator`]).
//!
//! | room | what it holds |
//! |---|---|
//! | [`sums`] | the fixed-point contract: `Block`, `BlockSums`, `to_fixed`, `fixed_mean`, `SumAccumulator` |
//! | [`radius`] | the shrinking radius of progressive's gathers and vcm's merges |
//! | [`samples`] | the sample driver and the one rows × pixels loop |
//! | [`progressive`] | progressive photon mapping's passes |
//! | [`vcm`] | vcm's, bdpt's and lt's passes |

pub mod progressive;
pub mod radius;
pub mod samples;
pub mod sums;
pub mod vcm;

pub use sums::{Block, BlockSums};

use crate::method::Technique;
use crate::prepare::Prepared;
use crate::run::{Guard, RunError};
use std::ops::Range;
use sums::{MAX_BLOCK_UNITS, SumAccumulator};

/// Renders `block`: each pixel channel's sum over the block's units of its fixed-point estimate, by the
/// technique of the job's method ([`crate::method::Method::technique`]). At most [`MAX_BLOCK_UNITS`] units
/// (more are cut off, as a caller that checked its input never asks for). `progress` gets the units finished
/// so far.
///
/// `guard` stops the render soon after its cancel flag is set (it is checked before every camera sample,
/// pixel, photon path and light subpath), and bounds the photons or light vertices that one pass stores.
///
/// # Errors
/// [`RunError::Cancelled`] once `guard.cancel` is set; [`RunError::Storage`] when a pass of progressive, vcm,
/// bdpt or lt would store more than `guard.storage_bytes`.
pub fn render_block(
    prep: &Prepared,
    block: &Block,
    progress: &(dyn Fn(u32) + Sync),
    guard: &Guard,
) -> Result<BlockSums, RunError> {
    let (rows, start) = (block.rows.clone(), block.units.start);
    let units = start..block.units.end.min(start.saturating_add(MAX_BLOCK_UNITS));
    match prep.settings.integrator.technique(prep.media.is_some(), prep.photons.is_some()) {
        Technique::Samples(estimator) => samples::render(prep, estimator, rows, units, progress, guard.cancel),
        Technique::PhotonPasses => progressive::render_passes(prep, rows, units, progress, guard),
        Technique::Subpaths(techniques) => vcm::render_passes(prep, techniques, rows, units, progress, guard),
    }
}

/// The units of the whole job ([`crate::scene::RenderSettings::units`]).
pub fn job_units(prep: &Prepared) -> u32 {
    prep.settings.units()
}

/// Rows of an image rendered on this machine: linear RGB radiance.
#[derive(Clone, Debug, PartialEq)]
pub struct Rendered {
    /// The rows rendered.
    pub rows: Range<u32>,
    /// `3 × width × rows.len()` floats, row-major, W·sr⁻¹·m⁻².
    pub pixels: Vec<f32>,
    /// Rays traced.
    pub rays: u64,
    /// Photon paths (or light subpaths) traced while rendering.
    pub photon_paths: u64,
}

/// Renders every unit of the job over rows `rows`, in blocks of at most [`MAX_BLOCK_UNITS`], and divides the
/// sums once: the pixels of a farm render, whatever its cut. `progress` gets the rows-equivalent done so far
/// (`rows.len()` at the end). Never cancelled and with no storage bound ([`Guard::unbounded`]): for tests and
/// tools of known size; the farm's workers render blocks under their own guard.
pub fn render_rows(prep: &Prepared, rows: Range<u32>, progress: &(dyn Fn(u32) + Sync)) -> Rendered {
    let total = job_units(prep);
    let width = prep.camera.width as usize;
    let mut acc = SumAccumulator::new(3 * width * rows.len(), total);
    let (mut rays, mut photon_paths) = (0, 0);
    let rows_n = rows.len() as u64;
    let unbounded = Guard::unbounded();
    let mut start = 0;
    while start < total {
        let end = start.saturating_add(MAX_BLOCK_UNITS).min(total);
        let block_progress = |n: u32| progress((u64::from(start + n) * rows_n / u64::from(total)) as u32);
        // Never cancelled and unbounded: it cannot fail.
        let block = render_block(prep, &Block { rows: rows.clone(), units: start..end }, &block_progress, &unbounded);
        let Ok(block) = block else { break };
        rays += block.rays;
        photon_paths += block.photon_paths;
        acc.add(&block.sums);
        start = end;
    }
    Rendered { rows, pixels: acc.image(), rays, photon_paths }
}

/// Renders the whole image on this machine ([`render_rows`] of every row).
pub fn render_image(prep: &Prepared, progress: &(dyn Fn(u32) + Sync)) -> Rendered {
    render_rows(prep, 0..prep.camera.height, progress)
}
