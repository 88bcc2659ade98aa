//! The `.vdag` v1 file format (byte-exact description in `docs/vdag-format.md`).
//!
//! Little-endian: a 64-byte header, a section table (24 bytes per section), 8-byte aligned
//! sections (level starts, node words, colours) and a trailing CRC-32 of every byte before it.
//! Loading checks every size and offset against the real file length before allocating, then
//! validates the DAG structure, so a corrupt file is an error, never a panic or a loop.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use super::validate::Place;
use super::{DagError, Svdag, MAX_RESOLUTION};

/// The 8 bytes every `.vdag` file starts with.
pub const MAGIC: [u8; 8] = *b"VOXDAG\0\x01";
/// The format version this code reads and writes.
pub const FORMAT_VERSION: u32 = 1;
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

/// Node encoding of the words section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Encoding {
    /// `Svdag::words` unchanged (32-bit masks and pointers).
    Svdag32 = 0,
}

/// Encoding of the per-voxel colour section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum ColorFormat {
    /// No colours (the section is empty).
    None = 0,
    /// One RGBA8 u32 per voxel, depth-first Morton order.
    Rgba8 = 1,
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

/// Rounds up to a multiple of 8.
fn align8(x: u64) -> u64 {
    x.div_ceil(8) * 8
}

/// Byte offsets and lengths of the three v1 sections plus the file size.
struct Layout {
    levels: (u64, u64),
    words: (u64, u64),
    colors: (u64, u64),
    file_size: u64,
}

impl Layout {
    fn of(dag: &Svdag) -> Layout {
        let table_end = HEADER_LEN + 3 * ENTRY_LEN;
        let levels = (align8(table_end), dag.level_starts.len() as u64 * 8);
        let words = (align8(levels.0 + levels.1), dag.words.len() as u64 * 4);
        let colors = (align8(words.0 + words.1), dag.colors.len() as u64 * 4);
        Layout {
            levels,
            words,
            colors,
            file_size: colors.0 + colors.1 + 4,
        }
    }
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

impl Svdag {
    /// Serialises the DAG in `.vdag` v1 format to a writer.
    pub fn write_to(&self, w: &mut impl Write) -> io::Result<()> {
        let layout = Layout::of(self);
        let mut out = CrcWriter {
            inner: w,
            crc: crc32fast::Hasher::new(),
            written: 0,
        };
        let color_format = if self.colors.is_empty() {
            ColorFormat::None
        } else {
            ColorFormat::Rgba8
        };
        let mut header = Vec::with_capacity((HEADER_LEN + 3 * ENTRY_LEN) as usize);
        header.extend_from_slice(&MAGIC);
        header.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        header.extend_from_slice(&(Encoding::Svdag32 as u32).to_le_bytes());
        header.extend_from_slice(&self.resolution.to_le_bytes());
        header.extend_from_slice(&(self.level_starts.len() as u32).to_le_bytes());
        header.extend_from_slice(&(color_format as u32).to_le_bytes());
        header.extend_from_slice(&3u32.to_le_bytes());
        header.extend_from_slice(&layout.file_size.to_le_bytes());
        header.extend_from_slice(&(self.words.len() as u64).to_le_bytes());
        header.extend_from_slice(&(self.colors.len() as u64).to_le_bytes());
        header.extend_from_slice(&0u64.to_le_bytes());
        for (id, (offset, len)) in [
            (SECTION_LEVELS, layout.levels),
            (SECTION_WORDS, layout.words),
            (SECTION_COLORS, layout.colors),
        ] {
            header.extend_from_slice(&id.to_le_bytes());
            header.extend_from_slice(&0u32.to_le_bytes());
            header.extend_from_slice(&offset.to_le_bytes());
            header.extend_from_slice(&len.to_le_bytes());
        }
        out.put(&header)?;
        out.pad_to(layout.levels.0)?;
        let levels: Vec<u8> = self
            .level_starts
            .iter()
            .flat_map(|s| s.to_le_bytes())
            .collect();
        out.put(&levels)?;
        out.pad_to(layout.words.0)?;
        out.put_u32s(&self.words)?;
        out.pad_to(layout.colors.0)?;
        out.put_u32s(&self.colors)?;
        let crc = out.crc.clone().finalize();
        out.inner.write_all(&crc.to_le_bytes())?;
        Ok(())
    }

    /// The `.vdag` v1 bytes of this DAG.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(Layout::of(self).file_size as usize);
        self.write_to(&mut bytes)
            .expect("writing to a Vec cannot fail");
        bytes
    }

    /// Saves the DAG as a `.vdag` v1 file, atomically (temporary file, fsync, rename).
    pub fn save(&self, path: &Path) -> Result<(), DagError> {
        write_atomic(path, |w| self.write_to(w))
    }

    /// Loads and validates a `.vdag` file.
    pub fn load(path: &Path) -> Result<Svdag, DagError> {
        let bytes = std::fs::read(path).map_err(|source| DagError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes, path)
    }

    /// Parses and validates `.vdag` bytes; `name` is used in error messages.
    pub fn from_bytes(bytes: &[u8], name: impl AsRef<Path>) -> Result<Svdag, DagError> {
        let err = |offset: u64, reason: String| DagError::Format {
            path: name.as_ref().to_path_buf(),
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
        if version != FORMAT_VERSION {
            return Err(err(8, format!("unsupported format version {version}")));
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
        let encoding = u32_at(bytes, 12);
        if encoding != Encoding::Svdag32 as u32 {
            return Err(err(12, format!("unknown encoding id {encoding}")));
        }
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
        let color_format = u32_at(bytes, 24);
        if color_format > ColorFormat::Rgba8 as u32 {
            return Err(err(24, format!("unknown colour format id {color_format}")));
        }
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
        let word_count = u64_at(bytes, 40);
        if word_count == 0 || word_count > u32::MAX as u64 {
            return Err(err(
                40,
                format!("word count {word_count} not in 1..=2^32-1"),
            ));
        }
        let color_count = u64_at(bytes, 48);
        if color_format == ColorFormat::None as u32 && color_count != 0 {
            return Err(err(
                48,
                format!("{color_count} colours with colour format 'none'"),
            ));
        }
        if u64_at(bytes, 56) != 0 {
            return Err(err(56, "reserved header field is not zero".into()));
        }

        // Section table: known ids exactly once, inside the file, expected lengths, no overlap.
        let mut sections: [Option<(u64, u64)>; 3] = [None; 3];
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
            let expected = match id {
                SECTION_LEVELS => Some(level_count as u64 * 8),
                SECTION_WORDS => Some(word_count * 4),
                SECTION_COLORS => color_count.checked_mul(4),
                _ => Some(length), // unknown sections are skipped
            };
            if expected != Some(length) {
                return Err(err(
                    at + 16,
                    format!("section {id} is {length} bytes, expected {expected:?}"),
                ));
            }
            if (1..=3).contains(&id) {
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
        let mut get = |id: u32| {
            sections[id as usize - 1]
                .take()
                .ok_or_else(|| err(28, format!("section {id} missing")))
        };
        let (levels_at, levels_len) = get(SECTION_LEVELS)?;
        let (words_at, words_len) = get(SECTION_WORDS)?;
        let (colors_at, colors_len) = get(SECTION_COLORS)?;

        // Every size is now bounded by the file length: allocate and decode.
        let slice = |at: u64, n: u64| &bytes[at as usize..(at + n) as usize];
        let level_starts: Vec<u64> = slice(levels_at, levels_len)
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        let words: Vec<u32> = slice(words_at, words_len)
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        let colors: Vec<u32> = slice(colors_at, colors_len)
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        let dag = Svdag {
            resolution,
            words,
            level_starts,
            colors,
        };
        dag.check().map_err(|(place, reason)| {
            let offset = match place {
                Place::Resolution => 16,
                Place::Level(l) => levels_at + 8 * l as u64,
                Place::Word(w) => words_at + 4 * w as u64,
                Place::Colors => 48,
            };
            err(offset, format!("invalid DAG: {reason}"))
        })?;
        Ok(dag)
    }
}
