//! The variable-bitrate (Dolonius et al.) and palette (Dado et al.) colour formats, the Hough
//! and offline lossy encoders: round trips, random access, GPU decoders against the CPU ones,
//! the lossy threshold promise and corrupt input.

mod common;

use std::sync::Arc;

use indicatif::ProgressBar;
use proptest::prelude::*;
use voxdag::attr::varbit::{self, BlockColors, VarbitBlock, MACRO_BLOCK_COLORS};
use voxdag::attr::{dado, AttrError};
use voxdag::dag::Svdag;
use voxdag::gpu::{shaders, GpuContext};
use voxdag::scene::{self, ImportOptions};

/// Small deterministic generator for test data (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 32) as u32
    }

    fn below(&mut self, n: u32) -> u32 {
        self.next() % n
    }
}

/// A random valid block list over `count` colours: runs of up to `max_run` colours, cut at the
/// macro block boundaries, mixing single-colour and 1-4 bit endpoint blocks.
fn random_blocks(count: usize, max_run: u32, seed: u64) -> Vec<VarbitBlock> {
    let mut rng = Rng(seed | 1);
    let mut blocks = Vec::new();
    let mut start = 0;
    while start < count {
        let macro_end = (start / MACRO_BLOCK_COLORS + 1) * MACRO_BLOCK_COLORS;
        let len = (1 + rng.below(max_run) as usize)
            .min(count - start)
            .min(macro_end - start);
        let bits = rng.below(5) as u8;
        let block = if bits == 0 {
            VarbitBlock {
                start,
                bits,
                kind: BlockColors::Single(rng.next()),
                weights: vec![],
            }
        } else {
            VarbitBlock {
                start,
                bits,
                kind: BlockColors::Endpoints {
                    a565: rng.next() as u16,
                    b565: rng.next() as u16,
                },
                weights: (0..len).map(|_| rng.below(1 << bits) as u8).collect(),
            }
        };
        blocks.push(block);
        start += len;
    }
    blocks
}

/// What a block list decodes to, computed from the blocks directly.
fn expected_colors(blocks: &[VarbitBlock], count: usize) -> Vec<u32> {
    let mut out = Vec::with_capacity(count);
    for (j, block) in blocks.iter().enumerate() {
        let end = blocks.get(j + 1).map_or(count, |b| b.start);
        for i in 0..end - block.start {
            let rgb = match block.kind {
                BlockColors::Single(c) => varbit::expand101210(c),
                BlockColors::Endpoints { a565, b565 } => varbit::blend(
                    varbit::expand565(a565),
                    varbit::expand565(b565),
                    u32::from(block.weights[i]),
                    u32::from(block.bits),
                ),
            };
            out.push(voxdag::attr::pack_rgb(rgb));
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn varbit_write_decode_round_trip(count in 0usize..40_000, max_run in 1u32..400, seed in any::<u64>()) {
        let blocks = random_blocks(count, max_run, seed);
        let words = varbit::write(&blocks, count).unwrap();
        let want = expected_colors(&blocks, count);
        prop_assert_eq!(&varbit::decode_all(&words, count).unwrap(), &want);
        let mut rng = Rng(seed ^ 0x9e37_79b9);
        for _ in 0..200.min(count) {
            let i = rng.below(count as u32) as usize;
            prop_assert_eq!(varbit::decode(&words, count, i).unwrap(), want[i]);
        }
        let past_end = varbit::decode(&words, count, count);
        prop_assert!(matches!(past_end, Err(AttrError::IndexOutOfRange { .. })), "{:?}", past_end);
    }

    /// Any flipped or truncated words give colours or errors, never a panic.
    #[test]
    fn varbit_corrupt_words_never_panic(count in 1usize..20_000, seed in any::<u64>(), flips in 1usize..6, cut in 0usize..8) {
        let blocks = random_blocks(count, 64, seed);
        let mut words = varbit::write(&blocks, count).unwrap();
        let mut rng = Rng(seed.rotate_left(17));
        for _ in 0..flips {
            let at = rng.below(words.len() as u32) as usize;
            words[at] ^= 1 << rng.below(32);
        }
        words.truncate(words.len().saturating_sub(cut));
        let all = varbit::decode_all(&words, count);
        for _ in 0..64 {
            let i = rng.below(count as u32) as usize;
            let one = varbit::decode(&words, count, i);
            if let Ok(all) = &all {
                // Words that validate decode the same both ways.
                prop_assert_eq!(one.unwrap(), all[i]);
            }
        }
    }
}

#[test]
fn varbit_corrupt_headers_are_errors() {
    let count = 20_000;
    let words = varbit::write(&random_blocks(count, 50, 7), count).unwrap();
    let corrupt = |edit: &dyn Fn(&mut Vec<u32>)| {
        let mut w = words.clone();
        edit(&mut w);
        assert!(matches!(
            varbit::decode_all(&w, count),
            Err(AttrError::Corrupt { .. })
        ));
    };
    corrupt(&|w| w.truncate(1));
    corrupt(&|w| w[0] = u32::MAX);
    corrupt(&|w| w[1] = 5);
    corrupt(&|w| w[2] = 1); // macro block 0 starts at its second block: colour 0 is missing
    corrupt(&|w| w[4] = 0); // macro block 1 starts at block 0
    corrupt(&|w| w[5] = 1 << 30); // weights far past the end
    corrupt(&|w| w.truncate(w.len() - 1));
    assert!(varbit::decode_all(&words, count + MACRO_BLOCK_COLORS).is_err());
}

fn assert_clean(ctx: &Arc<GpuContext>) {
    // Deferred releases wait for the GPU: drain them first.
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

#[test]
fn varbit_gpu_decode_equals_cpu() {
    let ctx = common::gpu();
    for (count, max_run, seed) in [(1usize, 1u32, 1u64), (50_001, 300, 2), (40_000, 3, 3)] {
        let words = varbit::write(&random_blocks(count, max_run, seed), count).unwrap();
        let cpu = varbit::decode_all(&words, count).unwrap();
        let gpu = common::run_test_shader(&ctx, shaders::TEST_VARBIT_DECODE, &words, count, 1);
        assert_eq!(gpu, cpu, "count {count}, runs up to {max_run}");
    }
    assert_clean(&ctx);
}

/// Colours in runs: smooth gradients, flat runs and noise, like textured surfaces in Morton order.
fn textured_colors(count: usize, seed: u64) -> Vec<u32> {
    let mut rng = Rng(seed | 1);
    let mut colors = Vec::with_capacity(count);
    while colors.len() < count {
        let run = 1 + rng.below(300) as usize;
        let a = [rng.next() as u8, rng.next() as u8, rng.next() as u8];
        let b = [rng.next() as u8, rng.next() as u8, rng.next() as u8];
        let noise = [0, 4, 40, 255][rng.below(4) as usize];
        for i in 0..run.min(count - colors.len()) {
            let t = i as f32 / run as f32;
            let c = [0, 1, 2].map(|k| {
                let v = f32::from(a[k]) + (f32::from(b[k]) - f32::from(a[k])) * t;
                let jitter = if noise == 0 {
                    0
                } else {
                    rng.below(2 * noise + 1) as i32 - noise as i32
                };
                (v as i32 + jitter).clamp(0, 255) as u8
            });
            colors.push(voxdag::attr::pack_rgb(c));
        }
    }
    colors
}

/// Largest channel difference of decoded against input colours, and the RMSE (colours in [0, 1]).
fn lossy_error(input: &[u32], decoded: &[u32]) -> (u8, f64) {
    assert_eq!(input.len(), decoded.len());
    let mut worst = 0;
    let mut sum = 0.0f64;
    for (&a, &b) in input.iter().zip(decoded) {
        let (a, b) = (voxdag::attr::rgb(a), voxdag::attr::rgb(b));
        worst = worst.max(varbit::channel_error(a, b));
        for k in 0..3 {
            sum += ((f64::from(a[k]) - f64::from(b[k])) / 255.0).powi(2);
        }
    }
    (worst, (sum / (3 * input.len().max(1)) as f64).sqrt())
}

/// `max_delta` maps k / 255 to k and never allows more than its threshold, also just below
/// k / 255 (0.16862524 is the case a random run found: 43 / 255 is 2e-6 above it).
#[test]
fn max_delta_is_exact_at_steps_and_never_above_the_threshold() {
    for k in 0..=255u8 {
        let step = f32::from(k) / 255.0;
        assert_eq!(varbit::max_delta(step), k, "threshold {k}/255");
        for below in [
            f32::from_bits(step.to_bits().saturating_sub(1)),
            step - 2e-6,
        ] {
            let allowed = varbit::max_delta(below);
            assert!(
                f32::from(allowed) / 255.0 <= below.max(0.0),
                "threshold {below}: {allowed}"
            );
        }
    }
    assert_eq!(varbit::max_delta(0.16862524), 42);
    assert_eq!(varbit::max_delta(f32::NAN), 0);
    assert_eq!(varbit::max_delta(-1.0), 0);
    assert_eq!(varbit::max_delta(2.0), 255);
}

type Encoder = fn(&[u32], f32) -> Vec<u32>;

/// The two lossy encoders, each with the most colours a test gives it (the offline encoder is
/// slow by design).
const LOSSY: [(&str, Encoder, usize); 2] = [
    ("hough", voxdag::attr::lossy::encode, usize::MAX),
    ("dolonius", voxdag::attr::dolonius::encode, 3_000),
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The format's promise: no decoded channel further than the threshold from its input.
    #[test]
    fn lossy_encoders_keep_the_threshold(count in 1usize..20_000, seed in any::<u64>(), threshold in 0.0f32..0.2) {
        let allowed = varbit::max_delta(threshold);
        prop_assert!(f32::from(allowed) / 255.0 <= threshold);
        for (name, encode, most) in LOSSY {
            let colors = textured_colors(count.min(most), seed);
            let count = colors.len();
            let words = encode(&colors, threshold);
            let decoded = varbit::decode_all(&words, count).unwrap();
            let (worst, _) = lossy_error(&colors, &decoded);
            prop_assert!(worst <= allowed, "{}: channel error {} > {}", name, worst, allowed);
            for i in [0, count / 2, count - 1] {
                prop_assert_eq!(varbit::decode(&words, count, i).unwrap(), decoded[i]);
            }
        }
    }

    #[test]
    fn dado_round_trip_is_exact(count in 0usize..5_000, seed in any::<u64>(), alphabet in 1u32..3000) {
        let mut rng = Rng(seed | 1);
        let colors: Vec<u32> = (0..count).map(|_| rng.below(alphabet).wrapping_mul(0x9e3779) | 0xff00_0000).collect();
        let words = dado::encode(&colors);
        prop_assert_eq!(&dado::decode_all(&words, count).unwrap(), &colors);
        for i in (0..count).step_by(97) {
            prop_assert_eq!(dado::decode(&words, count, i).unwrap(), colors[i]);
        }
    }

    #[test]
    fn dado_corrupt_words_never_panic(count in 1usize..5_000, seed in any::<u64>(), flips in 1usize..6, cut in 0usize..8) {
        let mut rng = Rng(seed | 1);
        let colors: Vec<u32> = (0..count).map(|_| (rng.below(40) * 0x010203) | 0xff00_0000).collect();
        let mut words = dado::encode(&colors);
        for _ in 0..flips {
            let at = rng.below(words.len() as u32) as usize;
            words[at] ^= 1 << rng.below(32);
        }
        words.truncate(words.len().saturating_sub(cut));
        let all = dado::decode_all(&words, count);
        for _ in 0..64 {
            let i = rng.below(count as u32) as usize;
            let one = dado::decode(&words, count, i);
            if let Ok(all) = &all {
                prop_assert_eq!(one.unwrap(), all[i]);
            }
        }
    }
}

#[test]
fn encoders_are_deterministic_handle_empty_input_and_are_exact_at_threshold_zero() {
    for (name, encode, most) in LOSSY {
        let colors = textured_colors(70_000.min(most), 11);
        assert_eq!(encode(&colors, 0.06), encode(&colors, 0.06), "{name}");
    }
    // A zero threshold still round-trips exactly.
    for (name, encode, _) in LOSSY {
        let words = encode(&[], 0.06);
        assert_eq!(
            varbit::decode_all(&words, 0).unwrap(),
            Vec::<u32>::new(),
            "{name}"
        );
        assert!(varbit::decode_all(&words, 1).is_err(), "{name}");
    }
    assert_eq!(
        dado::decode_all(&dado::encode(&[]), 0).unwrap(),
        Vec::<u32>::new()
    );
    let colors = textured_colors(5000, 12);
    let words = voxdag::attr::lossy::encode(&colors, 0.0);
    assert_eq!(varbit::decode_all(&words, 5000).unwrap(), colors);
}

#[test]
fn dado_corrupt_headers_are_errors() {
    let colors: Vec<u32> = (0..3000u32)
        .map(|i| ((i % 7) * 0x30201) | 0xff00_0000)
        .collect();
    let words = dado::encode(&colors);
    let corrupt = |edit: &dyn Fn(&mut Vec<u32>)| {
        let mut w = words.clone();
        edit(&mut w);
        assert!(matches!(
            dado::decode_all(&w, colors.len()),
            Err(AttrError::Corrupt { .. })
        ));
    };
    corrupt(&|w| w.truncate(2));
    corrupt(&|w| w[0] = 1); // block 0 on top of the offsets
    corrupt(&|w| w[1] = u32::MAX);
    corrupt(&|w| {
        let at = w[0] as usize;
        w[at] = 0;
    });
    corrupt(&|w| {
        let at = w[2] as usize;
        w[at] = 5000;
    });
    corrupt(&|w| w.truncate(w.len() - 1));
    // Palette of 7 uses 3-bit indices; index 7 is past the palette.
    corrupt(&|w| {
        let at = w[0] as usize + 1 + (7 * 24) / 32;
        w[at] |= 0x7 << ((7 * 24) % 32);
    });
}

#[test]
fn palette_gpu_decode_equals_cpu() {
    let ctx = common::gpu();
    for (count, alphabet) in [(1usize, 1u32), (10_000, 2), (33_333, 300), (5000, 100_000)] {
        let mut rng = Rng(count as u64);
        let colors: Vec<u32> = (0..count)
            .map(|_| rng.below(alphabet).wrapping_mul(0x00c0_ffee) | 0xff00_0000)
            .collect();
        let words = dado::encode(&colors);
        let gpu = common::run_test_shader(&ctx, shaders::TEST_PALETTE_DECODE, &words, count, 1);
        assert_eq!(gpu, colors, "count {count}, alphabet {alphabet}");
    }
    assert_clean(&ctx);
}

#[test]
fn lossy_gpu_decode_equals_cpu() {
    let ctx = common::gpu();
    for (name, encode, most) in LOSSY {
        let colors = textured_colors(40_000.min(most), 5);
        let count = colors.len();
        let words = encode(&colors, 0.06);
        let cpu = varbit::decode_all(&words, count).unwrap();
        let gpu = common::run_test_shader(&ctx, shaders::TEST_VARBIT_DECODE, &words, count, 1);
        assert_eq!(gpu, cpu, "{name}");
    }
    assert_clean(&ctx);
}

/// Real textured scenes at 256^3: the threshold promise, Dado's exactness, and the sizes and
/// errors printed for the record (size as % of raw RGB888 = 3 bytes per colour). The offline
/// encoder gets each scene's first macro block only.
#[test]
fn textured_scenes_keep_the_threshold() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let textured = data.join("textured");
    for (scene, texture) in [
        ("spot/spot_triangulated.obj", Some("spot/spot_texture.png")),
        ("Avocado/Avocado.gltf", None),
    ] {
        let options = ImportOptions {
            resolution: Some(256),
            texture_override: texture.map(|t| textured.join(t)),
            ..Default::default()
        };
        let voxels =
            scene::import(&textured.join(scene), &options, &ProgressBar::hidden()).unwrap();
        let colors = Svdag::from_voxels(&voxels).unwrap().colors;
        assert!(colors.len() > 100_000, "{scene}: {} colours", colors.len());
        let raw = |count: usize| 3.0 * count as f64;
        let words = dado::encode(&colors);
        assert_eq!(dado::decode_all(&words, colors.len()).unwrap(), colors);
        println!(
            "{scene}: {} colours; dado {:.1}% of raw",
            colors.len(),
            400.0 * words.len() as f64 / raw(colors.len())
        );
        for (name, encode, _) in LOSSY {
            let colors = if name == "dolonius" {
                &colors[..MACRO_BLOCK_COLORS]
            } else {
                &colors[..]
            };
            let count = colors.len();
            let start = std::time::Instant::now();
            let words = encode(colors, 0.06);
            let seconds = start.elapsed().as_secs_f64();
            let decoded = varbit::decode_all(&words, count).unwrap();
            let (worst, rmse) = lossy_error(colors, &decoded);
            println!(
                "{scene}: {name} on {count} colours: {:.1}% of raw, RMSE {rmse:.4}, max error {worst}/255, {seconds:.3} s",
                400.0 * words.len() as f64 / raw(count)
            );
            assert!(worst <= varbit::max_delta(0.06), "{name}: {worst}");
        }
    }
}
