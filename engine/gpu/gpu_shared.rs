// Push constants of the test shaders (shaders/glsl/test/), defined once (see
// engine/gpu_shared.rs): the engine expands this file into Rust structs, build.rs into
// `gen/test.glsl`.
gpu_shared! {
    /// Push constants of `test/fill.comp`.
    pub struct FillPush {
        /// Output words (`count` of them).
        pub out_addr: uint64_t,
        /// Optional per-invocation subgroup sizes (0 = none).
        pub aux_addr: uint64_t,
        /// Words to write.
        pub count: uint,
        /// Added to every word.
        pub seed: uint,
    }

    /// Push constants of `test/image.comp`.
    pub struct ImagePush {
        /// Image width in pixels.
        pub width: uint,
        /// Image height in pixels.
        pub height: uint,
        /// Mixed into every pixel.
        pub seed: uint,
    }

    /// Push constants of the decoder test shaders (`test/*_decode.comp`, `test/xform.comp`).
    pub struct DecodeTestPush {
        /// The input words (an encoded colour chunk; the transform test's records).
        pub chunk_addr: uint64_t,
        /// The output words (one RGBA8 word per colour; 8 words per transform test case).
        pub out_addr: uint64_t,
        /// Colours to decode, transform cases to run.
        pub count: uint,
        /// Padding to 8 bytes.
        pub pad: uint,
    }

    /// Push constants of `test/indirect_consume.comp`.
    pub struct IndirectConsumePush {
        /// `[count, x, y, z]` written by the compaction.
        pub count_args: uint64_t,
        /// The compacted words.
        pub input_words: uint64_t,
        /// One output word per survivor.
        pub output_words: uint64_t,
        /// Counters: invocations launched, invocations that did work.
        pub stats: uint64_t,
    }

    /// Push constants of `test/chain.comp`.
    pub struct ChainPush {
        /// The previous pass's words.
        pub src_addr: uint64_t,
        /// This pass's words.
        pub dst_addr: uint64_t,
        /// Words.
        pub count: uint,
        /// Index of the pass in the chain.
        pub pass_index: uint,
    }
}
