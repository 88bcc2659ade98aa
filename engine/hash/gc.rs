//! Garbage collection of a slab hash table (dissertation §4.4.3): keep exactly the items named
//! by a list of live handles, free every other item and return wholly empty slabs to the
//! allocator.
//!
//! Two GPU passes (`shaders/glsl/hash/gc_{mark,sweep}.comp`) in one submission:
//! 1. mark: each live handle sets its slot's bit in its slab's `active` word (header word 1,
//!    reserved for GC by the table layout, zero between collections);
//! 2. sweep: one team per bucket (the table's [`TeamMode`](super::TeamMode): the whole subgroup,
//!    or a single lane on CPU devices) walks the chain, clears every occupied slot whose bit is
//!    clear (the slot's words, the occupancy bit, the secondary hash), resets `active` to zero,
//!    and unlinks, zeroes and frees every slab left empty (the bucket's first too: its head then
//!    links the next slab, or nothing, and the next insert into the bucket starts a new chain).
//!
//! Handles of kept items do not change. [`collect_cpu`] does the same on a [`TableImage`]; since
//! GC allocates nothing its result is deterministic, and the GPU's image equals the CPU's word
//! for word.

use std::sync::Arc;

use super::gpu_shared::GcCounters;
use super::layout::{
    Handle, HashStatus, HashVariant, SlabLayout, HANDLE_INVALID, HANDLE_MISS,
    SLABS_PER_SUPER_BLOCK, SLAB_ACTIVE, SLAB_NEXT, SLAB_OCCUPANCY, SLAB_SLOTS,
    SUPER_BLOCK_BITMASK_WORDS,
};
use super::reference::TableImage;
use super::table::GpuHashTable;
use super::HashError;
use crate::gpu::{
    shaders, Buffer, Commands, ComputePipeline, ComputePipelineDesc, GpuContext, MemLocation,
    Profiler, Readback,
};

/// Most workgroups one GC dispatch launches (the passes loop over the rest).
const MAX_WORKGROUPS: u32 = 65_535;

/// What a collection did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GcReport {
    /// Live handles naming no allocated slab of the pool (beyond it, or stale: ignored).
    pub bad_handles: u32,
    /// Items removed (occupied slots whose handle was not live).
    pub freed_items: u32,
    /// Items kept (occupied slots whose handle was live): the table's live items after it.
    pub kept_items: u32,
    /// Slabs unlinked and returned to the allocator.
    pub freed_slabs: u32,
}

/// Word range of a slab inside its super block: (super block, first word).
fn slab_start(layout: &SlabLayout, slab: u32) -> (usize, usize) {
    let local = (slab % SLABS_PER_SUPER_BLOCK) as usize;
    (
        (slab / SLABS_PER_SUPER_BLOCK) as usize,
        SUPER_BLOCK_BITMASK_WORDS as usize + local * layout.slab_words as usize,
    )
}

/// Occupied slots of a slab, by the layout's own marker.
fn occupied_mask(layout: &SlabLayout, words: &[u32]) -> u32 {
    if layout.variant != HashVariant::Atomic64 {
        return words[SLAB_OCCUPANCY as usize];
    }
    (0..SLAB_SLOTS)
        .filter(|&slot| {
            let first = words[layout.item_word(slot, 0) as usize];
            if layout.item_words == 1 {
                first != 0
            } else {
                first | words[layout.item_word(slot, 1) as usize] != 0
            }
        })
        .fold(0, |mask, slot| mask | 1 << slot)
}

/// CPU reference of a collection on a table image: keeps exactly the items named by `live`.
pub fn collect_cpu(image: &mut TableImage, live: &[Handle]) -> GcReport {
    let layout = image.layout;
    let capacity = image.capacity_slabs();
    let mut report = GcReport::default();
    for handle in live {
        if Handle::from_raw(handle.0).is_none() {
            continue;
        }
        if handle.slab() as u64 >= capacity || !image.is_allocated(handle.slab()) {
            report.bad_handles += 1;
            continue;
        }
        let (sb, start) = slab_start(&layout, handle.slab());
        image.super_blocks[sb][start + SLAB_ACTIVE as usize] |= 1 << handle.slot();
    }
    let slab_words = layout.slab_words as usize;
    for bucket in 0..image.heads.len() {
        let mut link = image.heads[bucket];
        let mut prev: Option<u32> = None;
        while link != 0 {
            let slab = link - 1;
            let (sb, start) = slab_start(&layout, slab);
            let words = &mut image.super_blocks[sb][start..start + slab_words];
            let next = words[SLAB_NEXT as usize];
            let occupied = occupied_mask(&layout, words);
            let kept = occupied & words[SLAB_ACTIVE as usize];
            let garbage = occupied & !kept;
            report.freed_items += garbage.count_ones();
            report.kept_items += kept.count_ones();
            for slot in (0..SLAB_SLOTS).filter(|s| garbage >> s & 1 == 1) {
                for w in 0..layout.item_words {
                    words[layout.item_word(slot, w) as usize] = 0;
                }
                let h = layout.hashes as usize;
                match layout.variant {
                    HashVariant::AccelHash32 => words[h + slot as usize] = 0,
                    HashVariant::AccelHash8 => {
                        words[h + slot as usize / 4] &= !(0xff << (8 * (slot % 4)))
                    }
                    _ => {}
                }
            }
            match prev {
                _ if kept == 0 => {
                    words.fill(0);
                    match prev {
                        Some(prev_slab) => {
                            let (psb, pstart) = slab_start(&layout, prev_slab);
                            image.super_blocks[psb][pstart + SLAB_NEXT as usize] = next;
                        }
                        None => image.heads[bucket] = next,
                    }
                    let local = slab % SLABS_PER_SUPER_BLOCK;
                    image.super_blocks[sb][(local / 32) as usize] &= !(1 << (local % 32));
                    image.status.allocated_slabs = image.status.allocated_slabs.wrapping_sub(1);
                    report.freed_slabs += 1;
                }
                _ => {
                    if layout.variant != HashVariant::Atomic64 {
                        words[SLAB_OCCUPANCY as usize] = kept;
                    }
                    words[SLAB_ACTIVE as usize] = 0;
                    prev = Some(slab);
                }
            }
            link = next;
        }
    }
    report
}

/// A collection recorded by [`GpuGarbageCollector::record_collect`]: its counters and the
/// table's status, read by [`GpuGarbageCollector::finish_collect`] after the submission.
#[derive(Debug)]
pub struct PendingGc {
    counters: Readback<GcCounters>,
    status: Readback<HashStatus>,
}

/// The GC passes of one table layout (variant and item size).
pub struct GpuGarbageCollector {
    ctx: Arc<GpuContext>,
    layout: SlabLayout,
    /// Invocations per workgroup: with subgroup teams one subgroup (on lavapipe, Mesa 22.3,
    /// subgroups of one workgroup leaving a pass at different times gave wrong ballots), with
    /// single lanes the table's workgroup (no subgroup operations).
    workgroup: u32,
    /// Lanes sweeping one bucket: the subgroup size or 1.
    team: u32,
    mark: ComputePipeline,
    sweep: ComputePipeline,
    /// The passes' counters (zeroed at the start of every recorded collection; collections
    /// on the one queue run one after the other).
    counters: Buffer,
}

impl GpuGarbageCollector {
    /// Compiles the passes for `table`'s layout and team size (usable with any table of the same
    /// layout).
    pub fn new(
        ctx: &Arc<GpuContext>,
        table: &GpuHashTable,
    ) -> Result<GpuGarbageCollector, HashError> {
        let subgroup = ctx.info().subgroup_size;
        if subgroup == 0 || !subgroup.is_power_of_two() {
            return Err(HashError::Config(format!(
                "unsupported subgroup size {subgroup}"
            )));
        }
        // The table's constants; subgroup teams get a workgroup of one subgroup.
        let [table_workgroup, _, variant, item_words, team] = table.spec_constants();
        let workgroup = if team == 1 { table_workgroup } else { subgroup };
        let spec = [workgroup, subgroup, variant, item_words, team];
        let pipeline = |name: &str, spirv: &[u32]| {
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name,
                spirv,
                spec_constants: &spec,
                push_constant_size: std::mem::size_of::<super::layout::HashPush>() as u32,
                bindings: &[],
            })
        };
        Ok(GpuGarbageCollector {
            ctx: Arc::clone(ctx),
            layout: table.layout(),
            workgroup,
            team,
            mark: pipeline("hash gc mark", shaders::HASH_GC_MARK)?,
            sweep: pipeline("hash gc sweep", shaders::HASH_GC_SWEEP)?,
            counters: ctx.create_buffer(
                "hash gc counters",
                std::mem::size_of::<GcCounters>() as u64,
                MemLocation::GpuOnly,
            )?,
        })
    }

    /// The mark and sweep pipelines (to warm ahead: [`crate::gpu::Commands::warm`]).
    pub fn pipelines(&self) -> [&ComputePipeline; 2] {
        [&self.mark, &self.sweep]
    }

    /// Lanes sweeping one bucket: the subgroup size, or 1 (the table's team mode).
    pub fn team_size(&self) -> u32 {
        self.team
    }

    /// Collects `table`, keeping the items named by the host handles `live` (sentinels are
    /// skipped; a handle beyond the pool is an error and nothing is collected; a handle in a
    /// free slab is counted in [`GcReport::bad_handles`] and ignored).
    pub fn collect(
        &self,
        table: &mut GpuHashTable,
        live: &[Handle],
        profiler: Option<&mut Profiler>,
    ) -> Result<GcReport, HashError> {
        let capacity = table.pool().capacity_slabs();
        if let Some(bad) = live
            .iter()
            .find(|h| h.0 != HANDLE_MISS && h.0 != HANDLE_INVALID && h.slab() as u64 >= capacity)
        {
            return Err(HashError::InvalidArgument(format!(
                "live handle {:#x} names slab {} beyond the pool of {capacity} slabs",
                bad.0,
                bad.slab()
            )));
        }
        let count = u32::try_from(live.len())
            .map_err(|_| HashError::InvalidArgument("more than 2^32 live handles".into()))?;
        let raw: Vec<u32> = if live.is_empty() {
            vec![HANDLE_MISS]
        } else {
            live.iter().map(|h| h.0).collect()
        };
        let buffer = self.ctx.create_buffer(
            "hash gc live handles",
            4 * raw.len() as u64,
            MemLocation::GpuOnly,
        )?;
        // Upload and both passes in one submission, one host wait.
        let mut cmd = self.ctx.begin_commands("hash gc")?;
        cmd.upload(&buffer, 0, &raw)?;
        self.finish_recorded(cmd, table, &buffer, count, profiler)
    }

    /// Records, submits and finishes a collection that starts in `cmd`.
    fn finish_recorded<'a>(
        &'a self,
        mut cmd: Commands<'a>,
        table: &'a GpuHashTable,
        live: &'a Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<GcReport, HashError> {
        let pending = self.record_collect(&mut cmd, table, live, count, profiler.as_deref_mut())?;
        cmd.submit_async()?;
        let report = self.finish_collect(pending)?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Ok(report)
    }

    /// Collects `table`, keeping the items named by the first `count` handles of `live` (a GPU
    /// buffer of `u32` handles; sentinels skipped; handles beyond the pool or in a free slab
    /// counted in [`GcReport::bad_handles`] and ignored). One submission, one host wait.
    pub fn collect_buffers(
        &self,
        table: &mut GpuHashTable,
        live: &Buffer,
        count: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<GcReport, HashError> {
        let cmd = self.ctx.begin_commands("hash gc")?;
        self.finish_recorded(cmd, table, live, count, profiler)
    }

    /// Records a collection of `table` into `cmd` (mark, sweep, then readbacks of the counters
    /// and the table status); the table must not be used by other passes recorded between this
    /// and the submission's completion. Finish with [`GpuGarbageCollector::finish_collect`].
    pub fn record_collect<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        table: &'a GpuHashTable,
        live: &'a Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<PendingGc, HashError> {
        self.check_layout(table)?;
        if live.size() < 4 * count as u64 {
            return Err(HashError::InvalidArgument(format!(
                "buffer '{}' holds fewer than {count} handles",
                live.name()
            )));
        }
        let push = table.push_constants(self.counters.address(), live.address(), count);
        self.record_start(cmd, table);
        if let Some(p) = profiler.as_deref_mut() {
            p.begin_pass(cmd, "hash gc mark");
        }
        let mark_groups = count.div_ceil(self.workgroup).min(MAX_WORKGROUPS);
        cmd.dispatch(
            &self.mark,
            [mark_groups, 1, 1],
            bytemuck::bytes_of(&push),
            &[],
        )?;
        if let Some(p) = profiler.as_deref_mut() {
            p.end_pass(cmd);
        }
        cmd.barrier();
        self.record_sweep_pass(cmd, table, &push, profiler)
    }

    /// Records a sweep of `table` whose live items were marked by the caller's own passes (the
    /// hash DAG's GC marks what its roots reach): every unmarked item is freed, as in
    /// [`GpuGarbageCollector::record_collect`] without its mark pass.
    pub fn record_sweep<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        table: &'a GpuHashTable,
        profiler: Option<&mut Profiler>,
    ) -> Result<PendingGc, HashError> {
        self.check_layout(table)?;
        // The sweep reads no handles.
        let push = table.push_constants(self.counters.address(), 0, 0);
        self.record_start(cmd, table);
        self.record_sweep_pass(cmd, table, &push, profiler)
    }

    fn check_layout(&self, table: &GpuHashTable) -> Result<(), HashError> {
        if table.layout() != self.layout {
            return Err(HashError::InvalidArgument(format!(
                "collector built for {:?}, table is {:?}",
                self.layout,
                table.layout()
            )));
        }
        Ok(())
    }

    /// What every collection records first: zeroed counters and the table's GC side effects.
    fn record_start<'a>(&'a self, cmd: &mut Commands<'a>, table: &'a GpuHashTable) {
        cmd.fill_buffer(&self.counters, 0);
        table.record_gc_side_effects(cmd);
    }

    /// The sweep pass and the readbacks [`GpuGarbageCollector::finish_collect`] reads.
    fn record_sweep_pass<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        table: &'a GpuHashTable,
        push: &super::layout::HashPush,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<PendingGc, HashError> {
        if let Some(p) = profiler.as_deref_mut() {
            p.begin_pass(cmd, "hash gc sweep");
        }
        let sweep_groups = table
            .config()
            .buckets
            .div_ceil(self.workgroup / self.team)
            .min(MAX_WORKGROUPS);
        cmd.dispatch(
            &self.sweep,
            [sweep_groups, 1, 1],
            bytemuck::bytes_of(push),
            &[],
        )?;
        if let Some(p) = profiler {
            p.end_pass(cmd);
        }
        cmd.barrier();
        Ok(PendingGc {
            counters: cmd.readback::<GcCounters>(&self.counters, 0, 1)?,
            status: cmd.readback::<HashStatus>(table.pool().status_buffer(), 0, 1)?,
        })
    }

    /// Reads a recorded collection's results once its submission was made (waits if needed).
    pub fn finish_collect(&self, pending: PendingGc) -> Result<GcReport, HashError> {
        let status = pending.status.read()?[0];

        if status.subgroup_mismatch != 0 {
            return Err(HashError::SubgroupMismatch {
                expected: self.team,
                actual: status.subgroup_mismatch,
            });
        }
        if status.broken_chains != 0 {
            return Err(HashError::CorruptTable {
                walks: status.broken_chains,
            });
        }
        let c = pending.counters.read()?;
        Ok(GcReport {
            bad_handles: c[0].bad_handles,
            freed_items: c[0].freed_items,
            freed_slabs: c[0].freed_slabs,
            kept_items: c[0].kept_items,
        })
    }
}
