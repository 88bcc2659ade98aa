//! Editing: the hash DAG (every node of the scene in the per-size slab hash tables), its item
//! format, and the edit tools built on it (dissertation ch. 4).

pub mod cpu;
pub mod gpu;
pub mod gpu_gc;
mod gpu_shared;
pub mod item;
pub mod replay;
pub mod tool;
pub mod walk;
