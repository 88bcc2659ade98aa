//! A live hash DAG ready to render: an svdag32 DAG loaded into a [`GpuHashDag`] (nine slab hash
//! tables, `docs/editing-gpu.md`) together with the renderer's binding of it
//! ([`GpuRenderer::bind_hash_dag`]). `voxdag render --hash-dag` and the benchmarks use it; the
//! editor binds its own `GpuHashDag` the same way.

use std::sync::Arc;

use super::gpu::{GpuRenderer, GpuScene};
use crate::dag::Svdag;
use crate::edit::gpu::{GpuDagError, GpuHashDag, GpuHashDagConfig};
use crate::gpu::{GpuContext, Profiler};
use crate::hash::HashVariant;

/// A hash DAG and the scene that renders it in place. The scene is declared first, so it is
/// dropped before the tables it reads.
pub struct HashDagScene {
    /// The binding: pass it to `GpuRenderer::record` / `render` and `GpuPathTracer`.
    pub scene: GpuScene,
    /// The tables (edit it, then `scene.set_hash_root(&dag, dag.root())`).
    pub dag: GpuHashDag,
}

impl HashDagScene {
    /// Loads `dag` (geometry only) into tables of `variant` and binds them for `renderer`.
    pub fn load(
        ctx: &Arc<GpuContext>,
        renderer: &GpuRenderer,
        dag: &Svdag,
        variant: HashVariant,
        profiler: Option<&mut Profiler>,
    ) -> Result<HashDagScene, GpuDagError> {
        let config = GpuHashDagConfig::sized_by_load(variant);
        let hash = GpuHashDag::load(ctx, &config, dag, profiler)?;
        let scene = renderer.bind_hash_dag(&hash, None)?;
        Ok(HashDagScene { scene, dag: hash })
    }
}
