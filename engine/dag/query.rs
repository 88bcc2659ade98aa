//! CPU point queries: voxel lookup, colour index, and full decoding back to a voxel set.
//!
//! All functions assume a structurally valid DAG (built by `from_voxels`, or loaded and
//! validated by `load`/`from_bytes`, or checked with [`Svdag::validate`]).

use super::{Svdag, VoxelIndex};
use crate::scene::{morton, Voxels};

impl Svdag {
    /// Bounding box `(min, max)` (max exclusive, in voxels) of the occupied space, rounded outward
    /// to cells of `N / 64` voxels (whole leaves for small grids); `None` for an empty scene.
    /// Cheap (it visits at most 64^3 cells), meant for camera framing.
    pub fn occupied_bounds(&self) -> Option<([u32; 3], [u32; 3])> {
        let stop_level = self.root_level().saturating_sub(6);
        let mut min = [u32::MAX; 3];
        let mut max = [0u32; 3];
        // Depth-first over paths down to `stop_level`: (node, level, corner).
        let mut stack = vec![(0usize, self.root_level(), [0u32; 3])];
        while let Some((node, level, corner)) = stack.pop() {
            let size = 4u32 << level;
            if level == stop_level {
                for a in 0..3 {
                    min[a] = min[a].min(corner[a]);
                    max[a] = max[a].max(corner[a] + size);
                }
                continue;
            }
            let half = size / 2;
            for octant in 0..8 {
                if let Some(child) = self.child(node, octant) {
                    let offset = [octant & 1, (octant >> 1) & 1, octant >> 2];
                    let child_corner = [0, 1, 2].map(|a| corner[a] + offset[a] * half);
                    stack.push((child, level - 1, child_corner));
                }
            }
        }
        (min[0] != u32::MAX).then_some((min, max))
    }

    /// Word offset of the child in octant `octant` of the inner node at `node`, if present.
    #[inline]
    pub fn child(&self, node: usize, octant: u32) -> Option<usize> {
        let mask = self.words[node];
        if mask & (1 << octant) == 0 {
            return None;
        }
        let rank = (mask & ((1 << octant) - 1)).count_ones() as usize;
        Some(self.words[node + 1 + rank] as usize)
    }

    /// 64-bit occupancy mask of the leaf at word `node`.
    #[inline]
    pub fn leaf_mask(&self, node: usize) -> u64 {
        self.words[node] as u64 | (self.words[node + 1] as u64) << 32
    }

    /// Walks from the root to the leaf holding voxel (x, y, z); calls `visit(node, octant)` for
    /// every inner node on the way. Returns the leaf's word offset, or None when the path ends
    /// in an empty octant or the voxel is outside the grid.
    fn descend(&self, x: u32, y: u32, z: u32, mut visit: impl FnMut(usize, u32)) -> Option<usize> {
        let n = self.resolution;
        if x >= n || y >= n || z >= n {
            return None;
        }
        let mut node = 0usize;
        for level in (1..=self.root_level()).rev() {
            let bit = level + 1;
            let octant = ((x >> bit) & 1) | ((y >> bit) & 1) << 1 | ((z >> bit) & 1) << 2;
            visit(node, octant);
            node = self.child(node, octant)?;
        }
        Some(node)
    }

    /// True when voxel (x, y, z) is occupied; coordinates outside the grid give false.
    pub fn contains(&self, x: u32, y: u32, z: u32) -> bool {
        match self.descend(x, y, z, |_, _| {}) {
            Some(leaf) => self.leaf_mask(leaf) >> morton::encode(x & 3, y & 3, z & 3) & 1 == 1,
            None => false,
        }
    }

    /// Index of voxel (x, y, z) in `colors` (depth-first Morton order), or None when the voxel
    /// is empty. Builds a [`VoxelIndex`] on every call (O(DAG size)): for many queries build
    /// one with [`Svdag::voxel_index`] and use [`VoxelIndex::color_index`].
    pub fn color_index(&self, x: u32, y: u32, z: u32) -> Option<u64> {
        self.voxel_index().color_index(self, x, y, z)
    }

    /// Per-node voxel counts of this DAG, for repeated [`VoxelIndex::color_index`] queries.
    pub fn voxel_index(&self) -> VoxelIndex {
        VoxelIndex::new(self)
    }

    /// Calls `f` with the Morton code of every occupied voxel, in ascending order
    /// (depth-first traversal, octants in ascending order).
    pub fn for_each_voxel(&self, mut f: impl FnMut(u64)) {
        if self.words.first().copied().unwrap_or(0) == 0 {
            return;
        }
        let root_level = self.root_level() as usize;
        // stack[d] = (node, Morton prefix of node, remaining child mask) at depth d.
        let mut stack: Vec<(usize, u64, u32)> = Vec::with_capacity(root_level + 1);
        stack.push((0, 0, self.words[0]));
        while let Some(top) = stack.last_mut() {
            let (node, prefix, remaining) = *top;
            if remaining == 0 {
                stack.pop();
                continue;
            }
            let octant = remaining.trailing_zeros();
            top.2 = remaining & (remaining - 1);
            let child = self.child(node, octant).expect("octant is in the mask");
            let child_prefix = prefix << 3 | octant as u64;
            if stack.len() == root_level {
                // `child` is a leaf.
                let mut mask = self.leaf_mask(child);
                while mask != 0 {
                    f(child_prefix << 6 | mask.trailing_zeros() as u64);
                    mask &= mask - 1;
                }
            } else {
                stack.push((child, child_prefix, self.words[child]));
            }
        }
    }

    /// Decodes every voxel (codes ascending, colours attached): the inverse of `from_voxels`.
    pub fn to_voxels(&self) -> Voxels {
        let mut codes = Vec::with_capacity(self.colors.len());
        self.for_each_voxel(|code| codes.push(code));
        Voxels {
            resolution: self.resolution,
            codes,
            colors: self.colors.clone(),
        }
    }
}

impl VoxelIndex {
    /// Colour index of voxel (x, y, z) in `dag` (the DAG this index was built from): the voxel
    /// counts of all preceding siblings along its path, plus its rank inside its leaf.
    pub fn color_index(&self, dag: &Svdag, x: u32, y: u32, z: u32) -> Option<u64> {
        let mut index = 0u64;
        let leaf = dag.descend(x, y, z, |node, octant| {
            let mask = dag.words[node];
            let before = (mask & ((1 << octant) - 1)).count_ones() as usize;
            index += dag.words[node + 1..node + 1 + before]
                .iter()
                .map(|&c| self.node_voxels[c as usize])
                .sum::<u64>();
        })?;
        let bit = morton::encode(x & 3, y & 3, z & 3);
        let mask = dag.leaf_mask(leaf);
        if mask >> bit & 1 == 0 {
            return None;
        }
        Some(index + (mask & ((1u64 << bit) - 1)).count_ones() as u64)
    }
}
