//! `.vdag` format v2 and the TSVDAG encoder's modes: files written by the format-v1 encoder still
//! load and verify, the compact translation fields are refused in v1 files, and `voxdag build`
//! writes S+A+T files in the mode asked for (or the smallest) that verify.

mod common;

use voxdag::dag::encode::{EncodedDag, TsvdagEncoding, TsvdagOptions, VoxelDigest};
use voxdag::dag::{DagError, Svdag, TransformSet, VdagFile, FORMAT_VERSION};
use voxdag::scene::{morton, Voxels};

/// Files written by the format-v1 encoder (commit d17156b; bunny at 64^3, S+A+T, one per mode)
/// load and decode to their build-time digest.
#[test]
fn format_v1_files_load_and_verify() {
    for mode in ["base", "lut", "huffman"] {
        let path = common::repo().join(format!("tests/data/v1-sat-{mode}.vdag"));
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 1);
        let file = VdagFile::from_bytes(&bytes, &path).unwrap();
        let EncodedDag::Tsvdag(e) = &file.encoded else {
            panic!("{mode}: not a tsvdag file");
        };
        assert_eq!(e.options.mode_name(), mode);
        assert!(e.translations && !e.compact_translations(), "{mode}");
        let digest = file.digest.expect("digest section");
        assert!(digest.voxels > 1000, "{mode}: {} voxels", digest.voxels);
        assert_eq!(file.encoded.digest().unwrap(), digest, "{mode}");
        // The same voxels re-encoded by today's encoder give the same digest.
        let dag = file.encoded.to_svdag(Vec::new()).unwrap();
        let again =
            TsvdagEncoding::build_with_translations(&dag, TransformSet::All, true, e.options)
                .unwrap();
        assert_eq!(
            EncodedDag::Tsvdag(again).digest().unwrap(),
            digest,
            "{mode}"
        );
    }
}

/// A scene with translated and mirrored repeats.
fn scene(n: u32) -> Voxels {
    let mut codes = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                if (x * 7 + y * 3 + z * 5) % 23 < 2 || (y == 3 && x % 5 < 3) {
                    codes.push(morton::encode(x, y, z));
                }
            }
        }
    }
    codes.sort_unstable();
    Voxels {
        resolution: n,
        codes,
        colors: Vec::new(),
    }
}

/// Flag bit 4 (compact translation fields) in a file that says version 1 is refused, at the
/// payload's flags field.
#[test]
fn compact_translations_need_version_2() {
    let voxels = scene(32);
    let dag = Svdag::from_voxels(&voxels).unwrap();
    let base = TsvdagOptions {
        lut: false,
        huffman: false,
    };
    let e = TsvdagEncoding::build_with_translations(&dag, TransformSet::All, true, base).unwrap();
    assert!(e.compact_translations());
    let file = VdagFile {
        encoded: EncodedDag::Tsvdag(e),
        colors: Vec::new(),
        digest: Some(VoxelDigest::of_codes(&voxels.codes)),
        stored_colors: None,
        materials: None,
    };
    let mut bytes = file.to_bytes().unwrap();
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
        FORMAT_VERSION
    );
    let back = VdagFile::from_bytes(&bytes, "v2.vdag").unwrap();
    assert_eq!(back.encoded.digest().unwrap(), file.digest.unwrap());
    // The payload is section 5: the third table entry of a tsvdag file.
    let payload_at =
        u64::from_le_bytes(bytes[64 + 2 * 24 + 8..64 + 2 * 24 + 16].try_into().unwrap());
    bytes[8..12].copy_from_slice(&1u32.to_le_bytes());
    let len = bytes.len();
    let crc = crc32fast::hash(&bytes[..len - 4]);
    bytes[len - 4..].copy_from_slice(&crc.to_le_bytes());
    match VdagFile::from_bytes(&bytes, "v1.vdag") {
        Err(e @ DagError::Format { offset, .. }) => {
            assert_eq!(offset, payload_at + 4, "{e}");
            assert!(e.to_string().contains("version 2"), "{e}");
        }
        other => panic!("expected a format error, got {other:?}"),
    }
}

/// `voxdag build --encoding tsvdag` writes S+A+T by default, in the smallest mode unless one is
/// pinned; every file verifies against the svdag32 build, and `stats --json` names the mode.
#[test]
fn cli_writes_sat_files_in_every_mode() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bunny = data.join("meshes/bunny.obj");
    let bunny = bunny.to_str().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let reference = path("ref.vdag");
    let o = common::voxdag_cli(&["-q", "build", bunny, "-r", "128", "-o", &reference]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut sizes = Vec::new();
    for (flags, mode) in [
        (vec!["--tsvdag-mode", "base"], "base"),
        (vec!["--tsvdag-mode", "lut"], "lut"),
        (vec!["--tsvdag-mode", "huffman"], "huffman"),
        (vec!["--no-lut", "--no-huffman"], "base"),
        (vec!["--no-huffman"], "lut"),
        (vec!["--no-lut"], "huffman-nolut"),
        (vec![], ""),
    ] {
        let out = path(&format!("b{}.vdag", sizes.len()));
        let mut args = vec![
            "-q",
            "build",
            bunny,
            "-r",
            "128",
            "--encoding",
            "tsvdag",
            "-o",
            &out,
        ];
        args.extend(&flags);
        let o = common::voxdag_cli(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = common::voxdag_cli(&["verify", &out, "--against", &reference]);
        assert!(
            v.status.success() && String::from_utf8_lossy(&v.stdout).starts_with("ok"),
            "{flags:?}: {}",
            String::from_utf8_lossy(&v.stderr)
        );
        let file = VdagFile::load(std::path::Path::new(&out)).unwrap();
        let EncodedDag::Tsvdag(e) = &file.encoded else {
            panic!("{flags:?}: not tsvdag");
        };
        assert!(e.translations, "{flags:?}: sat is the default");
        let s = common::voxdag_cli(&["stats", "--json", &out]);
        assert!(s.status.success());
        let json: serde_json::Value = serde_json::from_slice(&s.stdout).unwrap();
        assert_eq!(json["encoding"], "tsvdag");
        assert_eq!(json["tsvdag_mode"], e.options.mode_name());
        if !mode.is_empty() {
            assert_eq!(e.options.mode_name(), mode, "{flags:?}");
        }
        for key in ["tsvdag", "tsvdag_base", "tsvdag_lut"] {
            assert!(json["bytes"][key].as_u64().unwrap() > 0, "{key}");
        }
        sizes.push(e.byte_size());
    }
    // The default is the smallest of the three pinned modes.
    assert_eq!(sizes[6], sizes[..3].iter().copied().min().unwrap());
    let conflict = common::voxdag_cli(&[
        "-q",
        "build",
        bunny,
        "-r",
        "16",
        "--encoding",
        "tsvdag",
        "--tsvdag-mode",
        "lut",
        "--no-lut",
        "-o",
        &path("x.vdag"),
    ]);
    assert!(!conflict.status.success());
}
