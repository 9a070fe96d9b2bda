//! The limits a scene's values are checked against (`validate`), and the image-side check that the frame of a
//! job on a worker shares.

use crate::error::FieldError;

/// The largest image side in pixels. Memory, not this limit, usually decides what renders: a job is also
/// checked against the machine's memory ([`crate::prepare::budget`]).
pub const MAX_IMAGE_SIDE: u32 = 65_536;

/// The most photons one k-nearest estimate gathers (`render.photons.k`): every render thread keeps a buffer
/// of k candidates, and beyond a few thousand the estimate blurs more than it gains.
pub const MAX_K: u32 = 100_000;

/// The most passes of progressive photon mapping (`render.photons.passes`): each pass keeps a slot for its
/// shared photon map.
pub const MAX_PASSES: u32 = 1_000_000;

/// An image side in pixels, `1..=MAX_IMAGE_SIDE`.
pub(crate) fn image_side(field: &str, v: u32) -> Result<(), FieldError> {
    if v == 0 || v > MAX_IMAGE_SIDE {
        return Err(FieldError::new(field, format!("expected a pixel count in 1..={MAX_IMAGE_SIDE}, found {v}")));
    }
    Ok(())
}

/// The largest camera coordinate in absolute value, in scene units.
pub const MAX_CAMERA_COORDINATE: f32 = 1e18;
