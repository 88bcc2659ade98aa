//! Hierarchical canonicalization of an SVDAG under a transform set (dissertation §3.3.1).
//!
//! Bottom-up, every SVDAG node `N` is written as `T(C)`: a canonical node `C` (one per orbit
//! of the transform set) and a transform `T`. Two subtrees share a canonical node exactly when
//! one is a transform of the other, so the number of canonical nodes per level is the number of
//! distinct subtrees up to the transform set.
//!
//! - Leaves: `C` = the largest 64-bit mask among `g(N)`, `g` in the set.
//! - Inner nodes: the children are already `(C_o, T_o)` pairs. `g(N)` has the child
//!   `(C_o, g ∘ T_o)` at octant `g(o)`. Because `T(C_o) = T'(C_o)` iff `T' ∈ T · Stab(C_o)`,
//!   every child transform is replaced by the smallest id of its coset, which makes the key
//!   of `g(N)` (transformed child mask, then per octant `(child id + 1) << 6 | transform`) equal
//!   for two nodes exactly when their voxel sets are equal. The canonical node is the `g(N)`
//!   with the largest key; only the `g` that maximise the transformed child mask are expanded
//!   (the children's canonical ids cluster the candidates; the search over the set is exhaustive).
//! - The stabiliser `Stab(C) = { e ∘ g*⁻¹ : e(N) = C }` (a 48-bit mask) is kept per canonical
//!   node; the pointer transform is the smallest id of `g*⁻¹ · Stab(C)`.
//!
//! Canonical ids are assigned in order of first occurrence in SVDAG level order, so the result
//! is deterministic for any thread count.

use std::hash::BuildHasher;

use hashbrown::HashTable;
use rayon::prelude::*;
use rustc_hash::{FxBuildHasher, FxHashMap};

use super::transform::{coset_min, transforms_in_mask, Transform, TransformSet, TRANSFORM_COUNT};
use super::Svdag;

/// A reference to a canonical node together with the transform to apply to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct TransformPointer {
    /// Canonical node index within its level.
    pub node: u32,
    /// The subtree is `transform` applied to the canonical node (the smallest id of its coset).
    pub transform: Transform,
}

/// The canonical nodes of one level.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CanonicalLevel {
    /// Level 0 only: the canonical 4^3 leaf masks.
    pub leaves: Vec<u64>,
    /// Inner levels: child mask of each canonical node.
    pub child_masks: Vec<u8>,
    /// Inner levels: index of each node's first child in `children` (one entry per node).
    pub child_starts: Vec<u32>,
    /// Inner levels: children of all nodes, ascending octant order, pointing into the level below.
    pub children: Vec<TransformPointer>,
    /// Stabiliser of each canonical node: bit `t` set when transform `t` maps it onto itself.
    pub stabilisers: Vec<u64>,
    /// For each SVDAG node of this level (in the order stored in `Svdag::words`): its canonical
    /// node and transform.
    pub svdag_nodes: Vec<TransformPointer>,
}

impl CanonicalLevel {
    /// Number of canonical nodes.
    pub fn len(&self) -> usize {
        self.stabilisers.len()
    }

    /// Whether the level holds no canonical node.
    pub fn is_empty(&self) -> bool {
        self.stabilisers.is_empty()
    }

    /// Children of inner canonical node `i`, ascending octant order.
    pub fn node_children(&self, i: usize) -> &[TransformPointer] {
        let start = self.child_starts[i] as usize;
        let n = self.child_masks[i].count_ones() as usize;
        &self.children[start..start + n]
    }

    /// The search key of inner canonical node `i`, rebuilt from the level's arrays (the dedup
    /// table stores node indices only, not keys).
    fn inner_key(&self, i: usize) -> InnerKey {
        let mut key = [0u64; 8];
        let mut children = self.node_children(i).iter();
        for (o, slot) in key.iter_mut().enumerate() {
            if (self.child_masks[i] >> o) & 1 == 1 {
                let c = children.next().expect("one child per mask bit");
                *slot = ((c.node as u64 + 1) << 6) | c.transform.index() as u64;
            }
        }
        key
    }
}

/// An SVDAG rewritten as canonical nodes per level and transform pointers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CanonicalDag {
    /// Grid side length.
    pub resolution: u32,
    /// The transforms used to match subtrees.
    pub set: TransformSet,
    /// Levels bottom-up (0 = 4^3 leaves); the last is the root level.
    pub levels: Vec<CanonicalLevel>,
}

/// Nodes processed per parallel batch (bounds the memory of per-node results).
const BATCH: usize = 1 << 16;

/// Dense coset-minimum tables, one row per distinct stabiliser subgroup.
#[derive(Default)]
struct CosetTables {
    index: FxHashMap<u64, u8>,
    rows: Vec<[u8; TRANSFORM_COUNT]>,
}

impl CosetTables {
    fn row_of(&mut self, stab: u64) -> u8 {
        if let Some(&i) = self.index.get(&stab) {
            return i;
        }
        let mut row = [0u8; TRANSFORM_COUNT];
        for t in Transform::all() {
            row[t.index()] = coset_min(t, stab).index() as u8;
        }
        let i = self.rows.len() as u8; // the group has 98 subgroups: fits u8
        self.rows.push(row);
        self.index.insert(stab, i);
        i
    }
}

/// Per-node result of the parallel search.
struct Found<K> {
    key: K,
    /// Stabiliser of the canonical node.
    stab: u64,
    /// Pointer transform (`N = transform(C)`), already the smallest of its coset.
    transform: Transform,
}

/// Given `E = { g : g(N) = C }` (48-bit mask) and the first of them `g*`, returns
/// `(Stab(C), coset-minimal T with N = T(C))`.
fn stab_and_pointer(equal: u64, first: Transform) -> (u64, Transform) {
    let inv = first.inverse();
    let stab = transforms_in_mask(equal).fold(0u64, |m, e| m | 1 << e.compose(inv).index());
    (stab, coset_min(inv, stab))
}

fn canonical_leaf(mask: u64, set: &[Transform]) -> Found<u64> {
    let mut best = 0u64;
    let mut first = Transform::IDENTITY;
    let mut equal = 0u64;
    for &g in set {
        let m = g.apply_leaf(mask);
        if m > best || equal == 0 {
            best = m;
            first = g;
            equal = 1 << g.index();
        } else if m == best {
            equal |= 1 << g.index();
        }
    }
    let (stab, transform) = stab_and_pointer(equal, first);
    Found {
        key: best,
        stab,
        transform,
    }
}

/// Child pointers of an inner SVDAG node in ascending octant order, with their coset table rows.
type InnerKey = [u64; 8];

fn canonical_inner(
    mask: u8,
    children: &[(TransformPointer, u8)],
    set: &[Transform],
    rows: &[[u8; TRANSFORM_COUNT]],
) -> Found<InnerKey> {
    let best_mask = set
        .iter()
        .map(|g| g.apply_child_mask(mask))
        .max()
        .unwrap_or(mask);
    let mut best: Option<InnerKey> = None;
    let mut first = Transform::IDENTITY;
    let mut equal = 0u64;
    for &g in set {
        if g.apply_child_mask(mask) != best_mask {
            continue;
        }
        let mut key = [0u64; 8];
        let mut k = 0;
        for o in 0..8 {
            if (mask >> o) & 1 == 1 {
                let (ptr, row) = children[k];
                k += 1;
                let t = rows[row as usize][g.compose(ptr.transform).index()];
                key[g.apply_octant(o)] = ((ptr.node as u64 + 1) << 6) | t as u64;
            }
        }
        match &best {
            Some(b) if key < *b => {}
            Some(b) if key == *b => equal |= 1 << g.index(),
            _ => {
                best = Some(key);
                first = g;
                equal = 1 << g.index();
            }
        }
    }
    let (stab, transform) = stab_and_pointer(equal, first);
    Found {
        key: best.unwrap_or([0; 8]),
        stab,
        transform,
    }
}

impl CanonicalDag {
    /// Canonicalizes every level of a (valid) SVDAG under `set`.
    pub fn build(dag: &Svdag, set: TransformSet) -> CanonicalDag {
        Self::build_with_progress(dag, set, &indicatif::ProgressBar::hidden())
    }

    /// [`CanonicalDag::build`] reporting its progress on `progress` (SVDAG words done).
    pub fn build_with_progress(
        dag: &Svdag,
        set: TransformSet,
        progress: &indicatif::ProgressBar,
    ) -> CanonicalDag {
        let transforms = set.transforms();
        progress.set_length(dag.words.len() as u64);
        let root_level = dag.root_level();
        let mut levels: Vec<CanonicalLevel> = Vec::with_capacity(root_level as usize + 1);
        let mut coset = CosetTables::default();
        let empty = dag.words.first().copied().unwrap_or(0) == 0;

        // Level 0.
        let mut level = CanonicalLevel::default();
        // Coset table row of each canonical node of the level below.
        let mut rows_below: Vec<u8> = Vec::new();
        if !empty {
            let range = dag.level_range(0);
            let masks: Vec<u64> = range.step_by(2).map(|p| dag.leaf_mask(p)).collect();
            let mut ids: FxHashMap<u64, u32> = FxHashMap::default();
            level.svdag_nodes.reserve(masks.len());
            for batch in masks.chunks(BATCH) {
                let found: Vec<Found<u64>> = batch
                    .par_iter()
                    .map(|&m| canonical_leaf(m, transforms))
                    .collect();
                progress.inc(2 * batch.len() as u64);
                for f in found {
                    let next = level.leaves.len() as u32;
                    let node = *ids.entry(f.key).or_insert(next);
                    if node == next {
                        level.leaves.push(f.key);
                        level.stabilisers.push(f.stab);
                        rows_below.push(coset.row_of(f.stab));
                    }
                    level.svdag_nodes.push(TransformPointer {
                        node,
                        transform: f.transform,
                    });
                }
            }
        }
        levels.push(level);

        // Inner levels. `below_index[w - start]` = SVDAG node index of the node at word `w`.
        let mut below_start = dag.level_range(0).start;
        let mut below_index: Vec<u32> = (0..dag.level_range(0).len())
            .map(|w| (w / 2) as u32)
            .collect();
        for l in 1..=root_level {
            let range = dag.level_range(l);
            let mut offsets: Vec<usize> = Vec::new();
            let mut index = vec![0u32; range.len()];
            if !empty {
                for p in dag.node_starts(l) {
                    index[p - range.start] = offsets.len() as u32;
                    offsets.push(p);
                }
            }
            let below = levels.last().expect("level 0 exists");
            let mut level = CanonicalLevel::default();
            let mut rows_here: Vec<u8> = Vec::new();
            // Node indices keyed by their `InnerKey`, compared through `inner_key`: 4 bytes
            // per canonical node instead of a 64-byte key (bunny 64K^3 has ~20 M per level).
            let mut ids: HashTable<u32> = HashTable::new();
            level.svdag_nodes.reserve(offsets.len());
            for batch in offsets.chunks(BATCH) {
                let found: Vec<Found<InnerKey>> = batch
                    .par_iter()
                    .map(|&p| {
                        let mask = dag.words[p] as u8;
                        let mut children = [(TransformPointer::default(), 0u8); 8];
                        let n = mask.count_ones() as usize;
                        for (i, child) in children.iter_mut().enumerate().take(n) {
                            let w = dag.words[p + 1 + i] as usize;
                            let ptr = below.svdag_nodes[below_index[w - below_start] as usize];
                            *child = (ptr, rows_below[ptr.node as usize]);
                        }
                        canonical_inner(mask, &children[..n], transforms, &coset.rows)
                    })
                    .collect();
                let last = batch[batch.len() - 1];
                progress.inc((last + 1 + dag.words[last].count_ones() as usize - batch[0]) as u64);
                for f in found {
                    let hash = FxBuildHasher.hash_one(f.key);
                    let existing = ids
                        .find(hash, |&i| level.inner_key(i as usize) == f.key)
                        .copied();
                    let node = existing.unwrap_or(level.stabilisers.len() as u32);
                    if existing.is_none() {
                        let mut mask = 0u8;
                        level.child_starts.push(level.children.len() as u32);
                        for (o, &k) in f.key.iter().enumerate() {
                            if k != 0 {
                                mask |= 1 << o;
                                level.children.push(TransformPointer {
                                    node: ((k >> 6) - 1) as u32,
                                    transform: Transform::from_index((k & 63) as usize)
                                        .expect("key holds a transform id"),
                                });
                            }
                        }
                        level.child_masks.push(mask);
                        level.stabilisers.push(f.stab);
                        rows_here.push(coset.row_of(f.stab));
                        ids.insert_unique(hash, node, |&i| {
                            FxBuildHasher.hash_one(level.inner_key(i as usize))
                        });
                    }
                    level.svdag_nodes.push(TransformPointer {
                        node,
                        transform: f.transform,
                    });
                }
            }
            levels.push(level);
            rows_below = rows_here;
            below_index = index;
            below_start = range.start;
        }
        CanonicalDag {
            resolution: dag.resolution,
            set,
            levels,
        }
    }

    /// Canonical node count per level, level 0 first.
    pub fn level_counts(&self) -> Vec<u64> {
        self.levels.iter().map(|l| l.len() as u64).collect()
    }

    /// The root as a transform pointer (`None` for an empty scene).
    pub fn root(&self) -> Option<TransformPointer> {
        self.levels.last()?.svdag_nodes.first().copied()
    }

    /// Whether the voxel at (x, y, z) is set, decoded through canonical nodes and transforms
    /// (a reference traversal: inverse-transforms the query point at every level).
    pub fn contains(&self, x: u32, y: u32, z: u32) -> bool {
        let Some(mut ptr) = self.root() else {
            return false;
        };
        if x >= self.resolution || y >= self.resolution || z >= self.resolution {
            return false;
        }
        let mut p = [x, y, z];
        let mut size = self.resolution;
        for l in (0..self.levels.len()).rev() {
            // The subtree is T(C): voxel p of it is voxel T⁻¹(p) of C.
            p = ptr.transform.inverse().apply_point(p, size);
            let level = &self.levels[l];
            if l == 0 {
                let [x, y, z] = p;
                let bit = crate::scene::morton::encode(x, y, z);
                return (level.leaves[ptr.node as usize] >> bit) & 1 == 1;
            }
            let half = size / 2;
            let o = ((p[0] / half) | (p[1] / half) << 1 | (p[2] / half) << 2) as usize;
            let mask = level.child_masks[ptr.node as usize];
            if (mask >> o) & 1 == 0 {
                return false;
            }
            let rank = (mask & ((1u16 << o) - 1) as u8).count_ones() as usize;
            ptr = level.node_children(ptr.node as usize)[rank];
            p = [p[0] % half, p[1] % half, p[2] % half];
            size = half;
        }
        false
    }
}

/// Unique node counts of one level under each compression scheme.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SymmetryLevelCounts {
    /// Level number, counted from the leaves.
    pub level: u32,
    /// Unique nodes of the SVDAG (no transforms).
    pub svdag: u64,
    /// SSVDAG as published (3 independent mirror-invariance bits).
    pub ssvdag: u64,
    /// Unique nodes up to the 8 mirrors (= SSVDAG with full invariance).
    pub s: u64,
    /// Unique nodes up to the 6 axis permutations.
    pub a: u64,
    /// Unique nodes up to all 48 transforms.
    pub sa: u64,
    /// Stored nodes of the S+A+T transform DAG (all 48 transforms plus destructive translations
    /// of 4^3, 8^3 and 16^3 subtrees; see `docs/translations.md`); `sat <= sa`.
    pub sat: u64,
}

/// Per-level unique counts for SVDAG, SSVDAG (3-bit), S, A, S+A and S+A+T, level 0 first.
pub fn symmetry_counts(dag: &Svdag) -> Vec<SymmetryLevelCounts> {
    symmetry_counts_with_progress(dag, &indicatif::ProgressBar::hidden())
}

/// [`symmetry_counts`] reporting the translation search on `progress`.
pub fn symmetry_counts_with_progress(
    dag: &Svdag,
    progress: &indicatif::ProgressBar,
) -> Vec<SymmetryLevelCounts> {
    analyze_symmetry(dag, progress).counts
}

/// The per-level counts together with the structures they were counted on, so that callers
/// that also encode (e.g. `voxdag stats`) run each search once.
pub struct SymmetryAnalysis {
    /// Per-level unique counts, level 0 first.
    pub counts: Vec<SymmetryLevelCounts>,
    /// The SSVDAG as published (3-bit invariance).
    pub ssvdag: super::Ssvdag,
    /// The S+A+T transform DAG.
    pub sat: super::TransformDag,
}

/// Builds the SSVDAG, the S, A and S+A canonical DAGs and the S+A+T transform DAG of `dag`,
/// reporting the translation search on `progress`.
pub fn analyze_symmetry(dag: &Svdag, progress: &indicatif::ProgressBar) -> SymmetryAnalysis {
    let svdag: Vec<u64> = dag.level_stats().iter().map(|l| l.svdag).collect();
    let ssvdag_dag = super::Ssvdag::build(dag, super::Invariance::Axes3);
    let ssvdag = ssvdag_dag.level_counts();
    let s = CanonicalDag::build(dag, TransformSet::Mirrors).level_counts();
    let a = CanonicalDag::build(dag, TransformSet::AxisPermutations).level_counts();
    let sa_dag = CanonicalDag::build(dag, TransformSet::All);
    let sa = sa_dag.level_counts();
    let sat_dag = super::TransformDag::from_canonical(sa_dag, true, progress);
    let sat = sat_dag.level_counts();
    let counts = (0..svdag.len())
        .map(|l| SymmetryLevelCounts {
            level: l as u32,
            svdag: svdag[l],
            ssvdag: ssvdag[l],
            s: s[l],
            a: a[l],
            sa: sa[l],
            sat: sat[l],
        })
        .collect();
    SymmetryAnalysis {
        counts,
        ssvdag: ssvdag_dag,
        sat: sat_dag,
    }
}
