//! The `.vdag` v1 file format (byte-exact description in `docs/vdag-format.md`).
//!
//! Little-endian: a 64-byte header, a section table (24 bytes per section), 8-byte aligned
//! sections (level starts, node words, colours) and a trailing CRC-32 of every byte before it.
//! Loading checks every size and offset against the real file length before allocating, then
//! validates the DAG structure, so a corrupt file is an error, never a panic or a loop.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use super::digest::{attributes_hash, chunked_colors_hash, ContentDigest, CONTENT_DIGEST_LEN};
use super::encode::{
    EncodeError, EncodedDag, EncodingKind, SsvdagEncoding, TsvdagEncoding, VoxelDigest,
};
use super::validate::Place;
use super::{DagError, Svdag, MAX_RESOLUTION};
use crate::attr::{AttrError, ChunkedColors, ColorCodec, Materials, StoredColors};
use rayon::prelude::*;

/// The 8 bytes every `.vdag` file starts with.
pub const MAGIC: [u8; 8] = *b"VOXDAG\0\x01";
/// The format version this code writes (2: tsvdag payloads may use compact translation fields,
/// payload flag bit 4). Versions `OLDEST_FORMAT_VERSION..=FORMAT_VERSION` are read.
pub const FORMAT_VERSION: u32 = 2;
/// The oldest format version this code reads.
pub const OLDEST_FORMAT_VERSION: u32 = 1;
/// Header size in bytes.
const HEADER_LEN: u64 = 64;
/// Bytes per section-table entry.
const ENTRY_LEN: u64 = 24;
/// Most sections a file may list (bounds the table before it is read).
const MAX_SECTIONS: u32 = 64;
/// Section id: `level_count` u64 word offsets, `level_starts[0]` (leaves) first.
const SECTION_LEVELS: u32 = 1;
/// Section id: `word_count` u32 node words.
const SECTION_WORDS: u32 = 2;
/// Section id: `color_count` attribute values in the colour format.
const SECTION_COLORS: u32 = 3;
/// Section id: voxel digest (u64 voxel count, u32 CRC-32 of the Morton codes, u32 zero).
const SECTION_DIGEST: u32 = 4;
/// Section id: the encoded node payload of an ssvdag/tsvdag file.
const SECTION_PAYLOAD: u32 = 5;
/// Section id: chunked encoded colours (colour format 2; layout in `docs/vdag-format.md`).
const SECTION_CHUNKED_COLORS: u32 = 6;
/// Section id: content digest (canonical DAG hash and colour hash, `dag::digest`).
const SECTION_CONTENT_DIGEST: u32 = 7;
/// Section id: materials (palette and 4-bit ids; layout in `docs/vdag-format.md`).
const SECTION_MATERIALS: u32 = 8;
/// Known section ids are `1..=KNOWN_SECTIONS`.
const KNOWN_SECTIONS: usize = 8;
/// Bytes of the fixed fields at the start of the material section (with the 16-entry palette).
const MATERIALS_HEADER_LEN: u64 = 80;
/// Bytes of the fixed fields at the start of the chunked colour section.
const CHUNKED_HEADER_LEN: u64 = 40;

/// Node encoding of the words section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Encoding {
    /// `Svdag::words` unchanged (32-bit masks and pointers).
    Svdag32 = 0,
    /// SSVDAG with 16/32-bit pointers (payload layout in `docs/encodings.md`).
    Ssvdag = 1,
    /// TSVDAG (payload layout in `docs/encodings.md`).
    Tsvdag = 2,
}

impl Encoding {
    /// The CLI name.
    pub fn name(self) -> &'static str {
        EncodingKind::from(self).name()
    }
}

impl From<EncodingKind> for Encoding {
    fn from(k: EncodingKind) -> Encoding {
        match k {
            EncodingKind::Svdag32 => Encoding::Svdag32,
            EncodingKind::Ssvdag => Encoding::Ssvdag,
            EncodingKind::Tsvdag => Encoding::Tsvdag,
        }
    }
}

impl From<Encoding> for EncodingKind {
    fn from(e: Encoding) -> EncodingKind {
        match e {
            Encoding::Svdag32 => EncodingKind::Svdag32,
            Encoding::Ssvdag => EncodingKind::Ssvdag,
            Encoding::Tsvdag => EncodingKind::Tsvdag,
        }
    }
}

/// Encoding of the per-voxel colour section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum ColorFormat {
    /// No colours (the section is empty).
    None = 0,
    /// One RGBA8 u32 per voxel, depth-first Morton order.
    Rgba8 = 1,
    /// Encoded colour chunks in the chunked colour section (`attr::ChunkedColors`).
    Chunked = 2,
}

/// The chunked colour section's bytes (layout in `docs/vdag-format.md`).
fn stored_colors_bytes(stored: &StoredColors) -> Vec<u8> {
    let c = &stored.chunks;
    let mut b = Vec::with_capacity(c.byte_size() as usize + CHUNKED_HEADER_LEN as usize);
    b.extend_from_slice(&c.codec.id().to_le_bytes());
    b.extend_from_slice(&(c.format as u32).to_le_bytes());
    b.extend_from_slice(&c.chunk_depth.to_le_bytes());
    b.extend_from_slice(&c.codec.threshold().to_le_bytes());
    b.extend_from_slice(&stored.rmse.to_le_bytes());
    b.extend_from_slice(&(c.chunk_count() as u64).to_le_bytes());
    b.extend_from_slice(&(c.words.len() as u64).to_le_bytes());
    for v in c.chunk_starts.iter().chain(&c.chunk_offsets) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for w in &c.words {
        b.extend_from_slice(&w.to_le_bytes());
    }
    b
}

/// Parses and validates the chunked colour section at `at` (`len` bytes, inside `bytes`) of a
/// file with `color_count` colours and root level `root_level`; sizes are checked before
/// allocating. Every chunk is decoded (a corrupt one is an error naming its offset); returns
/// the section and, with `keep_decoded`, the decoded colours (otherwise empty: each chunk is
/// dropped once checked, so a scene whose colours exceed memory still loads).
fn parse_stored_colors(
    bytes: &[u8],
    (at, len): (u64, u64),
    color_count: u64,
    root_level: u32,
    name: &Path,
    keep_decoded: bool,
) -> Result<(StoredColors, Vec<u32>), DagError> {
    let err = |offset: u64, reason: String| DagError::Format {
        path: name.to_path_buf(),
        offset,
        reason,
    };
    if len < CHUNKED_HEADER_LEN {
        return Err(err(at, format!("chunked colour section of {len} bytes")));
    }
    let (codec_id, format_id) = (u32_at(bytes, at), u32_at(bytes, at + 4));
    let chunk_depth = u32_at(bytes, at + 8);
    let threshold = f32::from_le_bytes(
        bytes[at as usize + 12..at as usize + 16]
            .try_into()
            .expect("4 bytes"),
    );
    let rmse = f64::from_bits(u64_at(bytes, at + 16));
    let (chunks, words) = (u64_at(bytes, at + 24), u64_at(bytes, at + 32));
    let codec = ColorCodec::from_id(codec_id, threshold).ok_or_else(|| {
        err(
            at,
            format!("unknown colour codec id {codec_id} (threshold {threshold})"),
        )
    })?;
    if format_id != codec.format() as u32 {
        return Err(err(
            at + 4,
            format!(
                "colour format id {format_id} is not what {} writes",
                codec.name()
            ),
        ));
    }
    if chunk_depth > root_level {
        return Err(err(
            at + 8,
            format!("chunk depth {chunk_depth} below the leaves (root level {root_level})"),
        ));
    }
    if !(rmse.is_finite() && rmse >= 0.0) {
        return Err(err(
            at + 16,
            format!("colour RMSE {rmse} is not a non-negative number"),
        ));
    }
    let expected = chunks
        .checked_add(1)
        .and_then(|n| n.checked_mul(16))
        .and_then(|t| words.checked_mul(4).and_then(|w| w.checked_add(t)))
        .and_then(|n| n.checked_add(CHUNKED_HEADER_LEN));
    if expected != Some(len) {
        return Err(err(
            at + 24,
            format!("{chunks} chunks and {words} words do not fill {len} bytes"),
        ));
    }
    // Sizes are now bounded by the section length: allocate.
    let table =
        |from: u64| -> Vec<u64> { (0..=chunks).map(|i| u64_at(bytes, from + 8 * i)).collect() };
    let starts_at = at + CHUNKED_HEADER_LEN;
    let offsets_at = starts_at + 8 * (chunks + 1);
    let words_at = offsets_at + 8 * (chunks + 1);
    let chunks_parsed = ChunkedColors {
        codec,
        format: codec.format(),
        chunk_depth,
        chunk_starts: table(starts_at),
        chunk_offsets: table(offsets_at),
        words: u32s(bytes, (words_at, words * 4)),
    };
    chunks_parsed
        .validate_tables()
        .map_err(|e| err(starts_at, e.to_string()))?;
    if chunks_parsed.color_count() != color_count {
        return Err(err(
            starts_at + 8 * chunks,
            format!(
                "chunks hold {} colours, header says {color_count}",
                chunks_parsed.color_count()
            ),
        ));
    }
    let chunk_error = |c: usize, e: AttrError| {
        let word = match &e {
            AttrError::Corrupt { word, .. } => *word,
            _ => 0,
        };
        let offset = words_at + 4 * (chunks_parsed.chunk_offsets[c] + word);
        err(offset, format!("colour chunk {c}: {e}"))
    };
    let mut colors = Vec::new();
    if keep_decoded {
        // Decoded colours can outgrow the file (a compressed run): check before decoding.
        crate::safety::check_memory(
            format!("{}: decoding {color_count} colours", name.display()),
            color_count.saturating_mul(8),
        )?;
        // Every chunk must decode (in parallel); report the first failure with its byte offset.
        let decoded: Vec<Result<Vec<u32>, AttrError>> = (0..chunks_parsed.chunk_count())
            .into_par_iter()
            .map(|c| chunks_parsed.decode_chunk(c))
            .collect();
        colors.reserve_exact(color_count as usize);
        for (c, chunk) in decoded.into_iter().enumerate() {
            colors.extend_from_slice(&chunk.map_err(|e| chunk_error(c, e))?);
        }
    } else {
        // The same check, one chunk at a time per thread (the first failure by chunk index).
        let failure = (0..chunks_parsed.chunk_count())
            .into_par_iter()
            .filter_map(|c| chunks_parsed.decode_chunk(c).err().map(|e| (c, e)))
            .min_by_key(|(c, _)| *c);
        if let Some((c, e)) = failure {
            return Err(chunk_error(c, e));
        }
    }
    let stored = StoredColors {
        chunks: chunks_parsed,
        rmse,
    };
    Ok((stored, colors))
}

/// The material section's bytes (layout in `docs/vdag-format.md`).
fn materials_bytes(m: &Materials) -> Vec<u8> {
    let packed = m.packed_ids();
    let mut b = Vec::with_capacity(MATERIALS_HEADER_LEN as usize + packed.len());
    b.extend_from_slice(&(m.palette.len() as u32).to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.extend_from_slice(&(m.ids.len() as u64).to_le_bytes());
    for c in m.palette16() {
        b.extend_from_slice(&c.to_le_bytes());
    }
    b.extend_from_slice(&packed);
    b
}

/// Parses and checks the material section at `at` (`len` bytes): palette size 1..=16, unused
/// palette entries zero, the length matching the id count before the ids are allocated, every
/// id below the palette size. The id count is checked against the voxels by the caller.
fn parse_materials(
    bytes: &[u8],
    (at, len): (u64, u64),
    name: &Path,
) -> Result<Materials, DagError> {
    let err = |offset: u64, reason: String| DagError::Format {
        path: name.to_path_buf(),
        offset,
        reason,
    };
    if len < MATERIALS_HEADER_LEN {
        return Err(err(at, format!("material section of {len} bytes")));
    }
    let size = u32_at(bytes, at);
    if !(1..=crate::attr::materials::MAX_MATERIALS).contains(&size) {
        return Err(err(at, format!("palette of {size} entries (1..=16)")));
    }
    if u32_at(bytes, at + 4) != 0 {
        return Err(err(at + 4, "reserved material field is not zero".into()));
    }
    let count = u64_at(bytes, at + 8);
    let palette: Vec<u32> = (0..16).map(|i| u32_at(bytes, at + 16 + 4 * i)).collect();
    if let Some(i) = (size as usize..16).find(|&i| palette[i] != 0) {
        return Err(err(
            at + 16 + 4 * i as u64,
            format!("palette entry {i} past the {size} used is not zero"),
        ));
    }
    let expected = count
        .checked_add(1)
        .map(|n| n / 2)
        .and_then(|n| n.checked_add(MATERIALS_HEADER_LEN));
    if expected != Some(len) {
        return Err(err(
            at + 8,
            format!("{count} material ids do not fill a {len}-byte section"),
        ));
    }
    // The count is now bounded by the section length: allocate.
    let ids_at = at + MATERIALS_HEADER_LEN;
    let packed = &bytes[ids_at as usize..(at + len) as usize];
    let ids = Materials::unpack_ids(packed, count as usize).map_err(|byte| {
        err(
            ids_at + byte as u64,
            "unused high nibble of the last material byte is not zero".into(),
        )
    })?;
    if let Some(i) = ids.iter().position(|&id| id as u32 >= size) {
        return Err(err(
            ids_at + i as u64 / 2,
            format!(
                "voxel {i} has material {} of a {size}-entry palette",
                ids[i]
            ),
        ));
    }
    Ok(Materials {
        palette: palette[..size as usize].to_vec(),
        ids,
    })
}

/// A `Write` that counts bytes and feeds them to a CRC-32.
struct CrcWriter<W: Write> {
    inner: W,
    crc: crc32fast::Hasher,
    written: u64,
}

impl<W: Write> CrcWriter<W> {
    fn put(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.crc.update(bytes);
        self.written += bytes.len() as u64;
        self.inner.write_all(bytes)
    }
    fn pad_to(&mut self, offset: u64) -> io::Result<()> {
        let zeros = [0u8; 8];
        while self.written < offset {
            let n = (offset - self.written).min(8) as usize;
            self.put(&zeros[..n])?;
        }
        Ok(())
    }
    fn put_u32s(&mut self, values: &[u32]) -> io::Result<()> {
        if cfg!(target_endian = "little") {
            self.put(bytemuck::cast_slice(values))
        } else {
            for chunk in values.chunks(4096) {
                let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
                self.put(&bytes)?;
            }
            Ok(())
        }
    }
}

impl<W: Write> Write for CrcWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.put(buf)?;
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Rounds up to a multiple of 8.
fn align8(x: u64) -> u64 {
    x.div_ceil(8) * 8
}

/// The contents of one section, borrowed for writing.
enum Data<'a> {
    U32(&'a [u32]),
    U64(&'a [u64]),
    Bytes(&'a [u8]),
    Owned(Vec<u8>),
    /// Written by a callback when its turn comes (exactly `.0` bytes): the streaming build's
    /// spilled colours and the digest computed while they are copied.
    Stream(u64, &'a dyn Fn(&mut dyn Write) -> io::Result<()>),
}

impl Data<'_> {
    fn len(&self) -> u64 {
        match self {
            Data::U32(v) => v.len() as u64 * 4,
            Data::U64(v) => v.len() as u64 * 8,
            Data::Bytes(v) => v.len() as u64,
            Data::Owned(v) => v.len() as u64,
            Data::Stream(len, _) => *len,
        }
    }
}

/// Header fields that vary between files.
struct HeaderFields {
    encoding: u32,
    resolution: u32,
    color_format: ColorFormat,
    /// Words (svdag32) or payload bytes (other encodings).
    count: u64,
    color_count: u64,
}

/// Byte offset of each section (in table order) and the file size.
fn layout(sections: &[(u32, Data)]) -> (Vec<u64>, u64) {
    let mut at = align8(HEADER_LEN + sections.len() as u64 * ENTRY_LEN);
    let mut offsets = Vec::with_capacity(sections.len());
    for (i, (_, data)) in sections.iter().enumerate() {
        if i > 0 {
            at = align8(at);
        }
        offsets.push(at);
        at += data.len();
    }
    (offsets, at + 4)
}

/// Writes header, table, sections (each at the next multiple of 8) and the CRC.
fn write_file(w: &mut impl Write, h: &HeaderFields, sections: &[(u32, Data)]) -> io::Result<()> {
    let (offsets, file_size) = layout(sections);
    let mut out = CrcWriter {
        inner: w,
        crc: crc32fast::Hasher::new(),
        written: 0,
    };
    let level_count = h.resolution.trailing_zeros() - 1;
    let mut header = Vec::with_capacity((HEADER_LEN + sections.len() as u64 * ENTRY_LEN) as usize);
    header.extend_from_slice(&MAGIC);
    header.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    header.extend_from_slice(&h.encoding.to_le_bytes());
    header.extend_from_slice(&h.resolution.to_le_bytes());
    header.extend_from_slice(&level_count.to_le_bytes());
    header.extend_from_slice(&(h.color_format as u32).to_le_bytes());
    header.extend_from_slice(&(sections.len() as u32).to_le_bytes());
    header.extend_from_slice(&file_size.to_le_bytes());
    header.extend_from_slice(&h.count.to_le_bytes());
    header.extend_from_slice(&h.color_count.to_le_bytes());
    header.extend_from_slice(&0u64.to_le_bytes());
    for ((id, data), offset) in sections.iter().zip(&offsets) {
        header.extend_from_slice(&id.to_le_bytes());
        header.extend_from_slice(&0u32.to_le_bytes());
        header.extend_from_slice(&offset.to_le_bytes());
        header.extend_from_slice(&data.len().to_le_bytes());
    }
    out.put(&header)?;
    for ((_, data), &offset) in sections.iter().zip(&offsets) {
        out.pad_to(offset)?;
        match data {
            Data::U32(v) => out.put_u32s(v)?,
            Data::U64(v) => {
                for chunk in v.chunks(4096) {
                    let bytes: Vec<u8> = chunk.iter().flat_map(|x| x.to_le_bytes()).collect();
                    out.put(&bytes)?;
                }
            }
            Data::Bytes(v) => out.put(v)?,
            Data::Owned(v) => out.put(v)?,
            Data::Stream(len, write) => {
                let start = out.written;
                write(&mut out)?;
                if out.written - start != *len {
                    return Err(io::Error::other(format!(
                        "section wrote {} bytes, {len} announced",
                        out.written - start
                    )));
                }
            }
        }
    }
    let crc = out.crc.clone().finalize();
    out.inner.write_all(&crc.to_le_bytes())?;
    Ok(())
}

/// Writes the file of a streaming build (`dag::stream::save_streamed`): the sections of
/// [`VdagFile::write_to`] for `encoded` with `color_count` chunked colours whose section
/// (`chunked_len` bytes, `None` without colours) and content digest are written by callbacks.
pub(crate) fn write_streamed(
    w: &mut impl Write,
    encoded: &EncodedDag,
    digest: &VoxelDigest,
    color_count: u64,
    chunked_len: Option<u64>,
    chunked: &dyn Fn(&mut dyn Write) -> io::Result<()>,
    content: &dyn Fn(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    let digest = digest_bytes(digest);
    let payload;
    let (count, mut sections) = match encoded {
        EncodedDag::Svdag32(dag) => (
            dag.words.len() as u64,
            vec![
                (SECTION_LEVELS, Data::U64(&dag.level_starts)),
                (SECTION_WORDS, Data::U32(&dag.words)),
                (SECTION_COLORS, Data::U32(&[])),
                (SECTION_DIGEST, Data::Bytes(&digest)),
            ],
        ),
        other => {
            payload = other.payload();
            (
                payload.len() as u64,
                vec![
                    (SECTION_COLORS, Data::U32(&[])),
                    (SECTION_DIGEST, Data::Bytes(&digest)),
                    (SECTION_PAYLOAD, Data::Bytes(&payload)),
                ],
            )
        }
    };
    if let Some(len) = chunked_len {
        sections.push((SECTION_CHUNKED_COLORS, Data::Stream(len, chunked)));
    }
    sections.push((
        SECTION_CONTENT_DIGEST,
        Data::Stream(CONTENT_DIGEST_LEN, content),
    ));
    let h = HeaderFields {
        encoding: Encoding::from(encoded.kind()) as u32,
        resolution: encoded.resolution(),
        color_format: if chunked_len.is_some() {
            ColorFormat::Chunked
        } else {
            ColorFormat::None
        },
        count,
        color_count,
    };
    write_file(w, &h, &sections)
}

fn digest_bytes(d: &VoxelDigest) -> [u8; 16] {
    let mut b = [0u8; 16];
    b[..8].copy_from_slice(&d.voxels.to_le_bytes());
    b[8..12].copy_from_slice(&d.crc32.to_le_bytes());
    b
}

/// [`crate::atomic_file::write_atomic`] with the error mapped to [`DagError::Io`].
pub(crate) fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<(), DagError> {
    crate::atomic_file::write_atomic(path, write).map_err(|source| DagError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a `.vdag` file, bounded: the header first, then never more than the file size the
/// header states (checked against the memory limit first), so `/dev/zero`, a FIFO or a
/// growing file cannot make it read or allocate without end.
pub(crate) fn read_vdag(path: &Path) -> Result<Vec<u8>, DagError> {
    use std::io::Read;
    let io_err = |source: io::Error| DagError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = File::open(path).map_err(io_err)?;
    let mut bytes = Vec::new();
    (&mut file)
        .take(HEADER_LEN)
        .read_to_end(&mut bytes)
        .map_err(io_err)?;
    if bytes.len() < HEADER_LEN as usize {
        return Ok(bytes); // too short: parse_header says so
    }
    if bytes[..8] != MAGIC {
        return Err(DagError::Format {
            path: path.to_path_buf(),
            offset: 0,
            reason: "not a .vdag file (bad magic)".into(),
        });
    }
    let size = u64_at(&bytes, 32);
    crate::safety::check_memory(format!("{}", path.display()), size)?;
    // One byte more than announced, so that a longer file is detected.
    let rest = (size + 1).saturating_sub(HEADER_LEN);
    bytes
        .try_reserve_exact(rest as usize)
        .map_err(|e| io_err(io::Error::other(e.to_string())))?;
    file.take(rest).read_to_end(&mut bytes).map_err(io_err)?;
    Ok(bytes)
}

/// Reads little-endian integers from a byte slice whose length was checked by the caller.
fn u32_at(b: &[u8], at: u64) -> u32 {
    let at = at as usize;
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

/// Reads a little-endian u64 at a checked offset.
fn u64_at(b: &[u8], at: u64) -> u64 {
    let at = at as usize;
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// A checked header and section table.
struct Parsed {
    version: u32,
    encoding: Encoding,
    resolution: u32,
    level_count: u32,
    color_format: ColorFormat,
    color_count: u64,
    /// `(offset, length)` of sections `1..=KNOWN_SECTIONS`.
    sections: [Option<(u64, u64)>; KNOWN_SECTIONS],
}

/// Checks everything up to and including the section table (reading rules 1-3 of
/// `docs/vdag-format.md`).
fn parse_header(bytes: &[u8], name: &Path) -> Result<Parsed, DagError> {
    let err = |offset: u64, reason: String| DagError::Format {
        path: name.to_path_buf(),
        offset,
        reason,
    };
    let len = bytes.len() as u64;
    let min = HEADER_LEN + 3 * ENTRY_LEN + 4;
    if len < min {
        return Err(err(
            len,
            format!("file is {len} bytes, shorter than the {min}-byte minimum"),
        ));
    }
    if bytes[..8] != MAGIC {
        return Err(err(0, "not a .vdag file (bad magic)".into()));
    }
    let version = u32_at(bytes, 8);
    if !(OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(err(
            8,
            format!(
                "unsupported format version {version} (this build reads \
                 {OLDEST_FORMAT_VERSION}..={FORMAT_VERSION})"
            ),
        ));
    }
    let file_size = u64_at(bytes, 32);
    if file_size != len {
        return Err(err(
            32,
            format!("header says {file_size} bytes, file has {len} (truncated?)"),
        ));
    }
    let stored_crc = u32_at(bytes, len - 4);
    let crc = crc32fast::hash(&bytes[..(len - 4) as usize]);
    if crc != stored_crc {
        return Err(err(
            len - 4,
            format!("checksum mismatch: stored {stored_crc:#010x}, computed {crc:#010x}"),
        ));
    }
    let encoding = match u32_at(bytes, 12) {
        0 => Encoding::Svdag32,
        1 => Encoding::Ssvdag,
        2 => Encoding::Tsvdag,
        other => return Err(err(12, format!("unknown encoding id {other}"))),
    };
    let resolution = u32_at(bytes, 16);
    if !resolution.is_power_of_two() || !(8..=MAX_RESOLUTION).contains(&resolution) {
        return Err(err(
            16,
            format!("resolution {resolution} is not a power of two in 8..=2^21"),
        ));
    }
    let level_count = u32_at(bytes, 20);
    if level_count != resolution.trailing_zeros() - 1 {
        return Err(err(
            20,
            format!("{level_count} levels for resolution {resolution}"),
        ));
    }
    let color_format = match u32_at(bytes, 24) {
        0 => ColorFormat::None,
        1 => ColorFormat::Rgba8,
        2 => ColorFormat::Chunked,
        other => return Err(err(24, format!("unknown colour format id {other}"))),
    };
    let section_count = u32_at(bytes, 28);
    if !(3..=MAX_SECTIONS).contains(&section_count) {
        return Err(err(
            28,
            format!("section count {section_count} not in 3..={MAX_SECTIONS}"),
        ));
    }
    let table_end = HEADER_LEN + section_count as u64 * ENTRY_LEN;
    if table_end > len - 4 {
        return Err(err(
            28,
            format!("section table of {section_count} entries runs past the end of the file"),
        ));
    }
    let count = u64_at(bytes, 40);
    if encoding == Encoding::Svdag32 {
        if count == 0 || count > u32::MAX as u64 {
            return Err(err(40, format!("word count {count} not in 1..=2^32-1")));
        }
    } else if count == 0 || count > len {
        return Err(err(
            40,
            format!("payload size {count} not in 1..={len} (the file length)"),
        ));
    }
    let color_count = u64_at(bytes, 48);
    if color_format == ColorFormat::None && color_count != 0 {
        return Err(err(
            48,
            format!("{color_count} colours with colour format 'none'"),
        ));
    }
    if u64_at(bytes, 56) != 0 {
        return Err(err(56, "reserved header field is not zero".into()));
    }

    // Section table: known ids at most once, inside the file, expected lengths, no overlap.
    let mut sections: [Option<(u64, u64)>; KNOWN_SECTIONS] = [None; KNOWN_SECTIONS];
    let mut ranges: Vec<(u64, u64, u64)> = Vec::new(); // (start, end, table entry offset)
    for i in 0..section_count as u64 {
        let at = HEADER_LEN + i * ENTRY_LEN;
        let (id, reserved) = (u32_at(bytes, at), u32_at(bytes, at + 4));
        let (offset, length) = (u64_at(bytes, at + 8), u64_at(bytes, at + 16));
        if reserved != 0 {
            return Err(err(at + 4, "reserved section field is not zero".into()));
        }
        let end = offset.checked_add(length).filter(|&e| e <= len - 4);
        let Some(end) = end.filter(|_| offset >= table_end && offset % 8 == 0) else {
            return Err(err(
                at + 8,
                format!("section {id} at {offset} (+{length} bytes) is outside the data area"),
            ));
        };
        let svdag32 = encoding == Encoding::Svdag32;
        let expected = match id {
            SECTION_LEVELS if svdag32 => Some(level_count as u64 * 8),
            SECTION_WORDS if svdag32 => Some(count * 4),
            SECTION_COLORS if color_format == ColorFormat::Rgba8 => color_count.checked_mul(4),
            SECTION_COLORS => Some(0),
            SECTION_CHUNKED_COLORS if color_format != ColorFormat::Chunked => {
                return Err(err(
                    at,
                    format!("section {id} in a file whose colour format is not chunked"),
                ))
            }
            SECTION_MATERIALS if color_format != ColorFormat::None => {
                return Err(err(
                    at,
                    format!("material section {id} in a file with colours"),
                ))
            }
            SECTION_DIGEST => Some(16),
            SECTION_CONTENT_DIGEST => Some(CONTENT_DIGEST_LEN),
            SECTION_PAYLOAD if !svdag32 => Some(count),
            SECTION_LEVELS | SECTION_WORDS | SECTION_PAYLOAD => {
                return Err(err(
                    at,
                    format!("section {id} does not belong in a {} file", encoding.name()),
                ))
            }
            _ => Some(length), // unknown sections are skipped
        };
        if expected != Some(length) {
            return Err(err(
                at + 16,
                format!("section {id} is {length} bytes, expected {expected:?}"),
            ));
        }
        if (1..=KNOWN_SECTIONS as u32).contains(&id) {
            let slot = &mut sections[id as usize - 1];
            if slot.is_some() {
                return Err(err(at, format!("section {id} listed twice")));
            }
            *slot = Some((offset, length));
        }
        ranges.push((offset, end, at));
    }
    ranges.sort_unstable();
    for pair in ranges.windows(2) {
        if pair[1].0 < pair[0].1 {
            return Err(err(pair[1].2 + 8, "sections overlap".into()));
        }
    }
    let required: &[u32] = if encoding == Encoding::Svdag32 {
        &[SECTION_LEVELS, SECTION_WORDS, SECTION_COLORS]
    } else {
        &[SECTION_COLORS, SECTION_DIGEST, SECTION_PAYLOAD]
    };
    let chunked: &[u32] = if color_format == ColorFormat::Chunked {
        &[SECTION_CHUNKED_COLORS]
    } else {
        &[]
    };
    for &id in required.iter().chain(chunked) {
        if sections[id as usize - 1].is_none() {
            return Err(err(28, format!("section {id} missing")));
        }
    }
    Ok(Parsed {
        version,
        encoding,
        resolution,
        level_count,
        color_format,
        color_count,
        sections,
    })
}

/// Decodes a u32 array of a checked section.
fn u32s(bytes: &[u8], (at, n): (u64, u64)) -> Vec<u32> {
    bytes[at as usize..(at + n) as usize]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect()
}

impl Svdag {
    /// Serialises the DAG in `.vdag` v1 format (encoding `svdag32`) to a writer.
    pub fn write_to(&self, w: &mut impl Write) -> io::Result<()> {
        self.write_with(w, None, None, None, None)
    }

    /// `write_to`, with optional digest sections, optional encoded colours (which replace
    /// `self.colors` in the file) and optional materials.
    fn write_with(
        &self,
        w: &mut impl Write,
        digest: Option<&VoxelDigest>,
        stored: Option<&StoredColors>,
        materials: Option<&Materials>,
        content: Option<&ContentDigest>,
    ) -> io::Result<()> {
        let (color_format, raw_colors, chunked) = color_sections(&self.colors, stored);
        let h = HeaderFields {
            encoding: Encoding::Svdag32 as u32,
            resolution: self.resolution,
            color_format,
            count: self.words.len() as u64,
            color_count: color_count(&self.colors, stored),
        };
        let digest = digest.map(digest_bytes);
        let mut sections = vec![
            (SECTION_LEVELS, Data::U64(&self.level_starts)),
            (SECTION_WORDS, Data::U32(&self.words)),
            (SECTION_COLORS, Data::U32(raw_colors)),
        ];
        if let Some(d) = &digest {
            sections.push((SECTION_DIGEST, Data::Bytes(d)));
        }
        if let Some(c) = chunked {
            sections.push((SECTION_CHUNKED_COLORS, c));
        }
        if let Some(m) = materials {
            sections.push((SECTION_MATERIALS, Data::Owned(materials_bytes(m))));
        }
        let content = content.map(|c| c.to_bytes());
        if let Some(c) = &content {
            sections.push((SECTION_CONTENT_DIGEST, Data::Bytes(c)));
        }
        write_file(w, &h, &sections)
    }

    /// The `.vdag` v1 bytes of this DAG (without the content digest that [`Svdag::save`]
    /// adds).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut bytes = Vec::new();
        self.write_to(&mut bytes)
            .expect("writing to a Vec cannot fail");
        bytes
    }

    /// Saves the DAG as a `.vdag` v1 file with its content digest (section 7), atomically
    /// (temporary file, fsync, rename).
    pub fn save(&self, path: &Path) -> Result<(), DagError> {
        let content = ContentDigest::of_svdag(self, &self.colors).map_err(|e| DagError::Io {
            path: path.to_path_buf(),
            source: io::Error::other(e.to_string()),
        })?;
        write_atomic(path, |w| {
            self.write_with(w, None, None, None, Some(&content))
        })
    }

    /// Loads and validates a `.vdag` file whose encoding is `svdag32` (see [`VdagFile::load`]
    /// for the other encodings).
    pub fn load(path: &Path) -> Result<Svdag, DagError> {
        Self::from_bytes(&read_vdag(path)?, path)
    }

    /// Parses and validates `.vdag` bytes of encoding `svdag32`; `name` is used in error messages.
    pub fn from_bytes(bytes: &[u8], name: impl AsRef<Path>) -> Result<Svdag, DagError> {
        let parsed = parse_header(bytes, name.as_ref())?;
        if parsed.encoding != Encoding::Svdag32 {
            return Err(DagError::Format {
                path: name.as_ref().to_path_buf(),
                offset: 12,
                reason: format!(
                    "encoding {} is not svdag32: load it with VdagFile (and decode)",
                    parsed.encoding.name()
                ),
            });
        }
        if parsed.color_format == ColorFormat::Chunked {
            // Decoding needs the chunked section: VdagFile parses it.
            let file = VdagFile::from_bytes(bytes, name.as_ref())?;
            return file.into_svdag(name.as_ref());
        }
        Self::from_parsed(bytes, name.as_ref(), &parsed, None)
    }

    /// Builds and validates the DAG of a parsed svdag32 file; `decoded` replaces the raw colour
    /// section (the decoded chunked colours).
    fn from_parsed(
        bytes: &[u8],
        name: &Path,
        parsed: &Parsed,
        decoded: Option<Vec<u32>>,
    ) -> Result<Svdag, DagError> {
        let get = |id: u32| parsed.sections[id as usize - 1].expect("required section checked");
        let (levels_at, levels_len) = get(SECTION_LEVELS);
        let (words_at, _) = get(SECTION_WORDS);
        // Every size is now bounded by the file length: allocate and decode.
        let level_starts: Vec<u64> = bytes[levels_at as usize..(levels_at + levels_len) as usize]
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        let dag = Svdag {
            resolution: parsed.resolution,
            words: u32s(bytes, get(SECTION_WORDS)),
            level_starts,
            colors: decoded.unwrap_or_else(|| u32s(bytes, get(SECTION_COLORS))),
        };
        dag.check().map_err(|(place, reason)| {
            let offset = match place {
                Place::Resolution => 16,
                Place::Level(l) => levels_at + 8 * l as u64,
                Place::Word(w) => words_at + 4 * w as u64,
                Place::Colors => 48,
            };
            DagError::Format {
                path: name.to_path_buf(),
                offset,
                reason: format!("invalid DAG: {reason}"),
            }
        })?;
        Ok(dag)
    }
}

/// A `.vdag` file in any encoding: the nodes, the colours, and the digest of the voxel set
/// computed when it was built (required for ssvdag/tsvdag, optional for svdag32).
#[derive(Clone, Debug, PartialEq)]
pub struct VdagFile {
    /// The stored nodes.
    pub encoded: EncodedDag,
    /// Per-voxel RGBA8 colours in Morton order (empty: none).
    pub colors: Vec<u32>,
    /// Voxel count and checksum of the source voxels.
    pub digest: Option<VoxelDigest>,
    /// The colours as an encoder stored them; when present they are written instead of the
    /// raw colours, and `colors` holds their decoded values (none when loaded with
    /// [`VdagFile::load_encoded_colors`]).
    pub stored_colors: Option<StoredColors>,
    /// Palette and per-voxel material ids (section 8); a file has materials or colours, not
    /// both (`docs/materials.md`).
    pub materials: Option<Materials>,
}

impl VdagFile {
    /// The content digest's colour field of this file's attributes: its materials, its decoded
    /// colours, or (loaded with [`VdagFile::load_encoded_colors`]) its chunks, decoded a batch
    /// at a time.
    pub fn attributes_hash(&self) -> Result<u64, AttrError> {
        match self.encoded_only_colors() {
            Some(chunks) => chunked_colors_hash(chunks),
            None => Ok(attributes_hash(&self.colors, self.materials.as_ref())),
        }
    }

    /// The colour chunks when they are the only form of the colours held (loaded with
    /// [`VdagFile::load_encoded_colors`]); `None` when the colours are decoded or absent.
    pub fn encoded_only_colors(&self) -> Option<&ChunkedColors> {
        self.stored_colors
            .as_ref()
            .filter(|_| self.colors.is_empty())
            .map(|s| &s.chunks)
    }

    /// Colours the file holds: its chunks' count, else its raw colours.
    pub fn color_count(&self) -> u64 {
        color_count(&self.colors, self.stored_colors.as_ref())
    }

    /// Serialises the file to a writer.
    /// Every file written here stores the content digest (section 7) of its nodes and its
    /// decoded colours.
    pub fn write_to(&self, w: &mut impl Write) -> io::Result<()> {
        let materials = self.materials.as_ref();
        if materials.is_some() && (!self.colors.is_empty() || self.stored_colors.is_some()) {
            return Err(io::Error::other(
                "a .vdag file holds materials or colours, not both",
            ));
        }
        if let Some(m) = materials {
            m.validate().map_err(|e| io::Error::other(e.to_string()))?;
        }
        let mut content = ContentDigest::of(&self.encoded, &self.colors)
            .map_err(|e| io::Error::other(format!("content digest: {e}")))?;
        content.colors = self
            .attributes_hash()
            .map_err(|e| io::Error::other(format!("content digest of the colours: {e}")))?;
        if materials.is_some_and(|m| m.ids.len() as u64 != content.voxels) {
            return Err(io::Error::other(format!(
                "{} material ids for {} voxels",
                materials.map_or(0, |m| m.ids.len()),
                content.voxels
            )));
        }
        let payload = match &self.encoded {
            EncodedDag::Svdag32(dag) => {
                let stored = self.stored_colors.as_ref();
                let digest = self.digest.as_ref();
                if dag.colors == self.colors {
                    return dag.write_with(w, digest, stored, materials, Some(&content));
                }
                let mut dag = dag.clone();
                dag.colors = self.colors.clone();
                return dag.write_with(w, digest, stored, materials, Some(&content));
            }
            other => other.payload(),
        };
        let digest = self
            .digest
            .ok_or_else(|| io::Error::other("ssvdag/tsvdag files need the voxel digest"))?;
        let digest = digest_bytes(&digest);
        let (color_format, raw_colors, chunked) =
            color_sections(&self.colors, self.stored_colors.as_ref());
        let h = HeaderFields {
            encoding: Encoding::from(self.encoded.kind()) as u32,
            resolution: self.encoded.resolution(),
            color_format,
            count: payload.len() as u64,
            color_count: self.color_count(),
        };
        let mut sections = vec![
            (SECTION_COLORS, Data::U32(raw_colors)),
            (SECTION_DIGEST, Data::Bytes(&digest)),
            (SECTION_PAYLOAD, Data::Bytes(&payload)),
        ];
        if let Some(c) = chunked {
            sections.push((SECTION_CHUNKED_COLORS, c));
        }
        if let Some(m) = materials {
            sections.push((SECTION_MATERIALS, Data::Owned(materials_bytes(m))));
        }
        let content = content.to_bytes();
        sections.push((SECTION_CONTENT_DIGEST, Data::Bytes(&content)));
        write_file(w, &h, &sections)
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, DagError> {
        let mut bytes = Vec::new();
        self.write_to(&mut bytes).map_err(|source| DagError::Io {
            path: "<memory>".into(),
            source,
        })?;
        Ok(bytes)
    }

    /// Saves atomically.
    pub fn save(&self, path: &Path) -> Result<(), DagError> {
        write_atomic(path, |w| self.write_to(w))
    }

    /// Loads and validates a file of any encoding (v1 svdag32 files included).
    pub fn load(path: &Path) -> Result<VdagFile, DagError> {
        Ok(Self::load_with_digest(path)?.0)
    }

    /// [`VdagFile::load`] for a renderer: chunked colours are checked (every chunk decodes)
    /// but kept encoded only (`stored_colors`), so `colors` is empty for such a file and its
    /// memory is the file's, not 4 bytes per voxel (sponza-crytek at 32768: 1.6 GB of chunks,
    /// 40 GB decoded). Raw colours load as with [`VdagFile::load`].
    pub fn load_encoded_colors(path: &Path) -> Result<VdagFile, DagError> {
        Ok(Self::load_encoded_colors_with_digest(path)?.0)
    }

    /// [`VdagFile::load_encoded_colors`] with the stored content digest (section 7), if any.
    pub fn load_encoded_colors_with_digest(
        path: &Path,
    ) -> Result<(VdagFile, Option<ContentDigest>), DagError> {
        let bytes = read_vdag(path)?;
        let parsed = parse_header(&bytes, path)?;
        let content = content_digest(&bytes, &parsed);
        Ok((Self::from_parsed(&bytes, path, parsed, false)?, content))
    }

    /// [`VdagFile::from_bytes`] keeping chunked colours encoded, as
    /// [`VdagFile::load_encoded_colors`].
    pub fn from_bytes_encoded_colors(
        bytes: &[u8],
        name: impl AsRef<Path>,
    ) -> Result<VdagFile, DagError> {
        let name = name.as_ref();
        Self::from_parsed(bytes, name, parse_header(bytes, name)?, false)
    }

    /// [`VdagFile::load`] with the stored content digest (section 7), if any.
    pub fn load_with_digest(path: &Path) -> Result<(VdagFile, Option<ContentDigest>), DagError> {
        Self::from_bytes_with_digest(&read_vdag(path)?, path)
    }

    /// Parses and validates bytes; `name` is used in error messages.
    pub fn from_bytes(bytes: &[u8], name: impl AsRef<Path>) -> Result<VdagFile, DagError> {
        Ok(Self::from_bytes_with_digest(bytes, name)?.0)
    }

    /// [`VdagFile::from_bytes`] with the stored content digest (section 7), if any.
    pub fn from_bytes_with_digest(
        bytes: &[u8],
        name: impl AsRef<Path>,
    ) -> Result<(VdagFile, Option<ContentDigest>), DagError> {
        let name = name.as_ref();
        let parsed = parse_header(bytes, name)?;
        let content = content_digest(bytes, &parsed);
        Ok((Self::from_parsed(bytes, name, parsed, true)?, content))
    }

    /// The file of a checked header and section table; `decode_colors`: chunked colours are
    /// also decoded into `colors` (else only checked).
    fn from_parsed(
        bytes: &[u8],
        name: &Path,
        parsed: Parsed,
        decode_colors: bool,
    ) -> Result<VdagFile, DagError> {
        let err = |offset: u64, reason: String| DagError::Format {
            path: name.to_path_buf(),
            offset,
            reason,
        };
        let digest = parsed.sections[SECTION_DIGEST as usize - 1].map(|(at, _)| VoxelDigest {
            voxels: u64_at(bytes, at),
            crc32: u32_at(bytes, at + 8),
        });
        if let Some((at, _)) = parsed.sections[SECTION_DIGEST as usize - 1] {
            if u32_at(bytes, at + 12) != 0 {
                return Err(err(at + 12, "reserved digest field is not zero".into()));
            }
            let d = digest.expect("section present");
            if parsed.color_format != ColorFormat::None && parsed.color_count != d.voxels {
                return Err(err(
                    48,
                    format!("{} colours for {} voxels", parsed.color_count, d.voxels),
                ));
            }
        }
        let (stored_colors, decoded) = match parsed.sections[SECTION_CHUNKED_COLORS as usize - 1] {
            Some(section) => {
                let (stored, colors) = parse_stored_colors(
                    bytes,
                    section,
                    parsed.color_count,
                    parsed.resolution.trailing_zeros() - 2,
                    name,
                    decode_colors,
                )?;
                (Some(stored), Some(colors))
            }
            None => (None, None),
        };
        let section = parsed.sections[SECTION_MATERIALS as usize - 1];
        let materials = match section {
            Some(section) => Some(parse_materials(bytes, section, name)?),
            None => None,
        };
        // Material ids must match the voxels: the digest's count here, the DAG's below.
        let count_err = |m: &Materials, voxels: u64| {
            err(
                section.expect("materials parsed").0 + 8,
                format!("{} material ids for {voxels} voxels", m.ids.len()),
            )
        };
        if let (Some(m), Some(d)) = (&materials, digest) {
            if m.ids.len() as u64 != d.voxels {
                return Err(count_err(m, d.voxels));
            }
        }
        if parsed.encoding == Encoding::Svdag32 {
            let dag = Svdag::from_parsed(bytes, name, &parsed, decoded)?;
            if let Some(m) = &materials {
                let voxels = dag.voxel_count();
                if m.ids.len() as u64 != voxels {
                    return Err(count_err(m, voxels));
                }
            }
            // Colours kept encoded are not in `dag.colors`, whose check counted them.
            if let Some(s) = stored_colors.as_ref().filter(|_| !decode_colors) {
                let voxels = dag.voxel_count();
                if s.chunks.color_count() != voxels {
                    return Err(err(
                        48,
                        format!("{} colours for {voxels} voxels", s.chunks.color_count()),
                    ));
                }
            }
            let colors = dag.colors.clone();
            return Ok(VdagFile {
                encoded: EncodedDag::Svdag32(dag),
                colors,
                digest,
                stored_colors,
                materials,
            });
        }
        let (at, n) = parsed.sections[SECTION_PAYLOAD as usize - 1].expect("required");
        let payload = &bytes[at as usize..(at + n) as usize];
        let map = |e: EncodeError| match e {
            EncodeError::Corrupt { offset, reason } => err(at + offset, reason),
            other => err(at, other.to_string()),
        };
        let encoded = match parsed.encoding {
            Encoding::Ssvdag => EncodedDag::Ssvdag(
                SsvdagEncoding::from_payload(payload, parsed.resolution).map_err(map)?,
            ),
            _ => {
                let e = TsvdagEncoding::from_payload(payload, parsed.resolution).map_err(map)?;
                if parsed.version < 2 && e.needs_v2() {
                    return Err(err(
                        at + 4,
                        format!(
                            "tsvdag flag bits 4-5 (compact translation fields, tagged pointers) \
                             need format version 2, file is version {}",
                            parsed.version
                        ),
                    ));
                }
                EncodedDag::Tsvdag(e)
            }
        };
        debug_assert_eq!(parsed.level_count, parsed.resolution.trailing_zeros() - 1);
        let colors = match decoded {
            Some(colors) => colors,
            None => u32s(
                bytes,
                parsed.sections[SECTION_COLORS as usize - 1].expect("required"),
            ),
        };
        Ok(VdagFile {
            encoded,
            colors,
            digest,
            stored_colors,
            materials,
        })
    }

    /// Decodes the nodes to an SVDAG (traversing the encoded bytes) with the file's colours.
    pub fn into_svdag(self, name: &Path) -> Result<Svdag, DagError> {
        if let EncodedDag::Svdag32(mut dag) = self.encoded {
            dag.colors = self.colors;
            return Ok(dag);
        }
        self.encoded
            .to_svdag(self.colors)
            .map_err(|e| DagError::Format {
                path: name.to_path_buf(),
                offset: 0,
                reason: format!("decoding {}: {e}", self.encoded.kind().name()),
            })
    }
}

/// Colours a file holds: the stored chunks' count, else the raw colours (a file loaded with its
/// colours kept encoded has no raw ones).
fn color_count(colors: &[u32], stored: Option<&StoredColors>) -> u64 {
    stored.map_or(colors.len() as u64, |s| s.chunks.color_count())
}

/// The stored content digest (section 7) of a parsed file, if any.
fn content_digest(bytes: &[u8], parsed: &Parsed) -> Option<ContentDigest> {
    parsed.sections[SECTION_CONTENT_DIGEST as usize - 1]
        .map(|(at, n)| ContentDigest::from_bytes(&bytes[at as usize..(at + n) as usize]))
}

/// Colour format, raw colour section and chunked colour section of a file with `colors` and
/// optionally their encoded form.
fn color_sections<'a>(
    colors: &'a [u32],
    stored: Option<&StoredColors>,
) -> (ColorFormat, &'a [u32], Option<Data<'a>>) {
    match stored {
        Some(s) => (
            ColorFormat::Chunked,
            &[],
            Some(Data::Owned(stored_colors_bytes(s))),
        ),
        None if colors.is_empty() => (ColorFormat::None, colors, None),
        None => (ColorFormat::Rgba8, colors, None),
    }
}
