//! The DAG formats the GPU traverses directly, and what is uploaded for each.
//!
//! Every shader that includes `render/traverse.glsl` is compiled once per [`TraversalFormat`]
//! (build.rs, list in `traversal_variants.rs`); the format-specific child fetch is
//! `render/dag_formats.glsl` (the hash DAG's in `render/dag_hash.glsl`: it is bound in place by
//! `GpuRenderer::bind_hash_dag`, nothing is laid out). [`GpuDagData::new`] lays a DAG out for
//! the other formats without decoding:
//! - svdag32: `Svdag::words`, `VoxelIndex::node_voxels`, a one-word info block (unused).
//! - SSVDAG / TSVDAG: the words are the encoding's leaves (two words each), pointer tables
//!   (TSVDAG with tables, two words per entry, child levels in order) and node streams (levels
//!   1..=root concatenated, two u16 per word), unchanged; `node_voxels` has one `u64` per u16 of
//!   the streams (`stream_voxel_counts`: the colour index sums them); the info block
//!   ([`info`] offsets, mirrored by `DAG_INFO_*` in the GLSL) holds where each level starts,
//!   the coding flags, the transform tables of `dag::transform` and the Huffman decoders.

use crate::dag::encode::{EncodeError, EncodedDag, SsvdagEncoding, TsvdagEncoding};
use crate::dag::transform::{Transform, TransformSet, TRANSFORM_COUNT};
use crate::dag::{Svdag, VoxelIndex};

/// `(name, GLSL defines)` of every traversal variant, in [`TraversalFormat::index`] order.
pub const TRAVERSAL_VARIANTS: [(&str, &[&str]); 11] = include!("traversal_variants.rs");

/// Word offsets of the format info block (`DAG_INFO_*` in `render/dag_formats.glsl`).
pub mod info {
    /// Root transform id (TSVDAG).
    pub const ROOT_XFORM: usize = 0;
    /// Transform set id (0 none, 1 S, 2 A, 3 S+A) | compact translation codings << 4.
    pub const SET: usize = 1;
    /// Word offset of the node streams in the DAG words.
    pub const STREAM_BASE: usize = 2;
    /// Word offset of the pointer tables in the DAG words.
    pub const TABLE_BASE: usize = 3;
    /// The payload's coding word (mask-coded levels, tagged levels << 8).
    pub const CODING: usize = 4;
    /// Per level: u16 index of its stream in the streams (24 entries).
    pub const LEVEL_START: usize = 8;
    /// Per child level: first entry of its table in the tables (24 entries).
    pub const TABLE_START: usize = 32;
    /// `Transform::compose`, one byte per pair (48 x 48).
    pub const COMPOSE: usize = 56;
    /// `Transform::inverse`, one byte each.
    pub const INVERSE: usize = 632;
    /// `Transform::apply_octant`, 8 x 3 bits per transform.
    pub const OCTANT: usize = 644;
    /// `Transform::apply_child_mask`, one byte per (transform, mask).
    pub const CHILD_MASK: usize = 692;
    /// Per child level: Huffman code kind | implied symbol << 16.
    pub const HUFF_KIND: usize = 3764;
    /// Per child level: 16 code counts by length.
    pub const HUFF_COUNT: usize = 3788;
    /// Per child level: 384 u16 symbols sorted by (length, symbol).
    pub const HUFF_SYMBOLS: usize = 4172;
    /// Words of the block.
    pub const LEN: usize = HUFF_SYMBOLS + 24 * 192;
    /// Levels the per-level arrays hold (root levels up to 19 for 2^21 grids).
    pub const MAX_LEVELS: usize = 24;
}

/// A DAG format as the traversal shaders see it: one compiled variant each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TraversalFormat {
    /// Plain 32-bit SVDAG words.
    Svdag32,
    /// SSVDAG (mirror bits on 16/32-bit pointers).
    Ssvdag,
    /// TSVDAG in one pointer mode, with or without translated subtrees.
    Tsvdag {
        /// Pointer look-up tables.
        lut: bool,
        /// Huffman-coded transform symbols.
        huffman: bool,
        /// Translated subtrees (S+A+T).
        translations: bool,
    },
    /// The live hash DAG of the editor (`edit::gpu::GpuHashDag`): items read in place from its
    /// nine slab hash tables (`render/dag_hash.glsl`, bound by `GpuRenderer::bind_hash_dag`).
    HashDag,
}

impl TraversalFormat {
    /// Every variant, in index order.
    pub fn all() -> [TraversalFormat; 11] {
        std::array::from_fn(TraversalFormat::from_index)
    }

    fn from_index(i: usize) -> TraversalFormat {
        match i {
            0 => TraversalFormat::Svdag32,
            1 => TraversalFormat::Ssvdag,
            10 => TraversalFormat::HashDag,
            _ => {
                let mode = (i - 2) % 4;
                TraversalFormat::Tsvdag {
                    lut: mode == 1 || mode == 2,
                    huffman: mode >= 2,
                    translations: i >= 6,
                }
            }
        }
    }

    /// The variant traversing `dag`.
    pub fn of(dag: &EncodedDag) -> TraversalFormat {
        match dag {
            EncodedDag::Svdag32(_) => TraversalFormat::Svdag32,
            EncodedDag::Ssvdag(_) => TraversalFormat::Ssvdag,
            EncodedDag::Tsvdag(e) => TraversalFormat::Tsvdag {
                lut: e.options.lut,
                huffman: e.options.huffman,
                translations: e.translations,
            },
        }
    }

    /// Index into `TRAVERSAL_VARIANTS` and the shaders' `*_BY_FORMAT` arrays.
    pub fn index(self) -> usize {
        match self {
            TraversalFormat::Svdag32 => 0,
            TraversalFormat::Ssvdag => 1,
            TraversalFormat::Tsvdag {
                lut,
                huffman,
                translations,
            } => {
                let mode = match (lut, huffman) {
                    (false, false) => 0,
                    (true, false) => 1,
                    (true, true) => 2,
                    (false, true) => 3,
                };
                2 + mode + 4 * translations as usize
            }
            TraversalFormat::HashDag => 10,
        }
    }

    /// The variant's name (`svdag32`, `ssvdag`, `tsvdag_base`, ..., `tsvdag_huffman_t`).
    pub fn name(self) -> &'static str {
        TRAVERSAL_VARIANTS[self.index()].0
    }
}

/// What the traversal reads for one DAG (see the module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GpuDagData {
    /// The shader variant.
    pub format: TraversalFormat,
    /// Grid side length.
    pub resolution: u32,
    /// The DAG's words.
    pub words: Vec<u32>,
    /// Voxel counts for the colour index.
    pub node_voxels: Vec<u64>,
    /// The format info block.
    pub info: Vec<u32>,
}

/// Packs bytes little-endian into words (zero-padded).
fn pack_bytes(out: &mut [u32], bytes: impl Iterator<Item = u8>) {
    for (i, b) in bytes.enumerate() {
        out[i / 4] |= (b as u32) << (8 * (i % 4));
    }
}

/// The info block's level-independent part: the transform tables.
fn base_info() -> Vec<u32> {
    let mut w = vec![0u32; info::LEN];
    let all: Vec<Transform> = Transform::all().collect();
    pack_bytes(
        &mut w[info::COMPOSE..info::INVERSE],
        all.iter()
            .flat_map(|a| all.iter().map(move |b| a.compose(*b).index() as u8)),
    );
    pack_bytes(
        &mut w[info::INVERSE..info::OCTANT],
        all.iter().map(|t| t.inverse().index() as u8),
    );
    for (i, t) in all.iter().enumerate() {
        w[info::OCTANT + i] = (0..8).fold(0, |acc, o| acc | (t.apply_octant(o) as u32) << (3 * o));
    }
    pack_bytes(
        &mut w[info::CHILD_MASK..info::CHILD_MASK + TRANSFORM_COUNT * 64],
        all.iter()
            .flat_map(|t| (0..=255u8).map(move |m| t.apply_child_mask(m))),
    );
    w
}

/// Appends the node streams (two u16 per word) and returns each level's u16 start.
fn push_streams(words: &mut Vec<u32>, levels: &[Vec<u16>]) -> Vec<u32> {
    let mut starts = vec![0u32; levels.len()];
    let mut all: Vec<u16> = Vec::new();
    for (l, s) in levels.iter().enumerate().skip(1) {
        starts[l] = all.len() as u32;
        all.extend_from_slice(s);
    }
    words.extend(
        all.chunks(2)
            .map(|p| p[0] as u32 | (p.get(1).copied().unwrap_or(0) as u32) << 16),
    );
    // A zero word after the streams: an empty scene's root reads a childless header there.
    words.push(0);
    starts
}

/// The counts by global u16 stream position.
fn flatten_counts(counts: Vec<Vec<u64>>) -> Vec<u64> {
    let mut out: Vec<u64> = counts.into_iter().flatten().collect();
    if out.is_empty() {
        out.push(0);
    }
    out
}

fn check_levels(levels: usize) -> Result<(), EncodeError> {
    if levels > info::MAX_LEVELS {
        return Err(EncodeError::TooLarge(format!(
            "{levels} levels: the GPU info block holds {}",
            info::MAX_LEVELS
        )));
    }
    Ok(())
}

fn ssvdag_data(e: &SsvdagEncoding) -> Result<GpuDagData, EncodeError> {
    check_levels(e.levels.len())?;
    let mut words: Vec<u32> = e
        .leaves
        .iter()
        .flat_map(|&m| [m as u32, (m >> 32) as u32])
        .collect();
    let mut w = base_info();
    w[info::STREAM_BASE] = words.len() as u32;
    let starts = push_streams(&mut words, &e.levels);
    w[info::LEVEL_START..info::LEVEL_START + starts.len()].copy_from_slice(&starts);
    Ok(GpuDagData {
        format: TraversalFormat::Ssvdag,
        resolution: e.resolution,
        words,
        node_voxels: flatten_counts(e.stream_voxel_counts()?),
        info: w,
    })
}

fn tsvdag_data(e: &TsvdagEncoding) -> Result<GpuDagData, EncodeError> {
    check_levels(e.levels.len())?;
    let mut words: Vec<u32> = e
        .leaves
        .iter()
        .flat_map(|&m| [m as u32, (m >> 32) as u32])
        .collect();
    let mut w = base_info();
    w[info::ROOT_XFORM] = e.root.map_or(0, |t| t.index() as u32);
    let set = match e.set {
        TransformSet::None => 0,
        TransformSet::Mirrors => 1,
        TransformSet::AxisPermutations => 2,
        TransformSet::All => 3,
    };
    w[info::SET] = set | (e.compact_translations() as u32) << 4;
    w[info::TABLE_BASE] = words.len() as u32;
    let mut table_start = 0u32;
    for (l, t) in e.tables.iter().enumerate().take(e.levels.len()) {
        w[info::TABLE_START + l] = table_start;
        table_start += t.len() as u32;
        words.extend(t.iter().flat_map(|&v| [v as u32, (v >> 32) as u32]));
    }
    let mask_levels = e
        .translation_coding
        .iter()
        .enumerate()
        .filter(|(_, c)| **c == crate::dag::encode::TranslationCoding::Mask)
        .fold(0u32, |m, (l, _)| m | 1 << l);
    let tagged_levels = e
        .tagged
        .iter()
        .enumerate()
        .filter(|(_, t)| **t)
        .fold(0u32, |m, (l, _)| m | 1 << (8 + l));
    w[info::CODING] = mask_levels | tagged_levels;
    w[info::STREAM_BASE] = words.len() as u32;
    let starts = push_streams(&mut words, &e.levels);
    w[info::LEVEL_START..info::LEVEL_START + starts.len()].copy_from_slice(&starts);
    if e.options.huffman {
        for (l, (kind, count, symbols)) in e.huffman_tables().into_iter().enumerate() {
            let single = if kind == 1 { symbols[0] as u32 } else { 0 };
            w[info::HUFF_KIND + l] = kind | single << 16;
            w[info::HUFF_COUNT + 16 * l..info::HUFF_COUNT + 16 * (l + 1)].copy_from_slice(&count);
            if kind == 2 {
                let base = info::HUFF_SYMBOLS + 192 * l;
                pack_bytes(
                    &mut w[base..base + 192],
                    symbols.iter().flat_map(|s| s.to_le_bytes()),
                );
            }
        }
    }
    Ok(GpuDagData {
        format: TraversalFormat::Tsvdag {
            lut: e.options.lut,
            huffman: e.options.huffman,
            translations: e.translations,
        },
        resolution: e.resolution,
        words,
        node_voxels: flatten_counts(e.stream_voxel_counts()?),
        info: w,
    })
}

impl GpuDagData {
    /// The svdag32 layout of `dag` (its words and `VoxelIndex`).
    pub fn svdag32(dag: &Svdag) -> GpuDagData {
        GpuDagData {
            format: TraversalFormat::Svdag32,
            resolution: dag.resolution,
            words: dag.words.clone(),
            node_voxels: VoxelIndex::new(dag).node_voxels,
            info: vec![0],
        }
    }

    /// Lays `dag` out for its traversal variant (no decoding; counts computed by walking it).
    pub fn new(dag: &EncodedDag) -> Result<GpuDagData, EncodeError> {
        match dag {
            EncodedDag::Svdag32(d) => Ok(GpuDagData::svdag32(d)),
            EncodedDag::Ssvdag(e) => ssvdag_data(e),
            EncodedDag::Tsvdag(e) => tsvdag_data(e),
        }
    }
}
