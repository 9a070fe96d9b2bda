//! Texture lookups per second on one core: a 1024×1024 sRGB RGB image (8-bit, decoded through the sRGB table)
//! and the same image as linear floats, with nearest and bilinear filtering, at pseudo-random coordinates (the
//! incoherent access of secondary rays); and the checkerboard. The scene-level cost of textures is in
//! docs/RESULTS.md ("Textures").

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Vec2, Vec3A};
use photon_core::material::Texture;
use photon_core::material::texture::{Filter, ImageRef, TexelImage, Texels, Wrap};
use std::hint::black_box;
use std::time::Duration;

const SIDE: u32 = 1024;
const LOOKUPS: usize = 1 << 16;

fn bench(c: &mut Criterion) {
    let n = (SIDE * SIDE * 3) as usize;
    let bytes: Vec<u8> = (0..n).map(|i| (i.wrapping_mul(2_654_435_761) >> 7) as u8).collect();
    let floats: Vec<f32> = bytes.iter().map(|&b| f32::from(b) / 255.0).collect();
    let images = [
        ("u8_srgb", TexelImage { width: SIDE, height: SIDE, channels: 3, texels: Texels::U8(bytes) }),
        ("f32", TexelImage { width: SIDE, height: SIDE, channels: 3, texels: Texels::F32(floats) }),
    ];
    // Coordinates from a fixed low-discrepancy-free hash: spread over the image, no cache-friendly order.
    let uvs: Vec<Vec2> = (0..LOOKUPS as u32)
        .map(|i| {
            let h = i.wrapping_mul(0x9E37_79B9) ^ (i >> 3).wrapping_mul(0x85EB_CA6B);
            Vec2::new((h & 0xFFFF) as f32 / 65536.0, (h >> 16) as f32 / 65536.0 * 1.7 - 0.35)
        })
        .collect();
    let mut g = c.benchmark_group("texture_lookups_one_core");
    g.sample_size(20).measurement_time(Duration::from_secs(3)).throughput(Throughput::Elements(LOOKUPS as u64));
    for (name, image) in images {
        let list = [image];
        for filter in [Filter::Nearest, Filter::Bilinear] {
            let t = Texture::Image(ImageRef {
                file: "bench.png".into(),
                slot: 0,
                scale: Vec2::ONE,
                offset: Vec2::ZERO,
                wrap: Wrap::Repeat,
                filter,
                colorspace: None,
            });
            g.bench_function(format!("{name}_{filter:?}").to_lowercase(), |b| {
                b.iter(|| uvs.iter().fold(Vec3A::ZERO, |acc, &uv| acc + t.eval(uv, Vec3A::ZERO, &list)))
            });
        }
    }
    let checker = Texture::Checker { a: Vec3A::splat(0.2), b: Vec3A::splat(0.8), scale: Vec2::splat(8.0) };
    g.bench_function("checker", |b| {
        b.iter(|| uvs.iter().fold(Vec3A::ZERO, |acc, &uv| acc + checker.eval(uv, Vec3A::ZERO, black_box(&[]))))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
