//! GPU primitives for GPU-driven work: exclusive prefix sum, stream compaction (with
//! indirect-dispatch arguments for the next pass) and a stable key/value LSD radix sort for 32-
//! and 64-bit keys. Each has a CPU reference in [`reference`](mod@reference), records into a caller's
//! [`Commands`](crate::gpu::Commands) (barriers, debug labels and profiler passes included) and has a blocking
//! convenience wrapper. Shaders: `shaders/glsl/compute/`; they work for any subgroup size.
//! See `docs/gpu-primitives.md`.

mod gpu_shared;
pub mod reference;
mod scan;
mod sort;

pub use scan::{ScanScratch, COUNT_ARGS_BYTES};
pub use sort::{KeyWidth, SortScratch};

use std::sync::Arc;

use crate::gpu::{shaders, Buffer, ComputePipeline, ComputePipelineDesc, GpuContext, GpuError};

/// Largest element count of any primitive (indices stay below 2^31 in the shaders); the
/// practical limit is the device's largest buffer (`maxMemoryAllocationSize`).
pub const MAX_ELEMENTS: u64 = 1 << 31;

/// Largest x workgroup count of the 2D grids: the smallest `maxComputeWorkGroupCount[0]` Vulkan
/// allows, so grids and indirect arguments are valid on every device.
pub const GRID_X: u32 = 65_535;

/// Tuning of [`Primitives`]; the defaults are what `docs/gpu-primitives.md` measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrimitiveOptions {
    /// Invocations per workgroup (a power of two, at most the device's limits).
    pub workgroup: u32,
    /// Consecutive elements per invocation (a block or tile is `workgroup * items`).
    pub items: u32,
    /// Radix sort digit width in bits: 4 (counting ranks, the default) or 8 (per-bit splits).
    pub radix_bits: u32,
}

impl Default for PrimitiveOptions {
    fn default() -> Self {
        PrimitiveOptions {
            workgroup: 256,
            items: 8,
            // Counting ranks with 4-bit digits measured 1.2-1.8x faster on lavapipe than
            // 8-bit digits with per-bit splits (docs/gpu-primitives.md).
            radix_bits: 4,
        }
    }
}

/// The primitives' compute pipelines.
pub struct Primitives {
    ctx: Arc<GpuContext>,
    options: PrimitiveOptions,
    scan_reduce: ComputePipeline,
    scan_block: ComputePipeline,
    indirect_args: ComputePipeline,
    radix_hist: [ComputePipeline; 2],
    radix_scatter: [ComputePipeline; 2],
}

/// A 2D grid of at least `groups` workgroups (x at most [`GRID_X`]); shaders skip the excess.
fn grid(groups: u32) -> [u32; 3] {
    let x = groups.clamp(1, GRID_X);
    [x, groups.div_ceil(x).max(1), 1]
}

/// Checks that `buffer` holds `count` elements of `elem` bytes.
fn check_len(buffer: &Buffer, count: u64, elem: u64) -> Result<(), GpuError> {
    if buffer.size() < count * elem {
        return Err(GpuError::InvalidArgument(format!(
            "buffer '{}' of {} bytes holds fewer than {count} elements of {elem} bytes",
            buffer.name(),
            buffer.size()
        )));
    }
    Ok(())
}

/// Checks an element count against [`MAX_ELEMENTS`] and returns it as `u32`.
fn check_count(n: u64) -> Result<u32, GpuError> {
    if n > MAX_ELEMENTS {
        return Err(GpuError::InvalidArgument(format!(
            "{n} elements exceed the primitives' limit of {MAX_ELEMENTS}"
        )));
    }
    Ok(n as u32)
}

impl Primitives {
    /// Builds the pipelines with the default [`PrimitiveOptions`].
    pub fn new(ctx: &Arc<GpuContext>) -> Result<Primitives, GpuError> {
        Primitives::with_options(ctx, PrimitiveOptions::default())
    }

    /// Builds the pipelines with the given tuning.
    pub fn with_options(
        ctx: &Arc<GpuContext>,
        options: PrimitiveOptions,
    ) -> Result<Primitives, GpuError> {
        let info = ctx.info();
        let wg = options.workgroup;
        if !wg.is_power_of_two()
            || wg > info.max_compute_workgroup_invocations
            || wg > info.max_compute_workgroup_size[0]
            || options.items == 0
            || options.items > 64
            || !matches!(options.radix_bits, 4 | 8)
        {
            return Err(GpuError::InvalidArgument(format!(
                "primitive options {options:?}: the workgroup must be a power of two within the \
                 device limits, items 1..=64, radix bits 4 or 8"
            )));
        }
        let spec = [wg, options.items, options.radix_bits];
        let pipeline = |name: &str, spirv: &[u32], push: usize| {
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name,
                spirv,
                spec_constants: &spec,
                push_constant_size: push as u32,
                bindings: &[],
            })
        };
        let radix = sort::PUSH_SIZE;
        Ok(Primitives {
            ctx: Arc::clone(ctx),
            options,
            scan_reduce: pipeline(
                "scan reduce",
                shaders::COMPUTE_SCAN_REDUCE,
                scan::REDUCE_PUSH_SIZE,
            )?,
            scan_block: pipeline(
                "scan block",
                shaders::COMPUTE_SCAN_BLOCK,
                scan::BLOCK_PUSH_SIZE,
            )?,
            indirect_args: pipeline(
                "indirect args",
                shaders::COMPUTE_INDIRECT_ARGS,
                scan::ARGS_PUSH_SIZE,
            )?,
            radix_hist: [
                pipeline(
                    "radix histogram u32",
                    shaders::COMPUTE_RADIX_HIST_U32,
                    radix,
                )?,
                pipeline(
                    "radix histogram u64",
                    shaders::COMPUTE_RADIX_HIST_U64,
                    radix,
                )?,
            ],
            // 4-bit digits: counting ranks (a 16 x workgroup table fits in shared memory);
            // 8-bit digits: a shared-memory split per bit. See docs/gpu-primitives.md.
            radix_scatter: if options.radix_bits == 4 {
                [
                    pipeline("radix rank u32", shaders::COMPUTE_RADIX_RANK_U32, radix)?,
                    pipeline("radix rank u64", shaders::COMPUTE_RADIX_RANK_U64, radix)?,
                ]
            } else {
                [
                    pipeline("radix split u32", shaders::COMPUTE_RADIX_SCATTER_U32, radix)?,
                    pipeline("radix split u64", shaders::COMPUTE_RADIX_SCATTER_U64, radix)?,
                ]
            },
        })
    }

    /// The tuning the pipelines were built with.
    pub fn options(&self) -> PrimitiveOptions {
        self.options
    }

    /// Elements one workgroup handles (scan block, radix sort tile).
    pub fn block(&self) -> u32 {
        self.options.workgroup * self.options.items
    }

    /// The context the pipelines belong to.
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }
}
