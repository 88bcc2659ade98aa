// The push constants the GPU editing passes share with their shaders, defined once (see
// engine/gpu_shared.rs): the engine expands this file into Rust structs, build.rs into
// `gen/edit.glsl`.
gpu_shared! {
    /// Push constants of every `shaders/glsl/edit/*.comp` pass (each names what it reads where).
    #[derive(Default)]
    pub(crate) struct EditPush {
        /// First input (svdag words, temporary nodes or leaves, traversal entries, dedup reps).
        pub(crate) src: uint64_t,
        /// Second input (node offsets, the level below's results).
        pub(crate) src2: uint64_t,
        /// First output (temporary nodes, this level's results, handles).
        pub(crate) dst: uint64_t,
        /// Second output (the result index per node, next traversal entries, slots).
        pub(crate) dst2: uint64_t,
        /// Per-size buffer addresses (`u64`s: the tables' super-block tables, or the level's
        /// item / handle / representative buffers).
        pub(crate) tables: uint64_t,
        /// Counters (`u32`s) the pass increments.
        pub(crate) counters: uint64_t,
        /// Records to process.
        pub(crate) count: uint,
        /// Tree level of the records (0 = leaves).
        pub(crate) level: uint,
        /// Pass flags (`EDIT_FLAG_*` in `edit/common.glsl`).
        pub(crate) flags: uint,
        /// Hash table variant id (all nine tables share it).
        pub(crate) variant: uint,
        /// Tool centre (xyz, voxels) and radius (w).
        pub(crate) tool: vec4,
        /// Tool shape (`EDIT_SHAPE_*`).
        pub(crate) shape: uint,
        /// Capacity of the output queue (records).
        pub(crate) capacity: uint,
        /// Material of the tool's new voxels (add, paint, fill).
        pub(crate) material: uint,
        /// The pre-edit root's child value (fill and copy read the scene before the edit).
        pub(crate) root: uint,
        /// Where a count computed on the GPU lies (a `u32`; 0: none): the pass then processes
        /// `min(that, count)` records (`edit_count()`), `count` being the buffers' capacity.
        pub(crate) count_at: uint64_t,
        /// Index of the input's first word in the word view build_items reads it through
        /// (`src` is that word's address).
        pub(crate) first: uint,
        /// Padding to the std430 size (a multiple of the `vec4`'s 16 bytes).
        pub(crate) pad: uint,
    }

    /// Push constants of `edit/merge_small_levels.comp`: the merge of an edit's small top
    /// levels in one dispatch (`engine/edit/gpu/small_levels.rs`).
    #[derive(Default)]
    pub(crate) struct SmallLevelsPush {
        /// Levels in the chain (the last one is the root's, which the dispatch also resolves).
        pub(crate) levels: uint,
    }

    /// Push constants of `edit/traverse_small_levels.comp`: the traversal's small top levels
    /// in one dispatch (`GpuHashDag::traverse`).
    #[derive(Default)]
    pub(crate) struct TraverseChainPush {
        /// Levels recorded in the bound records (the first is always traversed).
        pub(crate) levels: uint,
        /// A later level is traversed here only with at most this many entries.
        pub(crate) max_entries: uint,
    }
}
