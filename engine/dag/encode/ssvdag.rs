//! SSVDAG encoding (Villanueva, Marton, Gobbetti 2016): 4^3 leaves as 64-bit masks; inner nodes
//! as a 16-bit header with 2 bits per child (00 empty, 01 16-bit pointer, 10 32-bit pointer)
//! followed by the pointers in ascending octant order; a pointer is `target << 3 | mirror`,
//! `target` being a leaf index (children of level 1) or a node offset in 16-bit units.

#![allow(clippy::needless_range_loop)] // levels index several parallel arrays

use super::bytes::{Reader, Writer};
use super::traverse::{root_level, TreeView};
use super::{corrupt, EncodeError};
use crate::dag::ssvdag::{Invariance, Ssvdag, SymmetryPointer};
use crate::dag::transform::Transform;
use crate::dag::Svdag;

/// An SSVDAG in its 16/32-bit pointer encoding (layout in `docs/encodings.md`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SsvdagEncoding {
    /// Grid side length.
    pub resolution: u32,
    /// Stored 4^3 leaves (sorted by reference count).
    pub leaves: Vec<u64>,
    /// Node streams of the inner levels in 16-bit units; entry 0 (the leaf level) is empty.
    pub levels: Vec<Vec<u16>>,
    /// Whether the scene has no voxel (then every stream is empty).
    pub empty: bool,
}

/// Mirrors a 2^3 block (bit = octant) by `m`.
fn mirror8(mask: u8, m: u8) -> u8 {
    (0..8u8).fold(0, |out, o| out | (((mask >> o) & 1) << (o ^ m)))
}

/// Orders the nodes of every level by descending reference count (ties: old order), top-down,
/// dropping unreferenced nodes. `refs(level, node)` lists a node's children ids (level - 1).
/// Returns per level `new -> old` ids.
pub(crate) fn sort_by_refcount(
    counts: &[usize],
    root: usize,
    refs: impl Fn(usize, usize) -> Vec<usize>,
) -> Vec<Vec<usize>> {
    let top = counts.len() - 1;
    let mut order: Vec<Vec<usize>> = vec![Vec::new(); counts.len()];
    order[top] = vec![root];
    for l in (0..top).rev() {
        let mut count = vec![0u64; counts[l]];
        for &p in &order[l + 1] {
            for c in refs(l + 1, p) {
                count[c] += 1;
            }
        }
        let mut ids: Vec<usize> = (0..counts[l]).filter(|&i| count[i] > 0).collect();
        ids.sort_by(|&a, &b| count[b].cmp(&count[a]).then(a.cmp(&b)));
        order[l] = ids;
    }
    order
}

/// The pointers of one node by stored octant: `(value, size code)`.
pub(crate) type NodePointers = [Option<(u64, u8)>; 8];

/// Parses the node at `off` of a 2-bit-header stream: `(header, per stored octant the pointer
/// value, end offset)`. `max_code` is the largest size code allowed (2: 16/32-bit, 3: also 48).
pub(crate) fn read_node(
    stream: &[u16],
    off: usize,
    max_code: u16,
    byte_base: u64,
) -> Result<(NodePointers, usize), EncodeError> {
    let at = |i: usize| byte_base + 2 * i as u64;
    let header = *stream
        .get(off)
        .ok_or_else(|| corrupt(at(off), "node offset past the end of its level"))?;
    if header == 0 {
        return Err(corrupt(at(off), "inner node without children"));
    }
    let mut out = [None; 8];
    let mut p = off + 1;
    for (o, slot) in out.iter_mut().enumerate() {
        let code = (header >> (2 * o)) & 3;
        if code == 0 {
            continue;
        }
        if code > max_code {
            return Err(corrupt(at(off), format!("pointer size code {code}")));
        }
        let n = code as usize;
        let words = stream
            .get(p..p + n)
            .ok_or_else(|| corrupt(at(p), "pointer runs past the end of its level"))?;
        let v = words
            .iter()
            .rev()
            .fold(0u64, |acc, &w| acc << 16 | w as u64);
        *slot = Some((v, code as u8));
        p += n;
    }
    Ok((out, p))
}

/// Checks a level stream: a sequence of whole nodes; returns the node start offsets.
fn node_starts(stream: &[u16], max_code: u16, byte_base: u64) -> Result<Vec<u32>, EncodeError> {
    let mut starts = Vec::new();
    let mut off = 0;
    while off < stream.len() {
        starts.push(off as u32);
        off = read_node(stream, off, max_code, byte_base)?.1;
    }
    Ok(starts)
}

impl SsvdagEncoding {
    /// Builds the SSVDAG (published 3-bit invariance) of an SVDAG and encodes it.
    pub fn build(dag: &Svdag) -> Result<SsvdagEncoding, EncodeError> {
        let ss = Ssvdag::build(dag, Invariance::Axes3);
        Self::encode(&ss, dag.resolution)
    }

    /// Encodes a built SSVDAG.
    pub fn encode(ss: &Ssvdag, resolution: u32) -> Result<SsvdagEncoding, EncodeError> {
        let top = root_level(resolution) as usize;
        let mut out = SsvdagEncoding {
            resolution,
            leaves: Vec::new(),
            levels: vec![Vec::new(); top + 1],
            empty: true,
        };
        if ss.levels.len() != top + 1 || ss.levels[top].nodes.is_empty() {
            return Ok(out);
        }
        out.empty = false;
        let root = ss.levels[top].svdag_nodes[0].node as usize;
        let counts: Vec<usize> = ss.levels.iter().map(|l| l.nodes.len()).collect();
        let order = sort_by_refcount(&counts, root, |l, n| {
            ss.levels[l].nodes[n]
                .iter()
                .filter(|c| c.node != u32::MAX)
                .map(|c| c.node as usize)
                .collect()
        });
        // Leaves: the 64-bit mask of each stored level-0 node.
        let mut new_id = vec![u64::MAX; counts[0]];
        for (i, &old) in order[0].iter().enumerate() {
            let node = &ss.levels[0].nodes[old];
            let mask = (0..8).fold(0u64, |m, o| {
                let c: SymmetryPointer = node[o];
                m | (mirror8(c.node as u8, c.mirror) as u64) << (8 * o)
            });
            out.leaves.push(mask);
            new_id[old] = i as u64;
        }
        for l in 1..=top {
            let mut stream: Vec<u16> = Vec::new();
            let mut offsets = vec![u64::MAX; counts[l]];
            for &old in &order[l] {
                offsets[old] = stream.len() as u64;
                let header_at = stream.len();
                stream.push(0);
                let mut header = 0u16;
                for (o, c) in ss.levels[l].nodes[old].iter().enumerate() {
                    if c.node == u32::MAX {
                        continue;
                    }
                    let v = new_id[c.node as usize] << 3 | c.mirror as u64;
                    if v <= 0xffff {
                        stream.push(v as u16);
                        header |= 1 << (2 * o);
                    } else if v <= u32::MAX as u64 {
                        stream.push(v as u16);
                        stream.push((v >> 16) as u16);
                        header |= 2 << (2 * o);
                    } else {
                        return Err(EncodeError::TooLarge(format!(
                            "SSVDAG pointer {v:#x} at level {l} needs more than 32 bits"
                        )));
                    }
                }
                stream[header_at] = header;
            }
            out.levels[l] = stream;
            new_id = offsets;
        }
        Ok(out)
    }

    /// Bytes of the payload (`to_payload().len()`).
    pub fn byte_size(&self) -> u64 {
        8 + 8 * self.levels.len() as u64
            + 8 * self.leaves.len() as u64
            + self.levels.iter().map(|l| 2 * l.len() as u64).sum::<u64>()
    }

    /// Serialises the payload (layout in `docs/encodings.md`).
    pub fn to_payload(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.u32(self.levels.len() as u32);
        w.u32(self.empty as u32);
        w.u64(self.leaves.len() as u64);
        for l in &self.levels[1..] {
            w.u64(l.len() as u64);
        }
        w.u64s(&self.leaves);
        for l in &self.levels[1..] {
            w.u16s(l);
        }
        w.bytes
    }

    /// Parses and validates a payload for a grid of side `resolution` (already validated).
    pub fn from_payload(bytes: &[u8], resolution: u32) -> Result<SsvdagEncoding, EncodeError> {
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
        if flags > 1 {
            return Err(corrupt(4, format!("unknown flags {flags:#x}")));
        }
        let leaf_count = r.u64("leaf count")?;
        let mut counts = Vec::new();
        for _ in 1..=top {
            counts.push(r.u64("level length")?);
        }
        let leaves = r.u64s(leaf_count, "leaves")?;
        let mut levels = vec![Vec::new()];
        let mut bases = vec![0u64];
        for &c in &counts {
            bases.push(r.at as u64);
            levels.push(r.u16s(c, "level stream")?);
        }
        r.finish()?;
        let enc = SsvdagEncoding {
            resolution,
            leaves,
            levels,
            empty: flags == 1,
        };
        enc.validate(&bases)?;
        Ok(enc)
    }

    /// Structural checks: whole nodes, pointers to node starts one level down, a single root.
    fn validate(&self, bases: &[u64]) -> Result<(), EncodeError> {
        let top = self.levels.len() - 1;
        if self.empty {
            if !self.leaves.is_empty() || self.levels.iter().any(|l| !l.is_empty()) {
                return Err(corrupt(4, "empty scene with stored nodes"));
            }
            return Ok(());
        }
        if let Some(i) = self.leaves.iter().position(|&m| m == 0) {
            return Err(corrupt(
                bases[1] - 8 * (self.leaves.len() - i) as u64,
                "empty leaf",
            ));
        }
        let mut below: Option<Vec<u32>> = None;
        for l in 1..=top {
            let starts = node_starts(&self.levels[l], 2, bases[l])?;
            for &s in &starts {
                let (ptrs, _) = read_node(&self.levels[l], s as usize, 2, bases[l])?;
                for (v, _) in ptrs.into_iter().flatten() {
                    let target = v >> 3;
                    let ok = match &below {
                        None => target < self.leaves.len() as u64,
                        Some(st) => {
                            st.binary_search(&(target as u32)).is_ok() && target <= u32::MAX as u64
                        }
                    };
                    if !ok {
                        return Err(corrupt(
                            bases[l] + 2 * s as u64,
                            format!("pointer to {target} is not a node of level {}", l - 1),
                        ));
                    }
                }
            }
            if l == top && starts.len() != 1 {
                return Err(corrupt(bases[l], format!("{} root nodes", starts.len())));
            }
            below = Some(starts);
        }
        Ok(())
    }
}

impl TreeView for SsvdagEncoding {
    /// (leaf index or node offset, mirror bits).
    type Node = (u64, u8);

    fn resolution(&self) -> u32 {
        self.resolution
    }

    fn root(&self) -> Result<Option<(u64, u8)>, EncodeError> {
        Ok((!self.empty).then_some((0, 0)))
    }

    fn children(
        &self,
        node: &(u64, u8),
        level: u32,
    ) -> Result<[Option<(u64, u8)>; 8], EncodeError> {
        let stream = self
            .levels
            .get(level as usize)
            .ok_or_else(|| corrupt(0, format!("no level {level}")))?;
        let (ptrs, _) = read_node(stream, node.0 as usize, 2, 0)?;
        let m = node.1 & 7;
        let mut out = [None; 8];
        for (o, p) in ptrs.iter().enumerate() {
            if let Some((v, _)) = p {
                out[o ^ m as usize] = Some((v >> 3, m ^ (*v as u8 & 7)));
            }
        }
        Ok(out)
    }

    fn leaf(&self, node: &(u64, u8)) -> Result<u64, EncodeError> {
        let mask = *self
            .leaves
            .get(node.0 as usize)
            .ok_or_else(|| corrupt(0, format!("leaf index {} out of range", node.0)))?;
        let t = Transform::from_parts(0, node.1 & 7).expect("mirror below 8");
        Ok(t.apply_leaf(mask))
    }

    fn packed(&self, &(index, mirror): &(u64, u8)) -> Option<u64> {
        (index < 1 << 61).then_some(index << 3 | mirror as u64)
    }
}

impl SsvdagEncoding {
    /// Voxels below every node, by u16 position in its level's stream (the node's header word;
    /// other positions 0), level 0 empty.
    pub fn stream_voxel_counts(&self) -> Result<Vec<Vec<u64>>, EncodeError> {
        self.voxel_counts(false)
    }

    /// [`SsvdagEncoding::stream_voxel_counts`] plus, at the first word of every pointer, the
    /// voxels of the subtree it leads to: what the GPU colour index sums (`render::format`).
    pub fn pointer_voxel_counts(&self) -> Result<Vec<Vec<u64>>, EncodeError> {
        self.voxel_counts(true)
    }

    fn voxel_counts(&self, every_pointer: bool) -> Result<Vec<Vec<u64>>, EncodeError> {
        let mut counts: Vec<Vec<u64>> = vec![Vec::new(); self.levels.len()];
        for l in 1..self.levels.len() {
            let stream = &self.levels[l];
            let mut here = vec![0u64; stream.len()];
            let mut off = 0;
            while off < stream.len() {
                let (ptrs, end) = read_node(stream, off, 2, 0)?;
                let mut sum = 0u64;
                let mut at = off + 1;
                for (v, code) in ptrs.into_iter().flatten() {
                    let target = (v >> 3) as usize;
                    let n = if l == 1 {
                        self.leaves
                            .get(target)
                            .ok_or_else(|| corrupt(0, "leaf index out of range"))?
                            .count_ones() as u64
                    } else {
                        *counts[l - 1]
                            .get(target)
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
}
