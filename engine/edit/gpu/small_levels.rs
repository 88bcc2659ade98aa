//! The merge of an edit's small top levels in one dispatch
//! (`shaders/glsl/edit/merge_small_levels.comp`; docs/editing-gpu.md, "Speed, round 15").
//!
//! An edit's top levels hold one to a few dozen temporary nodes each, yet their merge took two
//! dispatches per level (build_items, then the fused search, claim and insert of
//! [`crate::hash::mixed`]), and on lavapipe each dispatch costs a hand-off to the driver's worker
//! threads that outweighs the work. Where every level from some level up to the root has at
//! most [`MAX_NODES`] nodes, one dispatch runs those levels' passes in turn, bottom-up, with a
//! subgroup barrier after each (the workgroup is one subgroup), then the root level's resolve:
//! the same pass bodies, their parameters read from records in memory: per level its
//! build_items parameters, its mixed batch and the batch's entries, read as `uvec4` texels
//! (lavapipe reads memory through an address inside the level loop one lane at a time, a loop
//! per field; docs/gpu.md, "Records read as texels").
//!
//! Its workgroup is one SIMD group (the subgroup size): lavapipe runs each SIMD group of a
//! workgroup as a coroutine that every barrier suspends, so with the mixed passes' 64 lanes
//! (eight coroutines on lavapipe) the chain ran ~4x the instructions of the dispatches it
//! replaced, and large edits got slower; with one SIMD group it runs fewer than they did.

use std::sync::Arc;

use super::super::gpu_shared::{EditPush, SmallLevelsPush};
use crate::gpu::{
    shaders, BindingKind, Bound, Buffer, Commands, ComputePipeline, ComputePipelineDesc,
    GpuContext, GpuError, MemLocation, Profiler, WordTexels,
};
use crate::hash::layout::HashPush;
use crate::hash::mixed::MIXED_SIZES;
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
/// the level's mixed batch ([`crate::hash::mixed::MixedPasses::batch`]) and the batch's entries.
pub(super) type SmallLevel = (EditPush, HashPush, [HashPush; MIXED_SIZES]);

/// Records of a chain (this one's or the traversal's, `edit/traverse_small_levels.comp`) and
/// their `uvec4` view, binding 0 of its dispatch.
pub(super) struct ChainRecords {
    buffer: Buffer,
    view: WordTexels,
}

impl ChainRecords {
    /// Records of `bytes` bytes (a multiple of 16), named `name`.
    pub(super) fn new(
        ctx: &Arc<GpuContext>,
        name: &str,
        bytes: usize,
    ) -> Result<ChainRecords, GpuError> {
        let buffer = ctx.create_buffer(name, bytes as u64, MemLocation::GpuOnly)?;
        let view = ctx.record_texels(&buffer)?;
        Ok(ChainRecords { buffer, view })
    }

    /// The buffer (the host uploads the records into it).
    pub(super) fn buffer(&self) -> &Buffer {
        &self.buffer
    }

    /// The dispatch's binding.
    pub(super) fn bound(&self) -> [Bound<'_>; 1] {
        [Bound::Words(&self.view)]
    }
}

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
            bindings: &[BindingKind::TexelBuffer],
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

    /// Records for `levels` levels.
    pub(super) fn records(ctx: &Arc<GpuContext>, levels: usize) -> Result<ChainRecords, GpuError> {
        let per_level =
            std::mem::size_of::<EditPush>() + (1 + MIXED_SIZES) * std::mem::size_of::<HashPush>();
        ChainRecords::new(ctx, "edit small levels records", levels * per_level)
    }

    /// Records the upload of `levels`' records into `records` ([`SmallLevelsPass::records`])
    /// and the dispatch (profiled as "edit merge small levels"), a barrier after it. Before it
    /// the levels' buffers are set as for their own passes (address buffers uploaded, counters
    /// zeroed, claim tables cleared, batch entries uploaded); the last level is the root's.
    pub(super) fn record<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        records: &'a ChainRecords,
        levels: &[SmallLevel],
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        if levels.is_empty() {
            return Err(GpuError::InvalidArgument(
                "merge of small levels without a level".into(),
            ));
        }
        // The shader's layout: every level's EditPush, then every level's batch, then every
        // level's entries (merge_small_levels.comp, hash_level_entry).
        let edits: Vec<EditPush> = levels.iter().map(|l| l.0).collect();
        let batches: Vec<HashPush> = levels.iter().map(|l| l.1).collect();
        let entries: Vec<HashPush> = levels.iter().flat_map(|l| l.2).collect();
        let batches_at = std::mem::size_of_val(edits.as_slice()) as u64;
        let entries_at = batches_at + std::mem::size_of_val(batches.as_slice()) as u64;
        cmd.upload(&records.buffer, 0, &edits)?;
        cmd.upload(&records.buffer, batches_at, &batches)?;
        cmd.upload(&records.buffer, entries_at, &entries)?;
        let push = SmallLevelsPush {
            levels: levels.len() as u32,
        };
        cmd.begin_pass(profiler, "edit merge small levels");
        cmd.dispatch(
            &self.pipeline,
            [1, 1, 1],
            bytemuck::bytes_of(&push),
            &records.bound(),
        )?;
        cmd.end_pass(profiler);
        cmd.barrier();
        Ok(())
    }
}
