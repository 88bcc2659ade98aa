//! Streaming SVDAG construction (`docs/scaling.md`): voxels arrive in ascending Morton order
//! (the voxelizer's bricks) and every node is completed and deduplicated as soon as its last
//! child is known, so only the path of incomplete nodes (one per level) is held besides the
//! DAG itself. Colours go the same way into the chunk encoders ([`ColorStream`]), whose words
//! wait in a spill file until the `.vdag` is written ([`save_streamed`]).
//!
//! Node ids are the order of first occurrence in Morton order on every level, exactly as in
//! [`Svdag::from_voxels`] (a level's nodes complete in ascending key order), so the laid-out
//! DAG, and the file, are byte-identical to the in-memory build's.

use std::cell::{Cell, RefCell};
use std::fs::File;
use std::io::{self, BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::build::{push_node, LevelNodes};
use super::digest::{empty_hash, inner_hash, leaf_hash, ColorsHasher, ContentDigest};
use super::encode::{EncodedDag, VoxelDigest};
use super::{DagError, Svdag, MAX_RESOLUTION};
use crate::attr::chunks::MAX_CHUNK_COLORS;
use crate::attr::{self, ColorCodec};

/// A deduplication table of one level: open addressing over node ids, each slot the id + 1
/// (0 = empty) with 32 bits of the node's hash above it, so a probe rarely touches the node
/// words. About 8-16 bytes per node instead of a map that stores the keys.
struct IdTable {
    slots: Vec<u64>,
    len: usize,
}

/// The words of node `id` of `level` (leaves: 2 words; inner: mask + one id per child).
fn node_words(level: &LevelNodes, id: u32, leaf: bool) -> &[u32] {
    let at = level.offsets[id as usize] as usize;
    let len = if leaf {
        2
    } else {
        1 + level.words[at].count_ones() as usize
    };
    &level.words[at..at + len]
}

/// 64-bit hash of a node's words (FxHash steps, splitmix finaliser).
fn hash_words(words: &[u32]) -> u64 {
    let mut h = words.len() as u64;
    for &w in words {
        h = (h.rotate_left(5) ^ w as u64).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^ (h >> 31)
}

impl IdTable {
    fn new() -> IdTable {
        IdTable {
            slots: vec![0; 1024],
            len: 0,
        }
    }

    /// First slot to probe for `hash` in a table of `slots` (a power of two).
    fn home(hash: u64, slots: usize) -> usize {
        (hash >> (64 - slots.trailing_zeros())) as usize
    }

    /// The id of `node` in `level`, appending it when new; `Ok((id, true))` for a new node.
    fn find_or_insert(
        &mut self,
        level: &mut LevelNodes,
        node: &[u32],
        leaf: bool,
    ) -> Result<(u32, bool), DagError> {
        if (self.len + 1) * 4 > self.slots.len() * 3 {
            self.grow(level, leaf);
        }
        let hash = hash_words(node);
        let tag = hash as u32 as u64;
        let mask = self.slots.len() - 1;
        let mut i = Self::home(hash, self.slots.len());
        loop {
            let slot = self.slots[i];
            if slot == 0 {
                let id = push_node(level, node)?;
                self.slots[i] = tag << 32 | (id as u64 + 1);
                self.len += 1;
                return Ok((id, true));
            }
            if slot >> 32 == tag {
                let id = (slot as u32) - 1;
                if node_words(level, id, leaf) == node {
                    return Ok((id, false));
                }
            }
            i = (i + 1) & mask;
        }
    }

    /// Doubles the table, re-inserting every node of `level`.
    fn grow(&mut self, level: &LevelNodes, leaf: bool) {
        let size = self.slots.len() * 2;
        let mut slots = vec![0u64; size];
        for id in 0..level.offsets.len() as u32 {
            let hash = hash_words(node_words(level, id, leaf));
            let mut i = Self::home(hash, size);
            while slots[i] != 0 {
                i = (i + 1) & (size - 1);
            }
            slots[i] = (hash as u32 as u64) << 32 | (id as u64 + 1);
        }
        self.slots = slots;
    }
}

/// A node whose children are not all known yet: its key (`code >> (6 + 3 level)`), child
/// mask and child ids so far (`n` - 1 of them; `n == 0`: no open node at this level).
#[derive(Clone, Copy, Default)]
struct OpenNode {
    key: u64,
    node: [u32; 9],
    n: usize,
}

/// Bottom-up SVDAG builder fed with ascending Morton codes (see the module docs).
pub struct StreamBuilder {
    resolution: u32,
    root_level: u32,
    cells: u64,
    levels: Vec<LevelNodes>,
    tables: Vec<IdTable>,
    /// Open node per level (index 0 unused: the open leaf is `leaf_key`/`leaf_mask`).
    open: Vec<OpenNode>,
    leaf_key: u64,
    leaf_mask: u64,
    last: Option<u64>,
    voxels: u64,
    root: Option<u32>,
    /// Level whose completed nodes are kept in `tops` instead of going to a parent (the root
    /// level for a whole build, the split level for a part: `partition`).
    top: u32,
    /// Completed nodes of level `top` below the root: key and id, ascending keys.
    tops: SubtreeRoots,
}

/// Subtree roots of a part: key and node id on the top level, ascending keys.
pub(super) type SubtreeRoots = Vec<(u64, u32)>;

/// What a finished [`StreamBuilder`] yields.
pub struct StreamedDag {
    /// The SVDAG, without colours (they went to a [`ColorStream`]).
    pub dag: Svdag,
    /// Voxels pushed.
    pub voxels: u64,
    /// Hash lanes of the canonical DAG (section 7's DAG hash), computed bottom-up.
    pub dag_hash: [u64; 2],
}

impl StreamBuilder {
    /// A builder for a grid of side `resolution` (a power of two in `8..=2^21`).
    pub fn new(resolution: u32) -> Result<StreamBuilder, DagError> {
        Self::with_top(resolution, u32::MAX)
    }

    /// A builder whose completed nodes of level `top` (at most the root level) are kept as
    /// subtree roots (`partition`): the levels above it are not built.
    pub(super) fn with_top(resolution: u32, top: u32) -> Result<StreamBuilder, DagError> {
        if !resolution.is_power_of_two() || !(8..=MAX_RESOLUTION).contains(&resolution) {
            return Err(DagError::InvalidResolution(resolution));
        }
        let root_level = resolution.trailing_zeros() - 2;
        let levels = root_level as usize + 1;
        Ok(StreamBuilder {
            resolution,
            root_level,
            cells: (resolution as u64).pow(3),
            levels: (0..levels).map(|_| LevelNodes::default()).collect(),
            tables: (0..levels).map(|_| IdTable::new()).collect(),
            open: vec![OpenNode::default(); levels],
            leaf_key: 0,
            leaf_mask: 0,
            last: None,
            voxels: 0,
            root: None,
            top: top.min(root_level),
            tops: Vec::new(),
        })
    }

    /// Adds the next voxels (Morton codes, strictly ascending across all calls).
    pub fn push(&mut self, codes: &[u64]) -> Result<(), DagError> {
        for &code in codes {
            if self.last.is_some_and(|last| code <= last) || code >= self.cells {
                return Err(DagError::InvalidVoxels(format!(
                    "Morton code {code} at voxel {}: not strictly ascending or outside the {}^3 grid",
                    self.voxels, self.resolution
                )));
            }
            self.last = Some(code);
            let key = code >> 6;
            if self.leaf_mask != 0 && key != self.leaf_key {
                self.close_leaf()?;
            }
            self.leaf_key = key;
            self.leaf_mask |= 1u64 << (code & 63);
            self.voxels += 1;
        }
        Ok(())
    }

    /// Bytes the builder holds now (capacities of the node words, offsets and tables).
    pub fn memory_bytes(&self) -> u64 {
        let levels: usize = self
            .levels
            .iter()
            .map(|l| 4 * (l.words.capacity() + l.offsets.capacity()))
            .sum();
        let tables: usize = self.tables.iter().map(|t| 8 * t.slots.capacity()).sum();
        (levels + tables) as u64
    }

    /// Peak bytes of [`StreamBuilder::finish`] (an upper bound): the level words and offsets
    /// (trimmed to their length), two levels' content hashes, then the laid-out copy of the
    /// words (the tables are freed first).
    pub fn layout_bytes(&self) -> u64 {
        let levels: usize = self
            .levels
            .iter()
            .map(|l| 8 * l.words.len() + 4 * l.offsets.len())
            .sum();
        let hashes = self
            .levels
            .windows(2)
            .map(|w| 16 * (w[0].offsets.len() + w[1].offsets.len()))
            .max()
            .unwrap_or(0);
        (levels + hashes) as u64
    }

    /// Voxels pushed so far.
    pub fn voxels(&self) -> u64 {
        self.voxels
    }

    /// Unique nodes stored so far, all levels.
    pub fn nodes(&self) -> u64 {
        self.levels.iter().map(|l| l.offsets.len() as u64).sum()
    }

    fn close_leaf(&mut self) -> Result<(), DagError> {
        let mask = std::mem::take(&mut self.leaf_mask);
        let id = self.dedup(0, &[mask as u32, (mask >> 32) as u32])?;
        self.completed(0, self.leaf_key, id)
    }

    /// Hands the completed node `id` (with `key`) of `level` to its parent, or keeps it when
    /// `level` is the top level.
    pub(super) fn completed(&mut self, level: u32, key: u64, id: u32) -> Result<(), DagError> {
        if level == self.root_level {
            self.root = Some(id);
            Ok(())
        } else if level == self.top {
            self.tops.push((key, id));
            Ok(())
        } else {
            self.add_child(level + 1, key, id)
        }
    }

    /// Adds node `id` with key `child_key` (one level down) to the open node of `level`,
    /// closing that node first when `child_key` belongs to another parent.
    fn add_child(&mut self, level: u32, child_key: u64, id: u32) -> Result<(), DagError> {
        let key = child_key >> 3;
        let l = level as usize;
        if self.open[l].n > 0 && self.open[l].key != key {
            self.close(level)?;
        }
        let open = &mut self.open[l];
        if open.n == 0 {
            *open = OpenNode {
                key,
                node: [0; 9],
                n: 1,
            };
        }
        open.node[0] |= 1 << (child_key & 7);
        open.node[open.n] = id;
        open.n += 1;
        Ok(())
    }

    /// Completes the open node of `level`: deduplicates it and hands it to its parent.
    fn close(&mut self, level: u32) -> Result<(), DagError> {
        let open = std::mem::take(&mut self.open[level as usize]);
        let id = self.dedup(level, &open.node[..open.n])?;
        self.completed(level, open.key, id)
    }

    /// The id of `node` on `level`, storing it when new.
    pub(super) fn dedup(&mut self, level: u32, node: &[u32]) -> Result<u32, DagError> {
        let l = level as usize;
        Ok(self.tables[l]
            .find_or_insert(&mut self.levels[l], node, level == 0)?
            .0)
    }

    /// Content-digest hash lanes of the root (`docs/vdag-format.md`), bottom-up over the
    /// stored nodes with only two levels' hashes held at a time.
    fn root_hash(&self, root: u32) -> [u64; 2] {
        let mut below: Vec<[u64; 2]> = Vec::new();
        for (l, level) in self.levels.iter().enumerate() {
            let hashes = level
                .offsets
                .iter()
                .map(|&at| {
                    let at = at as usize;
                    if l == 0 {
                        leaf_hash(level.words[at] as u64 | (level.words[at + 1] as u64) << 32)
                    } else {
                        let mask = level.words[at];
                        let children = &level.words[at + 1..at + 1 + mask.count_ones() as usize];
                        inner_hash(l as u32, mask, children.iter().map(|&c| below[c as usize]))
                    }
                })
                .collect();
            below = hashes;
        }
        below[root as usize]
    }

    /// Closes the open nodes up to the top level.
    fn close_path(&mut self) -> Result<(), DagError> {
        if self.leaf_mask != 0 {
            self.close_leaf()?;
        }
        for level in 1..=self.top {
            if self.open[level as usize].n > 0 {
                self.close(level)?;
            }
        }
        Ok(())
    }

    /// Closes the open path and returns the levels up to the top level (its nodes' ids kept
    /// in `tops`, or the root when the top is the root level), not laid out: a part of a
    /// partitioned build.
    pub(super) fn finish_levels(mut self) -> Result<(Vec<LevelNodes>, SubtreeRoots), DagError> {
        self.close_path()?;
        let mut tops = std::mem::take(&mut self.tops);
        if let Some(root) = self.root {
            tops.push((0, root));
        }
        self.levels.truncate(self.top as usize + 1);
        Ok((self.levels, tops))
    }

    /// Voxels fed outside [`StreamBuilder::push`] (a merged part's).
    pub(super) fn add_voxels(&mut self, voxels: u64) {
        self.voxels += voxels;
    }

    /// Closes the open path and lays the DAG out (as [`Svdag::from_voxels`] does).
    pub fn finish(mut self) -> Result<StreamedDag, DagError> {
        self.top = self.root_level;
        self.close_path()?;
        self.tables = Vec::new();
        for level in &mut self.levels {
            level.words.shrink_to_fit();
            level.offsets.shrink_to_fit();
        }
        let dag_hash = match self.root {
            Some(root) => self.root_hash(root),
            None => {
                // Empty scene: a root with no children.
                let root = self.levels.last_mut().expect("at least one level");
                root.offsets.push(0);
                root.words.push(0);
                empty_hash()
            }
        };
        let dag = Svdag::lay_out(self.resolution, self.levels, Vec::new())?;
        Ok(StreamedDag {
            dag,
            voxels: self.voxels,
            dag_hash,
        })
    }
}

/// The chunk depth a build uses: `chunk_depth`, by default the codec's, at most the leaves'
/// parents.
pub fn resolved_chunk_depth(codec: ColorCodec, chunk_depth: Option<u32>, resolution: u32) -> u32 {
    chunk_depth
        .unwrap_or_else(|| codec.default_chunk_depth(resolution))
        .min(resolution.trailing_zeros() - 2)
}

/// A chunk's encoded words and its colours' squared errors (empty for an exact codec).
type EncodedChunk = (Vec<u32>, Vec<f64>);

/// Colours per parallel encoding batch of [`ColorStream`] (complete chunks wait until this
/// many colours are ready, then are encoded together).
const BATCH_COLORS: usize = 1 << 22;

/// Colour chunks encoded as they complete (one chunk per SVO node at the chunk depth, as
/// [`crate::attr::ChunkedColors::build`] splits them); the words go to an unnamed temporary
/// file, the chunk tables stay in memory (16 bytes per chunk).
pub struct ColorStream {
    codec: ColorCodec,
    depth: u32,
    shift: u32,
    key: u64,
    open: Vec<u32>,
    ready: Vec<Vec<u32>>,
    ready_colors: usize,
    chunk_starts: Vec<u64>,
    chunk_offsets: Vec<u64>,
    spill: BufWriter<File>,
    spill_dir: PathBuf,
    squared: f64,
}

/// Encoded colours of a streaming build, their words in a spill file (what [`save_streamed`]
/// writes as the chunked colour section).
pub struct SpilledColors {
    /// The encoder.
    pub codec: ColorCodec,
    /// Chunk depth below the root.
    pub chunk_depth: u32,
    /// RMSE of the decoded colours against the input, as `attr::rmse` computes it.
    pub rmse: f64,
    /// First colour of each chunk, then the colour count.
    pub chunk_starts: Vec<u64>,
    /// First word of each chunk, then the word count.
    pub chunk_offsets: Vec<u64>,
    file: File,
}

impl SpilledColors {
    /// Colours stored.
    pub fn color_count(&self) -> u64 {
        *self.chunk_starts.last().expect("at least one entry")
    }

    /// Bytes of the chunk words and tables (as `ChunkedColors::byte_size`).
    pub fn byte_size(&self) -> u64 {
        4 * self.words() + 16 * self.chunk_starts.len() as u64
    }

    /// Encoded words.
    pub fn words(&self) -> u64 {
        *self.chunk_offsets.last().expect("at least one entry")
    }

    /// Number of chunks.
    pub fn chunk_count(&self) -> usize {
        self.chunk_starts.len() - 1
    }
}

/// An I/O error of the colour spill file in `dir`.
fn spill_error(dir: &Path) -> impl Fn(io::Error) -> DagError + '_ {
    move |source| DagError::Io {
        path: dir.join("<colour spill file>"),
        source,
    }
}

impl ColorStream {
    /// A stream for a grid of side `resolution`, chunks at `chunk_depth` (default
    /// `codec.default_chunk_depth`), spilling to an unnamed temporary file in `spill_dir`.
    pub fn new(
        codec: ColorCodec,
        chunk_depth: Option<u32>,
        resolution: u32,
        spill_dir: &Path,
    ) -> Result<ColorStream, DagError> {
        let log = resolution.trailing_zeros();
        let depth = resolved_chunk_depth(codec, chunk_depth, resolution);
        let file = tempfile::tempfile_in(spill_dir).map_err(spill_error(spill_dir))?;
        Ok(ColorStream {
            codec,
            depth,
            shift: 3 * (log - depth),
            key: 0,
            open: Vec::new(),
            ready: Vec::new(),
            ready_colors: 0,
            chunk_starts: vec![0],
            chunk_offsets: vec![0],
            spill: BufWriter::with_capacity(1 << 20, file),
            spill_dir: spill_dir.to_path_buf(),
            squared: std::iter::empty::<f64>().sum(),
        })
    }

    /// Adds the colours of the next voxels (codes ascending, one colour per code).
    pub fn push(&mut self, codes: &[u64], colors: &[u32]) -> Result<(), DagError> {
        if codes.len() != colors.len() {
            return Err(DagError::InvalidVoxels(format!(
                "{} colours for {} voxels",
                colors.len(),
                codes.len()
            )));
        }
        let mut from = 0;
        while from < codes.len() {
            let key = codes[from] >> self.shift;
            let run = codes[from..].partition_point(|&c| c >> self.shift == key);
            self.push_run(key, &colors[from..from + run])?;
            from += run;
        }
        Ok(())
    }

    /// `code >> shift` of a voxel code: the key of its chunk.
    pub fn chunk_shift(&self) -> u32 {
        self.shift
    }

    /// Adds the colours of the next voxels, all in the chunk `key` (`code >> chunk_shift`;
    /// keys ascending across calls).
    pub fn push_run(&mut self, key: u64, colors: &[u32]) -> Result<(), DagError> {
        if !self.open.is_empty() && key != self.key {
            self.close_chunk()?;
        }
        self.key = key;
        self.open.extend_from_slice(colors);
        Ok(())
    }

    /// Bytes held in memory (open chunk, chunks waiting for their batch, chunk tables).
    pub fn memory_bytes(&self) -> u64 {
        (4 * (self.open.capacity() + self.ready_colors)
            + 8 * (self.chunk_starts.capacity() + self.chunk_offsets.capacity())
            + self.spill.capacity()) as u64
    }

    fn close_chunk(&mut self) -> Result<(), DagError> {
        let chunk = std::mem::take(&mut self.open);
        if chunk.len() as u64 > MAX_CHUNK_COLORS {
            return Err(DagError::InvalidVoxels(format!(
                "colour chunk of {} colours (more than 2^32 - 1): pass a deeper --chunk-depth",
                chunk.len()
            )));
        }
        let start = self.chunk_starts.last().expect("non-empty") + chunk.len() as u64;
        self.chunk_starts.push(start);
        self.ready_colors += chunk.len();
        self.ready.push(chunk);
        if self.ready_colors >= BATCH_COLORS {
            self.encode_ready()?;
        }
        Ok(())
    }

    /// Encodes the waiting chunks in parallel; adds their squared errors in colour order (the
    /// order `attr::rmse` sums them) and appends their words to the spill file.
    fn encode_ready(&mut self) -> Result<(), DagError> {
        let codec = self.codec;
        let exact = codec.is_exact();
        let format = codec.format();
        let encoded: Vec<Result<EncodedChunk, DagError>> = self
            .ready
            .par_iter()
            .map(|colors| {
                let words = codec.encode(colors);
                if exact {
                    return Ok((words, Vec::new()));
                }
                let decoded = attr::decode_all(format, &words, colors.len())
                    .map_err(|e| DagError::InvalidVoxels(format!("colour encoder: {e}")))?;
                let errors = colors
                    .iter()
                    .zip(&decoded)
                    .map(|(&a, &b)| attr::squared_error(a, b))
                    .collect();
                Ok((words, errors))
            })
            .collect();
        let io = spill_error(&self.spill_dir);
        for result in encoded {
            let (words, errors) = result?;
            if exact {
                // Every term is 0 (the codec is exact): one addition gives the same bits.
                self.squared += 0.0;
            }
            for e in errors {
                self.squared += e;
            }
            self.spill
                .write_all(bytemuck::cast_slice(&words))
                .map_err(&io)?;
            let end = self.chunk_offsets.last().expect("non-empty") + words.len() as u64;
            self.chunk_offsets.push(end);
        }
        self.ready.clear();
        self.ready_colors = 0;
        Ok(())
    }

    /// Encodes the last chunks and returns the spilled colours (`None` when no colour came).
    pub fn finish(mut self) -> Result<Option<SpilledColors>, DagError> {
        if !self.open.is_empty() {
            self.close_chunk()?;
        }
        self.encode_ready()?;
        let colors = *self.chunk_starts.last().expect("non-empty");
        if colors == 0 {
            return Ok(None);
        }
        let io = spill_error(&self.spill_dir);
        let mut file = self.spill.into_inner().map_err(|e| io(e.into_error()))?;
        file.rewind().map_err(&io)?;
        Ok(Some(SpilledColors {
            codec: self.codec,
            chunk_depth: self.depth,
            rmse: (self.squared / (3 * colors) as f64).sqrt(),
            chunk_starts: self.chunk_starts,
            chunk_offsets: self.chunk_offsets,
            file,
        }))
    }
}

/// Writes the chunked colour section of `colors` to `w`, copying the words from the spill file
/// and absorbing every decoded chunk into `hasher` (the content digest's colour hash).
fn write_spilled(
    w: &mut dyn Write,
    colors: &mut SpilledColors,
    hasher: &mut ColorsHasher,
) -> io::Result<()> {
    let c = &*colors;
    let mut head = Vec::with_capacity(40 + 16 * c.chunk_starts.len());
    head.extend_from_slice(&c.codec.id().to_le_bytes());
    head.extend_from_slice(&(c.codec.format() as u32).to_le_bytes());
    head.extend_from_slice(&c.chunk_depth.to_le_bytes());
    head.extend_from_slice(&c.codec.threshold().to_le_bytes());
    head.extend_from_slice(&c.rmse.to_le_bytes());
    head.extend_from_slice(&(c.chunk_count() as u64).to_le_bytes());
    head.extend_from_slice(&c.words().to_le_bytes());
    for v in c.chunk_starts.iter().chain(&c.chunk_offsets) {
        head.extend_from_slice(&v.to_le_bytes());
    }
    w.write_all(&head)?;
    let format = c.codec.format();
    let mut bytes = Vec::new();
    let mut file = io::BufReader::with_capacity(1 << 20, &colors.file);
    for i in 0..colors.chunk_count() {
        let n = (colors.chunk_offsets[i + 1] - colors.chunk_offsets[i]) as usize;
        bytes.resize(4 * n, 0);
        file.read_exact(&mut bytes)?;
        w.write_all(&bytes)?;
        let words: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
            .collect();
        let count = (colors.chunk_starts[i + 1] - colors.chunk_starts[i]) as usize;
        let decoded = attr::decode_all(format, &words, count)
            .map_err(|e| io::Error::other(format!("decoding colour chunk {i}: {e}")))?;
        hasher.absorb(&decoded);
    }
    Ok(())
}

/// Saves the result of a streaming build atomically: `encoded` (built from the streamed DAG),
/// the voxel digest, the spilled colours and the content digest (DAG hash from the builder,
/// colour hash while the colours are copied). The bytes equal those [`super::VdagFile::save`]
/// writes for the same build in memory.
pub fn save_streamed(
    path: &Path,
    encoded: &EncodedDag,
    digest: &VoxelDigest,
    colors: Option<SpilledColors>,
    voxels: u64,
    dag_hash: [u64; 2],
) -> Result<(), DagError> {
    let color_count = colors.as_ref().map_or(0, SpilledColors::color_count);
    let colors = RefCell::new(colors);
    let color_hash = Cell::new(super::digest::colors_hash(&[]));
    let chunked = |w: &mut dyn Write| -> io::Result<()> {
        let mut colors = colors.borrow_mut();
        let colors = colors.as_mut().expect("section only written with colours");
        let mut hasher = ColorsHasher::new(colors.color_count());
        write_spilled(w, colors, &mut hasher)?;
        color_hash.set(hasher.finish());
        Ok(())
    };
    let content = |w: &mut dyn Write| -> io::Result<()> {
        let d = ContentDigest {
            voxels,
            dag: dag_hash,
            colors: color_hash.get(),
        };
        w.write_all(&d.to_bytes())
    };
    let chunked_len = colors
        .borrow()
        .as_ref()
        .map(|c| 40 + 16 * c.chunk_starts.len() as u64 + 4 * c.words());
    super::file::write_atomic(path, |w| {
        super::file::write_streamed(
            w,
            encoded,
            digest,
            color_count,
            chunked_len,
            &chunked,
            &content,
        )
    })
}
