//! The most a per-tile choice of method could gain, measured: `cargo run --release -p photon-core --example
//! tile_oracle -- TILE REFERENCE.exr NAME[:BETA]=IMAGE.exr…` reads renders of one scene by several methods (each
//! given the same time T) and the scene's reference, and prints:
//! - each render's relative MSE against the reference (`(x − r)² / (r² + ε)` averaged over channels, as
//!   `compare` measures it);
//! - `oracle-TILE`: the relative MSE of the image that takes each TILE×TILE tile from whichever render is best on
//!   that tile, and how many tiles each gave. Every method in it had the whole time T for every tile, so it
//!   bounds from below what any split of the time can reach;
//! - `split-TILE`: the same with the time shared: for each pair of renders and each share `f` (0.05 to 0.95) of
//!   T given to the first, each render's tile errors are scaled by `share^(−BETA)` (its error's fall with its
//!   time: 1 for an unbiased method, the default; about 2/3 for progressive photon mapping, whose error falls as
//!   `N^(−α)`), each tile takes the smaller, and the best pair and share are printed. Every method renders whole
//!   image blocks in its share (as the farm's unit of work is), so a method restricted to its tiles pays for
//!   the whole image: this is the split a per-tile `auto` could reach if it chose as well as the oracle.
//!
//! docs/RESULTS.md, "Choosing the method by measured efficiency": `docs/figures/auto/run.sh` writes the images.

use photon_core::image_io::Image;
use photon_core::metrics::EPSILON;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: tile_oracle TILE REFERENCE.exr NAME[:BETA]=IMAGE.exr...";
    let [tile, reference, renders @ ..] = args.as_slice() else { return Err(usage.into()) };
    let tile: usize = tile.parse().map_err(|_| usage)?;
    if tile == 0 || renders.is_empty() {
        return Err(usage.into());
    }
    let reference = Image::read(Path::new(reference))?;
    let (w, h) = (reference.width as usize, reference.height as usize);
    let mut names = Vec::new();
    let mut images = Vec::new();
    let mut betas = Vec::new();
    for r in renders {
        let (name, path) = r.split_once('=').ok_or(usage)?;
        let (name, beta) = match name.split_once(':') {
            Some((n, b)) => (n, b.parse::<f64>().map_err(|_| usage)?),
            None => (name, 1.0),
        };
        betas.push(beta);
        let image = Image::read(Path::new(path))?;
        if (image.width as usize, image.height as usize) != (w, h) {
            return Err(format!("{path}: {}x{}, the reference is {w}x{h}", image.width, image.height).into());
        }
        names.push(name.to_owned());
        images.push(image);
    }
    // Per value: (x − r)² / (r² + ε).
    let err = |img: &Image, i: usize| {
        let (x, r) = (f64::from(img.pixels[i]), f64::from(reference.pixels[i]));
        (x - r) * (x - r) / (r * r + EPSILON)
    };
    let values = (3 * w * h) as f64;
    for (name, img) in names.iter().zip(&images) {
        let total: f64 = (0..3 * w * h).map(|i| err(img, i)).sum();
        println!("{name} {:.4e}", total / values);
    }
    // Each tile's summed error for each render.
    let mut tiles: Vec<Vec<f64>> = Vec::new();
    for ty in (0..h).step_by(tile) {
        for tx in (0..w).step_by(tile) {
            let tile_err = |img: &Image| {
                let mut sum = 0.0;
                for y in ty..(ty + tile).min(h) {
                    for x in tx..(tx + tile).min(w) {
                        sum += (0..3).map(|c| err(img, 3 * (y * w + x) + c)).sum::<f64>();
                    }
                }
                sum
            };
            tiles.push(images.iter().map(tile_err).collect());
        }
    }
    let mut wins = vec![0usize; images.len()];
    let mut oracle = 0.0;
    for errs in &tiles {
        let (best, e) = errs.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).ok_or(usage)?;
        wins[best] += 1;
        oracle += e;
    }
    let counts: Vec<String> = names.iter().zip(&wins).map(|(n, c)| format!("{n}:{c}")).collect();
    println!("oracle-{tile} {:.4e} {}", oracle / values, counts.join(" "));
    let mut best: Option<(f64, usize, usize, f64, usize)> = None;
    for a in 0..images.len() {
        for b in a + 1..images.len() {
            for step in 1..20 {
                let f = f64::from(step) * 0.05;
                let (sa, sb) = (f.powf(-betas[a]), (1.0 - f).powf(-betas[b]));
                let (mut total, mut from_a) = (0.0, 0);
                for errs in &tiles {
                    let (ea, eb) = (errs[a] * sa, errs[b] * sb);
                    total += ea.min(eb);
                    from_a += usize::from(ea <= eb);
                }
                if best.is_none_or(|x| total < x.0) {
                    best = Some((total, a, b, f, from_a));
                }
            }
        }
    }
    if let Some((total, a, b, f, from_a)) = best {
        println!(
            "split-{tile} {:.4e} {}:{from_a} tiles with {:.2} of the time, {}:{} tiles with {:.2}",
            total / values,
            names[a],
            f,
            names[b],
            tiles.len() - from_a,
            1.0 - f
        );
    }
    Ok(())
}
