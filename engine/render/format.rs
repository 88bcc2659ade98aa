//! The DAG formats the GPU traverses directly, and what is uploaded for each.
//!
//! Every shader that includes `render/traverse.glsl` is compiled once per [`TraversalFormat`]
//! (build.rs, list in `traversal_variants.rs`); the format-specific child fetch is
//! `render/dag_formats.glsl` (the hash DAG's in `render/dag_hash.glsl`: it is bound in place by
//! `GpuRenderer::bind_hash_dag`, nothing is laid out). [`GpuDagData::new`] lays a DAG out for
//! the other formats without decoding:
//! - svdag32: `Svdag::words`, `VoxelIndex::node_voxels` plus the voxels before each child
//!   pointer (at the pointer's word), a two-word info block (unused).
//! - SSVDAG / TSVDAG: the words are the encoding's leaves (two words each), then the node
//!   streams (levels 1..=root concatenated, two u16 per word); leaves and streams unchanged.
//!   `node_voxels` has one `u64` per u16 of the streams (`pointer_voxel_counts`: at every
//!   pointer the voxels it leads to; the colour index sums them). The info block ([`info`]
//!   offsets, mirrored by `DAG_INFO_*` in the GLSL) holds the coding flags and one 64-bit record
//!   per level (where its stream and its tables start), so a child fetch reads its level's
//!   constants with one fetch (the transforms are computed in the shader); after it (TSVDAG),
//!   per child level its Huffman decode table (one word per entry, Huffman modes) and pointer
//!   table (two words per entry, modes with tables): unchanged, except that in the Huffman
//!   modes each pointer-table entry is stored decoded (`predecoded_entry`).
//!
//! The info block with its tables goes to the GPU as a uniform texel buffer of word pairs
//! (`render/dag_tables.glsl`): the traversal reads it at per-invocation indices, which lavapipe
//! serves for all SIMD lanes at once from a texel buffer but one lane at a time through a
//! buffer address (docs/pathtracing.md, "Format tables as texels"). The words and counts stay
//! behind buffer addresses (they may exceed any descriptor's range).

use crate::dag::encode::{EncodeError, EncodedDag, SsvdagEncoding, TsvdagEncoding};
use crate::dag::transform::TransformSet;
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
    /// The payload's coding word (mask-coded levels, tagged levels << 8).
    pub const CODING: usize = 3;
    /// Per level l, a record of two words at `LEVELS + 2 l`, read with one texel fetch per
    /// child fetch: the u16 index of the level's stream in the streams (0 for the leaves, which
    /// pointers index directly), and (TSVDAG) the info word where the level's pointer table
    /// starts (even) | the index bits of its Huffman decode table << [`TABLE_BITS_SHIFT`]: the
    /// decode table fills the `1 << bits` words before it.
    pub const LEVELS: usize = 8;
    /// Words of the block (the tables follow it).
    pub const LEN: usize = LEVELS + 2 * MAX_LEVELS;
    /// Levels the per-level records hold (root levels up to 19 for 2^21 grids).
    pub const MAX_LEVELS: usize = 24;
    /// Where a level record's table word keeps the Huffman index bits.
    pub const TABLE_BITS_SHIFT: u32 = 28;
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
    /// The format info block and (TSVDAG) the tables after it; an even number of words (word
    /// pairs on the GPU).
    pub info: Vec<u32>,
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
    let mut w = vec![0u32; info::LEN];
    w[info::STREAM_BASE] = words.len() as u32;
    for (l, start) in push_streams(&mut words, &e.levels).into_iter().enumerate() {
        w[info::LEVELS + 2 * l] = start;
    }
    Ok(GpuDagData {
        format: TraversalFormat::Ssvdag,
        resolution: e.resolution,
        words,
        node_voxels: flatten_counts(e.pointer_voxel_counts()?),
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
    let mut w = vec![0u32; info::LEN];
    w[info::ROOT_XFORM] = e.root.map_or(0, |t| t.index() as u32);
    let set = match e.set {
        TransformSet::None => 0,
        TransformSet::Mirrors => 1,
        TransformSet::AxisPermutations => 2,
        TransformSet::All => 3,
    };
    w[info::SET] = set | (e.compact_translations() as u32) << 4;
    // After the block, per child level: its Huffman decode table (a one-entry table for a
    // level with one implied symbol or none), then its pointer table at an even word.
    let codes = if e.options.huffman {
        e.huffman_tables()
    } else {
        Vec::new()
    };
    for l in 0..e.levels.len() {
        let mut bits = 0;
        let mut decode = Vec::new();
        if let Some((kind, count, symbols)) = codes.get(l) {
            let table = match kind {
                2 => {
                    let (b, table) = huffman_decode_table(count, symbols);
                    bits = b;
                    table
                }
                1 => vec![symbols[0] as u32],
                _ => vec![0],
            };
            // Padding before the table, so that the pointer table after it starts even.
            if (w.len() + table.len()) % 2 == 1 {
                w.push(0);
            }
            w.extend_from_slice(&table);
            decode = table;
        }
        if w.len() as u64 >= 1 << info::TABLE_BITS_SHIFT {
            return Err(EncodeError::TooLarge(format!(
                "the pointer table of level {l} starts at info word {}: the GPU traversal \
                 addresses fewer than 2^{} words of tables",
                w.len(),
                info::TABLE_BITS_SHIFT
            )));
        }
        w[info::LEVELS + 2 * l + 1] = w.len() as u32 | bits << info::TABLE_BITS_SHIFT;
        if let Some(t) = e.tables.get(l) {
            for &v in t {
                let pair = if e.options.huffman {
                    predecoded_entry(v, &decode, bits, e.translations, l)?
                } else {
                    [v as u32, (v >> 32) as u32]
                };
                w.extend(pair);
            }
        }
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
    for (l, start) in push_streams(&mut words, &e.levels).into_iter().enumerate() {
        w[info::LEVELS + 2 * l] = start;
    }
    Ok(GpuDagData {
        format: TraversalFormat::Tsvdag {
            lut: e.options.lut,
            huffman: e.options.huffman,
            translations: e.translations,
        },
        resolution: e.resolution,
        words,
        node_voxels: flatten_counts(e.pointer_voxel_counts()?),
        info: w,
    })
}

/// A Huffman mode's pointer-table entry `E` of child level `level` as the GPU reads it:
/// `[target, symbol | the 15 bits after the code << 16]`, decoded with the level's decode
/// table `decode` (index bits `bits`) exactly as the shader decodes an inline pointer. A child
/// fetch then makes one table read, the pre-decoded entry or the decode table's entry, instead
/// of the entry and then its code (docs/pathtracing.md, "Pointer tables pre-decoded").
fn predecoded_entry(
    entry: u64,
    decode: &[u32],
    bits: u32,
    translations: bool,
    level: usize,
) -> Result<[u32; 2], EncodeError> {
    let code = *decode
        .get((entry & ((1u64 << bits) - 1)) as usize)
        .ok_or_else(|| {
            EncodeError::InvalidInput(format!(
                "level {level} has a pointer table but no Huffman decode table"
            ))
        })?;
    let (symbol, len) = (code & 0xffff, code >> 16);
    let rest = entry >> len;
    // The translation fields follow the code: one of `level + 3` bits per axis in the
    // symbol's low 3 bits (translated levels only; elsewhere those bits are zero).
    let used = if translations {
        (symbol & 7).count_ones() * (level as u32 + 3)
    } else {
        0
    };
    let target = rest.checked_shr(used).unwrap_or(0);
    let target = u32::try_from(target).map_err(|_| {
        EncodeError::TooLarge(format!(
            "the pointer table of level {level} names node {target}: the GPU traversal \
             addresses 2^32 u16 of streams"
        ))
    })?;
    Ok([target, symbol | ((rest as u32) & 0x7fff) << 16])
}

/// The decode table of a canonical Huffman code (`count[len]` codes of each length, `symbols`
/// sorted by (length, symbol)), indexed by the low `bits` bits of a pointer (bits = the longest
/// code): entry = symbol | length << 16, what the bit-serial canonical decoder
/// (`Huffman::decode`, read least significant bit first) gives for those bits; 0 where no code
/// matches. One lookup replaces up to 15 dependent steps on the GPU.
pub fn huffman_decode_table(count: &[u32; 16], symbols: &[u16]) -> (u32, Vec<u32>) {
    let bits = (1..16).rev().find(|&l| count[l] > 0).unwrap_or(0) as u32;
    let table = (0..1u32 << bits)
        .map(|x| {
            let (mut code, mut first, mut index) = (0u32, 0u32, 0u32);
            for len in 1..16u32 {
                code |= (x >> (len - 1)) & 1;
                let n = count[len as usize];
                if code < first + n {
                    let sym = symbols.get((index + code - first) as usize).copied();
                    return sym.map_or(0, |s| s as u32 | len << 16);
                }
                index += n;
                first = (first + n) << 1;
                code <<= 1;
            }
            0
        })
        .collect();
    (bits, table)
}

impl GpuDagData {
    /// The svdag32 layout of `dag`: its words, and `VoxelIndex::node_voxels` with, at each child
    /// pointer word of an inner node, the voxels of the children before it (so the colour index
    /// reads one count per level instead of one per preceding sibling).
    pub fn svdag32(dag: &Svdag) -> GpuDagData {
        let mut node_voxels = VoxelIndex::new(dag).node_voxels;
        for l in 1..dag.level_starts.len() {
            let (start, end) = (
                dag.level_starts[l] as usize,
                dag.level_starts[l - 1] as usize,
            );
            let mut p = start;
            while p < end {
                let children = dag.words[p].count_ones() as usize;
                let mut before = 0u64;
                for k in 0..children {
                    let child = dag.words[p + 1 + k] as usize;
                    node_voxels[p + 1 + k] = before;
                    before += node_voxels[child];
                }
                p += 1 + children;
            }
        }
        GpuDagData {
            format: TraversalFormat::Svdag32,
            resolution: dag.resolution,
            words: dag.words.clone(),
            node_voxels,
            info: vec![0, 0],
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dag::encode::TsvdagOptions;
    use crate::scene::{morton, Voxels};

    /// A 64^3 scene whose pointers use many transforms and translations.
    fn patterned_dag() -> Svdag {
        let mut codes = Vec::new();
        for z in 0..64u32 {
            for y in 0..64u32 {
                for x in 0..64u32 {
                    let (dx, dy, dz) = (x as i32 - 32, y as i32 - 32, z as i32 - 32);
                    if dx * dx + dy * dy + dz * dz < 900 && (x * 7 + y * 13 + z * z) % 11 < 3 {
                        codes.push(morton::encode(x, y, z));
                    }
                }
            }
        }
        codes.sort_unstable();
        let voxels = Voxels {
            resolution: 64,
            codes,
            colors: Vec::new(),
        };
        Svdag::from_voxels(&voxels).unwrap()
    }

    /// Every child level's record names its pointer table (at an even info word) and, in the
    /// `1 << bits` words before it, a decode table giving what `Huffman::decode` gives for every
    /// index (a level with one implied symbol or none: one entry of length 0), then the pointer
    /// table with every entry decoded; the tables follow
    /// the info block in level order, with at most one padding word between them; the DAG
    /// words hold the leaves and the node streams only.
    #[test]
    fn level_records_name_decode_and_pointer_tables() {
        let dag = patterned_dag();
        for translations in [false, true] {
            let options = TsvdagOptions {
                lut: true,
                huffman: true,
            };
            let e = TsvdagEncoding::build_with_translations(
                &dag,
                TransformSet::All,
                translations,
                options,
            )
            .unwrap();
            let data = tsvdag_data(&e).unwrap();
            let mut previous_end = info::LEN as u32;
            for l in 0..e.levels.len() - 1 {
                let word = data.info[info::LEVELS + 2 * l + 1];
                let bits = word >> info::TABLE_BITS_SHIFT;
                let tables = word & ((1 << info::TABLE_BITS_SHIFT) - 1);
                assert_eq!(tables % 2, 0, "level {l}: pointer table at an even word");
                let start = tables - (1 << bits);
                assert!(
                    start == previous_end
                        || (start == previous_end + 1 && data.info[previous_end as usize] == 0),
                    "level {l}: tables packed in level order"
                );
                let table = e.tables.get(l).map_or(&[][..], Vec::as_slice);
                previous_end = tables + 2 * table.len() as u32;
                let decode = &data.info[start as usize..tables as usize];
                let pointers = &data.info[tables as usize..previous_end as usize];
                // Each entry decoded: the target and symbol `decode_pointer` gives, the
                // translation fields after the symbol.
                for (i, &v) in table.iter().enumerate() {
                    let code = e.codes[l].as_ref();
                    let (symbol, len) = code.map_or((0, 0), |c| c.decode(v).unwrap());
                    let got = &pointers[2 * i..2 * i + 2];
                    assert_eq!(
                        got[1] & 0xffff,
                        symbol as u32,
                        "level {l}, entry {i}: symbol"
                    );
                    let fields = (v >> len) as u32 & 0x7fff;
                    assert_eq!(got[1] >> 16, fields, "level {l}, entry {i}: fields");
                    let used = (symbol & 7).count_ones() * (l as u32 + 3);
                    let target = (v >> len) >> used;
                    assert_eq!(got[0] as u64, target, "level {l}, entry {i}: target");
                }
                for (x, &entry) in decode.iter().enumerate() {
                    let expected = match &e.codes[l] {
                        Some(code) => code
                            .decode(x as u64)
                            .map_or(0, |(s, len)| s as u32 | (len as u32) << 16),
                        None => 0,
                    };
                    assert_eq!(entry, expected, "level {l}, index {x}");
                }
            }
            assert_eq!(data.info.len() as u32, previous_end);
            assert_eq!(data.info[info::STREAM_BASE], 2 * e.leaves.len() as u32);
            assert!(e.codes.iter().flatten().any(|c| c.single().is_none()));
        }
    }

    /// A pre-decoded entry splits `E` at the code's length and the symbol's translation fields
    /// (here: symbol 0b101 of length 2, fields of 4 bits for x and z at level 1) and refuses a
    /// target beyond 32 bits.
    #[test]
    fn predecoded_entries_split_code_fields_and_target() {
        // A 2-bit decode table: low bits 0b10 decode to symbol 5 (t = 0, axes x and z), length 2.
        let decode = [0u32, 0, 5 | 2 << 16, 0];
        let (x, z, target) = (0b1001u64, 0b0110u64, 12345u64);
        let entry = 0b10 | (x | z << 4) << 2 | target << 10;
        let got = predecoded_entry(entry, &decode, 2, true, 1).unwrap();
        assert_eq!(
            got,
            [
                12345,
                5 | ((x | z << 4 | target << 8) as u32 & 0x7fff) << 16
            ]
        );
        // Without translations the bits after the code are the target.
        let plain = predecoded_entry(0b10 | 77 << 2, &decode, 2, false, 1).unwrap();
        assert_eq!(plain, [77, 5 | 77 << 16]);
        assert!(predecoded_entry(0b10 | 1 << 34, &decode, 2, false, 1).is_err());
    }
}
