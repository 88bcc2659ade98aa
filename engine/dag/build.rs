//! Bottom-up SVO -> SVDAG construction with per-level deduplication (dissertation §2.3).
//!
//! Level 0 groups the Morton-sorted voxels into 4^3 leaves (64-bit masks); every further level
//! groups the nodes of the level below by parent (key >> 3). Grouping runs in parallel over
//! chunks cut at parent boundaries; deduplication is a sequential pass over a `FxHashMap` with
//! fixed-size keys, which keeps node ids deterministic (first occurrence in Morton order).

use indicatif::ProgressBar;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::{DagError, Svdag, MAX_RESOLUTION};
use crate::scene::Voxels;

/// Nodes of one level before they are laid out: concatenated node words with child pointers
/// still given as node indices into the level below.
#[derive(Default)]
pub(crate) struct LevelNodes {
    /// Node words (leaf: 2 words; inner: mask + one index per child).
    pub(crate) words: Vec<u32>,
    /// Word offset of each unique node inside `words`.
    pub(crate) offsets: Vec<u32>,
}

/// An inner node before deduplication: child mask, then up to 8 child ids (unused slots 0).
type NodeKey = [u32; 9];

/// Minimum number of items per parallel chunk (below that, threads cost more than they save).
const MIN_CHUNK: usize = 1 << 16;

/// Splits `keys` (ascending) into about `parts` ranges such that no group of equal
/// `key >> shift` straddles two ranges.
fn split_at_groups(keys: &[u64], shift: u32) -> Vec<(usize, usize)> {
    let parts = (keys.len() / MIN_CHUNK).clamp(1, 4 * rayon::current_num_threads());
    let mut bounds = vec![0usize];
    for k in 1..parts {
        let mut i = (k * keys.len() / parts).max(*bounds.last().expect("non-empty"));
        while i > 0 && i < keys.len() && keys[i] >> shift == keys[i - 1] >> shift {
            i += 1;
        }
        if i > *bounds.last().expect("non-empty") && i < keys.len() {
            bounds.push(i);
        }
    }
    bounds.push(keys.len());
    bounds.windows(2).map(|w| (w[0], w[1])).collect()
}

/// Checks the builder's input invariants (in parallel).
fn validate_input(voxels: &Voxels) -> Result<(), DagError> {
    let n = voxels.resolution;
    if !n.is_power_of_two() || !(8..=MAX_RESOLUTION).contains(&n) {
        return Err(DagError::InvalidResolution(n));
    }
    let codes = &voxels.codes;
    if let Some(i) = codes
        .par_windows(2)
        .position_any(|w| w[0] >= w[1])
        .map(|i| i + 1)
    {
        return Err(DagError::InvalidVoxels(format!(
            "Morton codes not strictly ascending at index {i}"
        )));
    }
    let cells = (n as u64).pow(3);
    if let Some(&last) = codes.last() {
        if last >= cells {
            return Err(DagError::InvalidVoxels(format!(
                "Morton code {last} outside a {n}^3 grid"
            )));
        }
    }
    if !voxels.colors.is_empty() && voxels.colors.len() != codes.len() {
        return Err(DagError::InvalidVoxels(format!(
            "{} colours for {} voxels",
            voxels.colors.len(),
            codes.len()
        )));
    }
    Ok(())
}

/// Appends a node's words to a level, returning its new id, or `TooLarge` when the level's
/// words or ids no longer fit 32 bits.
pub(crate) fn push_node(level: &mut LevelNodes, node: &[u32]) -> Result<u32, DagError> {
    let offset = level.words.len();
    let id = level.offsets.len();
    if offset + node.len() > u32::MAX as usize || id >= u32::MAX as usize {
        return Err(DagError::TooLarge {
            words: (offset + node.len()) as u64,
        });
    }
    level.offsets.push(offset as u32);
    level.words.extend_from_slice(node);
    Ok(id as u32)
}

impl Svdag {
    /// Builds the SVDAG of a voxel set: groups voxels by 4^3 leaf, then repeatedly groups the
    /// nodes of one level by parent, deduplicating identical nodes on every level.
    pub fn from_voxels(voxels: &Voxels) -> Result<Svdag, DagError> {
        Self::from_voxels_with_progress(voxels, &ProgressBar::hidden())
    }

    /// [`Svdag::from_voxels`] reporting one progress step per level on `progress`
    /// (its length is set to the number of levels).
    pub fn from_voxels_with_progress(
        voxels: &Voxels,
        progress: &ProgressBar,
    ) -> Result<Svdag, DagError> {
        validate_input(voxels)?;
        let resolution = voxels.resolution;
        let root_level = resolution.trailing_zeros() - 2;
        progress.set_length(root_level as u64 + 1);
        progress.set_position(0);
        let mut levels: Vec<LevelNodes> = Vec::with_capacity(root_level as usize + 1);

        // Level 0: 4^3 leaves as 64-bit masks, built in parallel, deduplicated by mask.
        let codes = &voxels.codes;
        let chunks: Vec<(Vec<u64>, Vec<u64>)> = split_at_groups(codes, 6)
            .into_par_iter()
            .map(|(start, end)| {
                let codes = &codes[start..end];
                let mut keys = Vec::with_capacity(codes.len() / 4 + 1);
                let mut masks = Vec::with_capacity(codes.len() / 4 + 1);
                let mut i = 0;
                while i < codes.len() {
                    let key = codes[i] >> 6;
                    let mut mask = 0u64;
                    while i < codes.len() && codes[i] >> 6 == key {
                        mask |= 1u64 << (codes[i] & 63);
                        i += 1;
                    }
                    keys.push(key);
                    masks.push(mask);
                }
                keys.shrink_to_fit();
                masks.shrink_to_fit();
                (keys, masks)
            })
            .collect();
        let total: usize = chunks.iter().map(|c| c.0.len()).sum();
        let mut keys: Vec<u64> = Vec::with_capacity(total);
        let mut ids: Vec<u32> = Vec::with_capacity(total);
        let mut leaves = LevelNodes::default();
        {
            let mut leaf_ids: FxHashMap<u64, u32> = FxHashMap::default();
            leaf_ids.reserve(total / 4);
            for (chunk_keys, masks) in chunks {
                keys.extend_from_slice(&chunk_keys);
                for mask in masks {
                    let id = match leaf_ids.get(&mask) {
                        Some(&id) => id,
                        None => {
                            let id = push_node(&mut leaves, &[mask as u32, (mask >> 32) as u32])?;
                            leaf_ids.insert(mask, id);
                            id
                        }
                    };
                    ids.push(id);
                }
            }
        }
        levels.push(leaves);
        progress.inc(1);

        // Inner levels: group children by parent key, deduplicate (mask, child ids).
        for _level in 1..=root_level {
            let chunks: Vec<(Vec<u64>, Vec<NodeKey>)> = split_at_groups(&keys, 3)
                .into_par_iter()
                .map(|(start, end)| {
                    let (keys, ids) = (&keys[start..end], &ids[start..end]);
                    let mut parents = Vec::with_capacity(keys.len() / 2 + 1);
                    let mut nodes: Vec<NodeKey> = Vec::with_capacity(keys.len() / 2 + 1);
                    let mut j = 0;
                    while j < keys.len() {
                        let parent = keys[j] >> 3;
                        let mut node = [0u32; 9];
                        let mut n = 1;
                        while j < keys.len() && keys[j] >> 3 == parent {
                            node[0] |= 1 << (keys[j] & 7);
                            node[n] = ids[j];
                            n += 1;
                            j += 1;
                        }
                        parents.push(parent);
                        nodes.push(node);
                    }
                    parents.shrink_to_fit();
                    nodes.shrink_to_fit();
                    (parents, nodes)
                })
                .collect();
            let total: usize = chunks.iter().map(|c| c.0.len()).sum();
            keys.clear();
            keys.shrink_to(total);
            ids.clear();
            ids.shrink_to(total);
            let mut level = LevelNodes::default();
            let mut node_ids: FxHashMap<NodeKey, u32> = FxHashMap::default();
            node_ids.reserve(total / 4);
            for (parents, nodes) in chunks {
                keys.extend_from_slice(&parents);
                for node in nodes {
                    let id = match node_ids.get(&node) {
                        Some(&id) => id,
                        None => {
                            let len = 1 + node[0].count_ones() as usize;
                            let id = push_node(&mut level, &node[..len])?;
                            node_ids.insert(node, id);
                            id
                        }
                    };
                    ids.push(id);
                }
            }
            drop(node_ids);
            levels.push(level);
            progress.inc(1);
        }
        if keys.is_empty() {
            // Empty scene: a root with no children.
            let root = levels.last_mut().expect("at least one level");
            root.offsets.push(0);
            root.words.push(0);
        }
        Self::lay_out(resolution, levels, voxels.colors.clone())
    }

    /// Concatenates the levels top-down and turns child node indices into absolute word offsets.
    pub(crate) fn lay_out(
        resolution: u32,
        levels: Vec<LevelNodes>,
        colors: Vec<u32>,
    ) -> Result<Svdag, DagError> {
        let mut level_starts = vec![0u64; levels.len()];
        let mut total = 0u64;
        for (l, level) in levels.iter().enumerate().rev() {
            level_starts[l] = total;
            total += level.words.len() as u64;
        }
        if total > u32::MAX as u64 {
            return Err(DagError::TooLarge { words: total });
        }
        let mut words = Vec::with_capacity(total as usize);
        let mut levels = levels;
        for l in (0..levels.len()).rev() {
            // Each level is freed once copied (its parents, above it, are done), so the peak is
            // the laid-out words plus the levels not yet copied.
            let (below, rest) = levels.split_at_mut(l);
            let level = std::mem::take(&mut rest[0]);
            if l == 0 {
                words.extend_from_slice(&level.words);
                continue;
            }
            let below = &below[l - 1];
            let below_start = level_starts[l - 1] as u32;
            for &offset in &level.offsets {
                let offset = offset as usize;
                let mask = level.words[offset];
                words.push(mask);
                let children = &level.words[offset + 1..offset + 1 + mask.count_ones() as usize];
                words.extend(
                    children
                        .iter()
                        .map(|&child| below_start + below.offsets[child as usize]),
                );
            }
        }
        Ok(Svdag {
            resolution,
            words,
            level_starts,
            colors,
        })
    }
}
