//! Cut-outs: a mesh whose texture's alpha says where its faces are (glTF 2.0 `alphaMode` MASK, specification
//! §3.9.4 "Alpha Coverage"). Where the alpha read at a hit's texture coordinates is below the cutoff, the face is
//! not there: closest-hit and any-hit queries pass through it, so every method sees the same holes (camera and
//! light paths, shadow rays, photons).
//!
//! The test is a pure function of the face and the hit's barycentrics, so hits stay independent of the tree.

use crate::material::texture::{ColorSpace, Filter, ImageRef, TexelImage, Wrap};
use glam::Vec2;
use serde::{Deserialize, Serialize};

/// The alpha of a cut-out and the coverage below which its surface is absent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlphaMask {
    /// One linear channel of alpha in `[0, 1]` (integer texels are `v / max`, never sRGB-decoded).
    pub alpha: TexelImage,
    /// Folding of texture coordinates outside `[0, 1]`, as the colour texture the alpha belongs to.
    pub wrap: Wrap,
    /// Reconstruction between texel centres, as that texture's.
    pub filter: Filter,
    /// What multiplies the texture's alpha: the base colour factor's alpha.
    pub factor: f32,
    /// The surface is present where `factor · alpha ≥ cutoff` (glTF's `alphaCutoff`).
    pub cutoff: f32,
}

impl AlphaMask {
    /// Whether the surface is present at texture coordinates `uv` (photon's `v`-up convention, see
    /// `crate::material::texture`).
    #[inline]
    pub fn covers(&self, uv: Vec2) -> bool {
        let image = ImageRef {
            file: std::path::PathBuf::new(),
            slot: 0,
            scale: Vec2::ONE,
            offset: Vec2::ZERO,
            wrap: self.wrap,
            filter: self.filter,
            colorspace: None,
        };
        self.factor * image.lookup(&self.alpha, uv, ColorSpace::Linear).x >= self.cutoff
    }

    /// Checks the image (sizes, one channel), the factor and the cutoff (finite), saying what is wrong.
    ///
    /// # Errors
    /// A text naming the fault.
    pub fn check(&self) -> Result<(), String> {
        self.alpha.check().map_err(|e| e.to_string())?;
        if self.alpha.channels != 1 {
            return Err(format!("an alpha mask has one channel, not {}", self.alpha.channels));
        }
        if !self.cutoff.is_finite() || !self.factor.is_finite() {
            return Err(format!("the alpha factor {} and cutoff {} must be finite", self.factor, self.cutoff));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::texture::Texels;

    #[test]
    fn the_surface_is_present_where_alpha_reaches_the_cutoff() {
        // Two texels side by side: alpha 0.2 on the left, 0.6 on the right (u = 0.25 and 0.75).
        let alpha = TexelImage { width: 2, height: 1, channels: 1, texels: Texels::U8(vec![51, 153]) };
        let mask = AlphaMask { alpha, wrap: Wrap::Clamp, filter: Filter::Nearest, factor: 1.0, cutoff: 0.5 };
        assert!(!mask.covers(Vec2::new(0.25, 0.5)));
        assert!(mask.covers(Vec2::new(0.75, 0.5)));
        // Bilinear: halfway between the centres alpha is 0.4, below; at u = 0.7 it is 0.56, above.
        let bilinear = AlphaMask { filter: Filter::Bilinear, ..mask.clone() };
        assert!(!bilinear.covers(Vec2::new(0.5, 0.5)));
        assert!(bilinear.covers(Vec2::new(0.7, 0.5)));
        assert!(AlphaMask { cutoff: 0.2, ..mask.clone() }.covers(Vec2::new(0.25, 0.5)));
        // The factor multiplies: 0.8 · 0.6 = 0.48 is below 0.5.
        assert!(!AlphaMask { factor: 0.8, ..mask }.covers(Vec2::new(0.75, 0.5)));
    }
}
