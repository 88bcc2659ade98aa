//! SPIR-V of every `shaders/glsl/**/*.comp`, compiled by `build.rs` with glslc.
//!
//! One `pub const NAME: &[u32]` per shader, named after its path below `shaders/glsl`
//! (`render/primary.comp` -> `RENDER_PRIMARY`, `test/fill.comp` -> `TEST_FILL`), documented with
//! its source file. The `TEST_*` shaders (`shaders/glsl/test/`) exist only for the GPU-layer
//! tests (`tests/gpu_layer.rs`); they are compiled into the library because integration tests
//! can only reach its public items.

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
