//! Cut-outs: a mesh whose texture's alpha says where its faces are (glTF 2.0 `alphaMode` MASK, specification
//! §3.9.4 "Alpha Coverage"). Where the alpha read at a hit's texture coordinates is below the cutoff, the face is
//! not there: closest-hit and any-hit queries pass through it, so every method sees the same holes (camera and
//! light paths, shadow rays, photons).
//!
//! The test is a pure function of the face and the hit's barycentrics, so hits stay independent of the tree.
//! The alpha is read as `crate::material::texture` reads images (texel centres at `(i + ½)/width`, `v` up,
//! repeat or clamp, nearest or bilinear), from texels of its own: the geometry sits below the materials.

use glam::Vec2;
use serde::{Deserialize, Serialize};

/// The alpha of a cut-out and the coverage below which its surface is absent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlphaMask {
    /// Width in texels (> 0).
    pub width: u32,
    /// Height in texels (> 0).
    pub height: u32,
    /// Alpha of each texel, row-major from the top row, as `a / 65535` in `[0, 1]` (linear: alpha is never
    /// sRGB-encoded).
    pub alpha: Vec<u16>,
    /// Tile the image outside `[0, 1]` (else extend its edge texels), as the colour texture the alpha belongs to.
    pub repeat: bool,
    /// Interpolate the four texels around a point (else take the texel under it), as that texture does.
    pub bilinear: bool,
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
        let (w, h) = (self.width, self.height);
        // A NaN coordinate (a degenerate hit) reads the corner, never out of bounds.
        let s = if uv.x.is_finite() { uv.x } else { 0.0 };
        let t = if uv.y.is_finite() { uv.y } else { 0.0 };
        let (x, y) = (s * w as f32, (1.0 - t) * h as f32);
        let texel = |i: f32, j: f32| {
            let at = self.fold(j, h) as usize * w as usize + self.fold(i, w) as usize;
            f32::from(self.alpha.get(at).copied().unwrap_or(0)) / 65535.0
        };
        let alpha = if self.bilinear {
            let (x, y) = (x - 0.5, y - 0.5);
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let lerp = |a: f32, b: f32, f: f32| a + (b - a) * f;
            let top = lerp(texel(x0, y0), texel(x0 + 1.0, y0), fx);
            let bottom = lerp(texel(x0, y0 + 1.0), texel(x0 + 1.0, y0 + 1.0), fx);
            lerp(top, bottom, fy)
        } else {
            texel(x.floor(), y.floor())
        };
        self.factor * alpha >= self.cutoff
    }

    /// A texel index for the continuous index `x` (already floored) of an axis of `n` texels.
    #[inline]
    fn fold(&self, x: f32, n: u32) -> u32 {
        let n_f = n as f32;
        let i = if self.repeat { x - (x / n_f).floor() * n_f } else { x.clamp(0.0, n_f - 1.0) };
        // Float rounding can land a repeat on n itself; huge coordinates saturate in the cast.
        (i as u32).min(n - 1)
    }

    /// Checks the sizes (both sides > 0, one value a texel), the factor and the cutoff (finite), saying what is
    /// wrong.
    ///
    /// # Errors
    /// A text naming the fault.
    pub fn check(&self) -> Result<(), String> {
        let want = u64::from(self.width) * u64::from(self.height);
        if self.width == 0 || self.height == 0 || self.alpha.len() as u64 != want {
            return Err(format!(
                "an alpha mask of {}×{} texels holds {} values: it needs one a texel, and at least one",
                self.width,
                self.height,
                self.alpha.len()
            ));
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

    #[test]
    fn the_surface_is_present_where_alpha_reaches_the_cutoff() {
        // Two texels side by side: alpha 0.2 on the left, 0.6 on the right (u = 0.25 and 0.75).
        let alpha = vec![13107, 39321];
        let mask = AlphaMask { width: 2, height: 1, alpha, repeat: false, bilinear: false, factor: 1.0, cutoff: 0.5 };
        assert!(!mask.covers(Vec2::new(0.25, 0.5)));
        assert!(mask.covers(Vec2::new(0.75, 0.5)));
        // Clamped: far outside, the edge texels.
        assert!(!mask.covers(Vec2::new(-3.0, 0.5)) && mask.covers(Vec2::new(7.0, 0.5)));
        // Repeated: u = 1.25 is u = 0.25 again.
        assert!(!AlphaMask { repeat: true, ..mask.clone() }.covers(Vec2::new(1.25, 0.5)));
        // Bilinear: halfway between the centres alpha is 0.4, below; at u = 0.7 it is 0.56, above.
        let bilinear = AlphaMask { bilinear: true, ..mask.clone() };
        assert!(!bilinear.covers(Vec2::new(0.5, 0.5)));
        assert!(bilinear.covers(Vec2::new(0.7, 0.5)));
        assert!(AlphaMask { cutoff: 0.2, ..mask.clone() }.covers(Vec2::new(0.25, 0.5)));
        // The factor multiplies: 0.8 · 0.6 = 0.48 is below 0.5.
        assert!(!AlphaMask { factor: 0.8, ..mask }.covers(Vec2::new(0.75, 0.5)));
    }

    #[test]
    fn a_mask_with_the_wrong_texel_count_or_a_nan_cutoff_is_refused() {
        let mask = AlphaMask {
            width: 2,
            height: 2,
            alpha: vec![0; 4],
            repeat: true,
            bilinear: true,
            factor: 1.0,
            cutoff: 0.5,
        };
        assert!(mask.check().is_ok());
        assert!(AlphaMask { alpha: vec![0; 3], ..mask.clone() }.check().is_err());
        assert!(AlphaMask { width: 0, alpha: vec![], ..mask.clone() }.check().is_err());
        assert!(AlphaMask { cutoff: f32::NAN, ..mask }.check().is_err());
    }
}
