//! The real-time lossless colour codec (dissertation §5.2.1), CPU reference.
//!
//! Blocks of 128 colours; per block a per-channel minimum (normalization), a per-channel shift
//! `s` splitting each normalized value `n = c - min` into a 3-bit reference part `n >> s` and a
//! frame-of-reference offset `n & (2^s - 1)`, a palette of the references, a 128-bit mask marking
//! where the reference changes, and fixed-width offsets. A colour decodes in O(1): block offset
//! lookup, header, popcount of the mask, two fixed-width bit fields. The exact word layout is in
//! `docs/colors-lossless.md`; the GPU encoder (`attr_gpu::lossless`, `shaders/glsl/attr/`)
//! produces the same words bit for bit, and `shaders/glsl/attr/lossless.glsl` decodes them.
//!
//! Chunk words: `[block 0][64-bit word offsets of blocks 1.., 2 words each][blocks 1..]`: a
//! chunk of at most 128 colours is one bare block, so small chunks pay no table. The table
//! starts where block 0 ends, and block 0 (128 colours when there are more blocks) has its size
//! in its header. Block words: `[header A: minimums][header B: shifts, counts, flags, variant]
//! [mask: ceil(n / 32) words, only with more than one run][bit stream: palette, run indices
//! (indexed blocks), offsets]`.

use rayon::prelude::*;

use super::AttrError;

/// Colours per block.
pub const BLOCK_COLORS: usize = 128;
/// Words of a block header.
pub const BLOCK_HEADER_WORDS: usize = 2;
/// Words of the run-change mask of a full block (present only when a block has more than one
/// run; a shorter last block has `ceil(n / 32)`).
pub const MASK_WORDS: usize = 4;
/// Bits of one palette entry: 3 bits per channel.
pub const PALETTE_ENTRY_BITS: u32 = 9;
/// Extra shifts the encoder tries on top of the minimal one (0..EXTRA_SHIFTS).
pub const EXTRA_SHIFTS: u32 = 4;

const FORMAT: &str = "lossless";

/// Which colours the codec stores exactly.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LosslessVariant {
    /// 8 bits per channel, exact.
    Rgb888,
    /// Colours quantized to 5-6-5 bits first (round to nearest), then coded exactly; decoding
    /// expands to 8 bits by bit replication.
    Rgb565,
}

impl LosslessVariant {
    /// Id stored in bit 29 of every block header.
    pub fn id(self) -> u32 {
        match self {
            LosslessVariant::Rgb888 => 0,
            LosslessVariant::Rgb565 => 1,
        }
    }

    /// The variant with stored id `id`, if any.
    pub fn from_id(id: u32) -> Option<LosslessVariant> {
        match id {
            0 => Some(LosslessVariant::Rgb888),
            1 => Some(LosslessVariant::Rgb565),
            _ => None,
        }
    }

    /// Bits per channel of the coded values.
    pub fn channel_bits(self) -> [u32; 3] {
        match self {
            LosslessVariant::Rgb888 => [8, 8, 8],
            LosslessVariant::Rgb565 => [5, 6, 5],
        }
    }

    /// The coded channel values of an RGBA8 colour (quantized for RGB565).
    pub fn to_channels(self, color: u32) -> [u32; 3] {
        let c = super::rgb(color);
        match self {
            LosslessVariant::Rgb888 => [c[0] as u32, c[1] as u32, c[2] as u32],
            LosslessVariant::Rgb565 => [quantize(c[0], 5), quantize(c[1], 6), quantize(c[2], 5)],
        }
    }

    /// The opaque RGBA8 colour of coded channel values (expanded for RGB565).
    pub fn to_color(self, ch: [u32; 3]) -> u32 {
        match self {
            LosslessVariant::Rgb888 => super::pack_rgb([ch[0] as u8, ch[1] as u8, ch[2] as u8]),
            LosslessVariant::Rgb565 => {
                super::pack_rgb([expand(ch[0], 5), expand(ch[1], 6), expand(ch[2], 5)])
            }
        }
    }
}

/// `v` (8 bits) rounded to the nearest of `bits` bits: `(v * (2^bits - 1) + 127) / 255`.
pub fn quantize(v: u8, bits: u32) -> u32 {
    let max = (1u32 << bits) - 1;
    (v as u32 * max + 127) / 255
}

/// `v` (`bits` bits) expanded to 8 bits by bit replication.
pub fn expand(v: u32, bits: u32) -> u8 {
    ((v << (8 - bits)) | (v >> (2 * bits - 8))) as u8
}

/// What the encoder chose for one block (the two header words), with its colour count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct BlockPlan {
    variant: LosslessVariant,
    colors: usize,
    min: [u32; 3],
    shift: [u32; 3],
    runs: u32,
    palette: u32,
    indexed: bool,
}

/// Number of bits needed for `v` (0 for 0).
fn bit_length(v: u32) -> u32 {
    32 - v.leading_zeros()
}

/// The 9-bit reference of normalized channel values.
fn reference(n: [u32; 3], shift: [u32; 3]) -> u32 {
    (n[0] >> shift[0]) | (n[1] >> shift[1]) << 3 | (n[2] >> shift[2]) << 6
}

impl BlockPlan {
    fn header(&self) -> [u32; 2] {
        let a = self.min[0] | self.min[1] << 8 | self.min[2] << 16;
        let mask_field = (self.mask_words() as u32).saturating_sub(1);
        let b = self.shift[0]
            | self.shift[1] << 4
            | self.shift[2] << 8
            | (self.runs - 1) << 12
            | (self.palette - 1) << 19
            | (self.indexed as u32) << 26
            | mask_field << 27
            | self.variant.id() << 29;
        [a, b]
    }

    fn offset_bits(&self) -> u32 {
        self.shift.iter().sum()
    }

    fn index_bits(&self) -> u32 {
        if self.indexed {
            bit_length(self.palette - 1)
        } else {
            0
        }
    }

    /// Bits of the bit stream: palette, run indices, offsets.
    fn stream_bits(&self) -> u64 {
        self.palette as u64 * PALETTE_ENTRY_BITS as u64
            + self.runs as u64 * self.index_bits() as u64
            + self.colors as u64 * self.offset_bits() as u64
    }

    fn mask_words(&self) -> usize {
        if self.runs > 1 {
            self.colors.div_ceil(32)
        } else {
            0
        }
    }

    /// Total words of the block.
    fn words(&self) -> usize {
        BLOCK_HEADER_WORDS + self.mask_words() + self.stream_bits().div_ceil(32) as usize
    }
}

/// Runs, distinct references and the palette mode for one choice of shifts.
fn plan_with_shift(
    ch: &[[u32; 3]],
    variant: LosslessVariant,
    min: [u32; 3],
    shift: [u32; 3],
) -> BlockPlan {
    let mut seen = [0u32; 16];
    let mut runs = 0u32;
    let mut prev = u32::MAX;
    for c in ch {
        let r = reference([c[0] - min[0], c[1] - min[1], c[2] - min[2]], shift);
        if r != prev {
            runs += 1;
            prev = r;
        }
        seen[(r >> 5) as usize] |= 1 << (r & 31);
    }
    let palette: u32 = seen.iter().map(|w| w.count_ones()).sum();
    let direct_bits = runs * PALETTE_ENTRY_BITS;
    let indexed_bits = palette * PALETTE_ENTRY_BITS + runs * bit_length(palette - 1);
    let indexed = indexed_bits < direct_bits;
    BlockPlan {
        variant,
        colors: ch.len(),
        min,
        shift,
        runs,
        palette: if indexed { palette } else { runs },
        indexed,
    }
}

/// Chooses the block's shifts: the smallest that makes references 3-bit, plus 0..EXTRA_SHIFTS
/// (capped at the channel's range), keeping the first choice of fewest words.
fn plan_block(ch: &[[u32; 3]], variant: LosslessVariant) -> BlockPlan {
    let mut min = [u32::MAX; 3];
    let mut max = [0u32; 3];
    for c in ch {
        for k in 0..3 {
            min[k] = min[k].min(c[k]);
            max[k] = max[k].max(c[k]);
        }
    }
    let range_bits = [0, 1, 2].map(|k| bit_length(max[k] - min[k]));
    let mut best = plan_with_shift(ch, variant, min, range_bits.map(|b| b.saturating_sub(3)));
    for extra in 1..EXTRA_SHIFTS {
        let shift = range_bits.map(|b| (b.saturating_sub(3) + extra).min(b));
        let plan = plan_with_shift(ch, variant, min, shift);
        if plan.words() < best.words() {
            best = plan;
        }
    }
    best
}

/// LSB-first bit writer over a block's words.
struct BitWriter<'a> {
    words: &'a mut [u32],
    pos: u64,
}

impl BitWriter<'_> {
    /// Writes the low `width` (≤ 32) bits of `value`.
    fn put(&mut self, value: u32, width: u32) {
        if width == 0 {
            return;
        }
        let w = (self.pos >> 5) as usize;
        let bit = (self.pos & 31) as u32;
        let value = value as u64 & ((1u64 << width) - 1);
        self.words[w] |= (value << bit) as u32;
        if bit + width > 32 {
            self.words[w + 1] |= (value >> (32 - bit)) as u32;
        }
        self.pos += width as u64;
    }
}

/// Writes the block of `ch` with `plan` into `out` (zeroed, `plan.words()` long).
fn write_block(ch: &[[u32; 3]], plan: &BlockPlan, out: &mut [u32]) {
    out[..2].copy_from_slice(&plan.header());
    let refs: Vec<u32> = ch
        .iter()
        .map(|c| {
            reference(
                [c[0] - plan.min[0], c[1] - plan.min[1], c[2] - plan.min[2]],
                plan.shift,
            )
        })
        .collect();
    // Mask: bit i set where colour i starts a new run (bit 0 stays clear).
    let mask_words = plan.mask_words();
    let mut run_refs = Vec::with_capacity(plan.runs as usize);
    for (i, &r) in refs.iter().enumerate() {
        if i == 0 || r != refs[i - 1] {
            if i > 0 {
                out[BLOCK_HEADER_WORDS + i / 32] |= 1 << (i % 32);
            }
            run_refs.push(r);
        }
    }
    let mut bits = BitWriter {
        words: &mut out[BLOCK_HEADER_WORDS + mask_words..],
        pos: 0,
    };
    if plan.indexed {
        // Palette: the distinct references in ascending order; a run stores its rank.
        let mut seen = [0u32; 16];
        for &r in &run_refs {
            seen[(r >> 5) as usize] |= 1 << (r & 31);
        }
        for r in 0..512u32 {
            if seen[(r >> 5) as usize] & (1 << (r & 31)) != 0 {
                bits.put(r, PALETTE_ENTRY_BITS);
            }
        }
        let index_bits = plan.index_bits();
        for &r in &run_refs {
            let below: u32 = seen[..(r >> 5) as usize]
                .iter()
                .map(|w| w.count_ones())
                .sum::<u32>()
                + (seen[(r >> 5) as usize] & ((1u32 << (r & 31)) - 1)).count_ones();
            bits.put(below, index_bits);
        }
    } else {
        for &r in &run_refs {
            bits.put(r, PALETTE_ENTRY_BITS);
        }
    }
    let low = plan.shift.map(|s| (1u32 << s) - 1);
    let width = plan.offset_bits();
    for c in ch {
        let n = [0, 1, 2].map(|k| (c[k] - plan.min[k]) & low[k]);
        bits.put(
            n[0] | n[1] << plan.shift[0] | n[2] << (plan.shift[0] + plan.shift[1]),
            width,
        );
    }
}

/// Encodes a chunk of RGBA8 colours (alpha ignored) into self-contained words; no colours give
/// no words.
pub fn encode(colors: &[u32], variant: LosslessVariant) -> Vec<u32> {
    let blocks: Vec<Vec<u32>> = colors
        .par_chunks(BLOCK_COLORS)
        .map(|block| {
            let ch: Vec<[u32; 3]> = block.iter().map(|&c| variant.to_channels(c)).collect();
            let plan = plan_block(&ch, variant);
            let mut out = vec![0u32; plan.words()];
            write_block(&ch, &plan, &mut out);
            out
        })
        .collect();
    let Some((first, rest)) = blocks.split_first() else {
        return Vec::new();
    };
    let table = 2 * rest.len();
    let total = first.len() + table + rest.iter().map(Vec::len).sum::<usize>();
    let mut words = Vec::with_capacity(total);
    words.extend_from_slice(first);
    let mut offset = (first.len() + table) as u64;
    for b in rest {
        words.extend_from_slice(&[offset as u32, (offset >> 32) as u32]);
        offset += b.len() as u64;
    }
    for b in rest {
        words.extend_from_slice(b);
    }
    words
}

fn corrupt(word: usize, reason: impl Into<String>) -> AttrError {
    AttrError::Corrupt {
        format: FORMAT,
        word: word as u64,
        reason: reason.into(),
    }
}

/// A chunk whose block 0 header and offset table position were checked.
struct Chunk<'a> {
    words: &'a [u32],
    blocks: usize,
    count: usize,
    /// Word where the offset table of blocks 1.. starts (the end of block 0).
    table: usize,
}

/// A validated block header and the block's first word inside the chunk.
struct Block {
    plan: BlockPlan,
    start: usize,
}

impl<'a> Chunk<'a> {
    fn open(words: &'a [u32], count: usize) -> Result<Chunk<'a>, AttrError> {
        let mut chunk = Chunk {
            words,
            blocks: count.div_ceil(BLOCK_COLORS),
            count,
            table: 0,
        };
        if chunk.blocks > 0 {
            let first = chunk.block_at(0, 0)?;
            chunk.table = first.plan.words();
            if (words.len() - chunk.table) / 2 < chunk.blocks - 1 {
                return Err(corrupt(
                    words.len(),
                    format!(
                        "{count} colours need {} block offsets; chunk too short",
                        chunk.blocks - 1
                    ),
                ));
            }
        }
        Ok(chunk)
    }

    fn table_end(&self) -> usize {
        self.table + 2 * (self.blocks - 1)
    }

    fn block(&self, b: usize) -> Result<Block, AttrError> {
        if b == 0 {
            return self.block_at(0, 0);
        }
        let at = self.table + 2 * (b - 1);
        let offset = self.words[at] as u64 | (self.words[at + 1] as u64) << 32;
        if offset < self.table_end() as u64 || offset >= self.words.len() as u64 {
            return Err(corrupt(
                at,
                format!("block {b} offset {offset} out of range"),
            ));
        }
        self.block_at(b, offset as usize)
    }

    /// Reads and checks the header of block `b` at word `start`.
    fn block_at(&self, b: usize, start: usize) -> Result<Block, AttrError> {
        let len = self.words.len();
        if start + BLOCK_HEADER_WORDS > len {
            return Err(corrupt(
                start,
                format!("block {b} header past the chunk end"),
            ));
        }
        let [a, h] = [self.words[start], self.words[start + 1]];
        if a >> 24 != 0 || h >> 30 != 0 {
            return Err(corrupt(start, "reserved header bits set"));
        }
        let variant = if h >> 29 & 1 == 0 {
            LosslessVariant::Rgb888
        } else {
            LosslessVariant::Rgb565
        };
        let bits = variant.channel_bits();
        let min = [a & 0xff, (a >> 8) & 0xff, (a >> 16) & 0xff];
        let shift = [h & 15, (h >> 4) & 15, (h >> 8) & 15];
        for k in 0..3 {
            if bit_length(min[k]) > bits[k] || shift[k] > bits[k] {
                return Err(corrupt(
                    start,
                    format!("channel {k} min/shift out of range"),
                ));
            }
        }
        let plan = BlockPlan {
            variant,
            colors: (self.count - b * BLOCK_COLORS).min(BLOCK_COLORS),
            min,
            shift,
            runs: ((h >> 12) & 127) + 1,
            palette: ((h >> 19) & 127) + 1,
            indexed: (h >> 26) & 1 != 0,
        };
        let (runs, palette, colors) = (plan.runs, plan.palette, plan.colors);
        let mask_field = ((h >> 27) & 3) as usize;
        if runs as usize > colors
            || (!plan.indexed && palette != runs)
            || palette > runs
            || mask_field != plan.mask_words().saturating_sub(1)
        {
            return Err(corrupt(
                start + 1,
                format!(
                    "{runs} runs / {palette} palette entries / {} mask words in a block of {colors}",
                    mask_field + 1
                ),
            ));
        }
        if start as u64 + plan.words() as u64 > len as u64 {
            return Err(corrupt(start, format!("block {b} runs past the chunk end")));
        }
        if plan.runs > 1 {
            let mask = &self.words[start + BLOCK_HEADER_WORDS..][..plan.mask_words()];
            let valid = valid_mask(colors);
            let ones: u32 = mask.iter().map(|w| w.count_ones()).sum();
            if mask.iter().zip(valid).any(|(m, v)| m & !v != 0) || ones + 1 != runs {
                return Err(corrupt(
                    start + BLOCK_HEADER_WORDS,
                    format!("run mask does not mark {} run starts", runs - 1),
                ));
            }
        }
        Ok(Block { plan, start })
    }

    /// Colour `i` (below the block's colour count) of a validated block.
    fn color(&self, block: &Block, i: usize) -> Result<u32, AttrError> {
        let p = &block.plan;
        let mask_words = p.mask_words();
        let run = if mask_words > 0 {
            run_of(
                &self.words[block.start + BLOCK_HEADER_WORDS..][..mask_words],
                i,
            )
        } else {
            0
        };
        let stream = block.start + BLOCK_HEADER_WORDS + mask_words;
        let words = &self.words[stream..];
        let palette_bits = p.palette as u64 * PALETTE_ENTRY_BITS as u64;
        let entry = if p.indexed {
            let ib = p.index_bits();
            let idx = read_bits(words, palette_bits + run as u64 * ib as u64, ib);
            if idx >= p.palette {
                return Err(corrupt(
                    stream,
                    format!("palette index {idx} ≥ {}", p.palette),
                ));
            }
            idx
        } else {
            run
        };
        let r = read_bits(
            words,
            entry as u64 * PALETTE_ENTRY_BITS as u64,
            PALETTE_ENTRY_BITS,
        );
        let offsets_at = palette_bits + p.runs as u64 * p.index_bits() as u64;
        let width = p.offset_bits();
        let off = read_bits(words, offsets_at + i as u64 * width as u64, width);
        let refs = [r & 7, (r >> 3) & 7, (r >> 6) & 7];
        let offs = [
            off & ((1 << p.shift[0]) - 1),
            (off >> p.shift[0]) & ((1 << p.shift[1]) - 1),
            (off >> (p.shift[0] + p.shift[1])) & ((1 << p.shift[2]) - 1),
        ];
        let bits = p.variant.channel_bits();
        let mut ch = [0u32; 3];
        for k in 0..3 {
            ch[k] = p.min[k] + (refs[k] << p.shift[k]) + offs[k];
            if bit_length(ch[k]) > bits[k] {
                return Err(corrupt(
                    stream,
                    format!("channel {k} value {} overflows", ch[k]),
                ));
            }
        }
        Ok(p.variant.to_color(ch))
    }
}

/// Mask bits that may be set in a block of `colors` colours (bits 1..colors).
fn valid_mask(colors: usize) -> [u32; MASK_WORDS] {
    let mut v = [0u32; MASK_WORDS];
    for (w, word) in v.iter_mut().enumerate() {
        let lo = w * 32;
        let n = colors.saturating_sub(lo).min(32);
        *word = if n == 32 { u32::MAX } else { (1u32 << n) - 1 };
    }
    v[0] &= !1;
    v
}

/// Run index of colour `i`: set mask bits at positions 0..=i.
fn run_of(mask: &[u32], i: usize) -> u32 {
    let w = i / 32;
    let bit = i % 32;
    let below: u32 = mask[..w].iter().map(|m| m.count_ones()).sum();
    let keep = if bit == 31 {
        u32::MAX
    } else {
        (2u32 << bit) - 1
    };
    below + (mask[w] & keep).count_ones()
}

/// Reads `width` (≤ 32) bits LSB-first at bit `pos` (the caller checked the range).
fn read_bits(words: &[u32], pos: u64, width: u32) -> u32 {
    if width == 0 {
        return 0;
    }
    let w = (pos >> 5) as usize;
    let bit = (pos & 31) as u32;
    let mut v = (words[w] >> bit) as u64;
    if bit + width > 32 {
        v |= (words[w + 1] as u64) << (32 - bit);
    }
    (v & ((1u64 << width) - 1)) as u32
}

/// Checks everything a decoder without validation (`shaders/glsl/attr/lossless.glsl`) relies on
/// to stay inside the chunk: every block offset, header and run mask, and every palette index.
/// Channel values are not checked (that needs every colour: [`decode_all`]).
pub fn validate(words: &[u32], count: usize) -> Result<(), AttrError> {
    let chunk = Chunk::open(words, count)?;
    (0..chunk.blocks).into_par_iter().try_for_each(|b| {
        let block = chunk.block(b)?;
        let p = &block.plan;
        if p.indexed {
            let stream = block.start + BLOCK_HEADER_WORDS + p.mask_words();
            let palette_bits = p.palette as u64 * PALETTE_ENTRY_BITS as u64;
            let ib = p.index_bits();
            for run in 0..p.runs as u64 {
                let idx = read_bits(&words[stream..], palette_bits + run * ib as u64, ib);
                if idx >= p.palette {
                    return Err(corrupt(
                        stream,
                        format!("palette index {idx} ≥ {}", p.palette),
                    ));
                }
            }
        }
        Ok(())
    })
}

/// Decodes every colour of a chunk of `count` colours (opaque RGBA8).
pub fn decode_all(words: &[u32], count: usize) -> Result<Vec<u32>, AttrError> {
    let chunk = Chunk::open(words, count)?;
    let mut colors = vec![0u32; count];
    colors
        .par_chunks_mut(BLOCK_COLORS)
        .enumerate()
        .try_for_each(|(b, out)| {
            let block = chunk.block(b)?;
            for (i, c) in out.iter_mut().enumerate() {
                *c = chunk.color(&block, i)?;
            }
            Ok(())
        })?;
    Ok(colors)
}

/// Decodes colour `index` of a chunk of `count` colours in O(1).
pub fn decode(words: &[u32], count: usize, index: usize) -> Result<u32, AttrError> {
    if index >= count {
        return Err(AttrError::IndexOutOfRange {
            index: index as u64,
            count: count as u64,
        });
    }
    let chunk = Chunk::open(words, count)?;
    let block = chunk.block(index / BLOCK_COLORS)?;
    chunk.color(&block, index % BLOCK_COLORS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb565_quantize_expand_round_trips() {
        for bits in [5, 6] {
            for v in 0..(1u32 << bits) {
                assert_eq!(quantize(expand(v, bits), bits), v);
            }
        }
        assert_eq!(expand(31, 5), 255);
        assert_eq!(expand(63, 6), 255);
        assert_eq!(expand(0, 5), 0);
    }

    #[test]
    fn run_of_counts_mask_bits_up_to_the_colour() {
        let mask = [0b1010u32, 1 << 31, 0, 1];
        assert_eq!(run_of(&mask, 0), 0);
        assert_eq!(run_of(&mask, 1), 1);
        assert_eq!(run_of(&mask, 3), 2);
        assert_eq!(run_of(&mask, 63), 3);
        assert_eq!(run_of(&mask, 96), 4);
    }

    #[test]
    fn constant_block_is_header_and_one_palette_word() {
        let words = encode(&[0xff10_2030; 128], LosslessVariant::Rgb888);
        // Block header + one stream word (9 palette bits): no table, no mask.
        assert_eq!(words.len(), 2 + 1);
        assert_eq!(decode_all(&words, 128).unwrap(), vec![0xff10_2030; 128]);
    }

    #[test]
    fn empty_chunk_is_its_header() {
        let words = encode(&[], LosslessVariant::Rgb565);
        assert!(words.is_empty());
        assert_eq!(decode_all(&words, 0).unwrap(), Vec::<u32>::new());
    }
}
