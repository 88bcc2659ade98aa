//! Translations (§3.3.2): the S+A+T transform DAG decodes to exactly its input, its translation
//! search finds exactly the parents a brute-force search finds, translated copies collapse, and
//! `sat <= sa`.

mod common;

use std::collections::{BTreeSet, HashMap};

use proptest::prelude::*;
use voxdag::dag::translate::{apply_to_vector, MAX_TRANSLATION_LEVEL};
use voxdag::dag::{
    build_transform_dag, symmetry_counts, CanonicalDag, Svdag, Transform, TransformDag,
    TransformSet,
};
use voxdag::scene::{morton, Voxels};

type P = [i32; 3];

fn voxels(n: u32, coords: impl IntoIterator<Item = [u32; 3]>) -> Voxels {
    Voxels::from_coords(n, coords)
}

/// Independent point action of transform `t` (ids: 8 * permutation + mirror mask).
fn apply(t: Transform, p: P, n: i32) -> P {
    let perm = t.permutation();
    std::array::from_fn(|i| {
        let v = p[perm[i] as usize];
        if (t.mirror() >> i) & 1 == 1 {
            n - 1 - v
        } else {
            v
        }
    })
}

/// Voxels of canonical node `node` at level `l`, as local coordinates (brute force).
fn materialize(c: &CanonicalDag, l: usize, node: u32) -> BTreeSet<P> {
    let level = &c.levels[l];
    let mut out = BTreeSet::new();
    if l == 0 {
        let m = level.leaves[node as usize];
        for bit in 0..64 {
            if (m >> bit) & 1 == 1 {
                let [x, y, z] = morton::decode(bit);
                out.insert([x as i32, y as i32, z as i32]);
            }
        }
        return out;
    }
    let half = 2i32 << l;
    let mask = level.child_masks[node as usize];
    let mut k = 0;
    for o in 0..8 {
        if (mask >> o) & 1 == 1 {
            let ch = level.node_children(node as usize)[k];
            k += 1;
            let base = [o & 1, (o >> 1) & 1, o >> 2].map(|b| b * half);
            for p in materialize(c, l - 1, ch.node) {
                let q = apply(ch.transform, p, half);
                out.insert([q[0] + base[0], q[1] + base[1], q[2] + base[2]]);
            }
        }
    }
    out
}

/// `Tr_t(T(x))` with destructive clipping to the cube of side `n`.
fn moved(x: &BTreeSet<P>, t: Transform, tr: P, n: i32) -> BTreeSet<P> {
    x.iter()
        .map(|&p| {
            let q = apply(t, p, n);
            [q[0] + tr[0], q[1] + tr[1], q[2] + tr[2]]
        })
        .filter(|q| q.iter().all(|&v| (0..n).contains(&v)))
        .collect()
}

/// Preference of a parent candidate, larger is better (the documented order).
fn preference(rank: usize, t: Transform, tr: P) -> (usize, i32, i32, u32) {
    let l1 = tr.iter().map(|v| v.abs()).sum::<i32>();
    let enc = tr
        .iter()
        .enumerate()
        .fold(0u32, |a, (i, &v)| a | (((v + 16) as u32) << (5 * i)));
    (rank, -l1, -(t.index() as i32), enc)
}

/// Brute-force S+A+T stored counts: the same top-down, single-parent rules as the library, with
/// an exhaustive parent search (every transform, every translation that maps some voxel of the
/// transformed candidate onto the first voxel of the item).
fn reference_counts(c: &CanonicalDag) -> Vec<u64> {
    let nlev = c.levels.len();
    let Some(root) = c.root() else {
        return vec![0; nlev];
    };
    let set = c.set.transforms();
    let mut counts = vec![0u64; nlev];
    let mut stored: Vec<u32> = Vec::new();
    for l in (0..nlev).rev() {
        if l > MAX_TRANSLATION_LEVEL as usize {
            counts[l] = c.levels[l].len() as u64;
            stored = (0..c.levels[l].len() as u32).collect();
            continue;
        }
        let items: Vec<u32> = if l + 1 == nlev {
            vec![root.node]
        } else {
            let set: BTreeSet<u32> = stored
                .iter()
                .flat_map(|&s| {
                    c.levels[l + 1]
                        .node_children(s as usize)
                        .iter()
                        .map(|p| p.node)
                })
                .collect();
            set.into_iter().collect()
        };
        let n = 4i32 << l;
        let grids: Vec<BTreeSet<P>> = items.iter().map(|&i| materialize(c, l, i)).collect();
        // Rank: voxel count ascending, ties by descending canonical id.
        let mut order: Vec<usize> = (0..items.len()).collect();
        order.sort_by_key(|&i| (grids[i].len(), std::cmp::Reverse(items[i])));
        let mut rank = vec![0; items.len()];
        for (r, &i) in order.iter().enumerate() {
            rank[i] = r;
        }
        let mut parent = vec![0usize; items.len()];
        for b in 0..items.len() {
            let first = *grids[b].iter().next().expect("non-empty");
            let mut best = (preference(rank[b], Transform::IDENTITY, [0; 3]), b);
            for a in 0..items.len() {
                if a == b || rank[a] < rank[b] || grids[a].len() < grids[b].len() {
                    continue;
                }
                for &t in set {
                    let x: Vec<P> = grids[a].iter().map(|&p| apply(t, p, n)).collect();
                    let xs: BTreeSet<P> = x.iter().copied().collect();
                    for v in &x {
                        let tr = [first[0] - v[0], first[1] - v[1], first[2] - v[2]];
                        let key = (preference(rank[a], t, tr), a);
                        if key <= best {
                            continue;
                        }
                        if moved(&xs, Transform::IDENTITY, tr, n) == grids[b] {
                            best = key;
                        }
                    }
                }
            }
            parent[b] = best.1;
        }
        let parents: BTreeSet<usize> = parent.iter().copied().collect();
        counts[l] = parents.len() as u64;
        stored = parents.into_iter().map(|i| items[i]).collect();
    }
    counts
}

/// Every claimed pointer is exact: the DAG decodes (both decoders) to the input voxels.
fn check_decodes(t: &TransformDag, v: &Voxels) {
    assert_eq!(
        t.to_voxels().codes,
        v.codes,
        "to_voxels differs from the input"
    );
    let set: BTreeSet<u64> = v.codes.iter().copied().collect();
    let n = v.resolution;
    if n <= 32 {
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let want = set.contains(&morton::encode(x, y, z));
                    assert_eq!(t.contains(x, y, z), want, "voxel ({x}, {y}, {z})");
                }
            }
        }
    } else {
        for &code in &v.codes {
            let [x, y, z] = morton::decode(code);
            assert!(t.contains(x, y, z), "voxel ({x}, {y}, {z}) missing");
        }
    }
}

/// All checks on one scene: decoding, brute-force counts, `sat <= sa`, determinism.
fn check_scene(v: &Voxels) -> Vec<u64> {
    let dag = Svdag::from_voxels(v).expect("build");
    let t = build_transform_dag(&dag, TransformSet::All, true);
    check_decodes(&t, v);
    let c = CanonicalDag::build(&dag, TransformSet::All);
    let sat = t.level_counts();
    assert_eq!(
        sat,
        reference_counts(&c),
        "S+A+T counts differ from brute force"
    );
    for (l, (&s, &a)) in sat.iter().zip(&c.level_counts()).enumerate() {
        assert!(s <= a, "level {l}: sat {s} > sa {a}");
    }
    assert_eq!(
        build_transform_dag(&dag, TransformSet::All, true),
        t,
        "not deterministic"
    );
    let plain = build_transform_dag(&dag, TransformSet::All, false);
    assert_eq!(plain.level_counts(), c.level_counts());
    assert_eq!(plain.translated_pointers(), 0);
    check_decodes(&plain, v);
    sat
}

fn random_points(n: u32, seed: &[(u32, u32, u32)]) -> Vec<[u32; 3]> {
    seed.iter()
        .map(|&(x, y, z)| [x % n, y % n, z % n])
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Random sparse scenes, and random small blobs stamped at random offsets (many translated
    /// copies): decoding is exact and the counts equal brute force.
    #[test]
    fn random_scenes_match_brute_force(
        n_log in 3u32..=5,
        seed in prop::collection::vec((0u32..32, 0u32..32, 0u32..32), 1..60),
        blob in prop::collection::vec((0u32..4, 0u32..4, 0u32..4), 1..8),
        offsets in prop::collection::vec((0u32..32, 0u32..32, 0u32..32), 0..12),
    ) {
        let n = 1u32 << n_log;
        let mut pts = random_points(n, &seed);
        for &(ox, oy, oz) in &offsets {
            for &(x, y, z) in &blob {
                pts.push([(ox + x) % n, (oy + y) % n, (oz + z) % n]);
            }
        }
        check_scene(&voxels(n, pts));
    }

    /// Other transform sets with translations decode exactly.
    #[test]
    fn other_sets_decode(
        seed in prop::collection::vec((0u32..16, 0u32..16, 0u32..16), 1..80),
        set in 0usize..4,
    ) {
        let v = voxels(16, random_points(16, &seed));
        let set = [TransformSet::None, TransformSet::Mirrors, TransformSet::AxisPermutations, TransformSet::All][set];
        let dag = Svdag::from_voxels(&v).expect("build");
        let t = build_transform_dag(&dag, set, true);
        check_decodes(&t, &v);
        for level in &t.levels {
            for p in &level.children {
                prop_assert!(set.contains(p.transform));
            }
        }
    }
}

/// An asymmetric blob and copies shifted inside 16^3 nodes (room to shift): one stored 16^3
/// node, the others translations of it (also when the copies are rotated and mirrored).
#[test]
fn translated_copies_collapse() {
    let blob: Vec<[u32; 3]> = vec![
        [0, 0, 0],
        [1, 0, 0],
        [2, 0, 0],
        [0, 1, 0],
        [0, 2, 1],
        [3, 3, 2],
        [5, 1, 3],
        [5, 2, 3],
        [6, 6, 6],
        [2, 5, 7],
    ];
    let shifts = [
        [1, 2, 3],
        [2, 2, 3],
        [1, 4, 4],
        [3, 2, 3],
        [1, 2, 5],
        [4, 5, 6],
        [8, 7, 7],
        [2, 8, 1],
    ];
    for transformed in [false, true] {
        let mut pts = Vec::new();
        for (k, s) in shifts.iter().enumerate() {
            // Copy k lives in the 16^3 node at (k & 1, (k >> 1) & 1, k >> 2) of a 32^3 scene.
            let node = [k as u32 & 1, (k as u32 >> 1) & 1, k as u32 >> 2].map(|b| b * 16);
            let t = if transformed {
                Transform::from_index(k * 5 % 48).expect("id")
            } else {
                Transform::IDENTITY
            };
            for &p in &blob {
                let q = [p[0] + s[0], p[1] + s[1], p[2] + s[2]];
                let q = t.apply_point(q, 16);
                pts.push([q[0] + node[0], q[1] + node[1], q[2] + node[2]]);
            }
        }
        let v = voxels(32, pts);
        let dag = Svdag::from_voxels(&v).expect("build");
        let counts = symmetry_counts(&dag);
        assert_eq!(
            counts[2].sa,
            shifts.len() as u64,
            "the copies differ up to S+A"
        );
        assert_eq!(counts[2].sat, 1, "all copies collapse to one 16^3 node");
        let sat = check_scene(&v);
        assert_eq!(sat[2], 1);
        let t = build_transform_dag(&dag, TransformSet::All, true);
        let root = t.levels.last().expect("root level");
        let translated = root.children.iter().filter(|p| p.has_translation()).count();
        assert_eq!(translated, shifts.len() - 1);
        // Without translations every copy is stored.
        let plain = build_transform_dag(&dag, TransformSet::All, false);
        assert_eq!(plain.level_counts()[2], shifts.len() as u64);
    }
}

/// A destructive translation (a slab pushed out of the cube) and a chain `C -> B -> A`:
/// `B` is `A` shifted by -1 in x (its x = 0 slab drops), `C` is `B` shifted by +5 (lossless) but
/// no translation of `A`. `B` must stay stored for `C` although `A` could produce it.
#[test]
fn destructive_translation_and_chains() {
    let block = |x0: u32, w: u32, node: [u32; 3], pts: &mut Vec<[u32; 3]>| {
        for x in x0..x0 + w {
            for y in 0..4 {
                for z in 0..4 {
                    pts.push([x + node[0], y + node[1], z + node[2]]);
                }
            }
        }
    };
    let mut pts = Vec::new();
    block(0, 3, [0, 0, 0], &mut pts); // A: x = 0..3 (48 voxels)
    block(0, 2, [8, 0, 0], &mut pts); // B: x = 0..2 (32 voxels)
    block(5, 2, [0, 8, 0], &mut pts); // C: x = 5..7 (32 voxels)
    let v = voxels(16, pts);
    let sat = check_scene(&v);
    let dag = Svdag::from_voxels(&v).expect("build");
    let sa = CanonicalDag::build(&dag, TransformSet::All).level_counts();
    assert_eq!(sa[1], 3);
    assert_eq!(
        sat[1], 2,
        "one of B, C is a translation; the other is kept for the chain"
    );
    let t = build_transform_dag(&dag, TransformSet::All, true);
    let translated = t.levels[2]
        .children
        .iter()
        .filter(|p| p.has_translation())
        .count();
    assert_eq!(translated, 1, "{:?}", t.levels[2].children);
}

#[test]
fn vector_action_matches_point_action() {
    for t in Transform::all() {
        for v in [[1i8, 0, 0], [0, 2, -1], [-3, 5, 7]] {
            let n = 16;
            let p = [4u32, 5, 6];
            let q = [
                p[0] as i32 + v[0] as i32,
                p[1] as i32 + v[1] as i32,
                p[2] as i32 + v[2] as i32,
            ];
            let tp = t.apply_point(p, n);
            let tq = t.apply_point(q.map(|c| c as u32), n);
            let lv = apply_to_vector(t, v);
            for i in 0..3 {
                assert_eq!(tq[i] as i32 - tp[i] as i32, lv[i] as i32, "{t:?} {v:?}");
            }
        }
    }
}

#[test]
fn empty_and_single_voxel() {
    let empty = voxels(16, []);
    let dag = Svdag::from_voxels(&empty).expect("build");
    let t = build_transform_dag(&dag, TransformSet::All, true);
    assert!(t.root.is_none());
    assert_eq!(t.level_counts(), vec![0, 0, 0]);
    assert!(t.to_voxels().codes.is_empty());
    for res in [8, 16, 64] {
        let v = voxels(res, [[res - 1, 0, res / 2]]);
        assert_eq!(
            check_scene(&v),
            vec![1; (res.trailing_zeros() - 1) as usize]
        );
    }
}

/// Real meshes: decoding is exact, `sat <= sa`, and the small ones equal brute force.
#[test]
fn shared_meshes() {
    let Some(data) = common::shared_data() else {
        return;
    };
    for (mesh, res, brute) in [
        ("teapot.obj", 32, true),
        ("bunny.obj", 64, false),
        ("dragon.obj", 128, false),
    ] {
        let dag = common::build_scene(&data.join("meshes").join(mesh), Some(res));
        let v = dag.to_voxels();
        if brute {
            check_scene(&v);
            continue;
        }
        let t = build_transform_dag(&dag, TransformSet::All, true);
        check_decodes(&t, &v);
        let sa = CanonicalDag::build(&dag, TransformSet::All).level_counts();
        let sat = t.level_counts();
        println!("{mesh} {res}: sa {sa:?} sat {sat:?}");
        for l in 0..sa.len() {
            assert!(sat[l] <= sa[l]);
        }
        assert!(
            sat.iter().sum::<u64>() < sa.iter().sum::<u64>(),
            "translations found nothing"
        );
    }
}

/// The faster search (deduplicated table keys, per-item bounding boxes, gap filter) never stores
/// more elements per level than the search it replaced, whose counts are recorded here, and its
/// pointers decode exactly.
#[test]
fn shared_meshes_not_worse_than_previous_search() {
    let Some(data) = common::shared_data() else {
        return;
    };
    // `TransformDag::level_counts` of the previous search (commit 77c92bd) at 256^3.
    let previous: [(&str, [u64; 7]); 3] = [
        ("bunny.obj", [1694, 2516, 738, 195, 42, 8, 1]),
        ("dragon.obj", [2488, 1899, 522, 129, 29, 8, 1]),
        ("buddha.obj", [2369, 1418, 387, 87, 16, 8, 1]),
    ];
    for (mesh, before) in previous {
        let dag = common::build_scene(&data.join("meshes").join(mesh), Some(256));
        let t = build_transform_dag(&dag, TransformSet::All, true);
        check_decodes(&t, &dag.to_voxels());
        let sat = t.level_counts();
        println!("{mesh} 256: sat {sat:?}, previous search {before:?}");
        assert_eq!(sat.len(), before.len());
        for (l, (&now, &was)) in sat.iter().zip(&before).enumerate() {
            assert!(
                now <= was,
                "{mesh} level {l}: {now} elements, previously {was}"
            );
        }
    }
}

/// The counts reported by `symmetry_counts` and `stats --json` include `sat`.
#[test]
fn stats_report_sat() {
    let v = voxels(32, (0..20).map(|i| [i, (i * 7) % 32, (i * 3) % 32]));
    let dag = Svdag::from_voxels(&v).expect("build");
    let counts = symmetry_counts(&dag);
    let t = build_transform_dag(&dag, TransformSet::All, true);
    let stats = serde_json::to_value(dag.stats_with_symmetry()).expect("json");
    let by_level: HashMap<u64, u64> = stats["levels"]
        .as_array()
        .expect("levels")
        .iter()
        .map(|l| {
            (
                l["level"].as_u64().expect("level"),
                l["sat"].as_u64().expect("sat"),
            )
        })
        .collect();
    for (l, c) in counts.iter().enumerate() {
        assert_eq!(c.sat, t.level_counts()[l]);
        assert_eq!(by_level[&(l as u64)], c.sat);
        assert!(c.sat <= c.sa);
    }
    let plain = serde_json::to_value(dag.stats()).expect("json");
    assert!(plain["levels"][0].get("sat").is_none());
}
