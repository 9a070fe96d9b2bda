//! The origin's chapter-4 experiment: one scene rendered by direct visualisation of the global photon map
//! (`photon-map`) with every density-estimation kernel, gathering by a fixed radius and by the k nearest
//! photons, each tile scored against a path-traced reference.
//!
//! ```text
//! cargo run --release -p photon-core --example kernel_figure -- scenes/cornell.toml docs/figures/kernels
//! ```
//!
//! Writes into the output folder: `reference.exr` (linear, reusable with `--reference`) and `reference.png`,
//! one PNG per tile, `kernels.csv`, and `kernels.svg`, a grid with the PNG tiles embedded as data URIs
//! (rows: radius, k-nearest; columns: kernels). It prints a markdown table of the same numbers.
//!
//! Every tile reads the same global photon map (same photon count and seed), built once and timed apart
//! from rendering, and the same camera samples, so the tiles differ only in how the photons are gathered and
//! weighted. Each tile also has an untimed twin rendered with the next seed (its own photon map and pixel
//! samples), which splits its error into variance and bias (see [`Scores`]).
//!
//! Options (defaults in brackets): `--size N` [192] square image side, `--spp N` [32] samples per pixel of the
//! tiles, `--photons N` [200000] global photon paths, `--radius R` [0.05] fixed gather radius, `--k N` [100]
//! photons per k-nearest estimate, `--max-radius R` [0.15] k-nearest radius cap, `--seed N` [the scene's]
//! seed of the photons and the tiles' pixel samples, `--ref-spp N` [4096] samples per pixel of the reference,
//! `--reference FILE` an EXR reference to reuse instead of rendering one.
//!
//! Tiles take 32 samples per pixel: at 4, the tiles' pixel-sampling noise alone (RMSE ≈ 0.087, measured
//! with two seeds at 192 × 192 on `cornell.toml`) exceeds the whole error of a 32-sample tile (≈ 0.023) and
//! hides the kernels' differences.
//!
//! The reference is rendered as two halves with different seeds; `E[(a − b)²] / 4` over the halves `a`, `b` is
//! the variance of their mean, the reference's own noise. Every measured MSE includes it (the reference noise
//! is independent of the tile's error), so it is the floor below which no tile can score. It is written to
//! `reference.txt` beside the EXR and read back with `--reference` when present.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use photon_core::image_io::Image;
use photon_core::method::Method;
use photon_core::photon::Kernel;
use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::{GatherMode, Scene};

type Error = Box<dyn std::error::Error>;

/// The first block of kernels (the origin's four), then the second.
const KERNELS: [Kernel; 6] =
    [Kernel::Box, Kernel::Linear, Kernel::Quadratic, Kernel::Gaussian, Kernel::Cone, Kernel::Epanechnikov];
/// Columns before the gap between the two blocks.
const FIRST_BLOCK: usize = 4;
const GATHERS: [GatherMode; 2] = [GatherMode::Radius, GatherMode::KNearest];
/// Added to the scene's seed for the reference's two halves.
const REFERENCE_SEED_OFFSET: u64 = 1_000_000;

/// Command-line options.
struct Options {
    scene: PathBuf,
    out: PathBuf,
    size: u32,
    spp: u32,
    photons: u32,
    radius: f32,
    k: u32,
    max_radius: f32,
    seed: Option<u64>,
    ref_spp: u32,
    reference: Option<PathBuf>,
}

impl Options {
    fn parse() -> Result<Self, Error> {
        let usage = "usage: kernel_figure SCENE OUT_DIR [--size N] [--spp N] [--photons N] [--radius R] [--k N] \
                     [--max-radius R] [--seed N] [--ref-spp N] [--reference FILE.exr]";
        let mut positional = Vec::new();
        let mut o = Options {
            scene: PathBuf::new(),
            out: PathBuf::new(),
            size: 192,
            spp: 32,
            photons: 200_000,
            radius: 0.05,
            k: 100,
            max_radius: 0.15,
            seed: None,
            ref_spp: 4096,
            reference: None,
        };
        let mut args = std::env::args().skip(1);
        while let Some(a) = args.next() {
            if !a.starts_with("--") {
                positional.push(PathBuf::from(a));
                continue;
            }
            let value = args.next().ok_or_else(|| format!("{a} needs a value\n{usage}"))?;
            let bad = |e: &dyn std::fmt::Display| format!("{a} {value}: {e}");
            match a.as_str() {
                "--size" => o.size = value.parse().map_err(|e| bad(&e))?,
                "--spp" => o.spp = value.parse().map_err(|e| bad(&e))?,
                "--photons" => o.photons = value.parse().map_err(|e| bad(&e))?,
                "--radius" => o.radius = value.parse().map_err(|e| bad(&e))?,
                "--k" => o.k = value.parse().map_err(|e| bad(&e))?,
                "--max-radius" => o.max_radius = value.parse().map_err(|e| bad(&e))?,
                "--seed" => o.seed = Some(value.parse().map_err(|e| bad(&e))?),
                "--ref-spp" => o.ref_spp = value.parse().map_err(|e| bad(&e))?,
                "--reference" => o.reference = Some(PathBuf::from(value)),
                _ => return Err(format!("unknown option {a}\n{usage}").into()),
            }
        }
        let [scene, out] = <[PathBuf; 2]>::try_from(positional).map_err(|_| usage.to_string())?;
        (o.scene, o.out) = (scene, out);
        if o.size == 0 || o.spp == 0 || o.ref_spp < 2 || o.photons == 0 || o.k < 2 {
            return Err(format!("sizes and counts must be positive (--ref-spp ≥ 2, --k ≥ 2)\n{usage}").into());
        }
        if !(o.radius > 0.0 && o.max_radius > 0.0) {
            return Err("radii must be positive".into());
        }
        Ok(o)
    }
}

/// One rendered tile and its scores.
struct Tile {
    kernel: Kernel,
    gather: GatherMode,
    file: String,
    render_s: f64,
    scores: Scores,
}

/// A tile's error against the reference, and its split into variance and bias.
///
/// With `a` the tile, `b` its twin (the next seed: other photons, other pixel samples) and `r` the reference of
/// own noise `ρ`: `E[(a − r)²] = bias² + σ² + ρ` and `E[(a − b)²] = 2σ²`, so `σ²` is half the mean squared
/// difference of the twins and `bias² = ½(MSE_a + MSE_b) − σ² − ρ`. The relative forms divide each term by
/// `r² + 0.01` first. Either bias² is an estimate and can come out slightly negative when bias is tiny.
struct Scores {
    /// RMSE of `a` (the tile shown).
    rmse: f64,
    /// Relative MSE of `a`.
    rel_mse: f64,
    /// σ²: photon noise plus pixel-sampling noise.
    variance: f64,
    /// bias² (systematic error of the estimate).
    bias2: f64,
    /// σ² relative.
    rel_variance: f64,
    /// bias² relative.
    rel_bias2: f64,
}

impl Scores {
    fn new(a: &[f32], b: &[f32], reference: &[f32], (rho, rel_rho): (f64, f64)) -> Self {
        let (mse_a, rel_a) = mean_squares(a, reference, reference);
        let (mse_b, rel_b) = mean_squares(b, reference, reference);
        let (d, rel_d) = mean_squares(a, b, reference);
        let (variance, rel_variance) = (d / 2.0, rel_d / 2.0);
        Scores {
            rmse: mse_a.sqrt(),
            rel_mse: rel_a,
            variance,
            bias2: 0.5 * (mse_a + mse_b) - variance - rho,
            rel_variance,
            rel_bias2: 0.5 * (rel_a + rel_b) - rel_variance - rel_rho,
        }
    }
}

fn kernel_name(k: Kernel) -> &'static str {
    match k {
        Kernel::Box => "box",
        Kernel::Cone => "cone",
        Kernel::Epanechnikov => "epanechnikov",
        Kernel::Gaussian => "gaussian",
        Kernel::Linear => "linear",
        Kernel::Quadratic => "quadratic",
    }
}

fn gather_name(g: GatherMode) -> &'static str {
    match g {
        GatherMode::Radius => "radius",
        GatherMode::KNearest => "k-nearest",
    }
}

/// The mean of `(x − y)²` and of `(x − y)² / (r² + 0.01)` over every channel of every pixel, in f64: with
/// `y = r` the MSE and the relative MSE of `x` against the reference `r`.
fn mean_squares(x: &[f32], y: &[f32], reference: &[f32]) -> (f64, f64) {
    let n = x.len().max(1) as f64;
    let (mut se, mut rel) = (0.0f64, 0.0f64);
    for ((&a, &b), &r) in x.iter().zip(y).zip(reference) {
        let (d, r) = (f64::from(a) - f64::from(b), f64::from(r));
        se += d * d;
        rel += d * d / (r * r + 0.01);
    }
    (se / n, rel / n)
}

/// Standard base64 (RFC 4648, with padding) of `bytes`.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], chunk.get(1).copied().unwrap_or(0), chunk.get(2).copied().unwrap_or(0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(char::from(ALPHABET[(n >> (18 - 6 * i)) as usize & 63]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The path-traced reference.
struct Reference {
    image: Image,
    /// Its own MSE and relative MSE, when known.
    noise: Option<(f64, f64)>,
    /// Its samples per pixel, as text (`?` when unknown).
    spp: String,
}

/// The reference: read from `--reference`, or path-traced in two halves.
fn reference(o: &Options, scene: &Scene) -> Result<Reference, Error> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    if let Some(path) = &o.reference {
        let img = Image::read(path)?;
        if (img.width, img.height) != (w, h) {
            return Err(format!("{}: {}×{}, expected {w}×{h}", path.display(), img.width, img.height).into());
        }
        let note = std::fs::read_to_string(path.with_extension("txt")).ok();
        let value = |key: &str| note.as_deref().and_then(|t| key_value(t, key)).and_then(|v| v.parse().ok());
        let noise = value("noise_mse").zip(value("noise_rel_mse"));
        let spp = note.as_deref().and_then(|t| key_value(t, "spp")).unwrap_or("?").to_string();
        println!("reference: {} ({spp} spp)", path.display());
        return Ok(Reference { image: img, noise, spp });
    }
    let mut settings = scene.render.clone();
    settings.integrator = Method::Path;
    settings.spp = o.ref_spp / 2;
    // Streams apart from the tiles' (seed and seed + 1), so the reference's noise is independent of theirs.
    settings.seed = settings.seed.wrapping_add(REFERENCE_SEED_OFFSET);
    let mut s = scene.clone();
    s.render = settings.clone();
    let mut prep = Prepared::new(&s, &o.scene)?;
    let t = Instant::now();
    let a = render_image(&prep, &|_| {}).pixels;
    prep.settings.seed = prep.settings.seed.wrapping_add(1);
    let b = render_image(&prep, &|_| {}).pixels;
    let secs = t.elapsed().as_secs_f64();
    let pixels: Vec<f32> = a.iter().zip(&b).map(|(x, y)| 0.5 * (x + y)).collect();
    // E[(a − b)²] = 2σ² for halves of variance σ²; their mean has variance σ²/2 = E[(a − b)²]/4.
    let (d, rel_d) = mean_squares(&a, &b, &pixels);
    let noise = (d / 4.0, rel_d / 4.0);
    let spp = (2 * settings.spp).to_string();
    println!("reference: path tracer, {spp} spp, {secs:.1} s, own RMSE ≈ {:.5}", noise.0.sqrt());
    let img = Image { width: w, height: h, pixels };
    let path = o.out.join("reference.exr");
    img.write(&path, 0.0)?;
    std::fs::write(
        path.with_extension("txt"),
        format!("spp = {spp}\nnoise_mse = {:e}\nnoise_rel_mse = {:e}\nseconds = {secs:.1}\n", noise.0, noise.1),
    )?;
    Ok(Reference { image: img, noise: Some(noise), spp })
}

/// The value of `key = value` in a small text file.
fn key_value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.trim() == key).then_some(v.trim())
    })
}

fn main() -> Result<(), Error> {
    let o = Options::parse()?;
    std::fs::create_dir_all(&o.out)?;
    let mut scene = Scene::load(&o.scene)?;
    scene.camera.width = o.size;
    scene.camera.height = o.size;
    let exposure = scene.render.exposure;
    let Reference { image: reference, noise: ref_noise, spp: ref_spp } = reference(&o, &scene)?;
    reference.write(&o.out.join("reference.png"), exposure)?;

    // Prepare without photons, then build the global map once and time it on its own. A second preparation
    // with the next seed (its own photons and pixel samples) gives every tile an independent twin, for the
    // split of the error into variance and bias.
    scene.render.integrator = Method::Path;
    scene.render.spp = o.spp;
    scene.render.seed = o.seed.unwrap_or(scene.render.seed);
    scene.render.photons.global = o.photons;
    let mut prep = Prepared::new(&scene, &o.scene)?;
    prep.settings.integrator = Method::PhotonMap;
    let mut twin = prep.clone();
    twin.settings.seed = twin.settings.seed.wrapping_add(1);
    let t = Instant::now();
    prep.photons = Some(prep.build_photon_maps(&photon_core::run::Guard::unbounded())?);
    let build_s = t.elapsed().as_secs_f64();
    twin.photons = Some(twin.build_photon_maps(&photon_core::run::Guard::unbounded())?);
    let stored = prep.photons.as_ref().map_or(0, |m| m.global.len());
    println!("global map: {} paths, {stored} photons stored, built in {build_s:.2} s", o.photons);

    let mut tiles = Vec::new();
    for gather in GATHERS {
        for kernel in KERNELS {
            for p in [&mut prep, &mut twin] {
                configure(p, &o, gather, kernel);
            }
            let t = Instant::now();
            let a = render_image(&prep, &|_| {}).pixels;
            let render_s = t.elapsed().as_secs_f64();
            let b = render_image(&twin, &|_| {}).pixels;
            // A reference of unknown noise (an EXR without its `reference.txt`) leaves that noise in bias².
            let scores = Scores::new(&a, &b, &reference.pixels, ref_noise.unwrap_or((0.0, 0.0)));
            let file = format!("{}-{}.png", kernel_name(kernel), gather_name(gather));
            Image { width: o.size, height: o.size, pixels: a }.write(&o.out.join(&file), exposure)?;
            eprintln!("{file}: {render_s:.2} s, RMSE {:.5}, relMSE {:.5}", scores.rmse, scores.rel_mse);
            tiles.push(Tile { kernel, gather, file, render_s, scores });
        }
    }

    let radius_of = |g: GatherMode| if g == GatherMode::Radius { o.radius } else { o.max_radius };
    let mut csv = String::from(
        "kernel,gather,photons,k,radius,build_s,render_s,rmse,rel_mse,variance,bias2,rel_variance,rel_bias2\n",
    );
    let mut table = String::from(
        "| kernel | gather | photons | k | radius | build s | render s | RMSE | relMSE | rel. variance | rel. bias² |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for t in &tiles {
        let k = if t.gather == GatherMode::KNearest { o.k.to_string() } else { String::new() };
        let (kn, gn, r) = (kernel_name(t.kernel), gather_name(t.gather), radius_of(t.gather));
        let sc = &t.scores;
        writeln!(
            csv,
            "{kn},{gn},{},{k},{r},{build_s:.3},{:.3},{:.6},{:.6},{:.3e},{:.3e},{:.3e},{:.3e}",
            o.photons, t.render_s, sc.rmse, sc.rel_mse, sc.variance, sc.bias2, sc.rel_variance, sc.rel_bias2
        )?;
        let k = if k.is_empty() { "–".to_string() } else { k };
        let r = if t.gather == GatherMode::KNearest { format!("≤ {r}") } else { r.to_string() };
        writeln!(
            table,
            "| {kn} | {gn} | {} | {k} | {r} | {build_s:.2} | {:.1} | {:.4} | {:.5} | {:.5} | {:.5} |",
            o.photons, t.render_s, sc.rmse, sc.rel_mse, sc.rel_variance, sc.rel_bias2
        )?;
    }
    std::fs::write(o.out.join("kernels.csv"), csv)?;
    println!();
    print!("{table}");
    let ref_note = match ref_noise {
        Some((n, _)) => format!("RMSE ≈ {:.4}", n.sqrt()),
        None => "unknown".to_string(),
    };
    let noise_note = format!(
        "Reference's own noise {ref_note}. Captions: the tile's RMSE and relMSE, and its render time (the photon \
         map took {build_s:.2} s). Outlined: the lowest RMSE of its row."
    );
    println!("\nreference: path tracer, {ref_spp} spp. {noise_note}");
    let title = [
        format!(
            "Cornell box, photon-map (direct visualisation of the global map), {} photon paths ({stored} stored), \
             {} spp, {}×{}; radius: r = {}; k-nearest: k = {}, r ≤ {}. Reference: path tracer, {ref_spp} spp.",
            o.photons, o.spp, o.size, o.size, o.radius, o.k, o.max_radius
        ),
        noise_note,
    ];
    let reference_label = [format!("path tracer, {ref_spp} spp:"), format!("own noise {ref_note}")];
    let svg = compose_svg(&o.out, o.size, &tiles, &title, &reference_label)?;
    std::fs::write(o.out.join("kernels.svg"), svg)?;
    println!("wrote {}", o.out.join("kernels.svg").display());
    Ok(())
}

/// Sets the gather and the kernel of a tile in `prep`'s settings and in its photon maps' estimator.
fn configure(prep: &mut Prepared, o: &Options, gather: GatherMode, kernel: Kernel) {
    let ph = &mut prep.settings.photons;
    ph.gather = gather;
    ph.kernel = kernel;
    ph.k = o.k;
    ph.radius = Some(if gather == GatherMode::Radius { o.radius } else { o.max_radius });
    let estimator = prep.estimator();
    if let Some(maps) = prep.photons.as_mut() {
        maps.estimator = estimator;
    }
}

/// The figure: the reference on the left, then one row per gather mode and one column per kernel, the PNG
/// tiles embedded as data URIs, the lowest RMSE of each row outlined.
fn compose_svg(
    dir: &Path,
    size: u32,
    tiles: &[Tile],
    title: &[String],
    reference_label: &[String; 2],
) -> Result<String, Error> {
    let (margin, gap, block_gap, caption_h, title_h) = (10u32, 8u32, 16u32, 30u32, 14 * title.len() as u32);
    let cell_w = size + gap;
    let cell_h = size + caption_h + gap;
    let col_x = |c: usize| {
        let c = c as u32;
        let extra = if c > FIRST_BLOCK as u32 { block_gap } else { 0 };
        margin + c * cell_w + if c > 0 { block_gap } else { 0 } + extra
    };
    let width = col_x(KERNELS.len() + 1) + margin - gap;
    let height = title_h + margin + GATHERS.len() as u32 * cell_h + margin;
    let mut s = String::new();
    writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="Helvetica, Arial, sans-serif">"#
    )?;
    writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#)?;
    for (i, line) in title.iter().enumerate() {
        let y = margin + 10 + 14 * i as u32;
        writeln!(s, r#"<text x="{margin}" y="{y}" font-size="11">{}</text>"#, xml_escape(line))?;
    }
    let image = |s: &mut String, file: &str, x: u32, y: u32| -> Result<(), Error> {
        let data = base64(&std::fs::read(dir.join(file))?);
        writeln!(s, r#"<image x="{x}" y="{y}" width="{size}" height="{size}" href="data:image/png;base64,{data}"/>"#)?;
        Ok(())
    };
    let label = |s: &mut String, x: u32, y: u32, l1: &str, l2: &str| -> Result<(), Error> {
        writeln!(s, r#"<text x="{x}" y="{}" font-size="11" font-weight="bold">{}</text>"#, y + 12, xml_escape(l1))?;
        writeln!(s, r#"<text x="{x}" y="{}" font-size="10">{}</text>"#, y + 25, xml_escape(l2))?;
        Ok(())
    };
    let top = title_h + margin;
    // The reference, centred vertically between the two rows.
    let ref_y = top + (GATHERS.len() as u32 * cell_h - cell_h) / 2;
    image(&mut s, "reference.png", margin, ref_y)?;
    label(&mut s, margin, ref_y + size, &reference_label[0], &reference_label[1])?;
    for (row, gather) in GATHERS.iter().enumerate() {
        let y = top + row as u32 * cell_h;
        let in_row: Vec<&Tile> = tiles.iter().filter(|t| t.gather == *gather).collect();
        let best = in_row.iter().map(|t| t.scores.rmse).fold(f64::INFINITY, f64::min);
        for (col, t) in in_row.iter().enumerate() {
            let x = col_x(col + 1);
            image(&mut s, &t.file, x, y)?;
            if t.scores.rmse == best {
                writeln!(
                    s,
                    r##"<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="#1a9641" stroke-width="3"/>"##,
                    x - 2,
                    y - 2,
                    size + 4,
                    size + 4
                )?;
            }
            let l1 = format!("{} {}", kernel_name(t.kernel), gather_name(t.gather));
            let l2 = format!("RMSE {:.4}, relMSE {:.5}, {:.1} s", t.scores.rmse, t.scores.rel_mse, t.render_s);
            label(&mut s, x, y + size, &format!("{l1}:"), &l2)?;
        }
    }
    writeln!(s, "</svg>")?;
    Ok(s)
}

fn xml_escape(t: &str) -> String {
    t.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (plain, encoded) in
            [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("foobar", "Zm9vYmFy")]
        {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
    }
}
