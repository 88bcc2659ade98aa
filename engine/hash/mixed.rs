//! Mixed batches: the claim passes ([`super::claim`]) over the items of several tables of one
//! variant at once (the hash DAG's nine tables, one per item size): one search-and-claim and
//! one claimed insert dispatch for every size instead of two per size. On lavapipe each
//! dispatch costs a hand-off to its worker threads (~15 us), more than most sizes' few items.
//!
//! Each size is an *entry*: the parameters of its table naming its items, handles, claim table
//! and representatives ([`GpuHashTable::claimed_entry`]). The entries lie in a GPU buffer and
//! the sizes' item counts at `counts`, written on the GPU by an earlier pass of the same
//! submission, so that the host records a batch before knowing its sizes. Item `k` of the
//! batch is item `k` minus the items of the sizes before of its size (`hash_select` in
//! `shaders/glsl/hash/common.glsl`). Single lanes only, like the claim passes.

use std::sync::Arc;

use super::layout::HashPush;
use super::table::hash_pipeline;
use super::{GpuHashTable, HashError};
use crate::gpu::{shaders, Buffer, Commands, ComputePipeline, GpuContext, Profiler};

/// Entries of a mixed batch (GLSL `HASH_MIXED_SIZES`).
pub const MIXED_SIZES: usize = 9;

/// Items each invocation of a mixed pass takes (grid stride): what an invocation does once
/// (reading the nine counts, and lavapipe's start of each workgroup) then serves several
/// items. 4 made bunny 1024^3's 600 large spheres ~7 % faster on lavapipe than 1 (2 and 8 no
/// better; docs/editing-gpu.md, "Speed, round 8").
const ITEMS_PER_INVOCATION: u32 = 4;

/// The search-and-claim and claimed insert pipelines of mixed batches.
pub struct MixedPasses {
    claim: ComputePipeline,
    insert: ComputePipeline,
    /// Both passes in one dispatch of one workgroup (a barrier between them), for batches that
    /// fit one workgroup: one lavapipe thread-pool hand-off instead of two.
    claim_insert: ComputePipeline,
    items_per_group: u32,
    max_groups: u32,
}

impl MixedPasses {
    /// The passes for tables shaped like `table` (its variant and workgroup; single lanes).
    pub fn new(ctx: &Arc<GpuContext>, table: &GpuHashTable) -> Result<MixedPasses, HashError> {
        if table.team_size() != 1 {
            return Err(HashError::InvalidArgument(
                "mixed batches need single-lane tables (TeamMode::SingleLane)".into(),
            ));
        }
        let mut spec = table.spec_constants();
        // Item words 0: the size comes from each item's entry.
        spec[3] = 0;
        let pipeline = |name: &str, spirv: &[u32]| hash_pipeline(ctx, name, spirv, &spec);
        Ok(MixedPasses {
            claim: pipeline("hash mixed search and claim", shaders::HASH_CLAIM)?,
            insert: pipeline("hash mixed insert", shaders::HASH_INSERT)?,
            claim_insert: pipeline(
                "hash mixed search, claim and insert",
                shaders::HASH_CLAIM_INSERT,
            )?,
            items_per_group: table.items_per_group(),
            max_groups: ctx.info().max_compute_workgroup_count[0],
        })
    }

    /// The three pipelines (to warm ahead: [`crate::gpu::Commands::warm`]).
    pub fn pipelines(&self) -> [&ComputePipeline; 3] {
        [&self.claim, &self.insert, &self.claim_insert]
    }

    /// The largest batch one workgroup takes (its grid stride): such a batch gets the fused
    /// pass.
    fn one_group_bound(&self) -> u32 {
        self.items_per_group * ITEMS_PER_INVOCATION
    }

    /// The parameters of a mixed batch of at most `bound` items whose entries lie in `entries`
    /// and sizes' counts at byte `counts_offset` of `counts` (the passes' push constants; a
    /// shader running several batches reads them from memory).
    pub fn batch(entries: &Buffer, counts: &Buffer, counts_offset: u64, bound: u32) -> HashPush {
        HashPush {
            count: bound,
            count_at: counts.address() + counts_offset,
            mixed: entries.address(),
            ..HashPush::default()
        }
    }

    /// Records the search-and-claim pass and the claimed insert round of a mixed batch of at
    /// most `bound` items (profiled as "hash search and claim" and "hash insert"), each
    /// followed by a barrier; a batch that one workgroup takes gets both in one dispatch
    /// (profiled as "hash search, claim and insert"). `entries` holds [`MIXED_SIZES`] entries
    /// ([`GpuHashTable::claimed_entry`]; a size without items may hold any entry), `counts` the
    /// sizes' item counts ([`MIXED_SIZES`] `u32`s from byte `counts_offset`). Clear the claim
    /// tables before; check each table's status around the submission after
    /// ([`GpuHashTable::check_inserts`]): items a full pool left out keep `HANDLE_MISS`.
    pub fn record<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        entries: &'a Buffer,
        counts: &'a Buffer,
        counts_offset: u64,
        bound: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), HashError> {
        let entry_bytes = std::mem::size_of::<HashPush>() as u64;
        if entries.size() < MIXED_SIZES as u64 * entry_bytes
            || counts_offset + 4 * MIXED_SIZES as u64 > counts.size()
        {
            return Err(HashError::InvalidArgument(format!(
                "mixed batch: '{}' must hold {MIXED_SIZES} entries and '{}' {MIXED_SIZES} counts \
                 from byte {counts_offset}",
                entries.name(),
                counts.name()
            )));
        }
        if bound == 0 {
            return Ok(());
        }
        let push = Self::batch(entries, counts, counts_offset, bound);
        let groups = bound
            .div_ceil(self.one_group_bound())
            .clamp(1, self.max_groups);
        let passes: &[(&str, &ComputePipeline)] = if groups == 1 {
            &[("hash search, claim and insert", &self.claim_insert)]
        } else {
            &[
                ("hash search and claim", &self.claim),
                ("hash insert", &self.insert),
            ]
        };
        for &(name, pipeline) in passes {
            cmd.begin_pass(&mut profiler, name);
            cmd.dispatch(pipeline, [groups, 1, 1], bytemuck::bytes_of(&push), &[])?;
            cmd.end_pass(&mut profiler);
            cmd.barrier();
        }
        Ok(())
    }
}
