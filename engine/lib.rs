//! voxdag: store, compress, render and edit very large voxel scenes as sparse voxel DAGs.
//!
//! Data flows one way through the modules:
//! `scene` (import + voxelize) -> `dag` (SVO -> SVDAG, file format, CPU queries)
//! -> `attr` (per-voxel colours in chunks, colour codecs) -> `gpu` (Vulkan device layer)
//! -> `render` (GPU traversal, CPU reference renderer), `attr_gpu` (colour codec passes) and
//! `hash` (GPU slab hash tables, allocator and garbage collection for editing), `edit` (the hash
//! DAG stored in those tables and the edit tools).
//! `compute` holds the GPU primitives (prefix sum, stream compaction, radix sort) that
//! GPU-driven passes build on.

#![warn(missing_docs)]

// First: its `gpu_shared!` macro is used by the rooms' `gpu_shared.rs` files below.
#[macro_use]
pub mod gpu_shared;

pub mod atomic_file;
pub mod attr;
pub mod attr_gpu;
pub mod color;
pub mod compute;
pub mod dag;
pub mod edit;
pub mod gpu;
pub mod hash;
pub mod ooc;
pub mod render;
pub mod safety;
pub mod scene;
