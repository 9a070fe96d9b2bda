//! Vertex connection and merging, bidirectional path tracing and light tracing (`render::vcm`):
//! - the MIS weights of every technique that can make a path sum to 1, on paths stored in both Mitsuba rooms;
//! - light tracing alone, and the others, give the analytic radiance of a point light over a Lambert plane;
//! - white furnaces, open (white objects in a black emitting enclosure: invisible) and closed (Le/(1 − ρ));
//! - the image means agree with the path tracer's within 0.2 % on both rooms;
//! - the error against a converged image falls at every 4× step of iterations.

#![allow(clippy::unwrap_used)]

use glam::{Vec2, Vec3A};
use photon_core::geometry::{Hit, NONE};
use photon_core::image_io::Image;
use photon_core::light::Light;
use photon_core::material::bsdf::{Bsdf, TransportMode};
use photon_core::math::Ray;
use photon_core::math::fmath;
use photon_core::math::rng::Sampler;
use photon_core::method::Method;
use photon_core::photon::Kernel;
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::render::vcm::{Iteration, MisState, continuation, weights};
use photon_core::scene::Scene;
use std::f32::consts::FRAC_1_PI;
use std::path::Path;

fn load(path: &str) -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path);
    let scene = Scene::load(&path).unwrap();
    Prepared::new(&scene, &path).unwrap()
}

fn parse(text: &str) -> Prepared {
    let scene = Scene::parse(text, Path::new("vcm-test.toml")).unwrap();
    Prepared::new(&scene, Path::new("vcm-test.toml")).unwrap()
}

fn render(prep: &Prepared, integrator: Method, size: u32, budget: u32) -> Image {
    let mut prep = prep.clone();
    prep.settings.integrator = integrator;
    prep.camera.width = size;
    prep.camera.height = size;
    prep.settings.spp = budget;
    prep.settings.photons.passes = budget;
    let strip = render_image(&prep, &|_| {});
    assert!(strip.pixels.iter().all(|v| v.is_finite() && *v >= 0.0), "{integrator}: a pixel is negative or not finite");
    Image { width: size, height: size, pixels: strip.pixels }
}

fn mean(image: &Image) -> f64 {
    image.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / image.pixels.len() as f64
}

fn rel_mse(image: &Image, reference: &Image) -> f64 {
    photon_core::metrics::compare(image, reference, None).unwrap().rel_mse
}

// ---------------------------------------------------------------------------------------------------------
// MIS weights on stored paths

/// A vertex of a stored path: the hit, its BSDF, and whether the path scattered there by a delta lobe.
struct Vertex {
    hit: Hit,
    bsdf: Bsdf,
    delta: bool,
}

/// A full path from a point on the area light (`light`, z_0) over surface vertices z_1 … z_{k−1} (`surface`, in
/// light-to-camera order) to the camera's pinhole z_k.
struct StoredPath {
    light: Hit,
    surface: Vec<Vertex>,
    eye: Vec3A,
}

/// Paths made by following BSDF samples from the camera for a random number of bounces, then joining a point
/// on the light: every technique of the path can be evaluated whether or not it found it.
fn stored_paths(prep: &Prepared, count: usize) -> Vec<StoredPath> {
    let camera = &prep.camera;
    let mut out = Vec::new();
    let mut i = 0u32;
    while out.len() < count {
        i += 1;
        assert!(i < 100 * count as u32, "too few paths could be stored");
        let mut s = Sampler::for_pixel(7, i, 0, 0);
        let film = s.next_2d() * Vec2::new(camera.width as f32, camera.height as f32);
        let mut ray = camera.ray(film, Vec2::ZERO);
        let bounces = 1 + (s.next_f32() * 5.0) as usize;
        let mut camera_side: Vec<Vertex> = Vec::new();
        let mut ok = true;
        for b in 0..bounces {
            let Some(hit) = prep.geometry.intersect(&ray, f32::INFINITY) else {
                ok = false;
                break;
            };
            let bsdf = prep.materials[hit.material as usize].bsdf(&hit, &prep.textures);
            let wo = -ray.d;
            if hit.light != NONE || bsdf.black_from(wo) {
                ok = false;
                break;
            }
            if b + 1 == bounces {
                camera_side.push(Vertex { hit, bsdf, delta: !bsdf.has_non_delta() });
                break;
            }
            let Some(bs) = bsdf.sample(wo, s.next_f32(), s.next_2d(), TransportMode::Radiance) else {
                ok = false;
                break;
            };
            camera_side.push(Vertex { hit, bsdf, delta: bs.delta });
            ray = hit.spawn_ray(bs.wi);
        }
        let Some(last) = camera_side.last() else { continue };
        if !ok || last.delta {
            continue;
        }
        // Join a point on the light, seen from the last vertex on its emitting side.
        let Some(Light::Area { prim, .. }) = prep.lights.lights.first().copied() else { panic!("no area light") };
        let (lp, _, _) = prep.geometry.prim(prim).unwrap().shape.sample_area_with_error(s.next_2d());
        let w = fmath::normalize(lp - last.hit.p);
        let Some(light) = prep.geometry.intersect(&last.hit.spawn_ray(w), f32::INFINITY) else { continue };
        let wl = -w;
        if light.light == NONE
            || prep.lights.lights[light.light as usize].le(&prep.light_scene(), &light, wl) == Vec3A::ZERO
            || last.bsdf.f(-ray.d, w, TransportMode::Radiance) == Vec3A::ZERO
        {
            continue;
        }
        camera_side.reverse();
        out.push(StoredPath { light, surface: camera_side, eye: camera.eye() });
    }
    out
}

fn dir(from: Vec3A, to: Vec3A) -> Vec3A {
    fmath::normalize(to - from)
}

impl StoredPath {
    /// z_j: 0 the light, k the eye.
    fn p(&self, j: usize) -> Vec3A {
        match j {
            0 => self.light.p,
            j if j <= self.surface.len() => self.surface[j - 1].hit.p,
            _ => self.eye,
        }
    }

    fn k(&self) -> usize {
        self.surface.len() + 1
    }

    fn vertex(&self, j: usize) -> &Vertex {
        &self.surface[j - 1]
    }

    /// `(pdf, pdf_rev, cos_out, delta)` of scattering at surface vertex `j` from `from` to `to` (indices).
    fn scatter_at(&self, j: usize, from: usize, to: usize) -> (f32, f32, f32, bool) {
        let v = self.vertex(j);
        let (wo, wi) = (dir(self.p(j), self.p(from)), dir(self.p(j), self.p(to)));
        let q = continuation(&v.bsdf, wo);
        (v.bsdf.pdf(wo, wi) * q, v.bsdf.pdf(wi, wo) * q, wi.dot(v.bsdf.ng).abs(), v.delta)
    }

    /// The light choice, area and the emission densities `(direct_pdf_a, emission_pdf_w, cos_light)` of z_0
    /// towards z_1.
    fn light_densities(&self, prep: &Prepared) -> (f32, f32, f32) {
        let Light::Area { area, two_sided, .. } = prep.lights.lights[self.light.light as usize] else { panic!() };
        let pick = prep.lights.pmf(self.light.light as usize);
        let cos = dir(self.p(0), self.p(1)).dot(self.light.n).abs();
        let sides = if two_sided { 0.5 } else { 1.0 };
        (pick / area, pick / area * cos * FRAC_1_PI * sides, cos)
    }

    /// The light subpath's quantities at z_{last} (arrived there).
    fn light_state(&self, prep: &Prepared, it: &Iteration, last: usize) -> MisState {
        let (direct_pdf_a, emission_pdf_w, cos) = self.light_densities(prep);
        let mut state = MisState::emitted(it, direct_pdf_a, emission_pdf_w, cos, false);
        for j in 1..=last {
            if j > 1 {
                let (pdf, pdf_rev, cos_out, delta) = self.scatter_at(j - 1, j - 2, j);
                state.scatter(it, cos_out, pdf, pdf_rev, delta);
            }
            let (a, b) = (self.p(j - 1), self.p(j));
            state.arrive((b - a).length(), dir(b, a).dot(self.vertex(j).bsdf.ng).abs());
        }
        state
    }

    /// The camera subpath's quantities at z_{last} (arrived there; `last = 0` is the light).
    fn camera_state(&self, prep: &Prepared, it: &Iteration, last: usize) -> MisState {
        let k = self.k();
        let cos = dir(self.eye, self.p(k - 1)).dot(prep.camera.forward());
        let mut state = MisState::from_camera(it, prep.camera.pixel_direction_pdf(cos));
        for j in (last..k).rev() {
            if j + 1 < k {
                let (pdf, pdf_rev, cos_out, delta) = self.scatter_at(j + 1, j + 2, j);
                state.scatter(it, cos_out, pdf, pdf_rev, delta);
            }
            let (a, b) = (self.p(j + 1), self.p(j));
            let ng = if j == 0 { self.light.n } else { self.vertex(j).bsdf.ng };
            state.arrive((b - a).length(), dir(b, a).dot(ng).abs());
        }
        state
    }

    /// Every technique's weight for this path.
    fn weights(&self, prep: &Prepared, it: &Iteration) -> Vec<(String, f32)> {
        let k = self.k();
        let mut out = Vec::new();
        let (direct_pdf_a, emission_pdf_w, cos_light) = self.light_densities(prep);
        // s = 0: the camera subpath finds the light.
        out.push(("emission".into(), weights::emission(&self.camera_state(prep, it, 0), direct_pdf_a, emission_pdf_w)));
        let non_delta = |j: usize| !self.vertex(j).delta;
        if it.techniques.connect {
            // s = 1: next-event estimation at z_1.
            if k >= 2 && non_delta(1) {
                let c = self.camera_state(prep, it, 1);
                let v = self.vertex(1);
                let (wo, w) = (dir(self.p(1), self.p(2)), dir(self.p(1), self.p(0)));
                let q = continuation(&v.bsdf, wo);
                let d2 = (self.p(0) - self.p(1)).length_squared();
                let index = self.light.light as usize;
                let Light::Area { area, .. } = prep.lights.lights[index] else { panic!() };
                let pick = prep.lights.pmf(index);
                let direct_pdf_w = d2 / (cos_light * area);
                let light_pdf_w = pick * direct_pdf_w;
                let emission_ratio = emission_pdf_w / pick * w.dot(v.bsdf.ng).abs() / (direct_pdf_w * cos_light);
                let weight =
                    weights::direct(it, &c, v.bsdf.pdf(wo, w) * q, v.bsdf.pdf(w, wo) * q, light_pdf_w, emission_ratio);
                out.push(("direct".into(), weight));
            }
            // 2 ≤ s ≤ k − 1: z_{s−1} (light) to z_s (camera).
            for s in 2..k {
                if !(non_delta(s - 1) && non_delta(s)) {
                    continue;
                }
                let (l, c) = (self.light_state(prep, it, s - 1), self.camera_state(prep, it, s));
                let (lv, cv) = (self.vertex(s - 1), self.vertex(s));
                let (lwo, cwo) = (dir(self.p(s - 1), self.p(s - 2)), dir(self.p(s), self.p(s + 1)));
                let w = dir(self.p(s), self.p(s - 1));
                let d2 = (self.p(s - 1) - self.p(s)).length_squared();
                let (lq, cq) = (continuation(&lv.bsdf, lwo), continuation(&cv.bsdf, cwo));
                let camera_pdf_a = cv.bsdf.pdf(cwo, w) * cq * w.dot(lv.bsdf.ng).abs() / d2;
                let light_pdf_a = lv.bsdf.pdf(lwo, -w) * lq * w.dot(cv.bsdf.ng).abs() / d2;
                let weight = weights::connect(
                    it,
                    &c,
                    &l,
                    camera_pdf_a,
                    cv.bsdf.pdf(w, cwo) * cq,
                    light_pdf_a,
                    lv.bsdf.pdf(-w, lwo) * lq,
                );
                out.push((format!("connect s={s}"), weight));
            }
        }
        // s = k: light tracing from z_{k−1}.
        if k >= 2 && non_delta(k - 1) && (it.techniques.connect || it.techniques.light_tracing_only) {
            let l = self.light_state(prep, it, k - 1);
            let v = self.vertex(k - 1);
            let lwo = dir(self.p(k - 1), self.p(k - 2));
            let w = dir(self.p(k - 1), self.eye);
            let d2 = (self.eye - self.p(k - 1)).length_squared();
            let camera_pdf_a =
                prep.camera.pixel_direction_pdf((-w).dot(prep.camera.forward())) * w.dot(v.bsdf.ng).abs() / d2;
            let q = continuation(&v.bsdf, lwo);
            out.push(("light tracing".into(), weights::light_trace(it, &l, camera_pdf_a, v.bsdf.pdf(w, lwo) * q)));
        }
        if it.techniques.merge {
            for i in 1..k {
                if !non_delta(i) {
                    continue;
                }
                let (l, c) = (self.light_state(prep, it, i), self.camera_state(prep, it, i));
                let v = self.vertex(i);
                let (cwo, lwo) = (dir(self.p(i), self.p(i + 1)), dir(self.p(i), self.p(i - 1)));
                // As the renderer: the forward density with the camera vertex's roulette, the reverse one with
                // the light vertex's (here the same point).
                let (cq, lq) = (continuation(&v.bsdf, cwo), continuation(&v.bsdf, lwo));
                let weight = weights::merge(it, &c, &l, v.bsdf.pdf(cwo, lwo) * cq, v.bsdf.pdf(lwo, cwo) * lq);
                out.push((format!("merge at z{i}"), weight));
            }
        }
        out
    }
}

#[test]
fn mis_weights_of_every_technique_sum_to_one_on_stored_paths() {
    for room in ["scenes/rooms/cornell-boxes.toml", "scenes/rooms/cornell-spheres.toml"] {
        let prep = load(room);
        let paths = stored_paths(&prep, 300);
        let mut lengths = [0usize; 8];
        let mut with_delta = 0;
        for techniques in [Method::Vcm.techniques().unwrap(), Method::Bdpt.techniques().unwrap()] {
            // A radius small and large against the room (2 units wide), and the number of light paths of a
            // 256×256 image.
            for r in [0.003f32, 0.05] {
                let it = Iteration::new(techniques, 65536.0, r * r, Kernel::Box, 1000);
                for (n, path) in paths.iter().enumerate() {
                    let w = path.weights(&prep, &it);
                    let sum: f64 = w.iter().map(|(_, w)| f64::from(*w)).sum();
                    assert!(w.iter().all(|(_, w)| w.is_finite() && *w >= 0.0), "{room} path {n}: {w:?}");
                    assert!(
                        (sum - 1.0).abs() < 1e-4,
                        "{room}, {techniques:?}, r {r}, path {n} (k = {}): weights {w:?} sum to {sum}",
                        path.k()
                    );
                }
            }
        }
        for p in &paths {
            lengths[p.k().min(7)] += 1;
            with_delta += usize::from(p.surface.iter().any(|v| v.delta));
        }
        eprintln!("{room}: path lengths {lengths:?}, {with_delta} through mirror or glass");
        assert!(lengths[2..].iter().filter(|&&n| n > 0).count() >= 4, "too few lengths: {lengths:?}");
        if room.contains("spheres") {
            assert!(with_delta > 10, "too few paths through the spheres: {with_delta}");
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// Analytic cases

const PLANE: &str = r#"
[camera]
eye = [0.0, 3.0, 3.0]
look_at = [0.0, 0.0, 0.0]
fov = 50.0
width = 20
height = 20

[render]
max_depth = 5

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "plane"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
material = "grey"

[[lights]]
type = "point"
position = [0.3, 2.0, -0.4]
intensity = [10.0, 5.0, 2.5]
"#;

/// Every pixel of the plane scene integrated over its area by a 12×12 grid of pinhole rays: ρ/π · I cos θ / r².
fn plane_truth(prep: &Prepared) -> Image {
    let (light, intensity) = (Vec3A::new(0.3, 2.0, -0.4), Vec3A::new(10.0, 5.0, 2.5));
    let (w, h) = (prep.camera.width, prep.camera.height);
    let mut pixels = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let mut sum = Vec3A::ZERO;
            for j in 0..12 {
                for i in 0..12 {
                    let film = Vec2::new(x as f32 + (i as f32 + 0.5) / 12.0, y as f32 + (j as f32 + 0.5) / 12.0);
                    let ray: Ray = prep.camera.ray(film, Vec2::ZERO);
                    if ray.d.y >= 0.0 {
                        continue;
                    }
                    let p = ray.o + ray.d * (-ray.o.y / ray.d.y);
                    let d = light - p;
                    sum += 0.5 * FRAC_1_PI * intensity * (d.y / d.length()) / d.length_squared();
                }
            }
            pixels.extend_from_slice(&(sum / 144.0).to_array());
        }
    }
    Image { width: w, height: h, pixels }
}

#[test]
fn light_tracing_alone_and_with_connections_gives_a_point_light_over_a_lambert_plane() {
    let prep = parse(PLANE);
    let truth = plane_truth(&prep);
    for (integrator, passes) in [(Method::Lt, 2048), (Method::Bdpt, 256), (Method::Vcm, 256)] {
        let image = render(&prep, integrator, 20, passes);
        let (m, t) = (mean(&image), mean(&truth));
        let err = rel_mse(&image, &truth);
        eprintln!("{integrator}: mean {m:.5} vs {t:.5} ({:+.3} %), relMSE {err:.2e}", 100.0 * (m / t - 1.0));
        assert!((m / t - 1.0).abs() < 0.01, "{integrator}: mean {m} vs analytic {t}");
        assert!(err < 2e-3, "{integrator}: relMSE {err} against the analytic image");
    }
}

/// A black enclosure of radius 5 emitting 1 on both sides, holding white (albedo 1) objects: a sphere and a
/// box made of rectangles. Every surface reflects exactly what reaches it, which is 1 from everywhere, so the
/// image is 1 (the objects are invisible) for any correct method.
const OPEN_FURNACE: &str = r#"
[camera]
eye = [0.0, 0.3, 3.0]
look_at = [0.0, 0.0, 0.0]
fov = 60.0
width = 16
height = 16

[render]
max_depth = 1000

[materials.white]
type = "lambert"
albedo = 1.0

[materials.black]
type = "lambert"
albedo = 0.0

[[objects]]
type = "sphere"
center = [0.0, 0.0, 0.0]
radius = 5.0
material = "black"
emission = { radiance = [1.0, 1.0, 1.0], two_sided = true }

[[objects]]
type = "sphere"
center = [-0.5, 0.0, 0.0]
radius = 0.6
material = "white"

[[objects]]
type = "rect"
center = [0.6, -0.6, 0.0]
normal = [0.0, 1.0, 0.0]
width = 1.2
height = 1.2
material = "white"

[[objects]]
type = "rect"
center = [0.6, 0.0, -0.6]
normal = [0.0, 0.0, 1.0]
width = 1.2
height = 1.2
material = "white"
"#;

#[test]
fn white_objects_in_an_open_furnace_are_invisible() {
    let prep = parse(OPEN_FURNACE);
    for (integrator, passes) in [(Method::Vcm, 64), (Method::Bdpt, 64), (Method::Lt, 4096)] {
        let image = render(&prep, integrator, 16, passes);
        let m = mean(&image);
        // Every quadrant, not just the mean: a technique that double-counts or misses shows on the objects.
        let quadrant = |qx: u32, qy: u32| {
            let mut sum = 0.0;
            for y in qy * 8..qy * 8 + 8 {
                for x in qx * 8..qx * 8 + 8 {
                    sum += (0..3).map(|c| f64::from(image.pixels[3 * (y * 16 + x) as usize + c])).sum::<f64>();
                }
            }
            sum / 192.0
        };
        let quadrants = [quadrant(0, 0), quadrant(1, 0), quadrant(0, 1), quadrant(1, 1)];
        eprintln!("open furnace, {integrator}: mean {m:.4}, quadrants {quadrants:.4?}");
        assert!((m - 1.0).abs() < 0.01, "{integrator}: mean {m}");
        for q in quadrants {
            assert!((q - 1.0).abs() < 0.03, "{integrator}: quadrants {quadrants:?}");
        }
    }
}

#[test]
fn a_closed_furnace_gives_le_over_one_minus_albedo() {
    let text = r#"
[camera]
eye = [0.0, 0.0, 0.0]
look_at = [0.0, 0.0, -1.0]
fov = 90.0
width = 12
height = 12

[render]
max_depth = 1000

[materials.grey]
type = "lambert"
albedo = 0.5

[[objects]]
type = "sphere"
center = [0.1, -0.2, 0.05]
radius = 2.0
material = "grey"
emission = { radiance = [1.0, 1.0, 1.0], two_sided = true }
"#;
    let prep = parse(text);
    for integrator in [Method::Vcm, Method::Bdpt, Method::Lt] {
        let m = mean(&render(&prep, integrator, 12, 128));
        eprintln!("closed furnace, albedo 0.5, {integrator}: {m:.4} (expected 2)");
        assert!((m - 2.0).abs() < 0.02 * 2.0, "{integrator}: {m}");
    }
}

// ---------------------------------------------------------------------------------------------------------
// Against the path tracer

#[test]
fn means_agree_with_the_path_tracer_on_both_rooms() {
    for (room, methods) in [
        ("scenes/rooms/cornell-boxes.toml", &[Method::Vcm, Method::Bdpt, Method::Lt][..]),
        // Light tracing cannot see the spheres' reflections from the camera: it is not expected to agree there.
        ("scenes/rooms/cornell-spheres.toml", &[Method::Vcm, Method::Bdpt][..]),
    ] {
        let prep = load(room);
        let reference = mean(&render(&prep, Method::Path, 32, 4096));
        for &integrator in methods {
            let m = mean(&render(&prep, integrator, 32, 1024));
            let rel = m / reference - 1.0;
            eprintln!("{room}, {integrator}: mean {m:.5} vs path {reference:.5} ({:+.3} %)", 100.0 * rel);
            assert!(rel.abs() < 0.002, "{room}, {integrator}: mean {m} vs the path tracer's {reference}");
        }
    }
}

#[test]
fn error_falls_at_every_fourfold_step_of_iterations() {
    // The diffuse room: the path tracer's reference converges there (the caustic room's would carry its own
    // fireflies into every measurement).
    let prep = load("scenes/rooms/cornell-boxes.toml");
    let reference = render(&prep, Method::Path, 24, 16384);
    for integrator in [Method::Vcm, Method::Bdpt, Method::Lt] {
        let errors: Vec<f64> =
            [8, 32, 128, 512].iter().map(|&n| rel_mse(&render(&prep, integrator, 24, n), &reference)).collect();
        eprintln!("{integrator}: relMSE at 8, 32, 128, 512 iterations: {errors:?}");
        // An unbiased method's error falls 4× per step; vcm's merges, whose weight grows as the radius shrinks,
        // fall a little slower. Half is the bound.
        for w in errors.windows(2) {
            assert!(w[1] < 0.5 * w[0], "{integrator}: error {errors:?} does not fall fast enough");
        }
    }
}

/// The memory budget counts a light vertex as `LIGHT_VERTEX_BYTES`: it must not be smaller than the vertex.
#[test]
fn the_memory_budget_counts_a_whole_light_vertex() {
    use photon_core::prepare::budget::LIGHT_VERTEX_BYTES;
    use photon_core::render::vcm::LightVertex;
    assert!(std::mem::size_of::<LightVertex>() as u64 <= LIGHT_VERTEX_BYTES, "{}", std::mem::size_of::<LightVertex>());
}
