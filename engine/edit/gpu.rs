//! The hash DAG on the GPU (dissertation §4.3-4.4): every node of the scene in nine slab hash
//! tables (one per item size, `engine/edit/item.rs`), loading an `svdag32` DAG into them level by
//! level, reading them back, and the edit pipeline for sphere and cube add / remove.
//!
//! Both the load and the edit end in the same bottom-up *merge* of one level at a time
//! (`shaders/glsl/edit/`): `build_items` turns each temporary node or leaf into its canonical
//! form (uniform ones become empty / full child values, the others append their item to the
//! buffer of its size), then per size the batch's duplicates are found with the dedup table
//! ([`GpuDedup`]), a search pass finds items already stored, `mark` keeps one copy of each new
//! item, the insert round stores it, and `resolve` writes every node's pointer. Single-lane
//! tables (CPU devices) fold the duplicate detection into the search and insert passes instead
//! ([`crate::hash::claim`]: two passes per size, no dedup table, no `mark`); their edits record
//! every level's merge up front in one submission, the claim passes taking every size at once
//! ([`crate::hash::mixed`], `merge_recorded`) and each level's `build_items` resolving the
//! pending nodes of the level below, and wait once for it. The edit first
//! walks the tool's region top-down (`traverse`, then `leaves` with one invocation per voxel),
//! building the temporary SVO the merge consumes. See `docs/editing-gpu.md`.

mod build_items;
mod load;
mod small_levels;

use std::borrow::Cow;
use std::sync::{Arc, OnceLock};

use super::gpu_gc;
use super::gpu_shared::{EditPush, TraverseChainPush};
use super::item::{
    Child, ItemError, NodePtr, Root, MAX_ITEM_WORDS, MAX_TABLE_SLABS, MIN_ITEM_WORDS, TABLE_COUNT,
};
use super::tool::{self, CopyRegion, Shape, Tool};
use super::walk::{self, StoredDag};
use crate::dag::{DagError, Svdag};
use crate::gpu::{
    made_once, shaders, BindingKind, Buffer, BufferSlice, Commands, ComputePipeline,
    ComputePipelineDesc, GpuContext, GpuError, MemLocation, Profiler, Readback,
};
use crate::hash::claim::{ClaimTable, Claims};
use crate::hash::dedup::{DedupError, DedupResult, GpuDedup};
use crate::hash::layout::{HashPush, SLABS_PER_SUPER_BLOCK};
use crate::hash::mixed::{MixedPasses, MIXED_SIZES};
use crate::hash::{
    GpuHashTable, Handle, HashError, HashStatus, HashTableConfig, HashVariant, PendingInsert,
    TableImage, TeamMode,
};
use crate::scene::Voxels;
use build_items::{BuildItemsPipelines, LevelTexels};
use small_levels::{ChainRecords, SmallLevel, SmallLevelsPass};

/// Child value: empty cube (GLSL `EDIT_EMPTY`).
const VALUE_EMPTY: u32 = 0xFFFF_FFFF;
/// Child value tag: full cube, `| material` (GLSL `EDIT_FULL`).
const VALUE_FULL: u32 = 0xF000_0000;
/// Tag of a value naming an entry of the level below (GLSL `EDIT_TEMP`).
const VALUE_TEMP: u32 = 0x9000_0000;
/// Pass flags (GLSL `EDIT_FLAG_*`).
const FLAG_LEAVES: u32 = 1;
const FLAG_RESULT_INDEX: u32 = 8;
/// `EDIT_TOOL_FROM_FLAGS`: specialization constant 0 of the passes that read the tool from the
/// flags.
const TOOL_FROM_FLAGS: u32 = 7;
/// Shift of the tool kind in the flags of traverse / leaves / fill passes (GLSL
/// `EDIT_TOOL_SHIFT`).
const TOOL_SHIFT: u32 = 4;
/// Words of the tool parameter buffer (GLSL `EDIT_P_*`).
const TOOL_PARAMS: usize = 28;
/// Flood passes (one per axis) recorded per host wait of the fill.
const FLOOD_ROUNDS_PER_WAIT: u32 = 2;
/// Words of the per-level address buffer (GLSL `EDIT_LEVEL_*`): 9 items, slots, reps,
/// handles, their stride per size, the level below's address buffer (0: resolved by its own
/// pass), the missing handle counter.
const LEVEL_ADDRESSES: usize = 15;
/// `EDIT_LEVEL_SLOTS`: the node's index among the items of its size.
const LEVEL_SLOTS: usize = 9;
/// `EDIT_LEVEL_REPS`: every size's dedup representatives.
const LEVEL_REPS: usize = 10;
/// `EDIT_LEVEL_HANDLES`: every size's handles.
const LEVEL_HANDLES: usize = 11;
/// `EDIT_LEVEL_STRIDE`: words between two sizes' representatives (and handles).
const LEVEL_STRIDE: usize = 12;
/// `EDIT_LEVEL_BELOW`: where build_items finds the level below's pending results.
const LEVEL_BELOW: usize = 13;
/// `EDIT_LEVEL_MISSING`: the counter of nodes left without a handle (`merge_errors`).
const LEVEL_MISSING: usize = 14;
/// Counters of a merge: one item count per size.
const COUNTERS: usize = TABLE_COUNT as usize;
/// Invocations per workgroup of every edit pass.
const GROUP: u32 = 64;
/// Largest batch whose slab-table dedup gets a pool that cannot run out (2 x count slabs), so
/// that its dedup, search, mark and insert share one submission (`merge_items`).
const FUSED_DEDUP_MAX: u32 = 1024;

/// Default [`GpuHashDagConfig::traversal_budget`].
const TRAVERSAL_BUDGET: u64 = 64 << 20;

/// The temporary SVO of a traversal: nodes / leaves per level, entries per level.
type Traversal = (Vec<Option<Buffer>>, Vec<u32>);

/// Errors of the GPU hash DAG.
#[derive(Debug, thiserror::Error)]
pub enum GpuDagError {
    /// The GPU layer failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// A hash table failed (pool exhausted, corrupt table, ...).
    #[error(transparent)]
    Hash(#[from] HashError),
    /// The dedup table failed.
    #[error(transparent)]
    Dedup(#[from] DedupError),
    /// The SVDAG to load or to build is invalid.
    #[error(transparent)]
    Dag(#[from] DagError),
    /// A configuration or argument the hash DAG cannot take.
    #[error("invalid hash DAG argument: {0}")]
    Invalid(String),
    /// The tables hold something that is not a canonical hash DAG (a bug, reported).
    #[error("corrupt hash DAG: {0}")]
    Corrupt(String),
}

impl From<ItemError> for GpuDagError {
    fn from(e: ItemError) -> GpuDagError {
        GpuDagError::Corrupt(e.to_string())
    }
}

/// How the nine tables are built.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuHashDagConfig {
    /// Slab layout of every table (chosen at run time).
    pub variant: HashVariant,
    /// Buckets of each table (fixed for its life: a handle names its slab).
    pub buckets: Buckets,
    /// Super blocks per table at creation.
    pub initial_super_blocks: u32,
    /// Most super blocks per table (at most [`max_super_blocks`], which keeps handles in 28 bits).
    pub max_super_blocks: u32,
    /// Grow each table before an insert from a conservative estimate (false: only after a round
    /// ran out; tests force exhaustion that way).
    pub grow_before_insert: bool,
    /// Insert rounds (pass + grow) before an insert fails.
    pub max_insert_rounds: u32,
    /// Undo steps an edit keeps (older roots are dropped; GC frees what only they reached).
    pub undo_depth: usize,
    /// Collect garbage before an edit once a table's allocated slabs pass this fraction of its
    /// largest pool (`max_super_blocks`), and after an edit that ran a pool out (which then
    /// runs once more); `None`: only on request. See `edit::gpu_gc`.
    pub auto_gc_threshold: Option<f32>,
    /// Bytes of traversal buffers, sized by the tool's bounds, that one submission may hold
    /// (`GpuHashDag::traverse`); beyond, the count of the last level is read back first.
    /// 0: one level per submission with exact capacities (the path a wrong bound falls back to).
    pub traversal_budget: u64,
    /// Lanes per item of the table passes. The default is single lanes on every device: their
    /// merge (the tables' claim passes, the small levels chained in one dispatch) took 3 submits
    /// and 25 passes per edit on bunny 8192^3 against 18 and 250 for subgroup teams (the dedup
    /// table and `mark`), and edited 1.7-4.5x faster on an H200, as it already did on lavapipe
    /// (docs/editing-gpu.md, "Single lanes on GPUs too"). `Auto` keeps the tables' own choice
    /// (subgroups on GPUs).
    pub team: TeamMode,
    /// `build_items` reads the level below and its input through word views (texel fetches,
    /// which lavapipe gathers for all SIMD lanes) where every buffer fits in one
    /// (`maxTexelBufferElements` words), else through addresses; false: always through
    /// addresses (tests compare both).
    pub word_views: bool,
}

/// How many buckets each of the nine tables gets. Slabs (32 slots) are allocated per non-empty
/// bucket, so buckets set how full the slabs are: too many leave slabs nearly empty (memory,
/// zero-fills, GC sweeps), too few make long chains for the claims and inserts to walk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Buckets {
    /// This many in every table.
    Fixed(u32),
    /// Each table sized by the items the load puts in it ([`table_buckets`]); an empty scene's
    /// tables get the minimum.
    FromLoad,
}

/// Items per bucket a table is sized for at load ([`Buckets::FromLoad`]).
pub const LOAD_ITEMS_PER_BUCKET: u64 = 8;
/// Every table gets at least the buckets of this share of the loaded items, room for the item
/// sizes a scene has few of at load but edits make many of (solid edits: 8-child nodes).
pub const LOAD_GROWTH_SHARE: u64 = 16;
/// Fewest and most buckets of a table sized at load.
pub const LOAD_BUCKETS: std::ops::RangeInclusive<u32> = 1024..=1 << 22;

/// Buckets per table for `loaded` items per table (index = item words - 2): one per
/// [`LOAD_ITEMS_PER_BUCKET`] of the table's items or of `1 / LOAD_GROWTH_SHARE` of all items,
/// whichever is more, a power of two in [`LOAD_BUCKETS`] (docs/editing-gpu.md, "Buckets per
/// table").
pub fn table_buckets(loaded: &[u64; TABLE_COUNT as usize]) -> [u32; TABLE_COUNT as usize] {
    let total: u64 = loaded.iter().sum();
    loaded.map(|items| {
        let items = items.max(total / LOAD_GROWTH_SHARE);
        let buckets = items.div_ceil(LOAD_ITEMS_PER_BUCKET).next_power_of_two();
        buckets.clamp(*LOAD_BUCKETS.start() as u64, *LOAD_BUCKETS.end() as u64) as u32
    })
}

/// Super blocks that keep every handle below 2^28 ([`MAX_TABLE_SLABS`] slabs).
pub fn max_super_blocks() -> u32 {
    MAX_TABLE_SLABS / SLABS_PER_SUPER_BLOCK
}

impl GpuHashDagConfig {
    /// Tables of `variant` with `buckets` buckets each, one initial super block, growth before
    /// inserts, 8 insert rounds, the default undo depth and auto-GC threshold (`edit::gpu_gc`).
    pub fn new(variant: HashVariant, buckets: u32) -> GpuHashDagConfig {
        GpuHashDagConfig::with_buckets(variant, Buckets::Fixed(buckets))
    }

    /// As [`GpuHashDagConfig::new`], each table's buckets sized by what the load puts in it.
    pub fn sized_by_load(variant: HashVariant) -> GpuHashDagConfig {
        GpuHashDagConfig::with_buckets(variant, Buckets::FromLoad)
    }

    fn with_buckets(variant: HashVariant, buckets: Buckets) -> GpuHashDagConfig {
        GpuHashDagConfig {
            variant,
            buckets,
            initial_super_blocks: 1,
            max_super_blocks: max_super_blocks(),
            grow_before_insert: true,
            max_insert_rounds: 8,
            undo_depth: gpu_gc::DEFAULT_UNDO_DEPTH,
            auto_gc_threshold: Some(gpu_gc::DEFAULT_AUTO_GC_THRESHOLD),
            traversal_budget: TRAVERSAL_BUDGET,
            team: TeamMode::SingleLane,
            word_views: true,
        }
    }
}

/// What an edit did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EditReport {
    /// Temporary SVO entries per level (index = level), the traversal's work.
    pub temporary_nodes: Vec<u32>,
    /// Items built per level before deduplication (non-uniform temporary nodes).
    pub items: Vec<u32>,
    /// Insert rounds beyond the first (pool growth during the edit).
    pub retried_rounds: u32,
}

/// The scene as nine per-size slab hash tables on the GPU, with its history of roots.
pub struct GpuHashDag {
    pub(super) ctx: Arc<GpuContext>,
    pub(super) config: GpuHashDagConfig,
    pub(super) tables: Vec<GpuHashTable>,
    /// Per size the dedup table of the subgroup path; empty with single lanes (whose tables
    /// fold the dedup into their passes: `merge_items_claimed`).
    dedups: Vec<GpuDedup>,
    /// The claim passes over items of every size (single lanes: `merge_recorded`).
    mixed: Option<MixedPasses>,
    /// The merge of an edit's small top levels in one dispatch (with `mixed`).
    small_levels: Option<SmallLevelsPass>,
    /// Per level from the leaves up, each item size's share of the items of the last recorded
    /// merges (`observe_size_shares`): a floor for the next merge's pool reservations.
    size_shares: Vec<[f64; COUNTERS]>,
    /// The tables' super-block table addresses (`u64` each), read by the passes.
    pub(super) table_addresses: Buffer,
    expand: ComputePipeline,
    build_items: BuildItemsPipelines,
    mark: ComputePipeline,
    resolve: ComputePipeline,
    traverse: ToolPipelines,
    /// The traversal's small top levels in one dispatch (`traverse_small_levels`).
    traverse_chain: ToolPipelines,
    /// Records bound to the chains' warm-ups (the same native variant as real ones).
    records_stand_in: ChainRecords,
    leaves: ToolPipelines,
    fill_init: ComputePipeline,
    fill_flood: ComputePipeline,
    /// `0..n` for the dedup values, kept between merges (grown by powers of two).
    iota: Option<Buffer>,
    /// Nodes the merges' `resolve` left without a handle (one counter, checked by
    /// `read_root`).
    merge_errors: Buffer,
    pub(super) root_level: u32,
    with_materials: bool,
    /// RGBA8 sRGB palette of a material scene (`load_materials`); empty without materials.
    palette: Vec<u32>,
    pub(super) roots: Vec<Root>,
    /// Index of the current root in `roots` (undo moves it back, redo forward).
    pub(super) current: usize,
    /// GC pipelines and the log of automatic collections (`edit::gpu_gc`).
    pub(super) gc_state: gpu_gc::GcState,
}

/// One level of a bottom-up merge: where its nodes are and where their results go.
struct MergeLevel<'b> {
    /// Temporary nodes (8 values) or leaves (2 words, 10 with materials).
    input: BufferSlice<'b>,
    count: u32,
    leaves: bool,
    /// Results of the level below (none for leaves).
    below: Option<&'b Buffer>,
    /// Where results go.
    results: &'b Buffer,
    /// Result index per node (load: the node's svdag word offset).
    result_index: Option<&'b Buffer>,
}

/// The buffers of one level's merge (`GpuHashDag::merge_buffers`): per size its items, their
/// dedup representatives and their handles, each kind in one buffer (a level makes three
/// buffers, not 27).
struct MergeBuffers {
    /// Every size's items, size `s` from byte `item_offsets[s]` (`item_caps[s]` items).
    items: Buffer,
    item_offsets: [u64; TABLE_COUNT as usize],
    item_caps: [u64; TABLE_COUNT as usize],
    /// Representatives and handles: size `s` from word `s * stride` (`EDIT_LEVEL_STRIDE`; 0
    /// where the level has one possible size), `count` words each. build_items finds a
    /// child's from its size by arithmetic, with no load of a per-size address.
    reps: Buffer,
    handles: Buffer,
    stride: u64,
    count: u64,
    /// One slot per node (read through `addresses`, or the level above's word view).
    slots: Buffer,
    /// Items per size (build_items' counters).
    counters: Buffer,
    /// The per-level address buffer and its contents (`EDIT_LEVEL_*`).
    address_buf: Buffer,
    addresses: [u64; LEVEL_ADDRESSES],
    /// Push constants of build_items and resolve.
    push: EditPush,
    /// The word views build_items reads ([`LevelTexels`]; none where a buffer has more words
    /// than a view takes: build_items then reads through addresses).
    texels: Option<LevelTexels>,
}

impl MergeBuffers {
    /// Size `s`'s items.
    fn items(&self, s: usize) -> BufferSlice<'_> {
        let words = s as u64 + MIN_ITEM_WORDS as u64;
        self.items
            .slice(self.item_offsets[s], 4 * words * self.item_caps[s])
            .expect("inside the buffer made for it")
    }

    /// Size `s`'s representatives.
    fn reps(&self, s: usize) -> BufferSlice<'_> {
        Self::per_size(&self.reps, s, self.stride, self.count)
    }

    /// Size `s`'s handles.
    fn handles(&self, s: usize) -> BufferSlice<'_> {
        Self::per_size(&self.handles, s, self.stride, self.count)
    }

    fn per_size(buffer: &Buffer, s: usize, stride: u64, count: u64) -> BufferSlice<'_> {
        buffer
            .slice(4 * s as u64 * stride, 4 * count)
            .expect("inside the buffer made for it")
    }
}

/// One level of the recorded merge, made before the recording: its buffers, its claim tables
/// (one per possible item size) and its mixed-batch entries.
struct PreparedLevel {
    buffers: MergeBuffers,
    claim_tables: Vec<ClaimTable>,
    entry_buf: Buffer,
    entries: [HashPush; MIXED_SIZES],
}

/// What a merged level's submission records after its resolve.
#[derive(Clone, Copy)]
enum After<'a> {
    /// The next level's build_items.
    Level(&'a MergeBuffers),
    /// The readback of the root in the last level's results.
    Root(&'a Buffer),
    /// Nothing (a load's level: the load reads the root at its end).
    Nothing,
}

/// What that submission reads back: the next level's counters, or the root.
enum Back {
    Counts(Option<Readback<u32>>),
    Root(Box<RootReadback>),
}

/// What [`GpuHashDag::merge`] did: per level the items built and the extra insert rounds, and
/// the root's readback when the last level's submission recorded it.
struct Merged {
    levels: Vec<(u32, u32)>,
    root: Option<RootReadback>,
}

/// What [`GpuHashDag::merge_recorded`] did.
enum RecordedMerge {
    /// Every item found its slot.
    Merged(Box<Merged>),
    /// Some found no slab: the items it built per size (index = words - 2).
    LeftOut(Vec<u64>),
}

/// The readbacks that end an edit: the new root's value, the missing handles, the pools.
struct RootReadback {
    root: Readback<u32>,
    missing: Readback<u32>,
    statuses: Vec<Readback<HashStatus>>,
}

impl GpuHashDag {
    /// An empty hash DAG (root `Empty`) for a grid whose root is at `root_level` (side
    /// `4 << root_level`), geometry only or with materials.
    pub fn new(
        ctx: &Arc<GpuContext>,
        config: &GpuHashDagConfig,
        root_level: u32,
        with_materials: bool,
    ) -> Result<GpuHashDag, GpuDagError> {
        GpuHashDag::for_items(
            ctx,
            config,
            root_level,
            with_materials,
            &[0; TABLE_COUNT as usize],
        )
    }

    /// Empty tables for a load of `loaded` items per table (index = item words - 2), which
    /// [`Buckets::FromLoad`] sizes them by.
    fn for_items(
        ctx: &Arc<GpuContext>,
        config: &GpuHashDagConfig,
        root_level: u32,
        with_materials: bool,
        loaded: &[u64; TABLE_COUNT as usize],
    ) -> Result<GpuHashDag, GpuDagError> {
        if config.max_super_blocks > max_super_blocks() {
            return Err(GpuDagError::Invalid(format!(
                "at most {} super blocks per table keep handles below 2^28",
                max_super_blocks()
            )));
        }
        if !(1..=19).contains(&root_level) {
            return Err(GpuDagError::Invalid(format!(
                "root level {root_level} (grids of 8..=2^21 voxels have root levels 1..=19)"
            )));
        }
        let buckets = match config.buckets {
            Buckets::Fixed(n) => [n; TABLE_COUNT as usize],
            Buckets::FromLoad => table_buckets(loaded),
        };
        let mut tables = Vec::new();
        let mut dedups = Vec::new();
        for (words, buckets) in (MIN_ITEM_WORDS..=MAX_ITEM_WORDS).zip(buckets) {
            let table_config = HashTableConfig {
                initial_super_blocks: config.initial_super_blocks,
                grow_before_insert: config.grow_before_insert,
                max_insert_rounds: config.max_insert_rounds,
                max_super_blocks: config.max_super_blocks,
                team: config.team,
                ..HashTableConfig::new(config.variant, words, buckets)
            };
            tables.push(GpuHashTable::new(ctx, &table_config)?);
            // Single lanes fold the dedup into the table passes (`hash::claim`).
            if tables[0].team_size() > 1 {
                dedups.push(GpuDedup::with_team(ctx, words, config.team)?);
            }
        }
        // Specialization constants of every edit pass: the tool (read from the flags here) and
        // whether leaves carry materials (`EDIT_SPEC_*` in edit/common.glsl).
        let materials = with_materials as u32;
        let pipeline = |name: &str, spirv: &[u32]| {
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name,
                spirv,
                spec_constants: &[TOOL_FROM_FLAGS, materials],
                push_constant_size: std::mem::size_of::<EditPush>() as u32,
                bindings: &[],
            })
        };
        let mixed = (tables[0].team_size() == 1)
            .then(|| MixedPasses::new(ctx, &tables[0]))
            .transpose()?;
        let small_levels = mixed
            .as_ref()
            .map(|_| SmallLevelsPass::new(ctx, &tables[0], materials))
            .transpose()?;
        let table_addresses = ctx.create_buffer(
            "hash dag tables",
            8 * TABLE_COUNT as u64,
            MemLocation::GpuOnly,
        )?;
        let addresses: Vec<u64> = tables.iter().map(|t| t.pool().table_address()).collect();
        let merge_errors = ctx.create_buffer("hash dag merge errors", 4, MemLocation::GpuOnly)?;
        let mut cmd = ctx.begin_commands("hash dag init")?;
        cmd.upload(&table_addresses, 0, &addresses)?;
        cmd.fill_buffer(&merge_errors, 0);
        cmd.submit_async()?;
        Ok(GpuHashDag {
            ctx: Arc::clone(ctx),
            config: config.clone(),
            tables,
            dedups,
            mixed,
            small_levels,
            size_shares: Vec::new(),
            table_addresses,
            expand: pipeline("edit expand", shaders::EDIT_EXPAND)?,
            build_items: BuildItemsPipelines::new(ctx, materials)?,
            mark: pipeline("edit mark", shaders::EDIT_MARK)?,
            resolve: pipeline("edit resolve", shaders::EDIT_RESOLVE)?,
            traverse: ToolPipelines::new("edit traverse", shaders::EDIT_TRAVERSE, materials),
            traverse_chain: ToolPipelines::traverse_chain(materials, ctx.info().subgroup_size),
            records_stand_in: ChainRecords::new(
                ctx,
                "edit chain records (stand-in)",
                std::mem::size_of::<EditPush>(),
            )?,
            leaves: ToolPipelines::new("edit leaves", shaders::EDIT_LEAVES, materials),
            fill_init: pipeline("edit fill init", shaders::EDIT_FILL_INIT)?,
            fill_flood: pipeline("edit fill flood", shaders::EDIT_FILL_FLOOD)?,
            iota: None,
            merge_errors,
            root_level,
            with_materials,
            palette: Vec::new(),
            roots: vec![Root::Empty],
            current: 0,
            gc_state: gpu_gc::GcState::default(),
        })
    }

    /// Loads an `svdag32` DAG (geometry only) into new tables on the GPU, level by level
    /// bottom-up; its root becomes the current root.
    pub fn load(
        ctx: &Arc<GpuContext>,
        config: &GpuHashDagConfig,
        dag: &Svdag,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<GpuHashDag, GpuDagError> {
        dag.validate()?;
        if dag.words.len() >= 1 << 28 {
            return Err(GpuDagError::Invalid(format!(
                "{} svdag words (the loader indexes results with 28 bits)",
                dag.words.len()
            )));
        }
        // Items per table: an inner node of c children has 1 + c words, a leaf 2.
        let mut loaded = [0u64; TABLE_COUNT as usize];
        loaded[0] = dag.level_range(0).len() as u64 / 2;
        for level in 1..=dag.root_level() {
            for at in dag.node_starts(level) {
                // An empty scene's root has no child (and is no item).
                if let Some(table) = (dag.words[at].count_ones() as usize).checked_sub(1) {
                    loaded[table] += 1;
                }
            }
        }
        let mut hd = GpuHashDag::for_items(ctx, config, dag.root_level(), false, &loaded)?;
        let words = ctx.upload("hash dag load words", &dag.words)?;
        let results = ctx.create_buffer(
            "hash dag load results",
            4 * dag.words.len() as u64,
            MemLocation::GpuOnly,
        )?;
        for level in 0..=dag.root_level() {
            let range = dag.level_range(level);
            let offsets: Vec<u32> = dag.node_starts(level).map(|at| at as u32).collect();
            let count = offsets.len() as u32;
            if count == 0 {
                continue;
            }
            let offset_buf = ctx.upload("hash dag load offsets", &offsets)?;
            let input = if level == 0 {
                None
            } else {
                let nodes = ctx.create_buffer(
                    "hash dag load nodes",
                    32 * count as u64,
                    MemLocation::GpuOnly,
                )?;
                let mut cmd = ctx.begin_commands("hash dag expand")?;
                let push = EditPush {
                    src: words.address(),
                    src2: offset_buf.address(),
                    dst: nodes.address(),
                    count,
                    ..EditPush::default()
                };
                cmd.begin_pass(&mut profiler, "edit expand");
                cmd.dispatch(&hd.expand, groups(count), bytemuck::bytes_of(&push), &[])?;
                cmd.end_pass(&mut profiler);
                cmd.submit_async()?;
                Some(nodes)
            };
            let level_input = match &input {
                Some(nodes) => nodes.into(),
                None => {
                    words.slice(4 * range.start as u64, 4 * (range.end - range.start) as u64)?
                }
            };
            hd.merge(
                &[MergeLevel {
                    input: level_input,
                    count,
                    leaves: level == 0,
                    below: Some(&results),
                    results: &results,
                    result_index: Some(&offset_buf),
                }],
                false,
                profiler.as_deref_mut(),
            )?;
        }
        hd.roots = vec![hd.read_root(&results)?];
        if let Some(p) = profiler {
            p.resolve()?;
        }
        Ok(hd)
    }

    /// Makes the pipelines of the edits with every tool in `tools` ready now, which the first
    /// edit with each tool otherwise does: the traversal and leaves pipelines are made
    /// (`ToolPipelines`: lavapipe builds one in ~10-30 ms), and every pipeline the recorded
    /// edit runs is warmed ([`Commands::warm`]: llvmpipe compiles a pipeline's native code at
    /// its first dispatch, or loads it from Mesa's disk cache in ~0.5-1 ms; without a cache,
    /// ~1.3 s for a paint edit's). Stalls an editor's first stroke or a timed replay should not
    /// take. Returns the milliseconds it took.
    pub fn prepare_tools<'a>(
        &self,
        tools: impl IntoIterator<Item = &'a Tool>,
    ) -> Result<f64, GpuDagError> {
        let start = std::time::Instant::now();
        let ctx = &self.ctx;
        let mut kinds: Vec<u32> = tools
            .into_iter()
            .map(|tool| (ToolKind::of(tool) as u32) << TOOL_SHIFT)
            .collect();
        kinds.sort_unstable();
        kinds.dedup();
        let mut cmd = ctx.begin_commands("edit warm pipelines")?;
        for &flags in &kinds {
            for pipelines in [&self.traverse, &self.leaves] {
                cmd.warm(pipelines.get(ctx, flags)?, &[])?;
            }
            let chain = self.traverse_chain.get(ctx, flags)?;
            cmd.warm(chain, &self.records_stand_in.bound())?;
            if flags == (ToolKind::Fill as u32) << TOOL_SHIFT {
                cmd.warm(&self.fill_init, &[])?;
                cmd.warm(&self.fill_flood, &[])?;
            }
        }
        if !kinds.is_empty() {
            self.build_items.warm(&mut cmd)?;
            cmd.warm(&self.resolve, &[])?;
            for pipeline in self.mixed.iter().flat_map(|m| m.pipelines()) {
                cmd.warm(pipeline, &[])?;
            }
            if let Some(small) = &self.small_levels {
                cmd.warm(small.pipeline(), &self.records_stand_in.bound())?;
            }
        }
        cmd.submit()?;
        Ok(start.elapsed().as_secs_f64() * 1e3)
    }

    /// Buckets of each table (index = item words - 2).
    pub fn buckets(&self) -> Vec<u32> {
        self.tables.iter().map(|t| t.config().buckets).collect()
    }

    /// The current root.
    pub fn root(&self) -> Root {
        self.roots[self.current]
    }

    /// The history: every live root, oldest first (the current one and, after an undo, the
    /// redo branch after it). Garbage collection must keep all of them.
    pub fn roots(&self) -> &[Root] {
        &self.roots
    }

    /// Makes the previous root current; false when there is none.
    pub fn undo(&mut self) -> bool {
        let moved = self.current > 0;
        self.current -= moved as usize;
        moved
    }

    /// Makes the next root (undone before) current again; false when there is none.
    pub fn redo(&mut self) -> bool {
        let moved = self.current + 1 < self.roots.len();
        self.current += moved as usize;
        moved
    }

    /// Level of the root (grid side `4 << root_level`).
    pub fn root_level(&self) -> u32 {
        self.root_level
    }

    /// Grid side in voxels.
    pub fn resolution(&self) -> u32 {
        4 << self.root_level
    }

    /// Whether leaves carry materials.
    pub fn with_materials(&self) -> bool {
        self.with_materials
    }

    /// The configuration.
    pub fn config(&self) -> &GpuHashDagConfig {
        &self.config
    }

    /// The table of `words`-word items.
    pub fn table(&self, words: u32) -> Option<&GpuHashTable> {
        self.tables.get(words.checked_sub(MIN_ITEM_WORDS)? as usize)
    }

    /// The table of `words`-word items, mutable: for loaders that insert canonical items
    /// themselves (items of a CPU hash DAG with materials, say) and render a root they built.
    pub fn table_mut(&mut self, words: u32) -> Option<&mut GpuHashTable> {
        // Inserts through it are not seen by the kept pool use.
        self.gc_state.pool_use = None;
        self.tables
            .get_mut(words.checked_sub(MIN_ITEM_WORDS)? as usize)
    }

    /// Device memory of the nine tables, in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.tables.iter().map(|t| t.gpu_bytes()).sum()
    }

    /// Downloads every table (for host-side reads: voxels, counts, conversion to an SVDAG).
    pub fn download(&self) -> Result<HashDagImage, GpuDagError> {
        let tables = self
            .tables
            .iter()
            .map(|t| t.download())
            .collect::<Result<Vec<_>, _>>()?;
        Ok(HashDagImage {
            tables,
            root_level: self.root_level,
            with_materials: self.with_materials,
        })
    }

    /// Applies `tool` (validated with [`Tool::validate`]) to the current root; the result
    /// becomes the new current root (the redo branch is dropped). Every tool of
    /// `edit::tool` gives the CPU reference editor's voxels and materials (`Edit::voxel`); in
    /// a scene without materials the tool's material is 0 and paint changes nothing.
    /// All-or-nothing: stored items are never changed, so on an error the previous root stays
    /// current and intact. With automatic GC on ([`GpuHashDagConfig::auto_gc_threshold`]), an
    /// edit that runs a pool out at its cap collects garbage (the failed attempt's items
    /// included) and, when that freed anything, runs once more.
    pub fn edit(
        &mut self,
        tool: &Tool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<EditReport, GpuDagError> {
        tool.validate()
            .map_err(|e| GpuDagError::Invalid(format!("tool {tool:?}: {e}")))?;
        self.auto_gc()?;
        match self.edit_once(tool, profiler.as_deref_mut()) {
            Err(GpuDagError::Hash(HashError::Exhausted { .. }))
                if self.config.auto_gc_threshold.is_some() && self.gc_after_exhaustion()? =>
            {
                self.edit_once(tool, profiler)
            }
            result => result,
        }
    }

    /// One attempt of [`GpuHashDag::edit`] on a validated tool.
    fn edit_once(
        &mut self,
        tool: &Tool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<EditReport, GpuDagError> {
        let ctx = Arc::clone(&self.ctx);
        // Set again by the root's readback; an edit that fails may leave inserts unread.
        let pool_use = self.gc_state.pool_use.take();
        let materials = self.with_materials;
        let material = |m: u8| if materials { m as u32 } else { 0 };
        let root_value = value_of_root(self.root());
        let mut params = [0u32; TOOL_PARAMS];
        params[7] = self.root_level;
        let mut fill_bitmap = None;
        // (kind, shape, region centre, region radius, material); None: nothing changes.
        let setup = match *tool {
            Tool::Add {
                shape,
                center,
                radius,
                material: m,
            } => Some((ToolKind::Add, shape, center, radius, material(m))),
            Tool::Remove {
                shape,
                center,
                radius,
            } => Some((ToolKind::Remove, shape, center, radius, 0)),
            // Geometry-only scenes have one material: painting changes nothing (as on the CPU).
            Tool::Paint {
                center,
                radius,
                material: m,
            } => materials.then_some((ToolKind::Paint, Shape::Sphere, center, radius, m as u32)),
            Tool::Fill {
                center,
                radius,
                material: m,
            } => {
                let flooded = self.flood(center, radius, root_value, &mut params, &mut profiler)?;
                flooded.map(|bitmap| {
                    fill_bitmap = Some(bitmap);
                    (ToolKind::Fill, Shape::Cube, center, radius, material(m))
                })
            }
            Tool::Copy(p) => {
                let region = CopyRegion::new(p)
                    .map_err(|e| GpuDagError::Invalid(format!("tool {tool:?}: {e}")))?;
                let floats = |at: usize, v: &[f32], params: &mut [u32; TOOL_PARAMS]| {
                    for (k, x) in v.iter().enumerate() {
                        params[at + k] = x.to_bits();
                    }
                };
                floats(8, &p.source, &mut params);
                floats(11, &p.dest, &mut params);
                floats(14, &p.center, &mut params);
                floats(17, &[p.radius], &mut params);
                if let Some(inv) = region.inverse {
                    params[18] = 1;
                    floats(19, inv.as_flattened(), &mut params);
                }
                Some((
                    ToolKind::Copy,
                    Shape::Cube,
                    region.dest_center,
                    region.dest_radius,
                    0,
                ))
            }
        };
        let levels = self.root_level as usize + 1;
        let Some((kind, shape, center, radius, material)) = setup else {
            // The edit changes no voxel: the new root is the current one.
            self.gc_state.pool_use = pool_use;
            self.push_root(self.root());
            return Ok(EditReport {
                temporary_nodes: vec![0; levels],
                items: vec![0; levels],
                retried_rounds: 0,
            });
        };
        // Uploaded in the first traversal submission (no wait of their own).
        let param_buf = ctx.create_buffer(
            "edit tool params",
            4 * TOOL_PARAMS as u64,
            MemLocation::GpuOnly,
        )?;
        let flags = (kind as u32) << TOOL_SHIFT;
        let base_push = EditPush {
            src2: param_buf.address(),
            dst2: fill_bitmap.as_ref().map_or(0, |b: &Buffer| b.address()),
            tables: self.table_addresses.address(),
            flags,
            variant: self.config.variant.id(),
            tool: [center[0], center[1], center[2], radius],
            shape: match shape {
                Shape::Sphere => 0,
                Shape::Cube => 1,
            },
            material,
            root: root_value,
            ..EditPush::default()
        };
        let mut report = EditReport {
            temporary_nodes: vec![0; levels],
            items: vec![0; levels],
            retried_rounds: 0,
        };
        // Top-down: temp[l] = the temporary nodes (inner levels) or leaves (level 0) of the
        // level-l cubes the tool may change. Levels share a submission while the buffers sized
        // by the tool's bounds stay small; a bound that turns out wrong (checked after the
        // submission) makes the traversal run again one level per submission.
        let bounds = (self.config.traversal_budget > 0)
            .then(|| traversal_bounds(center, radius, self.root_level));
        let traversal = (params.as_slice(), &param_buf, root_value);
        let (temp, counts) =
            match self.traverse(&base_push, traversal, bounds.as_deref(), &mut profiler)? {
                Some(done) => done,
                None => self
                    .traverse(&base_push, traversal, None, &mut profiler)?
                    .ok_or_else(|| {
                        GpuDagError::Corrupt("traversal overflowed its exact capacity".into())
                    })?,
            };
        report.temporary_nodes = counts;
        // Bottom-up merge of the temporary SVO into the tables.
        let results = report
            .temporary_nodes
            .iter()
            .map(|&n| ctx.create_buffer("edit results", 4 * n.max(1) as u64, MemLocation::GpuOnly))
            .collect::<Result<Vec<_>, _>>()?;
        let mut merge_levels = Vec::new();
        for (level, input) in temp.iter().enumerate() {
            let Some(input) = input.as_ref() else {
                continue;
            };
            merge_levels.push(MergeLevel {
                input: input.into(),
                count: report.temporary_nodes[level],
                leaves: level == 0,
                below: level.checked_sub(1).map(|l| &results[l]),
                results: &results[level],
                result_index: None,
            });
        }
        let first = levels - merge_levels.len();
        // A recorded merge that ran a pool out runs once more on pools grown for the items it
        // built (it finds the ones it inserted); level by level, reserving for the worst case,
        // only after that.
        let recorded = match self.merges_recorded() {
            false => None,
            true => match self.merge_recorded(&merge_levels, None, profiler.as_deref_mut())? {
                RecordedMerge::Merged(merged) => Some(*merged),
                RecordedMerge::LeftOut(built) => {
                    let again = Some(built.as_slice());
                    match self.merge_recorded(&merge_levels, again, profiler.as_deref_mut())? {
                        RecordedMerge::Merged(merged) => Some(*merged),
                        RecordedMerge::LeftOut(_) => None,
                    }
                }
            },
        };
        let merged = match recorded {
            Some(merged) => merged,
            None => self.merge(&merge_levels, true, profiler.as_deref_mut())?,
        };
        for (k, &(items, retried)) in merged.levels.iter().enumerate() {
            report.items[first + k] = items;
            report.retried_rounds += retried;
        }
        let root = match merged.root {
            Some(readback) => self.finish_root_readback(readback)?,
            None => self.read_root(&results[levels - 1])?,
        };
        if let Some(p) = profiler {
            p.resolve()?;
        }
        self.push_root(root);
        Ok(report)
    }

    /// The top-down traversal of an edit: from the root entry (`root_value`, uploaded with
    /// the tool parameters in the first submission) level by level down to the leaves. Every
    /// pass reads its record count from the level's block `[count, x, 1, 1]` in one GPU buffer
    /// (`count_at`) and is dispatched indirectly from it; the traverse pass of the level above
    /// wrote it. Consecutive levels share one submission while their buffers, sized by
    /// `bounds` (entries per level, [`traversal_bounds`]), fit the configured traversal budget; the
    /// count of the last level of a submission is read back and sizes the next (at most 8 x).
    /// `bounds == None`: one level per submission, exact capacities. Returns the temporary
    /// nodes / leaves per level (None where a level has no entry) and the entries per level,
    /// or None when a level made more entries than its bound.
    fn traverse(
        &self,
        base: &EditPush,
        (params, param_buf, root_value): (&[u32], &Buffer, u32),
        bounds: Option<&[u64]>,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<Option<Traversal>, GpuDagError> {
        let ctx = &self.ctx;
        let levels = self.root_level as usize + 1;
        let top = levels - 1;
        let record = if self.with_materials { 40 } else { 8 };
        // Capacity of the entries the traverse pass of a level with `cap` entries appends.
        let next_cap = |level: usize, cap: u64| match bounds {
            Some(b) => b[level - 1].min(8 * cap),
            None => 8 * cap,
        };
        let cost = |level: usize, cap: u64| match level {
            0 => record * cap,
            _ => 32 * cap + 16 * next_cap(level, cap),
        };
        let mut blocks_init = [0u32, 0, 1, 1].repeat(levels);
        blocks_init[4 * top..4 * top + 2].copy_from_slice(&[1, 1]);
        let blocks = ctx.create_buffer(
            "edit traverse counts",
            16 * levels as u64,
            MemLocation::GpuOnly,
        )?;
        let block = |level: usize| blocks.address() + 16 * level as u64;
        let mut carry = ctx.create_buffer("edit entries", 16, MemLocation::GpuOnly)?;
        let mut temp: Vec<Option<Buffer>> = (0..levels).map(|_| None).collect();
        let mut counts = vec![0u32; levels];
        counts[top] = 1;
        let mut level = top;
        loop {
            // This submission's levels and capacities: the first one's count is known.
            let mut segment = vec![(level, counts[level] as u64)];
            let mut bytes = cost(level, counts[level] as u64);
            while let Some(&(l, cap)) = segment.last() {
                if l == 0 || bounds.is_none() {
                    break;
                }
                let next = next_cap(l, cap);
                if bytes + cost(l - 1, next) > self.config.traversal_budget {
                    break;
                }
                bytes += cost(l - 1, next);
                segment.push((l - 1, next));
            }
            // Buffers first (the recording borrows them): per level its nodes or leaves, and
            // for inner levels the next level's entries.
            let mut buffers = Vec::new();
            for &(l, cap) in &segment {
                if l == 0 {
                    let leaves = ctx.create_buffer(
                        "edit temporary leaves",
                        record * cap.max(1),
                        MemLocation::GpuOnly,
                    )?;
                    buffers.push((leaves, None));
                    continue;
                }
                let next = next_cap(l, cap);
                if next > u32::MAX as u64 {
                    return Err(GpuDagError::Invalid(
                        "temporary SVO larger than 2^32 entries".into(),
                    ));
                }
                let nodes = ctx.create_buffer(
                    "edit temporary nodes",
                    32 * cap.max(1),
                    MemLocation::GpuOnly,
                )?;
                let entries =
                    ctx.create_buffer("edit entries", 16 * next.max(1), MemLocation::GpuOnly)?;
                buffers.push((nodes, Some(entries)));
            }
            // Every level's push constants, as its own dispatch has them.
            let mut pushes = Vec::new();
            let mut input = &carry;
            for (&(l, cap), (out, next)) in segment.iter().zip(&buffers) {
                let mut push = EditPush {
                    src: input.address(),
                    dst: out.address(),
                    count_at: block(l),
                    count: cap as u32,
                    level: l as u32,
                    ..*base
                };
                if let Some(next) = next {
                    push.dst2 = next.address();
                    push.counters = block(l - 1);
                    push.capacity = next_cap(l, cap) as u32;
                    input = next;
                }
                pushes.push(push);
            }
            // The segment's first level (its count known here) and the next inner levels while
            // they are small go to one dispatch of one SIMD group (`traverse_small_levels`),
            // which leaves the levels it took zero workgroups in their own dispatches.
            let inner = segment.iter().filter(|&&(l, _)| l > 0).count();
            let chained = level > 0 && counts[level] <= TRAVERSE_CHAIN_ENTRIES;
            let chain = match chained {
                true => Some(ChainRecords::new(
                    ctx,
                    "edit traverse small levels",
                    inner * std::mem::size_of::<EditPush>(),
                )?),
                false => None,
            };
            let mut cmd = ctx.begin_commands("edit traverse")?;
            if level == top {
                // A failed attempt before may have counted missing handles (its resolves ran
                // with its inserts).
                cmd.fill_buffer(&self.merge_errors, 0);
                cmd.upload(param_buf, 0, params)?;
                cmd.upload(&carry, 0, &[0u32, 0, 0, root_value][..])?;
                cmd.upload(&blocks, 0, &blocks_init)?;
            }
            if let Some(records) = &chain {
                cmd.upload(records.buffer(), 0, &pushes[..inner])?;
                let push = TraverseChainPush {
                    levels: inner as u32,
                    max_entries: TRAVERSE_CHAIN_ENTRIES,
                };
                cmd.begin_pass(profiler, "edit traverse small levels");
                cmd.dispatch(
                    self.traverse_chain.get(ctx, base.flags)?,
                    [1, 1, 1],
                    bytemuck::bytes_of(&push),
                    &records.bound(),
                )?;
                cmd.end_pass(profiler);
                cmd.barrier();
            }
            // The chain surely takes the inner levels whose capacity (the tool's bound) is
            // within its limit, up to the first that is not: their own dispatches, which would
            // find zero workgroups, are left out (on lavapipe each still costs its barrier).
            let surely_chained = match chained {
                true => segment
                    .iter()
                    .skip(1)
                    .take_while(|&&(l, cap)| l > 0 && cap <= TRAVERSE_CHAIN_ENTRIES as u64)
                    .count(),
                false => 0,
            };
            for (k, (&(l, _), push)) in segment.iter().zip(&pushes).enumerate() {
                if chained && k <= surely_chained {
                    continue;
                }
                let (pipeline, name) = match l {
                    0 => (self.leaves.get(ctx, push.flags)?, "edit leaves"),
                    _ => (self.traverse.get(ctx, push.flags)?, "edit traverse"),
                };
                cmd.begin_pass(profiler, name);
                cmd.dispatch_indirect(
                    pipeline,
                    &blocks,
                    16 * l as u64 + 4,
                    bytemuck::bytes_of(push),
                    &[],
                )?;
                cmd.end_pass(profiler);
                cmd.barrier();
            }
            let back = cmd.readback::<[u32; 4]>(&blocks, 0, levels)?;
            cmd.submit_async()?;
            let made = back.read()?;
            let mut last = 0;
            for (&(l, cap), (out, next)) in segment.iter().zip(buffers) {
                if counts[l] > 0 {
                    temp[l] = Some(out);
                }
                if let Some(next) = next {
                    let n = made[l - 1][0];
                    if n as u64 > next_cap(l, cap) || n >= 1 << 28 {
                        if bounds.is_some() && n < 1 << 28 {
                            return Ok(None);
                        }
                        return Err(GpuDagError::Corrupt(format!(
                            "traversal of level {l} made {n} entries (room for {})",
                            next_cap(l, cap)
                        )));
                    }
                    counts[l - 1] = n;
                    carry = next;
                }
                last = l;
            }
            if last == 0 || counts[last - 1] == 0 {
                return Ok(Some((temp, counts)));
            }
            level = last - 1;
        }
    }

    /// The fill's flood on the GPU (`tool.rs` `FillSet`): fills the box fields of `params`,
    /// marks the free voxels of the fill box (`fill_init`), then repeats flood passes along x,
    /// y, z (`fill_flood`) until a round changes nothing. Returns the flooded bitmap, or None
    /// when the fill reaches no voxel (the box misses the grid, or the start voxel is outside
    /// the grid or the cube).
    fn flood(
        &self,
        center: [f32; 3],
        radius: f32,
        root_value: u32,
        params: &mut [u32; TOOL_PARAMS],
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<Option<Buffer>, GpuDagError> {
        let n = self.resolution();
        let Some((min, max)) = tool::voxel_box(center, radius, n) else {
            return Ok(None);
        };
        let start = center.map(|c| c.floor());
        if start.iter().any(|&s| !(s >= 0.0 && s < n as f32)) {
            return Ok(None);
        }
        let start = start.map(|s| s as u32);
        if !tool::in_cube(center, radius, start) {
            return Ok(None);
        }
        let dims = [0, 1, 2].map(|a| max[a] - min[a] + 1);
        let volume = dims.iter().map(|&d| d as u64).product::<u64>();
        if volume >= 1 << 32 {
            return Err(GpuDagError::Invalid(format!(
                "fill box of {volume} voxels (the GPU flood indexes voxels with 32 bits)"
            )));
        }
        let index =
            |v: [u32; 3]| (v[0] - min[0]) + dims[0] * ((v[1] - min[1]) + dims[1] * (v[2] - min[2]));
        params[0..3].copy_from_slice(&min);
        params[3..6].copy_from_slice(&dims);
        params[6] = index(start);
        let ctx = &self.ctx;
        let param_buf = ctx.upload("edit fill params", &params[..])?;
        let bytes = 4 * volume.div_ceil(32);
        let free = ctx.create_buffer("edit fill free", bytes, MemLocation::GpuOnly)?;
        let flooded = ctx.create_buffer("edit fill flooded", bytes, MemLocation::GpuOnly)?;
        let counter = ctx.create_buffer("edit fill counter", 4, MemLocation::GpuOnly)?;
        let push = EditPush {
            src2: param_buf.address(),
            dst: free.address(),
            dst2: flooded.address(),
            counters: counter.address(),
            tables: self.table_addresses.address(),
            count: volume as u32,
            flags: (ToolKind::Fill as u32) << TOOL_SHIFT,
            variant: self.config.variant.id(),
            tool: [center[0], center[1], center[2], radius],
            shape: 1,
            root: root_value,
            ..EditPush::default()
        };
        let mut cmd = ctx.begin_commands("edit fill init")?;
        cmd.fill_buffer(&free, 0);
        cmd.fill_buffer(&flooded, 0);
        cmd.begin_pass(profiler, "edit fill init");
        cmd.dispatch(
            &self.fill_init,
            groups(push.count),
            bytemuck::bytes_of(&push),
            &[],
        )?;
        cmd.end_pass(profiler);
        cmd.barrier();
        cmd.submit_async()?;
        loop {
            let mut cmd = ctx.begin_commands("edit fill flood")?;
            cmd.fill_buffer(&counter, 0);
            for _ in 0..FLOOD_ROUNDS_PER_WAIT {
                for axis in 0..3u32 {
                    let rows = (volume / dims[axis as usize] as u64) as u32;
                    let flood = EditPush {
                        count: rows,
                        level: axis,
                        ..push
                    };
                    cmd.begin_pass(profiler, "edit fill flood");
                    cmd.dispatch(
                        &self.fill_flood,
                        groups(rows),
                        bytemuck::bytes_of(&flood),
                        &[],
                    )?;
                    cmd.end_pass(profiler);
                    cmd.barrier();
                }
            }
            let back = cmd.readback::<u32>(&counter, 0, 1)?;
            cmd.submit_async()?;
            if back.read()?[0] == 0 {
                break;
            }
        }
        Ok(Some(flooded))
    }

    /// Reads the root value a bottom-up merge left in `results[0]`, the merges' missing
    /// handle count and the tables' pool use in a submission of its own (one wait); the
    /// merge of a level with items records the same readback with its inserts instead.
    fn read_root(&mut self, results: &Buffer) -> Result<Root, GpuDagError> {
        let mut cmd = self.ctx.begin_commands("hash dag root")?;
        let readback = self.record_root_readback(&mut cmd, results)?;
        cmd.submit_async()?;
        self.finish_root_readback(readback)
    }

    /// Records the readback of the root value in `results[0]`, the merges' missing handle
    /// count and the tables' pool use (kept for the next edit's auto-GC check), then clears
    /// the count for the next merge. Recorded at the start of a submission or after the
    /// barrier that ends the resolve (`record_resolve_after`).
    fn record_root_readback<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        results: &'a Buffer,
    ) -> Result<RootReadback, GpuDagError> {
        let root = cmd.readback::<u32>(results, 0, 1)?;
        let missing = cmd.readback::<u32>(&self.merge_errors, 0, 1)?;
        let statuses = self
            .tables
            .iter()
            .map(|t| t.record_status(&mut *cmd))
            .collect::<Result<Vec<_>, _>>()?;
        cmd.barrier();
        cmd.fill_buffer(&self.merge_errors, 0);
        Ok(RootReadback {
            root,
            missing,
            statuses,
        })
    }

    /// The root of a submitted [`GpuHashDag::record_root_readback`] (waits for it).
    fn finish_root_readback(&mut self, readback: RootReadback) -> Result<Root, GpuDagError> {
        let RootReadback {
            root,
            missing,
            statuses,
        } = readback;
        let missing = missing.read()?[0];
        if missing != 0 {
            return Err(GpuDagError::Corrupt(format!(
                "{missing} nodes without a handle after the insert"
            )));
        }
        let root = root_from_value(root.read()?[0])?;
        self.gc_state.pool_use = Some(
            statuses
                .into_iter()
                .map(|s| Ok(s.read()?[0].allocated_slabs as u64))
                .collect::<Result<_, GpuError>>()?,
        );
        Ok(root)
    }

    /// Makes `iota` hold at least `0..n` (uploaded only when it grows).
    fn ensure_iota(&mut self, n: u32) -> Result<(), GpuDagError> {
        if self.iota.as_ref().is_some_and(|b| b.size() >= 4 * n as u64) {
            return Ok(());
        }
        let len = n.next_power_of_two().max(1024);
        let iota: Vec<u32> = (0..len).collect();
        self.iota = Some(self.ctx.upload("edit iota", &iota)?);
        Ok(())
    }

    /// Records the mark pass of every size of a level (one dispatch: sizes with more than one
    /// item, counts read from the level's counters on the GPU) and the insert round of each
    /// size in `sizes`.
    fn record_mark_insert<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        b: &'a MergeBuffers,
        counts: &[u32],
        sizes: &[usize],
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<Vec<PendingInsert>, GpuDagError> {
        let largest = sizes.iter().map(|&s| counts[s]).max().unwrap_or(0);
        if largest > 1 {
            let mark = EditPush {
                tables: b.address_buf.address(),
                counters: b.counters.address(),
                count: largest,
                ..EditPush::default()
            };
            cmd.begin_pass(profiler, "edit mark");
            cmd.dispatch(&self.mark, groups(largest), bytemuck::bytes_of(&mark), &[])?;
            cmd.end_pass(profiler);
            cmd.barrier();
        }
        sizes
            .iter()
            .map(|&s| {
                Ok(self.tables[s].record_insert_round(
                    cmd,
                    b.items(s),
                    b.handles(s),
                    counts[s],
                    profiler.as_deref_mut(),
                )?)
            })
            .collect()
    }

    /// The buffers of one level's merge (sized by its node count) and its push constants;
    /// with `below`, its build_items resolves the pending results of that level (whose own
    /// resolve pass is left out: `merge_recorded`). `views`: word views for build_items' own
    /// dispatch (where the configuration has them).
    fn merge_buffers(
        &self,
        level: &MergeLevel<'_>,
        below: Option<&MergeBuffers>,
        views: bool,
    ) -> Result<MergeBuffers, GpuDagError> {
        let ctx = Arc::clone(&self.ctx);
        let n = level.count.max(1) as u64;
        let sizes = self.possible_sizes(level.leaves);
        let mut item_offsets = [0u64; TABLE_COUNT as usize];
        let mut item_caps = [1u64; TABLE_COUNT as usize];
        let mut item_bytes = 0;
        for s in 0..TABLE_COUNT as usize {
            if sizes.contains(&s) {
                item_caps[s] = n;
            }
            item_offsets[s] = item_bytes;
            item_bytes += 4 * (s as u64 + MIN_ITEM_WORDS as u64) * item_caps[s];
        }
        let items = ctx.create_buffer("edit level items", item_bytes, MemLocation::GpuOnly)?;
        let stride = if sizes.len() > 1 { n } else { 0 };
        let regions = if stride > 0 { TABLE_COUNT as u64 } else { 1 };
        let per_kind = 4 * n * regions;
        let reps = ctx.create_buffer("edit level reps", per_kind, MemLocation::GpuOnly)?;
        let handles = ctx.create_buffer("edit level handles", per_kind, MemLocation::GpuOnly)?;
        let slots = ctx.create_buffer("edit level slots", 4 * n, MemLocation::GpuOnly)?;
        // Where nothing below is resolved here, this level's own buffers stand in (unread).
        let [below_slots, below_reps, below_handles] = below
            .map_or([&slots, &reps, &handles], |b| {
                [&b.slots, &b.reps, &b.handles]
            });
        let texels = match self.config.word_views && views {
            false => None,
            true => LevelTexels::new(
                &ctx,
                [
                    level.input.buffer(),
                    level.below.unwrap_or(level.results),
                    below_slots,
                    below_reps,
                    below_handles,
                ],
            )?,
        };
        let counters = ctx.create_buffer(
            "edit level counters",
            4 * COUNTERS as u64,
            MemLocation::GpuOnly,
        )?;
        let mut addresses = [0u64; LEVEL_ADDRESSES];
        for s in 0..TABLE_COUNT as usize {
            addresses[s] = items.address() + item_offsets[s];
        }
        addresses[LEVEL_SLOTS] = slots.address();
        addresses[LEVEL_REPS] = reps.address();
        addresses[LEVEL_HANDLES] = handles.address();
        addresses[LEVEL_STRIDE] = stride;
        addresses[LEVEL_MISSING] = self.merge_errors.address();
        addresses[LEVEL_BELOW] = below.map_or(0, |b| b.address_buf.address());
        let address_buf = ctx.create_buffer(
            "edit level addresses",
            8 * LEVEL_ADDRESSES as u64,
            MemLocation::GpuOnly,
        )?;
        let mut flags = if level.leaves { FLAG_LEAVES } else { 0 };
        if level.result_index.is_some() {
            flags |= FLAG_RESULT_INDEX;
        }
        let push = EditPush {
            src: level.input.address(),
            src2: level.below.map_or(0, |b| b.address()),
            dst: level.results.address(),
            dst2: level.result_index.map_or(0, |b| b.address()),
            tables: address_buf.address(),
            counters: counters.address(),
            count: level.count,
            level: 0,
            first: (level.input.offset() / 4) as u32,
            flags,
            variant: self.config.variant.id(),
            ..EditPush::default()
        };
        Ok(MergeBuffers {
            items,
            item_offsets,
            item_caps,
            reps,
            handles,
            stride,
            count: n,
            texels,
            slots,
            counters,
            address_buf,
            addresses,
            push,
        })
    }

    /// Records what build_items of one level needs before it runs: the level's address
    /// buffer uploaded, its size counters zeroed.
    fn record_level_setup<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        b: &'a MergeBuffers,
    ) -> Result<(), GpuDagError> {
        cmd.upload(&b.address_buf, 0, &b.addresses)?;
        cmd.fill_buffer(&b.counters, 0);
        Ok(())
    }

    /// Records `build_items` of one level and the readback of its nine size counters.
    fn record_build_items<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        b: &'a MergeBuffers,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<Readback<u32>, GpuDagError> {
        self.record_level_setup(cmd, b)?;
        cmd.begin_pass(profiler, "edit build items");
        cmd.dispatch(
            self.build_items.get(&self.ctx, b.texels.is_some())?,
            groups(b.push.count),
            bytemuck::bytes_of(&b.push),
            &b.texels
                .as_ref()
                .unwrap_or(&self.build_items.stand_in)
                .bound(),
        )?;
        cmd.end_pass(profiler);
        cmd.barrier();
        Ok(cmd.readback::<u32>(&b.counters, 0, COUNTERS)?)
    }

    /// Records the level's `resolve` (missing handles counted in `merge_errors`), then what
    /// comes after it: the next level's `build_items` with the counters' readback, or the
    /// root's readback.
    fn record_resolve_after<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        b: &'a MergeBuffers,
        after: After<'a>,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<Back, GpuDagError> {
        cmd.begin_pass(profiler, "edit resolve");
        cmd.dispatch(
            &self.resolve,
            groups(b.push.count),
            bytemuck::bytes_of(&b.push),
            &[],
        )?;
        cmd.end_pass(profiler);
        cmd.barrier();
        Ok(match after {
            After::Level(n) => Back::Counts(Some(self.record_build_items(cmd, n, profiler)?)),
            After::Root(results) => Back::Root(Box::new(self.record_root_readback(cmd, results)?)),
            After::Nothing => Back::Counts(None),
        })
    }

    /// Merges `levels` bottom-up, each on the results of the one before (see the module
    /// docs); returns per level the items built and the extra insert rounds run, and the
    /// readback of the new root when the last level had items. The host waits once per level
    /// for its size counters and, where it has items, once for the table passes: the
    /// submission that ends with a level's inserts also holds its `resolve` and the next
    /// level's `build_items`, whose counters the wait reads (the last level: the root's
    /// readback, with `read_root`).
    fn merge(
        &mut self,
        levels: &[MergeLevel<'_>],
        read_root: bool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<Merged, GpuDagError> {
        let mut out = Vec::new();
        let Some(first) = levels.first() else {
            return Ok(Merged {
                levels: out,
                root: None,
            });
        };
        let mut current = self.merge_buffers(first, None, true)?;
        let mut cmd = self.ctx.begin_commands("edit build items")?;
        let mut counts = self.record_build_items(&mut cmd, &current, &mut profiler)?;
        cmd.submit_async()?;
        for at in 0..levels.len() {
            let level_counts = counts.read()?;
            let next = match levels.get(at + 1) {
                Some(level) => Some(self.merge_buffers(level, None, true)?),
                None => None,
            };
            let total: u32 = level_counts.iter().sum();
            let last = (read_root && at + 1 == levels.len()).then_some(levels[at].results);
            let (retried, next_counts) = if total > 0 {
                let after = match (next.as_ref(), last) {
                    (Some(n), _) => After::Level(n),
                    (None, Some(results)) => After::Root(results),
                    (None, None) => After::Nothing,
                };
                let (retried, back) =
                    self.merge_items(&current, &level_counts, after, &mut profiler)?;
                match back {
                    Back::Root(root) => {
                        out.push((total, retried));
                        return Ok(Merged {
                            levels: out,
                            root: Some(*root),
                        });
                    }
                    Back::Counts(c) => (retried, c),
                }
            } else {
                // Nothing to insert (every node uniform, written by build_items).
                let mut cmd = self.ctx.begin_commands("edit build items")?;
                let back = next
                    .as_ref()
                    .map(|n| self.record_build_items(&mut cmd, n, &mut profiler))
                    .transpose()?;
                cmd.submit_async()?;
                (0, back)
            };
            out.push((total, retried));
            match (next, next_counts) {
                (Some(n), Some(c)) => {
                    current = n;
                    counts = c;
                }
                _ => break,
            }
        }
        Ok(Merged {
            levels: out,
            root: None,
        })
    }

    /// The table passes of one level with items (`counts` per size), its resolve and what
    /// comes after it (the next level's build_items, or the root's readback); returns the
    /// extra insert rounds and the next level's counters or the root's readback.
    fn merge_items(
        &mut self,
        b: &MergeBuffers,
        counts: &[u32],
        after: After<'_>,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(u32, Back), GpuDagError> {
        if self.dedups.is_empty() {
            return self.merge_items_claimed(b, counts, after, profiler);
        }
        let ctx = Arc::clone(&self.ctx);
        let max = *counts.iter().max().unwrap_or(&0);
        self.ensure_iota(max)?;
        let sizes: Vec<usize> = (0..counts.len()).filter(|&s| counts[s] > 0).collect();
        // A batch of one item is its own representative: no dedup, no mark.
        let deduped: Vec<usize> = sizes.iter().copied().filter(|&s| counts[s] > 1).collect();
        // Batches whose dedup cannot run out (the probe table of single lanes, or a slab table
        // with a pool of 2 x count slabs, given to small batches) let the dedup, search, mark
        // and insert of every size share one submission and one wait.
        let fused = deduped
            .iter()
            .all(|&s| counts[s] <= FUSED_DEDUP_MAX || self.dedups[s].never_retries());
        let scratch = deduped
            .iter()
            .map(|&s| {
                let pool = fused.then(|| 2 * counts[s]);
                self.dedups[s].scratch(counts[s], pool)
            })
            .collect::<Result<Vec<_>, _>>()?;
        if fused {
            self.reserve_sizes(&sizes, counts)?;
        }
        let values = self.iota.as_ref().expect("iota made above");
        // Dedup and search of every size (the search does not read the representatives),
        // then in the same submission when fused the mark and insert round of every size.
        let mut cmd = ctx.begin_commands("edit dedup and search")?;
        let mut pending_dedup = Vec::new();
        for &s in &sizes {
            match deduped.iter().position(|&d| d == s) {
                Some(k) => {
                    pending_dedup.push(self.dedups[s].record_dedup(
                        &mut cmd,
                        b.items(s),
                        values,
                        counts[s],
                        b.reps(s),
                        &scratch[k],
                        profiler.as_deref_mut(),
                    )?);
                    cmd.barrier();
                }
                None => cmd.fill_slice(b.reps(s), 0)?,
            }
            self.tables[s].record_search(
                &mut cmd,
                b.items(s),
                b.handles(s),
                counts[s],
                profiler.as_deref_mut(),
            )?;
        }
        let mut pending_insert = Vec::new();
        let mut errors_before = None;
        let mut back = None;
        if fused {
            cmd.barrier();
            pending_insert = self.record_mark_insert(&mut cmd, b, counts, &sizes, profiler)?;
            errors_before = Some(cmd.readback::<u32>(&self.merge_errors, 0, 1)?);
            back = Some(self.record_resolve_after(&mut cmd, b, after, profiler)?);
        }
        cmd.submit_async()?;
        for (pending, &s) in pending_dedup.into_iter().zip(&deduped) {
            if let DedupResult::Retry { .. } = self.dedups[s].finish_dedup(pending, counts[s])? {
                // Rare (never when fused: finish_dedup reports a fused pool running out as
                // an error): the overflow pool ran out; the batch runs again on its own,
                // before any representative is used.
                self.dedups[s].dedup_buffers(
                    b.items(s),
                    values,
                    counts[s],
                    b.reps(s),
                    profiler.as_deref_mut(),
                )?;
            }
        }
        if !fused {
            self.reserve_sizes(&sizes, counts)?;
            // One submission for the mark and the insert round of every size, one host
            // wait (more only when a pool runs out: `finish_insert` grows it and runs more
            // rounds).
            let mut cmd = ctx.begin_commands("edit insert")?;
            pending_insert = self.record_mark_insert(&mut cmd, b, counts, &sizes, profiler)?;
            errors_before = Some(cmd.readback::<u32>(&self.merge_errors, 0, 1)?);
            back = Some(self.record_resolve_after(&mut cmd, b, after, profiler)?);
            cmd.submit_async()?;
        }
        let errors_before = errors_before.expect("recorded with the inserts");
        let back = back.expect("recorded with the inserts");
        self.finish_level(
            b,
            counts,
            &sizes,
            pending_insert,
            errors_before,
            back,
            after,
            profiler,
        )
    }

    /// Single lanes (CPU devices): per size the table's search-and-claim pass and its claimed
    /// insert round (`hash::claim`: the level's duplicate detection folded into them, no dedup
    /// table, no mark pass), every size in one submission with the level's resolve and what
    /// comes after it. The claim table never runs out, so this is always one submission.
    fn merge_items_claimed(
        &mut self,
        b: &MergeBuffers,
        counts: &[u32],
        after: After<'_>,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(u32, Back), GpuDagError> {
        let ctx = Arc::clone(&self.ctx);
        let sizes: Vec<usize> = (0..counts.len()).filter(|&s| counts[s] > 0).collect();
        let claim_tables = sizes
            .iter()
            .map(|&s| ClaimTable::new(&ctx, s as u32 + MIN_ITEM_WORDS, counts[s]))
            .collect::<Result<Vec<_>, _>>()?;
        self.reserve_sizes(&sizes, counts)?;
        let mut cmd = ctx.begin_commands("edit merge")?;
        let claims_of = |k: usize, s: usize| Claims {
            table: &claim_tables[k],
            reps: b.reps(s),
        };
        for (k, &s) in sizes.iter().enumerate() {
            self.tables[s].record_search_claim(
                &mut cmd,
                b.items(s),
                b.handles(s),
                counts[s],
                claims_of(k, s),
                profiler.as_deref_mut(),
            )?;
        }
        let pending = sizes
            .iter()
            .enumerate()
            .map(|(k, &s)| {
                self.tables[s].record_claimed_insert_round(
                    &mut cmd,
                    b.items(s),
                    b.handles(s),
                    counts[s],
                    claims_of(k, s),
                    profiler.as_deref_mut(),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let errors_before = cmd.readback::<u32>(&self.merge_errors, 0, 1)?;
        let back = self.record_resolve_after(&mut cmd, b, after, profiler)?;
        cmd.submit_async()?;
        self.finish_level(
            b,
            counts,
            &sizes,
            pending,
            errors_before,
            back,
            after,
            profiler,
        )
    }

    /// The sizes (table indices) a level's items may have: leaves without materials are 2
    /// words, with materials 2-10; inner nodes 2-9.
    fn possible_sizes(&self, leaves: bool) -> Vec<usize> {
        let largest = match (leaves, self.with_materials) {
            (true, false) => 2,
            (true, true) => MAX_ITEM_WORDS,
            (false, _) => 9,
        };
        (0..=(largest - MIN_ITEM_WORDS) as usize).collect()
    }

    /// Whether edits merge with [`GpuHashDag::merge_recorded`]: single lanes (the mixed claim
    /// passes) and tables that grow before inserts (the reservation it relies on).
    fn merges_recorded(&self) -> bool {
        self.mixed.is_some() && self.config.grow_before_insert
    }

    /// Single lanes: the merge of every level recorded without the host waiting between
    /// levels (`merge` waits once per level for its size counters), all levels in one
    /// submission. Per level build_items counts its items per size on the GPU and resolves the
    /// pending children of the level below (its resolve pass left out), one search-and-claim
    /// and one claimed insert dispatch take the items of every size ([`crate::hash::mixed`]),
    /// on claim tables sized for the level's node count (a bound of every size's items); only
    /// the last level runs resolve, for the root. One wait in all, for the tables' status and
    /// the root. The pools are grown for the expected case only
    /// ([`GpuHashTable::reserve_expected`] of each size's share of the nodes, at least
    /// `built[size]` items where given): where one runs out all the same, this returns the
    /// items it built per size, having changed no root (the new items are garbage until the
    /// caller merges again and finds them).
    fn merge_recorded(
        &mut self,
        levels: &[MergeLevel<'_>],
        built: Option<&[u64]>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<RecordedMerge, GpuDagError> {
        let ctx = Arc::clone(&self.ctx);
        let Some(last) = levels.last() else {
            return Ok(RecordedMerge::Merged(Box::new(Merged {
                levels: Vec::new(),
                root: None,
            })));
        };
        if levels.iter().any(|level| level.result_index.is_some()) {
            // build_items reads a pending child's slot at its result's index.
            return Err(GpuDagError::Invalid(
                "the recorded merge takes levels without a result index".into(),
            ));
        }
        let sizes: Vec<Vec<usize>> = levels
            .iter()
            .map(|level| self.possible_sizes(level.leaves))
            .collect();
        // Each table's expected new items: a level's nodes split over the sizes they may
        // have as the tables' slabs are (a level of one size gives it every node).
        let slabs: Vec<f64> = self
            .tables
            .iter()
            .map(|t| t.allocated_slabs() as f64 + 1.0)
            .collect();
        // At least the shares the sizes had at the same level in the last merges: a scene of
        // thin surfaces holds few 8-child nodes, solid edits make many.
        let leaves_up = levels[0].leaves;
        let mut expected = [0f64; TABLE_COUNT as usize];
        for (k, (level, sizes)) in levels.iter().zip(&sizes).enumerate() {
            let total: f64 = sizes.iter().map(|&s| slabs[s]).sum();
            let seen = self.size_shares.get(k).filter(|_| leaves_up);
            for &s in sizes {
                let share = (slabs[s] / total).max(seen.map_or(0.0, |seen| seen[s]));
                expected[s] += level.count as f64 * share;
            }
        }
        if let Some(built) = built {
            for (e, &b) in expected.iter_mut().zip(built) {
                *e = e.max(b as f64);
            }
        }
        let used: Vec<usize> = (0..expected.len()).filter(|&s| expected[s] > 0.0).collect();
        for &s in &used {
            self.tables[s].reserve_expected(expected[s].ceil() as u32)?;
        }
        let tables = &self.tables;
        let mixed = self.mixed.as_ref().expect("merges_recorded checked it");
        let small = self
            .small_levels
            .as_ref()
            .expect("made with the mixed passes");
        // The levels from `chained` up (the root's included) are small: one dispatch merges
        // them all (`small_levels`); the ones below get their own passes.
        let chained = levels
            .iter()
            .rposition(|level| !small.takes(level.count))
            .map_or(0, |k| k + 1);
        let entry_bytes = std::mem::size_of::<HashPush>() as u64;
        let mut before = Vec::new();
        let mut after = Vec::new();
        let mut counts = Vec::new();
        // Every level's buffers first (the level above resolves the pending results of the one
        // below through its address buffer), then one recording of all levels.
        let mut prepared: Vec<PreparedLevel> = Vec::with_capacity(levels.len());
        for (k, level) in levels.iter().enumerate() {
            let b = self.merge_buffers(level, prepared.last().map(|p| &p.buffers), k < chained)?;
            let claim_tables = sizes[k]
                .iter()
                .map(|&s| ClaimTable::new(&ctx, s as u32 + MIN_ITEM_WORDS, level.count))
                .collect::<Result<Vec<_>, _>>()?;
            let mut entries = [HashPush::default(); MIXED_SIZES];
            for (&s, table) in sizes[k].iter().zip(&claim_tables) {
                let claims = Claims {
                    table,
                    reps: b.reps(s),
                };
                entries[s] =
                    tables[s].claimed_entry(b.items(s), b.handles(s), level.count, claims)?;
            }
            let entry_buf = ctx.create_buffer(
                "edit level entries",
                MIXED_SIZES as u64 * entry_bytes,
                MemLocation::GpuOnly,
            )?;
            prepared.push(PreparedLevel {
                buffers: b,
                claim_tables,
                entry_buf,
                entries,
            });
        }
        let small_records = match chained < levels.len() {
            true => Some(SmallLevelsPass::records(&ctx, levels.len() - chained)?),
            false => None,
        };
        let mut cmd = ctx.begin_commands("edit merge")?;
        for &s in &used {
            before.push(tables[s].record_status(&mut cmd)?);
        }
        for (k, (level, p)) in levels.iter().zip(&prepared).enumerate() {
            cmd.upload(&p.entry_buf, 0, &p.entries)?;
            for table in &p.claim_tables {
                table.record_clear(&mut cmd)?;
            }
            if k >= chained {
                self.record_level_setup(&mut cmd, &p.buffers)?;
                continue;
            }
            counts.push(self.record_build_items(&mut cmd, &p.buffers, &mut profiler)?);
            let profiler_now = profiler.as_deref_mut();
            mixed.record(
                &mut cmd,
                &p.entry_buf,
                &p.buffers.counters,
                0,
                level.count,
                profiler_now,
            )?;
        }
        let top = prepared.last().expect("levels is not empty");
        match &small_records {
            Some(records) => {
                let chain: Vec<SmallLevel> = levels[chained..]
                    .iter()
                    .zip(&prepared[chained..])
                    .map(|(level, p)| {
                        let batch =
                            MixedPasses::batch(&p.entry_buf, &p.buffers.counters, 0, level.count);
                        (p.buffers.push, batch, p.entries)
                    })
                    .collect();
                small.record(&mut cmd, records, &chain, &mut profiler)?;
                for p in &prepared[chained..] {
                    counts.push(cmd.readback::<u32>(&p.buffers.counters, 0, COUNTERS)?);
                }
            }
            None => {
                self.record_resolve_after(&mut cmd, &top.buffers, After::Nothing, &mut profiler)?;
            }
        }
        for &s in &used {
            after.push(tables[s].record_status(&mut cmd)?);
        }
        let root = self.record_root_readback(&mut cmd, last.results)?;
        cmd.submit_async()?;
        // The last submission's readbacks first: one wait covers all levels.
        let after = after
            .into_iter()
            .map(|a| Ok(a.read()?[0]))
            .collect::<Result<Vec<_>, GpuError>>()?;
        let mut left_out = 0;
        for ((&s, before), after) in used.iter().zip(before).zip(after) {
            let check = self.tables[s].check_inserts(&before.read()?[0], after)?;
            if check.invalid != 0 {
                return Err(GpuDagError::Corrupt(format!(
                    "{} items of {} words rejected by the table layout",
                    check.invalid,
                    s as u32 + MIN_ITEM_WORDS
                )));
            }
            left_out += check.left_out;
        }
        let counts = counts
            .into_iter()
            .map(|c| c.read())
            .collect::<Result<Vec<_>, GpuError>>()?;
        if leaves_up {
            self.observe_size_shares(&counts);
        }
        if left_out > 0 {
            log::debug!("recorded merge: {left_out} items found no slab");
            let mut built = vec![0u64; COUNTERS];
            for level in &counts {
                for (b, &n) in built.iter_mut().zip(level) {
                    *b += n as u64;
                }
            }
            return Ok(RecordedMerge::LeftOut(built));
        }
        Ok(RecordedMerge::Merged(Box::new(Merged {
            levels: counts.iter().map(|c| (c.iter().sum(), 0)).collect(),
            root: Some(root),
        })))
    }

    /// Folds the items per size of each level (leaves first) of a merge into `size_shares`:
    /// a share rises at once and halves per merge that does not renew it.
    fn observe_size_shares(&mut self, counts: &[Vec<u32>]) {
        if self.size_shares.len() < counts.len() {
            self.size_shares.resize(counts.len(), [0.0; COUNTERS]);
        }
        for (shares, level) in self.size_shares.iter_mut().zip(counts) {
            let total: u32 = level.iter().sum();
            if total == 0 {
                continue;
            }
            for (share, &n) in shares.iter_mut().zip(level) {
                *share = (n as f64 / total as f64).max(0.5 * *share);
            }
        }
    }

    /// Grows the tables of `sizes` for `counts` new items each, where they grow before inserts.
    fn reserve_sizes(&mut self, sizes: &[usize], counts: &[u32]) -> Result<(), GpuDagError> {
        for &s in sizes {
            if self.tables[s].config().grow_before_insert {
                self.tables[s].reserve(counts[s])?;
            }
        }
        Ok(())
    }

    /// Completes a level's inserts once their submission was made (`finish_insert` per size:
    /// pool growth and further rounds); returns the extra rounds and what the level's
    /// submission read back after its resolve (`back`), recorded again when rounds were added.
    #[allow(clippy::too_many_arguments)]
    fn finish_level(
        &mut self,
        b: &MergeBuffers,
        counts: &[u32],
        sizes: &[usize],
        pending_insert: Vec<PendingInsert>,
        errors_before: Readback<u32>,
        mut back: Back,
        after: After<'_>,
        profiler: &mut Option<&mut Profiler>,
    ) -> Result<(u32, Back), GpuDagError> {
        let mut retried = 0;
        for (pending, &s) in pending_insert.into_iter().zip(sizes) {
            let report = self.tables[s].finish_insert(
                pending,
                b.items(s),
                b.handles(s),
                counts[s],
                profiler.as_deref_mut(),
            )?;
            retried += report.rounds - 1;
            if report.invalid_items != 0 {
                return Err(GpuDagError::Corrupt(format!(
                    "{} items of {} words rejected by the table layout",
                    report.invalid_items,
                    s as u32 + MIN_ITEM_WORDS
                )));
            }
        }
        // Nodes left without a handle are counted in `merge_errors`, read with the root.
        // When a pool ran out, the resolve recorded with the inserts saw the items of the
        // extra rounds missing (they stay pending): the count goes back to its value before,
        // and resolve and what comes after it (next build_items, root readback) run again.
        let before = errors_before.read()?[0];
        if retried > 0 {
            let mut cmd = self.ctx.begin_commands("edit resolve")?;
            cmd.fill_buffer(&self.merge_errors, before);
            back = self.record_resolve_after(&mut cmd, b, after, profiler)?;
            cmd.submit_async()?;
        }
        Ok((retried, back))
    }
}

/// The tool a traverse / leaves pass applies (GLSL `EDIT_TOOL_*`).
#[derive(Clone, Copy)]
enum ToolKind {
    Add = 0,
    Remove = 1,
    Paint = 2,
    Fill = 3,
    Copy = 4,
}

impl ToolKind {
    /// The kind of `tool`'s edit passes.
    fn of(tool: &Tool) -> ToolKind {
        match tool {
            Tool::Add { .. } => ToolKind::Add,
            Tool::Remove { .. } => ToolKind::Remove,
            Tool::Paint { .. } => ToolKind::Paint,
            Tool::Fill { .. } => ToolKind::Fill,
            Tool::Copy(_) => ToolKind::Copy,
        }
    }
}

/// Most entries of a level that `traverse_small_levels` takes (the first level's count is
/// known when the host records it: it chains only from a level this small). 64 / 128 / 256
/// timed the same on bunny 1024^3's 600 large spheres (16: 10 % slower, 1024: 10 % slower;
/// lavapipe, alternated six times).
const TRAVERSE_CHAIN_ENTRIES: u32 = 128;

/// Number of [`ToolKind`]s.
const TOOL_KINDS: usize = 5;

/// One pipeline of a pass per tool, each made on the first edit with that tool: the tool is
/// specialization constant 0 (`EDIT_SPEC_TOOL` in edit/common.glsl), so each pipeline leaves
/// the other tools' code out, which lavapipe would otherwise run (masked) for every voxel.
struct ToolPipelines {
    name: &'static str,
    spirv: &'static [u32],
    /// Specialization constant 1: whether leaves carry materials (1) or not (0).
    materials: u32,
    /// Specialization constant 2 where the shader has one (the workgroup size of
    /// `traverse_small_levels`).
    lanes: Option<u32>,
    push_constant_size: u32,
    bindings: &'static [BindingKind],
    made: [OnceLock<ComputePipeline>; TOOL_KINDS],
}

impl ToolPipelines {
    /// The pass `name` of `spirv` for a scene with or without materials, no pipeline made yet.
    fn new(name: &'static str, spirv: &'static [u32], materials: u32) -> ToolPipelines {
        ToolPipelines {
            name,
            spirv,
            materials,
            lanes: None,
            push_constant_size: std::mem::size_of::<EditPush>() as u32,
            bindings: &[],
            made: Default::default(),
        }
    }

    /// `traverse_small_levels` for a scene with or without materials, its workgroup `lanes`
    /// invocations (one SIMD group), its levels' records a `uvec4` view.
    fn traverse_chain(materials: u32, lanes: u32) -> ToolPipelines {
        ToolPipelines {
            lanes: Some(lanes),
            push_constant_size: std::mem::size_of::<TraverseChainPush>() as u32,
            bindings: &[BindingKind::TexelBuffer],
            ..ToolPipelines::new(
                "edit traverse small levels",
                shaders::EDIT_TRAVERSE_SMALL_LEVELS,
                materials,
            )
        }
    }

    /// The pipeline of the tool in `flags` (`EditPush::flags`), made now if needed.
    fn get(&self, ctx: &Arc<GpuContext>, flags: u32) -> Result<&ComputePipeline, GpuError> {
        let tool = (flags >> TOOL_SHIFT & 7) as usize;
        let cell = self.made.get(tool).ok_or_else(|| {
            GpuError::InvalidArgument(format!("{}: tool kind {tool} out of range", self.name))
        })?;
        made_once(cell, || {
            let spec = [tool as u32, self.materials, self.lanes.unwrap_or(0)];
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name: self.name,
                spirv: self.spirv,
                spec_constants: &spec[..2 + self.lanes.is_some() as usize],
                push_constant_size: self.push_constant_size,
                bindings: self.bindings,
            })
        })
    }
}

/// Workgroups for one invocation per record (grid-stride beyond 65 535 groups).
fn groups(count: u32) -> [u32; 3] {
    [count.div_ceil(GROUP).clamp(1, 65_535), 1, 1]
}

/// Most entries the traversal can make per level (index = level): the level's cubes (side
/// `4 << level`) that are not entirely outside the tool's region grown by the traverse pass's
/// one-voxel margin (`edit_cube_all_outside`; one more voxel here for f32 rounding). A sphere
/// is bounded by its box.
pub fn traversal_bounds(center: [f32; 3], radius: f32, root_level: u32) -> Vec<u64> {
    let n = 4u64 << root_level;
    let r = radius as f64 + 2.0;
    (0..=root_level)
        .map(|level| {
            let side = (4u64 << level) as f64;
            let cells = (n >> (level + 2)) as f64;
            center
                .iter()
                .map(|&c| {
                    // Cube k is outside when (k + 1) * side < c - r or k * side > c + r.
                    let lo = ((c as f64 - r) / side - 1.0).floor().max(0.0);
                    let hi = ((c as f64 + r) / side).floor().min(cells - 1.0);
                    if hi >= lo {
                        (hi - lo) as u64 + 1
                    } else {
                        0
                    }
                })
                .product()
        })
        .collect()
}

/// The child value of a root.
fn value_of_root(root: Root) -> u32 {
    match root {
        Root::Empty => VALUE_EMPTY,
        Root::Full(m) => VALUE_FULL | m as u32,
        Root::Node(ptr) => ptr.0,
    }
}

/// The root a child value names.
fn root_from_value(value: u32) -> Result<Root, GpuDagError> {
    match child_from_value(value)? {
        Child::Empty => Ok(Root::Empty),
        Child::Full(m) => Ok(Root::Full(m)),
        Child::Node(ptr) => Ok(Root::Node(ptr)),
    }
}

fn child_from_value(value: u32) -> Result<Child, GpuDagError> {
    if value == VALUE_EMPTY {
        Ok(Child::Empty)
    } else if value & 0xFFFF_FFF0 == VALUE_FULL {
        Ok(Child::Full((value & 15) as u8))
    } else if value < VALUE_TEMP {
        Ok(Child::Node(NodePtr(value)))
    } else {
        Err(GpuDagError::Corrupt(format!("child value {value:#010x}")))
    }
}

/// A host copy of the nine tables: reads items, enumerates voxels, counts nodes.
pub struct HashDagImage {
    /// Table images, index = item words - 2.
    pub tables: Vec<TableImage>,
    /// Level of the root.
    pub root_level: u32,
    /// Whether leaves carry materials.
    pub with_materials: bool,
}

impl HashDagImage {
    /// The item a pointer names.
    pub fn item(&self, ptr: NodePtr) -> Result<Vec<u32>, GpuDagError> {
        Ok(self.item_words(ptr)?.into_owned())
    }

    /// Every solid voxel under `root` as (Morton code, material), ascending by code (16 bytes
    /// per voxel: tests and small scenes; [`walk::for_each_voxel`] streams them).
    pub fn voxels(&self, root: Root) -> Result<Vec<(u64, u8)>, GpuDagError> {
        Ok(walk::voxels(self, root)?)
    }

    /// Unique stored nodes reachable from `root`, per level (index = level; uniform children
    /// are not nodes).
    pub fn level_counts(&self, root: Root) -> Result<Vec<u64>, GpuDagError> {
        Ok(walk::unique_nodes_per_level(self, root)?)
    }

    /// The voxels under `root` as a voxel set (materials dropped; no colours).
    pub fn to_voxels(&self, root: Root) -> Result<Voxels, GpuDagError> {
        Ok(Voxels {
            resolution: 4 << self.root_level,
            codes: self.voxels(root)?.into_iter().map(|(c, _)| c).collect(),
            colors: Vec::new(),
        })
    }

    /// `root` converted back to a compact `svdag32` DAG node by node (save it with
    /// `VdagFile`'s writer).
    pub fn to_svdag(&self, root: Root) -> Result<Svdag, GpuDagError> {
        walk::to_svdag(self, root)
    }
}

impl StoredDag for HashDagImage {
    fn item_words(&self, ptr: NodePtr) -> Result<Cow<'_, [u32]>, ItemError> {
        let table = self
            .tables
            .get(ptr.table())
            .ok_or(ItemError::Missing(ptr.0))?;
        let words = table.read(Handle(ptr.handle()));
        Ok(Cow::Owned(words.ok_or(ItemError::Missing(ptr.0))?))
    }

    fn root_level(&self) -> u32 {
        self.root_level
    }

    fn has_materials(&self) -> bool {
        self.with_materials
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_get_buckets_for_their_items_and_a_share_of_the_scene() {
        let mut loaded = [0u64; TABLE_COUNT as usize];
        loaded[0] = 100_000; // 12 500 buckets' worth
        loaded[3] = 1_000_000; // 125 000
        loaded[7] = 300; // a sparse size: the scene's share, 1 100 300 / 16 / 8 = 8 597
        let expected = [
            16384, 16384, 16384, 131072, 16384, 16384, 16384, 16384, 16384,
        ];
        assert_eq!(table_buckets(&loaded), expected);
        assert_eq!(table_buckets(&[0; TABLE_COUNT as usize]), [1024; 9]);
        assert_eq!(
            table_buckets(&[1 << 40; TABLE_COUNT as usize]),
            [1 << 22; 9]
        );
    }
}
