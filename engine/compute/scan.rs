//! Exclusive prefix sum of `u32` (reduce-then-scan over as many levels as needed) and stream
//! compaction on top of it, plus indirect-dispatch arguments from a GPU-side count.
//!
//! A level of `m` elements in blocks of `B = workgroup * items`: if one block holds it, one
//! `scan_block` workgroup scans it (and writes the total); otherwise `scan_reduce` writes each
//! block's sum to a partials buffer, the partials are scanned in place by the same procedure
//! (the next level), and `scan_block` scans each block starting at its partial. With `B = 2048`,
//! 2^31 elements need three levels. Compaction is the same scan over "flag != 0" whose last
//! pass scatters the surviving values instead of writing positions.

use super::gpu_shared::{ArgsPush, BlockPush, ReducePush};
use super::{check_count, check_len, grid, Primitives};
use crate::gpu::{Buffer, Commands, GpuError, MemLocation, Profiler};

/// Size of [`ReducePush`].
pub(super) const REDUCE_PUSH_SIZE: usize = std::mem::size_of::<ReducePush>();
/// Size of [`BlockPush`].
pub(super) const BLOCK_PUSH_SIZE: usize = std::mem::size_of::<BlockPush>();
/// Size of [`ArgsPush`].
pub(super) const ARGS_PUSH_SIZE: usize = std::mem::size_of::<ArgsPush>();

/// `scan_block.comp` mode: write the exclusive scan.
const MODE_SCAN: u32 = 0;
/// `scan_block.comp` mode: scatter values whose flag is non-zero.
const MODE_COMPACT: u32 = 1;

/// Bytes of a compaction's count buffer: `[count, x, y, z]` (indirect arguments at byte 4).
pub const COUNT_ARGS_BYTES: u64 = 16;

/// Partial sums of every level of a scan of up to `capacity` elements; keep it alive until the
/// command buffer it was recorded into has been submitted.
pub struct ScanScratch {
    levels: Vec<Buffer>,
    capacity: u32,
}

impl ScanScratch {
    /// Largest element count this scratch serves.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

/// What the last pass of a level-0 scan writes.
#[derive(Clone, Copy)]
enum Output {
    /// The exclusive scan, at this address.
    Scan(u64),
    /// Compaction: (values, output) addresses.
    Compact(u64, u64),
}

impl Primitives {
    /// Allocates the partial-sum buffers for scans (and compactions) of up to `n` elements.
    pub fn scan_scratch(&self, n: u64) -> Result<ScanScratch, GpuError> {
        let capacity = check_count(n)?;
        let block = self.block() as u64;
        let mut levels = Vec::new();
        let mut m = n;
        while m > block {
            m = m.div_ceil(block);
            let name = format!("scan partials L{}", levels.len());
            levels.push(self.ctx.create_buffer(&name, m * 4, MemLocation::GpuOnly)?);
        }
        Ok(ScanScratch { levels, capacity })
    }

    /// Records the exclusive prefix sum of the first `n` `u32`s of `input` into `output` (sums
    /// wrap modulo 2^32; `input == output` is allowed) and their total into word 0 of `total`.
    /// Barriers before and after are included; passes are profiled as `"scan reduce L<level>"`
    /// and `"scan block L<level>"`.
    #[allow(clippy::too_many_arguments)]
    pub fn record_exclusive_scan<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        input: &'a Buffer,
        output: &'a Buffer,
        total: &'a Buffer,
        n: u64,
        scratch: &'a ScanScratch,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let n32 = self.check_scan(n, scratch)?;
        check_len(input, n, 4)?;
        check_len(output, n, 4)?;
        check_len(total, 1, 4)?;
        cmd.barrier();
        self.record_level(
            cmd,
            input.address(),
            Output::Scan(output.address()),
            n32,
            total.address(),
            &scratch.levels,
            0,
            &mut profiler,
        )
    }

    /// Records a stable stream compaction: each of the first `n` `values` whose `flags` word is
    /// non-zero is copied, in order, to the front of `output`. `count_args` (at least
    /// [`COUNT_ARGS_BYTES`]) receives `[count, x, y, z]`: the survivors, then
    /// [`Commands::dispatch_indirect`] arguments at byte 4 for `ceil(count / group_size)`
    /// workgroups (see [`Primitives::record_indirect_args`]), so the next pass is sized on the
    /// GPU. Passes: the scan's, "compact scatter" and "indirect args".
    #[allow(clippy::too_many_arguments)]
    pub fn record_compact<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        values: &'a Buffer,
        flags: &'a Buffer,
        n: u64,
        output: &'a Buffer,
        count_args: &'a Buffer,
        group_size: u32,
        scratch: &'a ScanScratch,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let n32 = self.check_scan(n, scratch)?;
        check_len(values, n, 4)?;
        check_len(flags, n, 4)?;
        check_len(output, n, 4)?;
        check_len(count_args, 4, 4)?;
        cmd.barrier();
        self.record_level(
            cmd,
            flags.address(),
            Output::Compact(values.address(), output.address()),
            n32,
            count_args.address(),
            &scratch.levels,
            0,
            &mut profiler,
        )?;
        self.record_args(cmd, count_args, group_size, &mut profiler)
    }

    /// Records turning word 0 of `count_args` (a count written by an earlier pass) into
    /// [`Commands::dispatch_indirect`] arguments at byte 4: `groups = ceil(count / group_size)`
    /// as a 2D grid `x = min(groups, 65535)`, `y = ceil(groups / 65535)`, `z = 1`. Consumers
    /// use `gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x` as their workgroup index
    /// and skip invocations at or past the count.
    pub fn record_indirect_args<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        count_args: &'a Buffer,
        group_size: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        check_len(count_args, 4, 4)?;
        cmd.barrier();
        self.record_args(cmd, count_args, group_size, &mut profiler)
    }

    fn check_scan(&self, n: u64, scratch: &ScanScratch) -> Result<u32, GpuError> {
        let n32 = check_count(n)?;
        if n32 > scratch.capacity {
            return Err(GpuError::InvalidArgument(format!(
                "scan of {n} elements with scratch for {}",
                scratch.capacity
            )));
        }
        Ok(n32)
    }

    fn record_args<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        count_args: &'a Buffer,
        group_size: u32,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        if group_size == 0 {
            return Err(GpuError::InvalidArgument(
                "indirect arguments for a group size of 0".into(),
            ));
        }
        let push = ArgsPush {
            count_args: count_args.address(),
            group_size,
            pad: 0,
        };
        cmd.begin_pass(profiler, "indirect args");
        cmd.dispatch(
            &self.indirect_args,
            [1, 1, 1],
            bytemuck::bytes_of(&push),
            &[],
        )?;
        cmd.end_pass(profiler);
        cmd.barrier();
        Ok(())
    }

    /// Records an in-place exclusive scan of `n` words at device address `words` (no total).
    pub(super) fn record_scan_in_place<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        words: u64,
        n: u32,
        scratch: &ScanScratch,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        self.check_scan(n as u64, scratch)?;
        self.record_level(
            cmd,
            words,
            Output::Scan(words),
            n,
            0,
            &scratch.levels,
            0,
            profiler,
        )
    }

    /// One level: a single block, or reduce + scan of the partials (next level) + block scan.
    #[allow(clippy::too_many_arguments)]
    fn record_level<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        input: u64,
        output: Output,
        n: u32,
        total: u64,
        levels: &[Buffer],
        depth: usize,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let groups = n.div_ceil(self.block()).max(1);
        let (mode, output, values) = match output {
            Output::Scan(o) => (MODE_SCAN, o, 0),
            Output::Compact(v, o) => (MODE_COMPACT, o, v),
        };
        let mut offsets = 0;
        if groups > 1 {
            let (partials, rest) = levels.split_first().ok_or_else(|| {
                GpuError::InvalidArgument("scan scratch has too few levels".into())
            })?;
            let push = ReducePush {
                input_words: input,
                partials: partials.address(),
                n,
                predicate: (mode == MODE_COMPACT) as u32,
            };
            cmd.begin_pass(profiler, &format!("scan reduce L{depth}"));
            cmd.dispatch(
                &self.scan_reduce,
                grid(groups),
                bytemuck::bytes_of(&push),
                &[],
            )?;
            cmd.end_pass(profiler);
            cmd.barrier();
            let p = partials.address();
            self.record_level(
                cmd,
                p,
                Output::Scan(p),
                groups,
                total,
                rest,
                depth + 1,
                profiler,
            )?;
            offsets = p;
        }
        let push = BlockPush {
            input_words: input,
            output_words: output,
            offsets,
            total: if groups == 1 { total } else { 0 },
            values,
            n,
            mode,
        };
        let name = if mode == MODE_COMPACT {
            "compact scatter".to_string()
        } else {
            format!("scan block L{depth}")
        };
        cmd.begin_pass(profiler, &name);
        cmd.dispatch(
            &self.scan_block,
            grid(groups),
            bytemuck::bytes_of(&push),
            &[],
        )?;
        cmd.end_pass(profiler);
        cmd.barrier();
        Ok(())
    }

    /// Blocking exclusive prefix sum: returns the scan (wrapping) and the total.
    pub fn exclusive_scan(
        &self,
        data: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<u32>, u32), GpuError> {
        let n = data.len() as u64;
        let input = self.upload_words("scan input", data)?;
        let output = self.zeroed_words("scan output", n)?;
        let total = self.zeroed_words("scan total", 1)?;
        let scratch = self.scan_scratch(n)?;
        let mut cmd = self.ctx.begin_commands("exclusive scan")?;
        self.record_exclusive_scan(&mut cmd, &input, &output, &total, n, &scratch, profiler)?;
        cmd.submit()?;
        let scanned = self.ctx.read_buffer::<u32>(&output, 0, data.len())?;
        let total = self.ctx.read_buffer::<u32>(&total, 0, 1)?[0];
        Ok((scanned, total))
    }

    /// Blocking stream compaction: the values whose flag is non-zero, in order, and the
    /// indirect arguments `[x, y, z]` computed on the GPU for `group_size`.
    pub fn compact(
        &self,
        values: &[u32],
        flags: &[u32],
        group_size: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<u32>, [u32; 3]), GpuError> {
        if values.len() != flags.len() {
            return Err(GpuError::InvalidArgument(format!(
                "compaction of {} values with {} flags",
                values.len(),
                flags.len()
            )));
        }
        let n = values.len() as u64;
        let v = self.upload_words("compact values", values)?;
        let f = self.upload_words("compact flags", flags)?;
        let out = self.zeroed_words("compact output", n)?;
        let count_args = self.zeroed_words("compact count", 4)?;
        let scratch = self.scan_scratch(n)?;
        let mut cmd = self.ctx.begin_commands("compact")?;
        self.record_compact(
            &mut cmd,
            &v,
            &f,
            n,
            &out,
            &count_args,
            group_size,
            &scratch,
            profiler,
        )?;
        cmd.submit()?;
        let c = self.ctx.read_buffer::<u32>(&count_args, 0, 4)?;
        let kept = self.ctx.read_buffer::<u32>(&out, 0, c[0] as usize)?;
        Ok((kept, [c[1], c[2], c[3]]))
    }

    /// A device-local buffer holding `data` (one zero word when empty: Vulkan has no empty
    /// buffers).
    pub(super) fn upload_words<T: bytemuck::Pod>(
        &self,
        name: &str,
        data: &[T],
    ) -> Result<Buffer, GpuError> {
        if data.is_empty() {
            return self.zeroed_words(name, 0);
        }
        self.ctx.upload(name, data)
    }

    /// A zeroed device-local buffer of `n` words (at least 2, so 64-bit views fit).
    pub(super) fn zeroed_words(&self, name: &str, n: u64) -> Result<Buffer, GpuError> {
        let buffer = self
            .ctx
            .create_buffer(name, n.max(2) * 4, MemLocation::GpuOnly)?;
        let mut cmd = self.ctx.begin_commands(&format!("zero {name}"))?;
        cmd.fill_buffer(&buffer, 0);
        cmd.submit()?;
        Ok(buffer)
    }
}
