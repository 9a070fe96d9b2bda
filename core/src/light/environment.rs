//! The environment's image: the equirectangular map between directions and image coordinates, and the
//! piecewise-constant 2D distribution that samples directions in proportion to the image's radiance
//! (pbrt-v3 §14.2.4, "Infinite area lights"; pbrt-v4 §12.5.2).
//!
//! ```toml
//! [[lights]]
//! type = "environment"
//! image = "sky.exr"     # or radiance = [0.5, 0.6, 0.8] for a constant one
//! scale = 1.0
//! rotate = 90.0         # degrees about +y
//! ```
//! Image column `u` and row `v` (both in [0, 1], `v` from the top) hold the radiance arriving from the direction
//! at polar angle `θ = π·v` from +y and azimuth `φ = π·(2u − 1)`, measured from −z towards +x: the image's
//! centre is the horizon towards −z, its top row the zenith. Each texel is constant over its patch of the
//! sphere, and the distribution samples texel `(i, j)` with probability proportional to its luminance times
//! `sin θ` (its solid angle), so the density of a direction is `p(u, v) / (2π² sin θ)`.

use crate::Rgb;
use crate::material::texture::{ColorSpace, TexelImage};
use crate::math::{fmath, luminance};
use glam::{Vec2, Vec3A};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

/// The direction of image point `uv` in the environment's own frame (before its rotation).
#[inline]
pub fn direction(uv: Vec2) -> Vec3A {
    let theta = PI * uv.y;
    let phi = PI * (2.0 * uv.x - 1.0);
    let (sin_t, cos_t) = (fmath::sin(theta), fmath::cos(theta));
    Vec3A::new(sin_t * fmath::sin(phi), cos_t, -sin_t * fmath::cos(phi))
}

/// The image point of unit direction `d` in the environment's own frame, and `sin θ` there.
#[inline]
pub fn image_point(d: Vec3A) -> (Vec2, f32) {
    let theta = fmath::acos(d.y.clamp(-1.0, 1.0));
    let phi = fmath::atan2(d.x, -d.z);
    let u = 0.5 * (phi / PI + 1.0);
    (Vec2::new(u.clamp(0.0, 1.0), (theta / PI).clamp(0.0, 1.0)), (1.0 - d.y * d.y).max(0.0).sqrt())
}

/// The texel of image point `uv` (nearest, clamped at the edges): the patch the distribution samples as one.
#[inline]
fn texel_of(uv: Vec2, width: u32, height: u32) -> (u32, u32) {
    let i = ((uv.x * width as f32) as u32).min(width - 1);
    let j = ((uv.y * height as f32) as u32).min(height - 1);
    (i, j)
}

/// The radiance of the image at `uv` (the texel's value; PNG and JPEG values decoded from sRGB).
#[inline]
pub fn radiance(image: &TexelImage, uv: Vec2) -> Rgb {
    let (i, j) = texel_of(uv, image.width, image.height);
    image.texel(i, j, ColorSpace::Srgb)
}

/// A piecewise-constant density on `[0, 1)`, `n` equal pieces: the pieces' values and cumulative sums.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Pieces {
    /// Cumulative sums of the values over their total, `cdf[0] = 0`, `cdf[n] = 1` (`n + 1` entries).
    cdf: Vec<f32>,
    /// The values' mean over `[0, 1)` (their sum over `n`).
    integral: f32,
}

impl Pieces {
    /// The density of values `f` (each ≥ 0); uniform if they are all zero.
    fn new(f: &[f32]) -> Self {
        let n = f.len().max(1);
        let total: f64 = f.iter().map(|&x| f64::from(x)).sum();
        let mut acc = 0.0f64;
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0);
        for (k, &x) in f.iter().enumerate() {
            acc += f64::from(x);
            cdf.push(if total > 0.0 { (acc / total) as f32 } else { (k + 1) as f32 / n as f32 });
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Self { cdf, integral: (total / n as f64) as f32 }
    }

    /// Pieces.
    fn len(&self) -> usize {
        self.cdf.len() - 1
    }

    /// The probability of piece `k`.
    #[inline]
    fn mass(&self, k: usize) -> f32 {
        match (self.cdf.get(k), self.cdf.get(k + 1)) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }

    /// A point of `[0, 1)` for uniform `u` and its piece (inverting the cumulative sums).
    #[inline]
    fn sample(&self, u: f32) -> (f32, usize) {
        let n = self.len();
        let k = self.cdf.partition_point(|&c| c <= u).saturating_sub(1).min(n - 1);
        let mass = self.mass(k);
        let within = if mass > 0.0 { ((u - self.cdf[k]) / mass).clamp(0.0, 1.0) } else { 0.5 };
        (((k as f32 + within) / n as f32).min(1.0 - f32::EPSILON), k)
    }
}

/// The sampling distribution of an environment image: rows by their total, then columns within the row
/// (pbrt-v3's `Distribution2D`), over luminance × `sin θ`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkyDistribution {
    /// One density over the columns of each row.
    rows: Vec<Pieces>,
    /// The density over the rows.
    marginal: Pieces,
    /// The image's size in texels.
    width: u32,
    height: u32,
}

impl SkyDistribution {
    /// The distribution of `image`'s luminance (its radiance times `scale` does not change it).
    pub fn new(image: &TexelImage) -> Self {
        let (w, h) = (image.width, image.height);
        let rows: Vec<Pieces> = (0..h)
            .map(|j| {
                let sin_theta = fmath::sin(PI * (j as f32 + 0.5) / h as f32);
                let f: Vec<f32> =
                    (0..w).map(|i| luminance(image.texel(i, j, ColorSpace::Srgb)).max(0.0) * sin_theta).collect();
                Pieces::new(&f)
            })
            .collect();
        let marginal = Pieces::new(&rows.iter().map(|r| r.integral).collect::<Vec<_>>());
        Self { rows, marginal, width: w, height: h }
    }

    /// Whether the distribution was made for an image of `width × height` with every table of its length (a
    /// scene blob's is checked against its image).
    pub fn fits(&self, width: u32, height: u32) -> bool {
        self.width == width
            && self.height == height
            && self.marginal.len() == height as usize
            && self.rows.len() == height as usize
            && self.rows.iter().all(|r| r.len() == width as usize)
    }

    /// The mean over the sphere of `image`'s radiance, `∫L dω / 4π` per channel, each texel weighted by its
    /// solid angle (for the light's power).
    pub fn mean_radiance(image: &TexelImage) -> Rgb {
        let (w, h) = (image.width, image.height);
        let mut sum = [0.0f64; 3];
        for j in 0..h {
            let sin_theta = f64::from(fmath::sin(PI * (j as f32 + 0.5) / h as f32));
            for i in 0..w {
                for (s, c) in sum.iter_mut().zip(image.texel(i, j, ColorSpace::Srgb).to_array()) {
                    *s += f64::from(c) * sin_theta;
                }
            }
        }
        // Each texel spans (2π/w)·(π/h)·sin θ of solid angle.
        let texel = 2.0 * std::f64::consts::PI * std::f64::consts::PI / (f64::from(w) * f64::from(h));
        let k = texel / (4.0 * std::f64::consts::PI);
        Rgb::new((sum[0] * k) as f32, (sum[1] * k) as f32, (sum[2] * k) as f32)
    }

    /// An image point sampled in proportion to luminance × `sin θ`, for uniform `u2`, and its density over the
    /// unit square.
    pub fn sample(&self, u2: Vec2) -> (Vec2, f32) {
        let (v, j) = self.marginal.sample(u2.y);
        let Some(row) = self.rows.get(j) else { return (Vec2::ZERO, 0.0) };
        let (u, i) = row.sample(u2.x);
        let uv = Vec2::new(u, v);
        (uv, self.pdf_texel(i, j))
    }

    /// The density over the unit square of image point `uv`.
    pub fn pdf(&self, uv: Vec2) -> f32 {
        let (i, j) = texel_of(uv, self.width, self.height);
        self.pdf_texel(i as usize, j as usize)
    }

    /// The density over the unit square inside texel `(i, j)`: its probability times the number of texels.
    fn pdf_texel(&self, i: usize, j: usize) -> f32 {
        let Some(row) = self.rows.get(j) else { return 0.0 };
        row.mass(i) * self.marginal.mass(j) * (self.width as f32 * self.height as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::texture::Texels;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> TexelImage {
        let f = &f;
        let texels = (0..h).flat_map(|j| (0..w).flat_map(move |i| [f(i, j); 3])).collect::<Vec<_>>();
        TexelImage { width: w, height: h, channels: 3, texels: Texels::F32(texels) }
    }

    #[test]
    fn directions_and_image_points_invert() {
        for k in 0..200 {
            let uv = Vec2::new((k as f32 * 0.618_034).fract(), (k as f32 * 0.381_966 + 0.01).fract().max(0.01));
            let d = direction(uv);
            assert!((d.length() - 1.0).abs() < 1e-5);
            let (back, sin_t) = image_point(d);
            // u = 0 and u = 1 are the same azimuth.
            let du = (back.x - uv.x).abs();
            assert!(du.min(1.0 - du) < 1e-4 && (back.y - uv.y).abs() < 1e-4, "{uv} → {d} → {back}");
            assert!((sin_t - fmath::sin(PI * uv.y)).abs() < 2e-4, "{uv}: {sin_t}");
        }
        // The centre looks towards −z on the horizon, the top row at the zenith.
        assert!((direction(Vec2::new(0.5, 0.5)) - Vec3A::new(0.0, 0.0, -1.0)).length() < 1e-6);
        assert!((direction(Vec2::new(0.3, 0.0)) - Vec3A::Y).length() < 1e-6);
        assert!((direction(Vec2::new(0.75, 0.5)) - Vec3A::X).length() < 1e-6);
    }

    #[test]
    fn the_density_integrates_to_one_and_matches_the_samples() {
        // A bright spot, a dim band and black texels.
        let img = image(16, 8, |i, j| {
            if (i, j) == (3, 2) {
                50.0
            } else if j == 5 {
                1.0
            } else {
                0.0
            }
        });
        let dist = SkyDistribution::new(&img);
        assert!(dist.fits(16, 8));
        let mut total = 0.0f64;
        for j in 0..8 {
            for i in 0..16 {
                let uv = Vec2::new((i as f32 + 0.5) / 16.0, (j as f32 + 0.5) / 8.0);
                total += f64::from(dist.pdf(uv)) / 128.0;
            }
        }
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        // Samples land only where the image is bright, with the density the pdf gives.
        let mut hits = [0u32; 128];
        let n = 64 * 64;
        for a in 0..64 {
            for b in 0..64 {
                let u2 = Vec2::new((a as f32 + 0.5) / 64.0, (b as f32 + 0.5) / 64.0);
                let (uv, pdf) = dist.sample(u2);
                assert!(pdf > 0.0 && pdf == dist.pdf(uv), "{uv} {pdf} {}", dist.pdf(uv));
                let (i, j) = texel_of(uv, 16, 8);
                hits[(j * 16 + i) as usize] += 1;
            }
        }
        for j in 0..8 {
            for i in 0..16 {
                let uv = Vec2::new((i as f32 + 0.5) / 16.0, (j as f32 + 0.5) / 8.0);
                let expected = dist.pdf(uv) / 128.0 * n as f32;
                let got = hits[(j * 16 + i) as usize] as f32;
                assert!((got - expected).abs() <= 1.0 + 0.02 * expected, "texel ({i}, {j}): {got} vs {expected}");
            }
        }
    }

    #[test]
    fn a_constant_image_has_its_value_as_mean_radiance() {
        let img = image(64, 32, |_, _| 2.0);
        let m = SkyDistribution::mean_radiance(&img);
        // The midpoint rule over sin θ: exact to O(1/h²).
        assert!((m.x - 2.0).abs() < 2e-3, "{m}");
    }
}
