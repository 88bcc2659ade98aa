//! Symmetry-aware SVDAG (SSVDAG, Villanueva, Marton, Gobbetti 2016) and the dissertation's fix
//! (§3.2.2).
//!
//! Every pointer carries 3 mirror bits; a node matches a stored node if it equals it under one of
//! the 8 mirrors. As published (and as the dissertation's reference code reproduces it):
//! - a 4^3 leaf is a node of eight 2^3 sub-blocks (bytes of the leaf mask); a sub-block points to
//!   its canonical 8-bit mask (the largest of its 8 mirrors; the mirror is the first, in id order
//!   `x | y << 1 | z << 2`, that reaches it);
//! - levels are processed bottom-up, nodes in SVDAG order; a node is looked up in the level's
//!   table mirrored by `m = 1..8` (in that order) and points to the first match with mirror `m`;
//!   otherwise it becomes a new stored node (mirror 0);
//! - pointer equality: same target and equal mirror bits, except on the axes along which the
//!   target is invariant. [`Invariance::Axes3`] is the published rule: 3 independent bits
//!   (invariant under the x, y or z mirror alone). It misses invariance under combined mirrors
//!   (e.g. xy only), so some equal subtrees are stored twice. [`Invariance::Full`] is the fix:
//!   the invariance is the whole stabiliser subgroup (an 8-bit mask of mirrors) and two
//!   mirror bits are equal when they differ by an element of it; it then finds exactly the
//!   mirror orbits (the same counts as `CanonicalDag` with `TransformSet::Mirrors`).
//!
//! The rule is sound (equal keys imply equal voxels), so the identity never matches a different
//! SVDAG node and the first stored node of every class is the first in SVDAG order.

use std::hash::BuildHasher;

use hashbrown::HashTable;
use rayon::prelude::*;
use rustc_hash::FxBuildHasher;

use super::Svdag;

/// How invariance of a pointer's target is recorded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Invariance {
    /// As published: 3 bits, invariance under the single-axis mirrors only.
    Axes3,
    /// The dissertation's fix: the full stabiliser (8-bit mask over the mirrors).
    Full,
}

/// A child pointer of an SSVDAG node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SymmetryPointer {
    /// Stored node index in the level below; for leaves, the canonical 2^3 mask (0..256);
    /// `u32::MAX` for an empty child.
    pub node: u32,
    /// Mirror bits (bit 0 = x, 1 = y, 2 = z): the child is the target mirrored by these.
    pub mirror: u8,
}

impl SymmetryPointer {
    /// The empty child.
    pub const EMPTY: SymmetryPointer = SymmetryPointer {
        node: u32::MAX,
        mirror: 0,
    };
}

/// Stored nodes of one SSVDAG level.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SsvdagLevel {
    /// Children of each stored node by octant (level 0: the eight 2^3 sub-blocks).
    pub nodes: Vec<[SymmetryPointer; 8]>,
    /// Invariance of each stored node (`Axes3`: bit `a` = invariant under the axis-`a` mirror;
    /// `Full`: bit `m` = invariant under mirror `m`).
    pub invariance: Vec<u8>,
    /// For each SVDAG node of this level (SVDAG order): its stored node and mirror.
    pub svdag_nodes: Vec<SymmetryPointer>,
}

/// An SSVDAG: stored nodes per level, bottom-up.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ssvdag {
    /// Which invariance rule built it.
    pub invariance: Invariance,
    /// Levels bottom-up (0 = 4^3 leaves).
    pub levels: Vec<SsvdagLevel>,
}

/// Mirrors a 2^3 mask (bit = octant) by `m`.
fn mirror8(mask: u8, m: u8) -> u8 {
    (0..8u8).fold(0, |out, o| out | (((mask >> o) & 1) << (o ^ m)))
}

/// Canonical 2^3 mask, the mirror reaching it, and its invariance under `rule`.
fn sub_block(mask: u8, rule: Invariance) -> (u8, u8, u8) {
    let (mut best, mut best_t, mut inv) = (0u8, 0u8, 0u8);
    for t in 0..8u8 {
        let v = mirror8(mask, t);
        if v > best {
            best = v;
            best_t = t;
        }
        if v == mask {
            match rule {
                Invariance::Full => inv |= 1 << t,
                Invariance::Axes3 => {
                    if t.count_ones() == 1 {
                        inv |= t;
                    }
                }
            }
        }
    }
    (best, best_t, inv)
}

/// Mirror bits `t` normalised under the target's invariance.
#[inline]
fn normalise(t: u8, inv: u8, rule: Invariance) -> u8 {
    match rule {
        Invariance::Axes3 => t & !inv & 7,
        Invariance::Full => (0..8u8)
            .filter(|h| (inv >> h) & 1 == 1)
            .map(|h| t ^ h)
            .min()
            .unwrap_or(t),
    }
}

type Key = [u64; 8];

/// Key of a node mirrored by `m`: per octant `(target + 1) << 3 | normalised mirror`, 0 = empty.
fn mirrored_key(children: &[SymmetryPointer; 8], invs: &[u8], m: u8, rule: Invariance) -> Key {
    let mut key = [0u64; 8];
    for (o, c) in children.iter().enumerate() {
        if c.node != u32::MAX {
            let t = normalise(c.mirror ^ m, invs[c.node as usize], rule);
            key[o ^ m as usize] = ((c.node as u64 + 1) << 3) | t as u64;
        }
    }
    key
}

/// Nodes per parallel batch.
const BATCH: usize = 1 << 15;

/// Greedy matching of one level: `count` SVDAG nodes in SVDAG order, `children(i)` the
/// children of the `i`-th (made per batch, so the level's SVDAG nodes are never all expanded).
fn match_level(
    count: usize,
    children: impl Fn(usize) -> [SymmetryPointer; 8] + Sync,
    invs_below: &[u8],
    rule: Invariance,
) -> SsvdagLevel {
    let mut level = SsvdagLevel::default();
    // Stored node indices keyed by their unmirrored key, compared through `stored_key`: 4
    // bytes per stored node instead of a 64-byte key.
    let mut table: HashTable<u32> = HashTable::new();
    let stored_key =
        |level: &SsvdagLevel, id: u32| mirrored_key(&level.nodes[id as usize], invs_below, 0, rule);
    level.svdag_nodes.reserve(count);
    for start in (0..count).step_by(BATCH) {
        let keys: Vec<([SymmetryPointer; 8], [Key; 8], u8)> = (start..count.min(start + BATCH))
            .into_par_iter()
            .map(|i| {
                let children = children(i);
                let keys: [Key; 8] =
                    std::array::from_fn(|m| mirrored_key(&children, invs_below, m as u8, rule));
                let mut inv = 0u8;
                for m in 0..8u8 {
                    if keys[m as usize] == keys[0] {
                        match rule {
                            Invariance::Full => inv |= 1 << m,
                            Invariance::Axes3 => {
                                if m.count_ones() == 1 {
                                    inv |= m;
                                }
                            }
                        }
                    }
                }
                (children, keys, inv)
            })
            .collect();
        for (children, keys, inv) in keys {
            let found = (1..8u8).find_map(|m| {
                let key = &keys[m as usize];
                table
                    .find(FxBuildHasher.hash_one(key), |&id| {
                        stored_key(&level, id) == *key
                    })
                    .map(|&id| (id, m))
            });
            let ptr = match found {
                Some((node, mirror)) => SymmetryPointer { node, mirror },
                None => {
                    let node = level.nodes.len() as u32;
                    level.nodes.push(children);
                    level.invariance.push(inv);
                    table.insert_unique(FxBuildHasher.hash_one(keys[0]), node, |&id| {
                        FxBuildHasher.hash_one(stored_key(&level, id))
                    });
                    SymmetryPointer { node, mirror: 0 }
                }
            };
            level.svdag_nodes.push(ptr);
        }
    }
    // The level is kept while the levels above are matched: drop the growth slack.
    level.nodes.shrink_to_fit();
    level.invariance.shrink_to_fit();
    level
}

impl Ssvdag {
    /// Builds the SSVDAG of a (valid) SVDAG with the given invariance rule.
    pub fn build(dag: &Svdag, rule: Invariance) -> Ssvdag {
        let root_level = dag.root_level();
        let mut levels: Vec<SsvdagLevel> = Vec::with_capacity(root_level as usize + 1);
        if dag.words.first().copied().unwrap_or(0) == 0 {
            levels.resize(root_level as usize + 1, SsvdagLevel::default());
            return Ssvdag {
                invariance: rule,
                levels,
            };
        }
        // 2^3 sub-blocks: target = canonical mask value.
        let blocks: Vec<(u8, u8, u8)> = (0..=255u8).map(|m| sub_block(m, rule)).collect();
        // Indexed by the canonical mask: its invariance (the same for all its mirrors).
        let block_inv: Vec<u8> = blocks.iter().map(|b| b.2).collect();
        let leaves = dag.level_range(0);
        let leaf_children = |i: usize| {
            let mask = dag.leaf_mask(leaves.start + 2 * i);
            std::array::from_fn(|o| {
                let (canon, t, _) = blocks[((mask >> (8 * o)) & 0xff) as usize];
                SymmetryPointer {
                    node: canon as u32,
                    mirror: t,
                }
            })
        };
        levels.push(match_level(
            leaves.len() / 2,
            leaf_children,
            &block_inv,
            rule,
        ));

        let mut below_start = dag.level_range(0).start;
        let mut below_index: Vec<u32> = (0..dag.level_range(0).len())
            .map(|w| (w / 2) as u32)
            .collect();
        for l in 1..=root_level {
            let range = dag.level_range(l);
            let mut index = vec![0u32; range.len()];
            let mut offsets: Vec<usize> = Vec::new();
            for p in dag.node_starts(l) {
                index[p - range.start] = offsets.len() as u32;
                offsets.push(p);
            }
            let below = levels.last().expect("level 0 exists");
            let node_children = |i: usize| {
                let p = offsets[i];
                let mask = dag.words[p];
                let mut children = [SymmetryPointer::EMPTY; 8];
                let mut k = 0;
                for (o, child) in children.iter_mut().enumerate() {
                    if (mask >> o) & 1 == 1 {
                        let w = dag.words[p + 1 + k] as usize;
                        *child = below.svdag_nodes[below_index[w - below_start] as usize];
                        k += 1;
                    }
                }
                children
            };
            let level = match_level(offsets.len(), node_children, &below.invariance, rule);
            levels.push(level);
            below_index = index;
            below_start = range.start;
        }
        Ssvdag {
            invariance: rule,
            levels,
        }
    }

    /// Stored node count per level, level 0 first.
    pub fn level_counts(&self) -> Vec<u64> {
        self.levels.iter().map(|l| l.nodes.len() as u64).collect()
    }
}
