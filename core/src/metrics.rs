//! Error metrics of a linear image against a reference, for measuring speed against accuracy.
//!
//! Every metric runs over the three channels of every pixel (`n = 3 × width × height` values), with `x` a value
//! of the image, `r` the reference's value at the same place and `ε` = [`EPSILON`]:
//!
//! - RMSE: `sqrt(Σ (x − r)² / n)`, in the image's units (radiance).
//! - relative MSE: `Σ (x − r)² / (r² + ε) / n`. Dividing by `r²` weighs an error by how visible it is against
//!   the local brightness; `ε` stops black reference values (shadows, the open front of a box) from turning a
//!   tiny absolute error into a huge relative one and dominating the mean.
//! - mean absolute relative error (MARE): `Σ |x − r| / (|r| + ε) / n`, the same idea to the first power.
//! - bias over a pixel rectangle (the whole image by default): `mean(x − r)`, and relative bias
//!   `mean(x) / mean(r) − 1`, which is undefined (`None`) when the reference is black there.
//!
//! `ε = 0.01`. Published relMSE evaluations of Monte Carlo renderers use an `ε` between `10⁻³` and `10⁻²`;
//! we take the larger, so a black reference value weighs a squared error at most `1 / ε = 100` times, while
//! above about `r = 0.1` the denominator is dominated by `r²`.
//!
//! A value that is not finite (NaN or infinite) in either image is an error ([`MetricsError::NonFinite`]),
//! not skipped: a renderer that produces NaNs has a bug that no noise level describes, and skipping the pixels
//! would report a method as accurate exactly when it is broken. The error says how many pixels are affected
//! and where the first one is.
//!
//! Sums run in `f64` in pixel order, so the result is the same on every machine and thread count.

use crate::image_io::Image;
use crate::math::fmath;
use std::fmt;

/// The `ε` of the relative metrics, in the image's units (see the module documentation for the choice).
pub const EPSILON: f64 = 0.01;

/// A rectangle of pixels `[x0, x1) × [y0, y1)`: `x1` and `y1` are exclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    /// First column.
    pub x0: u32,
    /// First row (row 0 is the top of the image).
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl Region {
    /// The whole of a `width × height` image.
    pub fn full(width: u32, height: u32) -> Region {
        Region { x0: 0, y0: 0, x1: width, y1: height }
    }

    /// Whether the region holds at least one pixel and lies inside a `width × height` image.
    pub fn fits(&self, width: u32, height: u32) -> bool {
        self.x0 < self.x1 && self.y0 < self.y1 && self.x1 <= width && self.y1 <= height
    }

    /// Pixels in the region.
    pub fn pixel_count(&self) -> u64 {
        u64::from(self.x1.saturating_sub(self.x0)) * u64::from(self.y1.saturating_sub(self.y0))
    }
}

impl fmt::Display for Region {
    /// `X0,Y0,X1,Y1`, the form the command line reads.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{}", self.x0, self.y0, self.x1, self.y1)
    }
}

/// Why two images could not be compared.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MetricsError {
    /// The image and the reference differ in size.
    #[error("the image is {width}x{height} but the reference is {ref_width}x{ref_height}")]
    SizeMismatch {
        /// Width of the image.
        width: u32,
        /// Height of the image.
        height: u32,
        /// Width of the reference.
        ref_width: u32,
        /// Height of the reference.
        ref_height: u32,
    },
    /// The region is empty or reaches outside the image.
    #[error("region {region} (X0,Y0,X1,Y1, X1 and Y1 exclusive) is empty or outside the {width}x{height} image")]
    BadRegion {
        /// The region asked for.
        region: Region,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// An image's pixel buffer does not hold `3 × width × height` floats.
    #[error("the {which} has {len} floats for {width}x{height} RGB pixels (expected 3 per pixel)")]
    Malformed {
        /// `"image"` or `"reference"`.
        which: &'static str,
        /// Floats in the buffer.
        len: usize,
        /// Claimed width.
        width: u32,
        /// Claimed height.
        height: u32,
    },
    /// Some pixels hold NaN or an infinity.
    #[error("{count} pixel(s) of the {which} are not finite (NaN or infinite); the first is at ({x}, {y})")]
    NonFinite {
        /// `"image"` or `"reference"`.
        which: &'static str,
        /// Pixels with at least one non-finite channel.
        count: u64,
        /// Column of the first such pixel.
        x: u32,
        /// Row of the first such pixel.
        y: u32,
    },
}

/// The errors of an image against a reference; see the module documentation for the definitions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    /// Root-mean-square error over all channels of all pixels.
    pub rmse: f64,
    /// Mean over channels of `(x − r)² / (r² + ε)`.
    pub rel_mse: f64,
    /// Mean over channels of `|x − r| / (|r| + ε)`.
    pub mare: f64,
    /// The rectangle the bias is measured over.
    pub region: Region,
    /// `mean(x − r)` over the channels of the region's pixels.
    pub bias: f64,
    /// `mean(x) / mean(r) − 1` over the region; `None` when the reference's mean there is zero.
    pub rel_bias: Option<f64>,
    /// The largest `|x − r|` over all channels of all pixels.
    pub max_abs: f64,
    /// Channel values whose bits differ (0: the images are identical).
    pub differing: u64,
}

impl Metrics {
    /// One line of `key=value` pairs for scripts: `rmse=… rel_mse=… mare=… bias=… rel_bias=… region=…
    /// max_abs=… differing=…`. Values are
    /// printed in full (shortest round-trip form); an undefined relative bias is `nan`.
    pub fn key_values(&self) -> String {
        let rel_bias = self.rel_bias.map_or_else(|| "nan".to_owned(), |b| b.to_string());
        format!(
            "rmse={} rel_mse={} mare={} bias={} rel_bias={} region={} max_abs={} differing={}",
            self.rmse, self.rel_mse, self.mare, self.bias, rel_bias, self.region, self.max_abs, self.differing
        )
    }
}

/// Checks that the two images have the same size and that each buffer matches its size.
fn check_shapes(a: &Image, reference: &Image) -> Result<(), MetricsError> {
    if (a.width, a.height) != (reference.width, reference.height) {
        return Err(MetricsError::SizeMismatch {
            width: a.width,
            height: a.height,
            ref_width: reference.width,
            ref_height: reference.height,
        });
    }
    for (img, which) in [(a, "image"), (reference, "reference")] {
        if img.pixels.len() as u64 != 3 * u64::from(img.width) * u64::from(img.height) {
            return Err(MetricsError::Malformed { which, len: img.pixels.len(), width: img.width, height: img.height });
        }
    }
    Ok(())
}

/// Checks that every value is finite (the buffer already matches the size).
fn check_finite(img: &Image, which: &'static str) -> Result<(), MetricsError> {
    let width = img.width;
    let mut bad = img.pixels.chunks_exact(3).enumerate().filter(|(_, p)| !p.iter().all(|v| v.is_finite()));
    if let Some((first, _)) = bad.next() {
        let count = 1 + bad.count() as u64;
        let (x, y) = ((first % width as usize) as u32, (first / width as usize) as u32);
        return Err(MetricsError::NonFinite { which, count, x, y });
    }
    Ok(())
}

/// Checks sizes and values of both images.
fn check_pair(a: &Image, reference: &Image) -> Result<(), MetricsError> {
    check_shapes(a, reference)?;
    check_finite(a, "image")?;
    check_finite(reference, "reference")
}

/// The metrics of `a` against `reference`; the bias is measured over `region` (default: the whole image).
pub fn compare(a: &Image, reference: &Image, region: Option<Region>) -> Result<Metrics, MetricsError> {
    check_pair(a, reference)?;
    let (width, height) = (a.width, a.height);
    let region = region.unwrap_or(Region::full(width, height));
    if !region.fits(width, height) {
        return Err(MetricsError::BadRegion { region, width, height });
    }
    let (mut sq, mut rel_sq, mut abs_rel) = (0.0_f64, 0.0_f64, 0.0_f64);
    let (mut sum_x, mut sum_r) = (0.0_f64, 0.0_f64);
    let (mut max_abs, mut differing) = (0.0_f64, 0_u64);
    for (i, (pa, pr)) in a.pixels.chunks_exact(3).zip(reference.pixels.chunks_exact(3)).enumerate() {
        let (x, y) = ((i % width as usize) as u32, (i / width as usize) as u32);
        let inside = (region.x0..region.x1).contains(&x) && (region.y0..region.y1).contains(&y);
        for (&va, &vr) in pa.iter().zip(pr) {
            let (v, r) = (f64::from(va), f64::from(vr));
            let d = v - r;
            sq += d * d;
            rel_sq += d * d / (r * r + EPSILON);
            abs_rel += d.abs() / (r.abs() + EPSILON);
            max_abs = max_abs.max(d.abs());
            differing += u64::from(va.to_bits() != vr.to_bits());
            if inside {
                sum_x += v;
                sum_r += r;
            }
        }
    }
    let n = a.pixels.len() as f64;
    let n_region = 3.0 * region.pixel_count() as f64;
    Ok(Metrics {
        rmse: (sq / n).sqrt(),
        rel_mse: rel_sq / n,
        mare: abs_rel / n,
        region,
        // Sum the region's values separately and subtract once: mean(x − r) = mean(x) − mean(r).
        bias: (sum_x - sum_r) / n_region,
        rel_bias: (sum_r != 0.0).then(|| sum_x / sum_r - 1.0),
        max_abs,
        differing,
    })
}

/// Matplotlib's "inferno" colour map sampled at nine evenly spaced points, as 8-bit sRGB: perceptually uniform,
/// dark at 0 and bright at 1, and readable in greyscale.
const INFERNO: [[f32; 3]; 9] = [
    [0.0, 0.0, 4.0],
    [31.0, 12.0, 72.0],
    [85.0, 15.0, 109.0],
    [136.0, 34.0, 106.0],
    [186.0, 54.0, 85.0],
    [227.0, 89.0, 51.0],
    [249.0, 140.0, 10.0],
    [249.0, 201.0, 50.0],
    [252.0, 255.0, 164.0],
];

/// The linear value of an sRGB-encoded value in [0, 1] (the inverse of [`crate::image_io::srgb_encode`]).
fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 { v / 12.92 } else { fmath::powf((v + 0.055) / 1.055, 2.4) }
}

/// The ramp colour of `t` (clamped to [0, 1]; NaN counts as 1), in linear RGB. The ramp is interpolated in
/// sRGB and then decoded, so an 8-bit output (which encodes to sRGB) shows the table's colours.
pub fn ramp(t: f32) -> [f32; 3] {
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let s = t * (INFERNO.len() - 1) as f32;
    let i = (s as usize).min(INFERNO.len() - 2);
    let f = s - i as f32;
    let (c0, c1) = (INFERNO[i], INFERNO[i + 1]);
    std::array::from_fn(|k| srgb_decode((c0[k] + f * (c1[k] - c0[k])) / 255.0))
}

/// A false-colour map of per-pixel relative error, `mean over channels of |x − r| / (|r| + ε)`, through
/// [`ramp`]: 0 is black-purple, 1 or more is pale yellow. Linear RGB; write it as PNG with exposure 0.
/// Non-finite pixels of `a` are not an error here: they show at the top of the ramp.
pub fn error_image(a: &Image, reference: &Image) -> Result<Image, MetricsError> {
    check_shapes(a, reference)?;
    let mut out = Image::new(a.width, a.height);
    let pixels = out.pixels.chunks_exact_mut(3).zip(a.pixels.chunks_exact(3).zip(reference.pixels.chunks_exact(3)));
    for (o, (pa, pr)) in pixels {
        let e: f64 = pa
            .iter()
            .zip(pr)
            .map(|(&x, &r)| (f64::from(x) - f64::from(r)).abs() / (f64::from(r).abs() + EPSILON))
            .sum::<f64>()
            / 3.0;
        o.copy_from_slice(&ramp(e as f32));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(width: u32, height: u32, pixels: &[f32]) -> Image {
        Image { width, height, pixels: pixels.to_vec() }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1.0)
    }

    #[test]
    fn identical_images_have_zero_error() {
        let r = img(2, 1, &[0.0, 0.5, 2.0, 1.0, 0.25, 0.0]);
        let m = compare(&r, &r, None).unwrap();
        assert_eq!((m.rmse, m.rel_mse, m.mare, m.bias), (0.0, 0.0, 0.0, 0.0));
        assert_eq!(m.rel_bias, Some(0.0));
        assert_eq!(m.region, Region::full(2, 1));
        assert_eq!((m.max_abs, m.differing), (0.0, 0));
        assert_eq!(m.key_values(), "rmse=0 rel_mse=0 mare=0 bias=0 rel_bias=0 region=0,0,2,1 max_abs=0 differing=0");
    }

    /// One ulp in one channel and a larger error in another: both counted, the larger one is the largest.
    #[test]
    fn largest_difference_and_differing_values() {
        let r = img(2, 1, &[0.5, 1.0, 0.0, 2.0, 0.25, 0.0]);
        let mut a = r.clone();
        a.pixels[1] = f32::from_bits(1.0f32.to_bits() + 1);
        a.pixels[3] = 2.125;
        let m = compare(&a, &r, None).unwrap();
        assert_eq!((m.max_abs, m.differing), (0.125, 2));
        // -0.0 and 0.0 are equal values with different bits: a difference of zero, counted as differing.
        a.pixels = r.pixels.clone();
        a.pixels[2] = -0.0;
        let m = compare(&a, &r, None).unwrap();
        assert_eq!((m.max_abs, m.differing), (0.0, 1));
    }

    #[test]
    fn constant_offset_by_hand() {
        // Reference pixels 0.25 and 1.0 (grey), image = reference + 0.5: every difference is exactly 0.5.
        let r = img(2, 1, &[0.25, 0.25, 0.25, 1.0, 1.0, 1.0]);
        let a = img(2, 1, &[0.75, 0.75, 0.75, 1.5, 1.5, 1.5]);
        let m = compare(&a, &r, None).unwrap();
        assert_eq!(m.rmse, 0.5);
        assert_eq!(m.bias, 0.5);
        // (0.25 / (0.0625 + 0.01) + 0.25 / (1 + 0.01)) / 2 = (3.448275862… + 0.247524752…) / 2
        assert!(close(m.rel_mse, (0.25 / 0.0725 + 0.25 / 1.01) / 2.0), "{}", m.rel_mse);
        assert!(close(m.rel_mse, 1.847_900_307_272_106), "{}", m.rel_mse);
        // (0.5 / 0.26 + 0.5 / 1.01) / 2 = (1.923076923… + 0.495049504…) / 2
        assert!(close(m.mare, 1.209_063_214_013_709), "{}", m.mare);
        // mean(a) = 1.125, mean(r) = 0.625: 1.125 / 0.625 − 1 = 0.8
        assert!(close(m.rel_bias.unwrap(), 0.8));
    }

    #[test]
    fn black_reference_is_softened_by_epsilon() {
        // One black reference channel, error 0.1: relMSE term 0.01 / (0 + 0.01) = 1, MARE term 0.1 / 0.01 = 10.
        let r = img(1, 1, &[0.0, 0.0, 0.0]);
        let a = img(1, 1, &[0.1, 0.0, 0.0]);
        let m = compare(&a, &r, None).unwrap();
        let d = f64::from(0.1_f32);
        assert!(close(m.rel_mse, d * d / 0.01 / 3.0), "{}", m.rel_mse);
        assert!(close(m.mare, d / 0.01 / 3.0), "{}", m.mare);
        assert!(close(m.rmse, (d * d / 3.0).sqrt()));
        assert_eq!(m.rel_bias, None, "relative bias is undefined on a black reference");
        assert!(m.key_values().contains("rel_bias=nan"));
    }

    #[test]
    fn region_selects_the_bias_pixels() {
        // 2×2; only pixel (1, 0) differs, by 1 in every channel.
        let r = img(2, 2, &[0.5; 12]);
        let mut a = r.clone();
        a.pixels[3..6].copy_from_slice(&[1.5, 1.5, 1.5]);
        let whole = compare(&a, &r, None).unwrap();
        assert_eq!(whole.bias, 0.25);
        assert_eq!(whole.rmse, 0.5);
        let one = compare(&a, &r, Some(Region { x0: 1, y0: 0, x1: 2, y1: 1 })).unwrap();
        assert_eq!(one.bias, 1.0);
        assert_eq!(one.rel_bias, Some(2.0));
        assert_eq!(one.rmse, whole.rmse, "RMSE is over the whole image whatever the region");
        let bottom = compare(&a, &r, Some(Region { x0: 0, y0: 1, x1: 2, y1: 2 })).unwrap();
        assert_eq!(bottom.bias, 0.0);
        let right = compare(&a, &r, Some(Region { x0: 1, y0: 0, x1: 2, y1: 2 })).unwrap();
        assert_eq!(right.bias, 0.5);
    }

    #[test]
    fn bad_regions_are_errors() {
        let r = img(2, 2, &[0.5; 12]);
        for region in [
            Region { x0: 0, y0: 0, x1: 3, y1: 1 },
            Region { x0: 0, y0: 1, x1: 2, y1: 3 },
            Region { x0: 1, y0: 0, x1: 1, y1: 2 },
            Region { x0: 2, y0: 0, x1: 1, y1: 2 },
        ] {
            let e = compare(&r, &r, Some(region)).unwrap_err();
            assert_eq!(e, MetricsError::BadRegion { region, width: 2, height: 2 });
            assert!(e.to_string().contains("2x2 image"), "{e}");
        }
    }

    #[test]
    fn size_mismatch_names_both_sizes() {
        let a = img(2, 1, &[0.0; 6]);
        let r = img(1, 2, &[0.0; 6]);
        let e = compare(&a, &r, None).unwrap_err();
        assert_eq!(e.to_string(), "the image is 2x1 but the reference is 1x2");
        assert!(matches!(error_image(&a, &r), Err(MetricsError::SizeMismatch { .. })));
        let short = img(2, 1, &[0.0; 5]);
        assert!(matches!(compare(&short, &a, None), Err(MetricsError::Malformed { which: "image", len: 5, .. })));
    }

    #[test]
    fn non_finite_values_are_counted_errors() {
        let r = img(3, 1, &[0.5; 9]);
        let mut a = r.clone();
        a.pixels[4] = f32::NAN;
        a.pixels[6] = f32::INFINITY;
        a.pixels[7] = f32::NAN;
        let e = compare(&a, &r, None).unwrap_err();
        assert_eq!(e, MetricsError::NonFinite { which: "image", count: 2, x: 1, y: 0 });
        assert!(e.to_string().starts_with("2 pixel(s) of the image are not finite"), "{e}");
        let e = compare(&r, &a, None).unwrap_err();
        assert!(matches!(e, MetricsError::NonFinite { which: "reference", count: 2, .. }));
    }

    #[test]
    fn error_image_maps_relative_error_through_the_ramp() {
        let r = img(3, 1, &[1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        // Errors: 0; 0.02 / 0.01 = 2 (clamped to 1); NaN (top of the ramp).
        let a = img(3, 1, &[1.0, 1.0, 1.0, 0.02, 0.02, 0.02, f32::NAN, 1.0, 1.0]);
        let e = error_image(&a, &r).unwrap();
        assert_eq!((e.width, e.height), (3, 1));
        let srgb = e.to_srgb8(0.0);
        assert_eq!(&srgb[0..3], &[0, 0, 4]);
        assert_eq!(&srgb[3..6], &[252, 255, 164]);
        assert_eq!(&srgb[6..9], &[252, 255, 164]);
        // Half-way along the ramp is its middle entry.
        let mid = Image { width: 1, height: 1, pixels: ramp(0.5).to_vec() };
        assert_eq!(mid.to_srgb8(0.0), vec![186, 54, 85]);
    }

    #[test]
    fn ramp_is_monotone_in_brightness() {
        let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let mut last = -1.0;
        for i in 0..=64 {
            let l = luma(ramp(i as f32 / 64.0));
            assert!(l > last, "ramp({}) is not brighter than the step before", i as f32 / 64.0);
            last = l;
        }
    }
}
