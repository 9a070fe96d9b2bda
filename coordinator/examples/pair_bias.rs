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

use photon_core::image_io::Image;
use photon_core::metrics::EPSILON;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [reference, l2, l4, s2, s4] = args.as_slice() else {
        return Err("usage: pair_bias REFERENCE.exr L2.exr L4.exr S2.exr S4.exr".into());
    };
    let read = |p: &str| Image::read(Path::new(p)).map(|i| i.pixels);
    let reference = read(reference)?;
    let [l2, l4, s2, s4] = [l2, l4, s2, s4].map(|p| read(p));
    let (l2, l4, s2, s4) = (l2?, l4?, s2?, s4?);
    if [l2.len(), l4.len(), s2.len(), s4.len()].iter().any(|&n| n != reference.len()) {
        return Err("the images and the reference differ in size".into());
    }
    // Sums over each half's two passes.
    let halves = |two: &[f32], four: &[f32]| {
        let a: Vec<f64> = two.iter().map(|&x| 2.0 * f64::from(x)).collect();
        let b: Vec<f64> = four.iter().zip(&a).map(|(&x, a)| 4.0 * f64::from(x) - a).collect();
        (a, b)
    };
    let (la, lb) = halves(&l2, &l4);
    let (sa, sb) = halves(&s2, &s4);
    let share = photon_coordinator::auto::EdgeShare::new(photon_core::render::progressive::KERNEL);
    let bias2 = photon_coordinator::auto::radius_pair_bias2(
        ([&la, &lb], [2, 2]),
        ([&sa, &sb], [2, 2]),
        &reference,
        2.0 / 3.0,
        &share,
    );
    let rel_mse = |img: &[f32]| {
        let sum: f64 = img
            .iter()
            .zip(&reference)
            .map(|(&x, &r)| {
                let (x, r) = (f64::from(x), f64::from(r));
                (x - r) * (x - r) / (r * r + EPSILON)
            })
            .sum();
        sum / img.len() as f64
    };
    println!("bias2_r0 {bias2:.4e} rel_mse_r0 {:.4e} rel_mse_half {:.4e}", rel_mse(&l4), rel_mse(&s4));
    Ok(())
}
