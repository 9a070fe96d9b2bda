//! Textures, bump and normal maps against what they must do: a checker albedo under uniform light gives each
//! pixel `albedo · E/π` (path tracing and progressive photon mapping), sRGB texels decode to the right linear
//! value, images appear upright and unmirrored on rectangles, spheres and OBJ quads, a flat bump map changes
//! nothing and a ramp tilts the normal by the analytic angle, bumped and normal-mapped spheres keep a white
//! furnace at its analytic value, and bad images are clear errors that name the file and the material.

#![allow(clippy::unwrap_used)]

use glam::{Vec2, Vec3A};
use photon_core::math::{Ray, fmath};
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::{Path, PathBuf};

/// A fresh folder for one test's files.
fn folder(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("photon-textures-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write_rgb(path: &Path, w: u32, h: u32, texel: impl Fn(u32, u32) -> [u8; 3]) {
    let mut data = Vec::with_capacity((w * h * 3) as usize);
    for y in 0..h {
        for x in 0..w {
            data.extend(texel(x, y));
        }
    }
    image::RgbImage::from_raw(w, h, data).unwrap().save(path).unwrap();
}

fn write_grey(path: &Path, w: u32, h: u32, texel: impl Fn(u32, u32) -> u8) {
    let data: Vec<u8> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| texel(x, y)).collect();
    image::GrayImage::from_raw(w, h, data).unwrap().save(path).unwrap();
}

fn load(dir: &Path, text: &str) -> Prepared {
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::load(&path).unwrap();
    Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap()
}

fn load_err(dir: &Path, text: &str) -> String {
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    match Scene::load(&path).and_then(|s| Prepared::new(&s, &path)) {
        Ok(_) => panic!("the scene loaded"),
        Err(e) => e.to_string(),
    }
}

/// The first colour of the material hit by the ray from `eye` towards `target`.
fn colour_at(prep: &Prepared, eye: Vec3A, target: Vec3A) -> Vec3A {
    let ray = Ray::new(eye, fmath::normalize(target - eye));
    let hit = prep.geometry.intersect(&ray, f32::INFINITY).unwrap();
    let m = &prep.materials[hit.material as usize];
    m.colors()[0].1.eval(hit.uv, hit.p, &prep.textures)
}

#[test]
fn an_srgb_texel_of_188_is_half_reflectance() {
    let dir = folder("srgb");
    write_rgb(&dir.join("grey.png"), 1, 1, |_, _| [188, 188, 188]);
    let prep = load(
        &dir,
        "[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\nwidth = 4\nheight = 4\n\
         [materials.m]\ntype = \"lambert\"\nalbedo = { image = \"grey.png\" }\n\
         [materials.lin]\ntype = \"lambert\"\nalbedo = { image = \"grey.png\", colorspace = \"linear\" }\n\
         [[objects]]\ntype = \"rect\"\ncenter = [0, 0, 0]\nnormal = [0, 0, 1]\nwidth = 2\nheight = 2\nmaterial = \"m\"\n",
    );
    // IEC 61966-2-1: ((188/255 + 0.055)/1.055)^2.4 = 0.50289. Half reflectance lies between codes 187 (0.4969)
    // and 188, 0.58 % above it: no 8-bit code is within 0.5 % of 0.5, so the decoding is checked against the
    // curve itself, and 188 is the code nearest 0.5.
    let want = ((188.0f64 / 255.0 + 0.055) / 1.055).powf(2.4);
    let c = colour_at(&prep, Vec3A::new(0.0, 0.0, 3.0), Vec3A::ZERO);
    for v in c.to_array() {
        assert!((f64::from(v) - want).abs() / want < 1e-5, "sRGB 188/255 decoded to {v}, expected {want}");
        assert!((f64::from(v) - 0.5).abs() < 0.0029, "{v}");
    }
    let below = ((187.0f64 / 255.0 + 0.055) / 1.055).powf(2.4);
    assert!((want - 0.5).abs() < (below - 0.5).abs());
    // The same file read as linear data: 188/255.
    let lin = prep.materials.iter().find(|m| matches!(m.colors()[0].1.image(), Some(r) if r.colorspace.is_some()));
    let r = lin.unwrap().colors()[0].1.eval(Vec2::splat(0.5), Vec3A::ZERO, &prep.textures);
    assert!((r.x - 188.0 / 255.0).abs() < 1e-6, "{r}");
}

#[test]
fn jpeg_and_float_exr_images_read_and_float_texels_above_one_clamp_as_reflectances() {
    let dir = folder("formats");
    // A flat JPEG: 8×8 blocks of one value survive compression.
    let grey = image::RgbImage::from_pixel(16, 16, image::Rgb([188, 188, 188]));
    grey.save_with_format(dir.join("grey.jpg"), image::ImageFormat::Jpeg).unwrap();
    // A float image: left half 0.25, right half 2.0 (HDR data used as an albedo).
    let data: Vec<f32> = (0..4 * 2).flat_map(|i| if i % 4 < 2 { [0.25f32; 3] } else { [2.0f32; 3] }).collect();
    image::Rgb32FImage::from_raw(4, 2, data).unwrap().save(dir.join("hdr.exr")).unwrap();
    let prep = load(
        &dir,
        "[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\nwidth = 4\nheight = 4\n\
         [materials.j]\ntype = \"lambert\"\nalbedo = { image = \"grey.jpg\" }\n\
         [materials.h]\ntype = \"lambert\"\nalbedo = { image = \"hdr.exr\", filter = \"nearest\" }\n\
         [[objects]]\ntype = \"rect\"\ncenter = [-1, 0, 0]\nnormal = [0, 0, 1]\nwidth = 1\nheight = 1\nmaterial = \"j\"\n\
         [[objects]]\ntype = \"rect\"\ncenter = [1, 0, 0]\nnormal = [0, 0, 1]\ntangent = [1, 0, 0]\nwidth = 1\n\
         height = 1\nmaterial = \"h\"\n",
    );
    let eye = Vec3A::new(0.0, 0.0, 3.0);
    let j = colour_at(&prep, eye, Vec3A::new(-1.0, 0.0, 0.0));
    assert!((j.x - 0.5029).abs() < 0.01, "JPEG texel 188 read as {j}");
    let left = colour_at(&prep, eye, Vec3A::new(0.75, 0.0, 0.0));
    let right = colour_at(&prep, eye, Vec3A::new(1.25, 0.0, 0.0));
    assert_eq!((left.x, right.x), (0.25, 1.0), "float texels are linear, and a reflectance reads 2.0 as 1");
}

/// A 4×2 image whose texel (column c, row r from the top) has red 60·c and green 200·r, read as linear data
/// with nearest filtering, so every lookup names its texel.
fn texel_code(c: Vec3A) -> (u32, u32) {
    ((c.x * 255.0 / 60.0).round() as u32, (c.y * 255.0 / 200.0).round() as u32)
}

const CODED: &str = "{ image = \"coded.png\", filter = \"nearest\", colorspace = \"linear\" }";

#[test]
fn images_are_upright_and_unmirrored_on_rects_spheres_and_obj_quads() {
    let dir = folder("uv");
    write_rgb(&dir.join("coded.png"), 4, 2, |x, y| [60 * x as u8, 200 * y as u8, 0]);
    // An OBJ quad facing +z with the usual texture coordinates: (0, 0) at its bottom-left corner.
    std::fs::write(
        dir.join("quad.obj"),
        "v -1 -0.5 0\nv 1 -0.5 0\nv 1 0.5 0\nv -1 0.5 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    let head = format!(
        "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\nwidth = 4\nheight = 4\n\
         [materials.coded]\ntype = \"lambert\"\nalbedo = {CODED}\n"
    );
    let eye = Vec3A::new(0.0, 0.0, 5.0);
    // Seen from the eye (+x to the right, +y up), the texel centres of the whole image.
    for shape in [
        "type = \"rect\"\ncenter = [0, 0, 0]\nnormal = [0, 0, 1]\ntangent = [1, 0, 0]\nwidth = 2\nheight = 1",
        "type = \"mesh\"\nfile = \"quad.obj\"",
    ] {
        let prep = load(&dir, &format!("{head}[[objects]]\n{shape}\nmaterial = \"coded\"\n"));
        for (c, r) in [(0, 0), (1, 0), (2, 0), (3, 0), (0, 1), (3, 1)] {
            let target = Vec3A::new(-1.0 + 0.5 * (c as f32 + 0.5), 0.5 - 0.5 * (r as f32 + 0.5), 0.0);
            let got = texel_code(colour_at(&prep, eye, target));
            assert_eq!(got, (c, r), "{shape}: texel at {target}");
        }
    }
    // A sphere shows the half u ∈ (0, ½) of the image to +z, its left quarter on the left: columns 0 and 1.
    let prep = load(
        &dir,
        &format!("{head}[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"coded\"\n"),
    );
    for (x, y, want) in [(-0.5, 0.4, (0, 0)), (0.5, 0.4, (1, 0)), (-0.5, -0.4, (0, 1)), (0.5, -0.4, (1, 1))] {
        let got = texel_code(colour_at(&prep, eye, Vec3A::new(x, y, 0.9)));
        assert_eq!(got, want, "sphere at ({x}, {y})");
    }
}

/// A camera-facing rectangle, larger than the view, whose checker cells fall on pixel edges, lit by a point
/// light of intensity I = 100π on its axis at distance D = 10 (behind the pinhole camera, which casts no shadow):
/// the irradiance at `(x, y)` is `E = I·D/(D² + x² + y²)^{3/2}`, within 1.5 % of uniform over the view, and known
/// at every pixel. Nothing else is in the scene, so no light comes back: `L = albedo·E/π` exactly.
fn checker_scene(integrator: &str, extra: &str) -> String {
    format!(
        "[camera]\neye = [0, 0, 1]\nlook_at = [0, 0, 0]\nfov = 90\nwidth = 16\nheight = 16\n\
         [render]\nintegrator = \"{integrator}\"\nspp = 16\n{extra}\n\
         [materials.board]\ntype = \"lambert\"\nalbedo = {{ checker = [[0.2, 0.5, 0.8], 0.9], scale = 8 }}\n\
         [[objects]]\ntype = \"rect\"\ncenter = [0, 0, 0]\nnormal = [0, 0, 1]\ntangent = [1, 0, 0]\nwidth = 4\n\
         height = 4\nmaterial = \"board\"\n\
         [[lights]]\ntype = \"point\"\nposition = [0, 0, 10]\nintensity = [314.159265, 314.159265, 314.159265]\n"
    )
}

#[test]
fn a_checker_albedo_under_uniform_light_gives_albedo_times_irradiance_over_pi() {
    let dir = folder("checker");
    for (integrator, extra) in [("path", ""), ("progressive", "[render.photons]\npass_photons = 20000\npasses = 8\n")] {
        let prep = load(&dir, &checker_scene(integrator, extra));
        let img = render_image(&prep, &|_| {});
        // The view spans [−1, 1]² of the rectangle: u = ¼ + (x + ½)/32 across 16 pixels, cells of ⅛ in u (4
        // pixels) starting on pixel edges.
        let (mut worst, mut signed) = (0.0f64, 0.0f64);
        for y in 0..16u32 {
            for x in 0..16u32 {
                let (u, v) = (0.25 + (x as f32 + 0.5) / 32.0, 0.75 - (y as f32 + 0.5) / 32.0);
                let even = ((u * 8.0).floor() + (v * 8.0).floor()) as i32 % 2 == 0;
                let albedo = if even { [0.2, 0.5, 0.8] } else { [0.9, 0.9, 0.9] };
                let (px, py) = (f64::from(4.0 * u - 2.0), f64::from(4.0 * v - 2.0));
                let e = 100.0 * std::f64::consts::PI * 10.0 / (100.0 + px * px + py * py).powf(1.5);
                for (k, a) in albedo.iter().enumerate() {
                    let want = a * e / std::f64::consts::PI;
                    let got = f64::from(img.pixels[((y * 16 + x) * 3) as usize + k]);
                    worst = worst.max((got - want).abs() / want);
                    signed += (got - want) / want;
                }
            }
        }
        eprintln!(
            "{integrator}: worst pixel error {:.4} %, mean signed {:.4} %",
            worst * 100.0,
            signed * 100.0 / 768.0
        );
        assert!(worst < 0.01, "{integrator}: a pixel is {:.2} % off albedo · E/π", worst * 100.0);
    }
}

#[test]
fn a_flat_bump_map_changes_nothing_and_a_ramp_tilts_the_normal_by_the_analytic_angle() {
    let dir = folder("bump");
    write_grey(&dir.join("flat.png"), 16, 16, |_, _| 117);
    // A ramp across the width: texel x holds x, so the height rises by 1/255 per texel of 1/256 in u.
    write_grey(&dir.join("ramp.png"), 256, 4, |x, _| x as u8);
    let scene = |bump: &str| {
        format!(
            "[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\nwidth = 16\nheight = 16\n[render]\nspp = 8\n\
             [materials.wall]\ntype = \"phong\"\ndiffuse = 0.5\nspecular = 0.3\n{bump}\n\
             [[objects]]\ntype = \"rect\"\ncenter = [0, 0, 0]\nnormal = [0, 0, 1]\ntangent = [1, 0, 0]\nwidth = 2\n\
             height = 2\nmaterial = \"wall\"\n\
             [[objects]]\ntype = \"sphere\"\ncenter = [0.3, 0.2, 0.5]\nradius = 0.3\nmaterial = \"wall\"\n\
             [[lights]]\ntype = \"point\"\nposition = [1, 1, 2]\nintensity = [4, 4, 4]\n"
        )
    };
    let plain = render_image(&load(&dir, &scene("")), &|_| {}).pixels;
    let flat = render_image(&load(&dir, &scene("bump = { image = \"flat.png\", strength = 0.3 }")), &|_| {}).pixels;
    assert!(plain.iter().zip(&flat).all(|(a, b)| a.to_bits() == b.to_bits()), "a flat bump map changed the image");

    // Width w = 2, strength s: ∂d/∂u = s·256/255, so n' ∝ w·n − s·(256/255)·t and tilts by atan(s·256/255 / w)
    // away from +x.
    for strength in [0.2f32, 1.0, -0.7] {
        let prep = load(&dir, &scene(&format!("bump = {{ image = \"ramp.png\", strength = {strength} }}")));
        let ray = Ray::new(Vec3A::new(0.0, 0.0, 3.0), -Vec3A::Z);
        let hit = prep.geometry.intersect(&ray, f32::INFINITY).unwrap();
        let ns = prep.materials[hit.material as usize].shading_normal(&hit, &prep.textures);
        let want = (strength * 256.0 / 255.0 / 2.0).atan();
        let got = fmath::atan2(-ns.x, ns.z);
        assert!((got - want).abs() < 1e-4, "strength {strength}: tilt {got} rad, expected {want}");
        assert!(ns.y.abs() < 1e-6 && (ns.length() - 1.0).abs() < 1e-5, "{ns}");
    }

    // And the integrators shade with the bent normal: a Lambert wall (ρ = 0.5) under a point light of intensity
    // I = 1 at (0, 0, 2) shows L = ρ/π · I · (ŵ·n')/d² with n' = (−k, 0, 1)/√(1 + k²), k = s·(256/255)/w. The
    // camera sees [−0.75, 0.75]² of the wall; nothing else reflects light back.
    let strength = 0.6f32;
    let text = format!(
        "[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 28.0724869\nwidth = 12\nheight = 12\n\
         [render]\nspp = 256\n\
         [materials.wall]\ntype = \"lambert\"\nalbedo = 0.5\nbump = {{ image = \"ramp.png\", strength = {strength} }}\n\
         [[objects]]\ntype = \"rect\"\ncenter = [0, 0, 0]\nnormal = [0, 0, 1]\ntangent = [1, 0, 0]\nwidth = 2\n\
         height = 2\nmaterial = \"wall\"\n\
         [[lights]]\ntype = \"point\"\nposition = [0, 0, 2]\nintensity = [1, 1, 1]\n"
    );
    let img = render_image(&load(&dir, &text), &|_| {});
    let k = f64::from(strength) * 256.0 / 255.0 / 2.0;
    let n = [-k / (1.0 + k * k).sqrt(), 0.0, 1.0 / (1.0 + k * k).sqrt()];
    let mut worst = 0.0f64;
    for y in 0..12u32 {
        for x in 0..12u32 {
            // tan(14.036°) = 0.25: the view spans ±0.75 at distance 3. The pixel is the mean over its footprint
            // (a 16 × 16 grid of points; the camera's samples are uniform over the pixel).
            let mut want = 0.0;
            for (i, j) in (0..16).flat_map(|i| (0..16).map(move |j| (i, j))) {
                let px = -0.75 + 1.5 * (f64::from(x) + (f64::from(i) + 0.5) / 16.0) / 12.0;
                let py = 0.75 - 1.5 * (f64::from(y) + (f64::from(j) + 0.5) / 16.0) / 12.0;
                let d = [-px, -py, 2.0];
                let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                let cos = (d[0] * n[0] + d[2] * n[2]) / d2.sqrt();
                want += 0.5 / std::f64::consts::PI * cos / d2 / 256.0;
            }
            let got = f64::from(img.pixels[((y * 12 + x) * 3) as usize]);
            worst = worst.max((got - want).abs() / want);
        }
    }
    eprintln!("bumped wall under a point light: worst pixel {:.3} % from the bent normal's cosine law", worst * 100.0);
    assert!(worst < 0.01, "a bumped pixel is {:.2} % off", worst * 100.0);
}

/// Inside a closed sphere of albedo ρ emitting Le, a ball of albedo ρ emitting Le shows `Le/(1 − ρ)`, however
/// its shading normals are bent (the shading cosine integrates to π over the geometric hemisphere for any tilt).
#[test]
fn bumped_and_normal_mapped_spheres_keep_a_white_furnace_at_its_analytic_value() {
    let dir = folder("furnace");
    // Bumps of a few texels, steep enough to tilt normals by tens of degrees.
    write_grey(&dir.join("bumps.png"), 64, 32, |x, y| {
        let (fx, fy) = (x as f32 * 0.7, y as f32 * 1.3);
        (127.0 + 120.0 * (fmath::sin(fx) * fmath::cos(fy))) as u8
    });
    // Normals tilted by up to ~40° in varying directions.
    write_rgb(&dir.join("normals.png"), 32, 32, |x, y| {
        let (a, b) = (fmath::sin(x as f32 * 0.9) * 0.6, fmath::cos(y as f32 * 0.8) * 0.6);
        let n = fmath::normalize(Vec3A::new(a, b, 1.0));
        (n * 0.5 + Vec3A::splat(0.5)).to_array().map(|c| (c * 255.0).round() as u8)
    });
    for (integrator, extra) in [
        ("path", "spp = 64\nmax_depth = 1000"),
        ("progressive", "max_depth = 1000\n[render.photons]\npass_photons = 20000\npasses = 128\nradius = 0.15"),
    ] {
        for detail in
            ["", "bump = { image = \"bumps.png\", strength = 0.05 }", "normal_map = { image = \"normals.png\" }"]
        {
            let text = format!(
                "[camera]\neye = [0, 0, 1.6]\nlook_at = [0, 0, 0]\nfov = 30\nwidth = 12\nheight = 12\n\
                 [render]\nintegrator = \"{integrator}\"\n{extra}\n\
                 [materials.shell]\ntype = \"lambert\"\nalbedo = 0.5\n\
                 [materials.ball]\ntype = \"lambert\"\nalbedo = 0.5\n{detail}\n\
                 [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 3\nmaterial = \"shell\"\n\
                 emission = {{ radiance = [1, 1, 1], two_sided = true }}\n\
                 [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 0.6\nmaterial = \"ball\"\n\
                 emission = {{ radiance = [1, 1, 1] }}\n"
            );
            let img = render_image(&load(&dir, &text), &|_| {});
            // The ball fills the view (its silhouette spans ±0.43 rad; the view ±0.26).
            let mean = img.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / img.pixels.len() as f64;
            let rel = (mean - 2.0).abs() / 2.0;
            eprintln!("{integrator}, {detail}: {mean:.4} (expected 2)");
            assert!(rel < 0.02, "{integrator}, {detail}: mean {mean}, expected 2 within 2 %");
        }
    }
}

#[test]
fn bad_images_name_the_file_and_the_material() {
    let dir = folder("bad");
    std::fs::write(dir.join("empty.png"), b"").unwrap();
    std::fs::write(dir.join("corrupt.png"), b"\x89PNG\r\n\x1a\nthis is not a png").unwrap();
    // A PNG whose header says 0×0.
    let mut zero = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\0\0\0\0\0\0\x08\x02\0\0\0".to_vec();
    zero.extend(crc32(&zero[12..29]).to_be_bytes());
    std::fs::write(dir.join("zero.png"), zero).unwrap();
    write_rgb(&dir.join("big.png"), 700, 700, |x, y| [x as u8, y as u8, 0]);
    std::fs::write(dir.join("flat.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    write_rgb(&dir.join("ok.png"), 2, 2, |_, _| [1, 2, 3]);
    let scene = |albedo: &str, object: &str, limits: &str| {
        format!(
            "[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\nwidth = 4\nheight = 4\n{limits}\n\
             [materials.wood]\ntype = \"lambert\"\nalbedo = {albedo}\n[[objects]]\n{object}\nmaterial = \"wood\"\n"
        )
    };
    let sphere = "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1";
    for (file, limits, needle) in [
        ("missing.png", "", "cannot read"),
        ("empty.png", "", "empty"),
        ("corrupt.png", "", "cannot decode"),
        ("zero.png", "", ""),
        ("big.png", "[limits]\ntexture_mib = 1", "larger"),
    ] {
        let e = load_err(&dir, &scene(&format!("{{ image = \"{file}\" }}"), sphere, limits));
        eprintln!("{file}: {e}");
        assert!(e.contains("scene.toml") && e.contains("materials.wood.albedo.image"), "{file}: {e}");
        assert!(e.contains(file) && e.contains(needle), "{file}: {e}");
    }
    let e = load_err(&dir, &scene("{ image = \"ok.png\" }", "type = \"mesh\"\nfile = \"flat.obj\"", ""));
    assert!(e.contains("flat.obj") && e.contains("`wood`") && e.contains("texture coordinates"), "{e}");
    for (albedo, needle) in [
        ("{ image = \"ok.png\", checker = [0, 1] }", "not both"),
        ("{ checker = [0, 2] }", "[0, 1]"),
        ("{ image = \"ok.png\", scale = 0 }", "scale"),
        ("{ image = \"ok.png\", wrap = \"mirror\" }", "mirror"),
        ("{ image = \"ok.png\", strength = 1 }", "bump"),
        ("{ imag = \"ok.png\" }", "imag"),
    ] {
        let e = load_err(&dir, &scene(albedo, sphere, ""));
        assert!(e.contains(needle) && e.contains("scene.toml"), "{albedo}: {e}");
    }
}

/// CRC-32 (ISO 3309) of a PNG chunk's type and data.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
        }
    }
    !c
}
