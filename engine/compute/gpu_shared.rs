// The push constants the GPU primitives share with their shaders, defined once (see
// engine/gpu_shared.rs): the engine expands this file into Rust structs, build.rs into
// `gen/compute.glsl`.
gpu_shared! {
    /// Push constants of `compute/scan_reduce.comp`.
    pub(super) struct ReducePush {
        /// The level's input words.
        pub(super) input_words: uint64_t,
        /// One sum per block.
        pub(super) partials: uint64_t,
        /// Elements of the level.
        pub(super) n: uint,
        /// 1: sum the flags "value != 0" (compaction), 0: sum the values.
        pub(super) predicate: uint,
    }

    /// Push constants of `compute/scan_block.comp`.
    pub(super) struct BlockPush {
        /// The level's input words.
        pub(super) input_words: uint64_t,
        /// The exclusive scan, or the compacted values.
        pub(super) output_words: uint64_t,
        /// Per-block starting offsets (0 = the level fits one block).
        pub(super) offsets: uint64_t,
        /// Where the single block writes the total (0 = nowhere).
        pub(super) total: uint64_t,
        /// Values to scatter (compaction).
        pub(super) values: uint64_t,
        /// Elements of the level.
        pub(super) n: uint,
        /// `MODE_SCAN` or `MODE_COMPACT`.
        pub(super) mode: uint,
    }

    /// Push constants of `compute/indirect_args.comp`.
    pub(super) struct ArgsPush {
        /// `[count, x, y, z]`: the count in, the dispatch arguments out.
        pub(super) count_args: uint64_t,
        /// Invocations per workgroup of the pass to size.
        pub(super) group_size: uint,
        /// Padding to 8 bytes.
        pub(super) pad: uint,
    }

    /// Push constants of `compute/radix_hist_*.comp`, `radix_rank_*` and `radix_scatter_*`.
    pub(super) struct RadixPush {
        /// Keys read by this pass.
        pub(super) keys_in: uint64_t,
        /// Values read by this pass.
        pub(super) values_in: uint64_t,
        /// Keys written by the scatter.
        pub(super) keys_out: uint64_t,
        /// Values written by the scatter.
        pub(super) values_out: uint64_t,
        /// Per-(digit, block) histogram / offsets.
        pub(super) offsets: uint64_t,
        /// Keys.
        pub(super) n: uint,
        /// Bit position of this pass's digit.
        pub(super) shift: uint,
    }
}
