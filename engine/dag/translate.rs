//! Destructive translations of small subtrees combined with the symmetry group (dissertation
//! §3.3.2): the S+A+T transform DAG.
//!
//! # What a pointer means
//! A [`TPointer`] `(node, transform T, translation t)` into a level whose cubes have side `s`
//! denotes the subtree `Tr_t(T(C))`, `C` the stored node: first the transform (see
//! `transform.rs`), then a *destructive* translation. Voxel `v` (in `0..s` per axis) of the
//! subtree is set iff `w = v - t` lies inside the cube and `C` has the voxel `T⁻¹(w)`. Voxels of
//! `T(C)` that the translation moves out of the cube are dropped; the vacated region is empty.
//! A decoder therefore does, per level: `p ← p - t` (outside the cube → empty), `p ← T⁻¹(p)`,
//! then descends into `C` (see [`TransformDag::contains`]). Translations are signed (`[i8; 3]`,
//! `|t_i| < s`); they are non-zero only in pointers into the levels `0..=MAX_TRANSLATION_LEVEL`
//! (4^3 leaves, 8^3 and 16^3 nodes).
//!
//! A transform applied to a translated subtree is again a translated subtree:
//! `T'(Tr_t(X)) = Tr_{L(t)}(T'(X))` with `L(t)_i = m_i ? -t[π_i] : t[π_i]` ([`apply_to_vector`]),
//! which is how a parent's child transform composes with a child's translation.
//!
//! # Construction
//! 1. Hierarchical canonicalization under the transform set ([`CanonicalDag`]): one node per
//!    orbit and level. Levels above `MAX_TRANSLATION_LEVEL` are kept as they are.
//! 2. Top-down over the translation levels (16^3, then 8^3, then 4^3): the *items* are the
//!    canonical nodes referenced by the stored nodes of the level above (nodes that lose all
//!    parents disappear). For every item `B` the search finds the best *parent* `A` with
//!    `B = Tr_t(T(A))`, `T` in the set: items are ranked by occupancy (voxel count ascending,
//!    ties by descending canonical id) and the parent is the matching item of the highest rank
//!    (the most voxels); `B` itself (identity, `t = 0`) is always a candidate. Among the pointers
//!    into that parent the smallest `|t|_1`, then the smallest transform id, wins.
//! 3. Single-parent dependency graph: every item that is some item's parent (itself included)
//!    is stored; the others become `(parent, T, t)`. A stored node is never itself translated, so
//!    a decoder follows at most one translation per level. Where a chain `B → A → A'` exists,
//!    `A` is stored as a duplicate of what `A'` could produce (destructive translations do not
//!    compose, so the chain cannot be shortened).
//!
//! # The search (O(N·V))
//! Per direction group `d` (one sign per axis), the hash of the region of a grid from voxel `q`
//! toward `d` is `H_d(q) = Σ a^{u_x} b^{u_y} c^{u_z}` over the region's voxels, `u` = distance
//! from `q` along `d` (wrapping `u64`, random odd bases). It is computed separably, one Horner
//! pass per axis (`H(x) = v(x) + a·H(x ∓ 1)`), and so are the region voxel counts. Because
//! empty space far from `q` adds nothing, the hash of a region equals the hash of the same voxels
//! after a translation that keeps them inside; and because `u` is measured along `d`, the hash
//! of a mirrored grid in the mirrored direction is the same, so 8 directions cover the 8 mirrors.
//! - Table: for every item `B` and every axis permutation `P` of the set, the hash of all of
//!   `P(B)` from each of its 8 bounding-box corners (its "occupied extremes"): 48 keys for S+A.
//! - Lookups: every item `A` computes its 8 direction grids once and looks up only the *tight*
//!   voxels (where the region's bounding box starts at `q`: every distinct region once). A hit
//!   `(B, P, d_B)` gives the mirror `m = d ⊕ d_B`, the shift (corner of `P(B)` minus mirrored
//!   `q`), `T = P⁻¹ ∘ M_m` and `t = L_{P⁻¹}(shift)`; the region count at the window origin must
//!   equal `|B|` and the match is then confirmed voxel by voxel, so hash collisions never
//!   produce a wrong pointer.

use std::sync::atomic::{AtomicU64, Ordering};

use indicatif::ProgressBar;
use rayon::prelude::*;

use super::canonical::CanonicalDag;
use super::transform::{Transform, TransformSet};
use super::Svdag;
use crate::scene::{morton, Voxels};

/// Highest level (0 = 4^3 leaves) whose nodes may be translated: 2, i.e. 16^3 nodes.
pub const MAX_TRANSLATION_LEVEL: u32 = 2;

/// A child pointer of a [`TransformDag`]: `Tr_translation(transform(node))` (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct TPointer {
    /// Stored node index within the level below (or the root level for the root pointer).
    pub node: u32,
    /// Transform applied first (one of the transform set).
    pub transform: Transform,
    /// Destructive translation applied after the transform, per axis, `|t| < side`.
    pub translation: [i8; 3],
}

impl TPointer {
    /// Whether the translation is non-zero.
    pub fn has_translation(&self) -> bool {
        self.translation != [0; 3]
    }
}

/// The stored nodes of one level of a [`TransformDag`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TLevel {
    /// Level 0 only: the stored 4^3 leaf masks (bit `morton(x, y, z)`).
    pub leaves: Vec<u64>,
    /// Inner levels: child mask of each stored node (bit `o` = octant `x | y<<1 | z<<2`).
    pub child_masks: Vec<u8>,
    /// Inner levels: index of each node's first child in `children`.
    pub child_starts: Vec<u32>,
    /// Inner levels: children of all nodes, ascending octant order, into the level below.
    pub children: Vec<TPointer>,
    /// Canonical node (index into `CanonicalDag::levels[l]`) that each stored node is.
    pub canonical: Vec<u32>,
}

impl TLevel {
    /// Number of stored nodes.
    pub fn len(&self) -> usize {
        self.canonical.len()
    }

    /// Whether the level stores no node.
    pub fn is_empty(&self) -> bool {
        self.canonical.is_empty()
    }

    /// Children of inner node `i`, ascending octant order.
    pub fn node_children(&self, i: usize) -> &[TPointer] {
        let start = self.child_starts[i] as usize;
        let n = self.child_masks[i].count_ones() as usize;
        &self.children[start..start + n]
    }
}

/// An SVDAG rewritten with transform + translation pointers (S+A+T when built with
/// `TransformSet::All` and translations).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TransformDag {
    /// Grid side length.
    pub resolution: u32,
    /// Transforms allowed in pointers.
    pub set: TransformSet,
    /// Whether translations were searched (levels `0..=MAX_TRANSLATION_LEVEL`).
    pub translations: bool,
    /// Levels bottom-up (0 = 4^3 leaves); the last is the root level.
    pub levels: Vec<TLevel>,
    /// The root pointer into the last level (`None` for an empty scene).
    pub root: Option<TPointer>,
}

/// Builds the transform DAG of a (valid) SVDAG: canonicalization under `set`, then, when
/// `translations`, the translation search on the 4^3, 8^3 and 16^3 levels. (`voxdag build`
/// runs the two steps itself, with progress bars and the SVDAG dropped in between.)
pub fn build_transform_dag(dag: &Svdag, set: TransformSet, translations: bool) -> TransformDag {
    let canonical = CanonicalDag::build(dag, set);
    TransformDag::from_canonical(canonical, translations, &ProgressBar::hidden())
}

/// `L(v)`: how transform `t` acts on a translation vector (`t(x + v) = t(x) + L(v)`).
pub fn apply_to_vector<T: Copy + std::ops::Neg<Output = T>>(t: Transform, v: [T; 3]) -> [T; 3] {
    let perm = t.permutation();
    std::array::from_fn(|i| {
        let c = v[perm[i] as usize];
        if (t.mirror() >> i) & 1 == 1 {
            -c
        } else {
            c
        }
    })
}

/// `outer` applied to the subtree `p` points to: `outer(Tr_t(T(C))) = Tr_{L(t)}((outer∘T)(C))`.
pub fn compose_pointer(outer: Transform, p: TPointer) -> TPointer {
    TPointer {
        node: p.node,
        transform: outer.compose(p.transform),
        translation: apply_to_vector(outer, p.translation),
    }
}

impl TransformDag {
    /// Builds the transform DAG from a canonical DAG (its transform set is kept); searches
    /// translations when `translations`. Consumes the canonical DAG level by level, so the two
    /// are never both whole in memory.
    pub fn from_canonical(
        c: CanonicalDag,
        translations: bool,
        progress: &ProgressBar,
    ) -> TransformDag {
        let nlev = c.levels.len();
        let Some(root) = c.root() else {
            return TransformDag {
                resolution: c.resolution,
                set: c.set,
                translations,
                levels: vec![TLevel::default(); nlev],
                root: None,
            };
        };
        let top = nlev - 1;
        // For every level: the stored canonical ids, and for every canonical id the pointer
        // (into stored indices) that reproduces it.
        let mut stored: Vec<Vec<u32>> = vec![Vec::new(); nlev];
        let mut maps: Vec<Vec<TPointer>> = vec![Vec::new(); nlev];
        for l in (0..nlev).rev() {
            let count = c.levels[l].len();
            if translations && l <= MAX_TRANSLATION_LEVEL as usize {
                let items: Vec<u32> = if l == top {
                    vec![root.node]
                } else {
                    let above = &c.levels[l + 1];
                    let mut seen = vec![false; count];
                    for &s in &stored[l + 1] {
                        for ch in above.node_children(s as usize) {
                            seen[ch.node as usize] = true;
                        }
                    }
                    (0..count as u32).filter(|&i| seen[i as usize]).collect()
                };
                let parents = search_level(&c, l, &items, progress);
                let mut is_parent = vec![false; items.len()];
                for p in &parents {
                    is_parent[p.0 as usize] = true;
                }
                let mut stored_index = vec![u32::MAX; items.len()];
                for (i, &item) in items.iter().enumerate() {
                    if is_parent[i] {
                        stored_index[i] = stored[l].len() as u32;
                        stored[l].push(item);
                    }
                }
                let mut map = vec![TPointer::default(); count];
                for (i, &item) in items.iter().enumerate() {
                    let (parent, transform, translation) = parents[i];
                    map[item as usize] = if is_parent[i] {
                        TPointer {
                            node: stored_index[i],
                            ..TPointer::default()
                        }
                    } else {
                        TPointer {
                            node: stored_index[parent as usize],
                            transform,
                            translation,
                        }
                    };
                }
                maps[l] = map;
            } else {
                stored[l] = (0..count as u32).collect();
                maps[l] = (0..count as u32)
                    .map(|node| TPointer {
                        node,
                        ..TPointer::default()
                    })
                    .collect();
            }
        }
        let (resolution, set) = (c.resolution, c.set);
        let mut levels = Vec::with_capacity(nlev);
        for (l, src) in c.levels.into_iter().enumerate() {
            let mut level = TLevel::default();
            if l == 0 {
                level.leaves = stored[l].iter().map(|&i| src.leaves[i as usize]).collect();
            } else {
                for &i in &stored[l] {
                    level.child_starts.push(level.children.len() as u32);
                    level.child_masks.push(src.child_masks[i as usize]);
                    for ch in src.node_children(i as usize) {
                        let below = maps[l - 1][ch.node as usize];
                        level.children.push(compose_pointer(ch.transform, below));
                    }
                }
                // Only the root reads the top level's map; this level's map is read next.
                maps[l - 1] = Vec::new();
            }
            level.canonical = std::mem::take(&mut stored[l]);
            levels.push(level);
        }
        let root = compose_pointer(root.transform, maps[top][root.node as usize]);
        TransformDag {
            resolution,
            set,
            translations,
            levels,
            root: Some(root),
        }
    }

    /// Stored node count per level, level 0 first.
    pub fn level_counts(&self) -> Vec<u64> {
        self.levels.iter().map(|l| l.len() as u64).collect()
    }

    /// Number of child pointers (and the root pointer) with a non-zero translation.
    pub fn translated_pointers(&self) -> u64 {
        let inner: usize = self
            .levels
            .iter()
            .map(|l| l.children.iter().filter(|p| p.has_translation()).count())
            .sum();
        inner as u64 + self.root.is_some_and(|r| r.has_translation()) as u64
    }

    /// Whether voxel (x, y, z) is set: the reference decoder (per level `p ← T⁻¹(p - t)`).
    pub fn contains(&self, x: u32, y: u32, z: u32) -> bool {
        let Some(mut ptr) = self.root else {
            return false;
        };
        let n = self.resolution as i64;
        let mut p = [x as i64, y as i64, z as i64];
        if p.iter().any(|&v| v >= n) {
            return false;
        }
        let mut size = n;
        for l in (0..self.levels.len()).rev() {
            for (v, t) in p.iter_mut().zip(ptr.translation) {
                *v -= t as i64;
            }
            if p.iter().any(|&v| v < 0 || v >= size) {
                return false;
            }
            let q = ptr
                .transform
                .inverse()
                .apply_point(p.map(|v| v as u32), size as u32);
            let level = &self.levels[l];
            if l == 0 {
                let bit = morton::encode(q[0], q[1], q[2]);
                return (level.leaves[ptr.node as usize] >> bit) & 1 == 1;
            }
            let half = (size / 2) as u32;
            let o = ((q[0] / half) | (q[1] / half) << 1 | (q[2] / half) << 2) as usize;
            let mask = level.child_masks[ptr.node as usize];
            if (mask >> o) & 1 == 0 {
                return false;
            }
            let rank = (mask & ((1u16 << o) - 1) as u8).count_ones() as usize;
            ptr = level.node_children(ptr.node as usize)[rank];
            p = q.map(|v| (v % half) as i64);
            size = half as i64;
        }
        false
    }

    /// Decodes every voxel (Morton codes ascending, no colours).
    pub fn to_voxels(&self) -> Voxels {
        let mut codes = Vec::new();
        if let Some(root) = self.root {
            let n = self.resolution as i64;
            let frame = Frame {
                off: [0; 3],
                sgn: [1; 3],
                perm: [0, 1, 2],
            };
            let clip = ([0i64; 3], [n - 1; 3]);
            self.decode(self.levels.len() - 1, root, frame, clip, &mut codes);
        }
        codes.sort_unstable();
        codes.dedup();
        Voxels {
            resolution: self.resolution,
            codes,
            colors: Vec::new(),
        }
    }

    /// Emits the voxels of the subtree `ptr` (level `l`) whose cube is placed by `frame`,
    /// clipped to `clip` (inclusive world box: the intersection of all enclosing cubes).
    fn decode(
        &self,
        l: usize,
        ptr: TPointer,
        frame: Frame,
        clip: ([i64; 3], [i64; 3]),
        out: &mut Vec<u64>,
    ) {
        let size = 4i64 << l;
        let cube = frame.bounds(size);
        let clip = (
            std::array::from_fn(|i| clip.0[i].max(cube.0[i])),
            std::array::from_fn(|i| clip.1[i].min(cube.1[i])),
        );
        if (0..3).any(|i| clip.0[i] > clip.1[i]) {
            return;
        }
        let inner = frame.then_pointer(ptr.transform, ptr.translation, size);
        let level = &self.levels[l];
        if l == 0 {
            let mut mask = level.leaves[ptr.node as usize];
            while mask != 0 {
                let [x, y, z] = morton::decode(mask.trailing_zeros() as u64);
                mask &= mask - 1;
                let w = inner.apply([x as i64, y as i64, z as i64]);
                if (0..3).all(|i| w[i] >= clip.0[i] && w[i] <= clip.1[i]) {
                    out.push(morton::encode(w[0] as u32, w[1] as u32, w[2] as u32));
                }
            }
            return;
        }
        let half = size / 2;
        let mask = level.child_masks[ptr.node as usize];
        let mut k = 0;
        for o in 0..8 {
            if (mask >> o) & 1 == 1 {
                let child = level.node_children(ptr.node as usize)[k];
                k += 1;
                let offset = [o & 1, (o >> 1) & 1, o >> 2].map(|b| b as i64 * half);
                self.decode(l - 1, child, inner.then_offset(offset), clip, out);
            }
        }
    }
}

/// An axis-aligned affine map `world_i = off_i + sgn_i · v[perm_i]` (local cube → world).
#[derive(Clone, Copy, Debug)]
struct Frame {
    off: [i64; 3],
    sgn: [i64; 3],
    perm: [usize; 3],
}

impl Frame {
    fn apply(&self, v: [i64; 3]) -> [i64; 3] {
        std::array::from_fn(|i| self.off[i] + self.sgn[i] * v[self.perm[i]])
    }

    /// Inclusive world bounds of the local cube `[0, size)^3`.
    fn bounds(&self, size: i64) -> ([i64; 3], [i64; 3]) {
        let a = self.apply([0; 3]);
        let b = self.apply([size - 1; 3]);
        (
            std::array::from_fn(|i| a[i].min(b[i])),
            std::array::from_fn(|i| a[i].max(b[i])),
        )
    }

    /// The map of the pointed-to node's local frame: `v = T(u) + t`, then `self`.
    fn then_pointer(&self, t: Transform, tr: [i8; 3], size: i64) -> Frame {
        let perm = t.permutation();
        let mut out = *self;
        for i in 0..3 {
            let j = self.perm[i];
            let mirrored = (t.mirror() >> j) & 1 == 1;
            out.perm[i] = perm[j] as usize;
            out.off[i] =
                self.off[i] + self.sgn[i] * (tr[j] as i64 + if mirrored { size - 1 } else { 0 });
            out.sgn[i] = if mirrored { -self.sgn[i] } else { self.sgn[i] };
        }
        out
    }

    /// The map of a child cube at local offset `o`: `v = w + o`, then `self`.
    fn then_offset(&self, o: [i64; 3]) -> Frame {
        let mut out = *self;
        for i in 0..3 {
            out.off[i] = self.off[i] + self.sgn[i] * o[self.perm[i]];
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// The translation search.

/// Morton-ordered bit grid of a node of side 4, 8 or 16 (the first `side^3 / 64` words used).
type Grid = [u64; 64];

/// Random odd bases of the polynomial region hash, one per axis.
const BASES: [u64; 3] = [
    0x9e37_79b9_7f4a_7c15,
    0xc2b2_ae3d_27d4_eb4f,
    0x1656_67b1_9e37_79f9,
];

/// Writes the voxels of canonical node `node` of level `level`, transformed by `t`, into `out`
/// (Morton order; `out.len()` = words of the level).
fn fill_grid(c: &CanonicalDag, level: usize, node: u32, t: Transform, out: &mut [u64]) {
    let lv = &c.levels[level];
    if level == 0 {
        out[0] = t.apply_leaf(lv.leaves[node as usize]);
        return;
    }
    let wpc = out.len() / 8;
    let mask = lv.child_masks[node as usize];
    let kids = lv.node_children(node as usize);
    let mut k = 0;
    for o in 0..8 {
        if (mask >> o) & 1 == 1 {
            let ch = kids[k];
            k += 1;
            let to = t.apply_octant(o);
            fill_grid(
                c,
                level - 1,
                ch.node,
                t.compose(ch.transform),
                &mut out[to * wpc..(to + 1) * wpc],
            );
        } else {
            let to = t.apply_octant(o);
            out[to * wpc..(to + 1) * wpc].fill(0);
        }
    }
}

/// Per-level constants of the search.
struct Geometry {
    /// Side of the level's cubes (4, 8 or 16).
    n: usize,
    /// Words of a grid.
    words: usize,
    /// Morton index → `[x, y, z]`.
    coords: Vec<[u8; 3]>,
    /// `BASES[axis]^k` for `k < n`.
    powers: [Vec<u64>; 3],
}

impl Geometry {
    fn new(level: usize) -> Geometry {
        let n = 4usize << level;
        let cells = n * n * n;
        let coords: Vec<[u8; 3]> = (0..cells as u64)
            .map(|m| morton::decode(m).map(|v| v as u8))
            .collect();
        let powers = BASES.map(|b| {
            let mut v = Vec::with_capacity(n);
            let mut p = 1u64;
            for _ in 0..n {
                v.push(p);
                p = p.wrapping_mul(b);
            }
            v
        });
        Geometry {
            n,
            words: cells / 64,
            coords,
            powers,
        }
    }
}

/// What the table needs of an item `B`.
#[derive(Clone, Copy, Default)]
struct ItemInfo {
    voxels: u16,
    lo: [u8; 3],
    hi: [u8; 3],
}

/// One table entry: item `B` under permutation `(perm_dir & !LAST) >> 3` of the set, keyed from
/// its bounding-box corner toward direction `perm_dir & 7`, with the item's info inline so that a
/// candidate costs no further random access.
#[derive(Clone, Copy, Default)]
struct Entry {
    item: u32,
    perm_dir: u8,
    /// Per axis of `P(B)`: the distance of the keyed corner from the cube face behind it. A
    /// match moves the region's cut back by exactly this much, so it must not exceed the gap
    /// behind the region's cut (see `gaps`).
    offset: [u8; 3],
    info: ItemInfo,
}

impl Entry {
    fn new(item: u32, perm_dir: u8, info: ItemInfo, perms: &[usize], n: usize) -> Entry {
        let order = super::transform::PERMUTATIONS[perms[(perm_dir >> 3) as usize]];
        let offset = std::array::from_fn(|ax| {
            let j = order[ax] as usize;
            if (perm_dir >> ax) & 1 == 0 {
                info.lo[j]
            } else {
                (n - 1) as u8 - info.hi[j]
            }
        });
        Entry {
            item,
            perm_dir,
            offset,
            info,
        }
    }

    fn max_offset(&self) -> u8 {
        self.offset[0].max(self.offset[1]).max(self.offset[2])
    }
}

/// Hash table from region hash to the group of entries with that key. Keys are deduplicated
/// before insertion: small items share their shapes (every single-voxel item has the key 1 in
/// all 48 entries), and storing them one slot each made long linear-probing clusters that every
/// lookup landing nearby had to walk. Open addressing with linear probing over one `u64` per
/// distinct key, chosen by the high bits of the hash: high half the tag (bit 0 set: occupied;
/// bit 1: the group has an entry with all offsets zero; bits 2..32: the hash's low bits), low
/// half the index of the group's first entry (its last has [`LAST`] set). Only the tag is
/// compared: a lookup visits every group of its probe run with the same tag. Another key's group
/// is harmless (its candidates fail the count, window and voxel checks), and visiting all of
/// them never misses the right one (returning the first tag match lost a match on dragon 128).
/// A hit therefore costs one slot and one run of entries, no key or group-start array. Within a
/// group, entries are sorted by their largest offset, so that a lookup stops at the first entry
/// that no gap can accommodate.
struct Table {
    shift: u32,
    slots: Vec<u64>,
    entries: Vec<Entry>,
    /// Per group: its key and the index of its first entry.
    keys: Vec<u64>,
    starts: Vec<u32>,
    /// The groups with an open entry at the last [`Table::refilter`], ascending.
    live: Vec<u32>,
    /// Keys of groups with an entry whose offsets are all zero: the only entries a region with
    /// zero gaps on every axis can match (most regions).
    flush: KeyFilter,
    /// Every key.
    any: KeyFilter,
}

/// Bit of `Entry::perm_dir` marking the last entry of a group.
const LAST: u8 = 0x80;

/// Tag bit of a slot whose group has an entry with all offsets zero.
const FLUSH: u64 = 2;

impl Table {
    /// Sorts `(key, entry)` pairs into the order [`Table::build`] needs: by key, then largest
    /// offset; the rest makes the groups the same for any thread count.
    fn sort_pairs(pairs: &mut [(u64, Entry)]) {
        pairs.par_sort_unstable_by_key(|&(k, e)| (k, e.max_offset(), e.item, e.perm_dir));
    }

    /// The table of `(key, entry)` pairs sorted by [`Table::sort_pairs`], every entry open.
    fn build(pairs: Vec<(u64, Entry)>) -> Table {
        let starts: Vec<u32> = (0..pairs.len())
            .filter(|&i| i == 0 || pairs[i - 1].0 != pairs[i].0)
            .map(|i| i as u32)
            .collect();
        let cap = (starts.len() * 2).next_power_of_two().max(64);
        let mut slots = huge_zeroed(cap);
        let (shift, mask) = (64 - cap.trailing_zeros(), cap - 1);
        for &start in &starts {
            let (key, entry) = pairs[start as usize];
            // Entries are sorted by their largest offset within a group: the first tells.
            let flush = entry.max_offset() == 0;
            let tag = Self::tag(key) | if flush { FLUSH } else { 0 };
            let mut s = (key >> shift) as usize;
            while slots[s] != 0 {
                s = (s + 1) & mask;
            }
            slots[s] = tag << 32 | start as u64;
        }
        let keys: Vec<u64> = starts.iter().map(|&i| pairs[i as usize].0).collect();
        let entries = (0..pairs.len())
            .into_par_iter()
            .map(|i| {
                let mut entry = pairs[i].1;
                if pairs.get(i + 1).is_none_or(|next| next.0 != pairs[i].0) {
                    entry.perm_dir |= LAST;
                }
                entry
            })
            .collect();
        drop(pairs);
        let mut table = Table {
            shift,
            slots,
            entries,
            live: (0..keys.len() as u32).collect(),
            keys,
            starts,
            flush: KeyFilter::new(0),
            any: KeyFilter::new(0),
        };
        table.refilter(|_| true);
        table
    }

    /// Rebuilds the key filters from the entries whose item is still `open`: a group without
    /// one is left out of both filters (and out of every later rebuild: items never reopen), a
    /// group without an open zero-offset entry out of `flush`. Lookups of closed items' keys
    /// then stop at the cache-resident filter.
    fn refilter(&mut self, open: impl Fn(u32) -> bool + Sync) {
        const ANY: u8 = 1;
        const FLUSH_OPEN: u8 = 2;
        let entries = &self.entries;
        let starts = &self.starts;
        let flags: Vec<u8> = self
            .live
            .par_iter()
            .map(|&g| {
                let end = starts
                    .get(g as usize + 1)
                    .map_or(entries.len(), |&e| e as usize);
                entries[starts[g as usize] as usize..end]
                    .iter()
                    .filter(|e| open(e.item))
                    .fold(0, |f, e| {
                        f | ANY | if e.max_offset() == 0 { FLUSH_OPEN } else { 0 }
                    })
            })
            .collect();
        let count = |bit: u8| flags.iter().filter(|&&f| f & bit != 0).count();
        self.any = KeyFilter::new(count(ANY));
        self.flush = KeyFilter::new(count(FLUSH_OPEN));
        // Groups are in key order and the filters pick a word by the key's top bits, so these
        // writes run through the filters in order.
        for (&g, &f) in self.live.iter().zip(&flags) {
            let key = self.keys[g as usize];
            if f & ANY != 0 {
                self.any.insert(key);
            }
            if f & FLUSH_OPEN != 0 {
                self.flush.insert(key);
            }
        }
        let mut flags = flags.into_iter();
        self.live.retain(|_| flags.next().is_some_and(|f| f != 0));
    }

    /// The tag of `hash` without the [`FLUSH`] bit (never 0).
    #[inline]
    fn tag(hash: u64) -> u64 {
        (hash as u32 & !3 | 1) as u64
    }

    /// The first slot probed for `hash` (0: certainly absent).
    #[inline]
    fn first(&self, hash: u64) -> u64 {
        self.slots[(hash >> self.shift) as usize]
    }

    /// Calls `f` with the entries of every group whose tag equals that of `hash` (with an
    /// all-zero-offset entry when `flush_only`); the group of `hash` itself is among them.
    #[inline]
    fn for_each_group(&self, hash: u64, flush_only: bool, mut f: impl FnMut(GroupIter<'_>)) {
        let mask = self.slots.len() - 1;
        let tag = Self::tag(hash);
        let need = if flush_only { FLUSH } else { 0 };
        let mut s = (hash >> self.shift) as usize;
        loop {
            let v = self.slots[s];
            if v == 0 {
                return;
            }
            let t = v >> 32;
            if t & !FLUSH == tag && t & need == need {
                f(GroupIter {
                    entries: &self.entries,
                    next: v as u32 as usize,
                    done: false,
                });
            }
            s = (s + 1) & mask;
        }
    }
}

/// The entries of one group, in table order.
struct GroupIter<'a> {
    entries: &'a [Entry],
    next: usize,
    done: bool,
}

impl<'a> Iterator for GroupIter<'a> {
    type Item = &'a Entry;

    #[inline]
    fn next(&mut self) -> Option<&'a Entry> {
        if self.done {
            return None;
        }
        let e = &self.entries[self.next];
        self.next += 1;
        self.done = e.perm_dir & LAST != 0;
        Some(e)
    }
}

/// A blocked Bloom filter of table keys: one 64-bit word per key with three bits set, 16 to 32
/// bits per key (0.4% of the absent keys pass at bunny 2048; with 4 to 8 bits and two bits set,
/// 5 to 16% went on to probe the slot array). It is 4 to 8 times smaller than the slot array,
/// so most lookups (whose keys are absent) are answered from the cache instead of missing in
/// memory on the table.
struct KeyFilter {
    shift: u32,
    words: Vec<u64>,
}

impl KeyFilter {
    /// An empty filter sized for `keys` keys.
    fn new(keys: usize) -> KeyFilter {
        let words = (keys / 4).next_power_of_two().max(8);
        KeyFilter {
            shift: 64 - words.trailing_zeros(),
            words: huge_zeroed(words),
        }
    }

    /// The word index (the hash's top bits, so that keys inserted in ascending order write
    /// the words in order) and the three bits of `hash` (from a remix of the whole hash: the
    /// table uses the top bits for the slot and the low bits for the fingerprint).
    #[inline]
    fn place(&self, hash: u64) -> (usize, u64) {
        let h = (hash ^ hash >> 29).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        let bits = 1u64 << (h & 63) | 1u64 << ((h >> 6) & 63) | 1u64 << ((h >> 12) & 63);
        ((hash >> self.shift) as usize, bits)
    }

    fn insert(&mut self, hash: u64) {
        let (w, bits) = self.place(hash);
        self.words[w] |= bits;
    }

    /// False only if `hash` was never inserted (the search reads the words in a batch instead).
    #[cfg(test)]
    fn may_contain(&self, hash: u64) -> bool {
        let (w, bits) = self.place(hash);
        self.words[w] & bits == bits
    }
}

/// A zeroed vector whose pages are not yet touched, marked for transparent huge pages where the
/// OS supports it: the search reads the table and its filters at random, and with 4 KiB pages
/// nearly every such read of a large table also misses the TLB.
fn huge_zeroed(len: usize) -> Vec<u64> {
    let v = vec![0u64; len];
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let start = (v.as_ptr() as usize).next_multiple_of(HUGE);
        let end = (v.as_ptr() as usize + len * 8) / HUGE * HUGE;
        if end > start {
            // SAFETY: the range lies inside `v`'s allocation; the advice changes no contents.
            // A refusal (no THP support) only leaves the default pages.
            unsafe { libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE) };
        }
    }
    v
}

/// Packs a parent candidate so that a larger value is preferred: parent rank, then smaller
/// `|t|_1`, then smaller transform id; the low 15 bits hold the translation.
fn pack(rank: u32, t: Transform, tr: [i8; 3]) -> u64 {
    let l1: u64 = tr.iter().map(|v| v.unsigned_abs() as u64).sum();
    let enc = tr.iter().enumerate().fold(0u64, |a, (i, &v)| {
        a | (((v as i64 + 16) as u64 & 31) << (5 * i))
    });
    (rank as u64) << 32 | (63 - l1) << 26 | (63 - t.index() as u64) << 20 | enc
}

fn unpack(key: u64) -> (u32, Transform, [i8; 3]) {
    let t = Transform::from_index(63 - ((key >> 20) & 63) as usize).unwrap_or_default();
    let tr = std::array::from_fn(|i| (((key >> (5 * i)) & 31) as i64 - 16) as i8);
    ((key >> 32) as u32, t, tr)
}

/// Bit of a kept tight cell index marking a region with no gap on any axis.
const FLUSH_CELL: u32 = 1 << 31;

/// Scratch buffers of one worker.
struct Scratch {
    grid: Grid,
    /// Tight cells of the current direction, and the first table slot of each.
    tight: Vec<u32>,
    first: Vec<u64>,
    /// Per depth of the direction tree (x, y, z pass): hashes and counts.
    hash: [Vec<u64>; 4],
    count: [Vec<u16>; 4],
}

impl Scratch {
    fn new(cells: usize) -> Scratch {
        Scratch {
            grid: [0; 64],
            tight: Vec::with_capacity(cells),
            first: Vec::with_capacity(cells),
            hash: std::array::from_fn(|_| vec![0; cells]),
            count: std::array::from_fn(|_| vec![0; cells]),
        }
    }
}

/// One separable pass along `axis` over a dense box of `dims` cells (index `x + dx (y + dy z)`):
/// suffix (or prefix when `negative`) Horner sums of hashes and plain sums of counts, from `src`
/// into `dst`. The position along the axis is the outer loop and the independent lanes the inner
/// one, so that the multiply-add chains of different lanes overlap instead of running one
/// 16-step chain after another. Where the CPU has AVX-512 (DQ: 64-bit vector multiplies) the
/// same code runs compiled for it, eight lanes per instruction.
fn pass(
    dims: [usize; 3],
    src: (&[u64], &[u16]),
    dst: (&mut [u64], &mut [u16]),
    axis: usize,
    negative: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512dq") {
        // SAFETY: the CPU has the features `pass_avx512` is compiled for.
        return unsafe { pass_avx512(dims, src, dst, axis, negative) };
    }
    pass_lanes(dims, src, dst, axis, negative)
}

/// [`pass_lanes`] compiled for AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512bw,avx512vl")]
unsafe fn pass_avx512(
    dims: [usize; 3],
    src: (&[u64], &[u16]),
    dst: (&mut [u64], &mut [u16]),
    axis: usize,
    negative: bool,
) {
    pass_lanes(dims, src, dst, axis, negative)
}

/// The body of [`pass`].
#[inline(always)]
fn pass_lanes(
    dims: [usize; 3],
    (sh, sc): (&[u64], &[u16]),
    (dh, dc): (&mut [u64], &mut [u16]),
    axis: usize,
    negative: bool,
) {
    let [dx, dy, dz] = dims;
    let len = dims[axis];
    let stride = [1, dx, dx * dy][axis];
    // (outer planes, their stride, lanes per plane, lane stride).
    let (planes, plane_stride, lanes, lane_stride) = match axis {
        0 => (dz, dx * dy, dy, dx),
        1 => (dz, dx * dy, dx, 1),
        _ => (dy, dx, dx, 1),
    };
    let base = BASES[axis];
    for plane in 0..planes {
        for step in 0..len {
            let k = if negative { step } else { len - 1 - step };
            let row = plane * plane_stride + k * stride;
            if step == 0 {
                for l in 0..lanes {
                    let i = row + l * lane_stride;
                    dh[i] = sh[i];
                    dc[i] = sc[i];
                }
            } else if lane_stride == 1 {
                // Contiguous lanes: slices without bounds checks, so the loop vectorizes.
                let prev = if negative { row - stride } else { row + stride };
                let (cur_h, prev_h) = row_and_previous(dh, row, prev, lanes);
                let lane_h = cur_h.iter_mut().zip(&sh[row..row + lanes]).zip(prev_h);
                for ((d, &s), &p) in lane_h {
                    *d = s.wrapping_add(base.wrapping_mul(p));
                }
                let (cur_c, prev_c) = row_and_previous(dc, row, prev, lanes);
                for ((d, &s), &p) in cur_c.iter_mut().zip(&sc[row..row + lanes]).zip(prev_c) {
                    *d = s + p;
                }
            } else {
                let prev = if negative { row - stride } else { row + stride };
                for l in 0..lanes {
                    let i = row + l * lane_stride;
                    let p = prev + l * lane_stride;
                    dh[i] = sh[i].wrapping_add(base.wrapping_mul(dh[p]));
                    dc[i] = sc[i] + dc[p];
                }
            }
        }
    }
}

/// The `lanes` cells from `row` (written) and from `prev` (read) of one array; the two ranges
/// do not overlap.
fn row_and_previous<T>(v: &mut [T], row: usize, prev: usize, lanes: usize) -> (&mut [T], &[T]) {
    if prev < row {
        let (before, from_row) = v.split_at_mut(row);
        (&mut from_row[..lanes], &before[prev..prev + lanes])
    } else {
        let (before, from_prev) = v.split_at_mut(prev);
        (&mut before[row..row + lanes], &from_prev[..lanes])
    }
}

/// Calls `f(direction, hashes, counts)` for the 8 direction groups of the dense box held in
/// `hash[0]` / `count[0]` (direction bit `i` set = toward negative axis `i`).
fn for_each_direction(
    dims: [usize; 3],
    hash: &mut [Vec<u64>; 4],
    count: &mut [Vec<u16>; 4],
    mut f: impl FnMut(usize, &[u64], &[u16]),
) {
    let cells = dims[0] * dims[1] * dims[2];
    let [h0, h1, h2, h3] = hash;
    let [c0, c1, c2, c3] = count;
    let (h0, h1, h2, h3) = (
        &h0[..cells],
        &mut h1[..cells],
        &mut h2[..cells],
        &mut h3[..cells],
    );
    let (c0, c1, c2, c3) = (
        &c0[..cells],
        &mut c1[..cells],
        &mut c2[..cells],
        &mut c3[..cells],
    );
    for dx in 0..2 {
        pass(dims, (h0, c0), (h1, c1), 0, dx == 1);
        for dy in 0..2 {
            pass(dims, (h1, c1), (h2, c2), 1, dy == 1);
            for dz in 0..2 {
                pass(dims, (h2, c2), (h3, c3), 2, dz == 1);
                f(dx | dy << 1 | dz << 2, h3, c3);
            }
        }
    }
}

/// The tight cells of direction `d` in the dense box `bx` (grid side `n`): non-empty regions
/// whose slab through the cell is non-empty on every axis (the region's bounding box starts
/// there), i.e. every distinct region once. A cell whose region has no gap on any axis (see
/// [`gaps`]; read here from the neighbours behind the cut) carries [`FLUSH_CELL`].
fn collect_tight(bx: &DenseBox, n: usize, d: usize, count: &[u16], out: &mut Vec<u32>) {
    out.clear();
    let [dx, dy, dz] = bx.dims;
    let neg = [d & 1 == 1, (d >> 1) & 1 == 1, (d >> 2) & 1 == 1];
    // The neighbour toward the inside of the region along an axis of `len` cells, if any.
    let next = |v: usize, len: usize, negative: bool| -> Option<usize> {
        if negative {
            v.checked_sub(1)
        } else {
            Some(v + 1).filter(|&w| w < len)
        }
    };
    // The neighbour behind the cut, or `Err(flush)` at the box's end: the gap is zero there
    // exactly when the box touches the cube face.
    let back = |v: usize, ax: usize| -> Result<usize, bool> {
        if neg[ax] {
            if v + 1 == bx.dims[ax] {
                Err(bx.lo[ax] + bx.dims[ax] == n)
            } else {
                Ok(v + 1)
            }
        } else if v == 0 {
            Err(bx.lo[ax] == 0)
        } else {
            Ok(v - 1)
        }
    };
    for z in 0..dz {
        let nz = next(z, dz, neg[2]);
        let bz = back(z, 2);
        for y in 0..dy {
            let r = dx * (y + dy * z);
            let row = &count[r..r + dx];
            let ny = next(y, dy, neg[1]).map(|w| &count[dx * (w + dy * z)..][..dx]);
            let nzr = nz.map(|w| &count[dx * (y + dy * w)..][..dx]);
            let by = back(y, 1).map(|w| &count[dx * (w + dy * z)..][..dx]);
            let bzr = bz.map(|w| &count[dx * (y + dy * w)..][..dx]);
            // Branch-free over the row (strict comparisons: a tight cell is non-empty), then
            // only the tight cells, found by their mask bits, take the flush test.
            let next_y = ny.unwrap_or(&ZERO_ROW[..dx]);
            let next_z = nzr.unwrap_or(&ZERO_ROW[..dx]);
            let above = |x: usize, next_x: u16| {
                let c = row[x];
                ((c > next_x) & (c > next_y[x]) & (c > next_z[x])) as u32
            };
            let mut tight = 0u32;
            if neg[0] {
                tight |= above(0, 0);
                for x in 1..dx {
                    tight |= above(x, row[x - 1]) << x;
                }
            } else {
                for x in 0..dx - 1 {
                    tight |= above(x, row[x + 1]) << x;
                }
                tight |= above(dx - 1, 0) << (dx - 1);
            }
            while tight != 0 {
                let x = tight.trailing_zeros() as usize;
                tight &= tight - 1;
                let c = row[x];
                let flush = back(x, 0).map_or_else(|f| f, |w| row[w] != c)
                    && by.map_or_else(|f| f, |rr| rr[x] != c)
                    && bzr.map_or_else(|f| f, |rr| rr[x] != c);
                out.push((r + x) as u32 | if flush { FLUSH_CELL } else { 0 });
            }
        }
    }
}

/// A row of empty counts as long as the largest cube side, for [`collect_tight`].
const ZERO_ROW: [u16; 16] = [0; 16];

/// The dense box of an item: its bounding box (origin `lo`, `dims` cells per axis).
#[derive(Clone, Copy)]
struct DenseBox {
    lo: [usize; 3],
    dims: [usize; 3],
}

impl DenseBox {
    fn of(info: &ItemInfo) -> DenseBox {
        DenseBox {
            lo: info.lo.map(|v| v as usize),
            dims: std::array::from_fn(|i| (info.hi[i] - info.lo[i]) as usize + 1),
        }
    }

    /// Grid coordinates of box cell `i`.
    fn point(&self, i: usize) -> [usize; 3] {
        let [dx, dy, _] = self.dims;
        [
            self.lo[0] + i % dx,
            self.lo[1] + (i / dx) % dy,
            self.lo[2] + i / (dx * dy),
        ]
    }

    /// The box cell whose region toward `d` holds the same voxels as the region of grid point
    /// `p` toward `d`, or `None` when that region is empty (it starts beyond the box).
    fn cell(&self, p: [usize; 3], d: usize) -> Option<usize> {
        let mut index = 0;
        let mut scale = 1;
        for (ax, (&len, (&pa, &lo))) in self.dims.iter().zip(p.iter().zip(&self.lo)).enumerate() {
            let v = pa as isize - lo as isize;
            let local = if (d >> ax) & 1 == 0 {
                if v >= len as isize {
                    return None;
                }
                v.max(0) as usize
            } else {
                if v < 0 {
                    return None;
                }
                (v as usize).min(len - 1)
            };
            index += local * scale;
            scale *= len;
        }
        Some(index)
    }
}

/// How far the cut of the region of box cell `i` toward `d` can move back along each axis (alone)
/// without taking in more voxels, up to the cube face. A window whose cut lies further back
/// holds more voxels than the region, so a match never moves the cut back by more.
fn gaps(bx: &DenseBox, n: usize, count: &[u16], i: usize, d: usize) -> [usize; 3] {
    let [dx, dy, _] = bx.dims;
    let local = [i % dx, (i / dx) % dy, i / (dx * dy)];
    let strides = [1, dx, dx * dy];
    let c = count[i];
    std::array::from_fn(|ax| {
        let (stride, len) = (strides[ax], bx.dims[ax]);
        let mut idx = i;
        let mut v = local[ax];
        let mut gap = 0;
        if (d >> ax) & 1 == 0 {
            // The region is [q, n): its cut moves back toward 0; below the box nothing changes.
            loop {
                if v == 0 {
                    return gap + bx.lo[ax];
                }
                v -= 1;
                idx -= stride;
                if count[idx] != c {
                    return gap;
                }
                gap += 1;
            }
        } else {
            loop {
                if v + 1 == len {
                    return gap + (n - bx.lo[ax] - len);
                }
                v += 1;
                idx += stride;
                if count[idx] != c {
                    return gap;
                }
                gap += 1;
            }
        }
    })
}

/// Loads the voxels of a Morton grid as dense hash/count seeds (1 per occupied voxel) into its
/// bounding box `bx`.
fn load_dense(g: &Geometry, grid: &[u64], bx: &DenseBox, hash: &mut [u64], count: &mut [u16]) {
    let [dx, dy, dz] = bx.dims;
    hash[..dx * dy * dz].fill(0);
    count[..dx * dy * dz].fill(0);
    for_each_voxel(g, grid, |p| {
        let i = (p[0] as usize - bx.lo[0])
            + dx * ((p[1] as usize - bx.lo[1]) + dy * (p[2] as usize - bx.lo[2]));
        hash[i] = 1;
        count[i] = 1;
    });
}

/// Occupancy and bounding box of a grid.
fn item_info(g: &Geometry, grid: &[u64]) -> ItemInfo {
    let mut lo = [u8::MAX; 3];
    let mut hi = [0u8; 3];
    let mut voxels = 0u16;
    for_each_voxel(g, grid, |p| {
        voxels += 1;
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    });
    ItemInfo { voxels, lo, hi }
}

fn for_each_voxel(g: &Geometry, grid: &[u64], mut f: impl FnMut([u8; 3])) {
    for (w, &word) in grid.iter().enumerate() {
        let mut m = word;
        while m != 0 {
            f(g.coords[w * 64 + m.trailing_zeros() as usize]);
            m &= m - 1;
        }
    }
}

/// Table keys of an item: for permutation `perm` of the set, the hash of `P(item)` from each of
/// its 8 bounding-box corners (`keys[8 * k + d]`, `k` indexing `perms`).
fn item_keys(g: &Geometry, grid: &[u64], info: &ItemInfo, perms: &[usize], keys: &mut Vec<u64>) {
    keys.clear();
    keys.resize(perms.len() * 8, 0);
    for_each_voxel(g, grid, |p| {
        for (k, &perm) in perms.iter().enumerate() {
            let order = super::transform::PERMUTATIONS[perm];
            for d in 0..8 {
                let mut term = 1u64;
                for (i, &j) in order.iter().enumerate() {
                    let j = j as usize;
                    let u = if (d >> i) & 1 == 0 {
                        p[j] - info.lo[j]
                    } else {
                        info.hi[j] - p[j]
                    };
                    term = term.wrapping_mul(g.powers[i][u as usize]);
                }
                keys[8 * k + d] = keys[8 * k + d].wrapping_add(term);
            }
        }
    });
}

/// Whether `b = Tr_tr(t(a))` holds given that both have `|b|` voxels inside the translated
/// window (checked by the caller): every voxel of `b` must come from a voxel of `a`.
fn confirm(g: &Geometry, a: &[u64], b: &[u64], t: Transform, tr: [i8; 3]) -> bool {
    let inv = t.inverse();
    let n = g.n as i32;
    for (w, &word) in b.iter().enumerate() {
        let mut m = word;
        while m != 0 {
            let p = g.coords[w * 64 + m.trailing_zeros() as usize];
            m &= m - 1;
            let q: [i32; 3] = std::array::from_fn(|i| p[i] as i32 - tr[i] as i32);
            if q.iter().any(|&v| v < 0 || v >= n) {
                return false;
            }
            let [x, y, z] = inv.apply_point(q.map(|v| v as u32), g.n as u32);
            let bit = morton::encode(x, y, z) as usize;
            if (a[bit / 64] >> (bit % 64)) & 1 == 0 {
                return false;
            }
        }
    }
    true
}

/// Items per table batch: bounds the table (48 entries of 16 bytes per item, and per distinct
/// key a slot at load <= 1/2, its key, first entry and live index).
const TABLE_BATCH: usize = 1 << 20;

/// Phases of descending parent rank per table batch; the key filters are rebuilt from the items
/// still open before each (see `search_level`).
const SEARCH_PHASES: usize = 16;

/// Finds for every item (canonical ids of level `level`) its parent: `(item index of the parent,
/// T, t)` with `item = Tr_t(T(parent))`; an item that is its own parent gets `(itself, id, 0)`.
fn search_level(
    c: &CanonicalDag,
    level: usize,
    items: &[u32],
    progress: &ProgressBar,
) -> Vec<(u32, Transform, [i8; 3])> {
    let started = std::time::Instant::now();
    let g = Geometry::new(level);
    let set = c.set;
    let words = g.words;
    let n = g.n;
    let cells = n * n * n;
    let grid_of = |i: usize, out: &mut [u64]| {
        fill_grid(c, level, items[i], Transform::IDENTITY, &mut out[..words]);
    };
    let info: Vec<ItemInfo> = (0..items.len())
        .into_par_iter()
        .map_init(
            || [0u64; 64],
            |grid, i| {
                grid_of(i, grid);
                item_info(&g, &grid[..words])
            },
        )
        .collect();

    // Ranks: occupancy ascending, ties by descending canonical id; higher rank is preferred.
    let mut by_rank: Vec<u32> = (0..items.len() as u32).collect();
    by_rank.sort_unstable_by_key(|&i| {
        (
            info[i as usize].voxels,
            std::cmp::Reverse(items[i as usize]),
        )
    });
    let mut rank = vec![0u32; items.len()];
    for (r, &i) in by_rank.iter().enumerate() {
        rank[i as usize] = r as u32;
    }
    let best: Vec<AtomicU64> = (0..items.len())
        .map(|i| AtomicU64::new(pack(rank[i], Transform::IDENTITY, [0; 3])))
        .collect();

    let perms: Vec<usize> = (0..6)
        .filter(|&p| Transform::from_parts(p, 0).is_some_and(|t| set.contains(t)))
        .collect();
    let inverse_perms: Vec<Transform> = perms
        .iter()
        .map(|&p| Transform::from_parts(p, 0).unwrap_or_default().inverse())
        .collect();
    let lookups = AtomicU64::new(0);
    let confirmed = AtomicU64::new(0);
    let passed = AtomicU64::new(0);
    let hits = AtomicU64::new(0);
    let visited = AtomicU64::new(0);
    let axis_rejected = AtomicU64::new(0);
    // Table batches hold items of consecutive ranks, and the parents of a batch are searched in
    // phases of descending rank. A candidate parent never beats an item's own rank, so an item
    // of rank `r` is final once every parent ranked above `r` has been searched, and an item
    // already matched is final once the phase that matched it ends (later phases rank lower).
    // Before each phase the key filters are rebuilt from the items that are still open: the
    // popular small shapes that were matched early then stop costing a table probe from every
    // later parent that contains them.
    let batches = items.len().div_ceil(TABLE_BATCH).max(1);
    let mut refilter_time = 0.0;
    let total: usize = (0..batches).map(|b| items.len() - b * TABLE_BATCH).sum();
    progress.inc_length(total as u64);
    let open = |b: u32, below_rank: u32| {
        let r = rank[b as usize];
        r < below_rank && best[b as usize].load(Ordering::Relaxed) >> 32 == r as u64
    };
    for batch in 0..batches {
        let lo = batch * TABLE_BATCH;
        let batch_ranks = lo..((batch + 1) * TABLE_BATCH).min(items.len());
        let mut pairs: Vec<(u64, Entry)> = by_rank[batch_ranks]
            .par_iter()
            .map_init(
                || ([0u64; 64], Vec::new()),
                |(grid, keys), &b| {
                    let b = b as usize;
                    grid_of(b, grid);
                    item_keys(&g, &grid[..words], &info[b], &perms, keys);
                    let entry = |e: usize| Entry::new(b as u32, e as u8, info[b], &perms, n);
                    keys.iter()
                        .enumerate()
                        .map(|(e, &k)| (k, entry(e)))
                        .collect::<Vec<_>>()
                },
            )
            .flatten_iter()
            .collect();
        Table::sort_pairs(&mut pairs);
        let mut table = Table::build(pairs);
        // Parents ranked below `lo` cannot improve any item of the batch.
        let parents = &by_rank[lo..];
        let phase_len = parents.len().div_ceil(SEARCH_PHASES).max(1);
        // Phase `k` ends where `k` phases from the top end (`by_rank[r]` has rank `r`).
        for (k, phase) in parents.rchunks(phase_len).enumerate() {
            let phase_top = (items.len() - k * phase_len) as u32;
            let refilter_started = std::time::Instant::now();
            table.refilter(|b| open(b, phase_top));
            refilter_time += refilter_started.elapsed().as_secs_f64();
            let table = &table;
            phase.par_iter().rev().for_each_init(
                || Scratch::new(cells),
                |s, &a| {
                    let a = a as usize;
                    let ra = rank[a];
                    let mut n_lookups = 0u64;
                    let mut n_confirmed = 0u64;
                    let mut n_passed = 0u64;
                    let mut n_hits = 0u64;
                    let mut n_visited = 0u64;
                    let mut n_axis = 0u64;
                    grid_of(a, &mut s.grid);
                    let bx = DenseBox::of(&info[a]);
                    load_dense(&g, &s.grid[..words], &bx, &mut s.hash[0], &mut s.count[0]);
                    let grid_a = s.grid;
                    let mut other = [0u64; 64];
                    let Scratch {
                        hash: hashes,
                        count: counts,
                        tight,
                        first,
                        ..
                    } = s;
                    for_each_direction(bx.dims, hashes, counts, |d, hash, count| {
                        collect_tight(&bx, n, d, count, tight);
                        n_lookups += tight.len() as u64;
                        // The cache-resident filters first (most regions have no key in the table);
                        // a region with no gap can only match an entry with no offset. All filter
                        // words are loaded before any is tested, so that the loads overlap.
                        let filter = |cell: u32| {
                            let h = hash[(cell & !FLUSH_CELL) as usize];
                            if cell & FLUSH_CELL != 0 {
                                table.flush.place(h)
                            } else {
                                table.any.place(h)
                            }
                        };
                        first.clear();
                        first.extend(tight.iter().map(|&cell| {
                            let (w, _) = filter(cell);
                            if cell & FLUSH_CELL != 0 {
                                table.flush.words[w]
                            } else {
                                table.any.words[w]
                            }
                        }));
                        let mut kept = 0;
                        for j in 0..tight.len() {
                            let cell = tight[j];
                            let (_, bits) = filter(cell);
                            tight[kept] = cell;
                            kept += (first[j] & bits == bits) as usize;
                        }
                        tight.truncate(kept);
                        n_passed += tight.len() as u64;
                        // Independent loads first (they overlap in the memory system), then probes.
                        first.clear();
                        first.extend(
                            tight
                                .iter()
                                .map(|&i| table.first(hash[(i & !FLUSH_CELL) as usize])),
                        );
                        for (&cell, &f) in tight.iter().zip(first.iter()) {
                            if f == 0 {
                                continue;
                            }
                            let flush = cell & FLUSH_CELL != 0;
                            let i = (cell & !FLUSH_CELL) as usize;
                            let q = bx.point(i);
                            let cq = count[i];
                            let mut gap = None;
                            table.for_each_group(hash[i], flush, |group| {
                                n_hits += 1;
                                let gap = *gap.get_or_insert_with(|| {
                                    if flush {
                                        [0; 3]
                                    } else {
                                        gaps(&bx, n, count, i, d)
                                    }
                                });
                                let widest = gap[0].max(gap[1]).max(gap[2]);
                                'entries: for e in group {
                                    n_visited += 1;
                                    if e.max_offset() as usize > widest {
                                        break;
                                    }
                                    if (0..3).any(|ax| e.offset[ax] as usize > gap[ax]) {
                                        n_axis += 1;
                                        continue;
                                    }
                                    let b = e.item as usize;
                                    let k = ((e.perm_dir & !LAST) >> 3) as usize;
                                    let db = (e.perm_dir & 7) as usize;
                                    let ib = &e.info;
                                    if b == a || ib.voxels != cq {
                                        continue 'entries;
                                    }
                                    let m = (d ^ db) as u8;
                                    let order = super::transform::PERMUTATIONS[perms[k]];
                                    // P(b) = Tr_s(M_m(A)): corner of P(b) toward d_B minus M_m(q).
                                    let mut shift = [0i8; 3];
                                    let mut origin = [0usize; 3];
                                    for ax in 0..3 {
                                        let qm = if (m >> ax) & 1 == 1 {
                                            n - 1 - q[ax]
                                        } else {
                                            q[ax]
                                        } as i32;
                                        let j = order[ax] as usize;
                                        let o = if (db >> ax) & 1 == 0 {
                                            let s_ax = ib.lo[j] as i32 - qm;
                                            if s_ax > 0 {
                                                continue 'entries;
                                            }
                                            shift[ax] = s_ax as i8;
                                            -s_ax
                                        } else {
                                            let s_ax = ib.hi[j] as i32 - qm;
                                            if s_ax < 0 {
                                                continue 'entries;
                                            }
                                            shift[ax] = s_ax as i8;
                                            n as i32 - 1 - s_ax
                                        } as usize;
                                        origin[ax] = if (m >> ax) & 1 == 1 { n - 1 - o } else { o };
                                    }
                                    // The window of A that stays inside must hold |b| voxels.
                                    if bx.cell(origin, d).map_or(0, |c| count[c]) != cq {
                                        continue 'entries;
                                    }
                                    // b = P⁻¹(Tr_s(M_m(A))) = Tr_{L(s)}((P⁻¹ ∘ M_m)(A)).
                                    let pinv = inverse_perms[k];
                                    let t = pinv
                                        .compose(Transform::from_parts(0, m).unwrap_or_default());
                                    if !set.contains(t) {
                                        continue 'entries;
                                    }
                                    let tr = apply_to_vector(pinv, shift);
                                    let key = pack(ra, t, tr);
                                    if best[b].load(Ordering::Relaxed) >= key {
                                        continue 'entries;
                                    }
                                    n_confirmed += 1;
                                    grid_of(b, &mut other);
                                    if confirm(&g, &grid_a[..words], &other[..words], t, tr) {
                                        best[b].fetch_max(key, Ordering::Relaxed);
                                    }
                                }
                            });
                        }
                    });
                    lookups.fetch_add(n_lookups, Ordering::Relaxed);
                    confirmed.fetch_add(n_confirmed, Ordering::Relaxed);
                    passed.fetch_add(n_passed, Ordering::Relaxed);
                    hits.fetch_add(n_hits, Ordering::Relaxed);
                    visited.fetch_add(n_visited, Ordering::Relaxed);
                    axis_rejected.fetch_add(n_axis, Ordering::Relaxed);
                    progress.inc(1);
                },
            );
        }
    }
    log::debug!(
        "translations at {}^3: {} items, {:.1} s, {} lookups, {} past the filters, {} keys \
         found, {} entries visited ({} beyond the gap of an axis), {} confirmations, filter rebuilds {:.1} s",
        n,
        items.len(),
        started.elapsed().as_secs_f64(),
        lookups.load(Ordering::Relaxed),
        passed.load(Ordering::Relaxed),
        hits.load(Ordering::Relaxed),
        visited.load(Ordering::Relaxed),
        axis_rejected.load(Ordering::Relaxed),
        confirmed.load(Ordering::Relaxed),
        refilter_time
    );
    best.iter()
        .map(|k| {
            let (r, t, tr) = unpack(k.load(Ordering::Relaxed));
            (by_rank[r as usize], t, tr)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(item: u32) -> Entry {
        Entry {
            item,
            ..Entry::default()
        }
    }

    /// Two keys with the same fingerprint (low 32 bits) in the same probe run: each lookup gets
    /// its own group, never the other's (that lost matches before the full key was checked).
    #[test]
    fn table_groups_need_the_full_key() {
        let k1 = 0x0123_4567_89ab_cdef_u64;
        let k2 = k1 ^ (1 << 40);
        let mut pairs = vec![(k1, entry(1)), (k2, entry(2)), (k1, entry(3))];
        Table::sort_pairs(&mut pairs);
        let table = Table::build(pairs.clone());
        assert_eq!(Table::tag(k1), Table::tag(k2));
        let items = |k| {
            let mut out = Vec::new();
            table.for_each_group(k, false, |g| {
                out.push(g.map(|e| e.item).collect::<Vec<_>>())
            });
            out.sort();
            out
        };
        // Both groups share the tag: a lookup visits both, never a mix of them.
        assert_eq!(items(k1), vec![vec![1, 3], vec![2]]);
        assert_eq!(items(k2), vec![vec![1, 3], vec![2]]);
        assert!(items(k1 ^ 4).is_empty());
    }

    /// The filters never drop a key of the table: every key passes `any`, every key of a group
    /// with a zero-offset entry passes `flush`; absent keys mostly fail.
    #[test]
    fn filters_keep_every_key() {
        let mut rng = 0x1234_5678_9abc_def1_u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let mut pairs: Vec<(u64, Entry)> = (0..20_000)
            .map(|i| {
                let key = next() % 5000 * 0x9e37_79b9_7f4a_7c15;
                let offset = [0, 1, 2].map(|_| (next() % 3 == 0) as u8 * (i % 5) as u8);
                (key, Entry { offset, ..entry(i) })
            })
            .collect();
        Table::sort_pairs(&mut pairs);
        let table = Table::build(pairs.clone());
        for (k, e) in &pairs {
            assert!(table.any.may_contain(*k));
            if e.max_offset() == 0 {
                assert!(table.flush.may_contain(*k));
            }
            // The slot's flush bit: the key's own group is visited by a flush-only lookup
            // exactly when it has an entry with no offset.
            let mut visited = Vec::new();
            table.for_each_group(*k, true, |g| visited.extend(g.map(|e| e.item)));
            let flush_group = pairs.iter().any(|(k2, e2)| k2 == k && e2.max_offset() == 0);
            assert_eq!(visited.contains(&e.item), flush_group);
        }
        let absent = (0..10_000)
            .filter(|_| table.any.may_contain(next() | 1))
            .count();
        assert!(absent < 1500, "{absent} false positives of 10000");
    }

    /// A filter rebuild keeps exactly the groups with an open entry: every key of such a group
    /// passes `any` (and `flush` when the open entry has no offset), the closed groups leave
    /// the live list for good, and closing more items only shrinks it.
    #[test]
    fn refilter_keeps_the_open_groups() {
        let pairs_of = |i: u32| {
            let key = (i as u64 % 700 + 1) * 0x9e37_79b9_7f4a_7c15;
            let offset = [i.is_multiple_of(4) as u8, 0, 0];
            (key, Entry { offset, ..entry(i) })
        };
        let mut pairs: Vec<(u64, Entry)> = (0..5000).map(pairs_of).collect();
        Table::sort_pairs(&mut pairs);
        let mut table = Table::build(pairs.clone());
        assert_eq!(table.live.len(), 700);
        // Items close step by step (never reopen), as in the search.
        for step in 1..=3 {
            let open = |item: u32| [2, 3, 7][..step].iter().all(|&t| !item.is_multiple_of(t));
            let before = table.live.clone();
            table.refilter(open);
            let expected: Vec<u32> = (0..table.keys.len() as u32)
                .filter(|&g| {
                    let key = table.keys[g as usize];
                    pairs.iter().any(|(k, e)| *k == key && open(e.item))
                })
                .collect();
            assert_eq!(table.live, expected, "step {step}");
            assert!(expected.iter().all(|g| before.contains(g)));
            for (k, e) in pairs.iter().filter(|(_, e)| open(e.item)) {
                assert!(table.any.may_contain(*k));
                if e.max_offset() == 0 {
                    assert!(table.flush.may_contain(*k));
                }
            }
        }
    }

    /// `gaps` against counting the region of every cut position directly.
    #[test]
    fn gaps_match_direct_counts() {
        let n = 8usize;
        let voxels: Vec<[usize; 3]> = vec![[2, 3, 4], [3, 3, 4], [5, 6, 2], [2, 5, 6], [4, 4, 4]];
        let lo: [usize; 3] = std::array::from_fn(|i| voxels.iter().map(|v| v[i]).min().unwrap());
        let hi: [usize; 3] = std::array::from_fn(|i| voxels.iter().map(|v| v[i]).max().unwrap());
        let bx = DenseBox {
            lo,
            dims: std::array::from_fn(|i| hi[i] - lo[i] + 1),
        };
        let region = |q: [isize; 3], d: usize| {
            voxels
                .iter()
                .filter(|v| {
                    (0..3).all(|ax| {
                        let c = v[ax] as isize;
                        if (d >> ax) & 1 == 0 {
                            c >= q[ax]
                        } else {
                            c <= q[ax]
                        }
                    })
                })
                .count() as u16
        };
        let cells = bx.dims.iter().product::<usize>();
        for d in 0..8 {
            let count: Vec<u16> = (0..cells)
                .map(|i| region(bx.point(i).map(|v| v as isize), d))
                .collect();
            // Tight cells (the region's bounding box starts there) with their no-gap flag.
            let mut tight = Vec::new();
            collect_tight(&bx, n, d, &count, &mut tight);
            let expected: Vec<u32> = (0..cells)
                .filter(|&i| {
                    let q = bx.point(i);
                    count[i] > 0
                        && (0..3).all(|ax| {
                            voxels.iter().any(|v| {
                                v[ax] == q[ax] && region(v.map(|c| c as isize), d) > 0 && {
                                    let mut p = q.map(|c| c as isize);
                                    p[ax] = v[ax] as isize;
                                    (0..3).all(|k| {
                                        let c = v[k] as isize;
                                        if (d >> k) & 1 == 0 {
                                            c >= p[k]
                                        } else {
                                            c <= p[k]
                                        }
                                    })
                                }
                            })
                        })
                })
                .map(|i| {
                    let flush = gaps(&bx, n, &count, i, d) == [0; 3];
                    i as u32 | if flush { FLUSH_CELL } else { 0 }
                })
                .collect();
            assert_eq!(tight, expected, "d {d}");
            for i in 0..cells {
                let q = bx.point(i).map(|v| v as isize);
                let c = count[i];
                let gap = gaps(&bx, n, &count, i, d);
                for ax in 0..3 {
                    let back = |k: isize| {
                        let mut p = q;
                        p[ax] += if (d >> ax) & 1 == 0 { -k } else { k };
                        p
                    };
                    let g = gap[ax] as isize;
                    assert_eq!(region(back(g), d), c, "d {d} cell {i} axis {ax}");
                    let edge = if (d >> ax) & 1 == 0 {
                        q[ax]
                    } else {
                        n as isize - 1 - q[ax]
                    };
                    assert!(g <= edge);
                    if g < edge {
                        assert_ne!(region(back(g + 1), d), c, "d {d} cell {i} axis {ax}");
                    }
                }
            }
        }
    }
}
