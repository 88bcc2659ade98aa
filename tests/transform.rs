//! The cube's symmetry group, hierarchical canonicalization (S, A, S+A) and SSVDAG, checked
//! against brute force: every subtree is materialised as a voxel set and transformed with an
//! independent point-transform implementation.

mod common;

use std::collections::{HashMap, HashSet};

use proptest::prelude::*;
use voxdag::dag::transform::{Transform, TransformSet, TRANSFORM_COUNT};
use voxdag::dag::{symmetry_counts, CanonicalDag, Invariance, Ssvdag, Svdag};
use voxdag::gpu::shaders;
use voxdag::scene::morton;
use voxdag::scene::Voxels;

// ---------------------------------------------------------------- independent reference group

/// All 6 permutations of the axes (any order: only the set matters here).
fn perms() -> Vec<[usize; 3]> {
    let mut out = Vec::new();
    for a in 0..3 {
        for b in 0..3 {
            for c in 0..3 {
                if a != b && b != c && a != c {
                    out.push([a, b, c]);
                }
            }
        }
    }
    out
}

/// A group element as (permutation, mirror): p -> mirror(permute(p)).
type Elem = ([usize; 3], u8);

fn apply(e: Elem, p: [u32; 3], n: u32) -> [u32; 3] {
    let mut out = [0; 3];
    for i in 0..3 {
        let v = p[e.0[i]];
        out[i] = if (e.1 >> i) & 1 == 1 { n - 1 - v } else { v };
    }
    out
}

fn group(set: TransformSet) -> Vec<Elem> {
    let mut out = Vec::new();
    for p in perms() {
        for m in 0..8u8 {
            let ok = match set {
                TransformSet::None => p == [0, 1, 2] && m == 0,
                TransformSet::Mirrors => p == [0, 1, 2],
                TransformSet::AxisPermutations => m == 0,
                TransformSet::All => true,
            };
            if ok {
                out.push((p, m));
            }
        }
    }
    out
}

fn voxels(n: u32, coords: impl IntoIterator<Item = [u32; 3]>) -> Voxels {
    Voxels::from_coords(n, coords)
}

/// Per level: the distinct non-empty subtrees (local voxel sets) in order of first occurrence
/// in Morton order.
fn subtrees(v: &Voxels) -> Vec<Vec<Vec<[u32; 3]>>> {
    let levels = v.resolution.trailing_zeros() - 1;
    (0..levels)
        .map(|l| {
            let size = 4u32 << l;
            let shift = 3 * (2 + l);
            let mut nodes: Vec<(u64, Vec<[u32; 3]>)> = Vec::new();
            for &c in &v.codes {
                let key = c >> shift;
                let [x, y, z] = morton::decode(c);
                let local = [x % size, y % size, z % size];
                match nodes.last_mut() {
                    Some((k, set)) if *k == key => set.push(local),
                    _ => nodes.push((key, vec![local])),
                }
            }
            let mut seen = HashSet::new();
            let mut out = Vec::new();
            for (_, mut set) in nodes {
                set.sort_unstable();
                if seen.insert(set.clone()) {
                    out.push(set);
                }
            }
            out
        })
        .collect()
}

/// Brute-force count of distinct subtrees per level up to a transform set: canonical form =
/// lexicographically smallest sorted Morton list over all transformed copies.
fn brute_counts(v: &Voxels, set: TransformSet) -> Vec<u64> {
    let g = group(set);
    subtrees(v)
        .iter()
        .enumerate()
        .map(|(l, nodes)| {
            let size = 4u32 << l;
            let canon: HashSet<Vec<u64>> = nodes
                .iter()
                .map(|set| {
                    g.iter()
                        .map(|&e| {
                            let mut codes: Vec<u64> = set
                                .iter()
                                .map(|&p| {
                                    let [x, y, z] = apply(e, p, size);
                                    morton::encode(x, y, z)
                                })
                                .collect();
                            codes.sort_unstable();
                            codes
                        })
                        .min()
                        .expect("non-empty group")
                })
                .collect();
            canon.len() as u64
        })
        .collect()
}

// ---------------------------------------------------------------- SSVDAG reference (published rule)

#[derive(Clone, Copy, Debug)]
struct RPtr {
    ptr: usize,
    t: u8,
    /// Axes3: bit a = invariant under axis-a mirror; Full: bit m = invariant under mirror m.
    inv: u8,
}

fn rptr_eq(a: &RPtr, b: &RPtr, full: bool) -> bool {
    if a.ptr != b.ptr {
        return false;
    }
    if full {
        (0..8u8).any(|h| (a.inv >> h) & 1 == 1 && a.t ^ h == b.t)
    } else {
        let keep = !a.inv & 7;
        a.t & keep == b.t & keep
    }
}

type RNode = [Option<RPtr>; 8];

fn rnode_eq(a: &RNode, b: &RNode, full: bool) -> bool {
    a.iter().zip(b).all(|(x, y)| match (x, y) {
        (None, None) => true,
        (Some(x), Some(y)) => rptr_eq(x, y, full),
        _ => false,
    })
}

fn rmirror(n: &RNode, m: u8) -> RNode {
    let mut out = [None; 8];
    for o in 0..8 {
        out[o ^ m as usize] = n[o].map(|p| RPtr { t: p.t ^ m, ..p });
    }
    out
}

fn rinvariance(n: &RNode, full: bool) -> u8 {
    let mut inv = 0;
    for m in 0..8u8 {
        if rnode_eq(&rmirror(n, m), n, full) {
            if full {
                inv |= 1 << m;
            } else if m.count_ones() == 1 {
                inv |= m;
            }
        }
    }
    inv
}

fn rblock(mask: u8, full: bool) -> RPtr {
    let mirror = |m: u8| (0..8u8).fold(0u8, |a, o| a | (((mask >> o) & 1) << (o ^ m)));
    let (mut best, mut best_t, mut inv) = (0u8, 0u8, 0u8);
    for t in 0..8u8 {
        let v = mirror(t);
        if v > best {
            best = v;
            best_t = t;
        }
        if v == mask {
            if full {
                inv |= 1 << t;
            } else if t.count_ones() == 1 {
                inv |= t;
            }
        }
    }
    RPtr {
        ptr: best as usize,
        t: best_t,
        inv,
    }
}

/// SSVDAG stored-node counts per level by the published greedy rule with linear search.
fn reference_ssvdag(v: &Voxels, full: bool) -> Vec<u64> {
    let mut counts = Vec::new();
    let mut pointers: HashMap<Vec<[u32; 3]>, RPtr> = HashMap::new();
    for (l, nodes) in subtrees(v).iter().enumerate() {
        let size = 4u32 << l;
        let half = size / 2;
        let mut stored: Vec<RNode> = Vec::new();
        let mut next: HashMap<Vec<[u32; 3]>, RPtr> = HashMap::new();
        for set in nodes {
            let node: RNode = if l == 0 {
                let mut mask = 0u64;
                for &[x, y, z] in set {
                    mask |= 1 << morton::encode(x, y, z);
                }
                std::array::from_fn(|o| Some(rblock((mask >> (8 * o)) as u8, full)))
            } else {
                let mut parts: Vec<Vec<[u32; 3]>> = vec![Vec::new(); 8];
                for &[x, y, z] in set {
                    let o = (x / half) | (y / half) << 1 | (z / half) << 2;
                    parts[o as usize].push([x % half, y % half, z % half]);
                }
                std::array::from_fn(|o| {
                    let mut p = parts[o].clone();
                    p.sort_unstable();
                    (!p.is_empty()).then(|| pointers[&p])
                })
            };
            let inv = rinvariance(&node, full);
            let mut found = None;
            'search: for m in 1..8u8 {
                let mirrored = rmirror(&node, m);
                for (i, s) in stored.iter().enumerate() {
                    if rnode_eq(s, &mirrored, full) {
                        found = Some((i, m));
                        break 'search;
                    }
                }
            }
            let ptr = match found {
                Some((i, m)) => RPtr { ptr: i, t: m, inv },
                None => {
                    stored.push(node);
                    RPtr {
                        ptr: stored.len() - 1,
                        t: 0,
                        inv,
                    }
                }
            };
            next.insert(set.clone(), ptr);
        }
        counts.push(stored.len() as u64);
        pointers = next;
    }
    counts
}

// ---------------------------------------------------------------- helpers

/// Checks every count of a scene against brute force, and that the canonical DAGs decode to
/// exactly the scene.
fn check_scene(v: &Voxels) {
    let dag = Svdag::from_voxels(v).expect("build");
    let counts = symmetry_counts(&dag);
    let n = v.resolution;
    let levels = (n.trailing_zeros() - 1) as usize;
    assert_eq!(counts.len(), levels);
    let svdag = brute_counts(v, TransformSet::None);
    let s = brute_counts(v, TransformSet::Mirrors);
    let a = brute_counts(v, TransformSet::AxisPermutations);
    let sa = brute_counts(v, TransformSet::All);
    let ssvdag = reference_ssvdag(v, false);
    let ssvdag_full = reference_ssvdag(v, true);
    for (l, c) in counts.iter().enumerate() {
        let want = (svdag[l], ssvdag[l], s[l], a[l], sa[l]);
        assert_eq!((c.svdag, c.ssvdag, c.s, c.a, c.sa), want, "level {l}");
    }
    assert_eq!(ssvdag_full, s, "full-invariance SSVDAG = mirror orbits");
    assert_eq!(
        Ssvdag::build(&dag, Invariance::Full).level_counts(),
        ssvdag_full
    );
    assert_eq!(
        CanonicalDag::build(&dag, TransformSet::None).level_counts(),
        svdag
    );
    let occupied: HashSet<u64> = v.codes.iter().copied().collect();
    for set in [TransformSet::Mirrors, TransformSet::All] {
        let c = CanonicalDag::build(&dag, set);
        for code in 0..(n as u64).pow(3) {
            let [x, y, z] = morton::decode(code);
            assert_eq!(
                c.contains(x, y, z),
                occupied.contains(&code),
                "{set:?} {x} {y} {z}"
            );
        }
    }
}

/// Deterministic xorshift generator.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

// ---------------------------------------------------------------- group tests

#[test]
fn group_axioms_and_tables() {
    let all: Vec<Transform> = Transform::all().collect();
    assert_eq!(all.len(), TRANSFORM_COUNT);
    // The 48 ids are 48 distinct maps of the 8^3 grid, exactly the reference group.
    let pts: Vec<[u32; 3]> = (0..512).map(morton::decode).collect();
    let image = |t: Transform| pts.iter().map(|&p| t.apply_point(p, 8)).collect::<Vec<_>>();
    let ours: HashSet<Vec<[u32; 3]>> = all.iter().map(|&t| image(t)).collect();
    let theirs: HashSet<Vec<[u32; 3]>> = group(TransformSet::All)
        .iter()
        .map(|&e| pts.iter().map(|&p| apply(e, p, 8)).collect())
        .collect();
    assert_eq!(ours.len(), 48);
    assert_eq!(ours, theirs);
    let id = Transform::IDENTITY;
    assert_eq!(image(id), pts);
    for &a in &all {
        assert_eq!(a.compose(id), a);
        assert_eq!(id.compose(a), a);
        assert_eq!(a.compose(a.inverse()), id);
        assert_eq!(a.inverse().compose(a), id);
        assert_eq!(
            Transform::from_parts(a.permutation_index(), a.mirror()),
            Some(a)
        );
        for &b in &all {
            let ab = a.compose(b);
            for &p in pts.iter().step_by(7) {
                assert_eq!(ab.apply_point(p, 8), a.apply_point(b.apply_point(p, 8), 8));
            }
            for &c in all.iter().step_by(5) {
                assert_eq!(ab.compose(c), a.compose(b.compose(c)), "associativity");
            }
        }
        // Octants and child masks follow the point action at size 2.
        for o in 0..8usize {
            let [x, y, z] = a.apply_point([o as u32 & 1, (o as u32 >> 1) & 1, o as u32 >> 2], 2);
            assert_eq!(a.apply_octant(o), (x | y << 1 | z << 2) as usize);
        }
        for m in 0..=255u8 {
            let want = (0..8)
                .filter(|o| (m >> o) & 1 == 1)
                .fold(0u8, |w, o| w | 1 << a.apply_octant(o));
            assert_eq!(a.apply_child_mask(m), want);
        }
        // Nested action: a voxel in child octant o lands in octant T(o) at T applied locally.
        for &p in &pts {
            let q = a.apply_point(p, 8);
            let o = (p[0] / 4) | (p[1] / 4) << 1 | (p[2] / 4) << 2;
            let oq = (q[0] / 4) | (q[1] / 4) << 1 | (q[2] / 4) << 2;
            assert_eq!(a.apply_octant(o as usize), oq as usize);
            assert_eq!(
                a.apply_point([p[0] % 4, p[1] % 4, p[2] % 4], 4),
                [q[0] % 4, q[1] % 4, q[2] % 4]
            );
        }
    }
    // Subsets: sizes, identity first, closed under composition and inverse.
    for (set, size) in [
        (TransformSet::None, 1),
        (TransformSet::Mirrors, 8),
        (TransformSet::AxisPermutations, 6),
        (TransformSet::All, 48),
    ] {
        let ts = set.transforms();
        assert_eq!(ts.len(), size);
        assert_eq!(ts[0], id);
        assert_eq!(set.mask().count_ones() as usize, size);
        for &a in ts {
            assert!(set.contains(a.inverse()));
            for &b in ts {
                assert!(set.contains(a.compose(b)), "{set:?} closed");
            }
        }
    }
}

#[test]
fn leaf_bit_permutation_matches_voxel_transform() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let masks: Vec<u64> = (0..200)
        .map(|i| match i {
            0 => 0,
            1 => u64::MAX,
            _ => rng.next() & rng.next(),
        })
        .collect();
    for t in Transform::all() {
        for &mask in &masks {
            let mut want = 0u64;
            for bit in 0..64 {
                if (mask >> bit) & 1 == 1 {
                    let [x, y, z] = t.apply_point(morton::decode(bit), 4);
                    want |= 1 << morton::encode(x, y, z);
                }
            }
            assert_eq!(t.apply_leaf(mask), want, "transform {}", t.index());
            assert_eq!(t.inverse().apply_leaf(t.apply_leaf(mask)), mask);
        }
    }
}

/// The voxels of a 4^3 leaf (bit `morton(x, y, z)`) moved by `shift`, those leaving the leaf
/// dropped: a translated leaf as the traversal sees it in its cell.
fn shifted_leaf(leaf: u64, shift: [i32; 3]) -> u64 {
    (0..64u64)
        .filter(|&code| leaf >> code & 1 == 1)
        .filter_map(|code| {
            let p = morton::decode(code);
            let q: [i32; 3] = std::array::from_fn(|a| p[a] as i32 + shift[a]);
            q.iter()
                .all(|c| (0..4).contains(c))
                .then(|| 1u64 << morton::encode(q[0] as u32, q[1] as u32, q[2] as u32))
        })
        .fold(0, |m, bit| m | bit)
}

/// The GPU's transform arithmetic (`shaders/glsl/render/xform.glsl`, which the transformed
/// formats' traversal uses) equals `Transform` for all 48 transforms: leaves (every single
/// voxel and random masks), child masks, stored octants, compositions with every transform and
/// translations (`T(p + tr) = T(p) + tr'`); and a leaf moved in its cell (`xform_leaf_shift`)
/// equals `shifted_leaf` for every shift in -3..3 per axis.
#[test]
fn gpu_transform_arithmetic_equals_cpu() {
    const OUT_WORDS: usize = 10;
    let mut rng = Rng(0x51ed_2701_ab3c_9d44);
    // Records: leaf (2 words), child mask | octant << 8 | composed transform << 16, translation.
    let mut records: Vec<[u32; 4]> = Vec::new();
    for r in 0..256usize {
        let leaf = if r < 64 {
            1u64 << r
        } else {
            rng.next() & rng.next()
        };
        let word = rng.next();
        let tr: [i8; 3] = std::array::from_fn(|a| ((word >> (8 * a)) % 31) as i8 - 15);
        records.push([
            leaf as u32,
            (leaf >> 32) as u32,
            (r as u32 & 0xff) | ((r as u32 % 8) << 8) | ((r as u32 % 48) << 16),
            u32::from_le_bytes([tr[0] as u8, tr[1] as u8, tr[2] as u8, 0]),
        ]);
    }
    let ctx = common::gpu();
    let input: Vec<u32> = records.iter().flatten().copied().collect();
    let cases = records.len() * TRANSFORM_COUNT;
    let got = common::run_test_shader(&ctx, shaders::TEST_XFORM, &input, cases, OUT_WORDS);
    for (r, record) in records.iter().enumerate() {
        let leaf = record[0] as u64 | (record[1] as u64) << 32;
        let mask = (record[2] & 0xff) as u8;
        let octant = ((record[2] >> 8) & 7) as usize;
        let inner = Transform::from_index((record[2] >> 16) as usize).unwrap();
        let tr = record[3].to_le_bytes().map(|b| b as i8 as i32);
        for t in Transform::all() {
            let case = r * TRANSFORM_COUNT + t.index();
            let words = &got[case * OUT_WORDS..(case + 1) * OUT_WORDS];
            let what = format!("transform {}, record {r}", t.index());
            assert_eq!(
                words[0] as u64 | (words[1] as u64) << 32,
                t.apply_leaf(leaf),
                "leaf: {what}"
            );
            assert_eq!(
                words[2],
                t.apply_child_mask(mask) as u32,
                "child mask: {what}"
            );
            assert_eq!(
                words[3] as usize,
                t.inverse().apply_octant(octant),
                "stored octant: {what}"
            );
            assert_eq!(
                words[4] as usize,
                t.compose(inner).index(),
                "compose: {what}"
            );
            let p = [20u32, 21, 22];
            let moved: [u32; 3] = std::array::from_fn(|a| (p[a] as i32 + tr[a]) as u32);
            let (tp, tq) = (t.apply_point(p, 64), t.apply_point(moved, 64));
            let want: [i32; 3] = std::array::from_fn(|a| tq[a] as i32 - tp[a] as i32);
            let seen = [words[5] as i32, words[6] as i32, words[7] as i32];
            assert_eq!(seen, want, "translation {tr:?}: {what}");
            let s = (case % 343) as i32;
            let shift = [s % 7 - 3, s / 7 % 7 - 3, s / 49 - 3];
            assert_eq!(
                words[8] as u64 | (words[9] as u64) << 32,
                shifted_leaf(leaf, shift),
                "leaf moved by {shift:?}: {what}"
            );
        }
    }
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

// ---------------------------------------------------------------- count tests

/// A random blob in an 8^3 cell and its 48 transformed copies in separate cells of a 32^3 grid:
/// under S+A all copies are one canonical node, and every copy's pointer transform relates it
/// to the others.
#[test]
fn transformed_copies_collapse() {
    let mut rng = Rng(12345);
    let group48 = group(TransformSet::All);
    let blob: Vec<[u32; 3]> = loop {
        let blob: Vec<[u32; 3]> = (0..512u64)
            .filter(|_| rng.next().is_multiple_of(5))
            .map(morton::decode)
            .collect();
        let images: HashSet<Vec<u64>> = group48
            .iter()
            .map(|&e| {
                let mut c: Vec<u64> = blob
                    .iter()
                    .map(|&p| {
                        let [x, y, z] = apply(e, p, 8);
                        morton::encode(x, y, z)
                    })
                    .collect();
                c.sort_unstable();
                c
            })
            .collect();
        if images.len() == 48 {
            break blob;
        }
    };
    let all: Vec<Transform> = Transform::all().collect();
    let mut coords = Vec::new();
    for (i, t) in all.iter().enumerate() {
        let cell = [i as u32 & 3, (i as u32 >> 2) & 3, i as u32 >> 4];
        for &p in &blob {
            let q = t.apply_point(p, 8);
            coords.push([cell[0] * 8 + q[0], cell[1] * 8 + q[1], cell[2] * 8 + q[2]]);
        }
    }
    let v = voxels(32, coords);
    let dag = Svdag::from_voxels(&v).expect("build");
    let c = CanonicalDag::build(&dag, TransformSet::All);
    assert_eq!(c.levels[1].len(), 1, "48 copies, one canonical node");
    assert_eq!(c.levels[1].stabilisers[0], 1, "trivial stabiliser");
    assert_eq!(dag.level_stats()[1].svdag, 48);
    assert_eq!(
        CanonicalDag::build(&dag, TransformSet::Mirrors).levels[1].len(),
        6
    );
    assert_eq!(
        CanonicalDag::build(&dag, TransformSet::AxisPermutations).levels[1].len(),
        8
    );
    // Copy i is all[i](blob); its pointer says copy = T_i(C), so T_i ∘ T_0⁻¹ = all[i].
    let mut ptr_of_cell = HashMap::new();
    let range = dag.level_range(1);
    let mut p = range.start;
    let mut idx = 0;
    while p < range.end {
        ptr_of_cell.insert(p, c.levels[1].svdag_nodes[idx]);
        idx += 1;
        p += 1 + dag.words[p].count_ones() as usize;
    }
    for (i, t) in all.iter().enumerate() {
        let cell = [i as u32 & 3, (i as u32 >> 2) & 3, i as u32 >> 4];
        let mut node = 0usize;
        for l in (2..=dag.root_level()).rev() {
            let shift = l + 1;
            let o = ((cell[0] * 8) >> shift & 1)
                | ((cell[1] * 8) >> shift & 1) << 1
                | ((cell[2] * 8) >> shift & 1) << 2;
            let mask = dag.words[node];
            let rank = (mask & ((1 << o) - 1)).count_ones() as usize;
            node = dag.words[node + 1 + rank] as usize;
        }
        let ptr_i = ptr_of_cell[&node];
        let ptr_0 = c.levels[1].svdag_nodes[0];
        assert_eq!(ptr_i.node, 0);
        assert_eq!(
            ptr_i.transform.compose(ptr_0.transform.inverse()),
            *t,
            "copy {i}"
        );
    }
    check_scene(&v);
}

/// Symmetric and structured scenes: spheres, boxes, a random set symmetrised by a subgroup.
#[test]
fn structured_scenes_match_brute_force() {
    let n = 32;
    let sphere = voxels(
        n,
        (0..n * n * n)
            .map(|i| [i % n, (i / n) % n, i / (n * n)])
            .filter(|&[x, y, z]| {
                let d = |c: u32| (2 * c as i64 - 31).pow(2);
                let r = d(x) + d(y) + d(z);
                (700..1100).contains(&r)
            }),
    );
    check_scene(&sphere);
    let boxes = voxels(
        n,
        (0..n * n * n)
            .map(|i| [i % n, (i / n) % n, i / (n * n)])
            .filter(|&[x, y, z]| (x < 13 && y < 7 && z < 21) || (x > 20 && y > 3 && z < 5)),
    );
    check_scene(&boxes);
    check_scene(&voxels(16, [[0, 0, 0]]));
    check_scene(&voxels(8, (0..512).map(morton::decode)));
    let empty = voxels(16, []);
    let dag = Svdag::from_voxels(&empty).expect("build");
    for c in symmetry_counts(&dag) {
        assert_eq!((c.svdag, c.ssvdag, c.s, c.a, c.sa), (0, 0, 0, 0, 0));
    }
}

/// Closes a list of transforms into the subgroup it generates and unions the images of `seed`.
fn symmetrise(n: u32, seed: &[[u32; 3]], gens: &[usize]) -> Voxels {
    let mut sub: HashSet<Transform> = HashSet::from([Transform::IDENTITY]);
    loop {
        let before = sub.len();
        let cur: Vec<Transform> = sub.iter().copied().collect();
        for &a in &cur {
            for &g in gens {
                sub.insert(a.compose(Transform::from_index(g).expect("id < 48")));
            }
        }
        if sub.len() == before {
            break;
        }
    }
    voxels(
        n,
        sub.iter()
            .flat_map(|t| seed.iter().map(move |&p| t.apply_point(p, n))),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Random sparse sets (many small, often symmetric leaves) and random sets symmetrised by a
    /// random subgroup (nodes with non-trivial stabilisers): all counts equal brute force.
    #[test]
    fn random_scenes_match_brute_force(
        n_log in 3u32..=5,
        seed in prop::collection::vec((0u32..32, 0u32..32, 0u32..32), 1..120),
        gens in prop::collection::vec(0usize..48, 0..3),
    ) {
        let n = 1u32 << n_log;
        let pts: Vec<[u32; 3]> = seed.iter().map(|&(x, y, z)| [x % n, y % n, z % n]).collect();
        check_scene(&symmetrise(n, &pts, &gens));
    }
}

/// Real meshes at a small resolution: every count equals brute force.
#[test]
fn shared_meshes_match_brute_force() {
    let Some(data) = common::shared_data() else {
        return;
    };
    for (mesh, res) in [("bunny.obj", 128), ("dragon.obj", 64), ("teapot.obj", 64)] {
        let options = voxdag::scene::ImportOptions {
            resolution: Some(res),
            ..Default::default()
        };
        let v = voxdag::scene::import(
            &data.join("meshes").join(mesh),
            &options,
            &indicatif::ProgressBar::hidden(),
        )
        .expect("import");
        check_scene(&v);
    }
}

#[test]
fn stats_json_symmetry_keys_only_when_asked() {
    let v = symmetrise(16, &[[1, 2, 3], [5, 0, 9], [15, 15, 2]], &[1, 8]);
    let dag = Svdag::from_voxels(&v).expect("build");
    let plain = serde_json::to_value(dag.stats()).expect("json");
    let level0 = &plain["levels"][0];
    assert!(level0.get("sa").is_none() && level0.get("ssvdag").is_none());
    let full = serde_json::to_value(dag.stats_with_symmetry()).expect("json");
    let counts = symmetry_counts(&dag);
    for (l, c) in counts.iter().enumerate() {
        let level = &full["levels"][l];
        assert_eq!(level["svdag"], c.svdag);
        assert_eq!(level["ssvdag"], c.ssvdag);
        assert_eq!(level["s"], c.s);
        assert_eq!(level["a"], c.a);
        assert_eq!(level["sa"], c.sa);
        assert_eq!(level["svo"], plain["levels"][l]["svo"]);
    }
}

/// The published 3-bit rule misses invariance under a combined mirror: a leaf and its
/// xy-mirror whose only symmetric sub-block is xy-invariant are stored twice by SSVDAG (3 bits)
/// but once with full invariance (and under S).
#[test]
fn three_bit_invariance_misses_combined_mirrors() {
    // Sub-block 0: voxels (0,0,0) and (1,1,0) (invariant under xy only); sub-block 7: one voxel.
    let l1 = [[0, 0, 0], [1, 1, 0], [2, 2, 2]];
    let l2: Vec<[u32; 3]> = l1.iter().map(|&[x, y, z]| [3 - x, 3 - y, z]).collect();
    let coords = l1
        .iter()
        .copied()
        .chain(l2.iter().map(|&[x, y, z]| [x + 4, y, z]));
    let v = voxels(8, coords);
    let dag = Svdag::from_voxels(&v).expect("build");
    let c = symmetry_counts(&dag);
    assert_eq!((c[0].svdag, c[0].ssvdag, c[0].s), (2, 2, 1));
    assert_eq!(reference_ssvdag(&v, false)[0], 2);
    assert_eq!(reference_ssvdag(&v, true)[0], 1);
    check_scene(&v);
}

/// `voxdag stats --json` reports the transform counts per level; the table shows them too.
#[test]
fn cli_stats_reports_symmetry_counts() {
    let v = symmetrise(
        32,
        &[[1, 2, 3], [5, 0, 9], [15, 15, 2], [30, 7, 19]],
        &[3, 16],
    );
    let dag = Svdag::from_voxels(&v).expect("build");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("scene.vdag");
    dag.save(&path).expect("save");
    let run = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_voxdag"))
            .args(args)
            .output()
            .expect("run voxdag");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).expect("utf-8")
    };
    let path_str = path.to_str().expect("utf-8 path");
    let json: serde_json::Value =
        serde_json::from_str(&run(&["stats", path_str, "--json"])).expect("json");
    let levels = json["levels"].as_array().expect("levels");
    let counts = symmetry_counts(&dag);
    assert_eq!(levels.len(), counts.len());
    for (level, c) in levels.iter().zip(&counts) {
        for (key, want) in [
            ("svdag", c.svdag),
            ("ssvdag", c.ssvdag),
            ("s", c.s),
            ("a", c.a),
            ("sa", c.sa),
        ] {
            assert_eq!(level[key], want, "level {} {key}", c.level);
        }
    }
    let table = run(&["stats", path_str]);
    assert!(table.contains("ssvdag") && table.contains(" sa"), "{table}");
    let row0 = format!(
        "{} {:>10} {:>10} {:>10} {:>10}",
        counts[0].svdag, counts[0].ssvdag, counts[0].s, counts[0].a, counts[0].sa
    );
    assert!(table.contains(&row0), "{table}\n{row0}");
}
