//! Deterministic, portable random streams.
//!
//! Every stream is a PCG32 generator (`rand_pcg::Pcg32`, whose output is specified bit for bit) seeded by a
//! SplitMix64 hash of the render seed and the identity of the work: a pixel sample `(x, y, sample)` or a photon
//! index. No stream depends on thread, strip or worker, so images and photon maps are reproducible.

use glam::Vec2;
use rand::RngExt;
use rand_pcg::Pcg32;

/// SplitMix64's finaliser: a bijective 64-bit mix with good avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Domains keep streams for different purposes apart even for equal indices.
#[derive(Clone, Copy, Debug)]
#[repr(u64)]
pub enum Domain {
    /// Camera samples of one pixel.
    Pixel = 1,
    /// One photon path.
    Photon = 2,
    /// One progressive photon-mapping pass.
    Pass = 3,
}

/// A stream of uniform samples.
#[derive(Clone, Debug)]
pub struct Sampler {
    rng: Pcg32,
}

impl Sampler {
    /// A stream identified by a domain and up to three indices under a seed.
    pub fn new(seed: u64, domain: Domain, a: u64, b: u64, c: u64) -> Self {
        let h = mix64(mix64(mix64(mix64(seed ^ (domain as u64).rotate_left(56)) ^ a) ^ b) ^ c);
        let stream = mix64(h ^ 0x5851_F42D_4C95_7F2D);
        Self { rng: Pcg32::new(h, stream) }
    }

    /// The stream of one pixel sample.
    pub fn for_pixel(seed: u64, x: u32, y: u32, sample: u32) -> Self {
        Self::new(seed, Domain::Pixel, u64::from(x), u64::from(y), u64::from(sample))
    }

    /// The stream of one photon path: photon `index` of pass `pass`.
    pub fn for_photon(seed: u64, pass: u64, index: u64) -> Self {
        Self::new(seed, Domain::Photon, pass, index, 0)
    }

    /// A uniform sample in `[0, 1)` with 24 random bits.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        self.rng.random::<f32>()
    }

    /// A pair of uniform samples.
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_f32();
        Vec2::new(x, self.next_f32())
    }

    /// A uniform 32-bit integer.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        self.rng.random::<u32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::for_pixel(7, 3, 4, 5);
                move |_| s.next_f32()
            })
            .collect();
        let b: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::for_pixel(7, 3, 4, 5);
                move |_| s.next_f32()
            })
            .collect();
        let c: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::for_pixel(7, 4, 3, 5);
                move |_| s.next_f32()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.iter().all(|&v| (0.0..1.0).contains(&v)));
    }

    #[test]
    fn samples_are_uniform() {
        let mut s = Sampler::for_photon(1, 0, 0);
        let n = 100_000;
        let mut bins = [0u32; 10];
        for _ in 0..n {
            bins[(s.next_f32() * 10.0) as usize] += 1;
        }
        for b in bins {
            assert!((f64::from(b) / f64::from(n) - 0.1).abs() < 0.005, "{bins:?}");
        }
    }
}
