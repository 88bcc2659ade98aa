//! The lossless palette colour format of Dado et al. 2016 (`ColorFormat::Palette`), a baseline:
//! colours are cut into blocks of [`BLOCK_COLORS`]; each block stores its distinct colours once
//! (in order of first appearance) and one index of ceil(log2(palette size)) bits per colour
//! (no index bits for a one-colour block).
//!
//! # Words (little-endian `u32`, `N` = ceil(count / BLOCK_COLORS) blocks)
//! ```text
//! words 0 .. N      word offset (from the chunk start) of each block
//! block at offset o:
//!   word o          palette size P (1 ..= BLOCK_COLORS)
//!   words o + 1 ..  bit stream, LSB-first, starting on word o + 1: P palette entries of 24 bits
//!                   (r | g << 8 | b << 16), then one index per colour of the block
//! ```
//! Colour `i` of a block with `P` entries and `k = ceil(log2 P)` index bits: its index starts
//! at bit `24 P + k i` of the block's stream. The GLSL twin is `shaders/glsl/attr/palette.glsl`.

use rustc_hash::FxHashMap;

use super::{pack_rgb, AttrError};

/// Colours per palette block.
pub const BLOCK_COLORS: usize = 1024;
const FORMAT: &str = "palette";
const ENTRY_BITS: u64 = 24;

/// Encodes RGBA8 colours (alpha ignored) without loss.
pub fn encode(colors: &[u32]) -> Vec<u32> {
    let blocks = colors.len().div_ceil(BLOCK_COLORS);
    let mut words = vec![0u32; blocks];
    let mut slot: FxHashMap<u32, u32> = FxHashMap::default();
    for (n, block) in colors.chunks(BLOCK_COLORS).enumerate() {
        slot.clear();
        let mut palette = Vec::new();
        let indices: Vec<u32> = block
            .iter()
            .map(|&c| {
                let rgb = c & 0x00ff_ffff;
                *slot.entry(rgb).or_insert_with(|| {
                    palette.push(rgb);
                    palette.len() as u32 - 1
                })
            })
            .collect();
        words[n] = words.len() as u32;
        words.push(palette.len() as u32);
        let bits = index_bits(palette.len() as u32);
        let mut stream = BitStream::default();
        for &entry in &palette {
            stream.push(entry, ENTRY_BITS as u32);
        }
        for &index in &indices {
            stream.push(index, bits);
        }
        words.extend_from_slice(&stream.words);
    }
    words
}

/// Decodes every colour of a chunk of `count` colours.
pub fn decode_all(words: &[u32], count: usize) -> Result<Vec<u32>, AttrError> {
    let mut out = Vec::with_capacity(count);
    for n in 0..count.div_ceil(BLOCK_COLORS) {
        let block = Block::read(words, count, n)?;
        for i in 0..block.len {
            out.push(block.color(words, i)?);
        }
    }
    Ok(out)
}

/// Decodes colour `index` of a chunk of `count` colours (O(1)).
pub fn decode(words: &[u32], count: usize, index: usize) -> Result<u32, AttrError> {
    if index >= count {
        return Err(AttrError::IndexOutOfRange {
            index: index as u64,
            count: count as u64,
        });
    }
    Block::read(words, count, index / BLOCK_COLORS)?.color(words, index % BLOCK_COLORS)
}

/// Index bits for a palette of `size` entries.
fn index_bits(size: u32) -> u32 {
    if size <= 1 {
        0
    } else {
        32 - (size - 1).leading_zeros()
    }
}

fn corrupt(word: u64, reason: String) -> AttrError {
    AttrError::Corrupt {
        format: FORMAT,
        word,
        reason,
    }
}

/// One block's fields, checked against the slice length.
struct Block {
    /// First bit of the block's stream.
    stream: u64,
    palette: u32,
    bits: u32,
    len: usize,
}

impl Block {
    fn read(words: &[u32], count: usize, n: usize) -> Result<Block, AttrError> {
        let blocks = count.div_ceil(BLOCK_COLORS);
        if words.len() < blocks {
            return Err(corrupt(
                0,
                format!("{} words hold no {blocks} offsets", words.len()),
            ));
        }
        let offset = words[n] as usize;
        if offset < blocks || offset >= words.len() {
            return Err(corrupt(n as u64, format!("block {n} at word {offset}")));
        }
        let len = (count - n * BLOCK_COLORS).min(BLOCK_COLORS);
        let palette = words[offset];
        if palette == 0 || palette as usize > len {
            return Err(corrupt(
                offset as u64,
                format!("palette of {palette} for {len} colours"),
            ));
        }
        let bits = index_bits(palette);
        let stream = (offset as u64 + 1) * 32;
        let end = stream + ENTRY_BITS * u64::from(palette) + u64::from(bits) * len as u64;
        if end > words.len() as u64 * 32 {
            return Err(corrupt(
                offset as u64,
                format!("block {n} runs past the end"),
            ));
        }
        Ok(Block {
            stream,
            palette,
            bits,
            len,
        })
    }

    fn color(&self, words: &[u32], i: usize) -> Result<u32, AttrError> {
        let index = read_bits(
            words,
            self.stream + ENTRY_BITS * u64::from(self.palette) + u64::from(self.bits) * i as u64,
            self.bits,
        );
        if index >= self.palette {
            return Err(corrupt(
                self.stream / 32,
                format!("index {index} past a palette of {}", self.palette),
            ));
        }
        let rgb = read_bits(
            words,
            self.stream + ENTRY_BITS * u64::from(index),
            ENTRY_BITS as u32,
        );
        Ok(pack_rgb([rgb as u8, (rgb >> 8) as u8, (rgb >> 16) as u8]))
    }
}

/// `bits` (0..=24) bits at bit position `bit`; the caller has checked the range.
fn read_bits(words: &[u32], bit: u64, bits: u32) -> u32 {
    if bits == 0 {
        return 0;
    }
    let word = (bit / 32) as usize;
    let shift = (bit % 32) as u32;
    let mut v = words[word] >> shift;
    if shift + bits > 32 {
        v |= words[word + 1] << (32 - shift);
    }
    v & ((1u32 << bits) - 1)
}

/// Appends bit fields LSB-first.
#[derive(Default)]
struct BitStream {
    words: Vec<u32>,
    bits: u32,
}

impl BitStream {
    fn push(&mut self, value: u32, bits: u32) {
        if bits == 0 {
            return;
        }
        let shift = self.bits % 32;
        if shift == 0 {
            self.words.push(0);
        }
        let last = self.words.len() - 1;
        self.words[last] |= value << shift;
        if shift + bits > 32 {
            self.words.push(value >> (32 - shift));
        }
        self.bits += bits;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_bits_are_ceil_log2() {
        let want = [(1, 0), (2, 1), (3, 2), (4, 2), (5, 3), (1024, 10)];
        for (size, bits) in want {
            assert_eq!(index_bits(size), bits, "{size}");
        }
    }
}
