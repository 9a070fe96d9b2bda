//! The scene loader over mutated scenes: numbers replaced by hostile values (NaN, infinities, 1e30, 3e38, zero,
//! 2³²−1), lines deleted or repeated, bytes that are not UTF-8, truncation, megabyte-long strings. Every result
//! is a scene or an error that names a line or a field, quoting little of the input; none panics, and each takes
//! well under a second. The mutations are drawn from a fixed seed, so a failure repeats.

#![allow(clippy::unwrap_used)]

use photon_core::math::rng::mix64;
use photon_core::prepare::budget::MemoryEstimate;
use photon_core::scene::{Scene, SceneError};
use std::time::{Duration, Instant};

/// Values a careless or hostile user may give a field.
const VALUES: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "0.0",
    "1e30",
    "3.0e38",
    "-3.4e38",
    "4294967295",
    "65536",
    "1e-45",
    "\"x\"",
    "[]",
    "true",
    "1e300",
    "[0.0, 1.0, 3.0e38]",
    "-0.0",
    "18446744073709551615",
];

struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 = self.0.wrapping_add(1);
        (mix64(self.0) % n.max(1) as u64) as usize
    }
}

/// The byte ranges of the numbers in `text`.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = b[i].is_ascii_digit() || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        if starts && (i == 0 || !b[i - 1].is_ascii_alphanumeric() && b[i - 1] != b'_') {
            let j = i + 1 + b[i + 1..].iter().take_while(|c| c.is_ascii_alphanumeric() || **c == b'.').count();
            out.push((i, j));
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

fn mutate(text: &str, rng: &mut Rng) -> Vec<u8> {
    let mut bytes = text.as_bytes().to_vec();
    for _ in 0..1 + rng.below(3) {
        let s = String::from_utf8_lossy(&bytes).into_owned();
        let lines: Vec<&str> = s.lines().collect();
        bytes = match rng.below(7) {
            0..=2 => {
                let nums = numbers(&s);
                let (a, b) = nums[rng.below(nums.len())];
                [&s.as_bytes()[..a], VALUES[rng.below(VALUES.len())].as_bytes(), &s.as_bytes()[b..]].concat()
            }
            3 => {
                let k = rng.below(lines.len());
                lines
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i != k)
                    .map(|(_, l)| format!("{l}\n"))
                    .collect::<String>()
                    .into()
            }
            4 => {
                let k = rng.below(lines.len());
                lines
                    .iter()
                    .enumerate()
                    .flat_map(|(i, l)| if i == k { vec![*l, *l] } else { vec![*l] })
                    .map(|l| format!("{l}\n"))
                    .collect::<String>()
                    .into()
            }
            5 => {
                let at = rng.below(bytes.len());
                let byte = [0xE9, 0xFF, 0x00, b'"', b'[', b'\n'][rng.below(6)];
                [&bytes[..at], &[byte], &bytes[at..]].concat()
            }
            _ => {
                let nums = numbers(&s);
                let (a, b) = nums[rng.below(nums.len())];
                let long = format!("\"{}\"", "y".repeat(1 << 20));
                [&s.as_bytes()[..a], long.as_bytes(), &s.as_bytes()[b..]].concat()
            }
        };
    }
    if rng.below(10) == 0 {
        bytes.truncate(rng.below(bytes.len()));
    }
    bytes
}

#[test]
fn mutated_scenes_load_or_name_a_line_or_field() {
    let scenes = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let dir = std::env::temp_dir().join(format!("photon-scene-mutations-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut rng = Rng(15);
    let (mut ok, mut refused) = (0, 0);
    for name in ["cornell.toml", "caustic-point.toml", "mesh.toml"] {
        let original = std::fs::read_to_string(scenes.join(name)).unwrap();
        for case in 0..150 {
            let bytes = mutate(&original, &mut rng);
            let path = dir.join(name);
            std::fs::write(&path, &bytes).unwrap();
            let t0 = Instant::now();
            let result = Scene::load(&path);
            let took = t0.elapsed();
            assert!(took < Duration::from_secs(1), "{name} case {case} took {took:?}");
            match result {
                Ok(scene) => {
                    ok += 1;
                    // The memory estimate of any accepted scene is computed without overflow or panic.
                    let c = &scene.camera;
                    let e = MemoryEstimate::job(c.width, c.height, 16, &scene.render, 64);
                    let _ = e.check(1 << 30, c.width, c.height, &scene.render);
                }
                Err(e) => {
                    refused += 1;
                    let msg = e.to_string();
                    let named = match &e {
                        SceneError::Parse { message, .. } => message.contains("line "),
                        SceneError::Invalid { field, .. } => !field.is_empty(),
                        SceneError::Encoding { at, .. } => at.line >= 1,
                        other => panic!("{name} case {case}: unexpected {other}"),
                    };
                    assert!(named, "{name} case {case}: names no line or field: {msg}");
                    assert!(msg.len() < 4000, "{name} case {case}: a message of {} bytes", msg.len());
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
    // Both outcomes occur, so the mutations neither always break nor never break the scene.
    assert!(ok > 10 && refused > 100, "{ok} loaded, {refused} refused");
}
