//! Helpers shared by the physics tests: random streams, directions, the materials under test, running means
//! with their standard errors and the chi-square distribution.
#![allow(dead_code)]

use glam::Vec3A;
use photon_core::Rgb;
use photon_core::material::bsdf::{Bsdf, Bxdf};
use photon_core::material::microfacet::ConductorFresnel;
use photon_core::math::fmath;
use photon_core::math::rng::{Domain, Sampler};

/// The random stream of one test case.
pub fn sampler(test: u64, case: u64) -> Sampler {
    Sampler::new(0x5EED_B5DF, Domain::Photon, test, case, 0)
}

/// The unit direction at polar angle `theta` from +z and azimuth `phi`.
pub fn dir(theta: f32, phi: f32) -> Vec3A {
    Vec3A::new(fmath::sin(theta) * fmath::cos(phi), fmath::sin(theta) * fmath::sin(phi), fmath::cos(theta))
}

/// A BSDF on a surface whose geometric and shading normals are both +z.
pub fn flat(bxdf: Bxdf) -> Bsdf {
    Bsdf::new(Vec3A::Z, Vec3A::Z, bxdf)
}

/// One BxDF of every kind, with colours that differ per channel so that channel mix-ups show.
pub fn every_kind() -> Vec<(&'static str, Bxdf)> {
    vec![
        ("lambert", Bxdf::Lambert { r: Rgb::new(0.9, 0.5, 0.1) }),
        ("phong n=1", Bxdf::Phong { kd: Rgb::new(0.5, 0.2, 0.0), ks: Rgb::new(0.5, 0.3, 0.9), exponent: 1.0 }),
        ("phong n=20", Bxdf::Phong { kd: Rgb::new(0.3, 0.1, 0.0), ks: Rgb::new(0.7, 0.5, 1.0), exponent: 20.0 }),
        ("phong n=300", Bxdf::Phong { kd: Rgb::new(0.0, 0.2, 0.1), ks: Rgb::new(1.0, 0.8, 0.5), exponent: 300.0 }),
        ("mirror", Bxdf::Mirror { r: Rgb::new(0.95, 0.6, 0.3) }),
        ("glass 1.5", Bxdf::Dielectric { eta: 1.5, tint: Rgb::new(1.0, 0.9, 0.7) }),
        ("glass 2.4", Bxdf::Dielectric { eta: 2.4, tint: Rgb::ONE }),
        ("mix", Bxdf::Mix { color: Rgb::new(0.8, 0.4, 0.2), diffuse: 0.3, specular: 0.2, transmission: 0.4, eta: 1.5 }),
        ("mix diffuse+glass", Bxdf::Mix { color: Rgb::ONE, diffuse: 0.5, specular: 0.0, transmission: 0.5, eta: 1.33 }),
        ("gold r=0.3", Bxdf::Conductor { fresnel: gold(), alpha: 0.09 }),
        ("schlick metal r=0.7", Bxdf::Conductor { fresnel: schlick(), alpha: 0.49 }),
        ("smooth metal", Bxdf::Conductor { fresnel: schlick(), alpha: 0.0 }),
        ("rough glass r=0.3", Bxdf::RoughDielectric { eta: 1.5, tint: Rgb::new(1.0, 0.9, 0.7), alpha: 0.09 }),
        ("rough glass 2.4 r=0.8", Bxdf::RoughDielectric { eta: 2.4, tint: Rgb::ONE, alpha: 0.64 }),
        ("gltf metal r=0.5", Bxdf::MetallicRoughness { base: Rgb::new(0.95, 0.64, 0.54), metallic: 1.0, alpha: 0.25 }),
        ("gltf plastic r=0.3", Bxdf::MetallicRoughness { base: Rgb::new(0.8, 0.2, 0.1), metallic: 0.0, alpha: 0.09 }),
        (
            "gltf half metal r=0.8",
            Bxdf::MetallicRoughness { base: Rgb::new(0.3, 0.9, 0.6), metallic: 0.5, alpha: 0.64 },
        ),
        ("gltf smooth plastic", Bxdf::MetallicRoughness { base: Rgb::new(0.2, 0.5, 0.9), metallic: 0.0, alpha: 0.0 }),
    ]
}

/// About gold's complex index of refraction, its measured spectrum reduced to three channels (red, green, blue).
pub fn gold() -> ConductorFresnel {
    ConductorFresnel::Complex { eta: Rgb::new(0.143, 0.374, 1.442), k: Rgb::new(3.983, 2.385, 1.603) }
}

/// glTF's metal: Schlick's Fresnel with a coloured reflectance at normal incidence.
pub fn schlick() -> ConductorFresnel {
    ConductorFresnel::Schlick { f0: Rgb::new(0.95, 0.64, 0.54) }
}

/// Whether a BxDF is a microfacet lobe, whose single-scattering albedo loses energy and whose value is a longer
/// chain of f32 operations than the other lobes'.
pub fn is_microfacet(b: &Bxdf) -> bool {
    match *b {
        Bxdf::Conductor { alpha, .. } | Bxdf::MetallicRoughness { alpha, .. } => alpha > 0.0,
        Bxdf::RoughDielectric { .. } => true,
        _ => false,
    }
}

/// Whether a BxDF lets light through the surface.
pub fn transmits(b: &Bxdf) -> bool {
    match *b {
        Bxdf::Dielectric { .. } | Bxdf::RoughDielectric { .. } => true,
        Bxdf::Mix { transmission, .. } => transmission > 0.0,
        Bxdf::Lambert { .. }
        | Bxdf::Phong { .. }
        | Bxdf::Mirror { .. }
        | Bxdf::Conductor { .. }
        | Bxdf::MetallicRoughness { .. } => false,
    }
}

/// Running mean and variance of an RGB quantity (Welford, in f64).
#[derive(Clone, Copy, Debug, Default)]
pub struct Mean {
    n: u64,
    mean: [f64; 3],
    m2: [f64; 3],
}

impl Mean {
    /// Adds one observation.
    pub fn add(&mut self, x: Rgb) {
        self.n += 1;
        for (c, &v) in x.to_array().iter().enumerate() {
            let v = f64::from(v);
            let d = v - self.mean[c];
            self.mean[c] += d / self.n as f64;
            self.m2[c] += d * (v - self.mean[c]);
        }
    }

    /// The mean per channel.
    pub fn mean(&self) -> [f64; 3] {
        self.mean
    }

    /// The standard error of the mean per channel.
    pub fn std_error(&self) -> [f64; 3] {
        let n = self.n as f64;
        self.m2.map(|m2| (m2 / (n - 1.0) / n).sqrt())
    }
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, n = 9; relative error below 1e-13).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularised upper incomplete gamma function Q(a, x) (Numerical Recipes §6.2: series below a + 1,
/// continued fraction above).
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let front = (-x + a * x.ln() - ln_gamma(a)).exp();
    if x < a + 1.0 {
        let (mut ap, mut sum, mut del) = (a, 1.0 / a, 1.0 / a);
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * front
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        front * h
    }
}

/// P(X ≥ chi2) for X chi-square distributed with `dof` degrees of freedom.
pub fn chi2_p_value(chi2: f64, dof: usize) -> f64 {
    gamma_q(0.5 * dof as f64, 0.5 * chi2)
}

/// Pearson's chi-square test of observed against expected counts, after pooling the cells whose expected
/// count is below 5 (smallest first) until each pooled cell expects at least 5. Returns (chi², dof, p-value).
/// Panics if a cell that expects nothing received more than a stray sample: that is a sampling bug, not noise.
pub fn chi2_test(observed: &[f64], expected: &[f64]) -> (f64, usize, f64) {
    let total: f64 = observed.iter().sum();
    for (o, e) in observed.iter().zip(expected) {
        assert!(!(*e <= 0.0 && *o > 1e-5 * total), "{o} samples in a cell that expects {e}");
    }
    let mut order: Vec<usize> = (0..expected.len()).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let mut cells: Vec<(f64, f64)> = Vec::new();
    let (mut po, mut pe) = (0.0, 0.0);
    for i in order {
        po += observed[i];
        pe += expected[i];
        if pe >= 5.0 {
            cells.push((po, pe));
            po = 0.0;
            pe = 0.0;
        }
    }
    if pe > 0.0 || po > 0.0 {
        match cells.last_mut() {
            Some(last) => {
                last.0 += po;
                last.1 += pe;
            }
            None => cells.push((po, pe)),
        }
    }
    let chi2: f64 = cells.iter().map(|(o, e)| (o - e) * (o - e) / e).sum();
    let dof = cells.len().saturating_sub(1).max(1);
    (chi2, dof, chi2_p_value(chi2, dof))
}

/// ∫ g(ω) dω per channel over the part of the unit sphere with θ in `[t0, t1]` and φ in `[p0, p1]`, by the
/// midpoint rule on an `nt × np` grid in (θ, φ) with the Jacobian sin θ. Exact to O(h²) for smooth `g`; put
/// kinks on grid lines.
pub fn integrate_sphere(
    (t0, t1): (f64, f64),
    (p0, p1): (f64, f64),
    (nt, np): (usize, usize),
    g: impl Fn(Vec3A) -> Rgb,
) -> [f64; 3] {
    let (dt, dp) = ((t1 - t0) / nt as f64, (p1 - p0) / np as f64);
    let mut sum = [0.0f64; 3];
    for i in 0..nt {
        let t = t0 + (i as f64 + 0.5) * dt;
        let mut row = [0.0f64; 3];
        for j in 0..np {
            let p = p0 + (j as f64 + 0.5) * dp;
            let v = g(dir(t as f32, p as f32));
            for (r, x) in row.iter_mut().zip(v.to_array()) {
                *r += f64::from(x);
            }
        }
        for (s, r) in sum.iter_mut().zip(row) {
            *s += r * t.sin() * dt * dp;
        }
    }
    sum
}

/// [`integrate_sphere`] over the whole sphere, on a grid with an even number of θ rows so that the horizon
/// lies on a grid line.
pub fn integrate_whole_sphere(n: usize, g: impl Fn(Vec3A) -> Rgb) -> [f64; 3] {
    integrate_sphere((0.0, std::f64::consts::PI), (0.0, std::f64::consts::TAU), (2 * n, 2 * n), g)
}
pub mod gltf;

/// Renders `scene` (read from `path`) with `integrator` at its own size, `budget` samples or passes per pixel,
/// with the photon maps the method needs traced for it; asserts that every pixel is finite and non-negative.
#[allow(clippy::unwrap_used)]
pub fn render_method(
    scene: &photon_core::scene::Scene,
    path: &std::path::Path,
    integrator: photon_core::method::Method,
    budget: u32,
) -> photon_core::image_io::Image {
    let mut scene = scene.clone();
    scene.render.integrator = integrator;
    scene.render.spp = budget;
    scene.render.photons.passes = budget;
    let prep = photon_core::prepare::Prepared::new(&scene, path).unwrap().with_photon_maps(path).unwrap();
    let strip = photon_core::render::render_image(&prep, &|_| {});
    assert!(strip.pixels.iter().all(|v| v.is_finite() && *v >= 0.0), "{integrator}: a pixel is negative or not finite");
    photon_core::image_io::Image { width: scene.camera.width, height: scene.camera.height, pixels: strip.pixels }
}

/// The mean of every value of `image`.
pub fn image_mean(image: &photon_core::image_io::Image) -> f64 {
    image.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / image.pixels.len() as f64
}
