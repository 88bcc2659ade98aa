//! `.vdag` v1 round trips, rejection of corrupt files (never a panic), and xyz/.vox export.

use std::path::Path;

mod common;

use proptest::prelude::*;
use voxdag::dag::encode::EncodedDag;
use voxdag::dag::{export_vox, export_xyz_u32, export_xyz_u32_file, DagError, Svdag, MAGIC};
use voxdag::scene::{load_vox, morton, ImportOptions, Voxels};

/// A small scene with some sharing: a few slabs and scattered voxels.
fn scene(n: u32, colored: bool) -> Voxels {
    let mut codes = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                if (y == 2 && x % 4 < 3) || (x * 5 + y * 3 + z * 11) % 37 == 0 {
                    codes.push(morton::encode(x, y, z));
                }
            }
        }
    }
    codes.sort_unstable();
    let colors = if colored {
        codes
            .iter()
            .map(|&c| 0xff00_0000 | ((c as u32 % 7) * 0x0020_1008))
            .collect()
    } else {
        Vec::new()
    };
    Voxels {
        resolution: n,
        codes,
        colors,
    }
}

fn dag(n: u32, colored: bool) -> Svdag {
    Svdag::from_voxels(&scene(n, colored)).unwrap()
}

/// Recomputes the trailing CRC after a deliberate edit.
fn fix_crc(bytes: &mut [u8]) {
    let len = bytes.len();
    let crc = crc32fast::hash(&bytes[..len - 4]);
    bytes[len - 4..].copy_from_slice(&crc.to_le_bytes());
}

fn put_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn put_u64(bytes: &mut [u8], at: usize, v: u64) {
    bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

fn get_u64(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
}

/// Byte offset of the words section (second table entry).
fn words_offset(bytes: &[u8]) -> usize {
    get_u64(bytes, 64 + 24 + 8) as usize
}

/// Parses and expects a format error at `offset` that names the file.
fn expect_format_error(bytes: &[u8], offset: Option<u64>) {
    match Svdag::from_bytes(bytes, "corrupt.vdag") {
        Err(e @ DagError::Format { offset: got, .. }) => {
            assert!(e.to_string().contains("corrupt.vdag"), "{e}");
            if let Some(want) = offset {
                assert_eq!(got, want, "{e}");
            }
        }
        other => panic!("expected a format error, got {other:?}"),
    }
}

#[test]
fn round_trip_bytes_and_files() {
    let dir = tempfile::tempdir().unwrap();
    for (n, colored) in [(8, false), (16, true), (32, false), (64, true)] {
        let dag = dag(n, colored);
        let bytes = dag.to_bytes();
        assert_eq!(&bytes[..8], &MAGIC);
        assert_eq!(bytes.len() % 4, 0);
        assert_eq!(Svdag::from_bytes(&bytes, "mem").unwrap(), dag);
        let path = dir.path().join(format!("scene{n}.vdag"));
        dag.save(&path).unwrap();
        // `save` adds the content digest (section 7) that `to_bytes` leaves out.
        let saved = std::fs::read(&path).unwrap();
        assert!(saved.len() >= bytes.len() + 24 + 32);
        assert_eq!(Svdag::from_bytes(&saved, "saved").unwrap(), dag);
        assert_eq!(Svdag::load(&path).unwrap(), dag);
    }
    let empty = Svdag::from_voxels(&Voxels {
        resolution: 128,
        ..Default::default()
    })
    .unwrap();
    assert_eq!(Svdag::from_bytes(&empty.to_bytes(), "e").unwrap(), empty);
    // Saving over an existing file replaces it and leaves no temporary file behind.
    let path = dir.path().join("scene8.vdag");
    empty.save(&path).unwrap();
    assert_eq!(Svdag::load(&path).unwrap(), empty);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp-")), "{names:?}");
}

#[test]
fn missing_file_is_io_error() {
    let err = Svdag::load(Path::new("/nonexistent/dir/x.vdag")).unwrap_err();
    assert!(matches!(err, DagError::Io { .. }));
    assert!(err.to_string().contains("/nonexistent/dir/x.vdag"));
    let err = dag(8, false)
        .save(Path::new("/nonexistent/dir/x.vdag"))
        .unwrap_err();
    assert!(matches!(err, DagError::Io { .. }));
}

#[test]
fn every_truncation_is_rejected() {
    let bytes = dag(16, true).to_bytes();
    assert!(bytes.len() < 4096, "small file expected");
    for len in 0..bytes.len() {
        expect_format_error(&bytes[..len], None);
    }
    let mut longer = bytes.clone();
    longer.extend_from_slice(&[0; 4]);
    expect_format_error(&longer, Some(32));
}

#[test]
fn header_corruptions_are_rejected() {
    let good = dag(16, true).to_bytes();
    let len = good.len();

    let mut b = good.clone();
    b[0] = b'X';
    expect_format_error(&b, Some(0));

    for version in [0, voxdag::dag::FORMAT_VERSION + 1] {
        let mut b = good.clone();
        put_u32(&mut b, 8, version);
        fix_crc(&mut b);
        expect_format_error(&b, Some(8));
    }

    let mut b = good.clone();
    b[len - 10] ^= 0x40;
    expect_format_error(&b, Some(len as u64 - 4));

    let mut b = good.clone();
    put_u32(&mut b, 12, 7);
    fix_crc(&mut b);
    expect_format_error(&b, Some(12));

    for res in [0, 4, 24, 1 << 22] {
        let mut b = good.clone();
        put_u32(&mut b, 16, res);
        fix_crc(&mut b);
        expect_format_error(&b, Some(16));
    }
    // A valid resolution that disagrees with the level count.
    let mut b = good.clone();
    put_u32(&mut b, 16, 32);
    fix_crc(&mut b);
    expect_format_error(&b, Some(20));

    let mut b = good.clone();
    put_u32(&mut b, 24, 9);
    fix_crc(&mut b);
    expect_format_error(&b, Some(24));

    for count in [0, 2, 65, u32::MAX] {
        let mut b = good.clone();
        put_u32(&mut b, 28, count);
        fix_crc(&mut b);
        expect_format_error(&b, Some(28));
    }
}

#[test]
fn absurd_sizes_and_offsets_are_rejected() {
    let good = dag(16, true).to_bytes();

    // Word count 2^40: rejected before anything is allocated.
    let mut b = good.clone();
    put_u64(&mut b, 40, 1 << 40);
    fix_crc(&mut b);
    expect_format_error(&b, Some(40));

    // Word count plausible but disagreeing with the words section length.
    let mut b = good.clone();
    let words = get_u64(&b, 40);
    put_u64(&mut b, 40, words + 1);
    fix_crc(&mut b);
    expect_format_error(&b, Some(64 + 24 + 16));

    // Colour count 2^62 (its byte length overflows u64).
    let mut b = good.clone();
    put_u64(&mut b, 48, 1 << 62);
    fix_crc(&mut b);
    expect_format_error(&b, Some(64 + 2 * 24 + 16));

    // Section offsets past the end, overflowing, inside the header, misaligned.
    for (entry, offset) in [(0, u64::MAX - 3), (1, 1 << 40), (2, 8), (1, 4100), (1, 129)] {
        let mut b = good.clone();
        put_u64(&mut b, 64 + 24 * entry + 8, offset);
        fix_crc(&mut b);
        expect_format_error(&b, Some(64 + 24 * entry as u64 + 8));
    }
    // Two sections at the same offset.
    let mut b = good.clone();
    let levels_at = get_u64(&b, 64 + 8);
    put_u64(&mut b, 64 + 24 * 2 + 8, levels_at);
    fix_crc(&mut b);
    expect_format_error(&b, None);

    // A section id listed twice, or an unknown id standing in for a required one.
    for id in [2u32, 99] {
        let mut b = good.clone();
        put_u32(&mut b, 64, id);
        fix_crc(&mut b);
        expect_format_error(&b, None);
    }
}

#[test]
fn structural_corruptions_are_rejected() {
    // Resolution 16: root (level 2) -> level 1 -> leaves.
    let dag = dag(16, true);
    let good = dag.to_bytes();
    let words_at = words_offset(&good);
    let level1 = dag.level_starts[1] as usize;
    let leaves = dag.level_starts[0] as usize;

    // Root child pointer to a leaf (wrong level).
    let mut b = good.clone();
    put_u32(&mut b, words_at + 4, leaves as u32);
    fix_crc(&mut b);
    expect_format_error(&b, Some(words_at as u64 + 4));

    // Root child pointer into the middle of a level-1 node.
    let mut b = good.clone();
    put_u32(&mut b, words_at + 4, level1 as u32 + 1);
    fix_crc(&mut b);
    expect_format_error(&b, Some(words_at as u64 + 4));

    // Pointer past the end, and a pointer to itself (a cycle).
    for target in [u32::MAX, 0] {
        let mut b = good.clone();
        put_u32(&mut b, words_at + 4 * (level1 + 1), target);
        fix_crc(&mut b);
        expect_format_error(&b, Some((words_at + 4 * (level1 + 1)) as u64));
    }

    // Child masks with bits above 8, or zero.
    for mask in [0x100, 0] {
        let mut b = good.clone();
        put_u32(&mut b, words_at, mask);
        fix_crc(&mut b);
        expect_format_error(&b, None);
    }

    // An empty leaf.
    let mut b = good.clone();
    let last_leaf = words_at + 4 * (dag.words.len() - 2);
    put_u64(&mut b, last_leaf, 0);
    fix_crc(&mut b);
    expect_format_error(&b, Some(last_leaf as u64));

    // Level starts out of order.
    let mut b = good.clone();
    let levels_at = get_u64(&b, 64 + 8) as usize;
    put_u64(&mut b, levels_at, 1);
    fix_crc(&mut b);
    expect_format_error(&b, Some(levels_at as u64));

    // Colour count that does not match the voxel count (consistent sizes, valid checksum).
    let mut fewer = dag.clone();
    fewer.colors.pop();
    assert!(fewer.validate().is_err());
    expect_format_error(&fewer.to_bytes(), Some(48));
}

#[test]
fn validate_catches_bad_in_memory_dags() {
    let good = dag(32, false);
    good.validate().unwrap();
    let mut bad = good.clone();
    bad.level_starts.pop();
    assert!(matches!(bad.validate(), Err(DagError::Invalid { .. })));
    let mut bad = good.clone();
    bad.words[1] = bad.words.len() as u32;
    assert!(matches!(
        bad.validate(),
        Err(DagError::Invalid { word: 1, .. })
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Any single corrupted byte (with or without a repaired checksum) gives an error or a DAG
    /// that validates and can be traversed.
    #[test]
    fn flipped_bytes_never_panic(
        colored in any::<bool>(),
        flips in prop::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 1..4),
        repair in any::<bool>(),
    ) {
        let original = dag(16, colored);
        let mut b = original.to_bytes();
        for (at, xor) in &flips {
            let i = at.index(b.len());
            b[i] ^= xor;
        }
        if repair {
            fix_crc(&mut b);
        }
        if let Ok(d) = Svdag::from_bytes(&b, "fuzz.vdag") {
            d.validate().unwrap();
            let v = d.to_voxels();
            prop_assert_eq!(v.len() as u64, d.voxel_count());
            let rebuilt = Svdag::from_voxels(&v).unwrap();
            prop_assert_eq!(&rebuilt.to_voxels(), &v);
            for &code in v.codes.iter().take(64) {
                let [x, y, z] = morton::decode(code);
                prop_assert!(d.contains(x, y, z));
            }
            let _ = d.stats();
        }
    }
}

#[test]
fn xyz_export_bytes() {
    let v = scene(16, false);
    let dag = Svdag::from_voxels(&v).unwrap();
    let mut out = Vec::new();
    export_xyz_u32(&dag, &mut out).unwrap();
    let mut want = Vec::new();
    for &code in &v.codes {
        for c in morton::decode(code) {
            want.extend_from_slice(&c.to_le_bytes());
        }
    }
    assert_eq!(out, want);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.xyz");
    export_xyz_u32_file(&dag, &path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), want);
}

/// Reads a .vox written by `export_vox` back into voxdag coordinates and RGBA8 colours.
fn reimport(path: &Path, n: u32) -> Vec<(u64, u32)> {
    let data = dot_vox::load(path.to_str().unwrap()).unwrap();
    assert_eq!(data.models.len(), 1);
    let model = &data.models[0];
    assert_eq!((model.size.x, model.size.y, model.size.z), (n, n, n));
    let mut out: Vec<(u64, u32)> = model
        .voxels
        .iter()
        .map(|v| {
            let c = data.palette[v.i as usize];
            let rgba = u32::from_le_bytes([c.r, c.g, c.b, c.a]);
            // Import mapping: (x, y, z)_vox -> (x, z, N - 1 - y).
            let code = morton::encode(v.x as u32, v.z as u32, n - 1 - v.y as u32);
            (code, rgba)
        })
        .collect();
    out.sort_unstable();
    out
}

#[test]
fn vox_export_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.vox");

    // Exact palette (7 distinct colours).
    let v = scene(32, true);
    export_vox(&Svdag::from_voxels(&v).unwrap(), &path).unwrap();
    let want: Vec<(u64, u32)> = v
        .codes
        .iter()
        .copied()
        .zip(v.colors.iter().copied())
        .collect();
    assert_eq!(reimport(&path, 32), want);

    // No colours: one grey entry.
    let v = scene(8, false);
    export_vox(&Svdag::from_voxels(&v).unwrap(), &path).unwrap();
    let got = reimport(&path, 8);
    assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), v.codes);
    assert!(got.iter().all(|g| g.1 == 0xff80_8080));

    // More than 255 colours: positions exact, colours within one cube step (<= 26 per channel).
    let mut v = scene(64, false);
    v.colors = v
        .codes
        .iter()
        .map(|&c| 0xff00_0000 | ((c as u32).wrapping_mul(2_654_435_761) & 0xff_ffff))
        .collect();
    export_vox(&Svdag::from_voxels(&v).unwrap(), &path).unwrap();
    let got = reimport(&path, 64);
    assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), v.codes);
    for (g, &want) in got.iter().zip(&v.colors) {
        for ch in 0..3 {
            let (a, b) = ((g.1 >> (8 * ch)) & 0xff, (want >> (8 * ch)) & 0xff);
            assert!(a.abs_diff(b) <= 26, "{:#x} vs {want:#x}", g.1);
        }
    }
}

#[test]
fn vox_export_rejects_large_grids() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.vox");
    let v = Voxels {
        resolution: 512,
        codes: vec![0, 1],
        colors: vec![],
    };
    let err = export_vox(&Svdag::from_voxels(&v).unwrap(), &path).unwrap_err();
    assert!(matches!(err, DagError::Export { .. }));
    assert!(err.to_string().contains("256"), "{err}");
    assert!(!path.exists());
}

#[test]
fn documented_example_layout() {
    let dag = Svdag::from_voxels(&Voxels {
        resolution: 8,
        codes: vec![0, 511],
        colors: vec![],
    })
    .unwrap();
    assert_eq!(dag.words, vec![0x81, 3, 5, 1, 0, 0, 0x8000_0000]);
    assert_eq!(dag.level_starts, vec![3, 0]);
    let b = dag.to_bytes();
    assert_eq!(b.len(), 188);
    assert_eq!(get_u64(&b, 32), 188);
    let entries: Vec<(u64, u64)> = (0..3)
        .map(|i| (get_u64(&b, 64 + 24 * i + 8), get_u64(&b, 64 + 24 * i + 16)))
        .collect();
    assert_eq!(entries, vec![(136, 16), (152, 28), (184, 0)]);
    assert_eq!(&b[152..156], &0x81u32.to_le_bytes());
    assert_eq!(get_u64(&b, 136), 3);
    assert_eq!(
        u32::from_le_bytes(b[184..188].try_into().unwrap()),
        crc32fast::hash(&b[..184])
    );
}

#[test]
fn real_vox_model_round_trips() {
    let Some(dir) = common::shared_data() else {
        return;
    };
    let src = dir.join("vox/voxel-model/monument/monu1.vox");
    let v = load_vox(&src, &ImportOptions::default()).unwrap();
    let n = v.resolution;
    let pairs: Vec<(u64, u32)> = v
        .codes
        .iter()
        .copied()
        .zip(v.colors.iter().copied())
        .collect();
    let dag = Svdag::from_voxels(&v).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("monu1.vdag");
    dag.save(&path).unwrap();
    assert_eq!(Svdag::load(&path).unwrap(), dag);
    // .vox export and re-import: same voxels, exact colours (the source has <= 255 colours).
    let vox = tmp.path().join("monu1.vox");
    export_vox(&dag, &vox).unwrap();
    assert_eq!(reimport(&vox, n), pairs);
}

/// The fuzz property above must not pass by rejecting everything: a colour byte changed under a
/// repaired checksum is a valid file and loads with exactly that colour changed.
#[test]
fn repaired_colour_edit_is_accepted() {
    let original = dag(16, true);
    let mut bytes = original.to_bytes();
    let colors_len = original.colors.len() * 4;
    let at = bytes.len() - 4 - colors_len; // colours are the last section, before the CRC
    bytes[at] ^= 0x5a;
    fix_crc(&mut bytes);
    let loaded =
        Svdag::from_bytes(&bytes, "edited.vdag").expect("a colour edit keeps the file valid");
    assert_eq!(loaded.words, original.words);
    assert_eq!(loaded.colors[0], original.colors[0] ^ 0x5a);
    assert_eq!(loaded.colors[1..], original.colors[1..]);
}

// ---- Chunked encoded colours (colour format 2, section 6) ----

/// A colour-rich 32^3 file (svdag32, digest) with its colours stored by `codec`.
fn chunked_file(codec: &str) -> voxdag::dag::VdagFile {
    use voxdag::attr::{ColorCodec, StoredColors};
    use voxdag::dag::encode::VoxelDigest;
    let mut v = scene(32, true);
    for (i, c) in v.colors.iter_mut().enumerate() {
        *c ^= (i as u32).wrapping_mul(2654435761) & 0x00ff_ffff;
    }
    let dag = Svdag::from_voxels(&v).unwrap();
    let codec = ColorCodec::parse(codec).unwrap();
    let stored =
        StoredColors::encode(&dag, codec, Some(2), &indicatif::ProgressBar::hidden()).unwrap();
    // A reader sees the decoded colours, in the file and in its DAG.
    let mut decoded = dag;
    decoded.colors = stored.chunks.decode_all().unwrap();
    voxdag::dag::VdagFile {
        colors: decoded.colors.clone(),
        digest: Some(VoxelDigest::of_codes(&v.codes)),
        encoded: EncodedDag::Svdag32(decoded),
        stored_colors: Some(stored),
        materials: None,
    }
}

/// Byte offset of section `id` (from the section table).
fn section_offset(bytes: &[u8], id: u32) -> usize {
    let count = u32::from_le_bytes(bytes[28..32].try_into().unwrap()) as usize;
    (0..count)
        .map(|i| 64 + 24 * i)
        .find(|&at| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) == id)
        .map(|at| get_u64(bytes, at + 8) as usize)
        .expect("section present")
}

/// Both loaders (colours decoded, colours kept encoded) report the same format error.
fn expect_file_error(bytes: &[u8], offset: Option<u64>) {
    use voxdag::dag::VdagFile;
    for loaded in [
        VdagFile::from_bytes(bytes, "corrupt.vdag"),
        VdagFile::from_bytes_encoded_colors(bytes, "corrupt.vdag"),
    ] {
        match loaded {
            Err(e @ DagError::Format { offset: got, .. }) => {
                assert!(e.to_string().contains("corrupt.vdag"), "{e}");
                if let Some(want) = offset {
                    assert_eq!(got, want, "{e}");
                }
            }
            other => panic!("expected a format error, got {:?}", other.map(|_| ())),
        }
    }
}

#[test]
fn chunked_colours_round_trip() {
    for codec in ["raw", "lossless", "lossless565"] {
        let file = chunked_file(codec);
        let bytes = file.to_bytes().unwrap();
        assert_eq!(u32::from_le_bytes(bytes[24..28].try_into().unwrap()), 2);
        let loaded = voxdag::dag::VdagFile::from_bytes(&bytes, "mem").unwrap();
        assert!(loaded == file, "{codec}: loaded file differs");
        // Svdag::from_bytes decodes the chunks too.
        let dag = Svdag::from_bytes(&bytes, "mem").unwrap();
        assert_eq!(dag.colors, file.colors);
        // A renderer's load keeps them encoded: the same file without decoded colours.
        let encoded = voxdag::dag::VdagFile::from_bytes_encoded_colors(&bytes, "mem").unwrap();
        assert!(encoded.colors.is_empty());
        assert_eq!(encoded.stored_colors, file.stored_colors);
        assert_eq!(
            (encoded.digest, &encoded.materials),
            (file.digest, &file.materials)
        );
        let (EncodedDag::Svdag32(a), EncodedDag::Svdag32(b)) = (&encoded.encoded, &file.encoded)
        else {
            panic!("svdag32 expected");
        };
        assert!(a.colors.is_empty());
        assert_eq!((&a.words, &a.level_starts), (&b.words, &b.level_starts));
        // Saved as loaded, it is the same file: colour count and content digest come from
        // the chunks.
        assert!(
            encoded.to_bytes().unwrap() == bytes,
            "{codec}: re-saved bytes differ"
        );
        // Stored without encoding: RGBA8 files are still written and read.
        let mut plain = file.clone();
        plain.stored_colors = None;
        let plain_bytes = plain.to_bytes().unwrap();
        assert_eq!(
            u32::from_le_bytes(plain_bytes[24..28].try_into().unwrap()),
            1
        );
        assert_eq!(
            voxdag::dag::VdagFile::from_bytes(&plain_bytes, "mem").unwrap(),
            plain
        );
    }
}

#[test]
fn corrupt_chunked_colour_sections_are_rejected() {
    let file = chunked_file("lossless");
    let stored = file.stored_colors.as_ref().unwrap();
    let chunks = stored.chunks.chunk_count() as u64;
    assert!(chunks > 4);
    let good = file.to_bytes().unwrap();
    let at = section_offset(&good, 6);
    let starts = at + 40;
    let offsets = starts + 8 * (chunks as usize + 1);
    let words = offsets + 8 * (chunks as usize + 1);
    // (what, corruption, expected error offset)
    type Case = (&'static str, Box<dyn Fn(&mut Vec<u8>)>, Option<u64>);
    let cases: Vec<Case> = vec![
        (
            "codec id",
            Box::new(move |b| put_u32(b, at, 77)),
            Some(at as u64),
        ),
        (
            "format id",
            Box::new(move |b| put_u32(b, at + 4, 3)),
            Some(at as u64 + 4),
        ),
        (
            "chunk depth",
            Box::new(move |b| put_u32(b, at + 8, 9)),
            Some(at as u64 + 8),
        ),
        (
            "rmse",
            Box::new(move |b| put_u64(b, at + 16, f64::NAN.to_bits())),
            Some(at as u64 + 16),
        ),
        (
            "chunk count",
            Box::new(move |b| put_u64(b, at + 24, u64::MAX / 8)),
            Some(at as u64 + 24),
        ),
        (
            "word count",
            Box::new(move |b| put_u64(b, at + 32, u64::MAX)),
            Some(at as u64 + 24),
        ),
        (
            "starts not monotone",
            Box::new(move |b| put_u64(b, starts + 16, 1 << 40)),
            Some(starts as u64),
        ),
        (
            "offsets past the words",
            Box::new(move |b| put_u64(b, offsets + 8, 1 << 40)),
            Some(starts as u64),
        ),
        (
            "colour total",
            Box::new(move |b| {
                let last = starts + 8 * chunks as usize;
                let total = get_u64(b, last);
                put_u64(b, last, total - 1)
            }),
            None,
        ),
        // Chunk 0 starts with the lossless chunk header word: a wrong magic is reported there.
        (
            "chunk words",
            Box::new(move |b| put_u32(b, words, 0xdead_beef)),
            Some(words as u64),
        ),
        (
            "colour format without the section",
            Box::new(|b| put_u32(b, 24, 1)),
            None,
        ),
    ];
    for (what, mutate, offset) in cases {
        let mut bytes = good.clone();
        mutate(&mut bytes);
        fix_crc(&mut bytes);
        println!("{what}");
        expect_file_error(&bytes, offset);
        assert!(Svdag::from_bytes(&bytes, "corrupt.vdag").is_err(), "{what}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn flipped_chunked_colour_bytes_never_panic(at in 0usize..4096, bit in 0u8..8) {
        let mut bytes = chunked_file("lossless").to_bytes().unwrap();
        let at = at % (bytes.len() - 4);
        bytes[at] ^= 1 << bit;
        fix_crc(&mut bytes);
        let _ = voxdag::dag::VdagFile::from_bytes(&bytes, "flipped.vdag");
    }
}
