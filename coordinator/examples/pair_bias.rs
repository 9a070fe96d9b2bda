//! The radius pair's squared bias ([`photon_coordinator::auto::radius_pair_bias2`]), as `auto`'s pilot computes
//! it, from images rendered outside the pilot, so that its spread over seeds can be seen (docs/RESULTS.md,
//! "Choosing the method, third part").
//!
//! `cargo run --release -p photon-coordinator --example pair_bias -- REFERENCE.exr L2.exr L4.exr S2.exr S4.exr`
//! takes progressive photon mapping's images of one seed after 2 and 4 passes at the first radius `r₀` (`L2`,
//! `L4`) and at `r₀/2` (`S2`, `S4`), all with the default α = 2/3. The pilot's two halves are passes 1-2 and 3-4:
//! as sums, `2·L2` and `4·L4 − 2·L2`. It prints the estimate of `r₀`'s squared bias relative to `REFERENCE`
//! (the pilot uses the mean of every candidate's pilot there; a high-budget reference shows the estimator's own
//! noise), and `L4`'s and `S4`'s relative MSE against the reference.

use photon_coordinator::auto::{EdgeShare, radius_pair_bias2};
use photon_core::image_io::Image;
use photon_core::method::Method;
use photon_core::metrics::compare;
use photon_core::photon::Kernel;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [reference, l2, l4, s2, s4] = args.as_slice() else {
        return Err("usage: pair_bias REFERENCE.exr L2.exr L4.exr S2.exr S4.exr".into());
    };
    let read = |p: &str| Image::read(Path::new(p));
    let reference = read(reference)?;
    let [l2, l4, s2, s4] = [l2, l4, s2, s4].map(|p| read(p));
    let (l2, l4, s2, s4) = (l2?, l4?, s2?, s4?);
    if [&l2, &l4, &s2, &s4].iter().any(|i| i.pixels.len() != reference.pixels.len()) {
        return Err("the images and the reference differ in size".into());
    }
    // Sums over each half's two passes.
    let halves = |two: &Image, four: &Image| {
        let a: Vec<f64> = two.pixels.iter().map(|&x| 2.0 * f64::from(x)).collect();
        let b: Vec<f64> = four.pixels.iter().zip(&a).map(|(&x, a)| 4.0 * f64::from(x) - a).collect();
        (a, b)
    };
    let (la, lb) = halves(&l2, &l4);
    let (sa, sb) = halves(&s2, &s4);
    // Progressive photon mapping's kernel, whatever the scene's setting.
    let share = EdgeShare::new(Method::Progressive.kernel(Kernel::Epanechnikov));
    let bias2 = radius_pair_bias2(([&la, &lb], [2, 2]), ([&sa, &sb], [2, 2]), &reference.pixels, 2.0 / 3.0, &share);
    let rel_mse = |img: &Image| compare(img, &reference, None).map(|m| m.rel_mse);
    println!("bias2_r0 {bias2:.4e} rel_mse_r0 {:.4e} rel_mse_half {:.4e}", rel_mse(&l4)?, rel_mse(&s4)?);
    Ok(())
}
