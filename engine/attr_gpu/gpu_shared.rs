// The push constants the colour-codec passes share with their shaders, defined once (see
// engine/gpu_shared.rs): the engine expands this file into Rust structs, build.rs into
// `gen/attr.glsl`.
gpu_shared! {
    /// Push constants of `lossless_plan.comp`.
    pub(crate) struct PlanPush {
        /// `count` RGBA8 words.
        pub(crate) colors: uint64_t,
        /// 4 words per block.
        pub(crate) plans: uint64_t,
        /// Colours.
        pub(crate) count: uint,
        /// Codec variant (RGB888 / RGB565).
        pub(crate) variant: uint,
    }

    /// Push constants of `lossless_scan.comp`.
    pub(crate) struct ScanPush {
        /// 4 words per block.
        pub(crate) plans: uint64_t,
        /// `blocks + 1` uint64 offsets.
        pub(crate) offsets: uint64_t,
        /// Blocks.
        pub(crate) blocks: uint,
        /// Padding to 8 bytes.
        pub(crate) pad: uint,
    }

    /// Push constants of `lossless_write.comp`.
    pub(crate) struct WritePush {
        /// `count` RGBA8 words.
        pub(crate) colors: uint64_t,
        /// 4 words per block.
        pub(crate) plans: uint64_t,
        /// `blocks + 1` uint64 offsets.
        pub(crate) offsets: uint64_t,
        /// The encoded words.
        pub(crate) out_words: uint64_t,
        /// Colours.
        pub(crate) count: uint,
        /// Codec variant (RGB888 / RGB565).
        pub(crate) variant: uint,
    }

    /// Push constants of `lossless_decode.comp`.
    pub(crate) struct DecodePush {
        /// The encoded words of one chunk.
        pub(crate) chunk: uint64_t,
        /// One RGBA8 word per colour.
        pub(crate) out_colors: uint64_t,
        /// Colours.
        pub(crate) count: uint,
        /// Padding to 8 bytes.
        pub(crate) pad: uint,
    }
}
