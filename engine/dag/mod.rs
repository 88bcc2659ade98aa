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
//!
//! Colours (optional) are one RGBA8 word per occupied voxel in depth-first Morton order.

pub(crate) mod build;
pub mod canonical;
pub mod digest;
pub mod encode;
mod export;
mod file;
mod index;
pub mod partition;
mod query;
pub mod raycast;
pub mod ssvdag;
mod stats;
pub mod stream;
pub mod transform;
pub mod translate;
mod validate;

use std::path::PathBuf;

pub use canonical::{
    analyze_symmetry, symmetry_counts, symmetry_counts_with_progress, CanonicalDag,
    SymmetryAnalysis, SymmetryLevelCounts, TransformPointer,
};
pub use export::{export_vox, export_xyz_u32, export_xyz_u32_file};
pub use file::{ColorFormat, Encoding, VdagFile, FORMAT_VERSION, MAGIC, OLDEST_FORMAT_VERSION};
pub use index::VoxelIndex;
pub use ssvdag::{Invariance, Ssvdag};
pub use stats::{ByteStats, DagStats, LevelStats};
pub use transform::{Transform, TransformSet};
pub use translate::{build_transform_dag, TLevel, TPointer, TransformDag};

/// Largest supported grid side: Morton codes hold 21 bits per axis.
pub const MAX_RESOLUTION: u32 = 1 << 21;

/// Errors of SVDAG construction, validation, file I/O and export.
#[derive(Debug, thiserror::Error)]
pub enum DagError {
    /// The grid side is not a power of two in `8..=MAX_RESOLUTION`.
    #[error("invalid resolution {0}: must be a power of two between 8 and 2^21")]
    InvalidResolution(u32),
    /// The voxel set handed to the builder breaks its invariants.
    #[error("invalid voxel set: {0}")]
    InvalidVoxels(String),
    /// The DAG needs more words than 32-bit child pointers can address.
    #[error("SVDAG needs {words} 32-bit words, more than 32-bit pointers can address")]
    TooLarge {
        /// Words the DAG would need.
        words: u64,
    },
    /// An in-memory `Svdag` violates the layout of the module docs.
    #[error("invalid SVDAG structure at word {word}: {reason}")]
    Invalid {
        /// Word offset where the problem was found.
        word: u64,
        /// What is wrong.
        reason: String,
    },
    /// A `.vdag` file is malformed; `offset` is the byte offset of the offending field.
    #[error("{}: byte offset {offset}: {reason}", path.display())]
    Format {
        /// File (or name given to `from_bytes`).
        path: PathBuf,
        /// Byte offset in the file.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
    /// An I/O error on a file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The part files given to a merge are not exactly the parts of one partitioned build.
    #[error("partitioned build: {0}")]
    Parts(String),
    /// An allocation sized by the input would pass the memory limit.
    #[error(transparent)]
    Memory(#[from] crate::safety::MemoryError),
    /// The export format cannot hold this DAG.
    #[error("{}: cannot export: {reason}", path.display())]
    Export {
        /// The output file.
        path: PathBuf,
        /// Why not.
        reason: String,
    },
}

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
