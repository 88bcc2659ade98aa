//! SPIR-V of every `shaders/glsl/**/*.comp`, compiled by `build.rs` with glslc.
//!
//! One `pub const NAME: &[u32]` per shader, named after its path below `shaders/glsl`
//! (`render/primary.comp` -> `RENDER_PRIMARY`, `test/fill.comp` -> `TEST_FILL`).

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
