//! The Dolonius et al. (2017) variable-bitrate colour format (`ColorFormat::Varbit`), written by
//! the real-time Hough encoder (`lossy`) and the offline encoder (`dolonius`).
//!
//! Colours are cut into blocks of consecutive colours. A block holds either two RGB565 endpoints
//! and one weight of 1-4 bits per colour (colour = lerp of the endpoints by weight / (2^bits - 1))
//! or a single RGB 10-12-10 colour and no weights. Blocks never cross a macro block of
//! [`MACRO_BLOCK_COLORS`] colours, so a colour is found by a binary search among the block start
//! indices of its macro block.
//!
//! # Words (little-endian `u32`, `M` = ceil(count / 16384) macro blocks, `B` blocks)
//! ```text
//! word 0                    B, the number of blocks
//! word 1                    M, the number of macro blocks (must equal ceil(count / 16384))
//! words 2 + 2m, 3 + 2m      macro block m: index of its first block, word offset of its weights
//!                           (relative to word W); its blocks run up to the next macro's first
//!                           block (or B), its first block starts at its first colour
//! words H + 2j, H + 2j + 1  block j (H = 2 + 2M): header word, colour word
//! words W ..                weights (W = H + 2B), LSB-first bit stream; each macro block's
//!                           weights start on a word boundary, a weight may straddle two words
//! ```
//! Header word: bits 0-13 the block's first colour index inside its macro block, bits 14-15
//! bits-per-weight - 1, bits 16-31 the bit offset of the block's weights from its macro block's
//! weights, or `0xFFFF` (and bits 14-15 zero) for a single-colour block. `0xFFFF` is never a real
//! offset: the last block of a macro block starts at most 16383 colours x 4 bits = 65532 bits in.
//!
//! Colour word: endpoints `a565 | b565 << 16` (RGB565: R bits 0-4, G 5-10, B 11-15), or a single
//! colour `r10 | g12 << 10 | b10 << 22`.
//!
//! # Decoding (integer only, so that the GLSL decoder in `shaders/glsl/attr/varbit.glsl` is
//! bit-identical)
//! - RGB565 to 8 bits: `r8 = r5 << 3 | r5 >> 2`, `g8 = g6 << 2 | g6 >> 4`, `b8` like `r8`.
//! - Endpoint blend, per channel, with `n = 2^bits - 1`: `(a8 * (n - w) + b8 * w + n / 2) / n`.
//! - RGB 10-12-10 to 8 bits: `(v * 255 + (max / 2)) / max` with `max` = 1023 or 4095.

use super::{pack_rgb, AttrError};

/// Colours per macro block: blocks never cross a multiple of this index.
pub const MACRO_BLOCK_COLORS: usize = 16 * 1024;
/// Header offset field value marking a single-colour block.
const SINGLE_OFFSET: u32 = 0xFFFF;
const FORMAT: &str = "varbit";

/// Colour payload of a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockColors {
    /// Two RGB565 endpoints; weight 0 decodes to `a565`, the largest weight to `b565`.
    Endpoints {
        /// First endpoint.
        a565: u16,
        /// Second endpoint.
        b565: u16,
    },
    /// One RGB 10-12-10 colour for the whole block (`r | g << 10 | b << 22`).
    Single(u32),
}

/// One block as the encoders produce it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VarbitBlock {
    /// Index of the block's first colour in the chunk.
    pub start: usize,
    /// Bits per weight: 1-4 for `Endpoints`, 0 for `Single`.
    pub bits: u8,
    /// The block's colours.
    pub kind: BlockColors,
    /// One weight per colour of the block (`Endpoints`), empty for `Single`.
    pub weights: Vec<u8>,
}

/// Words before the macro block headers (block count, macro block count).
const FIXED_WORDS: usize = 2;

/// Writes a block list covering colours `0..count` in the word layout of the module docs.
///
/// The blocks must be sorted, start at 0, be non-empty, not cross a macro block and carry one
/// weight (< 2^bits) per colour for endpoint blocks; anything else is an error naming the block.
pub fn write(blocks: &[VarbitBlock], count: usize) -> Result<Vec<u32>, AttrError> {
    let bad = |j: usize, reason: String| AttrError::Corrupt {
        format: FORMAT,
        word: j as u64,
        reason: format!("block {j}: {reason}"),
    };
    let macros = count.div_ceil(MACRO_BLOCK_COLORS);
    let header = FIXED_WORDS + 2 * macros;
    let mut words = vec![0u32; header + 2 * blocks.len()];
    words[0] = blocks.len() as u32;
    words[1] = macros as u32;
    let mut weights = BitWriter::default();
    let mut macro_weight_start = 0usize;
    let mut next_macro = 0usize;
    for (j, block) in blocks.iter().enumerate() {
        let end = blocks.get(j + 1).map_or(count, |b| b.start);
        if block.start >= end || end > count {
            return Err(bad(
                j,
                format!("empty or unsorted ({}..{end})", block.start),
            ));
        }
        let m = block.start / MACRO_BLOCK_COLORS;
        if (end - 1) / MACRO_BLOCK_COLORS != m {
            return Err(bad(j, "crosses a macro block".into()));
        }
        if m + 1 == next_macro {
            // Continuing the current macro block.
        } else if m == next_macro && block.start == m * MACRO_BLOCK_COLORS {
            weights.align_to_word();
            macro_weight_start = weights.bits;
            words[FIXED_WORDS + 2 * m] = j as u32;
            words[FIXED_WORDS + 2 * m + 1] = (weights.bits / 32) as u32;
            next_macro = m + 1;
        } else {
            return Err(bad(j, "macro block does not start with a block".into()));
        }
        let local = (block.start % MACRO_BLOCK_COLORS) as u32;
        let (head, color) = match (block.kind, block.bits) {
            (BlockColors::Single(rgb), 0) if block.weights.is_empty() => {
                (local | SINGLE_OFFSET << 16, rgb)
            }
            (BlockColors::Endpoints { a565, b565 }, bits @ 1..=4) => {
                if block.weights.len() != end - block.start {
                    return Err(bad(j, "one weight per colour needed".into()));
                }
                let offset = (weights.bits - macro_weight_start) as u32;
                for &w in &block.weights {
                    if u32::from(w) >> bits != 0 {
                        return Err(bad(j, format!("weight {w} needs more than {bits} bits")));
                    }
                    weights.push(u32::from(w), u32::from(bits));
                }
                (
                    local | (u32::from(bits) - 1) << 14 | offset << 16,
                    u32::from(a565) | u32::from(b565) << 16,
                )
            }
            _ => return Err(bad(j, "bits do not match the block kind".into())),
        };
        words[header + 2 * j] = head;
        words[header + 2 * j + 1] = color;
    }
    if next_macro != macros {
        return Err(bad(
            blocks.len(),
            format!("blocks do not cover {count} colours"),
        ));
    }
    words.extend_from_slice(&weights.words);
    Ok(words)
}

/// Checks every field of a chunk; `decode_all` and the GPU decoder are safe on words that pass.
pub fn validate(words: &[u32], count: usize) -> Result<(), AttrError> {
    decode_all(words, count).map(|_| ())
}

/// Decodes every colour of a chunk of `count` colours.
pub fn decode_all(words: &[u32], count: usize) -> Result<Vec<u32>, AttrError> {
    let layout = Layout::read(words, count)?;
    let mut out = Vec::with_capacity(count);
    for m in 0..layout.macros {
        let (first, end) = layout.macro_blocks(words, m)?;
        let macro_start = m * MACRO_BLOCK_COLORS;
        let macro_len = (count - macro_start).min(MACRO_BLOCK_COLORS);
        for j in first..end {
            let block_end = if j + 1 < end {
                layout.local_index(words, j + 1) as usize
            } else {
                macro_len
            };
            let local = layout.local_index(words, j) as usize;
            if local != out.len() - macro_start || block_end <= local || block_end > macro_len {
                return Err(corrupt(
                    layout.block_word(j),
                    format!("block {j} starts at {local}, ends at {block_end}"),
                ));
            }
            for i in local..block_end {
                out.push(layout.color(words, m, j, i as u32)?);
            }
        }
    }
    Ok(out)
}

/// Decodes colour `index` of a chunk of `count` colours: a binary search among the blocks of its
/// macro block, O(log blocks).
pub fn decode(words: &[u32], count: usize, index: usize) -> Result<u32, AttrError> {
    if index >= count {
        return Err(AttrError::IndexOutOfRange {
            index: index as u64,
            count: count as u64,
        });
    }
    let layout = Layout::read(words, count)?;
    let m = index / MACRO_BLOCK_COLORS;
    let local = (index % MACRO_BLOCK_COLORS) as u32;
    let (first, end) = layout.macro_blocks(words, m)?;
    // The last block whose first colour is <= local (same loop as the GLSL decoder).
    let (mut lo, mut hi) = (first, end);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if layout.local_index(words, mid) <= local {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    if layout.local_index(words, lo) > local {
        return Err(corrupt(
            layout.block_word(lo),
            "macro block's first block does not start at 0".into(),
        ));
    }
    layout.color(words, m, lo, local)
}

/// RGB565 of an 8-bit colour, rounding each channel to the nearest level.
pub fn rgb565([r, g, b]: [u8; 3]) -> u16 {
    let q = |v: u8, max: u32| (u32::from(v) * max + 127) / 255;
    (q(r, 31) | q(g, 63) << 5 | q(b, 31) << 11) as u16
}

/// The 8-bit channels the decoder expands an RGB565 colour to.
pub fn expand565(c: u16) -> [u8; 3] {
    let c = u32::from(c);
    let (r, g, b) = (c & 31, (c >> 5) & 63, c >> 11);
    [
        (r << 3 | r >> 2) as u8,
        (g << 2 | g >> 4) as u8,
        (b << 3 | b >> 2) as u8,
    ]
}

/// The 8-bit colour the decoder returns for `weight` between two 8-bit endpoints.
pub fn blend(a: [u8; 3], b: [u8; 3], weight: u32, bits: u32) -> [u8; 3] {
    let n = (1u32 << bits) - 1;
    let w = weight.min(n);
    let mix = |a: u8, b: u8| ((u32::from(a) * (n - w) + u32::from(b) * w + n / 2) / n) as u8;
    [mix(a[0], b[0]), mix(a[1], b[1]), mix(a[2], b[2])]
}

/// RGB 10-12-10 word of a colour with channels in [0, 1] (clamped, rounded).
pub fn rgb101210(rgb: [f32; 3]) -> u32 {
    let q = |v: f32, max: f32| (v.clamp(0.0, 1.0) * max).round() as u32;
    q(rgb[0], 1023.0) | q(rgb[1], 4095.0) << 10 | q(rgb[2], 1023.0) << 22
}

/// The 8-bit channels the decoder expands an RGB 10-12-10 word to.
pub fn expand101210(c: u32) -> [u8; 3] {
    let q = |v: u32, max: u32| ((v * 255 + max / 2) / max) as u8;
    [
        q(c & 1023, 1023),
        q((c >> 10) & 4095, 4095),
        q(c >> 22, 1023),
    ]
}

/// The largest per-channel difference, in 8-bit steps, that a threshold in [0, 1] allows:
/// `floor(threshold * 255)` (NaN and negative thresholds allow none).
pub fn max_delta(threshold: f32) -> u8 {
    let threshold = threshold.clamp(0.0, 1.0);
    // The epsilon keeps thresholds given as k / 255 at k despite float rounding; the check
    // after it keeps the promise `max_delta(t) / 255 <= t` for thresholds just below k / 255.
    let steps = (threshold * 255.0 + 1e-3).floor() as u8;
    if f32::from(steps) / 255.0 > threshold {
        steps - 1
    } else {
        steps
    }
}

/// Largest channel difference between two colours.
pub fn channel_error(a: [u8; 3], b: [u8; 3]) -> u8 {
    (0..3).map(|c| a[c].abs_diff(b[c])).max().unwrap_or(0)
}

/// A single-colour block for `colors` (starting at chunk index `start`) if one colour is within
/// `max_delta` of all of them: the centre of their per-channel range, in RGB 10-12-10.
pub fn single_block(colors: &[[u8; 3]], start: usize, max_delta: u8) -> Option<VarbitBlock> {
    let (mut lo, mut hi) = ([255u8; 3], [0u8; 3]);
    for c in colors {
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    if (0..3).any(|k| hi[k] - lo[k] > max_delta.saturating_mul(2)) {
        return None;
    }
    let centre = |k: usize| (f32::from(lo[k]) + f32::from(hi[k])) / 510.0;
    let word = rgb101210([centre(0), centre(1), centre(2)]);
    let decoded = expand101210(word);
    colors
        .iter()
        .all(|c| channel_error(*c, decoded) <= max_delta)
        .then(|| VarbitBlock {
            start,
            bits: 0,
            kind: BlockColors::Single(word),
            weights: Vec::new(),
        })
}

/// An endpoint block for `colors` (starting at chunk index `start`) on the line from `a` to `b`
/// (channels in [0, 255]), quantized to RGB565, with the fewest bits per weight in `bits` whose
/// decoded colours are all within `max_delta`. Each colour gets the weight nearest its projection
/// on the quantized line, or a neighbour of it when that one decodes closer.
///
/// `Err(i)`: with the most bits tried, colour `i` of `colors` is the first that fails.
pub fn endpoint_block(
    colors: &[[u8; 3]],
    start: usize,
    [a, b]: [[f32; 3]; 2],
    bits: std::ops::RangeInclusive<u8>,
    max_delta: u8,
) -> Result<VarbitBlock, usize> {
    let quantize = |p: [f32; 3]| rgb565(p.map(|v| v.clamp(0.0, 255.0).round() as u8));
    let (a565, b565) = (quantize(a), quantize(b));
    let (a8, b8) = (expand565(a565), expand565(b565));
    let dir = [0, 1, 2].map(|k| f32::from(b8[k]) - f32::from(a8[k]));
    let len2 = dir.iter().map(|d| d * d).sum::<f32>();
    let mut first_fail = 0;
    let mut weights = Vec::with_capacity(colors.len());
    for bits in bits {
        let n = (1u32 << bits) - 1;
        weights.clear();
        let fail = colors.iter().position(|c| {
            let t = if len2 > 0.0 {
                (0..3)
                    .map(|k| (f32::from(c[k]) - f32::from(a8[k])) * dir[k])
                    .sum::<f32>()
                    / len2
            } else {
                0.0
            };
            let nearest = (t.clamp(0.0, 1.0) * n as f32).round() as u32;
            // Of the weights within the threshold, the one with the least squared error.
            let (w, err, _) = [nearest.saturating_sub(1), nearest, (nearest + 1).min(n)]
                .into_iter()
                .map(|w| {
                    let decoded = blend(a8, b8, w, u32::from(bits));
                    let squared: u32 = (0..3)
                        .map(|k| u32::from(c[k].abs_diff(decoded[k])).pow(2))
                        .sum();
                    (w, channel_error(*c, decoded), squared)
                })
                .min_by_key(|&(_, err, squared)| (err > max_delta, squared))
                .unwrap_or((nearest, u8::MAX, 0));
            weights.push(w as u8);
            err > max_delta
        });
        match fail {
            None => {
                return Ok(VarbitBlock {
                    start,
                    bits,
                    kind: BlockColors::Endpoints { a565, b565 },
                    weights,
                })
            }
            Some(i) => first_fail = i,
        }
    }
    Err(first_fail)
}

/// The longest prefix length in `1..=max_len` that `fit` accepts, with `fit`'s block: lengths
/// double while `fit` accepts them, then a binary search between the last accepted and the first
/// refused length (a search that assumes shorter prefixes fit when longer ones do; every
/// returned block was accepted by `fit`).
pub fn longest_prefix(
    max_len: usize,
    mut fit: impl FnMut(usize) -> Option<VarbitBlock>,
) -> Option<(usize, VarbitBlock)> {
    let mut best = None;
    let (mut fits, mut fails) = (0, max_len + 1);
    let mut len = 1.min(max_len);
    while len > fits {
        match fit(len) {
            Some(block) => {
                best = Some((len, block));
                fits = len;
                len = if fails > max_len {
                    (2 * len).min(max_len)
                } else {
                    (len + fails) / 2
                };
            }
            None => {
                fails = len;
                len = (fits + fails) / 2;
            }
        }
    }
    best
}

fn corrupt(word: usize, reason: String) -> AttrError {
    AttrError::Corrupt {
        format: FORMAT,
        word: word as u64,
        reason,
    }
}

/// Section boundaries of a chunk, checked against the slice length.
struct Layout {
    blocks: usize,
    macros: usize,
    /// First block word.
    header: usize,
    /// First weight word.
    weights: usize,
    len: usize,
}

impl Layout {
    fn read(words: &[u32], count: usize) -> Result<Layout, AttrError> {
        if words.len() < FIXED_WORDS {
            return Err(corrupt(0, format!("{} words, header needs 2", words.len())));
        }
        let (blocks, macros) = (words[0] as usize, words[1] as usize);
        if macros != count.div_ceil(MACRO_BLOCK_COLORS) {
            return Err(corrupt(
                1,
                format!("{macros} macro blocks for {count} colours"),
            ));
        }
        let header = FIXED_WORDS + 2 * macros;
        if blocks < macros || blocks > count || (words.len() - header.min(words.len())) / 2 < blocks
        {
            return Err(corrupt(0, format!("{blocks} blocks do not fit")));
        }
        Ok(Layout {
            blocks,
            macros,
            header,
            weights: header + 2 * blocks,
            len: words.len(),
        })
    }

    /// Blocks `first..end` of macro block `m`, non-empty and in range.
    fn macro_blocks(&self, words: &[u32], m: usize) -> Result<(usize, usize), AttrError> {
        let at = FIXED_WORDS + 2 * m;
        let first = words[at] as usize;
        let end = if m + 1 < self.macros {
            words[at + 2] as usize
        } else {
            self.blocks
        };
        if first >= end || end > self.blocks {
            return Err(corrupt(
                at,
                format!("macro block {m} has blocks {first}..{end}"),
            ));
        }
        Ok((first, end))
    }

    fn block_word(&self, j: usize) -> usize {
        self.header + 2 * j
    }

    fn local_index(&self, words: &[u32], j: usize) -> u32 {
        words[self.block_word(j)] & (MACRO_BLOCK_COLORS as u32 - 1)
    }

    /// Colour at local index `local` of block `j` in macro block `m` (`local` inside the block).
    fn color(&self, words: &[u32], m: usize, j: usize, local: u32) -> Result<u32, AttrError> {
        let head = words[self.block_word(j)];
        let color = words[self.block_word(j) + 1];
        let offset = head >> 16;
        let bits = (head >> 14 & 3) + 1;
        if offset == SINGLE_OFFSET {
            if bits != 1 {
                return Err(corrupt(self.block_word(j), "single block with bits".into()));
            }
            return Ok(pack_rgb(expand101210(color)));
        }
        let macro_weights = words[FIXED_WORDS + 2 * m + 1] as u64;
        let bit = (self.weights as u64 + macro_weights) * 32
            + u64::from(offset)
            + u64::from(local - (head & (MACRO_BLOCK_COLORS as u32 - 1))) * u64::from(bits);
        let word = (bit / 32) as usize;
        let shift = (bit % 32) as u32;
        let straddles = shift + bits > 32;
        if bit + u64::from(bits) > self.len as u64 * 32 {
            return Err(corrupt(
                self.block_word(j),
                format!("weight bit {bit} past the end"),
            ));
        }
        let mut w = words[word] >> shift;
        if straddles {
            w |= words[word + 1] << (32 - shift);
        }
        let w = w & ((1 << bits) - 1);
        let a = expand565(color as u16);
        let b = expand565((color >> 16) as u16);
        Ok(pack_rgb(blend(a, b, w, bits)))
    }
}

/// Appends bit fields LSB-first to a word vector.
#[derive(Default)]
struct BitWriter {
    words: Vec<u32>,
    bits: usize,
}

impl BitWriter {
    fn push(&mut self, value: u32, bits: u32) {
        let shift = (self.bits % 32) as u32;
        if shift == 0 {
            self.words.push(0);
        }
        let last = self.words.len() - 1;
        self.words[last] |= value << shift;
        if shift + bits > 32 {
            self.words.push(value >> (32 - shift));
        }
        self.bits += bits as usize;
    }

    fn align_to_word(&mut self) {
        self.bits = self.words.len() * 32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_trip() {
        for v in 0..=255u8 {
            assert_eq!(expand101210(rgb101210([v as f32 / 255.0; 3])), [v; 3]);
        }
        for c in [0u16, 0xffff, 0x1234, 0xf81f] {
            assert_eq!(rgb565(expand565(c)), c);
        }
        assert_eq!(blend([0; 3], [255; 3], 3, 2), [255; 3]);
        assert_eq!(blend([0; 3], [255; 3], 0, 4), [0; 3]);
    }

    #[test]
    fn write_rejects_bad_block_lists() {
        let single = |start| VarbitBlock {
            start,
            bits: 0,
            kind: BlockColors::Single(0),
            weights: vec![],
        };
        assert!(write(&[single(0)], 3).is_ok());
        assert!(write(&[single(1)], 3).is_err());
        assert!(write(&[single(0), single(0)], 3).is_err());
        assert!(write(&[single(0)], MACRO_BLOCK_COLORS + 1).is_err());
        assert!(write(&[], 1).is_err());
        assert_eq!(write(&[], 0).unwrap(), vec![0, 0]);
        let mut bad_weight = single(0);
        bad_weight.kind = BlockColors::Endpoints { a565: 0, b565: 1 };
        bad_weight.bits = 1;
        bad_weight.weights = vec![0, 2, 1];
        assert!(write(&[bad_weight], 3).is_err());
    }
}
