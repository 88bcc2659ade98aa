//! [`GpuHashTable`]: one slab hash table on the GPU and its batch passes.
//!
//! Passes (each one dispatch, `shaders/glsl/hash/*.comp`): `search` (items -> handles or
//! [`HANDLE_MISS`]), `insert` (places every item whose handle is still `HANDLE_MISS`), `read`
//! (handles -> items). `insert` of a batch = fill the handles with `HANDLE_MISS`, then insert
//! rounds; `find_or_insert` = search, then insert rounds over the misses (no compaction: items
//! already found are skipped by their handle). After each insert round the host reads the status
//! block; items left out for lack of a slab are counted there, the pool grows and the round
//! repeats for them only. Data stays on the GPU; the `&[u32]` helpers upload and read back.

use std::sync::Arc;

use super::alloc::SlabPool;
use super::layout::{
    Handle, HashPush, HashStatus, HashVariant, SlabLayout, HANDLE_INVALID, HANDLE_MISS,
    MAX_SUPER_BLOCKS, SLABS_PER_SUPER_BLOCK, SLAB_SLOTS,
};
use super::reference::TableImage;
use super::HashError;
use crate::gpu::{
    shaders, Buffer, Commands, ComputePipeline, ComputePipelineDesc, DeviceType, GpuContext,
    MemLocation, Profiler,
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
    search: ComputePipeline,
    insert: ComputePipeline,
    read: ComputePipeline,
    workgroup: u32,
    subgroup: u32,
    team: u32,
    /// Status read before and after each insert round (counters are cumulative).
    status: HashStatus,
    /// Seed of the next pass's random block choice.
    pass_seed: u32,
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
        if config.initial_super_blocks > MAX_SUPER_BLOCKS || config.max_insert_rounds == 0 {
            return Err(HashError::Config(format!(
                "initial super blocks must be <= {MAX_SUPER_BLOCKS} and insert rounds >= 1"
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
        let pipeline = |name: &str, spirv: &[u32]| {
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name,
                spirv,
                spec_constants: &spec,
                push_constant_size: std::mem::size_of::<HashPush>() as u32,
                storage_image: false,
            })
        };
        let search = pipeline("hash search", shaders::HASH_SEARCH)?;
        let insert = pipeline("hash insert", shaders::HASH_INSERT)?;
        let read = pipeline("hash read", shaders::HASH_READ)?;
        let heads = ctx.create_buffer(
            "hash bucket heads",
            4 * config.buckets as u64,
            MemLocation::GpuOnly,
        )?;
        let mut cmd = ctx.begin_commands("hash heads init")?;
        cmd.fill_buffer(&heads, 0);
        cmd.submit()?;
        let pool = SlabPool::new(ctx, layout, config.initial_super_blocks)?;
        Ok(GpuHashTable {
            ctx: Arc::clone(ctx),
            config: config.clone(),
            layout,
            pool,
            heads,
            search,
            insert,
            read,
            workgroup,
            subgroup,
            team,
            status: HashStatus::default(),
            pass_seed: 0x2545_f491,
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
            status: self.pool.status_address(),
            items,
            handles,
            count,
            buckets: self.config.buckets,
            blocks: self.pool.block_count(),
            seed: self.pass_seed,
        }
    }

    /// Device memory of the table (heads and pool), in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.heads.size() + self.pool.gpu_bytes()
    }

    /// Workgroups for `count` items at one item per team (grid-stride beyond the limit).
    fn cooperative_groups(&self, count: u32) -> u32 {
        let per_group = self.workgroup / self.team;
        count
            .div_ceil(per_group)
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
        match profiler.as_deref_mut() {
            Some(p) => p.begin_pass(cmd, name),
            None => cmd.begin_label(name),
        }
        cmd.dispatch(pipeline, [groups, 1, 1], bytemuck::bytes_of(push), None)?;
        match profiler.as_deref_mut() {
            Some(p) => p.end_pass(cmd),
            None => cmd.end_label(),
        }
        Ok(())
    }

    fn check_count(
        buffer: &Buffer,
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

    /// Search pass: `handles[i]` = handle of `items[i]` or [`HANDLE_MISS`] (profiled as
    /// "hash search"). `items` holds `count * item_words` words, `handles` `count` words.
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
        Self::check_count(items, count, self.config.item_words, "items")?;
        Self::check_count(handles, count, 1, "handles")?;
        let push = self.push_constants(items.address(), handles.address(), count);
        let mut cmd = self.ctx.begin_commands("hash search")?;
        let groups = self.cooperative_groups(count);
        self.record(
            &mut cmd,
            &mut profiler,
            "hash search",
            &self.search,
            groups,
            &push,
        )?;
        cmd.submit()?;
        if let Some(p) = profiler {
            p.resolve()?;
        }
        self.check_status()
    }

    /// Insert of items known to be absent: fills `handles` with [`HANDLE_MISS`] and runs insert
    /// rounds (profiled as "hash insert"). Duplicates inside the batch each get their own slot.
    pub fn insert_buffers(
        &mut self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        profiler: Option<&mut Profiler>,
    ) -> Result<InsertReport, HashError> {
        if count == 0 {
            return Ok(self.empty_report());
        }
        Self::check_count(handles, count, 1, "handles")?;
        let mut cmd = self.ctx.begin_commands("hash insert reset")?;
        cmd.fill_buffer(handles, HANDLE_MISS);
        cmd.submit()?;
        self.insert_rounds(items, handles, count, profiler)
    }

    /// Find-or-insert: a search pass, then insert rounds for the misses. Every item ends with a
    /// handle; an item present twice in the batch but absent from the table is inserted twice
    /// (each copy its own slot): deduplicate the batch first when that matters.
    pub fn find_or_insert_buffers(
        &mut self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<InsertReport, HashError> {
        if count == 0 {
            return Ok(self.empty_report());
        }
        self.search_buffers(items, handles, count, profiler.as_deref_mut())?;
        self.insert_rounds(items, handles, count, profiler)
    }

    fn empty_report(&self) -> InsertReport {
        InsertReport {
            super_blocks: self.pool.super_block_count(),
            ..InsertReport::default()
        }
    }

    /// Grows the pool so `new_items` more items fit at the worst case: each bucket they touch
    /// may need one new slab beyond `items / 32`, with the pool kept at most 7/8 full. Stops at
    /// [`MAX_SUPER_BLOCKS`] (the insert rounds then report what still does not fit).
    pub fn reserve(&mut self, new_items: u32) -> Result<(), HashError> {
        let new_slabs =
            new_items as u64 / SLAB_SLOTS as u64 + new_items.min(self.config.buckets) as u64 + 1;
        self.grow_for(self.status.allocated_slabs as u64 + new_slabs, false)
    }

    /// Adds super blocks until `slabs` fill at most 7/8 of the pool (at least one when `force`).
    fn grow_for(&mut self, slabs: u64, force: bool) -> Result<(), HashError> {
        let want = slabs * 8 / 7;
        let more = want
            .saturating_sub(self.pool.capacity_slabs())
            .div_ceil(SLABS_PER_SUPER_BLOCK as u64)
            .max(force as u64);
        let room = (MAX_SUPER_BLOCKS - self.pool.super_block_count()) as u64;
        if more.min(room) > 0 {
            self.pool.grow(more.min(room) as u32)?;
        }
        Ok(())
    }

    fn insert_rounds(
        &mut self,
        items: &Buffer,
        handles: &Buffer,
        count: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<InsertReport, HashError> {
        Self::check_count(items, count, self.config.item_words, "items")?;
        Self::check_count(handles, count, 1, "handles")?;
        // Fresh counters: other passes on this pool (garbage collection) change them.
        self.status = self.pool.read_status()?;
        if self.config.grow_before_insert {
            // Every item may be new (find-or-insert cannot tell without a readback).
            self.reserve(count)?;
        }
        let before = self.status;
        let mut report = InsertReport::default();
        loop {
            report.rounds += 1;
            self.pass_seed = super::layout::fmix32(self.pass_seed.wrapping_add(0x9e37_79b9));
            let push = self.push_constants(items.address(), handles.address(), count);
            let mut cmd = self.ctx.begin_commands("hash insert")?;
            let groups = self.cooperative_groups(count);
            self.record(
                &mut cmd,
                &mut profiler,
                "hash insert",
                &self.insert,
                groups,
                &push,
            )?;
            cmd.submit()?;
            if let Some(p) = profiler.as_deref_mut() {
                p.resolve()?;
            }
            let last = self.status;
            self.status = self.pool.read_status()?;
            Self::status_ok(&self.status, self.subgroup)?;
            let left = self.status.exhausted.wrapping_sub(last.exhausted);
            if left == 0 {
                break;
            }
            report.retried_items += left;
            let room = MAX_SUPER_BLOCKS - self.pool.super_block_count();
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
        report.invalid_items = self.status.invalid_items.wrapping_sub(before.invalid_items);
        report.super_blocks = self.pool.super_block_count();
        Ok(report)
    }

    fn check_status(&self) -> Result<(), HashError> {
        let status = self.pool.read_status()?;
        Self::status_ok(&status, self.subgroup)
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

    /// Read pass: `out[i * item_words ..]` = the item of `handles[i]` (zeros for
    /// [`HANDLE_MISS`], [`HANDLE_INVALID`] and handles beyond the pool). Profiled as "hash read".
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
        Self::check_count(handles, count, 1, "handles")?;
        Self::check_count(out, count, self.config.item_words, "output")?;
        let push = self.push_constants(out.address(), handles.address(), count);
        let groups = count
            .div_ceil(self.workgroup)
            .clamp(1, self.ctx.info().max_compute_workgroup_count[0]);
        let mut cmd = self.ctx.begin_commands("hash read")?;
        self.record(
            &mut cmd,
            &mut profiler,
            "hash read",
            &self.read,
            groups,
            &push,
        )?;
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
        if items.len() % w != 0 {
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

    fn upload_batch(&self, items: &[u32]) -> Result<(u32, Buffer, Buffer), HashError> {
        let count = self.validate_items(items)?;
        let items = self.ctx.upload("hash items", items)?;
        let handles =
            self.ctx
                .create_buffer("hash handles", 4 * count as u64, MemLocation::GpuOnly)?;
        Ok((count, items, handles))
    }

    /// Searches host items (`item_words` words each); `None` = absent.
    pub fn search(
        &self,
        items: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<Vec<Option<Handle>>, HashError> {
        if items.is_empty() {
            return Ok(Vec::new());
        }
        let (count, items, handles) = self.upload_batch(items)?;
        self.search_buffers(&items, &handles, count, profiler)?;
        let raw: Vec<u32> = self.ctx.download(&handles)?;
        Ok(raw.into_iter().map(Handle::from_raw).collect())
    }

    /// Inserts host items known to be absent; returns their handles.
    pub fn insert(
        &mut self,
        items: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<Handle>, InsertReport), HashError> {
        self.insert_host(items, profiler, false)
    }

    /// Finds or inserts host items; returns their handles.
    pub fn find_or_insert(
        &mut self,
        items: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<(Vec<Handle>, InsertReport), HashError> {
        self.insert_host(items, profiler, true)
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
        let (count, items, handles) = self.upload_batch(items)?;
        let report = if search_first {
            self.find_or_insert_buffers(&items, &handles, count, profiler)?
        } else {
            self.insert_buffers(&items, &handles, count, profiler)?
        };
        let raw: Vec<u32> = self.ctx.download(&handles)?;
        let handles = raw
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

    /// Dereferences handles on the GPU; returns `item_words` words per handle.
    pub fn read_items(&self, handles: &[Handle]) -> Result<Vec<u32>, HashError> {
        if handles.is_empty() {
            return Ok(Vec::new());
        }
        let count = u32::try_from(handles.len())
            .map_err(|_| HashError::InvalidArgument("more than 2^32 handles".into()))?;
        let raw: Vec<u32> = handles.iter().map(|h| h.0).collect();
        let handle_buf = self.ctx.upload("hash read handles", &raw)?;
        let out = self.ctx.create_buffer(
            "hash read items",
            4 * count as u64 * self.config.item_words as u64,
            MemLocation::GpuOnly,
        )?;
        self.read_items_buffers(&handle_buf, &out, count, None)?;
        Ok(self.ctx.download(&out)?)
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
