//! `build_items`' reads through word views (`docs/editing-gpu.md`, "Speed, round 10").
//!
//! On lavapipe a load through a buffer address is a loop over the SIMD lanes with a branch per
//! lane, run at every load site whether or not a lane needs it, while a texel fetch gathers
//! for all lanes at once (a call of a short function). build_items reads a node's input words
//! and, per child slot, the level below's result, slot, representative and handle: most of its
//! load sites. It reads them as
//! `R32_UINT` uniform texel views of those buffers ([`LevelTexels`]) where every buffer fits in
//! a view (`maxTexelBufferElements` words, 2^27 on lavapipe and common GPUs), and through
//! addresses otherwise (the loads of scenes that large; a second pipeline, specialization
//! constant 2, made when first needed).

use std::sync::{Arc, OnceLock};

use crate::gpu::{
    made_once, shaders, BindingKind, Bound, Buffer, Commands, ComputePipeline, ComputePipelineDesc,
    GpuContext, GpuError, MemLocation, WordTexels,
};

use super::super::gpu_shared::EditPush;

/// Views build_items binds (set 0, bindings 0-4): its input, the level below's results, and
/// the slots, representatives and handles of the level whose pending results it resolves.
pub(super) struct LevelTexels([WordTexels; 5]);

impl LevelTexels {
    /// Views of `buffers` (in binding order), or None where one has more words than a view
    /// takes.
    pub(super) fn new(
        ctx: &Arc<GpuContext>,
        buffers: [&Buffer; 5],
    ) -> Result<Option<LevelTexels>, GpuError> {
        if !buffers.iter().all(|b| fits(ctx, b)) {
            return Ok(None);
        }
        let [a, b, c, d, e] = buffers;
        Ok(Some(LevelTexels([
            ctx.word_texels(a)?,
            ctx.word_texels(b)?,
            ctx.word_texels(c)?,
            ctx.word_texels(d)?,
            ctx.word_texels(e)?,
        ])))
    }

    /// The dispatch's bindings.
    pub(super) fn bound(&self) -> [Bound<'_>; 5] {
        self.0.each_ref().map(Bound::Words)
    }
}

/// Whether a view can take all of `buffer`'s words.
fn fits(ctx: &GpuContext, buffer: &Buffer) -> bool {
    buffer.size() / 4 <= ctx.info().max_texel_buffer_elements as u64
}

/// build_items reading through views, and (made when first needed) through addresses.
pub(super) struct BuildItemsPipelines {
    by_texels: ComputePipeline,
    by_address: OnceLock<ComputePipeline>,
    /// Specialization constant 1: whether leaves carry materials.
    materials: u32,
    /// Views of a one-word buffer bound where build_items reads through addresses (the
    /// pipeline layout has the bindings either way).
    pub(super) stand_in: LevelTexels,
    _stand_in_buffer: Buffer,
}

impl BuildItemsPipelines {
    /// The view-reading pipeline, for a scene with or without materials.
    pub(super) fn new(
        ctx: &Arc<GpuContext>,
        materials: u32,
    ) -> Result<BuildItemsPipelines, GpuError> {
        let buffer = ctx.create_buffer("edit build items stand-in", 4, MemLocation::GpuOnly)?;
        let stand_in = LevelTexels::new(ctx, [&buffer; 5])?.expect("one word fits a view");
        Ok(BuildItemsPipelines {
            by_texels: Self::make(ctx, materials, true)?,
            by_address: OnceLock::new(),
            materials,
            stand_in,
            _stand_in_buffer: buffer,
        })
    }

    /// Records warm-ups ([`crate::gpu::Commands::warm`]) of the pipelines made so far.
    pub(super) fn warm<'a>(&'a self, cmd: &mut Commands<'a>) -> Result<(), GpuError> {
        cmd.warm(&self.by_texels, &self.stand_in.bound())?;
        if let Some(by_address) = self.by_address.get() {
            cmd.warm(by_address, &self.stand_in.bound())?;
        }
        Ok(())
    }

    /// The pipeline for a level with views (`texels`) or without.
    pub(super) fn get(
        &self,
        ctx: &Arc<GpuContext>,
        texels: bool,
    ) -> Result<&ComputePipeline, GpuError> {
        if texels {
            return Ok(&self.by_texels);
        }
        made_once(&self.by_address, || Self::make(ctx, self.materials, false))
    }

    fn make(
        ctx: &Arc<GpuContext>,
        materials: u32,
        texels: bool,
    ) -> Result<ComputePipeline, GpuError> {
        ctx.create_compute_pipeline(&ComputePipelineDesc {
            name: "edit build items",
            spirv: shaders::EDIT_BUILD_ITEMS,
            spec_constants: &[super::TOOL_FROM_FLAGS, materials, texels as u32],
            push_constant_size: std::mem::size_of::<EditPush>() as u32,
            bindings: &[BindingKind::TexelBuffer; 5],
        })
    }
}
