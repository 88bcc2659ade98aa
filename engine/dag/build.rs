//! Bottom-up SVO -> SVDAG construction with per-level deduplication (dissertation §2.3).

use rustc_hash::FxHashMap;

use super::Svdag;
use crate::scene::Voxels;

/// Nodes of one level before they are laid out: concatenated node words with child pointers
/// still given as node indices into the level below.
#[derive(Default)]
struct LevelNodes {
    /// Node words (leaf: 2 words; inner: mask + one index per child).
    words: Vec<u32>,
    /// Word offset of each unique node inside `words`.
    offsets: Vec<u32>,
}

impl Svdag {
    /// Builds the SVDAG of a voxel set: groups voxels by 4^3 leaf, then repeatedly groups the
    /// nodes of one level by parent, deduplicating identical nodes on every level.
    pub fn from_voxels(voxels: &Voxels) -> Svdag {
        let resolution = voxels.resolution;
        assert!(
            resolution.is_power_of_two() && resolution >= 8,
            "resolution must be a power of two >= 8"
        );
        let root_level = resolution.trailing_zeros() - 2;
        let mut levels: Vec<LevelNodes> = Vec::with_capacity(root_level as usize + 1);

        // Level 0: 4^3 leaves as 64-bit masks, deduplicated by mask.
        let mut leaves = LevelNodes::default();
        let mut leaf_ids: FxHashMap<u64, u32> = FxHashMap::default();
        let mut keyed: Vec<(u64, u32)> = Vec::new();
        let mut i = 0;
        let codes = &voxels.codes;
        while i < codes.len() {
            let key = codes[i] >> 6;
            let mut mask = 0u64;
            while i < codes.len() && codes[i] >> 6 == key {
                mask |= 1u64 << (codes[i] & 63);
                i += 1;
            }
            let id = *leaf_ids.entry(mask).or_insert_with(|| {
                leaves.offsets.push(leaves.words.len() as u32);
                leaves
                    .words
                    .extend_from_slice(&[mask as u32, (mask >> 32) as u32]);
                (leaves.offsets.len() - 1) as u32
            });
            keyed.push((key, id));
        }
        drop(leaf_ids);
        levels.push(leaves);

        // Inner levels: group children by parent key, deduplicate (mask, child ids).
        for _level in 1..=root_level {
            let mut nodes = LevelNodes::default();
            let mut node_ids: FxHashMap<Vec<u32>, u32> = FxHashMap::default();
            let mut parents: Vec<(u64, u32)> = Vec::new();
            let mut j = 0;
            while j < keyed.len() {
                let parent = keyed[j].0 >> 3;
                let mut node = vec![0u32];
                while j < keyed.len() && keyed[j].0 >> 3 == parent {
                    node[0] |= 1 << (keyed[j].0 & 7);
                    node.push(keyed[j].1);
                    j += 1;
                }
                let next_id = nodes.offsets.len() as u32;
                let id = match node_ids.get(&node) {
                    Some(&id) => id,
                    None => {
                        nodes.offsets.push(nodes.words.len() as u32);
                        nodes.words.extend_from_slice(&node);
                        node_ids.insert(node, next_id);
                        next_id
                    }
                };
                parents.push((parent, id));
            }
            keyed = parents;
            levels.push(nodes);
        }
        if keyed.is_empty() {
            // Empty scene: a root with no children.
            let root = levels.last_mut().expect("at least one level");
            root.offsets.push(0);
            root.words.push(0);
        }
        Self::lay_out(resolution, levels, voxels.colors.clone())
    }

    /// Concatenates the levels top-down and turns child node indices into absolute word offsets.
    fn lay_out(resolution: u32, levels: Vec<LevelNodes>, colors: Vec<u32>) -> Svdag {
        let mut level_starts = vec![0u64; levels.len()];
        let mut total = 0u64;
        for (l, level) in levels.iter().enumerate().rev() {
            level_starts[l] = total;
            total += level.words.len() as u64;
        }
        assert!(
            total <= u32::MAX as u64,
            "SVDAG too large for 32-bit pointers"
        );
        let mut words = Vec::with_capacity(total as usize);
        for l in (0..levels.len()).rev() {
            let level = &levels[l];
            if l == 0 {
                words.extend_from_slice(&level.words);
                continue;
            }
            let below = &levels[l - 1];
            let below_start = level_starts[l - 1] as u32;
            for &offset in &level.offsets {
                let offset = offset as usize;
                let mask = level.words[offset];
                words.push(mask);
                for c in 0..mask.count_ones() as usize {
                    let child = level.words[offset + 1 + c] as usize;
                    words.push(below_start + below.offsets[child]);
                }
            }
        }
        Svdag {
            resolution,
            words,
            level_starts,
            colors,
        }
    }
}
