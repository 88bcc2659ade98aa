//! Node and byte statistics of an SVDAG compared with its equivalent SVO.
//!
//! Path counts (how many root-to-node paths reach each stored node) are propagated top-down in
//! u64; a node's SVO multiplicity is its path count. Definitions are in `docs/svdag.md`.

use serde::{Deserialize, Serialize};

use super::Svdag;

/// Node counts of one level (0 = 4^3 leaves, the last entry is the root level).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LevelStats {
    /// Level number, counted from the leaves.
    pub level: u32,
    /// Non-empty nodes of the equivalent SVO (distinct paths reaching this level).
    pub svo: u64,
    /// Unique nodes stored in the DAG on this level.
    pub svdag: u64,
    /// SSVDAG stored nodes (3-bit invariance, as published); only from `stats_with_symmetry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ssvdag: Option<u64>,
    /// Unique nodes up to mirrors (S); only from `stats_with_symmetry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub s: Option<u64>,
    /// Unique nodes up to axis permutations (A); only from `stats_with_symmetry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub a: Option<u64>,
    /// Unique nodes up to all 48 transforms (S+A); only from `stats_with_symmetry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sa: Option<u64>,
    /// Stored nodes with S+A and translations (S+A+T); only from `stats_with_symmetry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sat: Option<u64>,
}

/// Sizes in bytes of the scene in several encodings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ByteStats {
    /// The same node format without sharing: inner 4 + 4 * children bytes, leaves 8 bytes.
    pub svo: u64,
    /// This DAG's `words` in bytes.
    pub svdag32: u64,
}

/// Summary of a DAG, serialised as the `stats --json` output.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DagStats {
    /// Grid side length.
    pub resolution: u32,
    /// Occupied voxels.
    pub voxels: u64,
    /// Sizes in bytes.
    pub bytes: ByteStats,
    /// Per-level node counts, level 0 first.
    pub levels: Vec<LevelStats>,
}

/// Everything one top-down pass computes.
struct PathCounts {
    /// Per level: (svo, svdag, svo bytes).
    levels: Vec<(u64, u64, u64)>,
    /// Voxels (leaf popcount x path count, summed).
    voxels: u64,
}

impl Svdag {
    /// Word range `[start, end)` of level `l` (levels are stored top-down, leaves last).
    pub fn level_range(&self, level: u32) -> std::ops::Range<usize> {
        let l = level as usize;
        let start = self.level_starts[l] as usize;
        let end = if l == 0 {
            self.words.len()
        } else {
            self.level_starts[l - 1] as usize
        };
        start..end
    }

    /// First word of every node of level `level`, in order (a leaf has 2 words, an inner node
    /// its child mask and one word per child).
    pub fn node_starts(&self, level: u32) -> impl Iterator<Item = usize> + '_ {
        let range = self.level_range(level);
        let mut at = range.start;
        std::iter::from_fn(move || {
            let node = (at < range.end).then_some(at)?;
            at += if level == 0 {
                2
            } else {
                1 + self.words[at].count_ones() as usize
            };
            Some(node)
        })
    }

    /// Propagates path counts from the root down and accumulates per-level figures.
    fn path_counts(&self) -> PathCounts {
        let root_level = self.root_level();
        let mut levels = vec![(0u64, 0u64, 0u64); root_level as usize + 1];
        if self.words.first().copied().unwrap_or(0) == 0 {
            // Empty scene: the root sentinel holds no voxel and counts as no node.
            return PathCounts { levels, voxels: 0 };
        }
        let mut paths = vec![0u64; self.words.len()];
        paths[0] = 1;
        for level in (1..=root_level).rev() {
            let (mut svo, mut svdag, mut bytes) = (0u64, 0u64, 0u64);
            let range = self.level_range(level);
            let mut p = range.start;
            while p < range.end {
                let children = self.words[p].count_ones() as u64;
                let count = paths[p];
                svo = svo.saturating_add(count);
                svdag += 1;
                bytes = bytes.saturating_add(count.saturating_mul(4 + 4 * children));
                for i in 0..children as usize {
                    let c = self.words[p + 1 + i] as usize;
                    paths[c] = paths[c].saturating_add(count);
                }
                p += 1 + children as usize;
            }
            levels[level as usize] = (svo, svdag, bytes);
        }
        let (mut svo, mut svdag, mut voxels) = (0u64, 0u64, 0u64);
        for p in self.level_range(0).step_by(2) {
            let count = paths[p];
            svo = svo.saturating_add(count);
            svdag += 1;
            voxels =
                voxels.saturating_add(count.saturating_mul(self.leaf_mask(p).count_ones() as u64));
        }
        levels[0] = (svo, svdag, svo.saturating_mul(8));
        PathCounts { levels, voxels }
    }

    /// Per-level SVO and SVDAG node counts, level 0 (leaves) first, root level last.
    pub fn level_stats(&self) -> Vec<LevelStats> {
        self.stats().levels
    }

    /// Number of occupied voxels (leaf popcounts times path counts).
    pub fn voxel_count(&self) -> u64 {
        self.path_counts().voxels
    }

    /// Bytes of the equivalent SVO in the same node format without sharing.
    pub fn bytes_svo(&self) -> u64 {
        self.stats().bytes.svo
    }

    /// Bytes of this DAG's node array (`words.len() * 4`).
    pub fn bytes_svdag32(&self) -> u64 {
        self.words.len() as u64 * 4
    }

    /// All statistics in one pass.
    pub fn stats(&self) -> DagStats {
        let counts = self.path_counts();
        DagStats {
            resolution: self.resolution,
            voxels: counts.voxels,
            bytes: ByteStats {
                svo: counts
                    .levels
                    .iter()
                    .fold(0u64, |a, l| a.saturating_add(l.2)),
                svdag32: self.bytes_svdag32(),
            },
            levels: counts
                .levels
                .iter()
                .enumerate()
                .map(|(l, &(svo, svdag, _))| LevelStats {
                    level: l as u32,
                    svo,
                    svdag,
                    ssvdag: None,
                    s: None,
                    a: None,
                    sa: None,
                    sat: None,
                })
                .collect(),
        }
    }

    /// [`Svdag::stats`] plus the per-level unique counts under transforms (`ssvdag`, `s`, `a`,
    /// `sa`, `sat`; see `docs/transforms.md`, `docs/translations.md`). Much slower than `stats`
    /// (the translation search dominates).
    pub fn stats_with_symmetry(&self) -> DagStats {
        self.stats().with_symmetry(&super::symmetry_counts(self))
    }
}

impl DagStats {
    /// Fills in the per-level transform counts (`ssvdag`, `s`, `a`, `sa`, `sat`).
    pub fn with_symmetry(mut self, counts: &[super::SymmetryLevelCounts]) -> DagStats {
        for (level, c) in self.levels.iter_mut().zip(counts) {
            level.ssvdag = Some(c.ssvdag);
            level.s = Some(c.s);
            level.a = Some(c.a);
            level.sa = Some(c.sa);
            level.sat = Some(c.sat);
        }
        self
    }
}
