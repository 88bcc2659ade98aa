//! SVO -> SVDAG construction, the `.vdag` file format and CPU queries (voxel lookup, ray cast).
//!
//! CPU-only; the reference for every GPU traversal.
//!
//! # In-memory layout of an SVDAG (encoding `svdag32`, Kämpe et al. 2013)
//! All nodes live in one flat `Vec<u32>` (`Svdag::words`), so the same array can be uploaded to
//! the GPU unchanged. Levels are numbered from the bottom: level 0 holds the 4^3 leaves, level
//! `l` nodes cover `4 << l` voxels per side, and the root is at level `log2(N) - 2`.
//! Levels are stored top-down: the root is always at word 0, leaves come last.
//! - Inner node at word `p`: `words[p]` = child mask (bit `o` set when octant `o = x | y<<1 | z<<2`
//!   is non-empty; upper 24 bits zero), followed by one absolute word offset per set bit, in
//!   ascending octant order.
//! - Leaf at word `p`: two words, the low then the high half of a 64-bit mask whose bit
//!   `morton(x, y, z)` (x, y, z in 0..4, see `scene::morton`) is the voxel at that position.
//! - An empty scene is a root with child mask 0.
//! Colours (optional) are one RGBA8 word per occupied voxel in depth-first Morton order.

mod build;
mod index;
pub mod raycast;

pub use index::VoxelIndex;

/// A sparse voxel DAG with 32-bit child pointers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Svdag {
    /// Grid side length N (power of two, at least 8).
    pub resolution: u32,
    /// All nodes, root at word 0 (layout in the module docs).
    pub words: Vec<u32>,
    /// `level_starts[l]` = first word of level `l` (0 = leaves); the root level is the last entry.
    pub level_starts: Vec<u64>,
    /// Per-voxel RGBA8 colours in depth-first Morton order; empty when the scene has none.
    pub colors: Vec<u32>,
}

impl Svdag {
    /// Level of the root node: `log2(resolution) - 2`.
    pub fn root_level(&self) -> u32 {
        self.resolution.trailing_zeros() - 2
    }
}
