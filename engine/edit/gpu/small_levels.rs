//! The merge of an edit's small top levels in one dispatch
//! (`shaders/glsl/edit/merge_small_levels.comp`; docs/editing-gpu.md, "Speed, round 15").
//!
//! An edit's top levels hold one to a few dozen temporary nodes each, yet their merge took two
//! dispatches per level (build_items, then the fused search, claim and insert of
//! [`crate::hash::mixed`]), and on lavapipe each dispatch costs a hand-off to the driver's worker
//! threads that outweighs the work. Where every level from some level up to the root has at
//! most [`MAX_NODES`] nodes, one dispatch runs those levels' passes in turn, bottom-up, with a
//! subgroup barrier after each (the workgroup is one subgroup), then the root level's resolve:
//! the same pass bodies, their parameters read from records in memory.
//!
//! Its workgroup is one SIMD group (the subgroup size): lavapipe runs each SIMD group of a
//! workgroup as a coroutine that every barrier suspends, so with the mixed passes' 64 lanes
//! (eight coroutines on lavapipe) the chain ran ~4x the instructions of the dispatches it
//! replaced, and large edits got slower; with one SIMD group it runs fewer than they did.

use std::sync::Arc;

use super::super::gpu_shared::{EditPush, SmallLevelsPush};
use crate::gpu::{
    shaders, Buffer, Commands, ComputePipeline, ComputePipelineDesc, GpuContext, GpuError,
    MemLocation, Profiler,
};
use crate::hash::layout::HashPush;
use crate::hash::GpuHashTable;

/// The largest level (temporary nodes) the chain takes: a level of more gets its own passes,
/// and so does every level below it. 64, 128 and 256 timed the same on bunny 1024^3's 600
/// large spheres (lavapipe, alternated six times); each lane takes up to 16 nodes here.
pub(super) const MAX_NODES: u32 = 128;

/// The pipeline of `merge_small_levels`.
pub(super) struct SmallLevelsPass {
    pipeline: ComputePipeline,
}

/// What the dispatch does for one level: build_items' parameters (those of its own dispatch),
/// then the level's mixed batch ([`crate::hash::mixed::MixedPasses::batch`]).
pub(super) type SmallLevel = (EditPush, HashPush);

impl SmallLevelsPass {
    /// The pass for tables shaped like `table` (its variant; single lanes), for a scene with or
    /// without materials.
    pub(super) fn new(
        ctx: &Arc<GpuContext>,
        table: &GpuHashTable,
        materials: u32,
    ) -> Result<SmallLevelsPass, GpuError> {
        let [_, subgroup, variant, _, team] = table.spec_constants();
        let pipeline = ctx.create_compute_pipeline(&ComputePipelineDesc {
            name: "edit merge small levels",
            spirv: shaders::EDIT_MERGE_SMALL_LEVELS,
            // The hash passes' five constants (a workgroup of one SIMD group, item words 0:
            // mixed batches), then the edit passes' two (`EDIT_SPEC_ID_BASE` 5 in the shader).
            spec_constants: &[
                subgroup,
                subgroup,
                variant,
                0,
                team,
                super::TOOL_FROM_FLAGS,
                materials,
            ],
            push_constant_size: std::mem::size_of::<SmallLevelsPush>() as u32,
            bindings: &[],
        })?;
        Ok(SmallLevelsPass { pipeline })
    }

    /// The pass's pipeline (to warm ahead).
    pub(super) fn pipeline(&self) -> &ComputePipeline {
        &self.pipeline
    }

    /// Whether a level of `nodes` temporary nodes joins the chain.
    pub(super) fn takes(&self, nodes: u32) -> bool {
        nodes <= MAX_NODES
    }

    /// A buffer for the records of `levels` levels.
    pub(super) fn records(ctx: &Arc<GpuContext>, levels: usize) -> Result<Buffer, GpuError> {
        let bytes = levels * (std::mem::size_of::<EditPush>() + std::mem::size_of::<HashPush>());
        ctx.create_buffer(
            "edit small levels records",
            bytes as u64,
            MemLocation::GpuOnly,
        )
    }

    /// Records the upload of `levels`' records into `records` ([`SmallLevelsPass::records`])
    /// and the dispatch (profiled as "edit merge small levels"), a barrier after it. Before it
    /// the levels' buffers are set as for their own passes (address buffers uploaded, counters
    /// zeroed, claim tables cleared, batch entries uploaded); the last level is the root's.
    pub(super) fn record<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        records: &'a Buffer,
        levels: &[SmallLevel],
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        if levels.is_empty() {
            return Err(GpuError::InvalidArgument(
                "merge of small levels without a level".into(),
            ));
        }
        let edits: Vec<EditPush> = levels.iter().map(|l| l.0).collect();
        let batches: Vec<HashPush> = levels.iter().map(|l| l.1).collect();
        let batches_at = (edits.len() * std::mem::size_of::<EditPush>()) as u64;
        cmd.upload(records, 0, &edits)?;
        cmd.upload(records, batches_at, &batches)?;
        let push = SmallLevelsPush {
            edit_levels: records.address(),
            hash_levels: records.address() + batches_at,
            levels: levels.len() as u32,
            ..SmallLevelsPush::default()
        };
        cmd.begin_pass(profiler, "edit merge small levels");
        cmd.dispatch(&self.pipeline, [1, 1, 1], bytemuck::bytes_of(&push), &[])?;
        cmd.end_pass(profiler);
        cmd.barrier();
        Ok(())
    }
}
