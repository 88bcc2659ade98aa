//! TSVDAG encoding (dissertation §3.4): transform-aware SVDAG with compact pointers.
//!
//! Input is a [`TransformGraph`]: per level stored nodes whose children are
//! `(child, transform, translation)`. The subtree a pointer denotes is `Shift_t(T(C))`: the
//! transform `T` applied to the stored node `C`, then every voxel moved by `t` inside the
//! child's cube (voxels moved out are dropped: destructive translation). Built from a
//! [`CanonicalDag`] every translation is zero.
//!
//! Encoded pointer value `E` (first field in the low bits), for a child at level `l`:
//! - Huffman on: the code of the symbol `transform id * 8 + nonzero-translation axes mask`,
//!   then `l + 3` bits of `t + side` for each nonzero axis (x, y, z order), then the target.
//! - Huffman off: when the set is not `None` or level `l` may translate, 1 flag bit (any
//!   transform or translation); if set, the transform field (S: mirror, 3 bits; A: permutation,
//!   3 bits; S+A: id, 6 bits; none: 0 bits) and, where level `l` may translate, 3 x `l + 3`
//!   translation bits; then the target.
//!
//! The target is a leaf index (level 0) or a node offset in 16-bit units. Inner nodes are a
//! 16-bit header (2 bits per child in stored octant order: 00 empty, 01 16-bit, 10 32-bit,
//! 11 48-bit pointer) followed by the pointers. With look-up tables a 16-bit pointer is an
//! index into the child level's table of 64-bit `E`s; 32/48-bit pointers hold `v` with
//! `v & 1` = 1: table index `v >> 1`, 0: `E = v >> 1`. Without tables every pointer is `E`.

#![allow(clippy::needless_range_loop)] // levels index several parallel arrays

use std::sync::Arc;

use super::bytes::{Reader, Writer};
use super::huffman::Huffman;
use super::ssvdag::read_node;
use super::traverse::{root_level, TreeView};
use super::{corrupt, EncodeError};
use crate::dag::transform::{Transform, TransformSet};
use crate::dag::translate::apply_to_vector;
use crate::scene::morton;
use rustc_hash::FxHashMap;

/// Highest level whose nodes may be translated (16^3 subtrees, dissertation §3.3.2).
pub use crate::dag::translate::MAX_TRANSLATION_LEVEL;

/// Number of Huffman symbols: 48 transforms x 8 nonzero-translation masks.
const SYMBOLS: usize = 48 * 8;

/// (new target id, transform id, translation): a distinct pointer of a level.
type PointerKey = (u64, u8, [i8; 3]);

/// A child level's candidate layout: (cost in u16 words, translation coding, tagged, per
/// distinct pointer its stored value and size, the table).
type Candidate = (u64, TranslationCoding, bool, Vec<(u64, u16)>, Vec<u64>);

/// A child pointer of a [`TransformGraph`] node: the transform DAG's pointer (translations
/// per axis in `(-side, side)`, at most 16^3 subtrees: `i8`).
pub type GraphPointer = crate::dag::TPointer;

/// Stored nodes of one level of a [`TransformGraph`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GraphLevel {
    /// Level 0 only: 4^3 leaf masks.
    pub leaves: Vec<u64>,
    /// Inner levels: child mask per node (bit = stored octant).
    pub child_masks: Vec<u8>,
    /// Inner levels: index of each node's first child in `children`.
    pub child_starts: Vec<u32>,
    /// Inner levels: children in ascending octant order.
    pub children: Vec<GraphPointer>,
}

impl GraphLevel {
    /// Number of stored nodes.
    pub fn len(&self) -> usize {
        if self.leaves.is_empty() {
            self.child_masks.len()
        } else {
            self.leaves.len()
        }
    }

    /// Whether the level has no node.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Children of inner node `i`.
    pub fn node_children(&self, i: usize) -> &[GraphPointer] {
        let s = self.child_starts[i] as usize;
        &self.children[s..s + self.child_masks[i].count_ones() as usize]
    }
}

/// The general input of the TSVDAG encoder: stored nodes with (child, transform, translation)
/// pointers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TransformGraph {
    /// Grid side length.
    pub resolution: u32,
    /// Transforms pointers may use.
    pub set: TransformSet,
    /// Whether pointers to levels `0..=MAX_TRANSLATION_LEVEL` may carry translations.
    pub translations: bool,
    /// Levels bottom-up (0 = leaves).
    pub levels: Vec<GraphLevel>,
    /// The root pointer (`None` for an empty scene); its translation must be zero.
    pub root: Option<GraphPointer>,
}

impl TransformGraph {
    /// The graph of a transform DAG (S+A+T when it was built with translations); moves its
    /// arrays (no copy: at 64^3K the pointers alone are gigabytes).
    pub fn from_transform_dag(dag: crate::dag::TransformDag) -> TransformGraph {
        TransformGraph {
            resolution: dag.resolution,
            set: dag.set,
            translations: dag.translations,
            levels: dag
                .levels
                .into_iter()
                .map(|l| GraphLevel {
                    leaves: l.leaves,
                    child_masks: l.child_masks,
                    child_starts: l.child_starts,
                    children: l.children,
                })
                .collect(),
            root: dag.root,
        }
    }
}

/// Run-time switches of the TSVDAG encoder (the transform set comes with the graph).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TsvdagOptions {
    /// Per-level pointer look-up tables.
    pub lut: bool,
    /// Huffman-coded transform ids.
    pub huffman: bool,
}

/// Encoder heuristics that do not change the format's semantics, switchable to measure each
/// (`voxdag bench compress` ablations). All off reproduces the format-v1 encoder byte for byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TsvdagTuning {
    /// Without tables: store each node in the orientation of its most frequent untranslated
    /// reference ([`reorient`]).
    pub reorient: bool,
    /// Without Huffman: escape or mask coding of translation fields, chosen per child level
    /// (format v2, payload flag bit 4).
    pub compact_translations: bool,
    /// Node order ties: untranslated references, then fewer children first.
    pub tie_break: bool,
    /// With tables: per child level, tagged 16-bit pointers where they cost less (format v2,
    /// payload flag bit 5).
    pub tagged_pointers: bool,
}

impl TsvdagTuning {
    /// Every heuristic on (what `encode` uses).
    pub const ALL: TsvdagTuning = TsvdagTuning {
        reorient: true,
        compact_translations: true,
        tie_break: true,
        tagged_pointers: true,
    };
    /// Every heuristic off: the format-v1 encoder.
    pub const V1: TsvdagTuning = TsvdagTuning {
        reorient: false,
        compact_translations: false,
        tie_break: false,
        tagged_pointers: false,
    };
}

impl TsvdagOptions {
    /// The three modes `voxdag build` chooses from: base, lut, huffman.
    pub const MODES: [TsvdagOptions; 3] = [
        TsvdagOptions {
            lut: false,
            huffman: false,
        },
        TsvdagOptions {
            lut: true,
            huffman: false,
        },
        TsvdagOptions {
            lut: true,
            huffman: true,
        },
    ];

    /// Whether `tuning` stores this mode's nodes re-oriented ([`reorient`]) for `set`.
    pub fn reorients(self, tuning: TsvdagTuning, set: TransformSet) -> bool {
        tuning.reorient && !self.lut && set != TransformSet::None
    }

    /// The mode's name: `base`, `lut`, `huffman`, or `huffman-nolut` (Huffman without tables).
    pub fn mode_name(&self) -> &'static str {
        match (self.lut, self.huffman) {
            (false, false) => "base",
            (true, false) => "lut",
            (true, true) => "huffman",
            (false, true) => "huffman-nolut",
        }
    }
}

impl Default for TsvdagOptions {
    fn default() -> Self {
        TsvdagOptions {
            lut: true,
            huffman: true,
        }
    }
}

/// A TSVDAG in its compact encoding (layout in `docs/encodings.md`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TsvdagEncoding {
    /// Grid side length.
    pub resolution: u32,
    /// Transforms pointers may use.
    pub set: TransformSet,
    /// Whether levels `0..=MAX_TRANSLATION_LEVEL` carry translations.
    pub translations: bool,
    /// Encoder switches.
    pub options: TsvdagOptions,
    /// Transform of the root (`None`: empty scene).
    pub root: Option<Transform>,
    /// Stored leaves.
    pub leaves: Vec<u64>,
    /// Node streams in 16-bit units per level (entry 0 empty).
    pub levels: Vec<Vec<u16>>,
    /// Pointer tables per child level (the root level's is empty).
    pub tables: Vec<Vec<u64>>,
    /// Huffman code per child level (when enabled and the level is pointed to).
    pub codes: Vec<Option<Huffman>>,
    /// Per child level: how translation fields are written without Huffman.
    pub translation_coding: Vec<TranslationCoding>,
    /// Per child level, with tables: 16-bit pointers carry the table/inline tag bit like the
    /// longer ones (format v2, payload flag bit 5).
    pub tagged: Vec<bool>,
}

/// How a pointer with its flag set writes its translation, per child level that translates,
/// without Huffman (`docs/encodings.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TranslationCoding {
    /// Three fields, zero translations included (the only form of format v1; Huffman files and
    /// levels without translations use it too).
    Full,
    /// A single all-zero field stands for "no translation"; otherwise the three fields.
    Escape,
    /// A 3-bit mask of the nonzero axes, then only their fields.
    Mask,
}

/// A node handle of the TSVDAG view.
#[derive(Clone, Debug)]
pub enum TNode {
    /// A stored node seen through a transform then a translation.
    Stored {
        /// Leaf index or node offset.
        index: u64,
        /// Transform applied to the stored node.
        transform: Transform,
        /// Translation applied after it.
        translation: [i32; 3],
    },
    /// A window of a materialised (translated) subtree: bits indexed by local Morton code.
    Dense {
        /// The subtree's occupancy.
        grid: Arc<Vec<u64>>,
        /// First Morton code of the window.
        base: u64,
    },
}

/// Identity, not content: two handles are equal when they name the same stored node under the
/// same transform and translation, or the same window of the same materialised grid. That is
/// what memoized walks (the `verify` digest) need to visit each distinct node once; a memo key
/// holds its `Arc`, so a grid's address is never reused while it is compared against.
impl PartialEq for TNode {
    fn eq(&self, other: &TNode) -> bool {
        match (self, other) {
            (
                TNode::Stored {
                    index: a,
                    transform: ta,
                    translation: ra,
                },
                TNode::Stored {
                    index: b,
                    transform: tb,
                    translation: rb,
                },
            ) => a == b && ta == tb && ra == rb,
            (TNode::Dense { grid: a, base: ba }, TNode::Dense { grid: b, base: bb }) => {
                Arc::ptr_eq(a, b) && ba == bb
            }
            _ => false,
        }
    }
}

impl Eq for TNode {}

impl std::hash::Hash for TNode {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        match self {
            TNode::Stored {
                index,
                transform,
                translation,
            } => {
                0u8.hash(state);
                index.hash(state);
                transform.hash(state);
                translation.hash(state);
            }
            TNode::Dense { grid, base } => {
                1u8.hash(state);
                (Arc::as_ptr(grid) as usize).hash(state);
                base.hash(state);
            }
        }
    }
}

fn set_id(set: TransformSet) -> u32 {
    match set {
        TransformSet::None => 0,
        TransformSet::Mirrors => 1,
        TransformSet::AxisPermutations => 2,
        TransformSet::All => 3,
    }
}

fn transform_bits(set: TransformSet) -> u32 {
    match set {
        TransformSet::None => 0,
        TransformSet::Mirrors | TransformSet::AxisPermutations => 3,
        TransformSet::All => 6,
    }
}

fn transform_field(set: TransformSet, t: Transform) -> u64 {
    match set {
        TransformSet::None => 0,
        TransformSet::Mirrors => t.mirror() as u64,
        TransformSet::AxisPermutations => t.permutation_index() as u64,
        TransformSet::All => t.index() as u64,
    }
}

fn field_transform(set: TransformSet, f: u64) -> Option<Transform> {
    match set {
        TransformSet::None => (f == 0).then_some(Transform::IDENTITY),
        TransformSet::Mirrors => Transform::from_parts(0, f as u8),
        TransformSet::AxisPermutations => Transform::from_parts(f as usize, 0),
        TransformSet::All => Transform::from_index(f as usize),
    }
}

/// Bits per translation axis of a child at `level` (`t + side` in `1..2 * side`).
fn translation_bits(level: u32) -> u32 {
    level + 3
}

impl TsvdagEncoding {
    fn translates(&self, level: u32) -> bool {
        self.translations && level <= MAX_TRANSLATION_LEVEL
    }

    /// Stored elements per level, leaves first (the node counts of the transform DAG it
    /// encodes, whatever the mode).
    pub fn node_counts(&self) -> Result<Vec<u64>, EncodeError> {
        let mut out = vec![self.leaves.len() as u64];
        for stream in &self.levels[1..] {
            let (mut nodes, mut off) = (0u64, 0usize);
            while off < stream.len() {
                off = read_node(stream, off, 3, 0)?.1;
                nodes += 1;
            }
            out.push(nodes);
        }
        Ok(out)
    }

    /// Whether the payload needs format v2: compact translation fields or tagged pointers.
    pub fn needs_v2(&self) -> bool {
        self.compact_translations() || self.tagged.contains(&true)
    }

    /// Whether some child level uses the escape or mask form (flag bit 4, format v2).
    pub fn compact_translations(&self) -> bool {
        self.translation_coding
            .iter()
            .any(|c| *c != TranslationCoding::Full)
    }

    /// Canonicalizes an SVDAG under `set` and encodes it (no translations).
    pub fn build(
        dag: &crate::dag::Svdag,
        set: TransformSet,
        options: TsvdagOptions,
    ) -> Result<TsvdagEncoding, EncodeError> {
        Self::build_with_translations(dag, set, false, options)
    }

    /// Builds the transform DAG of an SVDAG (`set`, plus translations when asked: S+A+T with
    /// `TransformSet::All`) and encodes it.
    pub fn build_with_translations(
        dag: &crate::dag::Svdag,
        set: TransformSet,
        translations: bool,
        options: TsvdagOptions,
    ) -> Result<TsvdagEncoding, EncodeError> {
        let tdag = crate::dag::build_transform_dag(dag, set, translations);
        Self::encode(&TransformGraph::from_transform_dag(tdag), options)
    }

    /// Encodes a graph. Without look-up tables every stored node is first re-oriented to the
    /// transform of its most frequent untranslated reference ([`reorient`]), so that most
    /// pointers become plain ones; the table modes keep the canonical orientation, whose
    /// pointers are more shareable.
    pub fn encode(
        g: &TransformGraph,
        options: TsvdagOptions,
    ) -> Result<TsvdagEncoding, EncodeError> {
        Self::encode_tuned(g, options, TsvdagTuning::ALL)
    }

    /// Encodes `g` in each of `modes` and keeps the smallest (the first of equal sizes). The
    /// modes that store nodes re-oriented run last, on `g` re-oriented in place, so about one
    /// graph is in memory at a time. A mode whose inline pointers do not fit 48 bits is
    /// skipped while another mode fits.
    pub fn encode_smallest(
        g: TransformGraph,
        modes: &[TsvdagOptions],
    ) -> Result<TsvdagEncoding, EncodeError> {
        let (plain, turned): (Vec<usize>, Vec<usize>) =
            (0..modes.len()).partition(|&i| !modes[i].reorients(TsvdagTuning::ALL, g.set));
        let mut best: Option<(usize, TsvdagEncoding)> = None;
        let mut too_large = None;
        let mut keep = |i: usize, encoded: Result<TsvdagEncoding, EncodeError>| match encoded {
            Ok(e) => {
                let smaller =
                    |(bi, b): &(usize, TsvdagEncoding)| (e.byte_size(), i) < (b.byte_size(), *bi);
                if best.as_ref().is_none_or(smaller) {
                    best = Some((i, e));
                }
                Ok(())
            }
            Err(e @ EncodeError::TooLarge(_)) if modes.len() > 1 => {
                too_large = Some(e);
                Ok(())
            }
            Err(e) => Err(e),
        };
        for &i in &plain {
            keep(i, Self::encode(&g, modes[i]))?;
        }
        if !turned.is_empty() {
            let g = reorient(g);
            let tuning = TsvdagTuning {
                reorient: false,
                ..TsvdagTuning::ALL
            };
            for &i in &turned {
                keep(i, Self::encode_tuned(&g, modes[i], tuning))?;
            }
        }
        match best {
            Some((_, e)) => Ok(e),
            None => Err(too_large
                .unwrap_or_else(|| EncodeError::InvalidInput("no encoding mode given".into()))),
        }
    }

    /// [`TsvdagEncoding::encode`] with a choice of heuristics.
    pub fn encode_tuned(
        g: &TransformGraph,
        options: TsvdagOptions,
        tuning: TsvdagTuning,
    ) -> Result<TsvdagEncoding, EncodeError> {
        let top = root_level(g.resolution) as usize;
        if g.levels.len() != top + 1 {
            return Err(EncodeError::InvalidInput(format!(
                "{} levels for resolution {}",
                g.levels.len(),
                g.resolution
            )));
        }
        let mut out = TsvdagEncoding {
            resolution: g.resolution,
            set: g.set,
            translations: g.translations,
            options,
            root: None,
            leaves: Vec::new(),
            levels: vec![Vec::new(); top + 1],
            tables: vec![Vec::new(); top + 1],
            codes: vec![None; top + 1],
            translation_coding: vec![TranslationCoding::Full; top + 1],
            tagged: vec![false; top + 1],
        };
        let Some(root) = g.root else {
            return Ok(out);
        };
        if root.translation != [0; 3] || !g.set.contains(root.transform) {
            return Err(EncodeError::InvalidInput(
                "root pointer out of the set or translated".into(),
            ));
        }
        let counts: Vec<usize> = g.levels.iter().map(|l| l.len()).collect();
        if root.node as usize >= counts[top] {
            return Err(EncodeError::InvalidInput("root node out of range".into()));
        }
        check_graph(g)?;
        let reoriented;
        let g = if options.reorients(tuning, g.set) {
            reoriented = reorient(g.clone());
            &reoriented
        } else {
            g
        };
        let root = g.root.expect("checked");
        out.root = Some(root.transform);
        let order = sort_nodes(g, &counts, root.node as usize, tuning.tie_break);
        let mut new_id = vec![u64::MAX; counts[0]];
        for (i, &old) in order[0].iter().enumerate() {
            out.leaves.push(g.levels[0].leaves[old]);
            new_id[old] = i as u64;
        }
        for l in 1..=top {
            let cl = (l - 1) as u32;
            // Distinct pointers, their reference counts, and the distinct id of every pointer
            // in stream order (so the stream is written without a second hash look-up). The
            // table is keyed by the pointer packed in 64 bits (16-byte entries: the largest
            // allocation of a 64K^3 encode).
            let mut ids: FxHashMap<u64, u32> = FxHashMap::default();
            let mut keys: Vec<(PointerKey, u64)> = Vec::new();
            let mut pointer_ids: Vec<u32> = Vec::new();
            for &old in &order[l] {
                for c in g.levels[l].node_children(old) {
                    let [x, y, z] = c.translation.map(|t| t as u8 as u64);
                    let packed = (c.node as u64) << 32
                        | (c.transform.index() as u64) << 24
                        | x << 16
                        | y << 8
                        | z;
                    let id = *ids.entry(packed).or_insert_with(|| {
                        let target = new_id[c.node as usize];
                        keys.push(((target, c.transform.index() as u8, c.translation), 0));
                        keys.len() as u32 - 1
                    });
                    keys[id as usize].1 += 1;
                    pointer_ids.push(id);
                }
            }
            drop(ids);
            let mut sorted: Vec<u32> = (0..keys.len() as u32).collect();
            sorted.sort_unstable_by(|&a, &b| {
                let (ka, kb) = (&keys[a as usize], &keys[b as usize]);
                kb.1.cmp(&ka.1).then(ka.0.cmp(&kb.0))
            });
            if options.huffman {
                let mut hist = vec![0u64; SYMBOLS];
                for ((_, t, tr), count) in &keys {
                    hist[*t as usize * 8 + nonzero_mask(tr)] += *count;
                }
                out.codes[l - 1] = Huffman::from_weights(&hist);
            }
            let compact = tuning.compact_translations && !options.huffman && out.translates(cl);
            let codings: &[TranslationCoding] = if compact {
                &[TranslationCoding::Escape, TranslationCoding::Mask]
            } else {
                &[TranslationCoding::Full]
            };
            // Per translation coding the pointer values, then per pointer layout (tables with
            // plain or tagged 16-bit pointers) the cost: the cheapest combination is written.
            let layouts: &[bool] = if options.lut && tuning.tagged_pointers {
                &[false, true]
            } else {
                &[false]
            };
            let mut best: Option<Candidate> = None;
            let mut last_err = None;
            for &coding in codings {
                out.translation_coding[l - 1] = coding;
                let values = match out.pointer_values(cl, &keys) {
                    Ok(v) => v,
                    Err(e) => {
                        last_err = Some(e);
                        continue;
                    }
                };
                for &tagged in layouts {
                    match out.assign_pointers(cl, &keys, &values, &sorted, tagged) {
                        Ok((entries, table, cost)) => {
                            let better = match &best {
                                Some(b) => cost < b.0,
                                None => true,
                            };
                            if better {
                                best = Some((cost, coding, tagged, entries, table));
                            }
                        }
                        Err(e) => last_err = Some(e),
                    }
                }
            }
            let Some((_, coding, tagged, entries, table)) = best else {
                return Err(last_err.expect("at least one coding tried"));
            };
            out.translation_coding[l - 1] = coding;
            out.tagged[l - 1] = tagged;
            out.tables[l - 1] = table;
            let mut stream: Vec<u16> = Vec::new();
            let mut offsets = vec![u64::MAX; counts[l]];
            let mut next = pointer_ids.iter();
            for &old in &order[l] {
                offsets[old] = stream.len() as u64;
                let at = stream.len();
                stream.push(0);
                let mut header = 0u16;
                let mask = g.levels[l].child_masks[old];
                for o in 0..8 {
                    if (mask >> o) & 1 == 0 {
                        continue;
                    }
                    let id = *next.next().expect("one id per pointer");
                    let (v, size) = entries[id as usize];
                    for i in 0..size {
                        stream.push((v >> (16 * i)) as u16);
                    }
                    header |= size << (2 * o);
                }
                stream[at] = header;
            }
            out.levels[l] = stream;
            new_id = offsets;
        }
        Ok(out)
    }

    /// `E` of every distinct pointer of child level `cl` (`keys[i]`: pointer, reference count).
    fn pointer_values(&self, cl: u32, keys: &[(PointerKey, u64)]) -> Result<Vec<u64>, EncodeError> {
        keys.iter()
            .map(|&((idx, t, tr), _)| {
                let ptr = GraphPointer {
                    node: 0,
                    transform: Transform::from_index(t as usize).expect("checked"),
                    translation: tr,
                };
                self.encode_pointer(cl, idx, &ptr)
            })
            .collect()
    }

    /// Stored value and size (u16 words) of every distinct pointer of child level `cl`
    /// (`keys[i]`: pointer and reference count, `values[i]` its `E`; `sorted`: ids by
    /// descending count), the level's table, and the cost in u16 words (pointers plus table).
    /// With tables, `tagged` makes 16-bit pointers carry the table/inline tag bit too.
    #[allow(clippy::type_complexity)]
    fn assign_pointers(
        &self,
        cl: u32,
        keys: &[(PointerKey, u64)],
        values: &[u64],
        sorted: &[u32],
        tagged: bool,
    ) -> Result<(Vec<(u64, u16)>, Vec<u64>, u64), EncodeError> {
        let mut entries = vec![(0u64, 0u16); keys.len()];
        let mut table: Vec<u64> = Vec::new();
        let mut cost = 0u64;
        let bits = |v: u64| 64 - v.leading_zeros();
        // Smallest tagged size: 16 bits when tagged, else 32 (16-bit values are table indices).
        let min_tagged = if tagged { 1 } else { 2 };
        for &id in sorted {
            let count = keys[id as usize].1;
            let e = values[id as usize];
            let entry = if self.options.lut {
                let inline_size = (bits(e) + 1).div_ceil(16).max(min_tagged) as u64;
                let inline_cost = if inline_size > 3 {
                    u64::MAX
                } else {
                    count * inline_size
                };
                let i = table.len() as u64;
                let (tv, tsize) = if !tagged && i <= 0xffff {
                    (i, 1u64)
                } else {
                    (
                        i << 1 | 1,
                        (bits(i) + 1).div_ceil(16).max(min_tagged) as u64,
                    )
                };
                let table_cost = count * tsize + 4;
                if table_cost < inline_cost && tsize <= 3 {
                    table.push(e);
                    cost += table_cost;
                    (tv, tsize as u16)
                } else if inline_size <= 3 {
                    cost += inline_cost;
                    (e << 1, inline_size as u16)
                } else {
                    return Err(EncodeError::TooLarge(format!(
                        "pointer of {} bits at level {}",
                        bits(e),
                        cl + 1
                    )));
                }
            } else {
                let size = bits(e).div_ceil(16).max(1);
                if size > 3 {
                    return Err(EncodeError::TooLarge(format!(
                        "pointer of {} bits at level {} without look-up tables",
                        bits(e),
                        cl + 1
                    )));
                }
                cost += count * size as u64;
                (e, size as u16)
            };
            entries[id as usize] = entry;
        }
        Ok((entries, table, cost))
    }

    /// `E` of a pointer to `target` at child level `level`.
    fn encode_pointer(
        &self,
        level: u32,
        target: u64,
        p: &GraphPointer,
    ) -> Result<u64, EncodeError> {
        let tb = translation_bits(level);
        let side = 4i64 << level;
        // Fields accumulate from the low bits (at most 1 + 6 + 3 + 3 * 5 bits before the target:
        // no allocation, this runs once per distinct pointer and candidate layout).
        let (mut e, mut used) = (0u64, 0u32);
        let mut push = |v: u64, bits: u32| {
            e |= v << used;
            used += bits;
        };
        if self.options.huffman {
            let sym = p.transform.index() * 8 + nonzero_mask(&p.translation);
            let code = self.codes[level as usize].as_ref();
            let (c, len) = code
                .and_then(|h| h.encode(sym))
                .ok_or_else(|| EncodeError::InvalidInput("symbol without a code".into()))?;
            push(c as u64, len as u32);
            for &t in &p.translation {
                if t != 0 {
                    push((t as i64 + side) as u64, tb);
                }
            }
        } else if self.set != TransformSet::None || self.translates(level) {
            let any = p.transform != Transform::IDENTITY || p.translation != [0; 3];
            push(any as u64, 1);
            if any {
                push(
                    transform_field(self.set, p.transform),
                    transform_bits(self.set),
                );
                if self.translates(level) {
                    let coding = self.translation_coding[level as usize];
                    let mask = nonzero_mask(&p.translation);
                    // Axes with a field: all (v1), none behind the zero escape, or the mask's.
                    let axes = match coding {
                        TranslationCoding::Full => 7,
                        TranslationCoding::Escape if mask == 0 => {
                            push(0, tb);
                            0
                        }
                        TranslationCoding::Escape => 7,
                        TranslationCoding::Mask => {
                            push(mask as u64, 3);
                            mask
                        }
                    };
                    for (a, &t) in p.translation.iter().enumerate() {
                        if (axes >> a) & 1 == 1 {
                            push((t as i64 + side) as u64, tb);
                        }
                    }
                }
            }
        }
        if used + (64 - target.leading_zeros()) > 63 {
            return Err(EncodeError::TooLarge(format!(
                "pointer to {target} needs over 63 bits"
            )));
        }
        Ok(target << used | e)
    }

    /// Decodes the pointer value `v` (size code `code`) of a child at level `level`:
    /// (target, transform, translation).
    fn decode_pointer(
        &self,
        level: u32,
        v: u64,
        code: u8,
    ) -> Result<(u64, Transform, [i32; 3]), EncodeError> {
        let l = level as usize;
        let mut e = v;
        if self.options.lut {
            let table_index = if code == 1 && !self.tagged[l] {
                Some(v)
            } else if v & 1 == 1 {
                Some(v >> 1)
            } else {
                e = v >> 1;
                None
            };
            if let Some(i) = table_index {
                e = *self.tables[l].get(i as usize).ok_or_else(|| {
                    corrupt(0, format!("table index {i} out of range at level {l}"))
                })?;
            }
        }
        let tb = translation_bits(level);
        let side = 4i32 << level;
        fn take(e: &mut u64, bits: u32) -> u64 {
            let x = *e & ((1u64 << bits) - 1);
            *e >>= bits;
            x
        }
        let mut transform = Transform::IDENTITY;
        let mut translation = [0i32; 3];
        let bad = |what: &str| corrupt(0, format!("{what} in pointer {v:#x} at level {l}"));
        if self.options.huffman {
            let h = self.codes[l]
                .as_ref()
                .ok_or_else(|| bad("no Huffman code"))?;
            let (sym, len) = h.decode(e).ok_or_else(|| bad("invalid Huffman code"))?;
            take(&mut e, len as u32);
            let (t, mask) = (sym as usize / 8, sym as usize % 8);
            transform = Transform::from_index(t).ok_or_else(|| bad("transform id"))?;
            if mask != 0 && !self.translates(level) {
                return Err(bad("translation"));
            }
            for (a, tr) in translation.iter_mut().enumerate() {
                if (mask >> a) & 1 == 1 {
                    *tr = take(&mut e, tb) as i32 - side;
                    if *tr == 0 || *tr <= -side || *tr >= side {
                        return Err(bad("translation amount"));
                    }
                }
            }
        } else if (self.set != TransformSet::None || self.translates(level)) && take(&mut e, 1) == 1
        {
            {
                let f = take(&mut e, transform_bits(self.set));
                transform = field_transform(self.set, f).ok_or_else(|| bad("transform field"))?;
                if self.translates(level) {
                    // Which axes have a field: all three (v1 files, and the escape form
                    // unless the first field is the zero escape) or the mask's.
                    let mask = match self.translation_coding[l] {
                        TranslationCoding::Full => 7,
                        TranslationCoding::Escape => {
                            let x = take(&mut e, tb);
                            if x == 0 {
                                0
                            } else {
                                translation[0] = x as i32 - side;
                                6
                            }
                        }
                        TranslationCoding::Mask => take(&mut e, 3),
                    };
                    for (a, tr) in translation.iter_mut().enumerate() {
                        if (mask >> a) & 1 == 1 {
                            *tr = take(&mut e, tb) as i32 - side;
                            if *tr <= -side || *tr >= side {
                                return Err(bad("translation amount"));
                            }
                            if *tr == 0 && self.translation_coding[l] == TranslationCoding::Mask {
                                return Err(bad("zero translation under a nonzero mask bit"));
                            }
                        }
                    }
                    let compact = self.translation_coding[l] != TranslationCoding::Full;
                    if compact && transform == Transform::IDENTITY && translation == [0; 3] {
                        return Err(bad("plain pointer with its flag set"));
                    }
                }
            }
        }
        if !self.set.contains(transform) {
            return Err(bad("transform outside the set"));
        }
        Ok((e, transform, translation))
    }

    /// Bytes of the payload (`to_payload().len()`).
    pub fn byte_size(&self) -> u64 {
        let top = self.levels.len() as u64 - 1;
        let huff: u64 = self
            .codes
            .iter()
            .take(top as usize)
            .map(|c| match c {
                None => 2,
                Some(h) if h.single().is_some() => 4,
                Some(_) => 2 + SYMBOLS as u64 / 2,
            })
            .sum();
        24 + 8 * top * 2
            + if self.options.huffman { huff } else { 0 }
            + 8 * self.leaves.len() as u64
            + 8 * self.tables.iter().map(|t| t.len() as u64).sum::<u64>()
            + 2 * self.levels.iter().map(|l| l.len() as u64).sum::<u64>()
    }

    /// Serialises the payload (layout in `docs/encodings.md`).
    pub fn to_payload(&self) -> Vec<u8> {
        let top = self.levels.len() - 1;
        let mut w = Writer::default();
        w.u32(self.levels.len() as u32);
        let flags = self.root.is_none() as u32
            | (self.options.lut as u32) << 1
            | (self.options.huffman as u32) << 2
            | (self.translations as u32) << 3
            | (self.compact_translations() as u32) << 4
            | (self.tagged.contains(&true) as u32) << 5
            | set_id(self.set) << 8;
        w.u32(flags);
        w.u32(self.root.map_or(0, |t| t.index() as u32));
        let mask_levels = self
            .translation_coding
            .iter()
            .enumerate()
            .filter(|(_, c)| **c == TranslationCoding::Mask)
            .fold(0u32, |m, (l, _)| m | 1 << l);
        let tagged_levels = self
            .tagged
            .iter()
            .enumerate()
            .filter(|(_, t)| **t)
            .fold(0u32, |m, (l, _)| m | 1 << (8 + l));
        w.u32(mask_levels | tagged_levels);
        w.u64(self.leaves.len() as u64);
        for l in &self.levels[1..] {
            w.u64(l.len() as u64);
        }
        for t in &self.tables[..top] {
            w.u64(t.len() as u64);
        }
        if self.options.huffman {
            for c in &self.codes[..top] {
                match c {
                    None => w.u16(0),
                    Some(h) => match h.single() {
                        Some(s) => {
                            w.u16(1);
                            w.u16(s);
                        }
                        None => {
                            w.u16(2);
                            for pair in h.lengths.chunks(2) {
                                w.u8(pair[0] | pair.get(1).copied().unwrap_or(0) << 4);
                            }
                        }
                    },
                }
            }
        }
        w.u64s(&self.leaves);
        for t in &self.tables[..top] {
            w.u64s(t);
        }
        for l in &self.levels[1..] {
            w.u16s(l);
        }
        w.bytes
    }

    /// Parses and validates a payload for a grid of side `resolution` (already validated).
    pub fn from_payload(bytes: &[u8], resolution: u32) -> Result<TsvdagEncoding, EncodeError> {
        let top = root_level(resolution) as usize;
        let mut r = Reader::new(bytes);
        let level_count = r.u32("level count")?;
        if level_count as usize != top + 1 {
            return Err(corrupt(
                0,
                format!("{level_count} levels, expected {}", top + 1),
            ));
        }
        let flags = r.u32("flags")?;
        if flags & !0x33f != 0 {
            return Err(corrupt(4, format!("unknown flags {flags:#x}")));
        }
        let set = match (flags >> 8) & 3 {
            0 => TransformSet::None,
            1 => TransformSet::Mirrors,
            2 => TransformSet::AxisPermutations,
            _ => TransformSet::All,
        };
        let root_t = r.u32("root transform")?;
        let root = if flags & 1 == 1 {
            None
        } else {
            let t = Transform::from_index(root_t as usize)
                .filter(|t| set.contains(*t))
                .ok_or_else(|| corrupt(8, format!("root transform {root_t}")))?;
            Some(t)
        };
        let options = TsvdagOptions {
            lut: flags & 2 != 0,
            huffman: flags & 4 != 0,
        };
        let translations = flags & 8 != 0;
        let word = r.u32("coding word")?;
        let (mask_levels, tagged_levels) = (word & 0xff, word >> 8);
        let mut tagged = vec![false; top + 1];
        if flags & 32 != 0 {
            if !options.lut {
                return Err(corrupt(4, "tagged pointers (flag bit 5) need tables"));
            }
            if tagged_levels >> top != 0 {
                return Err(corrupt(
                    12,
                    format!("coding word {word:#x} tags a level that has no parent"),
                ));
            }
            for (l, t) in tagged.iter_mut().enumerate() {
                *t = (tagged_levels >> l) & 1 == 1;
            }
        } else if tagged_levels != 0 {
            return Err(corrupt(12, "tagged-pointer bits without flag bit 5"));
        }
        let mut translation_coding = vec![TranslationCoding::Full; top + 1];
        if flags & 16 != 0 {
            if options.huffman || !translations {
                return Err(corrupt(
                    4,
                    "compact translation fields (flag bit 4) need translations and no Huffman",
                ));
            }
            if mask_levels >> (MAX_TRANSLATION_LEVEL + 1) != 0 {
                return Err(corrupt(
                    12,
                    format!(
                        "translation coding {mask_levels:#x} names a level that cannot translate"
                    ),
                ));
            }
            for (l, c) in translation_coding.iter_mut().enumerate().take(top) {
                if l as u32 <= MAX_TRANSLATION_LEVEL {
                    *c = if (mask_levels >> l) & 1 == 1 {
                        TranslationCoding::Mask
                    } else {
                        TranslationCoding::Escape
                    };
                }
            }
        } else if mask_levels != 0 {
            return Err(corrupt(
                12,
                "translation coding word is not zero without flag bit 4",
            ));
        }
        let leaf_count = r.u64("leaf count")?;
        let mut stream_lens = Vec::new();
        for _ in 0..top {
            stream_lens.push(r.u64("level length")?);
        }
        let mut table_lens = Vec::new();
        for _ in 0..top {
            table_lens.push(r.u64("table length")?);
        }
        let mut codes = vec![None; top + 1];
        if options.huffman {
            for code in codes.iter_mut().take(top) {
                let at = r.at as u64;
                match r.u16("code kind")? {
                    0 => {}
                    1 => {
                        let s = r.u16("symbol")?;
                        if s as usize >= SYMBOLS {
                            return Err(corrupt(at, format!("bad Huffman symbol {s}")));
                        }
                        *code = Huffman::from_lengths(vec![0; SYMBOLS], Some(s));
                    }
                    2 => {
                        let mut lengths = Vec::with_capacity(SYMBOLS);
                        for _ in 0..SYMBOLS / 2 {
                            let b = r.u8("code lengths")?;
                            lengths.push(b & 15);
                            lengths.push(b >> 4);
                        }
                        *code = Some(Huffman::from_lengths(lengths, None).ok_or_else(|| {
                            corrupt(at, "code lengths do not form a prefix code")
                        })?);
                    }
                    k => return Err(corrupt(at, format!("unknown code kind {k}"))),
                }
            }
        }
        let leaves = r.u64s(leaf_count, "leaves")?;
        let mut tables = Vec::new();
        for &n in &table_lens {
            tables.push(r.u64s(n, "pointer table")?);
        }
        tables.push(Vec::new());
        let mut levels = vec![Vec::new()];
        let mut bases = vec![0u64];
        for &n in &stream_lens {
            bases.push(r.at as u64);
            levels.push(r.u16s(n, "level stream")?);
        }
        r.finish()?;
        let enc = TsvdagEncoding {
            resolution,
            set,
            translations,
            options,
            root,
            leaves,
            levels,
            tables,
            codes,
            translation_coding,
            tagged,
        };
        enc.validate(&bases)?;
        Ok(enc)
    }

    /// Structural checks: whole nodes, decodable pointers to node starts one level down.
    fn validate(&self, bases: &[u64]) -> Result<(), EncodeError> {
        let top = self.levels.len() - 1;
        if self.root.is_none() {
            if !self.leaves.is_empty() || self.levels.iter().any(|l| !l.is_empty()) {
                return Err(corrupt(4, "empty scene with stored nodes"));
            }
            return Ok(());
        }
        if self.leaves.contains(&0) {
            return Err(corrupt(0, "empty leaf"));
        }
        let mut below: Option<Vec<u32>> = None;
        for l in 1..=top {
            let stream = &self.levels[l];
            let mut starts = Vec::new();
            let mut off = 0;
            while off < stream.len() {
                starts.push(off as u32);
                let at = bases[l] + 2 * off as u64;
                let (ptrs, end) = read_node(stream, off, 3, bases[l])?;
                for (v, code) in ptrs.into_iter().flatten() {
                    let (target, _, _) =
                        self.decode_pointer(l as u32 - 1, v, code)
                            .map_err(|e| match e {
                                EncodeError::Corrupt { reason, .. } => corrupt(at, reason),
                                other => other,
                            })?;
                    let ok = match &below {
                        None => target < self.leaves.len() as u64,
                        Some(st) => {
                            target <= u32::MAX as u64 && st.binary_search(&(target as u32)).is_ok()
                        }
                    };
                    if !ok {
                        return Err(corrupt(
                            at,
                            format!("pointer to {target} is not a node of level {}", l - 1),
                        ));
                    }
                }
                off = end;
            }
            if l == top && starts.len() != 1 {
                return Err(corrupt(bases[l], format!("{} root nodes", starts.len())));
            }
            below = Some(starts);
        }
        Ok(())
    }

    /// Whether voxel (x, y, z) is set: walks the encoded bytes mapping the query point into each
    /// stored node's frame (inverse translation, then inverse transform), the point form of the
    /// translation stack.
    pub fn contains(&self, x: u32, y: u32, z: u32) -> Result<bool, EncodeError> {
        let n = self.resolution;
        let Some(root_t) = self.root else {
            return Ok(false);
        };
        if x >= n || y >= n || z >= n {
            return Ok(false);
        }
        let mut p = root_t.inverse().apply_point([x, y, z], n);
        let mut index = 0u64;
        let mut size = n;
        for level in (1..self.levels.len()).rev() {
            let half = size / 2;
            let o = ((p[0] / half) | (p[1] / half) << 1 | (p[2] / half) << 2) as usize;
            let (ptrs, _) = read_node(&self.levels[level], index as usize, 3, 0)?;
            let Some((v, code)) = ptrs[o] else {
                return Ok(false);
            };
            let (target, t, tr) = self.decode_pointer(level as u32 - 1, v, code)?;
            let mut q = [0u32; 3];
            for a in 0..3 {
                let c = (p[a] % half) as i64 - tr[a] as i64;
                if c < 0 || c >= half as i64 {
                    return Ok(false);
                }
                q[a] = c as u32;
            }
            p = t.inverse().apply_point(q, half);
            index = target;
            size = half;
        }
        let mask = *self
            .leaves
            .get(index as usize)
            .ok_or_else(|| corrupt(0, "leaf index out of range"))?;
        Ok(mask >> morton::encode(p[0], p[1], p[2]) & 1 == 1)
    }

    /// Calls `f` with the local coordinates of every voxel of stored node `index` at `level`.
    fn for_each_stored_voxel(
        &self,
        index: u64,
        level: u32,
        origin: [u32; 3],
        f: &mut impl FnMut([u32; 3]),
    ) -> Result<(), EncodeError> {
        let node = TNode::Stored {
            index,
            transform: Transform::IDENTITY,
            translation: [0; 3],
        };
        self.for_each_voxel_of(&node, level, origin, f)
    }

    fn for_each_voxel_of(
        &self,
        node: &TNode,
        level: u32,
        origin: [u32; 3],
        f: &mut impl FnMut([u32; 3]),
    ) -> Result<(), EncodeError> {
        if level == 0 {
            let mut m = self.leaf(node)?;
            while m != 0 {
                let [x, y, z] = morton::decode(m.trailing_zeros() as u64);
                f([origin[0] + x, origin[1] + y, origin[2] + z]);
                m &= m - 1;
            }
            return Ok(());
        }
        let half = 2u32 << level;
        for (o, c) in self.children(node, level)?.iter().enumerate() {
            if let Some(c) = c {
                let o = o as u32;
                let child_origin = [
                    origin[0] + (o & 1) * half,
                    origin[1] + ((o >> 1) & 1) * half,
                    origin[2] + (o >> 2) * half,
                ];
                self.for_each_voxel_of(c, level - 1, child_origin, f)?;
            }
        }
        Ok(())
    }

    /// Materialises `Shift_t(T(C))` for stored node `index` at `level` as a Morton-indexed grid.
    fn materialise(
        &self,
        index: u64,
        level: u32,
        t: Transform,
        tr: [i32; 3],
    ) -> Result<Arc<Vec<u64>>, EncodeError> {
        if level > MAX_TRANSLATION_LEVEL {
            return Err(corrupt(0, format!("translated node at level {level}")));
        }
        let side = 4u32 << level;
        let mut grid = vec![0u64; (side as usize).pow(3) / 64];
        self.for_each_stored_voxel(index, level, [0; 3], &mut |v| {
            let w = t.apply_point(v, side);
            let mut q = [0u32; 3];
            for a in 0..3 {
                let c = w[a] as i64 + tr[a] as i64;
                if c < 0 || c >= side as i64 {
                    return;
                }
                q[a] = c as u32;
            }
            let code = morton::encode(q[0], q[1], q[2]);
            grid[(code / 64) as usize] |= 1 << (code % 64);
        })?;
        Ok(Arc::new(grid))
    }
}

/// Checks the pointers of a graph: transforms in the set, translations only where allowed and
/// in range, child indices in range.
fn check_graph(g: &TransformGraph) -> Result<(), EncodeError> {
    for l in 1..g.levels.len() {
        let cl = (l - 1) as u32;
        let side = 4i32 << cl;
        let below = g.levels[l - 1].len();
        for c in &g.levels[l].children {
            if !g.set.contains(c.transform) {
                return Err(EncodeError::InvalidInput(format!(
                    "transform {} outside the set at level {l}",
                    c.transform.index()
                )));
            }
            if c.translation != [0; 3] && !(g.translations && cl <= MAX_TRANSLATION_LEVEL) {
                return Err(EncodeError::InvalidInput(format!(
                    "translation at level {cl}, where none is allowed"
                )));
            }
            if c.translation
                .iter()
                .any(|&t| i32::from(t) <= -side || i32::from(t) >= side)
            {
                return Err(EncodeError::InvalidInput(format!(
                    "translation {:?} out of range at level {cl}",
                    c.translation
                )));
            }
            if c.node as usize >= below {
                return Err(EncodeError::InvalidInput(format!(
                    "child {} out of range at level {cl}",
                    c.node
                )));
            }
        }
    }
    Ok(())
}

/// Stores every node of a (checked) graph in the orientation of its most frequent untranslated
/// reference, top-down: node `C` becomes `R(C)` and every pointer `(C, T, t)` becomes
/// `(R(C), T ∘ R⁻¹, t)`, so that those references turn into plain pointers. The graph means
/// the same voxels and has the same number of stored nodes per level.
/// Takes the graph by value and rebuilds it level by level, so about one graph is in memory.
pub fn reorient(g: TransformGraph) -> TransformGraph {
    let top = g.levels.len() - 1;
    let mut orient: Vec<Vec<Transform>> = g
        .levels
        .iter()
        .map(|l| vec![Transform::IDENTITY; l.len()])
        .collect();
    let Some(root) = g.root else {
        return g;
    };
    orient[top][root.node as usize] = root.transform;
    for l in (1..=top).rev() {
        // Votes `node << 6 | transform` of the untranslated pointers as the re-oriented
        // parents see them; the most frequent transform per child wins (ties: smallest id).
        let level = &g.levels[l];
        let mut votes: Vec<u64> = Vec::with_capacity(level.children.len());
        for n in 0..level.len() {
            let r = orient[l][n];
            for c in level.node_children(n) {
                if c.translation == [0; 3] {
                    votes.push((c.node as u64) << 6 | r.compose(c.transform).index() as u64);
                }
            }
        }
        votes.sort_unstable();
        let below = &mut orient[l - 1];
        let mut best_count = vec![0u32; below.len()];
        let mut i = 0;
        while i < votes.len() {
            let mut j = i + 1;
            while j < votes.len() && votes[j] == votes[i] {
                j += 1;
            }
            let node = (votes[i] >> 6) as usize;
            let run = (j - i) as u32;
            if run > best_count[node] {
                best_count[node] = run;
                below[node] = Transform::from_index((votes[i] & 63) as usize).expect("id < 48");
            }
            i = j;
        }
    }
    let levels = g
        .levels
        .into_iter()
        .enumerate()
        .map(|(l, level)| {
            if l == 0 {
                let leaves = level
                    .leaves
                    .iter()
                    .zip(&orient[0])
                    .map(|(&m, r)| r.apply_leaf(m))
                    .collect();
                return GraphLevel {
                    leaves,
                    ..GraphLevel::default()
                };
            }
            let mut out = GraphLevel {
                leaves: Vec::new(),
                child_masks: Vec::with_capacity(level.len()),
                child_starts: Vec::with_capacity(level.len()),
                children: Vec::with_capacity(level.children.len()),
            };
            for n in 0..level.len() {
                let r = orient[l][n];
                let mut slots = [None; 8];
                let mut k = 0;
                for o in 0..8 {
                    if (level.child_masks[n] >> o) & 1 == 1 {
                        let c = level.node_children(n)[k];
                        k += 1;
                        let child_r = orient[l - 1][c.node as usize];
                        slots[r.apply_octant(o)] = Some(GraphPointer {
                            node: c.node,
                            transform: r.compose(c.transform).compose(child_r.inverse()),
                            translation: apply_to_vector(r, c.translation),
                        });
                    }
                }
                out.child_starts.push(out.children.len() as u32);
                out.child_masks
                    .push(r.apply_child_mask(level.child_masks[n]));
                out.children.extend(slots.into_iter().flatten());
            }
            out
        })
        .collect();
    TransformGraph {
        resolution: g.resolution,
        set: g.set,
        translations: g.translations,
        levels,
        root: Some(GraphPointer {
            node: root.node,
            transform: Transform::IDENTITY,
            translation: [0; 3],
        }),
    }
}

/// Orders the stored nodes of every level top-down, dropping unreferenced ones: descending
/// reference count, then (with `tie_break`) descending untranslated references and fewer
/// children first (smaller nodes give the following nodes smaller offsets), then the old order.
/// Returns per level `new -> old` ids.
fn sort_nodes(
    g: &TransformGraph,
    counts: &[usize],
    root: usize,
    tie_break: bool,
) -> Vec<Vec<usize>> {
    let top = counts.len() - 1;
    let mut order: Vec<Vec<usize>> = vec![Vec::new(); counts.len()];
    order[top] = vec![root];
    for l in (0..top).rev() {
        let mut refs = vec![0u64; counts[l]];
        let mut plain = vec![0u64; counts[l]];
        for &p in &order[l + 1] {
            for c in g.levels[l + 1].node_children(p) {
                refs[c.node as usize] += 1;
                plain[c.node as usize] += (tie_break && c.translation == [0; 3]) as u64;
            }
        }
        let size = |i: usize| {
            if l == 0 || !tie_break {
                0
            } else {
                g.levels[l].child_masks[i].count_ones()
            }
        };
        let mut ids: Vec<usize> = (0..counts[l]).filter(|&i| refs[i] > 0).collect();
        ids.sort_unstable_by(|&a, &b| {
            refs[b]
                .cmp(&refs[a])
                .then(plain[b].cmp(&plain[a]))
                .then(size(a).cmp(&size(b)))
                .then(a.cmp(&b))
        });
        order[l] = ids;
    }
    order
}

fn nonzero_mask(t: &[i8; 3]) -> usize {
    (t[0] != 0) as usize | ((t[1] != 0) as usize) << 1 | ((t[2] != 0) as usize) << 2
}

impl TreeView for TsvdagEncoding {
    type Node = TNode;

    fn resolution(&self) -> u32 {
        self.resolution
    }

    fn root(&self) -> Result<Option<TNode>, EncodeError> {
        Ok(self.root.map(|t| TNode::Stored {
            index: 0,
            transform: t,
            translation: [0; 3],
        }))
    }

    fn children(&self, node: &TNode, level: u32) -> Result<[Option<TNode>; 8], EncodeError> {
        match node {
            TNode::Dense { grid, base } => {
                let span = 64u64 << (3 * (level - 1));
                Ok(std::array::from_fn(|o| {
                    let start = base + o as u64 * span;
                    let words = grid.get((start / 64) as usize..((start + span) / 64) as usize)?;
                    words.iter().any(|&w| w != 0).then(|| TNode::Dense {
                        grid: grid.clone(),
                        base: start,
                    })
                }))
            }
            TNode::Stored {
                index,
                transform,
                translation,
            } => {
                if *translation != [0; 3] {
                    let grid = self.materialise(*index, level, *transform, *translation)?;
                    let dense = TNode::Dense { grid, base: 0 };
                    return self.children(&dense, level);
                }
                let stream = self
                    .levels
                    .get(level as usize)
                    .ok_or_else(|| corrupt(0, format!("no level {level}")))?;
                let (ptrs, _) = read_node(stream, *index as usize, 3, 0)?;
                let mut out: [Option<TNode>; 8] = Default::default();
                for (o, p) in ptrs.iter().enumerate() {
                    if let Some((v, code)) = p {
                        let (target, t, tr) = self.decode_pointer(level - 1, *v, *code)?;
                        out[transform.apply_octant(o)] = Some(TNode::Stored {
                            index: target,
                            transform: transform.compose(t),
                            translation: apply_to_vector(*transform, tr),
                        });
                    }
                }
                Ok(out)
            }
        }
    }

    fn leaf(&self, node: &TNode) -> Result<u64, EncodeError> {
        match node {
            TNode::Dense { grid, base } => grid
                .get((base / 64) as usize)
                .copied()
                .ok_or_else(|| corrupt(0, "dense window out of range")),
            TNode::Stored {
                index,
                transform,
                translation,
            } => {
                if *translation != [0; 3] {
                    return Ok(self.materialise(*index, 0, *transform, *translation)?[0]);
                }
                let mask = *self
                    .leaves
                    .get(*index as usize)
                    .ok_or_else(|| corrupt(0, format!("leaf index {index} out of range")))?;
                Ok(transform.apply_leaf(mask))
            }
        }
    }

    /// Stored handles: index, transform id (6 bits), translation + 16 (5 bits per axis).
    fn packed(&self, node: &TNode) -> Option<u64> {
        match node {
            TNode::Stored {
                index,
                transform,
                translation,
            } if *index < 1 << 43 && translation.iter().all(|t| (-16..16).contains(t)) => {
                let t = translation
                    .iter()
                    .fold(0u64, |v, &t| v << 5 | (t + 16) as u64);
                Some(index << 21 | (transform.index() as u64) << 15 | t)
            }
            _ => None,
        }
    }
}

impl TsvdagEncoding {
    /// Voxels below every node, by u16 position in its level's stream: at a node's header word
    /// the voxels of the stored node, at the first word of a translated pointer the voxels the
    /// translated subtree keeps in its cell (the destructive translation drops some), other
    /// positions 0; level 0 empty.
    pub fn stream_voxel_counts(&self) -> Result<Vec<Vec<u64>>, EncodeError> {
        self.voxel_counts(false)
    }

    /// [`TsvdagEncoding::stream_voxel_counts`] plus, at the first word of every pointer, the
    /// voxels of the subtree it leads to: what the GPU colour index sums (`render::format`).
    pub fn pointer_voxel_counts(&self) -> Result<Vec<Vec<u64>>, EncodeError> {
        self.voxel_counts(true)
    }

    fn voxel_counts(&self, every_pointer: bool) -> Result<Vec<Vec<u64>>, EncodeError> {
        let mut counts: Vec<Vec<u64>> = vec![Vec::new(); self.levels.len()];
        let mut shifted: FxHashMap<(u32, u64, u8, [i32; 3]), u64> = FxHashMap::default();
        for l in 1..self.levels.len() {
            let stream = &self.levels[l];
            let cl = l as u32 - 1;
            let mut here = vec![0u64; stream.len()];
            let mut off = 0;
            while off < stream.len() {
                let (ptrs, end) = read_node(stream, off, 3, 0)?;
                let mut at = off + 1;
                let mut sum = 0u64;
                for (v, code) in ptrs.into_iter().flatten() {
                    let (target, t, tr) = self.decode_pointer(cl, v, code)?;
                    let n = if tr != [0; 3] {
                        let key = (cl, target, t.index() as u8, tr);
                        let n = match shifted.get(&key) {
                            Some(&n) => n,
                            None => {
                                let grid = self.materialise(target, cl, t, tr)?;
                                let n = grid.iter().map(|w| w.count_ones() as u64).sum();
                                shifted.insert(key, n);
                                n
                            }
                        };
                        here[at] = n;
                        n
                    } else if l == 1 {
                        self.leaves
                            .get(target as usize)
                            .ok_or_else(|| corrupt(0, "leaf index out of range"))?
                            .count_ones() as u64
                    } else {
                        *counts[l - 1]
                            .get(target as usize)
                            .ok_or_else(|| corrupt(0, "node offset out of range"))?
                    };
                    if every_pointer {
                        here[at] = n;
                    }
                    sum += n;
                    at += code as usize;
                }
                here[off] = sum;
                off = end;
            }
            counts[l] = here;
        }
        Ok(counts)
    }

    /// Per child level with a Huffman code: `(kind, per code length 0..=15 the number of codes,
    /// symbols sorted by (length, symbol))`, kind 0 no code, 1 one implied symbol (then the
    /// symbol list holds it), 2 a code: the canonical decoder's tables (`Huffman::decode`).
    pub fn huffman_tables(&self) -> Vec<(u32, [u32; 16], Vec<u16>)> {
        let top = self.levels.len() - 1;
        (0..top)
            .map(|l| match self.codes.get(l).and_then(|c| c.as_ref()) {
                None => (0, [0; 16], Vec::new()),
                Some(h) => match h.single() {
                    Some(s) => (1, [0; 16], vec![s]),
                    None => {
                        let mut count = [0u32; 16];
                        let mut sorted: Vec<u16> = Vec::new();
                        for (s, &len) in h.lengths.iter().enumerate() {
                            if len > 0 {
                                count[len as usize] += 1;
                                sorted.push(s as u16);
                            }
                        }
                        sorted.sort_by_key(|&s| (h.lengths[s as usize], s));
                        (2, count, sorted)
                    }
                },
            })
            .collect()
    }
}
