//! Encodings (svdag32, ssvdag, tsvdag with every switch): exact round trips through the
//! traversal of the encoded bytes (enumeration, point lookup, ray cast), payload round trips,
//! translated pointers against a brute-force expansion, and corrupt payloads (errors, no panic).

mod common;

use proptest::prelude::*;
use voxdag::dag::digest::ContentDigest;
use voxdag::dag::encode::{
    contains, raycast, reorient, EncodedDag, GraphLevel, GraphPointer, SsvdagEncoding,
    TransformGraph, TranslationCoding, TsvdagEncoding, TsvdagOptions, VoxelDigest, VoxelIter,
};
use voxdag::dag::raycast::{Ray, T_UNBOUNDED};
use voxdag::dag::{build_transform_dag, Svdag, Transform, TransformSet, VoxelIndex};
use voxdag::scene::{morton, Voxels};

const SETS: [TransformSet; 4] = [
    TransformSet::None,
    TransformSet::Mirrors,
    TransformSet::AxisPermutations,
    TransformSet::All,
];

fn all_options() -> Vec<TsvdagOptions> {
    let mut v = Vec::new();
    for lut in [false, true] {
        for huffman in [false, true] {
            v.push(TsvdagOptions { lut, huffman });
        }
    }
    v
}

/// Every encoding of a DAG.
fn encodings(dag: &Svdag) -> Vec<(String, EncodedDag)> {
    let mut out = vec![
        ("svdag32".to_string(), EncodedDag::Svdag32(dag.clone())),
        (
            "ssvdag".to_string(),
            EncodedDag::Ssvdag(SsvdagEncoding::build(dag).unwrap()),
        ),
    ];
    for set in SETS {
        for o in all_options() {
            let e = TsvdagEncoding::build(dag, set, o).unwrap();
            out.push((format!("tsvdag {set:?} {o:?}"), EncodedDag::Tsvdag(e)));
        }
    }
    for o in all_options() {
        let e = TsvdagEncoding::build_with_translations(dag, TransformSet::All, true, o).unwrap();
        out.push((format!("tsvdag S+A+T {o:?}"), EncodedDag::Tsvdag(e)));
    }
    out
}

fn voxels_from(n: u32, codes: Vec<u64>) -> Voxels {
    let mut codes = codes;
    codes.sort_unstable();
    codes.dedup();
    Voxels {
        resolution: n,
        codes,
        colors: Vec::new(),
    }
}

/// Checks every traversal of every encoding against the voxel set.
fn check_all(voxels: &Voxels, rays: usize) {
    let dag = Svdag::from_voxels(voxels).unwrap();
    let n = voxels.resolution;
    let digest = VoxelDigest::of_codes(&voxels.codes);
    let index = VoxelIndex::new(&dag);
    for (name, enc) in encodings(&dag) {
        let codes: Vec<u64> = enc.voxels().collect::<Result<_, _>>().unwrap();
        assert_eq!(codes, voxels.codes, "{name}: enumeration");
        assert_eq!(enc.digest().unwrap(), digest, "{name}: digest");
        // The content digest (`verify`) walks the stored nodes of every encoding, tsvdag
        // translations included, and hashes the same canonical DAG.
        assert_eq!(
            ContentDigest::of(&enc, &[]).unwrap(),
            ContentDigest::of_svdag(&dag, &[]).unwrap(),
            "{name}: content digest"
        );
        // Point lookups: every set voxel plus a deterministic sample of the grid.
        for &c in &voxels.codes {
            let [x, y, z] = morton::decode(c);
            assert!(enc.contains(x, y, z).unwrap(), "{name}: ({x},{y},{z}) set");
        }
        let total = (n as u64).pow(3);
        let step = (total / 4096).max(1);
        let mut c = 0;
        while c < total {
            let [x, y, z] = morton::decode(c);
            let expected = voxels.codes.binary_search(&c).is_ok();
            assert_eq!(
                enc.contains(x, y, z).unwrap(),
                expected,
                "{name}: ({x},{y},{z})"
            );
            c += step * 7 / 3 + 1;
        }
        assert!(!enc.contains(n, 0, 0).unwrap());
        // Ray casts agree exactly with the SVDAG's (t, voxel, normal).
        for i in 0..rays {
            let f = i as f32;
            let ray = Ray {
                origin: [
                    -3.0 + (f * 0.37) % 2.0,
                    n as f32 * ((f * 0.61) % 1.0),
                    n as f32 * ((f * 0.23) % 1.0) - 1.5,
                ],
                dir: [1.0, ((f * 0.13) % 1.0) - 0.5, ((f * 0.71) % 1.0) - 0.3],
            };
            let want = dag.raycast(&index, &ray, T_UNBOUNDED);
            let got = enc.raycast(&ray, T_UNBOUNDED).unwrap();
            assert_eq!(
                got.map(|h| (h.t, h.voxel, h.normal)),
                want.map(|h| (h.t, h.voxel, h.normal)),
                "{name}: ray {i}"
            );
        }
        // Payload round trip.
        let payload = enc.payload();
        match &enc {
            EncodedDag::Ssvdag(e) => {
                assert_eq!(payload.len() as u64, e.byte_size(), "{name}: size");
                assert_eq!(&SsvdagEncoding::from_payload(&payload, n).unwrap(), e);
            }
            EncodedDag::Tsvdag(e) => {
                assert_eq!(payload.len() as u64, e.byte_size(), "{name}: size");
                assert_eq!(&TsvdagEncoding::from_payload(&payload, n).unwrap(), e);
            }
            EncodedDag::Svdag32(_) => {}
        }
        // Decoding back to an SVDAG gives the same DAG.
        assert_eq!(enc.to_svdag(Vec::new()).unwrap(), dag, "{name}: to_svdag");
        // No mode changes the per-level element counts of the transform DAG.
        if let EncodedDag::Tsvdag(e) = &enc {
            let want = build_transform_dag(&dag, e.set, e.translations).level_counts();
            assert_eq!(e.node_counts().unwrap(), want, "{name}: node counts");
        }
    }
}

/// A scene with mirrored, rotated and repeated structure.
fn symmetric_scene(n: u32) -> Voxels {
    let mut codes = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let (a, b, c) = (x % 8, y % 8, z % 8);
                let inside = a * a + b * b + c * c < 20 && (x / 8 + y / 8 + z / 8) % 3 != 1;
                let wall = y == 3 && (x * 3 + z) % 5 < 2;
                if inside || wall {
                    codes.push(morton::encode(x, y, z));
                }
            }
        }
    }
    voxels_from(n, codes)
}

#[test]
fn structured_scenes_round_trip() {
    check_all(&symmetric_scene(16), 64);
    check_all(&symmetric_scene(32), 64);
    check_all(&voxels_from(8, vec![]), 4);
    check_all(&voxels_from(8, vec![0]), 4);
    check_all(&voxels_from(8, vec![511]), 4);
}

#[test]
fn transforms_shrink_symmetric_scenes() {
    let dag = Svdag::from_voxels(&symmetric_scene(64)).unwrap();
    let base = TsvdagOptions {
        lut: false,
        huffman: false,
    };
    let none = TsvdagEncoding::build(&dag, TransformSet::None, base).unwrap();
    let sa = TsvdagEncoding::build(&dag, TransformSet::All, base).unwrap();
    let leaves_none = none.leaves.len();
    assert!(
        sa.leaves.len() < leaves_none,
        "S+A must merge mirrored leaves"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    #[test]
    fn random_grids_round_trip(
        n in prop::sample::select(vec![8u32, 16, 32]),
        seeds in prop::collection::vec(any::<u64>(), 0..200),
        blocks in prop::collection::vec((0u32..32, 0u32..32, 0u32..32, 1u32..6), 0..6),
    ) {
        let total = (n as u64).pow(3);
        let mut codes: Vec<u64> = seeds.iter().map(|s| s % total).collect();
        for (x, y, z, s) in blocks {
            for dz in 0..s { for dy in 0..s { for dx in 0..s {
                let (x, y, z) = (x + dx, y + dy, z + dz);
                if x < n && y < n && z < n { codes.push(morton::encode(x, y, z)); }
            }}}
        }
        check_all(&voxels_from(n, codes), 8);
    }
}

/// Brute-force expansion of a graph pointer: `Shift_t(T(C))` as a set of local coordinates.
fn expand(g: &TransformGraph, level: usize, p: &GraphPointer) -> Vec<[u32; 3]> {
    let side = 4u32 << level;
    let mut inner: Vec<[u32; 3]> = Vec::new();
    let l = &g.levels[level];
    if level == 0 {
        let m = l.leaves[p.node as usize];
        for b in 0..64 {
            if (m >> b) & 1 == 1 {
                inner.push(morton::decode(b));
            }
        }
    } else {
        let half = side / 2;
        let mask = l.child_masks[p.node as usize];
        let mut k = 0;
        for o in 0..8u32 {
            if (mask >> o) & 1 == 1 {
                let c = l.node_children(p.node as usize)[k];
                k += 1;
                for v in expand(g, level - 1, &c) {
                    inner.push([
                        v[0] + (o & 1) * half,
                        v[1] + ((o >> 1) & 1) * half,
                        v[2] + (o >> 2) * half,
                    ]);
                }
            }
        }
    }
    let mut out = Vec::new();
    for v in inner {
        let w = p.transform.apply_point(v, side);
        let q: Vec<i64> = (0..3)
            .map(|a| w[a] as i64 + p.translation[a] as i64)
            .collect();
        if q.iter().all(|&c| c >= 0 && c < side as i64) {
            out.push([q[0] as u32, q[1] as u32, q[2] as u32]);
        }
    }
    out
}

/// A random 32^3 graph (levels 0..=3) with transforms and translations on levels 0..=2.
fn random_graph(seed: u64) -> TransformGraph {
    let mut s = seed | 1;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let mut levels = vec![GraphLevel {
        leaves: (0..6).map(|_| rnd() | 1).collect(),
        ..Default::default()
    }];
    for level in 1..=3usize {
        let below = levels[level - 1].len() as u64;
        let count = if level == 3 { 1 } else { 5 };
        let mut l = GraphLevel::default();
        for _ in 0..count {
            let mask = (rnd() as u8) | 1;
            l.child_starts.push(l.children.len() as u32);
            l.child_masks.push(mask);
            for _ in 0..mask.count_ones() {
                let side = 4i64 << (level - 1);
                let mut tr = [0i8; 3];
                if level - 1 <= 2 && rnd() % 3 == 0 {
                    for t in tr.iter_mut() {
                        if rnd() % 2 == 0 {
                            *t = ((rnd() % (2 * side as u64 - 1)) as i64 - (side - 1)) as i8;
                        }
                    }
                }
                l.children.push(GraphPointer {
                    node: (rnd() % below) as u32,
                    transform: Transform::from_index((rnd() % 48) as usize).unwrap(),
                    translation: tr,
                });
            }
        }
        levels.push(l);
    }
    TransformGraph {
        resolution: 32,
        set: TransformSet::All,
        translations: true,
        levels,
        root: Some(GraphPointer {
            node: 0,
            transform: Transform::from_index((seed % 48) as usize).unwrap(),
            translation: [0; 3],
        }),
    }
}

#[test]
fn translated_pointers_match_brute_force() {
    for seed in 1..40u64 {
        let g = random_graph(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let mut want: Vec<u64> = expand(&g, 3, &g.root.unwrap())
            .into_iter()
            .map(|[x, y, z]| morton::encode(x, y, z))
            .collect();
        want.sort_unstable();
        for o in all_options() {
            let e = TsvdagEncoding::encode(&g, o).unwrap();
            let got: Vec<u64> = VoxelIter::new(&e).collect::<Result<_, _>>().unwrap();
            assert_eq!(got, want, "seed {seed} {o:?}");
            for c in 0..(32u64 * 32 * 32) {
                let [x, y, z] = morton::decode(c);
                let expected = want.binary_search(&c).is_ok();
                assert_eq!(
                    e.contains(x, y, z).unwrap(),
                    expected,
                    "seed {seed} {o:?} lookup"
                );
                assert_eq!(contains(&e, x, y, z).unwrap(), expected);
            }
            let payload = e.to_payload();
            assert_eq!(TsvdagEncoding::from_payload(&payload, 32).unwrap(), e);
            // Ray casts agree with the SVDAG of the expanded voxel set.
            let dag = Svdag::from_voxels(&voxels_from(32, want.clone())).unwrap();
            let index = VoxelIndex::new(&dag);
            for i in 0..32 {
                let f = i as f32;
                let ray = Ray {
                    origin: [-2.0, 3.0 + f * 0.8, 30.0 - f * 0.5],
                    dir: [1.0, 0.1 * ((f * 0.7) % 1.0), -0.2 + 0.4 * ((f * 0.3) % 1.0)],
                };
                let want = dag
                    .raycast(&index, &ray, T_UNBOUNDED)
                    .map(|h| (h.t, h.voxel, h.normal));
                let got = raycast(&e, &ray, T_UNBOUNDED)
                    .unwrap()
                    .map(|h| (h.t, h.voxel, h.normal));
                assert_eq!(got, want, "seed {seed} ray {i}");
            }
        }
    }
}

/// Re-orienting keeps the voxels, the node counts per level and the set; the root becomes
/// plain.
#[test]
fn reorient_keeps_voxels_and_counts() {
    for seed in 1..40u64 {
        let g = random_graph(seed.wrapping_mul(0x2545_f491_4f6c_dd1d));
        let r = reorient(g.clone());
        let lens = |g: &TransformGraph| g.levels.iter().map(|l| l.len()).collect::<Vec<_>>();
        assert_eq!(lens(&r), lens(&g), "seed {seed}");
        assert_eq!(r.root.unwrap().transform, Transform::IDENTITY);
        let sorted = |g: &TransformGraph| {
            let mut v = expand(g, 3, &g.root.unwrap());
            v.sort_unstable();
            v
        };
        assert_eq!(sorted(&r), sorted(&g), "seed {seed}");
        assert!(r
            .levels
            .iter()
            .all(|l| l.children.iter().all(|c| r.set.contains(c.transform))));
    }
}

/// The base mode of a translated graph uses the compact translation codings, and a mutation of
/// the new header fields is refused with a clear error.
#[test]
fn compact_translation_fields_are_checked() {
    let base = TsvdagOptions {
        lut: false,
        huffman: false,
    };
    let mut checked = 0;
    for seed in 1..20u64 {
        let e = TsvdagEncoding::encode(&random_graph(seed), base).unwrap();
        assert!(e.compact_translations());
        assert!(e.translation_coding[3..]
            .iter()
            .all(|c| *c == TranslationCoding::Full));
        let p = e.to_payload();
        assert_eq!(TsvdagEncoding::from_payload(&p, 32).unwrap(), e);
        let flags = u32::from_le_bytes(p[4..8].try_into().unwrap());
        let word = u32::from_le_bytes(p[12..16].try_into().unwrap());
        let with = |flags: u32, word: u32| {
            let mut b = p.clone();
            b[4..8].copy_from_slice(&flags.to_le_bytes());
            b[12..16].copy_from_slice(&word.to_le_bytes());
            TsvdagEncoding::from_payload(&b, 32)
        };
        let reason = |r: Result<TsvdagEncoding, _>| match r {
            Err(voxdag::dag::encode::EncodeError::Corrupt { offset, reason }) => (offset, reason),
            other => panic!("seed {seed}: expected a corrupt-payload error, got {other:?}"),
        };
        // Flag bit 4 with Huffman, or without translations.
        let (at, why) = reason(with(flags | 4, word));
        assert!(at == 4 && why.contains("flag bit 4"), "{why}");
        let (at, why) = reason(with(flags & !8, word));
        assert!(at == 4 && why.contains("flag bit 4"), "{why}");
        // A level that cannot translate named in the coding word.
        for bit in [3, 7] {
            let (at, why) = reason(with(flags, word | 1 << bit));
            assert!(at == 12 && why.contains("cannot translate"), "{why}");
        }
        // Tagged-pointer bits without flag bit 5, or flag bit 5 without tables.
        let (at, why) = reason(with(flags, word | 1 << 8));
        assert!(at == 12 && why.contains("flag bit 5"), "{why}");
        let (at, why) = reason(with(flags | 32, word | 1 << 8));
        assert!(at == 4 && why.contains("flag bit 5"), "{why}");
        // A coding word without flag bit 4.
        if word != 0 {
            let (at, why) = reason(with(flags & !16, word));
            assert!(at == 12 && why.contains("flag bit 4"), "{why}");
        }
        // The other coding for a level: decodes differently or is refused, never panics.
        for l in 0..3 {
            if let Ok(other) = with(flags, word ^ 1 << l) {
                let _ = VoxelIter::new(&other).count();
                checked += 1;
            }
        }
    }
    assert!(
        checked < 19 * 3,
        "flipping the coding of a level was never refused"
    );
}

/// Tagged 16-bit pointers (flag bit 5): the table modes use them where cheaper; a tag bit for a
/// level that has no parent is refused, and flipping a level's tagging never panics.
#[test]
fn tagged_pointers_are_checked() {
    let dag = Svdag::from_voxels(&symmetric_scene(64)).unwrap();
    let mut tagged_seen = false;
    for o in [TsvdagOptions::MODES[1], TsvdagOptions::MODES[2]] {
        for translations in [false, true] {
            let e =
                TsvdagEncoding::build_with_translations(&dag, TransformSet::All, translations, o)
                    .unwrap();
            tagged_seen |= e.tagged.contains(&true);
            let p = e.to_payload();
            assert_eq!(TsvdagEncoding::from_payload(&p, 64).unwrap(), e);
            let flags = u32::from_le_bytes(p[4..8].try_into().unwrap());
            let word = u32::from_le_bytes(p[12..16].try_into().unwrap());
            let with = |flags: u32, word: u32| {
                let mut b = p.clone();
                b[4..8].copy_from_slice(&flags.to_le_bytes());
                b[12..16].copy_from_slice(&word.to_le_bytes());
                TsvdagEncoding::from_payload(&b, 64)
            };
            // Level 4 is the root level of a 64^3 grid: no pointer points at it.
            match with(flags | 32, word | 1 << (8 + 4)) {
                Err(voxdag::dag::encode::EncodeError::Corrupt { offset, reason }) => {
                    assert!(offset == 12 && reason.contains("no parent"), "{reason}")
                }
                other => panic!("expected an error, got {other:?}"),
            }
            for l in 0..4 {
                let w = word ^ 1 << (8 + l);
                let f = if w >> 8 == 0 { flags & !32 } else { flags | 32 };
                if let Ok(other) = with(f, w) {
                    let _ = VoxelIter::new(&other).count();
                }
            }
        }
    }
    assert!(tagged_seen, "no level chose tagged pointers");
}

#[test]
fn translations_refused_where_not_allowed() {
    let mut g = random_graph(7);
    g.translations = false;
    assert!(TsvdagEncoding::encode(&g, TsvdagOptions::default()).is_err());
}

#[test]
fn corrupt_payloads_are_errors() {
    let dag = Svdag::from_voxels(&symmetric_scene(16)).unwrap();
    let mut payloads: Vec<(bool, Vec<u8>)> =
        vec![(false, SsvdagEncoding::build(&dag).unwrap().to_payload())];
    for o in all_options() {
        payloads.push((
            true,
            TsvdagEncoding::build(&dag, TransformSet::All, o)
                .unwrap()
                .to_payload(),
        ));
    }
    payloads.push((
        true,
        TsvdagEncoding::encode(&random_graph(3), TsvdagOptions::default())
            .unwrap()
            .to_payload(),
    ));
    for (i, (ts, p)) in payloads.iter().enumerate() {
        let n = if i == payloads.len() - 1 { 32 } else { 16 };
        let parse = |b: &[u8]| -> bool {
            if *ts {
                TsvdagEncoding::from_payload(b, n)
                    .map(|e| VoxelIter::new(&e).all(|r| r.is_ok()))
                    .unwrap_or(false)
            } else {
                SsvdagEncoding::from_payload(b, n)
                    .map(|e| VoxelIter::new(&e).all(|r| r.is_ok()))
                    .unwrap_or(false)
            }
        };
        assert!(parse(p));
        for len in 0..p.len() {
            assert!(!parse(&p[..len]), "payload {i} truncated to {len} parsed");
        }
        // Byte flips: any outcome but a panic or a hang.
        for at in 0..p.len() {
            for bit in [0u8, 3, 7] {
                let mut b = p.clone();
                b[at] ^= 1 << bit;
                let _ = parse(&b);
            }
        }
    }
}

/// Every shared mesh at a small resolution: every encoding enumerates exactly its voxels.
#[test]
fn shared_meshes_round_trip() {
    let Some(data) = common::shared_data() else {
        return;
    };
    for mesh in [
        "bunny.obj",
        "dragon.obj",
        "buddha.obj",
        "horse.obj",
        "teapot.obj",
        "sponza-dabrovic.obj",
    ] {
        let dag = common::build_scene(&data.join("meshes").join(mesh), Some(64));
        let mut codes = Vec::new();
        dag.for_each_voxel(|c| codes.push(c));
        let digest = VoxelDigest::of_codes(&codes);
        for (name, enc) in encodings(&dag) {
            assert_eq!(enc.digest().unwrap(), digest, "{mesh} {name}");
            let back = enc.to_svdag(Vec::new()).unwrap();
            assert_eq!(back.words, dag.words, "{mesh} {name}");
        }
    }
}

/// Every shared mesh with S+A+T in every mode at 256^3 (more with
/// `VOXDAG_TEST_SAT_RESOLUTIONS=256,512,1024`): the decoded voxels equal the input and the node
/// counts equal the transform DAG's.
#[test]
fn shared_meshes_sat_every_mode() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let resolutions: Vec<u32> = std::env::var("VOXDAG_TEST_SAT_RESOLUTIONS")
        .unwrap_or_else(|_| "256".into())
        .split(',')
        .map(|r| r.trim().parse().expect("resolution list"))
        .collect();
    for &n in &resolutions {
        for mesh in [
            "bunny.obj",
            "dragon.obj",
            "buddha.obj",
            "horse.obj",
            "teapot.obj",
            "sponza-dabrovic.obj",
            "sponza-crytek/sponza_crytek_noleaf.obj",
        ] {
            let dag = common::build_scene(&data.join("meshes").join(mesh), Some(n));
            let mut codes = Vec::new();
            dag.for_each_voxel(|c| codes.push(c));
            let tdag = build_transform_dag(&dag, TransformSet::All, true);
            let counts = tdag.level_counts();
            let graph = TransformGraph::from_transform_dag(tdag);
            for o in all_options() {
                let e = TsvdagEncoding::encode(&graph, o).unwrap();
                let name = format!("{mesh} {n} {}", o.mode_name());
                assert_eq!(e.node_counts().unwrap(), counts, "{name}");
                let back = TsvdagEncoding::from_payload(&e.to_payload(), n).unwrap();
                let got: Vec<u64> = VoxelIter::new(&back).collect::<Result<_, _>>().unwrap();
                assert!(got == codes, "{name}: decoded voxels differ");
            }
        }
    }
}

/// `voxdag build --encoding ..` then `voxdag verify`: ok for good files, an error (exit 1, no
/// panic) for corrupt ones, and the first differing voxel with `--against`.
#[test]
fn cli_build_and_verify() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bunny = data.join("meshes/bunny.obj");
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let mut files = Vec::new();
    for (enc, extra) in [
        ("svdag32", vec![]),
        ("ssvdag", vec![]),
        ("tsvdag", vec![]),
        ("tsvdag", vec!["--transforms", "s", "--no-lut"]),
        ("tsvdag", vec!["--transforms", "a", "--no-huffman"]),
        (
            "tsvdag",
            vec!["--transforms", "none", "--no-lut", "--no-huffman"],
        ),
    ] {
        let out = path(&format!("b-{enc}-{}.vdag", files.len()));
        let mut args = vec![
            "-q",
            "build",
            bunny.to_str().unwrap(),
            "-r",
            "64",
            "--encoding",
            enc,
            "-o",
            &out,
        ];
        args.extend(extra);
        let o = common::voxdag_cli(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = common::voxdag_cli(&["verify", &out, "--against", &path("b-svdag32-0.vdag")]);
        let stdout = String::from_utf8_lossy(&v.stdout);
        assert!(
            v.status.success() && stdout.starts_with("ok"),
            "{stdout} {}",
            String::from_utf8_lossy(&v.stderr)
        );
        files.push(out);
    }
    // stats --json carries the encoded sizes.
    let s = common::voxdag_cli(&["stats", "--json", &files[2]]);
    assert!(s.status.success());
    let json: serde_json::Value = serde_json::from_slice(&s.stdout).unwrap();
    for key in ["svdag32", "ssvdag", "tsvdag", "tsvdag_base", "tsvdag_lut"] {
        assert!(json["bytes"][key].as_u64().unwrap() > 0, "{key}");
    }
    // A different scene: the first differing voxel is named.
    let teapot = path("teapot.vdag");
    let teapot_obj = data.join("meshes/teapot.obj");
    assert!(common::voxdag_cli(&[
        "-q",
        "build",
        teapot_obj.to_str().unwrap(),
        "-r",
        "64",
        "-o",
        &teapot
    ])
    .status
    .success());
    let v = common::voxdag_cli(&["verify", &files[2], "--against", &teapot]);
    assert!(!v.status.success());
    assert!(String::from_utf8_lossy(&v.stderr).contains("first differing voxel ("));
    // Corrupt payloads (CRC fixed so the payload checks are reached): errors, never panics.
    for file in &files[1..3] {
        let good = std::fs::read(file).unwrap();
        let payload_at =
            u64::from_le_bytes(good[64 + 2 * 24 + 8..64 + 2 * 24 + 16].try_into().unwrap())
                as usize;
        let mut failures = 0;
        for (i, at) in (payload_at..good.len() - 4).step_by(7).enumerate().take(60) {
            let mut b = good.clone();
            b[at] ^= 1 << (i % 8);
            let len = b.len();
            let crc = crc32fast::hash(&b[..len - 4]);
            b[len - 4..].copy_from_slice(&crc.to_le_bytes());
            let bad = path("bad.vdag");
            std::fs::write(&bad, &b).unwrap();
            let v = common::voxdag_cli(&["verify", &bad]);
            let stderr = String::from_utf8_lossy(&v.stderr);
            assert!(!stderr.contains("panicked"), "{stderr}");
            if !v.status.success() {
                failures += 1;
                assert!(stderr.starts_with("error: "), "{stderr}");
            }
        }
        assert!(
            failures > 40,
            "{file}: only {failures} of 60 flips detected"
        );
    }
}
