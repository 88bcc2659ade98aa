//! The real-time lossless colour codec: CPU round trips, random access, corrupt-word fuzzing,
//! the compression ratio on real voxelized colours, and the GPU passes against the CPU reference
//! (bit-identical encoding, decoding through `shaders/glsl/attr/lossless.glsl`).

mod common;

use std::path::Path;

use proptest::prelude::*;
use voxdag::attr::lossless::{self, LosslessVariant};
use voxdag::attr::{pack_rgb, AttrError};
use voxdag::attr_gpu::lossless::LosslessGpu;
use voxdag::dag::Svdag;
use voxdag::scene::{self, ImportOptions};

const VARIANTS: [LosslessVariant; 2] = [LosslessVariant::Rgb888, LosslessVariant::Rgb565];

/// What decoding must return: the input, opaque, quantized for RGB565.
fn expected(colors: &[u32], variant: LosslessVariant) -> Vec<u32> {
    colors
        .iter()
        .map(|&c| variant.to_color(variant.to_channels(c)))
        .collect()
}

/// Encodes, then checks sequential and random-access decoding against the expectation.
fn round_trip(colors: &[u32], variant: LosslessVariant) -> Vec<u32> {
    let words = lossless::encode(colors, variant);
    let want = expected(colors, variant);
    lossless::validate(&words, colors.len()).unwrap();
    let all = lossless::decode_all(&words, colors.len()).unwrap();
    assert_eq!(all, want);
    // Decoded colours are fixed points: re-encoding them loses nothing (565: already quantized).
    let again = lossless::encode(&all, variant);
    assert_eq!(lossless::decode_all(&again, all.len()).unwrap(), all);
    for (i, &c) in want.iter().enumerate() {
        assert_eq!(
            lossless::decode(&words, colors.len(), i).unwrap(),
            c,
            "colour {i}"
        );
    }
    words
}

/// A tiny deterministic generator (xorshift) for structured inputs.
fn xorshift(state: &mut u64) -> u32 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 32) as u32
}

/// Runs of constant colours, gradients and noise, mixed, `n` colours.
fn structured(n: usize, seed: u64) -> Vec<u32> {
    let mut s = seed | 1;
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let len = (xorshift(&mut s) % 300 + 1) as usize;
        let base = xorshift(&mut s);
        match xorshift(&mut s) % 3 {
            0 => out.extend(std::iter::repeat_n(base, len)),
            1 => out.extend((0..len as u32).map(|i| {
                let [r, g, b] = voxdag::attr::rgb(base);
                pack_rgb([
                    r.wrapping_add(i as u8),
                    g.wrapping_add((i / 2) as u8),
                    b.wrapping_sub((i / 3) as u8),
                ])
            })),
            _ => {
                let amp = 1 + xorshift(&mut s) % 40;
                out.extend((0..len).map(|_| {
                    let [r, g, b] = voxdag::attr::rgb(base);
                    let mut j = || (xorshift(&mut s) % amp) as u8;
                    pack_rgb([
                        r.saturating_add(j()),
                        g.saturating_add(j()),
                        b.saturating_add(j()),
                    ])
                }))
            }
        }
    }
    out.truncate(n);
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn random_colours_round_trip(colors in prop::collection::vec(any::<u32>(), 0..1000)) {
        for v in VARIANTS {
            round_trip(&colors, v);
        }
    }

    #[test]
    fn structured_colours_round_trip(n in 0usize..1000, seed in any::<u64>()) {
        for v in VARIANTS {
            round_trip(&structured(n, seed), v);
        }
    }

    #[test]
    fn flipped_words_give_errors_or_colours_never_panics(
        n in 1usize..400,
        seed in any::<u64>(),
        flips in prop::collection::vec((any::<prop::sample::Index>(), 0u32..32), 1..4),
    ) {
        let colors = structured(n, seed);
        let mut words = lossless::encode(&colors, LosslessVariant::Rgb888);
        for (at, bit) in flips {
            let i = at.index(words.len());
            words[i] ^= 1 << bit;
        }
        match lossless::decode_all(&words, n) {
            Ok(all) => {
                prop_assert_eq!(all.len(), n);
                // Whatever decodes fully also passes the structural check the GPU relies on.
                prop_assert!(lossless::validate(&words, n).is_ok());
            }
            Err(e) => prop_assert!(matches!(e, AttrError::Corrupt { .. }), "{e}"),
        }
        if let Err(e) = lossless::validate(&words, n) {
            prop_assert!(matches!(e, AttrError::Corrupt { .. }), "{e}");
        }
        for i in [0, n / 2, n - 1] {
            match lossless::decode(&words, n, i) {
                Ok(_) => {}
                Err(e) => prop_assert!(matches!(e, AttrError::Corrupt { .. }), "{e}"),
            }
        }
    }

    #[test]
    fn truncated_or_garbage_chunks_give_errors(
        n in 1usize..400,
        seed in any::<u64>(),
        garbage in prop::collection::vec(any::<u32>(), 0..64),
    ) {
        let words = lossless::encode(&structured(n, seed), LosslessVariant::Rgb565);
        for len in [0, 1, words.len() / 2, words.len() - 1] {
            let short = &words[..len];
            prop_assert!(lossless::decode_all(short, n).is_err() || len == words.len());
            let _ = lossless::decode(short, n, n - 1);
        }
        let _ = lossless::decode_all(&garbage, n);
        let _ = lossless::decode(&garbage, n, n / 2);
    }
}

#[test]
fn index_past_the_end_is_an_error() {
    let words = lossless::encode(&[1, 2, 3], LosslessVariant::Rgb888);
    assert_eq!(
        lossless::decode(&words, 3, 3),
        Err(AttrError::IndexOutOfRange { index: 3, count: 3 })
    );
}

#[test]
fn smooth_gradient_compresses_below_half() {
    let colors: Vec<u32> = (0..128 * 64u32)
        .map(|i| pack_rgb([(i / 64) as u8, (i / 96) as u8, 200 - (i / 128) as u8]))
        .collect();
    let words = round_trip(&colors, LosslessVariant::Rgb888);
    let ratio = words.len() as f64 * 4.0 / (colors.len() as f64 * 3.0);
    assert!(ratio < 0.5, "ratio {ratio}");
}

/// Voxelizes a textured scene and returns its colours in depth-first Morton order.
fn scene_colors(path: &Path, texture: Option<&Path>, resolution: u32) -> Vec<u32> {
    let options = ImportOptions {
        resolution: Some(resolution),
        texture_override: texture.map(Path::to_path_buf),
        ..Default::default()
    };
    let voxels = scene::import(path, &options, &indicatif::ProgressBar::hidden())
        .unwrap_or_else(|e| panic!("importing {}: {e}", path.display()));
    Svdag::from_voxels(&voxels).expect("build SVDAG").colors
}

#[test]
fn textured_scenes_round_trip_and_report_ratio() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let tex = data.join("textured");
    let spot = tex.join("spot");
    let scenes = [
        (
            "spot",
            spot.join("spot_triangulated.obj"),
            Some(spot.join("spot_texture.png")),
        ),
        ("Avocado", tex.join("Avocado/Avocado.gltf"), None),
    ];
    for (name, path, texture) in scenes {
        let colors = scene_colors(&path, texture.as_deref(), 256);
        assert!(!colors.is_empty());
        for v in VARIANTS {
            let words = lossless::encode(&colors, v);
            assert_eq!(
                lossless::decode_all(&words, colors.len()).unwrap(),
                expected(&colors, v)
            );
            let ratio = words.len() as f64 * 4.0 / (colors.len() as f64 * 3.0);
            println!(
                "{name} 256^3 {v:?}: {} colours, {:.1}% of raw RGB888",
                colors.len(),
                100.0 * ratio
            );
            // The target for RGB888 on textured scenes; RGB565 is always smaller.
            assert!(ratio <= 0.70, "{name} {v:?}: {ratio}");
        }
    }
}

/// Inputs for the GPU comparisons: empty, short, exact blocks, a partial last block, real-ish.
fn gpu_inputs() -> Vec<Vec<u32>> {
    let mut s = 7u64;
    vec![
        Vec::new(),
        vec![0xff00_00ff],
        structured(127, 1),
        structured(128, 2),
        structured(129, 3),
        structured(5000, 4),
        (0..3000).map(|_| xorshift(&mut s)).collect(),
        vec![0x0012_3456; 1000],
    ]
}

#[test]
fn gpu_encode_writes_the_cpu_words() {
    let ctx = common::gpu();
    {
        let codec = LosslessGpu::new(&ctx).unwrap();
        for colors in gpu_inputs() {
            for v in VARIANTS {
                let gpu = codec.encode_vec(&colors, v, None).unwrap();
                let cpu = lossless::encode(&colors, v);
                assert_eq!(gpu, cpu, "{} colours, {v:?}", colors.len());
            }
        }
    }
    assert_clean(&ctx);
}

#[test]
fn gpu_decode_through_lossless_glsl_matches_cpu() {
    let ctx = common::gpu();
    {
        let codec = LosslessGpu::new(&ctx).unwrap();
        let mut profiler = voxdag::gpu::Profiler::new(&ctx).unwrap();
        for colors in gpu_inputs() {
            for v in VARIANTS {
                let words = lossless::encode(&colors, v);
                let cpu = lossless::decode_all(&words, colors.len()).unwrap();
                let gpu = codec
                    .decode_vec(&words, colors.len(), Some(&mut profiler))
                    .unwrap();
                assert_eq!(gpu, cpu, "{} colours, {v:?}", colors.len());
            }
        }
        assert!(profiler
            .passes()
            .iter()
            .any(|p| p.name == "lossless decode"));
        // Corrupt chunks are refused on the host before they reach the unvalidating shader.
        let mut words = lossless::encode(&structured(300, 9), LosslessVariant::Rgb888);
        words[1] = u32::MAX;
        assert!(codec.decode_vec(&words, 300, None).is_err());
    }
    assert_clean(&ctx);
}

#[test]
fn gpu_round_trip_on_a_textured_scene() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let spot = data.join("textured/spot");
    let colors = scene_colors(
        &spot.join("spot_triangulated.obj"),
        Some(&spot.join("spot_texture.png")),
        128,
    );
    let ctx = common::gpu();
    {
        let codec = LosslessGpu::new(&ctx).unwrap();
        let mut profiler = voxdag::gpu::Profiler::new(&ctx).unwrap();
        for v in VARIANTS {
            let words = codec.encode_vec(&colors, v, Some(&mut profiler)).unwrap();
            assert_eq!(words, lossless::encode(&colors, v));
            let decoded = codec.decode_vec(&words, colors.len(), None).unwrap();
            assert_eq!(decoded, expected(&colors, v));
        }
        print!("{}", profiler.table());
    }
    assert_clean(&ctx);
}

fn assert_clean(ctx: &std::sync::Arc<voxdag::gpu::GpuContext>) {
    // Deferred releases wait for the GPU: drain them first.
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// Asserts decoding `words` fails with `Corrupt` in validate, decode_all and decode of `index`.
fn assert_corrupt(words: &[u32], count: usize, index: usize, what: &str) {
    let is_corrupt = |r: Result<(), AttrError>| matches!(r, Err(AttrError::Corrupt { .. }));
    assert!(
        is_corrupt(lossless::validate(words, count)),
        "{what}: validate"
    );
    assert!(
        is_corrupt(lossless::decode_all(words, count).map(|_| ())),
        "{what}: decode_all"
    );
    assert!(
        is_corrupt(lossless::decode(words, count, index).map(|_| ())),
        "{what}: decode"
    );
}

#[test]
fn targeted_corruptions_are_reported() {
    let colors = structured(300, 5);
    let words = lossless::encode(&colors, LosslessVariant::Rgb888);
    let head_b = words[1];
    let runs = ((head_b >> 12) & 127) + 1;
    let mask_words = if runs > 1 { 4 } else { 0 };
    let palette = ((head_b >> 19) & 127) + 1;
    let indexed = (head_b >> 26) & 1 == 1;
    let stream_bits = palette * 9
        + if indexed {
            runs * (32 - (palette - 1).leading_zeros())
        } else {
            0
        }
        + 128 * ((head_b & 15) + ((head_b >> 4) & 15) + ((head_b >> 8) & 15));
    let table = 2 + mask_words + stream_bits.div_ceil(32) as usize;

    let mut w = words.clone();
    w[table] = 1; // block 1 pointing into block 0
    assert_corrupt(&w, 300, 128, "offset into block 0");
    let mut w = words.clone();
    w[table + 3] = 1; // block 2 offset beyond 2^32 words
    assert_corrupt(&w, 300, 299, "offset past the end");
    let mut w = words.clone();
    w[1] |= 1 << 31;
    assert_corrupt(&w, 300, 5, "reserved header bit");
    let mut w = words.clone();
    w[0] |= 1 << 24;
    assert_corrupt(&w, 300, 5, "reserved minimum bits");
    assert!(runs > 1, "the test input needs a mask in block 0");
    let mut w = words.clone();
    w[2] ^= 1; // bit 0 of the mask must stay clear
    assert_corrupt(&w, 300, 5, "mask bit 0");
    let mut w = words.clone();
    w[1] = (w[1] & !(127 << 12)) | ((runs % 127) << 12); // runs + 1 against the mask
    assert_corrupt(&w, 300, 5, "mask popcount");
    assert_corrupt(&words[..words.len() - 1], 300, 299, "truncated");
    assert_corrupt(&words[..table + 3], 300, 0, "table cut short");

    // A palette index past the palette, in an indexed block with a palette of 3 (2-bit indices).
    let colors: Vec<u32> = [0u8, 40, 0, 80, 40, 0, 80]
        .iter()
        .flat_map(|&g| std::iter::repeat_n(pack_rgb([0, g, 0]), 10))
        .collect();
    let mut w = lossless::encode(&colors, LosslessVariant::Rgb888);
    let h = w[1];
    assert_eq!((h >> 26) & 1, 1, "expected an indexed block: {h:#x}");
    assert_eq!(((h >> 19) & 127) + 1, 3);
    let stream = 2 + (((h >> 27) & 3) as usize + 1);
    w[stream] |= 3 << 27; // the first run index (bits 27..28 after three 9-bit entries)
    assert_corrupt(&w, colors.len(), 0, "palette index");
}
