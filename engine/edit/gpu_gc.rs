//! History limits and garbage collection of the GPU hash DAG (dissertation §4.4.3).
//!
//! GC keeps every item reachable from a live root (the undo steps, the current root and the
//! redo branch) and frees every other item of the nine tables:
//! 1. mark, top-down one level at a time (`shaders/glsl/edit/gc_trace.comp`): the distinct
//!    node roots form the first frontier; each frontier node reads its children (the
//!    `edit_read` logic of `edit/common.glsl`) and sets each child's bit in its slab's `active`
//!    word with an `atomicOr`; a child whose bit was clear joins the next frontier, so every
//!    reachable item is expanded once whatever the number of parents. The host reads one
//!    counter per level (the next frontier's length);
//! 2. sweep: the tables' own GC sweep ([`GpuGarbageCollector`], one submission for the nine
//!    tables) frees every occupied slot whose bit is clear, resets the bits and returns empty
//!    slabs to the allocator; its counts of kept slots are the live items per table. Handles of
//!    kept items never change.
//!
//! An item reached both as a leaf and as an inner node (2-word items can be either) is marked
//! once; only inner-level items are ever expanded, and an item is expanded as what its first
//! parent reached it as, which names the same child pointers at any level.
//!
//! The undo depth ([`GpuHashDagConfig::undo_depth`]) bounds the history: an edit drops the redo
//! branch and the oldest roots beyond the depth; the next GC frees what only they reached. GC
//! runs on request ([`GpuHashDag::gc`]) and automatically before an edit once a table's pool
//! use passes [`GpuHashDagConfig::auto_gc_threshold`], and after an edit that ran a pool out
//! (the edit then runs once more).

use std::sync::Arc;
use std::time::Instant;

use rustc_hash::FxHashSet;

use super::gpu::{GpuDagError, GpuHashDag, GpuHashDagConfig};
use super::gpu_shared::EditPush;
use super::item::{Root, TABLE_COUNT};
use crate::gpu::{
    shaders, Buffer, ComputePipeline, ComputePipelineDesc, MemLocation, Profiler, Readback,
};
use crate::hash::gc::GpuGarbageCollector;
use crate::hash::layout::SLABS_PER_SUPER_BLOCK;
use crate::hash::HashStatus;

/// Pass flag: the frontier items are the live roots and are marked too (GLSL `EDIT_FLAG_GC_ROOTS`).
const FLAG_GC_ROOTS: u32 = 16;
/// Pass flag: the children are leaves, marked but not listed (GLSL `EDIT_FLAG_GC_LAST`).
const FLAG_GC_LAST: u32 = 32;
/// Counters of a trace pass: next frontier length, pointers naming no allocated slab.
const TRACE_COUNTERS: usize = 2;
/// Invocations per workgroup of the trace pass.
const GROUP: u32 = 64;

/// Default undo depth: the undo steps kept by an edit (`voxdag edit --undo-depth`).
pub const DEFAULT_UNDO_DEPTH: usize = 64;
/// Default auto-GC threshold: collect before an edit once a table's allocated slabs pass 3/4
/// of its largest pool (`max_super_blocks`), early enough that the edit's inserts fit.
pub const DEFAULT_AUTO_GC_THRESHOLD: f32 = 0.75;

/// What a garbage collection did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GcStats {
    /// Live roots it kept (distinct node roots; empty and full roots name no item).
    pub roots: usize,
    /// Items reachable from the live roots, per table (index = item words - 2): all kept.
    pub live_per_table: Vec<u64>,
    /// Items freed per table.
    pub freed_per_table: Vec<u64>,
    /// Slabs returned to the allocators.
    pub freed_slabs: u64,
    /// Items kept (sum of `live_per_table`).
    pub live: u64,
    /// Items freed (sum of `freed_per_table`).
    pub freed: u64,
    /// Device bytes of the tables' allocated slabs before and after.
    pub slab_bytes_before: u64,
    /// Device bytes of the tables' allocated slabs after.
    pub slab_bytes_after: u64,
    /// Mark passes run (levels with a non-empty frontier).
    pub mark_passes: u32,
    /// Whether the collection was started by the pool threshold rather than a request.
    pub automatic: bool,
    /// Wall time of the whole collection, milliseconds.
    pub ms: f64,
}

/// GC state of a [`GpuHashDag`]: pipelines built on first use and the log of automatic runs.
#[derive(Default)]
pub struct GcState {
    trace: Option<ComputePipeline>,
    collectors: Vec<GpuGarbageCollector>,
    /// Statistics of automatic collections not yet taken by [`GpuHashDag::take_auto_gc`].
    auto_runs: Vec<GcStats>,
    /// Allocated slabs per table, read with the last root (`read_root`) or after the last GC:
    /// at least the current use (only inserts allocate, and every path that inserts outside a
    /// finished edit or load clears it), so the check before an edit needs no readback.
    pub(super) pool_use: Option<Vec<u64>>,
    /// Collections started (manual and automatic).
    collections: u64,
}

impl GpuHashDag {
    /// Undo steps kept.
    pub fn undo_depth(&self) -> usize {
        self.config.undo_depth
    }

    /// Sets the undo depth, dropping the oldest undo steps beyond it (GC then frees them).
    pub fn set_undo_depth(&mut self, depth: usize) {
        self.config.undo_depth = depth;
        self.trim_history();
    }

    /// Sets the auto-GC threshold (fraction of a table's largest pool; `None`: never).
    pub fn set_auto_gc_threshold(&mut self, threshold: Option<f32>) {
        self.config.auto_gc_threshold = threshold;
    }

    /// Makes `root` (the result of an edit) current: the redo branch is dropped, then the
    /// oldest roots beyond the undo depth.
    pub(super) fn push_root(&mut self, root: Root) {
        self.roots.truncate(self.current + 1);
        self.roots.push(root);
        self.current += 1;
        self.trim_history();
    }

    fn trim_history(&mut self) {
        let excess = self.current.saturating_sub(self.config.undo_depth);
        self.roots.drain(..excess);
        self.current -= excess;
    }

    /// Collections started so far, manual and automatic: a pointer read before one may name
    /// another item after it (freed handles are reused), so caches keyed by pointers compare it.
    pub fn collections(&self) -> u64 {
        self.gc_state.collections
    }

    /// Statistics of the automatic collections run since the last call, oldest first.
    pub fn take_auto_gc(&mut self) -> Vec<GcStats> {
        std::mem::take(&mut self.gc_state.auto_runs)
    }

    /// Per table: (allocated slabs, slabs of its largest pool), read in one submission.
    pub fn pool_use(&self) -> Result<Vec<(u64, u64)>, GpuDagError> {
        let mut cmd = self.ctx.begin_commands("hash dag pool use")?;
        let backs: Vec<Readback<HashStatus>> = self
            .tables
            .iter()
            .map(|t| cmd.readback::<HashStatus>(t.pool().status_buffer(), 0, 1))
            .collect::<Result<_, _>>()?;
        cmd.submit_async()?;
        let max = self.config.max_super_blocks as u64 * SLABS_PER_SUPER_BLOCK as u64;
        backs
            .into_iter()
            .map(|b| Ok((b.read()?[0].allocated_slabs as u64, max)))
            .collect()
    }

    /// Device bytes of the allocated slabs of the nine tables.
    fn slab_bytes(&self, pool_use: &[(u64, u64)]) -> u64 {
        self.tables
            .iter()
            .zip(pool_use)
            .map(|(t, &(slabs, _))| slabs * 4 * t.layout().slab_words as u64)
            .sum()
    }

    /// Runs a GC first when a table's pool use passes the auto-GC threshold (called before
    /// every edit); returns whether it ran (its statistics go to [`GpuHashDag::take_auto_gc`]).
    pub fn auto_gc(&mut self) -> Result<bool, GpuDagError> {
        let Some(threshold) = self.config.auto_gc_threshold else {
            return Ok(false);
        };
        let used = match &self.gc_state.pool_use {
            Some(used) => used.clone(),
            None => self.pool_use()?.iter().map(|&(used, _)| used).collect(),
        };
        let max = self.config.max_super_blocks as f64 * SLABS_PER_SUPER_BLOCK as f64;
        let over = used.iter().any(|&u| u as f64 > threshold as f64 * max);
        if !over {
            return Ok(false);
        }
        let mut stats = self.gc(None)?;
        stats.automatic = true;
        self.gc_state.auto_runs.push(stats);
        Ok(true)
    }

    /// After an edit ran a pool out: a GC (logged as automatic, [`GpuHashDag::take_auto_gc`])
    /// frees the failed attempt's unreachable items and whatever else only dropped roots
    /// reached; returns whether it freed anything (then the edit is worth one more attempt).
    pub(super) fn gc_after_exhaustion(&mut self) -> Result<bool, GpuDagError> {
        let mut stats = self.gc(None)?;
        stats.automatic = true;
        let freed = stats.freed > 0;
        self.gc_state.auto_runs.push(stats);
        Ok(freed)
    }

    /// Makes the collection's pipelines (the trace, each table's mark and sweep) unless made,
    /// and warms them ([`crate::gpu::Commands::warm`]): the first [`GpuHashDag::gc`] does it
    /// otherwise, a stall in the middle of editing (~65 ms on lavapipe for nine tables, plus
    /// their native compiles at the first dispatch). Returns the milliseconds it took.
    pub fn prepare_gc(&mut self) -> Result<f64, GpuDagError> {
        let start = Instant::now();
        let ctx = Arc::clone(&self.ctx);
        if self.gc_state.trace.is_none() {
            self.gc_state.trace = Some(ctx.create_compute_pipeline(&ComputePipelineDesc {
                name: "edit gc trace",
                spirv: shaders::EDIT_GC_TRACE,
                spec_constants: &[],
                push_constant_size: std::mem::size_of::<EditPush>() as u32,
                bindings: &[],
            })?);
        }
        if self.gc_state.collectors.is_empty() {
            self.gc_state.collectors = self
                .tables
                .iter()
                .map(|t| GpuGarbageCollector::new(&ctx, t))
                .collect::<Result<_, _>>()?;
        }
        // Compiled now rather than at their first dispatch (llvmpipe; `Commands::warm`).
        let mut cmd = ctx.begin_commands("edit gc warm pipelines")?;
        cmd.warm(self.gc_state.trace.as_ref().expect("made above"), &[])?;
        for collector in &self.gc_state.collectors {
            for pipeline in collector.pipelines() {
                cmd.warm(pipeline, &[])?;
            }
        }
        cmd.submit()?;
        Ok(start.elapsed().as_secs_f64() * 1e3)
    }

    /// Garbage collection from every live root ([`GpuHashDag::roots`]): marks what they reach
    /// on the GPU and frees every other item of the nine tables (see the module docs).
    pub fn gc(&mut self, mut profiler: Option<&mut Profiler>) -> Result<GcStats, GpuDagError> {
        let start = Instant::now();
        // Counted first: even a failed collection may have freed items.
        self.gc_state.collections += 1;
        let ctx = Arc::clone(&self.ctx);
        self.prepare_gc()?;
        let before = self.pool_use()?;
        let mut stats = GcStats {
            live_per_table: vec![0; TABLE_COUNT as usize],
            freed_per_table: vec![0; TABLE_COUNT as usize],
            slab_bytes_before: self.slab_bytes(&before),
            ..GcStats::default()
        };
        let mut seen = FxHashSet::default();
        let roots: Vec<u32> = self
            .roots
            .iter()
            .filter_map(|r| match r {
                Root::Node(p) => Some(p.0),
                _ => None,
            })
            .filter(|p| seen.insert(*p))
            .collect();
        stats.roots = roots.len();
        let pools: Vec<u32> = self
            .tables
            .iter()
            .map(|t| t.pool().capacity_slabs() as u32)
            .collect();
        let pool_buf = ctx.upload("hash dag gc pools", &pools)?;
        let counters = ctx.create_buffer(
            "hash dag gc counters",
            4 * TRACE_COUNTERS as u64,
            MemLocation::GpuOnly,
        )?;
        let trace = self.gc_state.trace.as_ref().expect("built above");
        let mut frontier: Option<Buffer> = None;
        let mut count = roots.len() as u32;
        if count > 0 {
            frontier = Some(ctx.upload("hash dag gc roots", &roots)?);
        }
        let mut level = self.root_level;
        while count > 0 && level > 0 {
            let input = frontier.take().expect("a frontier of `count` nodes");
            let last = level == 1;
            let capacity = if last { 1 } else { count.saturating_mul(8) };
            let next = ctx.create_buffer(
                "hash dag gc frontier",
                4 * capacity as u64,
                MemLocation::GpuOnly,
            )?;
            let mut flags = 0;
            if level == self.root_level {
                flags |= FLAG_GC_ROOTS;
            }
            if last {
                flags |= FLAG_GC_LAST;
            }
            let push = EditPush {
                src: input.address(),
                dst: next.address(),
                dst2: pool_buf.address(),
                tables: self.table_addresses.address(),
                counters: counters.address(),
                count,
                level,
                flags,
                capacity,
                variant: self.config.variant.id(),
                ..EditPush::default()
            };
            let mut cmd = ctx.begin_commands("hash dag gc trace")?;
            cmd.fill_buffer(&counters, 0);
            cmd.begin_pass(&mut profiler, "edit gc trace");
            cmd.dispatch(
                trace,
                [count.div_ceil(GROUP).clamp(1, 65_535), 1, 1],
                bytemuck::bytes_of(&push),
                &[],
            )?;
            cmd.end_pass(&mut profiler);
            cmd.barrier();
            let back = cmd.readback::<u32>(&counters, 0, TRACE_COUNTERS)?;
            cmd.submit_async()?;
            let c = back.read()?;
            stats.mark_passes += 1;
            if c[1] != 0 {
                // Nothing is swept: the marks left set only keep more items at the next GC.
                return Err(GpuDagError::Corrupt(format!(
                    "{} pointers reachable from the live roots name no allocated slab",
                    c[1]
                )));
            }
            count = if last { 0 } else { c[0] };
            if count > capacity {
                return Err(GpuDagError::Corrupt(format!(
                    "GC frontier of level {} has {count} nodes (room for {capacity})",
                    level - 1
                )));
            }
            frontier = Some(next);
            level -= 1;
        }
        // Leaf roots (a one-level grid has none) and roots of a root-level-0 grid cannot occur:
        // root levels start at 1, and the first pass marks the roots themselves.
        let mut cmd = ctx.begin_commands("hash dag gc sweep")?;
        let mut pending = Vec::new();
        for (table, collector) in self.tables.iter().zip(&self.gc_state.collectors) {
            // The marks are already set by the passes above: sweep only.
            pending.push(collector.record_sweep(&mut cmd, table, profiler.as_deref_mut())?);
        }
        cmd.submit_async()?;
        for ((p, collector), s) in pending.into_iter().zip(&self.gc_state.collectors).zip(0..) {
            let report = collector.finish_collect(p)?;
            stats.freed_per_table[s] = report.freed_items as u64;
            // Marked items are exactly the ones the live roots reach: the ones kept.
            stats.live_per_table[s] = report.kept_items as u64;
            stats.freed_slabs += report.freed_slabs as u64;
        }
        if let Some(p) = profiler {
            p.resolve()?;
        }
        stats.live = stats.live_per_table.iter().sum();
        stats.freed = stats.freed_per_table.iter().sum();
        let after = self.pool_use()?;
        stats.slab_bytes_after = self.slab_bytes(&after);
        self.gc_state.pool_use = Some(after.iter().map(|&(used, _)| used).collect());
        stats.ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(stats)
    }
}

impl GpuHashDagConfig {
    /// This configuration with an undo depth of `depth` steps.
    pub fn with_undo_depth(self, depth: usize) -> GpuHashDagConfig {
        GpuHashDagConfig {
            undo_depth: depth,
            ..self
        }
    }
}
