//! Per-node voxel counts, which turn a path through the DAG into an index into the colour array.

use super::Svdag;

/// Voxel count of every node's subtree, indexed by the node's first word.
///
/// A voxel's colour index (depth-first Morton order) is the sum of the counts of the siblings that
/// precede it on its path from the root, plus its rank inside its leaf.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VoxelIndex {
    /// `node_voxels[p]` = voxels below the node starting at word `p`; 0 for words that start no node.
    pub node_voxels: Vec<u64>,
}

impl VoxelIndex {
    /// Computes the counts bottom-up, one level at a time.
    pub fn new(dag: &Svdag) -> VoxelIndex {
        let mut node_voxels = vec![0u64; dag.words.len()];
        // Leaves: 2 words each, from the start of level 0 to the end of the array.
        let leaf_start = dag.level_starts[0] as usize;
        for p in (leaf_start..dag.words.len()).step_by(2) {
            node_voxels[p] = (dag.words[p].count_ones() + dag.words[p + 1].count_ones()) as u64;
        }
        // Inner levels, bottom-up.
        for l in 1..dag.level_starts.len() as u32 {
            for p in dag.node_starts(l) {
                let children = dag.words[p].count_ones() as usize;
                node_voxels[p] = dag.words[p + 1..p + 1 + children]
                    .iter()
                    .map(|&c| node_voxels[c as usize])
                    .sum();
            }
        }
        VoxelIndex { node_voxels }
    }
}
