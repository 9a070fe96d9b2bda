//! Participating media against analytic values and independent estimators: transmittance through an absorbing
//! slab, the Henyey–Greenstein phase function's sampling, single scattering from a point light against a
//! quadrature of its integral (and equiangular against distance sampling), and volumetric furnaces (a
//! conservative medium, where the radiance is the emitter's everywhere, and an absorbing one against an analog
//! random walk).

#![allow(clippy::unwrap_used)]

mod common;

use common::{Mean, chi2_test, sampler};
use glam::Vec3A;
use photon_core::Rgb;
use photon_core::integrator::Segment;
use photon_core::integrator::volume::{Strategy, in_scattering};
use photon_core::math::Ray;
use photon_core::medium::{HenyeyGreenstein, Medium};
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::prepare::tracer::Tracer;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::Path;

fn prepare(text: &str, dir: &Path) -> Prepared {
    let path = dir.join("scene.toml");
    let mut scene = Scene::parse(text, &path).unwrap();
    scene.base_dir = dir.to_path_buf();
    Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap()
}

fn mean_of(prep: &Prepared) -> f64 {
    let strip = render_image(prep, &|_| {});
    assert!(strip.pixels.iter().all(|v| v.is_finite() && *v >= 0.0));
    strip.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / strip.pixels.len() as f64
}

/// A folder of its own for a test's files.
fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-media-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// An axis-aligned box as an OBJ file, wound outwards.
fn write_box(path: &Path, min: [f32; 3], max: [f32; 3]) {
    let (a, b) = (min, max);
    let mut s = String::new();
    for &z in &[a[2], b[2]] {
        for &y in &[a[1], b[1]] {
            for &x in &[a[0], b[0]] {
                s += &format!("v {x} {y} {z}\n");
            }
        }
    }
    // Vertex i = x + 2y + 4z (bits); faces counter-clockwise seen from outside.
    s += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
    std::fs::write(path, s).unwrap();
}

/// The mean radiance by every method of a camera (1° field of view) looking along −z through a box of the
/// `interface` material spanning z ∈ [−h, h] (and far beyond the view in x and y) whose inside absorbs with
/// coefficient `sigma_a`, at an emitter of radiance 2; with `hole`, an `interface` sphere of that radius at the
/// centre of the box, vacuum inside, which the view's rays cross.
fn slab(h: f32, sigma_a: f32, hole: Option<f32>) -> Vec<(Method, f64)> {
    let dir = scratch(&format!("slab-{h}-{}", hole.unwrap_or(0.0)));
    write_box(&dir.join("slab.obj"), [-20.0, -20.0, -h], [20.0, 20.0, h]);
    let sphere = hole.map_or(String::new(), |r| {
        format!("[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = {r}\nmaterial = \"clear\"\n")
    });
    Method::ALL
        .into_iter()
        .map(|method| {
            let text = format!(
                r#"
[camera]
eye = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
fov = 1.0
width = 8
height = 8

[render]
spp = 4
integrator = "{method}"

[render.photons]
global = 2000
caustic = 2000
pass_photons = 2000
passes = 2
final_gather_rays = 2

[materials.clear]
type = "interface"

[materials.black]
type = "lambert"
albedo = 0.0

[[objects]]
type = "mesh"
file = "slab.obj"
material = "clear"
interior = {{ sigma_a = {sigma_a} }}

{sphere}
[[objects]]
type = "rect"
center = [0.0, 0.0, -3.0]
normal = [0.0, 0.0, 1.0]
width = 60.0
height = 60.0
material = "black"
emission = {{ radiance = [2.0, 2.0, 2.0] }}
"#
            );
            (method, mean_of(&prepare(&text, &dir)))
        })
        .collect()
}

#[test]
fn an_absorbing_slab_transmits_le_times_exp_minus_sigma_a_d() {
    // A slab 0.8 thick bounded by the `interface` material (no surface): every method sees 2·e^(−σa·d). The
    // slant path of the 1° view's corner pixels is 1 + 4·10⁻⁵ times the thickness.
    let (sigma_a, le) = (1.3f64, 2.0f64);
    let expected = le * (-sigma_a * 0.8).exp();
    for (method, mean) in slab(0.4, 1.3, None) {
        eprintln!("slab, {method}: {mean:.6} (expected {expected:.6})");
        assert!((mean - expected).abs() / expected < 0.005, "{method}: {mean} vs {expected}");
    }
    // A vacuum sphere of radius 0.8 nested in a slab 2 thick: the rays cross 0.4 of the medium, then the
    // sphere, then 0.4 again, the medium outside the sphere being the slab's inside. (The chord of the view's
    // corner rays is 0.15 % shorter than the diameter.)
    let expected = le * (-sigma_a * (2.0 - 1.6)).exp();
    for (method, mean) in slab(1.0, 1.3, Some(0.8)) {
        eprintln!("slab with a vacuum sphere, {method}: {mean:.6} (expected {expected:.6})");
        assert!((mean - expected).abs() / expected < 0.005, "{method}: {mean} vs {expected}");
    }
}

#[test]
fn segment_points_follow_their_density_in_a_coloured_medium() {
    // σt = (1, 0.1, 0) on a segment of length 1.5: the channel without extinction is never chosen, and
    // E[g(t)/p(t)] = ∫₀^1.5 g(t) dt for g(t) = t (1.125) and g = 1 (1.5).
    let m = Medium { sigma_a: Rgb::new(0.5, 0.0, 0.0), sigma_s: Rgb::new(0.5, 0.1, 0.0), g: 0.0 };
    let t_max = 1.5f32;
    let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
    let mut s = sampler(17, 0);
    let (mut lin, mut one) = (Mean::default(), Mean::default());
    for _ in 0..400_000 {
        let (t, pdf) = m.sample_segment(&ray, t_max, &mut s).unwrap();
        assert!((0.0..t_max).contains(&t), "{t}");
        lin.add(Rgb::splat(t / pdf));
        one.add(Rgb::splat(1.0 / pdf));
    }
    let (a, b) = (lin.mean()[0], one.mean()[0]);
    eprintln!("∫t = {a:.5} (1.125), ∫1 = {b:.5} (1.5)");
    assert!((a - 1.125).abs() < 4.0 * lin.std_error()[0] + 1e-4, "{a}");
    assert!((b - 1.5).abs() < 4.0 * one.std_error()[0] + 1e-4, "{b}");
    assert!((f64::from(m.segment_mass(&ray, t_max)) - (2.0 - (-1.5f64).exp() - (-0.15f64).exp()) / 3.0).abs() < 1e-6);
}

#[test]
fn henyey_greenstein_sampling_follows_its_pdf_and_g_0_is_isotropic() {
    for g in [-0.7f32, -0.2, 0.0, 0.3, 0.9] {
        let hg = HenyeyGreenstein { g };
        // The pdf integrates to 1 over the sphere: 2π ∫ p(cos) dcos, by the midpoint rule.
        let n = 200_000;
        let integral: f64 = (0..n)
            .map(|i| f64::from(hg.eval_cos(-1.0 + 2.0 * (i as f32 + 0.5) / n as f32)) * 2.0 / f64::from(n))
            .sum::<f64>()
            * 2.0
            * std::f64::consts::PI;
        assert!((integral - 1.0).abs() < 1e-3, "g = {g}: ∫p = {integral}");
        // Chi-square of sampled cos θ in 40 cells against the pdf's integral over each cell; the sampled
        // direction's cosine to the axis is the sampled cos θ, and its pdf is the phase function's value.
        let cells = 40;
        let mut observed = vec![0.0f64; cells];
        let samples = 200_000;
        let mut s = sampler(14, (g * 100.0) as i64 as u64);
        let axis = photon_core::math::fmath::normalize(Vec3A::new(0.3, -0.5, 0.81));
        for _ in 0..samples {
            let ps = hg.sample(axis, s.next_2d());
            let cos = ps.wi.dot(axis);
            assert!((ps.pdf - hg.eval_cos(cos)).abs() <= 1e-3 * ps.pdf.max(1e-3), "g {g}: pdf {} at {cos}", ps.pdf);
            let cell = (((cos + 1.0) / 2.0 * cells as f32) as usize).min(cells - 1);
            observed[cell] += 1.0;
        }
        let expected: Vec<f64> = (0..cells)
            .map(|c| {
                let (a, b) = (-1.0 + 2.0 * c as f64 / cells as f64, -1.0 + 2.0 * (c + 1) as f64 / cells as f64);
                let m = 400;
                let p: f64 = (0..m)
                    .map(|i| f64::from(hg.eval_cos((a + (b - a) * (i as f64 + 0.5) / m as f64) as f32)))
                    .sum::<f64>()
                    * (b - a)
                    / m as f64;
                p * 2.0 * std::f64::consts::PI * samples as f64
            })
            .collect();
        let (chi2, dof, p) = chi2_test(&observed, &expected);
        assert!(p > 1e-3, "g = {g}: chi² {chi2} with {dof} dof, p = {p}");
    }
    let iso = HenyeyGreenstein { g: 0.0 };
    for c in [-1.0f32, -0.3, 0.0, 0.5, 1.0] {
        assert!((iso.eval_cos(c) - 1.0 / (4.0 * std::f32::consts::PI)).abs() < 1e-7);
    }
}

/// The single-scattering integral from a point light of intensity `i` at `light` along the ray from the origin
/// along +x, in a medium of scattering `sigma_s` (no absorption) and asymmetry `g`:
/// `∫₀^∞ e^(−σ·t)·σ·p(cos θ)·I·e^(−σ·r)/r² dt`, `r` the distance from the point at `t` to the light. By the
/// midpoint rule in the angle seen from the light (`t = Δ + D·tan θ`, which takes out the `1/r²` peak), f64.
fn single_scattering_quadrature(sigma_s: f64, g: f64, i: f64, light: [f64; 3]) -> f64 {
    let [lx, ly, lz] = light;
    let delta = lx;
    let dist = (ly * ly + lz * lz).sqrt();
    let (a, b) = ((-delta / dist).atan(), std::f64::consts::FRAC_PI_2);
    let n = 400_000;
    let h = (b - a) / f64::from(n);
    let hg = |cos: f64| (1.0 - g * g) / (4.0 * std::f64::consts::PI * (1.0 + g * g - 2.0 * g * cos).powf(1.5));
    (0..n)
        .map(|k| {
            let theta = a + (f64::from(k) + 0.5) * h;
            let t = delta + dist * theta.tan();
            let r = dist / theta.cos();
            // Light travels from the light to the point (direction (t − lx, −ly, −lz)/r), then back along −x.
            let cos = -(t - lx) / r;
            // dt = D/cos²θ dθ = r²/D dθ: the r² cancels the falloff.
            (-sigma_s * t).exp() * sigma_s * hg(cos) * i * (-sigma_s * r).exp() / dist * h
        })
        .sum()
}

#[test]
fn single_scattering_from_a_point_light_matches_the_quadrature_and_equiangular_beats_distance_sampling() {
    let (sigma_s, g, intensity, light) = (0.05f32, 0.4f32, 3.0f32, [1.5f32, 0.6, 0.2]);
    let text = format!(
        r#"
[camera]
eye = [0.0, 0.0, 0.0]
look_at = [1.0, 0.0, 0.0]

[medium]
sigma_s = {sigma_s}
g = {g}

[[lights]]
type = "point"
position = [{}, {}, {}]
intensity = [{intensity}, {intensity}, {intensity}]
"#,
        light[0], light[1], light[2]
    );
    let prep = prepare(&text, &scratch("single"));
    let m: Medium = prep.media.as_ref().unwrap().global.unwrap();
    let expected =
        single_scattering_quadrature(f64::from(sigma_s), f64::from(g), f64::from(intensity), light.map(f64::from));
    let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
    let n = 400_000u64;
    let mut results = Vec::new();
    for (k, strategy) in [Strategy::Mis, Strategy::Equiangular, Strategy::Distance].into_iter().enumerate() {
        let mut mean = Mean::default();
        let mut tracer = Tracer::new(&prep, sampler(15, k as u64));
        let segment = Segment { ray: &ray, medium: &m, t_max: f32::INFINITY };
        for _ in 0..n {
            let flight = m.sample_distance(&ray, f32::INFINITY, &mut tracer.sampler);
            let at = flight.scattered.then_some((flight.t, flight.pdf));
            let pdf = |t: f32| m.distance_pdf(&ray, t);
            mean.add(in_scattering(&mut tracer, &segment, at, &pdf, strategy, false));
        }
        let (value, err) = (mean.mean()[0], mean.std_error()[0]);
        let variance = err * err * n as f64;
        eprintln!("{strategy:?}: {value:.6e} ± {err:.1e} (quadrature {expected:.6e}), variance {variance:.3e}");
        results.push((strategy, value, err, variance));
    }
    for &(strategy, value, err, _) in &results {
        let rel = (value - expected).abs() / expected;
        // Within 1 % (equiangular and MIS are far tighter than that), and within 4 standard errors.
        assert!(rel < 0.01 || strategy == Strategy::Distance, "{strategy:?}: {value} vs {expected}");
        assert!((value - expected).abs() < 4.0 * err + 1e-4 * expected, "{strategy:?}: {value} ± {err} vs {expected}");
    }
    let (eq, dist) = (results[1].3, results[2].3);
    eprintln!("variance ratio distance / equiangular: {:.1}", dist / eq);
    assert!(eq < dist, "equiangular variance {eq} not below distance sampling's {dist}");
    assert!(results[0].3 < dist, "MIS variance {} not below distance sampling's {dist}", results[0].3);
}

/// A sphere of radius 2 whose inside emits radiance 1 and absorbs everything that reaches it, filled with a
/// medium of extinction `density` and albedo `albedo`; the camera at its centre. The mean radiance over the
/// image, by `method` with `spp` samples.
fn volumetric_furnace(density: f32, albedo: f32, g: f32, method: Method, spp: u32) -> f64 {
    let text = format!(
        r#"
[camera]
eye = [0.0, 0.0, 0.0]
look_at = [0.0, 0.0, -1.0]
fov = 90.0
width = 16
height = 16

[render]
spp = {spp}
max_depth = 1000
integrator = "{method}"

[materials.black]
type = "lambert"
albedo = 0.0

[[objects]]
type = "sphere"
center = [0.0, 0.0, 0.0]
radius = 2.0
material = "black"
emission = {{ radiance = [1.0, 1.0, 1.0], two_sided = true }}
interior = {{ density = {density}, albedo = {albedo}, g = {g} }}
"#
    );
    mean_of(&prepare(&text, &scratch("furnace")))
}

#[test]
fn a_conservative_medium_in_an_emitting_sphere_has_the_emitters_radiance_everywhere() {
    // With albedo 1 and a black emitting boundary, L = Le is the equilibrium of the radiative transfer
    // equation, for any optical depth and any phase function.
    for (density, g) in [(0.5f32, 0.0f32), (2.0, 0.6), (4.0, -0.3)] {
        let mean = volumetric_furnace(density, 1.0, g, Method::Path, 64);
        eprintln!("conservative furnace, σt {density}, g {g}: {mean:.4}");
        assert!((mean - 1.0).abs() < 0.02, "σt {density}, g {g}: {mean} vs 1");
    }
}

/// The same furnace by an analog random walk in f64: from the centre, free flights of extinction `density`;
/// a walk that reaches the sphere sees radiance 1 times albedo^(scatterings). Independent of the renderer's
/// code (no light sampling, no MIS, no roulette).
fn furnace_random_walk(density: f64, albedo: f64, walks: u64) -> f64 {
    let mut s = sampler(16, (density * 1000.0) as u64);
    let mut sum = 0.0;
    for _ in 0..walks {
        let (mut p, mut d) = ([0.0f64; 3], [0.0f64, 0.0, -1.0]);
        let mut weight = 1.0;
        loop {
            // Distance to the sphere of radius 2: solve |p + t·d| = 2 for t > 0.
            let pd = p[0] * d[0] + p[1] * d[1] + p[2] * d[2];
            let pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
            let exit = -pd + (pd * pd - pp + 4.0).max(0.0).sqrt();
            let t = -(1.0 - f64::from(s.next_f32())).ln() / density;
            if t >= exit {
                sum += weight;
                break;
            }
            p = [p[0] + t * d[0], p[1] + t * d[1], p[2] + t * d[2]];
            weight *= albedo;
            if weight < 1e-6 {
                break;
            }
            let z = 1.0 - 2.0 * f64::from(s.next_f32());
            let phi = 2.0 * std::f64::consts::PI * f64::from(s.next_f32());
            let r = (1.0 - z * z).max(0.0).sqrt();
            d = [r * phi.cos(), r * phi.sin(), z];
        }
    }
    sum / walks as f64
}

#[test]
fn an_absorbing_medium_in_an_emitting_sphere_matches_an_analog_random_walk() {
    // 256 spp: at 64 the mean of σt 3, ρ 0.9 moves by ±1.5 % from seed to seed (0.1967 to 0.2025 over seeds 1–6),
    // too close to the 2 % tolerance; at 1024 spp it is 0.2008 against the walk's 0.2015.
    for (density, albedo) in [(1.0f32, 0.7f32), (3.0, 0.9)] {
        let reference = furnace_random_walk(f64::from(density), f64::from(albedo), 400_000);
        let mean = volumetric_furnace(density, albedo, 0.0, Method::Path, 256);
        eprintln!("furnace σt {density}, albedo {albedo}: path {mean:.4}, random walk {reference:.4}");
        assert!((mean - reference).abs() / reference < 0.02, "σt {density}, ρ {albedo}: {mean} vs {reference}");
    }
}

fn scene_path(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name)
}

/// A shipped scene at `w × h` with `method`, as `edit` changes it further.
fn shipped(name: &str, w: u32, h: u32, method: Method, edit: impl FnOnce(&mut Scene)) -> Prepared {
    let path = scene_path(name);
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = w;
    scene.camera.height = h;
    scene.render.integrator = method;
    edit(&mut scene);
    Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap()
}

fn region_mean(px: &[f32], w: u32, (x0, y0, x1, y1): (u32, u32, u32, u32)) -> f64 {
    let mut sum = 0.0;
    for y in y0..y1 {
        for x in x0..x1 {
            for c in 0..3 {
                sum += f64::from(px[3 * (y * w + x) as usize + c]);
            }
        }
    }
    sum / f64::from(3 * (x1 - x0) * (y1 - y0))
}

#[test]
fn path_and_progressive_agree_on_the_fog_scene() {
    let (w, h) = (32, 32);
    let path = render_image(&shipped("fog.toml", w, h, Method::Path, |s| s.render.spp = 1024), &|_| {});
    let progressive = render_image(
        &shipped("fog.toml", w, h, Method::Progressive, |s| {
            s.render.photons.passes = 48;
            s.render.photons.pass_photons = 50_000;
        }),
        &|_| {},
    );
    // The whole image, and the light shaft under the slit (the middle eighth of the columns, from the ceiling
    // to the sphere).
    for (name, region) in [("image", (0, 0, w, h)), ("shaft", (14, 3, 18, 20))] {
        let (a, b) = (region_mean(&path.pixels, w, region), region_mean(&progressive.pixels, w, region));
        eprintln!("fog, {name}: path {a:.5}, progressive {b:.5} ({:+.2} %)", (b / a - 1.0) * 100.0);
        assert!((b / a - 1.0).abs() < 0.02, "{name}: path {a} vs progressive {b}");
    }
}

/// Relative MSE of `img` against `reference`, as `compare` measures it.
fn rel_mse(img: &[f32], reference: &[f32], (width, height): (u32, u32)) -> f64 {
    let image = |pixels: &[f32]| photon_core::image_io::Image { width, height, pixels: pixels.to_vec() };
    photon_core::metrics::compare(&image(img), &image(reference), None).unwrap().rel_mse
}

#[test]
fn progressive_error_falls_with_passes_on_the_volume_caustic() {
    let (w, h) = (24, 18);
    let render = |passes: u32, seed: u64| {
        let prep = shipped("volume-caustic.toml", w, h, Method::Progressive, |s| {
            s.render.photons.passes = passes;
            s.render.photons.pass_photons = 20_000;
            s.render.seed = seed;
        });
        render_image(&prep, &|_| {}).pixels
    };
    let reference = render(384, 7);
    let errors: Vec<(u32, f64)> =
        [6u32, 24, 96].into_iter().map(|p| (p, rel_mse(&render(p, 1), &reference, (w, h)))).collect();
    eprintln!("volume caustic, relMSE against 384 passes: {errors:?}");
    for pair in errors.windows(2) {
        assert!(pair[1].1 < pair[0].1, "relMSE did not fall from {:?} to {:?}", pair[0], pair[1]);
    }
    // A path tracer never completes light → glass → fog paths from a point light: below the sphere the volume
    // caustic is missing from its image.
    let prep = shipped("volume-caustic.toml", w, h, Method::Path, |s| s.render.spp = 64);
    let path = render_image(&prep, &|_| {}).pixels;
    let under = (10, 10, 14, 14);
    let (p, r) = (region_mean(&path, w, under), region_mean(&reference, w, under));
    eprintln!("under the sphere: path {p:.5}, progressive {r:.5}");
    assert!(p < 0.9 * r, "the path tracer found the volume caustic: {p} vs {r}");
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn media_renders_do_not_depend_on_threads_or_strips() {
    for method in Method::ALL {
        let prep = shipped("fog.toml", 12, 10, method, |s| {
            s.render.spp = 2;
            s.render.photons.global = 4_000;
            s.render.photons.pass_photons = 4_000;
            s.render.photons.passes = 2;
            s.render.photons.final_gather_rays = 2;
        });
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let whole = one.install(|| photon_core::render::render_rows(&prep, 0..10, &|_| {}));
        let three = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let mut stitched = Vec::new();
        for rows in [0..4, 4..5, 5..10] {
            stitched.extend(three.install(|| photon_core::render::render_rows(&prep, rows, &|_| {})).pixels);
        }
        assert_eq!(bits(&whole.pixels), bits(&stitched), "{method}");
        assert!(whole.pixels.iter().any(|&v| v > 0.0), "{method}: black");
    }
}

#[test]
fn scenes_without_media_build_no_media_and_no_volume_map() {
    for method in [Method::Path, Method::PhotonMap, Method::FinalGather] {
        let prep = shipped("cornell.toml", 8, 8, method, |s| {
            s.render.photons.global = 2_000;
            s.render.photons.caustic = 2_000;
        });
        assert!(prep.media.is_none(), "{method}");
        assert!(prep.photons.as_ref().is_none_or(|m| m.volume.is_none()), "{method}");
    }
    let prep = shipped("fog.toml", 8, 8, Method::PhotonMap, |s| s.render.photons.global = 2_000);
    let volume = prep.photons.as_ref().and_then(|m| m.volume.as_ref()).map_or(0, |v| v.len());
    assert!(prep.media.is_some() && volume > 0, "fog: {volume} volume photons");
}

/// The error of preparing `text` (with a cube mesh `open.obj` missing one face beside it).
fn prepare_err(text: &str) -> String {
    let dir = scratch("errors");
    std::fs::write(dir.join("open.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n").unwrap();
    let path = dir.join("scene.toml");
    let err = match Scene::parse(text, &path) {
        Err(e) => e.to_string(),
        Ok(mut scene) => {
            scene.base_dir = dir.clone();
            match Prepared::new(&scene, &path) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("accepted:\n{text}"),
            }
        }
    };
    assert!(err.contains("scene.toml"), "the file is not named: {err}");
    err
}

#[test]
fn bad_media_are_errors_that_name_the_field() {
    const HEAD: &str =
        "[camera]\neye = [0.0, 0.0, 3.0]\nlook_at = [0.0, 0.0, 0.0]\n[materials.m]\ntype = \"lambert\"\n";
    for (table, field, expected) in [
        ("sigma_a = -0.1", "medium.sigma_a", "≥ 0"),
        ("sigma_s = [0.1, nan, 0.1]", "medium.sigma_s", "finite"),
        ("density = 1.0\nalbedo = 1.5", "medium.albedo", "[0, 1]"),
        ("density = -2.0", "medium.density", "[0,"),
        ("density = 1.0\nsigma_s = 0.5", "medium.density", "not both"),
        ("sigma_s = 0.5\nalbedo = 0.5", "medium.albedo", "with `density`"),
        ("sigma_s = 0.5\ng = 1.0", "medium.g", "(−1, 1)"),
        ("sigma_s = 0.5\ng = inf", "medium.g", "(−1, 1)"),
        ("sigma_t = 0.5", "sigma_t", "unknown field"),
    ] {
        let err = prepare_err(&format!("{HEAD}[medium]\n{table}\n"));
        assert!(err.contains(field) && err.contains(expected), "{table}: {err}");
    }
    let sphere = "[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"m\"\n";
    let err = prepare_err(&format!("{HEAD}{sphere}interior = {{ sigma_s = -1.0 }}\n"));
    assert!(err.contains("objects[0].interior.sigma_s"), "{err}");
    // An interface has no surface to emit from.
    let glow = "[materials.b]\ntype = \"interface\"\n[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\n\
                radius = 1.0\nmaterial = \"b\"\nemission = { radiance = [1.0, 1.0, 1.0] }\n";
    let err = prepare_err(&format!("{HEAD}{glow}"));
    assert!(err.contains("objects[0].emission") && err.contains("interface"), "{err}");
    // An interior needs an inside: an open mesh has none.
    let mesh = "[[objects]]\ntype = \"mesh\"\nfile = \"open.obj\"\nmaterial = \"m\"\ninterior = { sigma_s = 1.0 }\n";
    let err = prepare_err(&format!("{HEAD}{mesh}"));
    assert!(err.contains("objects[0].interior") && err.contains("not a closed mesh"), "{err}");
}

#[test]
fn an_interface_sphere_in_vacuum_changes_nothing() {
    // The Cornell box, and the same box with a sphere of the `interface` material (and vacuum inside) in the
    // middle of the room, which the camera, the light's paths and the shadow rays all cross: the same image
    // but for the rounding of the rays' restarts at the sphere.
    let plain = shipped("cornell.toml", 24, 24, Method::Path, |s| s.render.spp = 512);
    let crossed = shipped("cornell.toml", 24, 24, Method::Path, |s| {
        s.render.spp = 512;
        s.materials.insert("boundary".into(), photon_core::material::Material::Interface {});
        s.objects.push(photon_core::scene::Object::Sphere {
            center: glam::Vec3::new(0.0, 1.0, 0.0),
            radius: 0.6,
            material: "boundary".into(),
            emission: None,
            interior: None,
        });
    });
    assert!(crossed.media.is_some());
    let (a, b) = (render_image(&plain, &|_| {}).pixels, render_image(&crossed, &|_| {}).pixels);
    let (ma, mb) = (region_mean(&a, 24, (0, 0, 24, 24)), region_mean(&b, 24, (0, 0, 24, 24)));
    let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
    eprintln!("interface sphere: mean {ma:.5} without, {mb:.5} with; {same} of {} values identical", a.len());
    assert!((mb / ma - 1.0).abs() < 0.005, "{ma} vs {mb}");
}
