//! Partitioned build (`docs/scaling.md`): part `i` of `K` builds the levels of the DAG up to a
//! split level for one contiguous range of the subtrees at that level (a separate process, on
//! any machine) and writes them to a `.vdagp` file; [`merge`] deduplicates the parts' nodes in
//! part order and builds the levels above the split, giving the one-machine build's bytes.
//!
//! Why the bytes match: on every level the one-machine build numbers nodes by first occurrence
//! in Morton order. A part's nodes are numbered the same way inside its range, and the ranges
//! ascend with the part index, so inserting the parts' nodes in (part, local id) order into one
//! table per level assigns exactly the global first-occurrence ids.
//!
//! Part file (`.vdagp`, untrusted input: every count is checked against the file length and the
//! memory limit before use, the whole file against its CRC-32), little-endian:
//! ```text
//!  0 magic "VDAGPART"          8 version u32 (1)         12 resolution u32
//! 16 part count K u32          20 part index i u32       24 split level u32
//! 28 colour codec id u32 (u32::MAX: no colours)          32 codec threshold f32
//! 36 colour chunk depth u32    40 voxels u64             48 CRC-32 of the voxel codes u32
//! 52 reserved u32 (0)          56 subtree roots u64      64 colour runs u64
//! 72 colours u64               80 per level 0..=split: nodes u64, words u64
//! then the level words (children: ids into the level below), the subtree roots (key u64,
//! id u32), the colour runs (chunk key u64, colours u64), the colours (RGBA8 u32), and the
//! CRC-32 of everything before it (u32).
//! ```

use std::io::{self, Read, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

use super::encode::{DigestBuilder, EncodedDag, VoxelDigest};
use super::stream::{resolved_chunk_depth, save_streamed, ColorStream, StreamBuilder};
use super::DagError;
use crate::attr::ColorCodec;

/// The part file's magic bytes.
pub const PART_MAGIC: &[u8; 8] = b"VDAGPART";
/// The part file format version.
pub const PART_VERSION: u32 = 1;
/// Bytes of the fixed header (before the level table).
const HEADER: usize = 80;
/// Codec id meaning "no colours".
const NO_COLORS: u32 = u32::MAX;

/// Which subtrees part `index` of `count` builds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PartPlan {
    /// Grid side.
    pub resolution: u32,
    /// Part index, `0..count`.
    pub index: u32,
    /// Number of parts.
    pub count: u32,
    /// Level of the subtree roots (the root level when `count` is 1).
    pub split_level: u32,
    /// Keys (`code >> (6 + 3 split_level)`) of the subtrees this part builds.
    pub keys: Range<u64>,
    /// Morton codes of the voxels this part builds.
    pub codes: Range<u64>,
}

impl PartPlan {
    /// The plan of part `index` of `count` at `resolution`: the subtrees are those `d` levels
    /// below the root, `d` the smallest with `8^d >= count`, one level deeper when the grid
    /// allows (about 8 subtrees per part, so empty space spreads over the parts); part `i`
    /// takes the keys `[i 8^d / K, (i + 1) 8^d / K)`.
    pub fn new(resolution: u32, index: u32, count: u32) -> Result<PartPlan, DagError> {
        if !resolution.is_power_of_two() || !(8..=super::MAX_RESOLUTION).contains(&resolution) {
            return Err(DagError::InvalidResolution(resolution));
        }
        let log = resolution.trailing_zeros();
        let root_level = log - 2;
        let mut depth = 0;
        while 8u64.pow(depth) < count as u64 {
            depth += 1;
        }
        if count == 0 || index >= count || depth > root_level {
            return Err(DagError::InvalidVoxels(format!(
                "part {index}/{count}: the index must be below the count, and a {resolution}^3 \
                 grid has at most {} subtrees to share",
                8u64.pow(root_level)
            )));
        }
        if count > 1 && depth < root_level {
            depth += 1;
        }
        let subtrees = 8u128.pow(depth);
        let key = |i: u32| (i as u128 * subtrees / count as u128) as u64;
        let keys = key(index)..key(index + 1);
        let shift = 3 * (log - depth);
        Ok(PartPlan {
            resolution,
            index,
            count,
            split_level: root_level - depth,
            codes: keys.start << shift..keys.end << shift,
            keys,
        })
    }
}

/// Colours of a part: the codec settings and the colours grouped in runs of one chunk.
struct PartColors {
    codec: ColorCodec,
    depth: u32,
    shift: u32,
    runs: Vec<(u64, u64)>,
    colors: Vec<u32>,
}

/// Builds one part from its voxels (see [`PartPlan`]).
pub struct PartBuilder {
    plan: PartPlan,
    builder: StreamBuilder,
    digest: DigestBuilder,
    colors: Option<PartColors>,
}

impl PartBuilder {
    /// A builder for `plan`; with `colors` (codec, `--chunk-depth`) it keeps the voxels'
    /// colours for the merge, which encodes them.
    pub fn new(
        plan: PartPlan,
        colors: Option<(ColorCodec, Option<u32>)>,
    ) -> Result<PartBuilder, DagError> {
        let builder = StreamBuilder::with_top(plan.resolution, plan.split_level)?;
        let colors = colors.map(|(codec, depth)| {
            let depth = resolved_chunk_depth(codec, depth, plan.resolution);
            PartColors {
                codec,
                depth,
                shift: 3 * (plan.resolution.trailing_zeros() - depth),
                runs: Vec::new(),
                colors: Vec::new(),
            }
        });
        Ok(PartBuilder {
            plan,
            builder,
            digest: DigestBuilder::default(),
            colors,
        })
    }

    /// The part's plan.
    pub fn plan(&self) -> &PartPlan {
        &self.plan
    }

    /// Adds the next voxels (ascending codes; those outside the part's range are skipped; the
    /// colours are ignored without a colour codec).
    pub fn push(&mut self, codes: &[u64], colors: &[u32]) -> Result<(), DagError> {
        if self.colors.is_some() && colors.len() != codes.len() {
            return Err(DagError::InvalidVoxels(format!(
                "{} colours for {} voxels",
                colors.len(),
                codes.len()
            )));
        }
        let from = codes.partition_point(|&c| c < self.plan.codes.start);
        let to = codes.partition_point(|&c| c < self.plan.codes.end);
        let codes = &codes[from..to];
        for &c in codes {
            self.digest.push(c);
        }
        self.builder.push(codes)?;
        if let Some(p) = &mut self.colors {
            let colors = &colors[from..to];
            for (i, &c) in codes.iter().enumerate() {
                let key = c >> p.shift;
                match p.runs.last_mut() {
                    Some((k, n)) if *k == key => *n += 1,
                    _ => p.runs.push((key, 1)),
                }
                p.colors.push(colors[i]);
            }
        }
        Ok(())
    }

    /// Writes the part file atomically.
    pub fn write(self, path: &Path) -> Result<PartSummary, DagError> {
        let voxels = self.builder.voxels();
        let (levels, tops) = self.builder.finish_levels()?;
        let digest = self.digest.finish();
        let plan = &self.plan;
        let mut head = Vec::with_capacity(HEADER + 16 * levels.len());
        head.extend_from_slice(PART_MAGIC);
        for v in [
            PART_VERSION,
            plan.resolution,
            plan.count,
            plan.index,
            plan.split_level,
        ] {
            head.extend_from_slice(&v.to_le_bytes());
        }
        let c = self.colors.as_ref();
        head.extend_from_slice(&c.map_or(NO_COLORS, |c| c.codec.id()).to_le_bytes());
        head.extend_from_slice(&c.map_or(0.0, |c| c.codec.threshold()).to_le_bytes());
        head.extend_from_slice(&c.map_or(0, |c| c.depth).to_le_bytes());
        head.extend_from_slice(&voxels.to_le_bytes());
        head.extend_from_slice(&digest.crc32.to_le_bytes());
        head.extend_from_slice(&0u32.to_le_bytes());
        head.extend_from_slice(&(tops.len() as u64).to_le_bytes());
        head.extend_from_slice(&(c.map_or(0, |c| c.runs.len()) as u64).to_le_bytes());
        head.extend_from_slice(&(c.map_or(0, |c| c.colors.len()) as u64).to_le_bytes());
        for level in &levels {
            head.extend_from_slice(&(level.offsets.len() as u64).to_le_bytes());
            head.extend_from_slice(&(level.words.len() as u64).to_le_bytes());
        }
        let nodes = levels.iter().map(|l| l.offsets.len() as u64).sum();
        super::file::write_atomic(path, |w| {
            let mut w = CrcWriter {
                inner: w,
                crc: crc32fast::Hasher::new(),
            };
            w.write_all(&head)?;
            for level in &levels {
                w.write_all(bytemuck::cast_slice(&level.words))?;
            }
            for &(key, id) in &tops {
                w.write_all(&key.to_le_bytes())?;
                w.write_all(&id.to_le_bytes())?;
            }
            if let Some(c) = c {
                for &(key, n) in &c.runs {
                    w.write_all(&key.to_le_bytes())?;
                    w.write_all(&n.to_le_bytes())?;
                }
                w.write_all(bytemuck::cast_slice(&c.colors))?;
            }
            let crc = w.crc.finalize();
            w.inner.write_all(&crc.to_le_bytes())
        })?;
        Ok(PartSummary {
            voxels,
            nodes,
            subtrees: tops.len() as u64,
        })
    }
}

/// What a written part holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartSummary {
    /// Voxels in the part.
    pub voxels: u64,
    /// Unique nodes of the part, all levels up to the split.
    pub nodes: u64,
    /// Non-empty subtrees of the part.
    pub subtrees: u64,
}

/// A writer that computes the CRC-32 of what passes through.
struct CrcWriter<W: Write> {
    inner: W,
    crc: crc32fast::Hasher,
}

impl<W: Write> Write for CrcWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// The fixed header of a part file.
#[derive(Clone, Debug)]
struct PartHeader {
    plan: PartPlan,
    codec: Option<ColorCodec>,
    chunk_depth: u32,
    voxels: u64,
    codes_crc: u32,
    tops: u64,
    runs: u64,
    colors: u64,
}

/// A part file's error at `offset`.
fn bad(path: &Path, offset: u64, reason: impl Into<String>) -> DagError {
    DagError::Format {
        path: path.to_path_buf(),
        offset,
        reason: reason.into(),
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// Opens a part file: a regular file, its length.
fn open_part(path: &Path) -> Result<(std::fs::File, u64), DagError> {
    let io = |source| DagError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(bad(path, 0, "not a regular file"));
    }
    Ok((file, meta.len()))
}

/// Reads and checks the fixed header of a part file.
fn read_header(path: &Path) -> Result<PartHeader, DagError> {
    let (file, len) = open_part(path)?;
    let mut b = [0u8; HEADER];
    if len < HEADER as u64 + 4 {
        return Err(bad(
            path,
            0,
            format!("{len} bytes: too short for a part file"),
        ));
    }
    file.take(HEADER as u64)
        .read_exact(&mut b)
        .map_err(|source| DagError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    if &b[..8] != PART_MAGIC {
        return Err(bad(path, 0, "bad magic: not a voxdag part file (.vdagp)"));
    }
    let version = u32_at(&b, 8);
    if version != PART_VERSION {
        return Err(bad(
            path,
            8,
            format!("part format version {version}, this voxdag reads {PART_VERSION}"),
        ));
    }
    let (resolution, count, index) = (u32_at(&b, 12), u32_at(&b, 16), u32_at(&b, 20));
    let plan = PartPlan::new(resolution, index, count).map_err(|e| bad(path, 12, e.to_string()))?;
    if u32_at(&b, 24) != plan.split_level {
        return Err(bad(
            path,
            24,
            format!(
                "split level {}, part {index}/{count} at {resolution}^3 splits at {}",
                u32_at(&b, 24),
                plan.split_level
            ),
        ));
    }
    let id = u32_at(&b, 28);
    let threshold = f32::from_le_bytes(b[32..36].try_into().expect("4 bytes"));
    let codec = if id == NO_COLORS {
        None
    } else {
        Some(ColorCodec::from_id(id, threshold).ok_or_else(|| {
            bad(
                path,
                28,
                format!("unknown colour codec {id} (threshold {threshold})"),
            )
        })?)
    };
    let chunk_depth = u32_at(&b, 36);
    if codec.is_some() && chunk_depth > resolution.trailing_zeros() - 2 {
        return Err(bad(path, 36, format!("colour chunk depth {chunk_depth}")));
    }
    let h = PartHeader {
        plan,
        codec,
        chunk_depth,
        voxels: u64_at(&b, 40),
        codes_crc: u32_at(&b, 48),
        tops: u64_at(&b, 56),
        runs: u64_at(&b, 64),
        colors: u64_at(&b, 72),
    };
    if h.codec.is_none() && (h.runs != 0 || h.colors != 0) {
        return Err(bad(path, 64, "colour runs in a part without colours"));
    }
    if h.codec.is_some() && h.colors != h.voxels {
        return Err(bad(
            path,
            72,
            format!("{} colours for {} voxels", h.colors, h.voxels),
        ));
    }
    Ok(h)
}

/// A part file read and checked: its levels (children as ids into the level below), subtree
/// roots and colour runs.
struct Part {
    header: PartHeader,
    levels: Vec<Vec<u32>>,
    counts: Vec<usize>,
    tops: Vec<(u64, u32)>,
    runs: Vec<(u64, u64)>,
    colors: Vec<u32>,
}

/// Reads a whole part file: length against the header's counts and the memory limit, CRC,
/// then every node, root and run checked.
fn read_part(path: &Path) -> Result<Part, DagError> {
    let header = read_header(path)?;
    let (file, len) = open_part(path)?;
    let levels = header.plan.split_level as u64 + 1;
    let table = HEADER as u64 + 16 * levels;
    if len < table + 4 {
        return Err(bad(
            path,
            0,
            format!("{len} bytes: too short for its level table"),
        ));
    }
    let io = |source| DagError::Io {
        path: path.to_path_buf(),
        source,
    };
    // The level table first: the counts must add up to the file before the body is read.
    let mut file = file.take(len);
    let mut bytes = vec![0u8; table as usize];
    file.read_exact(&mut bytes).map_err(io)?;
    let mut need = Some(table + 4);
    let mut sizes = Vec::new();
    for l in 0..levels as usize {
        let (nodes, words) = (
            u64_at(&bytes, HEADER + 16 * l),
            u64_at(&bytes, HEADER + 16 * l + 8),
        );
        sizes.push((nodes, words));
        need = need.and_then(|n| n.checked_add(words.checked_mul(4)?));
    }
    need = need
        .and_then(|n| n.checked_add(header.tops.checked_mul(12)?))
        .and_then(|n| n.checked_add(header.runs.checked_mul(16)?))
        .and_then(|n| n.checked_add(header.colors.checked_mul(4)?));
    if need != Some(len) {
        return Err(bad(
            path,
            HEADER as u64,
            format!("the header's counts do not add up to the file's {len} bytes"),
        ));
    }
    crate::safety::check_memory(format!("{}", path.display()), len)?;
    bytes
        .try_reserve_exact(len as usize - bytes.len())
        .map_err(|e| bad(path, 0, e.to_string()))?;
    file.read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 != len {
        return Err(bad(path, bytes.len() as u64, "the file changed while read"));
    }
    let body = len as usize - 4;
    let stored = u32_at(&bytes, body);
    let crc = crc32fast::hash(&bytes[..body]);
    if crc != stored {
        return Err(bad(
            path,
            body as u64,
            format!("CRC-32 {stored:08x} stored, {crc:08x} computed: the file is corrupt"),
        ));
    }
    let mut at = table as usize;
    let mut out = Vec::with_capacity(levels as usize);
    let mut counts = Vec::with_capacity(levels as usize);
    for (l, &(nodes, words)) in sizes.iter().enumerate() {
        let start = at as u64;
        let w: Vec<u32> = bytes[at..at + 4 * words as usize]
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        at += 4 * words as usize;
        let mut i = 0;
        let mut n = 0u64;
        while i < w.len() {
            let len = if l == 0 {
                if w.len() - i < 2 || (w[i] | w[i + 1]) == 0 {
                    return Err(bad(path, start + 4 * i as u64, format!("bad leaf {n}")));
                }
                2
            } else {
                let mask = w[i];
                let len = 1 + mask.count_ones() as usize;
                if mask == 0 || mask > 0xff || w.len() - i < len {
                    return Err(bad(
                        path,
                        start + 4 * i as u64,
                        format!("bad node {n} of level {l}"),
                    ));
                }
                let below = counts[l - 1] as u32;
                if let Some(c) = w[i + 1..i + len].iter().position(|&c| c >= below) {
                    return Err(bad(
                        path,
                        start + 4 * (i + 1 + c) as u64,
                        format!(
                            "child {} of level {l} node {n} past the {below} nodes below",
                            w[i + 1 + c]
                        ),
                    ));
                }
                len
            };
            i += len;
            n += 1;
        }
        if n != nodes {
            return Err(bad(
                path,
                HEADER as u64 + 16 * l as u64,
                format!("level {l}: {n} nodes in its words, {nodes} in the table"),
            ));
        }
        counts.push(nodes as usize);
        out.push(w);
    }
    let mut tops = Vec::with_capacity(header.tops as usize);
    for t in 0..header.tops as usize {
        let (key, id) = (u64_at(&bytes, at), u32_at(&bytes, at + 8));
        let ascending = tops.last().is_none_or(|&(k, _)| key > k);
        if !ascending
            || !header.plan.keys.contains(&key)
            || id as usize >= *counts.last().expect("a level")
        {
            return Err(bad(
                path,
                at as u64,
                format!(
                    "subtree root {t} (key {key}, node {id}): keys must ascend inside {:?}, nodes exist",
                    header.plan.keys
                ),
            ));
        }
        tops.push((key, id));
        at += 12;
    }
    let mut runs = Vec::with_capacity(header.runs as usize);
    let mut total = 0u64;
    for r in 0..header.runs as usize {
        let (key, n) = (u64_at(&bytes, at), u64_at(&bytes, at + 8));
        if n == 0 || runs.last().is_some_and(|&(k, _)| key <= k) {
            return Err(bad(
                path,
                at as u64,
                format!("colour run {r}: empty or keys not ascending"),
            ));
        }
        total = total.saturating_add(n);
        runs.push((key, n));
        at += 16;
    }
    if total != header.colors {
        return Err(bad(
            path,
            64,
            format!(
                "colour runs hold {total} colours, the header says {}",
                header.colors
            ),
        ));
    }
    let colors = bytes[at..at + 4 * header.colors as usize]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    Ok(Part {
        header,
        levels: out,
        counts,
        tops,
        runs,
        colors,
    })
}

/// What [`merge`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MergeSummary {
    /// Grid side.
    pub resolution: u32,
    /// Parts merged.
    pub parts: u32,
    /// Voxels.
    pub voxels: u64,
    /// Unique nodes of the merged DAG.
    pub nodes: u64,
    /// Bytes of the written file.
    pub bytes: u64,
}

/// Merges the part files of one partitioned build (any order, every part exactly once) into
/// the `.vdag` at `output` (svdag32), byte-identical to the one-machine build with the same
/// options. Refuses a missing, duplicated, foreign or corrupt part, naming it.
pub fn merge(parts: &[PathBuf], output: &Path) -> Result<MergeSummary, DagError> {
    let set = DagError::Parts;
    let Some(first) = parts.first() else {
        return Err(set("no part files given".into()));
    };
    let mut headers: Vec<(PartHeader, &PathBuf)> = Vec::with_capacity(parts.len());
    for path in parts {
        headers.push((read_header(path)?, path));
    }
    let h0 = headers[0].0.clone();
    for (h, path) in &headers {
        let same = h.plan.resolution == h0.plan.resolution
            && h.plan.count == h0.plan.count
            && h.codec.map(|c| (c.id(), c.threshold().to_bits()))
                == h0.codec.map(|c| (c.id(), c.threshold().to_bits()))
            && h.chunk_depth == h0.chunk_depth;
        if !same {
            return Err(set(format!(
                "{} is part {}/{} at {}^3 ({}), {} is part {}/{} at {}^3 ({}): not one build",
                path.display(),
                h.plan.index,
                h.plan.count,
                h.plan.resolution,
                h.codec.map_or("no colours".into(), |c| c.name()),
                first.display(),
                h0.plan.index,
                h0.plan.count,
                h0.plan.resolution,
                h0.codec.map_or("no colours".into(), |c| c.name()),
            )));
        }
    }
    headers.sort_by_key(|(h, _)| h.plan.index);
    for w in headers.windows(2) {
        if w[0].0.plan.index == w[1].0.plan.index {
            return Err(set(format!(
                "{} and {} are both part {}/{}",
                w[0].1.display(),
                w[1].1.display(),
                w[0].0.plan.index,
                h0.plan.count
            )));
        }
    }
    let count = h0.plan.count;
    if let Some(missing) = (0..count).find(|&i| {
        headers
            .get(i as usize)
            .is_none_or(|(h, _)| h.plan.index != i)
    }) {
        return Err(set(format!(
            "part {missing}/{count} is missing ({} of {count} parts given)",
            headers.len()
        )));
    }
    let resolution = h0.plan.resolution;
    let split = h0.plan.split_level;
    let mut builder = StreamBuilder::new(resolution)?;
    let spill_dir = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut colors = match h0.codec {
        Some(codec) => Some(ColorStream::new(
            codec,
            Some(h0.chunk_depth),
            resolution,
            &spill_dir,
        )?),
        None => None,
    };
    let mut crc = crc32fast::Hasher::new();
    let mut voxels = 0u64;
    for (_, path) in &headers {
        let part = read_part(path)?;
        let mut below: Vec<u32> = Vec::new();
        for (l, words) in part.levels.iter().enumerate() {
            let mut ids = Vec::with_capacity(part.counts[l]);
            let mut i = 0;
            let mut node = [0u32; 9];
            while i < words.len() {
                let len = if l == 0 {
                    2
                } else {
                    1 + words[i].count_ones() as usize
                };
                node[..len].copy_from_slice(&words[i..i + len]);
                if l > 0 {
                    for c in &mut node[1..len] {
                        *c = below[*c as usize];
                    }
                }
                ids.push(builder.dedup(l as u32, &node[..len])?);
                i += len;
            }
            below = ids;
        }
        for &(key, id) in &part.tops {
            builder.completed(split, key, below[id as usize])?;
        }
        builder.add_voxels(part.header.voxels);
        voxels += part.header.voxels;
        crc.combine(&crc32fast::Hasher::new_with_initial_len(
            part.header.codes_crc,
            8 * part.header.voxels,
        ));
        if let Some(stream) = &mut colors {
            let mut from = 0;
            for &(key, n) in &part.runs {
                stream.push_run(key, &part.colors[from..from + n as usize])?;
                from += n as usize;
            }
        }
    }
    let digest = VoxelDigest {
        voxels,
        crc32: crc.finalize(),
    };
    let colors = match colors {
        Some(c) => c.finish()?,
        None => None,
    };
    let built = builder.finish()?;
    let nodes = built.dag.stats().levels.iter().map(|l| l.svdag).sum();
    let encoded = EncodedDag::Svdag32(built.dag);
    save_streamed(
        output,
        &encoded,
        &digest,
        colors,
        built.voxels,
        built.dag_hash,
    )?;
    let bytes = std::fs::metadata(output)
        .map_err(|source| DagError::Io {
            path: output.to_path_buf(),
            source,
        })?
        .len();
    Ok(MergeSummary {
        resolution,
        parts: count,
        voxels,
        nodes,
        bytes,
    })
}
