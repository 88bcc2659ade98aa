//! GPU passes of the lossless colour codec ([`crate::attr::lossless`] is the bit-exact CPU
//! reference).
//!
//! Encoding is three dispatches: `attr/lossless_plan.comp` (one invocation per block: header
//! words and block size), `attr/lossless_scan.comp` (one workgroup: exclusive prefix sum of the
//! block sizes into the 64-bit offset table), then, once the host has read the total size back
//! and allocated the output, `attr/lossless_write.comp` (one invocation per block writes its
//! words). Decoding runs `attr/lossless_decode.comp`, one invocation per colour through
//! `attr/lossless.glsl`, the decoder the renderer includes. Buffers are reached through device
//! addresses, so chunks may exceed `maxStorageBufferRange`.

use std::sync::Arc;

use super::gpu_shared::{DecodePush, PlanPush, ScanPush, WritePush};
use crate::attr::lossless::{self, LosslessVariant, BLOCK_COLORS, EXTRA_SHIFTS};
use crate::gpu::{
    shaders, Buffer, Commands, ComputePipeline, ComputePipelineDesc, GpuContext, GpuError,
    MemLocation, Profiler, Readback,
};

/// Invocations per workgroup of the per-block and the decode passes.
const WORKGROUP: u32 = 64;
/// Invocations of the single scan workgroup (capped by the device limits).
const SCAN_WORKGROUP: u32 = 256;
/// Words per block in the plan buffer: header A, header B, size in words, unused.
const PLAN_WORDS: u64 = 4;

/// The lossless codec's compute pipelines.
pub struct LosslessGpu {
    ctx: Arc<GpuContext>,
    plan: ComputePipeline,
    scan: ComputePipeline,
    write: ComputePipeline,
    decode: ComputePipeline,
}

/// Per-block scratch of one encode: block plans and the 64-bit offset table.
#[derive(Debug)]
pub struct EncodeScratch {
    plans: Buffer,
    offsets: Buffer,
    blocks: u32,
}

impl LosslessGpu {
    /// Builds the encode and decode pipelines.
    pub fn new(ctx: &Arc<GpuContext>) -> Result<LosslessGpu, GpuError> {
        let info = ctx.info();
        let scan_size = SCAN_WORKGROUP
            .min(info.max_compute_workgroup_invocations)
            .min(info.max_compute_workgroup_size[0]);
        // Specialization constants: 0 = workgroup size, 1 = the encoder's extra shifts (read by
        // the plan pass only; the same value everywhere keeps one source of truth).
        let pipeline = |name: &str, spirv: &[u32], size: u32, push: usize| {
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name,
                spirv,
                spec_constants: &[size, EXTRA_SHIFTS],
                push_constant_size: push as u32,
                bindings: &[],
            })
        };
        Ok(LosslessGpu {
            ctx: Arc::clone(ctx),
            plan: pipeline(
                "lossless plan",
                shaders::ATTR_LOSSLESS_PLAN,
                WORKGROUP,
                std::mem::size_of::<PlanPush>(),
            )?,
            scan: pipeline(
                "lossless scan",
                shaders::ATTR_LOSSLESS_SCAN,
                scan_size,
                std::mem::size_of::<ScanPush>(),
            )?,
            write: pipeline(
                "lossless write",
                shaders::ATTR_LOSSLESS_WRITE,
                WORKGROUP,
                std::mem::size_of::<WritePush>(),
            )?,
            decode: pipeline(
                "lossless decode",
                shaders::ATTR_LOSSLESS_DECODE,
                WORKGROUP,
                std::mem::size_of::<DecodePush>(),
            )?,
        })
    }

    /// Scratch for encoding `count` (≥ 1) colours.
    pub fn encode_scratch(&self, count: u32) -> Result<EncodeScratch, GpuError> {
        let blocks = count.max(1).div_ceil(BLOCK_COLORS as u32);
        Ok(EncodeScratch {
            plans: self.ctx.create_buffer(
                "lossless plans",
                blocks as u64 * PLAN_WORDS * 4,
                MemLocation::GpuOnly,
            )?,
            offsets: self.ctx.create_buffer(
                "lossless block offsets",
                (blocks as u64 + 1) * 8,
                MemLocation::GpuOnly,
            )?,
            blocks,
        })
    }

    /// Records the first encode step into `cmd`: the plan and scan passes (profiled as
    /// "lossless plan" and "lossless scan") and a readback of the encoded size in words, which
    /// the host needs to allocate the output of [`LosslessGpu::record_write`].
    #[allow(clippy::too_many_arguments)]
    pub fn record_plan<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        colors: &'a Buffer,
        count: u32,
        variant: LosslessVariant,
        scratch: &'a EncodeScratch,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<Readback<u64>, GpuError> {
        self.check_colors(colors, count, scratch)?;
        let blocks = scratch.blocks;
        cmd.begin_pass(&mut profiler, "lossless plan");
        let push = PlanPush {
            colors: colors.address(),
            plans: scratch.plans.address(),
            count,
            variant: variant.id(),
        };
        cmd.dispatch(
            &self.plan,
            [blocks.div_ceil(WORKGROUP), 1, 1],
            bytemuck::bytes_of(&push),
            &[],
        )?;
        cmd.end_pass(&mut profiler);
        cmd.barrier();
        cmd.begin_pass(&mut profiler, "lossless scan");
        let push = ScanPush {
            plans: scratch.plans.address(),
            offsets: scratch.offsets.address(),
            blocks,
            pad: 0,
        };
        cmd.dispatch(&self.scan, [1, 1, 1], bytemuck::bytes_of(&push), &[])?;
        cmd.end_pass(&mut profiler);
        cmd.barrier();
        cmd.readback::<u64>(&scratch.offsets, blocks as u64 * 8, 1)
    }

    /// Records the write pass (profiled as "lossless write") into `cmd`: the encoded words into
    /// `out`, which holds at least the size [`LosslessGpu::record_plan`] read back.
    #[allow(clippy::too_many_arguments)]
    pub fn record_write<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        colors: &'a Buffer,
        count: u32,
        variant: LosslessVariant,
        scratch: &'a EncodeScratch,
        out: &'a Buffer,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        self.check_colors(colors, count, scratch)?;
        cmd.begin_pass(&mut profiler, "lossless write");
        let push = WritePush {
            colors: colors.address(),
            plans: scratch.plans.address(),
            offsets: scratch.offsets.address(),
            out_words: out.address(),
            count,
            variant: variant.id(),
        };
        cmd.dispatch(
            &self.write,
            [scratch.blocks.div_ceil(WORKGROUP), 1, 1],
            bytemuck::bytes_of(&push),
            &[],
        )?;
        cmd.end_pass(&mut profiler);
        cmd.barrier();
        Ok(())
    }

    fn check_colors(
        &self,
        colors: &Buffer,
        count: u32,
        scratch: &EncodeScratch,
    ) -> Result<(), GpuError> {
        if count == 0 || colors.size() < count as u64 * 4 {
            return Err(GpuError::InvalidArgument(format!(
                "buffer '{}' of {} bytes cannot hold {count} (≥ 1) colours",
                colors.name(),
                colors.size()
            )));
        }
        if count.div_ceil(BLOCK_COLORS as u32) != scratch.blocks {
            return Err(GpuError::InvalidArgument(format!(
                "encode scratch for {} blocks used for {count} colours",
                scratch.blocks
            )));
        }
        Ok(())
    }

    /// Encodes the first `count` RGBA8 words of `colors` into a new GPU buffer holding the words
    /// [`lossless::encode`] returns (exactly; one unused word when `count` is 0) and returns
    /// their number. Passes are profiled as "lossless plan", "lossless scan" and "lossless
    /// write". Two submissions; one host wait (for the size), two with a profiler.
    pub fn encode(
        &self,
        colors: &Buffer,
        count: u32,
        variant: LosslessVariant,
        profiler: Option<&mut Profiler>,
    ) -> Result<(Buffer, usize), GpuError> {
        self.encode_flow(colors, count, variant, None, profiler)
            .map(|(b, n, _)| (b, n))
    }

    /// Encode with an optional upload of the colours (first submission) and readback of the
    /// words (second submission).
    fn encode_flow(
        &self,
        colors: &Buffer,
        count: u32,
        variant: LosslessVariant,
        upload: Option<&[u32]>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(Buffer, usize, Option<Vec<u32>>), GpuError> {
        let ctx = &self.ctx;
        if colors.size() < count as u64 * 4 {
            return Err(GpuError::InvalidArgument(format!(
                "buffer '{}' of {} bytes holds fewer than {count} colours",
                colors.name(),
                colors.size()
            )));
        }
        if count == 0 {
            // No colours encode to no words; Vulkan has no empty buffers.
            let out = ctx.create_buffer("lossless chunk (empty)", 4, MemLocation::GpuOnly)?;
            return Ok((out, 0, upload.map(|_| Vec::new())));
        }
        let scratch = self.encode_scratch(count)?;
        let mut cmd = ctx.begin_commands("lossless encode: plan + scan")?;
        if let Some(data) = upload {
            cmd.upload(colors, 0, data)?;
        }
        let total = self.record_plan(
            &mut cmd,
            colors,
            count,
            variant,
            &scratch,
            profiler.as_deref_mut(),
        )?;
        cmd.submit_async()?;
        let total = total.read()?[0];
        let out = ctx.create_buffer("lossless chunk", total.max(1) * 4, MemLocation::GpuOnly)?;
        let mut cmd = ctx.begin_commands("lossless encode: write")?;
        self.record_write(
            &mut cmd,
            colors,
            count,
            variant,
            &scratch,
            &out,
            profiler.as_deref_mut(),
        )?;
        let back = match upload {
            Some(_) => Some(cmd.readback::<u32>(&out, 0, total as usize)?),
            None => None,
        };
        cmd.submit_async()?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        let words = match back {
            Some(b) => Some(b.read()?),
            None => None,
        };
        Ok((out, total as usize, words))
    }

    /// Records the decode pass (profiled as "lossless decode") into `cmd`: `count` (≥ 1)
    /// colours of the encoded chunk in `chunk` into `out` (RGBA8 words). The GPU does not
    /// validate: pass only chunks that [`lossless::validate`] accepted.
    pub fn record_decode<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        chunk: &'a Buffer,
        count: u32,
        out: &'a Buffer,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        if count == 0 || out.size() < count as u64 * 4 {
            return Err(GpuError::InvalidArgument(format!(
                "lossless decode of {count} colours into '{}' of {} bytes",
                out.name(),
                out.size()
            )));
        }
        let max_groups = self.ctx.info().max_compute_workgroup_count[0];
        let groups = [count.div_ceil(WORKGROUP).min(max_groups), 1, 1];
        cmd.begin_pass(&mut profiler, "lossless decode");
        let push = DecodePush {
            chunk: chunk.address(),
            out_colors: out.address(),
            count,
            pad: 0,
        };
        cmd.dispatch(&self.decode, groups, bytemuck::bytes_of(&push), &[])?;
        cmd.end_pass(&mut profiler);
        cmd.barrier();
        Ok(())
    }

    /// Decodes `count` (≥ 1) colours of the encoded chunk in `chunk` into a new buffer of RGBA8
    /// words (profiled as "lossless decode"). The GPU does not validate: pass only chunks that
    /// [`lossless::validate`] accepted. One submission, waited for only with a profiler.
    pub fn decode_all(
        &self,
        chunk: &Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<Buffer, GpuError> {
        let ctx = &self.ctx;
        if count == 0 {
            return Err(GpuError::InvalidArgument(
                "lossless decode of an empty chunk".into(),
            ));
        }
        let out = ctx.create_buffer(
            "lossless decoded colours",
            count as u64 * 4,
            MemLocation::GpuOnly,
        )?;
        let mut cmd = ctx.begin_commands("lossless decode")?;
        self.record_decode(&mut cmd, chunk, count, &out, profiler.as_deref_mut())?;
        cmd.submit_async()?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Ok(out)
    }

    /// [`LosslessGpu::encode`] from and to host memory (upload and readback not profiled).
    pub fn encode_vec(
        &self,
        colors: &[u32],
        variant: LosslessVariant,
        profiler: Option<&mut Profiler>,
    ) -> Result<Vec<u32>, GpuError> {
        let count = gpu_count(colors.len())?;
        if count == 0 {
            return Ok(Vec::new());
        }
        let input = self.ctx.create_buffer(
            "lossless input colours",
            count as u64 * 4,
            MemLocation::GpuOnly,
        )?;
        let (_, _, words) = self.encode_flow(&input, count, variant, Some(colors), profiler)?;
        Ok(words.unwrap_or_default())
    }

    /// Validates `words` on the CPU ([`lossless::validate`]), then decodes them with
    /// [`LosslessGpu::decode_all`] (upload and readback not profiled).
    pub fn decode_vec(
        &self,
        words: &[u32],
        count: usize,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<Vec<u32>, GpuError> {
        lossless::validate(words, count)
            .map_err(|e| GpuError::InvalidArgument(format!("lossless chunk: {e}")))?;
        let count = gpu_count(count)?;
        if count == 0 {
            return Ok(Vec::new());
        }
        // Upload, decode and readback in one submission, one host wait.
        let chunk = self.ctx.create_buffer(
            "lossless chunk",
            words.len().max(1) as u64 * 4,
            MemLocation::GpuOnly,
        )?;
        let out = self.ctx.create_buffer(
            "lossless decoded colours",
            count as u64 * 4,
            MemLocation::GpuOnly,
        )?;
        let mut cmd = self.ctx.begin_commands("lossless decode")?;
        cmd.upload(&chunk, 0, words)?;
        self.record_decode(&mut cmd, &chunk, count, &out, profiler.as_deref_mut())?;
        let back = cmd.readback::<u32>(&out, 0, count as usize)?;
        cmd.submit_async()?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        back.read()
    }
}

/// A colour count as the `uint` the shaders index with.
fn gpu_count(count: usize) -> Result<u32, GpuError> {
    u32::try_from(count).map_err(|_| {
        GpuError::InvalidArgument(format!("{count} colours exceed the 2^32 GPU limit"))
    })
}
