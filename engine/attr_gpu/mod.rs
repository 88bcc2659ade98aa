//! The GPU room of the colour codecs: host drivers of the compute passes in
//! `shaders/glsl/attr/`, each bit-identical to its CPU reference in [`crate::attr`].

mod gpu_shared;
pub mod lossless;
