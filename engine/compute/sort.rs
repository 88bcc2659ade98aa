//! Stable LSD radix sort of key/value pairs: 32- or 64-bit keys, `u32` values.
//!
//! Each pass sorts by one digit (`radix_bits`: 4 by default, 8 passes for 32-bit keys and 16
//! for 64-bit) in three dispatches: `radix_hist` counts each tile's digits into a digit-major
//! histogram `[digit * tiles + tile]`, the exclusive scan of that histogram (the scan
//! primitive) gives every (digit, tile) its first output position, and the scatter pass ranks
//! each key among the equal digits of its tile and writes it to its position: `radix_rank`
//! (4-bit digits) from a per-invocation digit count table and one workgroup scan,
//! `radix_scatter` (8-bit digits) by sorting the tile in shared memory with one stable split
//! per bit. Passes alternate between the caller's buffers and the scratch copies; the
//! pass count is even, so the result ends in the caller's buffers.

use super::gpu_shared::RadixPush;
use super::scan::ScanScratch;
use super::{check_count, check_len, grid, Primitives};
use crate::gpu::{Buffer, Commands, GpuError, MemLocation, Profiler};

/// Size of [`RadixPush`].
pub(super) const PUSH_SIZE: usize = std::mem::size_of::<RadixPush>();

/// Width of radix sort keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyWidth {
    /// `u32` keys.
    U32,
    /// `u64` keys.
    U64,
}

impl KeyWidth {
    /// Bits per key.
    pub fn bits(self) -> u32 {
        match self {
            KeyWidth::U32 => 32,
            KeyWidth::U64 => 64,
        }
    }

    /// Bytes per key.
    pub fn bytes(self) -> u64 {
        self.bits() as u64 / 8
    }

    fn index(self) -> usize {
        match self {
            KeyWidth::U32 => 0,
            KeyWidth::U64 => 1,
        }
    }
}

/// Ping-pong copies of keys and values, the histogram and its scan scratch for sorts of up to
/// `capacity` keys of one width; keep it alive until the command buffer has been submitted.
pub struct SortScratch {
    keys: Buffer,
    values: Buffer,
    hist: Buffer,
    scan: ScanScratch,
    capacity: u32,
    width: KeyWidth,
}

impl SortScratch {
    /// Largest key count this scratch serves.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

impl Primitives {
    /// Histogram entries of a sort of `n` keys: digits x tiles.
    fn hist_len(&self, n: u64) -> u64 {
        (1u64 << self.options.radix_bits) * n.div_ceil(self.block() as u64).max(1)
    }

    /// Allocates the scratch for sorts of up to `n` keys of `width`.
    pub fn sort_scratch(&self, n: u64, width: KeyWidth) -> Result<SortScratch, GpuError> {
        let capacity = check_count(n)?;
        let ctx = &self.ctx;
        let m = n.max(2);
        let hist_len = self.hist_len(n);
        Ok(SortScratch {
            keys: ctx.create_buffer(
                "sort keys (ping-pong)",
                m * width.bytes(),
                MemLocation::GpuOnly,
            )?,
            values: ctx.create_buffer("sort values (ping-pong)", m * 4, MemLocation::GpuOnly)?,
            hist: ctx.create_buffer("sort histogram", hist_len * 4, MemLocation::GpuOnly)?,
            scan: self.scan_scratch(hist_len)?,
            capacity,
            width,
        })
    }

    /// Records a stable sort of the first `n` (key, value) pairs in `keys` (`width` keys) and
    /// `values` (`u32`), in place. Barriers before and after are included; passes are profiled
    /// as "radix histogram", the scan's, and "radix rank" (4-bit digits) or "radix split"
    /// (8-bit), each with the digit's shift (`@8`).
    #[allow(clippy::too_many_arguments)]
    pub fn record_sort<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        keys: &'a Buffer,
        values: &'a Buffer,
        n: u64,
        width: KeyWidth,
        scratch: &'a SortScratch,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let n32 = check_count(n)?;
        if n32 > scratch.capacity || width != scratch.width {
            return Err(GpuError::InvalidArgument(format!(
                "sort of {n} {width:?} keys with scratch for {} {:?} keys",
                scratch.capacity, scratch.width
            )));
        }
        check_len(keys, n, width.bytes())?;
        check_len(values, n, 4)?;
        cmd.barrier();
        if n32 <= 1 {
            return Ok(());
        }
        let bits = self.options.radix_bits;
        let hist_len = self.hist_len(n);
        let tiles = n32.div_ceil(self.block());
        let w = width.index();
        let buffers = [
            (keys.address(), values.address()),
            (scratch.keys.address(), scratch.values.address()),
        ];
        let hist = scratch.hist.address();
        // The two scatter variants (see the module docs) under their own pass names.
        let scatter = if bits == 4 {
            "radix rank"
        } else {
            "radix split"
        };
        for pass in 0..width.bits() / bits {
            let shift = pass * bits;
            let (src, dst) = (buffers[pass as usize % 2], buffers[1 - pass as usize % 2]);
            let push = RadixPush {
                keys_in: src.0,
                values_in: src.1,
                keys_out: dst.0,
                values_out: dst.1,
                offsets: hist,
                n: n32,
                shift,
            };
            cmd.begin_pass(&mut profiler, &format!("radix histogram @{shift}"));
            cmd.dispatch(
                &self.radix_hist[w],
                grid(tiles),
                bytemuck::bytes_of(&push),
                &[],
            )?;
            cmd.end_pass(&mut profiler);
            cmd.barrier();
            self.record_scan_in_place(cmd, hist, hist_len as u32, &scratch.scan, &mut profiler)?;
            cmd.begin_pass(&mut profiler, &format!("{scatter} @{shift}"));
            cmd.dispatch(
                &self.radix_scatter[w],
                grid(tiles),
                bytemuck::bytes_of(&push),
                &[],
            )?;
            cmd.end_pass(&mut profiler);
            cmd.barrier();
        }
        Ok(())
    }

    /// Blocking stable sort of `u32` keys with `u32` values: returns (keys, values) sorted.
    pub fn sort_u32(
        &self,
        keys: &[u32],
        values: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<u32>, Vec<u32>), GpuError> {
        self.sort_pairs(KeyWidth::U32, keys, values, profiler)
    }

    /// Blocking stable sort of `u64` keys with `u32` values: returns (keys, values) sorted.
    pub fn sort_u64(
        &self,
        keys: &[u64],
        values: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<u64>, Vec<u32>), GpuError> {
        self.sort_pairs(KeyWidth::U64, keys, values, profiler)
    }

    fn sort_pairs<K: bytemuck::Pod>(
        &self,
        width: KeyWidth,
        keys: &[K],
        values: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<K>, Vec<u32>), GpuError> {
        if keys.len() != values.len() {
            return Err(GpuError::InvalidArgument(format!(
                "sort of {} keys with {} values",
                keys.len(),
                values.len()
            )));
        }
        let n = keys.len() as u64;
        let k = self.upload_words("sort keys", keys)?;
        let v = self.upload_words("sort values", values)?;
        let scratch = self.sort_scratch(n, width)?;
        let mut cmd = self.ctx.begin_commands("radix sort")?;
        self.record_sort(&mut cmd, &k, &v, n, width, &scratch, profiler)?;
        cmd.submit()?;
        Ok((
            self.ctx.read_buffer::<K>(&k, 0, keys.len())?,
            self.ctx.read_buffer::<u32>(&v, 0, keys.len())?,
        ))
    }
}
