//! The duplicate-detection table of a temporary SVO (dissertation §4.4.2): a batch of keys (items
//! of `key_words` words, e.g. new nodes) with a `u32` value each (e.g. the temporary node id) is
//! reduced to one representative per distinct key, the smallest value among the inputs with that
//! key, and every input learns its representative.
//!
//! Three GPU passes over a table that lives for one batch (`shaders/glsl/hash/dedup_*.comp`,
//! layouts in `dedup_common.glsl`, mirrored by [`DedupLayout`]).
//! One team per input in passes 1 and 2: the whole subgroup or a single lane ([`TeamMode`]).
//! Subgroup teams use a slab table (the dissertation's: 32 slots scanned by 32 lanes at once):
//! 1. insert: each input checks its bucket's first slab for an equal key (the cheap duplicate
//!    check) and otherwise inserts its key; duplicates the check misses are inserted again;
//! 2. min: each input finds the first entry with its key along the chain (the same entry for all
//!    equal keys) and folds its value into that entry's minimum;
//! 3. resolve: each input reads its entry's minimum.
//!
//! Single lanes (CPU devices) use a probe table: open addressing with linear probing, the key's
//! hash in the tag, at least twice as many slots as inputs. The passes are the same, along a
//! probe sequence instead of a chain; a lane reads one tag per probe and compares keys only on
//! an equal hash (on lavapipe the slab scan's loop of tag and key loads cost ~5x more).
//!
//! The result is deterministic (the minimum over all equal keys) although the table's contents
//! are not; [`dedup_cpu`] is the reference. The slab table's overflow slabs come from a bump
//! pool sized for the worst case; if it still runs out the batch is run again with a bigger
//! pool (never a wrong answer). The probe table cannot run out.

use std::sync::Arc;

use rustc_hash::FxHashMap;

use super::gpu_shared::DedupPush;
use super::layout::murmur_words;
use super::TeamMode;
use crate::gpu::{
    shaders, Buffer, BufferSlice, Commands, ComputePipeline, ComputePipelineDesc, DeviceType,
    GpuContext, GpuError, MemLocation, Profiler, Readback,
};

/// Most workgroups one dedup dispatch launches (the passes loop over the rest).
const MAX_WORKGROUPS: u32 = 65_535;
/// Largest key size the dedup table accepts, in 32-bit words.
pub const MAX_KEY_WORDS: u32 = 32;
/// Slots per slab.
const SLOTS: u64 = 32;

/// Errors of the duplicate-detection table.
#[derive(Debug, thiserror::Error)]
pub enum DedupError {
    /// The GPU layer failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// Inputs the table cannot take (sizes, lengths).
    #[error("invalid dedup input: {0}")]
    InvalidInput(String),
    /// The table lost track of a key (a bug, reported instead of a wrong answer).
    #[error("dedup table inconsistent: {0}")]
    Inconsistent(String),
}

/// Representatives of a batch: `representatives[i]` is the smallest value among the inputs whose
/// key equals key `i`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DedupOutput {
    /// One representative value per input.
    pub representatives: Vec<u32>,
    /// Table entries made (distinct keys plus the duplicates written at the same time, or
    /// missed by the slab table's first-slab check).
    pub entries: u32,
    /// Times the batch ran (more than 1 when the overflow pool had to grow).
    pub attempts: u32,
}

/// CPU reference: for every input, the smallest value among the inputs with an equal key.
pub fn dedup_cpu(keys: &[u32], key_words: usize, values: &[u32]) -> Result<Vec<u32>, DedupError> {
    check_input(keys.len(), key_words, values.len())?;
    let mut smallest: FxHashMap<&[u32], u32> = FxHashMap::default();
    for (key, &value) in keys.chunks_exact(key_words).zip(values) {
        smallest
            .entry(key)
            .and_modify(|v| *v = (*v).min(value))
            .or_insert(value);
    }
    Ok(keys.chunks_exact(key_words).map(|k| smallest[k]).collect())
}

/// Checks key size and input lengths.
fn check_input(key_len: usize, key_words: usize, values: usize) -> Result<(), DedupError> {
    if key_words == 0 || key_words > MAX_KEY_WORDS as usize {
        return Err(DedupError::InvalidInput(format!(
            "key size {key_words} words is outside 1..={MAX_KEY_WORDS}"
        )));
    }
    if key_len != values * key_words {
        return Err(DedupError::InvalidInput(format!(
            "{key_len} key words for {values} values of {key_words}-word keys"
        )));
    }
    if values >= u32::MAX as usize {
        return Err(DedupError::InvalidInput(format!(
            "{values} inputs is too many"
        )));
    }
    Ok(())
}

/// Word layout of the dedup table (mirror of `dedup_common.glsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DedupLayout {
    /// Key size in words.
    pub key_words: u32,
    /// The probe table (single lanes) instead of the slab table (subgroup teams).
    pub probe: bool,
}

impl DedupLayout {
    /// Words of one slab: 32 tags, 32 values, 32 keys, the next-slab index.
    pub fn slab_words(self) -> u64 {
        2 * SLOTS + SLOTS * self.key_words as u64 + 1
    }

    /// Buckets for a batch of `count` inputs: about 16 keys per bucket, so that most keys'
    /// duplicates are in the bucket's first slab.
    pub fn buckets(count: u32) -> u32 {
        count.div_ceil(16).max(1)
    }

    /// Overflow slabs that always suffice when no slab is wasted by a lost link race: every
    /// overflow slab but a bucket's last is full, and a bucket with one holds at least 33 entries.
    pub fn pool_slabs(count: u32) -> u32 {
        count / 32 + count / 33 + 1
    }

    /// Slots of the probe table for `count` inputs: a power of two, at least twice the inputs
    /// (linear probing then walks ~1.5 slots on average to a key's copy); `None` past 2^31.
    pub fn probe_slots(count: u32) -> Option<u32> {
        (2 * count.max(1) as u64)
            .checked_next_power_of_two()
            .and_then(|slots| u32::try_from(slots).ok())
    }

    /// [`DedupLayout::probe_slots`] for this key size, `None` also when the table's words would
    /// not fit the shaders' 32-bit indices.
    pub fn fitting_probe_slots(self, count: u32) -> Option<u32> {
        Self::probe_slots(count).filter(|&slots| self.probe_words(slots) <= u32::MAX as u64)
    }

    /// Words of the probe table with `slots` slots: tags, values (the zeroed part), keys.
    pub fn probe_words(self, slots: u32) -> u64 {
        slots as u64 * (2 + self.key_words as u64)
    }
}

/// Hash of a key (the same function as `hash_key` in `dedup_common.glsl`).
pub fn hash_key(key: &[u32]) -> u32 {
    murmur_words(0x9e37_79b9, key)
}

/// Counters written by the passes (`counters[]` in `dedup_common.glsl`).
const COUNTER_POOL_USED: usize = 0;
const COUNTER_ENTRIES: usize = 1;
const COUNTER_OVERFLOW: usize = 2;

/// Scratch buffers of one dedup batch: the table (slabs: buckets + overflow pool; probe: slots),
/// the canonical entry of every input and the counters.
#[derive(Debug)]
pub struct DedupScratch {
    table: Buffer,
    canon: Buffer,
    counters: Buffer,
    count: u32,
    /// Slab table: buckets; probe table: slots.
    buckets: u32,
    /// Slab table: overflow slabs; probe table: 0.
    pool_slabs: u32,
}

impl DedupScratch {
    /// Overflow slabs of the table's pool.
    pub fn pool_slabs(&self) -> u32 {
        self.pool_slabs
    }
}

/// A batch recorded by [`GpuDedup::record_dedup`]: its counters, read by
/// [`GpuDedup::finish_dedup`] after the submission.
#[derive(Debug)]
pub struct PendingDedup {
    counters: Readback<u32>,
    pool_slabs: u32,
}

/// What [`GpuDedup::finish_dedup`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DedupResult {
    /// The representatives are written; this many table entries were made.
    Done {
        /// Table entries made.
        entries: u32,
    },
    /// The overflow pool ran out: run the batch again with scratch of this many pool slabs.
    Retry {
        /// Pool slabs for the next attempt.
        pool_slabs: u32,
    },
}

/// GPU duplicate detection for keys of one size: the three compiled passes.
pub struct GpuDedup {
    ctx: Arc<GpuContext>,
    layout: DedupLayout,
    /// Invocations per workgroup (specialization constant 0): one subgroup with subgroup teams,
    /// `max(64, subgroup)` with single lanes.
    workgroup: u32,
    /// Lanes working on one input (specialization constant 2): the subgroup size or 1.
    team: u32,
    /// Overflow pool of the first attempt (slab table); `None`: [`DedupLayout::pool_slabs`].
    initial_pool: Option<u32>,
    /// Bucket count (slab table); `None`: [`DedupLayout::buckets`].
    buckets: Option<u32>,
    insert: ComputePipeline,
    min: ComputePipeline,
    resolve: ComputePipeline,
}

impl GpuDedup {
    /// Compiles the passes for keys of `key_words` words (1..=[`MAX_KEY_WORDS`]) with the
    /// device's team mode ([`TeamMode::Auto`]).
    pub fn new(ctx: &Arc<GpuContext>, key_words: u32) -> Result<GpuDedup, DedupError> {
        GpuDedup::with_team(ctx, key_words, TeamMode::Auto)
    }

    /// Compiles the passes for keys of `key_words` words with `team` lanes per input (the whole
    /// subgroup, or a single lane: see [`TeamMode`]).
    pub fn with_team(
        ctx: &Arc<GpuContext>,
        key_words: u32,
        team: TeamMode,
    ) -> Result<GpuDedup, DedupError> {
        if key_words == 0 || key_words > MAX_KEY_WORDS {
            return Err(DedupError::InvalidInput(format!(
                "key size {key_words} words is outside 1..={MAX_KEY_WORDS}"
            )));
        }
        let subgroup = ctx.info().subgroup_size.max(1);
        let single_lane = match team {
            TeamMode::Auto => ctx.info().device_type == DeviceType::Cpu,
            TeamMode::Subgroup => false,
            TeamMode::SingleLane => true,
        };
        // Subgroup teams: one subgroup per workgroup (on lavapipe, Mesa 22.3, a workgroup whose
        // subgroups leave the pass at different times gave wrong ballots). Single lanes use no
        // subgroup operation, so any workgroup size works.
        let (workgroup, team) = if single_lane {
            (subgroup.max(64), 1)
        } else {
            (subgroup, subgroup)
        };
        let spec = [workgroup, key_words, team];
        let pipeline = |name: &str, spirv: &[u32]| {
            ctx.create_compute_pipeline(&ComputePipelineDesc {
                name,
                spirv,
                spec_constants: &spec,
                push_constant_size: std::mem::size_of::<DedupPush>() as u32,
                bindings: &[],
            })
        };
        Ok(GpuDedup {
            ctx: Arc::clone(ctx),
            layout: DedupLayout {
                key_words,
                probe: team == 1,
            },
            workgroup,
            team,
            initial_pool: None,
            buckets: None,
            insert: pipeline("dedup insert", shaders::HASH_DEDUP_INSERT)?,
            min: pipeline("dedup min", shaders::HASH_DEDUP_MIN)?,
            resolve: pipeline("dedup resolve", shaders::HASH_DEDUP_RESOLVE)?,
        })
    }

    /// Starts every batch with an overflow pool of `slabs` slabs instead of the worst-case
    /// estimate (a too-small pool makes the batch run again with a bigger one). Slab table
    /// only: the probe table has no pool.
    pub fn with_initial_pool(mut self, slabs: u32) -> GpuDedup {
        self.initial_pool = Some(slabs);
        self
    }

    /// Uses `buckets` buckets (at least 1) instead of one per 16 inputs: fewer buckets make
    /// longer chains and more duplicates that the first-slab check misses. Slab table only.
    pub fn with_buckets(mut self, buckets: u32) -> GpuDedup {
        self.buckets = Some(buckets.max(1));
        self
    }

    /// Lanes working on one input: the subgroup size, or 1 (see [`TeamMode`]).
    pub fn team_size(&self) -> u32 {
        self.team
    }

    /// The table layout of this dedup.
    pub fn layout(&self) -> DedupLayout {
        self.layout
    }

    /// Whether a batch always finishes in one attempt (the probe table, which cannot run out):
    /// its dedup can share a submission with what reads the representatives.
    pub fn never_retries(&self) -> bool {
        self.layout.probe
    }

    /// Uploads `keys` (`values.len()` keys of `key_words` words) and `values`, runs the passes and
    /// reads the representatives back: one submission, one host wait (more only when the
    /// overflow pool runs out).
    pub fn dedup(
        &self,
        keys: &[u32],
        values: &[u32],
        profiler: Option<&mut Profiler>,
    ) -> Result<DedupOutput, DedupError> {
        check_input(keys.len(), self.layout.key_words as usize, values.len())?;
        if values.is_empty() {
            return Ok(DedupOutput {
                representatives: Vec::new(),
                entries: 0,
                attempts: 0,
            });
        }
        let count = values.len() as u32;
        let key_buf =
            self.ctx
                .create_buffer("dedup keys", keys.len() as u64 * 4, MemLocation::GpuOnly)?;
        let value_buf =
            self.ctx
                .create_buffer("dedup values", count as u64 * 4, MemLocation::GpuOnly)?;
        let reps = self.ctx.create_buffer(
            "dedup representatives",
            count as u64 * 4,
            MemLocation::GpuOnly,
        )?;
        let (entries, attempts, out) = self.dedup_flow(
            (&key_buf).into(),
            &value_buf,
            count,
            (&reps).into(),
            Some((keys, values)),
            profiler,
        )?;
        Ok(DedupOutput {
            representatives: out.unwrap_or_default(),
            entries,
            attempts,
        })
    }

    /// Runs the passes on GPU buffers: `count` keys and values in, `count` representatives out.
    /// Returns the table entries made and the attempts needed (one submission and one host wait
    /// per attempt).
    pub fn dedup_buffers<'a>(
        &self,
        keys: impl Into<BufferSlice<'a>>,
        values: &Buffer,
        count: u32,
        reps: impl Into<BufferSlice<'a>>,
        profiler: Option<&mut Profiler>,
    ) -> Result<(u32, u32), DedupError> {
        self.dedup_flow(keys.into(), values, count, reps.into(), None, profiler)
            .map(|(e, a, _)| (e, a))
    }

    /// Scratch for a batch of `count` inputs with `pool_slabs` overflow slabs (slab table;
    /// `None`: the configured initial pool, else the worst-case estimate
    /// [`DedupLayout::pool_slabs`]). The probe table ignores `pool_slabs`.
    pub fn scratch(&self, count: u32, pool_slabs: Option<u32>) -> Result<DedupScratch, DedupError> {
        let n = count.max(1) as u64;
        let (buckets, pool_slabs, table_bytes) = if self.layout.probe {
            let slots = self.layout.fitting_probe_slots(count).ok_or_else(|| {
                DedupError::InvalidInput(format!(
                    "{count} inputs of {} words are too many for one probe table",
                    self.layout.key_words
                ))
            })?;
            (slots, 0, self.layout.probe_words(slots) * 4)
        } else {
            let buckets = self.buckets.unwrap_or_else(|| DedupLayout::buckets(count));
            let pool_slabs = pool_slabs
                .or(self.initial_pool)
                .unwrap_or_else(|| DedupLayout::pool_slabs(count));
            let bytes = (buckets as u64 + pool_slabs as u64) * self.layout.slab_words() * 4;
            (buckets, pool_slabs, bytes)
        };
        Ok(DedupScratch {
            table: self
                .ctx
                .create_buffer("dedup table", table_bytes, MemLocation::GpuOnly)?,
            canon: self
                .ctx
                .create_buffer("dedup canon", n * 4, MemLocation::GpuOnly)?,
            counters: self
                .ctx
                .create_buffer("dedup counters", 16, MemLocation::GpuOnly)?,
            count,
            buckets,
            pool_slabs,
        })
    }

    /// Records the three passes of a batch into `cmd` (profiled as "dedup insert" and "dedup
    /// representatives") and a readback of the counters; finish with
    /// [`GpuDedup::finish_dedup`] after the submission.
    #[allow(clippy::too_many_arguments)]
    pub fn record_dedup<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        keys: impl Into<BufferSlice<'a>>,
        values: &'a Buffer,
        count: u32,
        reps: impl Into<BufferSlice<'a>>,
        scratch: &'a DedupScratch,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<PendingDedup, DedupError> {
        let (keys, reps) = (keys.into(), reps.into());
        let key_words = self.layout.key_words as u64;
        let n = count as u64;
        for (buffer, words) in [(keys, n * key_words), (values.into(), n), (reps, n)] {
            if buffer.size() < words * 4 {
                return Err(DedupError::InvalidInput(format!(
                    "buffer '{}' has {} bytes, needs {}",
                    buffer.name(),
                    buffer.size(),
                    words * 4
                )));
            }
        }
        if scratch.count < count {
            return Err(DedupError::InvalidInput(format!(
                "scratch for {} inputs used for {count}",
                scratch.count
            )));
        }
        let push = DedupPush {
            keys: keys.address(),
            values: values.address(),
            table: scratch.table.address(),
            canon: scratch.canon.address(),
            reps: reps.address(),
            counters: scratch.counters.address(),
            count,
            buckets: scratch.buckets,
            pool_slabs: scratch.pool_slabs,
            slab_words: self.layout.slab_words() as u32,
        };
        let teams_per_group = self.workgroup / self.team;
        let per_team = [count.div_ceil(teams_per_group).min(MAX_WORKGROUPS), 1, 1];
        let per_invocation = [count.div_ceil(self.workgroup).min(MAX_WORKGROUPS), 1, 1];
        // The slab table starts zeroed; of the probe table only the tags and values (the key
        // words are read only where a published tag says they were written).
        let zeroed_bytes = if self.layout.probe {
            2 * scratch.buckets as u64 * 4
        } else {
            scratch.table.size()
        };
        cmd.fill_range(&scratch.table, 0, zeroed_bytes, 0)?;
        cmd.fill_buffer(&scratch.counters, 0);
        if let Some(p) = profiler.as_deref_mut() {
            p.begin_pass(cmd, "dedup insert");
        }
        cmd.dispatch(&self.insert, per_team, bytemuck::bytes_of(&push), &[])?;
        if let Some(p) = profiler.as_deref_mut() {
            p.end_pass(cmd);
        }
        cmd.barrier();
        if let Some(p) = profiler.as_deref_mut() {
            p.begin_pass(cmd, "dedup representatives");
        }
        cmd.dispatch(&self.min, per_team, bytemuck::bytes_of(&push), &[])?;
        cmd.barrier();
        cmd.dispatch(
            &self.resolve,
            per_invocation,
            bytemuck::bytes_of(&push),
            &[],
        )?;
        if let Some(p) = profiler {
            p.end_pass(cmd);
        }
        cmd.barrier();
        Ok(PendingDedup {
            counters: cmd.readback::<u32>(&scratch.counters, 0, 3)?,
            pool_slabs: scratch.pool_slabs,
        })
    }

    /// Reads a recorded batch's counters once its submission was made (waits if needed): done,
    /// or the overflow pool ran out and the batch must run again with a bigger one.
    pub fn finish_dedup(
        &self,
        pending: PendingDedup,
        count: u32,
    ) -> Result<DedupResult, DedupError> {
        let state = pending.counters.read()?;
        let pool_slabs = pending.pool_slabs;
        // Bit 0: the pool ran out in pass 1 (pass 2 then also misses keys: bit 1).
        // Bit 1 alone: a key without an entry, which pass 1 never leaves behind.
        let overflow = state[COUNTER_OVERFLOW];
        if overflow == 0 {
            return Ok(DedupResult::Done {
                entries: state[COUNTER_ENTRIES],
            });
        }
        if self.layout.probe {
            // The probe table has twice as many slots as inputs: no walk reaches its end.
            return Err(DedupError::Inconsistent(format!(
                "overflow state {overflow} in a probe table of {count} inputs"
            )));
        }
        // Bit 2: a chain walk was cut off (longer than the table: a loop, never a hang).
        // Every input links at most one slab per entry it makes and wastes at most one, so a
        // pool of 2 * count slabs never runs out.
        if overflow & 1 == 0 || overflow & 4 != 0 || pool_slabs >= 2 * count {
            return Err(DedupError::Inconsistent(format!(
                "overflow state {overflow} with a pool of {pool_slabs} slabs"
            )));
        }
        log::debug!(
            "dedup: pool of {pool_slabs} slabs ran out ({} taken), growing",
            state[COUNTER_POOL_USED]
        );
        Ok(DedupResult::Retry {
            pool_slabs: pool_slabs.saturating_mul(2).min(2 * count),
        })
    }

    /// Attempts until the pool suffices; the first uploads the host data when given and every
    /// attempt reads the representatives back in its own submission when it uploaded.
    fn dedup_flow(
        &self,
        keys: BufferSlice<'_>,
        values: &Buffer,
        count: u32,
        reps: BufferSlice<'_>,
        upload: Option<(&[u32], &[u32])>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(u32, u32, Option<Vec<u32>>), DedupError> {
        if count == 0 {
            return Ok((0, 0, upload.map(|_| Vec::new())));
        }
        let mut pool_slabs = None;
        let mut attempt = 0;
        loop {
            attempt += 1;
            let scratch = self.scratch(count, pool_slabs)?;
            let mut cmd = self.ctx.begin_commands("dedup")?;
            if let (Some((k, v)), 1) = (upload, attempt) {
                cmd.upload(keys.buffer(), keys.offset(), k)?;
                cmd.upload(values, 0, v)?;
            }
            let pending = self.record_dedup(
                &mut cmd,
                keys,
                values,
                count,
                reps,
                &scratch,
                profiler.as_deref_mut(),
            )?;
            let back = match upload {
                Some(_) => {
                    Some(cmd.readback::<u32>(reps.buffer(), reps.offset(), count as usize)?)
                }
                None => None,
            };
            cmd.submit_async()?;
            let result = self.finish_dedup(pending, count)?;
            if let Some(p) = profiler.as_deref_mut() {
                p.resolve()?;
            }
            match result {
                DedupResult::Done { entries } => {
                    let out = match back {
                        Some(b) => Some(b.read()?),
                        None => None,
                    };
                    return Ok((entries, attempt, out));
                }
                DedupResult::Retry { pool_slabs: p } => pool_slabs = Some(p),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::DedupLayout;

    #[test]
    fn probe_tables_have_a_power_of_two_of_at_least_twice_the_inputs() {
        assert_eq!(DedupLayout::probe_slots(0), Some(2));
        assert_eq!(DedupLayout::probe_slots(1), Some(2));
        assert_eq!(DedupLayout::probe_slots(3), Some(8));
        assert_eq!(DedupLayout::probe_slots(1024), Some(2048));
        assert_eq!(DedupLayout::probe_slots(1025), Some(4096));
        assert_eq!(DedupLayout::probe_slots(1 << 30), Some(1 << 31));
        // 2^32 slots do not fit the shaders' 32-bit slot count.
        assert_eq!(DedupLayout::probe_slots((1 << 30) + 1), None);
        assert_eq!(DedupLayout::probe_slots(u32::MAX), None);
        let layout = DedupLayout {
            key_words: 10,
            probe: true,
        };
        assert_eq!(layout.probe_words(8), 96);
    }
}
