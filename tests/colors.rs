//! Decoupled colour chunks (`attr::chunks`) with every codec: decode == input (exact codecs) or
//! within the threshold (lossy), random access == sequential decode, chunk rebuild == encoding
//! from scratch, chunk boundaries follow the SVO nodes, corrupt tables are errors.

use indicatif::ProgressBar;
use voxdag::attr::chunks::chunk_sizes;
use voxdag::attr::{
    max_channel_error, rmse, AttrError, ChunkOp, ChunkedColors, ColorCodec, ColorFormat,
    StoredColors,
};
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::scene::{morton, Voxels};

/// Every `--colors` spelling the tests cover.
const CODECS: &[&str] = &[
    "raw",
    "lossless",
    "lossless565",
    "lossy",
    "dolonius",
    "dado",
];

/// A 64^3 scene: a wavy surface with smooth colour gradients plus a few noisy speckles, so the
/// codecs see both easy and hard runs.
fn scene() -> Svdag {
    let n = 64u32;
    let mut voxels: Vec<(u64, u32)> = Vec::new();
    for z in 0..n {
        for x in 0..n {
            let h = 20.0 + 8.0 * ((x as f32) * 0.2).sin() * ((z as f32) * 0.15).cos();
            for y in 0..n {
                if (y as f32) <= h && (y as f32) > h - 3.0 || (x * 7 + y * 13 + z * 3) % 97 == 0 {
                    let speckle = (x * 31 + y * 17 + z * 5) % 11 == 0;
                    let c = if speckle {
                        x.wrapping_mul(2654435761) ^ z.wrapping_mul(40503) ^ y
                    } else {
                        (x * 4) | (y * 4) << 8 | (z * 4) << 16
                    };
                    voxels.push((morton::encode(x, y, z), c | 0xff00_0000));
                }
            }
        }
    }
    voxels.sort_unstable();
    let dag = Svdag::from_voxels(&Voxels {
        resolution: n,
        codes: voxels.iter().map(|v| v.0).collect(),
        colors: voxels.iter().map(|v| v.1).collect(),
    })
    .unwrap();
    assert!(dag.colors.len() > 5000);
    dag
}

fn codec(name: &str) -> ColorCodec {
    ColorCodec::parse(name).unwrap()
}

fn build(dag: &Svdag, codec: ColorCodec, depth: Option<u32>) -> ChunkedColors {
    ChunkedColors::build(dag, codec, depth, &ProgressBar::hidden()).unwrap()
}

/// The decoded colours are what the codec promises: exact, or within its threshold per channel.
fn assert_faithful(codec: ColorCodec, input: &[u32], decoded: &[u32]) {
    assert_eq!(input.len(), decoded.len());
    assert!(decoded.iter().all(|c| c >> 24 == 0xff), "alpha is 255");
    if codec.is_exact() {
        let rgb = |c: &u32| c & 0xff_ffff;
        assert!(
            input.iter().map(rgb).eq(decoded.iter().map(rgb)),
            "{}",
            codec.name()
        );
    } else {
        let err = max_channel_error(input, decoded);
        // The threshold is on colours in [0, 1]; allow one 8-bit step of rounding.
        assert!(
            err <= codec.threshold() + 1.0 / 255.0,
            "{}: max error {err}",
            codec.name()
        );
    }
}

#[test]
fn every_codec_round_trips_and_random_access_matches() {
    let dag = scene();
    for name in CODECS {
        let codec = codec(name);
        let chunks = build(&dag, codec, Some(3));
        chunks.validate().unwrap();
        assert_eq!(chunks.format, codec.format());
        assert_eq!(chunks.color_count(), dag.colors.len() as u64);
        let all = chunks.decode_all().unwrap();
        assert_faithful(codec, &dag.colors, &all);
        for i in (0..all.len()).step_by(7) {
            assert_eq!(chunks.color(i as u64).unwrap(), all[i], "{name} colour {i}");
        }
        assert!(matches!(
            chunks.color(all.len() as u64),
            Err(AttrError::IndexOutOfRange { .. })
        ));
    }
}

#[test]
fn chunks_are_the_svo_nodes_at_the_chosen_depth() {
    let dag = scene();
    let index = VoxelIndex::new(&dag);
    // Depth 0: the root, one chunk with every colour.
    assert_eq!(chunk_sizes(&dag, &index, 0), vec![dag.colors.len() as u64]);
    // Depth 2 at 64^3: nodes of 16^3 voxels. Count the occupied ones from the voxels.
    let mut cells: Vec<u64> = Vec::new();
    dag.for_each_voxel(|code| cells.push(code >> 12));
    cells.dedup();
    let sizes = chunk_sizes(&dag, &index, 2);
    assert_eq!(sizes.len(), cells.len());
    assert_eq!(sizes.iter().sum::<u64>(), dag.colors.len() as u64);
    // Deeper than the leaves: clamped to the leaves' depth (root level 4 at 64^3).
    let leaves = chunk_sizes(&dag, &index, 99);
    assert_eq!(leaves, chunk_sizes(&dag, &index, dag.root_level()));
    let chunks = build(&dag, codec("raw"), Some(99));
    assert_eq!(chunks.chunk_depth, dag.root_level());
    assert_eq!(chunks.chunk_count(), leaves.len());
    // Defaults: nodes of 256^3 (exact codecs) and 128^3 (lossy); 7 and 8 at 32K^3.
    assert_eq!(codec("raw").default_chunk_depth(1 << 15), 7);
    assert_eq!(codec("lossless").default_chunk_depth(1024), 2);
    assert_eq!(codec("dado").default_chunk_depth(64), 0);
}

#[test]
fn rebuild_equals_encoding_from_scratch() {
    let dag = scene();
    for name in CODECS {
        let codec = codec(name);
        let mut chunks = build(&dag, codec, Some(2));
        let reference = chunks.decode_all().unwrap();
        let c = chunks.chunk_count() / 2;
        let range = chunks.chunk_colors(c);
        let (start, len) = (range.start, range.end - range.start);
        // An edit inside chunk c: keep the first half, paint 10 voxels, add 5 new ones, keep the
        // rest, and copy the first 3 colours of chunk 0.
        let half = len / 2;
        let ops = vec![
            ChunkOp::Copy {
                from: start,
                len: half,
            },
            ChunkOp::Fill {
                color: 0xff10_2030,
                len: 10.min(len - half),
            },
            ChunkOp::Write(vec![
                0xff00_00ff,
                0xff00_ff00,
                0xffff_0000,
                0xff80_8080,
                0xff01_0203,
            ]),
            ChunkOp::Copy {
                from: start + half + 10.min(len - half),
                len: len - half - 10.min(len - half),
            },
            ChunkOp::Copy { from: 0, len: 3 },
        ];
        let mut new_chunk: Vec<u32> = reference[start as usize..(start + half) as usize].to_vec();
        new_chunk.resize(new_chunk.len() + 10.min(len - half) as usize, 0xff10_2030);
        new_chunk.extend([
            0xff00_00ff,
            0xff00_ff00,
            0xffff_0000,
            0xff80_8080,
            0xff01_0203,
        ]);
        new_chunk.extend_from_slice(
            &reference[(start + half + 10.min(len - half)) as usize..(start + len) as usize],
        );
        new_chunk.extend_from_slice(&reference[..3]);
        chunks.rebuild(c, &ops).unwrap();
        chunks.validate().unwrap();

        // From scratch: the same chunk sizes, the same stream.
        let mut stream = reference[..start as usize].to_vec();
        stream.extend_from_slice(&new_chunk);
        stream.extend_from_slice(&reference[(start + len) as usize..]);
        let mut sizes: Vec<u64> = chunks
            .chunk_starts
            .windows(2)
            .map(|w| w[1] - w[0])
            .collect();
        sizes[c] = new_chunk.len() as u64;
        let scratch =
            ChunkedColors::encode(&stream, &sizes, codec, 2, &ProgressBar::hidden()).unwrap();
        if codec.is_exact() {
            assert_eq!(chunks, scratch, "{name}");
        } else {
            // Other chunks are untouched; chunk c is encoded from its (already lossy) colours.
            assert_eq!(chunks.chunk_starts, scratch.chunk_starts, "{name}");
            assert_eq!(
                chunks.decode_chunk(c).unwrap(),
                codec_roundtrip(codec, &new_chunk)
            );
        }
        // Out-of-range copies and chunks are errors, and leave the chunks untouched.
        let before = chunks.clone();
        let past = chunks.color_count();
        assert!(chunks
            .rebuild(c, &[ChunkOp::Copy { from: past, len: 1 }])
            .is_err());
        assert!(chunks.rebuild(chunks.chunk_count(), &[]).is_err());
        assert!(chunks
            .rebuild(
                c,
                &[ChunkOp::Fill {
                    color: 0,
                    len: u64::MAX
                }]
            )
            .is_err());
        assert_eq!(chunks, before);
    }
}

fn codec_roundtrip(codec: ColorCodec, colors: &[u32]) -> Vec<u32> {
    voxdag::attr::decode_all(codec.format(), &codec.encode(colors), colors.len()).unwrap()
}

#[test]
fn corrupt_tables_are_errors() {
    let dag = scene();
    let good = build(&dag, codec("raw"), Some(2));
    type Mutation = (&'static str, Box<dyn Fn(&mut ChunkedColors)>);
    let mutations: Vec<Mutation> = vec![
        (
            "short offsets",
            Box::new(|c| {
                c.chunk_offsets.pop();
            }),
        ),
        ("start not 0", Box::new(|c| c.chunk_starts[0] = 1)),
        (
            "decreasing starts",
            Box::new(|c| c.chunk_starts[1] = c.chunk_starts[2] + 1),
        ),
        (
            "decreasing offsets",
            Box::new(|c| c.chunk_offsets[1] = c.chunk_offsets[2] + 1),
        ),
        (
            "offsets past the words",
            Box::new(|c| *c.chunk_offsets.last_mut().unwrap() += 1),
        ),
        (
            "words missing",
            Box::new(|c| {
                c.words.pop();
            }),
        ),
        (
            "wrong format",
            Box::new(|c| c.format = ColorFormat::Palette),
        ),
        (
            "raw chunk of wrong size",
            Box::new(|c| {
                c.chunk_offsets[1] -= 1;
            }),
        ),
    ];
    for (what, mutate) in mutations {
        let mut bad = good.clone();
        mutate(&mut bad);
        assert!(bad.validate().is_err(), "{what}");
    }
}

#[test]
fn codec_spellings() {
    for name in CODECS {
        let c = codec(name);
        assert_eq!(ColorCodec::parse(&c.name()).unwrap(), c, "{name}");
        assert_eq!(
            ColorCodec::from_id(c.id(), c.threshold()),
            Some(c),
            "{name}"
        );
    }
    assert_eq!(codec("lossy=0.1"), ColorCodec::Lossy { threshold: 0.1 });
    assert_eq!(codec("dolonius").threshold(), 0.06);
    assert_eq!(codec("lossy").default_chunk_depth(1 << 15), 8);
    assert_eq!(codec("dolonius").default_chunk_depth(1024), 3);
    for bad in [
        "",
        "rgb",
        "raw=0.1",
        "lossy=0",
        "lossy=2",
        "lossy=x",
        "dolonius=-1",
    ] {
        assert!(ColorCodec::parse(bad).is_err(), "{bad:?}");
    }
}

#[test]
fn stored_colors_measure_their_error() {
    let dag = scene();
    for name in CODECS {
        let codec = codec(name);
        let stored = StoredColors::encode(&dag, codec, None, &ProgressBar::hidden()).unwrap();
        let decoded = stored.chunks.decode_all().unwrap();
        assert_eq!(stored.rmse, rmse(&dag.colors, &decoded));
        if codec.is_exact() {
            assert_eq!(stored.rmse, 0.0);
        }
    }
    // Colours that do not match the voxels are rejected.
    let mut wrong = dag.clone();
    wrong.colors.pop();
    assert!(ChunkedColors::build(&wrong, codec("raw"), None, &ProgressBar::hidden()).is_err());
}
