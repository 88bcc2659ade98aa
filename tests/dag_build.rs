//! SVDAG construction, statistics and queries against naive references computed from the voxel
//! set itself (no DAG code involved in the expected values).

use std::collections::{BTreeMap, HashSet};

mod common;

use proptest::prelude::*;
use voxdag::dag::{DagError, Svdag};
use voxdag::scene::{load_vox, morton, ImportOptions, Voxels};

/// A voxel set from coordinates (duplicates removed); colours derived from the code when asked.
fn voxels(n: u32, coords: &[(u32, u32, u32)], colored: bool) -> Voxels {
    let mut codes: Vec<u64> = coords
        .iter()
        .map(|&(x, y, z)| morton::encode(x, y, z))
        .collect();
    codes.sort_unstable();
    codes.dedup();
    let colors = if colored {
        codes
            .iter()
            .map(|&c| (c as u32).wrapping_mul(2_654_435_761) | 0xff00_0000)
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

/// Levels of a grid of side n: log2(n) - 1.
fn level_count(n: u32) -> u32 {
    n.trailing_zeros() - 1
}

/// Distinct `code >> (6 + 3l)` per level: the SVO node count.
fn naive_svo(v: &Voxels) -> Vec<u64> {
    (0..level_count(v.resolution))
        .map(|l| {
            let mut prefixes: Vec<u64> = v.codes.iter().map(|c| c >> (6 + 3 * l)).collect();
            prefixes.dedup();
            prefixes.len() as u64
        })
        .collect()
}

/// Distinct subtrees per level: each node's voxel set relative to its corner, deduplicated.
fn naive_svdag(v: &Voxels) -> Vec<u64> {
    (0..level_count(v.resolution))
        .map(|l| {
            let shift = 6 + 3 * l;
            let mut subtrees: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
            for &c in &v.codes {
                subtrees
                    .entry(c >> shift)
                    .or_default()
                    .push(c & ((1u64 << shift) - 1));
            }
            subtrees.into_values().collect::<HashSet<_>>().len() as u64
        })
        .collect()
}

/// Checks everything the DAG reports against the naive references.
fn check(v: &Voxels, full_grid: bool) {
    let dag = Svdag::from_voxels(v).expect("valid input");
    dag.validate().expect("built DAG is valid");
    assert_eq!(dag.words.len() as u64 * 4, dag.bytes_svdag32());
    assert_eq!(&dag.to_voxels(), v, "to_voxels round trip");
    assert_eq!(dag.voxel_count(), v.len() as u64);

    let stats = dag.level_stats();
    let svo: Vec<u64> = stats.iter().map(|s| s.svo).collect();
    let svdag: Vec<u64> = stats.iter().map(|s| s.svdag).collect();
    let levels: Vec<u32> = stats.iter().map(|s| s.level).collect();
    assert_eq!(levels, (0..level_count(v.resolution)).collect::<Vec<_>>());
    assert_eq!(svo, naive_svo(v), "svo node counts");
    assert_eq!(svdag, naive_svdag(v), "svdag node counts");
    // Unshared node bytes: 8 per leaf, 4 per inner node plus 4 per child (= node below).
    let want_bytes = 8 * svo[0]
        + (1..svo.len())
            .map(|l| 4 * svo[l] + 4 * svo[l - 1])
            .sum::<u64>();
    assert_eq!(dag.bytes_svo(), want_bytes);
    let all = dag.stats();
    assert_eq!(all.levels, stats);
    assert_eq!(all.voxels, v.len() as u64);
    assert_eq!(all.bytes.svo, want_bytes);

    let index = dag.voxel_index();
    for (i, &code) in v.codes.iter().enumerate() {
        let [x, y, z] = morton::decode(code);
        assert!(dag.contains(x, y, z));
        assert_eq!(index.color_index(&dag, x, y, z), Some(i as u64));
    }
    let set: HashSet<u64> = v.codes.iter().copied().collect();
    let n = v.resolution;
    if full_grid {
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let want = set.contains(&morton::encode(x, y, z));
                    assert_eq!(dag.contains(x, y, z), want, "contains({x}, {y}, {z})");
                    if !want {
                        assert_eq!(index.color_index(&dag, x, y, z), None);
                    }
                }
            }
        }
    }
    for (x, y, z) in [(n, 0, 0), (0, n, 0), (0, 0, n), (u32::MAX, 0, 0)] {
        assert!(!dag.contains(x, y, z));
        assert_eq!(index.color_index(&dag, x, y, z), None);
    }
    if let Some(&code) = v.codes.last() {
        let [x, y, z] = morton::decode(code);
        assert_eq!(dag.color_index(x, y, z), Some(v.len() as u64 - 1));
    }
    check_bounds(&dag, v);
}

/// `occupied_bounds` is the exact bounding box rounded outward to cells of max(4, N/64) voxels.
fn check_bounds(dag: &Svdag, v: &Voxels) {
    let cell = (v.resolution / 64).max(4);
    let Some((min, max)) = dag.occupied_bounds() else {
        assert!(v.is_empty(), "bounds missing for a non-empty scene");
        return;
    };
    let mut exact_min = [u32::MAX; 3];
    let mut exact_max = [0u32; 3];
    for &code in &v.codes {
        let p = morton::decode(code);
        for a in 0..3 {
            exact_min[a] = exact_min[a].min(p[a]);
            exact_max[a] = exact_max[a].max(p[a] + 1);
        }
    }
    for a in 0..3 {
        assert_eq!(min[a], exact_min[a] / cell * cell, "min axis {a}");
        assert_eq!(max[a], exact_max[a].div_ceil(cell) * cell, "max axis {a}");
    }
}

/// All cells of an n^3 grid for which `f` holds.
fn grid(n: u32, f: impl Fn(u32, u32, u32) -> bool) -> Vec<(u32, u32, u32)> {
    let mut out = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                if f(x, y, z) {
                    out.push((x, y, z));
                }
            }
        }
    }
    out
}

#[test]
fn structured_scenes() {
    check(&voxels(16, &grid(16, |_, _, _| true), true), true);
    check(
        &voxels(32, &grid(32, |x, y, z| (x + y + z) % 2 == 0), false),
        true,
    );
    let shell = |x: u32, y: u32, z: u32| {
        let d = |a: u32| (a as i64 * 2 - 31).pow(2);
        let r2 = d(x) + d(y) + d(z);
        (26 * 26..=30 * 30).contains(&r2)
    };
    check(&voxels(32, &grid(32, shell), true), true);
    check(
        &voxels(
            64,
            &grid(64, |x, y, z| x < 40 && y == 7 && z % 3 == 0),
            true,
        ),
        false,
    );
    for n in [8, 64] {
        check(&voxels(n, &[], false), n <= 32);
        for corner in 0..8 {
            let c = |bit: u32| if corner >> bit & 1 == 1 { n - 1 } else { 0 };
            check(&voxels(n, &[(c(0), c(1), c(2))], true), n <= 32);
        }
    }
}

#[test]
fn empty_scene_layout() {
    let dag = Svdag::from_voxels(&voxels(64, &[], false)).unwrap();
    assert_eq!(dag.words, vec![0]);
    assert_eq!(dag.level_starts.len(), 5);
    assert!(dag.level_stats().iter().all(|s| s.svo == 0 && s.svdag == 0));
    assert_eq!(dag.to_voxels().codes, Vec::<u64>::new());
}

#[test]
fn stats_json_shape() {
    let dag = Svdag::from_voxels(&voxels(8, &[(0, 0, 0), (7, 7, 7)], false)).unwrap();
    let json = serde_json::to_string(&dag.stats()).unwrap();
    let words = dag.words.len() * 4;
    assert_eq!(
        json,
        format!(
            "{{\"resolution\":8,\"voxels\":2,\"bytes\":{{\"svo\":28,\"svdag32\":{words}}},\
             \"levels\":[{{\"level\":0,\"svo\":2,\"svdag\":2}},{{\"level\":1,\"svo\":1,\"svdag\":1}}]}}"
        )
    );
    // bytes_svo: 2 leaves * 8 + root (4 + 2 * 4).
    assert_eq!(dag.bytes_svo(), 28);
}

#[test]
fn builder_rejects_bad_input() {
    let bad_res = Voxels {
        resolution: 12,
        ..Default::default()
    };
    assert!(matches!(
        Svdag::from_voxels(&bad_res),
        Err(DagError::InvalidResolution(12))
    ));
    let too_small = Voxels {
        resolution: 4,
        ..Default::default()
    };
    assert!(matches!(
        Svdag::from_voxels(&too_small),
        Err(DagError::InvalidResolution(4))
    ));
    let unsorted = Voxels {
        resolution: 8,
        codes: vec![5, 3],
        colors: vec![],
    };
    assert!(matches!(
        Svdag::from_voxels(&unsorted),
        Err(DagError::InvalidVoxels(_))
    ));
    let duplicate = Voxels {
        resolution: 8,
        codes: vec![3, 3],
        colors: vec![],
    };
    assert!(matches!(
        Svdag::from_voxels(&duplicate),
        Err(DagError::InvalidVoxels(_))
    ));
    let outside = Voxels {
        resolution: 8,
        codes: vec![512],
        colors: vec![],
    };
    assert!(matches!(
        Svdag::from_voxels(&outside),
        Err(DagError::InvalidVoxels(_))
    ));
    let colors = Voxels {
        resolution: 8,
        codes: vec![1, 2],
        colors: vec![7],
    };
    assert!(matches!(
        Svdag::from_voxels(&colors),
        Err(DagError::InvalidVoxels(_))
    ));
}

#[test]
fn large_sparse_scene_matches_reference() {
    // Enough voxels that the builder splits its input into several parallel chunks.
    let n = 256;
    let coords = grid(n, |x, y, z| {
        (x * 7 + y * 13 + z * 29) % 11 == 0 && (x ^ y) & 4 == 0
    });
    assert!(coords.len() > 1 << 17);
    check(&voxels(n, &coords, true), false);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn random_sets_match_reference(
        exp in 3u32..=6,
        raw in prop::collection::vec((0u32..64, 0u32..64, 0u32..64), 0..400),
        box_side in 1u32..=64,
        colored in any::<bool>(),
    ) {
        let n = 1u32 << exp;
        // Squeeze the voxels into a box of random size so that dense and sparse sets both occur.
        let side = box_side.min(n);
        let coords: Vec<_> = raw.iter().map(|&(x, y, z)| (x % side, y % side, z % side)).collect();
        check(&voxels(n, &coords, colored), n <= 16);
    }
}

#[test]
fn real_vox_models_match_reference() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let models = data.join("vox/voxel-model");
    for file in [
        "procedure/menger.vox",
        "scan/teapot.vox",
        "scan/dragon.vox",
        "monument/monu1.vox",
    ] {
        let v = load_vox(&models.join(file), &ImportOptions::default()).unwrap();
        assert!(!v.is_empty(), "{file}");
        check(&v, false);
    }
}
