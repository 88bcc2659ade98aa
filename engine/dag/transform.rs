//! The cube's symmetry group: 6 axis permutations x 8 mirrors = 48 transforms (dissertation §3.2).
//!
//! # Convention
//! A transform `T` with axis permutation `π` (output axis `i` reads input axis `π[i]`) and mirror
//! bits `m` maps a voxel `v` of a grid of side `n` to
//!
//! ```text
//! T(v)[i] = if m & (1 << i) != 0 { n - 1 - v[π[i]] } else { v[π[i]] }
//! ```
//!
//! i.e. first the axes are permuted, then the result is mirrored (in the output frame).
//! Applying `T` to a grid moves the voxel at `v` to `T(v)`. The same formula with `n = 2` gives
//! the action on child octants (`o = x | y << 1 | z << 2`): applying `T` to a node moves the
//! child at octant `o` to octant `T(o)` and applies `T` to that child, recursively.
//!
//! Transform ids: `id = 8 * p + m`, where `p` indexes [`PERMUTATIONS`] (0 = identity) and `m` is
//! the mirror mask (bit 0 = x, 1 = y, 2 = z). So ids `0..8` are the mirrors (subgroup S),
//! ids `0, 8, .., 40` the axis permutations (subgroup A), and id 0 is the identity.
//! [`Transform::compose`]`(a, b)` is `a ∘ b` (apply `b` first).

use std::sync::OnceLock;

/// Number of elements of the group.
pub const TRANSFORM_COUNT: usize = 48;

/// The 6 axis permutations, identity first, in lexicographic order: entry `i` of a permutation
/// is the input axis read by output axis `i`.
pub const PERMUTATIONS: [[u8; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// One of the 48 symmetries of the cube (see the module docs for the exact convention).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct Transform(u8);

/// A bit-permutation step on a 64-bit leaf mask: swaps bit `p` with bit `p + shift` for every
/// `p` in `mask` (a "delta swap").
#[derive(Clone, Copy, Debug, Default)]
struct DeltaSwap {
    mask: u64,
    shift: u32,
}

/// At most 4 index-bit swaps for the permutation and 6 for the mirror.
const MAX_OPS: usize = 10;

/// Per-transform tables, computed once.
struct Tables {
    compose: [[u8; TRANSFORM_COUNT]; TRANSFORM_COUNT],
    inverse: [u8; TRANSFORM_COUNT],
    octant: [[u8; 8]; TRANSFORM_COUNT],
    child_mask: Vec<[u8; 256]>,
    leaf_ops: [([DeltaSwap; MAX_OPS], usize); TRANSFORM_COUNT],
}

fn tables() -> &'static Tables {
    static TABLES: OnceLock<Tables> = OnceLock::new();
    TABLES.get_or_init(build_tables)
}

#[inline]
fn delta_swap(x: u64, op: DeltaSwap) -> u64 {
    let t = ((x >> op.shift) ^ x) & op.mask;
    x ^ t ^ (t << op.shift)
}

/// Swap of index bits `i < j` of a 64-entry bit array.
fn index_bit_swap(i: u32, j: u32) -> DeltaSwap {
    let mut mask = 0u64;
    for p in 0..64u32 {
        if (p >> i) & 1 == 1 && (p >> j) & 1 == 0 {
            mask |= 1 << p;
        }
    }
    DeltaSwap {
        mask,
        shift: (1 << j) - (1 << i),
    }
}

/// XOR of the index with `1 << k`.
fn index_bit_flip(k: u32) -> DeltaSwap {
    let mut mask = 0u64;
    for p in 0..64u32 {
        if (p >> k) & 1 == 0 {
            mask |= 1 << p;
        }
    }
    DeltaSwap {
        mask,
        shift: 1 << k,
    }
}

fn run_ops(ops: &[DeltaSwap], mut x: u64) -> u64 {
    for &op in ops {
        x = delta_swap(x, op);
    }
    x
}

fn build_tables() -> Tables {
    let all: Vec<Transform> = (0..TRANSFORM_COUNT as u8).map(Transform).collect();
    let mut compose = [[0u8; TRANSFORM_COUNT]; TRANSFORM_COUNT];
    for a in &all {
        for b in &all {
            // a(b(v))[i] = ma_i(mb_{πa[i]}(v[πb[πa[i]]]))
            let (pa, pb) = (a.permutation(), b.permutation());
            let mut perm = [0u8; 3];
            let mut mirror = 0u8;
            for i in 0..3 {
                perm[i] = pb[pa[i] as usize];
                let bit = ((a.mirror() >> i) ^ (b.mirror() >> pa[i])) & 1;
                mirror |= bit << i;
            }
            let p = PERMUTATIONS
                .iter()
                .position(|q| *q == perm)
                .expect("composition of permutations is a permutation");
            compose[a.index()][b.index()] = (8 * p) as u8 + mirror;
        }
    }
    let mut inverse = [0u8; TRANSFORM_COUNT];
    for a in 0..TRANSFORM_COUNT {
        inverse[a] = (0..TRANSFORM_COUNT)
            .find(|&b| compose[a][b] == 0)
            .expect("every group element has an inverse") as u8;
    }
    let mut octant = [[0u8; 8]; TRANSFORM_COUNT];
    let mut child_mask = vec![[0u8; 256]; TRANSFORM_COUNT];
    for t in &all {
        for o in 0..8u32 {
            let [x, y, z] = t.apply_point([o & 1, (o >> 1) & 1, o >> 2], 2);
            octant[t.index()][o as usize] = (x | y << 1 | z << 2) as u8;
        }
        let oct = octant[t.index()];
        for (m, entry) in child_mask[t.index()].iter_mut().enumerate() {
            *entry = oct
                .iter()
                .enumerate()
                .filter(|(o, _)| (m >> o) & 1 == 1)
                .fold(0u8, |out, (_, &to)| out | 1 << to);
        }
    }
    // Leaf bit permutations: up to two axis transpositions (each = 2 index-bit swaps), found by
    // trying all short sequences against the per-voxel definition, then the mirror flips.
    let transpositions = [(0u32, 1u32), (0, 2), (1, 2)];
    let mut sequences: Vec<Vec<(u32, u32)>> = vec![vec![]];
    for &a in &transpositions {
        sequences.push(vec![a]);
        for &b in &transpositions {
            sequences.push(vec![a, b]);
        }
    }
    let mut leaf_ops = [([DeltaSwap::default(); MAX_OPS], 0usize); TRANSFORM_COUNT];
    for t in &all {
        let reference: Vec<u64> = (0..64).map(|bit| leaf_reference(*t, 1u64 << bit)).collect();
        let mut found = None;
        for seq in &sequences {
            let mut ops = Vec::new();
            for &(a, b) in seq {
                ops.push(index_bit_swap(a, b));
                ops.push(index_bit_swap(a + 3, b + 3));
            }
            for axis in 0..3u32 {
                if (t.mirror() >> axis) & 1 == 1 {
                    ops.push(index_bit_flip(axis));
                    ops.push(index_bit_flip(axis + 3));
                }
            }
            if (0..64).all(|bit| run_ops(&ops, 1u64 << bit) == reference[bit]) {
                found = Some(ops);
                break;
            }
        }
        let ops = found.expect("every axis permutation is at most two transpositions");
        let entry = &mut leaf_ops[t.index()];
        entry.0[..ops.len()].copy_from_slice(&ops);
        entry.1 = ops.len();
    }
    Tables {
        compose,
        inverse,
        octant,
        child_mask,
        leaf_ops,
    }
}

/// Per-voxel definition of a leaf transform (slow; the reference for [`Transform::apply_leaf`]).
pub fn leaf_reference(t: Transform, mask: u64) -> u64 {
    let mut out = 0u64;
    for bit in 0..64u64 {
        if (mask >> bit) & 1 == 1 {
            let [x, y, z] = crate::scene::morton::decode(bit);
            let [x, y, z] = t.apply_point([x, y, z], 4);
            out |= 1u64 << crate::scene::morton::encode(x, y, z);
        }
    }
    out
}

impl Transform {
    /// The identity transform (id 0).
    pub const IDENTITY: Transform = Transform(0);

    /// The transform with id `index` (`None` unless `index < 48`).
    pub const fn from_index(index: usize) -> Option<Transform> {
        if index < TRANSFORM_COUNT {
            Some(Transform(index as u8))
        } else {
            None
        }
    }

    /// The transform that permutes axes by `PERMUTATIONS[perm]` then mirrors the axes in `mirror`.
    pub const fn from_parts(perm: usize, mirror: u8) -> Option<Transform> {
        if perm < 6 && mirror < 8 {
            Some(Transform(perm as u8 * 8 + mirror))
        } else {
            None
        }
    }

    /// The id, `8 * permutation index + mirror mask`, in `0..48`.
    #[inline]
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// Index into [`PERMUTATIONS`].
    #[inline]
    pub const fn permutation_index(self) -> usize {
        (self.0 >> 3) as usize
    }

    /// Axis permutation: output axis `i` reads input axis `permutation()[i]`.
    #[inline]
    pub const fn permutation(self) -> [u8; 3] {
        PERMUTATIONS[self.permutation_index()]
    }

    /// Mirror mask applied after the permutation (bit 0 = x, 1 = y, 2 = z).
    #[inline]
    pub const fn mirror(self) -> u8 {
        self.0 & 7
    }

    /// All 48 transforms in id order.
    pub fn all() -> impl Iterator<Item = Transform> {
        (0..TRANSFORM_COUNT as u8).map(Transform)
    }

    /// Applies the transform to voxel `p` of a grid of side `size` (coordinates below `size`).
    pub fn apply_point(self, p: [u32; 3], size: u32) -> [u32; 3] {
        let perm = self.permutation();
        let mut out = [0u32; 3];
        for i in 0..3 {
            let v = p[perm[i] as usize];
            out[i] = if (self.mirror() >> i) & 1 == 1 {
                size - 1 - v
            } else {
                v
            };
        }
        out
    }

    /// `self ∘ inner`: the transform that applies `inner` first, then `self`.
    #[inline]
    pub fn compose(self, inner: Transform) -> Transform {
        Transform(tables().compose[self.index()][inner.index()])
    }

    /// The inverse transform.
    #[inline]
    pub fn inverse(self) -> Transform {
        Transform(tables().inverse[self.index()])
    }

    /// Where the child at octant `o` (`x | y << 1 | z << 2`, below 8) moves.
    #[inline]
    pub fn apply_octant(self, o: usize) -> usize {
        tables().octant[self.index()][o & 7] as usize
    }

    /// Transforms an 8-bit child mask (bit `o` = octant `o`).
    #[inline]
    pub fn apply_child_mask(self, mask: u8) -> u8 {
        tables().child_mask[self.index()][mask as usize]
    }

    /// Transforms a 4^3 leaf mask (bit `morton(x, y, z)`): a fixed bit permutation done with at
    /// most 10 delta swaps.
    #[inline]
    pub fn apply_leaf(self, mask: u64) -> u64 {
        let (ops, n) = &tables().leaf_ops[self.index()];
        run_ops(&ops[..*n], mask)
    }
}

/// Which transforms may be used to match subtrees (selectable at run time).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TransformSet {
    /// Identity only: plain SVDAG.
    None,
    /// The 8 mirrors (S).
    Mirrors,
    /// The 6 axis permutations (A).
    AxisPermutations,
    /// All 48 (S+A).
    All,
}

impl TransformSet {
    /// The transforms of the set, in ascending id order (always a subgroup, identity first).
    pub fn transforms(self) -> &'static [Transform] {
        static SETS: OnceLock<[Vec<Transform>; 4]> = OnceLock::new();
        let sets = SETS.get_or_init(|| {
            [
                TransformSet::None,
                TransformSet::Mirrors,
                TransformSet::AxisPermutations,
                TransformSet::All,
            ]
            .map(|s| Transform::all().filter(|t| s.contains(*t)).collect())
        });
        &sets[self as usize]
    }

    /// Whether `t` belongs to the set.
    pub fn contains(self, t: Transform) -> bool {
        match self {
            TransformSet::None => t == Transform::IDENTITY,
            TransformSet::Mirrors => t.permutation_index() == 0,
            TransformSet::AxisPermutations => t.mirror() == 0,
            TransformSet::All => true,
        }
    }

    /// The set as a 48-bit mask (bit `id`).
    pub fn mask(self) -> u64 {
        self.transforms()
            .iter()
            .fold(0u64, |m, t| m | 1 << t.index())
    }
}

/// Iterates the transforms whose bits are set in a 48-bit mask, in ascending id order.
pub fn transforms_in_mask(mask: u64) -> impl Iterator<Item = Transform> {
    let mut m = mask & ((1u64 << TRANSFORM_COUNT) - 1);
    std::iter::from_fn(move || {
        if m == 0 {
            return None;
        }
        let t = m.trailing_zeros() as u8;
        m &= m - 1;
        Some(Transform(t))
    })
}

/// The smallest id in the left coset `t · H` of a subgroup `H` given as a 48-bit mask: the
/// canonical transform among those that give the same result on a node whose stabiliser is `H`.
pub fn coset_min(t: Transform, subgroup: u64) -> Transform {
    transforms_in_mask(subgroup)
        .map(|s| t.compose(s))
        .min()
        .unwrap_or(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_and_leaf_ops() {
        assert_eq!(
            Transform::IDENTITY.apply_leaf(0xdead_beef_1234_5678),
            0xdead_beef_1234_5678
        );
        for t in Transform::all() {
            for bit in 0..64 {
                assert_eq!(t.apply_leaf(1 << bit), leaf_reference(t, 1 << bit));
            }
        }
    }
}
