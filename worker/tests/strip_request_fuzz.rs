//! Fuzzing of the worker's strip-request checks ([`photon_worker::check_strip_request`]): mutated frame bytes
//! (flipped bytes, hostile 32- and 64-bit values written anywhere, truncation, growth), frames encoded from
//! random settings and sizes, and random rows and blob ids. No case panics; every accepted request lies within
//! the documented limits and its strip's memory estimate within the worker's budget; every refusal is
//! INVALID_ARGUMENT, OUT_OF_RANGE or RESOURCE_EXHAUSTED with a short message. The cases come from a fixed seed
//! (a counter hashed by `mix64`), so a failure repeats; `PHOTON_FUZZ_CASES` sets how many (default 200,000, under
//! a second).

#![allow(clippy::unwrap_used)]

use photon_core::camera::Camera;
use photon_core::math::rng::mix64;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::prepare::budget::MemoryEstimate;
use photon_core::render::sums::MAX_BLOCK_UNITS;
use photon_core::scene::{MAX_IMAGE_SIDE, RenderSettings, Scene};
use photon_proto::pb;
use photon_worker::{Limits, check_strip_request};
use tonic::Code;

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(1);
        mix64(self.0)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
    fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[self.below(xs.len() as u64) as usize]
    }
}

/// 32-bit values that break careless code: zero, one, the limits' edges, all ones, NaN and infinities as f32.
const HOSTILE_U32: [u32; 10] = [0, 1, 2, 65_536, 65_537, 0x7FFF_FFFF, u32::MAX, 0x7F80_0000, 0x7FC0_0000, 0xFF80_0000];

fn base() -> (Camera, RenderSettings) {
    let text = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nwidth = 64\nheight = 48\n";
    let scene = Scene::parse(text, std::path::Path::new("fuzz.toml")).unwrap();
    (Camera::new(&scene.camera), scene.render)
}

fn random_settings(rng: &mut Rng, mut s: RenderSettings) -> RenderSettings {
    s.integrator = rng.pick(&Method::ALL);
    s.spp = rng.pick(&HOSTILE_U32);
    s.photons.k = rng.pick(&HOSTILE_U32);
    s.photons.passes = rng.pick(&HOSTILE_U32);
    s.photons.pass_photons = rng.pick(&HOSTILE_U32);
    s.max_depth = rng.pick(&HOSTILE_U32);
    s.exposure = f32::from_bits(rng.pick(&HOSTILE_U32));
    s.photons.alpha = f32::from_bits(rng.pick(&HOSTILE_U32));
    s
}

fn mutate_bytes(rng: &mut Rng, mut b: Vec<u8>) -> Vec<u8> {
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(b.len() as u64) as usize;
        match rng.below(5) {
            0 => b[at] ^= 1 << rng.below(8),
            1 if at + 4 <= b.len() => b[at..at + 4].copy_from_slice(&rng.pick(&HOSTILE_U32).to_le_bytes()),
            2 if at + 8 <= b.len() => b[at..at + 8].copy_from_slice(&rng.pick(&[u64::MAX, 1 << 40, 0]).to_le_bytes()),
            3 => b.truncate(at),
            _ => b.extend((0..rng.below(64)).map(|_| rng.next() as u8)),
        }
        if b.is_empty() {
            break;
        }
    }
    b
}

#[test]
fn strip_requests_are_checked_without_panic_or_over_budget_acceptance() {
    let cases: u64 = std::env::var("PHOTON_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(200_000);
    let (camera, settings) = base();
    let limits = Limits { strip_memory_bytes: 1 << 30, threads: 64, texture_bytes: 0, max_strip_work: u64::MAX };
    let id = photon_proto::blob_id(b"scene");
    let photons = photon_proto::blob_id(b"photons");
    let mut rng = Rng(15);
    let (mut accepted, mut refused) = (0u64, 0u64);
    let t0 = std::time::Instant::now();
    for case in 0..cases {
        let mode = rng.below(4);
        let frame = match mode {
            // Valid structure, hostile values: what the checks must refuse by name.
            0 => {
                let mut c = camera;
                let (w, h) = (rng.pick(&HOSTILE_U32), rng.pick(&HOSTILE_U32));
                c.width = rng.pick(&[w, 64, MAX_IMAGE_SIDE]);
                c.height = rng.pick(&[h, 48]);
                Prepared::encode_frame_of(&c, &random_settings(&mut rng, settings.clone())).unwrap()
            }
            // Bytes mutated: what the decoder must refuse without trusting a length.
            1 => mutate_bytes(&mut rng, Prepared::encode_frame_of(&camera, &settings).unwrap()),
            _ => Prepared::encode_frame_of(&camera, &settings).unwrap(),
        };
        let row = |rng: &mut Rng| {
            let hostile = rng.pick(&HOSTILE_U32);
            rng.pick(&[0, 1, 47, 48, 49, hostile])
        };
        let mut r = pb::StripRequest {
            scene_blob: rng.pick(&[id.as_str(), "", "../x", &id[..63]]).to_owned(),
            photons_blob: rng.pick(&["", photons.as_str(), "zz"]).to_owned(),
            frame,
            row_start: row(&mut rng),
            row_end: row(&mut rng),
            strip: rng.next() as u32,
            attempt: rng.next() as u32,
            unit_start: if rng.below(2) == 0 { 0 } else { row(&mut rng) },
            unit_end: if rng.below(2) == 0 { 0 } else { row(&mut rng) },
            trace_photons: rng.below(2) == 0,
            texture_blobs: match rng.below(4) {
                0 => vec![id.clone()],
                1 => vec!["not-a-blob".to_owned()],
                2 => vec![String::new(); 5000],
                _ => Vec::new(),
            },
        };
        if mode == 3 {
            r.texture_blobs.clear();
            // A well-formed request of the base frame (48 rows, path tracing: no photons blob, one sample).
            (r.scene_blob, r.photons_blob, r.trace_photons) = (id.clone(), String::new(), false);
            (r.unit_start, r.unit_end) = (0, 1);
            r.row_start = rng.below(48) as u32;
            r.row_end = r.row_start + 1 + rng.below(u64::from(48 - r.row_start)) as u32;
        }
        match check_strip_request(r.clone(), &limits) {
            Ok(order) => {
                accepted += 1;
                let frame = order.frame();
                assert_eq!(
                    (order.rows(), order.units()),
                    (r.row_start..r.row_end, r.unit_start..r.unit_end),
                    "case {case}"
                );
                let (w, h) = (frame.camera.width, frame.camera.height);
                assert!((1..=MAX_IMAGE_SIDE).contains(&w) && (1..=MAX_IMAGE_SIDE).contains(&h), "case {case}");
                assert!(r.row_start < r.row_end && r.row_end <= h, "case {case}: rows {}..{}", r.row_start, r.row_end);
                let rows = r.row_end - r.row_start;
                let mut estimate = MemoryEstimate::strip(w, rows, &frame.settings, limits.threads);
                estimate.light_paths = MemoryEstimate::light_paths(w, h, &frame.settings);
                if r.trace_photons {
                    estimate.photon_maps = MemoryEstimate::photon_maps(&frame.settings);
                }
                let bytes = estimate.total();
                assert!(bytes <= limits.strip_memory_bytes, "case {case}: {bytes} bytes accepted");
                // Photon maps come one way or the other when, and only when, the method reads them.
                let maps = usize::from(!r.photons_blob.is_empty()) + usize::from(r.trace_photons);
                assert_eq!(usize::from(frame.settings.integrator.needs_photon_maps()), maps, "case {case}");
                // Every request is a non-empty block of the frame's units (passes, or samples per pixel).
                let units = r.unit_start..r.unit_end;
                assert!(!units.is_empty() && units.end <= frame.settings.units(), "case {case}: units {units:?}");
                assert!(units.len() <= MAX_BLOCK_UNITS as usize, "case {case}: units {units:?}");
            }
            Err(e) => {
                refused += 1;
                let expected = [Code::InvalidArgument, Code::OutOfRange, Code::ResourceExhausted];
                assert!(expected.contains(&e.code()), "case {case}: {e:?}");
                assert!(e.message().len() < 600, "case {case}: {} bytes", e.message().len());
            }
        }
    }
    eprintln!("{cases} cases in {:?}: {accepted} accepted, {refused} refused", t0.elapsed());
    // A quarter of the cases are well-formed: they must pass, as hostile ones must not.
    assert!(accepted > cases / 5 && refused > cases / 2, "{accepted} accepted, {refused} refused");
}
