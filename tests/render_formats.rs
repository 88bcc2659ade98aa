//! GPU traversal of every DAG format directly (no decoding to svdag32): on three scenes (two
//! meshes and a synthetic scene of mirrored, permuted and translated copies), every format and
//! mode (the table modes also as the format-v1 encoder writes them, whose 16-bit pointers are
//! all table indices; and on teapot 256^3 the S+A+T table modes, whose tagged levels have
//! tables) gives exactly the svdag32 first-hit buffer (hit, voxel, normal, `t` bits, colour
//! index) and exactly the svdag32 image, on any Vulkan device (lavapipe in CI).

mod common;

use common::{build_scene, gpu, has_translated_pointer, repo};
use voxdag::dag::build_transform_dag;
use voxdag::dag::encode::{
    EncodedDag, SsvdagEncoding, TransformGraph, TsvdagEncoding, TsvdagOptions, TsvdagTuning,
};
use voxdag::dag::transform::{Transform, TransformSet};
use voxdag::dag::Svdag;
use voxdag::render::cpu::ColorSource;
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{Camera, FirstHit, RenderSettings, TraversalFormat};
use voxdag::scene::{morton, Voxels};

/// Every voxel gets its own colour (a hash of its Morton rank), so a wrong colour index shows
/// in the image as well as in the hit buffer.
fn with_rank_colors(mut dag: Svdag) -> Svdag {
    let voxels: u64 = voxdag::dag::VoxelIndex::new(&dag).node_voxels[0];
    dag.colors = (0..voxels)
        .map(|i| {
            let h = (i.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 40) as u32;
            h & 0x00ff_ffff | 0xff00_0000
        })
        .collect();
    dag
}

/// 64^3: an asymmetric 14-voxel blob stamped into 16^3 cells at different offsets, mirrored
/// and axis-permuted, plus a floor: S+A finds the mirrored/permuted copies, S+A+T the shifted
/// ones (translated pointers into 16^3, 8^3 and 4^3 nodes).
fn copies_scene() -> Svdag {
    let blob: [[u32; 3]; 14] = [
        [0, 0, 0],
        [1, 0, 0],
        [2, 0, 0],
        [3, 0, 0],
        [0, 1, 0],
        [0, 2, 0],
        [1, 2, 1],
        [0, 0, 1],
        [0, 0, 2],
        [2, 1, 2],
        [4, 1, 0],
        [5, 3, 1],
        [1, 4, 3],
        [3, 3, 5],
    ];
    let mut codes = Vec::new();
    let mut cell = 0u32;
    for cz in 0..4u32 {
        for cy in 1..4u32 {
            for cx in 0..4u32 {
                cell += 1;
                if cell.is_multiple_of(3) {
                    continue;
                }
                let t = Transform::from_index((cell * 7 % 48) as usize).unwrap();
                let shift = [cell % 7, (cell * 3) % 9, (cell * 5) % 8];
                for v in blob {
                    // Transform inside an 8^3 box, then shift inside the 16^3 cell.
                    let p = t.apply_point(v, 8);
                    codes.push(morton::encode(
                        cx * 16 + p[0] + shift[0],
                        cy * 16 + p[1] + shift[1],
                        cz * 16 + p[2] + shift[2],
                    ));
                }
            }
        }
    }
    for z in 0..64u32 {
        for x in 0..64u32 {
            if (x / 8 + z / 8) % 3 != 0 {
                codes.push(morton::encode(x, 0, z));
            }
        }
    }
    codes.sort_unstable();
    codes.dedup();
    Svdag::from_voxels(&Voxels {
        resolution: 64,
        codes,
        colors: Vec::new(),
    })
    .unwrap()
}

/// Every encoding the GPU traverses, with its name.
fn encodings(dag: &Svdag) -> Vec<(String, EncodedDag)> {
    let mut out = vec![(
        "ssvdag".to_string(),
        EncodedDag::Ssvdag(SsvdagEncoding::build(dag).unwrap()),
    )];
    // `voxdag build`'s three modes (base, lut, huffman) and Huffman without tables.
    let [base, lut, huffman] = TsvdagOptions::MODES;
    let huffman_nolut = TsvdagOptions {
        lut: false,
        huffman: true,
    };
    let modes = [base, lut, huffman, huffman_nolut];
    for (set, set_name) in [
        (TransformSet::All, "sa"),
        (TransformSet::Mirrors, "s"),
        (TransformSet::AxisPermutations, "a"),
    ] {
        for translations in [false, true] {
            for mode in modes {
                // S and A alone in the base mode only (the modes are tested with S+A).
                if set != TransformSet::All && (mode.lut || mode.huffman) {
                    continue;
                }
                let e =
                    TsvdagEncoding::build_with_translations(dag, set, translations, mode).unwrap();
                let name = format!(
                    "tsvdag {set_name}{} {}",
                    if translations { "t" } else { "" },
                    mode.mode_name()
                );
                out.push((name, EncodedDag::Tsvdag(e)));
            }
            // The format-v1 encoder (no tagged pointers): every 16-bit pointer is a pointer
            // table index, so the table modes read their tables on every scene (the tuned
            // encoder above tags the pointers of small scenes and leaves their tables empty).
            for mode in [lut, huffman] {
                let graph = TransformGraph::from_transform_dag(build_transform_dag(
                    dag,
                    TransformSet::All,
                    translations,
                ));
                let e = TsvdagEncoding::encode_tuned(&graph, mode, TsvdagTuning::V1).unwrap();
                assert!(
                    e.tables.iter().any(|t| !t.is_empty()),
                    "the v1 {} encoding has no pointer table: the test would not cover them",
                    mode.mode_name()
                );
                let name = format!(
                    "tsvdag sa{} {} (v1 encoder)",
                    if translations { "t" } else { "" },
                    mode.mode_name()
                );
                out.push((name, EncodedDag::Tsvdag(e)));
            }
        }
    }
    out
}

/// Cameras: the default framing, a close one looking down, an axis-aligned one from inside.
fn cameras(dag: &Svdag) -> Vec<RenderSettings> {
    let n = dag.resolution as f32;
    let mut close = Camera::frame(dag);
    close.eye = [0.9 * n, 0.8 * n, 0.15 * n];
    close.target = [0.4 * n, 0.1 * n, 0.6 * n];
    let mut inside = Camera::frame(dag);
    inside.eye = [0.5 * n + 0.25, 0.5 * n, 0.5 * n];
    inside.target = [0.5 * n + 0.25, 0.5 * n, -n];
    [Camera::frame(dag), close, inside]
        .into_iter()
        .map(|c| RenderSettings::new(96, 72, c))
        .collect()
}

fn check_scene(name: &str, dag: Svdag, expect_translations: bool) {
    let encodings = encodings(&dag);
    check_encodings(name, dag, &encodings, expect_translations);
}

/// Renders `encodings` of `dag` against svdag32 (see the module docs).
fn check_encodings(
    name: &str,
    dag: Svdag,
    encodings: &[(String, EncodedDag)],
    expect_translations: bool,
) {
    let dag = with_rank_colors(dag);
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let reference = renderer.upload(&dag).unwrap();
    let mut translated_modes = 0;
    for settings in cameras(&dag) {
        let (ref_image, ref_hits) = renderer.render_first_hits(&reference, &settings).unwrap();
        let hit_count = ref_hits.iter().filter(|h| h.hit == 1).count();
        assert!(
            hit_count > ref_hits.len() / 50,
            "{name}: only {hit_count} pixels hit, the camera misses the scene"
        );
        for (enc_name, enc) in encodings {
            let scene = renderer
                .upload_encoded(enc, ColorSource::Raw(&dag.colors))
                .unwrap();
            assert_eq!(scene.format(), TraversalFormat::of(enc));
            let (image, hits) = renderer.render_first_hits(&scene, &settings).unwrap();
            let bad: Vec<(usize, &FirstHit, &FirstHit)> = hits
                .iter()
                .zip(&ref_hits)
                .enumerate()
                .filter(|(_, (a, b))| a != b)
                .map(|(i, (a, b))| (i, a, b))
                .collect();
            assert!(
                bad.is_empty(),
                "{name} / {enc_name} ({}): {} of {} first hits differ from svdag32, first: \
                 pixel {} got {:?} expected {:?}",
                scene.format().name(),
                bad.len(),
                hits.len(),
                bad[0].0,
                bad[0].1,
                bad[0].2
            );
            assert!(
                image.rgba == ref_image.rgba && image.hits == ref_image.hits,
                "{name} / {enc_name}: the image differs from the svdag32 render"
            );
            if let EncodedDag::Tsvdag(e) = enc {
                if e.translations && has_translated_pointer(e) {
                    translated_modes += 1;
                }
            }
        }
    }
    if expect_translations {
        assert!(
            translated_modes > 0,
            "{name}: no S+A+T encoding has a translated pointer: the test would not cover them"
        );
    }
    drop(reference);
    drop(renderer);
    assert_eq!(
        context.validation_errors(),
        0,
        "Vulkan validation reported problems"
    );
}

#[test]
fn teapot_every_format_matches_svdag32() {
    let dag = build_scene(&repo().join("tests/data/teapot.obj"), Some(64));
    check_scene("teapot 64", dag, false);
}

#[test]
fn avocado_every_format_matches_svdag32() {
    let dag = build_scene(&repo().join("assets/avocado/Avocado.gltf"), Some(64));
    check_scene("avocado 64", dag, false);
}

#[test]
fn mirrored_and_translated_copies_every_format_matches_svdag32() {
    check_scene("copies 64", copies_scene(), true);
}

/// Tagged pointers into non-empty tables (a tag bit tells table index from inline value on
/// every pointer of a tagged level): the tuned encoder writes them for teapot 256^3 with
/// translations, not for the 64^3 scenes above.
#[test]
fn teapot_256_tagged_table_pointers_match_svdag32() {
    let dag = build_scene(&repo().join("tests/data/teapot.obj"), Some(256));
    let mut encodings = Vec::new();
    // The table modes: lut and huffman.
    for mode in TsvdagOptions::MODES.into_iter().filter(|m| m.lut) {
        let e =
            TsvdagEncoding::build_with_translations(&dag, TransformSet::All, true, mode).unwrap();
        let tagged_table = e
            .tables
            .iter()
            .zip(&e.tagged)
            .any(|(table, &tagged)| tagged && !table.is_empty());
        assert!(
            tagged_table,
            "teapot 256 sat {}: no tagged level with a table, the test would not cover them",
            mode.mode_name()
        );
        let name = format!("tsvdag sat {}", mode.mode_name());
        encodings.push((name, EncodedDag::Tsvdag(e)));
    }
    check_encodings("teapot 256", dag, &encodings, true);
}

#[test]
fn variant_indices_cover_every_compiled_variant() {
    let all = TraversalFormat::all();
    for (i, f) in all.iter().enumerate() {
        assert_eq!(f.index(), i);
    }
    let names: std::collections::HashSet<&str> = all.iter().map(|f| f.name()).collect();
    assert_eq!(names.len(), all.len());
    assert_eq!(
        voxdag::gpu::shaders::RENDER_PRIMARY_BY_FORMAT.len(),
        all.len()
    );
}
