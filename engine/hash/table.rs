//! [`GpuHashTable`]: one slab hash table on the GPU and its batch passes.
//!
//! Passes (each one dispatch, `shaders/glsl/hash/*.comp`): `search` (items -> handles or
//! [`HANDLE_MISS`]), `insert` (places every item whose handle is still `HANDLE_MISS`), `read`
//! (handles -> items). Each has a recorded form (`record_*`) that records into a caller's
//! [`Commands`]; the `*_buffers` and host-slice calls are wrappers that record everything (the
//! upload, the passes, the status and the result readbacks through the staging rings) into one
//! submission and wait once. `find_or_insert` = search, then an insert round over the misses (no
//! compaction: items already found are skipped by their handle), after a conservative pool
//! reservation; the status block is read back before and after the round in the same
//! submission. Only if a round reports items left out for lack of a slab does
//! [`GpuHashTable::finish_insert`] grow the pool and run another round for them.

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;

use super::alloc::SlabPool;
use super::claim::{ClaimTable, Claims};
use super::layout::{
    Handle, HashPush, HashStatus, HashVariant, SlabLayout, FLAG_CLAIMS, FLAG_HOLES, HANDLE_INVALID,
    HANDLE_MISS, MAX_SUPER_BLOCKS, SLABS_PER_SUPER_BLOCK, SLAB_SLOTS,
};
use super::reference::TableImage;
use super::HashError;
use crate::gpu::{
    shaders, Buffer, BufferSlice, Commands, ComputePipeline, ComputePipelineDesc, DeviceType,
    GpuContext, GpuError, MemLocation, Profiler, Readback,
};

/// How a table is built.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HashTableConfig {
    /// Slab layout.
    pub variant: HashVariant,
    /// Words per item, 1..=10.
    pub item_words: u32,
    /// Number of buckets (each a chain of slabs), at least 1.
    pub buckets: u32,
    /// Super blocks allocated at creation (at least 1).
    pub initial_super_blocks: u32,
    /// Grow the pool before each insert from a conservative estimate (true), or only after an
    /// insert round ran out of slabs (false; tests use it to force exhaustion).
    pub grow_before_insert: bool,
    /// Insert rounds (pass + grow) before giving up with [`HashError::Exhausted`].
    pub max_insert_rounds: u32,
    /// How many lanes work on one item.
    pub team: TeamMode,
    /// Most super blocks the pool may grow to (at most [`MAX_SUPER_BLOCKS`]; the hash DAG caps
    /// it so that handles fit its pointers).
    pub max_super_blocks: u32,
}

/// How many lanes of a subgroup work on one item.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TeamMode {
    /// [`TeamMode::SingleLane`] on CPU devices (lavapipe), [`TeamMode::Subgroup`] elsewhere.
    Auto,
    /// The whole subgroup cooperates on one item, scanning a slab in chunks of subgroup size.
    Subgroup,
    /// Every lane works on its own item and scans slabs alone (no subgroup operations: on a
    /// CPU implementation they cost more than the loads they spread).
    SingleLane,
}

impl HashTableConfig {
    /// A table of `variant` for `item_words`-word items with `buckets` buckets, one initial
    /// super block, growth before inserts, 8 insert rounds and the device's team mode.
    pub fn new(variant: HashVariant, item_words: u32, buckets: u32) -> HashTableConfig {
        HashTableConfig {
            variant,
            item_words,
            buckets,
            initial_super_blocks: 1,
            grow_before_insert: true,
            max_insert_rounds: 8,
            team: TeamMode::Auto,
            max_super_blocks: MAX_SUPER_BLOCKS,
        }
    }
}

/// What an insert did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct InsertReport {
    /// Insert passes run (1 unless the pool ran out of slabs).
    pub rounds: u32,
    /// Items left out by a round for lack of a slab (and placed by a later round).
    pub retried_items: u32,
    /// Items rejected by the layout (their handle is [`HANDLE_INVALID`]).
    pub invalid_items: u32,
    /// Super blocks in the pool afterwards.
    pub super_blocks: u32,
}

/// A slab hash table on the GPU.
pub struct GpuHashTable {
    ctx: Arc<GpuContext>,
    config: HashTableConfig,
    layout: SlabLayout,
    pool: SlabPool,
    heads: Buffer,
    /// Insert hints, one link per bucket (`HashPush::tails`): zeroed at creation and by GC.
    tails: Buffer,
    search: ComputePipeline,
    insert: ComputePipeline,
    read: ComputePipeline,
    /// Search-and-claim pass (single lanes only: `claim.rs`).
    claim: Option<ComputePipeline>,
    workgroup: u32,
    subgroup: u32,
    team: u32,
    /// Status after the last insert round this table read (counters are cumulative); its
    /// `allocated_slabs` only over-estimates (GC frees), which keeps [`GpuHashTable::reserve`]
    /// conservative.
    status: HashStatus,
    /// Seed of the next pass's random block choice.
    pass_seed: AtomicU32,
    /// Whether a garbage collection was recorded on this table ([`FLAG_HOLES`]).
    holes: AtomicBool,
}

/// A hash pass's pipeline: `spec` as [`GpuHashTable::spec_constants`], push constants `HashPush`.
pub(super) fn hash_pipeline(
    ctx: &Arc<GpuContext>,
    name: &str,
    spirv: &[u32],
    spec: &[u32],
) -> Result<ComputePipeline, GpuError> {
    ctx.create_compute_pipeline(&ComputePipelineDesc {
        name,
        spirv,
        spec_constants: spec,
        push_constant_size: std::mem::size_of::<HashPush>() as u32,
        bindings: &[],
    })
}

/// What the inserts of a submission did to a table, from its status block around them
/// ([`GpuHashTable::check_inserts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InsertCheck {
    /// Items left out for lack of a slab (their handles stayed [`HANDLE_MISS`]).
    pub left_out: u32,
    /// Items rejected by the layout.
    pub invalid: u32,
}

/// An insert recorded by [`GpuHashTable::record_insert`]: the status block before and after its
/// insert round, read by [`GpuHashTable::finish_insert`] once the submission has completed.
#[derive(Debug)]
pub struct PendingInsert {
    before: Readback<HashStatus>,
    after: Readback<HashStatus>,
}

impl GpuHashTable {
    /// An empty table: zeroed bucket heads, `initial_super_blocks` super blocks, its pipelines
    /// specialised for the device's subgroup size.
    pub fn new(ctx: &Arc<GpuContext>, config: &HashTableConfig) -> Result<GpuHashTable, HashError> {
        let layout = SlabLayout::new(config.variant, config.item_words).ok_or_else(|| {
            HashError::Config(format!(
                "item size {} is outside 1..=10 words",
                config.item_words
            ))
        })?;
        if config.buckets == 0 {
            return Err(HashError::Config(
                "a table needs at least one bucket".into(),
            ));
        }
        if config.max_super_blocks == 0
            || config.max_super_blocks > MAX_SUPER_BLOCKS
            || config.initial_super_blocks > config.max_super_blocks
            || config.max_insert_rounds == 0
        {
            return Err(HashError::Config(format!(
                "need initial super blocks <= max super blocks (1..={MAX_SUPER_BLOCKS}) and insert rounds >= 1"
            )));
        }
        let subgroup = ctx.info().subgroup_size;
        if subgroup == 0 || !subgroup.is_power_of_two() {
            return Err(HashError::Config(format!(
                "unsupported subgroup size {subgroup}"
            )));
        }
        let workgroup = subgroup.max(64);
        let single_lane = match config.team {
            TeamMode::Auto => ctx.info().device_type == DeviceType::Cpu,
            TeamMode::Subgroup => false,
            TeamMode::SingleLane => true,
        };
        let team = if single_lane { 1 } else { subgroup };
        let spec = [
            workgroup,
            subgroup,
            config.variant.id(),
            config.item_words,
            team,
        ];
        let pipeline = |name: &str, spirv: &[u32]| hash_pipeline(ctx, name, spirv, &spec);
        let search = pipeline("hash search", shaders::HASH_SEARCH)?;
        let insert = pipeline("hash insert", shaders::HASH_INSERT)?;
        let read = pipeline("hash read", shaders::HASH_READ)?;
        let claim = single_lane
            .then(|| pipeline("hash search and claim", shaders::HASH_CLAIM))
            .transpose()?;
        let heads = ctx.create_buffer(
            "hash bucket heads",
            4 * config.buckets as u64,
            MemLocation::GpuOnly,
        )?;
        let tails = ctx.create_buffer(
            "hash insert hints",
            4 * config.buckets as u64,
            MemLocation::GpuOnly,
        )?;
        let mut cmd = ctx.begin_commands("hash heads init")?;
        cmd.fill_buffer(&heads, 0);
        cmd.fill_buffer(&tails, 0);
        // No wait: later submissions on the queue are ordered after it.
        cmd.submit_async()?;
        let pool = SlabPool::new(ctx, layout, config.initial_super_blocks)?;
        Ok(GpuHashTable {
            ctx: Arc::clone(ctx),
            config: config.clone(),
            layout,
            pool,
            heads,
            tails,
            search,
            insert,
            read,
            claim,
            workgroup,
            subgroup,
            team,
            status: HashStatus::default(),
            pass_seed: AtomicU32::new(0x2545_f491),
            holes: AtomicBool::new(false),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &HashTableConfig {
        &self.config
    }

    /// The slab layout.
    pub fn layout(&self) -> SlabLayout {
        self.layout
    }

    /// The slab pool (addresses, occupancy, growth) — garbage collection frees into it.
    pub fn pool(&self) -> &SlabPool {
        &self.pool
    }

    /// The slab pool, mutably (to grow it).
    pub fn pool_mut(&mut self) -> &mut SlabPool {
        &mut self.pool
    }

    /// Device address of the bucket heads (`push.heads`).
    pub fn heads_address(&self) -> u64 {
        self.heads.address()
    }

    /// Records what a garbage collection of this table needs besides its passes: clears the
    /// insert hints (GC unlinks slabs they may name) and marks the table as possibly holding
    /// holes (Atomic64 inserts then scan whole slabs).
    pub(crate) fn record_gc_side_effects<'a>(&'a self, cmd: &mut Commands<'a>) {
        cmd.fill_buffer(&self.tails, 0);
        self.holes.store(true, Ordering::Relaxed);
    }

    /// Specialization constants of every hash pass: workgroup size, subgroup size, variant id,
    /// item words, team size (ids 0..=4 in `hash/common.glsl`).
    pub fn spec_constants(&self) -> [u32; 5] {
        [
            self.workgroup,
            self.subgroup,
            self.config.variant.id(),
            self.config.item_words,
            self.team,
        ]
    }

    /// Lanes working on one item: the subgroup size, or 1 (see [`TeamMode`]).
    pub fn team_size(&self) -> u32 {
        self.team
    }

    /// Push constants naming this table plus an items and a handles buffer (addresses).
    pub fn push_constants(&self, items: u64, handles: u64, count: u32) -> HashPush {
        HashPush {
            super_blocks: self.pool.table_address(),
            heads: self.heads.address(),
            tails: self.tails.address(),
            status: self.pool.status_address(),
            items,
            handles,
            count,
            buckets: self.config.buckets,
            blocks: self.pool.block_count(),
            seed: self.pass_seed.load(Ordering::Relaxed),
            flags: if self.holes.load(Ordering::Relaxed) {
                FLAG_HOLES
            } else {
                0
            },
            ..HashPush::default()
        }
    }

    /// Device memory of the table (heads and pool), in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.heads.size() + self.tails.size() + self.pool.gpu_bytes()
    }

    /// Slabs allocated when the host last read the table's status (after inserts and GC).
    pub fn allocated_slabs(&self) -> u32 {
        self.status.allocated_slabs
    }

    /// Items the search, claim and insert passes take per workgroup (one per team).
    pub fn items_per_group(&self) -> u32 {
        self.workgroup / self.team
    }

    /// Workgroups for `count` items at one item per team (grid-stride beyond the limit).
    pub(super) fn cooperative_groups(&self, count: u32) -> u32 {
        count
            .div_ceil(self.items_per_group())
            .clamp(1, self.ctx.info().max_compute_workgroup_count[0])
    }

    fn record<'a>(
        &self,
        cmd: &mut Commands<'a>,
        profiler: &mut Option<&mut Profiler>,
        name: &str,
        pipeline: &'a ComputePipeline,
        groups: u32,
        push: &HashPush,
    ) -> Result<(), HashError> {
        cmd.begin_pass(profiler, name);
        cmd.dispatch(pipeline, [groups, 1, 1], bytemuck::bytes_of(push), &[])?;
        cmd.end_pass(profiler);
        Ok(())
    }

    fn check_count(
        buffer: BufferSlice<'_>,
        count: u32,
        words_each: u32,
        what: &str,
    ) -> Result<(), HashError> {
        // The shaders index words with a 32-bit uint.
        if count as u64 * words_each as u64 > u32::MAX as u64 {
            return Err(HashError::InvalidArgument(format!(
                "{count} entries of {words_each} words exceed the 2^32-word limit of one batch"
            )));
        }
        let need = count as u64 * words_each as u64 * 4;
        if buffer.size() < need {
            return Err(HashError::InvalidArgument(format!(
                "{what} buffer '{}' has {} bytes; {count} entries need {need}",
                buffer.name(),
                buffer.size()
            )));
        }
        Ok(())
    }

    /// Records a search pass into `cmd`: `handles[i]` = handle of `items[i]` or
    /// [`HANDLE_MISS`] (profiled as "hash search"). `items` holds `count * item_words` words,
    /// `handles` `count` words. Errors the pass reports land in the status block
    /// ([`GpuHashTable::record_status`]).
    pub fn record_search<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: impl Into<BufferSlice<'a>>,
        handles: impl Into<BufferSlice<'a>>,
        count: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        self.record_search_pass(cmd, items.into(), handles.into(), count, None, profiler)
    }

    /// The search pass, or with `claims` the search-and-claim pass (which clears the claim
    /// table first).
    fn record_search_pass<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: BufferSlice<'a>,
        handles: BufferSlice<'a>,
        count: u32,
        claims: Option<Claims<'a>>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        if count == 0 {
            return Ok(());
        }
        let push = self.batch_push(items, handles, count, claims)?;
        let (name, pipeline) = match (claims, &self.claim) {
            (Some(claims), Some(claim)) => {
                claims.table.record_clear(cmd)?;
                ("hash search and claim", claim)
            }
            _ => ("hash search", &self.search),
        };
        let groups = self.cooperative_groups(count);
        self.record(cmd, &mut profiler, name, pipeline, groups, &push)?;
        cmd.barrier();
        Ok(())
    }

    /// Records a readback of the status block (through the readback ring).
    pub fn record_status<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
    ) -> Result<Readback<HashStatus>, HashError> {
        Ok(cmd.readback::<HashStatus>(self.pool.status_buffer(), 0, 1)?)
    }

    /// Records one insert round into `cmd`: places every item whose handle is still
    /// [`HANDLE_MISS`] (profiled as "hash insert"), with status readbacks before and after.
    /// Items left out for lack of a slab show in the status; [`GpuHashTable::finish_insert`]
    /// grows the pool and runs further rounds for them.
    pub fn record_insert_round<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: impl Into<BufferSlice<'a>>,
        handles: impl Into<BufferSlice<'a>>,
        count: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<PendingInsert, HashError> {
        self.record_round(cmd, items.into(), handles.into(), count, None, profiler)
    }

    /// Records the insert round that follows [`GpuHashTable::record_search_claim`] (single
    /// lanes): of the items still [`HANDLE_MISS`], only the owner of each distinct item's
    /// claim-table copy is inserted; the others get [`HANDLE_INVALID`] and `reps[i]` = the
    /// owner's index (whose handle is theirs). Items found by the search keep `reps[i] = i`.
    /// [`GpuHashTable::finish_insert`] completes it like any round (its further rounds, for
    /// owners a full pool left out, need no claims).
    pub fn record_claimed_insert_round<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: impl Into<BufferSlice<'a>>,
        handles: impl Into<BufferSlice<'a>>,
        count: u32,
        claims: Claims<'a>,
        profiler: Option<&mut Profiler>,
    ) -> Result<PendingInsert, HashError> {
        self.record_round(
            cmd,
            items.into(),
            handles.into(),
            count,
            Some(claims),
            profiler,
        )
    }

    fn record_round<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: BufferSlice<'a>,
        handles: BufferSlice<'a>,
        count: u32,
        claims: Option<Claims<'a>>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<PendingInsert, HashError> {
        let push = self.insert_push(items, handles, count, claims)?;
        let before = self.record_status(cmd)?;
        let groups = self.cooperative_groups(count);
        self.record(
            cmd,
            &mut profiler,
            "hash insert",
            &self.insert,
            groups,
            &push,
        )?;
        cmd.barrier();
        let after = self.record_status(cmd)?;
        Ok(PendingInsert { before, after })
    }

    /// The push constants of a batch of `count` items and handles (both checked), naming
    /// `claims` (checked: single lanes, sized for the batch) when given.
    fn batch_push(
        &self,
        items: BufferSlice<'_>,
        handles: BufferSlice<'_>,
        count: u32,
        claims: Option<Claims<'_>>,
    ) -> Result<HashPush, HashError> {
        Self::check_count(items, count, self.config.item_words, "items")?;
        Self::check_count(handles, count, 1, "handles")?;
        let mut push = self.push_constants(items.address(), handles.address(), count);
        if let Some(claims) = claims {
            self.check_claims(claims, count)?;
            claims.fill_push(&mut push);
        }
        Ok(push)
    }

    /// The push constants of an insert round ([`GpuHashTable::batch_push`]; with `claims` a
    /// claimed round) with a fresh seed for its random block choice.
    fn insert_push(
        &self,
        items: BufferSlice<'_>,
        handles: BufferSlice<'_>,
        count: u32,
        claims: Option<Claims<'_>>,
    ) -> Result<HashPush, HashError> {
        let mut push = self.batch_push(items, handles, count, claims)?;
        if claims.is_some() {
            push.flags |= FLAG_CLAIMS;
        }
        push.seed = self.next_seed();
        Ok(push)
    }

    /// A fresh seed for an insert pass's random block choice.
    fn next_seed(&self) -> u32 {
        let seed = super::layout::fmix32(
            self.pass_seed
                .load(Ordering::Relaxed)
                .wrapping_add(0x9e37_79b9),
        );
        self.pass_seed.store(seed, Ordering::Relaxed);
        seed
    }

    /// This table's entry in a mixed batch ([`super::mixed`]): the claim passes' parameters
    /// for its items and handles (at most `bound`), its claims, and a fresh insert seed.
    pub fn claimed_entry<'a>(
        &self,
        items: impl Into<BufferSlice<'a>>,
        handles: impl Into<BufferSlice<'a>>,
        bound: u32,
        claims: Claims<'_>,
    ) -> Result<HashPush, HashError> {
        let mut push = self.insert_push(items.into(), handles.into(), bound, Some(claims))?;
        push.item_words = self.config.item_words;
        Ok(push)
    }

    /// Checks the status block read before and after a submission's inserts (a mixed
    /// batch's, [`super::mixed`]): pass errors, items left out for lack of a slab, items
    /// rejected; keeps `after` as the table's status.
    pub fn check_inserts(
        &mut self,
        before: &HashStatus,
        after: HashStatus,
    ) -> Result<InsertCheck, HashError> {
        Self::status_ok(&after, self.subgroup)?;
        let check = InsertCheck {
            left_out: after.exhausted.wrapping_sub(before.exhausted),
            invalid: after.invalid_items.wrapping_sub(before.invalid_items),
        };
        self.status = after;
        Ok(check)
    }

    /// Checks the claim passes' arguments: single lanes, a claim table sized for the batch,
    /// `reps`.
    fn check_claims(&self, claims: Claims<'_>, count: u32) -> Result<(), HashError> {
        if self.claim.is_none() {
            return Err(HashError::InvalidArgument(
                "claim passes need a single-lane table (TeamMode::SingleLane)".into(),
            ));
        }
        claims.table.check_batch(count, self.config.item_words)?;
        Self::check_count(claims.reps, count, 1, "reps")
    }

    /// Records the search-and-claim pass (single lanes; profiled as "hash search and claim"):
    /// `handles[i]` = handle of `items[i]` or [`HANDLE_MISS`], `reps[i] = i`, and every
    /// missing item gets a copy in `claims` (cleared first, here). Follow it with
    /// [`GpuHashTable::record_claimed_insert_round`] on the same buffers.
    pub fn record_search_claim<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: impl Into<BufferSlice<'a>>,
        handles: impl Into<BufferSlice<'a>>,
        count: u32,
        claims: Claims<'a>,
        profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        self.record_search_pass(
            cmd,
            items.into(),
            handles.into(),
            count,
            Some(claims),
            profiler,
        )
    }

    /// Records an insert (`search_first == false`: the items are known to be absent; the
    /// handles are first filled with [`HANDLE_MISS`]) or a find-or-insert (`search_first`: a
    /// search pass, then an insert round over the misses) into `cmd`. Call
    /// [`GpuHashTable::reserve`]`(count)` before (it may grow the pool); after the submission,
    /// [`GpuHashTable::finish_insert`] reads the status and re-runs the round for items a full
    /// pool left out (rare with the reservation).
    pub fn record_insert<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        items: &'a Buffer,
        handles: &'a Buffer,
        count: u32,
        search_first: bool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<PendingInsert, HashError> {
        Self::check_count(handles.into(), count, 1, "handles")?;
        if search_first {
            self.record_search(cmd, items, handles, count, profiler.as_deref_mut())?;
        } else {
            cmd.fill_buffer(handles, HANDLE_MISS);
        }
        self.record_insert_round(cmd, items, handles, count, profiler)
    }

    /// Completes a recorded insert once its submission was made: reads the status before and
    /// after its round (waiting for the GPU if needed), reports pass errors, and while items
    /// were left out for lack of a slab grows the pool and runs another round (its own
    /// submission) for them, up to `max_insert_rounds`.
    pub fn finish_insert<'a>(
        &mut self,
        pending: PendingInsert,
        items: impl Into<BufferSlice<'a>>,
        handles: impl Into<BufferSlice<'a>>,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<InsertReport, HashError> {
        let PendingInsert { before, after } = pending;
        let (items, handles) = (items.into(), handles.into());
        let first = before.read()?[0];
        let mut first_after = Some(after);
        let mut report = InsertReport::default();
        loop {
            report.rounds += 1;
            let (last, after) = match first_after.take() {
                Some(after) => (first, after),
                None => {
                    let mut cmd = self.ctx.begin_commands("hash insert round")?;
                    let p = self.record_insert_round(
                        &mut cmd,
                        items,
                        handles,
                        count,
                        profiler.as_deref_mut(),
                    )?;
                    cmd.submit_async()?;
                    (p.before.read()?[0], p.after)
                }
            };
            self.status = after.read()?[0];
            Self::status_ok(&self.status, self.subgroup)?;
            let left = self.status.exhausted.wrapping_sub(last.exhausted);
            if left == 0 {
                break;
            }
            report.retried_items += left;
            let room = self
                .config
                .max_super_blocks
                .saturating_sub(self.pool.super_block_count());
            if report.rounds >= self.config.max_insert_rounds || room == 0 {
                return Err(HashError::Exhausted {
                    items: left,
                    super_blocks: self.pool.super_block_count(),
                });
            }
            // Grow for the left-over items, at least one super block.
            let slabs = self.status.allocated_slabs as u64
                + left as u64 / SLAB_SLOTS as u64
                + left.min(self.config.buckets) as u64;
            self.grow_for(slabs, true)?;
        }
        report.invalid_items = self.status.invalid_items.wrapping_sub(first.invalid_items);
        report.super_blocks = self.pool.super_block_count();
        Ok(report)
    }

    /// Search pass: `handles[i]` = handle of `items[i]` or [`HANDLE_MISS`] (profiled as
    /// "hash search"). One submission, one host wait (for the status check).
    pub fn search_buffers(
        &self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        if count == 0 {
            return Ok(());
        }
        let mut cmd = self.ctx.begin_commands("hash search")?;
        self.record_search(&mut cmd, items, handles, count, profiler.as_deref_mut())?;
        let status = self.record_status(&mut cmd)?;
        cmd.submit_async()?;
        let status = status.read()?[0];
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Self::status_ok(&status, self.subgroup)
    }

    /// Insert of items known to be absent: fills `handles` with [`HANDLE_MISS`] and runs insert
    /// rounds (profiled as "hash insert"). Duplicates inside the batch each get their own slot.
    /// One submission and one host wait unless the pool runs out.
    pub fn insert_buffers(
        &mut self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<InsertReport, HashError> {
        self.insert_flow(items, handles, count, None, false, profiler)
            .map(|r| r.0)
    }

    /// Find-or-insert: a search pass, then insert rounds for the misses. Every item ends with a
    /// handle; an item present twice in the batch but absent from the table is inserted twice
    /// (each copy its own slot): deduplicate the batch first when that matters. One submission
    /// and one host wait unless the pool runs out.
    pub fn find_or_insert_buffers(
        &mut self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<InsertReport, HashError> {
        self.insert_flow(items, handles, count, None, true, profiler)
            .map(|r| r.0)
    }

    /// Reserve, record (optionally the items' upload first and the handles' readback last),
    /// submit, finish. Returns the report and the handles when `upload` was given.
    fn insert_flow(
        &mut self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        upload: Option<&[u32]>,
        search_first: bool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(InsertReport, Option<Vec<u32>>), HashError> {
        if count == 0 {
            return Ok((self.empty_report(), upload.map(|_| Vec::new())));
        }
        Self::check_count(items.into(), count, self.config.item_words, "items")?;
        Self::check_count(handles.into(), count, 1, "handles")?;
        if self.config.grow_before_insert {
            // Every item may be new (find-or-insert cannot tell without a readback).
            self.reserve(count)?;
        }
        let name = if search_first {
            "hash find-or-insert"
        } else {
            "hash insert"
        };
        let (pending, handles_back) = {
            let mut cmd = self.ctx.begin_commands(name)?;
            if let Some(data) = upload {
                cmd.upload(items, 0, data)?;
            }
            let pending = self.record_insert(
                &mut cmd,
                items,
                handles,
                count,
                search_first,
                profiler.as_deref_mut(),
            )?;
            let back = match upload {
                Some(_) => Some(cmd.readback::<u32>(handles, 0, count as usize)?),
                None => None,
            };
            cmd.submit_async()?;
            (pending, back)
        };
        let report = self.finish_insert(pending, items, handles, count, profiler.as_deref_mut())?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        let out = match handles_back {
            // Later rounds changed handles after the readback: read them again.
            Some(_) if report.rounds > 1 => {
                Some(self.ctx.read_buffer(handles, 0, count as usize)?)
            }
            Some(back) => Some(back.read()?),
            None => None,
        };
        Ok((report, out))
    }

    fn empty_report(&self) -> InsertReport {
        InsertReport {
            super_blocks: self.pool.super_block_count(),
            ..InsertReport::default()
        }
    }

    /// Grows the pool so `new_items` more items fit at the worst case: each bucket they touch
    /// may need one new slab beyond `items / 32`, with the pool kept at most 7/8 full. Stops at
    /// `max_super_blocks` (the insert rounds then report what still does not fit).
    pub fn reserve(&mut self, new_items: u32) -> Result<(), HashError> {
        let new_slabs =
            new_items as u64 / SLAB_SLOTS as u64 + new_items.min(self.config.buckets) as u64 + 1;
        self.grow_for(self.status.allocated_slabs as u64 + new_slabs, false)
    }

    /// Grows the pool for `new_items` more items in the expected case rather than the worst
    /// ([`GpuHashTable::reserve`]): an item needs a slab of its own where its bucket is empty
    /// (at least 1 - allocated slabs / buckets of them; each empty bucket once) and 1/32 of one
    /// elsewhere (chain ends fill up); twice that, the pool kept at most 7/8 full. Inserts
    /// report what did not fit.
    pub fn reserve_expected(&mut self, new_items: u32) -> Result<(), HashError> {
        let allocated = self.status.allocated_slabs as f64;
        let buckets = self.config.buckets as f64;
        let empty_buckets = buckets - allocated.min(buckets);
        let items = new_items as f64;
        let heads = (items * empty_buckets / buckets).min(empty_buckets);
        let new_slabs = (2.0 * (heads + items / SLAB_SLOTS as f64)).ceil() as u64 + 1;
        self.grow_for(self.status.allocated_slabs as u64 + new_slabs, false)
    }

    /// Adds super blocks until `slabs` fill at most 7/8 of the pool (at least one when `force`).
    fn grow_for(&mut self, slabs: u64, force: bool) -> Result<(), HashError> {
        let want = slabs * 8 / 7;
        let more = want
            .saturating_sub(self.pool.capacity_slabs())
            .div_ceil(SLABS_PER_SUPER_BLOCK as u64)
            .max(force as u64);
        let room = self
            .config
            .max_super_blocks
            .saturating_sub(self.pool.super_block_count()) as u64;
        if more.min(room) > 0 {
            self.pool.grow(more.min(room) as u32)?;
        }
        Ok(())
    }

    /// The errors a pass leaves in the status block: a subgroup size other than the one the
    /// pipelines were specialised for, or chain walks cut off (a corrupt table).
    fn status_ok(status: &HashStatus, expected: u32) -> Result<(), HashError> {
        if status.subgroup_mismatch != 0 {
            return Err(HashError::SubgroupMismatch {
                expected,
                actual: status.subgroup_mismatch,
            });
        }
        if status.broken_chains != 0 {
            return Err(HashError::CorruptTable {
                walks: status.broken_chains,
            });
        }
        Ok(())
    }

    /// Records a read pass into `cmd`: `out[i * item_words ..]` = the item of `handles[i]`
    /// (zeros for [`HANDLE_MISS`], [`HANDLE_INVALID`] and handles beyond the pool). Profiled as
    /// "hash read".
    pub fn record_read_items<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        handles: &'a Buffer,
        out: &'a Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        if count == 0 {
            return Ok(());
        }
        Self::check_count(handles.into(), count, 1, "handles")?;
        Self::check_count(out.into(), count, self.config.item_words, "output")?;
        let push = self.push_constants(out.address(), handles.address(), count);
        let groups = count
            .div_ceil(self.workgroup)
            .clamp(1, self.ctx.info().max_compute_workgroup_count[0]);
        self.record(cmd, &mut profiler, "hash read", &self.read, groups, &push)?;
        cmd.barrier();
        Ok(())
    }

    /// Read pass ([`GpuHashTable::record_read_items`]) in its own submission, waited for.
    pub fn read_items_buffers(
        &self,
        handles: &Buffer,
        out: &Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        if count == 0 {
            return Ok(());
        }
        let mut cmd = self.ctx.begin_commands("hash read")?;
        self.record_read_items(&mut cmd, handles, out, count, profiler.as_deref_mut())?;
        cmd.submit()?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Ok(())
    }

    /// Checks a host batch (`item_words` words per item; Atomic64 rejects zero prefixes) and
    /// returns its item count.
    pub fn validate_items(&self, items: &[u32]) -> Result<u32, HashError> {
        let w = self.config.item_words as usize;
        if !items.len().is_multiple_of(w) {
            return Err(HashError::InvalidArgument(format!(
                "{} words are not a whole number of {w}-word items",
                items.len()
            )));
        }
        let count = u32::try_from(items.len() / w).map_err(|_| {
            HashError::InvalidArgument(format!("{} items exceed 2^32", items.len() / w))
        })?;
        if let Some(index) = items.chunks(w).position(|it| !self.layout.accepts(it)) {
            return Err(HashError::InvalidItem {
                index,
                variant: self.config.variant.name(),
                reason: "the first two words (the only word of a 1-word item) are zero, which marks an empty slot",
            });
        }
        Ok(count)
    }

    /// Buffers for a host batch: items (not uploaded yet) and handles.
    fn batch_buffers(&self, count: u32) -> Result<(Buffer, Buffer), HashError> {
        let items = self.ctx.create_buffer(
            "hash items",
            4 * count as u64 * self.config.item_words as u64,
            MemLocation::GpuOnly,
        )?;
        let handles =
            self.ctx
                .create_buffer("hash handles", 4 * count as u64, MemLocation::GpuOnly)?;
        Ok((items, handles))
    }

    /// Searches host items (`item_words` words each); `None` = absent. Upload, search, status
    /// and handles readback in one submission, one host wait.
    pub fn search(
        &self,
        items: &[u32],
        mut profiler: Option<&mut Profiler>,
    ) -> Result<Vec<Option<Handle>>, HashError> {
        if items.is_empty() {
            return Ok(Vec::new());
        }
        let count = self.validate_items(items)?;
        let (item_buf, handles) = self.batch_buffers(count)?;
        let mut cmd = self.ctx.begin_commands("hash search")?;
        cmd.upload(&item_buf, 0, items)?;
        self.record_search(
            &mut cmd,
            &item_buf,
            &handles,
            count,
            profiler.as_deref_mut(),
        )?;
        let status = self.record_status(&mut cmd)?;
        let back = cmd.readback::<u32>(&handles, 0, count as usize)?;
        cmd.submit_async()?;
        let status = status.read()?[0];
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Self::status_ok(&status, self.subgroup)?;
        Ok(back.read()?.into_iter().map(Handle::from_raw).collect())
    }

    /// Inserts host items known to be absent; returns their handles.
    pub fn insert(
        &mut self,
        items: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<Handle>, InsertReport), HashError> {
        self.insert_host(items, profiler, false)
    }

    /// Finds or inserts host items; returns their handles. Upload, search, insert and handles
    /// readback in one submission, one host wait (unless the pool runs out).
    pub fn find_or_insert(
        &mut self,
        items: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<Handle>, InsertReport), HashError> {
        self.insert_host(items, profiler, true)
    }

    /// Finds or inserts host items, each distinct item stored once however often the batch
    /// holds it (single lanes: the claim passes of `claim.rs`); returns every item's handle.
    /// Upload, search-and-claim, insert and the readbacks in one submission, one host wait
    /// (unless the pool runs out).
    pub fn find_or_insert_distinct(
        &mut self,
        items: &[u32],
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<Handle>, InsertReport), HashError> {
        if items.is_empty() {
            return Ok((Vec::new(), self.empty_report()));
        }
        let count = self.validate_items(items)?;
        let (item_buf, handles) = self.batch_buffers(count)?;
        let reps = self
            .ctx
            .create_buffer("hash reps", 4 * count as u64, MemLocation::GpuOnly)?;
        let table = ClaimTable::new(&self.ctx, self.config.item_words, count)?;
        let claims = Claims {
            table: &table,
            reps: (&reps).into(),
        };
        if self.config.grow_before_insert {
            self.reserve(count)?;
        }
        let mut cmd = self.ctx.begin_commands("hash find-or-insert distinct")?;
        cmd.upload(&item_buf, 0, items)?;
        self.record_search_claim(
            &mut cmd,
            &item_buf,
            &handles,
            count,
            claims,
            profiler.as_deref_mut(),
        )?;
        let pending = self.record_claimed_insert_round(
            &mut cmd,
            &item_buf,
            &handles,
            count,
            claims,
            profiler.as_deref_mut(),
        )?;
        let reps_back = cmd.readback::<u32>(&reps, 0, count as usize)?;
        let handles_back = cmd.readback::<u32>(&handles, 0, count as usize)?;
        cmd.submit_async()?;
        let report =
            self.finish_insert(pending, &item_buf, &handles, count, profiler.as_deref_mut())?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        // Further rounds (a full pool) changed owners' handles after the readback: read again.
        let raw = if report.rounds > 1 {
            self.ctx.read_buffer::<u32>(&handles, 0, count as usize)?
        } else {
            handles_back.read()?
        };
        let reps = reps_back.read()?;
        let handle_of = |i: usize| {
            let rep = reps[i] as usize;
            let h = if raw[i] == HANDLE_INVALID && rep < raw.len() && rep != i {
                raw[rep]
            } else {
                raw[i]
            };
            Handle::from_raw(h).ok_or_else(|| {
                HashError::InvalidArgument(format!("item {i} has no handle after insert"))
            })
        };
        let handles = (0..count as usize)
            .map(handle_of)
            .collect::<Result<Vec<_>, _>>()?;
        Ok((handles, report))
    }

    fn insert_host(
        &mut self,
        items: &[u32],
        profiler: Option<&mut Profiler>,
        search_first: bool,
    ) -> Result<(Vec<Handle>, InsertReport), HashError> {
        if items.is_empty() {
            return Ok((Vec::new(), self.empty_report()));
        }
        let count = self.validate_items(items)?;
        let (item_buf, handles) = self.batch_buffers(count)?;
        let (report, raw) = self.insert_flow(
            &item_buf,
            &handles,
            count,
            Some(items),
            search_first,
            profiler,
        )?;
        let handles = raw
            .unwrap_or_default()
            .into_iter()
            .enumerate()
            .map(|(i, h)| {
                Handle::from_raw(h).ok_or_else(|| {
                    HashError::InvalidArgument(format!(
                        "item {i} has no handle after insert ({})",
                        if h == HANDLE_INVALID {
                            "invalid"
                        } else {
                            "missing"
                        }
                    ))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((handles, report))
    }

    /// Dereferences handles on the GPU; returns `item_words` words per handle (one submission,
    /// one host wait).
    pub fn read_items(&self, handles: &[Handle]) -> Result<Vec<u32>, HashError> {
        if handles.is_empty() {
            return Ok(Vec::new());
        }
        let count = u32::try_from(handles.len())
            .map_err(|_| HashError::InvalidArgument("more than 2^32 handles".into()))?;
        let raw: Vec<u32> = handles.iter().map(|h| h.0).collect();
        let handle_buf =
            self.ctx
                .create_buffer("hash read handles", 4 * count as u64, MemLocation::GpuOnly)?;
        let words = count as usize * self.config.item_words as usize;
        let out =
            self.ctx
                .create_buffer("hash read items", 4 * words as u64, MemLocation::GpuOnly)?;
        let mut cmd = self.ctx.begin_commands("hash read")?;
        cmd.upload(&handle_buf, 0, &raw)?;
        self.record_read_items(&mut cmd, &handle_buf, &out, count, None)?;
        let back = cmd.readback::<u32>(&out, 0, words)?;
        cmd.submit_async()?;
        Ok(back.read()?)
    }

    /// Downloads the whole table (heads, every super block, status) for host-side checks.
    pub fn download(&self) -> Result<TableImage, HashError> {
        Ok(TableImage {
            layout: self.layout,
            heads: self.ctx.download(&self.heads)?,
            super_blocks: self.pool.download_super_blocks()?,
            status: self.pool.read_status()?,
        })
    }
}
