//! GPU slab hash tables (dissertation §4.3): variable-size items (1..=10 words) with stable
//! handles, four slab layouts ([`HashVariant`]), cooperative search/insert by a subgroup of any
//! size, and a SlabAlloc-style GPU slab allocator whose pool grows between passes.
//!
//! - [`layout`]: the memory layout shared word for word with `shaders/glsl/shared/hash_layout.h`,
//!   handles, the hash functions.
//! - [`alloc`]: the slab pool (super blocks, bitmasks, status block) seen from the host.
//! - [`table`]: [`GpuHashTable`], the batch passes (search, insert, find-or-insert, read).
//! - [`claim`]: the claim table that folds a batch's duplicate detection into the search and
//!   insert passes on single lanes.
//! - [`reference`](mod@reference): the sequential CPU reference on the same memory image, and the structural
//!   walk used by the tests on both.
//!
//! See `docs/hash.md`.

pub mod alloc;
pub mod claim;
pub mod dedup;
pub mod gc;
mod gpu_shared;
pub mod layout;
pub mod mixed;
pub mod reference;
pub mod table;

pub use alloc::{PoolOccupancy, SlabPool};
pub use layout::{Handle, HashStatus, HashVariant, SlabLayout, HANDLE_INVALID, HANDLE_MISS};
pub use reference::{ReferenceTable, TableImage, WalkReport};
pub use table::{
    GpuHashTable, HashTableConfig, InsertCheck, InsertReport, PendingInsert, TeamMode,
};

use crate::gpu::GpuError;

/// Errors of the hash tables.
#[derive(Debug, thiserror::Error)]
pub enum HashError {
    /// The GPU layer failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// A configuration the tables do not support (item size, bucket count, ...).
    #[error("invalid hash table configuration: {0}")]
    Config(String),
    /// An argument that does not fit the table (item buffer length, counts, handles).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// An item the layout cannot store (Atomic64 reserves the all-zero prefix for empty slots).
    #[error("item {index} cannot be stored in a {variant} table: {reason}")]
    InvalidItem {
        /// Index of the item in the batch.
        index: usize,
        /// Layout name.
        variant: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// The pool could not be grown enough for an insert (the device limit or [`layout::MAX_SUPER_BLOCKS`]).
    #[error(
        "slab pool exhausted: {items} items still not inserted with {super_blocks} super blocks"
    )]
    Exhausted {
        /// Items left without a slot.
        items: u32,
        /// Super blocks in the pool.
        super_blocks: u32,
    },
    /// The device ran a pass with a subgroup size other than the one it reported.
    #[error("pass ran with subgroup size {actual}, but the device reported {expected}")]
    SubgroupMismatch {
        /// `DeviceInfo::subgroup_size`.
        expected: u32,
        /// `gl_SubgroupSize` seen by the shader.
        actual: u32,
    },
    /// A pass found a bucket chain longer than the pool has slabs (a cycle): the table is
    /// corrupt. Every chain walk on the GPU is bounded, so this is reported instead of a hang.
    #[error("corrupt hash table: {walks} chain walks were cut off after more links than the pool has slabs")]
    CorruptTable {
        /// Chain walks cut off so far (`HashStatus::broken_chains`).
        walks: u32,
    },
}
