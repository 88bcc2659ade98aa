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
    shaders, Buffer, ComputePipeline, ComputePipelineDesc, GpuContext, GpuError, MemLocation,
    Profiler,
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

/// Opens a profiled pass, or just a debug label without a profiler.
fn begin(profiler: &mut Option<&mut Profiler>, cmd: &mut crate::gpu::Commands<'_>, name: &str) {
    match profiler {
        Some(p) => p.begin_pass(cmd, name),
        None => cmd.begin_label(name),
    }
}

fn end(profiler: &mut Option<&mut Profiler>, cmd: &mut crate::gpu::Commands<'_>) {
    match profiler {
        Some(p) => p.end_pass(cmd),
        None => cmd.end_label(),
    }
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
                storage_image: false,
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

    /// Encodes the first `count` RGBA8 words of `colors` into a new GPU buffer holding the words
    /// [`lossless::encode`] returns (exactly; one unused word when `count` is 0) and returns
    /// their number. Passes are profiled
    /// as "lossless plan", "lossless scan" and "lossless write".
    pub fn encode(
        &self,
        colors: &Buffer,
        count: u32,
        variant: LosslessVariant,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(Buffer, usize), GpuError> {
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
            return Ok((out, 0));
        }
        let blocks = count.div_ceil(BLOCK_COLORS as u32);
        let groups = [blocks.div_ceil(WORKGROUP), 1, 1];
        let plans = ctx.create_buffer(
            "lossless plans",
            blocks as u64 * PLAN_WORDS * 4,
            MemLocation::GpuOnly,
        )?;
        let offsets = ctx.create_buffer(
            "lossless block offsets",
            (blocks as u64 + 1) * 8,
            MemLocation::GpuOnly,
        )?;

        let mut cmd = ctx.begin_commands("lossless encode: plan + scan")?;
        begin(&mut profiler, &mut cmd, "lossless plan");
        let push = PlanPush {
            colors: colors.address(),
            plans: plans.address(),
            count,
            variant: variant.id(),
        };
        cmd.dispatch(&self.plan, groups, bytemuck::bytes_of(&push), None)?;
        end(&mut profiler, &mut cmd);
        cmd.barrier();
        begin(&mut profiler, &mut cmd, "lossless scan");
        let push = ScanPush {
            plans: plans.address(),
            offsets: offsets.address(),
            blocks,
            pad: 0,
        };
        cmd.dispatch(&self.scan, [1, 1, 1], bytemuck::bytes_of(&push), None)?;
        end(&mut profiler, &mut cmd);
        cmd.submit()?;

        let total = ctx.read_buffer::<u64>(&offsets, blocks as u64 * 8, 1)?[0];
        let out = ctx.create_buffer("lossless chunk", total * 4, MemLocation::GpuOnly)?;
        let mut cmd = ctx.begin_commands("lossless encode: write")?;
        begin(&mut profiler, &mut cmd, "lossless write");
        let push = WritePush {
            colors: colors.address(),
            plans: plans.address(),
            offsets: offsets.address(),
            out_words: out.address(),
            count,
            variant: variant.id(),
        };
        cmd.dispatch(&self.write, groups, bytemuck::bytes_of(&push), None)?;
        end(&mut profiler, &mut cmd);
        cmd.submit()?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Ok((out, total as usize))
    }

    /// Decodes `count` (≥ 1) colours of the encoded chunk in `chunk` into a new buffer of RGBA8
    /// words (profiled as "lossless decode"). The GPU does not validate: pass only chunks that
    /// [`lossless::validate`] accepted.
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
        let max_groups = ctx.info().max_compute_workgroup_count[0];
        let groups = [count.div_ceil(WORKGROUP).min(max_groups), 1, 1];
        let mut cmd = ctx.begin_commands("lossless decode")?;
        begin(&mut profiler, &mut cmd, "lossless decode");
        let push = DecodePush {
            chunk: chunk.address(),
            out_colors: out.address(),
            count,
            pad: 0,
        };
        cmd.dispatch(&self.decode, groups, bytemuck::bytes_of(&push), None)?;
        end(&mut profiler, &mut cmd);
        cmd.submit()?;
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
        let input = self.ctx.upload("lossless input colours", colors)?;
        let (out, words) = self.encode(&input, count, variant, profiler)?;
        self.ctx.read_buffer(&out, 0, words)
    }

    /// Validates `words` on the CPU ([`lossless::validate`]), then decodes them with
    /// [`LosslessGpu::decode_all`] (upload and readback not profiled).
    pub fn decode_vec(
        &self,
        words: &[u32],
        count: usize,
        profiler: Option<&mut Profiler>,
    ) -> Result<Vec<u32>, GpuError> {
        lossless::validate(words, count)
            .map_err(|e| GpuError::InvalidArgument(format!("lossless chunk: {e}")))?;
        let count = gpu_count(count)?;
        if count == 0 {
            return Ok(Vec::new());
        }
        let chunk = self.ctx.upload("lossless chunk", words)?;
        let out = self.decode_all(&chunk, count, profiler)?;
        self.ctx.download(&out)
    }
}

/// A colour count as the `uint` the shaders index with.
fn gpu_count(count: usize) -> Result<u32, GpuError> {
    u32::try_from(count).map_err(|_| {
        GpuError::InvalidArgument(format!("{count} colours exceed the 2^32 GPU limit"))
    })
}
