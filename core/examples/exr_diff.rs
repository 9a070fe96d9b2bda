//! How two renders of the same scene differ, pixel by pixel: `cargo run --release -p photon-core --example
//! exr_diff -- A.exr B.exr` prints one line,
//! `PIXELS DIFFERING MAX_ABS MAX_REL MEAN_A MEAN_B`: the pixel count, how many pixels have any channel whose bits
//! differ, the largest absolute and relative (to the larger of the two values) channel difference, and each
//! image's mean over all channels. `docs/figures/bvh-images/run.sh` runs it on the shipped scenes rendered by two
//! builds.

use photon_core::image_io::Image;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [a, b] = args.as_slice() else {
        return Err("usage: exr_diff A.exr B.exr".into());
    };
    let (a, b) = (Image::read(Path::new(a))?, Image::read(Path::new(b))?);
    if (a.width, a.height) != (b.width, b.height) {
        return Err(format!("sizes differ: {}x{} and {}x{}", a.width, a.height, b.width, b.height).into());
    }
    let (mut differ, mut max_abs, mut max_rel) = (0usize, 0f64, 0f64);
    for (pa, pb) in a.pixels.chunks_exact(3).zip(b.pixels.chunks_exact(3)) {
        if pa.iter().zip(pb).any(|(x, y)| x.to_bits() != y.to_bits()) {
            differ += 1;
        }
        for (&x, &y) in pa.iter().zip(pb) {
            let d = (f64::from(x) - f64::from(y)).abs();
            max_abs = max_abs.max(d);
            let scale = f64::from(x.abs().max(y.abs()));
            if scale > 0.0 {
                max_rel = max_rel.max(d / scale);
            }
        }
    }
    let mean = |img: &Image| img.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / img.pixels.len().max(1) as f64;
    println!("{} {differ} {max_abs:.3e} {max_rel:.3e} {:.6} {:.6}", a.pixels.len() / 3, mean(&a), mean(&b));
    Ok(())
}
