// The structs the hash passes share with their shaders, defined once (see engine/gpu_shared.rs):
// the engine expands this file into Rust structs, build.rs into `gen/hash.glsl`.
gpu_shared! {
    /// Status block of a table on the GPU (`HashStatus` buffer in `hash_layout.h`).
    #[derive(Default, PartialEq, Eq)]
    pub struct HashStatus {
        /// Items an insert pass could not place because no free slab was found (retried by the host).
        pub exhausted: uint,
        /// Slabs currently allocated (incremented by `alloc_slab`, decremented by `free_slab`).
        pub allocated_slabs: uint,
        /// Items rejected by the layout (Atomic64 zero prefix) since the last reset.
        pub invalid_items: uint,
        /// Non-zero when a pass ran with a subgroup size other than the specialised one.
        pub subgroup_mismatch: uint,
        /// Chain walks a pass cut off after more links than the pool has slabs: a bucket chain
        /// loops, the table is corrupt (the host reports `HashError::CorruptTable`).
        pub broken_chains: uint,
    }

    /// Push constants of every hash pass (search, insert, read, GC).
    #[derive(Default)]
    pub struct HashPush {
        /// Address of the super-block address table (`u64` per super block).
        pub super_blocks: uint64_t,
        /// Address of the bucket heads (`u32` link per bucket).
        pub heads: uint64_t,
        /// Address of the insert hints (`u32` link per bucket: a slab of the bucket's chain
        /// every slab before which was full, or 0 = start at the head).
        pub tails: uint64_t,
        /// Address of the `HashStatus` block.
        pub status: uint64_t,
        /// Address of the items (`item_words` words each).
        pub items: uint64_t,
        /// Address of the handles (one `u32` per item).
        pub handles: uint64_t,
        /// Address of a claim table (`engine/hash/claim.rs`; 0 = none): the search-and-claim
        /// pass and an insert round with `FLAG_CLAIMS` (`engine/hash/layout.rs`) use it.
        pub claims: uint64_t,
        /// Address of the representatives (one `u32` per item) the claim passes write.
        pub reps: uint64_t,
        /// A mixed batch: address of its sizes' item counts (one `u32` per entry of `mixed`),
        /// written on the GPU by an earlier pass; `count` is then only their sum's bound.
        pub count_at: uint64_t,
        /// Address of a mixed batch's entries (`engine/hash/mixed.rs`): per item size the
        /// `HashPush` of its table and buffers (0 = a batch of one size).
        pub mixed: uint64_t,
        /// Number of items (or handles).
        pub count: uint,
        /// Number of buckets.
        pub buckets: uint,
        /// Number of memory blocks in the pool (super blocks x 16).
        pub blocks: uint,
        /// Seed for the random block choice (changes every pass).
        pub seed: uint,
        /// `FLAG_*` bits of `engine/hash/layout.rs` (`HASH_FLAG_*` in `hash_layout.h`).
        pub flags: uint,
        /// Slots of the claim table (a power of two; 0 = none).
        pub claim_slots: uint,
        /// Words per item of a mixed batch's entry (the passes of one size ignore it: their
        /// pipelines are specialised for it).
        pub item_words: uint,
        /// Padding to a multiple of 8 bytes.
        pub pad: uint,
    }

    /// GC counters written by the mark and sweep passes (at `HashPush::items` during GC).
    #[derive(Default)]
    pub(crate) struct GcCounters {
        /// Live handles naming no slab of the pool (ignored).
        pub(crate) bad_handles: uint,
        /// Occupied slots cleared by the sweep.
        pub(crate) freed_items: uint,
        /// Slabs unlinked and returned to the allocator.
        pub(crate) freed_slabs: uint,
        /// Occupied slots the sweep kept (marked).
        pub(crate) kept_items: uint,
    }

    /// Push constants of the duplicate-detection passes.
    pub(crate) struct DedupPush {
        /// `count * KEY_WORDS` words.
        pub(crate) keys: uint64_t,
        /// `count` words.
        pub(crate) values: uint64_t,
        /// Slab table: `(buckets + pool_slabs) * SLAB_WORDS` words, zeroed; probe table:
        /// `buckets * (2 + KEY_WORDS)` words, the first `2 * buckets` zeroed.
        pub(crate) table: uint64_t,
        /// `count` words: the key's first entry (slab * 32 + slot, or the probe table's slot;
        /// between the probe table's passes 1 and 2 the key's hash).
        pub(crate) canon: uint64_t,
        /// `count` words: the representative value per input.
        pub(crate) reps: uint64_t,
        /// 3 words, zeroed.
        pub(crate) counters: uint64_t,
        /// Inputs.
        pub(crate) count: uint,
        /// Buckets (first slabs) of the slab table; slots of the probe table (a power of two).
        pub(crate) buckets: uint,
        /// Overflow slabs after the buckets (slab table).
        pub(crate) pool_slabs: uint,
        /// `SLAB_WORDS`, as a plain value for 64-bit address arithmetic.
        pub(crate) slab_words: uint,
    }
}
